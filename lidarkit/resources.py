"""Memory estimates checked before a large allocation: a clear ConfigError instead of a MemoryError (or swapping)."""

from __future__ import annotations


from lidarkit.errors import ConfigError


def available_memory_bytes() -> int | None:
    """Memory this process can still get (Linux ``MemAvailable``; psutil elsewhere); None if unknown."""
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
