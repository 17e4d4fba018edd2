"""Train parameters: the train file's values as equinox modules.

Field names and units mirror the train-file keys of interface.md (so a TOML path
such as ``1.inertia.sun`` or ``2.module_mm`` names a field), which keeps the
loader, the writer and the path lookup one-to-one. Every physical value is an
array field (traced by ``jit``, ``vmap`` and ``grad``); structural values (teeth,
ids, member paths, option strings) are static. Conversion to SI and radians
happens once, in assembly.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._errors import bad_argument

MEMBERS = ("sun", "ring", "carrier")
"""Central members of a stage, in the order of their coordinates."""

MODELS = ("torsional", "translational")
"""Stage models (model.md): rotations only, or Lin & Parker's translational-rotational."""


class Teeth(eqx.Module):
    """Tooth counts of one stage (static integers)."""

    sun: int = eqx.field(static=True)
    planet: int = eqx.field(static=True)
    ring: int = eqx.field(static=True)


class SunRing(eqx.Module):
    """A value per mesh side of a stage: sun-planet and ring-planet."""

    sun: Float[Array, "*batch"]
    ring: Float[Array, "*batch"]


class TransmissionError(eqx.Module):
    """Transmission-error harmonics per mesh side.

    **Fields:** ``sun``, ``ring``: shape ``(H_e, 2)``, each row ``(amplitude [m],
    phase [deg])`` of harmonic ``h = row + 1`` of the stage mesh frequency. Zero rows
    mean no excitation.
    """

    sun: Float[Array, "H 2"]
    ring: Float[Array, "H 2"]


class Inertia(eqx.Module):
    """Polar moments of inertia (kg m^2) of a stage's members; ``planet`` is one planet."""

    sun: Float[Array, ""]
    ring: Float[Array, ""]
    carrier: Float[Array, ""]
    planet: Float[Array, ""]


class PerGear(eqx.Module):
    """A value per gear of a stage: sun, planet, ring."""

    sun: Float[Array, ""]
    planet: Float[Array, ""]
    ring: Float[Array, ""]


class CentralMass(eqx.Module):
    """Masses (kg) of a stage's central members, for their translations (translational
    model; a planet's is ``Stage.planet_mass``)."""

    sun: Float[Array, ""]
    ring: Float[Array, ""]
    carrier: Float[Array, ""]


class BearingStiffness(eqx.Module):
    """Bearing stiffness (N/m, the same in each direction) of a stage's sun, ring and
    carrier bearings and of each planet pin (translational model). 0: the member floats,
    held only by its meshes."""

    sun: Float[Array, ""]
    ring: Float[Array, ""]
    carrier: Float[Array, ""]
    planet: Float[Array, ""]


class PlanetErrors(eqx.Module):
    """Pin position errors (um) of a stage's planets, one per planet in file order:
    ``tangential`` (along the carrier's positive rotation) and ``radial`` (outward)
    displacement of each pin from its nominal place (translational model)."""

    tangential: Float[Array, " N"]
    radial: Float[Array, " N"]


class TipRelief(eqx.Module):
    """Linear tip relief per gear: ``amount_um`` (um) at the tip, growing linearly in
    roll angle from the diameter ``start_diameter_mm`` (mm) to the tip. An amount of 0
    means no relief on that gear.
    """

    amount_um: PerGear
    start_diameter_mm: PerGear


class ToothGeometry(eqx.Module):
    """The tooth geometry of a stage's gears (train-file keys ``face_width_mm``,
    ``profile_shift``, ``addendum_coefficient``, ``dedendum_coefficient``,
    ``root_radius_coefficient``, ``youngs_modulus``, ``poisson_ratio``, ``tip_relief``).

    Coefficients are of the module (ISO 53 basic rack: 1.0, 1.25, 0.38); the modulus is
    in Pa. ``derives_stiffness`` (static): the file gives neither ``mesh_stiffness`` nor
    ``contact_ratio``, so both, and the stiffness wave, come from this geometry
    (:mod:`gearjax._gear.mesh_stiffness`); otherwise the geometry is only checked.
    ``relieved`` (static): some gear has tip relief.
    """

    face_width_mm: Float[Array, ""]
    profile_shift: PerGear
    addendum: Float[Array, ""]
    dedendum: Float[Array, ""]
    root_radius: Float[Array, ""]
    youngs_modulus: Float[Array, ""]
    poisson_ratio: Float[Array, ""]
    tip_relief: TipRelief
    derives_stiffness: bool = eqx.field(static=True, default=True)
    relieved: bool = eqx.field(static=True, default=False)


class Stage(eqx.Module):
    """One simple planetary stage: sun, ring, carrier and ``N`` planets.

    Units are those of the train-file keys: ``module_mm`` in mm, angles in degrees,
    stiffness in N/m, backlash in m, inertia in kg m^2, mass in kg. ``geometry`` is
    ``None`` unless the file gives ``face_width_mm``; where it derives the stiffness,
    ``contact_ratio`` and ``mesh_stiffness`` hold the geometric values (the unloaded
    mean) for reports, and assembly derives the wave from ``geometry`` itself.
    ``mass``, ``bearing_stiffness`` and ``bearing_damping_ratio`` (``None`` unless
    given; the damping ratio then is ``mesh_damping_ratio``) are what the
    translational model adds; ``base_diameter_mm`` (``None``: from module, teeth and
    pressure angle) gives published base circles.
    """

    id: str = eqx.field(static=True)
    teeth: Teeth
    module_mm: Float[Array, ""]
    pressure_angle_deg: Float[Array, ""]
    planet_angles_deg: Float[Array, " N"]
    carrier_radius_mm: Float[Array, ""] | None
    contact_ratio: SunRing
    mesh_stiffness: SunRing
    mesh_damping_ratio: Float[Array, ""]
    half_backlash: SunRing
    sun_ring_phase_deg: Float[Array, ""]
    stage_phase_deg: Float[Array, ""]
    transmission_error: TransmissionError
    inertia: Inertia
    planet_mass: Float[Array, ""]
    geometry: ToothGeometry | None = None
    mass: CentralMass | None = None
    bearing_stiffness: BearingStiffness | None = None
    bearing_damping_ratio: Float[Array, ""] | None = None
    planet_position_error_um: PlanetErrors | None = None
    base_diameter_mm: PerGear | None = None

    @property
    def stiffness_from_geometry(self) -> bool:
        """The mesh stiffness wave comes from the tooth geometry (module docstring of
        :mod:`gearjax._gear.mesh_stiffness`), not from ``mesh_stiffness`` and
        ``contact_ratio``."""
        return self.geometry is not None and self.geometry.derives_stiffness

    @property
    def n_planets(self) -> int:
        return self.planet_angles_deg.shape[-1]

    def carrier_radius(self) -> Float[Array, ""]:
        """Planet-centre radius (m): given, or ``module (Z_s + Z_p) / 2``."""
        if self.carrier_radius_mm is not None:
            return self.carrier_radius_mm * 1e-3
        return self.module_mm * 1e-3 * (self.teeth.sun + self.teeth.planet) / 2

    def base_radii(self) -> tuple[Array, Array, Array]:
        """Base radii (m) of sun, planet, ring: ``base_diameter_mm / 2`` where given,
        else ``m Z cos(alpha) / 2``."""
        d = self.base_diameter_mm
        if d is not None:
            return d.sun * 5e-4, d.planet * 5e-4, d.ring * 5e-4
        half = self.module_mm * 1e-3 * jnp.cos(jnp.deg2rad(self.pressure_angle_deg)) / 2
        return half * self.teeth.sun, half * self.teeth.planet, half * self.teeth.ring


class Coupling(eqx.Module):
    """A torsional spring (N m/rad) between central members of two stages, with an
    optional viscous damper in parallel.

    Permanent when ``gears`` is None, otherwise a clutch engaged only in those gears.
    The damper is given one of two ways (train-file keys, at most one; ``None``: not
    given): ``damping`` in N m s/rad, or ``damping_ratio`` ``zeta`` of the coupling's own
    mode, the two members as rigid inertias ``J_1``, ``J_2`` (:func:`member_inertia`)
    joined by the spring alone: ``c = 2 zeta sqrt(k J_1 J_2 / (J_1 + J_2))``
    (:meth:`viscous_damping`). Neither: no damper.
    """

    members: tuple[str, str] = eqx.field(static=True)
    stiffness: Float[Array, ""]
    id: str | None = eqx.field(static=True, default=None)
    gears: tuple[str, ...] | None = eqx.field(static=True, default=None)
    damping: Float[Array, ""] | None = None
    damping_ratio: Float[Array, ""] | None = None

    def engaged(self, gear: str) -> bool:
        return self.gears is None or gear in self.gears

    @property
    def damped(self) -> bool:
        """The file gives a damper (``damping`` or ``damping_ratio``, possibly 0)."""
        return self.damping is not None or self.damping_ratio is not None

    def critical_damping(self, j1, j2) -> Float[Array, ""]:
        """``2 sqrt(k j1 j2 / (j1 + j2))`` (N m s/rad): the damping that makes the
        coupling's own mode, members of inertias ``j1``, ``j2`` (kg m^2) on its spring
        alone, critically damped."""
        return 2 * jnp.sqrt(self.stiffness * j1 * j2 / (j1 + j2))

    def viscous_damping(self, j1, j2) -> Float[Array, ""]:
        """The damper's coefficient ``c`` (N m s/rad) between members of inertias ``j1``,
        ``j2`` (kg m^2): ``damping`` as given, or ``damping_ratio`` times
        :meth:`critical_damping`; 0 without a damper."""
        if self.damping is not None:
            return jnp.asarray(self.damping)
        if self.damping_ratio is not None:
            return self.damping_ratio * self.critical_damping(j1, j2)
        return jnp.asarray(0.0)

    @property
    def label(self) -> str:
        return self.id if self.id is not None else "-".join(self.members)


class Housing(eqx.Module):
    """Torsional stiffness (N m/rad) of central members to the housing."""

    braked: Float[Array, ""]
    free: Float[Array, ""]


class Gear(eqx.Module):
    """A power-flow configuration: input, output, brakes and loads.

    ``input_torque_ripple`` has shape ``(L, 2)``, rows ``(amplitude [N m], phase [deg])``
    at ``ripple_orders`` (static: they set frequencies, so they are structure), each a
    multiple of the input shaft speed. The train file writes the three together as
    ``[[amplitude, phase_deg, order], ...]``. ``input_rpm``: the gear's operating input
    speed (rpm) where the file gives one (``info`` reports at it), else ``None``.
    """

    name: str = eqx.field(static=True)
    input: str = eqx.field(static=True)
    output: str = eqx.field(static=True)
    brakes: tuple[str, ...] = eqx.field(static=True)
    input_torque: Float[Array, ""]
    input_torque_ripple: Float[Array, "L 2"]
    drag_torque: Float[Array, ""]
    ripple_orders: tuple[float, ...] = eqx.field(static=True, default=())
    input_rpm: float | None = eqx.field(static=True, default=None)
    note: str | None = eqx.field(static=True, default=None)


class Train(eqx.Module):
    """A compound planetary train: stages, couplings, housing and gears.

    ``model`` (static, one of :data:`MODELS`) applies to every stage. ``source`` is the
    file it was read from (for messages), ``None`` if built in code.
    """

    name: str = eqx.field(static=True)
    stages: tuple[Stage, ...]
    couplings: tuple[Coupling, ...]
    housing: Housing
    gears: tuple[Gear, ...]
    stiffness_harmonics: int = eqx.field(static=True, default=4)
    phasing: str = eqx.field(static=True, default="physical")
    mesh_damping: str = eqx.field(static=True, default="always")
    source: str | None = eqx.field(static=True, default=None)
    model: str = eqx.field(static=True, default="torsional")

    @property
    def stage_ids(self) -> tuple[str, ...]:
        return tuple(s.id for s in self.stages)

    @property
    def gear_names(self) -> tuple[str, ...]:
        return tuple(g.name for g in self.gears)

    @property
    def translational(self) -> bool:
        return self.model == "translational"

    @property
    def n_dof(self) -> int:
        """Coordinates of every stage (:meth:`stage_dof`)."""
        return sum(self.stage_dof(s) for s in self.stages)

    def stage_dof(self, stage: Stage) -> int:
        """A stage's coordinates: ``3 + N`` rotations (sun, ring, carrier, planets),
        then in the translational model ``6 + 2 N`` translations (``x, y`` of sun, ring
        and carrier; radial and tangential of each planet)."""
        return (9 + 3 * stage.n_planets) if self.translational else 3 + stage.n_planets

    def stage_offsets(self) -> tuple[int, ...]:
        """Index of each stage's first coordinate (its sun's rotation)."""
        sizes = [self.stage_dof(s) for s in self.stages]
        return tuple(sum(sizes[:i]) for i in range(len(sizes)))

    def stage(self, stage_id: str) -> Stage:
        for s in self.stages:
            if s.id == stage_id:
                return s
        raise KeyError(f"no stage {stage_id!r}; stages are {list(self.stage_ids)}")

    def gear(self, name: str | None = None) -> Gear:
        """The gear called ``name``; the first gear in the file when ``None``."""
        if name is None:
            return self.gears[0]
        for g in self.gears:
            if g.name == name:
                return g
        raise bad_argument("gear", name, f"no such gear in {self.source or 'the train'}; "
                           f"gears are {list(self.gear_names)}")

    def engaged_couplings(self, gear: str) -> tuple[Coupling, ...]:
        return tuple(c for c in self.couplings if c.engaged(gear))


def member_index(train: Train, path: str) -> int:
    """Coordinate index of central member ``path`` (``"ID.sun|ring|carrier"``)."""
    stage_id, _, member = path.rpartition(".")
    offset = 0
    for s in train.stages:
        if s.id == stage_id:
            return offset + MEMBERS.index(member)
        offset += train.stage_dof(s)
    raise KeyError(path)


def member_inertia(train: Train, path: str) -> Float[Array, ""]:
    """Polar inertia (kg m^2) of central member ``path`` (``"ID.sun|ring|carrier"``) on its
    own, with the meshes taken away: ``inertia.sun``, ``inertia.ring``, or for a carrier
    ``I_c + N m_p r_c^2``, the carrier carrying its ``N`` planets around, each free to spin
    on its bearing (the mass matrix's carrier entry with the planet coordinates condensed
    out). The inertia of a coupling's own mode (:meth:`Coupling.viscous_damping`)."""
    stage_id, _, member = path.rpartition(".")
    s = train.stage(stage_id)
    if member == "carrier":
        return s.inertia.carrier + s.n_planets * s.planet_mass * s.carrier_radius() ** 2
    return getattr(s.inertia, member)


def planet_index(train: Train, stage_id: str, planet: int) -> int:
    """Coordinate index of planet ``planet`` (0-based) of stage ``stage_id``."""
    offset = 0
    for s in train.stages:
        if s.id == stage_id:
            return offset + 3 + planet
        offset += train.stage_dof(s)
    raise KeyError(stage_id)


def member_paths(train: Train) -> tuple[str, ...]:
    """Every central member path, in coordinate order."""
    return tuple(f"{s.id}.{m}" for s in train.stages for m in MEMBERS)
