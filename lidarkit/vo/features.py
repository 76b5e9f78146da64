"""Image preprocessing and feature detection (GFTT, FAST, ORB, SIFT, AKAZE) with grid bucketing.

``get_preprocessor(cfg)`` and ``get_detector(cfg)`` are the stage factories; a detector returns
``(points_px (N, 2) float32, descriptors (N, D) or None)``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np

from lidarkit.errors import ConfigError
from lidarkit.vo.config import FeatureConfig, PreprocessConfig

_SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.01)

Preprocessor = Callable[[np.ndarray], np.ndarray]


PREPROCESSORS = ("none", "clahe", "gaussian", "bilateral")


def get_preprocessor(cfg: PreprocessConfig | str = "none") -> Preprocessor:
    """Image filter for ``cfg.method`` (none, clahe, gaussian, bilateral): uint8 (H, W) -> uint8 (H, W)."""
    if isinstance(cfg, str):
        if cfg not in PREPROCESSORS:
            raise ConfigError(f"unknown preprocessing {cfg!r}; known: {', '.join(PREPROCESSORS)}", source="preprocess")
        cfg = PreprocessConfig(method=cfg)
    if cfg.method == "none":
        return lambda image: image
    if cfg.method == "clahe":
        clahe = cv2.createCLAHE(clipLimit=cfg.clahe_clip_limit, tileGridSize=(cfg.clahe_tile_grid, cfg.clahe_tile_grid))
        return clahe.apply
    k = cfg.blur_kernel_px  # odd (PreprocessConfig refuses even sizes)
    if cfg.method == "gaussian":
        return lambda image: cv2.GaussianBlur(image, (k, k), 0)
    return lambda image: cv2.bilateralFilter(image, k, 50, 50)


def bucket_indices(points_px: np.ndarray, scores: np.ndarray, image_shape: tuple[int, int], rows: int, cols: int,
                   per_cell: int) -> np.ndarray:
    """Indices of the ``per_cell`` highest-scoring points in each of ``rows x cols`` image cells (vectorized)."""
    if len(points_px) == 0:
        return np.zeros(0, dtype=np.int64)
    h, w = image_shape
    cell_r = np.clip((points_px[:, 1] * rows / h).astype(np.int64), 0, rows - 1)
    cell_c = np.clip((points_px[:, 0] * cols / w).astype(np.int64), 0, cols - 1)
    cell = cell_r * cols + cell_c
    order = np.lexsort((-np.asarray(scores, dtype=np.float64), cell))
    sorted_cell = cell[order]
    first = np.searchsorted(sorted_cell, sorted_cell, side="left")
    rank = np.arange(len(order)) - first
    return np.sort(order[rank < per_cell])


def _akaze_factory():
    """``cv2.AKAZE_create`` (OpenCV 4) or ``cv2.xfeatures2d.AKAZE_create`` (OpenCV 5 with opencv-contrib)."""
    factory = getattr(cv2, "AKAZE_create", None) or getattr(getattr(cv2, "xfeatures2d", None), "AKAZE_create", None)
    if factory is None:
        raise ConfigError(f"AKAZE is not in this OpenCV build ({cv2.__version__}); OpenCV 5 has it only in "
                          "opencv-contrib (pip install opencv-contrib-python-headless); use orb or sift",
                          source="detector")
    return factory


@dataclass
class Detector:
    """A configured detector; ``has_descriptors`` tells whether descriptor matching is possible."""

    cfg: FeatureConfig

    def __post_init__(self) -> None:
        c = self.cfg
        self.name = c.detector
        self.has_descriptors = c.detector in ("orb", "sift", "akaze")
        self._cells = c.grid_rows * c.grid_cols
        oversample = 1 if self._cells == 1 else 3
        n = min(c.max_features * oversample, 200000)
        if c.detector == "orb":
            self._cv = cv2.ORB_create(nfeatures=n)
            self.norm = cv2.NORM_HAMMING
        elif c.detector == "sift":
            self._cv = cv2.SIFT_create(nfeatures=0 if c.max_features >= 100000 else n)
            self.norm = cv2.NORM_L2
        elif c.detector == "akaze":
            self._cv = _akaze_factory()(threshold=c.akaze_threshold)
            self.norm = cv2.NORM_HAMMING
        elif c.detector == "fast":
            self._cv = cv2.FastFeatureDetector_create(threshold=c.fast_threshold, nonmaxSuppression=True)
            self.norm = None
        else:
            self._cv = None
            self.norm = None

    @property
    def per_cell_budget(self) -> int:
        """Features kept per grid cell: ``ceil(max_features / cells)``. The budget is shared out, not capped: a frame
        gives up to ``cells x`` this (32 for a budget of 8 on the 4 x 8 grid)."""
        return max(1, -(-self.cfg.max_features // self._cells))

    def detect(self, image: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """Features of a uint8 (H, W) image: ``points_px (N, 2) float32`` and ``descriptors (N, D)`` or None; up to
        :attr:`per_cell_budget` per grid cell (with one cell, the detector's own ``max_features`` limit)."""
        c = self.cfg
        per_cell = self.per_cell_budget
        if c.detector == "gftt":
            points = self._gftt(image, per_cell)
            return self._subpixel(image, points), None
        if self._cells == 1 and self.has_descriptors:
            keypoints, desc = self._cv.detectAndCompute(image, None)
            if c.detector == "akaze" and len(keypoints) > c.max_features:
                keep = np.argsort([-k.response for k in keypoints], kind="stable")[: c.max_features]
                keypoints = [keypoints[i] for i in keep]
                desc = desc[keep]
            return self._subpixel(image, self._points(keypoints)), desc
        keypoints = self._cv.detect(image, None)
        if keypoints:
            pts = self._points(keypoints)
            scores = np.array([k.response for k in keypoints])
            keep = bucket_indices(pts, scores, image.shape[:2], c.grid_rows, c.grid_cols, per_cell)
            keypoints = [keypoints[i] for i in keep]
        if not self.has_descriptors:
            return self._subpixel(image, self._points(keypoints)), None
        if not keypoints:
            return np.zeros((0, 2), np.float32), None
        keypoints, desc = self._cv.compute(image, keypoints)
        return self._subpixel(image, self._points(keypoints)), desc

    @staticmethod
    def _points(keypoints) -> np.ndarray:
        if not keypoints:
            return np.zeros((0, 2), np.float32)
        return np.asarray(cv2.KeyPoint_convert(keypoints), dtype=np.float32).reshape(-1, 2)

    def _gftt(self, image: np.ndarray, per_cell: int) -> np.ndarray:
        c = self.cfg
        h, w = image.shape[:2]
        found = []
        for i in range(c.grid_rows):
            y0, y1 = i * h // c.grid_rows, (i + 1) * h // c.grid_rows
            for j in range(c.grid_cols):
                x0, x1 = j * w // c.grid_cols, (j + 1) * w // c.grid_cols
                corners = cv2.goodFeaturesToTrack(image[y0:y1, x0:x1], per_cell, c.gftt_quality, c.min_distance_px)
                if corners is not None:
                    found.append(corners.reshape(-1, 2) + np.array([x0, y0], np.float32))
        return np.concatenate(found).astype(np.float32) if found else np.zeros((0, 2), np.float32)

    def _subpixel(self, image: np.ndarray, points: np.ndarray) -> np.ndarray:
        """Corner positions refined by ``cv2.cornerSubPix`` when ``cfg.subpixel`` (gftt, fast, orb corners; the
        descriptors stay those computed at the detected position). SIFT/AKAZE are refused by FeatureConfig."""
        if not self.cfg.subpixel or len(points) == 0:
            return points
        refined = cv2.cornerSubPix(image, points.reshape(-1, 1, 2).copy(), (5, 5), (-1, -1), _SUBPIX_CRITERIA)
        return refined.reshape(-1, 2)


DETECTORS = ("gftt", "fast", "orb", "sift", "akaze")


def get_detector(cfg: FeatureConfig | str, **params) -> Detector:
    """Detector from a FeatureConfig or a name plus FeatureConfig fields (``get_detector("orb", max_features=3000)``)."""
    if isinstance(cfg, str):
        if cfg not in DETECTORS:
            raise ConfigError(f"unknown detector {cfg!r}; known: {', '.join(DETECTORS)}", source="detector")
        cfg = FeatureConfig(detector=cfg, **params)  # (a bad parameter: ConfigError naming the field)
    return Detector(cfg)
