"""Statistics over runs: summaries with confidence intervals of the mean and paired significance tests.

A single run of an odometry method is one draw: seeds, data excerpts and (for kiss-icp, which is not
bit-reproducible across thread schedules) the run itself vary. ``summarize`` turns the runs of one
(method, dataset) into mean, std, median and Student-t's CI of the mean at any count (a percentile bootstrap of the
mean is too narrow at the seed counts benchmarks use); ``paired_test`` compares two
methods on the *same* units (seeds, KITTI segments, frames) with the Wilcoxon signed-rank test, because
per-unit differences are rarely normal and one bad seed should not decide the verdict.
"""

from __future__ import annotations

import math
import reprlib
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from lidarkit.errors import ConfigError, EvaluationError
from lidarkit.params import is_integer, is_real_number

DEFAULT_CONFIDENCE = 0.95
DEFAULT_N_BOOT = 2000
DEFAULT_ALPHA = 0.05
#: differences smaller than this fraction of the values' scale are floating-point noise and count as ties
RELATIVE_TIE_TOLERANCE = 1e-9


def _finite(values: Any, source: str) -> np.ndarray:
    """``values`` ``(N,)`` as a float array. ConfigError for what is not a flat sequence of numbers (numeric text was read
    as numbers, a 2-D array flattened: its rows pooled as runs), EvaluationError for non-finite values."""
    try:
        arr = np.asarray(values)
    except (TypeError, ValueError):  # (ragged nesting)
        arr = None
    # (True among numbers was counted as 1: numpy makes [1, True, 3] an integer array)
    if arr is None or arr.dtype.kind not in "iuf" or (arr.dtype.kind in "iu" and arr.ndim == 1 and not isinstance(
            values, np.ndarray) and any(isinstance(v, (bool, np.bool_)) for v in values)):
        raise ConfigError(f"values must be numbers, got {reprlib.repr(values)}", source=source)
    if arr.ndim != 1:
        raise ConfigError(f"values must be a flat sequence of numbers, got an array of shape {arr.shape}", source=source)
    arr = arr.astype(np.float64)
    if arr.size and not np.isfinite(arr).all():
        raise EvaluationError(f"{int((~np.isfinite(arr)).sum())} non-finite value(s) among {arr.size}", source=source)
    return arr


#: the most bootstrap resamples drawn: bounds the run time (memory is bounded by the blocks below)
MAX_N_BOOT = 1_000_000
#: resample indices drawn per block of a bootstrap (80 MB of int64): 10**6 resamples of 20000 values drawn at once
#: asked numpy for 149 GiB
RESAMPLE_BLOCK_INDICES = 10_000_000
#: the interval :func:`summarize` gives the mean at any count. A percentile bootstrap of the mean is too narrow at the
#: seed counts benchmarks use: of 2 values it is [min, max], which held the mean of normal data 52 % of the time for a
#: "95 %" interval (5 values 83 %, 10 values 89.5 %, 15 values 91 %; Student-t 95 % at each)
STUDENT_T = "Student-t"
#: the name of a percentile bootstrap interval (:func:`bootstrap_ci`: the CI of a paired test's median difference)
BOOTSTRAP = "bootstrap"


def check_number(value: object, name: str) -> float:
    """``value`` as a float when it is a real number (not text, None or a bool: alpha="0.05" was a TypeError
    traceback); ConfigError naming ``name`` otherwise."""
    if not is_real_number(value):
        raise ConfigError(f"{name} must be a number, got {value!r}", source=name)
    return float(value)


def check_seed(seed: object) -> None:
    """A bootstrap seed: an integer >= 0 (numpy's generator took -1 as a ValueError traceback, 1.5 as a TypeError)."""
    if not is_integer(seed) or seed < 0:
        raise ConfigError(f"seed must be an integer >= 0, got {seed!r}", source="seed")


def check_bootstrap_args(confidence: object, n_boot: object, seed: object, statistic: object = "mean") -> None:
    """ConfigError naming the first bad argument of a bootstrap (:func:`summarize` checks them too, so that its
    arguments are refused alike whatever it computes)."""
    if not 0.0 < check_number(confidence, "confidence") < 1.0:
        raise ConfigError(f"confidence must be in (0, 1), got {confidence}", source="confidence")
    if not is_integer(n_boot) or not 1 <= n_boot <= MAX_N_BOOT:
        raise ConfigError(f"n_boot must be an integer in [1, {MAX_N_BOOT}], got {n_boot!r}", source="n_boot")
    if statistic not in ("mean", "median"):
        raise ConfigError(f"statistic must be 'mean' or 'median', got {statistic!r}", source="statistic")
    check_seed(seed)


def bootstrap_ci(
    values: Any,
    *,
    confidence: float = DEFAULT_CONFIDENCE,
    n_boot: int = DEFAULT_N_BOOT,
    seed: int = 0,
    statistic: str = "mean",
) -> tuple[float, float]:
    """Percentile bootstrap CI of the mean (or ``statistic="median"``) of ``values`` ``(N,)``.

    The resamples are drawn in sequence from ``numpy.random.default_rng(seed)``: the same values and seed give
    bit-identical bounds. One value gives a zero-width interval at that value.
    """
    check_bootstrap_args(confidence, n_boot, seed, statistic)
    arr = _finite(values, "bootstrap")
    if arr.size == 0:
        raise EvaluationError("no values to bootstrap", source="bootstrap")
    if arr.size == 1:
        return float(arr[0]), float(arr[0])
    stats = _resample_statistics(arr, int(n_boot), np.random.default_rng(seed), statistic)
    tail = 100.0 * (1.0 - confidence) / 2.0
    lo, hi = np.percentile(stats, [tail, 100.0 - tail])
    return float(lo), float(hi)


def _resample_statistics(arr: np.ndarray, n_boot: int, rng: np.random.Generator, statistic: str) -> np.ndarray:
    """The ``statistic`` of ``n_boot`` resamples of ``arr`` ``(n_boot,) float64``, drawn in blocks of rows of about
    :data:`RESAMPLE_BLOCK_INDICES` indices so that memory stays bounded; the generator's stream is consumed in the
    same order as one draw of all rows, so the values equal those of drawing them at once."""
    rows_per_block = max(1, RESAMPLE_BLOCK_INDICES // arr.size)
    stats = np.empty(n_boot)
    for start in range(0, n_boot, rows_per_block):
        rows = min(rows_per_block, n_boot - start)
        samples = arr[rng.integers(0, arr.size, size=(rows, arr.size))]
        stats[start:start + rows] = samples.mean(axis=1) if statistic == "mean" else np.median(samples, axis=1)
        del samples  # (else it sits beside the next block's draw: three blocks' memory instead of two)
    return stats


def t_interval(values: Any, *, confidence: float = DEFAULT_CONFIDENCE) -> tuple[float, float]:
    """Student-t CI of the mean of ``values`` ``(N,)``: the right width at any N >= 2 for normal values, where a
    percentile bootstrap of a few values is far too narrow. One value, or equal values, give a zero-width interval at
    the mean."""
    from scipy import stats as sstats

    if not 0.0 < check_number(confidence, "confidence") < 1.0:
        raise ConfigError(f"confidence must be in (0, 1), got {confidence}", source="confidence")
    arr = _finite(values, "t_interval")
    if arr.size == 0:
        raise EvaluationError("no values for a confidence interval", source="t_interval")
    mean = float(arr.mean())
    if arr.size == 1 or np.ptp(arr) == 0:  # (numpy's std of equal floats is 8.5e-18, not 0)
        return mean, mean
    half = float(sstats.t.ppf(0.5 + confidence / 2.0, arr.size - 1)) * float(arr.std(ddof=1)) / math.sqrt(arr.size)
    return mean - half, mean + half


@dataclass(frozen=True)
class Summary:
    """Mean, sample std, median and CI of the mean of ``n`` runs; ``ci_method`` names the interval: ``"Student-t"``
    from 2 runs on, ``""`` for fewer (no interval). ``n_boot`` and ``seed`` are the arguments given, kept for the
    readers of written summaries; the interval draws nothing."""

    n: int
    mean: float
    std: float
    median: float
    ci_low: float
    ci_high: float
    confidence: float = DEFAULT_CONFIDENCE
    n_boot: int = DEFAULT_N_BOOT
    seed: int = 0
    ci_method: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in asdict(self).items()}

    def format(self, digits: int = 4) -> str:
        """``mean ± std [ci_low, ci_high]`` (the mean alone for one run)."""
        if self.n == 0:
            return "–"
        if self.n == 1:
            return f"{self.mean:.{digits}g}"
        return f"{self.mean:.{digits}g} ± {self.std:.2g} [{self.ci_low:.{digits}g}, {self.ci_high:.{digits}g}]"


def summarize(
    values: Any, *, confidence: float = DEFAULT_CONFIDENCE, n_boot: int = DEFAULT_N_BOOT, seed: int = 0
) -> Summary:
    """Summary of the runs' values ``(N,)``; no values gives ``n == 0`` and NaNs. The CI of the mean is Student-t's
    at every count: a percentile bootstrap held the mean 89.5 % of the time at 10 values for a "95 %" interval, and
    adding a 10th seed narrowed the interval by a quarter (normal data) where the method switched."""
    arr = _finite(values, "summarize")
    check_bootstrap_args(confidence, n_boot, seed)
    if arr.size == 0:
        nan = float("nan")
        return Summary(0, nan, nan, nan, nan, nan, float(confidence), int(n_boot), int(seed))
    (lo, hi), method = t_interval(arr, confidence=confidence), STUDENT_T if arr.size > 1 else ""
    std = float(arr.std(ddof=1)) if arr.size > 1 and np.ptp(arr) > 0 else 0.0  # equal values: 0, not numpy's 8.5e-18
    return Summary(int(arr.size), float(arr.mean()), std, float(np.median(arr)), lo, hi, float(confidence), int(n_boot),
                   int(seed), method)  # (numpy scalars as plain numbers: to_dict() is for JSON)


def ci_methods(summaries: Any) -> str:
    """The interval methods of ``summaries`` for a column header: ``"Student-t"`` (what :func:`summarize` gives), the
    methods named in ``summaries`` built otherwise joined by ", "; ``""`` when none has an interval."""
    return ", ".join(sorted({s.ci_method for s in summaries if s is not None and s.ci_method}))


@dataclass(frozen=True)
class PairedComparison:
    """Wilcoxon signed-rank comparison of ``a`` and ``b`` over ``n_pairs`` matched units.

    ``diff = a - b`` per unit; ``diff_ci_low``/``diff_ci_high``: bootstrap CI of its median. ``effect_size`` is the
    matched-pairs rank-biserial correlation in [-1, 1] (positive: ``a`` larger; +-1: every unit agrees). ``better``
    is ``"a"``, ``"b"`` or ``""`` (no significant difference, or the median difference is within ``noise``); its
    direction is the rank test's (the sign of ``effect_size``), never the mean's, which one unit can turn. ``noise``
    is the run-to-run noise of the metric the verdict was held against (0 when none was measured).
    """

    name_a: str
    name_b: str
    metric: str
    pairing: str
    n_pairs: int
    n_ties: int
    mean_a: float
    mean_b: float
    mean_diff: float
    median_diff: float
    diff_ci_low: float
    diff_ci_high: float
    statistic: float
    p_value: float
    effect_size: float
    alpha: float
    noise: float
    lower_is_better: bool
    better: str
    note: str = ""
    """What the reader should know about the pairing (e.g. each run scored against its own instant of the sweep)."""
    repeated: bool = False
    """Every seed gave the same value on each side (a deterministic method on fixed data): one measurement repeated,
    not independent units, so no test is made."""
    metric_label: str = ""
    """What ``metric`` measures as the report labels it ("APE RMSE (SE(3)-aligned)"; two APEs of one task read alike
    by name); "" when there is no label beyond the name."""

    @property
    def significant(self) -> bool:
        return bool(self.better)

    @property
    def metric_text(self) -> str:
        """The metric's name with its label: ``ape_se3_rmse_m [APE RMSE (SE(3)-aligned)]``."""
        return f"{self.metric} [{self.metric_label}]" if self.metric_label else self.metric

    def verdict(self) -> str:
        """One plain sentence for a reader: who is better and how sure, or that no difference shows."""
        m, unit = self.metric_text, f"over {self.n_pairs} paired {self.pairing}s"
        p = p_text(self.p_value, self.alpha)
        if self.better:
            win, lose = (self.name_a, self.name_b) if self.better == "a" else (self.name_b, self.name_a)
            text = (f"{win} is better than {lose} on {m}: median difference {self.median_diff:+.3g} "
                    f"(95% CI [{self.diff_ci_low:+.3g}, {self.diff_ci_high:+.3g}]), mean {self.mean_a:.4g} vs {self.mean_b:.4g}, "
                    f"Wilcoxon {p}, effect size {self.effect_size:+.2f}, {unit}")
            if self.mean_diff * self.effect_size < 0:
                text += f"; the mean difference ({self.mean_diff:+.3g}) points the other way: a few units differ a lot"
            return text
        why = f"Wilcoxon {p} >= {self.alpha:g}"
        if self.p_value < self.alpha and self.noise > 0 and abs(self.median_diff) <= self.noise:
            why = f"the median difference {self.median_diff:+.3g} is within the run-to-run noise (±{self.noise:.3g})"
        elif self.p_value < self.alpha and self.median_diff == 0:
            why = (f"the median difference is 0: {self.n_ties} of {self.n_pairs} {self.pairing}s are tied (the test ranks the "
                   f"{self.n_pairs - self.n_ties} others, effect size {self.effect_size:+.2f})")
        elif self.p_value < self.alpha and self.median_diff * self.effect_size < 0:
            why = (f"the ranks (effect size {self.effect_size:+.2f}) and the median difference ({self.median_diff:+.3g}) "
                   "disagree in direction")
        elif self.p_value < self.alpha and self.diff_ci_low <= 0 <= self.diff_ci_high:
            why = f"the 95% CI of the median difference [{self.diff_ci_low:+.3g}, {self.diff_ci_high:+.3g}] includes 0"
        n_ranked = self.n_pairs - self.n_ties
        smallest_p = 2.0 ** (1 - n_ranked) if n_ranked > 0 else 1.0  # exact two-sided: every unit on one side
        if self.p_value >= self.alpha and smallest_p >= self.alpha and n_ranked > 0:
            units = self.pairing + ("" if n_ranked == 1 else "s")  # ("with 1 differing seeds")
            why += (f"; with {n_ranked} differing {units} the smallest p this test can give is {smallest_p:.3g}: "
                    f"at least {min_units(self.alpha)} are needed to reach p < {self.alpha:g}")
        if self.n_ties == self.n_pairs:
            why = "every paired difference is zero (within floating-point noise)"
        if self.repeated:
            why = (f"each side gave the same value for every one of the {self.n_pairs} {self.pairing}s: the {self.pairing}s change "
                   "nothing here (deterministic methods on fixed data), so they are one measurement repeated, not "
                   f"{self.n_pairs} independent ones, and no test is made: more datasets or sequences make one, not more seeds")
        return (f"no significant difference between {self.name_a} and {self.name_b} on {m}: {why}; "
                f"mean {self.mean_a:.4g} vs {self.mean_b:.4g}, {unit}")

    def to_dict(self) -> dict[str, Any]:
        out = {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in asdict(self).items()}
        out["significant"] = self.significant
        out["verdict"] = self.verdict()
        return out


#: how a p-value that underflowed to 0.0 is printed: the true p is only too small for a double ("p = 0" was false)
P_UNDERFLOW_TEXT = "< 1e-300"


def format_p(p: float, alpha: float | None = None) -> str:
    """``p`` with the fewest digits (2 or more) that still compare with ``alpha`` as ``p`` does (0.0497 printed as
    "0.05" beside a winner at alpha 0.05); 3 digits without ``alpha``; :data:`P_UNDERFLOW_TEXT` for a p of 0."""
    if p <= 0:
        return P_UNDERFLOW_TEXT
    if alpha is None:
        return f"{p:.3g}"
    for digits in (2, 3, 4, 6):
        text = f"{p:.{digits}g}"
        if (float(text) < alpha) == (p < alpha):
            break
    return text


def p_text(p: float, alpha: float | None = None) -> str:
    """``"p = 0.031"``, ``"p = 1"``, or ``"p < 1e-300"`` for a p that underflowed (see :func:`format_p`)."""
    if p >= 1:
        return "p = 1"
    text = format_p(p, alpha)
    return f"p {text}" if text.startswith("<") else f"p = {text}"


def min_units(alpha: float) -> int:
    """The fewest differing units whose smallest two-sided exact Wilcoxon p (``2 ** (1 - n)``, every unit on one side)
    is strictly below ``alpha`` (alpha 0.25 needs 4: 3 units give p = 0.25 at best)."""
    return math.floor(1 - math.log2(alpha)) + 1


def tie_tolerance(a: np.ndarray, b: np.ndarray) -> float:
    """Differences up to this are ties: ``RELATIVE_TIE_TOLERANCE`` of the largest value of either side (two runs of
    one deterministic method differ by round-off only). For one value against another; pairs of many units are tied
    each at its own scale (:func:`paired_ties`)."""
    return RELATIVE_TIE_TOLERANCE * max(float(np.max(np.abs(np.concatenate([a, b])))), 1e-300)


def paired_ties(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``(N,) bool``: the units whose ``a[i]`` and ``b[i]`` differ by round-off only, within ``RELATIVE_TIE_TOLERANCE``
    of the larger of the two. Each pair at its own scale: one diverged seed at 3e4 made the tolerance 3e-5 for all, and
    ten seeds 2e-5 apart became ties (p = 1 where the test gives 0.002)."""
    return np.abs(a - b) <= RELATIVE_TIE_TOLERANCE * np.maximum(np.abs(a), np.abs(b))


def spread_is_round_off(values: np.ndarray) -> bool:
    """Whether ``values`` ``(N,)`` of one side are one value up to round-off: their spread within
    ``RELATIVE_TIE_TOLERANCE`` of their own largest magnitude (the other side's scale does not widen it)."""
    return bool(values.size == 0 or np.ptp(values) <= tie_tolerance(values, values))


def paired_test(
    a: Any,
    b: Any,
    *,
    name_a: str = "a",
    name_b: str = "b",
    metric: str = "error",
    pairing: str = "seed",
    lower_is_better: bool = True,
    alpha: float = DEFAULT_ALPHA,
    noise: float = 0.0,
    seed: int = 0,
    repeated: bool | None = None,
) -> PairedComparison:
    """Compare matched values ``a[i]`` and ``b[i]`` (same seed / segment / frame) with the Wilcoxon signed-rank test.

    Differences within ``RELATIVE_TIE_TOLERANCE`` of the pair's larger value are ties (two runs of one deterministic
    method differ by round-off only) and are dropped as Wilcoxon does; all ties give p = 1. A difference is
    called significant when p < ``alpha`` and the median difference exceeds ``noise`` (the measured run-to-run
    noise, same unit as the metric) in the direction of the ranks; the better side is the one the ranks favour.
    """
    from scipy import stats as sstats

    alpha, noise = check_number(alpha, "alpha"), check_number(noise, "noise")
    if not isinstance(lower_is_better, (bool, np.bool_)):  # ("no" was read as true)
        raise ConfigError(f"lower_is_better must be True or False, got {lower_is_better!r}", source="lower_is_better")
    if repeated is not None and not isinstance(repeated, (bool, np.bool_)):
        raise ConfigError(f"repeated must be True, False or None, got {repeated!r}", source="repeated")
    va, vb = _finite(a, name_a), _finite(b, name_b)
    if va.shape != vb.shape:
        raise EvaluationError(f"paired values differ in count: {va.size} for {name_a}, {vb.size} for {name_b}",
                              source=metric)
    if va.size < 2:
        more = {"seed": " (a suite's `seeds: N` over seeded data, more datasets or sequences over fixed data such as KITTI: "
                        "2 or more, 6 or more for p < 0.05)",
                "dataset": " (more datasets or sequences: 2 or more, 6 or more for p < 0.05)",
                "segment": " (longer paths, or compare per frame: --metric rpe_translation_m)"}.get(pairing, "")
        raise EvaluationError(f"a paired test needs at least 2 matched {pairing}s, got {va.size}{more}", source=metric)
    if not 0.0 < alpha < 1.0:
        raise ConfigError(f"alpha must be in (0, 1), got {alpha}", source="alpha")
    check_seed(seed)
    if noise < 0 or not math.isfinite(noise):
        raise ConfigError(f"noise must be a finite value >= 0, got {noise}", source="noise")
    diff = va - vb
    tie = paired_ties(va, vb)
    diff = np.where(tie, 0.0, diff)
    nz = diff[~tie]
    if nz.size == 0:
        statistic, p_value, effect = 0.0, 1.0, 0.0
    else:
        res = sstats.wilcoxon(nz, zero_method="wilcox", alternative="two-sided")
        statistic, p_value = float(res.statistic), float(res.pvalue)
        ranks = sstats.rankdata(np.abs(nz))
        effect = float((ranks[nz > 0].sum() - ranks[nz < 0].sum()) / ranks.sum())
    # a median of differences of opposite signs that cancel up to round-off is 0, as a tie is (a CI printed as
    # [-0.605, -2.22e-16] excluded 0 by round-off alone and let a verdict stand); at the typical pair's scale (one
    # diverged seed at 3e4 would make differences of 2e-5 round-off)
    round_off = RELATIVE_TIE_TOLERANCE * float(np.median(np.maximum(np.abs(va), np.abs(vb))))
    lo, hi, median_diff = (0.0 if abs(x) <= round_off else x
                           for x in (*bootstrap_ci(diff, seed=seed, statistic="median"), float(np.median(diff))))
    better = ""
    # seeds that change nothing on either side are one measurement repeated: any constant difference would rank as
    # "significant" (6 copies of one value gave p = 0.031); ``repeated`` given by a caller that knows the seeds ran
    # other data (a count that is 0 and 7 on every one of 6 drives is six measurements, not one)
    if repeated is None:
        repeated = pairing == "seed" and spread_is_round_off(va) and spread_is_round_off(vb)
    # the direction is the ranks' (what the test tested); the median must agree with it, exceed the noise, and its
    # bootstrap CI must not include 0 (a verdict beside a CI of [-0.0006, +0.0044], or of [+0, +2], read as a contradiction)
    ci_clear = not lo <= 0 <= hi
    if p_value < alpha and effect * median_diff > 0 and abs(median_diff) > noise and ci_clear and not repeated:
        a_lower = effect < 0
        better = "a" if a_lower == lower_is_better else "b"
    return PairedComparison(
        name_a=name_a, name_b=name_b, metric=metric, pairing=pairing, n_pairs=int(va.size), n_ties=int(tie.sum()),
        mean_a=float(va.mean()), mean_b=float(vb.mean()), mean_diff=float(diff.mean()), median_diff=median_diff,
        diff_ci_low=lo, diff_ci_high=hi, statistic=statistic, p_value=p_value, effect_size=effect, alpha=alpha,
        noise=float(noise), lower_is_better=bool(lower_is_better), better=better, repeated=bool(repeated),
    )
