"""Evaluation layer: APE/RPE (evo), KITTI devkit drift, position MSE, statistics over runs and paired
comparisons; reports and plots on top.

Every metric takes ``(ref, est)`` lidarkit Trajectories of equal length (frame-aligned) unless it says
otherwise, never modifies them, and returns a frozen result with ``.to_dict()``. Plots live in
``lidarkit.eval.plots`` (matplotlib, imported only there).
"""

from lidarkit.eval.ape_rpe import (
    ALIGNMENTS,
    APE_RELATIONS,
    DELTA_UNITS,
    RPE_RELATIONS,
    AlignmentTransform,
    APEResult,
    RPEResult,
    align_trajectory,
    ape,
    rpe,
)
from lidarkit.eval.evaluate import Evaluation, EvaluationSettings, evaluate
from lidarkit.eval.kitti_drift import (
    KITTI_LENGTHS_M,
    DriftResult,
    DriftRow,
    drift_segments_possible,
    kitti_drift,
)
from lidarkit.eval.compare import compare
from lidarkit.eval.mse import position_mse
from lidarkit.eval.pairing import paired
from lidarkit.eval.statistics import PairedComparison, Summary, bootstrap_ci, paired_test, summarize
from lidarkit.eval.relations import RelationError, relation_error

__all__ = [
    "ALIGNMENTS",
    "APE_RELATIONS",
    "DELTA_UNITS",
    "KITTI_LENGTHS_M",
    "RPE_RELATIONS",
    "APEResult",
    "AlignmentTransform",
    "DriftResult",
    "DriftRow",
    "Evaluation",
    "PairedComparison",
    "Summary",
    "EvaluationSettings",
    "RPEResult",
    "RelationError",
    "align_trajectory",
    "bootstrap_ci",
    "compare",
    "ape",
    "drift_segments_possible",
    "evaluate",
    "kitti_drift",
    "paired",
    "paired_test",
    "position_mse",
    "relation_error",
    "rpe",
    "summarize",
]
