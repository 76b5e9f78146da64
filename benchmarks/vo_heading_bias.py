"""Where does the heading offset of lidarkit's VO on KITTI 06 (gt scale) come from: our estimate or the ground truth?

For every frame pair of the lidarkit pipeline (gt scale) it compares the estimated relative pose with the ground
truth's (rotation difference and translation-direction difference, signed components in the camera frame: x right,
y down, z forward) and evaluates the epipolar geometry of the SAME inlier correspondences (normalized coordinates,
Sampson error in px) under

* the estimated relative pose (fitted to these points) and, for a fair comparison, a pose fitted to the even-indexed
  points and scored on the odd-indexed ones only (held out),
* the ground-truth relative pose,
* the ground truth with its rotation re-fitted (translation direction kept) and with its translation direction
  re-fitted (rotation kept): which part of the GT disagrees with the images,
* the ground truth seen through one constant camera-to-GT rotation, and through corrected intrinsics (fx, cx, cy),
  each fitted over all pairs: can a constant frame/calibration error reconcile the GT with the images?

Finally it attributes the final-frame error: trajectories chained from (GT rotations + estimated translation
directions) and (estimated rotations + GT translation directions), both with the GT step lengths.

    python benchmarks/vo_heading_bias.py [--data ../shared/data/kitti_images/sequences] [--out benchmarks/results/vo]

Writes ``heading_bias.md`` and ``heading_bias.json`` into ``--out``.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

from lidarkit import atomic
from lidarkit.geometry import se3_inverse, so3_exp, so3_log
from lidarkit.io.kitti import KittiOdometry
from lidarkit.trajectory import Trajectory
from lidarkit.vo import MonoVO, images_in_memory, preset
from lidarkit.vo.consistency import constant_rate_prefix, motion_direction_deg, rotation_increments_deg, sampson_px
from lidarkit.vo.two_view import normalize_points, refine_pose

REPO = Path(__file__).resolve().parents[1]
DEFAULT_DATA = REPO.parent / "shared" / "data" / "kitti_images" / "sequences"


def pairs_of(result, gt_poses: np.ndarray, K: np.ndarray) -> list[dict]:
    """Per accepted frame pair: GT and estimated relative pose (``X_cur = R X_ref + t``, unit t) and the inliers."""
    accepted = [d for d in result.diagnostics[1:] if d.accepted]
    est = result.trajectory.poses_se3
    out = []
    for (j, p_ref, p_cur), d in zip(result.tracks, accepted, strict=True):
        i = d.ref_frame
        T_gt = se3_inverse(gt_poses[j]) @ gt_poses[i]
        T_est = se3_inverse(est[j]) @ est[i]
        out.append({"ref": i, "cur": j, "a": normalize_points(p_ref, K), "b": normalize_points(p_cur, K),
                    "R_gt": T_gt[:3, :3], "t_gt": T_gt[:3, 3] / np.linalg.norm(T_gt[:3, 3]),
                    "R_est": T_est[:3, :3], "t_est": T_est[:3, 3] / np.linalg.norm(T_est[:3, 3]),
                    "step_m": float(np.linalg.norm(T_gt[:3, 3]))})
    return out


def _fit(residuals, n_params: int) -> np.ndarray:
    return least_squares(residuals, np.zeros(n_params), loss="huber", f_scale=1.0, x_scale=1e-3).x


def refit_rotation(p: dict, focal: float) -> np.ndarray:
    """GT rotation re-fitted to the points with the GT translation direction kept (3 DOF)."""
    x = _fit(lambda x: sampson_px(so3_exp(x) @ p["R_gt"], p["t_gt"], p["a"], p["b"], focal), 3)
    return so3_exp(x) @ p["R_gt"]


def refit_direction(p: dict, focal: float) -> np.ndarray:
    """GT translation direction re-fitted with the GT rotation kept (2 DOF)."""
    basis = np.linalg.svd(p["t_gt"].reshape(1, 3))[2][1:]
    x = _fit(lambda x: sampson_px(p["R_gt"], p["t_gt"] + basis.T @ x, p["a"], p["b"], focal), 2)
    t = p["t_gt"] + basis.T @ x
    return t / np.linalg.norm(t)


def fit_constant_rotation(pairs: list[dict], focal: float) -> np.ndarray:
    """One rotation ``R_gt_cam`` (pitch and yaw; roll is unobservable for forward motion with small rotations) for
    all pairs: the camera's relative pose is then ``R_gt_cam^T T_gt R_gt_cam``."""
    def residuals(x):
        Rc = so3_exp(np.array([x[0], x[1], 0.0]))
        return np.concatenate([sampson_px(Rc.T @ p["R_gt"] @ Rc, Rc.T @ p["t_gt"], p["a"], p["b"], focal)
                               for p in pairs])
    x = _fit(residuals, 2)
    return so3_exp(np.array([x[0], x[1], 0.0]))


def fit_intrinsics(pairs: list[dict], K: np.ndarray, points_px: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
    """Intrinsics (fx = fy, cx, cy) that make the GT relative poses fit the pixel tracks best."""
    def K_of(x):
        Kx = K.copy()
        Kx[0, 0] = Kx[1, 1] = K[0, 0] * (1 + x[0])
        Kx[0, 2] += 100 * x[1]
        Kx[1, 2] += 100 * x[2]
        return Kx

    def residuals(x):
        Kx = K_of(x)
        return np.concatenate([sampson_px(p["R_gt"], p["t_gt"], normalize_points(pr, Kx), normalize_points(pc, Kx),
                                          Kx[0, 0]) for p, (pr, pc) in zip(pairs, points_px, strict=True)])
    return K_of(_fit(residuals, 3))


def chain(pairs: list[dict], T0: np.ndarray, rotations: list[np.ndarray], directions: list[np.ndarray],
          n: int) -> np.ndarray:
    """Positions (n, 3) chained from relative rotations/directions with the GT step lengths."""
    poses = np.zeros((n, 4, 4))
    poses[0] = T0
    for p, R, t in zip(pairs, rotations, directions, strict=True):
        T_cur_ref = np.eye(4)
        T_cur_ref[:3, :3], T_cur_ref[:3, 3] = R, t * p["step_m"]
        poses[p["cur"]] = poses[p["ref"]] @ se3_inverse(T_cur_ref)
    return poses[:, :3, 3]


def final_error_from(images, K, gt, start: int, preset_name: str, R_gt_cam: np.ndarray | None = None) -> float:
    """Unaligned final-frame error (m) of a gt-scale run on frames ``start..`` starting at the GT pose of
    ``start`` (its orientation corrected by ``R_gt_cam`` when given: camera = GT frame rotated by it)."""
    sub = gt[start:]
    if R_gt_cam is not None:
        T = np.eye(4)
        T[:3, :3] = R_gt_cam
        sub = sub.transformed(np.eye(4), T)
    result = MonoVO(preset(preset_name, **{"scale.mode": "gt"}), K, sub).run(images[start:])
    return float(np.linalg.norm(result.trajectory.positions_xyz[-1] - sub.positions_xyz[-1]))


def synthetic_bias(seeds=(1, 2, 3), n_frames: int = 8) -> dict:
    """Control: signed errors of the lidarkit pipeline on noise-free renders with KITTI 06 intrinsics."""
    from lidarkit.sim.camera import forward_trajectory, make_plane_scene, render_sequence
    K = np.array([[707.0912, 0, 601.8873], [0, 707.0912, 183.1104], [0, 0, 1.0]])
    scene = make_plane_scene(np.random.default_rng(7))
    errs = []
    for seed in seeds:
        traj = forward_trajectory(n_frames, step_m=0.5, rng=np.random.default_rng(seed))
        images = render_sequence(scene, traj, K, (1226, 370))
        est = MonoVO(preset("lidarkit", **{"scale.mode": "gt"}), K, traj).run(images).trajectory.poses_se3
        for j in range(1, n_frames):
            T_g = se3_inverse(traj.poses_se3[j]) @ traj.poses_se3[j - 1]
            T_e = se3_inverse(est[j]) @ est[j - 1]
            dR = np.degrees(so3_log(T_e[:3, :3] @ T_g[:3, :3].T))
            h_e = motion_direction_deg(T_e[:3, :3], T_e[:3, 3])
            h_g = motion_direction_deg(T_g[:3, :3], T_g[:3, 3])
            errs.append([dR[1], dR[0], h_e[0] - h_g[0], h_e[1] - h_g[1]])
    e = np.array(errs)
    return {"pairs": len(e), "mean_deg": e.mean(0).tolist(), "sem_deg": (e.std(0) / np.sqrt(len(e))).tolist(),
            "columns": ["yaw", "pitch", "heading", "elevation"]}


def analyse(data: Path, seq: str, preset_name: str = "lidarkit") -> dict:
    ds = KittiOdometry(data / seq).as_image_sequence()
    images, K, gt = images_in_memory(ds), ds.K, ds.ground_truth
    result = MonoVO(preset(preset_name, **{"scale.mode": "gt"}), K, gt).run(images, keep_tracks=True)
    focal = float(K[0, 0])
    pairs = pairs_of(result, gt.poses_se3, K)
    rows = []
    for p in pairs:
        a, b = p["a"], p["b"]
        even, odd = slice(0, None, 2), slice(1, None, 2)
        R_half, t_half = refine_pose(p["R_est"], p["t_est"], a[even], b[even], focal)
        R_rot = refit_rotation(p, focal)
        t_dir = refit_direction(p, focal)
        dR = np.degrees(so3_log(p["R_est"] @ p["R_gt"].T))
        head_e, elev_e = motion_direction_deg(p["R_est"], p["t_est"])
        head_g, elev_g = motion_direction_deg(p["R_gt"], p["t_gt"])
        rows.append({
            "frame": p["cur"], "n": len(a),
            "sampson_gt_px": float(np.median(sampson_px(p["R_gt"], p["t_gt"], a, b, focal))),
            "sampson_est_px": float(np.median(sampson_px(p["R_est"], p["t_est"], a, b, focal))),
            "sampson_gt_odd_px": float(np.median(sampson_px(p["R_gt"], p["t_gt"], a[odd], b[odd], focal))),
            "sampson_est_heldout_px": float(np.median(sampson_px(R_half, t_half, a[odd], b[odd], focal))),
            "sampson_gt_rot_refit_px": float(np.median(sampson_px(R_rot, p["t_gt"], a, b, focal))),
            "sampson_gt_dir_refit_px": float(np.median(sampson_px(p["R_gt"], t_dir, a, b, focal))),
            "drot_x_pitch_deg": float(dR[0]), "drot_y_yaw_deg": float(dR[1]), "drot_z_roll_deg": float(dR[2]),
            "rot_angle_gt_deg": float(np.degrees(np.linalg.norm(so3_log(p["R_gt"])))),
            "dheading_deg": head_e - head_g, "delevation_deg": elev_e - elev_g,
        })
    n = len(gt)
    final = {
        "estimate": float(np.linalg.norm(result.trajectory.positions_xyz[-1] - gt.positions_xyz[-1])),
        "gt_rotations_est_directions": float(np.linalg.norm(
            chain(pairs, gt.poses_se3[0], [p["R_gt"] for p in pairs], [p["t_est"] for p in pairs], n)[-1]
            - gt.positions_xyz[-1])),
        "est_rotations_gt_directions": float(np.linalg.norm(
            chain(pairs, gt.poses_se3[0], [p["R_est"] for p in pairs], [p["t_gt"] for p in pairs], n)[-1]
            - gt.positions_xyz[-1])),
    }
    yaw_cum = np.cumsum([r["drot_y_yaw_deg"] for r in rows])
    w_gt, w_change = rotation_increments_deg(gt)
    fill_end = constant_rate_prefix(gt)
    measured = [p for p in pairs if p["ref"] >= fill_end]
    Rc_late = fit_constant_rotation(measured, focal)
    const_late = [float(np.median(sampson_px(Rc_late.T @ p["R_gt"] @ Rc_late, Rc_late.T @ p["t_gt"], p["a"], p["b"],
                                             focal))) for p in measured]
    start = fill_end
    final["from_frame"] = start
    final["estimate_from_frame"] = final_error_from(images, K, gt, start, preset_name)
    final["estimate_from_frame_gt_rotated"] = final_error_from(images, K, gt, start, preset_name, Rc_late)
    Rc = fit_constant_rotation(pairs, focal)
    const = [float(np.median(sampson_px(Rc.T @ p["R_gt"] @ Rc, Rc.T @ p["t_gt"], p["a"], p["b"], focal)))
             for p in pairs]
    tracks_px = [(pr, pc) for _, pr, pc in result.tracks]
    K_fit = fit_intrinsics(pairs, K, tracks_px)
    kfit = [float(np.median(sampson_px(p["R_gt"], p["t_gt"], normalize_points(pr, K_fit),
                                       normalize_points(pc, K_fit), K_fit[0, 0])))
            for p, (pr, pc) in zip(pairs, tracks_px, strict=True)]
    return {"sequence": seq, "preset": preset_name, "rows": rows, "final_error_m": final,
            "cumulative_yaw_diff_deg": yaw_cum.tolist(),
            "gt_rotation_increment_deg": w_gt.tolist(), "gt_rotation_increment_change_deg": w_change.tolist(),
            "gt_constant_rate_until_frame": fill_end,
            "constant_rotation_measured_part": {"rotvec_deg": np.degrees(so3_log(Rc_late)).tolist(),
                                                "sampson_median_px": const_late,
                                                "gt_sampson_median_px": [float(np.median(sampson_px(
                                                    p["R_gt"], p["t_gt"], p["a"], p["b"], focal))) for p in measured],
                                                "est_sampson_median_px": [float(np.median(sampson_px(
                                                    p["R_est"], p["t_est"], p["a"], p["b"], focal))) for p in measured]},
            "constant_rotation": {"rotvec_deg": np.degrees(so3_log(Rc)).tolist(), "sampson_median_px": const},
            "intrinsics_fit": {"fx": float(K_fit[0, 0]), "cx": float(K_fit[0, 2]), "cy": float(K_fit[1, 2]),
                               "sampson_median_px": kfit}}


def _med(rows, key, sel=slice(None)):
    return float(np.median([r[key] for r in rows[sel]]))


def summary_table(res: dict) -> list[str]:
    rows = res["rows"]
    early, late = slice(0, 10), slice(10, None)
    keys = [("estimate as run (fitted to these points; report 1 pipeline: RANSAC pose, no refinement)", "sampson_est_px"),
            ("estimate fitted on even points, scored on odd (held out)", "sampson_est_heldout_px"),
            ("ground truth (odd points)", "sampson_gt_odd_px"),
            ("ground truth", "sampson_gt_px"),
            ("GT translation direction + re-fitted rotation (3 DOF)", "sampson_gt_rot_refit_px"),
            ("GT rotation + re-fitted translation direction (2 DOF)", "sampson_gt_dir_refit_px")]
    lines = ["| relative pose | median Sampson px, all pairs | pairs 1-10 | pairs 11-50 |", "|---|---|---|---|"]
    for label, key in keys:
        lines.append(f"| {label} | {_med(rows, key):.3f} | {_med(rows, key, early):.3f} | {_med(rows, key, late):.3f} |")
    c, k = res["constant_rotation"], res["intrinsics_fit"]
    lines.append(f"| GT through one constant pitch/yaw rotation (fitted rotation vector: {', '.join(f'{v:+.3f}' for v in c['rotvec_deg'])} deg) "
                 f"| {np.median(c['sampson_median_px']):.3f} | {np.median(c['sampson_median_px'][:10]):.3f} "
                 f"| {np.median(c['sampson_median_px'][10:]):.3f} |")
    lines.append(f"| GT with fitted intrinsics (fx {k['fx']:.1f}, cx {k['cx']:.1f}, cy {k['cy']:.1f}) "
                 f"| {np.median(k['sampson_median_px']):.3f} | {np.median(k['sampson_median_px'][:10]):.3f} "
                 f"| {np.median(k['sampson_median_px'][10:]):.3f} |")
    return lines


def per_frame_table(res: dict) -> list[str]:
    lines = ["| frame | inliers | Sampson GT px | Sampson est. held-out px | ratio | GT rot. refit px | dyaw deg | "
             "dpitch deg | droll deg | cum. dyaw deg | dheading deg | delev. deg |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r, cum in zip(res["rows"], res["cumulative_yaw_diff_deg"], strict=True):
        lines.append(f"| {r['frame']} | {r['n']} | {r['sampson_gt_odd_px']:.3f} | {r['sampson_est_heldout_px']:.3f} | "
                     f"{r['sampson_gt_odd_px'] / r['sampson_est_heldout_px']:.1f} | {r['sampson_gt_rot_refit_px']:.3f} | "
                     f"{r['drot_y_yaw_deg']:+.4f} | {r['drot_x_pitch_deg']:+.4f} | {r['drot_z_roll_deg']:+.4f} | "
                     f"{cum:+.3f} | {r['dheading_deg']:+.3f} | {r['delevation_deg']:+.3f} |")
    return lines


def constant_runs(traj: Trajectory, tol_deg: float = 1e-3, min_len: int = 3) -> dict:
    """Runs of >= ``min_len`` identical rotation increments (changes < ``tol_deg``) as (first, last) frames."""
    _, change = rotation_increments_deg(traj)
    small = np.concatenate([[False], change < tol_deg, [False]]).astype(int)
    edges = np.flatnonzero(np.diff(small))
    runs = [(int(a), int(b) + 1) for a, b in zip(edges[0::2], edges[1::2], strict=True) if b - a >= min_len]
    return {"poses": len(traj), "runs": runs}


def conclusion(results: dict) -> list[str]:
    """The diagnosis in a few sentences, with this run's numbers (sequence 06, lidarkit pipeline)."""
    r = results["06"]
    rows, fill = r["rows"], r["gt_constant_rate_until_frame"]
    in_fill = [x for x in rows if x["frame"] <= fill]
    after = [x for x in rows if x["frame"] > fill]
    c, f = r["constant_rotation_measured_part"], r["final_error_m"]
    yaw_fill = sum(x["drot_y_yaw_deg"] for x in in_fill)
    changes = r["gt_rotation_increment_change_deg"]
    yaw_img = [r["gt_rotation_increment_deg"][x["frame"] - 1][1] + x["drot_y_yaw_deg"] for x in in_fill]
    runs = results.get("full_gt_constant_runs")
    full = "" if runs is None else (f" (in all {runs['poses']} poses of the official 06 GT, runs of >= 3 identical "
                                    f"increments: frames {', '.join(f'{a}-{b}' for a, b in runs['runs'])})")
    return [
        "## Diagnosis", "",
        f"**The bias is in the ground truth, not in the pipeline.** (1) The GT's rotation increments of frames "
        f"0-{fill} are identical (they change by <= {max(changes[:fill - 1]):.4f} deg from frame to frame, afterwards "
        f"by {np.median(changes[fill:]):.3f} deg median): a constant-rate fill at the start of the recording{full}. "
        f"On these {len(in_fill)} pairs the GT explains the inlier tracks "
        f"{np.median([x['sampson_gt_odd_px'] for x in in_fill]):.2f} px (median Sampson) against "
        f"{np.median([x['sampson_est_heldout_px'] for x in in_fill]):.3f} px for a pose fitted on the other half of "
        f"the points; re-fitting only the GT's rotation (its translation direction kept) brings it to "
        f"{np.median([x['sampson_gt_rot_refit_px'] for x in in_fill]):.2f} px, so the GT rotation is what contradicts "
        f"the images. The images show the yaw rate going from {min(yaw_img):+.3f} to {max(yaw_img):+.3f} deg/frame where "
        f"the GT holds it at {r['gt_rotation_increment_deg'][0][1]:+.3f}; "
        f"the yaw difference summed over these pairs is {yaw_fill:+.2f} deg of the {sum(x['drot_y_yaw_deg'] for x in rows):+.2f} "
        f"deg over all 50. (2) After frame {fill} the GT still explains the tracks "
        f"{np.median([x['sampson_gt_odd_px'] for x in after]) / np.median([x['sampson_est_heldout_px'] for x in after]):.1f}x "
        f"worse than the estimate, and the estimated motion direction sits consistently "
        f"{np.median([x['dheading_deg'] for x in after]):+.2f} deg (heading) / "
        f"{np.median([x['delevation_deg'] for x in after]):+.2f} deg (elevation) from the GT's: one constant rotation "
        f"between the camera and the GT frame (pitch {c['rotvec_deg'][0]:+.2f}, yaw {c['rotvec_deg'][1]:+.2f} deg, "
        f"fitted to the tracks of these pairs) lowers the GT's residual from {np.median(c['gt_sampson_median_px']):.3f} "
        f"to {np.median(c['sampson_median_px']):.3f} px (estimate {np.median(c['est_sampson_median_px']):.3f}); the "
        f"rest is per-frame GT rotation noise. Neither one constant rotation nor corrected intrinsics reconcile the "
        f"first {fill} frames. (3) The pipeline itself is unbiased on noise-free renders with the same intrinsics "
        f"at the 0.05 deg level (control below). (4) Consequence: a gt-scale run started at frame {fill} ends {f['estimate_from_frame']:.3f} m "
        f"from the GT (within the 0.25 m target), and {f['estimate_from_frame_gt_rotated']:.3f} m when its start "
        f"orientation is corrected by the fitted constant rotation; from frame 0 it ends {f['estimate']:.2f} m away, most "
        f"of it from the constant-rate segment. The 0.25 m unaligned final error on frames 0-50 can only be met by "
        f"a pipeline that reproduces the GT's rotation error; lidarkit keeps following the images.", ""]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "vo")
    args = parser.parse_args()
    results = {seq: analyse(args.data, seq) for seq in ("06", "01")}
    results["06_sift"] = analyse(args.data, "06", "report_sift")
    results["synthetic_control"] = synthetic_bias()
    full_gt = args.data.parent / "poses" / "06.txt"
    if full_gt.exists():
        results["full_gt_constant_runs"] = constant_runs(Trajectory.from_kitti(full_gt))
    args.out.mkdir(parents=True, exist_ok=True)
    atomic.write_text(args.out / "heading_bias.json", json.dumps(results, indent=1))
    md = ["# Heading bias of monocular VO on KITTI 06: estimate vs ground truth", "",
          "Command: `python benchmarks/vo_heading_bias.py`  ",
          f"Date: {dt.datetime.now(dt.timezone.utc):%Y-%m-%d %H:%M} UTC", "",
          "Per frame pair of the lidarkit pipeline (gt scale): median Sampson error (px, normalized coordinates x fx) "
          "of the same inlier correspondences under different relative poses; rotation difference est vs GT "
          "(rotation vector of R_est R_gt^T in the current camera frame: x = pitch, y = yaw (y down, + = towards "
          "the right), z = roll) and motion-direction difference (heading + = right, elevation + = up).", ""]
    md += conclusion(results)
    syn = results["synthetic_control"]
    md += ["## Control: the pipeline on noise-free renders with KITTI 06 intrinsics (1226x370, fx 707)", "",
           f"{syn['pairs']} frame pairs of `lidarkit.sim.camera` forward motion (3 seeds); mean signed error "
           "(deg, +- standard error): " + ", ".join(f"{c} {m:+.4f} +- {e:.4f}" for c, m, e in
                                                  zip(syn["columns"], syn["mean_deg"], syn["sem_deg"], strict=True)),
           ""]
    for key, res in results.items():
        if key in ("synthetic_control", "full_gt_constant_runs"):
            continue
        f = res["final_error_m"]
        md += [f"## Sequence {res['sequence']} ({res['preset']} pipeline)", ""] + summary_table(res) + [
            "", f"Final-frame error (gt scale, unaligned): estimate {f['estimate']:.3f} m; GT rotations + estimated "
            f"directions {f['gt_rotations_est_directions']:.3f} m; estimated rotations + GT directions "
            f"{f['est_rotations_gt_directions']:.3f} m. Cumulative yaw difference after 10 / 50 pairs: "
            f"{res['cumulative_yaw_diff_deg'][9]:+.3f} / {res['cumulative_yaw_diff_deg'][-1]:+.3f} deg.", "",
            f"GT rotation increments identical (change < 0.001 deg) up to frame {res['gt_constant_rate_until_frame']}"
            f"; change per frame of the first 15: "
            + ", ".join(f"{v:.4f}" for v in res["gt_rotation_increment_change_deg"][:15]) + " deg.", ""]
        c = res["constant_rotation_measured_part"]
        md += [f"Pairs after the constant-rate segment (reference frame >= {res['gt_constant_rate_until_frame']}, "
               f"{len(c['sampson_median_px'])} pairs): median Sampson px: estimate "
               f"{np.median(c['est_sampson_median_px']):.3f}, GT {np.median(c['gt_sampson_median_px']):.3f}, GT seen "
               f"through one fitted constant rotation ({', '.join(f'{v:+.3f}' for v in c['rotvec_deg'])} deg, "
               f"rotation vector x/y/z) {np.median(c['sampson_median_px']):.3f}. Final-frame error of a gt-scale run "
               f"started at frame {f['from_frame']} (GT pose): {f['estimate_from_frame']:.3f} m; with that start "
               f"orientation corrected by the fitted rotation: {f['estimate_from_frame_gt_rotated']:.3f} m.", ""]
        if key == "06":
            md += ["### Per frame pair (sequence 06)", ""] + per_frame_table(res) + [""]
    atomic.write_text(args.out / "heading_bias.md", "\n".join(md) + "\n")
    print("\n".join(md))


if __name__ == "__main__":
    from lidarkit.cli import run_script

    run_script(main)
