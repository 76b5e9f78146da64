"""Progress of a long loop on stderr: a rich bar on a terminal, a line at every tenth of the run elsewhere (a log, CI).

``progress_bar(total, label)`` returns ``(bar, task)``; the loop calls ``bar.advance(task)`` per item and
``bar.stop()`` at the end.
"""

from __future__ import annotations

import sys
import time


class ProgressLines:
    """Progress where no bar can be drawn (stderr to a file or a pipe: a log, CI): one line at every tenth of the run
    and at least every 30 s, with the frame rate and the time left."""

    def __init__(self, total: int, label: str, unit: str = "frames"):
        self.total, self.label, self.unit, self.done = total, label, unit, 0
        self.start = self.last = time.monotonic()
        self.next_tenth = 1

    def advance(self, _task: int, advance: int = 1) -> None:
        self.done += advance
        now = time.monotonic()
        tenth = 10 * self.done // max(self.total, 1)
        if tenth < self.next_tenth and now - self.last < 30.0 and self.done < self.total:
            return
        self.next_tenth, self.last = tenth + 1, now
        rate = self.done / max(now - self.start, 1e-9)
        left = (self.total - self.done) / rate if rate > 0 else float("nan")
        print(f"{self.label}: {self.done}/{self.total} {self.unit} ({100 * self.done / max(self.total, 1):.0f} %), {rate:.1f} {self.unit}/s, "
              f"~{left:.0f} s left", file=sys.stderr, flush=True)

    def update(self, _task: int, *, total: int | None = None, refresh: bool = False) -> None:
        """The part of rich's ``Progress.update`` lidarkit uses: a new ``total`` (a loop that ended early), drawn when
        ``refresh``."""
        if total is not None:
            self.total = total
        if refresh:
            self.advance(_task, 0)

    def stop(self) -> None:
        pass


def progress_bar(total: int, label: str, unit: str = "frames"):
    """``(bar, task)`` for ``total`` items (``unit``) titled ``label``: rich's bar where stderr is a terminal, else lines."""
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    console = Console(stderr=True)
    if not console.is_terminal:
        return ProgressLines(total, label, unit), 0
    bar = Progress(TextColumn("{task.description}", markup=False), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(), console=console, transient=True)
    bar.start()
    return bar, bar.add_task(label, total=total)


__all__ = ["ProgressLines", "progress_bar"]
