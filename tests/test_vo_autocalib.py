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
    est = estimate_focal(images, workers=2)  # (the pool: the same estimate as one process, in less time)
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
    est = estimate_focal(seq, workers=2)
    assert est.constrained, est.reason
    assert est.focal_px == pytest.approx(seq.K[0, 0], rel=0.05)
    assert 0 < est.sigma_px < 0.1 * est.focal_px


def _exit_in_a_worker(parent_pid: int) -> str:
    """A pool job that kills the worker it runs in (not the test process)."""
    import os

    if os.getpid() != parent_pid:
        os._exit(1)
    return "ran in the parent"


@pytest.mark.slow
def test_the_windows_adjusted_by_workers_give_the_in_process_estimate(kitti_vo_frames):
    """The windows' grid sweeps run on a process pool as the next windows are tracked: the same profile, window minima
    and estimate bit for bit as in this process (KITTI 06 frames 0-9: two windows, each adjusted)."""
    images = kitti_vo_frames("06")[0][:10]
    cfg = AutocalibConfig(grid_steps=3)
    alone, pooled = (estimate_focal(images, cfg, workers=w) for w in (1, 2))
    assert alone.windows == 2 and len(alone.profile) == 3 and np.all(np.isfinite(list(alone.profile.values())))
    assert pooled == alone


def test_a_bad_worker_count_is_refused():
    with pytest.raises(ConfigError, match="workers: must be >= 1, got 0"):
        estimate_focal(_render([np.eye(4)] * 8), workers=0)


@pytest.mark.slow
def test_an_interrupt_stops_the_workers(kitti_vo_frames):
    """Ctrl-C while the workers adjust the windows: it reaches the caller and no worker outlives the call."""
    import multiprocessing

    images = kitti_vo_frames("06")[0][:10]
    running = []

    def on_step(done: int, total: int) -> None:
        if done == total // 2:  # every window tracked, its adjustment queued
            running.extend(multiprocessing.active_children())
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        estimate_focal(images, AutocalibConfig(grid_steps=3), on_step=on_step, workers=2)
    assert running and not any(p.is_alive() for p in running) and not multiprocessing.active_children()


def test_a_broken_pool_leaves_its_jobs_to_this_process(caplog):
    """A worker that dies (killed, or a script without ``if __name__ == "__main__":`` whose workers cannot start)
    breaks the pool: its jobs run in this process instead, with a warning."""
    import os

    from lidarkit.vo.autocalib import _WindowPool

    with _WindowPool(workers=2, jobs=2) as pool:
        pool.submit(_exit_in_a_worker, os.getpid())
        pool.submit(_exit_in_a_worker, os.getpid())
        assert sorted(pool.results()) == [(0, "ran in the parent"), (1, "ran in the parent")]
    assert any("a worker process died or could not start" in r.getMessage() for r in caplog.records)
