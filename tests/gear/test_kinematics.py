"""Kinematics against hand formulas: Willis equation, ratios, mesh frequencies, mu.

Every expected value here is worked out by hand from the tooth counts (exact
fractions), never read back from gearjax.
"""

from __future__ import annotations

import math
import tomllib
import warnings
from fractions import Fraction

import pytest
import tomli_w

import gearjax as gj
from gearjax._gear.kinematics import require_base


def single_stage(teeth, n_planets, gear, ripple=None) -> gj.Train:
    """A one-stage train from TOML text; ``gear`` is the body of ``[gears.g]``."""
    zs, zp, zr = teeth
    angles = [360.0 * i / n_planets for i in range(n_planets)]
    ripple_line = f"input_torque_ripple = {ripple}\n" if ripple is not None else ""
    text = f"""
[[stages]]
id = "1"
teeth = {{ sun = {zs}, planet = {zp}, ring = {zr} }}
module_mm = 2.0
pressure_angle_deg = 20.0
planet_angles_deg = {angles}
contact_ratio = {{ sun = 1.6, ring = 1.8 }}
mesh_stiffness = {{ sun = 4.0e8, ring = 5.0e8 }}
inertia = {{ sun = 2.0e-4, ring = 4.0e-3, carrier = 3.0e-3, planet = 6.0e-5 }}
planet_mass = 0.25

[gears.g]
{gear}
input_torque = 100.0
{ripple_line}"""
    return gj.loads_train(text, source="x.toml")


# concentric (Z_r = Z_s + 2 Z_p), assemblable and non-overlapping for the planet count
TEETH = [((24, 18, 60), 3), ((20, 31, 82), 3), ((20, 30, 80), 4), ((36, 24, 84), 5)]

RING_FIXED = 'input = "1.sun"\noutput = "1.carrier"\nbrakes = ["1.ring"]'
SUN_FIXED = 'input = "1.ring"\noutput = "1.carrier"\nbrakes = ["1.sun"]'
CARRIER_FIXED = 'input = "1.sun"\noutput = "1.ring"\nbrakes = ["1.carrier"]'


@pytest.mark.parametrize("teeth,n", TEETH)
def test_ring_fixed_sun_in_carrier_out(teeth, n):
    zs, zp, zr = teeth
    kin = gj.kinematics(single_stage(teeth, n, RING_FIXED))
    assert isinstance(kin.ratio, Fraction)
    assert kin.ratio == 1 + Fraction(zr, zs)
    st = kin.stage("1")
    wc = Fraction(zs, zs + zr)
    assert (st.sun, st.ring, st.carrier) == (1, 0, wc)
    # mesh cycles per input revolution: Z_r |w_r - w_c|
    assert st.mesh_frequency == zr * wc
    assert st.sigma == 1  # the sun turns faster than the carrier
    # rigid statics: the sun takes the unit input torque, Z_s L = 1
    assert st.load == Fraction(1, zs)
    assert st.loaded
    assert kin.mu == (1,)
    assert kin.base == zr * wc


@pytest.mark.parametrize("teeth,n", TEETH)
def test_sun_fixed_ring_in_carrier_out(teeth, n):
    zs, zp, zr = teeth
    kin = gj.kinematics(single_stage(teeth, n, SUN_FIXED))
    assert kin.ratio == Fraction(zr + zs, zr) == 1 + Fraction(zs, zr)
    st = kin.stage("1")
    wc = Fraction(zr, zr + zs)
    assert (st.sun, st.ring, st.carrier) == (0, 1, wc)
    assert st.mesh_frequency == zr * (1 - wc)
    assert st.sigma == -1  # sun at rest, carrier turning forwards
    assert st.loaded
    assert kin.mu == (1,)


@pytest.mark.parametrize("teeth,n", TEETH)
def test_carrier_fixed_is_a_reversing_train(teeth, n):
    zs, zp, zr = teeth
    kin = gj.kinematics(single_stage(teeth, n, CARRIER_FIXED))
    assert kin.ratio == -Fraction(zr, zs)
    st = kin.stage("1")
    assert (st.sun, st.ring, st.carrier) == (1, -Fraction(zs, zr), 0)
    # with the carrier at rest the mesh frequency is Z_s times the sun speed
    assert st.mesh_frequency == zs
    assert st.sigma == 1
    assert st.loaded


@pytest.mark.parametrize("gear", [RING_FIXED, SUN_FIXED, CARRIER_FIXED])
@pytest.mark.parametrize("teeth,n", TEETH)
def test_planet_speed_matches_both_meshes(teeth, n, gear):
    zs, zp, zr = teeth
    st = gj.kinematics(single_stage(teeth, n, gear)).stage("1")
    # planet speed relative to the carrier, from the sun mesh and from the ring mesh
    assert zp * st.planet_speed == -zs * (st.sun - st.carrier)
    assert zp * st.planet_speed == zr * (st.ring - st.carrier)
    # mesh frequency seen from the planet: Z_p |w_p - w_c| is the same tooth-pass rate
    assert st.mesh_frequency == zp * abs(st.planet_speed)


# ------------------------------------------------------------------ the paper's train


@pytest.fixture(scope="module")
def train(paper_train):
    """The bundled paper case (conftest's ``paper_train``)."""
    return paper_train


def hand_speeds_first():
    """First gear by hand: sun 1 = 1, sun 2 = 0, c1 = r2, c2 = r1 = output.

    Stage 2 (sun at rest): 80 (r2 - c2) = 44 c2 -> r2 = 124/80 c2 = 31/20 c2.
    Stage 1: 30 (1 - c1) + 70 (r1 - c1) = 0 with c1 = 31/20 c2, r1 = c2:
    30 - 155 c2 + 70 c2 = 0 -> c2 = 30/85 = 6/17.
    """
    c2 = Fraction(6, 17)
    r2 = Fraction(31, 20) * c2
    return {"1.sun": Fraction(1), "1.ring": c2, "1.carrier": r2,
            "2.sun": Fraction(0), "2.ring": r2, "2.carrier": c2}


def test_paper_first_gear_speeds_by_hand(train):
    kin = gj.kinematics(train, "first")
    assert kin.speeds == hand_speeds_first()
    assert kin.ratio == Fraction(17, 6)
    assert kin.ratio == Fraction(2125, 750)  # model.md: 2125 / 750


@pytest.mark.parametrize("gear,ratio", [
    ("first", Fraction(17, 6)),
    ("second", Fraction(31, 20)),
    ("third", Fraction(1)),
    ("fourth", Fraction(7, 10)),
    ("reverse", Fraction(-7, 3)),
])
def test_paper_gear_ratios_exact(train, gear, ratio):
    kin = gj.kinematics(train, gear)
    assert isinstance(kin.ratio, Fraction)
    assert kin.ratio == ratio


@pytest.mark.parametrize("gear", ["first", "second", "third", "fourth", "reverse"])
def test_paper_willis_and_planet_speed_every_gear(train, gear):
    kin = gj.kinematics(train, gear)
    for s, st in zip(train.stages, kin.stages):
        zs, zp, zr = s.teeth.sun, s.teeth.planet, s.teeth.ring
        assert zs * (st.sun - st.carrier) + zr * (st.ring - st.carrier) == 0
        assert zp * st.planet_speed == -zs * (st.sun - st.carrier)
        assert zp * st.planet_speed == zr * (st.ring - st.carrier)
        assert st.mesh_frequency == zr * abs(st.ring - st.carrier)
        assert st.sigma == (st.sun > st.carrier) - (st.sun < st.carrier)
    for b in train.gear(gear).brakes:
        assert kin.speeds[b] == 0
    for c in train.engaged_couplings(gear):
        assert kin.speeds[c.members[0]] == kin.speeds[c.members[1]]
    assert kin.speeds[train.gear(gear).input] == 1


def test_paper_first_gear_mu_and_mesh_frequencies(train):
    kin = gj.kinematics(train, "first")
    c2 = Fraction(6, 17)
    c1 = Fraction(31, 20) * c2
    f1 = 70 * abs(c2 - c1)  # Z_r1 |w_r1 - w_c1| = 231/17 per input revolution
    f2 = 80 * abs(c1 - c2)  # Z_r2 |w_r2 - w_c2| = 264/17
    assert (f1, f2) == (Fraction(231, 17), Fraction(264, 17))
    assert kin.stage("1").mesh_frequency == f1
    assert kin.stage("2").mesh_frequency == f2
    # w_2 / w_1 = Z_r2 / Z_r1 = 8/7 -> mu = (7, 8), Omega = w_1 / 7
    assert kin.mu == (7, 8)
    assert kin.base == f1 / 7 == f2 / 8
    assert kin.mesh_frequency_hz("1", 1000.0) == pytest.approx(float(f1) * 1000 / 60, rel=1e-12)
    assert kin.mesh_frequency_hz("1", 1000.0) == pytest.approx(226.47, abs=0.005)
    assert kin.mesh_frequency_hz("2", 1000.0) == pytest.approx(258.82, abs=0.005)
    assert kin.input_rpm("1", 226.4705882352941) == pytest.approx(1000.0, rel=1e-12)


def test_paper_third_gear_turns_as_a_block(train):
    kin = gj.kinematics(train, "third")
    assert all(w == 1 for w in kin.speeds.values())
    assert all(st.mesh_frequency == 0 for st in kin.stages)
    assert kin.mu is None
    assert kin.base is None
    with pytest.raises(gj.TrainError, match="no mesh turns"):
        require_base(kin, "x.toml")


@pytest.mark.parametrize("gear,loaded", [
    ("first", (True, True)),
    ("second", (False, True)),
    ("fourth", (True, False)),
    ("reverse", (True, False)),
])
def test_paper_loaded_stages(train, gear, loaded):
    kin = gj.kinematics(train, gear)
    assert tuple(st.loaded for st in kin.stages) == loaded
    for st, on in zip(kin.stages, loaded):
        if not on:
            assert st.load == 0


def test_paper_first_gear_rigid_loads_by_hand(train):
    """Per unit input torque: sun 1 alone, Z_s1 L1 = 1; shaft c1-r2: -(30+70) L1 + 80 L2 = 0;
    shaft c2-r1 (output): 70 L1 - (44+80) L2 = -ratio."""
    kin = gj.kinematics(train, "first")
    L1, L2 = Fraction(1, 30), Fraction(100, 30 * 80)
    assert 70 * L1 - 124 * L2 == -Fraction(17, 6)
    assert kin.stage("1").load == L1
    assert kin.stage("2").load == L2 == Fraction(1, 24)


def test_fourth_gear_is_overdrive_with_negative_stage_one_load(train):
    """Fourth: c1 input, sun 1 braked: 30 (0 - 1) + 70 (r1 - 1) = 0 -> r1 = c2 = 10/7."""
    kin = gj.kinematics(train, "fourth")
    assert kin.speeds["2.carrier"] == Fraction(10, 7)
    assert kin.stage("1").load == Fraction(-1, 100)  # group c1-r2 (input): -100 L1 + 80*0 = 1


def with_first_gear_ripple(train_text: str, rows) -> gj.Train:
    raw = tomllib.loads(train_text)
    raw["gears"]["first"]["input_torque_ripple"] = rows
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gj.GeometryWarning)
        return gj.loads_train(tomli_w.dumps(raw), source="x.toml")


def test_ripple_order_joins_mu_paper_first_gear():
    """Order 1 with mesh frequencies 231/17 and 264/17 per revolution:
    gcd(231/17, 264/17, 17/17) = gcd(231, 264, 17)/17 = 1/17 -> mu = (231, 264), ripple 17."""
    text = gj.bundled_example_path().read_text()
    kin = gj.kinematics(with_first_gear_ripple(text, [[5.0, 0.0, 1.0]]), "first")
    assert math.gcd(math.gcd(231, 264), 17) == 1
    assert kin.base == Fraction(1, 17)
    assert kin.mu == (231, 264)
    assert kin.ripple_mu == (17,)
    # 264 harmonics of the base is more than a solver accepts: refused, naming mu
    with pytest.raises(gj.TrainError, match="231, 264"):
        require_base(kin, "x.toml")


def test_ripple_order_on_the_base_keeps_mu():
    """Order 33 (per input revolution): gcd(231/17, 264/17, 561/17) = gcd(231, 264, 561)/17
    = 33/17, the mesh-only base, so mu stays (7, 8) and the ripple is harmonic 561/33 = 17."""
    assert math.gcd(math.gcd(231, 264), 561) == 33
    text = gj.bundled_example_path().read_text()
    kin = gj.kinematics(with_first_gear_ripple(text, [[5.0, 0.0, 33.0]]), "first")
    assert kin.base == Fraction(33, 17)
    assert kin.mu == (7, 8)
    assert kin.ripple_mu == (17,)  # 33 / (33/17)


@pytest.mark.parametrize("order,base,mu,ripple_mu", [
    # ring fixed 20/30/80: mesh = 80 * 20/100 = 16 cycles per input revolution
    (4, Fraction(4), (4,), (1,)),
    (3, Fraction(1), (16,), (3,)),
    (32, Fraction(16), (1,), (2,)),
])
def test_ripple_order_single_stage(order, base, mu, ripple_mu):
    train = single_stage((20, 30, 80), 4, RING_FIXED, ripple=[[2.0, 0.0, order]])
    kin = gj.kinematics(train)
    assert kin.stage("1").mesh_frequency == 16
    assert kin.base == base
    assert kin.mu == mu
    assert kin.ripple_mu == ripple_mu
