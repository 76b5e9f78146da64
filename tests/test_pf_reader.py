"""The particle filter's landmark data as read: what a run on it is told about its readings."""

from __future__ import annotations

import logging

from lidarkit.io.landmarks import LandmarkData

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
