"""KLD-sampling (Fox 2003): how many particles the current belief needs, from the occupied (x, y, theta) bins.

Fox's bound: with k occupied bins, n >= (k - 1) / (2 epsilon) * (1 - 2 / (9 (k - 1)) + sqrt(2 / (9 (k - 1))) z)^3
samples keep the KL divergence between the sample-based and the true (binned) posterior below ``epsilon``
with probability 1 - delta (``z`` = the upper 1 - delta standard normal quantile). As in Fox's algorithm
(and AMCL), k is counted on the resampled set while it is drawn: ancestors are drawn multinomially
in chunks, the number of distinct bins of every prefix follows from the bins' first occurrences,
and the size is the first prefix length that meets the bound. All of it vectorized over the draws.
"""

from __future__ import annotations

import math

import numpy as np

KEY_STRIDE = float(1 << 24)  # y bins per x bin in a bin key (integer-valued float64 keys stay exact)
SCALAR_K = 48  # up to this many occupied bins the bound is solved with Python floats


def kld_bound(k: np.ndarray | int, epsilon: float, z: float) -> np.ndarray:
    """Fox's sample count for ``k`` occupied bins (float; 1 for k <= 1)."""
    k = np.asarray(k, dtype=np.float64)
    km1 = np.maximum(k - 1.0, 1.0)
    a = 2.0 / (9.0 * km1)
    n = km1 / (2.0 * epsilon) * (1.0 - a + np.sqrt(a) * z) ** 3
    return np.where(k > 1, n, 1.0)


def bin_keys(states: np.ndarray, bin_m: float, bin_rad: float) -> np.ndarray:
    """Bin key ``(N,)`` float64 of every particle: one integer-valued number per (x, y, theta) cell (only compared).

    Headings are binned as stored (the filter wraps them to [-pi, pi] every few steps): cells are aligned at
    multiples of ``bin_rad`` either way, and a wrap moves a particle to another cell exactly like crossing a cell
    border would.
    """
    x, y, theta = states
    key = np.multiply(x, 1.0 / bin_m, dtype=np.float64)
    np.floor(key, out=key)
    key *= KEY_STRIDE
    ky = np.multiply(y, 1.0 / bin_m, dtype=np.float64)
    np.floor(ky, out=ky)
    key += ky
    key *= KEY_STRIDE
    np.multiply(theta, 1.0 / bin_rad, out=ky, dtype=np.float64)
    np.floor(ky, out=ky)
    key += ky
    return key


def _first_occurrences(b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distinct values of ``b`` and the position of each one's first occurrence (a stable sort, no np.unique overhead)."""
    order = np.argsort(b, kind="stable")
    sb = b[order]
    new = np.empty(len(b), dtype=bool)
    new[0] = True
    np.not_equal(sb[1:], sb[:-1], out=new[1:])
    return sb[new], order[new]


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
    keys = bin_keys(states, bin_m, bin_rad)
    cdf = np.cumsum(weights, dtype=np.float64)
    last = weights.shape[0] - 1
    drawn_bins: np.ndarray | None = None
    starts: list[np.ndarray] = []  # sorted draw positions where bin number 1, 2, ... first appears
    total = 0
    chunk = min(n_max, max(n_min, weights.shape[0]))
    while True:
        u = rng.random(chunk)
        u *= cdf[-1]
        anc = np.searchsorted(cdf, u, side="right")
        np.minimum(anc, last, out=anc)
        bins, first = _first_occurrences(keys[anc])  # first occurrence of every bin in this chunk
        if drawn_bins is None:
            drawn_bins, fresh_first = bins, first
        else:  # keep only bins not seen in the earlier chunks
            fresh = ~np.isin(bins, drawn_bins, assume_unique=True)
            fresh_first = first[fresh]
            drawn_bins = np.union1d(drawn_bins, bins)
        fresh_first.sort()
        starts.append(fresh_first + total if total else fresh_first)
        total += chunk
        pos = starts[0] if len(starts) == 1 else np.concatenate(starts)
        n = _first_feasible(pos, total, epsilon, z, n_min)
        if n is not None:
            return n, int(np.searchsorted(pos, n - 1, side="right"))
        if total >= n_max:
            return n_max, len(pos)
        chunk = min(n_max - total, total)


def _first_feasible(starts: np.ndarray, total: int, epsilon: float, z: float, n_min: int) -> int | None:
    """Smallest n <= ``total`` with n >= max(n_min, bound(k(n))), where k(n) = #starts < n; None if there is none.

    k(n) = j for starts[j-1] < n <= starts[j] (the j-th bin appears at position starts[j-1]), so there is one
    candidate per j: max(starts[j-1] + 1, bound(j), n_min), if it is still in that interval.
    """
    k_all = len(starts)
    if k_all <= SCALAR_K:  # converged clouds occupy few bins: plain floats beat a dozen tiny numpy calls
        pos = starts.tolist()
        for j in range(1, k_all + 1):
            lower = max(pos[j - 1] + 1, math.ceil(_bound_scalar(j, epsilon, z)), n_min)
            upper = pos[j] if j < k_all else total
            if lower <= upper:
                return int(lower)
        return None
    j = np.arange(1, k_all + 1)
    lower = np.maximum(np.maximum(starts + 1, np.ceil(kld_bound(j, epsilon, z))), n_min)
    upper = np.empty(k_all, dtype=np.int64)
    upper[:-1] = starts[1:]
    upper[-1] = total
    ok = lower <= upper
    if not ok.any():
        return None
    return int(lower[np.argmax(ok)])


def _bound_scalar(k: int, epsilon: float, z: float) -> float:
    if k <= 1:
        return 1.0
    a = 2.0 / (9.0 * (k - 1))
    return (k - 1) / (2.0 * epsilon) * (1.0 - a + math.sqrt(a) * z) ** 3


__all__ = ["bin_keys", "kld_bound", "kld_sample_size"]
