"""APE / RPE / position MSE: evo's stored reference results, invariances, and bad input."""

from __future__ import annotations

import io
import json
import zipfile

import numpy as np
import pytest
from conftest import shared_path

from lidarkit.errors import ConfigError, DataError, EvaluationError
from lidarkit.eval import align_trajectory, ape, position_mse, rpe
from lidarkit.geometry import make_se3, random_se3
from lidarkit.trajectory import Trajectory

STATS = ("rmse", "mean", "median", "std", "min", "max", "sse")


def load_evo_result(name: str) -> tuple[dict, dict, np.ndarray]:
    """info.json, stats.json and the error array of one of evo's stored result archives."""
    with zipfile.ZipFile(shared_path("evo_testdata", "res_files", f"{name}.zip")) as z:
        info = json.loads(z.read("info.json"))
        stats = json.loads(z.read("stats.json"))
        errors = np.load(io.BytesIO(z.read("error_array.npz")), allow_pickle=False)
    return info, stats, np.asarray(errors, dtype=float)


def kitti(name: str) -> Trajectory:
    return Trajectory.from_kitti(shared_path("evo_testdata", f"KITTI_00_{name}.txt"))


@pytest.fixture(scope="module")
def kitti_gt() -> Trajectory:
    return kitti("gt")


def synthetic(rng: np.random.Generator, n: int = 60, name: str = "") -> Trajectory:
    """A smooth random 3D trajectory: yaw/pitch random walk, ~1 m steps."""
    yaw = np.cumsum(rng.normal(0, 0.05, n))
    pitch = 0.1 * np.sin(np.linspace(0, 3, n))
    poses = np.tile(np.eye(4), (n, 1, 1))
    pos = np.zeros(3)
    for i in range(n):
        cy, sy, cp, sp = np.cos(yaw[i]), np.sin(yaw[i]), np.cos(pitch[i]), np.sin(pitch[i])
        R = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]]) @ np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
        pos = pos + R @ np.array([1.0, 0.0, 0.0])
        poses[i] = make_se3(R, pos)
    return Trajectory(poses, np.arange(n) * 0.1, name)


# ---- evo's stored reference results -----------------------------------------------------------------
@pytest.mark.parametrize("est_name,archive", [("ORB", "orb_ape"), ("SPTAM", "sptam_ape")])
def test_ape_reproduces_evo_stored_result(kitti_gt, est_name, archive):
    info, stats, errors = load_evo_result(archive)
    assert info["title"] == "APE w.r.t. translation part (m)\n(with SE(3) Umeyama alignment)"
    assert info["est_name"].endswith(f"KITTI_00_{est_name}.txt") and info["ref_name"].endswith("KITTI_00_gt.txt")
    result = ape(kitti_gt, kitti(est_name), align="se3", relation="translation")
    for stat in STATS:
        assert getattr(result, stat) == pytest.approx(stats[stat], rel=1e-4), stat
    np.testing.assert_allclose(result.errors, errors, rtol=1e-6, atol=1e-9)
    assert result.unit == "m" and result.alignment is not None and result.alignment.scale == 1.0
    assert result.to_dict()["stats"]["rmse"] == pytest.approx(stats["rmse"], rel=1e-4)


@pytest.mark.parametrize("est_name,archive", [("ORB", "orb_rpe"), ("SPTAM", "sptam_rpe")])
def test_rpe_reproduces_evo_stored_result_with_legacy_pairs(kitti_gt, est_name, archive):
    info, stats, errors = load_evo_result(archive)
    assert info["title"] == (
        "RPE w.r.t. translation part (m)\nfor delta = 10.0 (m) using consecutive pairs\n(not aligned)"
    )
    result = rpe(kitti_gt, kitti(est_name), delta=10, delta_unit="meters", align="none", legacy_pairs=True)
    assert result.n_errors == len(errors)
    for stat in STATS:
        assert getattr(result, stat) == pytest.approx(stats[stat], rel=1e-4), stat
    np.testing.assert_allclose(result.errors, errors, rtol=1e-6, atol=1e-9)


def test_evaluate_with_legacy_pairs_scores_rotation_on_the_translation_pairs(kitti_gt):
    """evaluate() hands the translation RPE's pairs to the rotation RPE, which dropped the first legacy pair again: 352
    rotation errors (from pair [26, 37]) beside 353 translation errors, rmse 0.65080 instead of 0.64994."""
    from lidarkit.eval import evaluate

    est = kitti("ORB")
    result = evaluate(kitti_gt, est, align="none", delta=10, delta_unit="meters", legacy_pairs=True, drift=False)
    direct = rpe(kitti_gt, est, delta=10, delta_unit="meters", align="none", legacy_pairs=True, relation="rotation_angle_deg")
    assert result.rpe.n_errors == result.rpe_rotation.n_errors == direct.n_errors == 353
    np.testing.assert_array_equal(result.rpe_rotation.pairs, direct.pairs)
    np.testing.assert_allclose(result.rpe_rotation.errors, direct.errors, rtol=1e-12)
    assert result.rpe_rotation.rmse == pytest.approx(0.64994, abs=1e-5)


def test_rpe_given_pairs_are_checked_and_scored_as_given(kitti_gt):
    """Pairs handed to rpe(pairs=...) out of range raised a bare IndexError; with consecutive pairs they were ignored
    (13 errors for 2 pairs given)."""
    est = kitti("ORB")
    with pytest.raises(ConfigError, match=r"pairs: pair 1 \(5, 9999\) is not two poses i < j of the 4541"):
        rpe(kitti_gt, est, pairs=[[0, 1], [5, 9999]], all_pairs=True, delta=10, delta_unit="meters")
    given = rpe(kitti_gt, est, pairs=[[0, 5], [100, 130]], align="none")
    assert given.n_errors == 2
    np.testing.assert_array_equal(given.pairs, [[0, 5], [100, 130]])
    for k, (i, j) in enumerate(given.pairs):
        one = rpe(kitti_gt[[int(i), int(j)]], est[[int(i), int(j)]], align="none")
        assert given.errors[k] == pytest.approx(one.errors[0], rel=1e-9)


def test_rpe_given_pairs_are_refused_for_point_distance_with_legacy_pairs_too(kitti_gt):
    """With legacy_pairs, pairs= for point_distance was read as a chain: [[0, 50], [100, 200], [300, 400]] were reported
    but (0, 50), (50, 200), (200, 400) scored (errors 1.875, 0.184, 0.633)."""
    for relation in ("point_distance", "point_distance_error_ratio"):
        with pytest.raises(ConfigError, match=rf"^pairs: pairs= is not supported for the {relation} relation "):
            rpe(kitti_gt, kitti("ORB"), 10, "m", relation=relation, legacy_pairs=True, pairs=[[0, 50], [100, 200], [300, 400]])


def test_rpe_given_pairs_that_are_empty_or_fractional_are_refused(kitti_gt):
    """pairs=np.zeros((0, 2)) scored evo's 4540 default pairs and reported none; [[0, 1.5]] was scored as [[0, 1]]."""
    est = kitti("ORB")
    with pytest.raises(ConfigError) as empty:
        rpe(kitti_gt, est, pairs=np.zeros((0, 2)))
    assert str(empty.value) == ("pairs: pairs is empty: give at least one (i, j) pose index pair, "
                                "or pairs=None to select them by delta")
    for bad, shown in (([[0, 1.5]], "pair 0 (0, 1.5)"), ([[0, 1], [2, float("nan")]], "pair 1 (2, nan)")):
        with pytest.raises(ConfigError) as fractional:
            rpe(kitti_gt, est, pairs=bad)
        assert str(fractional.value) == f"pairs: {shown} is not two whole pose indices"
    assert rpe(kitti_gt, est, pairs=np.array([[0.0, 2.0]])).pairs.tolist() == [[0, 2]]  # whole floats are indices


def test_rpe_default_pairs_match_current_evo_and_differ_from_stored(kitti_gt):
    """Today's evo starts the first 10 m pair at pose 0: one pair more than the stored 2018 result."""
    from evo.core.metrics import PoseRelation
    from evo.core.units import Unit
    from evo.main_rpe import rpe as evo_rpe

    est = kitti("ORB")
    ours = rpe(kitti_gt, est, delta=10, delta_unit="m")
    theirs = evo_rpe(kitti_gt.to_evo(), est.to_evo(), PoseRelation.translation_part, delta=10, delta_unit=Unit.meters)
    assert ours.rmse == pytest.approx(theirs.stats["rmse"], rel=1e-12)
    np.testing.assert_allclose(ours.errors, theirs.np_arrays["error_array"], rtol=1e-12)
    _, stats, errors = load_evo_result("orb_rpe")
    assert ours.n_errors == len(errors) + 1
    assert abs(ours.rmse - stats["rmse"]) > 5e-3  # 0.2368 vs 0.2263
    assert ours.pairs[0, 0] == 0 and (ours.pairs[1:, 0] == ours.pairs[:-1, 1]).all()


def test_ape_matches_evo_main_ape_for_every_alignment_and_relation(kitti_gt):
    from evo.core.metrics import PoseRelation
    from evo.main_ape import ape as evo_ape

    est = kitti("SPTAM")[:800]
    ref = kitti_gt[:800]
    for align, kw in [("none", {}), ("se3", {"align": True}), ("sim3", {"align": True, "correct_scale": True})]:
        for relation, evo_rel in [("translation", "translation_part"), ("rotation_angle_deg", "rotation_angle_deg"),
                                  ("full", "full_transformation")]:
            ours = ape(ref, est, align=align, relation=relation)
            theirs = evo_ape(ref.to_evo(), est.to_evo(), PoseRelation[evo_rel], **kw)
            for stat in STATS:
                assert getattr(ours, stat) == pytest.approx(theirs.stats[stat], rel=1e-9, abs=1e-12), (align, relation)


# ---- invariances -----------------------------------------------------------------------------------------
def test_sim3_alignment_recovers_scaled_and_moved_copy(rng):
    ref = synthetic(rng, 80, "ref")
    S = random_se3(rng, max_translation=20.0)
    scaled = ref.poses_se3.copy()
    scaled[:, :3, 3] *= 0.37
    est = Trajectory(S @ scaled, ref.timestamps_s, "est")
    result = ape(ref, est, align="sim3")
    assert result.rmse < 1e-9
    assert result.alignment.scale == pytest.approx(1 / 0.37, rel=1e-9)
    assert ape(ref, est, align="se3").rmse > 1.0  # rigid alignment cannot undo the scale
    rot = ape(ref, est, align="sim3", relation="rotation_angle_deg")
    assert rot.max < 1e-6
    aligned, transform = align_trajectory(ref, est, "sim3")
    np.testing.assert_allclose(aligned.positions_xyz, ref.positions_xyz, atol=1e-9)
    assert transform.method == "sim3"


def test_se3_alignment_and_origin_alignment_of_moved_copy(rng):
    ref = synthetic(rng, 50)
    S = random_se3(rng, max_translation=5.0)
    est = ref.transformed(T_left=S)
    assert ape(ref, est).rmse > 0.1
    assert ape(ref, est, align="se3").rmse < 1e-9
    assert ape(ref, est, align_origin=True).rmse < 1e-9
    assert ape(ref, est, align_origin=True).alignment.method == "origin"
    assert rpe(ref, est).rmse < 1e-9  # relative motions do not see a global transform


def test_identical_trajectories_give_zero_errors(rng):
    ref = synthetic(rng, 40)
    for relation in ("translation", "rotation_angle_deg", "full"):
        assert rpe(ref, ref, relation=relation).max < 1e-9
        assert rpe(ref, ref, delta=3, delta_unit="meters", relation=relation, all_pairs=True).max < 1e-9
        assert ape(ref, ref, relation=relation).max < 1e-9
    assert ape(ref, ref).max == 0.0  # translation: plain position differences


def test_rpe_of_constant_step_error_is_known(rng):
    """Estimate whose every step is 10 cm too long in x: RPE over 1 frame is exactly 0.1 m."""
    n = 30
    ref = Trajectory.from_relative_motions(np.tile(make_se3(translation=[1.0, 0, 0]), (n - 1, 1, 1)))
    est = Trajectory.from_relative_motions(np.tile(make_se3(translation=[1.1, 0, 0]), (n - 1, 1, 1)))
    res = rpe(ref, est, delta=1)
    np.testing.assert_allclose(res.errors, 0.1, atol=1e-12)
    assert res.n_errors == n - 1
    res5 = rpe(ref, est, delta=5)
    np.testing.assert_allclose(res5.errors, 0.5, atol=1e-12)
    assert res5.pairs.tolist()[:2] == [[0, 5], [5, 10]]
    ape_res = ape(ref, est)
    np.testing.assert_allclose(ape_res.errors, 0.1 * np.arange(n), atol=1e-12)
    assert ape_res.rmse == pytest.approx(np.sqrt(np.mean((0.1 * np.arange(n)) ** 2)))


def test_inputs_are_not_modified_by_alignment(rng):
    ref = synthetic(rng, 30)
    est = ref.transformed(T_left=random_se3(rng))
    before = est.poses_se3.copy()
    ape(ref, est, align="sim3")
    rpe(ref, est, align="se3")
    np.testing.assert_array_equal(est.poses_se3, before)


def test_associate_by_timestamps(rng):
    ref = synthetic(rng, 60)
    keep = np.arange(0, 60, 3)
    est = Trajectory(ref.poses_se3[keep], ref.timestamps_s[keep] + 0.004, "est")
    with pytest.raises(EvaluationError, match="differ in length.*associate"):
        ape(ref, est)
    res = ape(ref, est, associate=True, max_diff_s=0.01)
    assert res.n_errors == len(keep) and res.rmse == 0.0 and res.associated
    with pytest.raises(EvaluationError, match="association failed"):
        ape(ref, est, associate=True, max_diff_s=0.001)


def test_align_trajectory_associates_by_time_as_its_error_hint_says():
    """align_trajectory on TUM files of other lengths hinted "pass associate=True", which it did not take (TypeError)."""
    ref = Trajectory.from_tum(shared_path("evo_testdata", "freiburg1_xyz-groundtruth.txt"))
    est = Trajectory.from_tum(shared_path("evo_testdata", "freiburg1_xyz-rgbdslam.txt"))
    with pytest.raises(EvaluationError, match=r"3000 reference vs 788 estimated poses\); both have timestamps: pass associate=True"):
        align_trajectory(ref, est)
    aligned, transform = align_trajectory(ref, est, associate=True, max_diff_s=0.01)
    scored = ape(ref, est, "se3", associate=True, max_diff_s=0.01)
    assert len(aligned) == scored.n_errors == 785 and transform.method == "se3"
    np.testing.assert_allclose(aligned.positions_xyz, scored.est_aligned.positions_xyz, atol=1e-12)
    assert scored.rmse == pytest.approx(0.0134701, abs=1e-7)


@pytest.mark.parametrize("gt, est, max_diff_s, align", [
    ("freiburg1_xyz-groundtruth", "freiburg1_xyz-rgbdslam", 0.05, "se3"),  # a window that matches ground-truth poses twice
    ("fr2_desk_groundtruth", "fr2_desk_ORB_kf_mono", 0.01, "sim3"),  # TUM's own ground truth repeats one timestamp
])
def test_tum_association_scores_as_evo_does(gt, est, max_diff_s, align, caplog):
    from evo.core import metrics, sync
    from evo.tools import file_interface

    ref_path, est_path = (shared_path("evo_testdata", f"{name}.txt") for name in (gt, est))
    res = ape(Trajectory.from_tum(ref_path), Trajectory.from_tum(est_path), align=align, associate=True, max_diff_s=max_diff_s)
    evo_ref, evo_est = sync.associate_trajectories(file_interface.read_tum_trajectory_file(ref_path),
                                                   file_interface.read_tum_trajectory_file(est_path), max_diff=max_diff_s)
    evo_est.align(evo_ref, correct_scale=align == "sim3")
    evo_ape = metrics.APE(metrics.PoseRelation.translation_part)
    evo_ape.process_data((evo_ref, evo_est))
    assert res.n_errors == evo_est.num_poses and res.rmse == pytest.approx(evo_ape.get_statistic(metrics.StatisticsType.rmse), rel=1e-9)
    if gt == "fr2_desk_groundtruth":
        assert "1 pose(s) repeat the timestamp of the pose before them (line 10863): each left out" in caplog.text


def test_tum_timestamps_going_backwards_name_the_line(tmp_path):
    path = tmp_path / "back.txt"
    path.write_text("# t x y z qx qy qz qw\n1.0 0 0 0 0 0 0 1\n2.0 0 0 0 0 0 0 1\n\n1.5 0 0 0 0 0 0 1\n")
    with pytest.raises(DataError, match=r"back.txt \(line 5, frame 2\): timestamp 1.5 is earlier than the one before it \(2\)"):
        Trajectory.from_tum(path)


def test_n_to_align_uses_first_poses_only(rng):
    ref = synthetic(rng, 40)
    est_poses = ref.poses_se3.copy()
    est_poses[20:, :3, 3] += [0.0, 3.0, 0.0]  # second half is off
    est = Trajectory(est_poses)
    res = ape(ref, est, align="se3", n_to_align=15)
    assert res.errors[:20].max() < 1e-9 and res.errors[20:].min() == pytest.approx(3.0)
    assert res.alignment.n_poses_used == 15


# ---- bad input ------------------------------------------------------------------------------------------------
def test_bad_input_raises_named_errors(rng):
    ref = synthetic(rng, 20, "ref")
    with pytest.raises(EvaluationError, match=r"est vs ref.*differ in length \(20 reference vs 10"):
        ape(ref, synthetic(rng, 10, "est"))
    with pytest.raises(ConfigError, match="unknown alignment 'affine'"):
        ape(ref, ref, align="affine")
    with pytest.raises(ConfigError, match="unknown pose relation 'speed'"):
        rpe(ref, ref, relation="speed")
    with pytest.raises(ConfigError, match="unknown pose relation 'point_distance_error_ratio'"):
        ape(ref, ref, relation="point_distance_error_ratio")
    with pytest.raises(ConfigError, match="unknown delta unit 'seconds'"):
        rpe(ref, ref, delta=1, delta_unit="seconds")
    with pytest.raises(ConfigError, match="integer"):
        rpe(ref, ref, delta=1.5)
    with pytest.raises(ConfigError, match="delta must be > 0"):
        rpe(ref, ref, delta=0)
    with pytest.raises(EvaluationError, match="delta of 20 frames needs more than 20 poses"):
        rpe(ref, ref, delta=20)
    with pytest.raises(EvaluationError, match="delta = 500 m exceeds the path length of the estimate"):
        rpe(ref, ref, delta=500, delta_unit="meters")
    with pytest.raises(ConfigError, match="align_origin"):
        ape(ref, ref, align="se3", align_origin=True)
    with pytest.raises(ConfigError, match="legacy_pairs"):
        rpe(ref, ref, delta=2, legacy_pairs=True)
    with pytest.raises(EvaluationError, match="n_to_align"):
        ape(ref, ref, align="se3", n_to_align=99)
    with pytest.raises(ConfigError, match="n_to_align must be at least 1 pose, got 0"):  # a setting: was an EvaluationError
        ape(ref, ref, align="se3", n_to_align=0)
    with pytest.raises(EvaluationError, match="at least 3 poses"):
        ape(ref[:2], ref[:2], align="se3")
    with pytest.raises(EvaluationError, match="no timestamps"):
        ape(ref, Trajectory(ref.poses_se3), associate=True)
    with pytest.raises(EvaluationError, match="Trajectory"):
        ape(ref.poses_se3, ref)


def test_relation_error_given_a_path_names_the_argument():
    """relation_error("poses_tum.txt", relations) raised AttributeError 'str' object has no attribute 'name'."""
    from lidarkit.eval import relation_error
    from lidarkit.io.carmen import Relations

    relations = Relations.read(shared_path("carmen_2d", "aces.relations"))
    with pytest.raises(EvaluationError) as exc:
        relation_error("runs/aces/poses_tum.txt", relations)
    assert str(exc.value) == "estimate: the estimate must be a lidarkit Trajectory (e.g. Trajectory.from_tum(path)), got str"


def test_settings_given_as_text_are_named_errors_that_show_the_text(rng):
    """rpe(rel_delta_tol="x") raised a bare TypeError; EvaluationSettings(drift_step_frames="10") and
    position_mse(start="5") said "got 10" / "got 5", as if the numbers had been refused."""
    from lidarkit.eval import EvaluationSettings, kitti_drift

    ref = synthetic(rng, 20, "ref")
    for call, line in (
        (lambda: rpe(ref, ref, rel_delta_tol="x"), "rel_delta_tol: rel_delta_tol must be a number in [0, 1), got 'x'"),
        (lambda: rpe(ref, ref, rel_delta_tol=1.0), "rel_delta_tol: rel_delta_tol must be a number in [0, 1), got 1.0"),
        (lambda: EvaluationSettings(drift_step_frames="10"),
         "drift_step_frames: drift_step_frames must be a positive integer number of frames, got '10'"),
        (lambda: kitti_drift(ref, ref, step="x"), "step: step must be a positive integer number of frames, got 'x'"),
        (lambda: position_mse(ref, ref, start="5"), "start: start must be a frame index, got '5'"),
        (lambda: position_mse(ref, ref, dims="3"), "dims: dims must be 2 or 3, got '3'"),
    ):
        with pytest.raises(ConfigError) as exc:
            call()
        assert str(exc.value) == line
    assert position_mse(ref, ref, start=np.int64(5)) == 0.0 and EvaluationSettings(drift_step_frames=5).drift_step_frames == 5


def test_degenerate_alignment_is_an_error():
    still = Trajectory(np.tile(np.eye(4), (10, 1, 1)), name="still")
    with pytest.raises(EvaluationError, match="still vs still"):
        ape(still, still, align="sim3")


# ---- position MSE --------------------------------------------------------------------------------------------
def test_position_mse_hand_computed():
    ref = Trajectory(np.tile(np.eye(4), (4, 1, 1)), name="ref")
    est_poses = np.tile(np.eye(4), (4, 1, 1))
    est_poses[:, :3, 3] = [[3.0, 4.0, 0.0], [1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 2.0]]
    est = Trajectory(est_poses, name="est")
    assert position_mse(ref, est) == pytest.approx((25 + 1 + 4 + 4) / 4)
    assert position_mse(ref, est, start=1) == pytest.approx((1 + 4 + 4) / 3)
    assert position_mse(ref, est, start=1, dims=2) == pytest.approx((1 + 4 + 0) / 3)
    assert position_mse(ref, ref) == 0.0
    with pytest.raises(EvaluationError, match="needs more than 4 steps for the MSE from step 4; has 4"):
        position_mse(ref, est, start=4)
    with pytest.raises(EvaluationError, match="start must be a frame index in \\[0, 3\\]"):
        position_mse(ref, est, start=-1)
    with pytest.raises(ConfigError, match="dims"):
        position_mse(ref, est, dims=1)
    with pytest.raises(EvaluationError, match="differ in length"):
        position_mse(ref, est[:2])


def test_position_mse_associates_by_time_as_its_length_error_says():
    """position_mse(gt, rgbdslam) on TUM fr1_xyz said "pass associate=True (--associate)", but position_mse took no
    associate (a TypeError): now it pairs by timestamps as ape does, over the same 785 pose pairs."""
    ref = Trajectory.from_tum(shared_path("evo_testdata", "freiburg1_xyz-groundtruth.txt"))
    est = Trajectory.from_tum(shared_path("evo_testdata", "freiburg1_xyz-rgbdslam.txt"))
    with pytest.raises(EvaluationError, match=r"pass associate=True \(--associate\)"):
        position_mse(ref, est)
    mse = position_mse(ref, est, associate=True)
    assert mse == pytest.approx(4.0318304e-4, rel=1e-6)
    by_ape = ape(ref, est, associate=True)
    assert len(by_ape.errors) == 785 and mse == pytest.approx(by_ape.rmse ** 2, rel=1e-12)
    assert position_mse(ref, est, associate=True, max_diff_s=0.005) == pytest.approx(4.0172069e-4, rel=1e-6)
    with pytest.raises(ConfigError) as exc:
        position_mse(ref, est, associate="yes")
    assert str(exc.value) == "associate: associate must be True or False, got 'yes'"


def test_results_to_dict_is_json_safe(rng):
    ref = synthetic(rng, 30, "ref")
    est = ref.transformed(T_left=random_se3(rng, max_translation=1.0))
    for res in (ape(ref, est, align="sim3"), rpe(ref, est, delta=2, delta_unit="m", all_pairs=True)):
        data = json.loads(json.dumps(res.to_dict(), allow_nan=False))
        assert data["stats"]["rmse"] == pytest.approx(res.rmse)
        assert len(data["errors"]) == res.n_errors
    assert json.loads(json.dumps(rpe(ref, est).to_dict()))["pairs"][0] == [0, 1]


def test_orientation_errors_after_an_alignment_the_positions_hardly_fix_are_flagged():
    """5 poses of KITTI 00 lie on a line to 1e-6: the SE(3) alignment turns the estimate about it at random (APE
    rotation 136 deg aligned, 0.29 deg as estimated), as evo does; the result now says so, the whole run does not."""
    from lidarkit.eval import evaluate
    from lidarkit.eval.ape_rpe import AXIS_SIGMA_LIMIT_DEG
    from lidarkit.eval.report import evaluation_markdown, evaluation_notes

    gt = Trajectory.from_kitti(shared_path("evo_testdata", "KITTI_00_gt.txt"))
    orb = Trajectory.from_kitti(shared_path("evo_testdata", "KITTI_00_ORB.txt"))
    short_gt, short_orb = Trajectory(gt.poses_se3[:5]), Trajectory(orb.poses_se3[:5])
    aligned = ape(short_gt, short_orb, "se3", "rotation_angle_deg")
    assert aligned.rmse > 100 and aligned.alignment.axis_sigma_deg > 1e4
    assert "not meaningful" in aligned.warning and aligned.to_dict(False)["warning"] == aligned.warning
    assert aligned.warning.endswith("align='none' (--align none) compares orientations as estimated")  # (the CLI's option unnamed)
    assert ape(short_gt, short_orb, "se3", "translation").warning == ""  # positions are what the fit fits
    assert ape(short_gt, short_orb, "none", "rotation_angle_deg").warning == ""
    whole = ape(gt, orb, "se3", "rotation_angle_deg")
    assert whole.warning == "" and 0.1 < whole.alignment.axis_sigma_deg < AXIS_SIGMA_LIMIT_DEG / 2
    # Sim(3): the scale is stated beside the alignment, and the drift said to be on the estimate as given
    half = Trajectory(orb.poses_se3.copy())
    half.poses_se3[:, :3, 3] *= 0.5
    ev = evaluate(gt, half, align="sim3")
    assert ev.ape.alignment.scale == pytest.approx(2.0, rel=0.01)
    markdown = evaluation_markdown(ev)
    assert "align=sim3 (scale 2.0" in markdown and "KITTI drift is the devkit's, on the estimate as given (unscaled)" in markdown
    assert evaluation_notes(evaluate(short_gt, short_orb))[0] == aligned.warning
    # what the pairing warned of is in the filed report too (it was logged and in --json only)
    stamps = np.arange(len(gt)) * 0.1
    timed = evaluate(Trajectory(gt.poses_se3, stamps), Trajectory(orb.poses_se3, stamps + 1.0), drift=False)
    assert timed.warnings and f"Warning: {timed.warnings[0]}." in evaluation_markdown(timed)


def test_all_pairs_over_an_angle_delta_search_once_and_equal_evo(capsys):
    """evo searched the all-pairs selection again inside every RPE (quadratic in the poses: 4 searches for
    evaluate()'s two relations, 25 s on 1500 poses). The pairs are searched once now, the errors still evo's."""
    from evo.core import metrics as evo_metrics
    from evo.core.units import Unit

    from lidarkit.eval import evaluate

    gt = Trajectory.from_kitti(shared_path("evo_testdata", "KITTI_00_gt.txt"))
    orb = Trajectory.from_kitti(shared_path("evo_testdata", "KITTI_00_ORB.txt"))
    g, o = Trajectory(gt.poses_se3[:400]), Trajectory(orb.poses_se3[:400])
    for relation, evo_relation in (("translation", "translation_part"), ("rotation_angle_deg", "rotation_angle_deg"), ("full", "full_transformation")):
        ours = rpe(g, o, delta=5.0, delta_unit="degrees", all_pairs=True, relation=relation)
        theirs = evo_metrics.RPE(evo_metrics.PoseRelation[evo_relation], 5.0, Unit.degrees, 0.1, True)
        theirs.process_data((g.to_evo(), o.to_evo()))
        stats = theirs.get_all_statistics()
        assert len(ours.errors) == len(theirs.error) == len(ours.pairs) > 100
        for name in ("rmse", "mean", "max", "min"):
            assert getattr(ours, name) == pytest.approx(stats[name], rel=1e-12)
    capsys.readouterr()
    calls = []
    original = evo_metrics.id_pairs_from_delta

    def counted(*args, **kwargs):
        calls.append(kwargs.get("all_pairs", args[4] if len(args) > 4 else False))
        return original(*args, **kwargs)

    evo_metrics.id_pairs_from_delta = counted
    try:
        evaluate(g, o, delta=5, delta_unit="degrees", all_pairs=True, drift=False)
    finally:
        evo_metrics.id_pairs_from_delta = original
    assert sum(map(bool, calls)) == 1  # one all-pairs search (evo then compares consecutive copies: linear)
    said = capsys.readouterr()
    assert "%" not in said.out and "%" not in said.err  # evo's progress, without a line end, is kept out of both


def test_an_evaluation_prints_as_one_line_of_its_headline_figures(kitti_gt):
    """``print(evaluate(...))`` printed every field of every result (~4900 characters); now one line whose figures are
    the results' own."""
    from lidarkit.eval import evaluate

    ref, est = kitti_gt[:300], kitti("ORB")[:300]  # 300 poses, 216 m: drift on 100-200 m segments
    result = evaluate(ref, est)
    text = repr(result)
    assert "\n" not in text and len(text) < 400, text
    assert f"APE rmse {result.ape.rmse:.4g} m" in text and f"RPE rmse {result.rpe.rmse:.4g} m" in text
    assert f"drift {result.drift.translation_pct:.4g} %" in text
    assert f"{result.n_poses} poses" in text
    assert "no drift (not requested)" in repr(evaluate(ref, est, drift=False))


def test_evaluation_settings_refuse_an_unknown_alignment_when_made():
    """EvaluationSettings(align="xyz") was made without complaint and refused only by evaluate(), after the pairing."""
    from lidarkit.eval import EvaluationSettings

    for align in ("xyz", None):
        with pytest.raises(ConfigError) as exc:
            EvaluationSettings(align=align)
        assert str(exc.value) == f"align: unknown alignment {align!r}; known: none, se3, sim3, scale"
    assert EvaluationSettings(align="sim3").align == "sim3"


def test_rpe_title_names_the_delta_and_pair_mode_that_were_scored(kitti_gt):
    """All-pairs RPE and RPE over given pairs (every evaluate() hands its pairs to the rotation RPE) were titled
    "for delta = 1 (frames) using consecutive pairs": evo's metric that compared the laid-out copies was read."""
    from evo.core import metrics as evo_metrics
    from evo.core.units import Unit

    from lidarkit.eval import evaluate

    g, o = kitti_gt[:400], kitti("ORB")[:400]
    ours = rpe(g, o, delta=5.0, delta_unit="degrees", all_pairs=True)
    theirs = evo_metrics.RPE(evo_metrics.PoseRelation.translation_part, 5.0, Unit.degrees, 0.1, True)
    assert ours.title == f"{theirs} (not aligned)".replace("\n", " ")
    assert ours.title == "RPE w.r.t. translation part (m) for delta = 5.0 (deg) using all pairs (not aligned)"
    result = evaluate(g, o, align="none", delta=20, delta_unit="m", drift=False)
    assert result.rpe_rotation.title == ("RPE w.r.t. rotation angle in degrees (deg) for delta = 20.0 (m) "
                                         "using consecutive pairs (not aligned)")
    legacy = rpe(g, o, delta=20, delta_unit="m", legacy_pairs=True, pairs=result.rpe.pairs[1:])
    assert legacy.title == ("RPE w.r.t. translation part (m) for delta = 20.0 (m), legacy pairs "
                            "using consecutive pairs (not aligned)")


def test_a_path_delta_longer_than_the_path_says_so():
    """A path delta longer than the path failed with evo's "delta = 100.0 (m) produced an empty index list - try lower
    values or a less strict tolerance" (lidarkit eval has no tolerance option): the reason is stated now."""
    gt = kitti("gt")[:3]
    assert gt.length_m == pytest.approx(1.720, abs=1e-3)
    for all_pairs in (False, True):
        with pytest.raises(EvaluationError) as caught:
            rpe(gt, gt, delta=100, delta_unit="m", all_pairs=all_pairs)
        assert str(caught.value) == ("KITTI_00_gt vs KITTI_00_gt: delta = 100 m exceeds the path length of the estimate "
                                     "(1.72 m): no two poses are that far apart along it")
    assert rpe(gt, gt, delta=1.5, delta_unit="m").n_errors == 1  # (within the path: scored)


def test_an_angle_delta_beyond_the_rotation_along_the_path_says_so():
    """An angle delta larger than the rotation accumulated along the path failed with evo's "delta = 170.0 (deg)
    produced an empty index list - try lower values or a less strict tolerance", as path deltas did."""
    from scipy.spatial.transform import Rotation

    gt = kitti("gt")[:200]
    R = gt.poses_se3[:, :3, :3]
    turned = np.degrees(np.linalg.norm(Rotation.from_matrix(np.einsum("nji,njk->nik", R[:-1], R[1:])).as_rotvec(), axis=1).sum())
    assert turned == pytest.approx(146.03, abs=0.01)  # (the first corner)
    with pytest.raises(EvaluationError) as caught:
        rpe(gt, gt, delta=170, delta_unit="deg")
    assert str(caught.value) == ("KITTI_00_gt vs KITTI_00_gt: delta = 170 degrees exceeds the rotation accumulated along the "
                                 f"estimate ({turned:.4g} degrees): no two poses are that far apart in orientation along it")
    with pytest.raises(EvaluationError, match=r"delta = 3 radians exceeds the rotation accumulated along the estimate \(2\.549 radians\)"):
        rpe(gt, gt, delta=3, delta_unit="rad")
    assert rpe(gt, gt, delta=140, delta_unit="deg").n_errors == 1  # (within the rotation: scored)
    # all pairs take the direct angle between two poses: the widest, checked against every pair by scipy
    rotations = Rotation.from_matrix(R)
    widest = max(float(np.degrees((rotations[i].inv() * rotations).magnitude().max())) for i in range(len(R)))
    with pytest.raises(EvaluationError) as caught:
        rpe(gt, gt, delta=170, delta_unit="deg", all_pairs=True)
    assert str(caught.value) == ("KITTI_00_gt vs KITTI_00_gt: delta = 170 degrees: no two poses of the estimate are that far "
                                 f"apart in orientation (the widest is {widest:.4g} degrees)")


def test_rotations_the_reader_accepts_but_evo_refuses_are_scored():
    """SemanticKITTI's poses of KITTI 00 (rotations orthonormal to 1.6e-6) against KITTI's: `lidarkit eval` stopped
    with evo's "APE failed: matrix is not a valid SO(3) group element" (as does evo_ape -r angle_deg), though the reader
    accepts them (1e-4). A pair evo refuses is scored again on orthonormalized copies; evo's own figures on those copies
    agree (a pair evo takes is scored as given: evo's stored results, above)."""
    from evo.core import metrics

    from lidarkit.eval import evaluate
    from lidarkit.geometry import orthonormalize_se3

    gt = Trajectory.from_kitti(shared_path("kitti_odometry", "poses", "00.txt"))
    semantic = Trajectory.from_kitti(shared_path("kitti_odometry", "sequences", "00", "poses_semantickitti.txt"))
    ev = evaluate(gt, semantic, align="none", drift=False)
    metric = metrics.APE(metrics.PoseRelation.rotation_angle_deg)
    metric.process_data((gt.to_evo(), Trajectory(orthonormalize_se3(semantic.poses_se3)).to_evo()))
    assert ev.ape_rotation.rmse == pytest.approx(metric.get_statistic(metrics.StatisticsType.rmse), rel=1e-9)
    assert 0.1 < ev.ape_rotation.rmse < 5.0 and np.isfinite(ev.rpe_rotation.rmse)


def flat_square_loop(n: int = 400, side_m: float = 20.0, heading_drift_deg: float = 45.0) -> tuple[Trajectory, Trajectory]:
    """A square loop in the z = 0 plane and an estimate of it whose heading drifts linearly (every rotation about z)."""
    s = np.linspace(0.0, 4 * side_m, n)
    side, u = (s // side_m).astype(int) % 4, s % side_m
    x = np.select([side == 0, side == 1, side == 2], [u, np.full(n, side_m), side_m - u], np.zeros(n))
    y = np.select([side == 0, side == 1, side == 2], [np.zeros(n), u, np.full(n, side_m)], side_m - u)

    def poses(x, y, yaw):
        out = np.tile(np.eye(4), (len(x), 1, 1))
        c, si = np.cos(yaw), np.sin(yaw)
        out[:, 0, 0], out[:, 0, 1], out[:, 1, 0], out[:, 1, 1] = c, -si, si, c
        out[:, 0, 3], out[:, 1, 3] = x, y
        return out

    yaw = np.arctan2(np.gradient(y), np.gradient(x))
    drift = np.radians(heading_drift_deg) * s / s[-1]
    dx, dy = np.diff(x, prepend=x[0]), np.diff(y, prepend=y[0])
    x_est, y_est = np.cumsum(dx * np.cos(drift) - dy * np.sin(drift)), np.cumsum(dx * np.sin(drift) + dy * np.cos(drift))
    stamps = np.arange(n) * 0.1
    return Trajectory(poses(x, y, yaw), stamps, "ref"), Trajectory(poses(x_est, y_est, yaw + drift), stamps, "est")


def test_in_plane_drift_of_a_flat_loop_is_not_read_as_an_unfixed_tilt(tmp_path):
    """A flat 20 x 20 m loop whose heading drifts 45 deg: the plane fixes the alignment's turn about the main direction,
    yet the whole residual (in-plane drift) over the spread read ~18 deg and the rotation APE was called "not
    meaningful" (ACES with kiss-icp: "only to ~24 deg"). Only the residual out of the plane counts now."""
    ref, est = flat_square_loop()
    ref = Trajectory.from_tum(ref.to_tum(tmp_path / "ref.txt"))
    est = Trajectory.from_tum(est.to_tum(tmp_path / "est.txt"))
    result = ape(ref, est, "se3", "rotation_angle_deg")
    assert result.rmse > 5  # (the heading drift is there, and is what the figure measures)
    assert result.alignment.axis_sigma_deg < 1.0
    assert result.warning == ""
    # residuals out of the plane as large as the loop's spread still leave the turn about its main direction loose
    lifted = est.poses_se3.copy()
    lifted[:, 2, 3] = 8.0 * np.where(np.arange(len(est)) % 2, 1.0, -1.0)
    loose = ape(ref, Trajectory(lifted, est.timestamps_s, "lifted"), "se3", "rotation_angle_deg")
    assert loose.alignment.axis_sigma_deg > 10 and "not meaningful" in loose.warning


def test_index_pairing_advice_names_a_time_window_that_pairs_the_stamps(tmp_path):
    """Stamps 0.02 s apart pose by pose: the warning advised --associate, which then failed with the default --max-diff
    of 0.01 s. The advice now names a window above the largest gap, and calls a constant offset what it is."""
    from lidarkit.eval import evaluate

    ref, _ = flat_square_loop(n=100)
    stamps = ref.timestamps_s
    ref = Trajectory.from_tum(ref.to_tum(tmp_path / "ref.txt"))
    est = Trajectory.from_tum(Trajectory(ref.poses_se3, stamps + 0.02, "est").to_tum(tmp_path / "est.txt"))
    warned = evaluate(ref, est, drift=False).warnings[0]
    assert "the offset is a constant +0.02 s" in warned and "pairing by index, as here, already pairs them right" in warned
    assert warned.endswith("if not, --associate --max-diff 0.03 (associate=True, max_diff_s=0.03) pairs them by time")
    with pytest.raises(EvaluationError, match="no pose has a partner within 0.01 s"):
        evaluate(ref, est, drift=False, associate=True)
    assert evaluate(ref, est, drift=False, associate=True, max_diff_s=0.03).n_poses == 100  # (the advice works)
    # stamps off by 5 to 25 ms (a third within 0.01 s): no constant offset, the same window
    jittered = stamps + np.where(np.arange(100) % 3, 0.025, 0.005)
    est = Trajectory.from_tum(Trajectory(ref.poses_se3, jittered, "est").to_tum(tmp_path / "jittered.txt"))
    warned = evaluate(ref, est, drift=False).warnings[0]
    assert warned.endswith(": --associate --max-diff 0.03 (associate=True, max_diff_s=0.03) pairs them by time (within "
                           "0.01 s it pairs too few)")
    assert evaluate(ref, est, drift=False, associate=True, max_diff_s=0.03).n_poses == 100


def test_results_given_numpy_scalars_are_json_safe_and_keep_the_warnings(tmp_path):
    """np.int64(10) as delta (or drift_step_frames, n_to_align), np.float32 deltas and numpy booleans were kept as given:
    to_dict() of the evaluation, APE and RPE failed json.dumps ("Object of type int64 is not JSON serializable"). The
    evaluation's dict also lacked its warnings (the CLI added them; a library user's JSON had none)."""
    from lidarkit.eval import evaluate

    ref, est = flat_square_loop(n=200)
    ref = Trajectory.from_tum(ref.to_tum(tmp_path / "ref.txt"))
    est = Trajectory.from_tum(Trajectory(est.poses_se3, est.timestamps_s + 0.02, "est").to_tum(tmp_path / "est.txt"))
    ev = evaluate(ref, est, delta=np.int64(10), drift_step_frames=np.int64(5), drift_lengths_m=(np.float64(10), 20.0),
                  all_pairs=np.bool_(False))
    data = json.loads(json.dumps(ev.to_dict(), allow_nan=False))
    assert data["settings"]["delta"] == 10 and type(ev.settings.delta) is int and type(ev.settings.drift_step_frames) is int
    assert type(ev.settings.all_pairs) is bool and data["settings"]["drift_lengths_m"] == [10.0, 20.0]
    assert ev.warnings and data["warnings"] == list(ev.warnings)
    metres = evaluate(ref, est, delta=np.float32(2.0), delta_unit="m", drift=False)
    assert json.loads(json.dumps(metres.to_dict()))["settings"]["delta"] == 2.0
    aligned = ape(ref, est, "se3", n_to_align=np.int64(80), associate=np.bool_(False))  # (the first 50: one side)
    assert json.loads(json.dumps(aligned.to_dict(False)))["n_to_align"] == 80
    relative = rpe(ref, est, 5, all_pairs=np.bool_(True), pairs_from_reference=np.bool_(False), align="se3",
                   n_to_align=np.int64(80), associate=np.bool_(False))
    data = json.loads(json.dumps(relative.to_dict(False)))
    assert data["all_pairs"] is True and data["n_to_align"] == 80 and data["associated"] is False


def test_ape_and_rpe_refuse_statistics_that_overflow_without_numpy_warnings():
    """A coordinate of 1e300: the squares overflowed, numpy warned over several lines (overflow in dot and square,
    invalid value in subtract) and APE/RPE returned rmse inf, std NaN as results. One EvaluationError names the pair
    and the pose, and numpy stays quiet."""
    import warnings

    from lidarkit.eval import evaluate

    n = 150  # (a path over 100 m: evaluate() computes the KITTI drift first)
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, :3, 3] = np.column_stack([np.arange(n), np.sin(0.2 * np.arange(n)), 0.3 * np.cos(0.1 * np.arange(n))])
    far = poses.copy()
    far[10, 2, 3] = -1e300  # (a drift segment starts there)
    ref, est = Trajectory(poses, name="gt"), Trajectory(far, name="odo")
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        for metric, kwargs in ((ape, {"align": "se3"}), (ape, {}), (rpe, {"delta": 1}), (evaluate, {})):
            with pytest.raises(EvaluationError, match=r"^odo vs gt: (APE|RPE) \(translation\) statistics are not finite "
                                                      r"\(rmse inf, .*\): the largest coordinate is 1e\+300 m \(estimate, "
                                                      r"pose 10\), too large to score in float64$"):
                metric(ref, est, **kwargs)
        assert ape(ref, Trajectory(poses + 0.0)).rmse == 0.0  # (finite figures as before)
