"""The sweep's entry point: a gear's frequency response over a band."""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable

import jax.numpy as jnp
import numpy as np

from ..._errors import bad_argument
from ..._gear.case import gear_case, torus_fields
from ..._gear.toml_io import dumps_train
from ..._gear.train import Train
from .. import concurrency
from .. import harmonics as _harmonics
from ..validity import warn_contact_loss
from . import completion as _completion
from . import seeds as _seeds
from . import segments as _segments
from . import speculation as _speculation
from . import walk as _walk
from .arguments import check_arguments
from .context import Context
from .default_band import resolve_band
from .dataset import point_data, sweep_result_dataset
from .post import PostStream
from .progress import with_branches
from .refine import LINEAR_TOLERANCE, MAX_ROUNDS, RefinementWarning, refinement_warning
from .record import SweepLog, run_fields
from .summary import SweepResult


def sweep(
    train: Train,
    gear: str | None = None,
    from_hz: float | None = None,
    to_hz: float | None = None,
    *,
    stage: str | None = None,
    linear: bool = False,
    harmonics: int | None = None,
    eta: int = 1,
    max_step_hz: float | None = None,
    points: int = 300,
    max_points: int = 3000,
    max_detour: int = _walk.MAX_DETOUR,
    smoothing: float = 0.0,
    progress: Callable[[int, float], None] | None = None,
    say: Callable[[str], None] | None = None,
    journal=None,
    resume: bool = False,
    command: str | None = None,
    complete: bool = True,
    seeds: int = 0,
) -> SweepResult:
    """Frequency response of ``gear`` from ``from_hz`` to ``to_hz`` (reference-stage mesh Hz;
    both ``None``: the band chosen from the gear's modes and excitation orders,
    :mod:`~gearjax._studies.sweep.default_band`, said through ``say``).

    **Arguments:** ``stage``: reference stage id (default: first turning stage);
    ``linear``: drop the backlash; ``harmonics``: fixed K (default: frequency-dependent,
    :func:`gearjax._studies.harmonics.harmonics_rule`); ``eta``: sub-harmonic index;
    ``max_step_hz``: largest frequency step (default 1/100 of the band); ``points``:
    points of a linear sweep's even grid (refined where straight lines between them
    would misstate the curve); ``max_points``: cap on a continuation's points, or on
    the points a linear sweep solves (grid, refinement middles); ``max_detour``:
    points a branch may go without passing the furthest frequency it reached before the
    sweep restarts beyond it (:mod:`~gearjax._studies.sweep.walk`); ``smoothing``:
    corner rounding of the backlash relative to it (0: exact piecewise-linear, see
    :func:`gearjax._engine.mesh_force.backlash`); ``progress(points_done,
    frequency_hz, branches)``: called per point with the points kept so far, the
    frequency reached (Hz) and the branches begun so far (restarts plus one), the third
    argument only where ``progress`` takes one (:func:`.progress.with_branches`);
    ``say(line)``: called with a line of text before each step that runs before the
    first point (each truncation check of a segment's harmonics) and before each round
    of a linear sweep's refinement;
    ``command``: how the sweep was asked for, kept
    as the dataset's ``command`` attribute (default: empty).

    ``complete`` (non-linear sweeps): after the walk, look for the stable states it did
    not trace and trace their branches (:mod:`~gearjax._studies.sweep.completion`): the
    start at the band's far end, and the orbit a rig settles to where each stable
    stretch ends (a jump up or down); ``seeds``: also the end states of an up and a down
    time-integration sweep over that many even frequencies (0: none; each costs a few
    tens of periods of integration per direction). Every branch is numbered
    (``branch``) and the dataset attribute ``branches`` says how each was found.

    ``journal``: a file (e.g. ``RESULTS.nc.journal``, :func:`gearjax._io.journal.journal_path`)
    where every finished point (continuation) or segment (linear grid) is appended as it
    is found, with what the continuation needs to go on (scaled solution, tangent, step,
    parameter, harmonics, segment); ``resume``: continue the run that the existing
    ``journal`` holds instead of starting afresh (nothing is recomputed; the result is
    that of an uninterrupted run). Without ``resume`` an existing journal is refused (it
    is an interrupted run's work); a journal of another run (train text, gear,
    arguments) is refused naming the field. The caller deletes the journal once it has
    saved the results. Responses and stability are computed from the solutions, not
    journaled: beside the continuation as it finds them, the rest at the end
    (:class:`~gearjax._studies.sweep.post.PostStream`).

    **Segments.** K is fixed within a segment of the band
    (:mod:`~gearjax._studies.sweep.segments`). A segment continued from the one before
    starts on their boundary, by Newton from the chord of the branch across it. Where
    threads are allowed (:mod:`gearjax._studies.concurrency`) the last segment is
    continued in a thread from its own start while the others run, and kept where the
    branch arriving there enters it on the same orbit
    (:mod:`~gearjax._studies.sweep.speculation`): the same result with or without the
    thread.

    **Branch restarts** (:mod:`~gearjax._studies.sweep.walk`): where a branch closes on
    itself, detours, runs away or cannot go on, the sweep keeps its points and starts a
    new branch beyond the furthest frequency it reached. Each point carries its
    ``branch`` number and ``restarts`` lists where and why, so the frequencies between
    are known to be unexplored.

    **Raises:** ``ArgumentError`` (a ``TrainError``) naming the argument for arguments
    that cannot describe a sweep, too few or too many harmonics, or ``resume`` without
    a ``journal``; ``TrainError`` for a gear where no mesh turns, an impractical ``mu``,
    an unknown stage, backlash on an unloaded stage without ``drag_torque``, or a
    journal that cannot be resumed.

    **Warns:** :class:`~gearjax._studies.sweep.refine.RefinementWarning` where a linear
    sweep's refinement stopped (at ``max_points`` or after its most halvings) with lines
    still suspect; :class:`~gearjax._studies.validity.ContactLossWarning` where a linear
    sweep's alternating mesh force exceeds the static one (the teeth would leave
    contact), naming the first frequency (:func:`~gearjax._studies.validity.contact_loss`).
    """
    t_start = time.perf_counter()
    phases = Phases()
    from_hz, to_hz, chosen = resolve_band(train, gear, stage, linear, from_hz, to_hz)
    if chosen is not None and say is not None:
        say(f"band {from_hz:.1f}-{to_hz:.1f} Hz, chosen {chosen}")
    check_arguments(from_hz, to_hz, eta=eta, smoothing=smoothing, harmonics=harmonics,
                    max_step_hz=max_step_hz, points=points, max_points=max_points,
                    seeds=seeds, linear=linear)
    complete = bool(complete) and not linear
    case = gear_case(train, gear, stage, linear, torus=True)
    system = case.system
    if case.G > 1:
        if eta != 1:
            raise bad_argument("eta", eta, f"the gear's mesh frequencies fall in {case.G} "
                               "incommensurate groups: its response is quasi-periodic, and "
                               "sub-harmonic (eta > 1) solutions are periodic ones")
        if seeds:
            raise bad_argument("seeds", seeds, f"the gear's mesh frequencies fall in "
                               f"{case.G} incommensurate groups: integration seeds are the "
                               "end states of periodic integration sweeps; a quasi-periodic "
                               "gear is completed from the band's far end and the jumps")
    min_k = _harmonics.excitation_floor(system, eta)
    if harmonics is not None:
        _harmonics.require_harmonics(system, harmonics, eta)
    cutoff_hz = _harmonics.response_cutoff_hz(system)
    segments = _segments.band_segments(from_hz, to_hz, case.mu_ref, min_k, eta, harmonics,
                                       cutoff_hz, system)
    for K in sorted({k for *_, k in segments}):
        _harmonics.require_size(system, K, mu=case.mu, value=harmonics)
    F_static = jnp.asarray(case.F_static)
    runaway = _walk.RUNAWAY * (np.abs(np.asarray(F_static)) / np.asarray(system.kbar)
                               + np.asarray(system.backlash))  # RMS mesh deflection limit (m)
    train_toml = dumps_train(train)
    phases.end("gear")
    run = run_fields(train_toml, gear=case.gear.name, stage=case.stage, from_hz=from_hz,
                     to_hz=to_hz, linear=linear, harmonics=harmonics, eta=eta,
                     max_step_hz=max_step_hz, smoothing=smoothing, points=points,
                     max_points=max_points, complete=complete, seeds=seeds)
    log = SweepLog.open(journal, run, resume)
    ctx = Context(system=system, eta=eta, smoothing=smoothing, from_hz=from_hz,
                  to_hz=to_hz, mu_ref=case.mu_ref, max_step_hz=max_step_hz,
                  max_points=max_points, max_detour=max_detour, runaway=runaway)
    try:
        segments, truncation, start = _segments.checked_segments(
            ctx, segments, F_static, fixed=harmonics is not None, say=say)
    except BaseException:
        log.close()
        raise
    phases.end("check")
    solver = {"method": "harmonic balance", "linear": linear, "eta": eta,
              "band_hz": [float(from_hz), float(to_hz)],
              "segments": [[a, b, _segments.orders_json(K)] for a, b, K in segments],
              "reference_stage": case.stage,
              "max_step_hz": max_step_hz, "cutoff_hz": cutoff_hz,
              "truncation": truncation, "truncation_target": _harmonics.TRUNCATION_TARGET,
              "smoothing": smoothing, "torus": torus_fields(case)}
    walk = _walk.Walk(segments=list(segments))
    post = PostStream(F_static)
    pieces, branches = _run_walk(ctx, walk, log, post, linear=linear, points=points,
                                 progress=with_branches(progress), say=say,
                                 F_static=F_static,
                                 complete=complete, seeds=seeds, start=start,
                                 phases=phases)
    if linear:
        solver["refinement"] = _refinement(walk, max_points)
        line = refinement_warning(solver["refinement"])
        if line is not None:
            warnings.warn(RefinementWarning(line), stacklevel=2)
    if complete:
        solver["completion"] = {"seeds": int(seeds), "jump_multiplier":
                                _seeds.JUMP_MULTIPLIER, "max_branches":
                                _completion.MAX_BRANCHES}
    data = point_data(walk, log, post, ctx, F_static, linear=linear, pieces=pieces)
    folds = list(walk.folds) + [p["fold_lam"] * ctx.from_hz for piece in (pieces or [])
                                if not isinstance(piece.key, int)
                                for p in piece.pts if p["fold"]]
    ds = sweep_result_dataset(data, case, F_static=F_static, train_toml=train_toml,
                              solver=solver, folds=folds, stop=walk.stop,
                              restarts=walk.restarts,
                              command="" if command is None else command,
                              branches=branches)
    phases.end("results")
    warn_contact_loss(ds)
    return SweepResult(dataset=ds, folds_hz=tuple(folds), stop=walk.stop,
                       segments=tuple(walk.segments), seconds=time.perf_counter() - t_start,
                       restarts=tuple(walk.restarts), branches=tuple(branches or ()),
                       phase_seconds=dict(phases))


def _refinement(walk, max_points: int) -> dict:
    """A linear sweep's ``solver.refinement`` (:mod:`~gearjax._studies.sweep.refine`):
    ``tolerance``, ``grid`` (points of the even grids), ``added``, ``checked``, ``solved``
    (grid, segment ends and middles), ``max_points`` (the cap on ``solved``),
    ``unresolved`` (intervals still suspect where the refinement stopped) and
    ``stopped`` (``"max_points"``, ``"max_rounds"``, or ``None`` where every line was
    judged within the tolerance)."""
    stops = walk.refine_stops
    return {"tolerance": LINEAR_TOLERANCE, "grid": walk.done - walk.added,
            "added": walk.added, "checked": walk.checked, "solved": walk.solved,
            "max_points": int(max_points), "max_rounds": MAX_ROUNDS,
            "unresolved": walk.unresolved,
            "stopped": ("max_points" if "max_points" in stops else stops[0]) if stops
            else None}


class Phases(dict):
    """Wall seconds per phase of a sweep, in the order run (``SweepResult.phase_seconds``):
    :meth:`end` closes the phase running since the last call (or since creation)."""

    def __init__(self):
        super().__init__()
        self._since = time.perf_counter()

    def end(self, name: str) -> None:
        now = time.perf_counter()
        self[name] = self.get(name, 0.0) + now - self._since
        self._since = now


def _run_walk(ctx, walk, log, post, *, linear: bool, points: int, progress, say=None,
              F_static, complete: bool = False, seeds: int = 0, start=None,
              phases: Phases | None = None):
    """Walk every segment (a linear grid, or the continuations with the last segment
    speculated; the first from ``start`` ``(y, result, lambda)``, the point the
    truncation check solved there, where given), then, where ``complete``, the branches
    the walk missed (:func:`~gearjax._studies.sweep.completion.complete`); the journal
    is closed after, and the post-processing stopped where the walk is interrupted;
    ``phases`` (default: a new one) gets the end of the ``walk`` and of the
    ``completion``.
    **Returns:** ``(pieces, branch records)`` of the completion, ``(None, None)``
    without it. BLAS keeps a core for the post-processing while a continuation runs
    (:func:`gearjax._studies.concurrency.limit_blas`)."""
    phases = Phases() if phases is None else phases
    last = walk.segments[-1]
    blas = None if linear else concurrency.limit_blas()  # a linear sweep's post comes after
    spec = None
    try:
        if linear:
            _walk.linear_segments(ctx, walk, log, points, progress, F_static, say=say)
        while not linear and len(walk.problems) < len(walk.segments):
            entered, spec = _speculation.speculate(ctx, walk, log, post, spec, last)
            if not walk.problems and entered is None:
                entered = start
            if not _walk.walk_segment(ctx, walk, log, post, progress=progress,
                                      entered=entered):
                break
        if spec is not None:
            spec.cancel()
            spec = None
        phases.end("walk")
        if complete and walk.problems:
            done = _completion.complete(ctx, walk, log, post, F_static, seeds=seeds,
                                        progress=progress)
            phases.end("completion")
            return done
        return None, None
    except BaseException:
        post.close()
        raise
    finally:
        if spec is not None:
            spec.cancel()
        if blas is not None:
            blas.restore_original_limits()
        log.close()
