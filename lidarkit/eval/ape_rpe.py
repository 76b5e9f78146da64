"""Absolute and relative pose error (APE, RPE) computed by evo, returned as frozen result objects.

evo aligns, transforms and scales its trajectories in place, so every call works on fresh copies
(``Trajectory.to_evo()``); the caller's trajectories are never modified.
"""

from __future__ import annotations

import contextlib
import functools
import io
import logging
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from lidarkit.errors import ConfigError, EvaluationError
from lidarkit.eval.pairing import check_flags, pair_name, paired
from lidarkit.params import is_integer, is_real_number
from lidarkit.trajectory import Trajectory

logger = logging.getLogger(__name__)

ALIGNMENTS = ("none", "se3", "sim3", "scale")
"""``none``: compare as given; ``se3``: rigid Umeyama; ``sim3``: Umeyama with scale; ``scale``: scale only."""

# lidarkit name -> evo PoseRelation member name
RELATIONS = {
    "translation": "translation_part",
    "rotation": "rotation_part",
    "rotation_angle_deg": "rotation_angle_deg",
    "rotation_angle_rad": "rotation_angle_rad",
    "full": "full_transformation",
    "point_distance": "point_distance",
    "point_distance_error_ratio": "point_distance_error_ratio",
}
APE_RELATIONS = tuple(r for r in RELATIONS if r != "point_distance_error_ratio")
RPE_RELATIONS = tuple(RELATIONS)
#: relations that compare orientations (what an alignment the positions hardly fix makes arbitrary)
ORIENTATION_RELATIONS = ("rotation", "rotation_angle_deg", "rotation_angle_rad", "full")

# lidarkit delta unit -> evo Unit member name
DELTA_UNITS = {
    "frames": "frames",
    "meters": "meters",
    "m": "meters",
    "degrees": "degrees",
    "deg": "degrees",
    "radians": "radians",
    "rad": "radians",
}

STAT_NAMES = ("rmse", "mean", "median", "std", "min", "max", "sse")


@dataclass(frozen=True, eq=False)
class AlignmentTransform:
    """The similarity applied to the estimate: ``p_aligned = scale * rotation @ p + translation``."""

    method: str
    rotation: np.ndarray
    translation: np.ndarray
    scale: float = 1.0
    n_poses_used: int = 0
    axis_sigma_deg: float = 0.0
    """How loosely the positions fix the rotation about the reference path's main direction (deg): the aligned
    positions' RMS residual along the way that rotation moves them (out of a flat path's plane) over the reference's
    RMS spread across that direction. A nearly straight path (or such residuals as large as its spread) leaves that
    rotation to the noise: beyond :data:`AXIS_SIGMA_LIMIT_DEG`
    orientation errors after the alignment are not meaningful (APE rotation of 5 poses of KITTI 00: 136 deg aligned,
    0.29 deg as estimated); 0 for alignments without a rotation."""

    @property
    def rescaled(self) -> bool:
        """Whether the estimate was rescaled (``sim3`` or ``scale``): its scale belongs beside any figure of it."""
        return self.method in ("sim3", "scale")

    @property
    def sim3(self) -> np.ndarray:
        """``(4, 4)`` matrix with ``scale * rotation`` in the upper-left block."""
        T = np.eye(4)
        T[:3, :3] = self.scale * self.rotation
        T[:3, 3] = self.translation
        return T

    def applied_to(self, est: Trajectory) -> Trajectory:
        """``est`` aligned as the estimate was: positions ``scale * rotation @ p + translation``, orientations turned by
        ``rotation``."""
        if self.method == "origin":
            return est.transformed(T_left=self.sim3)
        poses = est.poses_se3.copy()
        poses[:, :3, 3] = self.scale * poses[:, :3, 3]
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = self.rotation, self.translation
        return Trajectory(T @ poses, est.timestamps_s, est.name, dict(est.meta))

    def to_dict(self) -> dict[str, Any]:
        return {
            "method": self.method,
            "rotation": self.rotation.tolist(),
            "translation": self.translation.tolist(),
            "scale": float(self.scale),
            "n_poses_used": int(self.n_poses_used),
            "axis_sigma_deg": float(self.axis_sigma_deg),
        }


@dataclass(frozen=True, eq=False)
class _ErrorResult:
    """Fields shared by APE and RPE: evo's statistics of the per-pose (per-pair) error array."""

    relation: str
    unit: str
    align: str
    align_origin: bool
    n_to_align: int | None
    rmse: float
    mean: float
    median: float
    std: float
    min: float
    max: float
    sse: float
    errors: np.ndarray = field(repr=False)
    alignment: AlignmentTransform | None
    ref_name: str
    est_name: str
    associated: bool
    title: str
    ref: Trajectory = field(repr=False)
    """Reference as compared (after association)."""
    est_aligned: Trajectory = field(repr=False)
    """Estimate as compared (after association and alignment)."""

    @property
    def stats(self) -> dict[str, float]:
        return {name: float(getattr(self, name)) for name in STAT_NAMES}

    @property
    def n_errors(self) -> int:
        return int(len(self.errors))

    def _base_dict(self, include_errors: bool) -> dict[str, Any]:
        out: dict[str, Any] = {
            "title": self.title,
            "relation": self.relation,
            "unit": self.unit,
            "align": self.align,
            "align_origin": self.align_origin,
            "n_to_align": self.n_to_align,
            "ref_name": self.ref_name,
            "est_name": self.est_name,
            "associated": self.associated,
            "n_errors": self.n_errors,
            "stats": self.stats,
            "alignment": None if self.alignment is None else self.alignment.to_dict(),
        }
        if include_errors:
            out["errors"] = self.errors.tolist()
        return out


@dataclass(frozen=True, eq=False)
class APEResult(_ErrorResult):
    """Absolute pose error: one error per pose pair ``(ref_i, est_i)`` after alignment; ``warning``: why the numbers
    mean little, "" when they do (orientation errors after an alignment the positions hardly fix)."""

    warning: str = ""

    def to_dict(self, include_errors: bool = True) -> dict[str, Any]:
        """JSON-safe dict (plain floats, lists)."""
        return {"metric": "ape", **self._base_dict(include_errors), "warning": self.warning}


@dataclass(frozen=True, eq=False)
class RPEResult(_ErrorResult):
    """Relative pose error: one error per pose pair ``(i, j)`` selected by ``delta`` in ``delta_unit``."""

    delta: float = 1.0
    delta_unit: str = "frames"
    all_pairs: bool = False
    pairs_from_reference: bool = False
    legacy_pairs: bool = False
    pairs: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), dtype=np.int64), repr=False)
    """``(M, 2)`` int: indices ``(i, j)`` (into ``ref``/``est_aligned``) of each compared pair."""

    def to_dict(self, include_errors: bool = True) -> dict[str, Any]:
        """JSON-safe dict (plain floats, lists)."""
        out = {"metric": "rpe", **self._base_dict(include_errors)}
        out.update(
            delta=self.delta,
            delta_unit=self.delta_unit,
            all_pairs=self.all_pairs,
            pairs_from_reference=self.pairs_from_reference,
            legacy_pairs=self.legacy_pairs,
        )
        if include_errors:
            out["pairs"] = self.pairs.tolist()
        return out


# ---- helpers -------------------------------------------------------------------------------------
def _relation(name: str, allowed: tuple[str, ...]):
    from evo.core.metrics import PoseRelation

    if not isinstance(name, str) or name not in allowed:  # (a list or an array raised TypeError: unhashable, ambiguous)
        raise ConfigError(f"unknown pose relation {name!r}; known: {', '.join(allowed)}", source="relation")
    return PoseRelation[RELATIONS[name]]


def check_legacy_pairs(legacy_pairs: bool, delta_unit: str, all_pairs: bool) -> None:
    """ConfigError for ``legacy_pairs`` where the 2018 evo releases chose pairs as today's: a delta in frames, or all
    pairs (only their first consecutive path/angle pair differs). ``delta_unit`` as :func:`checked_delta` returns it."""
    if legacy_pairs and (delta_unit == "frames" or all_pairs):
        raise ConfigError("legacy_pairs applies to consecutive pairs with a path or angle delta, not "
                          + ("to all pairs" if all_pairs else "to a delta in frames"), source="legacy_pairs")


def check_align_name(align: str) -> None:
    """ConfigError unless ``align`` is one of ``ALIGNMENTS`` (also checked by EvaluationSettings when it is made)."""
    if not isinstance(align, str) or align not in ALIGNMENTS:
        raise ConfigError(f"unknown alignment {align!r}; known: {', '.join(ALIGNMENTS)}", source="align")


def _check_align(align: str, align_origin: bool, n_to_align: int | None, n_poses: int, source: str) -> int:
    """Validate the alignment settings; return evo's ``n`` (-1 = all poses)."""
    check_align_name(align)
    if not isinstance(align_origin, (bool, np.bool_)):  # ("no" is a true string: it aligned the origin)
        raise ConfigError(f"align_origin must be True or False, got {align_origin!r}", source="align_origin")
    if align_origin and align != "none":
        raise ConfigError("align_origin cannot be combined with align != 'none'", source="align_origin")
    if n_to_align is None:
        return -1
    if align == "none":
        raise ConfigError("n_to_align needs align = se3, sim3 or scale", source="n_to_align")
    if not is_integer(n_to_align):  # ("5" read "must be in [1, 5], got 5")
        raise ConfigError(f"n_to_align must be a whole number of poses, got {n_to_align!r}", source="n_to_align")
    n = int(n_to_align)
    if n < 1:  # wrong for any trajectory: a setting, not the data (5.5 was a ConfigError, 0 an EvaluationError)
        raise ConfigError(f"n_to_align must be at least 1 pose, got {n_to_align}", source="n_to_align")
    if n > n_poses:
        raise EvaluationError(f"n_to_align must be an integer in [1, {n_poses}], got {n_to_align}", source=source)
    return n


def _aligned_copies(ref: Trajectory, est: Trajectory, align: str, align_origin: bool, n: int, source: str):
    """Fresh evo copies of ``ref`` and ``est``, the estimate aligned as asked; plus the applied transform."""
    from evo import EvoException

    ref_evo, est_evo = ref.to_evo(), est.to_evo()
    transform = None
    try:
        if align != "none":
            if align in ("se3", "sim3") and (len(ref) if n == -1 else n) < 3:
                raise EvaluationError(f"{align} alignment needs at least 3 poses", source=source)
            R, t, s = est_evo.align(
                ref_evo, correct_scale=(align == "sim3"), correct_only_scale=(align == "scale"), n=n
            )
            if align == "scale":
                R, t = np.eye(3), np.zeros(3)
            elif align == "se3":
                s = 1.0
            used = len(ref) if n == -1 else n
            sigma = _axis_sigma_deg(ref_evo.positions_xyz[:used], est_evo.positions_xyz[:used]) if align != "scale" else 0.0
            transform = AlignmentTransform(align, np.asarray(R, float), np.asarray(t, float), float(s), used, sigma)
        elif align_origin:
            T = np.asarray(est_evo.align_origin(ref_evo), float)
            transform = AlignmentTransform("origin", T[:3, :3], T[:3, 3], 1.0, 1)
    except EvoException as err:
        raise EvaluationError(
            f"{align if align != 'none' else 'origin'} alignment failed: {err} "
            "(positions collinear or constant? use align='none', --align none)",
            source=source,
        ) from err
    if transform is not None and not (np.isfinite(transform.sim3).all() and transform.scale > 0):
        raise EvaluationError(f"degenerate {transform.method} alignment (non-finite or zero scale)", source=source)
    return ref_evo, est_evo, transform


#: Beyond this :attr:`AlignmentTransform.axis_sigma_deg`, orientation errors after an alignment get a warning (well
#: spread paths: 0.26-1.0 deg on KITTI 00 with ORB-SLAM and S-PTAM; its first 5 or 50 poses: 1e4-2e5 and 55 deg)
AXIS_SIGMA_LIMIT_DEG = 10.0


def _axis_sigma_deg(ref_xyz: np.ndarray, aligned_xyz: np.ndarray) -> float:
    """:attr:`AlignmentTransform.axis_sigma_deg` of aligned positions (inf for a path with no spread across it).

    Only the residual along the way a turn about the main direction moves each position counts, on a flat path the
    part out of its plane: the in-plane drift of a 20 m loop whose heading turns 45 deg read as an 18 deg loose turn."""
    centred = ref_xyz - ref_xyz.mean(axis=0)
    _, spread, directions = np.linalg.svd(centred, full_matrices=False)
    if len(spread) < 3:  # (fewer than 3 positions: no spread across the main direction)
        residual = float(np.abs(ref_xyz - aligned_xyz).max()) if len(ref_xyz) else 0.0
        return 0.0 if residual == 0 else float("inf")
    moved = np.cross(directions[0], centred)  # a small turn about the main direction moves position i along moved[i]
    lever = np.linalg.norm(moved, axis=1)
    way = moved / np.where(lever > 0, lever, 1.0)[:, None]
    residual = float(np.sqrt(np.mean(np.einsum("ij,ij->i", ref_xyz - aligned_xyz, way) ** 2)))
    across = float(np.hypot(spread[1], spread[2])) / np.sqrt(len(ref_xyz))
    return float(np.degrees(residual / across)) if across > 0 else (0.0 if residual == 0 else float("inf"))


def alignment_warning(transform: AlignmentTransform | None) -> str:
    """Why orientation errors after ``transform`` mean little ("" when they do): see ``axis_sigma_deg``."""
    if transform is None or not transform.axis_sigma_deg > AXIS_SIGMA_LIMIT_DEG:
        return ""
    how = f"only to ~{transform.axis_sigma_deg:.2g} deg" if transform.axis_sigma_deg < 90 else "not at all"
    return (f"the positions fix the {transform.method} alignment's rotation about the path's main direction {how} (a "
            "nearly straight path, or residuals out of its plane as large as its spread across it): orientation errors "
            "after this alignment are not meaningful; align='none' (--align none) compares orientations as estimated")


#: How an estimate was aligned, in the words of labels and table titles (``alignment_label``)
ALIGNMENT_LABELS = {"none": "unaligned", "se3": "SE(3)-aligned", "sim3": "Sim(3)-aligned", "scale": "scale-corrected"}


def alignment_label(align: str) -> str:
    """``"unaligned"``, ``"SE(3)-aligned"``, ``"Sim(3)-aligned"`` or ``"scale-corrected"`` for an ``align`` mode (other
    text as given): one wording for plot legends, table titles and report labels."""
    return ALIGNMENT_LABELS.get(align, align)


#: the largest angle delta evo accepts: a rotation angle is at most half a turn
MAX_ANGLE_DELTA = {"degrees": 180.0, "radians": float(np.pi)}


def checked_delta(delta: float, delta_unit: str) -> tuple[float, str]:
    """``(delta, evo's unit name)`` of an RPE delta; ConfigError naming ``delta`` or ``delta_unit`` otherwise (checked
    with the settings: 200 deg was refused by evo only after the KITTI drift had been computed)."""
    if not isinstance(delta_unit, str) or delta_unit not in DELTA_UNITS:  # (a list raised TypeError: unhashable)
        raise ConfigError(f"unknown delta unit {delta_unit!r}; known: {', '.join(DELTA_UNITS)}", source="delta_unit")
    unit = DELTA_UNITS[delta_unit]
    if not is_real_number(delta):  # (True read as a delta of 1; "10" was kept as text and broke the report's format)
        raise ConfigError(f"delta must be a number, got {delta!r}", source="delta")
    delta = float(delta)
    if not np.isfinite(delta) or delta <= 0:
        raise ConfigError(f"delta must be > 0, got {delta}", source="delta")
    if unit == "frames" and not delta.is_integer():
        raise ConfigError(f"delta in frames must be an integer, got {delta}", source="delta")
    if unit in MAX_ANGLE_DELTA and delta > MAX_ANGLE_DELTA[unit]:
        raise ConfigError(f"delta in {unit} must be at most {MAX_ANGLE_DELTA[unit]:.6g} (a rotation angle), got {delta:g}",
                          source="delta")
    return delta, unit


def _accumulated_angle(poses_se3: np.ndarray, degrees: bool) -> float:
    """The rotation angle summed over consecutive poses: what an angle delta of consecutive pairs is measured along."""
    poses = np.asarray(poses_se3, dtype=np.float64)
    if len(poses) < 2:
        return 0.0
    from scipy.spatial.transform import Rotation

    # (as evo measures it: scipy's nearest rotation; the trace's arccos read 146.1 deg for 146.0 on 6-digit KITTI poses)
    relative = np.einsum("nji,njk->nik", poses[:-1, :3, :3], poses[1:, :3, :3])  # R_i^T R_{i+1}
    total = float(Rotation.from_matrix(relative).magnitude().sum())
    return float(np.degrees(total)) if degrees else total


def _widest_angle(poses_se3: np.ndarray, degrees: bool) -> float:
    """The largest rotation angle between any two poses (all pairs' angle deltas are direct); in blocks, not n x n."""
    from scipy.spatial.transform import Rotation

    q = Rotation.from_matrix(np.asarray(poses_se3, dtype=np.float64)[:, :3, :3]).as_quat()
    # the angle between two unit quaternions is 2 acos |q_i . q_j|: the widest has the smallest |dot| (rows in blocks)
    smallest = min(float(np.abs(q[start:start + 512] @ q.T).min()) for start in range(0, len(q), 512))
    widest = 2.0 * float(np.arccos(min(smallest, 1.0)))
    return float(np.degrees(widest)) if degrees else widest


def _checked_pairs(pairs, n_poses: int, source: str) -> np.ndarray:
    """``(m, 2)`` int pose pairs ``(i, j)``, ``0 <= i < j < n_poses``; ConfigError otherwise (an IndexError or, with
    consecutive pairs, silently other pairs than the ones named; no pairs scored evo's own, 1.5 was read as 1)."""
    try:
        given = np.asarray(pairs, dtype=np.float64).reshape(-1, 2)
    except (TypeError, ValueError):
        raise ConfigError(f"pairs must be (i, j) pose index pairs, got {type(pairs).__name__}", source="pairs") from None
    if len(given) == 0:
        raise ConfigError("pairs is empty: give at least one (i, j) pose index pair, or pairs=None to select them by delta",
                          source="pairs")
    fractional = np.flatnonzero(~np.isfinite(given).all(axis=1) | (given != np.round(given)).any(axis=1))
    if len(fractional):
        i, j = given[fractional[0]]
        raise ConfigError(f"pair {int(fractional[0])} ({i:g}, {j:g}) is not two whole pose indices", source="pairs")
    out = given.astype(np.int64)
    bad = np.flatnonzero((out[:, 0] < 0) | (out[:, 1] >= n_poses) | (out[:, 0] >= out[:, 1]))
    if len(bad):
        i, j = out[bad[0]]
        raise ConfigError(f"pair {int(bad[0])} ({int(i)}, {int(j)}) is not two poses i < j of the {n_poses} ({source})", source="pairs")
    return out


def _title(metric, align: str, align_origin: bool, n: int) -> str:
    suffix = {
        "none": "not aligned",
        "se3": "with SE(3) Umeyama alignment",
        "sim3": "with Sim(3) Umeyama alignment",
        "scale": "scale corrected",
    }[align]
    if align_origin:
        suffix = "with origin alignment"
    if align != "none" and n != -1:
        suffix += f", aligned poses: {n}"
    return f"{str(metric).replace(chr(10), ' ')} ({suffix})"


def _stats(metric, source: str, what: str, ref: Trajectory, est: Trajectory) -> dict[str, float]:
    """evo's statistics of ``metric``'s errors; an EvaluationError naming the pair when one is no finite number (a
    coordinate of 1e300 overflowed: the table printed "–", the JSON null, with exit 0)."""
    errors = np.asarray(metric.error, dtype=float)
    if errors.size == 0:
        raise EvaluationError("no errors were computed (empty comparison)", source=source)
    all_stats = metric.get_all_statistics()
    stats = {name: float(all_stats[name]) for name in STAT_NAMES}
    not_finite = [f"{name} {stats[name]:g}" for name in STAT_NAMES if not np.isfinite(stats[name])]
    if not_finite:
        raise EvaluationError(f"{what} statistics are not finite ({', '.join(not_finite)}): {_largest_coordinate(ref, est)}, "
                              "too large to score in float64", source=source)
    return stats


def _largest_coordinate(ref: Trajectory, est: Trajectory) -> str:
    """Where the largest position coordinate of the pair is: ``"the largest coordinate is 1e+300 m (estimate, pose 42)"``."""
    sides = [(float(np.abs(t.positions_xyz).max()), side, t) for side, t in (("reference", ref), ("estimate", est)) if len(t)]
    largest, side, trajectory = max(sides, key=lambda item: item[0])
    pose = int(np.argmax(np.abs(trajectory.positions_xyz).max(axis=1)))
    return f"the largest coordinate is {largest:.3g} m ({side}, pose {pose})"


def _float_overflow_quiet(metric):
    """Run ``metric`` with numpy's overflow and invalid-value warnings off: the statistics they leave non-finite are
    refused in one line (:func:`_stats`), where numpy printed several lines of RuntimeWarning first."""

    @functools.wraps(metric)
    def quiet(*args, **kwargs):
        with np.errstate(over="ignore", invalid="ignore"):
            return metric(*args, **kwargs)

    return quiet


# ---- public API ------------------------------------------------------------------------------------
def align_trajectory(
    ref: Trajectory,
    est: Trajectory,
    align: str = "se3",
    *,
    n_to_align: int | None = None,
    associate: bool = False,
    max_diff_s: float = 0.01,
) -> tuple[Trajectory, AlignmentTransform | None]:
    """Copy of ``est`` aligned onto ``ref`` with evo's Umeyama alignment, and the transform. Trajectories must have
    equal length unless ``associate`` (as in :func:`ape`; the copy then holds the matched poses only)."""
    source = pair_name(ref, est)
    check_flags(associate=associate)
    ref, est = paired(ref, est, associate=associate, max_diff_s=max_diff_s)
    n = _check_align(align, False, n_to_align, len(ref), source)
    _, est_evo, transform = _aligned_copies(ref, est, align, False, n, source)
    return Trajectory.from_evo(est_evo, name=est.name), transform


def _orthonormalized_if_evo_refuses(metric):
    """Score again on orthonormalized copies when evo refuses a rotation this project's reader accepts: evo's SO(3)
    check of a relative rotation allows 1e-6, the reader 1e-4 (SemanticKITTI's poses of KITTI 00, 1.6e-6, and a KITTI
    file written with 6 decimals could not be scored at all: "matrix is not a valid SO(3) group element"). Tried as
    given first, so that a pair evo takes is scored exactly as evo scores it."""

    @functools.wraps(metric)
    def scored(ref: Trajectory, est: Trajectory, *args, **kwargs):
        try:
            return metric(ref, est, *args, **kwargs)
        except EvaluationError as err:
            if "not a valid SO(3) group element" not in err.reason:
                raise
            logger.info("%s: rotations orthonormalized for evo (%s)", err.source, err.reason)
            return metric(ref.orthonormalized(), est.orthonormalized(), *args, **kwargs)

    return scored


@_orthonormalized_if_evo_refuses
@_float_overflow_quiet
def ape(
    ref: Trajectory,
    est: Trajectory,
    align: str = "none",
    relation: str = "translation",
    *,
    align_origin: bool = False,
    n_to_align: int | None = None,
    associate: bool = False,
    max_diff_s: float = 0.01,
) -> APEResult:
    """Absolute pose error of ``est`` against ``ref`` (evo ``APE``).

    ``align``: one of ``ALIGNMENTS`` (Umeyama on positions, using the first ``n_to_align`` poses or all);
    ``align_origin``: instead move the estimate so its first pose equals the reference's first pose.
    ``relation``: one of ``APE_RELATIONS``; units: translation/point_distance m, rotation_angle_* deg/rad,
    rotation/full unit-less (Frobenius norm of ``R - I`` / ``E - I``).
    Trajectories must have equal length unless ``associate`` (timestamps, within ``max_diff_s``).
    """
    from evo import EvoException
    from evo.core import metrics

    source = pair_name(ref, est)
    check_flags(associate=associate)
    pose_relation = _relation(relation, APE_RELATIONS)
    ref, est = paired(ref, est, associate=associate, max_diff_s=max_diff_s)
    n = _check_align(align, align_origin, n_to_align, len(ref), source)
    ref_evo, est_evo, transform = _aligned_copies(ref, est, align, align_origin, n, source)
    metric = metrics.APE(pose_relation)
    try:
        metric.process_data((ref_evo, est_evo))
    except EvoException as err:
        raise EvaluationError(f"APE failed: {err}", source=source) from err
    stats = _stats(metric, source, f"APE ({relation})", ref, est)
    return APEResult(
        relation=relation,
        unit=metric.unit.value,
        align=align,
        align_origin=bool(align_origin),  # (numpy scalars as plain values: to_dict() is for JSON)
        n_to_align=None if n_to_align is None else int(n_to_align),
        **stats,
        errors=np.array(metric.error, dtype=float),
        alignment=transform,
        ref_name=ref.name,
        est_name=est.name,
        associated=bool(associate),
        title=_title(metric, align, align_origin, n),
        ref=ref,
        est_aligned=Trajectory.from_evo(est_evo, name=est.name),
        warning=alignment_warning(transform) if relation in ORIENTATION_RELATIONS else "",
    )


@_orthonormalized_if_evo_refuses
@_float_overflow_quiet
def rpe(
    ref: Trajectory,
    est: Trajectory,
    delta: float = 1,
    delta_unit: str = "frames",
    *,
    all_pairs: bool = False,
    align: str = "none",
    relation: str = "translation",
    align_origin: bool = False,
    n_to_align: int | None = None,
    rel_delta_tol: float = 0.1,
    pairs_from_reference: bool = False,
    legacy_pairs: bool = False,
    associate: bool = False,
    max_diff_s: float = 0.01,
    pairs: np.ndarray | None = None,
) -> RPEResult:
    """Relative pose error over pose pairs ``delta`` apart (evo ``RPE``).

    ``delta_unit``: frames (integer delta), meters / degrees / radians of travelled path or rotation
    (pairs are chosen on the estimate unless ``pairs_from_reference``; ``all_pairs`` uses every start pose,
    accepting pairs within ``rel_delta_tol * delta``). Error per pair: ``E = (Q_i^-1 Q_j)^-1 (P_i^-1 P_j)``.
    ``legacy_pairs``: path/angle deltas only, consecutive pairs: reproduce the 2018 evo releases that made
    evo's stored reference results, whose first pair began at the first pose reaching ``delta`` instead
    of at pose 0; i.e. the first pair of today's selection is dropped.
    ``pairs``: the pairs an earlier call with the same trajectories and selection chose (``RPEResult.pairs``), so that
    its translation and rotation RPE search once: evo's all-pairs search over a path or angle delta is quadratic
    (4 searches for the two relations took 25 s on 1500 poses).
    """
    from evo import EvoException
    from evo.core import metrics
    from evo.core.units import Unit

    source = pair_name(ref, est)
    check_flags(all_pairs=all_pairs, pairs_from_reference=pairs_from_reference, legacy_pairs=legacy_pairs, associate=associate)
    pose_relation = _relation(relation, RPE_RELATIONS)
    delta, delta_unit = checked_delta(delta, delta_unit)
    unit = Unit[delta_unit]
    check_legacy_pairs(legacy_pairs, delta_unit, all_pairs)
    if not (is_real_number(rel_delta_tol) and 0 <= rel_delta_tol < 1):  # ("x": a bare TypeError)
        raise ConfigError(f"rel_delta_tol must be a number in [0, 1), got {rel_delta_tol!r}", source="rel_delta_tol")
    ref, est = paired(ref, est, associate=associate, max_diff_s=max_diff_s)
    n = _check_align(align, align_origin, n_to_align, len(ref), source)
    if unit is Unit.frames and int(delta) >= len(ref):
        raise EvaluationError(f"delta of {int(delta)} frames needs more than {len(ref)} poses", source=source)
    ref_evo, est_evo, transform = _aligned_copies(ref, est, align, align_origin, n, source)

    evo_delta: float = int(delta) if unit is Unit.frames else delta
    given = pairs is not None
    if given and relation in ("point_distance", "point_distance_error_ratio"):
        # (evo found its own pairs from the delta for these: 199 errors for the 3 pairs given, reported as those 3;
        # with legacy_pairs the given pairs were read as a chain: (0, 50), (100, 200) scored as (0, 50), (50, 200))
        raise ConfigError(f"pairs= is not supported for the {relation} relation (evo pairs the poses itself); use delta",
                          source="pairs")
    if given:
        pairs = _checked_pairs(pairs, len(ref), source)
    try:
        if pairs is None:
            paired_on = ref_evo if pairs_from_reference else est_evo
            # (evo prints the all-pairs search's progress, "0 %12 %25 %..." without a line end: it went into the tables
            # on stdout, then onto their title line on stderr; kept out of both)
            try:
                with contextlib.redirect_stdout(io.StringIO()):
                    found = metrics.id_pairs_from_delta(paired_on.poses_se3, evo_delta, unit, rel_delta_tol, all_pairs=all_pairs)
            except EvoException:
                # (evo's "produced an empty index list - try ... a less strict tolerance" hid the reason)
                side = "reference" if pairs_from_reference else "estimate"
                if unit is Unit.meters and delta > paired_on.path_length:
                    side += " as aligned" if transform and transform.rescaled else ""
                    raise EvaluationError(f"delta = {delta:g} m exceeds the path length of the {side} ({paired_on.path_length:.4g} m): "
                                          "no two poses are that far apart along it", source=source) from None
                if unit in (Unit.degrees, Unit.radians) and not all_pairs:
                    turned = _accumulated_angle(paired_on.poses_se3, unit is Unit.degrees)
                    if delta > turned:
                        raise EvaluationError(f"delta = {delta:g} {delta_unit} exceeds the rotation accumulated along the {side} "
                                              f"({turned:.4g} {delta_unit}): no two poses are that far apart in orientation along it",
                                              source=source) from None
                if unit in (Unit.degrees, Unit.radians) and all_pairs:  # (the direct angle between two poses)
                    widest = _widest_angle(paired_on.poses_se3, unit is Unit.degrees)
                    if delta > widest + rel_delta_tol * delta:
                        raise EvaluationError(f"delta = {delta:g} {delta_unit}: no two poses of the {side} are that far apart "
                                              f"in orientation (the widest is {widest:.4g} {delta_unit})", source=source) from None
                raise
            pairs = np.array(found, dtype=np.int64).reshape(-1, 2)
        # given pairs are compared as given (an earlier call's selection: its first legacy pair already dropped; the
        # second drop left the rotation RPE of `lidarkit eval --legacy-pairs` a pair short of the translation's)
        laid_out = ((all_pairs and unit is not Unit.frames) or given) and len(pairs) > 0 and relation not in (
            "point_distance", "point_distance_error_ratio")
        if laid_out:
            # evo would search the pairs again (quadratic): it compares consecutive poses of copies laid out as
            # i0, j0, i1, j1, ... instead, and every second error is one of the pairs
            layout = pairs.reshape(-1)
            ref_evo.reduce_to_ids(layout)
            est_evo.reduce_to_ids(layout)
            metric = metrics.RPE(pose_relation, 1, Unit.frames, rel_delta_tol, False, pairs_from_reference)
            metric.process_data((ref_evo, est_evo))
            metric.error = np.asarray(metric.error)[::2]
            metric.delta_ids = list(pairs[:, 1])
        elif legacy_pairs:
            # Consecutive pairs form a chain; reduce both copies to the chain without its first pair and
            # let evo compare consecutive poses of the reduced copies.
            pairs = pairs[1:]  # (given pairs were laid out above)
            if len(pairs) == 0:
                raise EvaluationError(
                    f"delta = {delta:g} ({delta_unit}) leaves no pair after dropping the first one", source=source
                )
            chain = np.concatenate([pairs[:1, 0], pairs[:, 1]])
            ref_evo.reduce_to_ids(chain)
            est_evo.reduce_to_ids(chain)
            metric = metrics.RPE(pose_relation, 1, Unit.frames, rel_delta_tol, False, pairs_from_reference)
        else:
            metric = metrics.RPE(pose_relation, evo_delta, unit, rel_delta_tol, all_pairs, pairs_from_reference)
        if not laid_out:  # (the laid-out copies were compared above)
            # (evo searches the pairs of point_distance relations again here, printing its progress as above)
            with contextlib.redirect_stdout(io.StringIO()):
                metric.process_data((ref_evo, est_evo))
    except EvoException as err:
        raise EvaluationError(f"RPE failed: {err}", source=source) from err
    stats = _stats(metric, source, f"RPE ({relation})", ref, est)
    if relation == "point_distance_error_ratio":
        # evo drops the pairs over which the reference stands still (no ratio); the same test here keeps each error at
        # its pair (matching end indices kept a dropped pair whose end another pair shared; legacy pairs kept all)
        ref_xyz = ref.positions_xyz
        pairs = pairs[np.linalg.norm(ref_xyz[pairs[:, 1]] - ref_xyz[pairs[:, 0]], axis=1) > 0]
    # the laid-out and legacy copies were compared as consecutive frames: title the selection that was scored (all-pairs
    # and given pairs read "delta = 1 (frames) using consecutive pairs")
    metric.delta, metric.delta_unit, metric.all_pairs = evo_delta, unit, all_pairs
    title = _title(metric, align, align_origin, n)
    if legacy_pairs:
        title = title.replace(" using consecutive pairs", ", legacy pairs using consecutive pairs")
    return RPEResult(
        relation=relation,
        unit=metric.unit.value,
        align=align,
        align_origin=bool(align_origin),  # (numpy scalars as plain values: to_dict() is for JSON)
        n_to_align=None if n_to_align is None else int(n_to_align),
        **stats,
        errors=np.array(metric.error, dtype=float),
        alignment=transform,
        ref_name=ref.name,
        est_name=est.name,
        associated=bool(associate),
        title=title,
        ref=ref,
        est_aligned=_est_from_evo_unreduced(est, transform, align_origin),
        delta=int(delta) if unit is Unit.frames else delta,
        delta_unit=delta_unit,
        all_pairs=bool(all_pairs),
        pairs_from_reference=bool(pairs_from_reference),
        legacy_pairs=bool(legacy_pairs),
        pairs=pairs,
    )


def _est_from_evo_unreduced(est: Trajectory, transform: AlignmentTransform | None, align_origin: bool) -> Trajectory:
    """The full estimate with the applied alignment (the evo copy may have been reduced to pair ids)."""
    return est if transform is None else transform.applied_to(est)
