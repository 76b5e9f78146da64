"""Dataset readers behind one registry: ``open_dataset(kind, path, **options)``.

Built-in kinds are imported only when asked for (pykitti and Open3D are slow to import);
third-party readers register themselves with :func:`register_dataset`.
"""

from __future__ import annotations

import importlib
import inspect
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

from lidarkit.errors import ConfigError
from lidarkit.plugins import checked_name, claim_name

# kind -> "module:attribute" of the reader class, imported on first use
_BUILTIN: dict[str, str] = {
    "kitti": "lidarkit.io.kitti:KittiOdometry",
    "kitti_raw": "lidarkit.io.kitti_raw:KittiRaw",
    "folder": "lidarkit.io.folder:ScanFolder",
    "tum": "lidarkit.io.tum:TumRGBD",
    "landmarks": "lidarkit.io.landmarks:LandmarkData",
    "carmen": "lidarkit.io.carmen:CarmenLog",
    # kiss-icp's dataloaders (lidarkit.io.kiss_loaders.KISS_KINDS maps kiss-icp names to these kinds)
    "rosbag": "lidarkit.io.rosbag:RosbagScans",
    "mcap": "lidarkit.io.rosbag:McapScans",
    "ouster": "lidarkit.io.kiss_loaders:OusterScans",
    "nclt": "lidarkit.io.kiss_loaders:NcltScans",
    "mulran": "lidarkit.io.kiss_loaders:MulranScans",
    "ncd": "lidarkit.io.kiss_loaders:NewerCollegeScans",
    "helipr": "lidarkit.io.kiss_loaders:HeliprScans",
    "boreas": "lidarkit.io.kiss_loaders:BoreasScans",
    "apollo": "lidarkit.io.kiss_loaders:ApolloScans",
    "nuscenes": "lidarkit.io.kiss_loaders:NuScenesScans",
    "generic": "lidarkit.io.kiss_loaders:GenericScans",
    "kiss_kitti": "lidarkit.io.kiss_loaders:KissKittiScans",
    "kiss_kitti_raw": "lidarkit.io.kiss_loaders:KissKittiRawScans",
    "kiss_tum": "lidarkit.io.kiss_loaders:KissTumScans",
}
_REGISTERED: dict[str, Callable[..., Any]] = {}
#: Built-in kinds whose readers hold other data than LiDAR scans (TUM RGB-D images, a landmark map)
NOT_SCANS = frozenset({"tum", "landmarks"})
#: what :func:`detect_kind` recognises a file by: its suffix -> kind; a CARMEN log (``.clf``) also compressed
DETECTED_SUFFIXES = {".bag": "rosbag", ".mcap": "mcap", ".pcap": "ouster", ".clf": "carmen"}
CARMEN_COMPRESSED = (".bz2", ".gz", ".xz")


def detected_files() -> str:
    """The files :func:`detect_kind` recognises, for messages (a list written out apart left CARMEN logs out)."""
    return f"a {'/'.join(DETECTED_SUFFIXES)} file (also {'/'.join(f'.clf{s}' for s in CARMEN_COMPRESSED)})"


def register_dataset(kind: str) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Class decorator registering a reader under ``kind``; the class is called as ``cls(path, **options)`` (the naming
    rule: :mod:`lidarkit.plugins`)."""
    checked_name(kind, "a dataset kind", "register_dataset")

    def decorator(reader: Callable[..., Any]) -> Callable[..., Any]:
        claim_name(_REGISTERED, kind, reader, f"register_dataset({kind!r})", _BUILTIN)
        _REGISTERED[kind] = reader
        return reader

    return decorator


def available_datasets() -> list[str]:
    """Names of every dataset kind ``open_dataset`` accepts."""
    return sorted(set(_BUILTIN) | set(_REGISTERED))


def detect_kind(path: str | os.PathLike) -> str | None:
    """The dataset kind a path unambiguously is, by extension or layout, else None.

    ``.bag`` (or a folder of ``.bag`` files) and a ROS 2 bag folder (``metadata.yaml``): ``rosbag``;
    ``.mcap``: ``mcap``; ``.pcap``: ``ouster``; a CARMEN log (``.clf``, also ``.clf.bz2`` / ``.gz`` / ``.xz``):
    ``carmen``; a folder with ``velodyne/`` or ``sequences/``: ``kitti``. A folder that is both a bag and KITTI
    raises ConfigError naming both readings (it was read as the bag, without a word).
    """
    from pathlib import Path

    if not isinstance(path, (str, os.PathLike)):  # (5 failed "expected str, bytes or os.PathLike object, not int")
        raise ConfigError(f"expected a path, got {type(path).__name__} {path!r:.60}", source="path")
    p = Path(path)
    suffix = p.suffix.lower()
    if p.is_file() or not p.exists():
        if ".clf" in [s.lower() for s in p.suffixes[-2:]]:
            return "carmen"
        if p.name == "metadata.yaml" and p.is_file():  # a ROS 2 bag's metadata (the reader opens its folder)
            return "rosbag"
        return DETECTED_SUFFIXES.get(suffix)
    bags = sorted(b.name for b in p.glob("*.bag"))
    bag = "metadata.yaml" if (p / "metadata.yaml").is_file() else bags[0] if bags else None
    kitti = next((name for name in ("velodyne", "sequences") if (p / name).is_dir()), None)
    if bag and kitti:
        raise ConfigError(f"both a KITTI dataset ({kitti}/) and a ROS bag ({bag}): give kitti:{p} or rosbag:{p}", source=p)
    return "rosbag" if bag else "kitti" if kitti else None


def ros2_storage_problem(path: str | os.PathLike) -> str | None:
    """Why ``path`` is a ROS 2 bag's storage that cannot be opened as it is (a ``.db3`` file given alone, a folder of
    ``.db3`` or ``.mcap`` files without ``metadata.yaml``), or None: read as a folder of scans it said "no scan files"."""
    from pathlib import Path

    p = Path(path)
    if p.is_file() and p.suffix.lower() == ".db3":
        return f"a ROS 2 bag is opened as its folder, the one with metadata.yaml: give {p.parent}"
    if p.is_dir() and not (p / "metadata.yaml").is_file():
        if any(p.glob("*.db3")):
            return "a ROS 2 bag folder (.db3 storage) without its metadata.yaml: 'ros2 bag reindex' rebuilds it"
        mcaps = sorted(p.glob("*.mcap"))
        if mcaps:
            return (f"a ROS 2 bag folder (.mcap storage) without its metadata.yaml: 'ros2 bag reindex' rebuilds it, or "
                    f"give one .mcap file ({mcaps[0]})")
    return None


def get_reader(kind: str) -> Callable[..., Any]:
    """The reader class for ``kind``; unknown kinds raise ConfigError listing the known ones."""
    if kind in _REGISTERED:
        return _REGISTERED[kind]
    if kind not in _BUILTIN:
        raise ConfigError(f"unknown dataset kind {kind!r}; known: {', '.join(available_datasets())}", source="dataset kind")
    module_name, attr = _BUILTIN[kind].split(":")
    return getattr(importlib.import_module(module_name), attr)


def open_dataset(kind: str, path: str | os.PathLike, **options: Any) -> Any:
    """Open the dataset at ``path`` with the reader registered as ``kind``.

    Options the reader does not take (or a missing required one) raise ConfigError listing the valid ones.
    """
    if not isinstance(path, (str, os.PathLike)):  # (None or a number: a TypeError from pathlib)
        raise ConfigError(f"the dataset path must be a path, got {type(path).__name__} {path!r}", source=f"{kind} dataset")
    reader = get_reader(kind)
    from lidarkit.atomic import missing_reason
    from lidarkit.errors import DataError

    link_problem = missing_reason(path, not_found="") if not os.path.exists(path) else ""
    if link_problem:  # (a loop of links read "dataset folder not found"; a missing path is each reader's to name)
        raise DataError(link_problem, source=path)
    try:
        signature = inspect.signature(reader)
    except (TypeError, ValueError):  # some builtins / C types have no signature: let the call decide
        signature = None
    if signature is not None:
        try:
            signature.bind(path, **options)
        except TypeError as err:
            params = list(signature.parameters.values())[1:]
            valid = [p.name for p in params if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)]
            unknown = [name for name in options if name not in valid]
            # (Python's own words read "got an unexpected keyword argument 'min_range_m'")
            why = f"unknown option{'s' if len(unknown) > 1 else ''} {', '.join(map(repr, unknown))}" if unknown else str(err)
            raise ConfigError(f"{why}; valid options: {', '.join(valid) or 'none'}", source=f"{kind} dataset options") from None
        options = _typed_options(reader, kind, options)
    return reader(path, **options)


def _typed_options(reader: Any, kind: str, options: dict[str, Any]) -> dict[str, Any]:
    """Options checked against the reader's annotations where those are plain (bool, int, float, str, None and their
    unions): ``drop_nonfinite=flase`` (a typo, truthy as text), ``min_range_m=abc`` or ``min_range_m=true`` (pydantic
    read True as 1.0) is a ConfigError naming it."""
    import typing

    from pydantic import TypeAdapter, ValidationError

    try:
        hints = typing.get_type_hints(reader.__init__ if inspect.isclass(reader) else reader)
    except Exception:  # noqa: BLE001 - annotations that do not resolve: the reader checks its options itself
        return options
    plain = {bool, int, float, str, type(None)}
    out = dict(options)
    for name, value in options.items():
        hint = hints.get(name)
        if hint is None:
            continue
        kinds = set(typing.get_args(hint) or (hint,))
        if not kinds <= plain:
            out[name] = _text_option(kind, name, value, kinds)
            continue
        if isinstance(value, bool) and bool not in kinds and kinds & {int, float}:
            expected = "a number or text" if str in kinds else "a number"
            raise ConfigError(f"must be {expected}, not a bool, got {value!r}", source=f"{kind} dataset option {name}")
        try:
            out[name] = TypeAdapter(hint).validate_python(value)
        except ValidationError as err:
            reason = err.errors()[0].get("msg", "invalid value")
            raise ConfigError(f"{reason}, got {value!r}", source=f"{kind} dataset option {name}") from None
    return out


def text_options(kind: str) -> set[str]:
    """The options of reader ``kind`` that take a path or text and no number: a spec keeps their value as written
    (``velodyne_dir=1.50`` is a folder named 1.50, which the value parser read as the number 1.5)."""
    import typing

    reader = get_reader(kind)
    try:
        hints = typing.get_type_hints(reader.__init__ if inspect.isclass(reader) else reader)
    except Exception:  # noqa: BLE001 - annotations that do not resolve: nothing known
        return set()
    names = set()
    for name, hint in hints.items():
        kinds = set(typing.get_args(hint) or (hint,))
        takes_text = str in kinds or any(getattr(k, "__origin__", k) in (os.PathLike, Path) for k in kinds)
        if takes_text and not kinds & {int, float}:
            names.add(name)
    return names


def _text_option(kind: str, name: str, value: Any, kinds: set) -> Any:
    """A path or list option (``str | os.PathLike``, ``tuple[str, ...] | str``) whose text a spec's value parser read
    as a number, a boolean or nothing (``velodyne_dir=2``, ``suffixes=``): the number back as its text (a folder named
    ``2``), nothing or a boolean refused naming the option (TypeError tracebacks inside the readers)."""
    takes_text = str in kinds or any(getattr(k, "__origin__", k) in (os.PathLike, Path) for k in kinds)
    if not takes_text or isinstance(value, (str, os.PathLike)):
        return value
    if value is None:
        if type(None) in kinds:
            return value
        raise ConfigError("needs a value", source=f"{kind} dataset option {name}")
    if isinstance(value, bool):
        raise ConfigError(f"expected a path or text, got {value!r}", source=f"{kind} dataset option {name}")
    if isinstance(value, (int, float)):
        return str(value)
    return value


__all__ = [
    "DETECTED_SUFFIXES", "NOT_SCANS", "available_datasets", "detect_kind", "detected_files", "get_reader", "open_dataset",
    "register_dataset", "text_options",
]
