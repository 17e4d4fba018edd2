"""An optimisation's outputs: the ``optimize`` JSON, a summary table, and the results
Dataset (NetCDF)."""

from __future__ import annotations

import datetime
import math

import numpy as np
import pandas as pd
import xarray as xr

from ..._gear.planet_sets import planet_imbalance
from ..._gear.toml_io import dumps_train
from ..._io.results import netcdf_attr
from ..._version import __version__
from .. import harmonics as _harmonics
from .result import Design, OptimizeResult
from .settings import settings_dict


def _design_json(d: Design) -> dict:
    nl = d.nonlinear
    return {
        "values": d.values,
        "planet_angles_deg": {k: v.tolist() for k, v in d.planet_sets.items()},
        "admissible": d.admissible,
        "linear_peak": d.linear_peak,
        "linear_stage_peaks": d.linear_stage_peaks,
        "nonlinear": None if nl is None else band_json(nl),
        "nonlinear_peak": None if nl is None else nl.peak,
    }


def band_json(nl) -> dict:
    """A complete sweep with backlash (:class:`.nonlinear.NonlinearBand`) as JSON: its
    peak over stable states, where, on which mesh and how that branch was found, the
    walk's peak, per-stage peaks, the point counts, branches, coverage, whether it is
    complete, and its settings."""
    return {"peak": nl.peak, "peak_hz": nl.peak_hz, "peak_mesh": nl.peak_mesh,
            "peak_found": nl.peak_found, "walk_peak": nl.walk_peak,
            "stage_peaks": nl.stage_peaks, "points": nl.points,
            "stable_points": int(nl.frequencies_hz.size), "unstable_points": nl.unstable,
            "runaway_points": nl.runaway, "not_converged_points": nl.not_converged,
            "branches": list(nl.branches), "stop": nl.stop, "coverage": nl.coverage,
            "complete": nl.complete, "settings": nl.settings.as_dict(),
            "seconds": nl.seconds}


def optimize_json(result: OptimizeResult) -> dict:
    """The ``optimize`` JSON: ``verdict`` (:func:`.result.verdict`: whether the optimum
    beats the baseline on the model that decided, by how much, the recommended design),
    ``models`` (which model and settings each step used), ``baseline``, ``optimum``
    (values, peaks; ``nonlinear``: the complete sweep with backlash, :func:`band_json`),
    ``improvement`` (optimum / baseline peak, linear and with backlash), ``relaxation``,
    ``stages``, ``candidates`` (those solved by the linear harmonic balance), settings;
    ``harmonics``: K of the linear screen (on a torus the list of orders per angle) and
    ``torus``: what a torus study solved (null for a periodic gear)."""
    b, o = result.baseline, result.optimum
    ratio = lambda x, y: (x / y) if (y and np.isfinite(x) and np.isfinite(y)) else None
    cand = result.candidates
    rows = []
    for k in np.flatnonzero(np.isfinite(cand["linear_peak"])):
        row = {key: (val[k].tolist() if isinstance(val[k], np.ndarray) else val[k])
               for key, val in cand.items()}
        row["planet_angles_deg"] = [a for a in row["planet_angles_deg"] if np.isfinite(a)]
        rows.append(row)
    r = result.relaxation
    return {
        "gear": result.gear,
        "reference_stage": result.reference_stage,
        "band_hz": list(result.band_hz),
        "vary": list(result.vary),
        "objective": OBJECTIVE,
        "verdict": result.verdict,
        "models": result.models,
        "baseline": _design_json(b),
        "optimum": _design_json(o),
        "improvement": {"linear": ratio(o.linear_peak, b.linear_peak),
                        "nonlinear": ratio(o.nonlinear_peak, b.nonlinear_peak)},
        "relaxation": None if r is None else {
            "values": r.values, "linear_peak": r.linear_peak, "start_peak": r.start_peak,
            "iterations": r.iterations, "message": r.message, "assemblable": False,
            "assembly_violations": r.assembly_violations,
            "max_slot_offset": r.max_slot_offset},
        "stages": result.stages,
        "candidates": rows,
        "settings": settings_dict(result.settings),
        "seconds": result.seconds,
        "harmonics": _harmonics.orders_json(result.harmonics),
        "torus": result.torus,
    }


OBJECTIVE = ("largest RMS alternating mesh force over the band and every mesh (N); with "
             "backlash over every stable state of a complete sweep")


def optimize_frame(result: OptimizeResult):
    """Baseline, optimum and relaxation side by side: a ``pandas.DataFrame`` with one row
    per design and the columns ``linear peak (N)`` (common grid), ``backlash peak (N)``
    (every stable state of the complete sweep; NaN where not swept), where it is
    (``backlash peak at (Hz)``), how its branch was found (``branch found by``), whether
    the sweep is complete (``sweep complete``), the linear peak of each stage's
    meshes, each varied stage's planet angles (deg), planet imbalance
    (:func:`gearjax._gear.planet_sets.planet_imbalance`), sun-ring and stage phases (deg), and ``assemblable``."""
    b, o, r = result.baseline, result.optimum, result.relaxation
    stages = list(dict.fromkeys(result.mesh_stage))
    rows = {}
    designs = [("baseline", b.values, b.linear_rms, b.nonlinear, b.admissible),
               ("optimum", o.values, o.linear_rms, o.nonlinear, o.admissible)]
    if r is not None:
        designs.append(("relaxed", r.values, r.linear_rms, None, False))
    for name, values, rms, nl, ok in designs:
        row = {"linear peak (N)": float(np.nanmax(rms)),
               "backlash peak (N)": math.nan if nl is None else nl.peak,
               "backlash peak at (Hz)": math.nan if nl is None else nl.peak_hz,
               "branch found by": "" if nl is None else nl.peak_found,
               "sweep complete": None if nl is None else nl.complete}
        for sid in stages:
            cols = np.asarray(result.mesh_stage) == sid
            row[f"stage {sid} linear peak (N)"] = float(np.nanmax(rms[:, cols]))
        for sid in stages:
            angles = [0.0] + [values[p] for p in values
                              if p.startswith(f"{sid}.planet_angles_deg.")]
            if len(angles) > 1:
                row[f"{sid}.planet_angles_deg"] = np.round(angles, 3).tolist()
                row[f"{sid} imbalance"] = planet_imbalance(angles)
            for key in ("sun_ring_phase_deg", "stage_phase_deg"):
                if f"{sid}.{key}" in values:
                    row[f"{sid}.{key}"] = values[f"{sid}.{key}"]
        row["assemblable"] = bool(ok)
        rows[name] = row
    return pd.DataFrame(rows).T


def optimize_dataset(result: OptimizeResult, attrs: dict | None = None):
    """The optimisation as an ``xarray.Dataset`` (``kind = "optimize"``).

    Dimensions ``candidate`` (every screened candidate, stage by stage, the incumbent
    first), ``planet`` (1-based, padded with NaN), ``frequency`` (the linear screen's
    grid), ``mesh`` (with ``stage``, ``side``, ``planet_of_mesh`` coordinates), ``design``
    (``baseline``, ``optimum``) and, with backlash, ``baseline_point`` and
    ``optimum_point`` (the converged points of their sweeps). Variables: the candidate
    columns of :class:`OptimizeResult` (``proxy_peak`` etc., N), ``linear_rms``
    (``design, frequency, mesh``, N), ``baseline_nonlinear_rms`` /
    ``optimum_nonlinear_rms`` (the stable points of their complete sweeps) with their
    ``..._frequency_hz`` and ``..._branch_found``. Attributes: ``kind``,
    ``gear``, ``reference_stage``, ``band_hz``, ``vary``, ``verdict`` (its ``text``)
    and ``recommended`` (``optimum`` or ``baseline``, :func:`.result.verdict`),
    ``verdict_json``, ``models`` (JSON: the model and settings of each step),
    ``baseline_nonlinear`` / ``optimum_nonlinear`` (JSON, :func:`band_json`), the peaks
    (``baseline_peak_linear``, ``optimum_peak_linear``, ``baseline_peak_nonlinear``,
    ``optimum_peak_nonlinear``, ``relaxed_peak_linear``; NaN where not computed), the
    values (JSON), ``stages``, ``settings``, ``harmonics`` (the linear screen's K; JSON
    list of orders on a torus), ``torus`` (JSON; ``null`` for a periodic gear),
    ``train_toml`` (the optimum), ``baseline_train_toml``, ``gearjax_version``,
    ``created``.
    """
    c = result.candidates
    r = result.relaxation
    n_max = c["planet_angles_deg"].shape[1]
    units = {"proxy_peak": "N", "linear_stage_peak": "N", "linear_peak": "N",
             "nonlinear_stage_peak": "N", "nonlinear_peak": "N", "nonlinear_walk_peak": "N",
             "nonlinear_peak_hz": "Hz", "nonlinear_coverage": "1", "nonlinear_complete": "1",
             "sun_ring_phase_deg": "deg", "stage_phase_deg": "deg", "incumbent": "1",
             "selected": "1"}
    names = {"proxy_peak": "largest RMS mesh force, first-order proxy",
             "linear_stage_peak": "largest RMS force of the stage's meshes, linear HB",
             "linear_peak": "largest RMS mesh force, linear time-varying HB",
             "nonlinear_stage_peak": "largest RMS force of the stage's meshes, with backlash",
             "nonlinear_peak": "largest RMS mesh force over every stable state of a "
                               "complete sweep with backlash",
             "nonlinear_walk_peak": "the same over the branches of the sweep's walk alone",
             "nonlinear_peak_hz": "where the peak with backlash is",
             "nonlinear_coverage": "share of the band (log frequency) the sweep traced",
             "nonlinear_complete": "1: the sweep's completion ran to its end",
             "sun_ring_phase_deg": "sun-ring phase", "stage_phase_deg": "stage phase",
             "incumbent": "the design before this stage's step",
             "selected": "chosen at this stage's step"}
    data = {
        "candidate_stage": ("candidate", c["stage"].astype(str), {"long_name": "stage varied"}),
        "planet_angles_deg": (("candidate", "planet"), c["planet_angles_deg"],
                              {"units": "deg", "long_name": "planet angles of the stage"}),
    }
    for key, unit in units.items():
        data[key] = ("candidate", c[key], {"units": unit, "long_name": names[key]})
    data["linear_rms"] = (("design", "frequency", "mesh"),
                          np.stack([result.baseline.linear_rms, result.optimum.linear_rms]
                                   + ([r.linear_rms] if r is not None else [])),
                          {"units": "N", "long_name": "RMS alternating mesh force, linear "
                           "time-varying harmonic balance"})
    for which, d in (("baseline", result.baseline), ("optimum", result.optimum)):
        if d.nonlinear is not None and d.nonlinear.frequencies_hz.size:
            data[f"{which}_nonlinear_branch_found"] = (
                f"{which}_point", d.nonlinear.found.astype(str),
                {"units": "1", "long_name": "how the point's branch was found"})
            data[f"{which}_nonlinear_frequency_hz"] = (
                f"{which}_point", d.nonlinear.frequencies_hz,
                {"units": "Hz", "long_name": "reference-stage mesh frequency"})
            data[f"{which}_nonlinear_rms"] = (
                (f"{which}_point", "mesh"), d.nonlinear.rms_force,
                {"units": "N", "long_name": "RMS alternating mesh force with backlash"})
    coords = {
        "candidate": np.arange(len(c["stage"])),
        "planet": np.arange(1, n_max + 1),
        "frequency": ("frequency", result.frequencies_hz,
                      {"units": "Hz", "long_name": "reference-stage mesh frequency"}),
        "mesh": np.asarray(result.meshes, dtype=str),
        "stage": ("mesh", np.asarray(result.mesh_stage, dtype=str)),
        "side": ("mesh", np.asarray(result.mesh_side, dtype=str)),
        "planet_of_mesh": ("mesh", np.asarray(result.mesh_planet, dtype=np.int64)),
        "design": np.asarray(["baseline", "optimum"] + (["relaxed"] if r is not None else [])),
    }
    out = {
        "kind": "optimize",
        "gear": result.gear,
        "reference_stage": result.reference_stage,
        "band_hz": list(result.band_hz),
        "vary": list(result.vary),
        "objective": OBJECTIVE,
        "verdict": (result.verdict or {}).get("text", ""),
        "recommended": (result.verdict or {}).get("recommended", ""),
        "verdict_json": result.verdict or {},
        "models": result.models or {},
        "baseline_nonlinear": {} if result.baseline.nonlinear is None else band_json(
            result.baseline.nonlinear),
        "optimum_nonlinear": {} if result.optimum.nonlinear is None else band_json(
            result.optimum.nonlinear),
        "baseline_peak_linear": result.baseline.linear_peak,
        "optimum_peak_linear": result.optimum.linear_peak,
        "baseline_peak_nonlinear": result.baseline.nonlinear_peak,
        "optimum_peak_nonlinear": result.optimum.nonlinear_peak,
        "relaxed_peak_linear": math.nan if r is None else r.linear_peak,
        "baseline_values": result.baseline.values,
        "optimum_values": result.optimum.values,
        "relaxed_values": {} if r is None else r.values,
        "stages": result.stages,
        "settings": settings_dict(result.settings),
        "harmonics": _harmonics.orders_json(result.harmonics),
        "torus": result.torus,
        "train_toml": dumps_train(result.train),
        "baseline_train_toml": dumps_train(result.baseline_train),
        "gearjax_version": __version__,
        "created": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "seconds": result.seconds,
    }
    out.update(attrs or {})
    return xr.Dataset(data, coords=coords, attrs={k: netcdf_attr(v) for k, v in out.items()})
