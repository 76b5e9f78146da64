"""The bench ``vo`` task: ground-truth scale on a dataset without poses, and runs too short to score."""

from __future__ import annotations

import textwrap

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
