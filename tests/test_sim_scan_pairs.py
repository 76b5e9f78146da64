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


def test_the_corridor_reaches_past_every_frame_and_n_frames_is_an_integer():
    """The corridor was a fixed tunnel ending at x = 300 m: ScanPairs('corridor', n_frames=500).draw(400) returned
    empty clouds (frames 1 m apart); n_frames=2.7 was truncated to 2 without a word."""
    pairs = ScanPairs("corridor", n_frames=500, range_noise_m=0.0, **SMALL)
    first, last = pairs.draw(0), pairs.draw(498)
    assert last.frame == 498 and len(last.source_xyz) == len(last.target_xyz) == len(first.source_xyz) == 720
    pose = pairs.poses[499]
    world_x = last.source_xyz @ pose[0, :3] + pose[0, 3]
    assert 499.0 - 80.0 <= world_x.min() and world_x.max() <= 499.0 + 80.0  # walls around frame 499, 200 m past the old end
    for value in (2.7, True):
        with pytest.raises(ConfigError) as err:
            ScanPairs("corridor", n_frames=value, **SMALL)
        assert (err.value.source, err.value.reason) == ("scan pairs", f"n_frames must be an integer, got {value!r}")


def test_draw_index_must_be_an_integer_at_least_zero():
    """draw(-1) raised numpy's bare "expected non-negative integer" ValueError, draw(2.7) drew pair 2 and draw('1')
    pair 1, naming nothing: a ConfigError naming the index, as the constructor's for n_frames and seed."""
    pairs = ScanPairs(n_frames=3, range_noise_m=0.0, **SMALL)
    for value in (-1, 2.7, "1", True):
        with pytest.raises(ConfigError) as err:
            pairs.draw(value)
        assert (err.value.source, err.value.reason) == ("scan pairs", f"index must be an integer >= 0, got {value!r}")
    assert pairs.draw(np.int64(3)).frame == 1  # numpy integers are integers; pairs repeat every n_frames - 1 draws
