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
from .frequency_groups import TorusLayout, gear_frequency_groups, torus_layout
from .kinematics import Kinematics, kinematics, require_base
from .static_loads import floating_reason
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
    (:class:`~gearjax.Kinematics`); ``mu``: each stage's mesh frequency over the base
    frequency ``Omega``, stage order (the gear's coprime integer multipliers for a
    periodic system; on a torus floats, ``Omega`` the base of the first frequency
    group); ``stage``: the reference stage id; ``mu_ref``: its entry of ``mu``;
    ``system``: the assembled :class:`~gearjax.System` (backlash removed when
    ``linear``); ``linear``; ``F_static`` ``(m,)``: static mesh forces (N); ``layout``:
    the :class:`~gearjax._gear.frequency_groups.TorusLayout` of a torus system, ``None``
    for a periodic one.
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
    layout: TorusLayout | None = None

    @property
    def G(self) -> int:
        """Torus angles of the system (1: periodic)."""
        return self.system.n_angles

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


def torus_fields(case: GearCase) -> dict | None:
    """What a study of ``case`` solves on its torus, for datasets and JSON (``None`` for a
    periodic system): ``G``; ``angle_ratio`` (each angle's base frequency over angle 0's,
    floats) and ``angle_ratio_exact`` (fractions, as text); ``stage_angle`` ``{stage id:
    [angle, multiplier]}``; ``ripple_angle`` ``[[angle, multiplier], ...]``;
    ``truncation`` (the set, :data:`gearjax._studies.harmonics.TORUS_TRUNCATION`); and the
    stability's near return, ``return_turns`` and ``return_drift``
    (:func:`gearjax._engine.floquet.return_turns`)."""
    from .._engine.floquet import return_turns
    from .._studies.harmonics import TORUS_TRUNCATION

    if case.layout is None:
        return None
    q, d = return_turns(case.system.angle_ratio)
    return {"G": case.layout.G, "angle_ratio": [float(r) for r in case.layout.ratio],
            "angle_ratio_exact": [str(r) for r in case.layout.ratio],
            "stage_angle": {k: list(v) for k, v in case.layout.stage.items()},
            "ripple_angle": [list(v) for v in case.layout.ripple],
            "truncation": TORUS_TRUNCATION, "return_turns": q, "return_drift": d}


def check_floating(train: Train, g: Gear, system: System, F_static) -> None:
    """Refuse backlash where the gear floats in its clearances (``floating_reason`` of
    the static mesh forces ``F_static`` (N): no mesh with backlash carries a static load
    the harmonic balance resolves).

    **Raises:** ``TrainError`` naming ``gears.<name>.input_torque``.
    """
    reason = floating_reason(system, F_static)
    if reason is not None:
        raise fail(train.source, f"gears.{g.name}.input_torque", float(g.input_torque),
                   f"{reason}: give the gear an input torque, or solve with `linear`")


def gear_case(train: Train, gear: str | None = None, stage: str | None = None,
              linear: bool = False, torus: bool = False) -> GearCase:
    """Assemble ``gear`` for solving at mesh frequencies of reference stage ``stage``.

    ``torus``: where the gear's frequencies fall in ``G > 1`` groups
    (:func:`~gearjax.gear_frequency_groups`), assemble the torus system of model.md,
    "Incommensurate stages" (one angle per group); otherwise (and always for one group)
    the periodic system of the common base.

    **Raises:** ``TrainError`` for a gear where no mesh turns, no common base within
    the periodic balance's limit (a periodic system of such a gear), an unknown or
    non-turning stage, backlash on an unloaded stage without ``drag_torque``, or
    backlash on a gear that floats in its clearances (:func:`check_floating`) (unless
    ``linear``, which drops the backlash).
    """
    g = train.gear(gear)
    kin = kinematics(train, g.name)
    layout = None
    if torus and kin.mu is not None:
        groups = gear_frequency_groups(kin, train.source)
        layout = torus_layout(kin, groups) if groups.G > 1 else None
    if layout is None:
        mu = require_base(kin, train.source)
    else:
        mu = tuple(float(layout.ratio[layout.stage[s.id][0]] * layout.stage[s.id][1])
                   if s.id in layout.stage else 0.0 for s in kin.stages)
    ref = reference_stage(train, kin, stage)
    system = assemble(train, g.name, kin, layout)
    if linear:
        system = dataclasses.replace(system, backlash=jnp.zeros_like(system.backlash))
    else:
        check_unloaded(train, g, kin, system)
    F_static = np.asarray(static_mesh_forces(system))
    if not linear:
        check_floating(train, g, system, F_static)
    return GearCase(train=train, gear=g, kin=kin, mu=tuple(mu), stage=ref,
                    mu_ref=mu[train.stage_ids.index(ref)], system=system, linear=linear,
                    F_static=F_static, layout=layout)
