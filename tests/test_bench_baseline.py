"""Golden baselines: record then check passes; a drifting variant fails with "regression"; changed data gives
"protocol changed"; bad baseline folders are clear errors."""

from __future__ import annotations

import dataclasses
import json
import re
import textwrap
from pathlib import Path

import pytest
from fake_kitti import write_fake_kitti_sequence
from pydantic import Field

from lidarkit.bench.baseline import check, load_baseline, record
from lidarkit.cli import main
from lidarkit.errors import ConfigError, DataError
from lidarkit.registration import registry as registry_module
from lidarkit.registration.open3d_icp import Open3DPointToPlane, Open3DSurfaceConfig


class StretchConfig(Open3DSurfaceConfig):
    stretch: float = Field(1.0, gt=0, description="scale of the estimated translation (a deliberate drift)")


class Stretch(Open3DPointToPlane):
    """Open3D point-to-plane whose translations are scaled by ``stretch``: +0.75 % gives ~+0.5 pp more KITTI drift here."""

    Config = StretchConfig

    def _align(self, source_xyz, target_xyz, init_T):
        result = super()._align(source_xyz, target_xyz, init_T)
        T = result.T_target_source.copy()
        T[:3, 3] *= self.config.stretch
        return dataclasses.replace(result, T_target_source=T)




class StretchedMoreConfig(StretchConfig):
    stretch: float = Field(1.0075, gt=0)


class StretchedMore(Stretch):
    Config = StretchedMoreConfig


@pytest.fixture(scope="module")
def stretch_registered():
    """``test_stretch`` in the registry for this module only (other modules parametrize over available_icp())."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(Stretch, "name", "test_stretch")
        mp.setitem(registry_module._VARIANTS, "test_stretch", Stretch)
        yield


@pytest.fixture(scope="module")
def recorded(tmp_path_factory, stretch_registered):
    root = tmp_path_factory.mktemp("fake_kitti")
    write_fake_kitti_sequence(root, "00", 56, step_m=2.0, seed=0)  # 110 m: 100 m KITTI segments exist
    suite = root / "golden.yaml"
    suite.write_text(textwrap.dedent(f"""
        name: golden
        experiments:
          - name: fake
            task: odometry
            dataset: {{kind: kitti, path: "{root / 'sequences' / '00'}", name: "fake 00"}}
            methods: [test_stretch]
    """))
    out = root / "baseline"
    baseline = record(suite, out, repeats=2)
    return root, out, baseline


def run_cli(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    out, err = capsys.readouterr()
    return int(exc.value.code or 0), out, err


def test_record_pins_protocol_and_unchanged_check_passes(recorded, capsys):
    root, out, baseline = recorded
    manifest = json.loads((out / "manifest.json").read_text())
    env = manifest["environment"]
    assert env["packages"]["kiss-icp"] and env["packages"]["open3d"] and env["packages"]["numpy"]
    assert env["platform"]["machine"] and manifest["evaluation"]["kitti_step_frames"] == 10
    job = manifest["jobs"][0]
    assert job["protocol"]["checksums"]["sequences/00/velodyne/000000.bin"] and "poses/00.txt" in job["protocol"]["checksums"]
    assert job["protocol"]["method_config"]["stretch"] == 1.0
    assert "kitti_angle_correction" in job["protocol"] and "pose_instant" in job["protocol"]
    drift = job["metrics"]["drift_translation_pct"]
    assert 0 < drift < 1.0, drift  # the fake sequence registers well
    assert job["bands"]["drift_translation_pct"] >= 0.05
    assert baseline.trajectory("test_stretch").poses_se3.shape == (56, 4, 4)
    code, text, _ = run_cli(["baseline", "check", str(out)], capsys)
    assert code == 0 and "baseline check passed" in text and "regression" not in text


def test_drifting_variant_fails_with_regression(recorded, monkeypatch, capsys):
    _, out, baseline = recorded
    monkeypatch.setattr(StretchedMore, "name", "test_stretch")
    monkeypatch.setitem(registry_module._VARIANTS, "test_stretch", StretchedMore)
    result = check(out)
    assert not result.passed
    lines = result.lines()
    regression = [line for line in lines if line.startswith("regression:") and "drift_translation_pct" in line]
    assert regression, lines
    assert not any(line.startswith("protocol changed") for line in lines)
    assert any(line.startswith("note:") and "stretch: 1.0 -> 1.0075" in line for line in lines)
    now = next(iter(result.measured.values()))["drift_translation_pct"]
    assert now - baseline.jobs[0]["metrics"]["drift_translation_pct"] > 0.4
    # a band given by the user replaces the recorded one
    from lidarkit.bench.baseline import parse_tolerances

    assert parse_tolerances(["drift_translation_pct=0.2", "ape_rmse_m=1e-2"]) == {"drift_translation_pct": 0.2,
                                                                                   "ape_rmse_m": 0.01}


def test_changed_data_file_is_a_protocol_change_not_a_regression(recorded, tmp_path, capsys):
    root, out, _ = recorded
    scan = root / "sequences" / "00" / "velodyne" / "000003.bin"
    original = scan.read_bytes()
    try:
        scan.write_bytes(original[:-16])  # one point less
        result = check(out)
        assert not result.passed
        lines = result.lines()
        assert any(line.startswith("protocol changed: test_stretch on fake 00 (seed 0): data.sequences/00/velodyne/000003.bin") for line in lines)
        assert not any(line.startswith("regression") for line in lines)
        code, text, _ = run_cli(["baseline", "check", str(out)], capsys)
        assert code == 1 and "protocol changed" in text
    finally:
        scan.write_bytes(original)


def test_another_kiss_icp_version_is_a_protocol_change(recorded, tmp_path):
    import shutil

    _, out, _ = recorded
    copy = tmp_path / "baseline"
    shutil.copytree(out, copy)
    manifest = json.loads((copy / "manifest.json").read_text())
    manifest["environment"]["packages"]["kiss-icp"] = "0.0.1"
    (copy / "manifest.json").write_text(json.dumps(manifest))
    result = check(copy)
    assert not result.passed and not result.measured  # nothing re-run: the numbers would not be comparable
    assert any(line.startswith("protocol changed: environment: packages.kiss-icp: 0.0.1 -> ") for line in result.lines())


def test_bad_baseline_folders_are_clear_errors(recorded, tmp_path, capsys):
    _, out, _ = recorded
    with pytest.raises(DataError, match="no manifest.json: not a baseline folder"):
        load_baseline(tmp_path)
    with pytest.raises(DataError, match="does not exist"):
        check(tmp_path / "nowhere")
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "manifest.json").write_text("{ not json")
    with pytest.raises(DataError, match="corrupt manifest: not readable JSON"):
        check(bad)
    manifest = json.loads((out / "manifest.json").read_text())
    del manifest["jobs"][0]["bands"]
    (bad / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(DataError, match="corrupt manifest: job 0 lacks bands"):
        check(bad)
    (bad / "manifest.json").write_text(json.dumps({"schema": "something-else"}))
    code, _, err = run_cli(["baseline", "check", str(bad)], capsys)
    assert code == 1 and "corrupt manifest: schema 'something-else'" in err
    with pytest.raises(ConfigError, match="METRIC=BAND"):
        check(out, tolerances=["drift_translation_pct"])


@pytest.mark.parametrize("edit, reason", [
    (lambda m: m["jobs"][0]["checked"].append("nosuch_m"), "job 0 checks 'nosuch_m' but its metric is None, not a finite number"),
    (lambda m: m["jobs"][0].update(bands={}), "job 0 checks 'ape_se3_rmse_m' but its band is None, not a finite number"),
    (lambda m: m["jobs"][0]["metrics"].update(ape_se3_rmse_m=None), "job 0 checks 'ape_se3_rmse_m' but its metric is None"),
    (lambda m: m["jobs"][0].update(protocol=None), "job 0 protocol is None, not a mapping"),
    (lambda m: m.update(jobs=[1]), "job 0 is 1, not a mapping"),
    (lambda m: m.update(environment=None), "'environment' is None, not a mapping"),
    (lambda m: m["jobs"][0]["spec"].update(dataset="kitti00"), "job 0 spec dataset is 'kitti00', not a mapping"),
])
def test_a_hand_edited_manifest_is_a_clear_error(recorded, tmp_path, edit, reason):
    _, out, _ = recorded
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["jobs"][0]["checked"][0] == "ape_se3_rmse_m"
    edit(manifest)
    (tmp_path / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(DataError, match=f"corrupt manifest: {reason}".replace("(", r"\(").replace(")", r"\)")):
        check(tmp_path)


def test_a_failing_job_and_an_unknown_tolerance_are_one_line_errors(recorded, tmp_path, capsys):
    """A method that raises its own exception during record names the job; ``-t`` on a metric no job checks is refused
    (a typo would otherwise never apply); the APE bands have their 1 cm floor."""
    _, out, baseline = recorded
    assert baseline.jobs[0]["bands"]["ape_se3_rmse_m"] >= 0.01
    suite = tmp_path / "fails.yaml"
    suite.write_text("experiments:\n  - name: bad\n    task: selftest\n    dataset: {kind: synthetic}\n    methods: [random_walk, fail]\n")
    code, _, err = run_cli(["baseline", "record", str(suite), "--out", str(tmp_path / "bl")], capsys)
    assert code == 1 and "Traceback" not in err
    assert "bad: fail on synthetic (seed 0): the job failed: RuntimeError: selftest failure" in " ".join(err.split())
    assert not (tmp_path / "bl").exists()
    with pytest.raises(ConfigError, match="no pinned job checks nosuch_metric; checked metrics: ape_rmse_m, ape_se3_rmse_m"):
        check(out, tolerances=["nosuch_metric=0.1"])


def _pf_suite(folder: Path, counts: tuple[int, ...]) -> Path:
    """A particle-filter suite on the Freiburg data, one method per particle count."""
    from conftest import shared_path

    path = folder / f"pf{'_'.join(map(str, counts))}.yaml"
    methods = ", ".join(f"{{name: particle_filter, params: {{n_particles: {n}}}}}" for n in counts)
    path.write_text(textwrap.dedent(f"""
        name: pf-golden
        experiments:
          - name: pf
            task: pf
            dataset: {{kind: landmarks, path: "{shared_path('pf', 'robot_mapping_stachniss')}", name: Freiburg}}
            methods: [{methods}]
    """))
    return path


def test_a_particle_filter_job_pins_its_filter_config(tmp_path, monkeypatch):
    """The pf task keeps its resolved config under info["run"]: it was pinned as {}, so a changed filter default was
    never reported."""
    from lidarkit.pf.config import PFConfig

    suite = _pf_suite(tmp_path, (200,))
    out = tmp_path / "baseline"
    record(suite, out, repeats=1)
    pinned = json.loads((out / "manifest.json").read_text())["jobs"][0]["protocol"]["method_config"]
    assert pinned["n_particles"] == 200 and pinned["q"] == list(PFConfig().q)
    import copy

    changed = copy.copy(PFConfig.model_fields["q"])
    changed.default = (4.0, 0.4)  # another default in a later version of the code
    monkeypatch.setitem(PFConfig.model_fields, "q", changed)
    PFConfig.model_rebuild(force=True)
    try:
        lines = check(out).lines()
    finally:
        monkeypatch.undo()
        PFConfig.model_rebuild(force=True)
    assert any(line.startswith("note:") and "method config.q" in line for line in lines), lines
    # a baseline recorded before the filter's config was pinned: one note, not one per setting
    manifest = json.loads((out / "manifest.json").read_text())
    manifest["jobs"][0]["protocol"]["method_config"] = {}
    (out / "manifest.json").write_text(json.dumps(manifest))
    notes = [line for line in check(out).lines() if line.startswith("note:")]
    assert len(notes) == 1 and "the baseline pinned no method config" in notes[0]


def test_recording_again_replaces_the_baseline_and_never_merges_into_other_folders(tmp_path):
    def suite(counts):
        return _pf_suite(tmp_path, tuple(counts))

    out = tmp_path / "baseline"
    record(suite([100, 150]), out, repeats=1)
    record(suite([100]), out, repeats=1)
    manifest = json.loads((out / "manifest.json").read_text())
    assert [p.name for p in (out / "jobs").iterdir()] == [job["key"] for job in manifest["jobs"]]  # was: 2 folders, 1 pinned
    bench_folder = tmp_path / "results"
    (bench_folder / "jobs").mkdir(parents=True)
    (bench_folder / "suite.json").write_text("{}")
    with pytest.raises(Exception, match="holds files but no manifest.json: not a baseline to replace"):
        record(suite([100]), bench_folder, repeats=1)
    assert sorted(p.name for p in bench_folder.iterdir()) == ["jobs", "suite.json"]
    other_tool = tmp_path / "webapp"  # a manifest.json of something else: its files are not the baseline's to delete
    (other_tool / "jobs" / "important").mkdir(parents=True)
    (other_tool / "manifest.json").write_text('{"name": "my web app"}')
    (other_tool / "jobs" / "important" / "data.txt").write_text("keep")
    with pytest.raises(Exception, match="its manifest.json is not a lidarkit baseline's"):
        record(suite([100]), other_tool, repeats=1)
    assert (other_tool / "jobs" / "important" / "data.txt").read_text() == "keep"


def test_a_metric_a_job_leaves_nan_is_not_checked_and_the_baseline_reads_back(tmp_path):
    """kiss in an icp_pair job reports no iterations (NaN): the manifest stored null and its own reading refused it, after
    the earlier baseline had been replaced. Such a metric is not checked; the manifest is read back before it replaces
    anything."""
    from conftest import shared_path

    suite = tmp_path / "pair.yaml"
    suite.write_text(textwrap.dedent(f"""
        name: pair
        experiments:
          - task: icp_pair
            dataset: {{kind: kitti, path: "{shared_path('kitti_odometry', 'sequences', '00')}", name: K00}}
            options: {{pairs: [[0, 1]]}}
            methods: [kiss]
    """))
    out = tmp_path / "baseline"
    baseline = record(suite, out, repeats=2)
    job = baseline.jobs[0]
    assert "iterations" not in job["checked"] and "translation_error_m" in job["checked"]
    assert check(out).passed


def test_the_checksums_cover_the_files_a_job_reads_and_only_those(tmp_path, stretch_registered):
    """A KITTI root given with ``sequence: "00"`` hashed every file under the root (a note added beside the data, or
    another sequence, read as changed data), while a ground-truth file kept outside it was not hashed (editing it
    read as a regression). A moved dataset listed each pinned file as absent instead of naming the folder."""
    root = tmp_path / "kdata"
    write_fake_kitti_sequence(root, "00", 12, step_m=2.0, seed=0)
    gt = tmp_path / "gt00.txt"
    gt.write_text((root / "poses" / "00.txt").read_text())
    suite = tmp_path / "suite.yaml"
    suite.write_text(textwrap.dedent(f"""
        name: files
        experiments:
          - task: odometry
            dataset: {{kind: kitti, path: "{root}", sequence: "00", poses_file: "{gt}", name: K00}}
            methods: [test_stretch]
    """))
    out = tmp_path / "baseline"
    record(suite, out, repeats=1)
    (root / "NOTES.txt").write_text("about the data")
    write_fake_kitti_sequence(root, "01", 3, step_m=2.0, seed=1)
    assert check(out).passed  # not data this job reads
    lines = gt.read_text().splitlines()
    gt.write_text("\n".join(lines[:-1] + [lines[-1].replace(lines[-1].split()[3], "9.5", 1)]) + "\n")
    result = check(out)
    assert any(line.startswith("protocol changed: test_stretch on K00 (seed 0): data.gt00.txt") for line in result.lines()), result.lines()
    assert not any(line.startswith("regression") for line in result.lines())
    root.rename(tmp_path / "moved")
    lines = check(out).lines()
    assert len(lines) == 1 and "dataset not readable" in lines[0] and "kdata: dataset path does not exist" in lines[0], lines


TWO_WALKS = """
name: walks
experiments:
  - name: walk
    task: selftest
    dataset: {kind: synthetic, name: synth}
    methods: [random_walk, {name: random_walk, params: {noise_m: 0.1}}]
"""


@pytest.fixture()
def two_walks(tmp_path):
    """``random_walk`` and ``random_walk(noise_m=0.1)`` pinned: a label equal to the other job's method name."""
    (tmp_path / "walks.yaml").write_text(textwrap.dedent(TWO_WALKS))
    return record(tmp_path / "walks.yaml", tmp_path / "baseline", repeats=1)


def test_a_job_that_fails_is_a_finding_and_the_other_jobs_are_still_reported(two_walks, capsys):
    """check() raised at the first job that failed: the regression of the job checked before it was never printed,
    only "error: ... the job failed"."""
    manifest = json.loads((two_walks.path / "manifest.json").read_text())
    pinned_ape = manifest["jobs"][0]["metrics"]["ape_rmse_m"]
    manifest["jobs"][0]["metrics"]["ape_rmse_m"] = pinned_ape - 0.5  # the first job now regresses
    manifest["jobs"][1]["spec"].update(method="fail", params={})  # the second raises when run
    (two_walks.path / "manifest.json").write_text(json.dumps(manifest))
    result = check(two_walks.path)
    assert not result.passed
    assert [line for line in result.lines() if not line.startswith("note:")] == [
        "failed: fail on synth (seed 0): the job failed: RuntimeError: selftest failure",
        f"regression: random_walk on synth (seed 0): ape_rmse_m = {pinned_ape:.6g}, baseline {pinned_ape - 0.5:.6g} ± 0.01 "
        "(change +0.5)",
    ]
    code, text, err = run_cli(["baseline", "check", str(two_walks.path)], capsys)
    assert code == 1 and "error:" not in err
    assert "failed: fail on synth" in text and "regression: random_walk on synth" in text and "baseline check FAILED" in text


def test_a_label_equal_to_another_jobs_method_name_picks_that_job(two_walks):
    """``job("random_walk")`` matched both ``random_walk`` and ``random_walk(noise_m=0.1)``: "2 pinned jobs match",
    so the plain job could not be picked at all. An exact label wins, as in ``compare``."""
    assert two_walks.job("random_walk")["label"] == "random_walk"
    assert two_walks.job("random_walk(noise_m=0.1)")["spec"]["params"] == {"noise_m": 0.1}
    assert two_walks.metrics("random_walk") == two_walks.jobs[0]["metrics"]


def test_a_file_given_as_the_baseline_folder_and_a_bad_seed_are_named(two_walks, tmp_path, capsys):
    """A file given read "baseline folder does not exist"; a pinned seed edited to "x" read as the job failing
    ("the job failed: TypeError: ...") instead of a corrupt manifest."""
    given = two_walks.path / "manifest.json"
    code, _, err = run_cli(["baseline", "check", str(given)], capsys)
    assert code == 1
    assert " ".join(err.split()) == (f"error: {given}: a file, not a baseline folder (give the folder `lidarkit baseline "
                                     "record --out` wrote)")
    manifest = json.loads(given.read_text())
    manifest["jobs"][1]["spec"]["seed"] = "x"
    (tmp_path / "edited").mkdir()
    (tmp_path / "edited" / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(DataError, match="corrupt manifest: job 1 spec seed is 'x', not an integer"):
        check(tmp_path / "edited")


def test_a_negative_pinned_seed_is_a_corrupt_manifest(two_walks, tmp_path):
    """A pinned seed edited to -3 read as the job failing ("ValueError: expected non-negative integer")."""
    manifest = json.loads((two_walks.path / "manifest.json").read_text())
    manifest["jobs"][1]["spec"]["seed"] = -3
    edited = tmp_path / "edited"
    edited.mkdir()
    (edited / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(DataError, match=r"corrupt manifest: job 1 spec seed is -3, not a non-negative integer$"):
        check(edited)


def test_a_job_listed_twice_is_a_corrupt_manifest(two_walks, tmp_path, capsys):
    """A job entry copied twice passed as "3 pinned jobs" for 2 jobs (checked twice): a one-line error naming both."""
    manifest = json.loads((two_walks.path / "manifest.json").read_text())
    edited = tmp_path / "edited"
    edited.mkdir()
    manifest["jobs"].append(manifest["jobs"][0])
    (edited / "manifest.json").write_text(json.dumps(manifest))
    key = manifest["jobs"][0]["key"]
    code, out, err = run_cli(["baseline", "check", str(edited)], capsys)
    assert code == 1 and "passed" not in out
    assert " ".join(err.split()) == (f"error: {edited / 'manifest.json'}: corrupt manifest: job 2 (random_walk on synth "
                                     f"(seed 0)) repeats the key {key} of job 0")


def test_the_progress_lines_name_the_seed_and_experiment_where_jobs_share_a_method_and_dataset(tmp_path, capsys):
    """`baseline record` and `check` printed "checking kiss on street8" once per seed, alike: each line now names the
    seed, and the experiment, where the suite runs that method on that dataset with several (and only there)."""
    (tmp_path / "s.yaml").write_text(textwrap.dedent("""
        name: seeds
        seeds: [0, 1]
        experiments:
          - {name: walk, task: selftest, dataset: {kind: synthetic, name: synth}, methods: [random_walk]}
          - {name: again, task: selftest, dataset: {kind: synthetic, name: synth}, seeds: [0], methods: [random_walk]}
          - {name: single, task: selftest, dataset: {kind: synthetic, name: other}, seeds: [0], methods: [random_walk]}
        """))
    code, _, err = run_cli(["baseline", "record", str(tmp_path / "s.yaml"), "--out", str(tmp_path / "bl"), "--repeats", "1"], capsys)
    names = ["random_walk on synth (seed 0, experiment walk)", "random_walk on synth (seed 1, experiment walk)",
             "random_walk on synth (seed 0, experiment again)", "random_walk on other"]
    assert code == 0 and err.splitlines() == [f"run 1/1: {name}" for name in names]
    code, _, err = run_cli(["baseline", "check", str(tmp_path / "bl")], capsys)
    assert code == 0 and err.splitlines() == [f"checking {name}" for name in names]

def test_sequence_given_as_an_integer_hashes_that_sequence_only(tmp_path):
    """``sequence: 0`` (a YAML integer the reader reads as "00") looked for ``sequences/0`` and hashed the whole
    KITTI root: a note beside the data or another sequence read as changed data."""
    from lidarkit.bench.baseline import dataset_checksums

    root = tmp_path / "kdata"
    write_fake_kitti_sequence(root, "00", 3, step_m=2.0, seed=0)
    write_fake_kitti_sequence(root, "01", 2, step_m=2.0, seed=1)
    (root / "NOTES.txt").write_text("about the data")
    files = sorted(dataset_checksums({"kind": "kitti", "path": str(root), "sequence": 0, "name": "K00"}))
    assert files == ["kdata/poses/00.txt", "kdata/sequences/00/calib.txt", "kdata/sequences/00/times.txt",
                     *(f"kdata/sequences/00/velodyne/00000{i}.bin" for i in range(3))]


def test_the_manifest_pins_the_angle_correction_and_deskew_the_run_applied(tmp_path, monkeypatch):
    """kiss on KITTI's own scans: the manifest pinned the correction of a freshly opened reader (off) and the deskew kiss
    asks for (on), while the run applied the correction and no deskew (no per-point times). A lidarkit that stopped
    applying the correction then read as a regression, not as a changed protocol."""
    from conftest import kiss_on_kitti_00_suite

    import lidarkit.io.kitti as kitti_module

    suite = kiss_on_kitti_00_suite(tmp_path, "0:5")
    baseline = record(suite, tmp_path / "baseline", repeats=1)
    protocol = baseline.jobs[0]["protocol"]
    assert (protocol["kitti_angle_correction"], protocol["deskew"]) == (True, False)
    assert check(baseline.path).passed
    monkeypatch.setattr(kitti_module, "CORRECTED_BY_DEFAULT", ())  # a lidarkit that no longer corrects kiss's scans
    lines = check(baseline.path).lines()
    assert lines[0] == "protocol changed: kiss on K00 (seed 0): kitti_angle_correction: true -> false", lines
    assert not any(line.startswith("regression") for line in lines)


def test_the_frame_check_thresholds_are_pinned_and_a_changed_default_is_a_protocol_change(tmp_path, monkeypatch):
    """The manifest did not pin the frame-check thresholds: a lidarkit whose default min_fitness became 0.99 read
    "regression: kiss on K00 (seed 0): n_bad_frames = 5, baseline 0" instead of a changed protocol."""
    from conftest import kiss_on_kitti_00_suite

    import lidarkit.odometry.frame_check as frame_check_module

    suite = kiss_on_kitti_00_suite(tmp_path, "2:8")
    baseline = record(suite, tmp_path / "baseline", repeats=1)
    pinned = json.loads((baseline.path / "manifest.json").read_text())["jobs"][0]
    assert (pinned["protocol"]["frame_check"]["min_fitness"], pinned["protocol"]["frame_check"]["max_accel_mps2"]) == (0.3, 15.0)
    assert "motion_rule" not in pinned["protocol"]["frame_check"] and pinned["metrics"]["n_bad_frames"] == 0
    as_frame_check = frame_check_module.as_frame_check
    monkeypatch.setattr(frame_check_module, "as_frame_check",  # a later lidarkit whose default changed
                        lambda value: frame_check_module.FrameCheckConfig(min_fitness=0.99) if value is None else as_frame_check(value))
    lines = check(baseline.path).lines()
    assert [line for line in lines if not line.startswith("note:")] == [
        "protocol changed: kiss on K00 (seed 0): frame_check.min_fitness: 0.3 -> 0.99"]
    monkeypatch.undo()
    # a baseline recorded before the thresholds were pinned reads back, held under today's defaults (and says so)
    del pinned["protocol"]["frame_check"]
    manifest = json.loads((baseline.path / "manifest.json").read_text())
    manifest["jobs"][0] = pinned
    (baseline.path / "manifest.json").write_text(json.dumps(manifest))
    result = check(baseline.path)
    assert result.passed and "note: kiss on K00 (seed 0): the baseline pinned no frame-check thresholds (recorded before " \
                             "lidarkit pinned them): held under today's defaults" in result.lines()


def test_two_experiments_are_named_and_round_off_is_no_regression(tmp_path, capsys):
    """Two experiments of random_walk on one dataset read alike in record's summary and check's lines ("random_walk on
    synth"); ``-t ape_rmse_m=0`` reported a round-off change (+1.11e-16) as a regression."""
    suite = tmp_path / "two.yaml"
    suite.write_text(textwrap.dedent("""
        name: two
        experiments:
          - {name: short, task: selftest, dataset: {kind: synthetic, name: synth}, methods: [{name: random_walk, params: {steps: 10}}]}
          - {name: long, task: selftest, dataset: {kind: synthetic, name: synth}, methods: [{name: random_walk, params: {steps: 10}}]}
    """))
    code, text, _ = run_cli(["baseline", "record", str(suite), "--out", str(tmp_path / "bl"), "--repeats", "1"], capsys)
    assert code == 0
    label = "random_walk(steps=10) on synth"
    assert [line.split(":")[0] for line in text.splitlines()[:2]] == [f"{label} (seed 0, experiment short)",
                                                                      f"{label} (seed 0, experiment long)"]
    manifest = json.loads((tmp_path / "bl" / "manifest.json").read_text())
    ape = manifest["jobs"][0]["metrics"]["ape_rmse_m"]
    manifest["jobs"][0]["metrics"]["ape_rmse_m"] = ape * (1 - 1e-12)  # round-off
    manifest["jobs"][1]["metrics"]["ape_rmse_m"] = ape - 0.5
    (tmp_path / "bl" / "manifest.json").write_text(json.dumps(manifest))
    code, text, _ = run_cli(["baseline", "check", str(tmp_path / "bl"), "-t", "ape_rmse_m=0"], capsys)
    assert code == 1
    assert [line for line in text.splitlines() if line.startswith(("regression", "improved"))] == [
        f"regression: {label} (seed 0, experiment long): ape_rmse_m = {ape:.6g}, baseline {ape - 0.5:.6g} ± 0 (change +0.5)"]


@pytest.mark.parametrize("argv, message", [
    (["-t", "ape_rmse_m=0.1", "-t", "ape_rmse_m=0.2"], "error: --tolerance: 'ape_rmse_m' given twice: one band per metric"),
    (["-t", "=0.1"], "error: --tolerance: expected METRIC=BAND, got '=0.1'"),
])
def test_a_repeated_or_nameless_tolerance_is_named(two_walks, capsys, argv, message):
    """``-t m=0.1 -t m=0.2`` kept the last band silently; ``-t =0.1`` read "no pinned job checks ;"."""
    code, _, err = run_cli(["baseline", "check", str(two_walks.path), *argv], capsys)
    assert code == 1 and " ".join(err.split()) == message


def test_zero_repeats_names_the_option_and_noise_from_names_no_flag(two_walks, tmp_path, capsys):
    """``--repeats 0`` read "error: repeats: ..." (no such flag); a --noise-from baseline without the compared metric
    said "name the metric with --metric" when it had been named."""
    from lidarkit.bench.baseline import measured_noise

    (tmp_path / "walks.yaml").write_text(textwrap.dedent(TWO_WALKS))
    code, _, err = run_cli(["baseline", "record", str(tmp_path / "walks.yaml"), "--out", str(tmp_path / "b"), "--repeats", "0"],
                           capsys)
    assert code == 1 and " ".join(err.split()) == "error: --repeats: must be a positive integer, got 0"
    with pytest.raises(ConfigError, match=r"no band for metric 'drift_translation_pct' in this baseline \(it has: "
                                          r"ape_rmse_m, final_error_m\): it did not check that metric$"):
        measured_noise(two_walks.path, "drift_translation_pct")


def test_report_on_a_baseline_folder_names_it_as_compare_does(two_walks, capsys):
    """`lidarkit report BASELINE_DIR` said "no readable job results in jobs/" (its jobs/ read as a bench folder's);
    `compare` named the case: report now does too."""
    code, out, err = run_cli(["report", str(two_walks.path)], capsys)
    assert (code, out) == (1, "")
    assert " ".join(err.split()) == (f"error: {two_walks.path}: a baseline folder (lidarkit baseline record): report takes "
                                     "bench results folders (`lidarkit baseline check` re-runs a baseline's jobs against it)")
    assert not (two_walks.path / "report.md").exists()


def test_an_icp_pair_job_of_kiss_on_kitti_pins_the_angle_correction(tmp_path, monkeypatch):
    """icp_pair reads KITTI as kiss does (corrected), as odometry jobs do, but its protocol did not pin it: a lidarkit
    that stopped correcting read as a regression of the pair errors, not as a changed protocol. Other methods' icp_pair
    protocols stay as they were (no such key)."""
    from conftest import shared_path

    import lidarkit.io.kitti as kitti_module

    velodyne = shared_path("kitti_odometry", "extra_frames", "00", "velodyne")
    suite = tmp_path / "suite.yaml"
    suite.write_text(textwrap.dedent(f"""\
        name: pairs
        experiments:
          - name: pair
            task: icp_pair
            dataset: {{kind: kitti, path: {shared_path("kitti_odometry")}, sequence: "00", velodyne_dir: {velodyne}, name: K00}}
            options: {{pairs: [[94, 95]]}}
            methods: [kiss, {{name: vanilla, params: {{voxel_size_m: 1.0}}}}]
            seeds: [0]
        """))
    baseline = record(suite, tmp_path / "baseline", repeats=1)
    protocols = {job["spec"]["method"]: job["protocol"] for job in baseline.jobs}
    assert protocols["kiss"]["kitti_angle_correction"] is True and "kitti_angle_correction" not in protocols["vanilla"]
    assert check(baseline.path).passed
    monkeypatch.setattr(kitti_module, "CORRECTED_BY_DEFAULT", ())  # a lidarkit that no longer corrects kiss's scans
    lines = check(baseline.path).lines()
    assert any(line.startswith("protocol changed: kiss on K00 (seed 0): kitti_angle_correction") for line in lines), lines
    assert not any(line.startswith("regression") for line in lines), lines


def test_scans_reached_through_a_linked_folder_are_pinned(tmp_path):
    """A KITTI sequence whose velodyne/ is a symbolic link to scans kept elsewhere (common for large data in CI): the
    checksums held calib, times and poses only, so changed scans read as a regression of the code; a loop of links is
    walked once."""
    import shutil

    from conftest import shared_path

    from lidarkit.bench.baseline import dataset_checksums

    sequence = tmp_path / "root" / "sequences" / "00"
    sequence.mkdir(parents=True)
    for name in ("calib.txt", "times.txt"):
        shutil.copy(shared_path("kitti_odometry", "sequences", "00", name), sequence / name)
    scans = tmp_path / "scans"
    shutil.copytree(shared_path("kitti_odometry", "sequences", "00", "velodyne"), scans)
    (sequence / "velodyne").symlink_to(scans, target_is_directory=True)
    (scans / "loop").symlink_to(scans, target_is_directory=True)
    spec = {"kind": "kitti", "path": str(sequence), "name": "k00"}
    pinned = dataset_checksums(spec)
    assert sorted(k for k in pinned if k.endswith(".bin")) == [f"sequences/00/velodyne/{i:06d}.bin" for i in range(10)]
    shutil.copy(scans / "000004.bin", scans / "000005.bin")
    changed = dataset_checksums(spec)
    assert [k for k in pinned if changed[k] != pinned[k]] == ["sequences/00/velodyne/000005.bin"]


def _scans_without_ground_truth(root: Path) -> Path:
    """8 simulated sweeps (16 beams) as a folder of scan files read by ``generic:`` (no ground truth)."""
    from lidarkit.sim.lidar import SimulatedLidarSequence, export_kitti

    export_kitti(SimulatedLidarSequence(n_frames=8, n_beams=16, n_azimuths=360, seed=0), root / "sim")
    return root / "sim" / "velodyne"


def _suite_without_ground_truth(root: Path) -> Path:
    """``root/gen.yaml``: test_stretch's odometry over :func:`_scans_without_ground_truth`."""
    scans = _scans_without_ground_truth(root)
    (root / "gen.yaml").write_text(textwrap.dedent(f"""
        name: no-truth
        experiments:
          - {{name: gen, task: odometry, dataset: {{kind: generic, path: "{scans}", name: gen}}, methods: [test_stretch]}}
    """))
    return root / "gen.yaml"


def test_a_job_without_ground_truth_is_held_on_its_pinned_trajectory(tmp_path, stretch_registered, monkeypatch):
    """Over data without ground truth (generic:, carmen, bags without odometry) a baseline checked n_bad_frames only:
    kiss with one ICP iteration and 3 m voxels moved the end pose 0.18 m and passed. The rerun is held on the pinned
    trajectory, in a band from its repeats' spread with a floor far above last-bit noise."""
    _suite_without_ground_truth(tmp_path)
    baseline = record(tmp_path / "gen.yaml", tmp_path / "baseline", repeats=2)
    (job,) = baseline.jobs
    band = job["trajectory_band"]
    assert job["checked"] == ["n_bad_frames"] and band["path_length_m"] > 0.1
    assert band["noise_position_m"] < 1e-9  # (the repeats agree to the last bits: the floor sets the band)
    assert band["position_m"] == max(1e-6, 1e-6 * band["path_length_m"]) and band["rotation_deg"] == 1e-4
    assert check(baseline.path).passed
    monkeypatch.setattr(StretchedMore, "name", "test_stretch")  # translations 0.75 % longer
    monkeypatch.setitem(registry_module._VARIANTS, "test_stretch", StretchedMore)
    result = check(baseline.path)
    (line,) = [line for line in result.lines() if not line.startswith("note:")]
    found = re.fullmatch(r"regression: test_stretch on gen \(seed 0\): trajectory differs from the pinned one by (\S+) m, "
                         r"(\S+) deg \(worst at pose (\d+); band 1e-06 m, 0.0001 deg\)", line)
    assert found and float(found[1]) > 1e-3 and not result.passed, line
    # a baseline recorded before such jobs pinned a trajectory band: held on the bad-frame count, and said
    manifest = json.loads((baseline.path / "manifest.json").read_text())
    del manifest["jobs"][0]["trajectory_band"]
    (baseline.path / "manifest.json").write_text(json.dumps(manifest))
    result = check(baseline.path)
    assert result.passed and [line for line in result.lines() if "bad-frame" in line] == [
        "note: test_stretch on gen (seed 0): no accuracy metric (no ground truth) and no trajectory band pinned (recorded "
        "before lidarkit pinned one): held on its bad-frame count only; record it again to compare its trajectory"]


def test_a_job_with_ground_truth_pins_no_trajectory_band(recorded):
    """Jobs held on accuracy metrics are checked as before: no trajectory band in their manifest entry."""
    _, _, baseline = recorded
    assert "trajectory_band" not in baseline.jobs[0] and "ape_se3_rmse_m" in baseline.jobs[0]["checked"]


@pytest.mark.parametrize("edit, reason", [
    (lambda p: p.update(checksums=None), "protocol checksums is None, not a mapping"),
    (lambda p: p.update(checksums=["a"]), "protocol checksums is ['a'], not a mapping"),
    (lambda p: p.update(checksums={"<generated>": 7}), "protocol checksums gives '<generated>' the checksum 7, not a string"),
    (lambda p: p.update(option_files="x"), "protocol option_files is 'x', not a mapping"),
    (lambda p: p.update(task_options=[1]), "protocol task_options is [1], not a mapping"),
    (lambda p: p.update(frame_check="x"), "protocol frame_check is 'x', not a mapping"),
    (lambda p: p.update(simulation=3), "protocol simulation is 3, not a mapping"),
])
def test_a_corrupt_pinned_protocol_field_is_one_line(two_walks, tmp_path, capsys, edit, reason):
    """Checksums edited to null or ["a"] gave a TypeError/ValueError traceback in check; option_files "x" read as "not
    pinned" (the files it names never compared); a frame_check of "x" read as a changed protocol."""
    manifest = json.loads((two_walks.path / "manifest.json").read_text())
    edit(manifest["jobs"][0]["protocol"])
    edited = tmp_path / "edited"
    edited.mkdir()
    (edited / "manifest.json").write_text(json.dumps(manifest))
    code, out, err = run_cli(["baseline", "check", str(edited)], capsys)
    assert code == 1 and "passed" not in out
    assert " ".join(err.split()) == f"error: {edited / 'manifest.json'}: corrupt manifest: job 0 {reason}"


def test_several_pinned_jobs_without_a_choice_name_the_keyword_to_pass(two_walks, tmp_path):
    """``job()`` over two pinned jobs was a DataError ("2 pinned jobs match no choice"), as if the baseline were at
    fault: an argument is missing, and the error names it with the values that pick one."""
    with pytest.raises(ConfigError, match=re.escape(f"{two_walks.path}: 2 pinned jobs: pick one with method= "
                                                    "(random_walk, random_walk(noise_m=0.1))") + "$"):
        two_walks.job()
    (tmp_path / "seeds.yaml").write_text(textwrap.dedent(TWO_WALKS) + "seeds: [0, 1]\n")
    seeds = record(tmp_path / "seeds.yaml", tmp_path / "seeds", repeats=1)
    with pytest.raises(ConfigError, match=re.escape("4 pinned jobs: pick one with method= (random_walk, "
                                                    "random_walk(noise_m=0.1)) and seed= (0, 1)") + "$"):
        seeds.job()
    with pytest.raises(ConfigError, match=re.escape("2 pinned jobs match method='random_walk': pick one with seed= (0, 1)") + "$"):
        seeds.metrics("random_walk")
    with pytest.raises(DataError, match="0 pinned jobs match method='nosuch'; pinned: "):  # (nothing pinned of it)
        seeds.job("nosuch")
    assert seeds.job("random_walk", seed=1)["spec"]["seed"] == 1


def test_record_says_the_trajectory_band_of_a_job_without_ground_truth(tmp_path, stretch_registered, capsys):
    """record's summary printed "n_bad_frames 0 ± 1e-09" alone for such a job, though its check holds the trajectory."""
    _suite_without_ground_truth(tmp_path)
    code, out, _ = run_cli(["baseline", "record", str(tmp_path / "gen.yaml"), "--out", str(tmp_path / "b"), "--repeats", "2",
                            "--no-progress"], capsys)
    assert code == 0
    assert "; trajectory within 1e-06 m, 0.0001 deg of the pinned one" in " ".join(out.split())


def test_tolerance_sets_the_trajectory_band_of_a_job_without_ground_truth(tmp_path, stretch_registered, monkeypatch):
    """``-t METRIC=BAND`` loosened accuracy metrics only: the trajectory band of a job without ground truth could not be
    widened (``trajectory_m`` was refused as a metric no job checks). ``trajectory_m`` / ``trajectory_deg`` set it."""
    _suite_without_ground_truth(tmp_path)
    baseline = record(tmp_path / "gen.yaml", tmp_path / "baseline", repeats=2)
    monkeypatch.setattr(StretchedMore, "name", "test_stretch")  # translations 0.75 % longer: > 1 mm off, < 1 m
    monkeypatch.setitem(registry_module._VARIANTS, "test_stretch", StretchedMore)
    assert not check(baseline.path).passed
    assert check(baseline.path, tolerances=["trajectory_m=1"]).passed  # (translations only: rotations within 1e-4 deg)
    (line,) = [line for line in check(baseline.path, tolerances=["trajectory_deg=1"]).lines() if line.startswith("regression")]
    assert line.endswith("band 1e-06 m, 1 deg)"), line
    with pytest.raises(ConfigError, match="checked metrics: n_bad_frames, trajectory_m, trajectory_deg"):
        check(baseline.path, tolerances=["trajectory_cm=1"])


@pytest.fixture(scope="module")
def no_truth_baseline(tmp_path_factory, stretch_registered):
    """test_stretch (deterministic) pinned over 8 simulated sweeps without ground truth: held on its trajectory."""
    root = tmp_path_factory.mktemp("no_truth")
    _suite_without_ground_truth(root)
    return record(root / "gen.yaml", root / "baseline", repeats=1)


def _copy_with_pinned_poses(baseline, out: Path, edit) -> Path:
    """A copy of ``baseline`` whose pinned poses_kitti.txt holds ``edit``(its (N, 4, 4) poses) instead."""
    import shutil

    import numpy as np

    from lidarkit.trajectory import Trajectory

    shutil.copytree(baseline.path, out)
    path = out / "jobs" / baseline.jobs[0]["key"] / "poses_kitti.txt"
    poses = Trajectory.from_kitti(path).poses_se3.copy()
    Trajectory(np.asarray(edit(poses))).to_kitti(path)
    return out


def test_round_off_of_a_trajectory_is_a_tie_at_a_zero_band(no_truth_baseline, tmp_path):
    """``-t trajectory_m=0 -t trajectory_deg=0`` read kiss's thread round-off (3.7e-15 m, 2.4e-15 deg over a 5 m path)
    as a regression, though metrics take round-off as a tie even at ``-t METRIC=0``. 1e-14 m and 1e-14 rad on the
    pinned last pose tie; 1e-6 m or 1e-6 rad is a regression."""
    from lidarkit.geometry import so3_exp

    zero = {"trajectory_m": 0.0, "trajectory_deg": 0.0}

    def moved(offset_m: float, angle_rad: float):
        def edit(poses):
            poses[-1, 0, 3] += offset_m
            poses[-1, :3, :3] = poses[-1, :3, :3] @ so3_exp([0.0, 0.0, angle_rad])
            return poses
        return edit

    assert check(no_truth_baseline.path, tolerances=zero).passed  # (a deterministic method: the rerun is the same)
    tie = _copy_with_pinned_poses(no_truth_baseline, tmp_path / "tie", moved(1e-14, 1e-14))
    result = check(tie, tolerances=zero)
    assert result.passed and not [line for line in result.lines() if not line.startswith("note:")], result.lines()
    for name, offset_m, angle_rad, shown in (("far", 1e-6, 0.0, r"1e-06 m, \S+"), ("turned", 0.0, 1e-6, r"\S+ m, 5\.73e-05")):
        result = check(_copy_with_pinned_poses(no_truth_baseline, tmp_path / name, moved(offset_m, angle_rad)), tolerances=zero)
        (line,) = [line for line in result.lines() if not line.startswith("note:")]
        assert not result.passed and re.fullmatch(r"regression: test_stretch on gen \(seed 0\): trajectory differs from the "
                                                  rf"pinned one by {shown} deg \(worst at pose 7; band 0 m, 0 deg\)", line), line


def test_a_truncated_pinned_trajectory_is_said_damaged_not_a_regression(no_truth_baseline, tmp_path):
    """A pinned poses_kitti.txt cut short read "regression: ... trajectory has 8 poses, the pinned one 7", as if the
    method had changed, though the manifest pins 8 frames: the baseline is damaged."""
    cut = _copy_with_pinned_poses(no_truth_baseline, tmp_path / "cut", lambda poses: poses[:-1])
    result = check(cut)
    (line,) = [line for line in result.lines() if not line.startswith("note:")]
    assert not result.passed and line == ("failed: test_stretch on gen (seed 0): its pinned trajectory has 7 poses for the "
                                           "pinned 8 frames (damaged): record the baseline again")


def test_a_job_key_that_is_not_a_plain_name_is_refused(two_walks, tmp_path):
    """A hand-edited key "../../other/jobs/x" was accepted, and the job's files were read outside the baseline folder."""
    for i, key in enumerate(("../../other/jobs/x", "..", "a\\b")):
        manifest = json.loads((two_walks.path / "manifest.json").read_text())
        manifest["jobs"][0]["key"] = key
        edited = tmp_path / f"edited{i}"
        edited.mkdir()
        (edited / "manifest.json").write_text(json.dumps(manifest))
        with pytest.raises(DataError, match=re.escape(f"corrupt manifest: job 0 key {key!r} is not a plain name (it names the "
                                                      "job's folder under jobs/)") + "$"):
            load_baseline(edited)


def test_the_opencv_version_is_pinned_and_an_earlier_baseline_without_it_is_a_note(two_walks):
    """VO jobs, the camera simulator and image decoding run on OpenCV, and the protocol did not pin its version. A
    baseline recorded before it was pinned is not a changed protocol: a note says so."""
    import cv2

    from lidarkit.bench.baseline import environment

    pinned = two_walks.manifest["environment"]["packages"]["opencv"]
    assert pinned == environment()["packages"]["opencv"] and pinned.startswith(cv2.__version__)
    manifest_path = two_walks.path / "manifest.json"
    manifest = json.loads(manifest_path.read_text())
    del manifest["environment"]["packages"]["opencv"]
    manifest_path.write_text(json.dumps(manifest))
    result = check(two_walks.path)
    assert result.passed and (f"note: environment: the baseline pinned no opencv version (recorded before lidarkit pinned "
                              f"it): not compared; opencv is {pinned} now") in result.lines()
    manifest["environment"]["packages"]["opencv"] = "3.4.0"
    manifest_path.write_text(json.dumps(manifest))
    result = check(two_walks.path)  # (random walks run on no OpenCV: another version voids only the jobs that do)
    assert result.passed and result.lines() == [f"note: environment: packages.opencv: 3.4.0 -> {pinned} (no pinned job "
                                                "runs on opencv: not compared)"]


def test_a_vo_job_is_banded_on_its_own_scale_not_lidar_odometry_floors(tmp_path):
    """A vo job on a simulated camera (APE ~1 mm) was pinned ``± 0.01`` by the LiDAR odometry floor of 1 cm, and
    max_features=100 (APE 2.9x, final error 8.5x worse) passed. vo takes no absolute floor: 2 % of its values here
    (it is deterministic), far below them."""
    camera = "n_frames: 5, width: 320, height: 128, fx: 200.0, fy: 200.0, cx: 159.5, cy: 63.5"
    (tmp_path / "vo.yaml").write_text(textwrap.dedent(f"""
        name: vo
        experiments:
          - {{name: vo, task: vo, dataset: {{kind: sim_camera, name: cam, {camera}}}, methods: [lidarkit]}}
    """))
    (job,) = record(tmp_path / "vo.yaml", tmp_path / "baseline", repeats=1).jobs
    for metric in ("ape_rmse_m", "final_error_m", "rpe_trans_rmse_m"):
        value = job["metrics"][metric]
        assert 1e-5 < value < 0.05, (metric, value)  # (mm to cm: below odometry's floors' scale)
        assert job["bands"][metric] == pytest.approx(0.02 * value), (metric, job["bands"][metric], value)
