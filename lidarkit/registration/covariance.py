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

Some variants also carry an error that no noise model explains and that the data reveal: point-to-point ICP on
ring-sampled ground settles where the rings of the two scans coincide, not where the surfaces do. From the final
pose, one Gauss-Newton step of the point-to-surface residuals above (:func:`covariance_and_step`, no ground truth
needed) points along that error: on the simulated training streets it correlates 0.91-0.97 with the true error of
vanilla, open3d_point_to_point and genz in x and y (yaw: 0.61-0.97; kiss: 0.70 in x). The calibration adds it as a
rank-one term ``(g * step)(g * step)^T`` (per-axis gains ``g`` learned like the factors), so the covariance grows in
the direction the pose is off, and, because the step predicts a large error less exactly than a small one, a
spread ``|step_t|^2 diag(h^2)`` on every axis (``h`` learned with the factors).
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

#: The point-to-surface step uses the pairs closer than this: a wider gate lets far, wrong matches steer it (kiss's
#: 3-sigma gate is 6 m at its initial threshold), and a pose off by more than this is not a small error to correct.
STEP_PAIR_DISTANCE_M = 1.0

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
    measured on); ``step_gains`` ``g``: the regression of the error on the result's point-to-surface step per axis
    (0 where the step does not predict the error), so that ``E[xi xi^T] = c (... + (g * step)(g * step)^T)``;
    ``step_spread`` ``h`` (m or rad per m of step): what the step's prediction misses grows with the step's size (a
    result far from where the surfaces agree is off by more than the step says, on every axis), so
    ``E[(xi_j - g_j step_j)^2] = f_j Sigma_jj + b_j^2 + h_j^2 |step_t|^2``, ``step_t`` the step's translation.
    """

    factors: tuple[float, ...]
    sigmas: tuple[float, ...]
    coverage: float = 1.0
    trained_variance: tuple[float, ...] | None = None
    step_gains: tuple[float, ...] | None = None
    step_spread: tuple[float, ...] | None = None
    axes: str = "target"
    """The axes the per-axis terms refer to: ``"target"``, the target frame's; ``"principal"``, the target frame
    turned about z so that x runs along the weakest horizontal direction of the closed form (:func:`principal_turn`),
    so the calibration's axes follow a scene however it is turned (its sigmas less closely than the closed form's: the
    surface step is taken on voxels fixed to the frame's axes, docs/registration.md)."""

    def __post_init__(self) -> None:
        if self.axes not in ("target", "principal"):
            raise ConfigError(f"axes must be 'target' or 'principal', got {self.axes!r}", source="covariance calibration")


#: the scenes and seeds (``scene:seed``) the calibration was learned on: any check of it must use others
CALIBRATION_TRAINING = ("street:0", "street:2", "street:4", "street:6", "street:12", "street:13", "street:14", "street:15")

#: Per-variant calibration of the default covariance, in the principal axes (x along the weakest horizontal direction
#: of each closed form, :func:`principal_turn`: its axes follow a scene turned in the frame), learned on street
#: seeds 0, 2, 4, 6, 12, 13, 14 and 15 (200 draws each, one frame pair per draw along a 201-frame street) and checked
#: on street seeds 1, 3, 5, 7, 8, 9, 10, 11, corridor seed 1 and open seed 1 (200 draws each;
#: ``benchmarks/covariance_calibration.py``, results in ``benchmarks/results/covariance``). ``g`` (step gains) carries
#: the error the point-to-surface step predicts (the sampling bias of point-to-point matching: vanilla, knn,
#: open3d_point_to_point, kiss, genz; ground_filtered's x, y and yaw; small_gicp's pitch); ``f`` absorbs what the closed form under- or
#: over-states in proportion (the ground refinement of ground_filtered that its assessment does not see, the GICP
#: variants' own surface model); ``b`` each variant's systematic error that neither shows; ``h`` (step spread, with the
#: step gains) the part of the error the step leaves that grows with the step; ``c`` the remaining over- or
#: under-coverage of the pooled training errors (94.5 % inside the 95 % bound, mean NEES at least 5); the training
#: range ``v`` keeps a direction weaker than on any training scene from being shrunk (a corridor's axis). Only the draws
#: a variant reports converged are learned from. knn is learned the same way (seeds 0, 2, 4, 6, 100 draws each),
#: pipeline carries kiss's entry (below); a variant without an entry, or configured other than the entry was learned
#: (:data:`CALIBRATED_SETTINGS`), is returned uncalibrated.
CALIBRATION: dict[str, AxisCalibration] = {
    # generated by benchmarks/covariance_calibration.py (the "CALIBRATION" block of its README)
    "vanilla": AxisCalibration(
        (9.51, 2.74, 0.123, 0.0568, 0.13, 0.471),
        (1.88e-11, 1.38e-14, 1.22e-09, 0.000363, 0.00048, 5.62e-12),
        0.841, (0.00394, 0.0014, 5.83e-05, 2.29e-05, 9.46e-06, 8.03e-06),
        (1.48, 1.46, 0.849, 0.8, 0.983, 1.36),
        (1.19e-08, 3.14e-12, 0.00891, 0.00123, 2.39e-09, 0.00371), axes="principal"),
    "ground_filtered": AxisCalibration(
        (0.079, 0.153, 4.49e-06, 5.12e-06, 3.75e-05, 0.00906),
        (0.000429, 3.32e-12, 0.000231, 2.9e-05, 3.81e-05, 0.000204),
        1.1, (0.00127, 0.000291, 0.0125, 0.000247, 0.000117, 9.06e-06),
        (1.07, 1.3, 0, 0, 0, 0.857),
        (0.0648, 0.121, 0.000404, 5.11e-05, 4.71e-06, 0.00111), axes="principal"),
    "open3d_point_to_point": AxisCalibration(
        (4.06, 1.6, 0.137, 0.0497, 0.263, 0.0903),
        (0.0109, 1.88e-10, 3.8e-13, 0.000468, 6.86e-10, 0.000461),
        0.933, (0.0024, 0.000923, 9.36e-05, 3.82e-05, 6.88e-06, 8.5e-06),
        (1.47, 1.6, 0.944, 0.862, 1.08, 1.14),
        (9.02e-13, 9.28e-09, 0.00752, 0.000446, 9.06e-17, 0.00267), axes="principal"),
    "open3d_point_to_plane": AxisCalibration(
        (0.504, 0.345, 0.0652, 0.0377, 0.193, 0.0337),
        (9.57e-10, 3.1e-08, 0.00296, 0.000451, 0.000274, 0.000206),
        0.992, (0.00201, 0.000406, 0.000431, 2.26e-05, 7.46e-06, 2.5e-06), axes="principal"),
    "open3d_gicp": AxisCalibration(
        (0.00613, 0.0639, 0.0047, 0.0152, 0.244, 0.0164),
        (0.0026, 0.00149, 0.00124, 0.000363, 0.000234, 0.00014),
        1.05, (0.00212, 0.000396, 0.000425, 2.19e-05, 8.96e-06, 2.75e-06), axes="principal"),
    "small_gicp": AxisCalibration(
        (0.0044, 0.00535, 0.00911, 0.0222, 0.0102, 0.00508),
        (0.000685, 0.000542, 0.00117, 0.000364, 0.000248, 7.51e-05),
        1.03, (0.000654, 0.00028, 0.000167, 3.15e-05, 7.67e-06, 2.55e-06),
        (0, 0, 0, 0, 0.278, 0),
        (0.012, 0.00449, 0.00834, 0.0034, 0.00365, 0.000266), axes="principal"),
    "kiss": AxisCalibration(
        (0.284, 0.455, 0.103, 0.0532, 1.46, 0.0368),
        (0.0458, 0.00828, 6.45e-13, 0.000818, 0.000307, 0.000389),
        1.08, (0.0248, 0.00858, 0.00128, 4.72e-05, 3.55e-06, 6.16e-06),
        (1.58, 0, 0.865, 0.582, 2.8, 0),
        (0.791, 0.543, 8.45e-11, 3.43e-12, 2.29e-09, 0.00385), axes="principal"),
    "genz": AxisCalibration(
        (0.114, 0.491, 0.724, 0.154, 0.242, 0.0232),
        (0.0068, 2.99e-14, 1.21e-24, 0.000869, 0.000483, 0.000396),
        0.971, (0.00291, 0.00135, 0.000146, 6.53e-05, 1.07e-05, 1.57e-05),
        (0.609, 1.03, 0.89, 0, 1.43, 0.378),
        (0.378, 0.185, 8.61e-09, 0.00884, 0.0057, 0.00241), axes="principal"),
    # the same point-to-point ICP as vanilla in one stage; 100 draws per training seed and per held-out seed
    # (benchmarks/results/covariance/knn)
    "knn": AxisCalibration(
        (8.77, 3.5, 0.112, 0.124, 0.151, 0.207),
        (5.78e-10, 2.48e-16, 5.62e-12, 0.00027, 0.000377, 1.31e-11),
        0.832, (0.00385, 0.00139, 5.38e-05, 1.12e-05, 8.53e-06, 8.65e-06),
        (1.5, 1.48, 0.933, 0.805, 1.01, 1.39),
        (2.6e-12, 5.2e-09, 0.00852, 0.00149, 1.28e-12, 0.00394), axes="principal"),
}


#: The same calibration learned without the step term, for the variants whose entry has one: used when a covariance
#: comes without its step (``calibrate(cov, variant)``), e.g. the odometry frame covariance of a stateful variant,
#: assessed on two voxelized scans rather than on the variant's own final correspondences, where the step shows
#: the scans' surface preference and not the variant's bias (kiss with the step term there: 1-frame NEES 3.1, 100 %
#: inside; the step-trained entry without its term: NEES 9.0, 79 % inside). Generated with :data:`CALIBRATION`.
CALIBRATION_WITHOUT_STEP: dict[str, AxisCalibration] = {
    "vanilla": AxisCalibration(
        (312, 48, 1.13, 0.165, 0.545, 14.6),
        (6.91e-14, 2.31e-17, 7.81e-10, 0.000863, 0.000399, 7.23e-11),
        0.909, (0.00394, 0.0014, 5.83e-05, 2.29e-05, 9.46e-06, 8.03e-06), axes="principal"),
    "ground_filtered": AxisCalibration(
        (0.206, 0.424, 4.57e-06, 5.17e-06, 3.75e-05, 0.0196),
        (0.00442, 2.58e-13, 0.00023, 2.89e-05, 3.81e-05, 0.000319),
        1.15, (0.00127, 0.000291, 0.0125, 0.000247, 0.000117, 9.06e-06), axes="principal"),
    "open3d_point_to_point": AxisCalibration(
        (172, 14.6, 0.94, 0.156, 0.744, 0.23),
        (7.6e-13, 1.02e-15, 2.41e-09, 0.000847, 9.68e-11, 0.0012),
        0.788, (0.0024, 0.000923, 9.36e-05, 3.82e-05, 6.88e-06, 8.5e-06), axes="principal"),
    "small_gicp": AxisCalibration(
        (0.00706, 0.00626, 0.00911, 0.0222, 0.0242, 0.00508),
        (0.000151, 0.000438, 0.00122, 0.000387, 0.000439, 7.58e-05),
        1.02, (0.000654, 0.00028, 0.000167, 3.15e-05, 7.67e-06, 2.55e-06), axes="principal"),
    "kiss": AxisCalibration(
        (0.695, 0.388, 0.269, 0.0761, 3.2, 0.0368),
        (0.109, 0.0391, 1.28e-08, 0.000978, 3.36e-13, 0.000464),
        1.2, (0.0248, 0.00858, 0.00128, 4.72e-05, 3.55e-06, 6.16e-06), axes="principal"),
    "genz": AxisCalibration(
        (0.255, 1.14, 1.19, 0.154, 2.99, 0.0304),
        (0.0279, 0.0193, 0.00452, 0.00096, 0.00303, 0.000471),
        1.2, (0.00291, 0.00135, 0.000146, 6.53e-05, 1.07e-05, 1.57e-05), axes="principal"),
    "knn": AxisCalibration(
        (269, 59.5, 1.09, 0.165, 0.564, 14.7),
        (4.46e-17, 3.87e-10, 3.45e-10, 0.000888, 1.8e-10, 4.95e-10),
        0.821, (0.00385, 0.00139, 5.38e-05, 1.12e-05, 8.53e-06, 8.65e-06), axes="principal"),
}


# the default composition of the pipeline variant (kiss_like) registers every pair exactly as kiss does (same poses, raw
# covariances and steps: benchmarks/results/covariance/pipeline), so it carries kiss's entries; another composition
# (another residual or kernel) gets them unverified
CALIBRATION["pipeline"] = CALIBRATION["kiss"]
CALIBRATION_WITHOUT_STEP["pipeline"] = CALIBRATION_WITHOUT_STEP["kiss"]

#: The settings an entry of :data:`CALIBRATION` was learned at (their defaults: the benchmark registers each variant with
#: them): another value models another residual, or another error scale, so the entry does not apply and the closed form
#: is returned as computed (small_gicp's point-to-point ICP under GICP's entry: NEES 1716 on a street pair with a 5 cm
#: error; a pipeline composition other than kiss's, e.g. preset vanilla_seq, under kiss's: mean NEES 15.8; ground_filtered
#: without its ground refinement under the entry learned with it, whose z, roll and pitch factors are tiny: mean NEES
#: ~7500), except within a measured band (:data:`CALIBRATED_BANDS`). The plane-based variants' gate and voxel size are
#: listed: beyond their bands their entry is over-confident where the closed form errs on the safe side (small_gicp at a
#: 3 m gate: mean NEES 16.5 and 47 % inside the 95 % bound, the closed form 4.0 and 97 %). The point-to-point variants'
#: are not: on held-out streets their entry stays nearer the targets than their closed form at every value measured
#: (vanilla and open3d_point_to_point at 1-3 m gates and 0.25-0.5 m voxels, kiss at 0.3-3 m voxels, genz at 0.2-1 m:
#: at worst vanilla's 16.8 / 0.81 at 0.5 m voxels, whose closed form gives 534 / 0.00); nor are ground_filtered's gate
#: and voxel size (1-3 m, 0.25 m: 6.5-7.1 / 0.90-0.93; its defaults on the same draws 7.2 / 0.89).
CALIBRATED_SETTINGS: dict[str, tuple[str, ...]] = {
    "small_gicp": ("registration_type", "downsampling_resolution_m", "max_correspondence_distance_m"),
    "open3d_point_to_plane": ("max_correspondence_distance_m", "voxel_size_m"),
    "open3d_gicp": ("max_correspondence_distance_m", "voxel_size_m"),
    "ground_filtered": ("ground_refine",),
    "pipeline": ("residual", "kernel", "threshold", "deskew", "map", "preprocess"),
}

#: Bands (per variant and setting, inclusive) around the learned value within which an entry of
#: :data:`CALIBRATED_SETTINGS` still applies: where it met the held-out targets (mean NEES 4.2-9, 90-98 % inside the 95 %
#: bound) or erred on the safe side, on street seeds 3 and 5 (80 draws). Just beyond them: small_gicp at 0.2 / 0.4 m
#: voxels 9.2 / 0.85 and 6.3 / 0.86 (the closed form 1.1 / 1.00 and 0.16 / 1.00), at a 1.25 m gate 10.0 / 0.76 (1.3 / 1.00);
#: open3d_point_to_plane at a 1.5 m gate 7.5 / 0.86 (2.4 / 1.00); open3d_gicp at a 3 m gate 13.4 / 0.56 (3.0 / 1.00).
#: Values outside a band are not all measured: the band keeps to those that were.
CALIBRATED_BANDS: dict[str, dict[str, tuple[float, float]]] = {
    "small_gicp": {"downsampling_resolution_m": (0.25, 0.3), "max_correspondence_distance_m": (0.5, 1.0)},
    "open3d_point_to_plane": {"max_correspondence_distance_m": (0.5, 1.0), "voxel_size_m": (0.3, 0.75)},
    "open3d_gicp": {"max_correspondence_distance_m": (0.75, 1.5), "voxel_size_m": (0.3, 0.75)},
}

#: Per-axis sigma (m and rad per m of motion within the sweep) that the odometry runner adds to the frame covariance
#: of a variant that registers motion-distorted sweeps as they are (no deskew; the scans carry per-point times), or
#: deskewed at constant velocity (ground_filtered): the skew that does not cancel between two sweeps, or that the
#: deskew leaves (changes of speed, turn rate, pitch and roll), which the pair
#: calibration above, learned on undistorted pairs, does not see. Learned on distorted 300-sweep streets of seeds
#: 0, 2, 4, 6 and checked on 5, 7, 8 (``benchmarks/covariance_distortion.py``, ``benchmarks/results/covariance/distortion``).
DISTORTION_SIGMA: dict[str, tuple[float, ...]] = {
    # generated by benchmarks/covariance_distortion.py (the "DISTORTION_SIGMA" block of its README), 2026-11-28: the
    # truth these are scored against is at the sweep middle since non-deskewed estimates refer to it (learned before
    # that, against sweep-end truth, small_gicp's floor was 5x too wide: NEES 2.5 on held-out seeds); vanilla learned
    # on seeds 0 and 2, checked on 5 (benchmarks/results/covariance/distortion_vanilla)
    "open3d_point_to_plane": (0.00443, 0, 0.00092, 0.000112, 0.000301, 8.56e-05),
    "small_gicp": (0.00206, 0.000533, 0.00149, 0.000458, 0.000374, 0.000199),
    "open3d_gicp": (0, 0.00211, 0.00139, 0, 0.000488, 0.00012),
    "open3d_point_to_point": (0.0567, 0, 0.000928, 0.00029, 0.000331, 0.000442),
    "vanilla": (0.0261, 0.00396, 0.000355, 9.59e-05, 5.16e-05, 0.000336),
    # ground_filtered deskews at constant velocity: what it leaves (roll and pitch above all: 1-frame NEES 268-804
    # without it); generated by `benchmarks/covariance_distortion.py --variants ground_filtered`
    # (benchmarks/results/covariance/distortion_ground_filtered)
    "ground_filtered": (0.0118, 0.00599, 0.0027, 0.000423, 0.000828, 0.000483),
}


def widen_for_distortion(covariance: np.ndarray, variant: str, translation_m: float) -> np.ndarray:
    """``covariance + diag((d * translation_m)^2)`` with the variant's :data:`DISTORTION_SIGMA` ``d`` (unchanged for a
    variant without one): the frame covariance of a motion-distorted sweep registered as it is."""
    sigma = DISTORTION_SIGMA.get(variant)
    if sigma is None:
        return covariance
    return covariance + np.diag((np.asarray(sigma, dtype=np.float64) * float(translation_m)) ** 2)


def calibrate(covariance: np.ndarray, variant: str, step: np.ndarray | None = None) -> np.ndarray:
    """``covariance`` with the variant's correction of :data:`CALIBRATION` applied (unchanged for a variant that
    has none), see :func:`apply_calibration`; ``step``: the result's point-to-surface step (``surface_step``). Without
    a (finite) step, the entry learned without the step term (:data:`CALIBRATION_WITHOUT_STEP`)."""
    entry = CALIBRATION.get(variant)
    if entry is None:
        return covariance
    if entry.step_gains is not None and (step is None or not np.all(np.isfinite(step))):
        entry = CALIBRATION_WITHOUT_STEP.get(variant, entry)
    return apply_calibration(covariance, entry, step)


def apply_calibration(covariance: np.ndarray, entry: AxisCalibration, step: np.ndarray | None = None) -> np.ndarray:
    """``Sigma' = c (S Sigma S + diag(b^2) + |step_t|^2 diag(h^2) + (g * step)(g * step)^T)``, symmetric PSD (the
    step terms only when the entry has gains and a finite ``step`` is given).

    ``S = diag(sqrt(g))`` with ``g_j = f_j`` while ``Sigma_jj`` stays within the training range ``v_j``; the part of
    the variance beyond it is scaled by ``max(f_j, 1)`` only: a direction weaker than on any training scene (a
    corridor's axis) is not shrunk by a factor measured where it was constrained, so the floors ``b`` of the
    constrained axes do not swamp it. The axes ``j`` are the entry's (:attr:`AxisCalibration.axes`): with
    ``"principal"`` the covariance and step are turned into them (:func:`principal_turn`) and the result turned back;
    a nearly isotropic horizontal block blends that with the two horizontal axes swapped (:data:`PRINCIPAL_BLEND_RATIO`),
    so the result changes smoothly with the closed form.
    """
    if entry.axes == "principal":  # calibrated in the principal axes, then turned back
        turn = principal_turn(covariance)
        weight = _principal_weight(covariance)
        out = _calibrated_in(covariance, entry, step, turn)
        if weight < 1.0:  # a nearly isotropic horizontal block: both orderings of its axes, blended
            quarter = twist_turn(np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]))
            out = weight * out + (1.0 - weight) * _calibrated_in(covariance, entry, step, quarter @ turn)
        return make_psd(float(entry.coverage) * out)
    return make_psd(float(entry.coverage) * _calibrated_in(covariance, entry, step, None))


#: Below this ratio of the horizontal block's eigenvalues the principal axes are blended with the same axes swapped,
#: reaching an even mix at 1 (an isotropic block has no weak direction: with a hard choice a 2 % change of the
#: closed form swapped the factors of the two axes, a 3-7x jump in sigma).
PRINCIPAL_BLEND_RATIO = 1.25


def _principal_weight(covariance: np.ndarray) -> float:
    """Weight of the principal ordering of the horizontal axes: 1 at or beyond :data:`PRINCIPAL_BLEND_RATIO`, 0.5 for
    an isotropic block."""
    lo, hi = np.linalg.eigvalsh(0.5 * (covariance[:2, :2] + covariance[:2, :2].T))
    if not hi > 0:
        return 0.5
    ratio = hi / max(lo, hi * 1e-12)
    return float(0.5 + 0.5 * np.clip((ratio - 1.0) / (PRINCIPAL_BLEND_RATIO - 1.0), 0.0, 1.0))


def _calibrated_in(covariance: np.ndarray, entry: AxisCalibration, step: np.ndarray | None, turn: np.ndarray | None) -> np.ndarray:
    """The calibration's terms (before the coverage scalar) in the axes ``turn`` takes the frame to, turned back."""
    if turn is not None:
        covariance = turn @ covariance @ turn.T
        step = None if step is None else turn @ np.asarray(step, dtype=np.float64).reshape(6)
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
    out = covariance * np.outer(scale, scale) + np.diag(sigmas**2)
    if entry.step_gains is not None and step is not None and np.all(np.isfinite(step)):
        step = np.asarray(step, dtype=np.float64).reshape(6)
        bias = np.asarray(entry.step_gains, dtype=np.float64) * step
        out = out + np.outer(bias, bias)
        if entry.step_spread is not None:
            out = out + np.diag(np.asarray(entry.step_spread, dtype=np.float64) ** 2 * float(step[:3] @ step[:3]))
    return out if turn is None else turn.T @ out @ turn


def principal_turn(covariance: np.ndarray) -> np.ndarray:
    """``blockdiag(R, R)`` (6x6), ``R`` the turn about z that puts the major axis of the covariance's horizontal
    translation block on x: ``turn @ Sigma @ turn.T`` is the covariance in axes where x is the weakest horizontal
    direction (a street's or corridor's axis, however the scene runs in the target frame). Per-axis factors learned
    on streets along x otherwise follow the frame, not the street: the same corridor turned by 45 degrees got a 16x
    larger sigma across it. An isotropic block keeps the frame's axes."""
    return twist_turn(horizontal_turn(np.asarray(covariance, dtype=np.float64)[:2, :2]))


def horizontal_turn(block_xy: np.ndarray) -> np.ndarray:
    """The 3x3 turn about z that puts the major axis of a symmetric 2x2 ``block_xy`` (a covariance's or a point spread's
    horizontal block) on x; the identity for an isotropic block."""
    angle = 0.5 * np.arctan2(2.0 * block_xy[0, 1], block_xy[0, 0] - block_xy[1, 1])
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])


def twist_turn(R: np.ndarray) -> np.ndarray:
    """``blockdiag(R, R)``: how a twist ``(t, r)`` (and a 6x6 covariance or normal matrix, on both sides) is expressed
    in a frame turned by ``R`` (the adjoint of a pure rotation)."""
    turn = np.zeros((6, 6))
    turn[:3, :3] = turn[3:, 3:] = R
    return turn


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


#: :func:`effective_observations` counts the voxels on a grid of flags up to this many cells (1 byte each)
_OCCUPANCY_CELLS = 1 << 22


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
    flat = (cols[0] * span[1] + cols[1]) * span[2] + cols[2]
    cells = span[0] * span[1] * span[2]
    if cells <= max(_OCCUPANCY_CELLS, 8 * len(flat)):  # a grid of flags: the same count without np.unique's sort (a
        occupied = np.zeros(cells, dtype=bool)  # KITTI scan in 1 m voxels: ~1e6 cells, 0.15 ms where the sort took 0.5)
        occupied[flat] = True
        return int(np.count_nonzero(occupied))
    return int(len(np.unique(flat)))


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
    return covariance_and_step(source_aligned_xyz, matched_target_xyz, constraints, T_target_source, model, n_total, n_effective,
                               surface_variance)[0]


def covariance_and_step(
    source_aligned_xyz: np.ndarray,
    matched_target_xyz: np.ndarray,
    constraints: np.ndarray,
    T_target_source: np.ndarray,
    model: CovarianceModel = DEFAULT_MODEL,
    n_total: int | None = None,
    n_effective: int | None = None,
    surface_variance: np.ndarray | None = None,
    target_origin: np.ndarray | None = None,
    source_origin: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`registration_covariance` and, from the same normal equations, the point-to-surface Gauss-Newton step
    ``xi = -(sum J^T J)^-1 sum J^T r`` (same convention as the covariance: ``se3_exp(xi) @ T_target_source`` is the
    pose the surfaces prefer), NaN with fewer than 3 pairs. ``target_origin``: where the target's sensor is in the
    frame of the points (default: their origin; a frame moved to a local origin puts it elsewhere); ``source_origin``:
    where the source's sensor is, in the same frame (default: the source frame's origin, ``T_target_source``'s
    translation)."""
    p = np.asarray(source_aligned_xyz, dtype=np.float64)
    q = np.asarray(matched_target_xyz, dtype=np.float64)
    n = len(p)
    if n < 3:
        return np.eye(6) / EIGEN_FLOOR, np.full(6, np.nan)
    n_total = n if n_total is None else int(n_total)
    n_effective = n_total if n_effective is None else max(int(n_effective), 1)
    M = np.asarray(constraints, dtype=np.float64)
    J0 = left_jacobians(p)
    J = np.matmul(M, J0)
    A = np.einsum("nki,nkj->ij", J, J)
    r = np.einsum("nij,nj->ni", M, p - q)
    A_inv = safe_inverse(A)
    step = _surface_step(J, r, A, np.einsum("ni,ni->n", p - q, p - q) <= STEP_PAIR_DISTANCE_M**2)
    if model.method == "gauss_newton":
        dof = float(np.trace(M, axis1=1, axis2=2).sum())
        sigma2 = float((r * r).sum()) / max(dof - 6.0, 1.0)
        cov_subsample = sigma2 * A_inv
    else:
        origin_source = (np.asarray(T_target_source, dtype=np.float64)[:3, 3] if source_origin is None
                         else np.asarray(source_origin, dtype=np.float64))
        d_s = _unit(p - origin_source)
        d_t = _unit(q if target_origin is None else q - np.asarray(target_origin, dtype=np.float64))
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
            # (the weights multiplied in first: the same products and sums as the three-operand einsum, 2.5x faster)
            B = B + np.einsum("nki,nkj->ij", np.asarray(surface_variance, dtype=np.float64)[:, None, None] * J, J)
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
    return make_psd(cov), step


def _surface_step(J: np.ndarray, r: np.ndarray, A: np.ndarray, near: np.ndarray) -> np.ndarray:
    """Gauss-Newton step ``-(sum J^T J)^-1 sum J^T r`` over the ``near`` pairs (``A``: ``sum J^T J`` over all of
    them), within the subspace they constrain (along a direction they do not constrain there is nothing to step to);
    NaN with fewer than 6 pairs."""
    if int(near.sum()) < 6:
        return np.full(6, np.nan)
    if not near.all():
        J, r = J[near], r[near]
        A = np.einsum("nki,nkj->ij", J, J)
    w, V = np.linalg.eigh(0.5 * (A + A.T))
    top = max(float(w[-1]), 0.0)
    if top <= 0:
        return np.zeros(6)
    kept = w >= EIGEN_FLOOR * top
    return -(V[:, kept] / w[kept]) @ (V[:, kept].T @ np.einsum("nki,nk->i", J, r))


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
    "COVARIANCE_CONVENTION", "COVARIANCE_METHODS", "CovarianceModel", "DEFAULT_CORRELATION_VOXEL_M", "DEFAULT_MODEL", "STEP_PAIR_DISTANCE_M",
    "AxisCalibration", "CALIBRATED_BANDS", "CALIBRATED_SETTINGS", "CALIBRATION", "CALIBRATION_TRAINING", "CALIBRATION_WITHOUT_STEP", "active_model", "adjoint", "apply_calibration", "calibrate", "covariance_and_step", "effective_observations", "use_model", "left_jacobians", "make_psd", "nees", "horizontal_turn", "principal_turn", "registration_covariance", "safe_inverse", "twist_turn",
]
