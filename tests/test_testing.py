"""lidarkit.testing: trajectory and baseline assertions, and the pytest plugin's fixtures in a user's test run."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from lidarkit.bench.baseline import record
from lidarkit.errors import ConfigError, DataError, EvaluationError
from lidarkit.geometry import make_se3, so3_exp
from lidarkit.testing import assert_no_worse_than, assert_trajectory_close
from lidarkit.trajectory import Trajectory

REPO = Path(__file__).resolve().parents[1]


def walk(n: int = 20, offset_m: float = 0.0, yaw_deg: float = 0.0) -> Trajectory:
    poses = np.stack([make_se3(so3_exp([0, 0, np.radians(yaw_deg)]), [i + offset_m * (i == 7), 0.0, 0.0]) for i in range(n)])
    return Trajectory(poses)


def test_assert_trajectory_close_names_the_worst_frame():
    assert_trajectory_close(walk(), walk())
    with pytest.raises(AssertionError, match=r"1 of 20 poses differ: worst at frame 7: 0.01 m"):
        assert_trajectory_close(walk(offset_m=0.01), walk(), atol_m=0.005)
    with pytest.raises(AssertionError, match="0.1 deg"):
        assert_trajectory_close(walk(yaw_deg=0.1), walk(), atol_deg=0.05)
    assert_trajectory_close(walk(yaw_deg=0.1), walk(), atol_deg=0.2)
    with pytest.raises(AssertionError, match="differ in length"):
        assert_trajectory_close(walk(5), walk(6))


def test_assert_trajectory_close_on_a_text_copy_and_bad_arguments(tmp_path):
    """A trajectory read back from its KITTI text differed from itself by 0.00085 deg (arccos of the trace near 1);
    a negative tolerance and an array in place of a Trajectory were taken (the array as an AttributeError)."""
    from scipy.spatial.transform import Rotation

    poses = np.tile(np.eye(4), (5, 1, 1))
    poses[:, :3, :3] = Rotation.from_rotvec(np.random.default_rng(0).normal(size=(5, 3))).as_matrix()
    original = Trajectory(poses)
    original.to_kitti(tmp_path / "poses.txt")
    assert_trajectory_close(Trajectory.from_kitti(tmp_path / "poses.txt"), original, atol_m=1e-6, atol_deg=1e-4)
    with pytest.raises(ConfigError, match="atol_m must be a finite number >= 0, got -1"):
        assert_trajectory_close(original, original, atol_m=-1)
    with pytest.raises(ConfigError, match="actual must be a lidarkit Trajectory .* got ndarray"):
        assert_trajectory_close(poses, original)



def test_numpy_tolerances_and_metrics_are_numbers(tmp_path):
    """atol_m=np.float32(0.01) was refused ("must be a finite number >= 0, got np.float32(0.01)"), and a float32 metric
    of a mapping was left out ("metric not in the result"); bools stay refused."""
    original = walk()
    original.to_kitti(tmp_path / "poses.txt")
    copy = Trajectory.from_kitti(tmp_path / "poses.txt")
    assert_trajectory_close(copy, original, atol_m=np.float32(0.01), atol_deg=np.float64(0.05))
    assert_trajectory_close(copy, original, atol_m=np.int64(1))
    with pytest.raises(AssertionError, match=r"1 of 20 poses differ: worst at frame 7"):
        assert_trajectory_close(walk(offset_m=0.01), original, atol_m=np.float32(0.005))
    for bad in (True, np.bool_(True), "0.01", np.float32("nan")):
        with pytest.raises(ConfigError, match="atol_m must be a finite number >= 0"):
            assert_trajectory_close(copy, original, atol_m=bad)
    assert_no_worse_than({"ape_rmse_m": np.float32(0.5)}, {"ape_rmse_m": 0.5}, metric="ape_rmse_m")
    with pytest.raises(AssertionError, match="regression: ape_rmse_m = 0.75"):
        assert_no_worse_than({"ape_rmse_m": np.float32(0.75)}, {"ape_rmse_m": 0.5}, metric="ape_rmse_m")

SUITE = """
name: tiny-golden
experiments:
  - name: walk
    task: selftest
    dataset: {kind: synthetic, name: synth}
    methods:
      - {name: random_walk, params: {steps: 40, noise_m: 0.05}}
"""


@pytest.fixture(scope="module")
def tiny_baseline(tmp_path_factory):
    root = tmp_path_factory.mktemp("tiny")
    (root / "suite.yaml").write_text(textwrap.dedent(SUITE))
    return record(root / "suite.yaml", root / "baseline", repeats=2)


def test_assert_no_worse_than_against_a_baseline_and_a_mapping(tiny_baseline):
    pinned = tiny_baseline.metrics("random_walk")
    ape = pinned["ape_rmse_m"]
    band = tiny_baseline.job("random_walk")["bands"]["ape_rmse_m"]
    assert band == pytest.approx(max(0.01, 0.02 * ape))  # deterministic job: the floor sets the band
    assert_no_worse_than({"ape_rmse_m": ape + 0.5 * band}, tiny_baseline, metric="ape_rmse_m")
    assert_no_worse_than({"ape_rmse_m": ape - 1.0}, tiny_baseline.path, metric="ape_rmse_m", method="random_walk")
    with pytest.raises(AssertionError, match=r"regression: ape_rmse_m = .* \(worse by 0.02"):
        assert_no_worse_than({"ape_rmse_m": ape + 0.02}, tiny_baseline, metric="ape_rmse_m", tolerance=0.0)
    with pytest.raises(AssertionError, match="regression"):
        assert_no_worse_than({"hz": 9.0}, {"hz": 10.0}, metric="hz", tolerance=0.5)
    assert_no_worse_than({"hz": 11.0}, {"hz": 10.0}, metric="hz")
    with pytest.raises(EvaluationError, match="not in the result"):
        assert_no_worse_than({"x": 1.0}, tiny_baseline, metric="ape_rmse_m")
    for bad in ("abc", [0.1], -1.0, float("nan")):  # a bare ValueError / TypeError for the first two
        with pytest.raises(ConfigError, match="tolerance must be a finite number >= 0"):
            assert_no_worse_than({"ape_rmse_m": ape}, tiny_baseline, metric="ape_rmse_m", tolerance=bad)
    with pytest.raises(EvaluationError, match="the baseline's ape_rmse_m is nan: nothing to hold the result against"):
        assert_no_worse_than({"ape_rmse_m": 0.3}, {"ape_rmse_m": float("nan")}, metric="ape_rmse_m")  # (it passed)
    # a pinned job's mapping (another baseline's) is held on its spec's data too: over another seed it passed on its
    # frame count alone
    import copy

    job = tiny_baseline.job("random_walk")
    assert_no_worse_than(job, tiny_baseline, method="random_walk", metric="ape_rmse_m", tolerance=0.0)
    other = copy.deepcopy(dict(job))
    other["spec"]["seed"] = int(other["spec"].get("seed") or 0) + 7
    with pytest.raises(EvaluationError, match="the result's job seed differs from the pinned job"):
        assert_no_worse_than(other, tiny_baseline, method="random_walk", metric="ape_rmse_m", tolerance=1.0)


def test_a_result_over_other_data_than_the_pinned_job_is_refused(tmp_path):
    """kiss pinned on an 8-sweep simulated drive: vanilla over 3 sweeps of it passed at tolerance 0 (nothing said the
    data differ); over another seed of the scene too."""
    from lidarkit.odometry import run
    from lidarkit.sim.lidar import SimulatedLidarSequence

    (tmp_path / "suite.yaml").write_text(textwrap.dedent("""
        name: kiss-reference
        experiments:
          - name: sim
            task: odometry
            dataset: {kind: sim_lidar, scene: street, n_frames: 8, n_beams: 16, n_azimuths: 360, seed: 0, name: sim street}
            methods: [kiss]
    """))
    baseline = record(tmp_path / "suite.yaml", tmp_path / "baseline", repeats=1)
    drive = dict(scene="street", n_beams=16, n_azimuths=360)
    same = run(SimulatedLidarSequence(n_frames=8, seed=0, **drive), "kiss")
    assert_no_worse_than(same, baseline, method="kiss", metric="ape_rmse_m", tolerance=1e-9)
    with pytest.raises(EvaluationError, match="the result ran over 3 frames, the pinned job 'kiss' over 8: not the pinned data"):
        assert_no_worse_than(run(SimulatedLidarSequence(n_frames=3, seed=0, **drive), "kiss"), baseline, method="kiss", metric="ape_rmse_m")
    with pytest.raises(EvaluationError, match=r"dataset differs from the pinned job 'kiss': seed 1 \(pinned 0\)"):
        assert_no_worse_than(run(SimulatedLidarSequence(n_frames=8, seed=1, **drive), "kiss"), baseline, method="kiss", metric="ape_rmse_m")
    # a setting the suite leaves at its default is part of the pinned data too: a noisier sensor passed against it
    with pytest.raises(EvaluationError, match=r"dataset differs from the pinned job 'kiss': range_noise_std_m 0.05 \(pinned 0.0\)"):
        assert_no_worse_than(run(SimulatedLidarSequence(n_frames=8, seed=0, range_noise_std_m=0.05, **drive), "kiss"), baseline,
                             method="kiss", metric="ape_rmse_m", tolerance=10.0)
    # a ground truth passed to run() by the caller (here the method's own estimate: APE 0) is not the pinned data's
    own = run(SimulatedLidarSequence(n_frames=8, seed=0, **drive), "kiss", ground_truth=same.trajectory)
    with pytest.raises(EvaluationError, match=r"the result's ground truth differs from the pinned job 'kiss': .*given to run\(\) by "
                                              r"the caller, not the dataset's"):
        assert_no_worse_than(own, baseline, method="kiss", metric="ape_rmse_m", tolerance=1.0)


def test_a_result_over_other_frames_another_dataset_or_another_seed_is_refused(tmp_path):
    """Pinned: kiss over frames 0:8 of a 12-sweep drive. Eight other sweeps of it (every other one, or 4:12), a
    simulated run against a pinned KITTI job, and bench records of other seeds all passed against it."""
    from conftest import shared_path

    from lidarkit.bench.results import load_results
    from lidarkit.bench.runner import run_suite
    from lidarkit.bench.suite import load_suite
    from lidarkit.odometry import run
    from lidarkit.sim.lidar import SimulatedLidarSequence

    kitti = shared_path("kitti_odometry", "sequences", "00")
    (tmp_path / "suite.yaml").write_text(textwrap.dedent(f"""
        name: frames
        seeds: [0, 1]
        experiments:
          - name: sim
            task: odometry
            dataset: {{kind: sim_lidar, scene: street, n_frames: 12, n_beams: 16, n_azimuths: 360, seed: 0, name: sim street}}
            options: {{frames: "0:8"}}
            methods: [kiss]
          - name: kitti
            task: odometry
            dataset: {{kind: kitti, path: "{kitti}", name: K00}}
            options: {{frames: "0:5"}}
            methods: [open3d_point_to_plane]
    """))
    baseline = record(tmp_path / "suite.yaml", tmp_path / "baseline", repeats=1)
    sim = SimulatedLidarSequence(n_frames=12, seed=0, scene="street", n_beams=16, n_azimuths=360)
    pick = dict(method="kiss", metric="ape_rmse_m", tolerance=10.0)
    seed0 = {"method": "kiss", "dataset": "sim street"}
    with pytest.raises(ConfigError, match="2 pinned jobs match .*: pick one with seed= \\(0, 1\\)$"):  # the seed picks one
        baseline.job(**seed0)
    pinned = baseline.job(**seed0, seed=0)
    assert_no_worse_than(run(sim, "kiss", frames="0:8"), baseline, dataset="sim street", seed=0, **pick)
    for frames, shown in (([0, 2, 4, 6, 8, 9, 10, 11], "0, 2, 4, 6, 8-11"), ("4:12", "4-11")):
        with pytest.raises(EvaluationError, match=rf"the result's frames differ from the pinned job 'kiss': {shown} \(pinned 0:8: 0-7\)$"):
            assert_no_worse_than(run(sim, "kiss", frames=frames), baseline, dataset="sim street", seed=0, **pick)
    other = run(SimulatedLidarSequence(n_frames=5, seed=1, scene="street", n_beams=16, n_azimuths=360), "open3d_point_to_plane")
    with pytest.raises(EvaluationError, match="the result's dataset differs from the pinned job 'open3d_point_to_plane': kind sim_lidar \\(pinned kitti\\)"):
        assert_no_worse_than(other, baseline, method="open3d_point_to_plane", metric="ape_rmse_m", tolerance=10.0, seed=0)
    run_suite(load_suite(tmp_path / "suite.yaml"), tmp_path / "results", executor="serial")
    record_seed1 = next(r for r in load_results(tmp_path / "results") if r["job"]["method"] == "kiss" and r["job"]["seed"] == 1)
    assert pinned["spec"]["seed"] == 0
    with pytest.raises(EvaluationError, match="the result's job seed differs from the pinned job 'kiss': 1 \\(pinned 0\\)"):
        assert_no_worse_than(record_seed1, baseline, dataset="sim street", seed=0, **pick)
    assert_no_worse_than(record_seed1, baseline, dataset="sim street", seed=1, **pick)


def test_frames_of_a_longer_drive_name_the_drive_and_frames_read_as_ranges(tmp_path):
    """Frames 0:8 of a 10-sweep drive against kiss pinned on the 8-sweep drive read "the result's frames differs ...:
    [0, 1, 2, 3, 4, 5]... (pinned all: [0, 1, 2, 3, 4, 5]...)": the pinned "all" was resolved on the result's 10 sweeps,
    and the first six frames of both read alike. The drive's length is named now; frames read as ranges."""
    from lidarkit.odometry import run
    from lidarkit.sim.lidar import SimulatedLidarSequence

    (tmp_path / "suite.yaml").write_text(textwrap.dedent("""
        name: eight
        experiments:
          - task: odometry
            dataset: {kind: sim_lidar, scene: street, n_frames: 8, n_beams: 16, n_azimuths: 360, seed: 0, name: sim street}
            methods: [kiss]
    """))
    baseline = record(tmp_path / "suite.yaml", tmp_path / "baseline", repeats=1)
    longer = run(SimulatedLidarSequence(n_frames=10, seed=0, scene="street", n_beams=16, n_azimuths=360), "kiss", frames="0:8")
    with pytest.raises(EvaluationError, match=r"^assert_no_worse_than: the result's dataset differs from the pinned job "
                                              r"'kiss': n_frames 10 \(pinned 8\)$"):
        assert_no_worse_than(longer, baseline, method="kiss", metric="ape_rmse_m", tolerance=10.0)
    from lidarkit.errors import index_runs

    assert index_runs(list(range(0, 40, 2)), max_runs=5) == "0, 2, 4, 6, 8, ... (20 frames)"
    assert index_runs([3, 4, 5, 9], max_runs=5) == "3-5, 9"


def test_pytest_plugin_fixture_in_a_user_test_run(tiny_baseline, tmp_path):
    (tmp_path / "test_user.py").write_text(textwrap.dedent("""
        from lidarkit.testing import assert_no_worse_than

        def test_my_variant_holds(lidarkit_baseline):
            pinned = lidarkit_baseline.metrics("random_walk")
            assert_no_worse_than({"ape_rmse_m": pinned["ape_rmse_m"]}, lidarkit_baseline, metric="ape_rmse_m")

        def test_my_variant_regressed(lidarkit_baseline):
            pinned = lidarkit_baseline.metrics("random_walk")
            assert_no_worse_than({"ape_rmse_m": pinned["ape_rmse_m"] + 1}, lidarkit_baseline, metric="ape_rmse_m")
    """))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}
    # installed (pip install -e .), the pytest11 entry point loads the plugin by itself; else name it with -p
    from importlib.metadata import entry_points

    installed = any(ep.value == "lidarkit.testing.plugin" for ep in entry_points(group="pytest11"))
    load = [] if installed else ["-p", "lidarkit.testing.plugin"]
    proc = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", *load, "-p", "no:cacheprovider",
         "--lidarkit-baseline", str(tiny_baseline.path), "test_user.py"],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert "1 failed, 1 passed" in proc.stdout, proc.stdout + proc.stderr
    assert "regression: ape_rmse_m" in proc.stdout
    # relative folders: on the command line from where pytest runs, in pytest.ini from the ini file's folder
    import shutil

    project = tmp_path / "project"
    shutil.copytree(tiny_baseline.path, project / "baselines" / "b")
    (project / "tests").mkdir()
    (project / "tests" / "test_user.py").write_text((tmp_path / "test_user.py").read_text())
    (project / "pytest.ini").write_text("[pytest]\nlidarkit_baseline = baselines/b\n")
    for option in (["--lidarkit-baseline", "../baselines/b"], []):
        proc = subprocess.run([sys.executable, "-m", "pytest", "-q", *load, "-p", "no:cacheprovider", *option, "test_user.py"],
                              cwd=project / "tests", env=env, capture_output=True, text=True, timeout=120)
        assert "1 failed, 1 passed" in proc.stdout, (option, proc.stdout + proc.stderr)


def test_load_lidarkit_baseline_reads_a_relative_folder_from_the_ini_file_or_where_pytest_runs(tiny_baseline, tmp_path):
    """``load_lidarkit_baseline("baselines/b")`` resolved against pytest's rootdir, which moves with the paths pytest is
    given: ``--lidarkit-baseline DIR`` (with a space, DIR read as a test path) moved it above the project, and
    ``--rootdir`` anywhere; the same test loaded another folder. It reads from the ini file's folder, else (here) from
    where pytest runs."""
    import shutil

    project = tmp_path / "project"
    shutil.copytree(tiny_baseline.path, project / "baselines" / "b")
    (project / "test_user.py").write_text(textwrap.dedent("""
        def test_loads(load_lidarkit_baseline):
            assert load_lidarkit_baseline("baselines/b").metrics("random_walk")["ape_rmse_m"] >= 0
    """))
    elsewhere = tmp_path / "elsewhere"
    shutil.copytree(tiny_baseline.path, elsewhere)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}
    from importlib.metadata import entry_points

    installed = any(ep.value == "lidarkit.testing.plugin" for ep in entry_points(group="pytest11"))
    load = [] if installed else ["-p", "lidarkit.testing.plugin"]
    pytest_argv = [sys.executable, "-m", "pytest", "-q", *load, "-p", "no:cacheprovider", "-W", "ignore"]
    # no ini file: from where pytest runs (the rootdir is tmp_path, above the folder given with a space)
    proc = subprocess.run([*pytest_argv, "--lidarkit-baseline", str(elsewhere)], cwd=project, env=env,
                          capture_output=True, text=True, timeout=120)
    assert "1 passed" in proc.stdout, proc.stdout + proc.stderr


def test_compare_holds_a_difference_against_the_noise_a_baseline_measured(tiny_baseline, tmp_path, capsys):
    from lidarkit.bench.runner import run_suite
    from lidarkit.bench.suite import load_suite
    from lidarkit.cli import main

    folders = []
    for noise_m in (0.05, 0.0502):  # a tiny but systematic difference
        path = tmp_path / f"s{noise_m}.yaml"
        path.write_text(textwrap.dedent(SUITE).replace("noise_m: 0.05", f"noise_m: {noise_m}") + "seeds: 8\n")
        run_suite(load_suite(path), tmp_path / f"r{noise_m}", executor="serial")
        folders.append(str(tmp_path / f"r{noise_m}"))
    argv = ["compare", *folders, "--metric", "ape_rmse_m"]
    with pytest.raises(SystemExit):
        main(argv)
    assert "is better than" in capsys.readouterr().out  # p < 0.05 over 8 seeds, same sign everywhere
    with pytest.raises(SystemExit):
        main([*argv, "--noise-from", str(tiny_baseline.path)])
    out = capsys.readouterr().out
    assert "no significant difference" in out and "within the run-to-run noise" in out


def test_a_kitti_root_pinned_with_its_sequence_accepts_a_run_on_that_sequence(tmp_path):
    """Pinned as a KITTI root + ``sequence: "00"`` (as docs/benchmarks.md shows), a run on exactly that data was refused:
    "path '.../sequences/00' (pinned '...')": the reader records the sequence folder, the spec names the root. A run
    without the angle correction the pinned job applied passed as the pinned data."""
    from conftest import kiss_on_kitti_00_suite, shared_path

    from lidarkit.bench.tasks._datasets import open_dataset_spec
    from lidarkit.io.kitti import KittiOdometry
    from lidarkit.odometry import run

    root = shared_path("kitti_odometry")
    baseline = record(kiss_on_kitti_00_suite(tmp_path, "0:5"), tmp_path / "baseline", repeats=1)
    pick = dict(method="kiss", metric="ape_rmse_m", tolerance=0.05)
    assert_no_worse_than(run(open_dataset_spec(baseline.job("kiss")["spec"]["dataset"]), "kiss", frames="0:5"), baseline, **pick)
    assert_no_worse_than(run(KittiOdometry(root / "sequences" / "00"), "kiss", frames="0:5"), baseline, **pick)
    uncorrected = run(KittiOdometry(root, sequence="00", vertical_correction=False), "kiss", frames="0:5")
    with pytest.raises(EvaluationError, match=r"dataset differs from the pinned job 'kiss': vertical_correction_applied False "
                                              r"\(pinned True\)"):
        assert_no_worse_than(uncorrected, baseline, **pick)


def test_a_kiss_kitti_root_pinned_with_its_sequence_accepts_a_run_on_that_sequence(tmp_path):
    """kiss-icp's KITTI loader records the root and ``sequence: "00"``; the pinned root was resolved to its sequence
    folder and the run's was not: a run over the pinned data was refused ("path '.../root' (pinned
    '.../root/sequences/00')"), and pinned as ``sequence: 0`` it read "sequence '00' (pinned 0)". Another sequence
    of the root is still refused."""
    import json

    from conftest import shared_path

    from lidarkit.odometry import run

    shared = shared_path("kitti_odometry")
    root = tmp_path / "kitti"
    (root / "poses").mkdir(parents=True)
    for seq in ("00", "01"):  # (the bundled 10 scans of 00, seen as two sequences)
        (root / "sequences" / seq).mkdir(parents=True)
        for name in ("velodyne", "calib.txt", "times.txt"):
            (root / "sequences" / seq / name).symlink_to(shared / "sequences" / "00" / name)
        (root / "poses" / f"{seq}.txt").symlink_to(shared / "poses" / "00.txt")
    (tmp_path / "suite.yaml").write_text(textwrap.dedent(f"""
        name: kk
        experiments:
          - task: odometry
            dataset: {{kind: kiss_kitti, path: "{root}", sequence: "00", name: k00}}
            options: {{frames: "0:4"}}
            methods: [kiss]
    """))
    baseline = record(tmp_path / "suite.yaml", tmp_path / "baseline", repeats=1)
    pick = dict(method="kiss", metric="ape_se3_rmse_m")
    result = run(f"kiss_kitti:{root}?sequence=00", "kiss", frames="0:4")
    assert_no_worse_than(result, baseline, **pick)
    manifest = json.loads((baseline.path / "manifest.json").read_text())
    manifest["jobs"][0]["spec"]["dataset"]["sequence"] = 0  # (as `sequence: 0` in the suite pins it)
    (baseline.path / "manifest.json").write_text(json.dumps(manifest))
    assert_no_worse_than(result, baseline.path, **pick)
    other = re.escape(f"path '{root}/sequences/01' (pinned '{root}/sequences/00'), sequence '01' (pinned 0)")
    with pytest.raises(EvaluationError, match=f"dataset differs from the pinned job 'kiss': {other}$"):
        assert_no_worse_than(run(f"kiss_kitti:{root}?sequence=1", "kiss", frames="0:4"), baseline.path, **pick)


@pytest.fixture(scope="module")
def kitti_selections(tmp_path_factory):
    """kiss pinned on the 10 KITTI 00 scans with ``frames: ":-2"`` and, in another baseline, ``"-3:"``."""
    from conftest import shared_path

    root = tmp_path_factory.mktemp("kitti_frames")
    baselines = {}
    for frames in (":-2", "-3:"):
        (root / "suite.yaml").write_text(textwrap.dedent(f"""
            name: selection
            experiments:
              - task: odometry
                dataset: {{kind: kitti, path: "{shared_path('kitti_odometry')}", sequence: "00", name: K00}}
                options: {{frames: "{frames}"}}
                methods: [kiss]
        """))
        baselines[frames] = record(root / "suite.yaml", root / frames.replace(":", "_"), repeats=1)
    return baselines


def test_negative_and_open_ended_frames_resolve_on_the_pinned_dataset(kitti_selections):
    """The pinned selection was resolved on max(frames the result ran) + 1 frames, not the dataset's 10: ``":-2"``
    refused the identical run ("[0..5] (pinned :-2: [0..5])") and ``"-3:"`` accepted frames 0:3 (the last 3 of 0:3)."""
    from conftest import shared_path

    from lidarkit.io.kitti import KittiOdometry
    from lidarkit.odometry import run

    sequence = KittiOdometry(shared_path("kitti_odometry"), sequence="00")
    pick = dict(method="kiss", metric="ape_rmse_m", tolerance=1.0)
    assert_no_worse_than(run(sequence, "kiss", frames=":-2"), kitti_selections[":-2"], **pick)
    assert_no_worse_than(run(sequence, "kiss", frames="7:10"), kitti_selections["-3:"], **pick)
    with pytest.raises(EvaluationError, match=r"the result's frames differ from the pinned job 'kiss': 0-2 \(pinned -3:: 7-9\)$"):
        assert_no_worse_than(run(sequence, "kiss", frames="0:3"), kitti_selections["-3:"], **pick)


def test_a_run_scored_against_another_ground_truth_file_is_refused(kitti_selections):
    """KITTI 00 scored against poses_semantickitti.txt (APE 0.064 m) passed against the job pinned with poses/00.txt
    (0.673 m): only the options both the spec and the run named were compared, and neither names the poses file."""
    from conftest import shared_path

    from lidarkit.io.kitti import KittiOdometry
    from lidarkit.odometry import run

    root = shared_path("kitti_odometry")
    other = root / "sequences" / "00" / "poses_semantickitti.txt"
    result = run(KittiOdometry(root, sequence="00", poses_file=other), "kiss", frames="7:10")
    # (the pinned side is the path the pinned dataset opens, links resolved: ../shared may be a link)
    with pytest.raises(EvaluationError, match=rf"the result's dataset differs from the pinned job 'kiss': poses_path "
                                              rf"'{re.escape(str(other))}' \(pinned '[^']*/kitti_odometry/poses/00\.txt'\)"):
        assert_no_worse_than(result, kitti_selections["-3:"], method="kiss", metric="ape_rmse_m", tolerance=1.0)


def test_two_experiments_of_one_method_on_one_dataset_are_told_apart(tmp_path):
    """``job("random_walk", "synth", 0)`` over two experiments raised "2 pinned jobs match" with no way to name the
    experiment (in assert_no_worse_than neither)."""
    (tmp_path / "suite.yaml").write_text(textwrap.dedent("""
        name: two
        experiments:
          - {name: walk, task: selftest, dataset: {kind: synthetic, name: synth}, methods: [{name: random_walk, params: {steps: 40}}]}
          - {name: long, task: selftest, dataset: {kind: synthetic, name: synth}, methods: [{name: random_walk, params: {steps: 40}}]}
    """))
    baseline = record(tmp_path / "suite.yaml", tmp_path / "baseline", repeats=1)
    with pytest.raises(ConfigError, match=r"2 pinned jobs match method='random_walk', dataset='synth', seed=0: pick one "
                                          r"with experiment= \(walk, long\)$"):
        baseline.job("random_walk", "synth", 0)
    assert baseline.job("random_walk", experiment="long", task="selftest")["spec"]["experiment"] == "long"
    ape = baseline.metrics("random_walk", experiment="walk")["ape_rmse_m"]
    assert_no_worse_than({"ape_rmse_m": ape}, baseline, metric="ape_rmse_m", experiment="walk", tolerance=0.0)
    with pytest.raises(DataError, match="0 pinned jobs match method='random_walk', task='icp_pair'"):
        baseline.job("random_walk", task="icp_pair")


def test_the_wrong_kind_of_arguments_are_refused(tiny_baseline, tmp_path):
    """A plain mapping as the baseline ignored ``method='no-such', seed=42``; ``atol_m=True`` was taken as 1 m; a failed
    bench record read as "metric 'ape_rmse_m' not in the result (it has: )"."""
    from lidarkit.bench.results import load_results
    from lidarkit.bench.runner import run_suite
    from lidarkit.bench.suite import load_suite

    with pytest.raises(ConfigError, match="method, seed pick a job of a baseline folder; the baseline given is a plain dict"):
        assert_no_worse_than({"ape_rmse_m": 0.1}, {"ape_rmse_m": 0.2}, metric="ape_rmse_m", method="no-such", seed=42)
    with pytest.raises(ConfigError, match="atol_m must be a finite number >= 0, got True"):
        assert_trajectory_close(walk(), walk(), atol_m=True)
    (tmp_path / "fails.yaml").write_text(textwrap.dedent(SUITE).replace("- {name: random_walk, params: {steps: 40, noise_m: 0.05}}",
                                                                         "- fail"))
    run_suite(load_suite(tmp_path / "fails.yaml"), tmp_path / "results", executor="serial")
    failed = load_results(tmp_path / "results")[0]
    with pytest.raises(EvaluationError, match="^assert_no_worse_than: the job failed: RuntimeError: selftest failure$"):
        assert_no_worse_than(failed, tiny_baseline, metric="ape_rmse_m")


def test_a_changed_simulator_default_is_a_changed_protocol_not_a_regression(tmp_path, monkeypatch):
    """The manifest hashed the suite's simulator settings only and assert_no_worse_than rebuilt the rest from today's
    defaults: a lidarkit whose default range noise became 0.05 m read as "regression: ... ape_rmse_m" in check, and
    a run on the noisier sensor passed assert_no_worse_than as the pinned data."""
    from collections import OrderedDict

    import lidarkit.sim.lidar as lidar_module
    from lidarkit.bench import baseline as baseline_module
    from lidarkit.bench.tasks import _datasets
    from lidarkit.odometry import run

    (tmp_path / "suite.yaml").write_text(textwrap.dedent("""
        name: seeded
        experiments:
          - name: sim
            task: odometry
            dataset: {kind: sim_lidar, scene: street, n_frames: 8, n_beams: 16, n_azimuths: 360, name: sim}
            seeds: [3]
            methods: [kiss]
    """))
    baseline = record(tmp_path / "suite.yaml", tmp_path / "baseline", repeats=1)
    pinned = baseline.job("kiss")["protocol"]["simulation"]
    assert (pinned["range_noise_std_m"], pinned["seed"], pinned["n_beams"]) == (0.0, 3, 16)
    drive = dict(scene="street", n_frames=8, n_beams=16, n_azimuths=360, seed=3)
    same = run(lidar_module.SimulatedLidarSequence(**drive), "kiss")
    assert_no_worse_than(same, baseline, method="kiss", metric="ape_rmse_m", tolerance=1e-9)
    make_config = lidar_module.make_config
    monkeypatch.setattr(lidar_module, "make_config", lambda **p: make_config(**{"range_noise_std_m": 0.05, **p}))
    monkeypatch.setattr(_datasets, "_CACHE", OrderedDict())  # (the simulator record opened, with the old default)
    result = baseline_module.check(baseline.path)
    assert [line for line in result.lines() if not line.startswith("note:")] == [
        "protocol changed: kiss on sim (seed 3): simulation.range_noise_std_m: 0.0 -> 0.05"]
    noisier = run(lidar_module.SimulatedLidarSequence(**drive), "kiss")
    with pytest.raises(EvaluationError, match=r"dataset differs from the pinned job 'kiss': range_noise_std_m 0.05 \(pinned 0.0\)"):
        assert_no_worse_than(noisier, baseline, method="kiss", metric="ape_rmse_m", tolerance=1.0)


def test_a_frame_check_count_under_other_thresholds_is_refused(tmp_path):
    """kiss (voxel 4 m) with 3 bad frames failed against the pinned 0 under the default frame check, and passed once
    its thresholds were loosened; kiss itself under min_fitness 0.99 read "regression: n_bad_frames = 5, baseline 0"."""
    import json

    from conftest import kiss_on_kitti_00_suite, shared_path

    from lidarkit.io.kitti import KittiOdometry
    from lidarkit.odometry import run

    baseline = record(kiss_on_kitti_00_suite(tmp_path, "2:8"), tmp_path / "baseline", repeats=1)
    sequence = KittiOdometry(shared_path("kitti_odometry"), sequence="00")
    pick = dict(method="kiss", metric="n_bad_frames")
    with pytest.raises(AssertionError, match=r"^regression: n_bad_frames = 3, baseline 0 "):
        assert_no_worse_than(run(sequence, "kiss", params={"voxel_size_m": 4.0}, frames="2:8"), baseline, **pick)
    loose = {"max_accel_mps2": 1e6, "max_angular_accel_dps2": 1e6, "min_fitness": 0.01}
    worse = run(sequence, "kiss", params={"voxel_size_m": 4.0}, frames="2:8", frame_check=loose)
    assert worse.n_bad_frames == 0 and worse.config["run"]["frame_check"]["min_fitness"] == 0.01
    with pytest.raises(EvaluationError, match=r"^assert_no_worse_than: the result's frame check differs from the pinned job "
                                              r"'kiss': max_accel_mps2 1000000.0 \(pinned 15.0\), max_angular_accel_dps2 1000000.0 "
                                              r"\(pinned 300.0\), min_fitness 0.01 \(pinned 0.3\) \(n_bad_frames counts under other "
                                              r"thresholds\)$"):
        assert_no_worse_than(worse, baseline, **pick)
    strict = run(sequence, "kiss", frames="2:8", frame_check={"min_fitness": 0.99})
    with pytest.raises(EvaluationError, match=r"'kiss': min_fitness 0.99 \(pinned 0.3\) \(n_bad_frames counts"):
        assert_no_worse_than(strict, baseline, **pick)
    assert_no_worse_than(strict, baseline, method="kiss", metric="ape_rmse_m")  # the poses do not depend on the check
    assert_no_worse_than(baseline.job("kiss"), baseline, **pick)  # a pinned job's mapping: its own thresholds
    # a baseline recorded before the thresholds were pinned is held under today's defaults
    manifest = json.loads((baseline.path / "manifest.json").read_text())
    del manifest["jobs"][0]["protocol"]["frame_check"]
    (baseline.path / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(EvaluationError, match=r"'kiss': min_fitness 0.99 \(pinned 0.3\)"):
        assert_no_worse_than(strict, baseline.path, **pick)
    assert_no_worse_than(run(sequence, "kiss", frames="2:8"), baseline.path, **pick)


def test_round_off_is_a_tie_at_tolerance_zero(tiny_baseline):
    """0.1 + 0.2 against 0.3 failed at tolerance 0 with "ape_rmse_m = 0.3, baseline 0.3 (worse by 5.551e-17, tolerance
    0)" (kiss rerun against its own pinned job: "worse by 2.082e-16"); ``baseline check`` counts round-off as a tie."""
    assert_no_worse_than({"ape_rmse_m": 0.1 + 0.2}, {"ape_rmse_m": 0.3}, metric="ape_rmse_m")
    ape = tiny_baseline.metrics("random_walk")["ape_rmse_m"]
    assert_no_worse_than({"ape_rmse_m": ape * (1 + 1e-15)}, tiny_baseline, metric="ape_rmse_m", tolerance=0)
    with pytest.raises(AssertionError, match=r"^regression: ape_rmse_m = 0.3003, baseline 0.3 \(worse by 0.0003, tolerance 0\)$"):
        assert_no_worse_than({"ape_rmse_m": 0.3003}, {"ape_rmse_m": 0.3}, metric="ape_rmse_m")
    with pytest.raises(AssertionError, match=r"^regression: hz = 9.99999, baseline 10"):  # (higher is better)
        assert_no_worse_than({"hz": 9.99999}, {"hz": 10.0}, metric="hz")


def test_a_seed_given_as_text_is_refused(tiny_baseline):
    """``seed="1"`` matched no job and read "0 pinned jobs match method='random_walk', seed='1'; pinned: ... (seed 1)"."""
    assert tiny_baseline.job("random_walk", seed=0)["spec"]["seed"] == 0
    assert tiny_baseline.job("random_walk", seed=np.int64(0))["spec"]["seed"] == 0
    for bad in ("0", 0.0, True):
        with pytest.raises(ConfigError, match=rf"^seed: seed must be an integer, got {re.escape(repr(bad))}$"):
            tiny_baseline.job("random_walk", seed=bad)
    with pytest.raises(ConfigError, match="^seed: seed must be an integer, got '0'$"):
        assert_no_worse_than({"ape_rmse_m": 0.1}, tiny_baseline, metric="ape_rmse_m", method="random_walk", seed="0")


def test_a_missing_baseline_folder_in_pytest_ini_is_one_line_per_test(tmp_path):
    """``lidarkit_baseline = nothere`` in pytest.ini printed a 51-line traceback through the plugin for each test
    using the fixture; now one line names the folder, the reason and where it was set."""
    (tmp_path / "pytest.ini").write_text("[pytest]\nlidarkit_baseline = nothere\n")
    (tmp_path / "test_user.py").write_text("def test_a(lidarkit_baseline):\n    pass\n")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}
    from importlib.metadata import entry_points

    installed = any(ep.value == "lidarkit.testing.plugin" for ep in entry_points(group="pytest11"))
    load = [] if installed else ["-p", "lidarkit.testing.plugin"]
    proc = subprocess.run([sys.executable, "-m", "pytest", "-q", *load, "-p", "no:cacheprovider", "-W", "ignore", "test_user.py"],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert "1 error" in proc.stdout, proc.stdout + proc.stderr
    errors = proc.stdout.split("ERROR at setup of test_a")[1].split("short test summary")[0]
    assert errors.strip().splitlines()[1:-1] == [
        f"{tmp_path / 'nothere'}: baseline folder does not exist (set by lidarkit_baseline in {tmp_path / 'pytest.ini'})"]
    assert "Traceback" not in proc.stdout and "baseline.py" not in proc.stdout


def test_a_bench_record_of_the_pinned_data_written_another_way_passes(tmp_path):
    """Bench records that ran on exactly the pinned data were refused as another dataset: a simulated drive with
    ``range_noise_std_m: 0.0`` (its default) written out, and KITTI 00 given as ``sequences/00`` or ``sequence: "00"``
    against a root pinned with ``sequence: 0``; the specs were compared as written (compare pairs them)."""
    from conftest import shared_path

    from lidarkit.bench.results import load_results
    from lidarkit.bench.runner import run_suite
    from lidarkit.bench.suite import load_suite

    root = shared_path("kitti_odometry")
    vanilla = "methods: [{name: vanilla, params: {voxel_size_m: 1.0}}]"
    sim = "{kind: sim_lidar, scene: street, n_frames: 4, n_beams: 16, n_azimuths: 360, seed: 0%s, name: s4}"
    (tmp_path / "pinned.yaml").write_text(textwrap.dedent(f"""
        name: pinned
        experiments:
          - {{name: sim, task: odometry, dataset: {sim % ""}, {vanilla}}}
          - {{name: kitti, task: odometry, dataset: {{kind: kitti, path: "{root}", sequence: 0, name: K00}},
             options: {{frames: "0:3"}}, {vanilla}}}
    """))
    baseline = record(tmp_path / "pinned.yaml", tmp_path / "baseline", repeats=1)
    (tmp_path / "written.yaml").write_text(textwrap.dedent(f"""
        name: written-another-way
        experiments:
          - {{name: sim, task: odometry, dataset: {sim % ", range_noise_std_m: 0.0"}, {vanilla}}}
          - {{name: folder, task: odometry, dataset: {{kind: kitti, path: "{root / 'sequences' / '00'}", name: K00}},
             options: {{frames: "0:3"}}, {vanilla}}}
          - {{name: text, task: odometry, dataset: {{kind: kitti, path: "{root}", sequence: "00", name: K00}},
             options: {{frames: "0:3"}}, {vanilla}}}
    """))
    run_suite(load_suite(tmp_path / "written.yaml"), tmp_path / "results", executor="serial")
    records = {r["job"]["experiment"]: r for r in load_results(tmp_path / "results")}
    for experiment, pinned in (("sim", "sim"), ("folder", "kitti"), ("text", "kitti")):
        assert records[experiment]["status"] == "ok", records[experiment].get("error")
        assert_no_worse_than(records[experiment], baseline, experiment=pinned, metric="ape_rmse_m", tolerance=1e-6)
    # another sensor, or another sequence, is still another dataset
    sim_job, kitti_job = records["sim"]["job"], records["text"]["job"]
    noisier = {**records["sim"], "job": {**sim_job, "dataset": {**sim_job["dataset"], "range_noise_std_m": 0.05}}}
    with pytest.raises(EvaluationError, match=r"the result's job dataset differs from the pinned job "
                                              r"'vanilla\(voxel_size_m=1\)': range_noise_std_m 0\.05 \(pinned 0\.0\)$"):
        assert_no_worse_than(noisier, baseline, experiment="sim", metric="ape_rmse_m", tolerance=1.0)
    other_sequence = {**records["text"], "job": {**kitti_job, "dataset": {**kitti_job["dataset"], "sequence": "01"}}}
    with pytest.raises(EvaluationError, match=r"the result's job dataset differs from the pinned job .*: path .*sequence '01' "
                                              r"\(pinned <absent>\)"):
        assert_no_worse_than(other_sequence, baseline, experiment="kitti", metric="ape_rmse_m", tolerance=1.0)



def test_a_bench_record_over_the_pinned_frames_written_another_way_passes(tmp_path):
    """Pinned over frames "0:3" of KITTI 00: bench records over ":3", "0:3:1" or [0, 1, 2], the same three scans, were
    refused ("the result's job options differs from the pinned job ...: {'frames': ':3'} (pinned {'frames': '0:3'})"):
    the options were compared as written. They are compared as the frames they select, as compare pairs runs."""
    from conftest import shared_path

    from lidarkit.bench.results import load_results
    from lidarkit.bench.runner import run_suite
    from lidarkit.bench.suite import load_suite

    dataset = f'{{kind: kitti, path: "{shared_path("kitti_odometry")}", sequence: 0, name: K00}}'
    vanilla = "methods: [{name: vanilla, params: {voxel_size_m: 1.0}}]"
    (tmp_path / "pinned.yaml").write_text(textwrap.dedent(f"""
        name: pinned
        experiments:
          - {{name: kitti, task: odometry, dataset: {dataset}, options: {{frames: "0:3"}}, {vanilla}}}
    """))
    baseline = record(tmp_path / "pinned.yaml", tmp_path / "baseline", repeats=1)
    (tmp_path / "written.yaml").write_text(textwrap.dedent(f"""
        name: frames-written-another-way
        experiments:
          - {{name: open, task: odometry, dataset: {dataset}, options: {{frames: ":3"}}, {vanilla}}}
          - {{name: step, task: odometry, dataset: {dataset}, options: {{frames: "0:3:1"}}, {vanilla}}}
          - {{name: list, task: odometry, dataset: {dataset}, options: {{frames: [0, 1, 2]}}, {vanilla}}}
          - {{name: later, task: odometry, dataset: {dataset}, options: {{frames: "1:4"}}, {vanilla}}}
    """))
    run_suite(load_suite(tmp_path / "written.yaml"), tmp_path / "results", executor="serial")
    records = {r["job"]["experiment"]: r for r in load_results(tmp_path / "results")}
    for experiment in ("open", "step", "list"):
        assert records[experiment]["status"] == "ok", records[experiment].get("error")
        assert_no_worse_than(records[experiment], baseline, metric="ape_rmse_m", tolerance=1e-6)
    # three other scans of the sequence are still other data
    with pytest.raises(EvaluationError, match=r"^assert_no_worse_than: the result's job options differ from the pinned job "
                                              r"'vanilla\(voxel_size_m=1\)': \{'frames': '1:4'\} \(pinned \{'frames': '0:3'\}\)$"):
        assert_no_worse_than(records["later"], baseline, metric="ape_rmse_m", tolerance=1.0)

def test_a_missing_drift_metric_says_why_and_none_values_are_named_apart():
    """A run shorter than the devkit's 100 m segments has no drift: the message said only "not in the result" though
    the result records why; a mapping holding the metric as None read "(it has: )"."""
    from lidarkit.odometry import run

    short = run("sim:street?frames=3&beams=8&azimuths=90", "vanilla")
    note = short.metrics["kitti_drift_note"]
    assert "shorter than the shortest devkit segment (100 m)" in note
    with pytest.raises(EvaluationError) as err:
        assert_no_worse_than(short, {"drift_translation_pct": 1.0})
    assert str(err.value).endswith(f"; KITTI drift not computed: {note}")
    assert "metric 'drift_translation_pct' not in the result (it has: ape_rmse_m, " in str(err.value)
    with pytest.raises(EvaluationError) as err:  # a bench record keeps the note with its odometry metrics
        assert_no_worse_than({"status": "ok", "metrics": {"ape_rmse_m": 0.1}, "info": {"odometry_metrics": short.metrics}},
                             {"drift_translation_pct": 1.0})
    assert str(err.value) == ("assert_no_worse_than: metric 'drift_translation_pct' not in the result (it has: ape_rmse_m); "
                              f"KITTI drift not computed: {note}")
    with pytest.raises(EvaluationError) as err:
        assert_no_worse_than({"drift_translation_pct": None}, {"drift_translation_pct": 1.0})
    assert str(err.value) == ("assert_no_worse_than: metric 'drift_translation_pct' not in the result (it has no numeric "
                              "metric; present but None: drift_translation_pct)")
    with pytest.raises(EvaluationError) as err:  # (not a drift metric: no drift note)
        assert_no_worse_than({"ape_rmse_m": 0.1}, {"ape_rmse_m": None, "hz": 10}, metric="ape_rmse_m")
    assert str(err.value) == ("assert_no_worse_than: metric 'ape_rmse_m' not in the baseline (it has: hz; present but None: "
                              "ape_rmse_m)")


def test_the_documented_baseline_loaders_work_as_docs_regression_md_says(tiny_baseline, tmp_path):
    """docs/regression.md presented the plugin's ``load_lidarkit_baseline`` fixture as a function, and
    ``from lidarkit.testing import load_lidarkit_baseline`` failed: outside pytest the page now imports ``load_baseline``
    from lidarkit.testing."""
    from lidarkit.bench import baseline as bench_baseline
    from lidarkit.testing import load_baseline

    assert load_baseline is bench_baseline.load_baseline
    loaded = load_baseline(tiny_baseline.path)
    assert loaded.metrics("random_walk") == tiny_baseline.metrics("random_walk")
    with pytest.raises(DataError, match="baseline folder does not exist"):
        load_baseline(tmp_path / "nothere")
    import lidarkit.testing

    assert "load_baseline" in lidarkit.testing.__all__
    page = (REPO / "docs" / "regression.md").read_text()
    imports = set(re.findall(r"from lidarkit\.testing import \w+(?:, \w+)*", page))
    assert "from lidarkit.testing import load_baseline" in imports
    for statement in imports:  # every import the page writes, in prose or in an example, runs
        exec(statement, {})
