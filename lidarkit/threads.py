"""Worker threads for the work lidarkit does beside a backend's own: the backends release the GIL while they register
(Open3D, kiss-icp's map search, small_gicp's parallel regions), so what does not need their result runs meanwhile.

- :class:`background`: one function in a thread of its own, started now and joined by :meth:`background.result`
  (the pose-free part of an assessment, built while the registration that needs it runs).
- :class:`Overlap`: one persistent worker for an odometry run. Frame k's assessment (correspondences, degeneracy,
  covariance) and frame check run in it while frame k+1 registers. Tasks run one at a time in the order submitted,
  each in a copy of the submitting thread's context (the covariance model in force,
  :func:`lidarkit.registration.covariance.use_model`), so their results are those of the same calls made in line.
  :meth:`Overlap.close` cancels what has not started and joins the thread, also on error or interrupt.

Neither leaves a thread behind: a run joins every thread it started.
"""

from __future__ import annotations

import contextvars
import threading
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any, TypeVar

T = TypeVar("T")


class background:  # noqa: N801 - used like a function
    """``fn()`` in a thread of its own, started now; :meth:`result` joins it and returns its value (or raises its
    error)."""

    def __init__(self, fn: Callable[[], Any]):
        self._value: Any = None
        self._error: BaseException | None = None

        def work() -> None:
            try:
                self._value = fn()
            except BaseException as err:  # noqa: BLE001 - handed to result()
                self._error = err

        self._thread = threading.Thread(target=work, name="lidarkit-assessment-prep", daemon=True)
        self._thread.start()

    def result(self) -> Any:
        self._thread.join()
        if self._error is not None:
            raise self._error
        return self._value


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


__all__ = ["Overlap", "background"]
