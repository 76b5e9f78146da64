"""The preprocessing functions that take their settings as arguments check them as the ground segmenters' configs do:
a setting out of range used to mark no ground, or crop the whole cloud, without a word."""

from __future__ import annotations

from importlib.resources import files

import numpy as np
import pytest

from lidarkit.errors import ConfigError, DataError
from lidarkit.registration.ground import get_ground_segmenter
from lidarkit.registration.preprocess import crop_range, ground_mask_by_height, ground_mask_by_plane, range_mask


@pytest.fixture(scope="module")
def kitti_scan(tmp_path_factory) -> np.ndarray:
    """The bundled KITTI scan 94, as a caller loads it from a file of its own."""
    path = tmp_path_factory.mktemp("scan") / "000094.npy"
    path.write_bytes(files("lidarkit.samples").joinpath("kitti_pair", "000094.npy").read_bytes())
    return np.load(path)


@pytest.mark.parametrize("segmenter, settings", [
    ("ransac", {"num_iterations": 0}),
    ("ransac", {"distance_threshold_m": -1.0}),
    ("ransac", {"max_tilt_deg": -5.0}),
    ("height", {"ground_threshold_m": float("nan")}),
    ("height", {"sensor_height_m": -1.0}),
])
def test_mask_functions_refuse_what_the_segmenters_refuse_in_the_same_words(kitti_scan, segmenter, settings):
    mask_function = {"ransac": ground_mask_by_plane, "height": ground_mask_by_height}[segmenter]
    with pytest.raises(ConfigError) as by_segmenter:
        get_ground_segmenter(segmenter, **settings)
    with pytest.raises(ConfigError) as by_function:
        mask_function(kitti_scan, **settings)  # (marked 0 ground points)
    assert str(by_function.value) == str(by_segmenter.value)
    assert str(by_function.value).startswith(f"ground segmenter {segmenter!r}: invalid parameters ({next(iter(settings))}: ")


def test_mask_functions_mark_the_segmenters_ground_and_refuse_a_2d_cloud(kitti_scan):
    plane = ground_mask_by_plane(kitti_scan)
    assert int(plane.sum()) == 19724 and len(plane) == 54478
    assert np.array_equal(plane, get_ground_segmenter("ransac").segment(kitti_scan))
    assert np.array_equal(ground_mask_by_height(kitti_scan), kitti_scan[:, 2] < -1.0)
    for mask_function in (ground_mask_by_plane, ground_mask_by_height):  # (a raw IndexError)
        with pytest.raises(DataError, match=r"^points: expected an \(N, 3\) point array, got shape \(54478, 2\)$"):
            mask_function(kitti_scan[:, :2])


@pytest.mark.parametrize("bounds", [(float("nan"), 50.0), (0.0, float("nan")), (float("inf"), float("inf")), ("1", 50.0)])
def test_range_crop_refuses_a_bound_that_is_no_number(kitti_scan, bounds):
    for crop in (crop_range, range_mask):  # (NaN compared False: an empty cloud)
        with pytest.raises(ConfigError, match=r"^range crop: need 0 <= min_range_m < max_range_m \(a finite minimum\), got "):
            crop(kitti_scan, *bounds)


def test_range_crop_keeps_the_points_in_range_and_refuses_a_2d_cloud(kitti_scan):
    kept = crop_range(kitti_scan, 5.0, 50.0)
    distance = np.linalg.norm(kitti_scan.astype(np.float64), axis=1)
    assert len(kept) == int(((distance >= 5.0) & (distance <= 50.0)).sum()) and len(kept) < len(kitti_scan)
    assert np.array_equal(range_mask(kitti_scan, 0.0, np.inf), np.ones(len(kitti_scan), dtype=bool))
    with pytest.raises(DataError, match=r"expected an \(N, 3\) point array, got shape \(54478, 2\)"):  # (cropped in 2D)
        crop_range(kitti_scan[:, :2], 0.0, 5.0)
