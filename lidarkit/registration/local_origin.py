"""A local origin for backends that lose precision far from the origin (georeferenced clouds, 1e5-1e6 m out).

small_gicp's voxel grid overflows its integer voxel coordinates ("voxel coord is out of range", and no
correspondences) and Open3D's GICP and point-to-plane drift off by metres once coordinates reach 1e5-1e6 m; the
point-to-point variants and lidarkit's own search are exact there. Those backends get both clouds shifted by one
origin near them; the pose they return is shifted back (``T = S T' S^-1``) and the assessment runs on the clouds as
given. Clouds within :data:`FAR_M` of the origin are passed on as they are (no copy, nothing changes).
"""

from __future__ import annotations

import numpy as np

#: Coordinates beyond this (m) are moved to a local origin before the backends that need it.
FAR_M = 1e4


class LocalOrigin:
    """The origin one registration instance works in: kept while the clouds stay within :data:`FAR_M` of it (so that
    prepared clouds cached from one frame serve the next), moved when they leave."""

    def __init__(self):
        self.offset: np.ndarray | None = None

    def update(self, target_xyz: np.ndarray) -> np.ndarray | None:
        """The offset to subtract from both clouds of this registration (None: none needed)."""
        probe = target_xyz[:: max(1, len(target_xyz) // 64)]
        reference = np.zeros(3) if self.offset is None else self.offset
        if np.abs(probe - reference).max(initial=0.0) <= FAR_M:
            return self.offset
        if np.abs(probe).max(initial=0.0) <= FAR_M:
            self.offset = None  # back near the true origin
        else:
            self.offset = np.round(probe.mean(axis=0), -3)  # a whole kilometre: the same origin for nearby clouds
        return self.offset

    @staticmethod
    def shift(points_xyz: np.ndarray, offset: np.ndarray | None) -> np.ndarray:
        return points_xyz if offset is None else points_xyz - offset

    @staticmethod
    def into(T: np.ndarray, offset: np.ndarray | None) -> np.ndarray:
        """A pose between the given clouds as a pose between the shifted ones: ``S^-1 T S`` (S: translation by offset)."""
        if offset is None:
            return T
        out = np.array(T, dtype=np.float64)
        out[:3, 3] = T[:3, :3] @ offset + T[:3, 3] - offset
        return out

    @staticmethod
    def out_of(T: np.ndarray, offset: np.ndarray | None) -> np.ndarray:
        """A pose between the shifted clouds as one between the given clouds: ``S T S^-1``."""
        if offset is None:
            return T
        out = np.array(T, dtype=np.float64)
        out[:3, 3] = T[:3, 3] + offset - T[:3, :3] @ offset
        return out


__all__ = ["FAR_M", "LocalOrigin"]
