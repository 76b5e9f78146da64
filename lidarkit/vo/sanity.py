"""Pose sanity checks: every rejection returns its reason (a string), acceptance returns None."""

from __future__ import annotations

import numpy as np

from lidarkit.errors import ConfigError
from lidarkit.geometry import rotation_angle_deg
from lidarkit.vo.config import SanityConfig
from lidarkit.vo.two_view import TwoViewEstimate, few_inliers_parallax_reason


def check_pose(estimate: TwoViewEstimate, cfg: SanityConfig | None = None) -> str | None:
    """Why ``estimate`` must be rejected, or None. Finite values and det(R) = 1 are always checked; inlier count,
    rotation flip guard and parallax (pure rotation / standstill) only when ``cfg.enabled``.

    Pure rotation / standstill is caught twice: by the K-free homography test (:func:`rotation_homography_reason`),
    which holds with guessed or wrong intrinsics, and by the parallax left after removing the rotation with K."""
    if not isinstance(estimate, TwoViewEstimate):  # (None failed on an attribute)
        raise ConfigError(f"estimate must be a TwoViewEstimate (lidarkit.vo.estimate_two_view), got "
                          f"{type(estimate).__name__} {estimate!r:.60}", source="estimate")
    if cfg is not None and not isinstance(cfg, SanityConfig):
        raise ConfigError(f"cfg must be a SanityConfig or None, got {type(cfg).__name__} {cfg!r:.60}", source="cfg")
    cfg = cfg or SanityConfig()
    if cfg.enabled and (reason := rotation_homography_reason(estimate, cfg)) is not None:
        return reason
    if cfg.enabled and min(estimate.rotation_only_px, estimate.parallax_px if estimate.ok else np.inf) < cfg.min_parallax_px:
        par = min(estimate.rotation_only_px, estimate.parallax_px if estimate.ok else np.inf)
        return (f"insufficient parallax ({par:.2f} px < {cfg.min_parallax_px:g} px): pure rotation "
                "or standstill, translation direction undefined")
    if not estimate.ok:  # (too few pose inliers at walking pace: most correspondences explained, no parallax yet)
        return (cfg.enabled and few_inliers_parallax_reason(estimate, cfg.min_inliers)) or estimate.failure
    R, t = estimate.R_cur_ref, estimate.t_cur_ref
    if not (np.all(np.isfinite(R)) and np.all(np.isfinite(t))):
        return "non-finite rotation or translation"
    det = float(np.linalg.det(R))
    if abs(det - 1.0) > 1e-6 or not np.allclose(R @ R.T, np.eye(3), atol=1e-6):
        return f"rotation is not orthonormal (det(R) = {det:.6f})"
    if abs(float(np.linalg.norm(t)) - 1.0) > 1e-6:
        return f"translation direction is not a unit vector (|t| = {np.linalg.norm(t):.3g})"
    if not cfg.enabled:
        return None
    if estimate.n_inliers < cfg.min_inliers:
        return (few_inliers_parallax_reason(estimate, cfg.min_inliers)
                or f"too few inliers ({estimate.n_inliers} < {cfg.min_inliers})")
    angle = float(rotation_angle_deg(R))
    if angle > cfg.max_rotation_deg:
        return f"rotation flip guard ({angle:.1f} deg > {cfg.max_rotation_deg:g} deg)"
    return None


def rotation_homography_reason(estimate: TwoViewEstimate, cfg: SanityConfig) -> str | None:
    """The K-free pure-rotation / no-parallax verdict: the homography explains at least ``max_homography_share`` of
    the fundamental-matrix inliers and is within ``max_rotation_homography_px`` of a pure rotation (focal length
    self-calibrated). A plane seen under translation passes: its homography is not rotation-conjugate."""
    if estimate.fundamental_inliers == 0 or estimate.homography_share < cfg.max_homography_share:
        return None
    if not estimate.rotation_homography_px <= cfg.max_rotation_homography_px:
        return None
    return (f"insufficient parallax (pure rotation / no parallax: homography explains "
            f"{100 * estimate.homography_share:.1f}% of {estimate.fundamental_inliers} fundamental-matrix inliers "
            f"and is a pure rotation within {estimate.rotation_homography_px:.2f} px, self-calibrated f = "
            f"{estimate.rotation_focal_px:.0f} px): translation direction undefined")
