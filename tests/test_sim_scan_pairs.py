"""Scan pairs for covariance calibration: bad settings are refused when the pairs are made."""

from __future__ import annotations

import numpy as np
import pytest

from lidarkit.errors import ConfigError
from lidarkit.sim.scan_pairs import ScanPairs

SMALL = dict(n_beams=8, n_azimuths=90)


@pytest.mark.parametrize("settings, message", [
    (dict(n_frames=1), "n_frames must be at least 2 (a pair is two frames), got 1"),
    (dict(range_noise_m=-1.0), "range_noise_m must be a finite std >= 0, got -1"),
    (dict(init_sigma=(-1.0, 0.0)), "init_sigma must be two finite stds >= 0 (translation m, rotation rad), got (-1.0, 0.0)"),
])
def test_bad_settings_are_config_errors_at_construction(settings, message):
    """n_frames=1 raised ZeroDivisionError at draw(0); a negative noise or guess std raised numpy's bare
    "scale < 0" at draw, naming no field: now a ConfigError naming it when the pairs are made."""
    with pytest.raises(ConfigError) as err:
        ScanPairs(**SMALL, **settings)
    assert (err.value.source, err.value.reason) == ("scan pairs", message)


def test_two_frames_give_one_pair_between_them():
    """The smallest valid set: every draw is the pair (1 -> 0), its motion the path's first step."""
    pairs = ScanPairs(n_frames=2, range_noise_m=0.0, init_sigma=(0.0, 0.0), **SMALL)
    a, b = pairs.draw(0), pairs.draw(5)
    assert (a.frame, b.frame) == (0, 0)
    step_m = np.linalg.norm(pairs.poses[1][:3, 3] - pairs.poses[0][:3, 3])
    assert step_m > 0.1 and np.linalg.norm(a.T_target_source[:3, 3]) == pytest.approx(step_m, abs=1e-9)
    assert (a.init_T == a.T_target_source).all()
