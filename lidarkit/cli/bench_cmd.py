"""``lidarkit bench SUITE.yaml`` (run a benchmark suite) and ``lidarkit report DIR`` (tables + HTML from results)."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn
from rich.markup import escape
from rich.table import Table

from lidarkit.cli.app import app, stderr, stdout
from lidarkit.errors import ConfigError, LidarKitError

EXECUTOR_HELP = "serial | process (local process pool sized to the machine) | dask (--address, or a local Dask cluster)"
PROGRESS_HELP = "Progress bar on stderr (a line every tenth of the jobs where stderr is no terminal)."


class _LineProgress:
    """The progress bar's interface where no bar can be drawn (stderr to a log, CI): a line at every tenth of the jobs
    and at least every 30 s (nothing was printed until the end), failures one line each."""

    def __init__(self, console):
        self.console = console
        self._lines = None

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def add_task(self, description: str, total=None, **fields) -> int:
        self._description = description
        return 0

    def update(self, task: int, total: int | None = None, advance: int = 0, **fields) -> None:
        from lidarkit.progress import ProgressLines

        if total is not None:
            self._lines = ProgressLines(total, self._description, "jobs")
        if advance and self._lines is not None:
            self._lines.advance(task, advance)

    def stop(self) -> None:
        pass


class _NoProgress(_LineProgress):
    """``--no-progress``: neither bar nor progress lines; failed and skipped jobs are still said, one line each."""

    def update(self, task: int, total: int | None = None, advance: int = 0, **fields) -> None:
        pass


def progress_bar(show: bool = True):
    """Rich progress bar with ETA on stderr (results go to stdout); progress lines where stderr is no terminal;
    neither with ``show=False``."""
    if not show:
        return _NoProgress(stderr())
    if not stderr().is_terminal:
        return _LineProgress(stderr())
    return Progress(
        TextColumn("{task.description}", style="bold", markup=False),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[failed]} failed"),
        TimeElapsedColumn(),
        TextColumn("ETA"),
        TimeRemainingColumn(),
        console=stderr(),
        transient=False,
    )


def run_with_progress(suite, out: Path, *, executor: str, workers: int | None, address: str | None, force: bool,
                      progress: bool = True):
    """Run ``suite`` into ``out`` showing a progress bar (none without ``progress``); Ctrl-C / SIGTERM say how to
    resume and exit 130 / 143."""
    from lidarkit.bench.executors import check_executor_args
    from lidarkit.lifetime import Interrupted, interrupt_handled
    from lidarkit.bench.runner import run_suite

    check_executor_args(executor, workers, address, cli=True)  # (named as `lidarkit demo` takes them, too)
    err = stderr()
    with progress_bar(progress) as progress:
        bar = progress.add_task(suite.name, total=None, failed=0)
        failed = 0

        def on_start(n_todo: int, n_skipped: int) -> None:
            progress.update(bar, total=n_todo)
            if n_skipped:
                progress.console.print(f"{n_skipped} job(s) already finished in {out}: skipped (use --force to rerun)")

        def on_result(job, record) -> None:
            nonlocal failed
            if record["status"] != "ok":
                failed += 1
                error = record.get("error") or {}
                text = f"{job.method_label} on {job.dataset_name} (seed {job.seed}): {error.get('type')}: {error.get('message')}"
                progress.console.print(f"[red]failed[/red] {escape(text)}", markup=True, soft_wrap=True)
            progress.update(bar, advance=1, failed=failed)

        try:
            return run_suite(suite, out, executor=executor, workers=workers, address=address, force=force,
                             on_start=on_start, on_result=on_result)
        except (KeyboardInterrupt, Interrupted) as stop:
            interrupt_handled()
            progress.stop()
            what = f"by {stop}" if isinstance(stop, Interrupted) else "by SIGINT"
            stale = f"; {_stale_report(out)}"
            again = ("run the command again without --force to resume (with it, every job runs again)" if force
                     else "run the same command again to resume")
            from lidarkit.bench.results import JOBS_DIR

            jobs = out / JOBS_DIR  # (it named a jobs/ folder that did not exist when no job had finished yet)
            kept = jobs.is_dir() and any(not p.name.startswith(".") for p in jobs.glob("*.json"))
            err.print(f"interrupted {what}: " + (f"finished results are kept in {out}/jobs" if kept else "no job had finished yet")
                      + f"; {again}"
                      + (stale if (out / "report.html").exists() else ""), soft_wrap=True)
            raise typer.Exit(getattr(stop, "exit_code", 130)) from None


def _stale_report(out: Path) -> str:
    if not (out / "report.html").is_file():  # (a folder of that name is not a report)
        return f"no report was written (`lidarkit report {out}` writes it from the finished jobs)"
    return f"{out}/report.html is from before this run (`lidarkit report {out}` rebuilds it from the finished jobs)"


def write_report(out: Path, only_keys: set[str]):
    """``build_report`` of the run just ended; Ctrl-C / SIGTERM while it writes say the jobs are done but the report
    is not this run's (the earlier one stayed without a word) and exit 130 / 143; a report that cannot be written (a
    full disk) says the same in its one line (it named the file only)."""
    from lidarkit.bench.report import build_report
    from lidarkit.errors import OutputError
    from lidarkit.lifetime import Interrupted, interrupt_handled

    html = out / "report.html"

    def version() -> tuple[int, int] | None:  # a report moved in is a new file (another inode)
        return (html.stat().st_ino, html.stat().st_mtime_ns) if html.exists() else None

    def state() -> str:
        if version() != before:  # moved in before the signal or failure came: that finished first
            return f"the report was written ({html})"
        if before is not None:
            return _stale_report(out)
        return f"no report was written (`lidarkit report {out}` writes it from the finished jobs)"

    before = version()
    try:
        return build_report(out, only_keys=only_keys)
    except OutputError as err:
        raise OutputError(f"{err.reason}; every job of the run is done (results in {out}/jobs); {state()}",
                          source=err.source, location=err.location) from None
    except (KeyboardInterrupt, Interrupted) as stop:
        interrupt_handled()
        what = f"by {stop}" if isinstance(stop, Interrupted) else "by SIGINT"
        stderr().print(f"interrupted {what} while the report was written: every job of the run is done "
                       f"(results in {out}/jobs); {state()}", soft_wrap=True)
        raise typer.Exit(getattr(stop, "exit_code", 130)) from None


def print_run_summary(summary) -> None:
    out = stdout()
    out.print(f"{summary.total} jobs: {summary.skipped} already done, {summary.ran} run now "
              f"({summary.ok} ok, {summary.failed} failed) in {summary.wall_s:.1f} s", soft_wrap=True)
    for key, label, error in summary.failures[:20]:
        out.print(f"  failed {key}: {label}: {error}", soft_wrap=True)
    if len(summary.failures) > 20:  # (the list stopped at 20 without a word)
        out.print(f"  ... and {len(summary.failures) - 20} more failed jobs (the report lists every one)", soft_wrap=True)


def summary_table(report, max_metrics: int = 2) -> list[Table]:
    """Short rich tables (the first accuracy metrics, each dataset's headline among them, + one speed figure) of a
    built report, one per task."""
    from lidarkit.bench.report import format_stat, headline_metrics

    tables = []
    for task_table in report.tables:
        accuracy = [m for m in task_table.metrics if m.kind == "accuracy"][:max_metrics]
        # (a CARMEN log beside a KITTI sequence: its relations columns, not dashes under the first two APE ones)
        headlines = {m.name for m in headline_metrics(task_table).values()}
        accuracy += [m for m in task_table.metrics if m.name in headlines and m not in accuracy]
        speed = [m for m in task_table.metrics if m.kind == "speed"][:1]
        metrics = accuracy + speed
        table = Table(title=f"{task_table.task} (mean ± std over seeds)", title_justify="left")
        show_failed = any(row.n_failed for row in task_table.rows)  # the run summary line already counts them
        table.add_column("dataset", overflow="fold", max_width=14)
        table.add_column("method", overflow="fold", ratio=1)
        if show_failed:
            table.add_column("ok/failed", no_wrap=True)
        for m in metrics:
            table.add_column(m.label, justify="right")
        for row in task_table.rows:
            cells = [format_stat(row.stats[m.name], digits=3) for m in metrics]
            counts = [f"{row.n_ok}/{row.n_failed}"] if show_failed else []
            table.add_row(row.dataset, row.method, *counts, *cells)
        tables.append(table)
    return tables


def check_report_targets(out: Path) -> None:
    """Refuse the report's files and folders under ``out`` before any job runs (a folder named report.html, a file
    named tables, were found after every job had run)."""
    from lidarkit.atomic import check_target
    from lidarkit.bench.publication import TABLES_DIR

    for name in ("report.html", "report.md", "report.csv"):
        check_target(out / name, "file")
    for folder in ("plots", TABLES_DIR):
        check_target(out / folder, "folder")


@app.command()
def bench(
    suite_file: Path = typer.Argument(..., help="Suite YAML file (see docs/benchmarks.md)."),
    out: Optional[Path] = typer.Option(None, "--out", "-o", help="Results folder (default: results/<suite file stem>)."),
    executor: str = typer.Option("process", "--executor", "-e", help=EXECUTOR_HELP),
    workers: Optional[int] = typer.Option(None, "--workers", "-j", help="Worker processes, never more than the jobs to run (default: CPUs available; a local Dask cluster: at most 2)."),
    address: Optional[str] = typer.Option(None, "--address", help="Dask scheduler address, e.g. tcp://HOST:8786."),
    force: bool = typer.Option(False, "--force", help="Rerun jobs that already have a result."),
    report: bool = typer.Option(True, "--report/--no-report", help="Write the report when the run ends."),
    dry_run: bool = typer.Option(False, "--dry-run", help="Validate and list the jobs, run nothing."),
    data: Optional[Path] = typer.Option(None, "--data", help="`bench kitti` only: the KITTI odometry root (sequences/, poses/)."),
    methods: Optional[str] = typer.Option(None, "--methods", help="`bench kitti` only: comma-separated variants (default: the bundled strong ones)."),
    sequences: Optional[str] = typer.Option(None, "--sequences", help="`bench kitti` only: comma-separated sequences (default 00-10)."),
    max_jobs: int = typer.Option(100_000, "--max-jobs", help="Refuse a suite that expands to more jobs."),
    progress: bool = typer.Option(True, "--progress/--no-progress", help=PROGRESS_HELP),
) -> None:
    """Run a benchmark suite: validate it, expand it into jobs, run the unfinished ones, write one JSON per job.

    `lidarkit bench kitti --data ROOT` runs the bundled KITTI suite (sequences 00-10 x strong variants) and prints
    the KISS-ICP-paper table (drift per sequence with the devkit average row)."""
    from lidarkit.bench.suite import load_suite

    from lidarkit.atomic import check_target
    from lidarkit.bench.executors import check_executor_args
    from lidarkit.bench.runner import check_results_folder

    check_executor_args(executor, workers, address, cli=True)  # before anything, a dry run included
    if max_jobs < 1:  # (as --workers: typer's min=1 exited 2 with its own usage wording)
        raise ConfigError(f"must be >= 1, got {max_jobs}", source="--max-jobs")
    kitti = str(suite_file) == "kitti" and not suite_file.exists()
    if kitti:
        from lidarkit.bench.kitti import kitti_suite

        if data is None:
            raise ConfigError("`lidarkit bench kitti` needs --data /path/to/kitti/dataset", source="--data")
        out = out or Path("results") / "kitti"
        check_target(out, "folder")
        check_results_folder(out)  # before the suite is written there
        split = (lambda text: [x.strip() for x in text.split(",") if x.strip()] if text else None)
        suite = kitti_suite(data, None if dry_run else out, methods=split(methods), sequences=split(sequences))
    else:
        given = [name for name, value in (("--data", data), ("--methods", methods), ("--sequences", sequences))
                 if value is not None]  # (it blamed --data when only --methods was given)
        if given:
            raise ConfigError(("applies" if len(given) == 1 else "apply") + " to `lidarkit bench kitti` only",
                              source=", ".join(given))
        suite = load_suite(suite_file, max_jobs=max_jobs)
    out = out or Path("results") / suite_file.stem
    check_target(out, "folder")
    check_results_folder(out)  # (a dry run included)
    check_report_targets(out)
    if dry_run:
        from lidarkit.bench.results import is_finished

        # done: a result is there and the run skips the job; with --force it runs again ("rerun", not "yes")
        table = Table(title=f"{suite.name}: {len(suite.jobs)} jobs" + (" (--force: every job runs)" if force else ""))
        table.add_column("key", no_wrap=True, min_width=20)
        for col in ("task", "dataset", "method", "seed", "done"):
            table.add_column(col, overflow="fold")
        for job in suite.jobs:
            key = job.key()
            done = ("rerun" if force else "yes") if is_finished(out, key) else ""
            table.add_row(key, job.task, job.dataset_name, job.method_label, str(job.seed), done)
        stdout().print(table)
        return
    summary = run_with_progress(suite, out, executor=executor, workers=workers, address=address, force=force,
                                progress=progress)
    # the report is written before anything is printed (a stdout that refuses the summary lost it); one that cannot be
    # written still leaves the jobs' summary above its error
    try:
        built = write_report(out, {job.key() for job in suite.jobs}) if report else None
    except LidarKitError:
        print_run_summary(summary)
        raise
    print_run_summary(summary)
    if built is not None:
        if kitti:
            from lidarkit.bench.kitti import paper_table

            stdout().print(paper_table(built) or "no sequence long enough for KITTI drift (100 m)", soft_wrap=True,
                           markup=False)
        stdout().print(f"report: {built.html_path}", soft_wrap=True)


@app.command("report")
def report_cmd(
    results_dir: Path = typer.Argument(..., help="Folder written by `lidarkit bench`."),
    title: Optional[str] = typer.Option(None, help="Page title (default: from the suite name)."),
    plots: bool = typer.Option(True, "--plots/--no-plots", help="Draw and embed plots."),
    every_result: bool = typer.Option(
        False, "--all", help="Every result in the folder (default: the jobs of its suite.json, the last suite run there)."
    ),
) -> None:
    """Aggregate a results folder into report.md, report.csv and a self-contained report.html."""
    from lidarkit.bench.report import build_report, coverage_text

    built = build_report(results_dir, title=title, plots=plots, every_result=every_result)
    out = stdout()
    for table in summary_table(built):
        out.print(table)
    out.print(f"{built.n_records} results{coverage_text(built)}, {len(built.failures)} failed; {len(built.plots)} plots", soft_wrap=True)
    out.print(f"markdown: {built.markdown_path}\ncsv: {built.csv_path}\nhtml: {built.html_path}", soft_wrap=True)
    publication = getattr(built, "publication", None)
    if publication is not None and publication.tables:
        out.print(f"publication tables (Markdown, CSV, LaTeX): {built.out_dir / 'tables'}", soft_wrap=True)
