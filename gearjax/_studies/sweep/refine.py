"""Points of a linear sweep placed where the curve needs them.

A linear sweep solves independent points. Drawn as straight lines between them, a
curve on a steep resonance flank misstates the response between its points even where
each point is exact. So the grid is refined by a midpoint check: every interval of
consecutive converged points is solved at its middle; where the straight line misses
the middle's RMS or peak mesh force by more than :data:`LINEAR_TOLERANCE` (relative to
that force, a mesh below :data:`~gearjax._studies.harmonics.RMS_FLOOR` of the largest
judged against that share) the middle becomes a point and both halves are checked in
the next round; elsewhere the checked middle is dropped (the line holds there). Only
the middles of intervals whose neighbours' curvature makes the line suspect are solved
(:data:`SCREEN`). Where the response has no bound (inside a parametric instability,
where the periodic solution is unstable and the plot dashes it) the halvings stop after
:data:`MAX_ROUNDS`. The points solved are capped (a sweep's ``max_points``); a
refinement stopped by either with lines still suspect says how many
(:class:`Refined`, :func:`refinement_warning`).
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from ..._engine.responses import mesh_responses
from ..._engine.results import result_word
from ..harmonics import RMS_FLOOR
from .starts import solve_points

LINEAR_TOLERANCE = 0.005
"""Largest error of the straight line between consecutive points of a linear sweep, at
the middle of each interval, relative to the RMS and peak mesh forces there."""

MAX_ROUNDS = 8
"""Most halvings of an interval (a 256 times finer grid where the curve needs it)."""

SCREEN = 0.5
"""A middle is solved where the curvature around its interval predicts a straight-line
error above this share of the tolerance (a margin for curvature the points underrate)."""


class RefinementWarning(UserWarning):
    """A linear sweep's refinement stopped with intervals whose straight line may miss
    the curve by more than the tolerance (the points themselves are exact)."""


def refinement_warning(refinement: dict) -> str | None:
    """The warning line of a linear sweep's ``solver.refinement`` (its fields:
    :func:`~gearjax._studies.sweep.api.sweep`), ``None`` where every line was judged
    within the tolerance."""
    if not refinement.get("unresolved"):
        return None
    why = (f"after {refinement['max_rounds']} halvings (a response without a bound there, "
           "or one steeper than halving follows)" if refinement["stopped"] == "max_rounds"
           else f"at `max_points` = {refinement['max_points']} points solved (raise it)")
    return (f"linear sweep: refinement stopped {why} with {refinement['unresolved']} "
            f"intervals where a straight line between exact points may miss the curve by "
            f"more than {100 * refinement['tolerance']:g}%")


class ReplayError(ValueError):
    """A journal's solved points are not those the refinement asks for (a journal of
    another refinement)."""


REPORT_CHUNK = 32
"""Points solved between two progress reports and two journal records (an interrupted
refinement loses at most this many points)."""


@dataclasses.dataclass
class Refined:
    """A linear segment's points after refinement: ``omega`` ``(P,)`` (rad/s, in sweep
    order), ``X`` ``(P, C, n)``, ``result`` ``(P,)`` (words); ``solved``: points solved
    (the grid, the end point, the middles); ``checked``: middles solved, ``added``: those
    kept as points; ``unresolved``: intervals whose straight line was still suspect when
    the refinement stopped (``stopped``: ``"max_points"`` where the cap on points solved
    stopped it, ``"max_rounds"`` after :data:`MAX_ROUNDS` halvings, ``None`` where
    every line was judged within the tolerance)."""

    omega: np.ndarray
    X: np.ndarray
    result: np.ndarray
    solved: int = 0
    checked: int = 0
    added: int = 0
    unresolved: int = 0
    stopped: str | None = None


@jax.jit
def _forces(problem, Xs, omegas, F_static):
    """``(P, 2m)``: every mesh's RMS force and peak force (N) of the points ``Xs``."""
    r = jax.vmap(mesh_responses, in_axes=(None, 0, 0, None))(problem, Xs, omegas, F_static)
    return jnp.concatenate([r.rms_force, r.max_force], axis=1)


class _Solves:
    """Solves batches of independent points, :data:`REPORT_CHUNK` at a time: taken from
    ``replay`` (earlier records ``{"omega", "X", "result", "converged"}``, in the order
    solved) while it lasts, else solved and handed to ``record``; ``report(solved)``
    after each chunk."""

    def __init__(self, problem, F_static, replay, record, report):
        self.problem, self.F_static = problem, F_static
        self.replay, self.record, self.report = list(replay), record, report
        self.solved = 0

    def __call__(self, omegas):
        """``(X, words, converged, forces)`` at ``omegas`` ``(P,)`` (rad/s).

        **Raises:** :class:`ReplayError` where a replayed record holds other
        frequencies than those asked for."""
        parts = []
        for i in range(0, omegas.size, REPORT_CHUNK):
            chunk = omegas[i:i + REPORT_CHUNK]
            if self.replay:
                rec = self.replay.pop(0)
                if np.shape(rec["omega"]) != chunk.shape or not np.allclose(
                        rec["omega"], chunk, rtol=1e-12, atol=0.0):
                    raise ReplayError("the journal's solved points are not those this "
                                      "refinement asks for")
            else:
                sols = solve_points(self.problem, jnp.asarray(chunk))
                rec = {"omega": chunk, "X": np.asarray(sols.X, float),
                       "result": np.asarray(result_word(sols.result)).reshape(-1),
                       "converged": np.asarray(sols.converged).reshape(-1)}
                if self.record is not None:
                    self.record(rec)
            parts.append(rec)
            self.solved += chunk.size
            if self.report is not None:
                self.report(self.solved)
        X = np.concatenate([np.asarray(r["X"], float) for r in parts])
        words = np.concatenate([np.asarray(r["result"]).reshape(-1) for r in parts])
        ok = np.concatenate([np.asarray(r["converged"], bool).reshape(-1) for r in parts])
        forces = np.asarray(_forces(self.problem, jnp.asarray(X), jnp.asarray(omegas),
                                    self.F_static))
        return X, words, ok, forces


def refine_linear(problem, omegas, F_static, end_omega=None, *,
                  tolerance: float = LINEAR_TOLERANCE, max_points: int | None = None,
                  replay=(), record=None, report=None, say=None) -> Refined:
    """Solve the linear segment at the base frequencies ``omegas`` ``(P,)`` (rad/s, in
    sweep order) and refine it (module docstring). ``end_omega``: where the next
    segment starts (solved there, not kept), so the last interval is checked too;
    ``max_points``: most points solved, grid and end point included (default 256 per
    grid point); a round with more suspect middles than room solves those of the
    largest predicted error.

    A middle is solved only where the curvature of the points around the interval (their
    divided differences) puts the straight line's error there above
    :data:`SCREEN` of ``tolerance``: where the curve is plainly straight, nothing
    is solved.

    **Journal and progress:** ``replay``: records ``record`` was handed by an
    interrupted run of the same refinement (taken in order instead of solving);
    ``record(rec)``: called with each chunk of points solved (``omega``, ``X``,
    ``result``, ``converged``); ``report(solved, kept)``: after each chunk, with the
    points solved and kept so far (the grid's points count as kept as they are solved);
    ``say(line)``: a line as each round begins.

    **Returns:** :class:`Refined`. **Raises:** :class:`ReplayError` for a ``replay`` of
    another refinement."""
    omegas = np.asarray(omegas, float)
    n = omegas.size
    direction = np.sign((omegas[-1] if end_omega is None else end_omega) - omegas[0]) or 1.0
    added = 0

    def progress(solved):
        if report is not None:
            report(solved, min(solved, n) + added)

    solve = _Solves(problem, F_static, replay, record, progress)
    w = omegas if end_omega is None else np.append(omegas, float(end_omega))
    X, words, ok, values = solve(w)
    kept = np.arange(w.size) < n  # False: the end point, solved for the check only
    order = np.argsort(w, kind="stable")
    w, X, words, ok, values, kept = (a[order] for a in (w, X, words, ok, values, kept))
    checked, unresolved, stopped = 0, 0, None
    cap = max_points if max_points is not None else 256 * n
    active = ok[:-1] & ok[1:]  # intervals still to judge
    for k in range(MAX_ROUNDS + 1):
        floor = RMS_FLOOR * np.maximum(np.max(np.abs(values), axis=0), 1e-300)
        estimate = _line_error_estimate(w, values, floor) if w.size > 1 else np.zeros(0)
        suspect = np.flatnonzero(active & (estimate > SCREEN * tolerance))
        todo, room = suspect, cap - solve.solved
        if todo.size == 0 or k == MAX_ROUNDS or room <= 0:
            if todo.size:
                unresolved, stopped = todo.size, ("max_rounds" if k == MAX_ROUNDS
                                                  else "max_points")
            break
        if todo.size > room:  # the largest predicted errors first; the rest wait
            todo = np.sort(todo[np.argsort(-estimate[todo], kind="stable")[:room]])
        waiting = w[np.setdiff1d(suspect, todo)]  # left ends of suspect intervals left
        if say is not None:
            say(f"sweep: refinement round {k + 1} of at most {MAX_ROUNDS}: {todo.size} "
                f"middles where a straight line may miss the curve by more than "
                f"{100 * tolerance:g}% ({int(kept.sum())} points so far)")
        mids = 0.5 * (w[todo] + w[todo + 1])
        m_X, m_words, m_ok, m_val = solve(mids)
        checked += mids.size
        line = 0.5 * (values[todo] + values[todo + 1])
        miss = np.max(np.abs(line - m_val) / np.maximum(np.abs(m_val), floor), axis=1)
        new = np.flatnonzero(m_ok & (miss > tolerance))
        added += new.size
        w, X, words, ok, values, kept = _insert(w, X, words, ok, values, kept, mids, m_X,
                                                m_words, m_ok, m_val, new)
        # judged next round: the two halves of a split interval and the suspect
        # intervals this round had no room for, nothing else
        position = np.searchsorted(w, mids[new])  # where each new point landed
        judge = np.zeros(w.size - 1, bool)
        judge[position - 1] = True
        judge[position] = True
        judge[np.searchsorted(w, waiting)] = True
        active = judge & ok[:-1] & ok[1:]
    order = np.argsort(w[kept] * direction, kind="stable")
    return Refined(omega=w[kept][order], X=X[kept][order], result=words[kept][order],
                   solved=solve.solved, checked=checked, added=added,
                   unresolved=int(unresolved), stopped=stopped)


def _insert(w, X, words, ok, values, kept, mids, m_X, m_words, m_ok, m_val, new):
    """The points with the middles ``new`` (indices into ``mids``) added as kept points,
    in ascending frequency."""
    w = np.concatenate([w, mids[new]])
    X = np.concatenate([X, m_X[new]])
    words = np.concatenate([words, m_words[new]])
    ok = np.concatenate([ok, m_ok[new]])
    values = np.concatenate([values, m_val[new]])
    kept = np.concatenate([kept, np.ones(new.size, bool)])
    order = np.argsort(w, kind="stable")
    return tuple(a[order] for a in (w, X, words, ok, values, kept))


def _line_error_estimate(w, values, floor) -> np.ndarray:
    """Per interval of the ascending points ``w`` ``(P,)`` with forces ``values``
    ``(P, q)``: the straight line's error at its middle, ``h^2 |f''| / 8``, relative to
    the forces there (``floor``: the least force a relative error is taken of), with
    ``f''`` the divided difference over the interval and either neighbour (the larger);
    a grid of two points has no curvature to judge by: every interval is suspect."""
    if w.size < 3:
        return np.full(w.size - 1, np.inf)
    h = np.diff(w)
    slope = np.diff(values, axis=0) / h[:, None]
    second = 2 * np.abs(np.diff(slope, axis=0)) / (h[:-1] + h[1:])[:, None]  # at inner points
    curvature = np.zeros_like(slope)
    curvature[:-1] = second
    curvature[1:] = np.maximum(curvature[1:], second)
    scale = np.maximum(np.abs(0.5 * (values[:-1] + values[1:])), floor)
    return np.max(h[:, None] ** 2 * curvature / 8 / scale, axis=1)
