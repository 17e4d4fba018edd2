"""The ``sensitivity`` command's JSON: a point study's fields and its derivatives, ranked,
each with the file unit of its parameter."""

from __future__ import annotations

import numpy as np

from .point import Sensitivity


def path_unit(path: str) -> str:
    """The file unit of a TOML path's value (``deg`` for angles)."""
    parts = path.split(".")
    key = parts[1] if len(parts) > 1 else ""
    if parts[0] == "gears":
        return "N m"
    if parts[0] in ("housing", "couplings"):
        return "N m/rad"
    return {"module_mm": "mm", "carrier_radius_mm": "mm", "pressure_angle_deg": "deg",
            "sun_ring_phase_deg": "deg", "stage_phase_deg": "deg", "planet_angles_deg": "deg",
            "mesh_stiffness": "N/m", "half_backlash": "m", "inertia": "kg m^2",
            "planet_mass": "kg", "face_width_mm": "mm", "youngs_modulus": "Pa"}.get(key, "1")


def sensitivity_json(result: Sensitivity, top: int | None = None) -> dict:
    """The ``sensitivity`` JSON: point fields and ``derivatives``, ranked by
    ``|normalised|`` (each ``{path, value, unit, derivative, derivative_unit,
    normalised}``; ``reason`` where ``normalised`` is null); ``harmonics`` is K, or on a
    torus the list of orders per angle, and ``torus`` what the torus study solved
    (:func:`~gearjax._gear.case.torus_fields`; null for a periodic gear)."""
    out = {
        "gear": result.gear,
        "reference_stage": result.reference_stage,
        "mesh_frequency_hz": result.mesh_frequency_hz,
        "omega": result.omega,
        "harmonics": list(result.harmonics) if isinstance(result.harmonics, tuple)
        else result.harmonics,
        "linear": result.linear,
        "response": result.response,
        "unit": result.unit,
        "mesh": result.mesh,
        "value": result.value,
        "result": result.result,
        "converged": result.converged,
        "stable": result.stable,
        "fold_distance": result.fold_distance,
        "fold_tol": result.fold_tol,
        "reason": result.message,
        "mesh_values": {m: float(v) for m, v in zip(result.meshes, result.mesh_values)},
        "derivatives": [],
        "torus": result.torus,
    }
    if result.derivative is None:
        out["derivatives"] = None
        return out
    rows = []
    for k in result.ranking()[:top]:
        path = result.paths[k]
        unit = path_unit(path)
        row = {"path": path, "value": float(result.values[k]), "unit": unit,
               "derivative": float(result.derivative[k]),
               "derivative_unit": f"{result.unit} per {unit}",
               "normalised": float(result.normalised[k])}
        if not np.isfinite(result.normalised[k]):
            row["normalised"] = None
            row["reason"] = ("the parameter is 0: no relative change (use the derivative)"
                             if result.values[k] == 0 else "the response is 0")
        rows.append(row)
    out["derivatives"] = rows
    return out
