"""``ground_filtered``: remove ground points from both clouds, then run ``vanilla``.

On roads a full-cloud point-to-point ICP matches ground rings to ground rings, which pulls the
estimate towards zero forward motion; dropping the ground (the report's fix) removes that bias.
"""

from __future__ import annotations

import dataclasses
from typing import Literal

import numpy as np
from pydantic import Field

from lidarkit.errors import RegistrationError
from lidarkit.registration.base import RegistrationResult
from lidarkit.registration.neighbors import NearestNeighbors
from lidarkit.registration.planar import refuse_2d
from lidarkit.registration.preprocess import KITTI_SENSOR_HEIGHT_M, ground_mask_by_height, ground_mask_by_plane
from lidarkit.registration.registry import register_icp
from lidarkit.registration.vanilla import VanillaConfig, VanillaICP, prepare, staged_icp


class GroundFilteredConfig(VanillaConfig):
    ground_method: Literal["height", "ransac"] = Field("height", description="'height': below a fixed level; 'ransac': plane fit")
    sensor_height_m: float = Field(KITTI_SENSOR_HEIGHT_M, ge=0, description="sensor height above the road (m)")
    ground_threshold_m: float = Field(
        0.73, description="height method: points lower than this above the road are ground (1.73-0.73 = 1 m below the sensor)"
    )
    ransac_distance_m: float = Field(0.2, gt=0, description="ransac method: max point-plane distance of ground points (m)")
    ransac_iterations: int = Field(200, ge=1, description="ransac method: RANSAC iterations")
    seed: int = Field(0, description="ransac method: Open3D random seed")


def ground_mask(points_xyz: np.ndarray, config: GroundFilteredConfig) -> np.ndarray:
    """``(N,)`` bool mask of ground points according to the config."""
    if config.ground_method == "height":
        return ground_mask_by_height(points_xyz, config.sensor_height_m, config.ground_threshold_m)
    return ground_mask_by_plane(
        points_xyz,
        distance_threshold_m=config.ransac_distance_m,
        num_iterations=config.ransac_iterations,
        sensor_height_m=config.sensor_height_m,
        seed=config.seed,
    )


@register_icp("ground_filtered")
class GroundFilteredICP(VanillaICP):
    """Ground removal (height threshold or RANSAC plane) followed by point-to-point ICP."""

    Config = GroundFilteredConfig

    def _align(self, source_xyz: np.ndarray, target_xyz: np.ndarray, init_T: np.ndarray) -> RegistrationResult:
        c = self.config
        if c.ground_method == "ransac":
            refuse_2d(self.name, source_xyz, target_xyz, "a RANSAC ground plane of a 2D scan is the scan plane itself")
        clouds = []
        for name, pts in (("source cloud", source_xyz), ("target cloud", target_xyz)):
            kept = pts[~ground_mask(pts, c)]
            if len(kept) < 3:
                raise RegistrationError(
                    f"only {len(kept)} of {len(pts)} points left after ground removal ({c.ground_method})", source=name
                )
            clouds.append(kept)
        src, dst = prepare(clouds[0], clouds[1], c.voxel_size_m)
        neighbors = NearestNeighbors(dst, backend=c.nn_backend, leafsize=c.leafsize, workers=c.workers)
        result = staged_icp(src, dst, init_T, neighbors, c)
        extra = {**result.extra, "source_points_kept": len(clouds[0]), "target_points_kept": len(clouds[1])}
        return dataclasses.replace(result, extra=extra)
