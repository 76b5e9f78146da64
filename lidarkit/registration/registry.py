"""Registry of ICP variants: ``@register_icp(name)``, ``get_icp(name, **params)``, ``available_icp()``.

Built-in variants register when :mod:`lidarkit.registration` imports their modules; third-party
packages declare an entry point in the group ``lidarkit.icp`` (``name = "pkg.module:VariantClass"``),
loaded lazily the first time the registry is asked for names or for that variant.
"""

from __future__ import annotations

import logging
import re
from collections.abc import Callable
from importlib.metadata import entry_points
from types import UnionType
from typing import Any, Literal, Union, get_args, get_origin

import pydantic

from lidarkit.errors import ConfigError, validation_problems
from lidarkit.params import shown_default
from lidarkit.plugins import checked_name, claim_name
from lidarkit.registration.base import Registration, RegistrationConfig

log = logging.getLogger(__name__)

ENTRY_POINT_GROUP = "lidarkit.icp"

_VARIANTS: dict[str, type[Registration]] = {}
_PLUGINS_LOADED = False
#: built-in variants whose library is an optional extra: name -> (package, extra)
OPTIONAL_VARIANTS = {"small_gicp": ("small_gicp", "gicp"), "genz": ("genz-icp", "genz")}
#: installed plugins that failed to load: name -> reason
_BROKEN: dict[str, str] = {}


def register_icp(name: str) -> Callable[[type[Registration]], type[Registration]]:
    """Class decorator: register a :class:`Registration` subclass under ``name`` (sets ``cls.name``; the naming rule:
    :mod:`lidarkit.plugins`)."""
    checked_name(name, "a variant name", "register_icp")

    def decorator(cls: type[Registration]) -> type[Registration]:
        if not (isinstance(cls, type) and issubclass(cls, Registration)):
            raise ConfigError(f"{cls!r} is not a Registration subclass", source=f"register_icp({name!r})")
        config = getattr(cls, "Config", None)
        if not (isinstance(config, type) and issubclass(config, RegistrationConfig)):
            raise ConfigError(f"{cls.__qualname__}.Config must derive from lidarkit.registration.RegistrationConfig (it carries the "
                              f"assessment and covariance settings every variant takes), got {config!r}", source=f"register_icp({name!r})")
        claim_name(_VARIANTS, name, cls, f"register_icp({name!r})")
        cls.name = name
        _VARIANTS[name] = cls
        return cls

    return decorator


def _load_plugins() -> None:
    """Import every ``lidarkit.icp`` entry point once. A broken plugin is left out with a warning (the others and
    the built-in variants stay usable); asking for it by name raises ConfigError with the reason (:data:`_BROKEN`)."""
    global _PLUGINS_LOADED
    if _PLUGINS_LOADED:
        return
    _PLUGINS_LOADED = True
    _BROKEN.clear()
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        if ep.name in _VARIANTS:
            builtin = getattr(_VARIANTS[ep.name], "__module__", "").startswith("lidarkit.")
            if builtin and not ep.value.startswith("lidarkit."):  # (it was dropped without a word, nor listed as left out)
                _BROKEN[ep.name] = f"its name is a built-in variant's: {ep.value!r} left out (rename the entry point)"
                log.warning("ICP plugin %r left out: %s", ep.name, _BROKEN[ep.name])
            continue
        try:
            obj = ep.load()
            if ep.name not in _VARIANTS:
                if not (isinstance(obj, type) and issubclass(obj, Registration)):
                    raise ConfigError(f"entry point {ep.value!r} is not a Registration subclass", source=f"ICP plugin {ep.name!r}")
                register_icp(ep.name)(obj)
        except Exception as err:  # a plugin may fail in any way while importing
            reason = err.reason if isinstance(err, ConfigError) else f"failed to load {ep.value!r}: {type(err).__name__}: {err}"
            _BROKEN[ep.name] = reason
            log.warning("ICP plugin %r left out: %s", ep.name, reason)
            continue
        log.info("loaded ICP plugin %s from %s", ep.name, ep.value)


def broken_plugins() -> dict[str, str]:
    """The installed ICP plugins that failed to load, with the reason (name -> reason)."""
    _load_plugins()
    return dict(_BROKEN)


def reload_plugins() -> None:
    """Forget which entry points were loaded and scan the group again (after installing a plugin)."""
    global _PLUGINS_LOADED
    _PLUGINS_LOADED = False
    _load_plugins()


def available_icp() -> list[str]:
    """Sorted names of every registered variant, plugins included."""
    _load_plugins()
    return sorted(_VARIANTS)


def missing_optional_variants() -> dict[str, str]:
    """Built-in variants whose optional library is not installed: name -> the pip line that installs it."""
    _load_plugins()
    return {name: f"pip install 'lidarkit[{extra}]'" for name, (_, extra) in OPTIONAL_VARIANTS.items() if name not in _VARIANTS}


def _same_class(a: type, b: type) -> bool:
    """``a`` is ``b``, or a redefinition of it (a notebook cell run again: the registry holds the newer class)."""
    return a is b or (a.__module__, a.__qualname__) == (b.__module__, b.__qualname__)


def recorded_name(cls: type[Registration]) -> str:
    """What results and runs of variant class ``cls`` record as their method: the name it is registered under; for a
    class outside the registry, a name of its own that no registered variant holds, else ``ClassName(parent)`` naming
    the variant it derives from. (A subclass inherits its parent's ``name``: a vanilla with another ``_align`` was
    recorded as ``vanilla`` with vanilla's config, and re-running that config ran vanilla.)"""
    own = vars(cls).get("name")
    if not (own and own in _VARIANTS):
        _load_plugins()  # (a plugin's class instantiated before its entry point was loaded: registered now)
        own = vars(cls).get("name")
    if own and (own not in _VARIANTS or _same_class(_VARIANTS[own], cls)):
        return own
    parent = next((str(vars(k)["name"]) for k in cls.__mro__[1:] if vars(k).get("name")), "")
    return f"{cls.__name__}({parent})" if parent else cls.__name__


def registered_ancestor(cls: type[Registration]) -> str | None:
    """The name of the nearest registered variant in ``cls``'s bases (``cls`` itself included), None for none."""
    for klass in cls.__mro__:
        own = vars(klass).get("name")
        if own and own in _VARIANTS and _same_class(_VARIANTS[own], klass):
            return str(own)
    return None


def get_icp_class(name: str) -> type[Registration]:
    """The class registered as ``name``; unknown names raise ConfigError listing the known ones."""
    if name not in _VARIANTS:
        _load_plugins()
    unknown = isinstance(name, str) and name not in _VARIANTS
    # (a parent is a plain variant name: "vanilla(voxel_size_m=0.5)" read as a subclass of "voxel_size_m=0.5")
    subclass = re.fullmatch(r"(\w+)\((\w+)\)", name) if unknown else None
    if subclass:  # (recorded_name's form: a run of such a class re-run from its config.yaml)
        raise ConfigError(f"{name!r} is how runs record {subclass[1]}, a subclass of {subclass[2]} outside the registry: it "
                          f"cannot be run by name until it is registered (@register_icp or a '{ENTRY_POINT_GROUP}' entry "
                          "point)", source="method")
    label = re.fullmatch(r"(\w+)\((\s*\w+\s*=.*)\)", name, flags=re.DOTALL) if unknown else None
    if label:  # (a report's or a baseline's row label given as the method)
        raise ConfigError(label_as_method_hint(name, label[1], label[2]), source="method")
    if name in _BROKEN and name not in _VARIANTS:  # (a plugin named like a built-in: the built-in answers)
        raise ConfigError(f"this plugin is installed but could not be loaded: {_BROKEN[name]}", source=f"ICP plugin {name!r}")
    if name in OPTIONAL_VARIANTS and name not in _VARIANTS:  # (it read as a typo: "unknown ICP method 'small_gicp'")
        package, extra = OPTIONAL_VARIANTS[name]
        raise ConfigError(f"the {name!r} variant needs the Python package {package!r}, not installed here: "
                          f"pip install 'lidarkit[{extra}]'", source="method")
    if name not in _VARIANTS:
        missing = missing_optional_variants()  # (a typo of small_gicp never said it existed)
        also = f" (not installed: {', '.join(f'{m}, {pip}' for m, pip in missing.items())})" if missing else ""
        raise ConfigError(f"unknown ICP method {name!r}; available: {', '.join(available_icp())}{also}", source="method")
    return _VARIANTS[name]


def label_as_method_hint(label: str, method: str, inner: str) -> str:
    """Why the label ``method(k=v, ...)`` (how bench rows and runs name a method with its params) is not a method name,
    and how to write that method: its name and its params apart."""
    pairs = [part.strip().partition("=") for part in _top_level_split(inner)]
    params = ", ".join(f"{k.strip()}: {v.strip()}" for k, _, v in pairs)
    options = " ".join(f"-p {k.strip()}={v.strip()}" for k, _, v in pairs)
    return (f"{label!r} is a label (the variant {method} with its parameters), not a method name: write the method as "
            f"{{name: {method}, params: {{{params}}}}} (CLI: --method {method} {options})")


def _top_level_split(text: str) -> list[str]:
    """``text`` split at the commas outside brackets (``a=1, b=[1, 2]``: two parts)."""
    parts, depth, start = [], 0, 0
    for i, char in enumerate(text):
        depth += char in "([{"
        depth -= char in ")]}"
        if char == "," and depth == 0:
            parts.append(text[start:i])
            start = i + 1
    parts.append(text[start:])
    return [part for part in parts if part.strip()]


def _type_name(annotation: Any) -> str:
    """Readable type of a config field: ``float``, ``float | None``, ``'a' | 'b'`` for Literal choices."""
    if get_origin(annotation) is Literal:
        return " | ".join(repr(a) for a in get_args(annotation))
    args = get_args(annotation)
    origin = get_origin(annotation)
    if args and origin in (Union, UnionType):
        return " | ".join(_type_name(a) for a in args)
    if args:  # a container: dict[str, Any], tuple[float, ...]
        inner = ", ".join("..." if a is Ellipsis else _type_name(a) for a in args)
        return f"{getattr(origin, '__name__', str(origin))}[{inner}]"
    if annotation is Any:
        return "Any"
    return "None" if annotation is type(None) else getattr(annotation, "__name__", str(annotation))


def config_fields(name: str) -> dict[str, tuple[str, Any, str]]:
    """``{param: (type, default, description)}`` of a variant's config, generated from the model."""
    cls = get_icp_class(name)
    out = {}
    for key, info in cls.Config.model_fields.items():
        type_name = _type_name(info.annotation)
        out[key] = (type_name, info.get_default(call_default_factory=True), info.description or "")
    return out


def not_a_choice(config: type[RegistrationConfig], params: dict[str, Any]) -> str:
    """``"preset: one of 'kiss_like' | 'vanilla_seq' | None, got list []"`` for the params of choice fields (``Literal``)
    given a list or a mapping, else ``""``: checked before the config's own validators, which may look a choice up
    (``preset=[]`` raised a bare "unhashable type: 'list'")."""
    problems = []
    for key, value in params.items():
        info = config.model_fields.get(key)
        if info is None or not isinstance(value, (list, dict, set)):
            continue
        annotation = info.annotation
        choices = [annotation] + [a for a in get_args(annotation) if get_origin(annotation) in (Union, UnionType)]
        if any(get_origin(a) is Literal for a in choices):
            problems.append(f"{key}: one of {_type_name(annotation)}, got {type(value).__name__} {value!r:.60}")
    return "; ".join(problems)


def get_icp(name: str, **params: Any) -> Registration:
    """A configured instance of variant ``name``; bad or unknown params raise ConfigError listing valid ones."""
    from lidarkit.registration.components.registry import glued_yaml_hint

    cls = get_icp_class(name)
    valid = ", ".join(f"{k}={shown_default(v[1])}" for k, v in config_fields(name).items()) or "(none)"
    unhashable_choices = not_a_choice(cls.Config, params)
    if unhashable_choices:
        raise ConfigError(f"invalid parameters ({unhashable_choices}); valid parameters: {valid}", source=f"method {name!r}")
    try:
        config = cls.Config(**params)
    except pydantic.ValidationError as err:
        problems = validation_problems(err, unnamed="")
        raise ConfigError(f"invalid parameters ({problems}){glued_yaml_hint(params)}; valid parameters: {valid}",
                          source=f"method {name!r}") from None
    except ValueError as err:
        raise ConfigError(f"invalid parameters ({err}){glued_yaml_hint(params)}; valid parameters: {valid}",
                          source=f"method {name!r}") from None
    return cls(config=config)


__all__ = ["ENTRY_POINT_GROUP", "available_icp", "broken_plugins", "config_fields", "get_icp", "get_icp_class", "register_icp", "reload_plugins"]
