"""The KITTI odometry devkit drift metric: translational error (%) and rotational error (deg/100 m).

Definition (KITTI odometry devkit, ``evaluate_odometry.cpp``): for every first frame ``a`` in steps of
``step`` frames and every segment length ``L``, the last frame ``b`` is the first frame whose path distance
along the reference exceeds ``dist[a] + L`` (strictly greater). The error pose is
``E = (est_a^-1 est_b)^-1 (ref_a^-1 ref_b)`` (general matrix inverses, as the devkit); the segment's
translational error is ``|t(E)| / L`` and its rotational error ``angle(R(E)) / L``. The reported numbers
average all segments of all lengths together (pooled, as the KITTI benchmark and kiss-icp do); the table
gives the mean per length.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from lidarkit.errors import ConfigError, EvaluationError
from lidarkit.eval.pairing import check_flags, pair_name, paired
from lidarkit.params import is_real_number
from lidarkit.trajectory import Trajectory

KITTI_LENGTHS_M = (100.0, 200.0, 300.0, 400.0, 500.0, 600.0, 700.0, 800.0)
KITTI_STEP_FRAMES = 10


def _none_if_nan(value: float) -> float | None:
    return None if not np.isfinite(value) else float(value)


@dataclass(frozen=True)
class DriftRow:
    """Mean drift over the ``n_segments`` segments of one length (NaN when there are none)."""

    length_m: float
    n_segments: int
    translation_pct: float
    rotation_deg_per_100m: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "length_m": float(self.length_m),
            "n_segments": int(self.n_segments),
            "translation_pct": _none_if_nan(self.translation_pct),
            "rotation_deg_per_100m": _none_if_nan(self.rotation_deg_per_100m),
        }


@dataclass(frozen=True, eq=False)
class DriftResult:
    """KITTI drift of an estimate: pooled means plus the per-length table and per-segment arrays.

    Per-segment arrays (``(S,)``): ``segment_first_frame``, ``segment_last_frame`` (int), ``segment_length_m``,
    ``segment_translation_pct``, ``segment_rotation_deg_per_100m``. When no segment fits (reference
    shorter than the shortest length and ``allow_empty=True``), ``n_segments == 0`` and the means are NaN.
    ``ref_length_m``: the reference path between the first and last pose scored, along which segments were measured.
    """

    translation_pct: float
    rotation_deg_per_100m: float
    n_segments: int
    per_length: tuple[DriftRow, ...]
    step_frames: int
    ref_length_m: float
    ref_name: str = ""
    est_name: str = ""
    segment_first_frame: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64), repr=False)
    segment_last_frame: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64), repr=False)
    segment_length_m: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)
    segment_translation_pct: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)
    segment_rotation_deg_per_100m: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)

    @property
    def valid(self) -> bool:
        """True when at least one segment was evaluated."""
        return self.n_segments > 0

    @property
    def lengths_m(self) -> tuple[float, ...]:
        return tuple(row.length_m for row in self.per_length)

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe dict; NaN (no segments) becomes None."""
        return {
            "metric": "kitti_drift",
            "translation_pct": _none_if_nan(self.translation_pct),
            "rotation_deg_per_100m": _none_if_nan(self.rotation_deg_per_100m),
            "n_segments": int(self.n_segments),
            "step_frames": int(self.step_frames),
            "ref_length_m": float(self.ref_length_m),
            "ref_name": self.ref_name,
            "est_name": self.est_name,
            "per_length": [row.to_dict() for row in self.per_length],
        }


def drift_segments_possible(ref: Trajectory, lengths: tuple[float, ...] = KITTI_LENGTHS_M, *,
                            path_along: Trajectory | None = None) -> bool:
    """Whether ``ref`` is long enough for at least one segment (its path must exceed the shortest length); its path
    measured along ``path_along`` as in :func:`kitti_drift`."""
    if not isinstance(ref, Trajectory):  # (None failed len() with a TypeError)
        raise ConfigError(f"ref must be a lidarkit Trajectory, got {type(ref).__name__} {ref!r:.60}", source="ref")
    lengths = checked_lengths(lengths, "lengths")
    if len(ref) < 2:
        return False
    dist = path_distances_m(ref, path_along)
    return float(dist[-1] - dist[0]) > min(lengths)


def path_distances_m(ref: Trajectory, path_along: Trajectory | None = None) -> np.ndarray:
    """``(N,)`` path distance (m) of each pose of ``ref``: along ``ref`` itself, or, for poses time-associated from a
    denser reference ``path_along``, along that one at their stamps (the line through 118 matched keyframes of TUM
    fr2/desk cuts its corners: 15.6 m where the reference travels 18.5 m)."""
    if path_along is None or path_along is ref:
        return ref.distances_m
    if not isinstance(path_along, Trajectory):
        raise ConfigError(f"path_along must be a Trajectory, got {type(path_along).__name__}", source="path_along")
    if ref.timestamps_s is None or path_along.timestamps_s is None:
        raise ConfigError("path distances along another reference need the timestamps of both", source="path_along")
    return np.interp(ref.timestamps_s, path_along.timestamps_s, path_along.distances_m)


def checked_step(step: int, source: str) -> int:
    """``step`` as an int; ConfigError unless a whole number >= 1 ("10" read "got 10", "x" raised a ValueError)."""
    if not is_real_number(step) or not (
            float(step).is_integer() and step >= 1):
        raise ConfigError(f"{source} must be a positive integer number of frames, got {step!r}", source=source)
    return int(step)


def checked_lengths(lengths: Sequence[float], source: str, what: str = "segment lengths") -> np.ndarray:
    """``lengths`` (m) as a float64 array; ConfigError unless a non-empty sequence of distinct positive numbers ("100,200"
    was a ValueError, None a TypeError, "200" or a single number ran with one length, a repeated length counted twice)."""
    if isinstance(lengths, np.ndarray):
        # (a 0-d or 2-D array was quoted as "got None": the value it had been replaced with)
        shown = f"an array of shape {lengths.shape}" if lengths.ndim != 1 else repr(lengths.tolist())
        items = lengths.tolist() if lengths.ndim == 1 else []
    else:
        shown = repr(lengths)
        items = list(lengths) if isinstance(lengths, Sequence) and not isinstance(lengths, (str, bytes)) else []
    if not items or not all(is_real_number(x) and np.isfinite(x) and x > 0 for x in items):
        raise ConfigError(f"{what} must be a non-empty list of positive numbers (m), got {shown}", source=source)
    if len(set(items)) != len(items):
        raise ConfigError(f"{what} must differ, got {shown}", source=source)
    return np.array(items, dtype=np.float64)


def kitti_drift(
    ref: Trajectory,
    est: Trajectory,
    lengths: tuple[float, ...] = KITTI_LENGTHS_M,
    step: int = KITTI_STEP_FRAMES,
    *,
    allow_empty: bool = False,
    associate: bool = False,
    max_diff_s: float = 0.01,
    path_along: Trajectory | None = None,
) -> DriftResult:
    """KITTI devkit drift of ``est`` against ``ref`` (frame-aligned, or ``associate`` by timestamps).

    Segments of each length in ``lengths`` (m) start every ``step`` frames; path distances come from ``ref``: with
    ``associate`` from the whole reference at the matched stamps, not from the line through the matched poses (which
    cuts the corners between sparse ones); ``path_along``: the whole reference of a ``ref`` associated beforehand.
    No alignment is needed: the metric only uses relative poses. A reference whose path is not longer
    than the shortest length raises EvaluationError, unless ``allow_empty`` (then ``result.valid`` is False).
    """
    source = pair_name(ref, est)
    check_flags(allow_empty=allow_empty, associate=associate)  # ("no" is a true string: it allowed, it associated)
    lengths_arr = checked_lengths(lengths, "lengths")
    step = checked_step(step, "step")
    if associate and path_along is not None:  # (the reference given is then the whole one)
        raise ConfigError("path_along is the whole reference of one associated beforehand, not with associate",
                          source="path_along")
    whole_ref = ref if associate else path_along
    ref, est = paired(ref, est, associate=associate, max_diff_s=max_diff_s)

    ref_poses, est_poses = ref.poses_se3, est.poses_se3
    dist = path_distances_m(ref, whole_ref)
    path_m = ref.length_m if whole_ref is None else float(dist[-1] - dist[0])
    n = len(ref)
    first = np.arange(0, n, min(step, max(n, 1)))  # (a step past the last frame starts at frame 0 only: 10**20 made
    # numpy's arange an object array, an IndexError)
    seg_first, seg_last, seg_len = [], [], []
    for length in lengths_arr:
        last = np.searchsorted(dist, dist[first] + length, side="right")  # first frame with dist > start + L
        ok = last < n
        seg_first.append(first[ok])
        seg_last.append(last[ok])
        seg_len.append(np.full(int(ok.sum()), length))
    a = np.concatenate(seg_first).astype(np.int64)
    b = np.concatenate(seg_last).astype(np.int64)
    seg_len_m = np.concatenate(seg_len)

    if a.size == 0:
        if not allow_empty:
            raise EvaluationError(
                f"reference path is {path_m:.1f} m long{' between the associated poses' if associate else ''}; KITTI drift "
                f"needs segments longer than {lengths_arr.min():g} m",
                source=source,
            )
        t_seg = r_seg = np.zeros(0)
    else:
        t_seg, r_seg = _segment_errors(ref_poses, est_poses, a, b)
        t_seg = 100.0 * t_seg / seg_len_m  # percent
        r_seg = np.degrees(r_seg) / seg_len_m * 100.0  # deg per 100 m

    rows = []
    for length in lengths_arr:
        sel = seg_len_m == length
        count = int(sel.sum())
        rows.append(
            DriftRow(
                float(length),
                count,
                float(t_seg[sel].mean()) if count else float("nan"),
                float(r_seg[sel].mean()) if count else float("nan"),
            )
        )
    return DriftResult(
        translation_pct=float(t_seg.mean()) if a.size else float("nan"),
        rotation_deg_per_100m=float(r_seg.mean()) if a.size else float("nan"),
        n_segments=int(a.size),
        per_length=tuple(rows),
        step_frames=step,
        ref_length_m=path_m,
        ref_name=ref.name,
        est_name=est.name,
        segment_first_frame=a,
        segment_last_frame=b,
        segment_length_m=seg_len_m,
        segment_translation_pct=t_seg,
        segment_rotation_deg_per_100m=r_seg,
    )


def _segment_errors(
    ref_poses: np.ndarray, est_poses: np.ndarray, a: np.ndarray, b: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Translation norm (m) and rotation angle (rad) of ``E = (est_a^-1 est_b)^-1 (ref_a^-1 ref_b)`` per segment.

    Written as ``t(E) = R_e^-1 (t_r - t_e)`` and ``trace(R(E)) - 3 = trace(R_e^-1 (R_r - R_e))`` with
    ``(R_r, t_r)``, ``(R_e, t_e)`` the relative motions: the same numbers as the devkit's product, but exactly
    zero when the estimate equals the reference and without the cancellation in ``trace - 3`` for small angles.
    """
    delta_ref = np.linalg.inv(ref_poses[a]) @ ref_poses[b]
    delta_est = np.linalg.inv(est_poses[a]) @ est_poses[b]
    R_est_inv = np.linalg.inv(delta_est[:, :3, :3])
    t_err = np.linalg.norm(np.einsum("nij,nj->ni", R_est_inv, delta_ref[:, :3, 3] - delta_est[:, :3, 3]), axis=1)
    trace_minus_3 = np.einsum("nij,nji->n", R_est_inv, delta_ref[:, :3, :3] - delta_est[:, :3, :3])
    r_err = np.arccos(np.clip(1.0 + 0.5 * trace_minus_3, -1.0, 1.0))
    return t_err, r_err
