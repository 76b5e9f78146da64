"""The function every executor runs: one job spec in, one JSON-ready record out (never raises for job errors)."""

from __future__ import annotations

import collections
import contextlib
import logging
import os
import socket
import time
import traceback
import warnings
from collections.abc import Iterator
from datetime import datetime, timezone
from typing import Any

from lidarkit.bench.jobs import Job


def _utc_now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="milliseconds")


#: warnings a job's result keeps: its first ones and its last ones (a run's closing summary comes last)
FIRST_WARNINGS_KEPT = 40
LAST_WARNINGS_KEPT = 10


class _WarningCapture(logging.Handler):
    """Collects the WARNING+ log messages a job emits: the first :data:`FIRST_WARNINGS_KEPT` and the last
    :data:`LAST_WARNINGS_KEPT`, with a line counting those between (it kept the first 50 and dropped the rest without a
    word, a run's closing summary among them)."""

    def __init__(self) -> None:
        super().__init__(level=logging.WARNING)
        self.first: list[str] = []
        self.last: collections.deque[str] = collections.deque(maxlen=LAST_WARNINGS_KEPT)
        self.n_dropped = 0

    def emit(self, record: logging.LogRecord) -> None:
        message = f"{record.levelname} {record.name}: {record.getMessage()}"
        if len(self.first) < FIRST_WARNINGS_KEPT:
            self.first.append(message)
            return
        if len(self.last) == self.last.maxlen:
            self.n_dropped += 1
        self.last.append(message)

    @property
    def messages(self) -> list[str]:
        """The kept warnings in the order they came, the count of those not kept where they were."""
        dropped = [f"... and {self.n_dropped} more warning{'s' if self.n_dropped != 1 else ''}, not kept (the job's first {FIRST_WARNINGS_KEPT} and last "
                   f"{LAST_WARNINGS_KEPT} are)"] if self.n_dropped else []
        return self.first + dropped + list(self.last)


@contextlib.contextmanager
def _warnings_captured() -> Iterator[_WarningCapture]:
    """For the job's length, every WARNING+ record that reaches the root logger (a custom task's, evo's, lidarkit's) and
    every ``warnings.warn`` goes to the capture alone: it was only the ``lidarkit`` logger's, and the rest printed over
    the progress bar and were missing from the result. The serial executor runs jobs in the main process: its handlers,
    levels and warning display are put back as they were."""
    capture = _WarningCapture()
    root = logging.getLogger()
    package_logger = logging.getLogger("lidarkit")
    saved_handlers, saved_level, saved_propagate = root.handlers[:], root.level, package_logger.propagate
    for handler in saved_handlers:
        root.removeHandler(handler)
    root.addHandler(capture)
    if root.level > logging.WARNING:
        root.setLevel(logging.WARNING)
    package_logger.propagate = True  # (its records reach the capture through the root logger, and only there)

    def show_warning(message: Warning | str, category: type[Warning], filename: str, lineno: int, *_: Any, **__: Any) -> None:
        logging.getLogger("py.warnings").warning("%s: %s (%s:%d)", category.__name__, message, os.path.basename(filename), lineno)

    try:
        # a fresh warnings registry for each job: a warning shown once per place went into the first job of each worker only
        with warnings.catch_warnings():
            warnings.showwarning = show_warning
            yield capture
    finally:
        root.removeHandler(capture)
        added_by_job = [h for h in root.handlers if h not in saved_handlers]
        root.handlers = saved_handlers + added_by_job
        root.setLevel(saved_level)
        package_logger.propagate = saved_propagate


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
    with _warnings_captured() as capture:  # a job's warnings go into its result, not over the progress bar
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
