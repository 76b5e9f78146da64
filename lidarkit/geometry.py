"""SE(3)/SO(3) helpers and closed-form (SVD) point-set alignment.

Poses are 4x4 homogeneous matrices named ``T_a_b``: they map points from frame ``b`` to frame ``a``.
Arrays of poses have shape ``(N, 4, 4)``; point sets ``(N, 3)``; everything is float64.
"""

from __future__ import annotations

import contextlib
import contextvars
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from lidarkit.errors import DataError

ORTHONORMAL_TOL = 1e-4


MAX_ABS_COORDINATE_M = 1e7
"""Largest coordinate magnitude accepted (10,000 km: covers UTM northings). Beyond it a cloud is garbage (a text file
read as floats, a unit error) and the backends (Open3D voxel grids, KD-trees) fail with internal errors."""


#: arrays already checked by :func:`as_points` in the current context (``id -> array``; see :func:`validated_points`)
_VALIDATED: contextvars.ContextVar[dict[int, np.ndarray] | None] = contextvars.ContextVar("validated_points", default=None)


@contextlib.contextmanager
def validated_points(arrays: dict[int, np.ndarray]) -> Iterator[None]:
    """Within the block, :func:`as_points` returns an array of ``arrays`` (``id -> array``, checked by ``as_points``
    before it was put there) without checking it again. The odometry runner checks each scan once, in its reading
    thread, and keeps a frame's entry only while that frame is in use: nothing outside the block, and no array that
    could have changed since its check, is trusted."""
    token = _VALIDATED.set(arrays)
    try:
        yield
    finally:
        _VALIDATED.reset(token)


def is_validated(points_xyz: np.ndarray) -> bool:
    """Whether ``points_xyz`` is an array the current :func:`validated_points` block holds (checked, not changed)."""
    known = _VALIDATED.get()
    return known is not None and known.get(id(points_xyz)) is points_xyz


def as_points(
    points_xyz: np.ndarray, name: str = "points", min_points: int = 0, on_float32_far: Callable[[float], None] | None = None,
) -> np.ndarray:
    """Validate an ``(N, 3)`` real, finite point array within ``MAX_ABS_COORDINATE_M`` and return it as float64.

    This is the boundary before every backend (Open3D, kiss-icp, small_gicp, scipy): nothing they would reject
    with an internal error, or accept silently (a complex array losing its imaginary part), gets past it.
    A cloud far from its origin held at float32 precision is logged once per ``name``, or, given ``on_float32_far``,
    passed to it as ``reach_m`` every time (a caller that reports it itself, e.g. per frame of a run).
    """
    known = _VALIDATED.get()
    if known is not None and known.get(id(points_xyz)) is points_xyz and len(points_xyz) >= min_points:
        return points_xyz  # checked once already (validated_points)
    arr = np.asarray(points_xyz)
    if arr.ndim == 0:  # (a file name or None read "got shape ()")
        raise DataError(f"expected an (N, 3) point array, got {type(points_xyz).__name__} {points_xyz!r:.60}", source=name)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise DataError(f"expected an (N, 3) point array, got shape {arr.shape}", source=name)
    if np.issubdtype(arr.dtype, np.complexfloating):
        raise DataError(f"expected real coordinates, got a complex array ({arr.dtype})", source=name)
    if not np.issubdtype(arr.dtype, np.number) or arr.dtype == np.bool_:
        raise DataError(f"expected a numeric point array, got dtype {arr.dtype}", source=name)
    arr = arr.astype(np.float64, copy=False)
    if not arr.flags.writeable:  # (a memory-mapped .npy: kiss-icp's and Open3D's bindings refuse a read-only buffer)
        arr = arr.copy()
    if len(arr) < min_points:
        raise DataError(f"needs at least {min_points} points, got {len(arr)}", source=name)
    reach = _reach_within_limits(arr) if len(arr) else None  # the common case in two flat reductions (NaN fails them)
    if reach is not None:
        if reach > FLOAT32_CM_LIMIT_M:
            if on_float32_far is not None:
                if float32_held(arr):
                    on_float32_far(reach)
            else:
                _say_if_float32_far_out(arr, name, reach)
        return arr
    if not np.isfinite(arr).all():
        bad = int((~np.isfinite(arr).all(axis=1)).sum())
        raise DataError(f"{bad} of {len(arr)} points are NaN or infinite", source=name)
    check_magnitude(arr, name)
    return arr


#: Coordinates (m) beyond which a cloud held at float32 precision is coarser than 1 cm (float32 steps are 1/64 m there).
FLOAT32_CM_LIMIT_M = 131072.0
_SAID_FLOAT32: set[str] = set()


def _say_if_float32_far_out(arr: np.ndarray, name: str, far: float) -> None:
    """Warn (once per cloud name) when a cloud reaching ``far`` metres from its origin holds only float32 values: a
    georeferenced cloud stored as float32 (.npy, .pcd) is 0.5 m coarse at UTM northings, and its registration said
    "converged" with a 1 mm sigma while 4.5 cm off. One comparison pass, for far clouds only."""
    if name in _SAID_FLOAT32:
        return
    if float32_held(arr):
        import logging

        _SAID_FLOAT32.add(name)
        logging.getLogger(__name__).warning("%s: %s", name, float32_far_message(far))


def float32_held(arr: np.ndarray) -> bool:
    """Whether every coordinate of ``arr`` is a float32 value (the cloud was stored at float32 precision)."""
    return bool(np.array_equal(arr.astype(np.float32).astype(np.float64), arr))


def float32_step(far: float) -> float:
    """The step (m) between float32 values at ``far`` metres."""
    return float(np.spacing(np.float32(far)))


def float32_far_message(far: float) -> str:
    """What a cloud reaching ``far`` metres at float32 precision means, and what to do."""
    return (f"coordinates up to {far:.3g} m held at float32 precision (steps of {float32_step(far):.3g} m there): store "
            "georeferenced clouds as float64, or shift them to a local origin before storing them")


def _within_limits(arr: np.ndarray) -> bool:
    """All coordinates finite and within ``MAX_ABS_COORDINATE_M`` (see :func:`_reach_within_limits`)."""
    return _reach_within_limits(arr) is not None


def _reach_within_limits(arr: np.ndarray) -> float | None:
    """The largest coordinate magnitude when all are finite and within ``MAX_ABS_COORDINATE_M``, else None: a flat max
    and min (NaN propagates through both), ~20x faster than a per-row test on an ``(N, 3)`` array. (A sum of squares
    by ``np.dot`` would take one pass instead of two, but wakes OpenBLAS's threads, which then spin on the cores the
    wrapped libraries need.)"""
    hi, lo = float(arr.max()), float(arr.min())
    return max(hi, -lo) if hi <= MAX_ABS_COORDINATE_M and lo >= -MAX_ABS_COORDINATE_M else None


def check_magnitude(points_xyz: np.ndarray, source: str, location: str | None = None) -> None:
    """DataError if any finite coordinate exceeds ``MAX_ABS_COORDINATE_M`` in magnitude (names the first point)."""
    if len(points_xyz) == 0 or _within_limits(np.asarray(points_xyz)):
        return
    big = np.abs(points_xyz).max(axis=1) > MAX_ABS_COORDINATE_M
    if big.any():
        first = int(np.argmax(big))
        raise DataError(f"{int(big.sum())} of {len(big)} points have a coordinate beyond {MAX_ABS_COORDINATE_M:g} m "
                        f"(first: point {first}, {np.abs(points_xyz[first]).max():.3g} m): not a metric point cloud",
                        source=source, location=location)


def make_se3(rotation: np.ndarray | None = None, translation: np.ndarray | None = None) -> np.ndarray:
    """Build a 4x4 pose from a 3x3 rotation and a 3-vector translation (identity where omitted)."""
    T = np.eye(4)
    if rotation is not None:
        T[:3, :3] = rotation
    if translation is not None:
        T[:3, 3] = np.asarray(translation, dtype=np.float64).reshape(3)
    return T


def se3_inverse(T: np.ndarray) -> np.ndarray:
    """Inverse of one pose ``(4, 4)`` or a stack ``(N, 4, 4)`` using R^T, without a general inverse."""
    T = np.asarray(T, dtype=np.float64)
    R = T[..., :3, :3]
    t = T[..., :3, 3]
    Rt = np.swapaxes(R, -1, -2)
    out = np.zeros_like(T)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, t)
    out[..., 3, 3] = 1.0
    return out


def transform_points(T: np.ndarray, points_xyz: np.ndarray) -> np.ndarray:
    """Apply a 4x4 pose to ``(N, 3)`` points."""
    T = np.asarray(T, dtype=np.float64)
    # einsum, not a tall matmul: multi-threaded BLAS on (N, 3) x (3, 3) is ~10x slower on a loaded machine
    return np.einsum("ij,nj->ni", T[:3, :3], np.asarray(points_xyz, dtype=np.float64)) + T[:3, 3]


def skew(v: np.ndarray) -> np.ndarray:
    """The 3x3 cross-product matrix of a 3-vector."""
    x, y, z = np.asarray(v, dtype=np.float64).reshape(3)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def so3_exp(rotvec: np.ndarray) -> np.ndarray:
    """Rotation matrix from an axis-angle vector (rad); works on ``(3,)`` or ``(N, 3)``."""
    return Rotation.from_rotvec(np.asarray(rotvec, dtype=np.float64)).as_matrix()


def so3_log(R: np.ndarray) -> np.ndarray:
    """Axis-angle vector (rad) of a rotation matrix; works on ``(3, 3)`` or ``(N, 3, 3)``."""
    return Rotation.from_matrix(np.asarray(R, dtype=np.float64)).as_rotvec()


def se3_exp(xi: np.ndarray) -> np.ndarray:
    """Pose from a twist ``(rho, phi)`` (translation part first), the exact SE(3) exponential."""
    xi = np.asarray(xi, dtype=np.float64).reshape(6)
    rho, phi = xi[:3], xi[3:]
    theta = np.linalg.norm(phi)
    K = skew(phi)
    if theta < 1e-10:
        V = np.eye(3) + 0.5 * K
    else:
        V = (
            np.eye(3)
            + (1 - np.cos(theta)) / theta**2 * K
            + (theta - np.sin(theta)) / theta**3 * (K @ K)
        )
    return make_se3(so3_exp(phi), V @ rho)


def se3_log(T: np.ndarray) -> np.ndarray:
    """Twist ``(rho, phi)`` of a pose, the inverse of :func:`se3_exp`."""
    T = np.asarray(T, dtype=np.float64)
    phi = so3_log(T[:3, :3])
    theta = np.linalg.norm(phi)
    K = skew(phi)
    if theta < 1e-10:
        V_inv = np.eye(3) - 0.5 * K
    else:
        half = theta / 2
        V_inv = np.eye(3) - 0.5 * K + (1 - half / np.tan(half)) / theta**2 * (K @ K)
    return np.concatenate([V_inv @ T[:3, 3], phi])


def se3_fraction(T: np.ndarray, parts: float) -> np.ndarray:
    """One of ``parts`` equal steps of the motion ``T`` along its geodesic, ``exp(log(T) / parts)``; ``T`` itself (the
    same array) for one part (a deskew's motion over several sweeps scaled to one, VO's motion over a gap per frame)."""
    return T if parts == 1 else se3_exp(se3_log(T) / parts)


def rotation_angle_rad(R: np.ndarray) -> np.ndarray | float:
    """Rotation angle in [0, pi] of ``(3, 3)`` or ``(N, 3, 3)`` matrices, robust near 0 and pi."""
    R = np.asarray(R, dtype=np.float64)
    cos = (np.trace(R, axis1=-2, axis2=-1) - 1.0) / 2.0
    axis = np.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]], axis=-1)
    sin = 0.5 * np.linalg.norm(axis, axis=-1)
    return np.arctan2(sin, cos)


def rotation_angle_deg(R: np.ndarray) -> np.ndarray | float:
    """Rotation angle in degrees, see :func:`rotation_angle_rad`."""
    return np.degrees(rotation_angle_rad(R))


def pose_error(T_est: np.ndarray, T_ref: np.ndarray) -> tuple[float, float]:
    """Translation (m) and rotation (deg) of ``T_ref^-1 T_est``, the error of one pose."""
    E = se3_inverse(T_ref) @ np.asarray(T_est, dtype=np.float64)
    return float(np.linalg.norm(E[:3, 3])), float(rotation_angle_deg(E[:3, :3]))


def orthonormalize(R: np.ndarray) -> np.ndarray:
    """Nearest rotation matrix (Frobenius norm) to ``R``, via SVD; accepts ``(3, 3)`` or ``(N, 3, 3)``."""
    U, _, Vt = np.linalg.svd(np.asarray(R, dtype=np.float64))
    D = np.ones(U.shape[:-1])
    D[..., -1] = np.sign(np.linalg.det(U @ Vt))
    return (U * D[..., None, :]) @ Vt


def orthonormalize_se3(T: np.ndarray) -> np.ndarray:
    """Copy of a pose (or stack) whose rotation block is exactly orthonormal."""
    out = np.array(T, dtype=np.float64, copy=True)
    out[..., :3, :3] = orthonormalize(out[..., :3, :3])
    out[..., 3, :] = (0.0, 0.0, 0.0, 1.0)
    return out


def is_rotation(R: np.ndarray, tol: float = ORTHONORMAL_TOL) -> bool:
    """True if every matrix in ``R`` is orthonormal with determinant +1 within ``tol``."""
    R = np.asarray(R, dtype=np.float64)
    eye_err = np.abs(np.swapaxes(R, -1, -2) @ R - np.eye(3)).max(initial=0.0)
    return bool(eye_err <= tol and np.all(np.linalg.det(R) > 0))


@dataclass(frozen=True)
class Alignment:
    """Result of a closed-form alignment ``dst ~= scale * R @ src + t``."""

    rotation: np.ndarray
    translation: np.ndarray
    scale: float = 1.0

    @property
    def T(self) -> np.ndarray:
        """The rigid part as a 4x4 pose (scale not included)."""
        return make_se3(self.rotation, self.translation)

    @property
    def sim3(self) -> np.ndarray:
        """The similarity as a 4x4 matrix with ``scale * R`` in its upper-left block."""
        return make_se3(self.scale * self.rotation, self.translation)

    def apply(self, points_xyz: np.ndarray) -> np.ndarray:
        """Map ``(N, 3)`` points with the similarity."""
        return self.scale * np.asarray(points_xyz, dtype=np.float64) @ self.rotation.T + self.translation


def kabsch_umeyama(
    source_xyz: np.ndarray,
    target_xyz: np.ndarray,
    *,
    with_scale: bool = False,
    weights: np.ndarray | None = None,
) -> Alignment:
    """Least-squares rigid (or similarity, ``with_scale``) transform taking ``source`` onto ``target``.

    Closed form by SVD of the cross-covariance (Kabsch; Umeyama 1991 for the scale); a reflection in
    the SVD is corrected so the result is always a proper rotation. Needs >= 3 non-collinear pairs.
    """
    src = as_points(source_xyz, "source", min_points=3)
    dst = as_points(target_xyz, "target", min_points=3)
    if src.shape != dst.shape:
        raise DataError(f"source and target differ in shape: {src.shape} vs {dst.shape}", source="kabsch_umeyama")
    if weights is None:
        w = np.full(len(src), 1.0 / len(src))
    else:
        w = np.asarray(weights, dtype=np.float64).reshape(-1)
        if w.shape[0] != len(src) or not np.isfinite(w).all() or (w < 0).any() or w.sum() <= 0:
            raise DataError("weights must be finite, non-negative, one per point and not all zero", source="weights")
        w = w / w.sum()
    mu_src = w @ src
    mu_dst = w @ dst
    src_c = src - mu_src
    dst_c = dst - mu_dst
    cov = (dst_c * w[:, None]).T @ src_c
    U, S, Vt = np.linalg.svd(cov)
    d = np.sign(np.linalg.det(U) * np.linalg.det(Vt))
    D = np.array([1.0, 1.0, d if d != 0 else 1.0])
    R = (U * D) @ Vt
    scale = 1.0
    if with_scale:
        var_src = float(w @ (src_c**2).sum(axis=1))
        if var_src <= 0:
            raise DataError("source points are all identical; scale is undefined", source="kabsch_umeyama")
        scale = float((S * D).sum() / var_src)
    t = mu_dst - scale * R @ mu_src
    return Alignment(rotation=R, translation=t, scale=scale)


def random_se3(rng: np.random.Generator, max_translation: float = 1.0, max_angle_rad: float = np.pi) -> np.ndarray:
    """A random pose: uniform axis, angle uniform in [0, max_angle], translation uniform in a cube."""
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    angle = rng.uniform(0.0, max_angle_rad)
    t = rng.uniform(-max_translation, max_translation, size=3)
    return make_se3(so3_exp(axis * angle), t)
