"""Point-cloud preprocessing for registration: voxel downsampling, range crop, ground removal.

All functions take ``(N, 3)`` float arrays in the sensor frame (z up, origin at the sensor) and
return new arrays; nothing is modified in place.
"""

from __future__ import annotations

import logging

import numpy as np

from lidarkit.errors import ConfigError, DataError
from lidarkit.geometry import as_points
from lidarkit.params import is_real_number

# ground segmentation lives in registration.ground; these names stay importable from here
from lidarkit.registration.ground.base import KITTI_SENSOR_HEIGHT_M
from lidarkit.registration.ground.height import ground_mask_by_height
from lidarkit.registration.ground.ransac import ground_mask_by_plane

log = logging.getLogger(__name__)


def voxel_downsample(points_xyz: np.ndarray, voxel_size_m: float) -> np.ndarray:
    """Centroid of the points in each occupied cubic voxel of edge ``voxel_size_m`` -> ``(K, 3)`` float64.

    Output order follows the sorted voxel keys, so the result is deterministic. ConfigError for a size that is not a
    finite positive number, DataError for points that are not ``(N, 3)`` finite numbers (a NaN point became an all-NaN
    centroid, a (3, N) array numpy's broadcast error).
    """
    if not is_real_number(voxel_size_m) or not 0 < voxel_size_m < np.inf:
        raise ConfigError(f"voxel size must be a finite number > 0, got {voxel_size_m!r}", source="voxel_size_m")
    try:
        pts = np.asarray(points_xyz, dtype=np.float64)
    except (TypeError, ValueError):
        raise DataError(f"expected an (N, 3) point array, got {type(points_xyz).__name__}", source="points") from None
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise DataError(f"expected an (N, 3) point array, got shape {pts.shape}", source="points")
    if len(pts) == 0:
        return pts.reshape(0, 3)
    with np.errstate(over="ignore"):
        finite_sum = np.isfinite(pts.sum())  # (one pass on good data: a NaN or inf makes the sum so)
    if not finite_sum:
        n_bad = int(np.count_nonzero(~np.isfinite(pts).all(axis=1)))
        raise DataError(f"{n_bad} point(s) with NaN or infinite coordinates" if n_bad else
                        "coordinates too large to average (their sum overflows float64)", source="points")
    keys = np.floor(pts / voxel_size_m).astype(np.int64)
    keys -= np.array([keys[:, i].min() for i in range(3)])  # per column: an axis=0 reduction is ~20x slower
    span = np.array([keys[:, i].max() for i in range(3)]) + 1
    if float(span[0]) * float(span[1]) * float(span[2]) >= 2.0**62:
        raise ConfigError(f"voxel grid too large for {voxel_size_m} m voxels", source="voxel_size_m")
    flat = (keys[:, 0] * span[1] + keys[:, 1]) * span[2] + keys[:, 2]
    inverse, counts = _voxel_groups(flat)
    sums = np.stack([np.bincount(inverse, weights=pts[:, d], minlength=len(counts)) for d in range(3)], axis=1)
    return sums / counts[:, None]


def _voxel_groups(flat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``np.unique(flat, return_inverse=True, return_counts=True)[1:]`` (each key's rank among the sorted distinct keys,
    and how many share each), the same arrays in half the time: one stable argsort (numpy's is the faster of its two
    on these keys) and a running count, where np.unique took more passes (1.4 vs 0.7 ms for a KITTI scan's 0.5 m
    surface voxels)."""
    order = np.argsort(flat, kind="stable")
    ordered = flat[order]
    first = np.empty(len(ordered), dtype=bool)
    first[:1] = True
    np.not_equal(ordered[1:], ordered[:-1], out=first[1:])
    inverse = np.empty(len(ordered), dtype=np.intp)
    inverse[order] = np.cumsum(first) - 1
    counts = np.diff(np.flatnonzero(np.append(first, True)))
    return inverse, counts


def range_mask(points_xyz: np.ndarray, min_range_m: float = 0.0, max_range_m: float = np.inf) -> np.ndarray:
    """Boolean ``(N,)`` mask of points whose distance to the sensor is in ``[min_range_m, max_range_m]``.

    ConfigError unless ``0 <= min_range_m < max_range_m`` with a finite minimum (a NaN bound emptied the cloud without
    a word), DataError for points that are not ``(N, 3)`` finite numbers (an ``(N, 2)`` array was cropped in 2D)."""
    _check_range(min_range_m, max_range_m)
    return _within_range(as_points(points_xyz, "points"), min_range_m, max_range_m)


def crop_range(points_xyz: np.ndarray, min_range_m: float = 0.0, max_range_m: float = np.inf) -> np.ndarray:
    """Points whose distance to the sensor lies in ``[min_range_m, max_range_m]`` (checked as :func:`range_mask`)."""
    _check_range(min_range_m, max_range_m)
    pts = as_points(points_xyz, "points")
    return pts[_within_range(pts, min_range_m, max_range_m)]


def _check_range(min_range_m: float, max_range_m: float) -> None:
    if not (is_real_number(min_range_m) and is_real_number(max_range_m) and np.isfinite(min_range_m)
            and 0 <= min_range_m < max_range_m):  # (NaN fails every comparison)
        shown = [repr(v.item() if isinstance(v, np.generic) else v) for v in (min_range_m, max_range_m)]
        raise ConfigError(f"need 0 <= min_range_m < max_range_m (a finite minimum), got {shown[0]}, {shown[1]}", source="range crop")


def _within_range(points_xyz: np.ndarray, min_range_m: float, max_range_m: float) -> np.ndarray:
    r = np.linalg.norm(points_xyz, axis=1)
    return (r >= min_range_m) & (r <= max_range_m)


def remove_ground(points_xyz: np.ndarray, method: str = "height", **options: float) -> np.ndarray:
    """Points that are not ground according to the segmenter ``method`` of :mod:`lidarkit.registration.ground`."""
    from lidarkit.registration.ground import get_ground_segmenter

    return np.asarray(points_xyz, dtype=np.float64)[~get_ground_segmenter(method, **options).segment(points_xyz)]


__all__ = [
    "KITTI_SENSOR_HEIGHT_M",
    "crop_range",
    "ground_mask_by_height",
    "ground_mask_by_plane",
    "range_mask",
    "remove_ground",
    "voxel_downsample",
]
