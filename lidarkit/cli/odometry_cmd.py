"""``lidarkit odometry DATA --method NAME``: run a registration variant over a sequence, print the scores."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer
from rich.table import Table
from rich.text import Text

from lidarkit.cli.app import app, named_by_option, parse_params, stdout


def _kinds() -> str:
    from lidarkit.io import NOT_SCANS, available_datasets

    return ", ".join(kind for kind in available_datasets() if kind not in NOT_SCANS)


DATA_HELP = (
    "A KITTI sequence folder (or odometry root), a .bag / .mcap / .pcap file or ROS 2 bag folder (detected), a folder "
    "of scans, KIND:PATH[?opt=v&...] for any dataset reader (e.g. 'kitti:/data/kitti?sequence=05&poses_file=...', "
    f"'rosbag:run.bag?topic=/velodyne_points'; kinds: {_kinds()}), or the simulator: 'sim:street?frames=300&seed=0' "
    "(scenes street|open|ground; keys: frames, seed, beams, azimuths, noise, distortion, instant, speed or any "
    "simulator config field)."
)


#: run() settings -> the option that sets them (a library error names the setting)
_OPTION_OF_SETTING = {"init": "--init", "out_dir": "--out"}


def _fmt(value: object, spec: str = ".3f") -> str:
    return "-" if value is None else format(value, spec)


def _deskew_text(deskew: dict | None) -> str:
    if not deskew:
        return "-"
    if deskew["applied"]:
        return f"on: {deskew['reason']}"
    if deskew.get("needed") is False:  # (snapshot sweeps: nothing to deskew, not a request left undone)
        return f"not needed: {deskew['reason']}"
    if deskew["requested"]:
        return f"REQUESTED, NOT APPLIED: {deskew['reason']}"
    return f"off: {deskew['reason']}"


def _stat(m: dict, key: str, spec: str = ".3f") -> str:
    return _fmt(((m.get(key) or {}).get("stats") or {}).get("rmse"), spec)


@app.command("odometry")
def odometry(
    data: str = typer.Argument(..., help=DATA_HELP),
    method: str = typer.Option("kiss", "--method", "-m", help="Registered ICP variant ('lidarkit icp --list')."),
    param: list[str] = typer.Option([], "--param", "-p", help="Method parameter KEY=VALUE (repeatable)."),
    frames: Optional[str] = typer.Option(None, "--frames", help="Frames START:STOP[:STEP] (Python slice, dataset indices)."),
    out: Optional[Path] = typer.Option(None, "--out", "-o", help="Run folder: poses (KITTI, TUM), config.yaml, metrics.json, timing.csv, plot."),
    name: Optional[str] = typer.Option(None, "--name", help="Title of the run (default: the dataset's name: kitti_NN, a folder's name, sim:SCENE?seed=N, rosbag:FILE/TOPIC)."),
    progress: bool = typer.Option(True, "--progress/--no-progress", help="Progress bar on stderr."),
    pose_covariance: Optional[bool] = typer.Option(
        None, "--pose-covariance/--no-pose-covariance",
        help="Propagate the per-frame covariances into pose_covariance.txt (default: on for scan-to-scan variants, off for "
        "stateful ones such as kiss, where it costs an extra assessment per frame).",
    ),
    strict: bool = typer.Option(
        False, "--strict",
        help="Fail on the first frame whose registration does not converge, and when a requested deskew cannot happen "
        "(default: warn; non-converged frames use constant velocity, or the odometry motion with --init odometry).",
    ),
    init: str = typer.Option(
        "constant_velocity", "--init",
        help="Initial guess per frame: constant_velocity | odometry (the dataset's own odometry, e.g. a carmen: log).",
    ),
    check: list[str] = typer.Option(
        [], "--check",
        help="Threshold of the independent per-frame check KEY=VALUE (repeatable), e.g. max_angular_accel_dps2=500 "
        "(keys: max_accel_mps2, max_angular_accel_dps2, min_fitness, inlier_min_m, inlier_range_fraction, ...); "
        "n_sample=0 leaves its fitness test out (~2.5 ms a KITTI scan), the motion test stays.",
    ),
) -> None:
    """Odometry of one ICP variant over a scan sequence, scored against its ground truth when it has one."""
    from lidarkit.atomic import check_target
    from lidarkit.odometry import run
    from lidarkit.odometry.frame_check import make_frame_check

    from lidarkit.run_files import RUN_FILES

    check_target(out, "folder", files=RUN_FILES, replaces=RUN_FILES)
    frame_check = make_frame_check(**parse_params(check, option="--check"))
    with named_by_option(_OPTION_OF_SETTING):  # a setting named as the library calls it ("init: unknown initial guess")
        result = run(
            data, method, params=parse_params(param), frames=frames, out_dir=out, progress=progress, strict=strict, name=name,
            init=init, pose_covariance=pose_covariance, frame_check=frame_check,
        )
    m = result.metrics
    effective = m.get("effective") or {}
    table = Table(title=result.trajectory.name, show_header=True)
    table.add_column("metric")
    table.add_column("value", overflow="fold")
    table.add_row("frames", str(m["n_frames"]))
    table.add_row("frame rate (Hz)", f"{m['fps']:.2f}")
    mean_s = m["register_time_s"]["mean"]
    table.add_row("registration time mean (ms)", "n/a (one frame: nothing registered)" if mean_s is None else f"{1e3 * mean_s:.1f}")
    table.add_row("deskew", _deskew_text(effective.get("deskew")))
    corrections = effective.get("corrections") or {}
    table.add_row("reader corrections", ", ".join(f"{k}={v}" for k, v in corrections.items()) or "none reported by the reader")
    if m.get("convergence_measured", True):
        degenerate = "n/a (not assessed: assess=False)" if m["n_degenerate"] is None else m["n_degenerate"]
        table.add_row("not converged / degenerate (variant's verdict)", f"{m['n_not_converged']} / {degenerate}")
        table.add_row(f"fallbacks ({m.get('fallback_motion', 'constant velocity')} motion)", str(m.get("n_constant_velocity_fallback", 0)))
    else:
        table.add_row("not converged / degenerate (variant's verdict)", "n/a (a stateful method gives no verdict)")
    check = m.get("frame_check")
    if check:
        table.add_row(
            "bad frames (independent check)",
            f"{check['n_bad_frames']} of {m['n_frames']} (motion "
            # frames whose stamps cannot time the motion are not checked for it: said when they are more than a few, and
            # "not checked" when none is (1-2 frames read "motion 0")
            + ("not checked" if check.get("n_motion_checked", m["n_frames"]) == 0 else f"{check['n_bad_motion']}"
               + (f" of {check['n_motion_checked']} checked" if check.get("n_motion_checked", m["n_frames"]) < 0.9 * (m["n_frames"] - 2) else ""))
            + ", fitness " + (f"{check['n_bad_fitness']})" if check.get("n_fitness_checked", 1) else "not checked)"),
        )
        said = check["n_said_converged_but_bad"]
        table.add_row("  of which the variant called converged", "n/a (no verdict)" if said is None else str(said))
    table.add_row("estimated path (m)", f"{m['estimated_length_m']:.2f}")
    from lidarkit.odometry.settings import skips_frames

    # the relative scores' step: one selected frame where the selection skips frames (the RPE's and the NEES's)
    step = "1 selected frame" if skips_frames(result.frames) else "1 frame"
    if "final_error" in m:
        table.add_row("ground truth", str(m["ground_truth"]))
        table.add_row("ground-truth instant / estimate instant", f"{effective.get('ground_truth_instant')} / {effective.get('estimate_instant')}")
        if m.get("ground_truth_instant_note"):
            table.add_row("ground-truth instant note", str(m["ground_truth_instant_note"]))
        table.add_row("ground-truth path (m)", f"{m['ground_truth_length_m']:.2f}")
        table.add_row("final error, unaligned (m / deg)", f"{m['final_error']['translation_m']:.3f} / {m['final_error']['rotation_deg']:.3f}")
        if "ape_translation_m" in m:
            table.add_row("APE translation RMSE, SE(3)-aligned (m)", m.get("ape_translation_se3_note") or _stat(m, "ape_translation_se3_m"))
            table.add_row("APE translation RMSE, unaligned, first pose anchored (m)", _stat(m, "ape_translation_m"))
            table.add_row(f"RPE {step} RMSE, alignment-free (m / deg)", f"{_stat(m, 'rpe_translation_m', '.4f')} / {_stat(m, 'rpe_rotation_deg', '.4f')}")
        drift = m.get("kitti_drift")
        if drift:
            table.add_row("KITTI drift, alignment-free (% / deg per 100 m)", f"{drift['translation_pct']:.3f} / {drift['rotation_deg_per_100m']:.4f}")
        else:
            table.add_row("KITTI drift", m.get("kitti_drift_note", "-"))
    else:
        table.add_row("ground truth", m.get("ground_truth_note") or "none: no scores")
    cov = m.get("pose_covariance")
    if cov and cov.get("final_position_sigma_m") is not None:
        table.add_row("propagated end position / heading 1-sigma (m / deg)", f"{cov['final_position_sigma_m']:.3f} / {cov['final_heading_sigma_deg']:.3f}")
        if "relative_nees_mean" in cov:
            left_out = cov.get("relative_nees_frames_left_out", 0)
            table.add_row(f"NEES of motions over {step} (6 = calibrated)", f"{cov['relative_nees_mean']:.2f} ({100 * cov['relative_inside_95']:.0f} % inside 95 %)"
                          + (f"; {left_out} frames left out (no registration covariance)" if left_out else ""))
            z = cov.get("per_frame_bias_z")
            if z is not None:  # the share the mean frame error rebuilds says nothing unless that mean is a bias
                threshold = cov.get("per_frame_bias_z_threshold", 3.0)
                table.add_row("per-frame bias (mean error / its standard error)",
                              f"z = {z:.1f} (a bias above {threshold:.1f}): "
                              + (f"rebuilds {100 * min(cov['end_error_bias_share'], 1.0):.0f} % of the end error as a world-frame twist "
                                 f"({cov['end_error_m']:.3f} m; the final error is the distance of the end positions)" if z > threshold
                                 else "none shows (noise)"))
        prior = cov.get("motion_prior_only") or {}
        if prior.get("n_frames"):  # (their covariance is the motion prior's: the run's end sigma is theirs)
            reasons = ", ".join(f"{n} {why}" for why, n in prior.get("by_reason", {}).items() if n)
            shown = ", ".join(str(f) for f in prior.get("frames", [])[:10])
            more = prior["n_frames"] - min(len(prior.get("frames", [])), 10)
            table.add_row("frames with the motion prior alone", f"{prior['n_frames']} ({reasons}): dataset indices {shown}"
                          + (f" and {more} more" if more > 0 else ""))
        if cov.get("distortion_floor"):
            table.add_row("covariance distortion floor", cov["distortion_floor"])
    for message in m.get("warnings") or []:  # also logged (stderr) by the runner
        table.add_row(Text("warning", style="yellow"), Text(message, style="yellow"))
    if result.out_dir is not None:
        table.add_row("run folder", str(result.out_dir.resolve()))
    console = stdout()
    console.print(table)
    if result.out_dir is not None:
        console.print(f"run folder: {result.out_dir.resolve()}", soft_wrap=True)
