"""``lidarkit vo DATA``: monocular visual odometry on a KITTI sequence, a TUM folder, a plain image folder or the camera
simulator (``simcam:street?...``)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Optional

import numpy as np
import typer

from lidarkit.cli.app import app, named_by_option, parse_params, stderr, stdout
from lidarkit.errors import ConfigError, DataError
from lidarkit.vo.config import VOConfig, available_presets
from lidarkit.vo.intrinsics import DEFAULT_FOCAL_FACTOR

_D = VOConfig()
_TOP_REASONS = 3  # rejection kinds shown in the summary table
_LISTED_REJECTIONS = 10  # rejected frames listed one per line


#: config fields the command's own options set (their errors name the option)
_OPTION_OF = {"features.detector": "--detector", "matching.method": "--matcher", "geometry.estimators": "--estimator",
              "preprocess.method": "--preprocess", "features.max_features": "--features", "scale.mode": "--scale",
              "sanity.enabled": "--sanity/--no-sanity", "geometry.refine": "--refine/--no-refine", "seed": "--seed"}


@app.command("vo")
def vo_command(
    data: Path = typer.Argument(..., help="KITTI sequence folder (image_0/, calib.txt), TUM folder (rgb.txt), image folder, or the camera simulator: 'simcam:street?frames=500&seed=0' (exact K and ground truth; --kind images hides its K)."),
    preset: str = typer.Option("lidarkit", help=f"Starting configuration: {' | '.join(available_presets())}."),
    detector: Optional[str] = typer.Option(None, help=f"gftt | fast | orb | sift | akaze (lidarkit: {_D.features.detector})."),
    matcher: Optional[str] = typer.Option(None, help=f"klt | bf_cross | knn_ratio (lidarkit: {_D.matching.method})."),
    estimator: Optional[list[str]] = typer.Option(None, help="Essential-matrix estimator, repeatable (best kept): "
                                                  f"ransac | magsac | lmeds (lidarkit: {', '.join(_D.geometry.estimators)})."),
    preprocess: Optional[str] = typer.Option(None, help="none | clahe | gaussian | bilateral (lidarkit: "
                                             f"{_D.preprocess.method})."),
    features: Optional[int] = typer.Option(None, help=f"Feature budget, shared over the detector's grid cells: ceil(N / cells) each, so a frame gives up to cells x that "
                                                         f"(lidarkit: {_D.features.max_features})."),
    scale: Optional[str] = typer.Option(None, help=f"gt | none | relative (lidarkit: {_D.scale.mode})."),
    sanity: Optional[bool] = typer.Option(None, "--sanity/--no-sanity", help="Pose sanity checks (lidarkit: on)."),
    refine: Optional[bool] = typer.Option(None, "--refine/--no-refine", help="Sampson refinement (lidarkit: on)."),
    calib: Optional[Path] = typer.Option(None, help="Intrinsics file: 9 numbers (K, bare or after 'K:'), 4 (fx fy cx cy), "
                                        "12 (a 3x4 P, its left 3x3), numpy's printed matrix, KITTI odometry calib.txt (P0) or KITTI raw "
                                        "calib_cam_to_cam.txt (P_rect_00)."),
    timestamps: Optional[Path] = typer.Option(None, help="Time stamps file (one per image)."),
    poses: Optional[Path] = typer.Option(None, help="Ground-truth camera poses for an image folder (or other KITTI poses)."),
    poses_format: str = typer.Option("kitti", help="Format of --poses: kitti | tum."),
    focal_factor: float = typer.Option(DEFAULT_FOCAL_FACTOR, help="Without intrinsics: fx = fy = factor * max(w, h)."),
    self_calibrate: bool = typer.Option(False, "--self-calibrate/--no-self-calibrate",
                                        help="Without intrinsics: estimate fx = fy from the sequence (principal point "
                                        "at the centre); falls back to the size guess when the motion does not "
                                        "constrain it. Costs 20-45 s per 50 KITTI frames."),
    kind: str = typer.Option("auto", help="Input kind: auto | kitti | tum | images (for simcam: auto | images)."),
    start: int = typer.Option(0, help="First image, by its index from 0 in the input (a KITTI folder whose files "
                              "begin at 000010.png has frame 10 at index 0)."),
    max_frames: Optional[int] = typer.Option(None, help="Number of frames to process (default: all)."),
    seed: Optional[int] = typer.Option(None, help="Shuffle the correspondences fed to RANSAC/MAGSAC/LMedS with this "
                                       "seed (same seed, same poses); default: detection order, also deterministic."),
    set_: Optional[list[str]] = typer.Option(None, "--set", help="Any config field, repeatable: "
                                             "--set matching.klt_levels=4 --set scale.min_common_points=20."),
    out: Optional[Path] = typer.Option(None, "--out", "-o", help="Run folder for poses, diagnostics, config, plot."),
    gif: bool = typer.Option(False, help="Also write features.gif (tracked inliers) into --out."),
    progress: bool = typer.Option(True, "--progress/--no-progress", help="Progress on stderr."),
) -> None:
    """Estimate the camera trajectory; print frames, rejected frames, speed and APE/RPE when ground truth exists."""
    from rich.table import Table

    from lidarkit.eval.ape_rpe import alignment_label
    from lidarkit.vo.config import inert_settings, preset as make_preset
    from lidarkit.vo.inputs import frame_range, open_vo_input, self_calibrate as calibrate
    from lidarkit.vo.pipeline import MonoVO

    from lidarkit.atomic import check_target

    from lidarkit.run_files import RUN_FILES

    check_target(out, "folder", files=RUN_FILES, replaces=RUN_FILES)  # (a folder named trajectory.png in it was found after the run)
    if seed is not None and seed < 0:
        raise ConfigError(f"must be >= 0, got {seed}", source="--seed")
    if max_frames is not None and max_frames < 1:
        raise ConfigError(f"must be >= 1, got {max_frames}", source="--max-frames")
    if start < 0:  # (named the sequence: "kitti_06_image_0: start frame -1 outside 0..50")
        raise ConfigError(f"must be >= 0, got {start}", source="--start")
    if gif and out is None:
        raise ConfigError("--gif needs --out DIR", source="--gif")
    if poses_format not in ("kitti", "tum"):
        raise ConfigError(f"unknown format {poses_format!r}; known: kitti, tum", source="--poses-format")
    if preset not in available_presets():  # (named the library's argument: "preset: unknown VO preset 'ORB'")
        raise ConfigError(f"unknown VO preset {preset!r}; known: {', '.join(available_presets())}", source="--preset")
    if not (math.isfinite(focal_factor) and focal_factor > 0):
        raise ConfigError(f"must be a finite number > 0, got {focal_factor}", source="--focal-factor")
    changes = {
        "features.detector": detector, "matching.method": matcher,
        "geometry.estimators": tuple(estimator) if estimator else None, "preprocess.method": preprocess,
        "features.max_features": features, "scale.mode": scale, "sanity.enabled": sanity, "geometry.refine": refine,
        "seed": seed,
    }
    settings = parse_params(set_ or [], option="--set")
    for key in settings:  # (the --set value replaced the option's silently)
        if changes.get(key) is not None:
            raise ConfigError(f"given twice, by {_OPTION_OF[key]} and by --set {key}=...: give it once", source=f"--set {key}")
    changes.update(settings)
    if matcher in ("bf_cross", "knn_ratio") and changes.get("features.detector") is None:
        # descriptor matching needs a detector with descriptors: the preset's own if it has them (report_sift keeps
        # SIFT), else ORB, said
        kept = make_preset(preset).features.detector
        if kept in ("gftt", "fast"):
            changes["features.detector"] = "orb"
            stderr().print(f"note: --matcher {matcher} needs descriptors, which {kept} has none of: detector orb "
                           "(--detector sift or akaze for another)", soft_wrap=True, markup=False)
    try:
        cfg = make_preset(preset, **{k: v for k, v in changes.items() if v is not None})
    except ConfigError as err:  # a setting given by its option names the option, not the config field ("vo config scale.mode")
        field = str(err.source or "").removeprefix("vo config").strip()
        option = next((o for f, o in _OPTION_OF.items() if (field == f or field.startswith(f + ".")) and f not in settings), None)
        if not field:  # the check across fields (descriptor matching needs descriptors): the options that set them
            given = {"matching.method": matcher, "features.detector": detector}
            option = " and ".join(f"--set {f}" if f in settings else _OPTION_OF[f] for f, value in given.items()
                                  if f in settings or value is not None) or None
        if option is None:
            raise
        raise ConfigError(err.reason, source=option) from None
    for key, why in inert_settings(cfg, settings):
        stderr().print(f"note: --set {key} not used: {why}", soft_wrap=True, markup=False)
    # (the library's names: "vo input kind: unknown input kind", "read it as kitti: poses_format='kitti'")
    with named_by_option({"vo input kind": "--kind"}):
        # (a --poses file in the other format advises the option, not the image folder's keyword)
        vo_input = open_vo_input(data, kind=kind, calib=calib, timestamps=timestamps, poses=poses,
                                 poses_format=poses_format, focal_factor=focal_factor,
                                 format_hint=lambda fmt: f"--poses-format {fmt}")
    _check_out_beside_images(out, vo_input.images)
    inputs = _files_read(data, vo_input, poses, poses_format, timestamps)  # (before --start/--max-frames wrap the images)
    numbers = getattr(vo_input.images, "frames", None)  # the input's own frame numbers (KITTI's file names), if any
    n_all = len(vo_input.images)
    # --start counts images; where the input's frame numbers are others (a KITTI folder from 000010.png) messages name
    # both ("--start 25: frame 25 is past the last frame 20" had counted images but read as frame numbers)
    renumbered = numbers is not None and not np.array_equal(numbers, np.arange(n_all))

    def image(index: int) -> str:
        return f"image index {index} (frame {int(numbers[index])})" if renumbered else f"frame {index}"

    if start >= n_all:  # (named the sequence only: "kitti_06_image_0: start frame 51 outside 0..50")
        raise ConfigError(f"image index {start} is past the last index {n_all - 1} of {data} (its {n_all} images are "
                          f"frames {int(numbers[0])}-{int(numbers[-1])}; --start counts images from 0)" if renumbered
                          else f"frame {start} is past the last frame {n_all - 1} of {data}", source="--start")
    # (cut without a word: 2 frames ran of --start 6 --max-frames 5, config.yaml recording the 5; odometry says it)
    last = f"image, index {n_all - 1} (frame {int(numbers[-1])})" if renumbered else f"frame ({n_all - 1})"
    frames_cut = (f"--max-frames {max_frames} from {image(start)} ends after the last {last}: ran {n_all - start}"
                  if max_frames is not None and start + max_frames > n_all else None)
    if frames_cut:
        stderr().print(f"warning: {frames_cut}", soft_wrap=True, markup=False)
    vo_input = frame_range(vo_input, start, max_frames)
    if cfg.scale.mode == "gt" and vo_input.ground_truth is None:  # (MonoVO refused it after --self-calibrate's 46 s)
        raise ConfigError(f"scale gt needs ground-truth poses and the input {data} has none: give --poses FILE or "
                          "--scale none|relative", source="--scale")
    if not vo_input.K_source.startswith("guess"):  # intrinsics known: the options that replace a guess do nothing
        unused = [name for name, given in (("--self-calibrate", self_calibrate), ("--focal-factor", focal_factor != DEFAULT_FOCAL_FACTOR))
                  if given]
        if unused:
            stderr().print(f"note: {' and '.join(unused)} not used: the intrinsics are known ({vo_input.K_source})", soft_wrap=True,
                           markup=False)
    from lidarkit.progress import progress_bar

    focal = None
    if self_calibrate:  # 15-45 s per 50 frames: progress as its windows are tracked and adjusted
        calib_bar: list = []  # (bar, task, steps shown), made at the first step, when the number of steps is known

        def on_step(done: int, total: int) -> None:
            if not progress:
                return
            if not calib_bar:
                calib_bar.extend([*progress_bar(total, "self-calibrating the focal length", unit="steps"), 0])
            if done > calib_bar[2]:
                calib_bar[0].advance(calib_bar[1], done - calib_bar[2])
                calib_bar[2] = done

        try:
            vo_input, focal = calibrate(vo_input, on_step=on_step, workers=None)  # (a worker a CPU: the command is guarded)
        finally:
            if calib_bar:
                calib_bar[0].stop()
    gt = vo_input.ground_truth  # (a guessed K is logged as a warning by open_vo_input)
    if len(vo_input.images) < 2:
        raise DataError(f"{len(vo_input.images)} frame from {image(start)} on: VO needs two frames or more (no frame pair)",
                        source=str(data))
    bar = progress_bar(len(vo_input.images), f"vo on {data}") if progress else None
    try:
        result = MonoVO(cfg, vo_input.K, gt if cfg.scale.mode == "gt" else None).run(
            vo_input.images, keep_tracks=gif, on_frame=None if bar is None else (lambda _j: bar[0].advance(bar[1])))
    finally:
        if bar is not None:
            bar[0].stop()
    if start or numbers is not None:  # the diagnostics name the input's frame numbers (the run counts from its first frame)
        import dataclasses

        def number(k: int) -> int:
            return int(numbers[start + k]) if numbers is not None else start + k

        result.diagnostics = [dataclasses.replace(d, frame=number(d.frame), ref_frame=number(d.ref_frame)) for d in result.diagnostics]
    extra_config = {**inputs, "kind": vo_input.kind, "K_source": vo_input.K_source, "start": start,
                    **({"start_frame": int(numbers[start])} if renumbered else {}),  # (--start is an image index)
                    "max_frames": max_frames, **({"frames_cut": frames_cut} if frames_cut else {})}
    if focal is not None:
        extra_config["self_calibration"] = {"focal_px": focal.focal_px, "sigma_px": focal.sigma_px if focal.constrained else None,
                                            "constrained": focal.constrained, "reason": focal.reason,
                                            "window_focals_px": list(focal.window_focals_px)}
    read_warnings = _read_warnings(vo_input)
    if read_warnings:  # (a pose file cut inside its last number scored APE 2.858 m, and the run folder said nothing)
        inputs = {**inputs, "warnings": read_warnings}
    if result.n_frames > 1 and result.accepted_pairs == 0:
        _fail_without_pairs(result, out, extra_config, str(data), inputs)
    if gt is not None and cfg.scale.mode != "gt":
        # into the GT's frame at the start frame (a later one when the first frames were unusable)
        result.trajectory = result.trajectory.transformed(T_left=gt.poses_se3[result.meta["start_frame"]])

    metrics, not_scored = _scores(result, gt, cfg.scale.mode)
    if "scored_from_frame" in metrics:  # (the input's own frame number)
        first = metrics["scored_from_frame"]
        metrics["scored_from_frame"] = int(numbers[start + first]) if numbers is not None else start + first
    if out is not None:  # the run folder before the table: a stdout that refuses it (> /dev/full) lost the whole run
        from lidarkit.vo.output import write_run

        paths = write_run(result, out, ground_truth=gt,
                          metrics={**metrics, **({"not_scored": not_scored} if not_scored else {}), **inputs},
                          extra_config=extra_config, gif_images=vo_input.images if gif else None,
                          frame_numbers=[int(numbers[start + k]) if numbers is not None else start + k
                                         for k in range(len(result.trajectory))])
    console = stdout()
    summary = result.summary()
    table = Table(title=f"lidarkit vo: {data} ({vo_input.kind}, {cfg.features.detector} + {cfg.matching.method}, "
                        f"scale {cfg.scale.mode})")
    table.add_column("quantity")
    table.add_column("value", justify="right")
    table.add_row("frames", str(summary["frames"]))
    table.add_row("accepted pairs", f"{summary['accepted_pairs']} of {summary['frames'] - 1}")
    table.add_row("rejected frames", str(summary["rejected"]))
    if summary["rejection_reasons"]:
        top = list(summary["rejection_reasons"].items())[:_TOP_REASONS]
        table.add_row("top rejection reasons", "; ".join(f"{kind} ({count})" for kind, count in top))
    if cfg.scale.mode == "relative":
        table.add_row("scale kept from the previous step", f"{summary['scale_kept_frames']} frames")
    table.add_row("frames/s (pipeline)", f"{summary['frames_per_s']:.1f}")
    table.add_row("intrinsics", vo_input.K_source)
    if focal is not None and not focal.constrained:
        table.add_row("self-calibration", f"not constrained: {focal.reason}")
    if metrics and not metrics["smoothed"]["smoothing"].startswith(f"window {cfg.smoothing.window},"):
        table.add_row("smoothing", metrics["smoothed"]["smoothing"])  # not the configured window: said
    if "scored_from_frame" in metrics:
        table.add_row("scored from frame", f"{metrics['scored_from_frame']} (the frames before it unreadable: not estimates)")
    for variant, m in ((v, metrics[v]) for v in ("raw", "smoothed") if v in metrics):
        table.add_row(f"APE {variant} ({alignment_label(m['align'])}) [m]", f"{m['ape_rmse_m']:.4f}")
        # (one rigid motion of every pose cancels in each relative pose; a Sim(3) alignment's scale does not)
        rpe_align = alignment_label(m["align"]) if m["align"] == "sim3" else "alignment-free"
        table.add_row(f"RPE {variant} 1 frame ({rpe_align}) [m / deg]",
                      f"{m['rpe_trans_rmse_m']:.4f} / {m['rpe_rot_rmse_deg']:.4f}")
        # (gt scale: the raw distance of the last positions, both trajectories starting together; else after alignment)
        final_align = "unaligned" if cfg.scale.mode == "gt" else alignment_label(m["align"])
        table.add_row(f"final error {variant} ({final_align}) [m]", f"{m['final_error_m']:.3f}")
    console.print(table)
    if not_scored:
        console.print(f"not scored against the ground truth: {not_scored}", soft_wrap=True, markup=False)
    for d in result.rejected[:_LISTED_REJECTIONS]:
        console.print(f"frame {d.frame} rejected: {d.reason}", soft_wrap=True)
    if len(result.rejected) > _LISTED_REJECTIONS:
        console.print(f"... and {len(result.rejected) - _LISTED_REJECTIONS} more rejected frames (see diagnostics.csv "
                      "with --out)")
    if out is not None:
        console.print(f"wrote {len(paths)} files to {out}")


def _files_read(data: Path, vo_input, poses: Optional[Path], poses_format: str, timestamps: Optional[Path]) -> dict:
    """What a run read, for config.yaml and metrics.json: ``input`` (resolved), the ground-truth ``poses`` and their
    ``poses_format``, the ``timestamps``; each a file given by its option, the dataset's own file or None (a run folder
    named neither the poses it was scored against nor the stamps it was written with)."""
    images = vo_input.images
    has_poses, has_stamps = vo_input.ground_truth is not None, images.timestamps_s is not None
    if vo_input.kind == "simcam":
        own = "the simulator's own"
        return {"input": str(data), "poses": own if has_poses else None, "poses_format": None,
                "timestamps": own if has_stamps else None}
    if vo_input.kind == "kitti":  # (the reader's paths: a relative --poses may have been found in the sequence folder)
        poses_file, stamps_file, read_as = images.odometry.poses_path, images.odometry.times_path, "kitti"
    elif vo_input.kind == "tum":
        poses_file, stamps_file, read_as = images.groundtruth_path, images.rgb_list_path, "tum"
    else:
        poses_file, stamps_file, read_as = poses, timestamps, poses_format

    def named(path: Path, given: Optional[Path]) -> str:
        return str(Path(path).resolve()) if given is not None else f"the dataset's own {Path(path).resolve()}"

    if not has_stamps:
        stamps = None
    elif stamps_file is None:  # an image folder stamped by its TUM poses
        stamps = f"the stamps of the poses {Path(poses).resolve()}"
    else:
        stamps = named(stamps_file, timestamps)
    return {"input": str(data.resolve()), "poses": named(poses_file, poses) if has_poses else None,
            "poses_format": read_as if has_poses else None, "timestamps": stamps}


def _read_warnings(vo_input) -> list[str]:
    """What the input's readers warned of (a file cut inside its last number: poses, time stamps, calib), once each: the
    reader's ``reader_warnings`` and the ground truth's ``meta["read_warnings"]``, for metrics.json's ``warnings``."""
    from lidarkit.io.base import read_warnings_of

    images = getattr(vo_input.images, "images", vo_input.images)  # (--start / --max-frames wrap the reader)
    return list(dict.fromkeys([*read_warnings_of(images, vo_input.ground_truth), *vo_input.read_warnings]))


def _check_out_beside_images(out: Optional[Path], images) -> None:
    """Refuse a run folder that is the folder of the input's images: the next run read its trajectory.png as a frame
    (a subfolder is not listed as images, so a run folder inside it is left alone)."""
    if out is None:
        return
    folders = {p.parent.resolve() for p in getattr(images, "image_paths", ())}
    if out.resolve() in folders:
        raise ConfigError(f"the run folder is the image folder {out.resolve()}: the next run would read its "
                          "trajectory.png as a frame; give another folder", source="--out")


def _scores(result, gt, scale_mode: str) -> tuple[dict, str | None]:
    """APE/RPE of the raw and smoothed estimate from the first estimated frame on
    (:func:`lidarkit.vo.evaluation.scored_from_frame`; ``({}, why)`` when they cannot be computed: a run's poses are
    written all the same)."""
    from lidarkit.errors import EvaluationError
    from lidarkit.vo.evaluation import evaluate_vo, scored_frames

    if gt is None:
        return {}, None
    first, tail, why = scored_frames(result, len(gt))
    if tail is None:
        return {}, why
    smoothed = result.smoothed()
    try:
        scores = {"raw": evaluate_vo(result.trajectory[tail], gt[tail], scale_mode),
                  "smoothed": {**evaluate_vo(smoothed[tail], gt[tail], scale_mode), "smoothing": smoothed.meta["smoothing"]}}
    except EvaluationError as err:  # (a ground truth on a straight line leaves the alignment undefined)
        return {}, err.reason
    if first:
        scores["scored_from_frame"] = first
    return scores, None


def _fail_without_pairs(result, out: Optional[Path], extra_config: dict, data: str, inputs: dict) -> None:
    """No frame pair accepted: write the run folder (diagnostics, and the files read, ``inputs``, in metrics.json)
    when asked, then raise one clear error naming the input ``data`` (not the run's internal trajectory name)."""
    from lidarkit.vo.pipeline import TrackingFailedError

    where = ""
    if out is not None:
        from lidarkit.vo.output import write_run

        write_run(result, out, metrics=inputs, extra_config=extra_config, plot=False)
        where = f"; per-frame reasons in {out / 'diagnostics.csv'}"
    try:
        result.check_tracking()
    except TrackingFailedError as err:
        raise TrackingFailedError(err.reason + where, source=data) from None
