"""One worker thread for the after-the-fact work of an odometry frame, overlapped with the next frame's registration.

The backends release the GIL while they register (Open3D, kiss-icp's map search, small_gicp's parallel regions), so
frame k's assessment (correspondences, degeneracy, covariance) and frame check run in this thread while frame k+1
registers. Tasks run one at a time in the order submitted, each in a copy of the submitting thread's context (the
covariance model in force, :func:`lidarkit.registration.covariance.use_model`), so their results are those of the
same calls made in line. :meth:`Overlap.close` cancels what has not started and joins the thread, also on error or
interrupt: a run leaves no thread behind.
"""

from __future__ import annotations

import contextvars
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any, TypeVar

T = TypeVar("T")


class Overlap:
    """``submit(fn)`` runs ``fn`` in one persistent worker thread (``enabled=False``: in line, at once)."""

    def __init__(self, enabled: bool = True):
        self._pool = ThreadPoolExecutor(1, thread_name_prefix="lidarkit-assess") if enabled else None

    def submit(self, fn: Callable[[], T]) -> Future:
        if self._pool is None:
            done: Future = Future()
            try:
                done.set_result(fn())
            except Exception as err:  # noqa: BLE001 - raised by result(), as from the thread
                done.set_exception(err)
            return done
        return self._pool.submit(contextvars.copy_context().run, fn)

    def close(self) -> None:
        """Cancel the tasks not yet started and join the thread (the running task, at most one frame's, finishes)."""
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)

    def __enter__(self) -> "Overlap":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


__all__ = ["Overlap"]
