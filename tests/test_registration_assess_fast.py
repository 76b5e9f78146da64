"""The assessment's faster paths give the numbers of the expressions they replace, bit for bit, on real KITTI scans.

Each shortcut in the after-the-fact assessment (small_gicp's final nearest-neighbour search, the reused aligned source,
the neighbourhood means, the surface voxel size, the voxel count, the weighted normal matrix) is checked here against
the plain expression it stands for, so that speeding the assessment up never moves a pose's correspondences,
degeneracy summary or covariance.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import shared_path
from registration_helpers import kitti_pair

from lidarkit.geometry import transform_points
from lidarkit.registration import covariance as cv
from lidarkit.registration import degeneracy as dg
from lidarkit.registration.assessment import assess_alignment
from lidarkit.registration.preprocess import voxel_downsample


@pytest.fixture(scope="module")
def pair_94_95():
    src, dst, T_gt = kitti_pair(shared_path, 94, 95)
    return voxel_downsample(src, 0.25), voxel_downsample(dst, 0.25), T_gt


@pytest.fixture(scope="module")
def matched(pair_94_95):
    """(aligned source, target, dist2, index) of the KITTI pair at its ground-truth pose (exact nearest neighbours)."""
    from scipy.spatial import cKDTree

    src, dst, T_gt = pair_94_95
    aligned = transform_points(T_gt, src)
    dist, index = cKDTree(dst).query(aligned)
    return aligned, dst, dist * dist, index


def _same_assessment(a, b) -> None:
    for f in dataclasses.fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
            assert np.array_equal(x, y, equal_nan=True), f.name
        else:
            assert x == y or (x != x and y != y), f.name


def test_small_gicp_k1_search_equals_its_nearest_neighbour_search(pair_94_95):
    small_gicp = pytest.importorskip("small_gicp")
    src, dst, T_gt = pair_94_95
    tree = small_gicp.KdTree(dst, num_threads=1)
    for T in (T_gt, np.eye(4)):  # matched, and 1 m off (some beyond the inlier distance)
        queries = transform_points(T, src)
        index, dist2 = tree.batch_nearest_neighbor_search(queries, num_threads=1)  # two Python lists
        k_index, k_dist2 = tree.batch_knn_search(queries, 1, num_threads=1)
        assert np.array_equal(np.asarray(index), k_index[:, 0].astype(np.int64))
        assert np.array_equal(np.asarray(dist2), k_dist2[:, 0])


def test_assess_alignment_with_the_aligned_source_is_the_same(pair_94_95, matched):
    src, dst, T_gt = pair_94_95
    _, _, dist2, index = matched
    plain = assess_alignment(src, dst, T_gt, 1.0, dist2=dist2, index=index)
    given = assess_alignment(src, dst, T_gt, 1.0, dist2=dist2, index=index, aligned_xyz=transform_points(T_gt, src))
    assert plain.covariance is not None and plain.n_correspondences > 10000
    _same_assessment(plain, given)


def test_neighbourhood_means_equal_numpys_mean(matched):
    aligned, dst, dist2, index = matched
    surfaces = dg.SurfaceIndex(dst)
    for k in (20, 5, 1):
        neighbourhoods = surfaces.surface_xyz[surfaces.knn(dst[np.unique(index)[:3000]], k)]
        assert np.array_equal(dg._neighbourhood_means(neighbourhoods), neighbourhoods.mean(axis=1, keepdims=True))


def _exact_surface_voxel(points: np.ndarray, surface_voxel_m: float) -> float:
    centred = points - points.mean(axis=0)
    return min(surface_voxel_m, float(np.sqrt((centred * centred).sum(axis=1).mean())) / 10.0)


def test_surface_voxel_equals_the_rms_radius_rule(pair_94_95, rng):
    _, dst, _ = pair_94_95
    small = dst[np.linalg.norm(dst, axis=1) < 6.0]  # an indoor-sized scene: RMS radius below 5 m
    for points in (dst, small, small * 1.2, dst[:5]):
        for voxel in (0.5, 0.2):
            assert dg._surface_voxel(points, voxel) == _exact_surface_voxel(points, voxel)
    # at the boundary (RMS radius within the margin of 10 voxels) the exact rule decides
    unit = rng.normal(size=(2000, 3))
    unit = unit - unit.mean(axis=0)
    on_edge = unit * (5.0 / np.sqrt((unit * unit).sum(axis=1).mean()))
    assert dg._surface_voxel(on_edge, 0.5) == _exact_surface_voxel(on_edge, 0.5)
    assert dg.SurfaceIndex(small).surface_xyz.shape[0] < len(small)


def test_effective_observations_equals_the_unique_count(matched, rng):
    aligned = matched[0]
    for points in (aligned, aligned[:7], aligned * 50.0, rng.normal(size=(500, 3)) * 1e4):  # grid of flags, and sort
        for voxel in (1.0, 0.3):
            keys = np.floor(points / voxel).astype(np.int64)
            assert cv.effective_observations(points, voxel) == len(np.unique(keys, axis=0))


def test_weighted_normal_matrix_equals_the_three_operand_einsum(matched):
    aligned, dst, dist2, index = matched
    inlier = dist2 <= 1.0
    pick, M, thickness = dg.matched_constraints(aligned[inlier], dst, index[inlier], return_thickness=True)
    J = np.matmul(M, cv.left_jacobians(aligned[inlier][pick]))
    assert np.array_equal(np.einsum("nki,nkj->ij", thickness[:, None, None] * J, J), np.einsum("n,nki,nkj->ij", thickness, J, J))


def test_turned_constraints_equal_the_einsum(matched, rng):
    aligned, dst, dist2, index = matched
    inlier = dist2 <= 1.0
    _, M = dg.matched_constraints(aligned[inlier], dst, index[inlier])
    angles = [0.0, np.pi / 2, np.pi, *rng.uniform(-np.pi, np.pi, 6)]
    for a in angles:
        R = cv.horizontal_turn(np.array([[np.cos(a) ** 2 + 0.1, np.sin(a) * np.cos(a)], [np.sin(a) * np.cos(a), np.sin(a) ** 2]]))
        assert np.array_equal(dg._turned(R, M), np.einsum("ij,njk,lk->nil", R, M, R))
    R = np.linalg.qr(rng.normal(size=(3, 3)))[0]  # not a turn about z: the einsum itself
    assert np.array_equal(dg._turned(R, M), np.einsum("ij,njk,lk->nil", R, M, R))


def test_voxel_downsample_groups_equal_numpys_unique(pair_94_95, rng):
    from lidarkit.registration.preprocess import _voxel_groups

    src, dst, _ = pair_94_95
    for points, voxel in ((dst, 0.5), (src, 1.0), (rng.normal(size=(300, 3)), 0.7), (np.zeros((4, 3)), 1.0), (dst[:1], 0.5)):
        keys = np.floor(points / voxel).astype(np.int64)
        flat = (keys[:, 0] - keys[:, 0].min()) * 10**12 + (keys[:, 1] - keys[:, 1].min()) * 10**6 + keys[:, 2] - keys[:, 2].min()
        _, inverse, counts = np.unique(flat, return_inverse=True, return_counts=True)
        mine = _voxel_groups(flat)
        assert np.array_equal(mine[0], inverse.reshape(-1)) and np.array_equal(mine[1], counts)
