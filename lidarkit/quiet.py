"""Silencing what compiled libraries print straight to a file descriptor (their C/C++ writes bypass ``sys.stdout``)."""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
import threading
from typing import Iterator


@contextlib.contextmanager
def silenced(fd: int, when: bool = True) -> Iterator[None]:
    """Within the block, writes to ``fd`` (1: stdout, 2: stderr) go to /dev/null, while ``when``. The descriptor is the
    whole process's (other threads' output too): keep the block to the one library call that prints."""
    stream = sys.stdout if fd == 1 else sys.stderr
    if not when:
        yield
        return
    try:
        stream.flush()
        saved = os.dup(fd)
    except (OSError, ValueError, AttributeError):  # no real descriptor (e.g. captured in a notebook): nothing to silence
        yield
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, fd)
        yield
    finally:
        os.dup2(saved, fd)
        os.close(saved)
        os.close(devnull)


#: Captures from several threads take turns: each restores the descriptor it found, so two at once could leave the
#: process writing to the other's closed capture file.
_CAPTURE_LOCK = threading.RLock()


class CapturedText:
    """What was written to a descriptor inside :func:`captured`; ``text`` is filled when the block ends."""

    def __init__(self) -> None:
        self.text = ""


def _capture_file():
    """An anonymous file to hold captured output (a file, not a pipe: a long message cannot block the writer): in
    memory where the system has ``memfd_create`` (Linux), needing no writable folder; else a temporary file."""
    if hasattr(os, "memfd_create"):
        try:
            return os.fdopen(os.memfd_create("lidarkit-capture"), "w+b")
        except OSError:
            pass
    return tempfile.TemporaryFile()


@contextlib.contextmanager
def captured(fd: int) -> Iterator[CapturedText]:
    """Within the block, writes to ``fd`` (1: stdout, 2: stderr) go to a temporary file whose text the yielded holder has
    once the block ends: a library's own error line kept for the error lidarkit raises, not printed between progress
    lines. The descriptor is the whole process's (other threads' output too): keep the block to the one library call."""
    stream = sys.stdout if fd == 1 else sys.stderr
    holder = CapturedText()
    with _CAPTURE_LOCK:
        try:
            stream.flush()
            saved = os.dup(fd)
        except (OSError, ValueError, AttributeError):  # no real descriptor (e.g. captured in a notebook): nothing to capture
            yield holder
            return
        try:
            sink = _capture_file()
        except OSError:  # (no memfd and no writable temporary folder, e.g. a read-only container: reads went on failing)
            os.close(saved)
            yield holder
            return
        try:
            with sink:
                os.dup2(sink.fileno(), fd)
                try:
                    yield holder
                finally:
                    os.dup2(saved, fd)
                    sink.seek(0)
                    holder.text = sink.read().decode("utf-8", "replace")
        finally:
            os.close(saved)
