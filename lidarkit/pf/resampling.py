"""Resampling schemes: each maps normalized weights ``(N,)`` to ``n`` ancestor indices ``(n,)`` int64.

All are unbiased (E[count_i] = n w_i). Variance of the counts: multinomial n w_i (1 - w_i); residual and
stratified are never worse; systematic keeps every count at floor or ceil of n w_i.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from lidarkit.errors import ConfigError, DataError

Resampler = Callable[[np.ndarray, np.random.Generator, "int | None"], np.ndarray]


def effective_sample_size(weights: np.ndarray) -> float:
    """Kish ESS ``(sum w)^2 / sum(w^2)`` of weights ``(N,)`` (N for uniform, 1 for a single particle; normalized or not).
    Array-likes are taken; weights that are not finite, >= 0 and not all zero raise DataError (a list was an
    AttributeError, an empty array inf with a warning, negative weights a number)."""
    try:
        w = np.asarray(weights, dtype=np.float64)
    except (TypeError, ValueError):  # text, ragged rows
        raise DataError(f"weights must be numbers, got {weights!r}", source="weights") from None
    total = _check_weights(w, "the effective sample size")
    return total * total / float(np.dot(w, w))


def ess_of_normalized(weights: np.ndarray) -> float:
    """``1 / sum(w^2)`` of weights ``(N,)`` the filter keeps normalized, unchecked: its ESS test at every step."""
    if weights.shape[0] <= 16384:  # single-threaded BLAS dot is fastest here
        return float(1.0 / np.dot(weights, weights))
    # multiply + sum, not np.dot: BLAS thread start-up dominates for large N on a busy machine
    return float(1.0 / np.add.reduce(weights * weights))


def _check_weights(weights: np.ndarray, needed_by: str = "resampling") -> float:
    """The weights' sum; DataError unless they are an (N,) array of finite values >= 0, not all zero (one reduction
    each)."""
    if weights.ndim != 1 or weights.shape[0] == 0:  # (an empty array failed in numpy's min)
        raise DataError(f"{needed_by} needs weights of shape (N,) with N >= 1, got shape {weights.shape}", source="weights")
    total = float(np.sum(weights, dtype=np.float64))
    if not (np.isfinite(total) and total > 0.0) or float(np.min(weights)) < 0.0:
        raise DataError(f"{needed_by} needs finite weights >= 0 that are not all zero (sum {total:g}, smallest "
                        f"{float(np.min(weights)):g})", source="weights")
    return total


def _scaled_cdf(weights: np.ndarray, n: int) -> np.ndarray:
    _check_weights(weights)
    cdf = np.cumsum(weights, dtype=np.float64)
    cdf *= n / cdf[-1]
    cdf[-1] = n  # exact, whatever the rounding
    return cdf


_ARANGE_CACHE: dict[int, np.ndarray] = {}


def _arange(n: int) -> np.ndarray:
    a = _ARANGE_CACHE.get(n)
    if a is None:
        if len(_ARANGE_CACHE) > 16:
            _ARANGE_CACHE.clear()
        a = _ARANGE_CACHE[n] = np.arange(n)
        a.flags.writeable = False
    return a


def _indices_from_counts(counts: np.ndarray) -> np.ndarray:
    return np.repeat(_arange(counts.shape[0]), counts)


def multinomial(weights: np.ndarray, rng: np.random.Generator, n: int | None = None) -> np.ndarray:
    """n independent draws from the categorical distribution ``weights``."""
    weights = np.asarray(weights)  # (a list: an AttributeError; O(1) for the filter's arrays)
    n = weights.shape[0] if n is None else n
    cdf = _scaled_cdf(weights, n)
    idx = np.searchsorted(cdf, rng.random(n) * n, side="right")
    return np.minimum(idx, weights.shape[0] - 1)


def systematic(weights: np.ndarray, rng: np.random.Generator, n: int | None = None) -> np.ndarray:
    """One uniform offset, n evenly spaced pointers; counts computed from the scaled CDF (no search)."""
    weights = np.asarray(weights)  # (a list: an AttributeError; O(1) for the filter's arrays)
    n = weights.shape[0] if n is None else n
    cdf = _scaled_cdf(weights, n)
    u0 = rng.random() or 0.5 / n  # u0 in (0, 1)
    # number of pointers u0 + k (k = 0..n-1) at or below each cdf value: floor(cdf - u0) + 1, in [0, n]
    cdf -= u0
    np.floor(cdf, out=cdf)
    cdf += 1.0
    np.minimum(cdf, n, out=cdf)
    below = cdf.astype(np.int64)
    counts = np.empty_like(below)
    counts[0] = below[0]
    np.subtract(below[1:], below[:-1], out=counts[1:])
    return _indices_from_counts(counts)


def stratified(weights: np.ndarray, rng: np.random.Generator, n: int | None = None) -> np.ndarray:
    """One independent uniform pointer in each of the n strata [k, k+1)."""
    weights = np.asarray(weights)  # (a list: an AttributeError; O(1) for the filter's arrays)
    n = weights.shape[0] if n is None else n
    cdf = _scaled_cdf(weights, n)
    pointers = rng.random(n)
    pointers += np.arange(n)
    idx = np.searchsorted(cdf, pointers, side="right")
    return np.minimum(idx, weights.shape[0] - 1)


def residual(weights: np.ndarray, rng: np.random.Generator, n: int | None = None) -> np.ndarray:
    """floor(n w_i) deterministic copies, the remainder drawn multinomially from the residual weights."""
    weights = np.asarray(weights, dtype=np.float64)
    n = weights.shape[0] if n is None else n
    scaled = weights * (n / _check_weights(weights))
    counts = np.floor(scaled).astype(np.int64)
    remainder = n - int(counts.sum())
    if remainder > 0:
        resid = scaled - counts
        resid /= resid.sum()
        counts += np.bincount(multinomial(resid, rng, remainder), minlength=weights.shape[0])
    return _indices_from_counts(counts)


_RESAMPLERS: dict[str, Resampler] = {
    "multinomial": multinomial,
    "systematic": systematic,
    "stratified": stratified,
    "residual": residual,
}


def available_resamplers() -> list[str]:
    """Names accepted by :func:`get_resampler`."""
    return list(_RESAMPLERS)


def get_resampler(name: str) -> Resampler:
    """The resampling function registered as ``name``; unknown names list the known ones."""
    try:
        return _RESAMPLERS[name]
    except KeyError:
        raise ConfigError(f"unknown resampler {name!r}; known: {', '.join(_RESAMPLERS)}", source="resampler") from None


__all__ = [
    "available_resamplers",
    "effective_sample_size",
    "get_resampler",
    "multinomial",
    "residual",
    "stratified",
    "systematic",
]
