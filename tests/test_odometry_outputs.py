"""Outputs that say what was actually done (issue 19): effective deskew and why, every score named by its
alignment, an independent per-frame check for every variant, runs titled after their folder, docs that match
the reader.

One small simulated KITTI-layout export (12 sweeps of 16 x 360 rays, moving from t = 0) serves the CLI tests;
the open scene of the frame-check test is 25 sweeps of 16 x 360 rays.
"""

from __future__ import annotations

import json
import re
import shutil
import textwrap
from pathlib import Path

import numpy as np
import pytest

from lidarkit.cli import main
from lidarkit.io.kitti import POINT_TIME_FOLDERS, KittiOdometry
from lidarkit.odometry import run
from lidarkit.errors import ConfigError, DataError
from lidarkit.registration import get_icp
from lidarkit.params import parse_kv
from lidarkit.odometry.frame_check import FrameCheckConfig, make_frame_check, motion_deviation, motion_limits
from lidarkit.sim.lidar import SimulatedLidarSequence, export_kitti

DOCS = Path(__file__).resolve().parents[1] / "docs"
EXPORT = {"scene": "street", "n_frames": 12, "n_beams": 16, "n_azimuths": 360, "seed": 0, "accel_time_s": 0.0}


def _cli(args: list[str], capsys) -> tuple[int, str, str]:
    try:
        code = main(args)
    except SystemExit as exc:
        code = exc.code
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.fixture(autouse=True)
def wide_console(monkeypatch):
    """Rich tables one row per line (no wrapping at 80 columns), so rows can be matched as printed."""
    monkeypatch.setenv("COLUMNS", "300")


@pytest.fixture(scope="module")
def exported(tmp_path_factory) -> Path:
    """A KITTI-layout sequence with per-point times in point_times/ (as lidarkit's simulator writes it)."""
    return export_kitti(SimulatedLidarSequence(**EXPORT), tmp_path_factory.mktemp("sim") / "street_seq")


def _copy(exported: Path, dest: Path, times_folder: str | None) -> Path:
    """A copy of the export whose per-point times live in ``times_folder`` (None: no per-point times)."""
    shutil.copytree(exported, dest)
    if times_folder is None:
        shutil.rmtree(dest / "point_times")
    elif times_folder != "point_times":
        (dest / "point_times").rename(dest / times_folder)
    return dest


# ---- deskew: requested vs applied -----------------------------------------------------------------------------
def test_per_point_times_under_every_documented_folder_name_are_found_and_deskew_is_applied(exported, tmp_path, capsys):
    poses = {}
    for folder in POINT_TIME_FOLDERS:
        seq = _copy(exported, tmp_path / folder / "street_seq", folder)
        assert KittiOdometry(seq).point_times_dir == seq / folder
        out = tmp_path / folder / "run"
        code, text, _ = _cli(["odometry", str(seq), "-m", "kiss", "--no-progress", "--out", str(out)], capsys)
        assert code == 0
        metrics = json.loads((out / "metrics.json").read_text())
        deskew = metrics["effective"]["deskew"]
        assert deskew["requested"] is True and deskew["applied"] is True and deskew["frames_with_point_times"] == 12
        assert f"{folder}/" in deskew["reason"] and metrics["warnings"] == []
        assert re.search(rf"on: per-point times from {folder}/", text)
        poses[folder] = np.loadtxt(out / "poses_kitti.txt")
    for folder in POINT_TIME_FOLDERS[1:]:  # the same times under another name: the same deskewed estimate
        np.testing.assert_allclose(poses[folder], poses["point_times"], atol=1e-9)
    without = run(_copy(exported, tmp_path / "none" / "street_seq", None), "kiss")
    assert without.metrics["effective"]["deskew"]["applied"] is False
    deskewed = poses["point_times"].reshape(-1, 3, 4)
    assert np.abs(without.trajectory.poses_se3[:, :3, :] - deskewed).max() > 0.01  # deskew changed the estimate


def test_per_point_times_under_an_unknown_folder_name_say_deskew_was_not_applied(exported, tmp_path, capsys):
    seq = _copy(exported, tmp_path / "street_seq", "stamps")
    out = tmp_path / "run"
    code, text, _ = _cli(["odometry", str(seq), "-m", "kiss", "--no-progress", "--out", str(out)], capsys)
    assert code == 0
    assert re.search(r"│ warning +│ deskew requested, no per-point times found \(looked for point_times/", text)
    assert "REQUESTED, NOT APPLIED: no per-point times found (looked for point_times/, timestamps/" in text
    metrics = json.loads((out / "metrics.json").read_text())
    deskew = metrics["effective"]["deskew"]
    assert deskew == {**deskew, "requested": True, "applied": False, "frames_with_point_times": 0}
    assert "no per-point times found" in deskew["reason"] and "timestamps/" in deskew["reason"]
    assert any(w.startswith("deskew requested, no per-point times found") for w in metrics["warnings"])
    config = (out / "config.yaml").read_text()
    assert "deskew: true" in config and "applied: false" in config  # requested and effective side by side

    code, _, err = _cli(["odometry", str(seq), "-m", "kiss", "--no-progress", "--strict"], capsys)
    assert code == 1
    (line,) = [ln for ln in err.splitlines() if ln.strip()]
    assert "frame 0" in line and "deskew requested, no per-point times found" in line


def test_per_point_times_that_are_all_equal_are_not_deskewed_with(exported, tmp_path):
    """A driver that writes zeros in its time field: kiss-icp would normalize the times by their zero span and abort
    the whole process (Sophus, SIGABRT). The frames are read as frames without per-point times, and the run says so."""
    seq = _copy(exported, tmp_path / "street_seq", "point_times")
    for path in sorted((seq / "point_times").glob("*.npy")):
        np.save(path, np.full_like(np.load(path), 0.05))
    flat = run(seq, "kiss", frames="0:4")
    plain = run(_copy(exported, tmp_path / "none" / "street_seq", None), "kiss", frames="0:4")
    np.testing.assert_allclose(flat.trajectory.poses_se3, plain.trajectory.poses_se3, atol=1e-9)  # (kiss-icp: round-off)
    deskew = flat.metrics["effective"]["deskew"]
    assert deskew["applied"] is False and deskew["frames_with_point_times"] == 0
    assert deskew["reason"] == "the per-point times of 4 of 4 frames are all equal (nothing to deskew with)"
    # strict: refused naming what the frame has (the times were there; "no per-point times found in point_times" sent the
    # user looking for missing files), for kiss and for ground_filtered (deskewing through align)
    for method in ("kiss", "ground_filtered"):
        with pytest.raises(DataError) as err:
            run(seq, method, frames="0:4", strict=True)
        assert str(err.value) == (f"{seq / 'velodyne' / '000000.bin'} (frame 0): deskew requested, its per-point times are "
                                  "all equal (nothing to deskew with)")  # (named by its file, as a frame's other errors)
    # kiss called directly with such times: no deskew rather than an aborted process
    scan = KittiOdometry(seq).read_scan(1)
    direct = get_icp("kiss")
    direct.register_frame(KittiOdometry(seq).read_scan(0).points_xyz, np.zeros(len(KittiOdometry(seq).read_scan(0).points_xyz)))
    assert np.isfinite(direct.register_frame(scan.points_xyz, scan.point_times_s)).all()


def test_deskew_off_or_not_offered_is_stated_without_a_warning(exported, tmp_path):
    seq = _copy(exported, tmp_path / "street_seq", "point_times")
    off = run(seq, "kiss", params={"deskew": False}, frames="0:3")
    assert off.metrics["effective"]["deskew"] == {**off.metrics["effective"]["deskew"], "requested": False, "applied": False}
    assert off.metrics["warnings"] == []
    scan_to_scan = run(seq, "vanilla", frames="0:3")
    assert scan_to_scan.metrics["effective"]["deskew"]["requested"] is None
    assert "does not deskew" in scan_to_scan.metrics["effective"]["deskew"]["reason"]


def test_what_the_reader_reports_applying_is_recorded_and_printed(exported, tmp_path, capsys):
    class CorrectedKitti(KittiOdometry):  # a reader that reports a correction it applied (as KITTI's angle fix)
        @property
        def reader_options(self):
            return {"vertical_correction": "auto", "vertical_correction_applied": True, "vertical_correction_deg": 0.205}

    result = run(CorrectedKitti(exported), "kiss", frames="0:3", out_dir=tmp_path / "run")
    effective = result.metrics["effective"]
    assert effective["corrections"] == {"vertical_correction": "auto", "vertical_correction_applied": True, "vertical_correction_deg": 0.205}
    assert effective["reader"]["point_times_dir"] == str(exported / "point_times")
    # paths recorded absolute (a run folder is read from anywhere), a file the reader did not find said to be absent
    import os
    import shutil

    shutil.copytree(exported, tmp_path / "copy")
    (tmp_path / "copy" / "times.txt").unlink()
    here = os.getcwd()
    try:
        os.chdir(tmp_path)
        reader = run(KittiOdometry("copy"), "vanilla", frames="0:2").metrics["effective"]["reader"]
    finally:
        os.chdir(here)
    assert reader["times_path"] == f"{tmp_path / 'copy' / 'times.txt'} (absent)" and reader["path"] == str(tmp_path / "copy")
    # a simulator export states its ground-truth instant (sim.yaml): the sweep end, where kiss deskews to
    assert effective["ground_truth_instant"] == "end" and effective["estimate_instant"] == "end"
    assert "vertical_correction_deg: 0.205" in (tmp_path / "run" / "config.yaml").read_text()
    sim = run("sim:street?frames=3&beams=8&azimuths=90", "kiss").metrics["effective"]
    assert (sim["ground_truth_instant"], sim["estimate_instant"]) == ("end", "end")  # deskewed to the sweep end, scored there


# ---- alignment of every score ---------------------------------------------------------------------------------
def _yawed_first_pose(seq: Path, yaw_deg: float) -> None:
    """Rotate the ground truth of frame 0 about z: anchoring at the first pose turns the whole reference (at every
    instant of the sweep the folder holds: a run re-timed to another reads its poses_{instant}.txt)."""
    c, s = np.cos(np.radians(yaw_deg)), np.sin(np.radians(yaw_deg))
    for name in ("poses.txt", *(p.name for p in seq.glob("poses_*.txt"))):
        poses = np.loadtxt(seq / name).reshape(-1, 3, 4)
        poses[0, :, :3] = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ poses[0, :, :3]
        np.savetxt(seq / name, poses.reshape(-1, 12), fmt="%.12e")


def test_every_score_names_its_alignment_in_cli_metrics_bench_table_and_report(exported, tmp_path, capsys):
    seq = _copy(exported, tmp_path / "street_seq", "point_times")
    _yawed_first_pose(seq, 3.0)
    out = tmp_path / "run"
    code, text, _ = _cli(["odometry", str(seq), "-m", "open3d_gicp", "--no-progress", "--out", str(out)], capsys)
    assert code == 0
    m = json.loads((out / "metrics.json").read_text())
    aligned, unaligned = m["ape_translation_se3_m"]["stats"]["rmse"], m["ape_translation_m"]["stats"]["rmse"]
    assert unaligned > 10 * aligned and aligned < 0.1  # a 3 deg first-pose yaw over a 12 m drive
    assert m["ape_translation_se3_m"]["alignment"] == "SE(3)-aligned" and m["ape_translation_se3_m"]["align"] == "se3"
    assert m["ape_translation_m"]["alignment"] == "unaligned, first pose anchored" and m["ape_translation_m"]["align"] == "none"
    assert "alignment-free" in m["rpe_translation_m"]["alignment"] and "alignment-free" in m["rpe_rotation_deg"]["alignment"]
    assert m["final_error"]["alignment"] == "unaligned, first pose anchored"
    flat = " ".join(text.split())
    assert f"APE translation RMSE, SE(3)-aligned (m) │ {aligned:.3f}" in flat
    assert f"APE translation RMSE, unaligned, first pose anchored (m) │ {unaligned:.3f}" in flat
    assert m["n_bad_frames"] == 0  # an accurate run: the independent check flags nothing

    from lidarkit.bench.report import build_report
    from lidarkit.bench.runner import run_suite
    from lidarkit.bench.suite import load_suite

    (tmp_path / "suite.yaml").write_text(textwrap.dedent(f"""
        name: alignment-labels
        seeds: [0]
        experiments:
          - name: odo
            task: odometry
            dataset: {{kind: kitti, path: "{seq}", name: yawed}}
            methods:
              - name: open3d_gicp
        """))
    run_suite(load_suite(tmp_path / "suite.yaml"), tmp_path / "bench", executor="serial")
    report = build_report(tmp_path / "bench", plots=False)
    (table,) = report.tables
    labels = {metric.name: metric.label for metric in table.metrics}
    assert labels["ape_se3_rmse_m"] == "APE RMSE (SE(3)-aligned) [m]"
    assert labels["ape_rmse_m"] == "APE RMSE (unaligned, first pose anchored) [m]"
    assert "alignment-free" in labels["rpe_trans_rmse_m"] and "alignment-free" in labels["rpe_rot_rmse_deg"]
    (row,) = table.rows
    assert row.stats["ape_rmse_m"][0] > 10 * row.stats["ape_se3_rmse_m"][0]
    assert row.stats["ape_se3_rmse_m"][0] == pytest.approx(aligned, rel=1e-6)
    html = report.html_path.read_text()
    markdown = report.markdown_path.read_text()
    for text_out in (html, markdown):
        assert "APE RMSE (SE(3)-aligned) [m]" in text_out and "APE RMSE (unaligned, first pose anchored) [m]" in text_out
    assert "APE RMSE (SE(3)-aligned) [m], methods x datasets" in markdown  # the aligned APE is the headline view


def test_the_rpe_of_a_frame_selection_that_skips_frames_is_labelled_over_one_selected_frame(tmp_path, capsys):
    """``--frames 1:10:3``: an RPE over 3 KITTI frames was labelled "1 frame" in the table, metrics.json and config.yaml
    (the bench task already said "1 selected frame")."""
    from conftest import shared_path

    out = tmp_path / "run"
    code, text, _ = _cli(["odometry", str(shared_path("kitti_odometry")), "--frames", "1:10:3", "-m", "small_gicp",
                          "--no-progress", "--out", str(out)], capsys)
    assert code == 0
    m = json.loads((out / "metrics.json").read_text())
    for key in ("rpe_translation_m", "rpe_rotation_deg"):
        assert m[key]["alignment"] == "relative over 1 selected frame, alignment-free"
    assert "rpe_translation_m: relative over 1 selected frame, alignment-free" in (out / "config.yaml").read_text()
    assert "RPE 1 selected frame RMSE" in " ".join(text.split())
    whole = run(f"kitti:{shared_path('kitti_odometry')}", "small_gicp", frames="1:5", progress=False)
    assert whole.metrics["rpe_translation_m"]["alignment"] == "relative over 1 frame, alignment-free"


def test_report_labels_metrics_with_the_alignment_their_records_state():
    from lidarkit.bench.report import MetricInfo, label_alignment

    def record(align):
        return {"info": {"metric_alignment": {"ape_rmse_m": align}}}

    ape = MetricInfo("ape_rmse_m", "APE RMSE [m]")
    assert label_alignment(ape, [record("sim3-aligned"), record("sim3-aligned")]).label == "APE RMSE (sim3-aligned) [m]"
    assert label_alignment(ape, [record("sim3-aligned"), record("unaligned")]).label == "APE RMSE (sim3-aligned / unaligned) [m]"
    assert label_alignment(ape, [{"info": {}}]).label == "APE RMSE [m]"  # nothing stated: nothing invented
    named = MetricInfo("ape_rmse_m", "APE RMSE (unaligned) [m]")
    assert label_alignment(named, [record("unaligned")]).label == "APE RMSE (unaligned) [m]"


# ---- the independent per-frame check --------------------------------------------------------------------------
def test_motion_check_thresholds_follow_the_stated_accelerations():
    cfg = FrameCheckConfig()
    n = 8
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, 0, 3] = np.arange(n) * 1.0  # 10 m/s at 10 Hz: constant velocity
    poses[5:, 0, 3] += 0.2  # frame 5 jumps 0.2 m ahead: 20 m/s^2 > 15 m/s^2 (limit 0.15 m at 0.1 s)
    dev_t, dev_r, dt = motion_deviation(poses, None, cfg)
    lim_t, lim_r = motion_limits(dt, cfg)
    assert np.isnan(dev_t[:2]).all() and np.allclose(lim_t[1:], 0.15) and np.allclose(lim_r[1:], 3.0)
    np.testing.assert_allclose(dev_t[2:], [0, 0, 0, 0.2, 0.2, 0], atol=1e-12)  # frame 6 stops jumping: a second deviation
    assert list(np.flatnonzero(dev_t > lim_t)) == [5, 6]
    times = np.arange(n) * 0.05  # a 20 Hz sensor: limits are 4x tighter, the deviation halves (velocity fixed)
    dev20, _, dt20 = motion_deviation(poses, times, cfg)
    lim20 = motion_limits(dt20, cfg)[0]
    assert np.allclose(lim20[1:], 15.0 * 0.05**2) and list(np.flatnonzero(dev20 > lim20)) == [5, 6]


def test_stamps_that_cannot_time_the_motion_leave_their_frames_unchecked():
    """Delivery stamps bunched 1 ms apart (Intel's CARMEN log) scaled the prediction by the interval ratio (0.2 s / 1 ms:
    200-fold) and failed correct frames of a steady 0.1 m a frame; those frames are now not checked for motion, and
    the frames around them, regularly timed, still are (and still catch a jump)."""
    from lidarkit.odometry.frame_check import MAX_INTERVAL_RATIO, MIN_INTERVAL_FRACTION

    n = 20
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, 0, 3] = 0.1 * np.arange(n)  # captured every 0.2 s at 0.5 m/s
    times = 0.2 * np.arange(n)
    times[8] = times[7] + 0.001  # delivered 1 ms after its predecessor
    poses[15:, 0, 3] += 1.0  # a real jump at frame 15 (25 m/s^2 over 0.2 s: limit 0.6 m)
    cfg = FrameCheckConfig()
    dev_t, _, dt = motion_deviation(poses, times, cfg)
    lim_t = motion_limits(dt, cfg)[0]
    assert MIN_INTERVAL_FRACTION == 0.25 and MAX_INTERVAL_RATIO == 4.0
    assert np.flatnonzero(np.isnan(dev_t)).tolist() == [0, 1, 8, 9]  # 8: 1 ms; 9: after it (ratio 199)
    assert list(np.flatnonzero(dev_t > lim_t)) == [15, 16]


def test_motion_prediction_follows_irregular_frame_intervals():
    """A constant speed and turn rate sampled at irregular times deviates nowhere from the prediction."""
    times = np.cumsum([0.0, 0.1, 0.3, 0.05, 0.2, 0.1, 0.4, 0.1])
    yaw, x = np.radians(30.0) * times, 10.0 * times  # a constant turn rate (30 deg/s) while sliding along x at 10 m/s
    poses = np.tile(np.eye(4), (len(times), 1, 1))
    poses[:, 0, 0], poses[:, 0, 1], poses[:, 1, 0], poses[:, 1, 1] = np.cos(yaw), -np.sin(yaw), np.sin(yaw), np.cos(yaw)
    poses[:, 0, 3] = x
    dev_t, dev_r, dt = motion_deviation(poses, times, FrameCheckConfig())
    np.testing.assert_allclose(dt[1:], np.diff(times))
    # the translation is no constant twist (it slides while turning): only the scaled rotation is checked here
    assert np.nanmax(dev_r) < 1e-9
    with pytest.raises(ConfigError, match="unknown setting.*max_accel"):
        make_frame_check(max_acel_mps2=3)
    with pytest.raises(ConfigError, match="min_fitness must be positive"):
        make_frame_check(min_fitness="-1")
    assert make_frame_check(max_angular_accel_dps2="500", n_sample="100") == FrameCheckConfig(max_angular_accel_dps2=500.0, n_sample=100)
    # settings under which no frame could be checked, or every frame fails, were accepted in silence
    for params, message in (({"n_sample": "20"}, "n_sample 20 is below min_points 50: no frame would be checked"),
                            ({"n_sample": "1.5"}, "n_sample must be a whole number"),
                            ({"max_target_points": "10"}, "max_target_points 10 is below min_points 50"),
                            ({"min_fitness": "1.5"}, "min_fitness is a share of the sampled points, at most 1"),
                            ({"max_accel_mps2": "inf"}, "max_accel_mps2 must be a finite number")):
        with pytest.raises(ConfigError, match=message):
            make_frame_check(**params)
    assert make_frame_check(n_sample="0", max_target_points="10") == FrameCheckConfig(n_sample=0, max_target_points=10)


def test_frame_check_booleans_are_refused_not_read_as_1(capsys):
    """``--check n_sample=true`` was read as 1 (True is 1 to float) and then refused as "n_sample 1 is below
    min_points"; a boolean is no number, refused as text is."""
    for text, value in (("true", "True"), ("false", "False")):
        with pytest.raises(ConfigError) as refused:
            make_frame_check(**parse_kv([f"n_sample={text}"], option="--check"))
        assert str(refused.value) == f"frame check: n_sample must be a number, got {value}"
    code, _, err = _cli(["odometry", "sim:open?frames=2", "-m", "vanilla", "--no-progress", "--check", "min_fitness=true"], capsys)
    assert code == 1 and err.strip() == "error: frame check: min_fitness must be a number, got True"


def test_frame_check_settings_given_to_run_are_checked_as_the_cli_checks_them():
    """``run(frame_check=FrameCheckConfig(...))`` skipped the CLI's checks: n_sample=-5 was a numpy traceback,
    min_fitness=2 failed every frame, a NaN limit turned its test off, all in silence."""
    from lidarkit.odometry import run

    for params, message in (({"n_sample": -5}, "n_sample must be >= 0"),
                            ({"min_fitness": 2}, "min_fitness is a share of the sampled points, at most 1"),
                            ({"max_angular_accel_dps2": float("nan")}, "max_angular_accel_dps2 must be a finite number"),
                            ({"nominal_period_s": 0}, "nominal_period_s must be positive"),
                            ({"seed": True}, "seed must be a number")):
        with pytest.raises(ConfigError, match=message):
            FrameCheckConfig(**params)
    spec = "sim:open?frames=4&beams=16&azimuths=360"
    with pytest.raises(ConfigError, match="frame_check must be a FrameCheckConfig or a mapping"):
        run(spec, "vanilla", frame_check="min_fitness=0.5")
    with pytest.raises(ConfigError, match="min_fitness is a share"):
        run(spec, "vanilla", frame_check={"min_fitness": 2})
    assert run(spec, "vanilla", frame_check={"min_fitness": "0.5"}).config["run"]["frame_check"]["min_fitness"] == 0.5


def test_independent_check_counts_the_bad_frames_of_a_drifting_variant_that_says_converged(tmp_path, capsys):
    spec = "sim:open?frames=25&beams=16&azimuths=360"
    out = tmp_path / "run"
    code, text, _ = _cli(["odometry", spec, "-m", "open3d_point_to_point", "--no-progress", "--out", str(out)], capsys)
    assert code == 0
    m = json.loads((out / "metrics.json").read_text())
    check = m["frame_check"]
    assert m["n_not_converged"] == 0  # the variant's own verdict: every frame converged
    assert m["ape_translation_se3_m"]["stats"]["rmse"] > 2.0  # ... while it drifts
    assert m["n_bad_frames"] == check["n_bad_frames"] >= 5
    assert check["n_said_converged_but_bad"] == check["n_bad_frames"]
    assert check["n_bad_motion"] + check["n_bad_fitness"] >= check["n_bad_frames"]
    assert check["thresholds"]["max_accel_mps2"] == 15.0 and check["thresholds"]["min_fitness"] == 0.3
    flat = " ".join(text.split())
    assert f"bad frames (independent check) │ {check['n_bad_frames']} of 25" in flat
    timing = (out / "timing.csv").read_text().splitlines()
    assert timing[0].endswith("point_times,motion_dev_m,rotation_dev_deg,fitness,check_failed,check_why")
    assert sum(line.split(",")[-2] == "1" for line in timing[1:]) == check["n_bad_frames"]

    # --check n_sample=0: no fitness test, the same motion test and poses
    lean = tmp_path / "lean"
    code, lean_text, _ = _cli(["odometry", spec, "-m", "open3d_point_to_point", "--no-progress", "--out", str(lean), "--check", "n_sample=0"], capsys)
    assert code == 0 and "fitness not checked)" in " ".join(lean_text.split())  # (it said "fitness 0")
    m0 = json.loads((lean / "metrics.json").read_text())
    check0 = m0["frame_check"]
    assert check0["n_fitness_checked"] == 0 and check0["n_bad_fitness"] == 0 and check0["fitness_median"] is None
    assert check0["n_motion_checked"] == check["n_motion_checked"] and check0["n_bad_motion"] == check["n_bad_motion"] > 0
    assert check0["thresholds"]["n_sample"] == 0
    np.testing.assert_array_equal(np.loadtxt(lean / "poses_kitti.txt"), np.loadtxt(out / "poses_kitti.txt"))
    with pytest.raises(ConfigError, match="n_sample must be >= 0"):
        make_frame_check(n_sample=-1)


def test_stateful_variants_are_checked_too(exported, tmp_path):
    seq = _copy(exported, tmp_path / "street_seq", "point_times")
    result = run(seq, "kiss")
    check = result.metrics["frame_check"]
    assert result.metrics["convergence_measured"] is False
    assert check["n_fitness_checked"] == 11 and check["n_motion_checked"] == 10
    assert check["n_said_converged_but_bad"] is None  # kiss gives no verdict to contradict
    assert np.isfinite(result.stats.fitness[1:]).all()


# ---- names, paths and docs -------------------------------------------------------------------------------------
def test_runs_are_titled_after_the_folder_or_name_and_print_the_full_run_folder(exported, tmp_path, capsys):
    deep = tmp_path / ("a_rather_long_folder_name_for_runs_" * 3) / "run"
    code, text, _ = _cli(["odometry", str(exported), "-m", "kiss", "--frames", "0:3", "--no-progress", "--out", str(deep)], capsys)
    assert code == 0
    assert "kiss on street_seq" in text and "kitti_00" not in text
    assert f"run folder: {deep.resolve()}" in text.splitlines()
    code, text, _ = _cli(["odometry", str(exported), "-m", "kiss", "--frames", "0:3", "--no-progress", "--name", "my drive"], capsys)
    assert code == 0 and "kiss on my drive" in text
    assert KittiOdometry(exported).name == "street_seq"


def test_docs_list_the_per_point_time_folders_the_reader_searches():
    datasets = (DOCS / "datasets.md").read_text()
    assert "### Per-point times" in datasets
    (line,) = [ln for ln in datasets.splitlines() if ln.startswith("Folders searched, in order")]
    assert tuple(re.findall(r"`([A-Za-z0-9_.-]+)/`", line.partition(":")[2])) == POINT_TIME_FOLDERS
    simulator = (DOCS / "simulator.md").read_text()
    assert "does not read `point_times/`" not in simulator
    assert "datasets.md#per-point-times" in simulator


def test_frame_check_fitness_is_the_exact_nearest_neighbour_fitness_as_with_small_gicp_s_tree():
    """The check's KD-tree (scipy's, built and queried with the GIL released) gives every sampled point its exact
    nearest distance: on consecutive KITTI scans and a few motions (right, off by 0.3 m, off by 2 m) the fitness is
    that of a brute-force search, and that of small_gicp's KdTree the check used before (when installed)."""
    from conftest import shared_path

    from lidarkit.geometry import make_se3
    from lidarkit.odometry import frame_check

    folder = shared_path("kitti_odometry", "sequences", "00", "velodyne")
    scans = [np.fromfile(folder / f"{i:06d}.bin", dtype=np.float32).reshape(-1, 4)[:, :3].astype(np.float64) for i in (0, 1)]
    cfg = FrameCheckConfig()
    motions = [make_se3(np.eye(3), t) for t in ([0.0, 0.0, 0.0], [0.3, 0.0, 0.0], [2.0, 0.0, 0.0])]
    previous, current = (frame_check.scan_geometry(s, cfg, k) for k, s in enumerate(scans))
    checked = [frame_check.scan_fitness(previous, current, T, cfg) for T in motions]

    def fitness_with(nearest) -> list[float]:  # the check's rule, its nearest distances from ``nearest(queries)``
        sample = current.sample_xyz
        tolerance = np.maximum(cfg.inlier_min_m, cfg.inlier_range_fraction * np.linalg.norm(sample, axis=1))
        return [float(np.mean(nearest(sample @ T[:3, :3].T + T[:3, 3]) < tolerance)) for T in motions]

    def brute_force(queries):
        target = previous.target_xyz
        return np.concatenate([np.sqrt(((q[:, None, :] - target[None]) ** 2).sum(-1).min(axis=1)) for q in np.array_split(queries, 30)])

    assert checked == fitness_with(brute_force)
    assert checked[0] > checked[2]  # the check does tell a wrong motion
    small_gicp = pytest.importorskip("small_gicp")
    tree = small_gicp.KdTree(previous.target_xyz, num_threads=1)
    assert checked == fitness_with(lambda q: np.sqrt(np.asarray(tree.batch_nearest_neighbor_search(q, num_threads=1)[1], dtype=np.float64)))


def test_kiss_with_every_point_cropped_is_an_error_not_a_still_trajectory(exported):
    """max_range_m below the sensor's minimum range: kiss-icp registers nothing and the estimate never moves (it
    passed every check); the first such sweep is a RegistrationError naming the ranges."""
    from lidarkit.errors import RegistrationError

    with pytest.raises(RegistrationError, match=r"\(frame 0\): kiss: no point of the sweep lies within \[0, 0.5\] m of the sensor"):
        run(exported, "kiss", params={"max_range_m": 0.5}, frames="0:3")


def test_progress_is_printed_as_lines_where_no_bar_can_be_drawn(exported, capsys):
    """stderr to a file or a pipe (a log, CI): a line at every tenth of the run instead of a bar that never shows."""
    with pytest.raises(SystemExit) as exc:
        main(["odometry", str(exported), "-m", "small_gicp"])
    assert exc.value.code == 0
    lines = [line for line in capsys.readouterr().err.splitlines() if " frames (" in line]
    assert 8 <= len(lines) <= 11 and lines[-1].startswith("small_gicp on street_seq: 12/12 frames (100 %)")
    assert re.search(r"\d+\.\d frames/s, ~\d+ s left$", lines[0])
    with pytest.raises(SystemExit):
        main(["odometry", str(exported), "-m", "small_gicp", "--frames", "0:5", "--no-progress"])
    assert " frames (" not in capsys.readouterr().err


def test_registration_time_counts_the_frames_registered():
    """A scan-to-scan chain's frame 0 is never registered: its 0 s was in the mean (10 % low over 10 frames)."""
    from lidarkit.odometry import odometry_metrics, run

    result = run("sim:open?frames=4&beams=16&azimuths=360", "vanilla")
    times = result.stats.register_s
    assert times[0] == 0.0 and (times[1:] > 0).all()
    assert odometry_metrics(result)["register_time_s"]["mean"] == pytest.approx(times[1:].mean())
    single = run("sim:open?frames=1&beams=16&azimuths=360", "vanilla")
    assert odometry_metrics(single)["register_time_s"] == {"mean": None, "median": None, "max": None}


def test_frame_stats_repr_says_what_metrics_say_of_registration_time_and_degeneracy():
    """repr(stats) averaged frame 0's 0 s into the registration time ("0.124 s a frame" where register_time_s.mean said
    0.165 s) and read "0 degenerate" for kiss, whose n_degenerate is null (no verdict)."""
    spec = "sim:street?frames=3&beams=8&azimuths=180"

    def expected(result, degenerate: str) -> str:
        m = result.metrics
        return (f"FrameStats(3 frames: {m['n_constant_velocity_fallback']} fallback, {degenerate}, {m['n_bad_frames']} failing the "
                f"check, registration {m['register_time_s']['mean']:.3g} s a frame; to_csv() for every frame)")

    chain = run(spec, "vanilla")
    assert chain.stats.register_s[0] == 0.0 and chain.metrics["register_time_s"]["mean"] == pytest.approx(chain.stats.register_s[1:].mean())
    assert repr(chain.stats) == expected(chain, f"{chain.metrics['n_degenerate']} degenerate")
    stateful = run(spec, "kiss")
    assert stateful.metrics["n_degenerate"] is None and repr(stateful.stats) == expected(stateful, "degenerate n/a")
    unassessed = run(spec, "small_gicp", params={"assess": False})
    assert unassessed.metrics["n_degenerate"] is None and repr(unassessed.stats) == expected(unassessed, "degenerate n/a")
    single = run("sim:street?frames=1&beams=8&azimuths=180", "vanilla")  # nothing registered: no time, no verdict
    assert repr(single.stats) == "FrameStats(1 frames: 0 fallback, degenerate n/a, 0 failing the check; to_csv() for every frame)"


def test_ground_truth_given_as_an_array_is_refused_before_the_run():
    from lidarkit.odometry import run

    with pytest.raises(ConfigError, match="ground_truth must be a lidarkit Trajectory .* got ndarray"):
        run("sim:open?frames=3&beams=16&azimuths=360", "vanilla", ground_truth=np.tile(np.eye(4), (3, 1, 1)))


def test_the_library_checks_its_run_folder_before_the_work(tmp_path):
    """run(out_dir=...) with a file in the way ran the whole sequence and then failed, its result lost; it is refused
    before the first frame, as the CLI's --out."""
    from lidarkit.errors import OutputError
    from lidarkit.odometry import run

    (tmp_path / "afile").write_text("x")
    calls = []

    class Counted:
        name = "counted"

        def __len__(self):
            return 3

        def read_scan(self, index):
            calls.append(index)
            raise AssertionError("read before the output was checked")

    with pytest.raises(OutputError, match="afile: cannot create the folder: a file is in the way"):
        run(Counted(), "vanilla", out_dir=tmp_path / "afile" / "run")
    assert calls == []


def test_an_empty_run_folder_is_refused(tmp_path, monkeypatch):
    """run(out_dir="") wrote the run into the current folder (Path("") is "."; the CLI refuses -o ""): refused before
    the first frame, naming out_dir."""
    monkeypatch.chdir(tmp_path)
    for empty in ("", "  "):
        with pytest.raises(ConfigError) as refused:
            run("sim:open?frames=3&beams=16&azimuths=360", "vanilla", out_dir=empty)
        assert str(refused.value) == "out_dir: empty path: give a folder ('.' for the current one)"
    assert list(tmp_path.iterdir()) == []


def test_poses_without_stamps_are_stamped_with_their_frame_numbers(tmp_path):
    """Scans without stamps: poses_tum.txt was stamped 0, 1, 2 for --frames 4:10:2 while timing.csv said frames 4, 6, 8
    (the docs: frame numbers when there are none)."""
    from conftest import shared_path

    from lidarkit.odometry import run
    from lidarkit.trajectory import Trajectory

    run(shared_path("kitti_odometry", "sequences", "00", "velodyne"), "small_gicp", frames="4:10:2", out_dir=tmp_path / "run")
    tum = Trajectory.from_tum(tmp_path / "run" / "poses_tum.txt")
    frames = np.loadtxt(tmp_path / "run" / "timing.csv", delimiter=",", skiprows=1, usecols=0)
    np.testing.assert_array_equal(tum.timestamps_s, [4.0, 6.0, 8.0])
    np.testing.assert_array_equal(frames, [4, 6, 8])


def test_scans_without_stamps_time_the_motion_check_by_their_frame_numbers(tmp_path):
    """KITTI scans 0, 1, 2, 9 without stamps: the check timed every interval as one nominal period, so frame 9, registered
    right (fitness 0.85), failed for motion (4.64 m off the prediction of a 0.1 s step). Timed by the frame numbers it is
    7 periods after frame 2, too unlike the previous interval to time the motion: left unchecked, as with stamps."""
    from conftest import shared_path

    velodyne = tmp_path / "gap" / "velodyne"
    velodyne.mkdir(parents=True)
    for frame in (0, 1, 2, 9):
        shutil.copy(shared_path("kitti_odometry", "sequences", "00", "velodyne", f"{frame:06d}.bin"), velodyne)
    result = run(tmp_path / "gap", "small_gicp")
    assert result.metrics["n_bad_frames"] == 0
    assert np.isfinite(result.stats.motion_dev_m[2]) and np.isnan(result.stats.motion_dev_m[3])
    assert result.stats.fitness[3] > 0.8
    assert "largest 7 frames between frames 2 and 9" in result.metrics["warnings"][0]


def test_bad_frames_cut_at_100_in_metrics_says_how_many_it_left_out(monkeypatch):
    """metrics.json listed the first 100 bad frames only, with nothing to say the list was cut (the limit lowered to 5
    here: 104 frames took 5 s)."""
    from lidarkit.odometry import metrics

    monkeypatch.setattr(metrics, "MAX_BAD_FRAMES_LISTED", 5)
    result = run("sim:open?frames=9&beams=16&azimuths=180", "vanilla", frame_check={"min_fitness": 1.0})
    check = result.metrics["frame_check"]
    assert check["n_bad_frames"] > 5 and len(check["bad_frames"]) == 5
    assert check["n_bad_frames_not_listed"] == check["n_bad_frames"] - 5
    assert run("sim:open?frames=4&beams=16&azimuths=180", "vanilla").metrics["frame_check"]["n_bad_frames_not_listed"] == 0


def test_a_two_frame_run_says_motion_not_checked_and_why_there_is_no_se3_ape(capsys):
    """With 2 frames the table read "motion 0" though no motion was checked, and the SE(3)-aligned APE row "-" without
    the reason (metrics.json had none either)."""
    from conftest import shared_path

    kitti = shared_path("kitti_odometry", "sequences", "00")
    code, text, _ = _cli(["odometry", str(kitti), "-m", "small_gicp", "--frames", "0:2", "--no-progress"], capsys)
    assert code == 0
    flat = " ".join(text.split())
    assert "bad frames (independent check) │ 0 of 2 (motion not checked, fitness 0)" in flat
    assert "APE translation RMSE, SE(3)-aligned (m) │ no SE(3)-aligned APE: a rigid fit needs 3 poses, the run has 2" in flat


def test_a_one_frame_run_is_unscored_with_a_note(tmp_path, capsys):
    """A one-frame run over a recording with ground truth printed "final error, unaligned 0.000 / 0.000" as if scored:
    its one pose is the start of both trajectories. It runs unscored with a note, as a one-sweep recording did."""
    note = "none: one frame, nothing to score (its pose is the start, where the estimate and the ground truth both begin)"
    single = run("sim:open?frames=3&beams=16&azimuths=360", "vanilla", frames="2:3")
    assert single.ground_truth is None and "final_error" not in single.metrics and "ape_translation_m" not in single.metrics
    assert single.metrics["ground_truth_note"] == note and single.config["run"]["ground_truth"] is None
    code, out, _ = _cli(["odometry", "sim:open?frames=3&beams=16&azimuths=360", "-m", "vanilla", "--frames", "2:3",
                         "--no-progress", "--out", str(tmp_path / "run")], capsys)
    assert code == 0 and f"ground truth │ {note}" in " ".join(out.split()) and "final error" not in out
    assert not (tmp_path / "run" / "ground_truth_kitti.txt").exists()
    assert "final_error" in run("sim:open?frames=3&beams=16&azimuths=360", "vanilla", frames="1:3").metrics  # two frames: scored


def _kitti_scans(folder: Path, n: int = 3) -> Path:
    """``folder`` holding KITTI sequence 00's first ``n`` scans and, as poses_kitti.txt, their ground truth."""
    from conftest import shared_path

    folder.mkdir(parents=True)
    for frame in range(n):
        shutil.copy(shared_path("kitti_odometry", "sequences", "00", "velodyne", f"{frame:06d}.bin"), folder)
    lines = shared_path("kitti_odometry", "poses", "00.txt").read_text().splitlines()[:n]
    (folder / "poses_kitti.txt").write_text("\n".join(lines) + "\n")
    return folder


def test_a_run_folder_that_would_replace_an_input_of_the_dataset_is_refused(tmp_path, capsys, monkeypatch):
    """`-o g` over `folder:g?poses=g/poses_kitti.txt` replaced the ground truth with the estimate (exit 0) and the next
    run scored "final error 0.000 / 0.000"; a KITTI layout's poses_file= went the same way. Refused before the work,
    naming the file (a folder that never held a run, as a folder of other files named like a run's); the library
    names out_dir."""
    monkeypatch.chdir(tmp_path)
    g = _kitti_scans(tmp_path / "g")
    truth = (g / "poses_kitti.txt").read_bytes()
    code, printed, err = _cli(["odometry", "folder:g?poses=g/poses_kitti.txt", "-m", "small_gicp", "-o", "g", "--no-progress"], capsys)
    assert code == 1 and printed == "" and "error: g: holds files named like a run's (poses_kitti.txt)" in err
    assert (g / "poses_kitti.txt").read_bytes() == truth
    # a folder that holds a run, its poses scored against: r/poses_kitti.txt is an input
    code, _, _ = _cli(["odometry", "folder:g?poses=g/poses_kitti.txt", "-m", "small_gicp", "-o", "r", "--no-progress"], capsys)
    estimate = (tmp_path / "r" / "poses_kitti.txt").read_bytes()
    assert code == 0 and estimate != truth
    code, printed, err = _cli(["odometry", "folder:g?poses=r/poses_kitti.txt", "-m", "small_gicp", "-o", "r", "--no-progress"], capsys)
    assert code == 1 and printed == ""
    assert err == ("error: --out: r/poses_kitti.txt is an input of the dataset (its poses_path): a run never replaces it; "
                   "give another folder\n")
    kt = tmp_path / "kt"
    (kt / "velodyne").mkdir(parents=True)
    for scan in g.glob("*.bin"):
        shutil.copy(scan, kt / "velodyne")
    code, _, err = _cli(["odometry", "kitti:kt?poses_file=r/poses_kitti.txt", "-m", "small_gicp", "-o", "r", "--no-progress"], capsys)
    assert code == 1 and err == ("error: --out: r/poses_kitti.txt is an input of the dataset (its poses_path): a run never "
                                 "replaces it; give another folder\n")
    with pytest.raises(ConfigError) as refused:
        run("folder:g?poses=r/poses_kitti.txt", "small_gicp", out_dir=tmp_path / "r")
    assert str(refused.value) == (f"out_dir: {tmp_path}/r/poses_kitti.txt is an input of the dataset (its poses_path): a "
                                  "run never replaces it; give another folder")
    assert (tmp_path / "r" / "poses_kitti.txt").read_bytes() == estimate



def test_write_run_refuses_to_replace_an_input_the_result_records(tmp_path, monkeypatch):
    """run(out_dir="r") over folder:g?poses=r/poses_kitti.txt was refused, but write_run(result, "r") of the same run
    replaced r/poses_kitti.txt (the reference) with the estimate, and the next run scored 3e-16 against itself. The
    result's recorded reader settings are refused the same way; another folder is written."""
    from lidarkit.odometry import write_run

    monkeypatch.chdir(tmp_path)
    _kitti_scans(tmp_path / "g", n=2)
    write_run(run("folder:g", "small_gicp"), "r")  # (unscored: no plots to draw)
    reference = (tmp_path / "r" / "poses_kitti.txt").read_bytes()
    scored_against_r = run("folder:g?poses=r/poses_kitti.txt", "small_gicp")
    with pytest.raises(ConfigError) as refused:
        write_run(scored_against_r, "r")
    assert str(refused.value) == ("out_dir: r/poses_kitti.txt is an input of the dataset (its poses_path): a run never "
                                  "replaces it; give another folder")
    assert (tmp_path / "r" / "poses_kitti.txt").read_bytes() == reference
    assert write_run(scored_against_r, "r2") == Path("r2") and (tmp_path / "r2" / "poses_kitti.txt").read_bytes() != reference

def test_an_unknown_initial_guess_names_the_option(capsys):
    """`--init odom` said "error: init: unknown initial guess 'odom'", the library's name, where other commands name
    their option."""
    code, _, err = _cli(["odometry", "sim:open?frames=3&beams=16&azimuths=360", "--init", "odom", "--no-progress"], capsys)
    assert code == 1 and err == "error: --init: unknown initial guess 'odom'; known: constant_velocity, odometry\n"


def test_a_folder_of_a_users_own_files_under_run_file_names_is_refused(tmp_path, capsys):
    """`lidarkit odometry SEQ -o proj` into a folder holding the user's own config.yaml and metrics.json (never a run)
    replaced both with exit 0, where the docs said other files stay. Refused before the work, naming them."""
    from conftest import shared_path

    proj = tmp_path / "proj"
    proj.mkdir()
    (proj / "config.yaml").write_text("lr: 0.1\n")
    (proj / "metrics.json").write_text("notes\n")
    kitti = str(shared_path("kitti_odometry", "sequences", "00"))
    code, printed, err = _cli(["odometry", kitti, "-m", "small_gicp", "--frames", "0:3", "-o", str(proj), "--no-progress"], capsys)
    assert code == 1 and printed == ""
    assert err == (f"error: {proj}: holds files named like a run's (config.yaml, metrics.json) but no config.yaml "
                   "written by lidarkit (the user's own, or a run cut off before it was complete): a run would replace "
                   "them; remove them or give a new or empty folder\n")
    assert (proj / "config.yaml").read_text() == "lr: 0.1\n" and (proj / "metrics.json").read_text() == "notes\n"
    (proj / "config.yaml").unlink()
    (proj / "metrics.json").unlink()
    for _ in range(2):  # an empty folder, then the run it holds: written
        code, _, _ = _cli(["odometry", kitti, "-m", "small_gicp", "--frames", "0:3", "-o", str(proj), "--no-progress"], capsys)
        assert code == 0 and "lidarkit_version" in (proj / "config.yaml").read_text()


def test_a_long_run_name_keeps_the_trajectory_plot_laid_out(tmp_path):
    """A 300-character --name ran trajectory.png's title off the figure, laid the legend (the name again) over the plot
    and printed matplotlib's "constrained_layout not applied" UserWarning; the title is wrapped and cut at 4 lines."""
    import warnings

    name = "long run name " * 22
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the layout warning fails the test
        result = run("sim:open?frames=3&beams=16&azimuths=360", "vanilla", name=name, out_dir=tmp_path / "run")
    assert result.trajectory.name == f"vanilla on {name}"  # the run keeps its full title; the figure a wrapped one
    assert (tmp_path / "run" / "trajectory.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_nominal_period_unused_for_a_dataset_with_stamps_is_a_warning():
    """`--check nominal_period_s=1` was accepted and recorded but did nothing on a dataset with time stamps, without a
    word (stateful variants get one for their unused min_fitness). Scans without stamps use it: no warning there."""
    from conftest import shared_path

    stamped = run("sim:open?frames=3&beams=16&azimuths=360", "vanilla", frame_check={"nominal_period_s": 1})
    assert stamped.config["run"]["frame_check"]["nominal_period_s"] == 1.0
    assert stamped.metrics["warnings"] == ["nominal_period_s=1: the frame check's period for scans without time stamps; "
                                           "this dataset has them, so it is not used"]
    assert run("sim:open?frames=3&beams=16&azimuths=360", "vanilla").metrics["warnings"] == []
    unstamped = run(shared_path("kitti_odometry", "sequences", "00", "velodyne"), "small_gicp", frames="0:3",
                    frame_check={"nominal_period_s": 1})
    assert not any("nominal_period_s" in w for w in unstamped.metrics["warnings"])


@pytest.mark.parametrize("method", ["small_gicp", "open3d_gicp"])
def test_a_run_without_assessment_says_degeneracy_not_assessed(method, tmp_path, capsys):
    """With assess=False the table read "not converged / degenerate │ 0 / 0", metrics.json n_degenerate 0 and timing.csv
    degenerate 0 (beside correspondences -1, RMSE nan) on every frame, though no frame's degeneracy was assessed; now
    "n/a" / null, as for a stateful variant (kiss) that gives no verdict."""
    out = tmp_path / "run"
    code, text, _ = _cli(["odometry", "sim:street?frames=4&beams=16&azimuths=360", "-m", method, "-p", "assess=false",
                          "--out", str(out), "--no-progress"], capsys)
    assert code == 0
    assert re.search(r"not converged / degenerate \(variant's verdict\) +│ 0 / n/a \(not assessed: assess=False\)", text)
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["n_degenerate"] is None and metrics["n_not_converged"] == 0 and metrics["convergence_measured"] is True
    rows = [line.split(",") for line in (out / "timing.csv").read_text().splitlines()]
    columns = {name: [row[i] for row in rows[1:]] for i, name in enumerate(rows[0])}
    assert columns["converged"] == ["n/a", "1", "1", "1"]  # the backend's own verdict, kept
    for name in ("rmse_m", "n_correspondences", "degenerate", "min_eigenvalue"):
        assert columns[name] == ["n/a"] * 4
    stateful = run("sim:street?frames=4&beams=16&azimuths=360", "kiss", params={"assess": False})
    assert stateful.metrics["n_degenerate"] is None  # the same word for the same lack of verdict
    assessed = run("sim:street?frames=4&beams=16&azimuths=360", method)
    assert assessed.metrics["n_degenerate"] == 0 and "n/a" not in assessed.stats.to_csv().splitlines()[2].split(",")[6:10]


def test_pose_covariance_file_states_only_the_per_pose_convention(tmp_path):
    """pose_covariance.txt's header also gave the "per frame (relative): ..." convention, though the file holds one
    row per pose and no per-frame covariance."""
    from lidarkit.odometry import run

    run("sim:street?frames=3&seed=4&beams=16&azimuths=360", "small_gicp", out_dir=tmp_path / "run")  # (a stateless variant: covariances by default)
    lines = (tmp_path / "run" / "pose_covariance.txt").read_text().splitlines()
    assert lines[0] == ("# one row per pose: its 6x6 covariance, row-major; left perturbation in the world frame, "
                        "T_true = se3_exp(xi) @ T_world_lidar, xi = (tx, ty, tz, rx, ry, rz) in m and rad")
    assert len(lines) == 1 + 3 and all(len(line.split()) == 36 for line in lines[1:])


def test_the_trajectory_plot_of_a_run_is_a_top_view(tmp_path, monkeypatch):
    """trajectory.png took the two axes the ground truth spreads most along: x-z on a straight drive over flat ground
    (no sideways or vertical truth motion), which hid the estimate's sideways drift. It is the x-y plane of the LiDAR
    frame (z up), as the docs say."""
    from lidarkit.eval import plots

    drawn = []
    draw = plots._draw_trajectories

    def labelled(ax, *args, **kwargs):
        draw(ax, *args, **kwargs)
        drawn.append((ax.get_xlabel(), ax.get_ylabel()))

    monkeypatch.setattr(plots, "_draw_trajectories", labelled)
    straight = "sim:street?frames=8&beams=8&azimuths=180&seed=1&max_curvature_per_m=0&sway_deg=0&heave_m=0&accel_time_s=0"
    result = run(straight, "vanilla", out_dir=tmp_path / "run")
    assert drawn == [("x (m)", "y (m)")]
    assert plots.choose_plane(result.ground_truth, "auto") == "xz"  # what the plot showed
    assert np.ptp(result.trajectory.positions_xyz[:, 1]) > 0.1  # the sideways drift (0.17 m) now in view
