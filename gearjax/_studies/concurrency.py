"""Every thread the studies start, under one policy.

The sweep overlaps three kinds of work: the continuation (one core busy: its dense LU
on one BLAS thread), the post-processing of the points it has found (responses and
Floquet stability, in a background worker and a pool of workers), and the
speculative continuation of the last segment (a background thread). Results never
depend on whether these run in threads: the same compiled programs see the same
arguments either way.

**The setting.** ``GEARJAX_THREADS=N`` (environment variable, read at each call)
allows at most ``N`` threads of work; ``GEARJAX_THREADS=1`` turns every thread off:
workers run their tasks at once in the calling thread, no speculation thread starts
and BLAS runs on one thread. Without it, one thread per CPU core this process may
run on (``os.sched_getaffinity``, else ``os.cpu_count()``): on one core everything
is serial.
"""

from __future__ import annotations

import concurrent.futures
import os
import threading
from collections.abc import Callable, Iterable

import threadpoolctl

from .._errors import one_line

THREADS_ENV = "GEARJAX_THREADS"
"""Environment variable: the most threads the studies may use (1: serial)."""

THREADS_RULE = "must be an integer >= 1 (1: no threads)"


def cores() -> int:
    """CPU cores this process may run on (>= 1)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def threads() -> int:
    """Threads of work the studies may use at once: :func:`cores`, at most the
    ``GEARJAX_THREADS`` setting.

    **Raises:** ``ValueError`` where ``GEARJAX_THREADS`` is set to anything but an
    integer >= 1."""
    n = threads_setting(os.environ.get(THREADS_ENV, ""))
    return cores() if n is None else min(n, cores())


def threads_setting(value: str) -> int | None:
    """The ``GEARJAX_THREADS`` value ``value`` read: ``None`` where empty, else the
    integer. **Raises:** ``ValueError`` (one line) where it is not an integer >= 1."""
    setting = value.strip()
    if not setting:
        return None
    try:
        n = int(setting)
    except ValueError:
        n = 0
    if n < 1:
        raise ValueError(one_line(f"{THREADS_ENV} = {setting!r}: {THREADS_RULE}"))
    return n


def parallel() -> bool:
    """Whether work may run in threads (:func:`threads` > 1)."""
    return threads() > 1


def start_thread(target: Callable[[], None], name: str) -> threading.Thread:
    """``target`` started in a daemon thread called ``name`` (callers start one only
    where :func:`parallel`)."""
    thread = threading.Thread(target=target, name=name, daemon=True)
    thread.start()
    return thread


class Worker:
    """One background worker for tasks submitted in order (a thread called ``name``),
    or, where the policy is serial, the calling thread: each task then runs at
    :meth:`submit` and its future is already done."""

    def __init__(self, name: str):
        self._pool = (concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix=name)
                      if parallel() else None)

    def submit(self, fn, *args) -> concurrent.futures.Future:
        """``fn(*args)`` as a future."""
        if self._pool is not None:
            return self._pool.submit(fn, *args)
        future = concurrent.futures.Future()
        try:
            future.set_result(fn(*args))
        except Exception as e:  # noqa: BLE001  raised where the result is asked for
            future.set_exception(e)
        return future

    def close(self) -> None:
        """Stop: tasks not started are dropped; a running one finishes on its own."""
        if self._pool is not None:
            self._pool.shutdown(wait=False, cancel_futures=True)


def map_in_threads(fn: Callable, items: Iterable, name: str) -> list:
    """``[fn(x) for x in items]``, in up to :func:`threads` threads called ``name`` (the
    calling thread alone where the policy is serial); results in the order of
    ``items``."""
    items = list(items)
    n = min(threads(), len(items))
    if n <= 1:
        return [fn(x) for x in items]
    with concurrent.futures.ThreadPoolExecutor(n, thread_name_prefix=name) as pool:
        return list(pool.map(fn, items))


def limit_blas() -> threadpoolctl.threadpool_limits:
    """BLAS (OpenBLAS, ...) limited to all threads but one, the one left for the
    background worker that runs beside a computation, and at least one (one where the
    policy is serial: a factorisation then rounds as it does beside the worker). The
    caller restores the limits (``.restore_original_limits()``)."""
    return threadpoolctl.threadpool_limits(max(1, threads() - 1), user_api="blas")
