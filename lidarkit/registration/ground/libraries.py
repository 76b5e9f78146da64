"""Wrapped ground segmentation libraries behind the segmenter interface: Patchwork++ and the cloth simulation filter.

Both are optional (``pip install 'lidarkit[ground]'``); a missing one is a ConfigError naming the pip line when
the segmenter is created, not when lidarkit is imported. Their C++ cores print progress on the process's
stdout, which library code must not do: the calls run with file descriptor 1 sent to /dev/null.
"""

from __future__ import annotations

import contextlib
from typing import Any

import numpy as np
from pydantic import Field, model_validator

from lidarkit.errors import ConfigError
from lidarkit.quiet import silenced
from lidarkit.registration.ground.base import KITTI_SENSOR_HEIGHT_M, GroundConfig, GroundSegmenter, register_ground_segmenter


def _import(module: str, package: str) -> Any:
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError as err:
        raise ConfigError(
            f"needs the Python package {package!r} ({err}); install it with: pip install {package}  (or pip install 'lidarkit[ground]')",
            source=f"ground segmenter ({module})",
        ) from None


def _own_openmp_thread_setters(module: Any) -> list[Any]:
    """``omp_set_num_threads`` of the OpenMP runtime a library's wheel ships for itself (``<package>.libs/libgomp*``),
    none when it has none. The cloth simulation's threads changed its ground mask from run to run (the KITTI pair's
    pose by 6 mm across six runs); on one thread it repeats, and the other libraries' runtimes keep their threads."""
    import ctypes
    from pathlib import Path

    setters = []
    for lib in sorted(Path(module.__file__).parent.glob("cloth_simulation_filter.libs/libgomp*.so*")):
        with contextlib.suppress(OSError, AttributeError):
            setters.append(ctypes.CDLL(str(lib)).omp_set_num_threads)
    return setters


class PatchworkConfig(GroundConfig):
    sensor_height_m: float = Field(KITTI_SENSOR_HEIGHT_M, gt=0, description="sensor height above the ground (m)")
    min_range_m: float = Field(2.7, ge=0, description="points closer are ignored (m)")
    max_range_m: float = Field(80.0, gt=0, description="points farther are ignored (m)")
    th_dist_m: float = Field(0.125, gt=0, description="distance of ground points to their patch plane (m)")
    uprightness_thr: float = Field(0.707, ge=0, le=1, description="min z component of a ground patch's normal")

    @model_validator(mode="after")
    def _ranges(self) -> "PatchworkConfig":
        if self.min_range_m >= self.max_range_m:  # (it marked no point as ground, silently)
            raise ValueError(f"min_range_m {self.min_range_m:g} must be below max_range_m {self.max_range_m:g}")
        return self


@register_ground_segmenter("patchworkpp")
class PatchworkSegmenter(GroundSegmenter):
    """Patchwork++ (pypatchworkpp): concentric-zone patches, region-wise plane fits, adaptive thresholds."""

    Config = PatchworkConfig

    def __init__(self, config: GroundConfig | None = None, **params: Any):
        super().__init__(config, **params)
        pw = _import("pypatchworkpp", "pypatchworkpp")
        c = self.config
        p = pw.Parameters()
        p.verbose = False
        p.sensor_height = float(c.sensor_height_m)
        p.min_range = float(c.min_range_m)
        p.max_range = float(c.max_range_m)
        p.th_dist = float(c.th_dist_m)
        p.uprightness_thr = float(c.uprightness_thr)
        p.enable_RNR = False  # reflected-noise removal needs intensities, which the interface does not pass
        self._pw, self._parameters = pw, p

    def _segment(self, points_xyz: np.ndarray) -> np.ndarray:
        cloud = np.zeros((len(points_xyz), 4), dtype=np.float32)
        cloud[:, :3] = points_xyz
        with silenced(1):
            # a fresh engine per scan: one engine keeps state between calls (the same scan twice gave 72600 and then
            # 72361 ground points), which made a stateless variant's result depend on the scans it saw before
            engine = self._pw.patchworkpp(self._parameters)
            engine.estimateGround(cloud)
            index = np.asarray(engine.getGroundIndices(), dtype=np.int64)
        mask = np.zeros(len(points_xyz), dtype=bool)
        mask[index] = True
        return mask


class ClothConfig(GroundConfig):
    cloth_resolution_m: float = Field(0.5, gt=0, description="grid spacing of the simulated cloth (m)")
    rigidness: int = Field(2, ge=1, le=3, description="1: steep terrain, 2: relief, 3: flat")
    class_threshold_m: float = Field(0.5, gt=0, description="points closer than this to the cloth are ground (m)")
    slope_smooth: bool = Field(True, description="post-process steep slopes")
    time_step: float = Field(0.65, gt=0, description="simulation time step")
    iterations: int = Field(500, ge=1, description="maximum simulation iterations")


@register_ground_segmenter("csf")
class ClothSegmenter(GroundSegmenter):
    """Cloth simulation filter (cloth-simulation-filter): a cloth dropped on the upside-down cloud settles on the ground."""

    Config = ClothConfig
    heights_from_sensor = False  # heights against the points themselves

    def __init__(self, config: GroundConfig | None = None, **params: Any):
        super().__init__(config, **params)
        self._csf = _import("CSF", "cloth-simulation-filter")
        self._omp_threads = _own_openmp_thread_setters(self._csf)

    def _segment(self, points_xyz: np.ndarray) -> np.ndarray:
        c = self.config
        for set_threads in self._omp_threads:  # (per calling thread: OpenMP keeps the setting per thread)
            set_threads(1)
        engine = self._csf.CSF()
        engine.params.bSloopSmooth = bool(c.slope_smooth)
        engine.params.cloth_resolution = float(c.cloth_resolution_m)
        engine.params.rigidness = int(c.rigidness)
        engine.params.class_threshold = float(c.class_threshold_m)
        engine.params.time_step = float(c.time_step)
        engine.params.interations = int(c.iterations)
        ground, rest = self._csf.VecInt(), self._csf.VecInt()
        with silenced(1):
            engine.setPointCloud(np.ascontiguousarray(points_xyz, dtype=np.float64))
            engine.do_filtering(ground, rest, False)
        mask = np.zeros(len(points_xyz), dtype=bool)
        mask[np.asarray(ground, dtype=np.int64)] = True
        return mask
