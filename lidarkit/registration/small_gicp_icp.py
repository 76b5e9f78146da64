"""``small_gicp``: koide3's small_gicp (optional dependency, extra ``gicp``) through ``small_gicp.align``.

Registered only when ``import small_gicp`` works; otherwise a note is logged and the name is absent.
Its own Gauss-Newton Hessian is reported in ``extra["native_hessian_eigenvalues"]`` (small_gicp's
parameter order: rx, ry, rz, tx, ty, tz); the degeneracy flag uses lidarkit's common measure.
"""

from __future__ import annotations

import logging
from typing import Literal

import numpy as np
from pydantic import Field, model_validator

from lidarkit.geometry import transform_points
from lidarkit.params import changed_fields
from lidarkit.quiet import silenced
from lidarkit.registration.assessment import assess_alignment
from lidarkit.registration.base import Registration, RegistrationConfig, RegistrationResult
from lidarkit.registration.cloud_cache import CloudCache
from lidarkit.registration import local_origin
from lidarkit.registration.planar import refuse_2d
from lidarkit.registration.registry import register_icp

log = logging.getLogger(__name__)

try:
    import small_gicp as _small_gicp
except ImportError as err:  # optional extra
    _small_gicp = None
    log.info("small_gicp not installed (%s): the 'small_gicp' ICP variant is not available", err)


def voxel_order(points: np.ndarray, voxel_m: float) -> np.ndarray:
    """Order of voxelized points (one per voxel) by their voxel: small_gicp's voxel grid returns its points in an
    order that varies with thread scheduling, and the assessment draws its seeded sample of pairs by position, so
    without a fixed order the covariance of the same alignment would change from run to run."""
    v = np.clip(np.floor(points / voxel_m).astype(np.int64) + (1 << 20), 0, (1 << 21) - 1)
    key = (v[:, 0] << 42) | (v[:, 1] << 21) | v[:, 2]
    order = np.argsort(key, kind="stable")
    # a few voxels hold two points (on two threads the grid can leave a voxel in two parts): those ties are broken by
    # the coordinates, not by the order the threads delivered them in
    sorted_key = key[order]
    tie = np.flatnonzero(sorted_key[1:] == sorted_key[:-1])
    if tie.size:
        at = np.union1d(tie, tie + 1)
        group = order[at]
        order[at] = group[np.lexsort((points[group, 2], points[group, 1], points[group, 0], key[group]))]
    return order


#: small_gicp warns on std::cerr when a (downsampled) cloud holds this many points or fewer
SMALL_GICP_WARNS_AT = 10


class SmallGICPConfig(RegistrationConfig):
    registration_type: Literal["ICP", "PLANE_ICP", "GICP", "VGICP"] = Field("GICP", description="small_gicp factor type")
    downsampling_resolution_m: float = Field(0.25, gt=0, description="voxel downsampling of both clouds (m)")
    max_correspondence_distance_m: float = Field(1.0, gt=0, description="max pair distance (m)")
    voxel_resolution_m: float = Field(1.0, gt=0, description="VGICP voxel size (m)")
    max_iterations: int = Field(50, ge=1, description="maximum Gauss-Newton iterations")
    num_threads: int = Field(2, ge=1, description="threads")

    @model_validator(mode="after")
    def _voxels_are_vgicps(self) -> "SmallGICPConfig":
        if changed_fields(self, ["voxel_resolution_m"]) and self.registration_type != "VGICP":  # (accepted and ignored)
            raise ValueError(f"voxel_resolution_m is VGICP's voxel size; registration_type {self.registration_type} has none")
        return self


if _small_gicp is not None:

    @register_icp("small_gicp")
    class SmallGICP(Registration):
        """small_gicp's GICP (or ICP / PLANE_ICP / VGICP) with its own downsampling and covariances."""

        Config = SmallGICPConfig
        # small_gicp holds the GIL through its KdTree, covariance and align calls (benchmarks/results/icp/gil_probe.md):
        # an assessment in a worker thread only contends for it (10 KITTI scans: 0.50 s in line, 0.53 s overlapped)
        overlap_assessment = False

        def __init__(self, config: SmallGICPConfig | None = None, **params):
            super().__init__(config, **params)
            # (PointCloud, KdTree, voxel-ordered points, rank) of the last two preprocessed clouds: a frame registered
            # again (the odometry runner's overlap, when the gate turns the previous frame down) finds both
            self._cache = CloudCache()

        def _preprocess(self, points: np.ndarray):
            """small_gicp's own downsampling + covariances + KdTree, reused when the same cloud comes back (in a
            scan-to-scan chain the source of one frame is the target of the next: preprocessed once, as small_gicp's
            own odometry loop does). Also the cloud's points in voxel order and each point's rank in that order, for the
            assessment (:func:`voxel_order`; None with ``assess=False``); and the local origin the cloud was prepared
            around (None: the origin, see :mod:`lidarkit.registration.local_origin`)."""
            c = self.config
            settings = (c.downsampling_resolution_m, c.assess, c.registration_type)
            cached = self._cache.get(points, settings)
            if cached is not None:
                return cached
            # the steps of small_gicp.preprocess_points (voxel grid, KdTree, 10-neighbour covariances, all on num_threads),
            # taken one by one to keep the cloud; the KdTree on num_threads rather than on one thread as align(points...)
            # builds it: ~1 ms less a KITTI scan, 2-3 % of a frame (10 KITTI scans, pairwise and odometry, with and without
            # the assessment, 9 alternating runs)
            points = np.asarray(points, dtype=np.float64)
            offset = local_origin.local_offset(points)
            cloud = _small_gicp.voxelgrid_sampling(local_origin.shift(points, offset), c.downsampling_resolution_m, num_threads=c.num_threads)
            tree = _small_gicp.KdTree(cloud, num_threads=c.num_threads)
            if c.registration_type == "PLANE_ICP":  # its factor reads normals: with covariances only it had none, and
                # returned the identity "converged" in 0 iterations (small_gicp.align(points...) estimates both)
                _small_gicp.estimate_normals_covariances(cloud, tree, num_neighbors=10, num_threads=c.num_threads)
            else:
                _small_gicp.estimate_covariances(cloud, tree, num_neighbors=10, num_threads=c.num_threads)
            ordered = rank = None  # only the assessment needs them
            if c.assess:
                xyz = cloud.points()[:, :3]
                order = voxel_order(xyz, c.downsampling_resolution_m)
                rank = np.empty_like(order)
                rank[order] = np.arange(len(order))
                ordered = xyz[order]
            return self._cache.put(points, (cloud, tree, ordered, rank, offset), settings)

        def _register(self, source_xyz: np.ndarray, target_xyz: np.ndarray, init_T: np.ndarray):
            c = self.config
            if c.registration_type != "ICP":
                refuse_2d(self.name, source_xyz, target_xyz, f"{c.registration_type} needs surface covariances / normals, undefined on a 2D scan")
            if c.registration_type == "VGICP":
                to, so = local_origin.local_offset(target_xyz), local_origin.local_offset(source_xyz)
                # (raw sizes: a larger cloud that small_gicp's own downsampling cuts to 10 points still warns)
                with silenced(2, when=min(len(source_xyz), len(target_xyz)) <= SMALL_GICP_WARNS_AT):  # its C++ "too small" warning
                    out = _small_gicp.align(
                        local_origin.shift(target_xyz, to), local_origin.shift(source_xyz, so), local_origin.into(init_T, to, so),
                        registration_type="VGICP", voxel_resolution=c.voxel_resolution_m, downsampling_resolution=c.downsampling_resolution_m,
                        max_correspondence_distance=c.max_correspondence_distance_m, num_threads=c.num_threads, max_iterations=c.max_iterations,
                    )
                T = local_origin.out_of(np.array(out.T_target_source, dtype=np.float64), to, so)

                def assess() -> RegistrationResult:
                    def voxelized(points, offset):  # voxel-ordered, around the local origin, then back where the cloud is
                        xyz = _small_gicp.voxelgrid_sampling(local_origin.shift(points, offset), c.downsampling_resolution_m,
                                                             num_threads=c.num_threads).points()[:, :3]
                        return local_origin.given(xyz[voxel_order(xyz, c.downsampling_resolution_m)], offset)

                    src, dst = voxelized(source_xyz, so), voxelized(target_xyz, to)
                    return self._result(out, T, assess_alignment(src, dst, T, c.max_correspondence_distance_m))

                assess.backend_reported = {"iterations": self._iterations(out)}
                return T, bool(out.converged), assess
            # the same computation as small_gicp.align(points...) (identical poses), with the preprocessed clouds and
            # the target's KdTree kept for the assessment instead of voxelizing and indexing both clouds again
            target, target_tree, dst, dst_rank, to = self._preprocess(target_xyz)
            source, _, src, _, so = self._preprocess(source_xyz)  # stays cached: the next frame's target
            with silenced(2, when=min(source.size(), target.size()) <= SMALL_GICP_WARNS_AT):
                out = _small_gicp.align(
                    target, source, target_tree, local_origin.into(init_T, to, so), registration_type=c.registration_type,
                    max_correspondence_distance=c.max_correspondence_distance_m, num_threads=c.num_threads, max_iterations=c.max_iterations,
                )
            T_local = np.array(out.T_target_source, dtype=np.float64)
            T = local_origin.out_of(T_local, to, so)

            def assess() -> RegistrationResult:
                # one thread: a single pass of nearest neighbours does not repay another OpenMP region (its threads spin
                # while they wait, which on a busy machine costs more CPU than the pass saves). The k=1 search, not
                # batch_nearest_neighbor_search: the same neighbours and distances (the same exact search), returned as
                # arrays where the other returns two Python lists (1.6 of its 5.8 ms on a KITTI scan were the lists)
                aligned = transform_points(T_local, src)
                index, dist2 = target_tree.batch_knn_search(aligned, 1, num_threads=1)
                index = dst_rank[index[:, 0]]  # the tree's indices into the voxel-ordered target
                given_src, given_dst = local_origin.given(src, so), local_origin.given(dst, to)  # where the clouds are
                assessment = assess_alignment(given_src, given_dst, T, c.max_correspondence_distance_m, dist2=dist2[:, 0], index=index,
                                              aligned_xyz=aligned if so is None and to is None else None)  # (the same pose then)
                return self._result(out, T, assessment)

            assess.backend_reported = {"iterations": self._iterations(out)}  # kept with assess=False
            return T, bool(out.converged), assess

        @staticmethod
        def _iterations(out) -> int:
            """small_gicp records the index of its last Gauss-Newton update (0-based; every pass, the converging one
            included, applies its update): max_iterations=1 read "did not converge in 0 iterations"."""
            return int(out.iterations) + 1

        def _result(self, out, T: np.ndarray, assessment) -> RegistrationResult:
            native = np.linalg.eigvalsh(0.5 * (np.asarray(out.H) + np.asarray(out.H).T))
            iterations = self._iterations(out)
            return assessment.to_result(
                T,
                converged=bool(out.converged),
                reason="" if out.converged else f"small_gicp did not converge in {iterations} iterations",
                iterations=iterations,
                extra={"native_hessian_eigenvalues": [float(x) for x in native], "num_inliers": int(out.num_inliers)},
            )
