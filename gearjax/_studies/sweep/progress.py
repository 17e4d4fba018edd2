"""A sweep's progress, as a line on a stream."""

from __future__ import annotations

import sys
import time
from collections.abc import Callable


def progress_printer(stream=sys.stderr) -> Callable[[int, float], None]:
    """A ``progress(points_done, frequency_hz)`` for :func:`gearjax._studies.sweep.sweep`
    that writes a line on ``stream``: rewritten in place on a terminal, every 25 points
    otherwise."""
    tty = stream.isatty()
    t0 = time.perf_counter()

    def show(n: int, f_hz: float) -> None:
        if tty or n % 25 == 0:
            end = "\r" if tty else "\n"
            stream.write(f"sweep: {n} points, at {f_hz:9.1f} Hz, {time.perf_counter() - t0:6.1f} s"
                         + end)
            stream.flush()

    return show
