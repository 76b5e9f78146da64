"""Pose sanity checks: every rejection returns its reason (a string), acceptance returns None."""

from __future__ import annotations

import numpy as np

from lidarkit.geometry import rotation_angle_deg
from lidarkit.vo.config import SanityConfig
from lidarkit.vo.two_view import TwoViewEstimate


def check_pose(estimate: TwoViewEstimate, cfg: SanityConfig | None = None) -> str | None:
    """Why ``estimate`` must be rejected, or None. Finite values and det(R) = 1 are always checked; inlier count,
    rotation flip guard and parallax (pure rotation / standstill) only when ``cfg.enabled``."""
    cfg = cfg or SanityConfig()
    if cfg.enabled and min(estimate.rotation_only_px, estimate.parallax_px if estimate.ok else np.inf) < cfg.min_parallax_px:
        par = min(estimate.rotation_only_px, estimate.parallax_px if estimate.ok else np.inf)
        return (f"insufficient parallax ({par:.2f} px < {cfg.min_parallax_px:g} px): pure rotation "
                "or standstill, translation direction undefined")
    if not estimate.ok:
        return estimate.failure
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
        return f"too few inliers ({estimate.n_inliers} < {cfg.min_inliers})"
    angle = float(rotation_angle_deg(R))
    if angle > cfg.max_rotation_deg:
        return f"rotation flip guard ({angle:.1f} deg > {cfg.max_rotation_deg:g} deg)"
    return None
