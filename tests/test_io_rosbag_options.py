"""A bag reader's options as a spec spells them: option words in any case, topics without their leading slash."""

from __future__ import annotations

import pytest

from lidarkit.errors import DataError
from lidarkit.odometry.inputs import open_sequence


@pytest.fixture
def bag(tmp_path):
    from test_io_bad_bags import good, write_ros1_bag

    poses = [(1000.0 + 0.1 * k, (float(k), 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)) for k in range(3)]
    return write_ros1_bag(tmp_path / "run.bag", [good(k) for k in range(3)], odometry=poses)


def test_none_in_any_case_is_the_option_word_not_a_field_or_topic_name(bag):
    """``time_field=None`` and ``ground_truth_topic=None`` (YAML reads only ``null`` as null) were taken for a field
    and a topic named "None": "no per-point time field 'None'", "'None' is not a nav_msgs/msg/Odometry topic"."""
    for word in ("None", "NONE", "none"):
        scans = open_sequence(f"rosbag:{bag}?time_field={word}&ground_truth_topic={word}")
        assert scans.read_scan(0).point_times_s is None
        assert scans.ground_truth is None
        assert scans.reader_options["time_field"] == "none" and scans.reader_options["ground_truth_topic"] is None
    # null, in any case, is the default, as a spec's null is: the point times and the one odometry topic
    from lidarkit.io import open_dataset

    for scans in (open_sequence(f"rosbag:{bag}?time_field=AUTO&ground_truth_topic=Null"),
                  open_dataset("rosbag", bag, time_field="NULL", ground_truth_topic="null")):
        assert scans.read_scan(0).point_times_s is not None and len(scans.ground_truth) == 3


def test_a_topic_named_without_its_leading_slash_is_the_bag_s_topic(bag):
    """``topic=points`` beside /points was refused as "no topic 'points'"; a ROS name without its leading slash is in
    the root namespace. A name the bag does not hold is still refused, naming the topics present."""
    scans = open_sequence(f"rosbag:{bag}?topic=points&ground_truth_topic=ground_truth")
    assert (scans.topic, scans.ground_truth_topic) == ("/points", "/ground_truth")
    assert scans.name == "rosbag:run.bag/points"
    assert len(scans.ground_truth) == 3
    with pytest.raises(DataError, match=r"run\.bag: no topic 'pts'; topics present: /ground_truth \(nav_msgs/msg/Odometry\), "
                                        r"/points \(sensor_msgs/msg/PointCloud2\)"):
        open_sequence(f"rosbag:{bag}?topic=pts")
