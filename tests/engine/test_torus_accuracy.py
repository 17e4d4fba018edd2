"""Accuracy of the torus harmonic balance and of its stability verdict, against results
that do not come from the balance:

- a linear system with two incommensurate parametric excitations, the RMS mesh
  forces of the torus balance against a long windowed time integration;
- the growth per turn of the Floquet verdict on a torus (the monodromy over the
  near return, :func:`gearjax._engine.floquet.return_turns`) against Hill's method on
  the torus basis and against the time integration from the solution: a point marked
  stable is one the integration stays on, one marked unstable one it leaves, and the
  integration's own growth or decay rate is the verdict's; and what the drift bound
  :data:`gearjax._engine.floquet.RETURN_DRIFT` costs;
- a torus whose ratio is rational (9/7), restricted to the line ``theta = rates
  Omega t``, against the periodic balance of the same system on the common base
  ``Omega / 7`` (mu = (7, 9)) and against the periodic time integration.

The test system: two bodies on a coupling spring, each behind one mesh; mesh 1 varies
with angle 0 (rate ``Omega``), mesh 2 with angle 1 (rate ``ratio Omega``); a mean load,
so the stiffness variation (``eps``) excites the response parametrically. Natural
frequencies of the mean-stiffness model: 0.93 and 1.20 rad/s; modal damping ratios
about 0.02.
"""

from __future__ import annotations

import dataclasses
import functools

import diffrax as dfx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gearjax as gj
from gearjax._engine import aft as _aft
from gearjax._engine import floquet as _floquet
from gearjax._engine import hb as _hb
from gearjax._engine import time_domain as _td
from gearjax._engine import verdict as _verdict
from gearjax._engine import windowed as _wd
from gearjax._engine.newton import newton_jit
from gearjax._engine.torus_stability import torus_stability

ROOT2 = float(np.sqrt(2.0))


def two_mesh_system(*, eps=0.2, te=0.02, amp=(0.0, 0.0), backlash=0.0, ratio=ROOT2):
    """Two bodies (inertias 1, 1.5) on a coupling spring 0.3, each behind one mesh (mean
    stiffness 1, 1.2; stiffness ``1 + eps cos``; transmission error ``te cos``; damping
    0.03, plus 0.02 to ground), mean loads 0.5, 0.6, forcing ``amp`` on each body at its
    mesh's angle. Mesh 1 turns with angle 0, mesh 2 with angle 1 (rate ``ratio``)."""
    return gj.system_from_matrices(
        np.diag([1.0, 1.5]), 0.02 * np.eye(2), [[0.3, -0.3], [-0.3, 0.3]], np.eye(2),
        [1.0, 1.2], backlash=[backlash] * 2, damping=[0.03, 0.03], k_cos=[[eps], [eps]],
        mesh_mu=[1, 1], mesh_angle=[0, 1], te_cos=[[te], [te]], f_mean=[0.5, 0.6],
        f_cos=[[amp[0], 0.0], [0.0, amp[1]]], f_sin=np.zeros((2, 2)), forcing_mu=[1, 1],
        forcing_angle=[0, 1], angle_ratio=[1.0, ratio])


def solve(system, K, omega, truncation="diamond"):
    """The torus balance at orders ``(K, K)`` from the linear guess; asserts convergence."""
    problem = _hb.hb_problem(system, _hb.HarmonicBalance(n_harmonics=(K, K),
                                                         truncation=truncation))
    omega = jnp.asarray(omega, dtype=float)
    sol = newton_jit(problem, omega, _hb.linear_guess(problem, omega))
    assert bool(sol.result == gj.RESULTS.successful), (K, float(omega))
    return problem, sol.X


stability = jax.jit(gj.stability, static_argnames="n_steps")
hill = jax.jit(torus_stability)


def per_turn_floquet(problem, X, omega):
    st = stability(problem, X, jnp.asarray(omega))
    return np.sort(np.abs(np.asarray(st.multipliers))), bool(st.stable)


def per_turn_hill(problem, X, omega):
    """Hill's exponents as growth per turn of the base angle, ``|exp(s 2 pi / omega)|``."""
    ts = hill(problem, X, jnp.asarray(omega))
    assert bool(ts.reliable)
    growth = np.abs(np.exp(np.asarray(ts.exponents) * 2 * np.pi / omega))
    return np.sort(growth), bool(ts.stable)


def on_line(basis, X, omega, t):
    """``x``, ``x'`` ``(T, n)`` of the torus solution ``X`` along the line ``theta = rates
    omega t`` at the times ``t`` ``(T,)`` (s): the series with frequency numbers ``k .
    rates``, written out here (not the engine's line series)."""
    nu = _aft.frequency_numbers(basis)[1::2]
    arg = omega * np.outer(t, nu)
    X = np.asarray(X)
    a, b = X[1::2], X[2::2]
    x = X[0] + np.cos(arg) @ a + np.sin(arg) @ b
    v = omega * ((np.cos(arg) * nu) @ b - (np.sin(arg) * nu) @ a)
    return x, v


@functools.partial(jax.jit, static_argnames="max_steps")
def _integrate(problem, omegas, z0, taus, max_steps=4_000_000):
    """Scaled states ``(B, T, 2n)`` at phases ``taus`` ``(T,)`` of the time integration of
    ``problem`` (the engine's ``vector_field``: the equations of the balance at the true
    rates) from ``z0`` ``(B, 2n)`` at ``omegas`` ``(B,)``; Dopri8 at rtol 1e-10."""
    def one(omega, z):
        return dfx.diffeqsolve(
            dfx.ODETerm(_td.vector_field), dfx.Dopri8(), 0.0, taus[-1], None, z,
            args=(problem, omega), saveat=dfx.SaveAt(ts=taus),
            stepsize_controller=dfx.PIDController(rtol=1e-10, atol=1e-10, pcoeff=0.0,
                                                  icoeff=1.0),
            max_steps=max_steps).ys
    return jax.vmap(one)(omegas, z0)


def integrate_from(system, starts, turns, per_turn):
    """Integrate ``system`` from each ``(omega, x0, v0)`` of ``starts`` over ``turns`` turns
    of the base angle, ``per_turn`` samples each: ``x`` ``(B, turns per_turn + 1, n)``."""
    ip = _td.integration_problem(system)
    taus = 2 * np.pi * np.arange(turns * per_turn + 1) / per_turn
    omegas = jnp.asarray([s[0] for s in starts], dtype=float)
    z0 = jnp.stack([jnp.concatenate([x0 / ip.x_scale, v0 / (w * ip.x_scale)])
                    for w, x0, v0 in starts])
    ys = np.asarray(_integrate(ip, omegas, z0, jnp.asarray(taus)))
    return ys[..., : system.n_dof] * np.asarray(ip.x_scale), taus


def per_turn_max(a, per_turn):
    """Largest value over each turn of the samples ``a`` ``(turns per_turn + 1,)``."""
    return a[:-1].reshape(-1, per_turn).max(axis=1)


# ---------------------------------------------- two incommensurate parametric excitations


@pytest.mark.slow
def test_two_parametric_excitations_match_windowed_integration():
    """Linear, ``k = 1 + 0.2 cos`` on both meshes at ``Omega`` and ``sqrt(2) Omega`` under
    mean load, plus transmission error. The orders are chosen by the truncation check
    (RMS and mean mesh forces change by < 1e-5 relative from ``K`` to ``K + 2``), then the
    torus balance's RMS and mean mesh forces match a windowed integration within 1e-4.

    The integration's windows span 40 cycles of the slowest beat ``(sqrt 2 - 1) Omega``,
    their averages weighted (the window's leak, under 1e-9 of a tone's amplitude), and
    consecutive windows agree to 1e-6 (``tol``): the integration's statistics are within
    about 1e-6 of the true ones, the balance's within its 1e-5 truncation check, so 1e-4
    holds both with room. Not a superposition check: the combination tones
    ``k`` with both entries non-zero (the interplay of the two parametric excitations)
    carry over 1% of a mesh's mean square, and the additive model (the stiffness
    variation acting on the static deflection only, without the parametric coupling)
    is off by more than 5%."""
    system = two_mesh_system()
    F_static = gj.static_mesh_forces(system)
    omegas = (0.6, 0.9)
    chosen = []
    for omega in omegas:
        previous = None
        for K in (2, 4, 6, 8):
            problem, X = solve(system, K, omega)
            r = gj.mesh_responses(problem, X, jnp.asarray(omega), F_static)
            now = np.concatenate([np.asarray(r.rms_force), np.asarray(r.mean_force)])
            if previous is not None and np.max(np.abs(now / previous[1] - 1)) < 1e-5:
                break
            previous = (problem, now, X, r)
        else:
            pytest.fail(f"the torus balance did not converge in K at omega = {omega}")
        problem, _, X, r = previous  # the smaller K: its change to K + 2 is the estimate
        print(f"\nomega {omega}: orders {problem.settings.n_harmonics} "
              f"({problem.basis.n_pairs} wave vectors), RMS {np.asarray(r.rms_force)}")
        chosen.append((problem, X, r))
    # the parametric interplay matters: combination tones and the additive model
    problem, X, r = chosen[0]
    k = np.asarray(problem.basis.orders)
    mixed = (k[:, 0] != 0) & (k[:, 1] != 0)
    Fh = np.asarray(_hb.mesh_force_harmonics(problem, X @ system.W.T, jnp.asarray(omegas[0])))
    power = (Fh[1::2] ** 2 + Fh[2::2] ** 2) / 2
    assert np.max(power[mixed].sum(0) / power.sum(0)) > 0.01
    p_static = np.asarray(F_static) / np.asarray(system.kbar)
    additive = dataclasses.replace(two_mesh_system(eps=0.0), te_cos=jnp.asarray(
        0.02 - 0.2 * p_static)[:, None])
    problem_a, X_a = solve(additive, problem.settings.n_harmonics[0], omegas[0])
    r_a = gj.mesh_responses(problem_a, X_a, jnp.asarray(omegas[0]), F_static)
    assert np.max(np.abs(np.asarray(r_a.rms_force) / np.asarray(r.rms_force) - 1)) > 0.05

    settings = _wd.Windowed(n_beats=40, tol=1e-6)
    out = _wd.simulate_windowed_points(system, jnp.asarray(omegas), settings=settings)
    assert np.all(np.asarray(out.stationary))
    for j, (_, _, r) in enumerate(chosen):
        rms_w = np.asarray(out.responses.rms_force[j])
        mean_w = np.asarray(out.responses.mean_force[j])
        print(f"omega {omegas[j]}: windowed RMS {rms_w}, relative difference "
              f"{np.asarray(r.rms_force) / rms_w - 1}")
        np.testing.assert_allclose(r.rms_force, rms_w, rtol=1e-4)
        np.testing.assert_allclose(r.mean_force, mean_w, rtol=1e-4)


# ------------------------------------------------------------- the verdict's growth per turn

# Per-turn growth of the Floquet verdict against Hill's: the monodromy is taken over the
# q = 29 turns after which the line theta = (1, sqrt 2) omega t returns within d = 0.012
# turns of angle 1 (RETURN_DRIFT = 0.02). The closure error perturbs the multipliers of
# the q turns relatively by about |P^-1 dP/dtheta| 2 pi d, their q-th root by that over q:
# measured up to 3.7e-4 on these cases (test_drift_of_the_near_return), so 1e-3.
GROWTH_TOL = 1e-3


@pytest.mark.parametrize("omega, stable", [(0.8, True), (1.3, False)])
def test_floquet_on_a_torus_agrees_with_hill_linear(omega, stable):
    """Linear parametric system (``eps = 0.2``): at 0.8 rad/s stable, at 1.3 rad/s inside
    the principal tongue of mode 2 under mesh 2 (``sqrt 2 x 1.3 = 1.84 ~ 2 x 0.93``).
    Hill's exponents at orders (8, 8) are converged (< 1e-8 from (6, 6)); every growth per
    turn of the Floquet verdict matches Hill's within ``GROWTH_TOL``, and the verdicts
    agree."""
    system = two_mesh_system()
    problem, X = solve(system, 8, omega)
    floquet, fl_stable = per_turn_floquet(problem, X, omega)
    hill8, hill_stable = per_turn_hill(problem, X, omega)
    hill6, _ = per_turn_hill(*solve(system, 6, omega), omega)
    print(f"\nomega {omega}: Floquet {floquet}, Hill {hill8}, Floquet - Hill "
          f"{floquet - hill8}")
    np.testing.assert_allclose(hill8, hill6, atol=1e-8)
    np.testing.assert_allclose(floquet, hill8, atol=GROWTH_TOL)
    assert fl_stable == hill_stable == stable


@pytest.mark.parametrize("amp, omega, stable", [((0.4, 0.3), 1.3, True),
                                                 ((0.25, 0.2), 1.1, False)])
def test_floquet_on_a_torus_agrees_with_hill_backlash(amp, omega, stable):
    """Backlash 0.45 with forcing on each angle: two torus solutions whose meshes separate
    (mesh 1 for 26% and 28% of the torus), one stable, one unstable. Hill's method
    samples the contact indicator on the AFT grid: from orders (8, 8) to (12, 12) its
    growth per turn moves by up to 2.3e-4 here (the Floquet verdict's, with the contact
    switches located along the line, by < 5e-5); every growth per turn of the Floquet
    verdict matches Hill's within ``GROWTH_TOL``."""
    system = two_mesh_system(amp=amp, backlash=0.45)
    problem, X = solve(system, 8, omega)
    r = gj.mesh_responses(problem, X, jnp.asarray(omega), gj.static_mesh_forces(system))
    assert float(np.max(r.separation)) > 0.2  # the backlash is in play
    floquet, fl_stable = per_turn_floquet(problem, X, omega)
    hill8, hill_stable = per_turn_hill(problem, X, omega)
    print(f"\nomega {omega}: separation {np.asarray(r.separation)}, Floquet {floquet}, "
          f"Hill {hill8}, Floquet - Hill {floquet - hill8}")
    np.testing.assert_allclose(floquet, hill8, atol=GROWTH_TOL)
    assert fl_stable == hill_stable == stable


@pytest.mark.slow
def test_integration_follows_the_verdict_linear():
    """From the state of the torus solution at t = 0 (its series and derivative along the
    line), 400 turns of the base angle (166 cycles of the slow beat ``(sqrt 2 - 1)
    Omega``) at rtol 1e-10, and from the same state kicked by 1e-3: the difference of
    the two is the variational solution (the system is linear), whose growth per turn
    (a straight-line fit of its log over turns 20..400) is the largest characteristic
    multiplier's modulus.

    - 1.5 rad/s, marked stable (growth 0.981 per turn, near the tongue): the
      integration stays within 1e-5 of the RMS deflection of the solution all along the
      line; the kick decays at Hill's rate within 1e-4 and the verdict's within
      ``GROWTH_TOL``.
    - 1.3 rad/s, marked unstable (1.067 per turn): the integration leaves the solution
      (the deviation grows past the RMS deflection) at Hill's rate within 1e-4 and the
      verdict's within ``GROWTH_TOL``."""
    system = two_mesh_system()
    turns, per_turn = 400, 16
    cases, starts = [], []
    for omega in (1.5, 1.3):
        problem, X = solve(system, 8, omega)
        t = 2 * np.pi * np.arange(turns * per_turn + 1) / per_turn / omega
        x, v = on_line(problem.basis, X, omega, t)
        kick = 1e-3 * np.max(np.abs(x[0])) * np.array([1.0, -1.0])
        starts += [(omega, x[0], v[0]), (omega, x[0] + kick, v[0])]
        floquet, fl_stable = per_turn_floquet(problem, X, omega)
        hill_growth, _ = per_turn_hill(problem, X, omega)
        cases.append((omega, x, floquet[-1], fl_stable, hill_growth[-1]))
    xs, _ = integrate_from(system, starts, turns, per_turn)
    W = np.asarray(system.W)
    for j, (omega, x, fl_max, fl_stable, hill_max) in enumerate(cases):
        scale = np.max(np.std(x @ W.T, axis=0))
        off = per_turn_max(np.max(np.abs((xs[2 * j] - x) @ W.T), axis=1) / scale, per_turn)
        kick = per_turn_max(np.max(np.abs((xs[2 * j + 1] - xs[2 * j]) @ W.T), axis=1), per_turn)
        n = np.arange(20, turns)
        rate = float(np.exp(np.polyfit(n, np.log(kick[n]), 1)[0]))
        print(f"\nomega {omega}: verdict {fl_max:.6f} ({'stable' if fl_stable else 'unstable'})"
              f", Hill {hill_max:.6f}, integration {rate:.6f} per turn; off the solution "
              f"at most {off.max():.2e} of its RMS deflection")
        assert abs(rate - hill_max) < 1e-4
        assert abs(rate - fl_max) < GROWTH_TOL
        if fl_stable:
            assert off.max() < 1e-5
        else:
            assert off[:10].max() < 1e-5 and off.max() > 1.0


@pytest.mark.parametrize("amp, omega, stable", [((0.4, 0.3), 1.3, True),
                                                 ((0.25, 0.2), 1.1, False)])
def test_integration_follows_the_verdict_backlash(amp, omega, stable):
    """The two separating torus solutions of the backlash test, integrated from their
    state at t = 0 over 200 turns (83 slow beats), 32 samples a turn. The balance's
    truncation at orders (8, 8) puts the integration about 4e-4 (stable case) and 1.2e-3
    (unstable case) of the RMS deflection off the solution over the first turn. Marked
    stable: the integration stays within 1e-3 of it all along the line. Marked unstable:
    it leaves (the deviation passes 30% of the RMS deflection), and while the deviation
    is small (5e-3 to 5e-2 of it: the linear range, above the truncation) it grows at the
    verdict's rate within 15% of the exponent."""
    system = two_mesh_system(amp=amp, backlash=0.45)
    problem, X = solve(system, 8, omega)
    floquet, fl_stable = per_turn_floquet(problem, X, omega)
    assert fl_stable == stable
    turns, per_turn = 200, 32
    t = 2 * np.pi * np.arange(turns * per_turn + 1) / per_turn / omega
    x, v = on_line(problem.basis, X, omega, t)
    xs, _ = integrate_from(system, [(omega, x[0], v[0])], turns, per_turn)
    W = np.asarray(system.W)
    scale = np.max(np.std(x @ W.T, axis=0))
    off = per_turn_max(np.max(np.abs((xs[0] - x) @ W.T), axis=1) / scale, per_turn)
    print(f"\nomega {omega}: verdict {floquet[-1]:.5f}; off the solution: first turn "
          f"{off[0]:.2e}, at most {off.max():.2e} of its RMS deflection")
    if stable:
        assert off.max() < 1e-3
        return
    assert off[0] < 3e-3 and off.max() > 0.3
    n = np.nonzero((off > 5e-3) & (off < 5e-2))[0]
    assert n.size >= 4
    rate = float(np.exp(np.polyfit(n, np.log(off[n]), 1)[0]))
    print(f"growth over turns {n[0]}..{n[-1]}: {rate:.4f} per turn")
    assert abs(np.log(rate) / np.log(floquet[-1]) - 1) < 0.15


@pytest.mark.slow
def test_drift_of_the_near_return():
    """Item 5(c): the verdict's growth per turn at the drift bound ``RETURN_DRIFT = 0.02``
    (q = 29 turns, drift 0.012) against a bound of 0.001 (q = 408 turns, drift 8.7e-4),
    on the unstable linear case (1.3 rad/s) and the stable one near the tongue (1.5).

    Measured: the largest growth per turn moves by 3.7e-4 (1.3) and 2.5e-4 (1.5) from
    drift 0.02 to 0.001, and at 0.001 it matches Hill's within 2e-5 (the integration's
    rate in ``test_integration_follows_the_verdict_linear`` matches Hill's within 1e-5):
    the closure error at 0.02 is a few 1e-4 per turn, so a verdict with ``|mu| - 1``
    within ~1e-3 of zero is not decided by it. The smaller bound does not fix the
    subdominant multipliers: over q = 408 turns ``(|mu_max| / |mu_min|)^q`` exceeds
    1e16 and their moduli are lost to round-off (printed, not asserted)."""
    system = two_mesh_system()
    original = _floquet.return_turns
    fine = functools.partial(original, drift=0.001, max_turns=1024)
    rates = (1.0, ROOT2)
    assert original(rates) == (29, pytest.approx(0.0122, abs=1e-4))
    assert fine(rates) == (408, pytest.approx(8.67e-4, abs=1e-6))
    for omega in (1.3, 1.5):
        problem, X = solve(system, 6, omega)
        coarse, _ = per_turn_floquet(problem, X, omega)
        hill_growth, _ = per_turn_hill(problem, X, omega)
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(_floquet, "return_turns", fine)
            mp.setattr(_verdict, "return_turns", fine)
            st = gj.stability(problem, X, jnp.asarray(omega))  # not the jitted one: new q
        small = np.sort(np.abs(np.asarray(st.multipliers)))
        print(f"\nomega {omega}: drift 0.02 {coarse}, drift 0.001 {small}, Hill {hill_growth};"
              f" largest: 0.02 - 0.001 = {coarse[-1] - small[-1]:.2e}, 0.001 - Hill = "
              f"{small[-1] - hill_growth[-1]:.2e}")
        assert abs(small[-1] - hill_growth[-1]) < 2e-5
        assert abs(coarse[-1] - small[-1]) < GROWTH_TOL


# ------------------------------------------------------------------- a rational torus (9/7)


def periodic_twin(system, mu):
    """``system`` (one mesh and one forcing column on each of two angles, ratio
    ``mu[1] / mu[0]``) as a periodic system on the common base ``Omega / mu[0]``: mesh and
    forcing multipliers ``mu``, one angle."""
    return dataclasses.replace(system, mesh_mu=tuple(mu), mesh_angle=(), forcing_mu=tuple(mu),
                               forcing_angle=(), angle_ratio=(1.0,))


def on_periodic_basis(basis, X, mu, K):
    """The torus solution ``X`` restricted to the line ``theta = (mu_0, mu_1) tau`` (``tau``
    the phase of the common base), as coefficients ``(2K+1, n)`` of harmonics of ``tau``:
    wave vector ``k`` is harmonic ``j = k . mu`` (its sine changes sign where ``j < 0``;
    ``j = 0`` joins the mean). Exact: raises where some ``|j| > K``."""
    X = np.asarray(X)
    out = np.zeros((2 * K + 1, X.shape[1]))
    out[0] = X[0]
    for i, j in enumerate(np.asarray(basis.orders) @ np.asarray(mu)):
        a, b = X[2 * i + 1], X[2 * i + 2]
        if j == 0:
            out[0] += a
            continue
        if abs(j) > K:
            raise ValueError(f"wave vector {basis.orders[i]} is harmonic {j} > K = {K}")
        out[2 * abs(j) - 1] += a
        out[2 * abs(j)] += np.sign(j) * b
    return out


@pytest.mark.slow
@pytest.mark.parametrize("backlash, amp, omegas, rtol", [
    (0.0, (0.0, 0.0), (0.8, 1.3), 1e-2),
    (0.45, (0.4, 0.3), (1.1, 1.3), 2e-2)])
def test_rational_torus_is_the_periodic_response(backlash, amp, omegas, rtol):
    """A G = 2 torus of ratio 9/7 (mesh 1 and forcing column 1 on angle 0, mesh 2 and
    column 2 on angle 1) against the same system as one angle with mu = (7, 9) on the
    base ``Omega / 7``. The torus balance at orders (8, 8), restricted to the line
    (:func:`on_periodic_basis`: harmonics up to 72), against the periodic balance at K = 72
    (>= H max(mu) = 9) from its own linear guess, and against the periodic time
    integration from the static contact state (``gj.simulate`` to a 1e-6 repetition,
    2048 samples a period): RMS and mean mesh forces within 1% (linear) and 2% (with
    backlash: points with contact loss on a stable branch, off the jumps); measured
    below 1e-4. The line's deflection history matches the periodic balance's within 1e-3
    of its RMS."""
    mu = (7, 9)
    torus = two_mesh_system(ratio=mu[1] / mu[0], amp=amp, backlash=backlash)
    periodic = periodic_twin(torus, mu)
    F_static = gj.static_mesh_forces(torus)
    K = 8
    Kp = K * max(mu)
    pp = _hb.hb_problem(periodic, _hb.HarmonicBalance(n_harmonics=Kp))
    settings = gj.TimeDomain(n_samples=2048, max_periods=300)
    tr = gj.simulate_points(periodic, jnp.asarray(omegas) / mu[0], settings=settings)
    assert np.all(np.asarray(tr.periodic))
    for i, omega in enumerate(omegas):
        problem, X = solve(torus, K, omega)
        assert per_turn_floquet(problem, X, omega)[1]
        wp = jnp.asarray(omega / mu[0])
        line = jnp.asarray(on_periodic_basis(problem.basis, X, mu, Kp))
        r_line = gj.mesh_responses(pp, line, wp, F_static)
        sol = newton_jit(pp, wp, _hb.linear_guess(pp, wp))
        assert bool(sol.result == gj.RESULTS.successful)
        r_hb = gj.mesh_responses(pp, sol.X, wp, F_static)
        r_td = gj.responses_from_samples(tr.p[i], tr.F[i], periodic.backlash, F_static,
                                         periodic.mesh_radius)
        print(f"\nomega {omega}: RMS line {np.asarray(r_line.rms_force)}, periodic balance "
              f"{np.asarray(r_hb.rms_force)}, integration {np.asarray(r_td.rms_force)}; "
              f"separation {np.asarray(r_line.separation)}")
        if backlash:
            assert float(np.max(r_line.separation)) > 0.05
        for ref in (r_hb, r_td):
            np.testing.assert_allclose(r_line.rms_force, ref.rms_force, rtol=rtol)
            np.testing.assert_allclose(r_line.mean_force, ref.mean_force, rtol=rtol)
        p_line = _aft.synthesis(line @ periodic.W.T, 4 * Kp)
        p_hb = _aft.synthesis(sol.X @ periodic.W.T, 4 * Kp)
        assert float(jnp.max(jnp.abs(p_line - p_hb))) < 1e-3 * float(jnp.max(jnp.std(p_hb, 0)))
