"""ParticleFilter: predict / update / resample / estimate over all particles at once."""

from __future__ import annotations

import logging

import numpy as np

from lidarkit.errors import ConfigError, DataError
from lidarkit.pf.base import LandmarkFilterBase, checked_odometry
from lidarkit.pf.config import PFConfig
from lidarkit.pf.models import OdometryMotionModel, RangeBearingModel, _wrap_inplace, resolve_q, standard_normal, wrap_angle

log = logging.getLogger(__name__)

THETA_WRAP_EVERY = 32  # predictions between wraps of the particle headings (keeps float32 theta precise)


def _heading_range(theta: np.ndarray) -> float:
    """The arc the headings span (rad): the smaller of their range wrapped to [-pi, pi) and to [0, 2 pi), exact
    below pi (a cloud facing +-pi spans a few degrees, not 2 pi)."""
    wrapped = np.remainder(theta.astype(np.float64) + np.pi, 2 * np.pi) - np.pi
    around_pi = np.remainder(wrapped, 2 * np.pi)
    return float(min(np.ptp(wrapped), np.ptp(around_pi)))


class ParticleFilter(LandmarkFilterBase):
    """Landmark-based Monte-Carlo localization in 2D (pose x_m, y_m, theta_rad).

    ``landmarks_xy``: ``(L, 2)`` map. Particles are ``(3, N)`` (``.states``; ``.particles`` gives
    an ``(N, 3)`` view) with normalized weights ``(N,)`` (both of ``config.dtype``, float32 by default) and
    their logs. Headings are wrapped to [-pi, pi] every ``THETA_WRAP_EVERY`` predictions. Counters:
    ``n_updates``, ``n_resamples``, ``n_weight_resets`` (updates whose log-likelihoods were all
    non-finite: weights reset to uniform, logged).
    """

    def _setup(self) -> None:
        self.dtype = np.dtype(self.config.dtype)
        self.motion = OdometryMotionModel(self.config.motion_noise_std)
        self.sensor = RangeBearingModel(resolve_q(self.config.q, self.config.q_as))
        self._landmarks_typed = self.landmarks_xy.astype(self.dtype)
        self._has_motion_noise = bool(self.motion.noise_std.any())
        self._odometry: np.ndarray | None = None
        self._odometry_pos = 0
        self._predicts_since_wrap = 0
        self._allocate()

    def _allocate(self) -> None:
        """Per-particle buffers for the current ``self.n``; pre-drawn noise and controls are dropped."""
        self._buffers_n = self.n
        self._noise_block: np.ndarray | None = None
        self._noise_pos = 0
        self._scratch = (np.empty(self.n, dtype=self.dtype), np.empty(self.n, dtype=self.dtype))
        self._controls = np.empty((3, self.n), dtype=self.dtype)
        self._estimate_buf = np.empty((4, self.n), dtype=self.dtype)
        self._work: np.ndarray | None = None  # (3, M, N) likelihood workspace, grown on demand
        self._control_block: np.ndarray | None = None
        self._control_buf: np.ndarray | None = None
        self._control_pos = 0

    def _block_steps(self) -> int:
        """Steps of motion noise drawn at once: cache-sized blocks; one step when the count changes per step (KLD)."""
        return 1 if self.config.kld else max(1, self.config.noise_block_elements // (3 * self.n))

    # ---- initialization -------------------------------------------------------------------------
    def initialize_gaussian(self, mean: np.ndarray | None = None, std: np.ndarray | None = None) -> None:
        """Particles ~ N(mean, diag(std^2)) (defaults from the config); weights uniform."""
        mean, std = self._gaussian_prior(mean, std)
        eps = standard_normal(self.rng, (3, self.n), self.dtype)
        self.states = (eps * std.astype(self.dtype)[:, None] + mean.astype(self.dtype)[:, None]).astype(self.dtype)
        self._reset_weights()

    def _set_uniform_states(self, states: np.ndarray, span: np.ndarray) -> None:
        self.states = states.astype(self.dtype)

    def _resize(self, n: int) -> None:
        self.n = int(n)
        if self.n != self._buffers_n:
            self._allocate()

    def set_particles(self, particles: np.ndarray, weights: np.ndarray | None = None) -> None:
        """Replace the particle set with ``(N, 3)`` poses (and optional weights, normalized here)."""
        p = np.asarray(particles, dtype=np.float64)
        if p.shape != (self.n, 3) or not np.isfinite(p).all():
            raise DataError(f"particles must be finite ({self.n}, 3), got {p.shape}", source="set_particles")
        self.states = np.ascontiguousarray(p.T, dtype=self.dtype)
        self._reset_weights()
        if weights is not None:
            w = np.asarray(weights, dtype=np.float64)
            if w.shape != (self.n,) or not np.isfinite(w).all() or (w < 0).any() or w.sum() <= 0:
                raise DataError("weights must be finite, >= 0, not all zero, shape (N,)", source="set_particles")
            self.weights = (w / w.sum()).astype(self.dtype)
            with np.errstate(divide="ignore"):
                self.log_weights = np.log(self.weights)
            self._uniform = False

    # ---- predict ----------------------------------------------------------------------------------
    def _next_noise(self) -> np.ndarray:
        if self._noise_block is None or self._noise_pos >= self._noise_block.shape[0]:
            steps = self._block_steps()
            self._noise_block = self.motion.sample_noise(self.rng, steps, self.n, self.dtype, self.config.antithetic)
            self._noise_pos = 0
        noise = self._noise_block[self._noise_pos]
        self._noise_pos += 1
        return noise

    def predict(self, odometry: np.ndarray, *, check: bool = True) -> None:
        """Move every particle by the odometry ``[r1_rad, t_m, r2_rad]`` with sampled motion noise."""
        if check:
            odometry = checked_odometry(odometry)
        r1, t, r2 = (self.dtype.type(v) for v in odometry)
        c = self._controls
        if self._has_motion_noise:
            noise = self._next_noise()
            np.add(noise[0], r1, out=c[0])
            np.add(noise[1], t, out=c[1])
            np.add(noise[2], r2, out=c[2])
            c[2] += c[0]
        else:
            c[0], c[1], c[2] = r1, t, r1 + r2
        self.motion.apply_controls(self.states, c, self._scratch)
        self._count_predict()

    def begin_odometry(self, odometry: np.ndarray) -> None:
        """Announce a whole ``(T, 3)`` odometry sequence for :meth:`predict_next` (validated by the caller)."""
        self._odometry = np.asarray(odometry, dtype=np.float64).reshape(-1, 3)
        self._odometry_pos = 0
        self._control_block = None

    def predict_next(self) -> None:
        """Predict with the next step of the announced odometry; noisy controls are formed per block of steps."""
        if self._odometry is None or self._odometry_pos >= len(self._odometry):
            raise DataError("no odometry left: call begin_odometry(odometry) first", source="predict_next")
        if self._control_block is None or self._control_pos >= self._control_block.shape[0]:
            steps = self._block_steps()
            if self._control_buf is None:  # reused: no fresh large allocation per block
                self._control_buf = np.empty(steps * 3 * self.n + ((steps * 3 * self.n) & 1), dtype=self.dtype)
            self._control_block = self.motion.controls_block(
                self.rng, self._odometry[self._odometry_pos :], steps, self.n, self.dtype, self.config.antithetic,
                out=self._control_buf,
            )
            self._control_pos = 0
        self.motion.apply_controls(self.states, self._control_block[self._control_pos], self._scratch)
        self._control_pos += 1
        self._odometry_pos += 1
        self._count_predict()

    def _count_predict(self) -> None:
        """Wrap the headings every ``THETA_WRAP_EVERY`` predictions (one vector op, amortized)."""
        self._predicts_since_wrap += 1
        if self._predicts_since_wrap >= THETA_WRAP_EVERY:
            self.wrap_headings()

    def wrap_headings(self) -> None:
        """Wrap every particle's theta to [-pi, pi] in place."""
        _wrap_inplace(self.states[2], self._scratch[0])
        self._predicts_since_wrap = 0

    # ---- update -----------------------------------------------------------------------------------
    def log_likelihood(self, landmark_index: np.ndarray, z: np.ndarray) -> np.ndarray:
        """Per-particle log-likelihood ``(N,)`` of the readings ``z`` ``(M, 2)`` of landmarks ``landmark_index`` ``(M,)``.

        ``likelihood="nearest"`` uses only the closest reading (smallest range; the protocol passes the
        truly nearest one), with its known landmark or each particle's nearest landmark (config
        ``nearest_association``); ``"all"`` sums every reading with its known landmark.
        """
        if self.config.likelihood == "nearest":
            k = int(np.argmin(z[:, 0])) if len(z) > 1 else 0
            if self.config.nearest_association == "per_particle":
                return self.sensor.log_likelihood_nearest(self.states, self._landmarks_typed, z[k])
            return self.sensor.log_likelihood_all(self.states, self._landmarks_typed[landmark_index[k : k + 1]], z[k : k + 1])
        m = len(landmark_index)
        if self._work is None or self._work.shape[1] < m:
            self._work = np.empty((3, max(m, 8), self.n), dtype=self.dtype)
        return self.sensor.log_likelihood_all(self.states, self._landmarks_typed[landmark_index], z, self._work)

    def update(self, landmark_index: np.ndarray, z: np.ndarray, *, check: bool = True) -> bool:
        """Reweight by the readings; an empty set of readings leaves the weights unchanged (returns False)."""
        if check:
            landmark_index, z = self._checked_readings(landmark_index, z)
        if len(z) == 0:
            return False
        self.apply_log_likelihood(self.log_likelihood(landmark_index, z))
        self.track_likelihood(1 if self.config.likelihood == "nearest" else len(z))
        return True

    # ---- resample ---------------------------------------------------------------------------------
    def _resample_states(self, idx: np.ndarray) -> None:
        """Take the particles ``idx`` (KLD: a new count), then moment matching / regularization / roughening per the config."""
        matching = self.config.moment_matching
        before = self._moments(self.weights, matching == "mean_cov") if matching != "none" else None
        self.states = np.take(self.states, idx, axis=1)
        self.n = int(idx.shape[0])
        if self.n != self._buffers_n:
            self._allocate()
        if before is not None:
            self._match_moments(before)
        if self.config.regularization > 0:
            self._regularize(self.config.regularization)
        if self.config.roughening > 0:
            self._roughen()

    def _replace_states(self, mask: np.ndarray, states: np.ndarray) -> None:
        self.states[:, mask] = states.astype(self.dtype)

    def _moments(self, weights: np.ndarray, with_cov: bool) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
        """Weighted mean (circular for theta), deviations ``(3, N)`` float64 and covariance (or None)."""
        w = weights
        st = self.states.astype(np.float64)
        mean = np.array([st[0] @ w, st[1] @ w, np.arctan2(np.sin(st[2]) @ w, np.cos(st[2]) @ w)])  # noqa: small N path
        dev = st - mean[:, None]
        dev[2] = wrap_angle(dev[2])
        cov = (dev * w) @ dev.T if with_cov else None
        return mean, cov, dev

    def _match_moments(self, before: tuple[np.ndarray, np.ndarray | None, np.ndarray]) -> None:
        """After resampling, restore the pre-resampling weighted mean (and covariance): an affine map of the cloud."""
        mean_b, cov_b, _ = before
        uniform = np.full(self.n, 1.0 / self.n)
        mean_a, cov_a, dev_a = self._moments(uniform, cov_b is not None)
        if cov_b is not None and self.n > 3:
            try:
                L_b = np.linalg.cholesky(cov_b + 1e-12 * np.eye(3))
                L_a = np.linalg.cholesky(cov_a + 1e-12 * np.eye(3))
                A = L_b @ np.linalg.inv(L_a)
                dev_a = A @ (dev_a - (dev_a.mean(axis=1, keepdims=True)))
            except np.linalg.LinAlgError:
                log.debug("moment matching skipped: degenerate particle covariance")
                dev_a = dev_a - dev_a.mean(axis=1, keepdims=True)
        else:
            dev_a = dev_a - dev_a.mean(axis=1, keepdims=True)
        self.states = (mean_b[:, None] + dev_a).astype(self.dtype)

    def _regularize(self, h: float) -> None:
        """Liu-West kernel move: shrink toward the mean by sqrt(1 - h^2), add N(0, h^2 Cov): keeps mean and covariance."""
        uniform = np.full(self.n, 1.0 / self.n)
        mean, cov, dev = self._moments(uniform, True)
        try:
            L = np.linalg.cholesky(cov + 1e-12 * np.eye(3))
        except np.linalg.LinAlgError:
            return
        eps = self.rng.standard_normal((3, self.n))
        new = mean[:, None] + np.sqrt(1.0 - h * h) * dev + h * (L @ eps)
        self.states = new.astype(self.dtype)

    def _roughen(self) -> None:
        spread = self.states.max(axis=1) - self.states.min(axis=1)
        spread[2] = min(_heading_range(self.states[2]), np.pi)
        sigma = (self.config.roughening * self.n ** (-1.0 / 3.0)) * spread
        eps = standard_normal(self.rng, (3, self.n), self.dtype)
        eps *= sigma.astype(self.dtype)[:, None]
        self.states += eps

    # ---- estimate ---------------------------------------------------------------------------------
    def _best_pose(self, i: int) -> np.ndarray:
        """Particle ``i`` as float64, theta in [-pi, pi)."""
        pose = self.states[:, i].astype(np.float64)
        pose[2] = wrap_angle(pose[2])
        return pose

    def _mean_pose(self) -> np.ndarray:
        """Weighted mean, circular for theta (one pass over a cos/sin buffer)."""
        buf = self._estimate_buf  # rows x, y, cos(theta), sin(theta)
        np.copyto(buf[:2], self.states[:2])
        np.cos(self.states[2], out=buf[2])
        np.sin(self.states[2], out=buf[3])
        w = self.weights
        if self.n <= 16384:  # single-threaded BLAS matrix-vector product
            x, y, c, s = buf @ w
        else:  # multiply + sum: BLAS threads would spin against other jobs for large N
            buf *= w
            x, y, c, s = np.add.reduce(buf, axis=1)
        return np.array([x, y, np.arctan2(s, c)], dtype=np.float64)

    # ---- consistency ------------------------------------------------------------------------------
    def innovation_stats(self, landmark_index: np.ndarray, z: np.ndarray, *, check: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Innovations ``(M, 2)`` (weighted mean of the per-particle residuals) and the particle set's own
        predictive spread ``(M, 2, 2)`` (their weighted covariance); S = spread + Q. ``check``: the readings as
        :meth:`update` checks them (index -1 was read as the last landmark; ``check=False`` for a loop that checked them
        all up front)."""
        idx, z = self._checked_readings(landmark_index, z, check_index=check, source="innovation_stats")
        if len(z) == 0:
            return np.zeros((0, 2)), np.zeros((0, 2, 2))
        lm = self.landmarks_xy[idx]
        e_r, e_b = self.sensor.residuals(self.states.astype(np.float64), lm, z)
        w = self.weights.astype(np.float64)
        nu = np.stack([e_r @ w, e_b @ w], axis=1)  # (M, 2)
        dr, db = e_r - nu[:, :1], e_b - nu[:, 1:]
        P = np.empty((len(z), 2, 2))
        P[:, 0, 0], P[:, 1, 1] = (dr * dr) @ w, (db * db) @ w
        P[:, 0, 1] = P[:, 1, 0] = (dr * db) @ w
        return nu, P

    def innovation_nis(self, landmark_index: np.ndarray, z: np.ndarray) -> np.ndarray:
        """Normalized innovation squared ``(M,)`` of each reading against the current (predicted) particle set.

        Innovation = weighted mean of the per-particle residuals; S = their weighted covariance + Q.
        For a consistent filter each value is chi-square distributed with 2 degrees of freedom.
        """
        idx, z = self._checked_readings(landmark_index, z, source="innovation_nis")
        nu, P = self.innovation_stats(idx, z, check=False)
        return nis_values(nu, P + self.sensor.q_cov)


def nis_values(nu: np.ndarray, S: np.ndarray) -> np.ndarray:
    """``nu_m^T S_m^-1 nu_m`` for ``(M, 2)`` innovations and ``(M, 2, 2)`` covariances."""
    if len(nu) == 0:
        return np.zeros(0)
    return np.einsum("mi,mij,mj->m", nu, np.linalg.inv(S), nu)


def check_config_type(config: object, source: str) -> None:
    """ConfigError naming ``source`` for a ``config`` that is neither None nor a PFConfig, as the filters say it (a dict
    was an AttributeError on the first setting read: 'dict' object has no attribute 'kernel')."""
    if config is not None and not isinstance(config, PFConfig):
        raise ConfigError(f"config must be a PFConfig (PFConfig(...) or PFConfig.make(...)), got {type(config).__name__}",
                          source=source)


def make_filter(landmarks_xy: np.ndarray, config: PFConfig | None = None, rng: np.random.Generator | int | None = 0):
    """The filter the config asks for: point particles (:class:`ParticleFilter`) or Kalman kernels."""
    check_config_type(config, "make_filter")
    config = config if config is not None else PFConfig()
    if config.kernel == "kalman":
        from lidarkit.pf.kalman_kernel import KalmanParticleFilter

        return KalmanParticleFilter(landmarks_xy, config, rng)
    return ParticleFilter(landmarks_xy, config, rng)


__all__ = ["ParticleFilter", "make_filter", "nis_values"]
