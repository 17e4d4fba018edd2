"""Coupling dampers (``[[couplings]] damping`` / ``damping_ratio``): the viscous matrix
they assemble, the damping ratio of the coupling's own mode against complex eigenvalues,
a harmonic-balance resonance against the single-degree-of-freedom estimate, refusals,
TOML paths, gradients and the round trip.

The realistic train is ``tests/data/wind_two_stage.toml``: a two-stage wind-turbine
gearbox whose low-speed sun drives the intermediate carrier through a hollow shaft with
``damping_ratio = 0.02``; its shaft mode is at 173 Hz. The closed form of the ratio is
exact for a coupling whose members are held by nothing else, so the exact check uses a
tiny train whose meshes are a million times softer than its coupling.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
import warnings
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg
import tomli_w

import gearjax as gj
from gearjax import TrainError
from gearjax._errors import RangeWarning, TrainWarning

import train_refusals
from train_refusals import SOURCE, mutate

WIND = Path(__file__).resolve().parents[1] / "data" / "wind_two_stage.toml"
SHARED = Path(__file__).resolve().parents[3] / "shared" / "examples" / "al_shyyab_2009.toml"

TINY = """
name = "two members on one shaft"
[[stages]]
id = "a"
teeth = { sun = 20, planet = 30, ring = 80 }
module_mm = 2.0
pressure_angle_deg = 20.0
planet_angles_deg = [0.0]
contact_ratio = 1.6
mesh_stiffness = 100.0
mesh_damping_ratio = 0.0
inertia = { sun = 0.002, ring = 0.05, carrier = 0.01, planet = 0.0005 }
planet_mass = 0.6

[[stages]]
id = "b"
teeth = { sun = 20, planet = 30, ring = 80 }
module_mm = 2.0
pressure_angle_deg = 20.0
planet_angles_deg = [0.0]
contact_ratio = 1.6
mesh_stiffness = 100.0
mesh_damping_ratio = 0.0
inertia = { sun = 0.003, ring = 0.05, carrier = 0.01, planet = 0.0005 }
planet_mass = 0.6

[[couplings]]
id = "shaft"
members = ["a.carrier", "b.sun"]
stiffness = 1.0e6
damping_ratio = 0.05

[housing]
free = 0.0

[gears.drive]
input = "a.sun"
output = "b.carrier"
brakes = ["a.ring", "b.ring"]
input_torque = 10.0
"""
"""Meshes of 100 N/m (torsional ``k r^2`` about 0.2 N m/rad) beside a 1e6 N m/rad shaft,
no mesh damping and no free-housing springs: the shaft's two members move alone in its
mode, so the closed form holds to about 1e-8 (measured: the frequency within 2e-8, the
ratio within 1e-8)."""


def quiet_load(text: str, source: str = "t.toml"):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", TrainWarning)
        return gj.loads_train(text, source=source)


@pytest.fixture(scope="module")
def wind():
    return gj.load_train(WIND)  # no warning of any kind: an ordinary train


def damped_eigenvalues(system) -> np.ndarray:
    """Eigenvalues (upper half plane) of ``M x'' + C_t x' + K_t x = 0``, ``C_t`` the
    coupling dampers plus the mesh dampers, ``K_t`` the mean stiffness: plain NumPy on
    the assembled matrices, independent of gearjax's solvers."""
    M = np.asarray(system.M)
    K = np.asarray(system.mean_stiffness())
    W = np.asarray(system.W)
    C = np.asarray(system.C) + (W.T * np.asarray(system.damping)) @ W
    n = M.shape[0]
    A = np.block([[np.zeros((n, n)), np.eye(n)],
                  [-np.linalg.solve(M, K), -np.linalg.solve(M, C)]])
    lam = np.linalg.eigvals(A)
    return lam[lam.imag > 0]


def nearest(lam: np.ndarray, w: float) -> complex:
    return lam[np.argmin(np.abs(np.abs(lam) - w))]


def ratio(lam: complex) -> float:
    return float(-lam.real / abs(lam))


# ------------------------------------------------------------------ assembled matrix


def test_wind_train_loads_with_its_damper(wind):
    (shaft,) = wind.couplings
    assert shaft.damping is None and float(shaft.damping_ratio) == 0.02
    s = gj.assemble(wind)
    i, j = s.dof_labels.index("low.sun"), s.dof_labels.index("mid.carrier")
    # J_1 = sun 0.30, J_2 = carrier I_c + N m_p r_c^2 = 8 + 3 * 36 * 0.171^2 (planets free
    # to spin on their bearings): c = 2 zeta sqrt(k J_1 J_2 / (J_1 + J_2))
    j1, j2 = 0.30, 8.0 + 3 * 36.0 * 0.171**2
    c = 2 * 0.02 * math.sqrt(4.0e6 * j1 * j2 / (j1 + j2))
    C = np.asarray(s.C)
    expected = np.zeros_like(C)
    expected[i, i] = expected[j, j] = c
    expected[i, j] = expected[j, i] = -c
    np.testing.assert_allclose(C, expected, rtol=1e-12, atol=0)
    assert c == pytest.approx(43.24, abs=0.01)


def test_paper_files_assemble_no_damping_bit_for_bit(paper_train):
    """Without a damper key, C is +0.0 in every bit, in every gear, as before the keys
    existed (the other fields were compared bit for bit with the previous version when
    the keys were added), and the file written back has no damper key."""
    trains = [paper_train]
    if SHARED.exists():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", TrainWarning)
            trains.append(gj.load_train(SHARED))
    for train in trains:
        assert all(c.damping is None and c.damping_ratio is None for c in train.couplings)
        written = tomllib.loads(gj.dumps_train(train))["couplings"]
        assert not any({"damping", "damping_ratio"} & set(c) for c in written)
        for gear in train.gear_names:
            C = np.asarray(gj.assemble(train, gear).C)
            assert C.tobytes() == np.zeros_like(C).tobytes(), gear


def test_open_clutch_adds_no_damping(paper_text):
    # the paper's lock-up clutch is engaged in third gear only
    text = mutate(paper_text, lambda r: r["couplings"][2].update(damping=50.0))
    train = quiet_load(text)
    assert not np.any(np.asarray(gj.assemble(train, "first").C))
    C = np.asarray(gj.assemble(train, "third").C)
    i, j = (gj.assemble(train, "third").dof_labels.index(m) for m in ("1.sun", "1.carrier"))
    assert C[i, i] == C[j, j] == 50.0 and C[i, j] == C[j, i] == -50.0
    assert np.count_nonzero(C) == 4


# ------------------------------------------------------------------ (a) the ratio


@pytest.mark.parametrize("zeta", [0.0, 0.05, 0.3])
def test_ratio_is_the_two_inertia_mode_ratio(zeta):
    """Where the coupling's members move alone, the mode of the damped train is the
    two-inertia oscillator: natural frequency sqrt(k / J_eq), damping ratio zeta."""
    train = gj.set_path(quiet_load(TINY), "couplings.shaft.damping_ratio", zeta)
    s = gj.assemble(train)
    j1 = 0.01 + 1 * 0.6 * (2.0 * (20 + 30) / 2 * 1e-3) ** 2  # a.carrier: I_c + N m_p r_c^2
    j2 = 0.003  # b.sun
    w = math.sqrt(1.0e6 * (j1 + j2) / (j1 * j2))
    lam = nearest(damped_eigenvalues(s), w)
    assert abs(lam) == pytest.approx(w, rel=1e-6)
    assert ratio(lam) == pytest.approx(zeta, abs=1e-7)


def test_wind_shaft_mode_damping(wind):
    """In the whole train the shaft mode (173.25 Hz) is not the two-inertia mode: the
    low-speed sun carries its stage's inertia through stiff meshes, so the ratio asked of
    the shaft's own mode, 0.02, gives that train mode 0.0056 (0.0058 with the mesh
    damping), in proportion to what is asked. The undamped modes do not move."""
    s = gj.assemble(wind)
    elastic = [m for m in gj.modes(s).modes if m.cls == "elastic"]
    shaft = elastic[0]
    assert shaft.hz == pytest.approx(173.25, abs=0.01)
    assert shaft.energy["elastic"] > 0.9  # the shaft's spring holds its strain energy
    w = 2 * math.pi * shaft.hz
    got = {}
    for zeta in (0.02, 0.04):
        t = gj.set_path(wind, "couplings.shaft.damping_ratio", zeta)
        st = gj.assemble(t)
        assert gj.modes(st).elastic_hz == pytest.approx(gj.modes(s).elastic_hz, rel=1e-12)
        alone = gj.system_from_matrices(st.M, st.C, st.K, st.W, st.kbar)  # no mesh dampers
        got[zeta] = (ratio(nearest(damped_eigenvalues(alone), w)),
                     ratio(nearest(damped_eigenvalues(st), w)))
    assert got[0.02][0] == pytest.approx(0.00559, abs=5e-5)
    assert got[0.02][1] == pytest.approx(0.00581, abs=5e-5)
    assert got[0.04][0] == pytest.approx(2 * got[0.02][0], rel=1e-3)


# ------------------------------------------------------------------ (b) harmonic balance


def test_hb_resonance_drops_as_the_sdof_estimate_says(wind):
    """A torque ripple on the rotor at the shaft mode's natural frequency, solved by the
    harmonic balance (mean stiffness: stiffness_harmonics = 0): the shaft's twist at
    resonance is |d_phi| |phi^T F| / (2 zeta omega^2) of that mode (mass-normalised
    shape phi, zeta from the complex eigenvalues), so four times the coupling damping
    lowers it by the ratio of the mode's total damping ratios (3.77 here, the mesh
    dampers adding 0.00023); both within 1e-4 (measured: 2e-7 and 4e-6)."""
    raw = tomllib.loads(WIND.read_text())
    raw["stiffness_harmonics"] = 0
    amplitude = 3000.0  # N m, about 1 % of the rated torque
    raw["gears"]["rated"]["input_torque_ripple"] = [[amplitude, 0.0, 9.0]]  # 9 per rev
    base = gj.loads_train(tomli_w.dumps(raw), source="wind")
    (k,) = gj.kinematics(base).ripple_mu  # the ripple is harmonic k of the base
    s0 = gj.assemble(base)
    lam, phi = scipy.linalg.eigh(np.asarray(s0.mean_stiffness()), np.asarray(s0.M))
    i, j = s0.dof_labels.index("low.sun"), s0.dof_labels.index("mid.carrier")
    mode = int(np.argmin(np.abs(np.sqrt(np.clip(lam, 0, None)) - 2 * math.pi * 173.25)))
    w = math.sqrt(lam[mode])
    twist_shape = abs(phi[i, mode] - phi[j, mode])
    force = abs(phi[s0.dof_labels.index("low.carrier"), mode]) * amplitude
    hb = gj.HarmonicBalance(n_harmonics=k + 1)
    got = {}
    for zeta in (0.01, 0.04):
        s = gj.assemble(gj.set_path(base, "couplings.shaft.damping_ratio", zeta))
        total = ratio(nearest(damped_eigenvalues(s), w))
        sol = gj.solve_hb_linear(gj.hb_problem(s, hb), w / k)
        assert bool(sol.converged)
        X = np.asarray(sol.X)
        twist = math.hypot(X[2 * k - 1, i] - X[2 * k - 1, j], X[2 * k, i] - X[2 * k, j])
        sdof = twist_shape * force / (2 * total * w**2)
        assert twist == pytest.approx(sdof, rel=1e-4), zeta
        got[zeta] = (total, twist)
    (za, ta), (zb, tb) = got[0.01], got[0.04]
    assert ta / tb == pytest.approx(zb / za, rel=1e-4)
    assert ta / tb == pytest.approx(3.77, abs=0.01)


# ------------------------------------------------------------------ gradients, paths


def test_damping_is_a_traced_leaf(wind):
    s = gj.assemble(wind)
    i, j = s.dof_labels.index("low.sun"), s.dof_labels.index("mid.carrier")

    def c_of(zeta):
        return gj.assemble(gj.set_path(wind, "couplings.shaft.damping_ratio", zeta)).C[i, i]

    j1, j2 = 0.30, 8.0 + 3 * 36.0 * 0.171**2
    exact = 2 * math.sqrt(4.0e6 * j1 * j2 / (j1 + j2))
    assert float(jax.grad(c_of)(0.02)) == pytest.approx(exact, rel=1e-12)
    # d c / d k through the ratio form: c / (2 k)
    d_k = jax.grad(lambda k: gj.assemble(gj.set_path(wind, "couplings.shaft.stiffness", k))
                   .C[i, j])(4.0e6)
    assert float(d_k) == pytest.approx(-0.02 * exact / (2 * 4.0e6), rel=1e-12)
    absolute = quiet_load(mutate(WIND.read_text(), _absolute(100.0)))
    d_c = jax.grad(lambda c: gj.assemble(gj.set_path(absolute, "couplings.shaft.damping", c))
                   .C[j, i])(100.0)
    assert float(d_c) == -1.0
    batch = jax.vmap(c_of)(jnp.array([0.01, 0.02]))
    np.testing.assert_allclose(np.asarray(batch), [0.01 * exact, 0.02 * exact], rtol=1e-12)


def _absolute(c):
    def change(raw):
        raw["couplings"][0].pop("damping_ratio")
        raw["couplings"][0]["damping"] = c
    return change


def test_paths_reach_the_damper(wind, paper_train):
    assert "couplings.shaft.damping_ratio" in gj.continuous_paths(wind)
    assert "couplings.shaft.damping" not in gj.continuous_paths(wind)
    assert "couplings.shaft.damping_ratio" in gj.continuous_paths(wind, "rated", linear=True)
    assert float(gj.get_path(wind, "couplings.0.damping_ratio")) == 0.02
    changed = gj.set_path(wind, "couplings.shaft.damping_ratio", 0.05)
    assert float(changed.couplings[0].damping_ratio) == 0.05
    assert not any("damping" in p for p in gj.continuous_paths(paper_train)
                   if p.startswith("couplings"))
    # a clutch left open in a gear: neither its stiffness nor its damper changes that gear
    damped = quiet_load(mutate(gj.bundled_example_path().read_text(),
                               lambda r: r["couplings"][2].update(damping=5.0)))
    assert "couplings.lockup.damping" in gj.continuous_paths(damped, "third")
    assert "couplings.lockup.damping" not in gj.continuous_paths(damped, "first")


@pytest.mark.parametrize(
    "path, rule",
    [
        ("couplings.shaft.damping", "coupling 'shaft' gives its damper as damping_ratio, not "
                                    "damping: vary couplings.shaft.damping_ratio"),
        ("couplings.shaft.viscosity", "a coupling's parameters are stiffness, and damping or"),
    ],
)
def test_bad_damper_paths(wind, path, rule):
    with pytest.raises(TrainError) as info:
        gj.get_path(wind, path)
    message = str(info.value)
    assert "\n" not in message and message.startswith(f"argument path = {path!r}: ")
    assert rule in message


def test_paper_coupling_has_no_damper_path(paper_train):
    with pytest.raises(TrainError, match="has no damper; set damping"):
        gj.set_path(paper_train, "couplings.0.damping", 1.0)


# ------------------------------------------------------------------ (c) refusals


def refuse(text, field, value, *words):
    return train_refusals.refuse(lambda t: gj.loads_train(t, source=SOURCE), text, field,
                                 value, *words, value_at_field=True)


def _coupling(**keys):
    return lambda r: r["couplings"][0].update(keys)


@pytest.mark.parametrize(
    "change, field, value, words",
    [
        (_coupling(damping=10.0, damping_ratio=0.02), "couplings[0].damping_ratio", "0.02",
         ("damping is given too", "not both")),
        (_coupling(damping=-1.0), "couplings[0].damping", "-1.0", ("must be >= 0",)),
        (_coupling(damping_ratio=-0.01), "couplings[0].damping_ratio", "-0.01",
         ("must be >= 0",)),
        (_coupling(damping_ratio=1.0), "couplings[0].damping_ratio", "1.0",
         ("< 1", "over-critically")),
        (_coupling(damping_ratio=2.5), "couplings[0].damping_ratio", "2.5", ("< 1",)),
        (_coupling(damping=1e13), "couplings[0].damping", "10000000000000.0",
         ("<= 1e+12 N m s/rad",)),
        (_coupling(damping="10"), "couplings[0].damping", "'10'", ("finite number",)),
        (_coupling(damping_ratio=float("nan")), "couplings[0].damping_ratio", "nan",
         ("finite number",)),
        (_coupling(damping_ratio=True), "couplings[0].damping_ratio", "True",
         ("finite number",)),
    ],
)
def test_refusals(paper_text, change, field, value, words):
    refuse(mutate(paper_text, change), field, value, *words)


def test_code_built_train_with_both_refused(wind):
    shaft = dataclasses.replace(wind.couplings[0], damping=jnp.asarray(10.0))
    both = dataclasses.replace(wind, couplings=(shaft,))
    with pytest.raises(TrainError, match=r"couplings\[0\]\.damping_ratio = 0\.02: damping is "
                                         r"given too"):
        gj.validate_train(both, emit_warnings=False)


def test_unusual_dampers_warned(paper_text):
    def notes(text):
        with warnings.catch_warnings(record=True) as record:
            warnings.simplefilter("always")
            gj.loads_train(text, source=SOURCE)
        return [str(w.message) for w in record if issubclass(w.category, RangeWarning)]

    high = notes(mutate(paper_text, _coupling(damping_ratio=0.5)))
    assert len(high) == 1 and "couplings[0].damping_ratio = 0.5: above the usual 0.3" in high[0]
    # the paper's coupling 1.carrier-2.ring, k = 1e8 N m/rad: J_1 = I_c + 4 m_p r_c^2 with
    # r_c = 1.5 mm (30 + 28) / 2, J_2 = the ring 2 inertia
    raw = tomllib.loads(paper_text)
    one, two = raw["stages"]
    j1 = one["inertia"]["carrier"] + 4 * one["planet_mass"] * (1.5e-3 * (30 + 28) / 2) ** 2
    j2 = two["inertia"]["ring"]
    critical = 2 * math.sqrt(1e8 * j1 * j2 / (j1 + j2))
    over = notes(mutate(paper_text, _coupling(damping=2 * critical)))
    assert len(over) == 1, over
    assert f"{critical:.4g} N m s/rad" in over[0] and "over-critical" in over[0]
    assert "damping ratio of 2" in over[0] and "data kept as given" in over[0]
    assert notes(mutate(paper_text, _coupling(damping=0.5 * critical))) == []
    assert notes(mutate(paper_text, _coupling(damping=0.0))) == []


# ------------------------------------------------------------------ (d) round trip


@pytest.mark.parametrize("change", [None, _absolute(123.5), _absolute(0.0)])
def test_round_trip(change):
    text = WIND.read_text() if change is None else mutate(WIND.read_text(), change)
    train = gj.loads_train(text, source="wind")
    again = gj.loads_train(gj.dumps_train(train), source="wind")
    for a, b in zip(train.couplings, again.couplings):
        for key in ("stiffness", "damping", "damping_ratio"):
            va, vb = getattr(a, key), getattr(b, key)
            assert (va is None) == (vb is None), key
            if va is not None:
                assert float(va) == float(vb), key
    assert jax.tree_util.tree_structure(train) == jax.tree_util.tree_structure(again)
    np.testing.assert_array_equal(np.asarray(gj.assemble(train).C),
                                  np.asarray(gj.assemble(again).C))
    written = tomllib.loads(gj.dumps_train(train))["couplings"][0]
    assert ("damping_ratio" in written) == (change is None)
    assert ("damping" in written) == (change is not None)
