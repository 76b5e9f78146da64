"""Monocular VO on KITTI sequences 06 and 01 (frames 0-50): the two reports' pipelines vs lidarkit's.

Measures APE (SE(3) alignment for ground-truth scale, Sim(3) otherwise) and RPE over 1 frame through
``lidarkit.eval``, the final-frame error, frames/s with images preloaded (best of ``--repeats`` runs, plus the ratio
to the report-2 ORB pipeline timed in the same run), rejected frames; raw vs smoothed; with/without sanity checks;
the spread of relative scale over RANSAC sample orders (seeds), and the sensitivity of the error to the focal length
(including the image-size guess used without calibration).

    python benchmarks/vo_kitti.py [--data ../shared/data/kitti_images/sequences] [--out benchmarks/results/vo]

Writes ``results.md``, ``results.json`` and ``trajectories.png`` into ``--out``.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import shlex
import sys
from pathlib import Path

import numpy as np

from lidarkit import atomic
from lidarkit.bench.machine import describe_machine, machine_info
from lidarkit.io.kitti import KittiOdometry
from lidarkit.vo import MonoVO, images_in_memory, preset
from lidarkit.vo.evaluation import evaluate_vo
from lidarkit.vo.intrinsics import DEFAULT_FOCAL_FACTOR, K_from_image_size

REPO = Path(__file__).resolve().parents[1]
DEFAULT_DATA = REPO.parent / "shared" / "data" / "kitti_images" / "sequences"

# (label, preset, changes)
PIPELINES = [
    ("report 1: SIFT + BF cross-check, RANSAC, gt scale", "report_sift", {}),
    ("report 2: CLAHE + ORB 3000 + ratio, MAGSAC (normalized), unit steps", "report_orb", {}),
    ("report 2 without sanity checks", "report_orb", {"sanity.enabled": False}),
    ("lidarkit: KLT + E-RANSAC + Sampson refinement, gt scale", "lidarkit", {"scale.mode": "gt"}),
    ("lidarkit, relative scale", "lidarkit", {"scale.mode": "relative"}),
    ("lidarkit, relative scale, without sanity checks", "lidarkit", {"scale.mode": "relative", "sanity.enabled": False}),
    ("lidarkit, unit steps", "lidarkit", {"scale.mode": "none"}),
    ("lidarkit ORB variant: ORB 3000 grid + ratio, MAGSAC+RANSAC best, gt scale", "lidarkit",
     {"scale.mode": "gt", "features.detector": "orb", "features.max_features": 3000, "matching.method": "knn_ratio",
      "geometry.estimators": ("magsac", "ransac")}),
    ("lidarkit AKAZE variant: AKAZE 3000 + ratio, MAGSAC+RANSAC best, gt scale", "lidarkit",
     {"scale.mode": "gt", "features.detector": "akaze", "features.max_features": 3000, "features.grid_rows": 1,
      "features.grid_cols": 1, "matching.method": "knn_ratio", "geometry.estimators": ("magsac", "ransac")}),
]
PLOTTED = {PIPELINES[i][0] for i in (0, 1, 3, 4)}
# relative scale per pipeline over RANSAC sample orders: the detection order (seed None) and shuffles with seeds 0-4
SEED_PIPELINES = [
    ("lidarkit (KLT on corners)", "lidarkit", {}),
    ("lidarkit with ORB keypoints (KLT)", "lidarkit", {"features.detector": "orb"}),
    ("report 2 pipeline (ORB + ratio test)", "report_orb", {}),
    ("report 1 pipeline (SIFT + BF cross-check)", "report_sift", {}),
]
SEEDS = (0, 1, 2, 3, 4)
FOCAL_FACTORS = (0.8, 0.9, 0.95, 1.0, 1.05, 1.1, 1.25)


def load(data: Path, seq: str):
    ds = KittiOdometry(data / seq).as_image_sequence()
    return images_in_memory(ds), ds.K, ds.ground_truth


def run_once(cfg, K, gt, images):
    return MonoVO(cfg, K, gt if cfg.scale.mode == "gt" else None).run(images)


def timed_pair(cfg, ref_cfg, K, gt, images, repeats: int):
    """Run ``cfg`` and the speed reference ``ref_cfg`` alternately ``repeats`` times; keep each one's fastest run
    (results are deterministic, so any run's trajectory serves). Alternating keeps both under the same load."""
    best, best_ref = None, None
    for _ in range(repeats):
        result = run_once(cfg, K, gt, images)
        ref = run_once(ref_cfg, K, gt, images)
        if best is None or result.runtime_s < best.runtime_s:
            best = result
        if best_ref is None or ref.runtime_s < best_ref.runtime_s:
            best_ref = ref
    return best, best_ref


def evaluate(result, gt):
    mode = result.config.scale.mode
    raw = evaluate_vo(result.trajectory, gt, mode)
    smooth = evaluate_vo(result.smoothed(), gt, mode)
    return {"raw": raw, "smoothed": smooth}


def fmt(x, digits=3):
    return "-" if x is None else f"{x:.{digits}f}"


def command_line(script: str, argv: list[str] | None = None) -> str:
    """The command as run, for a results file: the process's real niceness and shell-quoted arguments (the VO scripts
    recorded a hard-coded ``nice -n 5/10`` and bare ``simcam:street?frames=51&seed=0`` specs a shell splits at '&')."""
    niceness = os.nice(0)
    words = [shlex.quote(a) for a in (sys.argv[1:] if argv is None else argv)]
    return " ".join([f"nice -n {niceness}"] * bool(niceness) + ["python", f"benchmarks/{script}", *words])


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA, help="folder holding sequences/06 and 01")
    parser.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "vo")
    parser.add_argument("--sequences", nargs="+", default=["06", "01"])
    parser.add_argument("--repeats", type=int, default=3, help="timing repeats (best kept)")
    args = parser.parse_args(argv)
    if args.repeats < 1:  # (an AttributeError on the missing timed result, after --out was created)
        parser.error("--repeats must be >= 1")
    args.out.mkdir(parents=True, exist_ok=True)

    started = dt.datetime.now(dt.timezone.utc)
    results = {"command": command_line("vo_kitti.py", argv),
               "date_utc": started.strftime("%Y-%m-%d %H:%M UTC"),
               "machine": machine_info(),
               "pipelines": [], "intrinsics": [], "seeds": []}
    trajectories = {}
    for seq in args.sequences:
        images, K, gt = load(args.data, seq)
        ref_cfg = preset("report_orb")
        for label, name, changes in PIPELINES:
            cfg = preset(name, **changes)
            result, orb = timed_pair(cfg, ref_cfg, K, gt, images, args.repeats)  # orb: same-run speed reference
            metrics = evaluate(result, gt)
            row = {"sequence": seq, "pipeline": label, "preset": name, "changes": {k: list(v) if isinstance(v, tuple)
                                                                                   else v for k, v in changes.items()},
                   "frames": result.n_frames, "rejected": len(result.rejected),
                   "rejection_reasons": result.summary()["rejection_reasons"],
                   "frames_per_s": result.frames_per_s, "speed_vs_report2_orb": result.frames_per_s / orb.frames_per_s,
                   **metrics}
            results["pipelines"].append(row)
            print(f"{seq} {label}: APE {row['raw']['ape_rmse_m']:.4f} ({row['raw']['align']}) final "
                  f"{row['raw']['final_error_m']:.3f} fps {row['frames_per_s']:.1f} x{row['speed_vs_report2_orb']:.2f} "
                  f"rejected {row['rejected']}", flush=True)
            if label in PLOTTED:
                trajectories.setdefault(seq, {"gt": gt})[label] = (result.trajectory, row["raw"]["align"])

        # intrinsics sensitivity: focal length scaled by a factor (principal point kept), and the size-based guess
        h, w = images[0].shape
        for mode in ("gt", "relative"):
            cfg = preset("lidarkit", **{"scale.mode": mode})
            variants = [(f"fx x {f:g}", _scale_focal(K, f)) for f in FOCAL_FACTORS]
            variants.append((f"guess {DEFAULT_FOCAL_FACTOR:g} * max(w, h), centre", K_from_image_size(w, h)))
            for label, K_var in variants:
                result = run_once(cfg, K_var, gt, images)
                m = evaluate_vo(result.trajectory, gt, mode)
                results["intrinsics"].append({"sequence": seq, "scale": mode, "K": label,
                                              "focal_error_pct": 100 * (K_var[0, 0] / K[0, 0] - 1),
                                              "rejected": len(result.rejected), **m})
                print(f"{seq} {mode} {label}: APE {m['ape_rmse_m']:.4f} rejected {len(result.rejected)}", flush=True)
        for label, name, changes in SEED_PIPELINES:
            ape = {}
            for seed in (None, *SEEDS):
                cfg = preset(name, **{**changes, "scale.mode": "relative", "seed": seed})
                ape[str(seed)] = evaluate_vo(run_once(cfg, K, gt, images).trajectory, gt, "relative")["ape_rmse_m"]
            unit = preset(name, **{**changes, "scale.mode": "none"})
            unit_ape = evaluate_vo(run_once(unit, K, gt, images).trajectory, gt, "none")["ape_rmse_m"]
            results["seeds"].append({"sequence": seq, "pipeline": label, "ape_rmse_m": ape, "unit_steps_ape_m": unit_ape})
            print(f"{seq} seeds {label}: " + " ".join(f"{k}={v:.3f}" for k, v in ape.items()), flush=True)

        cfg = preset("report_orb")
        result = run_once(cfg, K_from_image_size(w, h), gt, images)
        m = evaluate_vo(result.trajectory, gt, "none")
        results["intrinsics"].append({"sequence": seq, "scale": "none (report 2 pipeline)",
                                      "K": f"guess {DEFAULT_FOCAL_FACTOR:g} * max(w, h), centre",
                                      "focal_error_pct": 100 * (K_from_image_size(w, h)[0, 0] / K[0, 0] - 1),
                                      "rejected": len(result.rejected), **m})

    atomic.write_text(args.out / "results.json", json.dumps(results, indent=2, default=float) + "\n")
    atomic.write_text(args.out / "results.md", markdown(results))
    plot(trajectories, args.out / "trajectories.png")
    print(f"wrote {args.out / 'results.md'}, results.json, trajectories.png")
    return 0


def _scale_focal(K: np.ndarray, factor: float) -> np.ndarray:
    K = K.copy()
    K[0, 0] *= factor
    K[1, 1] *= factor
    return K


def markdown(results: dict) -> str:
    lines = ["# Monocular VO on KITTI 06 and 01 (frames 0-50)", "",
             f"Command: `{results['command']}`  ", f"Date: {results['date_utc']}  ",
             f"Machine: {describe_machine(results['machine'])}; compare frames/s as ratios", "",
             "APE: translation RMSE after SE(3) alignment for ground-truth scale, Sim(3) otherwise (evo via "
             "`lidarkit.eval`). RPE: 1 frame, same alignment. Final error: distance of the last positions, raw for "
             "gt scale (both start at the same pose), after alignment otherwise; `final al.` is always after "
             "alignment. frames/s: pipeline time with images preloaded, best of the repeats; `x ORB` is the ratio to "
             "the report-2 pipeline timed alternately with it (the machine is shared: absolute frames/s vary with its "
             "load, the ratio much less).", ""]
    for seq in dict.fromkeys(r["sequence"] for r in results["pipelines"]):
        lines += [f"## Sequence {seq}", "",
                  "| pipeline | align | APE m | APE smoothed m | RPE m | RPE deg | final m | final al. m | "
                  "final smoothed m | frames/s | x ORB | rejected |",
                  "|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for r in results["pipelines"]:
            if r["sequence"] != seq:
                continue
            raw, sm = r["raw"], r["smoothed"]
            lines.append(f"| {r['pipeline']} | {raw['align']} | {fmt(raw['ape_rmse_m'], 4)} | {fmt(sm['ape_rmse_m'], 4)} | "
                         f"{fmt(raw['rpe_trans_rmse_m'], 4)} | {fmt(raw['rpe_rot_rmse_deg'], 3)} | "
                         f"{fmt(raw['final_error_m'])} | {fmt(raw['final_error_aligned_m'])} | "
                         f"{fmt(sm['final_error_m'])} | {r['frames_per_s']:.1f} | {r['speed_vs_report2_orb']:.2f} | "
                         f"{r['rejected']} |")
        lines.append("")
    lines += ["## Relative scale over RANSAC sample orders", "",
              "Sim(3) APE (m) with relative scale: `detection` is the default correspondence order (seed None), "
              f"seeds {SEEDS[0]}-{SEEDS[-1]} shuffle it; unit steps (detection order) for comparison.", "",
              "| sequence | pipeline | detection | " + " | ".join(f"seed {k}" for k in SEEDS) +
              " | median of seeds | max of seeds | unit steps |",
              "|---|---|---|" + "---|" * len(SEEDS) + "---|---|---|"]
    for r in results["seeds"]:
        shuffled = [r["ape_rmse_m"][str(k)] for k in SEEDS]
        lines.append(f"| {r['sequence']} | {r['pipeline']} | {fmt(r['ape_rmse_m']['None'])} | "
                     + " | ".join(fmt(v) for v in shuffled)
                     + f" | {fmt(float(np.median(shuffled)))} | {fmt(max(shuffled))} | {fmt(r['unit_steps_ape_m'])} |")
    lines.append("")
    lines += ["## Intrinsics sensitivity (lidarkit pipeline; focal length scaled, principal point kept)", "",
              "| sequence | scale | K | focal error % | APE m | final m | final al. m | RPE deg | rejected |",
              "|---|---|---|---|---|---|---|---|---|"]
    for r in results["intrinsics"]:
        lines.append(f"| {r['sequence']} | {r['scale']} | {r['K']} | {r['focal_error_pct']:+.0f} | "
                     f"{fmt(r['ape_rmse_m'], 4)} | {fmt(r['final_error_m'])} | {fmt(r['final_error_aligned_m'])} | "
                     f"{fmt(r['rpe_rot_rmse_deg'])} | {r['rejected']} |")
    lines.append("")
    return "\n".join(lines)


def plot(trajectories: dict, path: Path) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from lidarkit.eval import align_trajectory

    fig = Figure(figsize=(11, 5), dpi=90, layout="constrained")
    FigureCanvasAgg(fig)
    for i, (seq, trajs) in enumerate(trajectories.items()):
        ax = fig.add_subplot(1, len(trajectories), i + 1)
        gt = trajs["gt"]
        ax.plot(gt.positions_xyz[:, 0], gt.positions_xyz[:, 2], "k-", lw=2, label="ground truth")
        for label, value in trajs.items():
            if label == "gt":
                continue
            traj, align = value
            shown = align_trajectory(gt, traj, align)[0] if align == "sim3" else traj
            short = label.split(":")[0] + (" (Sim3-aligned)" if align == "sim3" else "")
            ax.plot(shown.positions_xyz[:, 0], shown.positions_xyz[:, 2], lw=1.2, label=short)
        ax.set_title(f"KITTI {seq}, frames 0-50 (top view, axes not to scale)", fontsize=9)
        ax.set_xlabel("x [m]")
        ax.set_ylabel("z [m]")
        ax.grid(True, alpha=0.3)  # axes not to scale: lateral deviations of a straight drive stay visible
        ax.legend(fontsize=7)
    with atomic.atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")


if __name__ == "__main__":
    from lidarkit.cli import run_script

    run_script(main)
