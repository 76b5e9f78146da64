"""Pose covariance along odometry: frames that fell back to their motion guess, the per-frame bias test and the end
position's sigma."""

from __future__ import annotations

import json

import numpy as np
import pytest

from lidarkit.errors import DataError
from lidarkit.geometry import se3_exp, se3_inverse
from lidarkit.odometry.covariance import CHI2_6_95, covariance_metrics, propagate, with_motion_prior
from lidarkit.registration.covariance import adjoint

#: a run where most frames fall back: vanilla turned down below 95 % fitness (15 of 24 frames)
FALLBACK_RUN = "sim:street?frames=25&beams=16&azimuths=360&seed=0"
FALLBACK_PARAMS = {"voxel_size_m": 0.5, "min_fitness": 0.95}


@pytest.fixture(autouse=True)
def wide_console(monkeypatch):
    """Rich tables one row per line, so rows can be matched as printed."""
    monkeypatch.setenv("COLUMNS", "300")


def _curve(n: int) -> np.ndarray:
    step = se3_exp(np.array([1.0, 0.0, 0.0, 0.0, 0.0, 0.02]))
    return np.stack([np.linalg.matrix_power(step, k) for k in range(n)])


def _prior_step(poses: np.ndarray, k: int, sigma_m: float, sigma_rad: float) -> np.ndarray:
    """What a frame known to the prior alone adds to the pose covariance at frame k."""
    Ad = adjoint(poses[k - 1])
    return Ad @ np.diag([sigma_m**2] * 3 + [sigma_rad**2] * 3) @ Ad.T


def test_a_frame_that_fell_back_gets_the_motion_prior_not_its_neighbours_covariance():
    poses = _curve(12)
    rel = np.tile(np.diag([1e-4] * 3 + [1e-6] * 3), (12, 1, 1))
    rel[0] = np.nan
    rel[5:8] = np.nan  # three frames that fell back (the runner leaves them without a covariance)
    cov = propagate(poses, rel)
    for k in (5, 6, 7):
        np.testing.assert_allclose(cov[k] - cov[k - 1], _prior_step(poses, k, 1.0, 0.1), rtol=1e-6, atol=1e-12)
    # said explicitly: the same; and over sweeps apart the sigma grows with them, a rotation's up to an unknown angle's
    fell_back = np.isnan(rel).all(axis=(1, 2))
    fell_back[0] = False
    np.testing.assert_allclose(propagate(poses, rel, fell_back=fell_back), cov)
    sweeps = np.ones(12)
    sweeps[6], sweeps[7] = 3.0, 100.0
    wide = propagate(poses, rel, fell_back=fell_back, sweeps_apart=sweeps)
    np.testing.assert_allclose(wide[6] - wide[5], _prior_step(poses, 6, 3.0, 0.3), rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(wide[7] - wide[6], _prior_step(poses, 7, 100.0, np.pi / np.sqrt(3)), rtol=1e-6, atol=1e-9)
    with pytest.raises(DataError, match="fell_back"):
        propagate(poses, rel, fell_back=fell_back[:-1])
    with pytest.raises(DataError, match="sweeps_apart"):
        propagate(poses, rel, sweeps_apart=np.zeros(12))


def test_a_run_with_fallbacks_has_an_end_covariance_that_covers_its_error(tmp_path, capsys):
    """15 of 24 frames fall back: each took the previous frame's covariance (end 1-sigma 1.1 m for a 7.8 m error, end
    NEES 87); with the motion prior the end error is inside the 95 % bound, and the 1-frame NEES says it left the 15
    frames out; the bias row names its threshold."""
    from lidarkit.cli import main

    args = ["odometry", FALLBACK_RUN, "-m", "vanilla", "--pose-covariance", "--no-progress", "--out", str(tmp_path / "run")]
    for key, value in FALLBACK_PARAMS.items():
        args += ["-p", f"{key}={value}"]
    try:
        main(args)
    except SystemExit as done:
        assert not done.code
    out = capsys.readouterr().out
    metrics = json.loads((tmp_path / "run" / "metrics.json").read_text())
    cov = metrics["pose_covariance"]
    assert metrics["n_constant_velocity_fallback"] == 15
    assert cov["end_error_m"] > 5.0 and cov["final_position_sigma_m"] > 5.0
    assert cov["end_nees"] < CHI2_6_95
    assert cov["relative_nees_frames_left_out"] == 15 and cov["frames_with_covariance"] == 9
    assert "15 frames left out (no registration covariance)" in out
    assert f"z = {cov['per_frame_bias_z']:.1f} (a bias above {cov['per_frame_bias_z_threshold']:.1f}): rebuilds" in out


def test_the_per_frame_bias_test_calls_white_noise_a_bias_in_one_run_in_a_hundred_whatever_the_frames():
    """z = |mean| / (std / sqrt(n)) against the normal 3 flagged white noise in 16 % of runs of 4 errors and 5 % of 9:
    the Student-t threshold keeps it at ~1 % (the docstring's), and a real bias is still flagged."""
    from lidarkit.odometry.covariance import BIAS_FALSE_ALARM, per_frame_bias

    rng = np.random.default_rng(26)
    for n, trials in ((4, 40000), (9, 40000), (100, 20000)):
        z, threshold = per_frame_bias(rng.normal(0.0, 0.02, (trials, n, 3)))
        rate = float((z > threshold).mean())
        assert 0.75 * BIAS_FALSE_ALARM < rate < 1.25 * BIAS_FALSE_ALARM, (n, rate, threshold)
    for n, bias_sigmas in ((9, 2.0), (100, 0.5)):  # a bias on one axis
        errors = rng.normal(0.0, 1.0, (2000, n, 3))
        errors[..., 1] += bias_sigmas
        z, threshold = per_frame_bias(errors)
        assert (z > threshold).mean() > 0.85, (n, bias_sigmas)
    with pytest.raises(DataError, match="per_frame_bias"):
        per_frame_bias(np.zeros((1, 3)))


def test_covariance_metrics_flag_no_bias_in_white_noise_over_few_frames():
    """Runs of 5 poses (4 frame errors) of white noise through covariance_metrics: z above the reported threshold (3
    when none is reported) in ~1 % of them, not 16 %."""
    rng = np.random.default_rng(5)
    n = 5
    ref = np.tile(np.eye(4), (n, 1, 1))
    ref[:, 0, 3] = np.arange(n)
    cov = np.tile(np.diag([4e-4] * 3 + [1e-8] * 3), (n, 1, 1))
    cov[0] = 0.0
    trials, flagged = 400, 0
    for _ in range(trials):
        est = [np.eye(4)]
        for k in range(1, n):
            est.append(est[-1] @ np.linalg.solve(ref[k - 1], ref[k]) @ se3_exp(np.r_[rng.normal(0.0, 0.02, 3), rng.normal(0.0, 1e-4, 3)]))
        m = covariance_metrics(np.stack(est), cov, np.cumsum(cov, axis=0), ref)
        flagged += m["per_frame_bias_z"] > m.get("per_frame_bias_z_threshold", 3.0)
    assert flagged / trials < 0.03, flagged


def test_a_fallback_across_a_gap_of_dropped_scans_gets_the_prior_of_every_sweep_it_spans():
    """KITTI files 94, 95, 198, 199: the frame across the 103-sweep gap falls back to the constant-velocity guess. Its
    prior spans the 103 sweeps (the runner passes them to propagate): the end 1-sigma covers the error, where one sweep's
    prior gave 1.7 m for a 56 m error."""
    from conftest import shared_path

    from lidarkit.odometry import run

    kitti = shared_path("kitti_odometry")
    result = run(f"kitti:{kitti / 'sequences' / '00'}?velodyne_dir={kitti / 'extra_frames' / '00' / 'velodyne'}", "small_gicp",
                 pose_covariance=True)
    assert result.metrics["n_constant_velocity_fallback"] == 1
    covariance = result.metrics["pose_covariance"]
    assert covariance["final_position_sigma_m"] > covariance["end_error_m"] > 10.0  # 204 m (the end position's) for 56 m
    assert covariance["relative_nees_frames_left_out"] == 1


def _accumulated(poses: np.ndarray, relative_covariances: np.ndarray) -> np.ndarray:
    """World-frame pose covariances of the first-order sum, without the motion prior that propagate fuses in."""
    steps = [adjoint(poses[k - 1]) @ relative_covariances[k] @ adjoint(poses[k - 1]).T for k in range(1, len(poses))]
    return np.cumsum([np.zeros((6, 6)), *steps], axis=0)


def test_the_end_position_sigma_counts_the_lever_arm_of_a_heading_uncertainty():
    """Eleven poses 10 m apart on a line, the first motion alone uncertain, by 1 deg of yaw: the end is 100 m x 1 deg
    = 1.745 m sideways at 1-sigma. The twist's translation block, read as the position's before, said 0 m."""
    from lidarkit.odometry import covariance as odometry_covariance

    poses = np.tile(np.eye(4), (11, 1, 1))
    poses[:, 0, 3] = 10.0 * np.arange(11)
    rel = np.zeros((11, 6, 6))
    rel[1, 5, 5] = np.radians(1.0) ** 2
    metrics = covariance_metrics(poses, rel, _accumulated(poses, rel), None)
    assert metrics["final_position_sigma_m"] == pytest.approx(100.0 * np.radians(1.0), abs=1e-3)
    assert metrics["final_heading_sigma_deg"] == pytest.approx(1.0)
    expected = np.diag([0.0, (100.0 * np.radians(1.0)) ** 2, 0.0])
    end_covariance = _accumulated(poses, rel)[-1]
    np.testing.assert_allclose(odometry_covariance.position_covariance(poses[-1], end_covariance), expected, atol=1e-12)
    with pytest.raises(DataError, match="position_covariance"):
        odometry_covariance.position_covariance(poses, rel[:3])


def test_the_end_position_sigma_matches_monte_carlo_draws_of_the_frame_motions_on_a_turning_path():
    """30 frames turning in yaw and pitch from a pose 45 m from the world origin, each motion drawn 10000 times from
    its covariance (as propagate fuses it with the motion prior): the end positions' spread is the reported sigma and
    position_covariance (the twist's translation block said 1.83 m for 0.59 m)."""
    from lidarkit.odometry import covariance as odometry_covariance
    from lidarkit.registration.components.motion import se3_exp_batch

    rng = np.random.default_rng(27)
    n, draws = 30, 10000
    start = se3_exp(np.array([40.0, -20.0, 1.0, 0.0, 0.0, 0.5]))
    step = se3_exp(np.array([1.0, 0.0, 0.02, 0.0, 0.01, 0.06]))
    poses = np.stack([start @ np.linalg.matrix_power(step, k) for k in range(n)])
    scale = np.diag([0.01] * 3 + [0.005] * 3)
    mix = rng.normal(size=(n, 6, 6))
    rel = scale @ (mix @ np.swapaxes(mix, 1, 2) / 6.0) @ scale  # correlated, translation and rotation alike
    rel[0] = np.nan
    pose_covariances = propagate(poses, rel)
    R, t = np.tile(start[:3, :3], (draws, 1, 1)), np.tile(start[:3, 3], (draws, 1))
    for k in range(1, n):  # T_k = T_{k-1} @ se3_exp(xi) @ T_rel, xi drawn as the registry's convention has it
        dR, dt = se3_exp_batch(rng.multivariate_normal(np.zeros(6), with_motion_prior(rel[k]), draws))
        T_rel = se3_inverse(poses[k - 1]) @ poses[k]
        t = t + np.einsum("nij,nj->ni", R, dt + dR @ T_rel[:3, 3])
        R = R @ dR @ T_rel[:3, :3]
    drawn = np.cov(t.T)
    reported = covariance_metrics(poses, rel, pose_covariances, None)["final_position_sigma_m"]
    assert reported == pytest.approx(np.sqrt(np.trace(drawn)), rel=0.03)
    np.testing.assert_allclose(odometry_covariance.position_covariance(poses[-1], pose_covariances[-1]), drawn, atol=0.01)


def _kitti_folder_with_dropped_scans(root):
    """A KITTI-layout folder of seq 00's scans 0-9, 94, 95, 198 and 199 (two gaps of dropped scans), its own stamps and
    SemanticKITTI poses, by symlinks to the shared data."""
    from conftest import shared_path

    kitti = shared_path("kitti_odometry")
    sequence = kitti / "sequences" / "00"
    velodyne = root / "velodyne"
    velodyne.mkdir(parents=True)
    for n in (*range(10), 94, 95, 198, 199):
        folder = sequence / "velodyne" if n < 10 else kitti / "extra_frames" / "00" / "velodyne"
        (velodyne / f"{n:06d}.bin").symlink_to(folder / f"{n:06d}.bin")
    for name in ("calib.txt", "times.txt", "poses_semantickitti.txt"):
        (root / name).symlink_to(sequence / name)
    return root


def test_a_stateful_frame_that_fails_the_check_across_a_gap_gets_the_motion_prior_of_its_sweeps(tmp_path):
    """kiss over KITTI scans 0-9, 94, 95, 198, 199: frames 10 and 12 (files 94 and 198), 85 and 103 sweeps after the
    previous scan, fail the run's own fitness check (0.008, 0.010) yet propagated their one-sweep-sized after-the-fact
    covariance (end 1-sigma 0.596 m for a 40.19 m end error, end NEES 57,567; over frames 8-13, as here, 0.72 m for
    36.3 m, end NEES 72,568). They take the motion prior over their sweeps, as small_gicp's fallbacks there do, and
    metrics.json names them."""
    from lidarkit.odometry import run
    from lidarkit.odometry.covariance import UNKNOWN_ROTATION_SIGMA

    folder = _kitti_folder_with_dropped_scans(tmp_path / "kg")
    result = run(f"kitti:{folder}?poses_file=poses_semantickitti.txt", "kiss", pose_covariance=True, frames="8:14")
    covariance = result.metrics["pose_covariance"]
    assert result.metrics["frame_check"]["bad_frames"] == [10, 12]
    assert covariance["end_nees"] < CHI2_6_95
    assert covariance["final_position_sigma_m"] > result.metrics["final_error"]["translation_m"] > 30.0
    assert covariance["motion_prior_only"] == {"n_frames": 2, "frames": [10, 12], "n_frames_not_listed": 0,
                                               "by_reason": {"fell back": 0, "failed the fitness check": 2, "across a gap": 2}}
    poses, pose_covariance = result.trajectory.poses_se3, result.pose_covariance
    stamps = np.loadtxt(folder / "times.txt")[[*range(10), 94, 95, 198, 199]]
    for k, frame in ((2, 10), (4, 12)):  # (85 and 103 sweeps of the folder's median interval)
        sweeps = (stamps[frame] - stamps[frame - 1]) / np.median(np.diff(stamps))
        np.testing.assert_allclose(pose_covariance[k] - pose_covariance[k - 1],
                                   _prior_step(poses, k, sweeps, min(0.1 * sweeps, UNKNOWN_ROTATION_SIGMA)), rtol=1e-6, atol=1e-6)


def test_frames_across_a_gap_are_those_beyond_four_times_the_runs_regular_step_of_sweeps():
    """The gap rule is relative to the run's step (a stepped selection is no gap) and leaves a sweep or two dropped to
    the frame check; a frame that failed the check takes the prior in propagate, whatever its covariance."""
    from lidarkit.odometry.covariance import GAP_SWEEPS_RATIO, motion_prior_frames, motion_prior_summary

    assert GAP_SWEEPS_RATIO == 4.0
    no_flags = np.zeros(6, dtype=bool)
    across = motion_prior_frames(no_flags, None, np.array([1.0, 1.0, 2.0, 4.0, 5.0, 1.0]))["across a gap"]
    assert across.tolist() == [False, False, False, False, True, False]
    stepped = motion_prior_frames(no_flags, None, np.array([1.0, 5.0, 5.0, 20.0, 21.0, 5.0]))["across a gap"]
    assert stepped.tolist() == [False, False, False, False, True, False]
    failed = np.array([True, False, True, False, False, False])  # (frame 0 is the start: never a prior's)
    reasons = motion_prior_frames(np.array([False, False, False, True, False, False]), failed, np.ones(6))
    assert motion_prior_summary(np.arange(100, 106), reasons) == {
        "n_frames": 2, "frames": [102, 103], "n_frames_not_listed": 0,
        "by_reason": {"fell back": 1, "failed the fitness check": 1, "across a gap": 0}}
    poses = _curve(6)
    rel = np.tile(np.diag([1e-4] * 3 + [1e-6] * 3), (6, 1, 1))
    cov = propagate(poses, rel, fell_back=np.logical_or.reduce(list(reasons.values())))
    np.testing.assert_allclose(cov[2] - cov[1], _prior_step(poses, 2, 1.0, 0.1), rtol=1e-6, atol=1e-12)
    with pytest.raises(DataError, match="failed_fitness"):
        motion_prior_frames(no_flags, failed[:-1], np.ones(6))


def test_the_cli_table_lists_the_frames_with_the_motion_prior_alone(tmp_path, capsys):
    """metrics.json named them; the terminal table did not, though they set the run's end 1-sigma."""
    from conftest import cli_exit_code

    folder = _kitti_folder_with_dropped_scans(tmp_path / "kg")
    assert cli_exit_code(["odometry", f"kitti:{folder}?poses_file=poses_semantickitti.txt", "--method", "kiss",
                          "--pose-covariance", "--frames", "8:14", "--no-progress"]) == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "frames with the motion prior alone" in out
    assert "2 (2 failed the fitness check, 2 across a gap): dataset indices 10, 12" in out
