"""Time stamps in messages: the shortest decimal that reads back as the same float64, cut at the nanosecond."""

from __future__ import annotations

import numpy as np
import pytest

from lidarkit.errors import ConfigError, DataError
from lidarkit.trajectory import Trajectory


def _tum(path, stamps) -> None:
    path.write_text("".join(f"{t} {0.8 * k} 0 0 0 0 0 1\n" for k, t in enumerate(stamps)))


def test_stamps_print_as_the_shortest_decimal_float64_holds(rng):
    """A nanosecond file name (1700000000049999952) or a TUM stamp 1700000000.05 printed 1700000000.049999952: digits
    float64 does not hold at an epoch stamp (its step there is 0.24 us)."""
    from lidarkit.trajectory import stamp_text

    assert stamp_text(1700000000049999952 / 1e9) == "1700000000.05"
    assert stamp_text(1700000000.05) == "1700000000.05"
    assert stamp_text(0.1234567891234) == "0.123456789"  # cut at the nanosecond
    assert (stamp_text(12.0), stamp_text(0.0)) == ("12", "0")
    epochs = 1.7e9 + rng.random(200) * 1e6
    assert all(float(stamp_text(t)) == t for t in epochs)


def test_a_tum_file_going_back_by_a_fraction_of_a_microsecond_names_both_stamps(tmp_path):
    """`.6f` printed "timestamp 1700000000.050000 is earlier than the one before it (1700000000.050000)"."""
    path = tmp_path / "est.txt"
    _tum(path, ["1700000000.0", "1700000000.0500004", "1700000000.0500002"])
    with pytest.raises(DataError) as err:
        Trajectory.from_tum(path)
    assert err.value.reason == "timestamp 1700000000.0500002 is earlier than the one before it (1700000000.0500004)"


def test_a_trajectory_and_its_interpolation_errors_print_stamps_as_written(tmp_path):
    """repr and interpolated's errors printed 1700000000.050000-1700000000.350000 s and times to 6 decimals only."""
    path = tmp_path / "gt.txt"
    _tum(path, [repr(1700000000.05 + 0.1 * k) for k in range(4)])
    traj = Trajectory.from_tum(path)
    assert repr(traj) == "Trajectory('gt', 4 poses, 1700000000.05-1700000000.35 s (0.3 s), path 2.4 m)"
    with pytest.raises(ConfigError) as err:
        traj.interpolated(np.array([1700000000.1000004, 1700000000.1000001]))
    assert err.value.reason == ("times_s must be strictly increasing: time 1 (1700000000.1000001 s) is not after time 0 "
                                "(1700000000.1000004 s)")
    with pytest.raises(DataError) as err:
        traj.interpolated(np.array([1700000000.4500003]))
    assert err.value.reason.startswith("time 1700000000.4500003 s lies 0.100 s outside the stamps 1700000000.05-1700000000.35 s")


def test_written_tum_stamps_read_back_as_the_same_double(tmp_path):
    """poses_tum.txt keeps its 9 fixed decimals (1700000000.049999952 for 1700000000.05): the same float64 read back,
    so its contents stay as they are; only messages print the shortest form."""
    stamps = 1700000000.05 + 0.1 * np.arange(5)
    traj = Trajectory(np.tile(np.eye(4), (5, 1, 1)), stamps, name="est")
    traj.to_tum(tmp_path / "poses_tum.txt")
    assert (tmp_path / "poses_tum.txt").read_text().splitlines()[1].split()[0] == "1700000000.049999952"
    assert np.array_equal(Trajectory.from_tum(tmp_path / "poses_tum.txt").timestamps_s, stamps)
