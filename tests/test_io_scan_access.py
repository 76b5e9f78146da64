"""Scan access across readers: out-of-range indices name the sequence; exported per-point times are read back."""

from __future__ import annotations

import shutil

import numpy as np
import pytest
from conftest import shared_path

from lidarkit.errors import DataError
from lidarkit.io.folder import ScanFolder
from lidarkit.io.kitti import KittiOdometry
from lidarkit.io.kitti_raw import KittiRaw
from lidarkit.sim.lidar import SimulatedLidarSequence, export_kitti, make_config
from lidarkit.trajectory import Trajectory


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    sim = SimulatedLidarSequence(make_config(scene="street", n_frames=3, seed=1, n_beams=16, n_azimuths=360))
    return sim, export_kitti(sim, tmp_path_factory.mktemp("sim") / "seq")


def test_kitti_reader_loads_exported_point_times(exported):
    sim, folder = exported
    seq = KittiOdometry(folder)
    for i in range(len(sim)):
        ours, ref = seq.read_scan(i), sim.read_scan(i)
        assert ours.point_times_s is not None and ours.point_times_s.dtype == np.float64
        assert len(ours.point_times_s) == len(ours.points_xyz)
        # same convention as the simulator's own Scan: seconds from the sweep start (stored as float32)
        np.testing.assert_allclose(ours.point_times_s, ref.point_times_s, atol=1e-6)
    assert 0.0 <= seq.read_scan(0).point_times_s.min() and seq.read_scan(0).point_times_s.max() < 0.1 + 1e-6


def test_kitti_point_times_length_mismatch_is_a_data_error(exported, tmp_path):
    _, folder = exported
    copy = tmp_path / "seq"
    shutil.copytree(folder, copy)
    np.save(copy / "point_times" / "000001.npy", np.zeros(7, dtype=np.float32))
    seq = KittiOdometry(copy)
    assert seq.read_scan(0).point_times_s is not None
    with pytest.raises(DataError, match=r"000001\.npy \(frame 1\): 7 point times for \d+ points"):
        seq.read_scan(1)
    shutil.rmtree(copy / "point_times")
    assert KittiOdometry(copy).read_scan(1).point_times_s is None  # KITTI proper: no per-point times


def test_out_of_range_scan_index_names_the_sequence(exported, tmp_path):
    _, folder = exported
    with pytest.raises(DataError, match=r"seq \(.*\): scan index 3 out of range for 3 scans"):
        KittiOdometry(folder).read_scan(3)
    scans = tmp_path / "scans"
    scans.mkdir()
    np.save(scans / "a.npy", np.zeros((5, 3)))
    with pytest.raises(DataError, match=r"scans .*scan index -2 out of range for 1 scans"):
        ScanFolder(scans).read_scan(-2)


def test_kitti_raw_out_of_range_names_the_drive(tmp_path):
    date = "2011_09_26"
    shutil.copytree(shared_path("kitti_raw", date), tmp_path / date)
    velo = tmp_path / date / f"{date}_drive_0001_sync" / "velodyne_points" / "data"
    velo.mkdir()
    np.zeros((10, 4), dtype=np.float32).tofile(velo / "0000000000.bin")
    with pytest.raises(DataError, match=r"kitti_raw_2011_09_26_0001.*scan index 5 out of range for 1 scans"):
        KittiRaw(tmp_path, date, 1).read_scan(5)


def test_from_kitti_accepts_a_list_of_timestamps(tmp_path):
    path = tmp_path / "poses.txt"
    np.savetxt(path, np.tile(np.eye(4)[:3].ravel(), (3, 1)))
    traj = Trajectory.from_kitti(path, [0.0, 0.1, 0.2])
    np.testing.assert_allclose(traj.timestamps_s, [0.0, 0.1, 0.2])
    times = tmp_path / "times.txt"
    times.write_text("0\n1\n2\n")
    np.testing.assert_allclose(Trajectory.from_kitti(path, str(times)).timestamps_s, [0, 1, 2])
    np.testing.assert_allclose(Trajectory.from_kitti(path, times).timestamps_s, [0, 1, 2])
    with pytest.raises(DataError):
        Trajectory.from_kitti(path, [0.0, 0.1])


def test_every_reader_refuses_an_index_that_is_not_an_integer_or_out_of_range(tmp_path):
    """Only the KITTI and simulator readers checked an index's type: a scan folder read scan 1 for 1.5 (Python's own
    error for a float list index, then) and image readers answered 2.7 or 99 with numpy / list tracebacks, a
    simulated camera read frame 2 for 2.7 without a word."""
    import bz2

    import cv2

    from lidarkit.io.carmen import CarmenLog
    from lidarkit.io.images import ImageFolder
    from lidarkit.sim.street_camera import SimulatedCameraSequence

    scans = tmp_path / "scans"
    scans.mkdir()
    for i in range(2):
        np.save(scans / f"{i}.npy", np.full((5, 3), float(i)))
    images = tmp_path / "images"
    images.mkdir()
    for i in range(2):
        cv2.imwrite(str(images / f"{i:06d}.png"), np.full((8, 8), 10 * i, dtype=np.uint8))
    head = bz2.decompress(shared_path("carmen_2d", "aces.clf.bz2").read_bytes()).decode().splitlines()[:60]
    (tmp_path / "head.clf").write_text("\n".join(head) + "\n")
    log = CarmenLog(tmp_path / "head.clf")
    camera = SimulatedCameraSequence(n_frames=3, width=32, height=24)
    cases = ((ScanFolder(scans).read_scan, "scan", 2), (ImageFolder(images).read_image, "image", 2),
             (log.read_scan, "scan", len(log)), (camera.read_image, "frame", 3))
    for read, what, n in cases:
        for index in (1.5, 2.0, "1", True):
            with pytest.raises(DataError, match=f"{what} index {index!r} is not an integer"):
                read(index)
        with pytest.raises(DataError, match=f"{what} index {n} out of range for {n} {what}s"):
            read(n)
    assert ScanFolder(scans).read_scan(np.int64(-1)).points_xyz[0, 0] == 1.0  # from the end, as a list counts
    assert ImageFolder(images).read_image(np.int32(1))[0, 0] == 10
