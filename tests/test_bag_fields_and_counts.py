"""Bags whose PointCloud2 field lists, message counts, paths or header stamps are unusual: read where the data is
usable, otherwise one DataError naming the bag, the message and the reason. Real files, no mocks."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from lidarkit.errors import DataError
from lidarkit.io import open_dataset

F32, U32, U16 = 7, 6, 4
N_POINTS = 256


def _ring(n: int = N_POINTS) -> tuple[np.ndarray, np.ndarray]:
    """``(xyz (n, 3), times (n,) s)`` of one 0.1 s sweep of a 10 m ring, times following the azimuth."""
    angle = np.linspace(0, 2 * np.pi, n, endpoint=False)
    xyz = np.column_stack([10 * np.cos(angle), 10 * np.sin(angle), np.linspace(-1, 1, n)])
    return xyz, np.linspace(0.0, 0.1, n)


def _write_bag(path, fields, records, stamps_s):
    """A ROS 1 bag of one PointCloud2 on /points per structured array in ``records`` (its bytes are the message data),
    stamped ``stamps_s``, with the PointFields ``fields`` ``(name, offset, datatype, count)`` (names may repeat, as
    the arrays' own names cannot)."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    T = store.types
    pc2 = "sensor_msgs/msg/PointCloud2"
    with Writer(path) as writer:
        conn = writer.add_connection("/points", pc2, typestore=store)
        for k, (rec, stamp_s) in enumerate(zip(records, stamps_s)):
            sec = int(np.floor(stamp_s))
            stamp = T["builtin_interfaces/msg/Time"](sec=sec, nanosec=int(round((stamp_s - sec) * 1e9)))
            msg = T[pc2](header=T["std_msgs/msg/Header"](seq=k, stamp=stamp, frame_id="lidar"), height=1, width=len(rec),
                         is_bigendian=False, point_step=rec.dtype.itemsize, row_step=rec.dtype.itemsize * len(rec),
                         fields=[T["sensor_msgs/msg/PointField"](name=n, offset=o, datatype=d, count=c) for n, o, d, c in fields],
                         data=np.frombuffer(rec.tobytes(), dtype=np.uint8), is_dense=True)
            writer.write(conn, 10**12 + k * 10**8, store.serialize_ros1(msg, pc2))
    return path


def test_a_counted_intensity_reads_its_first_value(tmp_path):
    """An ``intensity`` of count 2 (a dual-return driver) was a ValueError traceback ("no field of name intensity"): it
    is read as its first value."""
    xyz, times = _ring()
    rec = np.zeros(N_POINTS, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4", (2,)), ("t", "<u4")])
    rec["x"], rec["y"], rec["z"] = xyz.T
    rec["intensity"] = np.column_stack([np.linspace(0, 1, N_POINTS), np.full(N_POINTS, 7.0)])
    rec["t"] = np.round(times * 1e9)
    fields = [("x", 0, F32, 1), ("y", 4, F32, 1), ("z", 8, F32, 1), ("intensity", 12, F32, 2), ("t", 20, U32, 1)]
    scan = open_dataset("rosbag", _write_bag(tmp_path / "dual.bag", fields, [rec], [5.0])).read_scan(0)
    np.testing.assert_array_equal(scan.intensity, np.linspace(0, 1, N_POINTS).astype(np.float32))
    np.testing.assert_allclose(scan.point_times_s, times, atol=1e-9)


def test_a_counted_time_field_is_refused_naming_its_count(tmp_path):
    """A time field of count 2 was a ValueError traceback ("no field of name t"): one line naming the message and the
    count (its two values may be the halves of one 64-bit time: either read alone would deskew by nonsense)."""
    xyz, times = _ring()
    counted = np.zeros(N_POINTS, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("t", "<u4", (2,))])
    counted["x"], counted["y"], counted["z"] = xyz.T
    counted["t"] = np.column_stack([np.round(times * 1e9), np.zeros(N_POINTS)])
    fields = [("x", 0, F32, 1), ("y", 4, F32, 1), ("z", 8, F32, 1), ("t", 12, U32, 2)]
    bag = _write_bag(tmp_path / "t2.bag", fields, [counted], [5.0])
    for time_field in ("auto", "t"):
        with pytest.raises(DataError, match=r"t2\.bag \(message 0 on /points\): per-point time field 't' has count 2 \(2 values "
                                            r"per point\): which is the point's time is not known \(time_field= names another"):
            open_dataset("rosbag", bag, time_field=time_field).read_scan(0)
    assert open_dataset("rosbag", bag, time_field="none").read_scan(0).point_times_s is None  # the way out it names


def test_padding_and_repeated_fields_the_reader_does_not_use_are_left_out(tmp_path):
    """``x y z _ _ t`` (PCL's padding fields, repeated) was refused: "field layout not readable (duplicate field
    names)". Padding and repeated fields nothing reads are left out; a repeated x or intensity is ambiguous: refused."""
    xyz, times = _ring()
    rec = np.zeros(N_POINTS, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("pad0", "<f4"), ("pad1", "<f4"),
                                    ("t", "<u4"), ("ring0", "<u2"), ("ring1", "<u2")])
    rec["x"], rec["y"], rec["z"] = xyz.T
    rec["pad0"] = rec["pad1"] = np.nan
    rec["t"] = np.round(times * 1e9)
    base = [("x", 0, F32, 1), ("y", 4, F32, 1), ("z", 8, F32, 1)]
    fields = base + [("_", 12, F32, 1), ("_", 16, F32, 1), ("t", 20, U32, 1), ("ring", 24, U16, 1), ("ring", 26, U16, 1)]
    scan = open_dataset("rosbag", _write_bag(tmp_path / "pad.bag", fields, [rec], [5.0])).read_scan(0)
    np.testing.assert_allclose(scan.points_xyz, xyz.astype(np.float32), atol=0)
    np.testing.assert_allclose(scan.point_times_s, times, atol=1e-9)

    for name, what, extra in (("x", "a point's x", [("x", 12, F32, 1)]),
                              ("intensity", "which is the points' intensity", [("intensity", 12, F32, 1), ("intensity", 16, F32, 1)])):
        twice = base + extra + [("t", 20, U32, 1)]
        bag = _write_bag(tmp_path / f"two_{name}.bag", twice, [rec], [5.0])
        with pytest.raises(DataError, match=rf"two_{name}\.bag \(message 0 on /points\): field '{name}' is given 2 times in "
                                            rf"the field list: {what} is not known"):
            open_dataset("rosbag", bag).read_scan(0)


@pytest.fixture(scope="module")
def ros2_bag(tmp_path_factory):
    """A simulated ROS 2 bag folder of 4 sweeps."""
    from lidarkit.sim.bag_export import export_bag
    from lidarkit.sim.lidar import SimulatedLidarSequence

    root = tmp_path_factory.mktemp("ros2")
    return export_bag(SimulatedLidarSequence(n_frames=4, n_beams=8, n_azimuths=90), root / "bag", "rosbag2")


def _with_points_count(bag, out, count: int):
    """A copy of ROS 2 bag folder ``bag`` at ``out`` whose metadata.yaml counts ``count`` messages on /points."""
    shutil.copytree(bag, out)
    meta = out / "metadata.yaml"
    text = meta.read_text()
    entry = "- message_count: 4\n    topic_metadata:\n      name: /points\n"
    assert entry in text
    meta.write_text(text.replace(entry, entry.replace("4", str(count), 1)))
    return out


def test_a_ros2_bag_whose_metadata_over_counts_its_scans_ends_in_one_line(ros2_bag, tmp_path):
    """metadata.yaml counting 5 messages of 4 stored was a KeyError traceback from the stamps: one line, as reading
    the missing scan says, naming metadata.yaml's count."""
    over = open_dataset("rosbag", _with_points_count(ros2_bag, tmp_path / "over", 5))
    assert len(over) == 5
    with pytest.raises(DataError, match=r"over \(message 4 on /points\): the bag ends after 4 of 5 messages on /points "
                                        r"\(5: the count in metadata\.yaml; truncated\?\)"):
        over.timestamps_s
    with pytest.raises(DataError, match=r"over \(message 4 on /points\): the bag ends after 4 of 5 messages on /points"):
        over.read_scan(4)
    assert len(open_dataset("rosbag", ros2_bag).timestamps_s) == 4  # counted right: read


def test_a_ros2_bag_whose_metadata_under_counts_its_scans_is_refused_naming_both(ros2_bag, tmp_path):
    """metadata.yaml counting 3 messages of 4 stored read 3 scans without a word (the readers' scan count is
    metadata.yaml's, fixed before a run picks its frames): refused, naming both numbers and how to rebuild it."""
    under = open_dataset("rosbag", _with_points_count(ros2_bag, tmp_path / "under", 3))
    with pytest.raises(DataError, match=r"under: the bag holds 4 messages on /points but metadata\.yaml counts 3; only the "
                                        r"counted ones would be read \('ros2 bag reindex' rebuilds metadata\.yaml"):
        under.timestamps_s
    np.testing.assert_array_equal(under.read_scan(2).points_xyz, open_dataset("rosbag", ros2_bag).read_scan(2).points_xyz)


def test_a_ros2_bags_metadata_yaml_opens_its_folder(ros2_bag):
    """``rosbag:BAG/metadata.yaml`` (a path copied from a file browser) was "not a readable ROS bag (AnyReaderError:
    Unrecognized storage format '.yaml'...)": it opens the bag, its folder."""
    from_file = open_dataset("rosbag", ros2_bag / "metadata.yaml")
    assert from_file.path == ros2_bag and len(from_file) == 4
    np.testing.assert_array_equal(from_file.read_scan(3).points_xyz, open_dataset("rosbag", ros2_bag).read_scan(3).points_xyz)
    np.testing.assert_array_equal(from_file.timestamps_s, open_dataset("rosbag", ros2_bag).timestamps_s)


def test_header_stamps_all_zero_are_said_to_be_unset(tmp_path):
    """A driver that never stamps its clouds: the run said "time stamps are not strictly increasing: 0 s after 0 s of
    frame 0". It now says that every stamp is 0 and that the reader has no other times."""
    from lidarkit.odometry import run

    xyz, times = _ring()
    rec = np.zeros(N_POINTS, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("t", "<u4")])
    rec["x"], rec["y"], rec["z"] = xyz.T
    rec["t"] = np.round(times * 1e9)
    fields = [("x", 0, F32, 1), ("y", 4, F32, 1), ("z", 8, F32, 1), ("t", 12, U32, 1)]
    bag = _write_bag(tmp_path / "unstamped.bag", fields, [rec] * 3, [0.0] * 3)
    message = (r"unstamped\.bag: every PointCloud2 header stamp on /points is 0 \(not set by the driver\): the scans have no "
               r"time stamps .* the reader takes no other")
    with pytest.raises(DataError, match=message):
        open_dataset("rosbag", bag).timestamps_s
    with pytest.raises(DataError, match=message):
        run(str(bag), "vanilla")
    one = _write_bag(tmp_path / "one.bag", fields, [rec], [0.0])  # (one scan: nothing to order, its 0 is read)
    assert open_dataset("rosbag", one).timestamps_s.tolist() == [0.0]


def test_the_padding_field_named_as_the_time_field_is_one_line(tmp_path):
    """time_field=_ on a cloud with PCL's padding: numpy's "no field of name _" traceback (padding is never laid out)."""
    xyz, times = _ring()
    rec = np.zeros(N_POINTS, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("pad", "<u4"), ("t", "<u4")])
    rec["x"], rec["y"], rec["z"] = xyz.T
    rec["t"] = np.round(times * 1e9)
    fields = [("x", 0, F32, 1), ("y", 4, F32, 1), ("z", 8, F32, 1), ("_", 12, U32, 1), ("t", 16, U32, 1)]
    bag = _write_bag(tmp_path / "pad1.bag", fields, [rec], [5.0])
    with pytest.raises(DataError, match=r"'_' is padding \(PCL's filler bytes\), not a per-point time field"):
        open_dataset("rosbag", bag, time_field="_").read_scan(0)


def test_a_bare_metadata_yaml_is_detected_as_the_bag_and_named_by_its_folder(ros2_bag, monkeypatch):
    """`lidarkit odometry BAG/metadata.yaml` suggested carmen:; opened from inside the folder the run was named
    "rosbag:/points" (the folder "." has no name)."""
    from lidarkit.io import detect_kind

    assert detect_kind(ros2_bag / "metadata.yaml") == "rosbag"
    monkeypatch.chdir(ros2_bag)
    assert open_dataset("rosbag", "metadata.yaml").name == open_dataset("rosbag", ros2_bag).name
    assert open_dataset("rosbag", "metadata.yaml").name != "rosbag:/points"
