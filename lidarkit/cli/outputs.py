"""Where a command prints its results when one of its outputs is standard output itself."""

from __future__ import annotations

import os
from pathlib import Path

from rich.console import Console

from lidarkit.cli.app import stderr, stdout


def names_stdout(path: Path | None) -> bool:
    """Whether the output ``path`` is this process's standard output (``/dev/stdout``, ``/dev/fd/1``: the file or pipe
    of fd 1), the null device aside."""
    if path is None:
        return False
    try:
        target, out = os.stat(path), os.fstat(1)
        return (target.st_dev, target.st_ino) == (out.st_dev, out.st_ino) and not os.path.samefile(path, os.devnull)
    except (OSError, ValueError):
        return False


def results_console(outputs: list[Path | None]) -> Console:
    """stdout for the results table and ``wrote`` lines; stderr when an output is written to stdout
    (``--json /dev/stdout | jq``: the table printed after the JSON made it unreadable). Chosen before the outputs are
    written: a file renamed over is no longer fd 1's."""
    return stderr() if any(names_stdout(path) for path in outputs) else stdout()
