"""Which instant of a sweep a non-deskewed odometry estimate refers to: sweep start, middle or end.

lidarkit labels a variant's poses with the scans' stamp instant when it does not deskew
(``lidarkit.odometry.instants.estimate_instant``). Scan-to-scan registration of two motion-distorted sweeps fits
the motion between their middles, so its poses should match the ground truth at the sweep MIDDLE. This script runs
every non-deskewing variant (and kiss with deskew, which deskews to the sweep end, as the control) through
``lidarkit.odometry.run`` on simulated sequences (``lidarkit.sim.lidar``: motion distortion, per-point times) and
scores each estimate against the ground truth at the sweep start, middle and end (``lidarkit.eval``: RPE over 1
frame, alignment-free; APE after SE(3) Umeyama alignment, so the estimate's identity first pose does not matter).
The instants differ only where the motion changes between sweeps (the start-up ramp, sway, turns): each sequence
also reports that separation, the RPE between its own start- and end-instant ground truths.

    .venv/bin/python benchmarks/sweep_instant.py [--seeds 0 1 2 3 4] [--frames 40] [--beams 16] [--azimuths 720]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from lidarkit import eval as leval
from lidarkit.atomic import write_text
from lidarkit.bench.machine import describe_machine, machine_info
from lidarkit.geometry import se3_inverse
from lidarkit.odometry import run
from lidarkit.sim.lidar import POSE_INSTANTS, SimulatedLidarSequence

REPO = Path(__file__).resolve().parents[1]
#: scene label -> simulator settings (every built-in scene kind; "ground" on 2 m hills: the flat plane alone leaves
#: x, y and yaw unobservable; "street_turns": curvature up to 1/30 per m, up to 19 deg/s of yaw at 10 m/s)
SCENES = {"street": {"scene": "street"}, "street_turns": {"scene": "street", "max_curvature_per_m": 1 / 30},
          "open": {"scene": "open"}, "ground_hills": {"scene": "ground", "terrain_amplitude_m": 2.0}}
#: variant label -> (registered method, params); all but the control register the sweeps as delivered (no deskew)
VARIANTS = {"small_gicp": ("small_gicp", {}), "vanilla(voxel 0.5 m)": ("vanilla", {"voxel_size_m": 0.5}),
            "open3d_point_to_plane": ("open3d_point_to_plane", {}), "open3d_gicp": ("open3d_gicp", {}),
            "kiss(deskew off)": ("kiss", {"deskew": False}), "kiss(deskew on, control)": ("kiss", {"deskew": True})}


def log(msg: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


class Cached:
    """The simulated sequence with its sweeps cast once and shared by every variant (other members delegated)."""

    def __init__(self, sim: SimulatedLidarSequence):
        self._sim, self.scans = sim, [sim.read_scan(i) for i in range(len(sim))]

    def __len__(self) -> int:
        return len(self.scans)

    def read_scan(self, index: int):
        return self.scans[index]

    def __getattr__(self, name: str):
        return getattr(self._sim, name)


def separation(sim: SimulatedLidarSequence) -> dict:
    """How far apart the instants are: RPE (1 frame) of the start- against the end-instant ground truth, and the motion."""
    start, mid, end = (sim.ground_truth_at(i) for i in POSE_INSTANTS)
    t = end.timestamps_s
    rel = mid.relative_motions()
    yaw = np.degrees(np.abs(np.arctan2(rel[:, 1, 0], rel[:, 0, 0]))) * sim.config.frame_rate_hz
    return {"start_vs_end_cm": 100 * leval.rpe(end, start.with_timestamps(t)).mean,
            "start_vs_mid_cm": 100 * leval.rpe(mid, start.with_timestamps(t)).mean,
            "mean_speed_mps": float(np.linalg.norm(rel[:, :3, 3], axis=1).mean() * sim.config.frame_rate_hz),
            "mean_yaw_rate_dps": float(yaw.mean()), "max_yaw_rate_dps": float(yaw.max())}


def fitted_instant(sim: SimulatedLidarSequence, est, grid=np.round(np.arange(-1.0, 2.0001, 0.05), 2)) -> float:
    """The fraction of the sweep (0 start, 0.5 middle, 1 end; the grid reaches one sweep beyond either side) whose
    ground-truth relative motions are nearest the estimate's (mean translation error, plain numpy): a fit outside [0, 1]
    means the variant's own bias, not an instant, decides (e.g. motion estimated short while accelerating -> early)."""
    rel_est = est.relative_motions()
    frames = np.arange(len(est))
    err = []
    for a in grid:
        g = sim.poses_at((frames + a) * sim.config.sweep_period_s)
        rel_gt = se3_inverse(g[:-1]) @ g[1:]
        err.append(np.linalg.norm((se3_inverse(rel_gt) @ rel_est)[:, :3, 3], axis=1).mean())
    return float(grid[int(np.argmin(err))])


def score(sim: SimulatedLidarSequence, est, cruise_from: int) -> dict:
    """Per instant: RPE translation (cm, mean / max / mean after the start-up ramp), RPE rotation (deg), APE SE(3) (cm)."""
    out = {}
    for instant in POSE_INSTANTS:
        ref = sim.ground_truth_at(instant).with_timestamps(est.timestamps_s)
        t = leval.rpe(ref, est, relation="translation")
        r = leval.rpe(ref, est, relation="rotation_angle_deg")
        a = leval.ape(ref, est, align="se3")
        out[instant] = {"rpe_cm": 100 * t.mean, "rpe_max_cm": 100 * t.max, "rpe_cruise_cm": 100 * float(t.errors[cruise_from - 1:].mean()),
                        "rpe_deg": r.mean, "ape_se3_cm": 100 * a.rmse}
    ranked = sorted(POSE_INSTANTS, key=lambda i: out[i]["rpe_cm"])
    return {"by_instant": out, "best": ranked[0], "margin_cm": out[ranked[1]]["rpe_cm"] - out[ranked[0]]["rpe_cm"],
            "fitted_instant": fitted_instant(sim, est), "best_ape": min(POSE_INSTANTS, key=lambda i: out[i]["ape_se3_cm"]),
            "best_cruise": min(POSE_INSTANTS, key=lambda i: out[i]["rpe_cruise_cm"])}


def measure(args) -> list[dict]:
    rows = []
    for scene, scene_params in SCENES.items():
        for seed in args.seeds:
            sim = SimulatedLidarSequence(**scene_params, seed=seed, n_frames=args.frames, n_beams=args.beams, n_azimuths=args.azimuths,
                                         range_noise_std_m=args.noise, motion_distortion=True, point_times=True)
            seq, sep = Cached(sim), separation(sim)
            cruise_from = int(np.ceil(sim.config.accel_time_s * sim.config.frame_rate_hz)) + 1
            for label, (method, params) in VARIANTS.items():
                start = time.perf_counter()
                result = run(seq, method, params=params, pose_covariance=False)
                s = score(sim, result.trajectory, cruise_from)
                row = {"variant": label, "scene": scene, "seed": seed, **s, "separation": sep, "run_s": time.perf_counter() - start,
                       "estimate_instant_labelled": result.config["run"]["effective"]["estimate_instant"],
                       "deskew_applied": result.config["run"]["effective"]["deskew"]["applied"], "n_fallback": result.n_fallback}
                rows.append(row)
                b = s["by_instant"]
                log(f"{scene} seed {seed} {label}: RPE start/mid/end {b['start']['rpe_cm']:.2f}/{b['mid']['rpe_cm']:.2f}/"
                    f"{b['end']['rpe_cm']:.2f} cm -> {s['best']} ({row['run_s']:.1f} s)")
    return rows


def summary(rows: list[dict]) -> list[dict]:
    """Per variant x scene: wins per instant over seeds (RPE mean), the margins, and the variant's error vs the separation."""
    out = []
    for variant in VARIANTS:
        for scene in SCENES:
            rs = [r for r in rows if r["variant"] == variant and r["scene"] == scene]
            wins = {i: sum(r["best"] == i for r in rs) for i in POSE_INSTANTS}
            best_err = [r["by_instant"][r["best"]]["rpe_cm"] for r in rs]
            sep = [r["separation"]["start_vs_mid_cm"] for r in rs]
            out.append({"variant": variant, "scene": scene, "n": len(rs), "wins": wins, "ape_wins_mid": sum(r["best_ape"] == "mid" for r in rs),
                        "cruise_wins_mid": sum(r["best_cruise"] == "mid" for r in rs),
                        "margins_cm": [r["margin_cm"] for r in rs], "best_rpe_cm": best_err, "sep_start_mid_cm": sep, "fitted": [r["fitted_instant"] for r in rs],
                        "own_error_dominates": bool(np.median(best_err) > np.median(sep))})
    return out


def render(report: dict) -> str:
    s = report["settings"]
    lines = ["# Which instant of a sweep a non-deskewed estimate refers to", "",
             f"- date: {report['date']}", f"- machine: {report['machine']}", f"- command: `{report['command']}` ({report['runtime_s'] / 60:.1f} min)",
             f"- sequences: `lidarkit.sim.lidar.SimulatedLidarSequence`, {s['frames']} sweeps of {s['beams']} x {s['azimuths']} rays, seeds "
             f"{', '.join(map(str, s['seeds']))}, motion distortion and per-point times on, range noise {s['noise_m']} m, 10 Hz, "
             "10 m/s after a 2 s start from rest (sweeps 0-20: accelerating); scenes: " + "; ".join(f"{k} {v}" for k, v in SCENES.items()),
             "- variants through `lidarkit.odometry.run(seq, method, params=..., pose_covariance=False)`: " + "; ".join(
                 f"{k} = `{m}` {p or ''}" for k, (m, p) in VARIANTS.items()),
             "- scoring (`lidarkit.eval`): the same estimate against `ground_truth_at(start | mid | end)`; RPE over 1 frame "
             "(alignment-free: the estimate's identity first pose does not enter), translation mean / max (cm) and rotation mean "
             "(deg); APE RMSE after SE(3) Umeyama alignment (cm). Best instant = lowest RPE translation mean; margin = second best "
             "minus best. Fitted instant: the sweep fraction (grid -1..2, step 0.05) whose ground truth is nearest (RPE); "
             "0 / 0.5 / 1 = start / mid / end. `sep` = RPE of the start-instant against the mid-instant ground truth (how far apart the instants are).", "",
             "## Summary (variant x scene; wins over seeds by RPE translation mean)", "",
             "| variant | scene | start / mid / end wins | margin of the winner, per seed (cm) | best RPE per seed (cm) | sep start-mid per seed (cm) | fitted instant per seed | mid wins by APE | mid wins after the ramp |",
             "|---|---|---|---|---|---|---|---|---|"]
    f = lambda xs: " ".join(f"{x:.2f}" for x in xs)  # noqa: E731
    for r in report["summary"]:
        w = r["wins"]
        lines.append(f"| {r['variant']} | {r['scene']} | {w['start']} / {w['mid']} / {w['end']} | {f(r['margins_cm'])} | {f(r['best_rpe_cm'])} | "
                     f"{f(r['sep_start_mid_cm'])} | {f(r['fitted'])} | {r['ape_wins_mid']}/{r['n']} | {r['cruise_wins_mid']}/{r['n']} |")
    for variant in VARIANTS:
        lines += ["", f"## {variant}", "", "| scene | seed | yaw rate mean / max (deg/s) | sep (cm) | RPE cm start / mid / end | RPE max cm start / mid / end | "
                  "RPE deg start / mid / end | APE SE(3) cm start / mid / end | best (margin cm) | fitted instant |", "|---|---:|---|---:|---|---|---|---|---|---:|"]
        for r in (r for r in report["rows"] if r["variant"] == variant):
            b, sp = r["by_instant"], r["separation"]
            cells = [" / ".join(f"{b[i][k]:{spec}}" for i in POSE_INSTANTS) for k, spec in
                     (("rpe_cm", ".2f"), ("rpe_max_cm", ".2f"), ("rpe_deg", ".3f"), ("ape_se3_cm", ".2f"))]
            lines.append(f"| {r['scene']} | {r['seed']} | {sp['mean_yaw_rate_dps']:.1f} / {sp['max_yaw_rate_dps']:.1f} | {sp['start_vs_mid_cm']:.2f} | "
                         + " | ".join(cells) + f" | **{r['best']}** ({r['margin_cm']:.2f}) | {r['fitted_instant']:.2f} |")
    lines += ["", "## Findings (computed)", ""] + findings(report)
    lines += ["", "Raw numbers: `sweep_instant.json`; plot: `sweep_instant.png` (RPE translation mean per instant, one line per scene and seed)."]
    return "\n".join(lines) + "\n"


def findings(report: dict) -> list[str]:
    """Per variant: mid's wins overall and where the variant's own error is below the instants' separation (only there can
    the comparison tell the instants apart); kiss: how far deskew moves the fitted instant on the same sequence."""
    out = []
    for variant in VARIANTS:
        rs = [r for r in report["rows"] if r["variant"] == variant]
        ok = [r for r in rs if r["by_instant"][r["best"]]["rpe_cm"] < r["separation"]["start_vs_mid_cm"]]
        mid_m = [r["margin_cm"] for r in ok if r["best"] == "mid"]
        other = sorted({r["scene"] for r in rs if r not in ok})
        sep = [r["separation"]["start_vs_mid_cm"] for r in rs]
        line = (f"- {variant}: mid wins {sum(r['best'] == 'mid' for r in rs)}/{len(rs)} (start {sum(r['best'] == 'start' for r in rs)}, "
                f"end {sum(r['best'] == 'end' for r in rs)}); where its own error is below the separation ({len(ok)} runs: "
                f"{', '.join(sorted({r['scene'] for r in ok})) or 'none'})" + (f" mid wins {len(mid_m)}/{len(ok)}" if ok else ""))
        if ok:
            ratio = [min(r["by_instant"][i]["rpe_cm"] for i in ("start", "end")) / r["by_instant"]["mid"]["rpe_cm"] for r in ok]
            fit = [r["fitted_instant"] for r in ok]
            line += (f", margin {min(mid_m):.2f}-{max(mid_m):.2f} cm, start/end {min(ratio):.1f}-{max(ratio):.1f}x mid's RPE, fitted instant "
                     f"{min(fit):.2f}-{max(fit):.2f}" if mid_m else "")
        if other:
            fit = [r["fitted_instant"] for r in rs if r not in ok]
            line += (f"; elsewhere ({', '.join(other)}) its own error dominates (best RPE {min(r['by_instant'][r['best']]['rpe_cm'] for r in rs if r not in ok):.1f}-"
                     f"{max(r['by_instant'][r['best']]['rpe_cm'] for r in rs if r not in ok):.1f} cm vs separation {min(sep):.2f}-{max(sep):.2f} cm), fitted "
                     f"instant median {np.median(fit):.2f} ({min(fit):.2f} to {max(fit):.2f}; -1 and 2 are the grid's ends): mostly early, "
                     "as an estimate short of the accelerating motion reads")
        out.append(line + ".")
    on = {(r["scene"], r["seed"]): r for r in report["rows"] if r["variant"] == "kiss(deskew on, control)"}
    shifts = [on[(r["scene"], r["seed"])]["fitted_instant"] - r["fitted_instant"] for r in report["rows"] if r["variant"] == "kiss(deskew off)"
              and max(r["by_instant"]["mid"]["rpe_cm"], on[(r["scene"], r["seed"])]["by_instant"]["mid"]["rpe_cm"]) < 10.0]
    if shifts:
        out.append(f"- kiss, same sequence with deskew on minus off (runs under 10 cm RPE: {len(shifts)}): the fitted instant moves by "
                   f"{np.median(shifts):+.2f} sweep (median; {min(shifts):+.2f} to {max(shifts):+.2f}, {sum(x > 0 for x in shifts)} of {len(shifts)} later): "
                   "deskew to the end moves the pose half a sweep later than the non-deskewed one, i.e. the latter sits mid-sweep "
                   "(both carry kiss's own lag while accelerating).")
    cruise = [abs(r["by_instant"]["start"]["rpe_cruise_cm"] - r["by_instant"]["end"]["rpe_cruise_cm"]) for r in report["rows"] if r["variant"] == "small_gicp"]
    sep = [r["separation"]["start_vs_mid_cm"] for r in report["rows"]]
    out.append(f"- The instants differ by {min(sep):.2f}-{max(sep):.2f} cm RPE (start vs mid) on every sequence: that is the 2 s start-up ramp; after it (constant speed, "
               f"yaw rates below 7 deg/s) start and end scores of small_gicp differ by {max(cruise):.2f} cm at most, so the cruise frames barely discriminate.")
    return out


def plot(report: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(VARIANTS), figsize=(3.2 * len(VARIANTS), 3.6), sharex=True)
    colors = dict(zip(SCENES, ("tab:blue", "tab:red", "tab:green", "tab:brown")))
    for ax, variant in zip(axes, VARIANTS):
        for r in (r for r in report["rows"] if r["variant"] == variant):
            ax.plot(range(3), [r["by_instant"][i]["rpe_cm"] for i in POSE_INSTANTS], "-o", ms=3, lw=1, color=colors[r["scene"]], alpha=0.7)
        ax.set_title(variant, fontsize=9)
        ax.set_xticks(range(3), POSE_INSTANTS)
        ax.set_yscale("log")
    axes[0].set_ylabel("RPE translation mean (cm, 1 frame)")
    axes[-1].legend([plt.Line2D([], [], color=c) for c in colors.values()], list(colors), fontsize=7)
    fig.suptitle("Same estimate scored against the ground truth at the sweep start / middle / end", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    ap.add_argument("--frames", type=int, default=40)
    ap.add_argument("--beams", type=int, default=16)
    ap.add_argument("--azimuths", type=int, default=720)
    ap.add_argument("--noise", type=float, default=0.02, help="range noise std (m)")
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "odometry")
    ap.add_argument("--rerender", action="store_true", help="only rewrite the .md and .png from --out/sweep_instant.json")
    args = ap.parse_args(argv)
    if args.rerender:
        report = json.loads((args.out / "sweep_instant.json").read_text())
        plot(report, args.out / "sweep_instant.png")
        write_text(args.out / "sweep_instant.md", render(report))
        return 0
    start = time.perf_counter()
    info = machine_info()
    report = {"date": info["date_utc"], "machine": describe_machine(info), "machine_info": info,
              "command": " ".join([".venv/bin/python benchmarks/sweep_instant.py", *(sys.argv[1:] if argv is None else argv)]),
              "settings": {"seeds": args.seeds, "frames": args.frames, "beams": args.beams, "azimuths": args.azimuths, "noise_m": args.noise,
                           "scenes": SCENES, "variants": {k: {"method": m, "params": p} for k, (m, p) in VARIANTS.items()}},
              "rows": measure(args)}
    report["summary"] = summary(report["rows"])
    report["runtime_s"] = time.perf_counter() - start
    report["load_average_end"] = list(__import__("os").getloadavg())
    args.out.mkdir(parents=True, exist_ok=True)
    write_text(args.out / "sweep_instant.json", json.dumps(report, indent=1, default=float) + "\n")
    plot(report, args.out / "sweep_instant.png")
    write_text(args.out / "sweep_instant.md", render(report))
    log(f"wrote {args.out / 'sweep_instant.md'} in {report['runtime_s'] / 60:.1f} min")
    return 0


if __name__ == "__main__":
    from lidarkit.cli import run_script

    run_script(main)
