"""The continuation corrector: Broyden's method from the factorised bordered Jacobian, with
a full-Newton fallback.

Solves ``[G(y, lambda); t . (z - z_pred)] = 0`` for ``z = (y, lambda)`` from the
predictor ``z_pred``, ``G`` the residual of an
:class:`~gearjax._engine.continuation.AbstractParameter` and ``t = (ty, tlam)`` the
tangent at the last point. Each quasi-Newton iteration is one solve with the bordered
Jacobian at the last point (factorised, :mod:`gearjax._engine.bordered`, or kept for
matrix-free solves, :mod:`gearjax._engine.krylov`; ``krylov.solve`` either way) and a
few dot products: Broyden's secant updates learn how the Jacobian changed over the step (with
exact backlash it changes by the time samples that crossed a contact boundary, which a
chord iteration contracts away only linearly). When the iterations stop contracting,
the corrector restarts from the predictor in full Newton, refactorising at every
iterate. Converged: the scaled step below ``rtol max(1, max |y|)`` and the residual
below ``sqrt(rtol)`` (max norms).
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array

from . import krylov as _krylov


class _Corrector(eqx.Module):
    """Corrector loop state: iterate, total and per-phase iteration counts, ``full`` (the
    quasi-Newton phase stalled: go on in full Newton), outcome, the previous step size
    (contraction check) and the quasi-Newton steps so far (``(max_corrector + 1, N + 1)``,
    rows past ``i`` zero)."""

    y: Array
    lam: Array
    k: Array
    i: Array
    full: Array
    done: Array
    converged: Array
    prev: Array
    steps: Array


def broyden_step(z, steps, i):
    """Step ``i`` of Broyden's method from the chord step ``z = -B0^-1 F(z_i)`` ``(N + 1,)``
    and the steps ``steps[:i]`` taken before it (good Broyden, inverse updated in product
    form: Kelley, *Iterative Methods for Linear and Nonlinear Equations*, SIAM 1995,
    algorithm brsol, full steps). Where an update would be singular the chord step is
    taken.

        z += s_{j+1} (s_j . z) / |s_j|^2  for j < i - 1;
        s_i = z / (1 - s_{i-1} . z / |s_{i-1}|^2)
    """
    norms = jnp.sum(steps**2, axis=1)
    norms = jnp.where(norms > 0, norms, 1.0)

    def update(j, z):
        return z + steps[j + 1] * (steps[j] @ z) / norms[j]

    z = jax.lax.fori_loop(0, jnp.maximum(i - 1, 0), update, z)
    last = jnp.maximum(i - 1, 0)
    denom = 1.0 - (steps[last] @ z) / norms[last]
    ok = (i > 0) & (jnp.abs(denom) > 1e-3)
    return jnp.where(ok, z / jnp.where(ok, denom, 1.0), z)


def correct(param, factors, ty, tlam, y_p, lam_p, rtol: float,
            max_corrector: int, full_newton=True):
    """Correct the predictor ``(y_p, lam_p)`` onto the branch of ``param`` (jittable).

    **Arguments:** ``param``: the residual ``G`` and its bordered factorisation
    (``residual(y, lam)``, ``factor(y, lam, ty, tlam)``); ``factors``: the bordered
    Jacobian at the last point, last row the tangent ``(ty, tlam)`` ``((N,), scalar)``
    there; ``rtol``: tolerance; ``max_corrector``: iterations per phase; ``full_newton`` (a
    boolean, may be traced): whether a stalled quasi-Newton phase goes on in full Newton
    (else it ends there, not converged: factors from an earlier point, which the caller
    replaces).

    **Returns:** ``(y, lam, iterations, converged)``: the last iterate (the last finite
    one), the iterations of both phases together, and whether it converged.

    The two phases are separate loops, so the first reads ``factors`` in place (no copy
    of the factorised matrix per iteration).
    """

    def iterate(c, factors, full):
        r = param.residual(c.y, c.lam)
        arc = ty @ (c.y - y_p) + tlam * (c.lam - lam_p)
        d = _krylov.solve(factors, -jnp.concatenate([r, arc[None]]))
        if not full:
            d = broyden_step(d, c.steps, c.i)
        size = jnp.max(jnp.abs(d))
        finite = jnp.all(jnp.isfinite(d))
        small = size <= rtol * jnp.maximum(1.0, jnp.max(jnp.abs(c.y)))
        ok = finite & small & (jnp.max(jnp.abs(r)) <= jnp.sqrt(rtol))
        if full:
            stalled = jnp.asarray(False)
            failed = ~finite | (c.i + 1 >= max_corrector)
        else:
            # the iterations must contract; when they do not (the Jacobian changed too much,
            # e.g. contact samples crossed the clearance), restart from the predictor in
            # full Newton
            stalled = ((c.i > 1) & (size > c.prev)) | (c.i + 1 >= max_corrector)
            failed = ~finite
        restart = stalled & ~ok & ~failed
        return _Corrector(y=jnp.where(finite & ~restart, c.y + d[:-1], c.y),
                          lam=jnp.where(finite & ~restart, c.lam + d[-1], c.lam),
                          k=c.k + 1, i=c.i + 1, full=restart, done=ok | failed | restart,
                          converged=ok, prev=jnp.where(c.i == 0, jnp.inf, size),
                          steps=c.steps if full else c.steps.at[c.i].set(d))

    def broyden(c):
        return iterate(c, factors, False)

    def newton(c):
        return iterate(c, param.factor(c.y, c.lam, ty, tlam), True)

    not_done = lambda c: ~c.done  # noqa: E731
    init = _Corrector(y=y_p, lam=lam_p, k=jnp.asarray(0), i=jnp.asarray(0),
                      full=jnp.asarray(False), done=jnp.asarray(False),
                      converged=jnp.asarray(False), prev=jnp.asarray(jnp.inf),
                      steps=jnp.zeros((max_corrector + 1, y_p.shape[0] + 1)))
    c = jax.lax.while_loop(not_done, broyden, init)
    # the quasi-Newton phase stalled: full Newton from the predictor (flag ``full`` set)
    restart = lambda c: jax.lax.while_loop(not_done, newton, dataclasses.replace(  # noqa: E731
        c, y=y_p, lam=lam_p, i=jnp.asarray(0), done=jnp.asarray(False),
        prev=jnp.asarray(jnp.inf)))
    c = jax.lax.cond(c.full & full_newton, restart, lambda c: c, c)
    return c.y, c.lam, c.k, c.converged
