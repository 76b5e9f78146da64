"""The typer application every command module attaches to."""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Iterator, Mapping

import typer
from rich.console import Console


app = typer.Typer(
    name="lidarkit",
    help="LiDAR registration, particle-filter localization and monocular VO, scored by one evaluation layer.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_show_locals=False,
)


@contextlib.contextmanager
def named_by_option(options: Mapping[str, str]) -> Iterator[None]:
    """A library ConfigError whose source is a setting (``init``, ``delta``) re-raised naming the option that sets it
    (``--init``, ``--delta``); any other error as it is."""
    from lidarkit.errors import ConfigError

    try:
        yield
    except ConfigError as err:
        option = options.get(err.source or "")
        if option is None:
            raise
        raise ConfigError(err.reason, source=option, location=err.location) from None


def parse_params(items: list[str], option: str = "--param") -> dict:
    """``["k=v", ...]`` from a repeatable ``option`` -> dict (see :func:`lidarkit.params.parse_kv`)."""
    from lidarkit.params import parse_kv

    return parse_kv(items, option=option)


def stdout() -> Console:
    """Console for results (created per call so test capture works).

    Markup is off: file names, method labels and messages are user strings (``scan[v2].bin``, ``[/red]``) and must
    print as they are; styling goes through ``rich.text.Text`` or an explicit ``markup=True`` with ``escape``.
    """
    return Console(file=NamedStdout(), highlight=False, markup=False)


class NamedStdout:
    """A stdout whose refused writes are one OutputError naming stdout (`lidarkit version > /dev/full` ended in a
    70-line traceback; typer's help pages in a 133-line one): over ``stream``, or over ``sys.stdout`` as it is at each
    write (``None``, what :func:`stdout` consoles write to). A broken pipe (`| head -1`) is left to rich: a quiet
    exit."""

    def __init__(self, stream=None):
        self._fixed = stream

    @property
    def _stream(self):
        return sys.stdout if self._fixed is None else self._fixed

    def write(self, text: str) -> int:
        with _stdout_errors():
            return self._stream.write(text)

    def writelines(self, lines) -> None:
        with _stdout_errors():
            self._stream.writelines(lines)

    def flush(self) -> None:
        with _stdout_errors():
            self._stream.flush()

    def __getattr__(self, name: str):
        return getattr(self._stream, name)


@contextlib.contextmanager
def _stdout_errors():
    from lidarkit.atomic import error_for

    try:
        yield
    except BrokenPipeError:
        raise
    except OSError as err:
        with contextlib.suppress(OSError, ValueError):  # what stays buffered is dropped, not flushed again at exit
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        raise error_for("stdout", err) from err


def stderr() -> Console:
    """Console for errors and progress (markup off, like :func:`stdout`)."""
    return Console(stderr=True, highlight=False, markup=False)


def print_error(err: BaseException) -> None:
    """The one line the CLI prints for a LidarKitError (the message verbatim, never read as markup)."""
    from rich.text import Text

    line = Text("error:", style="bold red")
    line.append(" " + " ".join(str(err).split()))  # one line, whatever a wrapped library put in its message
    stderr().print(line, soft_wrap=True)


def _print_version(value: bool) -> None:
    if value:
        from lidarkit import __version__

        stdout().print(__version__)
        raise typer.Exit()


@app.callback()
def _root(
    verbose: bool = typer.Option(False, "--verbose", "-v", help="Log diagnostics (INFO level)."),
    show_version: bool = typer.Option(False, "--version", callback=_print_version, is_eager=True, help="Print the lidarkit version and exit."),
) -> None:
    """LiDAR registration, particle-filter localization and monocular VO, scored by one evaluation layer."""
    import logging

    if verbose:
        logging.getLogger("lidarkit").setLevel(logging.INFO)


@app.command()
def version() -> None:
    """Print the lidarkit version."""
    from lidarkit import __version__

    stdout().print(__version__)
