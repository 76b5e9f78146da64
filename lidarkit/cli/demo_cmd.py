"""``lidarkit demo`` (what ``make demo`` runs): the bundled benchmark suite on the bundled samples and the
simulators, the evaluation of the bundled KITTI 00 trajectories, then the report's path and a summary table."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from lidarkit.cli.app import app, stderr, stdout
from lidarkit.cli.bench_cmd import PROGRESS_HELP, check_report_targets, print_run_summary, run_with_progress, summary_table
from lidarkit.errors import ConfigError


@app.command("demo")
def demo_command(
    out_dir: Path = typer.Option(Path("results/demo"), "--out", "-o", help="Results folder (resumable: finished jobs are kept)."),
    quick: bool = typer.Option(False, "--quick", help="The reduced suite (seconds instead of minutes)."),
    executor: str = typer.Option("process", "--executor", "-e",  # (no --address: bench's help sent users to it)
                                 help="serial | process (local process pool sized to the machine's CPUs) | "
                                      "dask (a local Dask cluster)"),
    workers: Optional[int] = typer.Option(None, "--workers", "-j", help="Worker processes (default: CPUs available)."),
    force: bool = typer.Option(False, "--force", help="Rerun jobs that already have a result."),
    suite: Optional[Path] = typer.Option(None, "--suite", help="Run this suite instead of the bundled demo suite."),
    progress: bool = typer.Option(True, "--progress/--no-progress", help=PROGRESS_HELP),
) -> None:
    """Run the bundled demo: ICP variants (real KITTI pair, simulated sequence), particle filter MSE vs particles,
    visual odometry on the sample frames, and the evaluation of bundled trajectories; print where the report is."""
    from lidarkit.bench.demo import run_demo
    from lidarkit.eval import report as eval_report
    from lidarkit.eval.demo import EVO_REFERENCE_APE_RMSE_M, run_eval_demo

    console, err = stdout(), stderr()
    from lidarkit.atomic import check_target

    check_target(out_dir, "folder")  # (a file there failed later: "cannot write the results folder (File exists)")
    check_report_targets(out_dir)  # (a file named tables failed once every job had run)
    for name in ("eval", "eval/inputs"):  # (the evaluation's folders, written after the jobs)
        check_target(out_dir / name, "folder")
    if quick and suite is not None:  # (--quick picks a bundled suite: with --suite it was ignored without a word)
        raise ConfigError("--quick selects the reduced bundled suite; with --suite FILE that file runs: give one of them",
                          source="--quick")

    def runner(suite_obj, out, *, executor, workers, force):
        return run_with_progress(suite_obj, out, executor=executor, workers=workers, address=None, force=force,
                                 progress=progress)

    result = run_demo(out_dir, quick=quick, suite_path=suite, executor=executor, workers=workers, force=force, runner=runner)
    for experiment, reason in result.skipped:
        err.print(f"skipped {experiment}: {reason}", soft_wrap=True)
    evaluation_result = run_eval_demo(out_dir / "eval")  # (written before anything is printed, as the bench's report)
    print_run_summary(result.summary)

    for evaluation in evaluation_result.evaluations:
        console.print(eval_report.evaluation_table(evaluation))
        if evaluation.drift is not None:
            console.print(eval_report.drift_table(evaluation))
        console.print(
            f"APE translation rmse {evaluation.ape.rmse:.4f} m; evo's stored reference result: {EVO_REFERENCE_APE_RMSE_M:.4f} m"
        )

    if result.report is not None:
        for table in summary_table(result.report):
            console.print(table)
        publication = getattr(result.report, "publication", None)
        for dataset, comparison in getattr(publication, "comparisons", []) or []:  # (with its note: segments overlap)
            note = f" (note: {comparison.note})" if comparison.note else ""
            console.print(f"{dataset}: {comparison.verdict()}{note}", soft_wrap=True, markup=False)
        console.print(f"report: {result.report.html_path}  (also report.md, report.csv)", soft_wrap=True)
    else:
        console.print("no benchmark experiment could run (see the skipped list above)")
