"""``knn``: the report's leaf-size experiment — the same point-to-point ICP with the KD-tree leaf size
(scipy ``cKDTree(leafsize=...)``) as a parameter, or exact brute-force nearest neighbours.

A KD-tree query is exact for any leaf size; the leaf size only trades tree depth against the number
of points scanned per leaf, so it changes runtime, not the result (the benchmark measures both).
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field

from lidarkit.errors import RegistrationError
from lidarkit.registration.base import RegistrationResult
from lidarkit.registration.neighbors import NearestNeighbors
from lidarkit.registration.registry import register_icp
from lidarkit.registration.vanilla import VanillaConfig, VanillaICP, prepare, staged_icp

#: Refuse brute force beyond this many point pairs per iteration (use voxel_size_m to subsample): one pass over
#: 3.0e9 pairs (the bundled KITTI pair) took 41 s, and ICP makes 20-40 of them (it ran for 10 minutes and more).
MAX_BRUTE_FORCE_PAIRS = 2e8


class KnnConfig(VanillaConfig):
    nn_backend: Literal["auto", "scipy", "open3d", "brute"] = Field("scipy", description="nearest-neighbour backend")
    leafsize: int = Field(16, ge=1, description="cKDTree leaf size: 1 = single-point leaves, 16 = scipy default")
    exact: bool = Field(False, description="exact brute-force nearest neighbours (needs a small or voxelized cloud)")
    coarse_stride: int = Field(1, ge=1, description="1: single-stage ICP, so leaf sizes are compared on equal work")


@register_icp("knn")
class KnnICP(VanillaICP):
    """Point-to-point ICP whose nearest-neighbour structure is the experiment's variable."""

    Config = KnnConfig

    def _align(self, source_xyz: np.ndarray, target_xyz: np.ndarray, init_T: np.ndarray) -> RegistrationResult:
        c = self.config
        src, dst = prepare(source_xyz, target_xyz, c.voxel_size_m)
        backend = "brute" if c.exact else c.nn_backend
        if backend == "brute" and float(len(src)) * len(dst) > MAX_BRUTE_FORCE_PAIRS:
            raise RegistrationError(
                f"exact search over {len(src)} x {len(dst)} points is too slow; set voxel_size_m to subsample",
                source="knn exact",
            )
        neighbors = NearestNeighbors(dst, backend=backend, leafsize=c.leafsize, workers=c.workers)
        return staged_icp(src, dst, init_T, neighbors, c)
