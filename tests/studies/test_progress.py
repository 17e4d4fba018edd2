"""A sweep's progress: a tqdm bar on a terminal; otherwise and under ``--json`` a plain
line every ``PLAIN_EVERY_S`` seconds at most and a final line (the command line's
decision: ``--json`` keeps stdout for the JSON object and stderr for lines of progress
and warnings)."""

import io
import sys
import time

import pytest

import gearjax as gj
from gearjax._cli import main
from gearjax._studies.sweep import progress as _progress


class Terminal(io.StringIO):
    """A stream that says it is a terminal."""

    def isatty(self):
        return True


def feed(bar, frequencies, branches=None):
    for n, f in enumerate(frequencies, start=1):
        bar(n, f, 1 if branches is None else branches[n - 1])
        time.sleep(0.11)  # past tqdm's refresh interval (0.1 s): every call shown


def test_a_stream_that_is_no_terminal_gets_only_the_final_line_within_the_interval():
    stream = io.StringIO()
    with gj.progress_bar(3200, 3400, stream) as bar:
        for n, f in enumerate([3200, 3250, 3240, 3300, 3400], start=1):
            bar(n, f, 1 + n // 4)
    lines = stream.getvalue().splitlines()
    assert len(lines) == 1 and "\r" not in stream.getvalue()
    assert lines[0].startswith("sweep: 5 points, 2 branches, up to 3400.0 Hz, ")
    assert lines[0].endswith(" s")


def test_a_stream_that_is_no_terminal_gets_a_line_each_interval(monkeypatch):
    monkeypatch.setattr(_progress, "PLAIN_EVERY_S", 0.0)
    stream = io.StringIO()
    with gj.progress_bar(3200, 3400, stream) as bar:
        for n, f in enumerate([3200, 3250, 3240], start=1):
            bar(n, f, 1)
    lines = stream.getvalue().splitlines()
    assert [l.split(", up to ")[0] for l in lines] == [
        "sweep: 1 points, 1 branch", "sweep: 2 points, 1 branch", "sweep: 3 points, 1 branch",
        "sweep: 3 points, 1 branch"]  # the last one the final line
    assert "up to 3250.0 Hz" in lines[-1]  # the furthest reached, not the last reported


def test_a_terminal_gets_a_bar_across_the_band_with_frequency_points_and_branches():
    stream = Terminal()
    with gj.progress_bar(3400, 3200, stream) as bar:  # downwards
        feed(bar, [3390 - 10 * k for k in range(10)], branches=[1] * 5 + [2] * 5)
        shown = stream.getvalue()
    updates = [u for u in shown.split("\r") if u.startswith("sweep ")]
    assert len(updates) >= 6
    assert any("3310.0 Hz, 9 points, 2 branches" in u or "3300.0 Hz, 10 points, 2 branches"
               in u for u in updates)
    assert any(" 50%|" in u for u in updates)  # 3300 Hz: half of the band downwards
    assert all("<" in u and "[" in u for u in updates)  # elapsed<time left
    final = stream.getvalue().split("\r")[-1]
    assert final.startswith("sweep: 10 points, 2 branches, up to 3300.0 Hz, ")


def test_the_bar_follows_the_furthest_frequency_not_the_fold_turning_back():
    bar = gj.progress_bar(2000, 3000, Terminal())
    for n, f in enumerate([2100, 2600, 2400, 2200, 2500, 2800], start=1):
        bar(n, f)
        if n in (2, 5):
            assert bar.bar.n == pytest.approx(600)
    bar.close()
    assert bar.reached_hz == 2800


def test_quiet_draws_no_bar_and_nothing_without_a_point():
    stream = Terminal()
    with gj.progress_bar(2000, 3000, stream, quiet=True) as bar:
        bar(1, 2000.0)
    assert stream.getvalue().count("\n") == 1 and "\r" not in stream.getvalue()
    stream = io.StringIO()
    with pytest.raises(ValueError):
        with gj.progress_bar(2000, 3000, stream):
            raise ValueError("refused before the first point")
    assert stream.getvalue() == ""


def test_callbacks_of_two_arguments_still_work():
    seen = []
    two = _progress.with_branches(lambda n, f_hz: seen.append((n, f_hz)))
    two(3, 2500.0, 2)
    assert seen == [(3, 2500.0)]
    bar = gj.progress_bar(2000, 3000, io.StringIO())
    assert _progress.with_branches(bar) is bar
    assert _progress.with_branches(None) is None
    printer = gj.progress_printer(io.StringIO())
    assert _progress.with_branches(printer) is printer


def test_printer_off_a_terminal_writes_a_line_per_25_points_also_where_it_jumps():
    """A speculated segment or one taken from the journal reports many points at once:
    the count passing a multiple of 25 writes a line, a count going back does not."""
    stream = io.StringIO()
    show = gj.progress_printer(stream)
    for n in (1, 24, 25, 26, 49, 120, 119, 124, 130, 300):
        show(n, 1000.0 + n)
    counts = [int(line.split()[1]) for line in stream.getvalue().splitlines()]
    assert counts == [25, 120, 130, 300]


@pytest.mark.parametrize("json_flag", [[], ["--json"]])
@pytest.mark.parametrize("terminal", [False, True])
def test_sweep_command_writes_only_the_final_progress_line_unless_on_a_terminal(
        capsys, monkeypatch, paper_toml_h1, json_flag, terminal):
    """Off a terminal, and under --json also on one, stderr gets the line announcing the
    truncation check (the step before the first point) and one final progress line (the
    run is shorter than ``PLAIN_EVERY_S``; the flank is straight: no refinement round,
    whose lines tests/studies/test_refine_bounds.py checks)."""
    monkeypatch.setattr(_progress, "PLAIN_EVERY_S", 3600.0)
    stream = Terminal() if terminal else None
    if stream is not None:
        monkeypatch.setattr(sys, "stderr", stream)
    code = main(["sweep", str(paper_toml_h1), "--linear", "--from", "5000", "--to", "5400",
                 "--points", "3", "--harmonics", "16", *json_flag])
    err = stream.getvalue() if stream is not None else capsys.readouterr().err
    check = "sweep: truncation check, segment 1 of 1 at 5000.0 Hz: K = 16 against 32"
    lines = [l for l in err.splitlines() if not l.startswith("warning: ")]
    assert not any(l.startswith("sweep: refinement round ") for l in lines)  # a straight flank
    assert code == 0 and check in err
    if terminal and not json_flag:
        assert "\rsweep   0%|" in err and "5000.0 Hz, 0 points" in err  # the bar drawn
        lines = [err.split("\r")[-1].strip()]  # then wiped for the final line
    else:
        assert lines[0] == check
        lines = lines[1:]
    assert len(lines) == 1 and "\r" not in lines[0]
    assert lines[0].startswith("sweep: 3 points, 1 branch, up to 5400.0 Hz, ")
