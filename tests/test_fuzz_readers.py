"""Fuzzing every reader: a valid file, mutated (truncated, bytes flipped, huge / NaN values, wrong counts), must read
or fail with a LidarKitError; nothing else may escape. Derandomized (the same examples on every run), ~20 s."""

from __future__ import annotations

import gzip
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from lidarkit.errors import LidarKitError
from lidarkit.samples import sample_path

FUZZ = settings(max_examples=40, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])

NUMBERS = [b"nan", b"inf", b"-inf", b"1e300", b"-1e308", b"1e31", b"0", b"-0", b"9" * 40, b"1e-320", b"x", b""]


@st.composite
def mutated(draw, original: bytes) -> bytes:
    """``original`` with 1-3 mutations: truncate, flip bytes, replace a token by an odd number, drop / duplicate a
    line (a wrong count)."""
    data = bytearray(original)
    for _ in range(draw(st.integers(1, 3))):
        kind = draw(st.sampled_from(["truncate", "flip", "number", "drop_line", "dup_line"]))
        if not data:
            break
        if kind == "truncate":
            data = data[: draw(st.integers(0, len(data) - 1))]
        elif kind == "flip":
            for _ in range(draw(st.integers(1, 4))):
                i = draw(st.integers(0, len(data) - 1))
                data[i] = draw(st.integers(0, 255))
        elif kind in ("number", "drop_line", "dup_line"):
            lines = bytes(data).split(b"\n")
            i = draw(st.integers(0, len(lines) - 1))
            if kind == "number":
                tokens = lines[i].split(b" ")
                j = draw(st.integers(0, len(tokens) - 1))
                tokens[j] = draw(st.sampled_from(NUMBERS))
                lines[i] = b" ".join(tokens)
            elif kind == "drop_line":
                del lines[i]
            else:
                lines.insert(i, lines[i])
            data = bytearray(b"\n".join(lines))
    return bytes(data)


def only_lidarkit_errors(read: Callable[[Path], object], path: Path, data: bytes) -> None:
    path.write_bytes(data)
    try:
        read(path)
    except LidarKitError:
        pass


def _text_head(path: Path, n_lines: int, gz: bool = False) -> bytes:
    opener = gzip.open if gz else open
    with opener(path, "rb") as fh:
        return b"".join(fh.readline() for _ in range(n_lines))


def _bin_scan() -> bytes:
    xyz = np.load(sample_path("kitti_pair", "000094.npy"))[:64, :3].astype("<f4")
    return np.column_stack([xyz, np.full(len(xyz), 0.5, "<f4")]).astype("<f4").tobytes()


def _pcd() -> bytes:
    xyz = np.load(sample_path("kitti_pair", "000094.npy"))[:40, :3]
    body = "\n".join(" ".join(f"{v:.3f}" for v in row) for row in xyz)
    return (f"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 40\nHEIGHT 1\n"
            f"VIEWPOINT 0 0 0 1 0 0 0\nPOINTS 40\nDATA ascii\n{body}\n").encode()


def _npy() -> bytes:
    import io

    buf = io.BytesIO()
    np.save(buf, np.load(sample_path("kitti_pair", "000094.npy"))[:50, :3].astype(np.float32))
    return buf.getvalue()


def _suite() -> bytes:
    return (b"name: fuzz\nseeds: [0, 1]\nexperiments:\n  - name: a\n    task: selftest\n    dataset: {kind: synthetic}\n"
            b"    methods:\n      - name: random_walk\n        params: {steps: 5}\n        grid: {noise_m: [0.1, 0.2]}\n")


def _readers() -> dict[str, tuple[str, bytes, Callable[[Path], object]]]:
    from lidarkit.bench.suite import load_suite
    from lidarkit.io.images import read_image_timestamps, read_intrinsics
    from lidarkit.io.kitti import read_kitti_calib
    from lidarkit.io.landmarks import LandmarkData, read_world
    from lidarkit.io.pointfile import read_point_file
    from lidarkit.trajectory import Trajectory

    freiburg = sample_path("freiburg_pf")
    evo = sample_path("evo_kitti00")

    def landmarks(path: Path) -> object:
        (path.parent / "world.dat").write_bytes((freiburg / "world.dat").read_bytes())
        return LandmarkData(path.parent, sensor=path)

    def tum(path: Path) -> object:
        return Trajectory.from_tum(path)

    return {
        "kitti_bin": (".bin", _bin_scan(), read_point_file),
        "npy": (".npy", _npy(), read_point_file),
        "pcd": (".pcd", _pcd(), read_point_file),
        "kitti_poses": (".txt", _text_head(evo / "KITTI_00_gt.txt.gz", 20, gz=True), Trajectory.from_kitti),
        "tum": (".txt", b"# t x y z qx qy qz qw\n" + b"".join(
            f"{i * 0.1:.1f} {i:.1f} 0 0 0 0 0 1\n".encode() for i in range(15)), tum),
        "kitti_calib": (".txt", (sample_path("kitti_vo", "06", "calib.txt")).read_bytes(), read_kitti_calib),
        "intrinsics": (".txt", b"718.856 718.856 607.19 185.21\n", read_intrinsics),
        "image_times": (".txt", _text_head(sample_path("kitti_vo", "06", "times.txt"), 8), read_image_timestamps),
        "world": (".dat", (freiburg / "world.dat").read_bytes(), read_world),
        "sensor_data": (".dat", _text_head(freiburg / "sensor_data.dat", 40), landmarks),
        "suite": (".yaml", _suite(), load_suite),
    }


READERS = _readers()


@pytest.mark.parametrize("name", sorted(READERS))
def test_reader_survives_fuzzing(name):
    suffix, original, read = READERS[name]
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"input{suffix}"
        read(path) if path.write_bytes(original) else None  # the unmutated file is valid

        @FUZZ
        @given(data=mutated(original))
        def check(data: bytes) -> None:
            only_lidarkit_errors(read, path, data)

        check()
