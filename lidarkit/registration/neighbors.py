"""Nearest-neighbour search on a fixed target cloud, built once and queried every ICP iteration.

Backends:
- ``"scipy"``: :class:`scipy.spatial.cKDTree` (float64, exact), ``leafsize`` and ``workers`` settable.
- ``"open3d"``: Open3D tensor ``NearestNeighborSearch.knn_search`` (float32 on coordinates centred on
  the target centroid; the returned squared distances are recomputed in float64 from the indices).
- ``"brute"``: exact brute force in blocks (O(N M)) on coordinates centred on the target centroid (far from the
  origin, e.g. georeferenced, ``|t|^2 - 2 p.t`` lost the centimetres to cancellation); for small clouds and for
  checking the trees.
- ``"auto"``: ``"open3d"`` (measured fastest on KITTI scans, see benchmarks/README.md), else ``"scipy"``.
"""

from __future__ import annotations

from typing import Annotated

import numpy as np
from pydantic import AfterValidator

from lidarkit.errors import ConfigError, RegistrationError

BACKENDS = ("auto", "scipy", "open3d", "brute")

#: Refuse brute force beyond this many point pairs per pass (use voxel_size_m to subsample): one pass over 3.0e9 pairs
#: (the bundled KITTI pair) took 41 s, and ICP makes 20-40 of them (it ran for 10 minutes and more).
MAX_BRUTE_FORCE_PAIRS = 2e8


def refuse_slow_brute_force(n_queries: int, n_targets: int, source: str) -> None:
    """Refuse a brute-force search of ``n_queries`` points among ``n_targets`` beyond :data:`MAX_BRUTE_FORCE_PAIRS`;
    ``source`` names the option that chose brute force (e.g. ``"vanilla nn_backend='brute'"``)."""
    if float(n_queries) * n_targets > MAX_BRUTE_FORCE_PAIRS:
        raise RegistrationError(f"exact search over {n_queries} x {n_targets} points is too slow; set voxel_size_m to "
                                f"subsample (at most {MAX_BRUTE_FORCE_PAIRS:.0e} point pairs a pass)", source=source)


def _scipy_workers(value: int) -> int:
    if value != -1 and value < 1:  # scipy's own error came only at the first query, reported as a failure of the pair
        raise ValueError(f"workers must be -1 (all cores) or >= 1, got {value}")
    return value


#: a config field's type for scipy's query threads: -1 (all cores) or a count, checked when the config is made
ScipyWorkers = Annotated[int, AfterValidator(_scipy_workers)]


def resolved_backend(backend: str) -> str:
    """The backend ``"auto"`` stands for here (Open3D's when it is installed, else scipy's); others as given."""
    if backend == "auto":
        return "open3d" if _open3d_nns_available() else "scipy"
    return backend


class NearestNeighbors:
    """Index over ``(M, 3)`` target points; :meth:`query` returns squared distances and indices."""

    def __init__(self, target_xyz: np.ndarray, backend: str = "auto", leafsize: int = 16, workers: int = -1,
                 source: str = "nn_backend='brute'"):
        """``source``: what chose the backend, named when brute force refuses a query too large for it."""
        self.source = source
        if backend not in BACKENDS:
            raise ConfigError(f"unknown nearest-neighbour backend {backend!r}; available: {', '.join(BACKENDS)}", source="nn_backend")
        self.target_xyz = np.asarray(target_xyz, dtype=np.float64)
        self.workers = workers
        backend = resolved_backend(backend)
        self.backend = backend
        if backend == "scipy":
            from scipy.spatial import cKDTree

            self._tree = cKDTree(self.target_xyz, leafsize=int(leafsize))
        elif backend == "open3d":
            import open3d.core as o3c

            self._center = self.target_xyz.mean(axis=0)
            self._nns = o3c.nns.NearestNeighborSearch(o3c.Tensor((self.target_xyz - self._center).astype(np.float32)))
            self._nns.knn_index()
        else:
            self._center = self.target_xyz.mean(axis=0)
            self._centred = self.target_xyz - self._center
            self._sq_norms = np.einsum("ij,ij->i", self._centred, self._centred)

    def query(self, points_xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Nearest target point of each ``(N, 3)`` query: ``(dist2 (N,) float64 m^2, index (N,) int64)``."""
        pts = np.asarray(points_xyz, dtype=np.float64)
        if len(pts) == 0:
            return np.zeros(0), np.zeros(0, dtype=np.int64)
        if self.backend == "scipy":
            dist, idx = self._tree.query(pts, k=1, workers=self.workers)
            return dist * dist, idx.astype(np.int64, copy=False)
        if self.backend == "open3d":
            import open3d.core as o3c

            idx_t, _ = self._nns.knn_search(o3c.Tensor((pts - self._center).astype(np.float32)), 1)
            idx = idx_t.numpy().reshape(-1).astype(np.int64, copy=False)
        else:
            refuse_slow_brute_force(len(pts), len(self.target_xyz), self.source)
            idx = self._brute_indices(pts)
        diff = pts - self.target_xyz[idx]
        return np.einsum("ij,ij->i", diff, diff), idx

    def _brute_indices(self, pts: np.ndarray, block_bytes: int = 64 << 20) -> np.ndarray:
        """Index of the nearest target of each query, ``argmin_j |t_j|^2 - 2 p.t_j`` with both centred on the target
        centroid: at UTM coordinates (4.5e6 m) the terms reach 2e13 m^2, which float64 holds to ~4e-3 m^2 (5 % of the
        picks were wrong, by up to 7 cm); centred, they are the size of the scan."""
        rows = max(1, block_bytes // (8 * len(self._centred)))
        out = np.empty(len(pts), dtype=np.int64)
        for start in range(0, len(pts), rows):  # loop over blocks of queries, each fully vectorized
            block = pts[start : start + rows] - self._center
            d2 = self._sq_norms[None, :] - 2.0 * (block @ self._centred.T)
            out[start : start + rows] = np.argmin(d2, axis=1)
        return out


def _open3d_nns_available() -> bool:
    try:
        import open3d.core  # noqa: F401
    except ImportError:
        return False
    return True


__all__ = ["BACKENDS", "MAX_BRUTE_FORCE_PAIRS", "NearestNeighbors", "refuse_slow_brute_force"]
