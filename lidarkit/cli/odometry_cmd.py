"""``lidarkit odometry DATA --method NAME``: run a registration variant over a sequence, print the scores."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer
from rich.table import Table

from lidarkit.cli.app import app, parse_params, stdout

DATA_HELP = (
    "A KITTI sequence folder (or odometry root), a folder of scans, KIND:PATH[?opt=v&...] for any dataset reader "
    "(e.g. 'kitti:/data/kitti?sequence=05&poses_file=...'), or the simulator: 'sim:street?frames=300&seed=0' "
    "(scenes street|open|ground; keys: frames, seed, beams, azimuths, noise, distortion, instant, speed or any "
    "simulator config field)."
)


def _fmt(value: object, spec: str = ".3f") -> str:
    return "-" if value is None else format(value, spec)


@app.command("odometry")
def odometry(
    data: str = typer.Argument(..., help=DATA_HELP),
    method: str = typer.Option("kiss", "--method", "-m", help="Registered ICP variant ('lidarkit icp --list')."),
    param: list[str] = typer.Option([], "--param", "-p", help="Method parameter KEY=VALUE (repeatable)."),
    frames: Optional[str] = typer.Option(None, "--frames", help="Frames START:STOP[:STEP] (Python slice, dataset indices)."),
    out: Optional[Path] = typer.Option(None, "--out", "-o", help="Run folder: poses (KITTI, TUM), config.yaml, metrics.json, timing.csv, plot."),
    progress: bool = typer.Option(True, "--progress/--no-progress", help="Progress bar on stderr."),
    strict: bool = typer.Option(False, "--strict", help="Fail on the first frame whose registration does not converge (default: warn, use constant velocity)."),
) -> None:
    """Odometry of one ICP variant over a scan sequence, scored against its ground truth when it has one."""
    from lidarkit.odometry import run

    result = run(data, method, params=parse_params(param), frames=frames, out_dir=out, progress=progress, strict=strict)
    m = result.metrics
    table = Table(title=result.trajectory.name, show_header=True)
    table.add_column("metric")
    table.add_column("value", justify="right")
    table.add_row("frames", str(m["n_frames"]))
    table.add_row("frame rate (Hz)", f"{m['fps']:.2f}")
    table.add_row("registration time mean (ms)", f"{1e3 * m['register_time_s']['mean']:.1f}")
    if m.get("convergence_measured", True):
        table.add_row("not converged / degenerate", f"{m['n_not_converged']} / {m['n_degenerate']}")
        table.add_row("constant-velocity fallbacks", str(m.get("n_constant_velocity_fallback", 0)))
    else:
        table.add_row("not converged / degenerate", "n/a (not measured by a stateful method)")
    table.add_row("estimated path (m)", f"{m['estimated_length_m']:.2f}")
    if "final_error" in m:
        table.add_row("ground truth", str(m["ground_truth"]))
        table.add_row("ground-truth path (m)", f"{m['ground_truth_length_m']:.2f}")
        table.add_row("final error (m / deg)", f"{m['final_error']['translation_m']:.3f} / {m['final_error']['rotation_deg']:.3f}")
        if "ape_translation_m" in m:
            table.add_row("APE translation RMSE (m)", _fmt(m["ape_translation_m"]["stats"]["rmse"]))
            table.add_row("RPE 1 frame RMSE (m / deg)", f"{m['rpe_translation_m']['stats']['rmse']:.4f} / {m['rpe_rotation_deg']['stats']['rmse']:.4f}")
        drift = m.get("kitti_drift")
        if drift:
            table.add_row("KITTI drift (% / deg per 100 m)", f"{drift['translation_pct']:.3f} / {drift['rotation_deg_per_100m']:.4f}")
        else:
            table.add_row("KITTI drift", m.get("kitti_drift_note", "-"))
    else:
        table.add_row("ground truth", "none: no scores")
    cov = m.get("pose_covariance")
    if cov and cov.get("final_position_sigma_m") is not None:
        table.add_row("propagated end-pose 1-sigma (m / deg)", f"{cov['final_position_sigma_m']:.3f} / {cov['final_heading_sigma_deg']:.3f}")
        if "relative_nees_mean" in cov:
            table.add_row("NEES of 1-frame motions (6 = calibrated)", f"{cov['relative_nees_mean']:.2f} ({100 * cov['relative_inside_95']:.0f} % inside 95 %)")
            table.add_row("end error explained by bias", f"{100 * min(cov['end_error_bias_share'], 1.0):.0f} %")
    if result.out_dir is not None:
        table.add_row("run folder", str(result.out_dir))
    stdout().print(table)
