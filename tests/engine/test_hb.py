"""Harmonic balance core: AFT operators, residual, structured Jacobian, Newton."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gearjax as gj
from gearjax._engine import aft as _aft
from gearjax._engine import hb as _hb
from gearjax._engine import newton as _newton


def oscillator(clearance=0.0, c=0.1, k_cos=None, mu=(1,)):
    return gj.system_from_matrices([[1.0]], [[c]], [[0.0]], [[1.0]], [1.0], backlash=[clearance],
                                   k_cos=k_cos, f_mean=[0.1], f_cos=[[0.03]], f_sin=[[0.0]],
                                   forcing_mu=[1], mesh_mu=mu)


def test_aft_round_trip_and_derivative():
    K, T = 6, 32
    X = jax.random.normal(jax.random.PRNGKey(1), (2 * K + 1, 3))
    x = _aft.synthesis(X, T)
    tau = np.asarray(_aft.phases(T))
    k = np.arange(1, K + 1)
    direct = X[0] + np.cos(np.outer(tau, k)) @ X[1::2] + np.sin(np.outer(tau, k)) @ X[2::2]
    np.testing.assert_allclose(x, direct, atol=1e-13)
    np.testing.assert_allclose(_aft.analysis(x, K), X, atol=1e-13)
    dx = -np.sin(np.outer(tau, k)) @ (k[:, None] * X[1::2]) + np.cos(np.outer(tau, k)) @ (
        k[:, None] * X[2::2])
    np.testing.assert_allclose(_aft.synthesis(_aft.derivative(X), T), dx, atol=1e-12)
    np.testing.assert_allclose(_aft.derivative_matrix(K) @ X, _aft.derivative(X), atol=1e-14)


@pytest.mark.parametrize("omega", [0.4, 1.0, 1.7])
def test_linear_time_invariant_limit_is_exact_frequency_response(omega):
    """x'' + 0.1 x' + x = 0.1 + 0.03 cos(w t): mean 0.1, first harmonic 0.03 / (1 - w^2 + 0.1 i w)."""
    problem = _hb.hb_problem(oscillator(), _hb.HarmonicBalance(n_harmonics=4))
    sol = _newton.solve_hb(problem, omega)
    H = 0.03 / (1 - omega**2 + 0.1j * omega)
    assert bool(sol.converged)
    np.testing.assert_allclose(sol.X[:3, 0], [0.1, H.real, -H.imag], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(sol.X[3:, 0], 0.0, atol=1e-15)


def test_paper_linear_time_invariant_limit(paper_system):
    """Paper train with constant stiffness and no backlash: HB equals the complex FRF."""
    lti = eqx_set(paper_system, k_cos=jnp.zeros((paper_system.n_meshes, 0)),
                  k_sin=jnp.zeros((paper_system.n_meshes, 0)),
                  backlash=jnp.zeros_like(paper_system.backlash),
                  f_cos=jnp.zeros((paper_system.n_dof, 1)).at[0].set(10.0),
                  f_sin=jnp.zeros((paper_system.n_dof, 1)), forcing_mu=(1,))
    problem = _hb.hb_problem(lti, _hb.HarmonicBalance(n_harmonics=3))
    omega = 2 * np.pi * 5000.0
    sol = _newton.solve_hb(problem, omega)
    Kt = np.asarray(lti.mean_stiffness())
    Ct = np.asarray(lti.W.T @ (lti.damping[:, None] * lti.W))
    Z = Kt - omega**2 * np.asarray(lti.M) + 1j * omega * Ct
    f = np.zeros(lti.n_dof); f[0] = 10.0
    x1 = np.linalg.solve(Z, f)
    np.testing.assert_allclose(sol.X[0], np.linalg.solve(Kt, np.asarray(lti.f_mean)), rtol=1e-9)
    np.testing.assert_allclose(sol.X[1] - 1j * sol.X[2], x1, rtol=1e-8, atol=1e-12 * np.abs(x1).max())


def test_linear_guess_and_one_factorisation_solve(paper_system):
    """``linear_guess`` (one (2n, 2n) system per harmonic) is the exact response of the
    constant-stiffness train without backlash (the complex FRF of every harmonic);
    ``solve_linear`` (one factorisation) equals Newton on the time-varying train without
    backlash, whose mesh force is linear: ``g' = 1`` also at ``p = 0``."""
    omega = 2 * np.pi * 3000.0 / 7
    lti = eqx_set(paper_system, k_cos=jnp.zeros((paper_system.n_meshes, 0)),
                  k_sin=jnp.zeros((paper_system.n_meshes, 0)),
                  backlash=jnp.zeros_like(paper_system.backlash))
    problem = _hb.hb_problem(lti, _hb.HarmonicBalance(n_harmonics=8))
    X = _hb.linear_guess(problem, omega).reshape(problem.shape) * problem.x_scale
    Kt, M = np.asarray(lti.mean_stiffness()), np.asarray(lti.M)
    Ct = np.asarray(lti.C + lti.W.T @ (lti.damping[:, None] * lti.W))
    F = np.asarray(problem.forcing)
    for k in range(1, 9):
        Z = Kt - (k * omega) ** 2 * M + 1j * k * omega * Ct
        xk = np.linalg.solve(Z, F[2 * k - 1] - 1j * F[2 * k])
        scale = np.abs(xk).max() + 1e-30
        np.testing.assert_allclose(X[2 * k - 1] - 1j * X[2 * k], xk, atol=1e-10 * scale)
    np.testing.assert_allclose(X[0], np.linalg.solve(Kt, F[0]), rtol=1e-10)
    assert float(jax.grad(lambda p: gj.backlash(p, 0.0))(0.0)) == 1.0
    tv = _hb.hb_problem(eqx_set(paper_system, backlash=jnp.zeros_like(paper_system.backlash)),
                        _hb.HarmonicBalance(n_harmonics=32))
    one, ref = _newton.solve_linear(tv, omega), _newton.solve_hb(tv, omega)
    assert bool(one.converged) and int(one.stats["num_steps"]) <= 3
    np.testing.assert_allclose(one.X, ref.X, rtol=0, atol=1e-10 * float(jnp.max(jnp.abs(ref.X))))


def eqx_set(system, **fields):
    return dataclasses.replace(system, **fields)


@pytest.mark.parametrize("n_time", [64, 14])
def test_product_matrix_is_the_aft_of_a_multiplication(n_time):
    """``_aft.product_matrix(a)`` (from one FFT of ``a``) equals the AFT map
    ``X -> analysis(a * synthesis(X))`` column by column, aliasing included (T = 2K + 2);
    ``times_derivative(M)`` equals ``M @ derivative_matrix``."""
    K = 6
    a = jax.random.normal(jax.random.PRNGKey(2), (3, n_time))
    M = _aft.product_matrix(a, K)
    E = jnp.eye(2 * K + 1)
    ref = jnp.stack([_aft.analysis(a[i][:, None] * _aft.synthesis(E, n_time), K) for i in range(3)])
    np.testing.assert_allclose(M, ref, rtol=0, atol=1e-14)
    np.testing.assert_allclose(_aft.times_derivative(M), M @ _aft.derivative_matrix(K),
                               rtol=0, atol=1e-14)


@pytest.mark.parametrize("contact", [False, True])
@pytest.mark.parametrize("n_time", [64, 26])  # 26 = 2K + 10: the backlash's kinks alias
def test_structured_jacobian_equals_jacfwd(paper_system_h1, contact, n_time):
    system = eqx_set(paper_system_h1, contact_damping=contact)
    problem = _hb.hb_problem(system, _hb.HarmonicBalance(n_harmonics=8, n_time=n_time))
    y = _hb.linear_guess(problem, 2 * np.pi * 4000 / 7)
    y = y + 0.5 * jax.random.normal(jax.random.PRNGKey(0), y.shape)  # some meshes separate
    omega = 2 * np.pi * 4000 / 7
    J = _hb.jacobian(problem, y, omega)
    J_ad = jax.jacfwd(lambda v: _hb.residual(problem, v, omega))(y)
    np.testing.assert_allclose(J, J_ad, atol=1e-13 * float(jnp.max(jnp.abs(J_ad))))
    dw = _hb.omega_derivative(problem, y, omega)
    h = 1e-3 * omega
    fd = (_hb.residual(problem, y, omega + h) - _hb.residual(problem, y, omega - h)) / (2 * h)
    np.testing.assert_allclose(dw, fd, atol=1e-6 * float(jnp.max(jnp.abs(dw))))


def test_newton_converges_on_paper_case_with_backlash(paper_system_h1):
    problem = _hb.hb_problem(paper_system_h1, _hb.HarmonicBalance(n_harmonics=16))
    omega = 2 * np.pi * 3000 / 7
    sol = jax.jit(_newton.solve_hb)(problem, omega)
    assert bool(sol.converged) and float(sol.stats["residual_norm"]) < 1e-8
    # mean mesh forces carry the static load: stage-1 sun mesh 8942 N
    P = sol.X @ paper_system_h1.W.T
    assert float(jnp.max(jnp.abs(P[0] - (8942.2 / 4.5e8 + 5e-5)) [:4])) < 2e-6


def test_smoothed_backlash_is_close_odd_and_exact_without_clearance():
    p = jnp.linspace(-3e-4, 3e-4, 601)
    b, s = 1e-4, 1e-2
    g, g0 = gj.backlash(p, b, s), gj.backlash(p, b)
    assert float(jnp.max(jnp.abs(g - g0))) <= s * b / 2 * (1 + 1e-12)
    np.testing.assert_allclose(gj.backlash(-p, b, s), -g, atol=1e-20)
    np.testing.assert_array_equal(gj.backlash(p, 0.0, s), p)
    assert np.all(np.isfinite(jax.vmap(jax.grad(lambda q: gj.backlash(q, 0.0, s)))(p)))


def test_structured_jacobian_with_smoothed_backlash(paper_system_h1):
    problem = _hb.hb_problem(paper_system_h1,
                             _hb.HarmonicBalance(n_harmonics=8, n_time=64, smoothing=0.05))
    omega = 2 * np.pi * 4000 / 7
    y = _hb.linear_guess(problem, omega)
    y = y + 0.5 * jax.random.normal(jax.random.PRNGKey(1), y.shape)
    J = _hb.jacobian(problem, y, omega)
    J_ad = jax.jacfwd(lambda v: _hb.residual(problem, v, omega))(y)
    np.testing.assert_allclose(J, J_ad, atol=1e-13 * float(jnp.max(jnp.abs(J_ad))))


def test_newton_stops_as_diverging_when_its_residual_stops_falling():
    """Newton on ``y^3 - 2 y + 2`` from 0 cycles 0 -> 1 -> 0 (residuals 2, 1, 2, 1, ...):
    it stops after ``PATIENCE`` steps without a new lowest residual as
    ``nonlinear_divergence``, not after ``max_steps``; from -2 it converges to the root
    near -1.7693 (``successful``), the patience unused."""
    import lineax as lx
    import optimistix as optx

    def fn(y, args):
        return y**3 - 2 * y + 2, None

    def operator(y, args):
        return lx.MatrixLinearOperator(jnp.diag(3 * y**2 - 2))

    solver = _newton.FactorisedNewton(rtol=1e-12, operator=operator, linear_solver=lx.LU())
    cycling = optx.root_find(fn, solver, jnp.zeros(1), max_steps=40, throw=False,
                             has_aux=True)
    assert cycling.result == optx.RESULTS.nonlinear_divergence
    assert int(cycling.stats["num_steps"]) == _newton.PATIENCE + 2  # best at step 2
    root = optx.root_find(fn, solver, jnp.full(1, -2.0), max_steps=40, throw=False,
                          has_aux=True)
    assert root.result == optx.RESULTS.successful
    assert abs(float(root.value[0]) + 1.76929235423863) < 1e-12
