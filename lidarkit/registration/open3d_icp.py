"""Open3D's ICP pipelines as registered variants: ``open3d_point_to_point`` (the speed reference for
``vanilla``), ``open3d_point_to_plane`` and ``open3d_gicp`` (normals / covariances estimated inside).

Open3D's legacy pipeline reports neither iteration counts nor per-iteration RMSE: ``iterations`` is 0
and ``rmse_history`` holds the final RMSE only (``extra["iterations_reported"] = False``). Nor does it say whether
it stopped on its criteria or at ``max_iterations``: ``converged`` is True whenever correspondences were found.
"""

from __future__ import annotations

import contextlib

import numpy as np
from pydantic import Field, model_validator

from lidarkit.geometry import transform_points
from lidarkit.registration.assessment import FINAL_RMSE_ONLY_KEY, assess_alignment
from lidarkit.registration.base import Registration, RegistrationConfig, RegistrationResult
from lidarkit.registration.cloud_cache import CloudCache
from lidarkit.registration.degeneracy import SurfaceIndex
from lidarkit.registration import local_origin
from lidarkit.registration.planar import refuse_2d
from lidarkit.registration.registry import register_icp
from lidarkit.threads import background


class Open3DPointToPointConfig(RegistrationConfig):
    max_correspondence_distance_m: float = Field(2.0, gt=0, description="max pair distance (m)")
    voxel_size_m: float | None = Field(None, gt=0, description="Open3D voxel downsampling first (m); None keeps all points")
    max_iterations: int = Field(100, ge=1, description="maximum iterations")
    relative_fitness: float = Field(1e-6, ge=0, description="stop when fitness changes less than this")
    relative_rmse: float = Field(1e-6, ge=0, description="stop when RMSE changes less than this")


class Open3DSurfaceConfig(Open3DPointToPointConfig):
    max_correspondence_distance_m: float = Field(1.0, gt=0, description="max pair distance (m)")
    voxel_size_m: float | None = Field(0.5, gt=0, description="Open3D voxel downsampling first (m); None keeps all points")
    normal_radius_m: float = Field(1.5, gt=0, description="radius of the neighbourhood for normals/covariances (m)")
    normal_max_nn: int = Field(20, ge=3, description="max neighbours for normals/covariances")

    @model_validator(mode="after")
    def _normals_need_neighbours(self) -> "Open3DSurfaceConfig":
        """A radius below the voxel spacing finds no neighbour for most downsampled points (KITTI, 0.1 m at 0.5 m: all
        of them), whose normals Open3D then leaves at its default: point_to_plane stayed at the guess, "converged"."""
        if self.voxel_size_m is not None and self.normal_radius_m < self.voxel_size_m:
            raise ValueError(f"normal_radius_m ({self.normal_radius_m:g}) is below voxel_size_m ({self.voxel_size_m:g}): after "
                             "downsampling most points have no neighbour within it to estimate a normal from")
        return self


class _Open3DBase(Registration):
    _kind = "point_to_point"

    def __init__(self, config=None, **params):
        super().__init__(config, **params)
        self._cache = CloudCache()  # the last two prepared clouds: a frame registered again finds both

    def _clouds(self, source_xyz: np.ndarray, target_xyz: np.ndarray):
        """``(source, target)``, each an Open3D cloud (downsampled, with normals for the surface variants) around its
        local origin (:mod:`lidarkit.registration.local_origin`) and that origin (None: the origin). In a scan-to-scan
        chain the source of one frame is the target of the next: that cloud is prepared once, as an Open3D odometry loop
        would."""
        import open3d as o3d

        c = self.config
        clouds = []
        for pts in (target_xyz, source_xyz):
            hit = self._cache.get(pts)
            if hit is not None:
                clouds.append(hit)
                continue
            offset = local_origin.local_offset(pts)
            pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(local_origin.shift(pts, offset)))
            if c.voxel_size_m is not None:
                pc = pc.voxel_down_sample(c.voxel_size_m)
            if self._kind != "point_to_point":
                # GICP builds its plane-like covariances from these normals (Open3D's own rule)
                pc.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=c.normal_radius_m, max_nn=c.normal_max_nn))
            clouds.append(self._cache.put(pts, (pc, offset)))
        return clouds[1], clouds[0]

    def _register(self, source_xyz: np.ndarray, target_xyz: np.ndarray, init_T: np.ndarray):
        import open3d as o3d

        reg = o3d.pipelines.registration
        c = self.config
        if self._kind != "point_to_point":
            refuse_2d(self.name, source_xyz, target_xyz, "normals / covariances of a 2D scan's line-like neighbourhoods are undefined in 3D")
        (src, so), (dst, to) = self._clouds(source_xyz, target_xyz)
        dst_pts = local_origin.given(np.asarray(dst.points), to)  # the assessment works where the clouds are
        # the assessment's pose-free part (the target's local-surface index) is built in another thread while Open3D,
        # which releases the GIL, registers
        surfaces = background(lambda: SurfaceIndex(dst_pts)) if c.assess else None
        criteria = reg.ICPConvergenceCriteria(c.relative_fitness, c.relative_rmse, c.max_iterations)
        try:
            if self._kind == "gicp":
                out = reg.registration_generalized_icp(
                    src, dst, c.max_correspondence_distance_m, local_origin.into(init_T, to, so),
                    reg.TransformationEstimationForGeneralizedICP(), criteria,
                )
            else:
                estimation = (
                    reg.TransformationEstimationPointToPoint()
                    if self._kind == "point_to_point"
                    else reg.TransformationEstimationPointToPlane()
                )
                out = reg.registration_icp(src, dst, c.max_correspondence_distance_m, local_origin.into(init_T, to, so), estimation, criteria)
        except BaseException:
            if surfaces is not None:
                with contextlib.suppress(Exception):
                    surfaces.result()  # joined (its thread ends) before the error goes on
            raise
        prepared = surfaces.result() if surfaces is not None else None  # joined here: it never outlives the registration
        T = local_origin.out_of(np.array(out.transformation, dtype=np.float64), to, so)
        no_pairs = float(out.fitness) <= 0

        def assess() -> RegistrationResult:
            src_pts = local_origin.given(np.asarray(src.points), so)
            # Open3D's own final correspondences (nearest target point within the distance, at the returned pose): the
            # assessment reuses them instead of indexing the target a second time
            pairs = np.asarray(out.correspondence_set, dtype=np.int64).reshape(-1, 2)
            dist2 = np.full(len(src_pts), np.inf)
            index = np.zeros(len(src_pts), dtype=np.int64)
            if len(pairs):
                gap = transform_points(T, src_pts[pairs[:, 0]]) - dst_pts[pairs[:, 1]]
                dist2[pairs[:, 0]] = np.einsum("ij,ij->i", gap, gap)
                index[pairs[:, 0]] = pairs[:, 1]
            assessment = assess_alignment(src_pts, dst_pts, T, c.max_correspondence_distance_m, dist2=dist2, index=index,
                                          surfaces=prepared)
            return assessment.to_result(
                T,
                converged=not no_pairs,
                reason=f"Open3D fitness 0: no correspondence within {c.max_correspondence_distance_m} m" if no_pairs else "",
                rmse_history=(float("nan") if no_pairs else float(out.inlier_rmse),),  # Open3D reports 0 for "no pairs"
                extra={"iterations_reported": False, "open3d_fitness": float(out.fitness), FINAL_RMSE_ONLY_KEY: True},
            )

        return T, not no_pairs, assess


@register_icp("open3d_point_to_point")
class Open3DPointToPoint(_Open3DBase):
    """Open3D ``registration_icp`` with ``TransformationEstimationPointToPoint``."""

    Config = Open3DPointToPointConfig
    _kind = "point_to_point"


@register_icp("open3d_point_to_plane")
class Open3DPointToPlane(_Open3DBase):
    """Open3D ``registration_icp`` with ``TransformationEstimationPointToPlane`` (normals estimated inside)."""

    Config = Open3DSurfaceConfig
    _kind = "point_to_plane"


@register_icp("open3d_gicp")
class Open3DGICP(_Open3DBase):
    """Open3D ``registration_generalized_icp`` (covariances estimated inside)."""

    Config = Open3DSurfaceConfig
    _kind = "gicp"
