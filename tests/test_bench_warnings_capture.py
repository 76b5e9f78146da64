"""A job's warnings from any logger, and from ``warnings.warn``, go into its result once, and the process running it keeps
its own logging as it was."""

from __future__ import annotations

import logging
import textwrap
import warnings

from lidarkit.bench.results import load_results
from lidarkit.bench.runner import run_suite
from lidarkit.bench.suite import load_suite


def _warning_task(monkeypatch):
    """A task warning three ways: through its own logger, a third-party library's (evo's) and ``warnings.warn``."""
    from lidarkit.bench import tasks as bench_tasks
    from lidarkit.bench.tasks import Metric, Task, TaskOutput, register_task

    monkeypatch.setattr(bench_tasks, "_REGISTERED", {})
    monkeypatch.setattr(bench_tasks, "_INSTANCES", {})
    own_log = logging.getLogger("my_lab.warning_task")

    @register_task("warning_capture_test_task")
    class WarningTask(Task):
        dataset_kinds = ("synthetic",)
        metrics = (Metric("err_m", "error [m]"),)

        def run(self, job):
            own_log.warning("data looked odd (seed %d)", job.seed)
            logging.getLogger("evo").warning("third-party warning")
            warnings.warn("a UserWarning of the task")
            return TaskOutput(metrics={"err_m": 0.1 * job.seed})


def test_warnings_of_other_loggers_and_warnings_warn_are_stored_once_and_printed_nowhere(tmp_path, monkeypatch, capsys, caplog):
    """Only the ``lidarkit`` logger was captured: a custom task's logger, evo's and ``warnings.warn`` printed over the
    progress bar and were missing from the job's warnings. Both seeds run in this process (serial): each keeps its
    own, the process's handlers, levels and warning display come back as they were, and a process that sends warnings
    to logging itself does not get each twice."""
    _warning_task(monkeypatch)
    suite_path = tmp_path / "suite.yaml"
    suite_path.write_text(textwrap.dedent("""
        seeds: 2
        experiments:
          - {task: warning_capture_test_task, dataset: {kind: synthetic}, methods: [a]}
        """))
    root = logging.getLogger()
    package_logger = logging.getLogger("lidarkit")
    logging.captureWarnings(True)
    try:
        before = (root.handlers[:], root.level, package_logger.handlers[:], package_logger.propagate, warnings.showwarning,
                  warnings.filters[:])
        with caplog.at_level(logging.WARNING):
            summary = run_suite(load_suite(suite_path), tmp_path / "out", executor="serial")
        after = (root.handlers[:], root.level, package_logger.handlers[:], package_logger.propagate, warnings.showwarning,
                 warnings.filters[:])
    finally:
        logging.captureWarnings(False)
    assert summary.ok == 2
    by_seed = {r["job"]["seed"]: r["warnings"] for r in load_results(tmp_path / "out")}
    for seed in (0, 1):
        assert by_seed[seed] == [
            f"WARNING my_lab.warning_task: data looked odd (seed {seed})",
            "WARNING evo: third-party warning",
            "WARNING py.warnings: UserWarning: a UserWarning of the task (test_bench_warnings_capture.py:32)",
        ]
    printed = capsys.readouterr()
    assert not any(word in printed.err + printed.out for word in ("looked odd", "third-party", "UserWarning"))
    assert not [r.getMessage() for r in caplog.records if r.name in ("my_lab.warning_task", "evo", "py.warnings")]
    assert after == before


def test_overlapping_jobs_in_threads_each_keep_their_own_warnings_and_the_process_keeps_its_own(monkeypatch):
    """A dask worker runs several jobs at once in threads: each job swapping the root handlers, one job took the other's
    warnings and a capture stayed on the root logger for good. Two jobs overlap here (a barrier holds both inside their
    capture); the main thread logs and warns meanwhile and its messages go where they went before."""
    import threading

    from lidarkit.bench.job_warnings import warnings_captured

    class Collector(logging.Handler):
        def __init__(self):
            super().__init__(level=logging.WARNING)
            self.messages = []

        def emit(self, record):
            self.messages.append(record.getMessage())

    root = logging.getLogger()
    process_handler = Collector()
    shown_by_process = []
    monkeypatch.setattr(warnings, "showwarning", lambda message, *_args, **_kw: shown_by_process.append(str(message)))
    root.addHandler(process_handler)
    try:
        before = (root.handlers[:], root.level, logging.getLogger("lidarkit").propagate, warnings.showwarning,
                  warnings.filters[:])
        both_inside, both_warned, main_warned = threading.Barrier(3), threading.Barrier(3), threading.Barrier(3)
        captured = {}

        def job(name):
            with warnings_captured() as capture:
                both_inside.wait(timeout=5)
                logging.getLogger("my_lab.threaded_task").warning("from %s", name)
                warnings.warn(f"warned by {name}")
                both_warned.wait(timeout=5)
                main_warned.wait(timeout=5)
                if name == "B":  # B ends last: A's end must not take B's capture away
                    logging.getLogger("my_lab.threaded_task").warning("%s again, after A ended", name)
            captured[name] = capture.messages

        threads = {name: threading.Thread(target=job, args=(name,)) for name in ("A", "B")}
        for thread in threads.values():
            thread.start()
        both_inside.wait(timeout=5)
        both_warned.wait(timeout=5)
        logging.getLogger("my_lab.main").warning("from the main thread")
        warnings.warn("warned by the main thread")
        main_warned.wait(timeout=5)
        threads["A"].join(timeout=5)
        threads["B"].join(timeout=5)
        after = (root.handlers[:], root.level, logging.getLogger("lidarkit").propagate, warnings.showwarning,
                 warnings.filters[:])
    finally:
        root.removeHandler(process_handler)
    for name in ("A", "B"):
        assert captured[name][0] == f"WARNING my_lab.threaded_task: from {name}"
        assert captured[name][1].startswith(f"WARNING py.warnings: UserWarning: warned by {name} (test_bench_warnings_capture.py:")
    assert captured["A"][2:] == []
    assert captured["B"][2:] == ["WARNING my_lab.threaded_task: B again, after A ended"]
    assert process_handler.messages == ["from the main thread"]
    assert shown_by_process == ["warned by the main thread"]
    assert after == before
