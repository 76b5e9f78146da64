"""A plain folder of images (``.png``, ``.jpg``, ...) as an ``ImageSequence``, and intrinsics files.

Images are ordered by natural sort of their names (hidden ones, named ``.*``, left out); optional timestamps (one
number per line, or TUM-style ``stamp name`` lines), intrinsics (see :func:`read_intrinsics`) and ground-truth camera
poses (KITTI or TUM format) must match the number of images. Registered as dataset kind ``"images"``.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from lidarkit.errors import ConfigError, DataError
from lidarkit.io import register_dataset
from lidarkit.io.base import checked_index, keep_once, stamps_in_seconds
from lidarkit.io.folder import sorted_by_name
from lidarkit.io.kitti import read_gray_image, read_kitti_calib
from lidarkit.run_files import output_folder_kind
from lidarkit.textfile import read_lines
from lidarkit.trajectory import READ_WARNINGS, Trajectory

log = logging.getLogger(__name__)

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm")


#: what an intrinsics file (``lidarkit vo --calib``) may hold, for its docstring and errors
INTRINSICS_FILES = ("9 numbers (K row-major, bare or after 'K:'), 4 (fx fy cx cy), a KITTI odometry calib.txt (P0) or "
                    "a KITTI raw calib_cam_to_cam.txt (P_rect_00)")


def read_intrinsics(path: str | os.PathLike, *, warnings: list[str] | None = None) -> np.ndarray:
    """``(3, 3)`` K from a text file holding 9 numbers (K row-major, bare or after ``K:``), 4 numbers (``fx fy cx cy``),
    12 unlabelled numbers in any line layout (a 3x4 projection matrix P row-major: K is its left 3x3; three rows of 4
    were read as KITTI calib.txt rows of 12 and refused), a KITTI odometry ``calib.txt`` (``P0: ...`` or bare rows of
    12 numbers: K is the left 3x3 of P0) or a KITTI raw ``calib_cam_to_cam.txt`` (the left 3x3 of ``P_rect_00``, the
    kitti_raw reader's K; it was read as an odometry calib.txt and refused at its ``calib_time`` line). A matrix
    printed by numpy (``[[fx, 0, cx], ...]``, with or without commas or ``array(...)``) is read without its brackets,
    as ``--init`` reads one. ``warnings``: as for :func:`lidarkit.textfile.read_lines` (a file cut inside its last
    number)."""
    tokens: list[str] = []
    labels: dict[str, list[str]] = {}
    for raw in read_lines(path, warnings=warnings):
        line = _without_brackets(raw.split("#")[0]).strip()
        if not line:
            continue
        key, labelled, rest = line.partition(":")
        if labelled:
            labels[key.strip()] = rest.replace(",", " ").split()
        tokens.extend(line.replace(",", " ").split())
    if not labels and len(tokens) == 12:  # one 3x4 P, whatever its line layout
        tokens = [t for i, t in enumerate(tokens) if i % 4 != 3]
    elif "P0" in labels or not labels and len(tokens) % 12 == 0 and len(tokens) >= 12:
        return read_kitti_calib(path)["P0"][:, :3].copy()
    elif "P_rect_00" in labels:  # 12 numbers: its left 3x3 (another count is refused below, as found)
        p_rect = labels["P_rect_00"]
        tokens = [t for i, t in enumerate(p_rect) if i % 4 != 3] if len(p_rect) == 12 else p_rect
    elif "K" in labels:
        tokens = labels["K"]
    elif labels:  # ("K: 9 numbers" read "no P0 projection matrix")
        raise DataError(f"no P0:, P_rect_00: or K: line; intrinsics files hold {INTRINSICS_FILES}", source=path)
    try:
        values = np.array([float(t) for t in tokens])
    except ValueError:
        raise DataError(f"intrinsics must be numbers: {INTRINSICS_FILES}", source=path) from None
    if values.size == 9:
        K = values.reshape(3, 3)
    elif values.size == 4:
        fx, fy, cx, cy = values
        K = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]])
    else:
        raise DataError(f"expected {INTRINSICS_FILES}; found {values.size} numbers", source=path)
    if np.all(np.isfinite(K)) and (K[0, 0] <= 0 or K[1, 1] <= 0):
        raise DataError(f"focal lengths must be > 0 pixels, got fx = {K[0, 0]:g}, fy = {K[1, 1]:g}", source=path)
    if not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0 or not np.allclose(K[2], [0, 0, 1]):
        raise DataError("not a valid intrinsics matrix [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]", source=path)
    return K


def _without_brackets(line: str) -> str:
    """``line`` with numpy's matrix print removed around its numbers: ``array(``, ``[``, ``]`` and ``)``."""
    return line.replace("array(", " ").translate(str.maketrans("[]()", "    "))


def read_image_timestamps(path: str | os.PathLike, *, warnings: list[str] | None = None) -> np.ndarray:
    """Timestamps in seconds: one number per line, or ``stamp name`` lines (TUM ``rgb.txt``, EuRoC ``data.csv``); first
    column used. NaN or infinity is refused at its line (it failed later as "not strictly increasing", blaming the next
    line). Stamps above 1e15 are nanoseconds, converted with a logged warning (they were written out as seconds), unless
    they then read as microseconds (before 1973, or frames under 1 ms apart); those and the ones beyond 1e11 s
    (milliseconds) are refused (:func:`~lidarkit.io.base.stamps_in_seconds`).
    ``warnings``: as for :func:`lidarkit.textfile.read_lines` (a file cut inside its last number)."""
    stamps = []
    for lineno, raw in enumerate(read_lines(path, warnings=warnings), start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        try:
            stamps.append(float(line.replace(",", " ").split()[0]))
        except ValueError:
            raise DataError(f"not a time stamp: {line.split()[0]!r}", source=path, location=f"line {lineno}") from None
        if not np.isfinite(stamps[-1]):
            raise DataError("NaN or infinite value", source=path, location=f"line {lineno}")
    if not stamps:
        raise DataError("no time stamps", source=path)
    return stamps_in_seconds(np.asarray(stamps, dtype=np.float64), path)


def _warn_stamps_apart(pose_stamps: np.ndarray, image_stamps: np.ndarray, poses: Any) -> None:
    """Poses and images are paired one to one by order: say so when their stamps disagree by more than half a frame
    (a ground truth 100 s late was scored pose by pose without a word)."""
    steps = np.diff(image_stamps)
    half_frame = 0.5 * float(np.median(steps)) if len(steps) else 0.0
    apart = np.abs(np.asarray(pose_stamps, dtype=np.float64) - image_stamps)
    if half_frame > 0 and float(apart.max()) > half_frame:
        k = int(np.argmax(apart))
        log.warning("%s: pose %d is stamped %.3f s from its image (half a frame is %.3f s); poses and images are paired "
                    "by order, one each, not by time", poses, k, float(apart[k]), half_frame)


def poses_format_hint(fmt: str) -> str:
    """How to read an image folder's pose file as ``fmt``, named by the reader's error for a file in the other format:
    the keyword (a command that opens the folder names its own option instead)."""
    return f"poses_format='{fmt}'"


#: why a file shorter than the folder is refused though ``lidarkit vo --max-frames`` uses fewer images ("15 poses for
#: 51 images" with --max-frames 10): rows pair with images by order, from the folder's first
_ONE_PER_IMAGE = "(one per image of the folder, in order from its first: --start and --max-frames pick frames after pairing)"


@register_dataset("images")
class ImageFolder:
    """Images of one folder as an ``ImageSequence``.

    ``timestamps``: file or array (else None); ``calib``: intrinsics file (:func:`read_intrinsics`) or a (3, 3)
    array (else ``K`` is None and the caller must guess it); ``poses``: ground-truth camera poses file in
    ``poses_format`` (``kitti`` or ``tum``).
    """

    def __init__(self, path: str | os.PathLike, *, timestamps: str | os.PathLike | np.ndarray | None = None,
                 calib: str | os.PathLike | np.ndarray | None = None, poses: str | os.PathLike | None = None,
                 poses_format: str = "kitti", name: str | None = None,
                 format_hint: Callable[[str], str] = poses_format_hint):
        folder = Path(path)
        if not folder.is_dir():
            raise DataError("image folder not found" if not folder.exists() else "not a folder", source=folder)
        output = output_folder_kind(folder)
        if output:  # (a VO run read an odometry run's plots as camera images and failed on their sizes)
            raise DataError(f"{output}: lidarkit's output, not an image sequence", source=folder)
        self.path = folder
        self.name = name or folder.name
        # hidden files are no frames: macOS leaves a 4-byte AppleDouble "._000000.png" beside each image it copies
        self.image_paths = sorted_by_name([p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file()
                                           and not p.name.startswith(".")])
        if not self.image_paths:
            raise DataError(f"no images ({', '.join(IMAGE_SUFFIXES)})", source=folder)
        n = len(self.image_paths)
        #: files cut inside their last number (time stamps, poses), for the run's warnings: once each (only logged,
        #: a VO run scored against a cut pose file recorded nothing)
        self.reader_warnings: list[str] = []
        self._timestamps = None
        if timestamps is not None:
            stamps = (read_image_timestamps(timestamps, warnings=self.reader_warnings) if isinstance(timestamps, (str, os.PathLike))
                      else np.asarray(timestamps, dtype=np.float64))
            if len(stamps) != n:
                raise DataError(f"{len(stamps)} time stamps for {n} images {_ONE_PER_IMAGE}", source=str(timestamps)[:200])
            self._timestamps = stamps
        self._K = None
        if calib is not None:
            self._K = read_intrinsics(calib) if isinstance(calib, (str, os.PathLike)) else np.asarray(calib, float)
        self._gt = None
        if poses is not None:
            if poses_format not in ("kitti", "tum"):
                raise ConfigError(f"unknown poses format {poses_format!r}; known: kitti, tum", source="poses_format")
            gt = Trajectory.read(poses, poses_format, format_hint=format_hint)
            keep_once(self.reader_warnings, gt.meta.get(READ_WARNINGS, ()))
            if len(gt) != n:
                raise DataError(f"{len(gt)} poses for {n} images {_ONE_PER_IMAGE}", source=poses)
            if self._timestamps is not None and poses_format == "kitti":
                gt = gt.with_timestamps(self._timestamps)
            elif poses_format == "tum" and gt.timestamps_s is not None:  # paired one pose per image, by order
                if self._timestamps is None:  # the poses' stamps are the images' (the TUM output said 0, 1, 2 ... s)
                    self._timestamps = np.asarray(gt.timestamps_s, dtype=np.float64)
                else:
                    _warn_stamps_apart(gt.timestamps_s, self._timestamps, poses)
            self._gt = gt

    def __len__(self) -> int:
        return len(self.image_paths)

    def __repr__(self) -> str:
        return f"ImageFolder({str(self.path)!r}, {len(self)} images)"

    def read_image(self, index: int) -> np.ndarray:
        """The ``index``-th image as ``(H, W)`` uint8 grayscale; unreadable files raise DataError."""
        index = checked_index(index, len(self.image_paths), f"{self.name} ({self.path})", "image")
        return read_gray_image(self.image_paths[index], frame=index)

    @property
    def K(self) -> np.ndarray | None:
        return None if self._K is None else self._K.copy()

    @property
    def timestamps_s(self) -> np.ndarray | None:
        return self._timestamps

    @property
    def ground_truth(self) -> Trajectory | None:
        return self._gt

