"""KITTI odometry reader on the real sequence-00 excerpt and image sequences 06/01, plus corrupted copies."""

from __future__ import annotations

import logging
import shutil

import numpy as np
import pytest
from conftest import shared_path

from lidarkit.errors import ConfigError, DataError
from lidarkit.geometry import pose_error, se3_inverse
from lidarkit.io import available_datasets, open_dataset
from lidarkit.io.base import ImageSequence, ScanSequence
from lidarkit.io.kitti import KittiOdometry, read_kitti_calib
from lidarkit.io.pointfile import read_kitti_bin


@pytest.fixture
def odo_root():
    return shared_path("kitti_odometry")


@pytest.fixture
def extra(odo_root):
    """Sequence 00 calib/poses/times with the non-contiguous scans 94, 95, 198, 199."""
    return KittiOdometry(odo_root, "00", velodyne_dir=odo_root / "extra_frames" / "00" / "velodyne")


def _scan_copy(tmp_path, odo_root, name="000000.bin"):
    """A writable folder holding a copy of one real scan."""
    folder = tmp_path / "velodyne"
    folder.mkdir()
    shutil.copy2(odo_root / "sequences" / "00" / "velodyne" / name, folder / name)
    return folder / name


# ---- real data ------------------------------------------------------------------------------------------
def test_scan_000000_matches_raw_file(odo_root):
    ds = open_dataset("kitti", odo_root, sequence="00")
    assert isinstance(ds, ScanSequence)
    assert len(ds) == ds.n_scans == 10 and ds.n_images == 0
    assert list(ds.frames) == list(range(10))
    scan = ds.read_scan(0)
    raw = np.fromfile(odo_root / "sequences" / "00" / "velodyne" / "000000.bin", dtype=np.float32).reshape(-1, 4)
    assert scan.points_xyz.shape == (124668, 3) and scan.points_xyz.dtype == np.float64
    np.testing.assert_array_equal(scan.points_xyz, raw[:, :3].astype(np.float64))
    np.testing.assert_array_equal(scan.intensity, raw[:, 3])
    assert scan.frame == 0 and scan.timestamp_s == 0.0
    ranges = np.linalg.norm(scan.points_xyz, axis=1)
    assert 1.0 < ranges.min() and 75.0 < ranges.max() < 85.0  # HDL-64 range, per SOURCES.md 1.3-80.4 m
    assert ds.read_scan(-1).frame == 9
    assert ds.timestamps_s[1] == pytest.approx(0.1037359)


def test_calib_and_intrinsics(odo_root):
    ds = KittiOdometry(odo_root, 0)
    calib = ds.calib
    assert {"P0", "P1", "P2", "P3", "Tr"} <= set(calib)
    assert calib["P0"].shape == (3, 4) and calib["Tr"].shape == (4, 4)
    np.testing.assert_allclose(ds.K, [[718.856, 0, 607.1928], [0, 718.856, 185.2157], [0, 0, 1]])
    baseline_m = -calib["P1"][0, 3] / calib["P1"][0, 0]
    assert baseline_m == pytest.approx(0.5372, abs=1e-4)
    Tr = calib["Tr"]
    np.testing.assert_allclose(Tr[:3, :3] @ Tr[:3, :3].T, np.eye(3), atol=1e-5)
    # Tr maps LiDAR to camera: LiDAR forward (+x) becomes camera forward (+z), LiDAR up (+z) camera -y
    np.testing.assert_allclose(Tr[:3, :3] @ [1, 0, 0], [0, 0, 1], atol=0.02)
    np.testing.assert_allclose(Tr[:3, :3] @ [0, 0, 1], [0, -1, 0], atol=0.02)


def test_first_lidar_pose_is_identity_and_motion_is_along_lidar_x(odo_root):
    ds = KittiOdometry(odo_root, "00")
    gt = ds.ground_truth
    assert ds.ground_truth_frame == "lidar"
    np.testing.assert_array_equal(gt.poses_se3, ds.ground_truth_lidar.poses_se3)
    camera_gt = KittiOdometry(odo_root, "00", ground_truth_frame="camera").ground_truth
    np.testing.assert_array_equal(camera_gt.poses_se3, ds.ground_truth_camera.poses_se3)
    assert len(gt) == 10 and gt.timestamps_s is not None
    np.testing.assert_allclose(gt.relative_to_first().poses_se3[0], np.eye(4), atol=1e-6)
    np.testing.assert_allclose(gt.poses_se3[0], np.eye(4), atol=1e-6)  # P_0 is the identity in 00.txt
    step_lidar = gt.relative_motions()[0][:3, 3]
    step_camera = ds.ground_truth_camera.relative_motions()[0][:3, 3]
    assert 0.8 < step_lidar[0] < 0.92 and abs(step_lidar[1]) < 0.1 and abs(step_lidar[2]) < 0.1
    assert 0.8 < step_camera[2] < 0.92 and abs(step_camera[0]) < 0.1  # camera frame: forward is +z
    assert len(ds.ground_truth_at(None, frame="camera")) == 4541


def test_noncontiguous_frames_index_gt_rows(odo_root, extra):
    assert list(extra.frames) == [94, 95, 198, 199]
    np.testing.assert_allclose(extra.timestamps_s, [9.745342, 9.849229, 20.52747, 20.63096])
    assert extra.read_scan_by_frame(95).frame == 95 and extra.read_scan(1).frame == 95
    rows = np.loadtxt(odo_root / "poses" / "00.txt")
    np.testing.assert_allclose(extra.ground_truth_camera.poses_se3[:, :3, :4].reshape(-1, 12), rows[[94, 95, 198, 199]])
    gt = extra.ground_truth
    for a, b, forward_m in ((0, 1, 0.474), (2, 3, 0.514)):  # measured from poses/00.txt + calib Tr
        T_a_b = se3_inverse(gt.poses_se3[a]) @ gt.poses_se3[b]
        t = T_a_b[:3, 3]
        assert t[0] == pytest.approx(forward_m, abs=0.01)
        assert abs(t[1]) < 0.05 and abs(t[2]) < 0.03  # a wrong Tr direction would put the motion off +x
    with pytest.raises(DataError, match=r"no scan for frame 96"):
        extra.read_scan_by_frame(96)


def test_ground_truth_at_checks_the_frame_numbers(odo_root):
    """ground_truth_at([1.5]) gave frame 1's pose and [] an empty trajectory: frame numbers are checked as read_scan
    checks its index."""
    ds = KittiOdometry(odo_root, "00")
    source = odo_root / "poses" / "00.txt"
    for frames, reason in (([1.5], "frame index 1.5 is not an integer"), ([4541], "frame index 4541 out of range for 4541 frames"),
                           ([-1], "frame index -1 out of range for 4541 frames"), ([], "no frames selected")):
        with pytest.raises(DataError) as err:
            ds.ground_truth_at(frames)
        assert str(err.value) == f"{source}: {reason}"
    assert len(ds.ground_truth_at([4540], frame="camera")) == 1


def test_relative_pose_backwards_and_to_itself(odo_root):
    """relative_pose(9, 0), the truth of registering scan 0 onto scan 9 (a loop closure, a backward pass), was refused
    as "timestamps are not strictly increasing"; (3, 3) too. Backwards is the inverse of forwards; to itself identity."""
    ds = KittiOdometry(odo_root, "00")
    forward = ds.relative_pose(0, 9)
    np.testing.assert_allclose(ds.relative_pose(9, 0), se3_inverse(forward), atol=1e-5)  # (rotations of 7 digits)
    np.testing.assert_array_equal(ds.relative_pose(3, 3), np.eye(4))
    assert np.linalg.norm(forward[:3, 3]) > 5.0  # (the sequence moves between 0 and 9: not an identity passing by chance)


def test_gt_lidar_motion_agrees_with_icp_on_the_scans(extra):
    """Independent check of the Tr direction: Open3D ICP on scans 94/95 reproduces the LiDAR-frame GT."""
    import open3d as o3d

    def cloud(i):
        pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(extra.read_scan(i).points_xyz))
        pcd = pcd.voxel_down_sample(0.4)
        pcd.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=1.2, max_nn=20))
        return pcd

    gt = extra.ground_truth
    T_94_95_gt = se3_inverse(gt.poses_se3[0]) @ gt.poses_se3[1]
    np.testing.assert_allclose(extra.relative_pose(94, 95), T_94_95_gt, atol=1e-12)
    result = o3d.pipelines.registration.registration_icp(
        cloud(1), cloud(0), 1.0, np.eye(4), o3d.pipelines.registration.TransformationEstimationPointToPlane(),
        o3d.pipelines.registration.ICPConvergenceCriteria(max_iteration=50),
    )
    trans_m, rot_deg = pose_error(result.transformation, T_94_95_gt)
    assert trans_m < 0.06 and rot_deg < 0.2  # SOURCES.md: ICP vs GT 0.022 m / 0.03 deg


def test_semantickitti_poses_option(odo_root):
    official = KittiOdometry(odo_root, "00").ground_truth.relative_motions()[0][:3, 3]
    suma = KittiOdometry(odo_root, "00", poses_file=odo_root / "sequences" / "00" / "poses_semantickitti.txt")
    step = suma.ground_truth.relative_motions()[0][:3, 3]
    assert 0.6 < step[0] < 0.75 < 0.8 < official[0]  # SOURCES.md: SuMa 0.67-0.74 m vs GT 0.86 m at the start
    # relative to the dataset folder, as docs/datasets.md writes it (from any working directory)
    relative = KittiOdometry(odo_root, "00", poses_file="sequences/00/poses_semantickitti.txt")
    np.testing.assert_array_equal(relative.ground_truth.poses_se3, suma.ground_truth.poses_se3)
    with pytest.raises(DataError, match="calib file not found"):
        KittiOdometry(odo_root, "00", calib_file="nope.txt")  # at once, not when the ground truth is first used


def test_image_only_sequence_with_bare_calib():
    root = shared_path("kitti_images")
    ds = KittiOdometry(root, "06")
    assert len(ds) == ds.n_images == 51 and ds.n_scans == 0
    assert set(ds.calib) == {"P0", "P1"}
    assert ds.K[0, 0] == pytest.approx(707.0912) and ds.K[1, 2] == pytest.approx(183.1104)
    image = ds.read_image(12)
    assert image.dtype == np.uint8 and image.shape == (370, 1226)
    assert 20 < image.mean() < 235
    assert len(ds.timestamps_s) == 51 and len(ds.ground_truth_camera) == 51
    assert isinstance(ds, ImageSequence) and ds.ground_truth_frame == "camera"  # image-only: GT in camera frame
    np.testing.assert_array_equal(ds.ground_truth.poses_se3, ds.ground_truth_camera.poses_se3)
    with pytest.raises(DataError, match=r"calib\.txt: no Tr"):
        ds.ground_truth_lidar
    with pytest.raises(DataError, match=r"calib\.txt: no Tr"):
        KittiOdometry(root, "06", ground_truth_frame="lidar").ground_truth
    with pytest.raises(ConfigError, match="unknown ground_truth_frame 'world'"):
        KittiOdometry(root, "06", ground_truth_frame="world")
    with pytest.raises(DataError, match="sequence has no scans"):
        ds.read_scan(0)
    images = ds.as_image_sequence()
    assert isinstance(images, ImageSequence)
    assert repr(images) == f"KittiImages({str(ds.image_dir)!r}, images={len(images)})"  # (was "<... object at 0x...>")
    np.testing.assert_allclose(images.ground_truth.poses_se3[0], np.eye(4), atol=1e-6)
    step = images.ground_truth.relative_motions()[0][:3, 3]
    assert step[2] > 0.9 and abs(step[0]) < 0.1


def test_root_may_be_the_sequence_folder(tmp_path, monkeypatch):
    seq06 = KittiOdometry(shared_path("kitti_images", "sequences", "06"))
    assert seq06.name == "kitti_06" and seq06.poses_path.name == "06.txt"  # ../../poses/06.txt preferred
    seq01 = KittiOdometry(shared_path("kitti_images", "sequences", "01"))
    assert seq01.poses_path.name == "poses.txt" and len(seq01.ground_truth_camera) == 51
    assert seq01.timestamps_s is None and seq01.K[0, 0] == pytest.approx(718.856)
    # another sequence asked of a sequence folder is refused, not ignored
    with pytest.raises(ConfigError, match="the folder is sequence 06 itself; sequence=05 names another"):
        KittiOdometry(shared_path("kitti_images", "sequences", "06"), sequence="05")

    # the same under a name that is not a number (a folder of one sequence): sequence=05 was ignored
    renamed = tmp_path / "drive_a"
    shutil.copytree(shared_path("kitti_odometry", "sequences", "00"), renamed)
    assert len(KittiOdometry(renamed)) == 10
    with pytest.raises(ConfigError, match="the folder is one sequence itself .*sequence=05 names another"):
        KittiOdometry(renamed, sequence="05")
    # a spec's path after "kind:" is not expanded by the shell: lidarkit expands ~
    from lidarkit.odometry.inputs import open_sequence

    monkeypatch.setenv("HOME", str(tmp_path))
    assert len(open_sequence("kitti:~/drive_a")) == 10 and len(open_sequence("~/drive_a")) == 10  # (quoted: no shell expands it)


def test_times_out_of_order_name_the_file_line(tmp_path, odo_root):
    seq = tmp_path / "seq"
    shutil.copytree(odo_root / "sequences" / "00", seq)
    lines = (seq / "times.txt").read_text().splitlines()
    lines[4] = lines[2]  # frame 4 back at frame 2's time
    (seq / "times.txt").write_text("# stamps\n\n" + "\n".join(lines) + "\n")
    with pytest.raises(DataError, match=r"times.txt \(line 7, frame 4\): time stamps are not strictly increasing"):
        KittiOdometry(seq).timestamps_s


# ---- corrupted copies -------------------------------------------------------------------------------------
def test_truncated_bin(tmp_path, odo_root):
    path = _scan_copy(tmp_path, odo_root)
    data = path.read_bytes()
    path.write_bytes(data[:-5])
    with pytest.raises(DataError, match=r"000000\.bin: truncated: .* not a multiple of 16"):
        read_kitti_bin(path)  # a file read on its own: no frame named
    ds = KittiOdometry(odo_root, "00", velodyne_dir=path.parent)
    with pytest.raises(DataError, match="truncated"):
        ds.read_scan(0)


def test_empty_and_missing_bin(tmp_path, odo_root):
    path = tmp_path / "000003.bin"
    path.write_bytes(b"")
    with pytest.raises(DataError, match=r"000003\.bin \(frame 3\): empty"):
        read_kitti_bin(path, frame=3)
    with pytest.raises(DataError, match="not found"):
        read_kitti_bin(tmp_path / "nope.bin")


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_nonfinite_points_raise_or_drop(tmp_path, odo_root, caplog, bad):
    path = _scan_copy(tmp_path, odo_root)
    data = np.fromfile(path, dtype=np.float32).reshape(-1, 4)
    data[[10, 500, 9000], [0, 2, 3]] = bad
    data.tofile(path)
    ds = KittiOdometry(odo_root, "00", velodyne_dir=path.parent)
    with pytest.raises(DataError, match=r"000000\.bin \(frame 0\): 3 of 124668 points are NaN or infinite"):
        ds.read_scan(0)
    dropping = KittiOdometry(odo_root, "00", velodyne_dir=path.parent, drop_nonfinite=True)
    with caplog.at_level(logging.WARNING, logger="lidarkit.io.pointfile"):
        scan = dropping.read_scan(0)
    assert scan.points_xyz.shape == (124665, 3) and np.isfinite(scan.points_xyz).all()
    assert len(scan.intensity) == 124665
    assert "dropped 3 of 124668" in caplog.text and "frame 0" in caplog.text


def test_bounds_test_of_whole_records_falls_back_to_the_per_column_check(tmp_path, odo_root):
    """The reader tests x, y, z and intensity in one pass over the records; a value it cannot pass there (a huge but
    finite intensity) goes to the per-column check, which accepts it, while a huge coordinate is still refused."""
    path = _scan_copy(tmp_path, odo_root)
    data = np.fromfile(path, dtype=np.float32).reshape(-1, 4)
    data[7, 3] = 3e8  # beyond the coordinate bound, but an intensity has none
    data.tofile(path)
    scan = read_kitti_bin(path)
    assert scan.intensity[7] == np.float32(3e8) and np.array_equal(scan.points_xyz, data[:, :3].astype(np.float64))
    data[7, 3], data[11, 1] = 0.5, 3e8
    data.tofile(path)
    with pytest.raises(DataError, match=r"1 of 124668 points have a coordinate beyond .*first: point 11"):
        read_kitti_bin(path)


def test_all_nonfinite_is_an_error_even_when_dropping(tmp_path):
    path = tmp_path / "000000.bin"
    np.full((5, 4), np.nan, dtype=np.float32).tofile(path)
    with pytest.raises(DataError, match="no finite points"):
        read_kitti_bin(path, drop_nonfinite=True)


def test_malformed_calib_lines(tmp_path, copy_of, odo_root):
    calib = copy_of(odo_root / "sequences" / "00" / "calib.txt")
    lines = calib.read_text().splitlines()
    lines[2] = " ".join(lines[2].split()[:-1])  # P2 with 11 numbers
    calib.write_text("\n".join(lines) + "\n")
    with pytest.raises(DataError, match=r"calib\.txt \(line 3\): P2: expected 12 numbers .*found 11"):
        read_kitti_calib(calib)
    lines[2] = "P2: 1 2 3 4 5 6 7 8 9 10 eleven 12"
    calib.write_text("\n".join(lines) + "\n")
    with pytest.raises(DataError, match=r"\(line 3\): P2: not a number"):
        KittiOdometry(odo_root, "00", calib_file=calib).calib
    bare = copy_of(shared_path("kitti_images", "sequences", "06", "calib.txt"))
    bare.write_text(bare.read_text() + "\n1 2 3\n")
    with pytest.raises(DataError, match=r"\(line 3\): P2: expected 12 numbers"):
        read_kitti_calib(bare)


def test_malformed_poses_and_times(tmp_path, copy_of, odo_root):
    poses = copy_of(odo_root / "poses" / "00.txt")
    lines = poses.read_text().splitlines()
    lines[41] = lines[41] + " 7"
    poses.write_text("\n".join(lines) + "\n")
    with pytest.raises(DataError, match=r"00\.txt \(line 42\): expected 12 numbers, found 13"):
        KittiOdometry(odo_root, "00", poses_file=poses)
    times = copy_of(odo_root / "sequences" / "00" / "times.txt")
    lines = times.read_text().splitlines()
    lines[6] = "0.6x"
    times.write_text("\n".join(lines) + "\n")
    with pytest.raises(DataError, match=r"times\.txt \(line 7\): not a number"):
        KittiOdometry(odo_root, "00", times_file=times)


def test_times_and_poses_of_different_lengths_are_read_where_both_cover_the_frames(tmp_path, copy_of, odo_root):
    """Files of different lengths are an excerpt's when both cover the frames present (4000 stamps beside 4541 poses
    for scans 0-9 and 94-199); a file stopping short of a frame present is refused, naming the frame."""
    times = copy_of(odo_root / "sequences" / "00" / "times.txt")
    rows = times.read_text().splitlines()
    times.write_text("\n".join(rows[:4000]) + "\n")
    ds = KittiOdometry(odo_root, "00", times_file=times)
    np.testing.assert_array_equal(ds.timestamps_s, np.array([float(rows[f]) for f in ds.scan_frames]))
    times.write_text("\n".join(rows[:5]) + "\n")
    with pytest.raises(DataError, match=r"5 time stamps") as info:
        KittiOdometry(odo_root, "00", times_file=times).timestamps_s
    assert str(info.value).startswith(f"{times}")  # the short file is the source


def test_copied_sequence_folder_with_trimmed_poses_and_full_times(tmp_path):
    """A sequence folder copied on its own (51 images, poses.txt trimmed to them, the full 1101-line times.txt)."""
    seq = tmp_path / "06"
    shutil.copytree(shared_path("kitti_images", "sequences", "06"), seq)
    ds = KittiOdometry(seq)
    assert len(ds) == 51 and len(ds.ground_truth_camera) == 51
    full = np.loadtxt(shared_path("kitti_images", "sequences", "06", "times.txt"))
    np.testing.assert_array_equal(ds.timestamps_s, full[:51])
    every_row = ds.ground_truth_at(None, frame="camera")
    assert len(every_row) == 51 and np.array_equal(every_row.timestamps_s, full[:51])
    # files of different lengths that both cover the frames present (60 poses, 1101 stamps for frames 0-50): read;
    # a poses file stopping short of the last frame present: an error naming it where the poses are taken
    poses = shared_path("kitti_images", "poses", "06.txt").read_text().splitlines()
    (seq / "poses.txt").write_text("\n".join(poses[:60]) + "\n")
    assert len(KittiOdometry(seq).ground_truth_camera) == 51
    (seq / "poses.txt").write_text("\n".join(poses[:40]) + "\n")
    with pytest.raises(DataError, match=r"40 poses but image 000050\.png is frame 50$") as info:
        KittiOdometry(seq).ground_truth_camera
    assert str(info.value).startswith(f"{seq / 'poses.txt'}")  # the short file, not times.txt, is the source


def test_poses_must_cover_every_frame(tmp_path, copy_of, odo_root):
    seq = tmp_path / "seq"
    seq.mkdir()
    shutil.copy2(odo_root / "sequences" / "00" / "calib.txt", seq / "calib.txt")
    short = tmp_path / "short.txt"
    short.write_text("\n".join((odo_root / "poses" / "00.txt").read_text().splitlines()[:150]) + "\n")
    with pytest.raises(DataError, match=r"short\.txt: 150 poses but scan 000199\.bin is frame 199"):
        KittiOdometry(seq, velodyne_dir=odo_root / "extra_frames" / "00" / "velodyne", poses_file=short).ground_truth


def test_missing_paths(tmp_path, odo_root):
    with pytest.raises(DataError, match="dataset folder not found"):
        KittiOdometry(tmp_path / "nowhere")
    with pytest.raises(DataError, match="sequence 05 not found"):
        KittiOdometry(odo_root, "05")
    with pytest.raises(DataError, match="folder not found"):
        KittiOdometry(odo_root, "00", velodyne_dir=tmp_path / "no_velodyne")
    with pytest.raises(DataError, match="poses file not found"):
        KittiOdometry(odo_root, "00", poses_file=tmp_path / "no.txt")
    empty = tmp_path / "empty_seq"
    (empty / "velodyne").mkdir(parents=True)
    with pytest.raises(DataError, match="no scans"):
        KittiOdometry(empty)
    with pytest.raises(DataError, match=r"calib\.txt: calib file not found"):
        KittiOdometry(odo_root, "00", calib_file=tmp_path / "calib.txt")  # a file given is checked at once


def test_bad_file_names_and_images(tmp_path, odo_root):
    folder = tmp_path / "velodyne"
    folder.mkdir()
    (folder / "scan_a.bin").write_bytes(b"\0" * 16)
    with pytest.raises(DataError, match=r"scan_a\.bin: file name is not a frame number"):
        KittiOdometry(odo_root, "00", velodyne_dir=folder)
    images = tmp_path / "image_0"
    images.mkdir()
    (images / "000000.png").write_bytes(b"not a png")
    ds = KittiOdometry(odo_root, "00", image_dir=images)
    with pytest.raises(DataError, match=r"000000\.png \(frame 0\): cannot decode image"):
        ds.read_image(0)


def test_unknown_dataset_kind_lists_known_kinds():
    with pytest.raises(ConfigError, match=r"unknown dataset kind 'kitty'; known: .*kitti, kitti_raw") as err:
        open_dataset("kitty", ".")
    assert all(kind in str(err.value) for kind in available_datasets())


def test_per_point_times_files_integer_or_unreadable(tmp_path):
    """Integer per-point times are nanoseconds (as drivers write them and as bags are read); an empty file, an .npz
    archive or complex numbers under an .npy name are DataErrors naming the file and frame (EOFError and
    AttributeError escaped before, the CLI printing only 'Aborted.')."""
    from lidarkit.sim.lidar import SimulatedLidarSequence, export_kitti

    sim = SimulatedLidarSequence(n_frames=2, n_beams=8, n_azimuths=90)
    folder = export_kitti(sim, tmp_path / "seq")
    times = np.load(folder / "point_times" / "000001.npy").astype(np.float64)
    np.save(folder / "point_times" / "000001.npy", np.round(times * 1e9).astype(np.uint32))
    np.testing.assert_allclose(KittiOdometry(folder).read_scan(1).point_times_s, times, rtol=0, atol=1e-9)
    target = folder / "point_times" / "000001.npy"
    for write, message in ((lambda: target.write_bytes(b""), "not a readable .npy array"),
                           (lambda: np.savez(open(target, "wb"), a=times), "not an .npy array"),
                           (lambda: np.save(target, times.astype(np.complex64)), "expected a 1-D numeric array")):
        write()
        with pytest.raises(DataError, match=rf"000001.npy \(frame 1\): {message}"):
            KittiOdometry(folder).read_scan(1)


def test_one_sweep_simulator_export_is_retimed_by_its_frame_rate(tmp_path):
    """A one-sweep export has one stamp, so no period to take from times.txt: the sweep start and mid read the end's
    0.1 s before (and so did poses_start.txt named as the pose file); sim.yaml's frame_rate_hz gives the period."""
    from lidarkit.sim.lidar import SimulatedLidarSequence, export_kitti

    folder = export_kitti(SimulatedLidarSequence(n_frames=1, n_beams=8, n_azimuths=90, frame_rate_hz=10.0), tmp_path / "one")
    ds = open_dataset("kitti", folder)
    assert ds.ground_truth.timestamps_s.tolist() == pytest.approx([0.1])
    for instant, stamp in (("start", 0.0), ("mid", 0.05), ("end", 0.1)):
        assert ds.ground_truth_at_instant(instant).timestamps_s.tolist() == pytest.approx([stamp], abs=1e-12)
    named = open_dataset("kitti", folder, poses_file="poses_start.txt").ground_truth
    assert named.timestamps_s.tolist() == pytest.approx([0.0], abs=1e-12)
    assert named.meta["pose_instant"] == "start"


def test_an_explicit_00_or_a_name_asked_of_a_sequence_folder_is_refused(tmp_path):
    """``sequence=00`` (the default, so taken for no choice) or ``sequence=xyz`` on ``sequences/06`` read sequence 06
    without a word, and ``?sequence=abc`` on ``sequences/00`` read 00; only another number was refused."""
    from lidarkit.odometry.inputs import open_sequence

    seq06 = shared_path("kitti_images", "sequences", "06")
    for asked in ("00", 0, "xyz"):
        with pytest.raises(ConfigError) as err:
            KittiOdometry(seq06, sequence=asked)
        assert str(err.value) == (f"{seq06}: the folder is sequence 06 itself; sequence={asked} names another "
                                  "(give the odometry root that holds sequences/)")
    assert KittiOdometry(seq06, sequence="6").name == KittiOdometry(seq06, sequence="06").name == "kitti_06"
    seq00 = shared_path("kitti_odometry", "sequences", "00")
    with pytest.raises(ConfigError, match="the folder is sequence 00 itself; sequence=abc names another"):
        open_sequence(f"kitti:{seq00}?sequence=abc")
    assert len(open_sequence(f"kitti:{seq00}?sequence=00")) == len(open_sequence(f"kitti:{seq00}")) == 10
    renamed = tmp_path / "drive_a"  # a folder of one sequence under a name: that name is its own, another is not
    shutil.copytree(seq00, renamed)
    assert len(KittiOdometry(renamed, sequence="drive_a")) == 10
    with pytest.raises(ConfigError, match=r"one sequence itself \(no sequences/ inside\); sequence=00 names another"):
        KittiOdometry(renamed, sequence="00")
    assert KittiOdometry(shared_path("kitti_odometry"), sequence="00").name == "kitti_00"  # a root: 00 is a choice


def test_per_point_times_that_are_not_times_are_refused_as_in_a_bag(tmp_path):
    """point_times/ took any numeric array as times, without the bag reader's checks: ring numbers (uint8 0-15, read
    as nanoseconds: a 15 ns sweep), an intensity of 0-0.7 s and float32 absolute times 128 s apart in one scan were
    deskewed by without a word. Each is now a DataError naming the file and frame; the simulator's own times still
    read, a 2 s sweep too (frame_rate_hz 0.5: a sweep lasts the spacing of times.txt when that exceeds 1 s)."""
    from lidarkit.sim.lidar import SimulatedLidarSequence, export_kitti

    folder = export_kitti(SimulatedLidarSequence(n_frames=2, n_beams=16, n_azimuths=360), tmp_path / "k")
    target = folder / "point_times" / "000001.npy"
    n = len(np.load(target))
    assert open_dataset("kitti", folder).read_scan(1).point_times_s.max() == pytest.approx(0.1, abs=1e-3)
    hint = "rename point_times/ to read the scans without them"
    for values, message in (
        ((np.arange(n) % 16).astype(np.uint8), "per-point time array is a 8-bit integer: too small for times (drivers "
         f"write float seconds or 32/64-bit integer nanoseconds); {hint}"),
        # absolute float32 times about a rounding step of float32 (128 s apart near 1.7e9 s): float32 named as the reason
        ((1699999808.0 - 0.05 + np.linspace(0, 0.1, n)).astype(np.float32), "per-point time array is float32 holding times "
         "of 1.7e+09 s and more: float32 cannot hold absolute times (its steps are 128 s there; drivers write them as "
         f"float64 or integer nanoseconds); {hint}"),
    ):
        np.save(target, values)
        with pytest.raises(DataError) as err:
            open_dataset("kitti", folder).read_scan(1)
        assert str(err.value) == f"{target} (frame 1): {message}"
    for values in ((np.arange(n) % 16).astype(np.int64), np.random.default_rng(0).uniform(0, 0.7, n).astype(np.float32)):
        np.save(target, values)
        with pytest.raises(DataError, match=r"000001\.npy \(frame 1\): per-point time array does not follow the sweep: "
                                            r"its values go back \d+ times in \d+ points and do not turn with the azimuth"):
            open_dataset("kitti", folder).read_scan(1)

    slow = export_kitti(SimulatedLidarSequence(n_frames=2, n_beams=8, n_azimuths=90, frame_rate_hz=0.5), tmp_path / "slow")
    assert np.ptp(open_dataset("kitti", slow).read_scan(1).point_times_s) == pytest.approx(2.0, abs=0.05)


def test_absolute_per_point_times_say_so(tmp_path):
    """Times above 1e5 s in point_times/ are absolute (as in a bag); the reader labelled them "relative_s"."""
    from lidarkit.sim.lidar import SimulatedLidarSequence, export_kitti

    folder = export_kitti(SimulatedLidarSequence(n_frames=2, n_beams=8, n_azimuths=90), tmp_path / "k")
    relative = np.load(folder / "point_times" / "000001.npy").astype(np.float64)
    np.save(folder / "point_times" / "000001.npy", 1.7e9 + 0.1 + relative)
    scan = open_dataset("kitti", folder).read_scan(1)
    assert scan.point_time_convention == "absolute_s"
    np.testing.assert_allclose(scan.point_times_s - 1.7e9, 0.1 + relative, rtol=0, atol=1e-6)
    # one convention per folder: frame 0 (0-0.1 s, stamped 0.1 s: its stamp cannot tell) is read as the folder's
    assert open_dataset("kitti", folder).read_scan(0).point_time_convention == "absolute_s"
    plain = export_kitti(SimulatedLidarSequence(n_frames=2, n_beams=8, n_azimuths=90), tmp_path / "plain")
    assert open_dataset("kitti", plain).read_scan(0).point_time_convention == "relative_s"


def test_point_times_of_points_left_out_are_left_out_too(tmp_path):
    """Points the scan reader leaves out (non-finite with drop_nonfinite, missing returns at (0, 0, 0)) had their
    times dropped only when non-finite: the others shifted every time onto another point, or the lengths differed."""
    from lidarkit.sim.lidar import SimulatedLidarSequence, export_kitti

    folder = export_kitti(SimulatedLidarSequence(n_frames=2, n_beams=8, n_azimuths=90), tmp_path / "k")
    bin_path = folder / "velodyne" / "000001.bin"
    points = np.fromfile(bin_path, dtype="<f4").reshape(-1, 4)
    points[:3, :3], points[5, 0] = 0.0, np.nan
    points.tofile(bin_path)
    times = np.load(folder / "point_times" / "000001.npy").astype(np.float64)
    scan = KittiOdometry(folder, drop_nonfinite=True).read_scan(1)
    kept = np.isfinite(points).all(axis=1) & (points[:, :3] != 0).any(axis=1)
    assert len(scan.points_xyz) == len(points) - 4
    np.testing.assert_array_equal(scan.points_xyz, points[kept, :3].astype(np.float64))
    np.testing.assert_allclose(scan.point_times_s, times[kept], rtol=0, atol=1e-9)


def test_a_sequence_given_by_a_relative_path_keeps_its_ground_truth_and_name(monkeypatch):
    """From sequences/, "00" (or "./00", or "." inside it) had no parent named sequences/: the poses/00.txt beside
    were not found, the run had no scores and said nothing; "." was also named ''."""
    from conftest import shared_path

    from lidarkit.io import open_dataset

    sequences = shared_path("kitti_odometry", "sequences")
    whole = open_dataset("kitti", sequences / "00")
    monkeypatch.chdir(sequences)
    for given in ("00", "./00"):
        seq = open_dataset("kitti", given)
        assert seq.name == "kitti_00" and np.array_equal(seq.ground_truth.poses_se3, whole.ground_truth.poses_se3)
    monkeypatch.chdir(sequences / "00")
    here = open_dataset("kitti", ".")
    assert here.name == "kitti_00" and here.ground_truth is not None


def test_per_point_times_in_microseconds_are_refused_by_times_txt_spacing(tmp_path):
    """uint32 per-point times in microseconds were read as nanoseconds: 0.1 s sweeps of 1e-4 s, deskewed and re-timed
    by them without a word. Against times.txt's spacing (a median over the first frames) a sweep spanning less than
    1 % of it is a DataError naming the folder, the span, the spacing and the unit; a sensor seeing a quarter of its
    turn still reads."""
    from lidarkit.sim.lidar import SimulatedLidarSequence, export_kitti

    folder = export_kitti(SimulatedLidarSequence(n_frames=3, n_beams=8, n_azimuths=90), tmp_path / "k")
    seconds = {f: np.load(f).astype(np.float64) for f in sorted((folder / "point_times").glob("*.npy"))}
    for path, times in seconds.items():
        np.save(path, np.round(times * 1e6).astype(np.uint32))
    with pytest.raises(DataError) as err:
        open_dataset("kitti", folder).read_scan(1)
    assert str(err.value) == (f"{folder / 'point_times'}: per-point times in point_times/: sweeps of 9.89e-05 s (the median "
                              "over 3 frames; times.txt gives the stamps) while the scans are stamped 0.1 s apart (0.0989 % of "
                              "it), under 0.001 s: read as integer nanoseconds (uint32), the unit looks like microseconds (or "
                              "the values are 1000x too small); rename point_times/ to read the scans without them")
    for path, times in seconds.items():  # a quarter of the turn, as a sensor with a partial field of view sees it
        np.save(path, np.round(0.25 * times * 1e9).astype(np.uint32))
    assert np.ptp(open_dataset("kitti", folder).read_scan(1).point_times_s) == pytest.approx(0.25 * 0.0989, abs=1e-4)


def _sequence_with_extra_velodyne(root, odo_root):
    """Sequence 00's calib, times and poses with scan 0 in sequences/00/velodyne, and scans 94 and 95 in a folder of
    their own (``extra/velodyne``) whose per-point times sit beside it in ``extra/point_times``."""
    sequence, extra = root / "sequences" / "00", root / "extra"
    (sequence / "velodyne").mkdir(parents=True)
    (extra / "velodyne").mkdir(parents=True)
    (extra / "point_times").mkdir()
    (root / "poses").mkdir()
    for name in ("calib.txt", "times.txt"):
        shutil.copy2(odo_root / "sequences" / "00" / name, sequence / name)
    shutil.copy2(odo_root / "poses" / "00.txt", root / "poses" / "00.txt")
    shutil.copy2(odo_root / "sequences" / "00" / "velodyne" / "000000.bin", sequence / "velodyne" / "000000.bin")
    times = {}
    for frame in (94, 95):
        name = f"{frame:06d}"
        shutil.copy2(odo_root / "extra_frames" / "00" / "velodyne" / f"{name}.bin", extra / "velodyne" / f"{name}.bin")
        xy = np.fromfile(extra / "velodyne" / f"{name}.bin", dtype="<f4").reshape(-1, 4)[:, :2].astype(np.float64)
        times[frame] = 0.05 * (1.0 - np.arctan2(xy[:, 1], xy[:, 0]) / np.pi)  # a clockwise 0.1 s sweep from behind
        np.save(extra / "point_times" / f"{name}.npy", times[frame])
    return extra, times


def test_per_point_times_are_found_beside_a_velodyne_dir_given(tmp_path, odo_root):
    """velodyne_dir=extra/velodyne read the scans without the per-point times of extra/point_times: only the sequence
    folder was searched (and the warning named sequences/00)."""
    extra, times = _sequence_with_extra_velodyne(tmp_path, odo_root)
    ds = open_dataset("kitti", tmp_path, sequence="00", velodyne_dir="extra/velodyne")
    assert list(ds.frames) == [94, 95]
    assert ds.point_times_dir == extra / "point_times"
    assert ds.point_time_search_dirs == (extra, tmp_path / "sequences" / "00")
    scan = ds.read_scan(1)
    np.testing.assert_array_equal(scan.point_times_s, times[95])
    assert scan.point_time_convention == "relative_s"
    # the sequence folder is still searched after the scans' own; KITTI's own layout searches the one folder
    (extra / "point_times").rename(tmp_path / "sequences" / "00" / "point_times")
    moved = open_dataset("kitti", tmp_path, sequence="00", velodyne_dir="extra/velodyne")
    assert moved.point_times_dir == tmp_path / "sequences" / "00" / "point_times"
    np.testing.assert_array_equal(moved.read_scan(0).point_times_s, times[94])
    own = open_dataset("kitti", tmp_path, sequence="00")
    assert own.point_time_search_dirs == (tmp_path / "sequences" / "00",)
    assert own.point_times_dir == tmp_path / "sequences" / "00" / "point_times"


def test_a_pose_file_that_stops_early_scores_the_frames_it_covers(tmp_path, odo_root):
    """poses100.txt (frames 0-99) beside scans up to frame 199 refused every run at open, --frames 0:2 too: the poses
    are checked for the frames a run selects, with the same message when one of them has none."""
    from lidarkit.odometry import run

    seq = tmp_path / "seq"
    (seq / "velodyne").mkdir(parents=True)
    for name in ("calib.txt", "times.txt"):
        shutil.copy2(odo_root / "sequences" / "00" / name, seq / name)
    for frame in (0, 1):
        shutil.copy2(odo_root / "sequences" / "00" / "velodyne" / f"{frame:06d}.bin", seq / "velodyne" / f"{frame:06d}.bin")
    for frame in (198, 199):
        shutil.copy2(odo_root / "extra_frames" / "00" / "velodyne" / f"{frame:06d}.bin", seq / "velodyne" / f"{frame:06d}.bin")
    poses = seq / "poses100.txt"
    poses.write_text("\n".join((odo_root / "poses" / "00.txt").read_text().splitlines()[:100]) + "\n")
    ds = KittiOdometry(seq, poses_file="poses100.txt")
    covered = ds.ground_truth_of([0, 1])
    np.testing.assert_array_equal(covered.poses_se3, ds.ground_truth_at([0, 1]).poses_se3)
    np.testing.assert_array_equal(covered.timestamps_s, ds.timestamps_s[:2])
    result = run(ds, "vanilla", params={"voxel_size_m": 1.0}, frames="0:2")
    assert result.metrics["ground_truth_length_m"] == pytest.approx(ds.ground_truth_at([0, 1]).length_m)
    assert 0.8 < result.metrics["ground_truth_length_m"] < 0.9  # (poses/00.txt: 0.86 m from frame 0 to 1)
    message = f"{poses}: 100 poses but scan 000199.bin is frame 199"
    for asked in (lambda: ds.ground_truth, lambda: ds.ground_truth_of([1, 3]), lambda: run(ds, "vanilla", frames="1:4")):
        with pytest.raises(DataError) as err:
            asked()
        assert str(err.value) == message
    with pytest.raises(DataError) as err:
        ds.ground_truth_of([2])
    assert str(err.value) == f"{poses}: 100 poses but scan 000198.bin is frame 198"


def test_times_going_back_say_both_stamps(tmp_path, odo_root):
    """A times.txt going back (0, 0.1, 0.05, ...) said "(line 3, frame 2): time stamps are not strictly increasing"
    without the values; they are printed as the odometry runner prints them, a repeated stamp said so."""
    seq = tmp_path / "seq"
    shutil.copytree(odo_root / "sequences" / "00", seq)
    n = len((seq / "times.txt").read_text().split())
    for third, why in ((0.05, "0.05 s after 0.1 s of frame 1"), (0.1, "0.1 s repeats the stamp of frame 1")):
        stamps = [0.0, 0.1, third] + [0.1 * i for i in range(3, n)]
        (seq / "times.txt").write_text("".join(f"{t:g}\n" for t in stamps))
        with pytest.raises(DataError) as caught:
            KittiOdometry(seq).timestamps_s
        assert str(caught.value) == f"{seq / 'times.txt'} (line 3, frame 2): time stamps are not strictly increasing: " + why


def test_points_dropped_as_nonfinite_are_kept_once_for_the_runs_warnings(tmp_path):
    """The KITTI reader with drop_nonfinite=true logged the points it left out, and the run's metrics.json had no word
    of them. One line, the first frame's, is kept in ``reader_warnings``, which the run records."""
    from lidarkit.sim.lidar import SimulatedLidarSequence, export_kitti

    folder = export_kitti(SimulatedLidarSequence(n_frames=3, n_beams=8, n_azimuths=90), tmp_path / "k")
    for frame in (1, 2):
        bin_path = folder / "velodyne" / f"{frame:06d}.bin"
        points = np.fromfile(bin_path, dtype="<f4").reshape(-1, 4)
        points[4:6, 1] = np.inf
        points.tofile(bin_path)
    n = len(np.fromfile(folder / "velodyne" / "000001.bin", dtype="<f4")) // 4
    reader = KittiOdometry(folder, drop_nonfinite=True)
    for k in range(3):
        reader.read_scan(k)
    assert getattr(reader, "reader_warnings", None) == [f"left out 2 of {n} points with NaN or infinite values in frame 1 "
                                                         f"({folder / 'velodyne' / '000001.bin'}); in later frames without another warning"]


def test_time_stamps_in_nanoseconds_are_read_as_seconds_and_milliseconds_are_refused(tmp_path, odo_root, caplog):
    """times.txt (or times_file=, what lidarkit vo --timestamps gives) in nanoseconds was read as seconds: a run wrote
    1600000001038876928.0 to its poses_tum.txt, which lidarkit eval refused. Above 1e15 they are nanoseconds, converted
    with a warning, as an image folder's stamps are; milliseconds are refused naming the file, line and unit."""
    from lidarkit.vo.inputs import open_vo_input

    seconds = 1.6e9 + 0.1 * np.arange(len((odo_root / "sequences" / "00" / "times.txt").read_text().split()))
    ns_file, ms_file = tmp_path / "times_ns.txt", tmp_path / "times_ms.txt"
    ns_file.write_text("".join(f"{round(t * 1e9)}\n" for t in seconds))
    ms_file.write_text("".join(f"{t * 1e3:.3f}\n" for t in seconds))
    seq = tmp_path / "seq"
    shutil.copytree(odo_root / "sequences" / "00", seq)
    refused = r"time stamp 1600000000000 is beyond 1e\+11 s \(after the year 5000\): milliseconds\? .*divide by 1e3$"
    for given, unit in ((ns_file, "ns"), (ms_file, "ms")):
        (seq / "times.txt").write_text(given.read_text())
        for times_path, root, options in ((seq / "times.txt", seq, {}), (given, odo_root, {"times_file": given})):
            if unit == "ms":
                with pytest.raises(DataError, match=rf"{times_path.name} \(line 1, frame 0\): {refused}"):
                    KittiOdometry(root, **options).timestamps_s
                continue
            with caplog.at_level(logging.WARNING, logger="lidarkit.io.base"):
                ds = KittiOdometry(root, **options)
                stamps = ds.timestamps_s
            np.testing.assert_allclose(stamps, seconds[ds.frames], rtol=0, atol=1e-6)
            assert f"{times_path}: time stamps above 1e+15 read as nanoseconds (the first is 1600000000.000000 s)" in caplog.text
    # lidarkit vo --timestamps over a KITTI image sequence (sequence 01 has no times.txt of its own)
    images = shared_path("kitti_images", "sequences", "01")
    ns_file.write_text("".join(f"{round(t * 1e9)}\n" for t in seconds[:51]))
    assert open_vo_input(images, kind="kitti", timestamps=ns_file).images.timestamps_s[1] == pytest.approx(1.6e9 + 0.1, abs=1e-6)
    ms_file.write_text("".join(f"{t * 1e3:.3f}\n" for t in seconds[:51]))
    with pytest.raises(DataError, match=rf"times_ms\.txt \(line 1, frame 0\): {refused}"):
        open_vo_input(images, kind="kitti", timestamps=ms_file).images.timestamps_s


def test_time_stamps_in_microseconds_are_refused_not_read_as_nanoseconds(tmp_path, odo_root, caplog):
    """times.txt in microseconds (1.7e15, above the 1e15 where nanoseconds start) was read as nanoseconds with only a
    warning: frames 0.1 ms apart in January 1970. Seconds before 1973 or frames under 1 ms apart after the conversion
    are refused naming the file, its line and the unit, for a KITTI sequence and for an image sequence's stamps."""
    from lidarkit.vo.inputs import open_vo_input

    n = len((odo_root / "sequences" / "00" / "times.txt").read_text().split())
    seconds = 1.7e9 + 0.1 * np.arange(n)
    us_file = tmp_path / "times_us.txt"
    us_file.write_text("".join(f"{round(t * 1e6)}\n" for t in seconds))
    refused = (r"times_us\.txt \(line 1, frame 0\): time stamp 1700000000000000 read as nanoseconds is 1\.7e\+06 s after "
               r"1970, frames 0\.1 ms apart: microseconds\? write seconds, e\.g\. divide by 1e6$")
    with caplog.at_level(logging.WARNING, logger="lidarkit.io.base"):
        with pytest.raises(DataError, match=refused):
            KittiOdometry(odo_root, times_file=us_file).timestamps_s
    assert "read as nanoseconds (the first" not in caplog.text  # (refused, not converted with a warning)
    images = shared_path("kitti_images", "sequences", "01")
    us_file.write_text("".join(f"{round(t * 1e6)}\n" for t in seconds[:51]))
    with pytest.raises(DataError, match=refused):
        open_vo_input(images, kind="kitti", timestamps=us_file).images.timestamps_s
    # nanoseconds of a recent drive at 100 Hz (10 ms apart) still convert, as EuRoC's data.csv does
    ns_file = tmp_path / "times_ns.txt"
    ns_file.write_text("".join(f"{round((1.7e9 + 0.01 * k) * 1e9)}\n" for k in range(n)))
    np.testing.assert_allclose(KittiOdometry(odo_root, times_file=ns_file).timestamps_s,
                               1.7e9 + 0.01 * np.arange(n)[KittiOdometry(odo_root).frames], rtol=0, atol=1e-6)
