"""The 6x6 covariance of a registration, computed after the fact from its final correspondences.

Convention (every variant, see ``COVARIANCE_CONVENTION``): the perturbation is applied on the **left, in the
target frame**, translation first: ``T_true = se3_exp(xi) @ T_target_source`` with
``xi = (tx, ty, tz, rx, ry, rz)`` in metres and radians. ``information`` is its inverse (on the constrained
subspace; see :func:`safe_inverse`).

Both closed forms model each matched pair by its point-to-surface residual ``r_i = M_i (p_i - q_i)`` (``M_i``:
projector on the directions in which the target surface around ``q_i`` is thin, as in ``degeneracy.py``) with
Jacobian ``J_i = M_i [I, -[p_i]x]`` for the aligned source point ``p_i``:

- ``gauss_newton``: ``sigma^2 (sum J^T J)^-1``, ``sigma^2`` the residual variance per constrained dimension.
- ``censi`` (Censi 2007, the default): ``A^-1 B A^-1`` with ``A = sum J^T J`` and
  ``B = sum J^T Sigma_i J``, where ``Sigma_i`` is the noise of the pair along the two sensor rays (range noise of
  the source point along its ray from the source origin, of the target point along its ray from the target
  origin), plus the thickness of the target surface around ``q_i`` across it (the variance of its neighbours
  about their plane: curvature and sparse rings that a plane does not model, the map's sampling error). It
  weights grazing returns correctly, which the isotropic residual variance cannot.

Closed forms assume every correspondence carries independent noise; on real and simulated scans neighbouring
returns share their sampling error (the ray pattern, the surface discretisation), so taken as they are they are
over-confident by one to three orders of magnitude (``benchmarks/covariance_calibration.py``). Both are therefore
scaled by ``n / n_eff``, ``n_eff`` the number of distinct ``correlation_voxel_m`` voxels that hold a matched
source point (pairs inside one voxel count as one observation), and the default ``censi`` form by a measured
per-variant correction per tangent-space axis, a factor and a systematic floor, and one coverage scalar
(:data:`CALIBRATION`), learned on some scenes and seeds and checked on others.
"""

from __future__ import annotations

import contextlib
import contextvars
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from lidarkit.errors import ConfigError

COVARIANCE_CONVENTION = (
    "left perturbation in the target frame, T_true = se3_exp(xi) @ T_target_source, "
    "xi = (tx, ty, tz, rx, ry, rz) in m and rad"
)
COVARIANCE_METHODS = ("censi", "gauss_newton")

#: Matched source points within one voxel of this size count as one independent observation (see module doc).
DEFAULT_CORRELATION_VOXEL_M = 1.0

#: Eigenvalues of the information below this fraction of the largest are treated as this fraction: the
#: unconstrained directions get a large but finite variance, and the result stays symmetric positive definite.
EIGEN_FLOOR = 1e-12


@dataclass(frozen=True)
class CovarianceModel:
    """How :func:`registration_covariance` turns correspondences into a covariance.

    ``range_noise_m``: the sensor's range noise (std); ``None`` estimates it from the residuals of the pairs.
    """

    method: str = "censi"
    correlation_voxel_m: float | None = DEFAULT_CORRELATION_VOXEL_M
    range_noise_m: float | None = None
    surface_noise: bool = True

    def __post_init__(self) -> None:
        if self.method not in COVARIANCE_METHODS:
            raise ConfigError(f"unknown covariance method {self.method!r}; valid: {', '.join(COVARIANCE_METHODS)}", source="covariance")
        if self.correlation_voxel_m is not None and not self.correlation_voxel_m > 0:
            raise ConfigError("correlation_voxel_m must be > 0 (or None: every pair independent)", source="covariance")
        if self.range_noise_m is not None and not (np.isfinite(self.range_noise_m) and self.range_noise_m > 0):
            raise ConfigError("range_noise_m must be a finite positive number (or None: from the residuals)", source="covariance")


DEFAULT_MODEL = CovarianceModel()

_ACTIVE_MODEL: contextvars.ContextVar[CovarianceModel | None] = contextvars.ContextVar("covariance_model", default=DEFAULT_MODEL)


def active_model() -> CovarianceModel | None:
    """The model of the registration running in this context (None: no covariance wanted)."""
    return _ACTIVE_MODEL.get()


@contextlib.contextmanager
def use_model(model: CovarianceModel | None) -> Iterator[None]:
    """Run a registration with ``model`` (set by ``Registration.align`` from the variant's config), so the shared
    end-of-registration assessment computes the covariance the variant asked for, however deep it is called."""
    token = _ACTIVE_MODEL.set(model)
    try:
        yield
    finally:
        _ACTIVE_MODEL.reset(token)


@dataclass(frozen=True)
class AxisCalibration:
    """A variant's measured correction of its default (``censi``) covariance, per tangent-space axis
    ``(tx, ty, tz, rx, ry, rz)`` (see :func:`calibrate`).

    ``factors`` ``f`` and ``sigmas`` ``b`` (m, rad): ``E[xi_j^2 | Sigma_jj] = f_j Sigma_jj + b_j^2``; ``coverage`` ``c``:
    one scalar on the whole matrix, so that ~94.5 % of the training errors fall inside the chi-square(6) 95 % bound;
    ``trained_variance``: the largest closed-form variance per axis on the training pairs (the range ``f`` was
    measured on).
    """

    factors: tuple[float, ...]
    sigmas: tuple[float, ...]
    coverage: float = 1.0
    trained_variance: tuple[float, ...] | None = None


#: the scenes and seeds (``scene:seed``) the calibration was learned on: any check of it must use others
CALIBRATION_TRAINING = ("street:0", "street:2", "street:4", "street:6")

#: Per-variant calibration of the default covariance, learned on street seeds 0, 2, 4 and 6 (100 draws each, one frame
#: pair per draw: ``--train-frames 201``) and checked on street seeds 1, 3, 5, 7, 8 (41- and 201-frame runs) and
#: corridor seed 1 (``benchmarks/covariance_calibration.py``, results in ``benchmarks/results/covariance``). ``f``
#: absorbs what the closed form under- or over-states in proportion (the ground refinement of ground_filtered that
#: its assessment does not see, the GICP variants' own surface model);
#: ``b`` each variant's systematic error that no residual shows and that does not scale with the closed form
#: (point-to-point matching of ring-sampled ground holds the forward translation back); ``c`` the remaining
#: over- or under-coverage of the pooled training errors (94.5 % inside the 95 % bound, mean NEES at least 5); the
#: training range ``v`` keeps a direction weaker than on any training scene from being shrunk (a corridor's axis).
#: knn and pipeline (default composition) are learned the same way (knn on 50 draws per seed); a variant without an
#: entry is returned uncalibrated.
CALIBRATION: dict[str, AxisCalibration] = {
    # generated by benchmarks/covariance_calibration.py (the "CALIBRATION" block of its README)
    "vanilla": AxisCalibration(
        (282, 65.4, 1.08, 0.243, 0.564, 14.6),
        (7.64e-14, 3.62e-10, 1.47e-09, 0.00083, 3.8e-11, 5.92e-10),
        0.823, (0.00382, 0.00141, 5.83e-05, 6.55e-06, 7.98e-06, 7.8e-06)),
    "ground_filtered": AxisCalibration(
        (0.217, 0.381, 5.63e-06, 5.25e-06, 4.31e-05, 0.0268),
        (0.00366, 1.83e-08, 0.00024, 2.97e-05, 3.81e-05, 0.000322),
        1.19, (0.000763, 0.00022, 0.00897, 0.000166, 2.35e-05, 6.37e-06)),
    "open3d_point_to_point": AxisCalibration(
        (148, 16, 0.883, 0.174, 0.695, 0.216),
        (1.44e-12, 9.6e-15, 4.2e-09, 0.000882, 1.4e-11, 0.00118),
        0.748, (0.0015, 0.000873, 7.31e-05, 1.07e-05, 6.88e-06, 8.5e-06)),
    "open3d_point_to_plane": AxisCalibration(
        (0.292, 0.0727, 0.0576, 0.0436, 0.179, 0.0553),
        (0.00958, 0.00711, 0.00321, 0.000464, 0.000349, 0.000173),
        0.959, (0.00199, 0.000533, 0.000431, 1.72e-05, 4.23e-06, 2.5e-06)),
    "open3d_gicp": AxisCalibration(
        (0.00804, 0.0467, 0.00415, 0.0109, 0.314, 0.0118),
        (0.0021, 0.00319, 0.00119, 0.000323, 3.01e-10, 0.000156),
        1.06, (0.0021, 0.000457, 0.000425, 1.84e-05, 4.36e-06, 2.75e-06)),
    "small_gicp": AxisCalibration(
        (0.00726, 0.00388, 0.0183, 0.0238, 0.0212, 0.00343),
        (3.9e-07, 0.000797, 0.000818, 0.000396, 0.000429, 9.23e-05),
        1.06, (0.000484, 0.000449, 0.000104, 1.82e-05, 6.43e-06, 2.55e-06)),
    "kiss": AxisCalibration(
        (0.624, 0.379, 0.254, 0.0638, 3.44, 0.0293),
        (0.102, 0.0376, 3e-08, 0.000983, 1.38e-13, 0.000418),
        1.19, (0.0156, 0.0075, 0.00106, 3.51e-05, 3.17e-06, 4.42e-06)),
    "genz": AxisCalibration(
        (0.647, 6.5, 0.992, 0.252, 6.18, 0.0617),
        (0.0283, 2.51e-10, 0.0071, 0.000952, 0.003, 0.000537),
        1.2, (0.000815, 0.000319, 6.11e-05, 2.97e-05, 4.81e-06, 9.04e-06)),
    # the same point-to-point ICP as vanilla in one stage; 50 draws per training seed, 100 per held-out seed
    # (benchmarks/results/covariance/knn)
    "knn": AxisCalibration(
        (299, 83.5, 0.99, 0.171, 0.624, 23.7),
        (7.31e-11, 4.31e-11, 1.35e-09, 0.000852, 6.35e-11, 2.46e-10),
        0.813, (0.00385, 0.00139, 4.95e-05, 8.36e-06, 7.78e-06, 8.65e-06)),
    # measured for the default composition (kiss_like: same poses and raw covariances as kiss on every pair, so the
    # same entry); another composition (another residual or kernel) gets these numbers unverified
    # (benchmarks/results/covariance/pipeline)
    "pipeline": AxisCalibration(
        (0.624, 0.379, 0.254, 0.0638, 3.44, 0.0293),
        (0.102, 0.0376, 3e-08, 0.000983, 1.38e-13, 0.000418),
        1.19, (0.0156, 0.0075, 0.00106, 3.51e-05, 3.17e-06, 4.42e-06)),
}


def calibrate(covariance: np.ndarray, variant: str) -> np.ndarray:
    """``covariance`` with the variant's correction of :data:`CALIBRATION` applied (unchanged for a variant that
    has none), see :func:`apply_calibration`."""
    entry = CALIBRATION.get(variant)
    return covariance if entry is None else apply_calibration(covariance, entry)


def apply_calibration(covariance: np.ndarray, entry: AxisCalibration) -> np.ndarray:
    """``Sigma' = c (S Sigma S + diag(b^2))``, symmetric PSD.

    ``S = diag(sqrt(g))`` with ``g_j = f_j`` while ``Sigma_jj`` stays within the training range ``v_j``; the part of
    the variance beyond it is scaled by ``max(f_j, 1)`` only: a direction weaker than on any training scene (a
    corridor's axis) is not shrunk by a factor measured where it was constrained, so the floors ``b`` of the
    constrained axes do not swamp it.
    """
    factors, sigmas = np.asarray(entry.factors, dtype=np.float64), np.asarray(entry.sigmas, dtype=np.float64)
    var = np.clip(np.diag(covariance).astype(np.float64), 0.0, None)
    if entry.trained_variance is not None:
        limit = np.asarray(entry.trained_variance, dtype=np.float64)
        excess = np.clip(var - limit, 0.0, None)
        with np.errstate(divide="ignore", invalid="ignore"):
            g = np.where(var > 0, (factors * (var - excess) + np.maximum(factors, 1.0) * excess) / np.where(var > 0, var, 1.0), factors)
    else:
        g = factors
    scale = np.sqrt(g)
    return make_psd(float(entry.coverage) * (covariance * np.outer(scale, scale) + np.diag(sigmas**2)))


def left_jacobians(points_xyz: np.ndarray) -> np.ndarray:
    """``(n, 3, 6)`` derivative of ``se3_exp(xi) @ p`` at ``xi = 0``: ``[I, -[p]x]``."""
    p = np.asarray(points_xyz, dtype=np.float64)
    n = len(p)
    J = np.zeros((n, 3, 6))
    J[:, 0, 0] = J[:, 1, 1] = J[:, 2, 2] = 1.0
    J[:, 0, 4], J[:, 0, 5] = p[:, 2], -p[:, 1]
    J[:, 1, 3], J[:, 1, 5] = -p[:, 2], p[:, 0]
    J[:, 2, 3], J[:, 2, 4] = p[:, 1], -p[:, 0]
    return J


def make_psd(S: np.ndarray) -> np.ndarray:
    """Symmetric positive semi-definite part of a 6x6 matrix (negative eigenvalues from rounding set to 0)."""
    S = 0.5 * (S + S.T)
    w, V = np.linalg.eigh(S)
    return (V * np.clip(w, 0.0, None)) @ V.T


def safe_inverse(A: np.ndarray, floor: float = EIGEN_FLOOR) -> np.ndarray:
    """Inverse of a symmetric PSD 6x6 matrix with its eigenvalues floored at ``floor * max``: a direction the data
    do not constrain gets a large finite variance instead of inf/NaN."""
    A = 0.5 * (A + A.T)
    w, V = np.linalg.eigh(A)
    top = max(float(w[-1]), 0.0)
    if top <= 0 or not np.isfinite(top):
        return np.eye(6) / floor
    w = np.maximum(w, floor * top)
    return (V / w) @ V.T


def effective_observations(points_xyz: np.ndarray, voxel_m: float | None) -> int:
    """Number of distinct ``voxel_m`` voxels holding a point (``len(points)`` when ``voxel_m`` is None)."""
    if voxel_m is None or len(points_xyz) == 0:
        return len(points_xyz)
    keys = np.floor(np.asarray(points_xyz) / voxel_m).astype(np.int64)
    cols = [keys[:, i] - keys[:, i].min() for i in range(3)]
    span = [int(c.max()) + 1 for c in cols]
    if float(span[0]) * span[1] * span[2] >= 2.0**62:  # no room for one packed integer key: compare rows
        return int(len(np.unique(keys, axis=0)))
    # one integer per voxel: a 1-D unique, ~5x faster than np.unique(axis=0) on rows
    return int(len(np.unique((cols[0] * span[1] + cols[1]) * span[2] + cols[2])))


def registration_covariance(
    source_aligned_xyz: np.ndarray,
    matched_target_xyz: np.ndarray,
    constraints: np.ndarray,
    T_target_source: np.ndarray,
    model: CovarianceModel = DEFAULT_MODEL,
    n_total: int | None = None,
    n_effective: int | None = None,
    surface_variance: np.ndarray | None = None,
) -> np.ndarray:
    """6x6 covariance (see the module doc for the convention) of a registration from ``n`` matched pairs.

    ``source_aligned_xyz`` / ``matched_target_xyz``: ``(n, 3)`` pairs in the target frame; ``constraints``:
    ``(n, 3, 3)`` surface projectors; ``T_target_source`` places the source sensor origin. When the pairs are a
    subsample, ``n_total`` is the number of pairs they stand for (the Hessian is scaled up to it) and
    ``n_effective`` the independent observations among them (default: all of ``n_total``).
    """
    p = np.asarray(source_aligned_xyz, dtype=np.float64)
    q = np.asarray(matched_target_xyz, dtype=np.float64)
    n = len(p)
    if n < 3:
        return np.eye(6) / EIGEN_FLOOR
    n_total = n if n_total is None else int(n_total)
    n_effective = n_total if n_effective is None else max(int(n_effective), 1)
    M = np.asarray(constraints, dtype=np.float64)
    J0 = left_jacobians(p)
    J = np.matmul(M, J0)
    A = np.einsum("nki,nkj->ij", J, J)
    r = np.einsum("nij,nj->ni", M, p - q)
    if model.method == "gauss_newton":
        dof = float(np.trace(M, axis1=1, axis2=2).sum())
        sigma2 = float((r * r).sum()) / max(dof - 6.0, 1.0)
        cov_subsample = sigma2 * safe_inverse(A)
    else:
        origin_source = np.asarray(T_target_source, dtype=np.float64)[:3, 3]
        d_s = _unit(p - origin_source)
        d_t = _unit(q)
        # noise of the pair's residual per unit range variance: M (d_s d_s^T + d_t d_t^T) M
        Ms, Mt = np.einsum("nij,nj->ni", M, d_s), np.einsum("nij,nj->ni", M, d_t)
        if model.range_noise_m is None:
            unit_var = float((Ms * Ms).sum() + (Mt * Mt).sum())
            sigma2 = float((r * r).sum()) / max(unit_var, 1e-12)
        else:
            sigma2 = float(model.range_noise_m) ** 2
        # B = sigma^2 sum J0^T (M d_s d_s^T M + M d_t d_t^T M) J0 with J0 = [I, -[p]x]
        gs = np.einsum("ni,nij->nj", Ms, J0)
        gt = np.einsum("ni,nij->nj", Mt, J0)
        B = sigma2 * (gs.T @ gs + gt.T @ gt)
        if model.surface_noise and surface_variance is not None:
            # the target surface itself is known only to its thickness across the plane (curvature, sparse rings)
            B = B + np.einsum("n,nki,nkj->ij", np.asarray(surface_variance, dtype=np.float64), J, J)
        A_inv = safe_inverse(A)
        # the sandwich vanishes where A does (B has no noise there either): directions the data do not constrain
        # get the Gauss-Newton variance on the floored eigenvalue instead, i.e. a large one
        w, V = np.linalg.eigh(0.5 * (A + A.T))
        top = max(float(w[-1]), 0.0)
        free = w < EIGEN_FLOOR * top if top > 0 else np.ones(6, bool)
        cov_subsample = A_inv @ B @ A_inv
        if free.any():
            floor = max(EIGEN_FLOOR * top, 1e-300)
            cov_subsample = cov_subsample + (V[:, free] * (sigma2 / floor)) @ V[:, free].T
    # the subsample stands for n_total pairs of which n_effective are independent
    cov = cov_subsample * (n / n_total) * (n_total / n_effective)
    return make_psd(cov)


def _unit(v: np.ndarray) -> np.ndarray:
    norm = np.linalg.norm(v, axis=1, keepdims=True)
    return np.where(norm > 0, v / np.where(norm > 0, norm, 1.0), 0.0)


def nees(error_xi: np.ndarray, covariance: np.ndarray) -> float:
    """Normalized estimation error squared ``xi^T Sigma^-1 xi`` (expected value 6 for a calibrated covariance)."""
    xi = np.asarray(error_xi, dtype=np.float64).reshape(6)
    return float(xi @ safe_inverse(covariance) @ xi)


def adjoint(T: np.ndarray) -> np.ndarray:
    """6x6 adjoint of an SE(3) pose for twists ordered translation first: ``se3_exp(Ad xi) = T se3_exp(xi) T^-1``."""
    from lidarkit.geometry import skew

    R, t = T[:3, :3], T[:3, 3]
    Ad = np.zeros((6, 6))
    Ad[:3, :3] = R
    Ad[:3, 3:] = skew(t) @ R
    Ad[3:, 3:] = R
    return Ad


__all__ = [
    "COVARIANCE_CONVENTION", "COVARIANCE_METHODS", "CovarianceModel", "DEFAULT_CORRELATION_VOXEL_M", "DEFAULT_MODEL",
    "AxisCalibration", "CALIBRATION", "CALIBRATION_TRAINING", "active_model", "adjoint", "apply_calibration", "calibrate", "effective_observations", "use_model", "left_jacobians", "make_psd", "nees", "registration_covariance", "safe_inverse",
]
