"""Windowed time integration: periodic and quasi-periodic excitation, result codes."""

import dataclasses
import time

import jax.numpy as jnp
import numpy as np
import pytest

import gearjax as gj
from gearjax._engine import time_domain as td
from gearjax._engine import windowed as wd
from gearjax._engine.responses import responses_from_samples
from gearjax._engine.results import RESULTS, result_word

pytestmark = pytest.mark.fresh_programs  # counts the traces of ``_windows``

SQRT2 = float(np.sqrt(2.0))


def clearance_oscillator():
    """``x'' + 0.1 x' + g(x) = 0.1 + 0.03 cos(Omega t)``, half clearance 1 (G = 1)."""
    return gj.system_from_matrices([[1.0]], [[0.1]], [[0.0]], [[1.0]], [1.0], backlash=[1.0],
                                   f_mean=[0.1], f_cos=[[0.03]], f_sin=[[0.0]], forcing_mu=[1])


def two_tone(ratio=SQRT2):
    """Two masses on ground springs joined by a linear damped mesh; mass 1 forced at
    ``Omega``, mass 2 at ``ratio Omega`` (forcing columns on two torus angles)."""
    return gj.system_from_matrices(
        np.diag([1.0, 2.0]), 0.05 * np.eye(2), np.diag([1.0, 0.5]), [[1.0, -1.0]], [2.0],
        damping=[0.05], f_cos=[[0.3, 0.0], [0.0, 0.2]], f_sin=[[0.1, 0.0], [0.0, -0.15]],
        forcing_mu=[1, 1], forcing_angle=[0, 1], angle_ratio=[1.0, ratio])


def superposed_rms(system, omega):
    """``sqrt(sum_j |F_j|^2 / 2)``: the exact RMS mesh force of a linear, time-invariant
    system under forcing columns at the rates ``system.forcing_rates()``."""
    M, C, K, W = (np.asarray(a) for a in (system.M, system.C, system.K, system.W))
    kbar, c = np.asarray(system.kbar), np.asarray(system.damping)
    K_all, C_all = K + W.T @ (kbar[:, None] * W), C + W.T @ (c[:, None] * W)
    power = 0.0
    for j, rate in enumerate(system.forcing_rates()):
        w = rate * omega
        f = np.asarray(system.f_cos)[:, j] - 1j * np.asarray(system.f_sin)[:, j]
        X = np.linalg.solve(K_all - w**2 * M + 1j * w * C_all, f)
        F = (kbar + 1j * w * c) * (W @ X)
        power = power + np.abs(F) ** 2 / 2
    return np.sqrt(power)


def test_periodic_windows_match_the_periodic_steady_state():
    """G = 1, at Omega = 1 where the teeth separate for a third of every period. Same
    sample instants (512 per period) as ``simulate``. Across the contact switches the
    integration noise (rtol 1e-8) moves the statistics by ~1e-7 from window to window,
    so windows agree to 1e-6; the transient then contracts by ~0.5 per period (damping
    ratio 0.05), so the windowed statistics sit within ~1e-6 of the orbit's: mean, RMS
    and peak to 2e-5, shares to one sample."""
    system = clearance_oscillator()
    settings = wd.Windowed(samples_per_cycle=512, tol=1e-6, max_windows=200)
    assert wd.window_plan(system, settings) == wd.WindowPlan(periods=1, samples=512,
                                                              slowest=None, fastest=1.0)
    start = time.perf_counter()
    out = wd.simulate_windowed(system, 1.0, settings=settings)
    print(f"\n{int(out.windows)} windows, {time.perf_counter() - start:.2f} s")
    assert bool(out.result == RESULTS.quasi_periodic)
    assert float(out.change[int(out.windows) - 1]) <= 1e-6
    # the periodic search from the windows' end state certifies the orbit it stops on
    tr = gj.simulate(system, 1.0, x0=out.x_end, v0=out.v_end,
                     settings=gj.TimeDomain(periodic_tol=3e-7, max_periods=400))
    assert bool(tr.periodic)
    F_static = gj.static_mesh_forces(system)
    ref = responses_from_samples(tr.p, tr.F, system.backlash, F_static, system.mesh_radius)
    for name in ("mean_force", "rms_force", "max_force", "dlf", "mean_torque"):
        np.testing.assert_allclose(getattr(out.responses, name), getattr(ref, name),
                                   rtol=2e-5, err_msg=name)
    for name in ("separation", "back_contact"):
        np.testing.assert_allclose(getattr(out.responses, name), getattr(ref, name),
                                   atol=1.5 / 512, err_msg=name)
    assert float(out.responses.separation[0]) > 0.05  # the switches are exercised
    # the history's last row is the returned window; rows after it are blank
    last = int(out.windows) - 1
    np.testing.assert_array_equal(out.history.rms_force[last], out.responses.rms_force)
    assert np.all(np.isnan(np.asarray(out.history.rms_force[last + 1:])))


def test_two_incommensurate_tones_superpose():
    """A linear, time-invariant 2-DOF train forced at Omega and sqrt(2) Omega: the windowed
    RMS mesh force is the analytic ``sqrt(sum |F_j|^2 / 2)`` within 1e-5. A window spans
    20 beats (sqrt 2 - 1) Omega: a uniform mean would leave up to 1 / (20 pi) = 1.6% of
    the cross term in the mean square, the weighted one leaves at most the window's leak
    (5e-7); the transient decays within the first, discarded, window and the windows
    agree within 1e-3 of each other. Two frequencies in one vmapped call."""
    system = two_tone()
    settings = wd.Windowed()
    plan = wd.window_plan(system, settings)
    assert plan.slowest == pytest.approx(SQRT2 - 1, rel=1e-12)
    assert plan.periods == int(np.ceil(20 / (SQRT2 - 1))) and plan.samples == 23
    assert plan.leak == wd.window_leak(plan.slowest * plan.periods) < 1e-6
    omegas = np.array([0.6, 1.3])
    start = time.perf_counter()
    out = wd.simulate_windowed_points(system, omegas, settings=settings)
    print(f"\n{np.asarray(out.windows)} windows of {plan.periods} periods, "
          f"{np.asarray(out.stats['num_steps'])} steps, {time.perf_counter() - start:.2f} s")
    np.testing.assert_array_equal(result_word(out.result), ["quasi_periodic"] * 2)
    assert np.all(np.asarray(out.stationary))
    expected = np.stack([superposed_rms(system, w) for w in omegas])
    print("relative RMS error", np.asarray(out.responses.rms_force) / expected - 1)
    np.testing.assert_allclose(out.responses.rms_force, expected, rtol=1e-5)
    assert np.all(np.abs(np.asarray(out.responses.mean_force)) < 1e-5 * expected)  # no mean
    assert np.all(np.isnan(np.asarray(out.responses.dlf)))  # no static load: no load factor
    np.testing.assert_allclose(out.window_time, 2 * np.pi * plan.periods / omegas)


def test_quasi_periodic_excitation_is_the_series_at_float_rates():
    """G = 2: each mesh's stiffness and transmission error, and each forcing column, turn at
    their own angle's rate (``excitation`` against the series written out by hand)."""
    rng = np.random.default_rng(1)
    ratio = (1.0, SQRT2)
    system = gj.system_from_matrices(
        np.eye(2), 0.1 * np.eye(2), np.eye(2), [[1.0, -1.0], [0.0, 1.0]], [1.0, 2.0],
        k_cos=rng.normal(size=(2, 3)), k_sin=rng.normal(size=(2, 3)), mesh_mu=[7, 8],
        te_cos=rng.normal(size=(2, 2)), te_sin=rng.normal(size=(2, 2)), f_mean=[0.1, 0.2],
        f_cos=rng.normal(size=(2, 2)), f_sin=rng.normal(size=(2, 2)), forcing_mu=[1, 3],
        mesh_angle=[0, 1], forcing_angle=[1, 0], angle_ratio=ratio)
    np.testing.assert_array_equal(system.mesh_rates(), [7.0, 8 * SQRT2])
    tau = np.linspace(0.0, 50.0, 37)
    kappa, te, te_rate, f = (np.asarray(a) for a in td.excitation(system, jnp.asarray(tau)))
    k_cos, k_sin = np.asarray(system.k_cos), np.asarray(system.k_sin)
    e_cos, e_sin = np.asarray(system.te_cos), np.asarray(system.te_sin)
    for m, rate in enumerate((7.0, 8 * SQRT2)):
        want_k = 1 + sum(k_cos[m, h - 1] * np.cos(h * rate * tau)
                         + k_sin[m, h - 1] * np.sin(h * rate * tau) for h in (1, 2, 3))
        want_e = sum(e_cos[m, h - 1] * np.cos(h * rate * tau)
                     + e_sin[m, h - 1] * np.sin(h * rate * tau) for h in (1, 2))
        want_de = sum(h * rate * (-e_cos[m, h - 1] * np.sin(h * rate * tau)
                                  + e_sin[m, h - 1] * np.cos(h * rate * tau)) for h in (1, 2))
        np.testing.assert_allclose(kappa[m], want_k, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(te[m], want_e, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(te_rate[m], want_de, rtol=1e-12, atol=1e-11)
    f_cos, f_sin = np.asarray(system.f_cos), np.asarray(system.f_sin)
    rates = (SQRT2 * 1, 1.0 * 3)  # column 0 on angle 1, column 1 on angle 0
    want_f = np.asarray(system.f_mean)[:, None] + sum(
        f_cos[:, [j]] * np.cos(r * tau) + f_sin[:, [j]] * np.sin(r * tau)
        for j, r in enumerate(rates))
    np.testing.assert_allclose(f, want_f, rtol=1e-12, atol=1e-12)
    # scalar phase: the same values
    one = td.excitation(system, jnp.asarray(tau[5]))
    np.testing.assert_allclose(one[0], kappa[:, 5], rtol=1e-13)
    np.testing.assert_allclose(one[3], f[:, 5], rtol=1e-13)


def test_periodic_search_refuses_a_quasi_periodic_system():
    system = two_tone()
    msg = r"angle_ratio = \(1.0, 1.41421356237.*\) gives excitation rates .*windows"
    with pytest.raises(ValueError, match="simulate: system." + msg):
        gj.simulate(system, 1.0)
    with pytest.raises(ValueError, match="simulate_points: system." + msg):
        gj.simulate_points(system, np.array([1.0, 2.0]))
    with pytest.raises(ValueError, match="simulate_sweep: system." + msg):
        gj.simulate_sweep(system, np.array([1.0, 2.0]))
    with pytest.raises(ValueError, match="compile_simulate_points: system." + msg):
        gj.compile_simulate_points(system, np.array([1.0, 2.0]))
    # two angles at commensurate rates are refused too (one angle is the periodic model)
    with pytest.raises(ValueError, match=r"angle_ratio = \(1.0, 2.0\)"):
        gj.simulate(two_tone(ratio=2.0), 1.0)
    # one angle at a non-integer rate has no period 2 pi / Omega either
    half = gj.system_from_matrices([[1.0]], [[0.1]], [[1.0]], [[1.0]], [1.0],
                                   f_cos=[[1.0]], forcing_mu=[1], angle_ratio=[0.5])
    with pytest.raises(ValueError, match=r"angle_ratio = \(0.5,\) gives excitation rates"):
        gj.simulate(half, 1.0)


def test_result_codes_and_one_compilation(monkeypatch):
    """A budget of 3 one-period windows from the static state is too short for a 1e-8
    agreement (``not_stationary``). A new frequency reuses the compiled program."""
    traces = []
    original = wd._windows
    monkeypatch.setattr(wd, "_windows", lambda *a: traces.append(1) or original(*a))
    system = clearance_oscillator()
    settings = wd.Windowed(tol=1e-8, transient_windows=1, n_agree=1, max_windows=3)
    for omega in (1.1, 1.0):
        out = wd.simulate_windowed(system, omega, settings=settings)
    assert len(traces) == 1
    assert result_word(out.result) == "not_stationary" and int(out.windows) == 3
    assert not bool(out.stationary)
    assert np.all(np.isfinite(np.asarray(out.history.rms_force)))
    assert float(np.asarray(out.change)[2]) > 1e-8


def test_a_solver_failure_is_a_result():
    """2 solver steps per period end the first window: nothing kept, the start returned."""
    system = clearance_oscillator()
    out = wd.simulate_windowed(system, 1.0, settings=wd.Windowed(max_steps=2, n_agree=1,
                                                                 max_windows=3))
    assert bool(out.result == RESULTS.max_steps_reached) and int(out.windows) == 0
    assert np.all(np.isnan(np.asarray(out.responses.rms_force)))
    np.testing.assert_array_equal(out.x_end, td.contact_state(system)[0])


def test_settings_are_validated():
    with pytest.raises(ValueError, match="Windowed.n_beats must be a positive integer"):
        wd.Windowed(n_beats=0)
    with pytest.raises(ValueError, match="Windowed.tol must be positive"):
        wd.Windowed(tol=0.0)
    with pytest.raises(ValueError, match="Windowed.max_windows = 2 leaves no room"):
        wd.Windowed(max_windows=2)
    with pytest.raises(ValueError, match=r"Windowed.tol = 0.001 is below 10 times the "
                                         r"0.00\d+ of its slowest beat that a window of "
                                         r"Windowed.n_beats = 5 beats leaves"):
        wd.simulate_windowed(two_tone(), 1.0, settings=wd.Windowed(n_beats=5, tol=1e-3))
    # a periodic system's windows are exact: any tolerance
    assert wd.window_plan(clearance_oscillator(), wd.Windowed(tol=1e-12)).slowest is None
    with pytest.raises(ValueError, match=r"apart, so a window .* needs \d+ base periods, more than"):
        wd.simulate_windowed(two_tone(ratio=1.000001), 1.0)
    with pytest.raises(RuntimeError, match="omega must be positive"):
        wd.simulate_windowed(clearance_oscillator(), 0.0, settings=wd.Windowed(
            tol=1e-8, transient_windows=1, n_agree=1, max_windows=3))


def test_window_reports_tell_each_window_while_it_runs():
    """With ``report``, a listener hears every window (windows done, steps so far, the
    change from the window before) as the loop runs, also from a vmapped batch; without
    it, or outside the block, nothing is told and the result is the same. The settings
    of the test above (its program reused)."""
    system = clearance_oscillator()
    settings = wd.Windowed(tol=1e-8, transient_windows=1, n_agree=1, max_windows=3)
    told = dataclasses.replace(settings, report=True)
    heard = []
    with gj.window_reports(lambda k, steps, change: heard.append((k, steps, change))):
        out = wd.simulate_windowed(system, 1.0, settings=told)
        quiet = wd.simulate_windowed(system, 1.0, settings=settings)
    assert [int(k) for k, _, _ in heard] == [1, 2, 3] == list(range(1, int(out.windows) + 1))
    steps = [int(s) for _, s, _ in heard]
    assert steps == sorted(steps) and steps[-1] == int(out.stats["num_steps"])
    assert np.isnan(heard[0][2]) and float(heard[-1][2]) == float(out.change[2])
    np.testing.assert_array_equal(out.responses.rms_force, quiet.responses.rms_force)
    heard.clear()
    wd.simulate_windowed(system, 1.1, settings=told)
    assert heard == []  # no listener: the callback tells no one
    with gj.window_reports(lambda k, steps, change: heard.append(np.shape(k))):
        wd.simulate_windowed_points(system, jnp.asarray([1.0, 1.1]), settings=told)
    assert heard and all(shape in ((), (2,)) for shape in heard)
