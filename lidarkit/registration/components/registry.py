"""Registries of pipeline components, one per kind: ``@register_component(kind, name)``, ``make_component``.

A component is a small class with a typed ``Config`` (pydantic, frozen, unknown keys rejected). Built-in
components register when :mod:`lidarkit.registration.components` imports their modules; third-party packages
declare an entry point in the group ``lidarkit.components`` named ``KIND.NAME`` (``kernel.my_kernel =
"pkg.module:MyKernel"``), loaded lazily the first time a registry is asked for names or for that component.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from importlib.metadata import entry_points
from typing import Any, ClassVar

import pydantic
from pydantic import BaseModel, ConfigDict, model_validator

from lidarkit.errors import ConfigError, RegistrationError, validation_problems
from lidarkit.params import refuse_yes_no_numbers, shown_default
from lidarkit.plugins import checked_name, claim_name

log = logging.getLogger(__name__)

ENTRY_POINT_GROUP = "lidarkit.components"

#: The kinds of component a pipeline is composed of, in the order a frame meets them.
KINDS = ("motion", "preprocess", "map", "residual", "kernel", "threshold")


class ComponentConfig(BaseModel):
    """Base of every component's config: frozen, unknown keys rejected, numbers finite and not given as yes/no (as a
    variant's config: ``initial_threshold_m: .inf`` passed ``gt=0``; "no limit" is None where a field allows it)."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    @model_validator(mode="before")
    @classmethod
    def _numbers_are_not_yes_or_no(cls, data: Any) -> Any:
        return refuse_yes_no_numbers(cls, data)


class Component:
    """Base of every component: subclasses set ``Config``; ``kind`` is set by the kind's base class."""

    kind: ClassVar[str] = ""
    name: ClassVar[str] = ""
    Config: ClassVar[type[ComponentConfig]] = ComponentConfig

    def __init__(self, config: ComponentConfig | None = None, **params: Any):
        if config is not None and params:
            raise TypeError("pass either a config object or keyword parameters, not both")
        self.config = config if config is not None else self.Config(**params)

    def describe(self) -> dict[str, Any]:
        """``{"name": ..., **params}``: what a run folder records for this component."""
        return {"name": self.name, **self.config.model_dump(mode="json")}

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.config!r})"


def output_error(component: Component, returned: str) -> RegistrationError:
    """The error for a component (a plugin) whose output does not fit: numpy's shape mismatch further on named none."""
    return RegistrationError(f"{component.kind} {component.name or type(component).__name__!r} returned {returned}",
                             source="pipeline")


_COMPONENTS: dict[str, dict[str, type[Component]]] = {kind: {} for kind in KINDS}
_BASES: dict[str, type[Component]] = {}
_PLUGINS_LOADED = False
#: installed component plugins that failed to load: (kind, name) -> reason
_BROKEN: dict[tuple[str, str], str] = {}


def component_base(kind: str) -> Callable[[type[Component]], type[Component]]:
    """Class decorator for the abstract base of one kind (plugins must subclass it)."""
    if kind not in KINDS:
        raise ConfigError(f"unknown component kind {kind!r}; kinds: {', '.join(KINDS)}", source="component_base")

    def decorator(cls: type[Component]) -> type[Component]:
        cls.kind = kind
        _BASES[kind] = cls
        return cls

    return decorator


def _check_kind(kind: str) -> None:
    if kind not in KINDS:
        raise ConfigError(f"unknown component kind {kind!r}; kinds: {', '.join(KINDS)}", source="component kind")


def register_component(kind: str, name: str) -> Callable[[type[Component]], type[Component]]:
    """Class decorator: register a component class of ``kind`` under ``name`` (sets ``cls.name``; the naming rule:
    :mod:`lidarkit.plugins`)."""
    _check_kind(kind)
    checked_name(name, "a component name", f"register_component({kind!r})")

    def decorator(cls: type[Component]) -> type[Component]:
        base = _BASES.get(kind, Component)
        if not (isinstance(cls, type) and issubclass(cls, base)):
            raise ConfigError(f"{cls!r} is not a {base.__name__} subclass", source=f"register_component({kind!r}, {name!r})")
        claim_name(_COMPONENTS[kind], name, cls, f"register_component({kind!r}, {name!r})")
        cls.name = name
        _COMPONENTS[kind][name] = cls
        return cls

    return decorator


def _load_plugins() -> None:
    """Import every ``lidarkit.components`` entry point once. A broken one is left out with a warning (the others and
    the built-in components stay usable); asking for it by name raises ConfigError with the reason (:data:`_BROKEN`)."""
    global _PLUGINS_LOADED
    if _PLUGINS_LOADED:
        return
    _PLUGINS_LOADED = True
    _BROKEN.clear()
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        kind, _, name = ep.name.partition(".")
        try:
            if kind not in KINDS or not name:
                raise ConfigError(f"entry point names must read KIND.NAME with KIND one of {', '.join(KINDS)}",
                                  source=f"component plugin {ep.name!r}")
            if name in _COMPONENTS[kind]:
                builtin = _COMPONENTS[kind][name].__module__.startswith("lidarkit.")
                if builtin and not ep.value.startswith("lidarkit."):  # (it was dropped without a word, nor listed as left out)
                    raise ConfigError(f"its name is a built-in {kind}'s: {ep.value!r} left out (rename the entry point)",
                                      source=f"component plugin {ep.name!r}")
                continue
            obj = ep.load()
            if name not in _COMPONENTS[kind]:
                register_component(kind, name)(obj)
        except Exception as err:  # a plugin may fail in any way while importing
            reason = err.reason if isinstance(err, ConfigError) else f"failed to load {ep.value!r}: {type(err).__name__}: {err}"
            _BROKEN[(kind, name)] = reason
            log.warning("component plugin %r left out: %s", ep.name, reason)
            continue
        log.info("loaded %s component %s from %s", kind, name, ep.value)


def broken_component_plugins() -> dict[str, str]:
    """The installed component plugins that failed to load, ``"KIND.NAME" -> reason``."""
    _load_plugins()
    return {f"{kind}.{name}": reason for (kind, name), reason in _BROKEN.items()}


def reload_component_plugins() -> None:
    """Forget which entry points were loaded and scan the group again (after installing a plugin)."""
    global _PLUGINS_LOADED
    _PLUGINS_LOADED = False
    _load_plugins()


def available_components(kind: str | None = None) -> dict[str, list[str]] | list[str]:
    """Sorted names of the registered components of ``kind`` (plugins included); all kinds if None."""
    _load_plugins()
    if kind is None:
        return {k: sorted(_COMPONENTS[k]) for k in KINDS}
    _check_kind(kind)
    return sorted(_COMPONENTS[kind])


def get_component_class(kind: str, name: str) -> type[Component]:
    """The class registered as ``name`` for ``kind``; unknown names raise ConfigError listing the valid ones."""
    _check_kind(kind)
    if name not in _COMPONENTS[kind]:
        _load_plugins()
    if (kind, name) in _BROKEN and name not in _COMPONENTS[kind]:  # (a plugin named like a built-in: the built-in answers)
        raise ConfigError(f"this plugin is installed but could not be loaded: {_BROKEN[(kind, name)]}",
                          source=f"component plugin {kind}.{name}")
    if name not in _COMPONENTS[kind]:
        raise ConfigError(f"unknown {kind} component {name!r}; available: {', '.join(available_components(kind))}", source=kind)
    return _COMPONENTS[kind][name]


def component_fields(kind: str, name: str) -> dict[str, tuple[str, Any, str]]:
    """``{param: (type, default, description)}`` of a component's config."""
    from lidarkit.registration.registry import _type_name

    cls = get_component_class(kind, name)
    return {
        key: (_type_name(info.annotation), info.get_default(call_default_factory=True), info.description or "")
        for key, info in cls.Config.model_fields.items()
    }


ComponentSpec = str | Mapping[str, Any]


def glued_yaml_hint(params: Mapping[Any, Any]) -> str:
    """`` (YAML needs a space after ':': {scale_m: 0.3})`` for the keys of ``params`` that YAML read from ``key:value``
    written without the space (``{scale_m:0.3}`` is the key ``"scale_m:0.3"`` with no value), else ``""``: the reason
    an "Extra inputs are not permitted" alone did not give."""
    glued = [k for k, v in params.items() if v is None and isinstance(k, str) and ":" in k]
    return f" (YAML needs a space after ':': {{{', '.join(k.replace(':', ': ', 1) for k in glued)}}})" if glued else ""


def split_spec(kind: str, spec: ComponentSpec) -> tuple[str, dict[str, Any]]:
    """``"huber"`` or ``{"name": "huber", "scale_m": 0.5}`` -> ``("huber", {"scale_m": 0.5})``."""
    if isinstance(spec, str):
        return spec, {}
    if isinstance(spec, Mapping):
        params = dict(spec)
        name = params.pop("name", None)
        if not isinstance(name, str):
            raise ConfigError(f"a {kind} given as a mapping needs a 'name' key (one of: {', '.join(available_components(kind))})"
                              f"{glued_yaml_hint(params)}", source=kind)
        return name, params
    raise ConfigError(f"expected a component name or a mapping with 'name', got {type(spec).__name__}", source=kind)


def make_component(kind: str, spec: ComponentSpec, **defaults: Any) -> Component:
    """An instance of the component ``spec`` names; ``defaults`` fill params the spec does not set (and the
    component's config knows). Unknown or invalid params raise ConfigError listing the valid ones."""
    name, params = split_spec(kind, spec)
    cls = get_component_class(kind, name)
    known = cls.Config.model_fields
    merged = {k: v for k, v in defaults.items() if k in known and v is not None}
    merged.update(params)
    valid = ", ".join(f"{k}={shown_default(v[1])}" for k, v in component_fields(kind, name).items()) or "(none)"
    try:
        config = cls.Config(**merged)
    except pydantic.ValidationError as err:
        raise ConfigError(f"invalid parameters ({validation_problems(err, unnamed='')}){glued_yaml_hint(params)}; valid parameters: "
                          f"{valid}", source=f"{kind} component {name!r}") from None
    except ValueError as err:
        raise ConfigError(f"invalid parameters ({err}){glued_yaml_hint(params)}; valid parameters: {valid}",
                          source=f"{kind} component {name!r}") from None
    return cls(config=config)


__all__ = [
    "ENTRY_POINT_GROUP",
    "KINDS",
    "Component",
    "ComponentConfig",
    "ComponentSpec",
    "available_components",
    "component_base",
    "component_fields",
    "get_component_class",
    "glued_yaml_hint",
    "make_component",
    "output_error",
    "register_component",
    "reload_component_plugins",
    "split_spec",
]
