"""Run journals: an append-only file of finished work, so a long run loses nothing.

A journal is a text file of records, one a line::

    CRC32 JSON\\n

``CRC32`` is the eight-hex-digit CRC-32 of the JSON bytes. The first record is the
header, ``{"format": "gearjax-journal", "version": 1, "kind": ..., "gearjax_version":
..., "run": {FIELD: VALUE, ...}}``: ``run`` holds everything the results depend on
(train text, gear, flags), and a journal is only resumed by a run whose fields are
equal, compared one by one so a refusal names the field. Every later record is a
JSON object; float64 (and other) NumPy arrays in it are stored exactly as their raw
bytes, base64-encoded: ``{"__array__": [dtype, shape, base64]}``; floats as JSON
numbers round-trip exactly too (shortest repr), and NaN is stored as ``null``.

Each record is written whole, flushed and ``os.fsync``-ed before the run goes on,
so an interruption at any moment (``kill -9``, power loss) leaves every earlier
record intact. A torn last record (no newline, bad checksum or bad JSON) is
ignored with a warning and cut off when the journal is appended to again; a bad
record before the last is corruption, refused.

A journal being written is locked (:func:`lock`): an OS lock (``fcntl.flock``) on
``FILE.journal.lock``, which holds the writer's pid. The kernel drops the lock when
the process ends in any way (``kill -9`` included), so a journal left by a crash is
resumed at once; while a run is live, another process that would read, append to or
replace its journal is refused (:class:`JournalBusy`, naming the pid). The lock is
re-entrant within one process (a caller may hold it from before the run until the
journal is consolidated into the results; the :class:`Writer` takes it too).
"""

from __future__ import annotations

import base64
import errno
import fcntl
import json
import math
import os
import pathlib
import sys
import threading
import zlib
from collections.abc import Callable, Mapping

import numpy as np

from .._version import __version__
from .._errors import TrainError, fail

FORMAT = "gearjax-journal"
VERSION = 1
SUFFIX = ".journal"
LOCK_SUFFIX = ".lock"


def journal_path(results_path) -> pathlib.Path:
    """The journal next to a results file: ``FILE`` -> ``FILE.journal``."""
    return pathlib.Path(str(results_path) + SUFFIX)


def header(kind: str, run: Mapping) -> dict:
    """The first record of a journal for a run of ``kind`` (e.g. ``"sweep"``) with the
    fields ``run`` (JSON-able values: strings, numbers, booleans, ``None``)."""

    return {"format": FORMAT, "version": VERSION, "kind": kind,
            "gearjax_version": __version__, "run": dict(run)}


# ------------------------------------------------------------------------ encoding


def encode(record: Mapping) -> bytes:
    """One journal line (with its checksum and newline) holding ``record``."""
    text = json.dumps(_to_json(record), separators=(",", ":"), allow_nan=False).encode()
    return b"%08x %s\n" % (zlib.crc32(text), text)


def decode(line: bytes) -> dict | None:
    """The record of one journal line (without its newline), or ``None`` when the line
    is damaged (bad checksum or JSON)."""
    crc, _, text = line.partition(b" ")
    try:
        if len(crc) != 8 or int(crc, 16) != zlib.crc32(text):
            return None
        return _from_json(json.loads(text))
    except ValueError:
        return None


def _to_json(value):
    if isinstance(value, np.ndarray):
        a = np.ascontiguousarray(value)
        return {"__array__": [a.dtype.str, list(a.shape), base64.b64encode(a.tobytes()).decode()]}
    if isinstance(value, Mapping):
        return {str(k): _to_json(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_to_json(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        if math.isnan(value):
            return None
        raise ValueError(f"journal records cannot hold {value}")
    return value


def _from_json(value):
    if isinstance(value, dict):
        if set(value) == {"__array__"}:
            dtype, shape, data = value["__array__"]
            raw = base64.b64decode(data)
            return np.frombuffer(raw, dtype=np.dtype(dtype)).reshape(shape).copy()
        return {k: _from_json(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_from_json(v) for v in value]
    return value


# ------------------------------------------------------------------------ locking


class JournalBusy(TrainError):
    """Another live process is writing this journal (one line naming it and its pid);
    ``journal`` and ``pid`` (``None`` where unknown) are kept."""

    def __init__(self, journal, pid: int | None):
        who = f"pid {pid}" if pid else "pid unknown"
        super().__init__(f"{journal}: another gearjax process ({who}) is writing this "
                         "journal now; wait for it or choose another `journal`")
        self.journal = journal
        self.pid = pid


class JournalExists(TrainError):
    """A journal of an interrupted run is where a new run would start one (one line
    naming it); ``journal`` is kept."""

    def __init__(self, journal):
        super().__init__(f"{journal}: a journal of an interrupted run is there: add `resume` "
                         "to continue it, or delete it to start afresh")
        self.journal = journal


def lock_path(journal) -> pathlib.Path:
    """The lock file of a journal: ``FILE.journal`` -> ``FILE.journal.lock``."""
    return pathlib.Path(str(journal) + LOCK_SUFFIX)


class JournalLock:
    """This process's hold on a journal's lock (from :func:`lock`); ``release`` (or the
    ``with`` block's end) gives one hold back, the last one unlocks and removes the lock
    file."""

    def __init__(self, journal: pathlib.Path, key: str):
        self.journal = journal
        self._key = key
        self._released = False

    def release(self) -> None:
        if self._released:
            return
        self._released = True
        with _guard:
            entry = _held.get(self._key)
            if entry is None:
                return
            entry[1] -= 1
            if entry[1] > 0:
                return
            del _held[self._key]
            fd = entry[0]
            try:  # removed while still locked: a process that opened it meanwhile retries
                os.unlink(self._key)
            except OSError:
                pass
            os.close(fd)  # drops the lock

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.release()


_held: dict[str, list] = {}  # lock file (absolute) -> [fd, holds, pid] of this process
_guard = threading.Lock()


def lock(journal) -> JournalLock:
    """Lock the journal ``journal`` for this process (re-entrant) before writing it.

    **Raises:** :class:`JournalBusy` when another live process holds it; ``TrainError``
    when the lock file cannot be written (e.g. no such directory)."""
    journal = pathlib.Path(journal)
    key = os.path.abspath(lock_path(journal))
    with _guard:
        entry = _held.get(key)
        if entry is not None and entry[2] == os.getpid():
            entry[1] += 1
            return JournalLock(journal, key)
        _held.pop(key, None)  # inherited across a fork: not ours
        for _ in range(100):
            try:
                fd = os.open(key, os.O_RDWR | os.O_CREAT | getattr(os, "O_CLOEXEC", 0), 0o644)
            except OSError as e:
                raise fail(key, "journal lock", None,
                           f"cannot be written ({e.strerror or e})") from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as e:
                pid = _read_pid(fd)
                os.close(fd)
                if e.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                    raise _busy(journal, pid) from None
                raise fail(key, "journal lock", None,
                           f"cannot be taken ({e.strerror or e})") from None
            try:  # still the file at that name (not removed by its last holder meanwhile)?
                same = os.path.samestat(os.fstat(fd), os.stat(key))
            except FileNotFoundError:
                same = False
            if same:
                break
            os.close(fd)
        else:  # pragma: no cover  (a lock file replaced a hundred times in a row)
            raise fail(key, "journal lock", None, "keeps being replaced by another process")
        os.ftruncate(fd, 0)
        os.pwrite(fd, b"%d\n" % os.getpid(), 0)
        _held[key] = [fd, 1, os.getpid()]
        return JournalLock(journal, key)


def holder(journal) -> int | None:
    """The pid of another live process that holds ``journal``'s lock (0 when it has not
    written its pid yet), or ``None`` when none does (this process's own hold is not
    counted)."""
    key = os.path.abspath(lock_path(journal))
    with _guard:
        entry = _held.get(key)
        if entry is not None and entry[2] == os.getpid():
            return None
    try:
        fd = os.open(key, os.O_RDONLY | getattr(os, "O_CLOEXEC", 0))
    except OSError:
        return None  # no lock file: nobody writes it
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except OSError as e:
            if e.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                return _read_pid(fd) or 0
            return None
        return None
    finally:
        os.close(fd)  # drops the probe's shared lock


def refuse_if_busy(journal) -> None:
    """Raise :class:`JournalBusy` when another live process holds ``journal``'s lock."""
    pid = holder(journal)
    if pid is not None:
        raise _busy(pathlib.Path(journal), pid)


def _busy(journal: pathlib.Path, pid: int | None) -> JournalBusy:
    return JournalBusy(journal, pid)


def _read_pid(fd: int) -> int | None:
    try:
        text = os.pread(fd, 32, 0)
        return int(text.strip() or b"0") or None
    except (OSError, ValueError):
        return None


# -------------------------------------------------------------------- reading


def _stderr(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def read(path, warn: Callable[[str], None] = _stderr) -> tuple[dict | None, list[dict], int]:
    """Read the journal at ``path``.

    **Returns:** ``(header, records, size)``: the header (``None`` when not even the
    header was written whole), the records after it in order, and the byte length of
    the intact part (where appending continues). A torn last record is left out with
    a message to ``warn``.

    **Raises:** ``TrainError`` (one line naming the file) when the file cannot be read,
    is not a gearjax journal, or is damaged before its last record;
    :class:`JournalBusy` when another live process is writing it.
    """
    path = pathlib.Path(path)
    refuse_if_busy(path)
    try:
        data = path.read_bytes()
    except OSError as e:
        raise fail(str(path), "journal", None, f"cannot be read ({e.strerror or e})") from None
    lines = data.split(b"\n")
    tail = lines.pop()  # bytes after the last newline: empty unless a write was torn
    records, size = [], 0
    for n, line in enumerate(lines):
        rec = decode(line)
        if rec is None:
            if n == len(lines) - 1 and not tail:
                tail = line  # the last line is damaged: a torn write
                break
            raise fail(str(path), f"record {n}", None,
                       "is damaged (bad checksum) before the end of the journal: the file "
                       "was changed after it was written; delete it to start afresh")
        records.append(rec)
        size += len(line) + 1
    if tail:
        warn(f"gearjax: warning: {path}: ignoring a torn last record ({len(tail)} bytes): "
             "the run was interrupted while writing it")
    if not records:
        return None, [], 0
    head = records.pop(0)
    if not isinstance(head, dict) or head.get("format") != FORMAT:
        raise fail(str(path), "format", head.get("format") if isinstance(head, dict) else None,
                   f"is not a {FORMAT} file")
    if head.get("version") != VERSION:
        raise fail(str(path), "version", head.get("version"),
                   f"this gearjax reads journal version {VERSION}; delete it to start afresh")
    return head, records, size


def check(path, found: Mapping, expected: Mapping) -> None:
    """Refuse a journal whose header ``found`` is not that of the run ``expected`` (both
    from :func:`header`): ``TrainError`` naming the file and the first field that
    differs (``kind``, ``gearjax_version``, then the run fields in order, each written
    `` `name` `` as the library's argument names are, which the command line shows as
    its flags)."""
    rule = ("the journal was written by a different run; rerun with the same train, gear "
            "and settings, or delete the journal to start afresh")
    for key in ("kind", "gearjax_version"):
        if found.get(key) != expected.get(key):
            raise fail(str(path), key, found.get(key), f"differs from this run's "
                       f"{expected.get(key)!r}: {rule}")
    have, want = found.get("run", {}), expected["run"]
    for key in list(want) + [k for k in have if k not in want]:
        if key not in have or key not in want or have[key] != want[key]:
            value, mine = _brief(have.get(key)), _brief(want.get(key))
            raise fail(str(path), f"`{key}`", value, f"differs from this run's {mine!r}: {rule}")


def _brief(value):
    """Long texts (a train file) shown by length and checksum in messages."""
    if isinstance(value, str) and len(value) > 60:
        return f"<text of {len(value)} characters, crc32 {zlib.crc32(value.encode()):08x}>"
    return value


# -------------------------------------------------------------------- writing


class Writer:
    """Appends records to a journal, each flushed and fsync-ed before ``append`` returns.

    ``Writer.create(path, head)`` starts a new journal (replacing any file there);
    ``Writer.append_to(path, size)`` continues one whose intact part is ``size`` bytes
    (from :func:`read`), cutting off a torn last record. Both first :func:`lock` the
    journal (:class:`JournalBusy` when another live process writes it); ``close``
    gives the lock back.
    """

    def __init__(self, path, file, held: JournalLock | None = None):
        self.path = pathlib.Path(path)
        self._file = file
        self._lock = held

    @classmethod
    def create(cls, path, head: Mapping) -> Writer:
        def start(writer: Writer) -> None:
            writer.append(head)
            sync_directory(writer.path)

        return cls._open_locked(path, "wb", start)

    @classmethod
    def append_to(cls, path, size: int) -> Writer:
        def start(writer: Writer) -> None:
            writer._file.truncate(size)
            writer._file.seek(size)
            os.fsync(writer._file.fileno())

        return cls._open_locked(path, "r+b", start)

    @classmethod
    def _open_locked(cls, path, mode: str, start: Callable[[Writer], None]) -> Writer:
        """:func:`lock` the journal ``path``, open it in ``mode`` and ``start`` the writer
        on it; the lock is given back when any step fails.

        **Raises:** :class:`JournalBusy` as :func:`lock`; ``TrainError`` naming the file
        when it cannot be opened; whatever ``start`` raises."""
        path = pathlib.Path(path)
        held = lock(path)
        try:
            try:
                file = open(path, mode)
            except OSError as e:
                raise fail(str(path), "journal", None,
                           f"cannot be written ({e.strerror or e})") from None
            writer = cls(path, file, held)
            start(writer)
        except BaseException:
            held.release()
            raise
        return writer

    def append(self, record: Mapping) -> None:
        self._file.write(encode(record))
        self._file.flush()
        os.fsync(self._file.fileno())

    def close(self) -> None:
        try:
            self._file.close()
        finally:
            if self._lock is not None:
                self._lock.release()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def sync_directory(path: pathlib.Path) -> None:
    """Make the new file ``path``'s directory entry durable (best effort: not on every
    OS)."""
    try:
        fd = os.open(path.parent if str(path.parent) else ".", os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)
