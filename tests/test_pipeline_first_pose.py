"""The first two sweeps of a pipeline run deskewed to the sweep's start or middle: both are deskewed with no motion known
and fit each other at one instant, so both are restated alike (the middle run restated the first alone: its first
step read 1.49 m for a true 1.00 m on the 32 x 1024 street)."""

from __future__ import annotations

import numpy as np
import pytest

from lidarkit.geometry import se3_inverse
from lidarkit.odometry import run
from lidarkit.trajectory import Trajectory

STREET_32 = "sim:street?frames=40&beams=32&azimuths=1024&seed=4"
#: Half a sweep at 10 m/s: how far the instant the first two sweeps refer to may lie from the one they are taken at.
HALF_SWEEP_M = 0.5


def _run(tmp_path, reference: str) -> tuple[float, float, float]:
    """``(first step, true first step, final error)`` of a pipeline run deskewed to ``reference`` (m)."""
    out = tmp_path / reference
    result = run(STREET_32, "pipeline", params={"deskew": {"name": "constant_velocity", "reference": reference}},
                 frames="25:31", out_dir=out)
    poses = Trajectory.read(out / "poses_kitti.txt", "kitti").poses_se3
    truth = Trajectory.read(out / "ground_truth_kitti.txt", "kitti").poses_se3
    true_step = float(np.linalg.norm((se3_inverse(truth[0]) @ truth[1])[:3, 3]))
    return float(np.linalg.norm(poses[1][:3, 3])), true_step, result.metrics["final_error"]["translation_m"]


@pytest.fixture(scope="module")
def end_run(tmp_path_factory):
    return _run(tmp_path_factory.mktemp("end"), "end")


@pytest.mark.parametrize("reference", ["start", "middle"])
def test_the_first_step_of_a_start_or_middle_run_is_the_registered_one(tmp_path, end_run, reference):
    step, true_step, final_m = _run(tmp_path, reference)
    assert abs(true_step - 1.0) < 0.01  # one sweep at 10 m/s
    assert abs(step - true_step) < 0.1
    assert step == pytest.approx(end_run[0], abs=0.01)  # the end run's first step: frames 25 and 26 register alike
    assert final_m < end_run[2] + HALF_SWEEP_M  # (one sweep ahead, the start run ended 1.05 m off)
