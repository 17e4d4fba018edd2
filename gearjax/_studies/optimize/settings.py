"""The optimiser's settings and the checks of its arguments (in Python terms)."""

from __future__ import annotations

import dataclasses
import math

from ..._errors import bad_argument


@dataclasses.dataclass(frozen=True)
class OptimizeSettings:
    """Sizes of the optimiser's steps (the expensive parts; tests use tiny ones).

    **Fields:** ``proxy_points``: frequency grid of the first-order proxy;
    ``phase_grid``: sun-ring phases tried per planet set (``360 / phase_grid`` deg
    apart), and as many stage phases where the stage phase is varied; ``screen``: best
    proxy candidates per stage solved by the linear, time-varying harmonic balance;
    ``screen_points``: its frequencies per candidate (half geometric, half the
    candidate's highest proxy peaks); ``final_points``: geometric frequencies of the
    common grid the baseline, optimum and relaxation are compared on (plus the resonance
    frequencies and their proxy peaks);
    ``harmonics``: its K (``None``: the highest excitation order, so every stiffness
    harmonic is resolved; on a torus K on every angle, default each angle's highest
    excitation order); ``nonlinear``: best linear candidates per stage swept with
    backlash (0: decide on the linear model); the sweeps with backlash (the baseline's,
    each incumbent's and each candidate's) are complete sweeps
    (:func:`.nonlinear.nonlinear_band`: every stable state counts) with
    ``nonlinear_harmonics``: their fixed K (``None``: ``harmonics``, on a torus the
    largest of the screen's orders, on every angle), ``max_step_hz`` (``None``: 1/100 of
    the band), ``max_points`` (points of one sweep, walk and completion together) and
    ``seeds`` (integration seeds of the completion, 0: none);
    ``relax_iterations``: L-BFGS iterations of the continuous relaxation (0: skip it);
    ``temperature``: of its smooth peak (relative); ``passes``: rounds over the stages
    (a later stage's choice can unpin an earlier one's peak);
    ``chunk``: proxy designs per compiled call; ``devices``: shard the linear screen's
    designs across these (:mod:`gearjax._studies.design`).
    """

    proxy_points: int = 256
    phase_grid: int = 24
    screen: int = 24
    screen_points: int = 32
    final_points: int = 96
    harmonics: int | None = None
    nonlinear: int = 2
    nonlinear_harmonics: int | None = None
    max_step_hz: float | None = None
    max_points: int = 3000
    seeds: int = 0
    relax_iterations: int = 10
    temperature: float = 0.01
    passes: int = 1
    chunk: int = 64
    devices: tuple | None = None


INTEGER_BOUNDS = (("proxy_points", 2), ("phase_grid", 1), ("screen", 1),
                     ("screen_points", 2), ("nonlinear", 0), ("final_points", 2),
                     ("seeds", 0), ("max_points", 2), ("relax_iterations", 0),
                     ("passes", 1), ("chunk", 1))
"""Integer fields of :class:`OptimizeSettings` and their lower bounds, in checking order."""


def check_band(band_hz) -> tuple[float, float]:
    """``(lo, hi)`` (Hz) of a band ``band_hz``.

    **Raises:** ``ArgumentError`` naming ``band_hz`` where it is not two numbers with
    ``0 < lo < hi`` finite.
    """
    try:
        lo, hi = (float(x) for x in band_hz)
    except (TypeError, ValueError):
        raise bad_argument("band_hz", band_hz, "needs two frequencies (lo, hi) in Hz") from None
    if not (0 < lo < hi and math.isfinite(hi)):
        raise bad_argument("band_hz", [lo, hi],
                           "needs 0 < LO < HI, reference-stage mesh frequencies in Hz")
    return lo, hi


def check_settings(s: OptimizeSettings) -> None:
    """**Raises:** ``ArgumentError`` naming the first field of ``s`` (an argument of
    :class:`OptimizeSettings`) out of range: integers below their bound
    (:data:`INTEGER_BOUNDS`), harmonics below 1, a step or temperature not positive."""
    for name, low in INTEGER_BOUNDS:
        val = getattr(s, name)
        if int(val) != val or val < low:
            raise bad_argument(name, val, f"must be an integer >= {low}")
    for name in ("harmonics", "nonlinear_harmonics"):
        val = getattr(s, name)
        if val is not None and (int(val) != val or val < 1):
            raise bad_argument(name, val, "must be an integer >= 1")
    if s.max_step_hz is not None and not (s.max_step_hz > 0 and math.isfinite(s.max_step_hz)):
        raise bad_argument("max_step_hz", s.max_step_hz, "must be > 0 Hz")
    if not s.temperature > 0:
        raise bad_argument("temperature", s.temperature, "must be > 0")


def settings_dict(settings: OptimizeSettings) -> dict:
    """The settings as JSON values (``devices``: how many, or ``None``)."""
    out = {f.name: getattr(settings, f.name) for f in dataclasses.fields(settings)}
    out["devices"] = None if settings.devices is None else len(list(settings.devices))
    return out
