"""One exception family for lidarkit; the CLI catches it once and prints a single line."""

from __future__ import annotations

import os
from typing import Any


class LidarKitError(Exception):
    """Base of every error lidarkit raises on purpose.

    ``source`` names the input (a file, an argument, a method name) and ``location`` where in it
    (``"line 12"``, ``"frame 3"``); ``str(err)`` reads ``source (location): reason``.
    """

    def __init__(self, reason: str, *, source: str | os.PathLike | None = None, location: str | None = None):
        self.reason = reason
        self.source = None if source is None else str(source)
        self.location = location
        super().__init__(self._format())

    def _format(self) -> str:
        where = self.source or ""
        if self.location:
            where = f"{where} ({self.location})" if where else self.location
        return f"{where}: {self.reason}" if where else self.reason


class DataError(LidarKitError):
    """Input data is missing, malformed, truncated, non-finite or inconsistent."""


class ConfigError(LidarKitError):
    """A method name, parameter or configuration value is unknown or invalid."""


class RegistrationError(LidarKitError):
    """A registration could not be computed (too few points or correspondences)."""


class EvaluationError(LidarKitError):
    """Two trajectories cannot be compared as asked (lengths, timestamps, too short for a metric)."""


class OutputError(LidarKitError):
    """A result file or folder cannot be written (a file in the way, read-only, disk full, unknown plot format)."""


def validation_problems(err: Any, unnamed: str = "?") -> str:
    """One line for a pydantic ``ValidationError``: ``"field.path: message; ..."`` (``unnamed`` for a model-level
    problem), for the ConfigError that replaces it."""
    def line(e: dict) -> str:
        message = e["msg"].removeprefix("Value error, ")  # (pydantic's prefix for a validator's own ValueError)
        where = ".".join(map(str, e["loc"])) or unnamed
        return f"{where}: {message}" if where else message

    return "; ".join(line(e) for e in err.errors())


def not_increasing(later: float, earlier: float, of: str = "") -> str:
    """Why a time stamp ``later`` may not follow ``earlier`` (s) of ``of`` (e.g. ``"frame 2"``), both to the microsecond
    (``.9g`` printed every ROS epoch stamp as ``1.7e+09``; float64 holds an epoch stamp to ~0.2 us), saying when they
    are equal (a message logged twice, unset stamps)."""
    def text(t: float) -> str:
        return f"{t:.6f}".rstrip("0").rstrip(".")

    if later == earlier:
        return f"{text(later)} s repeats the stamp of {of}" if of else f"{text(later)} s repeats the previous stamp"
    return f"{text(later)} s after {text(earlier)} s" + (f" of {of}" if of else "")


def index_runs(indices: Any, max_runs: int | None = None) -> str:
    """``0-7`` / ``0, 2, 4-11``: sorted indices (frames, scans) as runs of consecutive ones, for a message; the first
    ``max_runs`` runs only, with ``, ... (N frames)`` after them, when given; ``""`` for none."""
    values = [int(v) for v in indices]
    runs: list[list[int]] = []
    for value in values:
        if runs and value == runs[-1][1] + 1:
            runs[-1][1] = value
        else:
            runs.append([value, value])
    shown = [f"{a}-{b}" if b > a else str(a) for a, b in runs]
    if max_runs is None or len(shown) <= max_runs:
        return ", ".join(shown)
    return ", ".join(shown[:max_runs]) + f", ... ({len(values)} frames)"
