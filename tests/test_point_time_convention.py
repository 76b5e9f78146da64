"""One per-point time convention per recording: a simulator's clock starts at 0, where a scan's own stamp cannot tell
absolute point times from relative ones, and its first scans were read as relative while the later ones read as absolute."""

from __future__ import annotations

import numpy as np
import pytest
from test_io_rosbag_latency import DRIVE, PERIOD_S, _late_bag

from lidarkit.errors import DataError
from lidarkit.io import open_dataset
from lidarkit.odometry import run
from lidarkit.sim.lidar import SimulatedLidarSequence, export_kitti


@pytest.fixture(scope="module")
def drive():
    return SimulatedLidarSequence(**{**DRIVE, "n_azimuths": 90})  # (the latency tests' drive, fewer columns: faster)


def _relative_times(scan) -> np.ndarray:
    """A scan's point times in seconds from its stamp, whatever its convention."""
    return scan.point_times_s - (scan.timestamp_s if scan.point_time_convention == "absolute_s" else 0.0)


def test_a_bag_on_a_clock_starting_at_0_reads_every_scan_as_absolute(tmp_path, drive):
    """Float64 absolute point times, the clock starting at 0 with the first sweep (stamped at the sweep ends): scans 0 and
    1 were read as relative (stamps of 0.1 and 0.2 s decide nothing), 0.1 and 0.2 s off the simulator's times. Read in
    the bag's one convention, every scan holds the simulator's times, and odometry equals that over the same bag on a
    clock 1000 s later."""
    at_zero = open_dataset("rosbag", _late_bag(tmp_path / "zero.bag", drive, 0.0, absolute=True, t0=0.0))
    later = open_dataset("rosbag", _late_bag(tmp_path / "later.bag", drive, 0.0, absolute=True, t0=1000.0))
    for k in range(len(drive)):
        scan = at_zero.read_scan(k)
        assert scan.point_time_convention == "absolute_s"
        # (stamped at the sweep end; the stamps hold whole nanoseconds)
        np.testing.assert_allclose(_relative_times(scan) + PERIOD_S, drive.read_scan(k).point_times_s, rtol=0, atol=2e-9)
    zero_run, later_run = run(at_zero, "vanilla"), run(later, "vanilla")
    np.testing.assert_allclose(zero_run.trajectory.poses_se3, later_run.trajectory.poses_se3, rtol=0, atol=1e-9)
    np.testing.assert_allclose(zero_run.trajectory.timestamps_s, later_run.trajectory.timestamps_s - 1000.0, rtol=0, atol=1e-6)


def test_a_message_whose_stamp_reads_its_times_the_other_way_is_refused_by_name(tmp_path, drive):
    """A bag whose first scans hold absolute times (on a clock starting at 0) and whose message 6 holds times relative
    to its stamp: read as relative by itself, it was deskewed as the others without a word; read as absolute, its sweep
    lies 0.7 s from its stamp. A DataError names the message and both conventions."""
    from rosbags.highlevel import AnyReader
    from test_io_bad_bags import write_ros1_bag

    path = _late_bag(tmp_path / "zero.bag", drive, 0.0, absolute=True, t0=0.0)
    clouds = []
    with AnyReader([path]) as reader:
        connections = [c for c in reader.connections if c.topic == "/points"]
        for k, (connection, _, raw) in enumerate(reader.messages(connections=connections)):
            msg = reader.deserialize(raw, connection.msgtype)
            stamp = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
            data = np.frombuffer(bytes(msg.data), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("timestamp", "<f8")]).copy()
            if k == 6:
                data["timestamp"] -= stamp  # relative to the stamp (the sweep end)
            clouds.append((stamp, [(f.name, f.offset, f.datatype) for f in msg.fields], msg.point_step, data.tobytes(), msg.width))
    mixed = open_dataset("rosbag", write_ros1_bag(tmp_path / "mixed.bag", clouds))
    assert mixed.read_scan(5).point_time_convention == "absolute_s"
    with pytest.raises(DataError) as err:
        mixed.read_scan(6)
    assert str(err.value) == (f"{mixed.path} (message 6 on /points): per-point time field 'timestamp' holds times relative to the "
                              "stamp (-0.100000 to -0.001111 s, stamp 0.700000 s) where the convention read from the first scans on "
                              "/points is absolute times on the stamps' clock: read as those, this sweep lies 0.701111 s from its "
                              "stamp (--frames can leave the scan out)")


def test_a_short_recording_near_0_reads_its_convention_from_how_its_sweeps_follow_the_stamps():
    """Two or three sweeps stamped within two sweeps of 0 are decided by no stamp: absolute times move with the stamps,
    relative ones keep their place (they were read by their size, absolute ones as relative)."""
    from lidarkit.io.pointcloud2 import recording_time_convention

    stamps = np.array([0.0, 0.1, 0.2])
    assert recording_time_convention(stamps, stamps, stamps + 0.099) == "absolute_s"
    assert recording_time_convention(stamps, np.zeros(3), np.full(3, 0.099)) == "relative_s"
    assert recording_time_convention(stamps + 0.1, np.full(3, -0.1), np.full(3, -0.001)) == "relative_s"  # stamped at the ends
    assert recording_time_convention(np.zeros(1), np.zeros(1), np.full(1, 0.099)) == "relative_s"  # one sweep: by size
    assert recording_time_convention(np.full(3, 1.7e9), np.full(3, 1.7e9 + 18), np.full(3, 1.7e9 + 18.1)) == "absolute_s"


def _absolute_kitti(tmp_path, drive, name: str, t0: float, relative_frames: tuple[int, ...] = ()):
    """The simulator's KITTI-layout export of ``drive`` with times.txt stamping each sweep start ``t0`` + k x period and
    point_times/ holding absolute float64 times on that clock (relative from the stamp for ``relative_frames``)."""
    folder = export_kitti(drive, tmp_path / name)
    (folder / "sim.yaml").unlink()  # (a plain KITTI-layout folder: its stamps are not the simulator's pose instant)
    stamps = t0 + PERIOD_S * np.arange(len(drive))
    np.savetxt(folder / "times.txt", stamps, fmt="%.9f")
    for k in range(len(drive)):
        relative = np.load(folder / "point_times" / f"{k:06d}.npy").astype(np.float64)
        np.save(folder / "point_times" / f"{k:06d}.npy", relative + (0.0 if k in relative_frames else stamps[k]))
    return folder


def test_kitti_absolute_point_times_read_the_same_on_a_clock_at_0_and_at_an_epoch(tmp_path, drive):
    """point_times/ holding absolute times: on stamps from 1.7e9 s they read as absolute by their size, on stamps from 0 s
    they read as relative (no stamp was passed), every sweep 0.1 k s later than it is. Judged against times.txt once for
    the folder, both read the simulator's times from the sweep start."""
    at_zero = open_dataset("kitti", _absolute_kitti(tmp_path, drive, "zero", 0.0))
    epoch = open_dataset("kitti", _absolute_kitti(tmp_path, drive, "epoch", 1.7e9))
    for k in range(len(drive)):
        expected = np.load(tmp_path / "zero" / "point_times" / f"{k:06d}.npy") - PERIOD_S * k
        for ds in (at_zero, epoch):
            scan = ds.read_scan(k)
            assert scan.point_time_convention == "absolute_s"
            np.testing.assert_allclose(_relative_times(scan), expected, rtol=0, atol=1e-6)  # (1.7e9 s holds 0.24 us)


def test_a_kitti_frame_whose_stamp_reads_its_times_the_other_way_is_refused_by_name(tmp_path, drive):
    """Frame 6 of an absolute folder holds times from its stamp: a DataError naming the file and frame."""
    ds = open_dataset("kitti", _absolute_kitti(tmp_path, drive, "mixed", 0.0, relative_frames=(6,)))
    assert ds.read_scan(5).point_time_convention == "absolute_s"
    with pytest.raises(DataError, match=r"000006\.npy \(frame 6\): per-point time array holds times relative to the stamp "
                                        r"\(0\.000000 to 0\.09\d+ s, stamp 0\.600000 s\) where the convention read from the first "
                                        r"frames of point_times/ is absolute times on the stamps' clock: read as those, this sweep lies 0\.50\d+ s"):
        ds.read_scan(6)
