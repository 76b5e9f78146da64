"""What the image decoder prints: a corrupt frame's libpng line belongs in its DataError, not on the terminal."""

from __future__ import annotations

import logging
import shutil

import pytest

from lidarkit.errors import DataError
from lidarkit.io.images import ImageFolder
from lidarkit.samples import sample_path


def test_a_truncated_png_is_refused_with_libpngs_line_in_the_reason_and_nothing_on_fd_2(tmp_path, capfd, caplog):
    """A truncated PNG printed "libpng error: Read Error" on stderr, between `lidarkit vo`'s progress lines (the frame
    was rejected, its reason saying only "corrupt or unsupported format"): the line now ends the reason."""
    frames = sorted((sample_path("kitti_vo", "06") / "image_0").glob("*.png"))[:3]
    folder = tmp_path / "images"
    folder.mkdir()
    for frame in frames:
        shutil.copyfile(frame, folder / frame.name)
    corrupt = folder / frames[1].name
    corrupt.write_bytes(corrupt.read_bytes()[:20000])  # the header and part of the data: libpng's read fails
    images = ImageFolder(folder)
    capfd.readouterr()
    with caplog.at_level(logging.WARNING):
        assert images.read_image(0).shape == (370, 1226)  # a good frame: read, nothing said
        with pytest.raises(DataError) as err:
            images.read_image(1)
        assert images.read_image(2).shape == (370, 1226)  # stderr is the terminal's again after a refusal
    out, err_text = capfd.readouterr()
    assert "libpng" not in err_text and "libpng" not in out
    assert err_text == "" and caplog.records == []
    assert str(err.value) == f"{corrupt} (frame 1): cannot decode image (corrupt or unsupported format): libpng error: Read Error"


def test_what_a_decoder_says_about_an_image_it_still_decodes_is_a_warning_naming_the_file(tmp_path, capfd, caplog):
    """A truncated JPEG decodes while libjpeg prints "Premature end of JPEG file" on stderr: the line is a warning
    naming the file and the frame, not bare text on fd 2."""
    import cv2

    frame = sorted((sample_path("kitti_vo", "06") / "image_0").glob("*.png"))[0]
    folder = tmp_path / "images"
    folder.mkdir()
    ok, encoded = cv2.imencode(".jpg", cv2.imread(str(frame), cv2.IMREAD_GRAYSCALE))
    assert ok
    jpeg = folder / "000000.jpg"
    jpeg.write_bytes(encoded.tobytes()[: len(encoded) // 2])
    capfd.readouterr()
    with caplog.at_level(logging.WARNING, logger="lidarkit.io.images"):
        assert ImageFolder(folder).read_image(0).shape == (370, 1226)
    assert capfd.readouterr().err == ""
    assert [r.getMessage() for r in caplog.records] == [
        f"{jpeg} (frame 0): the image decoder said: Premature end of JPEG file"]


def test_images_are_read_where_no_temporary_folder_is_writable(monkeypatch, tmp_path):
    """The capture needs somewhere to put the decoder's text; without memfd and a writable temporary folder (a read-only
    container) every read raised FileNotFoundError: it now reads without capturing."""
    import os
    import tempfile

    from lidarkit.io.kitti import read_gray_image

    frame = sorted((sample_path("kitti_vo", "06") / "image_0").glob("*.png"))[0]
    monkeypatch.delattr(os, "memfd_create", raising=False)
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "not_there"))
    assert read_gray_image(frame).shape == (370, 1226)


def test_an_image_header_claiming_too_many_pixels_is_a_data_error(tmp_path):
    """A PNG whose header says 100000 x 100000 pixels made OpenCV raise its own cv2.error (a size assertion): the run
    ended with a traceback and lost its folder. It is a refused image now."""
    import struct
    import zlib

    from lidarkit.io.kitti import read_gray_image

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    ihdr = struct.pack(">IIBBBBB", 100000, 100000, 8, 0, 0, 0, 0)
    path = tmp_path / "huge.png"
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(bytes(64))) + chunk(b"IEND", b""))
    with pytest.raises(DataError) as err:
        read_gray_image(path, frame=6)
    assert str(err.value).startswith(f"{path} (frame 6): cannot decode image") and "\n" not in str(err.value)
