"""benchmarks/compare_seeds.py's summary table: its header names the interval the CIs are."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from lidarkit.eval import summarize

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "compare_seeds.py"


@pytest.fixture(scope="module")
def compare_seeds():
    spec = importlib.util.spec_from_file_location("compare_seeds_script", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_summary_header_names_the_interval_summarize_used(compare_seeds):
    """"seeded 95 % bootstrap CI of the mean" was written whatever the seed count, while summarize gives Student-t's
    interval (`--seeds 5`): the header names the interval of the rows, Student-t's at 10 seeds too (0.55 -+ 2.262 x
    0.3028 / sqrt(10))."""
    ten = compare_seeds.summary_lines({"kiss": {"ape_rmse_m": summarize([0.1 * k for k in range(1, 11)], seed=0)}})
    assert ten[0] == "Per-method summaries over seeds (mean ± std, median, 95 % CI of the mean, Student-t):"
    assert ten[2:] == ["| method | metric | mean ± std | median | 95 % CI |", "|---|---|---:|---:|---:|",
                       "| kiss | ape_rmse_m | 0.55 ± 0.3 | 0.55 | [0.3334, 0.7666] |"]
    five = compare_seeds.summary_lines({"kiss": {"ape_rmse_m": summarize([0.1, 0.2, 0.3, 0.4, 0.5], seed=0)}})
    assert five[0] == "Per-method summaries over seeds (mean ± std, median, 95 % CI of the mean, Student-t):"
    assert five[-1] == "| kiss | ape_rmse_m | 0.3 ± 0.16 | 0.3 | [0.1037, 0.4963] |"
