"""Impossible train input is refused with one line naming file, field, value and rule.

Every case starts from the bundled paper case and breaks one thing. Geometry rules
that published data break (concentricity, assembly) are warnings with the numbers.
"""

from __future__ import annotations

import dataclasses
import math
import warnings

import pytest

import gearjax
from gearjax import GeometryWarning, TrainError

import train_refusals
from train_refusals import SOURCE, mutate


def load(text: str):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GeometryWarning)
        return gearjax.loads_train(text, source=SOURCE)


def refuse(text: str, field: str, value: str, *words: str) -> str:
    """Load ``text``, expect a TrainError and check its one-line message."""
    return train_refusals.refuse(load, text, field, value, *words)


def test_train_error_is_value_error():
    assert issubclass(TrainError, ValueError)


def test_bundled_example_is_valid(paper_text):
    train = load(paper_text)
    assert train.stage_ids == ("1", "2")
    assert train.source == SOURCE


# ------------------------------------------------------------------ member paths


@pytest.mark.parametrize(
    "where, change, field, value",
    [
        ("brake", lambda r: r["gears"]["first"].update(brakes=["3.sun"]),
         "gears.first.brakes", "'3.sun'"),
        ("output", lambda r: r["gears"]["first"].update(output="1.planet"),
         "gears.first.output", "'1.planet'"),
        ("input", lambda r: r["gears"]["second"].update(input="1.shaft"),
         "gears.second.input", "'1.shaft'"),
        ("coupling", lambda r: r["couplings"][0].update(members=["1.carrier", "3.ring"]),
         "couplings[0].members", "'3.ring'"),
        ("no stage", lambda r: r["gears"]["first"].update(brakes=["sun"]),
         "gears.first.brakes", "'sun'"),
    ],
)
def test_unknown_member_path(paper_text, where, change, field, value):
    msg = refuse(mutate(paper_text, change), field, value, "unknown member path")
    assert "'1'" in msg and "'2'" in msg  # names the stages that exist


def test_clutch_names_missing_gear(paper_text):
    def change(r):
        lockup = next(c for c in r["couplings"] if c.get("id") == "lockup")
        lockup["gears"] = ["third", "fifth"]

    msg = refuse(mutate(paper_text, change), "couplings[2]", "'fifth'", "does not exist")
    assert "lockup" in msg and "third" in msg  # the coupling's id and the gears that exist


def test_braked_input_or_output_refused(paper_text):
    refuse(mutate(paper_text, lambda r: r["gears"]["first"].update(brakes=["2.sun", "2.carrier"])),
           "gears.first.brakes", "'2.carrier'", "cannot be braked")


def test_output_equal_to_input_refused(paper_text):
    refuse(mutate(paper_text, lambda r: r["gears"]["first"].update(output="1.sun")),
           "gears.first.output", "'1.sun'", "differ")


# ------------------------------------------------------------------ teeth


@pytest.mark.parametrize("member, teeth", [("sun", 0), ("planet", -3), ("ring", 0)])
def test_teeth_below_one(paper_text, member, teeth):
    msg = refuse(mutate(paper_text, lambda r: r["stages"][0]["teeth"].update({member: teeth})),
                 f"1.teeth.{member}", f"= {teeth}:", ">= 1")
    assert "teeth" in msg


@pytest.mark.parametrize("teeth, shown", [(30.5, "30.5"), (30.0, "30.0"), ("30", "'30'")])
def test_teeth_not_integer(paper_text, teeth, shown):
    refuse(mutate(paper_text, lambda r: r["stages"][1]["teeth"].update(sun=teeth)),
           "2.teeth.sun", f"= {shown}:", "integer")


# ------------------------------------------------------------------ single-value rules


@pytest.mark.parametrize("side, value", [("sun", 0.9), ("ring", 0.0), ("sun", -1.25)])
def test_contact_ratio_below_one(paper_text, side, value):
    refuse(mutate(paper_text, lambda r: r["stages"][0]["contact_ratio"].update({side: value})),
           f"1.contact_ratio.{side}", repr(value), ">= 1")


@pytest.mark.parametrize("side, value", [("sun", 0.0), ("ring", -4.4e8)])
def test_mesh_stiffness_not_positive(paper_text, side, value):
    refuse(mutate(paper_text, lambda r: r["stages"][1]["mesh_stiffness"].update({side: value})),
           f"2.mesh_stiffness.{side}", repr(value), "> 0")


@pytest.mark.parametrize("key, value", [("braked", -1.0e10), ("free", -1.0)])
def test_housing_stiffness_negative(paper_text, key, value):
    refuse(mutate(paper_text, lambda r: r["housing"].update({key: value})),
           f"housing.{key}", repr(value), ">= 0")


def test_housing_free_may_be_zero(paper_text):
    train = load(mutate(paper_text, lambda r: r["housing"].update(free=0.0)))
    assert float(train.housing.free) == 0.0


def test_coupling_stiffness_negative(paper_text):
    refuse(mutate(paper_text, lambda r: r["couplings"][0].update(stiffness=-1.0e8)),
           "couplings[0].stiffness", repr(-1.0e8), ">= 0")


@pytest.mark.parametrize("member", ["sun", "ring", "carrier", "planet"])
@pytest.mark.parametrize("value", [0.0, -1e-4])
def test_inertia_not_positive(paper_text, member, value):
    refuse(mutate(paper_text, lambda r: r["stages"][0]["inertia"].update({member: value})),
           f"1.inertia.{member}", repr(value), "> 0")


@pytest.mark.parametrize("value", [0.0, -0.35])
def test_planet_mass_not_positive(paper_text, value):
    refuse(mutate(paper_text, lambda r: r["stages"][1].update(planet_mass=value)),
           "2.planet_mass", repr(value), "> 0")


@pytest.mark.parametrize("value", [0.0, -1.5])
def test_module_not_positive(paper_text, value):
    refuse(mutate(paper_text, lambda r: r["stages"][1].update(module_mm=value)),
           "2.module_mm", repr(value), "> 0")


# ------------------------------------------------------------------ planet angles


@pytest.mark.parametrize(
    "angles, shown",
    [
        ([10, 90, 180, 270], "[10.0, 90.0, 180.0, 270.0]"),       # does not start at 0
        ([0, 180, 90, 270], "[0.0, 180.0, 90.0, 270.0]"),         # not increasing
        ([0, 90, 90, 270], "[0.0, 90.0, 90.0, 270.0]"),           # repeated angle
        ([0, 90, 180, 360], "[0.0, 90.0, 180.0, 360.0]"),         # a whole turn
    ],
)
def test_planet_angles_rule(paper_text, angles, shown):
    refuse(mutate(paper_text, lambda r: r["stages"][0].update(planet_angles_deg=angles)),
           "1.planet_angles_deg", shown, "start at 0", "increase strictly")


def test_no_planet_refused(paper_text):
    refuse(mutate(paper_text, lambda r: r["stages"][0].update(planet_angles_deg=[])),
           "1.planet_angles_deg", "[]", "planet")


def test_overlapping_planets(paper_text):
    # Stage 1: m = 1.5 mm, Z_s = 30, Z_p = 28, so r_c = 1.5 (30 + 28) / 2 = 43.5 mm.
    # Six planets 60 deg apart: 2 r_c sin(30 deg) = 43.5 mm <= m (Z_p + 2) = 45 mm.
    rc, tip = 1.5 * (30 + 28) / 2, 1.5 * (28 + 2)
    assert 2 * rc * math.sin(math.radians(60) / 2) <= tip
    angles = [0, 60, 120, 180, 240, 300]
    msg = refuse(mutate(paper_text, lambda r: r["stages"][0].update(planet_angles_deg=angles)),
                 "1.planet_angles_deg", "[0.0, 60.0, 120.0, 180.0, 240.0, 300.0]", "overlap")
    assert "43.5" in msg and "45" in msg


def test_five_planets_do_not_overlap(paper_text):
    # 72 deg apart: 2 * 43.5 * sin(36 deg) = 51.1 mm > 45 mm; (30 + 70) 72 / 360 = 20
    rc, tip = 1.5 * (30 + 28) / 2, 1.5 * (28 + 2)
    assert 2 * rc * math.sin(math.radians(72) / 2) > tip
    train = load(mutate(paper_text, lambda r: r["stages"][0].update(
        planet_angles_deg=[0, 72, 144, 216, 288])))
    assert train.stages[0].n_planets == 5


def test_overlap_uses_given_carrier_radius(paper_text):
    # Four planets fit at the default radius but not at r_c = 30 mm:
    # 2 * 30 * sin(45 deg) = 42.4 mm <= 45 mm.
    msg = refuse(mutate(paper_text, lambda r: r["stages"][0].update(carrier_radius_mm=30.0)),
                 "1.planet_angles_deg", "[0.0, 90.0, 180.0, 270.0]", "overlap")
    assert "42.43" in msg


# ------------------------------------------------------------------ kinematics


def test_gear_undetermined(paper_text):
    # First gear without its brake: two Willis equations, two shafts, the input speed:
    # five equations for six speeds, so one degree of freedom is left.
    msg = refuse(mutate(paper_text, lambda r: r["gears"]["first"].update(brakes=[])),
                 "gears.first", "brakes []", "undetermined")
    assert "1.sun" in msg  # the input is named in the value


def test_gear_locks_train_two_brakes_on_stage_one(paper_text):
    # Stage 1 Willis: 30 (w_s - w_c) + 70 (w_r - w_c) = 0. Braking ring 1 and carrier 1
    # forces w_s = 0, but the input 1.sun turns at 1: no solution.
    refuse(mutate(paper_text, lambda r: r["gears"]["first"].update(brakes=["1.ring", "1.carrier"])),
           "gears.first", "1.ring", "lock")


def test_gear_locks_train_through_shafts(paper_text):
    # Brake 2.sun and 1.ring: 1.ring = 2.carrier = 0 and 2.sun = 0, so stage 2 is held
    # (w_r2 = 0), hence 1.carrier = 2.ring = 0 too; stage 1 then forces w_s1 = 0,
    # contradicting the input speed 1 on 1.sun.
    refuse(mutate(paper_text, lambda r: r["gears"]["first"].update(
        output="1.carrier", brakes=["2.sun", "1.ring"])),
        "gears.first", "2.sun", "lock")


def test_output_held_still(paper_text):
    # Input 1.sun, brake 1.ring: the shaft 1.ring = 2.carrier is held, so the output
    # 2.carrier does not turn (stage 1 still turns: w_c1 = 30 / 100) and the ratio is undefined.
    refuse(mutate(paper_text, lambda r: r["gears"]["first"].update(brakes=["1.ring"])),
           "gears.first.output", "'2.carrier'", "held still")


# ------------------------------------------------------------------ file format


def test_unknown_key(paper_text):
    bad = paper_text.replace("mesh_stiffness = { sun = 4.5e8", "mesh_stifness = { sun = 4.5e8")
    assert bad != paper_text
    msg = refuse(bad, "stages[0]", "'mesh_stifness'", "unknown key")
    assert "mesh_stiffness" in msg  # lists the known keys


@pytest.mark.parametrize(
    "change, field, value",
    [
        (lambda r: r.update(stifness_harmonics=4), "file", "'stifness_harmonics'"),
        (lambda r: r["housing"].update(brake=1e10), "housing", "'brake'"),
        (lambda r: r["gears"]["first"].update(break_=["2.sun"]), "gears.first", "'break_'"),
        (lambda r: r["couplings"][0].update(stiff=1e8), "couplings[0]", "'stiff'"),
        (lambda r: r["stages"][1]["inertia"].update(sunn=1e-3), "2.inertia", "'sunn'"),
    ],
)
def test_unknown_key_elsewhere(paper_text, change, field, value):
    refuse(mutate(paper_text, change), field, value, "unknown key")


def test_invalid_toml(paper_text):
    with pytest.raises(TrainError) as info:
        load(paper_text + "\n[[[broken\n")
    msg = str(info.value)
    assert "\n" not in msg
    assert msg.startswith("bad.toml: ")
    assert "TOML" in msg and "line" in msg


@pytest.mark.parametrize(
    "change, field",
    [
        (lambda r: r["stages"][0].pop("planet_mass"), "1.planet_mass"),
        (lambda r: r["stages"][0].pop("teeth"), "1.teeth"),
        (lambda r: r["stages"][1]["teeth"].pop("ring"), "2.teeth.ring"),
        (lambda r: r["stages"][1]["inertia"].pop("carrier"), "2.inertia.carrier"),
        (lambda r: r["stages"][0].pop("mesh_stiffness"), "1.mesh_stiffness"),
        (lambda r: r["gears"]["first"].pop("input"), "gears.first.input"),
        (lambda r: r["gears"]["first"].pop("input_torque"), "gears.first.input_torque"),
        (lambda r: r["couplings"][0].pop("stiffness"), "couplings[0].stiffness"),
        (lambda r: r.pop("gears"), "gears"),
        (lambda r: r.pop("stages"), "stages"),
    ],
)
def test_missing_required_key(paper_text, change, field):
    refuse(mutate(paper_text, change), field, "(missing)", "required")


@pytest.mark.parametrize(
    "key, value, option",
    [("phasing", "exact", "physical"), ("phasing", "Paper", "paper"),
     ("mesh_damping", "never", "contact")],
)
def test_option_not_allowed(paper_text, key, value, option):
    refuse(mutate(paper_text, lambda r: r.update({key: value})), key, repr(value), option)


def test_wrong_type(paper_text):
    refuse(mutate(paper_text, lambda r: r["stages"][0].update(module_mm="1.5")),
           "1.module_mm", "'1.5'", "number")


def test_duplicate_stage_id(paper_text):
    refuse(mutate(paper_text, lambda r: r["stages"][1].update(id="1")),
           "stages[1].id", "'1'", "unique")


# ------------------------------------------------------------------ geometry warnings


def test_concentricity_warning_for_published_stage_one(paper_text):
    with pytest.warns(GeometryWarning) as record:
        gearjax.loads_train(paper_text, source=SOURCE)
    messages = [str(w.message) for w in record if issubclass(w.category, GeometryWarning)]
    concentric = [m for m in messages if "concentricity" in m]
    assert len(concentric) == 1  # stage 2 (44 + 2*18 = 80) is concentric
    m = concentric[0]
    assert "\n" not in m
    assert m.startswith(SOURCE)
    assert "'1'" in m and "86" in m and "70" in m
    assert not any("assembly" in x for x in messages)  # 100*90/360 and 124*90/360 are integers


def test_assembly_warning(paper_text):
    # Stage 2: (44 + 80) * 100 / 360 = 34.44 and (44 + 80) * 200 / 360 = 68.89.
    bad = mutate(paper_text, lambda r: r["stages"][1].update(planet_angles_deg=[0, 100]))
    with pytest.warns(GeometryWarning) as record:
        train = gearjax.loads_train(bad, source=SOURCE)
    (one,) = [str(w.message) for w in record if "assembly" in str(w.message)]
    assert "'2'" in one and "planet 2 at 100 deg" in one and "124*100/360 = 34.44" in one
    assert train.stages[1].n_planets == 2


def test_planets_breaking_the_assembly_rule_make_one_line_per_stage(paper_text):
    """Nine planets 40 deg apart on stage 2: eight break the rule (124 * 40 / 360 =
    13.78): one warning for the stage, the count, the first planets with their numbers."""
    nine = [40.0 * i for i in range(9)]
    bad = mutate(paper_text, lambda r: r["stages"][1].update(planet_angles_deg=nine))
    with pytest.warns(GeometryWarning) as record:
        train = gearjax.loads_train(bad, source=SOURCE)
    (one,) = [str(w.message) for w in record if "assembly" in str(w.message)]
    assert one.startswith(f"{SOURCE}: stage '2': 8 of 9 planets break the assembly rule")
    assert "planets 2 at 40 deg (13.78), 3 at 80 deg (27.56)" in one
    assert one.endswith("and 4 more") and "\n" not in one
    assert train.stages[1].n_planets == 9


def test_bundled_example_keeps_published_teeth():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GeometryWarning)
        train = gearjax.load_train()
    t1, t2 = train.stages[0].teeth, train.stages[1].teeth
    assert (t1.sun, t1.planet, t1.ring) == (30, 28, 70)
    assert (t2.sun, t2.planet, t2.ring) == (44, 18, 80)


def test_validate_train_returns_warnings_without_emitting(paper_text):
    train = gearjax.loads_train(paper_text, source=SOURCE, validate=False)
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always")
        messages = gearjax.validate_train(train, emit_warnings=False)
    assert not [w for w in record if issubclass(w.category, GeometryWarning)]
    assert isinstance(messages, list) and len(messages) == 1
    assert all(isinstance(m, str) for m in messages)
    assert "86" in messages[0] and "70" in messages[0]
    assert messages == gearjax.geometry_warnings(train)
    with pytest.warns(GeometryWarning):
        assert gearjax.validate_train(train) == messages


def test_validate_train_refuses_code_built_train(paper_text):
    # A train changed in code (not read from a file) is checked the same way.
    train = gearjax.loads_train(paper_text, source=SOURCE, validate=False)
    first = dataclasses.replace(train.gears[0], brakes=())
    bad = dataclasses.replace(train, gears=(first,) + train.gears[1:])
    with pytest.raises(TrainError, match="undetermined"):
        gearjax.validate_train(bad, emit_warnings=False)
