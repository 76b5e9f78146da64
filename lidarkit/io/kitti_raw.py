"""KITTI raw reader (through pykitti): Velodyne scans, OXTS GPS/IMU poses and the rig calibration.

Layout::

    base_dir/DATE/calib_cam_to_cam.txt, calib_velo_to_cam.txt, calib_imu_to_velo.txt
    base_dir/DATE/DATE_drive_NNNN_sync/velodyne_points/data/0000000000.bin  (+ timestamps.txt)
    base_dir/DATE/DATE_drive_NNNN_sync/oxts/data/0000000000.txt             (+ timestamps.txt)
    base_dir/DATE/DATE_drive_NNNN_sync/image_00/data/0000000000.png

OXTS packets become poses ``T_enu_imu`` with pykitti's Mercator projection (scale from the first
latitude, origin at the first GPS position, x east, y north, z up), each at its own ``oxts/timestamps.txt`` stamp.
``ground_truth`` gives the LiDAR poses ``T_enu_velo = T_enu_imu @ T_velo_imu^-1`` of the scanned frames at their
Velodyne stamps, interpolated between the packets: a sync drive's packet f is stamped 12-24 ms after scan f (its
packets come 100 or 110 ms apart, the scans 103 ms), 12-24 cm along the track at 10 m/s.

Raw scans are not motion-compensated: as kiss-icp's own KITTI raw loader, the reader gives each point its place in
the sweep from its azimuth (``point_times="azimuth"``: the HDL-64 turns clockwise seen from above, a sweep starts and
ends facing backwards and faces forward half-way, when the cameras are triggered and ``velodyne_points/timestamps.txt``
stamps it), so deskewing variants deskew them; the stamps and the OXTS ground truth refer to the sweep middle. The
scans get KITTI's vertical-angle correction as the ``kitti`` reader does (``vertical_correction``; under ``"auto"``
for kiss and genz, as kiss-icp's and genz-icp's loaders read every drive).
Everything pykitti raises is turned into a DataError naming the file.
"""

from __future__ import annotations

import dataclasses
import os
import re
from functools import cached_property
from pathlib import Path

import numpy as np

from lidarkit.errors import ConfigError, DataError
from lidarkit.geometry import se3_inverse
from lidarkit.io.base import INSTANT_FRACTION, Scan, checked_index, checked_indices
from lidarkit.io.kitti import (
    CORRECTED_BY_DEFAULT, check_vertical_correction, correct_vertical_angle, correction_options, indexed_files, read_gray_image,
)
from lidarkit.io.pointfile import read_kitti_bin, said_once
from lidarkit.textfile import file_line, read_lines, read_numeric_table
from lidarkit.trajectory import Trajectory

CALIB_FILES = ("calib_cam_to_cam.txt", "calib_velo_to_cam.txt", "calib_imu_to_velo.txt")
OXTS_FIELDS = 30
#: the per-point times a drive's scans are given (``"azimuth"``: each point's sweep fraction, as kiss-icp's loader)
POINT_TIMES = ("azimuth", "none")
_DRIVE_DIR = re.compile(r"^(\d{4}_\d{2}_\d{2})_drive_(\d{4})_(\w+)$")


def is_drive_folder(path: str | os.PathLike) -> bool:
    """Whether ``path`` is named as a KITTI raw drive folder (``2011_09_26_drive_0002_sync``): read as a folder of
    scans it said "no scan files" without naming ``kitti_raw:``."""
    return _DRIVE_DIR.match(Path(os.path.abspath(path)).name) is not None


def read_kitti_raw_timestamps(path: str | os.PathLike) -> np.ndarray:
    """``YYYY-MM-DD hh:mm:ss.fffffffff`` lines as float seconds since the Unix epoch (nanosecond parse)."""
    stamps = []
    for lineno, raw in enumerate(read_lines(path), start=1):
        line = raw.strip()
        if not line:
            continue
        try:
            stamps.append(np.datetime64(line.replace(" ", "T"), "ns"))
        except ValueError:
            raise DataError(f"not a time stamp: {line!r}", source=path, location=f"line {lineno}") from None
    if not stamps:
        raise DataError("no time stamps", source=path)
    ns = np.array(stamps, dtype="datetime64[ns]").astype(np.int64)
    back = np.flatnonzero(np.diff(ns) <= 0)
    if len(back):  # named by the file's line here, not later as a frame of some trajectory
        raise DataError("time stamps are not strictly increasing", source=path, location=file_line(path, f"frame {back[0] + 1}"))
    return ns.astype(np.float64) * 1e-9


class KittiRaw:
    """One KITTI raw drive (``ScanSequence``): ``KittiRaw(base_dir, date="2011_09_26", drive="0001")``.

    ``base_dir`` may also be the drive folder itself (``.../2011_09_26_drive_0001_sync``), in which
    case date, drive and dataset are taken from its name. ``len`` is the number of Velodyne scans
    (0 when the drive has none: calibration and OXTS poses are still available, ``read_scan``
    raises DataError). Frame numbers come from file names, as in :class:`KittiOdometry`.

    ``vertical_correction``: as :class:`~lidarkit.io.kitti.KittiOdometry`'s; every raw drive is a recording of KITTI's
    HDL-64, so ``"auto"`` corrects whenever an odometry run of a method in ``CORRECTED_BY_DEFAULT`` (kiss, genz) asks
    (:meth:`configure_for_method`), as kiss-icp's own KITTI raw loader does; read directly, the points as stored.
    ``point_times``: ``"azimuth"`` (default) gives each point its sweep fraction from its azimuth, ``"none"`` none.
    """

    def __init__(
        self,
        base_dir: str | os.PathLike,
        date: str | None = None,
        drive: str | int | None = None,
        *,
        dataset: str = "sync",
        drop_nonfinite: bool = False,
        vertical_correction: bool | str = "auto",
        point_times: str = "azimuth",
    ):
        self.vertical_correction = check_vertical_correction(vertical_correction)
        if point_times not in POINT_TIMES:
            raise ConfigError(f"point_times must be one of {', '.join(POINT_TIMES)}, got {point_times!r}", source="point_times")
        self.point_times = point_times
        self._correct = vertical_correction is True
        base = Path(base_dir)
        if not base.exists():  # (it asked for date= and drive= of a folder that is not there)
            raise DataError("not found", source=base)
        base = Path(os.path.abspath(base))  # ("." inside the drive folder has no name to read its date and drive from)
        m = _DRIVE_DIR.match(base.name)
        if m:  # the drive folder itself names its date, drive and kind (options that say otherwise were ignored or refused)
            named = {"date": (date, m.group(1)), "drive": (drive, m.group(2)), "dataset": (dataset, m.group(3))}
            for option, (given, own) in named.items():
                if given is not None and not (option == "dataset" and given == "sync") and str(given).lstrip("0") != own.lstrip("0"):
                    raise ConfigError(f"{option}={given!r}, but the drive folder given is {own!r} ({base.name}): give the "
                                      "base folder with date= and drive=, or the drive folder alone", source=f"kitti_raw option {option}")
            date, drive, dataset = m.group(1), m.group(2), m.group(3)
            base = base.parent.parent
        if date is None or drive is None:
            raise DataError("give date= and drive= (e.g. '2011_09_26', '0001') or the drive folder itself", source=base)
        drive = f"{int(drive):04d}" if str(drive).isdigit() else str(drive)
        self.date, self.drive, self.dataset = str(date), drive, dataset
        self.calib_dir = base / self.date
        self.drive_dir = self.calib_dir / f"{self.date}_drive_{self.drive}_{self.dataset}"
        self.name = f"kitti_raw_{self.date}_{self.drive}"
        self.drop_nonfinite = drop_nonfinite
        #: what the reader left out (NaN or infinite points, under drop_nonfinite), for the run's warnings: once
        self.reader_warnings: list[str] = []
        for folder in (base, self.calib_dir, self.drive_dir):
            if not folder.is_dir():
                raise DataError("folder not found", source=folder)
        for name in CALIB_FILES:
            if not (self.calib_dir / name).is_file():
                raise DataError("calibration file not found", source=self.calib_dir / name)
        oxts_stamps = self.drive_dir / "oxts" / "timestamps.txt"
        if not oxts_stamps.is_file():
            raise DataError("OXTS time stamps not found (pykitti needs them)", source=oxts_stamps)
        self._oxts_times_all = read_kitti_raw_timestamps(oxts_stamps)

        velo_dir = self.drive_dir / "velodyne_points" / "data"
        self.velodyne_dir = velo_dir
        self.scan_paths, self.scan_frames = indexed_files(velo_dir, ".bin") if velo_dir.is_dir() else ([], np.zeros(0, np.int64))
        image_dir = self.drive_dir / "image_00" / "data"
        self.image_paths, self.image_frames = indexed_files(image_dir, ".png") if image_dir.is_dir() else ([], np.zeros(0, np.int64))
        oxts_dir = self.drive_dir / "oxts" / "data"
        self.oxts_paths, self.oxts_frames = indexed_files(oxts_dir, ".txt") if oxts_dir.is_dir() else ([], np.zeros(0, np.int64))
        for path in self.oxts_paths:  # line-numbered errors before pykitti parses them
            read_numeric_table(path, OXTS_FIELDS)
        if len(self.oxts_frames) and self.oxts_frames[-1] >= len(self._oxts_times_all):
            raise DataError(
                f"{len(self._oxts_times_all)} time stamps but OXTS file {self.oxts_paths[-1].name} is frame {self.oxts_frames[-1]}",
                source=oxts_stamps,
            )
        self._raw = self._open_pykitti(base)

    def _open_pykitti(self, base: Path):
        import pykitti

        try:
            raw = pykitti.raw(str(base), self.date, self.drive, dataset=self.dataset)
        except FileNotFoundError as err:
            raise DataError("file not found (pykitti)", source=err.filename or self.drive_dir) from err
        except (OSError, ValueError, KeyError, IndexError, TypeError, AttributeError) as err:
            raise DataError(f"pykitti cannot load the drive ({err.__class__.__name__}: {err})", source=self.drive_dir) from err
        if len(raw.oxts_files) != len(self.oxts_paths):
            raise DataError(f"pykitti found {len(raw.oxts_files)} OXTS files, expected {len(self.oxts_paths)}", source=self.drive_dir)
        return raw

    def __len__(self) -> int:
        return len(self.scan_paths)

    def configure_for_method(self, method: str) -> None:
        """Resolve ``vertical_correction="auto"`` for an odometry run of ``method`` (on for kiss and genz)."""
        if self.vertical_correction == "auto":
            self._correct = method in CORRECTED_BY_DEFAULT

    @property
    def reader_options(self) -> dict:
        """What the reader did to the data, for the run config."""
        return {"kind": "kitti_raw", "path": str(self.drive_dir.absolute()),
                **correction_options(self.vertical_correction, self._correct), "point_times": self.point_times}

    def __repr__(self) -> str:
        return f"KittiRaw({str(self.drive_dir)!r}, scans={len(self)}, oxts={len(self.oxts_paths)})"

    @property
    def frames(self) -> np.ndarray:
        """``(len,)`` frame numbers of the scans."""
        return self.scan_frames

    # ---- calibration -----------------------------------------------------------------------------------
    @property
    def calib(self):
        """pykitti's calibration namedtuple (``T_velo_imu``, ``T_cam0_velo``, ``K_cam0``, ``P_rect_00``, ``b_gray``...)."""
        return self._raw.calib

    @property
    def T_velo_imu(self) -> np.ndarray:
        """(4, 4) IMU-to-Velodyne transform."""
        return np.array(self._raw.calib.T_velo_imu, dtype=np.float64)

    @property
    def T_cam0_velo(self) -> np.ndarray:
        """(4, 4) Velodyne to rectified camera 0."""
        return np.array(self._raw.calib.T_cam0_velo, dtype=np.float64)

    @property
    def K(self) -> np.ndarray:
        """(3, 3) rectified intrinsics of camera 0 (gray left)."""
        return np.array(self._raw.calib.K_cam0, dtype=np.float64)

    # ---- time and poses --------------------------------------------------------------------------------
    @cached_property
    def _velo_times_all(self) -> np.ndarray | None:
        path = self.drive_dir / "velodyne_points" / "timestamps.txt"
        return read_kitti_raw_timestamps(path) if path.is_file() else None

    @property
    def timestamps_s(self) -> np.ndarray | None:
        """``(len,)`` Velodyne time stamps [s since epoch] of the scans, or None."""
        times = self._velo_times_all
        if times is None:
            return None
        if len(self.scan_frames) and self.scan_frames[-1] >= len(times):
            raise DataError(f"{len(times)} Velodyne time stamps but scan frame {self.scan_frames[-1]}", source=self.velodyne_dir)
        return times[self.scan_frames]

    @cached_property
    def oxts_packets(self) -> list:
        """pykitti ``OxtsPacket`` namedtuples (lat, lon, alt, roll, pitch, yaw, ...) per OXTS file."""
        return [o.packet for o in self._raw.oxts]

    @cached_property
    def oxts_poses(self) -> Trajectory:
        """``T_enu_imu`` per OXTS file (pykitti Mercator projection), time stamps from oxts/timestamps.txt."""
        if not self._raw.oxts:
            raise DataError("no OXTS packets (oxts/data/*.txt)", source=self.drive_dir / "oxts")
        poses = np.array([o.T_w_imu for o in self._raw.oxts], dtype=np.float64)
        return Trajectory(poses, self._oxts_times_all[self.oxts_frames], f"{self.name}_oxts").orthonormalized()

    def ground_truth_at(self, frames: np.ndarray | list[int]) -> Trajectory:
        """LiDAR poses ``T_enu_velo`` of the given frame numbers at their Velodyne stamps (the sweep middle): the OXTS
        poses, each at its own stamp, interpolated there (:meth:`_lidar_poses_at`). Without a Velodyne stamp of every
        frame, or with one OXTS packet, each frame gets its own packet's pose at the packet's stamp, said in
        ``meta["paired"]``. DataError if a frame has no OXTS packet."""
        frames = checked_indices(frames, len(self._oxts_times_all), self.drive_dir / "oxts", "frame", from_end=False)
        lookup = {int(f): i for i, f in enumerate(self.oxts_frames)}
        missing = [int(f) for f in frames if int(f) not in lookup]
        if missing:
            raise DataError(
                f"no OXTS packet for frame {missing[0]} ({len(missing)} frames missing, {len(self.oxts_paths)} OXTS files)",
                source=self.drive_dir / "oxts" / "data",
            )
        velo = self._velo_times_all
        if velo is not None and frames.max() < len(velo) and len(self.oxts_paths) >= 2:
            times = velo[frames]
            at, back = np.unique(times, return_inverse=True)  # (frames in any order: their Trajectory says so, as before)
            lidar = self._lidar_poses_at(at)
            return Trajectory(lidar.poses_se3[back], times, lidar.name)
        oxts = self.oxts_poses
        rows = [lookup[int(f)] for f in frames]
        why = "no Velodyne time stamp of every frame" if len(self.oxts_paths) >= 2 else "one OXTS packet: nothing to interpolate"
        return Trajectory(oxts.poses_se3[rows] @ se3_inverse(self.T_velo_imu), oxts.timestamps_s[rows], f"{self.name}_gt_lidar",
                          meta={"paired": f"OXTS packet f as the pose of frame f, at the packet's own stamp ({why})"})

    def _lidar_poses_at(self, times_s: np.ndarray) -> Trajectory:
        """LiDAR poses at ``times_s`` (s since the epoch): the IMU poses of the OXTS packets at their own stamps,
        interpolated (slerp, linear position; at constant velocity up to 1.5 packet intervals beyond the first or last
        packet), then moved to the Velodyne."""
        oxts = self.oxts_poses
        if len(oxts) < 2:
            raise DataError("interpolating needs two or more OXTS packets", source=self.drive_dir / "oxts" / "data")
        reach_s = 1.5 * float(np.median(np.diff(oxts.timestamps_s)))
        imu = oxts.interpolated(times_s, max_extrapolation_s=reach_s)
        return Trajectory(imu.poses_se3 @ se3_inverse(self.T_velo_imu), imu.timestamps_s, f"{self.name}_gt_lidar")

    @property
    def ground_truth(self) -> Trajectory | None:
        """LiDAR poses of the scans in the ENU frame of the first GPS fix at the scans' Velodyne stamps (the sweep
        middle), interpolated between the OXTS packets (:meth:`ground_truth_at`), or None when there are no scans."""
        if not self.scan_paths:
            return None
        gt = self.ground_truth_at(self.scan_frames)
        meta = {"frame": "lidar", "pose_instant": "mid", **gt.meta}
        stamps = self.timestamps_s  # (paired by frame: stamped as the scans, as a run pairs them; None without stamps)
        return Trajectory(gt.poses_se3, gt.timestamps_s if "paired" not in meta else stamps, gt.name, meta=meta)

    def ground_truth_at_instant(self, instant: str) -> Trajectory:
        """The scans' LiDAR poses at the ``instant`` (start, mid or end) of every sweep: the OXTS poses at their own
        stamps, interpolated at the scans' stamps moved by half the stamps' median interval (:meth:`_lidar_poses_at`);
        DataError without Velodyne time stamps."""
        if instant not in INSTANT_FRACTION:
            raise DataError(f"unknown instant {instant!r}; valid: {', '.join(INSTANT_FRACTION)}", source=self.drive_dir)
        stamps = self.timestamps_s
        if stamps is None or len(stamps) < 2:
            raise DataError("re-timing the ground truth needs the Velodyne time stamps of two or more scans", source=self.velodyne_dir)
        period = float(np.median(np.diff(self._velo_times_all)))
        times = stamps + (INSTANT_FRACTION[instant] - 0.5) * period
        lidar = self._lidar_poses_at(times)
        how = (f"the {len(self.oxts_paths)} OXTS poses, at their own stamps, interpolated {INSTANT_FRACTION[instant] - 0.5:+.1f} "
               "sweep from the scans' stamps")
        return Trajectory(lidar.poses_se3, times, lidar.name, meta={"frame": "lidar", "pose_instant": instant, "retimed": how})

    # ---- data -------------------------------------------------------------------------------------------
    def read_scan(self, index: int) -> Scan:
        """The ``index``-th Velodyne scan (float32 x, y, z, reflectance)."""
        if not self.scan_paths:
            raise DataError("no Velodyne scans (velodyne_points/data/*.bin) in this drive", source=self.velodyne_dir)
        index = checked_index(index, len(self), f"{self.name} ({self.drive_dir})")
        frame = int(self.scan_frames[index])
        times = self.timestamps_s  # (a timestamps.txt that does not cover the scans is an error, not a missing stamp)
        ts = None if times is None else float(times[index])
        dropped: list[str] = []
        scan = read_kitti_bin(self.scan_paths[index], frame=frame, timestamp_s=ts, drop_nonfinite=self.drop_nonfinite, dropped=dropped)
        said_once(self.reader_warnings, dropped)
        if self._correct:
            scan = dataclasses.replace(scan, points_xyz=correct_vertical_angle(scan.points_xyz))
        fractions = sweep_fraction_from_azimuth(scan.points_xyz) if self.point_times == "azimuth" else None
        return dataclasses.replace(scan, point_times_s=fractions, point_time_convention="fraction", stamp_instant="mid")

    def read_image(self, index: int) -> np.ndarray:
        """The ``index``-th image of camera 0 (gray left) as uint8."""
        if not self.image_paths:
            raise DataError("no images (image_00/data/*.png) in this drive", source=self.drive_dir / "image_00")
        index = checked_index(index, len(self.image_paths), f"{self.name} ({self.drive_dir})", "image")
        return read_gray_image(self.image_paths[index], frame=int(self.image_frames[index]))


def sweep_fraction_from_azimuth(points_xyz: np.ndarray) -> np.ndarray:
    """Each point's place in a clockwise sweep that starts facing backwards (0 at azimuth +180 degrees, 0.5 facing
    forward, 1 at -180 degrees), as kiss-icp's KITTI raw loader times a scan."""
    return 0.5 * (1.0 - np.arctan2(points_xyz[:, 1], points_xyz[:, 0]) / np.pi)


__all__ = ["KittiRaw", "is_drive_folder", "read_kitti_raw_timestamps", "sweep_fraction_from_azimuth"]
