"""A folder's TUM poses one short because a repeated stamp was left out: the count error says which line and why it
counts (poses pair with scans by order), not only "9 poses for 10 scans" for a file of 10 rows."""

from __future__ import annotations

import numpy as np
import pytest

from lidarkit.errors import DataError
from lidarkit.io import open_dataset


def _folder(tmp_path, n_scans: int, rng):
    folder = tmp_path / "scans"
    folder.mkdir()
    for k in range(n_scans):
        np.save(folder / f"{k}.npy", rng.uniform(-20, 20, (50, 3)))
    return folder


def _tum(path, stamps) -> None:
    rows = "".join(f"{t:.6f} {0.5 * k:.3f} 0 0 0 0 0 1\n" for k, t in enumerate(stamps))
    path.write_text("# timestamp tx ty tz qx qy qz qw\n" + rows)


@pytest.mark.parametrize(("stamps", "said"), [
    ([0.0, 0.1, 0.1, 0.3], "3 poses for 4 scans in {folder} (4 rows, line 4 left out: it repeats"),
    ([0.0, 0.0, 0.2, 0.2, 0.4, 0.5], "4 poses for 6 scans in {folder} (6 rows, lines 3, 5 left out: each repeats"),
], ids=["one", "two"])
def test_poses_left_out_as_repeated_stamps_are_named_in_the_count_error(tmp_path, rng, stamps, said):
    folder = _folder(tmp_path, len(stamps), rng)
    poses = folder / "poses.txt"
    _tum(poses, stamps)
    with pytest.raises(DataError) as err:
        open_dataset("folder", folder, poses=poses, poses_format="tum")
    assert str(err.value) == (f"{poses}: {said.format(folder=folder)} the stamp of the pose before it); the folder reader "
                              "pairs poses with scans by order, one each: give each pose its own stamp")


def test_a_pose_count_short_for_another_reason_keeps_the_plain_message(tmp_path, rng):
    """A file of 3 rows for 4 scans (nothing left out), and one that left a repeat out but is short anyway."""
    folder = _folder(tmp_path, 4, rng)
    poses = folder / "poses.txt"
    for stamps, n_read in (([0.0, 0.1, 0.2], 3), ([0.0, 0.0, 0.2], 2)):
        _tum(poses, stamps)
        with pytest.raises(DataError) as err:
            open_dataset("folder", folder, poses=poses, poses_format="tum")
        assert str(err.value) == f"{poses}: {n_read} poses for 4 scans in {folder}"
