"""A sweep's progress on a stream: a progress bar across the band (:func:`progress_bar`)
or a plain line (:func:`progress_printer`).

Both return a ``progress(points_done, frequency_hz, branches)`` for
:func:`gearjax._studies.sweep.sweep`; the sweep passes ``branches`` (restarts so far plus
one) to a callable that takes a third positional argument.
"""

from __future__ import annotations

import inspect
import sys
import time
from collections.abc import Callable

from tqdm import tqdm

BAR_FORMAT = "sweep {percentage:3.0f}%|{bar}| {desc} [{elapsed}<{remaining}]"
"""What the bar shows: share of the band reached, the bar, frequency, points and
branches, elapsed time and tqdm's estimate of the time left."""


PLAIN_EVERY_S = 10.0
"""Seconds between two progress lines where no bar is drawn (off a terminal, or under
the command line's ``--json``)."""


class SweepProgress:
    """A sweep's progress across the band ``from_hz`` to ``to_hz`` (Hz, either direction)
    on ``stream``.

    Called as ``progress(points_done, frequency_hz, branches=1)``. Where ``live``, a
    tqdm bar on ``stream`` advances with the furthest frequency reached towards
    ``to_hz`` (a continuation turning back at a fold does not move it back; time left:
    tqdm's estimate from the rate across the band) and shows the frequency, the points
    and the branches; where not ``live``, a plain line (:meth:`final_line`'s words so
    far) every :data:`PLAIN_EVERY_S` seconds at most. :meth:`close` removes the bar
    and writes one final line (points, branches, furthest frequency, elapsed seconds),
    also where not ``live``; nothing is written when no point was reported (a sweep
    refused before its first point). A context manager: leaving it closes.
    """

    def __init__(self, from_hz: float, to_hz: float, stream=sys.stderr, *, live: bool = True):
        self.from_hz, self.to_hz, self.stream = float(from_hz), float(to_hz), stream
        self.span = abs(self.to_hz - self.from_hz)
        self.points, self.branches, self.reached_hz = 0, 1, self.from_hz
        self.t0 = self.shown = time.perf_counter()
        self.closed = False
        self.bar = (tqdm(total=self.span, file=stream, bar_format=BAR_FORMAT, leave=False,
                         dynamic_ncols=True, desc=self._status(self.from_hz))
                    if live else None)

    def _status(self, f_hz: float) -> str:
        return (f"{f_hz:7.1f} Hz, {self.points} points, {self.branches} "
                f"branch{'es' if self.branches != 1 else ''}")

    def _covered(self, f_hz: float) -> float:
        """Share of the band from ``from_hz`` to ``f_hz`` (Hz, clipped to the band)."""
        way = 1.0 if self.to_hz >= self.from_hz else -1.0
        return min(max((f_hz - self.from_hz) * way, 0.0), self.span)

    def __call__(self, n: int, f_hz: float, branches: int = 1) -> None:
        self.points, self.branches = int(n), max(self.branches, int(branches))
        if self._covered(f_hz) > self._covered(self.reached_hz):
            self.reached_hz = float(f_hz)
        if self.bar is not None:
            self.bar.set_description_str(self._status(float(f_hz)), refresh=False)
            self.bar.update(self._covered(self.reached_hz) - self.bar.n)
        elif time.perf_counter() - self.shown >= PLAIN_EVERY_S:
            self.shown = time.perf_counter()
            self.stream.write(self.final_line() + "\n")
            self.stream.flush()

    def note(self, line: str) -> None:
        """Write ``line`` on the stream (above the bar where it is live), for the steps
        that run before the first point (a sweep's ``say``)."""
        if self.bar is not None:
            self.bar.write(line, file=self.stream)
        else:
            self.stream.write(line + "\n")
            self.stream.flush()

    def final_line(self) -> str:
        """``sweep: N points, B branches, up to F Hz, T s`` (the points and frequency
        reached so far while the sweep runs)."""
        return (f"sweep: {self.points} points, {self.branches} "
                f"branch{'es' if self.branches != 1 else ''}, up to {self.reached_hz:.1f} Hz, "
                f"{time.perf_counter() - self.t0:.1f} s")

    def close(self) -> None:
        """Remove the bar and write the final line (once; none without a point)."""
        if self.closed:
            return
        self.closed = True
        if self.bar is not None:
            self.bar.close()
        if self.points:
            self.stream.write(self.final_line() + "\n")
            self.stream.flush()

    def __enter__(self) -> SweepProgress:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def progress_bar(from_hz: float, to_hz: float, stream=None, *,
                 quiet: bool = False) -> SweepProgress:
    """The progress of a sweep from ``from_hz`` to ``to_hz`` (Hz) on ``stream`` (default:
    ``sys.stderr`` when called) (:class:`SweepProgress`): a tqdm bar where ``stream`` is a
    terminal and not ``quiet`` (the command line's ``--json``), and one final line on
    :meth:`~SweepProgress.close` in every case. Pass it as the sweep's ``progress`` and
    close it after (or use it as a context manager)."""
    stream = sys.stderr if stream is None else stream
    isatty = getattr(stream, "isatty", None)
    return SweepProgress(from_hz, to_hz, stream,
                         live=not quiet and bool(isatty is not None and isatty()))


def with_branches(progress: Callable[..., None] | None) -> Callable[..., None] | None:
    """``progress`` as a ``progress(points_done, frequency_hz, branches)``: itself where
    it takes a third positional argument (or ``*args``), else a wrapper that drops
    ``branches`` (a ``progress(points_done, frequency_hz)`` of the older contract);
    ``None`` stays ``None``."""
    if progress is None:
        return None
    try:
        params = list(inspect.signature(progress).parameters.values())
    except (TypeError, ValueError):  # no signature to read (some builtins)
        params = []
    positional = [p for p in params if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)]
    if len(positional) >= 3 or any(p.kind == p.VAR_POSITIONAL for p in params):
        return progress
    return lambda n, f_hz, branches: progress(n, f_hz)


def progress_printer(stream=sys.stderr) -> Callable[..., None]:
    """A ``progress(points_done, frequency_hz, branches=1)`` for
    :func:`gearjax._studies.sweep.sweep` that writes a line on ``stream``: rewritten in
    place on a terminal, otherwise each time the count passes a multiple of 25 (a
    segment taken whole from the journal or from the speculation passes several at
    once). :func:`progress_bar` draws a bar across the band instead."""
    tty = stream.isatty()
    t0 = time.perf_counter()
    shown = [0]

    def show(n: int, f_hz: float, branches: int = 1) -> None:
        if tty or n // 25 > shown[0] // 25:  # past a multiple of 25 (or several at once)
            shown[0] = n
            end = "\r" if tty else "\n"
            stream.write(f"sweep: {n} points, at {f_hz:9.1f} Hz, {branches} "
                         f"branch{'es' if branches != 1 else ''}, "
                         f"{time.perf_counter() - t0:6.1f} s" + end)
            stream.flush()

    return show
