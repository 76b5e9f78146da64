"""``lidarkit demo``: run what lidarkit bundles and print the results (for now: the evaluation sample)."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from lidarkit.cli.app import app, stdout


@app.command("demo")
def demo_command(
    out_dir: Optional[Path] = typer.Option(
        None, "--out", "-o", help="Also write metrics.json, report.md and evaluation.png here."
    ),
) -> None:
    """Evaluate the bundled KITTI 00 ORB-SLAM2 trajectory against ground truth and print the tables."""
    from lidarkit.eval import report
    from lidarkit.eval.demo import EVO_REFERENCE_APE_RMSE_M, run_eval_demo

    console = stdout()
    result = run_eval_demo(out_dir)
    for evaluation in result.evaluations:
        console.print(report.evaluation_table(evaluation))
        if evaluation.drift is not None:
            console.print(report.drift_table(evaluation))
        console.print(
            f"APE translation rmse {evaluation.ape.rmse:.4f} m; evo's stored reference result: "
            f"{EVO_REFERENCE_APE_RMSE_M:.4f} m"
        )
    for name, path in result.files.items():
        console.print(f"wrote {name}: {path}")
