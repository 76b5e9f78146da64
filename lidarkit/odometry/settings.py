"""What a run really applied, as opposed to what was asked for: deskew and why, the instants compared, the
reader's settings (e.g. a KITTI correction) and the alignment of every metric.

``config.yaml`` keeps the requested method config (``deskew: true``); these settings say whether it happened.
"""

from __future__ import annotations

import os
from collections.abc import Collection
from pathlib import Path
from typing import Any

import numpy as np

from lidarkit.errors import DataError
from lidarkit.odometry.instants import most_have_times, run_instant

#: Alignment of every score in metrics.json, the CLI table and the bench tables.
METRIC_ALIGNMENT = {
    "ape_translation_m": "unaligned, first pose anchored",
    "ape_translation_se3_m": "SE(3)-aligned",
    "rpe_translation_m": "relative over 1 frame, alignment-free",
    "rpe_rotation_deg": "relative over 1 frame, alignment-free",
    "final_error": "unaligned, first pose anchored",
    "kitti_drift": "KITTI devkit segments, alignment-free",
}
#: the RPE's step where the run's frames skip dataset frames (``--frames 1:10:3``): one selected frame, not one frame
SELECTED_FRAME = "relative over 1 selected frame, alignment-free"


def skips_frames(frames: np.ndarray | None) -> bool:
    """Whether a run over dataset ``frames`` skips some: its 1-frame RPE is then over one selected frame."""
    return frames is not None and not np.all(np.diff(frames) == 1)


def metric_alignment(frames: np.ndarray | None = None) -> dict[str, str]:
    """:data:`METRIC_ALIGNMENT` of a run over dataset ``frames``: a selection that skips frames has its RPE over one
    selected frame (``--frames 1:10:3``, an RPE over 3 KITTI frames, was labelled "over 1 frame")."""
    if not skips_frames(frames):
        return dict(METRIC_ALIGNMENT)
    return {**METRIC_ALIGNMENT, "rpe_translation_m": SELECTED_FRAME, "rpe_rotation_deg": SELECTED_FRAME}


def deskew_requested(registration: Any) -> bool | None:
    """True/False when the variant's config has a ``deskew`` switch, None when the variant does not deskew at all."""
    config = getattr(registration, "config", None)
    value = getattr(config, "deskew", None) if config is not None else None
    if value is None:
        return None
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    # a component spec (pipeline's "none" or {name: constant_velocity, deskew: false}) is always truthy: whether the
    # variant deskews is whether it names an instant to deskew to (it read "requested" with deskew off)
    return getattr(registration, "deskew_instant", None) is not None


#: sweeps between frames within this of 1 count as consecutive (jittered stamps): their deskew is left as it was
SWEEPS_APART_TOLERANCE = 0.25
#: the share of a dataset's intervals that must lie within SWEEPS_APART_TOLERANCE of a whole number of its typical one
#: for its stamps to count sweeps: a sensor's sweeps come at one period (KITTI, bags, the simulator: all of them); the
#: CARMEN logs' delivery stamps do not (Intel 28 %, ratios from 0.0013 to 20; ACES 50 %)
REGULAR_SHARE = 0.9


def sweeps_apart(stamps_s: np.ndarray | None, numbers: np.ndarray | None, indices: np.ndarray, n_total: int) -> np.ndarray:
    """``(n,)`` float64 sweeps between each selected frame and the previous one (1 for the first): the pair's time
    interval over the dataset's typical one (its stamps; else its frame numbers, else its indices), 1 where within
    :data:`SWEEPS_APART_TOLERANCE` of 1. A deskew that takes the motion between frames as one sweep's needs it
    (``--frames 0:60:3`` deskewed with three sweeps' motion: 0.26 m RPE against 0.10 m without deskew), and so does
    the constant-velocity guess across dropped scans. Only stamps that count sweeps do: an interval that is not
    about a whole number of sweeps, or a dataset where fewer than :data:`REGULAR_SHARE` of them are (delivery stamps:
    Intel's CARMEN log scaled a 5 cm motion to 40 m), gives 1."""
    from lidarkit.odometry.inputs import typical_interval

    values = np.arange(n_total, dtype=np.float64) if numbers is None else np.asarray(numbers, dtype=np.float64)
    if stamps_s is not None and len(stamps_s) == n_total and (typical_interval(stamps_s) or 0.0) > 0:
        values = np.asarray(stamps_s, dtype=np.float64)
    typical = typical_interval(values)
    out = np.ones(len(indices))
    if len(indices) < 2 or not typical or np.mean(_whole_sweeps(np.diff(values) / typical)) < REGULAR_SHARE:
        return out
    out[1:] = np.diff(values[indices]) / typical
    out[~_whole_sweeps(out) | (np.abs(out - 1.0) <= SWEEPS_APART_TOLERANCE)] = 1.0
    return out


def _whole_sweeps(ratios: np.ndarray) -> np.ndarray:
    """Which interval ratios lie within :data:`SWEEPS_APART_TOLERANCE` of a whole number of sweeps (1 or more)."""
    return (ratios >= 1.0 - SWEEPS_APART_TOLERANCE) & (np.abs(ratios - np.round(ratios)) <= SWEEPS_APART_TOLERANCE)


def point_time_source(sequence: Any) -> str:
    """Where the reader takes per-point times from, in words (the folder for a KITTI layout)."""
    folder = getattr(sequence, "point_times_dir", None)
    if folder is not None:
        return f"{Path(folder).name}/ ({folder})"
    if type(sequence).__name__ == "SimulatedLidarSequence":
        return "the simulator (column firing times)"
    return f"the {type(sequence).__name__} reader"


def point_times_not_found(sequence: Any) -> str:
    """Why a reader gave no per-point times: for a KITTI layout, the folder names it looked for; for a bag, the clouds'
    fields and the option naming the time field (a Livox ``offset_time`` read as no times said "gives none")."""
    from lidarkit.io.kitti import POINT_TIME_FOLDERS

    if hasattr(sequence, "point_times_dir") and getattr(sequence, "sequence_dir", None) is not None:
        if sequence.point_times_dir is None:
            names = ", ".join(f"{d}/" for d in POINT_TIME_FOLDERS)
            return f"no per-point times found (looked for {names} {_point_time_search(sequence)})"
        return f"no per-point times found for some frames in {sequence.point_times_dir}"
    from lidarkit.io.pointcloud2 import TIME_FIELDS

    reader = type(sequence).__name__
    unread = getattr(sequence, "unread_point_times", None)  # (a folder: read as "ScanFolder gives none")
    if unread:
        field, first, generic_reads = unread
        skipped = getattr(sequence, "unread_point_time_type", None)  # a PLY property type Open3D skips (uint, ...)
        other = (f"a PLY {skipped} property, which Open3D cannot read, so generic:PATH does not either: store the times "
                 "as float, double or int" if skipped
                 else f"generic:{sequence.path} reads them" if generic_reads
                 else "generic:PATH, which does, refuses these files (repeated _ padding fields)")
        return (f"no per-point times read (folder: does not read per-point times; its scans carry them in the {field!r} "
                f"field, e.g. {Path(first).name}; {other})")
    if reader == "SimulatedLidarSequence" and getattr(getattr(sequence, "config", None), "point_times", True) is False:
        return f"no per-point times found ({reader}: point_times=false attaches none)"
    fields = getattr(sequence, "cloud_fields", None)
    option = getattr(sequence, "time_field", None)
    if fields and option in ("", "none"):
        return f"no per-point times found ({reader}: time_field={option or 'none'} reads none)"
    if fields and option == "auto" and not set(fields) & set(TIME_FIELDS):
        timelike = [f for f in fields if "time" in f.lower() or "stamp" in f.lower()]
        example = f", e.g. time_field={timelike[0]}" if timelike else ""
        return (f"no per-point times found ({reader}: no time field among the clouds' fields {', '.join(fields)}; "
                f"time_field=auto reads one named {', '.join(TIME_FIELDS[:-1])} or {TIME_FIELDS[-1]}, time_field=NAME "
                f"reads another{example})")
    return f"no per-point times found ({reader} gives none)"


def _point_time_search(sequence: Any) -> str:
    """Where a KITTI-layout reader looked for per-point time folders, in words: beside the scans' folder, then in
    the sequence folder when that is another (a velodyne_dir elsewhere was said to be searched "beside velodyne/")."""
    velodyne = Path(os.path.abspath(getattr(sequence, "velodyne_dir", None) or Path(sequence.sequence_dir) / "velodyne"))
    searched = getattr(sequence, "point_time_search_dirs", None) or (velodyne.parent,)
    later = "".join(f", then in {folder}" for folder in searched[1:])
    return f"beside {velodyne.name}/ in {searched[0]}{later}"


def frames_named(numbers: np.ndarray, shown: int = 5) -> str:
    """``frame 5`` / ``frames 5, 9`` / ``frames 1, 2, 3, 4, 5 and 7 more``: the first ``shown`` frame numbers."""
    listed = ", ".join(str(int(k)) for k in numbers[:shown])
    more = f" and {len(numbers) - shown} more" if len(numbers) > shown else ""
    return f"frame{'s' if len(numbers) > 1 else ''} {listed}{more}"


#: why a snapshot's missing per-point times are no fault: every point was taken at one instant
SNAPSHOT_SWEEPS = "snapshot sweeps (motion_distortion false): nothing to deskew"


def snapshot_sweeps(sequence: Any) -> bool:
    """Whether the reader says each sweep is one snapshot (the simulator's ``motion_distortion=false``, in a ``sim:``
    spec or the ``sim.yaml`` of its KITTI-layout export): a deskew has nothing to do, rather than no times to do it with."""
    return getattr(sequence, "snapshot_sweeps", False) is True


def require_point_times(scan: Any, sequence: Any, dataset_name: str, frame: int, flat: Collection[int] = ()) -> None:
    """``--strict`` with deskew requested: a scan without per-point times is an error naming the frame (``flat``: the
    frames whose times the reading dropped as all equal, which were there); a snapshot sweep has nothing to deskew."""
    if scan.point_times_s is None and not snapshot_sweeps(sequence):
        why = ("its per-point times are all equal (nothing to deskew with)" if frame in flat
               else point_times_not_found(sequence))
        # named by the scan's file where the reader gives it, as a frame's other errors are (the folder named no file)
        raise DataError(f"deskew requested, {why}", source=getattr(scan, "source", None) or dataset_name,
                        location=f"frame {frame}")


def reader_settings(sequence: Any) -> dict[str, Any]:
    """The reader's public scalar settings as applied (paths, options, corrections), JSON-ready: its attributes,
    then what it reports itself in ``reader_options`` (e.g. a KITTI correction and whether it was applied)."""
    out: dict[str, Any] = {"reader": type(sequence).__name__}
    items = list(sorted(vars(sequence).items())) if hasattr(sequence, "__dict__") else []
    reported = getattr(sequence, "reader_options", None)
    items += list(reported.items()) if isinstance(reported, dict) else []
    for key, value in items:
        if key.startswith("_"):
            continue
        if isinstance(value, (str, int, float, bool)) or value is None:
            out[key] = value
        elif isinstance(value, os.PathLike):  # absolute (a run folder is read from anywhere), and said when absent
            path = Path(value).absolute()
            out[key] = str(path) if path.exists() else f"{path} (absent)"
        elif isinstance(value, np.generic):
            out[key] = value.item()
    return out


def corrections(reader: dict[str, Any]) -> dict[str, Any]:
    """Reader settings that correct the data (e.g. a KITTI vertical-angle correction), by name."""
    return {k: v for k, v in reader.items() if "correct" in k.lower() or "angle" in k.lower()}


def ground_truth_instant(sequence: Any, reference: Any) -> str:
    """The instant of each sweep the ground truth refers to, as the reader states it."""
    meta = getattr(reference, "meta", None) or {}
    for key in ("pose_instant", "instant"):
        if meta.get(key):
            return str(meta[key])
    for owner in (sequence, getattr(sequence, "config", None)):
        for key in ("pose_instant", "ground_truth_instant"):
            value = getattr(owner, key, None) if owner is not None else None
            if isinstance(value, str) and value:
                return value
    return "not stated by the reader"


def _mixed_instants(registration: Any, stamp_instant: str | None, has_point_times: np.ndarray,
                    frames: np.ndarray | None) -> str | None:
    """A note when a run's frames with per-point times and those without refer to two instants of the sweep, naming
    the one all are scored at (:func:`~lidarkit.odometry.instants.run_instant`: most frames'), or None."""
    timed = np.asarray(has_point_times, dtype=bool)
    n, n_timed = len(timed), int(np.count_nonzero(timed))
    deskew_to = getattr(registration, "deskew_instant", None)
    timed_at = "mid" if deskew_to is None else str(deskew_to)
    if not 0 < n_timed < n or timed_at == stamp_instant:
        return None
    at, _ = run_instant(registration, stamp_instant, timed)
    numbers = np.asarray(frames if frames is not None and len(frames) == n else np.arange(n))
    fewer = ~timed if most_have_times(timed) else timed
    timed_as = f"deskewed to the sweep {timed_at}" if deskew_to is not None else f"not deskewed: about the sweep {timed_at}"
    untimed_as = f"the sweep {stamp_instant}, their stamps'" if stamp_instant else "their stamps' instant, not stated"
    return (f"the poses of frames with per-point times ({n_timed} of {n}: {timed_as}) and without ({n - n_timed}: "
            f"{untimed_as}) refer to different instants of the sweep: all are scored at "
            f"{f'the sweep {at}' if at else 'the stamps'}, as most frames' (for {frames_named(numbers[fewer])} the motion "
            "between the two instants counts as error)")


def effective_settings(
    sequence: Any, registration: Any, method: str, stateful: bool, has_point_times: np.ndarray, reference: Any,
    stamp_instant: str | None = None, n_flat_times: int = 0, frames: np.ndarray | None = None,
    sweeps_apart: np.ndarray | None = None,
) -> tuple[dict[str, Any], list[str]]:
    """(settings really applied, warnings) of a finished run; ``has_point_times`` (n,) bool per processed frame;
    ``stamp_instant``: the instant of the sweep the scans' stamps refer to (what an estimate over snapshots refers to);
    ``n_flat_times``: frames whose per-point times were all equal (read as frames without per-point times);
    ``sweeps_apart``: (n,) sweeps since the previous frame (:func:`sweeps_apart`)."""
    warnings: list[str] = []
    requested = deskew_requested(registration)
    n, n_times = len(has_point_times), int(np.count_nonzero(has_point_times))
    missing = point_times_not_found(sequence)
    if n_flat_times:
        missing = f"the per-point times of {n_flat_times} of {n} frames are all equal (nothing to deskew with)"
    if 0 < n_times < n:  # some frames had times: the reader's word for none at all ("RosbagScans gives none") was wrong
        numbers = np.asarray(frames if frames is not None and len(frames) == n else np.arange(n))
        lacking = frames_named(numbers[~np.asarray(has_point_times, dtype=bool)])
        if n_flat_times == n - n_times:
            missing = f"the per-point times of {lacking} are all equal (nothing to deskew with)"
        else:
            flat = f" ({n_flat_times} of them had all-equal ones: nothing to deskew with)" if n_flat_times else ""
            folder = getattr(sequence, "point_times_dir", None)  # (a KITTI layout's: where those frames' files are missing)
            missing = f"{lacking} had no per-point times{'' if folder is None else f' in {folder}'}{flat}"
    deskew: dict[str, Any] = {"requested": requested, "applied": False, "frames_with_point_times": n_times, "n_frames": n}
    if requested is None:
        deskew["reason"] = f"{method} does not deskew (no deskew option)"
    elif not requested:
        deskew["reason"] = "deskew off in the method config"
    elif not stateful and not getattr(registration, "accepts_point_times", False):
        deskew["reason"] = f"{method} runs scan-to-scan through align(), which takes no per-point times"
        warnings.append(f"deskew requested, not applied: {deskew['reason']}")
    elif n_times == 0 and snapshot_sweeps(sequence):  # (it warned "no per-point times found", as if data were missing)
        deskew["reason"] = SNAPSHOT_SWEEPS
        deskew["needed"] = False
    elif n_times == 0:
        deskew["reason"] = missing
        warnings.append(f"deskew requested, {deskew['reason']}: ran without deskew")
    else:
        # applied when most frames were: their poses are the run's (one frame of 20 with times read "deskew on" and
        # had the run scored at the sweep end, where 19 were not deskewed)
        deskew["applied"] = most_have_times(has_point_times)
        if deskew["applied"]:
            deskew["reason"] = f"per-point times from {point_time_source(sequence)}" + (f" for {n_times} of {n} frames" if n_times < n else "")
        else:
            deskew["reason"] = f"most frames ran without deskew: {missing} (deskewed: {n_times} of {n} frames)"
        if n_times < n:
            warnings.append(f"deskew applied to {n_times} of {n} frames only: {missing}")
        apart = np.asarray(sweeps_apart if sweeps_apart is not None else [], dtype=np.float64)[1:]
        skipped = apart[apart != 1.0]
        if skipped.size:  # a stepped selection or dropped scans: the motion between frames spans several sweeps
            low, high = f"{skipped.min():.3g}", f"{skipped.max():.3g}"
            span = low if low == high else f"{low} to {high}"
            what = f"{skipped.size} of {n - 1} frames {span} sweeps apart"
            if getattr(registration, "accepts_sweeps_apart", False):
                deskew["motion"] = f"the motion between frames scaled to one sweep ({what})"
            else:
                deskew["motion"] = f"the motion between frames taken as one sweep's ({what})"
                warnings.append(f"{what} were deskewed with {span} sweeps' motion ({method} takes no sweeps_apart): "
                                "the deskew is that many times too large; run consecutive frames, or deskew=false")
    if deskew["applied"]:
        stated = getattr(registration, "deskew_instant", None)
        estimate_instant = str(stated) if stated else "end" if method == "kiss" else "the instant the variant deskews to (not stated)"
    elif most_have_times(has_point_times):  # (as run_instant in instants.py decides it)
        estimate_instant = "mid (sweeps not deskewed: a fit of distorted sweeps lands about mid-sweep, benchmarks/sweep_instant.py)"
    elif stamp_instant is not None:
        estimate_instant = f"{stamp_instant} (the scans' stamps: each scan taken as one snapshot)"
    else:
        estimate_instant = "none: each scan taken as one snapshot"
    mixed = _mixed_instants(registration, stamp_instant, has_point_times, frames)
    if mixed:
        warnings.append(mixed)
    gt_instant = None if reference is None else ground_truth_instant(sequence, reference)
    if deskew["applied"] and gt_instant in ("start", "mid") and estimate_instant == "end":
        warnings.append(
            f"the estimate refers to the sweep end (kiss-icp deskews to the last point) but the ground truth to the sweep {gt_instant}"
        )
    reader = reader_settings(sequence)
    settings = {
        "deskew": deskew,
        "estimate_instant": estimate_instant,
        "ground_truth_instant": gt_instant,
        "reader": reader,
        "corrections": corrections(reader),
        "metric_alignment": metric_alignment(frames),
    }
    return settings, warnings
