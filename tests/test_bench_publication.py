"""Publication tables and paired comparisons of odometry results: what a comparison not made says, and a Mean over
RPEs per selected frame only where the selections step alike."""

from __future__ import annotations

import csv

import pytest

from lidarkit.bench.jobs import Job
from lidarkit.bench.publication import reference_comparisons
from lidarkit.bench.report import build_report
from lidarkit.bench.results import make_record, write_result
from lidarkit.bench.tasks.odometry import METRIC_ALIGNMENT_BY_NAME, SELECTED_FRAME

ACES = {"kind": "carmen", "path": "/data/carmen_2d/aces.clf.bz2"}
KITTI = {"kind": "kitti", "path": "/data/kitti_odometry/sequences/00"}


def record(method, seed, metrics, dataset=ACES, name="ACES", params=None):
    job = Job("odometry", "cv", name, dataset, method, params or {}, seed=seed, options={"frames": "200:240"})
    return {"status": "ok", "job": job.spec(), "metrics": metrics, "series": {}}


def test_a_relations_only_dataset_is_not_compared_for_want_of_seeds_but_of_apes():
    """ACES over 6 seeds (suite s16) read "6 common seed(s) (a comparison over seeds needs 6) and no KITTI segments to
    pair": the log has relation ground truth only, no APE nor KITTI drift to compare."""
    records = [record(method, seed, {"relation_trans_mean_m": value, "n_bad_frames": 1.0})
               for seed in range(6) for method, value in (("kiss", 0.1051), ("vanilla", 0.389))]
    not_compared = []
    assert reference_comparisons(records, not_compared=not_compared) == []
    assert not_compared == ["ACES, kiss vs vanilla: no APE or KITTI drift on this dataset (relation ground truth only)"]


def test_seeds_without_a_value_are_counted_apart_and_the_others_are_compared():
    """A seed whose APE is NaN (written as null in its result) made the 6 seeds read "6 common seed(s) (a comparison
    over seeds needs 6)", and 7 such seeds were not compared at all: the seeds with a value are counted, those without
    named, and 6 with a value are compared."""
    def records(n_seeds):
        return [record(method, seed, {"ape_rmse_m": None if (method, seed) == ("vanilla", 3) else value + 0.01 * seed},
                       dataset=KITTI, name="K00")
                for seed in range(n_seeds) for method, value in (("kiss", 0.5), ("vanilla", 0.2))]

    not_compared = []
    assert reference_comparisons(records(6), not_compared=not_compared) == []
    assert not_compared == ["K00, kiss vs vanilla: 5 common seed(s) with a value (seed(s) 3 without one on a side; a "
                            "comparison over seeds needs 6) and no KITTI segments to pair (a path under 100 m)"]
    (dataset, c), = reference_comparisons(records(7))
    assert (dataset, c.pairing, c.n_pairs, c.better) == ("K00", "seed", 6, "b")
    assert c.note == "seed(s) 3 left out: no value (NaN, inf) on one side"


def test_step_patterns_of_frame_selections():
    from lidarkit.bench.publication import step_pattern

    assert step_pattern("0:10:3") == step_pattern([0, 3, 6, 9]) == step_pattern("5:100:3") == (3,)
    assert step_pattern([0, 3, 4, 9]) == (3, 1, 5)
    assert step_pattern("-4:") == step_pattern(None) == (1,)


def write_rpe(folder, experiment, frames, method, rpe):
    job = Job("odometry", experiment, "k00", KITTI, method, {}, options={"frames": frames})
    write_result(folder, make_record(job, job.key("1"), "1", {
        "status": "ok", "metrics": {"rpe_trans_rmse_m": rpe}, "series": {}, "error": None, "runtime_s": 0.1,
        "info": {"metric_alignment": {**METRIC_ALIGNMENT_BY_NAME, "rpe_trans_rmse_m": SELECTED_FRAME}},
        "finished_utc": "2026-01-01T00:00:00.000+00:00"}))


def test_rpes_per_selected_frame_of_selections_that_step_differently_have_no_mean(tmp_path):
    """KITTI 00 frames 0:10:3 and [0, 3, 4, 9] (suite s13): the table per selected frame averaged an RPE over steps of
    3 frames and one over steps of 3, 1 and 5 into one Mean (0.3705), where the docs say a Mean is never over two
    steps. Such a table has no Mean and its note says why; selections that step alike keep theirs."""
    write_rpe(tmp_path, "rev", "0:10:3", "vanilla", 0.3972)
    write_rpe(tmp_path, "unsorted", [0, 3, 4, 9], "vanilla", 0.3438)
    build_report(tmp_path, plots=False)
    with open(tmp_path / "tables" / "rpe_rmse_selected_frame.csv", newline="") as fh:
        assert list(csv.reader(fh)) == [["sequence", "vanilla"], ["k00(frames=0:10:3) *", "0.3972"],
                                        ["k00(frames=[0, 3, 4, 9]) *", "0.3438"]]
    md = (tmp_path / "tables" / "rpe_rmse_selected_frame.md").read_text()
    assert "Mean**" not in md
    assert ("No Mean: the selections step differently (k00(frames=0:10:3): a step of 3 frames; k00(frames=[0, 3, 4, 9]): "
            "steps of 3, 1, 5 frames), and a Mean is never over two steps.") in md
    assert "\\midrule\nk00(frames=0:10:3) * & 0.3972 \\\\\nk00(frames=[0, 3, 4, 9]) * & 0.3438 \\\\\n\\bottomrule" in (
        tmp_path / "tables" / "rpe_rmse_selected_frame.tex").read_text()
    (tmp_path / "jobs").rename(tmp_path / "differently")
    write_rpe(tmp_path, "rev", "0:10:3", "vanilla", 0.3972)
    write_rpe(tmp_path, "list", [0, 3, 6, 9], "vanilla", 0.3838)
    build_report(tmp_path, plots=False)
    with open(tmp_path / "tables" / "rpe_rmse_selected_frame.csv", newline="") as fh:
        label, mean = list(csv.reader(fh))[-1]
    assert label == "Mean" and float(mean) == pytest.approx((0.3972 + 0.3838) / 2, rel=1e-12)


def test_a_dataset_without_an_ok_plain_kiss_row_says_why_it_has_no_comparison(tmp_path):
    """kiss failed on every seed of one dataset, and ran with params only on another: neither said "no comparison"
    (the docs promise one line per method and why), and kiss(deskew=False) was not taken for the reference."""
    def write(method, seed, ape, name, params=None, status="ok"):
        job = Job("odometry", "cv", name, KITTI, method, params or {}, seed=seed)
        write_result(tmp_path, make_record(job, job.key("1"), "1", {
            "status": status, "metrics": {"ape_rmse_m": ape} if status == "ok" else {}, "series": {}, "runtime_s": 0.1,
            "error": None if status == "ok" else {"type": "RuntimeError", "message": "no scans", "traceback": ""},
            "info": {"metric_alignment": METRIC_ALIGNMENT_BY_NAME}, "finished_utc": "2026-01-01T00:00:00.000+00:00"}))

    for seed in range(2):
        write("kiss", seed, None, "bag", status="failed")
        write("small_gicp", seed, 0.3 + seed, "bag")
        write("kiss", seed, 0.2 + seed, "k00", params={"deskew": False})
        write("small_gicp", seed, 0.3 + seed, "k00")
    report = build_report(tmp_path, plots=False)
    assert report.publication.not_compared == [
        "bag, kiss vs small_gicp: kiss has no ok result on this dataset",
        "k00, kiss vs small_gicp: no plain kiss row (it ran as kiss(deskew=False))"]
    md = (tmp_path / "report.md").read_text(encoding="utf-8")
    assert "- no comparison: bag, kiss vs small_gicp: kiss has no ok result on this dataset\n" in md

    # a dataset kiss did not run on, beside one it ran on; a suite that runs no kiss at all says nothing
    records = [record(method, seed, {"ape_rmse_m": 0.5}, dataset=KITTI, name=name)
               for seed in range(2) for method, name in (("kiss", "K00"), ("vanilla", "K00"), ("vanilla", "K01"))]
    not_compared = []
    reference_comparisons(records, not_compared=not_compared)
    assert not_compared[-1] == "K01, kiss vs vanilla: kiss did not run on this dataset"
    not_compared = []
    reference_comparisons([r for r in records if r["job"]["method"] != "kiss"], not_compared=not_compared)
    assert not_compared == []
