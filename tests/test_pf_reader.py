"""The particle filter's landmark data as read: what a run on it is told about its readings."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from lidarkit.errors import DataError
from lidarkit.io.landmarks import LandmarkData
from lidarkit.pf import ParticleFilter, PFConfig, make_filter

WORLD = "1 2 1\n2 0 4\n3 2 7\n"
ODOMETRY = "".join(f"ODOMETRY 0.1 0.1 {-0.0003 * (i % 3):g}\n" for i in range(20))


def test_sensor_data_without_readings_is_said_once_read(tmp_path, caplog):
    """`lidarkit pf DIR` on a sensor_data.dat holding no SENSOR line ran (exit 0, its MSE worse than dead reckoning's)
    without a word: the reader warns that there are no readings; readings all dropped by the policy are counted."""
    (tmp_path / "world.dat").write_text(WORLD)
    sensor = tmp_path / "sensor_data.dat"
    sensor.write_text(ODOMETRY)
    with caplog.at_level(logging.WARNING, logger="lidarkit.io.landmarks"):
        data = LandmarkData(tmp_path)
    assert (len(data), data.n_readings) == (20, 0)
    assert [r.getMessage() for r in caplog.records] == [
        f"{sensor}: no SENSOR readings in its 20 ODOMETRY steps: a filter weighing the landmarks it recorded (the "
        "protocol's default) only predicts from the odometry"]
    caplog.clear()
    sensor.write_text(ODOMETRY + "SENSOR 1 -0.03 0.2\n")
    with caplog.at_level(logging.WARNING, logger="lidarkit.io.landmarks"):
        assert LandmarkData(tmp_path, negative_range="drop").n_readings == 0
    said = caplog.records[-1].getMessage()
    assert said.startswith(f"{sensor}: no SENSOR readings in its 20 ODOMETRY steps (1 dropped as negative ranges): ")
    caplog.clear()
    sensor.write_text(ODOMETRY + "SENSOR 2 3.5 0.2\n")
    with caplog.at_level(logging.WARNING, logger="lidarkit.io.landmarks"):
        assert LandmarkData(tmp_path).n_readings == 1
    assert caplog.records == []


def test_a_filter_takes_the_readers_landmark_map_its_rows_indexed_by_the_readings(tmp_path):
    """make_filter(data.landmarks) / ParticleFilter(data.landmarks) refused the reader's LandmarkMap in a 9-line message
    printing its repr; the map is taken as its positions in the world file's order, the rows the reader's
    ``meas_landmark_index`` points to (ids 7, 3, 12 are rows 0, 1, 2), and a filter run on it is the run on the array."""
    (tmp_path / "world.dat").write_text("7 2 1\n3 0 4\n12 2 7\n")
    (tmp_path / "sensor_data.dat").write_text("ODOMETRY 0.1 0.5 0\nSENSOR 12 6.1 1.2\nSENSOR 7 1.9 0.3\n"
                                              "ODOMETRY 0.0 0.5 0.1\nSENSOR 3 3.2 1.9\n")
    data = LandmarkData(tmp_path)
    assert data.meas_landmark_index.tolist() == [2, 0, 1]
    for kernel in ("point", "kalman"):
        runs = []
        for landmarks in (data.landmarks, data.landmarks.positions_xy):
            pf = make_filter(landmarks, PFConfig.make(kernel=kernel, n_particles=50), 3)
            for step in range(len(data)):
                pf.predict(data.odometry[step])
                rows = data.readings(step)
                pf.update(data.meas_landmark_index[rows], np.column_stack([data.meas_range_m[rows], data.meas_bearing_rad[rows]]))
            runs.append((pf.landmarks_xy, pf.estimate()))
        np.testing.assert_array_equal(runs[0][0], [[2, 1], [0, 4], [2, 7]])
        np.testing.assert_array_equal(runs[0][1], runs[1][1])
    assert ParticleFilter(data.landmarks, PFConfig.make(n_particles=5)).landmarks_xy.shape == (3, 2)
    with pytest.raises(DataError) as err:  # the whole data set: named by its type, in one line
        ParticleFilter(data, PFConfig.make(n_particles=5))
    assert str(err.value) == ("landmarks: landmarks must be numbers, an (L, 2) array or a LandmarkMap, got a LandmarkData "
                              "(its .landmarks is the map)")
