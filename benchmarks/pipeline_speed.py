"""Frame rate of ``kiss_like`` against kiss-icp and of ``genz`` against direct ``GenZICP`` calls, same run.

KITTI-size scans (the 10 KITTI seq-00 scans, ~120k points each), cached in memory first. Every repeat builds
fresh odometries and registers the sequence frame by frame, the methods interleaved per frame (the order
rotating) so load changes hit both members of a pair alike. genz and direct ``GenZICP`` run each in a fresh process on
the scans cached on disk, alternating (two GenZICP odometries in one process do not reproduce their
single-process poses), the same way ``benchmarks/ablation.py`` does. Reported per repeat and overall (total frames /
total seconds): frames/s and the ratio to the reference; plus the largest pose difference to the reference.

    PYTHONPATH=$PWD python benchmarks/pipeline_speed.py --repeats 5
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))
from ablation import GENZ_CHILD, GENZ_PARAMS, log, open_dataset  # noqa: E402

OUT = REPO / "benchmarks" / "results" / "registration" / "pipeline_speed.json"
PAIRS = {"kiss_like": "kiss-icp", "genz": "genz-icp (direct)"}


def build(name: str):
    from lidarkit.registration import get_icp

    m = get_icp("kiss") if name == "kiss-icp" else get_icp("pipeline", preset="kiss_like")
    m.reset()
    return m


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--methods", nargs="+", default=["kiss-icp", "kiss_like"])
    ap.add_argument("--out", type=Path, default=OUT)
    ap.add_argument("--no-genz", dest="genz", action="store_false", help="skip the genz pair")
    ap.add_argument("--profile", type=Path, help="instead: profile kiss_like on the scans (cProfile) and write the table here")
    a = ap.parse_args()
    load_start = [f"{x:.2f}" for x in os.getloadavg()]
    _, n, read, _ = open_dataset("kitti", 0, 10, a.data)
    frames = [read(i) for i in range(n)]
    if a.profile:
        return profile(frames, a.profile, a.repeats)
    names = a.methods
    per_repeat = []
    total = dict.fromkeys(names, 0.0)
    gaps = dict.fromkeys(PAIRS, 0.0)
    for rep in range(a.repeats):
        methods = {k: build(k) for k in names}
        spent = dict.fromkeys(names, 0.0)
        poses = {k: [] for k in names}
        for i, (points, times) in enumerate(frames):
            shift = (i + rep) % len(names)
            for k in names[shift:] + names[:shift]:
                t = time.perf_counter()
                poses[k].append(methods[k].register_frame(points, times))
                spent[k] += time.perf_counter() - t
        row = {k: {"fps": n / s} for k, s in spent.items()}
        for k, ref in PAIRS.items():
            if k in names and ref in names:
                row[k]["ratio_to_reference"] = spent[ref] / spent[k]
                gaps[k] = max(gaps[k], float(np.abs(np.stack(poses[k]) - np.stack(poses[ref])).max()))
        per_repeat.append(row)
        for k in names:
            total[k] += spent[k]
        log(f"repeat {rep + 1}/{a.repeats}: " + ", ".join(f"{k} {v['fps']:.2f} fps" for k, v in row.items()))
    genz_poses = {}
    with tempfile.TemporaryDirectory(prefix="lidarkit-speed-") as tmp:
        for i, (points, _) in enumerate(frames):
            np.save(Path(tmp) / f"{i:05d}.npy", points)
        env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}
        for rep in range(a.repeats if a.genz else 0):
            row = per_repeat[rep]
            for mode, key in ((("direct", "genz-icp (direct)"), ("lidarkit", "genz"))[:: 1 if rep % 2 == 0 else -1]):
                done = subprocess.run([sys.executable, "-c", GENZ_CHILD, tmp, mode, json.dumps(GENZ_PARAMS), str(n)],
                                      env=env, capture_output=True, text=True, check=True)
                s = json.loads(done.stdout.strip().splitlines()[-1])["seconds"]
                row[key] = {"fps": n / s}
                total[key] = total.get(key, 0.0) + s
                p = np.load(Path(tmp) / f"poses_{mode}.npy")
                gaps["genz"] = max(gaps["genz"], float(np.abs(p - genz_poses[mode]).max())) if mode in genz_poses else gaps["genz"]
                genz_poses[mode] = p
            row["genz"]["ratio_to_reference"] = row["genz"]["fps"] / row["genz-icp (direct)"]["fps"]
            gaps["genz_vs_direct"] = max(gaps.get("genz_vs_direct", 0.0), float(np.abs(genz_poses["lidarkit"] - genz_poses["direct"]).max()))
            log(f"genz repeat {rep + 1}/{a.repeats}: ratio {row['genz']['ratio_to_reference']:.3f}")
    if "genz" in total:
        gaps["genz"] = gaps.pop("genz_vs_direct")
        names = [*names, "genz-icp (direct)", "genz"]
    overall = {k: {"fps": n * a.repeats / s} for k, s in total.items()}
    for k, ref in PAIRS.items():
        if k in names and ref in names:
            overall[k]["ratio_to_reference"] = total[ref] / total[k]
            overall[k]["max_abs_pose_difference_to_reference"] = gaps[k]
            ratios = [row[k]["ratio_to_reference"] for row in per_repeat if k in row and "ratio_to_reference" in row[k]]
            overall[k]["ratio_per_repeat_median_min_max"] = [float(np.median(ratios)), float(np.min(ratios)), float(np.max(ratios))]
    record = {
        "date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "command": "python benchmarks/pipeline_speed.py " + " ".join(sys.argv[1:]),
        "machine": f"{platform.machine()}, {os.cpu_count()} cores, load {load_start} at the start, {[f'{x:.2f}' for x in os.getloadavg()]} at the end (1/5/15 min)",
        "scans": n, "mean_points_per_scan": float(np.mean([len(p) for p, _ in frames])), "repeats": a.repeats,
        "overall": overall, "per_repeat": per_repeat,
    }
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps(record, indent=1) + "\n")
    print(json.dumps(overall, indent=1))


def profile(frames, out: Path, repeats: int) -> None:
    """Where kiss_like's time goes: cProfile over ``repeats`` passes of the scans, cumulative and own time."""
    import cProfile
    import io
    import pstats

    prof = cProfile.Profile()
    wall = 0.0
    for _ in range(repeats):
        m = build("kiss_like")
        t = time.perf_counter()
        prof.enable()
        for points, times in frames:
            m.register_frame(points, times)
        prof.disable()
        wall += time.perf_counter() - t
    n = len(frames) * repeats
    text = io.StringIO()
    text.write(f"# kiss_like on the 10 KITTI scans, {repeats} passes: {n / wall:.2f} frames/s under cProfile "
               f"({time.strftime('%Y-%m-%dT%H:%M:%SZ', time.gmtime())}, {os.cpu_count()} cores, "
               f"load {[f'{x:.2f}' for x in os.getloadavg()]})\n")
    text.write("# command: python benchmarks/pipeline_speed.py --repeats %d --profile %s\n\n" % (repeats, out.name))
    for key in ("cumulative", "tottime"):
        text.write(f"## sorted by {key}\n")
        stats = pstats.Stats(prof, stream=text)
        stats.sort_stats(key).print_stats(25)
    out.parent.mkdir(parents=True, exist_ok=True)
    body = re.sub(r"/[^\s:(]*/(site-packages|lib/python3\.\d+)/", "", text.getvalue().replace(str(REPO) + "/", ""))  # no machine paths
    out.write_text("\n".join(line.rstrip() for line in body.splitlines()) + "\n")
    log(f"wrote {out}")


if __name__ == "__main__":
    from lidarkit.cli import run_script

    run_script(main)
