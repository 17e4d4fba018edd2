"""The objective with backlash: the largest RMS mesh force over every stable state that a
complete sweep finds.

:func:`nonlinear_band` runs one :func:`gearjax.sweep` with ``complete=True`` (its walk
with restarts, then the completion of :mod:`gearjax._studies.sweep.completion`: the
start at the band's far end, the orbits a rig sweeping up or down jumps to where a
stable stretch ends, period-doubled branches, optionally integration seeds) and takes
the peak over the points a gearbox can show (:func:`stable_points`): converged
(``result == "converged"``) and stable (``stable == 1``). Unstable orbits, points of
unknown stability and points flagged ``runaway`` (past the sweep's runaway bound,
:data:`gearjax._studies.sweep.RUNAWAY`) are counted and left out. The optimiser's
screening sweeps and its re-check use the same machinery with different
:class:`BandSettings` (screening: a fixed K and the optimiser's steps; re-check: the
sweep's own frequency-dependent K).
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from collections.abc import Callable

import numpy as np

from ..._gear.train import Train
from ..sweep import sweep
from ..sweep.completion import MAX_BRANCHES

NONLINEAR_RTOL = 1e-3
"""Peaks with backlash closer than this (relative) count as equal: a design beats another
only by more."""

WALKED = ("sweep", "restart")
"""How the branches of a sweep's walk are found (the completion's are found otherwise)."""


@dataclasses.dataclass(frozen=True)
class BandSettings:
    """Settings of one complete sweep with backlash (:func:`nonlinear_band`).

    **Fields:** ``harmonics``: a fixed K (``None``: the sweep's own frequency-dependent
    K, :func:`gearjax._studies.harmonics.harmonics_rule`); ``max_step_hz``: largest
    frequency step (``None``: 1/100 of the band); ``max_points``: points of the whole
    sweep, walk and completion together (a sweep that spends them is flagged not
    complete); ``seeds``: integration seeds of the completion (0: none; see
    :func:`gearjax.sweep`).
    """

    harmonics: int | None = None
    max_step_hz: float | None = None
    max_points: int = 3000
    seeds: int = 0

    def as_dict(self) -> dict:
        """JSON fields, with ``complete: true`` (every sweep of the optimiser is one)."""
        return {"complete": True, "harmonics": self.harmonics,
                "max_step_hz": self.max_step_hz, "max_points": int(self.max_points),
                "seeds": int(self.seeds)}

    def text(self) -> str:
        """``complete sweep, K = 32, steps <= 100 Hz, <= 3000 points``-style summary."""
        return ("complete sweep, "
                + ("the sweep's own K" if self.harmonics is None else f"K = {self.harmonics}")
                + (", steps <= 1/100 of the band" if self.max_step_hz is None
                   else f", steps <= {self.max_step_hz:g} Hz")
                + f", <= {int(self.max_points)} points"
                + (f", {int(self.seeds)} integration seeds" if self.seeds else ""))


@dataclasses.dataclass(frozen=True)
class NonlinearBand:
    """A complete sweep with backlash over a band and its peak over stable states.

    **Fields:** ``frequencies_hz`` ``(P,)``, ``rms_force`` ``(P, m)`` (N), ``branch``
    ``(P,)`` and ``found`` ``(P,)`` (how the point's branch was found: ``sweep``,
    ``restart``, ``far end``, ``jump up``, ``jump down``, ``period doubling``, ...) of
    the counted points (:func:`stable_points`), in sweep order; ``peak`` (N, NaN where no
    point counts), ``peak_hz``, ``peak_mesh``, ``peak_found`` (how the peak's branch was
    found); ``walk_peak``: the peak over the walk's branches alone (:data:`WALKED`: what
    a sweep without completion reports; below ``peak`` where the completion found a
    higher stable state); ``stage_peaks``: stage id -> peak of its meshes (N);
    ``unstable``: converged points left out as unstable or of unknown stability;
    ``runaway``: points flagged ``runaway``; ``not_converged``: other results;
    ``points``: all points of the sweep; ``branches``: the sweep's branch records
    (``{"branch", "found", "seed_hz", "stops", "eta"}``); ``stop``: why the walk ended;
    ``coverage``: share of the band (log frequency) within the span of some branch's
    converged points; ``complete``: the completion ran to its end (not stopped by
    ``max_points`` or :data:`~gearjax._studies.sweep.completion.MAX_BRANCHES`: then a
    stable state may be missing); ``settings``: the :class:`BandSettings`; ``seconds``.
    """

    frequencies_hz: np.ndarray
    rms_force: np.ndarray
    branch: np.ndarray
    found: np.ndarray
    peak: float
    peak_hz: float
    peak_mesh: str
    peak_found: str
    walk_peak: float
    stage_peaks: dict
    unstable: int
    runaway: int
    not_converged: int
    points: int
    branches: tuple
    stop: str
    coverage: float
    complete: bool
    settings: BandSettings
    seconds: float


def stable_points(ds) -> np.ndarray:
    """``(P,)`` bool: the points of a sweep Dataset that count towards a peak: result
    ``converged`` (``runaway`` and failed points do not) and ``stable == 1``."""
    result = np.asarray(ds["result"].values).astype(str)
    return (result == "converged") & (np.asarray(ds["stable"].values, dtype=float) == 1)


def point_found(ds) -> np.ndarray:
    """``(P,)`` str: how each point's branch was found (``found``; a sweep without
    completion: ``sweep`` for branch 0, ``restart`` for the rest)."""
    if "found" in ds.variables:
        return np.asarray(ds["found"].values).astype(str)
    branch = np.asarray(ds["branch"].values) if "branch" in ds.variables else np.zeros(
        ds.sizes["point"], int)
    return np.where(branch == 0, "sweep", "restart")


def band_peak(ds) -> tuple[float, float, str, int]:
    """``(peak RMS (N), reference-stage Hz, mesh, point index)`` of a sweep Dataset over
    the points :func:`stable_points` counts; ``(nan, nan, "", -1)`` when none does."""
    ok = stable_points(ds)
    rms = np.where(ok[:, None], np.asarray(ds["rms_force"].values, float), -np.inf)
    rms = np.where(np.isfinite(rms), rms, -np.inf)
    if not np.any(np.isfinite(rms)):
        return math.nan, math.nan, "", -1
    i, j = np.unravel_index(int(np.argmax(rms)), rms.shape)
    return (float(rms[i, j]), float(ds["mesh_frequency_hz"].values[i]),
            str(ds["mesh"].values[j]), int(i))


def sweep_complete(result, max_points: int) -> bool:
    """Whether the sweep ``result`` (:class:`~gearjax.SweepResult`) ran its completion to
    the end: no way of it stopped at the point budget ``max_points``, fewer branches
    than :data:`~gearjax._studies.sweep.completion.MAX_BRANCHES`, fewer points than the
    budget."""
    stops = [result.stop] + [s for b in result.branches for s in b.get("stops", ())]
    return ("max_points" not in stops and len(result.branches) < MAX_BRANCHES
            and result.dataset.sizes["point"] < max_points)


def band_of(result, lo: float, hi: float, settings: BandSettings,
            seconds: float | None = None) -> NonlinearBand:
    """The :class:`NonlinearBand` of a finished complete sweep ``result`` over
    ``(lo, hi)`` (Hz) run with ``settings``."""
    ds = result.dataset
    ok = stable_points(ds)
    word = np.asarray(ds["result"].values).astype(str)
    converged = word == "converged"
    found = point_found(ds)
    f_all = np.asarray(ds["mesh_frequency_hz"].values, float)
    rms_all = np.asarray(ds["rms_force"].values, float)
    branch_all = np.asarray(ds["branch"].values) if "branch" in ds.variables else np.zeros(
        f_all.size, int)
    peak, peak_hz, mesh, i = band_peak(ds)
    walked = ok & np.isin(found, WALKED)
    w = rms_all[walked]
    walk_peak = float(np.nanmax(w)) if w.size and np.any(np.isfinite(w)) else math.nan
    stage_of = np.asarray(ds["stage"].values).astype(str)
    stage_peaks = {}
    for sid in dict.fromkeys(stage_of.tolist()):
        v = rms_all[ok][:, stage_of == sid]
        stage_peaks[sid] = float(np.nanmax(v)) if v.size and np.any(np.isfinite(v)) else (
            math.nan)
    spans = []
    for b in np.unique(branch_all[converged]):
        f = f_all[converged & (branch_all == b)]
        spans.append((max(float(f.min()), lo), min(float(f.max()), hi)))
    covered, end = 0.0, lo
    for a, b in sorted(spans):  # the union of the branches' spans, in log frequency
        a = max(a, end)
        if b > a:
            covered += math.log(b / a)
            end = b
    branches = tuple(result.branches) or tuple(
        {"branch": int(b), "found": "sweep" if b == 0 else "restart"}
        for b in np.unique(branch_all))
    return NonlinearBand(
        frequencies_hz=f_all[ok], rms_force=rms_all[ok], branch=branch_all[ok],
        found=found[ok], peak=peak, peak_hz=peak_hz, peak_mesh=mesh,
        peak_found=str(found[i]) if i >= 0 else "", walk_peak=walk_peak,
        stage_peaks=stage_peaks, unstable=int(np.sum(converged & ~ok)),
        runaway=int(np.sum(word == "runaway")),
        not_converged=int(np.sum(~converged & (word != "runaway"))),
        points=int(f_all.size), branches=tuple(json.loads(json.dumps(list(branches)))),
        stop=str(result.stop), coverage=min(1.0, covered / math.log(hi / lo)),
        complete=sweep_complete(result, settings.max_points), settings=settings,
        seconds=result.seconds if seconds is None else seconds)


def complete_sweep(train: Train, gear: str, lo: float, hi: float, stage: str | None,
                   settings: BandSettings):
    """The complete :func:`gearjax.sweep` of ``gear`` with backlash from ``lo`` to ``hi``
    (reference-stage Hz, reference stage ``stage``) with ``settings``
    (:class:`BandSettings`). **Raises:** as :func:`gearjax.sweep`."""
    return sweep(train, gear, lo, hi, stage=stage, harmonics=settings.harmonics,
                 max_step_hz=settings.max_step_hz, max_points=settings.max_points,
                 complete=True, seeds=settings.seeds)


def nonlinear_band(train: Train, gear: str, lo: float, hi: float, *, stage: str | None = None,
                   settings: BandSettings = BandSettings(),
                   progress: Callable[[str], None] | None = None) -> NonlinearBand:
    """Sweep ``gear`` with backlash from ``lo`` to ``hi`` (reference-stage Hz) by one
    complete :func:`gearjax.sweep` with ``settings`` (:class:`BandSettings`) and take
    its peak over stable states. ``stage``: the reference stage; ``progress(message)``:
    called once, with the sweep's summary.

    **Returns:** :class:`NonlinearBand` (peak NaN where no point counts). **Raises:** as
    :func:`gearjax.sweep`; a sweep with no point at all (``RuntimeError``) gives a band
    with no point, coverage 0, not complete.
    """
    t0 = time.perf_counter()
    try:
        r = complete_sweep(train, gear, lo, hi, stage, settings)
    except RuntimeError as e:  # no point at all: nothing counts
        if progress:
            progress(f"  complete sweep {lo:.0f}-{hi:.0f} Hz: no point ({e})")
        return NonlinearBand(
            frequencies_hz=np.zeros(0), rms_force=np.zeros((0, 0)), branch=np.zeros(0, int),
            found=np.zeros(0, str), peak=math.nan, peak_hz=math.nan, peak_mesh="",
            peak_found="", walk_peak=math.nan, stage_peaks={}, unstable=0, runaway=0,
            not_converged=0, points=0, branches=(), stop=f"no point ({e})", coverage=0.0,
            complete=False, settings=settings, seconds=time.perf_counter() - t0)
    band = band_of(r, lo, hi, settings, seconds=time.perf_counter() - t0)
    if progress:
        extra = ("" if not np.isfinite(band.peak) or band.peak_found in WALKED else
                 f"; the walk alone: {band.walk_peak:.1f} N")
        progress(f"  complete sweep {lo:.0f}-{hi:.0f} Hz: {band.points} points on "
                 f"{len(band.branches)} branches in {band.seconds:.0f} s, {band.unstable} "
                 f"unstable, {band.runaway} runaway; peak {band.peak:.1f} N at "
                 f"{band.peak_hz:.0f} Hz ({band.peak_mesh}, branch found by "
                 f"{band.peak_found or '-'}){extra}"
                 + ("" if band.complete else "; NOT complete (point budget or branch cap "
                    "spent): a stable state may be missing"))
    return band
