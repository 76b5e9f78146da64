"""Benchmark harness: YAML suites expanded into jobs, run on serial / process-pool / Dask executors, resumable, reported.

``load_suite(path) -> Suite`` validates a suite before anything runs; ``run_suite(suite, out_dir,
executor=...)`` writes one JSON result per job atomically and skips finished jobs; ``build_report(out_dir)``
writes Markdown, CSV and a self-contained HTML page. Tasks (``icp_pair``, ``odometry``, ``pf``, ``vo``,
``selftest``) live in :mod:`lidarkit.bench.tasks`.
"""

from lidarkit.bench.jobs import Job
from lidarkit.bench.report import Report, build_report
from lidarkit.bench.runner import RunSummary, run_suite
from lidarkit.bench.suite import Suite, load_suite
from lidarkit.bench.tasks import Metric, Task, TaskOutput, available_tasks, get_task, register_task

__all__ = [
    "Job",
    "Metric",
    "Report",
    "RunSummary",
    "Suite",
    "Task",
    "TaskOutput",
    "available_tasks",
    "build_report",
    "get_task",
    "load_suite",
    "register_task",
    "run_suite",
]
