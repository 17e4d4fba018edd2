"""Per-mesh responses: hand-computed statistics of prescribed signals, loaded-flank logic,
and the paper case solved by harmonic balance."""

import dataclasses
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gearjax as gj
from gearjax._engine import aft as _aft
from gearjax._engine import hb as _hb
from gearjax._engine import responses as _responses

responses_from_samples = jax.jit(_responses.responses_from_samples)
mesh_time_history = jax.jit(_responses.mesh_time_history, static_argnames="n_time")

solve = jax.jit(gj.solve_hb)
problem_of = eqx.filter_jit(_hb.hb_problem)

K_MESH = 2.0e8  # N/m
B = 1.0e-5  # half backlash, m


def sinusoid(p0, a, n_time, b=B, k=K_MESH, c=0.0, omega=1.0):
    """``p = p0 + a cos(tau)`` through the one mesh force (constant stiffness)."""
    tau = np.asarray(_aft.phases(n_time))
    p = jnp.asarray(p0 + a * np.cos(tau))[None, :]
    p_dot = jnp.asarray(-a * omega * np.sin(tau))[None, :]
    F = gj.mesh_force(p, p_dot, 1.0, k, b, c)
    return p, F


def share_below(c0):
    """Share of a period with ``cos(tau) < c0``."""
    return 1.0 - np.arccos(c0) / np.pi


def test_sinusoid_in_contact_is_exact():
    """Always in contact: mean k (p0 - b), RMS k a / sqrt 2, peak k (p0 - b + a)."""
    p0, a, T = 3 * B, B, 64
    p, F = sinusoid(p0, a, T)
    F_static = K_MESH * (p0 - B)
    r = responses_from_samples(p, F, jnp.array([B]), jnp.array([F_static]), jnp.array([0.05]))
    np.testing.assert_allclose(r.mean_force, [K_MESH * (p0 - B)], rtol=1e-14)
    np.testing.assert_allclose(r.rms_force, [K_MESH * a / np.sqrt(2)], rtol=1e-13)
    np.testing.assert_allclose(r.max_force, [K_MESH * (p0 - B + a)], rtol=1e-14)
    np.testing.assert_allclose(r.dlf, [(p0 - B + a) / (p0 - B)], rtol=1e-14)
    np.testing.assert_allclose(r.mean_torque, [0.05 * K_MESH * (p0 - B)], rtol=1e-14)
    assert float(r.separation[0]) == 0.0 and float(r.back_contact[0]) == 0.0


def test_sinusoid_into_the_gap_matches_analytic_shares():
    """``p0 + a cos tau`` dips into the gap for ``cos tau <= (b - p0)/a``."""
    p0, a = 1.3 * B, B
    c0 = (B - p0) / a
    theta = np.arccos(c0)  # contact for |tau| < theta
    mean = K_MESH / np.pi * (theta * (p0 - B) + a * np.sin(theta))
    for T in (256, 4096):
        p, F = sinusoid(p0, a, T)
        r = responses_from_samples(p, F, jnp.array([B]), jnp.array([1.0]), jnp.array([1.0]))
        assert abs(float(r.separation[0]) - share_below(c0)) <= 1.0 / T  # resolution 1/T
        assert float(r.back_contact[0]) == 0.0
        np.testing.assert_allclose(r.max_force, [K_MESH * (p0 - B + a)], rtol=1e-12)
        np.testing.assert_allclose(r.mean_force, [mean], rtol=20 / T**2)
    # RMS of the alternating part of the clipped sinusoid, by quadrature on a fine grid
    tau = np.linspace(0, 2 * np.pi, 200001)
    f = K_MESH * np.maximum(p0 - B + a * np.cos(tau), 0.0)
    rms = np.sqrt(np.trapezoid((f - mean) ** 2, tau) / (2 * np.pi))
    np.testing.assert_allclose(r.rms_force, [rms], rtol=1e-6)


def test_back_contact_follows_the_loaded_flank():
    """``p`` from -1.5 b to 2.5 b: front contact for cos tau > 0.25, back for cos tau < -0.75.

    With a positive static force the loaded flank is ``p > b``; an overdrive (negative
    static force) loads ``p < -b``, so the same signal then has its back contact on ``p > b``.
    """
    p0, a, T = 0.5 * B, 2 * B, 4096
    p, F = sinusoid(p0, a, T)
    front, back = 1.0 - share_below(0.25), share_below(-0.75)
    ones = jnp.ones(1)
    drive = responses_from_samples(p, F, B * ones, 1e3 * ones, ones)
    assert abs(float(drive.back_contact[0]) - back) <= 1.0 / T
    assert abs(float(drive.separation[0]) - (1.0 - front - back)) <= 2.0 / T
    over = responses_from_samples(p, F, B * ones, -1e3 * ones, ones)
    assert abs(float(over.back_contact[0]) - front) <= 1.0 / T
    # the mirrored signal under the mirrored static force is the same physics
    mirror = responses_from_samples(-p, -F, B * ones, -1e3 * ones, ones)
    for name in ("rms_force", "max_force", "dlf", "separation", "back_contact"):
        np.testing.assert_allclose(getattr(mirror, name), getattr(drive, name), rtol=1e-14)
    np.testing.assert_allclose(mirror.mean_force, -drive.mean_force, rtol=1e-14)
    np.testing.assert_allclose(mirror.mean_torque, -drive.mean_torque, rtol=1e-14)
    np.testing.assert_allclose(over.dlf, drive.dlf, rtol=1e-14)  # |F_static|


def test_unloaded_mesh_has_no_load_factor_and_batches():
    p, F = sinusoid(3 * B, B, 32)
    p2, F2 = jnp.stack([p[0], -p[0]]), jnp.stack([F[0], -F[0]])  # (m=2, T)
    r = responses_from_samples(p2, F2, jnp.full(2, B), jnp.array([0.0, -5.0]), jnp.ones(2))
    assert np.isnan(r.dlf[0]) and np.isnan(r.back_contact[0])
    assert np.isfinite(r.dlf[1]) and float(r.back_contact[1]) == 0.0
    batched = responses_from_samples(jnp.stack([p2, p2]), jnp.stack([F2, F2]), jnp.full(2, B),
                                     jnp.array([1.0, -5.0]), jnp.ones(2))
    assert batched.rms_force.shape == (2, 2)


def test_time_history_is_the_shared_mesh_force_of_the_synthesis():
    """A parametric clearance oscillator with transmission error (stiffness and TE at
    2 Omega): ``p = x - e``, ``p' = w (x' - e')``, ``F = kappa g(p) + c p'``; a doubled grid
    (stiffness and TE re-evaluated) agrees at the shared instants."""
    system = gj.system_from_matrices(
        [[1.0]], [[0.05]], [[0.0]], [[1.0]], [1.0], backlash=[1.0], damping=[0.02],
        k_cos=[[0.2]], te_cos=[[0.1]], te_sin=[[0.3]], mesh_mu=[2])
    problem = problem_of(system, _hb.HarmonicBalance(n_harmonics=8, n_time=64))
    X = jax.random.normal(jax.random.PRNGKey(3), problem.shape)
    omega = 0.8
    p, p_dot, F = mesh_time_history(problem, X, omega)
    tau = np.asarray(_aft.phases(64))
    k = np.arange(1, 9)
    c, s_ = np.cos(np.outer(tau, k)), np.sin(np.outer(tau, k))
    x = X[0, 0] + c @ X[1::2, 0] + s_ @ X[2::2, 0]
    xd = -s_ @ (k * X[1::2, 0]) + c @ (k * X[2::2, 0])
    e = 0.1 * np.cos(2 * tau) + 0.3 * np.sin(2 * tau)
    ed = -0.2 * np.sin(2 * tau) + 0.6 * np.cos(2 * tau)
    np.testing.assert_allclose(p[0], x - e, atol=1e-13)
    np.testing.assert_allclose(p_dot[0], omega * (xd - ed), atol=1e-13)
    g = (x - e) - np.clip(x - e, -1, 1)
    np.testing.assert_allclose(F[0], (1 + 0.2 * np.cos(2 * tau)) * g + 0.02 * omega * (xd - ed),
                               atol=1e-13)
    p2, d2, F2 = mesh_time_history(problem, X, omega, n_time=128)
    assert p2.shape == (1, 128)
    np.testing.assert_allclose(p2[:, ::2], p, atol=1e-13)
    np.testing.assert_allclose(d2[:, ::2], p_dot, atol=1e-13)
    np.testing.assert_allclose(F2[:, ::2], F, atol=1e-13)


# ------------------------------------------------------------------------ paper case

OMEGA = 2 * np.pi * 3000 / 7
SETTINGS = _hb.HarmonicBalance(n_harmonics=16)
responses = jax.jit(gj.mesh_responses)
static_forces = jax.jit(gj.static_mesh_forces)


@pytest.fixture(scope="module")
def paper():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gj.GeometryWarning)
        # one stiffness harmonic: the excitation reaches harmonic 8 (<= K = 16)
        system = gj.assemble(dataclasses.replace(gj.load_train(), stiffness_harmonics=1))
    problem = problem_of(system, SETTINGS)
    sol = solve(problem, OMEGA)
    assert bool(sol.converged)
    return system, problem, sol


def test_paper_static_forces(paper):
    system, _, _ = paper
    F_static = np.asarray(static_forces(system))
    np.testing.assert_allclose(F_static[:8], 8942.2, rtol=1e-5)
    np.testing.assert_allclose(F_static[8:], 11178.5, rtol=1e-5)


def test_paper_mean_forces_balance_the_mean_row(paper):
    """Harmonic balance's mean row, ``K X_0 + W^T Fbar = f_mean``, holds exactly: the mean
    mesh torques carry the applied torques less the housing and coupling springs'."""
    system, problem, sol = paper
    F_static = static_forces(system)
    r = responses(problem, sol.X, OMEGA, F_static)
    f = np.asarray(system.f_mean)
    lhs = np.asarray(system.K @ sol.X[0] + system.W.T @ r.mean_force)
    np.testing.assert_allclose(lhs, f, atol=1e-10 * np.abs(f).max())
    np.testing.assert_allclose(r.mean_torque, system.mesh_radius * r.mean_force, rtol=1e-15)
    # against the static forces: equal but for the torque leaking through the 1e2 N m/rad
    # housing springs of the free members, whose mean rotation the backlash shifts
    dev = np.asarray(r.mean_force / F_static - 1)
    assert 1e-4 < np.abs(dev).max() < 1e-3
    np.testing.assert_allclose(r.dlf * np.abs(F_static), r.max_force, rtol=1e-14)
    assert np.all((0 <= r.separation) & (r.separation <= 1) & (r.back_contact >= 0))


def test_paper_mean_forces_equal_static_without_housing_leak(paper):
    """The mean mesh forces differ from the static ones only by the torque leaking through
    the 1e2 N m/rad housing springs of the free members (5.2e-4 relative): with those
    springs 100 times softer the difference is 100 times smaller (5.2e-6), the leak
    linear in their stiffness. (Softer still, 1e-2, the stiffness spans 12 decades and
    Newton's convergence depends on the machine's rounding.)"""
    system, problem, sol = paper
    free = np.flatnonzero([c == "rigid" for c in system.spring_class])  # the 1e2 N m/rad springs
    assert np.all(system.spring_stiffness[free] == 1e2)
    dev_stiff = np.asarray(responses(problem, sol.X, OMEGA, static_forces(system)).mean_force
                           / static_forces(system) - 1)
    system = dataclasses.replace(
        system, spring_stiffness=system.spring_stiffness.at[free].set(1.0))  # same compile key
    problem = problem_of(system, SETTINGS)
    sol = solve(problem, OMEGA)
    assert bool(sol.converged)
    F_static = static_forces(system)
    r = responses(problem, sol.X, OMEGA, F_static)
    np.testing.assert_allclose(r.mean_force, F_static, rtol=1e-5)
    dev_soft = np.asarray(r.mean_force / F_static - 1)
    np.testing.assert_allclose(np.abs(dev_soft).max() * 100, np.abs(dev_stiff).max(), rtol=0.01)


def test_paper_vmap_over_points(paper):
    system, problem, sol = paper
    omega2 = 2 * np.pi * 3100 / 7
    sol2 = solve(problem, omega2)
    assert bool(sol2.converged)
    F_static = static_forces(system)
    batched = jax.jit(jax.vmap(gj.mesh_responses, in_axes=(None, 0, 0, None)))(
        problem, jnp.stack([sol.X, sol2.X]), jnp.array([OMEGA, omega2]), F_static)
    assert batched.rms_force.shape == (2, system.n_meshes)
    for i, (s, w) in enumerate(((sol, OMEGA), (sol2, omega2))):
        one = responses(problem, s.X, w, F_static)
        for field in dataclasses.fields(one):
            np.testing.assert_allclose(getattr(batched, field.name)[i],
                                       getattr(one, field.name), rtol=1e-12, atol=1e-12)
    assert not np.allclose(batched.rms_force[0], batched.rms_force[1])
    # the batch goes straight into a results Dataset and JSON
    hz = np.array([3000.0, 3100.0])
    ds = gj.sweep_dataset(
        batched, **gj.mesh_coordinates(system), mesh_frequency_hz=hz,
        stage_mesh_frequency_hz=np.stack([hz, hz * 8 / 7], axis=1), input_rpm=np.zeros(2),
        omega=2 * np.pi * hz / 7, result=["converged"] * 2, stable=None,
        static_force=F_static)
    points = gj.points_json(ds)
    assert points[1]["meshes"][9]["name"] == "2.sp2"
    assert points[1]["meshes"][9]["rms_force"] == pytest.approx(float(batched.rms_force[1, 9]))
