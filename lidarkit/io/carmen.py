"""CARMEN laser logs (``.clf``, plain, ``.bz2`` or ``.gz``) as 2D scan sequences, and ``.relations`` ground truth.

The classic 2D SLAM benchmark logs (Intel Research Lab, ACES, Freiburg 079, ...) are CARMEN logs: one message per
line. The laser messages become scans with ``z = 0``, in the laser frame (x forward, y left):

- ``FLASER n r_1..r_n x y theta odom_x odom_y odom_theta ipc_ts host logger_ts``: the old format carries no
  sensor configuration; CARMEN's own reader assumes the first beam at -90 deg and 1 deg (180/181 beams), 0.5 deg
  (360/361) or 0.25 deg (400/401) between beams, which this reader follows. ``x y theta`` is the laser pose by
  odometry (the robot's odometry with the laser offset applied).
- ``ROBOTLASER1 type start_angle fov resolution max_range accuracy remission_mode n r.. m rem.. laser_x laser_y
  laser_theta robot_x robot_y robot_theta tv rv forward_safety side_safety turn_axis ipc_ts host logger_ts``.
- ``RAWLASER1`` (same configuration fields, no pose): the laser pose is interpolated from the ``ODOM`` messages.

Readings at or above the maximum range (no return) and at or below ``min_range_m`` are dropped. The maximum range
of FLASER logs is not written down and differs per log (ACES saturates at 50 m, Intel and FR079 at ~81.9 m): by
default it is the largest reading of the log, the value the driver writes for "no return"; so is a ROBOTLASER1 or
RAWLASER1 maximum of 0 or less (not stated: taken as it is, it dropped every reading).

Parsing is vectorized: each line is split once, the numbers of all scans are converted by one ``numpy`` call, and
the points of a scan are computed on request from its ranges and precomputed beam directions. Any malformed line
raises :class:`DataError` naming the file and the line.
"""

from __future__ import annotations

import bz2
import gzip
import logging
import lzma
import os
import zlib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np

from lidarkit.errors import ConfigError, DataError
from lidarkit.io.base import Scan, checked_index, option_path
from lidarkit.params import is_real_number
from lidarkit.textfile import read_lines, read_numeric_table
from lidarkit.trajectory import Trajectory, stamp_text

log_ = logging.getLogger(__name__)

LASER_MESSAGES = ("FLASER", "ROBOTLASER1", "RAWLASER1")

#: Least step (s) between the stamps of consecutive scans once made increasing (:func:`_increasing_stamps`).
MIN_STAMP_STEP_S = 1e-4

#: Scans around a stamp whose median is its expected time (:func:`_glitched_stamps`): runs of up to 5 glitches are seen.
STAMP_WINDOW = 11

#: A stamp out of order by more than this many scan periods from the median of the stamps around it is a glitch, not
#: a late delivery: Intel's delivery times stray up to 4.9 periods (0.97 s); an ACES stamp logged as 0.0 strays 600.
GLITCH_PERIODS = 20.0

#: FLASER beam spacing by number of beams (CARMEN's guess for the unconfigured old format); others: 180 deg / (n - 1).
_FLASER_RESOLUTION_RAD = {180: np.pi / 180, 181: np.pi / 180, 360: np.pi / 360, 361: np.pi / 360, 400: np.pi / 720, 401: np.pi / 720}
_FLASER_START_RAD = -np.pi / 2


def _isotonic_stamps(stamps_s: np.ndarray, min_step_s: float) -> np.ndarray:
    """``stamps_s`` made increasing (by at least ``min_step_s``) with the least squared change: the isotonic fit of
    ``t_i - i * min_step_s``, plus ``i * min_step_s``. Stamps that already increase by ``min_step_s`` stay as logged; a
    run that goes back is pooled to the times its neighbours allow, its scans spread ``min_step_s`` apart."""
    if len(stamps_s) < 2 or (np.diff(stamps_s) >= min_step_s).all():
        return stamps_s
    from scipy.optimize import isotonic_regression

    ramp = min_step_s * np.arange(len(stamps_s))
    return isotonic_regression(stamps_s - ramp).x + ramp


def _glitched_stamps(stamps_s: np.ndarray, suspects: np.ndarray) -> tuple[np.ndarray, float]:
    """``(S,)`` bool: the ``suspects`` (stamps out of order) further than :data:`GLITCH_PERIODS` scan periods from the
    median of the :data:`STAMP_WINDOW` stamps around them, and the scan period (s): the median time per scan over
    windows of that many scans, which neither a glitch nor a burst of deliveries moves."""
    n = len(stamps_s)
    width = min(STAMP_WINDOW, n)
    if width < 3 or not suspects.any():
        return np.zeros(n, dtype=bool), 0.0
    period = float(np.median((stamps_s[width - 1 :] - stamps_s[: n - width + 1]) / (width - 1)))
    if not period > 0:  # (stamps that mostly go back have no period to measure a glitch by)
        return np.zeros(n, dtype=bool), 0.0
    local_median = np.median(np.lib.stride_tricks.sliding_window_view(stamps_s, width), axis=1)
    window_of = np.clip(np.arange(n) - width // 2, 0, n - width)  # centred, held inside the log at its ends
    return suspects & (np.abs(stamps_s - local_median[window_of]) > GLITCH_PERIODS * period), period


def _increasing_stamps(stamps_s: np.ndarray, min_step_s: float = MIN_STAMP_STEP_S) -> tuple[np.ndarray, np.ndarray]:
    """``(stamps, glitched)``: ``stamps_s`` made increasing by at least ``min_step_s``, and ``(S,)`` bool the stamps
    found to be glitches. The least-squares fit (:func:`_isotonic_stamps`) suits delivery jitter, but pooled one
    stamp logged as 0.0 with 33 correct ones (27 moved by over 1 s): glitches are first placed between their nearest
    good neighbours by scan index (a scan period apart beyond the log's ends), then the rest is fitted as before."""
    fitted = _isotonic_stamps(stamps_s, min_step_s)
    glitched, period = _glitched_stamps(stamps_s, fitted != stamps_s)
    if not glitched.any():
        return fitted, glitched
    index = np.arange(len(stamps_s))
    good = np.flatnonzero(~glitched)
    if not good.size:  # (no stamp to place them by)
        return fitted, np.zeros_like(glitched)
    repaired = stamps_s.copy()
    repaired[glitched] = np.interp(index[glitched], good, stamps_s[good])
    before, after = glitched & (index < good[0]), glitched & (index > good[-1])
    repaired[before] = stamps_s[good[0]] - (good[0] - index[before]) * period
    repaired[after] = stamps_s[good[-1]] + (index[after] - good[-1]) * period
    return _isotonic_stamps(repaired, min_step_s), glitched


def _open_text(path: Path) -> str:
    """The whole file as text, decompressing ``.bz2`` / ``.gz`` / ``.xz``; unreadable files are DataErrors."""
    if not path.is_file():
        raise DataError("file not found" if not path.exists() else "not a regular file", source=path)
    opener = {".bz2": bz2.open, ".gz": gzip.open, ".xz": lzma.open}.get(path.suffix.lower(), open)
    try:
        with opener(path, "rb") as fh:
            data = fh.read()
    except (OSError, EOFError, lzma.LZMAError, zlib.error) as err:
        raise DataError(f"cannot read ({type(err).__name__}: {err})", source=path) from err
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:  # old logs carry Latin-1 comments: one such byte made the whole log unreadable
        return data.decode("latin-1")  # (never fails; a stray byte in a number is then that line's error)


def yaw_pose_se3(x: np.ndarray, y: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """``(N, 4, 4)`` SE(3) poses of planar poses ``(x, y, theta)`` (m, m, rad), z = 0."""
    c, s = np.cos(theta), np.sin(theta)
    poses = np.zeros((len(x), 4, 4))
    poses[:, 0, 0], poses[:, 0, 1], poses[:, 1, 0], poses[:, 1, 1] = c, -s, s, c
    poses[:, 2, 2] = poses[:, 3, 3] = 1.0
    poses[:, 0, 3], poses[:, 1, 3] = x, y
    return poses


@dataclass(frozen=True)
class Relations:
    """Relative-pose ground truth (Kümmerle et al. 2009): the pose at ``t2_s`` in the frame of the pose at ``t1_s``.

    ``t1_s``, ``t2_s``: ``(K,)`` float64 timestamps (s, the log's clock); ``dx_m``, ``dy_m``, ``dyaw_rad``: ``(K,)``
    the planar relative pose ``inv(T(t1)) @ T(t2)``.
    """

    t1_s: np.ndarray
    t2_s: np.ndarray
    dx_m: np.ndarray
    dy_m: np.ndarray
    dyaw_rad: np.ndarray
    source: str = ""
    scan_gap_s: float | None = None
    """The smallest gap between the stamps of the log's scans, whose stamps the relation times are (s); None: not known
    (a file read on its own). The metric matches poses within half of it, so a scan the estimate skips is not stood in
    for by its neighbour (Intel's scans lie down to 0.1 ms apart)."""

    def __post_init__(self) -> None:
        """Relations built in code are checked as a file's are: (K,) finite numbers of one length (a NaN scored "nan +-
        nan m", lists and unequal lengths failed inside the metric with a TypeError / IndexError)."""
        names = ("t1_s", "t2_s", "dx_m", "dy_m", "dyaw_rad")
        arrays = []
        for name in names:
            try:
                value = np.asarray(getattr(self, name), dtype=np.float64)
            except (TypeError, ValueError):
                raise DataError(f"{name} must be numbers", source=self.source or "relations") from None
            if value.ndim != 1 or not np.isfinite(value).all():
                raise DataError(f"{name} must be a 1-D array of finite numbers", source=self.source or "relations")
            arrays.append(value)
        if len({len(a) for a in arrays}) != 1:
            raise DataError(f"{', '.join(names)} differ in length ({', '.join(str(len(a)) for a in arrays)})",
                            source=self.source or "relations")
        same_time = np.flatnonzero(arrays[0] == arrays[1])
        if len(same_time):  # (as read() refuses it: scored, it was blamed on the estimate)
            raise DataError(f"t1 equals t2 (relation {same_time[0] + 1})", source=self.source or "relations")
        for name, value in zip(names, arrays):
            object.__setattr__(self, name, value)
        gap = self.scan_gap_s
        if gap is not None and not (is_real_number(gap) and np.isfinite(gap) and gap > 0):
            raise DataError(f"scan_gap_s must be a finite number of seconds > 0 or None, got {gap!r}",
                            source=self.source or "relations")
        if gap is not None:
            object.__setattr__(self, "scan_gap_s", float(gap))

    def __len__(self) -> int:
        return int(len(self.t1_s))

    def __repr__(self) -> str:
        """One line (the generated one printed five arrays: ~600 characters)."""
        span = (f", {stamp_text(min(self.t1_s.min(), self.t2_s.min()))}-{stamp_text(max(self.t1_s.max(), self.t2_s.max()))} s"
                if len(self) else "")
        return f"Relations({self.source!r}, {len(self)} relations{span})"

    @classmethod
    def read(cls, path: str | os.PathLike) -> "Relations":
        """Parse a ``.relations`` file: ``t1 t2 x y z roll pitch yaw`` per line (z, roll, pitch must be 0; t1 != t2)."""
        table = read_numeric_table(path, (8,))
        if len(table) == 0:
            raise DataError("no relations in the file", source=path)
        # a row that fails is named by its line, as every other error of the file (the row number misled past comments)
        off_plane = np.flatnonzero(np.abs(table[:, 4:7]).max(axis=1) > 1e-9)
        # t1 == t2 relates a pose to itself: scored, it was blamed on the estimate ("the same estimated pose nearest both")
        same_time = np.flatnonzero(table[:, 0] == table[:, 1])
        for bad, reason in ((off_plane, "z, roll and pitch of a planar relation must be 0"), (same_time, "t1 equals t2")):
            if len(bad):
                rows = [n for n, raw in enumerate(read_lines(path), start=1) if raw.strip() and not raw.strip().startswith("#")]
                raise DataError(f"{reason} (relation {bad[0] + 1})", source=path, location=f"line {rows[bad[0]]}")
        return cls(table[:, 0], table[:, 1], table[:, 2], table[:, 3], table[:, 7], source=str(path))


@dataclass(frozen=True)
class _Parsed:
    message: str
    ranges_m: np.ndarray  # flat (sum n,) float64
    offsets: np.ndarray  # (S + 1,) int64 into ranges_m
    start_rad: np.ndarray  # (S,)
    step_rad: np.ndarray  # (S,)
    max_range_m: np.ndarray  # (S,) the message's own maximum (nan: not stated)
    laser_xyt: np.ndarray  # (S, 3) laser pose by odometry
    timestamps_s: np.ndarray  # (S,) ipc time stamps
    lines: np.ndarray  # (S,) 1-based line numbers
    counts: dict = field(default_factory=dict)


class _LineParser:
    """Collects the fields of one laser message type; numbers stay strings until one vectorized conversion."""

    def __init__(self, path: Path, message: str):
        self.path, self.message = path, message
        self.range_tokens: list[str] = []
        self.fixed_tokens: list[str] = []  # per scan: start, step, max_range, x, y, theta, ts
        self.lengths: list[int] = []
        self.lines: list[int] = []

    def fail(self, lineno: int, reason: str) -> DataError:
        return DataError(f"{self.message}: {reason}", source=self.path, location=f"line {lineno}")

    def _count(self, tokens: list[str], i: int, lineno: int, what: str) -> int:
        try:
            n = int(tokens[i])
        except (IndexError, ValueError):
            raise self.fail(lineno, f"{what} is not an integer ({tokens[i] if i < len(tokens) else 'missing'!r})") from None
        if n < 0:
            raise self.fail(lineno, f"negative {what} {n}")
        return n

    def add(self, tokens: list[str], lineno: int) -> None:
        if self.message == "FLASER":
            n = self._count(tokens, 1, lineno, "number of readings")
            if n == 0:
                raise self.fail(lineno, "0 readings")
            if len(tokens) != n + 11:
                raise self.fail(lineno, f"expected {n + 11} fields for {n} readings, found {len(tokens)}")
            step = _FLASER_RESOLUTION_RAD.get(n, np.pi / max(n - 1, 1))
            self.range_tokens.extend(tokens[2 : 2 + n])
            self.fixed_tokens.extend((repr(_FLASER_START_RAD), repr(step), "nan", *tokens[2 + n : 5 + n], tokens[8 + n]))
        else:
            n = self._count(tokens, 8, lineno, "number of readings")
            m = self._count(tokens, 9 + n, lineno, "number of remissions")
            tail = 14 if self.message == "ROBOTLASER1" else 3  # pose + velocities + safety, then ts host logger_ts
            if len(tokens) != 10 + n + m + tail:
                raise self.fail(lineno, f"expected {10 + n + m + tail} fields for {n} readings, {m} remissions, found {len(tokens)}")
            if n == 0:
                raise self.fail(lineno, "0 readings")
            rest = 10 + n + m
            pose = tokens[rest : rest + 3] if self.message == "ROBOTLASER1" else ["nan"] * 3
            self.range_tokens.extend(tokens[9 : 9 + n])
            self.fixed_tokens.extend((tokens[2], tokens[4], tokens[5], *pose, tokens[-3]))
        self.lengths.append(n)
        self.lines.append(lineno)

    def _to_float(self, tokens: list[str], per_line: list[int]) -> np.ndarray:
        try:
            return np.array(tokens, dtype=np.float64)
        except ValueError:
            pass
        # locate the offending token only on failure: the fast path is one conversion
        start = 0
        for lineno, count in zip(self.lines, per_line):
            for token in tokens[start : start + count]:
                try:
                    float(token)
                except ValueError:
                    raise self.fail(lineno, f"not a number: {token!r}") from None
            start += count
        raise self.fail(self.lines[-1], "not a number")  # unreachable: some token failed above

    def finish(self) -> _Parsed:
        lengths = np.asarray(self.lengths, dtype=np.int64)
        ranges = self._to_float(self.range_tokens, self.lengths)
        fixed = self._to_float(self.fixed_tokens, [7] * len(self.lines)).reshape(-1, 7)
        lines = np.asarray(self.lines, dtype=np.int64)
        offsets = np.concatenate([[0], np.cumsum(lengths)])
        bad_range = ~np.isfinite(ranges)
        if bad_range.any():
            scan = int(np.searchsorted(offsets, int(np.argmax(bad_range)), side="right") - 1)
            raise self.fail(int(lines[scan]), "range reading is NaN or infinite")
        check = fixed[:, [0, 1, 6]] if self.message == "RAWLASER1" else fixed[:, [0, 1, 3, 4, 5, 6]]
        bad = ~np.isfinite(check).all(axis=1)
        if bad.any():
            raise self.fail(int(lines[np.argmax(bad)]), "pose, angle or timestamp is NaN or infinite")
        if (fixed[:, 1] <= 0).any():
            raise self.fail(int(lines[np.argmax(fixed[:, 1] <= 0)]), "angular resolution must be positive")
        return _Parsed(self.message, ranges, offsets, fixed[:, 0], fixed[:, 1], fixed[:, 2], fixed[:, 3:6], fixed[:, 6], lines)


def _parse_odom(path: Path, entries: list[tuple[int, list[str]]]) -> tuple[np.ndarray, np.ndarray]:
    """ODOM messages ``x y theta tv rv accel ts host logger_ts`` -> ``(M, 3)`` poses and ``(M,)`` timestamps."""
    tokens: list[str] = []
    for lineno, parts in entries:
        if len(parts) != 10:
            raise DataError(f"ODOM: expected 10 fields, found {len(parts)}", source=path, location=f"line {lineno}")
        tokens.extend((*parts[1:4], parts[7]))
    try:
        values = np.array(tokens, dtype=np.float64).reshape(-1, 4)
    except ValueError:
        for lineno, parts in entries:
            for token in (*parts[1:4], parts[7]):
                try:
                    float(token)
                except ValueError:
                    raise DataError(f"ODOM: not a number: {token!r}", source=path, location=f"line {lineno}") from None
        raise
    return values[:, :3], values[:, 3]


def _interpolate_pose(odom_xyt: np.ndarray, odom_t: np.ndarray, t: np.ndarray, path: Path) -> np.ndarray:
    """Odometry poses at times ``t`` (linear in x, y and unwrapped theta; clamped at the ends)."""
    if len(odom_t) == 0:
        raise DataError("RAWLASER1 messages carry no pose and the log has no ODOM messages to interpolate", source=path)
    order = np.argsort(odom_t, kind="stable")
    ts, xyt = odom_t[order], odom_xyt[order]
    theta = np.unwrap(xyt[:, 2])
    out = np.column_stack([np.interp(t, ts, xyt[:, 0]), np.interp(t, ts, xyt[:, 1]), np.interp(t, ts, theta)])
    out[:, 2] = np.arctan2(np.sin(out[:, 2]), np.cos(out[:, 2]))
    return out


def parse_log(path: str | os.PathLike, message: str = "auto") -> _Parsed:
    """Parse the laser messages of one CARMEN log (``message``: one of LASER_MESSAGES or ``"auto"``: the first
    of them the log contains)."""
    path = Path(path)
    if message != "auto" and message not in LASER_MESSAGES:
        raise ConfigError(f"unknown laser message {message!r}; known: auto, {', '.join(LASER_MESSAGES)}", source="laser")
    text = _open_text(path)
    groups: dict[str, list[tuple[int, list[str]]]] = {m: [] for m in (*LASER_MESSAGES, "ODOM")}
    counts: dict[str, int] = {}
    for lineno, line in enumerate(text.splitlines(), start=1):
        if not line or line[0] == "#":
            continue
        parts = line.split()
        if not parts:
            continue
        kind = parts[0]
        counts[kind] = counts.get(kind, 0) + 1
        if kind in groups:
            groups[kind].append((lineno, parts))
        elif kind[:1].isdigit() or kind[:1] in "-+.":
            raise DataError(f"line does not start with a message name ({kind!r})", source=path, location=f"line {lineno}")
    if message == "auto":
        message = next((m for m in LASER_MESSAGES if groups[m]), "")
        if not message:
            raise DataError(f"no laser messages ({', '.join(LASER_MESSAGES)}) in the log", source=path)
    elif not groups[message]:
        raise DataError(f"no {message} messages in the log", source=path)
    parser = _LineParser(path, message)
    for lineno, parts in groups[message]:
        parser.add(parts, lineno)
    parsed = parser.finish()
    if message == "RAWLASER1":
        odom_xyt, odom_t = _parse_odom(path, groups["ODOM"])
        parsed.laser_xyt[:] = _interpolate_pose(odom_xyt, odom_t, parsed.timestamps_s, path)
    parsed.counts.update(counts)
    return parsed


def log_name(path: str | os.PathLike) -> str:
    """The log's name without its suffixes: ``aces.v2.clf.bz2`` is ``aces.v2`` (its aces.v2.relations went unfound)."""
    stem = Path(path).name
    for suffix in (".bz2", ".gz", ".xz", ".clf", ".log", ".txt"):
        stem = stem[: -len(suffix)] if stem.lower().endswith(suffix) and len(stem) > len(suffix) else stem
    return stem


def relations_beside(path: str | os.PathLike) -> Path | None:
    """The ``NAME.relations`` file beside the log at ``path`` that ``relations="auto"`` reads, or None: found without
    opening the log (a baseline hashes it with the log's files)."""
    candidate = Path(path).with_name(log_name(path) + ".relations")
    return candidate if candidate.is_file() else None


class CarmenLog:
    """A CARMEN log as a 2D :class:`~lidarkit.io.base.ScanSequence` with the log's odometry and relation ground truth.

    ``open_dataset("carmen", "aces.clf.bz2")``. Options: ``laser`` (which message: ``"auto"``, ``"FLASER"``,
    ``"ROBOTLASER1"``, ``"RAWLASER1"``); ``min_range_m`` (readings at or below are dropped); ``max_range_m``
    (readings at or above are dropped as "no return"; None: the message's own maximum for ROBOTLASER1/RAWLASER1,
    the log's largest reading for FLASER and for a message whose maximum is 0 or less); ``relations`` (a
    ``.relations`` file; ``"auto"``: ``NAME.relations`` beside the log if present; None: none). ``reader_options``
    records them as applied.

    ``odometry``: the laser pose by odometry per scan (a Trajectory with the scan timestamps); ``ground_truth`` is
    None (these logs have relative ground truth only: ``relations``).
    """

    def __init__(
        self,
        path: str | os.PathLike,
        laser: Literal["auto", "FLASER", "ROBOTLASER1", "RAWLASER1"] = "auto",
        min_range_m: float = 0.0,
        max_range_m: float | None = None,
        relations: str | os.PathLike | None = "auto",
    ):
        self.path = Path(path)
        # is_real_number first: True passed np.isfinite as 1 m, text raised a TypeError
        if not (is_real_number(min_range_m) and np.isfinite(min_range_m) and min_range_m >= 0):
            raise ConfigError(f"min_range_m must be a finite number >= 0, got {min_range_m!r}", source="carmen dataset options")
        if max_range_m is not None and not (is_real_number(max_range_m) and np.isfinite(max_range_m) and max_range_m > min_range_m):
            raise ConfigError(f"max_range_m must be a finite number above min_range_m ({min_range_m}), got {max_range_m!r}",
                              source="carmen dataset options")
        self._log = parse_log(self.path, laser)
        self.name = log_name(self.path)
        self.laser = self._log.message
        self.min_range_m = float(min_range_m)
        log = self._log
        largest = float(log.ranges_m.max())
        if max_range_m is not None:
            self.max_range_m = np.full(len(log.timestamps_s), float(max_range_m))
        elif self.laser == "FLASER":
            self.max_range_m = np.full(len(log.timestamps_s), largest)
        else:  # a maximum of 0 (or less) is not stated: as FLASER's (it dropped every reading: "empty scan (0 points)")
            self.max_range_m = np.where(log.max_range_m > 0, log.max_range_m, largest)
        self._max_range_given = max_range_m
        # scans in file order, the order their poses follow: Intel's stamps are delivery times that go back up to 0.9 s
        # at 631 lines (sorted by them, the robot jumped back and forth: 94 odometry steps > 0.3 m in 18 ms, none in
        # file order); stamps that do are made increasing with the least change, a glitch (a stamp far from all around
        # it) first put between its neighbours (see _increasing_stamps)
        raw = log.timestamps_s
        seen = np.argsort(raw, kind="stable")
        same = np.flatnonzero(np.diff(raw[seen]) == 0)
        if same.size:
            first, second = sorted((int(seen[same[0]]), int(seen[same[0] + 1])))
            raise DataError(
                f"two laser scans with the same timestamp {stamp_text(raw[second])} s (also line {int(log.lines[first])})",
                source=self.path, location=f"line {int(log.lines[second])}",
            )
        self._timestamps_s, glitched = _increasing_stamps(raw)
        restamped = self._timestamps_s != raw
        self.n_restamped = int(restamped.sum())
        """Scans whose logged stamp went back (or less than 0.1 ms forward) and was moved (0 on most logs)."""
        self.n_stamp_glitches = int(glitched.sum())
        """Of those, stamps out of order by far more than a late delivery (:data:`GLITCH_PERIODS` scan periods), each
        placed between its neighbours by scan index instead of pulling them along (0 on the real logs)."""
        self.max_restamp_s = float(np.abs(self._timestamps_s - raw).max()) if len(raw) else 0.0
        if self.n_restamped:
            glitches = (f" ({self.n_stamp_glitches} far from the stamps around them, at lines "
                        f"{', '.join(str(int(n)) for n in log.lines[glitched][:5])}{', ...' if self.n_stamp_glitches > 5 else ''}: "
                        "placed between their neighbours)" if self.n_stamp_glitches else "")
            log_.warning("%s: %d scan stamps go back in file order (delivery times): scans kept in file order, %d stamps "
                         "moved by up to %.3f s to increase%s", self.path.name, int((np.diff(raw) <= 0).sum()), self.n_restamped,
                         self.max_restamp_s, glitches)
        self._starts = log.offsets[:-1]
        self._lengths = np.diff(log.offsets)
        self._relations_path = self._find_relations(relations)
        # read and checked now: a bad file found after a whole run's registration failed it, with nothing written
        self._logged_relations = None if self._relations_path is None else Relations.read(self._relations_path)
        self._relations: Relations | None = None
        self._odometry: Trajectory | None = None

    def _find_relations(self, relations: str | os.PathLike | None) -> Path | None:
        if relations is None or (isinstance(relations, str) and relations.lower() == "none"):  # ("?relations=none")
            return None
        if isinstance(relations, str) and relations == "auto":
            return relations_beside(self.path)
        path = option_path(relations, self.path.parent)  # (beside the log too, as the other readers' path options)
        if path.is_dir():  # (read "not found")
            raise DataError("a folder, not a relations file", source=path)
        if not path.is_file():
            raise DataError("relations file not found (neither from the working directory nor beside the log)", source=path)
        return path

    @property
    def reader_options(self) -> dict[str, Any]:
        """The options as applied, for the run config (max_range_m=30 gave the config.yaml of a run without), and the
        stamps moved to increase as a correction (an Intel run said "reader corrections: none"). The maximum range says
        the value taken for messages that state none (a ROBOTLASER1 log stating 0 was recorded as "the message's own")."""
        unstated = len(self) if self.laser == "FLASER" else int((~(self._log.max_range_m > 0)).sum())
        largest = f"the log's largest reading ({float(self._log.ranges_m.max()):g} m)"
        stated = (largest if unstated == len(self) else f"the message's own; {largest} for the {unstated} messages stating 0"
                  if unstated else "the message's own")
        options: dict[str, Any] = {
            "kind": "carmen", "path": str(self.path.absolute()), "laser": self.laser, "min_range_m": self.min_range_m,
            "max_range_m": stated if self._max_range_given is None else float(self._max_range_given),
            "relations": None if self._relations_path is None else str(self._relations_path.absolute()),
        }
        if self.n_restamped:
            glitches = (f"; {self.n_stamp_glitches} of them far from the stamps around them, placed between their neighbours"
                        if self.n_stamp_glitches else "")
            options["stamps_corrected"] = (f"{self.n_restamped} scan stamps moved by up to {self.max_restamp_s:.3f} s to increase "
                                           f"(they go back in file order{glitches})")
        return options

    # ---- ScanSequence ------------------------------------------------------------------------
    def __len__(self) -> int:
        return int(len(self._timestamps_s))

    def __repr__(self) -> str:
        return f"CarmenLog({str(self.path)!r}, {len(self)} scans)"

    @property
    def timestamps_s(self) -> np.ndarray:
        """``(S,)`` float64 ipc time stamps of the scans (s) in file order, strictly increasing (``n_restamped`` of them
        moved to be so)."""
        return self._timestamps_s

    @property
    def ground_truth(self) -> Trajectory | None:
        """None: the CARMEN logs have relation ground truth (``relations``), not absolute poses."""
        return None

    @property
    def odometry(self) -> Trajectory:
        """The laser pose by odometry at each scan (``T_odom_laser``, z = 0), timestamps = scan timestamps."""
        if self._odometry is None:
            xyt = self._log.laser_xyt
            self._odometry = Trajectory(
                yaw_pose_se3(xyt[:, 0], xyt[:, 1], xyt[:, 2]), self.timestamps_s, name=f"{self.name} odometry",
                meta={"frame": "laser", "source": "log odometry"},
            )
        return self._odometry.copy()  # (one shared Trajectory: a caller moving its poses in place moved everyone's)

    @property
    def relations(self) -> Relations | None:
        """The relation ground truth (``.relations`` file), or None if there is none. Its times are the log's, as
        logged; on a log whose stamps were moved to increase (Intel) each is moved with the scan logged at it, so that
        it finds that scan's pose (matched by the logged times, 428 of 2000 found none and others the wrong scan). They
        carry the smallest gap between the scans' stamps (``scan_gap_s``), which the metric's time tolerance stays under."""
        if self._relations is None and self._logged_relations is not None:
            gaps = np.diff(self._timestamps_s)  # (strictly increasing)
            on_clock = self._on_own_clock(self._logged_relations)
            self._relations = replace(on_clock, scan_gap_s=float(gaps.min()) if gaps.size else None)
        return self._relations

    def _on_own_clock(self, relations: Relations) -> Relations:
        """``relations`` with every time that is a scan's logged stamp moved as that scan's stamp was."""
        if not self.n_restamped:
            return relations
        import dataclasses

        logged = self._log.timestamps_s
        order = np.argsort(logged, kind="stable")
        shift = (self._timestamps_s - logged)[order]

        def moved(times: np.ndarray) -> np.ndarray:
            at = np.clip(np.searchsorted(logged[order], times), 1, len(order) - 1)
            at = np.where(np.abs(logged[order][at - 1] - times) <= np.abs(logged[order][at] - times), at - 1, at)
            near = np.abs(logged[order][at] - times) <= MIN_STAMP_STEP_S  # a scan's own stamp (to 0.1 ms)
            return np.where(near, times + shift[at], times)

        return dataclasses.replace(relations, t1_s=moved(relations.t1_s), t2_s=moved(relations.t2_s))

    def ranges_m(self, index: int) -> np.ndarray:
        """All range readings of scan ``index`` as logged ``(n,)`` (nothing dropped)."""
        index = checked_index(index, len(self), self.path)
        start = int(self._starts[index])
        return self._log.ranges_m[start : start + int(self._lengths[index])]

    def beam_angles_rad(self, index: int) -> np.ndarray:
        """Bearing of every beam of scan ``index`` in the laser frame ``(n,)`` (0 = forward, counter-clockwise)."""
        index = checked_index(index, len(self), self.path)
        return self._log.start_rad[index] + self._log.step_rad[index] * np.arange(int(self._lengths[index]))

    def line_of(self, index: int) -> int:
        """The 1-based line of the log that holds scan ``index``."""
        return int(self._log.lines[checked_index(index, len(self), self.path)])

    def read_scan(self, index: int) -> Scan:
        """Scan ``index`` as ``(N, 3)`` points in the laser frame, z = 0, invalid readings dropped."""
        index = checked_index(index, len(self), self.path)
        ranges = self.ranges_m(index)
        keep = ranges > self.min_range_m
        max_range = self.max_range_m[index]
        if np.isfinite(max_range):
            keep &= ranges < max_range
        bearing = self.beam_angles_rad(index)[keep]
        r = ranges[keep]
        points = np.zeros((len(r), 3))
        points[:, 0], points[:, 1] = r * np.cos(bearing), r * np.sin(bearing)
        return Scan(points, timestamp_s=float(self.timestamps_s[index]), frame=index, source=f"{self.path}:{self.line_of(index)}")

    @property
    def message_counts(self) -> dict[str, int]:
        """How many messages of each kind the log holds (``{"FLASER": 7374, "ODOM": 7375, ...}``)."""
        return dict(self._log.counts)


__all__ = ["LASER_MESSAGES", "CarmenLog", "Relations", "parse_log", "yaw_pose_se3"]
