"""Evaluation demo on the bundled sample (evo's KITTI 00 ground truth vs ORB-SLAM2 estimate)."""

from __future__ import annotations

import logging
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from lidarkit import atomic
from lidarkit.eval import report
from lidarkit.eval.evaluate import Evaluation, EvaluationSettings, evaluate
from lidarkit.samples import extract_sample
from lidarkit.trajectory import Trajectory

logger = logging.getLogger(__name__)

SAMPLE = "evo_kitti00"
DEMO_SETTINGS = EvaluationSettings(align="se3", delta=10.0, delta_unit="meters")
EVO_REFERENCE_APE_RMSE_M = 1.3034  # evo's stored res_files/orb_ape.zip (APE translation, SE(3) Umeyama)


@dataclass(frozen=True, eq=False)
class EvalDemoResult:
    """The demo's evaluations and the files it wrote (empty without ``out_dir``)."""

    evaluations: tuple[Evaluation, ...]
    files: dict[str, Path] = field(default_factory=dict)


def load_sample_pair(work_dir: str | os.PathLike) -> tuple[Trajectory, Trajectory]:
    """Ground truth and ORB-SLAM2 estimate of KITTI 00 from the bundled sample, both with timestamps."""
    work_dir = Path(work_dir)
    gt_path = extract_sample(SAMPLE, "KITTI_00_gt.txt", dest_dir=work_dir)
    est_path = extract_sample(SAMPLE, "KITTI_00_ORB.txt", dest_dir=work_dir)
    times_path = extract_sample(SAMPLE, "KITTI_00_gt_times.txt", dest_dir=work_dir)
    ref = Trajectory.from_kitti(gt_path, times_path, name="KITTI_00_gt")
    est = Trajectory.from_kitti(est_path, times_path, name="KITTI_00_ORB")
    return ref, est


def run_eval_demo(
    out_dir: str | os.PathLike | None = None, settings: EvaluationSettings = DEMO_SETTINGS
) -> EvalDemoResult:
    """Evaluate the bundled KITTI 00 ORB-SLAM2 estimate; with ``out_dir`` also write JSON, Markdown and a PNG.

    Files in ``out_dir``: ``inputs/`` (the extracted trajectories), ``metrics.json``, ``report.md``,
    ``evaluation.png``.
    """
    files: dict[str, Path] = {}
    if out_dir is None:
        with tempfile.TemporaryDirectory(prefix="lidarkit-demo-") as tmp:
            ref, est = load_sample_pair(tmp)
    else:
        ref, est = load_sample_pair(Path(out_dir) / "inputs")
    evaluation = evaluate(ref, est, settings)
    logger.info("demo: APE rmse %.4f m (evo reference %.4f m)", evaluation.ape.rmse, EVO_REFERENCE_APE_RMSE_M)
    if out_dir is not None:
        from lidarkit.eval import plots

        out = Path(out_dir)
        files["metrics"] = report.write_json(
            {"evaluations": [evaluation.to_dict()], "evo_reference_ape_rmse_m": EVO_REFERENCE_APE_RMSE_M},
            out / "metrics.json",
        )
        files["report"] = atomic.write_text(out / "report.md", report.evaluation_markdown(evaluation))
        files["plot"] = plots.plot_evaluation(evaluation, out / "evaluation.png")
    return EvalDemoResult((evaluation,), files)
