"""Per-point time values judged by ``checked_point_times``: the types that cannot hold a sweep's times are named."""

from __future__ import annotations

import numpy as np
import pytest

from lidarkit.errors import DataError
from lidarkit.io.pointcloud2 import checked_point_times

ANGLE = np.linspace(0, 2 * np.pi, 360, endpoint=False)
RING = np.column_stack([10 * np.cos(ANGLE), 10 * np.sin(ANGLE), np.zeros(len(ANGLE))])
SWEEP = np.linspace(0.0, 0.0997, len(ANGLE))


def _checked(raw):
    return checked_point_times(raw, RING, what="per-point time field 'timestamp'", within="one message",
                               hint="time_field= names the right field, none reads no times", source="run.bag", location="message 0")


def test_float32_absolute_times_are_refused_as_float32_not_read_as_all_equal():
    """Absolute times (1.7e9 s) in a float32 field are 128 s apart at best: every point of a sweep got one value, and the
    run said "per-point times ... all equal (nothing to deskew with)". The field's type is named as the reason."""
    with pytest.raises(DataError) as err:
        _checked((1.7e9 + SWEEP).astype(np.float32))
    assert str(err.value) == ("run.bag (message 0): per-point time field 'timestamp' is float32 holding times of 1.7e+09 s and more: "
                              "float32 cannot hold absolute times (its steps are 128 s there; drivers write them as float64 or "
                              "integer nanoseconds); time_field= names the right field, none reads no times")
    times, convention = _checked(1.7e9 + SWEEP)  # float64 holds them
    assert convention == "absolute_s" and np.ptp(times) == pytest.approx(0.0997, abs=1e-6)
    times, convention = _checked(SWEEP.astype(np.float32))  # float32 relative times read as before
    assert convention == "relative_s" and np.ptp(times) == pytest.approx(0.0997, abs=1e-6)
