"""The generic System: a hand-checkable one-DOF oscillator, the mesh element, and the
assembled paper train (matrices against the formulas of model.md, grad and vmap)."""

from __future__ import annotations

import math
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gearjax
from gearjax import GeometryWarning

OMEGA = 0.8


# ------------------------------------------------------------------ helpers


def g_hand(x, b=1.0):
    """Clearance function written out case by case."""
    return np.where(x > b, x - b, np.where(x < -b, x + b, 0.0))


@eqx.filter_jit
def residual(system, x, xd, xdd, omega, t):
    """``M x'' + C x' + K x + W^T F - f(t)`` at times ``t``; ``x`` etc. shape ``(n, T)``.

    Transmission error ``e(t)`` enters ``p = W x - e`` and ``p' = W x' - e'`` (``e'`` by
    ``jax.jvp`` of ``fourier_series`` in time); forcing column ``l`` is at ``forcing_mu[l]``.
    """
    mu = jnp.asarray(system.mesh_mu)

    def te(tt):
        return gearjax.fourier_series(system.te_cos, system.te_sin, mu, omega, tt)

    e, e_dot = jax.jvp(te, (t,), (jnp.ones_like(t),))
    p = system.W @ x - e
    p_dot = system.W @ xd - e_dot
    kappa = 1.0 + gearjax.fourier_series(system.k_cos, system.k_sin, mu, omega, t)
    F = gearjax.mesh_force(p, p_dot, kappa, system.kbar[:, None], system.backlash[:, None],
                           system.damping[:, None], system.contact_damping)
    fmu = jnp.asarray(system.forcing_mu)
    forcing = system.f_mean[:, None] + jnp.stack([
        gearjax.fourier_series(system.f_cos[i][:, None], system.f_sin[i][:, None], fmu, omega,
                               t).sum(axis=0)
        for i in range(system.n_dof)
    ])
    return system.M @ xdd + system.C @ xd + system.K @ x + system.W.T @ F - forcing


def trajectory(A, d, omega, t):
    x = A * jnp.cos(omega * t) + d
    xd = -A * omega * jnp.sin(omega * t)
    xdd = -A * omega**2 * jnp.cos(omega * t)
    return x[None], xd[None], xdd[None]


# ------------------------------------------------------------------ one-DOF oscillator


@pytest.fixture(scope="module")
def oscillator():
    # x'' + 0.1 x' + g(x) = 0.1 + 0.03 cos(Omega t), unit stiffness, half clearance 1
    return gearjax.system_from_matrices([[1.0]], [[0.1]], [[0.0]], [[1.0]], [1.0],
                                        backlash=[1.0], f_mean=[0.1], f_cos=[[0.03]],
                                        f_sin=[[0.0]], forcing_mu=[1])


def test_oscillator_shape(oscillator):
    s = oscillator
    assert s.n_dof == 1
    assert s.n_meshes == 1
    assert s.mesh_mu == (1,)
    assert s.forcing_mu == (1,)
    assert s.contact_damping is False
    np.testing.assert_array_equal(s.K, [[0.0]])
    np.testing.assert_array_equal(s.mean_stiffness(), [[1.0]])
    assert s.spring_rows.shape == (0, 1)
    np.testing.assert_array_equal(s.damping, [0.0])
    np.testing.assert_array_equal(s.backlash, [1.0])


@pytest.mark.parametrize("A, d", [(2.5, 0.3), (0.5, 0.2), (3.0, -1.2)])
def test_oscillator_residual_matches_hand_equation(oscillator, A, d):
    t = jnp.linspace(0.0, 2 * np.pi / OMEGA, 41)
    x, xd, xdd = trajectory(A, d, OMEGA, t)
    got = residual(oscillator, x, xd, xdd, OMEGA, t)[0]
    xs = np.asarray(x[0])
    want = (np.asarray(xdd[0]) + 0.1 * np.asarray(xd[0]) + g_hand(xs)
            - 0.1 - 0.03 * np.cos(OMEGA * np.asarray(t)))
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-13)
    if A == 2.5:  # the trajectory crosses both flanks and the gap
        assert xs.max() > 1 and xs.min() < -1 and np.any(np.abs(xs) < 1)


def test_oscillator_with_stiffness_and_transmission_error():
    # x'' + 0.1 x' + (1 + 0.2 cos 2Wt) g(x - 0.05 cos 2Wt) + 0.02 (x - e)' = 0.1 + 0.03 sin Wt
    s = gearjax.system_from_matrices([[1.0]], [[0.1]], [[0.0]], [[1.0]], [1.0],
                                     backlash=[1.0], damping=[0.02], k_cos=[[0.2]],
                                     te_cos=[[0.05]], mesh_mu=[2], f_mean=[0.1],
                                     f_cos=[[0.0]], f_sin=[[0.03]], forcing_mu=[1])
    assert s.k_sin.shape == (1, 1) and s.te_sin.shape == (1, 1)
    t = jnp.linspace(0.0, 2 * np.pi / OMEGA, 37)
    x, xd, xdd = trajectory(2.0, 0.4, OMEGA, t)
    got = residual(s, x, xd, xdd, OMEGA, t)[0]
    tn, xn, xdn, xddn = (np.asarray(v).ravel() for v in (t, x, xd, xdd))
    e = 0.05 * np.cos(2 * OMEGA * tn)
    e_dot = -0.1 * OMEGA * np.sin(2 * OMEGA * tn)
    want = (xddn + 0.1 * xdn + (1 + 0.2 * np.cos(2 * OMEGA * tn)) * g_hand(xn - e)
            + 0.02 * (xdn - e_dot) - 0.1 - 0.03 * np.sin(OMEGA * tn))
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-13)


def test_system_from_matrices_keeps_stiffness():
    K = np.array([[2.0, -1.0], [-1.0, 2.0]])
    s = gearjax.system_from_matrices(np.eye(2), np.zeros((2, 2)), K, [[1.0, -1.0]], [3.0])
    np.testing.assert_allclose(s.K, K, atol=1e-14)
    np.testing.assert_allclose(s.mean_stiffness(), K + 3.0 * np.array([[1, -1], [-1, 1]]),
                               atol=1e-14)
    assert s.spring_class == ("elastic", "elastic")
    assert s.dof_labels == ("x1", "x2") and s.mesh_labels == ("mesh1",)


def test_fourier_series():
    cos = jnp.array([[0.5, 0.25], [1.0, 0.0]])
    sin = jnp.array([[0.0, -0.5], [0.0, 2.0]])
    mu = jnp.array([2, 3])
    t = jnp.linspace(0.0, 3.0, 11)
    got = gearjax.fourier_series(cos, sin, mu, OMEGA, t)
    tn = np.asarray(t)
    row0 = 0.5 * np.cos(2 * OMEGA * tn) + 0.25 * np.cos(4 * OMEGA * tn) - 0.5 * np.sin(4 * OMEGA * tn)
    row1 = np.cos(3 * OMEGA * tn) + 2.0 * np.sin(6 * OMEGA * tn)
    np.testing.assert_allclose(got, np.stack([row0, row1]), atol=1e-14)
    scalar = gearjax.fourier_series(cos, sin, mu, OMEGA, 1.7)
    assert scalar.shape == (2,)
    np.testing.assert_allclose(scalar, gearjax.fourier_series(cos, sin, mu, OMEGA, jnp.array([1.7]))[:, 0])


# ------------------------------------------------------------------ mesh element


def test_backlash_piecewise():
    p = jnp.array([-3.0, -1.5, -1.0, -0.5, 0.0, 0.5, 1.0, 1.5, 3.0])
    np.testing.assert_array_equal(gearjax.backlash(p, 1.0),
                                  [-2.0, -0.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.5, 2.0])
    np.testing.assert_array_equal(gearjax.backlash(p, 1.0), g_hand(np.asarray(p)))
    np.testing.assert_array_equal(gearjax.backlash(p, 0.0), p)  # no clearance: g(p) = p
    # per-mesh clearance broadcasts against time samples
    b = jnp.array([[0.5], [2.0]])
    out = gearjax.backlash(jnp.array([[1.0, -1.0], [1.0, -3.0]]), b)
    np.testing.assert_array_equal(out, [[0.5, -0.5], [0.0, -1.0]])


def test_backlash_slope():
    slope = jax.vmap(jax.grad(lambda p: gearjax.backlash(p, 1.0)))
    np.testing.assert_array_equal(slope(jnp.array([-2.0, -0.5, 0.3, 2.0])), [1, 0, 0, 1])


def test_mesh_force_damping_always_and_in_contact():
    p = jnp.array([-2.0, -1.0, -0.5, 0.0, 0.5, 1.0, 2.0])
    p_dot = jnp.full_like(p, 3.0)
    kappa = jnp.full_like(p, 1.2)
    k, b, c = 10.0, 1.0, 0.5
    g = g_hand(np.asarray(p))
    always = gearjax.mesh_force(p, p_dot, kappa, k, b, c)
    np.testing.assert_allclose(always, k * 1.2 * g + c * 3.0)
    contact = gearjax.mesh_force(p, p_dot, kappa, k, b, c, contact_damping=True)
    touching = np.abs(np.asarray(p)) > b
    np.testing.assert_allclose(contact, np.where(touching, k * 1.2 * g + c * 3.0, 0.0))
    # inside the gap (|p| <= b, boundary included) no force at all
    assert np.all(np.asarray(contact)[~touching] == 0.0)
    assert np.all(np.asarray(always)[~touching] == c * 3.0)


def test_mesh_force_without_damping_is_spring():
    p = jnp.array([-2.0, 0.0, 2.0])
    out = gearjax.mesh_force(p, jnp.ones(3), jnp.ones(3), 4.0, 0.5, 0.0)
    np.testing.assert_allclose(out, [-6.0, 0.0, 6.0])


# ------------------------------------------------------------------ the paper's train

I_DATA = {  # from the example file
    "1": dict(zs=30, zp=28, zr=70, Is=1.360e-4, Ir=3.476e-3, Ic=2.090e-4, Ip=8.590e-5, mp=0.300,
              ks=4.5e8, kr=5.1e8, Cs=1.25, Cr=1.93),
    "2": dict(zs=44, zp=18, zr=80, Is=1.450e-3, Ir=2.590e-3, Ic=4.223e-4, Ip=4.068e-5, mp=0.350,
              ks=4.1e8, kr=4.4e8, Cs=1.1, Cr=1.95),
}
MODULE = 1.5e-3
ALPHA = math.radians(21.3)
ZETA = 0.04


def radius(z):
    return MODULE * z * math.cos(ALPHA) / 2


@pytest.fixture(scope="module")
def train():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GeometryWarning)
        return gearjax.load_train()


@pytest.fixture(scope="module")
def paper(train):
    return gearjax.assemble(train, "first")


def test_paper_sizes_and_labels(paper):
    assert paper.n_dof == 14
    assert paper.n_meshes == 16
    assert paper.dof_labels == tuple(
        f"{s}.{m}" for s in "12" for m in ("sun", "ring", "carrier", "planet1", "planet2",
                                           "planet3", "planet4"))
    assert paper.mesh_labels == tuple(
        f"{s}.{j}p{i}" for s in "12" for j in "sr" for i in range(1, 5))
    assert paper.mesh_mu == (7,) * 8 + (8,) * 8  # w2 / w1 = 80 / 70
    assert paper.forcing_mu == ()
    assert paper.contact_damping is False


def test_paper_mass_matrix(paper):
    M = np.asarray(paper.M)
    np.testing.assert_array_equal(M, M.T)
    assert np.linalg.eigvalsh(M).min() > 0
    for k, sid in enumerate("12"):
        d, o = I_DATA[sid], 7 * k
        rc = MODULE * (d["zs"] + d["zp"]) / 2
        assert M[o, o] == pytest.approx(d["Is"], rel=1e-14)
        assert M[o + 1, o + 1] == pytest.approx(d["Ir"], rel=1e-14)
        assert M[o + 2, o + 2] == pytest.approx(d["Ic"] + 4 * (d["Ip"] + d["mp"] * rc**2),
                                                rel=1e-12)
        for i in range(4):
            assert M[o + 3 + i, o + 3 + i] == pytest.approx(d["Ip"], rel=1e-14)
            assert M[o + 3 + i, o + 2] == M[o + 2, o + 3 + i] == pytest.approx(d["Ip"], rel=1e-14)


def expected_W():
    W = np.zeros((16, 14))
    for k, sid in enumerate("12"):
        d, o = I_DATA[sid], 7 * k
        rs, rp, rr = radius(d["zs"]), radius(d["zp"]), radius(d["zr"])
        for i in range(4):
            # p_si = r_s (theta_s - theta_c) + r_p phi_i
            sun = W[8 * k + i]
            sun[o], sun[o + 2], sun[o + 3 + i] = rs, -rs, rp
            # p_ri = r_r (theta_r - theta_c) - r_p phi_i
            ring = W[8 * k + 4 + i]
            ring[o + 1], ring[o + 2], ring[o + 3 + i] = rr, -rr, -rp
    return W


def test_paper_mesh_rows(paper):
    np.testing.assert_allclose(paper.W, expected_W(), rtol=1e-13, atol=0)
    rs1 = radius(30)
    assert rs1 == pytest.approx(0.5 * 1.5e-3 * 30 * math.cos(math.radians(21.3)))
    radii = [radius(I_DATA[s][z]) for s in "12" for z in ("zs", "zr") for _ in range(4)]
    np.testing.assert_allclose(paper.mesh_radius, radii, rtol=1e-13)


def test_paper_mesh_stiffness_backlash_damping(paper):
    kbar, c = [], []
    for sid in "12":
        d = I_DATA[sid]
        rp = radius(d["zp"])
        for side, z, I_j in (("s", d["zs"], d["Is"]), ("r", d["zr"], d["Ir"])):
            k = d["k" + side]
            r_j = radius(z)
            m_eq = I_j * d["Ip"] / (I_j * rp**2 + d["Ip"] * r_j**2)
            kbar += [k] * 4
            c += [2 * ZETA * math.sqrt(k * m_eq)] * 4
    np.testing.assert_array_equal(paper.kbar, kbar)
    np.testing.assert_allclose(paper.damping, c, rtol=1e-12)
    np.testing.assert_array_equal(paper.backlash, [5.0e-5] * 16)
    np.testing.assert_array_equal(paper.C, np.zeros((14, 14)))


def test_paper_stiffness_harmonics_of_first_planet(paper):
    # planet 1 sits at psi = 0 and every phase in the file is 0: pure cosines
    h = np.arange(1, 5)
    for row, C in ((0, 1.25), (4, 1.93), (8, 1.1), (12, 1.95)):
        A = 2 * np.sin(h * np.pi * (C - np.floor(C))) / (h * np.pi * C)
        np.testing.assert_allclose(paper.k_cos[row], A, atol=1e-15)
        np.testing.assert_allclose(paper.k_sin[row], 0.0, atol=1e-15)
    assert paper.te_cos.shape[0] == 16 and not np.any(np.asarray(paper.te_cos))


def test_paper_housing_and_coupling_stiffness(paper):
    K = np.asarray(paper.K)
    idx = {name: i for i, name in enumerate(paper.dof_labels)}
    np.testing.assert_array_equal(K, K.T)
    assert K[idx["2.sun"], idx["2.sun"]] == pytest.approx(1e10, rel=1e-14)  # braked
    assert K[idx["1.sun"], idx["1.sun"]] == pytest.approx(1e2, rel=1e-12)  # free
    assert K[idx["1.carrier"], idx["2.ring"]] == pytest.approx(-1e8, rel=1e-14)
    assert K[idx["2.carrier"], idx["1.ring"]] == pytest.approx(-1e8, rel=1e-14)
    for name in ("1.carrier", "2.ring", "2.carrier", "1.ring"):
        assert K[idx[name], idx[name]] == pytest.approx(1e8 + 1e2, rel=1e-12)
    assert K[idx["1.sun"], idx["1.carrier"]] == 0.0  # the lock-up clutch is not engaged
    planets = [i for i, k in enumerate(paper.dof_kind) if k == "planet"]
    assert len(planets) == 8
    assert not np.any(K[planets]) and not np.any(K[:, planets])
    assert sorted(paper.spring_class) == sorted(["rigid"] * 5 + ["penalty"] + ["elastic"] * 2)


def test_third_gear_engages_lockup(train):
    s = gearjax.assemble(train, "third")
    K = np.asarray(s.K)
    idx = {name: i for i, name in enumerate(s.dof_labels)}
    assert K[idx["1.sun"], idx["1.carrier"]] == pytest.approx(-1e8, rel=1e-14)
    assert K[idx["2.sun"], idx["2.sun"]] == pytest.approx(1e2, rel=1e-12)  # no brake
    assert s.mesh_mu == (0,) * 16  # third gear turns as a block: no mesh excitation


def test_paper_forcing(paper):
    f = np.asarray(paper.f_mean)
    idx = {name: i for i, name in enumerate(paper.dof_labels)}
    assert f[idx["1.sun"]] == pytest.approx(750.0)
    assert f[idx["2.carrier"]] == pytest.approx(-750.0 * 17 / 6)  # -2125 N m
    rest = [i for i in range(14) if i not in (idx["1.sun"], idx["2.carrier"])]
    assert not np.any(f[rest])  # drag_torque 0


def test_jit_assemble(train, paper):
    jitted = jax.jit(gearjax.assemble)(train)
    for a, b in zip(jax.tree_util.tree_leaves(jitted), jax.tree_util.tree_leaves(paper)):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)


def test_grad_through_assembly_wrt_module(train):
    m0 = train.stages[0].module_mm

    def w_norm(module_mm):
        t = eqx.tree_at(lambda t: t.stages[0].module_mm, train, module_mm)
        return jnp.sum(gearjax.assemble(t).W ** 2)

    grad = jax.grad(w_norm)(m0)
    # W of stage 1 is proportional to its module (mm): d sum(W^2) / dm = 2 sum(W_1^2) / m
    W1 = expected_W()[:8]
    assert float(grad) == pytest.approx(2 * np.sum(W1**2) / 1.5, rel=1e-10)
    h = 1e-6
    fd = (w_norm(m0 + h) - w_norm(m0 - h)) / (2 * h)
    assert float(grad) == pytest.approx(float(fd), rel=1e-6)


def test_grad_of_sum_of_W_is_zero(train):
    # each sun row sums to r_p and each ring row to -r_p: sum(W) = 0 for any module
    grad = jax.grad(lambda m: jnp.sum(gearjax.assemble(
        eqx.tree_at(lambda t: t.stages[0].module_mm, train, m)).W))(train.stages[0].module_mm)
    assert abs(float(grad)) < 1e-15


def test_grad_wrt_mesh_stiffness_and_planet_mass(train):
    def damping_sum(k):
        t = eqx.tree_at(lambda t: t.stages[0].mesh_stiffness.sun, train, k)
        return jnp.sum(gearjax.assemble(t).damping)

    k0 = train.stages[0].mesh_stiffness.sun
    c = np.asarray(gearjax.assemble(train).damping[:4])
    assert float(jax.grad(damping_sum)(k0)) == pytest.approx(np.sum(c) / (2 * 4.5e8), rel=1e-10)

    def carrier_inertia(mp):
        t = eqx.tree_at(lambda t: t.stages[0].planet_mass, train, mp)
        return gearjax.assemble(t).M[2, 2]

    rc = 1.5e-3 * (30 + 28) / 2
    assert float(jax.grad(carrier_inertia)(train.stages[0].planet_mass)) == pytest.approx(
        4 * rc**2, rel=1e-12)


def test_vmap_over_stacked_trains(train):
    other = eqx.tree_at(lambda t: t.stages[0].mesh_stiffness.sun, train, jnp.asarray(6.0e8))
    stacked = jax.tree_util.tree_map(lambda a, b: jnp.stack([a, b]), train, other)
    batched = jax.vmap(gearjax.assemble)(stacked)
    assert batched.M.shape == (2, 14, 14)
    assert batched.W.shape == (2, 16, 14)
    np.testing.assert_array_equal(batched.kbar[:, 0], [4.5e8, 6.0e8])
    assert batched.mesh_labels == gearjax.assemble(train).mesh_labels
    for k, t in enumerate((train, other)):
        single = gearjax.assemble(t)
        for a, b in zip(jax.tree_util.tree_leaves(batched), jax.tree_util.tree_leaves(single)):
            np.testing.assert_allclose(np.asarray(a)[k], b, rtol=1e-13)
    # damping scales with sqrt(k) on the changed meshes only
    ratio = np.asarray(batched.damping[1] / batched.damping[0])
    np.testing.assert_allclose(ratio[:4], math.sqrt(6.0 / 4.5), rtol=1e-12)
    np.testing.assert_allclose(ratio[4:], 1.0, rtol=1e-14)


def test_contact_damping_option(train):
    import dataclasses

    s = gearjax.assemble(dataclasses.replace(train, mesh_damping="contact"))
    assert s.contact_damping is True
