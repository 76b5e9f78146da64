"""Monocular VO on long simulated street runs (``lidarkit.sim.street_camera``) and the simulator's render speed.

Per seed: the default pipeline (preset ``lidarkit``) with ground-truth scale and with relative scale on a
``frames``-frame street sequence at KITTI size and intrinsics. Reported: APE (SE(3) alignment for gt scale, Sim(3)
for relative), final error, the KITTI devkit drift (translation % = m per 100 m, rotation deg/100 m; for relative
scale on the Sim(3)-aligned trajectory) and the relative-scale drift: the estimated over the true path length of
consecutive 100 m stretches (after the global Sim(3) scale), its spread and its change per 100 m.
Render speed: frames/s of ``read_image`` with one ray-casting thread, and the ratio to Open3D's bare ``cast_rays`` of
the same rays measured interleaved in the same run (the floor any ray-cast renderer pays).

    nice -n 5 python benchmarks/vo_sim_street.py [--seeds 0 1 2] [--frames 1000] [--out benchmarks/results/vo_sim]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from lidarkit import atomic
from lidarkit.bench.machine import describe_machine, machine_info
from lidarkit.eval.kitti_drift import kitti_drift
from lidarkit.sim.street_camera import SimulatedCameraSequence
from lidarkit.vo import MonoVO, preset
from lidarkit.vo.evaluation import score_vo

REPO = Path(__file__).resolve().parents[1]


def scale_drift(est, gt, stretch_m: float = 100.0) -> dict:
    """Estimated / true path length of consecutive ``stretch_m`` stretches of the ground truth (est already
    aligned): the ratios, their spread and the mean absolute change between neighbours (per ``stretch_m``)."""
    d = gt.distances_m
    edges = np.unique(np.r_[np.searchsorted(d, np.arange(0.0, d[-1], stretch_m)), len(d) - 1])  # last may be short
    steps_est = np.r_[0.0, np.linalg.norm(np.diff(est.positions_xyz, axis=0), axis=1)]
    steps_gt = np.r_[0.0, np.linalg.norm(np.diff(gt.positions_xyz, axis=0), axis=1)]
    ratios = []
    for a, b in zip(edges[:-1], edges[1:]):
        ratios.append(float(steps_est[a + 1 : b + 1].sum() / max(steps_gt[a + 1 : b + 1].sum(), 1e-9)))
    r = np.asarray(ratios)
    change = np.abs(np.diff(np.log(r))) if len(r) > 1 else np.array([np.nan])
    return {"stretch_m": stretch_m, "ratios": ratios, "ratio_min": float(r.min()), "ratio_max": float(r.max()),
            "mean_abs_change_pct_per_stretch": float(100 * np.mean(change))}


def run_vo(seq: SimulatedCameraSequence, mode: str) -> dict:
    gt = seq.ground_truth
    start = time.perf_counter()
    result = MonoVO(preset("lidarkit", **{"scale.mode": mode}), seq.K, gt if mode == "gt" else None).run(seq)
    wall = time.perf_counter() - start
    traj = result.trajectory
    if mode != "gt":
        traj = traj.transformed(T_left=gt.poses_se3[result.meta["start_frame"]])
    scores = score_vo(traj, gt, mode)
    aligned = scores.ape.est_aligned
    drift = kitti_drift(gt, aligned, allow_empty=True)
    row = dict(scores.metrics)
    row.update({"accepted_pairs": result.accepted_pairs, "rejected": len(result.rejected),
                "rejection_reasons": result.rejection_counts(), "vo_frames_per_s": result.frames_per_s,
                "wall_s_incl_render": wall, "path_m": gt.length_m,
                "kitti_translation_pct": drift.translation_pct if drift.valid else None,
                "kitti_rotation_deg_per_100m": drift.rotation_deg_per_100m if drift.valid else None,
                "scale_drift": scale_drift(aligned, gt)})
    return row


def render_speed(seed: int, frames: int) -> dict:
    """Interleaved: a full render (one thread) and the bare cast of the same rays, per frame."""
    import open3d as o3d

    seq = SimulatedCameraSequence(n_frames=frames, seed=seed, threads=1)
    seq.read_image(0)  # first frame generates the textures in view
    poses = seq.world_poses
    t_render, t_cast, c_render, c_cast = [], [], [], []
    for k in range(1, frames):
        t0, c0 = time.perf_counter(), time.process_time()
        seq.read_image(k)
        t1, c1 = time.perf_counter(), time.process_time()
        R, t = poses[k][:3, :3].astype(np.float32), poses[k][:3, 3].astype(np.float32)
        rays = np.c_[np.broadcast_to(t, seq._dirs_cam.shape), seq._dirs_cam @ R.T].astype(np.float32)
        t2, c2 = time.perf_counter(), time.process_time()
        seq.scene.cast_rays(o3d.core.Tensor(rays), nthreads=1)
        t3, c3 = time.perf_counter(), time.process_time()
        t_render.append(t1 - t0)
        t_cast.append(t3 - t2)
        c_render.append(c1 - c0)
        c_cast.append(c3 - c2)
    render, cast = float(np.median(t_render)), float(np.median(t_cast))
    cpu_render, cpu_cast = float(np.median(c_render)), float(np.median(c_cast))
    return {"frames": frames - 1, "render_ms_median": 1e3 * render, "cast_rays_ms_median": 1e3 * cast,
            "render_frames_per_s": 1.0 / render, "render_over_cast": render / cast,
            "render_cpu_ms_median": 1e3 * cpu_render, "cast_rays_cpu_ms_median": 1e3 * cpu_cast,
            "render_frames_per_cpu_s": 1.0 / cpu_render}


def geometry_checks(seed: int, frames: int, every: int) -> dict:
    """The synthetic-camera geometry check (tests/test_sim_camera.py) on pairs ``(k, k + 1)`` every ``every``
    frames of a ``frames``-frame run: GFTT + KLT, essential matrix (RANSAC), rotation error and translation-direction
    error against the ground truth. Pairs that move less than 5 cm (stops) have no direction and are skipped."""
    import cv2

    from lidarkit.geometry import se3_inverse
    from lidarkit.vo import VOConfig, estimate_two_view, get_detector, track_klt
    from lidarkit.vo.two_view import rotation_error_deg

    seq = SimulatedCameraSequence(n_frames=frames, seed=seed)
    gt = seq.ground_truth.poses_se3
    cfg = VOConfig()
    detector = get_detector(cfg.features)
    rows = []
    for k in range(0, frames - 1, every):
        T = se3_inverse(gt[k + 1]) @ gt[k]
        step = float(np.linalg.norm(T[:3, 3]))
        if step < 0.05:
            continue
        a, b = seq.read_image(k), seq.read_image(k + 1)
        p0, _ = detector.detect(a)
        p1, ok = track_klt(a, b, p0, cfg.matching)
        cv2.setRNGSeed(k)
        est = estimate_two_view(p0[ok], p1[ok], seq.K, cfg.geometry)
        if not est.ok:
            rows.append({"frame": k, "step_m": step, "ok": False})
            continue
        direction = float(np.degrees(np.arccos(np.clip(est.t_cur_ref @ (T[:3, 3] / step), -1, 1))))
        rows.append({"frame": k, "step_m": step, "ok": True, "rot_deg": rotation_error_deg(est.R_cur_ref, T[:3, :3]),
                     "dir_deg": direction})
    good = [r for r in rows if r["ok"]]
    passed = [r for r in good if r["rot_deg"] < 0.1 and r["dir_deg"] < 1.0]
    return {"seed": seed, "every": every, "pairs": len(rows), "estimated": len(good), "passed": len(passed),
            "rot_deg_max": max((r["rot_deg"] for r in good), default=float("nan")),
            "dir_deg_max": max((r["dir_deg"] for r in good), default=float("nan")),
            "rot_deg_median": float(np.median([r["rot_deg"] for r in good])) if good else float("nan"),
            "dir_deg_median": float(np.median([r["dir_deg"] for r in good])) if good else float("nan"),
            "failing": [r for r in rows if r not in passed]}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", nargs="+", type=int, default=[0])  # (none given: an IndexError)
    ap.add_argument("--frames", type=int, default=1000)
    ap.add_argument("--modes", nargs="*", default=["gt", "relative"], help="scale modes (none given: speed only)")
    ap.add_argument("--speed-frames", type=int, default=60)
    ap.add_argument("--geometry-every", type=int, default=0, help="geometry checks on pairs every N frames (0: none)")
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "vo_sim")
    args = ap.parse_args(argv)
    info_start = machine_info()
    command = "python benchmarks/vo_sim_street.py " + " ".join(sys.argv[1:] if argv is None else argv)
    import subprocess

    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True, text=True).stdout.strip()
    command += f"  (at commit {commit or 'unknown'})"
    speed = render_speed(args.seeds[0], args.speed_frames)
    print("render speed", speed, file=sys.stderr)
    rows = {}
    geometry = [geometry_checks(seed, args.frames, args.geometry_every) for seed in args.seeds] \
        if args.geometry_every else []
    if not args.modes or not args.seeds:
        write(args, command, info_start, speed, rows, geometry)
    for seed in args.seeds if args.modes else []:
        seq = SimulatedCameraSequence(n_frames=args.frames, seed=seed)
        for mode in args.modes:
            row = run_vo(seq, mode)
            print(seed, mode, {k: v for k, v in row.items() if k != "scale_drift"}, file=sys.stderr)
            rows[f"street seed {seed}, {args.frames} frames, scale {mode}"] = row
            write(args, command, info_start, speed, rows, geometry)  # after every run: a long benchmark keeps what it did
    return 0


def write(args, command: str, info_start: dict, speed: dict, rows: dict, geometry: list) -> None:
    info_end = machine_info()
    args.out.mkdir(parents=True, exist_ok=True)
    atomic.write_text(args.out / "results.json", json.dumps(
        {"command": command, "machine_start": info_start, "machine_end": info_end, "render_speed": speed,
         "runs": rows, "geometry_checks": geometry}, indent=1))
    lines = [f"# VO on simulated street runs ({args.frames} frames, KITTI size and intrinsics)", "",
             f"Command: `{command}`", "", f"Date: {info_start['date_utc']}", "", f"Start: {describe_machine(info_start)}", "",
             f"End: {describe_machine(info_end)}", ""]
    if rows:
        lines += ["| run | path m | accepted pairs | APE m (align) | final error m | KITTI drift % / deg per 100 m "
             "| 100 m scale ratio min..max | scale change % per 100 m |",
                  "|---|---|---|---|---|---|---|---|"]
    for name, r in rows.items():
        sd = r["scale_drift"]
        kt = r["kitti_translation_pct"]
        drift = "n/a" if kt is None else f"{kt:.2f} / {r['kitti_rotation_deg_per_100m']:.3f}"
        lines.append(f"| {name} | {r['path_m']:.0f} | {r['accepted_pairs']} | {r['ape_rmse_m']:.3f} ({r['align']}) | "
                     f"{r['final_error_m']:.2f} | {drift} | {sd['ratio_min']:.3f}..{sd['ratio_max']:.3f} | "
                     f"{sd['mean_abs_change_pct_per_stretch']:.2f} |")
    lines += ["", f"Render speed (seed {args.seeds[0]}, {speed['frames']} frames, one ray-casting thread): median "
              f"{speed['render_ms_median']:.1f} ms per frame = {speed['render_frames_per_s']:.1f} frames/s; bare "
              f"`cast_rays` of the same rays {speed['cast_rays_ms_median']:.1f} ms (render / cast = "
              f"{speed['render_over_cast']:.2f}, measured interleaved)"
              + (f"; CPU time (less sensitive to other jobs' load) {speed['render_cpu_ms_median']:.1f} ms per frame = "
                 f"{speed['render_frames_per_cpu_s']:.1f} frames per CPU second, bare cast "
                 f"{speed['cast_rays_cpu_ms_median']:.1f} ms." if "render_cpu_ms_median" in speed else ".")]
    for g in geometry:
        lines += ["", f"Geometry check, seed {g['seed']} (GFTT + KLT + RANSAC essential matrix on pairs (k, k + 1) every "
                  f"{g['every']} frames, noise-free, moving pairs): {g['passed']} of {g['pairs']} pairs within rotation "
                  f"< 0.1 deg and direction < 1 deg ({g['estimated']} estimated); median {g['rot_deg_median']:.3f} deg / "
                  f"{g['dir_deg_median']:.2f} deg, worst {g['rot_deg_max']:.3f} deg / {g['dir_deg_max']:.2f} deg."]
    atomic.write_text(args.out / "README.md", "\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    from lidarkit.cli import run_script

    run_script(main)
