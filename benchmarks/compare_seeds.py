"""Paired comparisons over 10 simulated drives: kiss vs vanilla, kiss vs small_gicp, kiss vs a second kiss run.

    .venv/bin/python benchmarks/compare_seeds.py [--frames 40] [--beams 32] [--azimuths 1000] [--seeds 10] [--out benchmarks/results/statistics]

Runs a bench suite (one simulated street drive per seed; the job seed seeds the simulation) twice for kiss,
then ``lidarkit.eval.compare`` per seed on APE and KITTI-free metrics, and writes ``results.md`` + ``results.json``
with the per-(method) summaries (mean, std, median, Student-t's 95 % CI of the mean) and the Wilcoxon verdicts.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import sys
import tempfile
from pathlib import Path

SUITE = """
name: compare-seeds
seeds: {seeds}
experiments:
  - name: sim
    task: odometry
    dataset: {{kind: sim_lidar, scene: street, n_frames: {frames}, n_beams: {beams}, n_azimuths: {azimuths}, accel_time_s: 0.0, name: sim street}}
    methods: {methods}
"""

METHODS = {"kiss": "kiss", "vanilla": "{name: vanilla, params: {voxel_size_m: 0.5}}", "small_gicp": "small_gicp"}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=40)
    ap.add_argument("--beams", type=int, default=32)
    ap.add_argument("--azimuths", type=int, default=1000)
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/statistics"))
    ap.add_argument("--workers", type=int, default=1)
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="compare_seeds_"))
    try:
        _run(args, work)
    finally:  # (the bench runs, ~0.2 MB, stayed in /tmp after every run)
        import shutil

        shutil.rmtree(work, ignore_errors=True)


def _run(args, work: Path) -> None:
    from lidarkit import atomic
    from lidarkit.bench.machine import describe_machine, machine_info
    from lidarkit.bench.runner import run_suite
    from lidarkit.bench.suite import load_suite
    from lidarkit.eval import compare, summarize
    from lidarkit.eval.compare import load_bench_runs

    folders = {}
    for run_name, methods in (("main", list(METHODS.values())), ("kiss_again", ["kiss"])):
        path = work / f"{run_name}.yaml"
        path.write_text(SUITE.format(seeds=args.seeds, frames=args.frames, beams=args.beams, azimuths=args.azimuths, methods="[" + ", ".join(methods) + "]"))
        summary = run_suite(load_suite(path), work / run_name, executor="process" if args.workers > 1 else "serial",
                            workers=args.workers)
        print(f"{run_name}: {summary.ok} ok, {summary.failed} failed in {summary.wall_s:.0f} s", file=sys.stderr)
        folders[run_name] = work / run_name
    metrics = ("ape_rmse_m", "rpe_trans_rmse_m", "final_error_m")
    summaries = {}
    for label in ("kiss", "vanilla(voxel_size_m=0.5)", "small_gicp"):
        runs = load_bench_runs(folders["main"], label)
        summaries[label] = {m: summarize([v[m] for v in runs.values.values()], seed=0) for m in metrics}
    comparisons = []
    for a, fa, b, fb in (("kiss", "main", "vanilla(voxel_size_m=0.5)", "main"), ("kiss", "main", "small_gicp", "main"),
                         ("kiss", "main", "kiss", "kiss_again")):
        for m in metrics:
            comparisons.append(compare(folders[fa], folders[fb], method_a=a, method_b=b, metric=m).to_dict()
                               | {"run_b": fb})
    cmd = "python benchmarks/compare_seeds.py " + " ".join(sys.argv[1:])
    meta = {"command": cmd.strip(), "date_utc": dt.datetime.now(dt.timezone.utc).isoformat(timespec="minutes"),
            "machine": describe_machine(machine_info()),
            "frames": args.frames, "seeds": args.seeds}
    lines = [f"# Paired comparisons over {args.seeds} simulated drives ({args.frames} sweeps each)", "",
             f"Command: `{meta['command']}`; {meta['date_utc']}; {meta['machine']}.", "", *summary_lines(summaries)]
    lines += ["", "Paired Wilcoxon signed-rank tests (A - B per seed):", "",
              "| A | B | metric | mean A | mean B | p | effect | verdict |", "|---|---|---|---:|---:|---:|---:|---|"]
    for c in comparisons:
        lines.append(f"| {c['name_a']} | {c['name_b']} | {c['metric']} | {c['mean_a']:.4g} | {c['mean_b']:.4g} | "
                     f"{c['p_value']:.3g} | {c['effect_size']:+.2f} | {c['verdict']} |")
    atomic.write_text(args.out / "results.md", "\n".join(lines) + "\n")
    as_dicts = {label: {m: s.to_dict() for m, s in per.items()} for label, per in summaries.items()}
    atomic.write_text(args.out / "results.json", json.dumps({"meta": meta, "summaries": as_dicts,
                                                              "comparisons": comparisons}, indent=1) + "\n")
    print((args.out / "results.md").read_text())


def summary_lines(summaries: dict) -> list[str]:
    """The Markdown table of the per-method summaries (method -> metric -> :class:`~lidarkit.eval.Summary`), headed
    by the interval its CIs are (a table of results.json written before 2026-11-28 says "bootstrap": the rule then)."""
    from lidarkit.eval.statistics import BOOTSTRAP, ci_methods

    every = [s for per in summaries.values() for s in per.values()]
    method = ci_methods(every)
    confidence = f"{100 * every[0].confidence:g} %" if every else "95 %"
    interval = (f"seeded {confidence} {BOOTSTRAP} CI of the mean" if method == BOOTSTRAP
                else f"{confidence} CI of the mean, {method}" if method else "no CI: one seed")
    lines = [f"Per-method summaries over seeds (mean ± std, median, {interval}):", "",
             f"| method | metric | mean ± std | median | {confidence} CI |", "|---|---|---:|---:|---:|"]
    for label, per in summaries.items():
        for m, s in per.items():
            lines.append(f"| {label} | {m} | {s.mean:.4g} ± {s.std:.2g} | {s.median:.4g} | [{s.ci_low:.4g}, {s.ci_high:.4g}] |")
    return lines


if __name__ == "__main__":
    from lidarkit.cli import run_script

    run_script(main)
