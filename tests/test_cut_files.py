"""Numeric text files cut off inside their last number: read, but said (a path's length read as four times the truth)."""

from __future__ import annotations

import logging

import numpy as np
from conftest import shared_path
from scipy.spatial.transform import Rotation

from lidarkit.io.landmarks import LandmarkData
from lidarkit.textfile import read_numeric_table
from lidarkit.trajectory import READ_WARNINGS, Trajectory



def _kitti_poses(tmp_path, n: int = 8):
    """A KITTI pose file as lidarkit writes it (``%.16e``, a newline at the end), every z negative."""
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, :3, :3] = Rotation.from_euler("z", np.linspace(0.0, 0.3, n)[:, None]).as_matrix()
    poses[:, :3, 3] = np.column_stack([np.linspace(0, 1, n), np.zeros(n), -np.linspace(0.01, 0.04, n)])
    return Trajectory(poses, None, "gt").to_kitti(tmp_path / "poses.txt")


def test_a_kitti_file_cut_inside_its_last_number_is_said_with_its_line(tmp_path, caplog):
    """A poses.txt cut before its last exponent (no line end) was read silently, its last z 25 times too large: the reader
    logs the file and line and keeps the warning in the trajectory's read warnings; its whole text read the same
    again without a newline at the end (a hand-written file) says nothing."""
    path = _kitti_poses(tmp_path)
    text = path.read_text()
    last = text.split()[-1]  # e.g. -4.0000000000000001e-02
    assert "e-02" in last
    path.write_text(text.rstrip("\n")[: -len("e-02")])  # cut before the exponent
    with caplog.at_level(logging.WARNING, logger="lidarkit.textfile"):
        traj = Trajectory.from_kitti(path)
    expected = (f"{path}: line 8 has no line end and its last value {last[:-4]} is shorter than that column's on every "
                "other line: the file may be cut off")
    assert traj.meta[READ_WARNINGS] == [expected]
    assert [r.getMessage() for r in caplog.records] == [expected]

    caplog.clear()
    path.write_text(text.rstrip("\n"))  # whole, only its line end missing
    with caplog.at_level(logging.WARNING, logger="lidarkit.textfile"):
        traj = Trajectory.from_kitti(path)
    assert READ_WARNINGS not in traj.meta and caplog.records == []


def test_a_cut_inside_the_exponent_is_said_though_no_shorter(tmp_path, caplog):
    """'-3.7371226775451863e-0' is as long as a positive value of that column: the exponent of fewer digits than
    every other line's is what shows the cut."""
    rows = ["1.0000000000000000e+00 -3.7371226775451863e-02", "2.0000000000000000e+00 3.7371226775451863e-02",
            "3.0000000000000000e+00 3.1000000000000000e-02", "4.0000000000000000e+00 -3.7371226775451863e-0"]
    path = tmp_path / "table.txt"
    path.write_text("\n".join(rows))
    expected = (f"{path}: line 4 has no line end and its last value -3.7371226775451863e-0 lacks the 2-digit exponent "
                "that column has on every other line: the file may be cut off")
    with caplog.at_level(logging.WARNING, logger="lidarkit.textfile"):
        table = read_numeric_table(path, 2)
    assert table[-1, 1] == -3.7371226775451863  # (what the cut file holds, read as before)
    assert [r.getMessage() for r in caplog.records] == [expected]
    warnings: list[str] = []
    read_numeric_table(path, 2, warnings=warnings)
    assert warnings == [expected]


def test_short_last_rows_of_their_own_kind_are_no_cut(tmp_path, caplog):
    """A 4x4 matrix's "0 0 0 1" row (every value short, not only the last) and a file of two lines are not warned of;
    nor the real files of ../shared/data that end without a line end."""
    matrix = tmp_path / "T.txt"
    matrix.write_text("0.999 -0.0228 0.0012 0.121214\n0.0228 0.999 -0.0017 -0.0253342\n"
                      "0.0017 0.0023 0.999996 1.2517\n0 0 0 1")
    short = tmp_path / "two.txt"
    short.write_text("0.123456\n0.1")
    real = [shared_path("kitti_images", "sequences", "06", "poses.txt"),
            shared_path("lidar_pairs", "T_target_source_small_gicp.txt")]
    assert not all(p.read_bytes().endswith(b"\n") for p in real)
    with caplog.at_level(logging.WARNING, logger="lidarkit.textfile"):
        read_numeric_table(matrix, 4)
        read_numeric_table(short, 1)
        read_numeric_table(real[0], 12)
        read_numeric_table(real[1], 4)
    assert caplog.records == []


def test_a_landmark_sensor_file_cut_in_its_last_bearing_is_said(tmp_path, caplog):
    """The pf sensor_data.dat cut to "SENSOR 7 4.46232141614 -1.0" was read as a bearing of -1.0 rad without a word:
    its SENSOR line is compared with the other SENSOR lines and the warning names the file and line."""
    source = shared_path("pf", "burgard_ekf")
    (tmp_path / "world.dat").write_text((source / "world.dat").read_text())
    text = (source / "sensor_data.dat").read_text()
    last_line = text.rstrip("\n").splitlines()[-1]
    assert last_line.startswith("SENSOR ")
    bearing = last_line.split()[-1]
    cut = text.rstrip("\n")[: -(len(bearing) - 4)]  # the bearing's first 4 characters left
    sensor = tmp_path / "sensor_data.dat"
    sensor.write_text(cut)
    n_lines = len(cut.splitlines())
    with caplog.at_level(logging.WARNING, logger="lidarkit.textfile"):
        data = LandmarkData(tmp_path)
    assert data.meas_bearing_rad[-1] == float(bearing[:4])
    assert [r.getMessage() for r in caplog.records] == [
        f"{sensor}: line {n_lines} has no line end and its last value {bearing[:4]} is shorter than that column's on "
        "every other line: the file may be cut off"]
    caplog.clear()
    sensor.write_text(text.rstrip("\n"))
    with caplog.at_level(logging.WARNING, logger="lidarkit.textfile"):
        LandmarkData(tmp_path)
    assert caplog.records == []


# ---- a cut file's warning in the run folders (it was logged only: a VO run scored APE 2.858 m said nothing) ----------


def _cut_last_exponent(path) -> str:
    """Cut ``path`` (rows of ``%e`` numbers) inside its last number's exponent, as a copy stopped early leaves it ("e-02"
    -> "e-0": still a number); the warning the readers give for it (one, naming the file and line)."""
    path.write_text(path.read_text().rstrip("\n")[:-1])
    said: list[str] = []
    read_numeric_table(path, (1, 12), warnings=said)
    assert len(said) == 1 and said[0].startswith(f"{path}: line ") and said[0].endswith("the file may be cut off")
    return said[0]


def _kitti_lidar_sequence(tmp_path, n: int = 3):
    """The first ``n`` scans of the shared KITTI sequence 00 with its calib, times and ground truth rows."""
    import shutil

    source = shared_path("kitti_odometry")
    seq = tmp_path / "seq"
    (seq / "velodyne").mkdir(parents=True)
    for k in range(n):
        shutil.copy(source / "sequences" / "00" / "velodyne" / f"{k:06d}.bin", seq / "velodyne")
    shutil.copy(source / "sequences" / "00" / "calib.txt", seq / "calib.txt")
    (seq / "times.txt").write_text("".join((source / "sequences" / "00" / "times.txt").read_text().splitlines(True)[:n]))
    (seq / "poses.txt").write_text("".join((source / "poses" / "00.txt").read_text().splitlines(True)[:n]))
    return seq


def test_the_kitti_reader_keeps_a_cut_pose_or_times_file_in_its_reader_warnings(tmp_path):
    """The poses and times.txt of a KITTI sequence cut inside their last number: said once each in reader_warnings, and
    kept in the ground truth of the frames asked for (sliced, it lost them)."""
    from lidarkit.io.kitti import KittiOdometry

    seq = _kitti_lidar_sequence(tmp_path)
    poses_cut, times_cut = _cut_last_exponent(seq / "poses.txt"), _cut_last_exponent(seq / "times.txt")
    reader = KittiOdometry(seq)
    gt = reader.ground_truth_at(reader.frames)
    assert gt.meta[READ_WARNINGS] == [poses_cut]
    reader.ground_truth_at()  # (read again: said once)
    assert reader.reader_warnings == [poses_cut, times_cut]


def test_an_odometry_run_on_a_cut_pose_file_records_it_in_metrics_json(tmp_path):
    import json

    from conftest import cli_exit_code

    seq = _kitti_lidar_sequence(tmp_path)
    expected = _cut_last_exponent(seq / "poses.txt")
    out = tmp_path / "run"
    assert cli_exit_code(["odometry", str(seq), "--method", "kiss", "--out", str(out), "--no-progress"]) == 0
    assert json.loads((out / "metrics.json").read_text())["warnings"][:1] == [expected]


def test_a_vo_run_on_a_cut_pose_file_records_it_in_metrics_json(tmp_path):
    """KITTI 06's poses.txt cut inside its last number scored APE 2.858 m (0.0091 m whole) with nothing on file."""
    import json
    import shutil

    from conftest import cli_exit_code

    source = shared_path("kitti_images", "sequences", "06")
    seq = tmp_path / "06"
    (seq / "image_0").mkdir(parents=True)
    n = 6
    for k in range(n):
        shutil.copy(source / "image_0" / f"{k:06d}.png", seq / "image_0")
    shutil.copy(source / "calib.txt", seq / "calib.txt")
    (seq / "poses.txt").write_text("".join((source / "poses.txt").read_text().splitlines(True)[:n]))
    expected = _cut_last_exponent(seq / "poses.txt")
    out = tmp_path / "run"
    assert cli_exit_code(["vo", str(seq), "--out", str(out), "--no-progress"]) == 0
    assert json.loads((out / "metrics.json").read_text())["warnings"] == [expected]


def test_the_folder_and_image_folder_readers_keep_a_cut_file_in_their_reader_warnings(tmp_path):
    """A scan folder's and an image folder's poses and time stamps cut inside their last number: in reader_warnings."""
    import shutil

    from lidarkit.io.folder import ScanFolder
    from lidarkit.io.images import ImageFolder

    seq = _kitti_lidar_sequence(tmp_path)
    poses_cut, times_cut = _cut_last_exponent(seq / "poses.txt"), _cut_last_exponent(seq / "times.txt")
    times = seq / "times.txt"
    scans = ScanFolder(seq / "velodyne", poses=seq / "poses.txt", timestamps=times)
    assert scans.reader_warnings == [times_cut, poses_cut]

    source = shared_path("kitti_images", "sequences", "06", "image_0")
    images = tmp_path / "images"
    images.mkdir()
    for k in range(3):
        shutil.copy(source / f"{k:06d}.png", images)
    folder = ImageFolder(images, poses=seq / "poses.txt", timestamps=times)
    assert folder.reader_warnings == [times_cut, poses_cut]


def test_a_pf_run_on_a_cut_recording_records_it_in_metrics_json(tmp_path):
    import json

    from conftest import cli_exit_code

    source = shared_path("pf", "burgard_ekf")
    (tmp_path / "world.dat").write_text((source / "world.dat").read_text())
    text = (source / "sensor_data.dat").read_text()
    bearing = text.rstrip("\n").splitlines()[-1].split()[-1]
    sensor = tmp_path / "sensor_data.dat"
    sensor.write_text(text.rstrip("\n")[: -(len(bearing) - 4)])
    expected = (f"{sensor}: line {len(sensor.read_text().splitlines())} has no line end and its last value {bearing[:4]} "
                "is shorter than that column's on every other line: the file may be cut off")
    out = tmp_path / "run"
    assert cli_exit_code(["pf", str(tmp_path), "--recorded", "--particles", "50", "--out", str(out)]) == 0
    assert json.loads((out / "metrics.json").read_text())["warnings"] == [expected]


def test_an_odometry_run_given_a_cut_ground_truth_records_it_in_metrics_json(tmp_path):
    """A ground truth read from a cut file and given to run(ground_truth=...): its read warning in the run's metrics."""
    import json

    from lidarkit.io.folder import ScanFolder
    from lidarkit.odometry import run

    seq = _kitti_lidar_sequence(tmp_path)
    expected = _cut_last_exponent(seq / "poses.txt")
    truth = Trajectory.from_kitti(seq / "poses.txt")
    run(ScanFolder(seq / "velodyne"), "kiss", ground_truth=truth, out_dir=tmp_path / "run")
    assert json.loads((tmp_path / "run" / "metrics.json").read_text())["warnings"][:1] == [expected]


def test_a_tum_sequence_keeps_its_cut_ground_truth_in_its_reader_warnings(tmp_path):
    """The poses a TUM sequence keeps per frame are a new trajectory: a groundtruth.txt cut inside its last number
    (its quaternion still of unit norm to the check's tolerance) was said in the log only, not in the run's warnings."""
    import cv2

    from lidarkit.io.base import read_warnings_of
    from lidarkit.io.tum import TumRGBD

    seq = tmp_path / "rgbd_dataset_freiburg3_cut"
    (seq / "rgb").mkdir(parents=True)
    for k in range(4):
        cv2.imwrite(str(seq / "rgb" / f"{k}.png"), np.full((48, 64), 40 * k, np.uint8))
    (seq / "rgb.txt").write_text("".join(f"{100 + 0.1 * k:.6f} rgb/{k}.png\n" for k in range(4)))
    rows = [f"{100 + 0.1 * k:.4f} {0.1234 * k:.4f} 0.5000 0.2500 0.0000 0.0000 0.0010 0.99999" for k in range(5)]
    (seq / "groundtruth.txt").write_text("\n".join(rows)[:-2])  # the last qw 0.99999 cut to 0.999, no line end
    tum = TumRGBD(seq)
    warned = read_warnings_of(tum, tum.ground_truth)
    assert len(warned) == 1 and warned[0].startswith(f"{seq / 'groundtruth.txt'}: line 5 ") and "cut off" in warned[0]


def test_a_vo_run_given_a_cut_intrinsics_file_records_it_in_metrics_json(tmp_path):
    """--calib read through a file cut inside its last number: in metrics.json's warnings with the reader's."""
    import json
    import shutil

    from conftest import cli_exit_code

    from lidarkit.io.kitti import read_kitti_calib

    source = shared_path("kitti_images", "sequences", "06")
    seq = tmp_path / "images"
    seq.mkdir()
    for k in range(6):
        shutil.copy(source / "image_0" / f"{k:06d}.png", seq)
    K = read_kitti_calib(source / "calib.txt")["P0"][:, :3]
    calib = tmp_path / "K.txt"
    calib.write_text("\n".join(" ".join(f"{v:.6f}" for v in row) for row in K)[:-5])  # 1.000000 cut to 1.0
    out = tmp_path / "run"
    assert cli_exit_code(["vo", str(seq), "--calib", str(calib), "--out", str(out), "--no-progress"]) == 0
    warned = json.loads((out / "metrics.json").read_text())["warnings"]
    assert [w for w in warned if str(calib) in w] == [f"{calib}: line 3 has no line end and its last value 1.0 is shorter "
                                                      "than that column's on every other line: the file may be cut off"]
