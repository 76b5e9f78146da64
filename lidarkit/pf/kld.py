"""KLD-sampling (Fox 2003): how many particles the current belief needs, from the occupied (x, y, theta) bins.

Fox's bound: with k occupied bins, n >= (k - 1) / (2 epsilon) * (1 - 2 / (9 (k - 1)) + sqrt(2 / (9 (k - 1))) z)^3
samples keep the KL divergence between the sample-based and the true (binned) posterior below ``epsilon``
with probability 1 - delta (``z`` = the upper 1 - delta standard normal quantile). As in Fox's algorithm
(and AMCL), k is counted on the resampled set while it is drawn: ancestors are drawn multinomially
in chunks, the number of distinct bins of every prefix follows from the bins' first occurrences,
and the size is the first prefix length that meets the bound. All of it vectorized over the draws.
"""

from __future__ import annotations

import numpy as np

from lidarkit.pf.resampling import multinomial

DENSE_ID_LIMIT = 1 << 22  # bins in the particles' bounding box above which the ids are made dense by sorting


def kld_bound(k: np.ndarray | int, epsilon: float, z: float) -> np.ndarray:
    """Fox's sample count for ``k`` occupied bins (float; 1 for k <= 1)."""
    k = np.asarray(k, dtype=np.float64)
    km1 = np.maximum(k - 1.0, 1.0)
    a = 2.0 / (9.0 * km1)
    n = km1 / (2.0 * epsilon) * (1.0 - a + np.sqrt(a) * z) ** 3
    return np.where(k > 1, n, 1.0)


def bin_ids(states: np.ndarray, bin_m: float, bin_rad: float) -> tuple[np.ndarray, int]:
    """Dense bin number ``(N,)`` int64 of every particle (``states`` ``(3, N)``) and the size of the id range.

    Bins are ``bin_m`` x ``bin_m`` x ``bin_rad`` cells; ids index the box spanned by the particles (no sort).
    """
    x, y, theta = states
    ix = np.floor(x * (1.0 / bin_m)).astype(np.int64)
    iy = np.floor(y * (1.0 / bin_m)).astype(np.int64)
    n_theta = max(1, int(np.ceil(2.0 * np.pi / bin_rad)))
    it = np.floor((theta % (2.0 * np.pi)) * (n_theta / (2.0 * np.pi))).astype(np.int64)
    np.minimum(it, n_theta - 1, out=it)  # float rounding at exactly 2 pi
    ix -= ix.min()
    iy -= iy.min()
    ny = int(iy.max()) + 1
    n_ids = (int(ix.max()) + 1) * ny * n_theta
    if n_ids > DENSE_ID_LIMIT:  # particles spread very far: number the occupied bins by sorting instead
        _, ids = np.unique(np.stack([ix, iy, it]), axis=1, return_inverse=True)
        ids = ids.reshape(-1)
        return ids, int(ids.max()) + 1
    return (ix * ny + iy) * n_theta + it, n_ids


def kld_sample_size(
    states: np.ndarray,
    weights: np.ndarray,
    rng: np.random.Generator,
    *,
    epsilon: float,
    z: float,
    bin_m: float,
    bin_rad: float,
    n_min: int,
    n_max: int,
) -> tuple[int, int]:
    """(particle count, occupied bins k at that count) for resampling the weighted set ``states`` ``(3, N)``.

    Ancestors are drawn multinomially in chunks (first ``max(n_min, N)``, doubling up to ``n_max``) until a
    prefix of the draw satisfies Fox's bound; the count is that prefix length clipped to [n_min, n_max].
    """
    ids, n_ids = bin_ids(states, bin_m, bin_rad)
    seen: np.ndarray | None = None
    starts = np.zeros(0, dtype=np.int64)  # sorted draw positions where bin number 1, 2, ... first appears
    total = 0
    chunk = min(n_max, max(n_min, weights.shape[0]))
    while True:
        b = ids[multinomial(weights, rng, chunk)]
        bins, first = np.unique(b, return_index=True)  # first occurrence of every bin in this chunk
        if total == 0:
            fresh_first = first
        else:  # keep only bins not seen in the earlier chunks
            if seen is None:
                seen = np.zeros(n_ids, dtype=bool)
                seen[ids_drawn] = True
            fresh = ~seen[bins]
            fresh_first = first[fresh]
        ids_drawn = bins if total == 0 else np.union1d(ids_drawn, bins)
        if seen is not None:
            seen[bins] = True
        starts = np.concatenate([starts, np.sort(fresh_first) + total])
        total += chunk
        n = _first_feasible(starts, total, epsilon, z, n_min)
        if n is not None:
            return n, int(np.searchsorted(starts, n - 1, side="right"))
        if total >= n_max:
            return n_max, len(starts)
        chunk = min(n_max - total, total)


def _first_feasible(starts: np.ndarray, total: int, epsilon: float, z: float, n_min: int) -> int | None:
    """Smallest n <= ``total`` with n >= max(n_min, bound(k(n))), where k(n) = #starts < n; None if there is none.

    k(n) = j on the interval starts[j-1] < n - 1 + 1 <= starts[j] (the j-th bin appears at position
    starts[j-1]), so one candidate per j: max(starts[j-1] + 1, bound(j), n_min) if it is still in the interval.
    """
    j = np.arange(1, len(starts) + 1)
    lower = np.maximum(np.maximum(starts + 1, np.ceil(kld_bound(j, epsilon, z))), n_min)
    upper = np.empty(len(starts), dtype=np.int64)
    upper[:-1] = starts[1:]  # n - 1 < starts[j] keeps k(n) = j
    upper[-1] = total
    ok = lower <= upper
    if not ok.any():
        return None
    return int(lower[np.argmax(ok)])


__all__ = ["bin_ids", "kld_bound", "kld_sample_size"]
