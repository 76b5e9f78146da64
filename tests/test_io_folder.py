"""ScanFolder on the real PCD pair and KITTI bins, synthetic npy/ply folders, and corrupted copies."""

from __future__ import annotations

import logging
import shutil
from pathlib import Path

import numpy as np
import pytest
from conftest import shared_path

from lidarkit.errors import ConfigError, DataError
from lidarkit.io import open_dataset
from lidarkit.io.base import ScanSequence
from lidarkit.io.folder import ScanFolder, natural_key, sorted_by_name
from lidarkit.trajectory import Trajectory


def _npy_folder(tmp_path, rng, names=("scan1.npy", "scan10.npy", "scan2.npy"), ncols=4):
    folder = tmp_path / "scans"
    folder.mkdir(parents=True)
    arrays = {}
    for k, name in enumerate(names):
        arr = rng.normal(size=(50 + k, ncols)).astype(np.float32)
        np.save(folder / name, arr)
        arrays[name] = arr
    return folder, arrays


def test_real_pcd_pair_with_intensity():
    folder = shared_path("lidar_pairs")
    ds = open_dataset("folder", folder)
    assert isinstance(ds, ScanSequence)
    assert [p.name for p in ds.scan_paths] == ["251370668.pcd", "251371071.pcd"]
    target, source = ds.read_scan(0), ds.read_scan(1)
    # SOURCES.md's 69088 and 69792 points less the 5032 and 5107 missing returns stored at (0, 0, 0)
    assert target.points_xyz.shape == (64056, 3) and source.points_xyz.shape == (64685, 3)
    assert target.intensity is not None and target.intensity.shape == (64056,)
    assert np.linalg.norm(target.points_xyz, axis=1).max() == pytest.approx(77.6, abs=0.1)
    assert target.frame == 0 and source.frame == 1 and ds.ground_truth is None and ds.timestamps_s is None


def test_points_at_the_sensor_origin_are_left_out_said_once_per_file_or_folder(tmp_path, rng, caplog):
    """The LiDAR pair's missing returns, stored as (0, 0, 0), were registered as real points (vanilla ICP: t 0.31 m
    where relative.txt has 0.49 m; 0.44 m without them) and --drop-nonfinite changed nothing; now left out with a
    warning once per file read on its own, once per folder for a sequence (not once per frame)."""
    from lidarkit.io.pointfile import read_point_file

    pcd = shared_path("lidar_pairs", "251370668.pcd")
    with caplog.at_level(logging.WARNING, logger="lidarkit.io.pointfile"):
        scan = read_point_file(pcd)
        read_point_file(pcd)
    assert scan.points_xyz.shape == (64056, 3) and scan.intensity.shape == (64056,)
    assert np.abs(scan.points_xyz).sum(axis=1).min() > 0
    assert [r.getMessage() for r in caplog.records] == [f"{pcd} (scan): left out 5032 of 69088 points at (0, 0, 0) (missing returns)"] * 2
    folder, arrays = _npy_folder(tmp_path, rng)
    for k, name in enumerate(arrays):
        arrays[name][: k + 2] = 0.0  # x, y, z and intensity zero: 2, 3, 4 missing returns
        np.save(folder / name, arrays[name])
    ds = ScanFolder(folder)
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="lidarkit.io.pointfile"):
        sizes = [len(ds.read_scan(k).points_xyz) for k in range(3)]
    assert sizes == [50 - 2, 52 - 4, 51 - 3]  # scan1, scan2, scan10
    assert [r.getMessage() for r in caplog.records] == [
        f"{folder / 'scan1.npy'} (frame 0): left out 2 of 50 points at (0, 0, 0) (missing returns); later scans in "
        f"{folder.absolute()}: left out without another warning"]
    np.save(folder / "scan1.npy", np.zeros((7, 3)))
    with pytest.raises(DataError) as err:
        ds.read_scan(0)
    assert str(err.value) == f"{folder / 'scan1.npy'} (frame 0): all 7 points are at (0, 0, 0) (missing returns): no point left"


def test_an_empty_npy_says_it_holds_no_points(tmp_path):
    """An empty .npy (np.zeros((0, 3))) said "scan has no finite points"; it says the file holds 0 points, as an
    empty .bin says "empty scan file (0 bytes)"."""
    from lidarkit.io.pointfile import read_point_file

    np.save(tmp_path / "empty.npy", np.zeros((0, 3)))
    with pytest.raises(DataError) as err:
        read_point_file(tmp_path / "empty.npy")
    assert str(err.value) == f"{tmp_path / 'empty.npy'}: empty scan file (0 points)"


def test_kitti_bins_and_poses(tmp_path):
    root = shared_path("kitti_odometry")
    folder = root / "extra_frames" / "00" / "velodyne"
    rows = np.loadtxt(root / "poses" / "00.txt")[[94, 95, 198, 199]]
    poses = tmp_path / "poses.txt"
    np.savetxt(poses, rows)
    ds = ScanFolder(folder, poses=poses, timestamps=[9.745342, 9.849229, 20.52747, 20.63096])
    assert len(ds) == 4 and ds.read_scan(2).points_xyz.shape[0] == 1968544 // 16
    np.testing.assert_allclose(ds.ground_truth.poses_se3[:, :3, :4].reshape(-1, 12), rows)
    assert ds.read_scan(3).timestamp_s == pytest.approx(20.63096)


def test_natural_sort_and_npy_columns(tmp_path, rng):
    folder, arrays = _npy_folder(tmp_path, rng)
    ds = ScanFolder(folder)
    assert [p.name for p in ds.scan_paths] == ["scan1.npy", "scan2.npy", "scan10.npy"]
    scan = ds.read_scan(2)
    np.testing.assert_array_equal(scan.points_xyz, arrays["scan10.npy"][:, :3].astype(np.float64))
    np.testing.assert_array_equal(scan.intensity, arrays["scan10.npy"][:, 3])
    assert sorted(["f10", "f9", "F1", "f1a"], key=natural_key) == ["F1", "f1a", "f9", "f10"]
    folder3, _ = _npy_folder(tmp_path / "xyz", rng, names=("a.npy",), ncols=3)
    assert ScanFolder(folder3).read_scan(0).intensity is None
    # the same scans also saved as .bin: read as twice as many frames, every other one the same scan
    for name, points in arrays.items():
        points.astype(np.float32).tofile(folder / name.replace(".npy", ".bin"))
    with pytest.raises(DataError, match=r"two files for scan 'scan1' \(scan1.bin, scan1.npy\)"):
        ScanFolder(folder)
    assert len(ScanFolder(folder, suffixes=".npy")) == 3


def test_files_named_by_decimal_time_stamps_are_read_in_time_order(tmp_path, rng):
    """The digits after a stamp's dot were compared as a number (1000.1, 1000.2, 1000.05, 1000.15: 5 > 1), so sweeps
    named by 20 Hz stamps were read out of order without a word; nanosecond stamps must not be rounded as floats."""
    names = ("1000.2.npy", "1000.05.npy", "1000.15.npy", "1000.1.npy", "999.95.npy", "1000.npy")
    folder, arrays = _npy_folder(tmp_path, rng, names=names)
    ds = ScanFolder(folder)
    assert [p.name for p in ds.scan_paths] == ["999.95.npy", "1000.npy", "1000.05.npy", "1000.1.npy", "1000.15.npy", "1000.2.npy"]
    np.testing.assert_array_equal(ds.read_scan(2).points_xyz, arrays["1000.05.npy"][:, :3].astype(np.float64))
    stamps = ["1317354879.12345679.bin", "1317354879.123456789.bin", "1317354879.1234567889.bin"]
    assert sorted(stamps, key=natural_key) == [stamps[2], stamps[1], stamps[0]]
    assert sorted(["scan10.npy", "scan2.npy", "1.5.npy"], key=natural_key) == ["1.5.npy", "scan2.npy", "scan10.npy"]


def test_decimal_time_stamps_after_a_prefix_are_read_in_time_order(tmp_path, rng):
    """scan_1000.05 ... scan_1000.2 were read 1000.1, 1000.2, 1000.05, 1000.15 (only a name that was a stamp alone
    compared its fraction as a decimal), and a TUM file stamped 1000.05 ... paired its poses with shuffled scans."""
    stamps = ("1000.05", "1000.1", "1000.15", "1000.2")
    names = tuple(f"scan_{stamp}.npy" for stamp in stamps[::-1])
    folder, arrays = _npy_folder(tmp_path, rng, names=names)
    (folder / "gt.tum").write_text("".join(f"{stamp} {k} 0 0 0 0 0 1\n" for k, stamp in enumerate(stamps)))
    ds = ScanFolder(folder, poses="gt.tum", poses_format="tum")
    assert [p.name for p in ds.scan_paths] == [f"scan_{stamp}.npy" for stamp in stamps]
    np.testing.assert_array_equal(ds.read_scan(1).points_xyz, arrays["scan_1000.1.npy"][:, :3].astype(np.float64))
    np.testing.assert_allclose(ds.timestamps_s, [1000.05, 1000.1, 1000.15, 1000.2])
    assert ds.read_scan(2).timestamp_s == pytest.approx(1000.15)  # (its own stamp, and the pose written beside it)
    np.testing.assert_allclose(ds.ground_truth.poses_se3[:, 0, 3], [0, 1, 2, 3])
    # names with other numbers keep their order: numbers by value, a version's digits as before
    assert sorted(["frame_10.bin", "frame_2.bin", "frame_1.bin"], key=natural_key) == ["frame_1.bin", "frame_2.bin", "frame_10.bin"]
    assert sorted(["000010.bin", "000002.bin", "000001.bin"], key=natural_key) == ["000001.bin", "000002.bin", "000010.bin"]
    assert sorted(["scan_v1.2_10.bin", "scan_v1.3_1.bin", "scan_v1.2_3.bin"], key=natural_key) == [
        "scan_v1.2_3.bin", "scan_v1.2_10.bin", "scan_v1.3_1.bin"]
    assert sorted(["scan_1000.05.bin", "scan_1000.bin", "scan_999.95.bin"], key=natural_key) == [
        "scan_999.95.bin", "scan_1000.bin", "scan_1000.05.bin"]


def test_dotted_counters_keep_counting_order(tmp_path, rng):
    """run_2.10 after run_2.9: a fraction ending in 0 beside shorter ones is a counter (it came before 2.2)."""
    names = [f"run_2.{i}" for i in range(1, 12)]
    for i, name in enumerate(names):
        np.save(tmp_path / f"{name}.npy", np.full((5, 4), float(i), np.float32) + rng.normal(size=(5, 4)).astype(np.float32))
    ds = ScanFolder(tmp_path)
    assert [p.stem for p in ds.scan_paths] == names
    # stamps written without trailing zeros, or to a fixed width, still sort as decimals
    assert [p.name for p in sorted_by_name([Path(f"s_{t}.npy") for t in ("1000.1", "1000.05", "1000.15", "1000.2")])] == [
        "s_1000.05.npy", "s_1000.1.npy", "s_1000.15.npy", "s_1000.2.npy"]
    assert [p.name for p in sorted_by_name([Path(f"s_{t}.npy") for t in ("1000.10", "1000.05", "1000.20")])] == [
        "s_1000.05.npy", "s_1000.10.npy", "s_1000.20.npy"]
    # Python's str() of a 20 Hz clock: 0.0, 0.05, 0.1, ... (the lone "0" fraction read the folder as counters)
    stamps = [str(round(i * 0.05, 2)) for i in range(12)]
    assert [p.stem for p in sorted_by_name([Path(f"{t}.npy") for t in reversed(stamps)])] == stamps


def test_ply_round_trip_keeps_intensity(tmp_path, rng):
    import open3d as o3d

    folder = tmp_path / "ply"
    folder.mkdir()
    xyz = rng.uniform(-20, 20, size=(200, 3)).astype(np.float32)
    intensity = rng.uniform(0, 1, size=(200, 1)).astype(np.float32)
    cloud = o3d.t.geometry.PointCloud(o3d.core.Tensor(xyz))
    cloud.point["intensity"] = o3d.core.Tensor(intensity)
    assert o3d.t.io.write_point_cloud(str(folder / "0.ply"), cloud)
    scan = ScanFolder(folder).read_scan(0)
    np.testing.assert_allclose(scan.points_xyz, xyz, atol=1e-6)
    np.testing.assert_allclose(scan.intensity, intensity[:, 0], atol=1e-6)


def test_tum_poses_give_timestamps(tmp_path, rng):
    folder, _ = _npy_folder(tmp_path, rng)
    traj = Trajectory(np.tile(np.eye(4), (3, 1, 1)), np.array([10.0, 10.1, 10.2]))
    traj.to_tum(tmp_path / "poses.tum")
    ds = ScanFolder(folder, poses=tmp_path / "poses.tum", poses_format="tum")
    np.testing.assert_allclose(ds.timestamps_s, [10.0, 10.1, 10.2])
    assert ds.read_scan(1).timestamp_s == pytest.approx(10.1)


def test_tum_stamps_replaced_by_timestamps_far_apart_are_a_warning(tmp_path, rng, caplog):
    """A TUM ground truth stamped 10.0, 10.1, 10.2 s took ``timestamps=`` 110.0, 110.1, 110.2 s without a word (an image
    folder warns); more than half a frame apart is now a logged warning, within it none."""
    folder, _ = _npy_folder(tmp_path, rng)
    Trajectory(np.tile(np.eye(4), (3, 1, 1)), np.array([10.0, 10.1, 10.2])).to_tum(tmp_path / "poses.tum")
    with caplog.at_level(logging.WARNING, logger="lidarkit.io.folder"):
        ds = ScanFolder(folder, poses=tmp_path / "poses.tum", poses_format="tum", timestamps=[110.0, 110.1, 110.2])
    np.testing.assert_allclose(ds.ground_truth.timestamps_s, [110.0, 110.1, 110.2])
    assert [r.getMessage() for r in caplog.records] == [
        f"{tmp_path / 'poses.tum'}: pose 0 is stamped 100.000 s from its scan's time stamp (half a frame is 0.050 s); "
        "poses and scans are paired by order, one each, and the poses take the stamps of timestamps="]
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="lidarkit.io.folder"):
        ScanFolder(folder, poses=tmp_path / "poses.tum", poses_format="tum", timestamps=[10.02, 10.12, 10.22])
    assert not caplog.records


# ---- errors -----------------------------------------------------------------------------------------------
def test_poses_count_must_match_scans(tmp_path, rng):
    folder, _ = _npy_folder(tmp_path, rng)
    poses = tmp_path / "poses.txt"
    np.savetxt(poses, np.tile(np.eye(4)[:3].reshape(1, 12), (5, 1)))
    with pytest.raises(DataError, match=r"poses\.txt: 5 poses for 3 scans in .*scans"):
        ScanFolder(folder, poses=poses)
    with pytest.raises(DataError, match=r"2 time stamps for 3 scans"):
        ScanFolder(folder, timestamps=[0.0, 0.1])
    times = tmp_path / "times.txt"
    times.write_text("0.0\n0.2\n0.1\n")
    with pytest.raises(DataError, match=r"times\.txt \(frame 2\): time stamps are not strictly increasing"):
        ScanFolder(folder, timestamps=times)


def test_malformed_poses_line(tmp_path, rng):
    folder, _ = _npy_folder(tmp_path, rng)
    poses = tmp_path / "poses.txt"
    poses.write_text("1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1\n1 0 0 0 0 1 0 0 0 0 1 0\n")
    with pytest.raises(DataError, match=r"poses\.txt \(line 2\): expected 12 numbers, found 11"):
        ScanFolder(folder, poses=poses)


def test_a_poses_file_of_the_other_format_names_the_poses_format_option(tmp_path, rng):
    """A KITTI poses file read as TUM (and the reverse) said "read it as kitti: --format kitti, Trajectory.from_kitti":
    options odometry does not have. Inside a dataset spec the option is poses_format=."""
    folder, _ = _npy_folder(tmp_path, rng)
    traj = Trajectory(np.tile(np.eye(4), (3, 1, 1)), np.array([10.0, 10.1, 10.2]))
    traj.to_kitti(tmp_path / "poses.txt")
    traj.to_tum(tmp_path / "poses.tum")
    with pytest.raises(DataError) as err:
        ScanFolder(folder, poses=tmp_path / "poses.txt", poses_format="tum")
    assert str(err.value) == (f"{tmp_path / 'poses.txt'} (line 1): expected 8 numbers, found 12 (a KITTI trajectory? read it "
                              "as kitti: poses_format=kitti)")
    with pytest.raises(DataError) as err:
        ScanFolder(folder, poses=tmp_path / "poses.tum")
    assert str(err.value).endswith("(a TUM trajectory? read it as tum: poses_format=tum)")


def test_relative_poses_and_timestamps_are_looked_up_in_the_scan_folder(tmp_path, rng, monkeypatch):
    """poses=poses.txt with the file beside the scans was "poses.txt: file not found": only the working directory was
    looked in. As the kitti reader does, the working directory comes first, then the scan folder; neither is named."""
    folder, _ = _npy_folder(tmp_path, rng)
    rows = np.tile(np.eye(4)[:3].reshape(1, 12), (3, 1))
    rows[:, 3] = [0.0, 1.0, 2.0]
    np.savetxt(folder / "poses.txt", rows)
    (folder / "times.txt").write_text("0\n0.1\n0.2\n")
    monkeypatch.chdir(tmp_path)
    ds = open_dataset("folder", "scans", poses="poses.txt", timestamps="times.txt")
    assert ds.poses_path == folder.relative_to(tmp_path) / "poses.txt"
    np.testing.assert_array_equal(ds.ground_truth.poses_se3[:, 0, 3], [0.0, 1.0, 2.0])
    np.testing.assert_array_equal(ds.timestamps_s, [0.0, 0.1, 0.2])
    np.savetxt(tmp_path / "poses.txt", rows * 0 + np.eye(4)[:3].reshape(1, 12))  # the working directory's comes first
    assert ScanFolder("scans", poses="poses.txt").ground_truth.poses_se3[:, 0, 3].tolist() == [0.0, 0.0, 0.0]
    with pytest.raises(DataError) as err:
        ScanFolder("scans", poses="nope.txt")
    assert str(err.value) == "nope.txt: file not found, neither from the working directory nor in the scan folder scans"


def test_nonfinite_pcd_points(tmp_path, caplog):
    folder = tmp_path / "pcd"
    folder.mkdir()
    header = "VERSION 0.7\nFIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\n"
    body = "1 2 3 0.5\nnan 2 3 0.1\n4 inf 6 0.2\n7 8 9 0.3\n"
    (folder / "000.pcd").write_text(header + "WIDTH 4\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 4\nDATA ascii\n" + body)
    with pytest.raises(DataError, match=r"000\.pcd \(frame 0\): 2 of 4 points are NaN or infinite \(first at point 1\)"):
        ScanFolder(folder).read_scan(0)
    with caplog.at_level(logging.WARNING):
        scan = ScanFolder(folder, drop_nonfinite=True).read_scan(0)
    np.testing.assert_allclose(scan.points_xyz, [[1, 2, 3], [7, 8, 9]])
    np.testing.assert_allclose(scan.intensity, [0.5, 0.3])
    assert "dropped 2 of 4" in caplog.text


def test_corrupt_files(tmp_path, copy_of):
    pcd = copy_of(shared_path("lidar_pairs", "251370668.pcd"))
    data = pcd.read_bytes()
    pcd.write_bytes(data[: len(data) // 2])
    with pytest.raises(DataError, match=r"251370668\.pcd \(frame 0\): the header declares 69088 points .* holds 552610 bytes"):
        ScanFolder(pcd.parent, suffixes=(".pcd",)).read_scan(0)
    folder = tmp_path / "bins"
    folder.mkdir()
    shutil.copy2(shared_path("kitti_odometry", "sequences", "00", "velodyne", "000001.bin"), folder / "a.bin")
    with open(folder / "a.bin", "ab") as f:
        f.write(b"\0" * 7)
    with pytest.raises(DataError, match=r"a\.bin \(frame 0\): truncated"):
        ScanFolder(folder).read_scan(0)
    np.save(folder / "b.npy", np.zeros((10, 5)))
    with pytest.raises(DataError, match=r"b\.npy \(frame 1\): expected a numeric \(N, 3\) or \(N, 4\) array"):
        ScanFolder(folder).read_scan(1)


def test_missing_or_empty_folder_and_bad_options(tmp_path):
    with pytest.raises(DataError, match="scan folder not found"):
        ScanFolder(tmp_path / "nope")
    (tmp_path / "notes.txt").write_text("x")
    with pytest.raises(DataError, match=r"no scan files \(\.bin, \.npy, \.pcd, \.ply\)"):
        ScanFolder(tmp_path)
    with pytest.raises(ConfigError, match="unknown poses format 'g2o'; known: kitti, tum"):
        ScanFolder(tmp_path, poses_format="g2o")
    with pytest.raises(ConfigError, match="unsupported scan suffix '.las'"):
        ScanFolder(tmp_path, suffixes=(".las",))
    np.save(tmp_path / "a.npy", np.zeros((5, 3)))
    np.zeros((5, 4), np.float32).tofile(tmp_path / "b.bin")
    from lidarkit.io import open_dataset
    from lidarkit.odometry.inputs import open_sequence

    assert len(open_sequence(f"folder:{tmp_path}?suffixes=.npy,.bin")) == 2  # the text, not its characters ('.')
    assert len(open_dataset("folder", tmp_path, suffixes=".npy")) == 1
    with pytest.raises(ConfigError, match="unsupported scan suffix '.las'"):
        open_sequence(f"folder:{tmp_path}?suffixes=.npy,.las")


def test_a_kitti_raw_drive_folder_read_as_a_scan_folder_names_kitti_raw(tmp_path):
    """lidarkit odometry raw/2011_09_26/2011_09_26_drive_0002_sync said "no scan files (.bin, ...)" with no word of
    kitti_raw:PATH, though the folder's name is a drive's."""
    drive = tmp_path / "2011_09_26" / "2011_09_26_drive_0002_sync"
    (drive / "velodyne_points" / "data").mkdir(parents=True)
    with pytest.raises(DataError) as err:
        open_dataset("folder", drive)
    assert str(err.value) == f"{drive}: no scan files (.bin, .npy, .pcd, .ply); a KITTI raw drive folder: read it as kitti_raw:PATH"
    with pytest.raises(DataError) as err:
        open_dataset("folder", drive.parent)
    assert str(err.value) == f"{drive.parent}: no scan files (.bin, .npy, .pcd, .ply)"


def test_cut_or_garbled_files_are_refused_not_read_as_garbage(tmp_path, rng):
    """A cut .ply (Open3D returned its full vertex count with leftover memory for the tail), an ascii .pcd row with a
    word or a missing value (read as zeros), an .npz under an .npy name and an empty .npy: each a DataError."""
    import open3d as o3d

    from lidarkit.io.pointfile import read_point_file

    xyz = rng.uniform(-20, 20, size=(2000, 3)).astype(np.float32)
    for name, ascii_body in (("bin.ply", False), ("text.ply", True)):
        path = tmp_path / name
        assert o3d.t.io.write_point_cloud(str(path), o3d.t.geometry.PointCloud(o3d.core.Tensor(xyz)), write_ascii=ascii_body)
        data = path.read_bytes()
        path.write_bytes(data[: len(data) // 2])
        with pytest.raises(DataError, match=rf"{name}: truncated: the header declares 2000 vertices"):
            read_point_file(path)
    header = "VERSION 0.7\nFIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\nWIDTH 2\nHEIGHT 1\nPOINTS 2\nDATA ascii\n"
    for body, message in (("1 2 3 0.5\n1 2 x 4\n", "ascii point 1 is not numbers: '1 2 x 4'"),
                          ("1 2 3 0.5\n1 2 3\n", "ascii point 1 has 3 values, the header declares 4")):
        (tmp_path / "a.pcd").write_text(header + body)
        with pytest.raises(DataError, match=message):
            read_point_file(tmp_path / "a.pcd")
    with open(tmp_path / "z.npy", "wb") as fh:
        np.savez(fh, a=np.zeros((5, 3)))
    with pytest.raises(DataError, match=r"z.npy: not an .npy array \(a NpzFile: an .npz archive\?\)"):
        read_point_file(tmp_path / "z.npy")
    (tmp_path / "e.npy").write_bytes(b"\x93NUMPY\x01\x00")
    with pytest.raises(DataError, match=r"e.npy: not a readable .npy array"):
        read_point_file(tmp_path / "e.npy")


def test_the_run_config_records_the_folder_s_stamps_and_suffixes(tmp_path, rng):
    """Two runs over one folder with other timestamps= files wrote the same config.yaml (only created_utc differed)."""
    import yaml

    from lidarkit.odometry.settings import reader_settings

    folder, _ = _npy_folder(tmp_path, rng)
    (tmp_path / "t.txt").write_text("0\n0.1\n0.2\n")
    options = reader_settings(ScanFolder(folder, timestamps=tmp_path / "t.txt", suffixes=".npy"))
    assert options["timestamps"] == str((tmp_path / "t.txt").absolute()) and options["suffixes"] == ".npy"
    assert reader_settings(ScanFolder(folder, timestamps=[0.0, 0.1, 0.2]))["timestamps"] == "3 values given"
    assert reader_settings(ScanFolder(folder))["timestamps"] is None
    assert yaml.safe_dump(options)  # plain values
    # the run's dataset_options name the poses file too (two runs with other poses= files had the same options)
    (tmp_path / "gt.txt").write_text("1 0 0 0 0 1 0 0 0 0 1 0\n" * 3)
    named = ScanFolder(folder, poses=tmp_path / "gt.txt").reader_options
    assert (named["poses_path"], named["poses_format"]) == (str((tmp_path / "gt.txt").absolute()), "kitti")


def test_poses_format_without_poses_is_refused(tmp_path, rng):
    """folder:scans?poses_format=tum without poses= ran without a word (an option with no effect, a poses file
    forgotten): a ConfigError naming the option; with poses= it reads as before, kitti the default."""
    from lidarkit.odometry.inputs import open_sequence

    folder, _ = _npy_folder(tmp_path, rng)
    for opened in (lambda: ScanFolder(folder, poses_format="tum"), lambda: open_sequence(f"folder:{folder}?poses_format=kitti")):
        with pytest.raises(ConfigError) as err:
            opened()
        assert str(err.value) == "poses_format: has no effect without poses= (the poses file whose format it names)"
    np.savetxt(tmp_path / "poses.txt", np.tile(np.eye(4)[:3].reshape(1, 12), (3, 1)))
    assert ScanFolder(folder, poses=tmp_path / "poses.txt").poses_format == "kitti"
    assert len(ScanFolder(folder, poses=tmp_path / "poses.txt", poses_format="kitti").ground_truth) == 3
    assert ScanFolder(folder).reader_options["poses_format"] == "kitti"


def test_a_scan_folder_given_as_dot_is_named_after_itself(tmp_path, monkeypatch):
    """`lidarkit odometry .` in a folder of scans titled the run "vanilla on " and recorded name ''."""
    from lidarkit.io.folder import ScanFolder

    folder = tmp_path / "drive_a"
    folder.mkdir()
    for i in range(3):
        np.save(folder / f"{i:06d}.npy", np.random.default_rng(i).normal(size=(100, 3)))
    monkeypatch.chdir(folder)
    assert ScanFolder(".").name == "drive_a"


def test_points_dropped_as_nonfinite_are_said_once_in_the_runs_warnings(tmp_path):
    """``folder:...?drop_nonfinite=true`` left NaN points out with a log line only: the run's metrics.json said nothing
    (kiss-icp's generic loader does say it). The reader keeps one line, the first frame's, for the run's warnings."""
    from lidarkit.odometry import run

    folder = tmp_path / "scans"
    folder.mkdir()
    rng = np.random.default_rng(4)
    cloud = rng.uniform(-20, 20, size=(400, 3)).astype(np.float32)
    for k in range(4):
        scan = cloud + np.float32(0.1 * k)
        if k >= 2:
            scan[7 + k] = np.nan
        np.save(folder / f"{k:06d}.npy", scan)
    said = (f"left out 1 of 400 points with NaN or infinite values in frame 2 ({folder / '000002.npy'}); in later frames "
            "without another warning")
    reader = ScanFolder(folder, drop_nonfinite=True)
    assert [len(reader.read_scan(k).points_xyz) for k in range(4)] == [400, 400, 399, 399]
    assert getattr(reader, "reader_warnings", None) == [said]
    result = run(ScanFolder(folder, drop_nonfinite=True), "vanilla", out_dir=tmp_path / "run")
    import json

    assert said in json.loads((tmp_path / "run" / "metrics.json").read_text())["warnings"]
    assert result.metrics["warnings"].count(said) == 1


def test_a_ply_time_field_of_a_type_open3d_skips_is_not_said_to_be_read_by_generic(tmp_path):
    """A folder of .ply scans whose time field ``t`` is a PLY uint (as Ouster writes nanoseconds) was said to be read
    by generic:PATH, which reads nothing of it (Open3D skips uint, ushort, short and char properties); a float one is."""
    for kind in ("uint", "float"):
        header = (f"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                  f"property {kind} t\nend_header\n")
        (tmp_path / kind).mkdir()
        (tmp_path / kind / "0.ply").write_text(header + "1 0 0 0\n0 1 0 5\n0 0 1 9\n")
    skipped = ScanFolder(tmp_path / "uint")
    assert skipped.unread_point_times == ("t", tmp_path / "uint" / "0.ply", False)
    assert skipped.unread_point_time_type == "uint"
    readable = ScanFolder(tmp_path / "float")
    assert readable.unread_point_times == ("t", tmp_path / "float" / "0.ply", True)
    assert readable.unread_point_time_type is None


def test_tum_stamps_far_from_timestamps_are_kept_in_the_reader_warnings_and_the_runs(tmp_path):
    """The warning that a TUM ground truth's stamps lie far from ``timestamps=`` was only logged: the run's metrics.json
    did not say its poses took other stamps. It is kept once in ``reader_warnings``, and so in the run's warnings."""
    from lidarkit.odometry import run
    from lidarkit.sim.lidar import SimulatedLidarSequence

    sim = SimulatedLidarSequence(n_frames=4, n_beams=8, n_azimuths=180, seed=2)
    scans = tmp_path / "scans"
    scans.mkdir()
    for k in range(len(sim)):
        np.save(scans / f"{k:06d}.npy", sim.read_scan(k).points_xyz.astype(np.float32))
    truth = sim.ground_truth
    Trajectory(truth.poses_se3, truth.timestamps_s).to_tum(tmp_path / "poses.tum")
    far = ScanFolder(scans, poses=tmp_path / "poses.tum", poses_format="tum", timestamps=truth.timestamps_s + 100.0)
    said = (f"{tmp_path / 'poses.tum'}: pose 0 is stamped 100.000 s from its scan's time stamp (half a frame is 0.050 s); "
            "poses and scans are paired by order, one each, and the poses take the stamps of timestamps=")
    assert far.reader_warnings == [said]
    assert run(far, "vanilla").metrics["warnings"].count(said) == 1
    near = ScanFolder(scans, poses=tmp_path / "poses.tum", poses_format="tum", timestamps=truth.timestamps_s + 0.02)
    assert near.reader_warnings == []


def test_nanosecond_time_stamps_in_a_timestamps_file_are_refused_naming_it(tmp_path, rng):
    """A timestamps file in nanoseconds ran: the run wrote poses_tum.txt stamped 1.4e18 s, which lidarkit eval then
    refused; the reader refuses it as the trajectory readers do, naming the file and line."""
    for k in range(3):
        np.save(tmp_path / f"{k:06d}.npy", rng.normal(size=(50, 3)).astype(np.float32))
    stamps = tmp_path.parent / f"{tmp_path.name}_ns.txt"
    stamps.write_text("".join(f"{1403715524907143168 + k * 100000000}\n" for k in range(3)))
    with pytest.raises(DataError, match=r"_ns\.txt \(line 1, frame 0\): time stamp 1403715524907143168 is beyond 1e\+11 s"):
        ScanFolder(tmp_path, timestamps=stamps)
