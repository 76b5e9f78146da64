"""Dataset specs of a suite: resolve paths (relative to the suite file, ``sample:NAME`` bundled samples).

A spec is a plain dict ``{"kind": ..., "path": ..., "name": ..., **options}``. Kinds with a path are
the reader kinds of :mod:`lidarkit.io` (``kitti``, ``folder``, ``mcap``, ``tum``, ``landmarks``, ...); simulator
kinds (``sim_lidar``, ``sim_camera``) and ``synthetic`` have none. Sample paths stay ``sample:NAME``
in the job spec (so job keys do not depend on where the package is installed) and are resolved in the
worker by :func:`dataset_path`.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from lidarkit.errors import ConfigError, DataError

SAMPLE_PREFIX = "sample:"
#: kinds generated in the job itself: no path
PATHLESS_KINDS = frozenset({"synthetic", "sim_lidar", "sim_camera"})


def scan_kinds() -> tuple[str, ...]:
    """Every dataset kind that gives LiDAR scans: the LiDAR simulator and each :mod:`lidarkit.io` reader of scans (bags,
    MCAP, pcaps, kiss-icp's loaders, and readers registered by others), as ``lidarkit.odometry.run`` opens them."""
    from lidarkit.io import NOT_SCANS, available_datasets

    return ("sim_lidar", *(kind for kind in available_datasets() if kind not in NOT_SCANS))


def sample_path(name: str) -> Path:
    """Folder/file of the bundled sample ``name`` (through ``lidarkit.samples.sample_path`` when it exists)."""
    import lidarkit.samples as samples

    accessor = getattr(samples, "sample_path", None)
    if accessor is not None:
        return Path(accessor(name))
    path = Path(samples.__file__).resolve().parent / name
    if not path.exists():
        raise DataError(f"no bundled sample {name!r}", source=f"{SAMPLE_PREFIX}{name}")
    return path


def resolve_dataset(spec: dict[str, Any], base_dir: Path) -> dict[str, Any]:
    """Return ``spec`` with its path checked and made absolute against ``base_dir``, symbolic links kept (DataError if
    missing)."""
    kind = spec.get("kind")
    if not isinstance(kind, str) or not kind:
        raise ConfigError("dataset needs a 'kind'", source="dataset")
    path = spec.get("path")
    resolved = dict(spec)
    if kind in PATHLESS_KINDS:
        if path is not None:
            raise ConfigError(f"dataset kind {kind!r} is generated and takes no 'path'", source="dataset")
        return resolved
    if not path:
        raise ConfigError(f"dataset kind {kind!r} needs a 'path'", source="dataset")
    path = str(path)
    if path.startswith(SAMPLE_PREFIX):
        sample_path(path[len(SAMPLE_PREFIX):])  # raises DataError if absent
        resolved["path"] = path
        return resolved
    # absolute, links not followed (as the CLI opens it): a CARMEN log linked into a folder with its own .relations is
    # read with those, and a reader's files beside its path are looked up beside the link, not beside its target
    full = Path(os.path.abspath(base_dir / Path(path).expanduser()))
    if not full.exists():  # (a link to a missing file or a loop of links: which, as its target is not named now)
        from lidarkit.atomic import missing_reason

        why = missing_reason(full, "")
        raise DataError(f"dataset path does not exist: {full}" + (f" ({why})" if why else ""), source="dataset")
    resolved["path"] = str(full)
    return resolved


def resolve_option_paths(spec: dict[str, Any], base_dir: Path) -> dict[str, Any]:
    """Make relative path options of a reader absolute (e.g. ``velodyne_dir``, ``poses``).

    Options the reader's signature types as ``os.PathLike`` are looked up first inside the dataset folder,
    then beside the suite file; the first that exists becomes an absolute path. Found in neither but from the working
    directory: DataError (left relative, each run read the file of its own working directory: one job key, different
    files); found nowhere: left to the reader, which looks in its own folders (KITTI's sequence folder) and names them.
    The reader's own default (TUM's ``groundtruth.txt``), bundled samples and generated kinds are left alone.
    """
    kind, path = spec.get("kind"), spec.get("path")
    if kind in PATHLESS_KINDS or not path or str(path).startswith(SAMPLE_PREFIX):
        return spec
    import inspect

    from lidarkit.io import get_reader

    try:
        params = inspect.signature(get_reader(kind)).parameters
    except (ConfigError, TypeError, ValueError):
        return spec
    data_dir = Path(path) if Path(path).is_dir() else Path(path).parent
    out = dict(spec)
    for key, value in dataset_options(spec).items():
        if key not in params or not isinstance(value, str) or Path(value).is_absolute():
            continue
        if "PathLike" not in str(params[key].annotation):
            continue
        if value == params[key].default:
            continue
        found = [root / value for root in (data_dir, base_dir) if (root / value).exists()]
        if found:
            out[key] = str(found[0].resolve())
        elif Path(value).exists():
            raise DataError(f"{key} {value!r} is found only from the working directory, neither in the dataset folder {data_dir} "
                            f"nor beside the suite file (in {base_dir}): give it from the suite file's folder or absolute",
                            source="dataset")
    return out


def dataset_path(spec: dict[str, Any]) -> Path:
    """The filesystem path of a resolved dataset spec (bundled samples resolved here)."""
    path = spec.get("path")
    if path is None:
        raise ConfigError(f"dataset kind {spec.get('kind')!r} has no path", source="dataset")
    if str(path).startswith(SAMPLE_PREFIX):
        return sample_path(str(path)[len(SAMPLE_PREFIX):])
    return Path(path)


def dataset_options(spec: dict[str, Any]) -> dict[str, Any]:
    """The spec without ``kind``, ``path`` and ``name``: options for the reader / simulator."""
    return {k: v for k, v in spec.items() if k not in ("kind", "path", "name")}


def dataset_label(spec: dict[str, Any]) -> str:
    """Report label: the spec's ``name`` or ``kind:basename[/sequence]``."""
    if spec.get("name"):
        return str(spec["name"])
    label = spec["kind"]
    if spec.get("path"):
        path = str(spec["path"])
        base = path[len(SAMPLE_PREFIX):] if path.startswith(SAMPLE_PREFIX) else Path(path).name
        label = f"{label}:{base}"
    if spec.get("sequence") is not None:
        label = f"{label}/{spec['sequence']}"
    return label
