"""``knn``: the report's leaf-size experiment — the same point-to-point ICP with the KD-tree leaf size
(scipy ``cKDTree(leafsize=...)``) as a parameter, or exact brute-force nearest neighbours.

A KD-tree query is exact for any leaf size; the leaf size only trades tree depth against the number
of points scanned per leaf, so it changes runtime, not the result (the benchmark measures both).
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from lidarkit.registration.neighbors import MAX_BRUTE_FORCE_PAIRS
from lidarkit.registration.registry import register_icp
from lidarkit.registration.vanilla import VanillaConfig, VanillaICP


class KnnConfig(VanillaConfig):
    nn_backend: Literal["auto", "scipy", "open3d", "brute"] = Field("scipy", description="nearest-neighbour backend")
    leafsize: int = Field(16, ge=1, description="cKDTree leaf size: 1 = single-point leaves, 16 = scipy default")
    exact: bool = Field(False, description="exact brute-force nearest neighbours (needs a small or voxelized cloud)")
    coarse_stride: int = Field(1, ge=1, description="1: single-stage ICP, so leaf sizes are compared on equal work")


@register_icp("knn")
class KnnICP(VanillaICP):
    """Point-to-point ICP whose nearest-neighbour structure is the experiment's variable (vanilla's loop; the index,
    brute force included, is :func:`~lidarkit.registration.vanilla.target_index`'s)."""

    Config = KnnConfig


__all__ = ["MAX_BRUTE_FORCE_PAIRS", "KnnConfig", "KnnICP"]
