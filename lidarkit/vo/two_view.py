"""Two-view geometry: essential matrix (RANSAC / USAC_MAGSAC / LMedS), recoverPose, Sampson refinement, F fallback.

Convention: ``X_cur = R_cur_ref @ X_ref + t_cur_ref`` (OpenCV ``recoverPose``); ``t`` has unit norm.
The estimate never raises for bad correspondences: it returns ``failure`` with the reason instead.

Degeneracy (pure rotation / standstill) is measured twice: with K (``parallax_px``, ``rotation_only_px``) and without
trusting K (``homography_share``, ``rotation_homography_px``): a homography fitted to the pixel correspondences that
explains (nearly) all fundamental-matrix inliers and equals a pure rotation ``K' R K'^-1`` for some focal length near
K's. A plane seen under translation is also explained by a homography, but not by a rotation-conjugate one.

Reproducibility: OpenCV 5's ``findEssentialMat`` / ``findHomography`` / ``findFundamentalMat`` sample with an internal
RNG that ``cv2.setRNGSeed`` does not reach (the same input order always gives the same result). ``rng`` permutes the
correspondences before they reach OpenCV, so the seed selects the samples; see :func:`correspondence_rng`.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from typing import NamedTuple

import cv2
import numpy as np
from scipy.optimize import least_squares

from lidarkit.errors import DataError
from lidarkit.geometry import skew, so3_exp, so3_log
from lidarkit.vo.config import GeometryConfig
from lidarkit.vo.intrinsics import validate_K

_METHODS = {"ransac": cv2.RANSAC, "magsac": cv2.USAC_MAGSAC, "lmeds": cv2.LMEDS}


@dataclass(frozen=True)
class TwoViewEstimate:
    """Relative pose of the current frame w.r.t. the reference frame, with its support.

    ``inliers``: ``(N,) bool`` over the input correspondences (RANSAC and cheirality inliers);
    ``epipolar_inliers``: the chosen matrix's RANSAC inliers (also of a pair failed for too few pose inliers);
    ``parallax_px``: median rotation-compensated image motion of the inliers (0 for a pure rotation);
    ``rotation_only_px``: median residual of the best pure-rotation fit with K (small: no translation; needs K right);
    ``attempts``: one line per estimator tried (inliers or why it failed);
    ``homography_share``: share of the fundamental-matrix inliers (``fundamental_inliers``, pixel RANSAC) that the
    RANSAC homography explains, both within ``degeneracy_threshold_px``; K-free;
    ``rotation_homography_px``: largest distance (px, over the inliers' bounding box) between that homography and the
    closest pure rotation ``K' R K'^-1`` (K' = K with focal self-calibrated, ``rotation_focal_px``, within
    ``rotation_focal_ratio``, principal point within 10 % of the box): ~0 for a pure rotation or standstill; inf when
    the homography explains less than ``MIN_SHARE_FOR_ROTATION_FIT`` (not computed).
    """

    R_cur_ref: np.ndarray
    t_cur_ref: np.ndarray
    inliers: np.ndarray
    method: str
    n_inliers: int
    parallax_px: float
    failure: str | None = None
    attempts: tuple[str, ...] = field(default_factory=tuple)
    rotation_only_px: float = float("inf")
    homography_share: float = 0.0
    fundamental_inliers: int = 0
    rotation_homography_px: float = float("inf")
    rotation_focal_px: float = float("nan")
    epipolar_inliers: int = 0

    @property
    def ok(self) -> bool:
        return self.failure is None

    @property
    def T_cur_ref(self) -> np.ndarray:
        """``(4, 4)`` pose of the reference camera in the current camera frame (unit translation)."""
        T = np.eye(4)
        T[:3, :3] = self.R_cur_ref
        T[:3, 3] = self.t_cur_ref
        return T


@dataclass(frozen=True)
class Degeneracy:
    """K-free degeneracy measures of one pair (see :class:`TwoViewEstimate`)."""

    homography_share: float = 0.0
    fundamental_inliers: int = 0
    rotation_homography_px: float = float("inf")
    rotation_focal_px: float = float("nan")


def _failed(n: int, reason: str, attempts: list[str], rotation_only_px: float = float("inf"),
            degeneracy: Degeneracy | None = None, epipolar_inliers: int = 0) -> TwoViewEstimate:
    return TwoViewEstimate(np.eye(3), np.zeros(3), np.zeros(n, bool), "none", 0, 0.0, reason, tuple(attempts),
                           rotation_only_px, **asdict(degeneracy or Degeneracy()), epipolar_inliers=epipolar_inliers)


#: depth limit (in baselines, in both cameras) of the cheirality inliers: recoverPose's default; nearer points are
#: triangulated under more than ~1 deg and fix the translation direction
NEAR_BASELINES = 50.0
#: rotation-compensated image motion (px, median) the points in front at any distance need to stand in for too few
#: near ones (sanity.min_parallax_px's default), and its least ratio to their median Sampson error (the match noise):
#: KLT tracks at walking pace move 1.2 px at 72-75x (translation direction 0.4 deg off); the ORB matches of a pure
#: rotation "move" 0.8 px at 5x, its KLT tracks 0.04 px
FAR_POINTS_MIN_PARALLAX_PX = 0.5
FAR_POINTS_MIN_SIGNAL_TO_NOISE = 20.0
#: a pair whose essential matrix explains at least this share of its correspondences but gives few pose inliers lacks
#: parallax (a standstill, or a baseline short against the scene depth: at walking pace E-RANSAC kept 1198 of 1207 KLT
#: tracks); lost tracking, or noisy descriptor matches (ORB on a pure rotation: 72 %), leave more unexplained
LOW_PARALLAX_EPIPOLAR_SHARE = 0.9


def mostly_explained(epipolar_inliers: int, n_correspondences: int, needed: int) -> bool:
    """At least :data:`LOW_PARALLAX_EPIPOLAR_SHARE` of the correspondences, and ``needed``, fit the essential
    matrix."""
    return epipolar_inliers >= max(needed, LOW_PARALLAX_EPIPOLAR_SHARE * n_correspondences)


def few_inliers_parallax_reason(estimate: TwoViewEstimate, needed: int) -> str | None:
    """The insufficient-parallax reason of an estimate with fewer than ``needed`` cheirality inliers whose essential
    matrix explains nearly all correspondences (:func:`mostly_explained`; the pipeline then keeps its reference, so
    the baseline grows); None when it does not (tracking lost, noisy matches)."""
    n = len(estimate.inliers)
    if (estimate.ok and estimate.n_inliers >= needed) or not mostly_explained(estimate.epipolar_inliers, n, needed):
        return None
    few = estimate.failure or f"too few inliers ({estimate.n_inliers} < {needed})"
    return (f"insufficient parallax (the essential matrix explains {estimate.epipolar_inliers} of {n} correspondences; "
            f"{few}): baseline short for the scene depth, translation direction undefined")


def correspondence_rng(seed: int, frame: int) -> np.random.Generator:
    """The generator that orders frame ``frame``'s correspondences for the robust estimators under ``seed``."""
    return np.random.default_rng([int(seed), int(frame)])


def rotation_homography_residual_px(H: np.ndarray, K: np.ndarray, points_px: np.ndarray,
                                    focal_ratio: float = 2.0) -> tuple[float, float]:
    """How far the pixel homography ``H (3, 3)`` is from a pure rotation, without trusting ``K``.

    Fits ``K' R K'^-1`` (``K'``: square pixels, focal ``fx * s`` with ``s`` in ``[1/focal_ratio, focal_ratio]``,
    principal point within 10 % of the box) to ``H`` on a 6 x 4 grid spanning the bounding box of ``points_px
    (N, 2)``; returns (largest grid distance in px, fitted focal in px). Closed-form rotations at five focal scales
    seed a bounded least-squares refinement of (log s, principal point, rotation vector).
    """
    lo, hi = points_px.min(axis=0), points_px.max(axis=0)
    gx, gy = np.meshgrid(np.linspace(lo[0], hi[0], 6), np.linspace(lo[1], hi[1], 4))
    grid = np.column_stack([gx.ravel(), gy.ravel(), np.ones(gx.size)])
    target = grid @ H.T
    if np.any(np.abs(target[:, 2]) < 1e-12):
        return float("inf"), float("nan")
    target = target[:, :2] / target[:, 2:3]
    f0, cx0, cy0 = float(K[0, 0]), float(K[0, 2]), float(K[1, 2])

    def conjugate(p: np.ndarray) -> np.ndarray:
        f = f0 * np.exp(p[0])
        Kp = np.array([[f, 0.0, cx0 + p[1]], [0.0, f, cy0 + p[2]], [0.0, 0.0, 1.0]])
        return Kp @ so3_exp(p[3:]) @ np.linalg.inv(Kp)

    def residuals(p: np.ndarray) -> np.ndarray:
        mapped = grid @ conjugate(p).T
        with np.errstate(divide="ignore", invalid="ignore"):
            diff = mapped[:, :2] / mapped[:, 2:3] - target
        return np.where(np.isfinite(diff), diff, 1e6).ravel()

    log_ratio = float(np.log(focal_ratio))
    best = None
    for log_s in np.linspace(-log_ratio, log_ratio, 5):
        f = f0 * np.exp(log_s)
        Kp = np.array([[f, 0.0, cx0], [0.0, f, cy0], [0.0, 0.0, 1.0]])
        U, _, Vt = np.linalg.svd(np.linalg.inv(Kp) @ H @ Kp)
        R = U @ np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))]) @ Vt
        p0 = np.concatenate([[log_s, 0.0, 0.0], so3_log(R)])
        cost = float(np.max(np.abs(residuals(p0))))
        if best is None or cost < best[0]:
            best = (cost, p0)
    margin = 0.1 * float(max(hi - lo)) + 1e-6
    lower = np.array([-log_ratio - 1e-9, -margin, -margin, -np.inf, -np.inf, -np.inf])
    upper = np.array([log_ratio + 1e-9, margin, margin, np.inf, np.inf, np.inf])
    result = least_squares(residuals, np.clip(best[1], lower, upper), bounds=(lower, upper), method="trf",
                           max_nfev=100)
    candidates = [best[1]] + ([result.x] if np.all(np.isfinite(result.x)) else [])
    worst, p = min((float(np.max(np.linalg.norm(residuals(c).reshape(-1, 2), axis=1))), i) for i, c in
                   enumerate(candidates))
    return worst, float(f0 * np.exp(candidates[p][0]))


#: the rotation fit runs only when the homography explains at least this share (below it the pair has parallax
#: whatever the fit says; SanityConfig.max_homography_share cannot be set lower)
MIN_SHARE_FOR_ROTATION_FIT = 0.5
#: homography RANSAC samples: finds a homography explaining >= 50 % with probability 1 - (1 - 0.5^4)^200 > 0.9999
#: while bounding the cost on pairs with parallax (where no homography explains much)
_HOMOGRAPHY_MAX_ITERS = 200


def degeneracy_measures(p0: np.ndarray, p1: np.ndarray, K: np.ndarray, cfg: GeometryConfig) -> Degeneracy:
    """Homography vs fundamental matrix on the pixel correspondences ``(N, 2)`` (RANSAC, ``degeneracy_threshold_px``)
    and, when the homography explains at least half of them, its distance from a pure rotation; K only bounds the
    self-calibrated focal length."""
    if len(p0) < 8:
        return Degeneracy()
    thr = cfg.degeneracy_threshold_px
    H, mask_h = cv2.findHomography(p0, p1, cv2.RANSAC, thr, maxIters=_HOMOGRAPHY_MAX_ITERS, confidence=cfg.confidence)
    F, mask_f = cv2.findFundamentalMat(p0, p1, cv2.FM_RANSAC, thr, cfg.confidence)
    n_h = int(mask_h.sum()) if H is not None and mask_h is not None else 0
    n_f = int(mask_f.sum()) if F is not None and mask_f is not None else 0
    share = n_h / max(n_f, n_h, 1)
    if n_h < 4 or share < MIN_SHARE_FOR_ROTATION_FIT or not np.all(np.isfinite(H)):
        return Degeneracy(share, n_f)
    residual, focal = rotation_homography_residual_px(H, K, p0[mask_h.ravel() > 0], cfg.rotation_focal_ratio)
    return Degeneracy(share, n_f, residual, focal)


def rotation_only_fit(norm_ref: np.ndarray, norm_cur: np.ndarray, focal_px: float) -> tuple[np.ndarray, float]:
    """``(R_cur_ref, median image residual px)`` of the best pure rotation mapping the reference rays onto the current
    ones (least squares on bearings, refit once on the better half); the residual is ~0 when the camera only rotated
    (identity and inf for fewer than 3 rays)."""
    if len(norm_ref) < 3:
        return np.eye(3), float("inf")
    b0 = np.column_stack([norm_ref, np.ones(len(norm_ref))])
    b1 = np.column_stack([norm_cur, np.ones(len(norm_cur))])
    b0 /= np.linalg.norm(b0, axis=1, keepdims=True)
    b1 /= np.linalg.norm(b1, axis=1, keepdims=True)
    use = np.ones(len(b0), bool)
    residual = np.zeros(len(b0))
    R = np.eye(3)
    for _ in range(2):
        U, _, Vt = np.linalg.svd(b0[use].T @ b1[use])
        D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
        R = Vt.T @ D @ U.T
        rays = b0 @ R.T
        with np.errstate(divide="ignore", invalid="ignore"):
            residual = np.linalg.norm(rays[:, :2] / rays[:, 2:3] - norm_cur, axis=1) * focal_px
        residual = np.where(np.isfinite(residual), residual, np.inf)
        use = residual <= np.median(residual)
    return R, float(np.median(residual))


def normalize_points(points_px: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Pixel points ``(N, 2)`` -> normalized image coordinates ``(N, 2)`` float64 (``K^-1 [u v 1]``)."""
    pts = np.asarray(points_px, dtype=np.float64)
    homog = np.column_stack([pts, np.ones(len(pts))]) @ np.linalg.inv(K).T
    return homog[:, :2] / homog[:, 2:3]


def sampson_residuals(E: np.ndarray, norm_ref: np.ndarray, norm_cur: np.ndarray) -> np.ndarray:
    """First-order geometric (Sampson) epipolar error of each correspondence, in normalized units ``(N,)``."""
    a = np.column_stack([norm_ref, np.ones(len(norm_ref))])
    b = np.column_stack([norm_cur, np.ones(len(norm_cur))])
    Ea = a @ E.T
    Etb = b @ E
    num = np.sum(b * Ea, axis=1)
    den = np.sqrt(Ea[:, 0] ** 2 + Ea[:, 1] ** 2 + Etb[:, 0] ** 2 + Etb[:, 1] ** 2) + 1e-15
    return num / den


def refine_pose(R: np.ndarray, t: np.ndarray, norm_ref: np.ndarray, norm_cur: np.ndarray,
                focal_px: float) -> tuple[np.ndarray, np.ndarray]:
    """Minimize the robust (Huber, 1 px) Sampson error over rotation and unit translation (5 DOF)."""
    t = t / np.linalg.norm(t)
    basis = np.linalg.svd(t.reshape(1, 3))[2][1:]  # two unit vectors orthogonal to t

    def unpack(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        Rx = so3_exp(x[:3]) @ R
        tx = t + basis.T @ x[3:]
        return Rx, tx / np.linalg.norm(tx)

    def residuals(x: np.ndarray) -> np.ndarray:
        Rx, tx = unpack(x)
        return sampson_residuals(skew(tx) @ Rx, norm_ref, norm_cur) * focal_px

    result = least_squares(residuals, np.zeros(5), loss="huber", f_scale=1.0, method="trf", x_scale=1e-3)
    if not result.success or not np.all(np.isfinite(result.x)):
        return R, t
    return unpack(result.x)


def parallax_px(R: np.ndarray, norm_ref: np.ndarray, norm_cur: np.ndarray, focal_px: float) -> float:
    """Median image motion left after removing the rotation ``R`` (px); ~0 for pure rotation or standstill."""
    if len(norm_ref) == 0:
        return 0.0
    rays = np.column_stack([norm_ref, np.ones(len(norm_ref))]) @ R.T
    front = rays[:, 2] > 1e-9
    if not front.any():
        return 0.0
    rotated = rays[front, :2] / rays[front, 2:3]
    return float(np.median(np.linalg.norm(rotated - norm_cur[front], axis=1)) * focal_px)


class _Decomposition(NamedTuple):
    """The best decomposition of an essential matrix: ``n_inliers`` cheirality inliers (in front of both cameras,
    nearer than the depth limit), ``inliers`` ``(N,) bool`` (those, or every RANSAC inlier with
    ``inliers="epipolar"``), ``epipolar_inliers`` its RANSAC inliers."""

    n_inliers: int
    R: np.ndarray
    t: np.ndarray
    inliers: np.ndarray
    epipolar_inliers: int


def _recover(E_stack: np.ndarray, a: np.ndarray, b: np.ndarray, K_est: np.ndarray, mask: np.ndarray,
             inlier_set: str = "cheirality", max_depth_baselines: float = NEAR_BASELINES) -> _Decomposition | None:
    """Best (most cheirality inliers within ``max_depth_baselines``) decomposition among the 3x3 blocks of
    ``E_stack``."""
    best = None
    epipolar = mask.ravel() > 0
    for i in range(0, E_stack.shape[0] - 2, 3):
        E = E_stack[i:i + 3]
        if not np.all(np.isfinite(E)):
            continue
        n_good, R, t, pose_mask, _ = cv2.recoverPose(E, a, b, K_est, distanceThresh=max_depth_baselines,
                                                     mask=mask.copy())
        if best is None or n_good > best.n_inliers:
            # "epipolar" keeps every RANSAC inlier, including the far points the depth limit drops
            inliers = epipolar if inlier_set == "epipolar" else (pose_mask.ravel() > 0)
            best = _Decomposition(int(n_good), R, t.ravel(), inliers, int(epipolar.sum()))
    return best


def far_points_move(R: np.ndarray, t: np.ndarray, norm_ref: np.ndarray, norm_cur: np.ndarray,
                    focal_px: float) -> tuple[bool, float]:
    """Whether far points fix the translation direction of ``R``, ``t`` (refined on them), and their motion: their
    rotation-compensated motion (median, px) is at least :data:`FAR_POINTS_MIN_PARALLAX_PX` and
    :data:`FAR_POINTS_MIN_SIGNAL_TO_NOISE` times their median Sampson error (the match noise)."""
    motion_px = parallax_px(R, norm_ref, norm_cur, focal_px)
    noise_px = float(np.median(np.abs(sampson_residuals(skew(t) @ R, norm_ref, norm_cur)))) * focal_px
    return motion_px >= FAR_POINTS_MIN_PARALLAX_PX and motion_px >= FAR_POINTS_MIN_SIGNAL_TO_NOISE * noise_px, motion_px


def estimate_two_view(points_ref_px: np.ndarray, points_cur_px: np.ndarray, K: np.ndarray,
                      cfg: GeometryConfig | None = None, min_inliers: int = 8,
                      rng: np.random.Generator | None = None, far_points: bool = False) -> TwoViewEstimate:
    """Relative pose from ``(N, 2)`` (or OpenCV's ``(N, 1, 2)``) pixel correspondences and intrinsics ``K (3, 3)``;
    points of another shape, unequal counts, NaN, or a K :func:`validate_K` refuses are a DataError naming the argument.

    Tries every estimator in ``cfg.estimators`` and keeps the decomposition with most cheirality inliers (in front of
    both cameras and nearer than :data:`NEAR_BASELINES`, recoverPose's count); falls back to the fundamental matrix
    (E = K^T F K) when no essential matrix gives ``min_inliers``. ``far_points``: then, if the matrix explains nearly
    all correspondences (:func:`mostly_explained`), the points in front at any distance give the pose when, refined
    on them, they move (:func:`far_points_move`): at walking pace (4.5 cm a frame) 0-1 of 1200 tracks were that near,
    1176 in front. Only for callers that reject a pure rotation otherwise (MonoVO with its sanity checks): under a
    guessed K a pure rotation's far points moved 1.4 px at 126x their Sampson error, which only the K-free
    homography test tells apart. ``rng`` shuffles the correspondences before the robust estimators see them
    (``inliers`` is returned in the input order): the same generator state gives identical results, another one
    other samples. Without ``rng`` the input order is used (deterministic too); ``cv2.setRNGSeed`` has no effect on
    these OpenCV 5 estimators.
    """
    cfg = cfg or GeometryConfig()
    p0 = _pixel_points(points_ref_px, "points_ref_px")
    p1 = _pixel_points(points_cur_px, "points_cur_px")
    if len(p1) != len(p0):
        raise DataError(f"{len(p1)} points for the {len(p0)} of points_ref_px: one per correspondence", source="points_cur_px")
    try:
        K = validate_K(K, source="K")
    except (TypeError, ValueError):
        raise DataError("K must be a 3x3 matrix of numbers", source="K") from None
    if rng is None:
        return _estimate_ordered(p0, p1, K, cfg, min_inliers, far_points)
    order = rng.permutation(len(p0))
    est = _estimate_ordered(p0[order], p1[order], K, cfg, min_inliers, far_points)
    inliers = np.zeros(len(p0), bool)
    inliers[order] = est.inliers
    return replace(est, inliers=inliers)


def _pixel_points(points: np.ndarray, name: str) -> np.ndarray:
    """``(N, 2)`` float64 of ``(N, 2)`` or OpenCV's ``(N, 1, 2)`` finite pixel coordinates; DataError naming ``name``
    otherwise (a transposed ``(2, N)`` was flattened into N pairs of scrambled x and y, and a wrong pose marked ok)."""
    try:
        xy = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError):
        raise DataError("must be (N, 2) pixel coordinates (numbers)", source=name) from None
    if xy.ndim == 3 and xy.shape[1:] == (1, 2):
        xy = xy[:, 0]
    if xy.ndim != 2 or xy.shape[1] != 2:
        transposed = " (one point per column: give its transpose)" if xy.ndim == 2 and xy.shape[0] == 2 else ""
        raise DataError(f"must be (N, 2) or (N, 1, 2) pixel coordinates, got shape {xy.shape}{transposed}", source=name)
    bad = np.flatnonzero(~np.isfinite(xy).all(axis=1))
    if len(bad):
        raise DataError(f"NaN or infinite coordinates in {len(bad)} of {len(xy)} points (first: row {bad[0]})", source=name)
    return xy


def _estimate_ordered(p0: np.ndarray, p1: np.ndarray, K: np.ndarray, cfg: GeometryConfig,
                      min_inliers: int, far_points: bool = False) -> TwoViewEstimate:
    n = len(p0)
    attempts: list[str] = []
    if n < 5:
        return _failed(n, f"too few correspondences for the essential matrix ({n} < 5)", attempts)
    focal = float(K[0, 0])
    n0, n1 = normalize_points(p0, K), normalize_points(p1, K)
    rot_px = rotation_only_fit(n0, n1, focal)[1]
    degeneracy = degeneracy_measures(p0, p1, K, cfg)
    if cfg.normalize:
        a, b, K_est, thr = n0, n1, np.eye(3), cfg.threshold_px / focal
    else:
        a, b, K_est, thr = p0, p1, np.asarray(K, np.float64), cfg.threshold_px

    best = None  # (n_good, R, t, inliers, epipolar inliers, method)
    matrices = []  # (E, mask, a, b, K_est, method): for the far points
    for name in cfg.estimators:
        E, mask = cv2.findEssentialMat(a, b, K_est, method=_METHODS[name], prob=cfg.confidence, threshold=thr)
        if E is None or mask is None or E.ndim != 2 or E.shape[1] != 3 or E.shape[0] < 3:
            attempts.append(f"E-{name}: no solution")
            continue
        rec = _recover(E, a, b, K_est, mask, cfg.inliers)
        if rec is None:
            attempts.append(f"E-{name}: non-finite E")
            continue
        matrices.append((E, mask, a, b, K_est, f"E-{name}"))
        attempts.append(f"E-{name}: {rec.n_inliers} inliers")
        if best is None or rec.n_inliers > best[0]:
            best = (*rec, f"E-{name}")

    if cfg.fundamental_fallback and (best is None or best[0] < min_inliers) and n >= 8:
        F, mask = cv2.findFundamentalMat(p0, p1, cv2.FM_RANSAC, cfg.threshold_px, cfg.confidence)
        if F is None or F.shape[0] < 3:
            attempts.append("F-fallback: no solution")
        else:
            E = K.T @ F[:3] @ K
            rec = _recover(E, n0, n1, np.eye(3), mask, cfg.inliers)
            if rec is None:
                attempts.append("F-fallback: non-finite E")
            else:
                matrices.append((E, mask, n0, n1, np.eye(3), "F-fallback"))
                attempts.append(f"F-fallback: {rec.n_inliers} inliers")
                if best is None or rec.n_inliers > best[0]:
                    best = (*rec, "F-fallback")

    if best is None:
        return _failed(n, "no essential/fundamental matrix found (" + "; ".join(attempts) + ")", attempts, rot_px,
                       degeneracy)
    # the correspondences the matrix explaining most of them explains (the F-fallback's, chosen for its near points,
    # had said "1109 of 1178" where E-RANSAC's explained 1171)
    explained = max(int(np.count_nonzero(mask)) for _, mask, *_ in matrices) if matrices else best[4]
    if far_points and best[0] < min_inliers and mostly_explained(explained, n, min_inliers):
        far = _far_points_estimate(matrices, n0, n1, focal, cfg, min_inliers)
        if far is not None:
            R, t, inliers, n_front, n_epipolar, method, motion_px = far
            attempts.append(f"{method}: {n_front} inliers in front at any distance, moving {motion_px:.2f} px")
            return TwoViewEstimate(R, t / max(np.linalg.norm(t), 1e-300), inliers, method, n_front, motion_px, None,
                                   tuple(attempts), rot_px, **asdict(degeneracy), epipolar_inliers=n_epipolar)
    n_good, R, t, inliers, n_epipolar, method = best
    if n_good < min_inliers:  # (the reason of too few pose inliers quotes the matrix that explains most)
        n_epipolar = max(n_epipolar, explained)
    if n_good < 5:
        return _failed(n, f"too few pose inliers ({n_good}) from {method}", attempts, rot_px, degeneracy,
                       epipolar_inliers=n_epipolar)
    if cfg.refine and n_good >= 8:
        R, t = refine_pose(R, t, n0[inliers], n1[inliers], focal)
    par = parallax_px(R, n0[inliers], n1[inliers], focal)
    return TwoViewEstimate(R, t / max(np.linalg.norm(t), 1e-300), inliers, method, n_good, par, None, tuple(attempts),
                           rot_px, **asdict(degeneracy), epipolar_inliers=n_epipolar)


def _far_points_estimate(matrices: list, n0: np.ndarray, n1: np.ndarray, focal: float, cfg: GeometryConfig,
                         min_inliers: int) -> tuple | None:
    """The pose from the points in front of both cameras at any distance, refined on them, of the first of
    ``matrices`` (most such points first) whose points number ``min_inliers`` and move (:func:`far_points_move`):
    ``(R, t, inliers, n_inliers, epipolar_inliers, method, motion_px)``, else None. Every matrix is tried: the
    F-fallback's had a few more points in front than E-RANSAC's but too noisy to move, and the pair was refused."""
    decompositions = []
    for E, mask, a, b, K_est, method in matrices:
        rec = _recover(E, a, b, K_est, mask, cfg.inliers, max_depth_baselines=np.inf)
        if rec is not None and rec.n_inliers >= max(min_inliers, 8):
            decompositions.append((rec, method))
    for (n_front, R, t, inliers, n_epipolar), method in sorted(decompositions, key=lambda d: -d[0].n_inliers):
        if cfg.refine:
            R, t = refine_pose(R, t, n0[inliers], n1[inliers], focal)
        moves, motion_px = far_points_move(R, t, n0[inliers], n1[inliers], focal)
        if moves:
            return R, t, inliers, n_front, n_epipolar, method, motion_px
    return None


def triangulate(R_cur_ref: np.ndarray, t_cur_ref: np.ndarray, norm_ref: np.ndarray,
                norm_cur: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Triangulate normalized correspondences; returns the points in the reference and in the current frame
    (``(N, 3)`` each, in units of ``|t|``) and the angle between the two viewing rays ``(N,)`` in degrees."""
    P0 = np.eye(3, 4)
    P1 = np.column_stack([R_cur_ref, t_cur_ref])
    X = cv2.triangulatePoints(P0, P1, norm_ref.T.astype(np.float64), norm_cur.T.astype(np.float64))
    with np.errstate(divide="ignore", invalid="ignore"):
        X_ref = (X[:3] / X[3]).T
    X_cur = X_ref @ R_cur_ref.T + t_cur_ref
    center_cur_in_ref = -R_cur_ref.T @ t_cur_ref
    ray0 = X_ref / np.linalg.norm(X_ref, axis=1, keepdims=True)
    ray1 = X_ref - center_cur_in_ref
    ray1 /= np.linalg.norm(ray1, axis=1, keepdims=True)
    angle = np.degrees(np.arccos(np.clip(np.sum(ray0 * ray1, axis=1), -1.0, 1.0)))
    return X_ref, X_cur, np.where(np.isfinite(angle), angle, 0.0)


def rotation_error_deg(R_est: np.ndarray, R_ref: np.ndarray) -> float:
    """Angle of ``R_est R_ref^T`` in degrees."""
    return float(np.degrees(np.linalg.norm(so3_log(R_est @ R_ref.T))))
