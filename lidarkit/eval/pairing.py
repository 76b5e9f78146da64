"""Pair a reference and an estimate pose by pose: equal length (frame-aligned) or associated by timestamps (evo)."""

from __future__ import annotations

import logging
import math
from typing import Any

import numpy as np

from lidarkit.errors import ConfigError, EvaluationError
from lidarkit.params import is_real_number
from lidarkit.trajectory import Trajectory

logger = logging.getLogger(__name__)

SPACING_RATIO = 5.0  # median stamp spacings further apart than this factor: other clocks or units, not an offset


def check_flags(**flags: Any) -> None:
    """ConfigError for a switch that is not True or False (``all_pairs="no"``, a true string, scored every pair)."""
    for name, value in flags.items():
        if not isinstance(value, (bool, np.bool_)):
            raise ConfigError(f"{name} must be True or False, got {value!r}", source=name)


def pair_name(ref: Trajectory, est: Trajectory) -> str:
    """``"est vs ref"`` label used as the source of evaluation errors."""
    return f"{getattr(est, 'name', '') or 'estimate'} vs {getattr(ref, 'name', '') or 'reference'}"


def paired(
    ref: Trajectory, est: Trajectory, *, associate: bool = False, max_diff_s: float = 0.01
) -> tuple[Trajectory, Trajectory]:
    """Return ``(ref, est)`` with one pose each per comparison.

    Without ``associate`` both must already have the same number of poses (pose i of one is pose i of the
    other). With ``associate`` both need timestamps and are matched by nearest timestamp within
    ``max_diff_s`` seconds (``evo.core.sync.associate_trajectories``); unmatched poses are dropped.
    """
    if not isinstance(ref, Trajectory) or not isinstance(est, Trajectory):
        raise EvaluationError("reference and estimate must be lidarkit Trajectory objects", source="evaluation")
    check_flags(associate=associate)  # ("no" is a true string: it associated)
    source = pair_name(ref, est)
    if not associate:
        if len(ref) != len(est):
            hint = (
                "; both have timestamps: pass associate=True (--associate) to match them by time"
                if ref.timestamps_s is not None and est.timestamps_s is not None
                else ""
            )
            raise EvaluationError(
                f"trajectories differ in length ({len(ref)} reference vs {len(est)} estimated poses){hint}",
                source=source,
            )
        if len(ref) == 0:
            raise EvaluationError("trajectories are empty", source=source)
        return ref, est
    if ref.timestamps_s is None or est.timestamps_s is None:
        missing = "reference" if ref.timestamps_s is None else "estimate"
        raise EvaluationError(f"cannot associate by time: the {missing} has no timestamps (a KITTI pose file has none: "
                              "give its times.txt, --ref-times / --est-times, or a TUM file)", source=source)
    check_max_diff(max_diff_s)
    from evo import EvoException
    from evo.core import sync

    if len(ref) == 0 or len(est) == 0:
        raise EvaluationError(f"the {'reference' if len(ref) == 0 else 'estimate'} has no poses to associate", source=source)
    ref_in, est_in = ref.to_evo(), est.to_evo()
    try:
        ref_evo, est_evo = sync.associate_trajectories(ref_in, est_in, max_diff=float(max_diff_s))
    except EvoException as err:  # (evo's only one: no match; in its words, "between first trajectory and second ...")
        raise EvaluationError(
            f"timestamp association failed: no pose has a partner within {max_diff_s:g} s (reference spans "
            f"{_span(ref)}, estimate spans {_span(est)}): are both stamped by the same clock?", source=source) from err
    ref_out, est_out = _matched(ref_evo, est_evo, ref.name), _matched(est_evo, ref_evo, est.name)
    logger.info("associated %d of %d/%d poses (max diff %.3g s)", len(ref_out), len(ref), len(est), max_diff_s)
    if few := association_warning(ref, est, ref_out, max_diff_s):
        logger.warning("%s: %s", source, few)
    return ref_out, est_out


def check_max_diff(max_diff_s: Any) -> None:
    """A setting, not the pair's fault: ConfigError naming ``max_diff_s`` unless a finite number of seconds > 0."""
    if not (is_real_number(max_diff_s) and math.isfinite(max_diff_s) and max_diff_s > 0):
        raise ConfigError(f"max_diff_s must be a finite number of seconds > 0, got {max_diff_s!r}", source="max_diff_s")


def association_warning(ref: Trajectory, est: Trajectory, ref_paired: Trajectory, max_diff_s: float) -> str:
    """Why scores over the time-associated poses (``ref_paired``, the reference's side) cover little of the trajectories
    ("" when they cover most): fewer pairs than half the sparser one's poses, or pairs spanning less than half of either
    one's time (454 of 4541 reference poses, or 96 pairs of frame numbers read as seconds, were scored with only the
    table's title saying so). A reference denser than the estimate (TUM RGB-D: 100 Hz vs 30 Hz) covers it all."""
    def duration(traj: Trajectory) -> float:
        return float(traj.timestamps_s[-1] - traj.timestamps_s[0])

    n_pairs, spanned = len(ref_paired), duration(ref_paired)
    if n_pairs >= 0.5 * min(len(ref), len(est)) and spanned >= 0.5 * max(duration(ref), duration(est)):
        return ""
    return (f"only {n_pairs} pose pairs associated within {max_diff_s:g} s (over {_span(ref_paired)}), of {len(ref)} reference "
            f"poses over {_span(ref)} and {len(est)} estimated poses over {_span(est)}: the scores cover those only")


def stamps_disagree(ref: Trajectory, est: Trajectory, max_diff_s: float) -> str:
    """Why pairing two equally long trajectories pose by pose compares poses of other times ("" when it does not):
    both have stamps and some pose's differ by more than ``max_diff_s`` (a TUM estimate that starts a second later
    than its reference was scored pose by pose without a word, where evo associates TUM files by time). Where few
    stamps have a partner within ``max_diff_s``, the advice names a window that takes in the largest gap (stamps
    0.02 s apart were told to --associate, which then found no partner within 0.01 s)."""
    if ref.timestamps_s is None or est.timestamps_s is None or len(ref) != len(est) or len(ref) == 0:
        return ""
    ref_stamps, est_stamps = (np.asarray(t.timestamps_s, dtype=np.float64) for t in (ref, est))
    offset = est_stamps - ref_stamps
    k = int(np.argmax(np.abs(offset)))
    gap = abs(float(offset[k]))
    if not gap > max_diff_s:
        return ""
    said = (f"poses paired by index, but their stamps differ by up to {gap:.6g} s (pose {k}: reference {ref_stamps[k]:.6f} s, "
            f"estimate {est_stamps[k]:.6f} s; more than {max_diff_s:g} s)")
    # stamps 0, 1, 2 (frame numbers) against seconds: associating by time then paired 96 poses of 4541, misaligned
    step_ref, step_est = (float(np.median(np.diff(stamps))) for stamps in (ref_stamps, est_stamps))
    if step_ref > 0 and step_est > 0 and not 1 / SPACING_RATIO <= step_est / step_ref <= SPACING_RATIO:
        return (f"{said}, and the estimate's stamps step by {step_est:.4g} s against the reference's {step_ref:.4g} s "
                "(median): the two clocks or units differ (frame numbers against seconds?); pairing by index, as here, is "
                "right when pose i of each is the same frame; --associate would pair the wrong poses")
    # the estimate's stamps within the reference's time (those an association can pair): have they a partner?
    overlapping = (est_stamps >= ref_stamps[0] - max_diff_s) & (est_stamps <= ref_stamps[-1] + max_diff_s)
    partnered = _nearest_gaps(est_stamps[overlapping], ref_stamps) <= max_diff_s
    if partnered.size and partnered.mean() >= 0.9:  # (an estimate that starts later: the same stamps, other indices)
        return f"{said}: --associate (associate=True) pairs them by time"
    window = _window_above(gap)
    how = f"--associate --max-diff {window:g} (associate=True, max_diff_s={window:g}) pairs them by time"
    if np.ptp(offset) <= max_diff_s:
        return (f"{said}; the offset is a constant {float(np.mean(offset)):+.6g} s: if pose i of each is the same frame "
                "(clocks that far apart), pairing by index, as here, already pairs them right"
                + (f"; if not, {how}" if partnered.size else ""))
    if not partnered.size:
        return (f"{said}, and the two do not overlap in time (reference {_span(ref)}, estimate {_span(est)}): --associate "
                "pairs poses of the same time only")
    return f"{said}: {how} (within {max_diff_s:g} s it pairs too few)"


def _nearest_gaps(stamps: np.ndarray, others: np.ndarray) -> np.ndarray:
    """``(N,)`` time (s) from each of ``stamps`` to the nearest of the increasing ``others``."""
    after = np.clip(np.searchsorted(others, stamps), 1, len(others) - 1) if len(others) > 1 else np.zeros(len(stamps), int)
    before = np.maximum(after - 1, 0)
    return np.minimum(np.abs(stamps - others[before]), np.abs(stamps - others[after]))


def _window_above(gap_s: float) -> float:
    """A round time window just above ``gap_s`` (0.02 -> 0.03, 0.25 -> 0.3): one that takes in the largest gap."""
    step = 10.0 ** math.floor(math.log10(gap_s))
    return round((math.floor(gap_s / step * (1 + 1e-9)) + 1) * step, 12)


def _span(traj: Trajectory) -> str:
    """``"first..last s"`` of a trajectory's timestamps."""
    return f"{float(traj.timestamps_s[0]):.3f}..{float(traj.timestamps_s[-1]):.3f} s"


def _matched(traj, partner, name: str) -> Trajectory:
    """One side of evo's association as a Trajectory. A window wider than half a pose interval can match one pose to
    two of the other side (evo scores both pairs, and so does lidarkit): that side then takes its partner's stamps,
    which are distinct and within ``max_diff_s`` of its own."""
    stamps = np.asarray(traj.timestamps, dtype=np.float64)
    if len(stamps) > 1 and not (np.diff(stamps) > 0).all():
        logger.info("%s: %d poses matched more than once", name, int((np.diff(stamps) <= 0).sum()))
        stamps = np.asarray(partner.timestamps, dtype=np.float64)
    return Trajectory(np.array(traj.poses_se3, dtype=np.float64), stamps, name)
