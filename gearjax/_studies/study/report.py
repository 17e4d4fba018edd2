"""Views of a study's Dataset: one record per candidate, the JSON summary, the Pareto
set of two figures of merit."""

from __future__ import annotations

import json

import numpy as np

from ..._errors import bad_argument
from ..._io.results import json_number

MERITS = ("first_elastic_hz", "linear_peak_rms_force", "backlash_peak_rms_force",
          "linear_coexisting_hz", "backlash_coexisting_hz", "verify_max_rel_diff")
"""Figures of merit a Pareto set may rank (a per-stage merit by its largest stage)."""

LARGER_IS_BETTER = ("first_elastic_hz",)
"""Merits to maximise; every other is minimised."""


def varied_paths(ds) -> list[str]:
    """The varied train-file paths: the coordinates along ``candidate`` other than it."""
    return [str(n) for n, c in ds.coords.items() if c.dims == ("candidate",)
            and n != "candidate"]


def candidate_records(ds) -> list[dict]:
    """One dict per candidate of the study Dataset ``ds`` (JSON-ready; NaN as ``None``):
    ``candidate``, ``values`` (path -> value), ``status``, ``reason``, ``notes`` (list
    of lines), ``seconds``, ``first_elastic_hz`` and per sweep kind run (else ``None``)
    ``{"peak_rms_force": {stage: N}, "peak_hz": {stage: Hz}, "coexisting_hz", "jumps",
    "stop", "points", "failed"}`` (the backlash sweep's with ``complete``), and
    ``verify`` (``{"max_rel_diff", "ok", "tolerance"}``, else ``None``)."""
    stages = [str(s) for s in ds["stage"].values]
    out = []
    for k in range(ds.sizes["candidate"]):
        row = ds.isel(candidate=k)
        rec = {"candidate": int(row["candidate"]),
               "values": {p: _plain(row[p].values) for p in varied_paths(ds)},
               "status": str(row["status"].values), "reason": str(row["reason"].values),
               "notes": [n for n in str(row["notes"].values).split("\n") if n],
               "seconds": json_number(row["seconds"]),
               "first_elastic_hz": json_number(row["first_elastic_hz"])}
        for kind in ("linear", "backlash"):
            if int(row[f"{kind}_points"]) < 0:
                rec[kind] = None
                continue
            rec[kind] = {
                "peak_rms_force": dict(zip(stages, map(json_number,
                                                       row[f"{kind}_peak_rms_force"].values))),
                "peak_hz": dict(zip(stages, map(json_number, row[f"{kind}_peak_hz"].values))),
                "coexisting_hz": json_number(row[f"{kind}_coexisting_hz"]),
                "jumps": json.loads(str(row[f"{kind}_jumps"].values)),
                "stop": str(row[f"{kind}_stop"].values),
                **({"complete": bool(int(row["backlash_complete"]))} if kind == "backlash"
                   else {}),
                "points": int(row[f"{kind}_points"]), "failed": int(row[f"{kind}_failed"])}
        ok = int(row["verify_ok"])
        rec["verify"] = None if ok < 0 else {
            "max_rel_diff": json_number(row["verify_max_rel_diff"]), "ok": bool(ok),
            "tolerance": json_number(row["verify_tolerance"])}
        out.append(rec)
    return out


def study_json(result) -> dict:
    """The JSON summary of a :class:`~.run.StudyResult`: ``study``, ``store``,
    ``design``, ``candidates``, ``missing``, ``ran``, ``refused``, ``failed``,
    ``skipped``, ``seconds``, ``varied`` (paths) and ``results``
    (:func:`candidate_records`)."""
    ds = result.dataset
    return {"study": ds.attrs["study"], "store": str(result.store),
            "design": ds.attrs["design"], "candidates": int(ds.attrs["candidates"]),
            "missing": int(ds.attrs["missing"]), "ran": result.ran,
            "refused": result.refused, "failed": result.failed, "skipped": result.skipped,
            "seconds": result.seconds, "varied": varied_paths(ds),
            "results": candidate_records(ds)}


def merit_values(ds, merit: str) -> np.ndarray:
    """The figure of merit ``merit`` (one of :data:`MERITS`) per candidate; a per-stage
    merit is its largest stage's value; NaN where a candidate has none.

    **Raises:** ``ArgumentError`` (``merit``) for another name, or a merit the study's
    analysis did not compute."""
    if merit not in MERITS:
        raise bad_argument("merit", merit, f"must be one of {', '.join(MERITS)}")
    kind = merit.split("_")[0]
    if kind in ("linear", "backlash") and not (ds[f"{kind}_points"].values >= 0).any():
        raise bad_argument("merit", merit, f"the study ran no {kind} sweep")
    if kind == "verify" and not (ds["verify_ok"].values >= 0).any():
        raise bad_argument("merit", merit, "the study verified no candidate")
    if merit == "first_elastic_hz" and not np.isfinite(ds[merit].values).any():
        raise bad_argument("merit", merit, "the study computed no modes")
    values = np.asarray(ds[merit].values, float)
    return values.max(axis=1) if values.ndim == 2 else values  # NaN where a stage has none


def pareto(ds, first: str, second: str) -> list[int]:
    """Candidate numbers (``candidate`` coordinate, ascending) of the Pareto set of the
    merits ``first`` and ``second`` (:func:`merit_values`; :data:`LARGER_IS_BETTER`
    maximised, the others minimised) among the candidates that are ``done`` and have
    both: no other such candidate is at least as good in both and better in one."""
    a = _oriented(ds, first)
    b = _oriented(ds, second)
    ok = (np.asarray(ds["status"].values) == "done") & np.isfinite(a) & np.isfinite(b)
    idx = np.flatnonzero(ok)
    keep = []
    for i in idx:
        dominated = ((a[idx] <= a[i]) & (b[idx] <= b[i])
                     & ((a[idx] < a[i]) | (b[idx] < b[i]))).any()
        if not dominated:
            keep.append(int(ds["candidate"].values[i]))
    return sorted(keep)


def _oriented(ds, merit: str) -> np.ndarray:
    v = merit_values(ds, merit)
    return -v if merit in LARGER_IS_BETTER else v


def _plain(v):
    v = v.item() if hasattr(v, "item") else v
    return v
