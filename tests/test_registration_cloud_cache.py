"""Variants that keep their prepared backend clouds can still be pickled and deep-copied (worker processes, copies)."""

from __future__ import annotations

import copy
import pickle

import numpy as np
import pytest

from lidarkit.registration import available_icp, get_icp
from lidarkit.samples import sample_path


@pytest.mark.parametrize("name", ["small_gicp", "open3d_point_to_plane", "open3d_gicp"])
def test_a_variant_pickled_after_an_align_aligns_as_before(name):
    """After a first align the cached small_gicp / Open3D clouds made pickle (and small_gicp's deepcopy) a TypeError
    ("cannot pickle 'small_gicp.PointCloud'"); the cache travels empty, and the copy's next align gives the same pose."""
    if name not in available_icp():
        pytest.skip(f"{name} is not installed")
    source = np.load(sample_path("kitti_pair", "000095.npy"))[::8]
    target = np.load(sample_path("kitti_pair", "000094.npy"))[::8]
    icp = get_icp(name)
    first = icp.align(source, target).T_target_source
    for restored in (pickle.loads(pickle.dumps(icp)), copy.deepcopy(icp)):
        np.testing.assert_allclose(restored.align(source, target).T_target_source, first, atol=1e-9)
    np.testing.assert_allclose(icp.align(source, target).T_target_source, first, atol=1e-9)  # the original's cache kept
