"""Correspondences between two frames: descriptor matching (BF cross-check, KNN + Lowe ratio) or KLT tracking.

``get_matcher(cfg, norm)`` returns a function ``(desc_ref, desc_cur) -> (idx_ref (K,), idx_cur (K,))``;
``track_klt`` follows points with pyramidal Lucas-Kanade and a forward-backward consistency check.
"""

from __future__ import annotations

from collections.abc import Callable

import cv2
import numpy as np

from lidarkit.errors import ConfigError
from lidarkit.vo.config import MatchConfig

Matcher = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]
MATCHERS = ("klt", "bf_cross", "knn_ratio")


def _empty() -> tuple[np.ndarray, np.ndarray]:
    return np.zeros(0, np.int64), np.zeros(0, np.int64)


def get_matcher(cfg: MatchConfig | str, norm: int = cv2.NORM_HAMMING, **params) -> Matcher:
    """Descriptor matcher for ``cfg.method`` (``bf_cross`` or ``knn_ratio``) with the detector's norm."""
    if isinstance(cfg, str):
        if cfg not in MATCHERS:
            raise ConfigError(f"unknown matcher {cfg!r}; known: {', '.join(MATCHERS)}", source="matcher")
        cfg = MatchConfig(method=cfg, **params)
    if cfg.method == "klt":
        raise ConfigError("klt tracks points, it does not match descriptors; use track_klt", source="matcher")
    if cfg.method == "bf_cross":
        bf = cv2.BFMatcher(norm, crossCheck=True)

        def match_cross(desc_ref: np.ndarray, desc_cur: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            if desc_ref is None or desc_cur is None or len(desc_ref) == 0 or len(desc_cur) == 0:
                return _empty()
            matches = bf.match(desc_ref, desc_cur)
            if not matches:
                return _empty()
            pairs = np.array([(m.queryIdx, m.trainIdx) for m in matches], dtype=np.int64)
            return pairs[:, 0], pairs[:, 1]

        return match_cross

    bf = cv2.BFMatcher(norm, crossCheck=False)
    ratio = cfg.ratio

    def match_ratio(desc_ref: np.ndarray, desc_cur: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if desc_ref is None or desc_cur is None or len(desc_ref) == 0 or len(desc_cur) < 2:
            return _empty()
        knn = bf.knnMatch(desc_ref, desc_cur, k=2)
        rows = np.array([(m[0].queryIdx, m[0].trainIdx, m[0].distance, m[1].distance) for m in knn if len(m) == 2])
        if len(rows) == 0:
            return _empty()
        keep = rows[:, 2] < ratio * rows[:, 3]
        return rows[keep, 0].astype(np.int64), rows[keep, 1].astype(np.int64)

    return match_ratio


def track_klt(image_ref: np.ndarray, image_cur: np.ndarray, points_ref_px: np.ndarray,
              cfg: MatchConfig | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Track ``points_ref_px (N, 2)`` from ``image_ref`` to ``image_cur``.

    Returns ``points_cur_px (N, 2) float32`` and ``ok (N,) bool``: tracked both ways, back within
    ``cfg.klt_fb_max_px`` of the start, and inside the current image.
    """
    cfg = cfg or MatchConfig()
    n = len(points_ref_px)
    if n == 0:
        return np.zeros((0, 2), np.float32), np.zeros(0, bool)
    params = dict(winSize=(cfg.klt_window_px, cfg.klt_window_px), maxLevel=cfg.klt_levels,
                  criteria=(cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01))
    p0 = np.ascontiguousarray(points_ref_px, dtype=np.float32).reshape(-1, 1, 2)
    p1, status, _ = cv2.calcOpticalFlowPyrLK(image_ref, image_cur, p0, None, **params)
    back, status_back, _ = cv2.calcOpticalFlowPyrLK(image_cur, image_ref, p1, None, **params)
    p1 = p1.reshape(-1, 2)
    fb_px = np.linalg.norm(back.reshape(-1, 2) - p0.reshape(-1, 2), axis=1)
    h, w = image_cur.shape[:2]
    inside = (p1[:, 0] >= 0) & (p1[:, 0] <= w - 1) & (p1[:, 1] >= 0) & (p1[:, 1] <= h - 1)
    ok = (status.ravel() == 1) & (status_back.ravel() == 1) & (fb_px < cfg.klt_fb_max_px) & inside
    ok &= np.isfinite(p1).all(axis=1)
    return p1.astype(np.float32), ok
