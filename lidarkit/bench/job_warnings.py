"""The warnings a bench job emits, kept in its result: every WARNING+ record of the job's thread and every
``warnings.warn`` of it, instead of printed over the progress bar (:func:`warnings_captured`)."""

from __future__ import annotations

import collections
import contextlib
import contextvars
import logging
import os
import threading
import warnings
from collections.abc import Iterator
from typing import Any


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


class _JobWarningRouter(logging.Handler):
    """The one root handler while any job runs in this process: a record goes to the capture of the job running in the
    record's thread, else on to the root handlers the process had, as it would have without jobs (several jobs run at
    once in the threads of a dask worker: each swapping the root handlers, they took each other's warnings)."""

    def __init__(self, saved_handlers: list[logging.Handler], saved_root_level: int, package_propagated: bool) -> None:
        super().__init__(level=logging.NOTSET)
        self.saved_handlers = saved_handlers
        self.saved_root_level = saved_root_level
        self.package_propagated = package_propagated

    def handle(self, record: logging.LogRecord) -> bool:  # (no lock of its own: each handler it calls locks itself)
        capture = _JOB_CAPTURE.get()
        if capture is not None:
            if record.levelno >= capture.level:
                capture.handle(record)
            return True
        if not self._reached_root_without_jobs(record):
            return True
        for handler in self.saved_handlers:
            if record.levelno >= handler.level:
                handler.handle(record)
        if not self.saved_handlers and not self._handled_below_root(record) and logging.lastResort is not None \
                and record.levelno >= logging.lastResort.level:
            logging.lastResort.handle(record)
        return True

    def emit(self, record: logging.LogRecord) -> None:  # (never called: handle routes every record)
        pass

    def _reached_root_without_jobs(self, record: logging.LogRecord) -> bool:
        """False for a record of another thread that only comes here through what a job changed: the root level lowered
        to WARNING, the ``lidarkit`` logger made to propagate."""
        logger: logging.Logger | None = logging.getLogger(record.name)
        level = None
        while logger is not None and logger is not logging.root:
            if level is None and logger.level:
                level = logger.level
            if logger.name == "lidarkit" and not self.package_propagated:
                return False
            logger = logger.parent
        return record.levelno >= (self.saved_root_level if level is None else level)

    @staticmethod
    def _handled_below_root(record: logging.LogRecord) -> bool:
        logger: logging.Logger | None = logging.getLogger(record.name)
        while logger is not None and logger is not logging.root:
            if logger.handlers:
                return True
            logger = logger.parent if logger.propagate else None
        return False


#: the capture of the job running in this thread (a context variable: each thread starts without one)
_JOB_CAPTURE: contextvars.ContextVar[_WarningCapture | None] = contextvars.ContextVar("lidarkit_job_capture", default=None)
_ROUTING_LOCK = threading.Lock()
_jobs_running = 0
_routing_state: dict[str, Any] = {}


def _show_warning(message: Warning | str, category: type[Warning], filename: str, lineno: int, file: Any = None,
                  line: str | None = None) -> None:
    """``warnings.showwarning`` while any job runs: a job's warning becomes a ``py.warnings`` record for its capture, another
    thread's is shown as the process showed it before."""
    if _JOB_CAPTURE.get() is None:
        _routing_state["showwarning"](message, category, filename, lineno, file, line)
        return
    logging.getLogger("py.warnings").warning("%s: %s (%s:%d)", category.__name__, message, os.path.basename(filename), lineno)


def _start_routing() -> None:
    """Installed by the first job to start; the root handlers, levels and warning display are kept to put back."""
    root = logging.getLogger()
    package_logger = logging.getLogger("lidarkit")
    saved_handlers = root.handlers[:]
    router = _JobWarningRouter(saved_handlers, root.level, package_logger.propagate)
    _routing_state.update(router=router, root_level=root.level, package_propagate=package_logger.propagate,
                          showwarning=warnings.showwarning, filters=warnings.filters[:])
    for handler in saved_handlers:
        root.removeHandler(handler)
    root.addHandler(router)
    if root.level > logging.WARNING:
        root.setLevel(logging.WARNING)
    package_logger.propagate = True  # (its records reach the capture through the root logger, and only there)
    warnings.showwarning = _show_warning


def _stop_routing() -> None:
    """Put back by the last job to end; a handler a job added to the root logger stays."""
    root = logging.getLogger()
    router = _routing_state["router"]
    added_by_jobs = [h for h in root.handlers if h is not router and h not in router.saved_handlers]
    root.handlers = router.saved_handlers + added_by_jobs
    root.setLevel(_routing_state["root_level"])
    logging.getLogger("lidarkit").propagate = _routing_state["package_propagate"]
    warnings.showwarning = _routing_state["showwarning"]
    warnings.filters[:] = _routing_state["filters"]
    warnings._filters_mutated()  # type: ignore[attr-defined]
    _routing_state.clear()


@contextlib.contextmanager
def warnings_captured() -> Iterator[_WarningCapture]:
    """For the job's length, every WARNING+ record of its thread that reaches the root logger (a custom task's, evo's,
    lidarkit's) and every ``warnings.warn`` of its thread goes to the capture alone: it was only the ``lidarkit`` logger's,
    and the rest printed over the progress bar and were missing from the result. Other threads (other jobs of a threaded
    dask worker, the process's own) keep theirs; once no job runs, the handlers, levels, warning display and filters are
    as they were."""
    global _jobs_running
    capture = _WarningCapture()
    with _ROUTING_LOCK:
        if _jobs_running == 0:
            _start_routing()
        _jobs_running += 1
        # a fresh warnings registry for each job: a warning shown once per place went into the first job of each worker
        # only (this shows such a warning of another thread once more too)
        warnings._filters_mutated()  # type: ignore[attr-defined]
    token = _JOB_CAPTURE.set(capture)
    try:
        yield capture
    finally:
        _JOB_CAPTURE.reset(token)
        with _ROUTING_LOCK:
            _jobs_running -= 1
            if _jobs_running == 0:
                _stop_routing()


__all__ = ["FIRST_WARNINGS_KEPT", "LAST_WARNINGS_KEPT", "warnings_captured"]
