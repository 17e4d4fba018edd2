"""The branches a non-linear sweep adds to the one it walked, so that it reports every
stable periodic state a test rig sweeping up or down would settle to.

**Seeds.** After the walk (:mod:`~gearjax._studies.sweep.walk`) the sweep looks for
converged periodic solutions off the branches it traced, in this order:

- ``far end``: the start at the other end of the band (Newton from the linear guess,
  :func:`~gearjax._studies.sweep.starts.start_point`), as a sweep from there would begin;
- ``jump up`` / ``jump down``: wherever a stable stretch of a traced branch ends (a
  fold, or a stability change), the orbit a rig sweeping on in that direction settles
  to: a time integration (:func:`~gearjax._studies.sweep.starts.settled_start`) from the
  last stable state, at the first frequency beyond where the branch there is clearly
  unstable (largest multiplier at least
  :data:`~gearjax._studies.sweep.seeds.JUMP_MULTIPLIER`, or past its fold), then Newton
  (:mod:`~gearjax._studies.sweep.seeds`: these jumps and the far end found side by
  side);
- ``period doubling``: wherever a Floquet multiplier of a traced branch passes through
  -1, the branch of twice the period born there (``eta`` doubled: K doubled too), entered
  along the critical Floquet mode (:mod:`~gearjax._studies.sweep.doubling`); the branches
  of a doubled branch's doublings too, up to ``doubling.MAX_ETA`` base periods. Its way
  back to the doubling stops where it is back on the orbit it was born on
  (:data:`PARENT_STOP`); a doubling where a doubled branch traced before came back is
  that branch's (its record's ``doublings_hz``);
- ``integration up`` / ``integration down`` (``seeds`` > 0 only): the end states of an up
  and a down time-integration sweep over an even grid of ``seeds`` frequencies
  (:func:`gearjax._engine.time_domain.simulate_sweep`, each point continued from the
  one before), each one Newton's guess.

**Known orbits.** A seed is on a traced branch where Newton from that branch's chord at
the seed's frequency (interpolated between the two points that bracket it, where it
lies within :data:`NEAR` of the seed) converges to the seed within :data:`SAME_ORBIT`.
A new seed is continued both ways, up to the band's ends (across the segments of the
band, each with its K), until it reaches one, closes on itself (an isola, one way
only), meets a branch traced before (a point within 0.6 of the local chord of one of
its points: the orbit is already traced), detours, runs away or cannot go on
(:mod:`~gearjax._studies.sweep.walk`); an isola whose way up detours before it comes
round (longer than ``max_detour`` points) closes where its way down meets its way up.
The new branch's stable stretches are seeds in turn, until no seed is new or
:data:`MAX_BRANCHES` are traced.

Orbits of another period are another problem: the known orbits and the meeting check
are per K and ``eta`` (:class:`Atlas`), so a doubled branch is never taken for the
period-one branch it crosses at its doubling, nor the reverse.

Every branch carries its number and how it was found (:func:`branch_records`):
``sweep`` (the walk's first), ``restart`` (the walk's restarts), or the seed's kind
above with the frequency it was found at, and its period ``eta``; a doubled branch's
record adds ``from_branch``, ``doubling_hz`` (where its parent's multiplier is -1) and
``doublings_hz`` (the midpoints that ``bifurcations`` lists for the doublings it starts
or ends at); a branch whose doubling was not followed lists it under ``not_doubled``
with why. The journal holds the seeded branches' points
as segments named ``"b{branch}{+|-}{piece}"``; the seeds themselves are found again
(deterministically) when a run is resumed.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

from ..._engine import continuation as _continuation
from ..._engine.results import RESULTS, result_from_word
from . import doubling as _doubling
from . import seeds as _seeds
from . import starts as _starts
from . import walk as _walk

SAME_ORBIT = 1e-5
"""Two converged solutions at one frequency are the same orbit where their scaled
unknowns differ by at most this much relative to the seed's norm (Newton converges to
``1e-9``; distinct orbits differ by far more)."""

NEAR = 0.05
"""A traced branch is checked against a seed (by Newton from its chord) where the chord
lies within this relative distance of the seed's scaled unknowns."""

MAX_BRANCHES = 24
"""Most branches of one sweep (walked and seeded)."""

@dataclasses.dataclass
class Piece:
    """Consecutive points of one branch with one K: ``key`` (journal segment), ``K``,
    ``pts`` (journal point records, in continuation order), ``branch``, ``reverse``
    (shown in reverse order: the part of a seeded branch traced down from its seed),
    ``rows`` (:func:`~gearjax._studies.sweep.post.point_rows` of ``pts``), ``eta``: its
    solutions' period in base periods (2 or more on a branch born at a period doubling,
    :mod:`~gearjax._studies.sweep.doubling`; ``K`` harmonics of ``Omega / eta``)."""

    key: object
    K: int
    pts: list
    branch: int
    reverse: bool = False
    rows: dict | None = None
    eta: int = 1


class Atlas:
    """Every traced point ``(y, lambda)``, per K and period ``eta`` (a period-``2 T``
    solution is one of another problem, even where it lies close to the period-``T``
    branch it was born on), with the larger chord to its neighbours (for :meth:`meets`),
    the pieces themselves (for :meth:`known`), and where doubled branches came back onto
    the orbit they were born on (for :meth:`returned`). The points of a branch with
    ``eta > 1`` are there with their mirror (the orbit half a period later,
    :func:`~gearjax._studies.sweep.doubling.mirror`): one orbit either way."""

    def __init__(self):
        self.pieces: list[Piece] = []
        self._z: dict[tuple, list] = {}
        self._gap: dict[tuple, list] = {}
        self.returns: list[tuple] = []

    def add(self, piece: Piece) -> None:
        if not piece.pts:
            return
        self.pieces.append(piece)
        ys = [np.asarray(p["y"]) for p in piece.pts]
        halves = [ys]
        if piece.eta > 1:  # periodic: K an int
            n = ys[0].size // (2 * piece.K + 1)
            halves.append([_doubling.mirror(y, piece.K, n) for y in ys])
        for half in halves:
            z = np.stack([np.append(y, p["lam"]) for y, p in zip(half, piece.pts)])
            chord = np.linalg.norm(np.diff(z, axis=0), axis=1)
            gap = np.maximum(np.r_[chord, 0.0], np.r_[0.0, chord])
            self._z.setdefault((piece.K, piece.eta), []).append(z)
            self._gap.setdefault((piece.K, piece.eta), []).append(gap)

    def meets(self, K: int, z, chord: float, eta: int = 1) -> bool:
        """Whether ``z`` (scaled unknowns with K harmonics of ``Omega / eta`` and lambda)
        lies on a traced stretch of that problem: within 0.6 of the larger of the chords
        there and ``chord`` (the step that reached ``z``) of a traced point."""
        for Z, gap in zip(self._z.get((K, eta), []), self._gap.get((K, eta), [])):
            d = np.sqrt(np.sum((Z - z) ** 2, axis=1))
            if np.any(d < 0.6 * np.maximum(gap, chord)):
                return True
        return False

    def returned(self, problem, y, lam: float, dlam: float) -> int | None:
        """The doubled branch that came back onto a period-``T`` orbit within ``dlam`` of
        ``lam`` where that orbit (on the doubled basis, ``y`` scaled, the K and ``eta``
        of ``problem``) is within :data:`NEAR` of ``y``: the doubling there is that
        branch's end (``None``: no such branch)."""
        y = np.asarray(y)
        norm = float(np.linalg.norm(y)) or 1.0
        n = problem.shape[1]
        K = problem.settings.n_harmonics
        even = ~np.repeat(_doubling.odd_rows(K), n)
        for K_r, eta, y_r, lam_r, branch in self.returns:
            if eta != problem.settings.eta or abs(lam_r - lam) > dlam:
                continue
            y_r = np.asarray(_starts.resize_harmonics(y_r, K_r, problem))
            if np.linalg.norm(np.where(even, y_r - y, 0.0)) / norm < NEAR:
                return branch
        return None

    def known(self, problem, omega_ref: float, y, lam: float) -> int | None:
        """The branch whose orbit at ``lam`` is the converged ``y`` (scaled, the K and
        ``eta`` of ``problem``; a period-``2 T`` orbit also where its mirror is traced):
        :data:`NEAR` chords checked by Newton (module docstring); ``None`` for a new
        orbit."""
        eta = problem.settings.eta
        if eta > 1:
            n = problem.shape[1]
            mirrored = _doubling.mirror(y, problem.settings.n_harmonics, n)
            for piece in self.pieces:
                if piece.eta == eta:
                    found = self._known_on(piece, problem, omega_ref, mirrored, lam)
                    if found is not None:
                        return found
        for piece in self.pieces:
            if piece.eta == eta:
                found = self._known_on(piece, problem, omega_ref, y, lam)
                if found is not None:
                    return found
        return None

    @staticmethod
    def _known_on(piece, problem, omega_ref: float, y, lam: float) -> int | None:
        """``piece.branch`` where its chord at ``lam`` leads to ``y`` (:meth:`known`)."""
        y = np.asarray(y)
        norm = float(np.linalg.norm(y)) or 1.0
        lams = np.array([p["lam"] for p in piece.pts])
        for i in np.flatnonzero((lams[:-1] - lam) * (lams[1:] - lam) <= 0):
            a, b = piece.pts[i], piece.pts[i + 1]
            w = 0.0 if b["lam"] == a["lam"] else (lam - a["lam"]) / (b["lam"] - a["lam"])
            chord = np.asarray(_starts.resize_harmonics(
                (1 - w) * a["y"] + w * b["y"], piece.K, problem))
            gap = float(np.linalg.norm(chord - y)) / norm
            if gap < SAME_ORBIT:
                return piece.branch
            if gap < NEAR:
                sol = _starts.newton(problem, jnp.asarray(lam * omega_ref),
                                     jnp.asarray(chord))
                if bool(sol.converged) and float(
                        np.linalg.norm(np.asarray(sol.y) - y)) / norm < SAME_ORBIT:
                    return piece.branch
        return None


def complete(ctx, walk, log, post, F_static, *, seeds: int = 0, progress=None):
    """The branches :func:`~gearjax._studies.sweep.sweep` adds after the walk ``walk``
    (module docstring). **Returns:** ``(pieces, records)``: the :class:`Piece` list of
    every branch, walked ones first (their ``rows`` computed), and one record per branch
    (:func:`branch_records`)."""
    plan = _plan(walk)
    periods = _doubling.Periods(ctx)
    atlas = Atlas()
    pieces = walked_pieces(ctx, walk, log, post)
    for piece in pieces:
        atlas.add(piece)
    records = branch_records(ctx, walk, pieces)
    done = {"points": walk.done}
    # the far end and the first jumps (time integrations, then Newton) side by side
    first = _seeds.seeds_in_threads([functools.partial(_seeds.far_end_seed, ctx, plan)]
                                     + _seeds.jump_jobs(ctx, plan, pieces))
    queue = _seeds.restart_seeds(ctx, pieces) + [s for s in first if s is not None]
    queue += _doubling.doubling_points(periods, pieces, records)
    if seeds:
        queue += _seeds.integration_seeds(ctx, plan, seeds)
    while queue and len(records) < MAX_BRANCHES and done["points"] < ctx.max_points:
        seed = queue.pop(0)
        if isinstance(seed, _doubling.Doubling):
            fields = _doubling.start(periods, atlas, records, seed)
            seed = None if fields is None else _seeds.Seed(found="period doubling", **fields)
        if seed is None:
            continue
        sctx = periods(seed.eta)
        problem = sctx.problem(seed.K)
        if not seed.back_only and atlas.known(problem, ctx.omega_ref, seed.y,
                                              seed.lam) is not None:
            continue
        number = 1 + max((r["branch"] for r in records), default=-1)
        new, stops, ends = trace_seed(sctx, periods.plan(plan, seed.eta), log, post, seed,
                                      number, atlas, done, progress)
        for piece in new:
            atlas.add(piece)
        for stop, end in zip(stops, ends):
            if stop == PARENT_STOP and end is not None:
                atlas.returns.append((*end, number))
        pieces += new
        records.append({"branch": number, "found": seed.found, "seed_hz": float(seed.f_hz),
                        "stops": stops, "eta": int(seed.eta), **seed.record})
        queue += (_seeds.jump_seeds(ctx, plan, new)
                  + _doubling.doubling_points(periods, new, records))
    return pieces, records


OWN_SKIP = 3
"""First points of a seeded way up (beside the seed) that its way down is not checked on."""

PARENT_STOP = "period one"
"""Why a way of a doubled branch stopped where it came back onto the orbit of the period
it was born from (:func:`~gearjax._studies.sweep.doubling.back_on_parent`)."""


def walked_pieces(ctx, walk, log, post) -> list[Piece]:
    """The walk's segments as pieces, numbered by branch as
    :func:`~gearjax._studies.sweep.dataset.point_data` numbers them (the point past a
    boundary that the next segment starts on left out), with their rows."""
    out = []
    for j, problem, pts, branch in _walk.walked_stretches(walk, log):
        piece = Piece(key=j, K=problem.settings.n_harmonics, pts=pts, branch=branch,
                      eta=ctx.eta)
        piece.rows = post.rows(j, problem, ctx.omega_ref, piece.pts)
        out.append(piece)
    return out


def branch_records(ctx, walk, pieces) -> list[dict]:
    """One record per walked branch: ``{"branch", "found", "seed_hz", "stops"}``,
    ``found`` ``sweep`` for the first and ``restart`` after a restart, ``seed_hz`` where
    it began."""
    numbers = sorted({p.branch for p in pieces})
    records = []
    for n in numbers:
        if n == 0:
            records.append({"branch": 0, "found": "sweep", "seed_hz": float(ctx.from_hz),
                            "stops": [walk.stop], "eta": int(ctx.eta)})
        else:
            r = walk.restarts[n - 1] if n - 1 < len(walk.restarts) else {}
            records.append({"branch": n, "found": "restart",
                            "seed_hz": float(r.get("at_hz", math.nan)),
                            "stops": [r.get("reason", "")], "eta": int(ctx.eta)})
    for k, r in enumerate(records[:-1]):  # a branch stopped where the next restarted
        nxt = walk.restarts[k] if k < len(walk.restarts) else None
        if nxt is not None:
            r["stops"] = [nxt["reason"]]
    return records


def _plan(walk) -> list[tuple[float, float, int]]:
    """The band's segments ``(f_a, f_b, K)`` in sweep order without the restart splits
    (each restart segment joined back to the one it was cut from)."""
    plan = []
    for f_a, f_b, K in walk.segments:
        if plan and plan[-1][2] == K and plan[-1][1] == f_b:
            continue  # a restart's rest of the segment before
        plan.append((f_a, f_b, K))
    return plan


def trace_seed(ctx, plan, log, post, seed, number, atlas, done, progress):
    """Continue ``seed`` both ways through the band's segments as branch ``number``
    (module docstring; ``ctx`` and ``plan`` those of the seed's period). **Returns:**
    the pieces (journal segments ``"b{number}{+|-}{i}"``) with their rows, the words of
    why each way stopped (``"joined"`` where it met a traced branch, :data:`PARENT_STOP`
    where a doubled branch came back onto the orbit it was born on), and each way's last
    point ``(K, eta, y, lambda)`` (``None`` for a way without points)."""
    s = _seeds.segment_at(plan, seed.f_hz)
    pieces, stops, ends, own = [], [], [], None
    ways = (("+", range(s, len(plan))), ("-", range(s, -1, -1)))
    for sign, order in ways[1:] if seed.back_only else ways:
        forward = sign == "+"
        parts = []
        previous = None
        stop = "reached_end"
        for n, i in enumerate(order):
            f_a, f_b, K = plan[i]
            end = f_b if forward else f_a
            start = seed.f_hz if n == 0 else (f_a if forward else f_b)
            key = f"b{number}{sign}{n}"
            if start == end:  # a seed on a segment's end: the next one starts from it
                previous = (seed.K, seed.y, seed.lam, None)
                continue
            entered = (jnp.asarray(seed.y), RESULTS.successful, seed.lam) if n == 0 else None
            stop, joined = _trace_piece(ctx, log, key, K, previous, start, end, entered,
                                        atlas, done, progress, number, own)
            pts = log.points(key)
            if pts:
                parts.append(Piece(key=key, K=K, pts=pts, branch=number, reverse=not forward,
                                   eta=ctx.eta))
                before = (pts[-2]["y"], pts[-2]["lam"]) if len(pts) > 1 else None
                previous = (K, pts[-1]["y"], pts[-1]["lam"], before)
            if joined:
                stop = joined
                break
            if not stop.startswith("no converged start") and bool(
                    result_from_word(stop) == RESULTS.reached_end):
                continue
            break
        last = parts[-1] if parts else None
        ends.append((last.K, ctx.eta, np.asarray(last.pts[-1]["y"]),
                     float(last.pts[-1]["lam"])) if last is not None and last.pts else None)
        # a piece continued by the next ends past the boundary: the next starts there
        for a, b in zip(parts[:-1], parts[1:]):
            if b.pts:
                a.pts = a.pts[:-1]
        if not forward and parts and (seed.back_only or any(p.pts for p in pieces)):
            parts[0].pts = parts[0].pts[1:]  # the seed: the first point of the way up
        parts = [p for p in parts if p.pts]
        for p in parts:
            p.rows = post.rows(p.key, ctx.problem(p.K), ctx.omega_ref, p.pts)
        pieces += list(reversed(parts)) if not forward else parts
        stops.append(stop)
        if stop == "closed_loop" and forward:
            break  # an isola: once round
        if forward:  # a way up that stopped before it closed (a detour on an isola)
            own = Atlas()
            for k, p in enumerate(parts):
                own.add(dataclasses.replace(p, pts=p.pts[OWN_SKIP * (k == 0):]))
    # the way down first (reversed), then the way up, so the branch reads in order
    down = [p for p in pieces if p.reverse]
    up = [p for p in pieces if not p.reverse]
    return down + up, stops, ends


def _trace_piece(ctx, log, key, K, previous, f_start, f_end, entered, atlas, done,
                 progress, number, own=None):
    """Continue one piece (journal segment ``key``) from ``f_start`` to ``f_end`` (Hz);
    ``own``: an :class:`Atlas` of the branch's way up, for its way down. **Returns:**
    ``(stop word, why it ended on a known orbit)``: ``""`` (it did not), ``"joined"`` (it
    met a traced branch), ``"closed_loop"`` (it met ``own``: an isola) or
    :data:`PARENT_STOP` (a doubled branch is back on its parent orbit): the end's ``onto``."""
    problem = ctx.problem(K)
    log.require_K(key, K)
    met = {"joined": False, "onto": None}
    n = problem.shape[1]
    if log.end(key) is None:
        param = _continuation.FrequencyParameter(problem=problem,
                                                 omega_ref=jnp.asarray(ctx.omega_ref))

        def meets(y, lam, chord):
            # called after the point went to the log, for every point but a piece's first
            if ctx.eta > 1 and _doubling.back_on_parent(y, log.points(key)[-2]["y"], K, n):
                met["joined"], met["onto"] = True, PARENT_STOP
                return True
            if own is not None and own.meets(K, np.append(y, lam), chord, ctx.eta):
                met["joined"], met["onto"] = True, "closed_loop"
                return True
            hit = atlas.meets(K, np.append(y, lam), chord, ctx.eta)
            met["joined"] |= hit
            return hit

        def found():
            done["points"] += 1

        stop = _walk.continue_segment(
            log, key, K, param, previous, ctx.lam(f_start), ctx.lam(f_end),
            _walk.continuation_settings(ctx.max_step_hz, ctx.to_hz - ctx.from_hz,
                                        ctx.from_hz),
            cap=max(ctx.max_points - done["points"], 2), f_a=f_start, guess=None,
            runaway=ctx.runaway, max_detour=ctx.max_detour, entered=entered, found=found,
            progress=(lambda i, lam: progress(done["points"], lam * ctx.from_hz, number + 1))
            if progress else None, meets=meets)
        end = {"type": "end", "segment": key, "stop": stop, "joined": met["joined"]}
        if met["onto"]:
            end["onto"] = met["onto"]
        log.add(end)
    else:
        done["points"] += len(log.points(key))
    end = log.end(key)
    return end["stop"], end.get("onto", "joined") if end.get("joined", False) else ""


def _numpy_rows(rows, reverse: bool) -> dict:
    """``rows`` in reverse point order where ``reverse``."""
    if not reverse:
        return rows
    out = {k: (v[::-1] if k != "responses" else v) for k, v in rows.items()}
    out["X"] = list(reversed(rows["X"]))
    out["responses"] = jax.tree.map(lambda a: np.asarray(a)[::-1], rows["responses"])
    return out


def piece_rows(piece: Piece) -> dict:
    """The rows of ``piece`` in shown order, with its ``branch`` number and ``eta``."""
    rows = dict(_numpy_rows(piece.rows, piece.reverse))
    rows["branch"] = np.full(len(piece.pts), piece.branch)
    rows["eta"] = np.full(len(piece.pts), piece.eta)
    return rows
