"""Harness overhead: N jobs through ``lidarkit bench`` executors vs the same job functions in a plain loop.

Two workloads of the built-in ``selftest`` task: ``sleep`` (fixed wall time per job, so any extra time is
the harness: expansion, keys, resume checks, atomic JSON writes with fsync, process start-up) and
``burn`` (CPU-bound numpy). For each: a plain ``for`` loop calling the job function, the harness with the
serial executor, the process pool with 1 worker (pure overhead incl. start-up) and with the default worker
count (the speed-up a user gets). Acceptance: harness wall time < 1.05 x the plain loop.

    .venv/bin/python benchmarks/harness_overhead.py [--jobs 32] [--sleep-s 0.5] [--burn-size 500] [--dask]

Writes ``benchmarks/results/bench/harness_overhead.{md,json}``.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import platform
import shlex
import sys
import tempfile
import time
from pathlib import Path

from lidarkit import atomic
from lidarkit.bench.executors import default_workers
from lidarkit.bench.jobs import Job
from lidarkit.bench.runner import run_suite
from lidarkit.bench.suite import Suite
from lidarkit.bench.tasks.selftest import run_selftest

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


def measure(suite: Suite, configs: list[tuple[str, str, int | None]]) -> list[dict]:
    rows = []
    plain = plain_loop(suite)
    rows.append({"runner": "plain loop", "wall_s": plain, "ratio": 1.0})
    for label, executor, workers in configs:
        wall = through_harness(suite, executor, workers)
        rows.append({"runner": label, "wall_s": wall, "ratio": wall / plain})
    plain_again = plain_loop(suite)  # bracket the harness runs: the machine is shared, load drifts
    rows.append({"runner": "plain loop (again)", "wall_s": plain_again, "ratio": plain_again / plain})
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=32, help="jobs per workload")
    parser.add_argument("--sleep-s", type=float, default=0.5, help="seconds per sleep job")
    parser.add_argument("--burn-size", type=int, default=500, help="matrix size of a burn job")
    parser.add_argument("--burn-repeats", type=int, default=30)
    parser.add_argument("--dask", action="store_true", help="also time a local Dask cluster (1 worker)")
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args(argv)

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
        results[name] = measure(suite, configs)
        for row in results[name]:
            print(f"  {row['runner']:<28} {row['wall_s']:8.2f} s  x{row['ratio']:.3f}", file=sys.stderr)

    meta = {
        "command": "python benchmarks/harness_overhead.py " + " ".join(shlex.quote(a) for a in (argv if argv is not None else sys.argv[1:])),
        "date_utc": dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%d %H:%M"),
        "machine": f"{platform.node()} {platform.machine()} {platform.system()} {platform.release()}, "
                   f"{os.cpu_count()} CPUs, python {platform.python_version()}",
        "load_average_1_5_15": list(os.getloadavg()),
        "jobs_per_workload": args.jobs,
    }
    args.out.mkdir(parents=True, exist_ok=True)
    atomic.write_text(args.out / "harness_overhead.json", json.dumps({"meta": meta, "results": results}, indent=1) + "\n")
    lines = [
        "# Harness overhead: `lidarkit bench` executors vs a plain loop",
        "",
        f"- command: `{meta['command']}`",
        f"- date: {meta['date_utc']} UTC",
        f"- machine: {meta['machine']}; load average {', '.join(f'{x:.1f}' for x in meta['load_average_1_5_15'])} "
        "(shared machine: other processes were running)",
        f"- {args.jobs} jobs per workload; ratio = wall time / plain loop wall time (acceptance: < 1.05 for the harness)",
        "",
    ]
    for name, rows in results.items():
        lines += [f"## {name}", "", "| runner | wall [s] | ratio vs plain loop |", "|---|---|---|"]
        lines += [f"| {r['runner']} | {r['wall_s']:.2f} | {r['ratio']:.3f} |" for r in rows]
        lines.append("")
    atomic.write_text(args.out / "harness_overhead.md", "\n".join(lines))
    print(f"wrote {args.out / 'harness_overhead.md'}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
