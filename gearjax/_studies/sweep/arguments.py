"""The arguments of a sweep checked before any work, in Python terms."""

from __future__ import annotations

import math
import numbers

from ..._errors import bad_argument


def check_arguments(from_hz, to_hz, *, eta, smoothing, harmonics, max_step_hz, points,
                    max_points, seeds=0, linear=False) -> None:
    """Refuse arguments of :func:`gearjax._studies.sweep.sweep` that cannot describe a
    sweep.

    **Raises:** ``ArgumentError`` naming the argument (``from_hz``, ``to_hz``, ``eta``,
    ``smoothing``, ``harmonics``, ``max_step_hz``, ``points``, ``max_points``,
    ``seeds``); ``linear``: a linear sweep, whose grid of ``points`` must fit in
    ``max_points``."""
    def integer(value) -> bool:
        return isinstance(value, numbers.Integral) and not isinstance(value, bool)

    def real(value) -> bool:
        return isinstance(value, numbers.Real) and not isinstance(value, bool)

    for name, f in (("from_hz", from_hz), ("to_hz", to_hz)):
        if not (real(f) and f > 0 and math.isfinite(f)):
            raise bad_argument(name, f, "must be a positive mesh frequency in Hz")
    if from_hz == to_hz:
        raise bad_argument("to_hz", to_hz, "must differ from `from_hz`")
    if not integer(eta) or eta < 1:
        raise bad_argument("eta", eta, "must be an integer >= 1")
    if not (real(smoothing) and 0.0 <= smoothing < 1.0):
        raise bad_argument("smoothing", smoothing,
                           "must be >= 0 (0: exact backlash) and < 1 (relative to the backlash)")
    if harmonics is not None and (not integer(harmonics) or harmonics < 1):
        raise bad_argument("harmonics", harmonics, "must be an integer >= 1")
    if max_step_hz is not None and not (real(max_step_hz) and max_step_hz > 0
                                        and math.isfinite(max_step_hz)):
        raise bad_argument("max_step_hz", max_step_hz, "must be a positive frequency step in "
                           "Hz (omit it for 1/100 of the band)")
    if not integer(points) or points < 2:
        raise bad_argument("points", points, "must be an integer >= 2")
    if not integer(max_points) or max_points < 2:
        raise bad_argument("max_points", max_points, "must be an integer >= 2")
    if linear and points > max_points:
        raise bad_argument("points", points, f"more than `max_points` = {max_points}, the "
                           "most points a linear sweep solves (its grid and the middles "
                           "that refine it)")
    if not integer(seeds) or seeds < 0 or seeds == 1:
        raise bad_argument("seeds", seeds, "must be 0 (no integration seeds) or an integer "
                           ">= 2 (frequencies of the up and down integration sweeps)")
