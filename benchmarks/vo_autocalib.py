"""Focal length self-calibration (``lidarkit.vo.autocalib``) against the true focal length, and what it does to VO.

Per sequence: the estimate (or the fallback and its reason), its 1-sigma, the error against the calibration, the
per-window minima, the time it took, and the relative-scale trajectory's Sim(3) APE of the default pipeline with the
true K, the image-size guess and the self-calibrated K (the guess again when it fell back).

    nice -n 10 python benchmarks/vo_autocalib.py [--data ../shared/data/kitti_images/sequences] \
        [--sequences 06 01 00] [--sim "simcam:street?frames=51&seed=1" ...] [--out benchmarks/results/vo_autocalib]
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import sys
import time
from pathlib import Path

from lidarkit import atomic
from lidarkit.bench.machine import describe_machine, machine_info
from lidarkit.io.kitti import KittiOdometry
from lidarkit.vo import MonoVO, images_in_memory, preset
from lidarkit.vo.autocalib import estimate_focal
from lidarkit.vo.evaluation import evaluate_vo
from lidarkit.vo.inputs import open_vo_input
from lidarkit.vo.intrinsics import K_from_image_size

sys.path.insert(0, str(Path(__file__).resolve().parent))
from vo_kitti import command_line  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
DEFAULT_DATA = REPO.parent / "shared" / "data" / "kitti_images" / "sequences"


def ape_sim3(images, K, gt) -> float:
    res = MonoVO(preset("lidarkit"), K).run(images)
    traj = res.trajectory.transformed(T_left=gt.poses_se3[0])
    return evaluate_vo(traj, gt, "relative")["ape_rmse_m"]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA)
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "vo_autocalib")
    ap.add_argument("--sequences", nargs="*", default=["06", "01", "00"])
    ap.add_argument("--sim", nargs="*", default=[], help="simulated sequences (simcam:street?frames=51&seed=1)")
    args = ap.parse_args(argv)
    rows = {}
    for seq in [*args.sequences, *args.sim]:
        if seq.startswith("simcam:"):
            vo_input = open_vo_input(seq)
            images, K_true, gt = images_in_memory(vo_input.images), vo_input.K, vo_input.ground_truth
            name = seq
        else:
            folder = args.data / seq
            # sequence 00's image excerpt has no poses.txt beside it: its ground truth is the odometry folder's
            poses = None
            if not (folder / "poses.txt").exists():
                poses = args.data.parents[1] / "kitti_odometry" / "poses" / f"{seq}.txt"
            ds = KittiOdometry(folder, poses_file=poses).as_image_sequence()
            images, K_true, gt = images_in_memory(ds), ds.K, ds.ground_truth
            name = f"KITTI {seq} frames 0-{len(images) - 1}"
        h, w = images[0].shape
        start = time.perf_counter()
        est = estimate_focal(images)
        seconds = time.perf_counter() - start
        f_true = float(K_true[0, 0])
        K_guess = K_from_image_size(w, h)
        row = {"true_focal_px": f_true, "focal_px": est.focal_px, "sigma_px": est.sigma_px if est.constrained else None,
               "constrained": est.constrained, "reason": est.reason, "error_pct": 100 * (est.focal_px / f_true - 1),
               "window_focals_px": list(est.window_focals_px), "windows": est.windows, "seconds": seconds,
               "ape_true_K_m": ape_sim3(images, K_true, gt), "ape_guess_K_m": ape_sim3(images, K_guess, gt),
               "ape_self_K_m": ape_sim3(images, est.K(w, h), gt)}
        print(seq, row, file=sys.stderr)
        rows[name] = row
    stamp = dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    cmd = command_line("vo_autocalib.py", argv)
    lines = ["# Focal length self-calibration", "", f"Command: `{cmd.strip()}`  ", f"Date: {stamp}  ",
             f"Machine: {describe_machine(machine_info())}", "",
             "APE: relative-scale trajectory of the default pipeline, Sim(3)-aligned translation RMSE. "
             "'self K' is the guess again when the self-calibration fell back. Time: seconds of the estimate on this "
             "shared, loaded machine (indicative only).", "",
             "| sequence | true f [px] | result | f [px] | 1-sigma [px] | error | window minima [px] | "
             "APE true K [m] | APE size guess [m] | APE self K [m] | time [s] |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, r in rows.items():
        result = "estimated" if r["constrained"] else f"fallback: {r['reason']}"
        sigma = f"{r['sigma_px']:.0f}" if r["sigma_px"] is not None else "-"
        minima = ", ".join(f"{x:.0f}" for x in r["window_focals_px"]) or "-"
        lines.append(f"| {name} | {r['true_focal_px']:.1f} | {result} | {r['focal_px']:.1f} | {sigma} | "
                     f"{r['error_pct']:+.1f} % | {minima} | {r['ape_true_K_m']:.3f} | {r['ape_guess_K_m']:.3f} | "
                     f"{r['ape_self_K_m']:.3f} | {r['seconds']:.0f} |")
    atomic.write_text(args.out / "results.md", "\n".join(lines) + "\n")
    atomic.write_text(args.out / "results.json", json.dumps({"command": cmd.strip(), "date": stamp,
                                                             "machine": machine_info(), "results": rows}, indent=2))
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    from lidarkit.cli import run_script

    run_script(main)
