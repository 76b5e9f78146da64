"""The relations metric of Kümmerle et al., "On measuring the accuracy of SLAM algorithms" (Auton. Robots 2009).

Ground truth is a set of relative poses ``delta*_ij`` between pairs of time stamps (hand-verified scan
alignments, :class:`lidarkit.io.carmen.Relations`). For each relation the estimate's own relative pose
``delta_ij = inv(T(t_i)) @ T(t_j)`` is taken between the poses nearest ``t_i`` and ``t_j`` (within
``max_time_diff_s``, and within half the log's smallest scan gap when the relations know it), and the error
``delta_ij (-) delta*_ij`` is split into a translational part (m, the norm of the difference of the planar
translations) and a rotational part (deg, the wrapped yaw difference). The
paper's tables report mean +- std of the absolute and of the squared errors, and the maximum; so does
:class:`RelationError`. The metric is planar: only x, y and yaw of the estimate enter.

Because it scores relative poses, no alignment of the estimate is needed, and odometry, scan matching and SLAM
results are scored the same way.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any

import numpy as np

from lidarkit.errors import ConfigError, EvaluationError
from lidarkit.io.carmen import Relations
from lidarkit.params import is_real_number
from lidarkit.trajectory import Trajectory

logger = logging.getLogger(__name__)

#: Default tolerance between a relation's time stamp and the nearest estimated pose (s). The relations of the
#: Freiburg benchmark are stamped with the scans' own time stamps (ACES: exact match). ACES and FR079 scans lie
#: >= 0.07 s apart, but Intel's stamps are delivery times: 5146 of its 13630 gaps are under 0.01 s (down to 0.1 ms
#: once made increasing), so on relations that know their log's smallest scan gap (``Relations.scan_gap_s``, set by
#: the CARMEN reader) the tolerance is at most half of it: a pose then stands only for the scan a relation was made
#: from, never for a neighbour the estimate skipped.
DEFAULT_MAX_TIME_DIFF_S = 0.01

#: A pose this close (s) to a relation's time is on that time exactly (TUM files hold stamps to 1e-9 s or 1e-6 s).
EXACT_MATCH_S = 1e-6


def _stats(values: np.ndarray) -> dict[str, float]:
    return {"mean": float(values.mean()), "std": float(values.std()), "max": float(values.max())}


@dataclass(frozen=True)
class RelationError:
    """Relation errors of one estimate: per relation ``translation_m`` / ``rotation_deg`` ``(K,)`` and summaries.

    ``n_relations``: relations in the file; ``n_used``: those with an estimated pose within ``max_time_diff_s`` (the
    tolerance applied: at most half ``scan_gap_s``, the log's smallest scan gap, when known) of both time stamps, a
    different one for each (the others are listed by index in ``unmatched``; ``n_same_pose`` of them had one pose
    nearest both).
    """

    translation_m: np.ndarray
    rotation_deg: np.ndarray
    used: np.ndarray
    n_relations: int
    max_time_diff_s: float
    name: str = ""
    n_same_pose: int = 0
    """Relations left out because one estimated pose is nearest both their time stamps (no motion to compare)."""
    warnings: tuple[str, ...] = ()
    """What the matching warned of (relations left out, most of them unmatched), as logged: the --json keeps them."""
    scan_gap_s: float | None = None
    """The log's smallest scan gap the tolerance was kept under (s), None when the relations did not know it."""

    def __repr__(self) -> str:
        """One line of the paper's figures, mean +- std (max) of the absolute errors (the generated one printed the
        arrays)."""
        t, r = self.translation_abs, self.rotation_abs
        return (f"RelationError({self.name!r}, {self.n_used} of {self.n_relations} relations: translation "
                f"{t['mean']:.4g} +- {t['std']:.4g} m (max {t['max']:.4g}), rotation {r['mean']:.4g} +- {r['std']:.4g} deg "
                f"(max {r['max']:.4g}))")

    @property
    def n_used(self) -> int:
        return int(len(self.used))

    @property
    def unmatched(self) -> np.ndarray:
        return np.setdiff1d(np.arange(self.n_relations), self.used)

    @property
    def translation_abs(self) -> dict[str, float]:
        """mean / std / max of |translational error| (m)."""
        return _stats(self.translation_m)

    @property
    def translation_sq(self) -> dict[str, float]:
        """mean / std / max of the squared translational error (m^2)."""
        return _stats(self.translation_m**2)

    @property
    def rotation_abs(self) -> dict[str, float]:
        """mean / std / max of |rotational error| (deg)."""
        return _stats(self.rotation_deg)

    @property
    def rotation_sq(self) -> dict[str, float]:
        """mean / std / max of the squared rotational error (deg^2)."""
        return _stats(self.rotation_deg**2)

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "n_relations": self.n_relations,
            "n_used": self.n_used,
            "n_same_pose": self.n_same_pose,
            "warnings": list(self.warnings),
            "max_time_diff_s": self.max_time_diff_s,
            "scan_gap_s": self.scan_gap_s,
            "translation_abs_m": self.translation_abs,
            "translation_sq_m2": self.translation_sq,
            "rotation_abs_deg": self.rotation_abs,
            "rotation_sq_deg2": self.rotation_sq,
        }


def nearest_pose_index(timestamps_s: np.ndarray, query_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Index of the time stamp nearest each query and the absolute time difference (s); timestamps increasing."""
    ts = np.asarray(timestamps_s, dtype=np.float64)
    q = np.asarray(query_s, dtype=np.float64)
    right = np.clip(np.searchsorted(ts, q), 1, len(ts) - 1) if len(ts) > 1 else np.zeros(len(q), dtype=np.int64)
    left = np.maximum(right - 1, 0)
    pick = np.where(np.abs(ts[left] - q) <= np.abs(ts[right] - q), left, right)
    return pick, np.abs(ts[pick] - q)


def relation_error(
    estimate: Trajectory,
    relations: Relations,
    max_time_diff_s: float = DEFAULT_MAX_TIME_DIFF_S,
) -> RelationError:
    """Score ``estimate`` (a Trajectory with timestamps, ``T_world_laser``) against relative-pose ground truth.

    Relations whose time stamps have no estimated pose within ``max_time_diff_s`` are left out (counted in the
    result); none matching at all is an EvaluationError. Relations that know their log's smallest scan gap (a CARMEN
    log's ``relations``) narrow the tolerance to half of it: wider, a scan the estimate skips took its neighbour's pose
    (every 2nd Intel scan: 60 of 140 relations (i, i+3) scored so). Without it (a file read on its own) the spacing of
    the scans is not known; a mix of exact and inexact matches is warned of.
    """
    if not isinstance(estimate, Trajectory):  # (a path: AttributeError 'str' object has no attribute 'name')
        raise EvaluationError("the estimate must be a lidarkit Trajectory (e.g. Trajectory.from_tum(path)), got "
                              f"{type(estimate).__name__}", source="estimate")
    source = estimate.name or "estimate"
    if relations is None or not isinstance(relations, Relations):  # (a log without a relations file: a TypeError)
        raise EvaluationError("no relations to score against (a CARMEN log has them when NAME.relations lies beside it, "
                              f"or with relations=FILE), got {type(relations).__name__}", source=source)
    if estimate.timestamps_s is None:
        raise EvaluationError("the relations metric needs the estimate's timestamps (e.g. a TUM-format file, or a KITTI file "
                              "with --est-times TIMES.txt)", source=source)
    if not is_real_number(max_time_diff_s):
        raise ConfigError(f"max_time_diff_s must be a number of seconds, got {max_time_diff_s!r}", source="max_time_diff_s")
    if not (np.isfinite(max_time_diff_s) and max_time_diff_s >= 0):
        raise ConfigError(f"max_time_diff_s must be a finite number >= 0, got {max_time_diff_s!r}", source="max_time_diff_s")
    if len(estimate) == 0 or len(relations) == 0:
        raise EvaluationError(f"nothing to score ({len(estimate)} poses, {len(relations)} relations)", source=source)
    scan_gap_s = relations.scan_gap_s
    max_time_diff_s = float(max_time_diff_s) if scan_gap_s is None else min(float(max_time_diff_s), 0.5 * scan_gap_s)
    i, di = nearest_pose_index(estimate.timestamps_s, relations.t1_s)
    j, dj = nearest_pose_index(estimate.timestamps_s, relations.t2_s)
    near = (di <= max_time_diff_s) & (dj <= max_time_diff_s)
    # both ends nearest one pose (a loose tolerance, relations past the estimate's end): no motion to compare; scored,
    # 1279 of 1279 relations read as matched on a 600-scan estimate, 1240 s past its end on its last pose
    same = int((near & (i == j)).sum())
    used = np.flatnonzero(near & (i != j))
    span = (float(estimate.timestamps_s[0]), float(estimate.timestamps_s[-1]))
    warnings: list[str] = []

    def warn(message: str) -> None:  # logged as it happens, and kept for the result (the --json)
        warnings.append(message)
        logger.warning("%s: %s", source, message)

    if same:
        warn(f"{same} of {len(relations)} relations have the same estimated pose nearest both their time stamps "
             f"(within {max_time_diff_s:g} s; estimate spans {span[0]:.3f}..{span[1]:.3f} s): left out, they would score as "
             "no motion")
    # (a relation may run back in time, t1 > t2: the span is over both stamps, not t1's least to t2's most)
    rel_lo = float(min(relations.t1_s.min(), relations.t2_s.min()))
    rel_hi = float(max(relations.t1_s.max(), relations.t2_s.max()))
    if len(used) == 0:
        raise EvaluationError(
            f"no relation has estimated poses within {max_time_diff_s:g} s of both its time stamps "
            + (f"other than one pose for both ({same} relations) " if same else "")
            + f"(estimate spans {span[0]:.3f}..{span[1]:.3f} s, relations {rel_lo:.3f}..{rel_hi:.3f} s)",
            source=source,
        )
    ends = np.concatenate([di[used], dj[used]])  # each scored relation's two time stamps, from their poses (s)
    off = ends[ends > EXACT_MATCH_S]
    if scan_gap_s is None and off.size and off.size < ends.size:
        # some time stamps met a pose exactly, so the estimate carries the stamps the relations were made at; one met off
        # them is then most likely a neighbouring scan's (a file read alone does not say how close the scans lie)
        warn(f"{off.size} of the {ends.size} time stamps of the scored relations met a pose {off.min():.3g}..{off.max():.3g} s "
             f"off, the other {ends.size - off.size} exactly: if the relation times are scan stamps, those are other scans' "
             f"poses (an estimate that skips scans, or one on another clock); a tolerance under {off.min():.3g} s leaves "
             "them out (a log's own relations, open_dataset(...).relations, know its scan spacing)")
    if len(used) + same < 0.5 * len(relations):  # most relations left out: the estimate's clock or its span does not match
        warn(f"only {len(used)} of {len(relations)} relations have estimated poses within {max_time_diff_s:g} s of both "
             f"their time stamps (estimate spans {span[0]:.3f}..{span[1]:.3f} s, relations {rel_lo:.3f}..{rel_hi:.3f} s): the "
             "score covers those only")
    P = estimate.poses_se3
    Ti, Tj = P[i[used]], P[j[used]]
    # delta_ij = inv(Ti) @ Tj, planar part: R_i^T (t_j - t_i) and yaw_j - yaw_i
    yaw_i = np.arctan2(Ti[:, 1, 0], Ti[:, 0, 0])
    yaw_j = np.arctan2(Tj[:, 1, 0], Tj[:, 0, 0])
    d = Tj[:, :2, 3] - Ti[:, :2, 3]
    c, s = np.cos(yaw_i), np.sin(yaw_i)
    dx, dy = c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]
    trans = np.hypot(dx - relations.dx_m[used], dy - relations.dy_m[used])
    dyaw = (yaw_j - yaw_i) - relations.dyaw_rad[used]
    rot = np.degrees(np.abs(np.arctan2(np.sin(dyaw), np.cos(dyaw))))
    return RelationError(trans, rot, used, len(relations), max_time_diff_s, name=source, n_same_pose=same,
                         warnings=tuple(warnings), scan_gap_s=scan_gap_s)


__all__ = ["DEFAULT_MAX_TIME_DIFF_S", "EXACT_MATCH_S", "RelationError", "nearest_pose_index", "relation_error"]
