"""What every dataset reader returns: scan sequences and image sequences share a small interface."""

from __future__ import annotations

import logging
import math
import os
from dataclasses import dataclass
from collections.abc import Iterable
from pathlib import Path
from typing import Any, Literal, Protocol, runtime_checkable

import numpy as np

from lidarkit.errors import DataError
from lidarkit.params import is_integer
from lidarkit.textfile import file_line
from lidarkit.trajectory import READ_WARNINGS, Trajectory, check_seconds

log = logging.getLogger(__name__)


#: How ``Scan.point_times_s`` is expressed: seconds from the sweep start (KITTI-layout ``point_times``, the
#: simulator, ROS ``time``/``t`` fields relative to the message stamp), absolute seconds on the clock of
#: ``timestamp_s``, or the fraction of the sweep in [0, 1] (kiss-icp's Ouster, MulRan, Newer College loaders).
PointTimeConvention = Literal["relative_s", "absolute_s", "fraction"]
POINT_TIME_CONVENTIONS = ("relative_s", "absolute_s", "fraction")
#: The instant of a sweep a time stamp or a pose refers to; None where a reader cannot tell.
PoseInstant = Literal["start", "mid", "end"]
POSE_INSTANTS = ("start", "mid", "end")
INSTANT_FRACTION = {"start": 0.0, "mid": 0.5, "end": 1.0}


def classify_instant(fraction: float, tol: float = 0.05) -> str | None:
    """``"start"`` / ``"mid"`` / ``"end"`` for a position ``fraction`` within the sweep (0 start, 1 end), None otherwise."""
    for name, value in INSTANT_FRACTION.items():
        if abs(fraction - value) <= tol:
            return name
    return None


#: how far (a fraction of the stamps' spacing) the points' span may be from it for sweeps to follow one another
FULL_SWEEP_TOLERANCE = 0.1


def sweep_length(span_s: float, spacing_s: float, step_s: float = 0.0) -> float:
    """How long a sweep whose points span ``span_s`` lasts when sweeps are stamped ``spacing_s`` apart: the spacing
    when the span, or the span and one firing step ``step_s`` where the firings are known (the last column fires a
    step before the next sweep's first: 8 columns span 7/8 of the turn), is within :data:`FULL_SWEEP_TOLERANCE` of it
    (sweeps follow one another, one ending where the next starts), else the span, first to last point, which kiss
    deskews over (every other sweep of a recording kept: 0.1 s of points stamped 0.2 s apart; a sensor seeing part of
    its turn); 0 when the spacing is (stamps all equal: the sweeps cannot be placed)."""
    if not spacing_s > 0 or min(abs(span_s - spacing_s), abs(span_s + step_s - spacing_s)) <= FULL_SWEEP_TOLERANCE * spacing_s:
        return spacing_s
    return span_s


def keep_once(kept: list[str], said: Iterable[str]) -> None:
    """Append to ``kept`` (a reader's ``reader_warnings``) what ``said`` holds that it does not yet, in order, once:
    a file's reading warned of it (a last line cut inside its number) and the run folder is to record it."""
    kept.extend(w for w in dict.fromkeys(said) if w not in kept)


def read_warnings_of(reader: Any, ground_truth: Any) -> list[str]:
    """What a dataset's reading warned of, once each: its reader's ``reader_warnings``, then its ground truth's
    ``meta["read_warnings"]`` (a pose file cut inside its last number), for a run's ``warnings``."""
    truth = (getattr(ground_truth, "meta", None) or {}).get(READ_WARNINGS, ()) if ground_truth is not None else ()
    return [str(w) for w in dict.fromkeys([*(getattr(reader, "reader_warnings", None) or ()), *truth])]


#: seconds since 1970 of nanosecond stamps are above this (after 1973); below, the file's unit is microseconds
NANOSECOND_EPOCH_AFTER_S = 1e8
#: frames of a dataset (scans, images) are at least this far apart; stamps read as nanoseconds closer are microseconds
MIN_FRAME_SPACING_S = 1e-3


def stamps_in_seconds(stamps: np.ndarray, path: str | os.PathLike) -> np.ndarray:
    """A file's ``(N,)`` time stamps as ``(N,) float64`` seconds: above :data:`~lidarkit.io.pointcloud2.NANOSECONDS_AFTER`
    they are nanoseconds (EuRoC's data.csv, a bag's export), converted with a logged warning, unless the seconds they
    give are before 1973 or frames under 1 ms apart: microseconds (1.7e15), a DataError naming the file and unit, as is
    a stamp still beyond :data:`~lidarkit.trajectory.MAX_STAMP_S` (milliseconds), as lidarkit eval refuses it (a run
    wrote 1.6e18 "s" to its poses_tum.txt)."""
    from lidarkit.io.pointcloud2 import NANOSECONDS_AFTER  # (pointcloud2 imports this module through pointfile)

    stamps_s = np.asarray(stamps, dtype=np.float64)
    if len(stamps_s) and float(np.abs(stamps_s).max()) > NANOSECONDS_AFTER:
        as_ns = stamps_s * 1e-9
        spacing_s = float(np.median(np.abs(np.diff(as_ns)))) if len(as_ns) > 1 else math.inf
        if float(np.abs(as_ns).max()) < NANOSECOND_EPOCH_AFTER_S or 0 < spacing_s < MIN_FRAME_SPACING_S:
            spacing = f", frames {spacing_s * 1e3:.3g} ms apart" if math.isfinite(spacing_s) else ""
            raise DataError(f"time stamp {stamps_s[0]:.0f} read as nanoseconds is {as_ns[0]:.6g} s after 1970{spacing}: "
                            "microseconds? write seconds, e.g. divide by 1e6", source=path,
                            location=file_line(path, "frame 0"))
        stamps_s = as_ns
        log.warning("%s: time stamps above %.0e read as nanoseconds (the first is %.6f s)", path, NANOSECONDS_AFTER,
                    stamps_s[0])
    check_seconds(stamps_s, path, nanoseconds_from=NANOSECONDS_AFTER)
    return stamps_s


def option_path(given: str | os.PathLike, *folders: Path) -> Path:
    """A reader's path option as given or, when it is relative and not found from the working directory, in the first
    of the dataset's ``folders`` that holds it (``poses=poses.txt`` beside the scans); as given when none does."""
    path = Path(given)
    if path.is_absolute() or path.exists():
        return path
    return next((folder / path for folder in folders if (folder / path).exists()), path)


def checked_index(index: object, n: int, source: object, what: str = "scan", *, from_end: bool = True) -> int:
    """The position ``index`` names among a reader's ``n`` scans or images (counted from the end when negative, as a
    list does, where ``from_end``); DataError naming ``source`` otherwise: a float (2.7 read item 2 without a word, or
    raised numpy's IndexError), a bool or an index out of range."""
    if not is_integer(index):
        raise DataError(f"{what} index {index!r} is not an integer", source=source)
    if not (-n if from_end else 0) <= index < n:
        raise DataError(f"{what} index {index} out of range for {n} {what}s", source=source)
    return int(index) % n


def checked_indices(indices: object, n: int, source: object, what: str = "scan", *, from_end: bool = True) -> np.ndarray:
    """``(k,) int64`` positions, each checked by :func:`checked_index` (a list of them: 1.5 picked item 1, 99 raised
    numpy's IndexError); DataError for none (numpy's "zero-size array" ValueError)."""
    values = np.asarray(indices).ravel().tolist()
    if not values:
        raise DataError(f"no {what}s selected", source=source)
    return np.array([checked_index(value, n, source, what, from_end=from_end) for value in values], dtype=np.int64)


@dataclass(frozen=True)
class Scan:
    """One LiDAR sweep.

    ``points_xyz``: ``(N, 3)`` float64 in the sensor frame; ``intensity``: ``(N,)`` or None;
    ``point_times_s``: ``(N,)`` per-point times in ``point_time_convention`` (None if unknown);
    ``timestamp_s``: the sweep's time stamp, referring to ``stamp_instant`` of the sweep (None: the reader
    cannot tell); ``frame``: its index in the sequence.

    Deskewing variants only use the order and spacing of the per-point times (kiss-icp normalizes them to
    [0, 1] and deskews to the latest point, the sweep END), so every convention works for them; the
    convention and instant matter when scoring against ground truth (see :mod:`lidarkit.odometry.instants`).
    """

    points_xyz: np.ndarray
    intensity: np.ndarray | None = None
    point_times_s: np.ndarray | None = None
    timestamp_s: float | None = None
    frame: int = 0
    source: str = ""
    point_time_convention: PointTimeConvention = "relative_s"
    stamp_instant: PoseInstant | None = None

    def __repr__(self) -> str:
        """One line (the generated one printed every point array)."""
        n = len(self.points_xyz)
        t = self.point_times_s
        times = "no point times"
        if t is not None:
            unit = "" if self.point_time_convention == "fraction" else " s"
            span = ""
            if len(t):
                first, last = float(np.min(t)), float(np.max(t))
                # (6 digits printed both ends of a sweep at 1.7e9 s as 1.7e+09)
                absolute = self.point_time_convention == "absolute_s"
                span = f" {first:.6f} s + {last - first:.6g} s" if absolute else f" {first:.6g}-{last:.6g}{unit}"
            times = f"point times {self.point_time_convention}{span}"
        stamp = "no stamp" if self.timestamp_s is None else f"stamp {self.timestamp_s:.6f} s"
        if self.stamp_instant is not None:
            stamp += f" at the sweep {self.stamp_instant}"
        source = f", {self.source!r}" if self.source else ""
        return f"Scan(frame {self.frame}, {n} points, {times}, {stamp}{source})"

    def point_fractions(self) -> np.ndarray | None:
        """Per-point position within the sweep in [0, 1] (first point 0, last point 1), whatever the convention."""
        if self.point_times_s is None or len(self.point_times_s) == 0:
            return None
        t = np.asarray(self.point_times_s, dtype=np.float64)
        lo, hi = float(t.min()), float(t.max())
        return np.zeros_like(t) if hi <= lo else (t - lo) / (hi - lo)

    def has_time_span(self) -> bool:
        """Whether the per-point times span part of a sweep (the points were measured while the sensor moved)."""
        times = self.point_times_s
        return times is not None and len(times) > 1 and float(np.ptp(times)) > 0.0


@runtime_checkable
class ScanSequence(Protocol):
    """A sequence of LiDAR scans; ``ground_truth`` is in the LiDAR frame (or None).

    Readers that know which instant of each sweep their ground truth refers to say so in
    ``ground_truth.meta["pose_instant"]`` (``"start"``, ``"mid"`` or ``"end"``); a reader that can give other
    instants offers ``ground_truth_at_instant(instant)``, one pose per frame as ``ground_truth``, or a LidarKitError
    saying why not (the simulator, bags, KITTI-layout folders the simulator wrote). A reader that leaves out part of
    what it was given (files, scans) may say so in ``reader_warnings`` (a list of one-line messages), which the
    odometry runner records among the run's warnings. Each ``read_scan`` returns arrays of its own: the runner reads
    ahead and keeps the previous scan, and refuses a reader that fills one buffer for every scan.
    """

    name: str

    def __len__(self) -> int: ...

    def read_scan(self, index: int) -> Scan: ...

    @property
    def timestamps_s(self) -> np.ndarray | None: ...

    @property
    def ground_truth(self) -> Trajectory | None: ...


@runtime_checkable
class ImageSequence(Protocol):
    """A sequence of grayscale images with intrinsics; ``ground_truth`` is in the camera frame (or None)."""

    name: str

    def __len__(self) -> int: ...

    def read_image(self, index: int) -> np.ndarray: ...

    @property
    def K(self) -> np.ndarray | None: ...

    @property
    def timestamps_s(self) -> np.ndarray | None: ...

    @property
    def ground_truth(self) -> Trajectory | None: ...
