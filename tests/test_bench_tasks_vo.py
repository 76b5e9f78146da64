"""The bench ``vo`` task on awkward inputs: unreadable first images, TUM folders without intrinsics."""

from __future__ import annotations

import shutil

import numpy as np
import pytest
from conftest import shared_path

from lidarkit.bench.jobs import Job
from lidarkit.bench.worker import execute_job

vo = pytest.importorskip("lidarkit.vo")


def _kitti06_with_bad_first_image(tmp_path, n_frames=10):
    """KITTI 06 frames 0..n-1 as one sequence folder whose first image is not a PNG."""
    src = shared_path("kitti_images", "sequences", "06")
    seq = tmp_path / "seq"
    (seq / "image_0").mkdir(parents=True)
    for i in range(1, n_frames):
        shutil.copy(src / "image_0" / f"{i:06d}.png", seq / "image_0" / f"{i:06d}.png")
    (seq / "image_0" / "000000.png").write_bytes(b"garbage\n")
    shutil.copy(src / "calib.txt", seq / "calib.txt")
    for name in ("poses.txt", "times.txt"):
        rows = (src / name).read_text().splitlines()[:n_frames]
        (seq / name).write_text("\n".join(rows) + "\n")
    return seq


def test_vo_job_scores_from_the_first_estimated_frame_as_the_cli(tmp_path):
    from lidarkit.io import open_dataset

    seq = _kitti06_with_bad_first_image(tmp_path)
    job = Job("vo", "e", "kcor", {"kind": "kitti", "path": str(seq)}, "lidarkit", {"scale.mode": "gt"}, seed=0)
    record = execute_job(job.spec())
    assert record["status"] == "ok", record["error"]
    assert record["info"]["scored_from_frame"] == 1
    # the CLI's score: frames 1.. of the same run against frames 1.. of the ground truth
    images = open_dataset("kitti", seq).as_image_sequence()
    result = vo.run_vo(vo.images_in_memory(images), images.K, vo.preset("lidarkit", **{"scale.mode": "gt", "seed": 0}),
                       ground_truth=images.ground_truth, timestamps_s=images.timestamps_s)
    assert result.meta["start_frame"] == 1
    tail = np.arange(1, len(images))
    expected = vo.evaluate_vo(result.trajectory[tail], images.ground_truth[tail], "gt")
    assert record["metrics"]["ape_rmse_m"] == pytest.approx(expected["ape_rmse_m"], rel=1e-9)
    assert record["metrics"]["ape_rmse_m"] < 0.05  # (frame 0 scored with frame 1's pose: 0.29 m)
    assert len(record["series"]["error_over_time"]["error"]) == len(images) - 1


def _tum_folder(folder, n_frames=3):
    """A small TUM RGB-D folder (rgb.txt, rgb/, groundtruth.txt) of KITTI 06's first images."""
    src = shared_path("kitti_images", "sequences", "06", "image_0")
    (folder / "rgb").mkdir(parents=True)
    stamps = 1000.0 + 0.1 * np.arange(n_frames)
    for i, t in enumerate(stamps):
        shutil.copy(src / f"{i:06d}.png", folder / "rgb" / f"{t:.6f}.png")
    (folder / "rgb.txt").write_text("# color images\n" + "".join(f"{t:.6f} rgb/{t:.6f}.png\n" for t in stamps))
    (folder / "groundtruth.txt").write_text("".join(f"{t:.6f} {0.5 * i} 0 0 0 0 0 1\n" for i, t in enumerate(stamps)))
    return folder


def test_a_tum_dataset_without_intrinsics_is_refused_with_the_suite(tmp_path):
    from lidarkit.bench.suite import load_suite
    from lidarkit.errors import ConfigError

    _tum_folder(tmp_path / "tum06")
    _tum_folder(tmp_path / "rgbd_dataset_freiburg1_xyz")
    suite = tmp_path / "suite.yaml"
    text = """
experiments:
  - task: vo
    dataset: {{kind: tum, path: {folder}{extra}}}
    methods: [lidarkit]
"""
    suite.write_text(text.format(folder="tum06", extra=""))
    with pytest.raises(ConfigError, match=r"TUM folder .*tum06 names no freiburg camera.*give the dataset's K: option \(3x3\)") as info:
        load_suite(suite)
    assert "experiments[0].dataset" in str(info.value) and "\n" not in str(info.value)
    # its K given, or a folder naming its freiburg camera: accepted
    suite.write_text(text.format(folder="tum06", extra=", K: [[700, 0, 600], [0, 700, 180], [0, 0, 1]]"))
    load_suite(suite)
    suite.write_text(text.format(folder="rgbd_dataset_freiburg1_xyz", extra=""))
    load_suite(suite)
