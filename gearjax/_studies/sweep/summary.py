"""A sweep's result and its JSON summary."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np

from ..._io.results import points_json
from ..validity import contact_loss, result_band
from .post import PARAMETRIC


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
        "band_hz": list(band_of(ds)),
        "largest": largest_responses(ds),
        "contact_loss": contact_loss(ds),
        "restarts": list(result.restarts),
        "segments": [list(s) for s in result.segments],
        "seconds": result.seconds,
        "phase_seconds": dict(result.phase_seconds),
        "points": points_json(ds),
        "solver": json.loads(ds.attrs.get("solver", "{}")),
    }


def band_of(ds) -> tuple[float, float]:
    """``(lowest, highest)`` reference-stage mesh frequency (Hz) of the band the sweep
    ``ds`` was asked for (:func:`~gearjax._studies.validity.result_band`), or, for a
    dataset that does not say (made by hand, or by an earlier version without
    segments), the range of its points."""
    band = result_band(ds)
    if band is None:
        f = np.asarray(ds["mesh_frequency_hz"].values, float)
        return float(np.min(f)), float(np.max(f))
    return min(band), max(band)


def in_band(ds) -> np.ndarray:
    """``(P,)`` bool: the points of the sweep ``ds`` inside its requested band
    (:func:`band_of`; a continuation may step past the band's ends, e.g. round a fold,
    and ends on a point just past its last frequency)."""
    lo, hi = band_of(ds)
    tol = 1e-9 * max(abs(hi), 1.0)
    f = np.asarray(ds["mesh_frequency_hz"].values, float)
    return (f >= lo - tol) & (f <= hi + tol)


def largest_responses(ds) -> list[dict]:
    """Per stage (in mesh order), the largest responses over the points of the sweep
    ``ds`` that are converged, stable (``stable`` true; unknown counts as not stable)
    and inside the requested band (:func:`in_band`): an unstable point is no state the
    gear settles to, and a point outside the band was not asked for.

    **Returns:** ``{"stage", "rms_force", "mesh", "mesh_frequency_hz", "separation",
    "separation_hz", "points", "of"}``: the largest RMS mesh force (N), its mesh and
    frequency (Hz), the largest separation share and where it is, the points counted
    and all the sweep's points; without such a point the values are ``None`` and
    ``reason`` says why."""
    keep = (in_band(ds) & (np.asarray(ds["stable"].values) == 1)
            & np.asarray(ds["converged"].values, bool))
    f = np.asarray(ds["mesh_frequency_hz"].values, float)
    rms = np.asarray(ds["rms_force"].values, float)
    sep = np.asarray(ds["separation"].values, float)
    names = ds["mesh"].values
    stages = ds["stage"].values
    out = []
    for stage in dict.fromkeys(stages.tolist()):
        cols = np.flatnonzero(stages == stage)
        row = {"stage": str(stage), "rms_force": None, "mesh": None,
               "mesh_frequency_hz": None, "separation": None, "separation_hz": None,
               "points": int(keep.sum()), "of": int(f.size)}
        block = rms[np.ix_(keep, cols)]
        if not keep.any() or not np.isfinite(block).any():
            lo, hi = band_of(ds)
            row["reason"] = f"no stable converged point inside {lo:.1f}-{hi:.1f} Hz"
            out.append(row)
            continue
        k, j = np.unravel_index(np.nanargmax(block), block.shape)
        pts = np.flatnonzero(keep)
        row.update(rms_force=float(block[k, j]), mesh=str(names[cols[j]]),
                   mesh_frequency_hz=float(f[pts[k]]))
        s = sep[np.ix_(keep, cols)]
        if np.isfinite(s).any():
            ks, _ = np.unravel_index(np.nanargmax(s), s.shape)
            row.update(separation=float(np.nanmax(s)), separation_hz=float(f[pts[ks]]))
        out.append(row)
    return out


def coexisting_bands(ds) -> list[tuple[float, float]]:
    """Bands ``(from_hz, to_hz)`` of reference-stage mesh frequency over which the sweep
    ``ds`` found two or more stable states: where a jump up and a jump down land on
    different states (the hysteresis between folds).

    A stable run is a stretch of consecutive points of one branch that are all stable
    (``stable`` true; unknown counts as not stable); a band is where two or more runs of
    at least two points overlap in frequency, also where a branch traced past the
    requested band's end (the states found there are states of the gear). In ascending
    order; empty for a linear sweep, whose periodic solution is unique."""
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
    (``stable`` true; unknown counts as not stable), in point order (not clipped to the
    band)."""
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
    the band, and where a stable state that overlaps the band ends inside the requested
    band (:func:`band_of`), sweeping up (its highest frequency: a rig sweeping up on it
    jumps there) or down (its lowest), ascending. A run that reaches an end of the
    requested band (or passes it) ends there because the sweep does, not in a jump."""
    lo, hi = band_of(ds)
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
    branch: beyond it the motion is quasi-periodic, which ``note`` says.

    A linear sweep (``solver.linear``) has no bifurcation: its notes are its bands of
    parametric instability instead (:func:`instability_notes`)."""
    if _linear(ds):
        return instability_notes(ds)
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


UNBOUNDED = ("in a linear train a Floquet multiplier outside the unit circle means that any "
             "disturbance grows without bound (no periodic or quasi-periodic motion "
             "follows it): the backlash, which a linear run leaves out, decides the motion")
"""What a linear sweep's unstable points mean, in words."""


def instability_notes(ds) -> list[dict]:
    """The bands of parametric instability of a linear sweep ``ds``: runs of consecutive
    converged, unstable points (``stable`` false) inside the requested band, in
    ascending frequency, each ``{"mesh_frequency_hz", "kind", "branch", "from_hz",
    "to_hz", "multiplier", "multiplier_hz", "note"}``: ``kind`` is
    ``"parametric_instability"``, ``from_hz`` and ``to_hz`` the band's first and last
    unstable point (``mesh_frequency_hz`` the first), ``multiplier`` the largest
    Floquet multiplier modulus there (rigid-body modes excluded) and ``multiplier_hz``
    where it is."""
    f = np.asarray(ds["mesh_frequency_hz"].values, float)
    keep = in_band(ds) & np.asarray(ds["converged"].values, bool)
    order = np.flatnonzero(keep)[np.argsort(f[keep], kind="stable")]
    unstable = np.asarray(ds["stable"].values)[order] == 0
    mult = (np.asarray(ds["max_multiplier"].values, float)[order]
            if "max_multiplier" in ds else np.full(order.size, np.nan))
    out, i = [], 0
    while i < order.size:
        if not unstable[i]:
            i += 1
            continue
        j = i
        while j + 1 < order.size and unstable[j + 1]:
            j += 1
        a, b = float(f[order[i]]), float(f[order[j]])
        m = mult[i:j + 1]
        top = int(np.nanargmax(m)) if np.isfinite(m).any() else None
        where = f"at {a:.1f} Hz" if a == b else f"over {a:.1f}-{b:.1f} Hz"
        worst = ("" if top is None else
                 f": largest Floquet multiplier {m[top]:.4f} at {f[order[i + top]]:.1f} Hz")
        out.append({"mesh_frequency_hz": a, "kind": PARAMETRIC, "branch": None,
                    "from_hz": a, "to_hz": b,
                    "multiplier": None if top is None else float(m[top]),
                    "multiplier_hz": None if top is None else float(f[order[i + top]]),
                    "note": f"parametric instability (unbounded) {where}{worst}; "
                            f"{UNBOUNDED}"})
        i = j + 1
    return out


def change_words(change: dict) -> str:
    """One stability change of a sweep's ``bifurcations`` (:func:`~.post.bifurcations`)
    in words: its kind, and for a linear sweep's ``parametric instability (unbounded)``
    the multiplier and how it crossed the unit circle."""
    kind = change.get("kind")
    if kind != PARAMETRIC:
        return str(kind)
    how = {"period_doubling": "through -1", "neimark_sacker": "a complex pair",
           "fold": "through +1"}.get(change.get("crossing"), "")
    m = change.get("multiplier")
    return ("parametric instability (unbounded)"
            + ("" if m is None else f", largest Floquet multiplier {m:.4f}")
            + (f" ({how})" if how else ""))


def _linear(ds) -> bool:
    try:
        return bool(json.loads(ds.attrs.get("solver", "{}") or "{}").get("linear", False))
    except (TypeError, ValueError):
        return False
