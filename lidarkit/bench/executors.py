"""Executors: run job functions serially, on a local process pool, or on a Dask cluster; yield results as they finish.

All three take ``(key, spec)`` items and a picklable function ``fn(spec) -> dict``; the parent process
consumes ``(key, outcome)`` pairs in completion order and writes the result files. No scheduling of our
own: ``concurrent.futures.ProcessPoolExecutor`` and ``distributed`` do it.
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing
import os
import time
from collections.abc import Callable, Iterator
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import Any

from lidarkit.lifetime import children_shielded, init_worker, mark_abandoned
from lidarkit.errors import ConfigError, LidarKitError

log = logging.getLogger(__name__)

JobFn = Callable[[dict[str, Any]], dict[str, Any]]
Item = tuple[str, dict[str, Any]]

EXECUTORS = ("serial", "process", "dask")
#: how long the dask executor tries to reach a scheduler at an address before it gives up
CONNECT_TIMEOUT_S = 20


def crash_outcome(error_type: str, message: str) -> dict[str, Any]:
    """Outcome for a job whose worker died or whose framework raised (the job function itself never raises)."""
    return {
        "status": "failed",
        "metrics": {},
        "series": {},
        "info": {},
        "error": {"type": error_type, "message": message, "traceback": ""},
        "runtime_s": None,
    }


def default_workers() -> int:
    """Worker count sized to the machine: the CPUs this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


class SerialExecutor:
    """Runs jobs one after another in this process (debugging, overhead baseline)."""

    name = "serial"

    def run(self, fn: JobFn, items: list[Item]) -> Iterator[tuple[str, dict[str, Any]]]:
        for key, spec in items:
            yield key, fn(spec)

    def close(self) -> None:
        pass


class ProcessExecutor:
    """A ``ProcessPoolExecutor`` (forkserver on Linux, spawn elsewhere) sized to the machine.

    A worker that dies (segfault, abort in a C extension) breaks the pool; the jobs it took down are
    re-run one at a time in a fresh single-worker pool so that only the job that really crashes is
    recorded as failed. Workers die with this process (:mod:`lidarkit.bench.lifetime`); an interrupted or
    failing run stops them before returning.
    """

    name = "process"

    def __init__(self, workers: int | None = None, start_method: str | None = None):
        self.workers = workers or default_workers()
        self.context = pool_context(start_method, preload=("lidarkit.bench._forkserver", "lidarkit.bench.worker",
                                                           "lidarkit.bench.tasks", "numpy"))

    def run(self, fn: JobFn, items: list[Item]) -> Iterator[tuple[str, dict[str, Any]]]:
        queue = list(items)
        while queue:
            broken: list[tuple[int, Item]] = []  # (submission order, item) of the jobs the broken pool took down
            pool = self._pool(min(self.workers, len(queue)))
            try:
                futures = {pool.submit(fn, spec): (order, (key, spec)) for order, (key, spec) in enumerate(queue)}
                pending = set(futures)
                while pending:
                    done, pending = wait(pending, return_when=FIRST_COMPLETED)
                    for fut in done:
                        order, (key, spec) = futures[fut]
                        try:
                            outcome = fut.result()
                        except BrokenProcessPool:
                            broken.append((order, (key, spec)))
                            continue
                        except Exception as err:  # e.g. a result that cannot be pickled back
                            outcome = crash_outcome(type(err).__name__, str(err))
                        yield key, outcome
            finally:
                stop_pool(pool)
            if not broken:
                return
            # the pool starts jobs in submission order, and at most one per worker plus one queued had left it: only
            # those can hold the culprit; the rest go to a fresh pool of full size (all of them ran one at a time)
            broken = [item for _, item in sorted(broken, key=lambda b: b[0])]
            in_flight = min(len(broken), self.workers + 1)
            log.warning("a worker process died; re-running the %d job(s) it may have held one at a time, %d other(s) in a new pool",
                        in_flight, len(broken) - in_flight)
            yield from self._run_isolated(fn, broken[:in_flight])
            queue = broken[in_flight:]

    def _run_isolated(self, fn: JobFn, items: list[Item]) -> Iterator[tuple[str, dict[str, Any]]]:
        pool = self._pool(1)
        try:
            for key, spec in items:
                try:
                    outcome = pool.submit(fn, spec).result()
                except BrokenProcessPool as err:
                    outcome = crash_outcome("WorkerCrashed", f"the worker process died while running this job ({err})")
                    stop_pool(pool)
                    pool = self._pool(1)
                except Exception as err:
                    outcome = crash_outcome(type(err).__name__, str(err))
                yield key, outcome
        finally:
            stop_pool(pool)

    def _pool(self, workers: int) -> ProcessPoolExecutor:
        return worker_pool(workers, self.context)

    def close(self) -> None:
        pass


def pool_context(start_method: str | None = None, preload: tuple[str, ...] = ()) -> Any:
    """The multiprocessing context of lidarkit's process pools: forkserver on Linux (``preload`` loaded once in the
    server, if it starts here), spawn elsewhere. The fork server (and Python's resource tracker) starts shielded from
    SIGINT and SIGHUP (:func:`lidarkit.lifetime.children_shielded`): a Ctrl-C to the process group while they load
    would print their KeyboardInterrupt tracebacks, a hang-up end them under the parent's cleanup; workers inherit
    it."""
    if start_method is None:
        start_method = "forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else "spawn"
    context = multiprocessing.get_context(start_method)
    if start_method == "forkserver":
        if preload:
            context.set_forkserver_preload(list(preload))
        from multiprocessing import forkserver

        with children_shielded():
            forkserver.ensure_running()
    return context


def worker_pool(workers: int, context: Any) -> ProcessPoolExecutor:
    """A pool of ``workers`` processes in ``context`` that die with this process (:func:`lidarkit.lifetime.init_worker`)."""
    return ProcessPoolExecutor(max_workers=workers, mp_context=context, initializer=init_worker, initargs=(os.getpid(),))


def stop_pool(pool: ProcessPoolExecutor) -> None:
    """Cancel queued jobs and stop the workers now (an interrupted run loses only the jobs in flight).

    Normal completion: the pool joins its idle workers. Otherwise the workers are terminated (SIGKILL after 2 s);
    if the pool's reader thread stays blocked on a result a worker was killed while sending, the process is
    marked so the CLI exits without waiting on it.
    """
    processes = list((getattr(pool, "_processes", None) or {}).values())
    thread = getattr(pool, "_executor_manager_thread", None)
    pending = bool(getattr(pool, "_pending_work_items", None))
    pool.shutdown(wait=False, cancel_futures=True)
    if not pending:
        for proc in processes:
            proc.join(timeout=5)
    for proc in processes:
        if proc.is_alive():
            proc.terminate()
    deadline = time.monotonic() + 2.0
    for proc in processes:
        proc.join(timeout=max(0.0, deadline - time.monotonic()))
        if proc.is_alive():
            proc.kill()
            proc.join(timeout=2)
    if thread is not None:
        thread.join(timeout=2)
        if thread.is_alive():
            mark_abandoned()


def local_dask_workers(workers: int | None, n_jobs: int) -> int:
    """Worker processes of a local Dask cluster for ``n_jobs`` jobs: ``workers`` (default up to 2), never more than
    the jobs, as the process pool is capped (``--workers 8`` on 2 jobs started 8 processes, 6 of them idle)."""
    return max(1, min(workers or min(2, default_workers()), n_jobs))


class DaskExecutor:
    """Jobs as ``distributed`` futures: on the cluster at ``address`` or on a LocalCluster started when the jobs are
    known (sized to them: :func:`local_dask_workers`) and closed here."""

    name = "dask"

    def __init__(self, address: str | None = None, workers: int | None = None):
        try:
            import distributed
        except ImportError as err:  # pragma: no cover - dependency of lidarkit
            raise ConfigError(f"the dask executor needs dask[distributed] ({err})", source="--executor") from err
        self._distributed = distributed
        self.address = address
        self.workers = workers
        self.cluster = None
        self.client = None
        # the client logs each failed reconnect with its traceback: a lost scheduler is reported once, by run()
        self._client_log = logging.getLogger("distributed.client")
        self._client_level = self._client_log.level
        self._client_log.setLevel(logging.CRITICAL)
        if address:
            try:
                self.client = distributed.Client(address, timeout=f"{CONNECT_TIMEOUT_S}s")
            except (OSError, TimeoutError) as err:
                self._client_log.setLevel(self._client_level)  # (no close() follows a failed start)
                raise ConfigError(f"cannot connect to the Dask scheduler: {err}", source=address) from None

    def _start_local_cluster(self, n_jobs: int) -> None:
        """A LocalCluster of :func:`local_dask_workers` processes and its client."""
        distributed = self._distributed
        self._quiet = logging.getLogger("distributed")
        self._level = self._quiet.level
        self._quiet.setLevel(logging.ERROR)  # a local cluster's INFO lines would only bury the progress bar
        os.environ.setdefault("DASK_LOGGING__DISTRIBUTED", "error")  # read by the worker processes at start
        # Worker processes start with SIGINT ignored and SIGINT / SIGHUP blocked (kept across exec): Ctrl-C and a
        # hang-up reach the whole process group, and only this process decides how the cluster stops. A Ctrl-C in the
        # few seconds the cluster takes to start is lost (see children_shielded).
        with children_shielded(), self._quiet_if_cut_off():
            # no dashboard; the scheduler's own HTTP routes on a free local port (by default 8787: another cluster
            # holding it printed distributed's 4-line "Port 8787 is already in use" warning). silence_logs is the level
            # of the workers' own log handler: at ERROR, a worker outliving a killed or interrupted bench printed a
            # 35-line "Failed to communicate with scheduler during heartbeat" traceback under its last line
            self.cluster = distributed.LocalCluster(
                n_workers=local_dask_workers(self.workers, n_jobs), threads_per_worker=1, processes=True,
                dashboard_address=None, scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
                silence_logs=logging.CRITICAL,
            )
            self.client = distributed.Client(self.cluster)

    @contextlib.contextmanager
    def _quiet_if_cut_off(self) -> Iterator[None]:
        """A cluster start cut off (SIGTERM, a hang-up) goes on closing what it started in its own thread while this
        process ends: its logging is silenced for good (it printed 15 INFO lines under the "interrupted by" line)."""
        try:
            yield
        except BaseException:
            self._level = logging.CRITICAL  # (what close() restores)
            self._quiet.setLevel(logging.CRITICAL)
            raise

    def run(self, fn: JobFn, items: list[Item]) -> Iterator[tuple[str, dict[str, Any]]]:
        if not items:
            return
        if self.client is None:
            self._start_local_cluster(len(items))
        futures = {}
        for key, spec in items:
            futures[self.client.submit(fn, spec, pure=False)] = key
        yielded = 0
        try:
            for fut in self._distributed.as_completed(list(futures)):
                key = futures[fut]
                try:
                    outcome = fut.result()
                except Exception as err:  # KilledWorker, lost connection, ...
                    if self._scheduler_lost(err):  # not the job's failure: stop, keep what finished (a resume runs the rest)
                        self._lost = True
                        raise LidarKitError(f"lost the Dask scheduler ({type(err).__name__}): {len(futures) - yielded} job(s) "
                                            "not run; the results so far are kept, run the suite again to run the rest",
                                            source=self.address or "local Dask cluster") from None
                    outcome = crash_outcome(type(err).__name__, str(err))
                yielded += 1
                yield key, outcome
        finally:
            self.client.cancel([f for f in futures if not f.done()])

    def _scheduler_lost(self, err: Exception) -> bool:
        """Whether ``err`` comes from losing the scheduler (every future cancelled with it: 87 jobs were recorded as
        failed, exit code 0), not from the job."""
        cancelled = getattr(self._distributed, "FutureCancelledError", None) or getattr(
            getattr(self._distributed, "client", None), "FutureCancelledError", ())
        if isinstance(err, cancelled or ()):
            return True
        return getattr(self.client, "status", "running") not in ("running", "connecting")

    def close(self) -> None:
        quiet = logging.getLogger("distributed")
        level = quiet.level
        if getattr(self, "_lost", False):  # the client's reconnect attempts would log their tracebacks while it closes
            quiet.setLevel(logging.CRITICAL)
        if self.client is not None:
            self.client.close()
        quiet.setLevel(level)
        if self.cluster is not None:
            self.cluster.close()
        if hasattr(self, "_quiet"):  # (a local cluster was started, or failed to start)
            self._quiet.setLevel(self._level)
        self._client_log.setLevel(self._client_level)


def check_executor_args(name: str, workers: int | None = None, address: str | None = None, *, cli: bool = False) -> None:
    """ConfigError for an unknown executor, a worker count < 1, or an address without the dask executor, naming the
    argument as the caller wrote it: ``workers`` in the library, ``--workers`` with ``cli``."""
    arg = (lambda flag: f"--{flag}") if cli else str
    if name not in EXECUTORS:
        raise ConfigError(f"unknown executor {name!r}; known: {', '.join(EXECUTORS)}", source=arg("executor"))
    if address and name != "dask":
        raise ConfigError("only applies to the dask executor", source=arg("address"))
    if address:
        _check_address(address, arg("address"))
    if workers is not None and workers < 1:
        raise ConfigError(f"must be >= 1, got {workers}", source=arg("workers"))
    if workers is not None and workers > 1 and name == "serial":  # (it was ignored: one job at a time)
        raise ConfigError(f"the serial executor runs one job at a time; {workers} workers are for process or dask",
                          source=arg("workers"))


def _check_address(address: str, source: str = "address") -> None:
    """A Dask scheduler address is ``[protocol://]host:port`` (``inproc://`` needs no port); anything else is a
    ConfigError before a folder is written (distributed raised a ValueError traceback after the run had started)."""
    scheme, sep, rest = address.partition("://")
    if not sep:
        scheme, rest = "tcp", address
    if scheme == "inproc" and rest:
        return
    host, colon, port = rest.rpartition(":")
    known = ("tcp", "tls", "ws", "wss", "ucx")
    if scheme not in known or not colon or not host.strip("[]") or not port.isdigit() or not 0 < int(port) < 65536:
        raise ConfigError(f"{address!r} is not a scheduler address: [{'|'.join(known)}://]host:port, e.g. tcp://127.0.0.1:8786",
                          source=source)


def make_executor(name: str, *, workers: int | None = None, address: str | None = None):
    """``serial`` | ``process`` | ``dask``; unknown names raise ConfigError."""
    check_executor_args(name, workers, address)
    if name == "serial":
        return SerialExecutor()
    if name == "process":
        return ProcessExecutor(workers)
    if name == "dask":
        return DaskExecutor(address, workers)
    raise ConfigError(f"unknown executor {name!r}; known: {', '.join(EXECUTORS)}", source="--executor")
