"""Time integration to the steady state: analytic, harmonic-balance and self checks."""

import dataclasses
import time
import warnings

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gearjax as gj
from gearjax._engine import aft as _aft
from gearjax._engine import hb as _hb
from gearjax._engine import newton as _newton
from gearjax._engine import time_domain as td
from gearjax._engine.results import RESULTS, result_word

pytestmark = pytest.mark.fresh_programs  # counts the traces of ``_steady_state``

solve_hb = jax.jit(_newton.solve_hb)


def oscillator(clearance=0.0, c=0.1, f_mean=0.1, f_amp=0.03):
    """``x'' + c x' + g(x) = f_mean + f_amp cos(Omega t)`` with half clearance ``clearance``."""
    return gj.system_from_matrices([[1.0]], [[c]], [[0.0]], [[1.0]], [1.0], backlash=[clearance],
                                   f_mean=[f_mean], f_cos=[[f_amp]], f_sin=[[0.0]], forcing_mu=[1])


def amplitude(x):
    """Half the peak-to-peak of samples along the last axis."""
    x = np.asarray(x)
    return 0.5 * (x.max(-1) - x.min(-1))


def rms(F):
    """RMS of the alternating part along the last axis (the paper's r.m.s. mesh force)."""
    F = np.asarray(F)
    return np.sqrt(np.mean((F - F.mean(-1, keepdims=True)) ** 2, axis=-1))


def hb_samples(system, X, omega, n_time=4096):
    """Mesh forces ``(m, T)`` of a harmonic-balance solution, through the same ``mesh_force``."""
    tau = _aft.phases(n_time)
    p = _aft.synthesis(X @ system.W.T, n_time).T
    p_dot = omega * _aft.synthesis(_aft.derivative(X) @ system.W.T, n_time).T
    kappa = 1.0 + gj.fourier_series(system.k_cos, system.k_sin, jnp.asarray(system.mesh_mu), 1.0,
                                    tau) if system.k_cos.shape[-1] else jnp.ones_like(p)
    return gj.mesh_force(p, p_dot, kappa, system.kbar[:, None], system.backlash[:, None],
                         system.damping[:, None], system.contact_damping)


@pytest.fixture(scope="module")
def clearance():
    system = oscillator(clearance=1.0)
    problem = _hb.hb_problem(system, _hb.HarmonicBalance(n_harmonics=15))
    return system, problem


@pytest.fixture(scope="module")
def sweeps(clearance):
    """Up from 0.5 and down from 1.1 to 0.75, one scan each, vmapped over direction."""
    system, _ = clearance
    omegas = jnp.stack([jnp.linspace(0.5, 0.75, 6), jnp.linspace(1.1, 0.75, 6)])
    return omegas, gj.simulate_sweep(system, omegas)


def test_linear_oscillator_amplitude_is_analytic():
    """From the static state (no harmonic balance): mean and first harmonic to 1e-6."""
    omegas = np.array([0.4, 1.0, 1.7])
    settings = gj.TimeDomain(periodic_tol=1e-9, max_periods=400)
    tr = gj.simulate_points(oscillator(), omegas, settings=settings)
    assert np.all(np.asarray(tr.periodic)) and np.all(np.asarray(tr.period) == 1)
    x = np.asarray(tr.x[:, 0, :])
    spectrum = np.fft.rfft(x, axis=-1) / x.shape[-1]
    H = 0.03 / (1 - omegas**2 + 0.1j * omegas)  # x = Re(H e^{i w t})
    np.testing.assert_allclose(spectrum[:, 0].real, 0.1, rtol=1e-6)
    np.testing.assert_allclose(2 * np.abs(spectrum[:, 1]), np.abs(H), rtol=1e-6)
    np.testing.assert_allclose(2 * spectrum[:, 1], H, rtol=1e-6)  # phase too (t = 0 is phase 0)


def test_sample_count_need_not_be_a_power_of_two():
    """``2 pi j / N`` rounds above the period's end for some ``N`` (260 here), which diffrax
    refuses as a save time outside the interval: the last sample is pinned to it."""
    settings = gj.TimeDomain(n_samples=260, periodic_tol=1e-9, max_periods=400)
    tr = gj.simulate(oscillator(), 1.0, settings=settings)
    assert bool(tr.periodic) and tr.x.shape == (1, 260)
    spectrum = np.fft.rfft(np.asarray(tr.x[0])) / 260
    np.testing.assert_allclose(2 * spectrum[1], 0.03 / (0.1j), rtol=1e-6)


def test_hb_initial_state_starts_on_the_orbit():
    """The harmonic-balance state at t = 0 is the linear orbit: periodic after one period."""
    system = oscillator()
    problem = _hb.hb_problem(system, _hb.HarmonicBalance(n_harmonics=4))
    sol = solve_hb(problem, 0.7)
    x0, v0 = gj.hb_initial_state(sol.X, 0.7)
    H = 0.03 / (1 - 0.49 + 0.07j)
    np.testing.assert_allclose([x0[0], v0[0]], [0.1 + H.real, -0.7 * H.imag], rtol=1e-12)
    tr = gj.simulate(system, 0.7, x0=x0, v0=v0)
    assert bool(tr.periodic) and int(tr.periods) == 1


def test_clearance_oscillator_matches_harmonic_balance_off_the_jump(clearance):
    system, problem = clearance
    omegas = np.array([0.5, 1.3])
    sols = [solve_hb(problem, w) for w in omegas]
    assert all(bool(s.converged) for s in sols)
    X = jnp.stack([s.X for s in sols])
    x0, v0 = jax.vmap(gj.hb_initial_state)(X, jnp.asarray(omegas))
    tr = gj.simulate_points(system, omegas, x0=x0, v0=v0)
    assert np.all(np.asarray(tr.periodic))
    for i, (w, s) in enumerate(zip(omegas, sols)):
        a_hb = amplitude(_aft.synthesis(s.X, 4096)[:, 0])
        np.testing.assert_allclose(amplitude(tr.x[i, 0]), a_hb, rtol=5e-3)
        np.testing.assert_allclose(rms(tr.F[i]), rms(hb_samples(system, s.X, w)), rtol=5e-3)


def test_up_and_down_sweeps_land_on_different_branches(clearance, sweeps):
    """Inside the hysteresis band (folds near 0.6365 and 0.852) at Omega = 0.75."""
    system, problem = clearance
    omegas, tr = sweeps
    assert tr.x.shape == (2, 6, 1, 512)
    assert np.all(np.asarray(tr.periodic))
    up, down = amplitude(tr.x[0, -1, 0]), amplitude(tr.x[1, -1, 0])
    assert down > 3 * up  # the down sweep stays on the resonant branch
    # each branch is a harmonic-balance solution: Newton from the integrated orbit
    for d, a in ((0, up), (1, down)):
        X = _aft.analysis(tr.x[d, -1].T, 15)
        sol = solve_hb(problem, 0.75, X.reshape(-1) / jnp.tile(problem.x_scale, 31))
        assert bool(sol.converged)
        np.testing.assert_allclose(amplitude(_aft.synthesis(sol.X, 4096)[:, 0]), a, rtol=5e-3)
    # the upper branch leaves contact: the test exercises the backlash switches
    assert float(jnp.min(tr.p[1, -1])) < 1.0 < float(jnp.max(tr.p[1, -1]))


def test_halving_tolerances_and_an_implicit_solver_agree(clearance, sweeps):
    """On the upper branch at 0.75 (tooth separation every period): RMS force moves < 0.1%."""
    system, _ = clearance
    _, tr = sweeps
    x0, v0 = tr.x_end[1, -1], tr.v_end[1, -1]
    runs = {
        "default": gj.TimeDomain(),  # rtol = atol = 1e-8
        "halved": gj.TimeDomain(rtol=5e-9, atol=5e-9),
        "kvaerno5": gj.TimeDomain(solver=diffrax.Kvaerno5(), pcoeff=0.3, icoeff=0.3),
    }
    out = {k: gj.simulate(system, 0.75, x0=x0, v0=v0, settings=s) for k, s in runs.items()}
    ref = rms(out["default"].F)
    for k, r in out.items():
        assert bool(r.periodic), k
        np.testing.assert_allclose(rms(r.F), ref, rtol=1e-3, err_msg=k)


def test_subharmonic_and_quasi_periodic_are_found():
    """Undamped ``x'' + x = 0.1 + 0.03 cos(Omega t)`` with a free vibration at frequency 1.

    The orbit repeats after 2 base periods at Omega = 2, after 3 at Omega = 3, and never
    (quasi-periodic) at Omega = pi.
    """
    system = oscillator(c=0.0)
    settings = gj.TimeDomain(max_periods=24, n_samples=64)
    tr = gj.simulate_points(system, np.array([2.0, 3.0, np.pi]), x0=jnp.array([0.6]),
                            settings=settings, batch_size=1)  # lax.map, one point at a time
    np.testing.assert_array_equal(result_word(tr.result), ["not_periodic"] * 3)
    np.testing.assert_array_equal(tr.period, [2, 3, 0])
    np.testing.assert_array_equal(tr.periods, [3, 5, 24])  # q checks in a row


def test_sample_periods_cover_a_subharmonic_orbit():
    """``sample_periods = 2`` at Omega = 2: the samples are the whole period-2 orbit
    ``x = 0.1 + A cos 2t + (0.5 - A) cos t``, ``A = 0.03 / (1 - 4)``, at the right times."""
    settings = gj.TimeDomain(max_periods=24, n_samples=64, sample_periods=2)
    tr = gj.simulate(oscillator(c=0.0), 2.0, x0=jnp.array([0.6]), settings=settings)
    assert int(tr.period) == 2 and tr.x.shape == (1, 128)
    t = np.asarray(tr.t)
    np.testing.assert_allclose(np.diff(t), np.pi / 64, rtol=1e-12)
    A = 0.03 / (1 - 4)
    np.testing.assert_allclose(tr.x[0], 0.1 + A * np.cos(2 * t) + (0.5 - A) * np.cos(t), atol=1e-6)


def test_result_codes_and_one_compilation(monkeypatch):
    traces = []
    original = td._steady_state
    monkeypatch.setattr(td, "_steady_state", lambda *a: traces.append(1) or original(*a))
    system = oscillator(clearance=1.0)
    settings = gj.TimeDomain(max_steps=5, n_samples=32)
    for omegas in ([0.5, 0.9], [0.6, 1.2]):  # new values, same shape: no retrace
        tr = gj.simulate_points(system, np.array(omegas), settings=settings)
        assert np.all(np.asarray(tr.result == RESULTS.max_steps_reached)) and tr.x.shape[0] == 2
        assert np.all(np.isfinite(np.asarray(tr.x_end)))
    assert len(traces) == 1
    tr = gj.simulate(system, 0.5, settings=gj.TimeDomain(max_periods=2, n_samples=32))
    assert bool(tr.result == RESULTS.not_periodic) and int(tr.period) == 0 and int(tr.periods) == 2


def test_settings_and_frequency_are_validated():
    with pytest.raises(ValueError, match="TimeDomain.n_samples must be a positive integer"):
        gj.TimeDomain(n_samples=0)
    with pytest.raises(ValueError, match="TimeDomain.rtol must be positive"):
        gj.TimeDomain(rtol=0.0)
    with pytest.raises(ValueError, match="simulate: the base frequency omega must be positive"):
        gj.simulate(oscillator(), 0.0, settings=gj.TimeDomain(max_steps=5, n_samples=32))
    with pytest.raises(ValueError, match="simulate_points: .* not -1.0"):
        gj.simulate_points(oscillator(), np.array([1.0, -1.0]), settings=gj.TimeDomain())
    # traced (under the caller's jit), a frequency that is not positive is a result
    run = jax.jit(lambda w: gj.simulate(oscillator(), w, settings=gj.TimeDomain(n_samples=32)))
    tr = run(-1.0)
    assert bool(tr.result == RESULTS.nonfinite) and int(tr.periods) == 0


def test_paper_first_gear_agrees_with_harmonic_balance():
    """Linear (no backlash) at a 3 kHz stage-1 mesh frequency, and with backlash at 4 kHz,
    where the meshes separate for ~15% of the period: RMS mesh forces within 1% and 2%.

    K = 48: at 3 kHz the parametric sidebands reach the 39-45 kHz shaft modes, and
    K = 24 / 32 truncate the harmonic balance by 9% / 0.8%; K = 48 is within 0.3%.
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gj.GeometryWarning)
        paper = gj.assemble(gj.load_train())
    cases = [(dataclasses.replace(paper, backlash=jnp.zeros_like(paper.backlash)), 3000.0, 1e-2),
             (paper, 4000.0, 2e-2)]
    for system, mesh_hz, tol in cases:
        omega = 2 * np.pi * mesh_hz / 7
        sol = solve_hb(_hb.hb_problem(system, _hb.HarmonicBalance(n_harmonics=48)), omega)
        assert bool(sol.converged)
        x0, v0 = gj.hb_initial_state(sol.X, omega)
        start = time.perf_counter()
        tr = gj.simulate(system, omega, x0=x0, v0=v0)
        tr.F.block_until_ready()
        elapsed = time.perf_counter() - start
        print(f"\n{mesh_hz:.0f} Hz: {int(tr.periods)} periods, {int(tr.stats['num_steps'])} steps, "
              f"{elapsed:.2f} s (first call includes compilation)")
        assert bool(tr.periodic)
        np.testing.assert_allclose(rms(tr.F), rms(hb_samples(system, sol.X, omega)), rtol=tol)
        if system is paper:
            separated = np.mean(np.abs(np.asarray(tr.p)) <= np.asarray(paper.backlash)[:, None],
                                axis=1)
            assert separated.max() > 0.05


def test_simulate_compiles_one_program_whatever_start_it_is_given(monkeypatch):
    """The contact state, a given position, and a given position and rate: one trace of
    the integration (one program to compile, or to load from the persistent cache)."""
    traces = []
    original = td._steady_state
    monkeypatch.setattr(td, "_steady_state", lambda *a: traces.append(1) or original(*a))
    # traces of the jitted program are counted: a program kept by an earlier run would be
    # loaded, not traced (tests/engine/test_kept.py)
    monkeypatch.setenv("GEARJAX_KEEP_PROGRAMS", "0")
    system = oscillator(clearance=0.3)
    settings = gj.TimeDomain(max_periods=3, n_samples=16, rtol=1e-5, atol=1e-5)
    x_contact, v_contact = (np.asarray(a) for a in td.contact_state(system))
    ends = [gj.simulate(system, 0.8, settings=settings).x_end,
            gj.simulate(system, 0.8, x0=x_contact, settings=settings).x_end,
            gj.simulate(system, 0.8, x0=x_contact, v0=v_contact, settings=settings).x_end]
    assert len(traces) == 1
    np.testing.assert_array_equal(ends[0], ends[1])
    np.testing.assert_array_equal(ends[0], ends[2])


def test_integration_programs_hold_no_host_callback():
    """The steady-state and sampled integrations compile to programs without a host
    callback (diffrax checks ``SaveAt(ts=...)`` with one, and JAX keeps no program that
    holds one in its persistent cache: it would be compiled again in every process)."""
    system = oscillator(clearance=0.3)
    x0, v0 = td.start_state(system, None, None)
    omega = jnp.asarray(0.8)
    settings = gj.TimeDomain(max_periods=3, n_samples=16)
    tau = jnp.asarray(np.linspace(0.5, 20.0, 40))
    programs = {"simulate": td._simulate.lower(system, omega, x0, v0, settings),
                "simulate_points": td._simulate_points.lower(
                    system, jnp.asarray([0.8, 0.9]), x0, v0, settings, None),
                "sample_trajectory": td._sample_trajectory.lower(system, omega, x0, v0, tau,
                                                                 settings, 4)}
    for name, lowered in programs.items():
        assert "callback" not in lowered.as_text(), name
