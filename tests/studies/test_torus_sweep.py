"""A sweep on a torus: continuation in the base frequency of a response
driven at two incommensurate frequencies, through folds, with its stability.

The clearance oscillator ``x'' + 0.1 x' + g(x) = 0.1 + 0.03 cos(w t) + 0.01 cos(sqrt(2) w
t)`` (gap 1): the second tone, on its own torus angle, makes the response quasi-periodic;
the first alone has a hysteresis band between folds near 0.64 and 0.85 rad/s, which the
second tone barely moves. References: the mean force, which the balance of the mean
fixes to 0.1 exactly (the mesh is the only spring), and a windowed time integration
(:func:`gearjax.simulate_windowed`) on either stable state of the band.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np
import pytest

import gearjax as gj
from gearjax._engine import aft as _aft
from gearjax._engine.responses import static_mesh_forces
from gearjax._studies.sweep import api as _api
from gearjax._studies.sweep import walk as _walk
from gearjax._studies.sweep.context import Context
from gearjax._studies.sweep.dataset import point_data
from gearjax._studies.sweep.post import PostStream
from gearjax._studies.sweep.record import SweepLog

ROOT2 = math.sqrt(2.0)
K = (12, 3)  # orders on the two angles: the impacts need harmonics of w, the weak tone few


def oscillator():
    return gj.system_from_matrices(
        [[1.0]], [[0.1]], [[0.0]], [[1.0]], [1.0], backlash=[1.0], f_mean=[0.1],
        f_cos=[[0.03, 0.01]], f_sin=[[0.0, 0.0]], forcing_mu=[1, 1], forcing_angle=[0, 1],
        angle_ratio=[1.0, ROOT2])


def hz(omega):
    return omega / (2 * math.pi)  # mu_ref = 1: the "mesh frequency" is the base one


@pytest.fixture(scope="module")
def swept():
    system = oscillator()
    F_static = static_mesh_forces(system)
    runaway = _walk.RUNAWAY * (np.abs(np.asarray(F_static)) / np.asarray(system.kbar)
                               + np.asarray(system.backlash))
    ctx = Context(system=system, eta=1, smoothing=0.0, from_hz=hz(0.55), to_hz=hz(0.95),
                  mu_ref=1.0, max_step_hz=hz(0.02), max_points=600,
                  max_detour=_walk.MAX_DETOUR, runaway=runaway)
    walk = _walk.Walk(segments=[(hz(0.55), hz(0.95), K)])
    log, post = SweepLog([]), PostStream(F_static)
    _api._run_walk(ctx, walk, log, post, linear=False, points=2, progress=None,
                   F_static=F_static)
    data = point_data(walk, log, post, ctx, F_static, linear=False)
    return system, ctx, walk, data


def test_torus_sweep_passes_both_folds(swept):
    """Up through the upper fold (0.852 rad/s with the first tone alone), back along the
    unstable middle branch, through the lower fold (0.6365) and on to the band's end: the
    two outermost folds, the mean force fixed by the balance of the mean, and stability
    that changes only where the branch turns (a multiplier through +1 at a fold; the
    grazing of the contact boundary adds small fold pairs of its own, near 0.662 and
    0.637 rad/s here)."""
    system, ctx, walk, data = swept
    assert walk.stop == "reached_end" and not walk.restarts
    folds = sorted(f * 2 * math.pi for f in walk.folds)  # rad/s
    assert folds[0] == pytest.approx(0.6365, abs=0.005)
    assert folds[-1] == pytest.approx(0.852, abs=0.01)
    # the mean of the force is fixed by the balance of the mean: 0.1, at every point
    mean = np.asarray(data["responses"].mean_force)[:, 0]
    np.testing.assert_allclose(mean, 0.1, rtol=0, atol=1e-9)
    om, stable = data["omega"], data["stable"]
    assert set(np.unique(stable)) == {0, 1}
    turns = np.flatnonzero(np.diff(np.sign(np.diff(om))) != 0) + 1  # where omega turns back
    for i in np.flatnonzero(np.diff(stable) != 0):
        assert np.min(np.abs(turns - i - 0.5)) <= 2.5, (i, om[i])
    # the middle branch, from the upper fold back to the lower one, is unstable
    top = int(np.argmax(om))
    low = top + int(np.argmin(om[top:]))
    assert np.all(stable[top + 2: low - 5] == 0)


@pytest.mark.slow
@pytest.mark.parametrize("which", ["upper", "lower"])
def test_stable_torus_states_match_a_windowed_integration(swept, which):
    """At 0.75 rad/s, inside the band: the RMS alternating force and the separation share
    of each stable state against the windowed integration started on it (within 2%:
    consecutive windows agree within 1%, ``Windowed.tol``)."""
    system, ctx, walk, data = swept
    w = 0.75
    om, stable = data["omega"], data["stable"] == 1
    rms = np.asarray(data["responses"].rms_force)[:, 0]
    crossings = [i for i in range(len(om) - 1)
                 if stable[i] and stable[i + 1] and (om[i] - w) * (om[i + 1] - w) <= 0]
    assert len(crossings) == 2
    i = sorted(crossings, key=lambda j: rms[j])[1 if which == "upper" else 0]
    problem = ctx.problem(K)
    y = jnp.asarray(data["X"][i] / problem.x_scale).reshape(-1)
    sol = gj.hb_newton(problem, jnp.asarray(w), y)
    assert bool(sol.converged)
    hb = gj.mesh_responses(problem, sol.X, w, static_mesh_forces(system))
    x0 = sol.X[0] + jnp.sum(sol.X[1::2], axis=0)  # theta = 0
    nu = _aft.frequency_numbers(problem.basis)
    v0 = w * jnp.sum(jnp.asarray(nu[2::2])[:, None] * sol.X[2::2], axis=0)
    out = gj.simulate_windowed(system, w, x0=x0, v0=v0, settings=gj.Windowed())
    assert out.result == gj.RESULTS.quasi_periodic
    np.testing.assert_allclose(out.responses.rms_force[0], hb.rms_force[0], rtol=0.02)
    assert abs(float(out.responses.separation[0]) - float(hb.separation[0])) < 0.02


@pytest.mark.slow
def test_completion_finds_the_state_the_torus_walk_missed():
    """The walk made to leave its branch right after the upper fold (``max_detour`` 5,
    as where a gear's branch wanders) misses the impacting state of the hysteresis band;
    the completion (the band's far end, the jumps: starts by time integration on the
    torus) traces it: two stable states at 0.75 rad/s, as the full walk above has."""
    system = oscillator()
    F_static = static_mesh_forces(system)
    runaway = _walk.RUNAWAY * (np.abs(np.asarray(F_static)) / np.asarray(system.kbar)
                               + np.asarray(system.backlash))
    ctx = Context(system=system, eta=1, smoothing=0.0, from_hz=hz(0.55), to_hz=hz(0.95),
                  mu_ref=1.0, max_step_hz=hz(0.02), max_points=600, max_detour=5,
                  runaway=runaway)
    walk = _walk.Walk(segments=[(hz(0.55), hz(0.95), K)])
    log, post = SweepLog([]), PostStream(F_static)
    pieces, records = _api._run_walk(ctx, walk, log, post, linear=False, points=2,
                                     progress=None, F_static=F_static, complete=True)
    data = point_data(walk, log, post, ctx, F_static, linear=False, pieces=pieces)
    assert walk.restarts and "restart" in [r["found"] for r in records]
    w = 0.75
    om, stable, branch = data["omega"], data["stable"] == 1, data["branch"]
    rms = np.asarray(data["responses"].rms_force)[:, 0]
    states = sorted(rms[i] for i in range(len(om) - 1)
                    if branch[i] == branch[i + 1] and stable[i] and stable[i + 1]
                    and (om[i] - w) * (om[i + 1] - w) <= 0)
    assert len(states) == 2 and states[1] > 1.5 * states[0]
    assert len(records) > 2  # walked, restarted, and at least one seeded branch
