"""The report's headline per dataset: a CARMEN log scored by its relations beside a KITTI sequence scored by APE in one
odometry section (suite s23: KITTI 00 frames 0:4 and ACES frames 200:240, vanilla and kiss)."""

from __future__ import annotations

from lidarkit.bench.jobs import Job
from lidarkit.bench.report import build_report, statistics_rows, summary_rows
from lidarkit.bench.results import make_record, write_result
from lidarkit.bench.tasks.odometry import METRIC_ALIGNMENT_BY_NAME

DATASETS = {"K00": {"kind": "kitti", "path": "/data/kitti_odometry/sequences/00"},
            "ACES": {"kind": "carmen", "path": "/data/carmen_2d/aces.clf.bz2"}}
#: the metrics the s23 jobs recorded (KITTI 00 frames 0:4: APE; ACES frames 200:240: relations only)
RESULTS = {
    ("k", "K00", "kiss"): {"ape_se3_rmse_m": 0.1651, "ape_rmse_m": 0.2874, "rpe_trans_rmse_m": 0.155,
                                  "n_bad_frames": 0.0, "hz": 4.977, "n_frames": 4.0, "n_not_converged": 0.0},
    ("k", "K00", "vanilla"): {"ape_se3_rmse_m": 0.04373, "ape_rmse_m": 0.09862, "rpe_trans_rmse_m": 0.07175,
                                     "n_bad_frames": 0.0, "hz": 4.402, "n_frames": 4.0, "n_not_converged": 0.0},
    ("c", "ACES", "kiss"): {"relation_trans_mean_m": 0.1051, "relation_rot_mean_deg": 0.5296,
                                    "n_bad_frames": 1.0, "hz": 428.5, "n_frames": 40.0, "n_not_converged": 0.0},
    ("c", "ACES", "vanilla"): {"relation_trans_mean_m": 0.4596, "relation_rot_mean_deg": 0.835,
                                       "n_bad_frames": 4.0, "hz": 73.56, "n_frames": 40.0, "n_not_converged": 0.0},
}


def write_results(folder, datasets=("K00", "ACES"), seeds=(0,)):
    for (experiment, name, method), metrics in RESULTS.items():
        if name not in datasets:
            continue
        params = {"voxel_size_m": 1.0} if method == "vanilla" else {}
        for seed in seeds:
            job = Job("odometry", experiment, name, DATASETS[name], method, params, seed=seed,
                      options={"frames": "0:4" if name == "K00" else "200:240"})
            write_result(folder, make_record(job, job.key("1"), "1", {
                "status": "ok", "metrics": {k: v * (1 + 0.01 * seed) for k, v in metrics.items()}, "series": {},
                "info": {"metric_alignment": dict(METRIC_ALIGNMENT_BY_NAME)}, "error": None, "runtime_s": 1.0,
                "finished_utc": "2026-01-01T00:00:00.000+00:00"}))


def test_a_relations_only_dataset_beside_one_with_poses_has_its_own_headline(tmp_path):
    """The ACES rows had no Summary row and only dashes in the methods x datasets table: the section's one headline
    was the APE, which the log (relation ground truth only) has none of. Each dataset is now headed by the first
    accuracy metric with a value on its rows, and every table says which."""
    write_results(tmp_path)
    report = build_report(tmp_path, plots=False)
    (table,) = report.tables
    _, rows = summary_rows(report)
    assert rows == [["odometry", "ACES", "relations: mean trans. error [m]", "c: kiss", "0.1051", "2"],
                    ["odometry", "K00", "APE RMSE (SE(3)-aligned) [m]", "k: vanilla(voxel_size_m=1)", "0.04373", "2"]]
    md = report.markdown_path.read_text()
    assert ("relations: mean trans. error [m], methods x datasets:\n\n| method | ACES |\n|---|---|\n"
            "| c: kiss | 0.1051 |\n| c: vanilla(voxel_size_m=1) | 0.4596 |\n") in md
    assert ("APE RMSE (SE(3)-aligned) [m], methods x datasets:\n\n| method | K00 |\n|---|---|\n"
            "| k: kiss | 0.1651 |\n| k: vanilla(voxel_size_m=1) | 0.04373 |\n") in md
    assert "| c: kiss | – |" not in md  # (the ACES column of dashes under the APE)
    assert "| c: kiss | 428.5 |  |" in md  # the speed view keeps every dataset
    header, stats = statistics_rows(table)
    assert header[:4] == ["dataset", "headline metric", "method", "n"]
    assert [row[:5] for row in stats] == [["ACES", "relations: mean trans. error [m]", "c: kiss", "1", "0.1051"],
                                          ["ACES", "relations: mean trans. error [m]", "c: vanilla(voxel_size_m=1)", "1", "0.4596"],
                                          ["K00", "APE RMSE (SE(3)-aligned) [m]", "k: kiss", "1", "0.1651"],
                                          ["K00", "APE RMSE (SE(3)-aligned) [m]", "k: vanilla(voxel_size_m=1)", "1", "0.04373"]]
    from lidarkit.bench.report import headline_metrics

    assert {d: m.name for d, m in headline_metrics(table).items()} == {"ACES": "relation_trans_mean_m",
                                                                       "K00": "ape_se3_rmse_m"}


def test_a_section_of_one_kind_of_dataset_reports_as_before(tmp_path):
    """ACES alone, and KITTI alone: one headline for the section, no headline column, one methods x datasets view."""
    for datasets, metric, label in ((("ACES",), "relation_trans_mean_m", "relations: mean trans. error [m]"),
                                    (("K00",), "ape_se3_rmse_m", "APE RMSE (SE(3)-aligned) [m]")):
        folder = tmp_path / datasets[0]
        write_results(folder, datasets, seeds=(0, 1))
        report = build_report(folder, plots=False)
        (table,) = report.tables
        _, rows = summary_rows(report)
        assert [row[2] for row in rows] == [label]
        header, stats = statistics_rows(table)
        assert header[:3] == ["dataset", "method", "n"] and len(stats) == 2
        md = report.markdown_path.read_text()
        assert md.count("methods x datasets:") == 2 and f"{label}, methods x datasets:" in md
        assert "Statistics over seeds of the headline metric</caption>" in report.html_path.read_text()


def test_the_terminal_summary_shows_each_datasets_headline(tmp_path):
    """`lidarkit bench`'s summary printed the section's first two accuracy metrics (APE): the ACES rows were dashes."""
    from rich.console import Console

    from lidarkit.cli.bench_cmd import summary_table

    write_results(tmp_path)
    (table,) = summary_table(build_report(tmp_path, plots=False))
    console = Console(width=250, record=True)
    console.print(table)
    lines = console.export_text().splitlines()
    assert "relations: mean trans. error" in lines[2]
    (aces_kiss,) = [line for line in lines if "ACES" in line and "kiss" in line]
    assert aces_kiss.split("│")[-3].strip() == "0.105"
