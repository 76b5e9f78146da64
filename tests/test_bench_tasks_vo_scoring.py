"""The bench ``vo`` task: ground-truth scale on a dataset without poses, runs too short to score, the RPE's label."""

from __future__ import annotations

import textwrap

import numpy as np
import pytest
from conftest import shared_path

from lidarkit.bench.jobs import Job
from lidarkit.bench.suite import load_suite
from lidarkit.bench.worker import execute_job
from lidarkit.errors import ConfigError

pytest.importorskip("lidarkit.vo")


def write(tmp_path, text):
    path = tmp_path / "suite.yaml"
    path.write_text(textwrap.dedent(text))
    return path


def test_ground_truth_scale_on_a_dataset_without_poses_is_refused_at_load(tmp_path):
    """report_sift (scale.mode gt by default) on KITTI image sequence 00, which has no pose file: the suite loaded and
    every job failed "scale mode 'gt' needs a ground-truth trajectory", exit 0."""
    seq00 = shared_path("kitti_images", "sequences", "00")
    path = write(tmp_path, f"""
        experiments:
          - task: vo
            dataset: {{kind: kitti, path: "{seq00}", name: K00img}}
            methods: [lidarkit, report_sift]
        """)
    with pytest.raises(ConfigError) as info:
        load_suite(path)
    assert str(info.value) == (
        f"{path} (experiments[0].methods[1], line 5): report_sift scales each step by the ground truth (scale.mode gt, "
        "the preset's default) and the dataset K00img has no ground-truth poses: give the dataset its poses, or the "
        "method params {scale.mode: relative} (or none)")
    path.write_text(path.read_text().replace("report_sift]", "{name: lidarkit, params: {scale.mode: gt}}]"))
    with pytest.raises(ConfigError, match=r"methods\[1\], line 5\): lidarkit scales each step by the ground truth "
                                          r"\(scale.mode gt, its params\) and the dataset K00img has no"):
        load_suite(path)
    path.write_text(path.read_text().replace("scale.mode: gt", "scale.mode: relative"))
    assert len(load_suite(path).jobs) == 2
    seq06 = shared_path("kitti_images", "sequences", "06")  # (with its poses.txt: gt scale loads)
    path.write_text(path.read_text().replace(str(seq00), str(seq06)).replace("relative", "gt"))
    assert len(load_suite(path).jobs) == 2


def test_a_vo_run_of_two_frames_is_ok_without_accuracy_metrics_and_says_why():
    """max_frames: 2 passed validation, then every job failed "se3 alignment needs at least 3 poses": scored as `lidarkit
    vo` scores it, the job is ok, has no APE / RPE, and its warning says why."""
    seq06 = shared_path("kitti_images", "sequences", "06")
    job = Job("vo", "e", "K06", {"kind": "kitti", "path": str(seq06)}, "lidarkit", {"scale.mode": "gt"}, seed=0,
              options={"max_frames": 2})
    record = execute_job(job.spec())
    assert record["status"] == "ok", record["error"]
    assert "ape_rmse_m" not in record["metrics"] and "rpe_trans_rmse_m" not in record["metrics"]
    assert record["metrics"]["n_frames"] == 2
    assert any(message.endswith("lidarkit(scale.mode=gt) on K06: 2 pose(s) from the first estimated frame on; APE and "
                                "RPE need 3; the job has no accuracy metric") for message in record["warnings"]), record["warnings"]
    assert record["info"]["ground_truth_note"] == "2 pose(s) from the first estimated frame on; APE and RPE need 3"



def test_the_rpe_label_of_a_vo_job_says_what_its_alignment_does_to_it(tmp_path, rng):
    """Ground-truth scale: the RPE column read "SE(3)-aligned" where `lidarkit vo` names no alignment for the same
    number; a rigid alignment cancels in every relative pose, so it is the unaligned RPE: "1 frame, alignment-free", as the
    odometry task labels it. Under Sim(3) (relative scale) the alignment's scale scales it, and the label says so."""
    import csv

    from lidarkit.bench import build_report, run_suite
    from lidarkit.bench.results import load_results

    path = write(tmp_path, """
        experiments:
          - task: vo
            dataset: {kind: sim_camera, n_frames: 4, width: 320, height: 120, name: cam}
            methods: [{name: lidarkit, params: {scale.mode: gt}}, {name: lidarkit, params: {scale.mode: relative}}]
        """)
    out = tmp_path / "out"
    summary = run_suite(load_suite(path), out, executor="serial")
    assert (summary.ran, summary.ok) == (2, 2)
    by_mode = {r["job"]["params"]["scale.mode"]: r for r in load_results(out)}
    assert by_mode["gt"]["info"]["metric_alignment"] == {
        "ape_rmse_m": "SE(3)-aligned", "rpe_trans_rmse_m": "1 frame, alignment-free", "final_error_m": "SE(3)-aligned"}
    assert by_mode["relative"]["info"]["metric_alignment"]["rpe_trans_rmse_m"] == "1 frame, Sim(3)-aligned"
    build_report(out, plots=False)
    with open(out / "report.csv", newline="") as f:
        rows = {(r["method"], r["metric"]): r["alignment"] for r in csv.DictReader(f)}
    assert rows[("lidarkit(scale.mode=gt)", "rpe_trans_rmse_m")] == "1 frame, alignment-free"
    assert rows[("lidarkit(scale.mode=relative)", "rpe_trans_rmse_m")] == "1 frame, Sim(3)-aligned"

    # what the task's scoring computes (score_vo, as `lidarkit vo`): under SE(3) the unaligned RPE, under Sim(3) not
    from lidarkit.eval import rpe
    from lidarkit.geometry import se3_exp
    from lidarkit.trajectory import Trajectory
    from lidarkit.vo.evaluation import score_vo

    truth = Trajectory.from_kitti(shared_path("kitti_images", "sequences", "06", "poses.txt"))[:20]
    noisy = np.array([T @ se3_exp(rng.normal(0.0, 0.02, 6)) for T in truth.poses_se3])
    est = Trajectory(noisy)
    unaligned = rpe(truth, est, delta=1, delta_unit="frames", align="none").rmse
    assert score_vo(est, truth, "gt").metrics["rpe_trans_rmse_m"] == pytest.approx(unaligned, rel=1e-9)
    scaled = noisy.copy()
    scaled[:, :3, 3] *= 0.7  # (a monocular run's scale)
    shrunk = Trajectory(scaled)
    shrunk_unaligned = rpe(truth, shrunk, delta=1, delta_unit="frames", align="none").rmse
    assert score_vo(shrunk, truth, "relative").metrics["rpe_trans_rmse_m"] < 0.5 * shrunk_unaligned
