"""Where the branches a sweep adds after its walk start
(:mod:`~gearjax._studies.sweep.completion`, whose module docstring lists the kinds in
order): the first point of each restarted branch, the band's far end, the jumps where a
stable stretch ends (found side by side in threads), and the end states of integration
sweeps."""

from __future__ import annotations

import dataclasses
import functools
import math

import jax.numpy as jnp
import numpy as np

from ..._engine import aft as _aft
from ..._engine import time_domain as _time_domain
from ..._engine.results import RESULTS
from .. import concurrency
from . import starts as _starts
from . import walk as _walk

JUMP_MULTIPLIER = 1.2
"""A jump lands where the branch beyond the end of a stable stretch has a Floquet
multiplier of at least this modulus (a start there leaves the unstable orbit within the
integrated periods: ``1.2 ** 40`` is about 1500)."""

SEED_TIME = _time_domain.TimeDomain(rtol=_starts.SETTLE_RTOL, atol=_starts.SETTLE_RTOL,
                                    periodic_tol=100 * _starts.SETTLE_RTOL,
                                    max_periods=_starts.SETTLE_PERIODS, n_samples=64)
"""Settings of the integration sweeps of ``seeds`` (as :func:`starts.settled_start`'s)."""


@dataclasses.dataclass
class Seed:
    """A converged periodic solution ``y`` (scaled, ``K`` harmonics) at ``lam``, and how
    it was ``found`` (:mod:`~gearjax._studies.sweep.completion`) at ``f_hz``;
    ``back_only``: the first point of a walked branch (a restart), traced only back
    towards the band's start, without the check that its orbit is new; ``eta``: the
    period in base periods (``K`` harmonics of ``Omega / eta``); ``record``: fields the
    branch's record adds (a doubled branch's origin)."""

    K: int
    y: np.ndarray
    lam: float
    found: str
    f_hz: float
    back_only: bool = False
    eta: int = 1
    record: dict = dataclasses.field(default_factory=dict)


def restart_seeds(ctx, pieces) -> list[Seed]:
    """The first point of each walked branch after a restart, to be traced back towards
    the band's start (the walk began it there, past where the branch before was left:
    the branch goes on below it)."""
    out, seen = [], set()
    for p in pieces:
        if p.branch > 0 and p.branch not in seen and p.pts:
            seen.add(p.branch)
            q = p.pts[0]
            out.append(Seed(K=p.K, y=np.asarray(q["y"]), lam=float(q["lam"]),
                            found="back from restart", f_hz=float(q["lam"]) * ctx.from_hz,
                            back_only=True))
    return out


def segment_at(plan, f_hz) -> int | None:
    """Index of the plan segment holding ``f_hz`` (None outside the band)."""
    for i, (f_a, f_b, _) in enumerate(plan):
        if min(f_a, f_b) <= f_hz <= max(f_a, f_b):
            return i
    return None


def far_end_seed(ctx, plan) -> Seed | None:
    """The start at the band's far end (Newton from the linear guess, else the
    integration start of :func:`~gearjax._studies.sweep.starts.start_point`)."""
    K = plan[-1][2]
    problem = ctx.problem(K)
    y, code = _starts.start_point(problem, ctx.omega(ctx.to_hz))
    if not bool(code == RESULTS.successful):
        return None
    return Seed(K=K, y=np.asarray(y), lam=ctx.lam(ctx.to_hz), found="far end",
                f_hz=float(ctx.to_hz))


SEED_THREAD = "gearjax-seed"
"""Name of the threads that find the completion's seeds side by side."""


def seeds_in_threads(jobs) -> list:
    """Each of ``jobs`` (callables returning a :class:`Seed` or None) called, side by side
    in up to :func:`gearjax._studies.concurrency.threads` threads; results in the order
    of ``jobs`` (each job is independent of the others: the same seeds as one after
    the other)."""
    return concurrency.map_in_threads(lambda job: job(), jobs, SEED_THREAD)


def jump_seeds(ctx, plan, pieces) -> list[Seed]:
    """Where each stable stretch of the branches of ``pieces`` ends, the orbit a rig
    sweeping on settles to (:mod:`~gearjax._studies.sweep.completion`), in frequency order
    along each branch (:func:`jump_jobs`, found side by side)."""
    return [s for s in seeds_in_threads(jump_jobs(ctx, plan, pieces)) if s is not None]


def jump_jobs(ctx, plan, pieces) -> list:
    """The jumps of :func:`jump_seeds` as callables, each returning its :class:`Seed` or
    None."""
    out = []
    by_branch: dict[int, list] = {}  # branch number -> its pieces
    for p in pieces:
        by_branch.setdefault(p.branch, []).append(p)
    for parts in by_branch.values():
        lam = np.concatenate([_ordered(p, [q["lam"] for q in p.pts]) for p in parts])
        stable = np.concatenate([_ordered(p, p.rows["stable"]) for p in parts]) == 1
        mult = np.concatenate([_ordered(p, p.rows["max_multiplier"]) for p in parts])
        X = [x for p in parts for x in _ordered(p, p.rows["X"])]
        Ks = [p.K for p in parts for _ in p.pts]
        # a point past the runaway bound is no stable state a rig settles to
        stable &= ~np.array([_walk.exceeds(ctx.system, x, ctx.runaway) for x in X], dtype=bool)
        for i in range(len(lam) - 1):
            for last, step in ((i, 1), (i + 1, -1)):
                nxt = last + step
                if not (stable[last] and not stable[nxt]):
                    continue
                out.append(functools.partial(_jump, ctx, plan, lam, mult, X, last, step,
                                             parts[0].eta, Ks[last]))
    return out


def _ordered(piece, values):
    values = list(values) if isinstance(values, list) else np.asarray(values)
    return values[::-1] if piece.reverse else values


def _jump(ctx, plan, lam, mult, X, last, step, eta, K_last=None) -> Seed | None:
    """The jump from point ``last`` (stable) of a branch whose next point, going by
    ``step`` (+1/-1 along it), is not stable: the landing frequency is the first point
    beyond with a multiplier of at least :data:`JUMP_MULTIPLIER` while the frequency
    moves on the same way, or a largest step beyond where it turns (a fold). ``eta``:
    the period of the branch's solutions ``X`` (the landing orbit is one of ``ctx``'s)."""
    f = np.asarray(lam) * ctx.from_hz
    max_step = _walk.largest_step_hz(ctx.max_step_hz, ctx.to_hz - ctx.from_hz)
    k = last + step
    if not 0 <= k < len(f):
        return None
    d = math.copysign(1.0, f[k] - f[last]) if f[k] != f[last] else 0.0
    if d == 0.0:
        return None
    land = None
    while 0 <= k < len(f) and (f[k] - f[k - step]) * d > 0:
        if mult[k] >= JUMP_MULTIPLIER:
            land = f[k]
            break
        k += step
    if land is None:
        far = f[k - step]  # where the branch turns, or its end
        land = far + d * max_step
    s = segment_at(plan, land)
    if s is None:
        return None
    K = plan[s][2]
    problem = ctx.problem(K)
    omega = ctx.omega(land)
    # a torus solution's state needs its basis (eta = 1 there); a periodic one's does not
    basis = ctx.problem(K_last).basis if ctx.system.n_angles > 1 else None
    state = _time_domain.hb_initial_state(jnp.asarray(X[last]), ctx.omega(f[last]), eta, basis)
    sol = _starts.settled_start(problem, omega, state)
    if not bool(sol.converged):
        return None
    return Seed(K=K, y=np.asarray(sol.y), lam=ctx.lam(land),
                found="jump up" if d > 0 else "jump down", f_hz=float(land))


def integration_seeds(ctx, plan, n: int) -> list[Seed]:
    """The end states of an up and a down integration sweep over ``n`` even frequencies
    of the band (:data:`SEED_TIME`), each converged by Newton with its segment's K; up
    first, then down, each in its sweep's order."""
    lo, hi = sorted((ctx.from_hz, ctx.to_hz))
    freqs = np.linspace(lo, hi, n)
    out = []
    for word, order in (("up", freqs), ("down", freqs[::-1])):
        tr = _time_domain.simulate_sweep(ctx.system, jnp.asarray([ctx.omega(f) for f in order]),
                                         settings=SEED_TIME)
        ok = np.asarray(tr.integrated)
        for k, f in enumerate(order):
            if not ok[k]:
                continue
            K = plan[segment_at(plan, f)][2]
            problem = ctx.problem(K)
            X = _aft.analysis(tr.x[k].T, K)
            y = (X / problem.x_scale).reshape(-1)
            if not bool(jnp.all(jnp.isfinite(y))):
                continue
            sol = _starts.newton(problem, jnp.asarray(ctx.omega(f)), y)
            if bool(sol.converged):
                out.append(Seed(K=K, y=np.asarray(sol.y), lam=ctx.lam(f),
                                found=f"integration {word}", f_hz=float(f)))
    return out
