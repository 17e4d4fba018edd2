"""Train files: TOML in (with field-by-field checks) and TOML out (round trip).

Reading checks every key's type and sign as it goes and names the file, field,
value and rule of the first thing that is wrong, then every value's bounds
(``bounds.check_ranges``); whole-train rules (member paths, kinematics, planet
overlap) and the geometry and range warnings live in ``_validate``. A file that cannot
be read (missing, a directory, not UTF-8, not TOML) is refused the same way.
"""

from __future__ import annotations

import math
import tomllib
from importlib import resources
from pathlib import Path

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import tomli_w

from .._errors import fail
from .train import (
    MEMBERS,
    MODELS,
    BearingStiffness,
    CentralMass,
    Coupling,
    Gear,
    Housing,
    Inertia,
    PerGear,
    PlanetErrors,
    Stage,
    SunRing,
    Teeth,
    Train,
    TipRelief,
    ToothGeometry,
    TransmissionError,
)
from .mesh_stiffness import geometric_stiffness
from .tooth_rules import check_tooth_geometry
from .toml_reader import TomlReader
from .bounds import check_ranges
from .validate import validate_train

BUNDLED_EXAMPLE = "al_shyyab_2009.toml"

_TOP_KEYS = {"name", "model", "stiffness_harmonics", "phasing", "mesh_damping", "stages",
             "couplings", "housing", "gears"}
_STAGE_KEYS = {"id", "teeth", "module_mm", "pressure_angle_deg", "planet_angles_deg",
               "carrier_radius_mm", "contact_ratio", "mesh_stiffness", "mesh_damping_ratio",
               "half_backlash", "sun_ring_phase_deg", "stage_phase_deg", "transmission_error",
               "inertia", "planet_mass", "mass", "bearing_stiffness", "bearing_damping_ratio",
               "base_diameter_mm", "planet_position_error_um",
               *("face_width_mm", "profile_shift",
               "addendum_coefficient", "dedendum_coefficient", "root_radius_coefficient",
               "youngs_modulus", "poisson_ratio", "tip_relief")}
_GEOMETRY_DEFAULTS = {"addendum_coefficient": 1.0, "dedendum_coefficient": 1.25,
                      "root_radius_coefficient": 0.38, "youngs_modulus": 206e9,
                      "poisson_ratio": 0.3}
"""Tooth-geometry keys beside ``face_width_mm``, defaults: ISO 53 profile A, steel."""
_GEARS = ("sun", "planet", "ring")
_DAMPER_KEYS = ("damping", "damping_ratio")
_COUPLING_KEYS = {"members", "stiffness", "id", "gears", *_DAMPER_KEYS}
_HOUSING_KEYS = {"braked", "free"}
_GEAR_KEYS = {"input", "output", "brakes", "input_torque", "input_torque_ripple", "drag_torque",
              "note", "input_rpm"}
PHASING_RULES = ("physical", "paper")
MESH_DAMPING_RULES = ("always", "contact")


def bundled_example_path() -> Path:
    """Path of the bundled paper case (the shared example plus its inferred gears)."""
    return Path(str(resources.files("gearjax") / "data" / BUNDLED_EXAMPLE))


def load_train(path: str | Path | None = None, *, validate: bool = True) -> Train:
    """Read and check a train file; ``None`` reads the bundled paper case.

    **Raises:** ``TrainError`` (a ``ValueError``) with one line naming file, field,
    value and rule, also for a file that cannot be read or is not UTF-8 TOML. Geometry
    rules that published data break, and unusual values, are warnings
    (``GeometryWarning``, ``RangeWarning``: both ``TrainWarning``), not errors.
    """
    path = bundled_example_path() if path is None else Path(path)
    source = str(path)
    try:
        data = path.read_bytes()
    except OSError as e:
        reason = e.strerror or type(e).__name__
        raise fail(source, "file", source, f"cannot be read ({reason})") from None
    return loads_train(_decode(data, source), source=source, validate=validate)


def _decode(data: bytes, source: str) -> str:
    """UTF-8 text of a train file; a UTF-8 byte-order mark (Windows editors) is dropped."""
    if data.startswith((b"\xff\xfe", b"\xfe\xff")):
        raise fail(source, "file", source,
                   "is UTF-16 text (it starts with a UTF-16 byte-order mark); a train file is "
                   "TOML and must be saved as UTF-8")
    nul = data.find(b"\x00")
    if nul >= 0:
        raise fail(source, "file", source,
                   f"contains NUL bytes (the first at offset {nul}): a binary file, "
                   "or UTF-16 text without a byte-order mark; a train file is TOML and must be "
                   "saved as UTF-8")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        line = data.count(b"\n", 0, e.start) + 1
        raise fail(source, "file", source,
                   f"is not UTF-8 text (byte 0x{data[e.start]:02x} at offset {e.start}, line "
                   f"{line}); a train file is TOML and must be saved as UTF-8") from None


def loads_train(text: str, source: str | None = None, *, validate: bool = True) -> Train:
    """Parse train-file text. ``source`` names it in messages and sets the default name."""
    if text.startswith("\ufeff"):  # a byte-order mark, as Windows editors write
        text = text[1:]
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        where = str(e)
        if "line" not in where:  # "(at end of document)": say where that is
            last = text.rsplit("\n", 1)[-1]
            where += f" (the end is line {text.count(chr(10)) + 1}, column {len(last) + 1})"
        raise fail(source, "file", "<TOML>", f"is not valid TOML ({where})") from None
    except RecursionError:
        raise fail(source, "file", "<TOML>",
                   "is not a train file: arrays or tables nested too deeply to read") from None
    train = train_from_dict(raw, source)
    if validate:
        validate_train(train)
    return train


def train_from_dict(raw: dict, source: str | None = None) -> Train:
    """Build a :class:`Train` from parsed TOML, checking types and single-value rules."""
    r = TomlReader(source)
    r.keys(raw, _TOP_KEYS, "file")
    default_name = Path(source).stem if source else "train"
    name = r.string(raw, "name", "name", default=default_name)
    model = r.choice(raw, "model", "model", MODELS, default="torsional")
    harmonics = r.integer(raw, "stiffness_harmonics", "stiffness_harmonics", default=4, low=0)
    phasing = r.choice(raw, "phasing", "phasing", PHASING_RULES, default="physical")
    damping = r.choice(raw, "mesh_damping", "mesh_damping", MESH_DAMPING_RULES, default="always")

    stages_raw = raw.get("stages")
    if not isinstance(stages_raw, list) or not stages_raw:
        raise fail(source, "stages", stages_raw, "at least one [[stages]] table is required")
    stages = tuple(_stage(r, s, i, model) for i, s in enumerate(stages_raw))
    ids = [s.id for s in stages]
    for i, sid in enumerate(ids):
        if sid in ids[:i]:
            raise fail(source, f"stages[{i}].id", sid, "stage ids must be unique")

    couplings_raw = raw.get("couplings", [])
    if not isinstance(couplings_raw, list):
        raise fail(source, "couplings", couplings_raw, "must be an array of [[couplings]] tables")
    couplings = tuple(_coupling(r, c, i) for i, c in enumerate(couplings_raw))

    housing_raw = raw.get("housing", {})
    r.table(housing_raw, "housing")
    r.keys(housing_raw, _HOUSING_KEYS, "housing")
    housing = Housing(
        braked=r.number(housing_raw, "braked", "housing.braked", default=1e10, low=0.0),
        free=r.number(housing_raw, "free", "housing.free", default=1e2, low=0.0),
    )

    gears_raw = raw.get("gears")
    if not isinstance(gears_raw, dict) or not gears_raw:
        raise fail(source, "gears", gears_raw, "at least one [gears.NAME] table is required")
    gears = tuple(_gear(r, name, g) for name, g in gears_raw.items())
    train = Train(
        name=name,
        stages=stages,
        couplings=couplings,
        housing=housing,
        gears=gears,
        stiffness_harmonics=harmonics,
        phasing=phasing,
        mesh_damping=damping,
        source=source,
        model=model,
    )
    check_ranges(train)  # bounds of every value (warnings come from validate_train)
    return train


def _stage(r: TomlReader, raw, i: int, model: str) -> Stage:
    r.table(raw, f"stages[{i}]")
    sid = raw.get("id")
    if not isinstance(sid, str) or not sid or "." in sid:
        raise r.fail(f"stages[{i}].id", sid, "a non-empty string without '.' is required")
    f = f"{sid}."  # field prefix: TOML paths start with the stage id
    r.keys(raw, _STAGE_KEYS, f"stages[{i}] (id {sid!r})")
    teeth_raw = r.sub(raw, "teeth", f + "teeth", {"sun", "planet", "ring"})
    teeth = Teeth(**{k: r.integer(teeth_raw, k, f"{f}teeth.{k}", low=1, rule="teeth must be >= 1")
                     for k in ("sun", "planet", "ring")})
    module = r.number(raw, "module_mm", f + "module_mm", low=0.0, strict=True)
    pressure = r.number(raw, "pressure_angle_deg", f + "pressure_angle_deg", low=0.0, strict=True)
    if not float(pressure) < 90.0:
        raise r.fail(f + "pressure_angle_deg", float(pressure), "must be between 0 and 90 degrees")
    angles = r.vector(raw, "planet_angles_deg", f + "planet_angles_deg")
    if angles.size < 1:
        raise r.fail(f + "planet_angles_deg", [], "at least one planet is required")
    if angles[0] != 0.0 or np.any(np.diff(angles) <= 0.0) or angles[-1] >= 360.0:
        raise r.fail(f + "planet_angles_deg", angles.tolist(),
                     "planet angles must start at 0 and increase strictly, below 360")
    inertia = r.sub(raw, "inertia", f + "inertia", {"sun", "ring", "carrier", "planet"})
    carrier = None
    if "carrier_radius_mm" in raw:
        carrier = r.number(raw, "carrier_radius_mm", f + "carrier_radius_mm", low=0.0, strict=True)
    geometry = _geometry(r, raw, f, teeth, module, pressure)
    derived = geometry is not None and geometry.derives_stiffness
    unknown = SunRing(sun=jnp.asarray(jnp.nan), ring=jnp.asarray(jnp.nan))
    stage = Stage(
        id=sid,
        teeth=teeth,
        module_mm=module,
        pressure_angle_deg=pressure,
        planet_angles_deg=jnp.asarray(angles),
        carrier_radius_mm=carrier,
        contact_ratio=unknown if derived else r.sun_ring(raw, "contact_ratio", f, low=1.0,
                                                         rule="must be >= 1"),
        mesh_stiffness=unknown if derived else r.sun_ring(raw, "mesh_stiffness", f, low=0.0,
                                                          strict=True),
        mesh_damping_ratio=r.number(raw, "mesh_damping_ratio", f + "mesh_damping_ratio",
                                    default=0.04, low=0.0),
        half_backlash=r.sun_ring(raw, "half_backlash", f, low=0.0, default=0.0),
        sun_ring_phase_deg=r.number(raw, "sun_ring_phase_deg", f + "sun_ring_phase_deg",
                                    default=0.0),
        stage_phase_deg=r.number(raw, "stage_phase_deg", f + "stage_phase_deg", default=0.0),
        transmission_error=_transmission_error(r, raw, f),
        inertia=Inertia(**{
            k: r.number(inertia, k, f"{f}inertia.{k}", low=0.0, strict=True)
            for k in ("sun", "ring", "carrier", "planet")
        }),
        planet_mass=r.number(raw, "planet_mass", f + "planet_mass", low=0.0, strict=True),
        geometry=geometry,
        **_translational_keys(r, raw, f, model),
    )
    if geometry is None:
        return stage
    check_tooth_geometry(stage, r.source)  # before any stiffness is derived from it
    return with_geometric_stiffness(stage) if derived else stage


def _translational_keys(r: TomlReader, raw, f: str, model: str) -> dict:
    """``mass``, ``bearing_stiffness`` (required by the translational model; kept and
    written back, but unused, by the torsional one), ``bearing_damping_ratio``,
    ``base_diameter_mm`` and ``planet_position_error_um``, as ``Stage`` keywords."""
    out = {}
    for key, cls, names, low, strict in (
            ("mass", CentralMass, MEMBERS, 0.0, True),
            ("bearing_stiffness", BearingStiffness, (*MEMBERS, "planet"), 0.0, False),
            ("base_diameter_mm", PerGear, _GEARS, 0.0, True)):
        if key not in raw:
            if model == "translational" and key != "base_diameter_mm":
                raise r.fail(f + key, None, 'is required when model = "translational" '
                             f"(a table {{ {', '.join(names)} }})")
            continue
        table = r.sub(raw, key, f + key, set(names))
        out[key] = cls(**{k: r.number(table, k, f"{f}{key}.{k}", low=low, strict=strict)
                          for k in names})
    if "bearing_damping_ratio" in raw:
        out["bearing_damping_ratio"] = r.number(raw, "bearing_damping_ratio",
                                                f + "bearing_damping_ratio", low=0.0)
    if "planet_position_error_um" in raw:
        out["planet_position_error_um"] = _planet_errors(r, raw, f, model)
    return out


def _planet_errors(r: TomlReader, raw, f: str, model: str) -> PlanetErrors:
    """``planet_position_error_um = { tangential = [...], radial = [...] }``: one number
    per planet each (um), a missing list all zeros; radial errors in the translational
    model only (the torsional one takes the tangential errors as mean transmission
    errors and has no radial freedom for the others)."""
    key = f + "planet_position_error_um"
    table = r.sub(raw, "planet_position_error_um", key, {"tangential", "radial"})
    n = len(raw.get("planet_angles_deg", []))
    lists = {}
    for d in ("tangential", "radial"):
        v = r.vector(table, d, f"{key}.{d}") if d in table else np.zeros(n)
        if v.size != n:
            raise r.fail(f"{key}.{d}", v.tolist(),
                         f"needs one error per planet ({n}, as planet_angles_deg)")
        lists[d] = jnp.asarray(v)
    if model != "translational" and np.any(np.asarray(lists["radial"]) != 0):
        raise r.fail(f"{key}.radial", np.asarray(lists["radial"]).tolist(),
                     'radial pin errors need model = "translational" (its planets move '
                     "radially); the torsional model takes tangential errors only")
    return PlanetErrors(**lists)


def _geometry(r: TomlReader, raw, f: str, teeth: Teeth, module, pressure) -> ToothGeometry | None:
    """The tooth geometry, or ``None`` without ``face_width_mm``."""
    others = [k for k in (*_GEOMETRY_DEFAULTS, "profile_shift", "tip_relief") if k in raw]
    if "face_width_mm" not in raw:
        if others:
            raise r.fail(f + others[0], raw[others[0]],
                         "tooth geometry needs face_width_mm in the same stage")
        return None
    given = [k for k in ("contact_ratio", "mesh_stiffness") if k in raw]
    if len(given) == 1:
        missing = ({"contact_ratio", "mesh_stiffness"} - set(given)).pop()
        raise r.fail(f + missing, None,
                     f"is required with {given[0]} (both are then used, the geometry only "
                     "checked), or leave out both to derive them from the geometry")
    width = r.number(raw, "face_width_mm", f + "face_width_mm", low=0.0, strict=True)
    shift = raw.get("profile_shift", {})
    r.table(shift, f + "profile_shift")
    r.keys(shift, set(_GEARS), f + "profile_shift")
    coef = {k: r.number(raw, k, f + k, default=v, low=0.0, strict=k != "root_radius_coefficient")
            for k, v in _GEOMETRY_DEFAULTS.items() if k != "poisson_ratio"}
    nu = r.number(raw, "poisson_ratio", f + "poisson_ratio", default=0.3, low=0.0)
    if not float(nu) < 0.5:
        raise r.fail(f + "poisson_ratio", float(nu), "must be below 0.5")
    amounts, starts = _tip_relief(r, raw, f, teeth, module, pressure)
    return ToothGeometry(
        face_width_mm=width,
        profile_shift=PerGear(**{g: r.number(shift, g, f"{f}profile_shift.{g}", default=0.0)
                                 for g in _GEARS}),
        addendum=coef["addendum_coefficient"],
        dedendum=coef["dedendum_coefficient"],
        root_radius=coef["root_radius_coefficient"],
        youngs_modulus=coef["youngs_modulus"],
        poisson_ratio=nu,
        tip_relief=TipRelief(amount_um=PerGear(**amounts), start_diameter_mm=PerGear(**starts)),
        derives_stiffness=not given,
        relieved=any(float(a) > 0 for a in amounts.values()),
    )


def _tip_relief(r: TomlReader, raw, f: str, teeth: Teeth, module, pressure):
    """Relief amount (um) and start diameter (mm) per gear; a start given as a roll
    angle ``xi`` (deg) is the diameter ``d_b sqrt(1 + xi^2)``."""
    table = raw.get("tip_relief", {})
    r.table(table, f + "tip_relief")
    r.keys(table, set(_GEARS), f + "tip_relief")
    amounts, starts = {}, {}
    for g in _GEARS:
        entry = table.get(g, {})
        field = f"{f}tip_relief.{g}"
        r.table(entry, field)
        r.keys(entry, {"amount_um", "start_diameter_mm", "start_roll_deg"}, field)
        amounts[g] = r.number(entry, "amount_um", field + ".amount_um", default=0.0, low=0.0)
        base = float(module) * getattr(teeth, g) * math.cos(math.radians(float(pressure)))
        ways = [k for k in ("start_diameter_mm", "start_roll_deg") if k in entry]
        if len(ways) == 2:
            raise r.fail(field + ".start_roll_deg", entry["start_roll_deg"],
                         "give the start as start_diameter_mm or start_roll_deg, not both")
        if not ways and float(amounts[g]) > 0:
            raise r.fail(field + ".start_diameter_mm", None,
                         "is required with amount_um (or start_roll_deg)")
        if not ways:
            starts[g] = jnp.asarray(base)
        elif ways[0] == "start_diameter_mm":
            starts[g] = r.number(entry, "start_diameter_mm", field + ".start_diameter_mm",
                                 low=0.0, strict=True)
        else:
            roll = r.number(entry, "start_roll_deg", field + ".start_roll_deg", low=0.0)
            starts[g] = jnp.asarray(base * math.sqrt(1.0 + math.radians(float(roll)) ** 2))
    return amounts, starts


def with_geometric_stiffness(stage: Stage) -> Stage:
    """``stage`` with ``contact_ratio`` and ``mesh_stiffness`` set to the values its
    tooth geometry gives (unloaded mean stiffness, geometric contact ratio)."""
    (k_s, c_s), (k_r, c_r) = (geometric_stiffness(stage, side) for side in ("sun", "ring"))
    return eqx.tree_at(lambda s: (s.contact_ratio, s.mesh_stiffness), stage,
                       (SunRing(sun=c_s, ring=c_r), SunRing(sun=k_s, ring=k_r)))


def _transmission_error(r: TomlReader, raw, f: str) -> TransmissionError:
    te = raw.get("transmission_error", {})
    r.table(te, f + "transmission_error")
    r.keys(te, {"sun", "ring"}, f + "transmission_error")
    sides = {}
    for side in ("sun", "ring"):
        rows = r.matrix(te, side, f"{f}transmission_error.{side}", 2,
                        "one [amplitude_m, phase_deg] pair per mesh harmonic")
        if np.any(rows[:, 0] < 0):
            raise r.fail(f"{f}transmission_error.{side}", rows.tolist(),
                         "amplitudes must be >= 0 (use the phase for sign)")
        sides[side] = jnp.asarray(rows)
    return TransmissionError(**sides)


def _coupling(r: TomlReader, raw, i: int) -> Coupling:
    f = f"couplings[{i}]"
    r.table(raw, f)
    r.keys(raw, _COUPLING_KEYS, f)
    members = raw.get("members")
    if (not isinstance(members, list) or len(members) != 2
            or not all(isinstance(m, str) for m in members)):
        raise r.fail(f + ".members", members, "two member paths such as \"1.carrier\" are required")
    cid = raw.get("id")
    if cid is not None and not isinstance(cid, str):
        raise r.fail(f + ".id", cid, "must be a string")
    gears = raw.get("gears")
    if gears is not None:
        if not isinstance(gears, list) or not all(isinstance(g, str) for g in gears):
            raise r.fail(f + ".gears", gears, "must be a list of gear names")
        gears = tuple(gears)
    return Coupling(  # damping and damping_ratio together: refused by check_ranges
        members=(members[0], members[1]),
        stiffness=r.number(raw, "stiffness", f + ".stiffness", low=0.0),
        id=cid,
        gears=gears,
        **{k: r.number(raw, k, f"{f}.{k}", low=0.0) for k in _DAMPER_KEYS if k in raw},
    )


def _gear(r: TomlReader, name: str, raw) -> Gear:
    f = f"gears.{name}"
    r.table(raw, f)
    r.keys(raw, _GEAR_KEYS, f)
    paths = {}
    for key in ("input", "output"):
        value = raw.get(key)
        if not isinstance(value, str):
            raise r.fail(f"{f}.{key}", value, "a member path such as \"1.sun\" is required")
        paths[key] = value
    brakes = raw.get("brakes", [])
    if not isinstance(brakes, list) or not all(isinstance(b, str) for b in brakes):
        raise r.fail(f + ".brakes", brakes, "must be a list of member paths")
    ripple = r.matrix(raw, "input_torque_ripple", f + ".input_torque_ripple", 3,
                      "rows [amplitude_Nm, phase_deg, order]")
    if np.any(ripple[:, 2] <= 0):
        raise r.fail(f + ".input_torque_ripple", ripple.tolist(),
                     "orders (third column) must be > 0")
    note = raw.get("note")
    if note is not None and not isinstance(note, str):
        raise r.fail(f + ".note", note, "must be a string")
    return Gear(
        name=name,
        input=paths["input"],
        output=paths["output"],
        brakes=tuple(brakes),
        input_torque=r.number(raw, "input_torque", f + ".input_torque"),
        input_torque_ripple=jnp.asarray(ripple[:, :2]),
        drag_torque=r.number(raw, "drag_torque", f + ".drag_torque", default=0.0, low=0.0),
        ripple_orders=tuple(float(o) for o in ripple[:, 2]),
        note=note,
        input_rpm=(float(r.number(raw, "input_rpm", f + ".input_rpm", low=0.0, strict=True))
                   if "input_rpm" in raw else None),
    )


# --------------------------------------------------------------------------- writing

def train_to_dict(train: Train) -> dict:
    """The train as a TOML-ready dict (inverse of :func:`train_from_dict`)."""
    out: dict = {
        "name": train.name,
        "model": train.model,
        "stiffness_harmonics": train.stiffness_harmonics,
        "phasing": train.phasing,
        "mesh_damping": train.mesh_damping,
    }
    stages = []
    for s in train.stages:
        d = {
            "id": s.id,
            "teeth": {"sun": s.teeth.sun, "planet": s.teeth.planet, "ring": s.teeth.ring},
            "module_mm": _f(s.module_mm),
            "pressure_angle_deg": _f(s.pressure_angle_deg),
            "planet_angles_deg": [_f(a) for a in np.asarray(s.planet_angles_deg)],
        }
        if s.carrier_radius_mm is not None:
            d["carrier_radius_mm"] = _f(s.carrier_radius_mm)
        for key in ("half_backlash",) if s.stiffness_from_geometry else ("contact_ratio", "mesh_stiffness",
                                                       "half_backlash"):
            pair = getattr(s, key)
            d[key] = {"sun": _f(pair.sun), "ring": _f(pair.ring)}
        if s.geometry is not None:
            d.update(_geometry_dict(s.geometry))
        d["mesh_damping_ratio"] = _f(s.mesh_damping_ratio)
        d["sun_ring_phase_deg"] = _f(s.sun_ring_phase_deg)
        d["stage_phase_deg"] = _f(s.stage_phase_deg)
        te = {side: [[_f(v) for v in row] for row in np.asarray(getattr(s.transmission_error, side))]
              for side in ("sun", "ring")}
        te = {k: v for k, v in te.items() if v}
        if te:
            d["transmission_error"] = te
        d["inertia"] = {k: _f(getattr(s.inertia, k)) for k in ("sun", "ring", "carrier", "planet")}
        d["planet_mass"] = _f(s.planet_mass)
        for key, names in (("mass", MEMBERS), ("bearing_stiffness", (*MEMBERS, "planet")),
                           ("base_diameter_mm", _GEARS)):
            if getattr(s, key) is not None:
                d[key] = {k: _f(getattr(getattr(s, key), k)) for k in names}
        if s.bearing_damping_ratio is not None:
            d["bearing_damping_ratio"] = _f(s.bearing_damping_ratio)
        if s.planet_position_error_um is not None:
            d["planet_position_error_um"] = {
                k: [_f(v) for v in np.asarray(getattr(s.planet_position_error_um, k))]
                for k in ("tangential", "radial")}
        stages.append(d)
    out["stages"] = stages
    couplings = []
    for c in train.couplings:
        d = {}
        if c.id is not None:
            d["id"] = c.id
        d["members"] = list(c.members)
        d["stiffness"] = _f(c.stiffness)
        d.update({k: _f(getattr(c, k)) for k in _DAMPER_KEYS if getattr(c, k) is not None})
        if c.gears is not None:
            d["gears"] = list(c.gears)
        couplings.append(d)
    if couplings:
        out["couplings"] = couplings
    out["housing"] = {"braked": _f(train.housing.braked), "free": _f(train.housing.free)}
    gears = {}
    for g in train.gears:
        d = {"input": g.input, "output": g.output, "brakes": list(g.brakes),
             "input_torque": _f(g.input_torque)}
        ripple = np.asarray(g.input_torque_ripple)
        if ripple.size:
            d["input_torque_ripple"] = [[_f(a), _f(ph), float(o)]
                                        for (a, ph), o in zip(ripple, g.ripple_orders)]
        d["drag_torque"] = _f(g.drag_torque)
        if g.input_rpm is not None:
            d["input_rpm"] = g.input_rpm
        if g.note is not None:
            d["note"] = g.note
        gears[g.name] = d
    out["gears"] = gears
    return out


def _geometry_dict(geo: ToothGeometry) -> dict:
    d = {"face_width_mm": _f(geo.face_width_mm),
         "profile_shift": {g: _f(getattr(geo.profile_shift, g)) for g in _GEARS}}
    for key, value in zip(_GEOMETRY_DEFAULTS, (geo.addendum, geo.dedendum, geo.root_radius,
                                                geo.youngs_modulus, geo.poisson_ratio)):
        d[key] = _f(value)
    relief = {g: {"amount_um": _f(getattr(geo.tip_relief.amount_um, g)),
                  "start_diameter_mm": _f(getattr(geo.tip_relief.start_diameter_mm, g))}
              for g in _GEARS if _f(getattr(geo.tip_relief.amount_um, g)) > 0}
    if relief:
        d["tip_relief"] = relief
    return d


def dumps_train(train: Train) -> str:
    """TOML text of a train; :func:`loads_train` reads it back to the same values."""
    header = f"# {train.name}\n# written by gearjax; SI units unless a key's suffix says otherwise\n\n"
    return header + tomli_w.dumps(train_to_dict(train))


def save_train(train: Train, path: str | Path) -> None:
    """Write ``train`` as a train file at ``path``."""
    Path(path).write_text(dumps_train(train))


def _f(x) -> float:
    return float(np.asarray(x))
