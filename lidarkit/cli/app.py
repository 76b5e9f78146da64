"""The typer application every command module attaches to."""

from __future__ import annotations

import typer
from rich.console import Console

from lidarkit.errors import ConfigError

app = typer.Typer(
    name="lidarkit",
    help="LiDAR registration, particle-filter localization and monocular VO, scored by one evaluation layer.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_show_locals=False,
)


def parse_params(items: list[str], option: str = "--param") -> dict:
    """``["k=v", ...]`` from a repeatable ``option`` -> dict; values are read as YAML scalars (numbers, booleans, null, strings)."""
    import yaml

    params: dict = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise ConfigError("expected KEY=VALUE", source=f"{option} {item!r}")
        try:
            params[key.strip()] = yaml.safe_load(value) if value.strip() else None
        except yaml.YAMLError:
            params[key.strip()] = value
    return params


def stdout() -> Console:
    """Console for results (created per call so test capture works)."""
    return Console(highlight=False)


def stderr() -> Console:
    """Console for errors and progress."""
    return Console(stderr=True, highlight=False)


@app.callback()
def _root(verbose: bool = typer.Option(False, "--verbose", "-v", help="Log diagnostics (INFO level).")) -> None:
    """LiDAR registration, particle-filter localization and monocular VO, scored by one evaluation layer."""
    import logging

    if verbose:
        logging.getLogger("lidarkit").setLevel(logging.INFO)


@app.command()
def version() -> None:
    """Print the lidarkit version."""
    from lidarkit import __version__

    stdout().print(__version__)
