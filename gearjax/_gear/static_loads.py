"""Static loads of a gear: mesh forces, member torques and the torque balance.

External torques plus housing reactions sum to zero (meshes and couplings are internal).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .assembly import assemble
from .kinematics import kinematics
from .._engine.hb import HarmonicBalance
from .._engine.static import static_deflection
from .._engine.system import System
from .._errors import field_message, warn_range
from .load_sharing import load_sharing
from .train import Train, member_index, member_paths
from .translational import pin_error_forcing

FLOAT_RESOLUTION = HarmonicBalance().rtol
"""Share of its backlash below which a mesh's static deflection is no load: the
harmonic balance's unknowns are in units of the largest backlash, resolved to Newton's
tolerance (``HarmonicBalance.rtol``)."""


def floating_reason(system: System, force) -> str | None:
    """Why ``system`` floats in its clearances, in words, from its static mesh forces
    ``force`` ``(m,)`` (N; ``static_deflection``): every mesh with backlash has a static
    deflection (``|force| / kbar``) below :data:`FLOAT_RESOLUTION` of its backlash (no
    input torque, or one too small to press any tooth pair together as far as the
    harmonic balance resolves). ``None`` where some mesh with backlash carries load, or
    none has backlash."""
    back = np.asarray(system.backlash)
    rows = back > 0
    if not np.any(rows):
        return None
    force = np.asarray(force)
    deflection = np.abs(force) / np.asarray(system.kbar)
    if np.any(deflection[rows] > FLOAT_RESOLUTION * back[rows]):
        return None
    i = int(np.argmax(np.where(rows, deflection, -1.0)))
    label = system.mesh_labels[i]
    return (f"every mesh with backlash floats in its clearance: the largest static mesh "
            f"deflection is {deflection[i]:.3g} m ({label}, static force {force[i]:.3g} N), "
            f"below {FLOAT_RESOLUTION:g} of its backlash {back[i]:.3g} m, so no tooth pair "
            "is pressed together and the mean position in the clearances is undetermined")


@dataclasses.dataclass(frozen=True)
class StaticLoads:
    """Static loads of a gear (N, N m), per unit of nothing: at the gear's input torque.

    **Fields:** ``mesh_force``: mesh label -> force (N, positive presses the positive
    flank); ``mesh_torque``: label -> ``r_j F`` (N m); ``external``: member -> applied
    torque (input, output load, drag); ``housing``: member -> torque the housing
    spring exerts on it (brake reactions and leaks through the free springs);
    ``brake_reaction``: braked member -> reaction (N m); ``leak``: total torque through
    the free housing springs; ``balance``: sum of external and housing torques (should
    be ~0); ``coordinates``: label -> static rotation (rad) or translation (m);
    ``load_sharing``: stage -> static load-sharing factor (:mod:`.load_sharing`).
    """

    gear: str
    mesh_force: dict[str, float]
    mesh_torque: dict[str, float]
    external: dict[str, float]
    housing: dict[str, float]
    brake_reaction: dict[str, float]
    leak: float
    balance: float
    coordinates: dict[str, float]
    load_sharing: dict[str, float | None]


def static_loads(train: Train, gear: str | None = None) -> StaticLoads:
    """Static mesh forces, member torques and the torque balance of ``gear``; a
    ``RangeWarning`` where the gear floats in its clearances (:func:`floating_reason`)."""
    g = train.gear(gear)
    system = assemble(train, g.name, kinematics(train, g.name))
    x, F = (np.asarray(a) for a in static_deflection(system))
    reason = floating_reason(system, F)
    if reason is not None:
        warn_range(field_message(train.source, f"gears.{g.name}.input_torque",
                                 float(g.input_torque), reason))
    mesh_force = dict(zip(system.mesh_labels, F.tolist()))
    mesh_torque = dict(zip(system.mesh_labels, (np.asarray(system.mesh_radius) * F).tolist()))
    f = np.asarray(system.f_mean)  # less the pins' internal error forces, if any
    for s, offset in zip(train.stages, train.stage_offsets()) if train.translational else ():
        f = f - np.asarray(pin_error_forcing(s, offset, train.n_dof))
    external, housing, brakes = {}, {}, {}
    leak = 0.0
    for path in member_paths(train):
        i = member_index(train, path)
        k = float(train.housing.braked if path in g.brakes else train.housing.free)
        housing[path] = -k * x[i]
        if f[i] != 0.0:
            external[path] = float(f[i])
        if path in g.brakes:
            brakes[path] = housing[path]
        else:
            leak += housing[path]
    balance = sum(external.values()) + sum(housing.values())
    return StaticLoads(
        gear=g.name,
        mesh_force=mesh_force,
        mesh_torque=mesh_torque,
        external=external,
        housing=housing,
        brake_reaction=brakes,
        leak=float(leak),
        balance=float(balance),
        coordinates=dict(zip(system.dof_labels, x.tolist())),
        load_sharing=load_sharing(system, F),
    )
