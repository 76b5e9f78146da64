"""Score a VO trajectory against ground truth with ``lidarkit.eval`` (evo): APE, RPE and final-frame error.

Alignment follows the scale mode: SE(3) when the scale came from the ground truth (``gt``), Sim(3) otherwise
(unit steps or relative scale leave one unknown global scale).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from lidarkit.trajectory import Trajectory


def alignment_for(scale_mode: str) -> str:
    """``se3`` for ground-truth scale, ``sim3`` for ``none`` / ``relative``; ConfigError for any other (``"GT"`` was
    scored with Sim(3), an APE of 0 for a trajectory twice too long)."""
    from lidarkit.vo.config import SCALE_MODES

    if scale_mode not in SCALE_MODES:
        from lidarkit.errors import ConfigError

        raise ConfigError(f"unknown scale mode {scale_mode!r}; known: {', '.join(SCALE_MODES)}", source="scale_mode")
    return "se3" if scale_mode == "gt" else "sim3"


@dataclass(frozen=True, eq=False)
class VOScores:
    """:func:`evaluate_vo`'s ``metrics`` dict plus the translation APE result behind it (errors, aligned estimate)."""

    metrics: dict[str, Any]
    ape: Any


def score_vo(est: Trajectory, ref: Trajectory, scale_mode: str, align: str | None = None, *,
             associate: bool = False, max_diff_s: float = 0.01) -> VOScores:
    """:func:`evaluate_vo` keeping the APE result; ``align`` (``none``/``se3``/``sim3``) overrides
    :func:`alignment_for` for APE and RPE. ``final_error_m`` keeps its definition (it depends on the scale mode only).
    ``associate``: match the poses by time stamp within ``max_diff_s`` s first (the length error advised it, but
    neither function took it); the final errors are then those of the last matched pair."""
    from lidarkit.eval import ape, rpe
    from lidarkit.eval.ape_rpe import check_flags
    from lidarkit.eval.pairing import paired

    by_scale = alignment_for(scale_mode)  # (checks the mode, which final_error_m depends on, whatever align says)
    align = by_scale if align is None else align
    check_flags(associate=associate)
    ref, est = paired(ref, est, associate=associate, max_diff_s=max_diff_s)
    a = ape(ref, est, align=align)
    r_t = rpe(ref, est, delta=1, delta_unit="frames", align=align)
    r_r = rpe(ref, est, delta=1, delta_unit="frames", align=align, relation="rotation_angle_deg")
    final_raw = float(np.linalg.norm(est.positions_xyz[-1] - ref.positions_xyz[-1]))
    final_aligned = float(np.linalg.norm(a.est_aligned.positions_xyz[-1] - ref.positions_xyz[-1]))
    metrics = {
        "align": align,
        "ape_rmse_m": float(a.rmse),
        "ape_max_m": float(a.max),
        "rpe_trans_rmse_m": float(r_t.rmse),
        "rpe_rot_rmse_deg": float(r_r.rmse),
        "final_error_m": final_raw if scale_mode == "gt" else final_aligned,
        "final_error_raw_m": final_raw,
        "final_error_aligned_m": final_aligned,
        "alignment_scale": float(a.alignment.scale) if a.alignment is not None else 1.0,
    }
    return VOScores(metrics, a)


def evaluate_vo(est: Trajectory, ref: Trajectory, scale_mode: str, align: str | None = None, *,
                associate: bool = False, max_diff_s: float = 0.01) -> dict[str, Any]:
    """APE (translation, m), RPE over 1 frame (translation m, rotation deg) and final-frame errors.

    ``final_error_m`` is the raw distance of the last positions for ``gt`` scale (both start at the same pose) and
    the distance after alignment otherwise; both variants are also reported separately. ``align``, ``associate``,
    ``max_diff_s``: see :func:`score_vo`.
    """
    return score_vo(est, ref, scale_mode, align, associate=associate, max_diff_s=max_diff_s).metrics


def scored_from_frame(result: Any) -> int:
    """The first frame a run estimated (``result.meta["start_frame"]``): frames before it (unreadable at the start)
    only hold its pose, and scored they raised the APE of a run with one bad first frame 67-fold (0.008 -> 0.29 m
    on KITTI 06), so the CLI and the bench score from here on."""
    return int(result.meta.get("start_frame", 0))


def scored_frames(result: Any, n_truth: int) -> tuple[int, np.ndarray | None, str | None]:
    """``(first, frames, why)``: the frames scored from the first estimated frame on (:func:`scored_from_frame`) of a
    ground truth of ``n_truth`` poses, or None and why when they are too few to score (APE and RPE need 3)."""
    first = scored_from_frame(result)
    if n_truth - first < 3:
        return first, None, f"{n_truth - first} pose(s) from the first estimated frame on; APE and RPE need 3"
    return first, np.arange(first, n_truth), None
