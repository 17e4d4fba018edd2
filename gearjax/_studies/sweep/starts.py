"""Where a branch of a sweep starts: Newton from a guess, from the orbit a time
integration settles to, or from the homotopy in backlash; and independent points
solved from scratch."""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np

from ..._engine import aft as _aft
from ..._engine import continuation as _continuation
from ..._engine import hb as _hb
from ..._engine import time_domain as _time_domain
from ..._engine.floquet import return_turns
from ..._engine.kept import kept_program
from ..._engine.newton import newton_jit, solve_hb, solve_linear
from ..._engine.results import RESULTS

newton = newton_jit
"""The compiled Newton solve ``newton(problem, omega, y)`` every start uses."""

SETTLE_PERIODS = 40
"""Base periods a start by time integration (:func:`settled_start`) integrates at most;
the orbit need not have settled to the periodicity tolerance: it is Newton's first
guess."""

SETTLE_RTOL = 1e-6
"""Integration tolerance of :func:`settled_start`: its orbit is only Newton's first
guess (the periodicity check is at ``100 SETTLE_RTOL``)."""


def enter_segment(problem, previous, lam, omega_ref, guess=None):
    """``(y, result, lambda)`` (``result`` a ``RESULTS`` item): scaled unknowns with this
    segment's harmonics, converged at ``lambda``, where the segment starts.

    Continuing ``previous`` ``(K, y, lambda, before)`` (the last point of the segment
    before, which lies past ``lam``, the boundary, and the point before it): at ``lam``
    itself, by Newton from the chord between the two, so that the next segment starts
    on the boundary (where a speculation on it starts too); where that Newton fails, at
    the last point's own ``lambda`` from it. A fresh branch starts at ``lam``, its first
    guess ``guess`` ``(K, y, lambda)`` (the furthest point of the branch before, as a
    rig's response jumps from it) and then :func:`start_point` from that point's
    state."""
    if previous is None:
        state = None
        if guess is not None:
            K_old, y_old, _ = guess
            y = resize_harmonics(y_old, K_old, problem)
            sol = newton(problem, jnp.asarray(lam * omega_ref), y)
            if bool(sol.converged):
                return sol.y, sol.result, lam
            state = _time_domain.hb_initial_state(y.reshape(problem.shape) * problem.x_scale,
                                                  lam * omega_ref, problem.settings.eta,
                                                  problem.basis)
        return (*start_point(problem, lam * omega_ref, state), lam)
    K_old, y_old, lam_old, before = previous
    if before is not None and (before[1] - lam) * (lam_old - lam) < 0:
        w = (lam - before[1]) / (lam_old - before[1])
        chord = (1 - w) * np.asarray(before[0]) + w * np.asarray(y_old)
        sol = newton(problem, jnp.asarray(lam * omega_ref),
                     resize_harmonics(chord, K_old, problem))
        if bool(sol.converged):
            return sol.y, sol.result, lam
    sol = newton(problem, jnp.asarray(lam_old * omega_ref),
                 resize_harmonics(y_old, K_old, problem))
    return sol.y, sol.result, lam_old


def start_point(problem, omega, state=None):
    """``(y, result)`` at ``omega`` (rad/s): Newton from the linear, in-contact
    guess; with backlash, when that fails, :func:`backlash_start`. With a ``state``
    ``(x0, v0)`` (where a branch left off) the time integration starts from it, and
    before Newton."""
    backlash = problem.system.has_backlash
    if state is not None and backlash:
        sol = settled_start(problem, omega, state)
        if bool(sol.converged):
            return sol.y, sol.result
    sol = newton(problem, jnp.asarray(omega), _hb.linear_guess(problem, omega))
    if not bool(sol.converged) and backlash:
        # the integration from ``state`` failed already: straight to the homotopy
        sol = backlash_start(problem, omega) if state is None else backlash_homotopy(
            problem, omega)
    return sol.y, sol.result


def backlash_start(problem, omega) -> _hb.HBSolution:
    """A periodic solution with backlash at ``omega`` (rad/s) where Newton from the
    linear guess fails (tooth separation far from the in-contact response): Newton from
    the orbit that a time integration settles to (:func:`settled_start`), else the
    homotopy in backlash 0 -> b (:func:`backlash_homotopy`, a continuation of a few
    hundred points at the full K, far slower)."""
    sol = settled_start(problem, omega)
    if bool(sol.converged):
        return sol
    return backlash_homotopy(problem, omega)


def settled_start(problem, omega, state=None) -> _hb.HBSolution:
    """Newton from the orbit that a time integration at ``omega`` (rad/s) settles to (a
    stable one, as a test rig's response settles after a jump), from ``state`` ``(x0,
    v0)`` or the static contact state (``time_domain.simulate``: Dopri8 at
    :data:`SETTLE_RTOL`, at most :data:`SETTLE_PERIODS` base periods; the last ``eta``
    periods give the harmonics; on a torus, whose response settles to no period, a
    least-squares fit over many turns, :func:`_settled_on_torus`). A solver failure is
    returned as a ``nonlinear_max_steps_reached`` solution at the linear guess."""
    if problem.basis.G > 1:
        return _settled_on_torus(problem, omega, state)
    K, eta = problem.settings.n_harmonics, problem.settings.eta
    settings = _time_domain.TimeDomain(
        rtol=SETTLE_RTOL, atol=SETTLE_RTOL, periodic_tol=100 * SETTLE_RTOL,
        max_periods=SETTLE_PERIODS * eta, sample_periods=eta,
        n_samples=-(-4 * (K + 1) // eta))
    x0, v0 = (None, None) if state is None else state
    tr = _time_domain.simulate(problem.system, omega, x0=x0, v0=v0, settings=settings)
    X = _aft.analysis(tr.x.T, K)
    y = (X / problem.x_scale).reshape(-1)
    if not bool(tr.integrated) or not bool(jnp.all(jnp.isfinite(y))):
        return _failed(problem, omega)
    return newton(problem, jnp.asarray(omega), y)


def fit_turns(basis) -> int:
    """Turns of the base angle a fit of torus coefficients to a time history spans
    (:func:`_settled_on_torus`): the near return of the torus line
    (:func:`gearjax._engine.floquet.return_turns`), and at least two cycles of the slowest
    beat between two of the basis's frequencies (the closest pair of ``|k . rates|``,
    zero included), which the fit must tell apart."""
    nu = np.unique(np.abs(_aft.frequency_numbers(basis)))
    beat = float(np.min(np.diff(nu))) if nu.size > 1 else 1.0
    q, _ = return_turns(basis.rates)
    return int(max(q, math.ceil(2.0 / max(beat, 1e-6))))


def _settled_on_torus(problem, omega, state=None) -> _hb.HBSolution:
    """:func:`settled_start` on a torus: integrate :data:`SETTLE_PERIODS` base periods
    from ``state`` (or the static contact state), then fit the coefficients of the basis
    by least squares to the motion sampled over :func:`fit_turns` more
    (:func:`gearjax._engine.aft.line_analysis`: four samples per period of the highest
    frequency and at least four per coefficient), then Newton."""
    basis, system = problem.basis, problem.system
    turns = fit_turns(basis)
    top = float(np.max(np.abs(_aft.frequency_numbers(basis))))
    count = max(4 * basis.n_coefficients, math.ceil(4 * top * turns))
    tau = 2 * np.pi * (SETTLE_PERIODS + turns * np.arange(1, count + 1) / count)
    x0, v0 = _time_domain.contact_state_jit(system) if state is None else state
    settings = _time_domain.TimeDomain(rtol=SETTLE_RTOL, atol=SETTLE_RTOL)
    x, _, ok = _time_domain.sample_trajectory(system, omega, x0, v0, tau, settings)
    if not bool(ok) or not bool(jnp.all(jnp.isfinite(x))):
        return _failed(problem, omega)
    X = _aft.line_analysis(basis, tau, np.asarray(x))
    y = jnp.asarray((X / np.asarray(problem.x_scale)).reshape(-1))
    return newton(problem, jnp.asarray(omega), y)


def _failed(problem, omega) -> _hb.HBSolution:
    """A start that found nothing: a ``nonlinear_max_steps_reached`` solution at the
    linear guess."""
    y = _hb.linear_guess(problem, omega)
    return _hb.HBSolution(X=y.reshape(problem.shape) * problem.x_scale, y=y,
                          omega=jnp.asarray(omega, float),
                          result=RESULTS.nonlinear_max_steps_reached,
                          stats={"num_steps": jnp.asarray(0),
                                 "residual_norm": jnp.asarray(jnp.inf)})


def backlash_homotopy(problem, omega) -> _hb.HBSolution:
    """Continue from the linear solution in backlash scale 0 -> 1 at fixed ``omega``
    (rad/s); Newton at full backlash from the continuation's last point."""
    param = _continuation.SystemParameter(problem=problem, omega_value=jnp.asarray(omega),
                                          where=lambda s: s.backlash)
    lin = _hb.linear_guess(problem, omega)
    start = newton(param.split(0.0)[0], jnp.asarray(omega), lin)
    branch = _continuation.continue_branch(param, start.y, 0.0, 1.0,
                                           _continuation.Settings(max_dlambda=0.05), 500)
    return newton(problem, jnp.asarray(omega), jnp.asarray(branch.y[-1]))


def resize_harmonics(y, K_old, problem):
    """Scaled unknowns of ``K_old`` harmonics (orders of each angle on a torus) padded
    with zeros or truncated to ``problem``'s basis (flat; :func:`gearjax._engine.aft.resize`
    by wave vector)."""
    n = problem.shape[1]
    if K_old == problem.settings.n_harmonics:
        return jnp.asarray(np.asarray(y).reshape(-1))
    old = _hb.harmonic_basis(problem.system, dataclasses.replace(
        problem.settings, n_harmonics=K_old, n_time=None))
    new = _aft.resize(old, problem.basis, np.asarray(y).reshape(old.n_coefficients, n))
    return jnp.asarray(new.reshape(-1))


POINTS_CHUNK = 8
"""Points per call of the compiled point solver: a batch of any size runs as chunks of
this many (the last one padded with its own last frequency), a single point alone, so
that one problem compiles two programs whatever the batch sizes a sweep or its
refinement asks for."""


def solve_points(problem, omegas):
    """Independent solutions at the base frequencies ``omegas`` ``(P,)`` (rad/s), from the
    linear guess: one factorisation each without backlash (``newton.solve_linear``), Newton
    with backlash; one point after the other (``lax.map``: a vmapped batch of dense
    factorisations is slower on a CPU). Returns an ``HBSolution`` batched over ``P``."""
    solve = _newton_points if problem.system.has_backlash else _linear_points
    omegas = np.asarray(omegas, dtype=float)  # host: chunks of any P with no program of their own
    P = omegas.shape[0]
    if P <= 1:
        return solve(problem, omegas)
    padded = np.concatenate([omegas, np.repeat(omegas[-1:], -P % POINTS_CHUNK)])
    chunks = [solve(problem, padded[i:i + POINTS_CHUNK])
              for i in range(0, padded.shape[0], POINTS_CHUNK)]
    return jax.tree.map(lambda *parts: jax.device_put(np.concatenate(parts)[:P]), *chunks)


@kept_program
def _newton_points(problem, omegas):
    return jax.lax.map(lambda w: solve_hb(problem, w), omegas)


@kept_program
def _linear_points(problem, omegas):
    return jax.lax.map(lambda w: solve_linear(problem, w), omegas)
