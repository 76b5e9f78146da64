"""Harness overhead: N jobs through ``lidarkit bench`` executors vs the same job functions in a plain loop.

Two workloads of the built-in ``selftest`` task: ``sleep`` (fixed wall time per job, so any extra time is
the harness: expansion, keys, resume checks, atomic JSON writes with fsync, process start-up) and
``burn`` (CPU-bound numpy). For each: a plain ``for`` loop calling the job function, the harness with the
serial executor, the process pool with 1 worker (pure overhead incl. start-up) and with the default worker
count (the speed-up a user gets). Acceptance: harness wall time < 1.05 x the plain loop.

    .venv/bin/python benchmarks/harness_overhead.py [--jobs 32] [--sleep-s 0.5] [--burn-size 400] [--burn-repeats 100] [--dask]

Writes ``benchmarks/results/bench/harness_overhead.{md,json}``.
"""

from __future__ import annotations

import os

# One BLAS thread everywhere (this process and the workers inherit it): CPU-bound jobs then measure the
# harness, not thread oversubscription on a shared machine.
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import datetime as dt  # noqa: E402
import json  # noqa: E402
import shlex  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402
from pathlib import Path  # noqa: E402

from lidarkit import atomic  # noqa: E402
from lidarkit.bench.executors import ProcessExecutor, default_workers  # noqa: E402
from lidarkit.bench.jobs import Job  # noqa: E402
from lidarkit.bench.machine import describe_machine, machine_info  # noqa: E402
from lidarkit.bench.runner import run_suite  # noqa: E402
from lidarkit.bench.suite import Suite  # noqa: E402
from lidarkit.bench.tasks.selftest import run_selftest  # noqa: E402
from lidarkit.bench.worker import execute_job  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results" / "bench"


def make_suite(name: str, method: str, params: dict, n_jobs: int) -> Suite:
    jobs = [Job("selftest", name, "synthetic", {"kind": "synthetic"}, method, dict(params), seed=seed) for seed in range(n_jobs)]
    return Suite(name=name, path=None, jobs=jobs)


def plain_loop(suite: Suite) -> float:
    t0 = time.perf_counter()
    for job in suite.jobs:
        run_selftest(job.method, job.params, job.seed)
    return time.perf_counter() - t0


def through_harness(suite: Suite, executor: str, workers: int | None) -> float:
    with tempfile.TemporaryDirectory(prefix="lidarkit-overhead-") as tmp:
        t0 = time.perf_counter()
        summary = run_suite(suite, tmp, executor=executor, workers=workers)
        wall = time.perf_counter() - t0
    assert summary.ok == len(suite.jobs), summary.failures[:3]
    return wall


def measure(suite: Suite, configs: list[tuple[str, str, int | None]], repeats: int, cold_start_s: float) -> list[dict]:
    """Interleaved repeats (plain, harness configs, plain, ...); the minimum of each is reported (shared machine).

    The forkserver outlives a pool inside one Python process; a ``lidarkit bench`` run starts it once. ``main``
    starts it before timing, so every repeat finds it running, and process-pool rows add the cold start measured in
    a fresh interpreter (``cold_start_s``) to their minimum once.
    """
    times: dict[str, list[float]] = {"plain loop": []}
    for label, _, _ in configs:
        times[label] = []
    for _ in range(repeats):
        times["plain loop"].append(plain_loop(suite))
        for label, executor, workers in configs:
            times[label].append(through_harness(suite, executor, workers))
    plain = min(times["plain loop"])
    rows = []
    for (label, ts), executor in zip(times.items(), ["plain"] + [c[1] for c in configs]):
        wall = min(ts) + (cold_start_s if executor == "process" else 0.0)
        rows.append({"runner": label + (" (+ cold start)" if executor == "process" else ""), "wall_s": wall, "all_s": ts, "ratio": wall / plain})
    return rows


def _cold_start_child() -> None:
    """In a fresh interpreter: start a 1-worker pool as the harness does, run one empty job, print the seconds."""
    spec = Job("selftest", "startup", "synthetic", {"kind": "synthetic"}, "sleep", {"seconds": 0.0}).spec()
    t0 = time.perf_counter()
    with ProcessPoolExecutor(1, mp_context=ProcessExecutor(1).context) as pool:
        pool.submit(execute_job, spec).result()
    print(time.perf_counter() - t0)


def pool_cold_start_s(repeats: int = 3) -> float:
    """Median over fresh interpreters of :func:`_cold_start_child` (forkserver start, preload imports, one job)."""
    import statistics
    import subprocess

    values = []
    for _ in range(repeats):
        out = subprocess.run([sys.executable, __file__, "--cold-start-child"], check=True, capture_output=True, text=True)
        values.append(float(out.stdout.strip().splitlines()[-1]))
    return statistics.median(values)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=32, help="jobs per workload")
    parser.add_argument("--sleep-s", type=float, default=0.5, help="seconds per sleep job")
    parser.add_argument("--burn-size", type=int, default=400, help="matrix size of a burn job")
    parser.add_argument("--burn-repeats", type=int, default=100)
    parser.add_argument("--repeats", type=int, default=2, help="interleaved repetitions (minimum reported)")
    parser.add_argument("--dask", action="store_true", help="also time a local Dask cluster (1 worker)")
    parser.add_argument("--out", type=Path, default=RESULTS)
    parser.add_argument("--cold-start-child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.jobs < 1 or args.repeats < 1:  # (0 jobs wrote ratios of x1e6 and exited 0)
        parser.error("--jobs and --repeats must be >= 1")
    if args.cold_start_child:
        _cold_start_child()
        return 0
    cold_start = pool_cold_start_s()
    print(f"process pool cold start (fresh interpreter, 1 worker, one empty job): {cold_start:.2f} s", file=sys.stderr)

    # start the forkserver before any timing: the first process-pool repeat included its start, and when it was the
    # minimum (--repeats 1) the cold start was counted twice
    through_harness(make_suite("warm-up", "sleep", {"seconds": 0.0}, 1), "process", 1)

    n_workers = default_workers()
    configs = [("serial executor", "serial", None), ("process pool, 1 worker", "process", 1),
               (f"process pool, {n_workers} workers", "process", n_workers)]
    if args.dask:
        configs.append(("dask LocalCluster, 1 worker", "dask", 1))
    workloads = {
        f"sleep {args.sleep_s} s": make_suite("sleep", "sleep", {"seconds": args.sleep_s}, args.jobs),
        f"burn {args.burn_size}x{args.burn_size} x{args.burn_repeats}": make_suite(
            "burn", "burn", {"size": args.burn_size, "repeats": args.burn_repeats}, args.jobs),
    }
    results = {}
    for name, suite in workloads.items():
        print(f"{name}: {len(suite.jobs)} jobs", file=sys.stderr)
        results[name] = measure(suite, configs, args.repeats, cold_start)
        for row in results[name]:
            print(f"  {row['runner']:<28} {row['wall_s']:8.2f} s  x{row['ratio']:.3f}", file=sys.stderr)

    meta = {
        "command": "python benchmarks/harness_overhead.py " + " ".join(shlex.quote(a) for a in (argv if argv is not None else sys.argv[1:])),
        "date_utc": dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%d %H:%M"),
        "machine": machine_info(),
        "jobs_per_workload": args.jobs,
        "repeats": args.repeats,
        "pool_cold_start_s": cold_start,
        "blas_threads": os.environ.get("OMP_NUM_THREADS"),
    }
    args.out.mkdir(parents=True, exist_ok=True)
    atomic.write_text(args.out / "harness_overhead.json", json.dumps({"meta": meta, "results": results}, indent=1) + "\n")
    lines = [
        "# Harness overhead: `lidarkit bench` executors vs a plain loop",
        "",
        f"- command: `{meta['command']}`",
        f"- date: {meta['date_utc']} UTC",
        f"- machine: {describe_machine(meta['machine'])}",
        f"- {args.jobs} jobs per workload, {args.repeats} interleaved repeats, minimum wall time reported; "
        f"BLAS threads = {meta['blas_threads']}; ratio = wall time / plain loop (acceptance: < 1.05)",
        f"- process pool cold start (fresh interpreter: forkserver + preload imports + one empty job): {cold_start:.2f} s, "
        "a fixed cost per run, added to the process-pool rows (a warm-up job starts the forkserver, so every timed repeat finds it running)",
        "",
    ]
    for name, rows in results.items():
        lines += [f"## {name}", "", "| runner | wall [s] (min) | all repeats [s] | ratio vs plain loop |", "|---|---|---|---|"]
        lines += [f"| {r['runner']} | {r['wall_s']:.2f} | {', '.join(f'{t:.2f}' for t in r['all_s'])} | {r['ratio']:.3f} |" for r in rows]
        lines.append("")
    atomic.write_text(args.out / "harness_overhead.md", "\n".join(lines))
    print(f"wrote {args.out / 'harness_overhead.md'}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    from lidarkit.cli import run_script

    run_script(main)
