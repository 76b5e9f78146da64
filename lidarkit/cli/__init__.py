"""Command-line interface: ``lidarkit COMMAND ...``. Commands only parse, call the library and print."""

from __future__ import annotations

import contextlib
import logging
import os
import sys
from collections.abc import Iterator

from lidarkit import lifetime

# the console script or `python -m lidarkit.cli`; not a pool worker, which imports this module again as its parent's
# main before it starts (its parent ends it with SIGTERM when the pool closes: each worker still starting then printed
# "interrupted by SIGTERM while starting" under the parent's own line)
if os.path.basename(sys.argv[0]) in ("lidarkit", "-m") and "multiprocessing.spawn" not in sys.modules:
    lifetime.install_startup_handlers()

from lidarkit.lifetime import Interrupted, abandoned, handle_signals, interrupt_handled, swallowed_interrupt  # noqa: E402
from lidarkit.cli.app import NamedStdout, app, print_error, stderr  # noqa: E402
from lidarkit.errors import LidarKitError  # noqa: E402

# Each module registers its commands on ``app`` when imported; listed here explicitly.
from lidarkit.cli import eval_cmd  # noqa: E402,F401
from lidarkit.cli import pf_cmd  # noqa: E402,F401
from lidarkit.cli import vo_cmd  # noqa: E402,F401
from lidarkit.cli import demo_cmd  # noqa: E402,F401
from lidarkit.cli import odometry_cmd  # noqa: E402,F401
from lidarkit.cli import sim_cmd  # noqa: E402,F401
from lidarkit.cli import bench_cmd  # noqa: E402,F401
from lidarkit.cli import icp_cmd  # noqa: E402,F401
from lidarkit.cli import compare_cmd  # noqa: E402,F401
from lidarkit.cli import baseline_cmd  # noqa: E402,F401

__all__ = ["app", "main", "run_script"]


def _interrupt_behind(err: BaseException) -> Interrupted | None:
    """The Interrupted that caused ``err`` (its ``__cause__`` / ``__context__`` chain), or None."""
    seen = set()
    while err is not None and id(err) not in seen:
        if isinstance(err, Interrupted):
            return err
        seen.add(id(err))
        err = err.__cause__ or err.__context__
    return None


#: (it said "give a path or a value" for --name too, which takes a title: a wording for every option and argument)
_EMPTY_VALUE = "empty value (an unset shell variable?): give a non-empty value"


def _refuse_empty_arguments(argv: list[str]) -> None:
    """ConfigError for an empty argument: typer reads ``-o ""`` (an unset shell variable) as the current folder, and a
    run was written there; no lidarkit option or argument takes an empty value."""
    from lidarkit.errors import ConfigError

    for i, arg in enumerate(argv):
        if arg == "":
            option = argv[i - 1] if i > 0 and argv[i - 1].startswith("-") else None
            where = option or f"argument {i + 1}" + (f" (after {argv[i - 1]})" if i > 0 else "")
            raise ConfigError(_EMPTY_VALUE, source=where)
        if arg.startswith("--") and arg.endswith("=") and arg.count("=") == 1:
            raise ConfigError(_EMPTY_VALUE, source=arg[:-1])


@contextlib.contextmanager
def _stdout_refusals_named() -> Iterator[None]:
    """Within the block ``sys.stdout`` is a :class:`~lidarkit.cli.app.NamedStdout` over the stream it was (restored
    after): typer prints its help pages itself."""
    stream = sys.stdout
    if stream is None or isinstance(stream, NamedStdout):
        yield
        return
    sys.stdout = NamedStdout(stream)
    try:
        yield
    finally:
        if isinstance(sys.stdout, NamedStdout):  # (not if the command set its own meanwhile)
            sys.stdout = stream


def _run_app(argv: list[str] | None) -> int:
    """Run the command; its exit code. The framework's usage errors (an unknown option, a missing argument) are one
    line naming the command and its help, exit code 2, as lidarkit's own errors are one line (they printed a
    five-line box); help pages, asked for or shown for a bare command group, stay the framework's."""
    import typer

    try:
        from typer._click import exceptions as usage  # the copy of click that typer carries (recent typer)
    except ImportError:  # pragma: no cover - typer built on click itself
        from click import exceptions as usage

    try:
        code = app(args=argv, prog_name="lidarkit", standalone_mode=False)
    except usage.NoArgsIsHelpError:  # `lidarkit sim`: the help page is printed
        return 2
    except typer.Abort:
        stderr().print("aborted", soft_wrap=True)
        return 1
    except usage.ClickException as err:
        args = sys.argv[1:] if argv is None else list(argv)
        ctx = getattr(err, "ctx", None)
        command = ctx.command_path if ctx is not None else " ".join(["lidarkit", *args[:1]]) if args and not args[0].startswith("-") else "lidarkit"
        print_error(LidarKitError(f"{err.format_message().rstrip('.')} (see {command} --help)", source=command))
        return err.exit_code
    return code if isinstance(code, int) else 0  # (a command's typer.Exit(code); commands return nothing)


def _exhausted(err: BaseException) -> str | None:
    """The one line for a library that could not be loaded, or a thread that could not start, for want of memory or
    threads (under `ulimit -v 600000` matplotlib's import failed with "libtiff...: failed to map segment from shared
    object" in a 40-line traceback, and a pool's thread with "can't start new thread"); None for anything else."""
    text = str(err)
    if isinstance(err, ImportError) and ("failed to map segment" in text or "cannot allocate memory" in text.lower()):
        return f"out of memory loading a library ({text}): free memory or raise the limit (ulimit -v)"
    if isinstance(err, RuntimeError) and text == "can't start new thread":
        return "cannot start a thread: out of memory, or at the limit of threads (ulimit -v, ulimit -u)"
    return None


def _command_path(args: list[str]) -> str:
    """``lidarkit`` and the (sub)command names that lead ``args`` ("lidarkit pf"), for an error that names the command;
    the first word alone when the command tree cannot be built (out of memory: the MemoryError's own line was a
    second traceback)."""
    import typer

    try:
        command = typer.main.get_command(app)
    except MemoryError:
        return " ".join(["lidarkit", *args[:1]]) if args and not args[0].startswith("-") else "lidarkit"
    path = ["lidarkit"]
    for arg in args:
        sub = (getattr(command, "commands", None) or {}).get(arg)
        if sub is None:
            break
        path.append(arg)
        command = sub
    return " ".join(path)


def main(argv: list[str] | None = None) -> None:
    """Entry point of the ``lidarkit`` console script.

    A LidarKitError or a MemoryError becomes one line and exit code 1; SIGINT / SIGTERM stop the command through its cleanup
    (temporary files and run folders removed, worker processes stopped) with one line and exit code 130 / 143.
    """
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    code, interrupted = 0, False
    try:
        try:
            with handle_signals(), _stdout_refusals_named():
                _refuse_empty_arguments(sys.argv[1:] if argv is None else list(argv))
                code = _run_app(argv)
        except Exception as err:  # an interrupt that a library turned into its own error (open3d's import: ImportError)
            raise _interrupt_behind(err) or err
    except LidarKitError as err:
        print_error(err)
        code = 1
    except MemoryError as err:  # (a 9,000,000-particle run under `ulimit -v` printed a 60-line traceback)
        command = _command_path(sys.argv[1:] if argv is None else list(argv))
        print_error(LidarKitError(f"out of memory: {str(err) or 'an allocation failed'} (ask for less, or free memory)",
                                  source=command))
        code = 1
    except (ImportError, RuntimeError) as err:
        reason = _exhausted(err)
        if reason is None:  # a defect: shown with its traceback
            raise
        print_error(LidarKitError(reason, source=_command_path(sys.argv[1:] if argv is None else list(argv))))
        code = 1
    except OSError as err:
        if err.filename is None:  # not about a path the user gave: a defect, shown with its traceback
            raise
        # a path the system refused where no check of lidarkit's came first (a name too long for the disk, a loop of
        # links): one line, as for the errors lidarkit raises itself
        print_error(LidarKitError((err.strerror or type(err).__name__).lower(), source=err.filename))
        code = 1
    except Interrupted as err:
        interrupt_handled()
        stderr().print(f"interrupted by {err}: stopped; no file is left half-written (each is complete or absent)",
                       soft_wrap=True)
        code, interrupted = err.exit_code, True
    except SystemExit as exc:
        swallowed = swallowed_interrupt()
        if swallowed is not None:  # caught by a library as it loaded: the command went on to its end
            interrupt_handled()
            stderr().print(f"interrupted by {swallowed}, which a library caught as it loaded: the command ran to its end "
                           "(every file it wrote is complete)", soft_wrap=True)
            code = swallowed.exit_code
        elif not abandoned():
            raise
        else:
            code = exc.code if isinstance(exc.code, int) else 1
    # a pool thread stuck on a result its killed worker never finished sending; or an interrupt that left a library's
    # buffers allocated: Open3D's memory statistics, a static object's destructor, then print them on stdout and end
    # the process with exit code 1 (a Ctrl-C inside a sim's ray cast: 1 instead of 130, 3 tries in 23). The cleanup is
    # done: the console script ends here, without the interpreter's shutdown (a caller's own process, main(argv), goes on)
    if abandoned() or (interrupted and argv is None):
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    sys.exit(code)  # (also 0: the framework's standalone run ended with SystemExit, which callers of main(argv) expect)


def run_script(script_main) -> None:
    """Run a script's ``main()`` (the benchmarks') as the CLI runs a command: a LidarKitError is one line on stderr and
    exit code 1 (a missing data folder printed a traceback ending in that line); ``main``'s return value is the exit
    code."""
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    try:
        code = script_main()
    except LidarKitError as err:
        print_error(err)
        code = 1
    sys.exit(code)

