"""A linear sweep's refinement is bounded, shown and resumable, on a
five-planet helicopter main stage (tests/data/helicopter_five_planets.toml), not the
paper's train: ``max_points`` caps the points solved (grid and middles), a refinement
stopped with lines still suspect says so (a warning, ``solver.refinement``), each
round is reported while it runs, and an interrupted refinement resumes from its
journal without solving again what it had solved.

One small sweep throughout (K = 4, three grid points, 7000 down to 6000 Hz): left to
itself its refinement solves 16 middles in four rounds and keeps 11 of them.
"""

import contextlib
import io
import json
import pathlib
import warnings

import numpy as np
import pytest

import gearjax as gj
from gearjax._cli import main
from gearjax._studies.sweep import progress as _progress
from gearjax._studies.sweep import refine as _refine
from gearjax._studies.sweep.record import SweepLog

TRAIN = pathlib.Path(__file__).parent.parent / "data" / "helicopter_five_planets.toml"
K = 4
BAND = (7000.0, 6000.0)


@pytest.fixture(scope="module")
def train():
    return gj.load_train(TRAIN)


def _sweep(train, **kw):
    """``(result, refinement fields, progress calls, said lines, refinement warnings)``."""
    calls, said = [], []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        r = gj.sweep(train, "flight", *BAND, linear=True, harmonics=K, points=3,
                     progress=lambda n, f, b: calls.append((n, f)), say=said.append, **kw)
    refinement = json.loads(r.dataset.attrs["solver"])["refinement"]
    found = [str(w.message) for w in caught if issubclass(w.category, gj.RefinementWarning)]
    return r, refinement, calls, said, found


@pytest.fixture(scope="module")
def unbounded(train):
    return _sweep(train)


def test_refinement_left_to_itself_judges_every_line_and_reports_each_round(unbounded):
    r, refinement, calls, said, found = unbounded
    assert refinement["stopped"] is None and refinement["unresolved"] == 0 and not found
    assert refinement["grid"] == 3
    assert r.dataset.sizes["point"] == 3 + refinement["added"]
    assert refinement["solved"] == 3 + refinement["checked"]  # the grid and the middles
    rounds = [s for s in said if s.startswith("sweep: refinement round ")]
    assert len(rounds) >= 2 and rounds[0].startswith("sweep: refinement round 1 of at most 8: ")
    # progress while it refines: the points kept so far, growing, more than once
    counts = [n for n, _ in calls]
    assert len(counts) > len(rounds) and counts == sorted(counts)
    assert counts[-1] == r.dataset.sizes["point"] and len(set(counts)) > 2


def test_max_points_caps_the_points_solved_and_says_what_it_left(train, unbounded):
    cap = 8
    assert unbounded[1]["solved"] > cap  # the cap binds
    r, refinement, _, _, found = _sweep(train, max_points=cap)
    assert refinement["solved"] == cap and refinement["max_points"] == cap
    assert refinement["stopped"] == "max_points" and refinement["unresolved"] > 0
    assert r.dataset.sizes["point"] == 3 + refinement["added"] < unbounded[0].dataset.sizes["point"]
    assert found == [f"linear sweep: refinement stopped at `max_points` = {cap} points solved "
                     f"(raise it) with {refinement['unresolved']} intervals where a straight "
                     "line between exact points may miss the curve by more than 0.5%"]
    # the points kept are exact points of the full refinement
    full = unbounded[0].dataset
    f_full = full["mesh_frequency_hz"].values
    for f, rms in zip(r.dataset["mesh_frequency_hz"].values, r.dataset["rms_force"].values):
        i = int(np.argmin(np.abs(f_full - f)))
        assert f_full[i] == pytest.approx(f, rel=1e-12)
        np.testing.assert_allclose(rms, full["rms_force"].values[i], rtol=1e-9)


def test_an_interrupted_refinement_resumes_from_its_journal(train, unbounded, tmp_path,
                                                            monkeypatch):
    journal = tmp_path / "lin.nc.journal"
    seen = []

    def stop_after_two_rounds(n, f, b):
        seen.append(n)
        if len(seen) == 3:  # the grid and two rounds solved and journaled
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        gj.sweep(train, "flight", *BAND, linear=True, harmonics=K, points=3,
                 progress=stop_after_two_rounds, journal=journal)
    solved = []
    real = _refine.solve_points
    monkeypatch.setattr(_refine, "solve_points",
                        lambda problem, w: solved.append(len(w)) or real(problem, w))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = gj.sweep(train, "flight", *BAND, linear=True, harmonics=K, points=3,
                     journal=journal, resume=True)
    full, refinement = unbounded[0].dataset, unbounded[1]
    assert json.loads(r.dataset.attrs["solver"])["refinement"] == refinement
    np.testing.assert_array_equal(r.dataset["mesh_frequency_hz"].values,
                                  full["mesh_frequency_hz"].values)
    np.testing.assert_allclose(r.dataset["rms_force"].values, full["rms_force"].values,
                               rtol=1e-12)
    # only the rounds after the interruption were solved again
    assert 0 < sum(solved) < refinement["solved"]


def test_linear_grid_beyond_max_points_is_refused_before_any_work(train):
    with pytest.raises(gj.TrainError, match="argument points = 10: more than `max_points` = 5"):
        gj.sweep(train, "flight", *BAND, linear=True, harmonics=K, points=10, max_points=5)


def test_sweep_command_shows_rounds_and_the_cap_under_json(monkeypatch):
    monkeypatch.setattr(_progress, "PLAIN_EVERY_S", 0.0)  # every report a line
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(["sweep", str(TRAIN), "--linear", "--from", "7000", "--to", "6000",
                     "--points", "3", "--harmonics", str(K), "--max-points", "8", "--json"])
    data, lines = json.loads(out.getvalue()), err.getvalue().splitlines()
    assert code == 0
    assert data["solver"]["refinement"]["stopped"] == "max_points"
    warning = next(w for w in data["warnings"] if w.startswith("linear sweep: refinement"))
    assert "--max-points = 8 points solved (raise it)" in warning
    assert f"warning: {warning}" in lines
    assert any(l.startswith("sweep: refinement round 2 of at most 8: ") for l in lines)
    progress = [l for l in lines if l.startswith("sweep: ") and " points, 1 branch" in l]
    assert len(progress) >= 3  # as the points are solved, then the final line


def test_solved_points_of_another_refinement_are_refused(train):
    """A replay (a journal's records of points solved) at other frequencies than the
    refinement asks for is refused, not taken; the sweep names the journal (a
    ``TrainError`` through ``SweepLog.refused``)."""
    case = gj.gear_case(train, "flight", None, True)
    problem = gj.hb_problem(case.system, gj.HarmonicBalance(n_harmonics=K))
    omegas = np.asarray([case.omega(f) for f in (6500.0, 6000.0)])
    other = {"omega": omegas * 1.01, "X": np.zeros((2, *problem.shape)),
             "result": np.asarray(["successful"] * 2), "converged": np.ones(2, bool)}
    with pytest.raises(_refine.ReplayError, match="not those this refinement asks for"):
        _refine.refine_linear(problem, omegas, case.F_static, replay=[other])
    log = SweepLog([{"type": "solved", "segment": 0, "K": K, **other}])
    assert str(log.refused(0, "the journal's solved points are not those")) == (
        "journal: segment 0 records of points solved = 1: the journal's solved points are "
        "not those: delete the journal to start afresh")
