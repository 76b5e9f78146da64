"""Kalman-particle kernel filter: each particle is a Gaussian kernel (mean, 3x3 covariance) updated by an EKF.

After Pham, Dahia & Musso (2003), "A Kalman-particle kernel filter and its application to terrain
navigation". The weights follow each kernel's predictive likelihood N(z; h(mean), H P H^T + Q);
resampling splits a kernel into children drawn from N(mean, (1 - a) P) with covariance a P
(``kernel_split`` = a), which keeps the mixture's mean and covariance. Because every kernel carries
its own uncertainty, a few tens of kernels reach the accuracy of ~10^4 point particles on the
Freiburg data; so does N=1, which is a plain EKF (a single kernel is never split): on that tracking
problem the kernels add nothing, they matter on multi-modal ones (see docs/particle_filter.md). Vectorized over kernels with batched 3x3 algebra;
meant for small N (memory and time grow as N x 9).
"""

from __future__ import annotations

import numpy as np

from lidarkit.errors import ConfigError
from lidarkit.pf.base import LandmarkFilterBase, checked_odometry
from lidarkit.pf.config import PFConfig
from lidarkit.pf.models import resolve_q, wrap_angle


class KalmanParticleFilter(LandmarkFilterBase):
    """Same interface as :class:`lidarkit.pf.filter.ParticleFilter`; kernels are ``(3, N)`` means + ``(N, 3, 3)`` covariances (float64)."""

    unit_name = "kernel"
    skip_uniform_prior = False  # the log-weights always include the prior, uniform or not

    def _default_config(self) -> PFConfig:
        return PFConfig(kernel="kalman")

    def _setup(self) -> None:
        self.dtype = np.dtype(np.float64)
        self.split = float(self.config.kernel_split)
        if not 0.0 < self.split <= 1.0:
            raise ConfigError(f"kernel_split must be in (0, 1], got {self.split}", source="kernel_split")
        self.motion_var = np.asarray(self.config.motion_noise_std, dtype=np.float64) ** 2
        self.q_cov = resolve_q(self.config.q, self.config.q_as)
        self.n_gated = 0  # kernel-reading pairs rejected by the innovation gate

    # ---- initialization ---------------------------------------------------------------------------
    def initialize_gaussian(self, mean: np.ndarray | None = None, std: np.ndarray | None = None) -> None:
        """Kernel means ~ N(mean, (1 - a) S0), covariances a S0 with S0 = diag(std^2): the mixture has covariance S0."""
        mean, std = self._gaussian_prior(mean, std)
        var = std**2
        a = self.split if self.n > 1 else 1.0
        self.states = mean[:, None] + np.sqrt((1.0 - a) * var)[:, None] * self.rng.standard_normal((3, self.n))
        self.cov = np.broadcast_to(np.diag(a * var), (self.n, 3, 3)).copy()
        self._reset_weights()

    def _set_uniform_states(self, states: np.ndarray, span: np.ndarray) -> None:
        """Kernel means uniform over the bounds, covariances of one cell of N."""
        self.states = states
        cell = span / np.array([np.sqrt(self.n), np.sqrt(self.n), 4.0])
        self.cov = np.broadcast_to(np.diag(cell**2 / 4.0), (self.n, 3, 3)).copy()

    # ---- predict ------------------------------------------------------------------------------------
    def predict(self, odometry: np.ndarray, *, check: bool = True) -> None:
        """EKF prediction of every kernel through the odometry model (noise std on r1, t, r2 from the config)."""
        r1, t, r2 = checked_odometry(odometry)  # ("abc" was numpy's ValueError)
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
        """Sequential EKF update of every kernel with each reading; weights times the predictive likelihoods.

        With ``innovation_gate`` > 0 a reading whose Mahalanobis distance exceeds it does not correct the kernel
        (K = 0: mean and covariance unchanged) but still enters the kernel's weight."""
        # checked before an empty set returns (indices without readings returned False where the point filter refuses them)
        idx, z = self._checked_readings(landmark_index, z, check_index=check)
        if len(z) == 0:
            return False
        if self.config.likelihood == "nearest":
            k = int(np.argmin(z[:, 0])) if len(z) > 1 else 0
            z, idx = z[k : k + 1], idx[k : k + 1]
        ll = np.zeros(self.n)
        d2_sum = np.zeros(self.n)
        gate = self.config.innovation_gate
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
            if gate > 0.0:  # outlier rejection: no correction by a reading beyond the gate
                K[d2 > gate] = 0.0
                self.n_gated += int(np.count_nonzero(d2 > gate))
            self.states += np.einsum("nij,nj->in", K, e)
            IKH = eye - K @ H
            self.cov = IKH @ self.cov @ IKH.transpose(0, 2, 1) + K @ self.q_cov @ K.transpose(0, 2, 1)  # Joseph form
        self.states[2] = wrap_angle(self.states[2])
        self.apply_log_likelihood(ll)
        self.last_max_loglik = float(-0.5 * d2_sum.min())  # Mahalanobis part only (comparable to point particles)
        return True

    def _resample_states(self, idx: np.ndarray) -> None:
        """Take the kernels ``idx`` and split each child: mean + sqrt(1 - a) L eps, covariance a P.

        A single kernel is left as it is (N=1 is a plain EKF: splitting would only add noise)."""
        if self.n == 1:
            return
        states, cov = self.states[:, idx], self.cov[idx]
        if self.split < 1.0:
            L = np.linalg.cholesky(cov + 1e-12 * np.eye(3))
            states = states + np.sqrt(1.0 - self.split) * np.einsum("nij,jn->in", L, self.rng.standard_normal((3, self.n)))
            cov = self.split * cov
        states[2] = wrap_angle(states[2])
        self.states, self.cov = states, cov

    # ---- estimate -----------------------------------------------------------------------------------
    def _best_pose(self, i: int) -> np.ndarray:
        return self.states[:, i].copy()

    def _mean_pose(self) -> np.ndarray:
        """Weighted mean of the kernel means (circular for theta)."""
        w = self.weights
        theta = np.arctan2(np.sin(self.states[2]) @ w, np.cos(self.states[2]) @ w)
        return np.array([self.states[0] @ w, self.states[1] @ w, theta])

    def innovation_stats(self, landmark_index: np.ndarray, z: np.ndarray, *, check: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Innovations ``(M, 2)`` against the mixture and its predictive spread without Q ``(M, 2, 2)``; ``check`` as
        :meth:`lidarkit.pf.filter.ParticleFilter.innovation_stats`."""
        idx, z = self._checked_readings(landmark_index, z, check_index=check, source="innovation_stats")
        nu_all, P_all = np.zeros((len(z), 2)), np.zeros((len(z), 2, 2))
        w = self.weights
        for m, k in enumerate(idx):
            e, H = self._innovation(self.landmarks_xy[k], z[m])
            HPHt = H @ self.cov @ H.transpose(0, 2, 1)
            nu = w @ e
            d = e - nu
            nu_all[m] = nu
            P_all[m] = np.einsum("n,nij->ij", w, HPHt) + (d * w[:, None]).T @ d
        return nu_all, P_all

    def innovation_nis(self, landmark_index: np.ndarray, z: np.ndarray) -> np.ndarray:
        """NIS ``(M,)`` of each reading against the mixture's predictive distribution (chi-square(2) if consistent)."""
        from lidarkit.pf.filter import nis_values

        idx, z = self._checked_readings(landmark_index, z, source="innovation_nis")
        nu, P = self.innovation_stats(idx, z, check=False)
        return nis_values(nu, P + self.q_cov)


__all__ = ["KalmanParticleFilter"]
