"""The typer application every command module attaches to."""

from __future__ import annotations

import contextlib
import functools
import os
import sys
from collections.abc import Iterator, Mapping

import typer
import typer.core
from rich.columns import Columns
from rich.console import Console
from rich.measure import Measurement
from rich.table import Table
from rich.text import Text


app = typer.Typer(
    name="lidarkit",
    help="LiDAR registration, particle-filter localization and monocular VO, scored by one evaluation layer.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_show_locals=False,
)


class _HelpTable(Table):
    """typer's options table, whose cells fold a word too long for their column onto the next line: rich's default ends
    it with an ellipsis, and at 80 columns the wide ``--x/--no-x`` pairs of odometry and vo left the help column too
    narrow for ``pose_covariance.txt`` and cut ``--no-pose-covariance`` itself. The option names and types keep their
    width while the help column has :attr:`HELP_MIN_WIDTH` beside them; on a narrower terminal they fold too."""

    #: Narrowest help column (characters) beside option names kept whole (odometry's and vo's at 80 columns: 16).
    HELP_MIN_WIDTH = 16

    def add_row(self, *renderables, **kwargs) -> None:
        while len(self.columns) < len(renderables):
            self.add_column(overflow="fold")
        super().add_row(*renderables, **kwargs)

    def __rich_console__(self, console, options):
        names = self.columns[:-1]  # (the last: the help)
        widest = [max((Measurement.get(console, options, cell).maximum for cell in column.cells), default=0)
                  for column in names]
        padding = (len(self.columns) - 1) * (self.padding[1] + self.padding[3])  # (none outside the outer columns)
        keep_whole = options.max_width - sum(widest) - padding >= self.HELP_MIN_WIDTH
        for column in names:
            column.no_wrap = keep_whole
        yield from super().__rich_console__(console, options)


class _HelpColumns(Columns):
    """The help cell (text, default, "required"): its texts fold too; the cell lays them out in a grid of its own."""

    def __init__(self, renderables=None, *args, **kwargs) -> None:
        renderables = list(renderables or [])
        for item in renderables:
            if isinstance(item, Text) and item.overflow is None:
                item.overflow = "fold"
        super().__init__(renderables, *args, **kwargs)


def _folding_help(format_help):
    """``format_help`` of typer's commands and groups, drawing the help page with :class:`_HelpTable` and
    :class:`_HelpColumns` (typer has no setting for it; its help module is imported on the first help page only)."""

    @functools.wraps(format_help)
    def format_help_folding(self, ctx, formatter):
        from typer import rich_utils

        rich_utils.Table, rich_utils.Columns = _HelpTable, _HelpColumns
        return format_help(self, ctx, formatter)

    return format_help_folding


for _command_class in (typer.core.TyperCommand, typer.core.TyperGroup):
    _command_class.format_help = _folding_help(_command_class.format_help)


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
