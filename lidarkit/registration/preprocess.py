"""Point-cloud preprocessing for registration: voxel downsampling, range crop, ground removal.

All functions take ``(N, 3)`` float arrays in the sensor frame (z up, origin at the sensor) and
return new arrays; nothing is modified in place.
"""

from __future__ import annotations

import logging

import numpy as np

from lidarkit.errors import ConfigError

log = logging.getLogger(__name__)

#: Mounting height of KITTI's Velodyne HDL-64E above the road (m).
KITTI_SENSOR_HEIGHT_M = 1.73


def voxel_downsample(points_xyz: np.ndarray, voxel_size_m: float) -> np.ndarray:
    """Centroid of the points in each occupied cubic voxel of edge ``voxel_size_m`` -> ``(K, 3)`` float64.

    Output order follows the sorted voxel keys, so the result is deterministic.
    """
    if not voxel_size_m > 0:
        raise ConfigError(f"voxel size must be > 0, got {voxel_size_m}", source="voxel_size_m")
    pts = np.asarray(points_xyz, dtype=np.float64)
    if len(pts) == 0:
        return pts.reshape(0, 3)
    keys = np.floor(pts / voxel_size_m).astype(np.int64)
    keys -= keys.min(axis=0)
    span = keys.max(axis=0) + 1
    if float(span[0]) * float(span[1]) * float(span[2]) >= 2.0**62:
        raise ConfigError(f"voxel grid too large for {voxel_size_m} m voxels", source="voxel_size_m")
    flat = (keys[:, 0] * span[1] + keys[:, 1]) * span[2] + keys[:, 2]
    _, inverse, counts = np.unique(flat, return_inverse=True, return_counts=True)
    sums = np.stack([np.bincount(inverse, weights=pts[:, d], minlength=len(counts)) for d in range(3)], axis=1)
    return sums / counts[:, None]


def range_mask(points_xyz: np.ndarray, min_range_m: float = 0.0, max_range_m: float = np.inf) -> np.ndarray:
    """Boolean ``(N,)`` mask of points whose distance to the sensor is in ``[min_range_m, max_range_m]``."""
    if min_range_m < 0 or max_range_m <= min_range_m:
        raise ConfigError(f"need 0 <= min_range_m < max_range_m, got {min_range_m}, {max_range_m}", source="range crop")
    r = np.linalg.norm(np.asarray(points_xyz, dtype=np.float64), axis=1)
    return (r >= min_range_m) & (r <= max_range_m)


def crop_range(points_xyz: np.ndarray, min_range_m: float = 0.0, max_range_m: float = np.inf) -> np.ndarray:
    """Points whose distance to the sensor lies in ``[min_range_m, max_range_m]``."""
    return np.asarray(points_xyz, dtype=np.float64)[range_mask(points_xyz, min_range_m, max_range_m)]


def ground_mask_by_height(
    points_xyz: np.ndarray, sensor_height_m: float = KITTI_SENSOR_HEIGHT_M, ground_threshold_m: float = 0.73
) -> np.ndarray:
    """Boolean ``(N,)`` mask of ground points: lower than ``ground_threshold_m`` above the road.

    The road is assumed flat at ``z = -sensor_height_m`` in the sensor frame. The defaults reproduce
    the report's rule "drop points more than 1 m below the LiDAR" for KITTI (1.73 m - 0.73 m = 1 m).
    """
    if sensor_height_m < 0:
        raise ConfigError(f"sensor height must be >= 0, got {sensor_height_m}", source="sensor_height_m")
    z = np.asarray(points_xyz, dtype=np.float64)[:, 2]
    return z < -sensor_height_m + ground_threshold_m


def ground_mask_by_plane(
    points_xyz: np.ndarray,
    distance_threshold_m: float = 0.2,
    num_iterations: int = 200,
    max_tilt_deg: float = 20.0,
    sensor_height_m: float = KITTI_SENSOR_HEIGHT_M,
    seed: int = 0,
) -> np.ndarray:
    """Boolean ``(N,)`` mask of points within ``distance_threshold_m`` of a RANSAC ground plane.

    The plane is fitted (Open3D ``segment_plane``, global seed ``seed``) to the points below the
    sensor's half height; a plane tilted more than ``max_tilt_deg`` from horizontal is rejected and no
    point is marked (logged), so a wall is never removed as "ground".
    """
    import open3d as o3d

    pts = np.asarray(points_xyz, dtype=np.float64)
    low = pts[:, 2] < -0.5 * sensor_height_m
    if low.sum() < 3:
        log.info("RANSAC ground: fewer than 3 points below the sensor, nothing removed")
        return np.zeros(len(pts), dtype=bool)
    o3d.utility.random.seed(int(seed))
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts[low]))
    plane, _ = cloud.segment_plane(float(distance_threshold_m), 3, int(num_iterations))
    normal = np.asarray(plane[:3], dtype=np.float64)
    norm = np.linalg.norm(normal)
    if norm == 0 or np.degrees(np.arccos(min(1.0, abs(normal[2]) / norm))) > max_tilt_deg:
        log.info("RANSAC ground: best plane is not horizontal (normal %s), nothing removed", normal)
        return np.zeros(len(pts), dtype=bool)
    dist = np.abs(pts @ normal + plane[3]) / norm
    return dist <= distance_threshold_m


def remove_ground(points_xyz: np.ndarray, method: str = "height", **options: float) -> np.ndarray:
    """Points that are not ground, by ``method`` ``"height"`` (:func:`ground_mask_by_height`) or ``"ransac"``."""
    if method == "height":
        mask = ground_mask_by_height(points_xyz, **options)
    elif method == "ransac":
        mask = ground_mask_by_plane(points_xyz, **options)
    else:
        raise ConfigError(f"unknown ground removal method {method!r}; available: height, ransac", source="ground_method")
    return np.asarray(points_xyz, dtype=np.float64)[~mask]


__all__ = [
    "KITTI_SENSOR_HEIGHT_M",
    "crop_range",
    "ground_mask_by_height",
    "ground_mask_by_plane",
    "range_mask",
    "remove_ground",
    "voxel_downsample",
]
