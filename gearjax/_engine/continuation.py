"""Pseudo-arclength continuation of harmonic-balance solutions in a scalar parameter.

The branch ``G(y, lambda) = 0`` (scaled HB residual, scaled unknowns ``y``) is
followed in arclength ``s`` of ``z = (y, lambda)``: tangent predictor
``z + h t``, bordered quasi-Newton (Broyden) corrector on
``[G(z); t . (z - z_pred)] = 0``, new tangent from the bordered system (its last row
keeps the orientation), adaptive step, folds where ``d lambda / ds`` changes sign,
located by Hermite interpolation of ``lambda(s)`` between the two points. The
parameter is the frequency (``FrequencyParameter``, ``lambda = Omega / Omega_ref``)
or any scalar that scales a field of the ``System`` (``SystemParameter``: torque,
backlash, damping, ...).

One step is one jittable function (``arclength_step``), driven either from Python
(``continue_branch``: progress, journaling, resumable) or entirely compiled in a
``lax.while_loop`` (``continue_compiled``: small systems, where per-call overhead
would dominate).
"""

from __future__ import annotations

import abc
import dataclasses
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from . import bordered as _bordered
from . import corrector as _corrector
from . import hb as _hb
from . import krylov as _krylov
from .kept import kept_program
from .results import RESULTS


class AbstractParameter(eqx.Module):
    """A residual ``G(y, lambda)`` of scaled HB unknowns and one scalar parameter."""

    problem: eqx.AbstractVar[_hb.HBProblem]

    @abc.abstractmethod
    def split(self, lam) -> tuple[_hb.HBProblem, Array]:
        """The problem and base frequency (rad/s) at parameter value ``lam``."""

    def residual(self, y, lam):
        problem, omega = self.split(lam)
        return _hb.residual(problem, y, omega)

    def jacobian(self, y, lam):
        problem, omega = self.split(lam)
        return _hb.jacobian(problem, y, omega)

    def d_lambda(self, y, lam):
        return jax.jvp(lambda l: self.residual(y, l), (lam,), (jnp.ones_like(lam),))[1]

    def factor(self, y, lam, ty, tlam, single: bool = False):
        """Factors of the bordered Jacobian ``[[dG/dy, dG/dlambda], [ty^T, tlam]]``:
        for matrix-free solves where the problem's ``linear_solver`` is ``"krylov"``
        (``_krylov.factor``, no factorisation, ``single`` has no effect; ``"auto"``
        factorises here: a factorised point serves a corrector's and a tangent's solves
        at about a millisecond each, and the matrix-free solve has no fallback inside the
        corrector); else condensed to the motions that deflect a mesh where some deflect
        none (``problem.mesh_null``; ``_bordered.factor``, from the harmonic-balance
        Jacobian), else dense from :meth:`jacobian`. Solved with ``_krylov.solve``. A
        subclass that replaces the residual of such a problem replaces this too."""
        problem, omega = self.split(lam)
        g = self.d_lambda(y, lam)
        if problem.settings.linear_solver == "krylov":
            return _krylov.factor(problem, y, omega, g, ty, tlam)
        if problem.mesh_null is None:
            return _bordered.dense(self.jacobian(y, lam), g, ty, tlam, single)
        return _bordered.factor(problem, y, omega, g, ty, tlam, single)

    def omega(self, lam):
        return self.split(lam)[1]


class FrequencyParameter(AbstractParameter):
    """``lambda = Omega / omega_ref``: a frequency sweep."""

    problem: _hb.HBProblem
    omega_ref: Array

    def split(self, lam):
        return self.problem, lam * self.omega_ref


class SystemParameter(AbstractParameter):
    """``lambda`` scales one ``System`` field at fixed frequency: ``field = lambda * base``.

    ``where`` selects the field (e.g. ``lambda s: s.backlash``); ``lambda`` from 0 to 1
    is the homotopy from a linear start to the full backlash.
    """

    problem: _hb.HBProblem
    omega_value: Array
    where: Callable = eqx.field(static=True)

    def split(self, lam):
        base = self.where(self.problem.system)
        system = eqx.tree_at(self.where, self.problem.system, lam * base)
        return eqx.tree_at(lambda p: p.system, self.problem, system), self.omega_value


class Settings(eqx.Module):
    """Continuation settings.

    ``step``: first arclength step (scaled units: unknowns in characteristic
    lengths, lambda relative); ``min_step``, ``max_step``: bounds of the adaptive
    step; ``max_dlambda``: largest parameter change per step; ``max_corrector``:
    corrector iterations per point; ``fast``/``slow``: iteration counts that grow or
    shrink the step; ``rtol``: corrector tolerance; ``fold_step``: a fold is only
    accepted across a step this short (longer ones are retried shorter), which sets
    the accuracy of the located fold; ``single``: the dense LU of the bordered Jacobian
    (the corrector's start, the tangent) in single precision, residual, iterates and
    tangent in double (the quasi-Newton corrector converges to the same ``rtol``; the
    tangent is refined, :func:`_tangent`); the full-Newton fallback factorises in double.
    ``reuse``: keep the factors of an earlier point for as long as they carry the corrector
    within ``fast`` iterations and the tangent refined with them is accurate
    (:func:`arclength_step`), instead of factorising at every point.

    The counts and switches (``max_corrector``, ``fast``, ``slow``, ``single``,
    ``reuse``) are static: a program each. The steps and tolerances are inputs of the
    compiled step and start (:func:`continue_branch`): continuations of one problem with
    other steps (a sweep of another band) run the same programs.
    """

    step: float = 0.02
    min_step: float = 1e-7
    max_step: float = 0.2
    max_dlambda: float = 0.02
    max_corrector: int = eqx.field(static=True, default=15)
    fast: int = eqx.field(static=True, default=5)
    slow: int = eqx.field(static=True, default=10)
    rtol: float = 1e-9
    fold_step: float = 1e-3
    single: bool = eqx.field(static=True, default=False)
    reuse: bool = eqx.field(static=True, default=False)


class ArcState(eqx.Module):
    """Continuation state after a step attempt.

    ``y``, ``lam``: last accepted point; ``ty``, ``tlam``: unit tangent there
    (``tlam`` = d lambda / ds); ``h``: next step; ``accepted``: the attempt
    succeeded; ``fold``: the accepted step crossed a fold (``tlam`` changed sign);
    ``fold_lam``: its located parameter value; ``steps``: corrector iterations;
    ``factors``: of the bordered Jacobian at the current point (``_bordered.Factors``,
    or ``_krylov.KrylovFactors`` where they are matrix-free),
    reused by the next corrector (Broyden from them: one factorisation per point), or at an
    earlier one (``Settings.reuse``): ``age`` accepted points back, last row that point's
    own tangent where ``own`` is set, else the tangent of the point before it (or, for
    the first point of a continuation, the tangent :func:`start` began from).
    """

    y: Array
    lam: Array
    ty: Array
    tlam: Array
    h: Array
    accepted: Array
    fold: Array
    fold_lam: Array
    steps: Array
    factors: _bordered.Factors | _krylov.KrylovFactors
    age: Array
    own: Array


def _tangent(param: AbstractParameter, y, lam, ty, tlam, factors, single: bool, fresh=True):
    """The solution ``t`` ``(N + 1,)`` of ``[[J, g], [ty^T, tlam]] t = e_last`` at ``(y,
    lam)`` (the tangent, not normalised, oriented along the previous one ``(ty, tlam)``, a
    unit vector) from ``factors`` of the bordered Jacobian, and whether it is accurate:
    ``(t, ok)``.

    From ``fresh`` factors (of this point and border; a boolean, may be traced) ``t`` is
    one solve: exact in double, ``ok`` true. From single-precision ones (``single``,
    :class:`Settings`), or from factors of an earlier point (``fresh`` false, starting
    from ``(ty, tlam)``), ``t`` is refined in double against the exact bordered product (a
    Jacobian-vector product of the residual). The error left after a correction ``d`` is
    estimated from the contraction ``rho = |d| / |d_before|`` as ``|d| rho / (1 - rho)``
    (from fresh factors the solve counts as the first correction; from an old tangent
    there is no estimate before the second); ``ok``: that estimate fell below
    :data:`SINGLE_TOL` of ``t`` within :data:`SINGLE_REFINE` corrections, and, from earlier
    factors, below a quarter of ``|t[-1]|`` (``d lambda / ds``, whose sign marks a fold:
    near a fold the point is factorised afresh).
    """
    e = jnp.zeros(y.shape[0] + 1).at[-1].set(1.0)
    if fresh is True and not single:
        return _krylov.solve(factors, e), jnp.asarray(True)
    t = jax.lax.cond(fresh, lambda: _krylov.solve(factors, e), lambda: jnp.append(ty, tlam))
    size = jnp.where(fresh, jnp.linalg.norm(t), jnp.inf)
    exact = fresh & (not single)

    def refine(c):
        t, size, _, i = c
        Jt = jax.jvp(param.residual, (y, lam), (t[:-1], t[-1]))[1]
        d = _krylov.solve(factors, e - jnp.concatenate([Jt, (ty @ t[:-1] + tlam * t[-1])[None]]))
        new = jnp.linalg.norm(d)
        rho = new / size  # no estimate after the first correction from an old tangent
        contracts = jnp.isfinite(size) & (rho < 1)
        error = jnp.where(contracts, new * rho / jnp.where(contracts, 1 - rho, 1.0), jnp.inf)
        return t + d, new, error, i + 1

    def go_on(c):
        t, _, error, i = c
        return ~(error <= SINGLE_TOL * jnp.linalg.norm(t)) & (i < SINGLE_REFINE)

    t, _, error, _ = jax.lax.while_loop(go_on, refine, (t, size, jnp.where(exact, 0.0, jnp.inf),
                                                        jnp.asarray(0)))
    # from earlier factors the refinement stops near the tolerance: its d lambda / ds must
    # be well clear of that error too, or its sign (which marks a fold) is not known
    clear = fresh | (4 * error <= jnp.abs(t[-1]))
    return t, (error <= SINGLE_TOL * jnp.linalg.norm(t)) & clear


SINGLE_REFINE = 4
"""Most refinement steps of a tangent (:func:`_tangent`)."""

SINGLE_TOL = 1e-4
"""A refined tangent is accurate where its estimated error is below this fraction of it
(:func:`_tangent`)."""


def tangent_factors(param: AbstractParameter, y, lam, ty, tlam, single: bool = False,
                    fallback=None):
    """Factorise the bordered Jacobian at ``(y, lam)`` (last row the previous tangent) and
    return the new unit tangent ``(ty, tlam)`` with the factors. With ``single`` the LU
    is in single precision and the tangent refined (:func:`_tangent`); where that does
    not converge, ``fallback`` ``(N + 1,)`` stands in for it (the chord from the last
    point, a tangent from double factors)."""
    if single and fallback is None:
        raise ValueError("tangent_factors with single=True needs a fallback tangent")
    factors = param.factor(y, lam, ty, tlam, single)
    t, ok = _tangent(param, y, lam, ty, tlam, factors, single)
    if single:
        t = jnp.where(ok, t, fallback)
    t = t / jnp.linalg.norm(t)
    return t[:-1], t[-1], factors


def tangent(param: AbstractParameter, y, lam, ty, tlam):
    """Unit tangent at ``(y, lam)`` oriented along the previous tangent ``(ty, tlam)``."""
    return tangent_factors(param, y, lam, ty, tlam)[:2]


def start(param: AbstractParameter, y, lam, direction, settings: Settings) -> ArcState:
    """State at a converged point, tangent pointing to increasing ``lam`` if ``direction > 0``."""
    lam = jnp.asarray(lam, float)
    ty, tlam = tangent(param, y, lam, jnp.zeros_like(y), jnp.sign(direction) * 1.0)
    ty, tlam, factors = tangent_factors(param, y, lam, ty, tlam, settings.single,
                                        fallback=jnp.append(ty, tlam))
    return ArcState(y=y, lam=lam, ty=ty, tlam=tlam,
                    h=jnp.asarray(settings.step, float), accepted=jnp.asarray(True),
                    fold=jnp.asarray(False), fold_lam=jnp.asarray(jnp.nan, float),
                    steps=jnp.asarray(0), factors=factors, age=jnp.asarray(0),
                    own=jnp.asarray(False))


def arclength_step(param: AbstractParameter, state: ArcState, settings: Settings) -> ArcState:
    """One predictor-corrector attempt from ``state`` (jittable).

    The corrector (:func:`gearjax._engine.corrector.correct`) is Broyden's method started
    from the state's factors of the bordered Jacobian, with a full-Newton restart when it
    stops contracting; the new point's Jacobian is factorised once, for its tangent and
    for the next corrector. On success the state moves to the new point with a grown or
    kept step; on failure it stays and the step halves (the caller stops below
    ``min_step``).

    A corrected point further from the predictor than the step length (on another
    stretch of the curve, across a fold) counts as not converged.

    With ``settings.reuse`` the factors are those of an earlier point for as long as they
    serve: where the corrector from them does not converge, the bordered Jacobian is
    factorised at the last point (last row its tangent) and the corrector runs again from
    those (with its full-Newton restart); at the new point the tangent is refined from
    the last one with the factors in hand (:func:`_tangent`), and the new point is
    factorised only where that refinement does not reach :data:`SINGLE_TOL` (and a
    quarter of ``|d lambda / ds|``) or the corrector took more than ``settings.fast``
    iterations.

    The returned ``factors`` (with ``age`` and ``own``) are those the returned state
    continues from: the new point's where accepted, else those the corrector used.
    """
    h = jnp.minimum(state.h, settings.max_dlambda / jnp.maximum(jnp.abs(state.tlam), 1e-12))
    y_p = state.y + h * state.ty
    lam_p = state.lam + h * state.tlam
    stale = (state.age > 0) & settings.reuse

    def correct(factors, fresh, before):
        y, lam, k, converged = _corrector.correct(
            param, factors, state.ty, state.tlam, y_p, lam_p, settings.rtol,
            settings.max_corrector, fresh | ~stale)
        # the corrector may land on another stretch of the curve across the predictor's
        # hyperplane (past a fold): a point further from the predictor than the step
        # itself does not count as converged (old factors: corrected again from fresh
        # ones; fresh: the step is retried shorter)
        near = jnp.sqrt(jnp.sum((y - y_p) ** 2) + (lam - lam_p) ** 2) <= h
        converged = converged & near
        return (y, lam, before[2] + k, converged), converged

    def at_last_point():
        return (param.factor(state.y, state.lam, state.ty, state.tlam, settings.single),
                jnp.asarray(0), jnp.asarray(True))

    held = (state.factors, state.age, state.own)
    if settings.reuse:
        (y, lam, k, converged), _, held = _held_or_fresh(
            correct, (y_p, lam_p, jnp.asarray(0), jnp.asarray(False)), held, at_last_point,
            True, stale)
    else:
        (y, lam, k, converged), _ = correct(state.factors, True, (None, None, 0))

    def new_tangent(_):
        def tangent(factors, fresh, _):
            return _tangent(param, y, lam, state.ty, state.tlam, factors, settings.single,
                            fresh)

        def at_new_point():
            return (param.factor(y, lam, state.ty, state.tlam, settings.single),
                    jnp.asarray(0), jnp.asarray(False))

        if settings.reuse:
            aged = (held[0], held[1] + 1, held[2])
            t, ok, factors = _held_or_fresh(tangent, jnp.zeros(y.shape[0] + 1), aged,
                                            at_new_point, k <= settings.fast, True)
        else:
            factors = at_new_point()
            t, ok = tangent(factors[0], True, None)
        # where the tangent from single-precision factors does not converge (a nearly
        # singular Jacobian), the chord from the last point stands in for it
        t = jnp.where(ok, t, jnp.concatenate([y - state.y, (lam - state.lam)[None]]))
        t = t / jnp.linalg.norm(t)
        return (t[:-1], t[-1]), factors

    def old_tangent(_):
        return (state.ty, state.tlam), held

    (ty, tlam), factors = jax.lax.cond(converged, new_tangent, old_tangent, None)
    crossed = converged & (jnp.sign(tlam) != jnp.sign(state.tlam))
    # a fold crossed with a long step is approached again with shorter ones, so that
    # the interpolated fold location below is accurate
    refine = crossed & (h > settings.fold_step)
    accepted = converged & ~refine
    fold = crossed & ~refine
    # d lambda/ds taken linear in s between the two tangents (a, b) over the chord
    # length h: zero at s* = h a / (a - b), where lambda = lam_old + a s* / 2
    a, b = state.tlam, tlam
    chord_length = jnp.sqrt(jnp.sum((y - state.y) ** 2) + (lam - state.lam) ** 2)
    fold_lam = jnp.where(fold, state.lam + chord_length * a**2 / (2 * jnp.where(fold, a - b, 1.0)),
                         jnp.nan)
    grow = jnp.where(k <= settings.fast, 1.5, jnp.where(k >= settings.slow, 0.6, 1.0))
    h_next = jnp.where(accepted, jnp.minimum(h * grow, settings.max_step),
                       jnp.where(refine, jnp.maximum(h * 0.25, settings.fold_step), h * 0.5))
    factors, age, own = jax.lax.cond(accepted, lambda _: factors, lambda _: held, None)
    keep = lambda new, old: jnp.where(accepted, new, old)  # noqa: E731
    return ArcState(
        y=keep(y, state.y),
        lam=keep(lam, state.lam),
        ty=keep(ty, state.ty),
        tlam=keep(tlam, state.tlam),
        h=h_next,
        accepted=accepted,
        fold=fold,
        fold_lam=fold_lam,
        steps=k,
        factors=factors,
        age=age,
        own=own,
    )


def _held_or_fresh(attempt, empty, held, refactor, use_held, retry):
    """``attempt(factors, fresh, before) -> (out, ok)`` with the factors ``held`` where
    ``use_held``, else with fresh ones (``refactor()``); where the held ones do not serve
    (``ok`` false) and ``retry``, again with fresh ones (``before``: the first attempt's
    ``out``). ``held`` and ``refactor()`` are ``(factors, age, own)`` (:class:`ArcState`);
    ``empty``: an ``out`` of the right shapes; the booleans may be traced. A loop of at most
    two attempts, so that ``attempt`` and ``refactor`` are traced once (jittable).

    **Returns:** ``(out, ok, (factors, age, own))`` of the last attempt.
    """
    use_held, retry = jnp.asarray(use_held, bool), jnp.asarray(retry, bool)

    def body(c):
        i, before, _, used = c
        fresh = ~use_held | (i > 0)
        used = jax.lax.cond(fresh, lambda _: refactor(), lambda u: u, used)
        out, ok = attempt(used[0], fresh, before)
        return i + 1, out, ok, used

    def go_on(c):
        i, _, ok, _ = c
        return (i == 0) | ((i == 1) & ~ok & use_held & retry)

    _, out, ok, used = jax.lax.while_loop(go_on, body, (jnp.asarray(0), empty,
                                                        jnp.asarray(False), held))
    return out, ok, used


class Branch(eqx.Module):
    """Points of a continued branch, in order along the branch: :func:`continue_branch`'s
    (numpy arrays, ``P = n_points``) and :func:`continue_compiled`'s (arrays of the
    program's fixed size ``P = max_points``; rows past ``n_points`` are padding, NaN in
    ``lam``, ``omega``, ``fold_lam``, ``tangent`` and ``h``; :meth:`trimmed` drops them).

    ``y`` ``(P, N)``: scaled unknowns; ``lam`` ``(P,)``; ``omega`` ``(P,)`` base
    frequency (rad/s); ``steps`` ``(P,)`` corrector iterations; ``fold`` ``(P,)``: a fold
    lies between this point and the previous one; ``fold_lam`` ``(P,)`` its location
    (NaN elsewhere); ``tangent`` ``(P, N + 1)``: the unit tangent ``(dy/ds, d lambda/ds)``;
    ``h`` ``(P,)``: the step the continuation would take next; ``result``: why
    continuation ended, a :class:`~gearjax._engine.results.RESULTS` item
    (``reached_end``, ``max_points``, ``step_too_small``, ``nonfinite``, ``closed_loop``,
    or the one ``on_point`` gave); ``n_points``: the points found.
    """

    y: np.ndarray
    lam: np.ndarray
    omega: np.ndarray
    steps: np.ndarray
    fold: np.ndarray
    fold_lam: np.ndarray
    tangent: np.ndarray
    h: np.ndarray
    result: RESULTS
    n_points: int | Array

    def trimmed(self) -> Branch:
        """The points found, as numpy arrays (padding dropped); ``result`` as it is."""
        n = int(self.n_points)
        rows = {f.name: np.asarray(getattr(self, f.name))[:n] for f in dataclasses.fields(self)
                if f.name not in ("result", "n_points")}
        return dataclasses.replace(self, **rows, n_points=n)


def distinct_folds(fold_lams, tol: float = 1e-3) -> np.ndarray:
    """Fold locations with zig-zags merged: folds closer than ``tol`` form a cluster; an
    odd cluster is one fold (at its median), an even one cancels (the discrete AFT of
    a non-smooth force can make the tangent flip back and forth right at a fold)."""
    lams = np.sort(np.asarray(fold_lams, float)[np.isfinite(fold_lams)])
    out, group = [], []
    for lam in lams:
        if group and lam - group[-1] > tol:
            if len(group) % 2:
                out.append(float(np.median(group)))
            group = []
        group.append(lam)
    if group and len(group) % 2:
        out.append(float(np.median(group)))
    return np.array(out)


def _row(state: ArcState) -> dict:
    """What :class:`Branch` keeps of a point (one row of each of its arrays)."""
    return {"y": state.y, "lam": state.lam, "steps": state.steps, "fold": state.fold,
            "fold_lam": state.fold_lam, "tangent": jnp.append(state.ty, state.tlam),
            "h": state.h}


def continue_compiled(param: AbstractParameter, y0, lam0, lam_end, settings: Settings,
                      max_points: int = 500) -> Branch:
    """The whole continuation as one compiled ``lax.while_loop`` (fixed buffers).

    **Returns:** a :class:`Branch` of ``max_points`` rows, the first ``n_points`` the
    points found (:meth:`Branch.trimmed`). Suited to small systems (the clearance
    oscillator benchmark), where per-step Python overhead would dominate. Compiled
    (``settings`` and ``max_points`` static); called outside a trace, its program is kept
    between processes (:mod:`~gearjax._engine.kept`).
    """
    direction = jnp.sign(lam_end - lam0)
    state = start(param, y0, lam0, direction, settings)
    first = _row(state)
    rows = {k: jnp.full((max_points,) + jnp.shape(v), 0 if k in ("y", "steps", "fold")
                        else jnp.nan, jnp.result_type(v)).at[0].set(v)
            for k, v in first.items()}

    def cond(c):
        return ~c[-1][0]

    def body(c):
        st, rows, n, _ = c
        new = arclength_step(param, st, settings)
        rows = {k: jnp.where(new.accepted, rows[k].at[n].set(v), rows[k])
                for k, v in _row(new).items()}
        n = n + new.accepted.astype(n.dtype)
        past = (new.lam - lam_end) * direction >= 0
        nonfinite = ~jnp.all(jnp.isfinite(new.y))
        reached = new.accepted & past
        full = n >= max_points
        small = new.h < settings.min_step
        result = RESULTS.where(
            nonfinite, RESULTS.nonfinite,
            RESULTS.where(reached, RESULTS.reached_end,
                          RESULTS.where(full, RESULTS.max_points, RESULTS.step_too_small)))
        return new, rows, n, (nonfinite | reached | full | small, result)

    init = (state, rows, jnp.asarray(1), (jnp.asarray(False), RESULTS.successful))
    _, rows, n, (_, result) = jax.lax.while_loop(cond, body, init)
    omega = jax.vmap(param.omega)(rows["lam"])
    return Branch(**rows, omega=omega, result=result, n_points=n)


def continue_branch(param: AbstractParameter, y0, lam0, lam_end, settings: Settings,
                    max_points: int = 2000, on_point: Callable | None = None,
                    state: ArcState | None = None) -> Branch:
    """Continuation driven from Python: one jitted step per call, ``on_point(i, state)``
    after each accepted point (progress, journaling; a ``RESULTS`` item it returns stops
    the branch there with that result). Keeps every point reached when it has to stop,
    with the reason. ``state`` resumes from a saved state.

    Stops with ``closed_loop`` when the branch comes back onto a stretch it has already
    traced, in the same direction (:func:`revisits`): with exact backlash the sampled
    residual is only piecewise smooth, and at a non-smooth junction of solution curves
    the continuation can enter a loop that it would otherwise circle until
    ``max_points``.
    """
    step = _arclength_step_jit
    direction = float(np.sign(lam_end - lam0))
    if state is None:
        state = start_jit(param, y0, lam0, direction, settings)
    host_row = lambda s: {k: np.asarray(v) for k, v in _row(s).items()}  # noqa: E731
    # the first point counts no corrector steps and no fold (a resumed state's are those
    # of the point it was saved at)
    rows = [{**host_row(state), "steps": np.asarray(0), "fold": np.asarray(False),
             "fold_lam": np.asarray(np.nan)}]
    trace = Trace(max_points, rows[0]["tangent"].size)
    trace.add(np.append(rows[0]["y"], rows[0]["lam"]), rows[0]["tangent"])
    if on_point is not None:
        on_point(0, state)
    stop = RESULTS.max_points
    while len(rows) < max_points:
        state = step(param, state, settings)
        if not bool(jnp.all(jnp.isfinite(state.y))):
            stop = RESULTS.nonfinite
            break
        if bool(state.accepted):
            rows.append(host_row(state))
            asked = on_point(len(rows) - 1, state) if on_point is not None else None
            if (float(state.lam) - lam_end) * direction >= 0:
                stop = RESULTS.reached_end
                break
            if asked is not None:
                stop = asked
                break
            z = np.append(rows[-1]["y"], rows[-1]["lam"])
            if trace.revisits(z, rows[-1]["tangent"]):
                stop = RESULTS.closed_loop
                break
            trace.add(z, rows[-1]["tangent"])
        elif float(state.h) < settings.min_step:
            stop = RESULTS.step_too_small
            break
    arrays = {k: np.stack([r[k] for r in rows]) for k in rows[0]}
    omegas = np.array([float(param.omega(lam)) for lam in arrays["lam"]])
    return Branch(**arrays, omega=omegas, result=stop, n_points=len(rows))


class Trace:
    """Accepted points ``z = (y, lambda)`` of a branch with their unit tangents and
    arclength, for :meth:`revisits` (preallocated; ``capacity`` points of size ``size``)."""

    def __init__(self, capacity: int, size: int):
        self.z = np.empty((capacity, size))
        self.t = np.empty((capacity, size))
        self.s = np.zeros(capacity)  # arclength (sum of chords) from the first point
        self.gap = np.zeros(capacity)  # chord to the neighbouring points, the larger
        self.n = 0

    def add(self, z, t) -> None:
        if self.n:
            chord = float(np.linalg.norm(z - self.z[self.n - 1]))
            self.gap[self.n - 1] = max(self.gap[self.n - 1], chord)
            self.gap[self.n] = chord
            self.s[self.n] = self.s[self.n - 1] + chord
        self.z[self.n], self.t[self.n] = z, t
        self.n += 1

    def revisits(self, z, t) -> bool:
        """``z`` lies on an earlier stretch of the branch: closer to an earlier point than
        0.6 of the chords there, with the tangent pointing the same way (cosine > 0.99),
        after a path at least 20 such chords long (a loop, not the neighbourhood of a
        fold, where the branch turns back close to itself)."""
        n = self.n
        if n < 2:
            return False
        s_now = self.s[n - 1] + float(np.linalg.norm(z - self.z[n - 1]))
        d = np.sqrt(np.sum((self.z[:n] - z) ** 2, axis=1))
        near = (d < 0.6 * self.gap[:n]) & (s_now - self.s[:n] > 20 * self.gap[:n]) & (
            self.t[:n] @ t > 0.99)
        return bool(np.any(near))


continue_compiled = kept_program(continue_compiled, static_argnums=(4, 5))
_arclength_step_jit = kept_program(arclength_step)
start_jit = kept_program(start)
