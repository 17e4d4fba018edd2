"""Mesh stiffness from tooth geometry: the wave over a mesh cycle, load sharing with tip
relief, the train-file keys, and derivatives through the geometry.

The stage is tests/data/geometry_stage.toml (21/39/99 teeth, module 3 mm, 40 mm face
width, three planets), not the paper's (whose teeth do not satisfy Z_r = Z_s + 2 Z_p)."""

import dataclasses
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gearjax as gj
from gearjax._gear import mesh_stiffness as ms
from gearjax._gear.phasing import stiffness_amplitudes

DATA = Path(__file__).parents[1] / "data"
STAGE_FILE = DATA / "geometry_stage.toml"


@pytest.fixture(scope="module")
def train():
    return gj.load_train(STAGE_FILE)


@pytest.fixture(scope="module")
def stage(train):
    return train.stages[0]


def relieved(stage, amount_um=15.0, load_start=0.5):
    """``stage`` with linear tip relief of ``amount_um`` on every gear, starting
    ``load_start`` of the way from the pitch circle to the tip."""
    forms = ms.tooth_forms(stage)
    starts = {}
    for name, form in zip(("sun", "planet", "ring"), forms):
        r = form.pitch_radius() + load_start * (form.tip_radius() - form.pitch_radius())
        starts[name] = 2e3 * r
    relief = gj.TipRelief(
        amount_um=gj.PerGear(**{k: jnp.asarray(amount_um) for k in starts}),
        start_diameter_mm=gj.PerGear(**{k: jnp.asarray(v) for k, v in starts.items()}))
    geo = dataclasses.replace(stage.geometry, tip_relief=relief, relieved=True)
    return dataclasses.replace(stage, geometry=geo)


def test_a_pair_stiffness_constant_along_the_path_gives_the_rectangular_wave(stage,
                                                                            monkeypatch):
    """The limit the docs describe: with each tooth pair equally stiff wherever it
    touches, the derived wave is the paper's rectangular wave of the geometric contact
    ratio (its closed-form amplitudes), with no sine terms."""
    monkeypatch.setattr(ms, "_compliance", lambda stage, forms, contact, s: 1e-9 + 0 * s)
    for side in ("sun", "ring"):
        wave = ms._mesh_wave(stage, side, 8, jnp.asarray(0.0))  # not compiled: patched
        C = wave.contact_ratio
        np.testing.assert_allclose(wave.mean, 1e9 * C, rtol=1e-12)
        np.testing.assert_allclose(wave.k_cos, stiffness_amplitudes(C, 8), atol=1e-12)
        np.testing.assert_allclose(wave.k_sin, 0.0, atol=1e-12)


@pytest.mark.parametrize("side", ["sun", "ring"])
def test_path_integrals_equal_the_sum_over_tooth_pairs_sampled(stage, side):
    """The Fourier coefficients by the path-of-contact integrals equal those of the mesh
    stiffness summed over the tooth pairs at each instant (sampled on 8192 phases; the
    jumps where pairs enter and leave make the sampled coefficients err by about
    jump / n, here below 3e-4 of the mean)."""
    wave = ms.mesh_wave(stage, side, 6)
    cycle = ms.mesh_cycle(stage, side, 0.0, 8192)
    spec = np.fft.rfft(np.asarray(cycle.stiffness)) / 8192
    np.testing.assert_allclose(spec[0].real, wave.mean, rtol=1e-4)
    np.testing.assert_allclose(2 * spec[1:7].real / spec[0].real, wave.k_cos, atol=3e-4)
    np.testing.assert_allclose(-2 * spec[1:7].imag / spec[0].real, wave.k_sin, atol=3e-4)
    pairs = np.asarray(cycle.pairs)
    C = float(wave.contact_ratio)
    assert set(np.unique(pairs)) == {np.floor(C), np.floor(C) + 1}
    np.testing.assert_allclose(np.mean(pairs == np.floor(C) + 1), C - np.floor(C), atol=1e-3)


def test_relieved_pairs_share_the_load_as_springs_with_gaps(stage):
    """The load sharing solves sum_j max(delta - e_j, 0) / lambda_j = F: checked against
    bisection on the same pairs, at a light and a design load."""
    s = relieved(stage)
    forms, names, contact = ms.mesh_pair(s, "sun")
    tau = jnp.linspace(0, 2 * np.pi, 64, endpoint=False)
    pos, on = ms._pair_positions(contact, tau)
    lam = np.asarray(ms._compliance(s, forms, contact, jnp.where(on, pos, contact.start)))
    gap = np.asarray(ms._relief(s, forms, names, contact, jnp.where(on, pos, contact.start)))
    on = np.asarray(on)
    for load in (200.0, 5000.0):
        cycle = ms.mesh_cycle(s, "sun", load, 64)
        for k in range(64):
            def force(d):
                return np.sum(np.where(on[k], np.maximum(d - gap[k], 0) / lam[k], 0.0))
            lo, hi = 0.0, 1e-3
            for _ in range(200):
                mid = (lo + hi) / 2
                lo, hi = (mid, hi) if force(mid) < load else (lo, mid)
            np.testing.assert_allclose(cycle.loaded_te[k], lo, rtol=1e-9, atol=1e-15)


def test_relief_closes_under_a_large_load(stage):
    """With every gap closed (a load far above relief times stiffness) the relieved
    mesh is as stiff as the unrelieved one and its transmission error is the
    stiffness-weighted mean gap; at a light load it is softer where relief acts."""
    s = relieved(stage, amount_um=10.0)
    plain = ms.mesh_cycle(stage, "sun", 1e7, 256)
    heavy = ms.mesh_cycle(s, "sun", 1e7, 256)
    np.testing.assert_allclose(heavy.stiffness, plain.stiffness, rtol=1e-12)
    light = ms.mesh_cycle(s, "sun", 100.0, 256)
    assert np.all(np.asarray(light.stiffness) <= np.asarray(plain.stiffness) * (1 + 1e-12))
    assert np.min(np.asarray(light.stiffness) / np.asarray(plain.stiffness)) < 0.9
    wave = ms.mesh_wave(s, "sun", 4, load=5000.0)
    assert float(jnp.max(jnp.hypot(wave.te_cos, wave.te_sin))) > 1e-7  # relief: a TE


@pytest.mark.parametrize("name", ["face_width_mm", "profile_shift"])
def test_derivatives_through_the_geometry_match_finite_differences(stage, name):
    """jax.grad of the mean stiffness and of the first harmonic (cosine and sine)
    through involute contact and potential energy, against central differences."""
    def where(s):
        g = s.geometry
        return g.face_width_mm if name == "face_width_mm" else g.profile_shift.sun

    def outputs(value):
        s = eqx.tree_at(where, stage, value)
        w = ms.mesh_wave(s, "sun", 2)
        return jnp.stack([w.mean / 1e9, w.k_cos[0], w.k_sin[0], w.k_cos[1]])

    x0 = jnp.asarray(40.0 if name == "face_width_mm" else 0.1)
    jac = jax.jacfwd(outputs)(x0)
    h = 1e-4 * max(abs(float(x0)), 1.0)
    fd = (outputs(x0 + h) - outputs(x0 - h)) / (2 * h)
    np.testing.assert_allclose(jac, fd, rtol=1e-6, atol=1e-9)
