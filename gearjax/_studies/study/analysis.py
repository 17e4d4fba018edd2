"""One candidate's analysis and its figures of merit: the work a study's worker does.

:func:`analyse_candidate` takes plain data (the candidate's train-file text, the gear,
the analysis) and returns plain data, so that it runs the same in this process or on
any worker of a Dask cluster, and gives the same numbers wherever it runs.
"""

from __future__ import annotations

import time
import warnings

import numpy as np

from ..._errors import TrainError, one_line

STATUSES = ("done", "refused", "failed")
"""A candidate's outcome: ``done`` (every analysis ran; its points keep their own
result codes), ``refused`` (the train file or an analysis's arguments break a rule:
the reason is the rule), ``failed`` (an analysis raised: the reason is the error)."""


def analyse_candidate(text: str, source: str, gear: str | None, analysis: dict) -> dict:
    """Run ``analysis`` (the fields of :class:`~.spec.Analysis`) on the train file
    ``text`` (named ``source`` in messages), gear ``gear``.

    **Returns:** ``{"status", "reason", "warnings", "seconds", "stages",
    "first_elastic_hz", "linear", "backlash", "verify"}``: ``status`` one of
    :data:`STATUSES` and its one-line ``reason`` (empty when done); the warnings the
    analyses gave and why a sweep's stage has no peak or a complete sweep is not (one
    line each); the stage ids; the first elastic natural frequency (Hz; ``None`` where
    not asked); per sweep asked for (else ``None``) :func:`sweep_merits` (the backlash
    sweep's with ``complete``:
    :func:`~gearjax._studies.optimize.nonlinear.sweep_complete`); ``verify``
    (:func:`verify_merits`, ``None`` where not asked). Never raises for
    the candidate's own failures: they are its status."""
    from ..._gear.toml_io import loads_train

    t0 = time.perf_counter()
    out = {"status": "done", "reason": "", "warnings": [], "stages": [],
           "first_elastic_hz": None, "linear": None, "backlash": None, "verify": None}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            train = loads_train(text, source=source)
            out["stages"] = [s.id for s in train.stages]
            _run(train, gear, analysis, out)
        except TrainError as e:
            out.update(status="refused", reason=one_line(str(e)))
        except Exception as e:  # noqa: BLE001  a candidate's failure is its status
            out.update(status="failed", reason=one_line(f"{type(e).__name__}: {e}"))
    lines = []
    for w in caught:
        line = one_line(" ".join(str(w.message).split()))
        if w.category.__module__.startswith("gearjax") and line not in lines:
            lines.append(line)
    for kind in ("linear", "backlash"):
        lines += [f"{kind} sweep: {note}" for note in (out[kind] or {}).get("notes", [])]
    out["warnings"] = lines
    out["seconds"] = time.perf_counter() - t0
    return out


def _run(train, gear: str | None, analysis: dict, out: dict) -> None:
    from ..._engine.modal import modes
    from ..._gear.assembly import assemble
    from ..optimize.nonlinear import sweep_complete
    from ..sweep import sweep
    from ..verify import verify_gear

    name = train.gear(gear).name
    if analysis.get("modes"):
        elastic = modes(assemble(train, name)).elastic_hz
        out["first_elastic_hz"] = float(elastic[0]) if elastic else None
    lin = analysis.get("linear")
    if lin is not None:
        lo, hi = lin["band_hz"]
        result = sweep(train, name, lo, hi, linear=True, points=lin.get("points", 300),
                       harmonics=lin.get("harmonics"))
        out["linear"] = sweep_merits(result)
    nl = analysis.get("backlash")
    if nl is not None:
        lo, hi = nl["band_hz"]
        max_points = nl.get("max_points", 3000)
        result = sweep(train, name, lo, hi, harmonics=nl.get("harmonics"),
                       max_points=max_points, max_step_hz=nl.get("max_step_hz"),
                       complete=True)
        out["backlash"] = sweep_merits(result)
        out["backlash"]["complete"] = sweep_complete(result, max_points)
        if not out["backlash"]["complete"]:
            out["backlash"]["notes"].append(
                f"not complete (stopped: {result.stop}; the point budget {max_points} or the "
                "cap on branches ran out): its peak and coexisting bands are over the states "
                "it found")
    check = analysis.get("verify")
    if check is not None:
        result = verify_gear(train, name, list(check["at_hz"]), linear=check["linear"],
                             harmonics=check.get("harmonics"))
        out["verify"] = verify_merits(result)


def verify_merits(result) -> dict:
    """Figures of merit of a verification (:class:`~gearjax.VerifyResult`):
    ``max_rel_diff`` (the largest difference of a mesh's RMS force between harmonic
    balance and integration, relative to its stage's largest, over the points; ``None``
    where a method failed everywhere), ``ok`` (every point and mesh within
    ``tolerance``), ``tolerance`` and ``points``."""
    diff = np.asarray(result.rel_diff, float)
    return {"max_rel_diff": float(np.nanmax(diff)) if np.isfinite(diff).any() else None,
            "ok": bool(result.all_ok), "tolerance": float(result.tolerance),
            "points": int(diff.shape[0])}


def sweep_merits(result) -> dict:
    """Figures of merit of a finished sweep (:class:`~gearjax.SweepResult`):
    ``peak_rms_force`` and ``peak_hz`` per stage (N, Hz: the largest RMS mesh force over
    the converged, stable points inside the band, ``None`` where there is none),
    ``coexisting_hz`` (total width of the bands with two or more stable states),
    ``jumps`` (the sweep's :func:`~gearjax._studies.sweep.summary.coexisting_jumps`),
    ``stop`` (why the sweep ended), ``points`` and ``failed`` (points that did not
    converge), ``notes`` (why a stage has no peak)."""
    from ..sweep.summary import coexisting_bands, coexisting_jumps, largest_responses

    ds = result.dataset
    largest = largest_responses(ds)
    converged = np.asarray(ds["converged"].values, bool)
    return {"peak_rms_force": [row["rms_force"] for row in largest],
            "peak_hz": [row["mesh_frequency_hz"] for row in largest],
            "coexisting_hz": float(sum(b - a for a, b in coexisting_bands(ds))),
            "jumps": coexisting_jumps(ds),
            "stop": str(result.stop), "points": int(converged.size),
            "failed": int((~converged).sum()),
            "notes": [f"stage {row['stage']}: {row['reason']}" for row in largest
                      if row.get("reason")]}
