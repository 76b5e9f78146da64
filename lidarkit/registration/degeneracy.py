"""Degeneracy of a final alignment: eigen-analysis of the 6x6 normal matrix of the matched points.

The point-to-point normal matrix ``sum J_i^T J_i`` is full rank for any three non-collinear pairs, so
it cannot reveal that a flat patch lets the source slide. We therefore weight each residual by the
directions in which the target surface around its match is *thin*: ``M_i = n n^T`` on a plane,
the two normals of a line, ``I`` in volumetric clutter (local PCA of the target's k nearest
neighbours). With ``J_i = [I, -[p_i]x diag(1/r)]`` (points centred on their centroid, the rotation about each axis
scaled by the RMS distance ``r`` of the points from that axis, so that all six columns are in metres) the normal
matrix is
``H = (1/n) sum J_i^T M_i J_i``. A plane leaves 3 zero eigenvalues, a line 2; the result is
flagged ``degenerate`` when ``min(eig) / max(eig) < DEGENERACY_RATIO_THRESHOLD`` (1e-2). Measured on
KITTI seq 00: full scans ~0.3, road-only patches (z < -1.5 m, 8-40 m around the car) 5e-4 to 8e-3.
"""

from __future__ import annotations

import numpy as np

from lidarkit.registration.base import DEGENERACY_RATIO_THRESHOLD, Degeneracy
from lidarkit.registration.covariance import horizontal_turn, left_jacobians, twist_turn

try:  # optional (extra ``gicp``): a faster exact k-nearest search for the local surfaces
    import small_gicp as _small_gicp
except ImportError:
    _small_gicp = None

#: An eigen-direction of the local covariance is "thin" (constrained) below this fraction of the largest.
THIN_RATIO = 0.1

#: The lever arm of a rotation in the normal matrix is at least this fraction of the RMS radius of the points.
MIN_ARM_FRACTION = 0.05

#: Weak eigenvalues within this factor of each other are named as one subspace (their eigenvectors are an arbitrary
#: mix of its axes).
SUBSPACE_FACTOR = 10.0

#: Neighbours of a local line in a 2D scan (a laser scan: its surfaces are walls seen as lines).
PLANAR_NEIGHBOURS = 5

#: Local surfaces are estimated on the target voxelized at min(this, RMS radius / 10) so that the
#: anisotropic sampling of a spinning LiDAR (dense along a ring, sparse across rings) does not make a
#: flat road look like a set of lines.
SURFACE_VOXEL_M = 0.5


def surface_constraints(neighborhoods_xyz: np.ndarray, return_thickness: bool = False):
    """``(n, 3, 3)`` constraint projectors ``M_i`` from ``(n, k, 3)`` neighbourhoods of target points; with
    ``return_thickness`` also ``(n,)`` the variance of the neighbours across the surface (mean over its constrained
    directions, m^2): range noise plus what a plane does not model (curvature, sparse rings)."""
    centred = neighborhoods_xyz - _neighbourhood_means(neighborhoods_xyz)
    cov = np.matmul(centred.transpose(0, 2, 1), centred) / neighborhoods_xyz.shape[1]  # batched matmul: 4x the einsum
    evals, evecs = np.linalg.eigh(cov)  # ascending
    top = evals[:, 2:3]
    thin = evals <= THIN_RATIO * top
    # no thin direction: a corner or an edge between two surfaces (or clutter). Only the normal of the best-fitting
    # plane is trusted; constraining all three would let a wall-floor corner pin the direction along the corner.
    thin[:, 0] = True
    thin[top[:, 0] <= 0] = True  # all neighbours identical: no surface, plain point-to-point
    M = np.matmul(evecs * thin.astype(np.float64)[:, None, :], evecs.transpose(0, 2, 1))
    if not return_thickness:
        return M
    return M, (np.clip(evals, 0.0, None) * thin).sum(axis=1) / thin.sum(axis=1)


def _neighbourhood_means(neighborhoods_xyz: np.ndarray) -> np.ndarray:
    """``(n, 1, 3)`` ``neighborhoods_xyz.mean(axis=1, keepdims=True)`` of C-contiguous neighbourhoods (the gathers
    ``surface[nbr]`` are), the same numbers (numpy reduces that middle axis one neighbour after another, as this does;
    a transposed view it sums pairwise) in a third of the time: the reduction's inner loop runs over 3 coordinates at a
    time, these additions over all n neighbourhoods."""
    k = neighborhoods_xyz.shape[1]
    if k == 0:
        return neighborhoods_xyz.mean(axis=1, keepdims=True)
    total = neighborhoods_xyz[:, 0].copy()
    for j in range(1, k):
        total += neighborhoods_xyz[:, j]
    return (total / k)[:, None, :]


def _turned(R: np.ndarray, constraints: np.ndarray) -> np.ndarray:
    """``einsum("ij,njk,lk->nil", R, constraints, R)`` (``R M_n R^T``) for a turn about z, the same numbers in half the
    time: einsum adds the products ``(R_ij M_jk) R_lk`` over ``j``, then ``k``, and so does this, leaving out the terms
    with one of the turn's zeros (each adds an exact 0) and the products by its 1."""
    if not (R[2, 0] == R[2, 1] == R[0, 2] == R[1, 2] == 0.0 and R[2, 2] == 1.0):
        return np.einsum("ij,njk,lk->nil", R, constraints, R)
    M, R2 = constraints, R[:2, :2]
    out = np.empty_like(M)
    P = (R2[None, :, None, :, None] * M[:, None, None, :2, :2]) * R2[None, None, :, None, :]  # (n, i, l, j, k)
    out[:, :2, :2] = P[..., 0, 0] + P[..., 0, 1] + P[..., 1, 0] + P[..., 1, 1]
    out[:, :2, 2] = R2[:, 0] * M[:, 0, 2, None] + R2[:, 1] * M[:, 1, 2, None]
    out[:, 2, :2] = M[:, 2, 0, None] * R2[:, 0] + M[:, 2, 1, None] * R2[:, 1]
    out[:, 2, 2] = M[:, 2, 2]
    return out


def normal_matrix(points_xyz: np.ndarray, constraints: np.ndarray) -> np.ndarray:
    """Normalised 6x6 ``H`` for ``(n, 3)`` aligned source points and ``(n, 3, 3)`` projectors.

    The lever arms are taken about the principal horizontal axes of the points (a corridor's own axis, however the
    scene is turned in the frame) and ``H`` is turned back: its eigen-summary is the same for the same scene at any
    heading (about the frame's x and y, a corridor at 30-45 degrees named roll as its weakest direction and flagged it
    degenerate, at 0 and 90 degrees the translation along it)."""
    p = points_xyz - points_xyz.mean(axis=0)
    n = len(p)
    R = horizontal_turn(p[:, :2].T @ p[:, :2] / max(n, 1))  # the points' major horizontal axis onto x
    p = p @ R.T
    constraints = _turned(R, constraints)
    # RMS lever arm about each axis through the centroid: a rotation about x is scaled by the distance of the points
    # from the x axis, not by their distance from the centroid (in a long corridor the two differ tenfold and a
    # single radius would make roll look weaker than the unconstrained translation along the corridor)
    # (the arm is floored at MIN_ARM_FRACTION of the RMS radius: about the axis of a thin line no point moves)
    sq = p * p
    radius = float(np.sqrt(sq.sum(axis=1).mean()))
    arm = np.sqrt(np.maximum(sq.sum(axis=1, keepdims=True) - sq, 0.0).mean(axis=0))
    arm = np.maximum(arm, MIN_ARM_FRACTION * radius)
    J = left_jacobians(p)
    J[:, :, 3:] *= np.where(arm > 0, 1.0 / np.where(arm > 0, arm, 1.0), 0.0)  # rotation columns in metres at the lever arm
    MJ = np.matmul(constraints, J)  # (n, 3, 6): two contractions instead of one 4-index einsum (10x faster)
    H = np.einsum("nki,nkj->ij", J, MJ) / max(n, 1)
    turn = twist_turn(R)
    return turn.T @ H @ turn  # back in the frame's axes (a turn: the eigenvalues are the principal axes' own)


def summarize(H: np.ndarray, threshold: float = DEGENERACY_RATIO_THRESHOLD, kind: str = "point_to_surface") -> Degeneracy:
    """Eigen-summary of a symmetric 6x6 normal matrix."""
    evals, evecs = np.linalg.eigh(0.5 * (H + H.T))
    evals = np.clip(evals, 0.0, None)
    top = evals[-1]
    ratio = evals[0] / top if top > 0 else 0.0
    weakest = evecs[:, 0]
    weakest = weakest * (1.0 if weakest[np.argmax(np.abs(weakest))] >= 0 else -1.0)
    weak = _weak_names(evals, evecs, int(np.sum(evals < threshold * top))) if top > 0 else ["all six"]
    return Degeneracy(
        eigenvalues=tuple(float(x) for x in evals),
        condition_number=float(top / evals[0]) if evals[0] > 0 else float("inf"),
        degenerate=bool(ratio < threshold),
        weakest_direction=tuple(float(x) for x in weakest),
        threshold=threshold,
        kind=kind,
        weak_directions=tuple(weak),
        weakest_name=describe_direction(weakest) if top > 0 else "all six",
    )


_AXES = ("x", "y", "z")


def _and(words: list[str]) -> str:
    return words[0] if len(words) == 1 else f"{', '.join(words[:-1])} and {words[-1]}"


def _weak_names(evals: np.ndarray, evecs: np.ndarray, n_weak: int) -> list[str]:
    """Names of the ``n_weak`` smallest eigen-directions. Eigenvalues within :data:`SUBSPACE_FACTOR` of each other are
    named once, by the axes their subspace spans (a flat ground's x, y and yaw were three arbitrary mixes, "translation
    along (0.52, 0.86, 0.00) coupled with rotation", differing from variant to variant)."""
    names, start = [], 0
    while start < n_weak:
        near = SUBSPACE_FACTOR * max(evals[start], 1e-12 * evals[-1])
        end = start + 1
        while end < n_weak and evals[end] <= near:
            end += 1
        wide, reach = end, SUBSPACE_FACTOR * max(evals[end - 1], 1e-12 * evals[-1])  # (from the weak ones' largest: a
        while wide < len(evals) and evals[wide] <= reach:  # yaw 3.1x above a road's y but 10.1x above its x was left out)
            wide += 1  # near-equal directions just above the threshold
        if wide > end and _subspace_axes(evecs[:, start:end]) is None and _subspace_axes(evecs[:, start:wide]) is not None:
            # they span one subspace with the weak ones, which alone are an arbitrary mix of its axes (a road's x and y
            # below the threshold, its yaw 2.7x above: two raw vectors, one or two from pair to pair): named whole
            end = wide
        axes = _subspace_axes(evecs[:, start:end])
        if end - start == 1 or axes is None:  # a single direction, or a subspace not along axes
            names += [describe_direction(evecs[:, i]) for i in range(start, end)]
        else:
            moves = [_AXES[a] for a in axes if a < 3]
            turns = [f"{_AXES[a - 3]} ({('roll', 'pitch', 'yaw')[a - 3]})" for a in axes if a >= 3]
            names.append(", ".join(([f"translation along {_and(moves)}"] if moves else [])
                                   + ([f"rotation about {_and(turns)}"] if turns else [])))
        start = end
    return names


def _subspace_axes(vectors: np.ndarray) -> np.ndarray | None:
    """The axes (indices, sorted) the columns of ``vectors`` span, or None when the subspace does not lie along axes."""
    span = np.sum(vectors**2, axis=1)  # how much of each axis lies in the subspace (sums to its size)
    axes = np.sort(np.argsort(span)[::-1][: vectors.shape[1]])
    return axes if span[axes].min() >= 0.9 else None


def describe_direction(direction: np.ndarray) -> str:
    """A 6-vector in ``TWIST_ORDER`` (rotation part scaled to metres, as in :func:`normal_matrix`) in words:
    ``"translation along x"``, ``"rotation about z (yaw)"``, or the vector when no axis dominates."""
    v = np.asarray(direction, dtype=np.float64).reshape(6)
    trans, rot = v[:3], v[3:]
    part, kind = (trans, "translation along") if np.linalg.norm(trans) >= np.linalg.norm(rot) else (rot, "rotation about")
    unit = part / max(np.linalg.norm(part), 1e-300)
    axis = int(np.argmax(np.abs(unit)))
    if abs(unit[axis]) >= 0.9:
        name = _AXES[axis]
        if kind == "rotation about":
            name += f" ({('roll', 'pitch', 'yaw')[axis]})"
    else:
        unit = unit * np.sign(unit[axis])
        name = "(" + ", ".join(f"{c:.2f}" for c in unit) + ")"
    mixed = min(np.linalg.norm(trans), np.linalg.norm(rot)) > 0.3 * max(np.linalg.norm(trans), np.linalg.norm(rot))
    return f"{kind} {name}" + (" coupled with " + ("rotation" if kind.startswith("translation") else "translation") if mixed else "")


class SurfaceIndex:
    """The pose-free part of :func:`matched_constraints` for one target cloud: the target voxelized at
    ``min(surface_voxel_m, RMS radius / 10)`` (``None``: the raw target) and a KD-tree over it. Built apart so that
    it can be prepared (e.g. in another thread) while the registration that needs it is still running."""

    def __init__(self, target_xyz: np.ndarray, surface_voxel_m: float | None = SURFACE_VOXEL_M):
        self.target_xyz = target_xyz
        self.surface_voxel_m = surface_voxel_m
        surface = target_xyz
        if surface_voxel_m is not None:
            from lidarkit.registration.preprocess import voxel_downsample

            voxel = _surface_voxel(target_xyz, surface_voxel_m)
            if voxel > 0:
                surface = voxel_downsample(target_xyz, voxel)
        self.surface_xyz = surface
        self._tree = _kdtree(surface)

    def knn(self, queries_xyz: np.ndarray, k: int) -> np.ndarray:
        """``(q, k)`` indices of the ``k`` nearest surface points of each query (exact)."""
        return _knn_query(self._tree, queries_xyz, k)


#: A quick mean squared radius this much above ``(10 * surface_voxel_m)^2`` settles the voxel size without the exact
#: one (the two differ by rounding: ~1e-15 relative in float64, ~1e-6 for a float32 cloud)
_QUICK_RADIUS_MARGIN = 1e-3


def _surface_voxel(target_xyz: np.ndarray, surface_voxel_m: float) -> float:
    """``min(surface_voxel_m, RMS radius / 10)`` of the target. The RMS radius, as written, is slow (two reductions along
    short axes, ~1 ms on a KITTI scan) and decides only whether it is below ``10 * surface_voxel_m`` (5 m: a small indoor
    scene); a scan wider than that with a margin is told apart by a quick estimate, anything else takes the exact one."""
    n = len(target_xyz)
    if n:
        quick = 0.0  # mean squared distance from the centroid, column by column
        for i in range(3):
            column = np.asarray(target_xyz[:, i], dtype=np.float64)
            d = column - column.mean()
            quick += float((d * d).sum()) / n  # (not np.dot: BLAS, 10-100x slower on a busy machine)
        if quick > (10.0 * surface_voxel_m) ** 2 * (1.0 + _QUICK_RADIUS_MARGIN):
            return surface_voxel_m
    centred = target_xyz - target_xyz.mean(axis=0)
    rms_radius = float(np.sqrt((centred * centred).sum(axis=1).mean()))
    return min(surface_voxel_m, rms_radius / 10.0)


def matched_constraints(
    source_aligned_xyz: np.ndarray,
    target_xyz: np.ndarray,
    matched_target_index: np.ndarray,
    k: int = 20,
    surface_voxel_m: float | None = SURFACE_VOXEL_M,
    max_points: int = 2000,
    seed: int = 0,
    return_thickness: bool = False,
    surfaces: SurfaceIndex | None = None,
):
    """``(picked pair indices (m,), surface projectors (m, 3, 3))`` of at most ``max_points`` matched pairs
    (a seeded random subset), shared by the degeneracy summary and the covariance; with ``return_thickness`` also the
    ``(m,)`` across-surface variance of each target neighbourhood (:func:`surface_constraints`).

    Local surfaces come from the ``k`` nearest neighbours in the target voxelized at
    ``min(surface_voxel_m, RMS radius / 10)`` (``surface_voxel_m=None``: the raw target), searched by :func:`_knn`;
    ``surfaces``: that :class:`SurfaceIndex` of ``target_xyz`` if already built.
    """
    n = len(source_aligned_xyz)
    if len(target_xyz) and float(np.ptp(target_xyz[:, 2])) == 0.0:
        # a 2D scan (one plane, a few hundred points): its surfaces are lines, seen only by close neighbours of the raw
        # points (20 neighbours of a voxelized 2D scan span both walls of a corridor and leave z as the only thin
        # direction: x, y and yaw then looked unconstrained on every frame)
        k, surface_voxel_m = min(k, PLANAR_NEIGHBOURS), None
    pick = np.arange(n)
    if n > max_points:
        pick = np.sort(np.random.default_rng(seed).choice(n, size=max_points, replace=False))
    if surfaces is None or surfaces.target_xyz is not target_xyz or surfaces.surface_voxel_m != surface_voxel_m:
        surfaces = SurfaceIndex(target_xyz, surface_voxel_m)
    surface = surfaces.surface_xyz
    k = int(min(k, len(surface)))
    # several source points often share a target point: each distinct anchor is queried and analysed once
    unique_anchors, inverse = np.unique(matched_target_index[pick], return_inverse=True)
    nbr = surfaces.knn(target_xyz[unique_anchors], k)
    inverse = inverse.reshape(-1)
    if return_thickness:
        M, thickness = surface_constraints(surface[nbr], return_thickness=True)
        return pick, M[inverse], thickness[inverse]
    return pick, surface_constraints(surface[nbr])[inverse]


def _kdtree(points_xyz: np.ndarray):
    """An exact KD-tree for :func:`_knn_query`: small_gicp's when installed (~2x scipy's on a few thousand queries of a
    scan, one thread), else a scipy tree built without the balancing and compaction that only pay off for many
    queries."""
    if _small_gicp is not None:
        return _small_gicp.KdTree(points_xyz, num_threads=1)
    from scipy.spatial import cKDTree

    return cKDTree(points_xyz, balanced_tree=False, compact_nodes=False)


def _knn_query(tree, queries_xyz: np.ndarray, k: int) -> np.ndarray:
    if _small_gicp is not None and isinstance(tree, _small_gicp.KdTree):
        index, _ = tree.batch_knn_search(queries_xyz, k, num_threads=1)
        return np.asarray(index, dtype=np.int64).reshape(len(queries_xyz), k)
    _, index = tree.query(queries_xyz, k=k)
    return np.asarray(index).reshape(len(queries_xyz), k)


def _knn(points_xyz: np.ndarray, queries_xyz: np.ndarray, k: int) -> np.ndarray:
    """``(q, k)`` indices of the ``k`` nearest of ``points_xyz`` to each query (exact, :func:`_kdtree`)."""
    return _knn_query(_kdtree(points_xyz), queries_xyz, k)


def assess_degeneracy(
    source_aligned_xyz: np.ndarray,
    target_xyz: np.ndarray,
    matched_target_index: np.ndarray,
    k: int = 20,
    surface_voxel_m: float | None = SURFACE_VOXEL_M,
    max_points: int = 2000,
    seed: int = 0,
    threshold: float = DEGENERACY_RATIO_THRESHOLD,
) -> Degeneracy:
    """Degeneracy of matched pairs (``source_aligned_xyz[i]`` <-> ``target_xyz[matched_target_index[i]]``), on the
    surfaces of :func:`matched_constraints`."""
    if len(source_aligned_xyz) < 3:
        return Degeneracy.unknown(f"{len(source_aligned_xyz)} correspondences")
    pick, constraints = matched_constraints(source_aligned_xyz, target_xyz, matched_target_index, k, surface_voxel_m, max_points, seed)
    return summarize(normal_matrix(source_aligned_xyz[pick], constraints), threshold)


__all__ = ["THIN_RATIO", "SurfaceIndex", "assess_degeneracy", "describe_direction", "matched_constraints", "normal_matrix", "summarize", "surface_constraints"]
