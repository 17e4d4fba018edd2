"""``gearjax study`` and ``gearjax plot STORE``: JSON keys, the text table, refusals in
one line before any work, and the figure."""

import json
import pathlib

import pytest

from gearjax._cli import main

DATA = pathlib.Path(__file__).parents[1] / "data"
STUDY = DATA / "helicopter_study.toml"
STUDY_KEYS = {"study", "store", "design", "candidates", "missing", "ran", "refused", "failed",
              "skipped", "seconds", "varied", "results", "warnings"}


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    path = tmp_path_factory.mktemp("cli") / "heli.study"
    assert main(["study", str(STUDY), "--out", str(path), "--workers", "0", "--json"]) == 0
    return path


def test_study_json_lists_every_candidate_with_its_values_and_status(store, capsys):
    code, out, err = run(capsys, "study", STUDY, "--out", store, "--resume", "--json")
    assert code == 0 and "candidate" not in err  # nothing left to run: no progress lines
    data = json.loads(out)
    assert set(data) == STUDY_KEYS
    assert (data["candidates"], data["skipped"], data["ran"], data["missing"]) == (6, 6, 0, 0)
    assert data["varied"] == ["main.mesh_stiffness.sun", "main.planet_angles_deg"]
    first = data["results"][0]
    assert first["values"] == {"main.mesh_stiffness.sun": 8e8,
                               "main.planet_angles_deg": "0, 72, 144, 216, 288"}
    assert first["status"] == "done" and first["first_elastic_hz"] > 0
    assert first["linear"] is None and first["backlash"] is None
    refused = data["results"][2]
    assert refused["status"] == "refused" and "overlap" in refused["reason"]
    assert refused["first_elastic_hz"] is None


def test_study_text_shows_one_line_per_candidate(store, capsys):
    code, out, _ = run(capsys, "study", STUDY, "--out", store, "--resume")
    assert code == 0
    lines = out.splitlines()
    assert lines[0].startswith(f"study {STUDY}: 6 candidates (grid)")
    assert "main.mesh_stiffness.sun = 8e+08; main.planet_angles_deg = 0, 90, 180, 270: " \
           "first mode" in lines[2]
    assert "refused" in lines[3] and "planets 1 and 2 overlap" in lines[3]


@pytest.mark.parametrize("argv, words", [
    (["--out", "STORE"], "--resume = False: {store} holds 6 finished candidates"),
    (["--out", "FILE"], "--out = '{file}': is a file: a study store is a directory"),
    (["--workers", "-1", "--out", "NEW"], "--workers = -1: must be an integer >= 0"),
    (["--workers", "1", "--scheduler", "tcp://127.0.0.1:1"],
     "--workers = 1: is for the local cluster"),
    (["--resume", "--out", "NEW"], "--resume = True: {new} does not exist"),
])
def test_a_study_that_cannot_run_is_refused_in_one_line(store, tmp_path, capsys, argv, words):
    file = tmp_path / "f.txt"
    file.write_text("")
    new = tmp_path / "new.study"
    names = {"STORE": store, "FILE": file, "NEW": new}
    code, out, err = run(capsys, "study", STUDY, *[names.get(a, a) for a in argv])
    assert code == 2 and out == ""
    assert err.count("\n") == 1
    assert words.format(store=store, file=file, new=new) in err
    assert not new.exists()


def test_a_broken_study_file_is_refused_naming_its_field(tmp_path, capsys):
    path = tmp_path / "s.toml"
    path.write_text('design = "grid"\n[[vary]]\npath = "main.teeth.sun"\nvalues = []\n')
    code, _, err = run(capsys, "study", path)
    assert code == 2
    assert err == (f"gearjax: error: {path}: vary[0].values = []: must be a non-empty list "
                   "of numbers, or of lists of numbers\n")


def test_plot_of_a_study_store_draws_the_pareto_set(store, tmp_path, capsys):
    fig = tmp_path / "study.png"
    code, out, _ = run(capsys, "plot", store, "--out", fig, "--json")
    assert code == 0 and fig.stat().st_size > 10_000
    assert json.loads(out) == {"results": str(store), "kind": "study", "figure": str(fig),
                               "pareto_merits": None, "pareto": None}  # one merit only
    code, _, err = run(capsys, "plot", store, "--out", fig, "--pareto", "first_elastic_hz",
                       "linear_peak_rms_force")
    assert code == 2
    assert "--pareto = 'linear_peak_rms_force': the study ran no linear sweep" in err
