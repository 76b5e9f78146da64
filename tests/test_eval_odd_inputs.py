"""Library calls given odd inputs: one-line LidarKitErrors naming the input, never a raw Python error; a round-off
bound of a paired test's CI reads 0."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import shared_path

from lidarkit.errors import ConfigError, DataError
from lidarkit.eval import ape, kitti_drift, paired_test, rpe
from lidarkit.textfile import read_numeric_table
from lidarkit.trajectory import Trajectory


def straight(n_frames: int, scale: float = 1.0) -> Trajectory:
    """Frames 1 m apart along x; ``scale`` stretches the estimate (every segment ``|scale - 1|`` too long)."""
    poses = np.tile(np.eye(4), (n_frames, 1, 1))
    poses[:, 0, 3] = scale * np.arange(n_frames, dtype=float)
    return Trajectory(poses)


def test_a_drift_step_past_the_last_frame_starts_one_segment_at_frame_0():
    """step=10**20 made numpy's arange an object array: IndexError; it starts segments at frame 0 only, as any step
    beyond the trajectory does."""
    ref, est = straight(150), straight(150, 1.02)
    huge = kitti_drift(ref, est, step=10**20)
    assert huge.n_segments == 1 and list(huge.segment_first_frame) == [0] and huge.step_frames == 10**20
    beyond = kitti_drift(ref, est, step=1000)
    assert huge.translation_pct == beyond.translation_pct == pytest.approx(2.0 * 101 / 100)


@pytest.mark.parametrize("given", [[], ["m"], np.array(["m"]), np.array("m"), {}])
def test_an_rpe_delta_unit_that_is_no_name_is_a_config_error(given):
    """delta_unit=[] raised TypeError: unhashable type: 'list' (an array alike)."""
    with pytest.raises(ConfigError) as err:
        rpe(straight(20), straight(20), delta_unit=given)
    assert err.value.source == "delta_unit" and str(err.value).startswith("delta_unit: unknown delta unit ")


@pytest.mark.parametrize("given", [np.array(["translation", "rotation"]), np.array("translation"), [], {}])
def test_a_pose_relation_that_is_no_name_is_a_config_error(given):
    """relation=np.array([...]) raised ValueError (ambiguous truth value) or TypeError (unhashable)."""
    for metric in (ape, rpe):
        with pytest.raises(ConfigError) as err:
            metric(straight(20), straight(20), relation=given)
        assert err.value.source == "relation" and "unknown pose relation" in str(err.value)


def test_a_ci_bound_that_is_round_off_reads_0_and_excludes_no_verdict():
    """The bootstrap median of differences -0.1 and +0.1 is -2.2e-16 (round-off of 2.0 - 2.1 and 6.3 - 6.2): the verdict
    printed "95% CI [-0.605, -2.22e-16]" and called a better, the CI excluding 0 by round-off alone. The bound is 0,
    as a tie is, and the CI includes it."""
    a = [1.0, 2.0, 3.1, 4.2, 5.0, 6.3, 7.1, 8.0]
    b = [1.1, 2.3, 3.0, 4.6, 5.4, 6.2, 7.9, 8.8]
    res = paired_test(a, b)
    assert res.diff_ci_low == pytest.approx(-0.605) and res.diff_ci_high == 0.0 and res.better == ""
    assert "the 95% CI of the median difference [-0.605, +0] includes 0" in res.verdict()


def test_date_time_stamps_in_a_times_file_say_seconds_are_wanted(tmp_path):
    """KITTI raw's timestamps.txt given as --ref-times read "(line 1): expected 1 number, found 2"."""
    raw = shared_path("kitti_raw", "2011_09_26", "2011_09_26_drive_0001_sync", "image_03", "timestamps.txt")
    with pytest.raises(DataError) as err:
        read_numeric_table(raw, 1)
    assert str(err.value) == (f"{raw} (line 1): not a number: '2011-09-26' (date/time stamps: give seconds, e.g. "
                              "read KITTI raw's timestamps.txt with lidarkit.io.kitti_raw.read_kitti_raw_timestamps)")
    clock = tmp_path / "clock.txt"
    clock.write_text("0.0\n13:02:25.96\n")  # (one field: the count fits, the word does not)
    with pytest.raises(DataError, match=r"clock\.txt \(line 2\): not a number: '13:02:25\.96' \(date/time stamps: give"):
        read_numeric_table(clock, 1)
    words = tmp_path / "words.txt"
    words.write_text("0.0\nhello world\n")  # (no date: the count, as before)
    with pytest.raises(DataError) as err:
        read_numeric_table(words, 1)
    assert str(err.value) == f"{words} (line 2): expected 1 number, found 2"
