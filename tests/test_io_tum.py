"""TumRGBD on a tiny synthetic sequence: generated PNGs + rgb.txt, ground truth rows of the real fr1/xyz file."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import shared_path

from lidarkit.errors import ConfigError, DataError
from lidarkit.io import open_dataset
from lidarkit.io.base import ImageSequence
from lidarkit.io.tum import TumRGBD, associate_nearest, tum_intrinsics_for
from lidarkit.trajectory import Trajectory

N_GT_ROWS = 60
# (GT row, offset s): +0.004 stays with the row, +0.007 is nearer the next row (GT runs at ~100 Hz)
RGB_FRAMES = [(3, 0.004), (10, -0.003), (20, 0.007), (30, 0.0)]
UNMATCHED_OFFSET_S = 0.5  # one frame 0.5 s after the last GT row: no GT within 0.02 s


@pytest.fixture
def tum_folder(tmp_path):
    """``rgbd_dataset_freiburg1_xyz`` with 5 rgb frames (the last without GT) and 60 real GT rows."""
    import cv2

    gt_src = shared_path("evo_testdata", "freiburg1_xyz-groundtruth.txt")
    lines = gt_src.read_text().splitlines()
    header = [line for line in lines if line.startswith("#")]
    rows = [line for line in lines if line and not line.startswith("#")][:N_GT_ROWS]
    folder = tmp_path / "rgbd_dataset_freiburg1_xyz"
    (folder / "rgb").mkdir(parents=True)
    (folder / "groundtruth.txt").write_text("\n".join(header + rows) + "\n")
    gt_stamps = np.array([float(r.split()[0]) for r in rows])
    stamps = [gt_stamps[row] + dt for row, dt in RGB_FRAMES] + [gt_stamps[-1] + UNMATCHED_OFFSET_S]
    listing = ["# color images", "# file: 'rgbd_dataset_freiburg1_xyz.bag'", "# timestamp filename"]
    for i, stamp in enumerate(stamps):
        name = f"rgb/{stamp:.6f}.png"
        image = np.zeros((48, 64, 3), np.uint8)
        image[..., 1] = 40 * (i + 1)  # green channel only: gray = 0.587 * value
        assert cv2.imwrite(str(folder / name), image)
        listing.append(f"{stamp:.6f} {name}")
    (folder / "rgb.txt").write_text("\n".join(listing) + "\n")
    return folder


def test_association_and_drop_policy(tum_folder):
    ds = open_dataset("tum", tum_folder)
    assert isinstance(ds, ImageSequence)
    assert len(ds) == 4  # the frame without GT is dropped by default
    gt_all = Trajectory.from_tum(tum_folder / "groundtruth.txt")
    expected_rows = [3, 10, 21, 30]
    np.testing.assert_allclose(ds.ground_truth.poses_se3, gt_all.poses_se3[expected_rows])
    np.testing.assert_allclose(ds.ground_truth.timestamps_s, ds.timestamps_s)
    np.testing.assert_allclose(ds.timestamps_s - gt_all.timestamps_s[[3, 10, 20, 30]], [0.004, -0.003, 0.007, 0.0], atol=2e-6)
    image = ds.read_image(2)
    assert image.dtype == np.uint8 and image.shape == (48, 64)
    assert image.mean() == pytest.approx(0.587 * 120, abs=1.0)


def test_a_frame_dropped_inside_the_sequence_is_warned_about(tum_folder, caplog):
    """A gap in the ground truth dropped the frames inside it at INFO level (hidden by the CLI): the images jumped
    over them unseen. Frames after the ground truth's end stay an INFO line."""
    import logging

    with caplog.at_level(logging.INFO, logger="lidarkit.io.tum"):
        assert len(TumRGBD(tum_folder)) == 4
    assert not [r for r in caplog.records if r.levelno >= logging.WARNING]
    gt = tum_folder / "groundtruth.txt"
    lines = gt.read_text().splitlines()
    header = sum(line.startswith("#") for line in lines)
    gt.write_text("\n".join(lines[: header + 15] + lines[header + 26 :]) + "\n")  # rows 15-25 gone: frame 2 has none
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="lidarkit.io.tum"):
        ds = TumRGBD(tum_folder)
    assert len(ds) == 3
    warned = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warned) == 1 and "1 rgb frame(s) inside the sequence have no ground-truth pose" in warned[0], warned


def test_keep_and_error_policies(tum_folder):
    kept = TumRGBD(tum_folder, unmatched="keep")
    assert len(kept) == 5 and kept.ground_truth is None
    assert kept.has_ground_truth.tolist() == [True, True, True, True, False]
    with pytest.raises(DataError, match=r"rgb\.txt \(frame 4\): rgb frame at .* no ground-truth pose within 0\.02 s \(nearest 0\.500 s away\)"):
        TumRGBD(tum_folder, unmatched="error")
    wide = TumRGBD(tum_folder, max_dt_s=0.6)
    assert len(wide) == 5 and len(wide.ground_truth) == 5
    with pytest.raises(ConfigError, match="unknown unmatched policy"):
        TumRGBD(tum_folder, unmatched="ignore")


def test_intrinsics_from_folder_name_or_option(tum_folder, tmp_path):
    np.testing.assert_allclose(TumRGBD(tum_folder).K, [[517.3, 0, 318.6], [0, 516.5, 255.3], [0, 0, 1]])
    assert tum_intrinsics_for(tmp_path / "rgbd_dataset_freiburg2_desk")[0, 0] == 520.9
    assert tum_intrinsics_for(tmp_path / "fr3_office")[1, 1] == 539.2
    assert tum_intrinsics_for(tmp_path / "my_room") is None
    K = np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]])
    np.testing.assert_array_equal(TumRGBD(tum_folder, K=K).K, K)


def test_the_built_in_fr1_fr2_intrinsics_say_once_that_distortion_is_not_corrected(tum_folder, caplog):
    """The freiburg1/2 default K was used without a word, though those colour images are distorted (k1 0.26 / 0.23)
    and lidarkit does not undistort them. Said once, at the first use of K; not for a given K nor for freiburg3."""
    import logging
    import shutil

    ds = TumRGBD(tum_folder)
    with caplog.at_level(logging.WARNING, logger="lidarkit.io.tum"):
        assert ds.K[0, 0] == ds.K[0, 0] == 517.3
    assert [r.getMessage() for r in caplog.records] == [
        f"{tum_folder}: the built-in freiburg1 intrinsics have no lens distortion model: its colour images are distorted "
        "(k1 = 0.26) and are used uncorrected (undistort them, and give their K, for exact geometry)"]
    caplog.clear()
    fr3 = shutil.copytree(tum_folder, tum_folder.parent / "rgbd_dataset_freiburg3_office")
    with caplog.at_level(logging.WARNING, logger="lidarkit.io.tum"):
        assert TumRGBD(tum_folder, K=np.eye(3)).K[0, 0] == 1.0 and TumRGBD(fr3).K[0, 0] == 535.4
    assert not caplog.records


def test_associate_nearest_edges():
    ref = np.array([0.0, 0.01, 0.02, 0.03])
    np.testing.assert_array_equal(associate_nearest(np.array([-0.5, -0.001, 0.014, 0.016, 0.031, 0.06]), ref, 0.02), [-1, 0, 1, 2, 3, -1])


def test_malformed_rgb_list(tum_folder):
    listing = tum_folder / "rgb.txt"
    lines = listing.read_text().splitlines()
    lines[4] = lines[4] + " extra"
    listing.write_text("\n".join(lines) + "\n")
    with pytest.raises(DataError, match=r"rgb\.txt \(line 5\): expected 'timestamp filename', found 3 fields"):
        TumRGBD(tum_folder)
    lines[4] = "12x rgb/a.png"
    listing.write_text("\n".join(lines) + "\n")
    with pytest.raises(DataError, match=r"rgb\.txt \(line 5\): time stamp is not a number: '12x'"):
        TumRGBD(tum_folder)
    lines[4], lines[5] = lines[5], lines[4].replace("12x", "1305031098.7")
    listing.write_text("\n".join(lines) + "\n")
    with pytest.raises(DataError, match=r"rgb\.txt \(line 6\): time stamp .* is not after the previous"):
        TumRGBD(tum_folder)


def test_malformed_groundtruth(tum_folder):
    gt = tum_folder / "groundtruth.txt"
    lines = gt.read_text().splitlines()
    lines[10] = " ".join(lines[10].split()[:7])
    gt.write_text("\n".join(lines) + "\n")
    with pytest.raises(DataError, match=r"groundtruth\.txt \(line 11\): expected 8 numbers, found 7"):
        TumRGBD(tum_folder)


def test_missing_files(tum_folder, tmp_path):
    (tum_folder / sorted((tum_folder / "rgb").iterdir())[1].relative_to(tum_folder)).unlink()
    ds = TumRGBD(tum_folder)
    with pytest.raises(DataError, match=r"\.png \(frame 1\): image file not found"):
        ds.read_image(1)
    (tum_folder / "groundtruth.txt").unlink()
    no_gt = TumRGBD(tum_folder)
    assert len(no_gt) == 5 and no_gt.ground_truth is None
    with pytest.raises(DataError, match=r"other_gt\.txt: ground-truth file not found"):
        TumRGBD(tum_folder, groundtruth="other_gt.txt")
    (tum_folder / "rgb.txt").unlink()
    with pytest.raises(DataError, match=r"rgb\.txt: file not found"):
        TumRGBD(tum_folder)
    with pytest.raises(DataError, match="TUM sequence folder not found"):
        TumRGBD(tmp_path / "nope")


def test_a_bool_given_as_the_number_option_max_dt_s_is_refused(tum_folder):
    """``open_dataset``'s option typing (pydantic's lax float) read ``max_dt_s=True`` as a 1 s tolerance: frames 0.5 s
    from any GT row were matched; every reader's int / float option now refuses a bool, naming the option."""
    with pytest.raises(ConfigError) as err:
        open_dataset("tum", tum_folder, max_dt_s=True)
    assert str(err.value) == "tum dataset option max_dt_s: must be a number, not a bool, got True"
    assert len(open_dataset("tum", tum_folder, max_dt_s=1)) == len(RGB_FRAMES) + 1  # the number 1 still reads as 1 s
