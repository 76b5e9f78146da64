"""TUM RGB-D reader: ``rgb.txt`` images associated by time stamp with ``groundtruth.txt``.

Layout (one sequence folder, e.g. ``rgbd_dataset_freiburg1_xyz/``)::

    rgb.txt          "# comments", then "timestamp rgb/1305031102.175304.png" per frame
    rgb/*.png        colour images (read as 8-bit grayscale)
    groundtruth.txt  TUM trajectory "timestamp tx ty tz qx qy qz qw" (camera pose in the mocap world)

Each rgb frame gets the ground-truth pose with the nearest time stamp if it is within ``max_dt_s``.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

import numpy as np

from lidarkit.errors import ConfigError, DataError
from lidarkit.io.base import checked_index, keep_once
from lidarkit.io.kitti import read_gray_image
from lidarkit.textfile import read_lines
from lidarkit.trajectory import READ_WARNINGS, Trajectory

log = logging.getLogger(__name__)

# Default intrinsics of the TUM RGB-D Kinects (fx, fy, cx, cy), from the dataset's camera calibration page.
TUM_INTRINSICS = {
    "freiburg1": (517.3, 516.5, 318.6, 255.3),
    "freiburg2": (520.9, 521.0, 325.1, 249.7),
    "freiburg3": (535.4, 539.2, 320.1, 247.6),
}
#: first radial distortion coefficient of the freiburg1/2 colour images (same page); freiburg3's are undistorted
TUM_DISTORTION_K1 = {"freiburg1": 0.262383, "freiburg2": 0.231222}
UNMATCHED_POLICIES = ("drop", "keep", "error")


def tum_camera_for(path: str | os.PathLike) -> str | None:
    """The freiburg camera (``"freiburg1"``...) named in the folder name (``freiburg1`` or ``fr1``...), else None."""
    name = Path(path).resolve().name.lower()
    for key in TUM_INTRINSICS:
        if key in name or any(part == "fr" + key[-1] for part in name.replace("-", "_").split("_")):
            return key
    return None


def tum_intrinsics_for(path: str | os.PathLike) -> np.ndarray | None:
    """(3, 3) K of the freiburg camera named in the folder name (``freiburg1`` or ``fr1``...), else None."""
    camera = tum_camera_for(path)
    if camera is None:
        return None
    fx, fy, cx, cy = TUM_INTRINSICS[camera]
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


def read_tum_file_list(path: str | os.PathLike, *, warnings: list[str] | None = None) -> tuple[np.ndarray, list[str]]:
    """Parse ``rgb.txt``/``depth.txt``: ``(timestamps_s (N,), relative file names)``; DataError on a bad line;
    ``warnings``: as for :func:`lidarkit.textfile.read_lines` (a file cut inside its last line)."""
    stamps: list[float] = []
    names: list[str] = []
    for lineno, raw in enumerate(read_lines(path, what="TUM file", warnings=warnings), start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        fields = line.split()
        if len(fields) != 2:
            raise DataError(f"expected 'timestamp filename', found {len(fields)} fields", source=path, location=f"line {lineno}")
        try:
            stamp = float(fields[0])
        except ValueError:
            raise DataError(f"time stamp is not a number: {fields[0]!r}", source=path, location=f"line {lineno}") from None
        if not np.isfinite(stamp):
            raise DataError("time stamp is NaN or infinite", source=path, location=f"line {lineno}")
        if stamps and stamp <= stamps[-1]:
            raise DataError(f"time stamp {stamp} is not after the previous {stamps[-1]}", source=path, location=f"line {lineno}")
        stamps.append(stamp)
        names.append(fields[1])
    if not stamps:
        raise DataError("no frames listed", source=path)
    return np.asarray(stamps), names


def associate_nearest(query_s: np.ndarray, reference_s: np.ndarray, max_dt_s: float) -> np.ndarray:
    """For each query time the index of the nearest reference time (sorted), or -1 if farther than ``max_dt_s``."""
    pos = np.clip(np.searchsorted(reference_s, query_s), 1, len(reference_s) - 1) if len(reference_s) > 1 else np.zeros(len(query_s), int)
    left = np.maximum(pos - 1, 0)
    choose_left = np.abs(query_s - reference_s[left]) <= np.abs(reference_s[pos] - query_s)
    nearest = np.where(choose_left, left, pos)
    return np.where(np.abs(reference_s[nearest] - query_s) <= max_dt_s, nearest, -1)


class TumRGBD:
    """One TUM RGB-D sequence as an ``ImageSequence`` (ground truth = camera poses in the mocap frame).

    ``unmatched`` decides what happens to rgb frames without a GT stamp within ``max_dt_s``:
    ``"drop"`` (default; the sequence then holds only frames with GT, and the number dropped is
    logged), ``"keep"`` (all frames; ``ground_truth`` is None unless every frame matched, and
    ``has_ground_truth`` marks which did) or ``"error"`` (DataError naming the first such frame).
    Without ``groundtruth.txt`` every frame is kept and ``ground_truth`` is None.
    ``K`` defaults to the freiburg1/2/3 intrinsics picked from the folder name.
    """

    def __init__(
        self,
        path: str | os.PathLike,
        *,
        max_dt_s: float = 0.02,
        unmatched: str = "drop",
        K: np.ndarray | None = None,
        rgb_list: str = "rgb.txt",
        groundtruth: str | os.PathLike | None = "groundtruth.txt",
    ):
        folder = Path(path)
        if not folder.is_dir():
            raise DataError("TUM sequence folder not found" if not folder.exists() else "not a folder", source=folder)
        if unmatched not in UNMATCHED_POLICIES:
            raise ConfigError(f"unknown unmatched policy {unmatched!r}; known: {', '.join(UNMATCHED_POLICIES)}", source="unmatched")
        if not max_dt_s > 0:
            raise ConfigError(f"max_dt_s must be positive, got {max_dt_s}", source="max_dt_s")
        self.path = folder
        self.name = Path(os.path.abspath(folder)).name  # ("." was named '')
        self.max_dt_s = float(max_dt_s)
        self.rgb_list_path = folder / rgb_list
        #: files cut inside their last line (rgb.txt, groundtruth.txt), for the run's warnings: the poses kept per frame
        #: are a new Trajectory, which does not carry the file's own ``meta["read_warnings"]``
        self.reader_warnings: list[str] = []
        stamps, names = read_tum_file_list(self.rgb_list_path, warnings=self.reader_warnings)
        paths = [folder / n for n in names]

        gt_path = None if groundtruth is None else folder / groundtruth
        self.groundtruth_path = gt_path if gt_path is not None and gt_path.is_file() else None
        gt_poses = None
        matched = np.ones(len(stamps), dtype=bool)
        if self.groundtruth_path is not None:
            gt = Trajectory.from_tum(self.groundtruth_path)
            keep_once(self.reader_warnings, gt.meta.get(READ_WARNINGS, ()))
            nearest = associate_nearest(stamps, gt.timestamps_s, self.max_dt_s)
            matched = nearest >= 0
            if not matched.all():
                first = int(np.argmin(matched))
                if unmatched == "error":
                    gap = np.min(np.abs(gt.timestamps_s - stamps[first]))
                    raise DataError(
                        f"rgb frame at t={stamps[first]:.6f} s ({names[first]}) has no ground-truth pose within "
                        f"{self.max_dt_s} s (nearest {gap:.3f} s away)",
                        source=self.rgb_list_path,
                        location=f"frame {first}",
                    )
                log.info("%s: %d of %d rgb frames have no ground truth within %.3f s (%s)",
                         self.rgb_list_path, int((~matched).sum()), len(stamps), self.max_dt_s, unmatched)
                inside = np.flatnonzero(~matched)
                inside = inside[(inside > np.argmax(matched)) & (inside < len(matched) - 1 - np.argmax(matched[::-1]))]
                if len(inside) and unmatched == "drop":  # a gap in the ground truth: the sequence jumps over frames
                    log.warning("%s: %d rgb frame(s) inside the sequence have no ground-truth pose within %.3f s and are "
                                "left out, the first at t=%.6f s (%s): the images jump there", self.rgb_list_path,
                                len(inside), self.max_dt_s, stamps[inside[0]], names[inside[0]])
            if unmatched == "drop":
                keep = np.flatnonzero(matched)
                if not len(keep):
                    raise DataError(f"no rgb frame has a ground-truth pose within {self.max_dt_s} s", source=self.rgb_list_path)
                stamps, paths, nearest, matched = stamps[keep], [paths[i] for i in keep], nearest[keep], matched[keep]
            if matched.all():
                gt_poses = Trajectory(gt.poses_se3[nearest], stamps, f"{self.name}_gt")
        elif groundtruth is not None and groundtruth != "groundtruth.txt":
            raise DataError("ground-truth file not found", source=gt_path)

        self.image_paths: list[Path] = paths
        self._timestamps_s = stamps
        self.has_ground_truth = matched
        self._ground_truth = gt_poses
        self._K = tum_intrinsics_for(folder) if K is None else np.asarray(K, dtype=np.float64).reshape(3, 3)
        camera = tum_camera_for(folder) if K is None else None
        self._distorted_camera = camera if camera in TUM_DISTORTION_K1 else None  # said at the first use of K

    def __len__(self) -> int:
        return len(self.image_paths)

    def __repr__(self) -> str:
        return f"TumRGBD({str(self.path)!r}, images={len(self)})"

    @property
    def K(self) -> np.ndarray | None:
        """(3, 3) intrinsics (given, or the freiburg default from the folder name), or None if unknown. The first use of
        the freiburg1/2 default logs that their distortion is not corrected (it was used without a word)."""
        if self._distorted_camera is not None:
            log.warning("%s: the built-in %s intrinsics have no lens distortion model: its colour images are distorted "
                        "(k1 = %.2f) and are used uncorrected (undistort them, and give their K, for exact geometry)",
                        self.path, self._distorted_camera, TUM_DISTORTION_K1[self._distorted_camera])
            self._distorted_camera = None
        return None if self._K is None else self._K.copy()

    @property
    def timestamps_s(self) -> np.ndarray:
        return self._timestamps_s.copy()

    @property
    def ground_truth(self) -> Trajectory | None:
        """Camera poses associated with each frame (rgb time stamps), or None."""
        return self._ground_truth

    def read_image(self, index: int) -> np.ndarray:
        """The ``index``-th rgb image as ``(H, W)`` uint8 grayscale."""
        index = checked_index(index, len(self.image_paths), self.path, "image")
        return read_gray_image(self.image_paths[index], frame=index)


__all__ = ["TUM_DISTORTION_K1", "TUM_INTRINSICS", "TumRGBD", "associate_nearest", "read_tum_file_list", "tum_camera_for",
           "tum_intrinsics_for"]
