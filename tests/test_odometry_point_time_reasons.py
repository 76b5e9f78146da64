"""Why a deskewing run had no per-point times, said as it is: a folder whose scans carry times it does not read, a bag
where only some frames lack them, the simulator told not to attach them, a KITTI layout's scans kept elsewhere."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import shared_path

from lidarkit.errors import DataError
from lidarkit.io import open_dataset
from lidarkit.odometry import run
from lidarkit.odometry.settings import point_times_not_found
from lidarkit.sim.lidar import SimulatedLidarSequence


def _sim_pcds(folder, padded: bool) -> None:
    """Three simulated sweeps as binary .pcd with Ouster's uint32 nanosecond ``t`` (and PCL's ``_`` padding)."""
    sim = SimulatedLidarSequence(n_frames=3, n_beams=16, n_azimuths=360, seed=1)
    pad = [("_", "u1", 4)] if padded else []
    names = ["x", "y", "z", *(n for n, *_ in pad), "intensity", "t", *(n for n, *_ in pad)]
    folder.mkdir()
    for k in range(len(sim)):
        scan = sim.read_scan(k)
        record = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), *((f"p{i}", "u1", (4,)) for i in range(len(pad))),
                           ("intensity", "<f4"), ("t", "<u4"), *((f"q{i}", "u1", (4,)) for i in range(len(pad)))])
        table = np.zeros(len(scan.points_xyz), record)
        table["x"], table["y"], table["z"] = scan.points_xyz.T
        table["t"] = np.round(scan.point_times_s * 1e9)
        sizes = {"x": "4 F 1", "y": "4 F 1", "z": "4 F 1", "_": "1 U 4", "intensity": "4 F 1", "t": "4 U 1"}
        size, kind, count = zip(*(sizes[n].split() for n in names))
        header = (f"VERSION 0.7\nFIELDS {' '.join(names)}\nSIZE {' '.join(size)}\nTYPE {' '.join(kind)}\n"
                  f"COUNT {' '.join(count)}\nWIDTH {len(table)}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {len(table)}\n"
                  "DATA binary\n")
        (folder / f"{1000 + k / 10:.1f}.pcd").write_bytes(header.encode() + table.tobytes())


@pytest.mark.parametrize("padded", [False, True], ids=["plain", "pcl_padding"])
def test_a_folder_whose_scans_carry_times_says_folder_reads_none_and_generic_does(tmp_path, padded):
    """folder: over .pcd files with a ``t`` field said "no per-point times found (ScanFolder gives none)", as if the
    files had none; generic:PATH reads them exactly (and refuses files with repeated ``_`` padding)."""
    folder = tmp_path / "scans"
    _sim_pcds(folder, padded)
    other = ("generic:PATH, which does, refuses these files (repeated _ padding fields)" if padded
             else f"generic:{folder} reads them")
    assert point_times_not_found(open_dataset("folder", folder)) == (
        "no per-point times read (folder: does not read per-point times; its scans carry them in the 't' field, e.g. "
        f"1000.0.pcd; {other})")
    if not padded:  # (what the message promises)
        sim = SimulatedLidarSequence(n_frames=3, n_beams=16, n_azimuths=360, seed=1)
        np.testing.assert_allclose(open_dataset("generic", folder).read_scan(1).point_times_s, sim.read_scan(1).point_times_s,
                                   atol=1e-9)


def test_a_bag_with_one_frame_without_times_names_that_frame(tmp_path):
    """One message of six without the time field: "deskew applied to 5 of 6 frames only: no per-point times found
    (RosbagScans gives none)" contradicted itself; the warning names the frame."""
    from test_io_bad_bags import F32, U32, write_ros1_bag

    sim = SimulatedLidarSequence(n_frames=6, n_beams=16, n_azimuths=360, seed=1)
    clouds = []
    for k in range(len(sim)):
        scan = sim.read_scan(k)
        timed = k != 3
        rec = np.zeros(len(scan.points_xyz), [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("t", "<u4")][: 4 if timed else 3])
        rec["x"], rec["y"], rec["z"] = scan.points_xyz.T
        if timed:
            rec["t"] = np.round(scan.point_times_s * 1e9)
        fields = [("x", 0, F32), ("y", 4, F32), ("z", 8, F32), ("t", 12, U32)][: 4 if timed else 3]
        clouds.append((1000.0 + 0.1 * k, fields, rec.itemsize, rec.tobytes(), len(rec)))
    result = run(open_dataset("rosbag", write_ros1_bag(tmp_path / "one_without.bag", clouds)), "kiss")
    deskew = result.metrics["effective"]["deskew"]
    assert (deskew["applied"], deskew["frames_with_point_times"], deskew["n_frames"]) == (True, 5, 6)
    assert "deskew applied to 5 of 6 frames only: frame 3 had no per-point times" in result.metrics["warnings"]


def test_the_simulator_without_point_times_names_its_option():
    """``point_times=false`` in a sim: spec, with --strict, was refused as "(SimulatedLidarSequence gives none)"."""
    with pytest.raises(DataError) as err:
        run("sim:street?frames=3&beams=16&azimuths=360&point_times=false", "kiss", strict=True)
    assert str(err.value).endswith("(frame 0): deskew requested, no per-point times found (SimulatedLidarSequence: "
                                   "point_times=false attaches none)")


def test_a_kitti_velodyne_dir_elsewhere_names_the_folders_searched_for_times():
    """With velodyne_dir=extra_frames/00/velodyne the KITTI reader looks for point_times/ beside it first; the reason
    said "beside velodyne/ in sequences/00" only."""
    root = shared_path("kitti_odometry")
    kitti = open_dataset("kitti", root, sequence="00", velodyne_dir=root / "extra_frames" / "00" / "velodyne")
    assert point_times_not_found(kitti) == (
        "no per-point times found (looked for point_times/, timestamps/, times/, point_timestamps/ beside velodyne/ in "
        f"{root / 'extra_frames' / '00'}, then in {root / 'sequences' / '00'})")


def _uint_time_plys(folder, n_scans: int = 3) -> None:
    """``n_scans`` small ASCII .ply scans with a PLY uint ``t`` field (nanoseconds, as Ouster writes them)."""
    rng = np.random.default_rng(7)
    folder.mkdir()
    header = ("ply\nformat ascii 1.0\nelement vertex 200\nproperty float x\nproperty float y\nproperty float z\n"
              "property uint t\nend_header\n")
    for k in range(n_scans):
        points = rng.uniform(-20.0, 20.0, size=(200, 3))
        rows = "".join(f"{x:.4f} {y:.4f} {z:.4f} {t}\n" for (x, y, z), t in zip(points, range(0, 100_000_000, 500_000)))
        (folder / f"{k}.ply").write_text(header + rows)


def test_a_folder_whose_ply_times_open3d_skips_does_not_point_to_generic(tmp_path):
    """A PLY uint time field was said to be read by generic:PATH, "which does, refuses these files (repeated _ padding
    fields)": these files have no padding, and generic reads no times from them either (Open3D skips uint)."""
    folder = tmp_path / "scans"
    _uint_time_plys(folder)
    assert point_times_not_found(open_dataset("folder", folder)) == (
        "no per-point times read (folder: does not read per-point times; its scans carry them in the 't' field, e.g. "
        "0.ply; a PLY uint property, which Open3D cannot read, so generic:PATH does not either: store the times as float, "
        "double or int)")


@pytest.mark.parametrize("method", ["pipeline", "kiss"])
def test_the_strict_refusal_of_a_scan_without_times_names_its_file(tmp_path, method):
    """``--strict`` on a folder named the folder ("scans (frame 0): deskew requested, ..."), where a frame's other
    errors name the scan's file."""
    folder = tmp_path / "scans"
    _uint_time_plys(folder)
    with pytest.raises(DataError) as err:
        run(open_dataset("folder", folder), method, strict=True)
    assert str(err.value).startswith(f"{folder / '0.ply'} (frame 0): deskew requested, no per-point times read")
