"""Does kiss_like follow kiss-icp on a simulated sequence, and how sensitive is kiss-icp itself?

Runs kiss-icp, kiss-icp on input moved by a tiny offset (``--perturbation-m``, a chaos reference: how far two
runs that differ only by rounding drift apart) and the ``kiss_like`` pipeline on one simulated sequence
(``sim:SCENE?frames=N&seed=S``, the ablation's data), interleaved per frame. Writes per run the end error,
APE, KITTI drift and frame rate, and per pair the largest pose difference and the first frame above 1e-12 /
1e-9 / 1e-6 / 1e-3 m.

    PYTHONPATH=$PWD python benchmarks/kiss_divergence.py run --scene open --seed 0 --frames 300
    PYTHONPATH=$PWD python benchmarks/kiss_divergence.py report   # table of every result file
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

from lidarkit.atomic import write_text

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))
from ablation import log, open_dataset, score  # noqa: E402

OUT = REPO / "benchmarks" / "results" / "registration" / "kiss_divergence"
LEVELS = (1e-12, 1e-9, 1e-6, 1e-3)


def make(run: str):
    from lidarkit.registration import get_icp

    if run == "kiss_like":
        return get_icp("pipeline", preset="kiss_like")
    if run.startswith("kiss_like_"):  # kiss_like_kdtree: the plain nearest neighbour, not kiss-icp's 27-voxel rule
        return get_icp("pipeline", preset="kiss_like", map={"name": "voxel_hash", "search": run.split("_", 2)[2]})
    return get_icp("kiss")


def run(scene: str, seed: int, frames: int, runs: list[str], perturbation_m: float, out: Path) -> Path:
    _, n, read, gt = open_dataset(scene, seed, frames, REPO)
    methods = {r: make(r) for r in runs}
    for m in methods.values():
        m.reset()
    poses = {r: np.empty((n, 4, 4)) for r in runs}
    spent = dict.fromkeys(runs, 0.0)
    for i in range(n):
        points, times = read(i)
        order = runs[i % len(runs):] + runs[: i % len(runs)]
        for r in order:
            p = points + perturbation_m if r.startswith("kiss_perturbed") else points
            t = time.perf_counter()
            poses[r][i] = methods[r].register_frame(p, times)
            spent[r] += time.perf_counter() - t
        if (i + 1) % 50 == 0:
            log(f"{scene} seed {seed}: {i + 1}/{n}")
    rows = {r: {**score(poses[r], gt), "fps": n / spent[r]} for r in runs}
    pairs = {}
    for r in runs[1:]:
        gap = np.linalg.norm(poses[r][:, :3, 3] - poses[runs[0]][:, :3, 3], axis=1)
        pairs[f"{runs[0]} vs {r}"] = {
            "max_translation_difference_m": float(gap.max()),
            "max_abs_pose_matrix_difference": float(np.abs(poses[r] - poses[runs[0]]).max()),
            **{f"first_frame_above_{lv:g}": (int(np.argmax(gap > lv)) if (gap > lv).any() else None) for lv in LEVELS},
        }
    record = {
        "scene": scene, "seed": seed, "n_frames": n, "perturbation_m": perturbation_m,
        "date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "command": "python benchmarks/kiss_divergence.py " + " ".join(sys.argv[1:]),
        "machine": f"{platform.machine()}, {os.cpu_count()} cores, load {[f'{x:.2f}' for x in os.getloadavg()]}",
        "runs": rows, "pairs": pairs,
    }
    out.mkdir(parents=True, exist_ok=True)
    path = out / f"{scene}_seed{seed}_{n}.json"
    write_text(path, json.dumps(record, indent=1) + "\n")
    log(f"wrote {path}")
    return path


def _cell(x, spec: str) -> str:
    """A table figure; '-' where the run has none (a run under 100 m has no KITTI drift: a KeyError before)."""
    return "-" if x is None else format(x, spec)


def _pair(pairs: dict, a: str, b: str) -> dict:
    """The two runs' pair record in either order (``--runs kiss_like kiss`` names it 'kiss_like vs kiss': NaN columns before)."""
    return pairs.get(f"{a} vs {b}") or pairs.get(f"{b} vs {a}") or {}


def report(out: Path) -> str:
    lines = ["| sequence | kiss-icp drift % | kiss_like drift % | rel. difference | max pose difference kiss_like vs kiss-icp (m) | kiss-icp vs perturbed: first frame > 1 mm |",
             "|---|---|---|---|---|---|"]
    for path in sorted(out.glob("*.json")):
        r = json.loads(path.read_text())
        k, kl = r["runs"].get("kiss", {}).get("drift_pct"), r["runs"].get("kiss_like", {}).get("drift_pct")
        rel = abs(kl - k) / k if k and kl is not None else None
        pair = _pair(r["pairs"], "kiss", "kiss_like")
        pert = _pair(r["pairs"], "kiss", "kiss_perturbed")
        first = pert.get("first_frame_above_0.001", "-") if pert else "-"
        first = f"never in {r['n_frames']}" if first is None else first  # (printed "None")
        lines.append(f"| {r['scene']} seed {r['seed']} ({r['n_frames']}) | {_cell(k, '.3f')} | {_cell(kl, '.3f')} | {_cell(rel, '.1e')} | "
                     f"{_cell(pair.get('max_translation_difference_m'), '.1e')} | {first} |")
    text = "\n".join(lines)
    write_text(out / "README.md", "# kiss_like vs kiss-icp on simulated sequences\n\n" + text + "\n")
    return text


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=OUT)
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("--scene", default="open")
    r.add_argument("--seed", type=int, default=0)
    r.add_argument("--frames", type=int, default=300)
    r.add_argument("--runs", nargs="+", default=["kiss", "kiss_like"], help="kiss, kiss_perturbed, kiss_like, kiss_like_kdtree")
    r.add_argument("--perturbation-m", type=float, default=1e-9)
    sub.add_parser("report")
    a = ap.parse_args()
    if a.cmd == "run":
        run(a.scene, a.seed, a.frames, a.runs, a.perturbation_m, a.out)
    else:
        print(report(a.out))


if __name__ == "__main__":
    from lidarkit.cli import run_script

    run_script(main)
