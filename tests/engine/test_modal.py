"""Natural frequencies against closed forms derived by hand from the equations of model.md.

- pure planet modes: central members at rest, sum_i phi_i = 0, each planet obeys
  I_p phi'' + r_p^2 (k_sp + k_rp) phi = 0, multiplicity N - 1 (any spacing);
- single stage, ring fixed, sun and carrier free (Kahraman 1994, torsional model): the
  in-phase planet motion phi_i = phi reduces the model to three coordinates
  (theta_s, theta_c, phi); its characteristic polynomial is built here from a 3x3 mass
  and stiffness matrix written down from the energies, not from gearjax's matrices;
- derivatives of repeated eigenvalues against finite differences and the planet closed form.
"""

from __future__ import annotations

import math
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from numpy.polynomial import Polynomial as P

import gearjax as gj

MODULE_MM = 2.0
ALPHA_DEG = 20.0
K_S, K_R = 4.0e8, 5.0e8
I_S, I_R, I_C, I_P = 2.0e-4, 4.0e-3, 3.0e-3, 6.0e-5
M_P = 0.25


def single_stage(teeth, angles, *, braked=1e10, free=1e2) -> gj.Train:
    """One stage, ring braked, sun in, carrier out."""
    zs, zp, zr = teeth
    text = f"""
[[stages]]
id = "1"
teeth = {{ sun = {zs}, planet = {zp}, ring = {zr} }}
module_mm = {MODULE_MM}
pressure_angle_deg = {ALPHA_DEG}
planet_angles_deg = {list(angles)}
contact_ratio = {{ sun = 1.6, ring = 1.8 }}
mesh_stiffness = {{ sun = {K_S}, ring = {K_R} }}
inertia = {{ sun = {I_S}, ring = {I_R}, carrier = {I_C}, planet = {I_P} }}
planet_mass = {M_P}

[housing]
braked = {braked}
free = {free}

[gears.g]
input = "1.sun"
output = "1.carrier"
brakes = ["1.ring"]
input_torque = 100.0
"""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gj.GeometryWarning)  # unequal spacing breaks assembly
        return gj.loads_train(text, source="x.toml")


def base_radius(z):
    return MODULE_MM * 1e-3 * z * math.cos(math.radians(ALPHA_DEG)) / 2


def hz(lam):
    return math.sqrt(lam) / (2 * math.pi)


# (teeth, planet angles): concentric teeth, planets that do not overlap
# (2 r_c sin(dpsi/2) > m (Z_p + 2)); the last has unequal spacing
CASES = {
    "N=2": ((24, 18, 60), [0.0, 180.0]),
    "N=3": ((24, 18, 60), [0.0, 120.0, 240.0]),
    "N=4": ((20, 30, 80), [0.0, 90.0, 180.0, 270.0]),
    "N=5": ((36, 24, 84), [0.0, 72.0, 144.0, 216.0, 288.0]),
    "unequal": ((24, 18, 60), [0.0, 100.0, 220.0]),
}


@pytest.mark.parametrize("case", ["N=2", "N=3", "N=5", "unequal"])
def test_pure_planet_mode(case):
    teeth, angles = CASES[case]
    n = len(angles)
    r_p = base_radius(teeth[1])
    expected = hz(r_p**2 * (K_S + K_R) / I_P)
    result = gj.modes(gj.assemble(single_stage(teeth, angles)))
    planet = [m for m in result.modes if m.family == "planet"]
    assert len(planet) == n - 1
    for m in planet:
        assert m.hz == pytest.approx(expected, rel=1e-9)
        assert m.cls == "elastic"
        assert m.stage == "1"
        assert m.multiplicity == n - 1
        # central members at rest, planets' relative rotations sum to zero
        for member in ("1.sun", "1.ring", "1.carrier"):
            assert abs(m.shape[member]) < 1e-6
        assert abs(sum(m.shape[f"1.planet{i + 1}"] for i in range(n))) < 1e-6
    # no other mode sits at the planet frequency
    near = [m for m in result.modes if abs(m.hz - expected) < 1e-6 * expected]
    assert len(near) == n - 1


def reduced_in_phase_matrices(teeth, n):
    """(theta_s, theta_c, phi) with theta_r = 0 and phi_i = phi for every planet.

    Kinetic energy: I_s ts'^2/2 + I_ce tc'^2/2 + sum_i [I_p tc' phi' + I_p phi'^2/2],
    I_ce = I_c + N (I_p + m_p r_c^2). Strain energy, per planet,
    k_s (r_s (ts - tc) + r_p phi)^2 / 2 + k_r (r_r (0 - tc) - r_p phi)^2 / 2.
    """
    zs, zp, zr = teeth
    r_s, r_p, r_r = base_radius(zs), base_radius(zp), base_radius(zr)
    r_c = MODULE_MM * 1e-3 * (zs + zp) / 2
    i_ce = I_C + n * (I_P + M_P * r_c**2)
    mass = np.array([[I_S, 0.0, 0.0],
                     [0.0, i_ce, n * I_P],
                     [0.0, n * I_P, n * I_P]])
    a = np.array([r_s, -r_s, r_p])   # sun mesh deflection per coordinate
    b = np.array([0.0, -r_r, -r_p])  # ring mesh deflection per coordinate
    stiff = n * (K_S * np.outer(a, a) + K_R * np.outer(b, b))
    return mass, stiff


def characteristic_polynomial(mass, stiff):
    """det(K - lambda M) by cofactor expansion over polynomial entries in lambda."""
    e = [[P([stiff[i, j], -mass[i, j]]) for j in range(3)] for i in range(3)]
    return (e[0][0] * (e[1][1] * e[2][2] - e[1][2] * e[2][1])
            - e[0][1] * (e[1][0] * e[2][2] - e[1][2] * e[2][0])
            + e[0][2] * (e[1][0] * e[2][1] - e[1][1] * e[2][0]))


@pytest.mark.parametrize("case", ["N=3", "N=4", "unequal"])
def test_ring_fixed_overall_modes_closed_form(case):
    teeth, angles = CASES[case]
    n = len(angles)
    mass, stiff = reduced_in_phase_matrices(teeth, n)
    poly = characteristic_polynomial(mass, stiff)
    coef = poly.coef
    # the rigid-body rotation (ring fixed, sun and carrier free) makes lambda = 0 a root
    assert abs(coef[0]) < 1e-12 * np.linalg.norm(stiff) ** 3
    # remaining quadratic: coef[3] l^2 + coef[2] l + coef[1] = 0
    lam = np.sort(np.roots([coef[3], coef[2], coef[1]]).real)
    assert np.all(lam > 0)
    expected = [hz(v) for v in lam]

    result = gj.modes(gj.assemble(single_stage(teeth, angles, braked=1e14, free=0.0)))
    assert len(result.modes) == 3 + n
    overall = [m for m in result.modes if m.cls == "elastic" and m.family == "overall"]
    assert [m.hz for m in overall] == pytest.approx(expected, rel=1e-7)
    # in an overall mode every planet moves alike (in-phase)
    for m in overall:
        phis = [m.shape[f"1.planet{i + 1}"] for i in range(n)]
        assert np.allclose(phis, phis[0], atol=1e-9)

    # the rigid-body mode: 0 Hz, class rigid, with the kinematic shape
    rigid = [m for m in result.modes if m.cls == "rigid"]
    assert len(rigid) == 1
    (r,) = rigid
    assert r.hz < 1.0
    zs, zp, zr = teeth
    sun, carrier = r.shape["1.sun"], r.shape["1.carrier"]
    assert carrier / sun == pytest.approx(zs / (zs + zr), rel=1e-6)
    assert r.shape["1.planet1"] / sun == pytest.approx(-zs / zp * (1 - zs / (zs + zr)), rel=1e-6)
    assert abs(r.shape["1.ring"]) < 1e-6

    # the braked ring's spring: one penalty mode, its energy in the braked spring
    penalty = [m for m in result.modes if m.cls == "penalty"]
    assert len(penalty) == 1
    assert penalty[0].energy["penalty"] > 0.5
    assert penalty[0].shape["1.ring"] == pytest.approx(1.0)
    assert penalty[0].hz > 10 * max(expected)

    planet = [m for m in result.modes if m.family == "planet"]
    assert len(planet) == n - 1


# ------------------------------------------------------------------ eigenvalue derivatives


@pytest.fixture(scope="module")
def paper(paper_train):
    """The bundled paper case (conftest's ``paper_train``)."""
    return paper_train


def _eigvals_of(paper, kin, where, value):
    train = eqx.tree_at(where, paper, value)
    system = gj.assemble(train, "first", kin)
    return gj.generalized_eigvals(system.mean_stiffness(), system.M)


@pytest.mark.parametrize("stage_index", [0, 1])
def test_repeated_eigenvalue_gradient_planet_inertia(paper, stage_index):
    kin = gj.kinematics(paper, "first")
    s = paper.stages[stage_index]
    where = lambda t: t.stages[stage_index].inertia.planet  # noqa: E731
    ip0 = float(s.inertia.planet)
    r_p = float(s.base_radii()[1])
    k_sum = float(s.mesh_stiffness.sun + s.mesh_stiffness.ring)
    lam_p = r_p**2 * k_sum / ip0

    lam0 = np.asarray(_eigvals_of(paper, kin, where, jnp.asarray(ip0)))
    idx = np.flatnonzero(np.abs(lam0 - lam_p) < 1e-6 * lam_p)
    assert idx.size == 3  # the triple planet eigenvalue of this stage

    def triple_sum(ip):
        return jnp.sum(_eigvals_of(paper, kin, where, ip)[idx])

    grad = float(jax.grad(triple_sum)(jnp.asarray(ip0)))
    # closed form: the sum is 3 r_p^2 (k_s + k_r) / I_p
    assert grad == pytest.approx(-3 * lam_p / ip0, rel=1e-6)
    h = 1e-4 * ip0
    up, down = (float(triple_sum(jnp.asarray(ip0 + d))) for d in (h, -h))
    fd = (up - down) / (2 * h)
    assert grad == pytest.approx(fd, rel=1e-5)

    # every single eigenvalue has a finite derivative (reverse mode, as jax.grad uses),
    # also inside the triple where eigh's own derivative divides by lambda_i - lambda_j = 0
    jac = np.asarray(jax.jacrev(lambda ip: _eigvals_of(paper, kin, where, ip))(jnp.asarray(ip0)))
    assert np.all(np.isfinite(jac))
    assert jac[idx].sum() == pytest.approx(grad, rel=1e-9)


def test_repeated_eigenvalue_gradient_mesh_stiffness(paper):
    """dK path of the JVP: d/dk_s of the stage-1 triple sum is 3 r_p^2 / I_p."""
    kin = gj.kinematics(paper, "first")
    s = paper.stages[0]
    where = lambda t: t.stages[0].mesh_stiffness.sun  # noqa: E731
    k0 = float(s.mesh_stiffness.sun)
    r_p = float(s.base_radii()[1])
    ip = float(s.inertia.planet)
    lam_p = r_p**2 * (k0 + float(s.mesh_stiffness.ring)) / ip
    lam0 = np.asarray(_eigvals_of(paper, kin, where, jnp.asarray(k0)))
    idx = np.flatnonzero(np.abs(lam0 - lam_p) < 1e-6 * lam_p)
    assert idx.size == 3
    grad = float(jax.grad(lambda k: jnp.sum(_eigvals_of(paper, kin, where, k)[idx]))(
        jnp.asarray(k0)))
    assert grad == pytest.approx(3 * r_p**2 / ip, rel=1e-6)


def test_eigenvalue_sum_gradient_is_trace_derivative(paper):
    """sum of all eigenvalues = trace(M^-1 K): its derivative by an independent route."""
    kin = gj.kinematics(paper, "first")
    where = lambda t: t.stages[1].inertia.planet  # noqa: E731
    ip0 = jnp.asarray(float(paper.stages[1].inertia.planet))

    def trace(ip):
        system = gj.assemble(eqx.tree_at(where, paper, ip), "first", kin)
        return jnp.trace(jnp.linalg.solve(system.M, system.mean_stiffness()))

    g_eig = float(jax.grad(lambda ip: jnp.sum(_eigvals_of(paper, kin, where, ip)))(ip0))
    g_tr = float(jax.grad(trace)(ip0))
    assert g_eig == pytest.approx(g_tr, rel=1e-6)
