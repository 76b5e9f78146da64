"""Pose covariance along an odometry run: per-frame registration covariances propagated to first order on SE(3).

Each frame's relative motion ``T_rel = T_target_source`` (previous scan <- current scan) comes with a 6x6
covariance under the registry's convention (left perturbation in the previous frame, translation first, m and
rad). With ``T_world_k = T_world_{k-1} @ T_rel`` and left perturbations in the world frame,
``Sigma_k = Sigma_{k-1} + Ad(T_world_{k-1}) Sigma_rel Ad(T_world_{k-1})^T`` (the first pose is exact: identity).
A pose's position has :func:`position_covariance`, not the twist's translation block.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from lidarkit.errors import DataError
from lidarkit.geometry import se3_inverse, se3_log
from lidarkit.odometry.frame_check import MAX_INTERVAL_RATIO
from lidarkit.registration.covariance import COVARIANCE_CONVENTION, adjoint, make_psd, nees

#: chi-square(6) 95 % bound for the NEES of a 6-DOF pose
CHI2_6_95 = 12.5916

#: A pose's covariance alone, as pose_covariance.txt holds it (one row per pose, no per-frame covariances)
POSE_COVARIANCE_PER_POSE = (
    "left perturbation in the world frame, T_true = se3_exp(xi) @ T_world_lidar, xi = (tx, ty, tz, rx, ry, rz) in m and rad"
)
POSE_COVARIANCE_CONVENTION = "per pose: " + POSE_COVARIANCE_PER_POSE + "; per frame (relative): " + COVARIANCE_CONVENTION


#: What a frame's motion is known to without its registration (the constant-velocity or odometry guess it started
#: from): 1 m and 0.1 rad (1-sigma) over one sweep. Fused with each frame's covariance, it bounds the variance of a
#: direction the scans do not constrain (a corridor's axis) instead of letting one frame's near-infinite variance swamp
#: the rest; a frame that fell back to the guess, or whose registration is not trusted (:func:`motion_prior_frames`),
#: has it alone.
MOTION_PRIOR_SIGMA = (1.0, 0.1)

#: 1-sigma (rad) of an angle wholly unknown (uniform over the circle): the most a rotation's prior can say
UNKNOWN_ROTATION_SIGMA = float(np.pi / np.sqrt(3.0))


def motion_prior_sigma(sweeps_apart: float = 1.0, prior_sigma: tuple[float, float] = MOTION_PRIOR_SIGMA) -> tuple[float, float]:
    """The motion prior of a frame ``sweeps_apart`` sweeps after the previous one: the guess repeats one motion over
    every sweep it spans, so it repeats its error too, and the sigma grows with the sweeps (not their square root)."""
    return prior_sigma[0] * sweeps_apart, min(prior_sigma[1] * sweeps_apart, UNKNOWN_ROTATION_SIGMA)


def with_motion_prior(covariance: np.ndarray, prior_sigma: tuple[float, float] = MOTION_PRIOR_SIGMA) -> np.ndarray:
    """``(Sigma^-1 + P^-1)^-1`` with ``P`` the diagonal motion prior: unchanged where the scans constrain the motion
    well, bounded by the prior where they do not."""
    from lidarkit.registration.covariance import safe_inverse

    prior_info = np.diag(np.repeat([prior_sigma[0] ** -2, prior_sigma[1] ** -2], 3))
    return make_psd(np.linalg.inv(safe_inverse(covariance) + prior_info))


#: A frame more than this many times the run's regular spacing of sweeps after the previous one is registered across a
#: gap, and its registration's covariance is not taken as a measure of its error: the frame check leaves its motion
#: untested (its interval differs from the previous one's by more than the check's MAX_INTERVAL_RATIO), so only the
#: fitness vouches for it, and the guess it started from may be off by the motion prior's metre per sweep over every
#: sweep of the gap, beyond the reach of the correspondences a registration pairs. A sweep or two dropped (ratio 2-3)
#: is still tested both ways and keeps its covariance.
GAP_SWEEPS_RATIO = MAX_INTERVAL_RATIO

#: Frames listed by index in ``metrics.json`` ``pose_covariance.motion_prior_only`` (all are counted)
MAX_PRIOR_FRAMES_LISTED = 100


def motion_prior_frames(fell_back: np.ndarray, failed_fitness: np.ndarray | None, sweeps_apart: np.ndarray) -> dict[str, np.ndarray]:
    """``(n,)`` bool masks, by reason, of the frames whose motion is known to the motion prior alone (never frame 0):
    ``"fell back"`` to the guess; ``"failed the fitness check"`` (the frame check's: its scan does not fit the previous
    one at the motion found), whose covariance, assessed at that wrong motion, is no measure of its error (kiss's
    one-sweep-sized ones at fitness 0.008 and 0.010 after KITTI's dropped scans put the end 1-sigma at 0.6 m for a 40 m
    end error); ``"across a gap"``, more than :data:`GAP_SWEEPS_RATIO` times the run's regular step of sweeps after the
    previous frame (the smallest ``sweeps_apart``: a stepped selection is no gap). A frame failing the check's motion
    test alone keeps its covariance: its scans fit, and kiss fails that test on 3 of 300 frames of a simulated street
    at fitness 0.97 (0.15-0.2 m off constant velocity), where the prior put the end 1-sigma at 69 m for a 2.2 m error."""
    n = len(fell_back)
    sweeps = _per_frame(sweeps_apart, n, "sweeps_apart").astype(np.float64)
    failed = np.zeros(n, dtype=bool) if failed_fitness is None else _per_frame(failed_fitness, n, "failed_fitness").astype(bool)
    across = sweeps > GAP_SWEEPS_RATIO * sweeps[1:].min() if n > 1 else np.zeros(n, dtype=bool)
    reasons = {"fell back": np.asarray(fell_back, dtype=bool).copy(), "failed the fitness check": failed.copy(), "across a gap": across}
    for flags in reasons.values():
        flags[:1] = False
    return reasons


def motion_prior_summary(frames: np.ndarray, reasons: dict[str, np.ndarray]) -> dict[str, Any]:
    """What ``metrics.json`` says of the frames :func:`motion_prior_frames` found: their count, the first
    :data:`MAX_PRIOR_FRAMES_LISTED` of their ``frames`` (dataset indices) and the count of each reason (a frame may have
    several)."""
    prior = np.logical_or.reduce(list(reasons.values()))
    listed = [int(f) for f in np.asarray(frames)[prior][:MAX_PRIOR_FRAMES_LISTED]]
    return {
        "n_frames": int(prior.sum()),
        "frames": listed,
        "n_frames_not_listed": int(prior.sum()) - len(listed),
        "by_reason": {why: int(flags.sum()) for why, flags in reasons.items()},
    }


def _per_frame(values: Any, n: int, name: str) -> np.ndarray:
    """``values`` as one entry per pose: a DataError naming ``name`` for another length."""
    out = np.asarray(values).reshape(-1)
    if len(out) != n:
        raise DataError(f"{len(out)} values for {n} poses", source=name)
    return out


def propagate(poses: np.ndarray, relative_covariances: np.ndarray, fell_back: np.ndarray | None = None,
              sweeps_apart: np.ndarray | None = None) -> np.ndarray:
    """``(n, 6, 6)`` world-frame pose covariances from ``(n, 4, 4)`` poses and the ``(n, 6, 6)`` covariance of each
    frame's relative motion (row 0 unused).

    A frame that fell back (``fell_back``, ``(n,)`` bool; None: every frame without a covariance, as in a scan-to-scan
    run, where only a fallback has none; the runner passes every frame of :func:`motion_prior_frames`) moved by the
    guess alone, or by a registration not trusted, so its motion is known to the motion prior and no better
    (:func:`motion_prior_sigma` over its ``sweeps_apart``, ``(n,)``, default 1): a neighbour's registration says
    nothing about it (reusing the previous frame's gave 1.1 m at the end of a run with 15 fallbacks in 24 frames, for a
    7.8 m error). Any other frame without one (a stateful variant's frame its assessment found no overlap for) takes
    the previous frame's, or the first that has one. Each frame's covariance is fused with the motion prior
    (:func:`with_motion_prior`). All NaN when no frame has one."""
    n = len(poses)
    out = np.zeros((n, 6, 6))
    given = np.isfinite(relative_covariances).all(axis=(1, 2))
    given[0] = False
    fell = ~given if fell_back is None else _per_frame(fell_back, n, "fell_back").astype(bool)
    sweeps = np.ones(n) if sweeps_apart is None else _per_frame(sweeps_apart, n, "sweeps_apart").astype(np.float64)
    if not np.all(np.isfinite(sweeps) & (sweeps > 0)):
        raise DataError("each frame's sweeps since the previous one must be a positive finite number", source="sweeps_apart")
    if not given.any():
        out[1:] = np.nan
        return out
    first = int(np.flatnonzero(given)[0])
    last = with_motion_prior(relative_covariances[first], motion_prior_sigma(sweeps[first]))
    for k in range(1, n):  # a running sum over frames: each step needs the previous one
        if fell[k]:
            rel = np.diag(np.repeat(np.square(motion_prior_sigma(sweeps[k])), 3))
        else:
            if given[k]:
                last = with_motion_prior(relative_covariances[k], motion_prior_sigma(sweeps[k]))
            rel = last
        Ad = adjoint(poses[k - 1])
        out[k] = make_psd(out[k - 1] + Ad @ rel @ Ad.T)
    return out


def position_covariance(pose: np.ndarray, covariance: np.ndarray) -> np.ndarray:
    """``(..., 3, 3)`` covariance of the position of ``(..., 4, 4)`` poses from their ``(..., 6, 6)`` world-frame left
    perturbation covariance: ``T_true = se3_exp(xi) @ T`` moves the position by ``rho + phi x p`` to first order, so the
    rotation's lever arm about the world origin counts and the twist's translation block alone is not the position's
    uncertainty (it said 0 m at the end of a straight line whose first heading alone was uncertain)."""
    pose, covariance = np.asarray(pose, dtype=np.float64), np.asarray(covariance, dtype=np.float64)
    if pose.shape[-2:] != (4, 4) or covariance.shape[-2:] != (6, 6) or pose.shape[:-2] != covariance.shape[:-2]:
        raise DataError(f"poses {pose.shape} and covariances {covariance.shape} are not (..., 4, 4) and (..., 6, 6) alike",
                        source="position_covariance")
    x, y, z = np.moveaxis(pose[..., :3, 3], -1, 0)
    jacobian = np.zeros(pose.shape[:-2] + (3, 6))
    jacobian[..., :3, :3] = np.eye(3)
    # -[p]x: d(phi x p) / d(phi)
    jacobian[..., 0, 4], jacobian[..., 0, 5] = z, -y
    jacobian[..., 1, 3], jacobian[..., 1, 5] = -z, x
    jacobian[..., 2, 3], jacobian[..., 2, 4] = y, -x
    return jacobian @ covariance @ np.swapaxes(jacobian, -1, -2)


def position_sigma_m(pose: np.ndarray, covariance: np.ndarray) -> np.ndarray | float:
    """1-sigma (m) of the position's distance from where it is estimated, ``sqrt(trace)`` of
    :func:`position_covariance`."""
    sigma = np.sqrt(np.trace(position_covariance(pose, covariance), axis1=-2, axis2=-1))
    return float(sigma) if np.ndim(sigma) == 0 else sigma


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
    1-frame relative motions (6 when calibrated; of the frames with a registration covariance, the others counted in
    ``relative_nees_frames_left_out``), and how much of the end-point error is a systematic drift (the
    mean relative error accumulated along the path) rather than noise the covariance describes."""
    final = pose_covariances[-1]
    out: dict[str, Any] = {
        "convention": POSE_COVARIANCE_CONVENTION,
        "frames_with_covariance": int(np.isfinite(relative_covariances[1:]).all(axis=(1, 2)).sum()),
        # the end position's, lever arm of the rotation included (the twist's translation block alone said 0 m where
        # one 1-deg yaw uncertainty 100 m back puts the end 1.745 m sideways)
        "final_position_sigma_m": position_sigma_m(poses[-1], final) if np.all(np.isfinite(final)) else None,
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
        # frames without a registration covariance (fallbacks, above all) have no NEES: counted, not dropped unsaid
        out["relative_nees_frames_left_out"] = int((~ok).sum())
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
    # errors are (white noise too). Whether there is a bias at all: per_frame_bias
    if len(errors) > 2:
        z, threshold = per_frame_bias(errors[:, :3])
        out["per_frame_bias_z"] = float(z)
        out["per_frame_bias_z_threshold"] = threshold
    return out


#: Share of white-noise runs the per-frame bias test calls biased, whatever their number of frames
BIAS_FALSE_ALARM = 0.01


def per_frame_bias(errors_xyz: np.ndarray, false_alarm: float = BIAS_FALSE_ALARM) -> tuple[np.ndarray, float]:
    """``(z, threshold)`` of ``(..., n, 3)`` per-frame translation errors: z is the largest of the three axes' |mean|
    over its standard error, a bias where above the threshold. The threshold is the Student-t quantile (n - 1 degrees
    of freedom) white noise passes on any of the three axes in ``false_alarm`` of runs; the normal 3 was passed by
    26 % of runs of 3 frame errors and 11 % of 5, the standard error being an estimate from as few."""
    from scipy.stats import t as student_t

    n = errors_xyz.shape[-2]
    if n < 2:
        raise DataError(f"{n} frame errors: a mean against its spread needs 2 or more", source="per_frame_bias")
    spread = errors_xyz.std(axis=-2, ddof=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(spread > 0, np.abs(errors_xyz.mean(axis=-2)) / (spread / np.sqrt(n)), 0.0)
    return z.max(axis=-1), float(student_t.ppf(1.0 - false_alarm / 6.0, n - 1))  # two-sided on each of 3 axes


__all__ = ["BIAS_FALSE_ALARM", "CHI2_6_95", "GAP_SWEEPS_RATIO", "MAX_PRIOR_FRAMES_LISTED", "MOTION_PRIOR_SIGMA",
           "POSE_COVARIANCE_CONVENTION", "POSE_COVARIANCE_PER_POSE", "UNKNOWN_ROTATION_SIGMA", "covariance_metrics",
           "motion_prior_frames", "motion_prior_sigma", "motion_prior_summary", "per_frame_bias", "position_covariance",
           "position_sigma_m", "propagate", "relative_errors", "with_motion_prior"]
