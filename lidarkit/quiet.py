"""Silencing what compiled libraries print straight to a file descriptor (their C/C++ writes bypass ``sys.stdout``)."""

from __future__ import annotations

import contextlib
import os
import sys
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
