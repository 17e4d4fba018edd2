"""The a posteriori truncation check of one converged point, for the studies that solve
points outside a sweep (``verify``, ``sensitivity``): the same estimate and target as a
sweep's segment check (:mod:`gearjax._studies.sweep.segments`)."""

from __future__ import annotations

import warnings

import jax.numpy as jnp
import numpy as np

from .._engine import hb as _hb
from .._gear.case import GearCase
from . import harmonics as _harmonics
from .sweep import newton, resize_harmonics


def checked_orders(case: GearCase, problems: dict, K, y, omega: float, *, fixed: bool,
                   command: str = "verify"):
    """The a posteriori truncation check of a converged point, as a sweep makes it for a
    segment (:func:`gearjax._studies.sweep.segments.checked_segments`): the point ``y``
    (scaled unknowns at orders ``K``, base frequency ``omega`` rad/s) solved again with
    each angle's order doubled (:func:`~gearjax._studies.harmonics.truncation_change`);
    where an estimate exceeds ``TRUNCATION_TARGET`` that angle's order doubles (while the
    check at twice it is affordable) and the point is solved again from its unknowns.
    A ``fixed`` K (the caller's ``harmonics``) is checked, warned about
    (:class:`~gearjax._studies.harmonics.TruncationWarning`, in the words of ``command``,
    the study that solved the point) and kept. ``problems`` (K -> problem) gains the
    problems made.

    **Returns:** ``(K, y, estimates)``: the orders kept, the point at them, and per check
    a dict ``K``, ``K_check``, ``change`` (``None`` where not checked: ``skipped`` says
    why, or the doubled solve did not converge)."""
    system, target = case.system, _harmonics.TRUNCATION_TARGET
    orders = _harmonics.orders_json

    def problem(k):
        if k not in problems:
            problems[k] = _hb.hb_problem(system, _harmonics.settings_for(system, k))
        return problems[k]

    estimates = []
    angles = range(len(K)) if isinstance(K, tuple) else (0,)
    while True:
        grow = []
        for g in angles:
            K2 = _harmonics.widened(K, g)
            skip = _harmonics.check_affordable(system, K, g)
            if skip is not None:
                estimates.append({"K": orders(K), "K_check": None, "change": None,
                                  "skipped": skip})
                continue
            change = _harmonics.truncation_change(problem(K), problem(K2), y, omega,
                                                  jnp.asarray(case.F_static))
            finite = bool(np.isfinite(change))
            estimates.append({"K": orders(K), "K_check": orders(K2),
                              "change": float(change) if finite else None})
            if finite and change > target:
                if fixed:
                    warnings.warn(_harmonics.TruncationWarning(
                        f"{command}: {omega / (2 * np.pi):.1f} Hz (base) with K = "
                        f"{_harmonics.orders_text(K)}: truncation estimate {change:.2%} "
                        f"(RMS mesh force change against K = {_harmonics.orders_text(K2)}; "
                        f"target {target:.1%}): omit `harmonics` to let {command} choose "
                        "K"))
                else:
                    grow.append(g)
        if not grow:
            return K, y, estimates
        wide = K
        for g in grow:
            wide = _harmonics.widened(wide, g)
        sol = newton(problem(wide), jnp.asarray(omega), resize_harmonics(y, K, problem(wide)))
        if not bool(sol.converged):
            estimates.append({"K": orders(wide), "K_check": None, "change": None,
                              "skipped": "the point did not converge with the raised orders"})
            return K, y, estimates
        K, y = wide, sol.y
