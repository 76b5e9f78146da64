"""Experiment names are checked for duplicates as the jobs carry them: a default name (task and index) included."""

from __future__ import annotations

import textwrap
from collections import Counter

import pytest

from lidarkit.bench.suite import load_suite
from lidarkit.errors import ConfigError

TWO = """
experiments:
  - {first}
    task: selftest
    dataset: {{kind: synthetic, name: syn}}
    seeds: [0, 1]
    methods: [{{name: random_walk, params: {{noise_m: 0.05}}}}]
  - {second}
    task: selftest
    dataset: {{kind: synthetic, name: syn}}
    seeds: [0, 1, 2, 3]
    methods: [{{name: random_walk, params: {{noise_m: 0.05}}}}, {{name: random_walk, params: {{noise_m: 0.5}}}}]
"""


def write(tmp_path, first, second):
    path = tmp_path / "suite.yaml"
    path.write_text(textwrap.dedent(TWO.format(first=first, second=second)))
    return path


def test_an_explicit_name_equal_to_another_experiments_default_name_is_refused(tmp_path):
    """experiments[0] named 'selftest_1' and an unnamed experiments[1] (default name selftest_1) were merged into one
    experiment silently: its seeds 0 and 1 of noise 0.05 kept once, the report one row over both."""
    path = write(tmp_path, "name: selftest_1", "name: null")
    with pytest.raises(ConfigError) as info:
        load_suite(path)
    assert str(info.value) == (
        f"{path} (experiments[1], line 8): duplicate experiment name 'selftest_1': the default name of experiments[1] "
        "(its task and index) is the name of experiments[0]; give experiments[1] a name of its own")

    path = write(tmp_path, "name: null", "name: selftest_0")
    with pytest.raises(ConfigError) as info:
        load_suite(path)
    assert str(info.value) == (
        f"{path} (experiments[1].name, line 8): duplicate experiment name 'selftest_0' (also the default name of "
        "experiments[0], its task and index): give one of them a name of its own")

    suite = load_suite(write(tmp_path, "name: selftest_1", "name: selftest_0"))  # (each its own name: both run)
    assert Counter(job.experiment for job in suite.jobs) == {"selftest_1": 2, "selftest_0": 8}
