"""Run a suite: skip finished jobs, execute the rest on an executor, write each result as it arrives."""

from __future__ import annotations

import contextlib
import fcntl
import json
import logging
import os
import sys
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from lidarkit import atomic
from lidarkit.bench.executors import check_executor_args, make_executor
from lidarkit.bench.jobs import Job
from lidarkit.bench.results import (JOBS_DIR, is_finished, make_record, path_argument, read_result, remove_stale_temp_files,
                                    result_path, write_result)
from lidarkit.lifetime import raise_if_interrupted
from lidarkit.params import is_integer
from lidarkit.bench.suite import Suite
from lidarkit.bench.tasks import task_module
from lidarkit.bench.worker import execute_job
from lidarkit.errors import ConfigError, OutputError

log = logging.getLogger(__name__)


@dataclass
class RunSummary:
    """Counts of one run; ``ran`` = jobs executed now, ``skipped`` = already finished before."""

    out_dir: Path
    total: int
    skipped: int = 0
    ran: int = 0
    ok: int = 0
    failed: int = 0
    wall_s: float = 0.0
    failures: list[tuple[str, str, str]] = field(default_factory=list)  # (key, label, "Type: message")


def job_label(job: Job) -> str:
    return f"{job.experiment} | {job.dataset_name} | {job.method_label} | seed {job.seed}"


def run_suite(
    suite: Suite,
    out_dir: str | Path,
    *,
    executor: str = "process",
    workers: int | None = None,
    address: str | None = None,
    force: bool = False,
    on_start: Callable[[int, int], None] | None = None,
    on_result: Callable[[Job, dict[str, Any]], None] | None = None,
    job_fn: Callable[[dict[str, Any]], dict[str, Any]] = execute_job,
) -> RunSummary:
    """Run every unfinished job of ``suite`` and write ``out_dir/jobs/<key>.json`` for each, atomically.

    ``on_start(n_to_run, n_skipped)`` and ``on_result(job, record)`` let a CLI drive a progress bar.
    Failed jobs are recorded (status "failed", error type and message) and retried on the next run; with ``force``, a
    job that fails where an ok result exists keeps that result, the failure noted in it as ``rerun_failed``.
    """
    from lidarkit.provenance import code_version

    version = code_version()
    if not isinstance(suite, Suite):
        raise ConfigError(f"must be a Suite (load_suite(path) reads one), got {type(suite).__name__} {suite!r}", source="suite")
    out_dir = path_argument(out_dir, "out_dir")
    _check_types(workers, force, on_start=on_start, on_result=on_result)
    if not callable(job_fn):
        raise ConfigError(f"must be a function, got {type(job_fn).__name__} {job_fn!r}", source="job_fn")
    check_executor_args(executor, workers, address)
    _check_task_modules(suite, executor)
    check_results_folder(out_dir)
    t0 = time.perf_counter()
    keyed = [(job.key(version), job) for job in suite.jobs]
    with folder_lock(out_dir):
        by_key = dict(keyed)
        todo = [(key, job) for key, job in keyed if force or not is_finished(out_dir, key)]
        summary = RunSummary(out_dir=out_dir, total=len(keyed), skipped=len(keyed) - len(todo))
        origins = {name: origin for name in sorted({job.task for job in suite.jobs}) if (origin := task_origin(name))}
        # the executor first: a Dask scheduler that cannot be reached left the folder's suite.json replaced by the
        # suite that never ran, and a report of the folder's finished results then failed
        runner = make_executor(executor, workers=workers, address=address) if todo else None
        try:
            _write_manifest(suite, out_dir, keyed, version, origins)
            remove_stale_temp_files(out_dir)
            if on_start is not None:
                on_start(len(todo), summary.skipped)
            if runner is not None:
                for key, outcome in runner.run(job_fn, [(key, _worker_spec(job)) for key, job in todo]):
                    job = by_key[key]
                    record = make_record(job, key, version, outcome)
                    if origins.get(job.task):
                        record["task_module"] = origins[job.task]
                    kept = _earlier_ok(out_dir, key) if force and record["status"] != "ok" else None
                    write_result(out_dir, record if kept is None else {**kept, "rerun_failed": _failure_note(record)})
                    raise_if_interrupted()  # (a Ctrl-C a library swallowed while it loaded: the run stops here, this job kept)
                    summary.ran += 1
                    if record["status"] == "ok":
                        summary.ok += 1
                    else:
                        summary.failed += 1
                        err = record.get("error") or {}
                        kept_note = " (the earlier ok result is kept)" if kept is not None else ""
                        summary.failures.append((key, job_label(job), f"{err.get('type')}: {err.get('message')}{kept_note}"))
                    if on_result is not None:
                        on_result(job, record)
        finally:
            if runner is not None:
                runner.close()
        summary.wall_s = time.perf_counter() - t0
        return summary


def _worker_spec(job: Job) -> dict[str, Any]:
    """The spec a worker runs: with the module of a task registered in code, which a worker process imports (it knew
    only the built-in tasks: every job of a custom task failed with "unknown task" on the process executor)."""
    module = task_module(job.task)
    return job.spec() if module is None else {**job.spec(), "task_module": module}


def task_origin(task: str) -> dict[str, str] | None:
    """Where the task registered in code as ``task`` is defined: ``{"module": name, "folder": the folder its top-level
    package was imported from}`` (no folder for a script's ``__main__``), None for a built-in. Kept with the results so
    that a report, in a process that never imported the module, can import it (it showed bare metric names, and removed
    the sweep figures an earlier report had drawn)."""
    module = task_module(task)
    if module is None:
        return None
    origin = {"module": module}
    file = getattr(sys.modules.get(module), "__file__", None)
    if file:
        path = Path(os.path.abspath(file))
        if module == "__main__":
            origin["script"] = str(path)
        else:
            depth = module.count(".") + (path.stem == "__init__")
            if depth < len(path.parents):
                origin["folder"] = str(path.parents[depth])
    return origin


def _check_task_modules(suite: Suite, executor: str) -> None:
    """ConfigError before any job starts for a task registered where no file holds it (``python -c``, a notebook):
    worker processes cannot import it, and every job failed with "unknown task"."""
    if executor == "serial" or getattr(sys.modules.get("__main__"), "__file__", None):
        return
    for name in sorted({job.task for job in suite.jobs}):
        if task_module(name) == "__main__":
            raise ConfigError(f"{name!r} is registered in __main__ with no file (python -c, a notebook), which worker "
                              "processes cannot import: define it in a module they can import and import that, or "
                              "run with executor=\"serial\"", source="task")


def _earlier_ok(out_dir: Path, key: str) -> dict[str, Any] | None:
    """The ok result already written for ``key``, or None: a ``--force`` rerun that fails (a transient error) replaced
    it with the failure, and the good result was lost."""
    path = result_path(out_dir, key)
    record = read_result(path) if path.exists() else None
    return record if record is not None and record.get("status") == "ok" else None


def _failure_note(record: dict[str, Any]) -> dict[str, Any]:
    """What a failed forced rerun left beside the kept result: its error and when it ran."""
    return {"error": record.get("error"), "started_utc": record.get("started_utc"), "finished_utc": record.get("finished_utc")}


def _check_types(workers: Any, force: Any, **callbacks: Any) -> None:
    """ConfigError naming the argument of a wrong type: force="no" was true (every job ran again), workers="2" a bare
    TypeError, on_start=5 a TypeError once suite.json had been rewritten."""
    if workers is not None and not is_integer(workers):
        raise ConfigError(f"must be an integer, got {type(workers).__name__} {workers!r}", source="workers")
    if not isinstance(force, bool):
        raise ConfigError(f"must be True or False, got {type(force).__name__} {force!r}", source="force")
    for name, callback in callbacks.items():
        if callback is not None and not callable(callback):
            raise ConfigError(f"must be a function (or None), got {type(callback).__name__} {callback!r}", source=name)


LOCK_FILE = ".lidarkit-bench.lock"
#: what a run writes before its suite.json (``lidarkit bench kitti`` its suite first): a folder of these is a new one
RUN_FILES = (LOCK_FILE, "kitti_suite.yaml")


def check_results_folder(out_dir: Path) -> None:
    """OutputError unless ``out_dir`` is missing, empty or a results folder (``suite.json`` or ``jobs/``): a run into a
    folder of other files replaced its report.md and removed its plots/*.png and tables/ of a report's names."""
    if not out_dir.is_dir() or (out_dir / "suite.json").is_file() or (out_dir / JOBS_DIR).is_dir():
        return
    others = sorted(p.name for p in out_dir.iterdir() if p.name not in RUN_FILES)
    if others:
        raise OutputError(f"holds other files ({', '.join(others[:3])}{', ...' if len(others) > 3 else ''}) and no "
                          "results of an earlier run (suite.json, jobs/): give a new or empty folder", source=out_dir)


@contextlib.contextmanager
def folder_lock(out_dir: Path) -> Iterator[None]:
    """Hold ``out_dir`` for one suite run: a second ``lidarkit bench`` on the folder is an OutputError naming the
    process that holds it (two runs ran every job twice, and one's report showed the other's title). The lock is the
    kernel's (``flock``): it goes with the process, even one killed with SIGKILL."""
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        fd = os.open(out_dir / LOCK_FILE, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError as err:
        raise OutputError(f"cannot write the results folder ({err.strerror or err})", source=out_dir) from None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 32, 0).decode(errors="replace").strip() or "?"
            raise OutputError(f"another lidarkit bench is running in this folder (pid {holder}): wait for it to end or give "
                              "another --out", source=out_dir) from None
        try:
            os.ftruncate(fd, 0)
            os.pwrite(fd, str(os.getpid()).encode(), 0)
        except OSError as err:  # (a full disk: a page of traceback)
            raise OutputError(f"cannot write the results folder ({err.strerror or err})", source=out_dir) from None
        yield
    finally:
        os.close(fd)  # (closing the descriptor releases the lock)


def _write_manifest(suite: Suite, out_dir: Path, keyed: list[tuple[str, Job]], version: str,
                    task_modules: dict[str, dict[str, str]]) -> None:
    """``suite.json`` beside the results: the resolved, expanded suite (what was asked, job by job), and where its tasks
    registered in code are defined (:func:`task_origin`)."""
    manifest = {
        "suite": suite.name,
        "description": suite.description,
        "suite_file": str(suite.path) if suite.path else None,
        "lidarkit_version": version,
        "skipped_experiments": [{"experiment": e, "reason": r} for e, r in suite.skipped],
        "jobs": [{"key": key, **job.spec()} for key, job in keyed],
        "task_modules": task_modules,
    }
    atomic.write_text(out_dir / "suite.json", json.dumps(manifest, indent=1, sort_keys=True) + "\n")
