"""Where a benchmark ran: CPU, cores, load and package versions, recorded beside every result."""

from __future__ import annotations

import datetime as dt
import os
import platform
from importlib import metadata
from pathlib import Path

PACKAGES = ("numpy", "scipy", "open3d", "kiss-icp", "small_gicp", "opencv-contrib-python-headless", "evo")


def cpu_model() -> str:
    """The CPU's model name from /proc/cpuinfo (the platform's processor string elsewhere)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def machine_info(packages: tuple[str, ...] = PACKAGES) -> dict:
    """JSON-safe description of this machine now: date, CPU, cores, load average (1, 5, 15 min), versions."""
    versions = {}
    for name in packages:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            continue
    return {
        "date_utc": dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "host": platform.node(),
        "cpu_model": cpu_model(),
        "cores": os.cpu_count(),
        "load_average": list(os.getloadavg()) if hasattr(os, "getloadavg") else None,
        "python": platform.python_version(),
        "platform": platform.platform(),
        "packages": versions,
    }


def describe_machine(info: dict) -> str:
    """One line for a benchmark's Markdown: CPU, cores, load average at the time, Python and package versions."""
    load = info.get("load_average")
    load_text = f"load average {load[0]:.1f}" if load else "load average unknown"
    versions = ", ".join(f"{k} {v}" for k, v in info.get("packages", {}).items())
    return (
        f"{info.get('cpu_model', '?')}, {info.get('cores', '?')} cores (shared machine, {load_text}), "
        f"Python {info.get('python', '?')}" + (f"; {versions}" if versions else "")
    )
