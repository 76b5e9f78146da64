"""MonoVO end to end on synthetic renders: exact ground truth, every bad-input case, determinism."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from lidarkit.errors import ConfigError, DataError
from lidarkit.eval import ape
from lidarkit.geometry import make_se3, so3_exp
from lidarkit.sim.camera import default_K, forward_trajectory, make_plane_scene, render_sequence
from lidarkit.trajectory import Trajectory
from lidarkit.vo import MonoVO, VOConfig, preset


@pytest.fixture(scope="module")
def scene():
    return make_plane_scene(np.random.default_rng(11))


@pytest.fixture(scope="module")
def sim(scene):
    traj = forward_trajectory(7)
    K = default_K()
    return traj, K, render_sequence(scene, traj, K)


def _cfg(mode="gt", **changes):
    return VOConfig().updated(**{"scale.mode": mode, **changes})


def _finite(result):
    return np.all(np.isfinite(result.trajectory.poses_se3))


@pytest.mark.parametrize("mode,align,tol_m", [("gt", "se3", 0.01), ("relative", "sim3", 0.01), ("none", "sim3", 0.01)])
def test_pipeline_recovers_synthetic_trajectory(sim, mode, align, tol_m):
    traj, K, images = sim
    result = MonoVO(_cfg(mode), K, traj if mode == "gt" else None).run(images)
    assert len(result.trajectory) == len(images) and not result.rejected
    assert ape(traj, result.trajectory, align=align).rmse < tol_m
    if mode == "relative":  # one global scale: the steps keep the true ratios (constant speed here)
        steps = np.linalg.norm(np.diff(result.trajectory.positions_xyz, axis=0), axis=1)
        true = np.linalg.norm(np.diff(traj.positions_xyz, axis=0), axis=1)
        ratio = steps / true
        assert ratio.std() / ratio.mean() < 0.02


def test_gt_mode_needs_ground_truth_and_K(sim):
    traj, K, images = sim
    with pytest.raises(ConfigError, match="needs a ground-truth"):
        MonoVO(_cfg("gt"), K)
    with pytest.raises(ConfigError, match="intrinsics K are required"):
        MonoVO(_cfg("none"), None)
    with pytest.raises(DataError, match="ground truth has 3 poses"):
        MonoVO(_cfg("gt"), K, traj[:3]).run(images)


class _Failing:
    """ImageSequence stand-in whose frames in ``bad`` raise DataError like an unreadable file."""

    name = "failing"

    def __init__(self, images, bad):
        self.images, self.bad = images, set(bad)

    def __len__(self):
        return len(self.images)

    def read_image(self, i):
        if i in self.bad:
            raise DataError("cannot decode image (corrupt or unsupported format)", source=f"img{i}.png")
        return self.images[i]


def _check_rejected(result, frame, text):
    d = result.diagnostics[frame]
    assert not d.accepted and text in d.reason, d.reason
    assert _finite(result)
    after = result.diagnostics[frame + 1]
    assert after.accepted and after.ref_frame == frame - 1  # matched against the last good frame
    return d


def test_unreadable_and_missing_images_are_rejected_with_reason(sim):
    traj, K, images = sim
    result = MonoVO(_cfg(), K, traj).run(_Failing(images, {3}))
    _check_rejected(result, 3, "unreadable image")
    missing = list(images)
    missing[3] = None
    _check_rejected(MonoVO(_cfg(), K, traj).run(missing), 3, "unreadable image (missing)")
    # the next frame, estimated over the gap, is still accurate
    assert ape(traj, MonoVO(_cfg(), K, traj).run(missing).trajectory, align="se3").rmse < 0.05


def test_first_frame_unreadable_is_a_clear_error(sim):
    traj, K, images = sim
    with pytest.raises(DataError, match="first frame cannot be used"):
        MonoVO(_cfg("none"), K).run(_Failing(images, {0}))


def test_image_of_different_size_is_rejected(sim):
    traj, K, images = sim
    bad = list(images)
    bad[3] = cv2.resize(images[3], (320, 240))
    _check_rejected(MonoVO(_cfg(), K, traj).run(bad), 3, "image size 320x240 differs from the sequence's 640x480")


@pytest.mark.parametrize("name,reason", [("lidarkit", "too few matches"), ("report_orb", "too few features")])
def test_black_frame_is_rejected(sim, name, reason):
    traj, K, images = sim
    bad = list(images)
    bad[3] = np.zeros_like(images[3])
    result = MonoVO(preset(name, **{"scale.mode": "gt"}), K, traj).run(bad)
    _check_rejected(result, 3, reason)


def test_too_few_features_in_first_frame_moves_the_reference(sim):
    traj, K, images = sim
    bad = list(images)
    bad[0] = np.full_like(images[0], 128)
    cv2.circle(bad[0], (320, 240), 40, 255, -1)  # a few corners at most
    result = MonoVO(_cfg("none"), K).run(bad)
    assert "too few" in result.diagnostics[1].reason
    assert result.diagnostics[1].note == "reference moved to this frame"
    assert all(d.accepted for d in result.diagnostics[2:]) and _finite(result)


def test_pure_rotation_pair_is_rejected(scene):
    K = default_K()
    poses = [np.eye(4), make_se3(so3_exp(np.radians([0.0, 2.0, 0.0])), np.zeros(3)),
             make_se3(so3_exp(np.radians([0.0, 2.0, 0.0])), np.array([0.0, 0.0, 0.5]))]
    traj = Trajectory(np.array(poses))
    images = render_sequence(scene, traj, K)
    result = MonoVO(_cfg("none"), K).run(images)
    assert "insufficient parallax" in result.diagnostics[1].reason and "pure rotation" in result.diagnostics[1].reason
    assert result.diagnostics[2].accepted and result.diagnostics[2].ref_frame == 0
    assert _finite(result)


def test_without_sanity_checks_failures_still_never_give_nan(sim):
    traj, K, images = sim
    bad = list(images)
    bad[2] = np.zeros_like(images[2])
    result = MonoVO(_cfg("none", **{"sanity.enabled": False}), K).run(bad)
    assert not result.diagnostics[2].accepted and _finite(result)


@pytest.mark.parametrize("name", ["lidarkit", "report_orb"])
def test_two_runs_are_identical(sim, name):
    traj, K, images = sim
    cfg = preset(name, **{"scale.mode": "relative"})
    a = MonoVO(cfg, K).run(images)
    b = MonoVO(cfg, K).run(images)
    assert np.array_equal(a.trajectory.poses_se3, b.trajectory.poses_se3)
    assert [d.n_inliers for d in a.diagnostics] == [d.n_inliers for d in b.diagnostics]


def test_lost_tracking_moves_the_reference_instead_of_cascading(sim):
    """After 'too few matches' on a frame that has features of its own, the next frame is matched against it."""
    traj, K, images = sim
    bad = list(images)
    bad[3] = np.ascontiguousarray(np.flipud(images[3]))  # textured, but unrelated to its neighbours
    result = MonoVO(_cfg("none"), K).run(bad)
    d3 = result.diagnostics[3]
    assert not d3.accepted and d3.note == "reference moved to this frame"
    assert result.diagnostics[4].ref_frame == 3 and _finite(result)
