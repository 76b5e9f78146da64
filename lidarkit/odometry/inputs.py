"""Inputs of an odometry run: dataset specs and frame selections."""

from __future__ import annotations

import os
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from lidarkit.errors import ConfigError, DataError
from lidarkit.io.base import ScanSequence
from lidarkit.params import is_integer

FrameSelection = slice | range | Sequence[int] | np.ndarray | str | None


def open_sequence(spec: str | os.PathLike | ScanSequence) -> ScanSequence:
    """A scan sequence from a spec, or the sequence itself.

    Specs: ``sim:SCENE?key=value&...`` (the simulator, see :func:`lidarkit.sim.lidar.open_sim`);
    ``KIND:PATH[?key=value&...]`` with KIND a :func:`lidarkit.io.available_datasets` reader
    (e.g. ``kitti:/data/kitti?sequence=05``); a plain folder path: a KITTI sequence / odometry root when it
    holds ``velodyne/`` or ``sequences/``, a ROS bag / MCAP / Ouster pcap by :func:`lidarkit.io.detect_kind`,
    otherwise a folder of scan files.
    """
    if not isinstance(spec, (str, os.PathLike)):
        # (looked up on the class: isinstance with the protocol reads every property, a bag's whole ground truth
        # included, and a ground-truth problem then refused the object before --frames could select around it)
        if all(callable(getattr(type(spec), name, None)) for name in ("read_scan", "__len__")):
            return spec
        raise ConfigError(f"expected a ScanSequence or a dataset spec, got {type(spec).__name__}", source="dataset")
    from lidarkit import io as lio
    from lidarkit.io.pointfile import POINT_FILE_SUFFIXES

    text = os.fspath(spec)
    if text.startswith("sim:"):
        from lidarkit.sim.lidar import open_sim

        return open_sim(text)
    kind, sep, rest = text.partition(":")
    if sep and kind in lio.available_datasets() and len(kind) > 1:
        path, query = _path_and_options(rest)
        if not path.strip():  # ("" reached the reader, which read the current folder)
            raise ConfigError(f"{kind}: with no path (expected {kind}:PATH[?key=value&...])", source=text)
        path = os.path.expanduser(path)  # the shell leaves ~ after "kind:" as it is
        from lidarkit.params import parse_kv

        options = parse_kv(query, option=f"{kind} dataset option", as_text=lio.text_options(kind))
        return _scans(lio.open_dataset(kind, path, **options), text)
    path = Path(os.path.expanduser(text))
    if not path.exists():
        if sep and len(kind) > 1 and "/" not in kind and "\\" not in kind:  # KIND:PATH with a kind no reader has
            raise ConfigError(f"unknown dataset kind {kind!r}; known: sim, {', '.join(lio.available_datasets())}", source=text)
        bare, _, query = text.partition("?")
        if query and Path(os.path.expanduser(bare)).exists():  # options on a path whose kind was to be detected
            found = Path(os.path.expanduser(bare))
            detected = lio.detect_kind(found) or ("folder" if found.is_dir() else "KIND")
            raise ConfigError(f"options need the dataset kind before the path: {detected}:{bare}?{query}", source=text)
        from lidarkit.atomic import missing_reason

        raise DataError(missing_reason(text, f"dataset not found (a folder, {lio.detected_files()}, KIND:PATH or sim:SCENE?...)"),
                        source=text)
    kind = lio.detect_kind(path)
    problem = lio.ros2_storage_problem(path) if kind is None else None
    if problem:
        raise DataError(problem, source=text)
    if kind is None and path.is_file() and path.suffix.lower() in POINT_FILE_SUFFIXES:  # (told to name its kind: carmen)
        raise DataError(f"a single scan file: odometry needs a sequence of scans, e.g. the folder holding it "
                        f"(folder:{path.parent})", source=text)
    if kind is None and path.is_file():  # (a CARMEN log named x.log read "not a folder")
        raise DataError(f"a file of no kind detected by its name ({lio.detected_files()}): give its kind, KIND:PATH "
                        f"(e.g. carmen:{text} for a CARMEN log; known: {', '.join(lio.available_datasets())})", source=text)
    return _scans(lio.open_dataset(kind or "folder", path), text)


def _path_and_options(rest: str) -> tuple[str, str]:
    """PATH and options of the ``PATH?key=value&...`` after ``KIND:``, cut at the last '?' that leaves an existing path
    before it (a bag named ``q?x.bag`` was cut at its own '?', ``x.bag`` refused as an option), else at the first."""
    marks = [i for i, char in enumerate(rest) if char == "?"]
    for cut in [len(rest), *reversed(marks)]:
        if os.path.exists(os.path.expanduser(rest[:cut])):
            return rest[:cut], rest[cut + 1:]
    path, _, query = rest.partition("?")
    return path, query


def _scans(dataset: Any, spec: str) -> Any:
    """``dataset`` when it is a sequence of scans; a ConfigError for readers of other data (TUM images, landmarks)."""
    if not callable(getattr(dataset, "read_scan", None)):
        raise ConfigError(f"a {type(dataset).__name__} holds no LiDAR scans: odometry needs a scan sequence", source=spec)
    return dataset


def frames_past_the_end(frames: FrameSelection, n_frames: int) -> str | None:
    """What a slice ``frames`` asks for beyond the last (or, counted from the end, before the first) of ``n_frames``
    frames (it is cut there), or None."""
    if isinstance(frames, str) and frames.count(":") in (1, 2):
        try:
            frames = slice(*(int(p) if p.strip() else None for p in frames.split(":")))
        except ValueError:
            return None
    if not isinstance(frames, slice):
        return None
    cuts = []  # both ends said when both are cut (-9:50 of 5 frames named the end only)
    if frames.start is not None and frames.start < -n_frames:
        cuts.append(f"start {-frames.start} frames from the end, before the first of {n_frames}: ran from it")
    if frames.stop is not None and frames.stop > n_frames:
        cuts.append(f"end after the last frame ({n_frames - 1}): ran up to it")
    return f"frames {frames_repr(frames, np.arange(0))} {'; and '.join(cuts)}" if cuts else None


def frame_numbers(sequence: Any) -> np.ndarray | None:
    """``(N,)`` int64 the recording's own number of every scan, or None: a reader's ``scan_frames`` (KITTI's file
    names), else the last number in each file name of a folder reader's ``scan_paths`` when they increase in its order
    (a plain folder of KITTI files 94, 95, 198, 199 ran without a gap warning)."""
    numbers = getattr(sequence, "scan_frames", None)
    if numbers is None and getattr(sequence, "scan_paths", None) is not None:
        found = [re.findall(r"\d+", Path(p).stem) for p in sequence.scan_paths]
        numbers = [int(f[-1]) for f in found] if found and all(found) else None
    if numbers is None or len(numbers) != len(sequence):
        return None
    numbers = np.asarray(numbers, dtype=np.int64)
    return numbers if (np.diff(numbers) > 0).all() else None


def typical_interval(values: np.ndarray | None) -> float | None:
    """The median step between consecutive entries of a whole dataset's stamps or frame numbers (None: fewer than 2)."""
    return float(np.median(np.diff(np.asarray(values, dtype=np.float64)))) if values is not None and len(values) > 1 else None


#: consecutive scans more than this many expected intervals apart are a gap
GAP_SWEEPS = 3.0
#: an interval within this fraction of GAP_SWEEPS intervals is not more than it: float stamps carry rounding noise
GAP_RELATIVE_TOLERANCE = 1e-6


def time_gap_warning(times_s: np.ndarray | None, frames: np.ndarray, guess: str = "constant velocity",
                     indices: np.ndarray | None = None, typical: float | None = None) -> str | None:
    """A warning when consecutive scans of a run lie far apart in time (more than 3x the expected interval: scans
    missing from a recording, a folder of non-consecutive scans, a selection that skips frames), or None. ``frames``:
    their numbers, as the warning names them; ``guess``: what the run starts a frame after a gap from,
    ``"constant velocity"`` (the motion before the gap at its rate over the gap), ``"odometry"`` (the dataset's own) or
    ``"one sweep"`` (a variant whose own prediction does not know the gap: one sweep's motion). Without stamps the jumps in ``frames`` are the gaps (KITTI scans 94, 95, 198, 199).
    The expected interval is ``typical`` (the dataset's own, :func:`typical_interval`; 1 frame without stamps, else
    the median of the run's) times the smallest step of the selected dataset ``indices``, so that a stepped selection
    is no gap (the median of the run's own two intervals hid frames 0, 1, 9)."""
    values = np.asarray(frames if times_s is None else times_s, dtype=np.float64)
    dt = np.diff(values)
    unit, what = ("frames", "in the frame numbers (no time stamps)") if times_s is None else ("s", "in time")
    if typical is None:
        if times_s is not None and len(values) < 3:
            return None
        typical = 1.0 if times_s is None else float(np.median(dt))
    step = int(np.diff(indices).min()) if indices is not None and len(indices) > 1 else 1
    expected = typical * step
    # (stamps of exactly three sweeps, 0.30000000000000004 s against 3 x 0.09999999999999998, were flagged by float noise)
    limit = GAP_SWEEPS * expected * (1.0 + GAP_RELATIVE_TOLERANCE)
    gaps = np.flatnonzero(dt > limit) if expected > 0 else np.zeros(0, dtype=np.int64)
    if not gaps.size:
        return None
    k = int(gaps[np.argmax(dt[gaps])])
    return (f"{gaps.size} gap(s) {what} between consecutive scans, the largest {dt[k]:.3g} {unit} between frames {int(frames[k])} "
            f"and {int(frames[k + 1])} (expected interval {expected:.3g} {unit}): "
            + _GAP_GUESS[guess])


#: What a gap warning says of the guess across the gap, by the run's kind of guess.
_GAP_GUESS = {
    "constant velocity": "the guess across them is the motion before at constant velocity; the scans on either side overlap less",
    "odometry": "the dataset's odometry gives the guess across them; the scans on either side overlap less",
    "one sweep": "odometry takes the motion between consecutive scans as small (one sweep's motion as the guess across them)",
}


def parse_frames(frames: FrameSelection, n_frames: int) -> np.ndarray:
    """Dataset indices selected by ``frames``: None (all), a slice/range, an index list or ``"a:b[:step]"``; a slice
    reaching past the end is cut there (:func:`frames_past_the_end` says so)."""
    if frames is None:
        return np.arange(n_frames)
    if isinstance(frames, str):
        parts = frames.split(":")
        if len(parts) not in (2, 3):
            raise ConfigError("expected START:STOP or START:STOP:STEP (each may be empty)", source=f"frames {frames!r}")
        try:
            frames = slice(*(int(p) if p.strip() else None for p in parts))
        except ValueError:
            raise ConfigError("frame bounds must be integers", source=f"frames {frames!r}") from None
    if isinstance(frames, slice):
        if not all(v is None or is_integer(v) for v in (frames.start, frames.stop, frames.step)):
            # (slice(0.5, 3) raised a bare TypeError from numpy; True read as 1)
            raise ConfigError("frame bounds must be integers", source=f"frames {frames_repr(frames, np.arange(0))!r}")
        if frames.step == 0:
            raise ConfigError("the step of a frame slice must not be zero", source=f"frames {frames_repr(frames, np.arange(0))!r}")
        if frames.step is not None and frames.step < 0:
            raise ConfigError("reversed frame selection (negative step): odometry runs forward in time; use a "
                              "positive step", source=f"frames {frames_repr(frames, np.arange(0))!r}")
        return np.arange(n_frames)[frames]
    idx = np.asarray(list(frames) if isinstance(frames, range) else frames)
    if idx.ndim != 1 or (idx.size and not np.issubdtype(idx.dtype, np.integer)):
        raise ConfigError("frame indices must be a 1-D list of integers", source="frames")
    idx = idx.astype(np.int64)
    if idx.size and (idx.min() < 0 or idx.max() >= n_frames):
        raise ConfigError(f"frame indices must lie in 0..{n_frames - 1}", source="frames")
    if idx.size > 1 and not (np.diff(idx) > 0).all():
        raise ConfigError("frame indices must be strictly increasing", source="frames")
    return idx


def frames_repr(frames: FrameSelection, indices: np.ndarray) -> Any:
    if frames is None:
        return "all"
    if isinstance(frames, str):
        return frames
    if isinstance(frames, slice):
        return f"{'' if frames.start is None else frames.start}:{'' if frames.stop is None else frames.stop}" + (
            "" if frames.step is None else f":{frames.step}"
        )
    return [int(i) for i in indices]


class ReusedBufferCheck:
    """Refuses a reader that fills one array for every scan: the runner reads ahead and keeps the previous scan as
    the next one's target, so each read overwrote scans still in use (a scan registered against itself: zero motion,
    a frame check that passes). Keeps the last ``depth`` scans' arrays with a sample of their values; a new scan's
    array sharing memory with one of them whose values changed is the reuse (the same unchanged array is harmless)."""

    def __init__(self, depth: int):
        from collections import deque

        self._recent: deque = deque(maxlen=depth)  # (frame, arrays, their sampled values)

    @staticmethod
    def _sample(array: np.ndarray) -> np.ndarray:
        return np.array(array[:: max(1, len(array) // 32)])

    def check(self, frame: int, arrays: Sequence[np.ndarray | None], source: str) -> None:
        """DataError when one of ``arrays`` (frame ``frame``'s points, per-point times) overwrote an earlier scan's."""
        new = [a for a in arrays if a is not None]
        for earlier, olds, samples in self._recent:
            for old, sample in zip(olds, samples):
                if any(np.may_share_memory(a, old) for a in new) and not np.array_equal(self._sample(old), sample, equal_nan=True):
                    raise DataError(f"read_scan returned frame {frame} in the array it returned for frame {earlier}, which now "
                                    "holds the new scan: each scan must be an array of its own (a reader that fills one buffer "
                                    "must return a copy of it)", source=source, location=f"frame {frame}")
        self._recent.append((frame, new, [self._sample(a) for a in new]))
