"""Freiburg landmark reader on the three real copies and on corrupted copies."""

from __future__ import annotations

import logging

import numpy as np
import pytest
from conftest import shared_path

from lidarkit.errors import ConfigError, DataError
from lidarkit.io import open_dataset
from lidarkit.io.landmarks import LandmarkData

VARIANTS = ["burgard_ekf", "burgard_particle_filter", "robot_mapping_stachniss"]


@pytest.mark.parametrize("variant", VARIANTS)
def test_real_copies_parse_into_arrays(variant):
    data = open_dataset("landmarks", shared_path("pf", variant))
    assert isinstance(data, LandmarkData)
    assert len(data) == 331 and data.odometry.shape == (331, 3)
    assert data.n_readings == 1212
    assert data.landmarks.ids.tolist() == list(range(1, 10))
    np.testing.assert_array_equal(data.landmarks.positions_xy[6], [5.0, 5.0])  # landmark 7
    assert data.step_offsets[0] == 0 and data.step_offsets[-1] == 1212 and len(data.step_offsets) == 332
    assert (np.diff(data.meas_step) >= 0).all()
    # every reading's landmark index points at its id
    np.testing.assert_array_equal(data.landmarks.ids[data.meas_landmark_index], data.meas_landmark_id)
    # the first step of every copy sees landmarks 1 and 2
    assert data.meas_landmark_id[data.readings(0)].tolist() == [1, 2]
    assert np.isfinite(data.meas_range_m).all() and np.isfinite(data.meas_bearing_rad).all()
    # first reading: line 2 of the file
    assert data.meas_line[0] == 2


def test_sensor_file_path_and_overrides(copy_of):
    folder = copy_of(shared_path("pf", "burgard_particle_filter"))
    by_file = LandmarkData(folder / "sensor_data.dat")
    (folder / "map.txt").write_text((folder / "world.dat").read_text())
    by_override = LandmarkData(folder, world="map.txt")
    np.testing.assert_array_equal(by_file.odometry, by_override.odometry)
    assert by_override.world_path.name == "map.txt"


def test_negative_range_policies(caplog):
    path = shared_path("pf", "robot_mapping_stachniss")
    with caplog.at_level(logging.WARNING, logger="lidarkit.io.landmarks"):
        kept = LandmarkData(path)
    assert kept.negative_range_mask.sum() == 1
    k = int(np.flatnonzero(kept.negative_range_mask)[0])
    assert kept.meas_range_m[k] == pytest.approx(-0.035065641258)
    assert kept.meas_landmark_id[k] == 7 and kept.meas_line[k] == 1541
    assert "negative range" in caplog.text
    dropped = LandmarkData(path, negative_range="drop")
    assert dropped.n_readings == 1211 and dropped.n_dropped == 1 and not dropped.negative_range_mask.any()
    assert dropped.step_offsets[-1] == 1211
    with pytest.raises(DataError, match=r"line 1541.*negative range"):
        LandmarkData(path, negative_range="error")
    with pytest.raises(ConfigError, match="negative_range"):
        LandmarkData(path, negative_range="clip")


def _corrupt(copy_of, variant: str, filename: str, edit) -> LandmarkData:
    folder = copy_of(shared_path("pf", variant))
    lines = (folder / filename).read_text().splitlines()
    (folder / filename).write_text("\n".join(edit(lines)) + "\n")
    return folder


@pytest.mark.parametrize(
    ("filename", "edit", "pattern"),
    [
        ("sensor_data.dat", lambda ls: ls[:4] + ["SENSOR 12 1.0 0.1"] + ls[4:], r"line 5\).*unknown landmark id 12"),
        ("sensor_data.dat", lambda ls: ls[:2] + ["SENSOR 1 1.0"] + ls[2:], r"line 3\).*SENSOR needs 3 values"),
        ("sensor_data.dat", lambda ls: ls[:2] + ["ODOMETRY 0.1 x 0.0"] + ls[2:], r"line 3\).*not a number: 'x'"),
        ("sensor_data.dat", lambda ls: ls[:2] + ["ODOMETRY 0.1 nan 0.0"] + ls[2:], r"line 3\).*non-finite"),
        ("sensor_data.dat", lambda ls: ls[:1] + ["SENSOR 2 inf 0.3"] + ls[1:], r"line 2\).*non-finite"),
        ("sensor_data.dat", lambda ls: ls[:3] + ["LASER 1 2 3"] + ls[3:], r"line 4\).*unknown record type 'LASER'"),
        ("sensor_data.dat", lambda ls: ls[1:], r"line 1\).*SENSOR reading before any ODOMETRY"),
        ("sensor_data.dat", lambda ls: [], r"no ODOMETRY records"),
        ("sensor_data.dat", lambda ls: ls[:2] + ["SENSOR 1.5 1.0 0.1"] + ls[2:], r"line 3\).*not an integer"),
        ("world.dat", lambda ls: ls + ["3 4 4"], r"world.dat \(line 10\).*duplicate landmark id 3 \(first on line 3\)"),
        ("world.dat", lambda ls: ls[:1] + ["2 0"] + ls[2:], r"world.dat \(line 2\).*3 fields"),
        ("world.dat", lambda ls: [], r"world.dat: no landmarks"),
        ("world.dat", lambda ls: ls[:-1] + ["9 5 nan"], r"world.dat \(line 9\).*non-finite"),
        # an id beyond int64 was an OverflowError; a 10 kB token is quoted shortened; the ids that exist are listed
        ("world.dat", lambda ls: ["99999999999999999999999 1 1"] + ls[1:], r"world.dat \(line 1\).*landmark id '9{23}' is beyond a 64-bit"),
        ("sensor_data.dat", lambda ls: ls[:2] + ["ODOMETRY 0.1 " + "7" * 10000 + "x 0.0"] + ls[2:], r"not a number: '7{40}'\.\.\. \(10001 characters\)$"),
        ("world.dat", lambda ls: ["-1 1 1"] + ls[1:], r"unknown landmark id 1 \(world file world.dat has ids -1, 2, 3, 4, 5, 6, 7, 8, 9\)"),
    ],
)
def test_corrupted_copies_raise_dataerror(copy_of, filename, edit, pattern):
    folder = _corrupt(copy_of, "burgard_particle_filter", filename, edit)
    with pytest.raises(DataError, match=pattern):
        LandmarkData(folder)


def test_a_byte_order_mark_is_left_out(copy_of):
    """A file an editor saved with a UTF-8 byte-order mark reads as the same data (its first record was 'unknown')."""
    folder = copy_of(shared_path("pf", "burgard_particle_filter"))
    plain = LandmarkData(folder)
    for name in ("world.dat", "sensor_data.dat"):
        (folder / name).write_bytes(b"\xef\xbb\xbf" + (folder / name).read_bytes())
    marked = LandmarkData(folder)
    np.testing.assert_array_equal(marked.odometry, plain.odometry)
    np.testing.assert_array_equal(marked.landmarks.ids, plain.landmarks.ids)


def test_missing_files(tmp_path):
    with pytest.raises(DataError, match="not found"):
        LandmarkData(tmp_path / "nope")
    (tmp_path / "sensor_data.dat").write_text("ODOMETRY 0 0.1 0\n")
    with pytest.raises(DataError, match=r"world.dat: file not found"):
        LandmarkData(tmp_path)


def test_empty_step_is_allowed(tmp_path):
    (tmp_path / "world.dat").write_text("1 2 1\n2 0 4\n")
    (tmp_path / "sensor_data.dat").write_text("ODOMETRY 0 0.1 0\nODOMETRY 0 0.1 0\nSENSOR 2 4.0 1.5\n")
    data = LandmarkData(tmp_path)
    assert len(data) == 2 and data.n_readings == 1
    assert data.readings(0) == slice(0, 0) and data.readings(1) == slice(0, 1)
    assert data.meas_landmark_index.tolist() == [1]


def test_bundled_sample_opens_without_shared_data():
    from lidarkit.samples import sample_path

    data = open_dataset("landmarks", sample_path("freiburg_pf"))
    assert len(data) == 331 and data.n_readings == 1212 and not data.negative_range_mask.any()
    assert data.odometry[0].tolist() == [0.100068080139, 0.100249642432, -0.000326992241362]


def test_the_parent_folder_of_several_datasets_lists_them(tmp_path):
    """`lidarkit pf DATA/pf` (the parent of the three Freiburg copies) said "DATA/pf/world.dat: file not found"."""
    parent = shared_path("pf")
    with pytest.raises(DataError) as exc:
        LandmarkData(parent)
    assert str(exc.value) == (f"{parent}: no world.dat + sensor_data.dat in this folder; its subfolders burgard_ekf, "
                              "burgard_particle_filter, robot_mapping_stachniss hold them: give one of those")
    (tmp_path / "empty").mkdir()  # no subfolder holds one: the missing file is named, as before
    with pytest.raises(DataError, match=r"world.dat: file not found"):
        LandmarkData(tmp_path)
