"""``height``: every point lower than a fixed level below the sensor is ground (the first report's rule).

Right on a flat road seen by a level sensor; on hills it keeps uphill ground and cuts downhill objects.
"""

from __future__ import annotations

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


def ground_mask_by_height(
    points_xyz: np.ndarray, sensor_height_m: float = KITTI_SENSOR_HEIGHT_M, ground_threshold_m: float = 0.73
) -> np.ndarray:
    """Boolean ``(N,)`` mask of ground points: lower than ``ground_threshold_m`` above the road.

    The road is assumed flat at ``z = -sensor_height_m`` in the sensor frame. The defaults reproduce
    the report's rule "drop points more than 1 m below the LiDAR" for KITTI (1.73 m - 0.73 m = 1 m).
    Settings are checked as the ``height`` segmenter checks them (a NaN threshold marked no ground), the points as
    every segmenter's are (an ``(N, 2)`` array raised an IndexError).
    """
    config = ground_config("height", sensor_height_m=sensor_height_m, ground_threshold_m=ground_threshold_m)
    return _below_ground_level(as_points(points_xyz, "points"), config)


def _below_ground_level(points_xyz: np.ndarray, config: HeightConfig) -> np.ndarray:
    return points_xyz[:, 2] < -config.sensor_height_m + config.ground_threshold_m


class HeightConfig(GroundConfig):
    sensor_height_m: float = Field(KITTI_SENSOR_HEIGHT_M, ge=0, description="sensor height above the road (m)")
    ground_threshold_m: float = Field(0.73, ge=0, description="points lower than this above the road are ground (m)")


@register_ground_segmenter("height")
class HeightSegmenter(GroundSegmenter):
    """Below a fixed level under the sensor (flat road assumed)."""

    Config = HeightConfig

    def _segment(self, points_xyz: np.ndarray) -> np.ndarray:
        return _below_ground_level(points_xyz, self.config)
