"""Suites refused at load rather than failing every job, and job keys that do not depend on how a number is written."""

from __future__ import annotations

import textwrap

import numpy as np
import pytest

from lidarkit.bench.jobs import Job
from lidarkit.bench.results import load_results
from lidarkit.bench.runner import run_suite
from lidarkit.bench.suite import load_suite
from lidarkit.errors import ConfigError


def write(tmp_path, text, name="suite.yaml"):
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


def test_a_number_written_1_or_1_0_is_one_job_and_an_edited_suite_reruns_nothing(tmp_path):
    """``noise_m: 1.0`` and ``noise_m: 1`` hashed to two keys: a suite edited from one to the other reran every job, and
    ``lidarkit report --all`` showed two rows with one label."""
    def job(params):
        return Job(task="selftest", experiment="rw", dataset_name="synthetic", dataset={"kind": "synthetic"},
                   method="random_walk", params=params, seed=1, options={"span": [0.0, 2.0]})

    assert job({"noise_m": 1.0, "steps": 60}).key("0") == job({"noise_m": 1, "steps": 60}).key("0")
    assert job({"noise_m": 1.5}).key("0") != job({"noise_m": 1}).key("0")
    assert job({"name": "1.0"}).key("0") != job({"name": "1"}).key("0")  # text stays text
    # a spec without a whole float keys as it did before (a folder written then is resumed, not rerun)
    kept = Job(task="odometry", experiment="e", dataset_name="sim",
               dataset={"kind": "sim_lidar", "n_frames": 40, "scene": "street"}, method="vanilla",
               params={"voxel_size_m": 0.5, "max_iterations": 30, "deskew": False, "name": "x"}, seed=3,
               options={"frames": [0, 2, 5]})
    assert kept.key("0.1.0+src.0123456789") == "8d5171a0dc3bfbe1a8d3"

    suite = """
        name: keys
        seeds: 2
        experiments:
          - name: rw
            task: selftest
            dataset: {kind: synthetic}
            methods:
              - {name: random_walk, params: {noise_m: NOISE, steps: 20}}
        """
    out = tmp_path / "out"
    first = run_suite(load_suite(write(tmp_path, suite.replace("NOISE", "1.0"))), out, executor="serial")
    assert (first.ran, first.ok) == (2, 2)
    again = run_suite(load_suite(write(tmp_path, suite.replace("NOISE", "1"))), out, executor="serial")
    assert (again.ran, again.skipped) == (0, 2)
    assert len(load_results(out)) == 2  # one row of two seeds, not two rows labelled random_walk(noise_m=1, steps=20)


def _scan_folder(tmp_path, poses: bool):
    folder = tmp_path / "pair"
    folder.mkdir(parents=True)
    rng = np.random.default_rng(0)
    for k in range(2):
        np.save(folder / f"{k:06d}.npy", rng.uniform(-10, 10, (500, 3)).astype(np.float32))
    if poses:
        rows = np.array([[1, 0, 0, x, 0, 1, 0, 0, 0, 0, 1, 0] for x in (0.0, 0.5)], dtype=float)
        np.savetxt(folder / "poses.txt", rows)
    return folder


def test_icp_pair_on_a_folder_without_ground_truth_is_refused_at_load(tmp_path):
    """A scan folder without poses passed the dry run; every job then failed "icp_pair needs ground-truth poses" and
    the run exited 0."""
    folder = _scan_folder(tmp_path, poses=False)
    path = write(tmp_path, f"""
        experiments:
          - task: icp_pair
            dataset: {{kind: folder, path: "{folder}"}}
            methods: [vanilla]
        """)
    with pytest.raises(ConfigError) as info:
        load_suite(path)
    assert str(info.value).startswith(f"{path} (experiments[0].dataset, line 4): icp_pair scores against ground-truth "
                                      "poses and pair has none")
    # with poses, or with one pair's motion as ground_truth_file, it loads
    np.savetxt(folder / "T.txt", np.eye(4))
    path = write(tmp_path, f"""
        experiments:
          - task: icp_pair
            dataset: {{kind: folder, path: "{folder}"}}
            options: {{pairs: [[0, 1]], ground_truth_file: T.txt}}
            methods: [vanilla]
        """)
    assert len(load_suite(path).jobs) == 1
    posed = _scan_folder(tmp_path / "posed", poses=True)
    path = write(tmp_path, f"""
        experiments:
          - task: icp_pair
            dataset: {{kind: folder, path: "{posed}", poses: poses.txt}}
            methods: [vanilla]
        """)
    assert len(load_suite(path).jobs) == 1


@pytest.mark.parametrize("task, dataset, options, reason", [
    ("icp_pair", "{kind: sim_lidar, n_frames: 3}", "{pairs: [[0, 5]]}",
     "pairs name scan indices the dataset lacks: 5 (it has scan indices 0..2)"),
    ("icp_pair", "{kind: sim_lidar}", "{pairs: [[299, 300]]}",  # n_frames' default, 300
     "pairs name scan indices the dataset lacks: 300 (it has scan indices 0..299)"),
    ("odometry", "{kind: sim_lidar, n_frames: 5}", "{frames: [0, 2, 20]}",
     "frames: frame indices must lie in 0..4 (the dataset has 5 scans)"),
    ("odometry", "{kind: sim_lidar, n_frames: 5}", '{frames: "10:20"}', "frames: '10:20' selects no scan of the dataset's 5"),
])
def test_pairs_and_frames_outside_a_simulated_drive_are_refused_at_load(tmp_path, task, dataset, options, reason):
    """On a simulated drive, pairs and frames past its ``n_frames`` passed the dry run; every job then failed."""
    path = write(tmp_path, f"""
        experiments:
          - task: {task}
            dataset: {dataset}
            options: {options}
            methods: [vanilla]
        """)
    with pytest.raises(ConfigError) as info:
        load_suite(path)
    assert str(info.value) == f"{path} (experiments[0].options, line 5): {reason}"


def test_pairs_and_frames_inside_a_simulated_drive_still_load(tmp_path):
    path = write(tmp_path, """
        experiments:
          - task: icp_pair
            dataset: {kind: sim_lidar}
            options: {pairs: [[298, 299]]}
            methods: [vanilla]
          - task: odometry
            dataset: {kind: sim_lidar, n_frames: 5}
            options: {frames: [0, 2, 4]}
            methods: [vanilla]
        """)
    assert [job.task for job in load_suite(path).jobs] == ["icp_pair", "odometry"]
