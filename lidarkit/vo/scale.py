"""Relative scale: the ratio of depths of points triangulated in two consecutive frame pairs."""

from __future__ import annotations

import numpy as np

from lidarkit.vo.config import ScaleConfig


def relative_scale(depth_ref_known: np.ndarray, points_ref_unit: np.ndarray, angle_deg: np.ndarray,
                   usable: np.ndarray, cfg: ScaleConfig | None = None) -> tuple[float | None, int]:
    """Scale of the current pair's unit translation so its depths agree with the previous pair's.

    ``depth_ref_known (N,)``: depth of each correspondence in the reference frame from the previous pair (in the
    trajectory's global scale; NaN if unknown); ``points_ref_unit (N, 3)``: the same points triangulated by the
    current pair with ``|t| = 1``; ``angle_deg (N,)``: their triangulation angles; ``usable (N,)``: inlier mask.
    Returns ``(scale, n_common)``; scale is None when fewer than ``cfg.min_common_points`` points qualify.
    The robust estimate is the median of log-ratios.
    """
    cfg = cfg or ScaleConfig()
    z = points_ref_unit[:, 2]
    with np.errstate(invalid="ignore"):
        common = (usable & np.isfinite(depth_ref_known) & (depth_ref_known > 0) & np.isfinite(z) & (z > 0)
                  & (angle_deg >= cfg.min_triangulation_angle_deg))
    n = int(common.sum())
    if n < cfg.min_common_points:
        return None, n
    log_ratio = np.log(depth_ref_known[common] / z[common])
    scale = float(np.exp(np.median(log_ratio)))
    return (scale if np.isfinite(scale) and scale > 0 else None), n
