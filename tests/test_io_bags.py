"""ROS 1/2 bags and MCAP written by the simulator read back through lidarkit, and every kiss-icp loader exposed."""

from __future__ import annotations

import re

import numpy as np
import pytest

from conftest import cli_exit_code
from lidarkit.errors import ConfigError, DataError, OutputError
from lidarkit.io import available_datasets, detect_kind, open_dataset
from lidarkit.io.base import sweep_length
from lidarkit.sim.bag_export import export_bag
from lidarkit.sim.lidar import SimulatedLidarSequence, export_kitti

N_FRAMES = 8
FORMATS = [("rosbag1", "sqlite3", "run.bag", "rosbag"), ("rosbag2", "sqlite3", "run_sqlite3", "rosbag"),
           ("rosbag2", "mcap", "run_mcap", "rosbag"), ("mcap", "sqlite3", "run.mcap", "mcap")]


@pytest.fixture(scope="module")
def sim():
    return SimulatedLidarSequence(n_frames=N_FRAMES, n_beams=16, n_azimuths=720, seed=3, accel_time_s=0.0, speed_mps=5.0)


@pytest.fixture(scope="module")
def exports(sim, tmp_path_factory):
    """The same sweeps as a KITTI-layout folder and as every bag format."""
    root = tmp_path_factory.mktemp("bags")
    out = {"kitti": export_kitti(sim, root / "kitti")}
    for fmt, storage, name, _ in FORMATS:
        out[(fmt, storage)] = export_bag(sim, root / name, fmt, storage=storage)
    return out


def test_every_kiss_icp_loader_is_a_dataset_kind():
    from kiss_icp.datasets import available_dataloaders

    import importlib

    from lidarkit.io.kiss_loaders import KISS_CLASSES, KISS_KINDS

    kinds = available_datasets()
    assert set(available_dataloaders()) <= set(KISS_KINDS)
    for loader in available_dataloaders():
        assert KISS_KINDS[loader] in kinds, loader
        assert isinstance(getattr(importlib.import_module(f"kiss_icp.datasets.{loader}"), KISS_CLASSES[loader]), type)


def test_odometry_help_lists_the_kinds(capsys):
    assert cli_exit_code(["odometry", "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    for kind in ("rosbag", "mcap", "ouster", "nclt", "mulran", "ncd", "helipr", "boreas", "apollo", "nuscenes", "generic", "kiss_kitti"):
        assert kind in text
    listed = text.split("kinds:")[1].split(")")[0].replace("│", " ")
    assert "landmarks" not in listed and " tum," not in f" {' '.join(listed.split())},"  # no scans to run odometry on


def test_detect_kind(exports, tmp_path):
    (tmp_path / "x.pcap").write_bytes(b"")
    with pytest.raises(ConfigError, match=r"^path: expected a path, got int 5$"):  # (a bare TypeError before)
        detect_kind(5)
    assert detect_kind(exports[("rosbag1", "sqlite3")]) == "rosbag"
    assert detect_kind(exports[("rosbag2", "sqlite3")]) == "rosbag"  # folder with metadata.yaml
    assert detect_kind(exports[("rosbag2", "mcap")]) == "rosbag"
    assert detect_kind(exports[("mcap", "sqlite3")]) == "mcap"
    assert detect_kind(tmp_path / "x.pcap") == "ouster"
    assert detect_kind(exports["kitti"]) == "kitti"
    assert detect_kind(tmp_path) is None
    for name in ("aces.clf", "aces.clf.bz2", "intel.CLF.gz"):  # a CARMEN log (read as a scan folder: "not a folder")
        assert detect_kind(tmp_path / name) == "carmen", name
    assert detect_kind(tmp_path / "x.bz2") is None


def test_a_kitti_folder_holding_a_bag_is_refused_naming_both_readings(exports, tmp_path, capsys):
    """A KITTI folder (velodyne/ or sequences/) that also held a .bag was read as the bag, without a word: odometry ran
    on the bag's sweeps and scored them on its ground truth. It is both: the user names the reading."""
    import shutil

    from lidarkit.odometry import open_sequence

    both = shutil.copytree(exports["kitti"], tmp_path / "seq")
    shutil.copy(exports[("rosbag1", "sqlite3")], both / "recording.bag")
    with pytest.raises(ConfigError) as err:
        detect_kind(both)
    assert str(err.value) == f"{both}: both a KITTI dataset (velodyne/) and a ROS bag (recording.bag): give kitti:{both} or rosbag:{both}"
    (tmp_path / "root" / "sequences").mkdir(parents=True)
    (tmp_path / "root" / "metadata.yaml").write_text("")
    with pytest.raises(ConfigError, match=r"both a KITTI dataset \(sequences/\) and a ROS bag \(metadata\.yaml\)"):
        detect_kind(tmp_path / "root")
    assert cli_exit_code(["odometry", str(both), "--method", "kiss", "--no-progress", "--out", str(tmp_path / "o")]) == 1
    assert f"error: {both}: both a KITTI dataset" in capsys.readouterr().err
    assert len(open_sequence(f"kitti:{both}")) == len(open_sequence(f"rosbag:{both}")) == N_FRAMES


def test_the_files_detected_by_name_are_listed_from_the_detection_table(tmp_path):
    """"dataset not found (a folder, a .bag/.mcap/.pcap file, ...)" left CARMEN logs out: the list written apart from
    detect_kind's rules drifted; detected_files() is made from the same table."""
    from lidarkit.io import DETECTED_SUFFIXES, detected_files

    assert detected_files() == "a .bag/.mcap/.pcap/.clf file (also .clf.bz2/.clf.gz/.clf.xz)"
    for suffix in (*DETECTED_SUFFIXES, ".clf.bz2", ".clf.gz", ".clf.xz"):
        assert suffix in detected_files() and detect_kind(tmp_path / f"nonexist{suffix}") is not None, suffix
    from lidarkit.odometry import open_sequence

    with pytest.raises(DataError, match=r"dataset not found \(a folder, a \.bag/\.mcap/\.pcap/\.clf file \(also \.clf\.bz2"):
        open_sequence(str(tmp_path / "nonexist.clf.bz2"))


def test_options_on_a_path_without_its_kind_say_the_kind_goes_first(exports):
    """`lidarkit odometry 'r1.bag?topic=/points'` read "dataset not found" of a file that exists (the docs show both
    `run.bag` and `rosbag:run.bag?topic=...`): the message now says options need the kind, and which one."""
    from lidarkit.errors import ConfigError
    from lidarkit.odometry import open_sequence

    bag, folder = exports[("rosbag1", "sqlite3")], exports["kitti"]
    with pytest.raises(ConfigError) as err:
        open_sequence(f"{bag}?topic=/points")
    assert str(err.value).endswith(f"options need the dataset kind before the path: rosbag:{bag}?topic=/points")
    with pytest.raises(ConfigError, match=f"kitti:{folder}\\?drop_nonfinite=true$"):
        open_sequence(f"{folder}?drop_nonfinite=true")


def test_a_bag_named_with_a_question_mark_is_read_whole_after_its_kind(exports, tmp_path):
    """``rosbag:q?x.bag`` was cut at the name's own '?' and refused "rosbag dataset option 'x.bag': expected KEY=VALUE"
    (without the kind it ran): a path that exists is read whole, options after the last '?' that leaves one."""
    import shutil

    from lidarkit.odometry import open_sequence

    bag = shutil.copy(exports[("rosbag1", "sqlite3")], tmp_path / "q?x.bag")
    assert len(open_sequence(f"rosbag:{bag}")) == len(open_sequence(f"rosbag:{bag}?topic=/points")) == N_FRAMES
    with pytest.raises(ConfigError, match="rosbag dataset options: unknown option 'foo'"):
        open_sequence(f"rosbag:{bag}?foo=1")


@pytest.mark.parametrize("fmt,storage,name,kind", FORMATS)
def test_bag_round_trip_points_times_and_ground_truth(sim, exports, fmt, storage, name, kind):
    ds = open_dataset(kind, exports[(fmt, storage)])
    assert len(ds) == N_FRAMES and ds.topic == "/points" and ds.ground_truth_topic == "/ground_truth"
    by_t = open_dataset(kind, exports[(fmt, storage)], time_field="t")
    for i in (0, 3, N_FRAMES - 1):
        ref = sim.read_scan(i)
        scan = ds.read_scan(i)
        np.testing.assert_array_equal(scan.points_xyz, ref.points_xyz.astype(np.float32).astype(np.float64))
        np.testing.assert_array_equal(scan.intensity, ref.intensity)
        # 'time': float32 seconds from the sweep start, bit-identical to the KITTI-layout export's point_times
        np.testing.assert_array_equal(scan.point_times_s, ref.point_times_s.astype(np.float32).astype(np.float64))
        assert scan.point_time_convention == "relative_s" and scan.stamp_instant == "start"
        assert scan.timestamp_s == pytest.approx(i * sim.config.sweep_period_s, abs=1e-9)
        # 't': uint32 nanoseconds, the simulator's times to the nanosecond
        np.testing.assert_allclose(by_t.read_scan(i).point_times_s, ref.point_times_s, rtol=0, atol=0.51e-9)
    gt = ds.ground_truth
    assert gt.meta["pose_instant"] == "end"
    np.testing.assert_allclose(gt.poses_se3, sim.ground_truth.poses_se3, rtol=0, atol=1e-12)
    np.testing.assert_allclose(gt.timestamps_s, sim.timestamps_s, rtol=0, atol=1e-9)


def test_an_mcap_converted_from_a_ros1_bag_reads_as_the_bag(exports, tmp_path):
    """An MCAP converted from a ROS 1 bag (``mcap convert``) keeps its ROS 1 messages (ros1msg schemas): it read "no
    sensor_msgs/msg/PointCloud2 topic; topics present: /points (sensor_msgs/PointCloud2)". rosbags decodes them: the
    same points, times, stamps and ground truth as the bag."""
    from mcap.writer import Writer
    from rosbags.rosbag1 import Reader

    bag = exports[("rosbag1", "sqlite3")]
    converted = tmp_path / "converted.mcap"
    with Reader(bag) as reader, open(converted, "wb") as fh:
        writer = Writer(fh)
        writer.start(profile="ros1")
        channels = {}
        for conn in reader.connections:
            schema = writer.register_schema(name=conn.msgtype.replace("/msg/", "/"), encoding="ros1msg", data=conn.msgdef.data.encode())
            channels[conn.id] = writer.register_channel(topic=conn.topic, message_encoding="ros1", schema_id=schema)
        for conn, received_ns, raw in reader.messages():
            writer.add_message(channels[conn.id], log_time=received_ns, publish_time=received_ns, data=raw)
        writer.finish()
    ros1, mcap = open_dataset("rosbag", bag), open_dataset("mcap", converted)
    assert len(mcap) == len(ros1) == N_FRAMES and mcap.topic == "/points"
    for k in (0, N_FRAMES - 1):
        ours, theirs = mcap.read_scan(k), ros1.read_scan(k)
        np.testing.assert_array_equal(ours.points_xyz, theirs.points_xyz)
        np.testing.assert_array_equal(ours.point_times_s, theirs.point_times_s)
        assert ours.stamp_instant == theirs.stamp_instant == "start"
    np.testing.assert_array_equal(mcap.timestamps_s, ros1.timestamps_s)
    np.testing.assert_array_equal(mcap.ground_truth.poses_se3, ros1.ground_truth.poses_se3)
    assert mcap.ground_truth.meta["pose_instant"] == ros1.ground_truth.meta["pose_instant"]
    assert len(open_dataset("mcap", converted, topic="/points", ground_truth_topic="/ground_truth")) == N_FRAMES


def test_null_is_each_options_default_and_none_turns_it_off(exports):
    """``?time_field=null`` read no point times while ``?ground_truth_topic=null`` was the automatic default (the docs
    gave null and none alike): null is every option's default (time_field auto), none turns the option off."""
    from lidarkit.odometry import open_sequence

    for kind, path in (("rosbag", exports[("rosbag1", "sqlite3")]), ("mcap", exports[("mcap", "sqlite3")])):
        nulled = open_sequence(f"{kind}:{path}?time_field=null&ground_truth_topic=null")
        assert nulled.read_scan(1).point_times_s is not None and nulled.stamp_instant == "start", kind
        assert nulled.reader_options["time_field"] == "auto" and nulled.ground_truth_topic == "/ground_truth"
        off = open_sequence(f"{kind}:{path}?time_field=none&ground_truth_topic=none")
        assert off.read_scan(1).point_times_s is None and off.ground_truth is None, kind


def test_ground_truth_of_checks_the_scan_numbers(exports):
    """ground_truth_of([99]) raised numpy's IndexError, [] its "zero-size array" ValueError, and [1.5] gave scan 1's
    pose: each is checked as read_scan checks its index."""
    bag = open_dataset("rosbag", exports[("rosbag1", "sqlite3")])
    source = f"{bag.path}{bag.ground_truth_topic}"
    for scans, reason in (([99], "scan index 99 out of range for 8 scans"), ([], "no scans selected"),
                          ([1.5], "scan index 1.5 is not an integer"), ([-1], "scan index -1 out of range for 8 scans")):
        with pytest.raises(DataError) as err:
            bag.ground_truth_of(scans)
        assert str(err.value) == f"{source}: {reason}"
    np.testing.assert_array_equal(bag.ground_truth_of(np.array([1, 2])).poses_se3, bag.ground_truth.poses_se3[1:3])


def test_the_run_config_records_the_time_field_read(exports, tmp_path):
    """config.yaml recorded time_field: auto, not the field read: the simulator's bags carry both time (float32 s) and
    t (uint32 ns). time_field_used names it once scans were read; none when times are ignored."""
    import yaml

    bag = exports[("rosbag1", "sqlite3")]
    ds = open_dataset("rosbag", bag)
    assert "time_field_used" not in ds.reader_options  # nothing read: not known yet
    ds.read_scan(0)
    assert ds.reader_options["time_field"] == "auto" and ds.reader_options["time_field_used"] == "time"
    for spec, used in ((str(bag), "time"), (f"rosbag:{bag}?time_field=t", "t"), (f"rosbag:{bag}?time_field=none", "none")):
        out = tmp_path / used
        assert cli_exit_code(["odometry", spec, "-m", "kiss", "--frames", "0:3", "--out", str(out), "--no-progress"]) == 0
        options = yaml.safe_load((out / "config.yaml").read_text())["run"]["dataset_options"]
        assert options["time_field_used"] == used, spec


def test_an_intensity_named_as_time_field_is_refused(exports):
    """time_field=intensity (0.007-0.696, within the 1 s a sweep may span) was read as each point's seconds and
    deskewed every sweep by it: values that neither follow the point order nor turn with the azimuth are refused."""
    bag = exports[("rosbag1", "sqlite3")]
    with pytest.raises(DataError, match=r"run\.bag \(message 0 on /points\): per-point time field 'intensity' does not follow the "
                                        r"sweep: its values go back 808 times in 11368 points and do not turn with the azimuth "
                                        r"nor trace a scan pattern in their order \(an intensity or another per-point value\): not the points' times \(time_field= names"):
        open_dataset("rosbag", bag, time_field="intensity").read_scan(0)
    assert open_dataset("rosbag", bag, time_field="time").read_scan(0).point_times_s.max() == pytest.approx(0.1, abs=1e-3)


def test_an_intensity_stored_in_another_order_is_still_refused(exports):
    """Times that trace a scan pattern in their order are read (a solid-state sweep binned in space); an intensity
    does not, whatever the order of the points: the simulator's (0.007-0.696) and KITTI's (real reflectances, the
    first scan of sequence 00) binned in space are refused as before."""
    from conftest import shared_path

    from lidarkit.io.pointcloud2 import checked_point_times

    scan = open_dataset("rosbag", exports[("rosbag1", "sqlite3")]).read_scan(0)
    kitti = np.fromfile(shared_path("kitti_odometry", "sequences", "00", "velodyne", "000000.bin"), dtype=np.float32).reshape(-1, 4)
    for xyz, intensity in ((scan.points_xyz, scan.intensity), (kitti[:, :3].astype(np.float64), kitti[:, 3])):
        binned = np.lexsort((np.floor(xyz[:, 1]), np.floor(xyz[:, 0])))
        with pytest.raises(DataError, match=r"^x \(m\): i does not follow the sweep: its values go back \d+ times in \d+ points "
                                            r"and do not turn with the azimuth nor trace a scan pattern in their order"):
            checked_point_times(intensity[binned], xyz[binned], what="i", within="m", hint="h", source="x", location="m")


def test_odometry_over_bags_equals_the_kitti_export(exports, tmp_path):
    """kiss through every bag format gives the KITTI-layout export's trajectory (1e-9 m); one via the CLI."""
    from lidarkit.odometry import run

    reference = run(exports["kitti"], "kiss").trajectory.poses_se3
    assert np.linalg.norm(reference[-1, :3, 3]) > 1.0  # it moved
    for fmt, storage, _, kind in FORMATS[1:]:
        poses = run(f"{kind}:{exports[(fmt, storage)]}", "kiss").trajectory.poses_se3
        assert np.abs(poses[:, :3, 3] - reference[:, :3, 3]).max() <= 1e-9, (fmt, storage)
    out = tmp_path / "run"
    assert cli_exit_code(["odometry", str(exports[("rosbag1", "sqlite3")]), "--method", "kiss", "--out", str(out), "--no-progress"]) == 0
    poses = np.loadtxt(out / "poses_kitti.txt").reshape(-1, 3, 4)
    assert np.abs(poses[:, :, 3] - reference[:, :3, 3]).max() <= 1e-9


def test_sim_cli_writes_each_format(tmp_path):
    for fmt, extra, name in (("rosbag2", ["--storage", "mcap"], "b2"), ("mcap", [], "c.mcap")):
        args = ["sim", "lidar", "--out", str(tmp_path / name), "--frames", "2", "--format", fmt, "--no-progress",
                "-p", "n_beams=8", "-p", "n_azimuths=180", *extra]
        assert cli_exit_code(args) == 0
        assert len(open_dataset(detect_kind(tmp_path / name), tmp_path / name)) == 2
    assert cli_exit_code(["sim", "lidar", "--out", str(tmp_path / "x"), "--format", "ply", "--no-progress"]) != 0


def test_sim_cli_refuses_a_bag_name_the_readers_would_not_recognise_or_an_existing_bag(tmp_path, capsys):
    from lidarkit.cli import main

    def sim(out, fmt):
        with pytest.raises(SystemExit) as exc:
            main(["sim", "lidar", "--out", str(out), "--frames", "2", "--format", fmt, "--no-progress", "-p", "n_beams=8",
                  "-p", "n_azimuths=90"])
        return exc.value.code, capsys.readouterr().err

    assert sim(tmp_path / "xdir", "rosbag1") == (1, "error: --out: a rosbag1 file is named *.bag, got 'xdir'\n")
    assert sim(tmp_path / "x.txt", "mcap")[1].startswith("error: --out: a mcap file is named *.mcap")
    assert sim(tmp_path / "r2.bag", "rosbag2")[1].startswith("error: --out: a rosbag2 bag is a folder: name it without .bag")
    with pytest.raises(ConfigError, match=r"a rosbag1 file is named \*\.bag, got 'lib'"):  # the library refuses it too
        export_bag(SimulatedLidarSequence(n_frames=1, n_beams=8, n_azimuths=90), tmp_path / "lib", "rosbag1")
    assert sim(tmp_path / "m.mcap", "mcap")[0] in (0, None)
    code, err = sim(tmp_path / "m.mcap", "mcap")
    assert code == 1 and "m.mcap: exists already; bags are never overwritten" in err
    with pytest.raises(SystemExit):  # --storage with another format, at its default value too (it was ignored)
        main(["sim", "lidar", "--out", str(tmp_path / "s.mcap"), "--frames", "2", "--format", "mcap", "--storage", "sqlite3"])
    assert "--storage: --storage applies to --format rosbag2 only" in capsys.readouterr().err and not (tmp_path / "s.mcap").exists()


def test_unknown_topic_lists_the_topics_and_never_exits(exports):
    with pytest.raises(DataError, match=r"no topic '/velodyne_points'; topics present: /ground_truth \(nav_msgs/msg/Odometry\), "
                                        r"/ground_truth/sweep_end \(geometry_msgs/msg/PoseStamped\), .*, /points"):
        open_dataset("rosbag", exports[("rosbag1", "sqlite3")], topic="/velodyne_points")
    with pytest.raises(DataError, match="carries nav_msgs/msg/Odometry"):
        open_dataset("mcap", exports[("mcap", "sqlite3")], topic="/ground_truth")


def test_a_loader_that_calls_exit_becomes_a_data_error(exports):
    """kiss-icp's own rosbag loader prints and exits on an unknown topic; the guard turns that into a DataError."""
    from pathlib import Path

    from kiss_icp.datasets.rosbag import RosbagDataset

    from lidarkit.io.rosbag import guarded_loader

    with pytest.raises(DataError, match="gave up: .*does not containg any msg with the topic name"):
        with guarded_loader("rosbag", "run.bag"):
            RosbagDataset(Path(exports[("rosbag1", "sqlite3")]), topic="/nope")


def test_missing_extra_is_a_config_error_with_the_pip_line(tmp_path, monkeypatch):
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name.startswith(("ouster", "rosbags")) else real(name, *a))
    (tmp_path / "x.pcap").write_bytes(b"\0" * 64)
    (tmp_path / "x.json").write_text("{}")
    with pytest.raises(ConfigError, match=r"pip install 'lidarkit\[ouster\]'"):
        open_dataset("ouster", tmp_path / "x.pcap")
    with pytest.raises(ConfigError, match=r"pip install 'lidarkit\[ros\]'"):
        open_dataset("rosbag", tmp_path / "x.bag")


def test_kiss_generic_loader_reads_a_kitti_bin_folder(exports):
    """kiss-icp's generic loader through lidarkit: same points as lidarkit's KITTI reader."""
    generic = open_dataset("generic", exports["kitti"] / "velodyne")
    kitti = open_dataset("kitti", exports["kitti"])
    assert len(generic) == N_FRAMES
    np.testing.assert_array_equal(generic.read_scan(2).points_xyz, kitti.read_scan(2).points_xyz)


@pytest.mark.parametrize("fmt, name", [("rosbag1", "plain.bag"), ("mcap", "plain.mcap")])
def test_an_export_without_point_times_has_no_time_fields(tmp_path, fmt, name):
    """point_times=false writes clouds without time fields (as a driver that writes none), not times of zero: kiss on
    such a bag runs without deskew and says why, instead of normalizing zero-span times (kiss-icp aborts on them)."""
    from lidarkit.odometry import run

    sim = SimulatedLidarSequence(n_frames=4, n_beams=16, n_azimuths=360, seed=1, point_times=False)
    ds = open_dataset(fmt if fmt == "mcap" else "rosbag", export_bag(sim, tmp_path / name, fmt))
    scan = ds.read_scan(2)
    assert scan.point_times_s is None
    np.testing.assert_array_equal(scan.points_xyz, sim.read_scan(2).points_xyz.astype(np.float32).astype(np.float64))
    deskew = run(ds, "kiss").metrics["effective"]["deskew"]
    assert deskew["applied"] is False and deskew["reason"].startswith("no per-point times found")


def test_a_killed_exports_scratch_folder_is_removed_by_the_next_export(tmp_path):
    """kill -9 during an export left `.big.bag.XXXX/` (285 MB after 6 s) that nothing removed: it is now marked as a
    partial output, and an export to the same name removes one older than an hour."""
    import os
    import time

    from lidarkit.atomic import PARTIAL_MARK

    left = tmp_path / f".run.bag{PARTIAL_MARK}abcd"
    left.mkdir()
    (left / "run.bag").write_bytes(b"\0" * 1000)
    old = time.time() - 2 * 3600
    os.utime(left, (old, old))
    export_bag(SimulatedLidarSequence(n_frames=1, n_beams=8, n_azimuths=90), tmp_path / "run.bag", "rosbag1")
    assert (tmp_path / "run.bag").is_file() and sorted(p.name for p in tmp_path.iterdir()) == ["run.bag"]


def test_sim_progress_lines_where_no_bar_can_be_drawn(tmp_path, capsys):
    """stderr to a log or CI: a 3000-sweep export ran minutes without a word; now a line every tenth, as odometry."""
    from lidarkit.cli import main

    for command, name in ((["lidar", "-p", "n_beams=8", "-p", "n_azimuths=90"], "lidar"), (["camera", "-p", "width=64", "-p", "height=48"], "cam")):
        with pytest.raises(SystemExit) as exc:
            main(["sim", *command, "--out", str(tmp_path / name), "--frames", "10"])
        assert exc.value.code in (0, None)
        err = capsys.readouterr().err
        unit = "sweeps" if name == "lidar" else "images"
        assert f"10/10 {unit} (100 %)" in err and len([line for line in err.splitlines() if f" {unit} (" in line]) >= 5


def test_sim_spec_memory_bag_t_field_and_odometry_frame(tmp_path):
    """A sim: spec asking for 1e10 rays was a 74 GiB MemoryError traceback; a sweep longer than 4.29 s wrapped the
    uint32 't' field back to 0; the odometry message said its pose was in the lidar frame."""
    from rosbags.highlevel import AnyReader

    from lidarkit.errors import ConfigError
    from lidarkit.odometry import run

    with pytest.raises(ConfigError, match=r"a sweep of 100000x100000 rays needs about .* of memory"):
        run("sim:street?frames=2&beams=100000&azimuths=100000", "kiss")
    slow = SimulatedLidarSequence(n_frames=2, n_beams=8, n_azimuths=90, frame_rate_hz=0.2)
    with pytest.raises(ConfigError, match=r"frame_rate_hz: a sweep of 5 s overflows the uint32 nanosecond 't' field"):
        export_bag(slow, tmp_path / "slow.bag", "rosbag1")
    # clouds without per-point times have no 't' field to overflow (they were refused the same way); a file named
    # run.MCAP, which the CLI and the readers take as MCAP, was refused by the writer
    for settings in ({"point_times": False}, {"motion_distortion": False}):
        slow = SimulatedLidarSequence(n_frames=2, n_beams=8, n_azimuths=90, frame_rate_hz=0.2, **settings)
        assert export_bag(slow, tmp_path / f"slow{len(settings)}{sorted(settings)[0]}.mcap", "mcap").is_file()
    upper = export_bag(SimulatedLidarSequence(n_frames=2, n_beams=8, n_azimuths=90), tmp_path / "run.MCAP", "mcap")
    assert len(open_dataset("mcap", upper)) == 2
    bag = export_bag(SimulatedLidarSequence(n_frames=2, n_beams=8, n_azimuths=90), tmp_path / "ok.bag", "rosbag1")
    with AnyReader([bag]) as reader:
        conn = next(c for c in reader.connections if c.topic == "/ground_truth")
        msg = reader.deserialize(next(reader.messages(connections=[conn]))[2], conn.msgtype)
    assert msg.header.frame_id == "world" and msg.child_frame_id == "lidar"


def test_a_bag_export_refuses_a_sweep_longer_than_its_readers_accept(tmp_path):
    """At 0.9 Hz a bag was written whose 1.11 s sweeps lidarkit's own bag readers then refused ("per-point time field
    'time' spans 1.10889 s"): the export refuses it before writing anything; at 1 Hz the bag reads back."""
    slow = SimulatedLidarSequence(n_frames=2, n_beams=8, n_azimuths=500, frame_rate_hz=0.9)
    with pytest.raises(ConfigError) as err:
        export_bag(slow, tmp_path / "r09.mcap", "mcap")
    assert str(err.value) == ("frame_rate_hz: a sweep of 1.11111 s is longer than the 1 s lidarkit's bag readers accept (they "
                              "would refuse its per-point times): frame_rate_hz must be at least 1 for a bag")
    assert list(tmp_path.iterdir()) == []
    one_hz = SimulatedLidarSequence(n_frames=2, n_beams=8, n_azimuths=500, frame_rate_hz=1.0)
    scan = open_dataset("mcap", export_bag(one_hz, tmp_path / "r1.mcap", "mcap")).read_scan(1)
    assert scan.point_times_s.max() == pytest.approx(0.998, abs=1e-6)


def test_a_snapshot_export_has_no_point_times_and_its_stamp_is_its_instant(tmp_path):
    """motion_distortion=false: the bag's clouds carried all-zero time fields (read as a sweep's times) stamped at the
    sweep start, 0.1 s before their ground truth; the KITTI folder got an empty point_times/ that warned."""

    sim = SimulatedLidarSequence(n_frames=3, n_beams=8, n_azimuths=90, motion_distortion=False, seed=1)
    bag = open_dataset("mcap", export_bag(sim, tmp_path / "snap.mcap", "mcap"))
    scan = bag.read_scan(2)
    assert scan.point_times_s is None
    np.testing.assert_allclose(bag.timestamps_s, sim.timestamps_s, atol=1e-9)
    np.testing.assert_allclose(bag.ground_truth.timestamps_s, bag.timestamps_s, atol=1e-9)
    np.testing.assert_array_equal(scan.points_xyz, sim.read_scan(2).points_xyz.astype(np.float32))  # (float32 fields)
    folder = export_kitti(sim, tmp_path / "snap")
    assert not (folder / "point_times").exists()


def test_a_sensor_that_sees_nothing_is_refused_before_an_export_is_written(tmp_path):
    """Beams above the horizon over the ground scene: 0-byte sweeps were exported (exit 0) that every reader refused."""
    sim = SimulatedLidarSequence(n_frames=3, n_beams=8, n_azimuths=90, scene="ground", elevation_min_deg=0.0, elevation_max_deg=10.0)
    with pytest.raises(DataError, match=r"sweep 0 has no return within 1-80 m: from where it is taken the beams \(0 to 10 deg, the "
                                        r"sensor 1.73 m up\) see nothing of the ground scene, and an empty sweep is no scan"):
        export_bag(sim, tmp_path / "up.bag", "rosbag1")
    assert not (tmp_path / "up.bag").exists()


def test_an_export_never_replaces_or_mixes_with_one_that_finished_while_it_ran(tmp_path):
    """Two exports to one target at once: the bag finishing second replaced the first, and the KITTI folder of the one
    finishing second was merged into the first's (30 sweeps beside 10 poses). The second is refused; the first stays."""
    from lidarkit.errors import OutputError

    sim = SimulatedLidarSequence(n_frames=2, n_beams=8, n_azimuths=90)
    for fmt, name in (("rosbag1", "run.bag"), ("mcap", "run.mcap"), ("rosbag2", "run_ros2")):
        out = tmp_path / name

        written_by_the_other = out / "metadata.yaml" if fmt == "rosbag2" else out

        def other_export_finishes(i, written=written_by_the_other):
            if i == 1:
                written.parent.mkdir(exist_ok=True)
                written.write_text("the other export")

        with pytest.raises(OutputError, match="a bag appeared there while this one was written"):
            export_bag(sim, out, fmt, on_frame=other_export_finishes)
        assert written_by_the_other.read_text() == "the other export"
    folder = tmp_path / "kitti"

    def other_folder_export_finishes(i):
        if i == 1:
            folder.mkdir()
            (folder / "poses.txt").write_text("the other export")

    with pytest.raises(OutputError, match=r"kitti: the folder filled while this export was written \(another export to it\?\)"):
        export_kitti(sim, folder, on_frame=other_folder_export_finishes)
    assert sorted(p.name for p in folder.iterdir()) == ["poses.txt"]
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no partial output left


def test_a_ros1_bag_named_with_an_upper_case_suffix_is_refused_by_name(tmp_path, capsys):
    """X.Bag was written (exit 0), then every reader said "not a readable ROS bag (AnyReaderError: Unrecognized storage
    format '.Bag'; truncated or damaged?)": rosbags opens a ROS 1 bag only by a lower-case .bag name."""
    from lidarkit.cli import main

    with pytest.raises(SystemExit) as exc:
        main(["sim", "lidar", "--out", str(tmp_path / "X.Bag"), "--frames", "2", "--format", "rosbag1", "--no-progress"])
    assert (exc.value.code, capsys.readouterr().err) == (
        1, "error: --out: a ROS 1 bag is read back only by a lower-case .bag name: name it X.bag, got 'X.Bag'\n")
    sim = SimulatedLidarSequence(n_frames=2, n_beams=8, n_azimuths=90)
    with pytest.raises(ConfigError, match=r"read back only by a lower-case \.bag name: name it lib\.bag, got 'lib\.BAG'"):
        export_bag(sim, tmp_path / "lib.BAG", "rosbag1")
    assert not list(tmp_path.iterdir())
    renamed = export_bag(sim, tmp_path / "ok.bag", "rosbag1").rename(tmp_path / "Y.Bag")
    with pytest.raises(DataError, match=r"Y\.Bag: a ROS 1 bag, read only by a lower-case \.bag name: rename it to Y\.bag$"):
        open_dataset(detect_kind(renamed), renamed)
    # any other name of a ROS 1 bag (it was "not a readable ROS bag (...); truncated or damaged?"), and what a killed
    # `rosbag record` leaves
    for name, hint in (("plain", "rename it to plain.bag"), ("rec.bag.active", "run rosbag reindex on it, then rename it to rec.bag")):
        other = renamed.rename(tmp_path / name)
        with pytest.raises(DataError, match=rf"{re.escape(name)}: a ROS 1 bag, read only by a lower-case \.bag name: {hint}$"):
            open_dataset("rosbag", other)
        renamed = other
    (tmp_path / "not_a_bag").write_bytes(b"#ROSBAG")  # (not the whole magic: the reader's own words)
    with pytest.raises(DataError, match="not a readable ROS bag"):
        open_dataset("rosbag", tmp_path / "not_a_bag")


def test_a_dangling_symbolic_link_as_a_bag_is_refused_before_the_simulation(tmp_path, capsys):
    """--out l.bag -> gone.bag: the sweeps were simulated, then the bag was refused as if "a bag appeared there while this
    one was written (another export?)" (the link does not exist() but takes the name); the same for mcap and rosbag2."""
    from lidarkit.cli import main

    sim = SimulatedLidarSequence(n_frames=2, n_beams=8, n_azimuths=90)
    for fmt, name, what in (("rosbag1", "l.bag", "file"), ("mcap", "l.mcap", "file"), ("rosbag2", "l2", "folder")):
        (tmp_path / name).symlink_to(f"gone_{name}")
        with pytest.raises(SystemExit) as exc:
            main(["sim", "lidar", "--out", str(tmp_path / name), "--frames", "2", "--format", fmt, "--no-progress"])
        assert (exc.value.code, capsys.readouterr().err) == (1, f"error: {tmp_path / name}: a symbolic link to a missing file is in "
                                                                f"the way (-> gone_{name}): remove it or name another {what}\n")
        frames = []
        with pytest.raises(OutputError, match="a symbolic link to a missing file is in the way"):
            export_bag(sim, tmp_path / name, fmt, on_frame=frames.append)
        assert frames == []  # refused before the first sweep
    assert sorted(p.name for p in tmp_path.iterdir()) == ["l.bag", "l.mcap", "l2"]


def test_a_scan_and_a_bag_reader_print_as_one_line(exports):
    """repr(scan) printed every point array (thousands of lines for a sweep); a bag reader printed as
    <lidarkit.io.rosbag.RosbagScans object at 0x...>."""
    from lidarkit.io.base import Scan

    bag = open_dataset("rosbag", exports[("rosbag1", "sqlite3")])
    scan = bag.read_scan(1)  # (the last of 720 columns fires 719 / 7200 s after the sweep start)
    assert repr(scan) == (f"Scan(frame 1, {len(scan.points_xyz)} points, point times relative_s 0-0.0998611 s, stamp 0.100000 s at "
                          f"the sweep start, '{bag.path} message 1 on /points')")
    assert repr(bag) == f"RosbagScans('{bag.path}', topic '/points', {N_FRAMES} scans, ground truth /ground_truth)"
    mcap = open_dataset("mcap", exports[("mcap", "sqlite3")], ground_truth_topic="none")
    assert repr(mcap) == f"McapScans('{mcap.path}', topic '/points', {N_FRAMES} scans, ground truth none)"
    assert repr(Scan(np.zeros((0, 3)))) == "Scan(frame 0, 0 points, no point times, no stamp)"
    absolute = Scan(np.zeros((3, 3)), None, 1.7e9 + np.array([0.4, 0.45, 0.4997]), 1.7e9 + 0.5, 3, "x", "absolute_s")
    assert repr(absolute) == ("Scan(frame 3, 3 points, point times absolute_s 1700000000.400000 s + 0.0997 s, stamp "
                              "1700000000.500000 s, 'x')")  # (it printed 1.7e+09-1.7e+09 s)
    assert repr(Scan(np.zeros((2, 3)), point_times_s=np.array([0.0, 1.0]), point_time_convention="fraction")) == (
        "Scan(frame 0, 2 points, point times fraction 0-1, no stamp)")


@pytest.mark.parametrize("fmt, name, kind", [("rosbag1", "run.bag", "rosbag"), ("mcap", "run.mcap", "mcap")])
@pytest.mark.parametrize("pose_instant", ["start", "end"])
def test_a_simulated_bag_gives_the_ground_truth_at_every_instant_as_the_simulator(tmp_path, fmt, name, kind, pose_instant):
    """A drive pulling away (0 to 10 m/s in 1 s): the bag held the ground truth at pose_instant only, and the other
    instants were interpolated (mid up to 9 mm off, the first sweep's start and the last one's end continued at constant
    velocity, 5-50 mm off). The export keeps the poses at every instant (/ground_truth/sweep_start, _mid, _end) and the
    reader gives those, as the simulator and the KITTI-layout export do."""
    sim = SimulatedLidarSequence(n_frames=6, n_beams=8, n_azimuths=180, seed=5, speed_mps=10.0, accel_time_s=1.0,
                                 pose_instant=pose_instant)
    bag = open_dataset(kind, export_bag(sim, tmp_path / name, fmt))
    for instant in ("start", "mid", "end"):
        got, truth = bag.ground_truth_at_instant(instant), sim.ground_truth_at(instant)
        assert np.abs(got.poses_se3[:, :3, 3] - truth.poses_se3[:, :3, 3]).max() <= 1e-6, instant
        assert np.abs(got.poses_se3[:, :3, :3] - truth.poses_se3[:, :3, :3]).max() <= 1e-9, instant
        np.testing.assert_allclose(got.timestamps_s, truth.timestamps_s, atol=1e-6, err_msg=instant)
        assert got.meta["retimed"] == f"the poses recorded at the sweep {instant} on /ground_truth/sweep_{instant}"
        np.testing.assert_allclose(bag.ground_truth_at_instant(instant, scans=[2, 4]).poses_se3, truth.poses_se3[[2, 4]], atol=1e-9)
    assert bag.ground_truth_topic == "/ground_truth"  # (the poses beside it are no second odometry topic to choose from)


def test_a_one_sweep_bag_gives_its_recorded_ground_truth_at_every_instant(tmp_path):
    """One sweep of 64 columns: its points span 63/64 of the 0.1 s period and no stamp spacing tells the rest, so the
    mid and end instants fell 0.8 and 1.6 ms before the poses kept for them and were refused ("interpolating needs two
    or more poses") though the bag holds them."""
    sim = SimulatedLidarSequence(n_frames=1, n_beams=8, n_azimuths=64, seed=1)
    bag = open_dataset("mcap", export_bag(sim, tmp_path / "one.mcap", "mcap"))
    for instant in ("start", "mid", "end"):
        got, truth = bag.ground_truth_at_instant(instant), sim.ground_truth_at(instant)
        np.testing.assert_allclose(got.poses_se3, truth.poses_se3, atol=1e-9, err_msg=instant)
        np.testing.assert_allclose(got.timestamps_s, truth.timestamps_s, atol=1e-6, err_msg=instant)
        assert got.meta["retimed"] == f"the poses recorded at the sweep {instant} on /ground_truth/sweep_{instant}"
    assert bag.sweep_duration_s == pytest.approx(sim.config.sweep_period_s, abs=1e-6)  # (one firing step past the last)


@pytest.mark.parametrize("n_azimuths", [8, 9])
def test_a_bag_of_few_columns_lasts_the_stamps_spacing(tmp_path, n_azimuths):
    """8 columns span 7/8 of the period (12.5 % short, beyond the 10 % of a full sweep): the sweep was taken to last
    its span and the mid and end ground truth was interpolated 6 and 12 ms early. The last column fires one firing
    step before the next sweep's first, and that step is counted."""
    sim = SimulatedLidarSequence(n_frames=3, n_beams=8, n_azimuths=n_azimuths, seed=1)
    bag = open_dataset("mcap", export_bag(sim, tmp_path / "few.mcap", "mcap"))
    assert bag.sweep_duration_s == pytest.approx(sim.config.sweep_period_s, abs=1e-9)
    for instant in ("mid", "end"):
        got, truth = bag.ground_truth_at_instant(instant), sim.ground_truth_at(instant)
        np.testing.assert_allclose(got.timestamps_s, truth.timestamps_s, atol=1e-9, err_msg=instant)
        np.testing.assert_allclose(got.poses_se3, truth.poses_se3, atol=1e-9, err_msg=instant)
        assert got.meta["retimed"] == f"the poses recorded at the sweep {instant} on /ground_truth/sweep_{instant}"


def test_sweep_length_counts_one_firing_step_only_near_the_spacing():
    """8 columns 12.5 ms apart span 87.5 ms of a 0.1 s period: a full sweep; every other sweep kept (0.2 s apart) or no
    step known stays the span."""
    assert sweep_length(0.0875, 0.1, 0.0125) == 0.1
    assert sweep_length(0.0875, 0.1) == 0.0875
    assert sweep_length(0.0875, 0.2, 0.0125) == 0.0875
    assert sweep_length(0.0999, 0.1, 1e-6) == 0.1
