"""The integrations every time-domain function is built on (gearjax/_engine/integrator.py):
to an end time, and through sample times, against the exact solution of a harmonic
oscillator."""

import diffrax
import jax
import jax.numpy as jnp
import numpy as np

from gearjax._engine import integrator as _integrator


def _oscillator(t, z, args):
    """``x'' = -x`` as a first-order system."""
    return jnp.stack([z[1], -z[0]])


SETTINGS = _integrator.Integrator(rtol=1e-10, atol=1e-10)
TERM = diffrax.ODETerm(_oscillator)


def test_sample_gives_the_exact_states_at_the_sample_times():
    """From ``(1, 0)`` at ``t = 0.3`` the state is ``(cos(t - 0.3), -sin(t - 0.3))``: the
    samples (not equally spaced, the first at the start time itself) within 1e-8, and
    the end state and steps of the whole reported."""
    ts = jnp.asarray([0.3, 0.5, 1.1, 2.0, 4.7, 9.0])
    zs, leg = jax.jit(lambda ts: _integrator.sample(SETTINGS, TERM, 0.3, jnp.asarray([1.0, 0.0]),
                                                    ts, None, 10_000))(ts)
    s = np.asarray(ts) - 0.3
    np.testing.assert_allclose(np.asarray(zs), np.stack([np.cos(s), -np.sin(s)], axis=1),
                               atol=1e-8)
    assert bool(leg.ok) and bool(leg.result == diffrax.RESULTS.successful)
    np.testing.assert_array_equal(np.asarray(leg.z), np.asarray(zs[-1]))
    assert int(leg.steps) > 0
    end = _integrator.integrate(SETTINGS, TERM, 0.3, 9.0, jnp.asarray([1.0, 0.0]), None, 10_000)
    np.testing.assert_allclose(np.asarray(end.z), [np.cos(8.7), -np.sin(8.7)], atol=1e-8)


def test_a_failed_interval_is_reported_and_the_states_stay_where_it_stopped():
    """Two steps allowed per interval: the first long interval fails (``max_steps``); its
    samples and the ones after keep the last state reached, which is finite, and the
    result is the failure, not a later interval's success."""
    ts = jnp.asarray([0.1, 50.0, 50.1])
    zs, leg = _integrator.sample(SETTINGS, TERM, 0.0, jnp.asarray([1.0, 0.0]), ts, None, 2)
    assert not bool(leg.ok)
    assert bool(leg.result == diffrax.RESULTS.max_steps_reached)
    np.testing.assert_array_equal(np.asarray(zs[1]), np.asarray(zs[0]))
    np.testing.assert_array_equal(np.asarray(zs[2]), np.asarray(zs[0]))
    np.testing.assert_allclose(np.asarray(zs[0]), [np.cos(0.1), -np.sin(0.1)], atol=1e-8)
