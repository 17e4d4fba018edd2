"""A gear prepared once for solving: kinematics, base frequency, reference stage, System.

Every study (sweep, simulate, verify, sensitivity, design, optimize) starts from a
:class:`GearCase`; the checks it makes (a turning mesh, a common base frequency, a
turning reference stage, no rattling unloaded stage) are made here only.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np

from .._engine.responses import static_mesh_forces
from .._engine.system import System
from .._errors import bad_argument, fail
from .._io.results import mesh_coordinates
from .assembly import assemble
from .kinematics import Kinematics, kinematics, require_base
from .train import Gear, Train


def reference_stage(train: Train, kin: Kinematics, stage: str | None) -> str:
    """The reference stage id: ``stage``, or the first turning stage when ``None``.

    **Raises:** ``TrainError`` (naming argument ``stage``) for an unknown stage or one
    that does not turn in the gear.
    """
    if stage is None:
        return next(s.id for s in kin.stages if s.turning)
    if stage not in train.stage_ids:
        raise bad_argument("stage", stage, f"no such stage; stages are "
                           f"{list(train.stage_ids)}")
    if not kin.stage(stage).turning:
        raise bad_argument("stage", stage, f"stage {stage!r} does not turn in gear "
                           f"{kin.gear!r}: its mesh frequency is 0")
    return stage


def check_unloaded(train: Train, g: Gear, kin: Kinematics, system: System) -> None:
    """Refuse backlash on a stage with no static load and no ``drag_torque``.

    **Raises:** ``TrainError`` naming ``gears.<name>.drag_torque``.
    """
    back = np.asarray(system.backlash)
    for s in kin.stages:
        rows = [i for i, grp in enumerate(system.mesh_group) if grp == s.id]
        if not s.loaded and np.any(back[rows] > 0) and float(g.drag_torque) == 0.0:
            raise fail(train.source, f"gears.{g.name}.drag_torque", 0.0,
                       f"stage {s.id!r} carries no static load in gear {g.name!r} (a central "
                       "member is free), so with backlash its meshes rattle at an undetermined "
                       "mean position: give the gear a drag_torque, or solve with `linear`")


@dataclasses.dataclass(frozen=True)
class GearCase:
    """A gear prepared for solving at reference-stage mesh frequencies.

    **Fields:** ``train``; ``gear`` (:class:`~gearjax.Gear`); ``kin``
    (:class:`~gearjax.Kinematics`); ``mu``: the gear's coprime multipliers, stage order;
    ``stage``: the reference stage id; ``mu_ref``: its multiplier; ``system``: the
    assembled :class:`~gearjax.System` (backlash removed when ``linear``);
    ``linear``; ``F_static`` ``(m,)``: static mesh forces (N).
    """

    train: Train
    gear: Gear
    kin: Kinematics
    mu: tuple[int, ...]
    stage: str
    mu_ref: int
    system: System
    linear: bool
    F_static: np.ndarray

    def omega(self, f_hz) -> np.ndarray:
        """Base frequency Omega (rad/s) at reference-stage mesh frequencies ``f_hz`` (Hz)."""
        return 2 * np.pi * np.asarray(f_hz, dtype=float) / self.mu_ref

    @property
    def has_backlash(self) -> bool:
        return self.system.has_backlash

    def point_coordinates(self, f_hz) -> dict:
        """``mesh_frequency_hz``, ``stage_mesh_frequency_hz``, ``input_rpm``, ``omega`` and
        the mesh coordinates: the keywords of ``sweep_dataset`` that describe the points."""
        f_hz = np.asarray(f_hz, dtype=float)
        omegas = self.omega(f_hz)
        return dict(
            **mesh_coordinates(self.system),
            mesh_frequency_hz=f_hz,
            stage_mesh_frequency_hz=np.outer(omegas / (2 * np.pi), np.asarray(self.mu, float)),
            input_rpm=np.array([self.kin.input_rpm(self.stage, f) for f in f_hz]),
            omega=omegas,
        )


def gear_case(train: Train, gear: str | None = None, stage: str | None = None,
              linear: bool = False) -> GearCase:
    """Assemble ``gear`` for solving at mesh frequencies of reference stage ``stage``.

    ``TrainError`` for a gear where no
    mesh turns, an unknown or non-turning stage, or backlash on an unloaded stage
    without ``drag_torque`` (unless ``linear``, which drops the backlash).
    """
    g = train.gear(gear)
    kin = kinematics(train, g.name)
    mu = require_base(kin, train.source)
    ref = reference_stage(train, kin, stage)
    system = assemble(train, g.name, kin)
    if linear:
        system = dataclasses.replace(system, backlash=jnp.zeros_like(system.backlash))
    else:
        check_unloaded(train, g, kin, system)
    return GearCase(train=train, gear=g, kin=kin, mu=tuple(mu), stage=ref,
                    mu_ref=mu[train.stage_ids.index(ref)], system=system, linear=linear,
                    F_static=np.asarray(static_mesh_forces(system)))
