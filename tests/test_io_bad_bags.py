"""Bad recordings: each a DataError naming the file, the message (or frame) and the reason. Real files, no mocks."""

from __future__ import annotations

import numpy as np
import pytest

from lidarkit.errors import DataError
from lidarkit.io import open_dataset
from lidarkit.odometry import run

F32, U32 = 7, 6


def _cloud_bytes(n: int, times: np.ndarray | None = None) -> tuple[list[tuple[str, int, int]], int, bytes]:
    """x, y, z, time float32 points on a 10 m ring (a valid cloud unless the caller breaks it)."""
    angle = np.linspace(0, 2 * np.pi, n, endpoint=False)
    rec = np.zeros(n, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("time", "<f4")])
    rec["x"], rec["y"], rec["z"] = 10 * np.cos(angle), 10 * np.sin(angle), np.linspace(-1, 1, n)
    rec["time"] = np.linspace(0, 0.1, n) if times is None else times
    return [("x", 0, F32), ("y", 4, F32), ("z", 8, F32), ("time", 12, F32)], 16, rec.tobytes()


def write_ros1_bag(path, clouds, *, extra_odometry: bool = False, topic: str = "/points", odometry=(), second_odometry: bool = False,
                   received_from_ns: int = 10**12, child_frame: str = "lidar", cloud_frames=None):
    """A ROS 1 bag with one PointCloud2 per ``(stamp_s, fields, point_step, data, width)`` in ``clouds`` and one
    nav_msgs/Odometry on /ground_truth (and /ground_truth2 with ``second_odometry``) per ``(stamp_s, xyz, quat_xyzw)``
    in ``odometry`` (the pose of ``child_frame``; cloud k is in frame ``cloud_frames[k]``, else lidar), message k received
    ``received_from_ns`` + k x 0.1 s (the log order is the lists' order)."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    T = store.types
    pc2 = "sensor_msgs/msg/PointCloud2"
    with Writer(path) as writer:
        conn = writer.add_connection(topic, pc2, typestore=store) if clouds else None
        for k, (stamp_s, fields, step, data, width) in enumerate(clouds):
            sec = int(np.floor(stamp_s))
            header = T["std_msgs/msg/Header"](seq=k, stamp=T["builtin_interfaces/msg/Time"](sec=sec, nanosec=int(round((stamp_s - sec) * 1e9))),
                                             frame_id="lidar" if cloud_frames is None else cloud_frames[k])
            msg = T[pc2](header=header, height=1, width=width, is_bigendian=False, point_step=step, row_step=step * width,
                         fields=[T["sensor_msgs/msg/PointField"](name=n, offset=o, datatype=d, count=1) for n, o, d in fields],
                         data=np.frombuffer(data, dtype=np.uint8), is_dense=True)
            writer.write(conn, received_from_ns + k * 10**8, store.serialize_ros1(msg, pc2))  # receive time: increasing
        for odometry_topic in ("/ground_truth", "/ground_truth2")[: 1 + second_odometry] if odometry else ():
            odo = writer.add_connection(odometry_topic, "nav_msgs/msg/Odometry", typestore=store)
            zeros, vec = np.zeros(36), T["geometry_msgs/msg/Vector3"]
            for k, (stamp_s, xyz, q) in enumerate(odometry):
                sec = int(np.floor(stamp_s))
                header = T["std_msgs/msg/Header"](seq=k, stamp=T["builtin_interfaces/msg/Time"](sec=sec, nanosec=int(round((stamp_s - sec) * 1e9))), frame_id="odom")
                pose = T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=xyz[0], y=xyz[1], z=xyz[2]),
                                                   orientation=T["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3]))
                msg = T["nav_msgs/msg/Odometry"](
                    header=header, child_frame_id=child_frame, pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=zeros),
                    twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=T["geometry_msgs/msg/Twist"](
                        linear=vec(x=0.0, y=0.0, z=0.0), angular=vec(x=0.0, y=0.0, z=0.0)), covariance=zeros))
                writer.write(odo, received_from_ns + k * 10**8 + 1, store.serialize_ros1(msg, "nav_msgs/msg/Odometry"))
        if extra_odometry or not clouds:
            odom = writer.add_connection("/odom", "std_msgs/msg/String", typestore=store)
            writer.write(odom, 1, store.serialize_ros1(T["std_msgs/msg/String"](data="not a cloud"), "std_msgs/msg/String"))
    return path


def good(k: int, n: int = 64):
    fields, step, data = _cloud_bytes(n)
    return (1000.0 + 0.1 * k, fields, step, data, n)


def test_bag_without_pointcloud2_topic(tmp_path):
    bag = write_ros1_bag(tmp_path / "no_clouds.bag", [])
    with pytest.raises(DataError, match=r"no_clouds\.bag: no sensor_msgs/msg/PointCloud2 topic; topics present: /odom \(std_msgs/msg/String\)"):
        open_dataset("rosbag", bag)


def test_pointcloud2_without_xyz(tmp_path):
    fields, step, data = _cloud_bytes(64)
    fields = [("a" if name == "y" else name, offset, dt) for name, offset, dt in fields]
    bag = write_ros1_bag(tmp_path / "no_y.bag", [good(0), (1000.1, fields, step, data, 64)])
    # (the run reads the recording's sweep timing before its frames: the message, named by file and topic, stops it there)
    with pytest.raises(DataError, match=r"no_y\.bag \(message 1 on /points\): PointCloud2 has no y field \(fields: x, a, z, time\)$"):
        run(str(bag), "kiss")
    with pytest.raises(DataError, match=r"no_y\.bag \(message 1 on /points\): PointCloud2 has no y field"):
        open_dataset("rosbag", bag).read_scan(1)


def test_truncated_bag_and_truncated_message(tmp_path):
    whole = write_ros1_bag(tmp_path / "whole.bag", [good(k, 2000) for k in range(4)])
    cut = tmp_path / "cut.bag"
    cut.write_bytes(whole.read_bytes()[: whole.stat().st_size // 2])
    with pytest.raises(DataError, match=r"cut\.bag: not a readable ROS bag \("):
        open_dataset("rosbag", cut)
    fields, step, data = _cloud_bytes(100)
    short = write_ros1_bag(tmp_path / "short.bag", [good(0), (1000.1, fields, step, data[: 50 * step], 100)])
    with pytest.raises(DataError, match=r"short\.bag \(message 1 on /points\): data holds 800 bytes but .* need 1600 \(truncated message\)"):
        open_dataset("rosbag", short).read_scan(1)


def test_a_bag_damaged_in_the_middle_is_a_data_error_in_every_pass(tmp_path):
    """A ROS 1 bag whose fourth message record header is overwritten: the stamps pass and the ground-truth pass (each
    reads a whole topic) say which message could not be read, as reading the scans does (they raised the reader's own
    exception)."""
    clouds = [good(k, 2000) for k in range(8)]
    whole = write_ros1_bag(tmp_path / "whole.bag", clouds, odometry=[(1000.0 + 0.1 * k, (k, 0, 0), (0, 0, 0, 1)) for k in range(8)])
    data = bytearray(whole.read_bytes())
    at = -1
    for _ in range(4):  # the header field "op=2" of a message data record
        at = data.index(b"op=\x02", at + 1)
    data[at - 8: at + 56] = b"\xff" * 64
    damaged = tmp_path / "damaged.bag"
    damaged.write_bytes(bytes(data))
    for what in ("timestamps_s", "ground_truth"):
        with pytest.raises(DataError, match=r"damaged\.bag \(message \d+ on /(points|ground_truth)\): cannot read the message .*damaged file"):
            getattr(open_dataset("rosbag", damaged), what)


def test_mcap_with_unknown_schema(tmp_path):
    from mcap.writer import Writer

    path = tmp_path / "blob.mcap"
    with open(path, "wb") as fh:
        writer = Writer(fh)
        writer.start()
        schema = writer.register_schema(name="acme_msgs/msg/Blob", encoding="jsonschema", data=b"{}")
        channel = writer.register_channel(topic="/blob", message_encoding="json", schema_id=schema)
        writer.add_message(channel, log_time=1, data=b"{}", publish_time=1)
        cloud_schema = writer.register_schema(name="sensor_msgs/msg/PointCloud2", encoding="jsonschema", data=b"{}")
        writer.register_channel(topic="/points_json", message_encoding="json", schema_id=cloud_schema)
        writer.finish()
    with pytest.raises(DataError, match=r"blob\.mcap: no sensor_msgs/msg/PointCloud2 topic; topics present: /blob \(acme_msgs/msg/Blob\), "
                                        r"/points_json \(sensor_msgs/msg/PointCloud2 \[jsonschema schema, not ros2msg or ros1msg\]\)"):
        open_dataset("mcap", path)
    with pytest.raises(DataError, match=r"topic '/blob' carries acme_msgs/msg/Blob, not sensor_msgs/msg/PointCloud2"):
        open_dataset("mcap", path, topic="/blob")


def test_a_ros1_bag_read_as_mcap_says_what_it_is(tmp_path):
    """mcap:run.bag (a ROS 1 bag) said "not a readable MCAP file (InvalidMagic: ... invalid magic: (35, 82, 79, 83, 66,
    65, 71, 32); truncated or damaged?)": those bytes are "#ROSBAG ", and the reader that opens it is named."""
    bag = write_ros1_bag(tmp_path / "run.bag", [good(k) for k in range(2)])
    with pytest.raises(DataError) as err:
        open_dataset("mcap", bag)
    assert str(err.value) == f"{bag}: a ROS 1 bag, not an MCAP file: read it with rosbag:{bag}"
    assert len(open_dataset("rosbag", bag)) == 2
    (tmp_path / "cut.mcap").write_bytes(b"#ROSBA")  # no whole ROS 1 magic: damaged, as before
    with pytest.raises(DataError, match=r"cut\.mcap: not a readable MCAP file \(.*; truncated or damaged\?\)"):
        open_dataset("mcap", tmp_path / "cut.mcap")


def test_time_field_with_nan(tmp_path):
    times = np.linspace(0, 0.1, 64)
    times[17] = np.nan
    fields, step, data = _cloud_bytes(64, times)
    bag = write_ros1_bag(tmp_path / "nan.bag", [good(0), good(1), (1000.2, fields, step, data, 64)])
    with pytest.raises(DataError, match=r"nan\.bag \(message 2 on /points\): per-point time field 'time' has 1 NaN or infinite values \(first at point 17\)"):
        open_dataset("rosbag", bag).read_scan(2)
    # points 0-2 missing returns (NaN x): the bad time is still named by its place in the message (it said point 14)
    rec = np.frombuffer(data, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("time", "<f4")]).copy()
    rec["x"][:3] = np.nan
    holes = write_ros1_bag(tmp_path / "holes.bag", [(1000.0, fields, step, rec.tobytes(), 64)])
    with pytest.raises(DataError, match=r"has 1 NaN or infinite values \(first at point 17\)"):
        open_dataset("rosbag", holes).read_scan(0)


def test_time_field_that_is_not_times(tmp_path):
    """A field that spans more than a sweep in one message (an intensity, 0-255, named by time_field=, or read as
    seconds where it holds microseconds) deskewed every sweep by it without a word: a DataError naming it."""
    fields, step, data = _cloud_bytes(64, np.linspace(0.0, 255.0, 64))
    bag = write_ros1_bag(tmp_path / "intensity.bag", [good(0), (1000.1, fields, step, data, 64)])
    ds = open_dataset("rosbag", bag)
    assert ds.read_scan(0).point_times_s is not None  # a sweep's times: read
    with pytest.raises(DataError, match=r"intensity\.bag \(message 1 on /points\): per-point time field 'time' spans 255 s within one "
                                        r"message \(read as seconds; a sweep lasts at most 1 s\): not the points' times"):
        ds.read_scan(1)
    assert open_dataset("rosbag", bag, time_field="none").read_scan(1).point_times_s is None  # the way out it names


def test_a_time_field_is_checked_against_the_point_order_and_the_azimuth(tmp_path):
    """A per-point value within 1 s named as time_field= (an intensity) was read as the points' times. Times that rise
    along the point order (a solid-state sensor in any direction) or that go back once per row but turn with the
    azimuth (an organized cloud, 16 rows of 128) are read; an intensity on either cloud is refused."""
    rng = np.random.default_rng(0)
    n = 2048
    rec = np.zeros(n, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("time", "<f4"), ("intensity", "<f4")])
    fields = [("x", 0, F32), ("y", 4, F32), ("z", 8, F32), ("time", 12, F32), ("intensity", 16, F32)]
    rec["intensity"] = rng.uniform(0.0, 0.9, n)
    rec["x"], rec["y"], rec["z"] = rng.normal(size=(3, n)) + [[10.0], [0.0], [0.0]]  # a forward view
    rec["time"] = np.linspace(0.0, 0.1, n)
    solid = rec.tobytes()
    azimuth = np.tile(np.linspace(0, 2 * np.pi, 128, endpoint=False), 16)
    rec["x"], rec["y"], rec["z"] = 10 * np.cos(azimuth), 10 * np.sin(azimuth), np.repeat(np.linspace(-1, 1, 16), 128)
    rec["time"] = np.tile(np.linspace(0.0, 0.1, 128, endpoint=False), 16)  # goes back 15 times in 2048 points
    bag = write_ros1_bag(tmp_path / "orders.bag", [(1000.0, fields, 20, solid, n), (1000.1, fields, 20, rec.tobytes(), n)])
    for k in (0, 1):
        assert open_dataset("rosbag", bag).read_scan(k).point_times_s.max() == pytest.approx(0.1, abs=1e-3)
        with pytest.raises(DataError, match=rf"orders\.bag \(message {k} on /points\): per-point time field 'intensity' does not "
                                            r"follow the sweep: its values go back 987 times in 2048 points"):
            open_dataset("rosbag", bag, time_field="intensity").read_scan(k)


def test_a_solid_state_sweep_stored_in_another_order_reads_its_times(tmp_path):
    """A Livox-like sweep (a rosette over 70 x 70 degrees, 20000 points in 0.1 s) stored binned in space goes back at
    every other point and sweeps no azimuth: its valid times were refused as "an intensity". Taken in the order of
    their times, its points trace the scan pattern: the times are read; a uniform value on the same cloud is not."""
    rng = np.random.default_rng(0)
    n = 20000
    times = np.sort(rng.uniform(0.0, 0.1, n))
    azimuth, elevation = np.radians(35) * np.sin(2 * np.pi * 1000 * times), np.radians(35) * np.cos(2 * np.pi * 1370 * times)
    range_m = rng.uniform(5.0, 30.0, n)
    xyz = range_m[:, None] * np.c_[np.cos(elevation) * np.cos(azimuth), np.cos(elevation) * np.sin(azimuth), np.sin(elevation)]
    binned = np.lexsort((np.floor(xyz[:, 1]), np.floor(xyz[:, 0])))
    rec = np.zeros(n, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("time", "<f4"), ("intensity", "<f4")])
    fields = [("x", 0, F32), ("y", 4, F32), ("z", 8, F32), ("time", 12, F32), ("intensity", 16, F32)]
    rec["x"], rec["y"], rec["z"] = xyz[binned].T
    rec["time"], rec["intensity"] = times[binned], rng.uniform(0.0, 0.9, n)
    bag = write_ros1_bag(tmp_path / "livox.bag", [(1000.0 + 0.1 * k, fields, 20, rec.tobytes(), n) for k in range(2)])
    scan = open_dataset("rosbag", bag).read_scan(1)
    np.testing.assert_array_equal(scan.point_times_s, rec["time"].astype(np.float64))
    assert scan.stamp_instant == "start"
    with pytest.raises(DataError, match=r"livox\.bag \(message 0 on /points\): per-point time field 'intensity' does not follow the "
                                        r"sweep: its values go back \d+ times in 20000 points and do not turn with the azimuth "
                                        r"nor trace a scan pattern in their order"):
        open_dataset("rosbag", bag, time_field="intensity").read_scan(0)


def test_clouds_of_two_frames_on_one_topic_are_refused(tmp_path):
    """A front and a rear LiDAR alternating on /points (header.frame_id front, rear) were registered as one sensor's
    sweeps (a 60.65 m path for a 3 m drive) without a word: the first message in another frame is a DataError naming
    it, both frames and the topic, whichever pass reads it first. A leading "/" names the same frame."""
    bag = write_ros1_bag(tmp_path / "two.bag", [good(k) for k in range(4)], cloud_frames=["front", "rear", "front", "rear"])
    message = (r"two\.bag \(message 1 on /points\): header\.frame_id 'rear' where message 0 on /points is in 'front': the "
               r"recording mixes sensors on one topic, and the reader reads one sensor per topic")
    with pytest.raises(DataError, match=message):
        open_dataset("rosbag", bag).read_scan(3)
    with pytest.raises(DataError, match=message):
        open_dataset("rosbag", bag).timestamps_s
    with pytest.raises(DataError, match=message):
        run(open_dataset("rosbag", bag), "kiss")
    slashed = write_ros1_bag(tmp_path / "slash.bag", [good(k) for k in range(3)], cloud_frames=["lidar", "/lidar", "lidar"])
    assert len(open_dataset("rosbag", slashed).timestamps_s) == 3


def test_a_ring_number_named_as_time_field_is_refused(tmp_path):
    """time_field=ring (a uint16 beam number, 0-15) read as 0-15 ns of per-point times: kiss 'deskewed' every sweep by
    ring number; an 8- or 16-bit integer field cannot hold times, refused naming it."""
    fields, step, data = _cloud_bytes(64)
    rec = np.zeros(64, dtype=[("p", "V16"), ("ring", "<u2"), ("pad", "V2")])
    rec["p"] = np.frombuffer(data, dtype="V16")
    rec["ring"] = np.arange(64) % 16
    bag = write_ros1_bag(tmp_path / "ring.bag", [(1000.0, [*fields, ("ring", 16, 4)], 20, rec.tobytes(), 64)])
    assert open_dataset("rosbag", bag).read_scan(0).point_times_s is not None  # its own 'time' field: read
    with pytest.raises(DataError, match=r"ring\.bag \(message 0 on /points\): per-point time field 'ring' is a 16-bit integer: "
                                        r"too small for times"):
        open_dataset("rosbag", bag, time_field="ring").read_scan(0)


def test_a_kitti_folder_given_as_a_bag_is_called_what_it_is(tmp_path):
    """rosbag:KITTI_FOLDER said "not a readable ROS bag (FileNotFoundError: Expected metadata file ...; truncated or
    damaged?)": it is a folder that holds no bag, and the kind it reads as is named."""
    from lidarkit.sim.lidar import SimulatedLidarSequence, export_kitti

    folder = export_kitti(SimulatedLidarSequence(n_frames=2, n_beams=8, n_azimuths=90), tmp_path / "run")
    with pytest.raises(DataError, match=r"run: a folder that is no ROS bag \(no \.bag files, no metadata\.yaml\): it reads as "
                                        r"'kitti' data \(kitti:PATH\)"):
        open_dataset("rosbag", folder, topic="/points").read_scan(0)


def test_a_folder_of_split_bags_with_an_unreadable_part_names_that_part(tmp_path):
    """A folder of split bags whose part is truncated said "a folder that is no ROS bag (no .bag files, no
    metadata.yaml)": the unreadable part is named with the reader's reason, as when it is opened on its own."""
    folder = tmp_path / "parts"
    folder.mkdir()
    write_ros1_bag(folder / "run_0.bag", [good(k, 2000) for k in range(2)])
    whole = write_ros1_bag(tmp_path / "run_1.bag", [good(k, 2000) for k in range(2, 4)])
    (folder / "run_1.bag").write_bytes(whole.read_bytes()[: whole.stat().st_size // 2])
    reason = r"not a readable ROS bag \(AnyReaderError: Bag index looks damaged: .*; truncated or damaged\?\)"
    with pytest.raises(DataError, match=rf"parts/run_1\.bag: {reason}$"):
        open_dataset("rosbag", folder)
    (folder / "run_0.bag").unlink()  # the only part unreadable
    with pytest.raises(DataError, match=rf"parts/run_1\.bag: {reason}$"):
        open_dataset("rosbag", folder)


def test_time_going_backwards(tmp_path):
    bag = write_ros1_bag(tmp_path / "back.bag", [good(0), good(1), (good(1)[0] - 0.05, *good(2)[1:])])
    ds = open_dataset("rosbag", bag)
    with pytest.raises(DataError, match=r"back\.bag \(message 2 on /points\): time goes backwards: header stamp 1000\.050000000 s is before "
                                        r"1000\.100000000 s of message 1"):
        ds.read_scan(2)
    with pytest.raises(DataError, match="time goes backwards"):
        ds.timestamps_s


def test_time_going_backwards_is_named_at_its_message_by_every_later_read(tmp_path):
    """The pass over the first scans stopped at message 2 and left the stream past it: reading scan 4 then went on from
    message 3, compared with message 1's stamp, and ran (or named a later message). Each read now names message 2."""
    clouds = [good(0), good(1), (good(1)[0] - 0.05, *good(2)[1:]), good(3), good(4)]
    bag = write_ros1_bag(tmp_path / "back.bag", clouds)
    message = (r"back\.bag \(message 2 on /points\): time goes backwards: header stamp 1000\.050000000 s is before "
               r"1000\.100000000 s of message 1")
    ds = open_dataset("rosbag", bag)
    for index in (4, 3, 4):
        with pytest.raises(DataError, match=message):
            ds.read_scan(index)
    assert ds.read_scan(1).timestamp_s == pytest.approx(1000.1)  # (the messages before it read)


def test_ouster_pcap_without_metadata(tmp_path):
    """The metadata is looked for once the ouster-sdk is there (without it nothing reads: its pip line comes first)."""
    import importlib.util

    from lidarkit.errors import ConfigError
    from lidarkit.io.kiss_loaders import ouster_metadata

    pcap = tmp_path / "drive.pcap"
    pcap.write_bytes(b"\xd4\xc3\xb2\xa1" + b"\0" * 60)  # a pcap header, no json beside it
    missing = r"drive\.pcap \(frame 0\): no sensor metadata: an Ouster pcap needs the \.json recorded with it"
    with pytest.raises(DataError, match=missing):
        ouster_metadata(pcap, None)
    with pytest.raises(DataError, match=r"meta\.json: Ouster metadata json not found"):
        ouster_metadata(pcap, str(tmp_path / "meta.json"))
    if importlib.util.find_spec("ouster") is None:
        with pytest.raises(ConfigError, match=r"the ouster reader needs the Python package 'ouster': pip install 'lidarkit\[ouster\]'"):
            open_dataset("ouster", pcap)
    else:
        with pytest.raises(DataError, match=missing):
            open_dataset("ouster", pcap)


@pytest.mark.parametrize("name, said", [
    ("s.mcap", "an MCAP file, not an Ouster .pcap (the ouster reader takes a .pcap with its metadata .json): mcap:{path} reads it"),
    ("s.bag", "a ROS bag, not an Ouster .pcap (the ouster reader takes a .pcap with its metadata .json): rosbag:{path} reads it"),
    ("s.txt", "a file, not an Ouster .pcap (the ouster reader takes a .pcap with its metadata .json)"),
])
def test_another_recording_given_to_the_ouster_reader_is_named_by_what_it_is(tmp_path, name, said):
    """ouster:s.mcap said "no sensor metadata: an Ouster pcap needs the .json" (or, with a json beside it, asked for the
    ouster-sdk): a file that is not a .pcap is refused by what it is, with the reader that reads it."""
    path = tmp_path / name
    path.write_bytes(b"\x89MCAP0\r\n" if name.endswith(".mcap") else b"#ROSBAG V2.0\n")
    (tmp_path / "sensor.json").write_text("{}")
    with pytest.raises(DataError) as err:
        open_dataset("ouster", path)
    assert str(err.value) == f"{path}: " + said.format(path=path)


def test_ground_truth_poses_that_cannot_stand_one_per_scan(tmp_path):
    """A zero quaternion, and fewer (or sparser) poses than scans: DataErrors saying so (a scipy ValueError, and
    'timestamps are not strictly increasing' about a pose used for two scans, before)."""
    scans = [good(k) for k in range(3)]
    zero = write_ros1_bag(tmp_path / "zero.bag", scans, odometry=[(1000.0 + 0.1 * k, (k, 0, 0), (0, 0, 0, 0)) for k in range(3)])
    with pytest.raises(DataError, match=r"zero.bag/ground_truth \(message 0\): .*not a finite position and unit quaternion"):
        open_dataset("rosbag", zero).ground_truth
    sparse = write_ros1_bag(tmp_path / "sparse.bag", scans, odometry=[(1000.0, (0, 0, 0), (0, 0, 0, 1)), (1005.0, (5, 0, 0), (0, 0, 0, 1))])
    with pytest.raises(DataError, match=r"2 poses for 3 scans: scans 0 and 1 are both nearest to the pose at 1000.000 s"):
        open_dataset("rosbag", sparse).ground_truth
    registered = []

    class Counting:  # a stateful stand-in: the ground truth's problem comes before any frame is registered
        name, stateful, config = "counting", True, None

        def reset(self):
            pass

        def register_frame(self, points_xyz, point_times_s=None):
            registered.append(1)
            return np.eye(4)

    with pytest.raises(DataError, match="2 poses for 3 scans"):
        run(open_dataset("rosbag", sparse), Counting())
    assert registered == []
    assert open_dataset("rosbag", sparse, ground_truth_topic="none").ground_truth is None  # none named (an empty spec value is "auto")
    # as many poses as scans, but 4 sweeps later: paired by count, scan 0 was scored against the pose of scan 4
    shifted = write_ros1_bag(tmp_path / "shifted.bag", scans, odometry=[(1000.4 + 0.1 * k, (k, 0, 0), (0, 0, 0, 1)) for k in range(3)])
    with pytest.raises(DataError, match=r"shifted.bag/ground_truth: pose 0 is stamped 1000.400 s, scan 0 1000.000 s: 0.400 s apart, "
                                        r"more than a sweep \(0.100 s\)"):
        open_dataset("rosbag", shifted).ground_truth
    late = write_ros1_bag(tmp_path / "late.bag", scans, odometry=[(1000.15 + 0.02 * k, (k, 0, 0), (0, 0, 0, 1)) for k in range(10)])
    with pytest.raises(DataError, match=r"10 poses for 3 scans: scan 0 \(1000.000 s\) comes before the first pose \(1000.150 s\)"):
        open_dataset("rosbag", late).ground_truth
    # the scans the odometry covers can still be run and scored (the whole recording's pairing refused every --frames)
    covered = open_dataset("rosbag", late).ground_truth_of([1, 2])
    np.testing.assert_allclose(covered.timestamps_s, [1000.15, 1000.19])  # the poses nearest scans 1 and 2
    assert len(run(open_dataset("rosbag", late), Counting(), frames="1:").ground_truth) == 2
    # every header stamp equal (a driver that stamps nothing): one line, not a ZeroDivisionError
    fields, step, data = _cloud_bytes(64)
    same = write_ros1_bag(tmp_path / "same.bag", [(1000.0, fields, step, data, 64)] * 3,
                          odometry=[(1000.0, (k, 0, 0), (0, 0, 0, 1)) for k in range(3)])
    with pytest.raises(DataError, match=r"same.bag/ground_truth \(frame 1\): timestamps are not strictly increasing"):
        open_dataset("rosbag", same).ground_truth
    two = write_ros1_bag(tmp_path / "two.bag", scans, odometry=[(1000.0 + 0.1 * k, (k, 0, 0), (0, 0, 0, 1)) for k in range(3)],
                         second_odometry=True)
    with pytest.raises(DataError, match=r"several nav_msgs/msg/Odometry topics \(/ground_truth, /ground_truth2\): choose"):
        open_dataset("rosbag", two)  # was: no ground truth at all, silently
    assert len(open_dataset("rosbag", two, ground_truth_topic="/ground_truth2").ground_truth) == 3
    one = write_ros1_bag(tmp_path / "one.bag", scans, odometry=[(1000.0, (0, 0, 0), (0, 0, 0, 1))])
    with pytest.raises(DataError, match=r"1 pose\(s\) for 3 scans: one pose per scan needed"):
        open_dataset("rosbag", one).ground_truth



def test_padded_rows_of_an_organized_cloud(tmp_path):
    """row_step beyond width x point_step (drivers pad rows): each row starts row_step bytes after the one before
    (read as if packed, every point after the first row was shifted, up to 91 m off)."""
    from types import SimpleNamespace

    from lidarkit.io.pointcloud2 import decode_pointcloud2

    fields, step, data = _cloud_bytes(6)
    field_msgs = [SimpleNamespace(name=n, offset=o, datatype=d, count=1) for n, o, d in fields]
    rows = [data[:3 * step], data[3 * step:]]
    padded = rows[0] + b"\xff" * 4 + rows[1] + b"\xff" * 4
    msg = SimpleNamespace(fields=field_msgs, point_step=step, width=3, height=2, row_step=3 * step + 4, data=padded, is_bigendian=False)
    packed = SimpleNamespace(**{**vars(msg), "row_step": 3 * step, "data": data})
    cloud = decode_pointcloud2(msg, source="pad.bag", location="/points message 0")
    np.testing.assert_array_equal(cloud.points_xyz, decode_pointcloud2(packed, source="p", location="m").points_xyz)
    with pytest.raises(DataError, match=r"pad.bag \(/points message 0\): row_step 40 is less than width 3 x point_step 16"):
        decode_pointcloud2(SimpleNamespace(**{**vars(msg), "row_step": 40}), source="pad.bag", location="/points message 0")
    with pytest.raises(DataError, match="truncated message"):
        decode_pointcloud2(SimpleNamespace(**{**vars(msg), "data": padded[:-10]}), source="pad.bag", location="/points message 0")


def test_a_ros2_bags_storage_given_without_its_folder_or_metadata_says_so(tmp_path):
    """A ROS 2 folder without metadata.yaml was read as a folder of scans ("no scan files (.bin, ...)"), its .db3
    file given alone was "not a folder"."""
    import shutil

    from lidarkit.odometry import run
    from lidarkit.sim.bag_export import export_bag
    from lidarkit.sim.lidar import SimulatedLidarSequence

    bag = export_bag(SimulatedLidarSequence(n_frames=2, n_beams=8, n_azimuths=90), tmp_path / "bag", "rosbag2")
    with pytest.raises(DataError, match=r"bag\.db3: a ROS 2 bag is opened as its folder, the one with metadata\.yaml"):
        run(str(next(bag.glob("*.db3"))), "vanilla")
    bare = tmp_path / "bare"
    shutil.copytree(bag, bare)
    (bare / "metadata.yaml").unlink()
    for spec in (str(bare), f"rosbag:{bare}"):
        with pytest.raises(DataError, match="a ROS 2 bag folder .* without its metadata.yaml: 'ros2 bag reindex' rebuilds it"):
            run(spec, "vanilla")
    mcap = export_bag(SimulatedLidarSequence(n_frames=2, n_beams=8, n_azimuths=90), tmp_path / "m", "rosbag2", storage="mcap")
    (mcap / "metadata.yaml").unlink()
    with pytest.raises(DataError, match=r"\(\.mcap storage\) without its metadata\.yaml: .* or give one \.mcap file"):
        run(str(mcap), "vanilla")


@pytest.mark.parametrize("fmt, name, reason", [("rosbag1", "x.bag", "file too large for the file system"),
                                               ("mcap", "x.mcap", "file too large for the file system"),
                                               ("rosbag2", "x2", "disk I/O error (is the disk full?)")])
def test_a_bag_export_that_fills_the_disk_is_one_line_and_leaves_nothing(tmp_path, fmt, name, reason):
    """A 40 KB file-size limit (a full disk) mid-export: a traceback of the writer's OSError, or of sqlite3's
    OperationalError for a ROS 2 bag; now one line naming the output, and nothing left behind."""
    import resource
    import subprocess
    import sys

    def limit():
        resource.setrlimit(resource.RLIMIT_FSIZE, (40 * 1024, 40 * 1024))

    done = subprocess.run([sys.executable, "-m", "lidarkit.cli", "sim", "lidar", "--out", name, "--format", fmt, "--frames", "5",
                           "-p", "n_beams=16", "-p", "n_azimuths=400", "--no-progress"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=300, preexec_fn=limit)
    assert done.returncode == 1 and done.stderr.strip().splitlines() == [f"error: {name}: cannot write: {reason}"], done.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_missing_returns_at_the_sensor_origin_are_left_out_of_a_bag_as_of_a_point_file(tmp_path):
    """An organized cloud's missing returns written as (0, 0, 0) (as Ouster drivers write them) were kept by the bag
    readers, where every point-file reader leaves them out: registered as points moving with the sensor, a 2.73 m
    drive came out 0.45 m (1.08 m with the same returns marked NaN). They are left out with their times and
    intensities, as NaN-marked ones are, and said once per reader."""
    n = 256
    rec = np.zeros(n, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4"), ("t", "<u4")])
    angle = np.linspace(0, 2 * np.pi, n, endpoint=False)
    rec["x"], rec["y"], rec["z"] = 10 * np.cos(angle), 10 * np.sin(angle), np.linspace(-1, 1, n)
    rec["intensity"] = np.arange(n)
    rec["t"] = np.round(np.linspace(0, 0.1, n) * 1e9)
    missing = np.arange(n) % 5 == 0  # 52 of 256
    by_zero, by_nan = rec.copy(), rec.copy()
    for axis in "xyz":
        by_zero[axis][missing], by_nan[axis][missing] = 0.0, np.nan
    fields = [("x", 0, F32), ("y", 4, F32), ("z", 8, F32), ("intensity", 12, F32), ("t", 16, U32)]
    zeros = open_dataset("rosbag", write_ros1_bag(tmp_path / "zero.bag", [(1000.0 + 0.1 * k, fields, 20, by_zero.tobytes(), n) for k in range(3)]))
    nans = open_dataset("rosbag", write_ros1_bag(tmp_path / "nan.bag", [(1000.0 + 0.1 * k, fields, 20, by_nan.tobytes(), n) for k in range(3)]))
    for k in range(3):
        scan = zeros.read_scan(k)
        assert len(scan.points_xyz) == n - 52
        np.testing.assert_array_equal(scan.points_xyz, nans.read_scan(k).points_xyz)
        np.testing.assert_array_equal(scan.intensity, rec["intensity"][~missing])
        np.testing.assert_array_equal(scan.point_times_s, rec["t"][~missing] * 1e-9)
    assert zeros.reader_warnings == ["left out 52 of 256 points at (0, 0, 0) (missing returns) in message 0 on /points; in later "
                                     "messages without another warning"]
    assert nans.reader_warnings == []


def test_auto_time_field_passes_over_a_time_field_holding_one_value(tmp_path):
    """A driver leaving 'time' at 0 for every point beside a valid 't' (uint32 ns): time_field=auto took 'time', and every
    sweep had zero times (not deskewed, no sweep instant). auto reads the first time field whose values differ, records
    it as time_field_used and says which it passed over; named, 'time' is read as it is."""
    n = 128
    rec = np.zeros(n, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("time", "<f4"), ("t", "<u4")])
    angle = np.linspace(0, 2 * np.pi, n, endpoint=False)
    rec["x"], rec["y"], rec["z"] = 10 * np.cos(angle), 10 * np.sin(angle), np.linspace(-1, 1, n)
    rec["t"] = np.round(np.linspace(0, 0.1, n) * 1e9)
    fields = [("x", 0, F32), ("y", 4, F32), ("z", 8, F32), ("time", 12, F32), ("t", 16, U32)]
    bag = write_ros1_bag(tmp_path / "zero_time.bag", [(1000.0 + 0.1 * k, fields, 20, rec.tobytes(), n) for k in range(3)])
    ds = open_dataset("rosbag", bag)
    scan = ds.read_scan(1)
    np.testing.assert_array_equal(scan.point_times_s, rec["t"] * 1e-9)
    assert scan.stamp_instant == "start" and ds.reader_options["time_field_used"] == "t"
    assert ds.reader_warnings == ["per-point time field 'time' holds one value for every point of message 1 on /points: the times "
                                  "are read from 't' (time_field= names the field to read)"]
    named = open_dataset("rosbag", bag, time_field="time")
    assert np.ptp(named.read_scan(1).point_times_s) == 0.0 and named.reader_options["time_field_used"] == "time"
    flat = rec.copy()
    flat["t"] = 0  # both flat: the first present, as before, without a word
    both = open_dataset("rosbag", write_ros1_bag(tmp_path / "flat.bag", [(1000.0, fields, 20, flat.tobytes(), n)]))
    both.read_scan(0)
    assert both.reader_options["time_field_used"] == "time" and both.reader_warnings == []


def test_a_folder_of_separate_recordings_is_not_read_as_one_split_bag(tmp_path):
    """run1.bag and run2.bag, recorded 100 s apart, were read as the parts of one split recording (merged: a 98.9 s gap
    in the frames, RPE 107 m), and two copies of one bag failed on stamps "not strictly increasing" without a hint.
    A folder's bags are parts of one recording only when each begins where the one before ends (within 3 scan
    periods); otherwise one line names them and how to read one. Parts are ordered by time, not by name."""
    import shutil

    split = tmp_path / "split"
    split.mkdir()
    write_ros1_bag(split / "run_2.bag", [good(k) for k in range(4)])
    write_ros1_bag(split / "run_10.bag", [good(k) for k in range(4, 8)], received_from_ns=10**12 + 4 * 10**8)
    ds = open_dataset("rosbag", split)
    assert len(ds) == 8
    np.testing.assert_allclose(ds.timestamps_s, 1000.0 + 0.1 * np.arange(8), atol=1e-9)
    two = tmp_path / "two"
    two.mkdir()
    write_ros1_bag(two / "run1.bag", [good(k) for k in range(4)])
    write_ros1_bag(two / "run2.bag", [good(k + 1000) for k in range(4)], received_from_ns=10**12 + 100 * 10**9)
    with pytest.raises(DataError) as err:
        open_dataset("rosbag", two)
    assert str(err.value) == (f"{two}: 2 bags (run1.bag, run2.bag) that are no parts of one recording: run2.bag begins 99.700 s "
                              "after run1.bag ends (a split recording's parts follow one another within 3 scan periods); read "
                              f"each on its own, e.g. rosbag:{two / 'run1.bag'}")
    copies = tmp_path / "copies"
    copies.mkdir()
    shutil.copy(two / "run1.bag", copies / "a.bag")
    shutil.copy(two / "run1.bag", copies / "b.bag")
    with pytest.raises(DataError, match=r"copies: 2 bags \(a\.bag, b\.bag\) that are no parts of one recording: b\.bag begins "
                                        r"0\.300 s before a\.bag ends .*e\.g\. rosbag:.*copies/a\.bag$"):
        open_dataset("rosbag", copies)
    assert len(open_dataset("rosbag", copies / "b.bag")) == 4  # the way out it names


def test_one_pose_per_scan_with_a_pose_skipped_is_not_paired_by_count(tmp_path):
    """As many poses as scans, but pose 4 missing and one more after the last scan: paired by count, scans 4-9 were
    scored against the next sweep's pose without a word. The count pairs them only when every pose lies as far from
    its scan as the others (a quarter of a sweep); else the nearest pairing names the gap."""
    scans = [good(k) for k in range(10)]
    skipped = [(1000.0 + 0.1 * k, (float(k), 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)) for k in range(11) if k != 4]
    bag = write_ros1_bag(tmp_path / "skipped.bag", scans, odometry=skipped)
    with pytest.raises(DataError, match=r"skipped.bag/ground_truth: 10 poses for 10 scans: scans 2 and 3 are both nearest to the pose at 1000.300 s"):
        open_dataset("rosbag", bag).ground_truth
    # the scans before the gap are still paired, each with the pose at its sweep's end (stamped with the next scan)
    np.testing.assert_allclose(open_dataset("rosbag", bag).ground_truth_of([0, 1, 2]).poses_se3[:, 0, 3], [1, 2, 3])
    # stamps a few ms apart from their scans, one pose each: paired by count as before
    jitter = [(1000.0 + 0.1 * k + 0.01 * (-1) ** k, (float(k), 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)) for k in range(10)]
    np.testing.assert_allclose(open_dataset("rosbag", write_ros1_bag(tmp_path / "jitter.bag", scans, odometry=jitter))
                               .ground_truth.poses_se3[:, 0, 3], np.arange(10))


def test_ground_truth_of_another_frame_than_the_clouds_is_said(tmp_path):
    """Odometry giving the pose of base_link (child_frame_id) beside clouds in frame lidar was scored as the LiDAR's
    pose without a word (the lever arm between the two counted as error). A reader warning names both frames, and the
    run's warnings carry it; the same frame, with or without ROS 1's leading slash, says nothing."""
    scans = [good(k) for k in range(4)]
    poses = [(1000.0 + 0.1 * k, (float(k), 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)) for k in range(4)]

    class Still:  # a registration that returns no motion: the warning is the reader's, before any pose
        name, stateful, config = "still", True, None

        def reset(self):
            pass

        def register_frame(self, points_xyz, point_times_s=None):
            return np.eye(4)

    warning = ("ground-truth topic /ground_truth gives the pose of frame 'base_link' (child_frame_id), the clouds on /points "
               "are in frame 'lidar': the ground truth is not the LiDAR's pose and is compared as if it were (the offset "
               "between the two frames counts as error)")
    base = write_ros1_bag(tmp_path / "base.bag", scans, odometry=poses, child_frame="base_link")
    bag = open_dataset("rosbag", base)
    assert len(bag.ground_truth) == 4 and bag.reader_warnings == [warning]
    assert warning in run(open_dataset("rosbag", base), Still()).metrics["warnings"]
    for child in ("lidar", "/lidar", ""):  # the clouds' own frame, or none named
        same = open_dataset("rosbag", write_ros1_bag(tmp_path / f"same{len(child)}.bag", scans, odometry=poses, child_frame=child))
        assert len(same.ground_truth) == 4 and same.reader_warnings == [], child


def test_a_ground_truth_topic_without_messages_names_the_way_to_run_without(tmp_path):
    """An odometry topic holding no message was "ground-truth topic /ground_truth has no messages", without the
    option that runs the recording unscored."""
    from rosbags.rosbag1 import Reader, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    clouds_only = write_ros1_bag(tmp_path / "clouds.bag", [good(k) for k in range(3)])
    with Reader(clouds_only) as reader, Writer(tmp_path / "both.bag") as writer:  # the clouds and an empty odometry topic
        clouds = {c.id: writer.add_connection(c.topic, c.msgtype, typestore=store) for c in reader.connections}
        writer.add_connection("/ground_truth", "nav_msgs/msg/Odometry", typestore=store)
        for conn, received_ns, raw in reader.messages():
            writer.write(clouds[conn.id], received_ns, raw)
    bag = open_dataset("rosbag", tmp_path / "both.bag")
    assert bag.ground_truth_topic == "/ground_truth"
    with pytest.raises(DataError) as err:
        bag.ground_truth
    assert str(err.value) == (f"{tmp_path / 'both.bag'}: ground-truth topic /ground_truth has no messages (ground_truth_topic=none "
                              "runs without ground truth)")
    assert open_dataset("rosbag", tmp_path / "both.bag", ground_truth_topic="none").ground_truth is None


def test_a_split_part_beginning_at_the_time_the_one_before_ends_is_read_as_one_recording(tmp_path):
    """rosbag record --split cut between two messages logged in one nanosecond: the folder was refused "run_1.bag begins
    0.000 s before run_0.bag ends" (rosbags' end time is the last message's + 1 ns, compared without tolerance). Parts
    may begin up to 1 ms before the one before ends; a real overlap is refused as before."""
    split = tmp_path / "split"
    split.mkdir()
    write_ros1_bag(split / "run_0.bag", [good(k) for k in range(4)])
    last_ns = 10**12 + 3 * 10**8  # run_0's last message
    write_ros1_bag(split / "run_1.bag", [good(k) for k in range(3, 8)], received_from_ns=last_ns)
    ds = open_dataset("rosbag", split)
    assert len(ds) == 9
    np.testing.assert_allclose(ds.timestamps_s, 1000.0 + 0.1 * np.array([0, 1, 2, 3, 3, 4, 5, 6, 7]), atol=1e-9)
    overlap = tmp_path / "overlap"
    overlap.mkdir()
    write_ros1_bag(overlap / "run_0.bag", [good(k) for k in range(4)])
    write_ros1_bag(overlap / "run_1.bag", [good(k) for k in range(4, 8)], received_from_ns=last_ns - 2 * 10**6)
    with pytest.raises(DataError, match=r"overlap: 2 bags \(run_0\.bag, run_1\.bag\) that are no parts of one recording: run_1\.bag "
                                        r"begins 0\.002 s before run_0\.bag ends "):
        open_dataset("rosbag", overlap)


def _missing_returns(n: int, how: str):
    """``good``'s cloud of ``n`` points with every return missing: all NaN, all at (0, 0, 0), or half of each."""
    fields, step, data = _cloud_bytes(n)
    rec = np.frombuffer(data, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("time", "<f4")]).copy()
    nan = {"nan": np.ones(n, bool), "zero": np.zeros(n, bool), "both": np.arange(n) % 2 == 0}[how]
    for axis in "xyz":
        rec[axis] = np.where(nan, np.nan, 0.0)
    return fields, step, rec.tobytes(), n


@pytest.mark.parametrize("how, what", [("nan", "NaN"), ("zero", "at (0, 0, 0)"), ("both", "NaN or at (0, 0, 0)")])
def test_a_message_of_missing_returns_only_says_so(tmp_path, how, what):
    """A message whose 5554 points were all missing returns read "empty scan (0 points)", as if it held none: it says
    how many points it held and why none is left, as the point-file readers do, and how to leave its frame out."""
    bag = write_ros1_bag(tmp_path / "missing.bag", [good(0), (1000.1, *_missing_returns(64, how)), good(2)])
    ds = open_dataset("rosbag", bag)
    assert len(ds.read_scan(0).points_xyz) == 64
    with pytest.raises(DataError) as err:
        ds.read_scan(1)
    assert str(err.value) == (f"{bag} (message 1 on /points): all 64 points are {what} (missing returns): no point left "
                              "(--frames can leave the frame out)")
    assert len(ds.read_scan(2).points_xyz) == 64


def test_an_empty_message_mid_recording_says_how_to_leave_its_frame_out(tmp_path):
    """An empty message mid-bag stopped the run with "empty scan (0 points)" alone, where a message of missing returns
    only names --frames as the way past it: the empty one names it too, and --frames leaving it out runs."""
    fields, step, _ = _cloud_bytes(64)
    clouds = [good(0), good(1), (1000.2, fields, step, b"", 0), good(3)]
    ds = open_dataset("rosbag", write_ros1_bag(tmp_path / "empty.bag", clouds))
    with pytest.raises(DataError) as err:
        run(ds, "kiss")
    assert str(err.value) == (f"{tmp_path / 'empty.bag'} message 2 on /points (frame 2): empty scan (0 points) (--frames can "
                              "leave the frame out)")
    assert len(run(ds, "kiss", frames=[0, 1]).trajectory) == 2


@pytest.mark.parametrize("first", ["empty", "all NaN", "one point"])
def test_a_first_message_without_point_times_leaves_the_sweep_timing_to_the_others(tmp_path, first):
    """A driver's empty start-up cloud (or one of missing returns only, or of one point) as message 0 made the whole
    recording one without point times: no stamp instant, no sweep length, no ground-truth instant, and small_gicp was
    scored against sweep-end poses without re-timing (RPE 0.0379 m for 0.0087 m). The sweep timing passes over scans
    without two or more point times and takes its medians over the first ones that carry them."""
    fields, step, data = _cloud_bytes(64)
    head = {"empty": (1000.0, fields, step, b"", 0), "all NaN": (1000.0, *_missing_returns(64, "nan")),
            "one point": (1000.0, fields, step, data[:step], 1)}[first]
    clouds = [head] + [good(k) for k in range(1, 8)]
    odometry = [(1000.1 + 0.1 * k, [0.5 * k, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]) for k in range(8)]  # stamped at sweep ends
    ds = open_dataset("rosbag", write_ros1_bag(tmp_path / "startup.bag", clouds, odometry=odometry))
    assert ds.stamp_instant == "start"
    assert ds.sweep_duration_s == pytest.approx(0.1)
    assert ds.ground_truth.meta["pose_instant"] == "end"
    retimed = ds.ground_truth_at_instant("start", scans=[1, 2, 3])
    np.testing.assert_allclose(retimed.poses_se3[:, 0, 3], [0.0, 0.5, 1.0], atol=1e-9)
    from numpy.lib.recfunctions import repack_fields

    xyz = repack_fields(np.frombuffer(data, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("time", "<f4")])[["x", "y", "z"]])
    timeless = [head] + [(1000.0 + 0.1 * k, fields[:3], 12, xyz.tobytes(), 64) for k in range(1, 4)]
    assert open_dataset("rosbag", write_ros1_bag(tmp_path / "timeless.bag", timeless)).stamp_instant is None


def test_a_time_field_of_another_name_is_named_with_the_option_that_reads_it(tmp_path):
    """A Livox bag's per-point times in 'offset_time' (uint32 ns) only said "deskew requested, no per-point times found
    (RosbagScans gives none): ran without deskew": the reader keeps its clouds' field names, and the reason lists them
    with the time_field= option that reads one (and says so when time_field=none turned the times off)."""
    from lidarkit.odometry.settings import point_times_not_found
    from lidarkit.sim.lidar import SimulatedLidarSequence

    sim = SimulatedLidarSequence(n_frames=4, n_beams=16, n_azimuths=360, seed=1)
    dtype = [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4"), ("offset_time", "<u4")]
    fields = [("x", 0, F32), ("y", 4, F32), ("z", 8, F32), ("intensity", 12, F32), ("offset_time", 16, U32)]
    clouds = []
    for k in range(len(sim)):
        scan = sim.read_scan(k)
        rec = np.zeros(len(scan.points_xyz), dtype=dtype)
        rec["x"], rec["y"], rec["z"] = scan.points_xyz.T
        rec["offset_time"] = np.round(scan.point_times_s * 1e9)
        clouds.append((1000.0 + 0.1 * k, fields, 20, rec.tobytes(), len(rec)))
    bag = write_ros1_bag(tmp_path / "livox.bag", clouds)
    reason = ("no per-point times found (RosbagScans: no time field among the clouds' fields x, y, z, intensity, offset_time; "
              "time_field=auto reads one named time, t, timestamp or timestamps, time_field=NAME reads another, e.g. "
              "time_field=offset_time)")
    result = run(open_dataset("rosbag", bag), "kiss")
    assert result.metrics["effective"]["deskew"]["reason"] == reason
    assert f"deskew requested, {reason}: ran without deskew" in result.metrics["warnings"]
    off = open_dataset("rosbag", bag, time_field="none")
    off.read_scan(0)
    assert point_times_not_found(off) == "no per-point times found (RosbagScans: time_field=none reads none)"
    named = open_dataset("rosbag", bag, time_field="offset_time")
    np.testing.assert_allclose(named.read_scan(1).point_times_s, sim.read_scan(1).point_times_s, atol=1e-9)


def test_integer_point_times_in_microseconds_are_refused_by_the_stamps_spacing(tmp_path):
    """A uint32 't' in microseconds was read as nanoseconds: sweeps of 1e-4 s against 0.1 s between the stamps
    (sweep_duration_s 9.97e-05), the ground truth re-timed 50 us after each sweep start, no word. Sweeps spanning less
    than 1 % of the stamps' spacing (a median over the first scans) are a DataError naming the field, both times and
    the way out; a sensor seeing a quarter of its turn still reads."""
    n = 128
    rec = np.zeros(n, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("t", "<u4")])
    angle = np.linspace(0, 2 * np.pi, n, endpoint=False)
    rec["x"], rec["y"], rec["z"] = 10 * np.cos(angle), 10 * np.sin(angle), np.linspace(-1, 1, n)
    fields = [("x", 0, F32), ("y", 4, F32), ("z", 8, F32), ("t", 12, U32)]
    odometry = [(1000.1 + 0.1 * k, [0.5 * k, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]) for k in range(6)]
    rec["t"] = np.round(np.linspace(0, 0.1, n) * 1e6)  # microseconds
    bag = write_ros1_bag(tmp_path / "us.bag", [(1000.0 + 0.1 * k, fields, 16, rec.tobytes(), n) for k in range(6)], odometry=odometry)
    message = (f"{bag}: per-point time field 't': sweeps of 0.0001 s (the median over the first 5 scans) while the scans are "
               "stamped 0.1 s apart (0.1 % of it), under 0.001 s: read as integer nanoseconds, the unit looks like "
               "microseconds (or the values are 1000x too small); time_field=none reads the scans without point times")
    for read in (lambda ds: ds.sweep_duration_s, lambda ds: ds.stamp_instant, lambda ds: ds.ground_truth):
        with pytest.raises(DataError) as err:
            read(open_dataset("rosbag", bag))
        assert str(err.value) == message
    assert open_dataset("rosbag", bag, time_field="none").ground_truth.meta["pose_instant"] is None
    rec["t"] = np.round(np.linspace(0, 0.025, n) * 1e9)  # nanoseconds over a quarter of the turn
    partial = open_dataset("rosbag", write_ros1_bag(tmp_path / "partial.bag", [(1000.0 + 0.1 * k, fields, 16, rec.tobytes(), n)
                                                                               for k in range(6)]))
    assert partial.sweep_duration_s == pytest.approx(0.025) and partial.stamp_instant == "start"


def test_ground_truth_stamps_all_zero_are_said_to_be_unset(tmp_path):
    """Odometry whose header stamps are all 0 (not set) beside normally stamped clouds: "12 poses for 12 scans: scan 1
    comes after the last pose (0.000 s); one pose per scan needed (--frames can pick ...)" contradicted itself."""
    fields, step, data = _cloud_bytes(64)
    scans = [(1000.0 + 0.1 * k, fields, step, data, 64) for k in range(3)]
    bag = write_ros1_bag(tmp_path / "gtzero.bag", scans, odometry=[(0.0, (k, 0, 0), (0, 0, 0, 1)) for k in range(3)])
    with pytest.raises(DataError, match=r"gtzero\.bag: every header stamp on the ground-truth topic /ground_truth is 0 \(not set "
                                        r"by the driver\): .* \(ground_truth_topic=none runs without ground truth\)$"):
        open_dataset("rosbag", bag).ground_truth
    assert open_dataset("rosbag", bag, ground_truth_topic="none").ground_truth is None
