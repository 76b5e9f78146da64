"""``lidarkit compare RUN_A RUN_B``: paired significance test of two runs (odometry run folders or bench results)."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from lidarkit import atomic
from lidarkit.cli.app import app
from lidarkit.cli.outputs import results_console
from lidarkit.errors import ConfigError
from lidarkit.eval.statistics import DEFAULT_ALPHA, p_text


@app.command("compare")
def compare_command(
    run_a: Path = typer.Argument(..., help="Odometry run folder (lidarkit odometry --out) or bench results folder (runs over a CARMEN log: its bench results only)."),
    run_b: Path = typer.Argument(..., help="The run to compare with (same kind and same data as RUN_A)."),
    metric: Optional[str] = typer.Option(
        None, help="Run folders: segment_translation_pct | segment_rotation_deg_per_100m | rpe_translation_m | "
        "rpe_rotation_deg; bench folders: a job metric (default: the task's headline metric, the one its report ranks by: "
        "odometry ape_se3_rmse_m, pf mse_m2, vo ape_rmse_m, icp_pair translation_error_m)."),
    method_a: Optional[str] = typer.Option(None, "--method-a", help="Method label in RUN_A when it holds several."),
    method_b: Optional[str] = typer.Option(None, "--method-b", help="Method label in RUN_B when it holds several."),
    alpha: float = typer.Option(DEFAULT_ALPHA, help="Significance level of the Wilcoxon signed-rank test."),
    noise: float = typer.Option(0.0, help="Run-to-run noise of the metric (its unit): smaller differences are not called."),
    noise_from: Optional[Path] = typer.Option(
        None, "--noise-from", help="Bench result folders only: a baseline folder (lidarkit baseline record) to take --noise from, the band it measured "
        "for the metric (the widest over its jobs of the compared task, and methods when pinned; with --noise too, the larger)."),
    seed: int = typer.Option(0, "--seed", help="Seed of the bootstrap CI of the difference."),
    json_out: Optional[Path] = typer.Option(None, "--json", help="Write the comparison as JSON here."),
    every_result: bool = typer.Option(False, "--all", help="Bench folders: every result in the folder, not only the jobs of its suite.json (as its report)."),
    task: Optional[str] = typer.Option(None, "--task", help="Bench folders: compare the units of this task (needed when several tasks report the metric)."),
    experiment: Optional[str] = typer.Option(
        None, "--experiment", help="Bench folders: compare the units of this experiment, or A_NAME,B_NAME for each side's own (needed when a method's experiments of the task ran the same dataset and seed)."),
) -> None:
    """Pair RUN_A and RUN_B on the same units (KITTI segments, frames or seeds) and test the difference (Wilcoxon)."""
    from lidarkit.eval.compare import compare

    _outside_inputs(json_out, {"RUN_A": run_a, "RUN_B": run_b, "--noise-from": noise_from})
    atomic.check_target(json_out, "file")  # (--json FOLDER failed after the comparison)
    result = compare(run_a, run_b, metric=metric, method_a=method_a, method_b=method_b, alpha=alpha, noise=noise,
                     noise_from=noise_from, seed=seed, every_result=every_result, task=task,
                     experiment=experiment)
    # (stderr when --json is stdout: `--json /dev/stdout | jq` read the table after the JSON; chosen before the JSON is
    # written, a file renamed over being no longer fd 1's)
    console = results_console([json_out])
    if json_out is not None:  # (before printing: `| head -1` or a full disk on stdout lost it, exit 1)
        from lidarkit.eval.report import write_json

        # (the folders compared: a saved comparison of two runs of one method could not say which was which)
        write_json({"run_a": str(Path(run_a).absolute()), "run_b": str(Path(run_b).absolute()), **result.to_dict()}, json_out)
    console.print(f"A: {result.name_a}   B: {result.name_b}   metric: {result.metric_text} ({result.n_pairs} paired "
                  f"{result.pairing}s, {result.n_ties} ties)", soft_wrap=True)
    console.print(f"mean A {result.mean_a:.6g}   mean B {result.mean_b:.6g}   A - B: mean {result.mean_diff:+.4g}, "
                  f"median {result.median_diff:+.4g}, 95% CI [{result.diff_ci_low:+.4g}, {result.diff_ci_high:+.4g}]",
                  soft_wrap=True)
    if not result.repeated:  # (one measurement repeated: no test is made, and a p-value printed read as one)
        console.print(f"Wilcoxon signed-rank: statistic {result.statistic:g}, {p_text(result.p_value)}; "
                      f"effect size (rank-biserial) {result.effect_size:+.3f}", soft_wrap=True)
    console.print(result.verdict(), soft_wrap=True, markup=False)
    if noise_from is not None or result.noise:  # (a baseline's band was applied without a word, deciding or not)
        source = "--noise" if noise_from is None else f"the band {noise_from} recorded" + (" or --noise, the larger" if noise else "")
        console.print(f"noise: differences within ±{result.noise:.4g} are run-to-run noise ({source})", soft_wrap=True, markup=False)
    if result.note:
        console.print(f"note: {result.note}", soft_wrap=True, markup=False)
    if json_out is not None:
        console.print(f"wrote {json_out}", soft_wrap=True)


def _outside_inputs(out: Optional[Path], folders: dict[str, Optional[Path]]) -> None:
    """ConfigError when ``--json`` lies in a folder compare reads: `--json A/suite.json` replaced A's manifest with exit 0
    (the next compare pooled an earlier suite's results), `A/metrics.json` a run's metrics, `BASELINE/manifest.json` a baseline."""
    if out is None:
        return
    target = atomic.resolved_path(out, output=True)  # (a loop of symbolic links was a RuntimeError traceback)
    for name, folder in folders.items():
        read = None if folder is None else atomic.resolved_path(folder, output=False)
        if read is not None and (target == read or read in target.parents):
            raise ConfigError(f"{out} is inside {folder} ({name}): compare never writes into a folder it reads", source="--json")
