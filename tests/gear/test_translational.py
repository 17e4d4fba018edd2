"""The translational-rotational model (Lin & Parker 1999, model.md): train-file keys and
refusals, the mode types Lin & Parker prove for equally spaced planets, their planet
modes' closed form, and the rigid-bearing limit that recovers the torsional model."""

from __future__ import annotations

import tomllib
import warnings
from pathlib import Path

import numpy as np
import pytest

import gearjax as gj
from gearjax import TrainError, assemble, dumps_train, loads_train
from gearjax._engine.modal import modes
from gearjax._gear.translational import line_geometry
from train_refusals import mutate, refuse

DATA = Path(__file__).parent.parent / "data"
LIN_PARKER = (DATA / "lin_parker_stage.toml").read_text()
HELICOPTER = (DATA / "helicopter_five_planets.toml").read_text()


def _load(text: str):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # Lin & Parker's soft ring brake is a RangeWarning
        return loads_train(text, source="bad.toml")


def _lin_parker(n_planets: int, **stage) -> str:
    def change(raw):
        raw["stages"][0]["planet_angles_deg"] = [360.0 * i / n_planets for i in range(n_planets)]
        raw["stages"][0].update(stage)
    return mutate(LIN_PARKER, change)


def _translational(text: str, bearing: float, **stage) -> str:
    """``text`` (one stage) in the translational model, every bearing ``bearing`` N/m."""
    def change(raw):
        raw["model"] = "translational"
        raw["stages"][0]["mass"] = {"sun": 2.1, "ring": 9.0, "carrier": 12.0}
        raw["stages"][0]["bearing_stiffness"] = dict.fromkeys(
            ("sun", "ring", "carrier", "planet"), bearing)
        raw["stages"][0].update(stage)
    return mutate(text, change)


@pytest.mark.parametrize("n_planets", [3, 4, 5])
def test_equally_spaced_planets_give_lin_parkers_three_mode_types(n_planets):
    """Lin & Parker (1999): with N equally spaced planets every mode is rotational (single),
    translational (multiplicity 2) or a planet mode (multiplicity N - 3): six rotational,
    six translational pairs and three planet frequencies, 9 + 3N in all."""
    result = modes(assemble(_load(_lin_parker(n_planets))))
    assert len(result.modes) == 9 + 3 * n_planets
    kinds: dict[str, list] = {"rotational": [], "translational": [], "planet": []}
    for m in result.modes:
        kinds[m.family].append(m.multiplicity)
    assert kinds["rotational"] == [1] * 6
    assert kinds["translational"] == [2] * 12
    assert kinds["planet"] == [n_planets - 3] * (3 * (n_planets - 3))


def test_planet_modes_solve_the_one_planet_problem():
    """In a planet mode only the planets move, each as the 3-coordinate system of one
    planet on its pin between a fixed sun and ring (Lin & Parker 1999):
    ``(k_s a_s a_s^T + k_r a_r a_r^T + k_p diag(1, 1, 0)) v = w^2 diag(m_p, m_p, I_p/r_p^2) v``
    in ``(zeta, eta, u)``, ``a_s = (-sin a, -cos a, 1)``, ``a_r = (sin a, -cos a, -1)``
    from model.md's mesh deflections. Its three frequencies are the planet modes', the
    same for four and five planets."""
    raw = tomllib.loads(LIN_PARKER)["stages"][0]
    a = np.deg2rad(raw["pressure_angle_deg"])
    k_mesh, k_p = raw["mesh_stiffness"], raw["bearing_stiffness"]["planet"]
    r_p = raw["base_diameter_mm"]["planet"] / 2e3
    a_s = np.array([-np.sin(a), -np.cos(a), 1.0])
    a_r = np.array([np.sin(a), -np.cos(a), -1.0])
    K = k_mesh * (np.outer(a_s, a_s) + np.outer(a_r, a_r)) + k_p * np.diag([1.0, 1.0, 0.0])
    m = np.diag([raw["planet_mass"], raw["planet_mass"], raw["inertia"]["planet"] / r_p**2])
    expected = np.sqrt(np.sort(np.linalg.eigvals(np.linalg.solve(m, K)).real)) / (2 * np.pi)
    for n_planets in (4, 5):
        found = sorted({round(m.hz, 6) for m in modes(assemble(_load(_lin_parker(n_planets))))
                        .modes if m.family == "planet"})
        np.testing.assert_allclose(found, expected, rtol=1e-9)


def test_rigid_bearings_recover_the_torsional_modes():
    """Bearings 1e15 N/m (model.md: the rigid limit) leave the helicopter stage's
    torsional elastic modes, within the limit's O(k_mesh / k_bearing) = 1e-6, and put
    every other mode far above them."""
    torsional = modes(assemble(_load(HELICOPTER))).elastic_hz
    rigid = modes(assemble(_load(_translational(HELICOPTER, 1e15)))).elastic_hz
    np.testing.assert_allclose(rigid[:len(torsional)], torsional, rtol=1e-5)
    assert rigid[len(torsional)] > 20 * torsional[-1]


def test_a_floating_sun_is_held_by_its_meshes():
    """A floating sun (bearing 0) between five planets: no mode at zero frequency beyond
    the train's one rigid-body rotation (the housing's free springs), and the sun's
    translation is in the translational modes."""
    train = _load(_translational(HELICOPTER, 5e8, bearing_stiffness={
        "sun": 0.0, "ring": 5e8, "carrier": 5e8, "planet": 5e8}))
    result = modes(assemble(train))
    assert min(m.hz for m in result.modes if m.cls == "elastic") > 100.0
    assert any(m.family == "translational" and abs(m.shape["main.sun.x"]) > 0
               for m in result.modes)


def test_a_torsional_file_with_translational_keys_is_unchanged():
    """Masses and bearings in a torsional file are kept but do not touch its System."""
    plain = assemble(_load(HELICOPTER))
    text = mutate(_translational(HELICOPTER, 1e8), lambda raw: raw.update(model="torsional"))
    keyed = assemble(_load(text))
    assert keyed.n_dof == plain.n_dof
    np.testing.assert_array_equal(keyed.M, plain.M)
    np.testing.assert_array_equal(keyed.W, plain.W)
    np.testing.assert_array_equal(keyed.K, plain.K)


def test_translational_train_files_round_trip():
    train = _load(LIN_PARKER)
    again = _load(dumps_train(train))
    assert again.model == "translational" and again.n_dof == train.n_dof == 21
    for key in ("mass", "bearing_stiffness", "base_diameter_mm"):
        np.testing.assert_array_equal(np.asarray(getattr(again.stages[0], key).sun),
                                      np.asarray(getattr(train.stages[0], key).sun))
    np.testing.assert_array_equal(assemble(again).M, assemble(train).M)


@pytest.mark.parametrize("key", ["mass", "bearing_stiffness"])
def test_translational_model_needs_masses_and_bearings(key):
    def drop(raw):
        del raw["stages"][0][key]
    refuse(_load, mutate(LIN_PARKER, drop), f"1.{key}", "(missing)", "required", "translational")


@pytest.mark.parametrize(("field", "value", "bad", "rule"), [
    ("bearing_stiffness", {"sun": -1.0, "ring": 1e8, "carrier": 1e8, "planet": 1e8}, "sun",
     ">= 0"),
    ("mass", {"sun": 0.0, "ring": 2.35, "carrier": 5.43}, "sun", "> 0"),
    ("base_diameter_mm", {"sun": 77.4, "planet": 100.3}, "ring", "required"),
])
def test_translational_values_are_checked(field, value, bad, rule):
    text = mutate(LIN_PARKER, lambda raw: raw["stages"][0].update({field: value}))
    refuse(_load, text, f"1.{field}.{bad}", "", *rule.split())


def test_a_stage_needs_a_bearing_somewhere():
    text = _lin_parker(4, bearing_stiffness={"sun": 0.0, "ring": 0.0, "carrier": 0.0,
                                              "planet": 1e8})
    refuse(_load, text, "1.bearing_stiffness", "", "at least one", "translates freely")


def test_a_floating_sun_needs_two_lines_of_action():
    text = mutate(_lin_parker(4, bearing_stiffness={"sun": 0.0, "ring": 1e8, "carrier": 1e8,
                                                     "planet": 1e8}),
                  lambda raw: raw["stages"][0].update(planet_angles_deg=[0.0, 180.0]))
    refuse(_load, text, "1.bearing_stiffness.sun", "0", "floating sun", "not parallel")


def test_an_unknown_model_is_refused():
    text = mutate(LIN_PARKER, lambda raw: raw.update(model="lumped"))
    with pytest.raises(TrainError, match="model = 'lumped': must be one of"):
        _load(text)


def test_translational_keys_are_paths():
    """Masses, bearings, base diameters and pin errors vary like every other value
    (sensitivities, calibration, studies)."""
    train = _load(_lin_parker(4, planet_position_error_um={"tangential": [0.0, 5.0, 0.0, 0.0]}))
    paths = gj.continuous_paths(train)
    assert {"1.mass.carrier", "1.bearing_stiffness.planet", "1.base_diameter_mm.ring",
            "1.planet_position_error_um.tangential.2"} <= set(paths)
    floating = gj.set_path(train, "1.bearing_stiffness.sun", 0.0)
    assert float(floating.stages[0].bearing_stiffness.sun) == 0.0
    moved = gj.set_path(train, "1.planet_position_error_um.radial.3", 7.0)
    assert np.asarray(moved.stages[0].planet_position_error_um.radial).tolist() == [0, 0, 7, 0]
    with pytest.raises(TrainError, match="planet I = 1..4"):
        gj.get_path(train, "1.planet_position_error_um.tangential.5")
    with pytest.raises(TrainError, match="does not set bearing_damping_ratio"):
        gj.get_path(train, "1.bearing_damping_ratio")


def test_campbell_applies_the_translational_phasing_rules():
    """Parker & Lin (2004): with N = 5 and Z_s = 41 the first harmonic is sequential
    (41 mod 5 = 1) and drives only the translational modes, the second counter-phase
    (82 mod 5 = 2) only the planet modes, the fifth in-phase only the rotational ones."""
    text = mutate(_translational(HELICOPTER, 5e8, teeth={"sun": 41, "planet": 30, "ring": 101}),
                  lambda raw: raw.update(stiffness_harmonics=5))
    diagram = gj.campbell(_load(text), "flight", rpm_range=(100.0, 20000.0), harmonics=5)
    families = diagram.mode_family
    excited = {h: {families[c.mode] for c in diagram.crossings if c.harmonic == h and c.excited}
               for h in (1, 2, 5)}
    assert excited == {1: {"translational"}, 2: {"planet"}, 5: {"rotational"}}


def test_info_and_modes_commands_report_the_model(capsys):
    import json

    from gearjax._cli import main

    path = str(DATA / "lin_parker_stage.toml")
    assert main(["info", path, "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert (info["model"], info["dof"]) == ("translational", 21)
    assert info["load_sharing"]["1"] == pytest.approx(1.0, abs=1e-9)
    assert main(["modes", path, "--json"]) == 0
    modes_out = json.loads(capsys.readouterr().out)
    assert {m["family"] for m in modes_out["modes"]} == {"rotational", "translational", "planet"}
    assert all(abs(sum(m["kinetic"].values()) - 1.0) < 1e-9 for m in modes_out["modes"])


def test_modes_says_where_unequal_spacing_breaks_the_mode_types(tmp_path, capsys):
    """Planets at 0, 90 and 180 degrees: no mode keeps Lin & Parker's types, and the
    text says why."""
    from gearjax._cli import main

    path = tmp_path / "unequal.toml"
    path.write_text(_translational((DATA / "three_planets.toml").read_text(), 5e8))
    assert main(["modes", str(path)]) == 0
    out = capsys.readouterr().out
    assert "mode families: overall 18" in out and "planets unequally spaced" in out


@pytest.mark.slow
def test_a_profile_shifted_stage_turns_rigidly_on_its_operating_lines_of_action():
    """Slow alone (about 14 s on 2 cores: loading and assembling a stage with tooth
    geometry compiles the potential-energy programs, which the tooth-geometry tests
    share). Profile shifts move the centre distance and the pressure angle of each mesh: on
    the operating angles and centre distance (``line_geometry``) a rigid rotation of the
    stage (every member turning by one radian, the planet centres carried along)
    deflects no mesh and no pin, as model.md requires, and the static torques balance;
    with the generating 20 degrees the sun mesh would strain."""
    text = _translational((DATA / "geometry_stage.toml").read_text(), 1e9,
                          profile_shift={"sun": 0.3, "planet": 0.0, "ring": -0.32})
    with warnings.catch_warnings():
        warnings.simplefilter("error", gj.GeometryWarning)
        train = loads_train(text, source="shifted.toml")
    stage = train.stages[0]
    a_s, _, r_c = (float(v) for v in line_geometry(stage))
    assert abs(a_s - np.deg2rad(20.0)) > 0.01  # both meshes at the one centre distance
    system = assemble(train)
    n_rot = 3 + stage.n_planets
    rigid = np.zeros(system.n_dof)
    rigid[:n_rot] = 1.0
    rigid[n_rot + 7::2] = r_c  # each planet's tangential motion follows the carrier
    r_s, r_p, _ = (float(r) for r in stage.base_radii())
    np.testing.assert_allclose(np.asarray(system.W) @ rigid, 0.0, atol=1e-12 * r_c)
    pins = np.asarray(system.spring_rows)[-2 * stage.n_planets:]
    np.testing.assert_allclose(pins @ rigid, 0.0, atol=1e-12 * r_c)
    assert abs(r_s + r_p - r_c * np.cos(np.deg2rad(20.0))) > 1e-4 * r_c
    loads = gj.static_loads(train)
    assert abs(loads.balance) < 1e-9 * abs(float(train.gears[0].input_torque))
