"""Set when gearjax is imported: float64 (tight Newton tolerances stall in float32), and
JAX's persistent compilation cache, so that a second run reuses the programs the first
one compiled. :func:`quiet_jax_logs`, for the command line only, keeps JAX's and XLA's
log messages off stderr.

The cache lives in ``$XDG_CACHE_HOME/gearjax/jax`` (``~/.cache/gearjax/jax`` by
default), never inside the package or the working directory, and holds at most
``CACHE_MAX_BYTES`` (least recently used entries go first). ``GEARJAX_CACHE_DIR=DIR``
moves it; ``GEARJAX_CACHE_DIR=0`` (or empty) switches it off; a cache directory set
through JAX itself (``JAX_COMPILATION_CACHE_DIR`` or ``jax.config``) is left as it is.
"""

import os

import jax

jax.config.update("jax_enable_x64", True)

CACHE_ENV = "GEARJAX_CACHE_DIR"
CACHE_MAX_BYTES = 2 * 1024**3


def cache_dir() -> str | None:
    """The compilation cache directory gearjax sets up (``None``: switched off, or JAX's
    own setting is kept). The answer does not change once :func:`_enable_cache` has
    given the directory to JAX: a JAX setting equal to the default directory is
    gearjax's own, not the user's."""
    value = os.environ.get(CACHE_ENV)
    if value is not None:
        return None if value.strip() in ("", "0") else os.path.expanduser(value)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    default = os.path.join(base, "gearjax", "jax")
    own = jax.config.jax_compilation_cache_dir
    return None if own and own != default else default


def _enable_cache() -> None:
    path = cache_dir()
    if path is None:
        return
    try:
        os.makedirs(path, exist_ok=True)
    except OSError:  # a read-only home: run without the cache
        return
    jax.config.update("jax_compilation_cache_dir", path)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_compilation_cache_max_size", CACHE_MAX_BYTES)


_enable_cache()


QUIET_LEVEL = "CRITICAL"
"""JAX's logging level on the command line: its Python loggers and XLA's C++ log keep
only fatal messages."""


def quiet_jax_logs() -> bool:
    """Keep JAX's and XLA's log messages off stderr for the rest of the process: JAX's own
    setting ``jax_logging_level`` to :data:`QUIET_LEVEL`, which sets its Python loggers
    (``jax``, ``jaxlib``) and the threshold of XLA's C++ log (the ``E1205 ...
    slow_operation_alarm ... Constant folding`` lines of a long compilation; at run time,
    so it works after jaxlib is loaded, where ``TF_CPP_MIN_LOG_LEVEL`` is read only when it
    loads). The console script calls it (``gearjax._cli.console``) unless
    ``GEARJAX_DEBUG=1``; importing gearjax never does, so a library user's logging is
    theirs. A ``JAX_LOGGING_LEVEL`` the user set is kept.

    **Returns:** whether it changed the level (``False``: ``JAX_LOGGING_LEVEL`` is set)."""
    if os.environ.get("JAX_LOGGING_LEVEL"):
        return False
    jax.config.update("jax_logging_level", QUIET_LEVEL)
    return True


def require_x64() -> None:
    """Refuse to solve in float32 (someone switched x64 off after importing gearjax)."""
    if not jax.config.jax_enable_x64:
        raise RuntimeError(
            "gearjax needs float64: jax_enable_x64 was turned off after importing gearjax; "
            "call jax.config.update('jax_enable_x64', True)"
        )
