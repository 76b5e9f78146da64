"""What point-particle and Kalman-kernel localization filters share: map, weights, resampling decision, estimators.

:class:`LandmarkFilterBase` holds the landmark map, the normalized weights ``(N,)`` and their logs
(log-sum-exp normalization, reset to uniform when every log-likelihood is non-finite), the ESS test,
the resampling bookkeeping, the reading validation and the estimator dispatch. A subclass supplies only
its own state and math: :meth:`_setup`, :meth:`initialize_gaussian`, :meth:`_set_uniform_states`,
``predict``, ``update``, :meth:`_resample_states`, :meth:`_best_pose` and :meth:`_mean_pose`.
"""

from __future__ import annotations

import logging

import numpy as np

from lidarkit.errors import ConfigError, DataError
from lidarkit.io.landmarks import LandmarkMap
from lidarkit.params import is_integer
from lidarkit.pf.augmented import LikelihoodAverages
from lidarkit.pf.config import MAX_POSE_SCALE, PFConfig
from lidarkit.pf.kld import bins_and_spread, kld_sample_count, occupied_bins
from lidarkit.pf.resampling import ess_of_normalized, get_resampler


def check_landmark_index(landmark_index: np.ndarray, n_landmarks: int, source: str = "update",
                         step_offsets: np.ndarray | None = None) -> np.ndarray:
    """``landmark_index`` as ``(M,)`` int64, or a DataError naming the first reading (and its step, given the ``(T+1,)``
    ``step_offsets``) whose index is no integer (1.9 was read as 1) or is outside ``0 .. n_landmarks - 1`` (-1 weighed
    the last landmark)."""
    raw = np.asarray(landmark_index).reshape(-1)
    if raw.dtype.kind == "f":  # whole numbers given as floats are indices
        not_whole = ~(np.isfinite(raw) & (raw == np.round(raw)))
    else:  # bools, text and objects are none
        not_whole = np.full(len(raw), raw.dtype.kind not in "iu")
    if not_whole.any():
        i = int(np.argmax(not_whole))
        raise DataError(f"landmark index must be an integer, got {raw[i : i + 1].tolist()[0]!r} ({_reading(i, step_offsets)})",
                        source=source)
    outside = (raw < 0) | (raw >= n_landmarks)
    if outside.any():
        i = int(np.argmax(outside))
        raise DataError(f"landmark index {int(raw[i])} outside 0..{n_landmarks - 1} ({_reading(i, step_offsets)})", source=source)
    return raw.astype(np.int64)


def readings_array(z: np.ndarray, source: str) -> np.ndarray:
    """Readings ``z`` as ``(M, 2)`` float64 [range_m, bearing_rad] (one reading may come as ``(2,)``, none as an empty
    array), or a DataError naming ``source`` (the wrong shape or text failed in numpy's reshape or float conversion)."""
    try:
        arr = np.asarray(z, dtype=np.float64)
    except (TypeError, ValueError):
        raise DataError(f"readings must be numbers [range_m, bearing_rad], got {_listed(z)}", source=source) from None
    if arr.size == 0:
        return arr.reshape(0, 2)
    if arr.shape != (2,) and (arr.ndim != 2 or arr.shape[1] != 2):
        raise DataError(f"readings must be an (M, 2) array [range_m, bearing_rad], got shape {arr.shape}", source=source)
    return arr.reshape(-1, 2)


def checked_odometry(odometry, source: str = "predict") -> np.ndarray:
    """One step's odometry as ``(3,)`` float64 finite [r1_rad, t_m, r2_rad], or a DataError naming ``source`` ("abc"
    was numpy's ValueError)."""
    try:
        u = np.asarray(odometry, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):  # text, ragged rows
        raise DataError(f"odometry must be numbers [r1, t, r2], got {odometry!r}", source=source) from None
    if u.shape != (3,):
        raise DataError(f"odometry must be [r1, t, r2], got shape {u.shape}", source=source)
    if not np.isfinite(u).all():
        raise DataError(f"non-finite odometry {u.tolist()}", source=source)
    return u


def _checked_bounds(bounds_xy) -> tuple[float, float, float, float]:
    """``bounds_xy`` as (xmin, xmax, ymin, ymax) floats: 4 finite numbers, each min below its max, within PFConfig's pose
    bound (an infinite box gave an estimate of inf and NaN kernels, 1e30 one of 5.6e29; text and 3 values were numpy's
    ValueError, a bare number a TypeError)."""
    try:
        b = np.asarray(bounds_xy, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        b = np.empty(0)
    if (b.shape != (4,) or not np.isfinite(b).all() or not (b[0] < b[1] and b[2] < b[3])
            or np.abs(b).max() > MAX_POSE_SCALE):
        raise ConfigError(f"bounds_xy must be 4 finite numbers (xmin, xmax, ymin, ymax) with each min below its max and "
                          f"|value| <= {MAX_POSE_SCALE:g} m, got {_listed(bounds_xy)}", source="initialize_uniform")
    x0, x1, y0, y1 = b.tolist()
    return x0, x1, y0, y1


def _generator(rng) -> np.random.Generator:
    """``rng`` as a Generator: one given, or seeded by an integer >= 0 (None: fresh entropy); "x" was numpy's TypeError,
    -1 its ValueError."""
    if isinstance(rng, np.random.Generator):
        return rng
    if rng is not None and not (is_integer(rng) and rng >= 0):
        raise ConfigError(f"rng must be a numpy.random.Generator, an integer seed >= 0 or None, got {rng!r}", source="rng")
    return np.random.default_rng(rng)


def _listed(value) -> str:
    """``value`` for an error message: a list of its elements where it is array-like, else its repr."""
    try:
        return repr(np.asarray(value).reshape(-1).tolist())
    except (TypeError, ValueError):  # ragged
        return repr(value)


def _shown_landmarks(value) -> str:
    """Landmarks that are no numbers, for a one-line message: text and sequences as listed, any other object by its type."""
    if isinstance(value, str):
        return repr(value)
    if isinstance(value, (list, tuple, np.ndarray)):
        return _listed(value)
    hint = " (its .landmarks is the map)" if isinstance(getattr(value, "landmarks", None), LandmarkMap) else ""
    return f"a {type(value).__name__}{hint}"


def _reading(i: int, step_offsets: np.ndarray | None) -> str:
    """The words "reading i", with its step when the readings are grouped by step (rows ``step_offsets[t]:step_offsets[t+1]``)."""
    if step_offsets is None:
        return f"reading {i}"
    return f"step {int(np.searchsorted(step_offsets, i, side='right')) - 1}, reading {i}"


class LandmarkFilterBase:
    """Weighted set of ``N`` pose hypotheses ``(3, N)`` (``.states``; x_m, y_m, theta_rad) against an ``(L, 2)`` landmark map.

    The map may be a reader's :class:`~lidarkit.io.landmarks.LandmarkMap`: its rows, in the world file's order, are the
    landmark indices ``update`` takes (``LandmarkData.meas_landmark_index``), not its ids.

    Weights and log-weights are of ``self.dtype`` (set by :meth:`_setup`). Counters: ``n_updates``,
    ``n_resamples``, ``n_weight_resets`` (updates whose log-likelihoods were all non-finite: weights
    reset to uniform, logged).
    """

    unit_name = "particle"  # what one hypothesis is called in log messages
    skip_uniform_prior = True  # uniform weights: take ll as the new log-weights without adding the constant -log N

    def __init__(self, landmarks_xy: np.ndarray | LandmarkMap, config: PFConfig | None = None,
                 rng: np.random.Generator | int | None = 0) -> None:
        if config is not None and not isinstance(config, PFConfig):  # (a dict: an AttributeError on n_particles)
            raise ConfigError(f"config must be a PFConfig (PFConfig(...) or PFConfig.make(...)), got {type(config).__name__}",
                              source=type(self).__name__)
        self.config = config if config is not None else self._default_config()
        self.rng = _generator(rng)
        if isinstance(landmarks_xy, LandmarkMap):  # the world file's map: update() takes its rows (meas_landmark_index)
            landmarks_xy = landmarks_xy.positions_xy
        try:
            lm = np.asarray(landmarks_xy, dtype=np.float64)
        except (TypeError, ValueError):  # text, ragged rows, an object (printed whole: a 9-line repr)
            raise DataError(f"landmarks must be numbers, an (L, 2) array or a LandmarkMap, got {_shown_landmarks(landmarks_xy)}",
                            source="landmarks") from None
        if lm.ndim != 2 or lm.shape[1] != 2 or len(lm) == 0 or not np.isfinite(lm).all():
            raise DataError(f"landmarks must be a finite (L, 2) array with L >= 1, got shape {lm.shape}", source="landmarks")
        self.landmarks_xy = lm
        self.n = int(self.config.n_particles)
        self.resampler = get_resampler(self.config.resampler)
        self._uniform_w: np.ndarray | None = None
        self._setup()
        self.n_updates = 0
        self.n_resamples = 0
        self.n_weight_resets = 0
        self.last_max_loglik = 0.0
        self.last_log_mean_lik = float("nan")  # log of the prior-weighted average likelihood of the last update
        c = self.config
        self.averages = LikelihoodAverages(c.alpha_slow, c.alpha_fast) if c.augmented else None
        self.n_injected = 0  # particles replaced by uniform draws (augmented MCL), in total
        self.last_injected = 0
        self.last_kld_bins = 0  # occupied bins at the last KLD-sized resampling
        # resamplings in a row with a narrow belief (KLD convergence test): a known start counts as converged,
        # a uniform (global) initialization re-arms the test
        self._narrow_steps = self.config.kld_converged_steps
        self._injected_mask: np.ndarray | None = None  # hypotheses replaced by uniform draws at the last resampling
        if self.config.init == "uniform":
            self.initialize_uniform()
        else:
            self.initialize_gaussian()

    def _default_config(self) -> PFConfig:
        return PFConfig()

    def _setup(self) -> None:
        """Filter-specific members (must set ``self.dtype``); called before the initialization."""
        raise NotImplementedError

    # ---- initialization -------------------------------------------------------------------------
    def initialize_gaussian(self, mean: np.ndarray | None = None, std: np.ndarray | None = None) -> None:
        raise NotImplementedError

    def _gaussian_prior(self, mean: np.ndarray | None, std: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """Mean ``(3,)`` and standard deviations ``(3,)`` float64 (defaults from the config), checked as PFConfig checks
        ``init_mean`` / ``init_std`` (a NaN mean was taken: every weight reset at the next update, a NaN estimate)."""
        checked = []
        for name, value in (("mean", self.config.init_mean if mean is None else mean),
                            ("std", self.config.init_std if std is None else std)):
            try:
                v = np.asarray(value, dtype=np.float64).reshape(-1)
            except (TypeError, ValueError):  # text
                v = np.empty(0)
            if v.shape != (3,) or not np.isfinite(v).all() or (name == "std" and (v < 0).any()):
                rule = "3 finite values >= 0" if name == "std" else "3 finite values"
                raise ConfigError(f"{name} must be {rule} [x_m, y_m, theta_rad], got {_listed(value)}", source="initialize_gaussian")
            checked.append(v)
        return checked[0], checked[1]

    def initialize_uniform(self, bounds_xy: tuple[float, float, float, float] | None = None) -> None:
        """Global localization: x, y uniform over ``(xmin, xmax, ymin, ymax)`` (default: landmarks +- margin), theta uniform."""
        if self.config.kld and self.n_updates > 0:  # relocalization (recovery="reinit"): as many particles as KLD allows
            self._resize(self.config.kld_max_n)
        states, span = self._uniform_draw(self.n, bounds_xy)
        self._set_uniform_states(states, span)
        self._reset_weights()
        self._narrow_steps = 0
        self._injected_mask = None

    def uniform_bounds(self) -> tuple[float, float, float, float]:
        """(xmin, xmax, ymin, ymax) of global localization and injection: the landmarks' box + ``uniform_margin_m``."""
        m = self.config.uniform_margin_m
        lo, hi = self.landmarks_xy.min(axis=0) - m, self.landmarks_xy.max(axis=0) + m
        return float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1])

    def _uniform_draw(self, n: int, bounds_xy: tuple[float, float, float, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
        """``n`` poses ``(3, n)`` float64 uniform over the box and all headings, and the box size ``(3,)``."""
        x0, x1, y0, y1 = self.uniform_bounds() if bounds_xy is None else _checked_bounds(bounds_xy)
        if not (x1 > x0 and y1 > y0):
            raise ConfigError(f"empty bounds {(x0, x1, y0, y1)!r}", source="initialize_uniform")
        u = self.rng.random((3, n))
        lo = np.array([x0, y0, -np.pi])[:, None]
        span = np.array([x1 - x0, y1 - y0, 2 * np.pi])
        return lo + u * span[:, None], span

    def _resize(self, n: int) -> None:
        """Change the hypothesis count to ``n`` (the state is replaced right after; KLD-capable filters only)."""
        raise NotImplementedError

    def _set_uniform_states(self, states: np.ndarray, span: np.ndarray) -> None:
        """Take the uniformly drawn float64 ``states`` ``(3, N)`` over the box of size ``span`` ``(3,)``."""
        raise NotImplementedError

    # ---- weights ------------------------------------------------------------------------------------
    def _reset_weights(self) -> None:
        # shared read-only arrays: every update creates new weight arrays
        if self._uniform_w is None or self._uniform_w.shape[0] != self.n:
            self._uniform_w = np.full(self.n, 1.0 / self.n, dtype=self.dtype)
            self._uniform_lw = np.full(self.n, -np.log(self.n), dtype=self.dtype)
            self._uniform_w.flags.writeable = False
            self._uniform_lw.flags.writeable = False
        self.weights = self._uniform_w
        self._lw_shifted = None
        self._log_weights = self._uniform_lw
        self._uniform = True

    @property
    def log_weights(self) -> np.ndarray:
        """Normalized log-weights ``(N,)`` (computed on demand after an update)."""
        if self._log_weights is None:
            self._log_weights = self._lw_shifted - self._log_sum
        return self._log_weights

    @log_weights.setter
    def log_weights(self, value: np.ndarray) -> None:
        self._log_weights = value
        self._lw_shifted = None

    @property
    def particles(self) -> np.ndarray:
        """``(N, 3)`` view of the poses (kernel means)."""
        return self.states.T

    @property
    def ess(self) -> float:
        return ess_of_normalized(self.weights)

    def apply_log_likelihood(self, ll: np.ndarray) -> None:
        """Add ``ll`` ``(N,)`` to the log-weights and renormalize with log-sum-exp (never underflows to all zero).

        Non-finite entries count as impossible; if none is finite the weights are reset to uniform (counted, logged).
        """
        prior_skipped = self._uniform and self.skip_uniform_prior
        lw = ll.astype(self.dtype) if prior_skipped else ll + self.log_weights
        m = lw.max()
        if not np.isfinite(m):  # NaN / inf somewhere, or every hypothesis impossible
            lw = np.where(np.isfinite(lw), lw, -np.inf).astype(self.dtype)
            m = lw.max()
            if not np.isfinite(m):
                self.n_weight_resets += 1
                logging.getLogger(type(self).__module__).warning(  # the concrete filter's logger
                    "no %s has a finite log-likelihood at update %d: weights reset to uniform", self.unit_name, self.n_updates
                )
                self._reset_weights()
                self.n_updates += 1
                return
        self.last_max_loglik = float(m) if prior_skipped else float(ll.max())
        lw -= m
        w = np.exp(lw)
        s = w.sum(dtype=np.float64)
        # log sum_i w_i L_i (prior weights w_i): with a skipped uniform prior, lw = ll and the mean is over N
        self.last_log_mean_lik = float(m) + float(np.log(s)) - (float(np.log(self.n)) if prior_skipped else 0.0)
        w /= self.dtype.type(s)
        self.weights, self._uniform = w, False
        self._lw_shifted, self._log_sum, self._log_weights = lw, self.dtype.type(np.log(s)), None
        self.n_updates += 1

    # ---- update -------------------------------------------------------------------------------------
    def _checked_readings(self, landmark_index: np.ndarray, z: np.ndarray, check_index: bool = True,
                          source: str = "update") -> tuple[np.ndarray, np.ndarray]:
        """``(M,)`` int64 landmark indices and ``(M, 2)`` float64 finite readings; with ``check_index`` also counts and
        indices (integers in range); errors name ``source``, the method called."""
        z = readings_array(z, source)
        if not np.isfinite(z).all():
            raise DataError("non-finite measurement", source=source)
        if not check_index:
            return np.asarray(landmark_index, dtype=np.int64).reshape(-1), z
        idx = check_landmark_index(landmark_index, len(self.landmarks_xy), source)
        if len(idx) != len(z):
            raise DataError(f"{len(idx)} landmark indices for {len(z)} readings", source=source)
        return idx, z

    # ---- resample -----------------------------------------------------------------------------------
    def track_likelihood(self, n_readings: int) -> None:
        """Augmented MCL: fold the last update's average likelihood, per reading, into w_slow / w_fast."""
        if self.averages is not None and n_readings > 0:
            self.averages.update(self.last_log_mean_lik / n_readings)

    def injection_probability(self) -> float:
        """Probability that a particle is replaced by a uniform draw at the next resampling (0 without augmented MCL)."""
        return self.averages.injection_probability() if self.averages is not None else 0.0

    def needs_resampling(self) -> bool:
        if self._uniform:
            return False
        if self.n == 1 and not self.config.kld and self.injection_probability() == 0.0:
            return False  # one hypothesis (N=1: a plain EKF) would only copy itself: counted 331 resamplings of none
        thr = self.config.ess_threshold
        if thr >= 1.0 or self.injection_probability() > 0.0:
            return True
        return ess_of_normalized(self.weights) < thr * self.n

    @property
    def kld_converged(self) -> bool:
        """KLD's convergence test: the belief's weighted RMS position spread was at most ``kld_converged_m`` on the
        last ``kld_converged_steps`` resamplings. A Gaussian (known-start) initialization counts as converged; the
        test is re-armed by a uniform (re)initialization, and by augmented-MCL injections that leave the belief wide."""
        return self._narrow_steps >= self.config.kld_converged_steps

    def next_count(self) -> int:
        """Particles after the next resampling: the current count, or with ``kld`` Fox's bound for the number of bins
        the predicted set occupies, clipped to [floor, ``kld_max_n``]; the floor is ``kld_unconverged_n`` until
        :attr:`kld_converged`, then ``kld_min_n`` (the bound counts bins of a set that one informative update can
        collapse onto a few ancestors: a ~1 m wide posterior fills only ~50-100 bins, a bound below 1000)."""
        c = self.config
        if not c.kld:
            return self.n
        injected = self._injected_mask
        # uniform draws of augmented MCL each fill a bin of their own: the bound is taken on the rest
        core = self.states if injected is None else self.states[:, ~injected]
        if self.kld_converged and injected is None:  # steady state: bins only
            floor = c.kld_min_n
            k = occupied_bins(core, c.kld_bin_m, c.kld_bin_rad)
        else:
            k, spread = bins_and_spread(self.states, self.weights, c.kld_bin_m, c.kld_bin_rad)
            if injected is not None:
                k = occupied_bins(core, c.kld_bin_m, c.kld_bin_rad)
            if not self.kld_converged or spread > c.kld_converged_m:  # injections the readings favour re-arm the test
                self._narrow_steps = self._narrow_steps + 1 if spread <= c.kld_converged_m else 0
            floor = c.kld_min_n if self.kld_converged else max(c.kld_min_n, min(c.kld_unconverged_n, c.kld_max_n))
        n, self.last_kld_bins = kld_sample_count(
            core, k, epsilon=c.kld_epsilon, z=c.kld_z, bin_m=c.kld_bin_m, bin_rad=c.kld_bin_rad,
            n_min=floor, n_max=c.kld_max_n,
        )
        return n

    def resample(self, force: bool = False) -> bool:
        """Resample (always if ``force``, else per the ESS threshold); returns whether it happened.

        The new count comes from :meth:`next_count` (KLD-sampling); with augmented MCL each new particle is
        then replaced with probability :meth:`injection_probability` by a uniform draw over the map box.
        """
        if not force and not self.needs_resampling():
            return False
        p_inject = self.injection_probability()
        self._resample_states(self.resampler(self.weights, self.rng, self.next_count()))
        self.last_injected = 0
        self._injected_mask = None
        if p_inject > 0.0:
            replace = self.rng.random(self.n) < p_inject
            k = int(np.count_nonzero(replace))
            if k:
                self._replace_states(replace, self._uniform_draw(k)[0])
                self._injected_mask = replace if self.config.kld else None
                self.last_injected = k
                self.n_injected += k
        self._reset_weights()
        self.n_resamples += 1
        return True

    def _replace_states(self, mask: np.ndarray, states: np.ndarray) -> None:
        """Overwrite the hypotheses where ``mask`` ``(N,)`` by ``states`` ``(3, count)`` float64 (augmented MCL)."""
        raise NotImplementedError

    def _resample_states(self, idx: np.ndarray) -> None:
        """Replace the state by the hypotheses ``idx`` ``(n,)`` and set ``self.n = n`` (weights are still the
        pre-resampling ones here)."""
        raise NotImplementedError

    # ---- estimate -----------------------------------------------------------------------------------
    def estimate(self, kind: str | None = None) -> np.ndarray:
        """Pose ``(3,)`` float64: weighted mean (circular mean for theta) or the highest-weight hypothesis."""
        kind = kind or self.config.estimator
        if kind == "best":
            if self._uniform:  # no hypothesis outweighs another (before the first reading; a step without readings after
                # a resampling): the mean, not whichever came first (a prior draw 2.6 m off read as the run's estimate)
                return self._mean_pose()
            return self._best_pose(int(np.argmax(self.weights)))
        if kind != "mean":
            raise ConfigError(f"unknown estimator {kind!r}; known: mean, best", source="estimator")
        return self._mean_pose()

    def _best_pose(self, i: int) -> np.ndarray:
        raise NotImplementedError

    def _mean_pose(self) -> np.ndarray:
        raise NotImplementedError


__all__ = ["LandmarkFilterBase", "check_landmark_index", "checked_odometry", "readings_array"]
