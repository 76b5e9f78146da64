"""Pose covariance along an odometry run: per-frame registration covariances propagated to first order on SE(3).

Each frame's relative motion ``T_rel = T_target_source`` (previous scan <- current scan) comes with a 6x6
covariance under the registry's convention (left perturbation in the previous frame, translation first, m and
rad). With ``T_world_k = T_world_{k-1} @ T_rel`` and left perturbations in the world frame,
``Sigma_k = Sigma_{k-1} + Ad(T_world_{k-1}) Sigma_rel Ad(T_world_{k-1})^T`` (the first pose is exact: identity).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from lidarkit.geometry import se3_inverse, se3_log
from lidarkit.registration.covariance import COVARIANCE_CONVENTION, adjoint, make_psd, nees

#: chi-square(6) 95 % bound for the NEES of a 6-DOF pose
CHI2_6_95 = 12.5916

#: A pose's covariance alone, as pose_covariance.txt holds it (one row per pose, no per-frame covariances)
POSE_COVARIANCE_PER_POSE = (
    "left perturbation in the world frame, T_true = se3_exp(xi) @ T_world_lidar, xi = (tx, ty, tz, rx, ry, rz) in m and rad"
)
POSE_COVARIANCE_CONVENTION = "per pose: " + POSE_COVARIANCE_PER_POSE + "; per frame (relative): " + COVARIANCE_CONVENTION


#: What a frame's motion is known to without its registration (the constant-velocity or odometry guess it started
#: from): 1 m and 0.1 rad (1-sigma). Fused with each frame's covariance, it bounds the variance of a direction the
#: scans do not constrain (a corridor's axis) instead of letting one frame's near-infinite variance swamp the rest.
MOTION_PRIOR_SIGMA = (1.0, 0.1)


def with_motion_prior(covariance: np.ndarray, prior_sigma: tuple[float, float] = MOTION_PRIOR_SIGMA) -> np.ndarray:
    """``(Sigma^-1 + P^-1)^-1`` with ``P`` the diagonal motion prior: unchanged where the scans constrain the motion
    well, bounded by the prior where they do not."""
    from lidarkit.registration.covariance import safe_inverse

    prior_info = np.diag(np.repeat([prior_sigma[0] ** -2, prior_sigma[1] ** -2], 3))
    return make_psd(np.linalg.inv(safe_inverse(covariance) + prior_info))


def propagate(poses: np.ndarray, relative_covariances: np.ndarray) -> np.ndarray:
    """``(n, 6, 6)`` world-frame pose covariances from ``(n, 4, 4)`` poses and the ``(n, 6, 6)`` covariance of each
    frame's relative motion (row 0 unused). A frame without one (NaN: a fallback, or a variant that gives none)
    takes the previous frame's: the motion it reused is no better known; one before any frame has one takes the
    first that does (a fallback at frame 1 left every pose NaN). Each frame's covariance is first fused with the
    motion prior (:func:`with_motion_prior`). All NaN when no frame has one."""
    n = len(poses)
    out = np.zeros((n, 6, 6))
    given = [k for k in range(1, n) if np.all(np.isfinite(relative_covariances[k]))]
    last = with_motion_prior(relative_covariances[given[0]]) if given else None
    for k in range(1, n):  # a running sum over frames: each step needs the previous one
        rel = relative_covariances[k]
        if np.all(np.isfinite(rel)):
            last = with_motion_prior(rel)
        if last is None:
            out[k] = np.full((6, 6), np.nan)
            continue
        Ad = adjoint(poses[k - 1])
        out[k] = make_psd(out[k - 1] + Ad @ last @ Ad.T) if np.all(np.isfinite(out[k - 1])) else np.full((6, 6), np.nan)
    return out


def relative_errors(ref_poses: np.ndarray, est_poses: np.ndarray) -> np.ndarray:
    """``(n-1, 6)`` errors of the 1-frame relative motions, in the convention of the relative covariances:
    ``xi_k = se3_log(T_rel_true @ inv(T_rel_est))``."""
    out = np.zeros((len(est_poses) - 1, 6))
    for k in range(1, len(est_poses)):
        rel_true = se3_inverse(ref_poses[k - 1]) @ ref_poses[k]
        rel_est = se3_inverse(est_poses[k - 1]) @ est_poses[k]
        out[k - 1] = se3_log(rel_true @ se3_inverse(rel_est))
    return out


def covariance_metrics(poses: np.ndarray, relative_covariances: np.ndarray, pose_covariances: np.ndarray,
                       ref_poses: np.ndarray | None) -> dict[str, Any]:
    """How large the propagated uncertainty is, and with ground truth how well it covers the errors: NEES of the
    1-frame relative motions (6 when calibrated), and how much of the end-point error is a systematic drift (the
    mean relative error accumulated along the path) rather than noise the covariance describes."""
    final = pose_covariances[-1]
    out: dict[str, Any] = {
        "convention": POSE_COVARIANCE_CONVENTION,
        "frames_with_covariance": int(np.isfinite(relative_covariances[1:]).all(axis=(1, 2)).sum()),
        "final_position_sigma_m": float(np.sqrt(np.trace(final[:3, :3]))) if np.all(np.isfinite(final)) else None,
        "final_heading_sigma_deg": float(np.degrees(np.sqrt(final[5, 5]))) if np.all(np.isfinite(final)) else None,
    }
    if ref_poses is None or len(poses) < 2:
        return out
    errors = relative_errors(ref_poses, poses)
    ok = np.isfinite(relative_covariances[1:]).all(axis=(1, 2))
    values = np.array([nees(e, c) for e, c in zip(errors[ok], relative_covariances[1:][ok])])
    if len(values):
        out["relative_nees_mean"] = float(values.mean())
        out["relative_nees_median"] = float(np.median(values))
        out["relative_inside_95"] = float((values < CHI2_6_95).mean())
    # end point: the error against the propagated covariance, and the part a constant per-frame bias explains
    end_err = se3_log(ref_poses[-1] @ se3_inverse(poses[-1]))
    bias = errors.mean(axis=0)
    drift = np.zeros(6)
    for k in range(1, len(poses)):
        drift += adjoint(poses[k - 1]) @ bias
    out["end_error_m"] = float(np.linalg.norm(end_err[:3]))
    if np.all(np.isfinite(final)):
        out["end_nees"] = nees(end_err, final)
    out["end_error_from_bias_m"] = float(np.linalg.norm(drift[:3]))
    out["end_error_bias_share"] = float(min(np.linalg.norm(drift[:3]) / max(np.linalg.norm(end_err[:3]), 1e-12), 10.0))
    # the share above rebuilds the end error from the mean frame error: on a straight path it is ~1 whatever the
    # errors are (white noise too). Whether there is a bias at all: the mean translation error per frame against its
    # standard error, the largest |z| of the three axes (white noise: below 3 but for one run in ~100)
    n = len(errors)
    if n > 2:
        spread = errors[:, :3].std(axis=0, ddof=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            z = np.abs(bias[:3]) / (spread / np.sqrt(n))
        out["per_frame_bias_z"] = float(np.nanmax(np.where(spread > 0, z, 0.0)))
    return out


__all__ = ["CHI2_6_95", "MOTION_PRIOR_SIGMA", "POSE_COVARIANCE_CONVENTION", "POSE_COVARIANCE_PER_POSE", "with_motion_prior", "covariance_metrics", "propagate", "relative_errors"]
