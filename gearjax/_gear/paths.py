"""TOML paths to the continuous parameters of a train: look up, replace, list.

A path names one scalar leaf of a :class:`Train` with the train-file keys
(interface.md), so a user writes on the command line what they see in the file:

- ``STAGE.KEY`` for a stage scalar: ``module_mm``, ``pressure_angle_deg``,
  ``carrier_radius_mm`` (only when the file sets it), ``mesh_damping_ratio``,
  ``sun_ring_phase_deg``, ``stage_phase_deg``, ``planet_mass``;
- ``STAGE.KEY.SIDE`` for ``contact_ratio``, ``mesh_stiffness``, ``half_backlash``
  (SIDE = ``sun`` | ``ring``) and ``inertia`` (``sun`` | ``ring`` | ``carrier`` |
  ``planet``);
- for a stage whose stiffness comes from its tooth geometry (``face_width_mm`` without
  ``mesh_stiffness`` and ``contact_ratio``), ``STAGE.face_width_mm``,
  ``STAGE.profile_shift.GEAR`` (GEAR = ``sun`` | ``planet`` | ``ring``) and the
  coefficients ``addendum_coefficient``, ``dedendum_coefficient``,
  ``root_radius_coefficient``, ``youngs_modulus``, ``poisson_ratio`` instead of
  ``contact_ratio`` and ``mesh_stiffness``;
- where the stage gives them (the translational model): ``STAGE.mass.MEMBER``,
  ``STAGE.bearing_stiffness.MEMBER`` (MEMBER also ``planet``),
  ``STAGE.base_diameter_mm.GEAR``, ``STAGE.bearing_damping_ratio`` and
  ``STAGE.planet_position_error_um.tangential.I`` (or ``radial``; ``I`` 1-based);
- ``STAGE.planet_angles_deg.I`` for the angle of planet ``I``, **1-based** as in
  "planet 2" of the messages and mesh names (``1.sp2``); planet 1 is the reference at
  0 deg and is not a parameter;
- ``housing.braked``, ``housing.free``;
- ``couplings.ID.stiffness`` (by the coupling's ``id``) or ``couplings.K.stiffness``
  (``K`` its 0-based position in the file; an ``id`` wins when both match), and
  ``couplings.ID.damping`` or ``couplings.ID.damping_ratio``, whichever the file gives
  (only then);
- ``gears.NAME.input_torque``, ``gears.NAME.drag_torque``.

``STAGE`` is a stage id; stage ids are matched before the words ``housing``,
``couplings`` and ``gears``. Structural values (teeth, ids, member paths, options)
and tables (``transmission_error``, ``input_torque_ripple``) are not paths.
A path that names nothing continuous raises ``TrainError`` with one line naming the
path and what is valid at the point where it went wrong.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._errors import bad_argument
from .kinematics import kinematics
from .train import Train, member_paths

STAGE_SCALARS = ("module_mm", "pressure_angle_deg", "carrier_radius_mm", "mesh_damping_ratio",
                 "sun_ring_phase_deg", "stage_phase_deg", "planet_mass")
"""Stage keys that are one number each."""

STAGE_TABLES = {
    "contact_ratio": ("sun", "ring"),
    "mesh_stiffness": ("sun", "ring"),
    "half_backlash": ("sun", "ring"),
    "inertia": ("sun", "ring", "carrier", "planet"),
}
"""Stage keys that are tables of numbers, with their sub-keys."""

OPTIONAL_TABLES = {
    "mass": ("sun", "ring", "carrier"),
    "bearing_stiffness": ("sun", "ring", "carrier", "planet"),
    "base_diameter_mm": ("sun", "planet", "ring"),
}
"""Stage tables a file may give (the translational model's), with their sub-keys."""

GEOMETRY_SCALARS = {"face_width_mm": "face_width_mm", "addendum_coefficient": "addendum",
                    "dedendum_coefficient": "dedendum",
                    "root_radius_coefficient": "root_radius",
                    "youngs_modulus": "youngs_modulus", "poisson_ratio": "poisson_ratio"}
"""Tooth-geometry keys that are one number each, and their field in ``ToothGeometry``."""

GEARS = ("sun", "planet", "ring")

_STAGE_NOT_CONTINUOUS = {
    "id": "the stage id is a name",
    "teeth": "tooth counts are integers (structure), not continuous parameters",
    "transmission_error": "transmission_error is a table of harmonics, not one number",
}
HOUSING_KEYS = ("braked", "free")
COUPLING_KEYS = ("stiffness", "damping", "damping_ratio")
GEAR_KEYS = ("input_torque", "drag_torque")
_SECTIONS = ("housing", "couplings", "gears")


@dataclasses.dataclass(frozen=True)
class Leaf:
    """Where a path points in a train.

    **Fields:** ``path``: the canonical spelling (coupling by id when it has one);
    ``where``: ``Train -> array leaf``, usable as ``equinox.tree_at(where, ...)``;
    ``index``: the element of that leaf (a planet angle), ``None`` for a scalar leaf.
    """

    path: str
    where: Callable[[Train], Array]
    index: int | None = None


def leaf_selector(train: Train, path: str, argument: str = "path") -> Leaf:
    """Resolve ``path`` in ``train``.

    **Arguments:** ``argument`` names the caller's argument the path came from, for the
    message (``free`` in ``calibrate``, ``vary`` in ``optimize``).

    **Raises:** ``ArgumentError`` (a ``TrainError``) naming ``argument`` when the path
    names no continuous scalar of the train.
    """
    if not isinstance(path, str) or not path:
        raise bad_argument(argument, path, "a TOML path such as '1.inertia.sun' is required")
    parts = path.split(".")
    head = parts[0]

    def bad(rule: str):
        return bad_argument(argument, path, rule)

    ids = train.stage_ids
    if head in ids:
        return _stage_leaf(train, ids.index(head), parts, bad)
    if head == "housing":
        if len(parts) != 2 or parts[1] not in HOUSING_KEYS:
            raise bad("housing paths are housing.braked and housing.free")
        return Leaf(path, _getter(("housing", parts[1])))
    if head == "couplings":
        return _coupling_leaf(train, parts, bad)
    if head == "gears":
        return _gear_leaf(train, parts, bad)
    raise bad(f"no stage or section {head!r}; a path starts with a stage id "
              f"({', '.join(ids)}), housing, couplings or gears")


def continuous_paths(train: Train, gear: str | None = None, *, linear: bool = False
                     ) -> list[str]:
    """Every continuous scalar path of ``train`` in file order (canonical spellings).

    Couplings appear by ``id`` when they have one, else by 0-based position, with their
    damper key where the file gives one; ``carrier_radius_mm`` only where the file sets
    it; planet angles from planet 2.

    With ``gear``, only the paths that change that gear's assembled system: not the
    other gears' torques, not clutches that gear leaves open, not ``housing.braked``
    in a gear without brakes (``housing.free`` where every member is braked), not the
    stiffness harmonics and phasing (contact ratios, planet angles, sun-ring and stage
    phases) of a stage that does not turn in it, not a ``drag_torque`` that acts on no
    member (every member the input, output, braked or at rest), and with ``linear``
    (no backlash) not the backlash.
    """
    keep = (lambda path: True) if gear is None else _affects(train, gear, linear)
    out = []
    for s in train.stages:
        f = f"{s.id}."
        for key in ("module_mm", "pressure_angle_deg", "carrier_radius_mm"):
            if getattr(s, key) is not None:
                out.append(f + key)
        if s.stiffness_from_geometry:
            out += [f + key for key in GEOMETRY_SCALARS]
            out += [f"{f}profile_shift.{g}" for g in GEARS]
        else:
            out += [f"{f}contact_ratio.{k}" for k in STAGE_TABLES["contact_ratio"]]
            out += [f"{f}mesh_stiffness.{k}" for k in STAGE_TABLES["mesh_stiffness"]]
        out.append(f + "mesh_damping_ratio")
        out += [f"{f}half_backlash.{k}" for k in STAGE_TABLES["half_backlash"]]
        out += [f + "sun_ring_phase_deg", f + "stage_phase_deg"]
        out += [f"{f}planet_angles_deg.{i}" for i in range(2, s.n_planets + 1)]
        out += [f"{f}inertia.{k}" for k in STAGE_TABLES["inertia"]]
        out.append(f + "planet_mass")
        out += _optional_paths(s) if train.translational else []
    for k, c in enumerate(train.couplings):
        out += [f"couplings.{c.id if c.id is not None else k}.{key}"
                for key in COUPLING_KEYS if getattr(c, key) is not None]
    out += [f"housing.{k}" for k in HOUSING_KEYS]
    out += [f"gears.{g.name}.{k}" for g in train.gears for k in GEAR_KEYS]
    return [p for p in out if keep(p)]


def _affects(train: Train, gear: str, linear: bool) -> Callable[[str], bool]:
    """``path -> bool``: whether ``path`` enters the assembled system of ``gear``."""

    g = train.gear(gear)
    kin = kinematics(train, g.name)
    still = {s.id for s in kin.stages if not s.turning}
    open_ = {f"couplings.{c.id if c.id is not None else k}.{key}"
             for k, c in enumerate(train.couplings) if not c.engaged(g.name)
             for key in COUPLING_KEYS}
    members = member_paths(train)
    dragged = any(kin.speeds.get(p, 0) != 0 and p not in (g.input, g.output)
                  and p not in g.brakes for p in members)
    phasing = ("contact_ratio", "sun_ring_phase_deg", "stage_phase_deg", "planet_angles_deg",
               "profile_shift", *GEOMETRY_SCALARS)

    def keep(path: str) -> bool:
        parts = path.split(".")
        if parts[0] == "gears":
            return parts[1] == g.name and (parts[2] != "drag_torque" or dragged)
        if path in open_:
            return False
        if path == "housing.braked":
            return bool(g.brakes)
        if path == "housing.free":
            return len(set(g.brakes)) < len(members)
        if parts[0] in still and parts[1] in phasing:
            return False
        if linear and parts[1:2] == ["half_backlash"]:
            return False
        return True

    return keep


def get_path(train: Train, path: str, argument: str = "path") -> Float[Array, ""]:
    """The value of ``path`` in ``train``, a scalar array in the file's unit."""
    leaf = leaf_selector(train, path, argument)
    value = jnp.asarray(leaf.where(train))
    return value if leaf.index is None else value[leaf.index]


def set_path(train: Train, path: str, value: ArrayLike, argument: str = "path") -> Train:
    """A copy of ``train`` with ``path`` set to ``value`` (a scalar in the file's unit).

    Pure: ``value`` may be a tracer, so ``jax.grad`` and ``jax.jit`` pass through.
    No value rule is checked here (``validate_train`` checks whole trains).
    """
    return set_leaf(train, leaf_selector(train, path, argument), value)


def set_leaf(train: Train, leaf: Leaf, value: ArrayLike) -> Train:
    """:func:`set_path` for a resolved :class:`Leaf` (no path parsing)."""
    value = jnp.asarray(value)
    if value.shape != ():
        raise ValueError(f"set_path({leaf.path!r}): a scalar value is required, got shape "
                         f"{value.shape}")
    old = jnp.asarray(leaf.where(train))
    value = value.astype(jnp.result_type(old.dtype, value.dtype))
    new = value if leaf.index is None else old.astype(value.dtype).at[leaf.index].set(value)
    return eqx.tree_at(leaf.where, train, new)


# --------------------------------------------------------------------------- resolution


def _getter(steps: tuple) -> Callable[[Train], Array]:
    """``train -> train.a[k].b...`` for steps that are attribute names or tuple indices."""

    def where(train):
        node = train
        for step in steps:
            node = node[step] if isinstance(step, int) else getattr(node, step)
        return node

    return where


def _optional_paths(s) -> list[str]:
    """The translational keys that stage ``s`` gives, as paths."""
    f = f"{s.id}."
    out = [f"{f}{key}.{sub}" for key, subs in OPTIONAL_TABLES.items()
           if getattr(s, key) is not None for sub in subs]
    if s.bearing_damping_ratio is not None:
        out.append(f + "bearing_damping_ratio")
    if s.planet_position_error_um is not None:
        out += [f"{f}planet_position_error_um.{d}.{i}" for d in ("tangential", "radial")
                for i in range(1, s.n_planets + 1)]
    return out


def _optional_leaf(s, k: int, parts: list[str], bad) -> Leaf:
    """A path into a translational key of stage ``s`` (``k`` its position)."""
    key, path = parts[1], ".".join(parts)
    if getattr(s, key) is None:
        raise bad(f"stage {s.id!r} does not set {key}; set it in the train file to vary it")
    if key == "bearing_damping_ratio":
        if len(parts) != 2:
            raise bad(f"{s.id}.{key} is one number; write the path as {s.id}.{key}")
        return Leaf(path, _getter(("stages", k, key)))
    if key == "planet_position_error_um":
        valid = (f"{s.id}.{key}.tangential.I or .radial.I with planet I = 1..{s.n_planets}")
        if (len(parts) != 4 or parts[2] not in ("tangential", "radial")
                or not parts[3].isdigit() or not 1 <= int(parts[3]) <= s.n_planets):
            raise bad(f"name one planet's error: {valid}")
        return Leaf(path, _getter(("stages", k, key, parts[2])), index=int(parts[3]) - 1)
    subs = OPTIONAL_TABLES[key]
    if len(parts) != 3 or parts[2] not in subs:
        raise bad(f"{s.id}.{key} has sub-keys {', '.join(subs)} (e.g. {s.id}.{key}.{subs[0]})")
    return Leaf(path, _getter(("stages", k, key, parts[2])))


def _stage_leaf(train: Train, k: int, parts: list[str], bad) -> Leaf:
    s = train.stages[k]
    path = ".".join(parts)
    keys = ", ".join(STAGE_SCALARS + tuple(STAGE_TABLES) + ("planet_angles_deg",))
    if len(parts) < 2:
        raise bad(f"name a key of stage {s.id!r}: {keys}")
    key = parts[1]
    if key in GEOMETRY_SCALARS or key == "profile_shift":
        return _geometry_leaf(s, k, parts, bad)
    if key in OPTIONAL_TABLES or key in ("bearing_damping_ratio", "planet_position_error_um"):
        return _optional_leaf(s, k, parts, bad)
    if key in ("contact_ratio", "mesh_stiffness") and s.stiffness_from_geometry:
        raise bad(f"stage {s.id!r} derives {key} from its tooth geometry; vary "
                  f"{s.id}.face_width_mm or {s.id}.profile_shift.sun|planet|ring instead")
    if key in STAGE_SCALARS:
        if len(parts) != 2:
            raise bad(f"{s.id}.{key} is one number; write the path as {s.id}.{key}")
        if key == "carrier_radius_mm" and s.carrier_radius_mm is None:
            raise bad(f"stage {s.id!r} does not set carrier_radius_mm (the default "
                      "module (Z_s + Z_p) / 2 applies); set it in the train file to vary it")
        return Leaf(path, _getter(("stages", k, key)))
    if key in STAGE_TABLES:
        subs = STAGE_TABLES[key]
        if len(parts) != 3 or parts[2] not in subs:
            what = f"no {parts[2]!r}; it has" if len(parts) == 3 else "sub-keys"
            raise bad(f"{s.id}.{key} has {what} {', '.join(subs)} (e.g. {s.id}.{key}.{subs[0]})")
        return Leaf(path, _getter(("stages", k, key, parts[2])))
    if key == "planet_angles_deg":
        n = s.n_planets
        if n < 2:
            raise bad(f"stage {s.id!r} has one planet, at the reference angle 0: no planet angle "
                      "is a parameter")
        valid = f"{s.id}.planet_angles_deg.I with planet I = 2..{n} (1-based, planet 1 is at 0)"
        if len(parts) != 3 or not parts[2].isdigit():
            raise bad(f"name one planet: {valid}")
        i = int(parts[2])
        if i == 1:
            raise bad(f"planet 1 is the reference at 0 deg, not a parameter; {valid}")
        if not 2 <= i <= n:
            raise bad(f"stage {s.id!r} has {n} planets; {valid}")
        return Leaf(f"{s.id}.planet_angles_deg.{i}", _getter(("stages", k, key)), index=i - 1)
    if key.startswith("planet_angles_deg["):
        raise bad(f"write one planet angle as {s.id}.planet_angles_deg.I with the planet number "
                  f"I = 2..{s.n_planets} (1-based), not with brackets")
    if key in _STAGE_NOT_CONTINUOUS:
        raise bad(f"{_STAGE_NOT_CONTINUOUS[key]}; continuous keys of a stage are {keys}")
    raise bad(f"stage {s.id!r} has no key {key!r}; continuous keys of a stage are {keys}")


def _geometry_leaf(s, k: int, parts: list[str], bad) -> Leaf:
    key = parts[1]
    if s.geometry is None:
        raise bad(f"stage {s.id!r} has no tooth geometry (it sets no face_width_mm)")
    if not s.geometry.derives_stiffness:
        raise bad(f"stage {s.id!r} gives mesh_stiffness and contact_ratio, so its tooth "
                  "geometry is only checked and changes nothing")
    if key == "profile_shift":
        if len(parts) != 3 or parts[2] not in GEARS:
            raise bad(f"{s.id}.profile_shift has sub-keys {', '.join(GEARS)} "
                      f"(e.g. {s.id}.profile_shift.sun)")
        return Leaf(".".join(parts), _getter(("stages", k, "geometry", "profile_shift",
                                              parts[2])))
    if len(parts) != 2:
        raise bad(f"{s.id}.{key} is one number; write the path as {s.id}.{key}")
    return Leaf(".".join(parts), _getter(("stages", k, "geometry", GEOMETRY_SCALARS[key])))


def _coupling_leaf(train: Train, parts: list[str], bad) -> Leaf:
    names = [c.id if c.id is not None else str(k) for k, c in enumerate(train.couplings)]
    valid = "the train has no couplings"
    if names:
        valid = (f"couplings.ID.KEY or couplings.K.KEY (K = 0..{len(names) - 1}, file order); "
                 f"couplings are {', '.join(names)}")
    if len(parts) < 3 or parts[-1] not in COUPLING_KEYS:
        raise bad(f"a coupling's parameters are stiffness, and damping or damping_ratio where "
                  f"the file gives one (KEY): {valid}")
    key = parts[-1]
    name = ".".join(parts[1:-1])
    ids = [c.id for c in train.couplings]
    if name in ids:
        k = ids.index(name)
    elif name.isdigit() and int(name) < len(ids):
        k = int(name)
    else:
        raise bad(f"no coupling {name!r}; {valid}")
    c = train.couplings[k]
    canonical = f"couplings.{c.id if c.id is not None else k}.{key}"
    if getattr(c, key) is None:
        given = [x for x in ("damping", "damping_ratio") if getattr(c, x) is not None]
        raise bad(f"coupling {c.label!r} gives its damper as {given[0]}, not {key}: vary "
                  f"{canonical.rpartition('.')[0]}.{given[0]}" if given else
                  f"coupling {c.label!r} has no damper; set damping (N m s/rad) or "
                  "damping_ratio in the train file (0 is allowed) to vary it")
    return Leaf(canonical, _getter(("couplings", k, key)))


def _gear_leaf(train: Train, parts: list[str], bad) -> Leaf:
    gears = train.gear_names
    valid = f"gears.NAME.{'|'.join(GEAR_KEYS)} with NAME in {', '.join(gears)}"
    if len(parts) < 3 or parts[-1] not in GEAR_KEYS:
        raise bad(f"continuous gear keys are {', '.join(GEAR_KEYS)}: {valid}")
    name = ".".join(parts[1:-1])
    if name not in gears:
        raise bad(f"no gear {name!r}; {valid}")
    return Leaf(".".join(parts), _getter(("gears", gears.index(name), parts[-1])))
