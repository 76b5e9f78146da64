"""A folder of scan files (``.bin``, ``.pcd``, ``.ply``, ``.npy``) as a ``ScanSequence``.

Files are ordered by natural sort of their names (``scan2`` before ``scan10``; decimal time stamps in names by
their value, ``scan_1000.05`` before ``scan_1000.1``; dotted counters, ``run_2.9`` before ``run_2.10``, where a
fraction ending in 0 beside fractions of other lengths shows that the numbers count). An optional poses file (KITTI
or TUM format, poses of the LiDAR in a world frame) must have exactly one pose per scan; optional timestamps (array
or a text file with one number per line) likewise.
"""

from __future__ import annotations

import logging
import os
import re
from functools import cached_property
from pathlib import Path

import numpy as np

from lidarkit.errors import ConfigError, DataError
from lidarkit.io.base import Scan, checked_index, keep_once, option_path
from lidarkit.io.pointfile import (POINT_FILE_SUFFIXES, open3d_skipped_type, point_file_fields, read_point_file,
                                   said_once)
from lidarkit.run_files import output_folder_kind
from lidarkit.textfile import data_line_numbers, read_numeric_table
from lidarkit.trajectory import READ_WARNINGS, Trajectory, check_seconds

POSE_FORMATS = ("kitti", "tum")
#: per-point time fields that kiss-icp's generic loader (generic:PATH) reads from .pcd/.ply files; this reader reads none
GENERIC_TIME_FIELDS = ("t", "timestamp", "timestamps", "time", "stamps")
log = logging.getLogger(__name__)


#: a run of digits, with the digits after a dot when a number follows it (``1000.05`` in ``scan_1000.05.bin``)
_NUMBER = re.compile(r"(\d+(?:\.\d+)?)")


def natural_key(name: str) -> tuple:
    """Sort key treating numbers in a name as numbers: ``frame2`` < ``frame10``. A number with a dot and digits after
    it (a time stamp, alone or after a prefix: ``scan_1000.05``) is a decimal whose fraction is compared as text
    (``1000.05`` < ``1000.1``; as a second number, 5 > 1 put 20 Hz sweeps out of order), so nanosecond stamps keep
    their order (floats would round them)."""
    return tuple(_number_key(part) if part[0].isdigit() else (1, 0, part.lower()) for part in _NUMBER.split(name) if part)


def _number_key(number: str) -> tuple[int, int, str]:
    whole, _, fraction = number.partition(".")
    return 0, int(whole), fraction.rstrip("0")


_DIGITS = re.compile(r"(\d+)")


def _counter_key(name: str) -> tuple:
    """Every run of digits an integer (``a_2.9`` < ``a_2.10``): the other reading of a dotted number."""
    return tuple((0, int(part), "") if part.isdigit() else (1, 0, part.lower()) for part in _DIGITS.split(name) if part)


def sorted_by_name(paths: list[Path]) -> list[Path]:
    """Paths in ``natural_key`` order of their names, unless the dotted numbers in them count: a fraction of two digits
    or more ending in 0 (``run_2.10``) beside fractions of other lengths (``run_2.9``) is no time stamp (decimal stamps
    are written either to a fixed number of digits or without trailing zeros, but for Python's ``0.0``), so every
    digit run is then an integer and ``run_2.9`` comes before ``run_2.10``."""
    fractions = {m.partition(".")[2] for p in paths for m in _NUMBER.findall(p.name) if "." in m}
    # (a lone "0" is Python's whole-number stamp, 0.0 beside 0.05: no counter; a 20 Hz folder was read 0.0, 0.1, 0.2, ...)
    counting = len({len(f) for f in fractions}) > 1 and any(len(f) > 1 and f.endswith("0") for f in fractions)
    return sorted(paths, key=lambda p: (_counter_key if counting else natural_key)(p.name))


class ScanFolder:
    """Scans in one folder, naturally sorted; ``ground_truth`` from ``poses`` (LiDAR frame) if given.

    ``poses_format`` is ``"kitti"`` (12 numbers per row, the default) or ``"tum"`` (``t x y z qx qy qz qw``; its
    time stamps become ``timestamps_s`` unless ``timestamps`` is given); without ``poses`` it is a ConfigError (it
    would have no effect). ``suffixes`` restricts the file types read (a sequence, or text such as ``".npy,.bin"`` as a spec writes it); a folder mixing several types
    is read as one sequence in name order.
    ``drop_nonfinite`` drops NaN/inf points instead of raising DataError, said once in ``reader_warnings`` (a run's
    metrics.json) as well as the log.
    """

    def __init__(
        self,
        path: str | os.PathLike,
        *,
        poses: str | os.PathLike | None = None,
        poses_format: str | None = None,
        timestamps: str | os.PathLike | np.ndarray | list[float] | None = None,
        drop_nonfinite: bool = False,
        suffixes: tuple[str, ...] | str = POINT_FILE_SUFFIXES,
        name: str | None = None,
    ):
        if isinstance(suffixes, str):  # a spec's ?suffixes=.npy,.bin: the text, not its characters
            suffixes = tuple(s.strip() for s in suffixes.strip("[]()").split(",") if s.strip())
        folder = Path(path)
        if not folder.is_dir():
            raise DataError("scan folder not found" if not folder.exists() else "not a folder", source=folder)
        output = output_folder_kind(folder)
        if output:  # (it said only "no scan files")
            raise DataError(f"{output}: lidarkit's output, not a scan sequence", source=folder)
        if poses_format is not None and poses_format not in POSE_FORMATS:
            raise ConfigError(f"unknown poses format {poses_format!r}; known: {', '.join(POSE_FORMATS)}", source="poses_format")
        if poses_format is not None and poses is None:  # (folder:scans?poses_format=tum ran without a word, and without poses)
            raise ConfigError("has no effect without poses= (the poses file whose format it names)", source="poses_format")
        unknown = [s for s in suffixes if s.lower() not in POINT_FILE_SUFFIXES]
        if unknown:
            raise ConfigError(f"unsupported scan suffix {unknown[0]!r}; supported: {', '.join(POINT_FILE_SUFFIXES)}", source="suffixes")
        wanted = {s.lower() for s in suffixes}
        self.path = folder
        self.name = name or Path(os.path.abspath(folder)).name  # ("." was named '')
        self.drop_nonfinite = drop_nonfinite
        #: what the reader left out (NaN or infinite points, under drop_nonfinite) or replaced (pose stamps far from
        #: ``timestamps``) and files cut inside their last number (poses, timestamps), for the run's warnings: once each
        self.reader_warnings: list[str] = []
        broken = next((p for p in folder.iterdir() if p.suffix.lower() in wanted and p.is_symlink() and not p.exists()), None)
        if broken is not None:  # a scan that is not there: never skipped without a word
            raise DataError(f"a broken link (to {os.readlink(broken)})", source=broken)
        self.scan_paths = sorted_by_name([p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in wanted])
        if not self.scan_paths:
            from lidarkit.io.kitti_raw import is_drive_folder

            hint = "; a KITTI raw drive folder: read it as kitti_raw:PATH" if is_drive_folder(folder) else ""
            raise DataError(f"no scan files ({', '.join(sorted(wanted))}){hint}", source=folder)
        stems: dict[str, Path] = {}
        for path in self.scan_paths:  # the same scan in two formats was read as two frames (every other step at rest)
            if path.stem in stems:
                raise DataError(f"two files for scan {path.stem!r} ({stems[path.stem].name}, {path.name}): keep one, or pick "
                                "one format with suffixes=", source=folder)
            stems[path.stem] = path
        self.poses_path = None if poses is None else self._option_path(poses)
        self.poses_format = poses_format or "kitti"
        self.suffixes = sorted(wanted)
        if isinstance(timestamps, (str, os.PathLike)):
            timestamps = self._option_path(timestamps)
        self._timestamps_given = (None if timestamps is None else str(Path(timestamps).absolute())
                                  if isinstance(timestamps, (str, os.PathLike)) else f"{len(np.ravel(timestamps))} values given")
        self._timestamps_s = self._load_timestamps(timestamps)
        self._ground_truth = self._load_poses()

    def _option_path(self, given: str | os.PathLike) -> Path:
        """A path option as given or in the scan folder (``poses=poses.txt`` beside the scans), as the kitti reader
        looks (:func:`lidarkit.io.base.option_path`); found in neither: both places named."""
        path = option_path(given, self.path)
        if not path.exists():
            raise DataError(f"file not found, neither from the working directory nor in the scan folder {self.path}", source=path)
        return path

    def _load_timestamps(self, timestamps) -> np.ndarray | None:
        if timestamps is None:
            return None
        if isinstance(timestamps, (str, os.PathLike)):
            source = Path(timestamps)
            read_warnings: list[str] = []
            values = read_numeric_table(source, 1, what="time stamps file", warnings=read_warnings)[:, 0]
            keep_once(self.reader_warnings, read_warnings)
            check_seconds(values, source)  # (nanoseconds ran, and the run's poses_tum.txt was refused by lidarkit eval)
        else:
            source = "timestamps"
            values = np.asarray(timestamps, dtype=np.float64).reshape(-1)
        if len(values) != len(self.scan_paths):
            raise DataError(f"{len(values)} time stamps for {len(self.scan_paths)} scans in {self.path}", source=source)
        if not np.isfinite(values).all():
            raise DataError("NaN or infinite time stamp", source=source)
        bad = np.flatnonzero(np.diff(values) <= 0)
        if len(bad):
            raise DataError("time stamps are not strictly increasing", source=source, location=f"frame {bad[0] + 1}")
        return values

    def _load_poses(self) -> Trajectory | None:
        if self.poses_path is None:
            return None
        gt = Trajectory.read(self.poses_path, self.poses_format, format_hint=lambda other: f"poses_format={other}")
        keep_once(self.reader_warnings, gt.meta.get(READ_WARNINGS, ()))
        if len(gt) != len(self.scan_paths):
            raise DataError(f"{len(gt)} poses for {len(self.scan_paths)} scans in {self.path}{self._repeats_left_out(len(gt))}",
                            source=self.poses_path)
        if self._timestamps_s is not None:
            if gt.timestamps_s is not None:
                self._warn_stamps_apart(gt.timestamps_s)
            gt = gt.with_timestamps(self._timestamps_s)
        elif gt.timestamps_s is not None:
            self._timestamps_s = gt.timestamps_s.copy()
        return gt.with_name(f"{self.name}_gt")

    def _repeats_left_out(self, n_read: int) -> str:
        """What a pose count short of the scans owes to poses left out for repeating the stamp before them (a 10-row
        TUM file for 10 scans read as "9 poses for 10 scans" beside a warning): their lines, and why that counts."""
        if self.poses_format != "tum":
            return ""
        rows = read_numeric_table(self.poses_path, 8)
        repeated = np.flatnonzero(np.diff(rows[:, 0]) == 0) + 1
        if not repeated.size or len(rows) != len(self.scan_paths) or len(rows) - repeated.size != n_read:
            return ""
        numbers = data_line_numbers(self.poses_path)
        lines = ", ".join(str(numbers[k]) for k in repeated[:5]) + (", ..." if repeated.size > 5 else "")
        left_out = f"lines {lines} left out: each repeats" if repeated.size > 1 else f"line {lines} left out: it repeats"
        return (f" ({len(rows)} rows, {left_out} the stamp of the pose before it); the folder reader pairs poses with scans "
                "by order, one each: give each pose its own stamp")

    def _warn_stamps_apart(self, pose_stamps: np.ndarray) -> None:
        """A TUM file's own stamps give way to ``timestamps``: say so when they disagree by more than half a frame
        (stamps 100 s apart were replaced without a word), as an image folder does, in the log and, once, in
        :attr:`reader_warnings` (a run's metrics.json: it was logged only)."""
        steps = np.diff(self._timestamps_s)
        half_frame = 0.5 * float(np.median(steps)) if len(steps) else 0.0
        apart = np.abs(pose_stamps - self._timestamps_s)
        k = int(np.argmax(apart))
        if half_frame > 0 and apart[k] > half_frame:
            message = (f"{self.poses_path}: pose {k} is stamped {float(apart[k]):.3f} s from its scan's time stamp (half a "
                       f"frame is {half_frame:.3f} s); poses and scans are paired by order, one each, and the poses take "
                       "the stamps of timestamps=")
            if message not in self.reader_warnings:
                self.reader_warnings.append(message)
            log.warning("%s", message)

    def __len__(self) -> int:
        return len(self.scan_paths)

    def __repr__(self) -> str:
        return f"ScanFolder({str(self.path)!r}, scans={len(self)})"

    @cached_property
    def frames(self) -> np.ndarray:
        """``(N,)`` frame indices ``0..N-1`` (position in the sorted file list)."""
        return np.arange(len(self.scan_paths))

    @property
    def reader_options(self) -> dict:
        """Where the stamps and poses came from and which files were read, for the run config (two runs over one
        folder with other timestamps= or poses= files had the same config.yaml)."""
        return {"kind": "folder", "path": str(self.path.absolute()), "timestamps": self._timestamps_given,
                "suffixes": ",".join(self.suffixes),
                # (named as the attribute, not as the option: regression checks compare a pinned spec's options by name)
                "poses_path": None if self.poses_path is None else str(Path(self.poses_path).absolute()),
                "poses_format": self.poses_format}

    @property
    def unread_point_times(self) -> tuple[str, Path, bool] | None:
        """(field, file, whether generic:PATH reads it): a per-point time field in the folder's first .pcd/.ply, which
        this reader leaves unread; None without one. For a deskew that found no times ("ScanFolder gives none" hid
        them). generic:PATH refuses a .pcd whose padding fields repeat (Open3D, its reader, aborts on them) and reads
        no field of a PLY type Open3D skips (:attr:`unread_point_time_type`)."""
        found = self._time_field_in_first_file
        if found is None:
            return None
        field, first, fields = found
        return field, first, len(set(fields)) == len(fields) and open3d_skipped_type(first, field) is None

    @property
    def unread_point_time_type(self) -> str | None:
        """The PLY type of the :attr:`unread_point_times` field when Open3D cannot read it (``uint``, ``ushort``...:
        :data:`~lidarkit.io.pointfile.OPEN3D_SKIPPED_PLY_TYPES`), so that no reader gets the times until the files
        store them as float, double or int; None otherwise."""
        found = self._time_field_in_first_file
        return None if found is None else open3d_skipped_type(found[1], found[0])

    @cached_property
    def _time_field_in_first_file(self) -> tuple[str, Path, list[str]] | None:
        """(time field, file, all its fields) of the first .pcd/.ply: the first of :data:`GENERIC_TIME_FIELDS` that
        Open3D reads, as kiss-icp's generic loader picks it, else the first present; None without one."""
        first = next((p for p in self.scan_paths if p.suffix.lower() in (".pcd", ".ply")), None)
        fields = [] if first is None else point_file_fields(first)
        present = [f for f in GENERIC_TIME_FIELDS if f in fields]
        if not present:
            return None
        readable = [f for f in present if open3d_skipped_type(first, f) is None]
        return (readable or present)[0], first, fields

    @property
    def timestamps_s(self) -> np.ndarray | None:
        return None if self._timestamps_s is None else self._timestamps_s.copy()

    @property
    def ground_truth(self) -> Trajectory | None:
        """Poses from the ``poses`` file, one per scan, taken to be LiDAR poses in a world frame."""
        return self._ground_truth

    def read_scan(self, index: int) -> Scan:
        """The ``index``-th scan in name order (``Scan.frame`` = ``index``)."""
        index = checked_index(index, len(self), f"{self.name} ({self.path})")
        ts = None if self._timestamps_s is None else float(self._timestamps_s[index])
        dropped: list[str] = []
        scan = read_point_file(self.scan_paths[index], frame=index, timestamp_s=ts, drop_nonfinite=self.drop_nonfinite,
                               dropped=dropped)
        said_once(self.reader_warnings, dropped)
        return scan


__all__ = ["ScanFolder", "natural_key", "sorted_by_name"]
