"""Condensed bordered solves (``bordered``, and its lineax solver) against dense solves."""

import dataclasses
import math

import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np

import gearjax as gj
from gearjax._engine import bordered as _bordered
from gearjax._engine import hb as _hb
from gearjax._engine import linear_solver as _ls


def test_mesh_null_space(paper_system):
    # two planetary stages of 7 degrees of freedom; two motions per stage deflect no mesh
    assert paper_system.n_dof == 14
    null = _hb.hb_problem(paper_system, _hb.HarmonicBalance(n_harmonics=32)).mesh_null
    assert null.shape == (14, 4)
    np.testing.assert_allclose(paper_system.W @ null, 0.0, atol=1e-15)
    np.testing.assert_allclose(null.T @ null, np.eye(4), atol=1e-12)
    one = gj.system_from_matrices([[1.0]], [[0.1]], [[0.0]], [[1.0]], [1.0], backlash=[1.0])
    assert _hb.mesh_null_space(one.W) is None  # every motion deflects the mesh: dense
    # a traced W has no static rank: dense
    assert int(jax.jit(lambda W: jnp.asarray(_hb.mesh_null_space(W) is None))(paper_system.W)) == 1


def test_small_bases_and_inverses():
    """The array-operation Householder bases and Gauss-Jordan inverses (no LAPACK)."""
    rng = np.random.default_rng(2)
    A = rng.normal(size=(3, 7, 2))
    Q = np.asarray(_bordered._complete_bases(jnp.asarray(A)))
    np.testing.assert_allclose(np.swapaxes(Q, 1, 2) @ Q, np.broadcast_to(np.eye(7), Q.shape),
                               atol=1e-14)
    np.testing.assert_allclose(np.swapaxes(Q[:, :, :5], 1, 2) @ A, 0.0, atol=1e-14)  # u ⟂ A
    B = rng.normal(size=(4, 6, 6)) * np.logspace(-6, 6, 6)  # columns of very different size
    np.testing.assert_allclose(B @ np.asarray(_bordered.small_inverses(jnp.asarray(B))),
                               np.broadcast_to(np.eye(6), B.shape), atol=1e-12)


def test_condensed_solve_equals_dense(paper_system_h1, K=16, eta=2):
    """At a state where teeth separate over part of the period (the mesh blocks then
    vary in time), the condensed factorisation solves the bordered system as the dense
    LU does, to round-off."""
    problem = _hb.hb_problem(paper_system_h1, _hb.HarmonicBalance(n_harmonics=K, eta=eta))
    omega = 2 * math.pi * 3000.0 / 7 * eta
    Y = _hb.linear_guess(problem, omega).reshape(problem.shape)
    deflection = lambda Y: _hb.mesh_samples(  # noqa: E731
        problem, (Y * problem.x_scale) @ paper_system_h1.W.T, omega)[0]
    rng = np.random.default_rng(1)
    mean = np.max(np.abs(np.asarray(deflection(Y))))
    Y = Y.at[1:].set(rng.normal(size=Y[1:].shape))  # a vibration that opens the clearance
    osc = np.max(np.abs(np.asarray(deflection(Y.at[0].set(0.0)))))
    Y = Y.at[1:].multiply(1.5 * mean / osc)
    y, p = Y.reshape(-1), deflection(Y)
    separated = np.mean(np.abs(np.asarray(p)) < np.asarray(paper_system_h1.backlash)[:, None])
    assert 0.01 < separated < 0.99
    N = problem.size
    g, ty = jnp.asarray(rng.normal(size=N)), jnp.asarray(rng.normal(size=N))
    tlam, rhs = 0.3, jnp.asarray(rng.normal(size=N + 1))
    dense = dataclasses.replace(problem, mesh_null=None)

    @jax.jit
    def solves(y):
        B = jnp.block([[_hb.jacobian(problem, y, omega), g[:, None]],
                       [ty[None, :], jnp.asarray([[tlam]])]])
        x = [_bordered.solve(_bordered.factor(p, y, omega, g, ty, tlam), rhs)
             for p in (problem, dense)]
        return x[0], x[1], B @ x[0] - rhs

    x_cond, x_dense, error = solves(y)
    assert float(jnp.max(jnp.abs(x_cond - x_dense))) < 1e-10 * float(jnp.max(jnp.abs(x_dense)))
    assert float(jnp.max(jnp.abs(error))) < 1e-8



def test_lineax_solver_and_its_transpose(paper_system_h1, K=8):
    """``CondensedLU`` on ``HBJacobian`` solves ``J x = b`` and, transposed, ``J^T x = b``
    (condensed and dense), as a dense solve of the materialised Jacobian does."""
    problem = _hb.hb_problem(paper_system_h1, _hb.HarmonicBalance(n_harmonics=K))
    omega = jnp.asarray(2 * math.pi * 3000.0 / 7)
    y = _hb.linear_guess(problem, omega)
    b = jnp.asarray(np.random.default_rng(2).normal(size=problem.size))
    J = np.asarray(_hb.jacobian(problem, y, omega))
    for p in (problem, dataclasses.replace(problem, mesh_null=None)):
        op = _ls.HBJacobian(p, y, omega)
        x = lx.linear_solve(op, b, _ls.CondensedLU()).value
        xt = lx.linear_solve(op.T, b, _ls.CondensedLU()).value
        np.testing.assert_allclose(J @ np.asarray(x), b, atol=1e-9)
        np.testing.assert_allclose(J.T @ np.asarray(xt), b, atol=1e-9)
        np.testing.assert_allclose(op.mv(x), b, atol=1e-9)
        np.testing.assert_allclose(op.T.mv(xt), b, atol=1e-9)
    # the transpose rule of the solve (reverse mode) is the transposed solver
    state = _ls.CondensedLU().init(_ls.HBJacobian(problem, y, omega), {})
    vjp = jax.vjp(lambda v: lx.linear_solve(_ls.HBJacobian(problem, y, omega), v,
                                            _ls.CondensedLU(), state=state).value, b)[1]
    np.testing.assert_allclose(J.T @ np.asarray(vjp(b)[0]), b, atol=1e-9)


def test_blocked_lu_solve_and_its_transpose():
    """The LU solve by blocks of rows (``_bordered._lu_solve``), on sizes below, at and
    across whole blocks, in double and single precision: the same solution as NumPy's
    dense solve, and its linear transpose solves with the transposed matrix."""
    rng = np.random.default_rng(5)
    m = _bordered.TRIANGLE_BLOCK
    for p in (7, m, 2 * m + 13):
        A = rng.standard_normal((p, p)) + p ** 0.5 * np.eye(p)
        b = rng.standard_normal(p)
        exact, exact_t = np.linalg.solve(A, b), np.linalg.solve(A.T, b)
        for single, tol in ((False, 1e-12), (True, 1e-5)):
            lu, perm = _bordered._bordered_lu(jnp.asarray(A[:-1, :-1]), jnp.asarray(A[:-1, -1]),
                                              jnp.asarray(A[-1, :-1]), A[-1, -1], single)
            factors = _bordered.Factors(lu=lu, perm=perm)
            assert lu.shape[0] % m == 0

            def solve(v, factors=factors):
                return _bordered._lu_solve(factors, v)

            x = np.asarray(jax.jit(solve)(jnp.asarray(b)))
            xt = np.asarray(jax.linear_transpose(solve, jnp.asarray(b))(jnp.asarray(b))[0])
            assert np.linalg.norm(x - exact) < tol * np.linalg.norm(exact)
            assert np.linalg.norm(xt - exact_t) < tol * np.linalg.norm(exact_t)
