"""Task options: integers take integers only (YAML's true / false were read as 1 / 0), and what the docs say of them."""

from __future__ import annotations

import textwrap

import pytest

from lidarkit.bench.suite import load_suite
from lidarkit.bench.tasks import get_task
from lidarkit.errors import ConfigError


def test_odometry_frames_refuse_a_boolean_and_keep_their_text_form(tmp_path):
    """frames: [true, 2, 3] ran frames 1, 2, 3."""
    path = tmp_path / "suite.yaml"
    text = textwrap.dedent("""
        experiments:
          - task: odometry
            dataset: {kind: sim_lidar, n_frames: 5}
            options: {frames: FRAMES}
            methods: [vanilla]
        """)
    path.write_text(text.replace("FRAMES", "[true, 2, 3]"))
    with pytest.raises(ConfigError) as info:
        load_suite(path)
    assert str(info.value) == (
        f"{path} (experiments[0].options, line 5): frames: a list of frame indices holds True, not an integer (a slice "
        "is text: '0:10') (options of task 'odometry': frames, init)")
    for frames, selected in (("[0, 2, 3]", [0, 2, 3]), ('"0:3"', "0:3")):
        path.write_text(text.replace("FRAMES", frames))
        assert load_suite(path).jobs[0].options["frames"] == selected


def test_pf_and_vo_integer_options_refuse_booleans():
    """pf mse_start: true scored from step 1; vo max_frames: 2.0 ran as 2 and true was refused as "below 2"."""
    with pytest.raises(ConfigError, match=r"^options: mse_start: Input should be a valid integer \(options of task 'pf'"):
        get_task("pf").validate_options({"mse_start": True})
    assert get_task("pf").resolved_options({"mse_start": 3})["mse_start"] == 3
    pytest.importorskip("lidarkit.vo")
    for value in (True, 2.0):
        with pytest.raises(ConfigError, match=r"^options: max_frames: Input should be a valid integer \(options of "
                                              r"task 'vo'"):
            get_task("vo").validate_options({"max_frames": value})
    assert get_task("vo").resolved_options({"max_frames": 4})["max_frames"] == 4


def test_the_docs_icp_pair_row_says_what_a_zero_init_noise_starts_from():
    """The row read "seeded perturbed start": that 0 (the default) starts from the identity, and any value above 0 from
    the ground truth plus noise, was in the code only."""
    from pathlib import Path

    docs = Path(__file__).resolve().parents[1] / "docs" / "benchmarks.md"
    (row,) = [line for line in docs.read_text(encoding="utf-8").splitlines() if line.startswith("| `icp_pair` |")]
    assert "both 0, the default, start from the identity" in row
    assert "either above 0 starts from the ground-truth pose perturbed by a seeded random twist" in row
