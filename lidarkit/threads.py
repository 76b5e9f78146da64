"""Helper threads that should only take the CPU a backend leaves idle.

lidarkit overlaps its own after-the-fact work (an odometry frame's assessment and check, a pairwise alignment's
pose-free index) with the backend's registration. The backends run OpenMP / TBB regions over every core and wait
for their slowest thread, so a helper that took a core from one of them would slow the whole region by as much as
it saves. On Linux a helper thread therefore lowers its own priority (``nice`` is per thread there): it runs in the
gaps (the backends' serial parts, the waits between calls) and yields the core whenever a backend thread wants it.
"""

from __future__ import annotations

import os
import sys
import threading

#: niceness a helper thread adds to its own (0: none); 19 is the lowest priority
HELPER_NICENESS = 19


def lower_priority() -> None:
    """Give the calling thread the helper priority (Linux only, where a thread has its own nice value; no-op elsewhere)."""
    if not HELPER_NICENESS or not sys.platform.startswith("linux"):
        return
    try:
        tid = threading.get_native_id()
        os.setpriority(os.PRIO_PROCESS, tid, min(19, os.getpriority(os.PRIO_PROCESS, tid) + HELPER_NICENESS))
    except (OSError, AttributeError):  # not permitted or not supported: the helper runs at normal priority
        pass


__all__ = ["HELPER_NICENESS", "lower_priority"]
