"""The last segment of a sweep continued ahead of time, in a background thread, while the
segments before it run; adopted where the branch arriving from them enters it on the
same orbit.

The rule is the same with or without a thread (and so on any machine, for an
uninterrupted or a resumed run): the walk from the last segment on is that from its
*fresh start* (Newton from the linear guess at its first frequency) whenever the start
that the walk arriving there finds (the branch continued, or a restart) is that orbit
(:data:`SAME_ORBIT`); otherwise the walk goes on from the start it found, as without
speculation. Either way each point is a converged point of the branch that arrives;
adopting only changes where the continuation of that branch started, within Newton's
tolerance. Adopted points go to the journal together, as if the walk had found them
there; a run interrupted before that repeats the speculation when resumed. The thread
runs only where :func:`gearjax._studies.concurrency.parallel`; otherwise the
speculation runs inline when the walk reaches the segment.
"""

from __future__ import annotations

import threading

import jax.numpy as jnp

from ..._engine import hb as _hb
from ..._engine.results import RESULTS
from .. import concurrency
from . import starts as _starts
from . import walk as _walk
from .record import SweepLog

SAME_ORBIT = 1e-6
"""Two converged starts are the same orbit where their scaled unknowns differ by at most
this much relative to the largest (Newton converges to ``1e-9``; distinct orbits at one
frequency differ by far more)."""

SPECULATION_THREAD = "gearjax-speculation"
"""Name of the speculation thread."""


class Speculation:
    """The continuation of ``segment`` ``(f_a, f_b, K)`` from its own fresh start
    (module docstring), with its own walk and in-memory log; its post-processing goes
    to ``post`` under the keys ``("speculation", j)``."""

    def __init__(self, ctx, segment, post):
        self.ctx, self.segment, self.post = ctx, segment, post
        self.walk = _walk.Walk(segments=[segment])
        self.log = SweepLog([])
        self.entered = None  # (y, result, lambda) of the fresh start
        self.error = None
        self._cancel = threading.Event()
        self._started = threading.Event()
        self._thread = None

    def start(self) -> Speculation:
        """Run in a background thread (:data:`SPECULATION_THREAD`)."""
        self._thread = concurrency.start_thread(self._run, SPECULATION_THREAD)
        return self

    def _run(self):
        try:
            self._enter()
            self._started.set()
            self._continue()
        except _walk.Cancelled:
            pass
        except BaseException as e:  # noqa: BLE001  re-raised where the walk would adopt it
            self.error = e
        finally:
            self._started.set()

    def _enter(self):
        f_a, _, K = self.segment
        problem = self.ctx.problem(K)
        omega = jnp.asarray(self.ctx.omega(f_a))
        sol = _starts.newton(problem, omega, _hb.linear_guess(problem, omega))
        self.entered = (sol.y, sol.result, self.ctx.lam(f_a))

    def _continue(self):
        if not bool(self.entered[1] == RESULTS.successful):
            return
        while len(self.walk.problems) < len(self.walk.segments):
            if self._cancel.is_set():
                raise _walk.Cancelled
            first = not self.walk.problems
            if not _walk.walk_segment(self.ctx, self.walk, self.log, self.post,
                                      entered=self.entered if first else None,
                                      key=self.key, cancel=self._cancel):
                break

    @staticmethod
    def key(j):
        """The name of the speculation's segment ``j`` in the post-processing."""
        return ("speculation", j)

    def cancel(self) -> None:
        """Call it off and drop its chunks. The thread stops at its next point or
        segment, not inside a restart's start (a time integration, a homotopy)."""
        self._cancel.set()
        for j in range(len(self.walk.segments)):
            self.post.drop(self.key(j))

    def adopt(self, walk, entered, log) -> bool:
        """Whether the walk's start ``entered`` ``(y, result, lambda)`` of the next segment
        (this one's) is this one's orbit, at its first frequency; if so, once it is
        finished, its records are appended to ``log`` as that segment and those after it
        (the walk then takes them from there) and its post-processing is handed over. A
        speculation that ran past caps the walk would have hit (``max_points``,
        :data:`~gearjax._studies.sweep.walk.MAX_RESTARTS`) is not adopted."""
        if self._thread is None:
            self._enter()
        else:
            self._started.wait()
        if self.error is not None and self.entered is None:
            raise self.error
        y, code, lam = entered
        y_spec, code_spec, lam_spec = self.entered
        same = bool((code == RESULTS.successful) & (code_spec == RESULTS.successful)) \
            and lam == lam_spec and float(
            jnp.max(jnp.abs(y - y_spec))) <= SAME_ORBIT * max(1.0, float(jnp.max(jnp.abs(y))))
        if not same:
            self.cancel()
            return False
        if self._thread is None:
            self._continue()
        else:
            self._thread.join()
        if self.error is not None:
            raise self.error
        if not (walk.done + self.walk.done + 2 < self.ctx.max_points
                and len(walk.restarts) + len(self.walk.restarts) < _walk.MAX_RESTARTS):
            self.cancel()
            return False
        j0 = len(walk.problems)
        for j in range(len(self.walk.problems)):
            for rec in self.log.points(j) + [self.log.end(j)]:
                log.add({**rec, "segment": j0 + j})
            self.post.rename(self.key(j), j0 + j)
        return True


def speculate(ctx, walk, log, post, spec, last):
    """Before the walk's next segment: start the speculation on the sweep's ``last``
    segment ``(f_a, f_b, K)`` while earlier segments are still to compute, where threads
    are allowed; at the last segment, find the walk's start there and adopt or call off
    the speculation. **Returns:** ``(entered, spec)``: the start found (``None`` where
    the speculation was adopted or nothing is to compute) and the speculation still
    running."""
    j = len(walk.problems)
    if len(walk.segments) < 2 or log.end(j) is not None:
        return None, spec
    target = walk.segments.index(last) if last in walk.segments[1:] else -1
    if j < target:
        if spec is None and concurrency.parallel():
            spec = Speculation(ctx, last, post).start()
        return None, spec
    if j != target or log.points(j):
        return None, spec
    f_a, _, K = last
    previous, guess = walk.handover(j)
    entered = _starts.enter_segment(ctx.problem(K), previous, ctx.lam(f_a), ctx.omega_ref, guess)
    spec = spec or Speculation(ctx, last, post)
    adopted = spec.adopt(walk, entered, log)
    return (None if adopted else entered), None
