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


def test_times_around_the_stamp_are_absolute_whatever_their_size_and_the_size_decides_where_the_stamp_cannot():
    """A simulator's clock starts at 0: float64 times of 100.0-100.1 s in a message stamped 100.0 s were read as relative
    (under 1e5 s), the sweep 100 s after its stamp. Read against the stamp they are absolute; relative times stay relative
    beside any stamp, and a stamp near 0 (both readings place the sweep at it), none, or 0 leaves the size to decide."""
    def convention(values, stamp_s):
        return checked_point_times(values, RING, what="per-point time field 'timestamp'", within="one message", hint="",
                                   source="run.bag", location="message 0", stamp_s=stamp_s)[1]

    assert convention(100.0 + SWEEP, 100.0) == "absolute_s"  # stamped at the sweep start
    assert convention(100.0 + SWEEP, 100.0997) == "absolute_s"  # ... at its end
    assert convention(100.0 + SWEEP, 100.25) == "absolute_s"  # ... 150 ms after its end (on receipt)
    assert convention(0.5 + SWEEP, 0.5) == "absolute_s"  # 5 sweeps after the clock started
    assert convention(100.0 + SWEEP, None) == "relative_s"  # no stamp: by size, as before
    assert convention(SWEEP, 100.0) == "relative_s"  # relative from the sweep start
    assert convention(SWEEP - 0.0997, 100.0) == "relative_s"  # ... up to the stamp at the sweep end
    assert convention(SWEEP, 0.05) == "relative_s"  # a stamp near 0: both readings hold the stamp, relative kept
    assert convention(SWEEP - 0.25, 0.1) == "relative_s"  # stamped on receipt near 0: nearer as relative
    assert convention(SWEEP, 0.0) == "relative_s"  # a stamp of 0 decides nothing
    assert convention(1.7e9 + SWEEP, 1000.0) == "absolute_s"  # another clock, by size (the bag reader says so)
    assert convention(100.0 + SWEEP, 300.0) == "relative_s"  # near neither: by size (the bag reader says another clock)
