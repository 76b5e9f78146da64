"""Figures docs/registration.md quotes for ground_filtered's fallbacks on the road-only KITTI 94/95 pair."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import shared_path
from registration_helpers import kitti_pair

from lidarkit.geometry import pose_error
from lidarkit.registration import get_icp


def _road(points_xyz: np.ndarray) -> np.ndarray:
    """The road alone: z below -1.5 m, 8 to 40 m out (too little is left after ground removal: the fallbacks run)."""
    r = np.hypot(points_xyz[:, 0], points_xyz[:, 1])
    return points_xyz[(points_xyz[:, 2] < -1.5) & (r > 8.0) & (r < 40.0)]


def test_with_ground_is_vanilla_at_ground_filtereds_gate_not_default_vanilla():
    """The docs called with_ground's pose "vanilla's identical pose": it is vanilla's solve with ground_filtered's
    1.5 m correspondence gate; default vanilla (all pairs) lands 7 mm / 0.09 deg from it, NEES 6.4 under vanilla's entry."""
    source, target, T_true = kitti_pair(shared_path, 94, 95)
    source, target = _road(source), _road(target)
    with_ground = get_icp("ground_filtered", fallback="with_ground").align(source, target)
    gated = get_icp("vanilla", max_correspondence_distance_m=1.5).align(source, target)
    default = get_icp("vanilla").align(source, target)
    np.testing.assert_allclose(with_ground.T_target_source, gated.T_target_source, atol=1e-12)
    dt_m, dr_deg = pose_error(with_ground.T_target_source, default.T_target_source)
    assert dt_m == pytest.approx(0.007, abs=0.0005) and dr_deg == pytest.approx(0.09, abs=0.005)
    assert with_ground.nees(T_true) == pytest.approx(6.4, abs=0.05)
