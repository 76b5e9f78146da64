"""Acceptance on real KITTI images (51 frames of sequences 06 and 01, ../shared/data/kitti_images)."""

from __future__ import annotations

import numpy as np
import pytest

from lidarkit.vo import MonoVO, preset
from lidarkit.vo.evaluation import evaluate_vo


@pytest.mark.slow
def test_seq06_gt_scale_beats_sift_reference(seq06, kitti_vo_run):
    """Report 1 (SIFT + BF, RANSAC, gt scale) measured APE 0.046 m (SE3) here; acceptance: <= 0.03 m."""
    gt = seq06[2]
    # (the run with its tracks: tests/test_vo_consistency.py checks them, one run for both)
    result = kitti_vo_run("06", "lidarkit", keep_tracks=True, **{"scale.mode": "gt"})
    assert not result.rejected
    m = evaluate_vo(result.trajectory, gt, "gt")
    assert m["align"] == "se3"
    assert m["ape_rmse_m"] <= 0.03
    # after the SE(3) alignment used for APE the last pose is within a few cm; unaligned it is 0.56 m: the GT's
    # rotation over frames 0-11 is a constant-rate fill the images contradict (docs/visual_odometry.md, checked in
    # tests/test_vo_consistency.py, where the run from frame 11 meets the 0.25 m target)
    assert m["final_error_aligned_m"] <= 0.05
    assert m["final_error_raw_m"] <= 0.6


@pytest.mark.slow
def test_seq06_akaze_descriptor_pipeline(seq06):
    """AKAZE (opencv-contrib's xfeatures2d in OpenCV 5) + ratio test, gt scale: measured APE 0.017 m, 0.014 m aligned
    final error; it must stay within the same acceptance bounds as the default pipeline."""
    images, K, gt = seq06
    cfg = preset("lidarkit", **{"scale.mode": "gt", "features.detector": "akaze", "features.max_features": 3000,
                                "features.grid_rows": 1, "features.grid_cols": 1, "matching.method": "knn_ratio",
                                "geometry.estimators": ("magsac", "ransac")})
    result = MonoVO(cfg, K, gt).run(images)
    assert not result.rejected
    assert min(d.n_inliers for d in result.diagnostics[1:]) >= 100
    m = evaluate_vo(result.trajectory, gt, "gt")
    assert m["ape_rmse_m"] <= 0.03
    assert m["final_error_aligned_m"] <= 0.05


@pytest.mark.slow
def test_seq01_relative_scale_follows_the_speed_up(seq01, kitti_vo_run):
    """Unit steps give Sim(3) APE 0.92 m on 01 (the car speeds up 0.95 -> 1.27 m/frame); acceptance: <= 0.3 m."""
    gt = seq01[2]
    result = kitti_vo_run("01", "lidarkit", **{"scale.mode": "relative"})  # (tests/test_vo_scale.py's default run)
    assert not result.rejected
    m = evaluate_vo(result.trajectory, gt, "relative")
    assert m["ape_rmse_m"] <= 0.3
    steps = np.linalg.norm(np.diff(result.trajectory.positions_xyz, axis=0), axis=1) * m["alignment_scale"]
    true_steps = np.linalg.norm(np.diff(gt.positions_xyz, axis=0), axis=1)
    # the estimated speed-up follows the true one (first vs last 10 steps)
    est_ratio = steps[-10:].mean() / steps[:10].mean()
    true_ratio = true_steps[-10:].mean() / true_steps[:10].mean()
    assert true_ratio > 1.15 and abs(est_ratio - true_ratio) < 0.1


def test_an_unknown_scale_mode_is_refused_not_scored_with_sim3():
    """evaluate_vo(est, gt, "GT") aligned by Sim(3): a trajectory twice too long scored an APE of 0."""
    from lidarkit.errors import ConfigError
    from lidarkit.trajectory import Trajectory

    poses = np.tile(np.eye(4), (6, 1, 1))
    poses[:, 0, 3] = np.arange(6.0)
    poses[:, 1, 3] = np.arange(6.0) ** 2 / 5  # a curve: Umeyama's rotation is defined
    doubled = poses.copy()
    doubled[:, :3, 3] *= 2
    gt, est = Trajectory(poses, name="gt"), Trajectory(doubled, name="vo")
    assert evaluate_vo(est, gt, "gt")["ape_rmse_m"] > 1.0
    assert evaluate_vo(est, gt, "relative")["ape_rmse_m"] < 1e-9
    for mode in ("GT", "ground_truth", ""):
        with pytest.raises(ConfigError, match=f"scale_mode: unknown scale mode '{mode}'; known: gt, none, relative"):
            evaluate_vo(est, gt, mode)
        with pytest.raises(ConfigError, match="unknown scale mode"):
            evaluate_vo(est, gt, mode, align="se3")


def test_trajectories_of_other_lengths_are_associated_as_the_error_advises():
    """evaluate_vo(est, gt, "gt") with one pose fewer advised "pass associate=True", which evaluate_vo did not take
    (a TypeError); it now pairs the poses by time stamp as ape()/rpe() do."""
    from lidarkit.errors import EvaluationError
    from lidarkit.trajectory import Trajectory

    poses = np.tile(np.eye(4), (6, 1, 1))
    poses[:, 0, 3] = np.arange(6.0)
    poses[:, 1, 3] = np.arange(6.0) ** 2 / 5
    gt = Trajectory(poses, np.arange(6.0), name="gt")
    shifted = poses[1:].copy()
    shifted[:, 2, 3] = 0.5  # 0.5 m off, every pose
    est = Trajectory(shifted, np.arange(1.0, 6.0), name="vo")
    with pytest.raises(EvaluationError, match=r"vo vs gt: trajectories differ in length \(6 reference vs 5 estimated "
                                              r"poses\); both have timestamps: pass associate=True"):
        evaluate_vo(est, gt, "gt")
    m = evaluate_vo(est, gt, "gt", align="none", associate=True)
    assert m["ape_rmse_m"] == pytest.approx(0.5) and m["final_error_m"] == pytest.approx(0.5)
    assert m["rpe_trans_rmse_m"] == pytest.approx(0.0, abs=1e-12)
    assert evaluate_vo(est, gt, "relative", associate=True)["ape_rmse_m"] == pytest.approx(0.0, abs=1e-9)


def test_an_excerpt_whose_pose_and_time_files_both_cover_its_frames_is_read(tmp_path):
    """Frames 10-30 of the 06 excerpt beside its poses.txt (51 rows) and the full times.txt (1101) were refused: "51
    poses ... but 1101 time stamps (and the shorter file does not end at the last frame present, 30)". Both cover the
    frames present, so each frame takes its own row; a file that stops short is still named with the frame it misses."""
    import shutil

    from conftest import shared_path

    from lidarkit.errors import DataError
    from lidarkit.vo.inputs import open_vo_input

    source = shared_path("kitti_images", "sequences", "06")
    seq = tmp_path / "06"
    (seq / "image_0").mkdir(parents=True)
    for frame in range(10, 31):
        shutil.copy(source / "image_0" / f"{frame:06d}.png", seq / "image_0")
    for name in ("calib.txt", "poses.txt", "times.txt"):
        shutil.copy(source / name, seq / name)
    vo_input = open_vo_input(seq)
    images = vo_input.images
    assert len(images) == 21
    times = np.loadtxt(source / "times.txt")
    np.testing.assert_array_equal(images.timestamps_s, times[10:31])
    poses = np.loadtxt(source / "poses.txt")
    np.testing.assert_allclose(vo_input.ground_truth.poses_se3[:, :3, :].reshape(-1, 12), poses[10:31], atol=1e-12)
    rows = (source / "poses.txt").read_text().splitlines()
    (seq / "poses.txt").write_text("\n".join(rows[:25]) + "\n")
    with pytest.raises(DataError, match=r"poses\.txt: 25 poses but image 000030\.png is frame 30$"):
        open_vo_input(seq)
