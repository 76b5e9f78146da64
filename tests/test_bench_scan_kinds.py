"""Suites over every scan reader (bags, MCAP, kiss-icp loaders) and the camera simulator, and the task checks that
go with them: odometry of fewer than 2 scans, icp_pair's KITTI frame numbers beside a ground-truth file, finite noise."""

from __future__ import annotations

import hashlib
import os
import textwrap
from pathlib import Path

import numpy as np
import pytest
from conftest import cli_exit_code, shared_path

from lidarkit.bench.runner import run_suite
from lidarkit.bench.suite import load_suite
from lidarkit.errors import ConfigError

#: six sweeps of the simulated street by a 16-beam, 360-column sensor: a real recording small enough for a test
SIM_ARGS = ["-n", "6", "-p", "n_beams=16", "-p", "n_azimuths=360"]


@pytest.fixture(scope="module")
def mcap_file(tmp_path_factory):
    """A real MCAP file written by ``lidarkit sim lidar -f mcap`` (PointCloud2 on /points, ground truth on /ground_truth)."""
    path = tmp_path_factory.mktemp("bag") / "drive.mcap"
    assert cli_exit_code(["sim", "lidar", "-f", "mcap", *SIM_ARGS, "-o", str(path), "--no-progress"]) == 0
    return path


def write(folder, text):
    path = folder / "suite.yaml"
    path.write_text(textwrap.dedent(text))
    return path


def run_serially(suite, out):
    """``{(experiment, dataset name, method): job record}`` of a serial run of ``suite``."""
    records = {}

    def keep(job, record):
        records[(job.experiment, job.dataset_name, job.method)] = record

    run_suite(suite, out, executor="serial", on_result=keep)
    return records


def test_an_odometry_suite_runs_on_an_mcap_file_as_the_odometry_run_does(mcap_file, tmp_path):
    """A suite on {kind: mcap, ...} was refused ("task 'odometry' does not take dataset kind 'mcap'") though
    ``lidarkit.odometry.run`` takes the same file; its baseline hashes the recording itself."""
    from lidarkit.bench.baseline import dataset_checksums
    from lidarkit.odometry import run

    path = write(tmp_path, f"""
        experiments:
          - name: bag
            task: odometry
            dataset: {{kind: mcap, path: "{mcap_file}", name: bag}}
            methods: [kiss]
        """)
    suite = load_suite(path)
    records = run_serially(suite, tmp_path / "out")
    record = records[("bag", "bag", "kiss")]
    assert record["status"] == "ok", record["error"]
    direct = run(f"mcap:{mcap_file}", "kiss")
    assert record["metrics"]["n_frames"] == 6
    # (kiss's threads reorder sums: equal up to round-off)
    ape = {name: direct.metrics[key]["stats"]["rmse"] for name, key in (("ape_se3_rmse_m", "ape_translation_se3_m"),
                                                                        ("ape_rmse_m", "ape_translation_m"))}
    assert {name: record["metrics"][name] for name in ape} == pytest.approx(ape, rel=1e-9)
    assert dataset_checksums(suite.jobs[0].dataset) == {"drive.mcap": hashlib.sha256(mcap_file.read_bytes()).hexdigest()}


def test_icp_pair_on_an_mcap_file_scores_as_on_the_simulated_drive_it_records(mcap_file, tmp_path):
    """icp_pair refused bags too; on the MCAP export of a simulated drive it scores the pair as on the drive itself
    (scan indices, the bag's ground truth re-timed as the simulator's)."""
    path = write(tmp_path, f"""
        experiments:
          - name: pair
            task: icp_pair
            datasets:
              - {{kind: mcap, path: "{mcap_file}", name: bag}}
              - {{kind: sim_lidar, n_frames: 6, n_beams: 16, n_azimuths: 360, seed: 0, name: sim}}
            options: {{pairs: [[1, 2]]}}
            methods: [{{name: vanilla, params: {{voxel_size_m: 0.5}}}}]
        """)
    records = run_serially(load_suite(path), tmp_path / "out")
    bag, sim = records[("pair", "bag", "vanilla")], records[("pair", "sim", "vanilla")]
    assert bag["status"] == sim["status"] == "ok", (bag["error"], sim["error"])
    assert [(p["target"], p["source"]) for p in bag["info"]["pairs"]] == [(1, 2)]
    # (the bag holds float32 points)
    assert bag["metrics"]["translation_error_m"] == pytest.approx(sim["metrics"]["translation_error_m"], rel=1e-4)
    assert bag["metrics"]["rotation_error_deg"] == pytest.approx(sim["metrics"]["rotation_error_deg"], rel=1e-3)


def test_a_kiss_kitti_suite_hashes_its_sequence_not_the_whole_root(tmp_path):
    """kiss-icp's KITTI loader was refused by the tasks; its baseline would have hashed every sequence of the root
    (it has no ``sequence_dir``): it hashes sequences/NN and poses/NN.txt, as the kitti kind does."""
    from lidarkit.bench.baseline import dataset_files

    root = shared_path("kitti_odometry")
    path = write(tmp_path, f"""
        experiments:
          - task: odometry
            dataset: {{kind: kiss_kitti, path: "{root}", sequence: 0}}
            options: {{frames: "0:3"}}
            methods: [kiss]
        """)
    (job,) = load_suite(path).jobs
    files = dataset_files(job.dataset)
    assert Path(os.path.abspath(root)) / "poses" / "00.txt" in files  # (named as the suite names the data, links kept)
    assert len([f for f in files if f.suffix == ".bin"]) == 10  # sequences/00/velodyne only
    assert not [f for f in files if "extra_frames" in f.parts]


def test_a_vo_suite_runs_on_the_camera_simulator_as_a_simcam_spec(tmp_path):
    """vo refused sim_camera (listed as a generated kind, taken by no task) though ``lidarkit vo`` reads
    ``simcam:street?...``; the job gives the APE of the same drive opened from the spec, and a baseline pins the
    simulator's whole config (its checksum hashes the suite's settings only), as for sim_lidar."""
    import lidarkit.vo as vo
    from lidarkit.vo.evaluation import score_vo
    from lidarkit.vo.inputs import open_vo_input

    camera = {"n_frames": 4, "width": 256, "height": 96, "fx": 160.0, "fy": 160.0, "cx": 127.5, "cy": 47.5, "seed": 1}
    path = write(tmp_path, f"""
        experiments:
          - name: vo
            task: vo
            dataset: {{kind: sim_camera, name: cam, {", ".join(f"{k}: {v}" for k, v in camera.items())}}}
            options: {{align: none}}
            methods: [{{name: lidarkit, params: {{scale.mode: gt}}}}]
        """)
    from lidarkit.bench.baseline import run_job

    (job,) = load_suite(path).jobs
    pinned = run_job(job)  # the job as a baseline runs it: its metrics and the simulator's whole config
    assert pinned.protocol["simulation"]["seed"] == 1 and pinned.protocol["simulation"]["width"] == 256
    assert pinned.protocol["simulation"]["noise_std"] == 0.0  # (a default, pinned too)
    spec = "simcam:street?" + "&".join(f"{k}={v}" for k, v in camera.items())
    vo_input = open_vo_input(spec)
    config = vo.preset("lidarkit", **{"scale.mode": "gt", "seed": 0})
    result = vo.run_vo(vo.images_in_memory(vo_input.images), vo_input.K, config, ground_truth=vo_input.ground_truth,
                       timestamps_s=np.asarray(vo_input.images.timestamps_s, dtype=float))
    direct = score_vo(result.trajectory, vo_input.ground_truth, "gt", "none").metrics["ape_rmse_m"]
    assert pinned.metrics["ape_rmse_m"] == pytest.approx(direct, rel=1e-9)
    assert pinned.metrics["n_frames"] == 4


def test_sim_camera_options_are_checked_with_the_suite(tmp_path):
    path = write(tmp_path, """
        experiments:
          - task: vo
            dataset: {kind: sim_camera, n_frame: 5}
            methods: [lidarkit]
        """)
    with pytest.raises(ConfigError, match=r"\(experiments\[0\]\.dataset, line 4\): .*n_frame"):
        load_suite(path)


@pytest.mark.parametrize("frames", ['"0:1"', '"9:"', "[3]"])
def test_odometry_frames_of_one_scan_are_refused_with_the_suite(tmp_path, frames):
    """``frames: "0:1"`` ran, "ok", and scored nothing ("none: one frame, nothing to score")."""
    path = write(tmp_path, f"""
        experiments:
          - name: one
            task: odometry
            dataset: {{kind: kitti, path: "{shared_path('kitti_odometry')}", sequence: "00"}}
            options: {{frames: {frames}}}
            methods: [kiss]
        """)
    with pytest.raises(ConfigError) as info:
        load_suite(path)
    message = str(info.value)
    assert "(experiments[0].options, line 6)" in message
    assert "selects 1 scan" in message and "odometry needs 2 scans or more" in message
    assert "\n" not in message


def test_an_odometry_dataset_of_one_scan_is_refused_with_the_suite(tmp_path):
    """Without ``frames`` a one-scan sequence ran, "ok", and scored nothing, as ``frames: "0:1"`` did."""
    velodyne = tmp_path / "kitti" / "sequences" / "00" / "velodyne"
    velodyne.mkdir(parents=True)
    np.zeros((10, 4), dtype=np.float32).tofile(velodyne / "000000.bin")
    path = write(tmp_path, f"""
        experiments:
          - task: odometry
            dataset: {{kind: kitti, path: "{tmp_path / 'kitti'}", sequence: "00"}}
            methods: [kiss]
        """)
    with pytest.raises(ConfigError) as info:
        load_suite(path)
    assert str(info.value) == (f"{path} (experiments[0].dataset, line 4): the dataset has 1 scan: odometry needs 2 scans "
                               "or more (the first is the start, where nothing is scored)")


def test_odometry_frames_of_one_scan_of_a_bag_fail_the_job_saying_why(mcap_file, tmp_path):
    """A bag's length is known when its job runs: there the job fails naming the selection (it ran and scored nothing)."""
    path = write(tmp_path, f"""
        experiments:
          - name: one
            task: odometry
            dataset: {{kind: mcap, path: "{mcap_file}", name: bag}}
            options: {{frames: "5:"}}
            methods: [kiss]
        """)
    record = run_serially(load_suite(path), tmp_path / "out")[("one", "bag", "kiss")]
    assert record["status"] == "failed"
    assert record["error"]["message"] == ("bag: frames: '5:' selects 1 scan of the dataset's 6: odometry needs 2 scans or more "
                                          "(the first is the start, where nothing is scored)")


def test_icp_pair_reads_kitti_frame_numbers_with_a_ground_truth_file_too(tmp_path):
    """With ``ground_truth_file`` the KITTI pairs became scan indices: [[94, 95]] on a velodyne_dir of frames 94, 95,
    198, 199 read "pairs name scan indices the dataset lacks: 94, 95 (it has scan indices 0..3)"."""
    from lidarkit.io import open_dataset

    root = shared_path("kitti_odometry")
    kitti = open_dataset("kitti", root, sequence="00", velodyne_dir="extra_frames/00/velodyne")
    np.savetxt(tmp_path / "gt9495.txt", kitti.relative_pose(94, 95))
    dataset = f'{{kind: kitti, path: "{root}", sequence: "00", velodyne_dir: extra_frames/00/velodyne, name: k}}'
    path = write(tmp_path, f"""
        experiments:
          - name: file
            task: icp_pair
            dataset: {dataset}
            options: {{pairs: [[94, 95]], ground_truth_file: "{tmp_path / 'gt9495.txt'}"}}
            methods: [{{name: vanilla, params: {{voxel_size_m: 1.0}}}}]
          - name: poses
            task: icp_pair
            dataset: {dataset}
            options: {{pairs: [[94, 95]]}}
            methods: [{{name: vanilla, params: {{voxel_size_m: 1.0}}}}]
        """)
    records = run_serially(load_suite(path), tmp_path / "out")
    with_file, with_poses = records[("file", "k", "vanilla")], records[("poses", "k", "vanilla")]
    assert with_file["status"] == with_poses["status"] == "ok", (with_file["error"], with_poses["error"])
    assert [(p["target"], p["source"]) for p in with_file["info"]["pairs"]] == [(94, 95)]
    # the same scans against the same motion (from the file, or the sequence's poses)
    assert with_file["metrics"]["translation_error_m"] == pytest.approx(with_poses["metrics"]["translation_error_m"], rel=1e-6)
    assert with_file["metrics"]["translation_error_m"] < 0.2
    # scan indices are frames the dataset lacks there
    path.write_text(path.read_text().replace("[[94, 95]], ground_truth_file", "[[0, 1]], ground_truth_file"))
    with pytest.raises(ConfigError, match=r"\(experiments\[0\]\.options, line 6\): pairs name frames the dataset lacks: 0, 1"):
        load_suite(path)


@pytest.mark.parametrize(("option", "value"), [("init_noise_m", ".inf"), ("init_noise_deg", ".inf")])
def test_icp_pair_noise_that_is_not_finite_is_refused_naming_the_option(tmp_path, option, value):
    """``init_noise_m: .inf`` read "(experiments[0].methods[0], line 1): values must be plain numbers ... (Out of range
    float values are not JSON compliant)", naming neither the option nor its line."""
    path = write(tmp_path, f"""
        experiments:
          - task: icp_pair
            dataset: {{kind: sim_lidar, n_frames: 3}}
            options: {{pairs: [[0, 1]], {option}: {value}}}
            methods: [vanilla]
        """)
    with pytest.raises(ConfigError) as info:
        load_suite(path)
    message = str(info.value)
    assert "(experiments[0].options, line 5)" in message and f"{option}: " in message
    assert "finite number" in message


@pytest.mark.parametrize(("options", "named"), [("{pairs: [[true, 2]]}", "pairs"), ("{pairs: [[0, 1]], init_noise_m: yes}", "init_noise_m"),
                                                ("{max_pairs: true}", "max_pairs"), ("{}", "no pair of scans")])
def test_icp_pair_options_refuse_yes_no_values_and_a_dataset_without_a_pair(tmp_path, options, named):
    """pairs [[true, 2]] registered frames 1 and 2, init_noise_m: yes perturbed by 1 m (YAML's booleans read as numbers);
    a one-scan drive without pairs passed the suite and every job failed "no scan pair to register", exit 0."""
    path = write(tmp_path, f"""
        experiments:
          - task: icp_pair
            dataset: {{kind: sim_lidar, n_frames: {1 if options == "{}" else 3}}}
            options: {options}
            methods: [vanilla]
        """)
    with pytest.raises(ConfigError) as info:
        load_suite(path)
    assert "(experiments[0].options" in str(info.value) and named in str(info.value)
