"""Runner and executors: identical results on serial/process/dask, failures recorded, kill + resume safe."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from lidarkit.bench.results import load_results, result_path
from lidarkit.bench.runner import run_suite
from lidarkit.bench.suite import load_suite
from lidarkit.bench.tasks.selftest import run_selftest

TINY = """
name: tiny
seeds: [0, 1]
experiments:
  - task: selftest
    dataset: {kind: synthetic, name: synth}
    methods:
      - name: random_walk
        params: {steps: 30}
        grid: {noise_m: [0.01, 0.1]}
      - name: fail
        params: {message: "deliberate failure 42"}
      - name: burn
        params: {size: 30, repeats: 3}
"""

TIMING_FIELDS = {"runtime_s", "started_utc", "finished_utc", "host", "pid"}


def suite_file(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "suite.yaml"
    path.write_text(textwrap.dedent(text))
    return path


def comparable(out_dir: Path) -> dict[str, dict]:
    return {r["key"]: {k: v for k, v in r.items() if k not in TIMING_FIELDS or k == "error"} for r in load_results(out_dir)}


def test_identical_results_on_serial_process_and_dask(tmp_path):
    suite = load_suite(suite_file(tmp_path, TINY))
    assert len(suite.jobs) == 8
    runs = {}
    for executor in ("serial", "process", "dask"):
        summary = run_suite(suite, tmp_path / executor, executor=executor, workers=2 if executor == "process" else 1)
        assert (summary.total, summary.ran, summary.ok, summary.failed) == (8, 8, 6, 2)
        runs[executor] = comparable(tmp_path / executor)
    assert len(runs["serial"]) == 8
    for record in runs["serial"].values():
        record.get("error", {}) and record["error"].pop("traceback", None)
    for executor in ("process", "dask"):
        for record in runs[executor].values():
            record.get("error", {}) and record["error"].pop("traceback", None)
        assert runs[executor] == runs["serial"], executor
    # and the harness gives what the plain job function gives
    walk = next(r for r in load_results(tmp_path / "dask") if r["job"]["method"] == "random_walk")
    direct = run_selftest("random_walk", walk["job"]["params"], walk["job"]["seed"])
    assert walk["metrics"]["ape_rmse_m"] == pytest.approx(direct.metrics["ape_rmse_m"], rel=0, abs=0)


def test_failing_job_is_recorded_and_the_suite_completes(tmp_path):
    suite = load_suite(suite_file(tmp_path, TINY))
    summary = run_suite(suite, tmp_path / "out", executor="serial")
    records = load_results(tmp_path / "out")
    failed = [r for r in records if r["status"] == "failed"]
    assert len(records) == 8 and len(failed) == 2
    for r in failed:
        assert r["job"]["method"] == "fail"
        assert r["error"]["type"] == "RuntimeError"
        assert r["error"]["message"] == "deliberate failure 42"
        assert "run_selftest" in r["error"]["traceback"]
    assert all(r["status"] == "ok" and r["metrics"] for r in records if r["job"]["method"] != "fail")
    assert len(summary.failures) == 2 and "deliberate failure 42" in summary.failures[0][2]
    # a rerun skips the successful jobs and retries only the failed ones
    again = run_suite(suite, tmp_path / "out", executor="serial")
    assert (again.skipped, again.ran, again.failed) == (6, 2, 2)
    forced = run_suite(suite, tmp_path / "out", executor="serial", force=True)
    assert (forced.skipped, forced.ran) == (0, 8)


def test_a_metric_that_is_not_a_number_fails_its_job_naming_the_metric(tmp_path, monkeypatch):
    """A custom task's text metric was recorded "ok" though no reader takes it: the result was never read back and
    the job ran again on every resume."""
    from lidarkit.bench import tasks as bench_tasks
    from lidarkit.bench.tasks import Metric, Task, TaskOutput, register_task

    monkeypatch.setattr(bench_tasks, "_REGISTERED", {})
    monkeypatch.setattr(bench_tasks, "_INSTANCES", {})

    @register_task("text_metric_test_task")
    class TextMetric(Task):
        dataset_kinds = ("synthetic",)
        metrics = (Metric("v", "value"),)

        def run(self, job):
            return TaskOutput(metrics={"v": "abc" if job.method == "text" else 1.5})

    suite = load_suite(suite_file(tmp_path, """
        experiments:
          - {task: text_metric_test_task, dataset: {kind: synthetic}, methods: [text, number]}
        """))
    summary = run_suite(suite, tmp_path / "out", executor="serial")
    assert (summary.ok, summary.failed) == (1, 1)
    failed = next(r for r in load_results(tmp_path / "out") if r["status"] == "failed")
    assert failed["metrics"] == {} and failed["error"]["type"] == "DataError"
    assert failed["error"]["message"] == ("task text_metric_test_task: metric v is 'abc', not a number "
                                          "(a task's metrics are numbers, or None where not defined)")
    again = run_suite(suite, tmp_path / "out", executor="serial")
    assert (again.skipped, again.failed) == (1, 1)  # the number job is read back as done


def test_a_forced_rerun_that_fails_keeps_the_earlier_ok_result(tmp_path, monkeypatch):
    """A ``--force`` rerun hit by a transient error replaced each job's ok result with the failure: the good results
    were lost. Now the ok result stays (a later resume skips it) with the failure beside it, and the summary says so."""
    from lidarkit.bench import tasks as bench_tasks
    from lidarkit.bench.tasks import Metric, Task, TaskOutput, register_task

    monkeypatch.setattr(bench_tasks, "_REGISTERED", {})
    monkeypatch.setattr(bench_tasks, "_INSTANCES", {})

    @register_task("flaky_test_task")
    class Flaky(Task):
        dataset_kinds = ("synthetic",)
        metrics = (Metric("err_m", "error [m]"),)

        def run(self, job):
            if os.environ.get("FLAKY_TEST_FAIL"):
                raise RuntimeError("transient: data disk not mounted")
            return TaskOutput(metrics={"err_m": 0.5 + job.seed})

    suite = load_suite(suite_file(tmp_path, """
        seeds: 2
        experiments:
          - {task: flaky_test_task, dataset: {kind: synthetic}, methods: [a]}
        """))
    assert run_suite(suite, tmp_path / "out", executor="serial").ok == 2
    monkeypatch.setenv("FLAKY_TEST_FAIL", "1")
    forced = run_suite(suite, tmp_path / "out", executor="serial", force=True)
    assert (forced.ran, forced.ok, forced.failed) == (2, 0, 2)
    assert forced.failures[0][2] == "RuntimeError: transient: data disk not mounted (the earlier ok result is kept)"
    records = load_results(tmp_path / "out")
    assert [(r["status"], r["metrics"]["err_m"]) for r in records] == [("ok", 0.5), ("ok", 1.5)]
    assert [r["rerun_failed"]["error"]["message"] for r in records] == ["transient: data disk not mounted"] * 2
    monkeypatch.delenv("FLAKY_TEST_FAIL")
    again = run_suite(suite, tmp_path / "out", executor="serial")
    assert (again.skipped, again.ran) == (2, 0)


CUSTOM_TASK = """
from lidarkit.bench import Metric, Task, TaskOutput, register_task

@register_task("module_test_task")
class ModuleTask(Task):
    dataset_kinds = ("synthetic",)
    metrics = (Metric("err_m", "error [m]"),)

    def run(self, job):
        return TaskOutput(metrics={"err_m": 0.5 + job.seed})
"""


def test_a_task_registered_in_a_module_runs_in_worker_processes(tmp_path, monkeypatch):
    """The docs said a task registered in code runs, but on the process executor every job failed with "unknown task
    'module_test_task'": a worker knew only the built-in tasks. Now it imports the module the task was registered in."""
    import importlib

    from lidarkit.bench import tasks as bench_tasks

    monkeypatch.setattr(bench_tasks, "_REGISTERED", {})
    monkeypatch.setattr(bench_tasks, "_INSTANCES", {})
    (tmp_path / "lidarkit_module_test_task.py").write_text(CUSTOM_TASK)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "lidarkit_module_test_task", raising=False)
    importlib.import_module("lidarkit_module_test_task")
    suite = load_suite(suite_file(tmp_path, """
        seeds: 2
        experiments:
          - {task: module_test_task, dataset: {kind: synthetic}, methods: [a]}
        """))
    summary = run_suite(suite, tmp_path / "out", executor="process", workers=2)
    assert (summary.ok, summary.failures) == (2, [])
    assert [r["metrics"]["err_m"] for r in load_results(tmp_path / "out")] == [0.5, 1.5]
    assert [r["job"] for r in load_results(tmp_path / "out")] == [job.spec() for job in suite.jobs]


def test_a_task_registered_where_no_file_holds_it_is_refused_before_any_job(tmp_path):
    """A task defined in ``python -c`` (or a notebook) cannot be imported by a worker process: every job failed with
    "unknown task". Now the run is refused, in one line saying what to do, before anything is written."""
    suite = suite_file(tmp_path, """
        experiments:
          - {task: module_test_task, dataset: {kind: synthetic}, methods: [a]}
        """)
    code = CUSTOM_TASK + textwrap.dedent(f"""
        from lidarkit.bench import load_suite, run_suite
        from lidarkit.errors import ConfigError
        try:
            run_suite(load_suite({str(suite)!r}), {str(tmp_path / "out")!r}, workers=1)
        except ConfigError as err:
            print(err)
        """)
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.stdout.strip() == ("task: 'module_test_task' is registered in __main__ with no file (python -c, a "
                                   "notebook), which worker processes cannot import: define it in a module they can "
                                   'import and import that, or run with executor="serial"'), proc.stderr
    assert not (tmp_path / "out").exists()


def test_result_file_records_key_version_and_resolved_job(tmp_path):
    from lidarkit import __version__
    from lidarkit.provenance import code_version

    suite = load_suite(suite_file(tmp_path, TINY))
    run_suite(suite, tmp_path / "out", executor="serial")
    job = suite.jobs[0]
    record = json.loads(result_path(tmp_path / "out", job.key()).read_text())
    assert record["key"] == job.key() and record["lidarkit_version"] == code_version()
    assert code_version().startswith(__version__ + "+src.") and len(code_version()) == len(__version__) + 15
    assert record["job"] == job.spec()
    manifest = json.loads((tmp_path / "out" / "suite.json").read_text())
    assert [j["key"] for j in manifest["jobs"]] == [j.key() for j in suite.jobs]


def test_a_folder_resumed_after_the_code_changed_runs_its_jobs_again(tmp_path, monkeypatch):
    """The release number does not change between commits of a checkout: the key holds a digest of the source, so
    results the changed code might not give are not kept as done."""
    import lidarkit.provenance as provenance

    suite = load_suite(suite_file(tmp_path, TINY))
    first = run_suite(suite, tmp_path / "out", executor="serial")
    assert run_suite(suite, tmp_path / "out", executor="serial").skipped == 6  # the 2 failed jobs are tried again
    monkeypatch.setattr(provenance, "source_digest", lambda: "0123456789")  # the source as another commit has it
    again = run_suite(suite, tmp_path / "out", executor="serial")
    assert (again.skipped, again.ran) == (0, first.total)


SLEEPS = """
name: sleeps
seeds: 12
experiments:
  - task: selftest
    dataset: {kind: synthetic}
    methods: [{name: sleep, params: {seconds: 0.4}}]
"""


@pytest.mark.slow
def test_killed_run_resumes_without_redoing_finished_jobs(tmp_path):
    path = suite_file(tmp_path, SLEEPS)
    out = tmp_path / "out"
    jobs_dir = out / "jobs"
    cmd = [sys.executable, "-m", "lidarkit.cli", "bench", str(path), "--out", str(out),
           "--executor", "process", "--workers", "2", "--no-report"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True)
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            done = list(jobs_dir.glob("[!.]*.json")) if jobs_dir.exists() else []
            if len(done) >= 3 or proc.poll() is not None:
                break
            time.sleep(0.05)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)  # the whole process group: parent and workers, no cleanup
        proc.wait(timeout=30)
    assert proc.returncode == -signal.SIGKILL, proc.stderr.read().decode()[-2000:]
    before = {p.name: p.stat().st_mtime_ns for p in jobs_dir.glob("[!.]*.json")}
    assert 3 <= len(before) < 12
    for p in jobs_dir.iterdir():  # every file a reader sees parses; temp files are hidden and ignored
        if not p.name.startswith("."):
            assert json.loads(p.read_text())["status"] == "ok"

    summary = run_suite(load_suite(path), out, executor="serial")
    assert summary.skipped == len(before)
    assert summary.ran == 12 - len(before)
    after = {p.name: p.stat().st_mtime_ns for p in jobs_dir.glob("[!.]*.json")}
    assert len(after) == 12
    assert {name: after[name] for name in before} == before  # finished jobs were not rewritten
    assert len(load_results(out)) == 12
    visible = [p for p in jobs_dir.iterdir() if not p.name.startswith(".")]
    assert len(visible) == 12 and all(json.loads(p.read_text())["status"] == "ok" for p in visible)


def test_worker_crash_is_isolated_to_its_job(tmp_path):
    """A job that kills its worker process is recorded as failed; the other jobs still succeed."""
    from lidarkit.bench import executors

    suite = load_suite(suite_file(tmp_path, """
        seeds: [0, 1, 2]
        experiments:
          - task: selftest
            dataset: {kind: synthetic}
            methods: [{name: random_walk, params: {steps: 5}}]
        """))
    crash_seed = 1
    records = []
    runner = executors.ProcessExecutor(workers=2)
    items = [(job.key(), job.spec()) for job in suite.jobs]
    items = [(k, {**s, "method": "crash"} if s["seed"] == crash_seed else s) for k, s in items]
    for key, outcome in runner.run(_crash_or_run, items):
        records.append((key, outcome))
    by_key = dict(records)
    assert len(by_key) == 3
    for key, spec in items:
        if spec["method"] == "crash":
            assert by_key[key]["status"] == "failed" and by_key[key]["error"]["type"] == "WorkerCrashed"
        else:
            assert by_key[key]["status"] == "ok"


def test_a_worker_crash_isolates_only_the_jobs_the_pool_may_have_held(tmp_path, caplog):
    """One crashing job among 12: the jobs queued behind it go to a fresh pool of full size (all 10 ran one at a time,
    which halved a large suite's throughput for the rest of the run)."""
    import logging

    from lidarkit.bench import executors

    suite = load_suite(suite_file(tmp_path, """
        seeds: 12
        experiments:
          - task: selftest
            dataset: {kind: synthetic}
            methods: [{name: random_walk, params: {steps: 5}}]
        """))
    items = [(job.key(), {**job.spec(), "method": "crash"} if job.seed == 1 else job.spec()) for job in suite.jobs]
    with caplog.at_level(logging.WARNING, logger="lidarkit.bench.executors"):
        outcomes = dict(executors.ProcessExecutor(workers=2).run(_crash_or_run, items))
    assert len(outcomes) == 12 and sum(o["status"] == "ok" for o in outcomes.values()) == 11
    said = [r.getMessage() for r in caplog.records if "a worker process died" in r.getMessage()]
    assert said and all("one at a time" in m for m in said)
    held = [int(m.split("re-running the ")[1].split(" ")[0]) for m in said]
    assert max(held) <= 3, said  # at most one job per worker and one queued: never the whole rest of the suite


def _crash_or_run(spec):
    if spec["method"] == "crash":
        os._exit(3)  # like a C extension aborting the process
    from lidarkit.bench.worker import execute_job

    return execute_job(spec)


def test_dask_executor_on_an_existing_cluster_address(tmp_path):
    """``--address``: jobs go to a running scheduler (here a LocalCluster the test starts) and results match."""
    distributed = pytest.importorskip("distributed")
    import logging

    suite = load_suite(suite_file(tmp_path, TINY))
    run_suite(suite, tmp_path / "serial", executor="serial")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None,
                                  silence_logs=logging.ERROR) as cluster:
        summary = run_suite(suite, tmp_path / "remote", executor="dask", address=cluster.scheduler_address)
        assert (summary.ran, summary.ok, summary.failed) == (8, 6, 2)
        again = run_suite(suite, tmp_path / "remote", executor="dask", address=cluster.scheduler_address)
        assert (again.skipped, again.ran) == (6, 2)  # resume works the same on a cluster
    strip = lambda recs: {k: {**v, "error": v["error"] and {**v["error"], "traceback": ""}} for k, v in recs.items()}  # noqa: E731
    assert strip(comparable(tmp_path / "remote")) == strip(comparable(tmp_path / "serial"))


def test_a_local_dask_cluster_starts_no_more_workers_than_jobs(tmp_path):
    """``-e dask --workers 8`` on a 2-job suite started 8 worker processes; the process pool stops at the job count."""
    pytest.importorskip("distributed")
    from lidarkit.bench.executors import make_executor
    from lidarkit.bench.worker import execute_job

    job = load_suite(suite_file(tmp_path, TINY)).jobs[0]
    executor = make_executor("dask", workers=8)
    try:
        (key, outcome), = executor.run(execute_job, [("only", job.spec())])
        assert len(executor.cluster.workers) == 1
    finally:
        executor.close()
    assert key == "only" and outcome["status"] == "ok"
    from lidarkit.bench.executors import local_dask_workers

    assert [local_dask_workers(8, 2), local_dask_workers(8, 20), local_dask_workers(3, 3)] == [2, 8, 3]
    assert local_dask_workers(None, 1) == 1 and local_dask_workers(None, 50) <= 2  # (default: up to 2)


def test_unknown_executor_and_misplaced_address_are_config_errors(tmp_path):
    from lidarkit.errors import ConfigError

    suite = load_suite(suite_file(tmp_path, TINY))
    with pytest.raises(ConfigError, match="unknown executor 'threads'"):
        run_suite(suite, tmp_path / "a", executor="threads")
    with pytest.raises(ConfigError, match="^address: only applies to the dask executor"):
        run_suite(suite, tmp_path / "b", executor="process", address="tcp://127.0.0.1:8786")
    with pytest.raises(ConfigError, match="^workers: the serial executor runs one job at a time; 2 workers"):  # it was ignored
        run_suite(suite, tmp_path / "b", executor="serial", workers=2)
    for address in ("notanaddress", "tcp://127.0.0.1", "tls://host:99999"):  # distributed's ValueError traceback, after suite.json
        with pytest.raises(ConfigError, match=rf"^address: '{address}' is not a scheduler address"):
            run_suite(suite, tmp_path / "b", executor="dask", address=address)
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()  # refused before writing anything


def test_a_folder_another_bench_is_running_in_is_refused(tmp_path):
    """Two runs on one folder ran every job twice and one's report took the other's title: the second is refused,
    naming the process that holds the folder; the lock goes with that process."""
    from lidarkit.bench.runner import folder_lock
    from lidarkit.errors import OutputError

    suite = load_suite(suite_file(tmp_path, TINY))
    out = tmp_path / "out"
    with folder_lock(out):
        with pytest.raises(OutputError, match=rf"another lidarkit bench is running in this folder \(pid {os.getpid()}\)"):
            run_suite(suite, out, executor="serial")
        assert not (out / "suite.json").exists()
    summary = run_suite(suite, out, executor="serial")  # released: the next run goes ahead
    assert summary.ran == summary.total
    # a holder killed with SIGKILL leaves the lock file but not the lock
    holder = subprocess.Popen([sys.executable, "-c", "import sys, time; from pathlib import Path; "
                               "from lidarkit.bench.runner import folder_lock; lock = folder_lock(Path(sys.argv[1])); lock.__enter__(); "
                               "print('held', flush=True); time.sleep(60)", str(out)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        with pytest.raises(OutputError, match=rf"\(pid {holder.pid}\)"):
            run_suite(suite, out, executor="serial")
    finally:
        holder.kill()
        holder.wait()
    assert run_suite(suite, out, executor="serial").total == summary.total


def test_job_warnings_go_into_the_result_and_the_report(tmp_path, capsys):
    from lidarkit.bench.report import build_report

    suite = load_suite(suite_file(tmp_path, """
        experiments:
          - task: selftest
            dataset: {kind: synthetic}
            methods: [{name: sleep, params: {seconds: 0, log_warning: "odd input, continuing"}}]
        """))
    run_suite(suite, tmp_path / "out", executor="serial")
    (record,) = load_results(tmp_path / "out")
    assert record["status"] == "ok"
    assert record["warnings"] == ["WARNING lidarkit.bench.tasks.selftest: odd input, continuing"]
    assert "odd input" not in capsys.readouterr().err  # captured, not printed over the progress bar
    report = build_report(tmp_path / "out", plots=False)
    assert "odd input, continuing" in report.html_path.read_text()


def test_bench_dry_run_lists_jobs_and_runs_nothing(tmp_path, capsys):
    from lidarkit.cli import main

    path = suite_file(tmp_path, TINY)
    with pytest.raises(SystemExit) as exc:
        main(["bench", str(path), "--out", str(tmp_path / "out"), "--dry-run"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    suite = load_suite(path)
    assert all(job.key() in out for job in suite.jobs)
    assert not (tmp_path / "out").exists()


def test_a_forced_dry_run_does_not_call_the_jobs_it_would_rerun_done(tmp_path, capsys):
    """``--dry-run --force`` showed done=yes for the finished jobs, which --force runs again."""
    from lidarkit.cli import main

    path = suite_file(tmp_path, TINY)
    run_suite(load_suite(path), tmp_path / "out", executor="serial")  # 6 ok, 2 failed (retried anyway)
    for flags, done in (([], "yes"), (["--force"], "rerun")):
        with pytest.raises(SystemExit) as exc:
            main(["bench", str(path), "--out", str(tmp_path / "out"), "--dry-run", *flags])
        assert exc.value.code == 0
        rows = [line.split("│") for line in capsys.readouterr().out.splitlines() if line.count("│") == 7]
        cells = [row[-2].strip() for row in rows if row[1].strip()]  # (a job's first line: its key; then wrapped lines)
        assert sorted(cells) == ["", ""] + [done] * 6


def test_a_dataset_warning_reaches_every_job_that_uses_the_dataset(tmp_path):
    """The Freiburg data warns on loading (a negative range kept); the dataset is cached per worker, so the warning went
    to the first job of each worker only and the report's warnings changed with the executor."""
    from conftest import shared_path

    path = suite_file(tmp_path, f"""
name: warned
seeds: [0, 1, 2]
experiments:
  - name: e
    task: pf
    dataset: {{kind: landmarks, path: "{shared_path('pf', 'robot_mapping_stachniss')}"}}
    methods: [{{name: particle_filter, params: {{n_particles: 50}}}}]
""")
    run_suite(load_suite(path), tmp_path / "out", executor="serial")
    records = load_results(tmp_path / "out")
    assert len(records) == 3
    assert all(any("kept negative range" in w for w in r["warnings"]) for r in records), [r["warnings"] for r in records]


@pytest.mark.slow
def test_a_lost_dask_scheduler_stops_the_run_in_one_line_and_keeps_what_finished(tmp_path):
    """An external scheduler killed mid-run turned every remaining job into a recorded failure (87 of 108, 253 log
    lines, exit code 0, a report picking the best method among the few that ran)."""
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    bin_dir = Path(sys.executable).parent
    address = f"tcp://127.0.0.1:{port}"
    scheduler = subprocess.Popen([str(bin_dir / "dask"), "scheduler", "--port", str(port), "--no-dashboard"],
                                 stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    worker = None
    try:
        time.sleep(4)
        worker = subprocess.Popen([str(bin_dir / "dask"), "worker", address, "--nworkers", "1", "--nthreads", "1", "--no-dashboard"],
                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(4)
        suite = tmp_path / "suite.yaml"
        suite.write_text(textwrap.dedent("""
            seeds: 30
            experiments:
              - {name: e, task: selftest, dataset: {kind: synthetic}, methods: [{name: sleep, params: {seconds: 0.3}}]}
        """))
        run = subprocess.Popen([sys.executable, "-m", "lidarkit.cli", "bench", str(suite), "--out", str(tmp_path / "out"), "-e", "dask",
                                "--address", address, "--no-report"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not list((tmp_path / "out" / "jobs").glob("*.json")):
            time.sleep(0.2)  # some jobs done, others still to run
        scheduler.kill()
        out, err = run.communicate(timeout=120)
    finally:
        for proc in (scheduler, worker):
            if proc is not None and proc.poll() is None:
                proc.kill()
                proc.wait()
    assert run.returncode == 1, err
    lines = [line for line in err.splitlines() if line.startswith("error:")]
    assert len(lines) == 1 and "lost the Dask scheduler" in lines[0] and "Traceback" not in err
    records = load_results(tmp_path / "out")
    assert records and all(r["status"] == "ok" for r in records) and len(records) < 30


def test_bench_progress_lines_where_no_bar_can_be_drawn(tmp_path, capsys):
    """stderr to a log or CI: nothing was printed until the run ended (71 of 108 jobs done, the log empty)."""
    from lidarkit.cli import main

    suite = tmp_path / "s.yaml"
    suite.write_text(textwrap.dedent("""
        seeds: 20
        experiments:
          - {name: e, task: selftest, dataset: {kind: synthetic}, methods: [{name: sleep, params: {seconds: 0.01}}]}
    """))
    with pytest.raises(SystemExit) as exc:
        main(["bench", str(suite), "--out", str(tmp_path / "out"), "-e", "serial", "--no-report"])
    assert exc.value.code in (0, None)
    err = capsys.readouterr().err
    assert "2/20 jobs (10 %)" in err and "20/20 jobs (100 %)" in err


def test_no_progress_runs_bench_and_baseline_without_progress_output(tmp_path, capsys):
    """`lidarkit bench SUITE --no-progress` was refused with a box ("No such option"), where odometry and sim take
    it; bench and baseline record / check now run with nothing on stderr, and say a failed job still."""
    from conftest import cli_exit_code

    suite = suite_file(tmp_path, """
        seeds: 20
        experiments:
          - {name: e, task: selftest, dataset: {kind: synthetic}, methods: [{name: sleep, params: {seconds: 0.0}}]}
        """)
    assert cli_exit_code(["bench", str(suite), "--out", str(tmp_path / "quiet"), "-e", "serial", "--no-report",
                          "--no-progress"]) == 0
    out, err = capsys.readouterr()
    assert err == "" and "20 jobs: 0 already done, 20 run now (20 ok, 0 failed)" in out
    assert cli_exit_code(["bench", str(suite), "--out", str(tmp_path / "shown"), "-e", "serial", "--no-report",
                          "--progress"]) == 0
    assert "20/20 jobs (100 %)" in capsys.readouterr().err  # (the default, as before: lines where no bar is drawn)
    failing = suite_file(tmp_path, """
        experiments:
          - {name: e, task: selftest, dataset: {kind: synthetic}, methods: [{name: fail, params: {message: boom 7}}]}
        """)
    assert cli_exit_code(["bench", str(failing), "--out", str(tmp_path / "failing"), "-e", "serial", "--no-report",
                          "--no-progress"]) == 0
    assert capsys.readouterr().err.splitlines() == ["failed fail(message=boom 7) on synthetic (seed 0): RuntimeError: boom 7"]
    walk = suite_file(tmp_path, """
        experiments:
          - {name: walk, task: selftest, dataset: {kind: synthetic, name: synth}, methods: [random_walk]}
        """)
    assert cli_exit_code(["baseline", "record", str(walk), "--out", str(tmp_path / "bl"), "--repeats", "1",
                          "--no-progress"]) == 0
    assert capsys.readouterr().err == ""
    assert cli_exit_code(["baseline", "check", str(tmp_path / "bl"), "--no-progress"]) == 0
    out, err = capsys.readouterr()
    assert err == "" and "baseline check passed: 1 pinned jobs" in out


def test_library_arguments_are_named_as_the_caller_wrote_them(tmp_path, capsys):
    """A suite file name for the suite raised AttributeError, None for a path TypeError, and workers=0 in the library
    was called "--workers" (the CLI's name): each is a one-line ConfigError naming the argument."""
    from lidarkit.bench.report import build_report
    from lidarkit.errors import ConfigError
    from conftest import cli_exit_code

    path = suite_file(tmp_path, TINY)
    calls = {
        "suite: must be a Suite (load_suite(path) reads one), got str 'suite.yaml'":
            lambda: run_suite("suite.yaml", tmp_path / "a", executor="serial"),
        "out_dir: must be a path, got NoneType None": lambda: run_suite(load_suite(path), None, executor="serial"),
        "path: must be a path, got NoneType None": lambda: load_suite(None),
        "out_dir: must be a path, got int 3": lambda: build_report(3),
        "workers: must be >= 1, got 0": lambda: run_suite(load_suite(path), tmp_path / "a", executor="serial", workers=0),
    }
    for message, call in calls.items():
        with pytest.raises(ConfigError) as info:
            call()
        assert str(info.value) == message
    assert not (tmp_path / "a").exists()
    capsys.readouterr()
    assert cli_exit_code(["bench", str(path), "--out", str(tmp_path / "a"), "--workers", "0"]) == 1
    assert capsys.readouterr().err.strip() == "error: --workers: must be >= 1, got 0"


def test_a_folder_of_other_files_is_refused_and_kept(tmp_path, capsys):
    """`lidarkit bench s.yaml --out P` into a folder of the user's own files (no suite.json, no jobs/) replaced its
    report.md and removed plots/figure1.png and tables/ape_rmse.md, exit 0. Such a folder is refused, untouched; a
    new, an empty or an earlier run's folder is taken."""
    from lidarkit.errors import OutputError
    from conftest import cli_exit_code

    path = suite_file(tmp_path, TINY)
    mine = tmp_path / "mine"
    for name in ("report.md", "plots/figure1.png", "tables/ape_rmse.md"):
        (mine / name).parent.mkdir(parents=True, exist_ok=True)
        (mine / name).write_text(f"my {name}")
    before = sorted(str(p.relative_to(mine)) for p in mine.rglob("*"))
    message = f"{mine}: holds other files (plots, report.md, tables) and no results of an earlier run (suite.json, jobs/): give a new or empty folder"
    with pytest.raises(OutputError) as info:
        run_suite(load_suite(path), mine, executor="serial")
    assert str(info.value) == message
    capsys.readouterr()
    assert cli_exit_code(["bench", str(path), "--out", str(mine), "--executor", "serial"]) == 1
    assert capsys.readouterr().err.strip() == f"error: {message}"
    assert sorted(str(p.relative_to(mine)) for p in mine.rglob("*")) == before
    assert all((mine / name).read_text() == f"my {name}" for name in before if (mine / name).is_file())

    (tmp_path / "empty").mkdir()
    assert run_suite(load_suite(path), tmp_path / "empty", executor="serial").ran == 8
    assert run_suite(load_suite(path), tmp_path / "empty", executor="serial").skipped == 6  # (the 2 failed run again)


def test_a_report_that_cannot_be_written_says_the_jobs_are_done_and_how_to_rebuild_it(tmp_path):
    """Every job finished but report.html could not be written (`ulimit -f 50`): the one line named the file only,
    not that the results are kept nor that `lidarkit report OUT` rebuilds the report (an interrupt says both)."""
    import resource

    path = tmp_path / "s.yaml"
    path.write_text(textwrap.dedent("""
        name: tiny
        seeds: 2
        experiments:
          - {name: st, task: selftest, dataset: {kind: synthetic, name: syn}, methods: [random_walk]}
    """))
    out = tmp_path / "b1"

    def bench(*extra: str) -> subprocess.CompletedProcess:  # files up to 50 kB: the jobs' results fit, the report does not
        return subprocess.run([sys.executable, "-m", "lidarkit", "bench", str(path), "--out", str(out), "-e", "serial", *extra],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, timeout=300,
                              preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_FSIZE, (50_000, 50_000)))

    done = bench()
    assert done.returncode == 1 and "2 jobs: 0 already done, 2 run now (2 ok, 0 failed)" in done.stdout
    assert done.stderr.splitlines()[-1] == (
        f"error: {out}/report.html: cannot write: file too large for the file system; every job of the run is done "
        f"(results in {out}/jobs); no report was written (`lidarkit report {out}` writes it from the finished jobs)")
    assert len(load_results(out)) == 2 and not (out / "report.html").exists()
    rebuilt = subprocess.run([sys.executable, "-m", "lidarkit", "report", str(out)], stdout=subprocess.PIPE, text=True, timeout=300)
    assert rebuilt.returncode == 0 and (out / "report.html").stat().st_size > 50_000
    done = bench("--force")  # an earlier report stays: said to be from before this run
    assert done.returncode == 1 and done.stderr.splitlines()[-1].endswith(
        f"(results in {out}/jobs); {out}/report.html is from before this run (`lidarkit report {out}` rebuilds it from the "
        "finished jobs)")


def test_a_report_path_in_the_way_is_refused_before_the_jobs(tmp_path, capsys):
    """A folder named report.html (or a file named plots) was found after every job had run, and the message called the
    folder "report.html ... from before this run"."""
    from conftest import cli_exit_code

    import shutil

    path = suite_file(tmp_path, TINY)
    done = tmp_path / "done"
    assert cli_exit_code(["bench", str(path), "--out", str(done), "--executor", "serial"]) == 0
    for name, kind in (("report.html", "folder"), ("plots", "file")):
        out = tmp_path / f"out_{kind}"
        shutil.copytree(done, out)
        shutil.rmtree(out / name) if (out / name).is_dir() else (out / name).unlink()
        (out / name).mkdir() if kind == "folder" else (out / name).write_text("mine\n")
        before = {p.name: p.stat().st_mtime_ns for p in (out / "jobs").iterdir()}
        capsys.readouterr()
        assert cli_exit_code(["bench", str(path), "--out", str(out), "--executor", "serial", "--force"]) == 1
        err = capsys.readouterr().err.strip()
        assert err.startswith(f"error: {out / name}: cannot ") and len(err.splitlines()) == 1
        assert {p.name: p.stat().st_mtime_ns for p in (out / "jobs").iterdir()} == before  # (no job ran again)


def test_library_arguments_of_a_wrong_type_are_config_errors_naming_them(tmp_path):
    """run_suite(force="no") counted as true (every finished job ran again) and workers="2" raised a bare TypeError
    ('<' not supported between 'str' and 'int'): each is a one-line ConfigError naming the argument, before a run."""
    from lidarkit.errors import ConfigError

    suite = load_suite(suite_file(tmp_path, TINY))
    done = run_suite(suite, tmp_path / "out", executor="serial")
    assert (done.skipped, done.ran) == (0, 8)
    calls = {
        "force: must be True or False, got str 'no'": {"executor": "serial", "force": "no"},
        "force: must be True or False, got int 1": {"executor": "serial", "force": 1},
        "workers: must be an integer, got str '2'": {"executor": "process", "workers": "2"},
        "workers: must be an integer, got float 2.0": {"executor": "process", "workers": 2.0},
    }
    for message, kwargs in calls.items():
        with pytest.raises(ConfigError) as info:
            run_suite(suite, tmp_path / "out", **kwargs)
        assert str(info.value) == message
    again = run_suite(suite, tmp_path / "out", executor="serial", force=False)
    assert (again.skipped, again.ran) == (6, 2)  # (the 2 failed jobs are retried, the 6 finished ones kept)


def test_a_job_with_many_warnings_keeps_its_first_and_last_ones_and_counts_those_between(tmp_path, monkeypatch):
    """A job's warnings were capped at 50 without a word: an odometry run warning on each of 59 frames lost frames
    51-59 and its closing summary. The result keeps the first 40 and the last 10, and says how many it left out
    between them; the report lists that line too."""
    import logging

    from lidarkit.bench import tasks as bench_tasks
    from lidarkit.bench.report import build_report
    from lidarkit.bench.tasks import Metric, Task, TaskOutput, register_task

    monkeypatch.setattr(bench_tasks, "_REGISTERED", {})
    monkeypatch.setattr(bench_tasks, "_INSTANCES", {})
    log = logging.getLogger("lidarkit.odometry.runner")

    @register_task("many_warnings_test_task")
    class ManyWarnings(Task):
        dataset_kinds = ("synthetic",)
        metrics = (Metric("err_m", "error [m]"),)

        def run(self, job):
            for frame in range(1, 60):
                log.warning("frame %d: did not converge; using the constant-velocity motion instead", frame)
            log.warning("59 of 59 frames did not converge")
            return TaskOutput(metrics={"err_m": 1.0})

    suite = load_suite(suite_file(tmp_path, """
        experiments:
          - {task: many_warnings_test_task, dataset: {kind: synthetic}, methods: [a]}
        """))
    run_suite(suite, tmp_path / "out", executor="serial")
    (record,) = load_results(tmp_path / "out")
    said = [w.removeprefix("WARNING lidarkit.odometry.runner: ") for w in record["warnings"]]
    assert len(said) == 51
    assert said[0] == "frame 1: did not converge; using the constant-velocity motion instead"
    assert said[39].startswith("frame 40:")
    assert said[40] == "... and 10 more warnings, not kept (the job's first 40 and last 10 are)"
    assert [w.split(":")[0] for w in said[41:50]] == [f"frame {k}" for k in range(51, 60)]
    assert said[50] == "59 of 59 frames did not converge"
    report = (build_report(tmp_path / "out", plots=False).markdown_path).read_text()
    assert "seed 0: ... and 10 more warnings, not kept (the job's first 40 and last 10 are)" in report
    assert "seed 0: WARNING lidarkit.odometry.runner: 59 of 59 frames did not converge" in report


def test_max_jobs_below_one_is_refused_as_workers_is(tmp_path, capsys):
    """``--max-jobs 0`` exited 2 with typer's usage wording ("Invalid value for '--max-jobs': 0 is not in the range
    x>=1") where ``--workers 0`` exits 1 with one line; load_suite(path, max_jobs="2") raised TypeError "'>' not
    supported"."""
    from lidarkit.errors import ConfigError
    from conftest import cli_exit_code

    path = suite_file(tmp_path, TINY)
    for value in ("0", "-3"):
        assert cli_exit_code(["bench", str(path), "--out", str(tmp_path / "a"), "--max-jobs", value, "--dry-run"]) == 1
        assert capsys.readouterr().err.strip() == f"error: --max-jobs: must be >= 1, got {value}"
    for value, message in (("2", "must be an integer, got str '2'"), (0, "must be >= 1, got 0"),
                           (True, "must be an integer, got bool True")):
        with pytest.raises(ConfigError) as info:
            load_suite(path, max_jobs=value)
        assert str(info.value) == f"max_jobs: {message}"
    assert len(load_suite(path, max_jobs=8).jobs) == 8  # (the limit itself passes)
    assert not (tmp_path / "a").exists()


def test_a_progress_callback_that_is_not_a_function_is_refused_before_anything_is_written(tmp_path):
    """``run_suite(suite, out, on_start=5)`` raised TypeError "'int' object is not callable" after suite.json had been
    rewritten (and with ``on_result`` after the first job had run)."""
    from lidarkit.errors import ConfigError

    suite = load_suite(suite_file(tmp_path, TINY))
    for name, value, message in (("on_start", 5, "must be a function (or None), got int 5"),
                                 ("on_result", "print", "must be a function (or None), got str 'print'"),
                                 ("job_fn", None, "must be a function, got NoneType None")):
        with pytest.raises(ConfigError) as info:
            run_suite(suite, tmp_path / "out", executor="serial", **{name: value})
        assert str(info.value) == f"{name}: {message}"
        assert not (tmp_path / "out").exists()


def test_a_full_disk_at_the_folder_lock_is_one_line(tmp_path, monkeypatch):
    """The lock's pid written on a full disk raised OSError through the progress display (a page of traceback)."""
    import errno

    from lidarkit.bench import runner
    from lidarkit.errors import OutputError

    def full(*args):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(runner.os, "pwrite", full)  # (a disk that fills at the lock file's first byte)
    out = tmp_path / "out"
    with pytest.raises(OutputError) as caught:
        run_suite(load_suite(suite_file(tmp_path, TINY)), out, executor="serial")
    assert str(caught.value) == f"{out}: cannot write the results folder (No space left on device)"
