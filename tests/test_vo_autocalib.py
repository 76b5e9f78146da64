"""Focal length self-calibration (lidarkit.vo.autocalib): within 5 % on KITTI, and a fallback with a reason when
the motion cannot constrain f."""

from __future__ import annotations

import numpy as np
import pytest

from lidarkit.errors import ConfigError
from lidarkit.geometry import make_se3, so3_exp
from lidarkit.sim.camera import default_K, make_plane_scene
from lidarkit.vo.autocalib import AutocalibConfig, estimate_focal

_SIZE = (640, 480)
_GUESS = 0.9 * 640


def _render(poses):
    K = default_K(_SIZE, 500.0)
    scene = make_plane_scene(np.random.default_rng(0))
    return [scene.render(T, K, _SIZE) for T in poses]


def test_no_motion_falls_back_to_the_size_guess():
    images = _render([np.eye(4)] * 8)
    est = estimate_focal(images, AutocalibConfig(window=4, stride=4))
    assert not est.constrained
    assert est.focal_px == pytest.approx(_GUESS) and est.sigma_px == float("inf")
    assert "translation parallax" in est.reason and "guess" in est.describe()
    assert est.K(*_SIZE)[0, 0] == pytest.approx(_GUESS)
    images[5] = None  # an unreadable frame skips its window instead of raising
    assert not estimate_focal(images, AutocalibConfig(window=4, stride=4)).constrained


def test_pure_rotation_falls_back_to_the_size_guess():
    poses = [make_se3(so3_exp(np.radians([0.3 * k, 1.5 * k, 0.1 * k])), np.zeros(3)) for k in range(8)]
    est = estimate_focal(_render(poses), AutocalibConfig(window=4, stride=4))
    assert not est.constrained and est.windows == 0
    assert "no motion or pure rotation" in est.reason


def test_too_short_sequence_falls_back_and_bad_window_is_refused():
    assert "a window needs 5" in estimate_focal(_render([np.eye(4)] * 3)).reason
    with pytest.raises(ConfigError, match="window"):
        estimate_focal(_render([np.eye(4)] * 3), AutocalibConfig(window=2))


@pytest.mark.slow
@pytest.mark.parametrize("sequence", ["01", "06"])
def test_kitti_focal_within_5_percent(kitti_vo_frames, sequence):
    """KITTI 01 (curve) and 06 (almost straight), frames 0-50, no intrinsics: the estimate is within 5 % of the
    calibration (measured -2.7 % / +3.6 %); before the plain-then-robust adjustment it was -5.9 % on 01 and a
    fallback on 06, so the tolerance can fail."""
    images, K, _ = kitti_vo_frames(sequence)
    est = estimate_focal(images)
    assert est.constrained, est.reason
    assert est.focal_px == pytest.approx(K[0, 0], rel=0.05)
    assert 0 < est.sigma_px < 0.1 * est.focal_px and est.windows >= 3


def test_one_window_of_frames_falls_back():
    """Five frames hold one 5-frame window (KITTI 00's excerpt): not enough to compare windows."""
    poses = [make_se3(np.eye(3), np.array([0.05 * k, 0.0, 0.5 * k])) for k in range(5)]
    est = estimate_focal(_render(poses))
    assert not est.constrained and "one window" in est.reason


@pytest.mark.slow
def test_simulated_street_corner_focal_within_5_percent():
    """A 51-frame simulated drive through a street corner (``first_corner_m``), principal point at the image centre
    (the method's assumption): the estimate is within 5 % of the simulator's focal length (measured -0.2 % on seed 1, seeds 0-2 in
    benchmarks/results/vo_autocalib); with 5-frame windows only it was +7.5 % on seed 1."""
    from lidarkit.sim.street_camera import SimulatedCameraSequence

    seq = SimulatedCameraSequence(n_frames=51, seed=1, first_corner_m=15.0, cx=None, cy=None)
    heading = np.degrees(np.arccos(np.clip(seq.ground_truth.poses_se3[-1][2, 2], -1.0, 1.0)))
    assert heading > 30.0  # the drive really turns
    est = estimate_focal(seq)
    assert est.constrained, est.reason
    assert est.focal_px == pytest.approx(seq.K[0, 0], rel=0.05)
    assert 0 < est.sigma_px < 0.1 * est.focal_px
