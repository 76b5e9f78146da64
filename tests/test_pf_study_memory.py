"""A study checks every particle count (its bound and its memory) before its first run."""

from __future__ import annotations

import pytest
from conftest import shared_path

from lidarkit.errors import ConfigError
from lidarkit.io.landmarks import LandmarkData
from lidarkit.pf.study import run_study


def test_a_study_refuses_a_count_past_the_bound_before_its_first_run():
    """[300, 20_000_000] ran every N=300 seed, then failed on the 10,000,000 bound."""
    runs = []
    with pytest.raises(ConfigError) as err:
        run_study(LandmarkData(shared_path("pf", "burgard_particle_filter")), [300, 20_000_000], [0, 1],
                  on_run=lambda: runs.append(1))
    assert runs == []
    assert str(err.value) == "particles: n_particles must be >= 1 and <= 10000000, got 20000000"


def test_a_study_refuses_a_count_that_does_not_fit_in_memory_before_its_first_run(monkeypatch):
    import lidarkit.resources

    monkeypatch.setattr(lidarkit.resources, "available_memory_bytes", lambda: 150 * 2**20)
    runs = []
    with pytest.raises(ConfigError) as err:  # 1,000,000 x 320 B = 305 MiB, more than 80% of 150 MiB
        run_study(LandmarkData(shared_path("pf", "burgard_particle_filter")), [50, 1_000_000], [0],
                  on_run=lambda: runs.append(1))
    assert runs == []
    assert str(err.value) == ("particles: a filter of 1,000,000 particles needs about 0.298 GiB of memory, more than 80% "
                              "of the 150 MiB available")
