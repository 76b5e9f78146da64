"""The CLI's own output refused by the system: one line, whatever prints it."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="needs /dev/full (a device that is always full)")
@pytest.mark.parametrize("args", [["--help"], ["eval", "--help"], []])
def test_a_help_page_on_a_full_stdout_is_the_one_stdout_line(args):
    """`lidarkit --help > /dev/full` printed a 133-line traceback (rich, inside click's help, raised ENOSPC); it is the
    line `lidarkit version > /dev/full` gives, exit 1."""
    with open("/dev/full", "w") as full:
        done = subprocess.run([sys.executable, "-m", "lidarkit", *args], stdout=full, stderr=subprocess.PIPE, text=True,
                              timeout=120)
    assert (done.returncode, done.stderr) == (1, "error: stdout: cannot write: no space left on the device\n")


def test_help_still_prints_in_full_and_stdout_is_restored(capsys):
    """The command's stdout is wrapped only while it runs: the help page is printed as before."""
    from lidarkit.cli import main

    stream = sys.stdout
    with pytest.raises(SystemExit) as exc:
        main(["eval", "--help"])
    assert exc.value.code == 0 and "--json" in capsys.readouterr().out
    assert sys.stdout is stream


def _kitti_poses(path: Path, offset_m: float) -> str:
    """20 poses on a quarter circle (KITTI format), shifted along x by ``offset_m``."""
    import numpy as np

    yaw = np.linspace(0.0, np.pi / 2, 20)
    rows = [[np.cos(a), -np.sin(a), 0.0, 10 * np.sin(a) + offset_m, np.sin(a), np.cos(a), 0.0, 10 * (1 - np.cos(a)),
             0.0, 0.0, 1.0, 0.0] for a in yaw]
    path.write_text("".join(" ".join(f"{v:.9f}" for v in row) + "\n" for row in rows))
    return str(path)


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs FIFOs")
def test_sigterm_while_an_output_fifo_waits_for_a_reader_ends_the_command(tmp_path):
    """`eval --json ff` with a FIFO nobody reads slept in the FIFO's open with SIGINT / SIGTERM held off, so every
    signal only restarted the wait: a stream is written into outside the held-off renames, and SIGTERM exits 143 with
    one line, leaving no temporary file."""
    import signal
    import time

    fifo, temporary = tmp_path / "ff", tmp_path / "tmp"
    os.mkfifo(fifo)
    temporary.mkdir()
    gt, est = _kitti_poses(tmp_path / "gt.txt", 0.0), _kitti_poses(tmp_path / "est.txt", 0.1)
    env = {**os.environ, "TMPDIR": str(temporary)}  # (where a stream's output waits to be copied in)
    proc = subprocess.Popen([sys.executable, "-m", "lidarkit", "eval", gt, est, "--no-drift", "--json", str(fifo)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=env)
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and proc.poll() is None:  # until the output is complete and the open waits
            written = [p for p in temporary.iterdir() if p.stat().st_size > 0]
            if written and _waits_in_fifo_open(proc.pid):
                break
            time.sleep(0.05)
        time.sleep(0.2)
        proc.send_signal(signal.SIGTERM)
        try:
            _, err = proc.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.communicate()
            pytest.fail("SIGTERM did not end the command waiting for a reader of its FIFO output")
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 143
    assert err.splitlines() == ["interrupted by SIGTERM: stopped; no file is left half-written (each is complete or absent)"]
    assert list(temporary.iterdir()) == []


def _waits_in_fifo_open(pid: int) -> bool:
    """Whether ``pid`` sleeps in a FIFO's open (Linux's /proc/<pid>/wchan); True where that cannot be told."""
    try:
        where = Path(f"/proc/{pid}/wchan").read_text().strip()
    except OSError:
        return True
    return where in ("", "0", "wait_for_partner", "fifo_open")


def test_a_local_dask_cluster_beside_another_holding_port_8787_starts_without_a_warning():
    """`bench -e dask` printed distributed's 4-line "Port 8787 is already in use" warning when another Dask cluster
    held the port its scheduler serves HTTP on: it takes a free local port instead, and no dashboard."""
    import socket
    import warnings

    pytest.importorskip("distributed")
    from lidarkit.bench.executors import DaskExecutor

    with socket.socket() as other:
        try:
            other.bind(("127.0.0.1", 8787))
            other.listen()
        except OSError:  # (held already: by another cluster, as in the report)
            pass
        executor = DaskExecutor(workers=1)
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                executor._start_local_cluster(1)
            http = executor.cluster.scheduler.http_server
            assert http.address == "127.0.0.1" and http.port != 8787
        finally:
            executor.close()
    assert [str(w.message) for w in caught if "already in use" in str(w.message)] == []
