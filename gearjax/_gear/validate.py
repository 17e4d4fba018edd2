"""Whole-train rules: member paths, clutches, planet overlap, kinematics; geometry and
range warnings.

Types and signs are checked while reading (``_toml_io``); the bounds of every value
(:mod:`.bounds`, listed in ``docs/input_bounds.md``) by the reader right after it
builds the train and again by :func:`validate_train` for trains built in code. Errors
are ``TrainError`` with one line naming file, field, value and rule. Values that are
possible but unusual are ``RangeWarning`` s with the numbers; the geometry rules of
standard gears (concentricity, assembly) are ``GeometryWarning`` s because published
data break them.
"""

from __future__ import annotations

import math

import numpy as np

from .bounds import check_ranges
from .tooth_rules import tooth_geometry_warnings
from .._errors import fail, warn_geometry, warn_range
from .kinematics import kinematics
from .train import MEMBERS, Train
from .translational import check_support, rigid_rotation_messages


def validate_train(train: Train, *, emit_warnings: bool = True) -> list[str]:
    """Check a train; raise ``TrainError`` on impossible input.

    **Returns:** the geometry warnings, then the range warnings (also issued as
    ``GeometryWarning`` and ``RangeWarning`` when ``emit_warnings``).
    """
    unusual = check_ranges(train)
    src = train.source
    ids = train.stage_ids
    valid_paths = [f"{sid}.{m}" for sid in ids for m in MEMBERS]

    def check_path(field: str, path: str) -> None:
        if path not in valid_paths:
            raise fail(src, field, path,
                       f"unknown member path; expected STAGE.sun|ring|carrier with STAGE in "
                       f"{list(ids)}")

    for s in train.stages:
        _check_overlap(train, s)
    if train.translational:
        check_support(train)
    gears = train.gear_names
    for i, c in enumerate(train.couplings):
        field = f"couplings[{i}]" + (f" (id {c.id!r})" if c.id else "")
        for path in c.members:
            check_path(field + ".members", path)
        if c.members[0] == c.members[1]:
            # interface.md asks for members of different stages; a lock-up clutch joins two
            # members of one stage (sun and carrier), so only a self-coupling is refused
            raise fail(src, field + ".members", list(c.members),
                       "a coupling joins two different members")
        for name in c.gears or ():
            if name not in gears:
                raise fail(src, field + ".gears", name,
                           f"the clutch names a gear that does not exist; gears are {list(gears)}")
    for g in train.gears:
        f = f"gears.{g.name}"
        check_path(f + ".input", g.input)
        check_path(f + ".output", g.output)
        for b in g.brakes:
            check_path(f + ".brakes", b)
            if b in (g.input, g.output):
                raise fail(src, f + ".brakes", b, "the input and the output cannot be braked")
        if g.input == g.output:
            raise fail(src, f + ".output", g.output, "the output must differ from the input")
        kinematics(train, g.name)  # raises on undetermined or locked speeds

    messages = geometry_warnings(train)
    if emit_warnings:
        for m in messages:
            warn_geometry(m)
        for m in unusual:
            warn_range(m)
    return messages + unusual


def geometry_warnings(train: Train) -> list[str]:
    """Concentricity and assembly rules of standard gears, and in the translational
    model the radii a rigid rotation needs, with the numbers."""
    out = []
    where = train.source or train.name
    for s in train.stages:
        zs, zp, zr = s.teeth.sun, s.teeth.planet, s.teeth.ring
        if s.geometry is not None:  # the centre distance is checked with the profile shifts
            out += tooth_geometry_warnings(s, where)
        elif zr != zs + 2 * zp:
            gap = float(s.module_mm) * (zr - zs - 2 * zp) / 2
            out.append(
                f"{where}: stage {s.id!r} teeth sun {zs}, planet {zp}, ring {zr}: concentricity "
                f"rule Z_r = Z_s + 2 Z_p fails ({zs} + 2*{zp} = {zs + 2 * zp} != {zr}), a "
                f"centre-distance mismatch of {gap:+.3g} mm at module {float(s.module_mm):g} mm; "
                "data kept as given"
            )
        slots = [(i, psi, (zs + zr) * psi / 360.0)
                 for i, psi in enumerate(np.asarray(s.planet_angles_deg))]
        off = [(i, psi, q) for i, psi, q in slots if abs(q - round(q)) > 1e-6]
        if len(off) == 1:
            ((i, psi, q),) = off
            out.append(
                f"{where}: stage {s.id!r} planet {i + 1} at {psi:g} deg: assembly rule "
                f"(Z_s + Z_r) psi / 360 = {zs + zr}*{psi:g}/360 = {q:.4g} is not an integer"
            )
        elif off:  # one line for the stage, however many planets
            shown = ", ".join(f"{i + 1} at {psi:g} deg ({q:.4g})" for i, psi, q in off[:SHOWN])
            more = f" and {len(off) - SHOWN} more" if len(off) > SHOWN else ""
            out.append(
                f"{where}: stage {s.id!r}: {len(off)} of {len(s.planet_angles_deg)} planets "
                f"break the assembly rule (Z_s + Z_r) psi / 360 = {zs + zr} psi / 360 an "
                f"integer: planets {shown}{more}"
            )
    if train.translational:
        out += rigid_rotation_messages(train)
    return out


SHOWN = 4
"""Planets named in a warning that many planets share (the rest are counted)."""


def assembly_slots(stage) -> int:
    """``Z_s + Z_r``: the assembly rule lets a planet sit only at multiples of
    ``360 / (Z_s + Z_r)`` degrees (model.md, Geometry)."""
    return int(stage.teeth.sun + stage.teeth.ring)


def assembly_ok(stage, angles_deg, atol: float = 1e-6) -> bool:
    """Whether every planet angle (deg) satisfies the assembly rule
    ``(Z_s + Z_r) psi / 360`` integer."""
    q = assembly_slots(stage) * np.asarray(angles_deg, dtype=float) / 360.0
    return bool(np.all(np.abs(q - np.round(q)) <= atol))


def min_planet_gap_deg(stage) -> float:
    """Smallest angle (deg) between two planet centres that do not overlap: the
    ``dpsi`` with ``2 r_c sin(dpsi / 2) = m (Z_p + 2)`` (any larger angle up to
    ``360 - dpsi`` is clear); 180 when even opposite planets overlap."""
    rc = float(stage.carrier_radius()) * 1e3
    tip = float(stage.module_mm) * (stage.teeth.planet + 2)
    if tip >= 2 * rc:
        return 180.0
    return math.degrees(2 * math.asin(tip / (2 * rc)))


def overlapping_planets(stage, angles_deg) -> tuple[int, int, float, float] | None:
    """The first pair of planets ``(i, j)`` (0-based) of ``angles_deg`` that overlap,
    with their centre distance ``2 r_c |sin(dpsi/2)|`` and the tip diameter
    ``m (Z_p + 2)`` (mm); ``None`` when none do (the rule of :func:`validate_train`)."""
    psi = np.deg2rad(np.asarray(angles_deg, dtype=float))
    rc = float(stage.carrier_radius()) * 1e3
    tip = float(stage.module_mm) * (stage.teeth.planet + 2)
    for i in range(len(psi)):
        for j in range(i + 1, len(psi)):
            gap = abs(2 * rc * math.sin((psi[j] - psi[i]) / 2))
            if gap <= tip:
                return i, j, gap, tip
    return None


def _check_overlap(train: Train, s) -> None:
    hit = overlapping_planets(s, s.planet_angles_deg)
    if hit is not None:
        i, j, gap, tip = hit
        raise fail(
            train.source, f"{s.id}.planet_angles_deg",
            np.asarray(s.planet_angles_deg).tolist(),
            f"planets {i + 1} and {j + 1} overlap: centre distance 2 r_c sin(dpsi/2) = "
            f"{gap:.4g} mm must exceed the tip diameter m (Z_p + 2) = {tip:.4g} mm",
        )
