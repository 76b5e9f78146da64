"""Open what the user points ``lidarkit vo`` at: a KITTI sequence folder, a TUM RGB-D folder or a plain image folder,
and resolve the intrinsics (user file > dataset calibration > guess from the image size)."""

from __future__ import annotations

import logging
import os
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from lidarkit.errors import ConfigError, DataError
from lidarkit.trajectory import Trajectory
from lidarkit.vo.intrinsics import DEFAULT_FOCAL_FACTOR, K_from_image_size, validate_K

log = logging.getLogger(__name__)

INPUT_KINDS = ("auto", "kitti", "tum", "images")


@dataclass
class VOInput:
    """An image sequence with resolved intrinsics; ``K_source`` says where K came from."""

    images: Any
    K: np.ndarray
    K_source: str
    ground_truth: Trajectory | None
    kind: str
    read_warnings: tuple[str, ...] = ()
    """What reading inputs beside the images warned of (an intrinsics file cut inside its last number), for the run's
    warnings with its reader's own."""


def _sequence_folders(path: Path) -> list[str]:
    """Names of the subfolders of ``path`` that hold an image_0/ (a KITTI ``sequences/`` folder's NN)."""
    return sorted(p.name for p in path.glob("*") if (p / "image_0").is_dir())


def detect_kind(path: Path) -> str:
    """``kitti`` (folder with image_0/, an image_0 folder beside calib.txt, a KITTI root with sequences/NN/image_0/ or
    its sequences/ folder: the last two are opened or refused naming their sequences, not read as "no images"),
    ``tum`` (rgb.txt) or ``images``."""
    if (path / "image_0").is_dir() or _sequence_folders(path / "sequences"):
        return "kitti"
    if path.name == "sequences" and _sequence_folders(path):
        return "kitti"
    if path.name == "image_0" and (path.parent / "calib.txt").is_file():
        return "kitti"
    if (path / "rgb.txt").is_file():
        return "tum"
    return "images"


def _check_timestamps(timestamps_s: Any, path: str | os.PathLike) -> None:
    """A time stamps file is checked before the run (not when the trajectory is built at its end): finite and
    strictly increasing, errors naming the file and line."""
    if timestamps_s is None:
        return
    from lidarkit.errors import DataError, not_increasing
    from lidarkit.textfile import file_line

    ts = np.asarray(timestamps_s, dtype=np.float64).reshape(-1)
    steps = np.diff(ts)
    if len(steps) and not (steps > 0).all():
        k = int(np.argmax(~(steps > 0))) + 1
        raise DataError(f"time stamps are not strictly increasing ({not_increasing(ts[k], ts[k - 1])})", source=path,
                        location=file_line(path, f"frame {k}"))


def open_vo_input(path: str | os.PathLike, *, kind: str = "auto", calib: str | os.PathLike | None = None,
                  timestamps: str | os.PathLike | None = None, poses: str | os.PathLike | None = None,
                  poses_format: str = "kitti", focal_factor: float = DEFAULT_FOCAL_FACTOR,
                  format_hint: Callable[[str], str] | None = None) -> VOInput:
    """Open ``path`` as an image sequence for VO. ``calib`` overrides the dataset's intrinsics; without either,
    K is guessed as ``fx = fy = focal_factor * max(w, h)``, principal point at the centre (logged as a warning).
    ``format_hint``: how a pose file in the other format is to be read, named for the caller (a command's option;
    default the image folder's keyword)."""
    from lidarkit.errors import ConfigError

    if str(path).startswith("simcam:"):
        for given, option in ((timestamps, "timestamps"), (poses, "poses")):
            if given is not None:
                raise ConfigError(f"the camera simulator has its own {option}; drop --{option}", source=str(path))
        return _open_simcam(str(path), kind, calib, focal_factor)
    path = Path(path)
    if not path.exists():
        from lidarkit.atomic import missing_reason

        raise DataError(missing_reason(path, "input not found"), source=path)
    if kind not in INPUT_KINDS:
        raise ConfigError(f"unknown input kind {kind!r}; known: {', '.join(INPUT_KINDS)}", source="vo input kind")
    kind = detect_kind(path) if kind == "auto" else kind
    if kind == "kitti" and poses_format != "kitti":  # (an image_0/ given, read as its sequence, was told to be an image folder)
        what = ("read as its KITTI sequence (an image_0/ beside calib.txt), whose poses" if path.name == "image_0"
                else "a KITTI folder's poses")
        raise ConfigError(f"{what} are KITTI rows (12 numbers, one per image): --poses-format {poses_format} is for image "
                          f"folders: {'add' if path.name == 'image_0' else 'give its image_0/ with'} --kind images (kind='images')",
                          source=str(path))
    if kind == "tum":  # its own stamps (rgb.txt) and ground truth (groundtruth.txt)
        for given, option in ((timestamps, "timestamps"), (poses, "poses")):
            if given is not None:
                raise ConfigError(f"a TUM RGB-D folder has its own {'rgb.txt stamps' if option == 'timestamps' else 'groundtruth.txt'}; "
                                  f"drop --{option}", source=str(path))
    if kind == "kitti":
        from lidarkit.io.kitti import KittiOdometry

        root = path.parent if path.name == "image_0" else path
        held = _sequence_folders(root / "sequences")
        inside = [] if (root / "image_0").is_dir() or held else _sequence_folders(root)
        if inside:  # (a root's sequences/ folder: read as images it said "no images")
            raise ConfigError(f"a folder of KITTI sequences ({', '.join(inside)}): give one sequence's folder, "
                              f"e.g. {root / inside[0]}", source=str(path))
        if not (root / "image_0").is_dir() and len(held) > 1:  # (sequence 00 of them ran without a word)
            raise ConfigError(f"a KITTI root with {len(held)} sequences ({', '.join(held)}): give one sequence's "
                              f"folder, e.g. {root / 'sequences' / held[0]}", source=str(path))
        if not (root / "image_0").is_dir() and not held:  # (it read "sequence 00 not found": 00 was never asked for)
            raise DataError("not a KITTI sequence folder (no image_0/) nor a KITTI root (no sequences/NN/image_0/)",
                            source=str(path))
        options = {} if timestamps is None else {"times_file": timestamps}
        if poses is not None:
            options["poses_file"] = poses
        if not (root / "image_0").is_dir():  # a root with one sequence: that one (it looked for 00)
            options["sequence"] = held[0]
        images = KittiOdometry(root, **options).as_image_sequence()
        ground_truth = images.ground_truth
    elif kind == "tum":
        from lidarkit.io.tum import TumRGBD

        images = TumRGBD(path)
        ground_truth = images.ground_truth
    else:
        from lidarkit.io.images import ImageFolder

        hint = {} if format_hint is None else {"format_hint": format_hint}
        images = ImageFolder(path, timestamps=timestamps, poses=poses, poses_format=poses_format, **hint)
        ground_truth = images.ground_truth
    if timestamps is not None:
        _check_timestamps(images.timestamps_s, timestamps)
    said: list[str] = []
    if calib is not None:
        from lidarkit.io.images import read_intrinsics

        K, source = read_intrinsics(calib, warnings=said), f"file {calib}"
    elif images.K is not None:
        K, source = images.K, f"{kind} calibration"
    else:
        from lidarkit.vo.pipeline import sequence_image_shape

        h, w = sequence_image_shape(images)[:2]
        K = K_from_image_size(w, h, focal_factor)
        source = f"guess: fx = fy = {focal_factor:g} * max({w}, {h}) = {K[0, 0]:.1f} px, principal point at centre"
        log.warning("no intrinsics given; %s", source)
    return VOInput(images, validate_K(K, source=str(calib or path)), source, ground_truth, kind, tuple(said))


def _open_simcam(spec: str, kind: str, calib: str | os.PathLike | None, focal_factor: float) -> VOInput:
    """The camera simulator (:func:`lidarkit.sim.street_camera.open_simcam`) with its exact K and ground truth;
    ``kind="images"`` hides its K (the no-intrinsics setting: K from ``calib`` or the size-based guess)."""
    from lidarkit.sim.street_camera import open_simcam

    if kind not in ("auto", "images"):
        raise ConfigError(f"a simcam: spec is read as kind auto (simulator K) or images (K unknown), not {kind!r}",
                          source="vo input kind")
    images = open_simcam(spec)
    said: list[str] = []
    if calib is not None:
        from lidarkit.io.images import read_intrinsics

        K, source = read_intrinsics(calib, warnings=said), f"file {calib}"
    elif kind == "auto":
        K, source = images.K, "simulator intrinsics (exact)"
    else:
        h, w = images.config.height, images.config.width
        K = K_from_image_size(w, h, focal_factor)
        source = f"guess: fx = fy = {focal_factor:g} * max({w}, {h}) = {K[0, 0]:.1f} px, principal point at centre"
        log.warning("no intrinsics given; %s", source)
    return VOInput(images, validate_K(K, source=str(calib or spec)), source, images.ground_truth, "simcam", tuple(said))


class FrameRange:
    """The first ``count`` images of an ``ImageSequence`` starting at ``start`` (same interface)."""

    def __init__(self, images: Any, start: int = 0, count: int | None = None):
        if count is not None and count < 1:
            raise ConfigError(f"frame count must be >= 1, got {count}", source="max_frames")
        n = len(images)
        if not 0 <= start < n:
            raise DataError(f"start frame {start} outside 0..{n - 1}", source=getattr(images, "name", "images"))
        stop = n if count is None else min(n, start + count)
        self.images, self.start, self.stop = images, start, stop
        self.name = getattr(images, "name", "images")

    def __len__(self) -> int:
        return self.stop - self.start

    def read_image(self, index: int) -> np.ndarray:
        if not 0 <= index < len(self):
            raise IndexError(index)
        return self.images.read_image(self.start + index)

    @property
    def K(self) -> np.ndarray | None:
        return self.images.K

    @property
    def timestamps_s(self) -> np.ndarray | None:
        ts = self.images.timestamps_s
        return None if ts is None else np.asarray(ts)[self.start:self.stop]

    @property
    def ground_truth(self) -> Trajectory | None:
        gt = self.images.ground_truth
        return None if gt is None else gt[self.start:self.stop]


def frame_range(vo_input: VOInput, start: int = 0, count: int | None = None) -> VOInput:
    """``vo_input`` restricted to frames ``start .. start + count - 1``."""
    if start == 0 and (count is None or count >= len(vo_input.images)):
        return vo_input
    images = FrameRange(vo_input.images, start, count)
    return replace(vo_input, images=images, ground_truth=images.ground_truth)


def self_calibrate(vo_input: VOInput, config: Any = None, on_step: Any = None, workers: int | None = 1) -> tuple[VOInput, Any]:
    """Replace a size-based K guess by the focal length self-calibrated from the sequence
    (:func:`lidarkit.vo.autocalib.estimate_focal`, its ``workers``); when the motion does not constrain it the guess
    stays and a warning names the reason. Inputs with given intrinsics are returned unchanged (estimate None)."""
    from lidarkit.vo.autocalib import estimate_focal

    if not vo_input.K_source.startswith("guess"):
        return vo_input, None
    guess_factor = vo_input.K[0, 0] / max(vo_input.K[0, 2] * 2 + 1, vo_input.K[1, 2] * 2 + 1)
    est = estimate_focal(vo_input.images, config, focal_factor=float(guess_factor), on_step=on_step, workers=workers)
    if not est.constrained:
        log.warning("focal length self-calibration: %s; keeping the %s", est.reason, vo_input.K_source)
        return vo_input, est
    K = vo_input.K.copy()
    K[0, 0] = K[1, 1] = est.focal_px
    return replace(vo_input, K=K, K_source=est.describe()), est
