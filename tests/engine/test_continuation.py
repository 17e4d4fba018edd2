"""Pseudo-arclength continuation through the folds of the clearance oscillator."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gearjax as gj
from gearjax._engine import aft as _aft
from gearjax._engine import bordered as _bordered
from gearjax._engine import continuation as C
from gearjax._engine import corrector as _corrector
from gearjax._engine import hb as _hb
from gearjax._engine import newton as _newton
from gearjax._engine.results import RESULTS

from clearance_oscillator import ivp_amplitude, oscillator

K, T = 15, 256


@pytest.fixture(scope="module")
def branch():
    problem = _hb.hb_problem(oscillator(), _hb.HarmonicBalance(n_harmonics=K, n_time=T))
    param = C.FrequencyParameter(problem=problem, omega_ref=jnp.asarray(1.0))
    settings = C.Settings(step=0.05, max_step=0.3, max_dlambda=0.02)
    y0 = _newton.solve_hb(problem, 0.5).y
    b = jax.jit(lambda y: C.continue_compiled(param, y, 0.5, 1.5, settings, 400))(y0)
    ys, lams, folds, fold_lams, n, code = b.y, b.lam, b.fold, b.fold_lam, b.n_points, b.result
    n = int(n)
    X = np.asarray(ys[:n]).reshape(n, 2 * K + 1, 1) * np.asarray(problem.x_scale)
    x = np.asarray(jax.vmap(lambda c: _aft.synthesis(c, T))(jnp.asarray(X)))[..., 0]
    return {"lam": np.asarray(lams[:n]), "amp": (x.max(1) - x.min(1)) / 2, "code": code,
            "folds": C.distinct_folds(np.asarray(fold_lams[:n])[np.asarray(folds[:n])]),
            "problem": problem, "param": param, "settings": settings, "y0": y0}


def test_reaches_the_end_through_both_folds(branch):
    assert bool(branch["code"] == RESULTS.reached_end)
    assert branch["lam"][-1] >= 1.5
    # pyHarm and NLvib put the folds near 0.852 and 0.6365
    folds = np.sort(branch["folds"])
    assert len(folds) == 2
    np.testing.assert_allclose(folds, [0.6365, 0.852], atol=2e-3)
    # the branch crosses Omega = 0.75 three times: lower, unstable middle, upper
    crossings = np.sum(np.diff(np.sign(branch["lam"] - 0.75)) != 0)
    assert crossings == 3
    assert branch["amp"].max() == pytest.approx(0.4328, abs=2e-3)


def test_coexisting_branches_match_time_integration(branch):
    lam, amp = branch["lam"], branch["amp"]
    near = np.where(np.diff(np.sign(lam - 0.75)) != 0)[0]
    # amplitude where each segment crosses 0.75, interpolated linearly along the branch
    hb_amps = sorted(amp[i] + (0.75 - lam[i]) / (lam[i + 1] - lam[i]) * (amp[i + 1] - amp[i])
                     for i in near)
    low_ref = ivp_amplitude(0.75, [1.1, 0.0])                 # contact start: low branch
    high_ref = ivp_amplitude(0.75, [1.1 + 0.8, 0.0])          # large start: impacting branch
    assert hb_amps[0] == pytest.approx(low_ref, rel=5e-3)
    assert hb_amps[2] == pytest.approx(high_ref, rel=5e-3)
    assert high_ref > 3 * low_ref
    assert low_ref == pytest.approx(abs(0.03 / (1 - 0.75**2 + 0.075j)), rel=1e-6)


def test_python_driver_matches_and_compiles_once_for_any_steps(branch):
    problem, settings = branch["problem"], branch["settings"]
    b1 = C.continue_branch(branch["param"], branch["y0"], 0.5, 0.6, settings, max_points=50)
    programs = [f._cache_size() for f in (C._arclength_step_jit, C.start_jit)]
    # other steps and tolerances are inputs of the same programs (another band of a sweep)
    other = dataclasses.replace(settings, step=0.04, max_step=0.25, max_dlambda=0.015,
                                rtol=2e-9, fold_step=2e-3, min_step=1e-8)
    b2 = C.continue_branch(branch["param"], _newton.solve_hb(problem, 0.55).y, 0.55, 0.62, other,
                           max_points=50)
    assert [f._cache_size() for f in (C._arclength_step_jit, C.start_jit)] == programs
    assert bool(b1.result == RESULTS.reached_end) and bool(b2.result == RESULTS.reached_end)
    # on the contact branch the response is linear: first harmonic 0.03 / (1 - w^2 + 0.1 i w)
    w = b1.omega[-1]
    X1 = b1.y[-1].reshape(2 * K + 1, 1)[1:3, 0] * float(problem.x_scale[0])
    assert np.hypot(*X1) == pytest.approx(abs(0.03 / (1 - w**2 + 0.1j * w)), rel=1e-9)


def test_compiled_and_python_continuations_give_the_same_branch(branch):
    param, settings, y0 = branch["param"], branch["settings"], branch["y0"]
    padded = C.continue_compiled(param, y0, 0.5, 0.6, settings, 50)
    assert padded.lam.shape == (50,) and bool(jnp.isnan(padded.lam[-1]))
    compiled = padded.trimmed()
    python = C.continue_branch(param, y0, 0.5, 0.6, settings, max_points=50)
    assert compiled.n_points == python.n_points == len(python.lam) > 2
    assert bool(compiled.result == python.result == RESULTS.reached_end)
    for field in ("lam", "omega", "y", "tangent", "h", "fold_lam"):
        np.testing.assert_allclose(getattr(compiled, field), getattr(python, field),
                                   rtol=1e-9, atol=1e-12, err_msg=field)
    np.testing.assert_array_equal(compiled.steps, python.steps)
    np.testing.assert_array_equal(compiled.fold, python.fold)


def test_stops_with_reason_and_keeps_points(branch):
    settings = C.Settings(step=0.05, max_step=0.3, max_dlambda=0.02)
    b = C.continue_branch(branch["param"], branch["y0"], 0.5, 1.5, settings, max_points=5)
    assert bool(b.result == RESULTS.max_points) and len(b.lam) == 5 and np.all(np.isfinite(b.y))


class _Circle(C.AbstractParameter):
    """``y^2 + (lambda - 1)^2 = 1/4``: a closed solution curve (an isola), one unknown."""

    problem: _hb.HBProblem

    def split(self, lam):
        return self.problem, lam

    def residual(self, y, lam):
        return y**2 + (lam - 1.0) ** 2 - 0.25

    def jacobian(self, y, lam):
        return jnp.diag(2 * y)

    def d_lambda(self, y, lam):
        return 2 * (lam - 1.0) * jnp.ones_like(y)


def test_closed_loop_stops_after_one_turn():
    problem = _hb.hb_problem(oscillator(), _hb.HarmonicBalance(n_harmonics=1, n_time=8))
    settings = C.Settings(step=0.05, max_step=0.05, max_dlambda=0.05, fold_step=0.05)
    br = C.continue_branch(_Circle(problem=problem), jnp.asarray([0.5]), 1.0, 3.0, settings,
                           max_points=2000)
    assert bool(br.result == RESULTS.closed_loop)
    # one turn of the circle (length pi) in chords of about 0.05, plus the closing stretch
    turn = np.pi / 0.05
    assert turn < len(br.lam) < 1.5 * turn
    np.testing.assert_allclose(br.y[:, 0] ** 2 + (br.lam - 1) ** 2, 0.25, atol=1e-8)


def test_branch_through_folds_is_not_a_loop(branch):
    """The oscillator's branch turns back twice, close to itself: not a closed loop."""
    br = C.continue_branch(branch["param"], branch["y0"], 0.5, 1.5, branch["settings"], 400)
    assert bool(br.result == RESULTS.reached_end)
    assert len(C.distinct_folds(br.fold_lam[br.fold])) == 2


def test_broyden_step_learns_a_rank_one_jacobian_error():
    """Broyden's method on a linear system whose starting matrix is off by a rank-one term
    ends in at most two steps (Gay, SIAM J. Numer. Anal. 16 (1979): at most 2r for rank
    r), where the chord iteration with that matrix only contracts linearly (0.6 here)."""
    rng = np.random.default_rng(3)
    n = 40
    A = np.eye(n) + 0.1 * rng.standard_normal((n, n))
    u, v = rng.standard_normal(n), rng.standard_normal(n)
    B0 = A + 0.6 * np.outer(u, v) / (v @ np.linalg.solve(A, u))  # chord ratio 0.6 / 1.6
    b = rng.standard_normal(n)
    exact = np.linalg.solve(A, b)
    solve = jax.jit(lambda z, steps, i: _corrector.broyden_step(z, steps, i))

    def run(quasi, iterations):
        z, steps = np.zeros(n), jnp.zeros((8, n))
        for i in range(iterations):
            d = -np.linalg.solve(B0, A @ z - b)
            if quasi:
                d = np.asarray(solve(jnp.asarray(d), steps, i))
                steps = steps.at[i].set(d)
            z = z + d
        return np.max(np.abs(z - exact)) / np.max(np.abs(exact))

    assert run(True, 3) < 1e-12
    assert run(False, 3) > 1e-2 and run(False, 30) < 1e-10


def test_single_precision_factors(paper_system_h1):
    """``Settings.single``: the bordered LU in single precision. On the paper gear with
    tooth separation, solves with those factors are a close preconditioner (relative
    error far below the corrector's contraction from Jacobian changes) and the refined
    tangent equals the one from double factors. (The paper sweeps in test_sweep run with
    single factors end to end.)"""
    problem = _hb.hb_problem(paper_system_h1, _hb.HarmonicBalance(n_harmonics=8))
    omega_ref = 2 * np.pi * 2000.0 / 7
    param = C.FrequencyParameter(problem=problem, omega_ref=jnp.asarray(omega_ref))
    lam = 3500.0 / 2000.0  # 6% of the mesh samples separated at K = 8
    sol = _newton.solve_hb(problem, lam * omega_ref)
    assert bool(sol.converged)
    deflection = _hb.mesh_samples(problem, sol.X @ paper_system_h1.W.T, lam * omega_ref)[0]
    assert np.any(np.abs(np.asarray(deflection)) < np.asarray(paper_system_h1.backlash)[:, None])
    rng = np.random.default_rng(0)
    ty0, tlam0 = jnp.asarray(rng.normal(size=sol.y.size)), 1.0
    rhs = jnp.asarray(rng.normal(size=sol.y.size + 1))

    @jax.jit
    def tangents_and_solves(y):
        out = []
        for single in (False, True):
            # NaN where the refinement would not converge: it must
            ty, tlam, factors = C.tangent_factors(param, y, lam, ty0, tlam0, single,
                                                  fallback=jnp.full(y.size + 1, jnp.nan))
            out.append((jnp.append(ty, tlam), _bordered.solve(factors, rhs), factors.lu))
        return out

    (t_double, x_double, lu_double), (t_single, x_single, lu_single) = tangents_and_solves(
        sol.y)
    assert lu_double.dtype == jnp.float64 and lu_single.dtype == jnp.float32
    np.testing.assert_allclose(t_single, t_double, atol=1e-10)
    error = float(jnp.linalg.norm(x_single - x_double) / jnp.linalg.norm(x_double))
    assert 1e-12 < error < 1e-3  # single-precision solves: not exact, and close


def _walk(param, state, settings, lam_end, attempts=1000):
    """Accepted states of ``arclength_step`` from ``state`` until ``lam_end``."""
    states = [state]
    for _ in range(attempts):
        if float(state.lam) >= lam_end:
            break
        state = C._arclength_step_jit(param, state, settings)
        if bool(state.accepted):
            states.append(state)
    return states


def test_reused_factors_follow_the_same_branch(branch):
    """``Settings.reuse``: the same branch through both folds (folds within the fold
    step of those factorised at every point, and of pyHarm's), most points without a
    factorisation of their own, and every point on the branch (residual at the
    corrector's tolerance)."""
    param, y0 = branch["param"], branch["y0"]
    settings = C.Settings(step=0.05, max_step=0.3, max_dlambda=0.02, reuse=True)
    states = _walk(param, C.start_jit(param, y0, 0.5, 1.0, settings), settings, 1.5)
    folds = C.distinct_folds(np.array([float(s.fold_lam) for s in states if bool(s.fold)]))
    np.testing.assert_allclose(folds, branch["folds"], atol=settings.fold_step)
    np.testing.assert_allclose(folds, [0.6365, 0.852], atol=2e-3)
    ages = np.array([int(s.age) for s in states])
    assert np.sum(ages == 0) < 0.8 * len(states) and ages.max() > 1
    residual = jax.jit(lambda y, lam: param.residual(y, lam))
    assert max(float(jnp.max(jnp.abs(residual(s.y, s.lam)))) for s in states) < 1e-4


def _stale_at(branch, lam_end):
    """``(param, settings, states, stale)``: the oscillator's branch with kept factors
    from 0.5 to ``lam_end`` (its accepted states), and its last state with the start's
    factors in place of its own."""
    param = branch["param"]
    settings = C.Settings(step=0.05, max_step=0.3, max_dlambda=0.02, reuse=True)
    first = C.start_jit(param, branch["y0"], 0.5, 1.0, settings)
    states = _walk(param, first, settings, lam_end)
    stale = dataclasses.replace(states[-1], factors=first.factors,
                                age=jnp.asarray(len(states) - 1), own=jnp.asarray(False))
    return param, settings, states, stale


def test_stale_factors_that_fail_are_replaced_at_the_last_point(branch):
    """Factors from the branch's start (lambda 0.5, the contact branch) do not carry the
    corrector on the impacting branch at 0.84: the step factorises at the last point
    (``own``: last row its own tangent) and corrects again, and the continuation goes on
    from those factors through both folds."""
    param, settings, _, stale = _stale_at(branch, 0.84)
    new = C._arclength_step_jit(param, stale, settings)
    assert bool(new.own) and int(new.age) == int(new.accepted)
    after = _walk(param, new, settings, 1.5)
    assert float(after[-1].lam) >= 1.5
    np.testing.assert_allclose(C.distinct_folds(np.array(
        [float(s.fold_lam) for s in after if bool(s.fold)])), [0.6365, 0.852], atol=2e-3)


def test_a_resumed_state_has_the_factors_the_continuation_had(branch):
    """``walk.resumed_state`` rebuilds, from saved points alone, the factors each state
    continues from: those of the start, of a later point with the tangent before it in
    the last row, and (after stale factors failed) of a point with its own tangent."""
    from gearjax._studies.sweep.walk import resumed_state

    param, settings, states, stale = _stale_at(branch, 0.84)
    states += _walk(param, stale, settings, 1.0)[1:]
    have = [{"y": np.asarray(s.y), "lam": float(s.lam), "ty": np.asarray(s.ty),
             "tlam": float(s.tlam), "h": float(s.h), "age": int(s.age), "own": bool(s.own)}
            for s in states]
    kinds = {(int(s.age) == i, bool(s.own)) for i, s in enumerate(states)}
    assert {(True, False), (False, False), (False, True)} <= kinds
    for i in range(1, len(have)):
        rebuilt = resumed_state(param, have[:i + 1], settings, 1.0)
        np.testing.assert_array_equal(rebuilt.factors.lu, states[i].factors.lu)
        assert int(rebuilt.age) == have[i]["age"] and bool(rebuilt.own) == have[i]["own"]
