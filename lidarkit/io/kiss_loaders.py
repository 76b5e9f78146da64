"""Every other kiss-icp dataloader (``kiss_icp.datasets``) as a lidarkit scan sequence.

Each class here wraps one kiss-icp loader: it checks what the loader would otherwise print-and-exit on
(missing packages, a missing file), builds the loader inside :func:`~lidarkit.io.rosbag.guarded_loader`, and
turns its frames into :class:`~lidarkit.io.base.Scan` (points, per-point times in the convention that loader
uses) and its ``gt_poses`` into a :class:`~lidarkit.trajectory.Trajectory`.

Ground truth is given exactly as kiss-icp's loader holds it (the frame kiss-icp evaluates in, named in
``meta["frame"]``); ``meta["pose_instant"]`` is None (kiss-icp's loaders do not say which instant of the sweep).
kiss-icp's ``kitti``, ``kitti_raw`` and ``tum`` loaders are the kinds ``kiss_kitti``, ``kiss_kitti_raw`` and
``kiss_tum`` (lidarkit has its own readers under the plain names).
"""

from __future__ import annotations

import dataclasses
import logging
import os
import re
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

from lidarkit.errors import ConfigError, DataError, not_increasing
from lidarkit.io.base import Scan, checked_index, checked_indices, option_path, stamps_in_seconds
from lidarkit.geometry import _within_limits
from lidarkit.io.rosbag import guarded_loader, require_modules
from lidarkit.trajectory import Trajectory

log = logging.getLogger(__name__)

#: kiss-icp loader name -> lidarkit dataset kind
KISS_KINDS = {
    "apollo": "apollo", "boreas": "boreas", "generic": "generic", "helipr": "helipr", "kitti": "kiss_kitti",
    "kitti_raw": "kiss_kitti_raw", "mcap": "mcap", "mulran": "mulran", "ncd": "ncd", "nclt": "nclt",
    "nuscenes": "nuscenes", "ouster": "ouster", "rosbag": "rosbag", "tum": "kiss_tum",
}
#: kiss-icp loader name -> its class in ``kiss_icp.datasets.<name>``
KISS_CLASSES = {
    "apollo": "ApolloDataset", "boreas": "BoreasDataset", "generic": "GenericDataset", "helipr": "HeLiPRDataset",
    "kitti": "KITTIOdometryDataset", "kitti_raw": "KITTIRawDataset", "mcap": "McapDataloader", "mulran": "MulranDataset",
    "ncd": "NewerCollegeDataset", "nclt": "NCLTDataset", "nuscenes": "NuScenesDataset", "ouster": "OusterDataloader",
    "rosbag": "RosbagDataset", "tum": "TUMDataset",
}
OUSTER_EXTRA = "pip install 'lidarkit[ouster]'  (ouster-sdk)"


class KissLoaderScans:
    """A kiss-icp dataloader as a ``ScanSequence`` (subclasses fix the loader and its options)."""

    loader_name = ""
    #: how the loader's per-point times are expressed (see ``lidarkit.io.base.PointTimeConvention``)
    point_time_convention = "fraction"
    #: module -> pip line, checked before the loader is built
    requires: dict[str, str] = {}
    #: what the loader's gt_poses are
    ground_truth_frame = "as kiss-icp's loader gives it"
    #: points with NaN / infinite coordinates left out (with a warning) instead of refused (the file readers' option)
    drop_nonfinite = False
    #: numbers in each row of the ground-truth file of :meth:`_pose_file`
    pose_columns = 0

    def __init__(self, path: str | os.PathLike, **loader_options: Any):
        self.path = Path(os.path.abspath(path))  # (nclt:. built its ground-truth file name from "." and found none)
        #: what the reader found and left out, for the run's warnings (metrics.json, config.yaml) as well as the log
        self.reader_warnings: list[str] = []
        self._origin_warned = False  # (points at (0, 0, 0) are said once, not for every frame)
        self._nonfinite_warned = False
        require_modules(self.requires, self.kind)
        if not self.path.exists():
            raise DataError(f"{self.kind} dataset not found", source=self.path)
        self.loader_options = {k: v for k, v in loader_options.items() if v is not None}
        self._check_pose_rows()
        self.loader = self._build()
        self.name = f"{self.kind}:{getattr(self.loader, 'sequence_id', self.path.name)}"
        self._stamp_cache: tuple[np.ndarray | None] | None = None

    def _pose_file(self) -> tuple[Path, int, list[Path] | None] | None:
        """(ground-truth file of :attr:`pose_columns` numbers a row, its header lines, the scan files it must give one
        pose each or None where the loader pairs them by time); None: nothing to check before the loader is built."""
        return None

    def _check_pose_rows(self) -> None:
        """The ground-truth file's rows read as numbers, :attr:`pose_columns` each, and one row per scan where the
        loader pairs them by count, said before the loader fails on it (numpy's words naming the folder, an
        AssertionError without a message, or a broadcasting error)."""
        found = self._pose_file()
        if found is None or not found[0].is_file():
            return
        path, header, scans = found
        rows = len(_read_pose_table(path, self.pose_columns, header))
        if scans is not None and rows != len(scans):
            raise DataError(f"{rows} ground-truth poses for {len(scans)} scans: one pose per scan needed", source=path)

    @property
    def kind(self) -> str:
        return KISS_KINDS[self.loader_name]

    @property
    def reader_options(self) -> dict[str, Any]:
        return {"kind": self.kind, "path": str(self.path.absolute()), "kiss_icp_loader": self.loader_name, **self.loader_options}

    def _build(self) -> Any:
        import importlib

        module = importlib.import_module(f"kiss_icp.datasets.{self.loader_name}")
        cls = getattr(module, KISS_CLASSES[self.loader_name])
        with guarded_loader(self.loader_name, str(self.path)):
            return cls(self.path, **self.loader_options)

    def __len__(self) -> int:
        return len(self.loader)

    def __repr__(self) -> str:
        """One line, as the other readers' (it was Python's ``<... object at 0x...>``)."""
        return f"{type(self).__name__}({str(self.path)!r}, kind={self.kind!r}, scans={len(self)})"

    def read_scan(self, index: int) -> Scan:
        n = len(self)
        index = checked_index(index, n, self.path, from_end=False)
        source = self._scan_file(index)
        with guarded_loader(self.loader_name, str(source), location=f"frame {index}"):
            item = self.loader[index]
        points, times = item if isinstance(item, tuple) else (item, None)
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if not len(points) and source != self.path:  # (a garbage PCD read as "empty scan" naming the folder; loaders swallow why)
            size = os.path.getsize(source) if os.path.isfile(source) else None
            raise DataError("empty scan file (0 bytes)" if size == 0 else "no points read: an empty or unreadable scan file",
                            source=source, location=f"frame {index}")
        times = None if times is None or np.size(times) == 0 else np.asarray(times, dtype=np.float64).ravel()
        if times is not None and len(times) != len(points):
            raise DataError(f"{len(times)} per-point times for {len(points)} points", source=source, location=f"frame {index}")
        if times is not None and not np.isfinite(times).all():
            raise DataError("per-point times contain NaN or infinite values", source=source, location=f"frame {index}")
        if len(points) and not _within_limits(points):  # (a flat reduction first: NaN fails it)
            points, times = self._without_nonfinite_points(points, times, source, index)
        if len(points) and (points[:, 0] == 0).any():  # (x alone first, as the point-file readers: most scans have none)
            points, times = self._without_origin_points(points, times, source, index)
        stamps = self.timestamps_s
        stamp = None if stamps is None or index >= len(stamps) else float(stamps[index])
        named = str(source) if source != self.path else f"{self.path} frame {index}"  # (the file, as other readers' scans)
        return Scan(points, None, times, stamp, index, named, self.point_time_convention, None)

    def _scan_file(self, index: int) -> str | Path:
        """The file of scan ``index`` where the loader lists its scans (a message names the file, not the folder);
        NCLT's and Newer College's loaders list bare names, read from their scan folders. Else the dataset path."""
        files = getattr(self.loader, "scan_files", None)
        if not isinstance(files, (list, tuple, np.ndarray)) or len(files) != len(self):
            return self.path
        name = str(files[index])
        folder = getattr(self.loader, "scans_dir", None) or getattr(self.loader, "scan_folder", None)
        return os.path.join(folder, name) if folder and not os.path.isabs(name) else name

    def _without_nonfinite_points(self, points: np.ndarray, times: np.ndarray | None, source: Any,
                                  index: int) -> tuple[np.ndarray, np.ndarray | None]:
        """``points`` and their ``times`` without the points holding NaN or infinite coordinates (an organized cloud's
        missing returns, as PCL and Ouster write them) when ``drop_nonfinite`` is set, said once per reader; else a
        DataError naming the file and the option, as the point-file readers say it (the scan reached the
        registration, whose error named neither)."""
        ok = np.isfinite(points).all(axis=1)
        n_bad = int(len(ok) - np.count_nonzero(ok))
        if not n_bad:
            return points, times
        if not self.drop_nonfinite:
            import inspect

            takes_it = "drop_nonfinite" in inspect.signature(type(self)).parameters
            way_out = (f"drop them with drop_nonfinite=true ({self.kind}:PATH?drop_nonfinite=true)" if takes_it else
                       f"the {self.kind} reader keeps every point (kiss-icp's loader): a reader of the files themselves "
                       "(kitti:, folder:) drops them with drop_nonfinite=true")
            raise DataError(f"{n_bad} of {len(ok)} points are NaN or infinite (first at point {int(np.argmin(ok))}); {way_out}",
                            source=source, location=f"frame {index}")
        if n_bad == len(ok):
            raise DataError(f"all {n_bad} points are NaN or infinite: no point left", source=source, location=f"frame {index}")
        if not self._nonfinite_warned:
            self._nonfinite_warned = True
            self.reader_warnings.append(f"left out {n_bad} of {len(ok)} points with NaN or infinite coordinates in frame {index} "
                                        f"({source}); in later frames without another warning")
            log.warning("%s: %s", self.path, self.reader_warnings[-1])
        return points[ok], None if times is None else times[ok]

    def _without_origin_points(self, points: np.ndarray, times: np.ndarray | None, source: Any,
                               index: int) -> tuple[np.ndarray, np.ndarray | None]:
        """``points`` (N, 3) and their ``times`` (N,) without the points exactly at (0, 0, 0), an organized cloud's
        missing returns, which every point-file reader leaves out (registered, they are points moving with the
        sensor); said once per reader in :attr:`reader_warnings`, a DataError when no point is left."""
        from lidarkit.io.pointfile import at_sensor_origin

        at_origin = at_sensor_origin(points)
        n_zero = int(np.count_nonzero(at_origin))
        if not n_zero:
            return points, times
        if n_zero == len(points):
            raise DataError(f"all {n_zero} points are at (0, 0, 0) (missing returns): no point left", source=source,
                            location=f"frame {index}")
        if not self._origin_warned:
            self._origin_warned = True
            self.reader_warnings.append(f"left out {n_zero} of {len(points)} points at (0, 0, 0) (missing returns) in frame "
                                        f"{index} ({source}); in later frames without another warning")
            log.warning("%s: %s", self.path, self.reader_warnings[-1])
        keep = ~at_origin
        return points[keep], None if times is None else times[keep]

    def _stamps(self) -> np.ndarray | None:
        get = getattr(self.loader, "get_frames_timestamps", None)
        if get is None:
            return None
        try:
            with guarded_loader(self.loader_name, str(self.path)):
                stamps = np.asarray(get(), dtype=np.float64).ravel()
        except DataError:
            return None
        return stamps if len(stamps) == len(self) else None

    @property
    def timestamps_s(self) -> np.ndarray | None:
        """The scans' stamps (s), read once (read_scan asks for them every frame)."""
        if self._stamp_cache is None:
            self._stamp_cache = (self._stamps(),)
        return self._stamp_cache[0]

    @property
    def ground_truth(self) -> Trajectory | None:
        poses = getattr(self.loader, "gt_poses", None)
        if poses is None:
            return None
        poses = np.asarray(poses, dtype=np.float64)
        if len(poses) != len(self):
            raise DataError(f"{len(poses)} ground-truth poses for {len(self)} scans: one pose per scan needed", source=self.path)
        stamps = self.timestamps_s
        return Trajectory(poses, stamps if stamps is not None and len(stamps) == len(poses) else None, name=f"{self.name}_gt",
                          meta={"frame": self.ground_truth_frame, "pose_instant": None, "kiss_icp_loader": self.loader_name})


class KissKittiScans(KissLoaderScans):
    """KITTI odometry as kiss-icp reads it (vertical-angle correction applied, GT in the LiDAR frame)."""

    loader_name = "kitti"
    point_time_convention = "relative_s"
    ground_truth_frame = "LiDAR frame (Tr^-1 P Tr, kiss-icp's KITTI loader)"

    def __init__(self, path: str | os.PathLike, sequence: str | int = "00"):
        try:
            number = int(sequence)
        except (TypeError, ValueError):
            raise ConfigError(f"sequence must be a number such as 00, got {sequence!r}", source="sequence") from None
        if not (Path(path) / "sequences" / f"{number:02d}" / "velodyne").is_dir():
            raise DataError(f"no sequences/{number:02d}/velodyne/ (kiss-icp's KITTI loader reads the odometry root)", source=path)
        super().__init__(path, sequence=f"{number:02d}")

    @property
    def reader_options(self) -> dict[str, Any]:
        """The base's, with the vertical-angle correction kiss-icp's KITTI loaders apply to every scan (a run recorded
        "none reported by the reader" for points each moved by 0.205 deg)."""
        from lidarkit.io.kitti import correction_options

        return {**KissLoaderScans.reader_options.fget(self), **correction_options(True, True)}  # (shared with the raw kind)

    @property
    def _frames(self) -> list[int]:
        """The KITTI frame number of each scan present (its file name): an excerpt need not start at 0."""
        return [int(Path(f).stem) for f in self.loader.scan_files]

    def _stamps(self) -> np.ndarray | None:
        """times.txt rows of the scans present (kiss-icp's loader returns the whole file)."""
        from lidarkit.textfile import read_numeric_table

        path = self.path / "sequences" / f"{int(self.loader.sequence_id):02d}" / "times.txt"
        if not path.is_file():
            return None
        # (a bad row is a DataError naming the file and line; nanoseconds read as the kitti reader reads them)
        times = stamps_in_seconds(read_numeric_table(path, 1)[:, 0], path)
        frames = self._frames
        return times[frames] if frames and max(frames) < len(times) else None

    @property
    def ground_truth(self) -> Trajectory | None:
        if not hasattr(self.loader, "gt_poses"):
            return None
        gt = np.asarray(self.loader.gt_poses, dtype=np.float64)
        frames = self._frames
        if frames and max(frames) >= len(gt):
            raise DataError(f"{len(gt)} ground-truth poses, but the scans reach frame {max(frames)}", source=self.path)
        # the rows of the scans present, by frame number (an excerpt from frame 5 on is not frames 0, 1, ...), stamped
        # by their times.txt rows (it had no stamps)
        return Trajectory(gt[frames], self.timestamps_s, name=f"{self.name}_gt",
                          meta={"frame": self.ground_truth_frame, "pose_instant": None})


class KissKittiRawScans(KissLoaderScans):
    """KITTI raw drives mapped to odometry sequences, as kiss-icp's ``kitti_raw`` loader reads them."""

    loader_name = "kitti_raw"
    requires = {"pykitti": "pip install pykitti"}

    def __init__(self, path: str | os.PathLike, sequence: str | int = "00"):
        if isinstance(sequence, bool) or not str(sequence).strip().isdigit():
            raise ConfigError(f"a KITTI odometry sequence number (0-10), got {sequence!r}", source="kiss_kitti_raw dataset option sequence")
        super().__init__(path, sequence=f"{int(sequence):02d}")

    reader_options = KissKittiScans.reader_options  # (kiss-icp's raw loader corrects every drive as its KITTI loader)


class KissTumScans(KissLoaderScans):
    """TUM RGB-D depth images as point clouds (kiss-icp's ``tum`` loader). Ground truth: each depth frame's nearest
    ``groundtruth.txt`` pose within ``max_dt_s``, as lidarkit's ``tum`` reader pairs its images (kiss-icp's loader
    took the nearest pose at any distance and merged the frames sharing one: one gap refused the whole run)."""

    loader_name = "tum"
    point_time_convention = "relative_s"
    #: the farthest (s) a depth frame's ground-truth pose may be stamped from it (lidarkit's tum reader's default)
    max_dt_s = 0.02

    def __init__(self, path: str | os.PathLike):
        for needed in ("depth.txt", "groundtruth.txt", "rgb"):
            if not (Path(path) / needed).exists():
                raise DataError(f"a TUM RGB-D sequence folder needs {needed}", source=path)
        super().__init__(path)

    @property
    def ground_truth(self) -> Trajectory | None:
        return self.ground_truth_of(None)

    def ground_truth_of(self, scans: np.ndarray | list[int] | None) -> Trajectory | None:
        """:attr:`ground_truth` of the depth frames numbered ``scans`` only (None: all): the frames a gap in the ground
        truth leaves out of its reach are named, and ``--frames`` can score the others."""
        from lidarkit.io.tum import associate_nearest

        stamps = self.timestamps_s
        if stamps is None:
            return super().ground_truth
        path = self.path / "groundtruth.txt"
        gt = Trajectory.from_tum(path)
        numbers = np.arange(len(stamps)) if scans is None else checked_indices(scans, len(stamps), self.path, from_end=False)
        nearest = associate_nearest(stamps[numbers], gt.timestamps_s, self.max_dt_s)
        unpaired = np.flatnonzero(nearest < 0)
        if len(unpaired):
            first = int(numbers[unpaired[0]])
            apart = float(np.min(np.abs(gt.timestamps_s - stamps[first])))
            which = "depth frames" if len(numbers) == len(stamps) else "selected depth frames"
            raise DataError(f"{len(unpaired)} of {len(numbers)} {which} have no pose within {self.max_dt_s} s, the first: "
                            f"frame {first} at t={stamps[first]:.6f} s (the nearest pose is {apart:.3f} s away): one pose "
                            "per scan needed (--frames can pick the frames it covers)", source=path)
        return Trajectory(gt.poses_se3[nearest], stamps[numbers], name=f"{self.name}_gt",
                          meta={"frame": self.ground_truth_frame, "pose_instant": None, "kiss_icp_loader": self.loader_name})


#: suffix: (what the file is, the dataset kind that reads it) for recordings given to the ouster reader (an MCAP read
#: "no sensor metadata: an Ouster pcap needs the .json")
OTHER_RECORDINGS = {".mcap": ("an MCAP file", "mcap"), ".bag": ("a ROS bag", "rosbag")}


class OusterScans(KissLoaderScans):
    """An Ouster ``.pcap`` with its sensor metadata ``.json`` (``meta``, a relative one found from the working directory
    or beside the pcap; default: the json beside it with the longest common name prefix, as kiss-icp looks for it).
    Per-point times are the column fraction in [0, 1). A file of another suffix is refused by what it is, and the
    ouster-sdk is checked before the metadata (without it, an MCAP read "no sensor metadata: an Ouster pcap needs the
    .json")."""

    loader_name = "ouster"
    requires = {"ouster.sdk": OUSTER_EXTRA}

    def __init__(self, path: str | os.PathLike, meta: str | None = None):
        pcap = Path(path)
        if not pcap.is_file():
            raise DataError("Ouster pcap not found (the ouster reader takes one .pcap file)", source=pcap)
        if pcap.suffix.lower() != ".pcap":
            what, kind = OTHER_RECORDINGS.get(pcap.suffix.lower(), ("a file", None))
            read_by = f": {kind}:{path} reads it" if kind else ""
            raise DataError(f"{what}, not an Ouster .pcap (the ouster reader takes a .pcap with its metadata .json){read_by}",
                            source=pcap)
        require_modules(self.requires, self.kind)  # (before the metadata: without the package nothing reads)
        super().__init__(pcap, meta=ouster_metadata(pcap, meta))


def ouster_metadata(pcap: Path, meta: str | None) -> str | None:
    """The sensor metadata json of ``pcap``: the one ``meta`` names (relative: from the working directory, else beside
    the pcap, as other readers' path options), None for kiss-icp's own look-up beside it; DataError when there is none."""
    if meta is not None:
        found = option_path(meta, pcap.parent)
        if not found.is_file():
            raise DataError(f"Ouster metadata json not found, neither from the working directory nor beside the pcap in "
                            f"{pcap.parent}", source=meta)
        return str(found)
    if not list(pcap.parent.glob("*.json")):
        raise DataError("no sensor metadata: an Ouster pcap needs the .json recorded with it (beside it, or meta=PATH)",
                        source=pcap, location="frame 0")
    return None


def nclt_points(path: str | os.PathLike) -> np.ndarray:
    """One NCLT ``velodyne_sync`` file: x, y, z as little-endian uint16 at 5 mm from -100 m, then intensity and laser
    id bytes (NCLT's own ``read_vel_sync.py``: ``'<HHHBB'``), turned to z up as kiss-icp does (x, -y, -z). kiss-icp's
    loader reads them as int16: every coordinate beyond 63.835 m came back 327.68 m short. A file cut short, or
    empty, is a DataError naming it (numpy read the whole points in it, without a word)."""
    dtype = np.dtype([("xyz", "<u2", 3), ("intensity", "u1"), ("laser", "u1")])
    size = os.path.getsize(path)
    if size % dtype.itemsize:
        raise DataError(f"{size} bytes is not a whole number of {dtype.itemsize}-byte points", source=path)
    if size == 0:
        raise DataError("no points (an empty file)", source=path)
    raw = np.fromfile(path, dtype=dtype)
    xyz = raw["xyz"].astype(np.float64) * 0.005 - 100.0
    return xyz * np.array([1.0, -1.0, -1.0])


class NcltScans(KissLoaderScans):
    """NCLT (``velodyne_sync`` + ``ground_truth``), kiss-icp's ``nclt`` loader with the points read as NCLT stores
    them (:func:`nclt_points`); the scans outside the ground truth's time span are left out, as the loader does
    (with a warning saying how many). Stamps: the file names (microseconds)."""

    loader_name = "nclt"
    point_time_convention = "relative_s"

    def __init__(self, path: str | os.PathLike):
        super().__init__(path)
        self.loader.read_point_cloud = nclt_points
        on_disk = len([p for p in (self.path / "velodyne_sync").iterdir() if p.is_file()])
        if on_disk > len(self.loader):
            self.reader_warnings.append(f"{on_disk - len(self.loader)} of {on_disk} scans lie outside the ground truth's time "
                                        "span and are left out (kiss-icp's NCLT loader reads only scans with ground truth)")
            log.warning("%s: %s", self.path, self.reader_warnings[-1])

    def _stamps(self) -> np.ndarray | None:
        return np.asarray(self.loader.timestamps, dtype=np.float64) * 1e-6


class MulranScans(KissLoaderScans):
    """MulRan (Ouster ``.bin`` + ``global_pose.csv``), kiss-icp's ``mulran`` loader. Stamps: the file names
    (nanoseconds); a scan outside the span of ``global_pose.csv`` is a DataError (the loader gives it the nearest pose,
    the last one for every scan past the end)."""

    loader_name = "mulran"
    pose_columns = 13

    def __init__(self, path: str | os.PathLike):
        super().__init__(path)

    def _pose_file(self) -> tuple[Path, int, list[Path] | None] | None:
        return self.path / "global_pose.csv", 0, None  # (paired by time: more poses than scans)

    def _stamps(self) -> np.ndarray | None:
        return np.asarray(self.loader.scan_timestamps, dtype=np.float64) * 1e-9

    @property
    def ground_truth(self) -> Trajectory | None:
        return self.ground_truth_of(None)

    def ground_truth_of(self, scans: np.ndarray | list[int] | None) -> Trajectory | None:
        """:attr:`ground_truth` of the scans numbered ``scans`` only (None: all): a recording whose ``global_pose.csv``
        covers part of its scans is scored on that part (``--frames``)."""
        stamps_ns = _read_pose_table(self.path / "global_pose.csv", self.pose_columns, 0)[:, 0]
        scans_ns = np.asarray(self.loader.scan_timestamps, dtype=np.float64)
        numbers = np.arange(len(scans_ns)) if scans is None else checked_indices(scans, len(scans_ns), self.path, from_end=False)
        picked = scans_ns[numbers]
        outside = numbers[(picked < stamps_ns.min() - 5e7) | (picked > stamps_ns.max() + 5e7)]  # half a 10 Hz sweep
        if len(outside):
            which = "scans" if scans is None else "selected scans"
            raise DataError(f"{len(outside)} of {len(numbers)} {which} (the first: scan {outside[0]}) lie outside the poses' time "
                            f"span ({stamps_ns.min() * 1e-9:.3f} to {stamps_ns.max() * 1e-9:.3f} s): one pose per scan needed "
                            "(--frames can pick the scans it covers)", source=self.path / "global_pose.csv")
        everything = super().ground_truth
        return everything if scans is None or everything is None else everything[numbers]


class NewerCollegeScans(KissLoaderScans):
    """Newer College (``raw_format/ouster_scan/*.pcd`` + ``ground_truth``), kiss-icp's ``ncd`` loader with the
    clouds read by Open3D (kiss-icp's pyntcloud fails on binary PCD files under numpy 2), every point kept so that the
    64 x 1024 per-point times still fit."""

    loader_name = "ncd"

    def __init__(self, path: str | os.PathLike, drop_nonfinite: bool = False):
        super().__init__(path)
        self.drop_nonfinite = drop_nonfinite
        self.loader.PyntCloud = _Open3DPcd

    def _stamps(self) -> np.ndarray | None:
        """The scans' stamps from their file names, ``cloud_SECONDS_NANOSECONDS.pcd`` (the loader sorts by them and
        gives none)."""
        found = [re.match(r"cloud_(\d+)_(\d+)", Path(name).name) for name in self.loader.scan_files]
        if not found or not all(found):
            return None
        return np.array([int(m[1]) + int(m[2]) * 1e-9 for m in found], dtype=np.float64)


class _Open3DPcd:
    """What kiss-icp's ``ncd`` loader asks of pyntcloud (``from_file(path).points[["x", "y", "z"]].to_numpy()``)."""

    def __init__(self, xyz: np.ndarray):
        self._xyz = xyz

    @classmethod
    def from_file(cls, path: str) -> "_Open3DPcd":
        import open3d as o3d

        cloud = o3d.io.read_point_cloud(str(path), remove_nan_points=False, remove_infinite_points=False)
        return cls(np.asarray(cloud.points, dtype=np.float64))

    @property
    def points(self) -> "_Open3DPcd":
        return self

    def __getitem__(self, columns) -> "_Open3DPcd":
        return self

    def to_numpy(self) -> np.ndarray:
        return self._xyz


#: struct format characters of kiss-icp's HeLiPR loader -> numpy types (standard sizes, little endian)
_STRUCT_TYPES = {"f": "<f4", "B": "u1", "H": "<u2", "I": "<u4", "L": "<u4", "l": "<i4"}


class HeliprScans(KissLoaderScans):
    """HeLiPR (``LiDAR/<sensor>`` + ``LiDAR_GT``), kiss-icp's ``helipr`` loader; ``sequence`` is the sensor. Files are
    read whole with numpy (the loader unpacked them point by point and dropped each file's last point). Stamps: the
    file names (nanoseconds)."""

    loader_name = "helipr"
    pose_columns = 8
    SENSORS = ("Avia", "Aeva", "Ouster", "Velodyne")

    def __init__(self, path: str | os.PathLike, sequence: str = "Ouster"):
        if not isinstance(sequence, str) or sequence not in self.SENSORS:
            raise ConfigError(f"unknown HeLiPR sensor {sequence!r}; known: {', '.join(self.SENSORS)}", source="helipr sequence")
        super().__init__(path, sequence=sequence)
        self.loader.get_data = self._records
        self.loader.read_timestamps = self._sweep_fractions

    def _pose_file(self) -> tuple[Path, int, list[Path]] | None:
        sensor = self.loader_options["sequence"]
        return (self.path / "LiDAR_GT" / f"global_{sensor}_gt.txt", 0, sorted((self.path / "LiDAR" / sensor).glob("*.bin")))

    def _records(self, index: int) -> np.ndarray:
        loader = self.loader
        path = loader.scan_files[index]
        fmt = loader.format_string
        if loader.sequence_id == "Aeva" and int(Path(path).stem) <= 1691936557946849179:  # early Aeva files: no intensity
            loader.intensity_channel, fmt = None, loader.format_string_no_intensity
        dtype = np.dtype([(f"c{i}", _STRUCT_TYPES[c]) for i, c in enumerate(fmt)])
        size = os.path.getsize(path)
        if size % dtype.itemsize:
            raise DataError(f"{size} bytes is not a whole number of {dtype.itemsize}-byte points", source=path)
        raw = np.fromfile(path, dtype=dtype)
        if len(raw) == 0:
            raise DataError("no points", source=path)
        return np.column_stack([raw[name].astype(np.float64) for name in dtype.names])

    def _sweep_fractions(self, records: np.ndarray) -> np.ndarray:
        """``(N,)`` each point's place in its sweep, 0 to 1, from the time column of ``records`` (N, columns); zeros for a
        time column of one value, as a bag's: the run reads such a scan without per-point times, with a warning
        (kiss-icp's loader divided by the zero span: NaN times, refused)."""
        times = records[:, self.loader.time_channel]
        span = np.ptp(times)
        return np.zeros(len(times)) if span == 0 else (times - times.min()) / span

    def _stamps(self) -> np.ndarray | None:
        return np.asarray(self.loader.scan_timestamps, dtype=np.float64) * 1e-9


class BoreasScans(KissLoaderScans):
    """Boreas (``lidar/*.bin`` + ``applanix/lidar_poses.csv``), kiss-icp's ``boreas`` loader. Stamps: the file names
    (microseconds)."""

    loader_name = "boreas"
    pose_columns = 13

    def __init__(self, path: str | os.PathLike):
        super().__init__(path)

    def _pose_file(self) -> tuple[Path, int, list[Path]] | None:
        return self.path / "applanix" / "lidar_poses.csv", 1, sorted((self.path / "lidar").glob("*.bin"))

    def _stamps(self) -> np.ndarray | None:
        try:
            return np.array([int(Path(f).stem) for f in self.loader.scan_files], dtype=np.float64) * 1e-6
        except ValueError:  # files not named by their time
            return None


class ApolloScans(KissLoaderScans):
    """Apollo-SouthBay (``pcds`` + ``poses/gt_poses.txt``), kiss-icp's ``apollo`` loader."""

    loader_name = "apollo"
    pose_columns = 9
    point_time_convention = "relative_s"

    def __init__(self, path: str | os.PathLike):
        super().__init__(path)

    def _pose_file(self) -> tuple[Path, int, list[Path]] | None:
        return self.path / "poses" / "gt_poses.txt", 0, sorted((self.path / "pcds").glob("*.pcd"))

    def _stamps(self) -> np.ndarray | None:
        """The second column of ``poses/gt_poses.txt`` (number, time in s, x y z, quaternion): its rows are the scans'
        in order, as kiss-icp pairs the poses with them (the scans had no stamps, the ground truth none)."""
        from lidarkit.textfile import data_line_numbers, read_numeric_table

        path = self.path / "poses" / "gt_poses.txt"
        stamps = read_numeric_table(path, 9)[:, 1]
        back = np.flatnonzero(np.diff(stamps) <= 0)
        if len(back):
            k = int(back[0]) + 1
            raise DataError(f"time stamps (column 2) are not strictly increasing ({not_increasing(stamps[k], stamps[k - 1])})",
                            source=path, location=f"line {data_line_numbers(path)[k]}")
        return stamps if len(stamps) == len(self) else None


class NuScenesScans(KissLoaderScans):
    """nuScenes scene ``sequence`` (number), kiss-icp's ``nuscenes`` loader (needs nuscenes-devkit)."""

    loader_name = "nuscenes"
    requires = {"nuscenes": "pip install nuscenes-devkit"}
    point_time_convention = "relative_s"

    def __init__(self, path: str | os.PathLike, sequence: str | int = "0061"):
        super().__init__(path, sequence=str(sequence))


class GenericScans(KissLoaderScans):
    """A folder of point-cloud files of one kind (``.bin`` KITTI format, ``.pcd``, ``.ply``, ...), kiss-icp's
    ``generic`` loader; per-point times from a ``t``/``timestamp``/``time`` attribute of PCD/PLY files, in the
    units the bag reader reads them (:func:`~lidarkit.io.pointcloud2.checked_point_times`: integers are nanoseconds,
    as Ouster's uint32 ``t``; floats seconds)."""

    loader_name = "generic"
    point_time_convention = "relative_s"

    def __init__(self, path: str | os.PathLike, drop_nonfinite: bool = False):
        from kiss_icp.datasets import supported_file_extensions

        from lidarkit.io.folder import natural_key, sorted_by_name
        from lidarkit.io.pointfile import POINT_FILE_SUFFIXES

        folder = Path(path)
        if not folder.is_dir():
            raise DataError("the generic reader takes a folder of point-cloud files", source=folder)
        extensions = supported_file_extensions()
        files = sorted(p for p in folder.iterdir() if p.is_file())
        read = [p for p in files if p.name.endswith(tuple(extensions))]  # the files kiss-icp's loader picks
        if not read:
            raise DataError(f"no point-cloud files ({', '.join(extensions)})", source=folder)
        formats = Counter(p.suffix for p in read)
        if len(formats) > 1:  # (the loader read every file as the first one's format: reshape errors or NaN points)
            counts = ", ".join(f"{n} {suffix}" for suffix, n in sorted(formats.items()))
            raise DataError(f"point-cloud files of {len(formats)} formats ({counts}): kiss-icp's generic loader reads every "
                            "file as the first one's format; keep one format, or read the folder as folder:PATH", source=folder)
        point_suffixes = {*POINT_FILE_SUFFIXES, *(f".{e}" for e in extensions)}
        skipped = [p.name for p in files if p not in read and p.suffix.lower() in point_suffixes]
        left_out = (f"{len(skipped)} point-cloud files that kiss-icp's generic loader does not read are skipped "
                    f"({', '.join(skipped)}); folder:PATH reads them")
        if skipped:  # (scan2.BIN and .npy scans were left out without a word)
            log.warning("%s: %s", folder, left_out)
        _check_header(sorted(read, key=lambda f: natural_key(f.name))[0], None)  # the loader reads one file to pick its reader
        super().__init__(folder)
        if skipped:  # (then only logged: the run's warnings did not say it)
            self.reader_warnings.append(left_out)
        # in folder:PATH's order (natsort read time-stamp names 1000.1 before 1000.05: sweeps out of order, no word)
        self.loader.scan_files = np.array([str(f) for f in sorted_by_name([Path(f) for f in self.loader.scan_files])],
                                          dtype=str)
        # the time field's type in the files (the loader hands every field over as float64: Ouster's uint32
        # nanoseconds were read as seconds, a 0.1 s sweep as one of 1e8 s)
        self.drop_nonfinite = drop_nonfinite
        self._time_field = getattr(getattr(self.loader, "_read_point_cloud", None), "time_field", None)
        self._time_dtype = None if self._time_field is None else _field_dtype(Path(self.loader.scan_files[0]), self._time_field)
        if self._time_field is None:
            self._say_skipped_time_field(Path(self.loader.scan_files[0]))

    def _say_skipped_time_field(self, first: Path) -> None:
        """A time field the loader found no times in because Open3D skips its PLY type (uint, ushort...), said in the
        run's warnings: the run went on without deskew saying only "no per-point times found"."""
        from lidarkit.io.folder import GENERIC_TIME_FIELDS
        from lidarkit.io.pointfile import open3d_skipped_type, point_file_fields

        fields = point_file_fields(first)
        field = next((f for f in GENERIC_TIME_FIELDS if f in fields), None)
        kind = None if field is None else open3d_skipped_type(first, field)
        if kind is None:
            return
        self.reader_warnings.append(f"per-point times not read: the scans carry them in the {field!r} field, of PLY type "
                                    f"{kind} (e.g. {first.name}), which Open3D cannot read (kiss-icp's generic loader reads "
                                    "with it); store them as float, double or int")
        log.warning("%s: %s", self.path, self.reader_warnings[-1])

    def read_scan(self, index: int) -> Scan:
        files = self.loader.scan_files
        if 0 <= index < len(files):  # (an index out of range is refused by the base class, naming the range)
            _check_header(Path(files[index]), index)
        scan = super().read_scan(index)
        if scan.point_times_s is None or self._time_dtype is None:
            return scan
        from lidarkit.io.pointcloud2 import check_sweep_span, checked_point_times, time_unit_read

        raw = scan.point_times_s.astype(self._time_dtype)  # (exact: the loader's float64 of the file's values)
        hint = "folder:PATH reads the scans without per-point times"
        times, convention = checked_point_times(raw, scan.points_xyz, what=f"the {self._time_field!r} field", within="one scan",
                                                hint=hint, source=files[index], location=f"frame {index}", stamp_s=scan.timestamp_s)
        # (no stamps to compare with: a sweep under a millisecond is another unit, as microseconds read as nanoseconds)
        check_sweep_span(float(np.ptp(times)), None, what=f"the {self._time_field!r} field", unit=time_unit_read(raw.dtype),
                         over="this scan", hint=hint, source=files[index], location=f"frame {index}")
        return dataclasses.replace(scan, point_times_s=times, point_time_convention=convention)


def _read_pose_table(path: Path, ncols: int, header_lines: int) -> np.ndarray:
    """``(N, ncols)`` rows of a ground-truth file after its ``header_lines`` (0 or 1: Boreas's column names), a bad row
    a DataError naming the file and its line."""
    from lidarkit.textfile import read_numeric_table

    header = ""
    if header_lines:
        with open(path, encoding="utf-8-sig", errors="replace") as f:
            header = f.readline().strip()
    # (the header, the file's first line, is skipped as the loader skips it: as a comment line of its own text)
    return read_numeric_table(path, ncols, **({"comment": header} if header else {}))


def _field_dtype(path: Path, field: str) -> np.dtype | None:
    """numpy type of the per-point attribute ``field`` of a point-cloud file as Open3D reads it (None if it has none)."""
    import open3d as o3d

    from lidarkit.io.pointfile import open3d_quiet

    with open3d_quiet(o3d):
        cloud = o3d.t.io.read_point_cloud(str(path))
    return cloud.point[field].numpy().dtype if field in cloud.point else None


def _check_header(path: Path, frame: int | None) -> None:
    """The point-file readers' header checks on a ``.pcd`` / ``.ply`` before kiss-icp's generic loader hands it to
    Open3D (a .pcd without z failed as "pip install kiss-icp[all] is required" with Open3D's coloured warnings), and
    a .pcd with repeated ``_`` padding fields refused: Open3D aborted the process on it (folder:PATH reads it)."""
    from lidarkit.io.pointfile import check_pcd_counts, check_ply_counts

    suffix = path.suffix.lower()
    if suffix == ".pcd":
        header = check_pcd_counts(path, frame)
        if header.padded:
            raise DataError(f"repeated padding fields _ (FIELDS {' '.join(header.fields)}): Open3D, which kiss-icp's generic "
                            "loader reads with, aborts the process on repeated field names; folder:PATH reads these files "
                            "(without per-point times)", source=path, location=None if frame is None else f"frame {frame}")
    elif suffix == ".ply":
        check_ply_counts(path, frame)


__all__ = [
    "KISS_KINDS", "ApolloScans", "BoreasScans", "GenericScans", "HeliprScans", "KissKittiRawScans", "KissKittiScans",
    "KissLoaderScans", "KissTumScans", "MulranScans", "NcltScans", "NewerCollegeScans", "NuScenesScans", "OusterScans",
    "ouster_metadata",
]
