"""The brute-force ("exact") nearest-neighbour backend against scipy's tree, at the sensor and georeferenced."""

from __future__ import annotations

import numpy as np
import pytest

from lidarkit.registration.neighbors import NearestNeighbors
from lidarkit.samples import sample_path

#: A UTM-like offset (easting, northing, height), where |t|^2 reaches 2e13 m^2.
UTM_OFFSET_M = np.array([512345.6, 4512345.7, 123.4])


@pytest.mark.parametrize("offset", [np.zeros(3), UTM_OFFSET_M], ids=["sensor_frame", "utm"])
def test_brute_backend_finds_the_true_nearest_neighbours_far_from_the_origin(offset):
    """``|t|^2 - 2 p.t`` on UTM coordinates picked a wrong neighbour for 296 of 5485 KITTI points (up to 7 cm farther):
    the terms cancel to 1e-3 m^2. Centred on the target centroid, the picks are scipy's, at the origin and far out."""
    folder = sample_path("kitti_pair")
    source = np.load(folder / "000095.npy").astype(np.float64)[::10] + offset
    target = np.load(folder / "000094.npy").astype(np.float64)[::5] + offset
    exact_d2, exact_idx = NearestNeighbors(target, backend="scipy").query(source)
    brute_d2, brute_idx = NearestNeighbors(target, backend="brute").query(source)
    farther_m = np.sqrt(brute_d2) - np.sqrt(exact_d2)
    assert int((brute_idx != exact_idx).sum()) == 0, f"{int((brute_idx != exact_idx).sum())} wrong, up to {farther_m.max():.3f} m"
    np.testing.assert_allclose(brute_d2, exact_d2, rtol=0, atol=1e-9)
