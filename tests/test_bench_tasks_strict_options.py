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
    for frames, selected in (("[0, 2, 3]", [0, 2, 3]), ("[0, 2.0, 3]", [0, 2, 3]), ('"0:3"', "0:3")):
        path.write_text(text.replace("FRAMES", frames))
        recorded = load_suite(path).jobs[0].options["frames"]
        assert recorded == selected and [type(f) for f in recorded] == [type(f) for f in selected]
    path.write_text(text.replace("FRAMES", "[0, 2.5, 3]"))
    with pytest.raises(ConfigError, match=r"line 5\): frames: a list of frame indices holds 2.5, not an integer"):
        load_suite(path)


def test_pf_and_vo_integer_options_refuse_booleans_and_fractions():
    """pf mse_start: true scored from step 1; vo max_frames: true was refused as "below 2". A whole float is its
    integer (2.0 was refused, where a job key already read it as 2); a fraction is not."""
    with pytest.raises(ConfigError, match=r"^options: mse_start: Input should be a valid integer \(options of task 'pf'"):
        get_task("pf").validate_options({"mse_start": True})
    assert get_task("pf").resolved_options({"mse_start": 3})["mse_start"] == 3
    assert get_task("pf").resolved_options({"mse_start": 3.0})["mse_start"] == 3
    pytest.importorskip("lidarkit.vo")
    for value in (True, 2.5, "2"):
        with pytest.raises(ConfigError, match=r"^options: max_frames: Input should be a valid integer \(options of "
                                              r"task 'vo'"):
            get_task("vo").validate_options({"max_frames": value})
    assert get_task("vo").resolved_options({"max_frames": 4})["max_frames"] == 4
    resolved = get_task("vo").resolved_options({"max_frames": 4.0})["max_frames"]
    assert resolved == 4 and type(resolved) is int


_PAIRS_SUITE = """
seeds: SEEDS
experiments:
  - task: icp_pair
    dataset: {kind: sim_lidar, n_frames: 3, n_beams: 8, n_azimuths: 360, seed: 1, name: sim}
    options: {max_pairs: MAX_PAIRS}
    methods: [vanilla]
"""


def _pairs_suite(path, seeds, max_pairs):
    path.write_text(_PAIRS_SUITE.replace("SEEDS", seeds).replace("MAX_PAIRS", max_pairs))
    return path


def test_a_whole_float_in_a_suite_is_its_integer_in_the_jobs_results_and_keys(tmp_path):
    """max_pairs: 2.0 and seeds: 2.0 were refused ("Input should be a valid integer") though a job key read 2.0 as 2:
    they run as 2, are recorded as 2, and a suite written with 2 finds their results."""
    import json

    from lidarkit.bench import load_suite as load, run_suite

    floats = load(_pairs_suite(tmp_path / "floats.yaml", "2.0", "2.0"))
    ints = load(_pairs_suite(tmp_path / "ints.yaml", "2", "2"))
    assert [job.seed for job in floats.jobs] == [0, 1]
    assert [job.key() for job in floats.jobs] == [job.key() for job in ints.jobs]
    assert all(job.options == {"max_pairs": 2} and type(job.options["max_pairs"]) is int for job in floats.jobs)
    first = run_suite(floats, tmp_path / "out", executor="serial")
    assert (first.ran, first.ok) == (2, 2)
    for result in sorted((tmp_path / "out" / "jobs").glob("*.json")):
        record = json.loads(result.read_text())
        recorded = record["job"]["options"]["max_pairs"]
        assert recorded == 2 and type(recorded) is int  # (JSON's 2, not 2.0)
        assert [(p["target"], p["source"]) for p in record["info"]["pairs"]] == [(0, 1), (1, 2)]
    again = run_suite(ints, tmp_path / "out", executor="serial")
    assert (again.skipped, again.ran) == (2, 0)


@pytest.mark.parametrize("seeds, max_pairs, where", [
    ("1", "2.5", "max_pairs"), ("1", "true", "max_pairs"), ("1", '"2"', "max_pairs"),
    ("2.5", "2", "seeds"), ("false", "2", "seeds"), ("[0, 1.5]", "2", "seeds[1]"),
])
def test_a_fraction_a_boolean_or_text_where_an_integer_counts_is_one_line_naming_it(tmp_path, seeds, max_pairs, where):
    path = _pairs_suite(tmp_path / "suite.yaml", seeds, max_pairs)
    with pytest.raises(ConfigError) as info:
        load_suite(path)
    message = str(info.value)
    assert message.startswith(f"{path} (") and "\n" not in message
    assert f"{where}: Input should be a valid integer" in message


def test_the_docs_icp_pair_row_says_what_a_zero_init_noise_starts_from():
    """The row read "seeded perturbed start": that 0 (the default) starts from the identity, and any value above 0 from
    the ground truth plus noise, was in the code only."""
    from pathlib import Path

    docs = Path(__file__).resolve().parents[1] / "docs" / "benchmarks.md"
    (row,) = [line for line in docs.read_text(encoding="utf-8").splitlines() if line.startswith("| `icp_pair` |")]
    assert "both 0, the default, start from the identity" in row
    assert "either above 0 starts from the ground-truth pose perturbed by a seeded random twist" in row
