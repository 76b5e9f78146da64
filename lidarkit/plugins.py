"""The names plugins register under, one rule for every registry (ICP variants, pipeline components, ground
segmenters, dataset readers, benchmark tasks).

A name is a non-empty word without spaces: None broke listing the names (sorting) and every "unknown name" message.
A taken name stays with its class, except for a redefinition of that same class (same module and qualified name: a
notebook cell run again, a module reloaded), which replaces it; an other class is refused, built-ins included.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from lidarkit.errors import ConfigError


def checked_name(name: Any, noun: str, source: str) -> str:
    """``name`` when it can name a plugin; else a ConfigError from ``source`` (``"register_task"``) saying ``noun``
    (``"a task name"``) must be a non-empty word."""
    if not isinstance(name, str) or name.split() != [name]:
        raise ConfigError(f"{noun} must be a non-empty word without spaces, got {name!r}", source=source)
    return name


def _definition(obj: Any) -> tuple[str, str] | None:
    """Where ``obj`` is defined, ``(module, qualified name)``; None for an object without both (an instance)."""
    module, qualname = getattr(obj, "__module__", None), getattr(obj, "__qualname__", None)
    return (module, qualname) if isinstance(module, str) and isinstance(qualname, str) else None


def claim_name(registered: Mapping[str, Any], name: str, obj: Any, source: str,
               builtins: Mapping[str, str] | None = None) -> None:
    """Refuse to register ``obj`` as ``name`` when another definition holds it: one in ``registered``, or a built-in
    imported on first use (``builtins``: name -> ``"module:attribute"``). ConfigError from ``source`` naming the
    holder; the same object or a redefinition of its class passes (the caller then replaces the old one)."""
    existing = registered.get(name)
    if existing is not None:
        if existing is obj or (_definition(existing) is not None and _definition(existing) == _definition(obj)):
            return
        holder = ".".join(_definition(existing)) if _definition(existing) is not None else repr(existing)
    elif builtins is not None and name in builtins:
        module, attribute = builtins[name].split(":")
        if _definition(obj) == (module, attribute):
            return
        holder = f"the built-in {module}.{attribute}"
    else:
        return
    raise ConfigError(f"name already taken by {holder}; register yours under another name", source=source)


__all__ = ["checked_name", "claim_name"]
