"""Process lifetime: worker processes die with the process that started them; SIGINT / SIGTERM / SIGHUP end the CLI
cleanly.

Only the standard library is imported here: the CLI installs :func:`install_startup_handlers` before its heavy
imports, and the fork server preloads this module.

- :func:`init_worker` runs first in every pool worker: it ignores SIGINT and SIGHUP (Ctrl-C and a closed terminal
  reach the whole process group; only the parent decides what to do), asks Linux to SIGKILL the worker when its parent
  dies (``PR_SET_PDEATHSIG``) and starts a watchdog thread that ends the worker once the lidarkit process that owns the
  pool is gone (the parent of a forkserver worker is the fork server, not lidarkit; and not every OS has prctl),
  killed-but-unreaped (a zombie) included.
- :class:`Interrupted` is what SIGINT / SIGTERM / SIGHUP become in the CLI (:func:`handle_signals`): a
  ``BaseException`` (so ``except Exception`` in job code does not swallow it) carrying the exit code 128 + signal
  number.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import select
import signal
import sys
import threading
import time
from collections.abc import Iterator

WATCHDOG_PERIOD_S = 0.5
#: the signals that stop a command through its cleanup: Ctrl-C, a kill, a hang-up (the terminal closed, SSH dropped:
#: the process had died at once, exit 129, its pool's semaphores reported leaked and nothing said)
STOP_SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name))
#: the stop signals that reach a whole process group (Ctrl-C, a hang-up): children ignore them, the parent decides
_GROUP_SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGHUP") if hasattr(signal, name))


class Interrupted(BaseException):
    """SIGINT, SIGTERM or SIGHUP received; ``exit_code`` is 130, 143 or 129."""

    def __init__(self, signum: int):
        self.signum = signum
        self.exit_code = 128 + signum
        super().__init__(signal.Signals(signum).name)


#: Signals :func:`_raise_interrupted` turned into :class:`Interrupted` in this command (cleared when one is handled).
_received: list[int] = []


def _raise_interrupted(signum: int, _frame) -> None:
    for s in STOP_SIGNALS:  # the cleanup that follows must not be interrupted in turn
        signal.signal(s, signal.SIG_IGN)
    _received.append(signum)
    raise Interrupted(signum)


def swallowed_interrupt() -> Interrupted | None:
    """The interrupt raised in this command that never reached its handler, or None. A library whose import code
    catches everything (a bare ``except:``) can swallow it while it loads; the signals then stayed ignored (for a
    cleanup that never came) and the run went on to its end, unstoppable, exiting 0 or 1 without a word."""
    return Interrupted(_received[0]) if _received else None


def raise_if_interrupted() -> None:
    """At a point where stopping is safe (between jobs, between frames): raise an interrupt a library swallowed."""
    if _received:
        raise Interrupted(_received[0])


def interrupt_handled() -> None:
    """The command's handler has dealt with the interrupt (the next command in this process starts afresh)."""
    _received.clear()


def _exit_at_startup(signum: int, _frame) -> None:
    os.write(2, f"interrupted by {signal.Signals(signum).name} while starting: nothing was written\n".encode())
    os._exit(128 + signum)


def install_startup_handlers() -> None:
    """SIGINT / SIGTERM / SIGHUP before the command runs (while modules load): one line, exit 130 / 143 / 129, no
    traceback.

    An ignored SIGINT or SIGHUP stays ignored: it is a child process started to leave Ctrl-C to its parent (a Dask
    worker re-imports this module as its ``__main__``; it exited on the Ctrl-C its cluster's start was to ride out), or
    a command started with ``nohup`` to outlive its terminal."""
    if threading.current_thread() is threading.main_thread():
        for s in STOP_SIGNALS:
            if s in _GROUP_SIGNALS and signal.getsignal(s) is signal.SIG_IGN:
                continue
            signal.signal(s, _exit_at_startup)


def _quiet_bootstrap_hook(exc_type, exc, tb) -> None:
    """Fork-server children: a worker that cannot start because its pool is already shut down (its semaphore or
    pipe gone) exits quietly instead of printing a traceback over the parent's last line."""
    if issubclass(exc_type, (OSError, EOFError)):
        return
    sys.__excepthook__(exc_type, exc, tb)


def setup_fork_server() -> None:
    """Run in the fork server (preloaded, before it saves the handlers its children get): children ignore SIGINT and
    SIGHUP from birth (Ctrl-C and a hang-up reach the whole process group; the parent decides) and get the quiet
    bootstrap hook. The server dies with the lidarkit process that started it (it also ends once that process and
    every worker are gone: they hold its "alive" pipe)."""
    for s in _GROUP_SIGNALS:
        signal.signal(s, signal.SIG_IGN)
    sys.excepthook = _quiet_bootstrap_hook
    if _started_by_main_thread():
        _set_parent_death_signal()


def _started_by_main_thread() -> bool:
    """Whether the parent's main thread started this process. ``PR_SET_PDEATHSIG`` fires when the parent *thread*
    ends: a fork server started from a thread that then ended would die under the pools still using it."""
    parent = os.getppid()
    try:
        with open(f"/proc/{parent}/task/{parent}/children") as children:
            return str(os.getpid()) in children.read().split()
    except OSError:
        return False


@contextlib.contextmanager
def handle_signals() -> Iterator[None]:
    """Within the block SIGINT, SIGTERM and SIGHUP raise :class:`Interrupted` (main thread only); handlers restored
    after. A signal the process was started ignoring stays ignored, as at startup: a job started in the background
    (``cmd &`` in a script), which a Ctrl-C at the terminal is to leave alone, was stopped by one arriving after its
    first seconds (``nohup cmd``: a hang-up)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {s: signal.getsignal(s) for s in STOP_SIGNALS}
    _received.clear()
    for s, handler in previous.items():
        if handler is not signal.SIG_IGN:
            signal.signal(s, _raise_interrupted)
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler if handler is not None else signal.SIG_DFL)


def _set_parent_death_signal() -> None:
    if not sys.platform.startswith("linux"):
        return
    with contextlib.suppress(OSError, AttributeError):
        libc = ctypes.CDLL(None, use_errno=True)
        PR_SET_PDEATHSIG = 1
        libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL)


def _process_state(pid: int) -> str | None:
    """The state letter of ``/proc/<pid>/stat`` (``R``, ``S``, ``Z``...), or None where it cannot be read."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as stat:
            return stat.read().rpartition(b")")[2].split()[0].decode()
    except (OSError, IndexError, UnicodeDecodeError):
        return None


def _alive(pid: int) -> bool:
    """Whether ``pid`` still runs. A zombie is gone: a killed owner stays one until its parent reaps it, and a parent
    using subprocess's ``communicate()`` reaps only after EOF on the pipes this worker holds (``os.kill(pid, 0)``
    succeeds on a zombie: the worker and that parent waited on each other for ever)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, owned by someone else (pid reused): treat as gone
        return False
    return _process_state(pid) not in ("Z", "X")


def _exit_notice(pid: int) -> int | None:
    """A descriptor that becomes readable the moment ``pid`` exits, zombie or not (a pidfd, Linux >= 5.3), or None."""
    try:
        return os.pidfd_open(pid)
    except (AttributeError, OSError):
        return None


def _watch(owner_pid: int, owner_exit: int | None) -> None:
    poller = None
    if owner_exit is not None:
        poller = select.poll()
        poller.register(owner_exit, select.POLLIN)
    while True:
        if poller is not None:
            owner_gone = bool(poller.poll(WATCHDOG_PERIOD_S * 1000))
        else:
            time.sleep(WATCHDOG_PERIOD_S)
            owner_gone = not _alive(owner_pid)
        if owner_gone or os.getppid() == 1:
            os._exit(1)  # the owner is gone: nobody will read this worker's result


def init_worker(owner_pid: int) -> None:
    """Pool-worker initializer (see the module docstring)."""
    for s in _GROUP_SIGNALS:
        signal.signal(s, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    _set_parent_death_signal()
    owner_exit = _exit_notice(owner_pid)  # before the check below: an owner dying in between is noticed all the same
    if not _alive(owner_pid):
        os._exit(1)
    threading.Thread(target=_watch, args=(owner_pid, owner_exit), name="lidarkit-owner-watchdog", daemon=True).start()


@contextlib.contextmanager
def children_shielded() -> Iterator[None]:
    """Start child processes in the block shielded from what reaches the whole process group (Ctrl-C, a closed terminal:
    the parent decides): SIGINT ignored, SIGINT and SIGHUP blocked, which they keep through exec. A Ctrl-C within the
    block itself is lost (an ignored signal is discarded, blocked or not): a pool starts in well under a second, a local
    Dask cluster in a few; once the block has ended, Ctrl-C stops the run as usual. SIGHUP keeps this process's handler
    (another of its threads takes it, so it is not lost): unshielded, a hang-up killed the Dask workers and Python's
    resource tracker under the parent's cleanup (a dozen tracebacks)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    can_block = hasattr(signal, "pthread_sigmask")
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, set(_GROUP_SIGNALS)) if can_block else None
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous if previous is not None else signal.SIG_DFL)
        if can_block:
            signal.pthread_sigmask(signal.SIG_SETMASK, mask)


_abandoned = threading.Event()


def mark_abandoned() -> None:
    """A pool could not be joined cleanly (a worker killed while sending its result leaves the pool's reader
    thread blocked): the CLI then ends the process with ``os._exit`` after its cleanup instead of hanging."""
    _abandoned.set()


def abandoned() -> bool:
    return _abandoned.is_set()
