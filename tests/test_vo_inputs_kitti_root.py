"""``lidarkit vo`` pointed at a KITTI root or its sequences/ folder with the default ``--kind auto``."""

from __future__ import annotations

import shutil

import pytest
from conftest import shared_path

from lidarkit.errors import ConfigError
from lidarkit.vo.inputs import detect_kind, open_vo_input


def _kitti_root(tmp_path, sequences=("06",), n_frames=3):
    """A KITTI root holding sequences/NN/ (image_0/, calib.txt, times.txt) copied from KITTI 06's first frames."""
    src = shared_path("kitti_images", "sequences", "06")
    root = tmp_path / "kitti"
    for name in sequences:
        seq = root / "sequences" / name
        (seq / "image_0").mkdir(parents=True)
        for i in range(n_frames):
            shutil.copy(src / "image_0" / f"{i:06d}.png", seq / "image_0" / f"{i:06d}.png")
        shutil.copy(src / "calib.txt", seq / "calib.txt")
        (seq / "times.txt").write_text("\n".join((src / "times.txt").read_text().splitlines()[:n_frames]) + "\n")
    return root


def test_auto_kind_opens_a_kitti_root_with_one_sequence(tmp_path):
    root = _kitti_root(tmp_path)
    assert detect_kind(root) == "kitti"
    opened = open_vo_input(root)
    assert opened.kind == "kitti" and len(opened.images) == 3
    assert opened.K_source == "kitti calibration"


def test_auto_kind_names_the_sequences_of_a_kitti_root_and_of_its_sequences_folder(tmp_path):
    root = _kitti_root(tmp_path, sequences=("06", "07"), n_frames=2)
    with pytest.raises(ConfigError, match=r"KITTI root with 2 sequences \(06, 07\)"):
        open_vo_input(root)
    assert detect_kind(root / "sequences") == "kitti"
    with pytest.raises(ConfigError, match=r"folder of KITTI sequences \(06, 07\).*e\.g\. .*sequences/06") as info:
        open_vo_input(root / "sequences")
    assert "\n" not in str(info.value)
