"""Dataset readers behind one registry: ``open_dataset(kind, path, **options)``.

Built-in kinds are imported only when asked for (pykitti and Open3D are slow to import);
third-party readers register themselves with :func:`register_dataset`.
"""

from __future__ import annotations

import importlib
import inspect
import os
from collections.abc import Callable
from typing import Any

from lidarkit.errors import ConfigError

# kind -> "module:attribute" of the reader class, imported on first use
_BUILTIN: dict[str, str] = {
    "kitti": "lidarkit.io.kitti:KittiOdometry",
    "kitti_raw": "lidarkit.io.kitti_raw:KittiRaw",
    "folder": "lidarkit.io.folder:ScanFolder",
    "tum": "lidarkit.io.tum:TumRGBD",
    "landmarks": "lidarkit.io.landmarks:LandmarkData",
    "carmen": "lidarkit.io.carmen:CarmenLog",
}
_REGISTERED: dict[str, Callable[..., Any]] = {}


def register_dataset(kind: str) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Class decorator registering a reader under ``kind``; the class is called as ``cls(path, **options)``."""

    def decorator(reader: Callable[..., Any]) -> Callable[..., Any]:
        _REGISTERED[kind] = reader
        return reader

    return decorator


def available_datasets() -> list[str]:
    """Names of every dataset kind ``open_dataset`` accepts."""
    return sorted(set(_BUILTIN) | set(_REGISTERED))


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
    reader = get_reader(kind)
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
            raise ConfigError(
                f"{err}; valid options: {', '.join(valid) or 'none'}", source=f"{kind} dataset options"
            ) from None
    return reader(path, **options)


__all__ = ["available_datasets", "get_reader", "open_dataset", "register_dataset"]
