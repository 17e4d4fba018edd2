"""The ``sensitivity`` command's JSON: a point study's fields and its derivatives, ranked,
each with the file unit of its parameter."""

from __future__ import annotations

import numpy as np

from ..._io.results import json_number
from ..harmonics import TRUNCATION_TARGET
from .point import Sensitivity
from .steps import RANKING_RULE


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
    """The ``sensitivity`` JSON: point fields and ``derivatives``, ranked by ``|relative|``
    (``ranking`` says the rule, :data:`~gearjax._studies.sensitivity.steps.RANKING_RULE`;
    each ``{path, value, unit, derivative, derivative_unit, normalised, step, step_rule,
    relative}``: ``normalised`` is ``(p/R) dR/dp``, null with a ``reason`` where it means
    nothing; ``step`` (in ``unit``) and ``step_rule`` (null: the value itself) what
    ``relative = (step/R) dR/dp`` is taken over); ``harmonics`` is K, or on a torus the
    list of orders per angle, and ``torus`` what the torus study solved
    (:func:`~gearjax._gear.case.torus_fields`; null for a periodic gear); ``mode``: the
    mode a linear point was refused for (null otherwise); ``truncation``: the point's a
    posteriori truncation checks (``K``, ``K_check``, ``change``; against
    ``truncation_target``)."""
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
        "mode": result.mode,
        "mesh_values": {m: float(v) for m, v in zip(result.meshes, result.mesh_values)},
        "ranking": RANKING_RULE,
        "derivatives": [],
        "torus": result.torus,
        "truncation": list(result.truncation),
        "truncation_target": TRUNCATION_TARGET,
    }
    if result.derivative is None:
        out["derivatives"] = None
        return out
    rows = []
    rules = result.step_rules or (None,) * len(result.paths)
    for k in result.ranking()[:top]:
        path = result.paths[k]
        unit = path_unit(path)
        row = {"path": path, "value": float(result.values[k]), "unit": unit,
               "derivative": float(result.derivative[k]),
               "derivative_unit": f"{result.unit} per {unit}",
               "normalised": float(result.normalised[k]),
               "step": None if result.steps is None else float(result.steps[k]),
               "step_rule": rules[k],
               "relative": (None if result.relative is None
                            else json_number(result.relative[k]))}
        if not np.isfinite(result.normalised[k]):
            row["normalised"] = None
            row["reason"] = (
                "the angle's origin is a convention: its relative change means nothing "
                f"(ranked over its step: {rules[k]})" if rules[k] is not None
                else "the parameter is 0: no relative change (use the derivative)"
                if result.values[k] == 0 else "the response is 0")
        rows.append(row)
    out["derivatives"] = rows
    return out

