"""KittiRaw (pykitti) on the real 2011_09_26 calibration + drive_0001 OXTS frame, and on modified copies."""

from __future__ import annotations

import re
import shutil
from datetime import datetime, timezone

import numpy as np
import pytest
from conftest import shared_path
from scipy.spatial.transform import Rotation

from lidarkit.errors import ConfigError, DataError
from lidarkit.io import open_dataset
from lidarkit.io.kitti_raw import KittiRaw, read_kitti_raw_timestamps

DATE, DRIVE = "2011_09_26", "0001"
EARTH_RADIUS_M = 6378137.0


@pytest.fixture
def raw_root():
    return shared_path("kitti_raw")


@pytest.fixture
def raw_copy(tmp_path, raw_root):
    """Writable copy of kitti_raw/2011_09_26 (calib + drive metadata, < 0.1 MB)."""
    shutil.copytree(raw_root / DATE, tmp_path / DATE)
    return tmp_path


def _drive(base):
    return base / DATE / f"{DATE}_drive_{DRIVE}_sync"


def _calib_rows(path):
    return {k.strip(): np.array(v.split(), float) for k, v in (line.split(":", 1) for line in path.read_text().splitlines()) if k != "calib_time"}


def test_calibration(raw_root):
    ds = open_dataset("kitti_raw", raw_root, date=DATE, drive=DRIVE)
    np.testing.assert_allclose(ds.T_velo_imu[:3, 3], [-8.086759e-01, 3.195559e-01, -7.997231e-01])
    velo_to_cam = _calib_rows(raw_root / DATE / "calib_velo_to_cam.txt")
    cam = _calib_rows(raw_root / DATE / "calib_cam_to_cam.txt")
    T_cam0unrect_velo = np.eye(4)
    T_cam0unrect_velo[:3, :3] = velo_to_cam["R"].reshape(3, 3)
    T_cam0unrect_velo[:3, 3] = velo_to_cam["T"]
    R_rect = np.eye(4)
    R_rect[:3, :3] = cam["R_rect_00"].reshape(3, 3)
    np.testing.assert_allclose(ds.T_cam0_velo, R_rect @ T_cam0unrect_velo, atol=1e-12)
    np.testing.assert_allclose(ds.K, cam["P_rect_00"].reshape(3, 4)[:, :3])
    assert ds.calib.b_gray == pytest.approx(0.5372, abs=2e-3)  # KITTI gray stereo baseline ~0.54 m
    assert len(ds) == 0 and ds.ground_truth is None and ds.name == "kitti_raw_2011_09_26_0001"


def test_oxts_frame_zero_pose(raw_root):
    ds = KittiRaw(_drive(raw_root))  # the drive folder itself: date/drive from its name
    packet = np.loadtxt(_drive(raw_root) / "oxts" / "data" / "0000000000.txt")
    lat, lon, alt, roll, pitch, yaw = packet[:6]
    assert ds.oxts_packets[0].lat == lat
    pose = ds.oxts_poses.poses_se3[0]
    R_expected = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix()  # R = Rz(yaw) Ry(pitch) Rx(roll)
    np.testing.assert_allclose(pose[:3, :3], R_expected, atol=1e-9)
    np.testing.assert_allclose(pose[:3, 3], 0.0, atol=1e-9)  # origin = first GPS fix
    stamp = datetime(2011, 9, 26, 13, 2, 25, tzinfo=timezone.utc).timestamp() + 0.964389445
    assert ds.oxts_poses.timestamps_s[0] == pytest.approx(stamp, abs=1e-6)
    # LiDAR pose: the Velodyne sits ~0.80 m above and ~0.81 m ahead of the IMU (T_velo_imu t = (-0.81, 0.32, -0.80))
    lidar = ds.ground_truth_at([0]).poses_se3[0]
    offset_imu = pose[:3, :3].T @ lidar[:3, 3]
    np.testing.assert_allclose(offset_imu, [0.81, -0.32, 0.80], atol=0.03)
    # the calib file's rotation is rounded to 7 digits, so R^T differs from R^-1 by ~5e-9
    np.testing.assert_allclose(lidar[:3, :3] @ ds.T_velo_imu[:3, :3], pose[:3, :3], atol=1e-7)


def test_ground_truth_at_checks_the_frame_numbers(raw_root):
    """ground_truth_at([0.5]) gave frame 0's pose (as ground_truth_at([1.5]) gave frame 1's) and [] failed inside
    numpy: frame numbers are checked as read_scan checks its index."""
    ds = KittiRaw(raw_root, DATE, DRIVE)
    source = _drive(raw_root) / "oxts"
    for frames, reason in (([0.5], "frame index 0.5 is not an integer"), ([108], "frame index 108 out of range for 108 frames"),
                           ([], "no frames selected")):
        with pytest.raises(DataError) as err:
            ds.ground_truth_at(frames)
        assert str(err.value) == f"{source}: {reason}"


def test_mercator_translation_of_a_second_packet(raw_copy):
    """A packet 1e-4 deg north-east and 1 m up lands where a local spherical approximation puts it."""
    oxts = _drive(raw_copy) / "oxts" / "data"
    fields = (oxts / "0000000000.txt").read_text().split()
    lat0, lon0, alt0 = (float(f) for f in fields[:3])
    fields[:3] = [repr(lat0 + 1e-4), repr(lon0 + 1e-4), repr(alt0 + 1.0)]
    (oxts / "0000000001.txt").write_text(" ".join(fields) + "\n")
    ds = KittiRaw(raw_copy, DATE, DRIVE)
    t = ds.oxts_poses.poses_se3[1][:3, 3]
    east = EARTH_RADIUS_M * np.cos(np.radians(lat0)) * np.radians(1e-4)
    north = EARTH_RADIUS_M * np.radians(1e-4)
    np.testing.assert_allclose(t, [east, north, 1.0], atol=1e-3)
    assert east == pytest.approx(7.30, abs=0.01) and north == pytest.approx(11.13, abs=0.01)


def test_scans_read_when_present(raw_copy):
    velo = _drive(raw_copy) / "velodyne_points" / "data"
    velo.mkdir()
    shutil.copy2(shared_path("kitti_odometry", "sequences", "00", "velodyne", "000000.bin"), velo / "0000000000.bin")
    ds = KittiRaw(raw_copy, DATE, int(DRIVE))
    assert len(ds) == 1
    scan = ds.read_scan(0)
    assert scan.points_xyz.shape == (124668, 3) and scan.frame == 0
    stamp = datetime(2011, 9, 26, 13, 2, 25, tzinfo=timezone.utc).timestamp() + 0.951199337
    assert scan.timestamp_s == pytest.approx(stamp, abs=1e-6)
    assert len(ds.ground_truth) == 1 and ds.ground_truth.timestamps_s[0] == pytest.approx(stamp, abs=1e-6)
    with open(velo / "0000000000.bin", "ab") as f:
        f.write(b"\0\0\0")
    with pytest.raises(DataError, match=r"0000000000\.bin \(frame 0\): truncated"):
        ds.read_scan(0)
    shutil.copy2(velo / "0000000000.bin", velo / "0000000002.bin")
    with pytest.raises(DataError, match=r"no OXTS packet for frame 2"):
        KittiRaw(raw_copy, DATE, DRIVE).ground_truth


def test_points_dropped_as_nonfinite_are_kept_once_for_the_runs_warnings(raw_copy):
    """drop_nonfinite=true logged the points it left out and the run's metrics.json had no word of them (as KITTI
    odometry and scan folders had not): the first scan's line is kept once in reader_warnings."""
    velo = _drive(raw_copy) / "velodyne_points" / "data"
    velo.mkdir()
    points = np.fromfile(shared_path("kitti_odometry", "sequences", "00", "velodyne", "000000.bin"), dtype="<f4").reshape(-1, 4)
    points[7:10, 2] = np.nan
    points.tofile(velo / "0000000000.bin")
    ds = KittiRaw(raw_copy, DATE, int(DRIVE), drop_nonfinite=True)
    assert len(ds.read_scan(0).points_xyz) == len(points) - 3
    ds.read_scan(0)
    assert ds.reader_warnings == [f"left out 3 of {len(points)} points with NaN or infinite values in frame 0 "
                                  f"({velo / '0000000000.bin'}); in later frames without another warning"]


# ---- errors -----------------------------------------------------------------------------------------------
def test_missing_velodyne_is_a_clear_error(raw_root):
    ds = KittiRaw(raw_root, DATE, DRIVE)
    with pytest.raises(DataError, match=r"velodyne_points/data: no Velodyne scans"):
        ds.read_scan(0)
    with pytest.raises(DataError, match=r"image_00: no images"):
        ds.read_image(0)


def test_missing_inputs(raw_copy):
    with pytest.raises(DataError, match=r"2011_09_26_drive_0002_sync: folder not found"):
        KittiRaw(raw_copy, DATE, "0002")
    with pytest.raises(DataError, match="give date= and drive="):
        KittiRaw(raw_copy)
    with pytest.raises(DataError, match=r"nowhere: not found"):  # (it asked for date= and drive=)
        KittiRaw(raw_copy / "nowhere")
    (raw_copy / DATE / "calib_imu_to_velo.txt").unlink()
    with pytest.raises(DataError, match=r"calib_imu_to_velo\.txt: calibration file not found"):
        KittiRaw(raw_copy, DATE, DRIVE)


def test_a_drive_folder_with_options_that_agree_or_not(raw_root):
    """The drive folder given with drive= or date= was refused ("give date= and drive= ... or the drive folder itself",
    which was given); dataset=extract on a _sync folder was ignored without a word."""
    drive = _drive(raw_root)
    for options in ({"drive": DRIVE}, {"drive": 1}, {"date": DATE}, {"date": DATE, "drive": DRIVE}, {}):
        assert KittiRaw(drive, **options).drive_dir == drive
    for options, named in (({"dataset": "extract"}, "dataset='extract', but the drive folder given is 'sync'"),
                           ({"drive": "0002"}, "drive='0002', but the drive folder given is '0001'"),
                           ({"date": "2011_09_28"}, "date='2011_09_28', but the drive folder given is '2011_09_26'")):
        with pytest.raises(ConfigError, match=re.escape(named)):
            KittiRaw(drive, **options)


def test_malformed_oxts_and_timestamps(raw_copy):
    packet = _drive(raw_copy) / "oxts" / "data" / "0000000000.txt"
    original = packet.read_text()
    packet.write_text(" ".join(original.split()[:29]) + "\n")
    with pytest.raises(DataError, match=r"0000000000\.txt \(line 1\): expected 30 numbers, found 29"):
        KittiRaw(raw_copy, DATE, DRIVE)
    packet.write_text(original)
    stamps = _drive(raw_copy) / "oxts" / "timestamps.txt"
    lines = stamps.read_text().splitlines()
    lines[3] = "2011-09-26 13:xx:26.4"
    stamps.write_text("\n".join(lines) + "\n")
    with pytest.raises(DataError, match=r"oxts/timestamps\.txt \(line 4\): not a time stamp"):
        KittiRaw(raw_copy, DATE, DRIVE)
    lines[3] = lines[1]  # back in time: named by its line, not later as a frame of some trajectory
    stamps.write_text("\n".join(lines) + "\n")
    with pytest.raises(DataError, match=r"oxts/timestamps\.txt \(line 4, frame 3\): time stamps are not strictly increasing"):
        KittiRaw(raw_copy, DATE, DRIVE)


def test_pykitti_errors_are_wrapped(raw_copy):
    calib = raw_copy / DATE / "calib_velo_to_cam.txt"
    calib.write_text(calib.read_text().replace("R: 7.533745e-03 ", "R: "))  # 8 numbers: pykitti reshape fails
    with pytest.raises(DataError, match=r"pykitti cannot load the drive \(ValueError"):
        KittiRaw(raw_copy, DATE, DRIVE)


def _moving_drive(base, n=6, north_deg_per_s=1e-4):
    """The shared drive with ``n`` KITTI scans and OXTS packets moving north at ``north_deg_per_s`` (~11 m/s), each
    packet at its own ``oxts/timestamps.txt`` stamp (12-24 ms after its scan's Velodyne stamp, as recorded)."""
    drive = _drive(base)
    oxts, velo = drive / "oxts" / "data", drive / "velodyne_points" / "data"
    velo.mkdir()
    fields = (oxts / "0000000000.txt").read_text().split()
    lat0 = float(fields[0])
    stamps = read_kitti_raw_timestamps(drive / "oxts" / "timestamps.txt")
    for k in range(n):
        fields[0] = repr(float(lat0 + north_deg_per_s * (stamps[k] - stamps[0])))
        (oxts / f"{k:010d}.txt").write_text(" ".join(fields) + "\n")
        shutil.copy2(shared_path("kitti_odometry", "sequences", "00", "velodyne", f"{k:06d}.bin"), velo / f"{k:010d}.bin")
    return drive


def test_raw_scans_are_timed_by_azimuth_and_stamped_mid_sweep(raw_copy):
    """As kiss-icp's raw loader: a clockwise sweep from behind (0) through forward (0.5) to behind (1)."""
    ds = KittiRaw(_moving_drive(raw_copy, n=1))
    scan = ds.read_scan(0)
    assert scan.point_time_convention == "fraction" and scan.stamp_instant == "mid"
    t, p = scan.point_times_s, scan.points_xyz
    assert t.min() >= 0.0 and t.max() <= 1.0 and np.ptp(t) > 0.99
    azimuth = np.degrees(np.arctan2(p[:, 1], p[:, 0]))
    for deg, fraction in ((0.0, 0.5), (90.0, 0.25), (-90.0, 0.75), (179.0, 0.0)):
        near = np.abs(azimuth - deg) < 1.0
        assert near.sum() > 50 and np.abs(t[near] - fraction).max() < 0.01
    assert KittiRaw(_drive(raw_copy), point_times="none").read_scan(0).point_times_s is None
    with pytest.raises(Exception, match="point_times must be one of azimuth, none"):
        KittiRaw(_drive(raw_copy), point_times="ring")


def test_raw_ground_truth_retimed_to_the_sweep_end(raw_copy):
    ds = KittiRaw(_moving_drive(raw_copy))
    north_m_per_s = EARTH_RADIUS_M * np.radians(1e-4)  # ~11.1 m/s
    mid = ds.ground_truth
    assert mid.meta["pose_instant"] == "mid"
    step = np.linalg.norm(np.diff(mid.poses_se3[:, :3, 3], axis=0), axis=1)
    np.testing.assert_allclose(step, north_m_per_s * np.diff(mid.timestamps_s), rtol=1e-3)  # ~1.15 m a frame
    same = ds.ground_truth_at_instant("mid")
    np.testing.assert_allclose(same.poses_se3, mid.poses_se3, atol=1e-7)
    end = ds.ground_truth_at_instant("end")
    assert end.meta["pose_instant"] == "end" and "OXTS" in end.meta["retimed"]
    period = np.median(np.diff(ds._velo_times_all))
    np.testing.assert_allclose(end.timestamps_s, mid.timestamps_s + 0.5 * period)
    # half a sweep further north, the last continued at constant velocity past the last packet
    moved = end.poses_se3[:, :3, 3] - mid.poses_se3[:, :3, 3]
    np.testing.assert_allclose(moved[:, 1], 0.5 * period * north_m_per_s, rtol=1e-3)
    np.testing.assert_allclose(moved[:, [0, 2]], 0.0, atol=1e-6)


def _drive_at_10_m_per_s_east(base, n=20):
    """A drive with the real drive_0001 stamps of its first ``n`` frames, level and driving east at 10 m/s, each OXTS
    packet holding the position at its own oxts stamp; the scans are small (ground truth does not read them)."""
    drive = _drive(base)
    (drive / "velodyne_points" / "data").mkdir(parents=True, exist_ok=True)
    shutil.rmtree(drive / "oxts" / "data")
    (drive / "oxts" / "data").mkdir()
    for sub in ("oxts/timestamps.txt", "velodyne_points/timestamps.txt"):
        lines = (shared_path("kitti_raw", DATE, drive.name) / sub).read_text().splitlines()[:n]
        (drive / sub).write_text("\n".join(lines) + "\n")
    oxts_s = read_kitti_raw_timestamps(drive / "oxts" / "timestamps.txt")
    packet = np.loadtxt(shared_path("kitti_raw", DATE, drive.name, "oxts", "data", "0000000000.txt"))
    packet[3:6] = 0.0  # level, facing east
    lat0 = packet[0]
    rng = np.random.default_rng(0)
    for k in range(n):
        east_m = 10.0 * (oxts_s[k] - oxts_s[0])
        moved = packet.copy()
        moved[1] = packet[1] + np.degrees(east_m / (EARTH_RADIUS_M * np.cos(np.radians(lat0))))  # Mercator: x = s R lon
        np.savetxt(drive / "oxts" / "data" / f"{k:010d}.txt", moved[None], fmt="%.15g")
        rng.uniform(-20, 20, (200, 4)).astype("<f4").tofile(drive / "velodyne_points" / "data" / f"{k:010d}.bin")
    return drive, oxts_s


def test_ground_truth_is_interpolated_from_the_oxts_stamps_to_the_scans(raw_copy):
    """Each OXTS packet was given its scan's Velodyne stamp, but drive_0001's packets come 11.8-23.9 ms after their
    scans (100 or 110 ms apart, the scans 103 ms): at 10 m/s the truth sat 12-24 cm behind and its frame-to-frame
    steps were 0.998-1.100 m where 1.031 m is right, a ~4.5 % RPE floor from the truth alone."""
    drive, oxts_s = _drive_at_10_m_per_s_east(raw_copy)
    ds = KittiRaw(drive)
    gt = ds.ground_truth
    velo_s = read_kitti_raw_timestamps(drive / "velodyne_points" / "timestamps.txt")
    assert 0.0118 <= (oxts_s - velo_s).min() and (oxts_s - velo_s).max() <= 0.0240  # as recorded
    np.testing.assert_array_equal(gt.timestamps_s, velo_s)
    east_m = 10.0 * (velo_s - oxts_s[0])  # where the car is at each scan's stamp (the origin: the first packet)
    imu_east = (gt.poses_se3 @ ds.T_velo_imu)[:, 0, 3]  # T_enu_imu = T_enu_velo @ T_velo_imu
    np.testing.assert_allclose(imu_east, east_m, atol=1e-4)
    steps = np.linalg.norm(np.diff(gt.poses_se3[:, :3, 3], axis=0), axis=1)
    np.testing.assert_allclose(steps, 10.0 * np.diff(velo_s), rtol=1e-4)
    np.testing.assert_allclose(ds.ground_truth_at([0, 5]).poses_se3, gt.poses_se3[[0, 5]], atol=1e-9)
    assert "paired" not in gt.meta
