"""KITTI odometry reader: Velodyne scans, grayscale images, calibration, times and ground-truth poses.

Layout (``root`` is the odometry root, or a sequence folder itself)::

    root/sequences/NN/velodyne/000000.bin   float32 x, y, z, intensity
    root/sequences/NN/image_0/000000.png    8-bit grayscale (left camera)
    root/sequences/NN/calib.txt             "P0: 12 numbers" ... "Tr: 12 numbers" (or bare lines P0, P1, ...)
    root/sequences/NN/times.txt             one time stamp [s] per frame (above 1e15: nanoseconds, converted)
    root/poses/NN.txt                       3x4 row-major T_world_cam0 per frame (or sequences/NN/poses.txt)
    root/sequences/NN/point_times/000000.npy   optional: one time per point [s from the sweep start]

Per-point times (KITTI proper has none) are looked for in the first folder of :data:`POINT_TIME_FOLDERS`
that exists beside the scans' folder (``point_times/`` as lidarkit's simulator writes it, then the names other
tools use), then in the sequence folder (the same one, unless ``velodyne_dir`` names another); ``point_times_dir``
says which one was found (None: no per-point times), ``point_time_search_dirs`` where they were looked for.

Frame numbers come from the file names, so a folder holding only some scans (``000094.bin``,
``000095.bin``) reads poses row 94 and 95. Ground truth is given in the camera frame as stored
(``ground_truth_camera``) and in the LiDAR frame (``ground_truth``): ``T_lidar_i = Tr^-1 P_i Tr``
with ``Tr = T_cam0_velo`` from calib.txt.
"""

from __future__ import annotations

import dataclasses
import logging
import os
import re
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from lidarkit.errors import ConfigError, DataError, not_increasing
from lidarkit.geometry import se3_inverse
from lidarkit.io.base import (INSTANT_FRACTION, Scan, checked_index, checked_indices, keep_once, option_path,
                              stamps_in_seconds)
from lidarkit.io.pointcloud2 import (MAX_SWEEP_S, check_sweep_span, checked_point_times, point_times_seconds,
                                     recording_time_convention, time_unit_read)
from lidarkit.io.pointfile import at_sensor_origin, load_npy, read_kitti_bin, said_once
from lidarkit.textfile import file_line, is_number, read_lines, read_numeric_table
from lidarkit.trajectory import READ_WARNINGS, Trajectory

log = logging.getLogger(__name__)

#: Folders searched, in this order, beside the scans' folder and then in the sequence folder, for per-point times
#: ``{frame:06d}.npy`` (1-D, one time per point of the scan, seconds from the sweep start); docs/datasets.md lists the
#: same names (a test checks it).
POINT_TIME_FOLDERS = ("point_times", "timestamps", "times", "point_timestamps")
#: frames whose per-point times' median span is checked against times.txt's spacing (their unit: MIN_SWEEP_SHARE)
POINT_TIME_SPAN_FRAMES = 5
#: KITTI's HDL-64 vertical-angle correction, as kiss-icp's KITTI loader applies it (``_correct_kitti_scan``)
KITTI_VERTICAL_CORRECTION_DEG = 0.205
#: fx (px) of KITTI's rectified cameras, one per recording day (2011_09_26, _28, _29, _30, 10_03): a calib.txt with one
#: of them is KITTI's own (its HDL-64 needs the vertical correction), not a user's recording in the KITTI layout
KITTI_FOCAL_LENGTHS_PX = np.array([721.5377, 707.0493, 718.3351, 707.0912, 718.856])

#: methods whose reference pipeline reads KITTI with the correction (``vertical_correction="auto"`` turns it on):
#: kiss-icp's and genz-icp's own KITTI (and KITTI raw) loaders both apply it
CORRECTED_BY_DEFAULT = ("kiss", "genz")

CALIB_KEYS_IN_ORDER = ("P0", "P1", "P2", "P3", "Tr")  # meaning of bare (prefix-less) calib lines
_TR_ALIASES = ("Tr", "Tr_velo_to_cam", "Tr_velo_cam")


def read_kitti_calib(path: str | os.PathLike, *, warnings: list[str] | None = None) -> dict[str, np.ndarray]:
    """Parse a KITTI odometry ``calib.txt`` into ``{"P0".."P3": (3, 4), "Tr": (4, 4) T_cam0_velo}``.

    Accepts ``KEY: 12 numbers`` lines and the prefix-less variant (bare rows of 12 numbers taken as
    P0, P1, P2, P3, Tr in order). Other ``KEY:`` lines are kept as flat float arrays.
    A line that is not 12 numbers for P0..P3/Tr raises DataError naming file and line; ``warnings``: as for
    :func:`lidarkit.textfile.read_lines` (a file cut inside its last number).
    """
    calib: dict[str, np.ndarray] = {}
    n_bare = 0
    for lineno, raw in enumerate(read_lines(path, warnings=warnings), start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        key, sep, rest = line.partition(":")
        if sep and not is_number(key.strip()):
            key = key.strip()
            fields = rest.split()
        else:
            if n_bare >= len(CALIB_KEYS_IN_ORDER):
                raise DataError(
                    f"more than {len(CALIB_KEYS_IN_ORDER)} unlabelled calibration rows", source=path, location=f"line {lineno}"
                )
            key, fields = CALIB_KEYS_IN_ORDER[n_bare], line.split()
            n_bare += 1
        try:
            values = np.array([float(f) for f in fields], dtype=np.float64)
        except ValueError:
            raise DataError(f"{key}: not a number in {rest.strip() if sep else line!r}", source=path, location=f"line {lineno}") from None
        if not np.isfinite(values).all():
            raise DataError(f"{key}: NaN or infinite value", source=path, location=f"line {lineno}")
        if key in _TR_ALIASES:
            key = "Tr"
        if key in CALIB_KEYS_IN_ORDER:
            if values.size != 12:
                raise DataError(f"{key}: expected 12 numbers (3x4 matrix), found {values.size}", source=path, location=f"line {lineno}")
            if key == "Tr":
                T = np.eye(4)
                T[:3, :4] = values.reshape(3, 4)
                R = T[:3, :3]
                err = float(np.abs(R.T @ R - np.eye(3)).max())
                if err > 1e-3 or np.linalg.det(R) <= 0:  # KITTI prints ~9 digits: a rigid Tr is orthonormal to ~1e-6
                    what = "a reflection (det < 0)" if err <= 1e-3 else f"not a rotation (max |R^T R - I| = {err:.2e})"
                    raise DataError(f"Tr (LiDAR-to-camera) is not rigid: its 3x3 block is {what}", source=path,
                                    location=f"line {lineno}")
                calib[key] = T
            else:
                calib[key] = values.reshape(3, 4)
        else:
            calib[key] = values
    if "P0" not in calib:
        raise DataError("no P0 projection matrix", source=path)
    return calib


_FRAME_NAME = re.compile(r"^(\d+)$")


def indexed_files(folder: Path, suffix: str) -> tuple[list[Path], np.ndarray]:
    """Files ``<digits><suffix>`` in ``folder`` sorted by frame number; ``(paths, frames (N,) int)``.

    A file with this suffix whose stem is not a number raises DataError (frames must be known).
    """
    paths: list[tuple[int, Path]] = []
    for p in folder.iterdir():
        if p.suffix.lower() != suffix:
            continue
        if p.is_symlink() and not p.exists():  # a scan that is not there: never skipped without a word
            raise DataError(f"a broken link (to {os.readlink(p)})", source=p)
        if not p.is_file():
            continue
        m = _FRAME_NAME.match(p.stem)
        if m is None:
            raise DataError(f"file name is not a frame number (expected e.g. 000042{suffix})", source=p)
        paths.append((int(m.group(1)), p))
    paths.sort()
    frames = np.array([f for f, _ in paths], dtype=np.int64)
    dup = np.flatnonzero(np.diff(frames) == 0)
    if len(dup):
        raise DataError(f"two files for frame {frames[dup[0]]}", source=folder)
    return [p for _, p in paths], frames


class KittiOdometry:
    """One KITTI odometry sequence (``ScanSequence``; ``as_image_sequence()`` gives the ``ImageSequence``).

    ``len(ds)`` is the number of scans, or the number of images for an image-only sequence
    (``n_scans`` / ``n_images`` give both). ``read_scan(i)`` / ``read_image(i)`` take the position
    in the sorted file list; ``read_scan_by_frame(f)`` the KITTI frame number. ``timestamps_s``,
    ``ground_truth`` and ``ground_truth_camera`` have one entry per item of ``frames`` (the scans,
    or the images for an image-only sequence).

    ``ground_truth`` is in the LiDAR frame for a sequence with scans (``ScanSequence``) and in the
    camera frame for an image-only one (``ImageSequence``, whose calib often has no Tr);
    ``ground_truth_frame="lidar"|"camera"`` forces one. ``ground_truth_lidar`` and
    ``ground_truth_camera`` are always available explicitly.

    Options: ``velodyne_dir`` / ``image_dir`` replace ``sequences/NN/velodyne`` / ``image_0`` (e.g. a
    folder of extra frames used with this sequence's calib and poses), ``poses_file`` another pose
    file (e.g. ``poses_semantickitti.txt``), ``calib_file`` / ``times_file`` likewise;
    ``drop_nonfinite`` drops NaN/inf points instead of raising, said once in ``reader_warnings`` (a run's metrics.json).

    ``vertical_correction``: rotate every point about the axis perpendicular to its azimuth by
    :data:`KITTI_VERTICAL_CORRECTION_DEG` (KITTI's HDL-64 calibration error, corrected exactly as kiss-icp's KITTI
    loader does, through kiss-icp's own ``_correct_kitti_scan``). ``True`` / ``False`` force it; ``"auto"``
    (default) applies it when an odometry run of a method in :data:`CORRECTED_BY_DEFAULT` (kiss, genz) asks through
    :meth:`configure_for_method` on KITTI's own recordings (:attr:`recorded_by_kitti`), so that "kiss through
    lidarkit" is kiss-icp's own experiment (and genz genz-icp's), and never to another folder in the KITTI layout (a
    user's recording, the simulator's export: no HDL-64 behind it). Read directly, "auto" reads the points as stored. ``reader_options`` records what was applied.
    """

    def __init__(
        self,
        root: str | os.PathLike,
        sequence: str | int | None = None,
        *,
        drop_nonfinite: bool = False,
        velodyne_dir: str | os.PathLike | None = None,
        image_dir: str | os.PathLike | None = None,
        poses_file: str | os.PathLike | None = None,
        calib_file: str | os.PathLike | None = None,
        times_file: str | os.PathLike | None = None,
        ground_truth_frame: str = "auto",
        vertical_correction: bool | str = "auto",
    ):
        self.vertical_correction = check_vertical_correction(vertical_correction)
        self._correct = vertical_correction is True
        if ground_truth_frame not in ("auto", "lidar", "camera"):
            raise ConfigError(
                f"unknown ground_truth_frame {ground_truth_frame!r}; known: auto, lidar, camera", source="ground_truth_frame"
            )
        # None: 00, or the sequence folder given (a sequence asked of a sequence folder must be its own, 00 too)
        asked = None if sequence is None else str(sequence)
        self.sequence = "00" if asked is None else f"{int(asked):02d}" if asked.isdigit() else asked
        self.drop_nonfinite = drop_nonfinite
        #: what the reader left out (NaN or infinite points, under drop_nonfinite) and files cut inside their last
        #: number (poses, times, calib: read as cut), for the run's warnings: once each
        self.reader_warnings: list[str] = []
        root = Path(root)
        if not root.is_dir():
            raise DataError("dataset folder not found" if not root.exists() else "not a folder", source=root)
        root = Path(os.path.abspath(root))  # ("00" or "." from sequences/: no parent named sequences/, no name, no truth)
        self.root = root
        self.sequence_dir, odometry_root = self._locate_sequence(root, asked)
        # titled after the folder: kitti_NN for a numbered KITTI sequence, the folder's own name otherwise
        folder = self.sequence_dir.name
        self.name = f"kitti_{self.sequence}" if folder.isdigit() or folder == self.sequence else folder

        self.velodyne_dir = self._option_path(velodyne_dir) if velodyne_dir is not None else self.sequence_dir / "velodyne"
        self.image_dir = self._option_path(image_dir) if image_dir is not None else self.sequence_dir / "image_0"
        for given, folder in ((velodyne_dir, self.velodyne_dir), (image_dir, self.image_dir)):
            if given is not None and not folder.is_dir():
                raise DataError("folder not found", source=folder)
        self.scan_paths, self.scan_frames = (
            indexed_files(self.velodyne_dir, ".bin") if self.velodyne_dir.is_dir() else ([], np.zeros(0, np.int64))
        )
        self.image_paths, self.image_frames = (
            indexed_files(self.image_dir, ".png") if self.image_dir.is_dir() else ([], np.zeros(0, np.int64))
        )
        if not self.scan_paths and not self.image_paths:
            raise DataError(
                f"no scans ({self.velodyne_dir.name}/*.bin) and no images ({self.image_dir.name}/*.png)",
                source=self.sequence_dir,
            )

        self.calib_path = self._option_path(calib_file) if calib_file is not None else self.sequence_dir / "calib.txt"
        self.times_path = self._option_path(times_file) if times_file is not None else self.sequence_dir / "times.txt"
        if calib_file is not None and not self.calib_path.is_file():  # checked now, as the other files given are
            raise DataError("calib file not found", source=self.calib_path)
        if times_file is not None and not self.times_path.is_file():
            raise DataError("times file not found", source=self.times_path)
        self.poses_path = self._locate_poses(poses_file, odometry_root)
        # beside the scans first: a velodyne_dir of extra frames keeps its point_times/ next to it, not in the sequence
        self.point_times_dir = next(
            (folder / d for folder in self.point_time_search_dirs for d in POINT_TIME_FOLDERS if (folder / d).is_dir()), None
        )
        self._check_counts()
        if ground_truth_frame == "auto":
            ground_truth_frame = "lidar" if self.scan_paths else "camera"
        self.ground_truth_frame = ground_truth_frame

    # ---- options -----------------------------------------------------------------------------------
    @property
    def point_time_search_dirs(self) -> tuple[Path, ...]:
        """The folders searched, in order, for a per-point time folder: the one holding the scans' folder, then the
        sequence folder (one folder in KITTI's own layout)."""
        return tuple(dict.fromkeys((Path(os.path.abspath(self.velodyne_dir)).parent, self.sequence_dir)))

    @property
    def simulated(self) -> bool:
        """True for a folder written by lidarkit's simulator (``sim.yaml`` beside ``velodyne/``)."""
        return (self.sequence_dir / "sim.yaml").is_file()

    @property
    def snapshot_sweeps(self) -> bool:
        """True for the simulator's snapshot sweeps (``motion_distortion: false`` in its ``sim.yaml``): every point of
        a sweep taken at one instant, so there is nothing to deskew (a run says so rather than that times are missing)."""
        return self._sim_config.get("motion_distortion") is False

    @cached_property
    def recorded_by_kitti(self) -> bool:
        """True for KITTI's own recordings (its HDL-64): a ``calib.txt`` whose camera focal length is one of KITTI's
        rectified calibrations (:data:`KITTI_FOCAL_LENGTHS_PX`), and no ``sim.yaml``. A user's recording kept in the
        KITTI layout has another camera, or none."""
        if self.simulated or not self.calib_path.is_file():
            return False
        try:
            P0 = self.calib.get("P0")
        except DataError:
            return False
        return P0 is not None and bool(np.isclose(P0[0, 0], KITTI_FOCAL_LENGTHS_PX, atol=1e-3).any())

    def configure_for_method(self, method: str) -> None:
        """Resolve ``vertical_correction="auto"`` for an odometry run of ``method`` (on for kiss and genz on KITTI's
        own recordings, :attr:`recorded_by_kitti`)."""
        if self.vertical_correction == "auto":
            self._correct = method in CORRECTED_BY_DEFAULT and self.recorded_by_kitti

    @property
    def reader_options(self) -> dict:
        """What the reader did to the data, for the run config."""
        return {"kind": "kitti", "path": str(self.sequence_dir.absolute()),
                # (named as the attribute, not as the option: regression checks compare a pinned spec's options by name)
                "poses_path": None if self.poses_path is None else str(Path(self.poses_path).absolute()),
                **correction_options(self.vertical_correction, self._correct)}

    # ---- layout ------------------------------------------------------------------------------------
    def _locate_sequence(self, root: Path, asked: str | None) -> tuple[Path, Path | None]:
        """(sequence folder, odometry root or None when ``root`` is the sequence folder itself). ``asked``: the
        ``sequence`` given, or None; on a sequence folder one other than the folder's own is refused (an explicit 00
        or a name such as ``xyz`` read sequence 05 without a word)."""
        candidate = root / "sequences" / self.sequence
        if candidate.is_dir():
            return candidate, root
        if (root / "velodyne").is_dir() or (root / "image_0").is_dir() or (root / "calib.txt").is_file():
            numbered = root.name.isdigit()
            same_number = numbered and asked is not None and asked.isdigit() and int(asked) == int(root.name)
            if asked is not None and asked != root.name and not same_number:
                itself = f"sequence {root.name} itself" if numbered else "one sequence itself (no sequences/ inside)"
                raise ConfigError(f"the folder is {itself}; sequence={asked} names another (give the odometry root that "
                                  "holds sequences/)", source=root)
            if numbered:
                self.sequence = root.name
            parent = root.parent.parent if root.parent.name == "sequences" else None
            return root, parent
        raise DataError(
            f"sequence {self.sequence} not found (expected sequences/{self.sequence}/ or a folder with velodyne/, image_0/, calib.txt)",
            source=root,
        )

    def _option_path(self, given: str | os.PathLike) -> Path:
        """A path option as given, or inside the dataset folder or the sequence folder
        (``poses_file=sequences/00/poses_semantickitti.txt`` with the root): :func:`lidarkit.io.base.option_path`."""
        return option_path(given, self.root, self.sequence_dir)

    def _locate_poses(self, poses_file: str | os.PathLike | None, odometry_root: Path | None) -> Path | None:
        if poses_file is not None:
            path = self._option_path(poses_file)
            if not path.is_file():
                raise DataError("poses file not found", source=path)
            return path
        candidates = [self.sequence_dir / "poses.txt"]
        if odometry_root is not None:
            candidates.insert(0, odometry_root / "poses" / f"{self.sequence}.txt")
        return next((p for p in candidates if p.is_file()), None)

    def _check_counts(self) -> None:
        """The pose and time files are read (a malformed line is an error at open); their lengths may differ (an
        excerpt: a copied sequence folder with a trimmed poses.txt beside the full times.txt, or frames 10-30 of it).
        Whether they reach the frames is checked where those frames' poses or stamps are taken (:meth:`_check_covered`):
        a pose file that stops at frame 99 refused every run, ``--frames 0:12`` of the frames it covers too."""
        n_poses = len(self._poses_camera_all) if self.poses_path is not None else None
        n_times = len(self._times_all) if self._times_all is not None else None
        images = self.image_frames
        if n_times is not None and not len(self.scan_frames) and len(images) and n_times <= images[-1]:
            # an image sequence's stamps said as an image folder's are (it compared them with the 1101 poses)
            raise DataError(f"{n_times} time stamps for {len(images)} images (frames {images[0]}-{images[-1]}: "
                            f"{images[-1] + 1} needed, one per frame from 0)", source=self.times_path)
        if n_poses is not None and n_times is not None and n_poses != n_times:
            last = max((int(f[-1]) for f in (self.scan_frames, self.image_frames) if len(f)), default=-1)
            if min(n_poses, n_times) > last:
                log.info("%s: %d poses and %d time stamps; both cover the frames present (up to %d)", self.sequence_dir,
                         n_poses, n_times, last)

    def _check_covered(self, frames: Any, count: int, what: str, source: Path) -> None:
        """DataError when a file of ``count`` rows (``what``: poses, time stamps) stops before one of the KITTI frame
        numbers ``frames`` that is a scan or image present, naming the last such file and its frame (the frames a
        run selects: the rest of the folder may reach beyond the file); other frames are left to the caller."""
        asked = np.asarray(frames).ravel()
        if asked.dtype.kind not in "iuf":  # (text, None: the caller's index check names them)
            return
        for kind, paths, numbers in (("scan", self.scan_paths, self.scan_frames), ("image", self.image_paths, self.image_frames)):
            short = np.flatnonzero(np.isin(numbers, asked) & (numbers >= count))
            if len(short):
                k = int(short[-1])
                raise DataError(f"{count} {what} but {kind} {paths[k].name} is frame {numbers[k]}", source=source)

    def _stamps_of(self, frames: np.ndarray) -> np.ndarray | None:
        """times.txt's stamps of the KITTI frame numbers ``frames`` ((k,) int), None without times.txt; a file that
        stops before one of them is a DataError naming the frame."""
        if self._times_all is None:
            return None
        self._check_covered(frames, len(self._times_all), "time stamps", self.times_path)
        beyond = frames[frames >= len(self._times_all)]
        if len(beyond):  # a frame number asked of ground_truth_at that no file holds
            raise DataError(f"{len(self._times_all)} time stamps but frame {int(beyond[0])} is asked for", source=self.times_path)
        return self._times_all[frames]

    # ---- sizes and frames ----------------------------------------------------------------------------
    @property
    def n_scans(self) -> int:
        return len(self.scan_paths)

    @property
    def n_images(self) -> int:
        return len(self.image_paths)

    @property
    def frames(self) -> np.ndarray:
        """``(len,)`` KITTI frame numbers of the scans (of the images for an image-only sequence)."""
        return self.scan_frames if self.scan_paths else self.image_frames

    def __len__(self) -> int:
        return self.n_scans if self.scan_paths else self.n_images

    def __repr__(self) -> str:
        return f"KittiOdometry({str(self.sequence_dir)!r}, scans={self.n_scans}, images={self.n_images})"

    # ---- calibration ---------------------------------------------------------------------------------
    @cached_property
    def calib(self) -> dict[str, np.ndarray]:
        """``P0..P3`` (3, 4) projection matrices and ``Tr`` (4, 4) = ``T_cam0_velo`` when present."""
        read_warnings: list[str] = []
        calib = read_kitti_calib(self.calib_path, warnings=read_warnings)
        keep_once(self.reader_warnings, read_warnings)
        return calib

    @property
    def K(self) -> np.ndarray:
        """(3, 3) intrinsics of the left grayscale camera (from P0)."""
        return self.calib["P0"][:, :3].copy()

    @property
    def T_cam0_velo(self) -> np.ndarray:
        """(4, 4) LiDAR-to-camera transform ``Tr``; DataError when calib.txt has none."""
        if "Tr" not in self.calib:
            raise DataError("no Tr (velodyne-to-camera) line: LiDAR-frame poses need it", source=self.calib_path)
        return self.calib["Tr"].copy()

    # ---- times and poses ---------------------------------------------------------------------------
    @cached_property
    def _times_all(self) -> np.ndarray | None:
        if not self.times_path.is_file():
            return None
        read_warnings: list[str] = []
        times = read_numeric_table(self.times_path, 1, what="time stamps file", warnings=read_warnings)[:, 0]
        keep_once(self.reader_warnings, read_warnings)
        # (nanoseconds were written to a run's poses_tum.txt as seconds, which lidarkit eval refused)
        times = stamps_in_seconds(times, self.times_path)
        bad = np.flatnonzero(np.diff(times) <= 0)
        if len(bad):  # (the values said, as the runner says them: "not strictly increasing" alone sent one to look)
            k = int(bad[0])
            why = not_increasing(times[k + 1], times[k], f"frame {k}")
            raise DataError(f"time stamps are not strictly increasing: {why}", source=self.times_path,
                            location=file_line(self.times_path, f"frame {k + 1}"))
        return times

    @cached_property
    def _poses_camera_all(self) -> Trajectory:
        gt = Trajectory.from_kitti(self.poses_path, name=f"{self.name}_gt",
                                   format_hint=lambda other: self._other_format_hint(self.poses_path, other))
        keep_once(self.reader_warnings, gt.meta.get(READ_WARNINGS, ()))
        return gt

    def _other_format_hint(self, path: Path, fmt: str) -> str:
        """How to use the pose file ``path`` in ``fmt`` with this sequence, which reads KITTI rows only: its images as
        an image folder, which reads either format (the reader's default named ``--format``, which ``lidarkit vo``
        has not, and ``Trajectory.from_tum``, which pairs no pose with a frame), else the file converted."""
        if self.image_paths:
            calib = f" --calib {self.calib_path}" if self.calib_path.is_file() else ""
            return (f"a KITTI sequence's poses are KITTI rows; give its images as an image folder: lidarkit vo "
                    f"{self.image_dir} --kind images{calib} --poses {path} --poses-format {fmt} "
                    f"(ImageFolder(..., poses_format='{fmt}'))")
        return (f"a KITTI sequence's poses are KITTI rows; convert the file: "
                f"Trajectory.from_{fmt}(path).to_kitti(new_path)")

    @property
    def sequence_timestamps_s(self) -> np.ndarray | None:
        """Every time stamp in times.txt (one per frame of the full sequence), or None."""
        return None if self._times_all is None else self._times_all.copy()

    @property
    def timestamps_s(self) -> np.ndarray | None:
        """``(len,)`` time stamps [s] of ``frames`` from times.txt, or None without times.txt (a DataError naming the
        frame when times.txt stops before one)."""
        return self._stamps_of(self.frames)

    def ground_truth_at(self, frames: np.ndarray | list[int] | None = None, *, frame: str = "lidar") -> Trajectory | None:
        """GT poses of the given KITTI frame numbers (all rows when None) in the ``"lidar"`` or ``"camera"`` frame.

        Returns None when the sequence has no pose file.
        """
        if self.poses_path is None:
            return None
        gt = self._poses_camera_all
        if frames is not None:
            self._check_covered(frames, len(gt), "poses", self.poses_path)  # (before the index check: it names the file)
            gt = self._rows(gt, frames, self.poses_path)
        elif self._times_all is not None:
            n = min(len(gt), len(self._times_all))  # an excerpt may trim one of the files to the frames present
            gt = gt[:n].with_timestamps(self._times_all[:n])
        if gt.timestamps_s is not None and self._poses_shift_s:  # the simulator's poses_start.txt named: its own instant
            gt = gt.with_timestamps(gt.timestamps_s + self._poses_shift_s)
        if frame == "camera":
            return gt
        if frame != "lidar":
            raise ConfigError(f"unknown pose frame {frame!r}; known: lidar, camera", source="frame")
        gt = self._in_lidar_frame(gt)
        instant = self._simulated_instant
        return gt if instant is None else Trajectory(gt.poses_se3, gt.timestamps_s, gt.name, meta={**gt.meta, "pose_instant": instant})

    def ground_truth_at_instant(self, instant: str) -> Trajectory:
        """Ground truth of ``frames`` (LiDAR frame) at another instant of each sweep: a folder written by lidarkit's
        simulator keeps ``poses_{instant}.txt`` beside ``poses.txt``; DataError for any other folder, which has only the
        one instant of ``poses.txt``, and for a pose file of the user's own named by ``poses_file`` (it stood in for the
        simulator's and the file named was never read)."""
        path = self.sequence_dir / f"poses_{instant}.txt"
        if instant not in INSTANT_FRACTION or self._simulator_pose_instant is None or not path.is_file():
            raise DataError(f"no ground truth at the sweep {instant} (only the simulator's folders keep poses_{instant}.txt)",
                            source=self.sequence_dir)
        if self._simulated_instant is None:
            raise DataError(f"no ground truth at the sweep {instant}: the poses file named is not one of the simulator's "
                            "(poses.txt, poses_start/mid/end.txt), whose other instants are known", source=self.poses_path)
        gt = Trajectory.from_kitti(path, name=f"{self.name}_gt", format_hint=lambda other: self._other_format_hint(path, other))
        keep_once(self.reader_warnings, gt.meta.get(READ_WARNINGS, ()))
        gt = self._in_lidar_frame(self._rows(gt, self.frames, path))
        times = gt.timestamps_s
        if times is not None:  # times.txt is at poses.txt's instant: moved by the fraction of the period
            times = times + self._instant_shift_s(instant)
        kept = {READ_WARNINGS: gt.meta[READ_WARNINGS]} if READ_WARNINGS in gt.meta else {}
        return Trajectory(gt.poses_se3, times, gt.name,
                          meta={"pose_instant": instant, "retimed": f"the simulator's poses_{instant}.txt", **kept})

    def _rows(self, gt: Trajectory, frames: np.ndarray | list[int], source: Path) -> Trajectory:
        """The poses of KITTI frame numbers ``frames`` of a whole-sequence pose file, with their times.txt stamps (and
        its ``meta``: a cut-off last line read is said by the scores of what is held against it)."""
        frames = checked_indices(frames, len(gt), source, "frame", from_end=False)  # (1.5 read frame 1)
        return Trajectory(gt.poses_se3[frames], self._stamps_of(frames), gt.name, dict(gt.meta))

    def _in_lidar_frame(self, gt: Trajectory) -> Trajectory:
        """Camera-frame poses ``P`` as LiDAR-frame poses ``Tr^-1 P Tr``."""
        Tr = self.T_cam0_velo
        return gt.transformed(T_left=se3_inverse(Tr), T_right=Tr).with_name(f"{self.name}_gt_lidar")

    @cached_property
    def _simulated_instant(self) -> str | None:
        """The sweep instant of the pose file in a folder written by lidarkit's simulator (sim.yaml): its poses.txt's,
        or ``X`` for its ``poses_X.txt``; else None (unknown). The paths are compared resolved: the folder's own
        poses.txt named by another path (absolute, relative) lost its instant, and kiss was scored against the wrong
        one without a word, as it was when poses_start.txt was named."""
        if self.poses_path is None or self._simulator_pose_instant is None:
            return None
        try:
            named = Path(self.poses_path).resolve()
            if named == (Path(self.sequence_dir) / "poses.txt").resolve():
                return self._simulator_pose_instant
            return next((i for i in INSTANT_FRACTION if named == (Path(self.sequence_dir) / f"poses_{i}.txt").resolve()), None)
        except OSError:
            return None

    @property
    def _poses_shift_s(self) -> float:
        """Seconds from times.txt's instant (poses.txt's) to the named pose file's (0 unless a poses_X.txt is named)."""
        instant = self._simulated_instant
        return 0.0 if instant is None else self._instant_shift_s(instant)

    def _instant_shift_s(self, instant: str) -> float:
        """Seconds from the simulator's poses.txt instant to sweep ``instant`` (a fraction of :attr:`_period_s`)."""
        if self._period_s is None:
            return 0.0
        return (INSTANT_FRACTION[instant] - INSTANT_FRACTION[self._simulator_pose_instant]) * self._period_s

    @cached_property
    def _period_s(self) -> float | None:
        """The median spacing of times.txt; with one stamp, the period of sim.yaml's ``frame_rate_hz`` (so a one-sweep
        export is re-timed too); None without times.txt or either."""
        if self._times_all is None:
            return None
        if len(self._times_all) >= 2:
            return float(np.median(np.diff(self._times_all)))
        try:
            return 1.0 / float(self._sim_config["frame_rate_hz"])
        except (TypeError, KeyError, ValueError, ZeroDivisionError):
            return None

    @cached_property
    def _sim_config(self) -> dict[str, Any]:
        """The simulator's ``sim.yaml`` beside the scans (read once), {} for any other folder or an unreadable file."""
        if not self.simulated:
            return {}
        import yaml

        try:
            config = yaml.safe_load((self.sequence_dir / "sim.yaml").read_text())
        except (OSError, yaml.YAMLError):
            return {}
        return config if isinstance(config, dict) else {}

    @cached_property
    def _simulator_pose_instant(self) -> str | None:
        """``pose_instant`` of the simulator's ``sim.yaml`` (its poses.txt and times.txt refer to it), else None."""
        instant = self._sim_config.get("pose_instant")
        return instant if instant in ("start", "mid", "end") else None

    def relative_pose(self, frame_a: int, frame_b: int, *, frame: str = "lidar") -> np.ndarray:
        """(4, 4) ground-truth motion ``T_a_b`` from KITTI frame ``frame_b`` to ``frame_a`` (e.g. 94 -> 95).

        This is the ``T_target_source`` a registration of scan b (source) onto scan a (target) should find.
        """
        # looked up in increasing order (a trajectory's stamps increase: b before a, a loop closure or a backward
        # registration, was "timestamps are not strictly increasing"), composed in the order asked
        gt = self.ground_truth_at(sorted({frame_a, frame_b}), frame=frame)
        if gt is None:
            raise DataError("no ground-truth pose file for this sequence", source=self.sequence_dir)
        if frame_a == frame_b:  # (the stored rotations hold 7 digits: inverse times itself was 4e-7 from identity)
            return np.eye(4)
        pose = dict(zip(sorted({frame_a, frame_b}), gt.poses_se3))
        return se3_inverse(pose[frame_a]) @ pose[frame_b]

    @property
    def ground_truth_camera(self) -> Trajectory | None:
        """GT ``T_cam0start_cam0`` of ``frames`` as stored in the pose file (camera frame), or None."""
        return self.ground_truth_at(self.frames, frame="camera")

    @property
    def ground_truth_lidar(self) -> Trajectory | None:
        """GT of ``frames`` in the LiDAR frame ``T_lidar0_lidar_i = Tr^-1 P_i Tr``, or None without poses."""
        return self.ground_truth_at(self.frames, frame="lidar")

    @property
    def ground_truth(self) -> Trajectory | None:
        """GT of ``frames`` in ``ground_truth_frame`` (LiDAR for scan sequences, camera for image-only ones)."""
        return self.ground_truth_at(self.frames, frame=self.ground_truth_frame)

    def ground_truth_of(self, scans: np.ndarray | list[int]) -> Trajectory | None:
        """:attr:`ground_truth` of the items at positions ``scans`` of ``frames`` only, as a run selects them: a pose
        file that stops before the folder's last scan scores a run of the frames it covers (``--frames 0:12``)."""
        if self.poses_path is None:
            return None
        positions = checked_indices(scans, len(self.frames), f"{self.name} ({self.sequence_dir})", from_end=False)
        return self.ground_truth_at(self.frames[positions], frame=self.ground_truth_frame)

    # ---- data ------------------------------------------------------------------------------------------
    def read_scan(self, index: int) -> Scan:
        """The ``index``-th scan (position in ``scan_paths``) with its KITTI frame number and time stamp.

        When ``point_times_dir`` (the first of :data:`POINT_TIME_FOLDERS` in :attr:`point_time_search_dirs`, e.g.
        ``point_times/`` as written by :func:`lidarkit.sim.lidar.export_kitti`) holds ``{frame:06d}.npy`` (one time per
        point, seconds from the sweep start) it becomes ``Scan.point_times_s`` (float64); a length that does not match
        the scan, or values that cannot be the points' times (:func:`~lidarkit.io.pointcloud2.checked_point_times`, as
        in a bag), is a DataError; a frame without its file has no per-point times.
        """
        if not self.scan_paths:
            raise DataError("sequence has no scans", source=self.velodyne_dir)
        index = checked_index(index, len(self.scan_paths), f"{self.name} ({self.sequence_dir})")
        frame = int(self.scan_frames[index])
        stamps = self._stamps_of(self.scan_frames[index:index + 1])
        ts = None if stamps is None else float(stamps[0])
        dropped: list[str] = []
        scan = read_kitti_bin(self.scan_paths[index], frame=frame, timestamp_s=ts, drop_nonfinite=self.drop_nonfinite, dropped=dropped)
        said_once(self.reader_warnings, dropped)
        if ts is not None and self._simulator_pose_instant is not None:  # the simulator stamps sweeps at its pose instant
            scan = dataclasses.replace(scan, stamp_instant=self._simulator_pose_instant)
        if self._correct:
            scan = dataclasses.replace(scan, points_xyz=correct_vertical_angle(scan.points_xyz))
        if self.point_times_dir is None:
            return scan
        times_path = self.point_times_dir / f"{frame:06d}.npy"
        if not times_path.is_file():
            return scan
        # a sweep lasts at most MAX_SWEEP_S, or the spacing of the scans when longer (the simulator at 0.5 Hz)
        longest_s = max(MAX_SWEEP_S, self._period_s or 0.0)
        times, convention = self._read_point_times(times_path, self.scan_paths[index], scan, frame, longest_s, ts,
                                                   self._point_time_convention)
        self._check_point_time_unit()
        return dataclasses.replace(scan, point_times_s=times, point_time_convention=convention)

    def _check_point_time_unit(self) -> None:
        """DataError when the per-point times span a sweep of less than a small share of times.txt's spacing (their
        median over the first frames): uint32 microseconds read as nanoseconds deskewed 0.1 s sweeps as 1e-4 s."""
        measured = self._point_time_span_s
        if measured is None or self._period_s is None:
            return
        span, n_frames, dtype = measured
        folder = self.point_times_dir.name
        unit = "nanoseconds or seconds" if dtype is None else f"{time_unit_read(dtype)} ({dtype})"
        check_sweep_span(span, self._period_s, what=f"per-point times in {folder}/", unit=unit,
                         over=f"the median over {n_frames} frames; times.txt gives the stamps", source=self.point_times_dir,
                         hint=f"rename {folder}/ to read the scans without them")

    @cached_property
    def _point_time_span_s(self) -> tuple[float, int, np.dtype | None] | None:
        """(median span in s, over how many frames, dtype or None when they differ) of the per-point times of the first
        :data:`POINT_TIME_SPAN_FRAMES` frames whose times differ (of the first three times as many files), None
        without such frames; a file that cannot be read is left to :meth:`read_scan` to name."""
        sweeps = self._first_point_times
        if not sweeps:
            return None
        spans = [last - first for _, first, last, _ in sweeps]
        dtypes = {dtype for *_, dtype in sweeps}
        return float(np.median(spans)), len(spans), dtypes.pop() if len(dtypes) == 1 else None

    @cached_property
    def _point_time_convention(self) -> str | None:
        """The one convention of the folder's per-point times, read from its first frames against times.txt
        (:func:`~lidarkit.io.pointcloud2.recording_time_convention`), None without times.txt or such frames (each scan
        is then read by its size). Per scan, absolute times of stamps starting at 0 s read as relative, 0.1-0.2 s off."""
        if self._times_all is None:
            return None
        sweeps = [sweep for sweep in self._first_point_times if sweep[0] < len(self._times_all)]
        if not sweeps:
            return None
        frames, firsts, lasts, _ = zip(*sweeps)
        return recording_time_convention(self._times_all[list(frames)], np.array(firsts), np.array(lasts))

    @cached_property
    def _first_point_times(self) -> list[tuple[int, float, float, np.dtype]]:
        """(frame, first and last point time in s, dtype) of the first :data:`POINT_TIME_SPAN_FRAMES` frames whose
        per-point times differ (of the first three times as many files); a file that cannot be read is left to
        :meth:`read_scan` to name."""
        sweeps = []
        for frame in self.scan_frames[: 3 * POINT_TIME_SPAN_FRAMES]:
            path = self.point_times_dir / f"{int(frame):06d}.npy"
            try:
                raw = load_npy(path, f"frame {int(frame)}") if path.is_file() else None
            except DataError:
                continue
            if raw is None or raw.ndim != 1 or not np.issubdtype(raw.dtype, np.number) or np.issubdtype(raw.dtype, np.complexfloating):
                continue
            times = point_times_seconds(raw[np.isfinite(raw)])
            if len(times) > 1 and np.ptp(times) > 0:
                sweeps.append((int(frame), float(times.min()), float(times.max()), raw.dtype))
                if len(sweeps) == POINT_TIME_SPAN_FRAMES:
                    break
        return sweeps

    @staticmethod
    def _read_point_times(times_path: Path, scan_path: Path, scan: Scan, frame: int, longest_s: float, stamp_s: float | None,
                          convention: str | None) -> tuple[np.ndarray, str]:
        """``(times (N,) float64 s, convention)`` of ``scan`` from ``times_path``, with the points dropped as non-finite
        dropped too, judged as a bag's time field is (ring numbers or an intensity were deskewed by without a word):
        against the scan's stamp ``stamp_s`` (None: none), in the folder's ``convention`` (None: the scan's own)."""
        raw = load_npy(times_path, f"frame {frame}")
        if raw.ndim != 1 or not np.issubdtype(raw.dtype, np.number) or np.issubdtype(raw.dtype, np.complexfloating):
            raise DataError(f"expected a 1-D numeric array, got shape {raw.shape} dtype {raw.dtype}", source=times_path, location=f"frame {frame}")
        n_points = len(scan.points_xyz)
        if len(raw) != n_points:
            points = np.fromfile(scan_path, dtype="<f4").reshape(-1, 4)
            if len(raw) == len(points) and n_points < len(points):  # points left out as non-finite: leave out their times
                keep = np.isfinite(points).all(axis=1)
                if np.count_nonzero(keep) != n_points:  # and those at (0, 0, 0), missing returns the reader leaves out
                    keep &= ~at_sensor_origin(points)
                raw = raw[keep]
            if len(raw) != n_points:  # (times of other points were paired with these)
                raise DataError(f"{len(raw)} point times for {n_points} points of {scan_path.name}", source=times_path, location=f"frame {frame}")
        if not np.isfinite(raw).all():
            raise DataError("point times contain NaN or infinite values", source=times_path, location=f"frame {frame}")
        # integers are nanoseconds, as drivers write them (Ouster's uint32 't') and as the bag reader reads them
        return checked_point_times(raw, scan.points_xyz, what="per-point time array", within="one scan", longest_s=longest_s,
                                   hint=f"rename {times_path.parent.name}/ to read the scans without them",
                                   source=times_path, location=f"frame {frame}", stamp_s=stamp_s, convention=convention,
                                   convention_from=f"the first frames of {times_path.parent.name}/")

    def read_scan_by_frame(self, frame: int) -> Scan:
        """The scan of KITTI frame number ``frame`` (file ``{frame:06d}.bin``)."""
        hits = np.flatnonzero(self.scan_frames == frame)
        if not len(hits):
            raise DataError(f"no scan for frame {frame}", source=self.velodyne_dir)
        return self.read_scan(int(hits[0]))

    def read_image(self, index: int) -> np.ndarray:
        """The ``index``-th image of ``image_paths`` as ``(H, W)`` uint8 grayscale."""
        if not self.image_paths:
            raise DataError("sequence has no images", source=self.image_dir)
        index = checked_index(index, len(self.image_paths), f"{self.name} ({self.sequence_dir})", "image")
        return read_gray_image(self.image_paths[index], frame=int(self.image_frames[index]))

    def as_image_sequence(self) -> KittiImages:
        """The images of this sequence as an ``ImageSequence`` (ground truth in the camera frame)."""
        return KittiImages(self)


def check_vertical_correction(value: Any) -> bool | str:
    """``value`` if it is a ``vertical_correction`` setting (True, False or "auto"), else ConfigError."""
    if value not in (True, False, "auto") or isinstance(value, (int, float)) and not isinstance(value, bool):
        raise ConfigError(f"vertical_correction must be true, false or auto, got {value!r}", source="vertical_correction")
    return value


def correction_options(setting: bool | str, applied: bool) -> dict:
    """A reader's vertical-angle correction in its run config: the setting, whether it applied, by how much."""
    return {"vertical_correction": setting, "vertical_correction_applied": applied,
            "vertical_correction_deg": KITTI_VERTICAL_CORRECTION_DEG if applied else 0.0}


def correct_vertical_angle(points_xyz: np.ndarray) -> np.ndarray:
    """KITTI's vertical-angle correction (:data:`KITTI_VERTICAL_CORRECTION_DEG`) through kiss-icp's own routine."""
    from kiss_icp.pybind import kiss_icp_pybind

    points = np.ascontiguousarray(points_xyz, dtype=np.float64)
    return np.asarray(kiss_icp_pybind._correct_kitti_scan(kiss_icp_pybind._Vector3dVector(points)))


class KittiImages:
    """``ImageSequence`` view of a :class:`KittiOdometry`: one item per image, GT in the camera frame."""

    def __init__(self, odometry: KittiOdometry):
        if not odometry.image_paths:
            raise DataError("sequence has no images", source=odometry.image_dir)
        self.odometry = odometry
        self.name = f"{odometry.name}_image_0"
        # every frame from the first image to the last: a missing file is a frame whose image cannot be read (the VO
        # run rejects it with that reason), not a frame left out (its neighbours taken as one frame apart)
        present = dict(zip((int(f) for f in odometry.image_frames), odometry.image_paths))
        first, last = min(present), max(present)
        self._frames = np.arange(first, last + 1)
        suffix = odometry.image_paths[0].suffix
        self._paths = [present.get(int(f), odometry.image_paths[0].with_name(f"{int(f):06d}{suffix}")) for f in self._frames]
        missing = [int(f) for f in self._frames if int(f) not in present]
        if missing:
            log.warning("%s: %d image(s) missing between frames %d and %d (the first: %s); read as unreadable frames",
                        odometry.image_dir, len(missing), first, last, self._paths[missing[0] - first].name)

    def __len__(self) -> int:
        return len(self._frames)

    def __repr__(self) -> str:
        return f"KittiImages({str(self.odometry.image_dir)!r}, images={len(self)})"

    @property
    def frames(self) -> np.ndarray:
        return self._frames

    @property
    def image_paths(self) -> list[Path]:
        return self._paths

    def read_image(self, index: int) -> np.ndarray:
        index = checked_index(index, len(self._paths), self.name, "image")
        return read_gray_image(self._paths[index], frame=int(self._frames[index]))

    @property
    def K(self) -> np.ndarray:
        return self.odometry.K

    @property
    def timestamps_s(self) -> np.ndarray | None:
        return self.odometry._stamps_of(self.frames)

    @property
    def ground_truth(self) -> Trajectory | None:
        return self.odometry.ground_truth_at(self.frames, frame="camera")

    @property
    def reader_warnings(self) -> list[str]:
        """The sequence reader's (files cut inside their last number: poses, times, calib), for a VO run's metrics."""
        return self.odometry.reader_warnings


def read_gray_image(path: str | os.PathLike, *, frame: int | None = None) -> np.ndarray:
    """Read an image file as ``(H, W)`` uint8 grayscale with OpenCV; unreadable files raise DataError.

    A 16-bit image is scaled to 8 bits by the bits its values use (its top used bit becomes bit 7): OpenCV divides
    by 256, which left a 12-bit image 16 grey levels and a 10-bit one 4 (VO then found too few matches).
    What the decoder prints on stderr is kept off the terminal (a truncated PNG printed libpng's "libpng error: Read
    Error" between the progress lines): it ends the DataError's reason of a refused image, and is a warning naming the
    file for an image that decoded anyway (a truncated JPEG's "Premature end of JPEG file")."""
    from lidarkit.quiet import captured

    path = Path(path)
    where = None if frame is None else f"frame {frame}"
    if not path.is_file():
        raise DataError("image file not found", source=path, location=where)
    try:
        with captured(2) as native:
            image = _decode_gray(path, where)
    except DataError as err:  # (raised in the block: ``native`` holds what the decoder said)
        said = _decoder_lines(native.text)
        if not said:
            raise
        raise DataError(f"{err.reason}: {said}", source=err.source, location=err.location) from None
    said = _decoder_lines(native.text)
    if said:
        log.warning("%s%s: the image decoder said: %s", path, "" if where is None else f" ({where})", said)
    return image


def _decoder_lines(text: str, limit: int = 300) -> str:
    """The decoder's lines of captured stderr text as one line; a progress bar drawn meanwhile (escape sequences) is
    left out."""
    lines = (line.strip() for line in text.replace("\r", "\n").split("\n"))
    said = "; ".join(line for line in lines if line and "\x1b" not in line)
    return said if len(said) <= limit else said[: limit - 3] + "..."


def _decode_gray(path: Path, where: str | None) -> np.ndarray:
    import cv2

    try:
        image = cv2.imread(str(path), cv2.IMREAD_ANYDEPTH)  # grayscale, depth kept
        if image is not None and image.dtype == np.uint16 and image.size:
            bits = max(8, int(image.max()).bit_length())
            image = (image >> (bits - 8)).astype(np.uint8)  # full-range 16-bit: >> 8, as IMREAD_GRAYSCALE reads it
        elif image is not None and image.dtype != np.uint8:  # (float TIFF...) read as before
            image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    except cv2.error as err:  # (a header claiming 100000 x 100000 pixels: OpenCV's size assertion ended the run)
        said = str(err).strip().splitlines()[-1] if str(err).strip() else type(err).__name__
        raise DataError(f"cannot decode image: {said}", source=path, location=where) from None
    if image is None or image.size == 0:
        raise DataError("cannot decode image (corrupt or unsupported format)", source=path, location=where)
    return image


__all__ = [
    "KITTI_VERTICAL_CORRECTION_DEG", "POINT_TIME_FOLDERS", "KittiImages", "KittiOdometry", "correct_vertical_angle", "indexed_files",
    "read_gray_image", "read_kitti_bin", "read_kitti_calib",
]
