"""What this process may use: the memory a solve is judged against (the size rules of
:mod:`gearjax._studies.harmonics`), read from the system at each call."""

from __future__ import annotations

import os

import jax

CGROUP_ROOT = "/sys/fs/cgroup"
"""Where the kernel mounts the control groups (v2: one tree; v1: ``memory/`` beside)."""

_UNLIMITED = 2**60
"""A cgroup v1 limit at or above this is the kernel's "no limit" (about 2**63)."""


def _read_int(path: str) -> int | None:
    try:
        with open(path) as f:
            text = f.read().strip()
    except OSError:
        return None
    try:
        return int(text)
    except ValueError:  # "max": no limit (cgroup v2)
        return None


def cgroup_memory(root: str = CGROUP_ROOT, membership: str = "/proc/self/cgroup") -> int | None:
    """Bytes the process's control group may still take (its memory limit less its
    usage; v2 ``memory.max - memory.current``, v1 ``memory.limit_in_bytes -
    memory.usage_in_bytes``); ``None`` where no limit is set or none can be read."""
    v2_path = v1_path = ""
    try:
        with open(membership) as f:
            for line in f:
                hierarchy, controllers, path = line.rstrip("\n").split(":", 2)
                if hierarchy == "0" and not controllers:
                    v2_path = path
                elif "memory" in controllers.split(","):
                    v1_path = path
    except (OSError, ValueError):
        pass
    candidates = []
    for base in dict.fromkeys([os.path.join(root, v2_path.lstrip("/")), root]):
        candidates.append((os.path.join(base, "memory.max"),
                           os.path.join(base, "memory.current")))
    for base in dict.fromkeys([os.path.join(root, "memory", v1_path.lstrip("/")),
                               os.path.join(root, "memory")]):
        candidates.append((os.path.join(base, "memory.limit_in_bytes"),
                           os.path.join(base, "memory.usage_in_bytes")))
    for limit_file, usage_file in candidates:
        limit = _read_int(limit_file)
        if limit is None or limit >= _UNLIMITED:
            continue
        return max(limit - (_read_int(usage_file) or 0), 0)
    return None


def address_space_memory(status: str = "/proc/self/status") -> int | None:
    """Bytes of address space the process may still map under its ``RLIMIT_AS`` (the
    soft limit less ``VmSize``); ``None`` where no limit is set."""
    try:
        import resource
    except ImportError:  # not POSIX
        return None
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft == resource.RLIM_INFINITY:
        return None
    used = 0
    try:
        with open(status) as f:
            for line in f:
                if line.startswith("VmSize:"):
                    used = int(line.split()[1]) * 1024
    except (OSError, ValueError):
        pass
    return max(soft - used, 0)


def host_memory() -> int:
    """Bytes of host memory this process may take: the smallest of the host's
    available memory (``MemAvailable``, else its physical memory), what its control
    group's limit leaves (:func:`cgroup_memory`) and what its address-space limit
    leaves (:func:`address_space_memory`)."""
    host = None
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    host = int(line.split()[1]) * 1024
    except OSError:
        pass
    if host is None:
        host = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    limits = [m for m in (cgroup_memory(), address_space_memory()) if m is not None]
    return min([host, *limits])


def available_memory() -> int:
    """Bytes of memory available to a solve: the accelerator's free memory, else
    :func:`host_memory`."""
    dev = jax.devices()[0]
    if dev.platform != "cpu":
        stats = dev.memory_stats() or {}
        if "bytes_limit" in stats:
            return int(stats["bytes_limit"] - stats.get("bytes_in_use", 0))
    return host_memory()
