"""Matrix-free solves (``krylov``) against the structured Jacobian and the condensed
factorisation, on the paper gear with tooth separation and on a two-group torus."""

import dataclasses
import warnings

import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import pytest

import gearjax as gj
from gearjax._engine import adjoint as _adjoint
from gearjax._engine import bordered as _bordered
from gearjax._engine import continuation as C
from gearjax._engine import hb as _hb
from gearjax._engine import krylov as _krylov
from gearjax._engine import linear_solver as _ls
from gearjax._engine import newton as _newton
from gearjax._studies import harmonics as _harmonics

OMEGA = 2 * np.pi * 3500.0 / 7  # stage-1 mesh at 3.5 kHz: teeth separate at K = 8


def _separated_point(problem, omega):
    """A converged point where some mesh samples lie inside the backlash gap."""
    sol = _newton.solve_hb(problem, omega)
    assert bool(sol.converged)
    p = _hb.mesh_samples(problem, sol.X @ problem.system.W.T, omega)[0]
    assert np.any(np.abs(np.asarray(p)) < np.asarray(problem.system.backlash)[:, None])
    return sol.y


@pytest.fixture(scope="module")
def paper(paper_system_h1):
    problem = _hb.hb_problem(paper_system_h1, _hb.HarmonicBalance(n_harmonics=8))
    return problem, _separated_point(problem, OMEGA)


@pytest.fixture(scope="module")
def torus(torus_h1_train):
    system = gj.gear_case(torus_h1_train, torus=True).system
    problem = _hb.hb_problem(system, _harmonics.settings_for(system, (2, 2)))
    omega = 2 * np.pi * 3000.0 / system.mesh_mu[0]
    return problem, _newton.solve_hb(problem, omega).y, omega


def test_jacobian_product_is_the_structured_jacobian(paper, torus):
    """``J v`` from the mesh slopes equals the assembled exact Jacobian times ``v``, with
    tooth separation (periodic) and on a 2-torus."""
    rng = np.random.default_rng(0)
    for problem, y, omega in [(*paper, OMEGA), torus]:
        v = jnp.asarray(rng.normal(size=y.size))
        J = _hb.jacobian(problem, y, omega)
        Jv = _krylov.jacobian_product(_krylov.slopes(problem, y, omega), v)
        np.testing.assert_allclose(Jv, J @ v, atol=1e-12 * float(jnp.max(jnp.abs(J @ v))))


def test_pair_preconditioner_inverts_a_time_invariant_gear(paper_system_h1):
    """With constant mesh stiffness and no backlash the Jacobian is the time-invariant
    one the preconditioner inverts pair by pair: ``B^-1 J = I`` to round-off, and its
    transpose ``J^T B^-T = I``."""
    s = paper_system_h1
    lti = dataclasses.replace(s, k_cos=jnp.zeros_like(s.k_cos), k_sin=jnp.zeros_like(s.k_sin),
                              backlash=jnp.zeros_like(s.backlash))
    problem = _hb.hb_problem(lti, _hb.HarmonicBalance(n_harmonics=8))
    y = _hb.linear_guess(problem, OMEGA)
    J = _hb.jacobian(problem, y, OMEGA)
    B = _krylov.pair_preconditioner(_krylov.slopes(problem, y, OMEGA))
    eye = np.eye(y.size)
    np.testing.assert_allclose(B.as_matrix() @ J, eye, atol=1e-9)
    np.testing.assert_allclose(J.T @ B.transpose().as_matrix(), eye, atol=1e-9)


def test_krylov_solves_agree_with_the_condensed_factorisation(paper):
    """``J x = b`` and ``J^T x = b`` by BiCGStab equal the condensed LU's solutions."""
    problem, y = paper
    b = jnp.asarray(np.random.default_rng(1).normal(size=y.size))
    J = _ls.HBJacobian(problem, y, jnp.asarray(OMEGA))
    for operator in (J, J.transpose()):
        exact = lx.linear_solve(operator, b, _ls.CondensedLU()).value
        sol = lx.linear_solve(operator, b, _krylov.KrylovHB(), throw=False)
        assert sol.result == lx.RESULTS.successful
        assert int(sol.stats["num_steps"]) < _krylov.STEP_BOUND
        np.testing.assert_allclose(sol.value, exact, atol=1e-8 * float(jnp.max(jnp.abs(exact))))


def test_bordered_krylov_solve_agrees_with_the_bordered_factorisation(paper):
    problem, y = paper
    rng = np.random.default_rng(2)
    g, ty = _hb.omega_derivative(problem, y, OMEGA), jnp.asarray(rng.normal(size=y.size))
    rhs = jnp.asarray(rng.normal(size=y.size + 1))
    exact = _bordered.solve(_bordered.factor(problem, y, OMEGA, g, ty, 0.3), rhs)
    x = _krylov.solve(_krylov.factor(problem, y, OMEGA, g, ty, 0.3), rhs)
    np.testing.assert_allclose(x, exact, atol=1e-8 * float(jnp.max(jnp.abs(exact))))


def test_newton_krylov_converges_to_the_factorised_newton_point(paper_system_h1, torus):
    """Newton with either linear solver reaches the same point (periodic with tooth
    separation; 2-torus)."""
    problem_t, _, omega_t = torus
    cases = [(_hb.hb_problem(paper_system_h1, _hb.HarmonicBalance(n_harmonics=8)), OMEGA),
             (problem_t, omega_t)]
    for problem, omega in cases:
        points = []
        for solver in ("lu", "krylov"):
            p = dataclasses.replace(problem, settings=dataclasses.replace(
                problem.settings, linear_solver=solver))
            sol = _newton.solve_hb(p, omega)
            assert bool(sol.converged)
            points.append(np.asarray(sol.X))
        np.testing.assert_allclose(points[1], points[0], atol=1e-9 * np.max(np.abs(points[0])))


def test_implicit_derivative_is_the_same_with_either_solver(paper):
    """The implicit derivative (adjoint: a transposed solve) of a mesh force's mean with
    respect to the frequency, through BiCGStab and through the LU."""
    problem, y = paper

    def mean_deflection(omega, solver):
        p = dataclasses.replace(problem, settings=dataclasses.replace(
            problem.settings, linear_solver=solver))
        X = _adjoint.implicit_coefficients(p, y, omega)
        return jnp.sum((X[1:] @ problem.system.W.T) ** 2)

    grads = [float(jax.grad(mean_deflection)(jnp.asarray(OMEGA), s)) for s in ("lu", "krylov")]
    assert grads[0] != 0.0
    assert abs(grads[1] - grads[0]) <= 1e-7 * abs(grads[0])


def test_continuation_with_matrix_free_solves_follows_the_same_branch(paper_system_h1):
    """The paper gear (one stiffness harmonic, K = 8) with tooth separation from 3 kHz,
    60 points through folds: the same points (within 1 mHz), corrector iterations and
    folds (within 0.01 Hz) with the bordered system solved by BiCGStab as by the condensed LU."""
    f0 = 3000.0
    omega_ref = jnp.asarray(2 * np.pi * f0 / 7)
    out = []
    for solver in ("lu", "krylov"):
        problem = _hb.hb_problem(paper_system_h1,
                                 _hb.HarmonicBalance(n_harmonics=8, linear_solver=solver))
        param = C.FrequencyParameter(problem=problem, omega_ref=omega_ref)
        y0 = _newton.solve_hb(problem, omega_ref).y
        factors = param.factor(y0, 1.0, jnp.zeros_like(y0), 1.0)
        assert isinstance(factors, _krylov.KrylovFactors) == (solver == "krylov")
        out.append(C.continue_branch(param, y0, 1.0, 1.2, C.Settings(), max_points=60))
    lu, kr = out
    assert len(kr.lam) == len(lu.lam) == 60
    np.testing.assert_allclose(kr.lam * f0, lu.lam * f0, atol=1e-3)
    # corrector iterations: the same but where an inexact solve tips a count by one
    assert np.max(np.abs(kr.steps - lu.steps)) <= 1
    assert abs(int(np.sum(kr.steps)) - int(np.sum(lu.steps))) <= 0.02 * np.sum(lu.steps)
    folds = [C.distinct_folds(b.fold_lam[b.fold]) * f0 for b in out]
    assert len(folds[0]) > 0 and len(folds[1]) == len(folds[0])
    np.testing.assert_allclose(folds[1], folds[0], atol=0.01)


def test_the_solver_is_chosen_from_the_problems_size(paper_system):
    """``"auto"``: the LU where one factorisation costs less than the Krylov bound, BiCGStab
    past it, decided from shapes alone; ``"lu"`` and ``"krylov"`` force either; anything
    else is refused."""
    def problem(K, solver="auto"):
        return _hb.hb_problem(paper_system, _hb.HarmonicBalance(n_harmonics=K,
                                                                linear_solver=solver))

    assert not _krylov.uses_krylov(problem(32))
    assert _krylov.uses_krylov(problem(128))
    # the crossover is where the flop counts say, not a fixed size
    C_, n, r, m, T = 257, 14, 10, paper_system.n_meshes, problem(128).n_time
    assert _krylov.lu_flops(C_, r) > _krylov.STEP_BOUND * _krylov.step_flops(C_, n, m, T)
    assert _krylov.uses_krylov(problem(32, "krylov"))
    assert not _krylov.uses_krylov(problem(128, "lu"))
    with pytest.raises(ValueError, match="linear_solver = 'cholesky': one of 'auto', 'lu'"):
        problem(32, "cholesky")


def test_truncation_checks_past_the_factorisation_bound_are_matrix_free():
    """The G = 3 train's check at doubled orders (21,074 unknowns: refused by the LU's
    bound) is affordable matrix-free, judged on its memory."""
    import pathlib

    train = gj.load_train(pathlib.Path(__file__).parents[1] / "data"
                          / "three_stage_incommensurate.toml")
    system = gj.gear_case(train, torus=True).system
    K2 = _harmonics.widened((8, 6, 12), 0)
    assert _harmonics.factor_unknowns(system, K2) > _harmonics.MAX_CHECK_UNKNOWNS
    assert _harmonics.solves_by_krylov(system, K2)
    assert _harmonics.check_affordable(system, (8, 6, 12), 0) is None
    assert _harmonics.krylov_memory_bytes(system, K2) < _harmonics.memory_bytes(system, K2) / 5


def test_a_solve_the_preconditioner_cannot_carry_falls_back_to_the_factorisation():
    """tests/data/three_stage.toml at 1 kHz (K = 64): its stiffness variation couples the
    harmonics so strongly that BiCGStab from the time-invariant preconditioner breaks
    down (forced, it says so in its result); the default's solver then solves with the
    condensed LU at the same point, and Newton converges as with the LU."""
    import math
    import pathlib

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gj.GeometryWarning)
        train = gj.load_train(pathlib.Path(__file__).parents[1] / "data" / "three_stage.toml")
    system = gj.assemble(train)
    system = dataclasses.replace(system, backlash=jnp.zeros_like(system.backlash))
    problem = _hb.hb_problem(system, _hb.HarmonicBalance(n_harmonics=64))
    assert _krylov.uses_krylov(problem)
    omega = jnp.asarray(2 * math.pi * 1000.0 / 7)
    y = _hb.linear_guess(problem, omega)
    b = jnp.asarray(np.random.default_rng(3).normal(size=y.size))
    J = _ls.HBJacobian(problem, y, omega)
    exact = lx.linear_solve(J, b, _ls.CondensedLU()).value
    forced = lx.linear_solve(J, b, _krylov.KrylovHB(), throw=False)
    assert forced.result != lx.RESULTS.successful
    sol = lx.linear_solve(J, b, _krylov.linear_solver(problem), throw=False)
    assert sol.result == lx.RESULTS.successful and bool(sol.stats["fallback"])
    np.testing.assert_allclose(sol.value, exact, atol=1e-10 * float(jnp.max(jnp.abs(exact))))
    assert bool(_newton.solve_hb(problem, omega).converged)
