"""``lidarkit.io.images.ImageFolder``: which files of a folder are frames."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from lidarkit.errors import DataError
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


KITTI_K = [[718.856, 0.0, 607.1928], [0.0, 718.856, 185.2157], [0.0, 0.0, 1.0]]


def test_a_projection_matrix_in_any_line_layout_gives_its_left_3x3(tmp_path):
    """Three unlabelled rows of 4 (a 3x4 P as printed) were read as KITTI calib.txt rows of 12: "P34.txt (line 1): P0:
    expected 12 numbers (3x4 matrix), found 4". Twelve unlabelled numbers are one row-major P, however split."""
    from lidarkit.io.images import read_intrinsics

    P = np.array(KITTI_K)
    P = np.column_stack([P, [-386.1448, 0.0, 0.0]])
    layouts = {"rows_of_4.txt": "\n".join(" ".join(f"{v:.10g}" for v in row) for row in P),
               "one_row.txt": " ".join(f"{v:.10g}" for v in P.ravel()),
               "rows_of_6.txt": "\n".join(" ".join(f"{v:.10g}" for v in half) for half in P.reshape(2, 6))}
    for name, text in layouts.items():
        (tmp_path / name).write_text(text + "\n")
        np.testing.assert_allclose(read_intrinsics(tmp_path / name), KITTI_K, err_msg=name)


def test_numpys_printed_matrix_is_read_without_its_brackets(tmp_path):
    """``print(K)``, ``repr(K)`` and a list with commas: "intrinsics must be numbers" (``--init`` reads numpy's print)."""
    from lidarkit.io.images import read_intrinsics

    K = np.array(KITTI_K)
    texts = {"commas.txt": "[[718.856, 0, 607.1928],\n [0, 718.856, 185.2157],\n [0, 0, 1]]\n",
             "print.txt": str(K) + "\n", "repr.txt": repr(K) + "\n",
             "labelled.txt": "K: [[718.856, 0, 607.1928], [0, 718.856, 185.2157], [0, 0, 1]]\n"}
    for name, text in texts.items():
        (tmp_path / name).write_text(text)
        np.testing.assert_allclose(read_intrinsics(tmp_path / name), KITTI_K, err_msg=name)
    (tmp_path / "short.txt").write_text("[[718.856, 0, 607.1928], [0, 718.856, 185.2157]]\n")
    with pytest.raises(DataError, match=r"short\.txt: expected 9 numbers .*; found 6 numbers$"):
        read_intrinsics(tmp_path / "short.txt")
