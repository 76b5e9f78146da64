"""Bags whose header stamps lag their sweeps (a driver stamping each cloud on receipt): where the sweeps lie is read
from the point times, and poses, ground truth and warnings follow it."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from lidarkit.io import open_dataset
from lidarkit.odometry import run
from lidarkit.sim.lidar import SimulatedLidarSequence

#: a small accelerating drive: which instant of the sweep a pose refers to matters
DRIVE = dict(n_frames=8, n_beams=8, n_azimuths=180, seed=5, speed_mps=10.0, accel_time_s=1.0, motion_distortion=True, pose_instant="end")
PERIOD_S = 0.1
EPOCH_S = 1.7e9


def _late_bag(path, sim, latency_s: float, absolute: bool, n_poses: int | None = None, poses=None, t0: float | None = None):
    """A ROS 1 bag of ``sim``'s sweeps, each stamped ``latency_s`` after its sweep end, its point times relative to
    the stamp (float32 ``time``) or ``absolute`` (float64 ``timestamp`` on the stamps' clock), with the odometry
    stamped at the sweep ends (the first ``n_poses`` of them) or ``poses`` (``write_ros1_bag``'s odometry); the clock
    starts ``t0`` s before the first sweep (default: an epoch time if absolute, else 1000 s)."""
    from test_io_bad_bags import write_ros1_bag

    t0 = t0 if t0 is not None else EPOCH_S if absolute else 1000.0
    field, code, dtype = ("timestamp", 8, "<f8") if absolute else ("time", 7, "<f4")
    clouds = []
    for k in range(len(sim)):
        scan = sim.read_scan(k)
        stamp = t0 + (k + 1) * PERIOD_S + latency_s
        rec = np.zeros(len(scan.points_xyz), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), (field, dtype)])
        rec["x"], rec["y"], rec["z"] = scan.points_xyz.T
        rec[field] = t0 + k * PERIOD_S + scan.point_times_s if absolute else scan.point_times_s + k * PERIOD_S - (stamp - t0)
        fields = [("x", 0, 7), ("y", 4, 7), ("z", 8, 7), (field, 12, code)]
        clouds.append((stamp, fields, rec.dtype.itemsize, rec.tobytes(), len(rec)))
    truth = sim.ground_truth  # at the sweep ends
    poses = poses if poses is not None else [(t0 + t, tuple(T[:3, 3]), tuple(Rotation.from_matrix(T[:3, :3]).as_quat()))
             for t, T in zip(truth.timestamps_s, truth.poses_se3)][:n_poses]
    return write_ros1_bag(path, clouds, odometry=poses)


@pytest.fixture(scope="module")
def drive():
    return SimulatedLidarSequence(**DRIVE)


def test_poses_of_a_bag_stamped_after_its_sweeps_are_stamped_at_their_instant(tmp_path, drive):
    """Header stamps 30 ms after each sweep end (relative float32 times): the stamp is at no instant of the sweep, so
    the poses kept the stamps, 30-80 ms off the sweep middles they refer to, without a note. They are moved where the
    point times place each sweep; the ground truth (stamped at the sweep ends) is re-timed to the same instants."""
    bag = open_dataset("rosbag", _late_bag(tmp_path / "late.bag", drive, 0.03, absolute=False))
    assert bag.stamp_instant is None and bag.ground_truth.meta["pose_instant"] == "end"
    result = run(bag, "vanilla")
    mids = 1000.0 + drive.frame_times_s("mid")
    np.testing.assert_allclose(result.trajectory.timestamps_s, mids, atol=1e-6)
    assert result.config["run"]["estimate_stamps_note"] == ("stamped at the sweep mid (the scans' stamps, at no clear instant of the "
                                                            "sweep, 0.1300 s after its start by the point times, moved by -0.0800 s)")
    np.testing.assert_allclose(bag.ground_truth_at_instant("mid").timestamps_s, mids, atol=1e-6)
    assert bag.sweep_offset_s == pytest.approx(-0.13, abs=1e-6)  # where a sweep starts against its stamp


@pytest.mark.parametrize("latency_s", [0.12, 0.15])
def test_stamps_lagging_their_sweeps_by_more_than_a_period_are_a_latency_not_another_clock(tmp_path, drive, latency_s):
    """Absolute float64 point times with header stamps 120-150 ms after the sweep end: read as "another clock?", the
    ground truth's instant was lost (small_gicp scored 4x worse against sweep-end poses) or, at 150 ms, the odometry
    paired one pose per scan by count was refused as "0.150 s apart, more than a sweep". Both are placed by the point
    times, and the run scores as the same sweeps stamped at their ends do."""
    late = open_dataset("rosbag", _late_bag(tmp_path / "late.bag", drive, latency_s, absolute=True))
    assert late.ground_truth.meta["pose_instant"] == "end"
    assert late.reader_warnings == []
    on_time = open_dataset("rosbag", _late_bag(tmp_path / "on_time.bag", drive, 0.0, absolute=True))
    assert on_time.stamp_instant == "end"
    late_run, on_time_run = run(late, "vanilla"), run(on_time, "vanilla")
    rmse = {name: result.metrics["rpe_translation_m"]["stats"]["rmse"] for name, result in (("late", late_run), ("on time", on_time_run))}
    assert rmse["late"] == pytest.approx(rmse["on time"], rel=1e-9)
    np.testing.assert_allclose(late_run.trajectory.timestamps_s, on_time_run.trajectory.timestamps_s, atol=1e-6)
    # odometry covering part of the scans is paired by where the sweeps lie (by the stamps' phase, modulo the period,
    # scans 4 and 5 were "after the last pose")
    part = open_dataset("rosbag", _late_bag(tmp_path / "part.bag", drive, latency_s, absolute=True, n_poses=6))
    np.testing.assert_allclose(part.ground_truth_of(range(6)).poses_se3, drive.ground_truth.poses_se3[:6], atol=1e-6)
    assert late.sweep_offset_s == pytest.approx(-PERIOD_S - latency_s, abs=1e-6)


@pytest.mark.parametrize("latency_s", [0.0, 0.03])
def test_absolute_point_times_on_a_simulators_clock_are_absolute_not_another_clock(tmp_path, drive, latency_s):
    """Float64 ``timestamp`` point times on the stamps' clock, a simulator's starting near 0 (sim time: 100 s): below
    1e5 s they were read as relative to the stamp, the sweeps 100 s after their stamps ("another clock?"), no stamp
    instant, no ground truth re-timing (small_gicp's RPE 0.036 m where 0.009 is right). Read against the stamp, they are
    absolute, and the bag reads and scores as the same sweeps on an epoch clock."""
    sim_time = open_dataset("rosbag", _late_bag(tmp_path / "sim_time.bag", drive, latency_s, absolute=True, t0=100.0))
    epoch = open_dataset("rosbag", _late_bag(tmp_path / "epoch.bag", drive, latency_s, absolute=True))
    assert sim_time.read_scan(2).point_time_convention == "absolute_s"
    assert sim_time.sweep_offset_s == pytest.approx(epoch.sweep_offset_s, abs=1e-6)
    assert sim_time.sweep_offset_s == pytest.approx(-PERIOD_S - latency_s, abs=1e-6)
    assert sim_time.stamp_instant == epoch.stamp_instant == ("end" if latency_s == 0.0 else None)
    assert sim_time.ground_truth.meta["pose_instant"] == "end"
    sim_run, epoch_run = run(sim_time, "vanilla"), run(epoch, "vanilla")
    assert not any("another clock" in w for w in sim_time.reader_warnings + sim_run.metrics["warnings"])
    rpe = [result.metrics["rpe_translation_m"]["stats"]["rmse"] for result in (sim_run, epoch_run)]
    assert rpe[0] == pytest.approx(rpe[1], rel=1e-6)  # (the epoch clock holds point times to 0.24 us only)
    np.testing.assert_allclose(sim_run.trajectory.timestamps_s - 100.0, epoch_run.trajectory.timestamps_s - EPOCH_S, atol=1e-6)


def test_poses_a_sweep_away_from_point_timed_sweeps_are_refused(tmp_path, drive):
    """The refusal of odometry that does not stand one pose per scan stays: poses 0.35 s after sweeps stamped at their
    ends (odometry on another schedule) are more than a sweep outside the scans' sweeps."""
    from lidarkit.errors import DataError

    truth = drive.ground_truth
    shifted = [(EPOCH_S + t + 0.35, tuple(T[:3, 3]), (0.0, 0.0, 0.0, 1.0)) for t, T in zip(truth.timestamps_s, truth.poses_se3)]
    bag = open_dataset("rosbag", _late_bag(tmp_path / "shifted.bag", drive, 0.0, absolute=True, poses=shifted))
    with pytest.raises(DataError, match=r"pose 0 is stamped 1700000000\.450 s, scan 0 1700000000\.100 s: 0\.350 s apart, more than a "
                                        r"sweep \(0\.100 s\) outside the scan's sweep \(1700000000\.000-1700000000\.100 s by its point times\)"):
        bag.ground_truth


def test_stamps_at_no_clear_instant_move_where_the_dataset_places_the_sweeps():
    """``stamps_at_instant`` of scans stamped at no clear instant of their sweeps: by the dataset's sweep offset and
    length when it gives them (a bag's ``sweep_offset_s``), kept as they are when it does not."""
    from lidarkit.io.base import Scan
    from lidarkit.odometry.instants import stamps_at_instant

    stamps = 1000.13 + 0.1 * np.arange(4)
    scan = Scan(np.zeros((3, 3)), None, np.array([-0.13, -0.08, -0.03]), float(stamps[0]), 0, "late", "relative_s", None)
    moved, note = stamps_at_instant(stamps, scan, "end", stamps, sweep_s=0.1, sweep_offset_s=-0.13)
    np.testing.assert_allclose(moved, stamps - 0.03)
    assert note == ("stamped at the sweep end (the scans' stamps, at no clear instant of the sweep, 0.1300 s after its start by "
                    "the point times, moved by -0.0300 s)")
    assert stamps_at_instant(stamps, scan, "end", stamps, sweep_s=0.1) == (stamps, None)
    # stamped before its sweep (a sensor seeing part of its turn, its first point 25 ms after the stamp)
    moved, note = stamps_at_instant(stamps, scan, "mid", stamps, sweep_s=0.05, sweep_offset_s=0.025)
    np.testing.assert_allclose(moved, stamps + 0.05)
    assert "at no clear instant of the sweep, 0.0250 s before its start by the point times, moved by +0.0500 s" in note
