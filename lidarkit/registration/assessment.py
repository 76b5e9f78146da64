"""Common end-of-registration bookkeeping: final correspondences, fitness, RMSE and degeneracy."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lidarkit.geometry import transform_points
from lidarkit.registration.base import Degeneracy
from lidarkit.registration.degeneracy import assess_degeneracy
from lidarkit.registration.neighbors import NearestNeighbors


@dataclass(frozen=True)
class Assessment:
    """Correspondences within ``inlier_distance_m`` of the source mapped by the final pose."""

    n_correspondences: int
    fitness: float
    rmse_m: float
    degeneracy: Degeneracy


def assess_alignment(
    source_xyz: np.ndarray,
    target_xyz: np.ndarray,
    T_target_source: np.ndarray,
    inlier_distance_m: float,
    neighbors: NearestNeighbors | None = None,
    dist2: np.ndarray | None = None,
    index: np.ndarray | None = None,
) -> Assessment:
    """Score a pose: pass ``dist2``/``index`` of the final correspondences if already known."""
    aligned = transform_points(T_target_source, source_xyz)
    if dist2 is None or index is None:
        if neighbors is None:
            neighbors = NearestNeighbors(target_xyz, backend="scipy")
        dist2, index = neighbors.query(aligned)
    inlier = dist2 <= inlier_distance_m**2
    n = int(inlier.sum())
    rmse = float(np.sqrt(dist2[inlier].mean())) if n else float("nan")
    degeneracy = assess_degeneracy(aligned[inlier], target_xyz, index[inlier])
    return Assessment(n_correspondences=n, fitness=n / max(len(source_xyz), 1), rmse_m=rmse, degeneracy=degeneracy)


__all__ = ["Assessment", "assess_alignment"]
