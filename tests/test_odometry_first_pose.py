"""The first frame of a pipeline run deskewed to the sweep's start or middle: registered with no motion known, its
pose is at its sweep's end, and the run restates it at the reference instant once the second frame gives the motion
(left at the end, the start run anchored one sweep ahead of its other poses: 1.049 m at the end of 12 simulated
sweeps at 10 m/s, where the end run has 0.096 m)."""

from __future__ import annotations

import numpy as np
import pytest

from lidarkit.geometry import se3_exp, se3_inverse, se3_log
from lidarkit.odometry import open_sequence, run
from lidarkit.registration import get_icp
from lidarkit.trajectory import Trajectory

STREET = "sim:street?frames=40&beams=16&azimuths=360&seed=4"


def _deskewed_to(reference: str) -> dict:
    return {"deskew": {"name": "constant_velocity", "deskew": True, "reference": reference}}


@pytest.mark.parametrize("reference, before_m", [("start", 1.049), ("middle", 0.527)])
def test_a_run_reported_at_the_sweep_start_or_middle_restates_its_first_pose(tmp_path, reference, before_m):
    """Frame 1's pose was the identity at the start (the start of sweep 1 is the end of sweep 0, where frame 0 was
    reported); the final error is now near the end run's (0.229 m at the start, 0.143 m at the middle)."""
    result = run(STREET, "pipeline", params=_deskewed_to(reference), frames="25:37", out_dir=tmp_path / "run")
    assert result.metrics["final_error"]["translation_m"] < 0.3 < before_m
    poses = Trajectory.read(tmp_path / "run" / "poses_kitti.txt", "kitti").poses_se3
    assert np.allclose(poses[0], np.eye(4), atol=1e-9)  # the run still starts at the identity
    assert np.linalg.norm(poses[1][:3, 3]) > 0.5  # one sweep at 10 m/s: about 1 m, not the identity
    assert any("frame 25: its pose" in w and f"sweep's {reference}" in w for w in result.metrics["warnings"])


def test_the_pipeline_restates_the_first_pose_from_the_second_frames_motion():
    """pipeline.restated_first_pose: None at the end and after the first frame; at the start, the first pose moved back
    by the second frame's motion (end to end), at the middle by half of it."""
    sim = open_sequence(STREET)
    scans = [sim.read_scan(k) for k in (25, 26)]
    for reference, part in (("end", None), ("middle", 0.5), ("start", 1.0)):
        icp = get_icp("pipeline", **_deskewed_to(reference))
        icp.reset()
        icp.register_frame(scans[0].points_xyz, scans[0].point_times_s)
        assert icp.restated_first_pose is None
        icp.register_frame(scans[1].points_xyz, scans[1].point_times_s)
        if part is None:
            assert icp.restated_first_pose is None
            continue
        expected = se3_inverse(se3_exp(part * se3_log(icp.last_delta)))  # from the identity, frame 0's end pose
        assert np.allclose(icp.restated_first_pose, expected, atol=1e-9)
        assert np.linalg.norm(icp.restated_first_pose[:3, 3]) > 0.3
