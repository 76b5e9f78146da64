"""`lidarkit compare` over real bench folders of small synthetic tasks: what it refuses, pairs and says."""

from __future__ import annotations

import json
import logging
import textwrap
from pathlib import Path

import numpy as np
import pytest
from test_eval_statistics import _register_metric_task

from lidarkit.cli import main
from lidarkit.errors import ConfigError, DataError, EvaluationError
from lidarkit.eval import compare


def run_cli(argv: list[str], capsys) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as exc:
        main(argv)
    out, err = capsys.readouterr()
    return int(exc.value.code or 0), out, err


def _task(name: str, metrics, info=lambda job: {}) -> None:
    """A bench task on synthetic data reporting ``metrics(job)`` (a dict) and ``info(job)``."""
    from lidarkit.bench import Metric

    _register_metric_task(name, tuple(Metric(m, m) for m in ("error_m", "ape_rmse_m", "drift_translation_pct")), metrics, info)


def _error(job) -> dict[str, float]:
    """good beats bad by 0.4 on every seed, each seed another draw."""
    noise = 0.01 * np.random.default_rng(job.seed).random()
    return {"ape_rmse_m": (0.1 if job.method == "good" else 0.5) + noise}


def _bench(tmp_path: Path, name: str, suite: str, out: str | None = None) -> Path:
    from lidarkit.bench import load_suite, run_suite

    (tmp_path / f"{name}.yaml").write_text(textwrap.dedent(suite))
    folder = tmp_path / (out or name)
    run_suite(load_suite(tmp_path / f"{name}.yaml"), folder, executor="serial")
    return folder


def test_json_into_a_compared_folder_is_refused_and_checked_before_the_work(tmp_path, capsys):
    """`compare A A --json A/suite.json` replaced A's suite manifest and exited 0 (the next compare then pooled an
    earlier suite's results), and `--json FOLDER` failed only after the comparison was printed."""
    _task("json_test_task", _error)
    out = _bench(tmp_path, "s", "seeds: 6\nexperiments:\n  - {task: json_test_task, dataset: {kind: synthetic}, methods: [good, bad]}\n")
    manifest = (out / "suite.json").read_bytes()
    pick = ["--method-a", "good", "--method-b", "bad"]
    code, stdout, err = run_cli(["compare", str(out), str(out), *pick, "--json", str(out / "suite.json")], capsys)
    assert (code, stdout) == (1, "")
    assert err == f"error: --json: {out}/suite.json is inside {out} (RUN_A): compare never writes into a folder it reads\n"
    assert (out / "suite.json").read_bytes() == manifest
    base = tmp_path / "baseline"
    code, stdout, err = run_cli(["compare", str(out), str(out), *pick, "--noise-from", str(base), "--json",
                                 str(base / "manifest.json")], capsys)
    assert (code, stdout) == (1, "") and "is inside " + str(base) + " (--noise-from)" in err
    code, stdout, err = run_cli(["compare", str(out), str(out), *pick, "--json", str(tmp_path)], capsys)
    assert (code, stdout) == (1, "") and err == f"error: {tmp_path}: cannot write: is a folder (a file name is needed here)\n"
    code, stdout, _ = run_cli(["compare", str(out), str(out), *pick, "--json", str(tmp_path / "cmp.json")], capsys)
    assert code == 0 and json.loads((tmp_path / "cmp.json").read_text())["n_pairs"] == 6


def test_an_unreadable_suite_json_is_an_error_not_every_result(tmp_path):
    """A corrupt suite.json read as "no suite": every result of the folder, an earlier suite's too, was compared."""
    _task("corrupt_test_task", _error)
    out = _bench(tmp_path, "s", "seeds: 6\nexperiments:\n  - {task: corrupt_test_task, dataset: {kind: synthetic}, methods: [good, bad]}\n")
    (out / "suite.json").write_text("{not json")
    with pytest.raises(DataError) as exc:
        compare(out, out, method_a="good", method_b="bad")
    assert str(exc.value) == (f"{out}/suite.json: not valid JSON (Expecting property name enclosed in double quotes, line 1 "
                              "column 2): which results are this suite's is unknown (--all: every result in the folder)")
    assert compare(out, out, method_a="good", method_b="bad", every_result=True).n_pairs == 6


def test_metrics_under_different_alignments_are_not_compared(tmp_path):
    """A Sim(3)-aligned APE (monocular VO) was ranked against an SE(3)-aligned one (scale from ground truth) without a
    word; the report labels such cells apart and never ranks across them."""
    _task("aligned_test_task", lambda job: {"ape_rmse_m": 0.1 + 0.01 * job.seed},
          lambda job: {"metric_alignment": {"ape_rmse_m": "SE(3)-aligned" if job.method == "gt_scale" else "Sim(3)-aligned"}})
    out = _bench(tmp_path, "s", "seeds: 6\nexperiments:\n  - {task: aligned_test_task, dataset: {kind: synthetic}, "
                 "methods: [gt_scale, mono, mono2]}\n")
    with pytest.raises(ConfigError) as exc:
        compare(out, out, method_a="gt_scale", method_b="mono", metric="ape_rmse_m")
    assert str(exc.value) == ("metric: gt_scale states ape_rmse_m SE(3)-aligned, mono Sim(3)-aligned: values under different "
                              "alignments are not compared")
    assert compare(out, out, method_a="mono", method_b="mono2", metric="ape_rmse_m").n_pairs == 6


def test_dataset_names_are_labels_not_data(tmp_path):
    """One spec named "sim street" in one suite and "street" in another was "runs over different data", and the error
    listed every seed of both sides; two entries of one suite differing by name only are one dataset (counted once)."""
    _task("named_test_task", _error)
    suite = "seeds: 10\nexperiments:\n  - {{task: named_test_task, datasets: [{datasets}], methods: [{method}]}}\n"
    a = _bench(tmp_path, "a", suite.format(datasets="{kind: synthetic, size: 3, name: sim street}", method="good"))
    b = _bench(tmp_path, "b", suite.format(datasets="{kind: synthetic, size: 3, name: street}, {kind: synthetic, size: 3, "
                                           "name: street again}", method="bad"))
    result = compare(a, b)
    assert (result.n_pairs, result.pairing, result.better, result.note) == (10, "seed", "a", "")
    other = _bench(tmp_path, "c", suite.format(datasets="{kind: synthetic, size: 4, name: street}", method="bad"))
    with pytest.raises(EvaluationError) as exc:
        compare(a, other)
    assert str(exc.value) == (f"compare: runs over different data: no (dataset, seed) in common between {a} (good: sim street, "
                              f"seed 0; sim street, seed 1; sim street, seed 2; ... (10 in all)) and {other} (bad: street, "
                              "seed 0; street, seed 1; street, seed 2; ... (10 in all)): their dataset specs differ in size (3 "
                              "in A, 4 in B)")


def test_one_seed_per_dataset_pairs_datasets_and_says_so(tmp_path, capsys):
    """With one seed per dataset the units are the datasets, but compare called them seeds ("2 paired seeds ... at least 6
    are needed"), advice to add seeds that over fixed data (KITTI) would change nothing."""
    _task("per_dataset_test_task", lambda job: {"ape_rmse_m": (0.1 if job.method == "good" else 0.5) + job.dataset["size"]})
    out = _bench(tmp_path, "s", "seeds: 1\nexperiments:\n  - {task: per_dataset_test_task, datasets: [{kind: synthetic, "
                 "size: 1}, {kind: synthetic, size: 2}, {kind: synthetic, size: 3}], methods: [good, bad]}\n")
    result = compare(out, out, method_a="good", method_b="bad")
    assert (result.pairing, result.n_pairs, result.better) == ("dataset", 3, "")
    assert ("with 3 differing datasets the smallest p this test can give is 0.25: at least 6 are needed to reach p < 0.05"
            in result.verdict())
    code, stdout, _ = run_cli(["compare", str(out), str(out), "--method-a", "good", "--method-b", "bad"], capsys)
    assert code == 0 and "(3 paired datasets, 0 ties)" in stdout


def test_units_missing_the_metric_are_left_out_naming_the_side_and_why(tmp_path):
    """"metric 'drift_translation_pct' missing for short, seed 0" named neither the side, nor how many units, nor that
    KITTI drift needs 100 m of path, nor the metric that would compare; such units are left out now, as the report
    leaves out such seeds, and the note says all of it."""
    def drift(job):
        metrics = {"ape_rmse_m": 0.2 + 0.01 * job.seed, "drift_translation_pct": 1.0 + 0.1 * job.seed}
        if job.method == "stopper" and job.seed < 2:
            metrics["drift_translation_pct"] = None  # (a path under 100 m: no KITTI segment)
        return metrics

    _task("drift_test_task", drift)
    out = _bench(tmp_path, "s", "seeds: 6\nexperiments:\n  - {task: drift_test_task, dataset: {kind: synthetic, name: short}, "
                 "methods: [walker, stopper]}\n")
    # (the task's headline is ape_rmse_m: drift is asked for)
    result = compare(out, out, method_a="walker", method_b="stopper", metric="drift_translation_pct")
    assert (result.n_pairs, result.n_ties) == (4, 4)
    assert result.note == ("2 of 6 (dataset, seed) unit(s) left out: stopper has no value (null) of drift_translation_pct "
                           "there (short, seed 0; short, seed 1): KITTI drift needs 100 m of path, --metric ape_rmse_m "
                           "compares every unit")


def test_failed_jobs_earlier_suites_baselines_and_one_folder_twice_are_said_plainly(tmp_path, caplog):
    """B's failed seeds were "units only in A"; a method of an earlier suite was "not found" with no word of --all; a
    baseline folder read "no successful job results in jobs/"; one folder given twice warned of each bad result twice;
    compare(None, ...) was a TypeError traceback."""
    def flaky(job):
        if job.method == "bad" and job.seed < 2:
            raise RuntimeError("failed on purpose")
        return _error(job)

    _task("flaky_test_task", flaky)
    out = _bench(tmp_path, "s", "seeds: 8\nexperiments:\n  - {task: flaky_test_task, dataset: {kind: synthetic}, methods: [good, bad]}\n")
    result = compare(out, out, method_a="good", method_b="bad")
    assert result.n_pairs == 6 and result.note == "2 (dataset, seed) unit(s) where B's job failed are left out (lidarkit report lists why)"
    (out / "jobs" / "broken.json").write_text("{")
    with caplog.at_level(logging.WARNING):
        compare(out, out, method_a="good", method_b="bad")
    assert sum("ignoring unreadable result" in r.getMessage() for r in caplog.records) == 1
    _bench(tmp_path, "only_good", "seeds: 8\nexperiments:\n  - {task: flaky_test_task, dataset: {kind: synthetic}, methods: [good]}\n",
           out="s")
    with pytest.raises(ConfigError) as exc:
        compare(out, out, method_a="good", method_b="bad")
    assert str(exc.value) == (f"{out}: method 'bad' not found; this folder has: good (it is in results of an earlier suite "
                              "here: --all compares every result)")
    baseline = tmp_path / "baseline"
    (baseline / "jobs").mkdir(parents=True)
    (baseline / "manifest.json").write_text(json.dumps({"schema": "lidarkit-baseline/1"}))
    with pytest.raises(DataError) as exc:
        compare(baseline, out)
    assert str(exc.value) == (f"{baseline}: a baseline folder (lidarkit baseline record): compare takes bench results folders "
                              "or odometry run folders (a baseline gives its noise: --noise-from)")
    with pytest.raises(ConfigError, match=r"^compare: a run folder path is needed, got None$"):
        compare(None, out)
    for kwargs, shown in (({"alpha": "x"}, "alpha must be a number, got 'x'"), ({"noise": None}, "noise must be a number, got None")):
        with pytest.raises(ConfigError, match=f": {shown}$"):
            compare(out, out, method_a="good", method_b="bad", **kwargs)


def test_results_of_an_earlier_lidarkit_version_are_named_and_a_mix_of_versions_is_said(tmp_path):
    """A folder reused after a source change: compare called the old code's results "an earlier suite" and counted 2 of
    its 12 (as the report does not), and --all paired seeds 0-4 of the new code with seed 5 of the old without a word."""
    from lidarkit.bench.jobs import Job
    from lidarkit.bench.results import load_results, make_record, result_path, write_result
    from lidarkit.provenance import code_version

    _task("version_test_task", _error)
    out = _bench(tmp_path, "s", "seeds: 6\nexperiments:\n  - {task: version_test_task, dataset: {kind: synthetic}, methods: [good, bad]}\n")
    for record in load_results(out):  # the same jobs as an earlier version ran them
        job = Job.from_spec(record["job"])
        old = {k: v for k, v in record.items() if k not in ("schema", "key", "lidarkit_version", "job")}
        write_result(out, make_record(job, job.key("0.0.9"), "0.0.9", {**old, "finished_utc": "2026-01-01"}))
        if job.seed == 5:  # this version has not run seed 5 yet
            result_path(out, record["key"]).unlink()
    result = compare(out, out, method_a="good", method_b="bad")
    not_run = "1 (dataset, seed) unit(s) of {}'s suite not run yet or unreadable (`lidarkit bench` resumes them)"
    assert (result.n_pairs, result.note) == (5, f"{not_run.format('A')}; {not_run.format('B')}; 12 result(s) in {out} of "
                                                "these jobs from an earlier lidarkit version left out")
    every = compare(out, out, method_a="good", method_b="bad", every_result=True)
    assert (every.n_pairs, every.note) == (6, f"the 6 paired results mix lidarkit versions (A: 5 of {code_version()}, 1 of 0.0.9; "
                                              f"B: the same); 10 result(s) in {out} of these jobs from an earlier lidarkit version left out")


def test_a_mix_of_versions_counts_the_paired_results_not_the_units(tmp_path):
    """A fixed dataset's 6 seeds count as one unit (7 paired units from 12 results), while the note said "the 12 pairs
    mix lidarkit versions": it counts the results each side's versions are of, and says so."""
    from lidarkit.bench.jobs import Job
    from lidarkit.bench.results import load_results, make_record, result_path, write_result
    from lidarkit.provenance import code_version

    def value(job):
        seeded = job.dataset_name == "seeded"
        return (0.1 if job.method == "good" else 0.5) + (0.01 * np.random.default_rng(job.seed).random() if seeded else 0.0)

    _register_metric_task("version_units_test_task", "error_m", value)
    out = _bench(tmp_path, "s", "seeds: 6\nexperiments:\n  - {task: version_units_test_task, datasets: [{kind: synthetic, "
                                "name: fixed, variant: fixed}, {kind: synthetic, name: seeded}], methods: [good, bad]}\n")
    for record in load_results(out):  # the fixed dataset's results as an earlier version ran them, and only those
        job = Job.from_spec(record["job"])
        if job.dataset_name == "fixed":
            old = {k: v for k, v in record.items() if k not in ("schema", "key", "lidarkit_version", "job")}
            write_result(out, make_record(job, job.key("0.0.9"), "0.0.9", {**old, "finished_utc": "2026-01-01"}))
            result_path(out, record["key"]).unlink()
    result = compare(out, out, method_a="good", method_b="bad", every_result=True)
    assert (result.n_pairs, result.pairing) == (7, "unit")
    assert result.note == ("the seeds of a dataset that gives each side one value whatever the seed count as one unit; "
                           f"the 12 paired results mix lidarkit versions (A: 6 of 0.0.9, 6 of {code_version()}; B: the same)")


def test_noise_from_a_baseline_of_another_task_is_refused_and_the_noise_is_printed(tmp_path, capsys):
    """--noise-from took the widest band of any job of the baseline (random_walk's on a self-test held a particle filter's
    APE, another method's band on the same task too) without a word: the noise the verdict was held against was never
    printed."""
    from lidarkit.bench.baseline import record

    def error(job):
        return {"ape_rmse_m": {"good": 0.1, "bad": 0.5}.get(job.method, 10.0) + 0.01 * np.random.default_rng(job.seed).random()}

    _task("noise_test_task", error)
    suite = "seeds: {seeds}\nexperiments:\n  - {{task: noise_test_task, dataset: {{kind: synthetic}}, methods: [{methods}]}}\n"
    out = _bench(tmp_path, "s", suite.format(seeds=6, methods="good, bad"))
    (tmp_path / "base.yaml").write_text(suite.format(seeds=1, methods="good, bad, far"))
    bands = {job["label"]: job["bands"]["ape_rmse_m"] for job in record(tmp_path / "base.yaml", tmp_path / "base", repeats=2).jobs}
    assert bands["far"] > max(bands["good"], bands["bad"])
    result = compare(out, out, method_a="good", method_b="bad", noise_from=tmp_path / "base")
    assert result.noise == max(bands["good"], bands["bad"])  # (it was far's)
    (tmp_path / "walk.yaml").write_text("seeds: 1\nexperiments:\n  - {task: selftest, dataset: {kind: synthetic}, "
                                        "methods: [{name: random_walk, params: {steps: 20}}]}\n")
    record(tmp_path / "walk.yaml", tmp_path / "walk", repeats=2)
    pick = ["--method-a", "good", "--method-b", "bad"]
    code, stdout, err = run_cli(["compare", str(out), str(out), *pick, "--noise-from", str(tmp_path / "walk")], capsys)
    assert (code, stdout) == (1, "")
    assert " ".join(err.split()) == (f"error: {tmp_path / 'walk'}: no band for metric 'ape_rmse_m' of task 'noise_test_task' in "
                                     "this baseline (it has: selftest: ape_rmse_m, selftest: final_error_m): it did not check "
                                     "that metric on that task (--noise-from)")
    code, stdout, _ = run_cli(["compare", str(out), str(out), *pick, "--noise-from", str(tmp_path / "base")], capsys)
    assert code == 0 and (f"noise: differences within ±{result.noise:.4g} are run-to-run noise (the band {tmp_path / 'base'} "
                          "recorded)\n") in stdout
    code, stdout, _ = run_cli(["compare", str(out), str(out), *pick, "--noise", "0.25"], capsys)
    assert code == 0 and "noise: differences within ±0.25 are run-to-run noise (--noise)\n" in stdout


def test_options_a_loaded_run_ignores_and_bad_option_types_are_named_before_loading(tmp_path):
    """compare(BenchRuns, BenchRuns, method_a=...) ignored method_a / method_b / every_result; every_result="no" was read as
    true; noise_from=5 was a bare TypeError after both folders were loaded."""
    from lidarkit.eval.compare import load_bench_runs

    _task("loaded_test_task", _error)
    out = _bench(tmp_path, "s", "seeds: 6\nexperiments:\n  - {task: loaded_test_task, dataset: {kind: synthetic}, methods: [good, bad]}\n")
    good, bad = load_bench_runs(out, "good"), load_bench_runs(out, "bad")
    assert compare(good, bad).n_pairs == 6
    loaded = ("applies to paths only: a loaded BenchRuns is compared as loaded (load_bench_runs picks a method, and every result)")
    for kwargs, source in (({"method_a": "bad"}, "method_a"), ({"method_b": "good"}, "method_b"), ({"every_result": True}, "every_result")):
        with pytest.raises(ConfigError) as exc:
            compare(good, bad, **kwargs)
        assert str(exc.value) == f"{source}: {loaded}"
    missing = tmp_path / "missing"  # (checked before any loading: not "does not exist")
    for kwargs, shown in (({"every_result": "no"}, "every_result: every_result must be True or False, got 'no'"),
                          ({"noise_from": 5}, "noise_from: must be a path, got int 5")):
        with pytest.raises(ConfigError) as exc:
            compare(missing, missing, **kwargs)
        assert str(exc.value) == shown


def test_a_run_folder_against_a_bench_folder_of_several_methods_names_the_real_reason(tmp_path, capsys):
    """`compare RUN_FOLDER BENCH_FOLDER` (two methods in it) said "2 methods in this folder; choose one of: good, bad";
    choosing one then gave the real reason: the two folders are of different kinds."""
    from lidarkit.odometry import run
    from lidarkit.odometry.run_folder import write_run
    from lidarkit.sim.lidar import SimulatedLidarSequence

    _task("kinds_test_task", _error)
    bench = _bench(tmp_path, "s", "seeds: 2\nexperiments:\n  - {task: kinds_test_task, dataset: {kind: synthetic}, methods: [good, bad]}\n")
    folder = write_run(run(SimulatedLidarSequence(scene="street", n_frames=3, n_beams=16, n_azimuths=360), "kiss"), tmp_path / "run")
    run_is, bench_is = f"{folder} (an odometry run folder)", f"{bench} (a bench results folder)"
    # (it read "compare an odometry run folder with another run folder, a bench folder with a bench folder", naming neither)
    for argv, a, b in (([str(folder), str(bench)], run_is, bench_is), ([str(bench), str(folder)], bench_is, run_is),
                       ([str(bench), str(folder), "--method-a", "good"], bench_is, run_is)):
        assert run_cli(["compare", *argv], capsys) == (1, "", f"error: compare: A is {a}, B is {b}: compare an odometry run "
                                                              "folder with another run folder, bench results with bench results\n")
    with pytest.raises(ConfigError, match=r"2 methods in this folder; choose one of: bad, good$"):  # (bench with bench: still asked)
        compare(bench, bench)


def test_two_experiments_of_one_task_are_not_pooled_as_seeds(tmp_path, capsys):
    """Two pf experiments differing only in mse_start, 3 seeds each: compare paired "6 seeds" (p = 0.031, a winner) from
    3 seeds whose APE each experiment repeats. A method's results over several experiments of the task are refused now,
    --experiment picks one, and the labels name the experiment."""
    _task("experiments_test_task", lambda job: {"ape_rmse_m": (0.1 if job.method == "good" else 0.5) + 0.01 * job.seed,
                                                "drift_translation_pct": None if job.seed == 0 else 1.0})
    out = _bench(tmp_path, "s", "seeds: 3\nexperiments:\n"
                 "  - {name: early, task: experiments_test_task, dataset: {kind: synthetic, name: syn}, options: {start: 10}, methods: [good, bad]}\n"
                 "  - {name: late, task: experiments_test_task, dataset: {kind: synthetic, name: syn}, options: {start: 100}, methods: [good, bad]}\n")
    pick = {"method_a": "good", "method_b": "bad", "metric": "ape_rmse_m"}
    with pytest.raises(ConfigError) as exc:
        compare(out, out, **pick)
    assert str(exc.value) == (f"{out}: good has results in 2 experiments of task experiments_test_task (early, late) over the "
                              "same (dataset, seed) units, each its own (task options: start 10 in early, 100 in late): "
                              "--experiment picks one")
    early = compare(out, out, **pick, experiment="early")
    assert (early.n_pairs, early.pairing, early.p_value, early.better, early.note) == (3, "seed", 0.25, "", "")
    with pytest.raises(ConfigError) as exc:
        compare(out, out, **pick, experiment="nope")
    assert str(exc.value) == f"{out}: no result of good in experiment 'nope'; it has results in: early, late"
    late = compare(out, out, **{**pick, "metric": "drift_translation_pct"}, experiment="late")
    assert (late.n_pairs, late.note) == (2, "1 of 3 (dataset, seed) unit(s) left out: good and bad have no value (null) "
                                            "of drift_translation_pct there (late: syn, seed 0): KITTI drift needs 100 m of "
                                            "path, --metric ape_rmse_m compares every unit")
    code, stdout, _ = run_cli(["compare", str(out), str(out), "--method-a", "good", "--method-b", "bad", "--metric", "ape_rmse_m",
                               "--experiment", "late"], capsys)
    assert code == 0 and "(3 paired seeds, 0 ties)" in stdout
    # one experiment per suite: its name is a label, two suites that name it apart still pair
    a = _bench(tmp_path, "a", "seeds: 3\nexperiments:\n  - {name: x, task: experiments_test_task, dataset: {kind: synthetic}, methods: [good]}\n")
    b = _bench(tmp_path, "b", "seeds: 3\nexperiments:\n  - {name: y, task: experiments_test_task, dataset: {kind: synthetic}, methods: [bad]}\n")
    assert compare(a, b, metric="ape_rmse_m").n_pairs == 3


def test_a_non_finite_metric_value_is_left_out_like_a_missing_one(tmp_path):
    """A NaN in one job result read "error: bad: 1 non-finite value(s) among 6", naming neither the metric nor the
    seed, where a null named both; its unit is left out and named, as a null's is."""
    _task("nan_test_task", _error)
    out = _bench(tmp_path, "s", "seeds: 6\nexperiments:\n  - {task: nan_test_task, dataset: {kind: synthetic, name: syn}, methods: [good, bad]}\n")
    path = next(p for p in (out / "jobs").glob("*.json")
                if (r := json.loads(p.read_text()))["job"]["method"] == "bad" and r["job"]["seed"] == 3)
    record = json.loads(path.read_text())
    record["metrics"]["ape_rmse_m"] = float("nan")
    path.write_text(json.dumps(record))  # (json writes NaN, as a hand edit would)
    result = compare(out, out, method_a="good", method_b="bad")
    assert (result.n_pairs, result.note) == (5, "1 of 6 (dataset, seed) unit(s) left out: bad has no finite value (null, "
                                                "NaN or infinite) of ape_rmse_m there (syn, seed 3)")
    for job in (out / "jobs").glob("*.json"):  # NaN in every result of bad: said so (it read "(null) ... reports none")
        record = json.loads(job.read_text())
        if record["job"]["method"] == "bad":
            record["metrics"]["ape_rmse_m"] = float("nan")
            job.write_text(json.dumps(record))
    with pytest.raises(EvaluationError) as exc:
        compare(out, out, method_a="good", method_b="bad", metric="ape_rmse_m")
    assert str(exc.value) == "compare: metric 'ape_rmse_m' has no finite value (null, NaN or infinite) in any result of bad"


def test_bench_pairs_scored_at_different_sweep_instants_are_said(tmp_path):
    """Bench results of kiss (ground truth at the sweep end) and kiss deskew=False (mid) were paired without a word,
    though two run folders of the same runs say so in the note."""
    _task("instant_test_task", _error, lambda job: {"odometry_metrics": {"effective": {
        "ground_truth_instant": "end" if job.method == "good" else "mid"}}})
    out = _bench(tmp_path, "s", "seeds: 6\nexperiments:\n  - {task: instant_test_task, dataset: {kind: synthetic}, methods: [good, bad, worse]}\n")
    result = compare(out, out, method_a="good", method_b="bad")
    assert result.note == "each side is scored against the ground truth at its own instant of the sweep (good: end, bad: mid)"
    assert compare(out, out, method_a="bad", method_b="worse").note == ""


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="needs /dev/full (a device that is always full)")
def test_the_json_is_written_before_stdout_refuses_the_comparison(tmp_path):
    """`lidarkit compare A B --json out.json > /dev/full` (or `| head -1`) failed printing, exit 1, and no JSON was
    written: it is written first now, as vo, pf and eval write theirs."""
    import subprocess
    import sys

    methods = "[{name: random_walk, params: {steps: 20, noise_m: 0.05}}, {name: random_walk, params: {steps: 20, noise_m: 0.5}}]"
    out = _bench(tmp_path, "s", f"seeds: 6\nexperiments:\n  - {{task: selftest, dataset: {{kind: synthetic}}, methods: {methods}}}\n")
    with open("/dev/full", "w") as full:
        done = subprocess.run([sys.executable, "-m", "lidarkit", "compare", str(out), str(out), "--method-a",
                               "random_walk(noise_m=0.05, steps=20)", "--method-b", "random_walk(noise_m=0.5, steps=20)",
                               "--metric", "ape_rmse_m", "--json", str(tmp_path / "c.json")],
                              stdout=full, stderr=subprocess.PIPE, text=True, timeout=300)
    assert (done.returncode, done.stderr) == (1, "error: stdout: cannot write: no space left on the device\n")
    data = json.loads((tmp_path / "c.json").read_text())
    assert (data["n_pairs"], data["better"]) == (6, "a")


def test_a_particle_filter_run_folder_is_named_as_one(tmp_path, capsys):
    """`compare PF_RUN PF_RUN` said "no ground_truth_kitti.txt: a paired comparison needs the estimate and its ground
    truth" (the folder holds it as TUM), and against a bench folder called it an odometry run folder."""
    from conftest import cli_exit_code, shared_path

    data = str(shared_path("pf", "robot_mapping_stachniss"))
    for name, n in (("one", "50"), ("two", "60")):
        assert cli_exit_code(["pf", data, "-n", n, "-o", str(tmp_path / name)]) == 0
    capsys.readouterr()
    assert cli_exit_code(["compare", str(tmp_path / "one"), str(tmp_path / "two")]) == 1
    assert capsys.readouterr().err.strip() == (
        f"error: {tmp_path / 'one'}: a particle-filter run folder: compare pairs odometry run folders, or bench results "
        "folders (the seeds of a suite: lidarkit bench)")
    (tmp_path / "bench" / "jobs").mkdir(parents=True)
    assert cli_exit_code(["compare", str(tmp_path / "one"), str(tmp_path / "bench")]) == 1
    assert "a particle-filter run folder" in capsys.readouterr().err
    # a study folder (-n 50,60: study.json, no metrics.json) read "no metrics.json: not a finished odometry run folder"
    assert cli_exit_code(["pf", data, "-n", "50,60", "--seeds", "2", "-o", str(tmp_path / "study")]) == 0
    capsys.readouterr()
    assert cli_exit_code(["compare", str(tmp_path / "study"), str(tmp_path / "one")]) == 1
    assert f"error: {tmp_path / 'study'}: a particle-filter run folder" in capsys.readouterr().err


def test_task_without_metric_takes_the_default_metric_of_that_task(tmp_path):
    """`--task icp_pair` without `--metric` took its default (ape_rmse_m) from the suite's other task, then refused it:
    "unknown metric 'ape_rmse_m'; these results have: ..., translation_error_m"."""
    _task("odo_default_test_task", _error)
    _task("pair_default_test_task", lambda job: {"translation_error_m": (0.1 if job.method == "good" else 0.5) + 0.01 * job.seed})
    out = _bench(tmp_path, "s", "seeds: 6\nexperiments:\n"
                 "  - {name: pairs, task: pair_default_test_task, dataset: {kind: synthetic}, methods: [good, bad]}\n"
                 "  - {name: odo, task: odo_default_test_task, dataset: {kind: synthetic}, methods: [good, bad]}\n")
    result = compare(out, out, method_a="good", method_b="bad", task="pair_default_test_task")
    assert (result.metric, result.n_pairs, result.better) == ("translation_error_m", 6, "a")
    assert compare(out, out, method_a="good", method_b="bad", task="odo_default_test_task").metric == "ape_rmse_m"


def test_units_that_differ_only_in_task_options_are_named_so(tmp_path):
    """An option written out at its default value in one suite only (pf `mse_start: 10`) read "runs over different data:
    no (dataset, seed) in common", with the same labels ("F, seed 0; ...") on both sides."""
    _task("options_test_task", _error)
    suite = "seeds: 3\nexperiments:\n  - {{task: options_test_task, dataset: {{kind: synthetic, name: F}}, {options}methods: [{method}]}}\n"
    a = _bench(tmp_path, "a", suite.format(options="", method="good"))
    b = _bench(tmp_path, "b", suite.format(options="options: {start: 10}, ", method="bad"))
    with pytest.raises(EvaluationError) as exc:
        compare(a, b)
    assert str(exc.value) == (f"compare: runs with different task options over the same (dataset, seed) units: {{}} in {a} "
                              f"(good), {{start: 10}} in {b} (bad): units pair only when their options are written alike (an "
                              "option set to its default value is not one left out)")


def test_too_few_pairs_say_which_units_were_left_out(tmp_path):
    """With B's job failed on 7 of 8 seeds the error read "needs at least 2 matched seeds, got 1 (a suite's `seeds: N`
    ...)", as if the suite had one seed: the note on the failed jobs was built after the test refused."""
    def flaky(job):
        if job.method == "bad" and job.seed < 7:
            raise RuntimeError("failed on purpose")
        return _error(job)

    _task("few_pairs_test_task", flaky)
    out = _bench(tmp_path, "s", "seeds: 8\nexperiments:\n  - {task: few_pairs_test_task, dataset: {kind: synthetic}, methods: [good, bad]}\n")
    with pytest.raises(EvaluationError) as exc:
        compare(out, out, method_a="good", method_b="bad")
    assert str(exc.value) == ("ape_rmse_m: a paired test needs at least 2 matched seeds, got 1 (a suite's `seeds: N` over "
                              "seeded data, more datasets or sequences over fixed data such as KITTI: 2 or more, 6 or more "
                              "for p < 0.05); 7 (dataset, seed) unit(s) where B's job failed are left out (lidarkit report "
                              "lists why)")


def test_run_folders_with_one_kitti_segment_compare_per_frame_by_default(tmp_path):
    """A path just over 100 m has one KITTI segment: the default metric (segment drift, chosen on length alone) failed
    with "needs at least 2 matched segments, got 1" and no hint of the per-frame metric."""
    from lidarkit.odometry import run

    run("sim:street?frames=112&beams=8&azimuths=360&seed=0", "kiss", out_dir=tmp_path / "kiss")  # (102.0 m: one segment)
    result = compare(tmp_path / "kiss", tmp_path / "kiss")
    assert (result.metric, result.pairing, result.n_pairs) == ("rpe_translation_m", "frame", 111)
    assert result.note == "1 KITTI segment in common (a paired test needs 2): compared per frame (rpe_translation_m)"
    with pytest.raises(EvaluationError) as exc:
        compare(tmp_path / "kiss", tmp_path / "kiss", metric="segment_translation_pct")
    assert str(exc.value) == ("segment_translation_pct: a paired test needs at least 2 matched segments, got 1 (longer paths, "
                              "or compare per frame: --metric rpe_translation_m)")


def test_a_speed_metric_its_task_declares_is_not_read_as_seeds_running_other_data(tmp_path, capsys):
    """A deterministic task whose speed metric is named ``latency_ms`` (no name the timing pattern knows) had its one
    measurement, repeated on 6 seeds, tested as 6 units: "a is better ... Wilcoxon p = 0.031". Each result records its
    task's speed metrics now, and compare leaves them out of whether the seeds ran other data."""
    from lidarkit.bench import Metric
    from test_eval_statistics import _register_metric_task

    _register_metric_task("latency_test_task", (Metric("error_m", "error [m]"), Metric("latency_ms", "latency [ms]", kind="speed")),
                          lambda job: {"error_m": 0.10 if job.method == "good" else 0.12, "latency_ms": 1.0 + 0.1 * job.seed})
    out = _bench(tmp_path, "s", "seeds: 6\nexperiments:\n  - {task: latency_test_task, dataset: {kind: synthetic}, methods: [good, bad]}\n")
    records = [json.loads(p.read_text()) for p in (out / "jobs").glob("*.json")]
    assert [r["speed_metrics"] for r in records] == [["latency_ms"]] * 12
    result = compare(out, out, method_a="good", method_b="bad", metric="error_m")
    assert (result.n_pairs, result.repeated, result.better) == (6, True, "")
    assert "one measurement repeated" in result.verdict()


def test_experiments_of_a_task_over_other_datasets_are_pooled(tmp_path):
    """A suite with one experiment per dataset could not be compared ("has results in 2 experiments of task pf (ds1,
    ds2), each its own: --experiment picks one"), though the same jobs written as one experiment over two datasets
    compare: experiments that share no (dataset, seed) are pooled now, and pair with the one-experiment suite."""
    _task("per_experiment_test_task", lambda job: {"ape_rmse_m": (0.1 if job.method == "good" else 0.5) + job.dataset["size"]
                                                   + 0.01 * np.random.default_rng(job.seed).random()})
    split = _bench(tmp_path, "split", "seeds: 3\nexperiments:\n"
                   "  - {name: ds1, task: per_experiment_test_task, dataset: {kind: synthetic, size: 1}, methods: [good, bad]}\n"
                   "  - {name: ds2, task: per_experiment_test_task, dataset: {kind: synthetic, size: 2}, methods: [good, bad]}\n")
    result = compare(split, split, method_a="good", method_b="bad")
    assert (result.n_pairs, result.pairing, result.better, result.note) == (6, "seed", "a", "")
    joint = _bench(tmp_path, "joint", "seeds: 3\nexperiments:\n  - {name: both, task: per_experiment_test_task, datasets: "
                   "[{kind: synthetic, size: 1}, {kind: synthetic, size: 2}], methods: [good, bad]}\n")
    assert compare(joint, joint, method_a="good", method_b="bad").mean_diff == result.mean_diff
    across = compare(split, joint, method_a="good", method_b="bad")
    assert (across.n_pairs, across.better, across.note) == (6, "a", "")


def test_one_experiment_named_apart_in_two_folders_pairs(tmp_path):
    """The same data and seeds were "runs over different data" when the folders name the experiment apart and one of
    them holds another experiment of the task (pf_rec and pf_all in A, recorded in B), and --experiment pf_rec then found
    nothing in B. Units pair without the experiment's name now; --experiment A_NAME,B_NAME names each side's own."""
    _task("named_apart_test_task", _error)
    a = _bench(tmp_path, "a", "seeds: 6\nexperiments:\n"
               "  - {name: pf_rec, task: named_apart_test_task, dataset: {kind: synthetic}, options: {visible: recorded}, methods: [good]}\n"
               "  - {name: pf_all, task: named_apart_test_task, dataset: {kind: synthetic}, options: {visible: all}, methods: [good]}\n")
    b = _bench(tmp_path, "b", "seeds: 6\nexperiments:\n"
               "  - {name: recorded, task: named_apart_test_task, dataset: {kind: synthetic}, options: {visible: recorded}, methods: [bad]}\n")
    result = compare(a, b)
    assert (result.n_pairs, result.better) == (6, "a")
    assert result.note == "6 (dataset, seed) units only in A and 0 only in B are left out: 6 paired"
    with pytest.raises(ConfigError) as exc:
        compare(a, b, experiment="pf_rec")
    assert str(exc.value) == (f"{b}: no result of bad in experiment 'pf_rec'; it has results in: recorded (--experiment "
                              "pf_rec,recorded names each side's own)")
    named = compare(a, b, experiment="pf_rec,recorded")
    assert (named.n_pairs, named.better, named.note) == (6, "a", "")
    with pytest.raises(ConfigError) as exc:  # (A's two experiments over one (dataset, seed) against themselves: not pooled)
        compare(a, a)
    assert str(exc.value) == (f"{a}: good has results in 2 experiments of task named_apart_test_task (pf_all, pf_rec) over "
                              "the same (dataset, seed) units, each its own (task options: visible \"all\" in pf_all, "
                              "\"recorded\" in pf_rec): --experiment picks one")


def _spec_task(name: str) -> None:
    """A bench task over simulated lidar and KITTI dataset specs that reads no data: the units pair by spec alone."""
    from lidarkit.bench import Metric, Task, TaskOutput, register_task

    class SpecTask(Task):
        dataset_kinds = ("sim_lidar", "kitti")
        metrics = (Metric("ape_rmse_m", "APE [m]"),)

        def validate_options(self, options):
            pass

        def run(self, job):
            return TaskOutput(metrics=_error(job))

    register_task(name)(SpecTask)


def test_a_simulated_dataset_written_with_a_default_setting_pairs(tmp_path):
    """``range_noise_std_m: 0.0`` (the simulator's default) written in one suite only read "runs over different data"
    with the same labels on both sides ("st, seed 0; st, seed 1"); the specs pair by the simulator's settings now, and
    specs that really differ are named field by field."""
    _spec_task("sim_spec_test_task")
    suite = "seeds: 6\nexperiments:\n  - {{task: sim_spec_test_task, dataset: {{kind: sim_lidar, scene: street, n_beams: 16, {extra}name: st}}, methods: [{method}]}}\n"
    a = _bench(tmp_path, "a", suite.format(extra="n_frames: 3, ", method="good"))
    b = _bench(tmp_path, "b", suite.format(extra="n_frames: 3, range_noise_std_m: 0.0, ", method="bad"))
    result = compare(a, b)
    assert (result.n_pairs, result.better, result.note) == (6, "a", "")
    c = _bench(tmp_path, "c", suite.format(extra="n_frames: 4, range_noise_std_m: 0.0, ", method="bad"))
    with pytest.raises(EvaluationError) as exc:
        compare(a, c)
    assert str(exc.value).endswith("(bad: st, seed 0; st, seed 1; st, seed 2; ... (6 in all)): their dataset specs differ in n_frames (3 in A, "
                                   "4 in B)")


def test_a_kitti_sequence_given_by_root_or_by_its_folder_pairs(tmp_path):
    """``path: kitti_odometry, sequence: "00"`` and ``path: kitti_odometry/sequences/00`` are one sequence: they read
    "runs over different data" with the same labels on both sides."""
    from conftest import shared_path

    root = shared_path("kitti_odometry")
    _spec_task("kitti_spec_test_task")
    suite = "seeds: 6\nexperiments:\n  - {{task: kitti_spec_test_task, dataset: {{kind: kitti, {where}, name: k00}}, methods: [{method}]}}\n"
    a = _bench(tmp_path, "a", suite.format(where=f"path: {root}, sequence: '00'", method="good"))
    b = _bench(tmp_path, "b", suite.format(where=f"path: {root / 'sequences' / '00'}", method="bad"))
    result = compare(a, b)
    assert (result.n_pairs, result.better, result.note) == (6, "a", "")


def test_compare_arguments_that_are_not_names_are_refused_by_name(tmp_path):
    """compare(..., experiment=["pfA"]) or metric=["mse_m2"] raised a bare TypeError (unhashable type: 'list')."""
    _task("argument_test_task", _error)
    out = _bench(tmp_path, "s", "seeds: 3\nexperiments:\n  - {task: argument_test_task, dataset: {kind: synthetic}, methods: [good, bad]}\n")
    pick = {"method_a": "good", "method_b": "bad"}
    for name, given in (("experiment", ["argument_test_task_0"]), ("metric", ["ape_rmse_m"]), ("task", ("argument_test_task",)),
                        ("method_a", ["good"]), ("method_b", 3)):
        with pytest.raises(ConfigError) as exc:
            compare(out, out, **{**pick, name: given})
        assert str(exc.value) == f"{name}: must be a name (text) or None, got {type(given).__name__} {given!r}"
    assert compare(out, out, **pick, experiment="argument_test_task_0").n_pairs == 3


def test_run_folders_over_the_same_frames_pair_whatever_their_selection_says(tmp_path):
    """kiss over every frame and kiss deskew=False with --frames 0:8 over the same drive were refused as "runs over
    different data ... with other values": config.yaml's selections ("all", "0:8") were compared as text. The frames
    run are compared now; a drive at another speed, whose name reads alike, is still other data, and says what differs."""
    from lidarkit.odometry import run

    spec = "sim:street?frames=8&beams=8&azimuths=360&seed=0&speed={speed}"
    run(spec.format(speed=10), "kiss", out_dir=tmp_path / "all")
    run(spec.format(speed=10), "kiss", params={"deskew": False}, frames="0:8", out_dir=tmp_path / "sliced")
    result = compare(tmp_path / "all", tmp_path / "sliced")
    assert (result.n_pairs, result.pairing) == (7, "frame")
    assert result.note == ("each run is scored against the ground truth at its own instant of the sweep (kiss: end, "
                           "kiss(deskew=False): mid), over the same dataset and frames (sim:street?seed=0, frames 0:8)")
    run(spec.format(speed=5), "kiss", params={"deskew": False}, out_dir=tmp_path / "slower")
    with pytest.raises(EvaluationError) as exc:
        compare(tmp_path / "all", tmp_path / "slower")
    assert str(exc.value) == (f"compare: runs over different data: {tmp_path / 'all'} has 8 ground-truth poses, "
                              f"{tmp_path / 'slower'} has 8 with other values (their dataset settings differ in speed_mps "
                              "(10.0 in A, 5.0 in B); ground truth at the sweep end in A, mid in B)")


def test_units_of_a_task_not_compared_are_not_counted_only_in_one_folder(tmp_path):
    """A: a pair task and a run task (good), B: the run task only (bad). `compare A B --task runs` noted "8 (dataset,
    seed) units only in A and 0 only in B are left out": A's pair-task units, which were never to be compared. They are
    worded as in one folder now: left out without --task because of the metric, unsaid with it."""
    _register_metric_task("pairs_only_test_task", "pair_error_m", lambda job: 0.1 + 0.01 * job.seed)
    _task("runs_only_test_task", _error)
    suite = "seeds: 8\nexperiments:\n{experiments}"
    pairs = "  - {name: p, task: pairs_only_test_task, dataset: {kind: synthetic}, methods: [good]}\n"
    runs = "  - {{name: r, task: runs_only_test_task, dataset: {{kind: synthetic}}, methods: [{method}]}}\n"
    a = _bench(tmp_path, "a", suite.format(experiments=pairs + runs.format(method="good")))
    b = _bench(tmp_path, "b", suite.format(experiments=runs.format(method="bad")))
    chosen = compare(a, b, task="runs_only_test_task")
    assert (chosen.n_pairs, chosen.better, chosen.note) == (8, "a", "")
    default = compare(a, b)
    assert (default.metric, default.n_pairs) == ("ape_rmse_m", 8)
    assert default.note == "8 (dataset, seed) units of pairs_only_test_task (no ape_rmse_m) left out: 8 paired"


def test_folders_of_other_tasks_are_named_as_such_not_as_other_data(tmp_path):
    """An odometry folder against an icp_pair folder over the same dataset and seeds read "runs over different data: no
    (dataset, seed) in common between A (good: syn, seed 0; ...) and B (bad: syn, seed 0; ...)"."""
    _register_metric_task("first_kind_test_task", "error_m", lambda job: 0.1 + 0.01 * job.seed)
    _register_metric_task("second_kind_test_task", "error_m", lambda job: 0.2 + 0.01 * job.seed)
    suite = "seeds: 3\nexperiments:\n  - {{task: {task}, dataset: {{kind: synthetic, name: syn}}, methods: [{method}]}}\n"
    a = _bench(tmp_path, "a", suite.format(task="first_kind_test_task", method="good"))
    b = _bench(tmp_path, "b", suite.format(task="second_kind_test_task", method="bad"))
    with pytest.raises(EvaluationError) as exc:
        compare(a, b)
    assert str(exc.value) == (f"compare: {a} (good) holds task(s) first_kind_test_task, {b} (bad) holds second_kind_test_task: "
                              "compare units of one task")
    with pytest.raises(ConfigError) as exc:
        compare(a, b, task="first_kind_test_task")
    assert str(exc.value) == (f"task: no unit of task 'first_kind_test_task' in both; {a} (good) holds first_kind_test_task, "
                              f"{b} (bad) holds second_kind_test_task")


def test_the_default_metric_is_the_headline_the_report_ranks_by(tmp_path, capsys):
    """Odometry results were compared on KITTI drift, else the unaligned APE, while the report's Summary ranks them by
    the SE(3)-aligned APE (kiss 1.71 against 0.556 m): the default is the task's first declared accuracy metric now, as
    the report's headline, and the verdict names its label."""
    from lidarkit.bench import Metric
    from lidarkit.bench.report import build_report, summary_rows

    def errors(job):
        bump = 0.01 * np.random.default_rng(job.seed).random()
        good = job.method == "good"
        return {"drift_translation_pct": 1.0 + bump, "ape_rmse_m": (0.9 if good else 0.5) + bump,
                "ape_se3_rmse_m": (0.1 if good else 0.3) + bump}

    _register_metric_task("headline_test_task", (Metric("ape_se3_rmse_m", "APE RMSE (SE(3)-aligned) [m]"),
                                                 Metric("ape_rmse_m", "APE RMSE (unaligned) [m]"),
                                                 Metric("drift_translation_pct", "KITTI drift [%]")), errors)
    out = _bench(tmp_path, "s", "seeds: 6\nexperiments:\n  - {task: headline_test_task, dataset: {kind: synthetic}, methods: [good, bad]}\n")
    result = compare(out, out, method_a="good", method_b="bad")
    assert (result.metric, result.metric_label, result.better) == ("ape_se3_rmse_m", "APE RMSE (SE(3)-aligned)", "a")
    assert result.verdict().startswith("good is better than bad on ape_se3_rmse_m [APE RMSE (SE(3)-aligned)]: median")
    _, rows = summary_rows(build_report(out, plots=False))
    assert [(r[2], r[3]) for r in rows] == [("APE RMSE (SE(3)-aligned) [m]", "good")]  # the report's headline and best
    asked = compare(out, out, method_a="good", method_b="bad", metric="ape_rmse_m")
    assert (asked.metric_label, asked.better) == ("APE RMSE (unaligned)", "b")
    code, stdout, _ = run_cli(["compare", str(out), str(out), "--method-a", "good", "--method-b", "bad"], capsys)
    assert code == 0 and stdout.startswith("A: good   B: bad   metric: ape_se3_rmse_m [APE RMSE (SE(3)-aligned)] (6 paired seeds")


def test_a_method_label_written_another_way_is_found(tmp_path):
    """`--method-a "vanilla(voxel_size_m=1.0)"` read "not found; this folder has: ..., vanilla(voxel_size_m=1)", and
    kiss(deskew=false) missed kiss(deskew=False): the label given is read as a method and its params."""
    _task("label_test_task", lambda job: {"ape_rmse_m": (0.1 if job.params.get("size") else 0.5) + 0.01 * job.seed})
    out = _bench(tmp_path, "s", "seeds: 3\nexperiments:\n  - {task: label_test_task, dataset: {kind: synthetic}, methods: "
                 "[{name: m, params: {size: 1.0, flag: true}}, {name: m, params: {flag: false}}]}\n")
    result = compare(out, out, method_a="m(size=1.0,flag=true)", method_b="m(flag=false)")
    assert (result.name_a, result.name_b, result.n_pairs) == ("m(flag=True, size=1)", "m(flag=False)", 3)
    with pytest.raises(ConfigError) as exc:
        compare(out, out, method_a="m(size=2.0)", method_b="m(flag=false)")
    assert str(exc.value) == f"{out}: method 'm(size=2.0)' not found; this folder has: m(flag=False), m(flag=True, size=1)"


def _straight_run(folder: Path, scale_error: np.ndarray) -> Path:
    """A run folder of a straight 1 m-a-frame drive whose estimate stretches frame k's step by ``scale_error[k]``."""
    folder.mkdir()
    steps = np.ones(len(scale_error) + 1)
    for name, x in (("ground_truth_kitti.txt", np.cumsum(steps)),
                    ("poses_kitti.txt", np.cumsum(steps * np.concatenate([[1.0], 1.0 + scale_error])))):
        poses = np.zeros((len(x), 12))
        poses[:, [0, 5, 10]] = 1.0
        poses[:, 3] = x
        np.savetxt(folder / name, poses)
    (folder / "metrics.json").write_text(json.dumps({"method": folder.name}))
    return folder


def test_a_p_value_that_underflows_is_printed_below_a_bound_not_as_0(tmp_path, capsys):
    """Two runs over 2500 frames, one worse on every frame: Wilcoxon's p underflows to 0, printed "p = 0", which no test
    gives. The line and the verdict read "p < 1e-300"; the JSON keeps the number, 0.0."""
    rng = np.random.default_rng(3)
    worse = _straight_run(tmp_path / "worse", 0.02 + 0.001 * rng.random(2500))
    better = _straight_run(tmp_path / "better", 0.01 + 0.001 * rng.random(2500))
    code, stdout, _ = run_cli(["compare", str(worse), str(better), "--metric", "rpe_translation_m", "--json",
                               str(tmp_path / "c.json")], capsys)
    assert code == 0 and "Wilcoxon signed-rank: statistic 0, p < 1e-300; effect size" in stdout
    assert "better is better than worse on rpe_translation_m: " in stdout and ", Wilcoxon p < 1e-300, " in stdout
    saved = json.loads((tmp_path / "c.json").read_text())
    assert saved["p_value"] == 0.0 and "p < 1e-300" in saved["verdict"] and "p = 0," not in saved["verdict"]


def test_a_run_folder_without_its_config_says_so_when_the_truths_differ(tmp_path):
    """A run folder whose config.yaml is gone (a run cut off before it finished) was "runs over different data" beside a
    finished run of the same sweeps scored at another instant, without a word why: the refusal names the folder that
    does not say what it ran over."""
    from lidarkit.odometry import run as odometry_run
    from lidarkit.odometry.run_folder import write_run

    spec = "sim:street?frames=8&beams=16&azimuths=180&seed=0"
    for name, method in (("kiss", "kiss"), ("cut", "small_gicp")):
        write_run(odometry_run(spec, method, progress=False), tmp_path / name)
    assert compare(tmp_path / "kiss", tmp_path / "cut").n_pairs  # finished: the instants are said, and compared
    (tmp_path / "cut" / "config.yaml").unlink()
    with pytest.raises(EvaluationError) as exc:
        compare(tmp_path / "kiss", tmp_path / "cut")
    message = str(exc.value)
    assert message.startswith("compare: runs over different data:") and message.endswith(
        f"; {tmp_path / 'cut'} has no readable config.yaml (a run cut off before it finished, or a folder made by hand): "
        "the dataset, frames and sweep instant it ran over are unknown")


PLUGIN_TASK_MODULE = """
from lidarkit.bench import Metric, Task, TaskOutput, register_task


@register_task("compare_plugin_task")
class ComparePluginTask(Task):
    dataset_kinds = ("synthetic",)
    metrics = (Metric("score", "match score [pts]", better="higher"), Metric("err_m", "error [m]"))

    def run(self, job):
        score = 50.0 + job.seed + (3.0 if job.method == "good" else 0.0)
        return TaskOutput(metrics={"score": score, "err_m": 1.0 / score})
"""


def test_a_plugin_task_is_compared_on_its_headline_as_its_report_ranks(tmp_path, monkeypatch):
    """A task registered in a module the suite's script imported: `compare RES RES --method-a good --method-b bad` in
    another process said "no default metric in these results" and `--metric score` had no label, while the report
    imports the module the results record and ranks by the task's headline. compare imports it too; a module that is
    gone leaves the metrics its results declare (as the report reads them), and results that declare none name it in
    the error."""
    import importlib
    import sys

    from lidarkit.bench import tasks as bench_tasks

    monkeypatch.setattr(bench_tasks, "_REGISTERED", {})
    monkeypatch.setattr(bench_tasks, "_INSTANCES", {})
    code = tmp_path / "code"
    code.mkdir()
    (code / "lidarkit_compare_plugin_task.py").write_text(PLUGIN_TASK_MODULE)
    monkeypatch.syspath_prepend(str(code))
    importlib.import_module("lidarkit_compare_plugin_task")
    out = _bench(tmp_path, "s", "seeds: 6\nexperiments:\n  - {task: compare_plugin_task, dataset: {kind: synthetic}, methods: [good, bad]}\n")

    def fresh_process() -> None:
        monkeypatch.setattr(bench_tasks, "_REGISTERED", {})
        monkeypatch.setattr(bench_tasks, "_INSTANCES", {})
        sys.modules.pop("lidarkit_compare_plugin_task", None)

    fresh_process()
    monkeypatch.setattr(sys, "path", [p for p in sys.path if p != str(code)])
    result = compare(out, out, method_a="good", method_b="bad")
    assert (result.metric, result.metric_label, result.better, result.n_pairs) == ("score", "match score", "a", 6)
    assert str(code) not in sys.path

    fresh_process()
    (code / "lidarkit_compare_plugin_task.py").unlink()
    importlib.invalidate_caches()
    gone = compare(out, out, method_a="good", method_b="bad")
    assert (gone.metric, gone.metric_label, gone.better, gone.n_pairs) == ("score", "match score", "a", 6)
    for job_file in (out / "jobs").glob("*.json"):  # results written before the metrics' labels were recorded
        record = json.loads(job_file.read_text())
        record.pop("metric_labels", None)
        job_file.write_text(json.dumps(record))
    with pytest.raises(EvaluationError) as exc:
        compare(out, out, method_a="good", method_b="bad")
    assert str(exc.value).startswith("compare: no default metric in these results (task compare_plugin_task: its module "
                                     "lidarkit_compare_plugin_task cannot be imported here (")
    assert str(exc.value).endswith("); pass one of: err_m, score")


RECORDED_LABELS_TASK_MODULE = """
from lidarkit.bench import Metric, Task, TaskOutput, register_task


@register_task("compare_recorded_labels_task")
class CompareRecordedLabelsTask(Task):
    dataset_kinds = ("synthetic",)
    metrics = (Metric("final_error_m", "final error [m]"), Metric("ape_rmse_m", "APE RMSE [m]"),
               Metric("coverage_pct", "coverage [%]"), Metric("align_time_s", "align time [s]", kind="speed"))

    def run(self, job):  # good ends closer (final error), bad tracks closer on the way (APE); coverage never reported
        good, bump = job.method == "good", 0.001 * job.seed
        return TaskOutput(metrics={"final_error_m": (0.2 if good else 0.5) + bump, "ape_rmse_m": (0.4 if good else 0.3) + bump,
                                   "align_time_s": 0.01})
"""


def test_a_task_that_cannot_be_imported_is_compared_on_the_metrics_its_results_declare(tmp_path, monkeypatch):
    """A task whose module is gone: the report heads it with "final error [m]", the first accuracy metric its results
    declare (``metric_labels``), while compare tested ape_rmse_m, the first of its fixed list, without a label, and a
    declared metric no result holds read "unknown metric". compare reads the declared metrics as the report does."""
    import importlib
    import sys

    from lidarkit.bench import tasks as bench_tasks
    from lidarkit.bench.report import build_report, summary_rows

    monkeypatch.setattr(bench_tasks, "_REGISTERED", {})
    monkeypatch.setattr(bench_tasks, "_INSTANCES", {})
    code = tmp_path / "code"
    code.mkdir()
    (code / "lidarkit_compare_recorded_labels_task.py").write_text(RECORDED_LABELS_TASK_MODULE)
    monkeypatch.syspath_prepend(str(code))
    try:
        importlib.import_module("lidarkit_compare_recorded_labels_task")
        out = _bench(tmp_path, "s", "seeds: 6\nexperiments:\n  - {task: compare_recorded_labels_task, dataset: {kind: "
                                    "synthetic}, methods: [good, bad]}\n")
        # another process, the module gone
        monkeypatch.setattr(bench_tasks, "_REGISTERED", {})
        monkeypatch.setattr(bench_tasks, "_INSTANCES", {})
        sys.modules.pop("lidarkit_compare_recorded_labels_task", None)
        (code / "lidarkit_compare_recorded_labels_task.py").unlink()
        importlib.invalidate_caches()
        _, rows = summary_rows(build_report(out, plots=False))
        assert [(r[2], r[3]) for r in rows] == [("final error [m]", "good")]
        result = compare(out, out, method_a="good", method_b="bad")
        assert (result.metric, result.metric_label, result.better, result.n_pairs) == ("final_error_m", "final error", "a", 6)
        assert result.mean_a == pytest.approx(0.2025) and result.mean_b == pytest.approx(0.5025)
        assert compare(out, out, method_a="good", method_b="bad", metric="ape_rmse_m").metric_label == "APE RMSE"
        with pytest.raises(EvaluationError) as exc:
            compare(out, out, method_a="good", method_b="bad", metric="coverage_pct")
        assert str(exc.value) == "compare: metric 'coverage_pct': declared by compare_recorded_labels_task but in no result"
    finally:
        sys.modules.pop("lidarkit_compare_recorded_labels_task", None)


def test_a_declared_metric_in_no_result_and_one_only_a_side_reports_are_not_unknown(tmp_path):
    """KITTI drift on a short drive (declared by the task, in no result) and a pair-task metric of A's extra experiment
    (B ran no pair task) were both "unknown metric '...'": they say why now; a misspelt name is still unknown."""
    _task("declared_runs_test_task", _error)
    _register_metric_task("declared_pairs_test_task", "translation_error_m", lambda job: 0.1 + 0.01 * job.seed)
    suite = "seeds: 3\nexperiments:\n{experiments}"
    pairs = "  - {name: p, task: declared_pairs_test_task, dataset: {kind: synthetic}, methods: [good]}\n"
    runs = "  - {{name: r, task: declared_runs_test_task, dataset: {{kind: synthetic}}, methods: [{method}]}}\n"
    a = _bench(tmp_path, "a", suite.format(experiments=pairs + runs.format(method="good")))
    b = _bench(tmp_path, "b", suite.format(experiments=runs.format(method="bad")))
    with pytest.raises(EvaluationError) as exc:
        compare(a, b, metric="drift_translation_pct")
    assert str(exc.value) == ("compare: metric 'drift_translation_pct': declared by declared_runs_test_task but in no "
                              "result (KITTI drift needs 100 m of path)")
    with pytest.raises(EvaluationError) as exc:
        compare(a, b, metric="translation_error_m")
    assert str(exc.value) == ("compare: metric 'translation_error_m': only A (good) reports it (task "
                              "declared_pairs_test_task, which B did not run)")
    with pytest.raises(EvaluationError) as exc:
        compare(b, a, metric="translation_error_m")
    assert str(exc.value).endswith("only B (good) reports it (task declared_pairs_test_task, which A did not run)")
    with pytest.raises(ConfigError) as exc:
        compare(a, b, metric="ape_rmse")
    assert str(exc.value) == "metric: unknown metric 'ape_rmse'; these results have: ape_rmse_m"


def test_a_bench_jobs_folder_and_an_icp_run_folder_are_named_as_such(tmp_path, capsys):
    """`compare RES/jobs RES/jobs` and `compare ICP_RUN ICP_RUN` said "no metrics.json: not a finished odometry run
    folder"; with --method-a, the jobs/ folder read "a method applies to bench results folders only"."""
    from conftest import cli_exit_code
    from lidarkit.samples import sample_path

    _task("jobs_folder_test_task", _error)
    out = _bench(tmp_path, "s", "seeds: 2\nexperiments:\n  - {task: jobs_folder_test_task, dataset: {kind: synthetic}, methods: [good, bad]}\n")
    for method in (None, "good"):
        with pytest.raises(DataError) as exc:
            compare(out / "jobs", out / "jobs", method_a=method)
        assert str(exc.value) == f"{out}/jobs: the jobs/ folder of the bench results {out}: give {out}"
    source, target = tmp_path / "source.npy", tmp_path / "target.npy"
    np.save(source, np.load(sample_path("kitti_pair", "000095.npy"))[::20])
    np.save(target, np.load(sample_path("kitti_pair", "000094.npy"))[::20])
    icp = tmp_path / "icp_run"
    assert cli_exit_code(["icp", str(source), str(target), "-m", "vanilla", "--out", str(icp)]) == 0
    capsys.readouterr()
    code, stdout, err = run_cli(["compare", str(icp), str(icp)], capsys)
    assert (code, stdout) == (1, "")
    assert err == (f"error: {icp}: an icp run folder: compare pairs odometry run folders, or bench results folders (the "
                   "seeds of a suite: lidarkit bench)\n")


def test_odometry_frames_written_apart_pair_as_the_frames_they_select(tmp_path):
    """Bench odometry options "0:3" and "0:3:1" (one selection) read "runs with different task options over the same
    (dataset, seed) units", while run folders pair "all" with "0:N": the unit holds the frames selected, over a KITTI
    sequence (the run registered every frame of a bounded slice) and over a simulated drive of known length."""
    from conftest import shared_path

    root = shared_path("kitti_odometry")
    suite = ("seeds: 2\nexperiments:\n  - {{task: odometry, dataset: {dataset}, {options}methods: [{method}]}}\n")
    kitti = f"{{kind: kitti, path: {root}, sequence: '00', name: k00}}"
    a = _bench(tmp_path, "a", suite.format(dataset=kitti, options="options: {frames: '0:3'}, ", method="kiss"))
    b = _bench(tmp_path, "b", suite.format(dataset=kitti, options="options: {frames: '0:3:1'}, ", method="kiss"))
    assert compare(a, b).n_pairs == 2
    sim = "{kind: sim_lidar, scene: street, n_frames: 3, n_beams: 8, n_azimuths: 180, name: st}"
    every = _bench(tmp_path, "every", suite.format(dataset=sim, options="", method="kiss"))
    sliced = _bench(tmp_path, "sliced", suite.format(dataset=sim, options="options: {frames: '0:3:1'}, ", method="kiss"))
    assert compare(every, sliced).n_pairs == 2
    fewer = _bench(tmp_path, "fewer", suite.format(dataset=sim, options="options: {frames: '1:3'}, ", method="kiss"))
    with pytest.raises(EvaluationError) as exc:
        compare(every, fewer)
    assert str(exc.value).startswith("compare: runs with different task options over the same (dataset, seed) units: "
                                     f"{{frames: '0:3'}} in {every} (kiss), {{frames: '1:3'}} in {fewer} (kiss)")


def test_json_to_stdout_leaves_stdout_to_the_json(tmp_path):
    """`lidarkit compare A B --json /dev/stdout | jq` failed: the table, the verdict and "wrote /dev/stdout" followed
    the JSON on stdout. They go to stderr then, as eval's do."""
    import subprocess
    import sys

    rng = np.random.default_rng(5)
    a = _straight_run(tmp_path / "a", 0.02 + 0.001 * rng.random(20))
    b = _straight_run(tmp_path / "b", 0.01 + 0.001 * rng.random(20))
    done = subprocess.run([sys.executable, "-m", "lidarkit", "compare", str(a), str(b), "--metric", "rpe_translation_m",
                           "--json", "/dev/stdout"], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0
    data = json.loads(done.stdout)
    assert (data["n_pairs"], data["better"], data["run_a"]) == (20, "b", str(a))
    assert "b is better than a on rpe_translation_m" in done.stderr and done.stderr.endswith("wrote /dev/stdout\n")


def test_a_loop_of_symbolic_links_is_named_as_one(tmp_path, capsys):
    """`compare RUN RUN --json o1.json` with o1.json -> o2.json -> o1.json ended in a RuntimeError traceback ("Symlink
    loop"); `compare l1 l2` over such links said "does not exist"."""
    run = _straight_run(tmp_path / "run", 0.01 * np.ones(8))
    (tmp_path / "o1.json").symlink_to("o2.json")
    (tmp_path / "o2.json").symlink_to("o1.json")
    code, stdout, err = run_cli(["compare", str(run), str(run), "--json", str(tmp_path / "o1.json")], capsys)
    assert (code, stdout) == (1, "")
    assert err == f"error: {tmp_path / 'o1.json'}: cannot write: a loop of symbolic links (a link that leads back to itself)\n"
    code, stdout, err = run_cli(["compare", str(tmp_path / "o1.json"), str(run)], capsys)
    assert (code, stdout) == (1, "")
    assert err == f"error: {tmp_path / 'o1.json'}: cannot read it: a loop of symbolic links (a link that leads back to itself)\n"
    with pytest.raises(DataError) as exc:
        compare(run, tmp_path / "o2.json")
    assert str(exc.value) == f"{tmp_path / 'o2.json'}: cannot read it: a loop of symbolic links (a link that leads back to itself)"
    # a link to nothing is named as one ("does not exist"), by the CLI and by load_odometry_run
    import importlib

    compare_module = importlib.import_module("lidarkit.eval.compare")  # (lidarkit.eval.compare is also the function)

    (tmp_path / "dang").symlink_to("nowhere")
    code, stdout, err = run_cli(["compare", str(tmp_path / "dang"), str(run)], capsys)
    assert (code, stdout, err) == (1, "", f"error: {tmp_path / 'dang'}: a symbolic link to a missing file (-> nowhere)\n")
    with pytest.raises(DataError) as exc:
        compare_module.load_odometry_run(tmp_path / "dang")
    assert str(exc.value) == f"{tmp_path / 'dang'}: a symbolic link to a missing file (-> nowhere)"


def test_a_diverged_drive_does_not_make_the_other_drive_s_seeds_one_measurement(tmp_path):
    """B diverged to 3e4 on one drive: the tolerance of "the seeds change nothing" was 1e-9 of the largest value of
    all units (3e-5), so the other drive's seeds, 1e-5 apart, counted as one unit: 2 units, p = 0.5. Each side's
    seeds of a drive are one value at their own scale only: 6 seeds + the diverged drive, p = 0.0156, A better."""
    def drives(job):
        if job.dataset_name == "calm":
            return {"ape_rmse_m": 0.05 + 2e-6 * job.seed + (2e-5 if job.method == "bad" else 0.0)}
        return {"ape_rmse_m": 0.07 if job.method == "good" else 3e4}

    _task("diverged_drive_test_task", drives)
    out = _bench(tmp_path, "s", "seeds: 6\nexperiments:\n  - {task: diverged_drive_test_task, datasets: [{kind: synthetic, "
                                "name: calm, variant: 1}, {kind: synthetic, name: wild, variant: 2}], methods: [good, bad]}\n")
    result = compare(out, out, method_a="good", method_b="bad")
    assert (result.pairing, result.n_pairs, result.n_ties) == ("unit", 7, 0)
    assert result.p_value == pytest.approx(2.0 ** -6) and result.better == "a"
    assert result.note == "the seeds of a dataset that gives each side one value whatever the seed count as one unit"


def test_jobs_of_a_suite_not_run_yet_or_unreadable_are_not_units_only_in_the_other(tmp_path):
    """B's jobs that never ran (or whose result file cannot be read) read "3 (dataset, seed) units only in A and 0 only
    in B are left out": they are the suite's units still to run, worded as the report words them; once `lidarkit
    bench` has resumed them every unit pairs."""
    from lidarkit.bench import load_suite, run_suite

    _task("not_run_test_task", _error)
    out = _bench(tmp_path, "s", "seeds: 8\nexperiments:\n  - {task: not_run_test_task, dataset: {kind: synthetic}, methods: [good, bad]}\n")
    bad = sorted((p for p in (out / "jobs").glob("*.json") if json.loads(p.read_text())["job"]["method"] == "bad"),
                 key=lambda p: json.loads(p.read_text())["job"]["seed"])
    bad[0].unlink()
    bad[1].unlink()
    bad[2].write_text("{")  # unreadable
    note = "3 (dataset, seed) unit(s) of {}'s suite not run yet or unreadable (`lidarkit bench` resumes them)"
    result = compare(out, out, method_a="good", method_b="bad")
    assert (result.n_pairs, result.note) == (5, note.format("B"))
    assert compare(out, out, method_a="bad", method_b="good").note == note.format("A")
    full = _bench(tmp_path, "full", "seeds: 8\nexperiments:\n  - {task: not_run_test_task, dataset: {kind: synthetic}, methods: [bad]}\n")
    across = compare(out, full, method_a="bad")
    assert (across.n_pairs, across.n_ties, across.note) == (5, 5, note.format("A"))
    run_suite(load_suite(tmp_path / "s.yaml"), out, executor="serial")  # resumes the three
    assert (compare(out, out, method_a="good", method_b="bad").n_pairs,
            compare(out, out, method_a="good", method_b="bad").note) == (8, "")


def test_task_options_and_dataset_specs_written_as_whole_floats_pair(tmp_path):
    """`init_noise_m: 1` in one suite and `1.0` in another are one bench job (its key counts whole floats as ints), but
    compare keyed the units by the options as written: "runs with different task options ... 1 in A, 1.0 in B". The
    dataset spec and the suite's jobs not run yet count them alike too."""
    _task("whole_float_test_task", _error)
    suite = ("seeds: 6\nexperiments:\n  - {{task: whole_float_test_task, dataset: {{kind: synthetic, name: F, size_m: {size}}}, "
             "options: {{noise_m: {noise}}}, methods: [{method}]}}\n")
    a = _bench(tmp_path, "a", suite.format(size="2", noise="1", method="good"))
    b = _bench(tmp_path, "b", suite.format(size="2.0", noise="1.0", method="bad"))
    result = compare(a, b)
    assert (result.n_pairs, result.better, result.note) == (6, "a", "")
    next(p for p in (b / "jobs").glob("*.json") if json.loads(p.read_text())["job"]["seed"] == 5).unlink()
    assert compare(a, b).note == ("1 (dataset, seed) unit(s) of B's suite not run yet or unreadable (`lidarkit bench` "
                                  "resumes them)")


def test_a_seed_without_the_metric_is_left_out_as_the_report_leaves_it(tmp_path):
    """One seed of 7 whose APE is null: the report left it out with a note and compared the 6 others, compare refused:
    "metric 'ape_rmse_m' missing in good for 1 of 7 units (syn, seed 3)". It leaves such units out and names them; with
    too few left the test's own verdict or error says so, beside the note."""
    _task("null_seed_test_task", lambda job: {**_error(job), **({"ape_rmse_m": None} if job.method == "good" and job.seed == 3 else {})})
    out = _bench(tmp_path, "s", "seeds: 7\nexperiments:\n  - {task: null_seed_test_task, dataset: {kind: synthetic, name: syn}, methods: [good, bad]}\n")
    result = compare(out, out, method_a="good", method_b="bad")
    note = "{} of 7 (dataset, seed) unit(s) left out: good has no value (null) of ape_rmse_m there ({})"
    assert (result.n_pairs, result.better, result.p_value) == (6, "a", pytest.approx(0.03125))
    assert result.note == note.format(1, "syn, seed 3")
    good = {json.loads(p.read_text())["job"]["seed"]: p for p in (out / "jobs").glob("*.json")
            if json.loads(p.read_text())["job"]["method"] == "good"}
    for seed in (0, 1, 2, 4):  # 2 units left: a test that cannot reach p < 0.05, said in its verdict
        record = json.loads(good[seed].read_text())
        record["metrics"]["ape_rmse_m"] = None
        good[seed].write_text(json.dumps(record))
    two = compare(out, out, method_a="good", method_b="bad")
    assert (two.n_pairs, two.better) == (2, "")
    assert two.note == note.format(5, "syn, seed 0; syn, seed 1; syn, seed 2; ... (5 in all)")
    assert "at least 6 are needed to reach p < 0.05" in two.verdict()
    record = json.loads(good[5].read_text())
    record["metrics"]["ape_rmse_m"] = None
    good[5].write_text(json.dumps(record))
    with pytest.raises(EvaluationError) as exc:  # 1 unit left: no test, and why
        compare(out, out, method_a="good", method_b="bad")
    assert str(exc.value).startswith("ape_rmse_m: a paired test needs at least 2 matched seeds, got 1 (")
    assert str(exc.value).endswith("; " + note.format(6, "syn, seed 0; syn, seed 1; syn, seed 2; ... (6 in all)"))


@pytest.mark.parametrize("layout", ["kitti", "sim", "root", "scans", "images", "kitti_images"])
def test_a_dataset_folder_is_named_as_one_with_the_command_that_makes_a_run(tmp_path, capsys, layout):
    """`lidarkit compare RUN SIM_DRIVE` said "no metrics.json: not a finished odometry run folder" of the simulated
    drive: a dataset folder is named as one, with its layout, and the command that makes a run of it."""
    data = tmp_path / "data"
    scans = {"kitti": data / "velodyne", "sim": data / "velodyne", "root": data / "sequences" / "00" / "velodyne",
             "scans": data}.get(layout)
    images = {"images": data, "kitti_images": data / "image_0"}.get(layout)
    for folder, suffix in ((scans, ".bin"), (images, ".png")):
        if folder is not None:
            folder.mkdir(parents=True)
            for k in range(3):
                (folder / f"{k:06d}{suffix}").write_bytes(b"\0" * 16)
    if layout in ("kitti", "sim"):
        (data / "times.txt").write_text("0.0\n0.1\n0.2\n")
    if layout == "sim":
        (data / "sim.yaml").write_text("scene: street\n")
    if layout == "kitti_images":
        (data / "calib.txt").write_text("P0: 1 0 0 0 0 1 0 0 0 0 1 0\n")
    held = {"kitti": "KITTI layout: velodyne/, times.txt",
            "sim": "a simulated drive in KITTI layout: velodyne/, sim.yaml, times.txt",
            "root": "a KITTI odometry root: sequences/", "scans": "3 .bin scan files", "images": "3 .png images",
            "kitti_images": "KITTI layout: image_0/, calib.txt"}[layout]
    then = ("an image sequence compares as bench results (a suite with a vo experiment over it: lidarkit bench)"
            if "images" in layout else f"run lidarkit odometry {data} --out DIR first")
    run = _straight_run(tmp_path / "run", np.full(5, 0.01))
    for argv in ([str(run), str(data)], [str(data), str(run)]):
        code, stdout, err = run_cli(["compare", *argv], capsys)
        assert (code, stdout, err) == (1, "", f"error: {data}: a dataset folder ({held}): compare takes run folders; {then}\n")
    (run / "metrics.json").unlink()  # a run cut off before its metrics, its plots beside its poses, is no image folder
    for name in ("ape.png", "trajectory.png"):
        (run / name).write_bytes(b"\0" * 16)
    code, _, err = run_cli(["compare", str(run), str(run)], capsys)
    assert (code, err) == (1, f"error: {run}: no metrics.json: not a finished odometry run folder\n")


def test_frames_of_a_stepped_run_are_named_as_typed():
    """A run over 2:12:3 of a 12-sweep drive was named "2:14:3" (its stop past the drive's end)."""
    import importlib

    frames_text = importlib.import_module("lidarkit.eval.compare")._frames_text
    assert frames_text((2, 5, 8, 11)) == "2:12:3"
    assert frames_text(tuple(range(12))) == "0:12"
    assert frames_text((0, 1, 4)) == "3 frames from 0 to 4"


def test_runs_over_a_slice_without_timing_csv_are_not_called_config_less(tmp_path, capsys):
    """Two KITTI runs over frames 0:10 against two pose files, timing.csv gone: the refusal said both had "no readable
    config.yaml" (a slice's frames needed the dataset's length, which a KITTI run does not record)."""
    import yaml

    for name, scale in (("a", 0.0), ("b", 0.05)):
        run = _straight_run(tmp_path / name, np.full(9, scale))
        run.joinpath("config.yaml").write_text(yaml.safe_dump({"run": {"dataset": "kitti_00", "dataset_config": None,
                                                                        "frames": "0:10", "n_frames": 10}}))
    (tmp_path / "b" / "ground_truth_kitti.txt").write_text((tmp_path / "b" / "poses_kitti.txt").read_text())
    code, stdout, err = run_cli(["compare", str(tmp_path / "a"), str(tmp_path / "b")], capsys)
    assert code == 1 and "runs over different data" in err and "config.yaml" not in err, err


def test_runs_over_two_pose_files_of_one_sequence_name_the_reader_option(tmp_path, capsys):
    """Two KITTI runs against poses/00.txt and poses_semantickitti.txt were refused as "with other values" and nothing
    more: config.yaml's dataset_options name the poses file each read."""
    import yaml

    for name, scale, poses in (("a", 0.0, "/data/poses/00.txt"), ("b", 0.05, "/data/00/poses_semantickitti.txt")):
        run = _straight_run(tmp_path / name, np.full(9, scale))
        run.joinpath("config.yaml").write_text(yaml.safe_dump({"run": {
            "dataset": "kitti_00", "dataset_config": None, "frames": "0:10", "n_frames": 10,
            "dataset_options": {"sequence": "00", "poses_path": poses}}}))
    (tmp_path / "b" / "ground_truth_kitti.txt").write_text((tmp_path / "b" / "poses_kitti.txt").read_text())
    code, stdout, err = run_cli(["compare", str(tmp_path / "a"), str(tmp_path / "b")], capsys)
    assert code == 1 and ('with other values (their reader options differ in poses_path ("/data/poses/00.txt" in A, '
                          '"/data/00/poses_semantickitti.txt" in B))') in err, err


def test_a_kitti_velodyne_folder_is_told_to_run_its_sequence(tmp_path, capsys):
    """compare SEQ/velodyne RUN advised "run lidarkit odometry SEQ/velodyne", a run without ground truth that compare
    then refused: the advice names the sequence folder, whose poses score the run."""
    sequence = tmp_path / "00"
    (sequence / "velodyne").mkdir(parents=True)
    for k in range(3):
        np.zeros((4, 4), np.float32).tofile(sequence / "velodyne" / f"{k:06d}.bin")
    (sequence / "times.txt").write_text("0\n0.1\n0.2\n")
    run = _straight_run(tmp_path / "run", np.zeros(3))
    code, stdout, err = run_cli(["compare", str(sequence / "velodyne"), str(run)], capsys)
    assert code == 1 and err.strip().endswith(f"run lidarkit odometry {sequence} --out DIR first"), err


def test_runs_over_two_exports_of_the_sweeps_name_their_ground_truth_instants(tmp_path, capsys):
    """kiss over a rosbag1 export (poses at the sweep start, re-timed to the end) and small_gicp over an mcap export of
    the same sweeps (re-timed mid-sweep) read "runs over different data: ... 9 with other values (datasets ...)": the
    instants each was scored at were said on the same-dataset branch only."""
    import yaml

    for name, scale, dataset, instant in (("a", 0.0, "rosbag:run1.bag/points", "end"), ("b", 0.05, "mcap:sim.mcap/points", "mid")):
        run = _straight_run(tmp_path / name, np.full(9, scale))
        run.joinpath("config.yaml").write_text(yaml.safe_dump({"run": {"dataset": dataset, "dataset_config": None,
                                                                        "frames": "0:10", "n_frames": 10}}))
        run.joinpath("metrics.json").write_text(json.dumps({"method": name, "effective": {"ground_truth_instant": instant}}))
    (tmp_path / "b" / "ground_truth_kitti.txt").write_text((tmp_path / "b" / "poses_kitti.txt").read_text())
    code, _, err = run_cli(["compare", str(tmp_path / "a"), str(tmp_path / "b")], capsys)
    assert code == 1 and err.endswith("with other values (datasets rosbag:run1.bag/points and mcap:sim.mcap/points; "
                                      "ground truth at the sweep end in A, mid in B)\n"), err
    # an instant a reader does not state is no sweep instant to name
    metrics = json.loads((tmp_path / "b" / "metrics.json").read_text())
    metrics["effective"]["ground_truth_instant"] = "not stated by the reader"
    (tmp_path / "b" / "metrics.json").write_text(json.dumps(metrics))
    code, _, err = run_cli(["compare", str(tmp_path / "a"), str(tmp_path / "b")], capsys)
    assert code == 1 and err.endswith("(datasets rosbag:run1.bag/points and mcap:sim.mcap/points)\n"), err


def test_experiments_over_other_frames_or_pairs_are_pooled_and_the_same_data_is_refused_naming_the_option(tmp_path):
    """Two odometry experiments over frames 0:4 and 4:8 of one drive (and icp_pair experiments over pairs [[0, 1]] and
    [[2, 3]]) were refused: "has results in 2 experiments ... over the same (dataset, seed) units", and --experiment left
    1 unit. The part of the dataset each ran is part of its unit now; experiments over the same part are still refused,
    naming the option they differ in (the default first pair and ``pairs: [[0, 1]]`` are one part)."""
    drive = "{kind: sim_lidar, scene: street, n_frames: 8, n_beams: 8, n_azimuths: 180, seed: 3, name: st}"
    methods = "methods: [vanilla, {name: vanilla, params: {voxel_size_m: 2.0}}]"
    pick = {"method_a": "vanilla", "method_b": "vanilla(voxel_size_m=2.0)"}
    frames = _bench(tmp_path, "frames", "experiments:\n"
                    f"  - {{name: a, task: odometry, dataset: {drive}, options: {{frames: '0:4'}}, {methods}}}\n"
                    f"  - {{name: b, task: odometry, dataset: {drive}, options: {{frames: '4:8'}}, {methods}}}\n")
    pooled = compare(frames, frames, **pick)
    assert (pooled.n_pairs, pooled.metric) == (2, "ape_se3_rmse_m")
    pairs = _bench(tmp_path, "pairs", "experiments:\n"
                   f"  - {{name: p01, task: icp_pair, dataset: {drive}, options: {{pairs: [[0, 1]]}}, {methods}}}\n"
                   f"  - {{name: p23, task: icp_pair, dataset: {drive}, options: {{pairs: [[2, 3]]}}, {methods}}}\n"
                   f"  - {{name: first, task: icp_pair, dataset: {drive}, {methods}}}\n"
                   f"  - {{name: noisy, task: icp_pair, dataset: {drive}, options: {{pairs: [[2, 3]], init_noise_m: 0.5}}, "
                   f"{methods}}}\n")
    with pytest.raises(ConfigError) as exc:
        compare(pairs, pairs, **pick)
    assert str(exc.value) == (f"{pairs}: vanilla has results in 4 experiments of task icp_pair (first, noisy, p01, p23) over "
                              "the same (dataset, seed) units and pairs, each its own (task options: init_noise_m 0.5 in "
                              "noisy, not written in p23; pairs not written in first, [[0, 1]] in p01): --experiment picks one")
    apart = _bench(tmp_path, "apart", "experiments:\n"
                   f"  - {{name: p01, task: icp_pair, dataset: {drive}, options: {{pairs: [[0, 1]]}}, {methods}}}\n"
                   f"  - {{name: p23, task: icp_pair, dataset: {drive}, options: {{pairs: [[2, 3]]}}, {methods}}}\n"
                   f"  - {{name: p45, task: icp_pair, dataset: {drive}, options: {{pairs: [[4, 5]]}}, {methods}}}\n")
    assert compare(apart, apart, **pick).n_pairs == 3
    twice = _bench(tmp_path, "twice", "experiments:\n"
                   f"  - {{name: p01, task: icp_pair, dataset: {drive}, options: {{pairs: [[0, 1]]}}, {methods}}}\n"
                   f"  - {{name: again, task: icp_pair, dataset: {drive}, options: {{pairs: [[0, 1]]}}, {methods}}}\n")
    with pytest.raises(ConfigError) as exc:
        compare(twice, twice, **pick)
    assert str(exc.value).endswith("each its own (task options: again and p01 alike): --experiment picks one")


def test_a_dataset_reached_through_a_symbolic_link_pairs_and_messages_keep_its_written_path(tmp_path):
    """KITTI 00 given through a link to the KITTI root read "runs over different data ... their dataset specs differ in
    path": specs pair with the links of their folders followed now; a path that differs is shown as written."""
    from conftest import shared_path

    root = shared_path("kitti_odometry")
    (tmp_path / "linked").symlink_to(root, target_is_directory=True)
    _spec_task("kitti_link_test_task")
    suite = "seeds: 6\nexperiments:\n  - {{task: kitti_link_test_task, dataset: {{kind: kitti, path: {where}, sequence: '00', name: k00}}, methods: [{method}]}}\n"
    a = _bench(tmp_path, "a", suite.format(where=root, method="good"))
    b = _bench(tmp_path, "b", suite.format(where=tmp_path / "linked", method="bad"))
    result = compare(a, b)
    assert (result.n_pairs, result.better, result.note) == (6, "a", "")
    other = tmp_path / "other"
    (other / "sequences" / "00" / "velodyne").mkdir(parents=True)
    (tmp_path / "elsewhere").symlink_to(other, target_is_directory=True)
    c = _bench(tmp_path, "c", suite.replace(", sequence: '00'", "").format(where=tmp_path / "elsewhere" / "sequences" / "00",
                                                                          method="bad"))
    with pytest.raises(EvaluationError) as exc:
        compare(b, c)
    assert str(exc.value).endswith(f'their dataset specs differ in path ("{tmp_path}/linked/sequences/00" in A, '
                                   f'"{tmp_path}/elsewhere/sequences/00" in B)')
