"""Programs kept between processes: traced and lowered once, not in every run.

JAX's persistent compilation cache (:mod:`gearjax._config`) keeps what XLA compiled,
but every process still traces each program and lowers it to StableHLO before the cache
can be looked up: seconds per process for the solver's larger programs. A function
wrapped by :func:`kept_program`, called outside any trace, is exported once
(``jax.export``: the lowered program with its input and output types) into
``programs/`` under the compilation cache directory and, in a later process, loaded from
there and called without tracing or lowering it again.

A stored program is looked up by a SHA-256 key of everything its program depends on: the
function's qualified name, the source of every gearjax module, the versions of Python
and of the libraries traced into it (:data:`LIBRARIES`), the JAX settings that change a
trace (:data:`TRACE_SETTINGS`), ``EQX_ON_ERROR``, the platform, the argument tree with
every static value (equinox static fields, static arguments) and the shape and dtype of
every array; array values are the program's inputs. A static value without a stable
written form, or holding code the key does not cover (a lambda, a closure, the caller's
own functions or classes, an object of an unknown kind), makes the call one the store
does not serve: it runs as an ordinary ``jax.jit`` program, as does every call inside a
trace (``jit``, ``vmap``, ``grad``), a program that cannot be exported (host callbacks,
outputs that are not arrays) and every call while the cache or the store is off
(:data:`KEEP_ENV`). The store holds at most :data:`STORE_MAX_BYTES`; a file that cannot
be read is exported again. The key sees gearjax's source as it is on disk, not module
globals changed at run time: code that patches what a program traces (a test's
``monkeypatch`` of a solver constant) switches the store off first.
"""

from __future__ import annotations

import dataclasses
import enum
import functools
import hashlib
import importlib.metadata
import inspect
import io
import logging
import os
import pathlib
import pickle
import struct
import sys
import tempfile
import threading
import types
import weakref

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import _config

MAGIC = b"gearjax kept program 1\n"
"""First bytes of a stored program's file."""

STORE_MAX_BYTES = 512 * 1024**2
"""Most bytes the store holds: beyond, the programs least recently used go first (the
store keeps every version of gearjax's source it has seen, each its own keys)."""

LIBRARIES = ("jax", "jaxlib", "equinox", "lineax", "optimistix", "diffrax", "numpy",
             "jaxtyping")
"""Distributions whose code is traced into the programs (their versions are in the key)."""

TRACE_SETTINGS = ("jax_enable_x64", "jax_numpy_rank_promotion", "jax_numpy_dtype_promotion",
                  "jax_default_matmul_precision", "jax_debug_nans", "jax_debug_infs",
                  "jax_enable_checks", "jax_default_prng_impl")
"""JAX settings that change a trace (their values are in the key)."""


_COVERED = frozenset(("gearjax", "builtins", "collections", *LIBRARIES))
"""Top-level packages whose code the key covers (gearjax's source, library versions)."""


class Unstable(Exception):
    """A static value with no stable written form: the call is not stored."""


KEEP_ENV = "GEARJAX_KEEP_PROGRAMS"
"""``GEARJAX_KEEP_PROGRAMS=0`` switches the store off (the compilation cache stays on)."""


def store_dir() -> pathlib.Path | None:
    """Where exported programs are kept: ``programs/`` in the compilation cache directory
    (``None`` where the cache is off, or its directory could not be made (a read-only
    home: every process would export each program and fail to save it), or the store
    is off, :data:`KEEP_ENV`)."""
    if os.environ.get(KEEP_ENV, "1").strip() in ("", "0"):
        return None
    root = _config.cache_dir()
    return None if root is None or not os.path.isdir(root) else pathlib.Path(root) / "programs"


def kept_program(fun=None, *, static_argnums=(), static_argnames=(), filtered=False):
    """``fun`` as a compiled program kept between processes (module docstring).

    Called inside a trace, or where nothing can be kept, it is ``jax.jit(fun,
    static_argnums, static_argnames)`` (``filtered``: ``equinox.filter_jit(fun)``, every
    argument leaf that is not an array static) and behaves exactly as that. Called
    outside any trace it returns the same values from the same program, exported once
    and, in later processes, loaded instead of traced. Usable as a decorator, with or
    without its keyword arguments."""
    if fun is None:
        return functools.partial(kept_program, static_argnums=static_argnums,
                                 static_argnames=static_argnames, filtered=filtered)
    if isinstance(static_argnums, int):
        static_argnums = (static_argnums,)
    if isinstance(static_argnames, str):
        static_argnames = (static_argnames,)
    return _Kept(fun, tuple(static_argnums), tuple(static_argnames), filtered).wrapper()


@dataclasses.dataclass
class _Entry:
    """A program in memory: the exported call (``None``: run the jitted function)."""

    call: object = None
    out_tree: object = None


class _Commit:
    """Arguments of an exported program, each committed to the device it is on.

    An exported program's outputs are committed to their device (a plain ``jax.jit``'s,
    from uncommitted arguments, are not), and ``jax.jit`` keeps a program apart for
    committed and uncommitted arguments of the same shapes: a program fed both by another
    kept program's outputs and by fresh arrays would be compiled twice (seconds, in a
    first run) and lowered twice in every run. Committing an array to its own device
    moves no data; each uncommitted array is committed once, remembered by identity while
    it lives (a problem's arrays enter every step of a continuation)."""

    def __init__(self):
        self.done: dict = {}  # id -> (weak reference to the array, its committed alias)

    def __call__(self, leaves):
        return [x if x.committed else self.one(x) for x in leaves]

    def one(self, x):
        key = id(x)
        hit = self.done.get(key)
        if hit is not None and hit[0]() is x:
            return hit[1]
        alias = jax.device_put(x, x.sharding)
        self.done[key] = (weakref.ref(x, lambda _, k=key: self.done.pop(k, None)), alias)
        return alias


_commit = _Commit()


class _Kept:
    """The state of one :func:`kept_program`: its jitted form and its programs in memory,
    by argument signature."""

    def __init__(self, fun, static_argnums, static_argnames, filtered):
        self.fun, self.filtered = fun, filtered
        self.static_argnums, self.static_argnames = static_argnums, static_argnames
        self.jitted = eqx.filter_jit(fun) if filtered else jax.jit(
            fun, static_argnums=static_argnums or None, static_argnames=static_argnames or None)
        self.entries: dict = {}
        self.lock = threading.Lock()
        # static by position or by name, either way (as jax.jit resolves them)
        params = list(inspect.signature(fun).parameters)
        self.static_nums = set(static_argnums) | {params.index(n) for n in static_argnames
                                                  if n in params}
        self.static_names = set(static_argnames) | {params[i] for i in static_argnums
                                                    if i < len(params)}

    def wrapper(self):
        @functools.wraps(self.fun)
        def call(*args, **kwargs):
            return self(args, kwargs)

        call.jitted, call.kept, call._cache_size = self.jitted, self, self.cache_size
        call.lower = self.jitted.lower  # ahead-of-time, as jax.jit's: the traced program
        return call

    def cache_size(self) -> int:
        """Programs held in this process: signatures met outside a trace, and the jitted
        function's own (calls in a trace, and those the store does not serve)."""
        size = getattr(self.jitted, "_cache_size", None)
        return len(self.entries) + (size() if size is not None else 0)

    def __call__(self, args, kwargs):
        if jax.config.jax_disable_jit or store_dir() is None:
            return self.jitted(*args, **kwargs)
        try:
            leaves, rebuild, static = self.split(args, kwargs)
            key = (rebuild.tree, static, tuple(_aval(x) for x in leaves))
            hash(key)
        except (TypeError, ValueError):  # unhashable statics, non-array leaves: as jit says
            return self.jitted(*args, **kwargs)
        if any(isinstance(x, jax.core.Tracer) for x in leaves):
            return self.jitted(*args, **kwargs)
        entry = self.entries.get(key)
        if entry is None:
            with self.lock:
                entry = self.entries.get(key)
                if entry is None:
                    entry = self.entries[key] = self.entry(leaves, rebuild, static)
        if entry.call is None:
            return self.jitted(*args, **kwargs)
        return jax.tree_util.tree_unflatten(entry.out_tree, entry.call(*_commit(leaves)))

    def split(self, args, kwargs):
        """``(array leaves, rebuild, static)``: the traced leaves of the arguments, a
        function making the arguments again from such leaves, and what is static."""
        if self.filtered:
            dynamic, static_part = eqx.partition((args, kwargs), eqx.is_array)
            leaves, tree = jax.tree_util.tree_flatten(dynamic)
            s_leaves, s_tree = jax.tree_util.tree_flatten(static_part)
            static = (s_tree, tuple(s_leaves))
            leaves = [_array(x) for x in leaves]

            def rebuild(new):
                return eqx.combine(jax.tree_util.tree_unflatten(tree, new), static_part)
        else:
            names = self.static_names
            fixed = {i for i in self.static_nums if i < len(args)}
            static = (tuple((i, args[i]) for i in sorted(fixed)),
                      tuple(sorted((k, v) for k, v in kwargs.items() if k in names)))
            dynamic = ([None if i in fixed else a for i, a in enumerate(args)],
                       {k: v for k, v in kwargs.items() if k not in names})
            leaves, tree = jax.tree_util.tree_flatten(dynamic)
            leaves = [_array(x) for x in leaves]

            def rebuild(new):
                a, k = jax.tree_util.tree_unflatten(tree, new)
                for i, v in static[0]:
                    a[i] = v
                return tuple(a), {**k, **dict(static[1])}
        rebuild.tree = tree
        return leaves, rebuild, static

    def entry(self, leaves, rebuild, static) -> _Entry:
        """The program for these arguments: loaded from the store, else exported (and
        stored where its key and output tree can be written down); ``_Entry()`` (the
        jitted function) where it cannot be exported."""
        folder = store_dir()
        try:
            digest = self.digest(rebuild.tree, static, leaves)
        except Unstable as e:
            _log.debug("not kept: %s (%s)", _name(self.fun), e)
            return _Entry()
        path = folder / f"{digest}.bin"
        loaded = _load(path)
        if loaded is not None:
            exported, out_tree = loaded
            return _Entry(jax.jit(exported.call), out_tree)
        box = []

        def flat(*new):
            a, k = rebuild(list(new))
            out_leaves, out_tree = jax.tree_util.tree_flatten(self.fun(*a, **k))
            if not all(isinstance(x, jax.core.Tracer) for x in out_leaves):
                # a constant or a Python value out: filter_jit returns it as it is
                raise Unstable("an output that is no traced array")
            box.append(out_tree)
            return out_leaves

        try:
            data = jax.export.export(jax.jit(flat))(*leaves).serialize()
        except Exception as e:  # noqa: BLE001  (host callbacks, non-array outputs: not kept)
            _log.debug("not exported: %s (%s)", _name(self.fun), str(e)[:300])
            return _Entry()
        _save(path, data, box[-1])
        # called as a later process loads it: the same program to compile, and to find in
        # the compilation cache next time
        return _Entry(jax.jit(jax.export.deserialize(bytearray(data)).call), box[-1])

    def digest(self, tree, static, leaves) -> str:
        """The store key (module docstring) of a call; raises :class:`Unstable`."""
        h = hashlib.sha256()
        settings = tuple((k, repr(getattr(jax.config, k, None))) for k in TRACE_SETTINGS)
        for part in (_qualified(self.fun), self.filtered, self.static_argnums,
                     self.static_argnames, _environment(), settings, _canon_tree(tree),
                     _canon(static), tuple(_aval(x) for x in leaves)):
            h.update(repr(part).encode())
            h.update(b"\0")
        return h.hexdigest()


_log = logging.getLogger(__name__)


def _name(fun) -> str:
    return f"{getattr(fun, '__module__', '?')}.{getattr(fun, '__qualname__', '?')}"


def _array(x):
    return x if isinstance(x, jax.Array) else jnp.asarray(x)


def _aval(x) -> tuple:
    return (tuple(x.shape), str(x.dtype), bool(getattr(x, "weak_type", False)))


@functools.cache
def _environment() -> tuple:
    """What every stored program depends on beyond its arguments and JAX's settings:
    gearjax's source, library and Python versions, the platform, ``EQX_ON_ERROR``
    (computed once per process)."""
    root = pathlib.Path(__file__).resolve().parent.parent
    h = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        h.update(str(path.relative_to(root)).encode())
        h.update(path.read_bytes())
    versions = []
    for name in LIBRARIES:
        try:
            versions.append((name, importlib.metadata.version(name)))
        except importlib.metadata.PackageNotFoundError:
            versions.append((name, None))
    return (h.hexdigest(), tuple(versions), sys.version, jax.default_backend(),
            os.environ.get("EQX_ON_ERROR", ""))


def _qualified(obj) -> str:
    """``module.qualname`` of a module-level function or class of gearjax, of a library
    in :data:`LIBRARIES` or of Python's builtins (code the key covers);
    :class:`Unstable` for anything else: a lambda, a closure, a function not found under
    its name, the caller's own code (which may change between runs)."""
    module, name = getattr(obj, "__module__", None), getattr(obj, "__qualname__", None)
    if not module or not name or "<" in name:
        raise Unstable(repr(obj))
    if module.split(".")[0] not in _COVERED:
        raise Unstable(f"{module}.{name}")
    if module == "builtins" and isinstance(obj, type):  # NoneType is no builtins name
        return f"builtins.{name}"
    found = importlib.import_module(module)
    for part in name.split("."):
        found = getattr(found, part, None)
    if found is not obj and getattr(found, "__wrapped__", None) is not obj:
        raise Unstable(repr(obj))
    return f"{module}.{name}"


def _canon_tree(tree) -> tuple:
    """A stable written form of a tree structure: every node's type and static data."""
    data = tree.node_data()
    if data is None:
        return ("*",)
    kind, aux = data
    return (_qualified(kind), _canon(aux), tuple(_canon_tree(c) for c in tree.children()))


def _canon(x):
    """A stable written form of a static value (equal values, equal forms, in every
    process); :class:`Unstable` where there is none."""
    if x is None or isinstance(x, (bool, int, float, complex, str, bytes)):
        return (type(x).__name__, repr(x))
    if x is _missing():
        return ("missing",)
    if isinstance(x, (tuple, list)):
        return (type(x).__name__, tuple(_canon(v) for v in x))
    if isinstance(x, dict):
        return ("dict", tuple((_canon(k), _canon(v)) for k, v in x.items()))
    if isinstance(x, (frozenset, set)):
        return (type(x).__name__, tuple(sorted(repr(_canon(v)) for v in x)))
    if isinstance(x, (np.ndarray, np.generic)):
        a = np.asarray(x)
        if a.dtype == object:
            raise Unstable("object array")
        return ("array", a.dtype.str, a.shape, hashlib.sha256(a.tobytes()).hexdigest())
    if isinstance(x, jax.Array):
        return _canon(np.asarray(x))
    if isinstance(x, enum.Enum):
        return ("enum", _qualified(type(x)), x.name)
    if isinstance(x, type):
        return ("type", _qualified(x))
    if isinstance(x, jax.tree_util.PyTreeDef):
        return ("treedef", _canon_tree(x))
    if isinstance(x, functools.partial):
        return ("partial", _canon(x.func), _canon(x.args), _canon(x.keywords))
    if isinstance(x, (types.FunctionType, types.BuiltinFunctionType)):
        return ("function", _qualified(x))
    if dataclasses.is_dataclass(x):
        return ("dataclass", _qualified(type(x)),
                tuple((f.name, _canon(getattr(x, f.name, None)))
                      for f in dataclasses.fields(x)))
    if isinstance(x, np.dtype):
        return ("dtype", x.str)
    raise Unstable(type(x).__qualname__)


@functools.cache
def _missing():
    """equinox's marker of an absent field (it appears in equinox modules' tree data)."""
    try:
        from equinox._module._flatten import MISSING
    except ImportError:  # another equinox: such trees are not stored
        return object()
    return MISSING


class _Pickler(pickle.Pickler):
    def persistent_id(self, obj):
        return "missing" if obj is _missing() else None


class _Unpickler(pickle.Unpickler):
    def persistent_load(self, pid):
        if pid == "missing":
            return _missing()
        raise pickle.UnpicklingError(pid)


def _tree_bytes(tree) -> bytes | None:
    """The output tree pickled, where it unpickles to an equal tree (else ``None``)."""
    try:
        buf = io.BytesIO()
        _Pickler(buf).dump(tree)
        data = buf.getvalue()
        if _Unpickler(io.BytesIO(data)).load() == tree:
            return data
    except Exception:  # noqa: BLE001  (an unpicklable static value: not stored)
        pass
    return None


def _save(path: pathlib.Path, exported: bytes, out_tree) -> None:
    """Write a program atomically (a rename); nothing where the tree cannot be written
    or the directory cannot be (a read-only cache)."""
    tree = _tree_bytes(out_tree)
    if tree is None:
        _log.debug("not stored (output tree): %s", path.name)
        return
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp")
        with os.fdopen(fd, "wb") as f:
            f.write(MAGIC + struct.pack("<Q", len(tree)) + tree)
            f.write(exported)
        os.replace(tmp, path)
        _prune_once(path.parent)
    except OSError:
        pass


@functools.cache
def _prune_once(folder: pathlib.Path) -> None:
    """Once per process, where the store holds more than :data:`STORE_MAX_BYTES`: remove
    the programs least recently used (modification time; a load renews it) down to
    three quarters of it."""
    files = []
    for f in folder.glob("*.bin"):
        try:
            st = f.stat()
        except OSError:
            continue
        files.append((st.st_mtime, st.st_size, f))
    total = sum(size for _, size, _ in files)
    if total <= STORE_MAX_BYTES:
        return
    for _, size, f in sorted(files, key=lambda t: t[0]):
        if total <= STORE_MAX_BYTES * 3 // 4:
            break
        try:
            f.unlink()
            total -= size
        except OSError:
            pass


def _load(path: pathlib.Path):
    """``(exported, out tree)`` from a stored file, ``None`` where there is none or it
    cannot be read (it is then removed and written again)."""
    try:
        data = path.read_bytes()
        os.utime(path)  # used now: the last to go (:func:`_prune_once`)
    except OSError:
        return None
    try:
        if not data.startswith(MAGIC):
            raise ValueError("not a kept program")
        start = len(MAGIC) + 8
        (n,) = struct.unpack("<Q", data[len(MAGIC):start])
        out_tree = _Unpickler(io.BytesIO(data[start:start + n])).load()
        exported = jax.export.deserialize(bytearray(data[start + n:]))
        return exported, out_tree
    except Exception:  # noqa: BLE001  (truncated, another format: export it again)
        try:
            path.unlink()
        except OSError:
            pass
        return None
