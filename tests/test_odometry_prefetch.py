"""The reading thread of an odometry run: order, bound, errors, clean shutdown, same result as reading inline."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from lidarkit.errors import DataError
from lidarkit.odometry import run
from lidarkit.odometry.prefetch import prefetched


def _threads() -> int:
    return sum(t.name == "lidarkit-prefetch" for t in threading.enumerate())


def test_in_order_and_at_most_depth_ahead():
    state = {"read": 0, "consumed": 0, "max_ahead": 0}

    def read(i):
        state["read"] += 1
        state["max_ahead"] = max(state["max_ahead"], state["read"] - state["consumed"])
        return i * 10

    seen = []
    for idx, scan, read_s, err in prefetched(read, np.arange(50), depth=3):
        time.sleep(0.002)  # a slow consumer: the reader must wait, not run ahead
        state["consumed"] += 1
        seen.append((idx, scan, err))
        assert read_s >= 0
    assert seen == [(i, i * 10, None) for i in range(50)]
    assert state["max_ahead"] <= 3 + 2  # the queue, the item being put and the one being consumed
    assert _threads() == 0


def test_a_read_error_is_handed_over_and_the_thread_ends():
    def read(i):
        if i == 3:
            raise DataError("broken", source="scan 3")
        return i

    items = list(prefetched(read, np.arange(10), depth=2))
    assert [i for i, *_ in items] == [0, 1, 2, 3]
    assert isinstance(items[-1][3], DataError) and items[-1][1] is None
    assert _threads() == 0


def test_closing_early_stops_the_reader():
    stream = prefetched(lambda i: i, np.arange(10_000), depth=4)
    assert next(stream)[0] == 0
    stream.close()
    assert _threads() == 0


def test_same_trajectory_with_and_without_prefetch_and_errors_name_the_frame():
    spec = "sim:street?frames=6&beams=16&azimuths=360&seed=2"
    inline = run(spec, "kiss", prefetch=0).trajectory.poses_se3
    ahead = run(spec, "kiss", prefetch=4).trajectory.poses_se3
    np.testing.assert_allclose(ahead, inline, rtol=0, atol=1e-9)
    assert _threads() == 0


def test_a_bad_scan_in_a_run_names_its_frame_and_leaves_no_thread():
    from lidarkit.sim.lidar import SimulatedLidarSequence

    class Broken(SimulatedLidarSequence):
        def read_scan(self, index):
            if index == 2:
                raise DataError("unreadable", source="scan file")
            return super().read_scan(index)

    seq = Broken(n_frames=5, n_beams=8, n_azimuths=180)
    for method in ("kiss", "vanilla"):
        with pytest.raises(DataError, match=r"\(frame 2\): .*unreadable"):
            run(seq, method)
    assert _threads() == 0
