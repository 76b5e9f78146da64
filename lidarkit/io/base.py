"""What every dataset reader returns: scan sequences and image sequences share a small interface."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from lidarkit.trajectory import Trajectory


@dataclass(frozen=True)
class Scan:
    """One LiDAR sweep.

    ``points_xyz``: ``(N, 3)`` float64 in the sensor frame; ``intensity``: ``(N,)`` or None;
    ``point_times_s``: ``(N,)`` per-point time relative to the sweep start (None if unknown);
    ``timestamp_s``: the sweep's time stamp; ``frame``: its index in the sequence.
    """

    points_xyz: np.ndarray
    intensity: np.ndarray | None = None
    point_times_s: np.ndarray | None = None
    timestamp_s: float | None = None
    frame: int = 0
    source: str = ""


@runtime_checkable
class ScanSequence(Protocol):
    """A sequence of LiDAR scans; ``ground_truth`` is in the LiDAR frame (or None)."""

    name: str

    def __len__(self) -> int: ...

    def read_scan(self, index: int) -> Scan: ...

    @property
    def timestamps_s(self) -> np.ndarray | None: ...

    @property
    def ground_truth(self) -> Trajectory | None: ...


@runtime_checkable
class ImageSequence(Protocol):
    """A sequence of grayscale images with intrinsics; ``ground_truth`` is in the camera frame (or None)."""

    name: str

    def __len__(self) -> int: ...

    def read_image(self, index: int) -> np.ndarray: ...

    @property
    def K(self) -> np.ndarray | None: ...

    @property
    def timestamps_s(self) -> np.ndarray | None: ...

    @property
    def ground_truth(self) -> Trajectory | None: ...
