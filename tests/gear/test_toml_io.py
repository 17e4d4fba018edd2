"""Train files: the shared and bundled examples, defaults, and the TOML round trip."""

from __future__ import annotations

import dataclasses
import tomllib
import warnings
from pathlib import Path

import jax
import numpy as np
import pytest
import tomli_w

import gearjax
from gearjax import GeometryWarning

SHARED = Path(__file__).resolve().parents[3] / "shared" / "examples" / "al_shyyab_2009.toml"


def quiet(fn, *args, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GeometryWarning)
        return fn(*args, **kwargs)


def assert_trees_equal(a, b):
    """Same static structure (ids, teeth, paths, options) and every array equal."""
    leaves_a, def_a = jax.tree_util.tree_flatten(a)
    leaves_b, def_b = jax.tree_util.tree_flatten(b)
    assert def_a == def_b
    assert len(leaves_a) == len(leaves_b)
    for x, y in zip(leaves_a, leaves_b):
        x, y = np.asarray(x), np.asarray(y)
        assert x.shape == y.shape
        assert x.dtype == y.dtype
        np.testing.assert_array_equal(x, y)


@pytest.fixture(scope="module")
def bundled():
    return quiet(gearjax.load_train)


@pytest.fixture(scope="module")
def shared():
    if not SHARED.exists():
        pytest.skip(f"shared example not found at {SHARED}")
    return quiet(gearjax.load_train, SHARED)


# ------------------------------------------------------------------ examples


def test_shared_example_loads(shared):
    assert shared.gear_names == ("first",)
    assert shared.source == str(SHARED)
    assert shared.name == "Al-shyyab et al. 2009, two-stage planetary train"
    assert shared.stage_ids == ("1", "2")
    assert shared.n_dof == 14
    g = shared.gear("first")
    assert (g.input, g.output, g.brakes) == ("1.sun", "2.carrier", ("2.sun",))
    assert float(g.input_torque) == 750.0
    assert [c.members for c in shared.couplings] == [("1.carrier", "2.ring"),
                                                     ("2.carrier", "1.ring")]
    assert all(c.gears is None for c in shared.couplings)
    s1, s2 = shared.stages
    assert (s1.teeth.sun, s1.teeth.planet, s1.teeth.ring) == (30, 28, 70)
    assert (s2.teeth.sun, s2.teeth.planet, s2.teeth.ring) == (44, 18, 80)
    assert float(s1.module_mm) == 1.5 and float(s1.pressure_angle_deg) == 21.3
    np.testing.assert_array_equal(s1.planet_angles_deg, [0, 90, 180, 270])
    assert float(s1.mesh_stiffness.sun) == 4.5e8 and float(s2.mesh_stiffness.ring) == 4.4e8
    assert float(s1.contact_ratio.ring) == 1.93 and float(s2.contact_ratio.sun) == 1.1
    assert float(s2.inertia.planet) == 4.068e-5 and float(s2.planet_mass) == 0.35
    assert float(shared.housing.braked) == 1e10 and float(shared.housing.free) == 1e2


def test_shared_example_file_unchanged_by_loading(shared):
    # the loader reads it as it is: every key of the file is in the train
    raw = tomllib.loads(SHARED.read_text())
    assert len(raw["stages"]) == len(shared.stages)
    for rs, s in zip(raw["stages"], shared.stages):
        assert rs["id"] == s.id
        for side in ("sun", "ring"):
            assert float(getattr(s.half_backlash, side)) == rs["half_backlash"][side]


def test_bundled_equals_shared_in_every_stage_value(bundled, shared):
    assert_trees_equal(bundled.stages, shared.stages)
    assert_trees_equal(bundled.couplings[:2], shared.couplings)
    assert_trees_equal(bundled.housing, shared.housing)
    assert_trees_equal(bundled.gears[0], shared.gears[0])
    assert bundled.name == shared.name
    assert bundled.stiffness_harmonics == shared.stiffness_harmonics == 4


def test_bundled_text_starts_with_shared_text(shared):
    # the bundled copy is the shared file with gears appended, stage data untouched
    bundled_text = gearjax.bundled_example_path().read_text()
    assert bundled_text.startswith(SHARED.read_text().rstrip("\n"))


def test_bundled_extra_gears_and_lockup_clutch(bundled):
    assert bundled.gear_names == ("first", "second", "third", "fourth", "reverse")
    (lockup,) = [c for c in bundled.couplings if c.id == "lockup"]
    assert lockup.members == ("1.sun", "1.carrier")
    assert lockup.gears == ("third",)
    for name in bundled.gear_names:
        engaged = bundled.engaged_couplings(name)
        assert (lockup in engaged) == (name == "third")
        assert len(engaged) == (3 if name == "third" else 2)  # the two shafts are permanent


def test_bundled_gear_ratios(bundled):
    from fractions import Fraction

    ratios = {name: gearjax.kinematics(bundled, name).ratio for name in bundled.gear_names}
    assert ratios == {"first": Fraction(17, 6), "second": Fraction(31, 20), "third": 1,
                      "fourth": Fraction(7, 10), "reverse": Fraction(-7, 3)}


def test_load_train_none_is_bundled(bundled):
    assert gearjax.bundled_example_path().exists()
    assert bundled.source == str(gearjax.bundled_example_path())


# ------------------------------------------------------------------ round trip


def roundtrip(train):
    return quiet(gearjax.loads_train, gearjax.dumps_train(train), source=train.source)


def test_round_trip_bundled(bundled):
    back = roundtrip(bundled)
    assert_trees_equal(back, bundled)
    assert [g.note for g in back.gears] == [g.note for g in bundled.gears]


@pytest.fixture(scope="module")
def rich_text():
    """The bundled case with every optional key set to a non-default value."""
    raw = tomllib.loads(gearjax.bundled_example_path().read_text())
    raw["phasing"] = "paper"
    raw["mesh_damping"] = "contact"
    raw["stiffness_harmonics"] = 6
    s1, s2 = raw["stages"]
    s1["transmission_error"] = {"sun": [[1.0e-6, 0.0], [5.0e-7, 30.0]],
                                "ring": [[2.0e-6, 45.0]]}
    s2["transmission_error"] = {"ring": [[3.0e-7, -10.0], [0.0, 0.0], [1.5e-7, 270.0]]}
    s2["carrier_radius_mm"] = 46.25
    s2["sun_ring_phase_deg"] = 12.5
    s2["stage_phase_deg"] = 90.0
    s1["half_backlash"] = {"sun": 2.5e-5, "ring": 0.0}
    s1["mesh_damping_ratio"] = 0.07
    raw["gears"]["first"]["input_torque_ripple"] = [[10.0, 0.0, 2.0], [5.0, 90.0, 4.0]]
    raw["gears"]["first"]["drag_torque"] = 1.5
    raw["gears"]["second"]["drag_torque"] = 0.25
    raw["couplings"][0]["id"] = "shaft A"
    raw["housing"] = {"braked": 2.0e9, "free": 0.0}
    return tomli_w.dumps(raw)


def test_rich_train_values(rich_text):
    t = quiet(gearjax.loads_train, rich_text, source="rich.toml")
    assert (t.phasing, t.mesh_damping, t.stiffness_harmonics) == ("paper", "contact", 6)
    s1, s2 = t.stages
    assert s1.transmission_error.sun.shape == (2, 2)
    assert s1.transmission_error.ring.shape == (1, 2)
    assert s2.transmission_error.sun.shape == (0, 2)
    assert s2.transmission_error.ring.shape == (3, 2)
    assert float(s2.carrier_radius_mm) == 46.25
    assert float(s2.carrier_radius()) == pytest.approx(46.25e-3)
    assert s1.carrier_radius_mm is None
    g = t.gear("first")
    # amplitude and phase are arrays; the orders set frequencies, so they are static
    np.testing.assert_array_equal(g.input_torque_ripple, [[10, 0], [5, 90]])
    assert g.ripple_orders == (2.0, 4.0)
    assert float(g.drag_torque) == 1.5
    assert t.couplings[0].id == "shaft A"


def test_round_trip_rich_train(rich_text):
    t = quiet(gearjax.loads_train, rich_text, source="rich.toml")
    back = roundtrip(t)
    assert_trees_equal(back, t)
    # and once more: the writer is stable
    assert gearjax.dumps_train(back) == gearjax.dumps_train(t)


def test_round_trip_preserves_awkward_floats(bundled):
    import equinox as eqx
    import jax.numpy as jnp

    t = eqx.tree_at(lambda t: (t.stages[0].module_mm, t.stages[1].inertia.sun,
                               t.gears[0].input_torque),
                    bundled, (jnp.asarray(0.1 + 0.2), jnp.asarray(1 / 3 * 1e-3),
                              jnp.asarray(-123.456789012345678)))
    assert_trees_equal(roundtrip(t), t)


def test_dumps_is_valid_toml_with_all_keys(rich_text):
    t = quiet(gearjax.loads_train, rich_text, source="rich.toml")
    raw = tomllib.loads(gearjax.dumps_train(t))
    assert raw["phasing"] == "paper" and raw["mesh_damping"] == "contact"
    assert raw["stages"][1]["carrier_radius_mm"] == 46.25
    assert "carrier_radius_mm" not in raw["stages"][0]
    assert "sun" not in raw["stages"][1]["transmission_error"]
    assert raw["gears"]["first"]["input_torque_ripple"] == [[10.0, 0.0, 2.0], [5.0, 90.0, 4.0]]
    assert "input_torque_ripple" not in raw["gears"]["second"]


# ------------------------------------------------------------------ defaults

MINIMAL = """
[[stages]]
id = "A"
teeth = { sun = 30, planet = 20, ring = 70 }
module_mm = 2.0
pressure_angle_deg = 20
planet_angles_deg = [0, 90, 180, 270]
contact_ratio = { sun = 1.6, ring = 1.8 }
mesh_stiffness = { sun = 5e8, ring = 6e8 }
inertia = { sun = 1e-3, ring = 1e-2, carrier = 2e-3, planet = 1e-4 }
planet_mass = 0.5

[gears.low]
input = "A.sun"
output = "A.carrier"
brakes = ["A.ring"]
input_torque = 100
"""


def test_defaults_applied():
    with warnings.catch_warnings():
        warnings.simplefilter("error", GeometryWarning)  # 30 + 2*20 = 70, 100*90/360 = 25
        t = gearjax.loads_train(MINIMAL, source="some/dir/my_train.toml")
    assert t.name == "my_train"
    assert t.stiffness_harmonics == 4
    assert t.phasing == "physical"
    assert t.mesh_damping == "always"
    assert t.couplings == ()
    assert float(t.housing.braked) == 1e10
    assert float(t.housing.free) == 1e2
    (s,) = t.stages
    assert float(s.mesh_damping_ratio) == 0.04
    assert float(s.half_backlash.sun) == 0.0 and float(s.half_backlash.ring) == 0.0
    assert float(s.sun_ring_phase_deg) == 0.0
    assert float(s.stage_phase_deg) == 0.0
    assert s.transmission_error.sun.shape == (0, 2)
    assert s.transmission_error.ring.shape == (0, 2)
    assert s.carrier_radius_mm is None
    assert float(s.carrier_radius()) == pytest.approx(2.0e-3 * (30 + 20) / 2)
    (g,) = t.gears
    assert g.name == "low"
    assert float(g.drag_torque) == 0.0
    assert g.input_torque_ripple.shape[0] == 0
    assert g.ripple_orders == ()
    assert g.note is None
    # integers in the file are floats in the train
    assert s.pressure_angle_deg.dtype == np.float64
    assert float(g.input_torque) == 100.0


def test_default_name_without_source():
    t = gearjax.loads_train(MINIMAL)
    assert t.name == "train"
    assert t.source is None


def test_default_brakes_empty():
    text = MINIMAL.replace('brakes = ["A.ring"]\n', "")
    t = gearjax.loads_train(text, source="x.toml", validate=False)
    assert t.gears[0].brakes == ()


def test_one_number_for_both_sides():
    text = MINIMAL.replace("mesh_stiffness = { sun = 5e8, ring = 6e8 }", "mesh_stiffness = 7e8")
    t = gearjax.loads_train(text, source="x.toml")
    assert float(t.stages[0].mesh_stiffness.sun) == float(t.stages[0].mesh_stiffness.ring) == 7e8


def test_round_trip_of_defaults_keeps_values(tmp_path):
    t = gearjax.loads_train(MINIMAL, source=str(tmp_path / "my_train.toml"))
    back = gearjax.loads_train(gearjax.dumps_train(t), source=t.source)
    assert_trees_equal(back, t)


# ------------------------------------------------------------------ files


def test_save_and_load(tmp_path, rich_text):
    t = quiet(gearjax.loads_train, rich_text, source="rich.toml")
    path = tmp_path / "out" / "saved.toml"
    path.parent.mkdir()
    gearjax.save_train(t, path)
    assert path.exists()
    back = quiet(gearjax.load_train, path)
    assert back.source == str(path)
    assert back.name == t.name  # the name is written, not taken from the new stem
    assert_trees_equal(back, dataclasses.replace(t, source=str(path)))


def test_save_accepts_str_path(tmp_path, bundled):
    path = str(tmp_path / "b.toml")
    gearjax.save_train(bundled, path)
    back = quiet(gearjax.load_train, path)
    assert_trees_equal(back, dataclasses.replace(bundled, source=path))


def test_load_missing_file(tmp_path):
    path = tmp_path / "nope.toml"
    with pytest.raises(gearjax.TrainError) as info:
        gearjax.load_train(path)
    msg = str(info.value)
    assert "\n" not in msg and "nope.toml" in msg and "cannot be read" in msg
