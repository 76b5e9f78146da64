"""``lidarkit baseline record SUITE --out DIR`` and ``lidarkit baseline check DIR``: golden baselines."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Optional

import typer

from lidarkit.cli.app import app, stderr, stdout

baseline_app = typer.Typer(help="Pin a suite's results under a protocol manifest and check later runs against them.",
                           no_args_is_help=True)
app.add_typer(baseline_app, name="baseline")

if TYPE_CHECKING:
    from lidarkit.bench.jobs import Job


def _progress_name(job: Job, jobs: list[Job]) -> str:
    """``kiss on street8``, with the seed and the experiment where the suite runs that method on that dataset in several
    (``kiss on street8 (seed 3)``): the lines of a suite with seeds 0-4 read as one line printed five times."""
    alike = [j for j in jobs if (j.method_label, j.dataset_name) == (job.method_label, job.dataset_name)]
    differ = [f"{field} {getattr(job, field)}" for field in ("seed", "experiment") if len({getattr(j, field) for j in alike}) > 1]
    return f"{job.method_label} on {job.dataset_name}" + (f" ({', '.join(differ)})" if differ else "")


@baseline_app.command("record")
def record_command(
    suite_file: Path = typer.Argument(..., help="Suite YAML file (see docs/benchmarks.md)."),
    out: Path = typer.Option(..., "--out", "-o", help="Baseline folder to write: an earlier baseline there is replaced whole, once the new one is complete; a folder holding anything else is refused."),
    repeats: int = typer.Option(3, help="Runs per job; their spread sets each metric's default band."),
    progress: bool = typer.Option(True, "--progress/--no-progress", help="A line per job run on stderr."),
) -> None:
    """Run SUITE_FILE REPEATS times and pin trajectories, metrics, bands and the protocol manifest in --out."""
    from lidarkit.bench.baseline import job_name, record
    from lidarkit.bench.suite import load_suite
    from lidarkit.errors import ConfigError

    if repeats < 1:  # (the library's error named `repeats`)
        raise ConfigError(f"must be a positive integer, got {repeats}", source="--repeats")
    err = stderr()
    jobs = load_suite(suite_file).jobs  # (record reads it again; the progress lines need all the jobs to name them apart)

    def say_run(job: Job, r: int) -> None:
        err.print(f"run {r + 1}/{repeats}: {_progress_name(job, jobs)}", soft_wrap=True, markup=False)

    baseline = record(suite_file, out, repeats=repeats, on_job=say_run if progress else None)
    console = stdout()
    for job in baseline.jobs:
        bands = ", ".join(f"{m} {job['metrics'][m]:.4g} ± {job['bands'][m]:.2g}" for m in job["checked"])
        band = job.get("trajectory_band")
        if band:  # (a job without ground truth is held on its trajectory: the counts alone said little)
            bands += f"; trajectory within {band['position_m']:.2g} m, {band['rotation_deg']:.2g} deg of the pinned one"
        console.print(f"{job_name(job, baseline.jobs)}: {bands}", soft_wrap=True, markup=False)
    console.print(f"baseline: {baseline.path} ({len(baseline.jobs)} jobs)", soft_wrap=True)


@baseline_app.command("check")
def check_command(
    baseline_dir: Path = typer.Argument(..., help="Folder written by `lidarkit baseline record`."),
    tolerance: Optional[list[str]] = typer.Option(
        None, "--tolerance", "-t", help="METRIC=BAND: absolute band of a metric instead of the recorded one (repeatable; trajectory_m, trajectory_deg: "
             "the trajectory band of jobs without ground truth)."),
    progress: bool = typer.Option(True, "--progress/--no-progress", help="A line per job checked on stderr."),
) -> None:
    """Re-run the pinned jobs; exit 1 on a regression, a changed protocol or a failed job (each reported distinctly)."""
    from lidarkit.bench.baseline import check, load_baseline
    from lidarkit.bench.jobs import Job

    err = stderr()
    jobs = [Job.from_spec(pinned["spec"]) for pinned in load_baseline(baseline_dir).jobs]

    def say_checking(job: Job) -> None:
        err.print(f"checking {_progress_name(job, jobs)}", soft_wrap=True, markup=False)

    result = check(baseline_dir, tolerances=tolerance or None, on_job=say_checking if progress else None)
    console = stdout()
    for line in result.lines():
        console.print(line, soft_wrap=True, markup=False)
    verdict = "passed" if result.passed else "FAILED"
    console.print(f"baseline check {verdict}: {result.n_jobs} pinned jobs", soft_wrap=True)
    if not result.passed:
        raise typer.Exit(1)
