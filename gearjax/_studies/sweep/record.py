"""A sweep's finished work as records, in memory and in its journal
(:mod:`gearjax._io.journal`).

Records: ``{"type": "point", "segment", "i", "K", "y", "lam", "ty", "tlam", "h", "age", "own",
"steps", "fold", "fold_lam"}`` per continuation point, ``{"type": "end", "segment",
"stop"}`` when a segment ends; per linear segment ``{"type": "solved", "segment", "K",
"omega", "X", "result", "converged"}`` per chunk of points solved and ``{"type":
"batch", "segment", "K", "omega", "X", "result", "solved", "checked", "added",
"unresolved", "stopped"}`` with its points once refined
(:func:`~gearjax._studies.sweep.walk.linear_segments`). The journal header's ``run`` fields are
:func:`run_fields`.
"""

from __future__ import annotations

import pathlib
import sys

from ..._errors import bad_argument, fail
from ..._io import journal as _journal
from ..harmonics import as_orders, orders_text


def run_fields(train_toml: str, *, gear: str, stage: str, from_hz, to_hz, linear: bool,
               harmonics, eta: int, max_step_hz, smoothing, points: int,
               max_points: int, complete: bool = True, seeds: int = 0) -> dict:
    """The fields of a sweep's journal header: everything its results depend on, under
    :func:`~gearjax.sweep`'s argument names (``train`` the train file's text); a refusal
    names the key that differs (``max_points`` bounds a linear sweep's refinement too).
    The completion's fields (:mod:`~gearjax._studies.sweep.completion`) are there only
    where they differ from the default: ``complete`` (False) where a non-linear sweep is
    not completed, ``seeds`` where it has integration seeds."""
    run = {"train": train_toml, "gear": gear, "stage": stage,
           "from_hz": float(from_hz), "to_hz": float(to_hz), "linear": bool(linear),
           "harmonics": None if harmonics is None else int(harmonics), "eta": int(eta),
           "max_step_hz": None if max_step_hz is None else float(max_step_hz),
           "smoothing": float(smoothing), "max_points": int(max_points)}
    if linear:
        run["points"] = int(points)
    else:
        if not complete:
            run["complete"] = False
        if complete and seeds:
            run["seeds"] = int(seeds)
    return run


class SweepLog:
    """A sweep's records (module docstring), indexed by segment; with a journal every
    record added is appended to it first."""

    def __init__(self, records: list[dict], writer=None):
        self._writer = writer
        self._points: dict[int, list[dict]] = {}
        self._solved: dict[int, list[dict]] = {}
        self._other: dict[tuple[str, int], dict] = {}
        for n, rec in enumerate(records):
            self._index(rec, writer.path if writer else None, n)

    @classmethod
    def open(cls, journal, run: dict, resume: bool) -> SweepLog:
        """The log of a run with header fields ``run``: in memory only where ``journal``
        is ``None``; else a new journal at ``journal``, or with ``resume`` the records of
        the one there (a journal of another run refused, naming the field).

        **Raises:** ``ArgumentError`` for ``resume`` without a journal;
        :class:`gearjax._io.journal.JournalExists` for a journal there without
        ``resume``; ``TrainError`` naming the journal for a damaged one or one of
        another run; :class:`gearjax._io.journal.JournalBusy` while another process
        writes it."""
        if journal is None:
            if resume:
                raise bad_argument("resume", True, "needs a `journal` to resume from")
            return cls([])
        path = pathlib.Path(journal)
        head = _journal.header("sweep", run)
        _journal.refuse_if_busy(path)
        if path.exists():
            if not resume:
                raise _journal.JournalExists(path)
            found, records, size = _journal.read(path)
            if found is not None:
                _journal.check(path, found, head)
                return cls(records, _journal.Writer.append_to(path, size))
        if resume:
            print(f"gearjax: {path}: no journal to resume; starting from the beginning",
                  file=sys.stderr, flush=True)
        return cls([], _journal.Writer.create(path, head))

    def _index(self, rec: dict, path, n: int) -> None:
        kind, j = rec.get("type"), rec.get("segment")
        if kind == "point":
            pts = self._points.setdefault(j, [])
            if rec.get("i") != len(pts) or ("end", j) in self._other:
                raise fail(str(path), f"record {n + 1}", f"segment {j} point {rec.get('i')}",
                           f"out of order (expected point {len(pts)}): the journal was "
                           "changed after it was written; delete it to start afresh")
            pts.append(rec)
        elif kind == "solved":
            self._solved.setdefault(j, []).append(rec)
        elif kind in ("end", "batch"):
            self._other[(kind, j)] = rec
        else:
            raise fail(str(path), f"record {n + 1}", kind, "is not a sweep record")

    def add(self, rec: dict) -> None:
        """Append ``rec`` (to the journal first)."""
        if self._writer is not None:
            self._writer.append(rec)
        self._index(rec, self._writer.path if self._writer else None, -1)

    def points(self, j: int) -> list[dict]:
        """Segment ``j``'s point records, in order."""
        return self._points.get(j, [])

    def end(self, j: int) -> dict | None:
        """Segment ``j``'s end record, ``None`` while it goes on."""
        return self._other.get(("end", j))

    def batch(self, j: int) -> dict | None:
        """Linear segment ``j``'s batch record, ``None`` before it is solved."""
        return self._other.get(("batch", j))

    def solved(self, j: int) -> list[dict]:
        """Linear segment ``j``'s records of points solved, in order."""
        return self._solved.get(j, [])

    def refused(self, j: int, rule: str):
        """The ``TrainError`` refusing to resume segment ``j`` of this journal for
        ``rule`` (to raise)."""
        where = self._writer.path if self._writer else "journal"
        return fail(str(where), f"segment {j} records of points solved",
                    len(self.solved(j)), f"{rule}: delete the journal to start afresh")

    def require_K(self, j: int, K: int) -> None:
        """Refuse a journal whose segment ``j`` was solved with another K than this run's
        ``K`` for it (e.g. a truncation check that decided otherwise on another machine),
        before any of its records is replayed."""
        recs = (self.points(j)[:1] + self.solved(j)[:1]
                + [r for r in [self.batch(j)] if r is not None])
        for rec in recs:
            if as_orders(rec["K"]) != as_orders(K):
                where = self._writer.path if self._writer else "journal"
                raise fail(str(where), f"segment {j} K", orders_text(rec["K"]),
                           f"this run's truncation check chose K = {orders_text(K)} for "
                           "that segment: delete the journal to start afresh")

    def close(self) -> None:
        """Close the journal (and give its lock back)."""
        if self._writer is not None:
            self._writer.close()
