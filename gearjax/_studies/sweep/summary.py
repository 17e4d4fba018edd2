"""A sweep's result and its JSON summary."""

from __future__ import annotations

import dataclasses
import json

import numpy as np

from ..._io.results import points_json


@dataclasses.dataclass(frozen=True)
class SweepResult:
    """A finished (or stopped) sweep: ``dataset`` (xarray, interface.md layout),
    ``folds_hz`` (located folds, reference-stage Hz), ``stop`` (why it ended),
    ``segments`` (``(from_hz, to_hz, K)`` in sweep order), ``seconds``, ``restarts``
    (``{"from_hz", "at_hz", "reason"}``: where a branch was left and the next begun)."""

    dataset: object
    folds_hz: tuple[float, ...]
    stop: str
    segments: tuple[tuple[float, float, int], ...]
    seconds: float
    restarts: tuple[dict, ...] = ()


def summary_json(result: SweepResult) -> dict:
    """Top-level JSON of a sweep (points per interface.md plus summary fields)."""
    ds = result.dataset
    return {
        "gear": ds.attrs.get("gear"),
        "reference_stage": ds.attrs.get("reference_stage"),
        "stop": result.stop,
        "folds_hz": list(result.folds_hz),
        "coexisting_hz": [list(b) for b in coexisting_bands(ds)],
        "bifurcations": json.loads(ds.attrs.get("bifurcations", "[]")),
        "restarts": list(result.restarts),
        "segments": [list(s) for s in result.segments],
        "seconds": result.seconds,
        "points": points_json(ds),
        "solver": json.loads(ds.attrs.get("solver", "{}")),
    }


def coexisting_bands(ds) -> list[tuple[float, float]]:
    """Bands ``(from_hz, to_hz)`` of reference-stage mesh frequency over which the sweep
    ``ds`` found two or more stable states: where a jump up and a jump down land on
    different states (the hysteresis between folds).

    A stable run is a stretch of consecutive points of one branch that are all stable
    (``stable`` true; unknown counts as not stable); a band is where two or more runs of
    at least two points overlap in frequency. In ascending order; empty for a linear
    sweep, whose periodic solution is unique."""
    f = np.asarray(ds["mesh_frequency_hz"].values, float)
    stable = np.asarray(ds["stable"].values) == 1
    branch = (np.asarray(ds["branch"].values) if "branch" in ds.variables
              else np.zeros(len(f), int))
    runs, first = [], None
    for i in range(len(f) + 1):
        going = i < len(f) and stable[i] and first is not None and branch[i] == branch[i - 1]
        if going:
            continue
        if first is not None and i - first >= 2:
            runs.append((float(f[first:i].min()), float(f[first:i].max())))
        first = i if i < len(f) and stable[i] else None
    edges = sorted([(a, 1) for a, _ in runs] + [(b, -1) for _, b in runs],
                   key=lambda e: (e[0], -e[1]))
    bands, depth, start = [], 0, 0.0
    for x, step in edges:
        if step > 0 and depth == 1:
            start = x
        if step < 0 and depth == 2 and x > start:
            bands.append((start, x))
        depth += step
    merged: list[tuple[float, float]] = []
    for a, b in bands:
        if merged and a <= merged[-1][1]:
            merged[-1] = (merged[-1][0], max(merged[-1][1], b))
        else:
            merged.append((a, b))
    return merged
