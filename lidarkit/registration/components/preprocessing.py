"""Preprocessing steps applied to each (deskewed) sweep in the sensor frame, in the order the pipeline lists them.

They are thin components over :mod:`lidarkit.registration.preprocess` and, for ``ground_filter``, the ground
segmenter registry :mod:`lidarkit.registration.ground` (any registered segmenter by name).
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
from pydantic import Field, model_validator

from lidarkit.registration import preprocess
from lidarkit.registration.components.maps import first_per_voxel
from lidarkit.registration.components.registry import Component, ComponentConfig, component_base, register_component


@component_base("preprocess")
class Preprocess(Component):
    """``(N, 3)`` sensor-frame points in, fewer points out."""

    def apply(self, points_xyz: np.ndarray) -> np.ndarray:
        raise NotImplementedError


class RangeCropConfig(ComponentConfig):
    min_range_m: float = Field(0.0, ge=0, description="drop points at or closer than this (m); the pipeline passes its own")
    max_range_m: float = Field(100.0, gt=0, description="drop points at or beyond this (m); the pipeline passes its own")

    @model_validator(mode="after")
    def _order(self) -> "RangeCropConfig":
        if self.max_range_m <= self.min_range_m:
            raise ValueError(f"max_range_m ({self.max_range_m}) must exceed min_range_m ({self.min_range_m})")
        return self


@register_component("preprocess", "range_crop")
class RangeCrop(Preprocess):
    """Keep points with ``min_range_m < range < max_range_m`` (strict, as kiss-icp)."""

    Config = RangeCropConfig

    def apply(self, points_xyz: np.ndarray) -> np.ndarray:
        pts = np.asarray(points_xyz, dtype=np.float64)
        r = np.linalg.norm(pts, axis=1)
        return pts[(r > self.config.min_range_m) & (r < self.config.max_range_m)]


class VoxelDownsampleConfig(ComponentConfig):
    voxel_size_m: float = Field(0.5, gt=0, description="voxel edge (m)")
    mode: Literal["first", "centroid"] = Field("first", description="keep each voxel's first point (kiss-icp) or the centroid")


@register_component("preprocess", "voxel_downsample")
class VoxelDownsample(Preprocess):
    """One point per occupied voxel."""

    Config = VoxelDownsampleConfig

    def apply(self, points_xyz: np.ndarray) -> np.ndarray:
        if self.config.mode == "first":
            return first_per_voxel(points_xyz, self.config.voxel_size_m)
        return preprocess.voxel_downsample(points_xyz, self.config.voxel_size_m)


class GroundFilterConfig(ComponentConfig):
    method: str = Field("height", description="ground segmenter of lidarkit.registration.ground (height, ransac, local_plane, ...)")
    options: dict[str, Any] = Field(default_factory=dict, description="parameters of that segmenter (e.g. sensor_height_m)")

    @model_validator(mode="after")
    def _known(self) -> "GroundFilterConfig":
        from lidarkit.registration.ground import available_ground_segmenters

        names = available_ground_segmenters()
        if self.method not in names:
            raise ValueError(f"unknown ground segmenter {self.method!r}; available: {', '.join(names)}")
        return self


@register_component("preprocess", "ground_filter")
class GroundFilter(Preprocess):
    """Remove the points a ground segmenter marks (flat-road height rule, RANSAC plane, local planes, ...)."""

    Config = GroundFilterConfig

    def __init__(self, config=None, **params):
        from lidarkit.registration.ground import get_ground_segmenter

        super().__init__(config, **params)
        self._segmenter = get_ground_segmenter(self.config.method, **self.config.options)

    def apply(self, points_xyz: np.ndarray) -> np.ndarray:
        pts = np.asarray(points_xyz, dtype=np.float64)
        return pts[~self._segmenter.segment(pts)]


__all__ = ["GroundFilter", "Preprocess", "RangeCrop", "VoxelDownsample"]
