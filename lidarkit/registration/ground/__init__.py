"""Ground segmentation: a registry of segmenters, ``segment(points_xyz) -> (N,) bool ground mask``.

>>> from lidarkit.registration.ground import get_ground_segmenter
>>> mask = get_ground_segmenter("local_plane").segment(points_xyz)   # the default of ground_filtered
>>> non_ground = points_xyz[~mask]

Built in: ``local_plane`` (slope-following grid of local planes, the default), ``height`` (fixed level
below the sensor), ``ransac`` (one plane); wrapped libraries (optional extra ``lidarkit[ground]``):
``patchworkpp`` (Patchwork++) and ``csf`` (cloth simulation filter).
"""

from __future__ import annotations

from lidarkit.registration.ground.base import (
    KITTI_SENSOR_HEIGHT_M,
    GroundConfig,
    GroundSegmenter,
    available_ground_segmenters,
    get_ground_segmenter,
    get_ground_segmenter_class,
    ground_config_fields,
    register_ground_segmenter,
)
from lidarkit.registration.ground.height import ground_mask_by_height
from lidarkit.registration.ground.local_plane import local_plane_ground_mask
from lidarkit.registration.ground.ransac import ground_mask_by_plane
from lidarkit.registration.ground import libraries  # noqa: F401  (registers patchworkpp and csf)

#: The segmenter ``ground_filtered`` uses unless told otherwise.
DEFAULT_GROUND_SEGMENTER = "local_plane"

__all__ = [
    "DEFAULT_GROUND_SEGMENTER",
    "KITTI_SENSOR_HEIGHT_M",
    "GroundConfig",
    "GroundSegmenter",
    "available_ground_segmenters",
    "get_ground_segmenter",
    "get_ground_segmenter_class",
    "ground_config_fields",
    "ground_mask_by_height",
    "ground_mask_by_plane",
    "local_plane_ground_mask",
    "register_ground_segmenter",
]
