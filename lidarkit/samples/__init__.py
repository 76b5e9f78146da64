"""Small real data excerpts bundled with lidarkit (each folder has a SOURCES.md with origin and licence).

``sample_path("evo_kitti00", "KITTI_00_gt.txt.gz")`` gives the installed file; ``extract_sample(...)``
writes a plain copy (gunzipping ``.gz`` members) where readers that expect plain text can use it.
"""

from __future__ import annotations

import gzip
import os
import shutil
from importlib import resources
from pathlib import Path

from lidarkit import atomic
from lidarkit.errors import DataError

__all__ = ["available_samples", "extract_sample", "path", "sample_path"]


def _root() -> Path:
    return Path(str(resources.files(__name__)))


def sample_path(*parts: str) -> Path:
    """Path of a bundled sample file or folder, e.g. ``sample_path("evo_kitti00", "KITTI_00_gt.txt.gz")``.

    ``parts`` may also be one slash-separated string. A missing sample raises DataError naming it.
    """
    if not parts:
        raise DataError("name a sample, e.g. sample_path('evo_kitti00', 'KITTI_00_gt.txt.gz')", source="samples")
    rel = Path(*[p for part in parts for p in str(part).split("/") if p])
    if rel.is_absolute() or ".." in rel.parts:
        raise DataError("sample names are relative paths inside lidarkit/samples", source=str(rel))
    full = _root() / rel
    if not full.exists():
        known = ", ".join(available_samples()) or "none"
        raise DataError(f"bundled sample not found (known: {known})", source=str(rel))
    return full


path = sample_path  # short alias: ``lidarkit.samples.path("evo_kitti00/KITTI_00_gt.txt.gz")``


def available_samples() -> list[str]:
    """Names of the bundled sample folders."""
    root = _root()
    return sorted(p.name for p in root.iterdir() if p.is_dir() and not p.name.startswith(("_", ".")))


def extract_sample(*parts: str, dest_dir: str | os.PathLike) -> Path:
    """Copy a bundled file into ``dest_dir`` as plain data and return the copy's path.

    ``extract_sample("evo_kitti00", "KITTI_00_gt.txt", dest_dir=d)`` finds ``KITTI_00_gt.txt`` or, if only
    the compressed ``KITTI_00_gt.txt.gz`` is bundled, decompresses it to ``d/KITTI_00_gt.txt`` (atomically).
    """
    rel = "/".join(parts)
    try:
        src = sample_path(rel)
        compressed = False
    except DataError:
        src = sample_path(rel + ".gz")
        compressed = True
    dest = Path(dest_dir) / Path(rel).name
    with atomic.atomic_path(dest) as tmp:
        if compressed:
            with gzip.open(src, "rb") as fin, open(tmp, "wb") as fout:
                shutil.copyfileobj(fin, fout)
        else:
            shutil.copyfile(src, tmp)
    return dest
