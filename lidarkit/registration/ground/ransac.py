"""``ransac``: one plane fitted by RANSAC to the low points; its inliers are ground.

Holds when the whole scan sees one planar ground; a hill or a dip bends the ground away from any one plane.
"""

from __future__ import annotations

import logging

import numpy as np
from pydantic import Field

from lidarkit.geometry import as_points
from lidarkit.registration.ground.base import (
    KITTI_SENSOR_HEIGHT_M,
    GroundConfig,
    GroundSegmenter,
    ground_config,
    register_ground_segmenter,
)

log = logging.getLogger(__name__)


#: candidate planes are scored on at most this many of the low points (the winner's inliers then on all of them)
SCORE_POINTS = 4000


class RansacConfig(GroundConfig):
    distance_threshold_m: float = Field(0.2, gt=0, description="max point-plane distance of ground points (m)")
    num_iterations: int = Field(200, ge=1, description="RANSAC iterations")
    max_tilt_deg: float = Field(20.0, ge=0, le=90, description="a plane tilted more than this is not ground (nothing removed)")
    sensor_height_m: float = Field(KITTI_SENSOR_HEIGHT_M, ge=0, description="the plane is fitted to points below half this height (m)")
    seed: int = Field(0, ge=0, description="seed of the RANSAC draws")


def ground_mask_by_plane(
    points_xyz: np.ndarray,
    distance_threshold_m: float = 0.2,
    num_iterations: int = 200,
    max_tilt_deg: float = 20.0,
    sensor_height_m: float = KITTI_SENSOR_HEIGHT_M,
    seed: int = 0,
) -> np.ndarray:
    """Boolean ``(N,)`` mask of points within ``distance_threshold_m`` of a RANSAC ground plane.

    The plane is fitted to the points below the sensor's half height: ``num_iterations`` planes through three of them,
    drawn with ``numpy.random.default_rng(seed)`` and scored at once on a seeded sample of :data:`SCORE_POINTS`; the
    best one's inliers among all low points are refitted by least squares. Open3D's ``segment_plane`` draws on worker
    threads and gave other planes in other processes under one seed (a ground-filtered pose moved by 2 mm between
    runs). A plane tilted more than ``max_tilt_deg`` from horizontal is rejected and no point is marked (logged), so a
    wall is never removed as "ground". Settings are checked as the ``ransac`` segmenter checks them (``num_iterations=0``
    or a negative distance marked no ground), the points as every segmenter's are.
    """
    config = ground_config("ransac", distance_threshold_m=distance_threshold_m, num_iterations=num_iterations,
                           max_tilt_deg=max_tilt_deg, sensor_height_m=sensor_height_m, seed=seed)
    return _plane_inliers(as_points(points_xyz, "points"), config)


def _plane_inliers(pts: np.ndarray, config: RansacConfig) -> np.ndarray:
    """:func:`ground_mask_by_plane` of points and settings already checked (the segmenter's own path)."""
    distance_threshold_m, max_tilt_deg = config.distance_threshold_m, config.max_tilt_deg
    low_pts = pts[pts[:, 2] < -0.5 * config.sensor_height_m]
    if len(low_pts) < 3:
        log.info("RANSAC ground: fewer than 3 points below the sensor, nothing removed")
        return np.zeros(len(pts), dtype=bool)
    rng = np.random.default_rng(config.seed)
    triples = low_pts[rng.integers(0, len(low_pts), size=(config.num_iterations, 3))]  # (I, 3, 3)
    normals = np.cross(triples[:, 1] - triples[:, 0], triples[:, 2] - triples[:, 0])
    length = np.linalg.norm(normals, axis=1)
    good = length > 1e-9  # three distinct, non-collinear points
    if not good.any():
        log.info("RANSAC ground: the low points span no plane, nothing removed")
        return np.zeros(len(pts), dtype=bool)
    normals, triples = normals[good] / length[good, None], triples[good]
    offsets = -np.einsum("ij,ij->i", normals, triples[:, 0])
    sample = low_pts if len(low_pts) <= SCORE_POINTS else low_pts[rng.choice(len(low_pts), SCORE_POINTS, replace=False)]
    counts = (np.abs(sample @ normals.T + offsets) <= distance_threshold_m).sum(axis=0)
    best = int(np.argmax(counts))  # (the first of equal counts: deterministic)
    inliers = low_pts[np.abs(low_pts @ normals[best] + offsets[best]) <= distance_threshold_m]
    normal, offset = normals[best], offsets[best]
    if len(inliers) >= 3:  # least-squares refit: the normal is the direction of least spread of the inliers
        centre = inliers.mean(axis=0)
        normal = np.linalg.svd(inliers - centre, full_matrices=False)[2][-1]
        offset = -float(normal @ centre)
    if np.degrees(np.arccos(min(1.0, abs(float(normal[2]))))) > max_tilt_deg:
        log.info("RANSAC ground: best plane is not horizontal (normal %s), nothing removed", normal)
        return np.zeros(len(pts), dtype=bool)
    return np.abs(pts @ normal + offset) <= distance_threshold_m


@register_ground_segmenter("ransac")
class RansacSegmenter(GroundSegmenter):
    """One RANSAC plane fitted to the low points (seeded numpy draws, scored at once)."""

    Config = RansacConfig

    def _segment(self, points_xyz: np.ndarray) -> np.ndarray:
        return _plane_inliers(points_xyz, self.config)
