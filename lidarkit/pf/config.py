"""Typed configuration of the particle filter; defaults live here and nowhere else."""

from __future__ import annotations

import math
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, ValidationError, ValidationInfo, field_validator, model_validator

from lidarkit.errors import ConfigError
from lidarkit.params import is_integer

LIKELIHOODS = ("all", "nearest")
ESTIMATORS = ("mean", "best")
INITS = ("gaussian", "uniform")


#: Smallest measurement variance (m^2, rad^2) Q may hold: below it the filter's float32 information matrix overflows.
MIN_Q_VARIANCE = 1e-30
#: Largest measurement variance (m^2, rad^2): a std of 1e6 (1000 km in range; a bearing is an angle) is no sensor, and
#: readings simulated with far more overflow the filter's float32 squares (1e40 ran 331 weight resets, exit 0).
MAX_Q_VARIANCE = 1e12
#: Largest magnitude of init_mean, init_std, uniform_margin_m and motion_noise_std (m or rad): 1000 km is past any landmark
#: map, like the kidnap offset's bound; 1e20 ran 331 weight resets (MSE 1e40, exit 0), 1e39 overflowed float32 to NaN.
MAX_POSE_SCALE = 1e6
#: Most particles a filter may hold (n_particles and the KLD counts): ~3.2 GiB at the filter's ~320 bytes a particle;
#: 3e9 failed in numpy's allocation (33.5 GiB), near 1e9 it would have been allocated.
MAX_PARTICLES = 10_000_000
#: Smallest KLD bin (m, and this many degrees as radians): the bin keys divide the poses by it; 1e-310 m overflowed its
#: reciprocal to inf (wrong bin counts) and 1e-308 the squares of the spread (NaN). No belief has nanometre structure.
MIN_KLD_BIN = 1e-9
#: Largest roughening constant K (jitter std = K x spread x N^(-1/3); Gordon et al. use ~0.2).
MAX_ROUGHENING = 10.0


def q_problem(q: tuple[float, ...], q_as: str) -> str | None:
    """Why ``q`` (read as ``q_as``) cannot be the measurement noise, or None: each variance must be in
    [MIN_Q_VARIANCE, MAX_Q_VARIANCE] (0 failed later as "Q must be symmetric positive definite"; 1e-40 ran a filter
    whose float32 information overflowed, no particle keeping a finite likelihood, one warning a step). A q that is
    not finite and >= 0 is left to the field's own check."""
    if not all(math.isfinite(x) and x >= 0 for x in q):
        return None
    variances = tuple(q) if q_as == "variance" else tuple(x * x for x in q)  # (1e200 squared is inf: above the bound)
    if min(variances) < MIN_Q_VARIANCE:
        return (f"q {tuple(q)} ({q_as}) gives a measurement variance of {min(variances):.3g}: each must be >= {MIN_Q_VARIANCE:g} "
                "(Q positive definite, its inverse finite in float32)")
    if max(variances) > MAX_Q_VARIANCE:
        return (f"q {tuple(q)} ({q_as}) gives a measurement variance of {max(variances):.3g}: each must be <= {MAX_Q_VARIANCE:g} "
                "(a std of 1e6 m or rad is no sensor; far noisier readings overflow the filter's float32)")
    return None


class PFConfig(BaseModel):
    """Particle-filter settings.

    ``q`` is the measurement noise [range, bearing] read as variances (``q_as="variance"``, default:
    Q is a covariance matrix) or standard deviations (``q_as="std"``). ``likelihood="nearest"`` uses one
    reading per step (the closest landmark) with its known landmark id (``nearest_association="known"``)
    or, as the report did, compared with each particle's own nearest landmark (``"per_particle"``:
    ambiguous, diverges with few particles). ``init_std`` are standard deviations: the report's
    ``x, y ~ N(0, 2)``, ``theta ~ N(0.1, 0.1)`` read as N(mean, variance), i.e. std sqrt(2) m and
    sqrt(0.1) rad. ``ess_threshold``: resample when ESS < threshold * N;
    ``>= 1`` resamples after every update (the report). ``roughening``: Gordon's constant K, jitter std
    K * spread_d * N^(-1/3) per state dimension after resampling (0 = off). ``regularization``: Liu-West
    kernel move with bandwidth h after resampling (keeps mean and covariance). ``moment_matching``:
    restore the pre-resampling weighted mean (and covariance) after resampling. ``antithetic``: motion
    noise in +/- pairs. ``kernel="kalman"``: each particle is a Gaussian kernel with its own EKF
    (:mod:`lidarkit.pf.kalman_kernel`), ``kernel_split`` = a (children get covariance a P); they run float64, and
    ``dtype`` (float32 by default, for point particles) reads float64 with them.
    ``innovation_gate`` (Kalman kernels): chi-square(2) threshold on a reading's Mahalanobis distance
    e^T S^-1 e; a kernel is not corrected by a reading beyond it (outlier rejection as EKF localization
    does it in practice; 9.21 = 99 %), the reading still enters its weight; 0 = off.
    ``recovery="reinit"``: when even the best particle fails the chi-square(2) 99.9% gate on a step
    (the filter is lost), spread all particles uniformly over the map and reweight them by that step's
    readings (global relocalization); otherwise lost steps are only counted and logged.

    ``augmented``: augmented MCL (Thrun et al., Probabilistic Robotics, 8.3.5): short- and long-term
    averages of the per-reading measurement likelihood (rates ``alpha_fast`` > ``alpha_slow``, bias
    corrected) and, at each resampling, every particle replaced with probability
    max(0, 1 - w_fast / w_slow) by a uniform draw over the map box (kidnapped-robot recovery).
    ``kld``: KLD-sampling (Fox 2003): each resampling draws as many particles as Fox's bound asks for
    the number k of (x, y, theta) bins the predicted set occupies, bins of size ``kld_bin_m`` x ``kld_bin_m`` x ``kld_bin_rad``
    (error ``kld_epsilon``, standard normal quantile ``kld_z``), clipped to [``kld_min_n``, ``kld_max_n``];
    ``n_particles`` is then only the initial count (point particles only). While the belief is not converged
    (weighted RMS position spread not yet below ``kld_converged_m`` on ``kld_converged_steps`` resamplings in
    a row: with two or three readings a step a narrow belief can sit ~1 m off for ~10 steps before the
    readings pull it in) the count stays at least ``kld_unconverged_n``:
    the bound counts bins of a set the likelihood has just collapsed, and a ~1 m wide posterior fills only
    ~50-100 bins (bound < 1000) while the sample that represents it is still thin (global localization).
    """

    model_config = ConfigDict(frozen=True, extra="forbid")

    n_particles: int = 1000
    kernel: Literal["point", "kalman"] = "point"
    kernel_split: float = 0.5
    innovation_gate: float = 0.0
    likelihood: Literal["all", "nearest"] = "all"
    nearest_association: Literal["known", "per_particle"] = "known"
    estimator: Literal["mean", "best"] = "mean"
    resampler: Literal["multinomial", "systematic", "stratified", "residual"] = "systematic"
    ess_threshold: float = 1.0
    roughening: float = 0.0
    antithetic: bool = False
    moment_matching: Literal["none", "mean", "mean_cov"] = "none"
    regularization: float = 0.0
    motion_noise_std: tuple[float, float, float] = (0.01, 0.1, 0.01)
    q: tuple[float, float] = (1.0, 0.1)
    q_as: Literal["variance", "std"] = "variance"
    init: Literal["gaussian", "uniform"] = "gaussian"
    init_mean: tuple[float, float, float] = (0.0, 0.0, 0.1)
    init_std: tuple[float, float, float] = (math.sqrt(2.0), math.sqrt(2.0), math.sqrt(0.1))
    uniform_margin_m: float = 2.0
    recovery: Literal["none", "reinit"] = "none"
    augmented: bool = False
    alpha_slow: float = 0.001
    alpha_fast: float = 0.1
    kld: bool = False
    kld_epsilon: float = 0.05
    kld_z: float = 2.326  # upper 1% standard normal quantile (1 - delta = 0.99)
    kld_bin_m: float = 0.5
    kld_bin_rad: float = math.radians(10.0)
    kld_min_n: int = 200
    kld_max_n: int = 5000
    kld_unconverged_n: int = 1000
    kld_converged_m: float = 0.4
    kld_converged_steps: int = 10
    dtype: Literal["float32", "float64"] = "float32"
    noise_block_elements: int = 1 << 17  # motion noise drawn for this many numbers at once (cache-sized)

    @field_validator("n_particles", "kld_min_n", "kld_max_n", "kld_unconverged_n", "kld_converged_steps", mode="before")
    @classmethod
    def _not_a_bool(cls, v, info: ValidationInfo):
        if isinstance(v, bool):  # (True was read as 1: a one-particle filter, a KLD floor of one particle)
            raise ValueError(f"{info.field_name} must be an integer >= 1, got {v!r}")
        return v

    @field_validator("noise_block_elements", mode="before")
    @classmethod
    def _block_size(cls, v):
        if not is_integer(v) or v < 1:  # (-5, 0 and True were written to config.yaml; the filter drew blocks of 1)
            raise ValueError(f"must be an integer >= 1, got {v!r}")
        return v

    @field_validator("n_particles")
    @classmethod
    def _positive_n(cls, v: int) -> int:
        if not 1 <= v <= MAX_PARTICLES:  # (the CLI's bound: the library and the bench took 3e9 to numpy's MemoryError)
            raise ValueError(f"n_particles must be >= 1 and <= {MAX_PARTICLES}, got {v}")
        return v

    @field_validator("kld_min_n", "kld_max_n", "kld_unconverged_n")
    @classmethod
    def _particle_bound(cls, v: int) -> int:
        if v > MAX_PARTICLES:  # KLD-sampling grows the set up to these counts
            raise ValueError(f"must be <= {MAX_PARTICLES}, got {v}")
        return v

    @field_validator("alpha_slow", "alpha_fast", "kld_epsilon")
    @classmethod
    def _unit_rate(cls, v: float) -> float:
        if not (math.isfinite(v) and 0.0 < v <= 1.0):
            raise ValueError(f"must be in (0, 1], got {v}")
        return v

    @field_validator("kld_z", "kld_bin_m", "kld_bin_rad", "kld_converged_m")
    @classmethod
    def _positive(cls, v: float) -> float:
        if not (math.isfinite(v) and v > 0):
            raise ValueError(f"must be finite and > 0, got {v}")
        return v

    @field_validator("kld_bin_m", "kld_bin_rad")
    @classmethod
    def _bin_size(cls, v: float, info: ValidationInfo) -> float:
        if info.field_name == "kld_bin_m":
            smallest, unit = MIN_KLD_BIN, "m"
        else:  # (the command line takes degrees)
            smallest, unit = math.radians(MIN_KLD_BIN), f"rad ({MIN_KLD_BIN:g} deg)"
        if not (v >= smallest and math.isfinite(1.0 / v)):
            raise ValueError(f"must be >= {smallest:.4g} {unit}: the bin keys divide the poses by it, got {v:g}")
        return v

    @field_validator("kld_min_n", "kld_max_n", "kld_unconverged_n", "kld_converged_steps")
    @classmethod
    def _positive_count(cls, v: int) -> int:
        if v < 1:
            raise ValueError(f"must be >= 1, got {v}")
        return v

    @model_validator(mode="after")
    def _consistent(self) -> PFConfig:
        problem = q_problem(self.q, self.q_as)
        if problem:
            raise ValueError(problem)
        if self.augmented and not self.alpha_slow < self.alpha_fast:
            raise ValueError(f"augmented MCL needs alpha_slow < alpha_fast, got {self.alpha_slow} and {self.alpha_fast}")
        if self.kld and self.kld_min_n > self.kld_max_n:
            raise ValueError(f"kld_min_n {self.kld_min_n} > kld_max_n {self.kld_max_n}")
        if self.kld and self.n_particles > self.kld_max_n:  # (20000 ran above the 5000 its title said, without a word)
            raise ValueError(f"n_particles {self.n_particles} > kld_max_n {self.kld_max_n}: KLD-sampling starts from n_particles "
                             "and holds at most kld_max_n")
        if self.kld and self.kld_unconverged_n > self.kld_max_n:
            raise ValueError(f"kld_unconverged_n {self.kld_unconverged_n} > kld_max_n {self.kld_max_n}")
        if (self.kld or self.augmented) and self.kernel == "kalman":
            raise ValueError("KLD-sampling and augmented MCL need point particles (kernel='point')")
        if self.kernel == "kalman":  # the kernels resample by splitting: these moves of point particles would be ignored
            moves = [name for name, on in (("roughening", self.roughening > 0), ("regularization", self.regularization > 0),
                                           ("moment_matching", self.moment_matching != "none"), ("antithetic", self.antithetic)) if on]
            if moves:
                raise ValueError(f"{', '.join(moves)} move point particles; the Kalman kernels (kernel='kalman') resample by splitting")
            if "dtype" in self.model_fields_set and self.dtype == "float32":  # (accepted, then run in float64)
                raise ValueError("dtype float32 is for point particles; the Kalman kernels (kernel='kalman') run float64 (leave dtype unset)")
            # the dtype they run, so every record of the config says it (metrics.json said float32); left unset, so
            # replace(kernel="point") returns to the point particles' default
            self.__dict__["dtype"] = "float64"
        elif self.innovation_gate > 0:
            raise ValueError("innovation_gate gates the readings of the Kalman kernels (kernel='kalman'); point particles weigh every reading")
        return self

    @field_validator("roughening")
    @classmethod
    def _roughening_bound(cls, v: float) -> float:
        if v > MAX_ROUGHENING:  # (1e20 scattered the particles 1e37 m, one warning a step, exit 0)
            raise ValueError(f"must be <= {MAX_ROUGHENING:g} (Gordon's K is ~0.2), got {v:g}")
        return v

    @field_validator("kernel_split")
    @classmethod
    def _split_range(cls, v: float) -> float:
        if not 0.0 < v <= 1.0:
            raise ValueError(f"kernel_split must be in (0, 1], got {v}")
        return v

    @field_validator("regularization")
    @classmethod
    def _bandwidth(cls, v: float) -> float:
        if not 0.0 <= v < 1.0:
            raise ValueError(f"regularization bandwidth must be in [0, 1), got {v}")
        return v

    @field_validator("ess_threshold", "roughening", "uniform_margin_m", "innovation_gate")
    @classmethod
    def _non_negative(cls, v: float) -> float:
        if not math.isfinite(v) or v < 0:
            raise ValueError(f"must be finite and >= 0, got {v}")
        return v

    @field_validator("init_mean")
    @classmethod
    def _finite(cls, v: tuple[float, ...]) -> tuple[float, ...]:
        if not all(math.isfinite(x) for x in v):  # (a NaN start ran 331 weight resets, then failed naming the estimate)
            raise ValueError(f"values must be finite, got {v}")
        return v

    @field_validator("init_mean", "init_std", "motion_noise_std", "uniform_margin_m")
    @classmethod
    def _pose_scale(cls, v):
        if any(abs(x) > MAX_POSE_SCALE for x in (v if isinstance(v, tuple) else (v,))):
            raise ValueError(f"values must be at most {MAX_POSE_SCALE:g} in magnitude (m or rad: 1000 km is past any map), got {v}")
        return v

    @field_validator("q", "motion_noise_std", "init_std")
    @classmethod
    def _finite_non_negative(cls, v: tuple[float, ...]) -> tuple[float, ...]:
        if not all(math.isfinite(x) and x >= 0 for x in v):
            raise ValueError(f"values must be finite and >= 0, got {v}")
        return v

    def __init__(self, /, **values: Any) -> None:
        """Invalid values raise ConfigError naming the setting (docs/particle_filter.md constructs PFConfig directly,
        where pydantic's ValidationError spanned lines and a URL)."""
        try:
            super().__init__(**values)
        except ValidationError as err:
            raise _config_error(err) from None

    @classmethod
    def make(cls, **values) -> PFConfig:
        """Validated config; invalid values raise ConfigError (as ``PFConfig(**values)`` does)."""
        return cls(**values)

    def particle_count_label(self) -> str:
        """The particle count as titles say it: KLD-sampling's range (``n_particles`` is only its start, which may be
        below ``kld_min_n``: the range then starts there), else N."""
        return f"{min(self.n_particles, self.kld_min_n):,}..{self.kld_max_n:,} (KLD)" if self.kld else f"{self.n_particles:,}"

    def replace(self, **changes) -> PFConfig:
        """A copy with ``changes``; the settings left at their defaults stay unset (so kernel='kalman' is no clash with
        the point particles' default dtype)."""
        return PFConfig.make(**{**self.model_dump(exclude_unset=True), **changes})


def _config_error(err: ValidationError) -> ConfigError:
    """The ConfigError of a PFConfig's first problem: an unknown setting with the valid ones, else the setting, the
    reason and the value given."""
    first = err.errors()[0]
    field = ".".join(str(p) for p in first.get("loc", ()))
    if first.get("type") == "extra_forbidden":  # (it said "Extra inputs are not permitted", naming no valid one)
        return ConfigError(f"unknown setting {field!r}; valid: {', '.join(sorted(PFConfig.model_fields))}", source="pf config")
    msg = str(first.get("msg", "invalid value")).removeprefix("Value error, ")
    if field and "got" not in msg:  # (a rule across fields names its values itself: no dump of the config)
        msg = f"{msg} (got {first.get('input')!r})"
    return ConfigError(msg, source=f"pf config {field}" if field else "pf config")


__all__ = ["ESTIMATORS", "INITS", "LIKELIHOODS", "MAX_PARTICLES", "MAX_POSE_SCALE", "MAX_Q_VARIANCE", "MAX_ROUGHENING", "MIN_KLD_BIN", "MIN_Q_VARIANCE", "PFConfig", "q_problem"]
