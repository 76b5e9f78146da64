"""What a baseline holds a job on, and nothing more: the files its task reads of a KITTI sequence (camera images added
beside the scans voided a LiDAR job), the number of frames it scored, its accuracy metrics (not an ICP's final RMSE or
iteration count), the versions of the packages it runs on (an OpenCV version voided a LiDAR job), and a task
registered in code, whose module a check imports."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from conftest import shared_path

from lidarkit.bench.baseline import check, checked_metrics, dataset_checksums, environment, opencv_version, record


def _kitti_copy(root: Path, n_scans: int = 3) -> Path:
    """``root``: KITTI 00's first ``n_scans`` scans with its calib, times, poses and SemanticKITTI poses."""
    source = shared_path("kitti_odometry")
    sequence = root / "sequences" / "00"
    (sequence / "velodyne").mkdir(parents=True)
    for name in ("calib.txt", "times.txt", "poses_semantickitti.txt"):
        shutil.copy(source / "sequences" / "00" / name, sequence / name)
    for i in range(n_scans):
        shutil.copy(source / "sequences" / "00" / "velodyne" / f"{i:06d}.bin", sequence / "velodyne" / f"{i:06d}.bin")
    (root / "poses").mkdir()
    shutil.copy(source / "poses" / "00.txt", root / "poses" / "00.txt")
    return root


@pytest.fixture(scope="module")
def kitti_baseline(tmp_path_factory):
    """vanilla over the 3 scans of a KITTI 00 copy, pinned once (repeats 1); each test checks a copy of the data."""
    folder = tmp_path_factory.mktemp("kitti_baseline")
    root = _kitti_copy(folder / "kd")
    (folder / "suite.yaml").write_text(textwrap.dedent(f"""
        name: kd
        experiments:
          - name: k
            task: odometry
            dataset: {{kind: kitti, path: "{root}", sequence: 0, name: k00}}
            options: {{frames: "0:3"}}
            methods: [{{name: vanilla, params: {{voxel_size_m: 1.0}}}}]
    """))
    return record(folder / "suite.yaml", folder / "baseline", repeats=1)


def test_a_lidar_job_on_kitti_hashes_what_its_reader_reads(kitti_baseline):
    """Every file of the sequence folder was pinned: camera images added later read ``protocol changed: ...
    image_2/000000.png: <absent> -> ...`` (and a full sequence's images were hashed, GBs, for a LiDAR job)."""
    pinned = sorted(kitti_baseline.jobs[0]["protocol"]["checksums"])
    assert pinned == ["kd/poses/00.txt", "kd/sequences/00/calib.txt", "kd/sequences/00/times.txt",
                      *(f"kd/sequences/00/velodyne/{i:06d}.bin" for i in range(3))]
    images = kitti_baseline.jobs[0]["spec"]["dataset"]["path"] + "/sequences/00/image_2"
    Path(images).mkdir()
    try:
        shutil.copy(shared_path("kitti_images", "sequences", "00", "image_0", "000000.png"), Path(images) / "000000.png")
        result = check(kitti_baseline.path)
    finally:
        shutil.rmtree(images)
    assert result.passed and not [line for line in result.lines() if not line.startswith("note: environment")]


def test_the_files_hashed_follow_the_task_and_the_poses_file_in_use(tmp_path):
    """A vo job reads the images, not the scans; a poses_file named: that file, not poses/00.txt."""
    root = _kitti_copy(tmp_path / "kd", n_scans=2)
    shutil.copytree(shared_path("kitti_images", "sequences", "00", "image_0"), root / "sequences" / "00" / "image_0")
    spec = {"kind": "kitti", "path": str(root), "sequence": 0, "name": "k00"}
    assert sorted(dataset_checksums(spec, task="vo")) == [
        "kd/poses/00.txt", "kd/sequences/00/calib.txt", *(f"kd/sequences/00/image_0/{i:06d}.png" for i in range(5)),
        "kd/sequences/00/times.txt"]
    semantic = {**spec, "poses_file": "sequences/00/poses_semantickitti.txt"}
    assert sorted(dataset_checksums(semantic, task="odometry")) == [
        "kd/sequences/00/calib.txt", "kd/sequences/00/poses_semantickitti.txt", "kd/sequences/00/times.txt",
        "kd/sequences/00/velodyne/000000.bin", "kd/sequences/00/velodyne/000001.bin"]


def _copy_with_manifest(baseline, folder: Path, edit) -> Path:
    shutil.copytree(baseline.path, folder)
    manifest = json.loads((folder / "manifest.json").read_text())
    edit(manifest)
    (folder / "manifest.json").write_text(json.dumps(manifest))
    return folder


def test_an_earlier_baseline_of_the_whole_sequence_folder_is_compared_on_the_files_read(kitti_baseline, tmp_path):
    """A baseline recorded when the whole folder was hashed pins files the job does not read (SemanticKITTI's poses, an
    image edited since): not compared, said in a note; a scan it reads still is."""
    def as_recorded_before(manifest):
        manifest["jobs"][0]["protocol"]["checksums"].update({
            "kd/sequences/00/poses_semantickitti.txt": "0" * 64, "kd/sequences/00/image_2/000000.png": "1" * 64})

    earlier = _copy_with_manifest(kitti_baseline, tmp_path / "earlier", as_recorded_before)
    result = check(earlier)
    assert result.passed, result.lines()
    assert ("note: vanilla(voxel_size_m=1) on k00 (seed 0): the baseline pinned 2 files its odometry job does not read "
            "(kd/sequences/00/image_2/000000.png, kd/sequences/00/poses_semantickitti.txt; recorded when lidarkit hashed "
            "the whole sequence folder): not compared") in result.lines()

    def scan_edited(manifest):
        as_recorded_before(manifest)
        manifest["jobs"][0]["protocol"]["checksums"]["kd/sequences/00/velodyne/000001.bin"] = "2" * 64

    result = check(_copy_with_manifest(kitti_baseline, tmp_path / "scan", scan_edited))
    assert not result.passed and any(line.startswith("protocol changed: vanilla(voxel_size_m=1) on k00 (seed 0): "
                                                     "data.kd/sequences/00/velodyne/000001.bin: 2222") for line in result.lines())


def test_a_rerun_over_fewer_frames_than_pinned_fails_naming_both_counts(kitti_baseline, monkeypatch):
    """A lidarkit that scored one frame fewer than asked read as 14 "improved" lines and passed: its metrics are of
    other frames. The count is compared first."""
    import lidarkit.odometry.runner as runner

    every = runner.parse_frames
    monkeypatch.setattr(runner, "parse_frames", lambda frames, n: every(frames, n)[:-1])  # (the regression emulated)
    result = check(kitti_baseline.path)
    assert not result.passed
    assert [line for line in result.lines() if not line.startswith("note:")] == [
        "failed: vanilla(voxel_size_m=1) on k00 (seed 0): scored 2 frames, the baseline 3 (n_frames): its metrics are "
        "of other frames and are not compared"]


PAIR_SUITE = """
    name: pair
    experiments:
      - name: pair
        task: icp_pair
        dataset: {kind: folder, path: "sample:kitti_pair", name: pair}
        options: {pairs: [[0, 1]], ground_truth_file: T_target_source.txt}
        methods: [%s]
      - {name: walk, task: selftest, dataset: {kind: synthetic, name: synth}, methods: [random_walk]}
"""


def test_an_icp_pairs_final_rmse_and_iterations_are_not_held_by_a_baseline(tmp_path):
    """A wider correspondence distance read as a regression of final_rmse_m (0.351 against 0.184) with the pose error in
    band, one more iteration as a regression: they say what the method did, not how well. An earlier baseline that
    pinned them is not checked on them, said in a note."""
    (tmp_path / "pair.yaml").write_text(textwrap.dedent(PAIR_SUITE % "{name: vanilla, params: {voxel_size_m: 1.0}}"))
    baseline = record(tmp_path / "pair.yaml", tmp_path / "baseline", repeats=1)
    pair = next(job for job in baseline.jobs if job["spec"]["task"] == "icp_pair")
    assert {"final_rmse_m", "iterations"} & set(pair["checked"]) == set()
    assert {"translation_error_m", "rotation_error_deg"} <= set(pair["checked"])
    assert "final_rmse_m" not in checked_metrics("icp_pair", {"final_rmse_m": 0.2, "translation_error_m": 0.1})

    def pinned_before(manifest):
        job = next(job for job in manifest["jobs"] if job["spec"]["task"] == "icp_pair")
        job["checked"] += ["final_rmse_m", "iterations"]
        job["metrics"].update(final_rmse_m=0.05, iterations=1)
        job["bands"].update(final_rmse_m=0.001, iterations=1e-9)

    result = check(_copy_with_manifest(baseline, tmp_path / "earlier", pinned_before))
    assert result.passed, result.lines()
    assert ("note: vanilla(voxel_size_m=1) on pair (seed 0): the baseline pinned iterations, final_rmse_m (recorded when "
            "icp_pair declared them accuracy metrics): not checked any more (diagnostic metrics)") in result.lines()


def test_a_package_version_voids_only_the_jobs_that_run_on_it(tmp_path):
    """Another OpenCV or small_gicp version voided every job (kiss on a simulated LiDAR: "protocol changed", FAILED,
    nothing run). It voids the small_gicp job here; the random walk runs and is compared; OpenCV, which no job runs on,
    is a note."""
    (tmp_path / "pair.yaml").write_text(textwrap.dedent(PAIR_SUITE % "small_gicp"))
    baseline = record(tmp_path / "pair.yaml", tmp_path / "baseline", repeats=1)
    now = environment()["packages"]

    def older(manifest):
        manifest["environment"]["packages"].update(opencv="3.4.0", small_gicp="0.0.1")

    result = check(_copy_with_manifest(baseline, tmp_path / "older", older))
    assert not result.passed
    assert [line for line in result.lines() if "lidarkit" not in line] == [
        f"protocol changed: small_gicp on pair (seed 0): packages.small_gicp: 0.0.1 -> {now['small_gicp']}",
        f"note: environment: packages.opencv: 3.4.0 -> {now['opencv']} (no pinned job runs on opencv: not compared)"]
    ran = {job["spec"]["method"] for job in baseline.jobs if job["key"] in result.measured}
    assert ran == {"random_walk"}  # (the small_gicp job is not run: its numbers would not be comparable)
    from lidarkit.bench.baseline import uses_package

    assert uses_package("opencv", {"task": "vo", "dataset": {"kind": "kitti"}})
    assert uses_package("opencv", {"task": "selftest", "dataset": {"kind": "sim_camera"}})
    assert not uses_package("opencv", {"task": "odometry", "method": "kiss", "dataset": {"kind": "sim_lidar"}})


def test_the_opencv_version_is_read_one_way(tmp_path):
    """With one OpenCV distribution the version was the distribution's (5.0.0.93), with two ``cv2.__version__`` (5.0.0):
    installing a second one read as another OpenCV. It is the cv2 folder's own record, OpenCV not imported; a baseline
    that pinned the short form is the same OpenCV."""
    import importlib.util
    import re

    folder = Path(importlib.util.find_spec("cv2").submodule_search_locations[0])
    written = re.search(r'opencv_version = "([^"]+)"', (folder / "version.py").read_text())[1]
    done = subprocess.run([sys.executable, "-c", "import sys; from lidarkit.bench.baseline import opencv_version; "
                           "print(opencv_version(), 'cv2' in sys.modules)"], capture_output=True, text=True, timeout=60)
    assert done.stdout.split() == [written, "False"], done.stderr
    assert opencv_version() == written

    (tmp_path / "walk.yaml").write_text("experiments:\n  - {task: selftest, dataset: {kind: synthetic, name: s}, "
                                        "methods: [random_walk]}\n")
    baseline = record(tmp_path / "walk.yaml", tmp_path / "baseline", repeats=1)
    short = ".".join(written.split(".")[:3])

    def short_form(manifest):
        manifest["environment"]["packages"]["opencv"] = short

    result = check(_copy_with_manifest(baseline, tmp_path / "short", short_form))
    assert result.passed and not [line for line in result.lines() if "opencv" in line]


TASK_MODULE = '''
from lidarkit.bench import Metric, Task, TaskOutput, register_task


@register_task("scope_probe")
class ScopeProbe(Task):
    dataset_kinds = ("synthetic",)
    metrics = (Metric("error_m", "error [m]"),)

    def run(self, job):
        return TaskOutput(metrics={"error_m": 0.1 + 0.001 * job.seed})
'''


def test_a_baseline_of_a_task_registered_in_code_is_checked_from_the_cli(tmp_path):
    """``lidarkit baseline check`` of it read "failed: ...: task: unknown task 'my_task'": the manifest now pins the
    task's module, which a check imports. An earlier baseline without it says how to check it."""
    site = tmp_path / "site"
    site.mkdir()
    (site / "scope_probe_task.py").write_text(TASK_MODULE)
    (tmp_path / "suite.yaml").write_text("experiments:\n  - {task: scope_probe, dataset: {kind: synthetic, name: syn}, "
                                         "methods: [any]}\n")
    script = (f"import sys; sys.path.insert(0, {str(site)!r}); import scope_probe_task; "
              f"from lidarkit.bench.baseline import record; record({str(tmp_path / 'suite.yaml')!r}, "
              f"{str(tmp_path / 'baseline')!r}, repeats=1)")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    manifest = json.loads((tmp_path / "baseline" / "manifest.json").read_text())
    assert manifest["jobs"][0]["task_module"] == {"module": "scope_probe_task", "folder": str(site)}
    cli = [sys.executable, "-m", "lidarkit", "baseline", "check"]
    done = subprocess.run([*cli, str(tmp_path / "baseline")], capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert done.returncode == 0 and "baseline check passed: 1 pinned jobs" in done.stdout, done.stdout + done.stderr

    del manifest["jobs"][0]["task_module"]  # (an earlier baseline; checked here, where the task is not imported either)
    (tmp_path / "baseline" / "manifest.json").write_text(json.dumps(manifest))
    result = check(tmp_path / "baseline")
    assert not result.passed and result.lines()[0] == (
        "failed: any on syn (seed 0): task 'scope_probe' is not known here and the baseline names no module defining "
        "it (recorded before lidarkit pinned a task's module): import the module that registers it and call "
        "lidarkit.bench.baseline.check() from Python, or record the baseline again")
