"""The phasing variables of an optimisation: which stages' planet sets and phases vary,
and how a train maps to and from its design vector.

**Variables** (``vary``, TOML paths; default :func:`default_vary`):
``STAGE.planet_angles_deg`` (the stage's whole planet set, chosen among the admissible
sets), ``STAGE.sun_ring_phase_deg`` and ``STAGE.stage_phase_deg`` (continuous, 360 deg =
one mesh cycle). The first turning stage's stage phase is the time origin (shifting it
shifts time) and is not a variable. The design vector holds, stage by stage in file
order, planet angles 2..N of a varied set, then the varied phases (deg).

On a torus (a gear whose mesh frequencies fall in ``G > 1`` incommensurate groups,
model.md) each angle has its own origin: the first turning stage of each frequency
group (:func:`phase_origins`). A torus average takes every relative phase of
incommensurate angles, so shifting a whole angle changes no response; only stage phases
relative to another stage of the same group are variables.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from ..._errors import bad_argument
from ..._gear.frequency_groups import gear_frequency_groups, torus_layout
from ..._gear.kinematics import Kinematics, kinematics, require_base
from ..._gear.paths import get_path, leaf_selector, set_path
from ..._gear.train import Train

PHASING_KEYS = ("planet_angles_deg", "sun_ring_phase_deg", "stage_phase_deg")


@dataclasses.dataclass(frozen=True)
class StageVariables:
    """The varied phasing of one stage: ``planets`` (the planet set), ``sun_ring``,
    ``stage_phase``; ``paths``: the TOML paths of the continuous values it owns in a
    design vector (planet angles 2..N, then the phases)."""

    stage: str
    planets: bool
    sun_ring: bool
    stage_phase: bool
    n_planets: int

    @property
    def paths(self) -> tuple[str, ...]:
        out = []
        if self.planets:
            out += [f"{self.stage}.planet_angles_deg.{i}" for i in range(2, self.n_planets + 1)]
        if self.sun_ring:
            out.append(f"{self.stage}.sun_ring_phase_deg")
        if self.stage_phase:
            out.append(f"{self.stage}.stage_phase_deg")
        return tuple(out)

    @property
    def names(self) -> tuple[str, ...]:
        """The ``vary`` spellings (``STAGE.KEY``)."""
        keys = [k for k, on in zip(PHASING_KEYS, (self.planets, self.sun_ring,
                                                  self.stage_phase)) if on]
        return tuple(f"{self.stage}.{k}" for k in keys)


def phase_origins(train: Train, kin: Kinematics) -> dict[str, int]:
    """``{stage id: torus angle}`` of the stages whose stage phase is an origin: the first
    turning stage (a periodic gear, angle 0), or on a torus the first turning stage of
    each frequency group (:func:`~gearjax.gear_frequency_groups`). Empty where no stage
    turns.

    **Raises:** ``TrainError`` as :func:`~gearjax.gear_frequency_groups`."""
    turning = [s.id for s in kin.stages if s.turning]
    if not turning:
        return {}
    groups = gear_frequency_groups(kin, train.source)
    if groups.G == 1:
        return {turning[0]: 0}
    layout = torus_layout(kin, groups)
    out: dict[str, int] = {}
    for sid in turning:
        angle = layout.stage[sid][0]
        if angle not in out.values():
            out[sid] = angle
    return out


def default_vary(train: Train, gear: str | None = None) -> list[str]:
    """Every phasing variable of the stages that turn in ``gear``: planet sets (2 or more
    planets), sun-ring phases, and the stage phases of all but the time-origin stage (on
    a torus: of every stage but each frequency group's first, :func:`phase_origins`)."""
    g = train.gear(gear)
    kin = kinematics(train, g.name)
    origins = phase_origins(train, kin)
    if not origins:
        require_base(kin, train.source)  # no turning mesh: says so
    out = []
    for s, sk in zip(train.stages, kin.stages):
        if not sk.turning:
            continue
        if s.n_planets >= 2:
            out.append(f"{s.id}.planet_angles_deg")
        out.append(f"{s.id}.sun_ring_phase_deg")
        if s.id not in origins:
            out.append(f"{s.id}.stage_phase_deg")
    return out


def phasing_variables(train: Train, gear: str, vary: Sequence[str] | None
                      ) -> tuple[StageVariables, ...]:
    """Parse ``vary`` (default :func:`default_vary`) into one :class:`StageVariables` per
    stage, in file order.

    **Raises:** ``ArgumentError`` naming argument ``vary``, the path and the rule (for a
    path that names no value of the train, the rule of :func:`gearjax.get_path`).
    """
    kin = kinematics(train, gear)
    origins = phase_origins(train, kin)
    vary = default_vary(train, gear) if vary is None else (
        [vary] if isinstance(vary, str) else list(vary))
    if not vary:
        raise bad_argument("vary", [], "at least one phasing path is required")
    chosen: dict[str, set] = {}
    allowed = ("STAGE.planet_angles_deg (the planet set), STAGE.sun_ring_phase_deg, "
               "STAGE.stage_phase_deg")
    for path in vary:
        parts = str(path).split(".")
        sid = parts[0]
        if len(parts) == 3 and sid in train.stage_ids and parts[1] == "planet_angles_deg":
            leaf_selector(train, path, "vary")  # a bad planet number says so
            raise bad_argument("vary", path,
                               f"planet angles are placed together among the admissible "
                               f"sets: write {sid}.planet_angles_deg")
        if len(parts) != 2 or sid not in train.stage_ids or parts[1] not in PHASING_KEYS:
            if not (len(parts) == 2 and sid in train.stage_ids
                    and parts[1] == "planet_angles_deg"):
                leaf_selector(train, path, "vary")  # names nothing: its own message
            raise bad_argument("vary", path, f"optimize varies the phasing only: {allowed}")
        s = train.stage(sid)
        if not kin.stage(sid).turning:
            raise bad_argument("vary", path, f"stage {sid!r} does not turn in gear {gear!r}: "
                               "its phasing has no effect")
        key = parts[1]
        if key == "planet_angles_deg" and s.n_planets < 2:
            raise bad_argument("vary", path, f"stage {sid!r} has one planet, at 0 deg: there "
                               "is no planet set to choose")
        if key == "stage_phase_deg" and sid in origins and len(origins) == 1:
            raise bad_argument("vary", path, f"stage {sid!r} is the first turning stage: its "
                               "phase is the time origin (shifting it shifts time and changes "
                               "no RMS); vary the other stages' stage_phase_deg")
        if key == "stage_phase_deg" and sid in origins:
            raise bad_argument("vary", path, f"stage {sid!r} is the first turning stage of "
                               f"frequency group {origins[sid]} (torus angle {origins[sid]}): "
                               "its phase is that angle's origin, and the torus average "
                               "takes every relative phase of incommensurate angles, so "
                               "shifting it changes no RMS; vary the stage_phase_deg of a "
                               "stage that shares its frequency group")
        if key in chosen.setdefault(sid, set()):
            raise bad_argument("vary", path, "the variable is given twice; name each once")
        chosen[sid].add(key)
    return tuple(
        StageVariables(stage=s.id, planets="planet_angles_deg" in chosen[s.id],
                       sun_ring="sun_ring_phase_deg" in chosen[s.id],
                       stage_phase="stage_phase_deg" in chosen[s.id], n_planets=s.n_planets)
        for s in train.stages if s.id in chosen)


def with_stage(train: Train, v: StageVariables, angles, gamma, stage_phase=None) -> Train:
    """``train`` with stage ``v.stage``'s varied values set: planet ``angles`` ``(N,)``
    (deg, planet 1 at 0 kept), sun-ring phase ``gamma`` and ``stage_phase`` (deg; ``None``
    keeps it)."""
    t = train
    if v.planets:
        for i, a in enumerate(np.asarray(angles, float)[1:], start=2):
            t = set_path(t, f"{v.stage}.planet_angles_deg.{i}", float(a), "vary")
    if v.sun_ring:
        t = set_path(t, f"{v.stage}.sun_ring_phase_deg", float(gamma), "vary")
    if v.stage_phase and stage_phase is not None:
        t = set_path(t, f"{v.stage}.stage_phase_deg", float(stage_phase), "vary")
    return t


def theta_of(train: Train, paths) -> np.ndarray:
    """The values (file units) of ``paths`` in ``train``, ``(p,)``.

    **Raises:** ``ArgumentError`` naming ``paths`` for a path that names no value."""
    return np.asarray([float(get_path(train, p, "paths")) for p in paths])


def train_at(train: Train, paths, theta) -> Train:
    """``train`` with ``paths`` set to ``theta`` ``(p,)`` (file units).

    **Raises:** ``ArgumentError`` naming ``paths`` for a path that names no value."""
    for p, x in zip(paths, np.asarray(theta, float)):
        train = set_path(train, p, float(x), "paths")
    return train
