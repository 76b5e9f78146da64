"""``ransac``: one plane fitted by RANSAC (Open3D) to the low points; its inliers are ground.

Holds when the whole scan sees one planar ground; a hill or a dip bends the ground away from any one plane.
"""

from __future__ import annotations

import logging

import numpy as np
from pydantic import Field

from lidarkit.registration.ground.base import KITTI_SENSOR_HEIGHT_M, GroundConfig, GroundSegmenter, register_ground_segmenter

log = logging.getLogger(__name__)


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


class RansacConfig(GroundConfig):
    distance_threshold_m: float = Field(0.2, gt=0, description="max point-plane distance of ground points (m)")
    num_iterations: int = Field(200, ge=1, description="RANSAC iterations")
    max_tilt_deg: float = Field(20.0, ge=0, le=90, description="a plane tilted more than this is not ground (nothing removed)")
    sensor_height_m: float = Field(KITTI_SENSOR_HEIGHT_M, ge=0, description="the plane is fitted to points below half this height (m)")
    seed: int = Field(0, description="Open3D random seed")


@register_ground_segmenter("ransac")
class RansacSegmenter(GroundSegmenter):
    """One RANSAC plane (Open3D segment_plane) fitted to the low points."""

    Config = RansacConfig

    def _segment(self, points_xyz: np.ndarray) -> np.ndarray:
        c = self.config
        return ground_mask_by_plane(points_xyz, c.distance_threshold_m, c.num_iterations, c.max_tilt_deg, c.sensor_height_m, c.seed)
