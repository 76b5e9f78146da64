"""Scores of an odometry run against its ground truth (APE, RPE, final error, KITTI drift) and its timing."""

from __future__ import annotations

from typing import Any

import numpy as np

from lidarkit.errors import EvaluationError
from lidarkit.geometry import pose_error
from lidarkit.odometry.result import OdometryResult
from lidarkit.odometry.settings import METRIC_ALIGNMENT, metric_alignment
from lidarkit.trajectory import Trajectory


def _register_times(register_s: np.ndarray, *, stateful: bool) -> dict[str, float | None]:
    """Mean / median / max registration time (s) of the frames registered: a scan-to-scan chain's frame 0 has no
    registration (its 0 s pulled the mean 10 % low over 10 frames); None without any."""
    times = register_s if stateful else register_s[1:]
    if not len(times):
        return {"mean": None, "median": None, "max": None}
    return {"mean": float(times.mean()), "median": float(np.median(times)), "max": float(times.max())}


def odometry_metrics(result: OdometryResult) -> dict[str, Any]:
    """Timing summary, the independent per-frame check and what was really applied, always; APE (unaligned and
    SE(3)-aligned) / RPE / final pose error against ground truth when there is one, and the KITTI drift when the
    path is long enough for at least one devkit segment (100 m). Every score names its alignment (``alignment``)."""
    stats = result.stats
    run = result.config.get("run", {})
    out: dict[str, Any] = {
        "method": result.method,
        "n_frames": int(len(result.frames)),
        "fps": result.fps,
        "total_time_s": result.total_time_s,
        "register_time_s": _register_times(stats.register_s, stateful=bool(run.get("stateful", True))),
        "read_time_s_mean": float(stats.read_s.mean()),
        "convergence_measured": result.convergence_measured,
        "n_not_converged": result.n_not_converged if result.convergence_measured else None,
        "n_constant_velocity_fallback": result.n_fallback,
        # (with init="odometry" a refused frame takes the dataset's odometry motion, not constant velocity)
        "fallback_motion": run.get("fallback_motion", "constant velocity"),
        # (None, not 0, where the variant gives no verdict: a stateful one, or a run with assess=False)
        "n_degenerate": int(stats.degenerate.sum()) if result.degeneracy_assessed else None,
        "n_ground_removal_flagged": sum("too little left after ground removal" in r for r in stats.reason),
        "estimated_length_m": result.trajectory.length_m,
        "n_bad_frames": result.n_bad_frames if stats.check_failed is not None else None,
        "frame_check": frame_check_summary(result),
        "effective": run.get("effective"),
        "warnings": list(run.get("warnings") or []),
    }
    if result.covariances is not None:
        from lidarkit.odometry.covariance import covariance_metrics

        truth = None if result.ground_truth is None or len(result.ground_truth) != len(result.trajectory) else result.ground_truth.poses_se3
        out["pose_covariance"] = covariance_metrics(result.trajectory.poses_se3, *result.covariances, truth)
        if run.get("covariance_distortion_floor"):
            out["pose_covariance"]["distortion_floor"] = run["covariance_distortion_floor"]
    ref = result.ground_truth
    if ref is None:
        if run.get("ground_truth_note"):
            out["ground_truth_note"] = run["ground_truth_note"]
        return out
    ref, est = paired(ref, result.trajectory)
    from lidarkit import eval as leval

    trans_m, rot_deg = pose_error(est.poses_se3[-1], ref.poses_se3[-1])
    out["ground_truth"] = ref.name
    out["ground_truth_length_m"] = ref.length_m
    out["final_error"] = {"translation_m": float(trans_m), "rotation_deg": float(rot_deg), "alignment": METRIC_ALIGNMENT["final_error"]}
    if len(ref) >= 2:
        out["ape_translation_m"] = leval.ape(ref, est, align="none", relation="translation").to_dict(include_errors=False)
        if len(ref) >= 3:  # a rigid fit needs three poses, not all on one line
            try:
                out["ape_translation_se3_m"] = leval.ape(ref, est, align="se3", relation="translation").to_dict(include_errors=False)
            except EvaluationError as err:
                out["ape_translation_se3_note"] = f"no SE(3)-aligned APE: {err.reason}"
        else:  # (the CLI's row read "-" without a reason)
            out["ape_translation_se3_note"] = f"no SE(3)-aligned APE: a rigid fit needs 3 poses, the run has {len(ref)}"
        out["rpe_translation_m"] = leval.rpe(ref, est, delta=1, delta_unit="frames", relation="translation").to_dict(include_errors=False)
        out["rpe_rotation_deg"] = leval.rpe(ref, est, delta=1, delta_unit="frames", relation="rotation_angle_deg").to_dict(include_errors=False)
        alignment = metric_alignment(result.stats.frame)
        for key in ("ape_translation_m", "ape_translation_se3_m", "rpe_translation_m", "rpe_rotation_deg"):
            if key in out:
                out[key]["alignment"] = alignment[key]
    if leval.drift_segments_possible(ref):
        out["kitti_drift"] = leval.kitti_drift(ref, est).to_dict()
        out["kitti_drift"]["alignment"] = METRIC_ALIGNMENT["kitti_drift"]
    else:
        out["kitti_drift"] = None
        out["kitti_drift_note"] = f"path {ref.length_m:.1f} m is shorter than the shortest devkit segment (100 m)"
    return out


#: bad frames listed by index in metrics.json (all of them are in timing.csv)
MAX_BAD_FRAMES_LISTED = 100


def frame_check_summary(result: OdometryResult) -> dict[str, Any] | None:
    """Counts of the independent per-frame check: bad frames (and why), how many the variant called converged."""
    stats = result.stats
    if stats.check_failed is None:
        return None
    failed = stats.check_failed
    by_motion = np.array(["motion" in w for w in stats.check_why], dtype=bool) if stats.check_why else np.zeros_like(failed)
    by_fitness = np.array(["fitness" in w for w in stats.check_why], dtype=bool) if stats.check_why else np.zeros_like(failed)
    verdict = result.convergence_measured
    converged_but_bad = int((failed & stats.measured & stats.converged).sum()) if verdict else None
    return {
        "n_bad_frames": int(failed.sum()),
        "n_bad_motion": int(by_motion.sum()),
        "n_bad_fitness": int(by_fitness.sum()),
        "n_motion_checked": int(np.isfinite(stats.motion_dev_m).sum()),
        "n_fitness_checked": int(np.isfinite(stats.fitness).sum()),
        "n_said_converged_but_bad": converged_but_bad,
        "variant_verdict": "per-frame converged flag" if verdict else "none (stateful variant: no per-frame verdict)",
        "bad_frames": [int(f) for f in stats.frame[failed][:MAX_BAD_FRAMES_LISTED]],
        # (the list was cut at 100 without a word)
        "n_bad_frames_not_listed": max(int(failed.sum()) - MAX_BAD_FRAMES_LISTED, 0),
        "fitness_median": float(np.nanmedian(stats.fitness)) if np.isfinite(stats.fitness).any() else None,
        "check_time_s_mean": float(stats.check_s.mean()) if stats.check_s is not None and len(stats.check_s) else None,
        "thresholds": result.config.get("run", {}).get("frame_check"),
    }


def paired(ref: Trajectory, est: Trajectory) -> tuple[Trajectory, Trajectory]:
    """Frame-aligned by construction: give both the same stamps so the metrics pair them one to one."""
    if ref.timestamps_s is None and est.timestamps_s is None:
        return ref, est
    stamps = ref.timestamps_s if ref.timestamps_s is not None else est.timestamps_s
    return ref.with_timestamps(stamps), est.with_timestamps(stamps)
