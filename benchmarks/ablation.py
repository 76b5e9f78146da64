"""Ablation of KISS-ICP's building blocks with the ``pipeline`` variant, and the wrapped references beside it.

Starting from ``kiss_like`` (kiss-icp rebuilt from lidarkit components), one component is switched at a time:

  no_deskew        constant-velocity prediction kept, no motion compensation
  fixed_threshold  a fixed 1 m correspondence distance instead of the adaptive threshold (kernel scale follows it)
  unlimited_threshold  every nearest neighbour is a correspondence (vanilla's threshold; no kernel: its scale would be
                   infinite)
  no_kernel        plain least squares instead of the Geman-McClure kernel
  scan_to_scan     the previous sweep as the map instead of the voxel-hash local map
  point_to_plane   point-to-plane residual (map normals) instead of point-to-point
  vanilla_settings every component as in the report's vanilla ICP (``vanilla_seq``: point-to-point, no kernel,
                   every nearest neighbour, no deskew, scan-to-scan) but on kiss's voxelized clouds (full clouds
                   would take ~3 s a sweep)

and compared with kiss-icp itself (``kiss``) and GenZ-ICP (``genz`` through lidarkit vs ``genz_icp.GenZICP``
called directly, each in a fresh process because genz-icp keeps process-wide state between instances).

Data: the 10 KITTI seq-00 scans (end error vs SemanticKITTI), and simulated ``street`` / ``open`` sequences
(``sim:SCENE?frames=N&seed=S``: HDL-64-like 64 x 2000 rays, motion distortion, ground truth at the sweep end).
The in-process variants run in lockstep on the same scans (each scan read once, the order of the variants
rotated every frame), so frame rates are comparable and reported as ratios to kiss-icp's in the same run.

    python benchmarks/ablation.py run --dataset kitti
    python benchmarks/ablation.py run --dataset street --seed 0 --frames 300
    python benchmarks/ablation.py report          # tables, bar chart, results.json from every raw/*.json
    python benchmarks/ablation.py all --seeds 0 1 --frames 300
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DEFAULT_DATA = REPO.parent / "shared" / "data"
DEFAULT_OUT = REPO / "benchmarks" / "results" / "ablation"

#: vanilla ICP's components on kiss's voxelized clouds (full clouds would take ~3 s a sweep).
VANILLA = {"preset": "vanilla_seq", "map_voxel_factor": 0.5, "source_voxel_factor": 1.5}
#: kiss ties its kernel scale to the adaptive threshold (c^2 = sigma x 1 m), which is infinite with vanilla's
#: unlimited threshold; the kernel added alone therefore gets kiss's scale before any motion is seen (sigma = 2 m).
VANILLA_KERNEL_SCALE_M = 2.0**0.5
#: kiss_like with one component switched (pipeline parameters on top of preset=kiss_like), and vanilla with one added.
ABLATIONS: dict[str, dict] = {
    "kiss_like": {},
    "no_deskew": {"deskew": {"name": "constant_velocity", "deskew": False}},
    "fixed_threshold": {"threshold": {"name": "fixed", "max_distance_m": 1.0}},
    # (the kernel's scale follows the threshold, infinite here: kernel none states what it did; the pipeline refuses the pair)
    "unlimited_threshold": {"threshold": {"name": "fixed", "max_distance_m": None}, "kernel": "none"},
    "no_kernel": {"kernel": "none"},
    "scan_to_scan": {"map": "scan_to_scan"},
    "point_to_plane": {"residual": "point_to_plane"},
    "vanilla_settings": VANILLA,
    # the other direction: vanilla_settings with one of kiss's components added
    "vanilla+deskew": {**VANILLA, "deskew": {"name": "constant_velocity", "deskew": True, "reference": "end"}},
    "vanilla+adaptive_threshold": {**VANILLA, "threshold": "adaptive"},
    "vanilla+kernel": {**VANILLA, "kernel": {"name": "geman_mcclure", "scale_m": VANILLA_KERNEL_SCALE_M}},
    "vanilla+local_map": {**VANILLA, "map": "voxel_hash"},
}
#: The single-component removals from kiss_like and the single-component additions to vanilla_settings.
REMOVALS = ["no_deskew", "fixed_threshold", "unlimited_threshold", "no_kernel", "scan_to_scan", "point_to_plane"]
ADDITIONS = ["vanilla+deskew", "vanilla+adaptive_threshold", "vanilla+kernel", "vanilla+local_map"]
#: genz-icp's pretuned KITTI settings (genz_icp/config/pretuned/kitti.yaml), used on every dataset.
GENZ_PARAMS = {"min_range_m": 5.0, "voxel_size_m": 0.6, "desired_num_voxelized_points": 3000, "planarity_threshold": 0.18, "max_points_per_voxel": 3}


def log(msg: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


def open_dataset(name: str, seed: int, frames: int, data: Path):
    """``(label, n_frames, read(i) -> (points, times or None), ground truth (N, 4, 4) relative to frame 0)``."""
    if name == "kitti":
        from lidarkit.io.kitti import KittiOdometry

        folder = data / "kitti_odometry" / "sequences" / "00"
        seq = KittiOdometry(folder, poses_file=folder / "poses_semantickitti.txt")
        label = "KITTI 00 (10 scans)"
    else:
        from lidarkit.sim.lidar import open_sim

        seq = open_sim(f"sim:{name}?frames={frames}&seed={seed}")
        label = f"sim {name} seed {seed} ({frames} sweeps)"
    gt = seq.ground_truth.poses_se3
    gt = np.linalg.inv(gt[0]) @ gt

    def read(i: int):
        scan = seq.read_scan(i)
        return np.asarray(scan.points_xyz, dtype=np.float64), scan.point_times_s

    return label, len(seq), read, gt


def score(poses: np.ndarray, gt: np.ndarray) -> dict:
    """End error, APE RMSE (no alignment: both start at the identity) and KITTI drift when the path allows."""
    from lidarkit import eval as leval
    from lidarkit.geometry import pose_error
    from lidarkit.trajectory import Trajectory

    stamps = np.arange(len(gt), dtype=np.float64) * 0.1
    ref, est = Trajectory(gt, stamps, name="ground truth"), Trajectory(poses, stamps, name="estimate")
    dt, dr = pose_error(poses[-1], gt[-1])
    out = {"end_error_m": float(dt), "end_error_deg": float(dr), "path_m": float(ref.length_m)}
    out["ape_rmse_m"] = float(leval.ape(ref, est, align="none", relation="translation").stats["rmse"])
    if leval.drift_segments_possible(ref):
        d = leval.kitti_drift(ref, est)
        out["drift_pct"], out["drift_deg_per_100m"] = float(d.translation_pct), float(d.rotation_deg_per_100m)
    return out


GENZ_CHILD = r"""
import json, sys, time, numpy as np
cache, mode, params = sys.argv[1], sys.argv[2], json.loads(sys.argv[3])
n = int(sys.argv[4])
frames = [np.load(f"{cache}/{i:05d}.npy") for i in range(n)]
from lidarkit.registration import get_icp
method = get_icp("genz", **params)
poses, spent = [], 0.0
if mode == "direct":
    from genz_icp.genz_icp import GenZICP
    odometry = GenZICP(method.config.to_genz_config())
    for f in frames:
        t = time.perf_counter(); odometry.register_frame(f, None); spent += time.perf_counter() - t
        poses.append(odometry.last_pose.copy())
else:
    method.reset()
    for f in frames:
        t = time.perf_counter(); poses.append(method.register_frame(f)); spent += time.perf_counter() - t
np.save(f"{cache}/poses_{mode}.npy", np.stack(poses))
print(json.dumps({"seconds": spent}))
"""


def run_genz(cache: Path, n: int, repeats: int) -> dict[str, tuple[np.ndarray, float]]:
    """genz-icp direct and genz through lidarkit, each the first GenZICP of a fresh process, on cached scans."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}
    out = {}
    for mode in ("direct", "lidarkit") * repeats:  # interleaved repeats: keep each one's faster loop
        done = subprocess.run(
            [sys.executable, "-c", GENZ_CHILD, str(cache), mode, json.dumps(GENZ_PARAMS), str(n)],
            env=env, capture_output=True, text=True, check=True,
        )
        seconds = json.loads(done.stdout.strip().splitlines()[-1])["seconds"]
        poses = np.load(cache / f"poses_{mode}.npy")
        if mode not in out or seconds < out[mode][1]:
            out[mode] = (poses, seconds)
    return out


def run_dataset(name: str, seed: int, frames: int, data: Path, out: Path, genz: bool, variants: list[str] | None = None) -> Path:
    from lidarkit.registration import available_icp, get_icp

    if not genz:  # (it replaced the record silently, and the next report lost the genz rows)
        earlier = _path(out, name, seed, frames if name != "kitti" else 10, variants)
        if earlier.is_file() and "genz" in json.loads(earlier.read_text()).get("rows", {}):
            raise SystemExit(f"--no-genz would replace {earlier}, which holds genz rows: run with genz, or give another --out")
    log(f"{name}: opening the data (a simulated sequence is ray-cast first)")
    label, n, read, gt = open_dataset(name, seed, frames, data)
    log(f"{label}: {n} frames, {1 + len(ABLATIONS if variants is None else [k for k in ABLATIONS if k in variants])} methods")
    methods = {"kiss": get_icp("kiss")}
    for key, params in ABLATIONS.items():
        if variants is None or key in variants:
            methods[key] = get_icp("pipeline", **{"preset": "kiss_like", **params})
    for m in methods.values():
        m.reset()
    names = list(methods)
    poses = {k: np.empty((n, 4, 4)) for k in names}
    spent = {k: 0.0 for k in names}
    genz = genz and "genz" in available_icp()
    with tempfile.TemporaryDirectory(prefix="lidarkit-ablation-") as tmp:
        cache = Path(tmp)
        n_points = 0
        for i in range(n):
            points, times = read(i)
            n_points += len(points)
            if genz:
                np.save(cache / f"{i:05d}.npy", points)
            order = names[i % len(names):] + names[: i % len(names)]
            for key in order:
                t = time.perf_counter()
                poses[key][i] = methods[key].register_frame(points, times)
                spent[key] += time.perf_counter() - t
            if i == 0:
                log(f"{label}: frame 1 done by every method")
            if (i + 1) % 25 == 0 or i + 1 == n:
                log(f"{label}: {i + 1}/{n} frames")
                if i + 1 < n:  # a checkpoint: the frames so far, kept if the run is cut short
                    _write(out, name, seed, i + 1, variants, {
                        "dataset": name, "seed": seed if name != "kitti" else None, "n_frames": i + 1, "label": f"{label}, first {i + 1}",
                        "partial_of": n, "rows": _rows(names, poses, spent, gt, i + 1),
                    }, partial=True)
        genz_runs = run_genz(cache, n, 3 if name == "kitti" else 1) if genz else {}
    rows = _rows(names, poses, spent, gt, n)
    kiss_like_gap = np.abs(poses["kiss_like"] - poses["kiss"]).max() if "kiss_like" in poses else float("nan")
    extra = {"kiss_like_max_abs_pose_difference_to_kiss": float(kiss_like_gap)}
    for mode, key in (("direct", "genz-icp (direct)"), ("lidarkit", "genz")):
        if mode in genz_runs:
            p, s = genz_runs[mode]
            rows[key] = {**score(p, gt), "fps": n / s, "seconds": s}
            rows[key]["fps_ratio_to_kiss"] = rows[key]["fps"] / rows["kiss"]["fps"]
    if genz_runs:
        extra["genz_max_abs_pose_difference_to_direct"] = float(np.abs(genz_runs["lidarkit"][0] - genz_runs["direct"][0]).max())
        extra["genz_fps_ratio_to_direct"] = rows["genz"]["fps"] / rows["genz-icp (direct)"]["fps"]
    record = {
        "dataset": name, "seed": seed if name != "kitti" else None, "n_frames": n, "label": label,
        "mean_points_per_scan": n_points / n, "rows": rows, **extra,
    }
    path = _write(out, name, seed, n, variants, record)
    partial = _path(out, name, seed, n, variants, partial=True)
    if partial.exists():
        partial.unlink()
    log(f"wrote {path}")
    return path


def _rows(names, poses, spent_s, gt, n) -> dict:
    rows = {key: {**score(poses[key][:n], gt[:n]), "fps": n / spent_s[key], "seconds": spent_s[key]} for key in names}
    for key in names:
        rows[key]["fps_ratio_to_kiss"] = rows[key]["fps"] / rows["kiss"]["fps"]
    return rows


def _path(out: Path, name: str, seed: int, n: int, variants, partial: bool = False) -> Path:
    subset = "" if variants is None else "_" + "-".join(sorted(variants))
    stem = name if name == "kitti" else f"{name}_seed{seed}"
    return out / ("partial" if partial else "raw") / f"{stem}{'' if partial else '_' + str(n) if name != 'kitti' else ''}{subset}.json"


def _write(out: Path, name: str, seed: int, n: int, variants, record: dict, partial: bool = False) -> Path:
    from lidarkit.atomic import write_text

    path = _path(out, name, seed, n, variants, partial)
    path.parent.mkdir(parents=True, exist_ok=True)
    record["variants_subset"] = variants
    write_text(path, json.dumps(record, indent=2) + "\n")
    return path


# ---------------------------------------------------------------------------------------------- report
#: The kiss component each single change concerns: (removed from kiss_like, added to vanilla_settings).
COMPONENTS = {
    "deskew": (["no_deskew"], ["vanilla+deskew"]),
    "adaptive threshold": (["fixed_threshold", "unlimited_threshold"], ["vanilla+adaptive_threshold"]),
    "robust kernel": (["no_kernel"], ["vanilla+kernel"]),
    "local map": (["scan_to_scan"], ["vanilla+local_map"]),
}


def _verdict(comps: dict, by_removal: str, by_addition: str) -> str:
    cost = np.nanmean(comps[by_removal]["removal_cost"])
    gain = np.nanmean(comps[by_addition]["addition_gain"])
    if by_removal == by_addition and cost > 0 and gain > 0:
        return (f"**The single component that accounts for most of the gap: {by_removal}**: removing it from kiss_like costs most, "
                "and adding it to vanilla_settings closes most.")
    first = f"Removing **{by_removal}** from kiss_like costs most" if cost > 0 else "No single removal from kiss_like costs anything"
    second = (f"adding **{by_addition}** to vanilla_settings closes most" if gain > 0
              else f"no single addition to vanilla_settings closes any of the gap (each makes it worse; {by_addition} least)")
    return f"{first}; {second}: the two directions do not name the same component here."


def attribute_gap(recs: list[dict]) -> tuple[list[str], dict]:
    """Which single component accounts for most of the gap vanilla_settings - kiss_like, in both directions.

    The metric is KITTI drift (percentage points) where every seed's path allows it, APE RMSE (m) otherwise.
    Removal: the change a switch away from kiss makes to kiss_like; addition: the change adding that component
    makes to vanilla_settings, as a share of the gap (100 % = the whole gap, negative = makes it worse).
    """
    use_drift = all(np.isfinite(r["rows"]["kiss_like"].get("drift_pct", np.nan)) for r in recs)
    field, unit = ("drift_pct", "pct points of drift") if use_drift else ("ape_rmse_m", "m APE RMSE")
    val = lambda r, k: r["rows"][k].get(field, np.nan) if k in r["rows"] else np.nan  # noqa: E731
    gap = np.array([val(r, "vanilla_settings") - val(r, "kiss_like") for r in recs])
    rows, out = [], {"metric": field, "gap": (float(gap.mean()), float(gap.std())), "per_seed_gap": gap.tolist(), "components": {}}
    for comp, (removals, additions) in COMPONENTS.items():
        # a component with several removals (threshold: fixed 1 m, unlimited) is judged by vanilla's own choice
        removal = removals[-1]
        cost = np.array([val(r, removal) - val(r, "kiss_like") for r in recs])
        gain = np.array([val(r, "vanilla_settings") - val(r, additions[0]) for r in recs])
        out["components"][comp] = {
            "removal": removal, "removal_cost": cost.tolist(), "removal_share_of_gap": (cost / gap).tolist(),
            "addition": additions[0], "addition_gain": gain.tolist(), "addition_share_of_gap": (gain / gap).tolist(),
        }
        # shares: mean change over mean gap (a per-seed ratio explodes where a seed's gap is small)
        rows.append(f"| {comp} | {removal} | {np.nanmean(cost):+.3g} +- {np.nanstd(cost):.2g} | {100 * np.nanmean(cost) / gap.mean():.0f} % "
                    f"| {additions[0]} | {np.nanmean(gain):+.3g} +- {np.nanstd(gain):.2g} | {100 * np.nanmean(gain) / gap.mean():.0f} % |")
    comps = out["components"]
    by_removal = max(comps, key=lambda c: np.nanmean(comps[c]["removal_cost"]))
    by_addition = max(comps, key=lambda c: np.nanmean(comps[c]["addition_gain"]))
    per_seed_removal = [max(comps, key=lambda c: comps[c]["removal_cost"][i]) for i in range(len(recs))]
    per_seed_addition = [max(comps, key=lambda c: comps[c]["addition_gain"][i]) for i in range(len(recs))]
    out.update(largest_by_removal=by_removal, largest_by_addition=by_addition,
               per_seed_largest_by_removal=per_seed_removal, per_seed_largest_by_addition=per_seed_addition)
    seeds = [r["seed"] for r in recs]
    text = [
        f"Gap vanilla_settings - kiss_like: {gap.mean():+.3g} +- {gap.std():.2g} {unit} (per seed: "
        + ", ".join(f"{s}: {g:+.3g}" for s, g in zip(seeds, gap)) + "). Each kiss component changed alone, mean +- std over seeds:",
        "",
        f"| component | removed from kiss_like | cost ({unit}) | share of gap | added to vanilla_settings | gain ({unit}) | share of gap closed |",
        "|---|---|---:|---:|---|---:|---:|",
        *rows,
        "",
        (_verdict(comps, by_removal, by_addition) if np.all(gap > 0) else
         "**No gap to attribute here**: kiss_like is not better than vanilla_settings on every seed (per-seed gaps above), so no "
         "component can account for it.")
        + " Largest per seed, removal: " + ", ".join(f"{s}: {c}" for s, c in zip(seeds, per_seed_removal))
        + "; addition: " + ", ".join(f"{s}: {c}" for s, c in zip(seeds, per_seed_addition)) + ". The shares need not add up to 100 %: the components interact.",
    ]
    return text, out



ORDER = ["kiss", "kiss_like", *[k for k in ABLATIONS if k != "kiss_like"], "genz", "genz-icp (direct)"]


def _fmt(v, digits=3):
    return "-" if v is None or (isinstance(v, float) and not np.isfinite(v)) else f"{v:.{digits}f}"


def report(out: Path, command: str) -> None:
    import datetime as dt

    from lidarkit.atomic import write_text
    from lidarkit.bench.machine import describe_machine, machine_info

    records = [json.loads(p.read_text()) for p in sorted((out / "raw").glob("*.json"))]
    if not records:
        raise SystemExit(f"no raw results in {out / 'raw'}")
    lines = [
        "# Ablation of KISS-ICP's components (pipeline variant)",
        "",
        f"- date: {dt.datetime.now(dt.timezone.utc).isoformat(timespec='seconds')}",
        f"- machine: {describe_machine(machine_info())}",
        f"- command: `{command}`",
        "- frame rates: frames / time in `register_frame`, all variants in lockstep on the same scans; `x kiss` is the",
        "  ratio to kiss-icp's rate in the same run (genz rows: each in its own fresh process, same cached scans).",
        "",
    ]
    summary: dict = {"datasets": [], "sim": {}}
    kitti = [r for r in records if r["dataset"] == "kitti"]
    for r in kitti:
        lines += [f"## {r['label']}: end error vs SemanticKITTI ({r['mean_points_per_scan']:.0f} points / scan)", "",
                  "| variant | end error m | end error deg | APE RMSE m | frame rate Hz | x kiss |", "|---|---:|---:|---:|---:|---:|"]
        for key in ORDER:
            if key in r["rows"]:
                row = r["rows"][key]
                lines.append(f"| {key} | {_fmt(row['end_error_m'])} | {_fmt(row['end_error_deg'])} | {_fmt(row['ape_rmse_m'])} | {_fmt(row['fps'], 1)} | {_fmt(row['fps_ratio_to_kiss'], 2)} |")
        lines += ["", f"kiss_like vs kiss-icp, largest pose-matrix difference over the 10 frames: {r['kiss_like_max_abs_pose_difference_to_kiss']:.2e}"]
        if "genz_max_abs_pose_difference_to_direct" in r:
            lines.append(f"genz vs genz-icp direct: largest difference {r['genz_max_abs_pose_difference_to_direct']:.2e}, frame-rate ratio {r['genz_fps_ratio_to_direct']:.3f}")
        if all(k in r["rows"] for k in ("kiss_like", "vanilla_settings", *ADDITIONS)):
            text, r["gap_attribution"] = attribute_gap([{**r, "seed": "KITTI"}])
            lines += ["", *text]
        lines.append("")
        summary["datasets"].append(r)
    sims = [r for r in records if r["dataset"] != "kitti"]
    # a subset run (--variants) of a sequence that also has a full run adds its extra variants to that run's rows
    full = {(r["dataset"], r["n_frames"], r["seed"]): r for r in sims if not r.get("variants_subset")}
    for r in [r for r in sims if r.get("variants_subset")]:
        target = full.get((r["dataset"], r["n_frames"], r["seed"]))
        if target is not None:
            extra = {k: v for k, v in r["rows"].items() if k not in target["rows"]}
            for v in extra.values():  # its frame rate relative to its own run's kiss-icp
                v["fps_note"] = "separate run"
            target["rows"].update(extra)
            sims.remove(r)
    groups = sorted({(r["dataset"], r["n_frames"], tuple(r.get("variants_subset") or ())) for r in sims})
    for scene, n_frames, subset in groups:
        recs = sorted([r for r in sims if (r["dataset"], r["n_frames"], tuple(r.get("variants_subset") or ())) == (scene, n_frames, subset)],
                      key=lambda r: r["seed"])
        seeds = [r["seed"] for r in recs]
        lines += [f"## sim {scene}: {recs[0]['n_frames']} sweeps, seeds {', '.join(map(str, seeds))} (mean +- std over seeds; per seed in results.json)", "",
                  "| variant | KITTI drift % | deg/100 m | APE RMSE m | end error m | frame rate Hz | x kiss | drift change vs base (pct points; base: kiss_like, for vanilla+ rows vanilla_settings) |",
                  "|---|---:|---:|---:|---:|---:|---:|---:|"]
        scene_summary = {}
        for key in ORDER:
            vals = [r["rows"][key] for r in recs if key in r["rows"]]
            if not vals:
                continue

            def stat(field, vals=vals):
                x = np.array([v.get(field, np.nan) for v in vals], dtype=float)
                return float(np.mean(x)), float(np.std(x))

            d, ddeg, ape, end, fps, ratio = (stat(f) for f in ("drift_pct", "drift_deg_per_100m", "ape_rmse_m", "end_error_m", "fps", "fps_ratio_to_kiss"))
            base = "vanilla_settings" if key in ADDITIONS else "kiss_like"
            change = np.array([r["rows"][key].get("drift_pct", np.nan) - r["rows"][base].get("drift_pct", np.nan) for r in recs if key in r["rows"] and base in r["rows"]])
            ape_change = np.array([r["rows"][key]["ape_rmse_m"] - r["rows"][base]["ape_rmse_m"] for r in recs if key in r["rows"] and base in r["rows"]])
            scene_summary[key] = {"base": base, "ape_change_vs_base": (float(ape_change.mean()), float(ape_change.std())), "drift_pct": d, "drift_deg_per_100m": ddeg, "ape_rmse_m": ape, "end_error_m": end, "fps": fps,
                                  "fps_ratio_to_kiss": ratio, "drift_change_vs_base": (float(change.mean()), float(change.std())),
                                  "per_seed": {str(r["seed"]): r["rows"][key] for r in recs if key in r["rows"]}}
            lines.append(
                f"| {key} | {_fmt(d[0], 2)} +- {_fmt(d[1], 2)} | {_fmt(ddeg[0], 2)} +- {_fmt(ddeg[1], 2)} | {_fmt(ape[0], 2)} +- {_fmt(ape[1], 2)} | "
                f"{_fmt(end[0], 2)} +- {_fmt(end[1], 2)} | {_fmt(fps[0], 1)} | {_fmt(ratio[0], 2)} | {_fmt(change.mean(), 2)} +- {_fmt(change.std(), 2)} |"
            )
        if all(k in recs[0]["rows"] for k in ("kiss_like", "vanilla_settings")):
            text, scene_summary["_gap_attribution"] = attribute_gap(recs)
            lines += ["", *text]
        lines += ["", "kiss_like vs kiss-icp, largest pose-matrix difference per seed: "
                  + ", ".join(f"seed {r['seed']}: {r.get('kiss_like_max_abs_pose_difference_to_kiss', float('nan')):.2e}" for r in recs)]
        if all("genz_max_abs_pose_difference_to_direct" in r for r in recs):
            lines.append("genz vs genz-icp direct, largest difference / frame-rate ratio per seed: "
                         + ", ".join(f"seed {r['seed']}: {r['genz_max_abs_pose_difference_to_direct']:.2e} / {r['genz_fps_ratio_to_direct']:.3f}" for r in recs))
        lines.append("")
        summary["sim"][f"{scene} {n_frames} sweeps" + (" (kiss vs kiss_like only)" if subset else "")] = scene_summary
    _chart(summary, out)
    lines += ["![change each single-component switch makes: removals vs kiss_like (top), additions vs vanilla_settings (bottom); drift, or APE where the run is too short for drift](ablation.png)", ""]
    notes = out / "notes.md"  # hand-written findings and the runs' limits, kept beside the generated tables
    if notes.exists():
        lines += [notes.read_text().rstrip(), ""]
    write_text(out / "results.json", json.dumps({"records": records, "summary_sim": summary["sim"]}, indent=2, default=float) + "\n")
    write_text(out / "README.md", "\n".join(lines) + "\n")


def _chart(summary: dict, out: Path) -> None:
    """Per scene: each single change's effect, removals from kiss_like (top) and additions to vanilla (bottom)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from lidarkit.atomic import save_figure

    scenes = sorted(k for k, v in summary["sim"].items() if "kiss_like" in v and any(key in v for key in REMOVALS))[:3]
    if not scenes:
        return
    fig, axes = plt.subplots(2, len(scenes), figsize=(5.8 * len(scenes), 7), squeeze=False)
    for col, scene in enumerate(scenes):
        s = summary["sim"][scene]
        use_drift = np.isfinite(s["kiss_like"]["drift_pct"][0])
        field = "drift_change_vs_base" if use_drift else "ape_change_vs_base"
        unit = "KITTI drift change (percentage points)" if use_drift else "APE RMSE change (m)"
        for row, (keys, base) in enumerate(((REMOVALS, "kiss_like"), (ADDITIONS, "vanilla_settings"))):
            ax = axes[row, col]
            keys = [k for k in keys if k in s]
            means = [s[k][field][0] for k in keys]
            ax.barh(keys, means, xerr=[s[k][field][1] for k in keys], color=["tab:red" if m > 0 else "tab:green" for m in means])
            ax.axvline(0, color="k", lw=0.8)
            ax.set_xscale("symlog", linthresh=0.1)
            level = s[base]["drift_pct" if use_drift else "ape_rmse_m"][0]
            ax.set_title(f"sim {scene}: vs {base} ({level:.2f} {'%' if use_drift else 'm'})", fontsize=10)
            ax.set_xlabel(unit + ", mean +- std", fontsize=9)
    fig.tight_layout()
    save_figure(fig, out / "ablation.png", dpi=100)
    plt.close(fig)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="one dataset -> raw/*.json")
    r.add_argument("--dataset", choices=["kitti", "street", "open"], required=True)
    r.add_argument("--seed", type=int, default=0)
    r.add_argument("--frames", type=int, default=300)
    r.add_argument("--variants", nargs="+", choices=list(ABLATIONS), help="only these pipeline variants (kiss always runs)")
    a = sub.add_parser("all", help="KITTI and every scene x seed, then the report")
    a.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    a.add_argument("--frames", type=int, default=300)
    a.add_argument("--scenes", nargs="+", default=["street", "open"])
    sub.add_parser("report", help="tables and chart from raw/*.json")
    for p in (r, a):
        p.add_argument("--no-genz", action="store_true", help="skip genz / genz-icp")
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args(argv)
    command = "python benchmarks/ablation.py " + " ".join(sys.argv[1:] if argv is None else argv)
    if args.cmd == "run":
        run_dataset(args.dataset, args.seed, args.frames, args.data, args.out, not args.no_genz, args.variants)
    elif args.cmd == "all":
        run_dataset("kitti", 0, 10, args.data, args.out, not args.no_genz)
        for scene in args.scenes:
            for seed in args.seeds:
                run_dataset(scene, seed, args.frames, args.data, args.out, not args.no_genz)
        report(args.out, command)
    else:
        report(args.out, command)


if __name__ == "__main__":
    from lidarkit.cli import run_script

    run_script(main)
