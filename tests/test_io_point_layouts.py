"""Point-file layouts Open3D misreads or dies on, read or refused before it sees them: a .pcd whose padding field ``_``
repeats (PCL's binary PointXYZI; Open3D aborted the interpreter, "free(): corrupted unsorted chunks") is read with
numpy, and an ascii .ply vertex line one value short or long (Open3D shifted every vertex after it) is a DataError."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from lidarkit.errors import DataError
from lidarkit.io.pointfile import read_point_file

N_POINTS = 5554  # (a size at which Open3D aborted on every padded layout below)
PCL_XYZI = [("x", "F", 4, 1), ("y", "F", 4, 1), ("z", "F", 4, 1), ("_", "U", 1, 4), ("intensity", "F", 4, 1), ("_", "U", 1, 12)]
WITH_TIMES = [("x", "F", 4, 1), ("y", "F", 4, 1), ("z", "F", 4, 1), ("_", "U", 1, 4), ("intensity", "F", 4, 1),
              ("t", "U", 4, 1), ("_", "U", 1, 4)]


def _write_pcd(path, columns, rng, data: str = "binary", n: int = N_POINTS) -> np.ndarray:
    """A .pcd of ``columns`` (name, TYPE, SIZE, COUNT) filled with random values (the padding too); returns its records."""
    record = np.dtype([(f"c{k}", f"<{ {'F': 'f', 'U': 'u'}[kind]}{size}", (count,) if count > 1 else ())
                       for k, (_, kind, size, count) in enumerate(columns)])
    table = np.zeros(n, record)
    for k, (_, kind, size, count) in enumerate(columns):
        shape = (n, count) if count > 1 else (n,)
        table[f"c{k}"] = rng.normal(0, 10, shape) if kind == "F" else rng.integers(0, 2 ** (8 * size) - 1, shape)
    header = "\n".join([
        "VERSION 0.7", "FIELDS " + " ".join(c[0] for c in columns), "SIZE " + " ".join(str(c[2]) for c in columns),
        "TYPE " + " ".join(c[1] for c in columns), "COUNT " + " ".join(str(c[3]) for c in columns), f"WIDTH {n}",
        "HEIGHT 1", "VIEWPOINT 0 0 0 1 0 0 0", f"POINTS {n}", f"DATA {data}", ""]).encode()
    if data == "ascii":
        values = np.hstack([table[f"c{k}"].reshape(n, -1).astype(np.float64) for k in range(len(columns))])
        body = ("\n".join(" ".join(f"{v:.9g}" for v in row) for row in values) + "\n").encode()
    else:
        body = table.tobytes()
    path.write_bytes(header + body)
    return table


_READ_IN_CHILD = """
import json, sys
import numpy as np
from lidarkit.errors import LidarKitError
from lidarkit.io import open_dataset
from lidarkit.io.pointfile import read_point_file
said = {}
for path in sys.argv[2:]:
    try:
        if sys.argv[1] == "generic":
            said[path] = f"{len(open_dataset('generic', path))} scans"
            continue
        scan = read_point_file(path)
    except LidarKitError as err:
        said[path] = str(err)
    else:
        np.savez(path + ".npz", points=scan.points_xyz, intensity=scan.intensity)
        said[path] = "read"
print(json.dumps(said))
"""


def _read_in_child(how: str, *paths) -> dict[str, str]:
    """What reading ``paths`` says, in another process: Open3D aborted the interpreter on these files (rc 134)."""
    done = subprocess.run([sys.executable, "-c", _READ_IN_CHILD, how, *map(str, paths)], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr[-400:]
    return json.loads(done.stdout.splitlines()[-1])


def test_a_pcd_with_pcl_padding_fields_is_read_with_numpy(tmp_path, rng):
    """PCL's binary PointXYZI (``x y z _ intensity _``), an Ouster-like layout with ``t`` and ascii: every point and
    intensity as written, the padding's random bytes skipped; no interpreter abort."""
    written = {name: _write_pcd(tmp_path / name, columns, rng, data)
               for name, columns, data in (("pcl_xyzi.pcd", PCL_XYZI, "binary"), ("with_t.pcd", WITH_TIMES, "binary"),
                                           ("pcl_ascii.pcd", PCL_XYZI, "ascii"))}
    said = _read_in_child("file", *(tmp_path / name for name in written))
    assert set(said.values()) == {"read"}, said
    for name, table in written.items():
        read = np.load(tmp_path / f"{name}.npz")
        assert np.array_equal(read["points"], np.column_stack([table["c0"], table["c1"], table["c2"]]).astype(np.float64)), name
        assert read["intensity"].dtype == np.float32 and np.array_equal(read["intensity"], table["c4"]), name


def test_repeated_field_names_other_than_padding_and_compressed_padding_are_refused(tmp_path, rng):
    """``FIELDS x y z a a`` (which ``a``?) is a DataError naming the field; a binary_compressed body with repeated ``_``
    fields is refused rather than handed to Open3D (both aborted the interpreter inside it)."""
    twice = tmp_path / "twice.pcd"
    _write_pcd(twice, [("x", "F", 4, 1), ("y", "F", 4, 1), ("z", "F", 4, 1), ("a", "F", 4, 1), ("a", "F", 4, 1)], rng)
    compressed = tmp_path / "compressed.pcd"
    records = _write_pcd(compressed, PCL_XYZI, rng).tobytes()
    head = compressed.read_bytes()[: -len(records)].replace(b"DATA binary\n", b"DATA binary_compressed\n")
    compressed.write_bytes(head + np.array([len(records), len(records)], "<u4").tobytes() + records)  # (sizes that add up)
    said = _read_in_child("file", twice, compressed)
    assert said[str(twice)] == (f"{twice}: field a appears 2 times (FIELDS x y z a a): a field is read by its name, only "
                                "the padding field _ may repeat")
    assert said[str(compressed)].startswith(f"{compressed}: binary_compressed with repeated fields (FIELDS x y z _ "
                                            "intensity _): Open3D aborts on repeated field names")


def test_the_generic_reader_refuses_padded_pcds_before_open3d_reads_them(tmp_path, rng):
    """generic:P (kiss-icp's loader reads with Open3D) died as folder:P did; it now names the file, and folder:P reads it."""
    for k in range(2):
        _write_pcd(tmp_path / f"{1000 + k}.pcd", WITH_TIMES, rng)
    said = _read_in_child("generic", tmp_path)
    assert said[str(tmp_path)] == (f"{tmp_path / '1000.pcd'}: repeated padding fields _ (FIELDS x y z _ intensity t _): "
                                   "Open3D, which kiss-icp's generic loader reads with, aborts the process on repeated "
                                   "field names; folder:PATH reads these files (without per-point times)")


def _open3d_ascii_ply(path, rng, n: int = 200) -> list[str]:
    import open3d as o3d

    cloud = o3d.t.geometry.PointCloud(o3d.core.Tensor(rng.uniform(-80, 80, (n, 3))))
    assert o3d.t.io.write_point_cloud(str(path), cloud, write_ascii=True)
    return path.read_text().splitlines()


@pytest.mark.parametrize(("edit", "n_values"), [(lambda line: "1 2", 2), (lambda line: line + " 5.0", 4)], ids=["short", "long"])
def test_an_ascii_ply_vertex_line_short_or_long_is_refused(tmp_path, rng, capfd, edit, n_values):
    """A vertex line one value short (or long) read every later vertex shifted by one value (points ~77 m off), with
    only RPly's "Unexpected end of file" on stderr; it is a DataError naming the vertex."""
    lines = _open3d_ascii_ply(tmp_path / "good.ply", rng)
    body_start = lines.index("end_header") + 1
    lines[body_start + 11] = edit(lines[body_start + 11])
    path = tmp_path / "edited.ply"
    path.write_text("\n".join(lines) + "\n")
    capfd.readouterr()
    with pytest.raises(DataError) as err:
        read_point_file(path)
    assert str(err.value) == f"{path}: ascii vertex 11 has {n_values} values, the header declares 3"
    assert capfd.readouterr() == ("", "")


def test_ascii_ply_line_widths_allow_what_open3d_reads(tmp_path, rng):
    """CRLF lines, blank lines, spaces and tabs around values, a face element after the vertices: read;
    a vertex list property makes the width vary (only a line without even the list's length word is refused)."""
    lines = _open3d_ascii_ply(tmp_path / "good.ply", rng, n=50)
    expected = read_point_file(tmp_path / "good.ply").points_xyz
    body_start = lines.index("end_header") + 1
    spaced = lines[:body_start] + [f" \t{line}  " for line in lines[body_start:]]
    blank_line = spaced[:body_start + 3] + [""] + spaced[body_start + 3:]
    for name, text in (("crlf.ply", "\r\n".join(lines) + "\r\n"), ("spaced.ply", "\n".join(blank_line) + "\n")):
        (tmp_path / name).write_bytes(text.encode())
        np.testing.assert_array_equal(read_point_file(tmp_path / name).points_xyz, expected, err_msg=name)
    header = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
    listed = tmp_path / "list.ply"
    listed.write_text(header + "property list uchar int extra\nend_header\n1 2 3 0\n4 5 6 2 7 8\n7 8 9 1 1\n")
    assert read_point_file(listed).points_xyz.tolist() == [[1, 2, 3], [4, 5, 6], [7, 8, 9]]
    listed.write_text(header + "property list uchar int extra\nend_header\n1 2 3 0\n4 5 6\n7 8 9 1 1\n")
    with pytest.raises(DataError, match=r"list\.ply: ascii vertex 1 has 3 values, the header declares at least 4$"):
        read_point_file(listed)
    faces = tmp_path / "faces.ply"
    faces.write_text(header + "element face 1\nproperty list uchar int vertex_indices\nend_header\n1 2 3\n4 5 6\n7 8 9\n"
                     "3 0 1 2\n")
    assert len(read_point_file(faces).points_xyz) == 3
