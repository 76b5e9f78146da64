"""Relative scale: the ratio of depths of points triangulated in two consecutive frame pairs.

Each pair's translation is known up to scale; points seen in both pairs fix the ratio. Errors of a step are
permanent (the next step measures against depths in the scale just chosen), so the estimator must be unbiased and
a wild step must not be accepted silently: :func:`relative_scale` is the median of log depth ratios and
:func:`guarded_scale` keeps the previous scale (with a note) when a step changes it by more than a bound.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lidarkit.vo.config import ScaleConfig

SCALE_KEPT_NOTE = "scale kept from the previous step"


def relative_scale(depth_ref_known: np.ndarray, points_ref_unit: np.ndarray, angle_deg: np.ndarray,
                   usable: np.ndarray, cfg: ScaleConfig | None = None,
                   min_angle_deg: float | None = None) -> tuple[float | None, int]:
    """Scale of the current pair's unit translation so its depths agree with the previous pair's.

    ``depth_ref_known (N,)``: depth of each correspondence in the reference frame from the previous pair (in the
    trajectory's global scale; NaN if unknown); ``points_ref_unit (N, 3)``: the same points triangulated by the
    current pair with ``|t| = 1``; ``angle_deg (N,)``: their triangulation angles; ``usable (N,)``: inlier mask.
    Returns ``(scale, n_common)``; scale is None when fewer than ``cfg.min_common_points`` points qualify (angle at
    least ``min_angle_deg``, default ``cfg.min_triangulation_angle_deg``).
    The estimate is the median of log depth ratios: unbiased for symmetric relative depth noise and robust to a
    minority of wrong depths (a mean of ratios is pulled by every far or mistracked point).
    """
    cfg = cfg or ScaleConfig()
    min_angle_deg = cfg.min_triangulation_angle_deg if min_angle_deg is None else min_angle_deg
    z = points_ref_unit[:, 2]
    with np.errstate(invalid="ignore"):
        common = (usable & np.isfinite(depth_ref_known) & (depth_ref_known > 0) & np.isfinite(z) & (z > 0)
                  & (angle_deg >= min_angle_deg))
    n = int(common.sum())
    if n < cfg.min_common_points:
        return None, n
    scale = float(np.exp(np.median(np.log(depth_ref_known[common] / z[common]))))
    return (scale if np.isfinite(scale) and scale > 0 else None), n


@dataclass(frozen=True)
class ScaleDecision:
    """Outcome of :func:`guarded_scale`: the per-frame ``scale`` used, whether the measurement was ``kept`` out
    (no estimate or a change beyond the bound) and a ``note`` for the diagnostics (empty when accepted)."""

    scale: float
    kept: bool
    note: str


def guarded_scale(measured: float | None, previous: float, n_common: int, first_step: bool,
                  cfg: ScaleConfig | None = None) -> ScaleDecision:
    """Per-frame scale for this step from the measured one and the previous step's.

    No measurement, or one that changes the scale by more than the factor ``cfg.max_step_change``, keeps the
    previous scale with a note; ``first_step`` (no depths exist yet): the previous (unit) scale starts the
    trajectory without a note.
    """
    cfg = cfg or ScaleConfig()
    if measured is None:
        if first_step:
            return ScaleDecision(previous, False, "")
        return ScaleDecision(previous, True, f"{SCALE_KEPT_NOTE} ({n_common} common points "
                                             f"< {cfg.min_common_points})")
    change = measured / previous
    if not 1.0 / cfg.max_step_change <= change <= cfg.max_step_change:
        return ScaleDecision(previous, True, f"{SCALE_KEPT_NOTE} (change x{change:.2f} beyond "
                                             f"x{cfg.max_step_change:g}, {n_common} common points)")
    return ScaleDecision(float(measured), False, "")
