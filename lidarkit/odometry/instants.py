"""Which instant of a sweep an estimate and its ground truth refer to, and the rule that scores like with like.

A deskewing variant moves every point to one instant of the sweep and reports the pose there: kiss-icp 1.x
deskews to the latest point, the sweep END (``Registration.deskew_instant``). A variant that does not deskew a
sweep measured while the sensor moved (per-point times spanning part of a sweep) fits the distorted clouds where
they agree on average, the sweep MIDDLE: measured in ``benchmarks/sweep_instant.py`` (small_gicp and open3d_gicp
on simulated streets, 20 of 20 runs: start and end 1.9-4.1x the RPE of mid, fitted instant 0.40-0.55 of the
sweep; kiss without deskew half a sweep before kiss deskewed to the end). Scans without a time span (a
snapshot, or no per-point times) are taken at the instant their stamp refers to (``Scan.stamp_instant``, as
the reader labels it). Ground truth states its instant in ``meta["pose_instant"]``. When both are known and
differ, the run re-times the ground truth to the estimate's instant when the dataset can give it
(``ground_truth_at_instant(instant)``: the simulator, bags, the simulator's KITTI folders) and says so in a note;
otherwise it refuses a deskewed estimate (EvaluationError) and compares a non-deskewed one as it is, with a note
(its instant is a measured tendency, not a rule the variant applies).
A run's poses are taken at the instant most of its frames' refer to (:func:`run_instant`): frames with per-point times
and frames without can refer to two instants, and one scan did not decide for the rest.
Ground truth of an unknown instant (None) is re-timed to the estimate's instant where the dataset can give it (a
bag whose poses are stamped at no clear instant of the sweep), else compared as it is: the reader could not tell (with
a note saying why when the dataset's re-timing failed).
"""

from __future__ import annotations

import inspect

from typing import Any

import numpy as np

from lidarkit.errors import EvaluationError, LidarKitError
from lidarkit.io.base import INSTANT_FRACTION, Scan, classify_instant, sweep_length
from lidarkit.trajectory import Trajectory


def deskews(registration: Any, scan: Scan | None) -> bool:
    """Whether ``registration`` moves the points of scans like ``scan`` to one instant of the sweep."""
    return (getattr(registration, "deskew_instant", None) is not None and scan is not None
            and scan.point_times_s is not None and len(scan.point_times_s) > 0)


def estimate_instant(registration: Any, scan: Scan | None) -> str | None:
    """The instant of the sweep the poses of ``registration`` over scans like ``scan`` refer to (None: unknown):
    the one it deskews to; the sweep middle for a sweep it does not deskew (see the module doc); else the stamp's."""
    if scan is None:
        return None
    if deskews(registration, scan):
        return str(registration.deskew_instant)
    if scan.has_time_span():
        return "mid"
    return scan.stamp_instant


def most_have_times(has_point_times: np.ndarray) -> bool:
    """Whether half of a run's frames or more came with per-point times (``has_point_times``: (n,) bool): their poses
    are the run's (deskewed, where the variant deskews)."""
    timed = np.asarray(has_point_times, dtype=bool)
    return bool(timed.any()) and 2 * int(np.count_nonzero(timed)) >= len(timed)


def run_instant(registration: Any, stamp_instant: str | None, has_point_times: np.ndarray) -> tuple[str | None, bool]:
    """``(instant, deskewed)`` of a run's poses: the instant of the sweep most of its frames' poses refer to
    (:func:`estimate_instant` of a frame with per-point times when half of them or more have some, else of one
    without: the scans' ``stamp_instant``), and whether that is the instant the variant deskews to.
    ``has_point_times``: (n,) bool, the frames whose per-point times span part of the sweep. (Decided by the first
    scan, 19 frames deskewed to the sweep end were scored at the middle, frame 0's stamp instant, for lack of frame
    0's times.)"""
    if most_have_times(has_point_times):
        deskewing = getattr(registration, "deskew_instant", None) is not None
        return (str(registration.deskew_instant) if deskewing else "mid"), deskewing
    return stamp_instant, False


def stamps_at_instant(stamps_s: np.ndarray | None, scan: Scan | None, instant: str | None,
                      all_stamps_s: np.ndarray | None = None, sweep_s: float | None = None,
                      sweep_offset_s: float | None = None) -> tuple[np.ndarray | None, str | None]:
    """``(the scans' stamps moved to the ``instant`` of their sweeps, note or None)``: the estimate's poses refer to
    ``instant`` (a deskewing variant's), its stamps to ``scan.stamp_instant``; stamped as they are, a pose written
    with its scan's stamp (``poses_tum.txt``) was paired with another instant's ground truth by anyone associating by
    time. The sweep lasts ``sweep_s`` where the dataset knows it (a bag's ``sweep_duration_s``), else the spacing of
    consecutive stamps of the whole sequence (``all_stamps_s``; not of a selection such as ``--frames 0:300:5``, which
    moved them by five sweeps) unless ``scan``, a whole sweep, spans clearly less or more (:func:`sweep_length`: a
    recording keeping every other sweep, 0.1 s of points stamped 0.2 s apart, was moved 0.2 s to the sweep end), else
    the point times' span. Stamps at no clear instant of their sweeps are moved where the dataset places the sweeps:
    ``sweep_offset_s`` after each stamp a sweep starts (a bag's ``sweep_offset_s``, e.g. -0.13 s for a driver stamping
    on receipt, 30 ms after the sweep end), lasting ``sweep_s``; without it they are kept as they are."""
    stamp_at = None if scan is None else scan.stamp_instant
    if stamps_s is not None and instant is not None and stamp_at is None and sweep_offset_s is not None and sweep_s:
        shift = float(sweep_offset_s) + INSTANT_FRACTION[instant] * float(sweep_s)
        side = "after" if sweep_offset_s <= 0 else "before"
        return (np.asarray(stamps_s, dtype=np.float64) + shift,
                f"stamped at the sweep {instant} (the scans' stamps, at no clear instant of the sweep, {abs(float(sweep_offset_s)):.4f} s "
                f"{side} its start by the point times, moved by {shift:+.4f} s)")
    if stamps_s is None or instant is None or stamp_at is None or instant == stamp_at:
        return stamps_s, None
    stamps_s = np.asarray(stamps_s, dtype=np.float64)
    consecutive = np.asarray(stamps_s if all_stamps_s is None else all_stamps_s, dtype=np.float64)
    span = _whole_sweep_span(scan)
    if sweep_s is not None and sweep_s > 0:
        duration = float(sweep_s)
    elif len(consecutive) > 1:
        duration = float(np.median(np.diff(consecutive)))
        duration = duration if span is None else sweep_length(span, duration)
    elif scan.point_time_convention != "fraction" and scan.has_time_span():
        duration = float(np.ptp(scan.point_times_s))
    else:
        return stamps_s, None
    shift = (INSTANT_FRACTION[instant] - INSTANT_FRACTION[stamp_at]) * duration
    return stamps_s + shift, f"stamped at the sweep {instant} (the scans' stamps, at the sweep {stamp_at}, moved by {shift:+.4f} s)"


def _whole_sweep_span(scan: Scan) -> float | None:
    """The seconds ``scan``'s points span when they are a whole sweep: their own times place its stamp at the instant
    it is said to be stamped at (a recording's first message, part of a sweep, is not; the reader says the
    recording's instant); None without point times in seconds."""
    if scan.point_time_convention == "fraction" or not scan.has_time_span() or scan.timestamp_s is None:
        return None
    times = np.asarray(scan.point_times_s, dtype=np.float64)
    lo, hi = float(times.min()), float(times.max())
    stamp = scan.timestamp_s if scan.point_time_convention == "absolute_s" else 0.0
    return hi - lo if classify_instant((stamp - lo) / (hi - lo)) == scan.stamp_instant else None


def like_with_like(reference: Trajectory, estimate_at: str | None, *, sequence: Any, own_ground_truth: bool,
                   method: str, deskewed: bool = True, frames: np.ndarray | None = None) -> tuple[Trajectory, str | None]:
    """``(reference at the estimate's instant, note or None)``; when it cannot be re-timed, EvaluationError for a
    deskewed estimate, the reference as it is with a note for one that is not. ``deskewed``: the estimate's instant is
    the one the variant deskews to (else the sweep middle or the scans' stamp instant, see :func:`estimate_instant`)."""
    truth_at = reference.meta.get("pose_instant") if reference.meta else None
    if estimate_at is None or estimate_at == truth_at:
        return reference, None
    retime = getattr(sequence, "ground_truth_at_instant", None)
    why_not = ""
    if own_ground_truth and callable(retime):
        try:
            # the selected frames only, where the reader can (a recording re-timed whole failed on scans not selected)
            takes_frames = frames is not None and "scans" in inspect.signature(retime).parameters
            retimed = retime(estimate_at, scans=frames) if takes_frames else retime(estimate_at)
        except LidarKitError as err:  # the dataset cannot give it (e.g. a recording that does not reach): refused below
            why_not = f"; re-timing it failed: {err.reason}"
        else:
            how = (retimed.meta or {}).get("retimed")
            # (poses stamped at no clear instant, 13 ms into each sweep: scored as they were, 0.41 m where 0.61 is right)
            origin = f"the sweep {truth_at}" if truth_at is not None else "stamps at no clear instant of the sweep"
            note = (f"ground truth re-timed from {origin} to the sweep {estimate_at}" + (f" ({how})" if how else "")
                    + f": {method}'s poses refer to the sweep {estimate_at}")
            return retimed, note
    if truth_at is None:  # the reader could not tell, nor give another instant: compared as it is
        # (re-timing that failed said nothing: one odometry message logged out of order, RPE 0.0165 m for 0.0079 m; a
        # KITTI-layout folder's poses, stamped at the sweep ends by times.txt, are at an instant it does not state, not
        # at "no clear instant": the runner's warning on such poses says it so)
        return reference, (f"ground truth stamped at an instant of the sweep the reader does not state: compared as it is "
                           f"with {method}'s poses of the sweep {estimate_at}{why_not}") if why_not else None
    if not deskewed:  # (a measured tendency of scan matching: no reason to refuse the run)
        held = ("which this dataset cannot re-time" + why_not if own_ground_truth else
                f"given with the run (not re-timed: give it at the sweep {estimate_at} to score like with like)")
        return reference, (f"{method}'s poses of sweeps it does not deskew refer to about the sweep {estimate_at} "
                           f"(benchmarks/sweep_instant.py), the ground truth to the sweep {truth_at}, {held}: compared as "
                           "it is (the motion between the two instants counts as error)")
    raise EvaluationError(
        f"{method}'s poses refer to the sweep {estimate_at} but the ground truth to the sweep {truth_at}; comparing them "
        f"would score the motion within a sweep as error{why_not}. Give ground truth at the sweep {estimate_at} (or run "
        "without deskewing)",
        source=reference.name or "ground truth",
    )


__all__ = ["deskews", "estimate_instant", "like_with_like", "most_have_times", "run_instant", "stamps_at_instant"]
