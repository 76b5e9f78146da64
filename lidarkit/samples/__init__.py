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
from lidarkit.errors import ConfigError, DataError

__all__ = ["available_samples", "extract_sample", "path", "sample_path"]


def _root() -> Path:
    return Path(str(resources.files(__name__)))


def _relative(parts: tuple, example: str) -> Path:
    """The sample named by ``parts`` (names or paths, each possibly slash-separated) as a path inside the samples."""
    if not parts:
        raise DataError(f"name a sample, e.g. {example}", source="samples")
    for part in parts:  # (None was looked up as a sample named "None")
        if not isinstance(part, (str, os.PathLike)):
            raise ConfigError(f"sample names must be str or os.PathLike, got {type(part).__name__}", source="samples")
    rel = Path(*[p for part in parts for p in os.fspath(part).split("/") if p])
    if rel.is_absolute() or ".." in rel.parts:
        raise DataError("sample names are relative paths inside lidarkit/samples", source=str(rel))
    if not rel.parts:
        raise DataError(f"name a sample, e.g. {example}", source="samples")
    return rel


def sample_path(*parts: str | os.PathLike) -> Path:
    """Path of a bundled sample file or folder, e.g. ``sample_path("evo_kitti00", "KITTI_00_gt.txt.gz")``.

    ``parts`` may also be one slash-separated string. A missing sample raises DataError naming it.
    """
    rel = _relative(parts, "sample_path('evo_kitti00', 'KITTI_00_gt.txt.gz')")
    full = _root() / rel
    if not full.exists():
        raise DataError(f"bundled sample not found ({_known_beside(rel)})", source=rel.as_posix())
    return full


def _known_beside(rel: Path) -> str:
    """What the samples hold where ``rel`` was looked for: its sample folder's entries, or the sample folders."""
    folder = _root() / rel.parent
    if len(rel.parts) > 1 and folder.is_dir():
        return f"{rel.parent.as_posix()} holds: {_entries(folder)}"
    return f"known: {', '.join(available_samples()) or 'none'}"


def _entries(folder: Path) -> str:
    """The names in ``folder``, sub-folders with a trailing slash."""
    return ", ".join(sorted(p.name + ("/" if p.is_dir() else "") for p in folder.iterdir() if not p.name.startswith(("_", "."))))


path = sample_path  # short alias: ``lidarkit.samples.path("evo_kitti00/KITTI_00_gt.txt.gz")``


def available_samples() -> list[str]:
    """Names of the bundled sample folders."""
    root = _root()
    return sorted(p.name for p in root.iterdir() if p.is_dir() and not p.name.startswith(("_", ".")))


def extract_sample(*parts: str | os.PathLike, dest_dir: str | os.PathLike) -> Path:
    """Copy a bundled file into ``dest_dir`` as plain data and return the copy's path.

    ``extract_sample("evo_kitti00", "KITTI_00_gt.txt", dest_dir=d)`` finds ``KITTI_00_gt.txt`` or, if only
    the compressed ``KITTI_00_gt.txt.gz`` is bundled, decompresses it to ``d/KITTI_00_gt.txt`` (atomically).
    """
    if not isinstance(dest_dir, (str, os.PathLike)):  # (None was a TypeError from Path)
        raise ConfigError(f"dest_dir must be a folder path (str or os.PathLike), got {type(dest_dir).__name__}",
                          source="extract_sample")
    rel = _relative(parts, "extract_sample('evo_kitti00', 'KITTI_00_gt.txt', dest_dir=...)")
    src = _root() / rel
    if src.is_dir():  # (it blamed the destination: "cannot write: is a folder")
        raise DataError(f"a sample folder, not a file: name one of its files ({_entries(src)})", source=rel.as_posix())
    compressed = not src.is_file()
    if compressed:
        src = src.with_name(src.name + ".gz")
        if not src.is_file():  # named as asked, not by the .gz looked for too
            raise DataError(f"bundled sample not found ({_known_beside(rel)})", source=rel.as_posix())
    dest = Path(dest_dir) / rel.name
    with atomic.atomic_path(dest) as tmp:
        if compressed:
            with gzip.open(src, "rb") as fin, open(tmp, "wb") as fout:
                shutil.copyfileobj(fin, fout)
        else:
            shutil.copyfile(src, tmp)
    return dest
