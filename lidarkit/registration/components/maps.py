"""Maps the current sweep is registered against: the previous sweep, or kiss-icp's voxel-hash local map.

Both keep their points in the world frame with a scipy ``cKDTree`` rebuilt once per update (the map changes
every frame; queries happen every ICP iteration). :meth:`Map.nearest` returns each query's nearest map point
closer than a distance; :meth:`Map.normals` / :meth:`Map.covariances` give the local surface of map points
(PCA of their ``k`` nearest map neighbours), computed only for the points asked for and cached until the
next update, for point-to-plane and plane-to-plane residuals.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field
from scipy.spatial import cKDTree

from lidarkit.geometry import transform_points
from lidarkit.registration.components.registry import Component, ComponentConfig, component_base, register_component
from lidarkit.registration.neighbors import ScipyWorkers

_KEY_BITS = 21
_KEY_OFFSET = 1 << (_KEY_BITS - 1)
_BLOCK = np.stack(np.meshgrid([-1, 0, 1], [-1, 0, 1], [-1, 0, 1], indexing="ij"), axis=-1).reshape(-1, 3)


def voxel_keys(points_xyz: np.ndarray, voxel_size_m: float) -> np.ndarray:
    """Integer voxel coordinates ``floor(p / v)`` -> ``(N, 3)`` int64."""
    return np.floor(np.asarray(points_xyz, dtype=np.float64) / voxel_size_m).astype(np.int64)


def encode_keys(keys: np.ndarray, origin: np.ndarray | None = None, outside: int | None = None) -> np.ndarray:
    """One int64 per voxel, for voxels within +-2^20 of ``origin`` (a voxel key; default: the keys' own corner).

    The fields are 21 bits: a key beyond that range would spill into the next field and give two voxels one code (a
    map at a UTM northing, ~4.2e6 voxels of 1 m, merged neighbouring voxels), so the keys are taken relative to a
    voxel near them. A key outside the range gets the code ``outside`` (a query cell no map voxel can be), else
    it is a DataError."""
    keys = np.asarray(keys, dtype=np.int64)
    if origin is None:
        origin = keys.min(axis=0) + _KEY_OFFSET if len(keys) else np.zeros(3, dtype=np.int64)
    k = keys - origin + _KEY_OFFSET
    out_of_range = ((k < 0) | (k >= (1 << _KEY_BITS))).any(axis=1) if len(k) else np.zeros(0, dtype=bool)
    if out_of_range.any():
        if outside is None:
            from lidarkit.errors import DataError

            raise DataError(f"voxels more than 2^{_KEY_BITS - 1} voxel edges apart in one map: a map this large cannot be "
                            "indexed (a larger voxel or a shorter max_range_m)", source="voxel map")
        k = np.where(out_of_range[:, None], 0, k)
    codes = (k[:, 0] << (2 * _KEY_BITS)) | (k[:, 1] << _KEY_BITS) | k[:, 2]
    return codes if outside is None else np.where(out_of_range, outside, codes)


def _decode_keys(codes: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """The voxel keys :func:`encode_keys` gave ``codes`` relative to ``origin``."""
    mask = (1 << _KEY_BITS) - 1
    k = np.stack([codes >> (2 * _KEY_BITS), (codes >> _KEY_BITS) & mask, codes & mask], axis=1)
    return k - _KEY_OFFSET + origin


def kiss_hash_buckets(keys: np.ndarray, n_reserved: int) -> np.ndarray:
    """Bucket of each voxel key in kiss-icp's voxel hash table reserved for ``n_reserved`` entries.

    kiss-icp hashes a voxel as ``x * 73856093 ^ y * 19349669 ^ z * 83492791`` (uint32) into a robin-hood table
    of ``2^ceil(log2(2 n))`` buckets; iterating the table visits voxels by bucket, ties in insertion order.
    """
    k = keys.astype(np.int64) & 0xFFFFFFFF
    h = ((k[:, 0] * 73856093) & 0xFFFFFFFF) ^ ((k[:, 1] * 19349669) & 0xFFFFFFFF) ^ ((k[:, 2] * 83492791) & 0xFFFFFFFF)
    n_buckets = 1 << int(np.ceil(np.log2(max(2 * n_reserved, 1))))
    return h & (n_buckets - 1)


def first_per_voxel(points_xyz: np.ndarray, voxel_size_m: float, order: str = "input", backend: str = "numpy") -> np.ndarray:
    """kiss-icp's voxel downsampling: the first point (in input order) of every occupied voxel.

    ``order="input"`` returns them in input order; ``"kiss_hash"`` in the order kiss-icp's hash table yields
    them (see :func:`kiss_hash_buckets`), which decides the order kiss-icp inserts them into its map.
    ``backend="kiss_icp"`` (``"kiss_hash"`` order only) calls kiss-icp's compiled downsampling, the same points
    in the same order several times faster; ``"auto"`` does so when kiss-icp is installed.
    """
    pts = np.asarray(points_xyz, dtype=np.float64)
    if len(pts) == 0:
        return pts.reshape(0, 3)
    if order == "kiss_hash" and backend != "numpy":
        try:
            from kiss_icp.voxelization import voxel_down_sample
        except ImportError:
            if backend == "kiss_icp":
                raise
        else:
            return np.asarray(voxel_down_sample(np.ascontiguousarray(pts), float(voxel_size_m)), dtype=np.float64).reshape(-1, 3)
    keys = voxel_keys(pts, voxel_size_m)
    _, first = np.unique(encode_keys(keys), return_index=True)
    first = np.sort(first)
    if order == "kiss_hash":
        buckets = kiss_hash_buckets(keys[first], len(pts))
        first = first[np.argsort(buckets, kind="stable")]
    return pts[first]


def pca_geometry(points_xyz: np.ndarray, tree: cKDTree, query_xyz: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Normals ``(Q, 3)`` and covariances ``(Q, 3, 3)`` of the ``k`` nearest points of each query."""
    k = int(min(k, len(points_xyz)))
    _, idx = tree.query(query_xyz, k=k)
    idx = idx.reshape(len(query_xyz), k)
    nbrs = points_xyz[idx]
    centered = nbrs - nbrs.mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", centered, centered) / max(k - 1, 1)
    _, vecs = np.linalg.eigh(cov)
    return vecs[:, :, 0], cov


#: Fewer query points than this are searched on one thread (scipy starts Python threads per call otherwise).
SMALL_QUERY = 1024


@component_base("map")
class Map(Component):
    """A world-frame point map with nearest-neighbour queries and lazily computed local geometry."""

    def __init__(self, config=None, **params):
        super().__init__(config, **params)
        self.reset()

    def reset(self) -> None:
        self.points_xyz = np.zeros((0, 3))
        self._tree: cKDTree | None = None
        self._normals: np.ndarray | None = None
        self._covs: np.ndarray | None = None

    @property
    def empty(self) -> bool:
        return len(self.points_xyz) == 0

    def update(self, points_xyz: np.ndarray, T_world_lidar: np.ndarray) -> None:
        """Add a sweep's points (sensor frame) seen from ``T_world_lidar``."""
        raise NotImplementedError

    def _rebuild(self) -> None:
        self._tree = cKDTree(self.points_xyz, balanced_tree=False, compact_nodes=False) if len(self.points_xyz) else None
        self._nns = None
        if self._tree is not None and self.config.nn_backend == "open3d":
            import open3d.core as o3c

            self._center = self.points_xyz.mean(axis=0)
            self._nns = o3c.nns.NearestNeighborSearch(o3c.Tensor((self.points_xyz - self._center).astype(np.float32)))
            self._nns.knn_index()
        self._normals = None
        self._covs = None
        self._by_code = None  # map point order by voxel code, built on the first block search

    def nearest(
        self, query_xyz: np.ndarray, max_distance_m: float, state: dict | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(dist (N,) m, index (N,), valid (N,) bool)``: the nearest map point closer than ``max_distance_m``.

        ``state``: a dict kept by the caller across queries of the same points moving (ICP iterations); a point
        that moved less than half the margin between its nearest and second-nearest map point since it was last
        searched keeps its nearest point without a new search (exact: no other point can have come closer).
        """
        n = len(query_xyz)
        if self._tree is None or n == 0:
            return np.full(n, np.inf), np.zeros(n, dtype=np.int64), np.zeros(n, dtype=bool)
        if state is not None and self._nns is None:
            return self._tracked_nearest(np.asarray(query_xyz, dtype=np.float64), max_distance_m, state)
        if self._nns is not None:
            import open3d.core as o3c

            idx_t, _ = self._nns.knn_search(o3c.Tensor((query_xyz - self._center).astype(np.float32)), 1)
            idx = idx_t.numpy().reshape(-1).astype(np.int64)
            diff = query_xyz - self.points_xyz[idx]
            dist = np.sqrt(np.einsum("ij,ij->i", diff, diff))  # float64 from the indices
        else:
            bound = max_distance_m if np.isfinite(max_distance_m) else np.inf
            dist, idx = self._tree.query(query_xyz, k=1, distance_upper_bound=bound, workers=self.config.workers)
        valid = dist < max_distance_m
        return dist, np.where(valid, idx, 0).astype(np.int64), valid

    def _tracked_nearest(self, query_xyz: np.ndarray, max_distance_m: float, state: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        bound = float(max_distance_m) if np.isfinite(max_distance_m) else np.inf
        n = len(query_xyz)
        fresh = state.get("tree") is not self._tree or state.get("bound") != bound or len(state.get("anchor", ())) != n
        if fresh:
            state.update(tree=self._tree, bound=bound, anchor=query_xyz.copy(), margin=np.zeros(n), index=np.zeros(n, dtype=np.int64))
            redo = np.arange(n)
        else:
            shift = query_xyz - state["anchor"]
            redo = np.flatnonzero(~(2.0 * np.sqrt(np.einsum("ij,ij->i", shift, shift)) < state["margin"]))
        state["searched"] = len(redo)
        if len(redo):
            workers = self.config.workers if len(redo) >= SMALL_QUERY else 1  # starting threads costs more than a few searches
            d, i = self._tree.query(query_xyz[redo], k=2, distance_upper_bound=bound, workers=workers)
            # any other map point was at least min(second nearest, bound) from the anchor; inf - inf -> nan: search again
            with np.errstate(invalid="ignore"):
                state["margin"][redo] = np.minimum(d[:, 1], bound) - d[:, 0]
            state["index"][redo] = np.where(np.isfinite(d[:, 0]), i[:, 0], 0)
            state["anchor"][redo] = query_xyz[redo]
            state["found"] = state.get("found", np.zeros(n, dtype=bool))
            state["found"][redo] = np.isfinite(d[:, 0])
        idx = state["index"].copy()
        diff = query_xyz - self.points_xyz[idx]
        dist = np.sqrt(np.einsum("ij,ij->i", diff, diff))
        dist[~state["found"] | (dist >= bound)] = np.inf
        valid = dist < max_distance_m
        return dist, np.where(valid, idx, 0).astype(np.int64), valid

    def _geometry(self, index: np.ndarray) -> None:
        m = len(self.points_xyz)
        if self._normals is None:
            self._normals = np.full((m, 3), np.nan)
            self._covs = np.full((m, 3, 3), np.nan)
        todo = np.unique(index[np.isnan(self._normals[index, 0])])
        if len(todo):
            normals, covs = pca_geometry(self.points_xyz, self._tree, self.points_xyz[todo], self.config.neighbors)
            self._normals[todo] = normals
            self._covs[todo] = covs

    def normals(self, index: np.ndarray) -> np.ndarray:
        """Unit surface normals ``(N, 3)`` at map points ``index`` (PCA of ``neighbors`` map points)."""
        self._geometry(index)
        return self._normals[index]

    def covariances(self, index: np.ndarray) -> np.ndarray:
        """Point covariances ``(N, 3, 3)`` m^2 at map points ``index`` (same neighbourhoods as the normals)."""
        self._geometry(index)
        return self._covs[index]


class ScanToScanConfig(ComponentConfig):
    neighbors: int = Field(10, ge=3, description="map points per normal / covariance estimate")
    nn_backend: Literal["scipy", "open3d"] = Field(
        "scipy", description="nearest-neighbour index: scipy cKDTree (float64, exact) or Open3D (float32 search, float64 distances)"
    )
    workers: ScipyWorkers = Field(-1, description="threads of the scipy nearest-neighbour queries (-1: all cores, as kiss-icp's TBB)")
    track_neighbors: bool = Field(
        True, description="ICP iterations: keep a point's nearest map point while it provably stays the nearest (same answers, fewer searches)"
    )


@register_component("map", "scan_to_scan")
class ScanToScanMap(Map):
    """The previous sweep only (the classic chained ICP)."""

    Config = ScanToScanConfig

    def update(self, points_xyz: np.ndarray, T_world_lidar: np.ndarray) -> None:
        self.points_xyz = transform_points(T_world_lidar, points_xyz)
        self._rebuild()


class VoxelHashConfig(ComponentConfig):
    voxel_size_m: float = Field(1.0, gt=0, description="map voxel edge (m); the pipeline passes its own")
    max_points_per_voxel: int = Field(20, ge=1, description="points kept per voxel (first come, first kept)")
    max_range_m: float = Field(100.0, gt=0, description="voxels whose first point is this far from the sensor are removed (m); the "
                                                        "pipeline passes its own")
    min_point_spacing_m: float | None = Field(
        None, ge=0, description="a new point this close to one of its voxel is dropped (m); None: kiss-icp's voxel / sqrt(max points)"
    )
    search: Literal["voxel_neighborhood", "kdtree"] = Field(
        "voxel_neighborhood", description="nearest point among the 27 voxels around the query (kiss-icp) or anywhere"
    )
    neighbors: int = Field(10, ge=3, description="map points per normal / covariance estimate")
    nn_backend: Literal["scipy", "open3d"] = Field(
        "scipy", description="nearest-neighbour index: scipy cKDTree (float64, exact) or Open3D (float32 search, float64 distances)"
    )
    workers: ScipyWorkers = Field(-1, description="threads of the scipy nearest-neighbour queries (-1: all cores, as kiss-icp's TBB)")
    track_neighbors: bool = Field(
        True, description="ICP iterations: keep a point's nearest map point while it provably stays the nearest (same answers, fewer searches)"
    )


@register_component("map", "voxel_hash")
class VoxelHashMap(Map):
    """kiss-icp's local map: up to ``max_points_per_voxel`` points per voxel, far voxels dropped every update."""

    Config = VoxelHashConfig

    def reset(self) -> None:
        super().reset()
        self._pkeys = np.zeros((0, 3), dtype=np.int64)
        self._pcodes = np.zeros(0, dtype=np.int64)
        self._vcodes = np.zeros(0, dtype=np.int64)  # sorted voxel codes
        self._vfirst = np.zeros((0, 3))  # first point of each voxel
        self._vcount = np.zeros(0, dtype=np.int64)
        self._key_origin: np.ndarray | None = None  # the voxel codes are relative to the first voxel inserted

    @property
    def spacing_m(self) -> float:
        c = self.config
        return c.min_point_spacing_m if c.min_point_spacing_m is not None else c.voxel_size_m / np.sqrt(c.max_points_per_voxel)

    def update(self, points_xyz: np.ndarray, T_world_lidar: np.ndarray) -> None:
        T = np.asarray(T_world_lidar, dtype=np.float64)
        self.add_points(transform_points(T, points_xyz))
        self.remove_far(T[:3, 3])
        self._rebuild()

    def add_points(self, points_xyz: np.ndarray) -> None:
        """Insert world points in order, as kiss-icp does: a point is dropped when its voxel is full or already
        holds a point closer than the spacing (checked against the map and against earlier points of the batch)."""
        new = np.asarray(points_xyz, dtype=np.float64)
        if len(new) == 0:
            return
        c = self.config
        keys = voxel_keys(new, c.voxel_size_m)
        far = self._key_origin is None or bool((np.abs(keys - self._key_origin) >= _KEY_OFFSET).any())
        if far:  # the codes follow the drive: relative to a voxel of this batch (the map is within max range of it)
            self._recenter(keys[0].copy())
        codes = encode_keys(keys, self._key_origin)
        spacing = self.spacing_m
        keep = np.ones(len(new), dtype=bool)
        if spacing > 0:
            if self._tree is not None:
                # any map point of the same voxel within the spacing (the nearest may lie in the next voxel)
                k = int(min(8, len(self.points_xyz)))
                d, idx = self._tree.query(new, k=k, distance_upper_bound=spacing, workers=self.config.workers)
                d, idx = d.reshape(len(new), k), idx.reshape(len(new), k)
                hit = d < spacing
                same = np.zeros_like(hit)
                same[hit] = self._pcodes[idx[hit]] == np.broadcast_to(codes[:, None], hit.shape)[hit]
                keep &= ~same.any(axis=1)
        # earlier points of this batch: kiss-icp inserts one at a time; replay it voxel by voxel in rounds,
        # round r offering every voxel its r-th candidate (a rejected point does not count)
        V = len(self._vcodes)
        pos = np.searchsorted(self._vcodes, codes)
        exists = pos < V
        exists[exists] = self._vcodes[pos[exists]] == codes[exists]
        existing = np.where(exists, self._vcount[np.minimum(pos, max(V - 1, 0))] if V else 0, 0)
        cand = np.flatnonzero(keep)
        order = cand[np.argsort(codes[cand], kind="stable")]
        sorted_codes = codes[order]
        starts = np.r_[0, np.flatnonzero(np.diff(sorted_codes)) + 1] if len(order) else np.zeros(0, dtype=np.int64)
        sizes = np.diff(np.r_[starts, len(order)])
        group = np.repeat(np.arange(len(starts)), sizes)
        rank = np.arange(len(order)) - np.repeat(starts, sizes)
        room = c.max_points_per_voxel - existing[order[starts]] if len(order) else np.zeros(0, dtype=np.int64)
        n_rounds = int(sizes.max()) if len(sizes) else 0
        slots = min(n_rounds, c.max_points_per_voxel)
        kept_xyz = np.full((len(starts), max(slots, 1), 3), np.nan)
        n_kept = np.zeros(len(starts), dtype=np.int64)
        ok = np.zeros(len(order), dtype=bool)
        for r in range(n_rounds):  # rounds, not points: at most the points one voxel receives in one sweep
            at = np.flatnonzero(rank == r)
            g = group[at]
            p = new[order[at]]
            free = n_kept[g] < np.minimum(room[g], slots)
            if spacing > 0 and r > 0:
                d2 = np.sum((kept_xyz[g] - p[:, None, :]) ** 2, axis=2)
                free &= ~(d2 < spacing * spacing).any(axis=1)
            at, g = at[free], g[free]
            kept_xyz[g, n_kept[g]] = new[order[at]]
            n_kept[g] += 1
            ok[at] = True
        accepted = np.sort(order[ok])
        if len(accepted) == 0:
            return
        acc_codes = codes[accepted]
        self.points_xyz = np.concatenate([self.points_xyz, new[accepted]])
        self._pkeys = np.concatenate([self._pkeys, keys[accepted]])
        self._pcodes = np.concatenate([self._pcodes, acc_codes])
        # voxel table: counts of existing voxels, new voxels with their first point
        ucodes, first, counts = np.unique(acc_codes, return_index=True, return_counts=True)
        upos = np.searchsorted(self._vcodes, ucodes)
        uex = upos < V
        uex[uex] = self._vcodes[upos[uex]] == ucodes[uex]
        self._vcount[upos[uex]] += counts[uex]
        if (~uex).any():
            vcodes = np.concatenate([self._vcodes, ucodes[~uex]])
            order_v = np.argsort(vcodes, kind="stable")
            self._vcodes = vcodes[order_v]
            self._vfirst = np.concatenate([self._vfirst, new[accepted[first[~uex]]]])[order_v]
            self._vcount = np.concatenate([self._vcount, counts[~uex]])[order_v]

    def remove_far(self, origin_xyz: np.ndarray) -> None:
        """Drop every voxel whose first point is at least ``max_range_m`` from ``origin_xyz``."""
        d2 = np.sum((self._vfirst - np.asarray(origin_xyz)) ** 2, axis=1)
        far = d2 >= self.config.max_range_m**2
        if not far.any():
            return
        gone = self._vcodes[far]
        self._vcodes, self._vfirst, self._vcount = self._vcodes[~far], self._vfirst[~far], self._vcount[~far]
        keep = ~np.isin(self._pcodes, gone)
        self.points_xyz, self._pkeys, self._pcodes = self.points_xyz[keep], self._pkeys[keep], self._pcodes[keep]

    def _recenter(self, origin: np.ndarray) -> None:
        """Voxel codes relative to ``origin`` from now on (the kept ones encoded again; their order is unchanged)."""
        if self._key_origin is not None and len(self._vcodes):
            self._vcodes = encode_keys(_decode_keys(self._vcodes, self._key_origin), origin)
            self._pcodes = encode_keys(self._pkeys, origin)
            self._by_code = None
        self._key_origin = origin

    def block_nearest(self, query_xyz: np.ndarray, query_keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Exact nearest map point among the 27 voxels around each query's voxel (kiss-icp's search rule).

        ``(dist (Q,) m, index (Q,))``; ``inf`` where the 27 voxels are empty. Brute force over the block's points
        (at most 27 x max points per voxel each), meant for the few queries the KD-tree answer does not settle.
        """
        q = len(query_xyz)
        if q == 0 or len(self.points_xyz) == 0:
            return np.full(q, np.inf), np.zeros(q, dtype=np.int64)
        if getattr(self, "_by_code", None) is None:
            self._by_code = np.argsort(self._pcodes, kind="stable")
        sorted_codes = self._pcodes[self._by_code]
        cells = (query_keys[:, None, :] + _BLOCK[None, :, :]).reshape(-1, 3)
        codes = encode_keys(cells, self._key_origin, outside=-1)  # (a cell beyond the codes' range holds no map voxel)
        lo = np.searchsorted(sorted_codes, codes, side="left")
        hi = np.searchsorted(sorted_codes, codes, side="right")
        counts = hi - lo
        owner = np.repeat(np.repeat(np.arange(q), len(_BLOCK)), counts)
        starts = np.repeat(lo - np.r_[0, np.cumsum(counts)[:-1]], counts)
        cand = self._by_code[np.arange(counts.sum()) + starts]
        diff = self.points_xyz[cand] - query_xyz[owner]
        d = np.sqrt(np.einsum("ij,ij->i", diff, diff))
        dist = np.full(q, np.inf)
        np.minimum.at(dist, owner, d)
        idx = np.zeros(q, dtype=np.int64)
        best = d == dist[owner]
        idx[owner[best][::-1]] = cand[best][::-1]  # ties: the first candidate (block order, then insertion)
        return dist, idx

    def nearest(
        self, query_xyz: np.ndarray, max_distance_m: float, state: dict | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        dist, idx, valid = super().nearest(query_xyz, max_distance_m, state)
        if self.config.search == "kdtree" or not valid.any():
            return dist, idx, valid
        # kiss-icp looks only in the 27 voxels around the query: a nearest point farther than one voxel may lie
        # outside them, and then the nearest point inside them (if any within the distance) is the answer
        v = self.config.voxel_size_m
        far = np.flatnonzero(valid & (dist >= v))
        if len(far):
            qkeys = voxel_keys(query_xyz[far], v)
            outside = np.abs(self._pkeys[idx[far]] - qkeys).max(axis=1) > 1
            redo = far[outside]
            if len(redo):
                d_r, i_r = self.block_nearest(query_xyz[redo], qkeys[outside])
                dist[redo], idx[redo] = d_r, np.where(np.isfinite(d_r), i_r, 0)
                valid[redo] = d_r < max_distance_m
        return dist, idx, valid


__all__ = ["Map", "ScanToScanMap", "VoxelHashMap", "encode_keys", "first_per_voxel", "pca_geometry", "voxel_keys"]
