"""Kill `lidarkit bench` at random moments and check what is left: corrupt results, orphan processes, resumability.

For each executor (process pool, Dask LocalCluster) and each signal (SIGKILL, SIGTERM to the lidarkit process;
SIGINT to its process group, like Ctrl-C), ``--repeats`` times:

1. start ``lidarkit bench`` on a suite of short sleep jobs, in its own session;
2. once the run has started (its ``suite.json`` exists; one trial in four: from the process start, i.e. also while
   it loads) wait a random delay (seeded) and send the signal; wait for the lidarkit process to end;
3. 5 s after it ended, list every process still alive in its session (orphans: pool workers, fork server,
   resource tracker, Dask nanny/worker);
4. parse every visible result file (corrupt = not complete lidarkit JSON);
5. rerun the same command without interruption: it must exit 0 with every job finished.

    python benchmarks/bench_kill.py [--repeats 20] [--out benchmarks/results/reliability]

Writes ``TAG.json`` (every trial) and ``TAG.md`` (summary table) under ``--out`` (``--tag``, default ``kill``). The test suite runs the same
code with one trial per signal (``tests/test_signals.py``).
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import os
import platform
import signal
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

SUITE = """
name: kill
seeds: {n_jobs}
experiments:
  - task: selftest
    dataset: {{kind: synthetic}}
    methods: [{{name: sleep, params: {{seconds: {job_s}}}}}]
"""


def session_processes(sid: int) -> list[tuple[int, str]]:
    """(pid, command) of every live process whose session id is ``sid`` (Linux /proc)."""
    found = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            stat = Path(f"/proc/{entry}/stat").read_text()
            fields = stat[stat.rindex(")") + 2:].split()
            state, session = fields[0], int(fields[3])
            if session == sid and state not in ("Z", "X"):
                cmd = Path(f"/proc/{entry}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
                found.append((int(entry), cmd.strip()[:160]))
        except (OSError, ValueError, IndexError):
            continue
    return found


def check_results(out: Path) -> tuple[int, int]:
    """(complete results, corrupt files) among the visible files of ``out/jobs``."""
    ok = corrupt = 0
    jobs = out / "jobs"
    for path in jobs.glob("*.json") if jobs.exists() else []:
        if path.name.startswith("."):
            continue  # a temporary file: never read as a result
        try:
            record = json.loads(path.read_text())
            assert record["schema"] == 1 and record["key"] + ".json" == path.name and record["status"] in ("ok", "failed")
            ok += 1
        except Exception:  # noqa: BLE001 - anything unreadable is corrupt
            corrupt += 1
    return ok, corrupt


def bench_cmd(suite: Path, out: Path, executor: str) -> list[str]:
    return [sys.executable, "-m", "lidarkit.cli", "bench", str(suite), "--out", str(out), "--executor", executor,
            "--workers", "2", "--no-report"]


def kill_trial(suite: Path, out: Path, executor: str, sig: signal.Signals, delay_s: float, n_jobs: int,
               from_run_start: bool = True, orphan_wait_s: float = 5.0) -> dict:
    """One trial (steps 1-5 of the module docstring) -> a dict of what was observed."""
    env = {**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    proc = subprocess.Popen(bench_cmd(suite, out, executor), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            start_new_session=True, env=env)
    sid = proc.pid
    t0 = time.monotonic()
    if from_run_start:
        while not (out / "suite.json").exists() and proc.poll() is None and time.monotonic() - t0 < 120:
            time.sleep(0.02)
    try:
        proc.wait(timeout=delay_s)
        finished_first = True
    except subprocess.TimeoutExpired:
        finished_first = False
        if sig == signal.SIGINT:
            os.killpg(sid, sig)  # Ctrl-C reaches the whole foreground process group
        else:
            os.kill(proc.pid, sig)
    t_sent = time.monotonic()
    try:
        proc.wait(timeout=60)
        hung = False
    except subprocess.TimeoutExpired:
        hung = True
        proc.kill()
        proc.wait()
    exit_s = time.monotonic() - t_sent
    stderr = proc.stderr.read().decode(errors="replace")
    deadline = time.monotonic() + orphan_wait_s
    while session_processes(sid) and time.monotonic() < deadline:
        time.sleep(0.1)
    orphans = session_processes(sid)
    for pid, _ in orphans:  # clean up so the next trial starts from nothing
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    n_ok, n_corrupt = check_results(out)
    lines = [line for line in stderr.splitlines() if line.strip() and "ETA" not in line and "━" not in line]
    rerun = subprocess.run(bench_cmd(suite, out, executor), capture_output=True, text=True, env=env, timeout=300)
    n_after, corrupt_after = check_results(out)
    return {
        "executor": executor,
        "signal": sig.name,
        "delay_s": round(delay_s, 3),
        "delay_from": "run start" if from_run_start else "process start",
        "finished_before_signal": finished_first,
        "returncode": proc.returncode,
        "hung": hung,
        "exit_after_signal_s": round(exit_s, 3),
        "results_before_rerun": n_ok,
        "n_jobs": n_jobs,
        "corrupt": n_corrupt + corrupt_after,
        "orphans": [cmd for _, cmd in orphans],
        "traceback": "Traceback" in stderr,
        "stderr_tail": stderr[-1200:] if "Traceback" in stderr else "",
        "message": lines[-1] if lines else "",
        "rerun_returncode": rerun.returncode,
        "rerun_complete": rerun.returncode == 0 and n_after == n_jobs,
        "elapsed_s": round(time.monotonic() - t0, 2),
    }


def expected_returncode(sig: signal.Signals) -> int:
    return -signal.SIGKILL if sig == signal.SIGKILL else 128 + int(sig)


def trial_ok(t: dict) -> bool:
    sig = signal.Signals[t["signal"]]
    # a signal that lands after the last result while the interpreter is exiting ends it with the default action
    done = t["finished_before_signal"] or (t["results_before_rerun"] == t["n_jobs"] and t["returncode"] in (0, -sig))
    code_ok = done or t["returncode"] == expected_returncode(sig)
    message_ok = sig == signal.SIGKILL or done or "interrupted" in t["message"]
    return (code_ok and message_ok and not t["hung"] and not t["corrupt"] and not t["orphans"] and not t["traceback"]
            and t["rerun_complete"])


def run(repeats: int, executors: list[str], signals: list[signal.Signals], seed: int, workdir: Path,
        n_jobs: int = 16, job_s: float = 0.4, max_delay_s: float = 8.0) -> list[dict]:
    import numpy as np

    rng = np.random.default_rng(seed)
    suite = workdir / "kill_suite.yaml"
    suite.write_text(textwrap.dedent(SUITE.format(n_jobs=n_jobs, job_s=job_s)))
    trials = []
    for executor in executors:
        for sig in signals:
            for i in range(repeats):
                out = workdir / f"{executor}_{sig.name}_{i}"
                from_run_start = bool(rng.uniform() >= 0.25)
                delay = float(rng.uniform(0.0, max_delay_s) if from_run_start else rng.uniform(0.2, 5.0))
                t = kill_trial(suite, out, executor, sig, delay, n_jobs, from_run_start)
                t["ok"] = trial_ok(t)
                trials.append(t)
                print(json.dumps(t), flush=True)
    return trials


def summary_markdown(trials: list[dict], command: str) -> str:
    rows = {}
    for t in trials:
        r = rows.setdefault((t["executor"], t["signal"]), {"n": 0, "killed": 0, "corrupt": 0, "orphans": 0, "tb": 0,
                                                           "bad_code": 0, "rerun": 0, "exit_s": []})
        r["n"] += 1
        r["killed"] += not t["finished_before_signal"]
        r["corrupt"] += t["corrupt"]
        r["orphans"] += len(t["orphans"])
        r["tb"] += t["traceback"]
        r["rerun"] += t["rerun_complete"]
        r["bad_code"] += not t["ok"]
        if not t["finished_before_signal"]:
            r["exit_s"].append(t["exit_after_signal_s"])
    lines = [f"Command: `{command}`  ",
             f"Date: {_dt.datetime.now(_dt.timezone.utc):%Y-%m-%d %H:%M} UTC; machine: {platform.node()} "
             f"({platform.machine()}, {os.cpu_count()} cpus, load {os.getloadavg()[0]:.1f}), Python {platform.python_version()}",
             "",
             "| executor | signal | trials | killed mid-run | corrupt files | orphans after 5 s | tracebacks | failed checks "
             "| reruns complete | exit after signal (median / max s) |",
             "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for (executor, sig), r in rows.items():
        import numpy as np

        ex = f"{np.median(r['exit_s']):.2f} / {max(r['exit_s']):.2f}" if r["exit_s"] else "-"
        lines.append(f"| {executor} | {sig} | {r['n']} | {r['killed']} | {r['corrupt']} | {r['orphans']} | {r['tb']} | "
                     f"{r['bad_code']} | {r['rerun']}/{r['n']} | {ex} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument("--executors", default="process,dask")
    parser.add_argument("--signals", default="SIGKILL,SIGTERM,SIGINT")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "reliability")
    parser.add_argument("--tag", default="kill", help="file stem of the results: TAG.json, TAG.md")
    args = parser.parse_args()
    sigs = [signal.Signals[s] for s in args.signals.split(",")]
    with tempfile.TemporaryDirectory(prefix="lidarkit-kill-") as tmp:
        trials = run(args.repeats, args.executors.split(","), sigs, args.seed, Path(tmp))
    command = "python benchmarks/bench_kill.py " + " ".join(sys.argv[1:])
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / f"{args.tag}.json").write_text(json.dumps({"command": command, "trials": trials}, indent=1) + "\n")
    (args.out / f"{args.tag}.md").write_text(summary_markdown(trials, command))
    print(summary_markdown(trials, command))
    sys.exit(0 if all(t["ok"] for t in trials) else 1)


if __name__ == "__main__":
    from lidarkit.cli import run_script

    run_script(main)
