"""Single point-cloud files (KITTI ``.bin``, ``.npy``, ``.pcd``, ``.ply``) read into a validated :class:`Scan`.

Every reader checks what it reads: a missing, empty or truncated file, a ``.pcd``/``.ply`` header Open3D would
misread (no x/y/z, a type it does not read), or NaN/inf points raise ``DataError`` naming the file, the frame and
the reason; with ``drop_nonfinite=True`` non-finite points are dropped instead and a warning is logged. A ``.pcd``
with PCL's repeated ``_`` padding fields, on which Open3D aborts the process, is read with numpy. Points
exactly at the sensor origin (0, 0, 0), an organized cloud's missing returns, are always left out
(:func:`drop_origin_points`).
"""

from __future__ import annotations

import dataclasses
import logging
import os
import re
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from lidarkit.errors import DataError
from lidarkit.geometry import _within_limits
from lidarkit.io.base import Scan

log = logging.getLogger(__name__)

KITTI_BIN_RECORD_BYTES = 16  # float32 x, y, z, intensity
POINT_FILE_SUFFIXES = (".bin", ".npy", ".pcd", ".ply")


def _where(frame: int | None) -> str | None:
    """An error's location: the frame of a sequence, none for a file read on its own (``lidarkit icp``'s two clouds)."""
    return None if frame is None else f"frame {frame}"


def _require_file(path: Path, frame: int | None) -> int:
    """Size in bytes of an existing, non-empty regular file."""
    from lidarkit.atomic import missing_reason, stream_reason

    where = _where(frame)
    if not path.exists():
        raise DataError(missing_reason(path, "scan file not found"), source=path, location=where)
    if not path.is_file():
        raise DataError(stream_reason(path) or "not a regular file", source=path, location=where)
    size = path.stat().st_size
    if size == 0:
        raise DataError("empty scan file (0 bytes)", source=path, location=where)
    if not os.access(path, os.R_OK):
        raise DataError("cannot read it (permission denied)", source=path, location=where)
    return size


def load_npy(path: Path, location: str | None) -> np.ndarray:
    """The array of an ``.npy`` file; DataError naming the file for anything unreadable: a cut or corrupt header, an
    empty file, an ``.npz`` archive under an ``.npy`` name, a file that cannot be opened."""
    try:
        data = np.load(path, allow_pickle=False)
    except Exception as err:  # noqa: BLE001 - a corrupt header raises ValueError, EOFError, SyntaxError, tokenize.TokenError, ...
        raise DataError(f"not a readable .npy array ({type(err).__name__}: {err})", source=path, location=location) from None
    if not isinstance(data, np.ndarray):  # np.load opens an .npz archive whatever the file's name
        getattr(data, "close", lambda: None)()
        raise DataError(f"not an .npy array (a {type(data).__name__}: an .npz archive?)", source=path, location=location)
    return data


def finite_points(
    points_xyz: np.ndarray,
    intensity: np.ndarray | None,
    *,
    source: str | os.PathLike,
    frame: int | None = None,
    drop_nonfinite: bool = False,
    dropped: list[str] | None = None,
) -> tuple[np.ndarray, np.ndarray | None]:
    """Check ``(N, 3)`` points (and ``(N,)`` intensity) for NaN/inf; raise DataError or drop them with a warning, said
    also in ``dropped`` (one line per scan) for a sequence reader's ``reader_warnings`` (a log line alone left a run's
    metrics.json without a word)."""
    from lidarkit.geometry import check_magnitude

    if len(points_xyz) and _within_limits(points_xyz) and (intensity is None or bool(np.isfinite(intensity).all())):
        return points_xyz, intensity  # the common case in flat reductions (NaN fails them); the per-row test below is ~20x slower
    where = _where(frame)
    ok = np.isfinite(points_xyz).all(axis=1)
    if intensity is not None:
        ok &= np.isfinite(intensity)
    n_bad = int(len(ok) - np.count_nonzero(ok))
    if n_bad:
        first = int(np.argmin(ok))
        if not drop_nonfinite:
            raise DataError(
                f"{n_bad} of {len(ok)} points are NaN or infinite (first at point {first}); "
                "drop them with drop_nonfinite=True (a dataset spec's ?drop_nonfinite=true, lidarkit icp --drop-nonfinite)",
                source=source,
                location=where,
            )
        log.warning("%s (%s): dropped %d of %d NaN/infinite points", source, where or "scan", n_bad, len(ok))
        if dropped is not None:
            dropped.append(f"left out {n_bad} of {len(ok)} points with NaN or infinite values in {where or 'the scan'} ({source})")
        points_xyz = points_xyz[ok]
        intensity = None if intensity is None else intensity[ok]
    if len(points_xyz) == 0:
        raise DataError("scan has no finite points", source=source, location=where)
    check_magnitude(points_xyz, str(source), where)
    return points_xyz, intensity



def said_once(reader_warnings: list[str], dropped: list[str]) -> None:
    """Keep the first scan's line of ``dropped`` (points a reader left out) in a sequence reader's ``reader_warnings``,
    once per reader: a run's metrics.json says it without a line per frame."""
    if dropped and not any(w.endswith(LATER_FRAMES) for w in reader_warnings):
        reader_warnings.append(f"{dropped[0]}{LATER_FRAMES}")


LATER_FRAMES = "; in later frames without another warning"

def at_sensor_origin(points_xyz: np.ndarray) -> np.ndarray:
    """``(N,)`` bool: the points exactly at (0, 0, 0), where an organized cloud stores its missing returns."""
    return (points_xyz[:, 0] == 0) & (points_xyz[:, 1] == 0) & (points_xyz[:, 2] == 0)  # 10x faster than any(axis=1)


_ORIGIN_WARNED: set[str] = set()  # folders whose scans' points at (0, 0, 0) were reported: once per folder, not per frame


def drop_origin_points(
    points_xyz: np.ndarray, intensity: np.ndarray | None, *, source: str | os.PathLike, frame: int | None = None
) -> tuple[np.ndarray, np.ndarray | None]:
    """Leave out points exactly at (0, 0, 0): no return lies at the sensor itself; an organized cloud stores its
    missing returns there (5032 of 69088 points of the shared LiDAR pair) and registration took them for points
    moving with the sensor (t 0.31 m where the reference has 0.49 m). Logged once for a file read on its own
    (``frame`` None), once per folder for a sequence's frames (a folder of thousands of scans says it once)."""
    if not (points_xyz[:, 0] == 0).any():  # (the common case, no x exactly 0, in a third of the time: 0.1 ms a KITTI scan)
        return points_xyz, intensity
    at_origin = at_sensor_origin(points_xyz)
    n_zero = int(np.count_nonzero(at_origin))
    if not n_zero:
        return points_xyz, intensity
    where = _where(frame)
    if n_zero == len(points_xyz):
        raise DataError(f"all {n_zero} points are at (0, 0, 0) (missing returns): no point left", source=source, location=where)
    folder = str(Path(source).parent.absolute())
    if frame is None or folder not in _ORIGIN_WARNED:
        later = "" if frame is None else f"; later scans in {folder}: left out without another warning"
        log.warning("%s (%s): left out %d of %d points at (0, 0, 0) (missing returns)%s", source, where or "scan", n_zero,
                    len(points_xyz), later)
        if frame is not None:
            _ORIGIN_WARNED.add(folder)
    keep = ~at_origin
    return points_xyz[keep], None if intensity is None else intensity[keep]


def read_kitti_bin(
    path: str | os.PathLike,
    *,
    frame: int | None = None,
    timestamp_s: float | None = None,
    drop_nonfinite: bool = False,
    dropped: list[str] | None = None,
) -> Scan:
    """Read a KITTI Velodyne ``.bin`` (little-endian float32 ``x y z intensity`` records).

    A size that is not a multiple of 16 bytes is a truncated file (DataError), as is an empty one.
    Points are returned as ``(N, 3)`` float64, intensity as ``(N,)`` float32; points left out: :func:`finite_points`.
    """
    path = Path(path)
    size = _require_file(path, frame)
    if size % KITTI_BIN_RECORD_BYTES:
        raise DataError(
            f"truncated: {size} bytes is not a multiple of {KITTI_BIN_RECORD_BYTES} "
            f"(float32 x, y, z, intensity per point); {size % KITTI_BIN_RECORD_BYTES} trailing bytes",
            source=path,
            location=_where(frame),
        )
    data = np.fromfile(path, dtype="<f4").reshape(-1, 4)
    if len(data) and _within_limits(data):
        # every value finite and bounded, tested in one flat pass over the contiguous records (~20x faster than the
        # same test on the strided x/y/z and intensity columns; anything else takes the full check below)
        points, intensity = data[:, :3], data[:, 3]
    else:
        points, intensity = finite_points(data[:, :3], data[:, 3], source=path, frame=frame, drop_nonfinite=drop_nonfinite,
                                          dropped=dropped)
    points, intensity = drop_origin_points(points, intensity, source=path, frame=frame)
    return Scan(points.astype(np.float64), np.ascontiguousarray(intensity), None, timestamp_s, frame or 0, str(path))


def read_npy_scan(
    path: str | os.PathLike, *, frame: int | None = None, timestamp_s: float | None = None, drop_nonfinite: bool = False,
    dropped: list[str] | None = None,
) -> Scan:
    """Read a ``.npy`` array of shape ``(N, 3)`` (x, y, z) or ``(N, 4)`` (x, y, z, intensity)."""
    path = Path(path)
    _require_file(path, frame)
    data = load_npy(path, _where(frame))
    if data.ndim != 2 or data.shape[1] not in (3, 4) or not np.issubdtype(data.dtype, np.number) \
            or np.issubdtype(data.dtype, np.complexfloating) or data.dtype == np.bool_:
        raise DataError(
            f"expected a numeric (N, 3) or (N, 4) array, got shape {data.shape} dtype {data.dtype}",
            source=path,
            location=_where(frame),
        )
    if len(data) == 0:  # (it read as "scan has no finite points")
        raise DataError("empty scan file (0 points)", source=path, location=_where(frame))
    intensity = data[:, 3].astype(np.float32) if data.shape[1] == 4 else None
    points, intensity = finite_points(
        data[:, :3].astype(np.float64), intensity, source=path, frame=frame, drop_nonfinite=drop_nonfinite, dropped=dropped
    )
    points, intensity = drop_origin_points(points, intensity, source=path, frame=frame)
    return Scan(points, intensity, None, timestamp_s, frame or 0, str(path))


def read_open3d_scan(
    path: str | os.PathLike, *, frame: int | None = None, timestamp_s: float | None = None, drop_nonfinite: bool = False,
    dropped: list[str] | None = None,
) -> Scan:
    """Read a ``.pcd`` or ``.ply`` with Open3D's tensor reader, keeping an ``intensity`` field if present.

    Open3D is asked not to drop NaN points itself so that they are reported (or dropped) here. A ``.pcd`` with
    repeated ``_`` padding fields is read with numpy instead (:func:`read_padded_pcd`): Open3D aborts on it.
    """
    path = Path(path)
    _require_file(path, frame)
    if path.suffix.lower() == ".pcd":
        header = check_pcd_counts(path, frame)
        if header.padded:  # (Open3D aborted the process on it)
            points, intensity = read_padded_pcd(path, header, frame)
            points, intensity = finite_points(points, intensity, source=path, frame=frame, drop_nonfinite=drop_nonfinite,
                                              dropped=dropped)
            points, intensity = drop_origin_points(points, intensity, source=path, frame=frame)
            return Scan(points, intensity, None, timestamp_s, frame or 0, str(path))
    elif path.suffix.lower() == ".ply":
        check_ply_counts(path, frame)
    import open3d as o3d  # slow import: only when a pcd/ply is read

    try:
        with open3d_quiet(o3d):
            cloud = o3d.t.io.read_point_cloud(str(path), remove_nan_points=False, remove_infinite_points=False)
    except RuntimeError as err:
        raise DataError(f"Open3D cannot read it ({open3d_reason(err)})", source=path, location=_where(frame)) from err
    if "positions" not in cloud.point or len(cloud.point.positions) == 0:
        raise DataError("no points read (unreadable, corrupt or empty point cloud)", source=path, location=_where(frame))
    points = cloud.point.positions.numpy().astype(np.float64)
    intensity = None
    for key in ("intensity", "intensities", "reflectance"):
        if key in cloud.point:
            intensity = cloud.point[key].numpy().reshape(len(points), -1)[:, 0].astype(np.float32)
            break
    points, intensity = finite_points(points, intensity, source=path, frame=frame, drop_nonfinite=drop_nonfinite,
                                      dropped=dropped)
    points, intensity = drop_origin_points(points, intensity, source=path, frame=frame)
    return Scan(points, intensity, None, timestamp_s, frame or 0, str(path))


_QUIET = threading.Lock()
_quiet_readers = 0  # reads in progress on all threads; the last one to finish restores the caller's level
_loud_level = None


@contextmanager
def open3d_quiet(o3d) -> Iterator[None]:
    """Open3D's warnings off while it reads: it prints them in colour on stdout (a result's console), and the header
    checks here name what it would warn about. Counted, so reads on two threads restore the earlier level once."""
    global _quiet_readers, _loud_level
    with _QUIET:
        if _quiet_readers == 0:
            _loud_level = o3d.utility.get_verbosity_level()
            o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
        _quiet_readers += 1
    try:
        yield
    finally:
        with _QUIET:
            _quiet_readers -= 1
            if _quiet_readers == 0:
                o3d.utility.set_verbosity_level(_loud_level)


_ANSI_CODE = re.compile(r"\x1b\[[0-9;]*m")
_OPEN3D_ERROR_PREFIX = re.compile(r"\[Open3D (?:Error|WARNING)\] \(.*?\) \S+:\d+: ")


def open3d_reason(err: BaseException) -> str:
    """An Open3D exception's message on one line: without its colour codes, its ``[Open3D Error] (signature)
    file:line:`` prefix and its trailing newline (it was printed whole inside a DataError)."""
    text = _OPEN3D_ERROR_PREFIX.sub("", _ANSI_CODE.sub("", str(err)))
    return " ".join(text.split()) or type(err).__name__


_PCD_HEADER_KEYS = ("VERSION", "FIELDS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT", "VIEWPOINT", "POINTS", "DATA")


@dataclasses.dataclass(frozen=True)
class PcdHeader:
    """A checked ``.pcd`` header: its fields in file order (PCL's ``_`` padding included), the point count, the DATA
    kind and the byte where the body starts."""

    fields: tuple[str, ...]
    types: tuple[str, ...]
    sizes: tuple[int, ...]
    counts: tuple[int, ...]
    n_points: int
    data: str
    body_offset: int

    @property
    def padded(self) -> bool:
        """Whether a field name repeats (only PCL's ``_`` padding may): Open3D corrupts its heap on such a file and
        the process aborts (PCL's binary PointXYZI, ``x y z _ intensity _``), so lidarkit reads it itself."""
        return len(set(self.fields)) < len(self.fields)


def check_pcd_counts(path: Path, frame: int | None = None) -> PcdHeader:
    """Check a ``.pcd`` body against its header before Open3D reads it: Open3D fills a short body with zeros (or
    fails deep inside), so a header declaring more points than the body holds is a DataError here. Returns the
    header, which says whether Open3D may read the file at all (:attr:`PcdHeader.padded`)."""
    where = _where(frame)
    try:
        fh = open(path, "rb")
    except OSError as err:
        raise DataError(f"cannot read it ({err.strerror})", source=path, location=where) from None
    with fh:
        header: dict[str, list[str]] = {}
        offset = 0
        for line_no in range(1, 64):
            raw = fh.readline()
            if not raw:
                raise DataError("truncated .pcd header (no DATA line)", source=path, location=where)
            offset += len(raw)
            text = raw.decode("ascii", errors="replace").strip()
            if not text or text.startswith("#"):
                continue
            key, *values = text.split()
            header[key.upper()] = values
            if key.upper() == "DATA":
                break
        else:
            raise DataError("not a .pcd header (no DATA line in the first 64 lines)", source=path, location=where)
        body = fh.read()
    try:
        n_points = int(header["POINTS"][0]) if "POINTS" in header else int(header["WIDTH"][0]) * int(header.get("HEIGHT", ["1"])[0])
        fields, types = header["FIELDS"], [t.upper() for t in header["TYPE"]]
        sizes = [int(v) for v in header["SIZE"]]
        counts = [int(v) for v in header.get("COUNT", ["1"] * len(sizes))]
        data = header["DATA"][0].lower()
    except KeyError as err:
        raise DataError(f"malformed .pcd header (no {err.args[0]} line)", source=path, location=where) from None
    except (IndexError, ValueError) as err:
        raise DataError(f"malformed .pcd header ({type(err).__name__}: {err})", source=path, location=where) from None
    if n_points < 0 or not len(fields) == len(types) == len(sizes) == len(counts):
        raise DataError("malformed .pcd header (negative POINTS or FIELDS/SIZE/TYPE/COUNT lengths differ)", source=path,
                        location=where)
    _check_pcd_fields(path, where, fields, types, sizes)
    header_read = PcdHeader(tuple(fields), tuple(types), tuple(sizes), tuple(counts), n_points, data, offset)
    if data not in ("ascii", "binary", "binary_compressed"):
        raise DataError(f"unsupported DATA {header['DATA'][0]!r} (ascii, binary or binary_compressed)", source=path,
                        location=where)
    if data == "ascii":
        rows = [line.split() for line in body.decode("ascii", errors="replace").splitlines() if line.strip()]
        held = len(rows)
        width = sum(counts)
        for k, row in enumerate(rows):  # Open3D reads a short row or a word in it as zeros
            try:
                [float(v) for v in row]
            except ValueError:
                raise DataError(f"ascii point {k} is not numbers: {' '.join(row)[:60]!r}", source=path, location=where) from None
            if len(row) != width:
                raise DataError(f"ascii point {k} has {len(row)} values, the header declares {width}", source=path, location=where)
    elif data == "binary":
        record = sum(s * c for s, c in zip(sizes, counts))
        held = len(body) // record if record else 0
        if record and len(body) < n_points * record:
            raise DataError(f"the header declares {n_points} points ({n_points * record} bytes) but the binary body holds "
                            f"{len(body)} bytes ({held} points)", source=path, location=where)
        return header_read
    else:  # binary_compressed: uint32 compressed and uncompressed sizes, then the compressed columns
        record = sum(s * c for s, c in zip(sizes, counts))
        packed, unpacked = np.frombuffer(body[:8], "<u4").tolist() if len(body) >= 8 else (None, None)
        if packed is None or packed > len(body) - 8 or unpacked < n_points * record:
            raise DataError(f"corrupt binary_compressed body: the header declares {n_points} points ({n_points * record} "
                            f"bytes); the body's size fields say {packed} compressed bytes ({unpacked} unpacked) and it "
                            f"holds {max(len(body) - 8, 0)}", source=path, location=where)
        return header_read
    if held != n_points:
        raise DataError(f"the header declares {n_points} points but the ascii body holds {held}", source=path, location=where)
    return header_read


_PCD_TYPE_SIZES = {"F": (4, 8), "I": (1, 2, 4, 8), "U": (1, 2, 4, 8)}  # what Open3D reads
_PCD_NUMPY_KINDS = {"F": "f", "I": "i", "U": "u"}
_INTENSITY_FIELDS = ("intensity", "intensities", "reflectance")


def read_padded_pcd(path: Path, header: PcdHeader, frame: int | None = None) -> tuple[np.ndarray, np.ndarray | None]:
    """``(N, 3)`` float64 points and ``(N,)`` float32 intensity (None without one) of a checked ``.pcd`` whose field
    names repeat (:attr:`PcdHeader.padded`), read with numpy at the header's offsets, the ``_`` padding skipped:
    Open3D aborts the process on these files. A ``binary_compressed`` one is refused (PCL writes its padding only
    into binary and ascii files)."""
    where = _where(frame)
    if header.data == "binary_compressed":
        raise DataError(f"binary_compressed with repeated fields (FIELDS {' '.join(header.fields)}): Open3D aborts on "
                        "repeated field names and lidarkit reads them only from binary or ascii files; save it as binary",
                        source=path, location=where)
    if header.n_points == 0:
        raise DataError("no points read (unreadable, corrupt or empty point cloud)", source=path, location=where)
    columns = [(f"{name}{k}" if name == "_" else name, size, count, kind)
               for k, (name, kind, size, count) in enumerate(zip(header.fields, header.types, header.sizes, header.counts))]
    if header.data == "binary":
        record = np.dtype([(name, f"<{_PCD_NUMPY_KINDS[kind]}{size}", (count,) if count > 1 else ())
                           for name, size, count, kind in columns])
        table = np.fromfile(path, record, count=header.n_points, offset=header.body_offset)

        def column(name: str) -> np.ndarray:
            return table[name].reshape(header.n_points, -1)[:, 0]
    else:  # ascii: the body was checked for numbers, one row of the header's width per point
        with open(path, "rb") as fh:
            fh.seek(header.body_offset)
            values = np.array(fh.read().split(), dtype=np.float64).reshape(header.n_points, -1)
        starts = dict(zip((name for name, *_ in columns), np.cumsum([0, *header.counts[:-1]]).tolist()))
        kinds = {name: f"<{_PCD_NUMPY_KINDS[kind]}{size}" for name, size, _, kind in columns}

        def column(name: str) -> np.ndarray:  # (in the field's type, as from a binary body: float32 x as float32)
            return values[:, starts[name]].astype(kinds[name])
    points = np.column_stack([column(axis) for axis in "xyz"]).astype(np.float64)
    named = next((name for name in _INTENSITY_FIELDS if name in header.fields), None)
    return points, None if named is None else column(named).astype(np.float32)


def _check_pcd_fields(path: Path, where: str | None, fields: list[str], types: list[str], sizes: list[int]) -> None:
    """The fields Open3D needs: x, y and z (lowercase, one type for the three: it reads no positions otherwise, "no
    points read"), a type it knows for every field (one it does not fails the whole read), and a name used once (a value
    is read by its field's name; only PCL's ``_`` padding repeats)."""
    repeated = next((name for name in fields if name != "_" and fields.count(name) > 1), None)
    if repeated is not None:
        raise DataError(f"field {repeated} appears {fields.count(repeated)} times (FIELDS {' '.join(fields)}): a field is "
                        "read by its name, only the padding field _ may repeat", source=path, location=where)
    missing = [axis for axis in "xyz" if axis not in fields]
    if missing:
        raise DataError(f"no {' '.join(missing)} field (FIELDS {' '.join(fields)}): positions are read from fields "
                        "named x, y and z (lowercase)", source=path, location=where)
    for name, kind, size in zip(fields, types, sizes):
        if size not in _PCD_TYPE_SIZES.get(kind, ()):
            raise DataError(f"field {name} has TYPE {kind} SIZE {size}: not a type Open3D reads (F 4/8, I or U 1/2/4/8)",
                            source=path, location=where)
    kinds = {axis: f"{types[fields.index(axis)]}{sizes[fields.index(axis)]}" for axis in "xyz"}
    if len(set(kinds.values())) > 1:
        raise DataError(f"fields x, y, z differ in TYPE/SIZE ({', '.join(f'{a} {k}' for a, k in kinds.items())}): "
                        "positions are read only as one type", source=path, location=where)


_PLY_TYPES = {"char": "int8", "int8": "int8", "uchar": "uint8", "uint8": "uint8", "short": "int16", "int16": "int16",
              "ushort": "uint16", "uint16": "uint16", "int": "int32", "int32": "int32", "uint": "uint32", "uint32": "uint32",
              "float": "float32", "float32": "float32", "double": "float64", "float64": "float64"}  # RPly's names: one type
_PLY_FORMATS = ("ascii", "binary_little_endian", "binary_big_endian")


def check_ply_counts(path: Path, frame: int | None = None) -> None:
    """Check a ``.ply`` header, and its body against the vertex count, before Open3D reads it: Open3D makes up the
    coordinates it cannot read (z = 0 for a vertex without z, leftover memory for a list x, a cut file's tail or a
    y typed unlike x) and prints its reasons on stdout, so each of these is a DataError here."""
    where = _where(frame)
    try:
        with open(path, "rb") as fh:
            head = fh.read(65536)
    except OSError as err:
        raise DataError(f"cannot read it ({err.strerror})", source=path, location=where) from None
    end = head.find(b"end_header")
    if not head.startswith(b"ply") or end < 0:
        raise DataError("not a .ply file (no 'ply' ... 'end_header' header)", source=path, location=where)
    body_start = head.find(b"\n", end) + 1
    lines = head[:end].decode("ascii", errors="replace").splitlines()
    if lines[0].strip() != "ply":
        raise DataError(f"not a .ply file (its first line is {lines[0][:40]!r}, not 'ply')", source=path, location=where)
    fmt, elements = "", []  # (name, count, [(property name, canonical type or the whole line of a list)])
    for line in lines[1:]:
        words = line.split()
        if words[:1] == ["format"]:
            if len(words) != 3 or words[1] not in _PLY_FORMATS or words[2] != "1.0":
                raise DataError(f"unsupported .ply format line {line.strip()!r} (format ascii, binary_little_endian or "
                                "binary_big_endian 1.0)", source=path, location=where)
            fmt = words[1]
        elif words[:1] == ["element"]:
            if len(words) != 3 or not words[2].isdigit():
                raise DataError(f"malformed .ply header line {line.strip()!r} (element NAME COUNT)", source=path,
                                location=where)
            elements.append((words[1], int(words[2]), []))
        elif words[:1] == ["property"]:
            listed = words[1:2] == ["list"]
            kinds = words[2:4] if listed else words[1:2]
            if not elements or len(words) != (5 if listed else 3) or any(k not in _PLY_TYPES for k in kinds):
                raise DataError(f"malformed .ply header line {line.strip()!r} (property TYPE NAME or property list TYPE "
                                f"TYPE NAME; types: {', '.join(_PLY_TYPES)})", source=path, location=where)
            elements[-1][2].append((words[-1], line.strip() if listed else _PLY_TYPES[words[1]]))
    vertex = next((e for e in elements if e[0] == "vertex"), None)
    if vertex is None:
        raise DataError(f"no vertex element (elements: {' '.join(e[0] for e in elements) or 'none'}): points are read from "
                        "an element named vertex", source=path, location=where)
    _check_ply_coordinates(path, where, dict(vertex[2]), [name for name, _ in vertex[2]])
    if elements[0][0] != "vertex":
        return  # the vertices come after another element's lines: no line or byte count to check
    n_vertices, names = vertex[1], [name for name, _ in vertex[2]]
    n_lists = sum(kind not in _PLY_TYPES.values() for _, kind in vertex[2])
    if fmt == "ascii":
        with open(path, "rb") as fh:
            fh.seek(body_start)
            body = fh.read()
        widths = _ascii_line_widths(body)
        if len(widths) < n_vertices:
            raise DataError(f"truncated: the header declares {n_vertices} vertices but the ascii body holds {len(widths)} lines",
                            source=path, location=where)
        # RPly reads words, not lines: a vertex line short or long by a value shifts every vertex after it
        declared = len(names)  # a list property: its length word, then that many values (a width of at least 1)
        off = np.flatnonzero(widths[:n_vertices] < declared if n_lists else widths[:n_vertices] != declared)
        if off.size:
            k = int(off[0])
            at_least = " at least" if n_lists else ""
            raise DataError(f"ascii vertex {k} has {widths[k]} values, the header declares{at_least} {declared}",
                            source=path, location=where)
        if not n_lists:
            _check_ply_ascii_numbers(path, where, body, n_vertices, names)
        return
    if n_lists:
        return  # a list's length varies by vertex: no byte count to check
    vertex_bytes = sum(np.dtype(kind).itemsize for _, kind in vertex[2])
    size = path.stat().st_size - body_start
    if size < n_vertices * vertex_bytes:
        raise DataError(f"truncated: the header declares {n_vertices} vertices ({n_vertices * vertex_bytes} bytes) but the body "
                        f"holds {size} bytes", source=path, location=where)


_WHITESPACE = np.zeros(256, dtype=bool)
_WHITESPACE[list(b" \t\n\r\v\f")] = True  # the bytes C's isspace takes for whitespace


def _ascii_line_widths(body: bytes) -> np.ndarray:
    """``(L,)`` int64: the number of whitespace-separated values on each non-blank line of an ascii body (lines end at
    ``\\n``; a ``\\r`` before it is whitespace), counted over the bytes with numpy (a million lines in no Python loop)."""
    data = np.frombuffer(body, dtype=np.uint8)
    if data.size == 0:
        return np.zeros(0, dtype=np.int64)
    space = _WHITESPACE[data]
    word_start = ~space
    word_start[1:] &= space[:-1]
    line_end = data == ord("\n")
    # words before each line's end, from the sorted positions (a cumulative sum over every byte took three times as long)
    words_before = np.searchsorted(np.flatnonzero(word_start), np.flatnonzero(line_end))
    widths = np.diff(words_before, prepend=0, append=np.count_nonzero(word_start))
    return widths[widths > 0]


_C_NUMBER = (rb"[+-]?(?:(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?"  # what C's strtod reads whole: decimal, hexadecimal, nan
             rb"|0[xX](?:[0-9a-fA-F]+\.?[0-9a-fA-F]*|\.[0-9a-fA-F]+)(?:[pP][+-]?\d+)?|[nN][aA][nN])")
_NOT_A_NUMBER = re.compile(rb"(?<!\S)(?!" + _C_NUMBER + rb"(?!\S))\S+")  # a word not one whole number ("inf" fails Open3D)


def _check_ply_ascii_numbers(path: Path, where: str | None, body: bytes, n_vertices: int, names: list[str]) -> None:
    """The ascii vertex values are numbers Open3D reads: at a word (or "inf", or "1e"), it stops reading and returns
    the vertex it was filling and the rest made up (1.7e22 m after ``4 x 6``). One regex pass, no per-value loop."""
    for bad in _NOT_A_NUMBER.finditer(body):
        index = len(body[: bad.start()].split())
        if index >= n_vertices * len(names):
            return  # a later element's (faces'): the vertices are read before it
        raise DataError(f"ascii vertex {index // len(names)} property {names[index % len(names)]} is "
                        f"{bad.group()[:30].decode('ascii', errors='replace')!r}, not a number Open3D reads (it stops "
                        "there and makes up the rest)", source=path, location=where)


def _check_ply_coordinates(path: Path, where: str | None, kinds: dict[str, str], names: list[str]) -> None:
    """Scalar vertex properties x, y and z of one type: Open3D reads no other names (names are case-sensitive; ``X``
    is not ``x``), gives z = 0 for a missing z, skips a list x (its points made up), and reads y and z as x's type
    (a double y read as float: garbage)."""
    missing = [axis for axis in "xyz" if axis not in kinds]
    if missing:
        raise DataError(f"the vertex element has no {' '.join(missing)} property (it has: {' '.join(names) or 'none'}); "
                        "coordinates are read from properties named x, y and z (lowercase)", source=path, location=where)
    listed = [kinds[axis] for axis in "xyz" if kinds[axis] not in _PLY_TYPES.values()]
    if listed:
        raise DataError(f"a vertex coordinate is a list ({listed[0]!r}): coordinates are read from scalar properties "
                        "only", source=path, location=where)
    if len({kinds[axis] for axis in "xyz"}) > 1:
        raise DataError(f"vertex properties x, y, z differ in type ({', '.join(f'{a} {kinds[a]}' for a in 'xyz')}): they "
                        "are read as one type", source=path, location=where)


def point_file_fields(path: str | os.PathLike) -> list[str]:
    """The per-point fields a ``.pcd`` (FIELDS) or ``.ply`` (vertex properties) header names, from its first 64 kB;
    empty for another file type or a header that cannot be read (the readers name what is wrong with it)."""
    return [name for name, _ in _header_fields(Path(path))]


#: PLY property types whose values Open3D's point-cloud reader skips ("unsupported datatype", on stdout), checked on
#: Open3D 0.20: a per-point time field of one of these reaches no reader (uchar, uint8, uint16, int, float and double
#: are read)
OPEN3D_SKIPPED_PLY_TYPES = ("char", "int8", "short", "int16", "ushort", "uint", "uint32")


def open3d_skipped_type(path: str | os.PathLike, field: str) -> str | None:
    """The type of vertex property ``field`` of a ``.ply`` as its header writes it, when Open3D cannot read that type
    (:data:`OPEN3D_SKIPPED_PLY_TYPES`); None otherwise, and for a ``.pcd`` (Open3D reads every PCD type)."""
    if Path(path).suffix.lower() != ".ply":
        return None
    kind = dict(_header_fields(Path(path))).get(field)
    return kind if kind in OPEN3D_SKIPPED_PLY_TYPES else None


def _header_fields(path: Path) -> list[tuple[str, str]]:
    """(name, type) of each per-point field in a ``.pcd`` / ``.ply`` header (a PCD's type is left empty; a PLY list's
    is ``list``); empty for another file type or a header that cannot be read."""
    suffix = path.suffix.lower()
    if suffix not in (".pcd", ".ply"):
        return []
    try:
        with open(path, "rb") as fh:
            head = fh.read(65536).split(b"end_header" if suffix == ".ply" else b"\nDATA", 1)[0]
    except OSError:
        return []
    lines = [line.split() for line in head.decode("ascii", errors="replace").splitlines()]
    if suffix == ".pcd":
        return next(([(name, "") for name in words[1:]] for words in lines if words and words[0].upper() == "FIELDS"), [])
    fields, in_vertex = [], False
    for words in lines:
        if words[:1] == ["element"]:
            in_vertex = words[1:2] == ["vertex"]
        elif words[:1] == ["property"] and in_vertex and len(words) > 2:
            fields.append((words[-1], words[1]))
    return fields


def read_point_file(
    path: str | os.PathLike, *, frame: int | None = None, timestamp_s: float | None = None, drop_nonfinite: bool = False,
    dropped: list[str] | None = None,
) -> Scan:
    """Read any supported point file, chosen by suffix (``.bin``, ``.npy``, ``.pcd``, ``.ply``)."""
    path = Path(path)
    suffix = path.suffix.lower()
    readers = {".bin": read_kitti_bin, ".npy": read_npy_scan, ".pcd": read_open3d_scan, ".ply": read_open3d_scan}
    if path.is_dir():  # (it read as "unsupported point file type ''")
        raise DataError(f"a folder, not a point file ({', '.join(POINT_FILE_SUFFIXES)})", source=path)
    from lidarkit.atomic import missing_reason, stream_reason

    streamed = stream_reason(path)  # (<(cat X.pcd)'s /dev/fd/63 has no suffix: "unsupported point file type ''")
    if streamed:
        raise DataError(streamed, source=path, location=_where(frame))
    if suffix not in readers and not path.exists():  # (a typo without its .bin read "unsupported point file type ''")
        raise DataError(missing_reason(path, "scan file not found"), source=path, location=_where(frame))
    if suffix not in readers:
        raise DataError(
            f"unsupported point file type {suffix!r}; supported: {', '.join(POINT_FILE_SUFFIXES)}",
            source=path,
            location=_where(frame),
        )
    return readers[suffix](path, frame=frame, timestamp_s=timestamp_s, drop_nonfinite=drop_nonfinite, dropped=dropped)


__all__ = [
    "POINT_FILE_SUFFIXES",
    "at_sensor_origin",
    "check_pcd_counts",
    "check_ply_counts",
    "drop_origin_points",
    "finite_points",
    "OPEN3D_SKIPPED_PLY_TYPES",
    "open3d_quiet",
    "open3d_reason",
    "open3d_skipped_type",
    "PcdHeader",
    "point_file_fields",
    "read_kitti_bin",
    "read_npy_scan",
    "read_open3d_scan",
    "read_padded_pcd",
    "read_point_file",
]
