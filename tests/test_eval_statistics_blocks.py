"""Bootstrap resamples drawn in blocks: memory bounded by the block, bounds bit-identical to one draw of them all."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from lidarkit.eval import bootstrap_ci, statistics

# bounds of the bootstrap as it drew every resample at once (before blocks), for the values below
VALUES = np.linspace(0.0, 3.0, 100) ** 2 + np.sin(np.arange(100))
MEAN_CI_SEED_7 = (2.493391915993806, 3.5706981609740573)
MEDIAN_CI_SEED_7 = (1.5587681551444927, 3.2666104158823455)
SUMMARY_37_SEED_11 = (0.1734872852795005, 0.6644093819785768)


@pytest.mark.parametrize("block_indices", [None, 1000, 37])
def test_blocked_resamples_give_the_bounds_of_one_draw_bit_for_bit(block_indices, monkeypatch):
    """Blocks of rows take the generator's numbers in the order one draw of all rows took them, so the bounds a seed
    gave are the bounds it gives (None: the default block, one block for these sizes)."""
    if block_indices is not None:
        monkeypatch.setattr(statistics, "RESAMPLE_BLOCK_INDICES", block_indices)
    assert bootstrap_ci(VALUES, n_boot=5000, seed=7) == MEAN_CI_SEED_7
    assert bootstrap_ci(VALUES, n_boot=5000, seed=7, statistic="median") == MEDIAN_CI_SEED_7
    assert bootstrap_ci(VALUES[:37], n_boot=3001, seed=11) == SUMMARY_37_SEED_11


def test_bootstrap_memory_is_bounded_by_the_block_not_by_n_boot(monkeypatch):
    """All n_boot x N indices were drawn at once: summarize(np.random.rand(20000), n_boot=1_000_000) asked numpy for
    149 GiB (a MemoryError traceback), 2000 values would have taken 16 GB. With blocks of 1000 indices, 5000 resamples
    of 100 values (4 MB of indices and 4 MB of resampled values at once) stay within a few blocks and the statistics."""
    monkeypatch.setattr(statistics, "RESAMPLE_BLOCK_INDICES", 1000)
    tracemalloc.start()
    try:
        bounds = bootstrap_ci(VALUES, n_boot=5000, seed=7)
        peak_bytes = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert bounds == MEAN_CI_SEED_7
    assert peak_bytes < 500_000, f"peak {peak_bytes} bytes"
