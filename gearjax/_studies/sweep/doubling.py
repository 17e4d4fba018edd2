"""Branch switching at a period doubling: the start of the branch of period ``2 T`` that
is born where a Floquet multiplier of a traced branch passes through -1.

**Where.** Between two neighbouring points of a branch whose multipliers say
``period_doubling`` (:func:`gearjax._engine.verdict.bifurcation_kind`), the doubling is
taken where the largest multiplier modulus, linear between the two, is 1; the
period-``T`` solution there is Newton's from the chord of the two points
(:func:`locate`).

**The doubled problem.** A solution of period ``T = 2 pi eta / Omega`` with ``K``
harmonics of ``Omega / eta`` is one of period ``2 T`` with ``2 K`` harmonics of
``Omega / (2 eta)``: its harmonic ``k`` is harmonic ``2 k`` there, and its odd harmonics
are zero (:func:`doubled`). On that basis the period-``T`` branch goes on as a branch of
the doubled problem, and the period-``2 T`` branch crosses it at the doubling: a
pitchfork, whose two halves are one orbit half a period apart (:func:`mirror`: the odd
harmonics change sign).

**The critical direction.** The Floquet mode of the multiplier -1 is antiperiodic over
``T``: it lives on the odd harmonics of the doubled basis, and there it is the null
vector of the doubled problem's Jacobian (Hill's method: a Floquet exponent
``i Omega / (2 eta)`` is a zero eigenvalue of the harmonic-balance Jacobian on those
harmonics). :func:`critical_mode` takes it as the right singular vector of the smallest
singular value of the Jacobian's odd-harmonic block (the even and odd harmonics do not
couple on a period-``T`` solution, whose excitation and orbit hold even ones only).

**The switch** (:func:`switch`). The period-``2 T`` branch is entered at
:data:`SWITCH_AMPLITUDE` along that mode: the corrector of the continuation
(:func:`gearjax._engine.corrector.correct`) on ``[R(y, lambda) = 0; phi . (y - y_T) =
SWITCH_AMPLITUDE]``, with the frequency free, which no solution of period ``T`` (whose
odd harmonics are zero) satisfies. From there the continuation goes on along the mode,
away from the doubling, until the frequency is :data:`LEAD_SHARE` of a largest
continuation step from the doubling's: where the new branch leaves the doubling at
right angles to the frequency axis (a doubling in a linear stretch of the period-``T``
branch: the teeth in contact, the period-``2 T`` motion grows at one frequency until
they separate), only a point off that vertical stretch has a direction along the band.
That point is the seed that :mod:`~gearjax._studies.sweep.completion` traces both ways
along the band; the way back reaches the doubling, where the odd harmonics change sign
or vanish (:func:`back_on_parent`: the branch is back on the period-``T`` orbit) and it
stops.

**In the completion.** :func:`doubling_points` locates the doublings of traced branches
(those it does not follow are noted in their branch's record), :func:`start` turns one
into a seed unless a doubled branch traced before came back onto the orbit there (it
is that branch's doubling), and :class:`Periods` holds the sweep context of each period.
Everything here is a deterministic function of the traced points, so a resumed sweep
finds the same seeds; the branches' points are journaled as the completion's others.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

from ..._engine import continuation as _continuation
from ..._engine import corrector as _corrector
from ..._engine import hb as _hb
from ..._engine.results import RESULTS
from ..._engine.verdict import bifurcation_kind
from .. import harmonics as _harmonics
from . import starts as _starts
from . import walk as _walk

MAX_ETA = 4
"""Longest period followed, in base periods: each doubling doubles the harmonics (a
period-4 branch solves 4 K harmonics), so a cascade is followed for two doublings; a
doubling on a branch of this period is reported, not followed."""

SWITCH_AMPLITUDE = 1e-2
"""Odd-harmonic amplitude (scaled unknowns: characteristic lengths, the continuation's
units) at which the period-``2 T`` branch is entered: small against the orbit, large
against Newton's tolerance."""

LEAD_SHARE = 0.5
"""The seed of a doubled branch lies this share of a largest continuation step (in the
frequency) from the doubling."""

LEAD_POINTS = 100
"""Most continuation points from the switch to the seed; a branch still at the
doubling's frequency after them (it grows without bound there: no backlash bounds it)
is not followed."""

PARENT_SHARE = 1e-6
"""A point of a doubled branch whose odd harmonics are below this share of its norm is
on the period-``T`` orbit (:func:`back_on_parent`)."""


@dataclasses.dataclass
class Doubling:
    """A located period doubling on ``branch`` (of period ``eta`` base periods): the
    period-``T`` solution ``y`` (scaled, ``K`` harmonics) at ``lam``, between the points
    at ``lam_a`` (the stable side where one is) and ``lam_b``; ``f_hz``: its frequency,
    ``mid_hz``: the midpoint of the two points (as the dataset's ``bifurcations`` list
    it)."""

    branch: int
    eta: int
    K: int
    y: np.ndarray
    lam: float
    lam_a: float
    lam_b: float
    f_hz: float
    mid_hz: float


def doublings(parts) -> list[tuple]:
    """The period doublings along one branch: ``((piece_a, i_a), (piece_b, i_b), t)`` per
    pair of neighbouring points (in the branch's shown order, over its ``parts``,
    :class:`~gearjax._studies.sweep.completion.Piece` with rows) whose multipliers say
    ``period_doubling`` where the stability changes (the pairs that
    :func:`~gearjax._studies.sweep.post.bifurcations` lists), ``t`` the share of the way
    from the first where the largest multiplier modulus (linear between them) is 1."""
    out = []
    rows = [(p, k) for p in parts for k in (range(len(p.pts))[::-1] if p.reverse
                                            else range(len(p.pts)))]
    for (pa, a), (pb, b) in zip(rows[:-1], rows[1:]):
        ra, rb = pa.rows, pb.rows
        if bool(ra["stable"][a]) == bool(rb["stable"][b]):
            continue  # as post.bifurcations: where the stability changes
        kind = bifurcation_kind(ra["multipliers"][a][~ra["excluded"][a]],
                                rb["multipliers"][b][~rb["excluded"][b]])
        if kind != "period_doubling":
            continue
        ma, mb = float(ra["max_multiplier"][a]), float(rb["max_multiplier"][b])
        t = 0.5 if ma == mb else min(max((1.0 - ma) / (mb - ma), 0.0), 1.0)
        out.append(((pa, a), (pb, b), t))
    return out


def locate(ctx, branch: int, eta: int, pair) -> Doubling | None:
    """The :class:`Doubling` of one pair of :func:`doublings` (``ctx``: the sweep context
    of period ``eta``), the period-``T`` solution there by Newton from the chord of the
    two points (with the first point's K); ``None`` where Newton fails."""
    (pa, a), (pb, b), t = pair
    problem = ctx.problem(pa.K)
    ya = np.asarray(pa.pts[a]["y"])
    yb = np.asarray(_starts.resize_harmonics(pb.pts[b]["y"], pb.K, problem))
    lam_a, lam_b = float(pa.pts[a]["lam"]), float(pb.pts[b]["lam"])
    lam = (1 - t) * lam_a + t * lam_b
    sol = _starts.newton(problem, jnp.asarray(lam * ctx.omega_ref),
                         jnp.asarray((1 - t) * ya + t * yb))
    if not bool(sol.converged):
        return None
    return Doubling(branch=branch, eta=eta, K=pa.K, y=np.asarray(sol.y), lam=lam,
                    lam_a=lam_a, lam_b=lam_b, f_hz=lam * ctx.from_hz,
                    mid_hz=0.5 * (lam_a + lam_b) * ctx.from_hz)


def doubled(y, K: int, n: int) -> np.ndarray:
    """Scaled unknowns ``(2K+1) n`` (flat) of a period-``T`` solution on the doubled basis
    (``4K+1`` coefficient rows): harmonic ``k`` to ``2 k``, odd harmonics zero."""
    Y = np.asarray(y).reshape(2 * K + 1, n)
    out = np.zeros((4 * K + 1, n))
    out[0] = Y[0]
    out[3::4] = Y[1::2]  # cos k -> cos 2k: row 2(2k) - 1
    out[4::4] = Y[2::2]  # sin k -> sin 2k: row 2(2k)
    return out.reshape(-1)


def odd_rows(K: int) -> np.ndarray:
    """Which of the ``2K+1`` coefficient rows belong to odd harmonics."""
    k = (np.arange(2 * K + 1) + 1) // 2
    return k % 2 == 1


def odd_part(y, K: int, n: int) -> np.ndarray:
    """The odd-harmonic coefficients of the flat scaled unknowns ``y`` (``K`` harmonics of
    ``n`` coordinates), flat."""
    return np.asarray(y).reshape(2 * K + 1, n)[odd_rows(K)].reshape(-1)


def mirror(y, K: int, n: int) -> np.ndarray:
    """The same orbit half its period later: the odd harmonics of ``y`` negated."""
    Y = np.array(np.asarray(y).reshape(2 * K + 1, n))
    Y[odd_rows(K)] *= -1
    return Y.reshape(-1)


def back_on_parent(y, y_before, K: int, n: int) -> bool:
    """Whether a doubled branch, going from ``y_before`` to ``y`` (flat scaled unknowns,
    ``K`` harmonics), came back onto the period-``T`` orbit it was born on: the odd
    harmonics changed sign (it passed a doubling onto its mirror half) or vanished
    (below :data:`PARENT_SHARE` of ``y``)."""
    odd, before = odd_part(y, K, n), odd_part(y_before, K, n)
    return bool(odd @ before <= 0.0 or np.linalg.norm(odd) <= PARENT_SHARE * max(
        float(np.linalg.norm(y)), 1e-300))


@jax.jit
def _jacobian(problem, y, omega):
    return _hb.jacobian(problem, y, omega)


def critical_mode(problem, y, omega) -> np.ndarray:
    """The unit critical direction ``phi`` (flat, zero on the even harmonics) of the
    doubled ``problem`` at its period-``T`` solution ``y`` (scaled) and ``omega`` (rad/s):
    module docstring. Signed so that its largest entry is positive."""
    K, n = problem.settings.n_harmonics, problem.shape[1]
    odd = np.repeat(odd_rows(K), n)
    J = np.asarray(_jacobian(problem, jnp.asarray(y), jnp.asarray(omega)))[np.ix_(odd, odd)]
    v = np.linalg.svd(J)[2][-1]
    v = v * math.copysign(1.0, v[np.argmax(np.abs(v))])
    phi = np.zeros(odd.size)
    phi[odd] = v / np.linalg.norm(v)
    return phi


@functools.partial(jax.jit, static_argnames=("rtol", "max_corrector"))
def _switch(param, y_p, lam_p, phi, rtol, max_corrector):
    factors = param.factor(y_p, lam_p, phi, jnp.asarray(0.0), False)
    return _corrector.correct(param, factors, phi, jnp.asarray(0.0), y_p, lam_p, rtol,
                              max_corrector)


@functools.partial(jax.jit, static_argnames="single")
def _away(param, y, lam, phi, h, single):
    """The continuation state at ``(y, lam)`` with its tangent along ``phi``."""
    ty, tlam, factors = _continuation.tangent_factors(
        param, y, lam, phi, jnp.asarray(0.0), single, fallback=jnp.append(phi, 0.0))
    return _continuation.ArcState(
        y=y, lam=lam, ty=ty, tlam=tlam, h=h, accepted=jnp.asarray(True),
        fold=jnp.asarray(False), fold_lam=jnp.asarray(jnp.nan, float), steps=jnp.asarray(0),
        factors=factors, age=jnp.asarray(0), own=jnp.asarray(False))


def switch(ctx2, d: Doubling):
    """The seed of the period-``2 T`` branch born at ``d`` (module docstring), on the
    doubled problem of ``ctx2`` (the sweep context of period ``2 eta``) with ``2 K``
    harmonics: ``(y, lambda)`` (scaled unknowns), or ``None`` with why (a word) where the
    switch does not converge or the branch does not leave the doubling's frequency."""
    K2 = 2 * d.K
    problem = ctx2.problem(K2)
    n = problem.shape[1]
    y2 = jnp.asarray(doubled(d.y, d.K, n))
    lam = jnp.asarray(d.lam, float)
    phi = jnp.asarray(critical_mode(problem, y2, d.lam * ctx2.omega_ref))
    param = _continuation.FrequencyParameter(problem=problem,
                                             omega_ref=jnp.asarray(ctx2.omega_ref))
    settings = _walk.continuation_settings(ctx2.max_step_hz, ctx2.to_hz - ctx2.from_hz,
                                           ctx2.from_hz)
    y, lam_s, _, converged = _switch(param, y2 + SWITCH_AMPLITUDE * phi, lam, phi,
                                     settings.rtol, settings.max_corrector)
    if not bool(converged) or float(odd_part(y, K2, n) @ odd_part(phi, K2, n)) <= 0.0:
        return None, "switch did not converge"
    lead = LEAD_SHARE * settings.max_dlambda
    lam_lo, lam_hi = sorted((ctx2.lam(ctx2.from_hz), ctx2.lam(ctx2.to_hz)))
    reached = {"ok": False}

    def on_point(i, state):
        if i == 0:
            return None
        y_now, lam_now = np.asarray(state.y), float(state.lam)
        if not lam_lo <= lam_now <= lam_hi or _walk.ran_away(problem, y_now, ctx2.runaway) \
                or float(odd_part(y_now, K2, n) @ odd_part(phi, K2, n)) <= 0.0:
            return RESULTS.runaway
        if abs(lam_now - d.lam) >= lead:
            reached["ok"] = True
            return RESULTS.reached_end
        return None

    state = _away(param, y, lam_s, phi, jnp.asarray(settings.step, float), settings.single)
    branch = _continuation.continue_branch(param, y, float(lam_s), math.inf, settings,
                                           max_points=LEAD_POINTS, on_point=on_point,
                                           state=state)
    if not reached["ok"]:
        return None, f"no period-{2 * d.eta} branch left the doubling ({branch.result})"
    return (np.asarray(branch.y[-1]), float(branch.lam[-1])), None


# ------------------------------------------------------------------ in the completion


class Periods:
    """The sweep contexts (:class:`~gearjax._studies.sweep.context.Context`) per period
    ``eta``: ``ctx`` for its own, a copy with ``eta`` (and its own problems) for each
    other."""

    def __init__(self, ctx):
        self.ctx = ctx
        self._by = {ctx.eta: ctx}

    def __call__(self, eta: int):
        if eta not in self._by:
            self._by[eta] = dataclasses.replace(self.ctx, eta=eta, problems={})
        return self._by[eta]

    def plan(self, plan, eta: int) -> list:
        """The band's segments ``(f_a, f_b, K)`` of ``ctx`` with the harmonics of period
        ``eta``: ``K eta / ctx.eta`` (the same harmonics of the base frequency); the plan
        itself for ``eta = ctx.eta`` (a torus plan, orders per angle, has no other)."""
        if eta == self.ctx.eta:
            return list(plan)
        return [(a, b, K * eta // self.ctx.eta) for a, b, K in plan]


def record_of(records: list, branch: int) -> dict:
    """The record of branch number ``branch``."""
    return next(r for r in records if r["branch"] == branch)


def doubling_points(periods: Periods, pieces, records: list) -> list[Doubling]:
    """The located period doublings along the branches of ``pieces``
    (:class:`~gearjax._studies.sweep.completion.Piece` with rows) whose doubled period is
    at most :data:`MAX_ETA` and whose doubled problem is affordable
    (:func:`gearjax._studies.harmonics.check_affordable`: a problem of twice the
    harmonics); the others are listed in their branch's record (``records``) as
    ``not_doubled``: ``{"doubling_hz", "why"}``."""
    ctx = periods.ctx
    out = []
    by_branch: dict[int, list] = {}
    for p in pieces:
        by_branch.setdefault(p.branch, []).append(p)
    for branch, parts in by_branch.items():
        eta = parts[0].eta
        for pair in doublings(parts):
            (pa, a), (pb, b), _ = pair
            mid = 0.5 * (pa.pts[a]["lam"] + pb.pts[b]["lam"]) * ctx.from_hz
            why = (f"the period-{2 * eta} branch is not followed (at most {MAX_ETA} base "
                   "periods)" if 2 * eta > MAX_ETA
                   else _harmonics.check_affordable(ctx.system, pa.K))
            d = None
            if why is None:
                d = locate(periods(eta), branch, eta, pair)
                why = None if d is not None else (
                    f"no period-{eta} solution converged at the doubling")
            if d is not None:
                out.append(d)
            else:
                record_of(records, branch).setdefault("not_doubled", []).append(
                    {"doubling_hz": float(mid), "why": why})
    return out


def start(periods: Periods, atlas, records: list, d: Doubling) -> dict | None:
    """The seed of the branch born at the doubling ``d`` (:func:`switch`), as the fields
    ``K``, ``y``, ``lam``, ``f_hz``, ``eta`` and ``record`` of a
    :class:`~gearjax._studies.sweep.seeds.Seed`; ``None`` where a doubled branch
    traced before came back there (``atlas.returned``; that branch's record's
    ``doublings_hz`` then lists ``d``) or the switch finds none (the record of ``d``'s
    branch lists it under ``not_doubled``, with why)."""
    ctx = periods.ctx
    ctx2 = periods(2 * d.eta)
    K2 = 2 * d.K
    problem = ctx2.problem(K2)
    y2 = doubled(d.y, d.K, problem.shape[1])
    dlam = _walk.continuation_settings(ctx.max_step_hz, ctx.to_hz - ctx.from_hz,
                                       ctx.from_hz).max_dlambda
    there = atlas.returned(problem, y2, d.lam, dlam)
    if there is not None:
        record_of(records, there).setdefault("doublings_hz", []).append(float(d.mid_hz))
        return None
    found, why = switch(ctx2, d)
    if found is None:
        record_of(records, d.branch).setdefault("not_doubled", []).append(
            {"doubling_hz": float(d.mid_hz), "why": why})
        return None
    y, lam = found
    return {"K": K2, "y": y, "lam": lam, "f_hz": lam * ctx.from_hz, "eta": 2 * d.eta,
            "record": {"from_branch": int(d.branch), "doubling_hz": float(d.f_hz),
                       "doublings_hz": [float(d.mid_hz)]}}
