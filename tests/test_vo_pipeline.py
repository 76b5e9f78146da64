"""MonoVO end to end on synthetic renders: exact ground truth, every bad-input case, determinism."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from lidarkit.errors import ConfigError, DataError
from lidarkit.eval import ape
from lidarkit.geometry import make_se3, so3_exp
from lidarkit.sim.camera import default_K, forward_trajectory, make_plane_scene, render_sequence
from lidarkit.trajectory import Trajectory
from lidarkit.vo import MonoVO, VOConfig, preset


@pytest.fixture(scope="module")
def scene():
    return make_plane_scene(np.random.default_rng(11))


@pytest.fixture(scope="module")
def sim(scene):
    traj = forward_trajectory(7)
    K = default_K()
    return traj, K, render_sequence(scene, traj, K)


def _cfg(mode="gt", **changes):
    return VOConfig().updated(**{"scale.mode": mode, **changes})


def _finite(result):
    return np.all(np.isfinite(result.trajectory.poses_se3))


@pytest.mark.parametrize("mode,align,tol_m", [("gt", "se3", 0.01), ("relative", "sim3", 0.01), ("none", "sim3", 0.01)])
def test_pipeline_recovers_synthetic_trajectory(sim, mode, align, tol_m):
    traj, K, images = sim
    result = MonoVO(_cfg(mode), K, traj if mode == "gt" else None).run(images)
    assert len(result.trajectory) == len(images) and not result.rejected
    assert ape(traj, result.trajectory, align=align).rmse < tol_m
    if mode == "relative":  # one global scale: the steps keep the true ratios (constant speed here)
        steps = np.linalg.norm(np.diff(result.trajectory.positions_xyz, axis=0), axis=1)
        true = np.linalg.norm(np.diff(traj.positions_xyz, axis=0), axis=1)
        ratio = steps / true
        assert ratio.std() / ratio.mean() < 0.02


def test_gt_mode_needs_ground_truth_and_K(sim):
    traj, K, images = sim
    with pytest.raises(ConfigError, match="needs a ground-truth"):
        MonoVO(_cfg("gt"), K)
    with pytest.raises(ConfigError, match="intrinsics K are required"):
        MonoVO(_cfg("none"), None)
    with pytest.raises(DataError, match="ground truth has 3 poses"):
        MonoVO(_cfg("gt"), K, traj[:3]).run(images)


class _Failing:
    """ImageSequence stand-in whose frames in ``bad`` raise DataError like an unreadable file."""

    name = "failing"

    def __init__(self, images, bad):
        self.images, self.bad = images, set(bad)

    def __len__(self):
        return len(self.images)

    def read_image(self, i):
        if i in self.bad:
            raise DataError("cannot decode image (corrupt or unsupported format)", source=f"img{i}.png")
        return self.images[i]


def _check_rejected(result, frame, text):
    d = result.diagnostics[frame]
    assert not d.accepted and text in d.reason, d.reason
    assert _finite(result)
    after = result.diagnostics[frame + 1]
    assert after.accepted and after.ref_frame == frame - 1  # matched against the last good frame
    return d


def test_unreadable_and_missing_images_are_rejected_with_reason(sim):
    traj, K, images = sim
    result = MonoVO(_cfg(), K, traj).run(_Failing(images, {3}))
    _check_rejected(result, 3, "unreadable image")
    missing = list(images)
    missing[3] = None
    _check_rejected(MonoVO(_cfg(), K, traj).run(missing), 3, "unreadable image (missing)")
    # the next frame, estimated over the gap, is still accurate
    assert ape(traj, MonoVO(_cfg(), K, traj).run(missing).trajectory, align="se3").rmse < 0.05


def test_unreadable_first_frame_is_rejected_and_no_usable_frame_is_a_clear_error(sim):
    traj, K, images = sim
    result = MonoVO(_cfg("none"), K).run(_Failing(images, {0}))
    assert not result.diagnostics[0].accepted and "unreadable image" in result.diagnostics[0].reason
    assert result.meta["start_frame"] == 1 and result.accepted_pairs == len(images) - 2 and _finite(result)
    with pytest.raises(DataError, match="none of the first 7 frames can be used"):
        MonoVO(_cfg("none"), K).run(_Failing(images, range(len(images))))


_FLOAT_HINT = ("convert with e.g. np.clip(img, 0, 255).astype(np.uint8) for 0-255 floats, "
               "np.clip(img * 255, 0, 255).astype(np.uint8) for 0-1 ones")


def test_no_usable_frame_names_each_reason_once_with_its_frames(sim):
    """Float images repeated "frame i: image dtype float32 is not uint8" for each of the first frames (~700 characters
    on KITTI); each reason is now said once, with the frames it applies to and how to convert."""
    traj, K, images = sim
    with pytest.raises(DataError) as err:
        MonoVO(_cfg(), K, traj).run([img.astype(np.float32) for img in images])
    assert str(err.value) == (f"images: none of the first 7 frames can be used (frames 0-6: image dtype float32 is not "
                              f"uint8 ({_FLOAT_HINT}))")
    colour = [np.repeat(img[:, :, None], 3, axis=2).astype(np.float64) for img in images]
    mixed = [None, colour[1], colour[2], None, colour[4], images[5].astype(np.uint16), images[6].astype(np.uint16)]
    with pytest.raises(DataError) as err:
        MonoVO(_cfg(), K, traj).run(mixed)
    assert str(err.value) == (
        "images: none of the first 7 frames can be used (frames 0, 3: unreadable image (missing); frames 1-2, 4: image "
        f"dtype float64 is not uint8 ({_FLOAT_HINT}); frames 5-6: image dtype uint16 is not uint8 (convert with e.g. "
        "(img >> 8).astype(np.uint8) for 16-bit images, np.clip(img, 0, 255).astype(np.uint8) for 0-255 values))")


def test_a_float_colour_frame_is_rejected_not_a_traceback(sim):
    """A float64 BGR frame reached OpenCV's colour conversion, which raised cv2.error (no float64 support) out of run();
    its dtype is checked first, so it is rejected like any unusable frame and the run goes on."""
    traj, K, images = sim
    frames = list(images)
    frames[3] = np.repeat(images[3][:, :, None], 3, axis=2).astype(np.float64)
    d = _check_rejected(MonoVO(_cfg(), K, traj).run(frames), 3, "image dtype float64 is not uint8")
    assert _FLOAT_HINT in d.reason


def test_odd_sized_first_frame_is_the_one_rejected(sim):
    """The sequence size is the majority of the first frames: an odd first frame cannot reject the others."""
    traj, K, images = sim
    bad = list(images)
    bad[0] = cv2.resize(images[0], (320, 240))
    result = MonoVO(_cfg(), K, traj).run(bad)
    d0 = result.diagnostics[0]
    assert not d0.accepted and "image size 320x240 differs from the sequence's 640x480" in d0.reason
    assert all(d.accepted for d in result.diagnostics[1:]) and result.meta["start_frame"] == 1
    assert result.meta["image_size_wh"] == [640, 480]
    # the start frame is anchored at its ground-truth pose; frames 1.. match the truth (gt scale, no alignment)
    assert ape(traj[1:], result.trajectory[1:], align="none").rmse < 0.01
    np.testing.assert_allclose(result.trajectory.poses_se3[0], traj.poses_se3[1])


def test_sequence_image_shape_is_the_majority_of_the_first_readable_frames():
    from lidarkit.vo.pipeline import sequence_image_shape

    a, b = np.zeros((40, 60), np.uint8), np.zeros((50, 70), np.uint8)
    assert sequence_image_shape([b, a, a, None, b, a]) == (40, 60)
    assert sequence_image_shape([None, b, a]) == (50, 70)  # tie: the earliest
    loaded = {}
    assert sequence_image_shape([a] * 20, loaded) == (40, 60) and sorted(loaded) == [0, 1, 2, 3, 4]
    with pytest.raises(DataError, match="images of 6 x 4 px: too small for feature detection"):
        sequence_image_shape([np.zeros((4, 6), np.uint8)] * 3)


def test_image_of_different_size_is_rejected(sim):
    traj, K, images = sim
    bad = list(images)
    bad[3] = cv2.resize(images[3], (320, 240))
    _check_rejected(MonoVO(_cfg(), K, traj).run(bad), 3, "image size 320x240 differs from the sequence's 640x480")


@pytest.mark.parametrize("name,reason", [("lidarkit", "too few matches"), ("report_orb", "too few features")])
def test_black_frame_is_rejected(sim, name, reason):
    traj, K, images = sim
    bad = list(images)
    bad[3] = np.zeros_like(images[3])
    result = MonoVO(preset(name, **{"scale.mode": "gt"}), K, traj).run(bad)
    _check_rejected(result, 3, reason)


def test_too_few_features_in_first_frame_moves_the_reference(sim):
    traj, K, images = sim
    bad = list(images)
    bad[0] = np.full_like(images[0], 128)
    cv2.circle(bad[0], (320, 240), 40, 255, -1)  # a few corners at most
    result = MonoVO(_cfg("none"), K).run(bad)
    assert "too few" in result.diagnostics[1].reason
    assert result.diagnostics[1].note == "reference moved to this frame"
    assert all(d.accepted for d in result.diagnostics[2:]) and _finite(result)


def test_pure_rotation_pair_is_rejected(scene):
    K = default_K()
    poses = [np.eye(4), make_se3(so3_exp(np.radians([0.0, 2.0, 0.0])), np.zeros(3)),
             make_se3(so3_exp(np.radians([0.0, 2.0, 0.0])), np.array([0.0, 0.0, 0.5]))]
    traj = Trajectory(np.array(poses))
    images = render_sequence(scene, traj, K)
    result = MonoVO(_cfg("none"), K).run(images)
    assert "insufficient parallax" in result.diagnostics[1].reason and "pure rotation" in result.diagnostics[1].reason
    assert result.diagnostics[2].accepted and result.diagnostics[2].ref_frame == 0
    assert _finite(result)


def test_pure_rotation_frame_turns_in_place_while_other_rejections_keep_constant_velocity(scene):
    """A parallax rejection (pure rotation) gets zero translation and the rotation of the matches; an unreadable
    frame still gets the constant-velocity step, or none with on_reject='identity'."""
    from lidarkit.vo.two_view import rotation_error_deg

    K = default_K()
    R = so3_exp(np.radians([1.0, -2.0, 0.5]))
    poses = [make_se3(np.eye(3), [0, 0, 0.0]), make_se3(np.eye(3), [0, 0, 0.5]), make_se3(R, [0, 0, 0.5]),
             make_se3(R, [0, 0, 1.0]), make_se3(R, [0, 0, 1.5]), make_se3(R, [0, 0, 2.0])]
    traj = Trajectory(np.array(poses))
    images = render_sequence(scene, traj, K)
    images[4] = None
    for on_reject, step4 in (("constant_velocity", 0.5), ("identity", 0.0)):
        result = MonoVO(_cfg("gt", on_reject=on_reject), K, traj).run(images)
        P = result.trajectory.poses_se3
        assert result.diagnostics[2].reason.startswith("insufficient parallax")
        assert np.linalg.norm(P[2, :3, 3] - P[1, :3, 3]) < 1e-9  # no translation (was 0.5 m: constant velocity)
        assert rotation_error_deg(P[2, :3, :3], R) < 0.1  # the pure rotation is kept (identity would be 2.3 deg)
        assert "unreadable" in result.diagnostics[4].reason
        assert np.linalg.norm(P[4, :3, 3] - P[3, :3, 3]) == pytest.approx(step4, abs=0.01)
        assert result.diagnostics[5].accepted and np.abs(P[5] - poses[5]).max() < 0.01


def test_all_rejected_pairs_are_visible_in_the_result(sim):
    from lidarkit.vo.pipeline import TrackingFailedError, rejection_key

    traj, K, images = sim
    black = [np.zeros_like(images[0])] * 4
    result = MonoVO(_cfg("none"), K).run(black)
    assert result.accepted_pairs == 0 and result.summary()["accepted_pairs"] == 0
    assert result.rejection_counts() == {"too few features in reference frame": 3}
    with pytest.raises(TrackingFailedError, match=r"no frame pair accepted \(3 of 4 frames rejected\); most common "
                                                  r"reason \(3x\): too few features in reference frame 0"):
        result.check_tracking()
    partial = list(images)
    partial[2] = None
    partial[4] = np.zeros_like(images[4])
    partial[5] = None
    result = MonoVO(_cfg("none"), K).run(partial)
    result.check_tracking()  # some pairs accepted: no error
    assert result.accepted_pairs == 3 and list(result.rejection_counts().items()) == [("unreadable image", 2),
                                                                                      ("too few matches", 1)]
    assert MonoVO(_cfg("none"), K).run(images[:1]).accepted_pairs == 0  # one frame: no pair, not a failure
    MonoVO(_cfg("none"), K).run(images[:1]).check_tracking()
    assert rejection_key("image size 640x200 differs from the sequence's 1226x370") == "image size"


def test_without_sanity_checks_failures_still_never_give_nan(sim):
    traj, K, images = sim
    bad = list(images)
    bad[2] = np.zeros_like(images[2])
    result = MonoVO(_cfg("none", **{"sanity.enabled": False}), K).run(bad)
    assert not result.diagnostics[2].accepted and _finite(result)


@pytest.mark.parametrize("name", ["lidarkit", "report_orb"])
@pytest.mark.parametrize("seed", [None, 5])
def test_two_runs_are_identical(sim, name, seed):
    traj, K, images = sim
    cfg = preset(name, **{"scale.mode": "relative", "seed": seed})
    a = MonoVO(cfg, K).run(images)
    b = MonoVO(cfg, K).run(images)
    assert np.array_equal(a.trajectory.poses_se3, b.trajectory.poses_se3)
    assert [d.n_inliers for d in a.diagnostics] == [d.n_inliers for d in b.diagnostics]


def test_seed_reaches_the_two_view_stage(sim):
    """A seed shuffles the correspondences the robust estimators sample from: other (equally valid) poses than the
    detection order."""
    traj, K, images = sim
    a = MonoVO(preset("lidarkit"), K).run(images)
    b = MonoVO(preset("lidarkit", seed=5), K).run(images)
    assert not np.array_equal(a.trajectory.poses_se3, b.trajectory.poses_se3)


def test_large_seeds_run(sim):
    """OpenCV's RNG takes a C int: seed 2148 and above raised "integer won't fit into a C int" (every such bench job
    failed); any seed runs now (seeds below 2148 set the same RNG seed as before)."""
    traj, K, images = sim
    for seed in (2148, 2**40):
        result = MonoVO(preset("lidarkit", seed=seed), K).run(images[:4])
        assert _finite(result) and all(d.accepted for d in result.diagnostics)


def test_one_unrelated_frame_does_not_take_over_the_reference(sim):
    """A single frame unrelated to its neighbours (corrupt, mis-ordered) is rejected; the next frame is matched
    against the old reference and accepted."""
    traj, K, images = sim
    bad = list(images)
    bad[3] = np.ascontiguousarray(np.flipud(images[3]))  # textured, but unrelated to its neighbours
    result = MonoVO(_cfg("none"), K).run(bad)
    d3, d4 = result.diagnostics[3], result.diagnostics[4]
    assert not d3.accepted and d3.reason.startswith("too few") and d3.note == ""
    assert d4.accepted and d4.ref_frame == 2 and _finite(result)
    assert [d.frame for d in result.rejected] == [3]


def test_tracking_lost_twice_moves_the_reference_instead_of_cascading(sim):
    """Lost on two frames in a row (the scene changed): the second becomes the reference, so tracking resumes."""
    traj, K, images = sim
    bad = [np.ascontiguousarray(np.flipud(im)) if i >= 3 else im for i, im in enumerate(images)]  # a new "scene"
    result = MonoVO(_cfg("none"), K).run(bad)
    d3, d4 = result.diagnostics[3], result.diagnostics[4]
    assert not d3.accepted and d3.note == ""
    assert not d4.accepted and d4.note == "reference moved to this frame"
    assert all(d.accepted and d.ref_frame == d.frame - 1 for d in result.diagnostics[5:]) and _finite(result)


def test_scale_kept_after_a_reference_reset_is_noted_and_counted(sim):
    """Relative scale: after the reference moved to a new frame (no depths there), the next pair cannot measure the
    scale; it keeps the previous one with a note, and VOResult counts it (only the very first pair starts silently)."""
    traj, K, images = sim
    bad = [np.ascontiguousarray(np.flipud(im)) if i >= 3 else im for i, im in enumerate(images)]
    result = MonoVO(_cfg("relative"), K).run(bad)
    moved = [d.frame for d in result.diagnostics if d.note == "reference moved to this frame"]
    after = result.diagnostics[moved[-1] + 1]
    assert after.accepted and after.note.startswith("scale kept from the previous step")
    assert result.n_scale_kept >= 1 and result.diagnostics[1].note == ""


def test_long_standstill_keeps_its_reference(sim):
    """Seven copies of a frame (a stop longer than the 5-frame stale limit) keep the reference: the depths carried
    for relative scale survive the stop, and the next moving frame is matched against the pre-stop reference."""
    traj, K, images = sim
    stopped = list(images[:3]) + [images[2]] * 7 + list(images[3:])
    result = MonoVO(_cfg("relative"), K).run(stopped)
    still = result.diagnostics[3:10]
    assert all(not d.accepted and d.reason.startswith("insufficient parallax") and d.ref_frame == 2 for d in still)
    assert all(d.note != "reference moved to this frame" for d in still)
    moving = result.diagnostics[10]
    assert moving.accepted and moving.ref_frame == 2 and moving.n_scale_points >= 15


@pytest.mark.parametrize("mode", ["relative", "none"])
def test_stopped_camera_on_kitti_stays_put(mode):
    """KITTI 06 frames 0-15 with frame 8 shown three times (the car stops): the copies get zero steps and the other
    frames the same poses as without the stop (measured: identical to the last bit; tolerance 1 mm APE)."""
    from conftest import shared_path

    from lidarkit.vo.inputs import open_vo_input

    vo_input = open_vo_input(shared_path("kitti_images", "sequences", "06"))
    images = [vo_input.images.read_image(i) for i in range(16)]
    gt = vo_input.ground_truth[:16]
    order = list(range(9)) + [8, 8] + list(range(9, 16))
    cfg = preset("lidarkit", **{"scale.mode": mode})
    moving = MonoVO(cfg, vo_input.K).run(images)
    stopped = MonoVO(cfg, vo_input.K).run([images[i] for i in order])
    assert [d.frame for d in stopped.rejected] == [9, 10]
    assert all(d.reason.startswith("insufficient parallax") for d in stopped.rejected)
    steps = np.linalg.norm(np.diff(stopped.trajectory.positions_xyz, axis=0), axis=1)
    assert np.all(steps[8:10] < 1e-9)  # were ~1 (constant velocity) before standstill handling
    assert steps[10] == pytest.approx(steps[7], rel=0.05)  # unit steps count moving frames only (was 3)
    others = stopped.trajectory[[k for k in range(len(order)) if k not in (9, 10)]]
    ape_moving = ape(gt, moving.trajectory, align="sim3").rmse
    assert ape_moving < 0.03
    assert abs(ape(gt, others, align="sim3").rmse - ape_moving) < 1e-3


def test_subpixel_refines_orb_corners_and_is_refused_for_blob_detectors():
    """Rectangles drawn at 8x and area-downsampled have corners at known fractional positions: cornerSubPix moves
    ORB keypoints onto them (measured median error 1.6 px -> 0.2 px). SIFT/AKAZE keypoints are already sub-pixel
    blobs: asking for subpixel there is a ConfigError instead of being silently ignored."""
    from scipy.spatial import cKDTree

    from lidarkit.vo import FeatureConfig, get_detector

    rng = np.random.default_rng(5)
    up, h, w = 8, 240, 320
    big = np.full((h * up, w * up), 60, np.uint8)
    corners = []
    for _ in range(40):
        x0, y0, dx, dy = rng.uniform(10, w - 50), rng.uniform(10, h - 50), rng.uniform(12, 30), rng.uniform(12, 30)
        X0, Y0, X1, Y1 = (int(round(v * up)) for v in (x0, y0, x0 + dx, y0 + dy))
        cv2.rectangle(big, (X0, Y0), (X1 - 1, Y1 - 1), int(rng.integers(150, 250)), -1)
        corners += [(X0, Y0), (X1, Y0), (X0, Y1), (X1, Y1)]
    image = cv2.GaussianBlur(cv2.resize(big, (w, h), interpolation=cv2.INTER_AREA), (3, 3), 0.8)
    true_px = np.array(corners, float) / up - 0.5  # pixel-centre convention
    median_error = {}
    for subpixel in (False, True):
        cfg = FeatureConfig(detector="orb", max_features=500, grid_rows=1, grid_cols=1, subpixel=subpixel)
        points, desc = get_detector(cfg).detect(image)
        assert len(points) == len(desc) > 100
        dist, _ = cKDTree(true_px).query(points)
        median_error[subpixel] = np.median(dist[dist < 2.0])
    assert median_error[False] > 1.0 and median_error[True] < 0.4
    for detector in ("sift", "akaze"):
        with pytest.raises(ConfigError, match="subpixel"):
            VOConfig().updated(**{"features.detector": detector, "features.subpixel": True})
        with pytest.raises(ConfigError, match="subpixel"):
            get_detector(detector, subpixel=True)


def test_a_result_reads_as_one_line_of_counts(sim):
    """repr printed every frame's diagnostics (~550 characters a frame): one line of counts now, whatever the length."""
    traj, K, images = sim
    result = MonoVO(_cfg("none"), K).run(images)
    name = result.trajectory.name
    assert repr(result) == (f"VOResult({name!r}, 7 frames in {result.runtime_s:.3g} s, 6 of 6 pairs accepted, scale none)")
    shorter = MonoVO(_cfg("none"), K).run(images[:3])
    assert repr(shorter) == (f"VOResult({name!r}, 3 frames in {shorter.runtime_s:.3g} s, 2 of 2 pairs accepted, scale none)")


def test_a_folder_path_is_refused_with_the_reader_to_use(sim, tmp_path):
    """A str was read one frame per character ("none of the first 10 frames can be used"), a Path failed on len():
    both are one DataError naming ImageFolder, which then reads the same folder."""
    from pathlib import Path

    from lidarkit.io.images import ImageFolder

    traj, K, images = sim
    for i, image in enumerate(images[:3]):
        cv2.imwrite(str(tmp_path / f"{i:06d}.png"), image)
    for path in (str(tmp_path), Path(tmp_path)):
        with pytest.raises(DataError) as err:
            MonoVO(_cfg("none"), K).run(path)
        assert str(err.value) == ("MonoVO.run images: a path is no image sequence: pass "
                                  f"lidarkit.io.images.ImageFolder({str(tmp_path)!r})")
    with pytest.raises(DataError, match="a generator is neither an ImageSequence"):
        MonoVO(_cfg("none"), K).run(image for image in images)
    assert MonoVO(_cfg("none"), K).run(ImageFolder(tmp_path)).accepted_pairs == 2


@pytest.fixture(scope="module")
def walking_pace():
    """6 frames of the street simulator at walking pace (1.2-1.5 m/s at 30 Hz: 4.5 cm a frame), rendered once."""
    from lidarkit.sim.street_camera import open_simcam

    seq = open_simcam("simcam:street?frames=6&seed=1&frame_rate_hz=30&speed_min_mps=1.2&speed_max_mps=1.5"
                      "&stop_probability=0")
    return [seq.read_image(i) for i in range(6)], seq.K, seq.ground_truth


def test_walking_pace_is_tracked_not_refused_for_too_few_pose_inliers(walking_pace):
    """recoverPose counts only points nearer than 50 baselines (2.3 m at 4.5 cm): on the first pair 1 of 1200
    E-RANSAC inliers, so every pair was refused ("too few pose inliers") and the run failed with no pair accepted.
    With fewer near points than the minimum the points in front at any distance give the pose (measured: 1176,
    rotation 0.001 deg and translation direction 0.4 deg off; the whole run 0.14 mm APE)."""
    from lidarkit.geometry import se3_inverse
    from lidarkit.vo import estimate_two_view, get_detector, track_klt
    from lidarkit.vo.config import FeatureConfig, MatchConfig
    from lidarkit.vo.evaluation import evaluate_vo
    from lidarkit.vo.two_view import rotation_error_deg

    images, K, gt = walking_pace
    corners = get_detector(FeatureConfig()).detect(images[0])[0]
    tracked, ok = track_klt(images[0], images[1], corners, MatchConfig())
    est = estimate_two_view(corners[ok], tracked[ok], K, min_inliers=30, far_points=True)
    T_cur_ref = se3_inverse(gt.poses_se3[1]) @ gt.poses_se3[0]
    direction = T_cur_ref[:3, 3] / np.linalg.norm(T_cur_ref[:3, 3])
    assert est.ok and est.n_inliers > 1000, est.failure
    assert rotation_error_deg(est.R_cur_ref, T_cur_ref[:3, :3]) < 0.05
    assert np.degrees(np.arccos(np.clip(est.t_cur_ref @ direction, -1.0, 1.0))) < 1.0
    result = MonoVO(_cfg("gt"), K, gt).run(images)
    assert result.accepted_pairs == 5 and not result.rejected
    assert evaluate_vo(result.trajectory, gt, "gt")["ape_rmse_m"] < 0.003


def test_walking_pace_takes_the_far_points_of_whichever_matrix_moves():
    """The F-fallback had a few more points in front than E-RANSAC (1190 for 1126) but too noisy to move, and only the
    matrix with most points in front was tried: frame 3 of this walk was refused as insufficient parallax (APE 7.4 mm
    for 1.3 mm); every matrix is tried now, most points in front first."""
    from lidarkit.sim.street_camera import open_simcam
    from lidarkit.vo.evaluation import evaluate_vo

    seq = open_simcam("simcam:street?frames=4&frame_rate_hz=30&speed_min_mps=1.2&speed_max_mps=1.5")
    result = MonoVO(_cfg("gt"), seq.K, seq.ground_truth).run([seq.read_image(i) for i in range(4)])
    assert result.accepted_pairs == 3 and not result.rejected, [d.reason for d in result.diagnostics]
    assert evaluate_vo(result.trajectory, seq.ground_truth, "gt")["ape_rmse_m"] < 0.003


def test_a_dropped_frame_leaves_the_smoothed_scores_close_to_the_raw_ones():
    """One frame left out of a simulated drive with its true time stamps: the Savitzky-Golay filter ran over the frame
    index, so the doubled step across the gap was a jump to smooth away (20 frames of 1.07 m steps: APE 0.0058 m raw,
    0.151 m smoothed; RPE 0.0075 / 0.22 m). Fitted against the time stamps the smoothed scores stay at the raw ones."""
    from lidarkit.sim.street_camera import open_simcam
    from lidarkit.vo.evaluation import evaluate_vo

    seq = open_simcam("simcam:street?frames=11&seed=4&width=320&height=100&fx=185&fy=185&cx=159.5&cy=49.5"
                      "&texel_scale=8")
    kept = np.array([k for k in range(11) if k != 5])  # frame 5 dropped: a 0.2 s step among 0.1 s ones
    gt = seq.ground_truth[kept]
    assert np.diff(gt.timestamps_s).max() == pytest.approx(2 * np.median(np.diff(gt.timestamps_s)))
    result = MonoVO(_cfg("gt"), seq.K, gt).run([seq.read_image(int(k)) for k in kept], timestamps_s=gt.timestamps_s)
    assert not result.rejected, [d.reason for d in result.diagnostics]
    raw = evaluate_vo(result.trajectory, gt, "gt")
    smoothed = evaluate_vo(result.smoothed(), gt, "gt")
    assert raw["ape_rmse_m"] < 0.05  # (measured 0.026 m raw, 0.007 m smoothed; over the index 0.219 m)
    assert smoothed["ape_rmse_m"] < 1.5 * raw["ape_rmse_m"]
    assert smoothed["rpe_trans_rmse_m"] < 1.5 * raw["rpe_trans_rmse_m"]


def test_smoothing_over_evenly_spaced_stamps_is_the_frame_index_filter():
    """Evenly spaced stamps give savgol_filter's result (ends included): the figures smoothed over the frame index
    stand; uneven ones weigh each pose by its time."""
    from scipy.signal import savgol_filter

    from lidarkit.vo.smoothing import smooth_translations

    rng = np.random.default_rng(3)
    poses = np.repeat(np.eye(4)[None], 20, axis=0)
    poses[:, :3, 3] = np.cumsum(rng.normal(0.0, 1.0, (20, 3)), axis=0)
    even = smooth_translations(Trajectory(poses, 100.0 + 0.1 * np.arange(20)), 9, 2)
    np.testing.assert_allclose(even.positions_xyz, savgol_filter(poses[:, :3, 3], 9, 2, axis=0, mode="interp"),
                               atol=1e-9)
    # positions on a parabola in time are kept exactly however the stamps are spaced (over the index they were not)
    stamps = np.cumsum(rng.uniform(0.05, 0.3, 20))
    poses[:, :3, 3] = np.column_stack([stamps**2, 3.0 * stamps, np.ones(20)])
    uneven = smooth_translations(Trajectory(poses, stamps), 9, 2)
    np.testing.assert_allclose(uneven.positions_xyz, poses[:, :3, 3], atol=1e-9)


def test_without_sanity_checks_features_and_matches_are_still_required(sim):
    """``--no-sanity`` keeps ``sanity.min_features`` and ``min_matches`` (a black frame has nothing to estimate from);
    the table in docs/visual_odometry.md listed them as checked only when the checks are enabled."""
    from pathlib import Path

    traj, K, images = sim
    frames = [image.copy() for image in images]
    frames[3][:] = 0
    result = MonoVO(_cfg("gt", **{"sanity.enabled": False}), K, traj).run(frames)
    assert result.diagnostics[3].accepted is False
    assert result.diagnostics[3].reason.startswith("too few matches (0 < 30)")
    docs = (Path(__file__).resolve().parents[1] / "docs" / "visual_odometry.md").read_text()
    row = next(line for line in docs.splitlines() if line.startswith("| sanity checks |"))
    always, _, when_enabled = row.partition("when enabled")
    assert "min_features" in always and "min_matches" in always
    assert "min_inliers" in when_enabled and "fundamental-matrix fallback" in when_enabled


def test_a_grayscale_image_with_a_channel_axis_is_taken_as_grayscale(sim):
    """(H, W, 1) frames (a single-channel image read with its channel axis) were each rejected as "not a grayscale
    image (shape (480, 640, 1))"; they give the same poses as the (H, W) frames, mixed with them too."""
    traj, K, images = sim
    plain = MonoVO(_cfg(), K, traj).run(images)
    with_axis = MonoVO(_cfg(), K, traj).run([image[:, :, None] for image in images])
    mixed = MonoVO(_cfg(), K, traj).run([image[:, :, None] if i % 2 else image for i, image in enumerate(images)])
    for result in (with_axis, mixed):
        assert not result.rejected and result.meta["image_size_wh"] == [640, 480]
        np.testing.assert_array_equal(result.trajectory.poses_se3, plain.trajectory.poses_se3)
