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
:data:`MAX_ROUNDS`.
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


@dataclasses.dataclass
class Refined:
    """A linear segment's points after refinement: ``omega`` ``(P,)`` (rad/s, in sweep
    order), ``X`` ``(P, C, n)``, ``result`` ``(P,)`` (words); ``checked``: middles
    solved, ``added``: those kept as points."""

    omega: np.ndarray
    X: np.ndarray
    result: np.ndarray
    checked: int = 0
    added: int = 0


@jax.jit
def _forces(problem, Xs, omegas, F_static):
    """``(P, 2m)``: every mesh's RMS force and peak force (N) of the points ``Xs``."""
    r = jax.vmap(mesh_responses, in_axes=(None, 0, 0, None))(problem, Xs, omegas, F_static)
    return jnp.concatenate([r.rms_force, r.max_force], axis=1)


def refine_linear(problem, omegas, F_static, end_omega=None, *,
                  tolerance: float = LINEAR_TOLERANCE, max_points: int | None = None
                  ) -> Refined:
    """Solve the linear segment at the base frequencies ``omegas`` ``(P,)`` (rad/s, in
    sweep order) and refine it (module docstring). ``end_omega``: where the next
    segment starts (solved there, not kept), so the last interval is checked too;
    ``max_points``: no refinement past this many points.

    A middle is solved only where the curvature of the points around the interval (their
    divided differences) puts the straight line's error there above
    :data:`SCREEN` of ``tolerance``: where the curve is plainly straight, nothing
    is solved. **Returns:** :class:`Refined`."""
    omegas = np.asarray(omegas, float)
    direction = np.sign((omegas[-1] if end_omega is None else end_omega) - omegas[0]) or 1.0
    sols = solve_points(problem, jnp.asarray(omegas))
    w = omegas
    X = np.asarray(sols.X)
    words = np.asarray(result_word(sols.result)).reshape(-1)
    ok = np.asarray(sols.converged).reshape(-1)
    values = np.asarray(_forces(problem, sols.X, jnp.asarray(omegas), F_static))
    kept = np.ones(w.size, bool)  # False: the end point, solved for the check only
    if end_omega is not None:
        end = solve_points(problem, jnp.asarray([float(end_omega)]))
        w = np.append(w, float(end_omega))
        X = np.concatenate([X, np.asarray(end.X)])
        words = np.append(words, np.asarray(result_word(end.result)).reshape(-1))
        ok = np.append(ok, np.asarray(end.converged).reshape(-1))
        values = np.concatenate([values, np.asarray(
            _forces(problem, end.X, jnp.asarray([float(end_omega)]), F_static))])
        kept = np.append(kept, False)
    order = np.argsort(w, kind="stable")
    w, X, words, ok, values, kept = (a[order] for a in (w, X, words, ok, values, kept))
    checked = added = 0
    cap = max_points if max_points is not None else 256 * omegas.size
    active = ok[:-1] & ok[1:]  # intervals still to judge
    for _ in range(MAX_ROUNDS):
        room = cap - int(kept.sum())
        if w.size < 2 or room <= 0:
            break
        floor = RMS_FLOOR * np.maximum(np.max(np.abs(values), axis=0), 1e-300)
        suspect = active & (_line_error_estimate(w, values, floor) > SCREEN * tolerance)
        todo = np.flatnonzero(suspect)
        if todo.size == 0:
            break
        mids = 0.5 * (w[todo] + w[todo + 1])
        m_sols = solve_points(problem, jnp.asarray(mids))
        m_ok = np.asarray(m_sols.converged).reshape(-1)
        m_val = np.asarray(_forces(problem, m_sols.X, jnp.asarray(mids), F_static))
        checked += mids.size
        line = 0.5 * (values[todo] + values[todo + 1])
        miss = np.max(np.abs(line - m_val) / np.maximum(np.abs(m_val), floor), axis=1)
        keep = m_ok & (miss > tolerance)
        keep &= np.cumsum(keep) <= room
        if not np.any(keep):
            break
        new = np.flatnonzero(keep)
        added += new.size
        # the two halves of a split interval are judged next round, nothing else
        halves = np.zeros(w.size - 1 + new.size, bool)
        w = np.concatenate([w, mids[new]])
        X = np.concatenate([X, np.asarray(m_sols.X)[new]])
        words = np.concatenate([words, np.asarray(result_word(m_sols.result)).reshape(-1)[new]])
        ok = np.concatenate([ok, m_ok[new]])
        values = np.concatenate([values, m_val[new]])
        kept = np.concatenate([kept, np.ones(new.size, bool)])
        order = np.argsort(w, kind="stable")
        w, X, words, ok, values, kept = (a[order] for a in (w, X, words, ok, values, kept))
        position = np.searchsorted(w, mids[new])  # where each new point landed
        halves[position - 1] = True
        halves[position] = True
        active = halves & ok[:-1] & ok[1:]
    order = np.argsort(w[kept] * direction, kind="stable")
    return Refined(omega=w[kept][order], X=X[kept][order], result=words[kept][order],
                   checked=checked, added=added)


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
