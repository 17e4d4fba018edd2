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
    ``linear_rms`` ``(F, m)`` (N) on the result's common grid; ``nonlinear``
    (:class:`NonlinearBand`: its complete sweep with backlash, or ``None``);
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
        """The largest RMS mesh force over every stable state of the complete sweep with
        backlash (N; NaN where not swept)."""
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
    (:func:`~gearjax._gear.case.torus_fields`; ``None`` for a periodic gear);
    ``models``: which model and settings each step used (``proxy``, ``linear``,
    ``backlash``, ``final``, ``relaxation``; JSON values); ``verdict``: the optimum
    against the baseline on the model that decided (:func:`verdict`).
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
    models: dict | None = None
    verdict: dict | None = None

    @property
    def recommended_train(self) -> Train:
        """The optimum where it beats the baseline (``verdict``), else the baseline."""
        beats = (self.verdict or {}).get("recommended") == "optimum"
        return self.train if beats else self.baseline_train

    @property
    def converged(self) -> bool:
        ok = bool(np.any(np.isfinite(self.optimum.linear_rms)))
        if self.optimum.nonlinear is not None:
            ok = ok and self.optimum.nonlinear.frequencies_hz.size > 0
        return ok


NO_BETTER = "no admissible phasing it tried beats the baseline"
"""The words of a :func:`verdict` where the optimum does not beat the baseline."""


def verdict(baseline_peak: float, optimum_peak: float, *, same: bool, rtol: float, model: str,
            settings: str = "", incomplete: list | tuple = (), notes: list | tuple = ()
            ) -> dict:
    """The optimum against the baseline, in plain words.

    ``baseline_peak``, ``optimum_peak``: their peaks (N) on ``model`` (what the peaks are,
    e.g. ``complete-sweep peak with backlash``; ``settings``: how they were computed, said
    after the text in brackets); ``same``: the optimum is the baseline design; ``rtol``:
    the optimum beats the baseline only where its peak is lower by more than this
    (relative); ``incomplete``: names of the designs whose sweep is not complete (said
    in the text: a stable state may be missing); ``notes``: more clauses for the text.

    **Returns:** ``{"beats_baseline", "recommended" ("optimum" or "baseline"),
    "baseline_peak", "optimum_peak", "reduction" (N, baseline - optimum; NaN where a peak
    is), "reduction_relative", "model", "settings", "text"}``; the text says either that
    the optimum's peak is below the baseline's and by how much, or :data:`NO_BETTER` and
    that the recommended design is the baseline.
    """
    b, o = float(baseline_peak), float(optimum_peak)
    comparable = math.isfinite(b) and math.isfinite(o)
    beats = bool(not same and comparable and o < b * (1 - rtol))
    drop = b - o if comparable else math.nan
    if beats:
        text = (f"the optimum's {model} is {o:.1f} N, below the baseline's {b:.1f} N by "
                f"{drop:.1f} N ({100 * drop / b:.1f}%)")
    else:
        if same and math.isfinite(b):
            why = f"every step kept the incumbent, the baseline's {model} is {b:.1f} N"
        elif comparable:
            why = f"the optimum's {model} is {o:.1f} N against the baseline's {b:.1f} N"
        else:
            why = (f"no {model} to compare, baseline {b:.1f} N, optimum {o:.1f} N (NaN: no "
                   "stable state counted)")
        text = f"{NO_BETTER}: {why}; the recommended design is the baseline"
    if incomplete:
        text += (f"; the sweep of the {' and the '.join(incomplete)} is not complete (point "
                 "budget or branch cap spent): a stable state may be missing")
    for note in notes:
        text += f"; {note}"
    if settings:
        text += f" [{settings}]"
    return {"beats_baseline": beats, "recommended": "optimum" if beats else "baseline",
            "baseline_peak": b, "optimum_peak": o, "reduction": drop,
            "reduction_relative": drop / b if comparable and b else math.nan,
            "model": model, "settings": settings, "text": text}
