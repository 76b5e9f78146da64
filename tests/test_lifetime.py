"""Pool workers and the fork server end with the lidarkit process that owns them, also while it is an unreaped zombie."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from lidarkit import lifetime

REPO = Path(__file__).resolve().parents[1]
linux_proc = pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads the process table from /proc")


def _state(pid: int) -> str | None:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()[0]
    except (OSError, IndexError):
        return None


@linux_proc
def test_a_zombie_owner_counts_as_gone():
    """``os.kill(pid, 0)`` succeeds on a zombie: a worker whose owner was killed but not yet reaped kept running."""
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    try:
        deadline = time.monotonic() + 30
        while _state(child.pid) != "Z" and time.monotonic() < deadline:
            time.sleep(0.02)
        assert _state(child.pid) == "Z"  # exited, not reaped (Popen reaps only when asked)
        assert not lifetime._alive(child.pid)
    finally:
        child.wait()
    assert lifetime._alive(os.getpid())


@linux_proc
@pytest.mark.parametrize("pidfd", [True, False], ids=["pidfd", "proc-state"])
def test_a_worker_ends_when_its_owner_is_killed_and_not_reaped(pidfd):
    """The worker's watchdog with the owner a zombie (its parent the test, which does not wait): the worker exits, by
    the owner's pidfd or, without one, by the owner's state in /proc."""
    setup = "" if pidfd else "import os; del os.pidfd_open; "
    owner = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    worker = subprocess.Popen([sys.executable, "-c", f"{setup}from lidarkit.lifetime import init_worker; import time; "
                               f"init_worker({owner.pid}); print('watching', flush=True); time.sleep(60)"],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO)
    try:
        assert worker.stdout.readline() == "watching\n", worker.stderr.read()
        owner.kill()  # a zombie until owner.wait() below
        worker.wait(timeout=15)
        assert worker.returncode == 1 and _state(owner.pid) == "Z"
    finally:
        worker.kill()
        worker.communicate()
        owner.kill()
        owner.wait()


@linux_proc
def test_the_fork_server_dies_with_the_main_thread_that_started_it_only():
    """``PR_SET_PDEATHSIG`` in the fork server: set when the parent's main thread started it; not when a thread did
    (the signal follows the parent thread, which could end while the server's pools are still in use)."""
    import threading

    code = textwrap.dedent("""
        import ctypes
        from lidarkit.lifetime import setup_fork_server
        setup_fork_server()
        value = ctypes.c_int()
        ctypes.CDLL(None).prctl(2, ctypes.byref(value))  # PR_GET_PDEATHSIG
        print(value.value)
    """)

    def death_signal() -> int:
        done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, cwd=REPO)
        assert done.returncode == 0, done.stderr
        return int(done.stdout)

    from_thread = []
    thread = threading.Thread(target=lambda: from_thread.append(death_signal()))
    thread.start()
    thread.join()
    assert death_signal() == signal.SIGKILL
    assert from_thread == [0]


def _descendants(pid: int) -> list[int]:
    import psutil

    try:
        return [p.pid for p in psutil.Process(pid).children(recursive=True)]
    except psutil.NoSuchProcess:
        return []


@linux_proc
def test_the_documented_timeout_idiom_returns_after_killing_a_process_pool_bench(tmp_path):
    """Python's ``communicate(timeout)`` / ``kill()`` / ``communicate()`` idiom hung for ever on ``lidarkit bench -e
    process``: the killed process stays a zombie until the driver reaps it, which it does after EOF on the pipes, and
    the fork server and workers holding them took the zombie for alive. They end; nothing of the run is left."""
    suite = tmp_path / "suite.yaml"
    suite.write_text(textwrap.dedent("""
        name: idiom
        seeds: 4
        experiments:
          - task: selftest
            dataset: {kind: synthetic}
            methods: [{name: sleep, params: {seconds: 60}}]
    """))
    command = [sys.executable, "-m", "lidarkit.cli", "bench", str(suite), "--out", str(tmp_path / "out"), "--executor",
               "process", "--workers", "2", "--no-report"]
    proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=REPO)
    started: list[int] = []
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:  # until both workers run a job (they are the fork server's children)
            try:
                out, err = proc.communicate(timeout=0.2)
                pytest.fail(f"the run ended before it was killed: {err.decode()[-800:]}")
            except subprocess.TimeoutExpired:
                pass
            started = _descendants(proc.pid)
            if len([p for p in started if _state(p) in ("S", "R")]) >= 4:  # tracker, fork server, two workers
                break
        time.sleep(0.5)  # the jobs taken from the queue
        started = _descendants(proc.pid)
        assert len(started) >= 4, started  # resource tracker, fork server, two workers
        proc.kill()
        try:
            proc.communicate(timeout=15)  # docs: the workers exit at once (pidfd), within 0.5 s without one
        except subprocess.TimeoutExpired:
            alive = [p for p in started if _state(p) not in (None, "Z")]
            pytest.fail(f"communicate() after kill() still waiting; alive: {alive}")
        assert proc.returncode == -signal.SIGKILL
        deadline = time.monotonic() + 10
        while [p for p in started if _state(p) not in (None, "Z", "X")] and time.monotonic() < deadline:
            time.sleep(0.05)
        assert [p for p in started if _state(p) not in (None, "Z", "X")] == []
    finally:
        if proc.poll() is None:
            proc.kill()
        for pid in started:
            if _state(pid) not in (None, "Z", "X"):
                os.kill(pid, signal.SIGKILL)
        proc.communicate()
