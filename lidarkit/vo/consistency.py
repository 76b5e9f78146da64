"""Does a ground-truth trajectory explain the image correspondences? Epipolar checks of VO against ground truth.

A VO estimate that disagrees with the ground truth may be wrong, or the ground truth may be. The images decide:
for every frame pair, the inlier correspondences of the VO run are scored (Sampson error, px) under the ground
truth's relative pose and under a pose fitted to half of the points and scored on the other half (held out, so the
estimate gets no advantage from having been fitted to them). A ground truth that is right explains the points about
as well as the held-out estimate; a much larger ground-truth residual means its relative pose contradicts the images.

Conventions as in :mod:`lidarkit.vo.two_view`: ``X_cur = R_cur_ref X_ref + t_cur_ref``; camera frame x right,
y down, z forward.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lidarkit.errors import ConfigError, DataError
from lidarkit.geometry import se3_inverse, skew, so3_log
from lidarkit.trajectory import Trajectory
from lidarkit.vo.pipeline import VOResult
from lidarkit.vo.two_view import normalize_points, refine_pose, sampson_residuals


@dataclass(frozen=True)
class PairConsistency:
    """One frame pair: median Sampson errors (px) of the same held-out inliers under the ground truth and the
    held-out estimate, and how the estimate differs from the ground truth (degrees).

    ``rotation_diff_deg``: rotation vector of ``R_est R_gt^T`` (x = pitch, y = yaw, z = roll, current camera frame);
    ``heading_diff_deg`` / ``elevation_diff_deg``: direction of motion (+ = right / up) of estimate minus GT.
    """

    frame: int
    ref_frame: int
    n_inliers: int
    sampson_gt_px: float
    sampson_est_px: float
    rotation_diff_deg: tuple[float, float, float]
    heading_diff_deg: float
    elevation_diff_deg: float

    @property
    def ratio(self) -> float:
        """Ground-truth residual over the estimate's (> 1: the GT explains the images worse)."""
        return self.sampson_gt_px / self.sampson_est_px if self.sampson_est_px > 0 else float("inf")


def sampson_px(R_cur_ref: np.ndarray, t_cur_ref: np.ndarray, norm_ref: np.ndarray, norm_cur: np.ndarray,
               focal_px: float) -> np.ndarray:
    """Absolute Sampson error ``(N,)`` in px of normalized correspondences ``(N, 2)`` under a relative pose."""
    t = np.asarray(t_cur_ref, float)
    return np.abs(sampson_residuals(skew(t / np.linalg.norm(t)) @ R_cur_ref, norm_ref, norm_cur)) * focal_px


def motion_direction_deg(R_cur_ref: np.ndarray, t_cur_ref: np.ndarray) -> tuple[float, float]:
    """Heading (+ = right) and elevation (+ = up) in degrees of the camera's motion, in the reference frame."""
    c = -R_cur_ref.T @ t_cur_ref
    return float(np.degrees(np.arctan2(c[0], c[2]))), float(np.degrees(np.arctan2(-c[1], np.hypot(c[0], c[2]))))


def ground_truth_consistency(result: VOResult, ground_truth: Trajectory) -> list[PairConsistency]:
    """Score every accepted frame pair of ``result`` (run with ``keep_tracks=True``) against ``ground_truth``
    (camera frame, one pose per frame). The estimate is re-fitted (Sampson refinement) on the even-indexed inliers
    and both poses are scored on the odd-indexed ones."""
    if result.tracks is None:
        raise ConfigError("the VO result has no tracks; run it with keep_tracks=True",
                          source="ground_truth_consistency")
    if len(ground_truth) != result.n_frames:
        raise DataError(f"ground truth has {len(ground_truth)} poses for {result.n_frames} frames",
                        source="ground_truth_consistency")
    K, focal = result.K, float(result.K[0, 0])
    gt, est = ground_truth.poses_se3, result.trajectory.poses_se3
    # by frame, not by position: unreadable frames before the start frame have rows of their own
    ref_frame = {d.frame: d.ref_frame for d in result.diagnostics if d.accepted}
    out = []
    for j, pts_ref, pts_cur in result.tracks:
        i = ref_frame[j]
        a, b = normalize_points(pts_ref, K), normalize_points(pts_cur, K)
        if len(a) < 16:
            continue
        T_gt = se3_inverse(gt[j]) @ gt[i]
        T_est = se3_inverse(est[j]) @ est[i]
        if np.linalg.norm(T_gt[:3, 3]) < 1e-9:  # no GT motion: no epipolar geometry to test
            continue
        R_fit, t_fit = refine_pose(T_est[:3, :3], T_est[:3, 3], a[0::2], b[0::2], focal)
        head_e, elev_e = motion_direction_deg(T_est[:3, :3], T_est[:3, 3])
        head_g, elev_g = motion_direction_deg(T_gt[:3, :3], T_gt[:3, 3])
        dR = np.degrees(so3_log(T_est[:3, :3] @ T_gt[:3, :3].T))
        out.append(PairConsistency(
            frame=j, ref_frame=i, n_inliers=len(a),
            sampson_gt_px=float(np.median(sampson_px(T_gt[:3, :3], T_gt[:3, 3], a[1::2], b[1::2], focal))),
            sampson_est_px=float(np.median(sampson_px(R_fit, t_fit, a[1::2], b[1::2], focal))),
            rotation_diff_deg=(float(dR[0]), float(dR[1]), float(dR[2])),
            heading_diff_deg=head_e - head_g, elevation_diff_deg=elev_e - elev_g))
    return out


def rotation_increments_deg(trajectory: Trajectory) -> tuple[np.ndarray, np.ndarray]:
    """Per-frame rotation vectors ``(N-1, 3)`` in degrees (current camera frame) and the change of each from the
    previous one ``(N-2,)`` in degrees; a run of ~0 changes means a constant-rate (interpolated) rotation."""
    P = trajectory.poses_se3
    w = np.array([np.degrees(so3_log((se3_inverse(P[k]) @ P[k - 1])[:3, :3])) for k in range(1, len(P))])
    return w, np.linalg.norm(np.diff(w, axis=0), axis=1)


def constant_rate_prefix(trajectory: Trajectory, tol_deg: float = 1e-3) -> int:
    """Last frame of the leading run of frames whose rotation increments agree within ``tol_deg`` (0 if the
    second increment already differs from the first)."""
    if len(trajectory) < 3:
        return 0
    _, change = rotation_increments_deg(trajectory)
    differs = np.flatnonzero(change >= tol_deg)
    run = int(differs[0]) if len(differs) else len(change)
    return run + 1 if run > 0 else 0


__all__ = ["PairConsistency", "constant_rate_prefix", "ground_truth_consistency", "motion_direction_deg",
           "rotation_increments_deg", "sampson_px"]
