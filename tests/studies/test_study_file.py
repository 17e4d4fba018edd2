"""The study file: its rules (one line naming file, field, value and rule, before any
work), the candidates each design makes, and the train-file keys a candidate replaces."""

import pathlib
import tomllib

import numpy as np
import pytest

import gearjax as gj
from gearjax._studies.study.candidates import candidate_text, candidates, set_value

DATA = pathlib.Path(__file__).parents[1] / "data"
HELI = DATA / "helicopter_five_planets.toml"


def study_text(vary: str, *, design: str = "grid", extra: str = "",
               analysis: str = "[analysis]\nmodes = true\n") -> str:
    return (f'train = "{HELI}"\ndesign = "{design}"\n{extra}\n{vary}\n{analysis}')


ONE = '[[vary]]\npath = "main.mesh_stiffness.sun"\nvalues = [0.8e9, 1.0e9]\n'


@pytest.mark.parametrize("text, field, rule", [
    (study_text(ONE).replace("design", "desing"), "key = 'desing'", "unknown key"),
    (study_text(ONE, design="random"), "design = 'random'", "must be one of grid, list, lhs"),
    (study_text(""), "vary = (missing)", "at least one [[vary]] table"),
    (study_text('[[vary]]\npath = "main.mesh_stiffness.sun"\nfrom = 1e9\nto = 2e9\n'),
     "vary[0].points = (missing)", "exactly one of points and step"),
    (study_text('[[vary]]\npath = "main.teeth.sun"\nfrom = 38\nto = 41\npoints = 3\n'),
     "vary[0].points = 3", "does not hold these even values"),
    (study_text(ONE + '[[vary]]\npath = "main.teeth.sun"\nvalues = [40]\n', design="list"),
     "vary = [2, 1]", "every variation needs as many values"),
    (study_text(ONE, design="lhs", extra="samples = 4"), "vary[0].values",
     "design = \"lhs\" samples ranges"),
    (study_text(ONE, extra="samples = 4"), "samples = 4", "is for design = \"lhs\""),
    (study_text(ONE + ONE), "vary[1].path = 'main.mesh_stiffness.sun'", "is varied twice"),
    (study_text(ONE, analysis="[analysis]\nmodes = false\n"), "analysis = {'modes': False}",
     "asks for nothing"),
    (study_text(ONE, analysis="[analysis]\nlinear = { band_hz = [3000.0] }\n"),
     "analysis.linear.band_hz = [3000.0]", "two different positive frequencies"),
    (study_text(ONE, analysis="[analysis]\nverify = { at_hz = [-5.0] }\n"),
     "analysis.verify.at_hz = [-5.0]", "positive frequencies"),
])
def test_a_study_file_that_breaks_a_rule_is_refused_in_one_line(tmp_path, text, field, rule):
    path = tmp_path / "s.toml"
    path.write_text(text)
    with pytest.raises(gj.TrainError) as e:
        gj.load_study(path)
    message = str(e.value)
    assert "\n" not in message and message.startswith(f"{path}: {field}"), message
    assert rule in message


def test_a_path_that_names_nothing_in_the_base_train_is_refused_before_any_work(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text(study_text('[[vary]]\npath = "sun.teeth.sun"\nvalues = [40]\n'))
    with pytest.raises(gj.TrainError, match=r"vary.path = 'sun.teeth.sun': 'sun' is no "
                       r"stage id \(main\)"):
        gj.study(path, tmp_path / "store", workers=0)
    assert not (tmp_path / "store").exists()


def test_grid_list_and_latin_hypercube_make_the_candidates_they_promise():
    two = ONE + '[[vary]]\npath = "main.teeth.sun"\nvalues = [38, 40, 42]\n'
    grid = candidates(gj.loads_study(study_text(two), base=DATA))
    assert [c.values for c in grid] == [(a, b) for a in (0.8e9, 1.0e9) for b in (38, 40, 42)]
    listed = candidates(gj.loads_study(study_text(
        ONE + '[[vary]]\npath = "main.teeth.sun"\nvalues = [38, 42]\n', design="list")))
    assert [c.values for c in listed] == [(0.8e9, 38), (1.0e9, 42)]
    ranged = gj.loads_study(study_text(
        '[[vary]]\npath = "main.inertia.planet"\nfrom = 8e-3\nto = 1.1e-2\nstep = 1e-3\n'))
    assert np.allclose([c.values[0] for c in candidates(ranged)], [8e-3, 9e-3, 1e-2, 1.1e-2])
    lhs_text = study_text('[[vary]]\npath = "main.inertia.planet"\nfrom = 8e-3\nto = 1.2e-2\n'
                          '[[vary]]\npath = "main.teeth.sun"\nfrom = 36\nto = 44\n',
                          design="lhs", extra="samples = 8\nseed = 3")
    lhs = [c.values for c in candidates(gj.loads_study(lhs_text))]
    assert lhs == [c.values for c in candidates(gj.loads_study(lhs_text))]  # seeded
    inertia = np.array([v[0] for v in lhs])
    # a Latin hypercube: one sample in each eighth of every range
    assert sorted(np.floor((inertia - 8e-3) / 4e-3 * 8).astype(int)) == list(range(8))
    assert all(isinstance(v[1], int) and 36 <= v[1] <= 44 for v in lhs)


def test_a_candidate_replaces_exactly_the_varied_keys_of_the_base_train():
    text = study_text('[[vary]]\npath = "main.planet_angles_deg"\nvalues = [[0, 90, 180, 270]]'
                      '\n[[vary]]\npath = "main.teeth.planet"\nvalues = [31]\n'
                      '[[vary]]\npath = "main.half_backlash.sun"\nvalues = [5e-5]\n'
                      '[[vary]]\npath = "housing.braked"\nvalues = [1e9]\n'
                      '[[vary]]\npath = "gears.flight.input_torque"\nvalues = [9000.0]\n')
    spec = gj.loads_study(text)
    got = tomllib.loads(candidate_text(spec, candidates(spec)[0]))
    want = tomllib.loads(HELI.read_text())
    stage = want["stages"][0]
    stage["planet_angles_deg"] = [0, 90, 180, 270]
    stage["teeth"]["planet"] = 31
    stage["half_backlash"]["sun"] = 5e-5
    want["housing"] = {"braked": 1e9}
    want["gears"]["flight"]["input_torque"] = 9000.0
    assert got == want


def test_a_key_given_as_one_number_for_both_sides_is_split_when_one_side_varies():
    raw = {"stages": [{"id": "1", "half_backlash": 5e-5}]}
    set_value(raw, "1.half_backlash.ring", 7e-5)
    assert raw["stages"][0]["half_backlash"] == {"sun": 5e-5, "ring": 7e-5}
    raw = {"stages": [{"id": "1"}], "couplings": [{"members": ["a", "b"], "stiffness": 1.0}]}
    set_value(raw, "couplings.0.stiffness", 2.0)
    assert raw["couplings"][0]["stiffness"] == 2.0
    with pytest.raises(gj.TrainError, match="no coupling has id or position '3'"):
        set_value(raw, "couplings.3.stiffness", 2.0)
    with pytest.raises(gj.TrainError, match="holds a list or table in the base train"):
        set_value({"stages": [{"id": "1", "teeth": {"sun": 3}}]}, "1.teeth", 4)


def test_candidates_of_one_shape_are_sent_to_one_worker_and_the_load_is_shared():
    from gearjax._studies.study.run import shape_key, worker_homes

    spec = gj.loads_study((DATA / "helicopter_study.toml").read_text(), base=DATA)
    keys = [shape_key(candidate_text(spec, c)) for c in candidates(spec)]
    assert keys[0] == keys[3] and keys[1] == keys[4] and keys[0] != keys[1]
    homes = worker_homes(keys, ["a", "b"])
    assert homes[0] == homes[3] and homes[1] == homes[4] and homes[0] != homes[1]
    assert worker_homes(["x"] * 3 + ["y"] * 2 + ["z"], ["a", "b"]) == \
        ["a", "a", "a", "b", "b", "b"]
    assert worker_homes(keys, []) == [None] * 6
