"""kiss, genz and pipeline crop each scan to ``[min_range_m, max_range_m]`` around its sensor: a cloud with nothing
in that range is a one-line RegistrationError, in a sequence and pairwise (docs/registration.md, "Conventions")."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lidarkit.errors import RegistrationError
from lidarkit.registration import available_icp, get_icp

KITTI_PAIR = Path(__file__).resolve().parents[1] / "lidarkit" / "samples" / "kitti_pair"
FAR_OFFSET_M = 1000.0


def _far_scans(tmp_path: Path) -> tuple[np.ndarray, np.ndarray]:
    """The bundled KITTI 94/95 pair moved 1000 m off their sensor, written to and read back from ``tmp_path``."""
    clouds = []
    for frame in ("000094", "000095"):
        path = tmp_path / f"{frame}_far.npy"
        np.save(path, np.load(KITTI_PAIR / f"{frame}.npy") + FAR_OFFSET_M)
        clouds.append(np.load(path))
    return clouds[0], clouds[1]


@pytest.mark.parametrize("method", ["kiss", "genz", "pipeline"])
def test_a_sweep_outside_the_range_crop_is_a_one_line_error(method, tmp_path):
    """genz returned the identity for such a sweep (a run of them: "estimated path 0.00 m, bad frames 0 of 4")."""
    if method not in available_icp():
        pytest.skip(f"{method} not installed")
    target, source = _far_scans(tmp_path)
    with pytest.raises(RegistrationError, match=r"no point of the sweep .*max_range_m.*nothing to register") as frame_err:
        get_icp(method).register_frame(target)
    with pytest.raises(RegistrationError, match=r"^source cloud: only 0 points") as pair_err:
        get_icp(method).align(source, target)
    for err in (frame_err, pair_err):
        assert "\n" not in str(err.value)
    if method == "genz":  # the crop and where the cloud lies (genz-icp's own message said neither)
        assert "within [0.3, 100] m of the sensor (min_range_m / max_range_m; the cloud lies 16" in str(frame_err.value)
        assert "within [0.3, 100] m of the sensor" in str(pair_err.value)
        # moved onto the target by init_T, the far source reached genz-icp, but the assessment's source was cropped
        # to nothing ("only 0 correspondences within 3 m" on a pose 1400 m off)
        init_T = np.eye(4)
        init_T[:3, 3] = -FAR_OFFSET_M
        with pytest.raises(RegistrationError, match=r"^source cloud: only 0 points within \[0.3, 100\] m"):
            get_icp(method).align(source, target - FAR_OFFSET_M, init_T=init_T)


@pytest.mark.parametrize("method", ["kiss", "genz", "pipeline"])
def test_a_far_cloud_refused_by_the_range_crop_says_where_it_lies(method, tmp_path):
    """kiss said "only 0 points within [0.0, 100.0] m of the sensor" and pipeline "only 0 points left after preprocessing"
    for a cloud 1000 m off its sensor, neither saying the cloud was far; both now say where it lies and that scans come
    in their sensor frame, as genz. A cloud in its sensor frame that the crop empties gets its distances, no such hint."""
    if method not in available_icp():
        pytest.skip(f"{method} not installed")
    target, source = _far_scans(tmp_path)
    far_hint = "m from the sensor, as a georeferenced or map-frame cloud does: give scans in their sensor frame"
    with pytest.raises(RegistrationError, match=rf"^source cloud: only 0 points .*the cloud lies 1[67]\d\d\.\d-1[78]\d\d\.\d {far_hint}\)$"):
        get_icp(method).align(source, target)
    with pytest.raises(RegistrationError, match=rf"the cloud lies 1[67]\d\d\.\d-1[78]\d\d\.\d {far_hint}\): there is nothing to register$"):
        get_icp(method).register_frame(target)
    near = target - FAR_OFFSET_M
    with pytest.raises(RegistrationError, match=r"^source cloud: only 0 points .*; the cloud lies \d\.\d-\d+\.\d m from the sensor\)$"):
        get_icp(method, max_range_m=1.0, min_range_m=0.5).align(near, near)
