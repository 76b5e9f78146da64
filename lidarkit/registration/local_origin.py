"""Local origins for backends that lose precision far from the origin (georeferenced clouds, 1e5-1e6 m out).

small_gicp's voxel grid overflows its integer voxel coordinates ("voxel coord is out of range", and no
correspondences) and Open3D's GICP and point-to-plane drift off by metres once coordinates reach 1e5-1e6 m; the
point-to-point variants and lidarkit's own search are exact there. Those backends get each cloud shifted to an origin
near it (a whole kilometre, so that one cloud always gets the same one and a prepared cloud can be reused); the pose
they return is shifted back, ``T = S_target T' S_source^-1``, and the assessment runs on the clouds as given. A cloud
within :data:`FAR_M` of the origin is passed on as it is (no copy, nothing changes).
"""

from __future__ import annotations

import numpy as np

#: Coordinates beyond this (m) are moved to a local origin before the backends that need it.
FAR_M = 1e4

#: The covariance's closed form loses the rotation to rounding sooner (7 km out: sigmas 0.06x): its local origin
#: is taken beyond this (m; a scan in its sensor frame stays well inside).
COVARIANCE_FAR_M = 1e3


def local_offset(points_xyz: np.ndarray, far_m: float = FAR_M) -> np.ndarray | None:
    """The origin to move ``points_xyz`` to (its mean to the kilometre), or None when it lies within ``far_m``."""
    probe = points_xyz[:: max(1, len(points_xyz) // 64)]
    if np.abs(probe).max(initial=0.0) <= far_m:
        return None
    return np.round(probe.mean(axis=0), -3)


def shift(points_xyz: np.ndarray, offset: np.ndarray | None) -> np.ndarray:
    return points_xyz if offset is None else points_xyz - offset


def into(T: np.ndarray, target_offset: np.ndarray | None, source_offset: np.ndarray | None) -> np.ndarray:
    """A pose between the given clouds as one between the shifted ones: ``S_target^-1 T S_source``."""
    if target_offset is None and source_offset is None:
        return T
    out = np.array(T, dtype=np.float64)
    out[:3, 3] = T[:3, 3] + (0.0 if source_offset is None else T[:3, :3] @ source_offset) - (0.0 if target_offset is None else target_offset)
    return out


def out_of(T: np.ndarray, target_offset: np.ndarray | None, source_offset: np.ndarray | None) -> np.ndarray:
    """A pose between the shifted clouds as one between the given clouds: ``S_target T S_source^-1``."""
    if target_offset is None and source_offset is None:
        return T
    out = np.array(T, dtype=np.float64)
    out[:3, 3] = T[:3, 3] - (0.0 if source_offset is None else T[:3, :3] @ source_offset) + (0.0 if target_offset is None else target_offset)
    return out


def given(points_xyz: np.ndarray, offset: np.ndarray | None) -> np.ndarray:
    """Shifted points back where the cloud is."""
    return points_xyz if offset is None else points_xyz + offset


__all__ = ["COVARIANCE_FAR_M", "FAR_M", "given", "into", "local_offset", "out_of", "shift"]
