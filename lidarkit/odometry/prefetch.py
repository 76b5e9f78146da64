"""Read scans in a background thread, a bounded number ahead of the registration that consumes them."""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Iterator

import numpy as np

from lidarkit.io.base import Scan

#: scans read ahead by default: enough to hide a slow read behind registration, few enough to keep memory flat
DEFAULT_DEPTH = 4


def prefetched(read, indices: np.ndarray, depth: int = DEFAULT_DEPTH) -> Iterator[tuple[int, Scan | None, float, BaseException | None]]:
    """``(index, scan, read_s, error)`` for each of ``indices`` in order; ``read(index)`` runs in one thread.

    At most ``depth`` scans wait in the queue (``depth=0``: read inline, no thread). A read that fails yields its
    error in place of the scan and ends the reading. Closing the generator early stops and joins the thread.
    """
    if depth <= 0:
        for idx in indices:
            t0 = time.perf_counter()
            try:
                scan = read(int(idx))
            except BaseException as err:  # noqa: BLE001 - handed to the consumer, which decides
                yield int(idx), None, time.perf_counter() - t0, err
                return
            yield int(idx), scan, time.perf_counter() - t0, None
        return
    slots: queue.Queue = queue.Queue(maxsize=depth)
    stop = threading.Event()

    def put(item) -> bool:
        while not stop.is_set():
            try:
                slots.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def work() -> None:
        for idx in indices:
            if stop.is_set():
                return
            t0 = time.perf_counter()
            try:
                scan = read(int(idx))
            except BaseException as err:  # noqa: BLE001
                put((int(idx), None, time.perf_counter() - t0, err))
                return
            if not put((int(idx), scan, time.perf_counter() - t0, None)):
                return

    worker = threading.Thread(target=work, name="lidarkit-prefetch", daemon=True)
    worker.start()
    try:
        for _ in range(len(indices)):
            item = slots.get()
            yield item
            if item[3] is not None:
                return
    finally:
        stop.set()
        worker.join()


__all__ = ["DEFAULT_DEPTH", "prefetched"]
