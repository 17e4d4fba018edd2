"""Frequency-response sweeps of a gear: the gear-train surface of the harmonic balance.

Frequencies are the mesh frequency (Hz) of a reference stage; with the gear's
coprime ``mu``, ``Omega = 2 pi f / mu_ref`` is the base frequency of every
excitation. The number of solution harmonics depends on frequency
(:func:`gearjax._harmonics.harmonics_rule`): low base frequencies need many harmonics
to reach the modes the excitation drives, high ones few. It is fixed within a segment
of the band, so each segment compiles once; at a segment boundary the solution is
padded or truncated to the next segment's harmonics and re-converged on the boundary.
Each segment's K is checked at its first frequency by the truncation estimate
(:func:`gearjax._harmonics.truncation_change`) and doubled until the estimate meets
the target, before the walk starts.

Linear sweeps (no backlash) are independent points: the periodic solution of a
linear time-periodic system is unique wherever it exists, so a grid of frequencies
is solved in one batched call and no continuation is needed (near a parametric
instability boundary the response grows without bound; those points are unstable).
Non-linear sweeps are pseudo-arclength continuations through the folds.
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import functools
import json
import math
import numbers
import os
import pathlib
import sys
import threading
import time
import warnings
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np
import threadpoolctl

from . import _aft, _continuation, _harmonics, _hb, _journal, _time_domain
from ._assembly import assemble
from ._errors import TrainError, fail
from ._harmonics import harmonics_rule
from ._kinematics import kinematics, require_base
from ._responses import mesh_responses, static_mesh_forces
from ._results import add_displacement_harmonics, mesh_coordinates, sweep_dataset
from ._stability import (bifurcation_kind, floquet_steps, scaled_monodromy, verdict,
                         verdict_basis)
from ._toml_io import dumps_train
from ._train import Train

MAX_DETOUR = 150
"""Points a continuation may go without passing its furthest frequency before the sweep
restarts beyond it (about the length of a fold pair of the paper case: up to a fold,
back along the unstable branch to the next)."""

MIN_ADVANCE = 0.05
"""Passing the furthest frequency counts only by this share of the largest step or more:
a branch that creeps upwards by tenths of a hertz per point (amplitude growing without
bound inside a parametric instability, measured at 6.87 kHz on the paper case) is a
detour too."""

RUNAWAY = 5.0
"""A branch whose RMS alternating deflection of a mesh exceeds this many times the
mesh's static deflection plus its backlash has run away (``runaway``): inside a
parametric instability the paper case's periodic orbits climb to meganewtons (RMS
deflections of centimetres, the teeth hammering across the clearance), every one
unstable, and the truncated harmonic balance cannot resolve such impacts anyway. The
sweep restarts beyond. Over 2-15 kHz the paper case's other orbits stay below 0.41
(measured as RMS force over static force plus stiffness x backlash); those in the
parametric instability at 6.7-6.9 kHz start above 10 and climb past 50."""

MAX_RESTARTS = 100

RESTART_STOPS = ("closed_loop", "detour", "step_too_small", "nonfinite", "runaway")
"""Continuation stops after which a sweep restarts on a new branch."""


@dataclasses.dataclass(frozen=True)
class SweepResult:
    """A finished (or stopped) sweep: ``dataset`` (xarray, interface.md layout),
    ``folds_hz`` (located folds, reference-stage Hz), ``stop`` (why it ended),
    ``segments`` (``(from_hz, to_hz, K)`` in sweep order), ``seconds``, ``restarts``
    (``{"from_hz", "at_hz", "reason"}``: where a branch was left and the next begun)."""

    dataset: object
    folds_hz: tuple[float, ...]
    stop: str
    segments: tuple[tuple[float, float, int], ...]
    seconds: float
    restarts: tuple[dict, ...] = ()


def sweep(
    train: Train,
    gear: str | None = None,
    from_hz: float = 2000.0,
    to_hz: float = 15000.0,
    *,
    stage: str | None = None,
    linear: bool = False,
    harmonics: int | None = None,
    eta: int = 1,
    max_step_hz: float | None = None,
    points: int = 300,
    max_points: int = 3000,
    max_detour: int = MAX_DETOUR,
    smoothing: float = 0.0,
    progress: Callable[[int, float], None] | None = None,
    journal=None,
    resume: bool = False,
) -> SweepResult:
    """Frequency response of ``gear`` from ``from_hz`` to ``to_hz`` (reference-stage mesh Hz).

    **Arguments:** ``stage``: reference stage id (default: first turning stage);
    ``linear``: drop the backlash; ``harmonics``: fixed K (default: frequency-dependent,
    :func:`harmonics_rule`); ``eta``: sub-harmonic index; ``max_step_hz``: largest
    frequency step; ``points``: grid size of a linear sweep; ``max_points``: cap on a
    continuation; ``max_detour``: points a branch may go without passing the furthest
    frequency it reached before the sweep restarts beyond it (see below); ``smoothing``: corner rounding of the backlash relative to it (0: exact
    piecewise-linear, see :func:`gearjax._mesh.backlash`); ``progress(points_done,
    frequency_hz)``: called per point.

    ``journal``: a file (e.g. ``RESULTS.nc.journal``, :func:`gearjax._journal.journal_path`)
    where every finished point (continuation) or segment (linear grid) is appended as it
    is found, with what the continuation needs to go on (scaled solution, tangent, step,
    parameter, harmonics, segment); ``resume``: continue the run that the existing
    ``journal`` holds instead of starting afresh (nothing is recomputed; the result is
    that of an uninterrupted run). Without ``resume`` an existing journal is refused (it
    is an interrupted run's work); a journal of another run (train text, gear, flags) is
    refused naming the field. The caller deletes the journal once it has saved the
    results. Responses and stability are computed from the solutions, not journaled:
    in a background thread as the continuation finds them, the rest at the end
    (:class:`_PostStream`; BLAS runs on all cores but one meanwhile).

    **Segments.** K is fixed within a segment of the band (:func:`harmonics_rule`). A
    segment continued from the one before starts on their boundary, by Newton from the
    chord of the branch across it. On a machine with more than one core the last
    segment is continued in a thread from its own start while the others run, and kept
    where the branch arriving there enters it on the same orbit (:class:`_Speculation`:
    the same result with or without the thread; on the paper case 25-29 s after
    compilation instead of 31-32 s on 2 cores).

    **Branch restarts.** A continuation follows one solution branch wherever it goes.
    Where the branch closes on itself (``closed_loop``), wanders back and forth for
    ``max_detour`` points without passing the furthest frequency it reached
    (``detour``: with tooth separation on many meshes the paper case has intricate
    multi-valued regions; passing it counts by :data:`MIN_ADVANCE` of the largest step
    or more), runs away to absurd amplitudes (``runaway``, :data:`RUNAWAY`), or cannot
    go on (``step_too_small``, ``nonfinite``), the sweep keeps every point of it and
    starts a new branch a quarter of the largest step beyond that furthest frequency,
    as a sweep on a test rig jumps: Newton from the branch's furthest point, else from
    the orbit that a time integration from that point's state settles to, else a fresh
    solution (:func:`start_point`). Where no start converges the gap doubles with each
    try (the unexplored band grows, but a failed start costs a backlash homotopy,
    seconds). Each point carries its ``branch`` number and ``restarts`` lists
    where and why, so the frequencies between are known to be unexplored.

    **Raises:** ``TrainError`` for a gear where no mesh turns, an impractical ``mu``,
    an unknown stage, or backlash on an unloaded stage without ``drag_torque``.
    """
    t_start = time.perf_counter()
    _check_arguments(from_hz, to_hz, eta=eta, smoothing=smoothing, harmonics=harmonics,
                     max_step_hz=max_step_hz, points=points, max_points=max_points)
    g = train.gear(gear)
    kin = kinematics(train, g.name)
    mu = require_base(kin, train.source)
    ref = _reference_stage(train, kin, stage)
    mu_ref = mu[train.stage_ids.index(ref)]
    system = assemble(train, g.name, kin)
    if linear:
        system = dataclasses.replace(system, backlash=jnp.zeros_like(system.backlash))
    else:
        _check_unloaded(train, g, kin, system)
    min_k = _harmonics.excitation_floor(system, eta)
    if harmonics is not None:
        _harmonics.require_harmonics(system, harmonics, eta)
    cutoff_hz = _harmonics.response_cutoff_hz(system)
    segments = _segments(from_hz, to_hz, mu_ref, min_k, eta, harmonics, cutoff_hz)
    for K in sorted({k for *_, k in segments}):
        _harmonics.require_size(system, K, mu=mu)
    F_static = static_mesh_forces(system)
    runaway = RUNAWAY * (np.abs(np.asarray(F_static)) / np.asarray(system.kbar)
                         + np.asarray(system.backlash))  # RMS mesh deflection limit (m)
    run = {"train": dumps_train(train), "--gear": g.name, "--stage": ref,
           "--from": float(from_hz), "--to": float(to_hz), "--linear": bool(linear),
           "--harmonics": None if harmonics is None else int(harmonics), "--eta": int(eta),
           "--max-step": None if max_step_hz is None else float(max_step_hz),
           "--smoothing": float(smoothing)}
    if linear:
        run["--points"] = int(points)
    else:
        run["--max-points"] = int(max_points)
    log = _SweepLog.open(journal, run, resume)
    ctx = _Context(system=system, eta=eta, smoothing=smoothing, from_hz=from_hz,
                   to_hz=to_hz, mu_ref=mu_ref, max_step_hz=max_step_hz,
                   max_points=max_points, max_detour=max_detour, runaway=runaway)
    try:
        segments, truncation = _checked_segments(ctx, log, segments, F_static,
                                                 fixed=harmonics is not None, mu=mu)
    except BaseException:
        log.close()
        raise
    solver = {"method": "harmonic balance", "linear": linear, "eta": eta,
              "segments": [list(s) for s in segments], "reference_stage": ref,
              "max_step_hz": max_step_hz, "cutoff_hz": cutoff_hz,
              "truncation": truncation, "truncation_target": _harmonics.TRUNCATION_TARGET,
              "smoothing": smoothing}
    post = _PostStream(F_static)
    blas = None if linear else _blas_threads()  # a linear sweep's post-processing is after
    walk = _Walk(segments=list(segments))
    spec = None
    try:
        if linear:
            _linear_segments(ctx, walk, log, points, progress)
        while not linear and len(walk.problems) < len(walk.segments):
            entered, spec = _speculate(ctx, walk, log, post, spec, segments[-1])
            if not _walk_segment(ctx, walk, log, post, progress=progress, entered=entered):
                break
    except BaseException:
        post.close()
        raise
    finally:
        if spec is not None:
            spec.cancel()
        if blas is not None:
            blas.restore_original_limits()
        log.close()
    problems, fresh, stop, folds, restarts = (walk.problems, walk.fresh, walk.stop,
                                              walk.folds, walk.restarts)
    segments = walk.segments
    rows: list[dict] = []
    branch = 0
    for j, problem in enumerate(problems):
        if linear:
            batch = log.batch(j)
            rows.append(_point_rows(problem, jnp.asarray(batch["X"]),
                                    jnp.asarray(batch["omega"]), batch["result"], F_static))
            rows[-1]["branch"] = np.zeros(len(batch["omega"]), int)
            continue
        # a segment continued by the next ends with a point past the boundary, which the
        # next one starts on (or, where it could not, from that point): its stretch
        pts = log.points(j)
        last = len(pts) - (j + 1 < len(problems) and j + 1 not in fresh
                           and bool(log.points(j + 1)))
        branch += j in fresh and j > 0
        if last <= 0:
            continue
        rows.append(post.rows(j, problem, ctx.omega_ref, pts[:last]))
        rows[-1]["branch"] = np.full(last, branch)
    post.close()
    if not rows:
        raise RuntimeError(f"sweep produced no point: {stop}")
    data = {k: np.concatenate([r[k] for r in rows]) for k in rows[0]
            if k not in ("responses", "X")}
    data["X"] = [X for r in rows for X in r["X"]]  # K differs between segments
    data["responses"] = jax.tree.map(lambda *a: np.concatenate(a),
                                     *[r["responses"] for r in rows])
    omegas = data["omega"]
    f_ref = omegas * mu_ref / (2 * math.pi)
    stage_hz = np.outer(omegas / (2 * math.pi), np.asarray(mu, float))
    bif = bifurcations(f_ref, data["stable"], data["multipliers"], data["excluded"],
                       data["branch"])
    coords = mesh_coordinates(system)
    ds = sweep_dataset(
        data["responses"], **coords,
        mesh_frequency_hz=f_ref,
        stage_mesh_frequency_hz=stage_hz,
        input_rpm=np.array([kin.input_rpm(ref, f) for f in f_ref]),
        omega=omegas,
        result=[_hb.RESULTS[c] for c in data["result"]],
        stable=data["stable"],
        static_force=np.asarray(F_static),
        train_toml=dumps_train(train),
        gear=g.name,
        solver=solver,
        attrs={"kind": "sweep", "folds_hz": folds, "stop": stop, "reference_stage": ref,
               "bifurcations": bif, "restarts": restarts, "command": " ".join(sys.argv)},
    )
    ds["branch"] = ("point", data["branch"], {
        "units": "1", "long_name": "solution branch (a new one after each restart)"})
    ds["max_multiplier"] = ("point", data["max_multiplier"], {
        "units": "1", "long_name": "largest Floquet multiplier modulus (rigid-body excluded)"})
    ds = add_displacement_harmonics(ds, data["X"], system.dof_labels, data["K"])
    return SweepResult(dataset=ds, folds_hz=tuple(folds), stop=stop,
                       segments=tuple(segments), seconds=time.perf_counter() - t_start,
                       restarts=tuple(restarts))


# ---------------------------------------------------------------------------- parts


def _reference_stage(train, kin, stage):
    if stage is None:
        return next(s.id for s in kin.stages if s.turning)
    if stage not in train.stage_ids:
        raise fail(train.source, "--stage", stage, f"no such stage; stages are "
                   f"{list(train.stage_ids)}")
    if not kin.stage(stage).turning:
        raise fail(train.source, "--stage", stage, f"stage {stage!r} does not turn in gear "
                   f"{kin.gear!r}: its mesh frequency is 0")
    return stage


@dataclasses.dataclass(frozen=True)
class _Context:
    """What every segment of a sweep shares: the ``system`` and harmonic-balance settings,
    the band and reference stage's ``mu_ref``, the caps, and the ``runaway`` deflection
    limits ``(m,)`` (m); one harmonic-balance problem per K, built once."""

    system: object
    eta: int
    smoothing: float
    from_hz: float
    to_hz: float
    mu_ref: float
    max_step_hz: float | None
    max_points: int
    max_detour: int
    runaway: np.ndarray
    _problems: dict = dataclasses.field(default_factory=dict, compare=False, repr=False)

    def problem(self, K: int) -> _hb.HBProblem:
        """The harmonic-balance problem with ``K`` harmonics (the same object for every
        segment of that K, in either thread)."""
        if K not in self._problems:
            self._problems[K] = _hb.hb_problem(self.system, _hb.HarmonicBalance(
                n_harmonics=K, eta=self.eta, smoothing=self.smoothing))
        return self._problems[K]

    def omega(self, f_hz: float) -> float:
        """Base frequency (rad/s) at reference-stage mesh frequency ``f_hz``."""
        return 2 * math.pi * f_hz / self.mu_ref

    @property
    def omega_ref(self) -> float:
        """The continuation parameter's reference (rad/s): ``lambda = Omega / omega_ref``,
        1 at the start of the band."""
        return self.omega(self.from_hz)

    def lam(self, f_hz: float) -> float:
        return self.omega(f_hz) / self.omega_ref


@dataclasses.dataclass
class _Walk:
    """A sweep's way through its segments ``(f_a, f_b, K)``: restarts insert segments;
    ``problems`` has one per segment done; ``fresh``: segments that start a new branch
    (the others continue the one before); ``previous``: ``(K, y, lambda, before)`` of
    the last point of the segment before, ``before`` the ``(y, lambda)`` of the point
    before it (``None`` for a segment of one point); ``furthest``: that of the furthest
    point so far (a fresh branch's first guess); ``failed``: fresh starts that failed in
    a row (the restart gap doubles with each); ``done``: points kept so far (a continued
    segment's first point stands in for the previous segment's last, past the boundary,
    which the output leaves out)."""

    segments: list
    problems: list = dataclasses.field(default_factory=list)
    fresh: set = dataclasses.field(default_factory=lambda: {0})
    folds: list = dataclasses.field(default_factory=list)
    restarts: list = dataclasses.field(default_factory=list)
    stop: str = "reached_end"
    previous: tuple | None = None
    furthest: tuple | None = None
    failed: int = 0
    done: int = 0

    def handover(self, j: int) -> tuple:
        """``(previous, guess)`` for :func:`_enter_segment` at segment ``j``: the branch
        continued, or a fresh one's first guess."""
        return (None, self.furthest) if j in self.fresh else (self.previous, None)


def _linear_segments(ctx, walk, log, points, progress) -> None:
    """A linear sweep: each segment's grid of independent points, one batched call and
    one journal record per segment."""
    span = ctx.to_hz - ctx.from_hz
    for j, (f_a, f_b, K) in enumerate(walk.segments):
        problem = ctx.problem(K)
        walk.problems.append(problem)
        log.require_K(j, K)
        if log.batch(j) is None:
            n = max(2, round(points * abs(f_b - f_a) / abs(span)))
            freqs = np.linspace(f_a, f_b, n, endpoint=(f_b == walk.segments[-1][1]))
            omegas = jnp.asarray([ctx.omega(f) for f in freqs])
            sols = _solve_points(problem, omegas)
            log.add({"type": "batch", "segment": j, "K": K,
                     "omega": np.asarray(omegas, float), "X": np.asarray(sols.X, float),
                     "result": np.asarray(sols.result, np.int64)})
        batch = log.batch(j)
        walk.done += len(batch["omega"])
        if progress:
            progress(walk.done, float(batch["omega"][-1]) * ctx.mu_ref / (2 * math.pi))


def _walk_segment(ctx, walk, log, post, *, progress=None, entered=None, key=None,
                  cancel=None) -> bool:
    """Continue the next segment of ``walk`` (or take it from ``log``, where it is there)
    and decide what follows: the next segment, a restart beyond where the branch was
    left (a segment inserted), or the end. ``entered``: the segment's start ``(y,
    result code, lambda)``, found already; ``key(j)``: segment ``j``'s name in ``post``;
    ``cancel``: an event that stops the continuation (:class:`_Cancelled`).
    **Returns:** whether the walk goes on."""
    j = len(walk.problems)
    f_a, f_b, K = walk.segments[j]
    name = j if key is None else key(j)
    problem = ctx.problem(K)
    walk.problems.append(problem)
    log.require_K(j, K)
    omega_ref = ctx.omega_ref
    direction = math.copysign(1.0, ctx.to_hz - ctx.from_hz)
    if log.end(j) is None:
        param = _continuation.FrequencyParameter(problem=problem,
                                                 omega_ref=jnp.asarray(omega_ref))

        def found():
            if cancel is not None and cancel.is_set():
                raise _Cancelled
            post.feed(name, problem, omega_ref, log.points(j))

        start = walk.done
        previous, guess = walk.handover(j)
        seg_stop = _continue_segment(
            log, j, K, param, previous, ctx.lam(f_a),
            ctx.lam(f_b), _settings(ctx.max_step_hz, ctx.to_hz - ctx.from_hz, ctx.from_hz,
                                    ctx.mu_ref),
            cap=ctx.max_points - walk.done, f_a=f_a, f_ref=ctx.from_hz,
            guess=guess, runaway=ctx.runaway,
            max_detour=ctx.max_detour, entered=entered, found=found,
            progress=(lambda i, lam: progress(start + i + 1, lam * ctx.from_hz))
            if progress else None)
        log.add({"type": "end", "segment": j, "stop": seg_stop})
    elif progress and log.points(j):  # taken from the journal
        progress(walk.done + len(log.points(j)), log.points(j)[-1]["lam"] * ctx.from_hz)
    seg_stop = log.end(j)["stop"]
    pts = log.points(j)
    post.feed(name, problem, omega_ref, pts)
    if pts:
        walk.folds += [p["fold_lam"] * ctx.from_hz for p in pts if p["fold"]]
        walk.done += len(pts) - (1 if walk.done and j not in walk.fresh else 0)
        before = (pts[-2]["y"], pts[-2]["lam"]) if len(pts) > 1 else None
        walk.previous = (K, pts[-1]["y"], pts[-1]["lam"], before)
        far = max(pts, key=lambda p: p["lam"] * direction)
        walk.furthest = (K, far["y"], far["lam"])
    walk.failed = walk.failed + 1 if seg_stop.startswith("no converged") else 0
    restartable = seg_stop in RESTART_STOPS or seg_stop.startswith("no converged")
    if restartable and len(walk.restarts) < MAX_RESTARTS and walk.done < ctx.max_points:
        lams = [ctx.lam(f_a)] + [p["lam"] for p in pts]
        reached = (max if direction > 0 else min)(lams) * ctx.from_hz
        at = reached + direction * _restart_step(
            ctx.max_step_hz, ctx.to_hz - ctx.from_hz) * 2 ** walk.failed
        walk.restarts.append({"from_hz": float(reached), "at_hz": float(at),
                              "reason": seg_stop})
        if (at - f_b) * direction < 0:
            walk.segments.insert(j + 1, (float(at), f_b, K))
        elif j + 1 < len(walk.segments):
            walk.restarts[-1]["at_hz"] = walk.segments[j + 1][0]
        else:
            walk.restarts.pop()
            walk.stop = seg_stop
            return False
        walk.fresh.add(j + 1)
        return True
    if seg_stop != "reached_end":
        walk.stop = seg_stop
        return False
    return True


class _Cancelled(Exception):
    """A speculative continuation was called off (:class:`_Speculation`)."""


SAME_ORBIT = 1e-6
"""Two converged starts are the same orbit where their scaled unknowns differ by at most
this much relative to the largest (Newton converges to ``1e-9``; distinct orbits of the
paper case at one frequency differ by percents)."""


class _Speculation:
    """The last segment of a sweep continued, in a thread, from its own start while the
    segments before it run; adopted where the branch arriving from them enters it on
    the same orbit.

    On the paper case the last segment (K = 32, 5.48-15 kHz) is about a third of the
    continuation, and on 2 cores the continuation of the others keeps one core busy
    and the post-processing half of the other. Measured there (2 cores, backlash sweep,
    second runs interleaved with the code before): 28.0 and 25.2 s against 31.5 and
    31.0 s; the speculation had finished when the walk reached it. The rule is the same with or without a
    thread (and so on any machine, for an uninterrupted or a resumed run): the walk from
    the last segment on is that from its *fresh start* (Newton from the linear guess at
    its first frequency) whenever the start that the walk arriving there finds (the
    branch continued, or a restart) is that orbit (:data:`SAME_ORBIT`); otherwise the
    walk goes on from the start it found, as without speculation. Either way each
    point is a converged point of the branch that arrives; adopting only changes where
    the continuation of that branch started, within Newton's tolerance. Adopted points
    go to the journal together, as if the walk had found them there; a run interrupted
    before that repeats the speculation when resumed."""

    def __init__(self, ctx, segment, post):
        self.ctx, self.segment, self.post = ctx, segment, post
        self.walk = _Walk(segments=[segment])
        self.log = _SweepLog([])
        self.entered = None  # (y, result code, lambda) of the fresh start
        self.error = None
        self._cancel = threading.Event()
        self._started = threading.Event()
        self._thread = None

    def start(self) -> _Speculation:
        """Run in a background thread (``gearjax-speculation``)."""
        self._thread = threading.Thread(target=self._run, name="gearjax-speculation",
                                        daemon=True)
        self._thread.start()
        return self

    def _run(self):
        try:
            self._enter()
            self._started.set()
            self._continue()
        except _Cancelled:
            pass
        except BaseException as e:  # re-raised where the walk would adopt this one
            self.error = e
        finally:
            self._started.set()

    def _enter(self):
        f_a, _, K = self.segment
        problem = self.ctx.problem(K)
        omega = jnp.asarray(self.ctx.omega(f_a))
        sol = _newton_jit(problem, omega, _hb.linear_guess(problem, omega))
        self.entered = (sol.y, int(sol.result), self.ctx.lam(f_a))

    def _continue(self):
        if self.entered[1] != _hb.CONVERGED:
            return
        while len(self.walk.problems) < len(self.walk.segments):
            if self._cancel.is_set():
                raise _Cancelled
            first = not self.walk.problems
            if not _walk_segment(self.ctx, self.walk, self.log, self.post,
                                 entered=self.entered if first else None,
                                 key=self._key, cancel=self._cancel):
                break

    @staticmethod
    def _key(j):
        return ("speculation", j)

    def cancel(self) -> None:
        """Call it off and drop its chunks. The thread stops at its next point or
        segment, not inside a restart's start (a time integration, a homotopy)."""
        self._cancel.set()
        for j in range(len(self.walk.segments)):
            self.post.drop(self._key(j))

    def adopt(self, walk, entered, log) -> bool:
        """Whether the walk's start ``entered`` ``(y, code, lambda)`` of the next segment
        (this one's) is this one's orbit, at its first frequency; if so, once it is
        finished, its records are appended to ``log`` as that segment and those after it
        (the walk then takes them from there) and its post-processing is handed over. A
        speculation that ran past caps the walk would have hit (``max_points``,
        :data:`MAX_RESTARTS`) is not adopted."""
        if self._thread is None:
            self._enter()
        else:
            self._started.wait()
        if self.error is not None and self.entered is None:
            raise self.error
        y, code, lam = entered
        y_spec, code_spec, lam_spec = self.entered
        same = code == code_spec == _hb.CONVERGED and lam == lam_spec and float(
            jnp.max(jnp.abs(y - y_spec))) <= SAME_ORBIT * max(1.0, float(jnp.max(jnp.abs(y))))
        if not same:
            self.cancel()
            return False
        if self._thread is None:
            self._continue()
        else:
            self._thread.join()
        if self.error is not None:
            raise self.error
        if not (walk.done + self.walk.done + 2 < self.ctx.max_points
                and len(walk.restarts) + len(self.walk.restarts) < MAX_RESTARTS):
            self.cancel()
            return False
        j0 = len(walk.problems)
        for j in range(len(self.walk.problems)):
            for rec in self.log.points(j) + [self.log.end(j)]:
                log.add({**rec, "segment": j0 + j})
            self.post.rename(self._key(j), j0 + j)
        return True


def _speculate(ctx, walk, log, post, spec, last):
    """Before the walk's next segment: start the speculation on the sweep's ``last``
    segment ``(f_a, f_b, K)`` (:class:`_Speculation`) while earlier segments are still
    to compute, on a machine with a core for it; at the last segment, find the walk's
    start there and adopt or call off the speculation. **Returns:** ``(entered, spec)``:
    the start found (``None`` where the speculation was adopted or nothing is to
    compute) and the speculation still running."""
    j = len(walk.problems)
    if len(walk.segments) < 2 or log.end(j) is not None:
        return None, spec
    target = walk.segments.index(last) if last in walk.segments[1:] else -1
    if j < target:
        if spec is None and post_threads() > 1:
            spec = _Speculation(ctx, last, post).start()
        return None, spec
    if j != target or log.points(j):
        return None, spec
    f_a, _, K = last
    previous, guess = walk.handover(j)
    entered = _enter_segment(ctx.problem(K), previous, ctx.lam(f_a), ctx.omega_ref, guess)
    spec = spec or _Speculation(ctx, last, post)
    adopted = spec.adopt(walk, entered, log)
    return (None if adopted else entered), None


class _SweepLog:
    """A sweep's finished work: records in memory and, with a journal, appended to it
    (``_journal``) as they are found. Records: ``{"type": "point", "segment", "i", "K",
    "y", "lam", "ty", "tlam", "h", "steps", "fold", "fold_lam"}`` per continuation
    point, ``{"type": "end", "segment", "stop"}`` when a segment ends, ``{"type":
    "batch", "segment", "K", "omega", "X", "result"}`` per linear segment."""

    def __init__(self, records: list[dict], writer=None):
        self._writer = writer
        self._points: dict[int, list[dict]] = {}
        self._other: dict[tuple[str, int], dict] = {}
        for n, rec in enumerate(records):
            self._index(rec, writer.path if writer else None, n)

    @classmethod
    def open(cls, journal, run: dict, resume: bool) -> _SweepLog:
        if journal is None:
            if resume:
                raise fail("command line", "--resume", True,
                           "needs a journal to resume from (the command line keeps it next "
                           "to --out FILE, as FILE.journal)")
            return cls([])
        path = pathlib.Path(journal)
        head = _journal.header("sweep", run)
        _journal.refuse_if_busy(path)
        if path.exists():
            if not resume:
                raise TrainError(
                    f"{path}: a journal of an interrupted run is there: add --resume to "
                    "continue it, or delete it to start afresh")
            found, records, size = _journal.read(path)
            if found is not None:
                _journal.check(path, found, head)
                return cls(records, _journal.Writer.append_to(path, size))
        if resume:
            print(f"gearjax: {path}: no journal to resume; starting from the beginning",
                  file=sys.stderr, flush=True)
        return cls([], _journal.Writer.create(path, head))

    def _index(self, rec: dict, path, n: int) -> None:
        kind, j = rec.get("type"), rec.get("segment")
        if kind == "point":
            pts = self._points.setdefault(j, [])
            if rec.get("i") != len(pts) or ("end", j) in self._other:
                raise fail(str(path), f"record {n + 1}", f"segment {j} point {rec.get('i')}",
                           f"out of order (expected point {len(pts)}): the journal was "
                           "changed after it was written; delete it to start afresh")
            pts.append(rec)
        elif kind in ("end", "batch"):
            self._other[(kind, j)] = rec
        else:
            raise fail(str(path), f"record {n + 1}", kind, "is not a sweep record")

    def add(self, rec: dict) -> None:
        if self._writer is not None:
            self._writer.append(rec)
        self._index(rec, self._writer.path if self._writer else None, -1)

    def points(self, j: int) -> list[dict]:
        return self._points.get(j, [])

    def end(self, j: int) -> dict | None:
        return self._other.get(("end", j))

    def batch(self, j: int) -> dict | None:
        return self._other.get(("batch", j))

    def require_K(self, j: int, K: int) -> None:
        """Refuse a journal whose segment ``j`` was solved with another K than this run's
        ``K`` for it (e.g. a truncation check that decided otherwise on another machine),
        before any of its records is replayed."""
        recs = self.points(j)[:1] + [r for r in [self.batch(j)] if r is not None]
        for rec in recs:
            if int(rec["K"]) != int(K):
                where = self._writer.path if self._writer else "journal"
                raise fail(str(where), f"segment {j} K", int(rec["K"]),
                           f"this run's truncation check chose K = {K} for that segment: "
                           "delete the journal to start afresh")

    def close(self) -> None:
        if self._writer is not None:
            self._writer.close()


def _continue_segment(log, j, K, param, previous, lam_a, lam_b, settings, *, cap, f_a, f_ref,
                      progress, max_detour=MAX_DETOUR, guess=None, runaway=None, found=None,
                      entered=None):
    """Continue segment ``j`` from ``lam_a`` to ``lam_b`` (at most ``cap`` points), or the
    rest of it after the points ``log`` holds; every point goes to ``log``. The resumed
    state is the saved point with its tangent and step, and the factors of its bordered
    Jacobian rebuilt as the continuation built them (last row: the tangent before), so
    the points that follow are those of an uninterrupted run. ``found()`` is called after
    each new point went to ``log``; ``entered``: the start ``(y, result code, lambda)``
    where it was found already (:func:`_enter_segment` otherwise). **Returns:** why the
    segment stopped (``_continuation.STOP_REASONS``, or no converged start)."""
    have = log.points(j)
    offset = max(len(have) - 1, 0)
    direction = float(np.sign(lam_b - lam_a))
    # a resumed continuation only knows the points from where it resumes; the
    # closed-loop check of continue_branch compares with every point of the segment,
    # so the journaled ones are checked here too
    trace = _segment_trace(have, cap) if have else None
    # the furthest lambda reached and the points since (detour check), over saved points too
    front = {"lam": lam_a, "since": 0}
    min_advance = MIN_ADVANCE * float(settings.max_dlambda)

    def detour(lam):
        if (lam - front["lam"]) * direction > min_advance:
            front["lam"], front["since"] = lam, 0
        else:
            front["since"] += 1
        return front["since"] >= max_detour

    for p in have:
        detoured = detour(p["lam"])

    def on_point(i, state):
        if i == 0 and have:
            return None  # the saved point the continuation resumes from
        fold_lam = float(state.fold_lam)
        y, lam = np.asarray(state.y, float), float(state.lam)
        t = np.concatenate([np.asarray(state.ty), [float(state.tlam)]])
        log.add({"type": "point", "segment": j, "i": offset + i, "K": K, "y": y, "lam": lam,
                 "ty": t[:-1], "tlam": float(t[-1]), "h": float(state.h),
                 "steps": int(state.steps), "fold": bool(state.fold),
                 "fold_lam": fold_lam if math.isfinite(fold_lam) else None})
        if found:
            found()
        if progress:
            progress(offset + i, lam)
        if trace is not None and (lam - lam_b) * direction < 0:
            z = np.append(y, lam)
            if trace.revisits(z, t):
                raise _ClosedLoop
            trace.add(z, t)
        if runaway is not None and _ran_away(param.problem, y, runaway):
            return "runaway"
        return "detour" if detour(lam) and (lam - lam_b) * direction < 0 else None

    if not have:
        y, code, lam = entered or _enter_segment(param.problem, previous, lam_a,
                                                 float(param.omega_ref), guess)
        if code != _hb.CONVERGED:
            return f"no converged start at {f_a:.1f} Hz ({_hb.RESULTS[code]})"
        return _continuation.continue_branch(param, y, lam, lam_b, settings, max_points=cap,
                                             on_point=on_point).stop
    last = have[-1]
    # why continue_branch stopped after the last saved point, in its order of checks
    if (last["lam"] - lam_b) * direction >= 0:
        return "reached_end"
    if trace is not None and trace.closed:
        return "closed_loop"
    if runaway is not None and _ran_away(param.problem, last["y"], runaway):
        return "runaway"
    if detoured:
        return "detour"
    if len(have) >= cap:
        return "max_points"
    # one saved point: the start state is rebuilt from it exactly as it was first built
    state = None if len(have) == 1 else _arc_state(
        param, jnp.asarray(last["y"]), jnp.asarray(last["lam"], float),
        jnp.asarray(last["ty"]), jnp.asarray(last["tlam"], float),
        jnp.asarray(last["h"], float), jnp.asarray(have[-2]["ty"]),
        jnp.asarray(have[-2]["tlam"], float), single=settings.single)
    try:
        return _continuation.continue_branch(param, jnp.asarray(last["y"]), last["lam"], lam_b,
                                             settings, max_points=cap - len(have) + 1,
                                             on_point=on_point, state=state).stop
    except _ClosedLoop:
        return "closed_loop"


class _ClosedLoop(Exception):
    """A resumed segment came back onto a stretch traced before it was interrupted."""


def _segment_trace(have, cap):
    """The closed-loop trace of ``continue_branch`` (``_continuation._Trace``, where the
    continuation has one) over the saved points ``have`` of a segment; ``.closed``: the
    last saved point already closed the loop. ``None`` without such a check."""
    cls = getattr(_continuation, "_Trace", None)
    if cls is None:
        return None
    trace = cls(max(cap, len(have)), have[0]["y"].size + 1)
    trace.closed = False
    for k, p in enumerate(have):
        z, t = np.append(p["y"], p["lam"]), np.append(p["ty"], p["tlam"])
        if k and trace.revisits(z, t):
            trace.closed = True
            break
        trace.add(z, t)
    return trace


@functools.partial(jax.jit, static_argnames="single")
def _arc_state(param, y, lam, ty, tlam, h, ty_before, tlam_before, single):
    """The continuation state at an accepted point ``(y, lam)`` with tangent ``(ty, tlam)``
    and next step ``h``: as ``arclength_step`` leaves it, with the bordered Jacobian
    factorised with the tangent of the point before in its last row (the corrector
    of the next step reuses those factors)."""
    factors = _continuation.tangent_factors(param, y, lam, ty_before, tlam_before, single,
                                            fallback=jnp.append(ty, tlam))[2]
    return _continuation.ArcState(
        y=y, lam=lam, ty=ty, tlam=tlam, h=h, accepted=jnp.asarray(True),
        fold=jnp.asarray(False), fold_lam=jnp.asarray(jnp.nan, float), steps=jnp.asarray(0),
        factors=factors)


def _check_unloaded(train, g, kin, system):
    back = np.asarray(system.backlash)
    for s in kin.stages:
        rows = [i for i, grp in enumerate(system.mesh_group) if grp == s.id]
        if not s.loaded and np.any(back[rows] > 0) and float(g.drag_torque) == 0.0:
            raise fail(train.source, f"gears.{g.name}.drag_torque", 0.0,
                       f"stage {s.id!r} carries no static load in gear {g.name!r} (a central "
                       "member is free), so with backlash its meshes rattle at an undetermined "
                       "mean position: give the gear a drag_torque, or sweep with --linear")


def _segments(from_hz, to_hz, mu_ref, min_k, eta, fixed, cutoff_hz):
    """``(f_a, f_b, K)`` in sweep order; K constant on each: ``fixed``, else the first
    choice of :func:`gearjax._harmonics.harmonics_rule` at response base frequencies
    ``f / mu_ref / eta`` with the system's ``cutoff_hz``, never below ``min_k``."""
    if fixed is not None:
        return [(from_hz, to_hz, int(fixed))]
    lo, hi = sorted((from_hz, to_hz))
    edges = np.geomspace(lo, hi, 65)
    ks = [harmonics_rule(f / mu_ref / eta, min_k, eta, cutoff_hz=cutoff_hz)
          for f in edges[:-1]]
    segs = []
    for f_a, f_b, k in zip(edges[:-1], edges[1:], ks):
        if segs and segs[-1][2] == k:
            segs[-1] = (segs[-1][0], f_b, k)
        else:
            segs.append((f_a, f_b, k))
    segs = [(float(a), float(b), k) for a, b, k in segs]
    if from_hz > to_hz:
        segs = [(b, a, k) for a, b, k in reversed(segs)]
    segs[0] = (float(from_hz), segs[0][1], segs[0][2])
    segs[-1] = (segs[-1][0], float(to_hz), segs[-1][2])
    return segs


def _check_arguments(from_hz, to_hz, *, eta, smoothing, harmonics, max_step_hz, points,
                     max_points) -> None:
    """Refuse arguments that cannot describe a sweep, before any work (``TrainError``
    named after the command-line flags)."""
    def integer(value) -> bool:
        return isinstance(value, numbers.Integral) and not isinstance(value, bool)

    def real(value) -> bool:
        return isinstance(value, numbers.Real) and not isinstance(value, bool)

    for name, f in (("--from", from_hz), ("--to", to_hz)):
        if not (real(f) and f > 0 and math.isfinite(f)):
            raise fail("command line", name, f, "must be a positive mesh frequency in Hz")
    if from_hz == to_hz:
        raise fail("command line", "--to", to_hz, "must differ from --from")
    if not integer(eta) or eta < 1:
        raise fail("command line", "--eta", eta, "must be an integer >= 1")
    if not (real(smoothing) and 0.0 <= smoothing < 1.0):
        raise fail("command line", "--smoothing", smoothing,
                   "must be >= 0 (0: exact backlash) and < 1 (relative to the backlash)")
    if harmonics is not None and (not integer(harmonics) or harmonics < 1):
        raise fail("command line", "--harmonics", harmonics, "must be an integer >= 1")
    if max_step_hz is not None and not (real(max_step_hz) and max_step_hz > 0
                                        and math.isfinite(max_step_hz)):
        raise fail("command line", "--max-step", max_step_hz,
                   "must be a positive frequency step in Hz (omit it for 1/100 of the band)")
    if not integer(points) or points < 2:
        raise fail("command line", "--points", points, "must be an integer >= 2")
    if not integer(max_points) or max_points < 2:
        raise fail("command line", "--max-points", max_points, "must be an integer >= 2")


def _checked_segments(ctx, log, segments, F_static, *, fixed: bool, mu):
    """The segments with K checked a posteriori, and the estimates ``[{"from_hz", "K",
    "change", "K_check", "backlash"}]`` (``backlash``: whether the checked point had it).

    At each segment's first frequency the point is solved with K and with 2K
    (:func:`gearjax._harmonics.truncation_change`); where the relative change of a
    mesh's RMS force exceeds ``TRUNCATION_TARGET`` K doubles (while the check at twice
    it is affordable, :func:`gearjax._harmonics.check_affordable`) and the check repeats.
    A ``fixed`` K (the user's) is checked, warned about and kept. A resumed run checks
    again (the same decisions on the same machine); a journal segment solved with
    another K is refused where the walk reaches it (:meth:`_SweepLog.require_K`)."""
    target = _harmonics.TRUNCATION_TARGET
    out, estimates = [], []
    for f_a, f_b, K in segments:
        while True:
            skip = _harmonics.check_affordable(ctx.system, K)
            if skip is not None:
                estimates.append({"from_hz": float(f_a), "K": int(K), "K_check": None,
                                  "change": None, "skipped": skip})
                warnings.warn(_harmonics.TruncationWarning(
                    f"sweep: segment from {f_a:.1f} Hz with K = {K}: truncation not "
                    f"checked ({skip})"))
                break
            K2 = 2 * K
            change, backlash = _truncation_at(ctx, K, f_a, F_static)
            estimates.append({"from_hz": float(f_a), "K": int(K), "K_check": int(K2),
                              "change": None if not math.isfinite(change) else change,
                              "backlash": backlash})
            if not math.isfinite(change):
                warnings.warn(_harmonics.TruncationWarning(
                    f"sweep: segment from {f_a:.1f} Hz with K = {K}: truncation not checked "
                    f"(no converged point there with K = {K} and {K2})"))
                break
            if fixed and change > target:
                warnings.warn(_harmonics.TruncationWarning(
                    f"sweep: segment from {f_a:.1f} Hz with K = {K}: truncation estimate "
                    f"{change:.2%} (RMS mesh force change against K = {K2}; target "
                    f"{target:.1%}): omit --harmonics to let the sweep choose K"))
            if change <= target or fixed:
                break
            K = K2  # affordable: the check above solved it
        out.append((f_a, f_b, int(K)))
    return out, estimates


def _truncation_at(ctx, K: int, f_hz, F_static) -> tuple[float, bool]:
    """``(change, with backlash)``: the truncation estimate of the point at ``f_hz`` with
    K against 2K (the sweep's problems of those K), Newton from the linear guess; where
    that fails with backlash (tooth separation far from contact), of the system without
    backlash (the check then judges the time-varying stiffness only, and says so:
    ``False``)."""
    omega = ctx.omega(f_hz)
    problem, wide = ctx.problem(K), ctx.problem(2 * K)
    sol = _newton_jit(problem, jnp.asarray(omega), _hb.linear_guess(problem, omega))
    if int(sol.result) != _hb.CONVERGED and problem.system.has_backlash:
        lin = dataclasses.replace(problem.system,
                                  backlash=jnp.zeros_like(problem.system.backlash))
        problem, wide = (_hb.hb_problem(lin, p.settings) for p in (problem, wide))
        sol = _newton_jit(problem, jnp.asarray(omega), _hb.linear_guess(problem, omega))
    backlash = problem.system.has_backlash
    if int(sol.result) != _hb.CONVERGED:
        return math.inf, backlash
    return _harmonics.truncation_change(problem, wide, sol.y, omega, F_static), backlash


def _ran_away(problem, y, limit) -> bool:
    """Whether the RMS alternating deflection of a mesh, from the scaled unknowns ``y``,
    exceeds ``limit`` ``(m,)`` (m): see :data:`RUNAWAY`."""
    X = np.asarray(y).reshape(problem.shape) * np.asarray(problem.x_scale)
    deflection = X[1:] @ np.asarray(problem.system.W).T  # cos/sin amplitudes, (2K, m)
    return bool(np.any(np.sqrt(0.5 * np.sum(deflection ** 2, axis=0)) > limit))


def _restart_step(max_step_hz, span_hz) -> float:
    """Frequency step (Hz, > 0) from the furthest point of a branch to the next branch's
    start: a quarter of the largest continuation step (doubled per failed start by the
    caller)."""
    return 0.25 * (max_step_hz or abs(span_hz) / 100)


def _settings(max_step_hz, span_hz, f_ref, mu_ref):
    """Continuation settings: parameter steps of at most ``max_step_hz`` (default 1/100 of
    the band), in units of the start frequency; the step grows after at most 6 corrector
    iterations (paper case with backlash, 2-15 kHz, whole run with compilation, on 2
    cores: 820 points in 75 s with 6, 1139 in 82 s with 5, 833 in 77 s with 7); the
    corrector's LU in single precision (``Settings.single``: a continuation step at
    K = 64 on the paper case 32 ms instead of 40, the same iterations and folds)."""
    max_step_hz = max_step_hz or abs(span_hz) / 100
    return _continuation.Settings(step=0.02, max_step=0.5, fast=6, single=True,
                                  max_dlambda=float(max_step_hz / f_ref), fold_step=1e-3)


def _solve_points(problem, omegas):
    """Independent solutions at the base frequencies ``omegas`` ``(P,)`` (rad/s), from the
    linear guess: one factorisation each without backlash (``_hb.solve_linear``), Newton
    with backlash. One point after the other (``lax.map``): vmapped, Newton's batch of
    dense factorisations ran 1.3x slower at K = 64 (1.04x at K = 32) on 2 cores."""
    if problem.system.has_backlash:
        return _newton_points(problem, omegas)
    return _linear_points(problem, omegas)


@jax.jit
def _newton_points(problem, omegas):
    return jax.lax.map(lambda w: _hb.solve_hb(problem, w), omegas)


@jax.jit
def _linear_points(problem, omegas):
    return jax.lax.map(lambda w: _hb.solve_linear(problem, w), omegas)


def _enter_segment(problem, previous, lam, omega_ref, guess=None):
    """``(y, result code, lambda)``: scaled unknowns with this segment's harmonics,
    converged at ``lambda``, where the segment starts.

    Continuing ``previous`` ``(K, y, lambda, before)`` (the last point of the segment
    before, which lies past ``lam``, the boundary, and the point before it): at ``lam``
    itself, by Newton from the chord between the two, so that the next segment starts
    on the boundary (where a speculation on it, :class:`_Speculation`, starts too);
    where that Newton fails, at the last point's own ``lambda`` from it. A fresh branch
    starts at ``lam``, its first guess ``guess`` (the furthest point of the branch
    before, as a rig's response jumps from it) and then :func:`start_point` from that
    point's state."""
    if previous is None:
        state = None
        if guess is not None:
            K_old, y_old, _ = guess
            y = resize_harmonics(y_old, K_old, problem)
            sol = _newton_jit(problem, jnp.asarray(lam * omega_ref), y)
            if int(sol.result) == _hb.CONVERGED:
                return sol.y, _hb.CONVERGED, lam
            state = _time_domain.hb_initial_state(y.reshape(problem.shape) * problem.x_scale,
                                                  lam * omega_ref, problem.settings.eta)
        return (*start_point(problem, lam * omega_ref, state), lam)
    K_old, y_old, lam_old, before = previous
    if before is not None and (before[1] - lam) * (lam_old - lam) < 0:
        w = (lam - before[1]) / (lam_old - before[1])
        chord = (1 - w) * np.asarray(before[0]) + w * np.asarray(y_old)
        sol = _newton_jit(problem, jnp.asarray(lam * omega_ref),
                          resize_harmonics(chord, K_old, problem))
        if int(sol.result) == _hb.CONVERGED:
            return sol.y, _hb.CONVERGED, lam
    sol = _newton_jit(problem, jnp.asarray(lam_old * omega_ref),
                      resize_harmonics(y_old, K_old, problem))
    return sol.y, int(sol.result), lam_old


def start_point(problem, omega, state=None):
    """``(y, result code)`` at ``omega``: Newton from the linear, in-contact guess; with
    backlash, when that fails, :func:`backlash_start`. With a ``state`` ``(x0, v0)``
    (where a branch left off) the time integration starts from it, and before Newton."""
    backlash = problem.system.has_backlash
    if state is not None and backlash:
        sol = settled_start(problem, omega, state)
        if int(sol.result) == _hb.CONVERGED:
            return sol.y, _hb.CONVERGED
    sol = _newton_jit(problem, jnp.asarray(omega), _hb.linear_guess(problem, omega))
    if int(sol.result) != _hb.CONVERGED and backlash:
        # the integration from ``state`` failed already: straight to the homotopy
        sol = backlash_start(problem, omega) if state is None else _backlash_homotopy(
            problem, omega)
    return sol.y, int(sol.result)


def backlash_start(problem, omega) -> _hb.HBSolution:
    """A periodic solution with backlash where Newton from the linear guess fails (tooth
    separation far from the in-contact response): Newton from the orbit that a time
    integration settles to (:func:`settled_start`), else the homotopy in backlash 0 -> b
    (:func:`_backlash_homotopy`, a continuation of a few hundred points at the full K:
    measured on the paper case at 3306 Hz, K = 64, 374 points and 54 s against 0.4 s for
    the integration and Newton, which reach the same orbit within 7e-12)."""
    sol = settled_start(problem, omega)
    if int(sol.result) == _hb.CONVERGED:
        return sol
    return _backlash_homotopy(problem, omega)


SETTLE_PERIODS = 40
"""Base periods a start by time integration (:func:`settled_start`) integrates at most.
On the paper case the mesh damping settles the orbit within 5 periods at 3306 Hz; at
6.9 and 9.7 kHz it had not settled to ``100 SETTLE_RTOL`` after 40, yet Newton from
the last period converged in 3 and 4 steps."""

SETTLE_RTOL = 1e-6
"""Integration tolerance of :func:`settled_start`: its orbit is only Newton's first
guess (the periodicity check is at ``100 SETTLE_RTOL``)."""


def settled_start(problem, omega, state=None) -> _hb.HBSolution:
    """Newton from the orbit that a time integration at ``omega`` settles to (a stable one,
    as a test rig's response settles after a jump), from ``state`` ``(x0, v0)`` or the
    static contact state (``_time_domain.simulate``: Dopri8 at :data:`SETTLE_RTOL`, at
    most :data:`SETTLE_PERIODS` base periods; the last ``eta`` periods give the
    harmonics). A solver failure is returned as a ``MAX_STEPS`` solution at the start
    guess."""
    K, eta = problem.settings.n_harmonics, problem.settings.eta
    settings = _time_domain.TimeDomain(
        rtol=SETTLE_RTOL, atol=SETTLE_RTOL, periodic_tol=100 * SETTLE_RTOL,
        max_periods=SETTLE_PERIODS * eta, sample_periods=eta,
        n_samples=-(-4 * (K + 1) // eta))
    x0, v0 = (None, None) if state is None else state
    tr = _time_domain.simulate(problem.system, omega, x0=x0, v0=v0, settings=settings)
    X = _aft.analysis(tr.x.T, K)
    y = (X / problem.x_scale).reshape(-1)
    if int(tr.result) > _time_domain.NOT_PERIODIC or not bool(jnp.all(jnp.isfinite(y))):
        y = _hb.linear_guess(problem, omega)
        return _hb.HBSolution(X=y.reshape(problem.shape) * problem.x_scale, y=y,
                              omega=jnp.asarray(omega, float), result=jnp.asarray(_hb.MAX_STEPS),
                              steps=jnp.asarray(0), residual_norm=jnp.asarray(jnp.inf))
    return _newton_jit(problem, jnp.asarray(omega), y)


def resize_harmonics(y, K_old: int, problem):
    """Scaled unknowns of ``K_old`` harmonics padded with zeros or truncated to
    ``problem``'s K (flat)."""
    C, n = problem.shape
    old = np.asarray(y).reshape(2 * K_old + 1, n)
    new = np.zeros((C, n))
    rows = min(C, old.shape[0])
    new[:rows] = old[:rows]
    return jnp.asarray(new.reshape(-1))


_newton_jit = _hb.newton_jit


def _backlash_homotopy(problem, omega):
    """Continue from the linear solution in backlash scale 0 -> 1 at fixed ``omega``."""
    param = _continuation.SystemParameter(problem=problem, omega_value=jnp.asarray(omega),
                                          where=lambda s: s.backlash)
    lin = _hb.linear_guess(problem, omega)
    start = _newton_jit(param.split(0.0)[0], jnp.asarray(omega), lin)
    branch = _continuation.continue_branch(param, start.y, 0.0, 1.0,
                                           _continuation.Settings(max_dlambda=0.05), 500)
    sol = _newton_jit(problem, jnp.asarray(omega), jnp.asarray(branch.y[-1]))
    return sol


POST_CHUNK = 8
"""Points per compiled call of the post-processing (responses + Floquet). The step
exponentials of a chunk of points (``_stability.CHUNK`` steps each) stay in cache:
measured on 2 cores, responses and Floquet stability of the paper case cost 27 ms a point
at K = 64 in chunks of 8 points and 26 ms in chunks of 16 (13 and 12 ms at K = 32), with
the single-point default of Floquet steps; 11.1 and 5.3 ms in chunks of 8 with the
sweep's (:data:`SWEEP_FLOQUET_STEPS`)."""


SWEEP_FLOQUET_STEPS = 16
"""Floquet steps per period of the highest harmonic in a sweep's stability (the power of
two above, at least 256: :func:`gearjax._stability.floquet_steps`, whose default for a
single point is 32): half the steps and half the time of that default. The multipliers
of a truncated orbit are only as accurate as the orbit. Measured on 75 orbits of the
paper's backlash sweep (2-15 kHz, every 8th point at K = 64, every 12th above; Newton at
2K from each): where teeth separate (62 orbits) the largest retained ``|mu|`` changes
by 1.3e-2 from K to 2K (median; quartiles 1.8e-3 and 4e-2) and by 7.2e-5 from the
halved steps to four times the default (median; 2.5e-3 at most), the latter smaller in
61 of the 62; where none separates, 4e-6 at most. Over all 843 points of that sweep,
against four times the default steps: 2.5e-3 / 2.6e-5 / 6.9e-3 relative at most at K =
64 / 48 / 32 (3.4e-4 / 3e-6 / 7.6e-4 with the default), 1.9e-4 / - / 1.3e-3 where ``|mu|``
is within 1e-2 of 1, no verdict changed; post-processing 6.4 s instead of 11.7 s."""


def post_threads() -> int:
    """Threads that post-process the chunks of a sweep at once: one per CPU core this
    process may run on. One chunk's program keeps about one core busy (its batched
    products of 28 x 28 matrices are not split across XLA's threads): on 2 cores two
    threads took 0.74 s for 64 points of the paper case at K = 64, one 1.55 s."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def _point_rows(problem, Xs, omegas, results, F_static, done=()):
    """Responses and stability of a batch of solutions ``Xs`` ``(P, C, n)`` at base
    frequencies ``omegas`` ``(P,)`` (rad/s), in chunks of :data:`POST_CHUNK` points (the
    last padded by repeating its final point: one compilation per K),
    :func:`post_threads` chunks at a time. ``done``: the outputs of :func:`_post_chunk`
    for the leading chunks, computed before (:class:`_PostStream`). The chunk programs
    call no LAPACK routine (``_stability.verdict_basis``); the eigenvalues of the
    monodromy matrices are NumPy's."""
    P = len(omegas)
    pad = -P % POST_CHUNK
    Xs, omegas_p = jnp.asarray(Xs), jnp.asarray(omegas)
    if pad:
        Xs = jnp.concatenate([Xs, jnp.repeat(Xs[-1:], pad, axis=0)])
        omegas_p = jnp.concatenate([omegas_p, jnp.repeat(omegas_p[-1:], pad)])
    basis = verdict_basis(problem)
    size = POST_CHUNK

    def chunk(i):
        return _post_chunk(problem, basis, Xs[i:i + size], omegas_p[i:i + size], F_static)

    starts = range(len(done) * size, P + pad, size)
    parts = list(done)
    if starts and _signature((problem, basis, Xs[:size], omegas_p[:size], F_static)) \
            not in _POST_COMPILED:  # the first call compiles: alone, before the threads
        parts.append(chunk(starts[0]))
        starts = starts[1:]
    if starts:
        with concurrent.futures.ThreadPoolExecutor(min(post_threads(), len(starts))) as pool:
            parts += list(pool.map(chunk, starts))
    resp, stab = jax.tree.map(lambda *a: np.concatenate(a)[:P], *parts)
    return {"responses": resp, "omega": np.asarray(omegas), "result": np.asarray(results),
            "X": list(np.asarray(Xs[:P])), "K": np.full(P, problem.settings.n_harmonics),
            "stable": np.asarray(stab.stable), "max_multiplier": np.asarray(stab.max_abs),
            "multipliers": np.asarray(stab.multipliers), "excluded": np.asarray(stab.excluded)}


def _post_chunk(problem, basis, Xs, omegas, F_static):
    """Responses and stability verdicts (host arrays) of one chunk of :data:`POST_CHUNK`
    solutions ``Xs`` ``(POST_CHUNK, C, n)`` at ``omegas`` (rad/s)."""
    resp, Phi = _batch_monodromy(problem, basis, Xs, omegas, F_static)
    mu, V = _eig(np.asarray(Phi))
    out = jax.device_get((resp, _batch_verdict(problem, basis, mu, V)))
    _POST_COMPILED.add(_signature((problem, basis, Xs, omegas, F_static)))
    return out


class _PostStream:
    """Responses and stability of a continuation's points while it goes on: each full
    chunk of :data:`POST_CHUNK` points of a segment, as soon as the continuation has
    found it, in one background thread (:func:`_post_chunk`); :meth:`rows` waits for
    those and computes the rest. The continuation keeps about one core busy (its
    dense LU on one BLAS thread, :func:`_blas_threads`), the post-processing takes
    the other. Measured on 2 cores, paper backlash sweep, two interleaved pairs of runs
    (second run in each process): 36.2 and 35.4 s against 41.4 and 39.3 s with the
    post-processing after the continuation (6.8 and 7.4 s there; 1.1 and 0.9 s left
    at the end now), continuation steps 28.2 and 27.5 s against 28.2 and 25.9 s.
    Results are those of :func:`_point_rows` over the whole segment at once (the same
    chunks)."""

    def __init__(self, F_static):
        self._F = F_static
        self._pool = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="gearjax-post")
        self._chunks: dict[int, list] = {}  # segment -> futures of its leading chunks
        self._basis: dict[int, object] = {}

    def feed(self, j: int, problem, omega_ref: float, pts: list[dict]) -> None:
        """Submit the full chunks of segment ``j``'s points ``pts`` (journal records) not
        submitted yet."""
        futures = self._chunks.setdefault(j, [])
        while (len(futures) + 1) * POST_CHUNK <= len(pts):
            i = len(futures) * POST_CHUNK
            if j not in self._basis:
                self._basis[j] = verdict_basis(problem)
            Xs, omegas = _point_arrays(problem, omega_ref, pts[i:i + POST_CHUNK])
            futures.append(self._pool.submit(_post_chunk, problem, self._basis[j], Xs,
                                             omegas, self._F))

    def rows(self, j: int, problem, omega_ref: float, pts: list[dict]) -> dict:
        """:func:`_point_rows` of segment ``j``'s points ``pts``."""
        done = [f.result() for f in self._chunks.pop(j, [])]
        Xs, omegas = _point_arrays(problem, omega_ref, pts)
        return _point_rows(problem, Xs, omegas, np.zeros(len(pts), int), self._F, done)

    def rename(self, old, new) -> None:
        """Segment ``old``'s chunks are segment ``new``'s (an adopted speculation)."""
        if old in self._chunks:
            self._chunks[new] = self._chunks.pop(old)
        if old in self._basis:
            self._basis[new] = self._basis.pop(old)

    def drop(self, j) -> None:
        """Forget segment ``j``'s chunks; those not started are not computed."""
        for f in self._chunks.pop(j, []):
            f.cancel()
        self._basis.pop(j, None)

    def close(self) -> None:
        """Stop: chunks not started are dropped (an interrupted sweep)."""
        self._pool.shutdown(wait=False, cancel_futures=True)


def _point_arrays(problem, omega_ref: float, pts: list[dict]):
    """Unscaled solutions ``(P, C, n)`` and base frequencies ``(P,)`` (rad/s) of journal
    point records."""
    Xs = jnp.asarray(np.stack([p["y"] for p in pts])).reshape(
        (-1,) + problem.shape) * problem.x_scale
    return Xs, jnp.asarray(np.array([p["lam"] for p in pts]) * omega_ref)


def _blas_threads() -> threadpoolctl.threadpool_limits:
    """BLAS (OpenBLAS, ...) limited to all cores but one while a sweep's continuation
    runs, the one for its post-processing (:class:`_PostStream`); the caller restores the
    limits (``.restore_original_limits()``). Measured on 2 cores, paper sweep: the
    continuation's steps took 23.9 s with one BLAS thread and 23.6 s with two, whose
    second thread mostly spins (1.23 against 1.97 cores busy), although a lone LU of
    1291 unknowns in single precision takes 23 ms on one thread and 20.5 ms on two."""
    return threadpoolctl.threadpool_limits(max(1, post_threads() - 1), user_api="blas")


_POST_COMPILED: set = set()
"""Signatures (:func:`_signature`) of the post-processing chunk programs compiled in
this process."""


def _signature(args) -> tuple:
    """What a jitted function's compilation depends on, of arguments ``args``: the tree
    structure (with the static fields) and every leaf's shape and type."""
    leaves, tree = jax.tree.flatten(args)
    return tree, tuple((np.shape(a), str(getattr(a, "dtype", type(a).__name__)))
                       for a in leaves)


def bifurcations(f_hz, stable, multipliers, excluded, branch=None) -> list[dict]:
    """Where stability changes between neighbouring points of one branch, and how
    (interface: a list of ``{"mesh_frequency_hz", "kind"}``, the frequency the midpoint
    of the two points).

    ``kind`` is from :func:`~gearjax._stability.bifurcation_kind`: ``fold``,
    ``period_doubling`` or ``neimark_sacker`` (``None`` where no retained multiplier
    changed side of the unit circle; the rigid-body multipliers are left out, see
    :class:`~gearjax._stability.Stability`).
    """
    out = []
    change = np.asarray(stable[1:]) != np.asarray(stable[:-1])
    if branch is not None:
        change &= np.asarray(branch[1:]) == np.asarray(branch[:-1])
    for i in np.flatnonzero(change):
        kind = bifurcation_kind(multipliers[i][~excluded[i]], multipliers[i + 1][~excluded[i + 1]])
        out.append({"mesh_frequency_hz": float((f_hz[i] + f_hz[i + 1]) / 2), "kind": kind})
    return out


@jax.jit
def _batch_monodromy(problem, basis, Xs, omegas, F_static):
    """Mesh responses and scaled monodromy matrices of a chunk of solutions."""
    resp = jax.vmap(mesh_responses, in_axes=(None, 0, 0, None))(problem, Xs, omegas, F_static)
    n_steps = floquet_steps(problem, SWEEP_FLOQUET_STEPS)
    Phi = jax.vmap(lambda X, w: scaled_monodromy(problem, basis, X, w, n_steps))(Xs, omegas)
    return resp, Phi


def _eig(Phi):
    """Eigenvalues ``(c, k)`` and eigenvectors ``(c, k, k)`` (complex) of a batch of
    matrices, NaN for a matrix with a non-finite entry (as ``jnp.linalg.eig`` gives)."""
    finite = np.all(np.isfinite(Phi), axis=(1, 2))
    mu, V = np.linalg.eig(np.where(finite[:, None, None], Phi, np.eye(Phi.shape[-1])))
    mu, V = mu.astype(complex), V.astype(complex)  # NumPy's are real when all are
    mu[~finite], V[~finite] = np.nan, np.nan
    return mu, V


@jax.jit
def _batch_verdict(problem, basis, mu, V):
    """Stability verdicts of a chunk from its multipliers and Floquet modes."""
    return jax.vmap(verdict, in_axes=(None, None, 0, 0))(problem, basis, mu, V)


def progress_printer(stream=sys.stderr) -> Callable[[int, float], None]:
    """A progress line on ``stream``: rewritten in place on a terminal, every 25 points
    otherwise."""
    tty = stream.isatty()
    t0 = time.perf_counter()

    def show(n: int, f_hz: float) -> None:
        if tty or n % 25 == 0:
            end = "\r" if tty else "\n"
            stream.write(f"sweep: {n} points, at {f_hz:9.1f} Hz, {time.perf_counter() - t0:6.1f} s"
                         + end)
            stream.flush()

    return show


def summary_json(result: SweepResult) -> dict:
    """Top-level JSON of a sweep (points per interface.md plus summary fields)."""
    from ._results import points_json

    ds = result.dataset
    return {
        "gear": ds.attrs.get("gear"),
        "reference_stage": ds.attrs.get("reference_stage"),
        "stop": result.stop,
        "folds_hz": list(result.folds_hz),
        "bifurcations": json.loads(ds.attrs.get("bifurcations", "[]")),
        "restarts": list(result.restarts),
        "segments": [list(s) for s in result.segments],
        "seconds": result.seconds,
        "points": points_json(ds),
        "solver": json.loads(ds.attrs.get("solver", "{}")),
    }
