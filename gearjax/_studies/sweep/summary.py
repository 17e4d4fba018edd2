"""A sweep's result and its JSON summary."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np

from ..._io.results import points_json


@dataclasses.dataclass(frozen=True)
class SweepResult:
    """A finished (or stopped) sweep: ``dataset`` (xarray, interface.md layout),
    ``folds_hz`` (located folds, reference-stage Hz), ``stop`` (why it ended),
    ``segments`` (``(from_hz, to_hz, K)`` in sweep order), ``seconds``, ``restarts``
    (``{"from_hz", "at_hz", "reason"}``: where a branch was left and the next begun),
    ``branches`` (a completed sweep's ``{"branch", "found", "seed_hz", "stops", "eta"}``,
    and a doubled branch's origin, :mod:`~gearjax._studies.sweep.completion`),
    ``phase_seconds`` (wall seconds of each phase run, in order: ``gear`` (arguments,
    assembly, harmonics plan), ``check`` (truncation check and the first point),
    ``walk``, ``completion`` (where run), ``results`` (the post-processing's wait,
    the dataset); they add up to ``seconds``)."""

    dataset: object
    folds_hz: tuple[float, ...]
    stop: str
    segments: tuple[tuple[float, float, int], ...]
    seconds: float
    restarts: tuple[dict, ...] = ()
    branches: tuple[dict, ...] = ()
    phase_seconds: dict = dataclasses.field(default_factory=dict)


def summary_json(result: SweepResult) -> dict:
    """Top-level JSON of a sweep (points per interface.md plus summary fields)."""
    ds = result.dataset
    return {
        "gear": ds.attrs.get("gear"),
        "reference_stage": ds.attrs.get("reference_stage"),
        "stop": result.stop,
        "folds_hz": list(result.folds_hz),
        "coexisting_hz": [list(b) for b in coexisting_bands(ds)],
        "coexisting": coexisting_jumps(ds),
        "branches": list(result.branches),
        "bifurcations": json.loads(ds.attrs.get("bifurcations", "[]")),
        "bifurcation_notes": bifurcation_notes(ds, result.branches),
        "restarts": list(result.restarts),
        "segments": [list(s) for s in result.segments],
        "seconds": result.seconds,
        "phase_seconds": dict(result.phase_seconds),
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
    runs = stable_runs(ds)
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


def stable_runs(ds) -> list[tuple[float, float]]:
    """``(lowest, highest)`` frequency (Hz) of each stable run of the sweep ``ds``: a
    stretch of at least two consecutive points of one branch that are all stable
    (``stable`` true; unknown counts as not stable), in point order."""
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
    return runs


def coexisting_jumps(ds) -> list[dict]:
    """Per band of :func:`coexisting_bands`: ``{"from_hz", "to_hz", "states",
    "jump_up_hz", "jump_down_hz"}``: the most stable states found at one frequency in
    the band, and where a stable state that overlaps the band ends inside the sweep's
    range, sweeping up (its highest frequency: a rig sweeping up on it jumps there) or
    down (its lowest), ascending."""
    f = np.asarray(ds["mesh_frequency_hz"].values, float)
    lo, hi = float(np.min(f)), float(np.max(f))
    tol = 1e-9 * max(abs(hi), 1.0)
    runs = stable_runs(ds)
    out = []
    for a, b in coexisting_bands(ds):
        mine = [(x, y) for x, y in runs if x <= b and y >= a]
        mid = [(a + b) / 2]
        states = max(sum(x <= m <= y for x, y in mine) for m in mid)
        out.append({"from_hz": a, "to_hz": b, "states": int(states),
                    "jump_up_hz": sorted(y for _, y in mine if y < hi - tol),
                    "jump_down_hz": sorted(x for x, _ in mine if x > lo + tol)})
    return out


QUASI_PERIODIC = ("a complex pair of Floquet multipliers crosses the unit circle; beyond "
                  "it the motion is quasi-periodic (a torus), not a periodic branch: "
                  "integrate in time there (gearjax simulate)")
"""What a Neimark-Sacker bifurcation means for the sweep, in words."""


def bifurcation_lines(notes: list[dict]) -> list[str]:
    """The notes of :func:`bifurcation_notes` as lines to print: one per period doubling,
    the Neimark-Sacker ones on one line."""
    lines = [n["note"] for n in notes if n["kind"] != "neimark_sacker"]
    ns = [n["mesh_frequency_hz"] for n in notes if n["kind"] == "neimark_sacker"]
    if ns:
        lines.append("Neimark-Sacker near " + ", ".join(f"{f:.1f}" for f in sorted(ns))
                     + f" Hz: {QUASI_PERIODIC.replace('beyond it', 'beyond each')}")
    return lines


def bifurcation_notes(ds, branches=()) -> list[dict]:
    """What follows each period doubling and Neimark-Sacker bifurcation of the sweep
    ``ds`` (its ``bifurcations`` attribute), with the completed sweep's branch records
    ``branches`` (:mod:`~gearjax._studies.sweep.completion`): ``{"mesh_frequency_hz",
    "kind", "branch", "note"}``, ``branch`` the number of the branch of twice the period
    born at a doubling (``None`` where it was not followed: ``note`` says why), in the
    order of the attribute. A Neimark-Sacker bifurcation gives birth to no periodic
    branch: beyond it the motion is quasi-periodic, which ``note`` says."""
    out = []
    for b in json.loads(ds.attrs.get("bifurcations", "[]")):
        f, kind = float(b["mesh_frequency_hz"]), b.get("kind")
        if kind == "neimark_sacker":
            out.append({"mesh_frequency_hz": f, "kind": kind, "branch": None,
                        "note": f"Neimark-Sacker near {f:.1f} Hz: {QUASI_PERIODIC}"})
            continue
        if kind != "period_doubling":
            continue
        near = lambda x: math.isclose(float(x), f, rel_tol=1e-9, abs_tol=1e-9)  # noqa: E731
        born = [r for r in branches if any(near(x) for x in r.get("doublings_hz", ()))]
        skipped = [s for r in branches for s in r.get("not_doubled", ())
                   if near(s["doubling_hz"])]
        if born:
            r = born[0]
            note = (f"period doubling near {f:.1f} Hz: branch {r['branch']} has twice the "
                    f"period (eta = {r.get('eta', 2)})"
                    + ("" if r.get("found") == "period doubling" and near(
                        r["doublings_hz"][0]) else ", born at another doubling"))
            out.append({"mesh_frequency_hz": f, "kind": kind, "branch": int(r["branch"]),
                        "note": note})
            continue
        why = skipped[0]["why"] if skipped else (
            "the sweep was not completed" if not branches
            else "the sweep's cap on branches or points came first")
        out.append({"mesh_frequency_hz": f, "kind": kind, "branch": None,
                    "note": f"period doubling near {f:.1f} Hz: the branch of twice the "
                            f"period born there was not followed ({why})"})
    return out
