"""Statistics over runs and paired comparisons: bootstrap CIs, Wilcoxon verdicts, `lidarkit compare` on runs."""

from __future__ import annotations

import json
import textwrap
from pathlib import Path

import numpy as np
import pytest
from scipy import stats as sstats

from lidarkit.cli import main
from lidarkit.errors import ConfigError, DataError, EvaluationError
from lidarkit.eval import bootstrap_ci, compare, paired_test, summarize


def run_cli(argv: list[str], capsys) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as exc:
        main(argv)
    out, err = capsys.readouterr()
    return int(exc.value.code or 0), out, err


def test_summary_matches_numpy_and_bootstrap_reproduces_exactly():
    values = np.random.default_rng(3).gamma(2.0, 0.5, size=12)
    s = summarize(values, seed=7)
    assert (s.n, s.mean, s.median) == (12, pytest.approx(values.mean()), pytest.approx(np.median(values)))
    assert s.std == pytest.approx(values.std(ddof=1))
    assert s.ci_low < s.mean < s.ci_high
    again = bootstrap_ci(values.copy(), seed=7)
    assert again == bootstrap_ci(values, seed=7)  # bit-identical for the same seed
    assert bootstrap_ci(values, seed=8) != again
    # the percentile interval of a large normal sample is close to mean +- 1.96 sem
    big = np.random.default_rng(0).normal(5.0, 2.0, 4000)
    lo, hi = bootstrap_ci(big, seed=1)
    sem = big.std(ddof=1) / np.sqrt(big.size)
    assert (hi - lo) == pytest.approx(2 * 1.96 * sem, rel=0.1)
    assert bootstrap_ci([2.5]) == (2.5, 2.5)
    assert summarize([]).n == 0
    same = summarize([0.0419] * 5)  # numpy's std of equal floats is 8.5e-18, printed as "0.0419 ± 8.5e-18"
    assert same.std == 0.0 and same.format() == "0.0419 ± 0 [0.0419, 0.0419]"
    from lidarkit.bench.report import _stats

    assert _stats([0.0419] * 5) == (pytest.approx(0.0419), 0.0, 5)


def test_bad_statistics_input_raises():
    with pytest.raises(EvaluationError, match="non-finite"):
        summarize([1.0, float("nan")])
    with pytest.raises(ConfigError, match="confidence"):
        bootstrap_ci([1.0, 2.0], confidence=1.5)
    with pytest.raises(EvaluationError, match="differ in count"):
        paired_test([1.0, 2.0, 3.0], [1.0, 2.0])
    with pytest.raises(EvaluationError, match="at least 2"):
        paired_test([1.0], [2.0])
    for seed in (-1, 1.5, True):  # a ValueError / TypeError traceback from numpy's generator (lidarkit compare --seed -1)
        with pytest.raises(ConfigError, match=f"seed must be an integer >= 0, got {seed!r}"):
            paired_test([1.0, 2.0, 3.0], [2.0, 3.0, 4.5], seed=seed)
        with pytest.raises(ConfigError, match="seed must be an integer >= 0"):
            bootstrap_ci([1.0, 2.0], seed=seed)


def test_values_that_are_text_are_one_named_error():
    """summarize(["a"]) raised numpy's ValueError "could not convert string to float: 'a'"; numeric text is text too (it
    was read as numbers)."""
    for values, shown in ((["a"], "['a']"), ([1.0, "x"], "[1.0, 'x']"), (["1.5", 2.5], "['1.5', 2.5]")):
        with pytest.raises(ConfigError) as exc:
            summarize(values)
        assert str(exc.value) == f"summarize: values must be numbers, got {shown}"


def test_paired_test_agrees_with_scipy_and_reads_plainly():
    rng = np.random.default_rng(1)
    b = rng.uniform(1.0, 2.0, 15)
    a = b - rng.uniform(0.05, 0.3, 15)  # a lower (better) on every unit
    res = paired_test(a, b, name_a="kiss", name_b="vanilla", metric="ape_rmse_m")
    ref = sstats.wilcoxon(a - b)
    assert res.p_value == pytest.approx(ref.pvalue) and res.statistic == pytest.approx(ref.statistic)
    assert res.p_value < 0.001 and res.effect_size == pytest.approx(-1.0) and res.better == "a"
    assert res.verdict().startswith("kiss is better than vanilla on ape_rmse_m")
    flipped = paired_test(b, a, name_a="vanilla", name_b="kiss", metric="ape_rmse_m")
    assert flipped.better == "b" and flipped.effect_size == pytest.approx(1.0)
    # higher-is-better metrics flip the winner
    assert paired_test(a, b, lower_is_better=False).better == "b"
    # differences of pure round-off are ties: p = 1 and "no significant difference"
    same = paired_test(b, b * (1 + 1e-15), name_a="kiss", name_b="kiss again")
    assert same.n_ties == 15 and same.p_value == 1.0 and not same.significant
    assert "no significant difference" in same.verdict()
    # a significant but tiny difference inside the measured noise is not called
    small = paired_test(a, b, noise=1.0)
    assert not small.significant and "within the run-to-run noise" in small.verdict()


def test_the_winner_is_the_one_the_ranks_favour_not_the_mean():
    """A better on 19 of 20 seeds, one seed 5 worse: the mean points at B, the signed-rank test and the median at A."""
    b = np.linspace(1.0, 2.0, 20)
    a = b - 0.1
    a[-1] = b[-1] + 5.0
    res = paired_test(a, b, name_a="A", name_b="B", metric="ape_rmse_m")
    assert res.mean_diff > 0 and res.median_diff == pytest.approx(-0.1) and res.effect_size < 0
    assert res.p_value < 0.05 and res.better == "a"
    assert res.diff_ci_high == pytest.approx(-0.1) and res.diff_ci_low < 0  # the median's CI: it excludes 0 here
    text = res.verdict()
    assert text.startswith("A is better than B") and "median difference -0.1" in text and "points the other way" in text


SUITE = """
name: sim-seeds
seeds: 10
experiments:
  - name: sim
    task: odometry
    # no dataset seed: each job seed simulates another drive
    dataset: {{kind: sim_lidar, scene: street, n_frames: 10, n_beams: 32, n_azimuths: 720, name: sim street}}
    methods: {methods}
"""


def _run(tmp_path: Path, name: str, methods: str) -> Path:
    from lidarkit.bench.runner import run_suite
    from lidarkit.bench.suite import load_suite

    path = tmp_path / f"{name}.yaml"
    path.write_text(textwrap.dedent(SUITE.format(methods=methods)))
    out = tmp_path / name
    summary = run_suite(load_suite(path), out, executor="serial")
    assert summary.failed == 0
    return out


@pytest.fixture(scope="module")
def kiss_and_vanilla_10_seeds(tmp_path_factory) -> Path:
    """The folder of SUITE with kiss and vanilla(voxel_size_m=0.5) over its 10 seeds, run once for the tests that
    compare in it: read it, never change it (a test that runs another suite into it does so in a copy)."""
    return _run(tmp_path_factory.mktemp("suite"), "both", "[kiss, {name: vanilla, params: {voxel_size_m: 0.5}}]")


def test_compare_tells_kiss_from_vanilla_and_kiss_from_itself_over_10_simulated_seeds(tmp_path, capsys,
                                                                                        kiss_and_vanilla_10_seeds):
    both = kiss_and_vanilla_10_seeds
    again = _run(tmp_path, "kiss_again", "[kiss]")
    code, out, _ = run_cli(["compare", str(both), str(both), "--method-a", "kiss", "--method-b", "vanilla",
                            "--metric", "ape_rmse_m", "--json", str(tmp_path / "cmp.json")], capsys)
    assert code == 0
    data = json.loads((tmp_path / "cmp.json").read_text())
    assert data["n_pairs"] == 10 and data["p_value"] < 0.01 and data["better"] == "a"
    assert "kiss is better than vanilla(voxel_size_m=0.5)" in out
    same = compare(both, again, method_a="kiss", metric="ape_rmse_m")
    assert same.n_pairs == 10 and not same.significant
    assert "no significant difference" in same.verdict()
    # the per-seed APE summary over the 10 drives is reproducible
    from lidarkit.eval.compare import load_bench_runs

    values = [v["ape_rmse_m"] for v in load_bench_runs(both, "kiss").values.values()]
    assert summarize(values, seed=0) == summarize(values, seed=0)
    # different data: the kiss-only folder against a suite over another simulated scene
    other = tmp_path / "other.yaml"
    other.write_text(textwrap.dedent(SUITE.format(methods="[kiss]")).replace("seeds: 10", "seeds: [11, 12]"))
    from lidarkit.bench.runner import run_suite
    from lidarkit.bench.suite import load_suite

    run_suite(load_suite(other), tmp_path / "other", executor="serial")
    with pytest.raises(EvaluationError, match="runs over different data"):
        compare(again, tmp_path / "other")
    with pytest.raises(ConfigError, match="choose one of"):
        compare(both, again)
    # a folder over 3 of the 10 seeds: the 3 are paired, and the comparison says 7 were left out
    few = tmp_path / "few.yaml"
    few.write_text(textwrap.dedent(SUITE.format(methods="[kiss]")).replace("seeds: 10", "seeds: [0, 1, 2]"))
    run_suite(load_suite(few), tmp_path / "few", executor="serial")
    partial = compare(again, tmp_path / "few", metric="ape_rmse_m")
    assert partial.n_pairs == 3 and partial.note == "7 (dataset, seed) units only in A and 0 only in B are left out: 3 paired"


def test_compare_run_folders_per_frame_and_bad_input(tmp_path, capsys):
    from lidarkit.odometry import run
    from lidarkit.sim.lidar import SimulatedLidarSequence

    seq = SimulatedLidarSequence(scene="street", n_frames=10, n_beams=32, n_azimuths=720, seed=4)
    run(seq, "kiss", out_dir=tmp_path / "kiss")
    run(seq, "vanilla", params={"voxel_size_m": 0.5}, out_dir=tmp_path / "vanilla")
    res = compare(tmp_path / "kiss", tmp_path / "vanilla")
    assert res.pairing == "frame" and res.metric == "rpe_translation_m" and res.n_pairs == 9
    assert res.mean_a < res.mean_b
    # runs are named with their settings away from the defaults, as bench labels them (two kiss runs read "kiss (A)",
    # "kiss (B)"), and the JSON names the folders
    run(seq, "kiss", params={"deskew": False}, out_dir=tmp_path / "kiss_nd")
    code, _, _ = run_cli(["compare", str(tmp_path / "kiss"), str(tmp_path / "kiss_nd"), "--json", str(tmp_path / "c.json")], capsys)
    saved = json.loads((tmp_path / "c.json").read_text())
    assert code == 0 and (saved["name_a"], saved["name_b"]) == ("kiss", "kiss(deskew=False)")
    assert (saved["run_a"], saved["run_b"]) == (str(tmp_path / "kiss"), str(tmp_path / "kiss_nd"))
    assert res.name_b == "vanilla(voxel_size_m=0.5)"
    code, out, _ = run_cli(["compare", str(tmp_path / "kiss"), str(tmp_path / "kiss")], capsys)
    assert code == 0 and "no significant difference" in out
    with pytest.raises(ConfigError, match="a task applies to bench results folders only"):  # (it was ignored)
        compare(tmp_path / "kiss", tmp_path / "vanilla", task="odometry")
    with pytest.raises(ConfigError, match=r"all: every result \(--all\) applies to bench results folders only"):
        compare(tmp_path / "kiss", tmp_path / "vanilla", every_result=True)
    with pytest.raises(DataError, match=r"metrics.json: is a file: compare takes an odometry run folder or a bench results folder"):
        compare(tmp_path / "kiss" / "metrics.json", tmp_path / "vanilla")  # (it read "does not exist")
    other = SimulatedLidarSequence(scene="street", n_frames=10, n_beams=32, n_azimuths=720, seed=5)
    run(other, "kiss", out_dir=tmp_path / "kiss_other")
    with pytest.raises(EvaluationError, match="runs over different data"):
        compare(tmp_path / "kiss", tmp_path / "kiss_other")
    (tmp_path / "kiss_other" / "metrics.json").unlink()
    with pytest.raises(DataError, match="no metrics.json"):
        compare(tmp_path / "kiss", tmp_path / "kiss_other")
    code, _, err = run_cli(["compare", str(tmp_path / "kiss"), str(tmp_path / "kiss_other")], capsys)
    assert code == 1 and "no metrics.json" in err


def test_compare_runs_over_one_bag_scored_at_their_own_sweep_instants(tmp_path, capsys):
    """kiss (deskewed to the sweep end) and small_gicp (no deskew: the sweep middle) over one bag are each scored
    against the bag's ground truth re-timed to their own instant: the truths differ, yet it is the same data, so the
    comparison runs and says so; a run over another drive is still refused."""
    from lidarkit.odometry import run
    from lidarkit.registration import available_icp
    from lidarkit.sim.bag_export import export_bag
    from lidarkit.sim.lidar import SimulatedLidarSequence

    other_method = "small_gicp" if "small_gicp" in available_icp() else "open3d_point_to_plane"
    sim = dict(scene="street", n_frames=6, n_beams=16, n_azimuths=720, speed_mps=5.0, accel_time_s=0.0)
    bag = export_bag(SimulatedLidarSequence(pose_instant="mid", seed=4, **sim), tmp_path / "run.bag", "rosbag1")
    run(bag, "kiss", out_dir=tmp_path / "kiss")
    run(bag, other_method, out_dir=tmp_path / "other")
    res = compare(tmp_path / "kiss", tmp_path / "other")
    assert res.n_pairs == 5
    assert f"(kiss: end, {other_method}: mid), over the same dataset and frames" in res.note
    code, out, _ = run_cli(["compare", str(tmp_path / "kiss"), str(tmp_path / "other"), "--json", str(tmp_path / "c.json")], capsys)
    assert code == 0 and "note: each run is scored against the ground truth at its own instant" in " ".join(out.split())
    assert json.loads((tmp_path / "c.json").read_text())["note"] == res.note
    assert compare(tmp_path / "kiss", tmp_path / "kiss").note == ""
    another = export_bag(SimulatedLidarSequence(pose_instant="mid", seed=5, **sim), tmp_path / "another.bag", "rosbag1")
    run(another, other_method, out_dir=tmp_path / "another")
    with pytest.raises(EvaluationError, match="runs over different data"):
        compare(tmp_path / "kiss", tmp_path / "another")


def test_runs_at_other_sweep_instants_pair_their_kitti_segments_by_first_frame_and_length(tmp_path):
    """kiss (sweep end) and vanilla (no deskew: mid-sweep) over one simulated drive were refused per KITTI segment
    ("paired values differ in count: 12 for kiss, 11 for small_gicp"): measured on other truths, a path of 200.0 m
    against 199.5 m gave one run a segment the other lacks, and segments paired by position covered other frames.
    They pair by first frame and length, the rest left out and said; the default metric needs segments on both."""
    from lidarkit.eval import kitti_drift
    from lidarkit.eval.compare import load_odometry_run as load_run
    from lidarkit.odometry import run

    spec = "sim:street?frames=210&beams=8&azimuths=360&seed=1"  # (a 200.0 m path at the sweep ends, 199.5 m mid-sweep)
    for method in ("kiss", "vanilla"):
        run(spec, method, params={"voxel_size_m": 0.5} if method == "vanilla" else {}, out_dir=tmp_path / method)
    runs = {m: load_run(tmp_path / m) for m in ("kiss", "vanilla")}
    drifts = {m: kitti_drift(r.ground_truth, r.estimate) for m, r in runs.items()}
    keys = {m: list(zip(d.segment_first_frame.tolist(), d.segment_length_m.tolist())) for m, d in drifts.items()}
    assert keys["kiss"] != keys["vanilla"]  # (the premise: other truths, other segments)
    common = [k for k in keys["kiss"] if k in keys["vanilla"]]
    res = compare(tmp_path / "kiss", tmp_path / "vanilla")
    assert res.metric == "segment_translation_pct" and res.n_pairs == len(common) > 0
    expected = [drifts["kiss"].segment_translation_pct[keys["kiss"].index(k)] - drifts["vanilla"].segment_translation_pct[keys["vanilla"].index(k)]
                for k in common]
    np.testing.assert_allclose(np.mean(expected), res.mean_a - res.mean_b, rtol=1e-9)
    left = len(keys["kiss"]) + len(keys["vanilla"]) - 2 * len(common)
    assert f"{left} KITTI segment(s) on only one run's ground truth left out (paired by first frame and length)" in res.note
    assert compare(tmp_path / "vanilla", tmp_path / "kiss").n_pairs == len(common)  # (either order)


def test_a_metric_a_task_declares_better_higher_is_compared_that_way(tmp_path):
    """compare and assert_no_worse_than took the direction from a fixed list (hz, converged_fraction): a task's
    Metric(better="higher") was compared as lower-is-better, and the verdict inverted."""
    import textwrap

    from lidarkit.bench import Metric, load_suite, run_suite
    from lidarkit.bench.tasks import higher_is_better
    from lidarkit.eval import compare
    from lidarkit.testing import assert_no_worse_than

    def success(job):
        bump = 0.01 * np.random.default_rng(job.seed).random()
        good = job.method == "good"
        return {"success_rate": (0.9 if good else 0.5) + bump, "error_m": (0.1 if good else 0.5) + bump}

    _register_metric_task("success_test_task", (Metric("success_rate", "success rate", better="higher"), Metric("error_m", "error [m]")),
                          success)

    assert higher_is_better("success_rate") and not higher_is_better("error_m") and higher_is_better("hz")
    (tmp_path / "s.yaml").write_text(textwrap.dedent("""
        seeds: 8
        experiments:
          - {name: e, task: success_test_task, dataset: {kind: synthetic}, methods: [good, bad]}
    """))
    run_suite(load_suite(tmp_path / "s.yaml"), tmp_path / "out", executor="serial")
    for metric in ("success_rate", "error_m"):
        verdict = compare(tmp_path / "out", tmp_path / "out", method_a="good", method_b="bad", metric=metric).verdict()
        assert verdict.startswith("good is better than bad"), verdict
    assert_no_worse_than({"success_rate": 0.95}, {"success_rate": 0.90}, metric="success_rate", tolerance=0.0)
    with pytest.raises(AssertionError, match="regression: success_rate"):
        assert_no_worse_than({"success_rate": 0.85}, {"success_rate": 0.90}, metric="success_rate", tolerance=0.0)


def test_compare_in_a_suite_of_two_tasks_pairs_the_units_of_the_metric_s_task(tmp_path):
    """A suite with an icp_pair and an odometry experiment could not be compared at all: every metric was "missing"
    in the other task's units. Those units are left out now, said in the note."""
    import textwrap

    from lidarkit.bench import load_suite, run_suite
    from lidarkit.eval import compare

    for name, metric in (("pairs_test_task", "pair_error_m"), ("runs_test_task", "run_error_m")):
        _register_metric_task(name, metric, lambda job: (0.1 if job.method == "good" else 0.5)
                              + 0.01 * np.random.default_rng(job.seed).random())
    (tmp_path / "s.yaml").write_text(textwrap.dedent("""
        seeds: 8
        experiments:
          - {name: p, task: pairs_test_task, dataset: {kind: synthetic}, methods: [good, bad]}
          - {name: r, task: runs_test_task, dataset: {kind: synthetic}, methods: [good, bad]}
    """))
    run_suite(load_suite(tmp_path / "s.yaml"), tmp_path / "out", executor="serial")
    for metric, other in (("pair_error_m", "runs_test_task"), ("run_error_m", "pairs_test_task")):
        result = compare(tmp_path / "out", tmp_path / "out", method_a="good", method_b="bad", metric=metric)
        assert result.n_pairs == 8 and result.verdict().startswith("good is better than bad")
        assert f"8 (dataset, seed) units of {other} (no {metric}) left out: 8 paired" in result.note
    with pytest.raises(ConfigError, match="unknown metric 'error_m'"):
        compare(tmp_path / "out", tmp_path / "out", method_a="good", method_b="bad", metric="error_m")


def test_verdicts_with_tied_units_and_a_median_ci_across_zero():
    """The median counts tied units, which the rank test leaves out: with 10 of 18 tied it is 0, and the verdict said the
    ranks and the median 'disagree in direction'. A verdict beside a median CI reaching across 0 read as a contradiction."""
    tied = paired_test([1.0] * 10 + [2.0] * 8, [1.0] * 18, name_a="A", name_b="B")
    assert tied.better == "" and "the median difference is 0: 10 of 18 seeds are tied" in tied.verdict()
    touching = paired_test([1.0] * 8 + [2.0] * 10, [1.0] * 18, name_a="A", name_b="B")  # a CI of [+0, +1] includes 0
    assert touching.better == "" and touching.diff_ci_low == 0.0 and "[+0, +1] includes 0" in touching.verdict()
    diffs = np.random.default_rng(16).normal(0.3, 1.0, 25)  # Wilcoxon p = 0.048, median +0.44, its CI [-0.07, +0.87]
    mixed = paired_test(diffs, np.zeros(25), name_a="A", name_b="B")
    assert mixed.p_value < mixed.alpha and mixed.diff_ci_low < 0 < mixed.diff_ci_high
    assert mixed.better == "" and "includes 0" in mixed.verdict()


def test_seeds_that_change_nothing_are_one_measurement_and_few_seeds_say_so():
    """Six seeds of deterministic methods on fixed data gave six copies of one difference: Wilcoxon p = 0.031 and a
    winner. Five pairs can never reach p < 0.05: the verdict says so instead of 'no significant difference' alone."""
    copies = paired_test([0.40] * 6, [0.35] * 6, name_a="A", name_b="B")
    assert copies.repeated and copies.better == "" and copies.p_value < 0.05
    assert "one measurement repeated, not 6 independent ones" in copies.verdict()
    varied = paired_test([0.40, 0.41, 0.42, 0.43, 0.44, 0.45], [0.35] * 6, name_a="A", name_b="B")  # B fixed, A varies: a test
    assert not varied.repeated and varied.better == "b"
    assert not paired_test([1.0] * 6, [2.0] * 6, pairing="segment").repeated  # segments are units by construction
    few = paired_test(np.arange(1.0, 6.0) * 10, np.arange(1.0, 6.0), name_a="A", name_b="B")
    assert few.better == "" and few.p_value == pytest.approx(0.0625)
    assert "with 5 differing seeds the smallest p this test can give is 0.0625: at least 6 are needed to reach p < 0.05" in few.verdict()


def test_compare_holds_the_jobs_of_the_folder_s_suite_as_its_report(tmp_path, capsys, kiss_and_vanilla_10_seeds):
    """A folder reused for a smaller suite still holds the earlier suite's results: compare paired them too (its
    report left them out), turning p = 0.25 over 3 seeds into a verdict over 10."""
    import shutil

    from lidarkit.bench.runner import run_suite
    from lidarkit.bench.suite import load_suite

    folder = tmp_path / "reused"
    shutil.copytree(kiss_and_vanilla_10_seeds, folder)  # 10 seeds
    smaller = tmp_path / "smaller.yaml"
    smaller.write_text(textwrap.dedent(SUITE.format(methods="[kiss, {name: vanilla, params: {voxel_size_m: 0.5}}]"))
                       .replace("seeds: 10", "seeds: [0, 1, 2]"))
    run_suite(load_suite(smaller), folder, executor="serial")
    now = compare(folder, folder, method_a="kiss", method_b="vanilla", metric="ape_rmse_m")
    assert now.n_pairs == 3 and "14 result(s) in" in now.note and "not in its suite.json (an earlier suite) left out" in now.note
    every = compare(folder, folder, method_a="kiss", method_b="vanilla", metric="ape_rmse_m", every_result=True)
    assert every.n_pairs == 10 and every.note == ("each side is scored against the ground truth at its own instant of the "
                                                  "sweep (kiss: end, vanilla(voxel_size_m=0.5): mid)")
    with pytest.raises(ConfigError, match=r"unknown metric 'ape_rmse'; these results have: .*ape_rmse_m"):  # it listed the seeds
        compare(folder, folder, method_a="kiss", method_b="vanilla", metric="ape_rmse")
    code, out, _ = run_cli(["compare", str(folder), str(folder), "--method-a", "kiss", "--method-b", "vanilla", "--metric", "ape_rmse_m",
                            "--all"], capsys)
    assert code == 0 and "(10 paired seeds" in out


def test_noise_from_a_baseline_is_refused_for_run_folders(tmp_path):
    """A baseline's bands are of whole-run metrics: for two run folders (compared per segment or frame) no metric ever
    matched, and the hint to name one could not be followed."""
    from conftest import shared_path

    from lidarkit.odometry import run

    spec = f"kitti:{shared_path('kitti_odometry')}?sequence=00"
    for name in ("a", "b"):
        run(spec, "small_gicp", out_dir=tmp_path / name, progress=False)
    with pytest.raises(ConfigError, match="a baseline's bands are of bench metrics .* give that noise with --noise"):
        compare(tmp_path / "a", tmp_path / "b", metric="rpe_translation_m", noise_from=tmp_path / "baseline")


def test_compare_counts_a_dataset_whose_seeds_change_nothing_once(tmp_path):
    """Two datasets whose every seed gives each side one value: 10 "seeds" were tested as independent units
    (p = 0.002) from 2 measurements; now one unit per dataset."""
    import textwrap

    from lidarkit.bench import load_suite, run_suite
    from lidarkit.eval import compare

    # deterministic: the seed changes nothing
    _register_metric_task("fixed_data_test_task", "error_m",
                          lambda job: (0.1 if job.method == "good" else 0.5) + len(job.dataset_name) * 0.01)

    (tmp_path / "s.yaml").write_text(textwrap.dedent("""
        seeds: 5
        experiments:
          - {name: e, task: fixed_data_test_task, datasets: [{kind: synthetic, name: a, variant: 1}, {kind: synthetic, name: bb, variant: 2}], methods: [good, bad]}
    """))
    run_suite(load_suite(tmp_path / "s.yaml"), tmp_path / "out", executor="serial")
    result = compare(tmp_path / "out", tmp_path / "out", method_a="good", method_b="bad", metric="error_m")
    assert result.pairing == "dataset" and result.n_pairs == 2 and not result.significant
    assert "with 2 differing datasets the smallest p this test can give is 0.5" in result.verdict()


def _register_metric_task(name: str, metric, value, info=lambda job: {}) -> None:
    """A bench task on synthetic data (for compare over real bench folders): ``metric`` a name, reported as
    ``value(job)``, or a tuple of ``Metric`` reported as the dict ``value(job)`` returns; ``info(job)`` its info."""
    from lidarkit.bench import Metric, Task, TaskOutput, register_task

    one = isinstance(metric, str)

    class MetricTask(Task):
        dataset_kinds = ("synthetic",)
        metrics = (Metric(metric, metric),) if one else tuple(metric)

        def validate_options(self, options):
            pass

        def validate_dataset(self, dataset, options):
            pass

        def validate(self, method, params, dataset, options):
            pass

        def run(self, job):
            return TaskOutput(metrics={metric: value(job)} if one else value(job), series={}, info=info(job))

    register_task(name)(MetricTask)


def test_compare_counts_units_not_copies_and_asks_which_task(tmp_path, monkeypatch):
    """A fixed dataset beside a seeded one counted its one value once per seed (12 units, p = 0.0005, from 7
    measurements); a metric two tasks report was pooled into one test (icp_pair pairs/s with odometry frames/s); the
    direction of a task's metric was lost to a process without the task; a null metric read "unknown"; a method whose
    jobs all failed read "not found"."""
    from lidarkit.bench import Metric, load_suite, run_suite
    from lidarkit.bench import tasks as bench_tasks

    def value(job):
        seeded = job.dataset_name == "seeded"
        noise = 0.01 * np.random.default_rng(job.seed).random() if seeded else 0.0
        return (0.1 if job.method == "good" else 0.5) + noise

    _register_metric_task("mixed_data_test_task", "error_m", value)
    _register_metric_task("other_rate_test_task", "error_m", value)
    def recall(job):
        if job.method == "broken":
            raise RuntimeError("broken on purpose")
        return {"recall_x": (0.9 if job.method == "good" else 0.5) + 0.01 * np.random.default_rng(job.seed).random(), "unreported": None}

    _register_metric_task("recall_test_task", (Metric("recall_x", "recall", better="higher"), Metric("unreported", "unreported")), recall)
    (tmp_path / "s.yaml").write_text(textwrap.dedent("""
        seeds: 6
        experiments:
          - {name: e, task: mixed_data_test_task, datasets: [{kind: synthetic, name: fixed, variant: fixed}, {kind: synthetic, name: seeded}], methods: [good, bad]}
          - {name: o, task: other_rate_test_task, dataset: {kind: synthetic, name: seeded}, methods: [good, bad]}
          - {name: r, task: recall_test_task, dataset: {kind: synthetic, name: seeded}, methods: [good, bad, broken]}
    """))
    out = tmp_path / "out"
    run_suite(load_suite(tmp_path / "s.yaml"), out, executor="serial")
    with pytest.raises(ConfigError, match="metric 'error_m' is reported by tasks mixed_data_test_task, other_rate_test_task of "
                                          "these results, each its own experiment: --task picks one"):
        compare(out, out, method_a="good", method_b="bad", metric="error_m")
    mixed = compare(out, out, method_a="good", method_b="bad", metric="error_m", task="mixed_data_test_task")
    assert mixed.n_pairs == 7 and mixed.pairing == "unit" and mixed.p_value == pytest.approx(1 / 64)
    assert "count as one unit" in mixed.note
    with pytest.raises(EvaluationError, match="metric 'unreported' has no value \\(null\\) in any result of good and bad"):
        compare(out, out, method_a="good", method_b="bad", metric="unreported", task="recall_test_task")
    with pytest.raises(DataError, match="method 'broken' has no successful result: its 6 job\\(s\\) here failed"):
        compare(out, out, method_a="good", method_b="broken", metric="recall_x")
    monkeypatch.delitem(bench_tasks._REGISTERED, "recall_test_task")  # read by a process that does not have the task
    monkeypatch.delitem(bench_tasks._INSTANCES, "recall_test_task", raising=False)
    assert not bench_tasks.higher_is_better("recall_x")
    verdict = compare(out, out, method_a="good", method_b="bad", metric="recall_x", task="recall_test_task").verdict()
    assert verdict.startswith("good is better than bad"), verdict
    from lidarkit.bench.report import build_report, summary_rows

    _, rows = summary_rows(build_report(out, plots=False))
    assert next(r for r in rows if r[0] == "recall_test_task")[3] == "good"  # the report's best method too


def test_a_count_flat_on_every_seed_of_seeded_data_is_tested(tmp_path):
    """6 seeds, each another drive: one method failed on no frame, the other on all 7 of every drive. Flat on both sides,
    the count was taken for "one measurement repeated" (no test) though the drives' errors differ by seed; a seed that
    changes another accuracy metric is other data, and the count is tested over the 6 seeds."""
    from lidarkit.bench import Metric, load_suite, run_suite
    from lidarkit.eval import compare

    def metrics(job):
        return {"error_m": 0.1 * (job.method == "good") + 0.2 + 0.05 * np.random.default_rng(job.seed).random(),
                "n_failed_frames": 0 if job.method == "good" else 7, "runtime_s": 0.01}

    _register_metric_task("count_test_task", (Metric("error_m", "error"), Metric("n_failed_frames", "failed frames"),
                                              Metric("runtime_s", "runtime")), metrics)
    (tmp_path / "s.yaml").write_text(textwrap.dedent("""
        seeds: 6
        experiments:
          - {name: e, task: count_test_task, dataset: {kind: synthetic, name: drives}, methods: [good, bad]}
    """))
    run_suite(load_suite(tmp_path / "s.yaml"), tmp_path / "out", executor="serial")
    count = compare(tmp_path / "out", tmp_path / "out", method_a="good", method_b="bad", metric="n_failed_frames")
    assert not count.repeated and count.n_pairs == 6 and count.better == "a" and count.p_value == pytest.approx(1 / 32)

    _register_metric_task("flat_test_task", (Metric("error_m", "error"), Metric("runtime_s", "runtime")),
                          lambda job: {"error_m": 0.1 if job.method == "good" else 0.5, "runtime_s": 0.01 * job.seed})
    (tmp_path / "f.yaml").write_text(textwrap.dedent("""
        seeds: 6
        experiments:
          - {name: e, task: flat_test_task, dataset: {kind: synthetic, name: fixed}, methods: [good, bad]}
    """))
    run_suite(load_suite(tmp_path / "f.yaml"), tmp_path / "flat", executor="serial")
    flat = compare(tmp_path / "flat", tmp_path / "flat", method_a="good", method_b="bad", metric="error_m")
    assert flat.repeated and not flat.significant  # a time that varies is no other data


def test_a_median_ci_with_a_bound_at_0_names_no_winner():
    """5 of 12 seeds tied, 7 worse for A: "b is better ... (95% CI [+0, +2])", a winner beside a CI that includes 0."""
    res = paired_test([3.0] * 5 + [4, 5, 6, 4, 5, 6, 4], [3.0] * 12, name_a="A", name_b="B")
    assert res.p_value < 0.05 and (res.diff_ci_low, res.diff_ci_high) == (0.0, 2.0) and res.better == ""
    assert res.verdict().startswith("no significant difference between A and B on error: the 95% CI of the median "
                                    "difference [+0, +2] includes 0")


def test_the_units_needed_and_p_read_against_alpha():
    """At alpha 0.25, 3 seeds were told "the smallest p is 0.25: at least 3 are needed to reach p < 0.25"; a p of 0.0497
    was printed "p = 0.05" beside a winner at alpha 0.05; one seed per dataset of fixed data was told to add seeds."""
    from lidarkit.eval.statistics import format_p, min_units

    three = paired_test([1.0, 2.0, 3.0], [0.0] * 3, alpha=0.25)
    assert "smallest p this test can give is 0.25: at least 4 are needed to reach p < 0.25" in three.verdict()
    assert [min_units(a) for a in (0.25, 0.125, 0.05, 0.01)] == [4, 5, 6, 8]
    assert (format_p(0.0497, 0.05), format_p(0.04997, 0.05), format_p(0.0312, 0.05), format_p(0.5, 0.05)) == (
        "0.0497", "0.04997", "0.031", "0.5")
    with pytest.raises(EvaluationError) as exc:
        paired_test([1.0], [2.0], pairing="dataset")
    assert str(exc.value) == ("error: a paired test needs at least 2 matched datasets, got 1 (more datasets or sequences: "
                              "2 or more, 6 or more for p < 0.05)")
    assert "more datasets or sequences make one, not more seeds" in paired_test([1.0] * 6, [2.0] * 6).verdict()


def test_arguments_of_the_wrong_kind_are_named_errors():
    """alpha="0.05", noise="0.1" or None, confidence="0.9" were TypeError tracebacks; lower_is_better="no" was read as
    true; n_boot=10**12 a MemoryError; n_boot="100" said "got 100"; summarize(None) "1 non-finite value(s)"."""
    a, b = [1.0, 2.0, 3.0], [2.0, 3.0, 4.5]
    for kwargs, text in (({"alpha": "0.05"}, "alpha: alpha must be a number, got '0.05'"),
                         ({"noise": "0.1"}, "noise: noise must be a number, got '0.1'"),
                         ({"noise": None}, "noise: noise must be a number, got None"),
                         ({"lower_is_better": "no"}, "lower_is_better: lower_is_better must be True or False, got 'no'")):
        with pytest.raises(ConfigError) as exc:
            paired_test(a, b, **kwargs)
        assert str(exc.value) == text
    for kwargs, text in (({"confidence": "0.9"}, "confidence: confidence must be a number, got '0.9'"),
                         ({"n_boot": 10**12}, "n_boot: n_boot must be an integer in [1, 1000000], got 1000000000000"),
                         ({"n_boot": "100"}, "n_boot: n_boot must be an integer in [1, 1000000], got '100'")):
        with pytest.raises(ConfigError) as exc:
            summarize(a, **kwargs)
        assert str(exc.value) == text
    with pytest.raises(ConfigError) as exc:
        summarize(None)
    assert str(exc.value) == "summarize: values must be numbers, got None"
    assert not paired_test(a, b, lower_is_better=np.bool_(False)).lower_is_better  # numpy booleans are booleans


def test_two_kiss_run_folders_at_different_sweep_instants_are_named_as_the_header(tmp_path):
    """kiss (deskewed: the sweep end) against kiss deskew=False (mid) over one bag: the header said "kiss (A)" and
    "kiss (B)", the note "(kiss: end, kiss: mid)", which could not tell which run was scored at which instant."""
    from lidarkit.odometry import run
    from lidarkit.sim.bag_export import export_bag
    from lidarkit.sim.lidar import SimulatedLidarSequence

    sim = dict(scene="street", n_frames=6, n_beams=16, n_azimuths=720, speed_mps=5.0, accel_time_s=0.0)
    bag = export_bag(SimulatedLidarSequence(pose_instant="mid", seed=4, **sim), tmp_path / "run.bag", "rosbag1")
    run(bag, "kiss", out_dir=tmp_path / "kiss")
    run(bag, "kiss", params={"deskew": False}, out_dir=tmp_path / "flat")
    res = compare(tmp_path / "kiss", tmp_path / "flat")
    assert (res.name_a, res.name_b, res.n_pairs) == ("kiss", "kiss(deskew=False)", 5)
    assert res.note.startswith("each run is scored against the ground truth at its own instant of the sweep (kiss: end, "
                               "kiss(deskew=False): mid), over the same dataset and frames")
    # runs that differ in nothing config.yaml records are told apart as A and B
    run(bag, "kiss", out_dir=tmp_path / "again")
    assert (compare(tmp_path / "kiss", tmp_path / "again").name_a, compare(tmp_path / "kiss", tmp_path / "again").name_b) == (
        "kiss (A)", "kiss (B)")


def test_a_p_value_that_underflows_reads_below_a_bound():
    """2500 units, A worse on each: Wilcoxon's p underflows to 0.0, and the verdict read "Wilcoxon p = 0", a p no test
    gives; the report's p column printed "0". Both read "< 1e-300" now; the value stays 0.0."""
    b = np.random.default_rng(2).random(2500)
    res = paired_test(b + 0.5, b + 0.01 * np.random.default_rng(3).random(2500), name_a="A", name_b="B")
    assert res.p_value == 0.0 and res.better == "b" and res.to_dict()["p_value"] == 0.0
    assert ", Wilcoxon p < 1e-300, effect size +1.00, over 2500 paired seeds" in res.verdict()
    from lidarkit.eval.statistics import format_p, p_text

    assert (format_p(0.0, 0.05), format_p(0.0), p_text(0.0), p_text(0.0312, 0.05), p_text(1.0)) == (
        "< 1e-300", "< 1e-300", "p < 1e-300", "p = 0.031", "p = 1")


def test_numpy_scalar_arguments_leave_the_results_json_safe():
    """seed=np.int64(3), confidence=np.float32(0.9) and lower_is_better=np.bool_(True) were stored as given: to_dict()
    failed json.dumps ("Object of type int64 is not JSON serializable")."""
    values = np.array([1.0, 1.4, 0.9, 1.2, 1.1])
    summary = summarize(values, seed=np.int64(3), confidence=np.float32(0.9), n_boot=np.int64(100))
    data = json.loads(json.dumps(summary.to_dict()))
    assert data["seed"] == 3 and data["confidence"] == pytest.approx(0.9) and data["n_boot"] == 100
    assert json.loads(json.dumps(summarize([], seed=np.int64(3)).to_dict()))["seed"] == 3
    comparison = paired_test(values, values + 0.5, lower_is_better=np.bool_(True), repeated=np.bool_(False))
    data = json.loads(json.dumps(comparison.to_dict()))
    assert data["lower_is_better"] is True and data["repeated"] is False
    with pytest.raises(ConfigError, match="repeated: repeated must be True, False or None, got 'no'"):
        paired_test(values, values + 0.5, repeated="no")


def test_values_that_are_not_a_flat_sequence_of_numbers_are_refused():
    """summarize(["1", "2"]) read the text as numbers, and a 2-D array was flattened (its rows pooled as runs)."""
    for values, text in ((["1", "2"], "summarize: values must be numbers, got ['1', '2']"),
                         ([[1.0, 2.0], [3.0, 4.0]], "summarize: values must be a flat sequence of numbers, got an array of "
                                                    "shape (2, 2)"),
                         ([True, False], "summarize: values must be numbers, got [True, False]")):
        with pytest.raises(ConfigError) as exc:
            summarize(values)
        assert str(exc.value) == text
    with pytest.raises(ConfigError, match=r"^a: values must be a flat sequence of numbers, got an array of shape \(3, 1\)$"):
        paired_test(np.ones((3, 1)), np.ones(3))
    assert summarize(np.array([1, 2, 3])).mean == 2.0  # (integers are numbers)


def test_one_diverged_seed_leaves_the_other_seeds_differences_ranked():
    """Ties were within 1e-9 of the largest value of all units: A's last seed diverged to 3e4 made every difference of
    2e-5 a tie, "p = 1; with 1 differing seeds ..." where Wilcoxon over the ten pairs gives p = 0.00195. Each pair is
    tied at its own scale now, and a side's seeds are "one value" at that side's scale only."""
    b = np.random.default_rng(0).uniform(0.04, 0.06, 10)
    a = b + 2e-5  # B better by 2e-5 on every seed
    a[-1] = 3e4  # ... and on A's diverged seed
    res = paired_test(a, b, name_a="A", name_b="B", repeated=False)
    assert res.n_ties == 0 and res.p_value == pytest.approx(sstats.wilcoxon(a, b).pvalue) == pytest.approx(0.001953125)
    assert res.better == "b" and res.verdict().startswith("B is better than A on error: median difference +2e-05")
    # round-off of each pair's own scale is still a tie, beside the diverged seed too
    again = paired_test(a, a * (1 + 1e-12), name_a="A", name_b="A again", repeated=False)
    assert again.n_ties == 10 and again.p_value == 1.0
    # A's seeds differ by 1e-5 (at 0.05), B's one value at 3e4: six measurements, not one repeated (B's scale made
    # A's spread round-off)
    varied = paired_test(0.05 + 2e-6 * np.arange(6), np.full(6, 3e4), name_a="A", name_b="B")
    assert not varied.repeated and varied.better == "a" and varied.p_value == pytest.approx(0.03125)


def test_a_boolean_among_values_is_refused_and_one_differing_unit_is_singular():
    """summarize([1, True, 3]) counted True as 1 (numpy made an integer array of it); a verdict read "with 1 differing
    seeds"."""
    from lidarkit.eval.statistics import paired_test, summarize

    with pytest.raises(ConfigError, match=r"values must be numbers, got \[1, True, 3\]"):
        summarize([1, True, 3])
    assert summarize(np.array([1, 2, 3])).n == 3  # (integer arrays stay numbers)
    with pytest.raises(ConfigError, match=r"a flat sequence of numbers, got an array of shape \(\)"):
        summarize(5)  # (one number: not iterated in search of booleans)
    one = paired_test([0.5, 0.5, 0.5], [0.5, 0.5, 0.4], pairing="seed")
    assert "with 1 differing seed the smallest p" in one.verdict()
