"""One job written two ways in a suite (a dataset's number as 10 and 10.0, a default written out, a method's value in
params and in a grid) is refused with file and line, as identical duplicates are."""

from __future__ import annotations

import pytest

from lidarkit.bench.suite import load_suite
from lidarkit.errors import ConfigError


def _suite(tmp_path, datasets: str, methods: str = "[kiss]", task: str = "odometry"):
    path = tmp_path / "suite.yaml"
    path.write_text(f"experiments:\n  - task: {task}\n    datasets: {datasets}\n    methods: {methods}\n")
    return path


@pytest.mark.parametrize("datasets, why", [
    ("[{kind: sim_lidar, n_frames: 3, speed_mps: 10}, {kind: sim_lidar, n_frames: 3, speed_mps: 10.0}]",
     "speed_mps: 10 and 10.0 are one value"),
    ("[{kind: sim_lidar, n_frames: 3}, {kind: sim_lidar, n_frames: 3, scene: street}]", "scene: 'street' is its default"),
])
def test_one_dataset_written_two_ways_is_refused_naming_both(tmp_path, datasets, why):
    """10 and 10.0 gave one job key: the suite ran 1 job for 2 datasets without a word. A default written out gave two
    labels (``sim_lidar``, ``sim_lidar(scene=street)``): the same drive ran twice as two datasets."""
    path = _suite(tmp_path, datasets)
    with pytest.raises(ConfigError) as info:
        load_suite(path)
    assert str(info.value) == (f"{path} (experiments[0].datasets[1], line 3): duplicate dataset (also datasets[0], written "
                               f"another way: {why}): give it once")


def test_datasets_that_differ_stay_two_datasets(tmp_path):
    """Another scene, or a drive's own seed beside one the job's seed seeds, are other data: two datasets each."""
    suite = load_suite(_suite(tmp_path, "[{kind: sim_lidar, n_frames: 3}, {kind: sim_lidar, n_frames: 3, scene: open}, "
                                        "{kind: sim_lidar, n_frames: 3, seed: 0}]"))
    assert len(suite.jobs) == 3


def test_a_value_in_params_of_one_method_and_a_grid_of_another_is_refused(tmp_path):
    """The job both gave was left out once without a word (3 jobs written, 2 run)."""
    path = _suite(tmp_path, "[{kind: synthetic}]", task="selftest", methods=(
        "\n      - {name: random_walk, params: {noise_m: 0.1}}\n      - {name: random_walk, grid: {noise_m: [0.1, 0.2]}}"))
    with pytest.raises(ConfigError) as info:
        load_suite(path)
    assert str(info.value) == (f"{path} (experiments[0].methods[1], line 6): random_walk(noise_m=0.1) on synthetic runs the "
                               "same job as experiments[0].methods[0] (in params of one and a grid of the other, or in two "
                               "grids): give it once")
