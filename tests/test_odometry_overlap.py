"""Frame k's assessment overlapped with frame k+1's registration: the same results as the pair-by-pair definition,
the speculative guess redone when the acceptance gate turns a frame down, errors named and no thread left behind."""

from __future__ import annotations

import logging
import threading

import numpy as np
import pytest
from conftest import shared_path

from lidarkit.errors import RegistrationError
from lidarkit.geometry import orthonormalize_se3
from lidarkit.odometry import run
from lidarkit.odometry.frame_check import FrameChecker
from lidarkit.registration import available_icp, get_icp

SPEC = f"kitti:{shared_path('kitti_odometry')}?sequence=00"
#: single-threaded backends are bit-reproducible: the overlapped run must then equal the definition exactly
EXACT = 1e-12
_THREADS = ("lidarkit-assess", "lidarkit-prefetch", "lidarkit-assessment-prep")

needs_small_gicp = pytest.mark.skipif("small_gicp" not in available_icp(), reason="small_gicp not installed")


def _our_threads() -> list[str]:
    return [t.name for t in threading.enumerate() if t.name.startswith(_THREADS)]


@pytest.fixture(scope="module")
def scans():
    from lidarkit.odometry.inputs import open_sequence

    sequence = open_sequence(SPEC)
    return [sequence.read_scan(i).points_xyz for i in range(len(sequence))]


def _pair_by_pair(scans, method: str, params: dict):
    """The definition: ``align`` frame after frame from the previous motion (kept when a frame is not converged)."""
    icp = get_icp(method, **params)
    poses, motion, results = [np.eye(4)], np.eye(4), [None]
    for k in range(1, len(scans)):
        result = icp.align(scans[k], scans[k - 1], init_T=motion)
        if result.converged:
            motion = orthonormalize_se3(np.asarray(result.T_target_source))
        poses.append(poses[-1] @ motion)
        results.append(result)
    checker = FrameChecker(len(scans))
    for k, points in enumerate(scans):
        checker.add(k, k, points, None, np.stack(poses))
    return np.stack(poses), results, checker.fitness


def _assert_same_as_definition(out, scans, method: str, params: dict) -> int:
    poses, results, check_fitness = _pair_by_pair(scans, method, params)
    np.testing.assert_allclose(out.trajectory.poses_se3, poses, rtol=0, atol=EXACT)
    relative_cov = out.covariances[0]
    for k in range(1, len(scans)):
        r = results[k]
        assert out.stats.converged[k] == r.converged
        assert out.stats.n_correspondences[k] == r.n_correspondences
        assert out.stats.degenerate[k] == r.degeneracy.degenerate
        assert out.stats.min_eigenvalue[k] == pytest.approx(r.degeneracy.eigenvalues[0], rel=EXACT, abs=0)
        assert out.stats.rmse_m[k] == pytest.approx(r.rmse, rel=EXACT, abs=0)
        if r.converged:
            np.testing.assert_allclose(relative_cov[k], r.covariance, rtol=EXACT, atol=EXACT * np.abs(r.covariance).max())
        else:
            assert np.isnan(relative_cov[k]).all()
    np.testing.assert_allclose(out.stats.fitness, check_fitness, rtol=0, atol=EXACT)
    return int((~out.stats.converged[1:]).sum())


def _overlapped(method: str, params: dict):
    """The variant with its assessment overlapped (small_gicp runs in line by default: its backend holds the GIL)."""
    icp = get_icp(method, **params)
    icp.overlap_assessment = True
    return icp


@needs_small_gicp
def test_overlapped_run_equals_the_pair_by_pair_definition(scans):
    params = {"num_threads": 1}
    out = run(SPEC, _overlapped("small_gicp", params))
    assert _assert_same_as_definition(out, scans, "small_gicp", params) == 0
    assert not _our_threads()


@needs_small_gicp
def test_a_frame_the_gate_turns_down_is_followed_by_a_registration_from_the_right_guess(scans, caplog):
    # KITTI pairs score fitness 0.96-0.995: a gate at 0.98 turns some frames down after small_gicp said "converged",
    # so the speculative guess of the next frame is wrong there and that frame must be registered again
    params = {"num_threads": 1, "min_fitness": 0.98}
    with caplog.at_level(logging.WARNING):
        out = run(SPEC, _overlapped("small_gicp", params))
    turned_down = _assert_same_as_definition(out, scans, "small_gicp", params)
    assert 0 < turned_down < len(scans) - 1  # some of each
    assert not out.stats.converged[1:-1].all()


def test_overlapped_open3d_run_equals_the_definition_to_rounding(scans):
    # Open3D's parallel reductions change the last bits from run to run (~1e-14 m): equal to far below any effect
    out = run(SPEC, "open3d_point_to_plane")
    poses, results, check_fitness = _pair_by_pair(scans, "open3d_point_to_plane", {})
    np.testing.assert_allclose(out.trajectory.poses_se3, poses, rtol=0, atol=1e-9)
    for k in range(1, len(scans)):
        np.testing.assert_allclose(out.covariances[0][k], results[k].covariance, rtol=1e-6, atol=1e-6 * np.abs(results[k].covariance).max())
        assert out.stats.min_eigenvalue[k] == pytest.approx(results[k].degeneracy.eigenvalues[0], rel=1e-6)
    np.testing.assert_allclose(out.stats.fitness, check_fitness, rtol=0, atol=1e-3)  # 1 of 1500 sample points


def test_stateful_overlap_equals_the_in_line_calls():
    # kiss-icp itself is not bit-reproducible run to run (~1e-15 m): the after-the-fact work done in the worker is
    # compared with the same calls made in line on the run's own poses
    from lidarkit.odometry.inputs import open_sequence
    from lidarkit.odometry.runner import frame_covariance

    sequence = open_sequence(SPEC)
    sequence.configure_for_method("kiss")  # the scans as the run reads them for kiss (KITTI's vertical-angle correction)
    scans = [sequence.read_scan(i).points_xyz for i in range(len(sequence))]

    from lidarkit.registration.kiss import KissRegistration

    class OverlappedKiss(KissRegistration):
        overlap_assessment = True  # kiss runs its after-the-fact work in line (it holds the GIL): the worker path, forced

    assert get_icp("kiss").overlap_assessment is False
    for variant in ("kiss", OverlappedKiss()):
        out = run(SPEC, variant, pose_covariance=True)
        poses = out.trajectory.poses_se3
        checker = FrameChecker(len(scans))
        for k, points in enumerate(scans):
            checker.add(k, k, points, None, poses)
            if k:
                cov, min_eig = frame_covariance(scans[k - 1], points, poses[k - 1], poses[k], "kiss")
                np.testing.assert_array_equal(out.covariances[0][k], cov)
                assert out.stats.min_eigenvalue[k] == min_eig
        np.testing.assert_array_equal(out.stats.fitness, checker.fitness)
        assert np.isfinite(out.covariances[0][1:]).all()
        assert not _our_threads()


class _Failing:
    """Wraps a variant: its registration (or its assessment) of the ``fail_at``-th pair raises."""

    def __init__(self, inner, fail_at: int, where: str, error: BaseException):
        self.inner, self.fail_at, self.where, self.error, self.calls = inner, fail_at, where, error, 0
        self.name, self.config, self.stateful = inner.name, inner.config, False

    def align_deferred(self, source, target, init_T=None):
        self.calls += 1
        if self.calls == self.fail_at and self.where == "register":
            raise self.error
        pending = self.inner.align_deferred(source, target, init_T)
        if self.calls == self.fail_at and self.where == "assess":
            error = self.error

            def fail():
                raise error

            pending._finish = fail
        return pending

    def align(self, source, target, init_T=None):
        return self.align_deferred(source, target, init_T).result()


@pytest.mark.parametrize("where", ["register", "assess"])
def test_an_error_names_its_frame_and_leaves_no_thread(where):
    failing = _Failing(get_icp("open3d_point_to_plane"), fail_at=4, where=where, error=RuntimeError("backend refused"))
    with pytest.raises(RegistrationError, match="frame 4"):
        run(SPEC, failing)
    assert not _our_threads()


@pytest.mark.parametrize("where", ["register", "assess"])
def test_an_interrupt_leaves_no_thread_and_writes_nothing(where, tmp_path):
    failing = _Failing(get_icp("open3d_point_to_plane"), fail_at=3, where=where, error=KeyboardInterrupt())
    with pytest.raises(KeyboardInterrupt):
        run(SPEC, failing, out_dir=tmp_path / "run")
    assert not _our_threads()
    assert list(tmp_path.iterdir()) == []  # no run folder, not even a partial one


def test_a_subclass_overriding_align_keeps_its_override(scans):
    import dataclasses

    from lidarkit.registration.open3d_icp import Open3DPointToPlane

    class Shifted(Open3DPointToPlane):  # post-processes the split variant's result in _align
        def _align(self, source_xyz, target_xyz, init_T):
            result = super()._align(source_xyz, target_xyz, init_T)
            T = result.T_target_source.copy()
            T[0, 3] += 1.0
            return dataclasses.replace(result, T_target_source=T)

    plain = Open3DPointToPlane().align(scans[1], scans[0]).T_target_source
    pending = Shifted().align_deferred(scans[1], scans[0])
    assert pending.T_target_source[0, 3] == pytest.approx(plain[0, 3] + 1.0, abs=1e-9)
    assert pending.result().T_target_source[0, 3] == pytest.approx(plain[0, 3] + 1.0, abs=1e-9)
    assert Shifted().align(scans[1], scans[0]).T_target_source[0, 3] == pytest.approx(plain[0, 3] + 1.0, abs=1e-9)


def test_a_subclass_moving_the_pose_in_register_but_not_in_its_assessment_is_refused(scans):
    from lidarkit.registration.open3d_icp import Open3DPointToPlane

    class Shifted(Open3DPointToPlane):  # moves the pose and keeps the parent's assessment (at the parent's pose)
        def _register(self, source_xyz, target_xyz, init_T):
            T, converged, assess = super()._register(source_xyz, target_xyz, init_T)
            T = T.copy()
            T[0, 3] += 1.0
            return T, converged, assess

    with pytest.raises(RegistrationError, match="_register returned a pose that its assess"):
        Shifted().align(scans[1], scans[0])
    with pytest.raises(RegistrationError, match="assess\\(\\) must score the pose"):
        run(SPEC, Shifted(), frames="0:3")
    assert not _our_threads()


def test_points_checked_once_are_trusted_only_inside_the_block_and_only_by_identity():
    from lidarkit.errors import DataError
    from lidarkit.geometry import as_points, validated_points

    checked = np.zeros((10, 3))
    bad = np.full((10, 3), np.nan)  # stands for an array changed after its check: only the registered object is trusted
    with validated_points({id(bad): bad}):
        assert as_points(bad) is bad
        with pytest.raises(DataError):
            as_points(bad.copy())  # same content, another object: checked
        with pytest.raises(DataError):
            as_points(bad, min_points=11)  # the point count is still enforced
    with pytest.raises(DataError):
        as_points(bad)  # outside the block: checked
    assert as_points(checked) is checked


def test_the_run_checks_each_scan_in_its_reading_thread_not_again_in_the_registration(monkeypatch):
    import lidarkit.geometry as geometry

    calls = []
    original = geometry._reach_within_limits

    def counting(arr):
        calls.append(threading.current_thread().name)
        return original(arr)

    monkeypatch.setattr(geometry, "_reach_within_limits", counting)
    run(SPEC, "open3d_point_to_plane")
    in_main = [name for name in calls if name == threading.main_thread().name]
    assert len(calls) >= 10 and not in_main  # the reader's and the run's checks, all in the reading thread


def _spy_on_fitness(monkeypatch, fail_at: int | None = None, error: BaseException | None = None) -> list[str]:
    """The names of the threads the check's fitness queries run in, one per call; the ``fail_at``-th call raises ``error``."""
    from lidarkit.odometry import frame_check

    real, where = frame_check.scan_fitness, []

    def spy(*args, **kwargs):
        where.append(threading.current_thread().name)
        if len(where) == fail_at:
            raise error
        return real(*args, **kwargs)

    monkeypatch.setattr(frame_check, "scan_fitness", spy)
    return where


def test_the_checks_queries_run_beside_a_variant_kept_in_line_with_the_fitness_of_the_check_in_line(monkeypatch):
    """kiss keeps its after-the-fact work in line (overlap_assessment=False): the frame check's nearest-neighbour
    queries run in a thread of the checker's own while the next frame registers, and on the 10 real KITTI scans give
    exactly the fitness (and flagged frames) of the check made in line, and the same poses."""
    from lidarkit.odometry.inputs import open_sequence

    sequence = open_sequence(SPEC)
    sequence.configure_for_method("kiss")  # the scans as the run reads them for kiss (KITTI's vertical-angle correction)
    scans = [sequence.read_scan(i).points_xyz for i in range(len(sequence))]
    where = _spy_on_fitness(monkeypatch)
    out = run(SPEC, "kiss")
    assert len(where) == len(scans) - 1 and threading.main_thread().name not in where
    assert not _our_threads()
    where.clear()
    inline = run(SPEC, "kiss", overlap=False)
    assert where == [threading.main_thread().name] * (len(scans) - 1)
    # (kiss-icp's threads are not bit-reproducible: the two runs' poses agree to rounding)
    np.testing.assert_allclose(out.trajectory.poses_se3, inline.trajectory.poses_se3, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(out.stats.check_failed, inline.stats.check_failed)
    for result in (out, inline):
        checker = FrameChecker(len(scans))  # the definition: frame after frame, in line, at the run's poses
        for k, points in enumerate(scans):
            checker.add(k, k, points, None, result.trajectory.poses_se3)
        np.testing.assert_array_equal(result.stats.fitness, checker.fitness)
    assert np.isfinite(out.stats.fitness[1:]).all() and (out.stats.check_s[1:] > 0).all()


def test_an_overlapped_checker_gives_the_in_line_fitness_and_joins_its_thread(scans):
    """FrameChecker(overlap=True) as the runner drives it (prepare, then add once the pose is known): the fitness of
    the in-line checker on the real KITTI scans, a wrong motion included, and no thread once finished."""
    poses = np.stack([np.eye(4)] * len(scans))
    poses[:, 0, 3] = 0.8 * np.arange(len(scans))  # ~the right motion, then 2 m off at frame 5
    poses[5:, 0, 3] += 2.0
    inline, beside = FrameChecker(len(scans)), FrameChecker(len(scans), overlap=True)
    for k, points in enumerate(scans):
        inline.add(k, k, points, None, poses)
        beside.add(k, k, points, None, poses, beside.prepare(k, points))
    assert _our_threads()  # its worker, until finished
    np.testing.assert_array_equal(beside.finish(poses, None).fitness, inline.finish(poses, None).fitness)
    assert not _our_threads()
    assert inline.fitness[5] < inline.fitness[4]


@pytest.mark.parametrize("fail_at", [1, 9])  # the first frame's queries, and the last frame's (waited for at the end)
def test_an_error_in_the_checks_thread_is_the_runs_one_line_error_and_leaves_no_thread(monkeypatch, capsys, tmp_path, fail_at):
    from lidarkit.cli import main
    from lidarkit.errors import DataError

    where = _spy_on_fitness(monkeypatch, fail_at, DataError("no nearest neighbour", source="frame check"))
    with pytest.raises(DataError, match="no nearest neighbour"):
        run(SPEC, "kiss")
    assert len(where) == fail_at and where[-1] != threading.main_thread().name
    assert not _our_threads()
    where.clear()
    with pytest.raises(SystemExit) as exc:
        main(["odometry", SPEC, "-m", "kiss", "--no-progress", "--out", str(tmp_path / "run")])
    assert exc.value.code == 1
    assert capsys.readouterr().err.strip().splitlines() == ["error: frame check: no nearest neighbour"]
    assert not _our_threads() and not (tmp_path / "run").exists()


@pytest.mark.parametrize("where", ["register", "check"])
def test_an_interrupt_while_the_checks_thread_runs_leaves_no_thread_and_writes_nothing(monkeypatch, tmp_path, where):
    """Ctrl-C in the main thread (kiss registering frame 4) or in the check's thread (frame 4's queries)."""
    from lidarkit.registration.kiss import KissRegistration

    class Interrupted(KissRegistration):
        frames = 0

        def register_frame(self, *args, **kwargs):
            self.frames += 1
            if where == "register" and self.frames == 5:
                raise KeyboardInterrupt
            return super().register_frame(*args, **kwargs)

    spied = _spy_on_fitness(monkeypatch, 4 if where == "check" else None, KeyboardInterrupt())
    with pytest.raises(KeyboardInterrupt):
        run(SPEC, Interrupted(), out_dir=tmp_path / "run")
    assert len(spied) == (4 if where == "check" else 3) and threading.main_thread().name not in spied  # frames 1-3 (and 4)
    assert not _our_threads()
    assert list(tmp_path.iterdir()) == []


def test_sigterm_during_a_kiss_run_stops_it_with_one_line(tmp_path):
    """SIGTERM while kiss registers and the check's thread runs: exit 143 with the one interrupted line (a thread
    left waiting would keep the process from exiting), no run folder."""
    import os
    import signal
    import subprocess
    import sys
    import time

    command = [sys.executable, "-m", "lidarkit", "odometry", "sim:street?frames=600&beams=16&azimuths=360", "-m", "kiss",
               "--progress", "--out", str(tmp_path / "run")]
    err_path = tmp_path / "stderr.txt"
    with err_path.open("w") as err:
        proc = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=err, env={**os.environ}, cwd=tmp_path)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None and " frames (" not in err_path.read_text():
            time.sleep(0.05)  # until the first progress line: the loop runs
        assert proc.poll() is None, err_path.read_text()[-2000:]
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 143
    lines = [line for line in err_path.read_text().splitlines() if " frames (" not in line]
    assert lines == ["interrupted by SIGTERM: stopped; no file is left half-written (each is complete or absent)"]
    assert not (tmp_path / "run").exists()
