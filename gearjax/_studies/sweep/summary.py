"""A sweep's result and its JSON summary."""

from __future__ import annotations

import dataclasses
import json

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
        "bifurcations": json.loads(ds.attrs.get("bifurcations", "[]")),
        "restarts": list(result.restarts),
        "segments": [list(s) for s in result.segments],
        "seconds": result.seconds,
        "points": points_json(ds),
        "solver": json.loads(ds.attrs.get("solver", "{}")),
    }
