"""The harmonics plan of a sweep: the band cut into segments of constant K
(:func:`band_segments`), each K checked a posteriori at its segment's first frequency
and doubled until the truncation estimate meets the target (:func:`checked_segments`)."""

from __future__ import annotations

import math
import warnings

import jax.numpy as jnp
import numpy as np

from ..._engine import hb as _hb
from .. import harmonics as _harmonics
from .starts import newton, resize_harmonics, settled_start


def band_segments(from_hz, to_hz, mu_ref, min_k, eta, fixed, cutoff_hz, system=None):
    """``(f_a, f_b, K)`` in sweep order (Hz, reference stage); K constant on each:
    ``fixed``, else the first choice of :func:`gearjax._studies.harmonics.harmonics_rule`
    at response base frequencies ``f / mu_ref / eta`` with the system's ``cutoff_hz``,
    never below ``min_k``. For a ``system`` on a torus (``G > 1``) ``K`` is a tuple of
    orders: ``fixed`` on every angle, else
    :func:`gearjax._studies.harmonics.torus_orders_rule` at the lower end of each piece
    of the band (the orders fall as the frequency rises)."""
    torus = system is not None and system.n_angles > 1
    if fixed is not None:
        return [(from_hz, to_hz, (int(fixed),) * system.n_angles if torus else int(fixed))]
    lo, hi = sorted((from_hz, to_hz))
    edges = np.geomspace(lo, hi, 65)
    if torus:
        ks = [_harmonics.torus_orders_rule(system, 2 * math.pi * f / mu_ref,
                                           cutoff_hz=cutoff_hz) for f in edges[:-1]]
    else:
        ks = [_harmonics.harmonics_rule(f / mu_ref / eta, min_k, eta, cutoff_hz=cutoff_hz)
              for f in edges[:-1]]
    segs = []
    for f_a, f_b, k in zip(edges[:-1], edges[1:], ks):
        if segs and segs[-1][2] == k:
            segs[-1] = (segs[-1][0], f_b, k)
        else:
            segs.append((f_a, f_b, k))
    segs = [(float(a), float(b), _harmonics.as_orders(k)) for a, b, k in segs]
    if from_hz > to_hz:
        segs = [(b, a, k) for a, b, k in reversed(segs)]
    segs[0] = (float(from_hz), segs[0][1], segs[0][2])
    segs[-1] = (segs[-1][0], float(to_hz), segs[-1][2])
    return segs


def checked_segments(ctx, segments, F_static, *, fixed: bool, say=None):
    """``(segments, estimates, start)``: the segments with K checked a posteriori, the
    estimates ``[{"from_hz", "K", "change", "K_check", "backlash"}]`` (``backlash``:
    whether the checked point had it; ``skipped`` instead where the check was not
    affordable), and the walk's start ``(y, result, lambda)`` at the band's first
    frequency with the first segment's K where the check solved it on the sweep's own
    problem (else None: the walk finds its start, ``starts.enter_segment``).

    At each segment's first frequency the point is solved with K and with 2K
    (:func:`gearjax._studies.harmonics.truncation_change`); where the relative change of a
    mesh's RMS force exceeds ``TRUNCATION_TARGET`` K doubles (while the check at twice
    it is affordable, :func:`gearjax._studies.harmonics.check_affordable`) and the check
    repeats. On a torus each angle is checked on its own (its order doubled, the others
    kept, :func:`gearjax._studies.harmonics.widened`: one estimate per angle), and only
    the angles whose estimate exceeds the target double. A ``fixed`` K (the caller's
    ``harmonics``) is checked, warned about (``TruncationWarning``) and kept. A resumed
    run checks again (the same decisions on the same machine); a journal segment solved
    with another K is refused where the walk reaches it
    (:meth:`gearjax._studies.sweep.record.SweepLog.require_K`). ``say(line)`` is told
    of each check before it runs."""
    target = _harmonics.TRUNCATION_TARGET
    say = say or (lambda line: None)
    out, estimates, start = [], [], None
    for i, (f_a, f_b, K) in enumerate(segments):
        angles = range(len(K)) if isinstance(K, tuple) else (0,)
        solved = {}  # K -> the point at f_a (one solve serves every angle's check)
        previous = None  # the K checked before, whose point starts a grown K's
        while True:
            grow = []
            for g in angles:
                K2 = _harmonics.widened(K, g)
                where = f" (angle {g})" if isinstance(K, tuple) else ""
                skip = _harmonics.check_affordable(ctx.system, K, g)
                if skip is not None:
                    estimates.append({"from_hz": float(f_a), "K": orders_json(K),
                                      "K_check": None, "change": None, "skipped": skip})
                    warnings.warn(_harmonics.TruncationWarning(
                        f"sweep: segment from {f_a:.1f} Hz with K = "
                        f"{_harmonics.orders_text(K)}: truncation{where} not checked ({skip})"))
                    continue
                say(f"sweep: truncation check, segment {i + 1} of {len(segments)} at "
                    f"{f_a:.1f} Hz: K = {_harmonics.orders_text(K)} against "
                    f"{_harmonics.orders_text(K2)}")
                if K not in solved:
                    solved[K] = checked_point(ctx, K, f_a, solved.get(previous),
                                              first=i == 0)
                previous = K
                change, backlash = truncation_at(ctx, K, f_a, F_static, K2, solved[K])
                estimates.append({"from_hz": float(f_a), "K": orders_json(K),
                                  "K_check": orders_json(K2),
                                  "change": None if not math.isfinite(change) else change,
                                  "backlash": backlash})
                if not math.isfinite(change):
                    warnings.warn(_harmonics.TruncationWarning(
                        f"sweep: segment from {f_a:.1f} Hz with K = "
                        f"{_harmonics.orders_text(K)}: truncation{where} not checked (no "
                        f"converged point there with K = {_harmonics.orders_text(K)} and "
                        f"{_harmonics.orders_text(K2)})"))
                    continue
                if fixed and change > target:
                    warnings.warn(_harmonics.TruncationWarning(
                        f"sweep: segment from {f_a:.1f} Hz with K = "
                        f"{_harmonics.orders_text(K)}: truncation estimate{where} "
                        f"{change:.2%} (RMS mesh force change against K = "
                        f"{_harmonics.orders_text(K2)}; target {target:.1%}): omit "
                        "`harmonics` to let the sweep choose K"))
                if change > target and not fixed:
                    grow.append(g)
            if not grow:
                break
            for g in grow:  # affordable: the check above solved it
                K = _harmonics.widened(K, g)
        out.append((f_a, f_b, K))
        if i == 0 and K in solved and solved[K][0] is ctx.problem(K):
            sol = solved[K][1]
            if bool(sol.converged):
                start = (sol.y, sol.result, ctx.lam(f_a))
    return out, estimates, start


def orders_json(K):
    """``K`` for JSON: an int, or a list of orders."""
    return list(K) if isinstance(K, tuple) else int(K)


def checked_point(ctx, K, f_hz, previous=None, *, first=False):
    """``(problem, solution, with backlash)``: the point at ``f_hz`` (Hz) with the
    sweep's problem of ``K``. From ``previous`` (the converged point of smaller orders
    at ``f_hz``, a result of this function) where given: Newton from its unknowns padded
    with zeros, on the same system. Else, or where that fails, Newton from the linear
    guess; where that fails with backlash (tooth separation far from contact), at the
    band's ``first`` frequency (where the walk starts, and starts from this point) Newton
    from the orbit a time integration settles to, as the walk's start
    (:func:`~gearjax._studies.sweep.starts.settled_start`); where that fails too, or at
    a later segment's start, the point of the system without backlash (a check from it
    judges the time-varying stiffness only, and says so: ``False``)."""
    omega = ctx.omega(f_hz)
    problem = ctx.problem(K)
    if previous is not None and bool(previous[1].converged):
        small, sol_small, backlash = previous
        problem = ctx.problem(K, backlash)
        y0 = resize_harmonics(sol_small.y, small.settings.n_harmonics, problem)
        sol = newton(problem, jnp.asarray(omega), y0)
        if bool(sol.converged):
            return problem, sol, backlash
        problem = ctx.problem(K)
    sol = newton(problem, jnp.asarray(omega), _hb.linear_guess(problem, omega))
    if not bool(sol.converged) and problem.system.has_backlash and first:
        sol = settled_start(problem, omega)
        if bool(sol.converged):
            return problem, sol, True
    if not bool(sol.converged) and problem.system.has_backlash:
        problem = ctx.problem(K, backlash=False)
        sol = newton(problem, jnp.asarray(omega), _hb.linear_guess(problem, omega))
    return problem, sol, problem.system.has_backlash


def truncation_at(ctx, K, f_hz, F_static, K2, point) -> tuple[float, bool]:
    """``(change, with backlash)``: the truncation estimate of ``point`` (the point at
    ``f_hz`` (Hz) with K, :func:`checked_point`) against the sweep's problem of ``K2`` on
    the same system (with or without backlash)."""
    problem, sol, backlash = point
    wide = ctx.problem(K2, backlash)
    if not bool(sol.converged):
        return math.inf, backlash
    return _harmonics.truncation_change(problem, wide, sol.y, ctx.omega(f_hz), F_static), backlash
