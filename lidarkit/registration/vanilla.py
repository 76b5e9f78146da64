"""``vanilla``: point-to-point ICP, nearest-neighbour correspondences, closed-form SVD (Kabsch) update.

Stops when ``|MSE_k - MSE_(k-1)| < epsilon_m2`` or after ``max_iterations``. The target index is
built once; each iteration is one vectorized nearest-neighbour query plus one Kabsch solve.
"""

from __future__ import annotations

import dataclasses
from typing import Literal

import numpy as np
from pydantic import Field, model_validator

from lidarkit.geometry import kabsch_umeyama, make_se3
from lidarkit.params import changed_fields
from lidarkit.registration.assessment import assess_alignment
from lidarkit.registration.base import Degeneracy, Registration, RegistrationConfig, RegistrationResult
from lidarkit.registration.neighbors import NearestNeighbors, ScipyWorkers, refuse_slow_brute_force, resolved_backend
from lidarkit.registration.planar import planar_kabsch
from lidarkit.registration.preprocess import voxel_downsample
from lidarkit.registration.registry import register_icp

#: Distance used for fitness / final correspondences when no max correspondence distance is set.
DEFAULT_INLIER_DISTANCE_M = 1.0


class VanillaConfig(RegistrationConfig):
    max_iterations: int = Field(100, ge=1, description="maximum number of ICP iterations of each stage (with coarse_stride > "
                                "1 the coarse and the full-resolution stage each get as many: iterations reports both)")
    epsilon_m2: float = Field(1e-6, ge=0, description="stop when |MSE_k - MSE_k-1| < epsilon (m^2)")
    max_correspondence_distance_m: float | None = Field(
        None, gt=0, description="ignore pairs farther apart than this (m); None uses every nearest neighbour (the report's ICP)"
    )
    voxel_size_m: float | None = Field(None, gt=0, description="voxel-downsample both clouds first (m); None keeps all points")
    nn_backend: Literal["auto", "scipy", "open3d", "brute"] = Field("auto", description="nearest-neighbour search backend")
    leafsize: int = Field(16, ge=1, description="KD-tree leaf size (scipy backend)")
    workers: ScipyWorkers = Field(-1, description="threads for the scipy KD-tree query (nn_backend scipy; -1: all cores)")
    coarse_stride: int = Field(
        8, ge=1, description="first converge with every k-th source point, then refine with all (1: single stage)"
    )
    planar: bool = Field(
        False, description="solve x, y, yaw only (SE(2)); z, roll and pitch stay as in init_T (2D laser scans)"
    )

    @model_validator(mode="after")
    def _scipy_settings_need_scipy(self):
        """``leafsize`` / ``workers`` set for a search that is not scipy's were recorded and did nothing (the report's
        leaf-size experiment under the default backend, Open3D, compared identical runs)."""
        given = changed_fields(self, ("leafsize", "workers"))
        exact = bool(getattr(self, "exact", False))
        backend = "brute" if exact else self.nn_backend
        if backend == "auto":
            backend = resolved_backend("auto")
        if given and backend != "scipy":
            how = "exact=true" if exact else f"nn_backend={self.nn_backend!r}" + (f" ({backend} here)" if self.nn_backend == "auto" else "")
            raise ValueError(f"{' and '.join(given)} set{'s' if len(given) == 1 else ''} scipy's KD-tree, which {how} does not use: "
                             + ("leave exact out" if exact else "add nn_backend='scipy'"))
        return self


def point_to_point_icp(
    source_xyz: np.ndarray,
    target_xyz: np.ndarray,
    init_T: np.ndarray,
    neighbors: NearestNeighbors,
    *,
    max_iterations: int,
    epsilon_m2: float,
    max_correspondence_distance_m: float | None,
    min_correspondences: int,
    assess: bool = True,
    planar: bool = False,
) -> RegistrationResult:
    """The ICP loop on prepared clouds with a prebuilt index over ``target_xyz``.

    ``assess=False`` skips the final fitness / degeneracy assessment (for an intermediate stage whose result
    only seeds the next one): fitness is then the loop's last inlier fraction and the degeneracy unknown.
    ``planar=True`` updates x, y and yaw only (closed-form 2D fit, :func:`planar_kabsch`).
    """
    T = init_T.copy()
    history: list[float] = []
    prev_mse = None
    converged = False
    reason = f"reached max_iterations={max_iterations}"
    iterations = 0
    max_d2 = np.inf if max_correspondence_distance_m is None else max_correspondence_distance_m**2
    for _ in range(max_iterations + 1):
        # einsum, not matmul: a tall (N, 3) @ (3, 3) goes to multi-threaded BLAS, ~10x slower on a busy machine
        moved = np.einsum("ij,kj->ik", source_xyz, T[:3, :3]) + T[:3, 3]
        dist2, index = neighbors.query(moved)
        inlier = dist2 <= max_d2
        n = int(inlier.sum())
        if n < min_correspondences:
            within = "in all" if max_correspondence_distance_m is None else f"within {max_correspondence_distance_m:g} m"
            reason = f"only {n} correspondences {within} (need {min_correspondences})"
            converged = False
            break
        mse = float(dist2[inlier].mean())
        history.append(float(np.sqrt(mse)))
        if prev_mse is not None and abs(mse - prev_mse) < epsilon_m2:
            converged, reason = True, ""
            break
        if iterations == max_iterations:
            break
        prev_mse = mse
        if planar:
            T = make_se3(*planar_kabsch(moved[inlier], target_xyz[index[inlier]])) @ T
        else:
            step = kabsch_umeyama(moved[inlier], target_xyz[index[inlier]])
            T = make_se3(step.rotation, step.translation) @ T
        iterations += 1
    if not assess:
        return RegistrationResult(
            T_target_source=T,
            converged=converged,
            iterations=iterations,
            rmse_history=tuple(history),
            n_correspondences=n,
            runtime_s=0.0,
            fitness=n / max(len(source_xyz), 1),
            degeneracy=Degeneracy.unknown("not assessed (intermediate stage)"),
            reason=reason,
        )
    inlier_distance = max_correspondence_distance_m or DEFAULT_INLIER_DISTANCE_M
    assessment = assess_alignment(source_xyz, target_xyz, T, inlier_distance, dist2=dist2, index=index)
    degeneracy = assessment.degeneracy
    if assessment.n_correspondences < 3:
        degeneracy = Degeneracy.unknown("too few correspondences")
    if degeneracy.degenerate and converged:
        reason = f"degenerate geometry: min/max eigenvalue {degeneracy.ratio:.2e} < {degeneracy.threshold:g}"
    return RegistrationResult(
        T_target_source=T,
        converged=converged,
        iterations=iterations,
        rmse_history=tuple(history),
        n_correspondences=assessment.n_correspondences,
        runtime_s=0.0,
        fitness=assessment.fitness,
        degeneracy=degeneracy,
        reason=reason,
        covariance=assessment.covariance,
        surface_step=assessment.surface_step,
        extra=assessment.covariance_extra,
    )


def prepare(source_xyz: np.ndarray, target_xyz: np.ndarray, voxel_size_m: float | None) -> tuple[np.ndarray, np.ndarray]:
    """Optional voxel downsampling of both clouds."""
    if voxel_size_m is None:
        return source_xyz, target_xyz
    return voxel_downsample(source_xyz, voxel_size_m), voxel_downsample(target_xyz, voxel_size_m)


def target_index(source_xyz: np.ndarray, target_xyz: np.ndarray, config: VanillaConfig, variant: str) -> NearestNeighbors:
    """The nearest-neighbour index over ``target_xyz`` that ``config`` asks for; brute force (``nn_backend='brute'``,
    knn's ``exact=true``) over a pair too large for it is refused before the first pass, naming the option (vanilla ran
    for minutes on a full KITTI pair)."""
    exact = bool(getattr(config, "exact", False))
    backend = "brute" if exact else config.nn_backend
    source = f"{variant} " + ("exact=true" if exact else f"nn_backend={backend!r}")
    if backend == "brute":
        refuse_slow_brute_force(len(source_xyz), len(target_xyz), source)
    return NearestNeighbors(target_xyz, backend=backend, leafsize=config.leafsize, workers=config.workers, source=source)


def staged_icp(
    source_xyz: np.ndarray,
    target_xyz: np.ndarray,
    init_T: np.ndarray,
    neighbors: NearestNeighbors,
    config: VanillaConfig,
) -> RegistrationResult:
    """Coarse-to-fine schedule: ICP on every ``coarse_stride``-th source point, then on all of them.

    Both stages use the same full target index and stopping rule, so the result is a fixed point of
    the full-resolution ICP; the coarse stage only makes the long approach cheap.
    """
    kwargs = dict(
        max_iterations=config.max_iterations,
        epsilon_m2=config.epsilon_m2,
        max_correspondence_distance_m=config.max_correspondence_distance_m,
        min_correspondences=config.min_correspondences,
        planar=config.planar,
    )
    stride = config.coarse_stride
    if stride <= 1 or len(source_xyz) < stride * 4 * config.min_correspondences:
        return point_to_point_icp(source_xyz, target_xyz, init_T, neighbors, **kwargs)
    coarse = point_to_point_icp(source_xyz[::stride], target_xyz, init_T, neighbors, assess=False, **kwargs)
    start = coarse.T_target_source if coarse.converged or coarse.iterations > 0 else init_T
    fine = point_to_point_icp(source_xyz, target_xyz, start, neighbors, **kwargs)
    return dataclasses.replace(
        fine,
        iterations=coarse.iterations + fine.iterations,
        # one value at the initial guess and one after each iteration: the fine stage's first value (at the coarse
        # result, where the coarse stage measured last on its subsample) is left out
        rmse_history=coarse.rmse_history + fine.rmse_history[1:],
        extra={**fine.extra, "coarse_iterations": coarse.iterations, "coarse_stride": stride},
    )


@register_icp("vanilla")
class VanillaICP(Registration):
    """Point-to-point ICP with KD-tree (or Open3D NNS) correspondences and a Kabsch update."""

    Config = VanillaConfig

    def _align(self, source_xyz: np.ndarray, target_xyz: np.ndarray, init_T: np.ndarray) -> RegistrationResult:
        c = self.config
        src, dst = prepare(source_xyz, target_xyz, c.voxel_size_m)
        return staged_icp(src, dst, init_T, target_index(src, dst, c, self.name), c)
