"""Golden baselines pin what a job reads and runs under: the files its task options name, its task options with their
defaults, never the baseline's own files; pinned labels are found as compare finds them."""

from __future__ import annotations

import copy
import json
import shutil
import textwrap
from pathlib import Path

import pytest

from lidarkit.bench.baseline import check, dataset_checksums, record
from lidarkit.errors import DataError, OutputError


def _pair_data(root: Path) -> tuple[Path, Path]:
    """The bundled KITTI pair's two scans in ``root/data/pair``, its ground truth kept apart in ``root/gt/T.txt``."""
    from lidarkit.bench.datasets import sample_path

    sample = sample_path("kitti_pair")
    data = root / "data" / "pair"
    data.mkdir(parents=True)
    for name in ("000094.npy", "000095.npy"):
        shutil.copy(sample / name, data / name)
    (root / "gt").mkdir()
    shutil.copy(sample / "T_target_source.txt", root / "gt" / "T.txt")
    return data, root / "gt" / "T.txt"


def _pair_suite(root: Path, data: Path, ground_truth: str) -> Path:
    suite = root / "pair.yaml"
    suite.write_text(textwrap.dedent(f"""
        name: pair
        experiments:
          - name: pair
            task: icp_pair
            dataset: {{kind: folder, path: "{data}", name: pair}}
            options: {{pairs: [[0, 1]], ground_truth_file: "{ground_truth}"}}
            methods: [{{name: vanilla, params: {{voxel_size_m: 1.0}}}}]
    """))
    return suite


@pytest.fixture(scope="module")
def pair_baseline(tmp_path_factory):
    """vanilla on the KITTI pair, scored against a ground truth kept outside the dataset folder (``../../gt/T.txt``)."""
    root = tmp_path_factory.mktemp("pair")
    data, _ = _pair_data(root)
    return record(_pair_suite(root, data, "../../gt/T.txt"), root / "baseline", repeats=1)


def test_an_edited_ground_truth_file_outside_the_data_is_a_changed_protocol(pair_baseline, tmp_path):
    """The icp_pair ground_truth_file was not hashed: edited after record, check read "regression: ...
    translation_error_m" (and the edit undone, an improvement that passed) instead of "protocol changed"."""
    baseline = tmp_path / "baseline"
    shutil.copytree(pair_baseline.path, baseline)
    truth = pair_baseline.path.parent / "gt" / "T.txt"
    assert check(baseline).passed
    original = truth.read_text()
    try:
        truth.write_text(original.replace("4.744355362474e-01", "9.744355362474e-01"))  # 0.5 m more forward motion
        lines = check(baseline).lines()
    finally:
        truth.write_text(original)
    assert [line.split(" -> ")[0].rsplit(": ", 1)[0] for line in lines] == [
        f"protocol changed: vanilla(voxel_size_m=1) on pair (seed 0): data.{truth}"], lines
    pinned = pair_baseline.jobs[0]["protocol"]  # (named by its path: it lies outside the dataset's parent folder)
    assert list(pinned["option_files"]) == [str(truth)] and list(pinned["checksums"]) == ["pair/000094.npy", "pair/000095.npy"]
    # a baseline recorded before lidarkit hashed the option files: not compared on them, and said once
    manifest = json.loads((baseline / "manifest.json").read_text())
    del manifest["jobs"][0]["protocol"]["option_files"]
    (baseline / "manifest.json").write_text(json.dumps(manifest))
    result = check(baseline)
    assert result.passed and [line for line in result.lines() if "option" in line] == [
        "note: vanilla(voxel_size_m=1) on pair (seed 0): the baseline pinned no checksum of the files its task options name "
        f"({truth}; recorded before lidarkit hashed them): not compared; record it again to pin them"]


def test_a_changed_task_option_default_is_a_changed_protocol(tmp_path, monkeypatch):
    """A later lidarkit starting the pf MSE at step 0 (default 10) read as a regression of the filter: the manifest pinned
    the options as written ({}), not the defaults they ran under."""
    from conftest import shared_path

    import lidarkit.bench.tasks.pf as pf_task

    (tmp_path / "pf.yaml").write_text(textwrap.dedent(f"""
        name: pf
        experiments:
          - name: pf
            task: pf
            dataset: {{kind: landmarks, path: "{shared_path('pf', 'robot_mapping_stachniss')}", name: Freiburg}}
            methods: [{{name: particle_filter, params: {{n_particles: 50}}}}]
    """))
    baseline = record(tmp_path / "pf.yaml", tmp_path / "baseline", repeats=1)
    changed = copy.copy(pf_task.PFOptions.model_fields["mse_start"])
    changed.default = 0
    monkeypatch.setitem(pf_task.PFOptions.model_fields, "mse_start", changed)
    pf_task.PFOptions.model_rebuild(force=True)
    try:
        assert pf_task.PFOptions().mse_start == 0
        lines = [line for line in check(baseline.path).lines() if not line.startswith("note:")]
        assert lines == ["protocol changed: particle_filter(n_particles=50) on Freiburg (seed 0): task_options.mse_start: "
                         "10 -> 0"]
        manifest = json.loads((baseline.path / "manifest.json").read_text())
        del manifest["jobs"][0]["protocol"]["task_options"]  # recorded before lidarkit pinned them: not compared
        (baseline.path / "manifest.json").write_text(json.dumps(manifest))
        unpinned = check(baseline.path).lines()
    finally:
        monkeypatch.undo()
        pf_task.PFOptions.model_rebuild(force=True)
    assert baseline.jobs[0]["protocol"]["task_options"] == {"visible": "recorded", "mse_start": 10}
    assert not any(line.startswith("protocol changed") for line in unpinned), unpinned


def test_the_icp_pair_options_are_pinned_with_their_defaults(pair_baseline):
    """max_pairs and the initial-noise sizes left at their defaults are pinned as they ran."""
    assert pair_baseline.jobs[0]["protocol"]["task_options"] == {
        "pairs": [[0, 1]], "ground_truth_file": "../../gt/T.txt", "max_pairs": 1, "init_noise_m": 0.0, "init_noise_deg": 0.0}


def test_a_baseline_inside_the_dataset_folder_is_refused_and_never_hashed(tmp_path):
    """--out inside the pinned dataset folder pinned the baseline's own files: its check read "protocol changed:
    data.pair/bl/manifest.json: <absent> -> ..." forever. record refuses it; a baseline already written there is left out
    of the checksums."""
    data, truth = _pair_data(tmp_path)
    suite = _pair_suite(tmp_path, data, str(truth))
    with pytest.raises(OutputError) as caught:
        record(suite, data / "bl", repeats=1)
    assert str(caught.value) == (f"{data / 'bl'}: inside the dataset folder {data} of the job pair: vanilla(voxel_size_m=1) on "
                                 "pair (seed 0): the baseline would pin its own files as the job's data (its check always "
                                 "reads 'protocol changed'); choose a folder outside the data")
    assert not (data / "bl").exists()
    spec = {"kind": "folder", "path": str(data), "name": "pair"}
    before = dataset_checksums(spec)
    written = record(suite, tmp_path / "bl", repeats=1)
    shutil.copytree(written.path, data / "old_baseline")  # one written there before record refused it
    assert dataset_checksums(spec) == before == {"pair/000094.npy": before["pair/000094.npy"],
                                                 "pair/000095.npy": before["pair/000095.npy"]}


def test_a_label_written_otherwise_finds_the_pinned_job(pair_baseline, tmp_path):
    """``job('vanilla(voxel_size_m=1.0)')`` found no ``vanilla(voxel_size_m=1)``, ``kiss(deskew=false)`` no
    ``kiss(deskew=False)``: compare reads labels as bench writes them, and so does the baseline."""
    for asked in ("vanilla(voxel_size_m=1.0)", "vanilla(voxel_size_m=1.00)", "vanilla( voxel_size_m=1 )"):
        assert pair_baseline.job(asked)["label"] == "vanilla(voxel_size_m=1)"
    manifest = json.loads((pair_baseline.path / "manifest.json").read_text())
    kiss = copy.deepcopy(manifest["jobs"][0])
    kiss.update(key="kiss-job", label="kiss(deskew=False)")
    kiss["spec"].update(method="kiss", params={"deskew": False})
    manifest["jobs"].append(kiss)
    edited = tmp_path / "edited"
    edited.mkdir()
    (edited / "manifest.json").write_text(json.dumps(manifest))
    from lidarkit.bench.baseline import load_baseline

    assert load_baseline(edited).job("kiss(deskew=false)")["key"] == "kiss-job"
    with pytest.raises(DataError, match="0 pinned jobs match method='kiss\\(deskew=true\\)'"):
        load_baseline(edited).job("kiss(deskew=true)")


def test_a_suite_file_that_is_a_loop_of_links_is_one_line(tmp_path):
    """A suite path that is a loop of symbolic links raised "RuntimeError: Symlink loop" from pathlib, in ``record`` and in
    the copy of the suite it writes into the baseline folder."""
    from lidarkit.bench.baseline import suite_copy_text

    (tmp_path / "l1.yaml").symlink_to(tmp_path / "l2.yaml")
    (tmp_path / "l2.yaml").symlink_to(tmp_path / "l1.yaml")
    message = f"{tmp_path / 'l1.yaml'}: cannot read it: a loop of symbolic links (a link that leads back to itself)"
    for call in (lambda: record(tmp_path / "l1.yaml", tmp_path / "bl", repeats=1), lambda: suite_copy_text(tmp_path / "l1.yaml")):
        with pytest.raises(DataError) as caught:
            call()
        assert str(caught.value) == message
    assert not (tmp_path / "bl").exists()


def test_the_vo_and_odometry_options_are_pinned_with_their_defaults():
    """VO's align, smoothed and max_frames (and odometry's frames) left at their defaults were pinned as written: a
    later default read as a regression of the method."""
    from lidarkit.bench.tasks import get_task

    assert get_task("vo").resolved_options({}) == {"max_frames": None, "align": "auto", "smoothed": False}
    assert get_task("vo").resolved_options({"smoothed": True})["smoothed"] is True
    assert get_task("odometry").resolved_options({}) == {"frames": None, "init": "constant_velocity"}


def test_a_ros2_bag_given_as_its_metadata_file_pins_the_whole_bag(tmp_path):
    """A ROS 2 bag given as ``BAG/metadata.yaml`` (the reader opens the folder) was hashed as metadata.yaml alone: other
    scans in its storage file read as a regression of the method. Its folder's files are pinned, as the folder given
    itself; --out inside the bag is refused; a run on the bag (the folder or its metadata.yaml) is the pinned data."""
    from lidarkit.odometry import run
    from lidarkit.sim.bag_export import export_bag
    from lidarkit.sim.lidar import SimulatedLidarSequence
    from lidarkit.testing import assert_no_worse_than

    def bag(folder: Path, seed: int) -> Path:
        return export_bag(SimulatedLidarSequence(n_frames=6, n_beams=16, n_azimuths=360, seed=seed), folder, "rosbag2")

    pinned, other = bag(tmp_path / "drive", 0), bag(tmp_path / "other", 1)
    suite = tmp_path / "bag.yaml"
    suite.write_text(textwrap.dedent(f"""
        name: bag
        experiments:
          - {{name: bag, task: odometry, dataset: {{kind: rosbag, path: "{pinned / 'metadata.yaml'}", name: bag}}, methods: [kiss]}}
    """))
    spec = {"kind": "rosbag", "path": str(pinned / "metadata.yaml")}
    assert dataset_checksums(spec) == dataset_checksums({"kind": "rosbag", "path": str(pinned)})
    assert sorted(dataset_checksums(spec)) == ["drive/bag.db3", "drive/metadata.yaml"]
    with pytest.raises(OutputError, match="inside the dataset folder"):
        record(suite, pinned / "baseline", repeats=1)
    baseline = record(suite, tmp_path / "baseline", repeats=1)
    assert check(baseline.path).passed
    for given in (pinned, pinned / "metadata.yaml"):
        assert_no_worse_than(run(f"rosbag:{given}", "kiss"), baseline, metric="ape_rmse_m")
    shutil.copy(other / "bag.db3", pinned / "bag.db3")  # other scans, the same metadata
    lines = check(baseline.path).lines()
    assert [line.split(" -> ")[0].rsplit(": ", 1)[0] for line in lines if not line.startswith("note:")] == [
        "protocol changed: kiss on bag (seed 0): data.drive/bag.db3"], lines
