"""Learning a variant's covariance calibration from training draws (used by ``covariance_calibration.py``).

A run is a dict of per-draw arrays: ``errors`` ``(n, 6)`` (true error, left/target-frame convention), ``covs``
``(n, 6, 6)`` (the raw closed form) and ``steps`` ``(n, 6)`` (the result's point-to-surface step). The learned
:class:`~lidarkit.registration.covariance.AxisCalibration` models the second moment of the error as
``c (S Sigma S + diag(b^2) + |step_t|^2 diag(h^2) + (g * step)(g * step)^T)``:

1. step gains ``g``: per axis, the regression (through the origin) of the error on the step, kept where their pooled
   correlation is at least ``STEP_MIN_CORRELATION`` (elsewhere the step is noise and would only widen the bound);
2. factor ``f``, floor ``b`` and step spread ``h`` per axis on what the step leaves (``xi - g * step``); ``h`` only
   where the step term is used (``g`` not all zero);
3. one coverage scalar ``c`` on the pooled training NEES.
"""

from __future__ import annotations

import numpy as np

from lidarkit.registration.covariance import AxisCalibration, apply_calibration, nees, principal_turn

CHI2_6_95 = 12.5916

#: the fitted factor of an axis is at least this share of the plain ratio mean(xi^2) / mean(Sigma): a weak direction
#: (a corridor's axis) keeps most of its large variance instead of being replaced by the constant floor
MIN_SCALE_SHARE = 0.25
#: the coverage scalar puts this share of the pooled training errors inside the 95 % bound ...
TARGET_INSIDE = 0.945
#: ... unless that pushes their mean NEES below this (heavy-tailed NEES: kiss, genz), then it puts the mean here
MIN_MEAN_NEES = 5.0
#: the axes the calibration is learned in (``AxisCalibration.axes``): a street's own, however it runs in the frame
AXES = "principal"
#: an axis's step gain is used when the step and the error correlate at least this much on the pooled training draws
STEP_MIN_CORRELATION = 0.5


def _steps(run: dict) -> np.ndarray:
    """The run's steps, NaN where a cache has none (a step-free calibration then)."""
    steps = run.get("steps")
    return np.full_like(run["errors"], np.nan) if steps is None or len(steps) != len(run["errors"]) else steps


def step_gains(runs: list[dict]) -> tuple[np.ndarray | None, np.ndarray]:
    """``(gains or None, correlation)`` per axis of the error with the point-to-surface step over the pooled draws."""
    errors = np.concatenate([r["errors"] for r in runs])
    steps = np.concatenate([_steps(r) for r in runs])
    ok = np.isfinite(steps).all(axis=1)
    corr, gains = np.zeros(6), np.zeros(6)
    if ok.sum() < 10:
        return None, corr
    e, s = errors[ok], steps[ok]
    for j in range(6):
        if s[:, j].std() > 0 and e[:, j].std() > 0:
            corr[j] = float(np.corrcoef(s[:, j], e[:, j])[0, 1])
            gains[j] = float(s[:, j] @ e[:, j] / (s[:, j] @ s[:, j]))
    gains = np.where(corr >= STEP_MIN_CORRELATION, gains, 0.0)
    return (gains if gains.any() else None), corr


def residual_runs(runs: list[dict], gains: np.ndarray | None) -> list[dict]:
    """``runs`` with the part of the error the step predicts taken out (unchanged where a step is missing)."""
    if gains is None:
        return runs
    return [{**r, "errors": r["errors"] - np.nan_to_num(gains * _steps(r))} for r in runs]


def axis_calibration(runs: list[dict], spread: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Per axis ``(factor f_j, systematic sigma b_j, step spread h_j)`` with
    ``E[xi_j^2 | Sigma_jj, step] = f_j Sigma_jj + b_j^2 + h_j^2 |step_t|^2`` over the pooled draws (bounded least
    squares on the standardised variances); ``h`` None unless ``spread``."""
    from scipy.optimize import lsq_linear

    errors = np.concatenate([r["errors"] for r in runs])
    var = np.concatenate([np.einsum("nii->ni", r["covs"]) for r in runs])
    step2 = np.concatenate([(np.nan_to_num(_steps(r))[:, :3] ** 2).sum(axis=1) for r in runs])
    f, b, h = np.zeros(6), np.zeros(6), np.zeros(6)
    for j in range(6):
        unit = var[:, j].mean()
        y = errors[:, j] ** 2 / unit
        X = np.column_stack([var[:, j] / unit, np.ones(len(y))] + ([step2 / unit] if spread else []))
        lower = [MIN_SCALE_SHARE * y.mean()] + [0.0] * (X.shape[1] - 1)
        fit = lsq_linear(X, y, bounds=(lower, [np.inf] * X.shape[1]))
        f[j], b[j] = fit.x[0], np.sqrt(fit.x[1] * unit)
        if spread:
            h[j] = np.sqrt(fit.x[2])
    return f, b, (h if spread else None)


def block_factors(runs: list[dict]) -> np.ndarray:
    """The oldest calibration: one factor for the translation block, one for the rotation block."""
    errors = np.concatenate([r["errors"] for r in runs])
    var = np.concatenate([np.einsum("nii->ni", r["covs"]) for r in runs])
    ratio = errors**2 / var
    return np.repeat([ratio[:, :3].mean(), ratio[:, 3:].mean()], 3)


def scaled(covs: np.ndarray, factors: np.ndarray) -> np.ndarray:
    s = np.sqrt(np.asarray(factors, dtype=np.float64))
    return covs * np.outer(s, s)


def apply_all(covs: np.ndarray, entry: AxisCalibration, steps: np.ndarray | None = None) -> np.ndarray:
    steps = [None] * len(covs) if steps is None else steps
    return np.array([apply_calibration(c, entry, s) for c, s in zip(covs, steps)]).reshape(-1, 6, 6)


def nees_values(errors: np.ndarray, covs: np.ndarray) -> np.ndarray:
    return np.array([nees(e, c) for e, c in zip(errors, covs)])


def in_axes(run: dict, axes: str) -> dict:
    """``run`` with each draw's covariance, error and step turned into the calibration's ``axes`` (``"principal"``: x along
    the draw's weakest horizontal direction, :func:`~lidarkit.registration.covariance.principal_turn`; NEES unchanged)."""
    if axes == "target" or not len(run["covs"]):
        return run
    turns = np.array([principal_turn(c) for c in run["covs"]])
    out = {**run, "covs": np.einsum("nij,njk,nlk->nil", turns, run["covs"], turns), "errors": np.einsum("nij,nj->ni", turns, run["errors"])}
    if run.get("steps") is not None and len(run["steps"]) == len(run["errors"]):
        out["steps"] = np.einsum("nij,nj->ni", turns, run["steps"])
    return out


def factor_floor(runs: list[dict], use_step: bool = True, axes: str = AXES) -> AxisCalibration:
    """Step gains (``use_step``), then the per-axis factor, floor and step spread of what they leave, pooled over ``runs``
    (turned into ``axes``), with the training range of the closed-form variances; coverage 1."""
    runs = [in_axes(r, axes) for r in runs]
    gains = step_gains(runs)[0] if use_step else None
    f, b, h = axis_calibration(residual_runs(runs, gains), spread=gains is not None)
    top = np.max(np.concatenate([np.einsum("nii->ni", r["covs"]) for r in runs if len(r["covs"])]), axis=0)
    return AxisCalibration(tuple(f.tolist()), tuple(b.tolist()), 1.0, tuple(top.tolist()),
                           None if gains is None else tuple(gains.tolist()), None if h is None else tuple(h.tolist()), axes)


def calibrated_nees(run: dict, entry: AxisCalibration) -> np.ndarray:
    return nees_values(run["errors"], apply_all(run["covs"], entry, _steps(run)))


def fit_calibration(runs: list[dict], use_step: bool = True, axes: str = AXES) -> tuple[AxisCalibration, dict]:
    """:func:`factor_floor` pooled over all training runs (seeds), then the coverage scalar from the pooled training
    NEES. Also the leave-one-seed-out NEES (each seed scored with the calibration learned on the others), the
    training-side estimate of how the calibration does on a scene it has not seen."""
    base = factor_floor(runs, use_step, axes)
    pooled = np.concatenate([calibrated_nees(r, base) for r in runs])
    c = min(float(np.quantile(pooled, TARGET_INSIDE)) / CHI2_6_95, float(pooled.mean()) / MIN_MEAN_NEES)
    entry = AxisCalibration(base.factors, base.sigmas, c, base.trained_variance, base.step_gains, base.step_spread, axes)
    oof = np.concatenate([calibrated_nees(r, factor_floor(runs[:k] + runs[k + 1:], use_step, axes)) for k, r in enumerate(runs)]) \
        if len(runs) > 1 else pooled
    stats = lambda v: {"nees_mean": float(v.mean()), "inside_95": float((v < CHI2_6_95).mean())}  # noqa: E731
    return entry, {"pooled_before_coverage": stats(pooled), "pooled_after_coverage": stats(pooled / c),
                   "leave_one_out_after_coverage": stats(oof / c), "step_correlation": step_gains([in_axes(r, axes) for r in runs])[1].tolist()}
