"""One ``KEY=VALUE`` parser for every place users pass options as text.

Used by the CLI's repeatable ``--param`` / ``--set`` options (:func:`lidarkit.cli.app.parse_params`),
dataset specs ``KIND:PATH?key=value&...`` (:func:`lidarkit.odometry.open_sequence`) and simulator specs
``sim:SCENE?key=value&...`` (:func:`lidarkit.sim.lidar.open_sim`).

Values are read as YAML scalars (``1`` -> int, ``0.5`` -> float, ``true``/``false`` -> bool,
``null`` or empty -> None, anything else a string), except text YAML 1.1 would mangle: numbers with a
leading zero or underscores (``05``, ``2011_09_26``) and dates stay strings. A spec's empty value (``?time_field=``)
is refused: read as None, it silently meant "auto", "no per-point times" or the default file. So is a value in braces
or brackets YAML cannot read (``kernel={name: huber``): kept as text, it failed later as an unknown name or "not a
valid dictionary".
"""

from __future__ import annotations

import datetime as _dt
import re
from collections.abc import Iterable
from typing import Any
from urllib.parse import unquote

from lidarkit.errors import ConfigError

_KEEP_AS_TEXT = re.compile(r"^[-+]?(0\d|\d*_)")
_EXPONENT_FLOAT = re.compile(r"^[-+]?(\d+\.?\d*|\.\d+)[eE][-+]?\d+$")  # 1e-3: a string to YAML 1.1


def shown_default(value: Any) -> str:
    """A parameter's value as it is typed back into ``-p KEY=VALUE`` (None as ``null``: "None", copied from a listing,
    was refused as "not a valid number")."""
    return "null" if value is None else repr(value)


def parse_value(text: str) -> Any:
    """One value: a YAML scalar, or the text itself when YAML would change its meaning or fails."""
    import yaml

    stripped = text.strip()
    if not stripped:
        return None
    if _KEEP_AS_TEXT.match(stripped):
        return stripped
    if _EXPONENT_FLOAT.match(stripped):
        return float(stripped)
    try:
        value = yaml.safe_load(stripped)
    except yaml.YAMLError:
        return stripped
    if isinstance(value, (_dt.date, _dt.datetime)):
        return stripped
    return value


def parse_kv(items: Iterable[str] | str, option: str = "option", as_text: Iterable[str] = ()) -> dict[str, Any]:
    """``["k=v", ...]`` or a query string ``"k=v&k2=v2"`` (URL-encoded) -> ``{key: value}``; keys in ``as_text`` keep
    their value as written (a path: ``1.50`` or ``1e3`` are file names there, not numbers).

    A missing ``=``, an empty key, a key given twice or (in a query string) an empty value raises ConfigError naming
    ``option`` and the item; a ``{...}`` / ``[...]`` value YAML cannot read, one naming the key and YAML's reason.
    """
    as_text = set(as_text)
    if isinstance(items, str):
        pairs = []
        for part in items.split("&"):
            if part:
                key, sep, value = part.partition("=")
                pairs.append((unquote(key), sep, unquote(value), part))
    else:
        pairs = [(*str(item).partition("="), str(item)) for item in items]
    out: dict[str, Any] = {}
    for key, sep, value, raw in pairs:
        key = key.strip()
        if not sep or not key:
            raise ConfigError("expected KEY=VALUE", source=f"{option} {raw!r}")
        if key in out:
            raise ConfigError(f"{key!r} is given twice", source=f"{option} {raw!r}")
        if isinstance(items, str) and not value.strip():  # (an unset shell variable in a spec)
            raise ConfigError(f"{key}= has no value; give one, or leave {key} out for its default", source=option)
        if value.strip().startswith(("{", "[")) and (problem := _yaml_problem(value.strip())):
            raise ConfigError(f"{value.strip()!r} is not valid YAML ({problem})", source=f"{option} {key}")
        parsed = parse_value(value)
        numeric = isinstance(parsed, (int, float)) and not isinstance(parsed, bool)
        out[key] = value.strip() if key in as_text and numeric else parsed
    return out


def _yaml_problem(text: str) -> str:
    """Why YAML cannot read ``text``, in one line ("flow mapping not closed"); "" when it can."""
    import yaml

    try:
        yaml.safe_load(text)
    except yaml.YAMLError as err:
        problem = (getattr(err, "problem", None) or str(err).splitlines()[0]).replace("'<stream end>'", "the end")
        context = (getattr(err, "context", None) or "").removeprefix("while parsing a ")
        mark = getattr(err, "problem_mark", None)
        at = f" at character {mark.column + 1}" if mark is not None else ""
        if problem.endswith("the end") and context in ("flow mapping", "flow sequence"):
            return f"{context} not closed"
        if problem.startswith("expected '<document start>'"):  # (YAML's words for text after a complete value)
            return f"text after the closing bracket{at}"
        return f"{context + ': ' if context else ''}{problem}{at}"
    return ""


def number_field(annotation: Any) -> bool:
    """Whether a config field annotated ``annotation`` holds an int or a float (``float | None`` too; ``bool`` not):
    such a field refuses a yes/no value, which YAML reads from ``true``/``yes``/``on`` and pydantic's lax mode would
    take as 1 or 0 without a word."""
    import typing

    return annotation in (int, float) or any(number_field(a) for a in typing.get_args(annotation) if a is not bool)


def refuse_yes_no_numbers(model: Any, data: Any) -> Any:
    """``data`` as given, unless a number field of the pydantic ``model`` holds a yes/no value (``True``, or ``yes`` in
    YAML), which pydantic's lax mode reads as 1 or 0 without a word (1 iteration ran; ``sensor_height_m: yes`` ran with
    1 m): then ValueError naming it. The before-validator of every lidarkit config that takes numbers."""
    import numpy as np

    if isinstance(data, dict):
        named = [f"{k} ({v})" for k, v in data.items() if isinstance(v, (bool, np.bool_)) and k in model.model_fields
                 and number_field(model.model_fields[k].annotation)]
        if named:
            raise ValueError(f"{', '.join(named)}: takes a number, not a yes/no value")
    return data


def is_real_number(value: Any) -> bool:
    """A real number given as one (Python's or numpy's int or float), not a bool nor text: a setting of text compared as
    a number raised a TypeError, and True read as 1."""
    import numpy as np

    return not isinstance(value, bool) and isinstance(value, (int, float, np.integer, np.floating))


def is_integer(value: Any) -> bool:
    """An integer given as one (Python's or numpy's), not a bool, a float nor text: 1.5 read as step 1, True as 1."""
    import numpy as np

    return not isinstance(value, bool) and isinstance(value, (int, np.integer))


def changed_fields(config: Any, names: Any) -> list[str]:
    """The fields among ``names`` (sorted) of a pydantic ``config`` given with a value other than their default: what a
    check of settings the configuration does not read may refuse. A value equal to the default changes nothing, and a
    full dump of a config (the config.json ``lidarkit icp --out`` writes, a simulator's sim.yaml) gives every field, so
    it must load again."""
    fields = type(config).model_fields
    return sorted(n for n in names if n in config.model_fields_set
                  and getattr(config, n) != fields[n].get_default(call_default_factory=True))


__all__ = ["changed_fields", "is_integer", "is_real_number", "number_field", "parse_kv", "parse_value"]
