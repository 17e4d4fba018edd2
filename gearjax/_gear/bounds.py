"""Bounds of every train-file value, and the rules between values that give warnings.

Outside ``low .. high`` a value is refused (no gear has it, or float64 arithmetic on it
means nothing); outside ``warn_low .. warn_high`` it is possible but unusual and gives a
``RangeWarning`` with the numbers. ``docs/input_bounds.md`` lists the same table; keep
the two in step.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .._errors import fail, field_message
from .train import MEMBERS, Train, member_inertia

class Bound(NamedTuple):
    """Range of one train-file key: refused outside ``low .. high`` (``None``: no bound;
    ``*_open``: the bound itself is refused too), warned outside ``warn_low ..
    warn_high``; ``magnitude``: the rules apply to ``|value|``; ``why``: one line."""

    key: str
    unit: str
    low: float | None
    high: float | None
    warn_low: float | None
    warn_high: float | None
    why: str
    low_open: bool = False
    high_open: bool = False
    magnitude: bool = False


MAX_HARMONICS = 512
"""Most stiffness harmonics, transmission-error pairs per mesh side and ripple rows: the
solution needs at least ``H max(mu)`` harmonics and the solver's memory grows with the
square of that (a solve refuses what does not fit: ``gearjax._studies.harmonics.require_size``);
beyond 512 terms a Fourier series of the stiffness wave only describes it more finely
than any solvable balance can use (the paper keeps 4)."""

STIFFNESS_HARMONICS = Bound(
    "stiffness_harmonics", "", 0, MAX_HARMONICS, None, None,
    "the solution needs at least H x max(mu) harmonics and the solver's memory grows with "
    "the square of that (the paper keeps 4)")
TE_PAIRS = Bound(
    "transmission_error.sun/ring (pairs)", "", 0, MAX_HARMONICS, None, None,
    "one pair per mesh harmonic, and the solution needs at least (pairs) x max(mu) harmonics and "
    "the solver's memory grows with the square of that")
RIPPLE_ROWS = Bound(
    "input_torque_ripple (rows)", "", 0, MAX_HARMONICS, None, None,
    "each row is one more frequency the solution must hold, and the solver's memory grows "
    "with the square of the harmonics it needs")
RIPPLE_ORDER = Bound(
    "input_torque_ripple order", "", 0.01, 1000.0, None, None,
    "an order is a multiple of the input shaft speed: below 0.01 it is a slow load change, "
    "not a ripple; above 1000 it is far above every mesh frequency and its harmonics")
TEETH = Bound(
    "teeth.sun/planet/ring", "", 1, 10_000, 7, 1000,
    "real gears have about 7 to 1000 teeth, fewer undercut beyond what profile shift "
    "repairs; above 10000 the exact speed ratios and mesh multipliers mu become impractical")
PLANETS = Bound(
    "planet_angles_deg (count)", "", 1, 64, None, None,
    "the densest planet sets carry about 20 planets; each adds a degree of freedom and two "
    "meshes to every solve")
MODULE_MM = Bound(
    "module_mm", "mm", 1e-3, 1e3, 0.1, 50.0,
    "instrument gears go down to about 0.1 mm and the largest industrial gears up to about "
    "50 mm; outside 0.001-1000 mm no gear exists")
PRESSURE_ANGLE_DEG = Bound(
    "pressure_angle_deg", "deg", 5.0, 45.0, 14.5, 30.0,
    "standard gears use 14.5-25 deg and special ones up to 30 deg; no involute gear practice "
    "goes outside 5-45 deg (undercut below, pointed teeth above)")
CARRIER_RADIUS_MM = Bound(
    "carrier_radius_mm", "mm", 1e-3, 1e5, None, None,
    "a planet-centre radius from 0.001 mm to 100 m covers every gear; outside it no gear exists")
CONTACT_RATIO = Bound(
    "contact_ratio", "", 1.0, 20.0, None, 4.0,
    "spur pairs reach about 2.5, helical totals rarely exceed 4 and wide turbo helicals "
    "reach about 8; no gear has 20 tooth pairs in contact at once")
MESH_STIFFNESS = Bound(
    "mesh_stiffness", "N/m", 1e2, 1e13, 1e6, 1e11,
    "steel meshes give about 1.4e10 N/m per metre of face width, so 1e6-1e11 spans fine-pitch "
    "plastic to metres of steel face; outside 1e2-1e13 no material and face width gives it")
MESH_DAMPING_RATIO = Bound(
    "mesh_damping_ratio", "", 0.0, 1.0, 0.005, 0.2,
    "measured gear-mesh damping ratios are about 0.01-0.1; at 1 and above a mesh is "
    "over-critically damped, which no gear mesh is", high_open=True)
HALF_BACKLASH = Bound(
    "half_backlash", "m", 0.0, None, None, None,
    "a clearance; its upper bounds follow from the module (HALF_BACKLASH_BASE_PITCHES, "
    "HALF_BACKLASH_WARN_MODULES)")
PHASE_DEG = Bound(
    "sun_ring_phase_deg, stage_phase_deg, phase columns", "deg", None, 1e4, None, None,
    "a phase is an angle of one cycle, written within +-360 deg; beyond +-10000 deg it is a "
    "typo", magnitude=True)
INERTIA = Bound(
    "inertia.sun/ring/carrier/planet", "kg m^2", 1e-20, 1e9, 1e-12, 1e6,
    "an instrument wheel has about 1e-12 kg m^2 and a 10-m girth gear about 1e6; outside "
    "1e-20..1e9 no gear exists and the mass matrix loses all precision beside its other terms")
PLANET_MASS = Bound(
    "planet_mass", "kg", 1e-15, 1e7, 1e-6, 1e4,
    "instrument planets weigh milligrams and wind-turbine planets about a tonne; outside "
    "1e-15..1e7 kg no gear exists")
TORSIONAL_STIFFNESS = Bound(
    "housing.braked, housing.free, couplings.stiffness", "N m/rad", 0.0, 1e14, None, None,
    "1e14 N m/rad is 1e4 x the mesh torsional stiffness of the largest gears: a stiffer "
    "spring adds nothing but round-off to every solve")
COUPLING_DAMPING = Bound(
    "couplings.damping", "N m s/rad", 0.0, 1e12, None, None,
    "a viscous damper across the coupling; 1e12 N m s/rad is above the critical damping "
    "2 sqrt(k J) of the stiffest coupling (1e14 N m/rad) on the heaviest member (1e9 kg m^2)")
COUPLING_DAMPING_RATIO = Bound(
    "couplings.damping_ratio", "", 0.0, 1.0, None, 0.3,
    "steel shafts have about 0.005-0.02 and elastomer couplings about 0.05-0.2; at 1 and "
    "above the coupling's own mode is over-critically damped", high_open=True)
TORQUE = Bound(
    "input_torque, drag_torque, ripple amplitudes", "N m", None, 1e10, None, 1e8,
    "the largest gear drives built carry about 2e7 N m; above 1e10 N m no gear exists",
    magnitude=True)

# Rules between keys (the ratios are dimensionless):
BRAKE_MIN_RATIO = 10.0
"""Warned: a braked-housing stiffness below 10 x the mesh torsional stiffness
``N k r_b^2`` of a member it holds lets that member turn with its meshes."""
FREE_MAX_RATIO = 0.01
"""Warned: a free-housing stiffness above 1/100 of the smallest mesh torsional stiffness
of a central member holds members that should turn freely."""
HALF_BACKLASH_BASE_PITCHES = 0.5
"""Refused: a clearance ``2 b`` of a whole base pitch ``pi m cos(alpha)`` leaves no tooth."""
HALF_BACKLASH_WARN_MODULES = 0.1
"""Warned: ordinary clearances ``2 b`` are 0.03-0.1 module, so ``b`` above 0.1 module is
unusual."""
TE_MAX_MODULES = 1.0
"""Refused: a transmission error of a whole module is a missing tooth, not an error."""
TE_WARN_MODULES = 0.05
"""Warned: transmission errors are micrometres, about 0.001-0.01 module."""
DRAG_WARN_RATIO = 0.1
"""Warned: the drag torque is a small preload; above 1/10 of the input torque it is a load."""
CARRIER_RADIUS_WARN_MODULES = 1.0
"""Warned: a planet-centre radius more than one module from ``m (Z_s + Z_p) / 2`` needs
profile shifts ``x_s + x_p`` beyond +-1."""

FACE_WIDTH_MM = Bound(
    "face_width_mm", "mm", 1e-3, 1e5, 1.0, 2000.0,
    "instrument gears are about 1 mm wide and the widest girth and mill gears about 2 m; "
    "outside 0.001 mm-100 m no gear exists")
PROFILE_SHIFT = Bound(
    "profile_shift.sun/planet/ring", "", None, 3.0, None, 1.5,
    "practical shifts stay within +-1 and rarely reach 1.5; beyond 3 a tooth is all tip "
    "or all root (the geometry rules refuse most such gears anyway)", magnitude=True)
TOOTH_COEFFICIENTS = Bound(
    "addendum_coefficient, dedendum_coefficient", "", 0.0, 3.0, 0.75, 1.6,
    "basic racks use 1.0/1.25 (ISO 53), stub teeth 0.8 and high teeth up to about 1.4/1.6; "
    "above 3 modules a tooth is a spike", low_open=True)
ROOT_RADIUS_COEFFICIENT = Bound(
    "root_radius_coefficient", "", 0.0, 1.0, None, 0.6,
    "ISO 53 racks use 0.25-0.39 and full-radius roots about 0.47; a cutter tip radius above "
    "one module does not fit the tooth space")
YOUNGS_MODULUS = Bound(
    "youngs_modulus", "Pa", 1e6, 1e13, 1e9, 5e11,
    "plastic gears are about 1-5 GPa and steel 206 GPa; outside 1 MPa-10 TPa no solid "
    "exists", low_open=True)
TIP_RELIEF_UM = Bound(
    "tip_relief amount_um", "um", 0.0, 1e4, None, 500.0,
    "linear tip relief is micrometres to about a hundred; 10 mm of relief removes the tooth")

BOUNDS = (STIFFNESS_HARMONICS, TE_PAIRS, RIPPLE_ROWS, RIPPLE_ORDER, TEETH, PLANETS, MODULE_MM,
          PRESSURE_ANGLE_DEG, CARRIER_RADIUS_MM, CONTACT_RATIO, MESH_STIFFNESS,
          MESH_DAMPING_RATIO, HALF_BACKLASH, PHASE_DEG, INERTIA, PLANET_MASS,
          TORSIONAL_STIFFNESS, COUPLING_DAMPING, COUPLING_DAMPING_RATIO, TORQUE, FACE_WIDTH_MM,
          PROFILE_SHIFT, TOOTH_COEFFICIENTS, ROOT_RADIUS_COEFFICIENT, YOUNGS_MODULUS,
          TIP_RELIEF_UM)
"""Every single-key bound, in the order of docs/input_bounds.md."""


def check_ranges(train: Train) -> list[str]:
    """Check every value of ``train`` against its bound; raise ``TrainError`` on the first
    value outside it (file order).

    **Returns:** one message per unusual value (``RangeWarning`` text, not issued here).
    """
    src = train.source
    notes: list[str] = []

    def check(field: str, value, bound: Bound) -> None:
        first = None  # one warning per field, every element checked for refusal
        for x in _concrete(value):
            note = _judge(src, field, x, bound)
            first = first or note
        if first is not None:
            notes.append(first)

    def count(field: str, n: int, shown, bound: Bound) -> None:
        if bound.high is not None and n > bound.high:
            raise fail(src, field, shown, f"at most {bound.high:g} {_what(bound)} are allowed, "
                                          f"got {n}: {bound.why}")

    check("stiffness_harmonics", train.stiffness_harmonics, STIFFNESS_HARMONICS)
    for s in train.stages:
        f = f"{s.id}."
        for k in ("sun", "planet", "ring"):
            check(f"{f}teeth.{k}", getattr(s.teeth, k), TEETH)
        check(f + "module_mm", s.module_mm, MODULE_MM)
        check(f + "pressure_angle_deg", s.pressure_angle_deg, PRESSURE_ANGLE_DEG)
        count(f + "planet_angles_deg", s.n_planets, _short(s.planet_angles_deg), PLANETS)
        if s.carrier_radius_mm is not None:
            check(f + "carrier_radius_mm", s.carrier_radius_mm, CARRIER_RADIUS_MM)
        for side in ("sun", "ring"):
            check(f"{f}contact_ratio.{side}", getattr(s.contact_ratio, side), CONTACT_RATIO)
        for side in ("sun", "ring"):
            check(f"{f}mesh_stiffness.{side}", getattr(s.mesh_stiffness, side), MESH_STIFFNESS)
        check(f + "mesh_damping_ratio", s.mesh_damping_ratio, MESH_DAMPING_RATIO)
        if s.geometry is not None:
            _check_geometry_ranges(check, f, s.geometry)
        for side in ("sun", "ring"):
            check(f"{f}half_backlash.{side}", getattr(s.half_backlash, side), HALF_BACKLASH)
        check(f + "sun_ring_phase_deg", s.sun_ring_phase_deg, PHASE_DEG)
        check(f + "stage_phase_deg", s.stage_phase_deg, PHASE_DEG)
        for side in ("sun", "ring"):
            rows = getattr(s.transmission_error, side)
            field = f"{f}transmission_error.{side}"
            count(field, int(np.shape(rows)[-2]) if np.ndim(rows) >= 2 else 0, _short(rows),
                  TE_PAIRS)
            for j, row in enumerate(_rows(rows)):
                _judge(src, f"{field}[{j}] phase", row[1], PHASE_DEG)
        for k in ("sun", "ring", "carrier", "planet"):
            check(f"{f}inertia.{k}", getattr(s.inertia, k), INERTIA)
        check(f + "planet_mass", s.planet_mass, PLANET_MASS)
        notes.extend(_stage_rules(src, s))
    for i, c in enumerate(train.couplings):
        field = f"couplings[{i}].stiffness"
        for x in _concrete(c.stiffness):
            if x == 0.0:
                raise fail(src, field, x,
                           f"must be > 0: coupling {c.label!r} joins {c.members[0]} and "
                           f"{c.members[1]}, which the kinematics then turns together, but a "
                           "zero stiffness transmits no torque; remove the coupling, or make it "
                           "a clutch with gears = [...] naming the gears where it is engaged")
        check(field, c.stiffness, TORSIONAL_STIFFNESS)
        if c.damping is not None and c.damping_ratio is not None:
            raise fail(src, f"couplings[{i}].damping_ratio", _short(c.damping_ratio),
                       "damping is given too: give the coupling's damper as damping "
                       "(N m s/rad) or as damping_ratio, not both")
        if c.damping is not None:
            check(f"couplings[{i}].damping", c.damping, COUPLING_DAMPING)
        if c.damping_ratio is not None:
            check(f"couplings[{i}].damping_ratio", c.damping_ratio, COUPLING_DAMPING_RATIO)
    for x in _concrete(train.housing.braked):
        if x == 0.0:
            raise fail(src, "housing.braked", x,
                       "must be > 0: a brake with no stiffness cannot hold the braked member, "
                       "so the speeds and static loads are undetermined")
    check("housing.braked", train.housing.braked, TORSIONAL_STIFFNESS)
    check("housing.free", train.housing.free, TORSIONAL_STIFFNESS)
    for g in train.gears:
        f = f"gears.{g.name}."
        check(f + "input_torque", g.input_torque, TORQUE)
        ripple = g.input_torque_ripple
        count(f + "input_torque_ripple", len(g.ripple_orders), _short(ripple), RIPPLE_ROWS)
        orders = list(g.ripple_orders)
        for j, row in enumerate(_rows(ripple)):
            check(f"{f}input_torque_ripple[{j}] amplitude", row[0], TORQUE)
            check(f"{f}input_torque_ripple[{j}] phase", row[1], PHASE_DEG)
            if j < len(orders):
                check(f"{f}input_torque_ripple[{j}] order", float(orders[j]), RIPPLE_ORDER)
        check(f + "drag_torque", g.drag_torque, TORQUE)
    notes.extend(_train_rules(train))
    return notes


def _check_geometry_ranges(check, f: str, geo) -> None:
    check(f + "face_width_mm", geo.face_width_mm, FACE_WIDTH_MM)
    for g in ("sun", "planet", "ring"):
        check(f"{f}profile_shift.{g}", getattr(geo.profile_shift, g), PROFILE_SHIFT)
    check(f + "addendum_coefficient", geo.addendum, TOOTH_COEFFICIENTS)
    check(f + "dedendum_coefficient", geo.dedendum, TOOTH_COEFFICIENTS)
    check(f + "root_radius_coefficient", geo.root_radius, ROOT_RADIUS_COEFFICIENT)
    check(f + "youngs_modulus", geo.youngs_modulus, YOUNGS_MODULUS)
    for g in ("sun", "planet", "ring"):
        check(f"{f}tip_relief.{g}.amount_um", getattr(geo.tip_relief.amount_um, g),
              TIP_RELIEF_UM)


def mesh_torsional_stiffness(stage, member: str) -> float:
    """Torsional stiffness (N m/rad) of ``member``'s meshes with the others held:
    ``N kbar_s r_s^2`` (sun), ``N kbar_r r_r^2`` (ring), their sum (carrier), with base
    radii ``r``; the scale a brake must exceed and a free housing spring stay below."""
    rs, _, rr = (_float(r) for r in stage.base_radii())
    sun = stage.n_planets * _float(stage.mesh_stiffness.sun) * rs**2
    ring = stage.n_planets * _float(stage.mesh_stiffness.ring) * rr**2
    return {"sun": sun, "ring": ring, "carrier": sun + ring}[member]


def _stage_rules(src, s) -> list[str]:
    """Bounds of one stage that depend on its module: backlash, transmission error, carrier
    radius. Raises on refusal; returns the warnings."""
    notes = []
    if not _all_scalar(s.module_mm, s.pressure_angle_deg):
        return notes
    m = _float(s.module_mm) * 1e-3  # m
    base_pitch = math.pi * m * math.cos(math.radians(_float(s.pressure_angle_deg)))
    for side in ("sun", "ring"):
        field, warned = f"{s.id}.half_backlash.{side}", False
        for b in _concrete(getattr(s.half_backlash, side)):
            if b >= HALF_BACKLASH_BASE_PITCHES * base_pitch:
                raise fail(src, field, b,
                           f"must be < {HALF_BACKLASH_BASE_PITCHES:g} base pitch = "
                           f"{HALF_BACKLASH_BASE_PITCHES * base_pitch:.4g} m: a clearance 2 b of a "
                           f"whole base pitch pi m cos(alpha) = {base_pitch:.4g} m leaves no tooth")
            if b > HALF_BACKLASH_WARN_MODULES * m and not warned:
                warned = True
                notes.append(field_message(
                    src, field, b,
                    f"above the usual {HALF_BACKLASH_WARN_MODULES:g} module = "
                    f"{HALF_BACKLASH_WARN_MODULES * m:.3g} m (ordinary clearances 2 b are 0.03-0.1 "
                    "module); data kept as given"))
    for side in ("sun", "ring"):
        rows = getattr(s.transmission_error, side)
        field, warned = f"{s.id}.transmission_error.{side}", False
        for j, row in enumerate(_rows(rows)):
            a, field_j = row[0], f"{field}[{j}] amplitude"
            if a > TE_MAX_MODULES * m:
                raise fail(src, field_j, a,
                           f"must be <= {TE_MAX_MODULES:g} module = {TE_MAX_MODULES * m:.4g} m: a "
                           "transmission error of a whole module is a missing tooth, not an error")
            if a > TE_WARN_MODULES * m and not warned:
                warned = True
                notes.append(field_message(
                    src, field_j, a,
                    f"above the usual {TE_WARN_MODULES:g} module = {TE_WARN_MODULES * m:.3g} m "
                    "(transmission errors are micrometres); data kept as given"))
    if s.carrier_radius_mm is not None and _all_scalar(s.carrier_radius_mm):
        rc = _float(s.carrier_radius_mm)
        nominal = _float(s.module_mm) * (s.teeth.sun + s.teeth.planet) / 2
        if abs(rc - nominal) > CARRIER_RADIUS_WARN_MODULES * _float(s.module_mm):
            notes.append(field_message(
                src, f"{s.id}.carrier_radius_mm", rc,
                f"differs from m (Z_s + Z_p) / 2 = {nominal:.4g} mm by {rc - nominal:+.3g} mm, "
                f"more than {CARRIER_RADIUS_WARN_MODULES:g} module: that needs profile shifts "
                "x_s + x_p beyond +-1; data kept as given"))
    return notes


def _train_rules(train: Train) -> list[str]:
    """Warnings that compare keys across the train: brake and free housing stiffness
    against the meshes, drag and ripple against the input torque."""
    src, notes = train.source, []
    stages = {s.id: s for s in train.stages}
    scalars = [train.housing.braked, train.housing.free]
    for s in train.stages:
        scalars += [s.module_mm, s.pressure_angle_deg, s.mesh_stiffness.sun,
                    s.mesh_stiffness.ring]
    if _all_scalar(*scalars):
        held = {}  # braked member -> first gear that brakes it
        for g in train.gears:
            for b in g.brakes:
                held.setdefault(b, g.name)
        kt = {}
        for path in held:
            sid, _, member = path.rpartition(".")
            if sid in stages and member in MEMBERS:
                kt[path] = mesh_torsional_stiffness(stages[sid], member)
        braked = _float(train.housing.braked)
        if kt:
            path = max(kt, key=kt.get)
            if braked < BRAKE_MIN_RATIO * kt[path]:
                notes.append(field_message(
                    src, "housing.braked", braked,
                    f"a brake should be much stiffer than what it holds: below "
                    f"{BRAKE_MIN_RATIO:g} x the mesh torsional stiffness N k r_b^2 = "
                    f"{kt[path]:.3g} N m/rad of {path} (braked in gear {held[path]!r}), i.e. "
                    f"{BRAKE_MIN_RATIO * kt[path]:.3g} N m/rad, the braked member turns with its "
                    "meshes and speeds and static loads depart from the rigid kinematics; data "
                    "kept as given"))
        every = {f"{s.id}.{m}": mesh_torsional_stiffness(s, m)
                 for s in train.stages for m in MEMBERS}
        path = min(every, key=every.get)
        free = _float(train.housing.free)
        if free > FREE_MAX_RATIO * every[path]:
            notes.append(field_message(
                src, "housing.free", free,
                f"a free member should turn freely: above {FREE_MAX_RATIO:g} x the smallest mesh "
                f"torsional stiffness N k r_b^2 = {every[path]:.3g} N m/rad (of {path}), i.e. "
                f"{FREE_MAX_RATIO * every[path]:.3g} N m/rad, the housing springs hold the free "
                "members and shift modes and static loads; data kept as given"))
    notes.extend(_damper_rules(train))
    for g in train.gears:
        if not _all_scalar(g.input_torque, g.drag_torque):
            continue
        torque, drag = abs(_float(g.input_torque)), _float(g.drag_torque)
        if torque > 0 and drag > DRAG_WARN_RATIO * torque:
            notes.append(field_message(
                src, f"gears.{g.name}.drag_torque", drag,
                f"above {DRAG_WARN_RATIO:g} x the input torque {torque:g} N m: the drag torque is "
                "a small preload for unloaded stages, not a load; data kept as given"))
        ripple = np.asarray(g.input_torque_ripple) if _all_scalar(g.input_torque) else None
        if ripple is not None and ripple.ndim == 2 and ripple.shape[0]:
            total = float(np.sum(np.abs(ripple[:, 0])))
            if total > torque:
                notes.append(field_message(
                    src, f"gears.{g.name}.input_torque_ripple", ripple.tolist(),
                    f"the ripple amplitudes add up to {total:g} N m, more than the input torque "
                    f"{torque:g} N m: the load reverses every cycle; data kept as given"))
    return notes


def _damper_rules(train: Train) -> list[str]:
    """Warned: a coupling ``damping`` above the critical damping of its own mode
    (``Coupling.critical_damping``; a ``damping_ratio`` that high is refused)."""
    notes, members = [], {f"{s.id}.{m}" for s in train.stages for m in MEMBERS}
    for i, c in enumerate(train.couplings):
        if c.damping is None or not set(c.members) <= members:
            continue  # an unknown member is refused by validate_train
        try:
            damping, critical = _float(c.damping), _float(
                c.critical_damping(*(member_inertia(train, m) for m in c.members)))
        except Exception:  # traced (inside jit or grad): nothing concrete to check
            continue
        if damping > critical > 0:
            notes.append(field_message(
                train.source, f"couplings[{i}].damping", damping,
                f"above the critical damping 2 sqrt(k J1 J2 / (J1 + J2)) = {critical:.4g} "
                f"N m s/rad of the own mode of coupling {c.label!r} ({c.members[0]} and "
                f"{c.members[1]} as rigid inertias on its spring): a damping ratio of "
                f"{damping / critical:.3g}, over-critical; data kept as given"))
    return notes


def _judge(src, field: str, value, b: Bound) -> str | None:
    """Refuse ``value`` outside ``b`` (raise); return a warning when it is unusual."""
    if isinstance(value, float) and not math.isfinite(value):  # a train built in code
        raise fail(src, field, value, "must be a finite number")
    x = abs(value) if b.magnitude else value
    mag = "|value| " if b.magnitude else ""
    unit = f" {b.unit}" if b.unit else ""
    below = b.low is not None and (x <= b.low if b.low_open else x < b.low)
    above = b.high is not None and (x >= b.high if b.high_open else x > b.high)
    if below or above:
        parts = []
        if b.low is not None:
            parts.append(f"{'>' if b.low_open else '>='} {b.low:g}")
        if b.high is not None:
            parts.append(f"{'<' if b.high_open else '<='} {b.high:g}")
        raise fail(src, field, value, f"{mag}must be {' and '.join(parts)}{unit}: {b.why}")
    if b.warn_low is not None and x < b.warn_low or b.warn_high is not None and x > b.warn_high:
        if b.warn_low is not None and b.warn_high is not None:
            usual = f"outside the usual {b.warn_low:g} to {b.warn_high:g}{unit}"
        elif b.warn_high is not None:
            usual = f"{mag}above the usual {b.warn_high:g}{unit}"
        else:
            usual = f"{mag}below the usual {b.warn_low:g}{unit}"
        return field_message(src, field, value, f"{usual}: {b.why}; data kept as given")
    return None


def _rows(value) -> list[list[float]]:
    """Rows of a concrete ``(L, 2)`` array as lists of floats ([] for a traced or batched
    value)."""
    try:
        a = np.asarray(value, dtype=float)
    except Exception:
        return []
    return a.tolist() if a.ndim == 2 else []


def _what(b: Bound) -> str:
    return b.key.split("(")[-1].rstrip(")") if "(" in b.key else "values"


def _concrete(value) -> list:
    """The values of a scalar or array as Python numbers ([] for a traced value)."""
    if isinstance(value, int | float) and not isinstance(value, bool):
        return [value]
    try:
        a = np.asarray(value, dtype=float)
    except Exception:  # a tracer inside jit/grad: nothing concrete to check
        return []
    return [float(v) for v in a.ravel()]


def _all_scalar(*values) -> bool:
    try:
        return all(np.ndim(v) == 0 and np.asarray(v, dtype=float).size == 1 for v in values)
    except Exception:
        return False


def _float(x) -> float:
    return float(np.asarray(x))


def _short(value):
    """A list for a message (``_show`` shortens it to one line)."""
    try:
        return np.asarray(value).tolist()
    except Exception:
        return "(traced)"
