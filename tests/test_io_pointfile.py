""".pcd / .ply headers checked before Open3D reads them: what Open3D would read as made-up points (a vertex without z,
a list x, a y typed unlike x, a word in an ascii body) or fail on with a warning printed on stdout (a field missing, a
TYPE it does not read, a bad magic number) is a one-line DataError naming the file and the reason, with nothing on
stdout; files Open3D reads well still read."""

from __future__ import annotations

import re
import struct

import numpy as np
import pytest
from conftest import shared_path

from lidarkit.errors import DataError
from lidarkit.io.pointfile import open3d_reason, read_point_file


def _ply(path, properties: list[str], body: bytes, n_vertices: int, fmt: str = "binary_little_endian",
         magic: str = "ply", extra_header: str = ""):
    header = (f"{magic}\nformat {fmt} 1.0\nelement vertex {n_vertices}\n" + "".join(f"property {p}\n" for p in properties)
              + extra_header + "end_header\n")
    path.write_bytes(header.encode() + body)
    return path


def _xyz_body(rng, n: int) -> bytes:
    return rng.uniform(-20, 20, size=(n, 3)).astype("<f4").tobytes()


def _pcd(path, fields: str, types: str, data: str, body: bytes, n_points: int, sizes: str = "4 4 4 4"):
    header = (f"VERSION 0.7\nFIELDS {fields}\nSIZE {sizes}\nTYPE {types}\nCOUNT 1 1 1 1\nWIDTH {n_points}\nHEIGHT 1\n"
              f"VIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n_points}\nDATA {data}\n")
    path.write_bytes(header.encode() + body)
    return path


def _refused(path, capfd) -> str:
    """The DataError reading ``path`` raises; nothing may reach stdout or stderr (Open3D's and RPly's C prints)."""
    capfd.readouterr()
    with pytest.raises(DataError) as err:
        read_point_file(path)
    out, errout = capfd.readouterr()
    assert out == "" and errout == "", (out, errout)
    text = str(err.value)
    assert "\n" not in text and "\x1b" not in text
    return text


@pytest.mark.parametrize("n_points", [500, 200_000])
def test_a_ply_vertex_without_z_is_refused_not_read_with_z_zero(tmp_path, rng, capfd, n_points):
    """property float x, y, w: Open3D returned z = 0.0 for every point (200,000 points: ICP "converged") or leftover
    memory (500 points: NaN or 2e14, changing run to run)."""
    path = _ply(tmp_path / "noz.ply", ["float x", "float y", "float w"], _xyz_body(rng, n_points), n_points)
    assert _refused(path, capfd) == (f"{path}: the vertex element has no z property (it has: x y w); coordinates are "
                                     "read from properties named x, y and z (lowercase)")


def test_ply_coordinate_names_are_lowercase(tmp_path, rng, capfd):
    """X Y Z read as "Open3D cannot read it (<ANSI>[Open3D Error] (void open3d::...) TensorMap.cpp:34: ...)"."""
    path = _ply(tmp_path / "upper.ply", ["float X", "float Y", "float Z"], _xyz_body(rng, 300), 300)
    assert _refused(path, capfd) == (f"{path}: the vertex element has no x y z property (it has: X Y Z); coordinates "
                                     "are read from properties named x, y and z (lowercase)")


def test_a_list_coordinate_and_coordinates_of_two_types_are_refused(tmp_path, rng, capfd):
    """A list x gave 500 points of leftover memory; a double y beside float x and z was read as float (garbage y)."""
    listed = _ply(tmp_path / "list.ply", ["list uchar int x", "float y", "float z"], _xyz_body(rng, 500), 500)
    assert _refused(listed, capfd) == (f"{listed}: a vertex coordinate is a list ('property list uchar int x'): "
                                       "coordinates are read from scalar properties only")
    body = b"".join(struct.pack("<fdf", 1.0 + k, 2.0, 3.0) for k in range(50))
    mixed = _ply(tmp_path / "mixed.ply", ["float x", "double y", "float z"], body, 50)
    assert _refused(mixed, capfd) == (f"{mixed}: vertex properties x, y, z differ in type (x float32, y float64, "
                                      "z float32): they are read as one type")


def test_a_word_in_an_ascii_ply_body_is_refused(tmp_path, capfd):
    """At ``x`` (or ``inf``) Open3D stopped and returned the rest made up (a point at 1.7e22 m, or z = 0)."""
    path = _ply(tmp_path / "word.ply", ["float x", "float y", "float z"], b"1 2 3\n4 x 6\n7 8 9\n", 3, fmt="ascii")
    assert _refused(path, capfd) == (f"{path}: ascii vertex 1 property y is 'x', not a number Open3D reads (it stops "
                                     "there and makes up the rest)")
    path.write_bytes(path.read_bytes().replace(b"4 x 6", b"4 5 inf"))
    assert "ascii vertex 1 property z is 'inf'" in _refused(path, capfd)


def test_a_bad_ply_magic_number_is_named_with_nothing_on_stdout(tmp_path, rng, capfd):
    """'plyx': RPly's "Wrong magic number" on stderr, Open3D's warning on stdout, then "no points read"."""
    path = _ply(tmp_path / "magic.ply", ["float x", "float y", "float z"], _xyz_body(rng, 100), 100, magic="plyx")
    assert _refused(path, capfd) == f"{path}: not a .ply file (its first line is 'plyx', not 'ply')"


@pytest.mark.parametrize("fields, types, sizes, reason", [
    ("x y w intensity", "F F F F", "4 4 4 4",
     "no z field (FIELDS x y w intensity): positions are read from fields named x, y and z (lowercase)"),
    ("x y z intensity", "U F F F", "4 4 4 4",
     "fields x, y, z differ in TYPE/SIZE (x U4, y F4, z F4): positions are read only as one type"),
    ("x y z intensity", "F F F F", "4 4 4 2",
     "field intensity has TYPE F SIZE 2: not a type Open3D reads (F 4/8, I or U 1/2/4/8)"),
])
def test_a_pcd_header_open3d_cannot_read_is_named_with_nothing_on_stdout(tmp_path, rng, capfd, fields, types, sizes, reason):
    """Open3D printed "[Open3D WARNING] Read PCD failed: unable to parse header." on stdout and lidarkit said only
    "no points read (unreadable, corrupt or empty point cloud)" though the header it parses holds the reason."""
    record = sum(int(s) for s in sizes.split())
    path = _pcd(tmp_path / "bad.pcd", fields, types, "binary", rng.bytes(200 * record), 200, sizes)
    assert _refused(path, capfd) == f"{path}: {reason}"


def test_a_garbled_compressed_pcd_and_an_unknown_data_kind_are_named(tmp_path, rng, capfd):
    """A binary_compressed body of raw floats read as "no points read" after Open3D's "[ReadPCDData] Failed to read
    data record" on stdout; its size fields (994952868 compressed bytes in a 1 kB body) say why."""
    raw = struct.pack("<4f", 12.5, -3.0, 0.25, 7.0) * 64
    path = _pcd(tmp_path / "c.pcd", "x y z intensity", "F F F F", "binary_compressed", raw, 1000)
    packed, unpacked = struct.unpack("<2I", raw[:8])
    assert _refused(path, capfd) == (f"{path}: corrupt binary_compressed body: the header declares 1000 points (16000 "
                                     f"bytes); the body's size fields say {packed} compressed bytes ({unpacked} "
                                     f"unpacked) and it holds {len(raw) - 8}")
    path = _pcd(tmp_path / "d.pcd", "x y z intensity", "F F F F", "binaryx", raw, 16)
    assert _refused(path, capfd) == f"{path}: unsupported DATA 'binaryx' (ascii, binary or binary_compressed)"


def test_open3d_prints_nothing_on_stdout_when_it_fails_past_the_header_checks(tmp_path, capfd):
    """Size fields that fit but a compressed payload that does not decompress: the failure is Open3D's own; its
    coloured warnings went to stdout (a result's console) and now nothing does; its verbosity is restored after."""
    import open3d as o3d

    payload = bytes(range(256)) * 4
    body = struct.pack("<2I", len(payload), 1000 * 16) + payload
    path = _pcd(tmp_path / "garbled.pcd", "x y z intensity", "F F F F", "binary_compressed", body, 1000)
    before = o3d.utility.get_verbosity_level()
    assert _refused(path, capfd) == f"{path}: no points read (unreadable, corrupt or empty point cloud)"
    assert o3d.utility.get_verbosity_level() == before


def test_an_open3d_error_message_is_one_line_without_colour_codes(tmp_path, rng):
    """An Open3D exception inside a DataError carried its ANSI colour codes, its C++ signature, source file and line,
    and a newline."""
    import open3d as o3d

    path = _ply(tmp_path / "upper.ply", ["float X", "float Y", "float Z"], _xyz_body(rng, 10), 10)
    with pytest.raises(RuntimeError) as err:
        o3d.t.io.read_point_cloud(str(path))
    assert "\x1b[" in str(err.value) and re.search(r"\.cpp:\d+:", str(err.value))
    assert open3d_reason(err.value) == 'TensorMap does not contain primary key "positions".'


def test_files_open3d_reads_well_still_read(tmp_path, rng, capfd):
    """The checks refuse no layout Open3D reads right: CRLF lines, big-endian doubles, comments, a face element
    before the vertices, an extra list property, a compressed .pcd, lowercase TYPE letters, a hexadecimal value."""
    import open3d as o3d

    xyz = [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]
    plain = ["float x", "float y", "float z"]
    cases = {
        "crlf.ply": _ply(tmp_path / "crlf.ply", plain, b"1 2 3\r\n4 5 6\r\n", 2, fmt="ascii"),
        "big.ply": _ply(tmp_path / "big.ply", ["double x", "double y", "double z"], struct.pack(">6d", 1, 2, 3, 4, 5, 6), 2,
                        fmt="binary_big_endian"),
        "list.ply": _ply(tmp_path / "list.ply", [*plain, "list uchar int extra", "float32 intensity"],
                         struct.pack("<3fB2if", 1, 2, 3, 2, 7, 8, 0.5) + struct.pack("<3fBif", 4, 5, 6, 1, 9, 0.25), 2),
        "hex.ply": _ply(tmp_path / "hex.ply", plain, b"1 2 0x3\n4 5 6\n", 2, fmt="ascii", extra_header="comment by x\n"),
    }
    crlf = cases["crlf.ply"]
    crlf.write_bytes(crlf.read_bytes().replace(b"\n", b"\r\n").replace(b"\r\r\n", b"\r\n"))
    face_first = tmp_path / "face.ply"
    face_first.write_bytes(b"ply\nformat ascii 1.0\nelement face 1\nproperty list uchar int vertex_indices\nelement vertex 2\n"
                           b"property float x\nproperty float y\nproperty float z\nend_header\n2 0 1\n1 2 3\n4 5 6\n")
    cases["face.ply"] = face_first
    cases["lower.pcd"] = _pcd(tmp_path / "lower.pcd", "x y z intensity", "f f f f", "ascii", b"1 2 3 0.5\n4 5 6 0.5\n", 2)
    for name, path in cases.items():
        assert read_point_file(path).points_xyz.tolist() == xyz, name
    assert read_point_file(cases["list.ply"]).intensity.tolist() == [0.5, 0.25]
    real = shared_path("lidar_pairs", "251370668.pcd")
    compressed = tmp_path / "compressed.pcd"
    assert o3d.t.io.write_point_cloud(str(compressed), o3d.t.io.read_point_cloud(str(real)), compressed=True)
    assert np.array_equal(read_point_file(compressed).points_xyz, read_point_file(real).points_xyz)
    assert capfd.readouterr().out == ""


def test_a_missing_scan_without_its_suffix_is_called_missing(tmp_path):
    """A path typed without its .bin, or a link to a missing file, read "unsupported point file type ''"."""
    with pytest.raises(DataError) as caught:
        read_point_file(tmp_path / "000000")
    assert str(caught.value) == f"{tmp_path / '000000'}: scan file not found"
    (tmp_path / "dang").symlink_to(tmp_path / "nothere")
    with pytest.raises(DataError) as caught:
        read_point_file(tmp_path / "dang")
    assert str(caught.value) == f"{tmp_path / 'dang'}: a symbolic link to a missing file (-> {tmp_path / 'nothere'})"
