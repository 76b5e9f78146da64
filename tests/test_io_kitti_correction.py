"""KITTI as kiss-icp reads it: the vertical-angle correction makes `lidarkit odometry --method kiss` kiss-icp's own run."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from conftest import cli_exit_code, shared_path

pytestmark = pytest.mark.shared_data


@pytest.fixture(scope="module")
def kiss_icp_pipeline_poses():
    """kiss-icp's OdometryPipeline with kiss-icp's own KITTI dataloader on the 10 shared scans of sequence 00."""
    from kiss_icp.datasets.kitti import KITTIOdometryDataset
    from kiss_icp.pipeline import OdometryPipeline

    dataset = KITTIOdometryDataset(shared_path("kitti_odometry"), sequence="00")
    assert len(dataset) == 10
    pipeline = OdometryPipeline(dataset)
    pipeline._run_pipeline()  # the odometry loop only: no result folder written
    return pipeline.poses.copy()


def test_kiss_through_lidarkit_equals_kiss_icp_pipeline(kiss_icp_pipeline_poses, tmp_path):
    out = tmp_path / "run"
    root = shared_path("kitti_odometry")
    assert cli_exit_code(["odometry", f"kitti:{root}?sequence=00", "--method", "kiss", "--out", str(out), "--no-progress"]) == 0
    poses = np.loadtxt(out / "poses_kitti.txt").reshape(-1, 3, 4)
    assert poses.shape[0] == 10
    gap = np.linalg.norm(poses[:, :, 3] - kiss_icp_pipeline_poses[:, :3, 3], axis=1).max()
    assert gap <= 1e-6
    options = yaml.safe_load((out / "config.yaml").read_text())["run"]["dataset_options"]
    assert options["vertical_correction"] == "auto" and options["vertical_correction_applied"] is True
    assert options["vertical_correction_deg"] == pytest.approx(0.205)


def test_without_the_correction_it_is_another_experiment(kiss_icp_pipeline_poses):
    from lidarkit.odometry import run

    root = shared_path("kitti_odometry")
    result = run(f"kitti:{root}?sequence=00&vertical_correction=false", "kiss")
    gap = np.linalg.norm(result.trajectory.poses_se3[:, :3, 3] - kiss_icp_pipeline_poses[:, :3, 3], axis=1).max()
    assert gap > 1e-4  # the correction changes kiss's poses measurably
    assert result.config["run"]["dataset_options"]["vertical_correction_applied"] is False


def test_auto_is_off_for_other_methods_and_for_simulated_folders(tmp_path):
    from lidarkit.io.kitti import KittiOdometry
    from lidarkit.sim.lidar import SimulatedLidarSequence, export_kitti

    ds = KittiOdometry(shared_path("kitti_odometry"), "00")
    raw = ds.read_scan(0).points_xyz
    ds.configure_for_method("small_gicp")
    assert ds.reader_options["vertical_correction_applied"] is False
    ds.configure_for_method("kiss")
    corrected = ds.read_scan(0).points_xyz
    # a point at range r moves by about r * 0.205 deg, along the vertical direction of its azimuth
    moved = np.linalg.norm(corrected - raw, axis=1) / np.linalg.norm(raw, axis=1)
    assert np.median(moved) == pytest.approx(np.deg2rad(0.205), rel=0.05)
    sim = export_kitti(SimulatedLidarSequence(n_frames=1, n_beams=4, n_azimuths=64), tmp_path / "sim")
    simulated = KittiOdometry(sim)
    simulated.configure_for_method("kiss")
    assert simulated.reader_options["vertical_correction_applied"] is False

    # a user's own recording kept in the KITTI layout (the simulator's sweeps, sim.yaml gone): no HDL-64 behind it
    (sim / "sim.yaml").unlink()
    recording = KittiOdometry(sim)
    recording.configure_for_method("kiss")
    assert not recording.recorded_by_kitti and recording.reader_options["vertical_correction_applied"] is False
    (sim / "calib.txt").write_text((shared_path("kitti_odometry", "sequences", "00", "calib.txt")).read_text())
    copied_calib = KittiOdometry(sim)  # KITTI's camera calibration: taken for KITTI's own recording
    copied_calib.configure_for_method("kiss")
    assert copied_calib.recorded_by_kitti and copied_calib.reader_options["vertical_correction_applied"] is True


def test_kiss_kitti_kind_reads_what_the_corrected_kitti_reader_reads():
    from lidarkit.io import open_dataset

    root = shared_path("kitti_odometry")
    theirs = open_dataset("kiss_kitti", root, sequence="00")
    ours = open_dataset("kitti", root, sequence="00", vertical_correction=True)
    assert len(theirs) == len(ours) == 10
    np.testing.assert_array_equal(theirs.read_scan(4).points_xyz, ours.read_scan(4).points_xyz)
    assert theirs.read_scan(4).timestamp_s == ours.read_scan(4).timestamp_s
    # kiss-icp reads calib.txt in float32: its LiDAR-frame ground truth agrees to ~1e-6 m
    np.testing.assert_allclose(theirs.ground_truth.poses_se3, ours.ground_truth.poses_se3, rtol=0, atol=1e-5)


def test_kiss_kitti_on_an_excerpt_pairs_each_scan_with_its_own_ground_truth(tmp_path):
    """Scans 5-9 only: the ground truth is that of frames 5-9 (it was frames 0-4, beside the right time stamps)."""
    import shutil

    from lidarkit.io import open_dataset

    root = shared_path("kitti_odometry")
    copy = tmp_path / "kitti"
    shutil.copytree(root, copy, ignore=shutil.ignore_patterns("extra_frames"))
    for frame in range(5):
        (copy / "sequences" / "00" / "velodyne" / f"{frame:06d}.bin").unlink()
    theirs, ours = open_dataset("kiss_kitti", copy), open_dataset("kitti", copy)
    assert len(theirs) == len(ours) == 5
    np.testing.assert_allclose(theirs.ground_truth.poses_se3, ours.ground_truth.poses_se3, rtol=0, atol=1e-5)
    np.testing.assert_array_equal(theirs.timestamps_s, ours.timestamps_s)
    with (copy / "sequences" / "00" / "times.txt").open("a") as f:
        f.write("garbage\n")
    from lidarkit.errors import ConfigError, DataError

    with pytest.raises(DataError, match=r"times.txt \(line 4542\)"):
        open_dataset("kiss_kitti", copy).timestamps_s
    with pytest.raises(ConfigError, match="sequence must be a number such as 00, got 'abc'"):
        open_dataset("kiss_kitti", copy, sequence="abc")


def _raw_drive_of_sequence_00(base):
    """A KITTI raw drive laid out where kiss-icp's raw loader looks for odometry sequence 00 (2011_10_03 drive 0027),
    holding the 10 shared scans of sequence 00 (the calibration and an OXTS packet of the shared 2011_09_26 drive)."""
    import shutil

    shared_day = shared_path("kitti_raw", "2011_09_26")
    day = base / "2011_10_03"
    drive = day / "2011_10_03_drive_0027_sync"
    for name in ("calib_cam_to_cam.txt", "calib_velo_to_cam.txt", "calib_imu_to_velo.txt"):
        (day).mkdir(parents=True, exist_ok=True)
        shutil.copy2(shared_day / name, day / name)
    shared_drive = shared_day / "2011_09_26_drive_0001_sync"
    (drive / "oxts" / "data").mkdir(parents=True)
    (drive / "velodyne_points" / "data").mkdir(parents=True)
    shutil.copy2(shared_drive / "oxts" / "timestamps.txt", drive / "oxts" / "timestamps.txt")
    shutil.copy2(shared_drive / "velodyne_points" / "timestamps.txt", drive / "velodyne_points" / "timestamps.txt")
    scans = sorted(shared_path("kitti_odometry", "sequences", "00", "velodyne").glob("*.bin"))
    for i, scan in enumerate(scans):
        shutil.copy2(shared_drive / "oxts" / "data" / "0000000000.txt", drive / "oxts" / "data" / f"{i:010d}.txt")
        shutil.copy2(scan, drive / "velodyne_points" / "data" / f"{i:010d}.bin")
    return drive


def test_kiss_on_kitti_raw_equals_kiss_icp_pipeline_with_its_raw_loader(tmp_path):
    """kiss-icp's KITTI raw loader corrects every drive's scans as its KITTI loader does: so does lidarkit's
    kitti_raw reader for kiss (auto), recorded in the run config; other methods read the points as stored."""
    from kiss_icp.datasets.kitti_raw import KITTIRawDataset
    from kiss_icp.pipeline import OdometryPipeline

    from lidarkit.odometry import run

    drive = _raw_drive_of_sequence_00(tmp_path)
    dataset = KITTIRawDataset(tmp_path, sequence="00")
    assert len(dataset) == 10
    pipeline = OdometryPipeline(dataset)
    pipeline._run_pipeline()
    out = tmp_path / "run"
    assert cli_exit_code(["odometry", f"kitti_raw:{drive}", "--method", "kiss", "--out", str(out), "--no-progress"]) == 0
    poses = np.loadtxt(out / "poses_kitti.txt").reshape(-1, 3, 4)
    assert np.linalg.norm(poses[:, :, 3] - pipeline.poses[:, :3, 3], axis=1).max() <= 1e-6
    options = yaml.safe_load((out / "config.yaml").read_text())["run"]["dataset_options"]
    assert options["kind"] == "kitti_raw" and options["vertical_correction_applied"] is True
    uncorrected = run(f"kitti_raw:{drive}?vertical_correction=false", "kiss")
    assert np.linalg.norm(uncorrected.trajectory.poses_se3[:, :3, 3] - pipeline.poses[:, :3, 3], axis=1).max() > 1e-4
    other = run(f"kitti_raw:{drive}", "vanilla", frames="0:2")
    assert other.config["run"]["dataset_options"]["vertical_correction_applied"] is False


def test_a_number_is_not_a_correction_setting():
    """1 == True in Python: it passed the check and was then never applied (neither True nor "auto")."""
    from lidarkit.errors import ConfigError
    from lidarkit.io.kitti import KittiOdometry

    with pytest.raises(ConfigError, match="vertical_correction must be true, false or auto, got 1"):
        KittiOdometry(shared_path("kitti_odometry"), "00", vertical_correction=1)


def test_pipeline_with_kiss_composition_reads_kitti_as_kiss_does(kiss_icp_pipeline_poses):
    """The pipeline's default composition (kiss_like) gives kiss's poses on KITTI too: 1.4 cm apart without the
    correction kiss gets under auto; another composition reads the points as stored."""
    from lidarkit.odometry import run

    root = shared_path("kitti_odometry")
    result = run(f"kitti:{root}?sequence=00", "pipeline")
    gap = np.linalg.norm(result.trajectory.poses_se3[:, :3, 3] - kiss_icp_pipeline_poses[:, :3, 3], axis=1).max()
    assert gap <= 1e-6
    assert result.config["run"]["dataset_options"]["vertical_correction_applied"] is True
    other = run(f"kitti:{root}?sequence=00", "pipeline", params={"preset": "vanilla_seq"}, frames="0:2")
    assert other.config["run"]["dataset_options"]["vertical_correction_applied"] is False


def test_kiss_kitti_kinds_report_the_correction_their_loader_applies(tmp_path):
    """kiss-icp's KITTI and KITTI raw loaders move every point by 0.205 deg, but a run recorded no correction ("reader
    corrections: none reported by the reader", effective.corrections {})."""
    from lidarkit.io import open_dataset
    from lidarkit.odometry import run
    from lidarkit.odometry.settings import corrections, reader_settings

    applied = {"vertical_correction": True, "vertical_correction_applied": True, "vertical_correction_deg": 0.205}
    result = run(f"kiss_kitti:{shared_path('kitti_odometry')}?sequence=0", "kiss", frames="0:2")
    assert result.metrics["effective"]["corrections"] == applied
    assert result.config["run"]["dataset_options"]["vertical_correction_applied"] is True
    _raw_drive_of_sequence_00(tmp_path)
    raw = open_dataset("kiss_kitti_raw", tmp_path, sequence="00")
    assert corrections(reader_settings(raw)) == applied
    assert raw.reader_options["kind"] == "kiss_kitti_raw"
    scans = tmp_path / "scans"  # another kiss-icp loader: no correction reported
    scans.mkdir()
    np.random.default_rng(0).uniform(-20, 20, (500, 4)).astype("<f4").tofile(scans / "000000.bin")
    assert corrections(reader_settings(open_dataset("generic", scans))) == {}


def test_genz_reads_kitti_corrected_as_genz_icp_loaders_do(tmp_path):
    """genz-icp's KITTI and KITTI raw loaders apply the same 0.205 deg correction as kiss-icp's: under auto genz got
    the points as stored, another experiment than genz-icp's (0.047 m end error where genz-icp's own reading gives
    0.080 m on the 10 scans); another method still reads them as stored."""
    from genz_icp.pybind import genz_icp_pybind

    from lidarkit.io.kitti import KittiOdometry
    from lidarkit.io.kitti_raw import KittiRaw

    ds = KittiOdometry(shared_path("kitti_odometry"), "00")
    stored = ds.read_scan(0).points_xyz
    ds.configure_for_method("genz")
    assert ds.reader_options["vertical_correction_applied"] is True
    theirs = np.asarray(genz_icp_pybind._correct_kitti_scan(genz_icp_pybind._Vector3dVector(stored)))
    np.testing.assert_array_equal(ds.read_scan(0).points_xyz, theirs)
    ds.configure_for_method("small_gicp")
    assert ds.reader_options["vertical_correction_applied"] is False
    raw = KittiRaw(_raw_drive_of_sequence_00(tmp_path))
    raw.configure_for_method("genz")
    assert raw.reader_options["vertical_correction_applied"] is True
