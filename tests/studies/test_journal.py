"""Journaled sweeps: the record format, torn and damaged files, refusals, and resuming
an interrupted sweep to exactly the uninterrupted result."""

import dataclasses
import json
import pathlib
import tempfile
import warnings

import numpy as np
import pytest
import xarray as xr

import gearjax as gj
from gearjax._engine import continuation as _continuation
from gearjax._io import journal as _journal
from gearjax._studies import sweep as _sweep
from gearjax._studies.sweep import refine as sweep_refine
from gearjax._studies.sweep import segments as sweep_segments, starts
from gearjax._cli import main

BAND = dict(from_hz=2400.0, to_hz=2450.0, harmonics=8, max_step_hz=5.0)
# the bundled paper case with one stiffness harmonic (the ``train`` fixture, as a file)
H1_TOML = pathlib.Path(tempfile.mkdtemp()) / "paper_h1.toml"
H1_TOML.write_text(gj.bundled_example_path().read_text().replace(
    "stiffness_harmonics = 4", "stiffness_harmonics = 1", 1))
CLI_BAND = [str(H1_TOML), "--from", "2400", "--to", "2450", "--harmonics", "8", "--max-step",
            "5"]


@pytest.fixture(scope="module")
def train():
    """The paper case with one stiffness harmonic: its excitation reaches harmonic 8 of
    the base, so these short sweeps may use 8 or 16 harmonics."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gj.GeometryWarning)
        return dataclasses.replace(gj.load_train(), stiffness_harmonics=1)


@pytest.fixture(scope="module")
def full(train, tmp_path_factory):
    """An uninterrupted short sweep with backlash and its whole journal."""
    path = tmp_path_factory.mktemp("full") / "sweep.nc.journal"
    result = _sweep.sweep(train, "first", journal=path, **BAND)
    return result, path.read_bytes()


def same_results(a: xr.Dataset, b: xr.Dataset) -> None:
    """Identical data and attributes except when and how each was made."""
    a, b = a.copy(), b.copy()
    for ds in (a, b):
        for key in ("created", "command"):
            ds.attrs.pop(key, None)
    xr.testing.assert_identical(a, b)


def records(data: bytes) -> list[bytes]:
    """The lines (records) of a journal, newline kept."""
    return data.splitlines(keepends=True)


# ------------------------------------------------------------------------ the format


def test_records_round_trip_exactly(tmp_path):
    y = np.array([1 / 3, -0.0, 5e-324, np.pi * 1e300, np.nan, np.inf])
    rec = {"type": "point", "y": y, "i": 3, "lam": 1 / 7, "fold_lam": float("nan"),
           "codes": np.arange(4, dtype=np.int64), "ok": True, "stop": None,
           "nested": {"X": np.linspace(0, 1, 6).reshape(2, 3)}}
    path = tmp_path / "j.journal"
    with _journal.Writer.create(path, _journal.header("test", {"a": 1})) as w:
        w.append(rec)
        w.append({"type": "end"})
    head, got, size = _journal.read(path)
    assert head["kind"] == "test" and head["run"] == {"a": 1}
    assert head["gearjax_version"] == gj.__version__ and size == path.stat().st_size
    assert len(got) == 2 and got[1] == {"type": "end"}
    back = got[0]
    assert back["y"].dtype == np.float64 and back["y"].tobytes() == y.tobytes()  # bit for bit
    assert back["nested"]["X"].shape == (2, 3) and back["codes"].dtype == np.int64
    assert back["lam"] == 1 / 7 and back["fold_lam"] is None and back["ok"] is True
    line = path.read_bytes().splitlines()[1]
    assert len(line) < 400 and b"__array__" in line  # base64, not a list of numbers


def test_torn_last_record_is_ignored_with_a_warning_and_cut_off(tmp_path):
    path = tmp_path / "j.journal"
    with _journal.Writer.create(path, _journal.header("test", {})) as w:
        for i in range(3):
            w.append({"i": i, "y": np.full(50, float(i))})
    whole = path.read_bytes()
    for cut in (1, 40, len(records(whole)[-1]) - 1):  # interrupted inside the last write
        path.write_bytes(whole[:-cut])
        said = []
        head, got, size = _journal.read(path, warn=said.append)
        assert [r["i"] for r in got] == [0, 1]
        assert len(said) == 1 and "torn last record" in said[0] and str(path) in said[0]
    # appending again cuts the torn bytes off: the journal reads clean
    with _journal.Writer.append_to(path, size) as w:
        w.append({"i": 2, "y": np.full(50, 2.0)})
    said = []
    assert [r["i"] for r in _journal.read(path, warn=said.append)[1]] == [0, 1, 2]
    assert not said and path.read_bytes() == whole
    # a changed byte in the last complete record is a torn write too ...
    path.write_bytes(whole[:-5] + b"X" + whole[-4:])
    assert len(_journal.read(path, warn=said.append)[1]) == 2 and said
    # ... but a damaged record before the last one is refused
    lines = records(whole)
    lines[1] = lines[1].replace(b'"i":0', b'"i":7')
    path.write_bytes(b"".join(lines))
    with pytest.raises(gj.TrainError, match=r"j\.journal: record 1 = \(missing\): is damaged"):
        _journal.read(path)
    # only a torn header: nothing to resume
    path.write_bytes(whole[:20])
    assert _journal.read(path, warn=said.append) == (None, [], 0)


def test_not_a_journal_is_refused(tmp_path):
    path = tmp_path / "x.journal"
    path.write_bytes(_journal.encode({"format": "something else"}))
    with pytest.raises(gj.TrainError, match=r"x\.journal: format = 'something else': is not a "
                                            r"gearjax-journal file"):
        _journal.read(path)


def test_a_different_run_is_refused_naming_the_field(tmp_path):
    path = tmp_path / "r.nc.journal"
    mine = _journal.header("sweep", {"train": "a" * 100, "gear": "first", "to_hz": 2450.0})
    _journal.check(path, json.loads(json.dumps(mine)), mine)  # equal after a JSON trip
    for key, value, words in (
            ("to_hz", 2460.0, ["`to_hz` = 2460.0", "this run's 2450.0"]),
            ("gear", "second", ["`gear` = 'second'", "'first'"]),
            ("train", "b" * 100, ["`train` = '<text of 100 characters, crc32 "])):
        other = json.loads(json.dumps(mine))
        other["run"][key] = value
        with pytest.raises(gj.TrainError) as e:
            _journal.check(path, other, mine)
        msg = str(e.value)
        assert msg.startswith(f"{path}: ") and "\n" not in msg and "different run" in msg
        for w in words:
            assert w in msg
    other = dict(mine, gearjax_version="0.0.1")
    with pytest.raises(gj.TrainError, match="gearjax_version = '0.0.1'"):
        _journal.check(path, other, mine)


# --------------------------------------------------------------------------- sweeps


def test_the_journal_holds_every_point_with_its_continuation_state(full):
    result, data = full
    lines = records(data)
    head = _journal.decode(lines[0].rstrip(b"\n"))
    assert head["kind"] == "sweep" and head["run"]["from_hz"] == 2400.0
    assert head["run"]["harmonics"] == 8 and "[[stages]]" in head["run"]["train"]
    recs = [_journal.decode(line.rstrip(b"\n")) for line in lines[1:]]
    points = [r for r in recs if r["type"] == "point"]
    assert recs[-1] == {"type": "end", "segment": 0, "stop": "reached_end"}
    assert [p["i"] for p in points] == list(range(len(points)))
    assert len(points) == result.dataset.sizes["point"]
    p = points[3]
    assert {"y", "lam", "ty", "tlam", "h", "K", "segment"} <= set(p) and p["K"] == 8
    assert p["y"].shape == p["ty"].shape == (17 * 14,)
    np.testing.assert_allclose(np.array([q["lam"] for q in points]) * 2400.0,
                               result.dataset["mesh_frequency_hz"].values, rtol=1e-14)


@pytest.mark.parametrize("keep", [1, 2, 5, -1, None])
def test_resumed_sweep_equals_the_uninterrupted_one(train, full, tmp_path, keep):
    """Interrupted after ``keep`` points (-1: all points but not the segment's end record;
    None: finished, not yet consolidated), with a torn record after them."""
    result, data = full
    lines = records(data)
    kept = lines if keep is None else lines[:-1] if keep == -1 else lines[:1 + keep]
    path = tmp_path / "sweep.nc.journal"
    torn = lines[len(kept)][: len(lines[len(kept)]) // 2] if len(kept) < len(lines) else b""
    path.write_bytes(b"".join(kept) + torn)
    resumed = _sweep.sweep(train, "first", journal=path, resume=True, **BAND)
    same_results(resumed.dataset, result.dataset)
    assert resumed.stop == result.stop and resumed.folds_hz == result.folds_hz
    assert path.read_bytes() == data  # nothing lost, nothing written twice


TWO_SEGMENTS = [(2400.0, 2425.0, 8), (2425.0, 2450.0, 8)]


@pytest.fixture(scope="module")
def two_segments(train, tmp_path_factory):
    """The short sweep cut in two segments, whose second is speculated
    (``gearjax._studies.sweep.speculation``) and adopted: the result and its whole journal."""
    path = tmp_path_factory.mktemp("two") / "sweep.nc.journal"
    with pytest.MonkeyPatch.context() as m:
        m.setattr(sweep_segments, "band_segments", lambda *a: list(TWO_SEGMENTS))
        result = _sweep.sweep(train, "first", journal=path, **BAND)
    return result, path.read_bytes()


@pytest.mark.parametrize("keep", [3, 8, 10])
def test_resumed_speculation_equals_the_uninterrupted_one(train, two_segments, tmp_path,
                                                          monkeypatch, keep):
    """Interrupted in the first segment (the speculation on the second starts again and
    is adopted: in a thread), after it (adopted at once, without a thread), in the
    second (its adopted points taken from the journal, the rest continued)."""
    result, data = two_segments
    monkeypatch.setattr(sweep_segments, "band_segments", lambda *a: list(TWO_SEGMENTS))
    lines = records(data)
    assert 1 + keep < len(lines) - 1
    segments = [json.loads(line.split(b" ", 1)[1]).get("segment") for line in lines[1:]]
    assert segments[keep - 1] == (0 if keep <= 8 else 1)  # where it was interrupted
    path = tmp_path / "sweep.nc.journal"
    path.write_bytes(b"".join(lines[:1 + keep]))
    resumed = _sweep.sweep(train, "first", journal=path, resume=True, **BAND)
    same_results(resumed.dataset, result.dataset)
    assert path.read_bytes() == data


def test_a_finished_journal_is_not_recomputed(train, full, tmp_path, monkeypatch):
    result, data = full
    path = tmp_path / "sweep.nc.journal"
    path.write_bytes(data)

    def no(*args, **kwargs):
        raise AssertionError("recomputed a journaled point")

    monkeypatch.setattr(_continuation, "continue_branch", no)
    monkeypatch.setattr(starts, "enter_segment", no)
    same_results(_sweep.sweep(train, "first", journal=path, resume=True, **BAND).dataset,
                 result.dataset)


def test_cli_resume_consolidates_and_removes_the_journal(capsys, full, tmp_path):
    result, data = full
    nc = tmp_path / "sweep.nc"
    journal = _journal.journal_path(nc)
    journal.write_bytes(b"".join(records(data)[:4]))
    code = main(["sweep", *CLI_BAND, "--out", str(nc), "--resume", "--json"])
    out, err = capsys.readouterr()
    assert code == 0 and "resuming from" in err and str(journal) in err
    assert len(json.loads(out)["points"]) == result.dataset.sizes["point"]
    assert not journal.exists()
    back = gj.load_results(nc)  # the NetCDF reads back as the in-memory result
    same_results(back, result.dataset)
    assert back.attrs["kind"] == "sweep"


@pytest.mark.parametrize("argv, words", [
    (CLI_BAND[:4] + ["2460"] + CLI_BAND[5:], ["--to = 2450.0", "differs from this run's 2460.0"]),
    (CLI_BAND[:-1] + ["4"], ["--max-step = 5.0", "this run's 4.0"]),
    (CLI_BAND + ["--gear", "second", "--linear"], ["--gear = 'first'", "'second'"]),
])
def test_cli_refuses_a_journal_of_another_run(capsys, full, tmp_path, argv, words):
    nc = tmp_path / "sweep.nc"
    journal = _journal.journal_path(nc)
    journal.write_bytes(full[1])
    code = main(["sweep", *argv, "--out", str(nc), "--resume"])
    out, err = capsys.readouterr()
    line = [l for l in err.splitlines() if l.startswith("gearjax: error:")]
    assert code == 2 and out == "" and len(line) == 1 and "Traceback" not in err
    assert f"{journal}: " in line[0]
    for w in words:
        assert w in line[0]
    assert journal.read_bytes() == full[1]  # left as it was


def test_another_train_is_refused(train, full, tmp_path):
    path = tmp_path / "sweep.nc.journal"
    path.write_bytes(full[1])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gj.GeometryWarning)
        other = gj.loads_train(gj.dumps_train(train).replace("mesh_damping_ratio = 0.04",
                                                             "mesh_damping_ratio = 0.05", 1))
    with pytest.raises(gj.TrainError, match=r"sweep\.nc\.journal: `train` = '<text of"):
        _sweep.sweep(other, "first", journal=path, resume=True, **BAND)


def test_cli_journal_without_resume_and_resume_without_out(capsys, full, tmp_path):
    nc = tmp_path / "sweep.nc"
    _journal.journal_path(nc).write_bytes(full[1])
    code = main(["sweep", *CLI_BAND, "--out", str(nc)])
    err = capsys.readouterr().err
    assert code == 2 and "sweep.nc.journal: a journal of an interrupted run" in err
    assert "add --resume" in err
    code = main(["sweep", *CLI_BAND, "--resume"])
    err = capsys.readouterr().err
    assert code == 2 and "--resume = True: needs --out FILE" in err


def test_linear_sweep_journals_its_points_solved_and_its_batch(train, tmp_path, monkeypatch):
    """A linear segment journals each chunk of points as solved, then its batch: a run
    interrupted while writing the batch, or before it, resumes to the same results
    without solving again what the journal holds."""
    kw = dict(from_hz=2400.0, to_hz=2450.0, linear=True, harmonics=8, points=3)
    path = tmp_path / "lin.nc.journal"
    result = _sweep.sweep(train, "first", journal=path, **kw)
    data = path.read_bytes()
    lines = records(data)
    kinds = [_journal.decode(line.rstrip(b"\n"))["type"] for line in lines[1:]]
    assert kinds == ["solved", "batch"]  # three points, one chunk; a straight flank
    path.write_bytes(b"".join(lines[:2]) + lines[2][:100])  # interrupted in the batch
    same_results(_sweep.sweep(train, "first", journal=path, resume=True, **kw).dataset,
                 result.dataset)
    assert path.read_bytes() == data

    def no(*args, **kwargs):
        raise AssertionError("recomputed journaled points")

    monkeypatch.setattr(starts, "solve_points", no)
    monkeypatch.setattr(sweep_refine, "solve_points", no)
    same_results(_sweep.sweep(train, "first", journal=path, resume=True, **kw).dataset,
                 result.dataset)
    path.write_bytes(b"".join(lines[:2]))  # interrupted before the batch
    same_results(_sweep.sweep(train, "first", journal=path, resume=True, **kw).dataset,
                 result.dataset)
    assert path.read_bytes() == data


def test_resume_without_a_journal_starts_afresh(train, full, tmp_path, capsys):
    path = tmp_path / "sweep.nc.journal"
    resumed = _sweep.sweep(train, "first", journal=path, resume=True, **BAND)
    assert "no journal to resume" in capsys.readouterr().err
    same_results(resumed.dataset, full[0].dataset)
    assert path.read_bytes() == full[1]


def test_sweep_results_are_labelled_data_and_read_back_identical(full, tmp_path):
    """interface.md's results files for a real sweep: flat mesh dimension with stage,
    side, planet coordinates, units everywhere, the run in global attributes; NetCDF
    reads back identical, CSV has one row per point and mesh."""
    import pandas as pd

    ds = full[0].dataset
    assert ds["rms_force"].dims == ("point", "mesh")
    assert {"stage", "side", "planet"} <= set(ds["mesh"].coords)
    assert all("units" in ds[v].attrs for v in ds.data_vars)
    assert {"train_toml", "gear", "solver", "gearjax_version", "kind"} <= set(ds.attrs)
    assert json.loads(ds.attrs["solver"])["segments"] == [[2400.0, 2450.0, 8]]
    xr.testing.assert_identical(gj.load_results(gj.save_results(ds, tmp_path / "s.nc")), ds)
    df = pd.read_csv(gj.save_results(ds, tmp_path / "s.csv"))
    assert len(df) == ds.sizes["point"] * ds.sizes["mesh"]
    row = df[(df.point == 4) & (df.mesh == "2.sp3")].iloc[0]
    assert row.rms_force == pytest.approx(float(ds.rms_force.sel(mesh="2.sp3")[4]), rel=1e-12)


def test_journal_lock_is_reentrant_and_held_by_the_writer(tmp_path):
    """The command line locks a journal before the sweep opens its Writer on it (the
    same process: re-entrant); the lock file goes with the last hold, and a lock file
    left by a dead process (no OS lock on it) is taken over."""
    path = tmp_path / "r.nc.journal"
    lock_file = _journal.lock_path(path)
    assert lock_file.name == "r.nc.journal.lock" and _journal.holder(path) is None
    with _journal.lock(path):
        assert lock_file.read_text().strip() == str(__import__("os").getpid())
        with _journal.Writer.create(path, _journal.header("test", {})) as w:
            w.append({"i": 0})
        assert lock_file.exists()  # still held by the outer lock
        assert _journal.holder(path) is None  # this process's own hold is no refusal
        assert len(_journal.read(path)[1]) == 1
    assert not lock_file.exists()
    with _journal.Writer.append_to(path, path.stat().st_size) as w:
        assert lock_file.exists()
        w.append({"i": 1})
    assert not lock_file.exists()
    lock_file.write_text("999999\n")  # stale: its process died (kill -9)
    with _journal.lock(path):
        assert _journal.holder(path) is None
    assert not lock_file.exists() and len(_journal.read(path)[1]) == 2


def test_a_journal_with_integer_result_codes_resumes(train, tmp_path):
    """Journals written before the one ``RESULTS`` enumeration stored a linear batch's
    results as integer codes (0 converged, 1 max_steps, 2 nonfinite): they still resume,
    to the same words."""
    kw = dict(from_hz=2400.0, to_hz=2450.0, linear=True, harmonics=8, points=3)
    path = tmp_path / "lin.nc.journal"
    result = _sweep.sweep(train, "first", journal=path, **kw)
    head, solved, batch = records(path.read_bytes())
    rec = _journal.decode(batch.rstrip(b"\n"))
    assert list(rec["result"]) == ["converged"] * 3
    rec["result"] = np.zeros(3, np.int64)
    path.write_bytes(head + solved + _journal.encode(rec))
    same_results(_sweep.sweep(train, "first", journal=path, resume=True, **kw).dataset,
                 result.dataset)
