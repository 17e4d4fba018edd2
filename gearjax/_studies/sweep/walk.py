"""A sweep's way through its segments: the grid of a linear sweep, the continuation of a
segment (fresh, continued from the one before, or resumed from its journal records),
and the decision what follows it: the next segment, a restart beyond where the branch
was left, or the end.

**Branch restarts.** A continuation follows one solution branch wherever it goes.
Where the branch closes on itself (``closed_loop``), wanders back and forth for
``max_detour`` points without passing the furthest frequency it reached (``detour``;
passing it counts by :data:`MIN_ADVANCE` of the largest step or more), runs away to
absurd amplitudes (``runaway``, :data:`RUNAWAY`), or cannot go on
(``step_too_small``, ``nonfinite``), the sweep keeps every point of it and starts a
new branch a quarter of the largest step beyond that furthest frequency, as a sweep
on a test rig jumps (:func:`gearjax._studies.sweep.starts.enter_segment`). Where no
start converges, or the start lands past the runaway bound (inside a parametric
instability every periodic orbit does), the gap doubles with each try. A point past the
runaway bound is kept but flagged (result ``runaway``, stability unknown: a truncated
balance cannot resolve such impacts, :func:`~gearjax._studies.sweep.dataset.point_data`).
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np

from ..._engine import continuation as _continuation
from ..._engine.kept import kept_program
from ..._engine.results import RESULTS, result_from_word, result_word
from . import starts as _starts
from .refine import ReplayError, refine_linear

MAX_DETOUR = 150
"""Points a continuation may go without passing its furthest frequency before the sweep
restarts beyond it (about the length of a fold pair: up to a fold, back along the
unstable branch to the next)."""

MIN_ADVANCE = 0.05
"""Passing the furthest frequency counts only by this share of the largest step or more:
a branch that creeps upwards by tiny steps (amplitude growing without bound inside a
parametric instability) is a detour too."""

RUNAWAY = 5.0
"""A branch whose RMS alternating deflection of a mesh exceeds this many times the
mesh's static deflection plus its backlash has run away (``runaway``): inside a
parametric instability periodic orbits climb to absurd forces (the teeth hammering
across the clearance), every one unstable, and a truncated harmonic balance cannot
resolve such impacts anyway. The sweep restarts beyond."""

MAX_RESTARTS = 100
"""Most branch restarts of one sweep."""

RESTART_STOPS = (RESULTS.closed_loop, RESULTS.detour, RESULTS.step_too_small,
                 RESULTS.nonfinite, RESULTS.runaway, RESULTS.no_converged_start)
"""Segment results after which a sweep restarts on a new branch."""


@dataclasses.dataclass
class Walk:
    """A sweep's way through its segments ``(f_a, f_b, K)``: restarts insert segments;
    ``problems`` has one per segment done; ``fresh``: segments that start a new branch
    (the others continue the one before); ``previous``: ``(K, y, lambda, before)`` of
    the last point of the segment before, ``before`` the ``(y, lambda)`` of the point
    before it (``None`` for a segment of one point); ``furthest``: that of the furthest
    point so far (a fresh branch's first guess); ``failed``: fresh starts that failed in
    a row (the restart gap doubles with each); ``done``: points kept so far (a continued
    segment's first point stands in for the previous segment's last, past the boundary,
    which the output leaves out). A linear sweep's refinement (:func:`linear_segments`)
    counts ``solved``, ``checked``, ``added`` and ``unresolved``, and ``refine_stops``
    lists why a segment's refinement stopped with intervals unresolved."""

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
    solved: int = 0
    checked: int = 0
    added: int = 0
    unresolved: int = 0
    refine_stops: list = dataclasses.field(default_factory=list)

    def handover(self, j: int) -> tuple:
        """``(previous, guess)`` for :func:`~gearjax._studies.sweep.starts.enter_segment`
        at segment ``j``: the branch continued, or a fresh one's first guess."""
        return (None, self.furthest) if j in self.fresh else (self.previous, None)


class Cancelled(Exception):
    """A continuation was called off (a speculation, from its ``cancel`` event)."""


def linear_segments(ctx, walk, log, points, progress, F_static, say=None) -> None:
    """A linear sweep: each segment's grid of independent points (``points`` evenly over
    the whole band to start with), refined where straight lines between them would
    misstate the curve (:func:`~gearjax._studies.sweep.refine.refine_linear`), with at
    most ``ctx.max_points`` points solved over the band (each segment's grid always);
    every chunk of points solved is journaled as solved (a ``solved`` record), the
    segment's points as one ``batch`` record when it is done. ``walk`` counts the points
    ``solved``, the middles ``checked`` and ``added``, and the ``unresolved`` intervals
    with the reason the refinement stopped (``refine_stops``); ``progress`` is told the
    points kept as they are solved, ``say`` each refinement round.

    **Raises:** ``TrainError`` naming the journal where its solved points are not those
    this run's refinement asks for."""
    span = ctx.to_hz - ctx.from_hz
    for j, (f_a, f_b, K) in enumerate(walk.segments):
        problem = ctx.problem(K)
        walk.problems.append(problem)
        log.require_K(j, K)
        if log.batch(j) is None:
            n = max(2, round(points * abs(f_b - f_a) / abs(span)))
            last = f_b == walk.segments[-1][1]
            freqs = np.linspace(f_a, f_b, n, endpoint=last)
            done = walk.done

            def report(solved, kept, done=done, freqs=freqs):
                if progress:
                    progress(done + kept, float(freqs[min(kept, freqs.size) - 1]), 1)

            try:
                refined = refine_linear(
                    problem, [ctx.omega(f) for f in freqs], F_static,
                    None if last else ctx.omega(f_b),
                    max_points=max(ctx.max_points - walk.solved, n + (not last)),
                    replay=log.solved(j), report=report, say=say,
                    record=lambda rec, j=j, K=K: log.add({"type": "solved", "segment": j,
                                                          "K": K, **rec}))
            except ReplayError as e:
                raise log.refused(j, str(e)) from None
            log.add({"type": "batch", "segment": j, "K": K, "omega": refined.omega,
                     "X": np.asarray(refined.X, float), "result": refined.result,
                     "solved": refined.solved, "checked": refined.checked,
                     "added": refined.added, "unresolved": refined.unresolved,
                     "stopped": refined.stopped})
        batch = log.batch(j)
        walk.solved += int(batch["solved"])
        walk.checked += int(batch["checked"])
        walk.added += int(batch["added"])
        walk.unresolved += int(batch["unresolved"])
        if batch["stopped"] is not None:
            walk.refine_stops.append(batch["stopped"])
        walk.done += len(batch["omega"])
        if progress:
            progress(walk.done, float(batch["omega"][-1]) * ctx.mu_ref / (2 * math.pi), 1)


def walked_stretches(walk, log):
    """The walk's segments in sweep order, as ``(j, problem, points, branch)``: segment
    ``j``'s points without the last where the next segment continues from it (the point
    past the boundary that the next one starts on), and the branch they belong to (a new
    one after each restart); segments left with no point are skipped."""
    branch = 0
    problems, fresh = walk.problems, walk.fresh
    for j, problem in enumerate(problems):
        pts = log.points(j)
        last = len(pts) - (j + 1 < len(problems) and j + 1 not in fresh
                           and bool(log.points(j + 1)))
        branch += j in fresh and j > 0
        if last > 0:
            yield j, problem, pts[:last], branch


def walk_segment(ctx, walk, log, post, *, progress=None, entered=None, key=None,
                 cancel=None) -> bool:
    """Continue the next segment of ``walk`` (or take it from ``log``, where it is there)
    and decide what follows: the next segment, a restart beyond where the branch was
    left (a segment inserted), or the end. ``entered``: the segment's start ``(y,
    result, lambda)``, found already; ``key(j)``: segment ``j``'s name in ``post``;
    ``cancel``: an event that stops the continuation (:class:`Cancelled`).
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
                raise Cancelled
            post.feed(name, problem, omega_ref, log.points(j))

        start, branches = walk.done, len(walk.restarts) + 1
        previous, guess = walk.handover(j)
        seg_stop = continue_segment(
            log, j, K, param, previous, ctx.lam(f_a), ctx.lam(f_b),
            continuation_settings(ctx.max_step_hz, ctx.to_hz - ctx.from_hz, ctx.from_hz),
            cap=ctx.max_points - walk.done, f_a=f_a,
            guess=guess, runaway=ctx.runaway,
            max_detour=ctx.max_detour, entered=entered, found=found,
            progress=(lambda i, lam: progress(start + i + 1, lam * ctx.from_hz, branches))
            if progress else None)
        log.add({"type": "end", "segment": j, "stop": seg_stop})
    elif progress and log.points(j):  # taken from the journal
        progress(walk.done + len(log.points(j)), log.points(j)[-1]["lam"] * ctx.from_hz,
                 len(walk.restarts) + 1)
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
    result = result_from_word(seg_stop)
    # a fresh branch that runs away at its start found no state either: the gap doubles
    landed_away = (bool(result == RESULTS.runaway) and j in walk.fresh and bool(pts)
                   and ran_away(problem, pts[0]["y"], ctx.runaway))
    failed = bool(result == RESULTS.no_converged_start) or landed_away
    walk.failed = walk.failed + 1 if failed else 0
    restartable = any(bool(result == r) for r in RESTART_STOPS)
    if restartable and len(walk.restarts) < MAX_RESTARTS and walk.done < ctx.max_points:
        lams = [ctx.lam(f_a)] + [p["lam"] for p in pts]
        reached = (max if direction > 0 else min)(lams) * ctx.from_hz
        at = reached + direction * restart_step(
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
    if not bool(result == RESULTS.reached_end):
        walk.stop = seg_stop
        return False
    return True


def continue_segment(log, j, K, param, previous, lam_a, lam_b, settings, *, cap, f_a,
                     progress, max_detour=MAX_DETOUR, guess=None, runaway=None, found=None,
                     entered=None, meets=None):
    """Continue segment ``j`` from ``lam_a`` to ``lam_b`` (at most ``cap`` points), or the
    rest of it after the points ``log`` holds; every point goes to ``log``. The resumed
    state is the saved point with its tangent and step, and the factors of its bordered
    Jacobian rebuilt as the continuation built them (last row: the tangent before), so
    the points that follow are those of an uninterrupted run. ``found()`` is called after
    each new point went to ``log``; ``entered``: the start ``(y, result, lambda)``
    where it was found already (``starts.enter_segment`` otherwise); ``meets(y, lambda,
    chord)``: whether a point (after the first) lies on a branch traced before, ``chord``
    the step that reached it (the segment then stops as ``closed_loop``,
    :mod:`~gearjax._studies.sweep.completion`). **Returns:** why the
    segment stopped: the word (:func:`~gearjax._engine.results.result_word`) of a
    ``RESULTS`` item; ``no_converged_start`` is written "no converged start at F Hz
    (why)"."""
    have = log.points(j)
    offset = max(len(have) - 1, 0)
    direction = float(np.sign(lam_b - lam_a))
    # a resumed continuation only knows the points from where it resumes; the
    # closed-loop check of continue_branch compares with every point of the segment,
    # so the journaled ones are checked here too
    trace = segment_trace(have, cap) if have else None
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
    if have:
        front["z"] = np.append(have[-1]["y"], have[-1]["lam"])

    def on_point(i, state):
        if i == 0 and have:
            return None  # the saved point the continuation resumes from
        fold_lam = float(state.fold_lam)
        y, lam = np.asarray(state.y, float), float(state.lam)
        t = np.concatenate([np.asarray(state.ty), [float(state.tlam)]])
        log.add({"type": "point", "segment": j, "i": offset + i, "K": K, "y": y, "lam": lam,
                 "ty": t[:-1], "tlam": float(t[-1]), "h": float(state.h),
                 "steps": int(state.steps), "fold": bool(state.fold),
                 "fold_lam": fold_lam if math.isfinite(fold_lam) else None,
                 "age": int(state.age), "own": bool(state.own)})
        if found:
            found()
        if progress:
            progress(offset + i, lam)
        if trace is not None and (lam - lam_b) * direction < 0:
            z = np.append(y, lam)
            if trace.revisits(z, t):
                raise ClosedLoop
            trace.add(z, t)
        z = np.append(y, lam)
        if meets is not None and front.get("z") is not None and (lam - lam_b) * direction < 0 \
                and meets(y, lam, float(np.linalg.norm(z - front["z"]))):
            return RESULTS.closed_loop
        front["z"] = z
        if runaway is not None and ran_away(param.problem, y, runaway):
            return RESULTS.runaway
        return RESULTS.detour if detour(lam) and (lam - lam_b) * direction < 0 else None

    if not have:
        y, code, lam = entered or _starts.enter_segment(param.problem, previous, lam_a,
                                                        float(param.omega_ref), guess)
        if not bool(code == RESULTS.successful):
            return f"no converged start at {f_a:.1f} Hz ({result_word(code)})"
        return result_word(_continuation.continue_branch(
            param, y, lam, lam_b, settings, max_points=cap, on_point=on_point).result)
    last = have[-1]
    # why continue_branch stopped after the last saved point, in its order of checks
    if (last["lam"] - lam_b) * direction >= 0:
        return result_word(RESULTS.reached_end)
    if trace is not None and trace.closed:
        return result_word(RESULTS.closed_loop)
    if meets is not None and len(have) > 1:
        z, z0 = (np.append(p["y"], p["lam"]) for p in (last, have[-2]))
        if meets(last["y"], last["lam"], float(np.linalg.norm(z - z0))):
            return result_word(RESULTS.closed_loop)
    if runaway is not None and ran_away(param.problem, last["y"], runaway):
        return result_word(RESULTS.runaway)
    if detoured:
        return result_word(RESULTS.detour)
    if len(have) >= cap:
        return result_word(RESULTS.max_points)
    # one saved point: the start state is rebuilt from it exactly as it was first built
    state = None if len(have) == 1 else resumed_state(param, have, settings, direction)
    try:
        return result_word(_continuation.continue_branch(
            param, jnp.asarray(last["y"]), last["lam"], lam_b, settings,
            max_points=cap - len(have) + 1, on_point=on_point, state=state).result)
    except ClosedLoop:
        return result_word(RESULTS.closed_loop)


class ClosedLoop(Exception):
    """A resumed segment came back onto a stretch traced before it was interrupted."""


def segment_trace(have, cap):
    """The closed-loop trace of ``continue_branch`` (:class:`continuation.Trace`) over the
    saved points ``have`` of a segment; ``.closed``: the last saved point already closed
    the loop."""
    trace = _continuation.Trace(max(cap, len(have)), have[0]["y"].size + 1)
    trace.closed = False
    for k, p in enumerate(have):
        z, t = np.append(p["y"], p["lam"]), np.append(p["ty"], p["tlam"])
        if k and trace.revisits(z, t):
            trace.closed = True
            break
        trace.add(z, t)
    return trace


def resumed_state(param, have, settings, direction) -> _continuation.ArcState:
    """The continuation state at the last of the saved points ``have`` (two or more) of a
    segment, as ``arclength_step`` left it: its tangent and next step, and the factors
    of the bordered Jacobian rebuilt where the continuation built them (``age`` and
    ``own`` of the record, :class:`~gearjax._engine.continuation.ArcState`; a record
    without them, from before factors were reused, had them built at the point itself):
    at the point ``age`` records back, last row that point's tangent (``own``) or the
    one before it, or as :func:`~gearjax._engine.continuation.start` built them at the
    segment's first point."""
    last = have[-1]
    age, own = int(last.get("age", 0)), bool(last.get("own", False))
    at = len(have) - 1 - age
    point = jnp.asarray(have[at]["y"]), jnp.asarray(have[at]["lam"], float)
    if own or at > 0:
        border = have[at if own else at - 1]
        factors = _factor(param, *point, jnp.asarray(border["ty"]),
                          jnp.asarray(border["tlam"], float), settings.single)
    else:
        factors = _continuation.start_jit(param, *point, direction, settings).factors
    return _continuation.ArcState(
        y=jnp.asarray(last["y"]), lam=jnp.asarray(last["lam"], float),
        ty=jnp.asarray(last["ty"]), tlam=jnp.asarray(last["tlam"], float),
        h=jnp.asarray(last["h"], float), accepted=jnp.asarray(True),
        fold=jnp.asarray(False), fold_lam=jnp.asarray(jnp.nan, float), steps=jnp.asarray(0),
        factors=factors, age=jnp.asarray(age), own=jnp.asarray(own))


@kept_program(static_argnames="single")
def _factor(param, y, lam, ty, tlam, single):
    return param.factor(y, lam, ty, tlam, single)


def ran_away(problem, y, limit) -> bool:
    """Whether the RMS alternating deflection of a mesh, from the scaled unknowns ``y``,
    exceeds ``limit`` ``(m,)`` (m): see :data:`RUNAWAY`."""
    X = np.asarray(y).reshape(problem.shape) * np.asarray(problem.x_scale)
    return exceeds(problem.system, X, limit)


def exceeds(system, X, limit) -> bool:
    """Whether the RMS alternating deflection of a mesh of the solution ``X`` ``(C, n)``
    (coefficients, rad or m; periodic or on a torus: the rows are orthogonal) exceeds
    ``limit`` ``(m,)`` (m)."""
    deflection = np.asarray(X)[1:] @ np.asarray(system.W).T  # cos/sin amplitudes, (C-1, m)
    return bool(np.any(np.sqrt(0.5 * np.sum(deflection ** 2, axis=0)) > limit))


def largest_step_hz(max_step_hz, span_hz) -> float:
    """The largest frequency step of a continuation (Hz): ``max_step_hz``, by default
    1/100 of the band ``span_hz``."""
    return max_step_hz or abs(span_hz) / 100


def restart_step(max_step_hz, span_hz) -> float:
    """Frequency step (Hz, > 0) from the furthest point of a branch to the next branch's
    start: a quarter of the largest continuation step (doubled per failed start by the
    caller)."""
    return 0.25 * largest_step_hz(max_step_hz, span_hz)


def continuation_settings(max_step_hz, span_hz, f_ref):
    """Continuation settings: parameter steps of at most ``max_step_hz`` (default 1/100 of
    the band ``span_hz``), in units of the start frequency ``f_ref``; the step grows
    after at most 6 corrector iterations; the corrector's LU in single precision
    (``Settings.single``: the same iterations and folds, faster), kept from point to point
    for as long as it serves (``Settings.reuse``)."""
    max_step_hz = largest_step_hz(max_step_hz, span_hz)
    return _continuation.Settings(step=0.02, max_step=0.5, fast=6, single=True, reuse=True,
                                  max_dlambda=float(max_step_hz / f_ref), fold_step=1e-3)
