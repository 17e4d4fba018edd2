"""An integration's progress: the lines ``simulate`` and ``verify``
write as points end (one at a time on a CPU) and, for a quasi-periodic gear, as its
windows run, from the engine's window reports."""

import math
import pathlib

import numpy as np
import pytest

import gearjax as gj
from gearjax._studies import simulate as _simulate

DATA = pathlib.Path(__file__).parent.parent / "data"


def test_each_point_reports_its_first_window_then_at_most_one_line_per_interval(monkeypatch):
    monkeypatch.setattr(_simulate, "REPORT_EVERY_S", 3600.0)
    lines = []
    settings = gj.Windowed(max_windows=6, tol=1e-2, n_agree=2)
    listen = _simulate.WindowProgress(lines.append, [36.0, 37.5], settings)
    for point in range(2):  # one point after the other: the windows start again
        for k in range(1, 5):
            listen(np.asarray(k), np.asarray(100 * k), np.asarray(np.nan if k == 1 else 0.1 / k))
    assert len(lines) == 2  # each point's first window; the rest within the interval
    assert lines[0].startswith("integration: point 1 of 2 (36.0 Hz): window 1 of at most 6, "
                               "100 solver steps; ")
    assert lines[1].startswith("integration: point 2 of 2 (37.5 Hz): window 1 of at most 6, ")
    # the time left is bounded by every window the run may still integrate
    left = float(lines[1].split("at most about ")[1].split(" s left")[0])
    assert math.isfinite(left) and left >= 0


def test_lines_say_how_far_the_windows_are_from_agreeing(monkeypatch):
    monkeypatch.setattr(_simulate, "REPORT_EVERY_S", 0.0)
    lines = []
    listen = _simulate.WindowProgress(lines.append, [36.0], gj.Windowed(tol=1e-2, n_agree=2))
    listen(np.asarray(1), np.asarray(10), np.asarray(np.nan))
    listen(np.asarray(2), np.asarray(25), np.asarray(0.034))
    assert "windows differ" not in lines[0]
    assert ("window 2 of at most 32, 25 solver steps, windows differ by 3.4% (agreement: "
            "within 1%, 2 in a row); ") in lines[1]


def test_a_vmapped_batch_is_reported_as_points_at_once(monkeypatch):
    monkeypatch.setattr(_simulate, "REPORT_EVERY_S", 0.0)
    lines = []
    listen = _simulate.WindowProgress(lines.append, [30.0, 40.0, 45.0], gj.Windowed())
    listen(np.asarray([1, 1, 1]), np.asarray([5, 6, 7]), np.full(3, np.nan))
    listen(np.asarray([2, 2, 2]), np.asarray([9, 12, 14]), np.asarray([0.5, np.nan, 0.2]))
    assert lines[0].startswith("integration: 3 points at once: window 1 of at most 32, 7 solver")
    assert "windows differ by 50%" in lines[1]


def test_window_reports_are_not_in_the_results_settings():
    """``report`` asks for progress only: a results file's solver settings leave it out."""
    train = gj.load_train(DATA / "two_stage_14_17.toml")
    case = gj.gear_case(train, None, None, True, torus=True)
    assert case.G > 1
    plain = _simulate.windowed_settings(case, gj.Windowed())
    told = _simulate.windowed_settings(case, gj.Windowed(report=True))
    assert "report" not in told and told == plain and plain["max_windows"] == 32


def test_points_run_one_at_a_time_are_reported_as_they_end(monkeypatch):
    """A five-planet helicopter stage, linear, two points: a line per point (its steps,
    its result, the time left) and the same results as the batch without progress."""
    monkeypatch.setattr(_simulate, "REPORT_EVERY_S", 0.0)
    train = gj.load_train(DATA / "helicopter_five_planets.toml")
    lines, f = [], [2500.0, 2600.0]
    with pytest.warns(gj.ContactLossWarning):
        told = gj.simulate_gear(train, at_hz=f, linear=True, progress=lines.append)
        batch = gj.simulate_gear(train, at_hz=f, linear=True)
    points = [l for l in lines if l.startswith("integration: ")]
    assert [p.split(":")[1] for p in points] == [" point 1 of 2 (2500.0 Hz)",
                                                 " point 2 of 2 (2600.0 Hz)"]
    assert all(", converged; " in p and p.endswith(" s left") for p in points)
    steps = [int(p.split("): ")[1].split(" solver steps")[0]) for p in points]
    assert steps == told["num_steps"].values.tolist()
    np.testing.assert_allclose(told["rms_force"].values, batch["rms_force"].values,
                               rtol=1e-10)


@pytest.mark.slow
def test_a_sweep_is_reported_point_by_point_and_continues_as_in_one_call(monkeypatch):
    """The same stage swept up over two points: each point starts from the end of the one
    before, as the single compiled sweep does (same results). Slow (10-18 s on 2 cores):
    the claim compares two compiled sweeps, of one point and of two."""
    monkeypatch.setattr(_simulate, "REPORT_EVERY_S", 0.0)
    train = gj.load_train(DATA / "helicopter_five_planets.toml")
    lines = []
    with pytest.warns(gj.ContactLossWarning):
        told = gj.simulate_gear(train, from_hz=2500.0, to_hz=2600.0, points=2, linear=True,
                                progress=lines.append)
        whole = gj.simulate_gear(train, from_hz=2500.0, to_hz=2600.0, points=2, linear=True)
    points = [l for l in lines if l.startswith("integration: ")]
    assert [p.split(":")[1] for p in points] == [" point 1 of 2 (2500.0 Hz)",
                                                 " point 2 of 2 (2600.0 Hz)"]
    np.testing.assert_allclose(told["rms_force"].values, whole["rms_force"].values,
                               rtol=1e-10)
    np.testing.assert_array_equal(told["num_steps"].values, whole["num_steps"].values)
