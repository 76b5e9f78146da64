"""What the NIS of a run on recorded readings says about Q, and a maximum-likelihood Q from the innovations.

Each reading's innovation nu (the particle set's mean residual) is modelled as N(0, P + Q), with P the
particle set's own predictive spread of that reading. The NIS nu^T (P + Q)^-1 nu of a consistent filter is
chi-square(2): mean 2. :func:`q_verdict` turns the NIS mean into one sentence ("Q too large by about
k x", k = 2 / NIS mean, the ML scale of the innovation covariance), or none for a run that lost track. :func:`fit_q` maximizes the
innovations' likelihood over a diagonal Q (range and bearing variances, L-BFGS-B in log space). The fit
holds P fixed, but the filter run again with another Q has another P (with Q far too large the cloud is
so wide that P alone over-explains the innovations and the fit hits its floor), so
:func:`lidarkit.pf.protocol.fit_q_recorded` iterates fit and re-run, scaling Q by the ML scale when
the fit is at its floor.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize

from lidarkit.errors import EvaluationError

NIS_EXPECTED_MEAN = 2.0
NIS_CONSISTENT = (1.5, 2.5)  # NIS means read as "consistent"
Q_VARIANCE_BOUNDS = (1e-8, 1e4)  # search range of each fitted variance
#: A run lost on more than this share of its steps says nothing about Q: its innovations are localization error.
#: (50 particles from a uniform start: lost on 308 of 331 steps, read as "Q too small by 15x" and fitted to a range std
#: of 5.2 m; the true residual std is ~0.1 m. The distance to dead reckoning is no test: on a log whose odometry drifts,
#: a localized filter is far from it.) The steps before the filter first passes the gate are its initial convergence
#: (a uniform start), not lost track: they are left out of this share and of the NIS (2000 particles from a uniform start
#: failed the gate on steps 1-4 and once after, and got no verdict for "5 of 331 steps").
LOST_SHARE_MAX = 0.01


def _neg_log_likelihood(log_q: np.ndarray, nu: np.ndarray, P: np.ndarray) -> float:
    """-log L (without the constant) of innovations ``(M, 2)`` under N(0, P + diag(exp(log_q)))."""
    q = np.exp(log_q)
    a, d, b = P[:, 0, 0] + q[0], P[:, 1, 1] + q[1], P[:, 0, 1]
    det = a * d - b * b
    quad = (d * nu[:, 0] ** 2 - 2.0 * b * nu[:, 0] * nu[:, 1] + a * nu[:, 1] ** 2) / det
    return float(0.5 * np.sum(np.log(det) + quad))


def fit_q(innovations: np.ndarray, spread: np.ndarray, q0: np.ndarray | None = None) -> np.ndarray:
    """Maximum-likelihood diagonal Q ``(2, 2)`` for innovations ``(M, 2)`` with predictive spreads ``(M, 2, 2)``."""
    nu = np.asarray(innovations, dtype=np.float64).reshape(-1, 2)
    P = np.asarray(spread, dtype=np.float64).reshape(-1, 2, 2)
    if len(nu) < 2 or len(P) != len(nu) or not (np.isfinite(nu).all() and np.isfinite(P).all()):
        raise EvaluationError(f"need >= 2 finite innovations with matching spreads, got {len(nu)} and {len(P)}", source="fit_q")
    start = np.log(np.maximum(nu.var(axis=0), 1e-12)) if q0 is None else np.log(np.diag(np.asarray(q0, dtype=np.float64)))
    lo, hi = np.log(Q_VARIANCE_BOUNDS)
    res = minimize(_neg_log_likelihood, np.clip(start, lo, hi), args=(nu, P), method="L-BFGS-B", bounds=[(lo, hi)] * 2)
    q = np.exp(res.x)
    if not np.isfinite(q).all() or (q <= 0).any():
        raise EvaluationError(f"Q fit did not converge ({res.message})", source="fit_q")
    return np.diag(q)


def at_lower_bound(q_fit: np.ndarray) -> bool:
    """True when a fitted variance sits at the search floor: the particle spread alone over-explains the innovations."""
    return bool((np.diag(q_fit) <= Q_VARIANCE_BOUNDS[0] * 1.01).any())


def scale_fit(nis_mean: float) -> float:
    """ML factor c of the innovation covariance (nu ~ N(0, c S) for 2-D readings): NIS mean / 2."""
    return nis_mean / NIS_EXPECTED_MEAN


@dataclass(frozen=True)
class QVerdict:
    """``status`` is "consistent", "too large", "too small" or "lost" (no verdict, ``factor`` None); ``factor`` = 2 / NIS mean or NIS mean / 2 (the ML
    scale of the innovation covariance, which is Q's factor where Q dominates it); ``text`` is the sentence to print."""

    status: str
    factor: float | None
    nis_mean: float
    text: str


def localization_problem(n_lost: int, n_steps: int, from_step: int = 1) -> str | None:
    """Why a run's NIS cannot judge Q (it lost track, see LOST_SHARE_MAX), or None; ``n_lost`` of the ``n_steps`` counted
    from ``from_step``, the step the filter first converged at (1: from the start)."""
    if n_lost > LOST_SHARE_MAX * n_steps:
        after = f" from step {from_step}, after it first converged" if from_step > 1 else ""
        return f"the filter lost track on {n_lost} of {n_steps} steps{after}"
    return None


def _times(k: float) -> str:
    return f"{k:.0f}x" if k >= 10 else f"{k:.1f}x"


def q_verdict(nis_mean: float, q_cov: np.ndarray, q_fit: np.ndarray | None = None, lost: str | None = None,
              nis_from_step: int | None = None) -> QVerdict:
    """Read the NIS mean (chi-square(2) expects 2) of a run with ``q_cov``; ``q_fit`` (ML, same run) is quoted if usable.
    ``lost`` (see :func:`localization_problem`): no verdict, status "lost" and factor None. ``nis_from_step``: the NIS
    leaves out the steps before it (the filter's initial convergence), and the text says so."""
    q = np.diag(np.asarray(q_cov, dtype=np.float64))
    detail = f"NIS mean {nis_mean:.3f}, chi-square(2) expects {NIS_EXPECTED_MEAN:.1f}"
    if lost:  # (its reason names the step the count starts at)
        return QVerdict("lost", None, nis_mean, f"no verdict on Q: {lost}, so the NIS ({detail}) reflects localization "
                                                 "error, not Q")
    if nis_from_step is not None and nis_from_step > 1:
        detail = f"NIS from step {nis_from_step}, after the filter first converged: {detail}"
    if q_fit is not None and not at_lower_bound(q_fit):
        f = np.diag(np.asarray(q_fit, dtype=np.float64))
        detail += f"; ML fit on these innovations: range variance {f[0]:.3g} (used {q[0]:.3g}), bearing variance {f[1]:.3g} (used {q[1]:.3g})"
    lo, hi = NIS_CONSISTENT
    if lo <= nis_mean <= hi:
        return QVerdict("consistent", 1.0, nis_mean, f"Q consistent with the readings ({detail})")
    if nis_mean < lo:
        k = 1.0 / max(scale_fit(nis_mean), 1e-12)
        return QVerdict("too large", k, nis_mean, f"Q too large by about {_times(k)} ({detail}); --fit-q estimates Q")
    k = scale_fit(nis_mean)
    return QVerdict("too small", k, nis_mean, f"Q too small by about {_times(k)} ({detail}); --fit-q estimates Q")


__all__ = ["LOST_SHARE_MAX", "NIS_CONSISTENT", "NIS_EXPECTED_MEAN", "QVerdict", "at_lower_bound", "fit_q",
           "localization_problem", "q_verdict", "scale_fit"]
