"""Reports: aggregated numbers, CSV/Markdown, and a well-formed self-contained HTML page whose images all exist."""

from __future__ import annotations

import base64
import csv
import math
import textwrap
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest

from lidarkit.bench.report import build_report
from lidarkit.bench.results import load_results
from lidarkit.bench.runner import run_suite
from lidarkit.bench.suite import load_suite
from lidarkit.cli import main
from lidarkit.errors import DataError

SUITE = """
name: report-test
seeds: [0, 1, 2]
experiments:
  - name: walk
    task: selftest
    dataset: {kind: synthetic, name: synth}
    methods:
      - name: random_walk
        params: {steps: 40}
        grid: {noise_m: [0.01, 0.03, 0.1]}
      - name: fail
"""

VOID = {"area", "base", "br", "col", "embed", "hr", "img", "input", "link", "meta", "source", "track", "wbr"}
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


class WellFormed(HTMLParser):
    """Checks that every non-void element is closed in order; collects image sources."""

    def __init__(self):
        super().__init__()
        self.stack: list[str] = []
        self.errors: list[str] = []
        self.images: list[str] = []
        self.saw_doctype = False

    def handle_decl(self, decl):
        self.saw_doctype = decl.lower() == "doctype html"

    def handle_starttag(self, tag, attrs):
        if tag == "img":
            self.images.append(dict(attrs).get("src", ""))
        if tag not in VOID:
            self.stack.append(tag)

    def handle_endtag(self, tag):
        if not self.stack or self.stack[-1] != tag:
            self.errors.append(f"unexpected </{tag}> with open {self.stack[-3:]}")
        else:
            self.stack.pop()


def check_html(path: Path) -> list[str]:
    """Parse the page; assert well formed; return image sources after checking each one resolves to a PNG."""
    parser = WellFormed()
    parser.feed(path.read_text(encoding="utf-8"))
    parser.close()
    assert parser.saw_doctype
    assert parser.errors == [] and parser.stack == []
    for src in parser.images:
        if src.startswith("data:image/png;base64,"):
            data = base64.b64decode(src.split(",", 1)[1], validate=True)
        else:
            target = path.parent / src
            assert target.is_file(), src
            data = target.read_bytes()
        assert data.startswith(PNG_MAGIC) and len(data) > 1000
    return parser.images


@pytest.fixture(scope="module")
def results_dir(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("report")
    (tmp / "suite.yaml").write_text(textwrap.dedent(SUITE))
    run_suite(load_suite(tmp / "suite.yaml"), tmp / "out", executor="serial")
    return tmp / "out"


def test_report_tables_are_mean_and_sample_std_over_seeds(results_dir):
    report = build_report(results_dir, plots=False)
    (table,) = report.tables
    assert table.task == "selftest"
    rows = {r.method: r for r in table.rows}
    assert set(rows) == {"random_walk(noise_m=0.01, steps=40)", "random_walk(noise_m=0.03, steps=40)",
                         "random_walk(noise_m=0.1, steps=40)", "fail"}
    values = [r["metrics"]["ape_rmse_m"] for r in load_results(results_dir)
              if r["job"]["params"].get("noise_m") == 0.03]
    mean, std, n = rows["random_walk(noise_m=0.03, steps=40)"].stats["ape_rmse_m"]
    assert n == 3
    assert mean == pytest.approx(np.mean(values), rel=1e-12)
    assert std == pytest.approx(np.std(values, ddof=1), rel=1e-12)
    assert (rows["fail"].n_ok, rows["fail"].n_failed) == (0, 3)
    assert math.isnan(rows["fail"].stats["ape_rmse_m"][0])
    assert len(report.failures) == 3

    with open(report.csv_path, newline="") as fh:
        lines = list(csv.DictReader(fh))
    row = next(r for r in lines if r["method"] == "random_walk(noise_m=0.03, steps=40)" and r["metric"] == "ape_rmse_m")
    assert float(row["mean"]) == pytest.approx(mean, rel=1e-12) and row["n"] == "3"
    from lidarkit.bench.report import format_stat, pivot

    header, prow = pivot(table, "ape_rmse_m")
    assert header == ["method", "synth"]
    # one experiment in the task: rows carry the method alone, not "walk: " on every row
    assert ["random_walk(noise_m=0.03, steps=40)", format_stat((mean, std, n))] in prow
    md = report.markdown_path.read_text()
    assert "APE RMSE [m], methods x datasets:" in md
    assert "| walk | synth | random_walk(noise_m=0.03, steps=40) | 3/0 |" in md
    assert "Failed jobs" in md


def test_html_is_well_formed_self_contained_and_every_image_exists(results_dir):
    report = build_report(results_dir)
    titles = [p.title for p in report.plots]
    assert any(t.startswith("Trajectories") for t in titles)
    assert any(t.startswith("Error over time") for t in titles)
    assert any(t.startswith("RMSE vs iteration") for t in titles)
    assert any(t.startswith("APE RMSE [m] vs noise_m") for t in titles)
    images = check_html(report.html_path)
    assert len(images) == len(report.plots)
    assert all(src.startswith("data:image/png;base64,") for src in images)
    for p in report.plots:  # the Markdown's image files exist too
        assert (results_dir / "plots" / p.filename).read_bytes().startswith(PNG_MAGIC)


def test_report_cli(results_dir, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["report", str(results_dir), "--no-plots"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert "report.html" in out and "12 results, 3 failed" in out


def test_report_on_a_folder_without_results(tmp_path):
    with pytest.raises(DataError, match="not a bench results folder"):
        build_report(tmp_path)
    (tmp_path / "suite.json").write_text("{}")  # a run stopped before its first job finished: not "not a results folder"
    with pytest.raises(DataError, match="no job has finished in this results folder yet .* run the suite again to resume"):
        build_report(tmp_path)
    (tmp_path / "jobs").mkdir()
    (tmp_path / "jobs" / "broken.json").write_text("{not json")
    with pytest.raises(DataError, match="no readable job results"):
        build_report(tmp_path)


def test_results_of_an_older_version_do_not_count_twice(tmp_path):
    from lidarkit.bench.jobs import Job
    from lidarkit.bench.results import make_record, write_result

    job = Job("selftest", "e", "synth", {"kind": "synthetic"}, "random_walk", {"steps": 10}, seed=0)
    outcome = {"status": "ok", "metrics": {"ape_rmse_m": 1.0}, "series": {}, "info": {}, "error": None,
               "runtime_s": 0.1, "finished_utc": "2026-01-01T00:00:00.000+00:00"}
    write_result(tmp_path, make_record(job, job.key("0.0.9"), "0.0.9", outcome))
    newer = {**outcome, "metrics": {"ape_rmse_m": 2.0}, "finished_utc": "2026-02-01T00:00:00.000+00:00"}
    write_result(tmp_path, make_record(job, job.key("0.1.0"), "0.1.0", newer))
    report = build_report(tmp_path, plots=False)
    (row,) = report.tables[0].rows
    assert row.stats["ape_rmse_m"] == (2.0, 0.0, 1)


@pytest.mark.parametrize("edit, reason", [
    (lambda r: r.update(metrics=None), "metrics is None, not a mapping"),
    (lambda r: r["metrics"].update(ape_rmse_m="x"), "metric ape_rmse_m is 'x', not a number"),
    (lambda r: r["job"].pop("experiment"), "job lacks experiment"),
    (lambda r: r["job"].update(added_later=1), "job has unknown added_later"),
    (lambda r: r.update(job=None), "'job' is NoneType, not a mapping"),
    (lambda r: r["job"].update(params=None), "job params is None, not a mapping"),
    (lambda r: r.update(runtime_s="1 s"), "runtime_s is '1 s', not a number"),
    (lambda r: r.update(warnings=5), "warnings is 5, not a list of text"),
])
def test_a_malformed_result_file_is_skipped_with_its_reason(tmp_path, caplog, edit, reason):
    """A result edited by hand (or written by another version) is left out with a one-line warning naming the file
    and what is wrong with it; the report, compare and a resumed bench read the other results."""
    import json

    from lidarkit.bench.jobs import Job
    from lidarkit.bench.results import make_record, write_result

    outcome = {"status": "ok", "metrics": {"ape_rmse_m": 1.0}, "series": {}, "info": {}, "error": None, "runtime_s": 0.1,
               "finished_utc": "2026-01-01T00:00:00.000+00:00"}
    paths = [write_result(tmp_path, make_record(job, job.key(), "1", outcome)) for job in
             (Job("selftest", "e", "synth", {"kind": "synthetic"}, "random_walk", {"steps": 10}, seed=s) for s in (0, 1))]
    record = json.loads(paths[0].read_text())
    edit(record)
    paths[0].write_text(json.dumps(record))
    assert len(load_results(tmp_path)) == 1
    assert f"ignoring {paths[0]}: {reason}" in caplog.text
    (row,) = build_report(tmp_path, plots=False).tables[0].rows
    assert row.n_ok == 1


def test_datasets_and_params_that_print_alike_are_separate_rows(tmp_path):
    """Two unnamed datasets of one kind, parameters equal to 6 digits, and a folder reused after the suite's
    options changed: each job is its own row (never pooled as if seeds of one), labelled by what differs."""
    suite = tmp_path / "suite.yaml"
    suite.write_text(textwrap.dedent("""
        seeds: [0, 1]
        experiments:
          - name: walk
            task: selftest
            datasets: [{kind: synthetic}, {kind: synthetic, name: synthetic}]
            methods:
              - name: random_walk
                grid: {noise_m: [0.5000001, 0.5000002]}
    """))
    loaded = load_suite(suite)
    assert sorted({job.dataset_name for job in loaded.jobs}) == ["synthetic", "synthetic(name=synthetic)"]
    assert sorted({job.method_label for job in loaded.jobs}) == ["random_walk(noise_m=0.5000001)", "random_walk(noise_m=0.5000002)"]
    run_suite(loaded, tmp_path / "out", executor="serial")
    rows = build_report(tmp_path / "out", plots=False).tables[0].rows
    assert len(rows) == 4 and all(row.n_ok == 2 for row in rows)
    # the folder reused with other task options: the old and the new jobs are separate rows, told apart by them
    from lidarkit.bench.jobs import Job
    from lidarkit.bench.results import make_record, write_result

    outcome = {"status": "ok", "metrics": {"ape_rmse_m": 1.0}, "series": {}, "info": {}, "error": None, "runtime_s": 0.1}
    for steps in (10, 20):
        job = Job("selftest", "e", "synth", {"kind": "synthetic"}, "random_walk", {}, seed=0, options={"steps": steps})
        write_result(tmp_path / "reused", make_record(job, job.key(), "1", outcome))
    rows = build_report(tmp_path / "reused", plots=False).tables[0].rows
    assert [row.dataset for row in rows] == ["synth(steps=10)", "synth(steps=20)"] and all(row.n_ok == 1 for row in rows)


def test_a_dataset_label_leaves_out_an_option_one_experiment_does_not_set(tmp_path):
    """Two experiments on one dataset, one with ``init_noise_m: 2.0``: the other's rows read
    ``k00(init_noise_m=None)`` where the option's default is 0; unset, it is left out, as a method label leaves out
    params it does not set."""
    from lidarkit.bench.jobs import Job
    from lidarkit.bench.results import make_record, write_result

    outcome = {"status": "ok", "metrics": {"ape_rmse_m": 1.0}, "series": {}, "info": {}, "error": None, "runtime_s": 0.1}
    for experiment, options in (("clean", {}), ("noisy", {"init_noise_m": 2.0, "init_noise_deg": 10.0})):
        job = Job("selftest", experiment, "k00", {"kind": "synthetic"}, "random_walk", {}, seed=0, options=options)
        write_result(tmp_path, make_record(job, job.key(), "1", outcome))
    rows = build_report(tmp_path, plots=False).tables[0].rows
    assert [(row.experiment, row.dataset) for row in rows] == [("clean", "k00"), ("noisy", "k00(init_noise_deg=10, init_noise_m=2)")]


def test_every_plot_has_its_own_file(tmp_path):
    """Experiments named "x/y" and "x y", and two datasets whose labels share their first 80 characters: each plot
    has its own file (report.md showed one experiment's trajectories under the other's caption)."""
    suite = tmp_path / "suite.yaml"
    suite.write_text(textwrap.dedent("""
        experiments:
          - name: random_walk_noise_sweep_on_the_synthetic_paths_for_the_paper_ablation
            task: selftest
            datasets: [{kind: synthetic, name: "path A (short)"}, {kind: synthetic, name: "path B (long)"}]
            methods: [random_walk]
          - {name: "x/y", task: selftest, dataset: {kind: synthetic, name: d}, methods: [random_walk]}
          - {name: "x y", task: selftest, dataset: {kind: synthetic, name: d}, methods: [random_walk]}
    """))
    run_suite(load_suite(suite), tmp_path / "out", executor="serial")
    report = build_report(tmp_path / "out")
    names = [p.filename for p in report.plots]
    assert len(names) == len(set(names)) and sum(name.startswith("traj_") for name in names) == 4
    links = [line for line in (tmp_path / "out" / "report.md").read_text().splitlines() if "](plots/" in line]
    assert len(links) == len({line.split("](plots/")[1] for line in links})
    build_report(tmp_path / "out", plots=False)  # a report without plots leaves none of the earlier report's behind
    assert not list((tmp_path / "out" / "plots").glob("*.png"))


def test_a_method_that_failed_on_most_seeds_is_not_the_best_and_its_cells_say_so(tmp_path):
    from lidarkit.bench.jobs import Job
    from lidarkit.bench.report import pivot, summary_rows
    from lidarkit.bench.results import make_record, write_result

    def result(method, seed, ape):
        job = Job("selftest", "e", "synth", {"kind": "synthetic"}, "random_walk", {"noise_m": method}, seed=seed)
        outcome = ({"status": "ok", "metrics": {"ape_rmse_m": ape}, "error": None, "runtime_s": 0.1} if ape is not None else
                   {"status": "failed", "metrics": {}, "error": {"type": "RuntimeError", "message": "lost"}, "runtime_s": 0.1})
        write_result(tmp_path, make_record(job, job.key(), "1", outcome))

    for seed in range(5):
        result(0.1, seed, 0.1 if seed == 0 else None)  # fragile: one lucky seed, four failures
        result(0.2, seed, 0.2 + 0.01 * seed)  # robust
    report = build_report(tmp_path, plots=False)
    _, rows = summary_rows(report)
    assert rows[0][3] == "random_walk(noise_m=0.2)"
    _, cells = pivot(report.tables[0], "ape_rmse_m")
    assert cells[0][1] == "0.1 (4 of 5 failed)"


def test_a_seed_without_a_value_is_counted_in_its_cell_and_such_a_row_is_not_the_best(tmp_path):
    """A seed whose metric was NaN / inf / null was dropped from its cell without a word (``0.001`` as if all seeds
    counted), and that row was named the best over its one finite seed."""
    from lidarkit.bench.jobs import Job
    from lidarkit.bench.report import _table_rows, pivot, summary_rows
    from lidarkit.bench.results import make_record, write_result
    from lidarkit.eval.report import json_safe

    for seed, nanny in enumerate((float("nan"), float("inf"), 0.001)):
        for noise_m, ape in ((0.1, nanny), (0.2, 0.2 + 0.01 * seed)):
            job = Job("selftest", "e", "synth", {"kind": "synthetic"}, "random_walk", {"noise_m": noise_m}, seed=seed)
            metrics = json_safe({"ape_rmse_m": ape})  # (as the worker stores them: NaN and inf become null)
            write_result(tmp_path, make_record(job, job.key(), "1", {"status": "ok", "metrics": metrics,
                                                                      "error": None, "runtime_s": 0.1}))
    report = build_report(tmp_path, plots=False)
    _, cells = pivot(report.tables[0], "ape_rmse_m")
    assert cells == [["random_walk(noise_m=0.1)", "0.001 (2 of 3 no value)"], ["random_walk(noise_m=0.2)", "0.21 ± 0.01"]]
    _, summary = summary_rows(report)
    assert summary[0][3:5] == ["random_walk(noise_m=0.2)", "0.21 ± 0.01"]
    _, rows = _table_rows(report.tables[0])
    assert rows[0][3:5] == ["3/0", "0.001 (2 of 3 no value)"]


def test_rows_of_different_alignments_say_theirs_and_are_not_ranked_together(tmp_path):
    """VO rows with SE(3)-aligned (GT scale) and Sim(3)-aligned APE shared one column "(SE(3)-aligned / Sim(3)-aligned)"
    with nothing per row, and the summary named one best method across the two alignments."""
    from lidarkit.bench.jobs import Job
    from lidarkit.bench.report import _table_rows, pivot, summary_rows
    from lidarkit.bench.results import make_record, write_result

    for method, ape, alignment in (("gt_scale", 0.005, "SE(3)-aligned"), ("mono", 0.015, "Sim(3)-aligned"),
                                   ("mono_fast", 0.02, "Sim(3)-aligned")):
        job = Job("selftest", "e", "synth", {"kind": "synthetic"}, method, {}, seed=0)
        write_result(tmp_path, make_record(job, job.key(), "1", {
            "status": "ok", "metrics": {"ape_rmse_m": ape}, "error": None, "runtime_s": 0.1,
            "info": {"metric_alignment": {"ape_rmse_m": alignment}}}))
    report = build_report(tmp_path, plots=False)
    _, summary = summary_rows(report)
    assert [row[2:6] for row in summary] == [["APE RMSE (SE(3)-aligned) [m]", "gt_scale", "0.005", "1"],
                                             ["APE RMSE (Sim(3)-aligned) [m]", "mono", "0.015", "2"]]
    _, cells = pivot(report.tables[0], "ape_rmse_m")
    assert cells == [["gt_scale", "0.005 [SE(3)-aligned]"], ["mono", "0.015 [Sim(3)-aligned]"], ["mono_fast", "0.02 [Sim(3)-aligned]"]]
    header, rows = _table_rows(report.tables[0])
    assert header[4] == "APE RMSE (SE(3)-aligned / Sim(3)-aligned) [m]" and rows[1][4] == "0.015 [Sim(3)-aligned]"


def test_report_csv_names_the_alignment_of_each_row(tmp_path):
    """report.csv gave a VO suite's SE(3)-aligned (GT scale) and Sim(3)-aligned APE two rows ``metric=ape_rmse_m``
    with nothing telling them apart, while report.md and report.html named each cell's alignment."""
    from lidarkit.bench.jobs import Job
    from lidarkit.bench.results import make_record, write_result

    for method, ape, alignment in (("gt_scale", 0.00222, "SE(3)-aligned"), ("mono", 0.0039, "Sim(3)-aligned")):
        job = Job("selftest", "e", "synth", {"kind": "synthetic"}, method, {}, seed=0)
        write_result(tmp_path, make_record(job, job.key(), "1", {
            "status": "ok", "metrics": {"ape_rmse_m": ape, "hz": 8.0}, "error": None, "runtime_s": 0.1,
            "info": {"metric_alignment": {"ape_rmse_m": alignment}}}))
    report = build_report(tmp_path, plots=False)
    with open(report.csv_path, newline="") as fh:
        header, *lines = list(csv.reader(fh))
    # the columns readers index keep their places; new ones are last
    assert header == ["task", "experiment", "dataset", "method", "metric", "mean", "std", "n", "n_ok", "n_failed",
                      "n_not_run", "median", "ci95_low", "ci95_high", "alignment", "n_rerun_failed", "lidarkit_version"]
    assert [(r[3], r[4], float(r[5]), r[14]) for r in lines] == [
        ("gt_scale", "ape_rmse_m", 0.00222, "SE(3)-aligned"), ("gt_scale", "hz", 8.0, ""), ("gt_scale", "runtime_s", 0.1, ""),
        ("mono", "ape_rmse_m", 0.0039, "Sim(3)-aligned"), ("mono", "hz", 8.0, ""), ("mono", "runtime_s", 0.1, "")]


def test_each_trajectory_is_drawn_with_the_reference_of_its_own_seed(tmp_path):
    """The trajectory plot drew every method against the reference of the first chosen record: a method whose first
    good seed was 1 (another simulated drive) was drawn against seed 0's path."""
    from lidarkit.bench.jobs import Job
    from lidarkit.bench.report import _first_ok_per_method, _references
    from lidarkit.bench.results import make_record, write_result

    def path(seed):
        return [[0.0, 0.0], [10.0, 8.0 * seed]]

    for method, seed, ok in (("a_good", 0, True), ("a_good", 1, True), ("b_flaky", 0, False), ("b_flaky", 1, True)):
        job = Job("selftest", "d", "sim", {"kind": "synthetic"}, method, {}, seed=seed)
        series = {"trajectory_xy": {"ref": path(seed), "est": [[x, y + 0.2] for x, y in path(seed)]}}
        outcome = ({"status": "ok", "metrics": {"ape_rmse_m": 0.28}, "series": series, "error": None, "runtime_s": 0.1} if ok
                   else {"status": "failed", "metrics": {}, "error": {"type": "RuntimeError", "message": "diverged"}, "runtime_s": 0.1})
        write_result(tmp_path, make_record(job, job.key(), "1", outcome))
    chosen, _ = _first_ok_per_method(load_results(tmp_path), "trajectory_xy")
    assert {label: r["job"]["seed"] for label, r in chosen.items()} == {"a_good": 0, "b_flaky": 1}
    refs, ref_of = _references(chosen)
    assert list(refs) == ["reference (seed 0)", "reference (seed 1)"]
    assert refs["reference (seed 0)"].tolist() == path(0) and refs["reference (seed 1)"].tolist() == path(1)
    assert ref_of == {"a_good": "reference (seed 0)", "b_flaky": "reference (seed 1)"}
    plot = next(p for p in build_report(tmp_path).plots if p.title.startswith("Trajectories"))
    assert "against the reference of that seed" in plot.caption


def test_a_pipe_in_a_name_does_not_break_the_markdown_tables(tmp_path):
    from lidarkit.bench.jobs import Job
    from lidarkit.bench.results import make_record, write_result

    for seed in (0, 1):
        job = Job("selftest", "e", "a|b", {"kind": "synthetic"}, "random_walk", {}, seed=seed)
        write_result(tmp_path, make_record(job, job.key(), "1", {"status": "ok", "metrics": {"ape_rmse_m": 1.0 + seed},
                                                                 "error": None, "runtime_s": 0.1}))
    md = build_report(tmp_path, plots=False).markdown_path.read_text()
    named = [line for line in md.splitlines() if "a" in line and "b |" in line and line.startswith("| ")]
    assert named and all("a\\|b" in line for line in named)  # escaped in every table (the pivot's header too)


def test_the_report_holds_the_suite_last_run_in_the_folder_and_says_what_is_missing(tmp_path, capsys):
    """A folder reused by an edited suite keeps the earlier suite's results: the report holds the jobs of suite.json
    (the others counted as left out, ``--all`` takes them); the suite's jobs without a result are named, their rows
    say how many seeds were not run, and such a row is ranked against the others on the seeds they share."""
    from lidarkit.bench.report import pivot, summary_rows
    from lidarkit.bench.results import result_path

    (tmp_path / "a.yaml").write_text(textwrap.dedent(SUITE))  # 3 seeds x (3 noise levels + fail) = 12 jobs
    run_suite(load_suite(tmp_path / "a.yaml"), tmp_path / "out", executor="serial")
    edited_text = (SUITE.replace("name: report-test", "name: edited").replace("seeds: [0, 1, 2]", "seeds: [0, 1]")
                   .replace("[0.01, 0.03, 0.1]", "[0.01, 0.5]").replace("      - name: fail\n", ""))
    assert edited_text.count("fail") == 0 and "[0.01, 0.5]" in edited_text  # the suite edited: 2 seeds x 2 noise levels
    (tmp_path / "b.yaml").write_text(textwrap.dedent(edited_text))
    edited = load_suite(tmp_path / "b.yaml")
    run_suite(edited, tmp_path / "out", executor="serial")
    report = build_report(tmp_path / "out", plots=False)
    assert sorted(row.method for row in report.tables[0].rows) == ["random_walk(noise_m=0.01, steps=40)", "random_walk(noise_m=0.5, steps=40)"]
    assert all(row.n_ok == 2 for row in report.tables[0].rows)  # the 0.01 row was 3 seeds: the earlier suite's seed 2
    assert (report.n_records, report.n_expected, report.n_left_out, report.not_run) == (4, 4, 10, [])
    assert "10 results in jobs/ of jobs not in the folder's suite.json" in (tmp_path / "out" / "report.md").read_text()
    assert len(build_report(tmp_path / "out", plots=False, every_result=True).tables[0].rows) == 5
    with pytest.raises(SystemExit) as exc:
        main(["report", str(tmp_path / "out"), "--all", "--no-plots"])
    assert exc.value.code == 0
    assert "14 results, 3 failed" in capsys.readouterr().out

    # an interrupted run: the better method has one seed so far
    low_noise = next(job for job in edited.jobs if job.params["noise_m"] == 0.01 and job.seed == 1)
    result_path(tmp_path / "out", low_noise.key()).unlink()
    report = build_report(tmp_path / "out", plots=False)
    assert report.not_run == ["selftest | walk | synth | random_walk(noise_m=0.01, steps=40) | seed 1"]
    _, cells = pivot(report.tables[0], "ape_rmse_m")
    assert cells[0][1].endswith("(1 of 2 not run)")
    _, summary = summary_rows(report)
    # a seed not run is no failure: the better method on the seed both ran (it was the complete row, its mean larger)
    assert summary[0][3] == "random_walk(noise_m=0.01, steps=40)"
    assert summary[0][4].endswith("(1 of 2 not run) (ranked on the common seeds 0)"), summary[0][4]
    text = (tmp_path / "out" / "report.md").read_text()
    assert "3 job results of the suite's 4 jobs (1 not run yet)" in text and "## Jobs of the suite without a result" in text


def test_results_of_an_earlier_lidarkit_version_are_counted_and_named_as_such(tmp_path, capsys):
    """After a source change the report said "47 results in jobs/ of jobs not in the folder's suite.json (an earlier
    suite) left out" of the same suite's 59 older results: counted after one result per job was kept, and named as
    an earlier suite's though only the lidarkit version (and so the key) differed."""
    from lidarkit.bench.jobs import Job
    from lidarkit.bench.results import make_record, result_path, write_result

    (tmp_path / "a.yaml").write_text(textwrap.dedent(SUITE))  # 12 jobs
    suite = load_suite(tmp_path / "a.yaml")
    run_suite(suite, tmp_path / "out", executor="serial")
    for record in load_results(tmp_path / "out"):  # the same jobs as an earlier version ran them
        job = Job.from_spec(record["job"])
        old = {k: v for k, v in record.items() if k not in ("schema", "key", "lidarkit_version", "job")}
        write_result(tmp_path / "out", make_record(job, job.key("0.0.9"), "0.0.9", {**old, "finished_utc": "2026-01-01"}))
    for job in suite.jobs[4:]:  # this version ran 4 of them so far
        result_path(tmp_path / "out", job.key()).unlink()
    other = Job("selftest", "gone", "synth", {"kind": "synthetic"}, "random_walk", {"steps": 5})  # an earlier suite's
    write_result(tmp_path / "out", make_record(other, other.key("0.0.9"), "0.0.9", {"status": "ok", "metrics": {}}))
    from conftest import cli_exit_code

    assert cli_exit_code(["report", str(tmp_path / "out"), "--no-plots"]) == 0
    assert ("4 results of the suite's 12 jobs (8 not run yet); 12 results in jobs/ of these jobs from an earlier lidarkit "
            "version left out; 1 results in jobs/ of jobs not in the folder's suite.json (an earlier suite) left out, ") in (
        " ".join(capsys.readouterr().out.split()))
    report = build_report(tmp_path / "out", plots=False)
    assert (report.n_records, report.n_expected, len(report.not_run), report.n_left_out, report.n_earlier_version) == (4, 12, 8, 13, 12)
    # --all: the most recent result of each job (8 of the earlier version); the 4 it superseded are left out
    report = build_report(tmp_path / "out", plots=False, every_result=True)
    assert (report.n_records, report.n_left_out, report.n_earlier_version) == (13, 4, 4)


def test_an_earlier_reports_plots_and_tables_do_not_stay_beside_the_new_ones(results_dir, tmp_path):
    import shutil

    folder = tmp_path / "reused"
    shutil.copytree(results_dir, folder)
    (folder / "tables").mkdir(exist_ok=True)
    (folder / "plots").mkdir(exist_ok=True)
    for stale in ("tables/kitti_translation_pct.md", "tables/kitti_translation_pct.tex", "plots/segments_translation_pct.png"):
        (folder / stale).write_text("an earlier suite's (odometry over 100 m)")
    (folder / "tables" / "my_notes.md").write_text("mine")
    report = build_report(folder)
    assert sorted(p.name for p in (folder / "plots").iterdir()) == sorted(p.filename for p in report.plots)
    assert sorted(p.name for p in (folder / "tables").iterdir()) == ["my_notes.md"]


def test_a_report_that_cannot_be_written_leaves_the_earlier_plots_and_tables(results_dir, tmp_path):
    """report.html in the way (a folder): the report failed only after it had removed the earlier report's plots/ and
    tables/, so neither the old report nor a new one had its figures."""
    import shutil

    from lidarkit.errors import OutputError

    folder = tmp_path / "reused"
    shutil.copytree(results_dir, folder)
    build_report(folder)
    (folder / "tables").mkdir(exist_ok=True)
    (folder / "tables" / "ape_rmse.md").write_text("an earlier report's table")
    before = {p.name: p.read_bytes() for p in (folder / "plots").iterdir()}
    assert len(before) >= 3
    (folder / "report.html").unlink()
    (folder / "report.html").mkdir()
    with pytest.raises(OutputError) as info:
        build_report(folder, plots=False)
    assert str(info.value) == f"{folder / 'report.html'}: cannot write: is a folder (a file name is needed here)"
    assert {p.name: p.read_bytes() for p in (folder / "plots").iterdir()} == before
    assert (folder / "tables" / "ape_rmse.md").read_text() == "an earlier report's table"
    (folder / "report.html").rmdir()
    build_report(folder, plots=False)  # written: now the earlier figures and tables go
    assert not list((folder / "plots").iterdir()) and not list((folder / "tables").iterdir())


def test_a_suite_job_whose_result_cannot_be_read_is_not_called_not_run(tmp_path):
    """A job of the suite whose result file is damaged was listed as 'not run yet', as if it had never run."""
    from lidarkit.bench.report import coverage_text
    from lidarkit.bench.results import result_path

    suite = tmp_path / "suite.yaml"
    suite.write_text(textwrap.dedent("""
        seeds: [0, 1, 2]
        experiments:
          - {name: walk, task: selftest, dataset: {kind: synthetic, name: synth}, methods: [random_walk]}
    """))
    run_suite(load_suite(suite), tmp_path / "out", executor="serial")
    damaged = sorted((tmp_path / "out" / "jobs").glob("*.json"))[0]
    damaged.write_text("{")
    report = build_report(tmp_path / "out", plots=False)
    assert len(report.not_run) == 1 and report.not_run[0].endswith("(its result file cannot be read: see the log)")
    assert coverage_text(report) == " of the suite's 3 jobs (0 not run yet, 1 with a result file that cannot be read)"
    assert result_path(tmp_path / "out", damaged.stem).exists()


def test_plots_say_which_methods_they_leave_out_and_sweeps_keep_experiments_apart(tmp_path):
    """12 methods were drawn as 8 with nothing said (plain random_walk among those dropped); a sweep over two
    experiments on one dataset averaged them into one line."""
    suite = tmp_path / "suite.yaml"
    suite.write_text(textwrap.dedent("""
        seeds: [0, 1]
        experiments:
          - name: many
            task: selftest
            dataset: {kind: synthetic, name: d}
            methods: [{name: random_walk, grid: {steps: [10, 11, 12, 13, 14, 15, 16, 17, 18, 19]}}]
          - name: short
            task: selftest
            dataset: {kind: synthetic, name: d}
            methods: [{name: random_walk, params: {steps: 10}, grid: {noise_m: [0.01, 0.1]}}]
          - name: long
            task: selftest
            dataset: {kind: synthetic, name: d}
            methods: [{name: random_walk, params: {steps: 40}, grid: {noise_m: [0.01, 0.1]}}]
    """))
    run_suite(load_suite(suite), tmp_path / "out", executor="serial")
    report = build_report(tmp_path / "out")
    traj = next(p for p in report.plots if p.title.startswith("Trajectories") and "many" in p.title)
    assert "8 of 10 shown; left out: random_walk(steps=18), random_walk(steps=19)." in traj.caption
    sweep = next(p for p in report.plots if p.filename.startswith("sweep_"))
    assert "one line per experiment, dataset and method" in sweep.caption and "left out" not in sweep.caption


def test_a_sweep_over_zero_draws_every_point(tmp_path):
    """A sweep plot took a log x axis where its values spanned a factor of 10, the smallest clamped to 1e-12: a grid
    noise_m [0, 0.1, 1, 2] was drawn without its 0 point, and nothing said so."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from lidarkit.bench.jobs import Job
    from lidarkit.bench.results import make_record, write_result

    grid = [0.0, 0.1, 1.0, 2.0]
    for noise in grid:
        job = Job("selftest", "e", "synth", {"kind": "synthetic"}, "random_walk", {"noise_m": noise}, seed=0)
        write_result(tmp_path, make_record(job, job.key(), "1", {
            "status": "ok", "metrics": {"ape_rmse_m": 0.01 + noise}, "error": None, "runtime_s": 0.1}))
    (sweep,) = [p for p in build_report(tmp_path).plots if p.filename.startswith("sweep_")]
    assert sweep.caption == ("APE RMSE [m] against noise_m: mean ± std over seeds, one line per experiment, dataset and "
                             "method; symmetric log x axis, linear within ±0.1.")
    from lidarkit.bench.report import sweep_x_scale

    scale, args, _ = sweep_x_scale(grid)
    assert (scale, args) == ("symlog", {"linthresh": 0.1})
    fig, ax = plt.subplots()
    ax.set_xscale(scale, **args)
    assert np.isfinite(ax.xaxis.get_transform().transform(np.asarray(grid))).all()  # (a log axis maps 0 to -inf)
    plt.close(fig)
    assert sweep_x_scale([0.1, 1.0, 2.0]) == ("log", {}, "; log x axis")  # positive values alone: log as before
    assert sweep_x_scale([0.0, 1.0, 2.0]) == ("linear", {}, "")  # a span of less than 10 above 0: linear


def test_one_seed_has_no_spread_and_an_unreported_count_is_not_zero(tmp_path):
    """report.csv gave one seed a std of 0 and a CI [v, v]; kiss's iterations (which kiss-icp does not report) read
    as a measured 0 +- 0."""
    import csv
    import io

    suite = tmp_path / "suite.yaml"
    suite.write_text(textwrap.dedent("""
        seeds: 1
        experiments:
          - name: p
            task: icp_pair
            dataset: {kind: sim_lidar, scene: street, n_frames: 3, n_beams: 8, n_azimuths: 360}
            options: {max_pairs: 1}
            methods: [kiss, vanilla]
    """))
    run_suite(load_suite(suite), tmp_path / "out", executor="serial")
    build_report(tmp_path / "out")
    rows = {(r["method"], r["metric"]): r for r in csv.DictReader(io.StringIO((tmp_path / "out" / "report.csv").read_text()))}
    assert rows[("kiss", "iterations")]["mean"] == "" and rows[("kiss", "iterations")]["median"] == ""
    vanilla = rows[("vanilla", "iterations")]
    assert float(vanilla["mean"]) > 0 and vanilla["std"] == "" and vanilla["ci95_low"] == "" and vanilla["n"] == "1"


def test_lists_cut_short_say_how_many_more(tmp_path, capsys):
    """130 job warnings showed the first 100 and 25 failed jobs the first 20, each without a word of the rest."""
    from conftest import cli_exit_code

    suite = tmp_path / "many.yaml"
    suite.write_text(textwrap.dedent("""
        name: many
        seeds: 25
        experiments:
          - task: selftest
            dataset: {kind: synthetic}
            methods: [{name: fail}]
          - task: selftest
            dataset: {kind: synthetic}
            methods: [{name: sleep, params: {seconds: 0.0, log_warning: careful}}]
            seeds: 110
    """))
    assert cli_exit_code(["bench", str(suite), "--out", str(tmp_path / "r"), "--executor", "serial"]) == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "... and 5 more failed jobs (the report lists every one)" in out
    text = (tmp_path / "r" / "report.md").read_text()
    assert "and 10 more job warnings" in text


def test_reference_comparisons_pair_seeds_as_compare_does_and_say_when_segments_overlap():
    """The demo's report said "kiss better, p = 0.002 over 10 paired segments" (5 overlapping segments of each of 2
    drives) where `lidarkit compare` on the same folder said no difference over 2 seeds. With 6 or more seeds the
    report pairs seeds (their drift, as compare); with fewer, its segment test says the segments overlap."""
    from lidarkit.bench.jobs import Job
    from lidarkit.bench.publication import OVERLAPPING_SEGMENTS, reference_comparisons
    from lidarkit.bench.report import comparison_rows

    def record(method, seed, drift, segments):
        job = Job("odometry", "e", "drive", {"kind": "sim_lidar", "scene": "street"}, method, seed=seed)
        return {"status": "ok", "job": job.spec(), "metrics": {"drift_translation_pct": drift, "ape_rmse_m": drift / 10},
                "series": {"drift_segments": {"translation_pct": segments}}}

    rng = np.random.default_rng(0)
    def records(n_seeds):
        return [record(m, s, d + 0.1 * rng.random(), list(d + 0.01 * rng.random(5)))
                for s in range(n_seeds) for m, d in (("kiss", 0.5), ("small_gicp", 1.5))]

    (dataset, few), = reference_comparisons(records(2))
    assert few.pairing == "segment" and few.n_pairs == 10 and few.note == OVERLAPPING_SEGMENTS
    assert comparison_rows([(dataset, few)])[1][0][-1] == "kiss better (overlapping segments: p optimistic)"
    (_, many), = reference_comparisons(records(6))
    assert many.pairing == "seed" and many.n_pairs == 6 and many.metric == "KITTI drift %" and many.better == "a"


def test_reference_comparisons_pair_segments_by_first_frame_and_length_and_note_other_instants():
    """The report paired two methods' KITTI segments by position and dropped the comparison without a word when their
    counts differed (kiss scored at the sweep end, small_gicp at its middle: a 200 m segment on one truth only), and
    did not say the sides were scored at other instants (``lidarkit compare`` did). Segments now pair by first frame
    and length as compare pairs them, the ones left out and the instants are noted under the table."""
    from types import SimpleNamespace

    from lidarkit.bench.jobs import Job
    from lidarkit.bench.publication import OVERLAPPING_SEGMENTS, reference_comparisons
    from lidarkit.bench.report import comparison_notes
    from lidarkit.bench.tasks.odometry import drift_segments
    from lidarkit.eval.tables import SegmentErrors
    from lidarkit.trajectory import Trajectory

    # a record's series keeps each segment's first frame (a 150 m straight drive at 1 m a frame: 100 m segments)
    poses = np.tile(np.eye(4), (151, 1, 1))
    poses[:, 0, 3] = np.arange(151.0)
    truth = Trajectory(poses, np.arange(151) * 0.1, "gt")
    series = drift_segments(SimpleNamespace(ground_truth=truth, trajectory=truth))
    assert series["first_frame"] == list(range(0, 41, 10)) and series["length_m"] == [100.0] * 5
    assert SegmentErrors.from_dict(series).first_frame.tolist() == list(range(0, 41, 10))

    def record(method, seed, instant, keys, drift):
        job = Job("odometry", "e", "drive", {"kind": "sim_lidar", "scene": "street"}, method, seed=seed)
        first, length = zip(*keys)
        return {"status": "ok", "job": job.spec(), "metrics": {"drift_translation_pct": float(np.mean(drift))},
                "info": {"odometry_metrics": {"effective": {"ground_truth_instant": instant}}},
                "series": {"drift_segments": {"first_frame": list(first), "length_m": list(length),
                                              "translation_pct": list(drift)}}}

    kiss_keys = [(0, 100.0), (10, 100.0), (20, 100.0), (0, 200.0)]
    gicp_keys = [(0, 100.0), (10, 100.0), (20, 100.0), (30, 100.0)]  # no 200 m segment on the mid-sweep truth
    records = [record("kiss", s, "end", kiss_keys, [0.5 + s, 0.6 + s, 0.7 + s, 9.0]) for s in (0, 1)]
    records += [record("small_gicp", s, "mid", gicp_keys, [1.5 + s, 1.6 + s, 1.7 + s, 1.8]) for s in (0, 1)]
    (dataset, c), = reference_comparisons(records)
    assert c.pairing == "segment" and c.n_pairs == 6 and c.mean_a == pytest.approx(1.1) and c.mean_b == pytest.approx(2.1)
    assert c.note == (f"{OVERLAPPING_SEGMENTS}; 4 KITTI segment(s) on only one side's ground truth left out (paired by "
                      "first frame and length); each side is scored against the ground truth at its own instant of the "
                      "sweep (kiss: sweep end, small_gicp: sweep mid)")
    assert comparison_notes([(dataset, c)]) == [f"{dataset}, kiss vs small_gicp: {c.note}"]



def test_a_comparison_with_p_below_alpha_and_no_verdict_says_its_ci_includes_0(tmp_path):
    """The demo's report.md and report.html showed p = 0.049 beside "no significant difference" without the reason the
    terminal gave: the 95 % CI of the median difference includes 0 (compare's rule). The row shows the CI and says so."""
    import html

    from lidarkit.bench.jobs import Job
    from lidarkit.bench.results import make_record, write_result

    diffs = (0.05, 0.1, -1.0, -2.0, -3.0, -4.0, -5.0, -6.0)  # Wilcoxon p = 0.039; the median's CI [-5, +0.05]
    for seed, diff in enumerate(diffs):
        for method, drift in (("kiss", 10.0 + diff), ("small_gicp", 10.0)):
            job = Job("odometry", "e", "drive", {"kind": "sim_lidar", "scene": "street"}, method, seed=seed)
            outcome = {"status": "ok", "metrics": {"drift_translation_pct": drift}, "error": None, "runtime_s": 0.1}
            write_result(tmp_path, make_record(job, job.key(), "1", outcome))
    build_report(tmp_path, plots=False)
    row = ("| drive | kiss | small_gicp | 8 seeds (KITTI drift %) | 7.394 | 10 | 0.039 | -0.83 | -2.5 [-5, +0.05] "
           "| no significant difference (CI includes 0) |")
    assert row in (tmp_path / "report.md").read_text().splitlines()
    page = (tmp_path / "report.html").read_text()
    assert "<th>median A - B (95 % CI)</th>" in page
    cells = "".join(f"<td>{html.escape(c)}</td>" for c in ("-2.5 [-5, +0.05]", "no significant difference (CI includes 0)"))
    assert cells in page


def test_reference_comparisons_count_seeds_that_ran_the_same_data_once():
    """An unseeded dataset (its own seed fixed) run with 3 seeds: the report pooled the same 2 segments once per seed,
    6 units, "kiss better, p = 0.031", where one seed's 2 give p = 0.5; with 6 such seeds it printed p = 0.031 and
    effect -1.00 beside "no significant difference". Seeds alike on both sides count once, and a repeated measurement
    is said to be one, with no p (as lidarkit compare says it)."""
    from lidarkit.bench.jobs import Job
    from lidarkit.bench.publication import reference_comparisons
    from lidarkit.bench.report import comparison_rows

    def record(method, seed, drift, ape):
        job = Job("odometry", "e", "fixed", {"kind": "sim_lidar", "scene": "street", "seed": 3}, method, seed=seed)
        return {"status": "ok", "job": job.spec(), "metrics": {"ape_rmse_m": ape},
                "series": {"drift_segments": {"first_frame": [0, 10], "length_m": [100.0, 100.0], "translation_pct": drift}}}

    few = [record(m, s, d, a) for s in range(3) for m, d, a in (("kiss", [0.40, 0.41], 0.12), ("small_gicp", [0.50, 0.52], 0.23))]
    (_, c), = reference_comparisons(few)
    assert c.n_pairs == 2 and not c.better and "the 3 seeds ran the same data" in c.note
    many = [record(m, s, d, a) for s in range(6) for m, d, a in (("kiss", [0.40, 0.41], 0.12), ("small_gicp", [0.50, 0.52], 0.23))]
    (dataset, c), = reference_comparisons(many)
    assert c.pairing == "seed" and c.repeated
    row = comparison_rows([(dataset, c)])[1][0]
    assert (row[6], row[7], row[-1]) == ("–", "–", "one measurement repeated (every seed gave each side the same value): no test")


def test_publication_tables_average_over_common_seeds_and_the_summary_says_when_seeds_differ(tmp_path):
    """kiss over seeds 0-4 and ground_filtered over 1 and 3 (another experiment, or the rest failed): the APE table set
    ground_filtered's 0.46 bold against kiss's 0.64, where on seeds 1 and 3 kiss was better (0.33), and the Summary
    named it best, neither saying the seeds differed. The tables now average every method over the common seeds and
    say which were left out; the Summary ranks the rows on the common seeds too, and says so."""
    from lidarkit.bench.jobs import Job
    from lidarkit.bench.results import make_record, write_result

    ape = {"kiss": {0: 1.0, 1: 0.3, 2: 1.0, 3: 0.36, 4: 0.54}, "ground_filtered": {1: 0.4, 3: 0.52}}
    for method, per_seed in ape.items():
        for seed, value in per_seed.items():
            job = Job("odometry", f"e_{method}", "drive", {"kind": "sim_lidar", "scene": "street"}, method, seed=seed)
            outcome = {"status": "ok", "metrics": {"ape_rmse_m": value, "ape_se3_rmse_m": value}, "error": None, "runtime_s": 0.1}
            write_result(tmp_path, make_record(job, job.key(), "1", outcome))
    build_report(tmp_path, plots=False)
    table = (tmp_path / "tables" / "ape_rmse.md").read_text()
    assert "| drive | **0.330** | 0.460 |" in table or "| drive | 0.460 | **0.330** |" in table, table
    assert "Means over common seeds, drive: seeds 1, 3 of every method (left out: kiss 0, 2, 4)." in table
    assert "seeds 1, 3 of every method" in (tmp_path / "tables" / "ape_rmse.tex").read_text()
    summary = next(line for line in (tmp_path / "report.md").read_text().splitlines() if line.startswith("| odometry | drive"))
    # ranked as the tables average: over the common seeds, where kiss is better (it named ground_filtered over its own)
    assert "| e_kiss: kiss | 0.64 ± 0.34 (ranked on the common seeds 1, 3: 0.33 there) |" in summary, summary
    # and no comparison with the reference is said, not left out without a word
    assert ("- no comparison: drive, kiss vs ground_filtered: 2 common seed(s) (a comparison over seeds needs 6) and no "
            "KITTI segments to pair (a path under 100 m)") in (tmp_path / "report.md").read_text().splitlines()
    # where the tables are, from the report (it named the folder's last name only: `suite/tables/` for runs/suite)
    assert "Also as CSV and LaTeX (booktabs) in `tables/` beside this report." in (tmp_path / "report.md").read_text()


ODOMETRY_AND_PAIRS = """
name: odometry-and-pairs
experiments:
  - name: odo
    task: odometry
    dataset: {{kind: kitti, path: "{root}", sequence: "00", name: K00}}
    options: {{frames: "0:3"}}
    methods: [kiss]
  - name: pair
    task: icp_pair
    dataset: {{kind: kitti, path: "{root}", sequence: "00", name: K00}}
    methods: [vanilla]
"""


@pytest.fixture(scope="module")
def odometry_dir(tmp_path_factory):
    """Odometry (3 real KITTI frames: publication tables) and an ICP pair on the same dataset name, K00."""
    from conftest import shared_path

    tmp = tmp_path_factory.mktemp("odometry")
    (tmp / "suite.yaml").write_text(ODOMETRY_AND_PAIRS.format(root=shared_path("kitti_odometry")))
    run_suite(load_suite(tmp / "suite.yaml"), tmp / "out", executor="serial")
    return tmp / "out"


def test_a_figure_a_user_put_in_plots_is_kept(results_dir, tmp_path):
    """The next report deleted every PNG of plots/ it did not draw, a user's own figure1.png too: only figures of the
    names a report draws go."""
    import shutil

    folder = tmp_path / "reused"
    shutil.copytree(results_dir, folder)
    (folder / "plots").mkdir(exist_ok=True)
    (folder / "plots" / "figure1.png").write_bytes(b"mine")
    (folder / "plots" / "traj_selftest_e_synth_0123abcd.png").write_bytes(b"an earlier report's")
    report = build_report(folder)
    assert sorted(p.name for p in (folder / "plots").iterdir()) == sorted([p.filename for p in report.plots] + ["figure1.png"])
    assert (folder / "plots" / "figure1.png").read_bytes() == b"mine"


def test_a_report_that_fails_after_its_figures_keeps_the_earlier_report_whole(odometry_dir, tmp_path):
    """tables/ a file: the report failed after it had written its figures to plots/, beside the earlier report.md.
    Figures, tables and texts are moved in together, once all are written."""
    import shutil

    from lidarkit.errors import OutputError

    folder = tmp_path / "reused"
    shutil.copytree(odometry_dir, folder)
    build_report(folder)
    texts = {name: (folder / name).read_bytes() for name in ("report.md", "report.csv", "report.html")}
    drawn = sorted(p.name for p in (folder / "plots").iterdir())
    assert len(drawn) == 3  # trajectory and error over time of the odometry, RMSE per iteration of the pair
    (folder / "plots" / drawn[0]).unlink()
    shutil.rmtree(folder / "tables")
    (folder / "tables").write_text("in the way")
    with pytest.raises(OutputError) as info:
        build_report(folder)
    assert str(info.value) == f"{folder / 'tables'}: cannot create the folder: a file is in the way (a folder is needed here)"
    assert sorted(p.name for p in (folder / "plots").iterdir()) == drawn[1:]  # no new figure beside the earlier report
    assert {name: (folder / name).read_bytes() for name in texts} == texts
    assert [p.name for p in folder.parent.iterdir() if ".partial-" in p.name] == []


def test_publication_tables_label_odometry_datasets_as_its_section_does(odometry_dir):
    """With an icp_pair experiment on K00 too, the publication tables said K00(frames=0:3) (the labels were told apart
    over every task's records) where the odometry section said K00."""
    report = build_report(odometry_dir, plots=False)
    odometry = next(t for t in report.tables if t.task == "odometry")
    assert [row.dataset for row in odometry.rows] == ["K00"]
    ape = next(t for t in report.publication.tables if t.name == "ape_rmse")
    assert ape.row_labels[0] == "K00"
    assert "frames=" not in (odometry_dir / "tables" / "ape_rmse.md").read_text()


def test_all_metrics_and_the_csv_say_the_seeds_not_run(results_dir, tmp_path):
    """After an interrupted run the methods x datasets table said "(1 of 3 not run)" but the All metrics table and
    report.csv gave the numbers over the seeds that ran without a word."""
    import shutil

    from lidarkit.bench.report import _table_rows

    folder = tmp_path / "interrupted"
    shutil.copytree(results_dir, folder)
    walk = next(r for r in load_results(folder) if r["job"]["params"].get("noise_m") == 0.03 and r["job"]["seed"] == 2)
    (folder / "jobs" / f"{walk['key']}.json").unlink()
    report = build_report(folder, plots=False)
    header, rows = _table_rows(report.tables[0])
    row = next(row for row in rows if row[2] == "random_walk(noise_m=0.03, steps=40)")
    assert row[3] == "2/0" and row[header.index("APE RMSE [m]")].endswith(" (1 of 3 not run)")
    with open(report.csv_path, newline="") as fh:
        lines = [r for r in csv.DictReader(fh) if r["metric"] == "ape_rmse_m"]
    assert {r["method"]: (r["n_ok"], r["n_failed"], r["n_not_run"]) for r in lines} == {
        "random_walk(noise_m=0.01, steps=40)": ("3", "0", "0"), "random_walk(noise_m=0.03, steps=40)": ("2", "0", "1"),
        "random_walk(noise_m=0.1, steps=40)": ("3", "0", "0"), "fail": ("0", "3", "0")}


def test_a_method_none_of_whose_seeds_ran_has_its_row_saying_so(results_dir, tmp_path):
    """A method with no result on any seed yet (an interrupted run) had no row in any table nor in report.csv: it was
    named only under "Jobs of the suite without a result"."""
    import shutil

    from lidarkit.bench.report import _table_rows, pivot

    folder = tmp_path / "interrupted"
    shutil.copytree(results_dir, folder)
    for r in load_results(folder):
        if r["job"]["params"].get("noise_m") == 0.1:
            (folder / "jobs" / f"{r['key']}.json").unlink()
    report = build_report(folder, plots=False)
    header, rows = _table_rows(report.tables[0])
    row = next(row for row in rows if row[2] == "random_walk(noise_m=0.1, steps=40)")
    assert row[3] == "0/0" and row[header.index("APE RMSE [m]")] == "– (3 of 3 not run)"
    _, cells = pivot(report.tables[0], "ape_rmse_m")
    assert ["random_walk(noise_m=0.1, steps=40)", "– (3 of 3 not run)"] in cells
    with open(report.csv_path, newline="") as fh:
        lines = [r for r in csv.DictReader(fh) if r["method"] == "random_walk(noise_m=0.1, steps=40)"]
    assert [(r["metric"], r["mean"], r["n"], r["n_ok"], r["n_failed"], r["n_not_run"]) for r in lines] == [
        (m, "", "0", "0", "0", "3") for m in ("ape_rmse_m", "final_error_m", "runtime_s")]


def test_names_the_font_cannot_draw_warn_of_no_missing_glyph(tmp_path):
    """A dataset named "d 名前" printed matplotlib's "Glyph ... missing from font" UserWarning on stderr for each
    character, twice per run (the title shows boxes: that is kept)."""
    import warnings

    suite = tmp_path / "suite.yaml"
    suite.write_text(SUITE.replace("name: synth", 'name: "d 名前"'), encoding="utf-8")
    run_suite(load_suite(suite), tmp_path / "out", executor="serial")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        report = build_report(tmp_path / "out")
    assert [str(w.message) for w in caught if "Glyph" in str(w.message)] == []
    assert len(report.plots) == 4 and all(p.png.startswith(PNG_MAGIC) for p in report.plots)  # (with the noise sweep)


def test_a_task_none_of_whose_jobs_ran_has_its_table_saying_so(odometry_dir, tmp_path):
    """A task with no result on any job yet (an interrupted run, its jobs last) had no table at all, nor a line in
    report.csv: only "Jobs of the suite without a result" named its jobs."""
    import shutil

    from lidarkit.bench.report import _table_rows

    folder = tmp_path / "interrupted"
    shutil.copytree(odometry_dir, folder)
    for r in load_results(folder):
        if r["job"]["task"] == "icp_pair":
            (folder / "jobs" / f"{r['key']}.json").unlink()
    report = build_report(folder, plots=False)
    assert [t.task for t in report.tables] == ["icp_pair", "odometry"]
    header, rows = _table_rows(report.tables[0])
    assert len(rows) == 1 and rows[0][header.index("ok/failed")] == "0/0"
    assert {row[i] for row in rows for i in range(len(header)) if header[i] not in ("experiment", "dataset", "method", "ok/failed")} == {"– (1 of 1 not run)"}
    with open(report.csv_path, newline="") as fh:
        lines = [r for r in csv.DictReader(fh) if r["task"] == "icp_pair"]
    assert lines and {(r["n"], r["n_ok"], r["n_not_run"]) for r in lines} == {("0", "0", "1")}
    assert "translation_error_m" in {r["metric"] for r in lines}
    assert "icp_pair" in report.markdown_path.read_text()


def test_methods_scored_against_truths_of_different_sweep_instants_are_each_drawn_with_their_own(tmp_path):
    """kiss (poses at the sweep end) and small_gicp (re-timed to the sweep mid) on one simulated drive: the references
    were keyed by seed, the two truths of seed 0 became one ("0"), and kiss was drawn against the mid-sweep truth."""
    pytest.importorskip("small_gicp")
    from lidarkit.bench.report import _first_ok_per_method, _references
    from lidarkit.bench.tasks._datasets import open_dataset_spec

    dataset = {"kind": "sim_lidar", "scene": "street", "n_frames": 5, "n_beams": 16, "n_azimuths": 300, "seed": 0}
    (tmp_path / "suite.yaml").write_text(textwrap.dedent("""
        seeds: [0]
        experiments:
          - name: odo
            task: odometry
            dataset: {kind: sim_lidar, scene: street, n_frames: 5, n_beams: 16, n_azimuths: 300, seed: 0, name: street}
            methods: [kiss, small_gicp]
        """))
    run_suite(load_suite(tmp_path / "suite.yaml"), tmp_path / "out", executor="serial")
    chosen, _ = _first_ok_per_method(load_results(tmp_path / "out"), "trajectory_xy")
    refs, ref_of = _references(chosen)
    assert ref_of == {"kiss": "reference (sweep end)", "small_gicp": "reference (sweep mid)"}
    sequence = open_dataset_spec(dataset)
    for instant in ("end", "mid"):
        poses = sequence.ground_truth_at_instant(instant).poses_se3
        truth_xy = (np.linalg.inv(poses[0]) @ poses)[:, :2, 3]  # the reference starts at the first pose
        assert np.allclose(refs[f"reference (sweep {instant})"], truth_xy, atol=1e-4)
    assert not np.allclose(refs["reference (sweep end)"], refs["reference (sweep mid)"], atol=1e-3)
    plot = next(p for p in build_report(tmp_path / "out").plots if p.title.startswith("Trajectories"))
    assert "against the reference of that seed and sweep instant" in plot.caption


def test_a_paired_comparison_over_ape_names_the_apes_alignment(tmp_path):
    """Over short drives (no KITTI drift) the paired comparisons were labelled "APE RMSE m" beside headline tables of
    SE(3)-aligned APE, though they pair the unaligned, first-pose-anchored APE."""
    from lidarkit.bench.jobs import Job
    from lidarkit.bench.report import comparison_rows
    from lidarkit.bench.results import make_record, write_result

    for seed in range(6):  # (6 seeds: the fewest whose test can reach p < 0.05)
        for method, ape in (("kiss", 0.2 + 0.01 * seed), ("small_gicp", 0.5 + 0.02 * seed)):
            job = Job("odometry", "e", "drive", {"kind": "sim_lidar", "scene": "street"}, method, seed=seed)
            outcome = {"status": "ok", "metrics": {"ape_rmse_m": ape, "ape_se3_rmse_m": ape / 4}, "error": None,
                       "runtime_s": 0.1}
            write_result(tmp_path, make_record(job, job.key(), "1", outcome))
    report = build_report(tmp_path, plots=False)
    (dataset, comparison), = report.publication.comparisons
    assert comparison.metric == "APE RMSE (unaligned, first pose anchored) m"
    assert comparison.mean_a == pytest.approx(0.225) and comparison.mean_b == pytest.approx(0.55)
    assert comparison_rows([(dataset, comparison)])[1][0][3] == "6 seeds (APE RMSE (unaligned, first pose anchored) m)"


def test_a_seed_without_a_value_is_left_out_of_the_publication_tables_and_the_comparison_says_so(tmp_path):
    """One NaN APE of small_gicp (a record edited by hand) made its mean NaN: the APE table showed it as "–" and set
    kiss bold though small_gicp was ~30x better on every other seed, and the paired comparison vanished without a word
    (the reason only logged). A NaN is now no value, as in report.csv, and a comparison not made is said."""
    import json

    from lidarkit.bench.jobs import Job
    from lidarkit.bench.results import make_record, result_path

    def write(method, seed, metrics, series=None):  # (by hand: write_result refuses NaN)
        job = Job("odometry", "e", "drive", {"kind": "sim_lidar", "scene": "street"}, method, seed=seed)
        record = make_record(job, job.key(), "1", {"status": "ok", "metrics": metrics, "series": series or {},
                                                   "error": None, "runtime_s": 0.1})
        result_path(tmp_path, job.key()).parent.mkdir(exist_ok=True)
        result_path(tmp_path, job.key()).write_text(json.dumps(record))

    for seed in range(8):
        write("kiss", seed, {"ape_rmse_m": 0.3 + 0.01 * seed})
        write("small_gicp", seed, {"ape_rmse_m": float("nan") if seed == 3 else 0.01 + 0.001 * seed})
    report = build_report(tmp_path, plots=False)
    assert "| drive | 0.3350 | **0.0136** |" in (tmp_path / "tables" / "ape_rmse.md").read_text()  # (3 significant figures of the smallest)
    (_, c), = report.publication.comparisons
    assert (c.n_pairs, c.better) == (7, "b")
    assert c.note == "seed(s) 3 left out: no value (NaN, inf) on one side"
    # a comparison the statistics refuse (a NaN drift of a KITTI segment) is said in the report, not only logged
    (tmp_path / "jobs").rename(tmp_path / "seeds")
    def segments(drift):
        return {"drift_segments": {"first_frame": [0, 10], "length_m": [100.0, 100.0], "translation_pct": drift,
                                   "rotation_deg_per_100m": [0.1, 0.1], "speed_mps": [10.0, 10.0]}}

    for seed in range(2):
        write("kiss", seed, {}, segments([0.5, 0.6]))
        write("small_gicp", seed, {}, segments([1.5, float("nan") if seed else 1.6]))
    build_report(tmp_path, plots=False)
    assert ("- no comparison: drive, kiss vs small_gicp: small_gicp: 1 non-finite value(s) among 4"
            in (tmp_path / "report.md").read_text().splitlines())


def test_the_summary_counts_only_the_methods_it_ranked(tmp_path):
    """sleep, fail and random_walk over a 2-value grid: the Summary's "methods" read 4 where 2 had an APE to rank."""
    from lidarkit.bench.report import summary_rows

    suite = tmp_path / "suite.yaml"
    suite.write_text(textwrap.dedent("""
        seeds: 2
        experiments:
          - name: sl
            task: selftest
            dataset: {kind: synthetic}
            methods:
              - {name: sleep, params: {seconds: 0.0}}
              - {name: fail, params: {message: boom}}
              - {name: random_walk, grid: {noise_m: [0.01, 0.1]}}
    """))
    run_suite(load_suite(suite), tmp_path / "out", executor="serial")
    header, rows = summary_rows(build_report(tmp_path / "out", plots=False))
    assert header[5] == "methods ranked"
    assert [row[1:4] + row[5:] for row in rows] == [["synthetic", "APE RMSE [m]", "random_walk(noise_m=0.01)", "2"]]


CUSTOM_TASK_MODULE = """
from lidarkit.bench import Metric, Task, TaskOutput, register_task

@register_task("report_module_task")
class ReportModuleTask(Task):
    dataset_kinds = ("synthetic",)
    metrics = (Metric("error_m", "error [m]"), Metric("hz", "frames/s", kind="speed", better="higher"))
    sweep_plots = (("n_iterations", "error_m"),)

    def run(self, job):
        return TaskOutput(metrics={"error_m": 0.1 / job.params["n_iterations"] + 0.01 * job.seed, "hz": 20.0})
"""


def test_a_report_imports_the_module_of_a_custom_task_the_run_recorded(tmp_path, monkeypatch, caplog):
    """`lidarkit report OUT` on a custom task's results (a process that never imported its module) showed bare metric
    names, no speed table, and removed the sweep figure the run's report drew, saying so at INFO only. The run records
    the task's module; the report imports it (from the folder it was imported from when the suite ran, when it is not
    on sys.path), and a module that is gone is one warning, the figure kept."""
    import importlib
    import json
    import sys

    from lidarkit.bench import tasks as bench_tasks
    from lidarkit.bench.report import pivot

    monkeypatch.setattr(bench_tasks, "_REGISTERED", {})
    monkeypatch.setattr(bench_tasks, "_INSTANCES", {})
    code = tmp_path / "code"
    code.mkdir()
    (code / "lidarkit_report_module_task.py").write_text(CUSTOM_TASK_MODULE)
    monkeypatch.syspath_prepend(str(code))
    try:
        importlib.import_module("lidarkit_report_module_task")  # (registers the task, as the user's script does)

        (tmp_path / "suite.yaml").write_text(textwrap.dedent("""
            seeds: 2
            experiments:
              - task: report_module_task
                dataset: {kind: synthetic}
                methods: [{name: m, grid: {n_iterations: [1, 10, 100]}}]
            """))
        run_suite(load_suite(tmp_path / "suite.yaml"), tmp_path / "out", executor="serial")
        origin = {"module": "lidarkit_report_module_task", "folder": str(code)}
        assert json.loads((tmp_path / "out" / "suite.json").read_text()).get("task_modules") == {"report_module_task": origin}
        assert [r["task_module"] for r in load_results(tmp_path / "out")] == [origin] * 6
        first = build_report(tmp_path / "out")
        sweep = [p.filename for p in first.plots if p.filename.startswith("sweep_")]
        assert len(sweep) == 1

        # another process: the task unknown, its module neither imported nor on sys.path
        def fresh_process():
            monkeypatch.setattr(bench_tasks, "_REGISTERED", {})
            monkeypatch.setattr(bench_tasks, "_INSTANCES", {})
            sys.modules.pop("lidarkit_report_module_task", None)

        fresh_process()
        monkeypatch.setattr(sys, "path", [p for p in sys.path if p != str(code)])
        report = build_report(tmp_path / "out")
        table = report.tables[0]
        assert [(m.name, m.label, m.kind) for m in table.metrics] == [
            ("error_m", "error [m]", "accuracy"), ("hz", "frames/s", "speed"), ("runtime_s", "runtime [s]", "speed")]
        assert pivot(table, "hz")[0] == ["method", "synthetic"]  # the speed table of the task's own speed metric
        assert [p.filename for p in report.plots if p.filename.startswith("sweep_")] == sweep
        assert str(code) not in sys.path  # (the folder is searched for this import alone)

        # the module is gone: one warning line, and the sweep drawn as the results record it (the figure stayed in
        # plots/ but was gone from report.md and report.html)
        fresh_process()
        (code / "lidarkit_report_module_task.py").unlink()
        importlib.invalidate_caches()
        caplog.clear()
        report = build_report(tmp_path / "out")
        warnings = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
        gone = ("task 'report_module_task': its module lidarkit_report_module_task cannot be imported here "
                "(ModuleNotFoundError: No module named 'lidarkit_report_module_task'); its metrics are shown as its "
                "results declare them")
        assert [r["sweep_plots"] for r in load_results(tmp_path / "out")] == [[["n_iterations", "error_m"]]] * 6
        assert f"(plots/{sweep[0]})" in (tmp_path / "out" / "report.md").read_text(encoding="utf-8")
        (plot,) = report.plots
        assert plot.filename == sweep[0] and plot.title == "error [m] vs n_iterations — report_module_task"
        assert plot.caption in (tmp_path / "out" / "report.html").read_text(encoding="utf-8")
        assert warnings == [gone + " and its sweep figures drawn as its results record them"]

        # results written before the sweeps were recorded: the figure this report cannot draw is kept
        from lidarkit.bench.results import write_result

        for record in load_results(tmp_path / "out"):
            del record["sweep_plots"]
            write_result(tmp_path / "out", record)
        caplog.clear()
        report = build_report(tmp_path / "out")
        assert [r.getMessage() for r in caplog.records if r.levelname == "WARNING"] == [
            gone + " and its sweep figures in plots/ are kept"]
        assert report.plots == [] and (tmp_path / "out" / "plots" / sweep[0]).is_file()
    finally:
        sys.modules.pop("lidarkit_report_module_task", None)


def test_a_seed_not_run_yet_does_not_make_the_worse_method_the_best(tmp_path):
    """An interrupted run: the better method's seed 2 had no result yet, and the Summary named the complete method
    best, 0.55 against 0.225 on the seeds both ran (complete rows came first). Rows are now ranked on their means over
    the seeds they share, as the publication tables average them; a failed seed still puts its row behind."""
    import json

    from lidarkit.bench.jobs import Job
    from lidarkit.bench.report import summary_rows
    from lidarkit.bench.results import make_record, write_result

    values = {"good": {0: 0.2, 1: 0.25, 2: None}, "worse": {0: 0.5, 1: 0.6, 2: 0.55}}  # None: not run yet
    jobs = []
    for method, per_seed in values.items():
        for seed, ape in per_seed.items():
            job = Job("selftest", "e", "synth", {"kind": "synthetic"}, method, seed=seed)
            jobs.append({"key": job.key(), **job.spec()})
            if ape is not None:
                write_result(tmp_path, make_record(job, job.key(), "1", {"status": "ok", "metrics": {"ape_rmse_m": ape},
                                                                         "error": None, "runtime_s": 0.1}))
    (tmp_path / "suite.json").write_text(json.dumps({"suite": "s", "jobs": jobs}))
    _, rows = summary_rows(build_report(tmp_path, plots=False))
    assert rows[0][3:] == ["good", "0.225 ± 0.035 (1 of 3 not run) (ranked on the common seeds 0, 1)", "2"]
    # a failed seed is no seed not run: that row still comes after the complete one
    job = Job("selftest", "e", "synth", {"kind": "synthetic"}, "good", seed=2)
    write_result(tmp_path, make_record(job, job.key(), "1", {"status": "failed", "metrics": {}, "runtime_s": 0.1,
                                                              "error": {"type": "RuntimeError", "message": "lost"}}))
    _, rows = summary_rows(build_report(tmp_path, plots=False))
    assert rows[0][3:5] == ["worse", "0.55 ± 0.05"]


def test_a_failed_forced_rerun_is_listed_and_the_rows_it_left_say_so(tmp_path, monkeypatch):
    """A ``--force`` rerun that failed keeps the earlier ok result (``rerun_failed`` in its record), but the report never
    said so: the rows read as fresh results. The failures section lists each such job and its cells say how many of
    their seeds are results kept after a failed rerun (report.csv: ``n_rerun_failed``)."""
    import os

    from lidarkit.bench import tasks as bench_tasks
    from lidarkit.bench.report import _table_rows, pivot
    from lidarkit.bench.tasks import Metric, Task, TaskOutput, register_task

    monkeypatch.setattr(bench_tasks, "_REGISTERED", {})
    monkeypatch.setattr(bench_tasks, "_INSTANCES", {})

    @register_task("flaky_report_task")
    class Flaky(Task):
        dataset_kinds = ("synthetic",)
        metrics = (Metric("err_m", "error [m]"),)

        def run(self, job):
            if os.environ.get("FLAKY_REPORT_FAIL") and job.seed == 1:
                raise RuntimeError("transient: data disk not mounted")
            return TaskOutput(metrics={"err_m": 0.5 + job.seed})

    (tmp_path / "suite.yaml").write_text(textwrap.dedent("""
        seeds: 2
        experiments:
          - {task: flaky_report_task, dataset: {kind: synthetic, name: synth}, methods: [a]}
        """))
    suite = load_suite(tmp_path / "suite.yaml")
    run_suite(suite, tmp_path / "out", executor="serial")
    monkeypatch.setenv("FLAKY_REPORT_FAIL", "1")
    run_suite(suite, tmp_path / "out", executor="serial", force=True)
    report = build_report(tmp_path / "out", plots=False)
    line = ("forced rerun failed: RuntimeError: transient: data disk not mounted; the earlier ok result is shown")
    md = (tmp_path / "out" / "report.md").read_text()
    assert f"flaky_report_task | flaky_report_task_0 | synth | a | seed 1: {line}" in md
    assert report.failures == []  # (its result is the earlier ok one: no failed job)
    assert [f["error"] for f in report.rerun_failures] == [line]
    assert f"{line}</li>" in (tmp_path / "out" / "report.html").read_text()
    assert pivot(report.tables[0], "err_m")[1] == [["a", "1 ± 0.71 (1 of 2 kept after a failed rerun)"]]
    assert "1 ± 0.71 (1 of 2 kept after a failed rerun)" in (tmp_path / "out" / "report.html").read_text()
    assert _table_rows(report.tables[0])[1][0][3:5] == ["2/0 (1 kept after a failed rerun)", "1 ± 0.71"]
    with open(report.csv_path, newline="") as fh:
        assert {r["metric"]: r["n_rerun_failed"] for r in csv.DictReader(fh)} == {"err_m": "1", "runtime_s": "1"}


def test_the_segment_box_plots_say_how_many_segments_each_method_has_and_their_lengths(tmp_path, monkeypatch):
    """Two methods of 4 segments of 100 m each: the caption said "8 segments (100-800 m) pooled over datasets and seeds"
    and the title "(8 segments)". Both now say the count per method and the lengths present."""
    from lidarkit.bench.jobs import Job
    from lidarkit.bench.publication import build_publication
    from lidarkit.eval import plots
    from lidarkit.eval.tables import SegmentErrors

    titles = []
    save_figure = plots.save_figure
    monkeypatch.setattr(plots, "save_figure", lambda fig, path: titles.append(fig.axes[0].get_title()) or save_figure(fig, path))

    def record(method, lengths):
        job = Job("odometry", "e", "drive", {"kind": "sim_lidar", "scene": "street"}, method, seed=0)
        n = len(lengths)
        return {"status": "ok", "job": job.spec(), "metrics": {"ape_rmse_m": 0.1},
                "series": {"drift_segments": {"first_frame": list(range(0, 10 * n, 10)), "length_m": lengths,
                                              "translation_pct": [1.0 + 0.1 * k for k in range(n)],
                                              "rotation_deg_per_100m": [0.5] * n, "speed_mps": [1.0] * n}}}

    grid = {("drive", method): SegmentErrors.from_dict(record(method, [100.0] * 4)["series"]["drift_segments"])
            for method in ("kiss", "vanilla")}
    plots.plot_segment_boxplots(grid, tmp_path / "box.png", "rotation_deg_per_100m")
    assert [" ".join(t.split()) for t in titles] == ["per-segment KITTI rotational drift (deg/100 m): 4 segments per method (100 m)"]
    pub = build_publication([record("kiss", [100.0] * 4), record("vanilla", [100.0] * 4)], tmp_path)
    assert [caption for caption, _ in pub.boxplots] == [
        f"Per-segment KITTI {what} drift per method: 4 segments per method (100 m), pooled over datasets and seeds; "
        "box = quartiles, whiskers = 1.5 IQR." for what in ("translational", "rotational")]
    assert " ".join(titles[1].split()) == "per-segment KITTI translational drift (%): 4 segments per method (100 m)"
    pub = build_publication([record("kiss", [100.0, 200.0, 300.0]), record("vanilla", [100.0])], tmp_path)
    assert pub.boxplots[0][0].startswith("Per-segment KITTI translational drift per method: kiss 3, vanilla 1 segments "
                                         "(100-300 m), pooled")


def test_plots_and_reports_print_in_one_short_line(results_dir, tmp_path):
    """``repr`` of a Plot printed its PNG bytes (54,846 characters) and of a Report everything it holds (58,095)."""
    import shutil

    from lidarkit.bench.report import Plot

    shutil.copytree(results_dir, tmp_path / "out")
    report = build_report(tmp_path / "out", plots=False)
    report.plots = [Plot("trajectories", "traj.png", PNG_MAGIC + bytes(50_000), "selftest", "Top view")]
    assert repr(report.plots[0]) == "Plot(title='trajectories', filename='traj.png', task='selftest', caption='Top view')"
    assert repr(report) == f"Report({str(tmp_path / 'out')!r}, 1 tables, 1 plots, 12 results, 3 failed, 0 not run)"


def test_the_statistics_table_names_its_interval_method(tmp_path):
    """The page's header said "95 % CI (bootstrap)" for every row: of 3 seeds the interval is Student-t's (the bootstrap
    of a few seeds is far too narrow), its t quantile with 2 degrees of freedom, 4.30."""
    from lidarkit.bench.jobs import Job
    from lidarkit.bench.results import make_record, write_result

    for seed in range(3):
        for method, value in (("kiss", 1.0 + seed), ("small_gicp", 2.0 + 0.5 * seed)):
            job = Job("odometry", "e", "drive", {"kind": "sim_lidar", "scene": "street"}, method, seed=seed)
            outcome = {"status": "ok", "metrics": {"ape_rmse_m": value}, "error": None, "runtime_s": 0.1}
            write_result(tmp_path, make_record(job, job.key(), "1", outcome))
    build_report(tmp_path, plots=False)
    page = (tmp_path / "report.html").read_text()
    assert '<th>95 % CI (Student-t)</th></tr></thead><tbody><tr><td class="l">drive</td><td class="l">kiss</td><td>3</td>' in page
    assert "<td>[-0.4841, 4.484]</td>" in page and "bootstrap" not in page  # kiss: 2 -+ 4.303 x 1 / sqrt(3)


def test_error_over_time_lines_of_different_alignments_each_name_theirs(tmp_path):
    """A VO grid over scale.mode [gt, relative]: the error-over-time axis and caption read "APE (sim3 aligned) [m]",
    the last line's label, for the SE(3)-aligned gt line too."""
    from lidarkit.bench.jobs import Job
    from lidarkit.bench.results import make_record, write_result

    dataset = {"kind": "kitti", "path": str(tmp_path / "06"), "name": "K06"}
    for mode, align, stated in (("gt", "se3", "SE(3)-aligned"), ("relative", "sim3", "Sim(3)-aligned")):
        job = Job("vo", "vo", "K06", dataset, "lidarkit", {"scale.mode": mode}, seed=0)
        series = {"error_over_time": {"t": [0.0, 0.1, 0.2], "error": [0.01, 0.02, 0.015], "label": f"APE ({align} aligned) [m]"}}
        write_result(tmp_path, make_record(job, job.key(), "1", {
            "status": "ok", "metrics": {"ape_rmse_m": 0.02}, "series": series, "error": None, "runtime_s": 0.1,
            "info": {"metric_alignment": {"ape_rmse_m": stated}}}))
    (err,) = [p for p in build_report(tmp_path).plots if p.filename.startswith("err_")]
    assert err.caption == ("APE [m] over time per method (lidarkit(scale.mode=gt): se3 aligned; "
                           "lidarkit(scale.mode=relative): sim3 aligned): vo, K06.")
    from lidarkit.bench.report import error_axis_label

    # the axis label and what each legend entry adds
    assert error_axis_label({"gt": "APE (se3 aligned) [m]", "relative": "APE (sim3 aligned) [m]"}) == (
        "APE [m]", {"gt": "se3 aligned", "relative": "sim3 aligned"})
    assert error_axis_label({"a": "position error [m]", "b": "position error [m]"}) == ("position error [m]", {})
    assert error_axis_label({"a": "position error [m]", "b": "APE (sim3 aligned) [m]"}) == (
        "error [m]", {"a": "position error [m]", "b": "APE (sim3 aligned) [m]"})


def test_an_interrupted_run_keeps_the_declared_metrics_of_the_methods_not_run_yet(tmp_path):
    """Stopped after the sleep jobs: the only table was "slept [s]" and the random walks' rows sat under it; APE and
    final error, the task's headline metrics, had no column until the walks ran."""
    from lidarkit.bench.report import _pivot_metrics

    (tmp_path / "suite.yaml").write_text(textwrap.dedent("""
        name: interrupted
        seeds: 2
        experiments:
          - name: mix
            task: selftest
            dataset: {kind: synthetic}
            methods:
              - {name: sleep, params: {seconds: 0}}
              - {name: random_walk, params: {noise_m: 0.1, steps: 10}}
              - {name: random_walk, params: {noise_m: 0.3, steps: 10}}
    """))
    run_suite(load_suite(tmp_path / "suite.yaml"), tmp_path / "out", executor="serial")
    walks = [r for r in load_results(tmp_path / "out") if r["job"]["method"] == "random_walk"]
    for r in walks:
        if r["job"]["params"]["noise_m"] == 0.3:  # one random walk still to run: the other says what it reports
            (tmp_path / "out" / "jobs" / f"{r['key']}.json").unlink()
    (table,) = build_report(tmp_path / "out", plots=False).tables
    assert [m.name for m in table.metrics] == ["ape_rmse_m", "final_error_m", "slept_s", "runtime_s"]
    for r in walks:  # no random walk has run yet
        (tmp_path / "out" / "jobs" / f"{r['key']}.json").unlink(missing_ok=True)
    (table,) = build_report(tmp_path / "out", plots=False).tables
    assert [m.name for m in table.metrics] == ["ape_rmse_m", "final_error_m", "slept_s", "checksum", "runtime_s"]
    assert [m.name for m in _pivot_metrics(table)] == ["ape_rmse_m", "slept_s"]  # the headline leads, as when finished
    md = (tmp_path / "out" / "report.md").read_text()
    assert md.index("APE RMSE [m], methods x datasets:") < md.index("slept [s], methods x datasets:")
    assert "| random_walk(noise_m=0.3, steps=10) | – (2 of 2 not run) |" in md


def test_a_particle_filter_sweep_plot_names_its_metric_by_its_label(tmp_path):
    """The MSE-vs-particles figure read "mse_m2" on its axis, title and caption (the tables say "position MSE [m²]")."""
    from lidarkit.bench.jobs import Job
    from lidarkit.bench.results import make_record, write_result

    dataset = {"kind": "landmarks", "path": str(tmp_path / "pf"), "name": "Freiburg"}
    for n_particles in (20, 200):
        for seed in range(2):
            job = Job("pf", "pfx", "Freiburg", dataset, "particle_filter", {"n_particles": n_particles}, seed=seed)
            write_result(tmp_path, make_record(job, job.key(), "1", {
                "status": "ok", "metrics": {"mse_m2": 1.0 / n_particles + 0.01 * seed}, "error": None, "runtime_s": 0.1}))
    (sweep,) = [p for p in build_report(tmp_path).plots if p.filename.startswith("sweep_")]
    assert sweep.title == "position MSE [m²] vs n_particles — pf"
    assert sweep.caption.startswith("position MSE [m²] against n_particles: mean ± std over seeds")
    assert sweep.filename.startswith("sweep_pf_mse_m2_n_particles_")  # (the file keeps its name)


def _odometry_record(folder, experiment, dataset, method, metrics, *, params=None, frames=None, seed=0, version="1",
                     finished="2026-01-01T00:00:00.000+00:00"):
    """An odometry result as the task writes it (its metrics, the RPE step its frames give), written to ``folder``."""
    from lidarkit.bench.jobs import Job
    from lidarkit.bench.results import make_record, write_result
    from lidarkit.bench.tasks.odometry import METRIC_ALIGNMENT_BY_NAME, SELECTED_FRAME

    job = Job("odometry", experiment, dataset, {"kind": "kitti", "sequence": "00"}, method, params or {}, seed=seed,
              options={} if frames is None else {"frames": frames})
    skips = isinstance(frames, str) and frames.count(":") == 2
    alignment = {**METRIC_ALIGNMENT_BY_NAME, **({"rpe_trans_rmse_m": SELECTED_FRAME} if skips else {})}
    write_result(folder, make_record(job, job.key(version), version, {
        "status": "ok", "metrics": metrics, "series": {}, "info": {"metric_alignment": alignment}, "error": None,
        "runtime_s": 0.1, "finished_utc": finished}))


def test_rpe_over_one_frame_and_over_one_selected_frame_are_two_tables(tmp_path):
    """Two odometry experiments on KITTI 00, frames "0:5" and "0:10:2": the one RPE table, titled "m per frame /
    selected frame", averaged the 1-frame and the 2-frame RPE into one bold Mean (kiss 0.1917). Each step now has its
    own table, named by its file, the selected-frame rows marked; a later report without that step removes its files."""
    rpe = {("0:5", "kiss"): 0.14827, ("0:5", "vanilla"): 0.24638, ("0:10:2", "kiss"): 0.23513,
           ("0:10:2", "vanilla"): 0.22047}
    for (frames, method), value in rpe.items():
        _odometry_record(tmp_path, f"e{frames}", "k00", method, {"ape_rmse_m": 0.5, "rpe_trans_rmse_m": value},
                         frames=frames)
    report = build_report(tmp_path, plots=False)
    with open(tmp_path / "tables" / "rpe_rmse.csv", newline="") as fh:
        assert list(csv.reader(fh)) == [["sequence", "kiss", "vanilla"], ["k00(frames=0:5)", "0.14827", "0.24638"],
                                        ["Mean", "0.14827", "0.24638"]]
    with open(tmp_path / "tables" / "rpe_rmse_selected_frame.csv", newline="") as fh:
        assert list(csv.reader(fh)) == [["sequence", "kiss", "vanilla"], ["k00(frames=0:10:2) *", "0.23513", "0.22047"],
                                        ["Mean", "0.23513", "0.22047"]]
    md = (tmp_path / "tables" / "rpe_rmse_selected_frame.md").read_text()
    assert md.startswith("**RPE translation RMSE (m per selected frame)**")
    assert "*: over one selected frame of the row's frame selection, not one dataset frame. Mean:" in md
    assert [t.name for t in report.publication.tables] == ["ape_rmse", "rpe_rmse", "rpe_rmse_selected_frame"]
    assert "**RPE translation RMSE (m per frame)**" in (tmp_path / "report.md").read_text()
    # a dataset whose label does not say its selection has it named in the note
    (tmp_path / "jobs").rename(tmp_path / "both")
    for method in ("kiss", "vanilla"):
        _odometry_record(tmp_path, "skip", "k00", method, {"rpe_trans_rmse_m": 0.2}, frames="0:10:2")
    build_report(tmp_path, plots=False)
    assert ("| k00 * |" in (tmp_path / "tables" / "rpe_rmse_selected_frame.md").read_text()
            and "not one dataset frame (k00: frames 0:10:2)." in (tmp_path / "tables" / "rpe_rmse_selected_frame.md").read_text())
    assert not (tmp_path / "tables" / "rpe_rmse.md").exists()
    # and the next report over every frame removes the selected-frame table an earlier one wrote
    (tmp_path / "jobs").rename(tmp_path / "skipping")
    for method in ("kiss", "vanilla"):
        _odometry_record(tmp_path, "all", "k00", method, {"rpe_trans_rmse_m": 0.1})
    build_report(tmp_path, plots=False)
    assert sorted(p.name for p in (tmp_path / "tables").iterdir()) == ["rpe_rmse.csv", "rpe_rmse.md", "rpe_rmse.tex"]


def test_a_run_whose_frames_did_not_register_is_marked_and_neither_bold_nor_in_the_mean(tmp_path):
    """ground_filtered on "sim open" (7 of its 8 frames not converged: its estimate never left the origin) was set bold
    as the best APE and RPE, and its 0.481 made its bold Mean. Its cells now carry a mark saying why, are not bold, and
    its sequence is left out of the Mean; a run with fewer than half its frames not registered is a result as any."""
    runs = {("sim open", "kiss"): (1.773, 0.5155, 0), ("sim open", "ground_filtered"): (0.481, 0.1781, 7),
            ("sim street", "kiss"): (0.424, 0.1372, 0), ("sim street", "ground_filtered"): (0.240, 0.0902, 3)}
    for (dataset, method), (ape, rpe, failed) in runs.items():
        _odometry_record(tmp_path, "odo", dataset, method, {"ape_rmse_m": ape, "rpe_trans_rmse_m": rpe, "n_frames": 8,
                                                            "n_not_converged": failed})
    build_report(tmp_path, plots=False)
    ape = (tmp_path / "tables" / "ape_rmse.md").read_text()
    assert "| sim open | 0.481 (a) | **1.773** |" in ape, ape
    assert "| sim street | **0.240** | 0.424 |" in ape  # (3 of 7 not registered: a result)
    assert "| **Mean** | **0.240** | 0.424 |" in ape
    assert ("(a) sim open, ground_filtered: no frame registered. A frame that does not register takes the fallback "
            "motion's pose: a marked cell is not set bold and its sequence is left out of the Mean.") in ape
    assert "| sim open | 0.1781 (a) | **0.5155** |" in (tmp_path / "tables" / "rpe_rmse.md").read_text()
    assert "\\textbf{1.773}" in (tmp_path / "tables" / "ape_rmse.tex").read_text()
    assert "sim open & 0.481 (a) & " in (tmp_path / "tables" / "ape_rmse.tex").read_text()
    assert "<td>0.481 (a)</td><td><b>1.773</b></td>" in (tmp_path / "report.html").read_text()
    rows = (tmp_path / "tables" / "ape_rmse.csv").read_text().splitlines()  # (the CSV gave the value without a word)
    assert rows[0].endswith(",marks") and rows[1].startswith("sim open,0.48") and rows[1].endswith(",ground_filtered (a)")
    # most but not all frames, over two seeds
    (tmp_path / "jobs").rename(tmp_path / "first")
    for seed, failed in ((0, 5), (1, 2)):
        _odometry_record(tmp_path, "odo", "sim open", "ground_filtered", {"ape_rmse_m": 0.5, "n_frames": 8,
                                                                          "n_not_converged": failed}, seed=seed)
        _odometry_record(tmp_path, "odo", "sim open", "kiss", {"ape_rmse_m": 1.7}, seed=seed)
    build_report(tmp_path, plots=False)
    ape = (tmp_path / "tables" / "ape_rmse.md").read_text()
    assert "| sim open | 0.500 (a) | **1.700** |" in ape, ape
    assert "(a) sim open, ground_filtered: 7 of the 14 frames after the first not registered (over 2 seeds)." in ape


def test_results_shown_from_two_lidarkit_versions_are_counted_per_version(tmp_path, capsys):
    """``lidarkit report DIR --all`` after a rerun under new code showed rows of two lidarkit versions in one table, the
    coverage line saying only that an earlier version's results of the rerun jobs were "left out". It now says how
    many of those shown are of which version, and report.csv names each row's."""
    from conftest import cli_exit_code

    for seed, version, day in ((0, "0.1.0+src.new", "02"), (1, "0.1.0+src.new", "02"), (1, "0.1.0+src.old", "01"),
                               (2, "0.1.0+src.old", "01")):
        _odometry_record(tmp_path, "odo", "k00", "kiss", {"ape_rmse_m": 0.5 + seed}, seed=seed, version=version,
                         finished=f"2026-01-{day}T00:00:00.000+00:00")
    _odometry_record(tmp_path, "odo", "k00", "vanilla", {"ape_rmse_m": 0.7}, version="0.1.0+src.old",
                     finished="2026-01-01T00:00:00.000+00:00")
    assert cli_exit_code(["report", str(tmp_path), "--all", "--no-plots"]) == 0
    said = ("4 results; 1 results in jobs/ of these jobs from an earlier lidarkit version left out; the 4 shown are "
            "from 2 lidarkit versions: 2 from 0.1.0+src.new (the latest), 2 from 0.1.0+src.old (report.csv's "
            "lidarkit_version names each row's), 0 failed")
    assert said in " ".join(capsys.readouterr().out.split())
    assert said.replace("4 results;", "4 job results;").removesuffix(", 0 failed") in (tmp_path / "report.md").read_text()
    with open(tmp_path / "report.csv", newline="") as fh:
        versions = {(r["method"], r["metric"]): r["lidarkit_version"] for r in csv.DictReader(fh)}
    assert versions[("kiss", "ape_rmse_m")] == "0.1.0+src.new / 0.1.0+src.old"
    assert versions[("vanilla", "ape_rmse_m")] == "0.1.0+src.old"
    # one version: nothing more said
    assert len(build_report(tmp_path, plots=False).versions) == 2  # (no suite.json: every result, as --all)
    one = build_report(tmp_path, plots=False, only_keys={r["key"] for r in load_results(tmp_path)
                                                         if r["lidarkit_version"] == "0.1.0+src.old"})
    assert one.versions == {"0.1.0+src.old": 3} and "lidarkit versions" not in (tmp_path / "report.md").read_text()


def test_grid_values_written_as_numbers_in_text_sort_by_value(tmp_path):
    """A grid of n_particles [20, "60", 180] listed its rows 20, 180, 60: a number written as text sorted after every
    number. Text that reads as a finite number now sorts by its value; other text after the numbers."""
    from lidarkit.bench.jobs import Job
    from lidarkit.bench.results import make_record, write_result

    for value in ("nan", 180, "60", "fast", 20, "1e3"):
        job = Job("selftest", "e", "synth", {"kind": "synthetic"}, "random_walk", {"n": value}, seed=0)
        write_result(tmp_path, make_record(job, job.key(), "1", {"status": "ok", "metrics": {"ape_rmse_m": 1.0},
                                                                 "error": None, "runtime_s": 0.1}))
    (table,) = build_report(tmp_path, plots=False).tables
    assert [row.method for row in table.rows] == [f"random_walk(n={v})" for v in (20, 60, 180, "1e3", "fast", "nan")]


SCRIPT_TASK_METRICS = """
from lidarkit.bench import Metric, Task, TaskOutput, register_task

@register_task("script_task")
class ScriptTask(Task):
    dataset_kinds = ("synthetic",)
    metrics = (Metric("translation_error_m", "trans. error [m]"), Metric("iterations", "iterations"),
               Metric("align_time_s", "align time [s]", kind="speed"))

    def run(self, job):  # slow_good: accurate, slow, few iterations; fast_bad: 10x the error, 10x faster
        good = job.method == "slow_good"
        return TaskOutput(metrics={"translation_error_m": 0.01 if good else 0.1, "iterations": 30.0 if good else 5.0,
                                   "align_time_s": 0.5 if good else 0.05})
"""


def test_a_task_the_report_cannot_load_is_headed_by_its_first_declared_accuracy_metric(tmp_path, monkeypatch):
    """A task registered in the script that ran the suite (or whose module moved) was read by metric names: every
    metric an accuracy one, sorted by name, so the speed metric align_time_s was the Summary's headline and the fastest
    method "best". Its results record the task's metric labels in order, its speed metrics and directions."""
    import importlib
    import sys

    from lidarkit.bench import tasks as bench_tasks
    from lidarkit.bench.report import summary_rows

    monkeypatch.setattr(bench_tasks, "_REGISTERED", {})
    monkeypatch.setattr(bench_tasks, "_INSTANCES", {})
    (tmp_path / "lidarkit_script_task.py").write_text(SCRIPT_TASK_METRICS)
    monkeypatch.syspath_prepend(str(tmp_path))
    try:
        importlib.import_module("lidarkit_script_task")
        (tmp_path / "suite.yaml").write_text("seeds: 2\nexperiments:\n  - {task: script_task, dataset: {kind: synthetic, "
                                             "name: syn}, methods: [slow_good, fast_bad]}\n")
        run_suite(load_suite(tmp_path / "suite.yaml"), tmp_path / "out", executor="serial")
        assert {tuple(map(tuple, r["metric_labels"])) for r in load_results(tmp_path / "out")} == {
            (("translation_error_m", "trans. error [m]"), ("iterations", "iterations"), ("align_time_s", "align time [s]"))}
        # a report in another process, the module gone (moved, or the script's own __main__)
        monkeypatch.setattr(bench_tasks, "_REGISTERED", {})
        monkeypatch.setattr(bench_tasks, "_INSTANCES", {})
        sys.modules.pop("lidarkit_script_task", None)
        (tmp_path / "lidarkit_script_task.py").unlink()
        importlib.invalidate_caches()
        report = build_report(tmp_path / "out", plots=False)
    finally:
        sys.modules.pop("lidarkit_script_task", None)
    assert [(m.name, m.label, m.kind) for m in report.tables[0].metrics] == [
        ("translation_error_m", "trans. error [m]", "accuracy"), ("iterations", "iterations", "accuracy"),
        ("align_time_s", "align time [s]", "speed"), ("runtime_s", "runtime [s]", "speed")]
    assert summary_rows(report)[1] == [["script_task", "syn", "trans. error [m]", "slow_good", "0.01 ± 0", "2"]]


def test_results_without_metric_labels_take_kind_and_direction_from_the_records(tmp_path):
    """Results written before the labels were recorded still say which metrics are speeds and which are better higher:
    the headline is an accuracy metric, ranked in its direction (recall, the highest best; "hz" led, the fastest best)."""
    from lidarkit.bench.jobs import Job
    from lidarkit.bench.report import summary_rows
    from lidarkit.bench.results import make_record, write_result

    for n in (1, 5, 9):
        for seed in (0, 1):
            job = Job("high_task_not_here", "h", "syn", {"kind": "synthetic"}, "m", {"n": n}, seed=seed)
            write_result(tmp_path, make_record(job, job.key(), "1", {
                "status": "ok", "metrics": {"recall": n / 10, "hz": 100.0 / n}, "error": None, "runtime_s": 0.1,
                "higher_is_better": ["hz", "recall"], "speed_metrics": ["hz"],
                "task_module": {"module": "high_task_module_moved_away"}}))
    report = build_report(tmp_path, plots=False)
    assert [(m.name, m.kind) for m in report.tables[0].metrics] == [("hz", "speed"), ("recall", "accuracy"),
                                                                   ("runtime_s", "speed")]
    assert summary_rows(report)[1] == [["high_task_not_here", "syn", "recall", "m(n=9)", "0.9 ± 0", "3"]]


def test_the_summary_says_tie_where_the_best_means_are_equal(tmp_path):
    """One-frame odometry runs (no APE: bad frames is the only accuracy metric) of 0 bad frames each: the Summary named
    kiss best, by sort order. Means equal up to round-off are a tie; a worse method is not in it."""
    from lidarkit.bench.report import summary_rows

    for method in ("kiss", "small_gicp"):
        _odometry_record(tmp_path / "one", "e", "k", method, {"n_bad_frames": 0.0, "hz": 20.0})
    _, rows = summary_rows(build_report(tmp_path / "one", plots=False))
    assert rows == [["odometry", "k", "bad frames (independent check)", "tie: kiss, small_gicp", "0", "2"]]

    ape = 0.3
    for method, value in (("kiss", ape), ("small_gicp", ape * (1 + 1e-14)), ("vanilla", 0.4)):
        _odometry_record(tmp_path / "ape", "e", "k", method, {"ape_se3_rmse_m": value, "n_bad_frames": 1.0})
    _, rows = summary_rows(build_report(tmp_path / "ape", plots=False))
    assert [row[2:4] for row in rows] == [["APE RMSE (SE(3)-aligned) [m]", "tie: kiss, small_gicp"]]


def test_seeds_equal_to_the_last_bits_show_no_spread(tmp_path):
    """Seeds that agree up to round-off showed `0.06198 ± 5.7e-15`; a real spread, however small, is kept."""
    from lidarkit.bench.report import format_stat, pivot, statistics_rows

    same = 0.0619815
    for seed, (a, b) in enumerate(((same, 1.0), (same + 7e-15, 1.0 + 1e-9), (same, 1.0))):
        _odometry_record(tmp_path, "e", "k", "kiss", {"ape_se3_rmse_m": a, "final_error_m": b}, seed=seed)
    table = build_report(tmp_path, plots=False).tables[0]
    assert np.std([same, same + 7e-15, same], ddof=1) > 0  # (numpy's std of them is round-off, not zero)
    assert pivot(table, "ape_se3_rmse_m")[1] == [["kiss", "0.06198 ± 0"]]
    assert statistics_rows(table)[1][0][4] == "0"
    assert table.rows[0].stats["final_error_m"][1] == pytest.approx(np.std([1.0, 1.0 + 1e-9, 1.0], ddof=1), rel=1e-6)
    assert format_stat(table.rows[0].stats["final_error_m"]) == "1 ± 5.8e-10"


@pytest.mark.parametrize("damaged", ['{\n "description": "",\n "jobs": [\n  {\n', "{", '{"suite": "s"}'])
def test_a_damaged_suite_json_is_an_error_not_every_result(tmp_path, capsys, damaged):
    """A truncated suite.json (or `{`) read as no suite: the report held every result in the folder, an earlier
    suite's too, and lost its title, without a word. It is one error line naming the file and why; --all reports every
    result, and compare says the same line."""
    import json

    from lidarkit.bench.report import suite_jobs

    for method in ("kiss", "small_gicp"):
        _odometry_record(tmp_path, "e", "k", method, {"ape_se3_rmse_m": 0.1})
    (tmp_path / "suite.json").write_text(damaged)
    try:
        json.loads(damaged)
        why = "lists no jobs (its 'jobs' is missing, empty or malformed)"
    except ValueError as err:
        why = f"not valid JSON ({err.msg}, line {err.lineno} column {err.colno})"
    line = (f"{tmp_path}/suite.json: {why}: which results are this suite's is unknown (--all: every result in the "
            "folder)")
    with pytest.raises(DataError) as exc:
        build_report(tmp_path, plots=False)
    assert str(exc.value) == line
    with pytest.raises(DataError) as exc:
        suite_jobs(tmp_path)  # (what compare restricts a folder to)
    assert str(exc.value) == line
    for command in (["report", str(tmp_path), "--no-plots"],
                    ["compare", str(tmp_path), str(tmp_path), "--method-a", "kiss", "--method-b", "small_gicp"]):
        with pytest.raises(SystemExit) as exit_:
            main(command)
        assert (exit_.value.code, capsys.readouterr().err) == (1, f"error: {line}\n")
    assert build_report(tmp_path, plots=False, every_result=True).n_records == 2
    (tmp_path / "suite.json").unlink()  # no suite.json: every result is the folder's suite
    assert build_report(tmp_path, plots=False).n_records == 2


def test_five_seeds_are_too_few_for_a_seed_comparison_and_a_verdict_that_cannot_be_significant_says_why():
    """With 5 seeds the exact two-sided Wilcoxon cannot go below p = 0.0625: the report tested them and said "no
    significant difference" without why (3 seeds were told a comparison needs 5). Seeds are paired from 6 on, and a
    verdict over too few differing units gives the smallest p they could give, as compare says it."""
    from lidarkit.bench.jobs import Job
    from lidarkit.bench.publication import reference_comparisons
    from lidarkit.bench.report import comparison_rows
    from lidarkit.eval.statistics import paired_test

    def records(n_seeds, tied_seed=None):
        out = []
        for seed in range(n_seeds):
            for method, ape in (("kiss", 0.5 + 0.01 * seed), ("small_gicp", 0.2 if seed != tied_seed else 0.5)):
                job = Job("odometry", "e", "drive", {"kind": "sim_lidar", "scene": "street"}, method, seed=seed)
                out.append({"status": "ok", "job": job.spec(), "metrics": {"ape_rmse_m": ape}, "series": {}})
        return out

    not_compared = []
    assert reference_comparisons(records(5), not_compared=not_compared) == []
    assert not_compared == ["drive, kiss vs small_gicp: 5 common seed(s) (a comparison over seeds needs 6) and no KITTI "
                            "segments to pair (a path under 100 m)"]
    (dataset, c), = reference_comparisons(records(6, tied_seed=0))  # one seed tied: 5 differ
    assert (c.pairing, c.n_pairs, c.n_ties, c.better) == ("seed", 6, 1, "")
    assert comparison_rows([(dataset, c)])[1][0][-1] == ("no significant difference (5 seeds of 6 differing: smallest "
                                                         "possible p 0.0625)")
    five = paired_test([0.5, 0.51, 0.52, 0.53, 0.54], [0.2] * 5, name_a="kiss", name_b="small_gicp", pairing="seed")
    assert comparison_rows([("drive", five)])[1][0][-1] == "no significant difference (5 seeds: smallest possible p 0.0625)"
    (_, six), = reference_comparisons(records(6))
    assert six.better == "b" and comparison_rows([("drive", six)])[1][0][-1] == "small_gicp better"


def test_seeds_that_change_nothing_are_not_told_to_be_more():
    """3 seeds over a fixed recording (every seed the same value on each side) were told "a comparison over seeds
    needs 6"; 6 seeds then made "one measurement repeated": more seeds cannot help, and the reason says so."""
    from lidarkit.bench.jobs import Job
    from lidarkit.bench.publication import reference_comparisons

    records = []
    for seed in range(3):
        for method, ape in (("kiss", 0.5), ("small_gicp", 0.2)):
            job = Job("odometry", "e", "bag", {"kind": "rosbag", "path": "/data/run.bag"}, method, seed=seed)
            records.append({"status": "ok", "job": job.spec(), "metrics": {"ape_rmse_m": ape}, "series": {}})
    not_compared = []
    assert reference_comparisons(records, not_compared=not_compared) == []
    assert not_compared == ["bag, kiss vs small_gicp: the 3 seeds gave each side one value (deterministic methods on fixed "
                            "data): one measurement repeated, which more seeds do not change; more datasets or sequences "
                            "make more measurements"]


def test_the_report_says_how_many_seeds_a_comparison_over_seeds_needs(tmp_path):
    """A comparison over the KITTI segments of 2 seeds said "with 5 or more seeds the units are the seeds", while seeds
    are paired from min_units(0.05) = 6 on (5 give p = 0.0625 at best): the note names the count the report uses."""
    from lidarkit.bench.jobs import Job
    from lidarkit.bench.results import make_record, write_result
    from lidarkit.eval.statistics import DEFAULT_ALPHA, min_units

    first, length = list(range(0, 41, 10)), [100.0] * 5
    for seed in (0, 1):
        for method, drift in (("kiss", 0.5), ("small_gicp", 1.5)):
            segments = [drift + 0.01 * seed + 0.001 * k for k in range(5)]
            job = Job("odometry", "e", "drive", {"kind": "sim_lidar", "scene": "street"}, method, seed=seed)
            write_result(tmp_path, make_record(job, job.key("1"), "1", {
                "status": "ok", "metrics": {"drift_translation_pct": float(np.mean(segments)), "ape_rmse_m": drift / 10},
                "series": {"drift_segments": {"first_frame": first, "length_m": length, "translation_pct": segments,
                                              "rotation_deg_per_100m": [0.1] * 5, "speed_mps": [10.0] * 5}},
                "info": {}, "error": None, "runtime_s": 0.1, "finished_utc": "2026-01-01T00:00:00.000+00:00"}))
    build_report(tmp_path, plots=False)
    text = " ".join((tmp_path / "report.md").read_text().split())
    assert min_units(DEFAULT_ALPHA) == 6
    assert ("drive, kiss vs small_gicp: the segments overlap (one starts every 10 frames): they are not independent units "
            "and the p-value is optimistic; with 6 or more seeds the units are the seeds (lidarkit compare)") in text
