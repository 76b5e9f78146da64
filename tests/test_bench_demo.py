"""``lidarkit demo``: the bundled suites are valid; a reduced demo writes a well-formed report with all images."""

from __future__ import annotations

import json
import re

import pytest
from test_bench_report import check_html

from lidarkit.bench.demo import DEMO_QUICK_SUITE, DEMO_SUITE
from lidarkit.bench.results import load_results
from lidarkit.bench.suite import load_suite, read_suite_file
from lidarkit.cli import main


@pytest.mark.parametrize("suite_path", [DEMO_SUITE, DEMO_QUICK_SUITE], ids=["demo", "quick"])
def test_bundled_demo_suites_validate_and_run_or_explain_every_experiment(suite_path):
    model, _ = read_suite_file(suite_path)
    suite = load_suite(suite_path, skip_unavailable=True)
    ran = {job.experiment for job in suite.jobs}
    skipped = dict(suite.skipped)
    for experiment in model.experiments:
        assert (experiment.name in ran) != (experiment.name in skipped), experiment.name
    assert all(reason for reason in skipped.values())
    assert "icp_sim_street" in ran  # the simulator needs no bundled data: always part of the demo
    tasks = {job.task for job in suite.jobs}
    assert tasks <= {"icp_pair", "odometry", "pf", "vo"}


@pytest.mark.slow
def test_quick_demo_writes_a_complete_report(tmp_path, capsys):
    out = tmp_path / "demo"
    with pytest.raises(SystemExit) as exc:
        main(["demo", "--quick", "--out", str(out), "--executor", "serial"])
    assert exc.value.code == 0
    captured = capsys.readouterr()
    stdout = captured.out
    match = re.search(r"report: (\S+report\.html)", stdout)
    assert match, stdout[-2000:]
    html_path = out / "report.html"
    assert match.group(1) == str(html_path)
    assert "1.3034" in stdout  # the bundled trajectory evaluation (evo's reference APE)
    records = load_results(out)
    suite = load_suite(DEMO_QUICK_SUITE, skip_unavailable=True)
    assert {r["key"] for r in records} == {j.key() for j in suite.jobs}
    failed = [(r["job"]["method"], r["error"]) for r in records if r["status"] != "ok"]
    assert not failed
    images = check_html(html_path)
    # at least one trajectory + error-over-time plot per odometry dataset, and the tables
    assert len(images) >= 2
    text = html_path.read_text()
    assert "<h2>odometry</h2>" in text
    for experiment, reason in suite.skipped:
        assert f"skipped {experiment}" in captured.err
    manifest = json.loads((out / "suite.json").read_text())
    assert manifest["suite"] == "demo-quick"
    # rerunning resumes: nothing is recomputed
    with pytest.raises(SystemExit):
        main(["demo", "--quick", "--out", str(out), "--executor", "serial"])
    assert f"{len(records)} already done, 0 run now" in capsys.readouterr().out


def test_demo_refuses_quick_with_its_own_suite_and_a_typo_in_it(tmp_path, capsys):
    """--quick beside --suite was ignored; a user suite's misspelt method read "not installed" and the demo exited 0."""
    from conftest import cli_exit_code

    suite = tmp_path / "typo.yaml"
    suite.write_text("name: typo\nexperiments:\n  - task: selftest\n    dataset: {kind: synthetic}\n    methods: [random_walk]\n")
    assert cli_exit_code(["demo", "--quick", "--suite", str(suite), "--out", str(tmp_path / "d")]) == 1
    assert "--quick: --quick selects the reduced bundled suite" in capsys.readouterr().err
    icp = tmp_path / "icp.yaml"
    icp.write_text('name: t\nexperiments:\n  - task: icp_pair\n    dataset: {kind: folder, path: "sample:kitti_pair"}\n'
                   "    options: {pairs: [[0, 1]], ground_truth_file: T_target_source.txt}\n    methods: [vanila]\n")
    assert cli_exit_code(["demo", "--suite", str(icp), "--out", str(tmp_path / "d2")]) == 1
    assert "unknown ICP method 'vanila'" in capsys.readouterr().err



def test_demo_takes_progress_and_no_progress_as_bench_does(capsys):
    """bench, odometry and sim take --progress/--no-progress; demo refused --no-progress as an unknown option. (A demo
    run costs ~10 s, the bundled trajectories' evaluation included: the option is checked on the command and its help.)"""
    import typer

    from lidarkit.cli import app

    demo = typer.main.get_command(app).commands["demo"]
    bench = typer.main.get_command(app).commands["bench"]
    flags = {param.name: (param.opts, param.secondary_opts, param.default, param.help) for param in demo.params}
    assert flags["progress"][:3] == (["--progress"], ["--no-progress"], True)
    assert flags["progress"][3] == next(p.help for p in bench.params if p.name == "progress")  # the same words
    from conftest import cli_exit_code

    assert cli_exit_code(["demo", "--help"]) == 0
    text = " ".join(capsys.readouterr().out.replace("│", " ").split())
    assert "--progress --no-progress" in text and "Progress bar on stderr" in text
