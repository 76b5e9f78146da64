"""What the NIS of a run on recorded readings says about Q, and a maximum-likelihood Q from the innovations.

Each reading's innovation nu (the particle set's mean residual) is modelled as N(0, P + Q), with P the
particle set's own predictive spread of that reading. The NIS nu^T (P + Q)^-1 nu of a consistent filter is
chi-square(2): mean 2. :func:`q_verdict` turns the NIS mean into one sentence ("Q too large by about
k x", k = 2 / NIS mean, the ML scale of the innovation covariance), or none for a run that lost track. :func:`fit_q` maximizes the
innovations' likelihood over a diagonal Q (range and bearing variances: the best of a log grid of starts, polished by
L-BFGS-B in log space). The fit holds P fixed, but the filter run again with another Q has another P (with Q far too
large the cloud is so wide that the fit to its P is far too small a Q, or the floor where P alone over-explains the
innovations), so :func:`lidarkit.pf.protocol.fit_q_recorded` iterates fit and re-run, scaling Q by the ML scale when
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
START_GRID_POINTS = 13  # per axis over Q_VARIANCE_BOUNDS: one start a decade
#: A run lost on more than this share of its steps says nothing about Q: its innovations are localization error.
#: (50 particles from a uniform start: lost on 308 of 331 steps, read as "Q too small by 15x" and fitted to a range std
#: of 5.2 m; the true residual std is ~0.1 m. The distance to dead reckoning is no test: on a log whose odometry drifts,
#: a localized filter is far from it.) The steps before the filter first passes the gate are its initial convergence
#: (a uniform start), not lost track: they are left out of this share and of the NIS (2000 particles from a uniform start
#: failed the gate on steps 1-4 and once after, and got no verdict for "5 of 331 steps").
LOST_SHARE_MAX = 0.01


def _neg_log_likelihood(log_q: np.ndarray, nu: np.ndarray, P: np.ndarray) -> float:
    """-log L (without the constant) of innovations ``(M, 2)`` under N(0, P + diag(exp(log_q)))."""
    return float(_neg_log_likelihood_many(np.reshape(log_q, (1, 2)), nu, P)[0])


def _neg_log_likelihood_many(log_q: np.ndarray, nu: np.ndarray, P: np.ndarray,
                             with_gradient: bool = False) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """-log L of every candidate ``log_q`` ``(G, 2)`` at once ``(G,)``; with its gradient over log q ``(G, 2)``."""
    q = np.exp(log_q)
    a = P[None, :, 0, 0] + q[:, :1]
    d = P[None, :, 1, 1] + q[:, 1:]
    b = P[None, :, 0, 1]
    det = a * d - b * b
    w0 = (d * nu[:, 0] - b * nu[:, 1]) / det  # (P + Q)^-1 nu
    w1 = (a * nu[:, 1] - b * nu[:, 0]) / det
    value = 0.5 * np.sum(np.log(det) + w0 * nu[:, 0] + w1 * nu[:, 1], axis=1)
    if not with_gradient:
        return value
    # d/dq_i of log det is (P + Q)^-1_ii, of the quadratic form -w_i^2; times q_i for log q
    gradient = 0.5 * q * np.stack([np.sum(d / det - w0 * w0, axis=1), np.sum(a / det - w1 * w1, axis=1)], axis=1)
    return value, gradient


def _start_candidates(nu: np.ndarray, P: np.ndarray, q0: np.ndarray | None) -> np.ndarray:
    """Log-variance starts ``(G, 2)``: a log grid per axis over the search range (the likelihood is flat towards the floor
    where P dominates, so a descent from one start stopped there, 66 nats short of the maximum), the moment estimate
    var(nu) - mean P, the innovations' own variance and ``q0``; each at least the floor."""
    lo, hi = np.log(Q_VARIANCE_BOUNDS)
    axis = np.linspace(lo, hi, START_GRID_POINTS)
    grid = np.stack(np.meshgrid(axis, axis, indexing="ij"), axis=-1).reshape(-1, 2)
    moments = nu.var(axis=0) - np.diagonal(P, axis1=1, axis2=2).mean(axis=0)
    extra = [np.log(np.maximum(moments, Q_VARIANCE_BOUNDS[0])), np.log(np.maximum(nu.var(axis=0), Q_VARIANCE_BOUNDS[0]))]
    if q0 is not None:
        extra.append(np.log(np.maximum(np.diag(q0), Q_VARIANCE_BOUNDS[0])))
    return np.clip(np.vstack([grid, *extra]), lo, hi)


def fit_q(innovations: np.ndarray, spread: np.ndarray, q0: np.ndarray | None = None) -> np.ndarray:
    """Maximum-likelihood diagonal Q ``(2, 2)`` for innovations ``(M, 2)`` with predictive spreads ``(M, 2, 2)``: the best
    of :func:`_start_candidates`, polished by L-BFGS-B; ``q0`` (a Q) is one of the starts. A variance is at the search
    floor only when the floor's likelihood beats every interior candidate."""
    nu = np.asarray(innovations, dtype=np.float64).reshape(-1, 2)
    P = np.asarray(spread, dtype=np.float64).reshape(-1, 2, 2)
    if len(nu) < 2 or len(P) != len(nu) or not (np.isfinite(nu).all() and np.isfinite(P).all()):
        raise EvaluationError(f"need >= 2 finite innovations with matching spreads, got {len(nu)} and {len(P)}", source="fit_q")
    starts = _start_candidates(nu, P, None if q0 is None else np.asarray(q0, dtype=np.float64))
    values = _neg_log_likelihood_many(starts, nu, P)
    lo, hi = np.log(Q_VARIANCE_BOUNDS)
    interior = (starts > lo).all(axis=1)
    # the best start may lie on the floor's flat stretch (the other variance a decade off its best), where a step gains
    # < 1e-5 nats (L-BFGS-B's default ftol stopped there): tolerances near float precision, and the best start with no
    # variance at the floor is polished too, the floor kept only if it does better
    picks = {int(np.nanargmin(values))}
    if interior.any():
        picks.add(int(np.flatnonzero(interior)[np.nanargmin(values[interior])]))

    def objective(log_q: np.ndarray) -> tuple[float, np.ndarray]:
        value, gradient = _neg_log_likelihood_many(log_q[None], nu, P, with_gradient=True)
        return float(value[0]), gradient[0]

    best_x, best_value, message = None, np.inf, "no finite likelihood"
    for i in sorted(picks):
        res = minimize(objective, starts[i], jac=True, method="L-BFGS-B", bounds=[(lo, hi)] * 2,
                       options={"ftol": 1e-15, "gtol": 1e-9})
        x, value = (res.x, res.fun) if np.isfinite(res.fun) and res.fun <= values[i] else (starts[i], values[i])
        if value < best_value:
            best_x, best_value, message = x, value, res.message
    q = np.exp(best_x) if best_x is not None else np.full(2, np.nan)
    if not np.isfinite(q).all() or (q <= 0).any():
        raise EvaluationError(f"Q fit did not converge ({message})", source="fit_q")
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
