"""The harmonics plan of a sweep: the band cut into segments of constant K
(:func:`band_segments`), each K checked a posteriori at its segment's first frequency
and doubled until the truncation estimate meets the target (:func:`checked_segments`)."""

from __future__ import annotations

import dataclasses
import math
import warnings

import jax.numpy as jnp
import numpy as np

from ..._engine import hb as _hb
from .. import harmonics as _harmonics
from .starts import newton


def band_segments(from_hz, to_hz, mu_ref, min_k, eta, fixed, cutoff_hz):
    """``(f_a, f_b, K)`` in sweep order (Hz, reference stage); K constant on each:
    ``fixed``, else the first choice of :func:`gearjax._studies.harmonics.harmonics_rule`
    at response base frequencies ``f / mu_ref / eta`` with the system's ``cutoff_hz``,
    never below ``min_k``."""
    if fixed is not None:
        return [(from_hz, to_hz, int(fixed))]
    lo, hi = sorted((from_hz, to_hz))
    edges = np.geomspace(lo, hi, 65)
    ks = [_harmonics.harmonics_rule(f / mu_ref / eta, min_k, eta, cutoff_hz=cutoff_hz)
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


def checked_segments(ctx, segments, F_static, *, fixed: bool):
    """The segments with K checked a posteriori, and the estimates ``[{"from_hz", "K",
    "change", "K_check", "backlash"}]`` (``backlash``: whether the checked point had it;
    ``skipped`` instead where the check was not affordable).

    At each segment's first frequency the point is solved with K and with 2K
    (:func:`gearjax._studies.harmonics.truncation_change`); where the relative change of a
    mesh's RMS force exceeds ``TRUNCATION_TARGET`` K doubles (while the check at twice
    it is affordable, :func:`gearjax._studies.harmonics.check_affordable`) and the check
    repeats. A ``fixed`` K (the caller's ``harmonics``) is checked, warned about
    (``TruncationWarning``) and kept. A resumed run checks again (the same decisions on
    the same machine); a journal segment solved with another K is refused where the walk
    reaches it (:meth:`gearjax._studies.sweep.record.SweepLog.require_K`)."""
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
            change, backlash = truncation_at(ctx, K, f_a, F_static)
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
                    f"{target:.1%}): omit `harmonics` to let the sweep choose K"))
            if change <= target or fixed:
                break
            K = K2  # affordable: the check above solved it
        out.append((f_a, f_b, int(K)))
    return out, estimates


def truncation_at(ctx, K: int, f_hz, F_static) -> tuple[float, bool]:
    """``(change, with backlash)``: the truncation estimate of the point at ``f_hz`` (Hz)
    with K against 2K (the sweep's problems of those K), Newton from the linear guess;
    where that fails with backlash (tooth separation far from contact), of the system
    without backlash (the check then judges the time-varying stiffness only, and says
    so: ``False``)."""
    omega = ctx.omega(f_hz)
    problem, wide = ctx.problem(K), ctx.problem(2 * K)
    sol = newton(problem, jnp.asarray(omega), _hb.linear_guess(problem, omega))
    if not bool(sol.converged) and problem.system.has_backlash:
        lin = dataclasses.replace(problem.system,
                                  backlash=jnp.zeros_like(problem.system.backlash))
        problem, wide = (_hb.hb_problem(lin, p.settings) for p in (problem, wide))
        sol = newton(problem, jnp.asarray(omega), _hb.linear_guess(problem, omega))
    backlash = problem.system.has_backlash
    if not bool(sol.converged):
        return math.inf, backlash
    return _harmonics.truncation_change(problem, wide, sol.y, omega, F_static), backlash
