"""Run a study: every candidate as a task on a Dask cluster, each result written to the
study store as it arrives.

Without a ``client``, :func:`study` starts a ``LocalCluster`` of this machine's cores:
one worker process per core, one thread each, with BLAS and gearjax's own threads held
to one (:data:`WORKER_ENV`), so the workers do not compete for the cores. Each
worker keeps its compiled programs in memory and in the persistent compilation cache
(:mod:`gearjax._config`), so a worker compiles once per shape of problem, not once per
candidate; candidates that share the shapes of their programs (:func:`shape_key`) are
sent to one worker where they can be (:func:`worker_homes`). Dask reruns a task whose
worker dies on another worker; a candidate whose task cannot finish (its workers died
every time) is recorded as failed.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import os
import pathlib
import time
import tomllib
from collections.abc import Callable

import xarray as xr

from ..._config import QUIET_LEVEL
from ..._errors import bad_argument
from ..._io.journal import JournalBusy, lock
from ..concurrency import cores
from .analysis import analyse_candidate
from .candidates import Candidate, candidate_text, candidates, check_paths, refusal
from .spec import StudySpec, load_study
from .store import IDENTITY, done_indices, load_study_results, open_store, write_candidate

WORKER_ENV = {"GEARJAX_THREADS": "1", "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
              "MKL_NUM_THREADS": "1", "JAX_LOGGING_LEVEL": QUIET_LEVEL}
"""Environment of a ``LocalCluster``'s worker processes: gearjax's threads
(:mod:`gearjax._studies.concurrency`) and BLAS held to one, and JAX's and XLA's log
messages kept off the terminal as the command line keeps them
(:func:`gearjax._config.quiet_jax_logs`). XLA's own CPU thread pool, which the compiled
programs' dense algebra uses, is left as it is."""


@dataclasses.dataclass(frozen=True)
class StudyResult:
    """A study's ``dataset`` (:func:`~.store.load_study_results`: every finished
    candidate, this run's and earlier ones'), its ``store``, and this run's counts:
    ``ran`` (candidates analysed), ``refused`` (train file refused, or an analysis's
    rule), ``failed``, ``skipped`` (already in the store), and ``seconds``."""

    dataset: xr.Dataset
    store: pathlib.Path
    ran: int
    refused: int
    failed: int
    skipped: int
    seconds: float


def study(spec: StudySpec | str | os.PathLike, store, *, client=None,
          workers: int | None = None, resume: bool = False,
          say: Callable[[str], None] | None = None) -> StudyResult:
    """Run the study ``spec`` (a :class:`~.spec.StudySpec` or a study file's path) into
    the study store ``store`` (a directory, :mod:`~.store`).

    **Arguments:** ``client``: a ``dask.distributed.Client`` of a cluster to run on
    (default: a ``LocalCluster`` started for this call and closed after); ``workers``:
    worker processes of that ``LocalCluster`` (default: this machine's cores; ``0``: no
    cluster, every candidate in this process, one after another); ``resume``: run only
    the candidates ``store`` has no result for (a store of another study is refused);
    ``say(line)``: called with a line of progress per finished candidate. The store is
    locked while the study runs.

    **Raises:** ``TrainError`` (one line: file, field, value, rule), before any
    candidate runs, for a study file, base train or gear that breaks a rule, a varied
    path that names nothing in the base train, or a store that cannot be used (another
    process runs a study on it); an ``ArgumentError`` for ``workers`` below 0 or given
    with ``client``."""
    from ..._gear.toml_io import loads_train

    t0 = time.perf_counter()
    if not isinstance(spec, StudySpec):
        spec = load_study(spec)
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int)
                                or workers < 0):
        raise bad_argument("workers", workers, "must be an integer >= 0 (0: no cluster)")
    if workers is not None and client is not None:
        raise bad_argument("workers", workers, "is for the LocalCluster a study starts; "
                           "a `client` brings its own workers")
    base = loads_train(spec.train_text, source=spec.train_path or "bundled paper case")
    base.gear(spec.gear)
    check_paths(spec)
    every = candidates(spec)
    path = open_store(store, spec, len(every), resume=resume)
    try:
        hold = lock(path / IDENTITY)
    except JournalBusy as e:
        who = f"pid {e.pid}" if e.pid else "pid unknown"
        raise bad_argument("store", str(path), f"another gearjax process ({who}) is running "
                           "this study now: wait for it, or choose another store") from None
    try:
        return _run_study(spec, every, path, client, workers, say, t0)
    finally:
        hold.release()


def _run_study(spec: StudySpec, every, path, client, workers, say, t0) -> StudyResult:
    done = done_indices(path)
    todo = [c for c in every if c.index not in done]
    progress = _Progress(len(every), len(done), say)
    runnable = []
    for c in todo:
        text = candidate_text(spec, c)
        reason = refusal(text, _source(spec, c))
        if reason is None:
            runnable.append((c, text))
        else:
            merits = {"status": "refused", "reason": reason, "warnings": [], "seconds": 0.0}
            write_candidate(path, spec, c, merits)
            progress.finished(c, merits)
    analysis = dataclasses.asdict(spec.analysis)
    if workers == 0 and client is None:
        for c, text in runnable:
            progress.running = 1
            merits = analyse_candidate(text, _source(spec, c), spec.gear, analysis)
            write_candidate(path, spec, c, merits)
            progress.finished(c, merits)
    elif runnable:
        with _cluster(client, workers) as cl:
            _run_tasks(cl, spec, runnable, analysis, path, progress)
    return StudyResult(dataset=load_study_results(path), store=path, ran=progress.ran,
                       refused=progress.refused, failed=progress.failed, skipped=len(done),
                       seconds=time.perf_counter() - t0)


def _source(spec: StudySpec, c: Candidate) -> str:
    return f"{spec.source} candidate {c.index}"


@contextlib.contextmanager
def _cluster(client, workers: int | None):
    if client is not None:
        yield client
        return
    from dask.distributed import Client, LocalCluster

    n = cores() if workers is None else workers
    with LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                      dashboard_address=None, env=WORKER_ENV,
                      silence_logs=logging.CRITICAL) as cluster, Client(cluster) as cl:
        yield cl


def _run_tasks(client, spec: StudySpec, runnable, analysis: dict, path, progress) -> None:
    from dask.distributed import as_completed

    home = worker_homes([shape_key(text) for _, text in runnable], _workers(client))
    futures = {}
    for (c, text), worker in zip(runnable, home):
        key = f"gearjax-candidate-{spec.digest[:12]}-{c.index}"
        where = {} if worker is None else {"workers": [worker], "allow_other_workers": True}
        futures[client.submit(analyse_candidate, text, _source(spec, c), spec.gear,
                              analysis, key=key, **where)] = c
    progress.running = min(len(futures), _worker_count(client))
    try:
        for fut in as_completed(futures):
            c = futures[fut]
            try:
                merits = fut.result()
            except Exception as e:  # noqa: BLE001  e.g. KilledWorker: its workers died
                merits = {"status": "failed", "reason": f"{type(e).__name__}: {e}",
                          "warnings": [], "seconds": 0.0}
            write_candidate(path, spec, c, merits)
            progress.finished(c, merits)
    finally:  # interrupted: leave no task running on a cluster that outlives the study
        client.cancel(list(futures))


def _worker_count(client) -> int:
    return max(1, len(_workers(client)))


def _workers(client) -> list[str]:
    try:
        return sorted(client.scheduler_info().get("workers", {}))
    except Exception:  # noqa: BLE001  a scheduler that does not answer: no preference
        return []


def shape_key(text: str) -> tuple:
    """What decides the shapes of a candidate's compiled programs: per stage its planet
    count and tooth counts (the mesh frequency ratios, hence the harmonics), and the
    stiffness harmonics. Candidates with one key reuse each other's programs."""
    raw = tomllib.loads(text)
    stages = tuple((len(s.get("planet_angles_deg", ())),
                    tuple(sorted((s.get("teeth") or {}).items())))
                   for s in raw.get("stages", []) if isinstance(s, dict))
    return stages, raw.get("stiffness_harmonics")


def worker_homes(keys: list, workers: list[str]) -> list[str | None]:
    """A preferred worker per candidate, so that candidates of one :func:`shape_key` go
    to one worker, which compiles their programs once: the keys, largest group first,
    each to the worker with the fewest candidates so far. A preference, not a rule: an
    idle worker still takes a waiting candidate (``allow_other_workers``). ``None``
    (no preference) where no worker is known."""
    if not workers:
        return [None] * len(keys)
    groups: dict = {}
    for i, key in enumerate(keys):
        groups.setdefault(key, []).append(i)
    load = dict.fromkeys(workers, 0)
    home: list[str | None] = [None] * len(keys)
    for members in sorted(groups.values(), key=len, reverse=True):
        worker = min(workers, key=lambda w: load[w])
        load[worker] += len(members)
        for i in members:
            home[i] = worker
    return home


class _Progress:
    """Progress lines over candidates: done, running, refused or failed, time left."""

    def __init__(self, total: int, skipped: int, say):
        self.total, self.done, self.say = total, skipped, say
        self.ran = self.refused = self.failed = 0
        self.running = 0
        self.busy = 0.0
        self.t0 = time.perf_counter()

    def finished(self, c: Candidate, merits: dict) -> None:
        self.done += 1
        status = merits["status"]
        if status != "refused" or merits.get("seconds", 0.0) > 0:
            self.ran += 1
        self.refused += status == "refused"
        self.failed += status == "failed"
        self.busy += merits.get("seconds", 0.0)
        if self.say is None:
            return
        left = self.total - self.done
        running = min(self.running, left)
        elapsed = time.perf_counter() - self.t0
        rate = elapsed / max(self.ran, 1)
        words = f", about {rate * left:.0f} s left" if self.ran and left else ""
        why = f": {merits['reason']}" if merits["reason"] else ""
        self.say(f"candidate {c.index} {status}{why} ({merits.get('seconds', 0.0):.1f} s); "
                 f"{self.done}/{self.total} done, {running} running, {self.refused} "
                 f"refused, {self.failed} failed{words}")
