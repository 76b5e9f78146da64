"""A bench results folder, its suite.json or a baseline given where a suite file is read: named, with the file to give."""

from __future__ import annotations

import textwrap

import pytest

from lidarkit.bench import load_suite, run_suite
from lidarkit.bench.baseline import record
from lidarkit.cli import main

SUITE = """
name: walks
experiments:
  - {name: walk, task: selftest, dataset: {kind: synthetic, name: synth}, methods: [random_walk]}
"""


def _run_cli(argv: list[str], capsys) -> tuple[int, str]:
    with pytest.raises(SystemExit) as exc:
        main(argv)
    return int(exc.value.code or 0), " ".join(capsys.readouterr().err.split())


@pytest.fixture()
def outputs(tmp_path, monkeypatch):
    """A suite file, the bench results folder it ran into and a baseline recorded from it."""
    monkeypatch.chdir(tmp_path)  # (a bench without --out writes under results/ here)
    suite = tmp_path / "walks.yaml"
    suite.write_text(textwrap.dedent(SUITE))
    run_suite(load_suite(suite), tmp_path / "res", executor="serial")
    record(suite, tmp_path / "bl", repeats=1)
    return suite, tmp_path / "res", tmp_path / "bl"


def test_bench_and_record_of_a_results_folder_name_the_suite_it_ran(outputs, tmp_path, capsys):
    """Both read "cannot read suite file: [Errno 21] Is a directory"."""
    suite, results, _ = outputs
    reason = (f"{results}: a bench results folder (jobs/, suite.json), not a suite file: give the suite file it ran "
              f"({suite}); its suite.json is bench's record of that run, not a suite")
    assert _run_cli(["bench", str(results), "--out", str(tmp_path / "again")], capsys) == (1, f"error: {reason}")
    assert _run_cli(["baseline", "record", str(results), "--out", str(tmp_path / "b2")], capsys) == (1, f"error: {reason}")
    assert not (tmp_path / "again").exists() and not (tmp_path / "b2").exists()


def test_a_results_suite_json_is_named_as_bench_s_record(outputs, capsys):
    """It read "unknown key 'jobs'; unknown key 'lidarkit_version'; unknown key 'skipped_experiments' (+4 more)"."""
    suite, results, _ = outputs
    code, err = _run_cli(["bench", str(results / "suite.json")], capsys)
    assert (code, err) == (1, f"error: {results / 'suite.json'}: bench's record of the jobs it ran (a results folder's "
                              f"suite.json), not a suite: give the suite file it ran ({suite})")


def test_a_baseline_folder_or_its_manifest_names_its_suite_yaml(outputs, tmp_path, capsys):
    _, _, baseline = outputs
    reason = f"{baseline}: a baseline folder (manifest.json), not a suite file: give its suite.yaml ({baseline / 'suite.yaml'})"
    assert _run_cli(["baseline", "record", str(baseline), "--out", str(tmp_path / "b2")], capsys) == (1, f"error: {reason}")
    assert _run_cli(["bench", str(baseline)], capsys) == (1, f"error: {reason}")
    assert _run_cli(["bench", str(baseline / "manifest.json")], capsys) == (
        1, f"error: {baseline / 'manifest.json'}: a baseline's manifest.json, not a suite: give the suite.yaml beside it")
    # the file named is one: the baseline records again from it
    assert load_suite(baseline / "suite.yaml").name == "walks"


def test_another_folder_is_no_suite_file(tmp_path, capsys):
    assert _run_cli(["bench", str(tmp_path)], capsys) == (
        1, f"error: {tmp_path}: a folder, not a suite file: a suite is a YAML file with an 'experiments' list "
           "(docs/benchmarks.md)")
