"""KLD-sampling (Fox 2003): how many particles the belief needs, from the number of occupied (x, y, theta) bins.

Fox's bound: with k occupied bins, n >= (k - 1) / (2 epsilon) * (1 - 2 / (9 (k - 1)) + sqrt(2 / (9 (k - 1))) z)^3
samples keep the KL divergence between the sample-based and the true (binned) posterior below ``epsilon``
with probability 1 - delta (``z`` = the upper 1 - delta standard normal quantile).

As in Fox (2003), k is counted on the predicted set (the particles after the motion update, before the
likelihood reweights and resampling thins them), not on the resampled set. Fox draws and predicts one
sample at a time and stops at the bound; here the whole predicted set of the last count is binned at once
(one sort of the bin keys, the number of key changes) and the next resampling draws ``bound(k)`` particles;
an oversampled set is thinned evenly and counted again (:func:`kld_sample_count`), which reaches the same
fixed point n = bound(k(n)) as Fox's loop. Only k matters, never which bins: no per-bin bookkeeping, a
handful of vector ops per step (one sort of N keys in the steady state).
"""

from __future__ import annotations

import math

import numpy as np

_EXACT_KEYS = float(1 << 53)  # float64 holds every integer below this: the most cells a packed key may tell apart

_SCALES: dict[tuple[float, float], np.ndarray] = {}


def kld_bound(k: np.ndarray | int, epsilon: float, z: float) -> np.ndarray:
    """Fox's sample count for ``k`` occupied bins (float; 1 for k <= 1; inf where it exceeds a float)."""
    k = np.asarray(k, dtype=np.float64)
    km1 = np.maximum(k - 1.0, 1.0)
    a = 2.0 / (9.0 * km1)
    with np.errstate(over="ignore"):
        n = km1 / (2.0 * epsilon) * (1.0 - a + np.sqrt(a) * z) ** 3
    return np.where(k > 1, n, 1.0)


def kld_count(k: int, epsilon: float, z: float, n_min: int, n_max: int) -> int:
    """Particles for ``k`` occupied bins: ``ceil(kld_bound(k))`` clipped to [n_min, n_max] (plain floats: one value)."""
    if k <= 1:
        n = 1.0
    else:
        a = 2.0 / (9.0 * (k - 1))
        base = 1.0 - a + math.sqrt(a) * z
        # compared in logs first: an absurd z or epsilon (1e200, 1e-320) overflowed the cube (OverflowError) or gave
        # inf (ceil failed) at the first resampling; a bound that large is n_max
        if base > 0 and math.log(k - 1) - math.log(2.0 * epsilon) + 3.0 * math.log(base) >= math.log(n_max):
            return int(n_max)
        n = (k - 1) / (2.0 * epsilon) * base ** 3
    return int(min(max(math.ceil(n - 1e-9), n_min), n_max))


def _scale(bin_m: float, bin_rad: float) -> np.ndarray:
    key = (float(bin_m), float(bin_rad))
    s = _SCALES.get(key)
    if s is None:
        if len(_SCALES) > 32:
            _SCALES.clear()
        s = _SCALES[key] = np.array([[1.0 / bin_m], [1.0 / bin_m], [1.0 / bin_rad]])
    return s


def bin_keys(states: np.ndarray, bin_m: float, bin_rad: float) -> np.ndarray:
    """Bin key ``(N,)`` float64 of every particle: one integer-valued number per (x, y, theta) cell (only compared).

    Headings are binned as stored (the filter wraps them every few steps): a wrap moves a particle to another cell
    like crossing a border would. Keys are relative to the set's own lowest cell, so they compare within one call only.
    """
    cells = np.multiply(states, _scale(bin_m, bin_rad))  # float64 (3, N)
    return _cell_keys(cells)


def _cell_keys(cells: np.ndarray) -> np.ndarray:
    """Keys ``(N,)`` of the cells ``(3, N)`` float64 (positions in bin units; floored in place), distinct per cell.

    Mixed radix over the box the set spans: key = x * (ny * nt) + y * nt + theta, distinct for distinct cells of the
    box, exact in float64 while the sum of |terms| stays below 2^53 (else counted from the box's lowest cell). Packed
    with fixed strides (x * 2^40 + y * 2^20 + theta), cells past 2^12 bins from the origin (2 km at 0.5 m) shared keys:
    the same cloud 100 km out counted 2183 bins instead of 26192. A box of 2^53 cells or more (no map at any sensible
    bin size) is numbered by np.unique, exact but slower.
    """
    np.floor(cells, out=cells)
    lo = cells.min(axis=1)
    (x0, y0, t0), (x1, y1, t1) = lo.tolist(), cells.max(axis=1).tolist()
    ny, nt = y1 - y0 + 1.0, t1 - t0 + 1.0
    if (x1 - x0 + 1.0) * ny * nt >= _EXACT_KEYS:
        return np.unique(cells, axis=1, return_inverse=True)[1].reshape(-1).astype(np.float64)
    if ny * nt * max(-x0, x1) + nt * max(-y0, y1) + max(-t0, t1) >= _EXACT_KEYS:  # far out: count from the lowest cell
        cells -= lo[:, None]
    return np.array([ny * nt, nt, 1.0]) @ cells


def occupied_bins(states: np.ndarray, bin_m: float, bin_rad: float) -> int:
    """Number of distinct (x, y, theta) bins among the particles ``(3, N)`` (sorted keys, count of changes)."""
    if states.shape[1] == 0:
        return 0
    keys = bin_keys(states, bin_m, bin_rad)
    keys.sort()
    return int(np.count_nonzero(keys[1:] != keys[:-1])) + 1


def bins_and_spread(states: np.ndarray, weights: np.ndarray, bin_m: float, bin_rad: float) -> tuple[int, float]:
    """(occupied bins of ``states`` ``(3, N)``, weighted RMS position spread [m]) from one pass over the cells.

    The spread (sqrt of var x + var y under ``weights``) is taken on the positions in bin units (float64)
    before they are floored into keys, so the convergence test costs two matrix-vector products.
    """
    cells = np.multiply(states, _scale(bin_m, bin_rad))  # float64 (3, N): positions in bins
    xy = cells[:2]
    w = weights.astype(np.float64)
    total = float(w.sum())  # ~1 (float32 weights): divided out exactly
    mx, my = (xy @ w).tolist()
    sx, sy = ((xy * xy) @ w).tolist()
    var = (sx + sy) / total - (mx * mx + my * my) / (total * total)
    keys = _cell_keys(cells)
    keys.sort()
    return int(np.count_nonzero(keys[1:] != keys[:-1])) + 1, bin_m * math.sqrt(max(var, 0.0))


def kld_sample_count(
    states: np.ndarray, k: int, *, epsilon: float, z: float, bin_m: float, bin_rad: float, n_min: int, n_max: int, rounds: int = 3
) -> tuple[int, int]:
    """(particle count, occupied bins it rests on) for the predicted set ``states`` ``(3, N)`` occupying ``k`` bins.

    n = bound(k(N)). If that is well below N the set is oversampled and k(N) overstates what n particles would
    occupy: k is counted again on n evenly spaced particles of the set (a fair subsample whatever the order)
    and n = bound(k(n)), up to ``rounds`` times: the fixed point n = bound(k(n)) that Fox's one-at-a-time loop
    stops at, in a few sorts (only while the count shrinks). A set that is too small grows to bound(k(N)) at
    once. The result is clipped to [n_min, n_max].
    """
    size = states.shape[1]
    n = kld_count(k, epsilon, z, 1, n_max)
    sub = states
    for _ in range(rounds):
        if n <= n_min or n >= 0.8 * size:
            break
        sub = sub[:, (np.arange(n) * (size / n)).astype(np.int64)]  # n evenly spaced particles
        size = n
        k = occupied_bins(sub, bin_m, bin_rad)
        n = kld_count(k, epsilon, z, 1, n_max)
    return min(max(n, n_min), n_max), k


__all__ = ["bin_keys", "bins_and_spread", "kld_bound", "kld_count", "kld_sample_count", "occupied_bins"]
