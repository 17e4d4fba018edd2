"""Compiled programs kept whole between processes: :func:`persistent_jit`.

JAX's persistent compilation cache keeps compiled programs, but a new process traces
and lowers each function again before it can look its program up (for a large program,
most of a second). :func:`persistent_jit` keeps the lowered program itself
(``jax.export``) for the arguments a function was called with, beside that cache, so a
later process calls it without tracing; the compilation cache then serves its compiled
form.

A kept program is used only where everything that could make it differ is the same:
the versions of JAX, jaxlib and the libraries traced into it (equinox, lineax,
optimistix, diffrax, NumPy), the content of every gearjax source file, the JAX options
that change lowering, the backend, the function, the tree structure and every static
value of its arguments (pickled: by content, never by ``repr``), and the shape and type
of every array. Where one of these cannot be stated (a static value that would pickle
by reference to code outside those libraries, such as a user's function, or not at all,
such as a lambda), where an argument is traced (the call is inside another
transformation), where the program cannot be exported, or where the compilation cache
is off, the function runs jitted as usual: the same results either way.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.metadata
import io
import os
import pathlib
import pickle
import tempfile
import threading
import types
from collections.abc import Callable

import equinox as eqx
import jax

from .. import _config

LIBRARIES = ("jax", "jaxlib", "equinox", "lineax", "optimistix", "diffrax", "numpy")
"""Distributions whose versions are part of every key (their code is traced into the
programs)."""

MAX_BYTES = 512 * 1024**2
"""Size of the kept programs above which the least recently used are removed."""

_OPTIONS = ("jax_enable_x64", "jax_default_matmul_precision", "jax_numpy_dtype_promotion",
            "jax_numpy_rank_promotion", "jax_debug_nans", "jax_debug_infs")
"""JAX options that change what a function lowers to."""

_CODE_ROOTS = frozenset({"gearjax", "jax", "jaxlib", "equinox", "lineax", "optimistix",
                         "diffrax", "numpy", "builtins", "jaxtyping", "typing",
                         "collections", "functools", "operator", "math"})
"""Packages whose functions and classes may appear in a key by name: their code is
covered by the versions and the source digest."""


class _Unkeyable(Exception):
    """A value that cannot be part of a key by content."""


class _KeyPickler(pickle.Pickler):
    """Pickles a key's values; refuses code that would pickle by a name whose content
    the key does not cover."""

    def reducer_override(self, obj):
        if isinstance(obj, (types.FunctionType, types.BuiltinFunctionType, types.MethodType,
                            type)):
            module = (getattr(obj, "__module__", None) or "").split(".")[0]
            name = getattr(obj, "__qualname__", "")
            if module not in _CODE_ROOTS or "<lambda>" in name or "<locals>" in name:
                raise _Unkeyable(f"{module}.{name}")
        return NotImplemented


def _dumps(value) -> bytes:
    buffer = io.BytesIO()
    try:
        _KeyPickler(buffer, protocol=pickle.HIGHEST_PROTOCOL).dump(value)
    except _Unkeyable:
        raise
    except Exception as error:  # unpicklable
        raise _Unkeyable(repr(error)) from error
    return buffer.getvalue()


@functools.cache
def _sources_digest() -> bytes:
    """Digest of every gearjax source file, and of the libraries' versions."""
    h = hashlib.sha256()
    for name in LIBRARIES:
        h.update(f"{name}={importlib.metadata.version(name)}\n".encode())
    root = pathlib.Path(__file__).resolve().parents[1]
    for path in sorted(root.rglob("*.py")):
        h.update(path.relative_to(root).as_posix().encode() + b"\0" + path.read_bytes())
    return h.digest()


def _options() -> tuple:
    return tuple(getattr(jax.config, name, None) for name in _OPTIONS)


def directory() -> pathlib.Path | None:
    """Where the programs are kept: beside the compilation cache gearjax sets up
    (``.../gearjax/exported``); ``None`` where it is off or JAX's own setting is kept."""
    path = _config.cache_dir()
    return None if path is None else pathlib.Path(path).parent / "exported"


class persistent_jit:  # noqa: N801  (used as a decorator, like jax.jit)
    """``jax.jit(fn, static_argnums=...)`` whose programs are kept between processes
    (module docstring); with ``filter``, ``equinox.filter_jit(fn)`` instead (every leaf
    of the arguments that is not an array is static). Called as ``fn``; ``jit``: the
    plain jitted function."""

    def __init__(self, fn: Callable, static_argnums: tuple[int, ...] = (),
                 filter: bool = False):
        self.fn = fn
        self.static_argnums = tuple(static_argnums)
        self.filter = filter
        self.jit = (eqx.filter_jit(fn) if filter
                    else jax.jit(fn, static_argnums=static_argnums))
        self._calls: dict = {}
        self._lock = threading.Lock()
        functools.update_wrapper(self, fn)

    def __call__(self, *args):
        statics = tuple(args[i] for i in self.static_argnums)
        dynamic = [a for i, a in enumerate(args) if i not in self.static_argnums]
        leaves, tree = jax.tree.flatten(dynamic)
        if any(isinstance(x, jax.core.Tracer) for x in leaves) or directory() is None:
            return self.jit(*args)
        # per leaf: (True, None) for an array, (False, value) for a static one
        held = tuple((True, None) if not self.filter or eqx.is_array(x) else (False, x)
                     for x in leaves)
        leaves = [x if isinstance(x, jax.Array) else jax.numpy.asarray(x)
                  for x, (array, _) in zip(leaves, held) if array]
        avals = tuple((x.shape, x.dtype, x.weak_type) for x in leaves)
        key = (len(args), tree, held, statics, avals, _options())
        try:
            call = self._calls.get(key)
        except TypeError:  # an unhashable static value
            return self.jit(*args)
        if call is None:
            with self._lock:
                call = self._calls.get(key)
                if call is None:
                    call = self._calls[key] = self._program(len(args), tree, held, statics,
                                                            leaves, avals)
        if call is False:
            return self.jit(*args)
        out_tree, run = call
        return jax.tree.unflatten(out_tree, run(*leaves))

    def lower(self, *args):
        """The plain jitted function's lowering (``jax.stages.Lowered``) for ``args``."""
        return self.jit.lower(*args)

    def cache_size(self) -> int:
        """Programs this function holds in this process: kept ones and plain jitted ones."""
        own = sum(call is not False for call in self._calls.values())
        return own + (0 if self.filter else self.jit._cache_size())

    def _program(self, n, tree, held, statics, leaves, avals):
        """``(out_tree, callable on the leaves)`` from the kept program, or exported and
        kept now; ``False`` where the call cannot be kept (module docstring)."""
        module = getattr(self.fn, "__module__", None) or ""
        name = getattr(self.fn, "__qualname__", "")
        if module.split(".")[0] not in _CODE_ROOTS or "<" in name:
            return False  # its code is not covered by the key
        try:
            head = _dumps((module, name, n, self.static_argnums, self.filter, tree, held,
                           statics, avals, _options()))
        except _Unkeyable:
            return False
        h = hashlib.sha256(_sources_digest())
        h.update(jax.default_backend().encode() + b"\0" + head)
        path = directory() / f"{getattr(self.fn, '__name__', 'fn')}-{h.hexdigest()[:40]}.bin"
        kept = _load(path)
        if kept is not None:
            return kept
        box = {}

        def flat(*xs):
            arrays = iter(xs)
            xs = [next(arrays) if array else value for array, value in held]
            dyn = iter(jax.tree.unflatten(tree, xs))
            full = [statics[self.static_argnums.index(i)] if i in self.static_argnums
                    else next(dyn) for i in range(n)]
            out, box["tree"] = jax.tree.flatten(self.fn(*full))
            return out

        try:
            exported = jax.export.export(jax.jit(flat))(*leaves)
            blob = pickle.dumps({"program": bytes(exported.serialize()),
                                 "skeleton": _dumps(_skeleton(box["tree"]))})
        except Exception:  # not exportable (a host callback, an unkeyable output)
            return False
        _store(path, blob)
        return box["tree"], jax.jit(exported.call)


class _Leaf:
    """Where an array goes in a kept program's output (:func:`_skeleton`)."""


def _skeleton(tree):
    """The output of structure ``tree`` with a :class:`_Leaf` for each array: pickled by
    value, it gives the structure back in a later process (a tree structure itself does
    not survive pickling: equinox's holds sentinels compared by identity)."""
    return jax.tree.unflatten(tree, [_Leaf() for _ in range(tree.num_leaves)])


def _load(path: pathlib.Path):
    """A kept program ``(out_tree, callable)``, or None (absent or unreadable)."""
    try:
        data = pickle.loads(path.read_bytes())
        exported = jax.export.deserialize(bytearray(data["program"]))
        out_tree = jax.tree.structure(pickle.loads(data["skeleton"]),
                                      is_leaf=lambda x: isinstance(x, _Leaf))
        os.utime(path)  # recently used
    except Exception:
        return None
    return out_tree, jax.jit(exported.call)


def _store(path: pathlib.Path, blob: bytes) -> None:
    """Write ``blob`` to ``path`` atomically, then keep the directory under
    :data:`MAX_BYTES` (least recently used first); a directory that cannot be written
    keeps nothing."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path.parent, delete=False, suffix=".tmp") as f:
            f.write(blob)
        os.replace(f.name, path)
        files = sorted(path.parent.glob("*.bin"), key=lambda p: p.stat().st_mtime)
        total = sum(p.stat().st_size for p in files)
        for old in files:
            if total <= MAX_BYTES or old == path:
                break
            total -= old.stat().st_size
            old.unlink(missing_ok=True)
    except OSError:
        return
