"""Mesh phasing and stiffness harmonics against hand formulas and numerical integrals.

Phasing (model.md, Parker & Lin 2004), harmonic h of mesh j p_i of a stage:

    physical: sun h (-sigma Z_s psi_i + Gamma),  ring h (sigma Z_r psi_i + gamma_sr + Gamma)
    paper:    sun h Z_s psi_i + Gamma,           ring h (Z_r psi_i + gamma_sr) + Gamma

Stiffness: kappa(t) is a rectangular wave of mean 1 (floor(C) or floor(C) + 1 pairs in
contact, divided by C), the double-contact interval centred on phase 0 so that its
Fourier series is 1 + sum_h A_h cos(h (w t + Phi)).
"""

from __future__ import annotations

import math
import tomllib
import warnings

import jax.numpy as jnp
import numpy as np
import pytest
import tomli_w

import gearjax as gj


def wrap(a):
    """Angle in degrees to (-180, 180]."""
    w = -((-np.asarray(a, dtype=float) + 180.0) % 360.0 - 180.0)
    return np.where(np.abs(w) < 1e-9, 0.0, w)


def same_angles(a, b, tol=1e-6):
    d = wrap(np.asarray(a, dtype=float) - np.asarray(b, dtype=float))
    return bool(np.all(np.abs(d) < tol))


def hand_phases(zs, zr, psi_deg, h, sigma, rule, gamma_sr=0.0):
    """Sun and ring phases (deg) relative to planet 1's sun mesh, harmonic h."""
    psi = np.asarray(psi_deg, dtype=float)
    if rule == "physical":
        return wrap(-h * sigma * zs * psi), wrap(h * (sigma * zr * psi + gamma_sr))
    return wrap(h * zs * psi), wrap(h * (zr * psi + gamma_sr))


def hand_signs(sun_deg):
    return "".join("+" if abs(a) < 1e-6 else "-" if abs(abs(a) - 180) < 1e-6 else "~"
                   for a in sun_deg)


@pytest.fixture(scope="module")
def paper(paper_train):
    """The bundled paper case (conftest's ``paper_train``)."""
    return paper_train


def stage_from_toml(teeth, angles, gamma_sr=0.0, stage_phase=0.0):
    zs, zp, zr = teeth
    text = f"""
[[stages]]
id = "1"
teeth = {{ sun = {zs}, planet = {zp}, ring = {zr} }}
module_mm = 2.0
pressure_angle_deg = 20.0
planet_angles_deg = {list(angles)}
contact_ratio = {{ sun = 1.6, ring = 1.8 }}
mesh_stiffness = {{ sun = 4.0e8, ring = 5.0e8 }}
sun_ring_phase_deg = {gamma_sr}
stage_phase_deg = {stage_phase}
inertia = {{ sun = 2.0e-4, ring = 4.0e-3, carrier = 3.0e-3, planet = 6.0e-5 }}
planet_mass = 0.25

[gears.g]
input = "1.sun"
output = "1.carrier"
brakes = ["1.ring"]
input_torque = 100.0
"""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gj.GeometryWarning)
        return gj.loads_train(text, source="x.toml")


# ------------------------------------------------------------------ phasing report


@pytest.mark.parametrize("rule", ["physical", "paper"])
@pytest.mark.parametrize("sigma", [1, -1])
def test_paper_stage_one(paper, rule, sigma):
    """Z_s = 30, 4 planets: h Z_s mod 4 = 2 for odd h (planets alternate), 0 for even h."""
    stage = paper.stage("1")
    report = gj.phasing_report(stage, sigma, rule, 4)
    assert [r.h for r in report] == [1, 2, 3, 4]
    for r in report:
        assert r.k == (r.h * 30) % 4
        sun, ring = hand_phases(30, 70, [0, 90, 180, 270], r.h, sigma, rule)
        assert same_angles(r.sun_deg, sun)
        assert same_angles(r.ring_deg, ring)
        if r.h % 2:
            assert r.k == 2
            assert r.signs == "+-+-"
            assert r.kind != "in-phase"
        else:
            assert r.k == 0
            assert r.signs == "++++"
            assert r.kind == "in-phase"


@pytest.mark.parametrize("rule", ["physical", "paper"])
@pytest.mark.parametrize("sigma", [1, -1])
def test_paper_stage_two_all_in_phase(paper, rule, sigma):
    """Z_s = 44 is a multiple of 4: every harmonic in phase."""
    report = gj.phasing_report(paper.stage("2"), sigma, rule, 4)
    for r in report:
        assert r.k == 0
        assert r.kind == "in-phase"
        assert r.signs == "++++"
        assert same_angles(r.sun_deg, [0, 0, 0, 0])
        # ring: h Z_r psi with Z_r = 80 -> 80 * 90 = 20 turns: in phase too (gamma_sr = 0)
        assert same_angles(r.ring_deg, [0, 0, 0, 0])


def test_paper_stage_phasing_rules_agree_for_the_case_study(paper):
    """model.md: both forms coincide for the paper's stages (2 Z psi / 360 is an integer)."""
    for sid in ("1", "2"):
        for sigma in (1, -1):
            a = gj.phasing_report(paper.stage(sid), sigma, "physical", 4)
            b = gj.phasing_report(paper.stage(sid), sigma, "paper", 4)
            for x, y in zip(a, b):
                assert same_angles(x.sun_deg, y.sun_deg)
                assert same_angles(x.ring_deg, y.ring_deg)
                assert x.signs == y.signs


FIVE = ((36, 24, 84), [0.0, 72.0, 144.0, 216.0, 288.0])  # (36 + 84) * 72 / 360 = 24: assemblable


@pytest.mark.parametrize("sigma", [1, -1])
def test_five_planets_physical_differs_from_paper(sigma):
    teeth, angles = FIVE
    stage = stage_from_toml(teeth, angles).stage("1")
    phys = gj.phasing_report(stage, sigma, "physical", 4)
    pap = gj.phasing_report(stage, sigma, "paper", 4)
    for p, q in zip(phys, pap):
        assert p.k == (p.h * 36) % 5
        sun, ring = hand_phases(36, 84, angles, p.h, sigma, "physical")
        assert same_angles(p.sun_deg, sun)
        assert same_angles(p.ring_deg, ring)
        sun_p, ring_p = hand_phases(36, 84, angles, q.h, sigma, "paper")
        assert same_angles(q.sun_deg, sun_p)
        assert same_angles(q.ring_deg, ring_p)
    # 2 Z_s psi_2 / 360 = 14.4 is not an integer: the two rules disagree
    differ = [not same_angles(p.sun_deg, q.sun_deg) for p, q in zip(phys, pap)]
    if sigma == 1:
        assert all(differ)
    # h = 1: k = 36 mod 5 = 1, sequential; planet 2 sun mesh at -sigma * 36 * 72 = -sigma 72 deg
    assert phys[0].k == 1
    assert phys[0].kind == "sequential"
    assert phys[0].sun_deg[1] == pytest.approx(-sigma * 72.0, abs=1e-9)
    assert pap[0].sun_deg[1] == pytest.approx(72.0, abs=1e-9)
    assert phys[1].k == 2  # 72 mod 5
    assert phys[1].kind == "counter-phase"
    assert phys[0].signs == "+~~~~"


def test_ring_leads_sun_by_gamma_when_assembly_rule_holds():
    """Physical rule with (Z_s + Z_r) psi_i / 360 integer: h (Phi_ri - Phi_si) = h gamma_sr."""
    teeth, angles = FIVE
    gamma = 37.0
    stage = stage_from_toml(teeth, angles, gamma_sr=gamma, stage_phase=25.0).stage("1")
    for sigma in (1, -1):
        for r in gj.phasing_report(stage, sigma, "physical", 6):
            assert same_angles(np.subtract(r.ring_deg, r.sun_deg), r.h * gamma)
            # the stage phase shifts every mesh alike: it drops out of relative phases
            sun, ring = hand_phases(36, 84, angles, r.h, sigma, "physical", gamma)
            assert same_angles(r.sun_deg, sun)
            assert same_angles(r.ring_deg, ring)


@pytest.mark.parametrize("rule", ["physical", "paper"])
def test_unequal_spacing(rule):
    angles = [0.0, 100.0, 220.0]
    stage = stage_from_toml((24, 18, 60), angles).stage("1")
    report = gj.phasing_report(stage, 1, rule, 4)
    assert len(report) == 4
    for r in report:
        assert r.kind == "unequal spacing"
        assert r.k is None
        sun, ring = hand_phases(24, 60, angles, r.h, 1, rule)
        assert len(r.sun_deg) == len(r.ring_deg) == 3
        assert same_angles(r.sun_deg, sun)
        assert same_angles(r.ring_deg, ring)
        assert r.signs == hand_signs(sun)
    # h = 1, physical: planet 2 sun at -24 * 100 = -2400 = -240 - 6*360 -> +120 deg
    if rule == "physical":
        assert report[0].sun_deg[1] == pytest.approx(120.0, abs=1e-9)
        assert report[0].signs == "+~~"


# ------------------------------------------------------------------ stiffness harmonics

N_SAMPLES = 1 << 16


def rectangular_wave(theta, c):
    """kappa at mesh phase theta (rad): floor(C) + 1 pairs for |theta| < pi frac(C), over C."""
    f = c - math.floor(c)
    th = np.mod(theta + np.pi, 2 * np.pi) - np.pi
    return (math.floor(c) + (np.abs(th) < np.pi * f)) / c


@pytest.mark.parametrize("c", [1.0, 1.1, 1.25, 1.5, 1.93, 1.95, 2.3])
def test_stiffness_amplitudes_match_fourier_integral(c):
    H = 8
    theta = (np.arange(N_SAMPLES) + 0.5) * 2 * np.pi / N_SAMPLES  # midpoint rule over a cycle
    kappa = rectangular_wave(theta, c)
    assert kappa.mean() == pytest.approx(1.0, abs=1e-4)
    h = np.arange(1, H + 1)[:, None]
    a_num = 2 * np.mean(kappa * np.cos(h * theta), axis=1)
    b_num = 2 * np.mean(kappa * np.sin(h * theta), axis=1)
    a = np.asarray(gj.stiffness_amplitudes(jnp.asarray(c), H))
    assert a.shape == (H,)
    np.testing.assert_allclose(a, a_num, atol=1e-4)
    np.testing.assert_allclose(b_num, 0.0, atol=1e-4)
    # and the closed form of model.md, written out
    frac = c - math.floor(c)
    closed = [2 * math.sin(k * math.pi * frac) / (k * math.pi * c) for k in range(1, H + 1)]
    np.testing.assert_allclose(a, closed, rtol=1e-12, atol=1e-15)


def paper_with(changes: dict, harmonics: int) -> gj.Train:
    raw = tomllib.loads(gj.bundled_example_path().read_text())
    raw["stiffness_harmonics"] = harmonics
    for st in raw["stages"]:
        st.update(changes.get(st["id"], {}))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gj.GeometryWarning)
        return gj.loads_train(tomli_w.dumps(raw), source="x.toml")


def five_planet_train(harmonics: int, gamma_sr: float) -> gj.Train:
    train = stage_from_toml(FIVE[0], FIVE[1], gamma_sr=gamma_sr)
    text = gj.dumps_train(train)
    raw = tomllib.loads(text)
    raw["stiffness_harmonics"] = harmonics
    return gj.loads_train(tomli_w.dumps(raw), source="x.toml")


# (train builder, mesh label, sigma, Z_s, Z_r, psi_i (deg), gamma_sr, Gamma, contact ratio)
MESHES = {
    # paper stage 2 in first gear: sigma = sign(0 - 6/17) = -1; ring mesh of planet 2
    "paper 2.rp2": (lambda H: paper_with({"2": {"sun_ring_phase_deg": 50.0,
                                                 "stage_phase_deg": 30.0}}, H),
                    "2.rp2", -1, 44, 80, 90.0, 50.0, 30.0, 1.95),
    # paper stage 1: sigma = sign(1 - 93/170) = +1; sun mesh of planet 2
    "paper 1.sp2": (lambda H: paper_with({}, H), "1.sp2", 1, 30, 70, 90.0, 0.0, 0.0, 1.25),
    # five planets, ring fixed, sun in: sigma = +1; sun mesh of planet 2 (phase -72 deg)
    "five 1.sp2": (lambda H: five_planet_train(H, 20.0), "1.sp2", 1, 36, 84, 72.0, 20.0, 0.0,
                   1.6),
    "five 1.rp4": (lambda H: five_planet_train(H, 20.0), "1.rp4", 1, 36, 84, 216.0, 20.0, 0.0,
                   1.8),
}


def hand_mesh_phase(label, sigma, zs, zr, psi, gamma, stage_phase):
    """Phi (rad) of the physical rule for the mesh ``label``."""
    if label.split(".")[1].startswith("s"):
        deg = -sigma * zs * psi + stage_phase
    else:
        deg = sigma * zr * psi + gamma + stage_phase
    return math.radians(deg)


@pytest.mark.parametrize("case", list(MESHES))
def test_system_coefficients_are_the_shifted_wave(case):
    """k_cos/k_sin of the assembled System against a numerical Fourier integral in time of
    kappa(t) = wave(w t + Phi), Phi by hand."""
    build, label, sigma, zs, zr, psi, gamma, stage_phase, c = MESHES[case]
    H = 4
    system = gj.assemble(build(H))
    m = system.mesh_labels.index(label)
    mu = system.mesh_mu[m]
    assert mu > 0
    phi = hand_mesh_phase(label, sigma, zs, zr, psi, gamma, stage_phase)
    omega = 2 * np.pi  # base frequency (rad/s); the mesh turns at mu * omega
    t = (np.arange(N_SAMPLES) + 0.5) / N_SAMPLES / mu  # one mesh period
    wt = mu * omega * t
    kappa = rectangular_wave(wt + phi, c)
    h = np.arange(1, H + 1)[:, None]
    cos_num = 2 * np.mean(kappa * np.cos(h * wt), axis=1)
    sin_num = 2 * np.mean(kappa * np.sin(h * wt), axis=1)
    np.testing.assert_allclose(np.asarray(system.k_cos[m]), cos_num, atol=1e-4)
    np.testing.assert_allclose(np.asarray(system.k_sin[m]), sin_num, atol=1e-4)


@pytest.mark.parametrize("case", list(MESHES))
def test_system_series_reproduces_the_wave(case):
    """With many harmonics, 1 + fourier_series(k_cos, k_sin) is the rectangular wave itself
    (L2 error = the truncated tail), and a wrongly phased wave is far from it."""
    build, label, sigma, zs, zr, psi, gamma, stage_phase, c = MESHES[case]
    H = 300
    system = gj.assemble(build(H))
    m = system.mesh_labels.index(label)
    mu = system.mesh_mu[m]
    phi = hand_mesh_phase(label, sigma, zs, zr, psi, gamma, stage_phase)
    omega = 2 * np.pi
    n_t = 4096
    t = (np.arange(n_t) + 0.5) / n_t / mu
    series = 1.0 + np.asarray(gj.fourier_series(
        system.k_cos[m:m + 1], system.k_sin[m:m + 1], jnp.asarray([mu]), omega,
        jnp.asarray(t)))[0]
    wave = rectangular_wave(mu * omega * t + phi, c)
    rms = np.sqrt(np.mean((series - wave) ** 2))
    frac = c - math.floor(c)
    k = np.arange(H + 1, 200_000)
    tail = np.sqrt(np.sum((2 * np.sin(k * np.pi * frac) / (k * np.pi * c)) ** 2) / 2)
    assert rms < 2 * tail + 1e-3
    assert rms < 0.03
    # away from the jumps the series and the wave agree pointwise
    edge = np.abs(np.abs(np.mod(mu * omega * t + phi + np.pi, 2 * np.pi) - np.pi) - np.pi * frac)
    far = edge > 0.1
    if frac > 0:
        assert np.max(np.abs(series - wave)[far]) < 0.03
    # the same wave shifted by a quarter cycle does not match (the phase is tested)
    shifted = rectangular_wave(mu * omega * t + phi + np.pi / 2, c)
    if frac > 0:
        assert np.sqrt(np.mean((series - shifted) ** 2)) > 10 * rms
