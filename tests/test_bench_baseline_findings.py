"""Golden baselines: every finding of ``check`` is one line, a pinned spec is validated as its suite file was, and the
baseline's own suite.yaml copy records again."""

from __future__ import annotations

import json
import textwrap

import pytest

from lidarkit.bench.baseline import check, record
from lidarkit.bench.jobs import Job
from lidarkit.bench.tasks import get_task
from lidarkit.cli import main
from lidarkit.errors import ConfigError

KINDS = ("protocol changed:", "failed:", "regression:", "improved:", "note:", "baseline check")


def run_cli(argv: list[str], capsys) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as exc:
        main(argv)
    out, err = capsys.readouterr()
    return int(exc.value.code or 0), out, err


def test_a_failed_finding_with_a_multi_line_message_is_one_line(tmp_path, capsys):
    """A job whose exception message holds a newline (a plugin's ``ValueError("bad\\nthing happened")``) printed its
    finding over two lines, the second starting with no kind."""
    (tmp_path / "walk.yaml").write_text(textwrap.dedent("""
        name: walk
        experiments:
          - {name: walk, task: selftest, dataset: {kind: synthetic, name: synth}, methods: [random_walk]}
    """))
    baseline = record(tmp_path / "walk.yaml", tmp_path / "baseline", repeats=1)
    manifest = json.loads((baseline.path / "manifest.json").read_text())
    manifest["jobs"][0]["spec"].update(method="fail", params={"message": "bad\nthing  happened"})
    (baseline.path / "manifest.json").write_text(json.dumps(manifest))
    result = check(baseline.path)
    assert [f.line() for f in result.findings if f.kind == "failed"] == [
        "failed: fail(message=bad thing happened) on synth (seed 0): the job failed: RuntimeError: bad thing happened"]
    code, out, _ = run_cli(["baseline", "check", str(baseline.path)], capsys)
    assert code == 1
    assert all(line.startswith(KINDS) for line in out.splitlines()), out


def test_a_pinned_option_this_version_does_not_know_is_one_line_naming_the_valid_ones(tmp_path, capsys):
    """A pinned icp_pair spec with an option lidarkit no longer knows failed with pydantic's 4-line dump (its URL
    included): the task's run built its options model raw, without the check a suite file gets when it loads."""
    (tmp_path / "pair.yaml").write_text(textwrap.dedent("""
        name: pair
        experiments:
          - name: pair
            task: icp_pair
            dataset: {kind: folder, path: "sample:kitti_pair", name: pair}
            options: {pairs: [[0, 1]], ground_truth_file: T_target_source.txt}
            methods: [{name: vanilla, params: {voxel_size_m: 1.0}}]
    """))
    baseline = record(tmp_path / "pair.yaml", tmp_path / "baseline", repeats=1)
    manifest = json.loads((baseline.path / "manifest.json").read_text())
    manifest["jobs"][0]["spec"]["options"]["bogus"] = 1
    (baseline.path / "manifest.json").write_text(json.dumps(manifest))
    code, out, err = run_cli(["baseline", "check", str(baseline.path)], capsys)
    assert code == 1 and "error:" not in err
    assert [line for line in out.splitlines() if line.startswith("failed:")] == [
        "failed: vanilla(voxel_size_m=1) on pair (seed 0): options: bogus: Extra inputs are not permitted (options of task "
        "'icp_pair': pairs, ground_truth_file, max_pairs, init_noise_m, init_noise_deg)"]
    assert all(line.startswith(KINDS) for line in out.splitlines()), out
    # what the suite file's loading refuses beyond the model is refused too: a ground-truth file for two pairs
    manifest["jobs"][0]["spec"]["options"] = {"pairs": [[0, 1], [1, 0]], "ground_truth_file": "T_target_source.txt"}
    (baseline.path / "manifest.json").write_text(json.dumps(manifest))
    assert [f.line() for f in check(baseline.path).findings if f.kind == "failed"] == [
        "failed: vanilla(voxel_size_m=1) on pair (seed 0): options: ground_truth_file gives one pair's motion: set exactly "
        "one pair in 'pairs'"]


@pytest.mark.parametrize("task, valid", [
    ("icp_pair", "pairs, ground_truth_file, max_pairs, init_noise_m, init_noise_deg"),
    ("odometry", "frames, init"),
    ("pf", "visible, mse_start"),
    ("vo", "max_frames, align, smoothed"),
])
def test_a_task_run_names_an_unknown_option_in_one_line(task, valid):
    """Each task's run() met an option its model forbids with pydantic's multi-line ValidationError: the same one-line
    ConfigError a suite file gets, naming the options the task takes."""
    job = Job.from_spec({"task": task, "experiment": "e", "dataset_name": "d", "dataset": {"kind": "folder", "path": "/nowhere"},
                         "method": "m", "params": {}, "seed": 0, "options": {"bogus": 1}})
    with pytest.raises(ConfigError) as caught:
        get_task(task).run(job)
    assert str(caught.value) == f"options: bogus: Extra inputs are not permitted (options of task {task!r}: {valid})"


def test_the_baselines_suite_copy_records_again_with_relative_dataset_paths(tmp_path, capsys):
    """The baseline's suite.yaml was the suite's text verbatim: a relative ``path: data/pair`` then resolved against the
    baseline folder, and ``lidarkit baseline record BASELINE/suite.yaml --out BASELINE`` read "dataset path does not
    exist: .../BASELINE/data/pair". The copy writes the path as the manifest pins it, the rest of the text as it was."""
    import shutil

    from lidarkit.bench.datasets import sample_path

    shutil.copytree(sample_path("kitti_pair"), tmp_path / "data" / "pair")
    (tmp_path / "suite.yaml").write_text(textwrap.dedent("""
        name: relative
        experiments:
          - name: pair
            task: icp_pair
            dataset: {kind: folder, path: data/pair, name: pair}  # beside this file
            options: {pairs: [[0, 1]], ground_truth_file: T_target_source.txt}
            methods: [{name: vanilla, params: {voxel_size_m: 1.0}}]
    """))
    first = record(tmp_path / "suite.yaml", tmp_path / "bk", repeats=1)
    pinned_path = first.jobs[0]["spec"]["dataset"]["path"]
    assert pinned_path == str((tmp_path / "data" / "pair").resolve())
    copy = (tmp_path / "bk" / "suite.yaml").read_text()
    code, out, err = run_cli(["baseline", "record", str(tmp_path / "bk" / "suite.yaml"), "--out", str(tmp_path / "bk"),
                              "--repeats", "1"], capsys)
    assert code == 0 and "error" not in err, err
    assert f'dataset: {{kind: folder, path: {json.dumps(pinned_path)}, name: pair}}  # beside this file' in copy
    assert copy.startswith(f"# the suite recorded from {(tmp_path / 'suite.yaml').resolve()}")
    again = json.loads((tmp_path / "bk" / "manifest.json").read_text())
    assert [job["spec"] for job in again["jobs"]] == [job["spec"] for job in first.jobs]
    # recorded again from its own copy: one header, naming the file this record read (it kept the first file's name,
    # a different suite once the copy was edited), the rest unchanged (its paths absolute already)
    again_text = (tmp_path / "bk" / "suite.yaml").read_text()
    header = f"# the suite recorded from {(tmp_path / 'bk' / 'suite.yaml').resolve()}"
    assert again_text.startswith(header) and again_text.count("# the suite recorded from") == 1
    assert again_text.split("\n", 2)[2] == copy.split("\n", 2)[2]


def test_a_job_failing_in_record_names_its_dataset_once_and_keeps_a_file_it_names(tmp_path):
    """A job whose reader's error named the dataset read "exp1: kiss on scans (seed 0): scans: frames: ..." (the name
    twice); an error naming a file keeps the file."""
    from lidarkit.errors import DataError
    from lidarkit.sim.lidar import SimulatedLidarSequence, export_kitti

    scans = export_kitti(SimulatedLidarSequence(n_frames=8, n_beams=16, n_azimuths=360, seed=0), tmp_path / "sim") / "velodyne"

    def suite(frames: str) -> str:
        path = tmp_path / f"s{len(list(tmp_path.iterdir()))}.yaml"
        path.write_text(textwrap.dedent(f"""
            name: one
            experiments:
              - {{name: exp1, task: odometry, dataset: {{kind: generic, path: "{scans}", name: scans}},
                  options: {{frames: "{frames}"}}, methods: [kiss]}}
        """))
        return path

    with pytest.raises(DataError) as caught:
        record(suite("7:"), tmp_path / "bl", repeats=1)
    assert str(caught.value) == ("exp1: kiss on scans (seed 0): frames: '7:' selects 1 scan of the dataset's 8: odometry "
                                 "needs 2 scans or more (the first is the start, where nothing is scored)")
    broken = scans / "000001.bin"
    broken.write_bytes(broken.read_bytes()[:-3])  # not a whole number of points
    with pytest.raises(DataError) as caught:
        record(suite("0:3"), tmp_path / "bl", repeats=1)
    assert str(caught.value).startswith(f"exp1: kiss on scans (seed 0): {broken}"), str(caught.value)
