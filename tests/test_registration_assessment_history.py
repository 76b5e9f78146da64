"""A result's RMSE history says when it is the final RMSE alone (the library reports none per iteration)."""

from __future__ import annotations

import numpy as np

from lidarkit.geometry import transform_points
from lidarkit.registration import get_icp
from lidarkit.registration.assessment import assess_alignment

FINAL_RMSE_ONLY_KEY = "rmse_history_final_only"  # (as RegistrationResult.extra names it)


def corner_cloud(rng: np.random.Generator, n: int = 2000) -> np.ndarray:
    """(n, 3) float64 points on three orthogonal walls: every direction constrained."""
    uv = rng.uniform(0.0, 5.0, size=(n, 2))
    wall = rng.integers(0, 3, size=n)
    xyz = np.zeros((n, 3))
    for k in range(3):
        on = wall == k
        xyz[on, (k + 1) % 3], xyz[on, (k + 2) % 3] = uv[on, 0], uv[on, 1]
    return xyz + rng.normal(0.0, 0.002, size=xyz.shape)


def test_a_history_of_the_final_rmse_alone_is_flagged_and_a_measured_one_is_not(rng):
    """small_gicp's rmse_history is lidarkit's final RMSE alone, one value beside its 3-4 iterations, and nothing said
    so: a report drew it as an ICP that stopped after one step. The result's extra now says so; vanilla's history,
    measured at the start and after each iteration, is not flagged."""
    target = corner_cloud(rng)
    T = np.eye(4)
    T[:3, 3] = [0.05, -0.03, 0.02]
    source = transform_points(np.linalg.inv(T), target)
    gicp = get_icp("small_gicp").align(source, target)
    assert gicp.iterations >= 1 and len(gicp.rmse_history) == 1 and gicp.extra.get(FINAL_RMSE_ONLY_KEY) is True
    o3d = get_icp("open3d_point_to_plane").align(source, target)  # (Open3D's inlier RMSE, passed on by lidarkit)
    assert len(o3d.rmse_history) == 1 and o3d.extra.get(FINAL_RMSE_ONLY_KEY) is True
    vanilla = get_icp("vanilla").align(source, target)
    assert len(vanilla.rmse_history) == vanilla.iterations + 1 and FINAL_RMSE_ONLY_KEY not in vanilla.extra

    assessment = assess_alignment(source, target, T, 0.5, covariance_model=None)
    assert FINAL_RMSE_ONLY_KEY not in assessment.to_result(T, rmse_history=(0.2, 0.1)).extra
    assert assessment.to_result(T).rmse_history == (assessment.rmse_m,)

