"""The function every executor runs: one job spec in, one JSON-ready record out (never raises for job errors)."""

from __future__ import annotations

import os
import socket
import time
import traceback
from datetime import datetime, timezone
from typing import Any

from lidarkit.bench.job_warnings import warnings_captured
from lidarkit.bench.jobs import Job


def _utc_now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="milliseconds")


def execute_job(spec: dict[str, Any]) -> dict[str, Any]:
    """Run the job described by ``spec`` (``Job.spec()``, plus ``task_module`` for a task registered in code: the
    module this process imports to know the task); a raising job gives ``status="failed"`` with its error."""
    from lidarkit.bench.results import malformed
    from lidarkit.bench.tasks import get_task
    from lidarkit.errors import DataError
    from lidarkit.eval.report import json_safe

    started = _utc_now()
    t0 = time.perf_counter()
    record: dict[str, Any] = {"status": "ok", "metrics": {}, "series": {}, "info": {}, "error": None}
    with warnings_captured() as capture:  # a job's warnings go into its result, not over the progress bar
        try:
            job = Job.from_spec({k: v for k, v in spec.items() if k != "task_module"})
            task = get_task(job.task, module=spec.get("task_module"))
            output = task.run(job)
            metrics = json_safe(output.metrics)
            # a metric no reader takes (text, an array) fails the job: recorded "ok", it was never read back and the job
            # ran again on every resume
            problem = malformed({"job": job.spec(), "status": "ok", "metrics": metrics})
            if problem:
                raise DataError(f"{problem} (a task's metrics are numbers, or None where not defined)", source=f"task {job.task}")
            record["metrics"] = metrics
            # the direction of each metric as the task declares it, kept with the result: a process that reads the results
            # without the task (a task registered in the script that ran the suite) took every metric as lower-is-better
            record["higher_is_better"] = sorted(m.name for m in task.metrics if m.better == "higher")
            # its speed metrics too: they vary from run to run on the same data, and compare must not read that as seeds
            # running other data (a task's ``latency_ms`` is no name a pattern knows)
            record["speed_metrics"] = sorted(m.name for m in task.metrics if m.kind == "speed")
            # and their labels in the task's order (a list: results are written with sorted keys), so that a report without
            # the task heads its table with the task's first accuracy metric, not the first name in the alphabet
            record["metric_labels"] = [[m.name, m.label] for m in task.metrics]
            # and its sweep plots ([param, metric] pairs), so that a report without the task still draws them
            record["sweep_plots"] = [[str(param), str(metric)] for param, metric in task.sweep_plots]
            record["series"] = json_safe(output.series)
            record["info"] = json_safe(output.info)
        except Exception as err:  # a job's failure is data, not a crash of the suite
            record["status"] = "failed"
            record["error"] = {
                "type": type(err).__name__,
                "message": str(err),
                "traceback": traceback.format_exc(limit=8),
            }
    record["warnings"] = capture.messages
    record["runtime_s"] = time.perf_counter() - t0
    record["started_utc"] = started
    record["finished_utc"] = _utc_now()
    record["host"] = socket.gethostname()
    record["pid"] = os.getpid()
    return record
