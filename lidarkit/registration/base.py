"""The registration interface: every ICP variant returns a :class:`RegistrationResult`.

Convention: ``align(source_xyz, target_xyz, init_T)`` estimates ``T_target_source``, the pose that maps
points of the source cloud into the target cloud's frame (``target ~= T_target_source @ source``).
For two consecutive scans with LiDAR poses ``T_world_a`` (target) and ``T_world_b`` (source) the
ground truth is ``inv(T_world_a) @ T_world_b``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal

import numpy as np
import pydantic
from pydantic import BaseModel, ConfigDict, Field, model_validator

from lidarkit.errors import ConfigError, DataError, LidarKitError, RegistrationError, validation_problems
from lidarkit.geometry import MAX_ABS_COORDINATE_M, as_points, is_rotation, orthonormalize_se3
from lidarkit.params import changed_fields, refuse_yes_no_numbers
from lidarkit.registration import local_origin
from lidarkit.registration.covariance import use_model

#: A result is flagged ``degenerate`` when min/max eigenvalue of the normalised normal matrix is below this
#: (KITTI full scans: ~0.3; road-only patches: 5e-4 to 8e-3; see degeneracy.py).
DEGENERACY_RATIO_THRESHOLD = 1e-2

#: Order of the 6 parameters of the normal matrix and of ``weakest_direction``.
TWIST_ORDER = ("tx", "ty", "tz", "rx", "ry", "rz")


#: Default acceptance gate on the final fitness (fraction of source points with a correspondence within the
#: variant's inlier distance). Good pairs score far above it (KITTI consecutive scans > 0.94, the fast_gicp
#: sample pair ~0.8), while a start 30 m off that "converges" onto a wrong local minimum scores 0.02-0.22.
DEFAULT_MIN_FITNESS = 0.3

#: An initial guess's rotation block must be orthonormal to this (rounding to 3-4 decimals passes; 2*I does not).
INIT_ROTATION_TOL = 1e-3

#: Default minimum number of final correspondences for a result to count as converged.
DEFAULT_MIN_CORRESPONDENCES = 10


class InvalidParameters(ConfigError, ValueError):
    """A variant config's invalid values in one line (``"max_iterations: Input should be ..."``). A ValueError too: a
    caller that names the variant around a config's ValueError (``get_icp``) keeps its message."""


class RegistrationConfig(BaseModel):
    """Base of every variant's typed config: frozen, unknown keys rejected.

    ``min_fitness`` / ``min_correspondences`` are the acceptance gate every variant applies to its final
    alignment (see :meth:`Registration.align`): below either, the result is reported ``converged=False``.
    """

    # NaN and infinity are refused in every field (``voxel_size_m=inf`` passed ``gt=0``); "no limit" is None
    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    min_fitness: float = Field(
        DEFAULT_MIN_FITNESS, ge=0, le=1, description="final fitness below this -> not converged (good pairs: > 0.8)"
    )
    min_correspondences: int = Field(
        DEFAULT_MIN_CORRESPONDENCES, ge=3, description="fewer final correspondences than this -> not converged"
    )
    covariance: Literal["censi", "gauss_newton", "none"] = Field(
        "censi", description="closed form of the result's 6x6 covariance (none: skip it)"
    )
    calibrated_covariance: bool = Field(
        True, description="apply the variant's measured translation/rotation factors (benchmarks/covariance_calibration.py; "
        "learned on covariance='censi' and applied to it only: gauss_newton is returned as computed)"
    )
    assess: bool = Field(
        True, description="score the result once the backend returns: final correspondences, fitness, RMSE, degeneracy summary, "
        "covariance, acceptance gate (False: the backend's pose and its own verdict only, near the library's speed; for the "
        "variants that register apart from their assessment: kiss, small_gicp, the Open3D ones)"
    )

    def __init__(self, /, **data: Any) -> None:
        """Invalid values raise :class:`InvalidParameters` naming each field (``VanillaConfig(max_iterations=0)``
        raised pydantic's ValidationError, lines long with a URL, where ``get_icp`` said it in one line)."""
        try:
            super().__init__(**data)
        except pydantic.ValidationError as err:
            raise InvalidParameters(validation_problems(err, unnamed="")) from None

    @model_validator(mode="before")
    @classmethod
    def _numbers_are_not_yes_or_no(cls, data: Any) -> Any:
        """A yes/no value for a number field (``-p max_iterations=yes``) is refused (:func:`refuse_yes_no_numbers`)."""
        return refuse_yes_no_numbers(cls, data)

    @model_validator(mode="after")
    def _assessment_settings_need_the_assessment(self) -> "RegistrationConfig":
        """Settings of the assessment given with ``assess=False`` (accepted and ignored: no gate, no covariance)."""
        given = changed_fields(self, ("min_fitness", "min_correspondences", "covariance", "calibrated_covariance"))
        if not self.assess and given:
            raise ValueError(f"{', '.join(given)} set(s) the assessment, which assess=False leaves out")
        if self.covariance != "censi" and changed_fields(self, ("calibrated_covariance",)):  # (accepted and ignored)
            raise ValueError(f"calibrated_covariance sets the calibration of covariance='censi' (learned on it), "
                             f"not {self.covariance!r}")
        return self

    def covariance_model(self):
        """The :class:`~lidarkit.registration.covariance.CovarianceModel` this config asks for (None: no covariance)."""
        from lidarkit.registration.covariance import CovarianceModel

        return None if self.covariance == "none" else CovarianceModel(method=self.covariance)


def json_safe(value: Any) -> Any:
    """``value`` with numpy scalars/arrays turned into Python data and NaN / +-inf into None (strict JSON)."""
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if isinstance(value, np.ndarray):
        return json_safe(value.tolist())
    if isinstance(value, (np.bool_, bool)):
        return bool(value)
    if isinstance(value, (np.integer, int)):
        return int(value)
    if isinstance(value, (np.floating, float)):
        return float(value) if np.isfinite(value) else None
    return value


@dataclass(frozen=True)
class Degeneracy:
    """How well the final alignment constrains the 6 degrees of freedom.

    ``eigenvalues``: ascending eigenvalues of the normalised 6x6 normal matrix ``J^T M J / n``
    (the rotation about each axis scaled by the RMS distance of the matched points from that axis, so all six
    are in m^2 / m^2);
    ``condition_number``: max/min eigenvalue (inf if min is 0); ``degenerate``: min/max below
    ``threshold``; ``weakest_direction``: unit eigenvector of the smallest eigenvalue in
    ``TWIST_ORDER`` (tx, ty, tz, rx, ry, rz); ``kind``: which residual the normal matrix models;
    ``weak_directions``: the eigen-directions below ``threshold`` in words, in the target sensor frame
    (e.g. ``"translation along x"``; near-equal weak eigenvalues named once by the axes they span, e.g.
    ``"translation along x and y, rotation about z (yaw)"``), empty when nothing is degenerate; ``weakest_name``: the weakest direction in
    words, whether or not it is below ``threshold``.
    """

    eigenvalues: tuple[float, ...]
    condition_number: float
    degenerate: bool
    weakest_direction: tuple[float, ...]
    threshold: float = DEGENERACY_RATIO_THRESHOLD
    kind: str = "point_to_surface"
    weak_directions: tuple[str, ...] = ()
    weakest_name: str = ""

    @property
    def ratio(self) -> float:
        """min/max eigenvalue (0 for a fully degenerate problem; NaN where nothing was assessed, not 0 beside
        ``degenerate=False``)."""
        top = self.eigenvalues[-1]
        if np.isnan(top):
            return float("nan")
        return float(self.eigenvalues[0] / top) if top > 0 else 0.0

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-ready data; an infinite condition number becomes None."""
        out = dataclasses.asdict(self)
        out["ratio"] = self.ratio
        out["twist_order"] = list(TWIST_ORDER)
        return json_safe(out)

    @staticmethod
    def not_assessed() -> "Degeneracy":
        """The summary of a result registered with ``assess=False``: nothing known, nothing flagged."""
        nan = float("nan")
        return Degeneracy(eigenvalues=(nan,) * 6, condition_number=nan, degenerate=False, weakest_direction=(nan,) * 6,
                          kind="not assessed (assess=False)")

    @staticmethod
    def unknown(reason: str = "not computed") -> "Degeneracy":
        """A placeholder for results where no correspondences exist: no geometry to judge, so nothing is known or
        flagged (flagged degenerate, with eigenvalues 0, a pair 100x apart read "degenerate geometry" before "only 0
        correspondences")."""
        nan = float("nan")
        return Degeneracy(eigenvalues=(nan,) * 6, condition_number=nan, degenerate=False, weakest_direction=(nan,) * 6,
                          kind=f"unknown ({reason})")


#: ``extra`` key of the covariance as calibrated about ``extra["covariance_origin_m"]`` (before it was moved to the
#: target frame's origin): :meth:`RegistrationResult.covariance_about` returns it exactly
LOCAL_COVARIANCE_KEY = "covariance_about_origin"


def calibration_note(variant: str, learned: str | None) -> str:
    """What calibrated a variant's covariance, in words (``extra["covariance_calibration"]``)."""
    if learned is None:
        return f"none learned for {variant}: the closed form as computed (typically over-confident)"
    return learned if learned == variant else f"{learned}'s (inherited by {variant})"


def _briefly(value: Any) -> str:
    """``value`` for a one-line message: an array by its shape (its repr spans lines), anything else by its repr, cut."""
    if isinstance(value, np.ndarray):
        bad = int((~np.isfinite(value)).sum()) if value.dtype.kind in "fc" else 0
        return f"an array of shape {value.shape}" + (f" with {bad} NaN or infinite entries" if bad else "")
    text = " ".join(repr(value).split())
    return text if len(text) <= 60 else text[:57] + "..."


def _adjoint_about(c: np.ndarray) -> np.ndarray:
    """``Ad(S)^-1``, ``S`` the translation to the point ``c``: takes a covariance's perturbation from the frame's origin
    to ``c`` (``Ad Sigma Ad^T``)."""
    from lidarkit.registration.covariance import adjoint

    S_inv = np.eye(4)
    S_inv[:3, 3] = -c
    return adjoint(S_inv)


@dataclass(frozen=True)
class RegistrationResult:
    """Outcome of one pairwise registration.

    ``T_target_source``: ``(4, 4)`` float64; ``rmse_history``: RMSE (m) of the correspondences as the variant's
    loop measured them, oldest first (lidarkit's point-to-point loops: at the initial guess and after each iteration,
    ``iterations + 1`` values, the first ``extra["coarse_iterations"] + 1`` of a coarse-to-fine run over every
    ``extra["coarse_stride"]``-th source point, the rest over all of them; ``pipeline``: at the start of each iteration over its own pairs, then at the final pose over the assessment's pairs (those of ``fitness``, as kiss reports it); the final RMSE alone where the library
    reports no RMSE per iteration: small_gicp, Open3D, kiss, genz); ``fitness``: fraction of source points with a
    correspondence within the inlier distance at the solution; ``reason``: why it did not converge or was flagged ("" if all is well);
    ``covariance``: ``(6, 6)`` uncertainty of ``T_target_source`` (left perturbation in the target frame,
    translation first, m and rad: see ``lidarkit.registration.covariance``), None where it was not computed;
    ``surface_step``: ``(6,)`` one Gauss-Newton step of the point-to-surface residuals from ``T_target_source``, in
    the covariance's convention: where the local surfaces would move the pose (the variant's systematic error as the
    data show it; the calibrated covariance includes it), None with the covariance.
    """

    T_target_source: np.ndarray
    converged: bool
    iterations: int
    rmse_history: tuple[float, ...]
    n_correspondences: int
    runtime_s: float
    fitness: float
    degeneracy: Degeneracy
    reason: str = ""
    method: str = ""
    extra: dict[str, Any] = field(default_factory=dict)
    covariance: np.ndarray | None = None
    surface_step: np.ndarray | None = None

    @property
    def information(self) -> np.ndarray | None:
        """Inverse of ``covariance`` (eigenvalues floored, so unconstrained directions get ~0 information), inverted
        about ``extra["covariance_origin_m"]`` where there is one: the stored matrix of a target at UTM coordinates is
        conditioned ~1e25, and its floored inverse lost the z and yaw information (2e-4 where 5.9e5 is exact)."""
        if self.covariance is None:
            return None
        from lidarkit.registration.assessment import COVARIANCE_ORIGIN_KEY
        from lidarkit.registration.covariance import safe_inverse

        at = self.extra.get(COVARIANCE_ORIGIN_KEY)
        if at is None:
            return safe_inverse(self.covariance)
        Ad = _adjoint_about(np.asarray(at, dtype=np.float64))  # covariance_about(c) = Ad covariance Ad^T: its inverse
        return Ad.T @ safe_inverse(self.covariance_about(at)) @ Ad  # is Ad^T information_c Ad

    def covariance_about(self, origin_m: np.ndarray | list[float]) -> np.ndarray | None:
        """``covariance`` with the perturbation taken about the point ``origin_m`` (m, target frame) instead of the
        target frame's origin: ``Ad(S)^-1 Sigma Ad(S)^-T``, ``S`` the translation to it. About
        ``extra["covariance_origin_m"]`` (a target far from its frame's origin: a map frame, UTM) it is the covariance
        as calibrated there, exactly, where moving the stored one back would lose what float64 cannot hold."""
        if self.covariance is None:
            return None
        from lidarkit.registration.assessment import COVARIANCE_ORIGIN_KEY

        try:
            c = np.asarray(origin_m, dtype=np.float64).reshape(3)
        except (TypeError, ValueError):
            c = np.full(3, np.nan)
        if not np.isfinite(c).all():  # (a NaN origin gave a NaN matrix without a word)
            raise ConfigError(f"origin_m must be 3 finite numbers (m), got {_briefly(origin_m)}", source="covariance_about")
        local = self.extra.get(LOCAL_COVARIANCE_KEY)
        at = self.extra.get(COVARIANCE_ORIGIN_KEY)
        if local is not None and at is not None and np.array_equal(c, np.asarray(at, dtype=np.float64)):
            return np.array(local, dtype=np.float64)
        Ad = _adjoint_about(c)
        return Ad @ self.covariance @ Ad.T

    def nees(self, T_target_source_true: np.ndarray) -> float:
        """Normalized estimation error squared of this pose against the true one, ``xi^T Sigma^-1 xi`` (6 on average
        for a calibrated covariance; NaN without one), with ``T_true = se3_exp(xi) T`` taken about
        ``extra["covariance_origin_m"]`` when there is one: exact at any coordinates (``nees`` of
        :mod:`lidarkit.registration.covariance` with the stored covariance is not, far from the frame's origin). A planar
        result is scored over what it estimated, x, y and yaw (3 on average): its z, roll and pitch carry no variance,
        and their true values' error against none read as 1e10."""
        if self.covariance is None:
            return float("nan")
        from lidarkit.geometry import se3_inverse, se3_log
        from lidarkit.registration.assessment import COVARIANCE_ORIGIN_KEY
        from lidarkit.registration.covariance import nees

        from lidarkit.geometry import is_rotation

        try:
            true = np.asarray(T_target_source_true, dtype=np.float64)
        except (TypeError, ValueError):  # (a string: numpy's ValueError)
            raise ConfigError(f"T_target_source_true must be a finite 4x4 rigid transform, got {_briefly(T_target_source_true)}",
                              source="nees") from None
        if true.shape != (4, 4) or not np.isfinite(true).all() or not is_rotation(true[:3, :3]) or not np.allclose(true[3], [0, 0, 0, 1]):
            # (a 3x3 gave numpy's matmul error, NaN an SVD that did not converge, a scaled pose a number)
            raise ConfigError(f"T_target_source_true must be a finite 4x4 rigid transform, got shape {true.shape}"
                              + ("" if true.shape != (4, 4) else " (not finite, or not a rotation with a [0 0 0 1] last row)"),
                              source="nees")
        c = np.asarray(self.extra.get(COVARIANCE_ORIGIN_KEY, (0.0, 0.0, 0.0)), dtype=np.float64)
        S = np.eye(4)
        S[:3, 3] = c
        error = se3_log(se3_inverse(S) @ true @ se3_inverse(self.T_target_source) @ S)
        covariance = self.covariance_about(c)
        estimated = np.flatnonzero(np.any(covariance != 0.0, axis=1))  # (a planar solve: rows of z, roll, pitch zero)
        if len(estimated) < 6:
            return float(error[estimated] @ np.linalg.pinv(covariance[np.ix_(estimated, estimated)]) @ error[estimated])
        return nees(error, covariance)

    def __repr__(self) -> str:
        """One line of the headline figures (the generated one printed the whole rmse_history, the 6x6 covariance and
        the degeneracy: ~2000 characters)."""
        from lidarkit.geometry import rotation_angle_deg

        T = np.asarray(self.T_target_source)
        state = "converged" if self.converged else "not converged"
        weak = f", degenerate: {'; '.join(self.degeneracy.weak_directions)}" if self.degeneracy.degenerate else ""
        why = f", reason {self.reason!r}" if self.reason else ""
        # (without the assessment, assess=False, there are no correspondences to count: no rmse, fitness, count)
        fit = (f", rmse {self.rmse:.4g} m, fitness {self.fitness:.3g}, {self.n_correspondences} correspondences"
               if self.n_correspondences >= 0 else ", not assessed")
        # (Open3D reports no iteration count: "converged in 0 iterations" read as a count)
        steps = f" in {self.iterations} iterations" if self.extra.get("iterations_reported", True) else " (iterations not reported)"
        return (f"RegistrationResult({self.method!r}, {state}{steps}, t [{', '.join(f'{v:.4g}' for v in T[:3, 3])}] m, "
                f"rotation {float(rotation_angle_deg(T[:3, :3])):.4g} deg{fit}, {self.runtime_s:.3g} s{weak}{why})")

    @property
    def rmse(self) -> float:
        """Final RMSE (m) of the correspondences, NaN if there was none."""
        return float(self.rmse_history[-1]) if self.rmse_history else float("nan")

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-ready data; non-finite numbers (NaN RMSE, infinite condition number) become None."""
        return json_safe({
            "method": self.method,
            "T_target_source": np.asarray(self.T_target_source).tolist(),
            "converged": bool(self.converged),
            "iterations": int(self.iterations),
            "rmse_m": self.rmse,
            "rmse_history": [float(x) for x in self.rmse_history],
            "n_correspondences": int(self.n_correspondences),
            "runtime_s": float(self.runtime_s),
            "fitness": float(self.fitness),
            "degeneracy": self.degeneracy.to_dict(),
            "reason": self.reason,
            "extra": self.extra,
            "covariance": None if self.covariance is None else np.asarray(self.covariance).tolist(),
            "surface_step": None if self.surface_step is None else np.asarray(self.surface_step).tolist(),
        })


def finite_4x4(T: np.ndarray, source: str, what: str = "matrix") -> np.ndarray:
    """``T`` as a float64 4x4 array; DataError naming ``source`` for another shape or NaN / infinite entries."""
    try:
        T = np.asarray(T, dtype=np.float64)
    except (TypeError, ValueError):
        raise DataError(f"expected a 4x4 {what} of numbers, got {type(T).__name__} {str(T)[:40]!r}", source=source) from None
    if T.shape != (4, 4):
        raise DataError(f"expected a 4x4 {what}, got shape {T.shape}", source=source)
    if not np.isfinite(T).all():
        raise DataError(f"{int((~np.isfinite(T)).sum())} of its 16 entries are NaN or infinite", source=source)
    return T


def as_point_times(point_times_s: np.ndarray, source: str = "point_times_s") -> np.ndarray:
    """Per-point times as a flat float64 array; DataError naming ``source`` for something that is not numbers (a string
    ended the run in a raw ValueError "could not convert string to float")."""
    try:
        return np.asarray(point_times_s, dtype=np.float64).ravel()
    except (TypeError, ValueError):
        raise DataError(f"expected per-point times in seconds (numbers), got {type(point_times_s).__name__} "
                        f"{str(point_times_s)[:40]!r}", source=source) from None


def check_point_times(point_times_s: np.ndarray, n_points: int, source: str = "point_times_s") -> np.ndarray:
    """``(N,)`` float64 per-point times of a sweep of ``n_points``; DataError naming ``source`` for another count or for
    NaN / infinite times, saying which (both read "need 54850 finite per-point times, got 54850")."""
    times = as_point_times(point_times_s, source)
    if len(times) != n_points:
        raise DataError(f"{len(times)} per-point times for {n_points} points: one per point is needed", source=source)
    bad = int((~np.isfinite(times)).sum())
    if bad:
        raise DataError(f"{bad} of the {n_points} per-point times are NaN or infinite", source=source)
    return times


def check_sweeps_apart(value: object) -> float:
    """``sweeps_apart`` (sweeps between two frames, which a deskew scales its motion by) as a float; ConfigError for
    anything but a finite number > 0 (0 divided the motion by zero)."""
    from lidarkit.params import is_real_number

    if not is_real_number(value) or not np.isfinite(value) or value <= 0:
        raise ConfigError(f"sweeps_apart must be a finite number of sweeps > 0, got {value!r}", source="sweeps_apart")
    return float(value)


def check_init_T(init_T: np.ndarray, source: str = "init_T") -> np.ndarray:
    """A validated initial guess with an exactly orthonormal rotation (see :func:`check_pair`)."""
    T0 = finite_4x4(init_T, source)
    if not np.array_equal(T0[3], [0.0, 0.0, 0.0, 1.0]):
        raise DataError(f"last row must be [0, 0, 0, 1], got {T0[3].tolist()}", source=source)
    if not is_rotation(T0[:3, :3], tol=INIT_ROTATION_TOL):
        raise DataError(f"the 3x3 block is not a rotation (R^T R = I within {INIT_ROTATION_TOL:g}, det > 0)", source=source)
    reach_m = float(np.abs(T0[:3, 3]).max())
    if reach_m > MAX_ABS_COORDINATE_M:  # (as a point beyond it is refused: 1e200 m overflowed to "inf m" from the target)
        raise DataError(f"the translation has a coordinate of {reach_m:.3g} m, beyond {MAX_ABS_COORDINATE_M:g} m: not a "
                        "metric pose", source=source)
    return orthonormalize_se3(T0)


def check_pair(
    source_xyz: np.ndarray, target_xyz: np.ndarray, init_T: np.ndarray | None, min_points: int = 3
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Validate a registration input: two ``(N, 3)`` finite clouds of >= ``min_points`` and a 4x4 guess.

    Returns float64 copies-or-views and the initial guess with an exactly orthonormal rotation. The guess
    must already be a rigid transform up to rounding (``R^T R = I`` within ``INIT_ROTATION_TOL``,
    ``det R > 0``, last row ``[0, 0, 0, 1]``); anything else (a scaled matrix, a projective row) is refused
    rather than silently projected onto SE(3).
    """
    src = as_points(source_xyz, "source cloud", min_points=min_points)
    dst = as_points(target_xyz, "target cloud", min_points=min_points)
    for name, cloud in (("source cloud", src), ("target cloud", dst)):
        probe = cloud[:: max(1, len(cloud) // 64)]
        if not np.ptp(probe, axis=0).any() and not np.ptp(cloud, axis=0).any():  # (the whole cloud only when the probe is)
            raise DataError(f"all {len(cloud)} points are one point ({', '.join(f'{v:g}' for v in cloud[0])}): nothing to register",
                            source=name)
    T0 = np.eye(4) if init_T is None else check_init_T(init_T)
    return src, dst, T0


NO_OVERLAP_MARGIN = 0.05  # boxes further apart than 5 % of the target's extent (at least 1 m) do not overlap
_OVERLAP_PROBES = 64  # source points moved first by initial_gap_m (an evenly strided sample)
_BOX_SAMPLE = 1024  # target points whose box initial_gap_m tries first


def bounds(points_xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-axis ``(min, max)`` of ``(N, 3)`` points, one column at a time (an ``axis=0`` reduction over three
    columns is ~20x slower in numpy)."""
    cols = [points_xyz[:, i] for i in range(3)]
    return np.array([c.min() for c in cols]), np.array([c.max() for c in cols])


def initial_gap_m(source_xyz: np.ndarray, target_xyz: np.ndarray, T0: np.ndarray) -> float | None:
    """Distance (m) between the bounding boxes of the source moved by ``T0`` and the target when they do not
    overlap (beyond a margin); None when they do. ICP from no overlap converges to a meaningless local fit."""
    from lidarkit.geometry import transform_points

    # the moved source's box holds each of its moved points, so one of them within the margin of the target's box
    # already settles "overlap" (the usual case) without moving the whole cloud; otherwise the exact boxes decide.
    # The box of an evenly strided sample of the target lies inside the target's box, with a margin no larger, so a
    # probe within that margin of it is within the margin of the whole box too: the sample settles the usual case
    # without a pass over the whole target (~0.6 ms on a KITTI scan)
    probe = transform_points(T0, source_xyz[:: max(1, len(source_xyz) // _OVERLAP_PROBES)])
    for target in (target_xyz[:: max(1, len(target_xyz) // _BOX_SAMPLE)], target_xyz):
        lo_t, hi_t = bounds(target)
        margin = max(1.0, NO_OVERLAP_MARGIN * float(np.linalg.norm(hi_t - lo_t)))
        outside = np.maximum(0.0, np.maximum(probe - hi_t, lo_t - probe))
        if float(np.einsum("ij,ij->i", outside, outside).min()) <= margin**2:
            return None
    lo_s, hi_s = bounds(transform_points(T0, source_xyz))
    gap = np.maximum(0.0, np.maximum(lo_s - hi_t, lo_t - hi_s))
    distance = float(np.linalg.norm(gap))
    return distance if distance > margin else None


def no_overlap_result(T0: np.ndarray, gap_m: float, method: str) -> RegistrationResult:
    """The flagged result for a pair that starts without overlap (no iteration run)."""
    return RegistrationResult(
        T_target_source=T0.copy(), converged=False, iterations=0, rmse_history=(), n_correspondences=0, runtime_s=0.0,
        fitness=0.0, degeneracy=Degeneracy.unknown("no initial overlap"), method=method,
        reason=f"no initial overlap: the source (moved by the initial guess) is {gap_m:.1f} m from the target's "
               "bounding box; pass init_T",
    )


def unassessed_result(T_target_source: np.ndarray, converged: bool, method: str, runtime_s: float,
                      iterations: int | None = None, reason: str = "") -> RegistrationResult:
    """The result of an alignment with ``assess=False``: the backend's pose and verdict, and its iteration count where
    it reports one (``iterations``), nothing counted or scored (no correspondences: -1, fitness and RMSE unknown, no
    covariance, no acceptance gate). ``reason``: why the backend did not converge, where it knows (kiss's cap), kept in
    place of the generic one."""
    within = "" if iterations is None else f" in {iterations} iterations"
    return RegistrationResult(
        T_target_source=np.asarray(T_target_source, dtype=np.float64), converged=converged, iterations=iterations or 0,
        rmse_history=(), n_correspondences=-1, runtime_s=runtime_s, fitness=float("nan"), degeneracy=Degeneracy.not_assessed(),
        reason="" if converged else reason or f"{method} reports no convergence{within}", method=method,
        extra={"assessed": False, "iterations_reported": iterations is not None},
    )


def accept(result: RegistrationResult, config: RegistrationConfig) -> RegistrationResult:
    """Apply the config's acceptance gate: too few correspondences or too low a fitness -> not converged."""
    if not result.converged:
        return result
    problems = []
    if result.n_correspondences < config.min_correspondences:
        problems.append(f"only {result.n_correspondences} correspondences (min_correspondences={config.min_correspondences})")
    if not np.isfinite(result.fitness) or result.fitness < config.min_fitness:
        problems.append(f"fitness {result.fitness:.3f} below min_fitness={config.min_fitness:g}")
    if not problems:
        return result
    return dataclasses.replace(result, converged=False, reason="; ".join([result.reason, *problems] if result.reason else problems))


@functools.lru_cache(maxsize=None)
def _learned_composition(klass: type) -> dict[str, Any]:
    """What a variant built with its defaults (where its calibration was learned) resolves its components to."""
    return klass().describe()


@functools.lru_cache(maxsize=None)
def _learned_config(klass: type) -> Any:
    """A variant's default config: the settings its calibration was learned at."""
    return klass.Config()


def _as_learned(value: Any, learned: Any, band: tuple[float, float] | None) -> bool:
    """True if a setting's ``value`` is the one the entry was learned at ``learned``, or within its measured ``band``."""
    if band is not None and isinstance(value, (int, float)) and not isinstance(value, bool):
        return band[0] <= value <= band[1]
    return value == learned


#: a composition's settings every component is handed (the range crop, the voxel size): not the residual model
_SHARED_SETTINGS = ("max_range_m", "min_range_m", "voxel_size_m")


def _own_settings(described: Any) -> Any:
    """A component's description (or a list of them) without the shared settings it was handed."""
    if isinstance(described, list):
        return [_own_settings(d) for d in described]
    return {k: v for k, v in described.items() if k not in _SHARED_SETTINGS} if isinstance(described, dict) else described


#: what a backend (Open3D, kiss-icp, small_gicp, scipy under a plugin, a plugin's own arithmetic) raises when it fails on
#: a pair; shared with the odometry runner, which reports them as the frame's error (a ZeroDivisionError or KeyError
#: in a plugin's ``_align`` was one line there, a traceback from ``lidarkit icp``; so were an AssertionError, an OSError and
#: a LookupError). lidarkit's own errors are no OSError: they pass :func:`use_backend` unchanged
BACKEND_ERRORS = (RuntimeError, ValueError, MemoryError, LookupError, TypeError, ArithmeticError, AssertionError, OSError,
                  ImportError, NameError, StopIteration)


@contextlib.contextmanager
def use_backend(name: str, source: str) -> Iterator[None]:
    """A backend's own refusal (RuntimeError, ValueError, ... from Open3D, kiss-icp, small_gicp) becomes a
    :class:`RegistrationError` naming the variant and the clouds; lidarkit's own errors pass unchanged. An
    AttributeError in the block (a plugin's slip in ``_align``) becomes one too; outside it, the odometry runner lets
    an AttributeError through as the programming error it is."""
    try:
        yield
    except LidarKitError:
        raise
    except (*BACKEND_ERRORS, AttributeError) as err:
        raise RegistrationError(f"the {name} backend failed on this pair: {type(err).__name__}: {err}", source=source) from err


class PendingAlignment:
    """A registration whose pose is known and whose assessment is still to come (:meth:`Registration.align_deferred`).

    ``T_target_source``: the backend's pose (the result's, whatever the assessment says); ``likely_converged``: the
    backend's own verdict, which the result's ``converged`` keeps unless the acceptance gate (too few correspondences,
    too low a fitness) turns it down. :meth:`result` runs the assessment once (thread-safe) and returns the result.
    """

    def __init__(self, T_target_source: np.ndarray, likely_converged: bool, finish: Callable[[], RegistrationResult]):
        self.T_target_source = T_target_source
        self.likely_converged = likely_converged
        self._finish: Callable[[], RegistrationResult] | None = finish
        self._result: RegistrationResult | None = None
        self._lock = threading.Lock()

    @staticmethod
    def done(result: RegistrationResult) -> "PendingAlignment":
        pending = PendingAlignment(np.asarray(result.T_target_source, dtype=np.float64), bool(result.converged), lambda: result)
        pending._result, pending._finish = result, None
        return pending

    def result(self) -> RegistrationResult:
        with self._lock:
            if self._result is None:
                assert self._finish is not None
                self._result = self._finish()
                self._finish = None  # drops the clouds the assessment held
            return self._result


def assessed_apart(cls: type) -> bool:
    """Whether variant class ``cls`` registers apart from its after-the-fact assessment (the nearest definition of
    ``_register`` / ``_align`` in its MRO is a ``_register``), so that a result can leave the assessment out
    (``assess=False``): the wrapped libraries (kiss, small_gicp, Open3D)."""
    for klass in cls.__mro__:
        if "_register" in vars(klass):
            return True
        if "_align" in vars(klass):
            return False
    return False


class Registration:
    """Base of every ICP variant: subclasses set ``name``, ``Config`` and implement :meth:`_align`.

    Stateful variants (``stateful = True``) also implement :meth:`reset` and :meth:`register_frame`
    and keep their own map between frames.
    """

    name: ClassVar[str] = ""
    Config: ClassVar[type[RegistrationConfig]] = RegistrationConfig
    stateful: ClassVar[bool] = False
    #: the odometry runner may assess frame k in a worker thread while frame k+1 registers (False for a backend that
    #: holds the GIL through its calls: the worker would only contend for it)
    overlap_assessment: ClassVar[bool] = True

    def __init__(self, config: RegistrationConfig | None = None, **params: Any):
        from lidarkit.registration.registry import not_a_choice, recorded_name

        # a class outside the registry by its own name, or ``Sub(vanilla)`` (its results and messages read method '';
        # a subclass of vanilla read 'vanilla', and its run re-ran as vanilla)
        self.name = recorded_name(type(self))
        if config is not None and params:
            raise ConfigError("pass either a config object or keyword parameters, not both", source=self.name)
        if config is not None and not isinstance(config, self.Config):  # (another variant's config, or a dict: an
            # AttributeError traceback at the first align)
            raise ConfigError(f"config must be a {self.Config.__name__}, got {type(config).__name__} (or pass the settings "
                              "as keyword parameters)", source=self.name)
        if config is None:
            unhashable_choices = not_a_choice(self.Config, params)
            if unhashable_choices:
                raise ConfigError(f"invalid parameters ({unhashable_choices})", source=self.name)
            try:
                config = self.Config(**params)
            except InvalidParameters as err:  # (named by the variant, as get_icp names it)
                raise ConfigError(f"invalid parameters ({err})", source=self.name) from None
        self._config = config
        if not self._config.assess and not assessed_apart(type(self)):
            from lidarkit.registration.registry import available_icp, get_icp_class

            split = [n for n in available_icp() if assessed_apart(get_icp_class(n))]
            raise ConfigError(f"assess=False is for the variants that register apart from their assessment ({', '.join(split)}); "
                              f"{self.name} scores its result within its own iterations", source=self.name)

    @property
    def config(self) -> RegistrationConfig:
        """The resolved configuration (all defaults filled in)."""
        return self._config

    @property
    def reads_data_as(self) -> str | None:
        """The variant a reader prepares the data for (on KITTI, kiss's and genz's vertical-angle correction) when it is
        not :attr:`name`: for a subclass outside the registry (recorded as ``Sub(kiss)``), the registered variant it
        derives from, which its name stood for before; None otherwise."""
        from lidarkit.registration.registry import registered_ancestor

        return None if self.name == type(self).name else registered_ancestor(type(self))

    def align(
        self, source_xyz: np.ndarray, target_xyz: np.ndarray, init_T: np.ndarray | None = None
    ) -> RegistrationResult:
        """Estimate ``T_target_source`` for ``(N, 3)`` source and ``(M, 3)`` target clouds."""
        return self._deferred(source_xyz, target_xyz, init_T).result()

    def align_deferred(
        self, source_xyz: np.ndarray, target_xyz: np.ndarray, init_T: np.ndarray | None = None
    ) -> "PendingAlignment":
        """:meth:`align` in two steps: the backend's registration now (the pose), the after-the-fact assessment
        (correspondences, degeneracy, covariance) when :meth:`PendingAlignment.result` is called, possibly in another
        thread, so that it can overlap the next registration. ``align`` is exactly ``align_deferred(...).result()``.

        A variant that overrides :meth:`align` itself (e.g. to take extra arguments) is run whole, here and now."""
        if type(self).align is not Registration.align:
            return PendingAlignment.done(self.align(source_xyz, target_xyz, init_T))
        return self._deferred(source_xyz, target_xyz, init_T)

    def _deferred(self, source_xyz: np.ndarray, target_xyz: np.ndarray, init_T: np.ndarray | None) -> "PendingAlignment":
        src, dst, T0 = check_pair(source_xyz, target_xyz, init_T)
        gap = initial_gap_m(src, dst, T0)
        if gap is not None:
            return PendingAlignment.done(no_overlap_result(T0, gap, self.name))
        model = self._config.covariance_model()
        source = f"{self.name} ({len(src)} source / {len(dst)} target points)"
        start = time.perf_counter()
        # a subclass that overrides _align below the class that split it (e.g. to post-process the result) gets its _align
        register = self._register if assessed_apart(type(self)) else functools.partial(Registration._register, self)
        sensors = local_origin.sensors_of(dst, src) if self._config.assess else None
        with use_backend(self.name, source), use_model(model), local_origin.use_sensors(sensors):
            T, likely_converged, assess = register(src, dst, T0)
        T = np.asarray(T, dtype=np.float64)
        if T.shape != (4, 4) or not np.isfinite(T).all():  # a backend (or a plugin) that returns garbage instead of raising
            what = "NaN or infinite entries" if T.shape == (4, 4) else f"shape {T.shape}"
            raise RegistrationError(f"{self.name} returned a pose with {what}, not a finite 4x4 matrix", source=source)
        if not (is_rotation(T[:3, :3]) and np.allclose(T[3], (0.0, 0.0, 0.0, 1.0))):  # (a scaled rotation: "converged")
            raise RegistrationError(f"{self.name} returned a pose that is not a rigid transform (its 3x3 block is no rotation, "
                                    "or its last row is not 0 0 0 1)", source=source)
        register_s = time.perf_counter() - start
        if not self._config.assess:
            reported = getattr(assess, "backend_reported", {})  # e.g. small_gicp's own iteration count
            return PendingAlignment.done(unassessed_result(T, bool(likely_converged), self.name, register_s, **reported))

        def finish() -> RegistrationResult:
            start = time.perf_counter()
            with use_backend(self.name, source), use_model(model), local_origin.use_sensors(sensors):
                result = assess()
            if not np.allclose(result.T_target_source, T, rtol=0.0, atol=1e-9):
                # a subclass's _register that moves the pose but returns its parent's assess(): which pose is the result's?
                raise RegistrationError(f"{type(self).__name__}._register returned a pose that its assess() result does not carry; "
                                        "assess() must score the pose _register returns (or override _align instead)", source=source)
            return self._finish(result, register_s + time.perf_counter() - start)

        return PendingAlignment(T, bool(likely_converged), finish)

    def calibration_variant(self) -> str | None:
        """The variant whose learned covariance calibration applies: this one's, else that of the nearest registered
        variant it derives from (a plugin subclassing ``vanilla``), None where there is none or where this config is not
        the one it was learned at (the closed form is then returned as computed; ``extra["covariance_calibration"]``
        says so)."""
        learned, unlearned = self._calibration()
        return None if unlearned else learned

    def _calibration(self) -> tuple[str | None, list[str]]:
        """``(variant whose entry applies, this config's settings that differ from those it was learned at as
        "name=value")``: small_gicp's ICP under GICP's entry gave a 1.3 mm sigma for a 4.8 cm error (NEES 1716), its
        GICP at a 3 m gate mean NEES 16.5 (47 % inside the 95 % bound). A setting with a measured band
        (``CALIBRATED_BANDS``) is learned anywhere within it."""
        from lidarkit.registration.covariance import CALIBRATED_BANDS, CALIBRATED_SETTINGS, CALIBRATION

        for klass in type(self).__mro__:
            name = vars(klass).get("name")
            if not (name and name in CALIBRATION):
                continue
            settings = CALIBRATED_SETTINGS.get(name, ())
            mine = self.describe() if settings and callable(getattr(self, "describe", None)) else {}
            bands, unlearned = CALIBRATED_BANDS.get(name, {}), []
            for k in settings:
                if k in mine:  # a component, compared as resolved: kiss's own threshold written as {"name": "adaptive"}
                    if _own_settings(mine[k]) != _own_settings(_learned_composition(klass)[k]):  # is the one it was learned at
                        unlearned.append(f"{k}={getattr(self._config, k)}")
                elif hasattr(self._config, k):  # (a plugin's config without the field runs as learned)
                    value = getattr(self._config, k)
                    if not _as_learned(value, getattr(_learned_config(klass), k), bands.get(k)):
                        unlearned.append(f"{k}={value}")
            return str(name), unlearned
        return None, []

    def _finish(self, result: RegistrationResult, runtime: float) -> RegistrationResult:
        """The config's calibration and acceptance gate applied to the variant's assessed result; a covariance computed
        around a local origin (far clouds: ``extra["covariance_origin_m"]``) is calibrated there, then moved to the
        target frame's origin with the adjoint."""
        from lidarkit.registration.assessment import COVARIANCE_ORIGIN_KEY
        from lidarkit.registration.covariance import adjoint, calibrate

        covariance, step, extra = result.covariance, result.surface_step, result.extra
        if covariance is not None and self._config.calibrated_covariance and self._config.covariance == "censi":
            learned, unlearned = self._calibration()
            if learned is not None and not unlearned:
                covariance = calibrate(covariance, learned, step)
            configured = f"{self.name} ({', '.join(unlearned)})" if unlearned else self.name
            extra = {**extra, "covariance_calibration": calibration_note(configured, None if unlearned else learned)}
        if covariance is not None and getattr(self._config, "planar", False):
            # a planar solve keeps z, roll and pitch of the guess: they are not estimated, and carry no variance here
            covariance = covariance.copy()
            covariance[[2, 3, 4], :] = 0.0
            covariance[:, [2, 3, 4]] = 0.0
        origin = result.extra.get(COVARIANCE_ORIGIN_KEY)
        if covariance is not None and origin is not None:
            S = np.eye(4)
            S[:3, 3] = origin
            Ad = adjoint(S)  # se3_exp(Ad xi) = S se3_exp(xi) S^-1: a perturbation at c as one at the frame's origin
            # kept as calibrated about c: far out (UTM) the moved matrix spans more than float64 resolves
            extra = {**extra, LOCAL_COVARIANCE_KEY: np.asarray(covariance, dtype=np.float64).tolist()}
            covariance = Ad @ covariance @ Ad.T
            step = None if step is None else Ad @ step
        return dataclasses.replace(accept(result, self._config), runtime_s=runtime, method=self.name, covariance=covariance,
                                   surface_step=step, extra=extra)

    def _register(
        self, source_xyz: np.ndarray, target_xyz: np.ndarray, init_T: np.ndarray
    ) -> tuple[np.ndarray, bool, Callable[[], RegistrationResult]]:
        """The backend's part of an alignment: ``(pose, the backend's own convergence verdict, the assessment still to
        do)``; what the backend itself reported, kept with ``assess=False``, may ride on the assessment as its
        ``backend_reported`` attribute (``{"iterations": n, "reason": why it did not converge}``). Variants whose
        assessment can run apart override it; by default the whole :meth:`_align` runs now."""
        result = self._align(source_xyz, target_xyz, init_T)
        if not isinstance(result, RegistrationResult):  # (a bare 4x4 pose, None: a plugin's easy mistake)
            raise RegistrationError(f"{type(self).__name__}._align returned {type(result).__name__}, not a RegistrationResult "
                                    "(score the pose with assess_alignment(...).to_result(T))", source=self.name or type(self).__name__)
        return result.T_target_source, bool(result.converged), lambda: result

    def _align(self, source_xyz: np.ndarray, target_xyz: np.ndarray, init_T: np.ndarray) -> RegistrationResult:
        """The whole alignment at once: a variant implements this or :meth:`_register` (then this runs its assessment
        at once)."""
        if type(self)._register is Registration._register:
            raise NotImplementedError
        return self._register(source_xyz, target_xyz, init_T)[2]()

    # stateful API (kiss); stateless variants refuse it as a caller's mistake (a bare NotImplementedError "vanilla is
    # stateless" said neither what to call instead nor, through the CLI, in one line)
    def reset(self) -> None:
        """Forget the map and motion history (stateful variants only)."""
        raise self._stateless("reset")

    def register_frame(self, points_xyz: np.ndarray, point_times_s: np.ndarray | None = None) -> np.ndarray:
        """Register one frame into the variant's own map; return ``T_world_lidar`` (stateful only)."""
        raise self._stateless("register_frame")

    def _stateless(self, call: str) -> ConfigError:
        return ConfigError(f"{call}() needs a stateful variant (one with a map of its own); {self.name} is stateless: "
                           "align a pair of scans with align(), or run odometry with lidarkit.odometry.run()", source=self.name)

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self._config!r})"
