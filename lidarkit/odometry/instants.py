"""Which instant of a sweep an estimate and its ground truth refer to, and the rule that scores like with like.

A deskewing variant moves every point to one instant of the sweep and reports the pose there: kiss-icp 1.x
deskews to the latest point, the sweep END (``Registration.deskew_instant``). Without per-point times (or
without deskewing) the pose refers to the instant the scan's stamp refers to (``Scan.stamp_instant``, as the
reader labels it). Ground truth states its instant in ``meta["pose_instant"]``. When both are known and differ,
the run re-times the ground truth to the estimate's instant when the dataset can give it
(``ground_truth_at(instant)``, the simulator) and says so in a note; otherwise it refuses (EvaluationError).
Unknown instants (None) are compared as they are: the reader could not tell.
"""

from __future__ import annotations

from typing import Any

from lidarkit.errors import EvaluationError
from lidarkit.io.base import Scan
from lidarkit.trajectory import Trajectory


def estimate_instant(registration: Any, scan: Scan | None) -> str | None:
    """The instant of the sweep the poses of ``registration`` over scans like ``scan`` refer to (None: unknown)."""
    if scan is None:
        return None
    deskew_to = getattr(registration, "deskew_instant", None)
    if deskew_to is not None and scan.point_times_s is not None and len(scan.point_times_s) > 0:
        return str(deskew_to)
    return scan.stamp_instant


def like_with_like(reference: Trajectory, estimate_at: str | None, *, sequence: Any, own_ground_truth: bool,
                   method: str) -> tuple[Trajectory, str | None]:
    """``(reference at the estimate's instant, note or None)``; EvaluationError when it cannot be re-timed."""
    truth_at = reference.meta.get("pose_instant") if reference.meta else None
    if estimate_at is None or truth_at is None or estimate_at == truth_at:
        return reference, None
    retime = getattr(sequence, "ground_truth_at", None)
    if own_ground_truth and callable(retime):
        retimed = retime(estimate_at)
        note = (f"ground truth re-timed from the sweep {truth_at} to the sweep {estimate_at}: {method}'s poses refer "
                f"to the sweep {estimate_at}")
        return retimed, note
    raise EvaluationError(
        f"{method}'s poses refer to the sweep {estimate_at} but the ground truth to the sweep {truth_at}; comparing them "
        f"would score the motion within a sweep as error. Give ground truth at the sweep {estimate_at} (or run without "
        "deskewing)", source=reference.name or "ground truth",
    )


__all__ = ["estimate_instant", "like_with_like"]
