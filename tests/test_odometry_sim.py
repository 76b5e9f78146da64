"""Simulated sequences through lidarkit.odometry: deskew matters when scored at the matching instant.

Test-suite size: 300 sweeps of 32 x 720 rays (the benchmark runs 64 x 2000); motion distortion and 2 cm range
noise on, street scene, ground truth at the sweep end (kiss-icp deskews to the end of the sweep).
"""

from __future__ import annotations

import pytest

from lidarkit.odometry import run
from lidarkit.sim.lidar import SimulatedLidarSequence


@pytest.mark.slow
def test_kiss_with_deskew_beats_kiss_without_on_a_distorted_street():
    seq = SimulatedLidarSequence(scene="street", n_frames=300, n_beams=32, n_azimuths=720, range_noise_std_m=0.02, seed=0)
    assert seq.config.motion_distortion and seq.config.pose_instant == "end"
    with_deskew = run(seq, "kiss", params={"deskew": True})
    without = run(seq, "kiss", params={"deskew": False})
    drift_with = with_deskew.metrics["kitti_drift"]["translation_pct"]
    drift_without = without.metrics["kitti_drift"]["translation_pct"]
    assert with_deskew.ground_truth.length_m > 280.0  # long enough for the 100 and 200 m devkit segments
    assert drift_with < drift_without
    assert drift_with < 1.0  # and kiss tracks the street well (measured 0.37 % vs 0.51 % without deskew)
