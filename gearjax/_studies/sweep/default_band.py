"""The band a sweep covers when none is asked for: from the train's elastic modes and
the gear's excitation orders, not the paper's 2-15 kHz.

At reference-stage mesh frequency ``f``, stage ``n`` excites at ``h r_n f`` (``r_n`` its
mesh frequency over the reference stage's, ``h = 1..H`` the stiffness harmonics kept).
The band reaches down until the highest of these, ``H max(r_n) f``, meets the lowest
elastic mode (with a margin :data:`LOW_MARGIN`), and up until the fastest stage's
fundamental, ``max(r_n) f``, passes the highest mode whose strain energy is mostly in
the meshes (with a margin :data:`HIGH_MARGIN`): the super-harmonic resonances of the
kept stiffness harmonics with the lowest mode, and the primary resonances of the
fastest stage with every mesh-dominated mode, lie inside.
"""

from __future__ import annotations

import dataclasses

from ..._errors import bad_argument, fail
from ..._gear.case import GearCase, gear_case
from ..harmonics import elastic_mode_span_hz

LOW_MARGIN = 0.8
"""The band starts at this fraction of the lowest super-harmonic resonance."""
HIGH_MARGIN = 1.25
"""The band ends at this multiple of the highest mesh-dominated primary resonance."""


@dataclasses.dataclass(frozen=True)
class DefaultBand:
    """``from_hz``, ``to_hz`` (reference-stage mesh Hz) and ``reason``, one line naming
    the modes and orders that set them."""

    from_hz: float
    to_hz: float
    reason: str


def default_band(case: GearCase) -> DefaultBand:
    """The band of :mod:`this module <gearjax._studies.sweep.default_band>` for a gear.

    **Raises:** ``TrainError`` where the gear has no elastic mode (nothing to resonate).
    """
    system = case.system
    span = elastic_mode_span_hz(system)
    if span is None:
        raise fail(case.train.source, f"gears.{case.gear.name}", case.gear.name,
                   "has no elastic mode, so no band can be chosen from its modes; give the "
                   "band (`from_hz`, `to_hz`)")
    bottom, top = span
    ref = case.kin.stage(case.stage).mesh_frequency
    ratios = [float(s.mesh_frequency / ref) for s in case.kin.stages if s.turning]
    H = max(int(system.k_cos.shape[-1]), int(system.te_cos.shape[-1]), 1)  # as the floor
    lo = LOW_MARGIN * bottom / (H * max(ratios))
    hi = HIGH_MARGIN * top / max(ratios)
    reason = (f"from the gear's elastic modes: down to {LOW_MARGIN:g} x the lowest "
              f"({bottom:.1f} Hz) over the highest excitation order (H = {H} x "
              f"{max(ratios):.4g}), up to {HIGH_MARGIN:g} x the highest mesh-dominated mode "
              f"({top:.1f} Hz) over the fastest stage's fundamental ({max(ratios):.4g} x "
              f"stage {case.stage}'s mesh frequency)")
    return DefaultBand(from_hz=lo, to_hz=hi, reason=reason)


def resolve_band(train, gear: str | None, stage: str | None, linear: bool, from_hz,
                 to_hz) -> tuple[float, float, str | None]:
    """``(from_hz, to_hz, reason)``: the band asked for (``reason`` ``None``), or with
    both ends ``None`` the :func:`default_band` of the gear and its reason.

    **Raises:** ``ArgumentError`` naming the end that is missing when only one is given.
    """
    if from_hz is not None and to_hz is not None:
        return from_hz, to_hz, None
    if from_hz is not None or to_hz is not None:
        missing = "to_hz" if to_hz is None else "from_hz"
        raise bad_argument(missing, None, "give both `from_hz` and `to_hz`, or neither for "
                           "the band chosen from the gear's modes")
    band = default_band(gear_case(train, gear, stage, linear, torus=True))
    return band.from_hz, band.to_hz, band.reason
