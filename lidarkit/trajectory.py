"""The Trajectory type every lidarkit module produces, with KITTI/TUM I/O and evo conversion."""

from __future__ import annotations

import copy
import inspect
import logging
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from lidarkit import atomic
from lidarkit.errors import ConfigError, DataError
from lidarkit.geometry import ORTHONORMAL_TOL, is_rotation, orthonormalize_se3, se3_inverse
from lidarkit.params import is_real_number
from lidarkit.textfile import data_line_numbers, file_line, read_numeric_table

log = logging.getLogger(__name__)

FORMATS = ("kitti", "tum")
#: ``Trajectory.meta`` key of what a file's reader warned of (list of str), e.g. TUM poses left out for a repeated stamp
READ_WARNINGS = "read_warnings"


def default_format_hint(fmt: str) -> str:
    """How to read a file as ``fmt`` with eval's option and the library (a reader's message for a file in the other
    format); a caller whose users choose the format otherwise passes its own (e.g. a dataset's ``poses_format=``)."""
    return f"--format {fmt}, Trajectory.from_{fmt}"


def _check_rigid(poses: np.ndarray, source: str, item: str) -> None:
    """DataError naming the first of ``(N, 4, 4)`` matrices that is no rigid transform (``item`` k: a pose's frame, a
    motion): a non-finite value, a last row other than [0, 0, 0, 1], a rotation not orthonormal or a reflection."""
    if not np.isfinite(poses).all():
        frame = int(np.argmax(~np.isfinite(poses).all(axis=(1, 2))))
        raise DataError("pose is NaN or infinite", source=source, location=f"{item} {frame}")
    if len(poses) and not np.allclose(poses[:, 3, :], [0.0, 0.0, 0.0, 1.0]):
        frame = int(np.argmax(~np.isclose(poses[:, 3, :], [0.0, 0.0, 0.0, 1.0]).all(axis=1)))
        raise DataError("last row of the pose is not [0, 0, 0, 1]", source=source, location=f"{item} {frame}")
    R = poses[:, :3, :3]
    err = np.abs(np.swapaxes(R, 1, 2) @ R - np.eye(3)).max(axis=(1, 2)) if len(poses) else np.zeros(0)
    det = np.linalg.det(R) if len(poses) else np.zeros(0)
    bad = np.flatnonzero((err > ORTHONORMAL_TOL) | (det <= 0)) if len(poses) else []
    if len(bad):
        k = int(bad[0])
        if err[k] <= ORTHONORMAL_TOL:
            reason = f"rotation is a reflection (det R = {det[k]:.3g}, a proper rotation has det R = +1)"
        else:
            reason = (f"rotation is not orthonormal (max |R^T R - I| = {err[k]:.2e}); "
                      "if it is a file's rounding, write more digits (or, in Python, lidarkit.geometry.orthonormalize_se3 "
                      "the poses before making the Trajectory)")
        raise DataError(reason, source=source, location=f"{item} {k}")


#: the largest time stamp a file may hold in seconds (1e11 s after 1970 is the year 5138): larger ones are nanoseconds or
#: another unit read as seconds (a EuRoC file's 1.4e18 put every segment in "0-5 m/s" and associated 0.01 ns apart)
MAX_STAMP_S = 1e11


def stamp_text(seconds: float) -> str:
    """A time stamp (s) for a message: the shortest decimal that reads back as the same float64, cut at the nanosecond
    (``.9f`` printed 1700000000.05 as 1700000000.049999952, digits float64 does not hold; ``.6f`` printed two stamps
    0.3 us apart as one). Pose files keep their own fixed digits (:meth:`Trajectory.to_tum`)."""
    return np.format_float_positional(float(seconds), unique=True, precision=9, trim="-")


def check_seconds(stamps: np.ndarray, path: str | os.PathLike, *, nanoseconds_from: float | None = None) -> None:
    """DataError naming the first of a file's ``(N,)`` stamps beyond :data:`MAX_STAMP_S`: no time in seconds.
    ``nanoseconds_from``: the reader took stamps above it as nanoseconds, so the ones left are named milliseconds."""
    beyond = np.abs(stamps) > MAX_STAMP_S
    if beyond.any():
        k = int(np.argmax(beyond))
        stamp = float(stamps[k])  # (as the file wrote it: 1403715524907143168, not the shortest repr ...143200)
        text = f"{stamp:.0f}" if stamp.is_integer() else np.format_float_positional(stamp, trim="-")
        unit = ("they look like nanoseconds (or micro/milliseconds): write seconds, e.g. divide by 1e9" if nanoseconds_from is None
                else f"milliseconds? (stamps above {nanoseconds_from:.0e} are read as nanoseconds): write seconds, e.g. "
                     "divide by 1e3")
        raise DataError(f"time stamp {text} is beyond {MAX_STAMP_S:.0e} s (after the year 5000): {unit}", source=path,
                        location=file_line(path, f"frame {k}"))


def _rigid_argument(T: np.ndarray, name: str) -> np.ndarray:
    """``T`` (an argument such as ``T_left``) as a float64 4x4 rigid transform, else a ConfigError naming it (a scaled
    or NaN one was blamed on the trajectory's frame 0, with advice about a file's rounding)."""
    if np.shape(T) != (4, 4):  # (numpy's matmul or broadcast error for a 3x3)
        raise ConfigError(f"{name} must be a 4x4 transform, got shape {np.shape(T)}", source=name)
    try:
        T = np.asarray(T, dtype=np.float64)
    except (TypeError, ValueError):
        raise ConfigError(f"{name} must be a 4x4 array of numbers", source=name) from None
    if not np.isfinite(T).all():
        why = "it has NaN or infinite entries"
    elif not np.allclose(T[3], [0.0, 0.0, 0.0, 1.0]):
        why = f"its last row is {T[3].tolist()}, not [0, 0, 0, 1]"
    elif not is_rotation(T[:3, :3]):
        why = f"its 3x3 block is no rotation (R^T R = I within {ORTHONORMAL_TOL:g}, det R > 0; a scale is not rigid)"
    else:
        return T
    raise ConfigError(f"{name} is not a rigid transform: {why}", source=name)


@dataclass(frozen=True, eq=False)
class Trajectory:
    """A sequence of poses ``T_world_body`` with optional timestamps.

    ``poses_se3``: ``(N, 4, 4)`` float64; ``timestamps_s``: ``(N,)`` float64, strictly increasing, or None.
    """

    poses_se3: np.ndarray
    timestamps_s: np.ndarray | None = None
    name: str = ""
    meta: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        source = self.name or "trajectory"
        try:
            poses = np.array(self.poses_se3, dtype=np.float64)
        except (TypeError, ValueError):  # (numpy's "could not convert string to float")
            raise DataError(f"poses must be numbers, an (N, 4, 4) array, got {type(self.poses_se3).__name__}", source=source) from None
        if poses.ndim != 3 or poses.shape[1:] != (4, 4):
            raise DataError(f"poses must have shape (N, 4, 4), got {poses.shape}", source=source)
        _check_rigid(poses, source, "frame")
        object.__setattr__(self, "poses_se3", poses)
        if self.timestamps_s is not None:
            try:
                ts = np.array(self.timestamps_s, dtype=np.float64).reshape(-1)
            except (TypeError, ValueError):
                raise DataError("timestamps must be numbers (seconds)", source=source) from None
            if ts.shape[0] != poses.shape[0]:
                raise DataError(f"{ts.shape[0]} timestamps for {poses.shape[0]} poses", source=source)
            if not np.isfinite(ts).all():
                raise DataError("timestamp is NaN or infinite", source=source)
            if len(ts) > 1 and not (np.diff(ts) > 0).all():
                frame = int(np.argmax(~(np.diff(ts) > 0))) + 1
                raise DataError("timestamps are not strictly increasing", source=source, location=f"frame {frame}")
            object.__setattr__(self, "timestamps_s", ts)

    # ---- basic views -------------------------------------------------------------------------
    def __len__(self) -> int:
        return int(self.poses_se3.shape[0])

    def __repr__(self) -> str:
        """One line (the generated one printed every pose: 7,200 characters for 20)."""
        t = self.timestamps_s
        # (TUM epoch stamps read "1.30503e+09-1.30503e+09 s": the span hidden)
        stamps = "no stamps" if t is None or not len(self) else f"{stamp_text(t[0])}-{stamp_text(t[-1])} s ({t[-1] - t[0]:.4g} s)"
        return f"Trajectory({self.name!r}, {len(self)} poses, {stamps}, path {self.length_m:.4g} m)"

    def __getitem__(self, index: slice | np.ndarray | list[int]) -> Trajectory:
        """Sub-trajectory by slice or index array (an int index is not supported: use ``poses_se3[i]``)."""
        if isinstance(index, (int, np.integer)):
            raise TypeError("index a Trajectory with a slice or an index array; use poses_se3[i] for one pose")
        ts = None if self.timestamps_s is None else self.timestamps_s[index]
        return Trajectory(self.poses_se3[index], ts, self.name, dict(self.meta))

    @property
    def positions_xyz(self) -> np.ndarray:
        """``(N, 3)`` positions."""
        return self.poses_se3[:, :3, 3].copy()

    @property
    def rotations(self) -> np.ndarray:
        """``(N, 3, 3)`` rotation matrices."""
        return self.poses_se3[:, :3, :3].copy()

    @property
    def distances_m(self) -> np.ndarray:
        """``(N,)`` cumulative path length from the first pose."""
        steps = np.linalg.norm(np.diff(self.poses_se3[:, :3, 3], axis=0), axis=1)
        return np.concatenate([[0.0], np.cumsum(steps)])[: len(self)]  # (none for no pose)

    @property
    def length_m(self) -> float:
        """Total path length."""
        return float(self.distances_m[-1]) if len(self) else 0.0

    def with_name(self, name: str) -> Trajectory:
        return Trajectory(self.poses_se3, self.timestamps_s, name, dict(self.meta))

    def with_timestamps(self, timestamps_s: np.ndarray | None) -> Trajectory:
        return Trajectory(self.poses_se3, timestamps_s, self.name, dict(self.meta))

    # ---- frame changes ---------------------------------------------------------------------------
    def transformed(self, T_left: np.ndarray | None = None, T_right: np.ndarray | None = None) -> Trajectory:
        """New trajectory with poses ``T_left @ P_i @ T_right``.

        E.g. KITTI camera-frame poses to the LiDAR frame: ``T_left = Tr^-1``, ``T_right = Tr``.
        """
        poses = self.poses_se3
        if T_left is not None:
            poses = _rigid_argument(T_left, "T_left") @ poses
        if T_right is not None:
            poses = poses @ _rigid_argument(T_right, "T_right")
        return Trajectory(poses, self.timestamps_s, self.name, dict(self.meta))

    def relative_to_first(self) -> Trajectory:
        """Same motion expressed so that the first pose is the identity."""
        if not len(self):
            return self
        return self.transformed(T_left=se3_inverse(self.poses_se3[0]))

    def relative_motions(self) -> np.ndarray:
        """``(N-1, 4, 4)`` frame-to-frame motions ``T_{i-1}^-1 T_i``."""
        return se3_inverse(self.poses_se3[:-1]) @ self.poses_se3[1:]

    @classmethod
    def from_relative_motions(
        cls, motions: np.ndarray, T_first: np.ndarray | None = None, timestamps_s: np.ndarray | None = None, name: str = ""
    ) -> Trajectory:
        """Chain ``(N-1, 4, 4)`` motions from ``T_first`` (identity by default) into N poses, each re-orthonormalized
        once its rotation drifts (the rounding of a file's rotations, chained over 481 of KITTI 00's motions, made a
        pose no rotation and the trajectory was refused)."""
        motions = np.asarray(motions, dtype=np.float64)
        if motions.size == 0:  # (a one-pose trajectory's relative_motions())
            motions = motions.reshape(0, 4, 4)
        if motions.ndim != 3 or motions.shape[1:] != (4, 4):  # (48 numbers were 3 motions, 3x3 ones a reshape error)
            raise ConfigError(f"motions must have shape (n, 4, 4), got {motions.shape}", source="motions")
        # each motion must be rigid itself (zeros chained into identity poses, a Sim(3) motion lost its scale)
        _check_rigid(motions, f"{name or 'trajectory'}: relative motions", "motion")
        poses = np.empty((len(motions) + 1, 4, 4))
        poses[0] = np.eye(4) if T_first is None else _rigid_argument(T_first, "T_first")
        for i, M in enumerate(motions):
            poses[i + 1] = poses[i] @ M
            if not is_rotation(poses[i + 1, :3, :3], 1e-9):
                poses[i + 1] = orthonormalize_se3(poses[i + 1])
        return cls(poses, timestamps_s, name)

    def interpolated(self, times_s: np.ndarray, *, max_extrapolation_s: float = 0.0) -> Trajectory:
        """Poses at ``times_s``: between two stamped poses, the rotation slerped and the position linear in time;
        up to ``max_extrapolation_s`` before the first or after the last stamp, the first or last interval's motion
        continued at constant velocity. Times farther out raise DataError naming the first of them."""
        source = self.name or "trajectory"
        # (a negative bound refused every time, inside the stamps too; None or text was a bare TypeError)
        if not (is_real_number(max_extrapolation_s) and max_extrapolation_s >= 0):
            raise ConfigError(f"max_extrapolation_s must be a number of seconds >= 0, got {max_extrapolation_s!r}",
                              source="max_extrapolation_s")
        if self.timestamps_s is None or len(self) < 2:
            raise DataError("interpolating needs at least two poses with time stamps", source=source)
        try:
            t = np.asarray(times_s)
        except (TypeError, ValueError):
            t = None
        if t is None or t.dtype.kind not in "biuf":  # (None, [0, None] as float64: NaN, "(time 0): time nan is not a finite number")
            raise ConfigError(f"times_s must be numbers (s), got {times_s!r:.60}", source="times_s")
        t = t.astype(np.float64).reshape(-1)
        stamps = self.timestamps_s
        if not np.isfinite(t).all():
            k = int(np.argmax(~np.isfinite(t)))
            raise DataError(f"time {t[k]} is not a finite number", source=source, location=f"time {k}")
        if len(t) > 1 and not np.all(np.diff(t) > 0):  # (read "<name> (frame 1): timestamps are not strictly increasing")
            k = int(np.argmax(~(np.diff(t) > 0))) + 1
            raise ConfigError(f"times_s must be strictly increasing: time {k} ({stamp_text(t[k])} s) is not after time {k - 1} "
                              f"({stamp_text(t[k - 1])} s)", source="times_s")
        outside = np.maximum(stamps[0] - t, t - stamps[-1])
        if len(t) and outside.max() > max_extrapolation_s:
            k = int(np.argmax(outside > max_extrapolation_s))
            raise DataError(
                f"time {stamp_text(t[k])} s lies {outside[k]:.3f} s outside the stamps {stamp_text(stamps[0])}-{stamp_text(stamps[-1])} s "
                f"(at most {max_extrapolation_s:g} s is extrapolated)", source=source, location=f"time {k}",
            )
        if not len(t):
            return Trajectory(np.zeros((0, 4, 4)), t, self.name, dict(self.meta))
        i = np.clip(np.searchsorted(stamps, t, side="right") - 1, 0, len(stamps) - 2)
        alpha = (t - stamps[i]) / (stamps[i + 1] - stamps[i])  # < 0 or > 1 beyond the ends: constant velocity
        R0 = Rotation.from_matrix(self.poses_se3[i, :3, :3])
        step = (R0.inv() * Rotation.from_matrix(self.poses_se3[i + 1, :3, :3])).as_rotvec()
        poses = np.tile(np.eye(4), (len(t), 1, 1))
        poses[:, :3, :3] = (R0 * Rotation.from_rotvec(step * alpha[:, None])).as_matrix()
        p0, p1 = self.poses_se3[i, :3, 3], self.poses_se3[i + 1, :3, 3]
        poses[:, :3, 3] = p0 + alpha[:, None] * (p1 - p0)
        return Trajectory(poses, t, self.name, dict(self.meta))

    def orthonormalized(self) -> Trajectory:
        """Copy whose rotations are exactly orthonormal (text files round them)."""
        return Trajectory(orthonormalize_se3(self.poses_se3), self.timestamps_s, self.name, dict(self.meta))

    # ---- KITTI / TUM files -----------------------------------------------------------------------
    @classmethod
    def from_kitti(
        cls, path: str | os.PathLike, timestamps_s: np.ndarray | list[float] | str | os.PathLike | None = None, name: str | None = None,
        *, format_hint: Callable[[str], str] = default_format_hint,
    ) -> Trajectory:
        """Read a KITTI pose file: one row of 12 numbers (a row-major 3x4 ``[R|t]``) per pose.

        ``timestamps_s`` may be a ``times.txt`` path (``str`` / ``os.PathLike``, one number per line) or
        anything ``np.asarray`` turns into ``(N,)`` seconds (array, list, tuple). ``format_hint``: how a caller's
        users choose the format (:func:`default_format_hint`), named when the file is a TUM trajectory.
        """
        read_warnings: list[str] = []  # (a cut-off last line, kept in meta as from_tum keeps its own)
        try:
            rows = read_numeric_table(path, 12, what="trajectory file", warnings=read_warnings)
        except DataError as err:  # a TUM file (8 numbers a row: time, x y z, qx qy qz qw) read as KITTI: say so
            if "expected 12 numbers, found 8" in err.reason and err.location == _first_data_line(path):  # (not a cut-off line)
                raise DataError(err.reason + f" (a TUM trajectory? read it as tum: {format_hint('tum')})",
                                source=err.source, location=err.location) from None
            raise
        poses = np.tile(np.eye(4), (len(rows), 1, 1))
        poses[:, :3, :4] = rows.reshape(-1, 3, 4)
        times_path = None
        if isinstance(timestamps_s, (str, os.PathLike)):
            times_path = timestamps_s
            timestamps_s = read_numeric_table(times_path, 1, what="time stamps file", warnings=read_warnings)[:, 0]
            check_seconds(timestamps_s, times_path)
            if len(timestamps_s) != len(poses):
                raise DataError(f"{len(timestamps_s)} timestamps for {len(poses)} poses in {path}", source=times_path)
        elif timestamps_s is not None:
            try:
                timestamps_s = np.asarray(timestamps_s, dtype=np.float64)
            except (TypeError, ValueError) as err:
                raise DataError(f"timestamps are not numbers ({err})", source="timestamps_s") from None
        try:
            Trajectory(poses, None, "poses")
        except DataError as err:  # name the file and its line, not the trajectory and frame
            raise DataError(err.reason, source=path, location=file_line(path, err.location)) from None
        try:
            return cls(poses, timestamps_s, Path(path).stem if name is None else name,
                       {READ_WARNINGS: read_warnings} if read_warnings else {})
        except DataError as err:
            if times_path is not None and "timestamp" in err.reason:
                raise DataError(err.reason, source=times_path, location=file_line(times_path, err.location)) from None
            raise

    @classmethod
    def from_tum(cls, path: str | os.PathLike, name: str | None = None, *,
                 format_hint: Callable[[str], str] = default_format_hint) -> Trajectory:
        """Read a TUM trajectory: ``timestamp tx ty tz qx qy qz qw`` per line, ``#`` comments.

        A pose stamped like the one before it is left out (with a warning naming the lines, also kept in
        ``meta["read_warnings"]``): TUM RGB-D's own ground truth of ``fr2/desk`` has one; more than half of them
        repeating is a DataError (stamps written with too few digits). Timestamps that go backwards, or beyond any time
        in seconds (nanoseconds), are a DataError naming the line."""
        read_warnings: list[str] = []
        try:
            rows = read_numeric_table(path, 8, what="trajectory file", warnings=read_warnings)
        except DataError as err:  # a KITTI file (12 numbers a row, a 3x4 [R|t]) read as TUM: say so, as from_kitti does
            if "expected 8 numbers, found 12" in err.reason and err.location == _first_data_line(path):  # (not a cut-off line)
                raise DataError(err.reason + f" (a KITTI trajectory? read it as kitti: {format_hint('kitti')})",
                                source=err.source, location=err.location) from None
            raise
        check_seconds(rows[:, 0], path)
        quat_xyzw = rows[:, 4:8]
        norms = np.linalg.norm(quat_xyzw, axis=1)
        if (np.abs(norms - 1.0) > 1e-2).any():
            i = int(np.argmax(np.abs(norms - 1.0) > 1e-2))
            raise DataError(f"quaternion norm {norms[i]:.4f} is not 1", source=path, location=file_line(path, f"frame {i}"))
        step = np.diff(rows[:, 0])
        if (step < 0).any():
            k = int(np.argmax(step < 0)) + 1
            raise DataError(f"timestamp {stamp_text(rows[k, 0])} is earlier than the one before it ({stamp_text(rows[k - 1, 0])})",
                            source=path, location=file_line(path, f"frame {k}"))
        repeated = np.flatnonzero(step == 0) + 1
        if repeated.size > len(rows) / 2:  # no recorder's glitch: the file's stamps lost their digits (90 % left out, scored)
            raise DataError(f"{repeated.size} of {len(rows)} poses repeat the timestamp of the pose before them: were the "
                            "stamps written with too few decimals (TUM stamps need sub-millisecond digits)?", source=path)
        if repeated.size:
            numbers = data_line_numbers(path)  # (the file is read once for all the lines named)
            lines = ", ".join(f"line {numbers[k]}" for k in repeated[:5])
            read_warnings.append(f"{path}: {repeated.size} pose(s) repeat the timestamp of the pose before them "
                                 f"({lines}{', ...' if repeated.size > 5 else ''}): each left out")
            log.warning("%s", read_warnings[-1])
            rows = np.delete(rows, repeated, axis=0)
        poses = np.tile(np.eye(4), (len(rows), 1, 1))
        poses[:, :3, :3] = Rotation.from_quat(rows[:, 4:8]).as_matrix()
        poses[:, :3, 3] = rows[:, 1:4]
        # what was left out travels with the poses (evaluate() files it beside the scores: the report read clean)
        meta = {READ_WARNINGS: read_warnings} if read_warnings else {}
        return cls(poses, rows[:, 0], Path(path).stem if name is None else name, meta)

    @classmethod
    def read(cls, path: str | os.PathLike, fmt: str = "kitti", *, format_hint: Callable[[str], str] = default_format_hint,
             **kwargs) -> Trajectory:
        """Read ``path`` in ``fmt`` (``kitti`` or ``tum``); ``kwargs`` are the reader's options (an option of the other
        format, e.g. ``timestamps_s`` for tum, was a TypeError); ``format_hint`` names how the caller's users pick the
        format, for the message of a file in the other one (``poses_format=tum`` for a dataset option)."""
        readers = {"kitti": cls.from_kitti, "tum": cls.from_tum}
        if fmt not in readers:
            raise ConfigError(f"unknown trajectory format {fmt!r}; known: {', '.join(FORMATS)}", source="format")
        options = {f: [p for p in inspect.signature(r).parameters if p not in ("path", "format_hint")] for f, r in readers.items()}
        for key in kwargs:
            if key not in options[fmt]:
                applies = [f for f in FORMATS if key in options[f]]
                reason = f"applies to the {applies[0]} format, not {fmt}" if applies else f"is no option of the {fmt} format"
                raise ConfigError(f"{key} {reason} ({fmt} options: {', '.join(options[fmt])})", source=key)
        return readers[fmt](path, **kwargs, format_hint=format_hint)

    def to_kitti(self, path: str | os.PathLike) -> Path:
        """Write the KITTI pose format atomically, every number to the digits that read back the same double (10
        significant digits rounded georeferenced positions, ~5e6 m, by up to 0.5 mm)."""
        self._refuse_empty(path)
        rows = self.poses_se3[:, :3, :4].reshape(-1, 12)
        text = "\n".join(" ".join(f"{v:.16e}" for v in row) for row in rows) + "\n"
        return atomic.write_text(path, text)

    def to_tum(self, path: str | os.PathLike) -> Path:
        """Write the TUM format atomically (frame index as time when there are no timestamps)."""
        self._refuse_empty(path)
        ts = self.timestamps_s if self.timestamps_s is not None else np.arange(len(self), dtype=np.float64)
        quat = Rotation.from_matrix(self.poses_se3[:, :3, :3]).as_quat()
        data = np.column_stack([ts, self.poses_se3[:, :3, 3], quat])
        text = "# timestamp tx ty tz qx qy qz qw\n" + "\n".join(
            f"{row[0]:.9f} " + " ".join(f"{v:.9f}" for v in row[1:]) for row in data  # (stamps to 1e-9 s: 6 decimals lost 0.5 us)
        ) + "\n"
        return atomic.write_text(path, text)

    def _refuse_empty(self, path: str | os.PathLike) -> None:
        """DataError for a trajectory without poses: its file would be one the readers refuse ("no data rows")."""
        if not len(self):
            raise DataError("an empty trajectory (0 poses) is not written: the readers refuse empty files", source=path)

    def write(self, path: str | os.PathLike, fmt: str = "kitti") -> Path:
        if fmt == "kitti":
            return self.to_kitti(path)
        if fmt == "tum":
            return self.to_tum(path)
        raise ConfigError(f"unknown trajectory format {fmt!r}; known: {', '.join(FORMATS)}", source="format")

    # ---- evo -------------------------------------------------------------------------------------
    def to_evo(self):
        """A fresh evo trajectory (``PoseTrajectory3D`` with timestamps, else ``PosePath3D``).

        evo's align/transform/scale work in place; this returns a new object every call.
        """
        from evo.core.trajectory import PosePath3D, PoseTrajectory3D

        poses = [p.copy() for p in self.poses_se3]
        if self.timestamps_s is None:
            return PosePath3D(poses_se3=poses)
        return PoseTrajectory3D(poses_se3=poses, timestamps=self.timestamps_s.copy())

    @classmethod
    def from_evo(cls, traj, name: str = "") -> Trajectory:
        """Copy an evo ``PosePath3D``/``PoseTrajectory3D`` into a Trajectory."""
        poses = np.array(traj.poses_se3, dtype=np.float64)
        ts = getattr(traj, "timestamps", None)
        return cls(poses, None if ts is None else np.array(ts, dtype=np.float64), name)

    def copy(self) -> Trajectory:
        return copy.deepcopy(self)


def _first_data_line(path: str | os.PathLike) -> str | None:
    """``"line N"`` of a text file's first line that is neither blank nor a comment (None when unreadable)."""
    from lidarkit.textfile import data_line_numbers

    try:
        lines = data_line_numbers(path)
    except (DataError, OSError):
        return None
    return f"line {lines[0]}" if lines else None
