"""``lidarkit baseline record SUITE --out DIR`` and ``lidarkit baseline check DIR``: golden baselines."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from lidarkit.cli.app import app, stderr, stdout

baseline_app = typer.Typer(help="Pin a suite's results under a protocol manifest and check later runs against them.",
                           no_args_is_help=True)
app.add_typer(baseline_app, name="baseline")


@baseline_app.command("record")
def record_command(
    suite_file: Path = typer.Argument(..., help="Suite YAML file (see docs/benchmarks.md)."),
    out: Path = typer.Option(..., "--out", "-o", help="Baseline folder to write: an earlier baseline there is replaced whole, once the new one is complete; a folder holding anything else is refused."),
    repeats: int = typer.Option(3, help="Runs per job; their spread sets each metric's default band."),
) -> None:
    """Run SUITE_FILE REPEATS times and pin trajectories, metrics, bands and the protocol manifest in --out."""
    from lidarkit.bench.baseline import job_name, record
    from lidarkit.errors import ConfigError

    if repeats < 1:  # (the library's error named `repeats`)
        raise ConfigError(f"must be a positive integer, got {repeats}", source="--repeats")
    err = stderr()
    baseline = record(suite_file, out, repeats=repeats,
                      on_job=lambda job, r: err.print(f"run {r + 1}/{repeats}: {job.method_label} on {job.dataset_name}",
                                                      soft_wrap=True, markup=False))
    console = stdout()
    for job in baseline.jobs:
        bands = ", ".join(f"{m} {job['metrics'][m]:.4g} ± {job['bands'][m]:.2g}" for m in job["checked"])
        console.print(f"{job_name(job, baseline.jobs)}: {bands}", soft_wrap=True, markup=False)
    console.print(f"baseline: {baseline.path} ({len(baseline.jobs)} jobs)", soft_wrap=True)


@baseline_app.command("check")
def check_command(
    baseline_dir: Path = typer.Argument(..., help="Folder written by `lidarkit baseline record`."),
    tolerance: Optional[list[str]] = typer.Option(
        None, "--tolerance", "-t", help="METRIC=BAND: absolute band of a metric instead of the recorded one (repeatable)."),
) -> None:
    """Re-run the pinned jobs; exit 1 on a regression, a changed protocol or a failed job (each reported distinctly)."""
    from lidarkit.bench.baseline import check

    err = stderr()
    result = check(baseline_dir, tolerances=tolerance or None,
                   on_job=lambda job: err.print(f"checking {job.method_label} on {job.dataset_name}", soft_wrap=True,
                                                markup=False))
    console = stdout()
    for line in result.lines():
        console.print(line, soft_wrap=True, markup=False)
    verdict = "passed" if result.passed else "FAILED"
    console.print(f"baseline check {verdict}: {result.n_jobs} pinned jobs", soft_wrap=True)
    if not result.passed:
        raise typer.Exit(1)
