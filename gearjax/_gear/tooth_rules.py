"""Tooth-geometry rules of a stage: what cannot mesh is refused, what is unusual warned.

Both meshes of a stage are judged at the stage's one centre distance
(:func:`.mesh_stiffness.stage_contacts`) by the involute rules of
:func:`.involute.mesh_violations`; the model's backlash is the file's
``half_backlash``, so a centre distance that gives a mesh more is said.
"""

from __future__ import annotations

from .._errors import fail
from .involute import mesh_violations
from .mesh_stiffness import mesh_pair, stage_contacts


def _mesh_rules(stage):
    """``(mesh name, rule, message)`` for each geometry rule the stage's meshes break."""
    out = []
    for side in ("sun", "ring"):
        pair, _, contact = mesh_pair(stage, side)
        out += [(f"{side}-planet", rule, message)
                for rule, message in mesh_violations(*pair, contact)]
    return out


def check_tooth_geometry(stage, source: str | None) -> None:
    """Refuse tooth geometry that cannot mesh (interference, pointed teeth, contact ratio
    below 1, a centre distance the two meshes cannot share), naming the stage, the mesh,
    the rule and the numbers. **Raises:** ``TrainError``."""
    for name, rule, message in _mesh_rules(stage):
        if rule.startswith("warning:"):
            continue
        if rule == "jamming" and stage.carrier_radius_mm is not None:
            field, value = f"{stage.id}.carrier_radius_mm", float(stage.carrier_radius_mm)
        else:
            field, value = f"{stage.id}.profile_shift", _shifts(stage)
        raise fail(source, field, value, f"the {name} mesh breaks the {rule} rule: {message}")


def tooth_geometry_warnings(stage, where: str) -> list[str]:
    """Geometry that meshes but is unusual (thin tips; a shared centre distance that
    gives a mesh more backlash than the file's ``half_backlash`` states), with the
    numbers."""
    out = [f"{where}: stage {stage.id!r} {name} mesh: {rule.removeprefix('warning:').strip()}: "
           f"{message}" for name, rule, message in _mesh_rules(stage)
           if rule.startswith("warning:")]
    for side, contact in zip(("sun", "ring"), stage_contacts(stage)):
        added = float(contact.normal_backlash)
        stated = 2 * float(getattr(stage.half_backlash, side))
        if added > stated + 1e-9:
            out.append(
                f"{where}: stage {stage.id!r} {side}-planet mesh: the centre distance "
                f"{1e3 * float(contact.centre_distance):.4f} mm (zero-backlash "
                f"{1e3 * float(contact.zero_backlash_centre_distance):.4f} mm with these "
                f"profile shifts) gives {1e6 * added:.1f} um of normal backlash, more than "
                f"the {1e6 * stated:.1f} um of 2 half_backlash.{side}; the model uses the "
                "file's backlash")
    return out


def _shifts(stage) -> dict:
    shift = stage.geometry.profile_shift
    return {g: float(getattr(shift, g)) for g in ("sun", "planet", "ring")}
