"""Suite parsing and validation: bad suites are refused before anything runs, naming file, key and reason."""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np
import pytest

from lidarkit.bench import Metric, Task, TaskOutput, register_task
from lidarkit.bench.datasets import resolve_dataset
from lidarkit.bench.suite import load_suite
from lidarkit.cli import main
from lidarkit.errors import ConfigError, DataError

GOOD = """
name: tiny
seeds: 2
datasets:
  synth: {kind: synthetic}
experiments:
  - name: walk
    task: selftest
    dataset: synth
    methods:
      - name: random_walk
        params: {steps: 20}
        grid: {noise_m: [0.01, 0.02, 0.05]}
      - sleep
    seeds: [3, 4, 5]
  - task: selftest
    datasets: [synth, {kind: synthetic, name: other}]
    methods: [{name: burn, grid: {size: [10, 20]}}]
"""


def write(tmp_path: Path, text: str, name: str = "suite.yaml") -> Path:
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


def test_good_suite_expands_grid_datasets_and_seeds(tmp_path):
    suite = load_suite(write(tmp_path, GOOD))
    assert suite.name == "tiny"
    walk = [j for j in suite.jobs if j.experiment == "walk"]
    # (3 grid points + 1 sleep) x 3 seeds
    assert len(walk) == 12
    assert {j.params["noise_m"] for j in walk if j.method == "random_walk"} == {0.01, 0.02, 0.05}
    assert all(j.params["steps"] == 20 for j in walk if j.method == "random_walk")
    assert {j.seed for j in walk} == {3, 4, 5}
    burn = [j for j in suite.jobs if j.method == "burn"]
    # 2 grid points x 2 datasets x suite default seeds 0, 1
    assert len(burn) == 8
    assert {j.dataset_name for j in burn} == {"synth", "other"}
    assert {j.seed for j in burn} == {0, 1}
    keys = [j.key() for j in suite.jobs]
    assert len(set(keys)) == len(keys)



def test_suite_repr_is_one_line_of_counts(tmp_path):
    """The generated repr printed every Job (2,300 characters for 9 jobs; a suite of hundreds flooded a notebook)."""
    path = write(tmp_path, GOOD)
    suite = load_suite(path)
    assert repr(suite) == f"Suite('tiny', 20 jobs, 2 experiments, {str(path)!r})"
    one = load_suite(write(tmp_path, "experiments: [{task: selftest, dataset: {kind: synthetic}, methods: [sleep]}]\n", "one.yaml"))
    assert repr(one) == f"Suite('suite', 1 job, 1 experiment, {str(tmp_path / 'one.yaml')!r})"

def test_job_key_depends_on_spec_and_version(tmp_path):
    job = load_suite(write(tmp_path, GOOD)).jobs[0]
    assert job.key("0.1.0") == job.key("0.1.0")
    assert job.key("0.1.0") != job.key("0.2.0")
    other = type(job)(**{**job.spec(), "seed": job.seed + 100})
    assert other.key("0.1.0") != job.key("0.1.0")


BAD = {
    "unknown_task": (
        """
        experiments:
          - task: icp_magic
            dataset: {kind: synthetic}
            methods: [sleep]
        """,
        ConfigError,
        ["unknown task 'icp_magic'", "experiments[0].task", "line 3", "selftest"],
    ),
    "unknown_method": (
        """
        experiments:
          - task: selftest
            dataset: {kind: synthetic}
            methods: [sleep, {name: teleport}]
        """,
        ConfigError,
        ["unknown selftest method 'teleport'", "experiments[0].methods[1]", "random_walk"],
    ),
    "unknown_param": (
        """
        experiments:
          - task: selftest
            dataset: {kind: synthetic}
            methods:
              - name: random_walk
                grid: {noise_m: [0.1], warp_factor: [9]}
        """,
        ConfigError,
        ["warp_factor", "experiments[0].methods[0]", "line 6", "noise_m"],
    ),
    "bad_param_value": (
        """
        experiments:
          - task: selftest
            dataset: {kind: synthetic}
            methods: [{name: sleep, params: {seconds: -1}}]
        """,
        ConfigError,
        ["seconds", "greater than or equal to 0"],
    ),
    "missing_dataset": (
        """
        experiments:
          - task: selftest
            dataset: {kind: kitti, path: data/nowhere}
            methods: [sleep]
        """,
        DataError,
        ["dataset path does not exist", "nowhere", "experiments[0].dataset", "line 4"],
    ),
    "undefined_dataset_name": (
        """
        experiments:
          - task: selftest
            dataset: synth
            methods: [sleep]
        """,
        ConfigError,
        ["unknown dataset 'synth'"],
    ),
    "unknown_key": (
        """
        experiments:
          - task: selftest
            dataset: {kind: synthetic}
            method: [sleep]
        """,
        ConfigError,
        ["unknown key 'method'", "experiments[0]"],
    ),
    "malformed_yaml": (
        """
        experiments:
          - task: selftest
            dataset: {kind: synthetic
            methods: [sleep]
        """,
        ConfigError,
        ["malformed YAML", "line 5"],
    ),
    "not_a_mapping": ("- just\n- a list\n", ConfigError, ["YAML mapping"]),
    "options_for_optionless_task": (
        """
        experiments:
          - task: selftest
            dataset: {kind: synthetic}
            options: {speed: 3}
            methods: [sleep]
        """,
        ConfigError,
        ["takes no options, got speed", "experiments[0].options, line 5"],
    ),
    "boolean_seed": (
        """
        seeds: [true, 2]
        experiments:
          - task: selftest
            dataset: {kind: synthetic}
            methods: [random_walk]
        """,
        ConfigError,
        ["seeds[0]: Input should be a valid integer", "line 2"],
    ),
    "bad_frames_option": (
        """
        experiments:
          - task: odometry
            dataset: {kind: sim_lidar, scene: street, n_frames: 4, n_beams: 16, n_azimuths: 360}
            options: {frames: "0:abc"}
            methods: [vanilla]
        """,
        ConfigError,
        ["frames '0:abc': frame bounds must be integers", "experiments[0].options, line 5"],
    ),
    "not_plain_json": (
        """
        experiments:
          - task: dataset_options_test_task
            dataset: {kind: synthetic, recorded: 2024-01-01}
            methods: [fail]
        """,
        ConfigError,
        ["values must be plain numbers", "date", "experiments[0].methods[0]"],
    ),
}


@register_task("dataset_options_test_task")
class DatasetOptionsTask(Task):
    """A task on ``synthetic`` datasets that takes any dataset option (a third party's own, as in test_compare)."""

    dataset_kinds = ("synthetic",)
    metrics = (Metric("err_m", "error [m]"),)

    def run(self, job):
        return TaskOutput(metrics={"err_m": 0.0})


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_suite_is_refused_with_file_key_and_reason(tmp_path, case):
    text, error, fragments = BAD[case]
    path = write(tmp_path, text, f"{case}.yaml")
    with pytest.raises(error) as info:
        load_suite(path)
    message = str(info.value)
    assert f"{case}.yaml" in message
    for fragment in fragments:
        assert fragment in message, (fragment, message)


@pytest.mark.parametrize("case", ["unknown_task", "unknown_param", "missing_dataset", "malformed_yaml"])
def test_cli_refuses_bad_suite_before_running_anything(tmp_path, capsys, case):
    text, _, fragments = BAD[case]
    path = write(tmp_path, text, f"{case}.yaml")
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as exc:
        main(["bench", str(path), "--out", str(out), "--executor", "serial"])
    assert exc.value.code == 1
    err = capsys.readouterr().err
    assert "error:" in err and f"{case}.yaml" in err and fragments[0] in err
    assert "Traceback" not in err
    assert not out.exists()  # nothing ran, nothing written


def test_options_for_a_builtin_task_without_options_name_the_task(tmp_path):
    """A built-in task (loaded by module, not registered by name) had no name: "task '' takes no options, got foo"."""
    path = write(tmp_path, """
        experiments:
          - task: selftest
            dataset: {kind: synthetic}
            methods: [random_walk]
            options: {foo: 1}
        """)
    with pytest.raises(ConfigError) as info:
        load_suite(path)
    assert str(info.value) == f"{path} (experiments[0].options, line 6): task 'selftest' takes no options, got foo"


def test_missing_suite_file(tmp_path):
    with pytest.raises(DataError, match="suite file not found"):
        load_suite(tmp_path / "absent.yaml")


def test_relative_dataset_paths_resolve_against_suite_folder(tmp_path, monkeypatch):
    (tmp_path / "suites" / "data" / "seq").mkdir(parents=True)
    spec = resolve_dataset({"kind": "folder", "path": "data/seq"}, tmp_path / "suites")
    assert spec["path"] == str((tmp_path / "suites" / "data" / "seq").resolve())
    monkeypatch.chdir(tmp_path)  # the working directory does not matter
    with pytest.raises(DataError, match="does not exist"):
        resolve_dataset({"kind": "folder", "path": "data/seq"}, tmp_path)


def test_generated_dataset_kinds_take_no_path(tmp_path):
    with pytest.raises(ConfigError, match="takes no 'path'"):
        resolve_dataset({"kind": "synthetic", "path": "x"}, tmp_path)
    with pytest.raises(ConfigError, match="needs a 'path'"):
        resolve_dataset({"kind": "kitti"}, tmp_path)


def test_unavailable_task_is_skipped_only_when_asked(tmp_path, monkeypatch):
    from lidarkit.bench import tasks

    class Missing(tasks.Task):
        dataset_kinds = ("synthetic",)

        def require(self) -> None:
            raise ConfigError("needs lidarkit.nothing", source="task")

    monkeypatch.setitem(tasks._REGISTERED, "later", Missing)
    monkeypatch.delitem(tasks._INSTANCES, "later", raising=False)
    path = write(tmp_path, """
        experiments:
          - {task: later, dataset: {kind: synthetic}, methods: [x]}
          - {task: selftest, dataset: {kind: synthetic}, methods: [sleep]}
        """)
    with pytest.raises(ConfigError, match="needs lidarkit.nothing"):
        load_suite(path)
    suite = load_suite(path, skip_unavailable=True)
    assert [j.task for j in suite.jobs] == ["selftest"]
    assert suite.skipped == [("later_0", "needs lidarkit.nothing")]
    from lidarkit.bench.report import build_report
    from lidarkit.bench.runner import run_suite

    run_suite(suite, tmp_path / "out", executor="serial")
    report = build_report(tmp_path / "out", plots=False)
    assert report.skipped == [("later_0", "needs lidarkit.nothing")]
    assert "<li>later_0: needs lidarkit.nothing</li>" in report.html_path.read_text()


def test_reader_path_options_resolve_against_dataset_then_suite_folder(tmp_path):
    from lidarkit.bench.datasets import resolve_option_paths

    (tmp_path / "data" / "scans").mkdir(parents=True)
    (tmp_path / "data" / "scans" / "poses.txt").write_text("")
    (tmp_path / "suites").mkdir()
    (tmp_path / "suites" / "times.txt").write_text("")
    spec = {"kind": "folder", "path": str(tmp_path / "data" / "scans"), "poses": "poses.txt",
            "timestamps": "times.txt", "poses_format": "kitti"}
    out = resolve_option_paths(spec, tmp_path / "suites")
    assert out["poses"] == str(tmp_path / "data" / "scans" / "poses.txt")  # inside the dataset folder
    assert out["timestamps"] == str(tmp_path / "suites" / "times.txt")  # beside the suite file
    assert out["poses_format"] == "kitti"  # not a path option: untouched
    sample = {"kind": "folder", "path": "sample:kitti_pair", "poses": "poses.txt"}
    assert resolve_option_paths(sample, tmp_path) == sample


def test_a_reader_path_option_is_never_found_from_the_working_directory(tmp_path, monkeypatch):
    """``poses: lidar_poses.txt`` found neither in the scan folder nor beside the suite was kept relative: each run read
    it from its own working directory, so one job key stood for two poses files (resumed with the other's APE)."""
    import shutil

    from lidarkit.bench.datasets import sample_path

    shutil.copytree(sample_path("kitti_pair"), tmp_path / "data" / "scans", ignore=shutil.ignore_patterns("*.md", "*.txt"))
    (tmp_path / "suites").mkdir()
    (tmp_path / "run").mkdir()
    identity = "1 0 0 0 0 1 0 0 0 0 1 0\n"
    (tmp_path / "run" / "lidar_poses.txt").write_text(identity * 2)  # only in the working directory
    monkeypatch.chdir(tmp_path / "run")
    path = write(tmp_path / "suites", """
        experiments:
          - task: odometry
            dataset: {kind: folder, path: ../data/scans, poses: lidar_poses.txt}
            methods: [vanilla]
        """)
    with pytest.raises(DataError) as info:
        load_suite(path)
    assert str(info.value) == (f"{path} (experiments[0].dataset, line 4): poses 'lidar_poses.txt' is found only from the "
                               f"working directory, neither in the dataset folder {tmp_path / 'data' / 'scans'} nor beside the "
                               f"suite file (in {tmp_path / 'suites'}): give it from the suite file's folder or absolute")
    (tmp_path / "suites" / "lidar_poses.txt").write_text(identity * 2)
    job = load_suite(path).jobs[0]
    assert job.dataset["poses"] == str(tmp_path / "suites" / "lidar_poses.txt")  # absolute: the key names the file
    monkeypatch.chdir(tmp_path)
    assert load_suite(path).jobs[0].key("0") == job.key("0")


def test_text_params_that_read_as_numbers_stay_text(tmp_path):
    """A string param "nan" / "Infinity" became a float at load (a ValueError traceback: "Out of range float values are
    not JSON compliant"), and log_warning "1" and "1.0" were refused as one job written two ways: they are two texts."""
    path = write(tmp_path, """
        experiments:
          - task: selftest
            dataset: {kind: synthetic}
            methods:
              - {name: fail, params: {message: "nan"}}
              - {name: sleep, params: {log_warning: "Infinity"}}
              - {name: sleep, params: {log_warning: "1"}}
              - {name: sleep, params: {log_warning: "1.0"}}
        """)
    assert [j.params for j in load_suite(path).jobs] == [
        {"message": "nan"}, {"log_warning": "Infinity"}, {"log_warning": "1"}, {"log_warning": "1.0"}]
    path.write_text(path.read_text().replace('log_warning: "1.0"', 'seconds: 1').replace('log_warning: "1"', 'seconds: "1.0"'))
    with pytest.raises(ConfigError, match=r"methods\[3\], line 9\): sleep\(seconds=1\) runs the same job as experiments\[0\]"
                       r".methods\[2\] \(a value written two ways"):
        load_suite(path)  # a number and a numeric string are still one value


def test_an_empty_suite_seed_list_is_named_where_it_is_written(tmp_path):
    """``seeds: []`` on line 2 read "(experiments[0].seeds, line 4): no seeds", blaming an experiment without seeds."""
    path = write(tmp_path, """
        seeds: []
        experiments:
          - task: selftest
            dataset: {kind: synthetic}
            methods: [sleep]
        """)
    with pytest.raises(ConfigError) as info:
        load_suite(path)
    assert str(info.value) == f"{path} (seeds, line 2): no seeds"
    path.write_text(path.read_text().replace("seeds: []", "seeds: [1]") + "    seeds: []\n")
    with pytest.raises(ConfigError) as info:
        load_suite(path)
    assert str(info.value) == f"{path} (experiments[0].seeds, line 7): no seeds"


def test_uninstalled_methods_are_skipped_only_when_asked(tmp_path, monkeypatch):
    from lidarkit.bench.tasks.selftest import SelfTestTask

    monkeypatch.setattr(SelfTestTask, "available_methods", lambda self: ["sleep"])  # as if 'burn' were an absent extra
    monkeypatch.setattr(SelfTestTask, "optional_methods", lambda self: ("burn",))
    path = write(tmp_path, """
        experiments:
          - {name: e, task: selftest, dataset: {kind: synthetic}, methods: [sleep, burn]}
        """)
    assert {j.method for j in load_suite(path).jobs} == {"sleep", "burn"}  # a plain run validates, never skips
    suite = load_suite(path, skip_unavailable=True)
    assert [j.method for j in suite.jobs] == ["sleep"]
    assert suite.skipped == [("e: burn", "method 'burn' is not installed (available: sleep)")]
    # a name that is no optional extra (a typo in a user's demo suite) is validated, not skipped as "not installed"
    path.write_text(path.read_text().replace("[sleep, burn]", "[sleep, slep]"))
    with pytest.raises(ConfigError, match="slep"):
        load_suite(path, skip_unavailable=True)
    from lidarkit.bench.tasks import get_task

    assert {"small_gicp", "genz"} <= set(get_task("odometry").optional_methods()) | set(get_task("icp_pair").optional_methods())


def test_a_demo_skipping_an_absent_extra_gives_the_pip_line_bench_gives(tmp_path, monkeypatch):
    """Without small_gicp, a demo said "method 'small_gicp' is not installed (available: ...)" where `lidarkit bench` on
    the same suite said "... not installed here: pip install 'lidarkit[gicp]'": the demo now gives bench's line."""
    from lidarkit.registration import registry as registry_module

    monkeypatch.delitem(registry_module._VARIANTS, "small_gicp", raising=False)  # as if the extra were not installed
    path = write(tmp_path, """
        experiments:
          - name: icp_kitti_pair
            task: icp_pair
            dataset: {kind: folder, path: "sample:kitti_pair"}
            options: {pairs: [[0, 1]], ground_truth_file: T_target_source.txt}
            methods: [vanilla, small_gicp]
        """)
    pip_line = "the 'small_gicp' variant needs the Python package 'small_gicp', not installed here: pip install 'lidarkit[gicp]'"
    suite = load_suite(path, skip_unavailable=True)
    assert [j.method for j in suite.jobs] == ["vanilla"]
    assert suite.skipped == [("icp_kitti_pair: small_gicp", pip_line)]
    with pytest.raises(ConfigError) as err:  # what bench says of the same file
        load_suite(path)
    assert str(err.value) == f"{path} (experiments[0].methods[1], line 7): {pip_line}"


def test_a_pf_suite_scoring_past_the_end_of_its_data_is_refused_before_running(tmp_path):
    """mse_start beyond the Freiburg data's steps passed validation (and --dry-run); every job then failed at its end."""
    from conftest import shared_path

    path = tmp_path / "pf.yaml"
    path.write_text(textwrap.dedent(f"""
        seeds: [0]
        experiments:
          - name: e
            task: pf
            dataset: {{kind: landmarks, path: "{shared_path('pf', 'robot_mapping_stachniss')}"}}
            options: {{mse_start: 100000}}
            methods: [particle_filter]
    """))
    with pytest.raises(ConfigError, match=r"pf.yaml \(experiments\[0\].options, line 7\): mse_start 100000 is not below the data's 331 steps"):
        load_suite(path)
    path.write_text(path.read_text().replace("100000", "10"))
    assert len(load_suite(path).jobs) == 1


def test_a_kitti_sequence_that_is_not_there_is_refused_with_the_suite(tmp_path):
    """sequence: "05" of a root that holds 00 only passed validation and --dry-run; every job then failed."""
    root = tmp_path / "kitti"
    (root / "sequences" / "00" / "velodyne").mkdir(parents=True)
    for frame in ("000000", "000001"):  # (two: one scan is refused too, scoring nothing)
        np.zeros((10, 4), dtype=np.float32).tofile(root / "sequences" / "00" / "velodyne" / f"{frame}.bin")
    path = tmp_path / "kitti.yaml"
    path.write_text(textwrap.dedent(f"""
        experiments:
          - task: odometry
            dataset: {{kind: kitti, path: "{root}", sequence: "05"}}
            methods: [kiss]
    """))
    with pytest.raises(DataError, match=r"kitti.yaml \(experiments\[0\].dataset, line 4\): .*sequence 05 not found"):
        load_suite(path)
    path.write_text(path.read_text().replace('"05"', '"00"'))
    assert len(load_suite(path).jobs) == 1


def test_a_validator_message_is_given_alone_without_pydantics_prefix(tmp_path):
    """``grid: {seconds: []}`` read "...grid: Value error, grid values of 'seconds' are empty; experiments[0].methods[0]:
    Input should be a valid string": pydantic's prefix, and the other branch of a method (a name) that a mapping is not."""
    path = write(tmp_path, """
        experiments:
          - task: selftest
            dataset: {kind: synthetic}
            methods:
              - name: sleep
                grid: {seconds: []}
        """)
    with pytest.raises(ConfigError) as info:
        load_suite(path)
    assert str(info.value) == (f"{path} (experiments[0].methods[0].grid, line 7): "
                               "experiments[0].methods[0].grid: grid values of 'seconds' are empty")
    path = write(tmp_path, """
        experiments:
          - task: selftest
            dataset: {kind: synthetic}
            methods: [3]
        """)
    with pytest.raises(ConfigError) as info:  # neither a mapping nor a name: both branches say what they take
        load_suite(path)
    assert str(info.value) == (f"{path} (experiments[0].methods[0], line 5): experiments[0].methods[0]: Input should be "
                               "a valid dictionary or instance of MethodSpec; experiments[0].methods[0]: Input should be "
                               "a valid string")


def test_an_option_in_a_selftest_dataset_is_refused_naming_file_and_line(tmp_path):
    """``dataset: {kind: synthetic, foo: 1}`` with the selftest task passed (``--dry-run`` exit 0): selftest reads
    nothing of its dataset, so the key was a typo accepted without a word. A task of its own on ``synthetic`` data may
    still read options there (``dataset_options_test_task`` above)."""
    path = write(tmp_path, """
        experiments:
          - task: selftest
            dataset: {kind: synthetic, foo: 1}
            methods: [random_walk]
        """)
    with pytest.raises(ConfigError) as info:
        load_suite(path)
    assert str(info.value) == (f"{path} (experiments[0].dataset, line 4): unknown option(s) foo for dataset kind "
                               "'synthetic' of task 'selftest'; it takes none (only a name)")
    path = write(tmp_path, """
        experiments:
          - task: dataset_options_test_task
            dataset: {kind: synthetic, size: 3}
            methods: [good]
        """)
    assert [job.dataset for job in load_suite(path).jobs] == [{"kind": "synthetic", "size": 3}]
