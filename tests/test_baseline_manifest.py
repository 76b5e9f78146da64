"""A baseline's manifest and files edited or damaged by hand: one line naming the field and why, never a traceback or
a finding that reads as the method's."""

from __future__ import annotations

import json
import shutil
import textwrap

import pytest

from lidarkit.bench.baseline import check, load_baseline, record
from lidarkit.errors import DataError

SUITE = """
    name: sim
    experiments:
      - name: drive
        task: odometry
        dataset: {kind: sim_lidar, n_frames: 4, n_beams: 16, n_azimuths: 360, name: sim}
        methods: [vanilla]
"""


@pytest.fixture(scope="module")
def pinned(tmp_path_factory):
    root = tmp_path_factory.mktemp("pinned")
    (root / "suite.yaml").write_text(textwrap.dedent(SUITE))
    return record(root / "suite.yaml", root / "baseline", repeats=1)


def _edited_copy(pinned, folder, edit):
    shutil.copytree(pinned.path, folder)
    manifest = json.loads((folder / "manifest.json").read_text())
    edit(manifest)
    (folder / "manifest.json").write_text(json.dumps(manifest))
    return folder


def test_a_truncated_pinned_trajectory_is_refused_by_baseline_trajectory(pinned, tmp_path):
    """``Baseline.trajectory`` returned 3 poses for the pinned 4 frames without a word (check said "damaged")."""
    folder = _edited_copy(pinned, tmp_path / "cut", lambda manifest: None)
    poses = folder / "jobs" / pinned.jobs[0]["key"] / "poses_kitti.txt"
    assert len(load_baseline(folder).trajectory("vanilla")) == 4
    poses.write_text("".join(poses.read_text().splitlines(keepends=True)[:-1]))
    with pytest.raises(DataError) as info:
        load_baseline(folder).trajectory("vanilla")
    assert str(info.value) == (f"{poses}: its pinned trajectory has 3 poses for the pinned 4 frames (damaged): record "
                               "the baseline again")



def test_a_pinned_trajectory_cut_inside_its_last_number_is_damaged_not_the_methods_regression(pinned, tmp_path):
    """A pinned poses file cut inside its last number (a copy cut short) read "regression: trajectory differs from the
    pinned one by 2.831 m": lidarkit writes its files whole, so a cut one is the baseline's damage."""
    folder = _edited_copy(pinned, tmp_path / "cut", lambda manifest: None)
    poses = folder / "jobs" / pinned.jobs[0]["key"] / "poses_kitti.txt"
    poses.write_text(poses.read_text().rstrip("\n")[:-5])
    with pytest.raises(DataError, match=r"its pinned trajectory is damaged \(.*line 4 has no line end.*record the baseline again$"):
        load_baseline(folder).trajectory("vanilla")


@pytest.mark.parametrize("edit, problem", [
    (lambda m: m["jobs"][0].update(label=5), "label is 5, not a method label"),
    (lambda m: m["jobs"][0]["spec"]["dataset"].update(path=5), "spec dataset path is 5, not a string"),
    (lambda m: m["jobs"][0]["spec"]["dataset"].update(name=["sim"]), "spec dataset name is ['sim'], not a string"),
    (lambda m: m["jobs"][0]["spec"]["dataset"].pop("kind"), "spec dataset kind is '<absent>', not a string"),
    (lambda m: m["jobs"][0]["checked"].append(m["jobs"][0]["checked"][0]), "checks 'ape_se3_rmse_m' twice"),
])
def test_a_corrupt_field_of_a_pinned_job_is_one_line(pinned, tmp_path, edit, problem):
    """A label of 5 was a TypeError from Baseline.job, a dataset path of 5 a TypeError traceback in check, a metric
    listed twice in ``checked`` was held twice."""
    folder = _edited_copy(pinned, tmp_path / "edited", edit)
    assert pinned.jobs[0]["checked"][0] == "ape_se3_rmse_m"
    with pytest.raises(DataError) as info:
        load_baseline(folder)
    assert str(info.value) == f"{folder / 'manifest.json'}: corrupt manifest: job 0 {problem}"


def test_a_number_pinned_as_text_shows_its_type_in_the_finding(pinned, tmp_path):
    """``"kitti_step_frames": "10"`` read "protocol changed: evaluation: kitti_step_frames: 10 -> 10"."""
    folder = _edited_copy(pinned, tmp_path / "text", lambda m: m["evaluation"].update(kitti_step_frames="10"))
    assert [line for line in check(folder).lines() if not line.startswith("note:")] == [
        "protocol changed: evaluation: kitti_step_frames: 10 (str) -> 10 (int)"]
