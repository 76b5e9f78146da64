"""Kalman-particle kernel filter: each particle is a Gaussian kernel (mean, 3x3 covariance) updated by an EKF.

After Pham, Dahia & Musso (2003), "A Kalman-particle kernel filter and its application to terrain
navigation". The weights follow each kernel's predictive likelihood N(z; h(mean), H P H^T + Q);
resampling splits a kernel into children drawn from N(mean, (1 - a) P) with covariance a P
(``kernel_split`` = a), which keeps the mixture's mean and covariance. Because every kernel carries
its own uncertainty, a few tens of kernels reach the accuracy of ~10^4 point particles on the
Freiburg data (see docs/particle_filter.md). Vectorized over kernels with batched 3x3 algebra;
meant for small N (memory and time grow as N x 9).
"""

from __future__ import annotations

import logging

import numpy as np

from lidarkit.errors import ConfigError, DataError
from lidarkit.pf.config import PFConfig
from lidarkit.pf.filter import check_landmark_index
from lidarkit.pf.models import resolve_q, wrap_angle
from lidarkit.pf.resampling import effective_sample_size, get_resampler

log = logging.getLogger(__name__)


class KalmanParticleFilter:
    """Same interface as :class:`lidarkit.pf.filter.ParticleFilter`; kernels are ``(3, N)`` means + ``(N, 3, 3)`` covariances."""

    def __init__(self, landmarks_xy: np.ndarray, config: PFConfig | None = None, rng: np.random.Generator | int | None = 0) -> None:
        self.config = config if config is not None else PFConfig(kernel="kalman")
        lm = np.asarray(landmarks_xy, dtype=np.float64)
        if lm.ndim != 2 or lm.shape[1] != 2 or len(lm) == 0 or not np.isfinite(lm).all():
            raise DataError(f"landmarks must be a finite (L, 2) array with L >= 1, got shape {lm.shape}", source="landmarks")
        self.landmarks_xy = lm
        self.rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        self.n = int(self.config.n_particles)
        self.split = float(self.config.kernel_split)
        if not 0.0 < self.split <= 1.0:
            raise ConfigError(f"kernel_split must be in (0, 1], got {self.split}", source="kernel_split")
        self.motion_var = np.asarray(self.config.motion_noise_std, dtype=np.float64) ** 2
        self.q_cov = resolve_q(self.config.q, self.config.q_as)
        self.resampler = get_resampler(self.config.resampler)
        self.n_updates = 0
        self.n_resamples = 0
        self.n_weight_resets = 0
        self.last_max_loglik = 0.0
        if self.config.init == "uniform":
            self.initialize_uniform()
        else:
            self.initialize_gaussian()

    # ---- initialization ---------------------------------------------------------------------------
    def initialize_gaussian(self, mean: np.ndarray | None = None, std: np.ndarray | None = None) -> None:
        """Kernel means ~ N(mean, (1 - a) S0), covariances a S0 with S0 = diag(std^2): the mixture has covariance S0."""
        mean = np.asarray(self.config.init_mean if mean is None else mean, dtype=np.float64).reshape(3)
        var = np.asarray(self.config.init_std if std is None else std, dtype=np.float64).reshape(3) ** 2
        a = self.split if self.n > 1 else 1.0
        self.states = mean[:, None] + np.sqrt((1.0 - a) * var)[:, None] * self.rng.standard_normal((3, self.n))
        self.cov = np.broadcast_to(np.diag(a * var), (self.n, 3, 3)).copy()
        self._reset_weights()

    def initialize_uniform(self, bounds_xy: tuple[float, float, float, float] | None = None) -> None:
        """Kernel means uniform over the bounds (default: landmarks +- margin), covariances of one cell of N."""
        if bounds_xy is None:
            m = self.config.uniform_margin_m
            lo, hi = self.landmarks_xy.min(axis=0) - m, self.landmarks_xy.max(axis=0) + m
            bounds_xy = (lo[0], hi[0], lo[1], hi[1])
        x0, x1, y0, y1 = (float(b) for b in bounds_xy)
        if not (x1 > x0 and y1 > y0):
            raise ConfigError(f"empty bounds {bounds_xy!r}", source="initialize_uniform")
        span = np.array([x1 - x0, y1 - y0, 2 * np.pi])
        self.states = np.array([x0, y0, -np.pi])[:, None] + self.rng.random((3, self.n)) * span[:, None]
        cell = span / np.array([np.sqrt(self.n), np.sqrt(self.n), 4.0])
        self.cov = np.broadcast_to(np.diag(cell**2 / 4.0), (self.n, 3, 3)).copy()
        self._reset_weights()

    def _reset_weights(self) -> None:
        self.weights = np.full(self.n, 1.0 / self.n)
        self.log_weights = np.full(self.n, -np.log(self.n))
        self._uniform = True

    @property
    def particles(self) -> np.ndarray:
        """``(N, 3)`` kernel means."""
        return self.states.T

    @property
    def ess(self) -> float:
        return effective_sample_size(self.weights)

    # ---- predict ------------------------------------------------------------------------------------
    def predict(self, odometry: np.ndarray, *, check: bool = True) -> None:
        """EKF prediction of every kernel through the odometry model (noise std on r1, t, r2 from the config)."""
        u = np.asarray(odometry, dtype=np.float64).reshape(-1)
        if u.shape != (3,) or not np.isfinite(u).all():
            raise DataError(f"odometry must be 3 finite values [r1, t, r2], got {u.tolist()}", source="predict")
        r1, t, r2 = u
        heading = self.states[2] + r1
        c, s = np.cos(heading), np.sin(heading)
        n = self.n
        F = np.zeros((n, 3, 3))
        F[:, 0, 0] = F[:, 1, 1] = F[:, 2, 2] = 1.0
        F[:, 0, 2] = -t * s
        F[:, 1, 2] = t * c
        J = np.zeros((n, 3, 3))  # d pose / d (r1, t, r2)
        J[:, 0, 0], J[:, 0, 1] = -t * s, c
        J[:, 1, 0], J[:, 1, 1] = t * c, s
        J[:, 2, 0] = J[:, 2, 2] = 1.0
        self.states[0] += t * c
        self.states[1] += t * s
        self.states[2] = wrap_angle(self.states[2] + r1 + r2)
        self.cov = F @ self.cov @ F.transpose(0, 2, 1) + (J * self.motion_var) @ J.transpose(0, 2, 1)

    # ---- update -------------------------------------------------------------------------------------
    def _innovation(self, lm_xy: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Residuals ``(N, 2)`` and Jacobians ``(N, 2, 3)`` of one reading; ``lm_xy`` ``(N, 2)`` or ``(2,)``."""
        lm = np.broadcast_to(lm_xy, (self.n, 2))
        dx, dy = lm[:, 0] - self.states[0], lm[:, 1] - self.states[1]
        q = np.maximum(dx * dx + dy * dy, 1e-12)
        r = np.sqrt(q)
        e = np.stack([z[0] - r, wrap_angle(z[1] - (np.arctan2(dy, dx) - self.states[2]))], axis=1)
        H = np.zeros((self.n, 2, 3))
        H[:, 0, 0], H[:, 0, 1] = -dx / r, -dy / r
        H[:, 1, 0], H[:, 1, 1], H[:, 1, 2] = dy / q, -dx / q, -1.0
        return e, H

    def update(self, landmark_index: np.ndarray, z: np.ndarray, *, check: bool = True) -> bool:
        """Sequential EKF update of every kernel with each reading; weights times the predictive likelihoods."""
        z = np.asarray(z, dtype=np.float64).reshape(-1, 2)
        if len(z) == 0:
            return False
        if not np.isfinite(z).all():
            raise DataError("non-finite measurement", source="update")
        idx = np.asarray(landmark_index, dtype=np.int64).reshape(-1)
        if check:
            if len(idx) != len(z):
                raise DataError(f"{len(idx)} landmark indices for {len(z)} readings", source="update")
            check_landmark_index(idx, len(self.landmarks_xy))
        if self.config.likelihood == "nearest":
            k = int(np.argmin(z[:, 0])) if len(z) > 1 else 0
            z, idx = z[k : k + 1], idx[k : k + 1]
        ll = np.zeros(self.n)
        d2_sum = np.zeros(self.n)
        eye = np.eye(3)
        for m in range(len(z)):
            if self.config.likelihood == "nearest" and self.config.nearest_association == "per_particle":
                d2 = (self.landmarks_xy[:, 0:1] - self.states[0]) ** 2 + (self.landmarks_xy[:, 1:2] - self.states[1]) ** 2
                lm = self.landmarks_xy[np.argmin(d2, axis=0)]
            else:
                lm = self.landmarks_xy[idx[m]]
            e, H = self._innovation(lm, z[m])
            PHt = self.cov @ H.transpose(0, 2, 1)
            S = H @ PHt + self.q_cov
            det = S[:, 0, 0] * S[:, 1, 1] - S[:, 0, 1] * S[:, 1, 0]
            S_inv = np.empty_like(S)
            S_inv[:, 0, 0], S_inv[:, 1, 1] = S[:, 1, 1] / det, S[:, 0, 0] / det
            S_inv[:, 0, 1], S_inv[:, 1, 0] = -S[:, 0, 1] / det, -S[:, 1, 0] / det
            S_inv_e = np.einsum("nij,nj->ni", S_inv, e)
            d2 = np.einsum("ni,ni->n", e, S_inv_e)
            d2_sum += d2
            ll += -0.5 * d2 - 0.5 * np.log(det)
            K = PHt @ S_inv
            self.states += np.einsum("nij,nj->in", K, e)
            IKH = eye - K @ H
            self.cov = IKH @ self.cov @ IKH.transpose(0, 2, 1) + K @ self.q_cov @ K.transpose(0, 2, 1)  # Joseph form
        self.states[2] = wrap_angle(self.states[2])
        self.apply_log_likelihood(ll)
        self.last_max_loglik = float(-0.5 * d2_sum.min())  # Mahalanobis part only (comparable to point particles)
        return True

    def apply_log_likelihood(self, ll: np.ndarray) -> None:
        """Add ``ll`` to the log-weights and renormalize with log-sum-exp; all non-finite -> uniform (counted)."""
        lw = ll + self.log_weights
        lw = np.where(np.isfinite(lw), lw, -np.inf)
        m = lw.max()
        if not np.isfinite(m):
            self.n_weight_resets += 1
            log.warning("no kernel has a finite log-likelihood at update %d: weights reset to uniform", self.n_updates)
            self._reset_weights()
            self.n_updates += 1
            return
        self.last_max_loglik = float(np.max(ll))
        lw -= m
        w = np.exp(lw)
        s = w.sum()
        self.weights = w / s
        self.log_weights = lw - np.log(s)
        self._uniform = False
        self.n_updates += 1

    # ---- resample -----------------------------------------------------------------------------------
    def needs_resampling(self) -> bool:
        if self._uniform:
            return False
        thr = self.config.ess_threshold
        return thr >= 1.0 or self.ess < thr * self.n

    def resample(self, force: bool = False) -> bool:
        """Resample kernels and split each child: mean + sqrt(1 - a) L eps, covariance a P."""
        if not force and not self.needs_resampling():
            return False
        idx = self.resampler(self.weights, self.rng, self.n)
        states, cov = self.states[:, idx], self.cov[idx]
        if self.split < 1.0:
            L = np.linalg.cholesky(cov + 1e-12 * np.eye(3))
            states = states + np.sqrt(1.0 - self.split) * np.einsum("nij,jn->in", L, self.rng.standard_normal((3, self.n)))
            cov = self.split * cov
        states[2] = wrap_angle(states[2])
        self.states, self.cov = states, cov
        self._reset_weights()
        self.n_resamples += 1
        return True

    # ---- estimate -----------------------------------------------------------------------------------
    def estimate(self, kind: str | None = None) -> np.ndarray:
        """Weighted mean of the kernel means (circular for theta), or the mean of the highest-weight kernel."""
        kind = kind or self.config.estimator
        if kind == "best":
            return self.states[:, int(np.argmax(self.weights))].copy()
        if kind != "mean":
            raise ConfigError(f"unknown estimator {kind!r}; known: mean, best", source="estimator")
        w = self.weights
        theta = np.arctan2(np.sin(self.states[2]) @ w, np.cos(self.states[2]) @ w)
        return np.array([self.states[0] @ w, self.states[1] @ w, theta])

    def innovation_nis(self, landmark_index: np.ndarray, z: np.ndarray) -> np.ndarray:
        """NIS ``(M,)`` of each reading against the mixture's predictive distribution (chi-square(2) if consistent)."""
        z = np.asarray(z, dtype=np.float64).reshape(-1, 2)
        out = np.zeros(len(z))
        w = self.weights
        for m, k in enumerate(np.asarray(landmark_index, dtype=np.int64).reshape(-1)):
            e, H = self._innovation(self.landmarks_xy[k], z[m])
            S_k = H @ self.cov @ H.transpose(0, 2, 1) + self.q_cov
            nu = w @ e
            d = e - nu
            S = np.einsum("n,nij->ij", w, S_k) + (d * w[:, None]).T @ d
            out[m] = float(nu @ np.linalg.solve(S, nu))
        return out


__all__ = ["KalmanParticleFilter"]
