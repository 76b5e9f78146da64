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
