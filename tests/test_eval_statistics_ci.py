"""The CI of the mean that summaries (and the bench report's "95 % CI" column) give at the seed counts benchmarks use."""

from __future__ import annotations

import numpy as np
import pytest

from lidarkit.eval import bootstrap_ci, summarize


@pytest.mark.parametrize("n", [2, 3, 5])
def test_the_95_percent_ci_of_a_few_seeds_holds_the_mean_95_percent_of_the_time(n):
    """A percentile bootstrap of 2 values is [min, max]: it held the true mean of normal data 52 % of the time (3
    values 72 %, 5 values 83 %), far from the 95 % the report's column claims."""
    true_mean, draws = 3.0, 400
    samples = np.random.default_rng(2026 + n).normal(true_mean, 0.5, size=(draws, n))
    summaries = [summarize(row, seed=0) for row in samples]
    bounds = np.array([(s.ci_low, s.ci_high) for s in summaries])
    coverage = float(np.mean((bounds[:, 0] <= true_mean) & (true_mean <= bounds[:, 1])))
    assert 0.92 <= coverage <= 0.98, f"{coverage:.3f} of {draws} {n}-value 95 % intervals hold the mean"
    assert {s.ci_method for s in summaries} == {"Student-t"}
    # the interval is mean +- t(0.975, n-1) * std / sqrt(n)
    t975 = {2: 12.7062047, 3: 4.30265273, 5: 2.77644511}[n]
    s = summaries[0]
    assert (s.ci_high - s.ci_low) / 2 == pytest.approx(t975 * s.std / np.sqrt(n), rel=1e-6)
    assert (s.ci_low + s.ci_high) / 2 == pytest.approx(s.mean)


def test_ten_or_more_values_keep_the_seeded_bootstrap_and_the_method_is_named():
    """From MIN_VALUES_FOR_BOOTSTRAP values on the interval is the seeded percentile bootstrap it was (the figures
    benchmarks/results/statistics documents over 10 seeds); fewer name Student-t, one value no method."""
    from lidarkit.eval.statistics import MIN_VALUES_FOR_BOOTSTRAP, ci_methods, t_interval

    values = np.random.default_rng(5).gamma(2.0, 0.5, size=MIN_VALUES_FOR_BOOTSTRAP)
    s = summarize(values, seed=0)
    assert (s.ci_low, s.ci_high) == bootstrap_ci(values, seed=0) and s.ci_method == "bootstrap"
    few = summarize(values[:4])
    assert (few.ci_low, few.ci_high) == t_interval(values[:4]) and few.ci_method == "Student-t"
    assert summarize([1.5]).ci_method == "" and (summarize([1.5]).ci_low, summarize([1.5]).ci_high) == (1.5, 1.5)
    assert summarize([2.0, 2.0, 2.0]).ci_low == summarize([2.0, 2.0, 2.0]).ci_high == 2.0  # equal values: zero width
    assert few.to_dict()["ci_method"] == "Student-t"
    assert ci_methods([s]) == "bootstrap" and ci_methods([few, None]) == "Student-t" and ci_methods([summarize([1.0])]) == ""
    assert ci_methods([few, s]) == "Student-t below 10 runs, bootstrap from 10"
