"""Tooth geometry in train files: keys, defaults, refusals and warnings, the round trip,
the `mesh` command and `info`'s meshes, and a response's derivative with respect to
the geometry through the whole harmonic balance."""

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

import gearjax as gj
from gearjax import _cli
from gearjax._gear.assembly import assemble
from gearjax._gear.mesh_stiffness import geometric_stiffness
from gearjax._studies import sensitivity as S
from sensitivity_differences import finite_differences

DATA = Path(__file__).parents[1] / "data"
TEXT = (DATA / "geometry_stage.toml").read_text()
STAGE_LINE = 'face_width_mm = 40.0\n'
RELIEF = ('tip_relief = { sun = { amount_um = 10.0, start_diameter_mm = 66.5 }, '
          'planet = { amount_um = 10.0, start_roll_deg = 30.0 } }\n')


def variant(extra: str = "", drop: str = "") -> str:
    """The geometry stage with lines added after ``face_width_mm`` (or one removed)."""
    text = TEXT.replace(STAGE_LINE, STAGE_LINE + extra)
    return text.replace(drop, "") if drop else text


def load(text: str, name: str = "stage.toml"):
    return gj.loads_train(text, source=name)


def test_stiffness_and_contact_ratio_come_from_the_geometry_and_round_trip():
    train = load(variant('profile_shift = { sun = 0.2, planet = -0.2, ring = 0.2 }\n' + RELIEF))
    s = train.stages[0]
    assert s.geometry.derives_stiffness and s.geometry.relieved
    for side in ("sun", "ring"):
        mean, ratio = geometric_stiffness(s, side)
        np.testing.assert_allclose(getattr(s.mesh_stiffness, side), mean, rtol=1e-14)
        np.testing.assert_allclose(getattr(s.contact_ratio, side), ratio, rtol=1e-14)
    # a start roll angle xi is the diameter d_b sqrt(1 + xi^2)
    d_b = 3.0 * 39 * np.cos(np.radians(20.0))
    np.testing.assert_allclose(s.geometry.tip_relief.start_diameter_mm.planet,
                               d_b * np.sqrt(1 + np.radians(30.0) ** 2), rtol=1e-14)
    text = gj.dumps_train(train)
    assert "mesh_stiffness" not in text and "contact_ratio" not in text
    again = load(text)
    for a, b in zip(*(jax_leaves(t) for t in (train, again))):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(assemble(train).kbar, assemble(again).kbar)


def jax_leaves(train):
    import jax

    return [np.asarray(x) for x in jax.tree_util.tree_leaves(train)]


def test_given_stiffness_wins_and_the_geometry_is_only_checked():
    text = variant('contact_ratio = { sun = 1.6, ring = 1.9 }\n'
                   'mesh_stiffness = { sun = 5e8, ring = 6e8 }\n')
    train = load(text)
    assert not train.stages[0].geometry.derives_stiffness
    np.testing.assert_array_equal(assemble(train).kbar[:3], 5e8)
    with pytest.raises(gj.TrainError, match="pointed teeth"):
        load(text.replace(STAGE_LINE, STAGE_LINE + "profile_shift = { sun = 1.4, planet = "
                                                   "-1.2, ring = 1.4 }\n"))


@pytest.mark.parametrize("text, field, rule", [
    (TEXT.replace(STAGE_LINE, "profile_shift = { sun = 0.1 }\n"), "1.profile_shift",
     "needs face_width_mm"),
    (variant("contact_ratio = { sun = 1.6, ring = 1.9 }\n"), "1.mesh_stiffness",
     "is required with contact_ratio"),
    (variant("tip_relief = { sun = { amount_um = 5.0 } }\n"),
     "1.tip_relief.sun.start_diameter_mm", "is required with amount_um"),
    (variant("tip_relief = { sun = { amount_um = 5.0, start_roll_deg = 20.0, "
             "start_diameter_mm = 66.0 } }\n"), "1.tip_relief.sun.start_roll_deg", "not both"),
    (variant("poisson_ratio = 0.5\n"), "1.poisson_ratio", "below 0.5"),
    (variant("profile_shift = { sun = 1.4, planet = -1.2, ring = 1.4 }\n"),
     "1.profile_shift", "sun-planet mesh breaks the pointed teeth rule"),
    (variant("profile_shift = { sun = -0.5, planet = 0.5, ring = -0.5 }\n"),
     "1.profile_shift", "sun-planet mesh breaks the undercut rule"),
    (variant("profile_shift = { sun = 0.9, planet = -0.9, ring = 0.9 }\n"),
     "1.profile_shift", "ring-planet mesh breaks the involute interference rule"),
    (variant("carrier_radius_mm = 89.0\n"), "1.carrier_radius_mm", "sun-planet mesh breaks "
     "the jamming rule"),
    (variant("carrier_radius_mm = 90.05\n"), "1.carrier_radius_mm", "ring-planet mesh breaks "
     "the jamming rule"),
    (variant("addendum_coefficient = 0.3\n"), "1.profile_shift", "contact ratio"),
])
def test_geometry_that_cannot_mesh_is_refused_in_one_line(text, field, rule):
    with pytest.raises(gj.TrainError) as e:
        load(text)
    message = str(e.value)
    assert "\n" not in message and message.startswith(f"stage.toml: {field} = ")
    assert rule in message, message


def test_a_shared_centre_distance_that_adds_backlash_is_warned_about():
    with pytest.warns(gj.GeometryWarning, match="ring-planet mesh: the centre distance"):
        load(variant("profile_shift = { ring = -0.1 }\n"))
    with warnings.catch_warnings():
        warnings.simplefilter("error", gj.GeometryWarning)
        load(TEXT)  # standard gears at the standard centre distance: nothing to say


def test_mesh_command_reports_contact_stiffness_and_iso(tmp_path, capsys):
    path = tmp_path / "relief.toml"
    path.write_text(variant(RELIEF))
    fig = tmp_path / "cycle.png"
    assert _cli.main(["mesh", str(path), "--plot", str(fig), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert fig.stat().st_size > 10_000
    sides = {m["side"]: m for m in out["meshes"]}
    assert set(sides) == {"sun", "ring"}
    for m in sides.values():
        assert m["source"] == "geometry" and 1.2 < m["contact_ratio"] < 2.2
        assert abs(m["iso_difference"]) < 0.6  # the PE method and ISO's fit agree broadly
        assert m["load"] == pytest.approx(500.0 / (3 * 0.0315 * np.cos(np.radians(20))),
                                          rel=1e-12)  # T_s / (N r_b)
    assert len(sides["sun"]["relief_te_um"]) == 4 and max(sides["sun"]["relief_te_um"]) > 0.1
    assert _cli.main(["mesh", str(path), "--stage", "9"]) == 2
    assert "--stage = '9'" in capsys.readouterr().err


def test_info_reports_the_file_meshes_of_the_paper(capsys):
    assert _cli.main(["info", "--json"]) == 0
    meshes = json.loads(capsys.readouterr().out)["meshes"]
    first = meshes[0]
    assert (first["stage"], first["side"], first["source"]) == ("1", "sun", "file")
    assert first["contact_ratio"] == 1.25 and first["mean_stiffness"] == 4.5e8
    assert first["iso_mesh"] is None and len(first["harmonics"]) == 4


@pytest.mark.slow
def test_response_derivative_through_the_geometry_matches_finite_differences():
    """Slow (about 30 s on 2 cores, nearly all compilation of the implicit derivative
    through the potential-energy quadrature): the only test of a derivative through the
    geometry all the way to a response. d(RMS mesh force)/d(face width) and d/d(profile shift) through involute contact,
    potential energy and the harmonic balance (linear, K = 4, 2 kHz mesh frequency,
    below the first elastic mode at 5.2 kHz), against central differences of the
    re-solved response."""
    train = load(variant('profile_shift = { sun = 0.1, planet = -0.1, ring = 0.1 }\n'))
    paths = ("1.face_width_mm", "1.profile_shift.sun")
    result = S.sensitivity(train, at_hz=2000.0, paths=paths, harmonics=4, linear=True)
    assert result.ok, result.message
    fd, noise = finite_differences(train, result, linear=True)
    assert np.all(np.abs(fd) > 1e-3 * abs(result.value))  # the geometry moves the response
    err = np.abs(np.asarray(result.derivative) - fd)
    assert np.all(err <= 1e-5 * np.abs(fd) + noise), (result.derivative, fd)


def test_geometry_paths_replace_the_stiffness_paths_of_a_derived_stage():
    train = load(TEXT)
    paths = gj.continuous_paths(train, "reduction")
    assert {"1.face_width_mm", "1.profile_shift.sun", "1.profile_shift.ring"} <= set(paths)
    assert not any(p.startswith(("1.mesh_stiffness", "1.contact_ratio")) for p in paths)
    wider = gj.set_path(train, "1.face_width_mm", 50.0)
    np.testing.assert_allclose(assemble(wider).kbar[0] / assemble(train).kbar[0], 1.25,
                               rtol=1e-12)  # every compliance term scales as 1 / b
    with pytest.raises(gj.TrainError, match="derives mesh_stiffness from its tooth geometry"):
        gj.get_path(train, "1.mesh_stiffness.sun")
    with pytest.raises(gj.TrainError, match="has no tooth geometry"):
        gj.get_path(gj.load_train(), "1.face_width_mm")
