"""Report figures of names matplotlib would read as math, figures that cannot be drawn, and the captions of report.md."""

from __future__ import annotations

import pytest

from lidarkit.bench.jobs import Job
from lidarkit.bench.report import build_report
from lidarkit.bench.results import make_record, write_result
from lidarkit.errors import OutputError

WALK = [[0.0, 0.0], [1.0, 0.1], [2.0, 0.3], [3.0, 0.2]]


def write(folder, experiment, dataset_name, series, method="random_walk", params=None):
    job = Job("selftest", experiment, dataset_name, {"kind": "synthetic", "name": dataset_name}, method, params or {}, seed=0)
    write_result(folder, make_record(job, job.key("1"), "1", {
        "status": "ok", "metrics": {"ape_rmse_m": 0.25}, "series": series, "info": {}, "error": None,
        "runtime_s": 0.1, "finished_utc": "2026-01-01T00:00:00.000+00:00"}))


def test_names_with_dollar_signs_are_drawn_as_written(tmp_path):
    """A dataset named 'drive_$1_$2' (and a method param '$\\x$') was read by matplotlib as math: its parse error was
    a 274-line traceback and no report.md, report.csv or report.html at all."""
    series = {"trajectory_xy": {"ref": WALK, "est": WALK},
              "error_over_time": {"t": [0.0, 0.1, 0.2, 0.3], "error": [0.0, 0.1, 0.2, 0.1], "label": "error in $m$ [m]"}}
    write(tmp_path, "e", "drive_$1_$2", series, params={"mode": "$\\x$"})
    report = build_report(tmp_path)
    assert sorted(p.filename.split("_")[0] for p in report.plots) == ["err", "traj"]
    assert all(p.png.startswith(b"\x89PNG") for p in report.plots)
    assert "drive_$1_$2" in (tmp_path / "report.md").read_text(encoding="utf-8")
    from lidarkit.bench.report import _literal

    assert _literal("drive_$1_$2") == r"drive_\$1_\$2"


def test_a_figure_that_cannot_be_drawn_is_one_output_error_and_the_tables_are_written(tmp_path):
    """Any error while a figure is drawn (here a record's trajectory of one row) ended the report with a traceback and
    no file: it is one OutputError line naming the figure, after report.md/csv/html are written without figures."""
    write(tmp_path, "e", "syn", {"trajectory_xy": {"ref": WALK, "est": [1.0, 2.0]}})
    with pytest.raises(OutputError) as info:
        build_report(tmp_path)
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith(f"{tmp_path}: no figures (traj_selftest_e_syn_")
    assert "cannot be drawn (IndexError: " in message
    assert message.endswith("); report.md, report.csv and report.html are written without them")
    markdown = (tmp_path / "report.md").read_text(encoding="utf-8")
    assert "| syn | random_walk |" in markdown.replace("  ", " ")
    assert "- report: no figures: traj_selftest_e_syn_" in markdown and "## Plots" not in markdown
    assert (tmp_path / "report.csv").is_file() and (tmp_path / "report.html").is_file()
    assert not list((tmp_path / "plots").glob("*.png"))


def test_report_md_has_each_figure_caption_under_it(tmp_path):
    """The captions were in report.html only; report.md had ![title](plots/...) alone."""
    series = {"trajectory_xy": {"ref": WALK, "est": WALK},
              "error_over_time": {"t": [0.0, 0.1, 0.2, 0.3], "error": [0.0, 0.1, 0.2, 0.1], "label": "position error [m]"}}
    write(tmp_path, "walk*2", "syn_a", series)
    report = build_report(tmp_path)
    lines = (tmp_path / "report.md").read_text(encoding="utf-8").splitlines()
    assert len(report.plots) == 2
    for plot in report.plots:
        at = lines.index(f"![{plot.title}](plots/{plot.filename})")
        assert lines[at + 1] == ""
        assert lines[at + 2].startswith("*") and lines[at + 2].endswith("*")
    traj = next(p for p in report.plots if p.filename.startswith("traj_"))
    at = lines.index(f"![{traj.title}](plots/{traj.filename})")
    assert lines[at + 2] == ("*Top view of the estimated trajectories (first seed of each method) against the reference "
                             r"of that seed and sweep instant (black): walk\*2, syn_a.*")
