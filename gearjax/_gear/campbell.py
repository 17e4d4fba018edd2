"""Campbell diagram of a gear: mesh-frequency harmonics against input speed, and the
elastic natural frequencies they cross.

Harmonic ``h`` of stage ``n`` meshes at ``h * f_n(rpm)``, ``f_n = Z_r |w_r - w_c| rpm / 60``
(exact kinematics, :func:`gearjax.kinematics`): a ray through the origin. The natural
frequencies are those of the linear, mean-stiffness model (:func:`gearjax.modes`),
horizontal lines. A ray crosses a mode at ``rpm = 60 f_mode / (h f_n per rev)``.

Whether a crossing is a resonance the mesh stiffness drives (first order, the forced
response of Figs 4-5 of the paper) follows from the planet phasing (Parker & Lin 2004,
:func:`gearjax.phasing_report`): in this torsional model a harmonic whose meshes of a
stage are in phase (``k = h Z_s mod N = 0``) drives the overall modes and no planet
mode; any other phasing pattern sums to zero over the planets, so it drives only the
planet modes of its own stage. A harmonic above the stiffness harmonics kept
(``stiffness_harmonics``) and without transmission error, or of an unloaded stage,
drives nothing directly. Parametric instabilities (near ``2 f_mode / h`` and
combinations) and responses through the backlash are not marked.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np

from .assembly import assemble
from .._errors import fail
from .kinematics import kinematics
from .phasing import phasing_report
from .._engine.modal import modes
from .train import Train


@dataclasses.dataclass(frozen=True)
class Crossing:
    """A harmonic ray meeting a natural frequency.

    **Fields:** ``rpm``: input speed (rpm); ``hz``: the natural frequency (Hz);
    ``stage``, ``harmonic``: the ray; ``mode``: index into :attr:`Campbell.mode_hz`;
    ``excited``: the stiffness excitation drives that mode at first order; ``why``: the
    reason, in words (``in-phase harmonic, overall mode``, ``phasing cancels``, ...).
    """

    rpm: float
    hz: float
    stage: str
    harmonic: int
    mode: int
    excited: bool
    why: str


@dataclasses.dataclass(frozen=True)
class Campbell:
    """Data of a Campbell diagram of one gear (:func:`campbell`).

    **Fields:**

    - ``gear``, ``input``: the gear and its input member;
    - ``rpm`` ``(R,)``: input speeds (rpm);
    - ``stages`` ``(S,)``: ids of the stages whose meshes turn; ``loaded`` ``(S,)``: they
      carry static load; ``mesh_hz_per_rpm`` ``(S,)``: mesh frequency (Hz) per input rpm;
    - ``harmonics`` ``(H,)``: ``1..N``; ``phasing`` ``(S, H)``: ``in-phase``,
      ``sequential``, ``counter-phase`` or ``unequal spacing`` (``beyond model`` above the
      stiffness harmonics kept);
    - ``excitation_hz`` ``(S, H, R)``: ``h * f_n`` at each speed (Hz);
    - ``mode_hz`` ``(M,)``: distinct elastic natural frequencies (Hz), ascending;
      ``mode_multiplicity``, ``mode_family`` (``overall`` | ``planet``, and in the
      translational model ``rotational`` | ``translational``), ``mode_stage`` (stage id
      of a mode that moves one stage only, ``""`` otherwise);
    - ``crossings``: every ray-mode crossing inside the speed range, by speed.
    """

    gear: str
    input: str
    rpm: np.ndarray
    stages: tuple[str, ...]
    loaded: tuple[bool, ...]
    mesh_hz_per_rpm: np.ndarray
    harmonics: np.ndarray
    phasing: tuple[tuple[str, ...], ...]
    excitation_hz: np.ndarray
    mode_hz: np.ndarray
    mode_multiplicity: tuple[int, ...]
    mode_family: tuple[str, ...]
    mode_stage: tuple[str, ...]
    crossings: tuple[Crossing, ...]


def campbell(
    train: Train,
    gear: str | None = None,
    rpm_range: Sequence[float] = (0.0, 10000.0),
    harmonics: int | None = None,
    *,
    points: int = 2,
    max_hz: float | None = None,
) -> Campbell:
    """Campbell diagram of ``gear`` (default: the first gear).

    **Arguments:** ``rpm_range``: ``(low, high)`` input speeds (rpm), ``0 <= low <
    high``; ``harmonics``: mesh harmonics ``1..N`` drawn per stage (default the train's
    ``stiffness_harmonics``); ``points``: speeds sampled (rays are straight, 2 is
    exact); ``max_hz``: keep only natural frequencies up to this (Hz; default all).

    **Returns:** :class:`Campbell`. A gear in which no mesh turns (a locked train) has no
    rays and no crossings. **Raises:** ``TrainError`` naming the argument for a bad
    speed range, harmonic count or point count, and as :func:`gearjax.kinematics`.
    """
    lo, hi = (float(v) for v in rpm_range)
    if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 <= lo < hi):
        raise fail("campbell", "rpm_range", (lo, hi),
                   "must be (low, high) input speeds in rpm with 0 <= low < high")
    n_h = train.stiffness_harmonics if harmonics is None else harmonics
    if int(n_h) != n_h or n_h < 1:
        raise fail("campbell", "harmonics", harmonics, "must be an integer >= 1")
    n_h = int(n_h)
    if int(points) != points or points < 2:
        raise fail("campbell", "points", points, "must be an integer >= 2")
    g = train.gear(gear)
    kin = kinematics(train, g.name)
    modal = modes(assemble(train, g.name, kin))

    elastic = [m for m in modal.modes if m.cls == "elastic"]
    distinct, k = [], 0
    while k < len(elastic):
        distinct.append(elastic[k])
        k += elastic[k].multiplicity
    if max_hz is not None:
        distinct = [m for m in distinct if m.hz <= max_hz]
    mode_hz = np.array([m.hz for m in distinct])

    rpm = np.linspace(lo, hi, int(points))
    hs = np.arange(1, n_h + 1)
    stages, loaded, per_rpm, phasing = [], [], [], []
    for s, sk in zip(train.stages, kin.stages):
        if not sk.turning:
            continue
        stages.append(s.id)
        loaded.append(bool(sk.loaded))
        per_rpm.append(float(sk.mesh_frequency) / 60.0)
        report = phasing_report(s, sk.sigma, train.phasing, n_h)
        te = np.maximum(np.abs(np.asarray(s.transmission_error.sun)[:, 0]),
                        np.abs(np.asarray(s.transmission_error.ring)[:, 0]))
        # a harmonic above the stiffness harmonics kept excites only through transmission error
        phasing.append(tuple(
            r.kind if r.h <= train.stiffness_harmonics or (r.h <= te.size and te[r.h - 1] > 0)
            else "beyond model" for r in report))
    per_rpm_arr = np.array(per_rpm, dtype=float)
    excitation = per_rpm_arr[:, None, None] * hs[None, :, None] * rpm[None, None, :]

    crossings = []
    for i, sid in enumerate(stages):
        for j, h in enumerate(hs):
            for m_idx, m in enumerate(distinct):
                r = m.hz / (h * per_rpm_arr[i])
                if lo <= r <= hi:
                    excited, why = _drives(phasing[i][j], loaded[i], sid, m.family, m.stage,
                                           train.translational)
                    crossings.append(Crossing(rpm=float(r), hz=float(m.hz), stage=sid,
                                              harmonic=int(h), mode=m_idx, excited=excited,
                                              why=why))
    crossings.sort(key=lambda c: (c.rpm, c.hz))
    return Campbell(
        gear=g.name, input=g.input, rpm=rpm, stages=tuple(stages), loaded=tuple(loaded),
        mesh_hz_per_rpm=per_rpm_arr, harmonics=hs, phasing=tuple(phasing),
        excitation_hz=excitation, mode_hz=mode_hz,
        mode_multiplicity=tuple(m.multiplicity for m in distinct),
        mode_family=tuple(m.family for m in distinct),
        mode_stage=tuple(m.stage or "" for m in distinct),
        crossings=tuple(crossings))


def _drives(kind: str, loaded: bool, stage: str, family: str, mode_stage: str | None,
            translational: bool = False):
    """``(excited, why)`` of harmonic phasing ``kind`` of ``stage`` against a mode of
    ``family`` (:func:`~gearjax._engine.modal.modes`); ``translational``: the train's
    model has translations (then a sequential harmonic moves the centres, not the
    planets: Parker & Lin, J. Mech. Des. 126 (2004))."""
    if kind == "beyond model":
        return False, "no stiffness harmonic this high in the model"
    if not loaded:
        return False, "unloaded stage: parametric only"
    if kind == "unequal spacing":
        return True, "unequal planet spacing: phasing rule does not apply"
    if family in ("planet", "translational") and mode_stage not in (None, stage):
        return False, f"{family} mode of stage {mode_stage}: not moved by stage {stage}"
    if family == "translational":  # Parker & Lin 2004: only k = 1, N - 1 moves the centres
        if kind == "sequential":
            return True, "sequential harmonic, translational mode"
        return False, f"phasing cancels: {kind} harmonic, translational mode"
    if family == "planet":
        if kind == "in-phase":
            return False, "phasing cancels: in-phase harmonic, planet mode"
        if kind == "sequential" and translational:
            return False, ("phasing cancels: a sequential harmonic drives the translational "
                           "modes, not the planet modes")
        return True, f"{kind} harmonic, planet mode"
    if kind == "in-phase":
        return True, f"in-phase harmonic, {family} mode"
    return False, f"phasing cancels: {kind} harmonic, {family} mode"
