"""Local origins for backends that lose precision far from the origin (georeferenced clouds, 1e5-1e6 m out).

small_gicp's voxel grid overflows its integer voxel coordinates ("voxel coord is out of range", and no
correspondences) and Open3D's GICP and point-to-plane drift off by metres once coordinates reach 1e5-1e6 m; the
point-to-point variants and lidarkit's own search are exact there. Those backends get each cloud shifted to an origin
near it (a whole kilometre, so that one cloud always gets the same one and a prepared cloud can be reused); the pose
they return is shifted back, ``T = S_target T' S_source^-1``, and the assessment runs on the clouds as given. A cloud
within :data:`FAR_M` of the origin is passed on as it is (no copy, nothing changes).
"""

from __future__ import annotations

import contextlib
import contextvars
from collections.abc import Iterator

import numpy as np

#: Coordinates beyond this (m) are moved to a local origin before the backends that need it.
FAR_M = 1e4

#: A scan whose median point lies farther than this (m) from its frame's origin is not in its sensor frame
#: (georeferenced, a map frame): its covariance is computed and calibrated around :func:`sensor_proxy` instead.
SENSOR_NEAR_M = 50.0


def local_offset(points_xyz: np.ndarray, far_m: float = FAR_M) -> np.ndarray | None:
    """The origin to move ``points_xyz`` to (its mean to the kilometre), or None when it lies within ``far_m``."""
    probe = points_xyz[:: max(1, len(points_xyz) // 64)]
    if np.abs(probe).max(initial=0.0) <= far_m:
        return None
    return np.round(probe.mean(axis=0), -3)


def sensor_proxy(points_xyz: np.ndarray, near_m: float = SENSOR_NEAR_M) -> np.ndarray | None:
    """Where the sensor of a scan given in another frame is likely to be: the median of its points (a scan's returns
    crowd around its sensor: within 2 m of it on the streets and the KITTI pairs; on a small indoor scene 1 m is far,
    see docs/registration.md: the LiDAR pair's sigmas moved 300 m came out up to 2.2x), or None when that lies within
    ``near_m`` of the frame's origin (the scan is in its sensor frame, where the covariance calibration was learned).

    The covariance is computed and calibrated around it and moved to the frame's origin with the adjoint: calibrated
    around a point hundreds of metres from the sensor (a map frame's origin, a georeferenced cloud's rounded mean),
    the per-axis factors mixed the rotation into the translation (small_gicp's sigmas 0.4 m instead of 1.5 mm after a
    300 m shift of both clouds), and the rays of the sensor model ran from the wrong place."""
    probe = np.asarray(points_xyz, dtype=np.float64)[:: max(1, len(points_xyz) // 256)]  # (a few m is close enough)
    if len(probe) == 0:
        return None
    centre = np.median(probe, axis=0)
    return None if float(np.linalg.norm(centre)) <= near_m else centre


def where_cloud_lies(points_xyz: np.ndarray) -> str:
    """How far ``(N, 3)`` points lie from their frame's origin, where a range crop puts the sensor, for the error of a
    cloud the crop leaves (nearly) empty; a cloud whose middle is far out (:func:`sensor_proxy`) is told to come in its
    sensor frame (georeferenced, 5e6 m out, kiss said only "0 points within [0.0, 100.0] m of the sensor")."""
    range_m = np.linalg.norm(np.asarray(points_xyz, dtype=np.float64), axis=1)
    if len(range_m) == 0:
        return "the cloud is empty"
    text = f"the cloud lies {range_m.min():.1f}-{range_m.max():.1f} m from the sensor"
    if sensor_proxy(points_xyz) is None:
        return text
    return text + ", as a georeferenced or map-frame cloud does: give scans in their sensor frame"


def range_crop_text(min_range_m: float, max_range_m: float, points_xyz: np.ndarray) -> str:
    """``[min, max] m of the sensor``, the options that set it and :func:`where_cloud_lies` for ``points_xyz``."""
    return f"[{min_range_m:g}, {max_range_m:g}] m of the sensor (min_range_m / max_range_m; {where_cloud_lies(points_xyz)})"


#: ``(target, source)`` sensor proxies of the clouds as the caller gave them to ``align`` (see :func:`use_sensors`)
_SENSORS: contextvars.ContextVar[tuple[np.ndarray | None, np.ndarray | None] | None] = contextvars.ContextVar("cloud_sensors", default=None)


def sensors_of(target_xyz: np.ndarray, source_xyz: np.ndarray) -> tuple[np.ndarray | None, np.ndarray | None]:
    """``(target, source)`` :func:`sensor_proxy` of the clouds a registration was given, unless an outer registration
    (one that hands filtered clouds on, e.g. without the ground) already took them from the clouds it was given."""
    outer = _SENSORS.get()
    return outer if outer is not None else (sensor_proxy(target_xyz), sensor_proxy(source_xyz))


@contextlib.contextmanager
def use_sensors(sensors: tuple[np.ndarray | None, np.ndarray | None] | None) -> Iterator[None]:
    """Run an assessment with the sensor proxies of the clouds as given (:func:`sensors_of`): a backend assesses its
    voxelized clouds, whose median lies 6-12 m from the sensor on a KITTI scan (the dense returns around the sensor
    thin out), where the raw scan's lies within 2 m; the covariance moved from there was 1.7-3.3x off in z. None:
    nothing set (a registration that is not assessed)."""
    if sensors is None:
        yield
        return
    token = _SENSORS.set(sensors)
    try:
        yield
    finally:
        _SENSORS.reset(token)


def given_sensors() -> tuple[np.ndarray | None, np.ndarray | None] | None:
    """The proxies set by :func:`use_sensors` for the running registration, or None (assessed outside ``align``)."""
    return _SENSORS.get()


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


__all__ = ["FAR_M", "SENSOR_NEAR_M", "given", "given_sensors", "into", "local_offset", "out_of", "range_crop_text", "sensor_proxy", "sensors_of",
           "shift", "use_sensors", "where_cloud_lies"]
