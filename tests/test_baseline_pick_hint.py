"""Which keywords of ``Baseline.job`` pick one of several pinned jobs: each that alone does, or those that do together."""

from __future__ import annotations

import re
import textwrap

import pytest

from lidarkit.bench.baseline import record
from lidarkit.errors import ConfigError


def test_keywords_that_each_pick_a_job_alone_are_offered_with_or(tmp_path):
    """Two experiments (sim, bag) over two datasets (st, mc) read "pick one with dataset= (st, mc) and experiment= (sim,
    bag)", as if both were needed: either alone picks one."""
    (tmp_path / "two.yaml").write_text(textwrap.dedent("""
        name: two
        experiments:
          - {name: sim, task: selftest, dataset: {kind: synthetic, name: st}, methods: [random_walk]}
          - {name: bag, task: selftest, dataset: {kind: synthetic, name: mc}, methods: [random_walk]}
    """))
    baseline = record(tmp_path / "two.yaml", tmp_path / "bl", repeats=1)
    with pytest.raises(ConfigError, match=re.escape("2 pinned jobs: pick one with dataset= (st, mc) or experiment= (sim, bag)")
                       + "$"):
        baseline.job()
    assert baseline.job(dataset="mc")["spec"]["experiment"] == baseline.job(experiment="bag")["spec"]["experiment"] == "bag"
