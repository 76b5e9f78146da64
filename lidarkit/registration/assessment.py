"""Common end-of-registration bookkeeping: final correspondences, fitness, RMSE and degeneracy."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lidarkit.geometry import transform_points
from lidarkit.registration.base import Degeneracy, RegistrationResult
from lidarkit.registration.covariance import CovarianceModel, active_model, covariance_and_step, effective_observations
from lidarkit.registration.degeneracy import SurfaceIndex, matched_constraints, normal_matrix, summarize
from lidarkit.registration import local_origin
from lidarkit.registration.neighbors import NearestNeighbors

#: ``RegistrationResult.extra`` key: the point (target frame, m) the covariance was computed around before it was moved
COVARIANCE_ORIGIN_KEY = "covariance_origin_m"
#: ``RegistrationResult.extra`` key, True where ``rmse_history`` holds the final RMSE alone (the library reports none per
#: iteration): a reader that draws histories leaves such a result out rather than draw one point as a curve
FINAL_RMSE_ONLY_KEY = "rmse_history_final_only"


@dataclass(frozen=True)
class Assessment:
    """Correspondences within ``inlier_distance_m`` of the source mapped by the final pose."""

    n_correspondences: int
    fitness: float
    rmse_m: float
    degeneracy: Degeneracy
    inlier_distance_m: float = float("nan")
    covariance: np.ndarray | None = None
    surface_step: np.ndarray | None = None
    covariance_origin: np.ndarray | None = None
    """Where the covariance and step were computed (clouds far from their origin, see :func:`assess_alignment`), or
    None: at the target frame's origin."""

    @property
    def covariance_extra(self) -> dict:
        """The result's ``extra`` entry that says where the covariance was computed (empty at the origin)."""
        return {} if self.covariance_origin is None else {COVARIANCE_ORIGIN_KEY: [float(v) for v in self.covariance_origin]}

    def to_result(
        self,
        T_target_source: np.ndarray,
        *,
        converged: bool = True,
        reason: str = "",
        iterations: int = 0,
        rmse_history: tuple[float, ...] | None = None,
        extra: dict | None = None,
    ) -> RegistrationResult:
        """The variant's result for this pose: not converged below 3 correspondences, the reason naming why;
        a converged result on degenerate geometry keeps ``converged`` but says so in ``reason``. Without
        ``rmse_history`` it is this pose's RMSE alone, and ``extra`` says so (:data:`FINAL_RMSE_ONLY_KEY`)."""
        if converged and self.n_correspondences < 3:
            converged = False
            reason = f"only {self.n_correspondences} correspondences within {self.inlier_distance_m:g} m"
        elif converged and self.degeneracy.degenerate:
            reason = f"degenerate geometry: min/max eigenvalue {self.degeneracy.ratio:.2e} < {self.degeneracy.threshold:g}"
        final_only = rmse_history is None
        return RegistrationResult(
            T_target_source=T_target_source,
            converged=converged,
            iterations=iterations,
            rmse_history=(self.rmse_m,) if final_only else rmse_history,
            n_correspondences=self.n_correspondences,
            runtime_s=0.0,
            fitness=self.fitness,
            degeneracy=self.degeneracy,
            reason=reason,
            extra={**(extra or {}), **self.covariance_extra, **({FINAL_RMSE_ONLY_KEY: True} if final_only else {})},
            covariance=self.covariance,
            surface_step=self.surface_step,
        )


def assess_alignment(
    source_xyz: np.ndarray,
    target_xyz: np.ndarray,
    T_target_source: np.ndarray,
    inlier_distance_m: float,
    neighbors: NearestNeighbors | None = None,
    dist2: np.ndarray | None = None,
    index: np.ndarray | None = None,
    covariance_model: CovarianceModel | None | str = "active",
    surfaces: SurfaceIndex | None = None,
    aligned_xyz: np.ndarray | None = None,
) -> Assessment:
    """Score a pose: pass ``dist2``/``index`` of the final correspondences if already known.

    The degeneracy summary and the covariance (``covariance_model=None``: not computed) share one set of
    local surfaces around at most 2000 of the matched pairs; ``"active"`` takes the model of the registration that
    is running (:func:`lidarkit.registration.covariance.use_model`); ``surfaces``: the target's
    :class:`~lidarkit.registration.degeneracy.SurfaceIndex` if already built (e.g. by :class:`lidarkit.threads.background`
    while the registration ran); ``aligned_xyz``: ``source_xyz`` mapped by ``T_target_source``, if the caller has it
    (e.g. from the final nearest-neighbour search).

    Clouds not in their sensor frame (a map frame, georeferenced; :func:`lidarkit.registration.local_origin.sensor_proxy`):
    the covariance and step are computed around the target's likely sensor ``c``, where the calibration was learned and
    the lever arms stay small (at 7 km the closed form lost the rotation to rounding: sigmas 0.06x; at 1e6 m an 8x too
    small yaw), with the sensor model's rays from there and from the source's likely sensor, and ``extra`` names
    ``c``; :meth:`lidarkit.registration.base.Registration.align` calibrates them there and moves them to the target
    frame (``Ad(c) Sigma Ad(c)^T``)."""
    if isinstance(covariance_model, str):
        covariance_model = active_model()
    aligned = transform_points(T_target_source, source_xyz) if aligned_xyz is None else aligned_xyz
    if dist2 is None or index is None:
        if neighbors is None:
            # one query pass: scipy's worker threads (Python threads started per call) cost more than they save here
            neighbors = NearestNeighbors(target_xyz, backend="scipy", workers=1)
        dist2, index = neighbors.query(aligned)
    inlier = dist2 <= inlier_distance_m**2
    n = int(inlier.sum())
    rmse = float(np.sqrt(dist2[inlier].mean())) if n else float("nan")
    covariance = step = origin = None
    if n < 3:
        degeneracy = Degeneracy.unknown(f"{n} correspondences")
    else:
        matched, matched_index = aligned[inlier], index[inlier]
        pick, constraints, thickness = matched_constraints(matched, target_xyz, matched_index, return_thickness=True, surfaces=surfaces)
        degeneracy = summarize(normal_matrix(matched[pick], constraints))
        if covariance_model is not None:
            # around the target's sensor (its frame's origin, or where its points say it is: see sensor_proxy), where
            # the calibration was learned; the source's rays run from its own sensor
            given = local_origin.given_sensors()  # of the clouds as given to align (these may be voxelized)
            origin, source_sensor = given if given is not None else (local_origin.sensor_proxy(target_xyz), local_origin.sensor_proxy(source_xyz))
            T_local = local_origin.into(T_target_source, origin, None)
            source_origin = None if source_sensor is None else T_local[:3, :3] @ source_sensor + T_local[:3, 3]
            p, q = local_origin.shift(matched[pick], origin), local_origin.shift(target_xyz[matched_index[pick]], origin)
            n_eff = effective_observations(local_origin.shift(matched, origin), covariance_model.correlation_voxel_m)
            covariance, step = covariance_and_step(
                p, q, constraints, T_local, covariance_model, n_total=n, n_effective=n_eff, surface_variance=thickness,
                source_origin=source_origin,
            )
    return Assessment(
        n_correspondences=n, fitness=n / max(len(source_xyz), 1), rmse_m=rmse, degeneracy=degeneracy,
        inlier_distance_m=inlier_distance_m, covariance=covariance, surface_step=step,
        covariance_origin=origin if covariance is not None else None,
    )


__all__ = ["COVARIANCE_ORIGIN_KEY", "FINAL_RMSE_ONLY_KEY", "Assessment", "assess_alignment"]
