"""Memory estimates checked before a large allocation: a clear ConfigError instead of a MemoryError (or swapping)."""

from __future__ import annotations


from lidarkit.errors import ConfigError


def _system_available_bytes() -> int | None:
    """The machine's free memory (Linux ``MemAvailable``; psutil elsewhere); None if unknown."""
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        import psutil

        return int(psutil.virtual_memory().available)
    except Exception:  # noqa: BLE001 - no estimate is not an error
        return None


def _address_space_left_bytes() -> int | None:
    """What the soft ``RLIMIT_AS`` (``ulimit -v``) leaves: the limit less this process's current ``VmSize`` (the limit
    itself where VmSize cannot be read); None without a limit."""
    try:
        import resource

        soft, _hard = resource.getrlimit(resource.RLIMIT_AS)
    except (ImportError, OSError, ValueError, AttributeError):
        return None
    if soft == resource.RLIM_INFINITY or soft < 0:
        return None
    used = 0
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("VmSize:"):
                    used = int(line.split()[1]) * 1024
                    break
    except (OSError, ValueError, IndexError):
        pass
    return max(int(soft) - used, 0)


CGROUP_ROOT = "/sys/fs/cgroup"  # the process's cgroup v2 files (a container's own limit)


def _cgroup_left_bytes() -> int | None:
    """What the cgroup v2 memory limit leaves (``memory.max`` less ``memory.current``); None without a limit."""
    try:
        with open(f"{CGROUP_ROOT}/memory.max", encoding="ascii") as fh:
            limit = fh.read().strip()
        if limit == "max":
            return None
        with open(f"{CGROUP_ROOT}/memory.current", encoding="ascii") as fh:
            current = int(fh.read().strip())
        return max(int(limit) - current, 0)
    except (OSError, ValueError):
        return None


def available_memory_bytes() -> int | None:
    """Memory this process can still get: the least of the machine's free memory, what ``ulimit -v`` and the cgroup's
    limit leave (a container or a lowered limit failed with numpy's MemoryError though /proc/meminfo showed plenty);
    None if none is known."""
    known = [v for v in (_system_available_bytes(), _address_space_left_bytes(), _cgroup_left_bytes()) if v is not None]
    return min(known) if known else None


def _gib(n: float) -> str:
    return f"{n / 2**30:.3g} GiB" if n >= 2**28 else f"{n / 2**20:.3g} MiB"


def check_memory(needed_bytes: float, what: str, source: str, fraction: float = 0.8) -> None:
    """ConfigError naming ``source`` if ``what`` needs more than ``fraction`` of the available memory."""
    available = available_memory_bytes()
    if available is None or needed_bytes <= fraction * available:
        return
    raise ConfigError(f"{what} needs about {_gib(needed_bytes)} of memory, more than {fraction:.0%} of the "
                      f"{_gib(available)} available", source=source)


__all__ = ["available_memory_bytes", "check_memory"]
