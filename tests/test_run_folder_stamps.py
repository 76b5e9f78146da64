"""poses_tum.txt of a run over a recording without time stamps: stamped as timing.csv counts frames, paired by eval."""

from __future__ import annotations

import numpy as np
from fake_kitti import write_fake_kitti_sequence

from lidarkit import eval as leval
from lidarkit.odometry import run
from lidarkit.trajectory import Trajectory


def test_a_run_without_stamps_is_stamped_with_dataset_indices_that_eval_pairs(tmp_path):
    """KITTI files 8, 9, 10 and 94 (no times.txt): the gap warning names the recording's numbers (10 and 94) while
    poses_tum.txt and timing.csv count the dataset's frames 0-3 (docs/odometry.md, Run folder); eval pairs the TUM poses
    with ground_truth_kitti.txt pose by pose, as the KITTI ones."""
    seq = write_fake_kitti_sequence(tmp_path / "root", "00", 12, range_m=15.0)
    (seq / "times.txt").unlink()
    (seq / "velodyne" / "000011.bin").rename(seq / "velodyne" / "000094.bin")
    for k in range(8):
        (seq / "velodyne" / f"{k:06d}.bin").unlink()
    poses = (tmp_path / "root" / "poses" / "00.txt").read_text().splitlines()
    (tmp_path / "root" / "poses" / "00.txt").write_text("\n".join(poses + poses[-1:] * 83) + "\n")  # rows up to 94
    result = run(f"kitti:{tmp_path / 'root'}?sequence=00", "small_gicp", out_dir=tmp_path / "out")
    assert any("between frames 10 and 94" in w for w in result.metrics["warnings"]), result.metrics["warnings"]
    tum = Trajectory.from_tum(tmp_path / "out" / "poses_tum.txt")
    timing = np.loadtxt(tmp_path / "out" / "timing.csv", delimiter=",", skiprows=1, usecols=0)
    np.testing.assert_array_equal(tum.timestamps_s, [0, 1, 2, 3])
    np.testing.assert_array_equal(timing, [0, 1, 2, 3])
    truth = Trajectory.from_kitti(tmp_path / "out" / "ground_truth_kitti.txt")
    by_tum = leval.ape(truth, tum, align="se3", relation="translation")
    by_kitti = leval.ape(truth, Trajectory.from_kitti(tmp_path / "out" / "poses_kitti.txt"), align="se3", relation="translation")
    assert len(by_tum.errors) == 4 and np.allclose(by_tum.errors, by_kitti.errors, atol=1e-6)
