"""What the VO sanity checks are worth: KITTI frames 0-50 with injected faults, run with and without the checks.

Faults (each a thing real recordings do): a standstill (two copies of a frame inserted after it), a pure rotation
(a copy of a frame warped by a 1.5 deg yaw homography ``K R K^-1`` inserted after it), a black frame (replacing one)
and a mis-ordered frame (an early frame in place of a late one). The ground truth follows the faults: copies and the
rotated frame keep the position of the frame they copy; replaced frames keep their own. Scored by Sim(3) APE (relative
scale and unit steps) through ``lidarkit.eval``, with each fault frame's outcome (accepted, or the recorded reason).

    python benchmarks/vo_faults.py [--data ../shared/data/kitti_images/sequences] [--out benchmarks/results/vo]

Writes ``faults.md`` and ``faults.json`` into ``--out``.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import sys
from pathlib import Path

import cv2
import numpy as np

from lidarkit import atomic
from lidarkit.bench.machine import describe_machine, machine_info
from lidarkit.geometry import so3_exp
from lidarkit.io.kitti import KittiOdometry
from lidarkit.trajectory import Trajectory
from lidarkit.vo import MonoVO, images_in_memory, preset
from lidarkit.vo.evaluation import evaluate_vo
from lidarkit.vo.intrinsics import K_from_image_size
from lidarkit.vo.pipeline import rejection_key

REPO = Path(__file__).resolve().parents[1]
DEFAULT_DATA = REPO.parent / "shared" / "data" / "kitti_images" / "sequences"

STANDSTILL_AFTER, ROTATION_AFTER, BLACK_AT, MISORDERED_AT, MISORDERED_FROM = 15, 25, 32, 40, 5
ROTATION_DEG = 1.5

PIPELINES = [  # (label, preset, changes)
    ("lidarkit (KLT), relative scale", "lidarkit", {"scale.mode": "relative"}),
    ("lidarkit (KLT), unit steps", "lidarkit", {"scale.mode": "none"}),
    ("report 2 (CLAHE + ORB + ratio, MAGSAC), unit steps", "report_orb", {}),
]


def inject_faults(images: list[np.ndarray], gt: Trajectory, K: np.ndarray):
    """``(images, ground truth, {fault name: frame index in the new sequence})`` with the four faults injected."""
    imgs = list(images)
    poses = list(gt.poses_se3)
    imgs[BLACK_AT] = np.zeros_like(imgs[BLACK_AT])
    imgs[MISORDERED_AT] = images[MISORDERED_FROM]
    R = so3_exp(np.array([0.0, np.radians(ROTATION_DEG), 0.0]))  # yaw about the camera's y axis
    H = K @ R @ np.linalg.inv(K)
    h, w = images[ROTATION_AFTER].shape
    rotated = cv2.warpPerspective(images[ROTATION_AFTER], H, (w, h), flags=cv2.INTER_LINEAR)
    T_rot = poses[ROTATION_AFTER].copy()
    T_rot[:3, :3] = T_rot[:3, :3] @ R.T  # X_new = R X_old: the camera turned by R^T
    # insert from the back so the earlier insertion index stays valid
    imgs.insert(ROTATION_AFTER + 1, rotated)
    poses.insert(ROTATION_AFTER + 1, T_rot)
    for _ in range(2):
        imgs.insert(STANDSTILL_AFTER + 1, images[STANDSTILL_AFTER])
        poses.insert(STANDSTILL_AFTER + 1, poses[STANDSTILL_AFTER].copy())
    shift = 2  # the standstill copies come before the other faults
    faults = {"standstill copy 1": STANDSTILL_AFTER + 1, "standstill copy 2": STANDSTILL_AFTER + 2,
              "pure rotation": ROTATION_AFTER + 1 + shift, "black frame": BLACK_AT + 1 + shift,
              "mis-ordered frame": MISORDERED_AT + 1 + shift}
    return imgs, Trajectory(np.stack(poses), name=f"{gt.name} with faults"), faults


def run(images, K, gt, faults, label, name, changes, sanity: bool, K_label: str) -> dict:
    cfg = preset(name, **{**changes, "sanity.enabled": sanity})
    result = MonoVO(cfg, K).run(images)
    metrics = evaluate_vo(result.trajectory, gt, cfg.scale.mode)
    diag = {d.frame: d for d in result.diagnostics}
    steps = np.linalg.norm(np.diff(result.trajectory.positions_xyz, axis=0), axis=1) * metrics["alignment_scale"]
    outcome = {}
    for fault, i in faults.items():
        d = diag[i]
        outcome[fault] = {"accepted": d.accepted, "reason": d.reason, "step_m": float(steps[i - 1])}
    return {"pipeline": label, "K": K_label, "sanity": sanity, "rejected": len(result.rejected),
            "ape_rmse_m": metrics["ape_rmse_m"], "final_error_m": metrics["final_error_m"], "faults": outcome}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA, help="folder holding sequences/06 and 01")
    parser.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "vo")
    parser.add_argument("--sequences", nargs="+", default=["06", "01"])
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    results = {"command": " ".join(["python", "benchmarks/vo_faults.py", *(argv if argv is not None else sys.argv[1:])]),
               "date_utc": dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
               "machine": machine_info(), "rows": []}
    for seq in args.sequences:
        ds = KittiOdometry(args.data / seq).as_image_sequence()
        clean = images_in_memory(ds)
        images, gt, faults = inject_faults(clean, ds.ground_truth, ds.K)
        for K_label, K in (("calib", ds.K), ("guessed", K_from_image_size(clean[0].shape[1], clean[0].shape[0]))):
            for label, name, changes in PIPELINES:
                for sanity in (True, False):
                    row = {"sequence": seq, **run(images, K, gt, faults, label, name, changes, sanity, K_label)}
                    results["rows"].append(row)
                    print(f"{seq} {K_label} {label} sanity={sanity}: APE {row['ape_rmse_m']:.4f} "
                          f"rejected {row['rejected']}", flush=True)
    atomic.write_text(args.out / "faults.json", json.dumps(results, indent=2, default=float) + "\n")
    atomic.write_text(args.out / "faults.md", markdown(results))
    print(f"wrote {args.out / 'faults.md'}, faults.json")
    return 0


def markdown(results: dict) -> str:
    faults = list(results["rows"][0]["faults"])
    lines = ["# Monocular VO with injected faults: with and without sanity checks", "",
             f"Command: `{results['command']}`  ", f"Date: {results['date_utc']}  ",
             f"Machine: {describe_machine(results['machine'])}", "",
             f"KITTI frames 0-50 with: two copies of frame {STANDSTILL_AFTER} inserted after it (standstill), a "
             f"{ROTATION_DEG:g} deg yaw homography warp of frame {ROTATION_AFTER} inserted after it (pure rotation), "
             f"frame {BLACK_AT} black, frame {MISORDERED_AT} replaced by frame {MISORDERED_FROM} (mis-ordered); frame "
             "numbers below are in the faulty sequence. APE: Sim(3)-aligned translation RMSE. Per fault: the "
             "step length into that frame after alignment (m; truth 0 for the standstill copies and the rotation) "
             "and `ok` when accepted, else the recorded reason. K: the KITTI calibration or the image-size guess "
             "used when none is given.", ""]
    header = "| seq | K | pipeline | checks | APE m | rejected | " + " | ".join(faults) + " |"
    lines += [header, "|" + "---|" * (6 + len(faults))]
    for r in results["rows"]:
        cells = []
        for f in faults:
            o = r["faults"][f]
            verdict = "ok" if o["accepted"] else rejection_key(o["reason"])
            cells.append(f"{o['step_m']:.2f} m, {verdict}")
        lines.append(f"| {r['sequence']} | {r['K']} | {r['pipeline']} | {'on' if r['sanity'] else 'off'} | "
                     f"{r['ape_rmse_m']:.4f} | {r['rejected']} | " + " | ".join(cells) + " |")
    lines.append("")
    return "\n".join(lines)


if __name__ == "__main__":
    from lidarkit.cli import run_script

    run_script(main)
