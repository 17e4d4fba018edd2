"""Refuse, don't guess: every refusal of the command line is one line on
stderr and an exit code, never a usage dump or a traceback; output paths are checked
before any work; results are written atomically; a journal being written by a live
run is locked, and the lock dies with its process."""

import json
import os
import signal
import subprocess
import sys
import time
import warnings

import numpy as np
import pandas as pd
import pytest
import xarray as xr

import gearjax as gj
from gearjax._io import journal as _journal
from gearjax._gear import kinematics as _kinematics
from gearjax._io import results as _results
from gearjax._studies import sweep as _sweep
from gearjax._gear import toml_io as _toml_io
from gearjax._cli import main
from gearjax._errors import RangeWarning

SWEEP = ["sweep", "--linear", "--points", "3", "--from", "2400", "--to", "2450",
         "--harmonics", "32"]


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def one_line(err: str, start: str = "gearjax: error: ") -> str:
    """The single refusal line of ``err`` (besides ``warning:`` lines), no traceback."""
    lines = [l for l in err.splitlines() if not l.startswith("warning: ")]
    assert len(lines) == 1 and lines[0].startswith(start), err
    assert "Traceback" not in err and "usage:" not in err
    return lines[0]


@pytest.fixture
def no_work(monkeypatch):
    """Fail the test if a train is loaded (the first step of any work)."""
    def no(*a, **k):
        raise AssertionError("work started before the output paths were checked")

    monkeypatch.setattr(_toml_io, "load_train", no)


# ------------------------------------------------------------ 1. argparse's errors


@pytest.mark.parametrize("argv, words", [
    (["sensitivity", "--at", "3000", "--response", "bogus"],
     ["--response = 'bogus'", "must be one of rms, max, dlf"]),
    (["plot", "x.nc", "--what", "bogus"],
     ["--what = 'bogus'", "must be one of rms, dlf, separation, torque"]),
    (["sensitivity"], ["--at = (missing)", "gearjax sensitivity needs it"]),
    (["sensitivity", "--at", "abc"], ["--at = 'abc'", "must be a number"]),
    (["sweep", "--points", "3.5"], ["--points = '3.5'", "must be a whole number"]),
    (["simulate", "--at"], ["--at = (missing)", "expected at least one argument"]),
    (["info", "--bogus"], ["--bogus: not a flag or argument"]),
    (["bogus"], ["COMMAND = 'bogus'", "must be one of info, modes, calibrate"]),
    ([], ["COMMAND = (missing)", "info, modes"]),
])
def test_usage_errors_are_one_line(capsys, argv, words):
    code, out, err = run(capsys, *argv)
    line = one_line(err)
    assert code == 2 and out == "" and line.startswith("gearjax: error: command line: ")
    for w in words:
        assert w in line


def test_help_still_works(capsys):
    with pytest.raises(SystemExit) as e:
        main(["sweep", "--help"])
    out = capsys.readouterr().out
    assert e.value.code == 0 and "usage: gearjax sweep" in out and "--resume" in out


# --------------------------------------------------------------- 2. output paths


@pytest.mark.parametrize("argv, words", [
    (SWEEP + ["--out", "{tmp}"], ["--out = '{tmp}'", "is a directory"]),
    (SWEEP + ["--out", "{tmp}/no/such/x.nc"], ["'{tmp}/no/such' does not exist"]),
    (SWEEP + ["--out", "{tmp}/x.txt"], ["--out = '{tmp}/x.txt'", "must end in .nc or .csv"]),
    (SWEEP + ["--out", "{tmp}/f.nc/x.nc"], ["'{tmp}/f.nc' is not a directory"]),
    (SWEEP + ["--plot", "{tmp}/p.xyz"], ["--plot = '{tmp}/p.xyz'", "matplotlib", ".png",
                                         ".pdf"]),
    (SWEEP + ["--plot", "{tmp}"], ["--plot = '{tmp}'", "is a directory"]),
    (["simulate", "--at", "3000", "--out", "{tmp}"], ["is a directory"]),
    (["simulate", "--at", "3000", "--out", "{tmp}/s.json"], ["must end in .nc or .csv"]),
    (["verify", "--at", "3000", "--out", "{tmp}/v.csv"], ["must end in .nc (NetCDF"]),
    (["optimize", "--out", "{tmp}/o.csv"], ["--out = '{tmp}/o.csv'", "must end in .nc"]),
    (["optimize", "--out-train", "{tmp}"], ["--out-train = '{tmp}'", "is a directory"]),
    (["optimize", "--out-train", "{tmp}/t.json"], ["must end in .toml"]),
    (["calibrate", "--targets-hz", "3880", "--free", "1.inertia.sun", "--out-train",
      "{tmp}/missing/t.toml"], ["--out-train", "does not exist"]),
    (["modes", "--plot", "{tmp}/m"], ["--plot = '{tmp}/m'", "figure format"]),
    (["modes", "--plot", "/proc/m.png"], ["'/proc' is not writable"]),
    (["plot", "{tmp}/f.nc", "--out", "{tmp}/p.xyz"], ["--out = '{tmp}/p.xyz'", "matplotlib"]),
    (["plot", "{tmp}/f.nc", "--out", "{tmp}/f.nc"], ["would overwrite the results file"]),
    (["sweep", "--resume"], ["--resume = True: needs --out FILE"]),
])
def test_output_paths_are_refused_before_any_work(capsys, tmp_path, no_work, argv, words):
    (tmp_path / "f.nc").write_text("a file, not a directory")
    t0 = time.perf_counter()
    code, out, err = run(capsys, *[a.format(tmp=tmp_path) for a in argv])
    assert time.perf_counter() - t0 < 1.5
    line = one_line(err)
    assert code == 2 and out == ""
    for w in words:
        assert w.format(tmp=tmp_path) in line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f.nc"]  # nothing left behind


# ------------------------------------------------------- 2b. environment variables


@pytest.mark.parametrize("argv", [["info"], ["modes"], SWEEP, ["plot", "results.nc"]])
@pytest.mark.parametrize("name, value, words", [
    ("GEARJAX_THREADS", "abc", "must be an integer >= 1"),
    ("GEARJAX_THREADS", "0", "must be an integer >= 1"),
    ("GEARJAX_KEEP_PROGRAMS", "yes", "must be 0 or 1"),
    ("GEARJAX_DEBUG", "on", "must be 0 or 1"),
    ("GEARJAX_THREAD", "2", "not a gearjax setting (gearjax reads GEARJAX_THREADS,"),
])
def test_environment_is_checked_before_any_work(capsys, monkeypatch, no_work, argv, name,
                                                 value, words):
    """Every command, whatever its work, refuses a bad or misspelt ``GEARJAX_*`` setting
    at its start: exit 2, one line naming the variable, its value and the rule."""
    monkeypatch.setenv(name, value)
    code, out, err = run(capsys, *argv)
    line = one_line(err)
    assert code == 2 and out == ""
    assert f"environment: {name} = {value!r}: " in line and words in line


def test_a_cache_directory_that_is_a_file_is_refused(capsys, monkeypatch, no_work, tmp_path):
    (tmp_path / "f").write_text("not a directory")
    monkeypatch.setenv("GEARJAX_CACHE_DIR", str(tmp_path / "f"))
    code, out, err = run(capsys, "info")
    assert code == 2 and "environment: GEARJAX_CACHE_DIR = " in one_line(err)
    assert "must be a directory" in one_line(err)


def _dataset(n: int = 3) -> xr.Dataset:
    return xr.Dataset({"a": ("point", np.arange(float(n)), {"units": "1"})},
                      attrs={"gearjax_version": gj.__version__})


@pytest.mark.parametrize("named", [True, False], ids=["named", "unnamed"])
@pytest.mark.parametrize("suffix", [".nc", ".csv"])
def test_results_are_written_atomically(tmp_path, monkeypatch, suffix, named):
    path = tmp_path / f"r{suffix}"
    monkeypatch.setattr(_results, "results_frame", lambda ds: ds.to_dataframe())
    _results.save_results(_dataset(3), path)
    before = path.read_bytes()

    def torn(self, target, *a, **k):  # half a file, then the writer dies
        with open(target, "wb") as f:
            f.write(before[: len(before) // 2])
        if named:
            raise OSError(28, "No space left on device", str(target))
        raise OSError(f"Can't write data (file write failed: errno = 28, error message = "
                      "'No space left on device')")  # as h5py says it: no file named

    monkeypatch.setattr(xr.Dataset, "to_netcdf", torn)
    monkeypatch.setattr(pd.DataFrame, "to_csv", torn)
    with pytest.raises(OSError) as e:
        _results.save_results(_dataset(5), path)
    assert e.value.filename == str(path)  # the caller's path, not the temporary one
    assert "No space left on device" in e.value.strerror
    assert path.read_bytes() == before  # the old file, whole
    assert [p.name for p in tmp_path.iterdir()] == [path.name]  # no temporary file left


# ------------------------------------------------------------- 3. journals, locks


@pytest.fixture
def holder(tmp_path):
    """A separate process that holds the lock of ``tmp/sweep.nc.journal`` as a sweep
    writing it does (a journal with a header, then a record): yields it; kill -9 at
    the end if still alive."""
    journal = tmp_path / "sweep.nc.journal"
    code = ("import sys, time\n"
            "from gearjax._io import journal as _journal\n"
            f"w = _journal.Writer.create({str(journal)!r}, _journal.header('sweep', {{'a': 1}}))\n"
            "w.append({'type': 'end', 'segment': 0, 'stop': 'reached_end'})\n"
            "print('writing', flush=True)\n"
            "time.sleep(120)\n")
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "writing"
        yield proc, journal
    finally:
        proc.kill()
        proc.wait()


def test_a_live_journal_is_refused_and_a_killed_holder_leaves_it_resumable(capsys, holder,
                                                                           no_work_sweep):
    proc, journal = holder
    data = journal.read_bytes()
    nc = str(journal)[: -len(_journal.SUFFIX)]
    assert _journal.holder(journal) == proc.pid
    for extra in ([], ["--resume"]):  # with or without --resume: refused, same line
        code, out, err = run(capsys, *SWEEP, "--out", nc, *extra)
        line = one_line(err)
        assert code == 2 and out == ""
        assert line == (f"gearjax: error: {journal}: another gearjax process (pid {proc.pid}) "
                        "is writing this journal now; wait for it or choose another --out")
    # the library refuses too: reading, appending, replacing
    for attempt in (lambda: _journal.read(journal),
                    lambda: _journal.Writer.append_to(journal, len(data)),
                    lambda: _journal.Writer.create(journal, _journal.header("sweep", {}))):
        with pytest.raises(_journal.JournalBusy, match=f"pid {proc.pid}"):
            attempt()
    assert journal.read_bytes() == data  # untouched
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    # the lock died with its process: the journal resumes at once
    assert _journal.holder(journal) is None
    log = _sweep.SweepLog.open(journal, {"a": 1}, resume=True)
    try:
        assert log.end(0) == {"type": "end", "segment": 0, "stop": "reached_end"}
        assert _journal.holder(journal) is None  # this process holds it now, not another
    finally:
        log.close()
    assert journal.read_bytes() == data
    assert not _journal.lock_path(journal).exists()


@pytest.fixture
def no_work_sweep(monkeypatch):
    def no(*a, **k):
        raise AssertionError("a refused run started sweeping")

    monkeypatch.setattr(_sweep, "sweep", no)


def test_a_running_sweep_refuses_a_second_one(capsys, tmp_path, no_work_sweep):
    """The real race: a sweep command in another process, the same command here."""
    nc = tmp_path / "lin.nc"
    journal = _journal.journal_path(nc)
    proc = subprocess.Popen([sys.executable, "-m", "gearjax._cli", *SWEEP, "--out", str(nc)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        while _journal.holder(journal) != proc.pid:
            assert proc.poll() is None, proc.stderr.read()
            assert time.monotonic() < deadline
            time.sleep(0.05)
        for extra in ([], ["--resume"]):
            code, _, err = run(capsys, *SWEEP, "--out", str(nc), *extra)
            assert code == 2 and f"another gearjax process (pid {proc.pid})" in one_line(err)
        assert proc.poll() is None  # the first run goes on
    finally:
        proc.kill()
        proc.wait()
    assert _journal.holder(journal) is None


def test_interrupted_sweep_says_how_to_resume(capsys, tmp_path, monkeypatch):
    nc = tmp_path / "sweep.nc"
    journal = _journal.journal_path(nc)

    def interrupted(*a, journal=None, **k):
        assert _journal.lock_path(journal).exists()
        journal.write_bytes(_journal.encode(_journal.header("sweep", {})))
        raise KeyboardInterrupt

    monkeypatch.setattr(_sweep, "sweep", interrupted)
    code, out, err = run(capsys, *SWEEP, "--out", str(nc))
    line = one_line(err, "gearjax: interrupted")
    assert code == 130 and out == ""
    assert line == (f"gearjax: interrupted; the points found so far are in {journal}: run "
                    "the same command with --resume to go on")
    assert journal.exists() and not _journal.lock_path(journal).exists()


# ------------------------------------------------------- 4. no traceback, ever


def _failing_info(monkeypatch, error):
    def boom(*a, **k):
        raise error

    monkeypatch.setattr(_kinematics, "kinematics", boom)


def test_os_error_is_one_line_naming_the_file(capsys, monkeypatch):
    _failing_info(monkeypatch, PermissionError(13, "Permission denied", "/x/out.nc"))
    code, out, err = run(capsys, "info")
    assert code == 2 and one_line(err) == "gearjax: error: /x/out.nc: Permission denied"


def test_internal_error_is_one_line_or_a_traceback_when_debugging(capsys, monkeypatch):
    _failing_info(monkeypatch, RuntimeError("boom\nsecond line"))
    monkeypatch.delenv("GEARJAX_DEBUG", raising=False)
    code, out, err = run(capsys, "info")
    assert code == 1 and one_line(err, "gearjax: internal error: ") == (
        "gearjax: internal error: RuntimeError: boom second line (set GEARJAX_DEBUG=1 for "
        "the traceback)")
    monkeypatch.setenv("GEARJAX_DEBUG", "1")
    with pytest.raises(RuntimeError, match="boom"):
        main(["info"])


def test_out_of_memory_names_the_harmonics(capsys, monkeypatch):
    monkeypatch.delenv("GEARJAX_DEBUG", raising=False)
    monkeypatch.setattr(_sweep, "sweep", lambda *a, **k: (_ for _ in ()).throw(RuntimeError(
        "RESOURCE_EXHAUSTED: Out of memory while trying to allocate 81604378624 bytes.")))
    code, out, err = run(capsys, *SWEEP)
    line = one_line(err)
    assert code == 1 and "did not fit in memory" in line and "--harmonics" in line


def test_keyboard_interrupt_without_a_journal(capsys, monkeypatch):
    _failing_info(monkeypatch, KeyboardInterrupt())
    code, out, err = run(capsys, "info")
    assert code == 130 and one_line(err, "gearjax: interrupted") == "gearjax: interrupted"


# ---------------------------------------------------------------- 5. warnings


def test_every_train_warning_is_one_line_and_in_the_json(capsys, monkeypatch):
    real = _kinematics.kinematics

    def unusual(*a, **k):
        for _ in range(3):  # repeated: said once
            warnings.warn("<train>: 1.backlash = 1.0: unusually large", RangeWarning)
        return real(*a, **k)

    monkeypatch.setattr(_kinematics, "kinematics", unusual)
    code, out, err = run(capsys, "info", "--json")
    said = [l for l in err.splitlines() if "unusually large" in l]
    assert code == 0 and said == ["warning: <train>: 1.backlash = 1.0: unusually large"]
    notes = json.loads(out)["warnings"]
    assert "<train>: 1.backlash = 1.0: unusually large" in notes
    assert any("concentricity" in w for w in notes)  # the GeometryWarning of the file
