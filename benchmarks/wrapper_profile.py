"""Where the CPU of a lidarkit odometry run goes, per function: the profile behind ``wrapper_cost.md``'s ratios.

Runs ``lidarkit.odometry.run`` over the 10 KITTI 00 scans (../shared/data) with one variant, reading inline and
assessing in line (``prefetch=0, overlap=False``, so every call is in one thread), once to warm up and ``--runs`` times under cProfile with a
process-time clock (CPU of all threads, steadier than wall time on a shared machine), and writes the functions
by cumulative CPU time per frame.

    OMP_WAIT_POLICY=passive nice -n 10 .venv/bin/python benchmarks/wrapper_profile.py small_gicp [--runs 2]

Writes ``benchmarks/results/icp/wrapper_profile_VARIANT.txt``.
"""

from __future__ import annotations

import argparse
import cProfile
import datetime as dt
import io
import logging
import os
import pstats
import shlex
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "data" / "kitti_odometry"
RESULTS = REPO / "benchmarks" / "results" / "icp"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("variant")
    parser.add_argument("--runs", type=int, default=2)
    parser.add_argument("--lines", type=int, default=40)
    args = parser.parse_args()

    from lidarkit import atomic
    from lidarkit.bench.machine import describe_machine, machine_info
    from lidarkit.odometry import run

    logging.disable(logging.WARNING)
    spec = f"kitti:{DATA}?sequence=00"
    n_frames = len(run(spec, args.variant, prefetch=0, overlap=False).trajectory.poses_se3)
    profiler = cProfile.Profile(time.process_time)
    profiler.enable()
    for _ in range(args.runs):
        run(spec, args.variant, prefetch=0, overlap=False)
    profiler.disable()
    out = io.StringIO()
    pstats.Stats(profiler, stream=out).sort_stats("cumulative").print_stats(args.lines)
    omp = os.environ.get("OMP_WAIT_POLICY")
    niceness = os.nice(0)
    command = (f"OMP_WAIT_POLICY={omp} " if omp else "") + (f"nice -n {niceness} " if niceness else "") + \
        ".venv/bin/python benchmarks/wrapper_profile.py " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    header = (f"# {dt.datetime.now(dt.timezone.utc).isoformat(timespec='seconds')} on {describe_machine(machine_info())}, "
              f"load average {os.getloadavg()[0]:.1f}\n# `{command}`\n# {args.runs} runs x {n_frames} frames (cumtime / "
              f"{args.runs * n_frames} = CPU s per frame; per-frame calls: ncalls / {args.runs * n_frames})\n\n")
    RESULTS.mkdir(parents=True, exist_ok=True)
    atomic.write_text(RESULTS / f"wrapper_profile_{args.variant}.txt", header + relative_paths(out.getvalue()))


def relative_paths(text: str) -> str:
    """The profile's file names without this machine's folders (the repository, site-packages, the stdlib)."""
    import re
    import sysconfig

    text = text.replace(str(REPO) + os.sep, "")
    for key in ("purelib", "platlib", "stdlib"):
        folder = sysconfig.get_paths().get(key)
        if folder:
            text = text.replace(folder + os.sep, f"<{key}>/")
    return re.sub(r"/\S*/(site-packages|lib/python3\.\d+)/", r"<\1>/", text)


if __name__ == "__main__":
    from lidarkit.cli import run_script

    run_script(main)
