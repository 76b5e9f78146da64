"""What the report counts: the rows the Summary ranked, and seeds whose result file cannot be read told from those not run."""

from __future__ import annotations

import textwrap

from lidarkit.bench.report import build_report, summary_rows
from lidarkit.bench.runner import run_suite
from lidarkit.bench.suite import load_suite


def test_the_summary_counts_a_method_ranked_in_two_experiments_twice(tmp_path):
    """random_walk(noise_m=0.01) in two experiments and noise_m=0.1 in one: 3 rows ranked, "methods ranked" read 2."""
    suite = tmp_path / "suite.yaml"
    suite.write_text(textwrap.dedent("""
        seeds: 2
        experiments:
          - {name: x, task: selftest, dataset: {kind: synthetic, name: synth}, methods: [{name: random_walk, params: {noise_m: 0.01}}]}
          - name: y
            task: selftest
            dataset: {kind: synthetic, name: synth}
            methods: [{name: random_walk, grid: {noise_m: [0.01, 0.1]}}]
    """))
    run_suite(load_suite(suite), tmp_path / "out", executor="serial")
    report = build_report(tmp_path / "out", plots=False)
    assert len(report.tables[0].rows) == 3
    header, rows = summary_rows(report)
    assert header[5] == "methods ranked"
    assert [row[1] for row in rows] == ["synth"] and rows[0][5] == "3"


def test_a_seed_whose_result_file_cannot_be_read_is_called_unreadable_in_its_cells(tmp_path):
    """Its cells said "(1 of 3 not run)" for a job that ran and whose result file is damaged."""
    suite = tmp_path / "suite.yaml"
    suite.write_text(textwrap.dedent("""
        seeds: [0, 1, 2]
        experiments:
          - {name: walk, task: selftest, dataset: {kind: synthetic, name: synth}, methods: [random_walk]}
    """))
    run_suite(load_suite(suite), tmp_path / "out", executor="serial")
    sorted((tmp_path / "out" / "jobs").glob("*.json"))[0].write_text("{")
    report = build_report(tmp_path / "out", plots=False)
    header, rows = summary_rows(report)
    assert rows[0][4].endswith(" (1 of 3 unreadable)"), rows[0][4]
    markdown = report.markdown_path.read_text()
    assert "(1 of 3 unreadable)" in markdown and "not run)" not in markdown
    (row,) = report.tables[0].rows
    assert (row.n_ok, row.n_missing, row.n_unreadable) == (2, 1, 1)
