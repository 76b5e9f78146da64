"""Scores of an odometry run against its ground truth (APE, RPE, final error, KITTI drift) and its timing."""

from __future__ import annotations

from typing import Any

import numpy as np

from lidarkit.geometry import pose_error
from lidarkit.odometry.result import OdometryResult
from lidarkit.trajectory import Trajectory


def odometry_metrics(result: OdometryResult) -> dict[str, Any]:
    """Timing summary always; APE / RPE / final pose error against ground truth when there is one, and the
    KITTI drift when the path is long enough for at least one devkit segment (100 m)."""
    stats = result.stats
    out: dict[str, Any] = {
        "method": result.method,
        "n_frames": int(len(result.frames)),
        "fps": result.fps,
        "total_time_s": result.total_time_s,
        "register_time_s": {"mean": float(stats.register_s.mean()), "median": float(np.median(stats.register_s)), "max": float(stats.register_s.max())},
        "read_time_s_mean": float(stats.read_s.mean()),
        "convergence_measured": result.convergence_measured,
        "n_not_converged": result.n_not_converged if result.convergence_measured else None,
        "n_constant_velocity_fallback": result.n_fallback,
        "n_degenerate": int(stats.degenerate.sum()) if result.convergence_measured else None,
        "estimated_length_m": result.trajectory.length_m,
    }
    if result.covariances is not None:
        from lidarkit.odometry.covariance import covariance_metrics

        truth = None if result.ground_truth is None or len(result.ground_truth) != len(result.trajectory) else result.ground_truth.poses_se3
        out["pose_covariance"] = covariance_metrics(result.trajectory.poses_se3, *result.covariances, truth)
    ref = result.ground_truth
    if ref is None:
        return out
    ref, est = paired(ref, result.trajectory)
    from lidarkit import eval as leval

    trans_m, rot_deg = pose_error(est.poses_se3[-1], ref.poses_se3[-1])
    out["ground_truth"] = ref.name
    out["ground_truth_length_m"] = ref.length_m
    out["final_error"] = {"translation_m": float(trans_m), "rotation_deg": float(rot_deg)}
    if len(ref) >= 2:
        out["ape_translation_m"] = leval.ape(ref, est, align="none", relation="translation").to_dict(include_errors=False)
        out["rpe_translation_m"] = leval.rpe(ref, est, delta=1, delta_unit="frames", relation="translation").to_dict(include_errors=False)
        out["rpe_rotation_deg"] = leval.rpe(ref, est, delta=1, delta_unit="frames", relation="rotation_angle_deg").to_dict(include_errors=False)
    if leval.drift_segments_possible(ref):
        out["kitti_drift"] = leval.kitti_drift(ref, est).to_dict()
    else:
        out["kitti_drift"] = None
        out["kitti_drift_note"] = f"path {ref.length_m:.1f} m is shorter than the shortest devkit segment (100 m)"
    return out


def paired(ref: Trajectory, est: Trajectory) -> tuple[Trajectory, Trajectory]:
    """Frame-aligned by construction: give both the same stamps so the metrics pair them one to one."""
    if ref.timestamps_s is None and est.timestamps_s is None:
        return ref, est
    stamps = ref.timestamps_s if ref.timestamps_s is not None else est.timestamps_s
    return ref.with_timestamps(stamps), est.with_timestamps(stamps)
