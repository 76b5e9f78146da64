"""kiss-icp's dataloaders as lidarkit reads them, on small datasets written in each dataset's own layout: points as the
dataset stores them, stamps from the file names, and ground truth that cannot stand one pose per scan refused."""

from __future__ import annotations

import logging
import re

import numpy as np
import pytest

from lidarkit.errors import DataError
from lidarkit.io import open_dataset

RING = np.column_stack([np.cos(np.linspace(0, 6, 200)) * 20, np.sin(np.linspace(0, 6, 200)) * 20, np.linspace(-1, 1, 200)])


def test_nclt_points_are_unsigned_and_scans_outside_the_ground_truth_are_counted(tmp_path, caplog):
    sequence = tmp_path / "2012-01-08"
    (sequence / "velodyne_sync").mkdir(parents=True)
    (tmp_path / "ground_truth").mkdir()
    points = np.vstack([RING, [[70.0, 0.0, 0.0], [0.0, 80.0, -2.0]]])  # beyond 63.835 m: past int16's range
    stored = np.round((points * [1.0, -1.0, -1.0] + 100.0) / 0.005).astype(np.uint16)  # NCLT: z down, 5 mm from -100 m
    utimes = 1326031000000000 + np.arange(4) * 100000
    for ut in utimes:
        record = np.zeros(len(stored), dtype=[("xyz", "<u2", 3), ("i", "u1"), ("l", "u1")])
        record["xyz"] = stored
        record.tofile(sequence / "velodyne_sync" / f"{ut}.bin")
    gt = [[ut, k, 0, 0, 0, 0, 0] for k, ut in enumerate([utimes[0] - 50000, *utimes[:3], utimes[2] + 50000])]  # scan 3 outside
    np.savetxt(tmp_path / "ground_truth" / "groundtruth_2012-01-08.csv", gt, delimiter=",", fmt="%d")
    with caplog.at_level(logging.WARNING):
        dataset = open_dataset("nclt", sequence)
    assert len(dataset) == 3 and "1 of 4 scans lie outside the ground truth's time span" in caplog.text
    assert dataset.reader_warnings == ["1 of 4 scans lie outside the ground truth's time span and are left out (kiss-icp's "
                                       "NCLT loader reads only scans with ground truth)"]  # (for the run's warnings)
    np.testing.assert_allclose(dataset.read_scan(0).points_xyz, points, atol=0.003)  # x = 70 m read as -257.68 m before
    np.testing.assert_allclose(dataset.timestamps_s, utimes[:3] * 1e-6)
    assert dataset.read_scan(1).timestamp_s == pytest.approx(utimes[1] * 1e-6)
    assert repr(dataset) == f"NcltScans({str(sequence)!r}, kind='nclt', scans=3)"  # (Python's <... object at 0x...>)


def test_a_truncated_or_empty_nclt_scan_is_refused_naming_the_file(tmp_path):
    """A velodyne_sync file cut 3 bytes into a point (427 bytes) was read as its 53 whole points, without a word."""
    sequence = tmp_path / "2012-01-08"
    (sequence / "velodyne_sync").mkdir(parents=True)
    (tmp_path / "ground_truth").mkdir()
    utimes = 1326031000000000 + np.arange(3) * 100000
    record = np.zeros(len(RING), dtype=[("xyz", "<u2", 3), ("i", "u1"), ("l", "u1")])
    record["xyz"] = np.round((RING * [1.0, -1.0, -1.0] + 100.0) / 0.005).astype(np.uint16)
    for ut in utimes:
        record.tofile(sequence / "velodyne_sync" / f"{ut}.bin")
    gt = [[ut, k, 0, 0, 0, 0, 0] for k, ut in enumerate([utimes[0] - 50000, *utimes, utimes[-1] + 50000])]
    np.savetxt(tmp_path / "ground_truth" / "groundtruth_2012-01-08.csv", gt, delimiter=",", fmt="%d")
    cut = sequence / "velodyne_sync" / f"{utimes[1]}.bin"
    cut.write_bytes(record.tobytes()[:427])
    (sequence / "velodyne_sync" / f"{utimes[2]}.bin").write_bytes(b"")
    dataset = open_dataset("nclt", sequence)
    assert len(dataset.read_scan(0).points_xyz) == len(RING)
    with pytest.raises(DataError, match=rf"{utimes[1]}.bin: 427 bytes is not a whole number of 8-byte points$"):
        dataset.read_scan(1)
    with pytest.raises(DataError, match=rf"{utimes[2]}.bin: no points \(an empty file\)$"):
        dataset.read_scan(2)


def _mulran(root, n_scans: int, n_poses: int):
    (root / "Ouster").mkdir(parents=True)
    ns = 1_600_000_000_000_000_000 + np.arange(n_scans) * 100_000_000
    for stamp in ns:
        np.column_stack([RING, np.ones(len(RING))]).astype(np.float32).tofile(root / "Ouster" / f"{stamp}.bin")
    with open(root / "global_pose.csv", "w") as f:
        for k in range(n_poses):
            f.write(f"{ns[k]}," + ",".join(f"{v:g}" for v in np.eye(4)[:3].ravel() + np.array([0, 0, 0, k, 0, 0, 0, 0, 0, 0, 0, 0])) + "\n")
    return ns


def test_mulran_stamps_and_a_pose_file_that_ends_before_the_scans(tmp_path):
    ns = _mulran(tmp_path / "full", 4, 4)
    dataset = open_dataset("mulran", tmp_path / "full")
    np.testing.assert_allclose(dataset.timestamps_s, ns * 1e-9)
    assert len(dataset.ground_truth) == 4
    _mulran(tmp_path / "half", 6, 3)  # the last 3 scans got the last pose, silently
    with pytest.raises(DataError, match=r"global_pose.csv: 3 of 6 scans \(the first: scan 3\) lie outside the poses' time span"):
        open_dataset("mulran", tmp_path / "half").ground_truth


def test_mulran_scans_the_pose_file_covers_are_scored_on_their_own(tmp_path):
    """``--frames`` within the span of ``global_pose.csv``: the run is scored on those scans (the whole recording's
    pairing refused it); a selection reaching past the span names its first scan outside."""
    from lidarkit.odometry import run

    _mulran(tmp_path / "half", 6, 3)
    _mulran(tmp_path / "full", 3, 3)  # the same first three scans and poses, nothing uncovered
    dataset = open_dataset("mulran", tmp_path / "half")
    expected = open_dataset("mulran", tmp_path / "full").ground_truth.poses_se3
    np.testing.assert_allclose(dataset.ground_truth_of([0, 1, 2]).poses_se3, expected, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(expected[:, :3, 3], axis=1), [0.0, 1.0, 2.0], atol=1e-4)  # 1 m apart, as written
    with pytest.raises(DataError, match=r"1 of 2 selected scans \(the first: scan 3\) lie outside"):
        dataset.ground_truth_of([2, 3])
    result = run(dataset, "vanilla", frames="0:3")
    np.testing.assert_allclose(np.linalg.norm(result.ground_truth.poses_se3[:, :3, 3], axis=1), [0.0, 1.0, 2.0], atol=1e-4)


def test_helipr_reads_every_point_and_checks_the_pose_rows(tmp_path):
    folder = tmp_path / "LiDAR" / "Ouster"
    folder.mkdir(parents=True)
    (tmp_path / "LiDAR_GT").mkdir()
    dtype = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("i", "<f4"), ("t", "<u4"), ("r", "<u2"), ("ring", "<u2"), ("a", "<u2")])
    ns = 1_690_000_000_000_000_000 + np.arange(3) * 100_000_000
    for stamp in ns:
        record = np.zeros(len(RING), dtype=dtype)
        record["x"], record["y"], record["z"] = RING.T
        record["t"] = np.arange(len(RING)) * 1000
        record.tofile(folder / f"{stamp}.bin")
    rows = [f"{stamp} {k} 0 0 0 0 0 1" for k, stamp in enumerate(ns)]
    (tmp_path / "LiDAR_GT" / "global_Ouster_gt.txt").write_text("\n".join(rows) + "\n")
    dataset = open_dataset("helipr", tmp_path, sequence="Ouster")
    scan = dataset.read_scan(0)
    np.testing.assert_allclose(scan.points_xyz, RING.astype(np.float32), atol=1e-6)  # the last point was dropped
    np.testing.assert_allclose(scan.point_times_s, np.linspace(0, 1, len(RING)))
    np.testing.assert_allclose(dataset.timestamps_s, ns * 1e-9)
    (tmp_path / "LiDAR_GT" / "global_Ouster_gt.txt").write_text("\n".join(rows[:2]) + "\n")
    with pytest.raises(DataError, match=r"global_Ouster_gt.txt: 2 ground-truth poses for 3 scans"):  # numpy's broadcast error
        open_dataset("helipr", tmp_path, sequence="Ouster")


def _helipr_velodyne(root, sweep_times):
    """A HeLiPR Velodyne recording (x y z intensity float32, ring uint16, time float32) of one scan per row of
    ``sweep_times`` (the time field of each of its points), with one ground-truth pose per scan."""
    folder = root / "LiDAR" / "Velodyne"
    folder.mkdir(parents=True)
    (root / "LiDAR_GT").mkdir()
    dtype = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("i", "<f4"), ("ring", "<u2"), ("t", "<f4")])
    ns = 1_690_000_000_000_000_000 + np.arange(len(sweep_times)) * 100_000_000
    for stamp, times in zip(ns, sweep_times):
        record = np.zeros(len(RING), dtype=dtype)
        record["x"], record["y"], record["z"] = RING.T
        record["t"] = times
        record.tofile(folder / f"{stamp}.bin")
    (root / "LiDAR_GT" / "global_Velodyne_gt.txt").write_text("".join(f"{s} {k} 0 0 0 0 0 1\n" for k, s in enumerate(ns)))
    return [folder / f"{stamp}.bin" for stamp in ns]


def test_a_helipr_time_field_of_one_value_reads_as_a_bags_and_nan_times_name_the_file(tmp_path):
    """kiss-icp's HeLiPR loader divided a time field of one value by its zero span (numpy's RuntimeWarning, then NaN
    times refused naming the recording's folder): the scan is read as a bag's, its times all equal, which the run
    reads as no per-point times and says so. NaN times are refused naming the scan file, not the folder."""
    import warnings

    from lidarkit.odometry import run

    _helipr_velodyne(tmp_path / "flat", [np.zeros(len(RING))] * 3)
    dataset = open_dataset("helipr", tmp_path / "flat", sequence="Velodyne")
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        scan = dataset.read_scan(0)
    np.testing.assert_array_equal(scan.point_times_s, np.zeros(len(RING)))
    assert not scan.has_time_span()
    result = run(dataset, "kiss")
    said = "deskew requested, the per-point times of 3 of 3 frames are all equal (nothing to deskew with): ran without deskew"
    assert said in result.metrics["warnings"]
    sweep = np.linspace(0.0, 0.1, len(RING))
    with_nan = sweep.copy()
    with_nan[7] = np.nan
    files = _helipr_velodyne(tmp_path / "nan", [sweep, with_nan])
    dataset = open_dataset("helipr", tmp_path / "nan", sequence="Velodyne")
    np.testing.assert_allclose(dataset.read_scan(0).point_times_s, np.linspace(0, 1, len(RING)), atol=1e-6)
    with pytest.raises(DataError, match=rf"^{re.escape(str(files[1]))} \(frame 1\): per-point times contain NaN or infinite values$"):
        dataset.read_scan(1)


def test_boreas_pose_rows_are_checked_before_the_loader_asserts(tmp_path):
    (tmp_path / "lidar").mkdir()
    (tmp_path / "applanix").mkdir()
    for k in range(3):
        np.zeros((10, 6), np.float32).tofile(tmp_path / "lidar" / f"{1606417230000000 + k * 100000}.bin")
    header = "GPSTime,easting,northing,altitude,vel_east,vel_north,vel_up,roll,pitch,heading,angvel_z,angvel_y,angvel_x\n"
    (tmp_path / "applanix" / "lidar_poses.csv").write_text(header + "1606417230.0" + ",0" * 12 + "\n")
    with pytest.raises(DataError, match=r"lidar_poses.csv: 1 ground-truth poses for 3 scans"):  # an AssertionError without text
        open_dataset("boreas", tmp_path)
    rows = "".join(f"{1606417230.0 + 0.1 * k}" + ",0" * 12 + "\n" for k in range(3))
    (tmp_path / "applanix" / "lidar_poses.csv").write_text(header + rows)
    np.testing.assert_allclose(open_dataset("boreas", tmp_path).timestamps_s, 1606417230.0 + 0.1 * np.arange(3))  # (none before)


def test_newer_college_binary_pcd_without_pyntcloud(tmp_path):
    import open3d as o3d

    (tmp_path / "raw_format" / "ouster_scan").mkdir(parents=True)
    (tmp_path / "ground_truth").mkdir()
    rows = []
    for k in range(2):
        secs, nsecs = 1583836591 + k, 182590976
        cloud = o3d.t.geometry.PointCloud(o3d.core.Tensor(RING.astype(np.float32)))
        o3d.t.io.write_point_cloud(str(tmp_path / "raw_format" / "ouster_scan" / f"cloud_{secs}_{nsecs}.pcd"), cloud)
        rows.append(f"{secs},{nsecs},{k},0,0,0,0,0,1")
    (tmp_path / "ground_truth" / "registered_poses.csv").write_text("\n".join(rows) + "\n")
    dataset = open_dataset("ncd", tmp_path)
    np.testing.assert_allclose(dataset.read_scan(1).points_xyz, RING.astype(np.float32), atol=1e-6)
    assert len(dataset.ground_truth) == 2
    # stamped by the file names' seconds and nanoseconds (kiss-icp's loader sorts by them and gave none)
    np.testing.assert_allclose(dataset.timestamps_s, 1583836591.182590976 + np.arange(2), rtol=0, atol=1e-6)
    np.testing.assert_allclose(dataset.ground_truth.timestamps_s, dataset.timestamps_s)


def test_apollo_scans_and_ground_truth_take_the_stamps_of_the_pose_file(tmp_path):
    """poses/gt_poses.txt holds each scan's time (its second column), yet the scans and the ground truth had none;
    stamps that go back are refused naming the line."""
    import open3d as o3d

    (tmp_path / "pcds").mkdir()
    (tmp_path / "poses").mkdir()
    stamps = 1537574000.6 + 0.1 * np.arange(3)
    for k in range(3):
        cloud = o3d.t.geometry.PointCloud(o3d.core.Tensor((RING + k).astype(np.float32)))
        o3d.t.io.write_point_cloud(str(tmp_path / "pcds" / f"{k + 1}.pcd"), cloud)
    rows = [f"{k + 1} {stamp:.6f} {587001 + k} 4140000 100 0 0 0 1" for k, stamp in enumerate(stamps)]
    (tmp_path / "poses" / "gt_poses.txt").write_text("\n".join(rows) + "\n")
    dataset = open_dataset("apollo", tmp_path)
    np.testing.assert_allclose(dataset.timestamps_s, stamps, rtol=0, atol=1e-6)
    assert dataset.read_scan(1).timestamp_s == pytest.approx(stamps[1], abs=1e-6)
    np.testing.assert_allclose(dataset.ground_truth.timestamps_s, stamps, rtol=0, atol=1e-6)
    np.testing.assert_allclose(dataset.ground_truth.poses_se3[:, 0, 3], [0, 1, 2])  # (kiss-icp's: from the first pose)
    rows[2] = rows[2].replace(f"{stamps[2]:.6f}", f"{stamps[0]:.6f}")
    (tmp_path / "poses" / "gt_poses.txt").write_text("\n".join(rows) + "\n")
    with pytest.raises(DataError, match=r"gt_poses.txt \(line 3\): time stamps \(column 2\) are not strictly increasing"):
        open_dataset("apollo", tmp_path).timestamps_s


def test_a_file_the_generic_loader_cannot_read_is_named_once(tmp_path):
    """A scan the loader cannot read: "generic:mixed (frame 1): mixed (frame 1): kiss-icp's generic loader failed"
    named the folder twice and not the file."""
    from lidarkit.errors import LidarKitError
    from lidarkit.odometry import run

    import open3d as o3d

    o3d.t.io.write_point_cloud(str(tmp_path / "scan1.pcd"), o3d.t.geometry.PointCloud(o3d.core.Tensor(RING.astype(np.float32))))
    (tmp_path / "scan2.pcd").write_bytes(b"not a point cloud\n")
    with pytest.raises(LidarKitError) as err:
        run(f"generic:{tmp_path}", "vanilla")
    # (the point-file readers' header check speaks before the loader's KeyError)
    assert str(err.value) == f"{tmp_path / 'scan2.pcd'} (frame 1): truncated .pcd header (no DATA line)"


def test_a_generic_folder_of_several_formats_is_refused_and_skipped_files_are_named(tmp_path, caplog):
    """kiss-icp's generic loader reads every file as the first one's format (.pcd read as .bin: a reshape error or NaN
    points) and only lower-case suffixes it knows (scan2.BIN and .npy scans were left out without a word)."""
    import open3d as o3d

    mixed, other = tmp_path / "mixed", tmp_path / "other"
    mixed.mkdir()
    other.mkdir()
    for k in range(2):
        RING.astype(np.float32).tofile(mixed / f"a{k}.bin")
        o3d.t.io.write_point_cloud(str(mixed / f"a{k + 2}.pcd"), o3d.t.geometry.PointCloud(o3d.core.Tensor(RING.astype(np.float32))))
    with pytest.raises(DataError, match=r"mixed: point-cloud files of 2 formats \(2 \.bin, 2 \.pcd\): kiss-icp's generic loader reads "
                                        r"every file as the first one's format; keep one format, or read the folder as folder:PATH$"):
        open_dataset("generic", mixed)
    np.column_stack([RING, np.zeros(len(RING))]).astype(np.float32).tofile(other / "scan1.bin")
    for name in ("scan2.BIN", "scan3.npy", "notes.txt"):
        (other / name).write_bytes(b"")
    with caplog.at_level(logging.WARNING):
        assert len(open_dataset("generic", other)) == 1
    assert f"{other}: 2 point-cloud files that kiss-icp's generic loader does not read are skipped (scan2.BIN, scan3.npy); " \
           "folder:PATH reads them" in caplog.text


def test_files_the_generic_loader_leaves_out_are_in_the_run_folders_warnings(tmp_path):
    """The generic reader only logged the point-cloud files kiss-icp's loader does not read: a run over 000000-2.bin
    with 000003.npy and 000004.BIN beside them wrote 3 frames and no warning about the other two to metrics.json or
    config.yaml."""
    import json

    import yaml
    from registration_helpers import structured_cloud

    from lidarkit.odometry import run

    folder = tmp_path / "mixed"
    folder.mkdir()
    cloud = structured_cloud(np.random.default_rng(0), 3000)
    for k in range(3):
        np.column_stack([cloud + [0.3 * k, 0.0, 0.0], np.zeros(len(cloud))]).astype(np.float32).tofile(folder / f"00000{k}.bin")
    np.save(folder / "000003.npy", cloud)
    np.column_stack([cloud, np.zeros(len(cloud))]).astype(np.float32).tofile(folder / "000004.BIN")
    result = run(f"generic:{folder}", "vanilla", out_dir=tmp_path / "out")
    said = ("2 point-cloud files that kiss-icp's generic loader does not read are skipped (000003.npy, 000004.BIN); "
            "folder:PATH reads them")
    assert len(result.trajectory) == 3 and result.metrics["warnings"][0] == said
    assert json.loads((tmp_path / "out" / "metrics.json").read_text())["warnings"][0] == said
    assert yaml.safe_load((tmp_path / "out" / "config.yaml").read_text())["run"]["warnings"][0] == said


def test_generic_reads_files_named_by_decimal_time_stamps_in_time_order(tmp_path):
    """kiss-icp's natsort read 1000.1 before 1000.05 (the digits after the dot as a number): 20 Hz sweeps out of order;
    generic: now reads the files in folder:PATH's order."""
    for k, stamp in enumerate(("1000.05", "1000.1", "1000.15", "1000.2")):
        np.column_stack([RING + k, np.zeros(len(RING))]).astype(np.float32).tofile(tmp_path / f"{stamp}.bin")
    dataset = open_dataset("generic", tmp_path)
    assert [p.split("/")[-1] for p in dataset.loader.scan_files] == ["1000.05.bin", "1000.1.bin", "1000.15.bin", "1000.2.bin"]
    np.testing.assert_allclose(dataset.read_scan(1).points_xyz, (RING + 1).astype(np.float32))


def test_generic_reads_prefixed_decimal_time_stamps_in_time_order(tmp_path):
    """scan_1000.05 ... scan_1000.2: the fraction after a prefix was compared as a second number (scan_1000.1 read
    before scan_1000.05), as folder:PATH did."""
    stamps = ("1000.05", "1000.1", "1000.15", "1000.2")
    for k, stamp in enumerate(stamps):
        np.column_stack([RING + k, np.zeros(len(RING))]).astype(np.float32).tofile(tmp_path / f"scan_{stamp}.bin")
    dataset = open_dataset("generic", tmp_path)
    assert [p.split("/")[-1] for p in dataset.loader.scan_files] == [f"scan_{stamp}.bin" for stamp in stamps]
    np.testing.assert_allclose(dataset.read_scan(1).points_xyz, (RING + 1).astype(np.float32))


def test_generic_leaves_out_points_at_the_sensor_origin_with_their_times(tmp_path):
    """kiss-icp's generic loader kept points at exactly (0, 0, 0) (an organized cloud's missing returns), which every
    point-file reader leaves out: registered, they are points moving with the sensor. They are left out with their
    per-point times, said once per reader; a scan of nothing else is a DataError naming the file."""
    import open3d as o3d

    times = np.linspace(0.0, 0.1, len(RING))
    missing = np.arange(len(RING)) % 4 == 0  # 50 of 200
    for k in range(2):
        points = RING + [k, 0.0, 0.0]
        points[missing] = 0.0
        cloud = o3d.t.geometry.PointCloud(o3d.core.Tensor(points.astype(np.float32)))
        cloud.point["t"] = o3d.core.Tensor(times.astype(np.float32)[:, None])
        o3d.t.io.write_point_cloud(str(tmp_path / f"{k:06d}.pcd"), cloud)
    dataset = open_dataset("generic", tmp_path)
    for k in range(2):
        scan = dataset.read_scan(k)
        np.testing.assert_array_equal(scan.points_xyz, (RING + [k, 0.0, 0.0])[~missing].astype(np.float32))
        np.testing.assert_array_equal(scan.point_times_s, times[~missing].astype(np.float32))
    assert dataset.reader_warnings == [f"left out 50 of 200 points at (0, 0, 0) (missing returns) in frame 0 ({tmp_path / '000000.pcd'}); "
                                       "in later frames without another warning"]
    cloud = o3d.t.geometry.PointCloud(o3d.core.Tensor(np.zeros((10, 3), dtype=np.float32)))
    cloud.point["t"] = o3d.core.Tensor(np.linspace(0, 0.1, 10, dtype=np.float32)[:, None])
    o3d.t.io.write_point_cloud(str(tmp_path / "000002.pcd"), cloud)
    with pytest.raises(DataError, match=r"000002\.pcd \(frame 2\): all 10 points are at \(0, 0, 0\) \(missing returns\): no point left$"):
        open_dataset("generic", tmp_path).read_scan(2)


def test_generic_reads_integer_time_fields_as_nanoseconds_and_checks_headers_first(tmp_path):
    """kiss-icp's generic loader hands every field over as float64: an Ouster cloud's uint32 ``t`` (ns from the sweep
    start) was read as seconds, a 0.1 s sweep as one of 99,500 s. Integers are nanoseconds now, as the bag reader
    reads them. A .pcd without z failed as "pip install kiss-icp[all] is required" with Open3D's coloured warnings:
    the point-file readers' header checks come first, naming the file."""
    import open3d as o3d

    ns = np.linspace(0, 99_500_000, len(RING)).astype(np.uint32)
    for k in range(2):
        cloud = o3d.t.geometry.PointCloud(o3d.core.Tensor((RING + [k, 0.0, 0.0]).astype(np.float32)))
        cloud.point["t"] = o3d.core.Tensor(ns[:, None])
        o3d.t.io.write_point_cloud(str(tmp_path / f"{k:06d}.pcd"), cloud)
    scan = open_dataset("generic", tmp_path).read_scan(1)
    np.testing.assert_allclose(scan.point_times_s, ns * 1e-9)
    assert scan.point_time_convention == "relative_s"

    no_z = tmp_path / "no_z"
    no_z.mkdir()
    body = RING[:, :2].astype(np.float32)
    header = ("VERSION .7\nFIELDS x y\nSIZE 4 4\nTYPE F F\nCOUNT 1 1\nWIDTH 200\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 200\n"
              "DATA binary\n")
    (no_z / "000000.pcd").write_bytes(header.encode() + body.tobytes())
    with pytest.raises(DataError, match=r"^\S+000000\.pcd: no z field \(FIELDS x y\): positions are read from fields named x, y and z"):
        open_dataset("generic", no_z)
    (tmp_path / "000002.pcd").write_bytes(header.encode() + body.tobytes())  # a later file: refused when read, by name
    with pytest.raises(DataError, match=r"000002\.pcd \(frame 2\): no z field"):
        open_dataset("generic", tmp_path).read_scan(2)


def test_generic_points_with_nan_are_refused_naming_the_file_or_dropped_when_asked(tmp_path):
    """A .pcd whose missing returns are NaN (as PCL and Ouster write organized clouds) reached the registration, which
    refused it naming neither the file nor a way out ("generic:... (frame 0): frame: 300 of 3000 points are NaN"), and
    generic: had no drop_nonfinite option. Now the reader says it, as the point-file readers do, and drops them (with
    their per-point times) when asked."""
    import open3d as o3d

    points = np.vstack([RING, RING + [0.0, 0.0, 1.0]])
    times = np.linspace(0.0, 0.1, len(points))
    missing = np.arange(len(points)) % 8 == 3  # 50 of 400
    points[missing] = np.nan
    for k in range(2):
        cloud = o3d.t.geometry.PointCloud(o3d.core.Tensor(points.astype(np.float32)))
        cloud.point["time"] = o3d.core.Tensor(times.astype(np.float32)[:, None])
        o3d.t.io.write_point_cloud(str(tmp_path / f"{k:06d}.pcd"), cloud)
    with pytest.raises(DataError, match=r"000001\.pcd \(frame 1\): 50 of 400 points are NaN or infinite \(first at point 3\); "
                                        r"drop them with drop_nonfinite=true \(generic:PATH\?drop_nonfinite=true\)$"):
        open_dataset("generic", tmp_path).read_scan(1)
    dataset = open_dataset("generic", f"{tmp_path}", drop_nonfinite=True)
    scan = dataset.read_scan(1)
    np.testing.assert_array_equal(scan.points_xyz, points[~missing].astype(np.float32))
    np.testing.assert_allclose(scan.point_times_s, times[~missing].astype(np.float32))
    assert dataset.reader_warnings[0].startswith("left out 50 of 400 points with NaN or infinite coordinates in frame 1")


def test_generic_refuses_integer_times_in_microseconds(tmp_path):
    """uint32 times in microseconds were read as nanoseconds by generic: (a 0.1 s sweep of 1e-4 s, no word), where the
    bag and KITTI readers refuse them: with no stamps to compare, a sweep under a millisecond is refused."""
    import open3d as o3d

    us = np.linspace(0, 99_500, len(RING)).astype(np.uint32)
    for k in range(2):
        cloud = o3d.t.geometry.PointCloud(o3d.core.Tensor((RING + [k, 0.0, 0.0]).astype(np.float32)))
        cloud.point["t"] = o3d.core.Tensor(us[:, None])
        o3d.t.io.write_point_cloud(str(tmp_path / f"{k:06d}.pcd"), cloud)
    with pytest.raises(DataError, match=r"000001\.pcd \(frame 1\): the 't' field: sweeps of 9\.95e-05 s \(this scan\), under "
                                        r"0\.001 s: read as integer nanoseconds, the unit looks like microseconds"):
        open_dataset("generic", tmp_path).read_scan(1)


def test_kiss_kitti_ground_truth_is_stamped_by_the_scans_times(tmp_path):
    """times.txt stamps the scans, yet the ground truth had no stamps: it takes those of the scans present (frames 5
    and 6 of an excerpt: their own rows of times.txt, not the first two)."""
    import shutil

    from conftest import shared_path

    seq = tmp_path / "sequences" / "00"
    (seq / "velodyne").mkdir(parents=True)
    (tmp_path / "poses").mkdir()
    for n in (5, 6):
        shutil.copy(shared_path("kitti_odometry", "sequences", "00", "velodyne", f"{n:06d}.bin"), seq / "velodyne")
    shutil.copy(shared_path("kitti_odometry", "sequences", "00", "calib.txt"), seq)
    shutil.copy(shared_path("kitti_odometry", "sequences", "00", "times.txt"), seq)
    rows = shared_path("kitti_odometry", "poses", "00.txt").read_text().splitlines()[:7]
    (tmp_path / "poses" / "00.txt").write_text("\n".join(rows) + "\n")
    times = np.loadtxt(seq / "times.txt")[[5, 6]]
    dataset = open_dataset("kiss_kitti", tmp_path, sequence="00")
    np.testing.assert_array_equal(dataset.timestamps_s, times)
    np.testing.assert_array_equal(dataset.ground_truth.timestamps_s, times)
    np.testing.assert_allclose(dataset.ground_truth.poses_se3, open_dataset("kitti", tmp_path).ground_truth.poses_se3, atol=1e-5)


def test_a_kiss_kind_without_drop_nonfinite_names_a_reader_that_has_it(tmp_path):
    """The NaN refusal told every kiss-icp kind to use drop_nonfinite=true, which only generic and ncd take
    (kiss_kitti: 'unknown option drop_nonfinite'): it names the readers of the files themselves."""
    import shutil

    from conftest import shared_path

    seq = tmp_path / "sequences" / "00"
    (seq / "velodyne").mkdir(parents=True)
    (tmp_path / "poses").mkdir()
    for n in (0, 1):
        shutil.copy(shared_path("kitti_odometry", "sequences", "00", "velodyne", f"{n:06d}.bin"), seq / "velodyne")
    shutil.copy(shared_path("kitti_odometry", "sequences", "00", "calib.txt"), seq)
    rows = shared_path("kitti_odometry", "poses", "00.txt").read_text().splitlines()[:2]
    (tmp_path / "poses" / "00.txt").write_text("\n".join(rows) + "\n")
    scan = np.fromfile(seq / "velodyne" / "000001.bin", dtype=np.float32).reshape(-1, 4)
    scan[10, 0] = np.nan
    scan.tofile(seq / "velodyne" / "000001.bin")
    with pytest.raises(DataError, match=r"000001\.bin \(frame 1\): 1 of \d+ points are NaN or infinite \(first at point 10\); the "
                                        r"kiss_kitti reader keeps every point \(kiss-icp's loader\): a reader of the files "
                                        r"themselves \(kitti:, folder:\) drops them with drop_nonfinite=true$"):
        open_dataset("kiss_kitti", tmp_path, sequence="00").read_scan(1)


def test_ouster_meta_given_by_a_relative_name_is_looked_up_beside_the_pcap(tmp_path, monkeypatch):
    """``meta=sensor.json`` named the json beside the pcap, as other readers' path options name files beside their
    data; run from another folder it was refused as "not found". It is found there (what follows is the ouster-sdk
    step), and a name found in neither place says both."""
    from lidarkit.errors import LidarKitError
    from lidarkit.io.kiss_loaders import OusterScans, ouster_metadata

    recording = tmp_path / "drive"
    recording.mkdir()
    (recording / "run.pcap").write_bytes(b"\xd4\xc3\xb2\xa1")
    (recording / "sensor.json").write_text("{}")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    with pytest.raises(LidarKitError) as err:  # (without ouster-sdk: the ConfigError naming its pip line)
        OusterScans(recording / "run.pcap", meta="sensor.json")
    assert "metadata json not found" not in str(err.value)
    assert ouster_metadata(recording / "run.pcap", "sensor.json") == str(recording / "sensor.json")
    with pytest.raises(DataError, match=re.escape(f"other.json: Ouster metadata json not found, neither from the working "
                                                  f"directory nor beside the pcap in {recording}")):
        ouster_metadata(recording / "run.pcap", "other.json")


def _ply_scans(folder, time_type: str, n_scans: int = 3):
    """``n_scans`` binary .ply scans of RING whose per-point time field ``t`` has the PLY type ``time_type`` (uint:
    nanoseconds, float: seconds)."""
    folder.mkdir(parents=True, exist_ok=True)
    stored = {"uint": "<u4", "float": "<f4"}[time_type]
    record = np.zeros(len(RING), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("t", stored)])
    record["t"] = np.linspace(0, 99_000_000 if time_type == "uint" else 0.099, len(RING))
    for k in range(n_scans):
        record["x"], record["y"], record["z"] = (RING + [k, 0.0, 0.0]).T
        header = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(RING)}\nproperty float x\nproperty float y\n"
                  f"property float z\nproperty {time_type} t\nend_header\n")
        (folder / f"{k}.ply").write_bytes(header.encode() + record.tobytes())
    return [folder / f"{k}.ply" for k in range(n_scans)]


def test_a_ply_time_field_of_a_type_open3d_skips_is_named_by_the_generic_reader(tmp_path):
    """Open3D skips a .ply property of type uint (as ushort, short, char): generic: ran without deskew saying only "no
    per-point times found". The reader names the field, its type and what to store instead."""
    _ply_scans(tmp_path / "uint", "uint")
    dataset = open_dataset("generic", tmp_path / "uint")
    assert dataset.read_scan(0).point_times_s is None
    assert dataset.reader_warnings == ["per-point times not read: the scans carry them in the 't' field, of PLY type uint "
                                       "(e.g. 0.ply), which Open3D cannot read (kiss-icp's generic loader reads with it); "
                                       "store them as float, double or int"]
    _ply_scans(tmp_path / "float", "float")
    readable = open_dataset("generic", tmp_path / "float")
    assert readable.reader_warnings == []
    np.testing.assert_allclose(readable.read_scan(0).point_times_s, np.linspace(0, 0.099, len(RING)), atol=1e-7)


def _tum_folder(root, gt_stamps):
    """A TUM RGB-D folder of 8 depth frames at 30 Hz (80 x 60, a slanted wall), with comment lines as TUM writes them,
    and one ground-truth pose at each of ``gt_stamps``: x = 10 * (t - t0), the identity rotation."""
    import open3d as o3d

    (root / "depth").mkdir(parents=True)
    (root / "rgb").mkdir()
    rows, cols = np.mgrid[0:60, 0:80]
    o3d.io.write_image(str(root / "rgb" / "0.png"), o3d.geometry.Image(np.zeros((60, 80, 3), np.uint8)))
    stamps = 1305031099.665900 + np.arange(8) / 30
    lines = ["# depth maps", "# file: 'x.bag'", "# timestamp filename"]
    for k, stamp in enumerate(stamps):
        depth = (5000 + 20 * cols + 10 * rows + 30 * ((rows // 10 + cols // 10 + k) % 2)).astype(np.uint16)  # 1 mm per unit / 5
        o3d.io.write_image(str(root / "depth" / f"{stamp:.6f}.png"), o3d.geometry.Image(depth))
        lines.append(f"{stamp:.6f} depth/{stamp:.6f}.png")
    (root / "depth.txt").write_text("\n".join(lines) + "\n")
    gt = ["# ground truth trajectory", "# file: 'x.bag'", "# timestamp tx ty tz qx qy qz qw"]
    gt += [f"{t:.4f} {10 * (t - stamps[0]):.4f} 0 0 0 0 0 1" for t in gt_stamps]
    (root / "groundtruth.txt").write_text("\n".join(gt) + "\n")
    return stamps


def test_kiss_tum_pairs_each_depth_frame_with_its_nearest_pose_and_names_a_gap(tmp_path):
    """kiss-icp's TUM loader gave each depth frame the nearest pose at any distance and merged the frames sharing one:
    a gap in groundtruth.txt refused the whole run ("6 ground-truth poses for 8 scans"). Frames pair with a pose within
    0.02 s, as the tum reader pairs images; the first frame without one is named, and --frames scores the others."""
    from lidarkit.odometry import run

    t0 = 1305031099.665900
    every = t0 - 0.5 + 0.01 * np.arange(120)
    stamps = _tum_folder(tmp_path / "whole", every)
    whole = open_dataset("kiss_tum", tmp_path / "whole")
    np.testing.assert_allclose(whole.ground_truth.poses_se3, np.asarray(whole.loader.gt_poses), atol=1e-12)  # kiss-icp's
    np.testing.assert_allclose(whole.ground_truth.timestamps_s, stamps)
    gap = every[(every < t0 + 0.12) | (every > t0 + 0.19)]  # frames 4 (t0 + 0.133) and 5 (t0 + 0.167) without a pose
    _tum_folder(tmp_path / "gap", gap)
    dataset = open_dataset("kiss_tum", tmp_path / "gap")
    with pytest.raises(DataError, match=r"groundtruth\.txt: 2 of 8 depth frames have no pose within 0\.02 s, the first: frame 4 "
                                        r"at t=1305031099\.799233 s \(the nearest pose is 0\.023 s away\)"):
        dataset.ground_truth
    np.testing.assert_allclose(dataset.ground_truth_of([0, 1, 2]).poses_se3[:, 0, 3], [0.0, 0.3, 0.7], atol=0.011)
    with pytest.raises(DataError, match=r"1 of 2 selected depth frames have no pose within 0\.02 s, the first: frame 5"):
        dataset.ground_truth_of([5, 6])
    result = run(dataset, "vanilla", frames="0:3")
    np.testing.assert_allclose(result.ground_truth.poses_se3[:, 0, 3], [0.0, 0.3, 0.7], atol=0.011)


def test_kiss_tum_comment_lines_give_no_python_warnings(tmp_path, caplog):
    """numpy warned six lines about the comment lines of every TUM folder kiss-icp's loader opened: they are logged
    at debug level, as what the loaders print."""
    import warnings

    _tum_folder(tmp_path, 1305031099.665900 + 0.01 * np.arange(-10, 40))
    with warnings.catch_warnings(record=True) as shown, caplog.at_level(logging.DEBUG, logger="lidarkit.io.rosbag"):
        warnings.simplefilter("always")
        dataset = open_dataset("kiss_tum", tmp_path)
    assert len(dataset) == 8
    assert [str(w.message) for w in shown] == []
    assert "tum loader warned: UserWarning: Input line 1 contained no data" in caplog.text


def test_a_pose_file_kiss_icp_cannot_read_is_named_with_its_line(tmp_path):
    """A ground-truth file the loader cannot read failed in numpy's words naming the folder ("not enough values to
    unpack", "could not convert string 'timestamp'"); its rows are read first, naming the file and line."""
    import open3d as o3d

    apollo = tmp_path / "apollo"
    (apollo / "pcds").mkdir(parents=True)
    (apollo / "poses").mkdir()
    for k in range(3):
        o3d.t.io.write_point_cloud(str(apollo / "pcds" / f"{k + 1}.pcd"), o3d.t.geometry.PointCloud(o3d.core.Tensor(RING.astype(np.float32))))
    rows = [f"{k + 1} {1537574000.6 + 0.1 * k:.6f} {k} 0 0 0 0 0 1" for k in range(3)]
    rows[1] = rows[1][: rows[1].rindex(" ")]  # 8 numbers: no qw
    (apollo / "poses" / "gt_poses.txt").write_text("\n".join(rows) + "\n")
    with pytest.raises(DataError, match=r"gt_poses\.txt \(line 2\): expected 9 numbers, found 8$"):
        open_dataset("apollo", apollo)

    _mulran(tmp_path / "mulran", 3, 3)
    pose_file = tmp_path / "mulran" / "global_pose.csv"
    pose_file.write_text("timestamp,r11,r12,r13,x,r21,r22,r23,y,r31,r32,r33,z\n" + pose_file.read_text())
    with pytest.raises(DataError, match=r"global_pose\.csv \(line 1\): not a number: 'timestamp'$"):
        open_dataset("mulran", tmp_path / "mulran")

    boreas = tmp_path / "boreas"
    (boreas / "lidar").mkdir(parents=True)
    (boreas / "applanix").mkdir()
    for k in range(3):
        np.zeros((10, 6), np.float32).tofile(boreas / "lidar" / f"{1606417230000000 + k * 100000}.bin")
    header = "GPSTime,easting,northing,altitude,vel_east,vel_north,vel_up,roll,pitch,heading,angvel_z,angvel_y,angvel_x\n"
    rows = [f"{1606417230.0 + 0.1 * k}" + ",0" * 12 for k in range(3)]
    (boreas / "applanix" / "lidar_poses.csv").write_text(header + "\n".join([rows[0], rows[1][:-2], rows[2]]) + "\n")
    with pytest.raises(DataError, match=r"lidar_poses\.csv \(line 3\): expected 13 numbers, found 12$"):
        open_dataset("boreas", boreas)

    helipr = tmp_path / "helipr"
    _helipr_velodyne(helipr, [np.linspace(0, 0.1, len(RING))] * 2)
    (helipr / "LiDAR_GT" / "global_Velodyne_gt.txt").write_text("1690000000000000000 0 0 0 0 0 0 1\n1690000000100000000 1 0 0 0 0 1\n")
    with pytest.raises(DataError, match=r"global_Velodyne_gt\.txt \(line 2\): expected 8 numbers, found 7$"):
        open_dataset("helipr", helipr, sequence="Velodyne")


def test_a_loader_read_in_another_thread_leaves_the_main_threads_warnings_alone(caplog, recwarn):
    """catch_warnings around each frame's loader call in the reading-ahead thread is process-wide: a warning of the
    main thread meanwhile was taken as the loader's and only logged at debug level."""
    import logging
    import threading
    import warnings

    from lidarkit.io.rosbag import guarded_loader

    inside, release = threading.Event(), threading.Event()

    def read():
        with guarded_loader("generic", "scans", location="frame 3"):
            inside.set()
            release.wait(5.0)

    reader = threading.Thread(target=read)
    with caplog.at_level(logging.DEBUG, logger="lidarkit.io.rosbag"):
        reader.start()
        assert inside.wait(5.0)
        warnings.warn("the main thread's own warning", UserWarning, stacklevel=1)
        release.set()
        reader.join(5.0)
    assert not [r for r in caplog.records if "the main thread's own warning" in r.getMessage()]
    assert [str(w.message) for w in recwarn] == ["the main thread's own warning"]  # (shown to the main thread's filters)


def test_kiss_kitti_reads_nanosecond_times_as_the_kitti_reader_does(tmp_path):
    """A times.txt in nanoseconds was read as seconds by kiss_kitti (1.6e18 "s" written to poses_tum.txt) where the kitti
    reader converts it: one rule for both."""
    import shutil

    from conftest import shared_path

    seq = tmp_path / "sequences" / "00"
    (seq / "velodyne").mkdir(parents=True)
    for n in (0, 1):
        shutil.copy(shared_path("kitti_odometry", "sequences", "00", "velodyne", f"{n:06d}.bin"), seq / "velodyne")
    shutil.copy(shared_path("kitti_odometry", "sequences", "00", "calib.txt"), seq)
    seconds = 1.6e9 + np.loadtxt(shared_path("kitti_odometry", "sequences", "00", "times.txt"))[:2]
    (seq / "times.txt").write_text("".join(f"{int(round(t * 1e9))}\n" for t in seconds))
    (tmp_path / "poses").mkdir()  # (kiss-icp's loader needs them)
    rows = shared_path("kitti_odometry", "poses", "00.txt").read_text().splitlines()[:2]
    (tmp_path / "poses" / "00.txt").write_text("\n".join(rows) + "\n")
    np.testing.assert_allclose(open_dataset("kiss_kitti", tmp_path, sequence="00").timestamps_s, seconds, rtol=0, atol=1e-6)
    np.testing.assert_array_equal(open_dataset("kiss_kitti", tmp_path, sequence="00").timestamps_s,
                                  open_dataset("kitti", tmp_path).timestamps_s)


def test_an_empty_or_unreadable_scan_of_a_kiss_loader_is_named_by_its_file(tmp_path):
    """generic: and apollo: named the folder and "frame 2" for an empty .bin, and called a garbage PCD (whose reading
    error the loader swallowed) an "empty scan": the file is named, with the reason; scans are named by their file."""
    import shutil

    from conftest import shared_path

    for n in range(4):
        shutil.copy(shared_path("kitti_odometry", "sequences", "00", "velodyne", f"{n:06d}.bin"), tmp_path)
    (tmp_path / "000002.bin").write_bytes(b"")
    dataset = open_dataset("generic", tmp_path)
    assert dataset.read_scan(1).source == str(tmp_path / "000001.bin")
    with pytest.raises(DataError) as caught:
        dataset.read_scan(2)
    assert str(caught.value) == f"{tmp_path / '000002.bin'} (frame 2): empty scan file (0 bytes)"
    apollo = tmp_path / "apollo"
    (apollo / "pcds").mkdir(parents=True)
    (apollo / "poses").mkdir()
    points = np.fromfile(tmp_path / "000000.bin", dtype=np.float32).reshape(-1, 4)[::50, :3]
    header = ("VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
              f"WIDTH {len(points)}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {len(points)}\nDATA binary\n")
    for n in (1, 2, 3):  # (Apollo numbers its scans from 1.pcd)
        (apollo / "pcds" / f"{n}.pcd").write_bytes(header.encode() + points.astype("<f4").tobytes())
        with open(apollo / "poses" / "gt_poses.txt", "a") as poses:
            poses.write(f"{n} {1500000000 + 0.1 * n:.6f} {float(n)} 0 0 0 0 0 1\n")
    (apollo / "pcds" / "2.pcd").write_text("garbage\n")
    dataset = open_dataset("apollo", apollo)
    assert dataset.read_scan(0).source == str(apollo / "pcds" / "1.pcd")
    with pytest.raises(DataError) as caught:
        dataset.read_scan(1)
    assert str(caught.value) == f"{apollo / 'pcds' / '2.pcd'} (frame 1): no points read: an empty or unreadable scan file"
