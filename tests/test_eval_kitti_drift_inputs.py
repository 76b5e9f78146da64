"""drift_segments_possible's arguments: a Trajectory and segment lengths, else one-line ConfigErrors."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import shared_path

from lidarkit.errors import ConfigError
from lidarkit.eval import drift_segments_possible
from lidarkit.trajectory import Trajectory


def test_drift_segments_possible_refuses_what_is_no_trajectory(tmp_path):
    """drift_segments_possible(None) raised TypeError ("object of type 'NoneType' has no len()"), and empty lengths a
    ValueError from min(): ConfigErrors naming the argument. A KITTI 00 stretch of 201 poses (145 m) has room for a
    100 m segment, not for a 200 m one."""
    poses = np.loadtxt(shared_path("evo_testdata", "KITTI_00_gt.txt"))[:201]
    path = tmp_path / "gt_201.txt"
    np.savetxt(path, poses)
    ref = Trajectory.from_kitti(path)
    assert drift_segments_possible(ref) and drift_segments_possible(ref, (100.0,))
    assert not drift_segments_possible(ref, (200.0,))
    with pytest.raises(ConfigError) as refused:
        drift_segments_possible(None)
    assert str(refused.value) == "ref: ref must be a lidarkit Trajectory, got NoneType None"
    with pytest.raises(ConfigError, match=r"^lengths: segment lengths must be a non-empty list of positive numbers"):
        drift_segments_possible(ref, ())
