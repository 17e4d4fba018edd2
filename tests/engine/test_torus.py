"""The harmonic balance on a torus of incommensurate frequencies (model.md, "Incommensurate
stages"): the AFT operators of a truncation set, the structured Jacobian, the exact
superposition of a linear system's responses, the grid rule.

The test system: two bodies on a coupling spring, each behind one mesh; mesh 1 varies
with angle 0 (rate ``Omega``), mesh 2 with angle 1 (rate ``sqrt(2) Omega``), each
forced on its own angle.
"""

from __future__ import annotations

import pathlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gearjax as gj
from gearjax._engine import aft as _aft
from gearjax._engine import hb as _hb
from gearjax._engine.newton import newton

ROOT2 = float(np.sqrt(2.0))
DATA = pathlib.Path(__file__).resolve().parents[1] / "data"


def two_angle_system(backlash=0.0, eps=0.2, amp=(0.05, 0.04)):
    return gj.system_from_matrices(
        np.diag([1.0, 1.5]), 0.02 * np.eye(2), [[0.3, -0.3], [-0.3, 0.3]], np.eye(2), [1.0, 1.2],
        backlash=[backlash] * 2, damping=[0.03, 0.03], k_cos=[[eps], [eps]], mesh_mu=[1, 1],
        mesh_angle=[0, 1], f_mean=[0.5, 0.6], f_cos=[[amp[0], 0.0], [0.0, amp[1]]],
        f_sin=np.zeros((2, 2)), forcing_mu=[1, 1], forcing_angle=[0, 1],
        angle_ratio=[1.0, ROOT2])


@pytest.mark.parametrize("truncation", ["box", "diamond"])
@pytest.mark.parametrize("Ks", [(3, 4), (2, 3, 2)])
def test_torus_aft_operators(truncation, Ks):
    """Synthesis equals the series at the grid angles; analysis inverts it; the product
    matrix is the AFT of a multiplication, aliasing included."""
    G = len(Ks)
    basis = _aft.torus_basis(Ks, [2 * K + 4 for K in Ks], np.linspace(1.0, 1.7, G), truncation)
    rng = np.random.default_rng(0)
    X = jnp.asarray(rng.normal(size=(basis.n_coefficients, 3)))
    theta = _aft.angles(basis)  # (G, T)
    k = np.asarray(basis.orders)  # (P, G)
    phase = k @ theta  # (P, T)
    direct = X[0] + np.cos(phase).T @ X[1::2] + np.sin(phase).T @ X[2::2]
    samples = _aft.torus_synthesis(basis, X)
    np.testing.assert_allclose(samples, direct, atol=1e-12)
    np.testing.assert_allclose(_aft.torus_analysis(basis, samples), X, atol=1e-12)
    a = jnp.asarray(rng.normal(size=basis.n_samples))
    np.testing.assert_allclose(_aft.torus_product_matrix(basis, a) @ X,
                               _aft.torus_analysis(basis, a[:, None] * samples), atol=1e-11)
    # the derivative: d/dt of cos(k . theta) at rates r is -(k . r) sin(k . theta)
    nu = k @ np.asarray(basis.rates)
    dx = -np.sin(phase).T @ (nu[:, None] * X[1::2]) + np.cos(phase).T @ (nu[:, None] * X[2::2])
    np.testing.assert_allclose(_aft.torus_synthesis(basis, _aft.torus_derivative(basis, X)), dx,
                               atol=1e-11)


def test_truncation_sets():
    """The diamond keeps ``sum |k_g| / K_g <= 1``, the box ``|k_g| <= K_g``; each holds one
    of every pair ``+-k``; one angle gives the periodic harmonics ``1..K``."""
    box = _aft.torus_basis((3, 2), (8, 8), (1.0, ROOT2), "box")
    diamond = _aft.torus_basis((3, 2), (8, 8), (1.0, ROOT2), "diamond")
    assert len(box.orders) == (7 * 5 - 1) // 2
    assert set(diamond.orders) == {k for k in box.orders if abs(k[0]) / 3 + abs(k[1]) / 2 <= 1}
    for basis in (box, diamond):
        assert not set(basis.orders) & {tuple(-v for v in k) for k in basis.orders}
    assert _aft.torus_basis((5,), (16,), (1.0,)).orders == _aft.periodic_basis(5, 16).orders
    with pytest.raises(ValueError, match="grid"):
        _aft.torus_basis((5, 2), (10, 8), (1.0, ROOT2))


@pytest.mark.parametrize("truncation", ["box", "diamond"])
@pytest.mark.parametrize("Ks", [(1,), (7,), (3, 2), (4, 6), (5, 3, 2), (2, 3, 4, 2),
                                (1, 1, 1, 1, 1)])
def test_truncation_set_size_is_counted_without_building_the_set(truncation, Ks):
    """The closed-form count equals the rows of the basis built wave vector by wave
    vector, against a brute-force set over the whole box (the definition)."""
    import itertools

    basis = _aft.torus_basis(Ks, [2 * k + 2 for k in Ks], (1.0,) * len(Ks), truncation)
    box = itertools.product(*(range(-k, k + 1) for k in Ks))
    inside = [k for k in box if truncation == "box"
              or sum(abs(v) / K for v, K in zip(k, Ks)) <= 1 + 1e-12]
    assert _aft.truncation_set_size(Ks, truncation) == basis.n_coefficients == len(inside)


def test_a_set_on_eight_angles_is_counted_at_once():
    """Eight angles of order 16: the lattice points of the cross-polytope ``sum |k_g| <=
    16``, ``sum_j 2^j C(8, j) C(16, j)`` = 39,490,049 rows (a box of 1.4e12 vectors
    around them), counted in well under a second so that a size rule can refuse the set
    before any work."""
    import math
    import time

    t0 = time.perf_counter()
    rows = sum(2**j * math.comb(8, j) * math.comb(16, j) for j in range(9))
    assert _aft.truncation_set_size((16,) * 8) == rows == 39_490_049
    assert _aft.truncation_set_size((16,) * 8, "box") == 33**8
    assert time.perf_counter() - t0 < 0.5


@pytest.mark.parametrize("truncation", ["box", "diamond"])
def test_structured_jacobian_is_the_derivative_on_a_torus(truncation):
    """The Jacobian assembled from per-mesh blocks equals ``jax.jacfwd`` of the residual,
    at a state whose meshes separate over part of the torus."""
    system = two_angle_system(backlash=0.45)
    problem = _hb.hb_problem(system, _hb.HarmonicBalance(n_harmonics=(4, 3), n_time=(16, 16),
                                                         truncation=truncation))
    omega = 0.8
    X = np.random.default_rng(1).normal(size=problem.shape) * 0.1
    X[0] = 0.45  # W = I: both meshes hover about their backlash
    y = jnp.asarray(X / np.asarray(problem.x_scale)).reshape(-1)
    p = _hb.mesh_samples(problem, (y.reshape(problem.shape) * problem.x_scale) @ system.W.T,
                         omega)[0]
    assert 0.05 < float(jnp.mean(jnp.abs(p) <= 0.45)) < 0.95  # the kinks are in play
    J = jax.jit(_hb.jacobian)(problem, y, omega)
    J_ad = jax.jit(jax.jacfwd(lambda v: _hb.residual(problem, v, omega)))(y)
    np.testing.assert_allclose(J, J_ad, atol=1e-12 * float(jnp.max(jnp.abs(J_ad))))
    d = _hb.omega_derivative(problem, y, omega)
    h = 1e-6
    fd = (_hb.residual(problem, y, omega + h) - _hb.residual(problem, y, omega - h)) / (2 * h)
    np.testing.assert_allclose(d, fd, atol=1e-7 * float(jnp.max(jnp.abs(d))))


def test_two_incommensurate_forcings_superpose_exactly():
    """A linear, time-invariant system forced at ``Omega`` and ``sqrt(2) Omega``: the torus
    balance gives the two complex frequency responses ``(K - w^2 M + i w C)^-1 f`` on the
    wave vectors (1, 0) and (0, 1), the static solution as mean, and nothing else."""
    system = two_angle_system(eps=0.0)
    problem = _hb.hb_problem(system, _hb.HarmonicBalance(n_harmonics=(3, 3)))
    omega = 0.9
    sol = newton(problem, omega, _hb.linear_guess(problem, omega))
    assert sol.result == gj.RESULTS.successful
    Kt = np.asarray(system.mean_stiffness())
    Ct = np.asarray(system.C + system.W.T @ (system.damping[:, None] * system.W))
    M = np.asarray(system.M)
    X = np.asarray(sol.X)
    expected = np.zeros_like(X)
    expected[0] = np.linalg.solve(Kt, np.asarray(system.f_mean))
    for col, (k, w) in enumerate((((1, 0), omega), ((0, 1), ROOT2 * omega))):
        z = np.linalg.solve(Kt - w**2 * M + 1j * w * Ct, np.asarray(system.f_cos)[:, col])
        j = problem.basis.orders.index(k) + 1
        expected[2 * j - 1], expected[2 * j] = z.real, -z.imag
    np.testing.assert_allclose(X, expected, atol=1e-12 * np.max(np.abs(expected)))


@pytest.mark.parametrize("per_order", [_hb.SAMPLES_PER_ORDER, _hb.DENSE_TORUS_SAMPLES_PER_ORDER])
def test_torus_grid_rule_holds_with_backlash(per_order):
    """The per-angle sample rules (16x the highest order on a 2-torus, 8x on a torus of
    three or more angles, a power of two): doubling every angle's samples changes the RMS
    mesh forces by less than 0.1% on a torus solution that separates."""
    system = two_angle_system(backlash=0.45, amp=(0.25, 0.2))
    omega = 0.8
    rule = _hb.harmonic_basis(system, _hb.HarmonicBalance(n_harmonics=(6, 6))).grid
    grid = tuple(t * per_order // _hb.SAMPLES_PER_ORDER for t in rule)
    rms = []
    for scale in (1, 2):
        settings = _hb.HarmonicBalance(n_harmonics=(6, 6), n_time=tuple(scale * t for t in grid))
        problem = _hb.hb_problem(system, settings)
        sol = newton(problem, omega, _hb.linear_guess(problem, omega))
        assert sol.result == gj.RESULTS.successful
        r = gj.mesh_responses(problem, sol.X, omega, gj.static_mesh_forces(system))
        assert float(jnp.max(r.separation)) > 0.01  # the backlash is in play
        rms.append(np.asarray(r.rms_force))
    np.testing.assert_allclose(rms[1], rms[0], rtol=1e-3)


def test_torus_refusals():
    system = two_angle_system()
    with pytest.raises(ValueError, match="eta"):
        _hb.hb_problem(system, _hb.HarmonicBalance(n_harmonics=4, eta=2))
    with pytest.raises(ValueError, match="torus angle 1"):
        _hb.hb_problem(system, _hb.HarmonicBalance(n_harmonics=(4, 0)))
    with pytest.raises(ValueError, match="2 torus angles"):
        _hb.hb_problem(system, _hb.HarmonicBalance(n_harmonics=(4, 4, 4)))
    with pytest.raises(ValueError, match="truncation"):
        _hb.hb_problem(system, _hb.HarmonicBalance(n_harmonics=4, truncation="ball"))


def test_excitation_on_a_torus_grid_is_each_meshs_series_at_its_own_angle():
    # three groups, stiffness harmonics on every mesh, unequal samples per angle: every
    # sample of every mesh against the series evaluated at that sample's own angle
    train = gj.load_train(DATA / "three_stage_incommensurate.toml")
    system = gj.gear_case(train, torus=True).system
    basis = _hb.harmonic_basis(system, gj.harmonics_settings(system, (4, 5, 6)))
    assert len(set(basis.grid)) > 1
    kappa, te, te_rate = _hb.excitation_on_grid(system, basis)
    theta = _aft.angles(basis)[np.asarray(system.mesh_angles)]  # (m, T)
    mu = np.asarray(system.mesh_mu, float)
    h = np.arange(1, system.k_cos.shape[1] + 1)
    arg = mu[:, None, None] * h[None, :, None] * theta[:, None, :]
    expected = 1 + np.sum(np.asarray(system.k_cos)[:, :, None] * np.cos(arg)
                          + np.asarray(system.k_sin)[:, :, None] * np.sin(arg), axis=1)
    assert kappa.shape == theta.shape
    np.testing.assert_allclose(np.asarray(kappa), expected, rtol=0, atol=1e-12)
    assert np.ptp(expected) > 0.1  # the stiffness does vary
    np.testing.assert_array_equal(np.asarray(te), 0.0)  # the train gives no error

    # transmission error and its rate, angle rates 1 and sqrt(2), grids 10 and 14
    te_cos, te_sin = np.array([[1e-6, 2e-7], [0.0, 3e-7]]), np.array([[0.0, 5e-7], [4e-7, 0.0]])
    base = two_angle_system()
    system = gj.system_from_matrices(
        base.M, base.C, base.K, base.W, base.kbar, damping=base.damping, mesh_mu=[2, 3],
        k_cos=[[0.2], [0.1]], te_cos=te_cos, te_sin=te_sin, mesh_angle=[0, 1],
        f_mean=base.f_mean, angle_ratio=[1.0, ROOT2])
    basis = _aft.torus_basis((2, 3), (10, 14), (1.0, ROOT2))
    _, te, te_rate = _hb.excitation_on_grid(system, basis)
    theta = _aft.angles(basis)  # meshes 0 and 1 on angles 0 and 1
    arg = np.array([2.0, 3.0])[:, None, None] * np.arange(1, 3)[None, :, None] * theta[:, None, :]
    e = np.sum(te_cos[:, :, None] * np.cos(arg) + te_sin[:, :, None] * np.sin(arg), axis=1)
    rate = np.array([2.0, 3.0])[:, None] * np.arange(1, 3)[None, :]
    de = np.sum(rate[:, :, None] * (te_sin[:, :, None] * np.cos(arg)
                                    - te_cos[:, :, None] * np.sin(arg)), axis=1)
    np.testing.assert_allclose(np.asarray(te), e, rtol=0, atol=1e-18)
    # d e / d t over omega_0: along angle g the phase turns at rate g's rate
    np.testing.assert_allclose(np.asarray(te_rate), de * np.array([1.0, ROOT2])[:, None],
                               rtol=1e-12, atol=1e-18)
