"""Static loads of a gear: mesh forces, member torques and the torque balance.

External torques plus housing reactions sum to zero (meshes and couplings are internal).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .assembly import assemble
from .kinematics import kinematics
from .._engine.static import static_deflection
from .train import Train, member_index, member_paths


@dataclasses.dataclass(frozen=True)
class StaticLoads:
    """Static loads of a gear (N, N m), per unit of nothing: at the gear's input torque.

    **Fields:** ``mesh_force``: mesh label -> force (N, positive presses the positive
    flank); ``mesh_torque``: label -> ``r_j F`` (N m); ``external``: member -> applied
    torque (input, output load, drag); ``housing``: member -> torque the housing
    spring exerts on it (brake reactions and leaks through the free springs);
    ``brake_reaction``: braked member -> reaction (N m); ``leak``: total torque through
    the free housing springs; ``balance``: sum of external and housing torques (should
    be ~0); ``coordinates``: label -> static rotation (rad).
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


def static_loads(train: Train, gear: str | None = None) -> StaticLoads:
    """Static mesh forces, member torques and the torque balance of ``gear``."""
    g = train.gear(gear)
    system = assemble(train, g.name, kinematics(train, g.name))
    x, F = (np.asarray(a) for a in static_deflection(system))
    mesh_force = dict(zip(system.mesh_labels, F.tolist()))
    mesh_torque = dict(zip(system.mesh_labels, (np.asarray(system.mesh_radius) * F).tolist()))
    f = np.asarray(system.f_mean)
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
    )
