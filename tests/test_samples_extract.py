"""Bundled samples named and copied out: paths as names, and refusals that name what was asked for."""

from __future__ import annotations

import gzip
from pathlib import Path

import pytest

from lidarkit.errors import ConfigError, DataError
from lidarkit.samples import extract_sample, sample_path


def test_extract_sample_takes_paths_and_names_what_it_refuses(tmp_path):
    """A Path name was a TypeError (its parts joined as str), dest_dir=None a TypeError, a sample folder blamed the
    destination ("cannot write: is a folder") and a missing file was named by the .gz looked for in its place."""
    plain = extract_sample(Path("evo_kitti00/KITTI_00_gt.txt"), dest_dir=tmp_path)
    assert plain == tmp_path / "KITTI_00_gt.txt"
    with gzip.open(sample_path("evo_kitti00", "KITTI_00_gt.txt.gz"), "rb") as fh:
        assert plain.read_bytes() == fh.read()
    assert extract_sample("kitti_pair", Path("T_target_source.txt"), dest_dir=str(tmp_path)).read_bytes() == \
        sample_path("kitti_pair/T_target_source.txt").read_bytes()
    refusals = (
        (lambda: extract_sample("evo_kitti00", "KITTI_00_gt.txt", dest_dir=None), ConfigError,
         "extract_sample: dest_dir must be a folder path (str or os.PathLike), got NoneType"),
        (lambda: extract_sample("kitti_pair", dest_dir=tmp_path), DataError,
         "kitti_pair: a sample folder, not a file: name one of its files (000094.npy, 000095.npy, SOURCES.md, "
         "T_target_source.txt)"),
        (lambda: extract_sample("evo_kitti00", "KITTI_00_gt.csv", dest_dir=tmp_path), DataError,
         "evo_kitti00/KITTI_00_gt.csv: bundled sample not found (evo_kitti00 holds: KITTI_00_ORB.txt.gz, "
         "KITTI_00_gt.txt.gz, KITTI_00_gt_times.txt.gz, SOURCES.md)"),
        (lambda: sample_path(None), ConfigError, "samples: sample names must be str or os.PathLike, got NoneType"),
    )
    for call, error, message in refusals:
        with pytest.raises(error) as err:
            call()
        assert str(err.value) == message
    assert sorted(p.name for p in tmp_path.iterdir()) == ["KITTI_00_gt.txt", "T_target_source.txt"]
