"""Sweeps with backlash over a band, restarted above each early stop.

A sweep stops early at a fold with a jump it cannot pass, a closed loop or its point
budget; :func:`nonlinear_band` restarts just above the highest frequency reached, so the
band is covered as an up-sweep covers it. Its peak is over the stable points: unstable
orbits and spurious branches with a dynamic load factor above :data:`MAX_DLF` are
counted and left out.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable

import numpy as np

from ..._gear.train import Train
from ..sweep import sweep

MAX_DLF = 50.0
"""Sweep points with a larger dynamic load factor are spurious (:class:`NonlinearBand`)."""


@dataclasses.dataclass(frozen=True)
class NonlinearBand:
    """Sweeps with backlash over a band, restarted above each early stop.

    **Fields:** ``frequencies_hz`` ``(P,)`` and ``rms_force`` ``(P, m)`` of the converged,
    stable points of every sweep, in solve order (an unstable periodic orbit is not
    what the gearbox shows, and branches past parametric instabilities reach absurd
    amplitudes); ``unstable``: converged points left out; ``implausible``: stable points
    left out because a mesh's dynamic load factor exceeds ``max_dlf`` (RMS forces of
    meganewtons on a mesh loaded with kilonewtons: spurious branches of the truncated
    harmonic balance, not responses); ``starts_hz``, ``stops``
    (one per sweep: where it started, why it ended); ``coverage``: share of the band
    (in log frequency) the sweeps traced; ``peak``: largest RMS (N); ``stage_peaks``:
    per stage; ``seconds``.
    """

    frequencies_hz: np.ndarray
    rms_force: np.ndarray
    starts_hz: tuple[float, ...]
    stops: tuple[str, ...]
    coverage: float
    peak: float
    stage_peaks: dict
    unstable: int
    implausible: int
    seconds: float


def nonlinear_band(train: Train, gear: str, lo: float, hi: float, *, stage: str | None = None,
                   harmonics: int | None = None, max_step_hz: float | None = None,
                   max_points: int = 3000, restarts: int = 8, jump: float = 0.01,
                   max_dlf: float = MAX_DLF,
                   progress: Callable[[str], None] | None = None) -> NonlinearBand:
    """Sweep ``gear`` with backlash from ``lo`` to ``hi`` (reference-stage Hz); where a
    sweep stops early (a fold it cannot pass, a closed loop, ``max_points`` continuation
    points, no start), start a new one ``jump`` (relative) above the highest frequency
    reached, at most ``restarts`` times. ``stage``, ``harmonics``, ``max_step_hz``,
    ``max_points``: as :func:`gearjax.sweep`; ``max_dlf``: load factor above which a
    stable point is implausible; ``progress(message)``: called per sweep.

    **Returns:** :class:`NonlinearBand`. **Raises:** as :func:`gearjax.sweep`, except
    a sweep with no converged start, which is recorded and jumped over.
    """
    t0 = time.perf_counter()
    f0, freqs, rms, starts, stops, spans = lo, [], [], [], [], []
    labels = stage_of = None
    unstable = implausible = 0
    for _ in range(restarts + 1):
        starts.append(f0)
        try:
            r = sweep(train, gear, f0, hi, stage=stage, harmonics=harmonics,
                      max_step_hz=max_step_hz, max_points=max_points)
        except RuntimeError as e:  # no converged start: jump further
            stops.append(f"no start ({e})")
            f0 *= 1 + 10 * jump
            if f0 >= hi:
                break
            continue
        ds = r.dataset
        traced = ds["converged"].values
        stable = traced & (ds["stable"].values == 1)  # what a gearbox shows: stable orbits
        dlf = np.nanmax(np.where(np.isfinite(ds["dlf"].values), ds["dlf"].values, 0.0), axis=1)
        ok = stable & (dlf <= max_dlf)
        implausible += int(np.sum(stable & (dlf > max_dlf)))
        f = ds["mesh_frequency_hz"].values[ok]
        labels = ds["mesh"].values.tolist()
        stage_of = ds["stage"].values.tolist()
        freqs.append(f)
        rms.append(ds["rms_force"].values[ok])
        stops.append(r.stop)
        unstable += int(traced.sum() - stable.sum())
        reached = ds["mesh_frequency_hz"].values[traced]
        top = float(np.max(reached)) if reached.size else f0
        spans.append((f0, max(top, f0)))
        if progress:
            progress(f"  sweep from {f0:.0f} Hz: {int(traced.sum())} points to {top:.0f} Hz "
                     f"({r.stop}), {int(traced.sum() - stable.sum())} unstable, "
                     f"{int(np.sum(stable & (dlf > max_dlf)))} implausible")
        if r.stop == "reached_end" or top >= hi:
            break
        f0 = max(top, f0) * (1 + jump)
        if f0 >= hi:
            break
    f = np.concatenate(freqs) if freqs else np.zeros(0)
    m = len(labels) if labels else 0
    R = np.concatenate(rms) if rms else np.zeros((0, m))
    covered = sum(math.log(b / a) for a, b in spans if b > a)
    peak = float(np.nanmax(R)) if R.size and np.any(np.isfinite(R)) else math.nan
    stage_peaks = {}
    if labels:
        for sid in dict.fromkeys(stage_of):
            cols = np.asarray(stage_of) == sid
            v = R[:, cols]
            stage_peaks[sid] = float(np.nanmax(v)) if v.size and np.any(np.isfinite(v)) else (
                math.nan)
    return NonlinearBand(frequencies_hz=f, rms_force=R, starts_hz=tuple(starts),
                         stops=tuple(stops), coverage=min(1.0, covered / math.log(hi / lo)),
                         peak=peak, stage_peaks=stage_peaks, unstable=unstable,
                         implausible=implausible,
                         seconds=time.perf_counter() - t0)
