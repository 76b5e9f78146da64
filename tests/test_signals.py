"""Killing `lidarkit bench` (process pool): SIGTERM mid-run and SIGKILL of the parent alone. A few kills here;
the 20-per-signal run over both executors is benchmarks/bench_kill.py (results in benchmarks/results/reliability)."""

from __future__ import annotations

import signal
import sys
import textwrap
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import bench_kill  # noqa: E402

pytestmark = pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads the process table from /proc")


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL])
def test_killed_bench_leaves_no_orphans_no_corrupt_results_and_resumes(tmp_path, sig):
    suite = tmp_path / "suite.yaml"
    suite.write_text(textwrap.dedent(bench_kill.SUITE.format(n_jobs=8, job_s=0.3)))
    trial = bench_kill.kill_trial(suite, tmp_path / "out", "process", sig, delay_s=1.0, n_jobs=8)
    assert not trial["finished_before_signal"], trial  # the signal landed while jobs were running
    assert trial["returncode"] == bench_kill.expected_returncode(sig), trial
    assert trial["orphans"] == [], trial  # nothing alive 5 s after the parent ended (workers, fork server, tracker)
    assert trial["corrupt"] == 0 and not trial["traceback"], trial
    if sig == signal.SIGTERM:
        assert trial["message"].startswith("interrupted by SIGTERM") and "run the same command again" in trial["message"]
    assert trial["rerun_complete"], trial
    assert bench_kill.trial_ok(trial)


@pytest.mark.slow
def test_an_interrupted_run_says_the_folders_report_is_from_before_it(tmp_path):
    """A suite run into a folder that holds an earlier run's report.html and stopped half-way leaves that report in
    place: the interrupt's line says it predates the run and how to rebuild it."""
    import subprocess

    first = tmp_path / "first.yaml"
    first.write_text(textwrap.dedent(bench_kill.SUITE.format(n_jobs=2, job_s=0.01)))
    out = tmp_path / "out"
    command = [c for c in bench_kill.bench_cmd(first, out, "process") if c != "--no-report"]
    subprocess.run(command, check=True, capture_output=True, timeout=300)
    assert (out / "report.html").is_file()
    (out / "suite.json").unlink()  # the trial waits for the second run to write its own before it counts the delay
    second = tmp_path / "second.yaml"
    second.write_text(textwrap.dedent(bench_kill.SUITE.format(n_jobs=8, job_s=0.3)).replace("name: kill", "name: second"))
    trial = bench_kill.kill_trial(second, out, "process", signal.SIGTERM, delay_s=1.0, n_jobs=8)
    assert not trial["finished_before_signal"], trial
    assert trial["message"].startswith("interrupted by SIGTERM"), trial
    assert f"{out}/report.html is from before this run (`lidarkit report {out}` rebuilds it" in trial["message"], trial


def test_a_child_started_with_sigint_ignored_keeps_ignoring_it():
    """A Dask worker re-imports the CLI as its __main__: the CLI's start-up handler made it exit on the Ctrl-C its
    cluster's start was to ride out ("Nanny failed to start" and a traceback in the parent). An ignored SIGINT stays
    ignored; SIGTERM still ends the process with one line."""
    import subprocess

    code = textwrap.dedent("""
        import os, signal, sys
        sys.argv = ["lidarkit"]  # as a spawned worker has it: its parent's argv
        import lidarkit.cli  # installs the start-up handlers
        os.kill(os.getpid(), signal.SIGINT)
        print("still running")
        os.kill(os.getpid(), signal.SIGTERM)
        print("not reached")
    """)
    env_root = Path(__file__).resolve().parents[1]
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, cwd=env_root,
                          preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
    assert done.stdout.strip() == "still running" and done.returncode == 128 + signal.SIGTERM
    assert done.stderr.strip() == "interrupted by SIGTERM while starting: nothing was written"
    normal = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, cwd=env_root)
    assert normal.returncode == 130 and normal.stdout == ""  # without the inherited ignore: the one-line exit as before


def test_a_pool_worker_importing_the_cli_as_its_main_leaves_sigterm_to_its_parent():
    """A process-pool worker imports the CLI again as its parent's main module before it starts; when the pool closed
    while workers were still starting, each printed "interrupted by SIGTERM while starting: nothing was written"
    under the parent's own line. Such a worker (multiprocessing's start-up code loaded) ends silently on SIGTERM."""
    import subprocess

    code = textwrap.dedent("""
        import os, signal, sys
        import multiprocessing.spawn  # as in a forkserver or spawn child preparing itself
        sys.argv = ["/venv/bin/lidarkit", "bench", "suite.yaml"]  # the parent's argv, which the child takes over
        import lidarkit.cli
        os.kill(os.getpid(), signal.SIGTERM)
        print("not reached")
    """)
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60,
                          cwd=Path(__file__).resolve().parents[1])
    assert (done.returncode, done.stdout, done.stderr) == (-signal.SIGTERM, "", "")


def test_an_interrupt_a_library_swallows_still_ends_the_command_as_interrupted(monkeypatch, capsys):
    """Ctrl-C while a library's import code caught everything: the handler had set SIGINT and SIGTERM ignored for a
    cleanup that never came, so the run went on unstoppable and exited 0 or 1 without a word. A loop of lidarkit's
    stops at its next step; a command that ran to its end says it was interrupted and exits 130."""
    import os

    from lidarkit import cli
    from lidarkit.lifetime import raise_if_interrupted

    steps = []

    def swallowing_app(*_args, **_kwargs):
        try:
            os.kill(os.getpid(), signal.SIGINT)  # delivered at once: the handler raises inside the try
        except BaseException:  # noqa: BLE001 - what a library's bare except does
            pass
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN  # ignored for the cleanup: nothing would stop the run
        steps.append("ran on")
        raise SystemExit(0)

    monkeypatch.setattr(cli, "app", swallowing_app)
    with pytest.raises(SystemExit) as exc:
        cli.main(["version"])
    err = capsys.readouterr().err
    assert exc.value.code == 130 and steps == ["ran on"]
    assert err.startswith("interrupted by SIGINT, which a library caught as it loaded: the command ran to its end")
    raise_if_interrupted()  # handled: the next command in this process starts afresh

    def looping_app(*_args, **_kwargs):
        try:
            os.kill(os.getpid(), signal.SIGINT)
        except BaseException:  # noqa: BLE001
            pass
        for step in range(3):  # a run's frames or jobs: the next one stops it
            raise_if_interrupted()
            steps.append(step)

    monkeypatch.setattr(cli, "app", looping_app)
    with pytest.raises(SystemExit) as exc:
        cli.main(["version"])
    assert exc.value.code == 130 and steps == ["ran on"]
    assert capsys.readouterr().err.startswith("interrupted by SIGINT: stopped")


def test_an_interrupt_a_library_wraps_in_its_own_error_is_still_an_interrupt(monkeypatch, capsys):
    """Ctrl-C while open3d is first imported in the middle of a run came out as 'ImportError: initialization failed'
    (caused by the Interrupted) with a traceback and exit 1; it is the interrupt's one line and exit 130."""
    from lidarkit import cli
    from lidarkit.lifetime import Interrupted

    def wrapped(*_args, **_kwargs):
        try:
            raise Interrupted(signal.SIGINT)
        except Interrupted as err:
            raise ImportError("initialization failed") from err

    monkeypatch.setattr(cli, "app", wrapped)
    with pytest.raises(SystemExit) as exc:
        cli.main(["version"])
    assert exc.value.code == 130 and capsys.readouterr().err.startswith("interrupted by SIGINT: stopped")
    monkeypatch.setattr(cli, "app", lambda *a, **k: (_ for _ in ()).throw(ImportError("not an interrupt")))
    with pytest.raises(ImportError, match="not an interrupt"):
        cli.main(["version"])


def test_an_interrupted_forced_run_says_to_resume_without_force(tmp_path, monkeypatch, capsys):
    """`lidarkit bench SUITE --force` stopped half-way said "run the same command again to resume": run again, --force
    ran every job again (12 jobs: 0 already done, 12 run now)."""
    from lidarkit import cli
    from lidarkit.bench import runner

    suite = tmp_path / "suite.yaml"
    suite.write_text(textwrap.dedent(bench_kill.SUITE.format(n_jobs=3, job_s=0.01)))
    out = tmp_path / "out"
    real = runner.run_suite

    def stopped_after_one_job(*args, on_result=None, **kwargs):
        def result(*a, **k):
            on_result(*a, **k)
            raise KeyboardInterrupt  # Ctrl-C once the first job is kept

        return real(*args, on_result=result, **kwargs)

    monkeypatch.setattr(runner, "run_suite", stopped_after_one_job)
    for force, line in ((True, "run the command again without --force to resume (with it, every job runs again)"),
                        (False, "run the same command again to resume")):
        with pytest.raises(SystemExit) as exc:
            cli.main(["bench", str(suite), "--out", str(out), "--executor", "serial", "--no-report", *(["--force"] if force else [])])
        err = " ".join(capsys.readouterr().err.split())
        assert exc.value.code == 130 and f"finished results are kept in {out}/jobs; {line}" in err, err
    # stopped before any job finished: no jobs/ folder to point to (it was named all the same)
    monkeypatch.setattr(runner, "run_suite", lambda *a, **k: (_ for _ in ()).throw(KeyboardInterrupt()))
    with pytest.raises(SystemExit) as exc:
        cli.main(["bench", str(suite), "--out", str(tmp_path / "new"), "--executor", "serial", "--no-report"])
    err = " ".join(capsys.readouterr().err.split())
    assert exc.value.code == 130 and "interrupted by SIGINT: no job had finished yet; run the same command again" in err, err


def test_an_interrupt_while_a_run_is_moved_into_its_folder_takes_effect_once_every_file_is_in(tmp_path):
    """SIGTERM while an export's files were moved into an existing folder (one rename each) stopped the move half-way:
    the folder kept sim.yaml, poses.txt (1000 lines) and only 327 of 1000 sweeps, and read as a finished sequence of
    327 frames. The move finishes first (the files that mark a run finished last), then the interrupt ends the
    command with its usual line and exit code."""
    import subprocess

    code = textwrap.dedent("""
        import os, signal, sys
        from lidarkit import atomic
        from lidarkit.cli import main

        real_replace, moved = os.replace, []

        def replace(src, dst):  # a real SIGTERM right after the 3rd file is moved into the folder
            real_replace(src, dst)
            if atomic.PARTIAL_MARK not in str(dst):
                moved.append(os.path.basename(dst))
                if len(moved) == 3:
                    os.kill(os.getpid(), signal.SIGTERM)

        os.replace = replace
        try:
            main(sys.argv[1:])
        finally:
            print(" ".join(moved))
    """)
    out = tmp_path / "ex1"
    out.mkdir()  # an existing (empty) folder: the files are moved in one by one
    done = subprocess.run([sys.executable, "-c", code, "sim", "lidar", "-n", "5", "-p", "n_beams=4", "-p",
                           "n_azimuths=50", "-o", str(out)], capture_output=True, text=True, timeout=300,
                          cwd=Path(__file__).resolve().parents[1])
    assert done.returncode == 128 + signal.SIGTERM, done.stderr
    assert done.stderr.strip().splitlines()[-1].startswith("interrupted by SIGTERM: stopped"), done.stderr
    moved = done.stdout.split()
    assert len(moved) == 5 + 5 + 7 and moved[-1] == "sim.yaml"  # every file moved, the one naming the run last
    assert sorted(p.name for p in (out / "velodyne").iterdir()) == [f"{i:06d}.bin" for i in range(5)]
    assert len((out / "poses.txt").read_text().splitlines()) == 5 and (out / "sim.yaml").is_file()
    assert [p.name for p in tmp_path.iterdir()] == ["ex1"]  # no temporary folder left beside it


def test_an_interrupt_while_the_report_is_written_says_the_report_is_not_this_runs(tmp_path, monkeypatch, capsys):
    """Ctrl-C while `lidarkit bench` wrote its end-of-run report said "stopped; no file is left half-written" and kept
    the earlier run's report.md / report.html / plots without a word. The line says the jobs are done and the report
    predates them (or was not written, or was: a signal during the move takes effect once the files are in)."""
    import os

    from lidarkit import atomic, cli
    from lidarkit.bench import report

    suite = tmp_path / "suite.yaml"
    suite.write_text(textwrap.dedent(bench_kill.SUITE.format(n_jobs=2, job_s=0.01)))
    out = tmp_path / "out"
    bench = ["bench", str(suite), "--out", str(out), "--executor", "serial", "--force"]
    with pytest.raises(SystemExit) as exc:
        cli.main(bench)
    assert exc.value.code == 0
    earlier = (out / "report.html").read_bytes()
    capsys.readouterr()

    def signalled(real):
        def call(*args, **kwargs):
            os.kill(os.getpid(), signal.SIGINT)  # a real Ctrl-C while the report is drawn, or moved into the folder
            return real(*args, **kwargs)

        return call

    monkeypatch.setattr(report, "make_plots", signalled(report.make_plots))
    done = f"interrupted by SIGINT while the report was written: every job of the run is done (results in {out}/jobs); "
    for folder, then in ((out, f"{out}/report.html is from before this run (`lidarkit report {out}` rebuilds it "
                               "from the finished jobs)"),
                         (tmp_path / "new", f"no report was written (`lidarkit report {tmp_path / 'new'}` writes it "
                                            "from the finished jobs)")):
        bench[3] = str(folder)
        with pytest.raises(SystemExit) as exc:
            cli.main(bench)
        err = " ".join(capsys.readouterr().err.split())
        assert exc.value.code == 130 and err.endswith(done.replace(str(out), str(folder)) + then), err
    assert (out / "report.html").read_bytes() == earlier and not (tmp_path / "new" / "report.html").exists()
    inode = (out / "report.html").stat().st_ino
    monkeypatch.undo()
    monkeypatch.setattr(atomic, "_move_into_place", signalled(atomic._move_into_place))
    bench[3] = str(out)
    with pytest.raises(SystemExit) as exc:
        cli.main(bench)
    err = " ".join(capsys.readouterr().err.split())
    assert exc.value.code == 130 and err.endswith(f"{done}the report was written ({out}/report.html)"), err
    assert (out / "report.html").stat().st_ino != inode  # (its text may equal the earlier one's)


def test_an_ignored_sigint_stays_ignored_for_the_whole_command(tmp_path):
    """A command started with SIGINT ignored (a background job of a script, which a Ctrl-C at the terminal is to leave
    alone) ignored it while starting, then was stopped by one after its first seconds ("interrupted by SIGINT", the run
    lost): it stays ignored throughout, and the run completes."""
    import subprocess
    import time

    out = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-m", "lidarkit", "odometry", "sim:street?frames=60&beams=16&azimuths=360", "-m", "vanilla",
                             "--out", str(out), "--no-progress"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            cwd=Path(__file__).resolve().parents[1], preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
    sent = 0
    while proc.poll() is None:  # one every 0.2 s, from startup to the end of the run
        time.sleep(0.2)
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
            sent += 1
    err = proc.stderr.read().decode()
    assert sent > 10 and proc.returncode == 0 and "interrupted" not in err, err
    assert (out / "metrics.json").is_file()


def test_an_interrupted_command_ends_with_its_code_whatever_a_library_does_at_shutdown(tmp_path):
    """Open3D's memory statistics (a static object) print themselves at process end when an interrupt left tensors
    allocated, and end the process with exit code 1: a Ctrl-C inside a sim's ray cast exited 1 instead of 130 (3 tries
    in 23). The console script now ends right after its cleanup; here an exit handler stands for Open3D's."""
    import os
    import subprocess
    import time

    marker, out = tmp_path / "started", tmp_path / "sim"
    script = textwrap.dedent(f"""
        import atexit, os, sys
        atexit.register(os._exit, 1)  # (as Open3D's statistics do at shutdown after leaks)
        sys.argv = ["lidarkit", "sim", "lidar", "-n", "100000", "-o", {str(out)!r}, "--no-progress",
                    "-p", "n_beams=8", "-p", "n_azimuths=64"]
        from lidarkit.cli import main
        open({str(marker)!r}, "w").close()
        main()
        """)
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120
        while not marker.exists() and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.1)
        time.sleep(2.0)  # inside the command (its signal handlers in place), casting sweeps
        assert proc.poll() is None, proc.communicate()
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 143, err
    # (the 100 km drive's float32 warning comes first when the simulator logs it before the signal)
    lines = [line for line in err.splitlines() if line.strip()]
    assert lines[-1].startswith("interrupted by SIGTERM: stopped"), err
    assert all(line.startswith("WARNING lidarkit.sim.lidar: ") for line in lines[:-1]), err
    assert not out.exists() and not [p for p in os.listdir(tmp_path) if p.startswith(".")]  # nothing half-written


def test_a_hang_up_stops_bench_like_sigterm_and_its_workers_leave_it_to_the_parent(tmp_path):
    """A closed terminal (or a dropped SSH session) sends SIGHUP to the bench's whole process group: it died at once,
    exit 129 with no word, no cleanup, and Python's resource tracker reported leaked semaphores. It stops as on
    SIGTERM now: one "interrupted by SIGHUP" line, exit 129, finished results kept and whole, nothing left running."""
    import os
    import subprocess
    import time

    suite, out = tmp_path / "suite.yaml", tmp_path / "out"
    suite.write_text(textwrap.dedent(bench_kill.SUITE.format(n_jobs=4, job_s=1.0)))
    env = {**os.environ, "PYTHONPATH": str(bench_kill.REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    proc = subprocess.Popen(bench_kill.bench_cmd(suite, out, "process"), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True, start_new_session=True, env=env)
    try:
        deadline = time.monotonic() + 120
        while not (out / "suite.json").exists() and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.02)
        time.sleep(0.5)  # the first jobs running (4 jobs of 1 s on 2 workers)
        assert proc.poll() is None, proc.communicate()
        os.killpg(proc.pid, signal.SIGHUP)  # as the terminal's hang-up reaches the job's process group
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    deadline = time.monotonic() + 5
    while bench_kill.session_processes(proc.pid) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert proc.returncode == 128 + signal.SIGHUP, err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("interrupted by SIGHUP") and "run the same command again" in lines[0], err
    assert bench_kill.session_processes(proc.pid) == []  # workers, fork server, resource tracker gone
    assert bench_kill.check_results(out)[1] == 0


def test_a_command_started_with_sighup_ignored_keeps_ignoring_it():
    """``nohup lidarkit ...`` starts the command with SIGHUP ignored, to outlive its terminal: the CLI's handlers
    leave it ignored (as an ignored SIGINT), while the command runs too."""
    import subprocess

    code = textwrap.dedent("""
        import os, signal, sys
        from lidarkit.lifetime import handle_signals, install_startup_handlers
        install_startup_handlers()  # (what the CLI does first)
        os.kill(os.getpid(), signal.SIGHUP)
        with handle_signals():
            os.kill(os.getpid(), signal.SIGHUP)
        print("still running")
    """)
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60,
                          cwd=Path(__file__).resolve().parents[1],
                          preexec_fn=lambda: signal.signal(signal.SIGHUP, signal.SIG_IGN))
    assert (done.returncode, done.stdout.strip(), done.stderr) == (0, "still running", "")
