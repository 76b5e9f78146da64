"""Report figures of a task's sweep over parameters that are not numbers, and of ICP RMSE histories that are the final
RMSE alone."""

from __future__ import annotations

import pytest

from lidarkit.bench import Metric, Task, TaskOutput
from lidarkit.bench.jobs import Job
from lidarkit.bench.report import build_report
from lidarkit.bench.results import load_results, make_record, write_result
from lidarkit.errors import DataError

KITTI = {"kind": "kitti", "path": "/data/kitti_odometry/sequences/00"}


class ModeSweepTask(Task):
    dataset_kinds = ("synthetic",)
    metrics = (Metric("error_m", "mode error [m]"),)
    sweep_plots = (("mode", "error_m"),)

    def run(self, job):
        return TaskOutput(metrics={"error_m": 1.0})


def write(folder, task, method, params, seed, metrics, series=None, info=None):
    name, dataset = ("k00", KITTI) if task == "icp_pair" else ("synthetic", {"kind": "synthetic"})
    job = Job(task, "e", name, dataset, method, params, seed=seed)
    write_result(folder, make_record(job, job.key("1"), "1", {
        "status": "ok", "metrics": metrics, "series": series or {}, "info": info or {}, "error": None,
        "runtime_s": 0.1, "finished_utc": "2026-01-01T00:00:00.000+00:00"}))


def test_a_sweep_over_text_lists_and_null_draws_them_as_categories(tmp_path, monkeypatch):
    """A grid `mode: [fast, slow]` ended `lidarkit report` with "ValueError: could not convert string to float:
    'fast'" (a list or null: TypeError): such values are categories on the x axis, numbers first, then by text."""
    from lidarkit.bench import tasks as bench_tasks

    monkeypatch.setattr(bench_tasks, "_REGISTERED", {})
    monkeypatch.setattr(bench_tasks, "_INSTANCES", {})
    bench_tasks.register_task("mode_sweep_task")(ModeSweepTask)
    modes = {"slow": 0.5, "fast": 1.0, "10": 0.7, None: 2.0}
    for seed in range(2):
        for mode, error in modes.items():
            write(tmp_path, "mode_sweep_task", "m", {"mode": mode}, seed, {"error_m": error + 0.01 * seed})
        write(tmp_path, "mode_sweep_task", "m", {"mode": [1, 2]}, seed, {"error_m": 3.0})
    report = build_report(tmp_path)
    (sweep,) = [p for p in report.plots if p.filename.startswith("sweep_")]
    assert sweep.title == "mode error [m] vs mode — mode_sweep_task"
    assert sweep.caption == ("mode error [m] against mode: mean ± std over seeds, one line per experiment, dataset and "
                             "method; the values of mode as categories (numbers by value, then the rest by their text).")
    from lidarkit.bench.report import _sweep_plots, sweep_categories

    values = [r["job"]["params"]["mode"] for r in load_results(tmp_path)]
    assert list(sweep_categories(values).values()) == ["10", "[1,2]", "fast", "null", "slow"]

    # anything else that cannot be drawn is one error naming the task and the parameter
    records = load_results(tmp_path)
    records[0]["metrics"]["error_m"] = "n/a"
    with pytest.raises(DataError, match=r"^task mode_sweep_task: its sweep of error_m over parameter 'mode' cannot be "
                                        r"drawn \(ValueError"):
        _sweep_plots(records)


def test_icp_rmse_histories_of_the_final_rmse_alone_are_not_drawn_as_curves(tmp_path):
    """small_gicp (4 iterations) and kiss report their final RMSE alone: each was drawn as one point at iteration 1,
    and vanilla's history, whose first value is at the starting pose, began at iteration 1 too."""
    def pair(iterations):
        return {"pairs": [{"target": 0, "source": 1, "iterations": iterations}]}

    for method, history, iterations in (("vanilla", [0.30, 0.25, 0.22, 0.21], 3), ("small_gicp", [0.22], 4),
                                        ("kiss", [0.69], None)):
        write(tmp_path, "icp_pair", method, {}, 0, {"final_rmse_m": history[-1]}, {"rmse_history": [history]},
              pair(iterations))
    (plot,) = [p for p in build_report(tmp_path).plots if p.filename.startswith("rmse_")]
    assert plot.caption == ("Correspondence RMSE per ICP iteration (first pair, log scale; iteration 0 is the starting "
                            "pose; first seed of each method): e, k00. Not drawn, their library reports the final "
                            "RMSE alone: kiss, small_gicp.")
    from lidarkit.bench.report import rmse_histories

    assert rmse_histories(load_results(tmp_path)) == ({"vanilla": ([0.30, 0.25, 0.22, 0.21], 0)}, ["kiss", "small_gicp"])
