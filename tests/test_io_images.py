"""``lidarkit.io.images.ImageFolder``: which files of a folder are frames."""

from __future__ import annotations

import shutil

from lidarkit.io.images import ImageFolder
from lidarkit.samples import sample_path


def test_macos_appledouble_stubs_are_not_frames(tmp_path):
    """A folder copied from macOS holds a 4-byte ``._000000.png`` beside each image: they were listed as frames
    (rejected as unreadable, extrapolated poses written for them) and 8 poses for the 8 images were refused."""
    sample = sample_path("kitti_vo", "06")
    folder = tmp_path / "images"
    shutil.copytree(sample / "image_0", folder)
    for image in sorted(folder.glob("*.png")):
        (folder / f"._{image.name}").write_bytes(b"\x00\x05\x16\x07")
    (folder / ".hidden.png").write_bytes(b"\x00\x05\x16\x07")

    images = ImageFolder(folder, poses=sample / "poses.txt")
    assert len(images) == 8
    assert [p.name for p in images.image_paths] == [f"{k:06d}.png" for k in range(8)]
    assert len(images.ground_truth) == 8
    assert images.read_image(0).shape == (370, 1226)  # (the sample keeps KITTI frames cropped to 1226 x 370)
