"""What an optimisation returns: the designs compared and the optimiser's record."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..._gear.train import Train
from .nonlinear import NonlinearBand
from .relaxation import Relaxation
from .settings import OptimizeSettings


@dataclasses.dataclass(frozen=True)
class Design:
    """One design and its objective values.

    **Fields:** ``values``: path -> value of every varied path (deg); ``planet_sets``:
    stage -> angles (deg); ``linear_peak``, ``linear_stage_peaks`` (N) and
    ``linear_rms`` ``(F, m)`` (N) on the result's common grid; ``nonlinear`` (:class:`NonlinearBand` or ``None``);
    ``admissible``: every planet set assemblable and clear.
    """

    values: dict
    planet_sets: dict
    linear_peak: float
    linear_stage_peaks: dict
    linear_rms: np.ndarray
    nonlinear: NonlinearBand | None
    admissible: bool

    @property
    def nonlinear_peak(self) -> float:
        return self.nonlinear.peak if self.nonlinear is not None else math.nan


@dataclasses.dataclass(frozen=True)
class OptimizeResult:
    """A finished phasing optimisation.

    **Fields:** ``gear``, ``reference_stage``, ``band_hz`` ``(lo, hi)`` (Hz), ``vary``
    (the ``vary`` spellings, ``STAGE.KEY``), ``paths`` (the design vector's TOML paths);
    ``baseline``, ``optimum``: :class:`Design`; ``train``: the optimum train;
    ``baseline_train``: the train given;
    ``relaxation``: :class:`Relaxation` or ``None``; ``candidates``: dict of columns,
    one row per candidate (``stage``, ``planet_angles_deg`` ``(C, N_max)``,
    ``sun_ring_phase_deg``, ``stage_phase_deg``, ``proxy_peak``, ``linear_stage_peak``,
    ``linear_peak``, ``nonlinear_stage_peak``, ``nonlinear_peak``,
    ``nonlinear_coverage``, ``incumbent``, ``selected``; NaN where a model was not run);
    ``stages``: per stage, what was enumerated and chosen; ``frequencies_hz`` ``(F,)``:
    the common grid of the designs' ``linear_rms`` (Hz); ``meshes``, ``mesh_stage``, ``mesh_side``, ``mesh_planet``;
    ``settings``; ``seconds``; ``converged``: the optimum has converged points;
    ``harmonics``: K of the linear screen (an ``int``, or on a torus the orders per
    angle, a tuple); ``torus``: what a torus study solves
    (:func:`~gearjax._gear.case.torus_fields`; ``None`` for a periodic gear).
    """

    gear: str
    reference_stage: str
    band_hz: tuple[float, float]
    vary: tuple[str, ...]
    paths: tuple[str, ...]
    baseline: Design
    optimum: Design
    train: Train
    baseline_train: Train
    relaxation: Relaxation | None
    candidates: dict
    stages: list
    frequencies_hz: np.ndarray
    meshes: tuple[str, ...]
    mesh_stage: tuple[str, ...]
    mesh_side: tuple[str, ...]
    mesh_planet: tuple[int, ...]
    settings: OptimizeSettings
    seconds: float
    harmonics: int | tuple[int, ...] | None = None
    torus: dict | None = None

    @property
    def converged(self) -> bool:
        ok = bool(np.any(np.isfinite(self.optimum.linear_rms)))
        if self.optimum.nonlinear is not None:
            ok = ok and self.optimum.nonlinear.frequencies_hz.size > 0
        return ok
