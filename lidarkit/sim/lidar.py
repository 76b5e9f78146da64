"""Simulated spinning LiDAR on Open3D's RaycastingScene: procedural scenes, a smooth drive, exact ground truth.

Frames, units and instants (the contract users score against):

* World frame: x/y horizontal, z up, origin at the sensor at the start of sweep 0 (so the ground is the plane
  ``z = -sensor_height_m``). Sensor frame: x forward, y left, z up (KITTI Velodyne convention).
* Sweep ``i`` covers ``[i / frame_rate_hz, (i + 1) / frame_rate_hz)``. Column ``k`` of ``n_azimuths`` fires at
  ``t_k = k / (n_azimuths * frame_rate_hz)`` after the sweep start, at azimuth ``pi - 2 pi k / n_azimuths`` (the
  sweep starts and ends behind the vehicle and turns clockwise seen from above, like a Velodyne).
* ``Scan.point_times_s`` are those column times (relative to the sweep start, non-decreasing in point order).
* Ground-truth poses ``T_world_lidar`` refer to ONE instant of each sweep, chosen by ``pose_instant``:
  ``"start"`` (``t = i T``), ``"mid"`` (``t = (i + 0.5) T``) or ``"end"`` (``t = (i + 1) T``), with ``T`` the sweep
  period. The default is ``"end"`` because kiss-icp 1.x deskews every sweep to its last point (the sweep end);
  :meth:`SimulatedLidarSequence.ground_truth_at` gives the other instants. ``timestamps_s`` refer to the same
  instant as ``ground_truth``.
* The vehicle starts at rest and accelerates smoothly to ``speed_mps`` within ``accel_time_s`` (a car pulling
  away; a constant-velocity tracker such as kiss-icp cannot pick up a 10 m/s motion from a cold start on a flat
  ground plane), then drives at constant speed along gentle seeded curves on flat ground, its body pitching,
  rolling (``sway_deg``) and heaving (``heave_m``) gently as on a suspension (set both to 0 for planar motion).
* With ``motion_distortion=True`` every column is cast from the pose at its own firing time and its points are
  expressed in the sensor frame of that time (what a real spinning sensor reports). With ``False`` the whole sweep
  is cast from the ground-truth pose (an ideal snapshot at ``pose_instant``), and carries no per-point times.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, ValidationInfo, field_validator, model_validator

from lidarkit.errors import ConfigError, DataError
from lidarkit.io.base import Scan, checked_index
from lidarkit.params import number_field
from lidarkit.trajectory import Trajectory

log = logging.getLogger(__name__)

#: Distance (m) from the start within which sweeps lie on the exact surfaces to ~0.3 mm (median) despite the float32
#: ray casting (0.03 mm at 0.1 km, 0.14 mm at 5 km, 0.31 mm at 10 km, 2.5 mm at 98 km; 32 x 512 rays at 100 m/s)
FLOAT32_EXACT_REACH_M = 10_000.0

SCENES = ("street", "open", "ground")

#: Per-point semantic labels (``read_scan_labels``): the class of the scene triangle each ray hit.
LABEL_NAMES = ("unlabeled", "ground", "building", "pole", "trunk", "vegetation", "car")
LABELS = {name: code for code, name in enumerate(LABEL_NAMES)}
GROUND_LABEL = LABELS["ground"]
POSE_INSTANTS = ("start", "mid", "end")
#: Peak memory of one sweep per ray (bytes), for the memory check: ray directions and hits in float64 and the exported
#: records, a few copies each (measured 214-235 on 64 x 50000 and 32 x 100000 sweeps; it was taken as 160).
SWEEP_BYTES_PER_RAY = 240.0
PoseInstant = Literal["start", "mid", "end"]
_INSTANT_FRACTION = {"start": 0.0, "mid": 0.5, "end": 1.0}


#: Nearest the open scene's objects may stand to the path (m): its largest box (6 x 6 m, turned any way) reaches 4.25 m
#: from its centre, plus 0.75 m for the vehicle carrying the sensor.
OPEN_OBJECT_CLEARANCE_M = 5.0
#: Longest drive the simulator builds a scene along (m): ~5 MB of scene mesh per km.
MAX_DRIVE_M = 200_000.0
#: Steepest hills: ``terrain_amplitude_m x 2 pi / terrain_wavelength_m``, their typical steepest rise over run (at 0.5 the
#: body tilted at most 15-27 deg over 300 sweeps of seeds 0-3; 20 m hills every 60 m, 2.1, tilted it 48-66 deg).
MAX_TERRAIN_SLOPE = 0.5
#: Least height of the sensor above the ground at the bottom of its heave (m): the hills' mesh lies up to 2 cm above
#: the true terrain under the path (measured at the steepest hills allowed), and a sensor below the ground mesh
#: returned the underside of the ground.
MIN_GROUND_CLEARANCE_M = 0.05
#: Most sweeps of one sequence: its ground truth and stamps take ~0.7 KB a sweep (0.7 GB for a million).
MAX_FRAMES = 1_000_000


def number_not_yes_or_no(model: type[BaseModel], value: object, info: ValidationInfo) -> object:
    """``value`` of a simulator setting, refused when it is a yes/no value for a number: pydantic's lax mode reads True as
    1 without a word (``-p n_beams=true`` cast one beam, ``speed=off`` stood still, ``seed=yes`` was seed 1)."""
    items = value if isinstance(value, (list, tuple)) else [value]  # (a range: open_object_lateral_m=[true,10])
    yes_no = [v for v in items if isinstance(v, (bool, np.bool_))]
    if yes_no and number_field(model.model_fields[info.field_name].annotation):
        raise ValueError(f"takes a number, not a yes/no value ({yes_no[0]})")
    return value


class LidarSimConfig(BaseModel):
    """Everything that defines a simulated sequence; equal configs give bit-identical scans."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    scene: Literal["street", "open", "ground"] = "street"
    n_frames: int = Field(300, ge=1, le=MAX_FRAMES, description="number of sweeps (a million at most: 28 hours at 10 Hz)")
    seed: int = Field(0, ge=0, description="seeds the scene, the path and the range noise")
    # sensor (KITTI HDL-64-like)
    n_beams: int = Field(64, ge=1)
    n_azimuths: int = Field(2000, ge=8, description="columns per sweep")
    elevation_max_deg: float = Field(2.0, ge=-89.0, le=89.0)
    elevation_min_deg: float = Field(-24.8, ge=-89.0, le=89.0)
    max_range_m: float = Field(80.0, gt=0.0, le=1000.0, description="longest range measured (m; a kilometre at most)")
    min_range_m: float = Field(1.0, ge=0.0)
    sensor_height_m: float = Field(1.73, gt=0.0, le=1000.0, description="sensor above the ground plane (m; at most a "
                                   "kilometre, the longest max_range_m: 1e308 overflowed the float32 scene)")
    range_noise_std_m: float = Field(0.0, ge=0.0, le=10.0, description="Gaussian noise along each ray (m; at most 10: "
                                     "1e308 overflowed to NaN ranges, reported as a sweep with no return)")
    # motion
    frame_rate_hz: float = Field(10.0, ge=0.1, le=1000.0)
    speed_mps: float = Field(10.0, ge=0.0, le=100.0, description="cruise speed (at most 100 m/s = 360 km/h)")
    accel_time_s: float = Field(
        2.0, ge=0.0, le=600.0, description="the drive starts at rest and reaches speed_mps after this (smooth ramp); 0: moving "
        "from t = 0; at most 10 minutes (1e308 overflowed the ramp to NaN poses, reported as a sweep with no return)"
    )
    max_curvature_per_m: float = Field(1.0 / 150.0, ge=0.0, le=1.0 / 30.0, description="bound of the path curvature "
                                       "(gentle curves; at most 1/30: the street's facades stand 9-13 m from the path, and "
                                       "tighter turns drove the sensor through them)")
    sway_deg: float = Field(0.3, ge=0.0, le=10.0, description="amplitude of the body's pitch and roll oscillation (suspension)")
    heave_m: float = Field(0.02, ge=0.0, le=1.0, description="amplitude of the body's vertical oscillation")
    # terrain (0: the flat ground plane; > 0: rolling hills the vehicle and every object follow)
    terrain_amplitude_m: float = Field(
        0.0, ge=0.0, le=20.0, description="undulating ground: height amplitude of the seeded hills (0: flat ground plane)"
    )
    terrain_wavelength_m: float = Field(60.0, ge=10.0, description="undulating ground: typical wavelength of the hills")
    open_object_lateral_m: tuple[float, float] | None = Field(
        None, description=f"open scene: objects this far left/right of the path (min, max) in m, min >= {OPEN_OBJECT_CLEARANCE_M:g}; None: 8..40 m"
    )
    motion_distortion: bool = True
    point_times: bool = Field(True, description="attach per-point times to each Scan")
    pose_instant: PoseInstant = "end"

    @field_validator("*", mode="before")
    @classmethod
    def _numbers_are_not_yes_or_no(cls, value: object, info: ValidationInfo) -> object:
        return number_not_yes_or_no(cls, value, info)

    @model_validator(mode="after")
    def _check(self) -> LidarSimConfig:
        if self.elevation_min_deg > self.elevation_max_deg:
            raise ValueError("elevation_min_deg must not exceed elevation_max_deg")
        if self.min_range_m >= self.max_range_m:
            raise ValueError("min_range_m must be below max_range_m")
        check_terrain_slope(self.terrain_amplitude_m, self.terrain_wavelength_m)
        lowest_m = 2.0 * self.heave_m + MIN_GROUND_CLEARANCE_M  # the heave swings up to 2 x heave_m from its start
        if self.sensor_height_m < lowest_m - 1e-9 and self.heave_m == 0:  # (no heave to make smaller)
            raise ValueError(f"sensor_height_m {self.sensor_height_m:g} m is below the {MIN_GROUND_CLEARANCE_M:g} m the sensor "
                             "must stay above the ground")
        if self.sensor_height_m < lowest_m - 1e-9:  # (0.01 m with the default 2 cm heave swept from below the ground)
            raise ValueError(f"sensor_height_m {self.sensor_height_m:g} m with heave_m {self.heave_m:g} m can take the sensor below "
                             f"the ground (the heave lowers it by up to 2 x heave_m, and it must stay {MIN_GROUND_CLEARANCE_M:g} m "
                             f"above the ground): sensor_height_m at least {lowest_m:g} m or a smaller heave_m")
        lateral = self.open_object_lateral_m
        if lateral is not None and self.scene != "open":  # (accepted and ignored)
            raise ValueError(f"open_object_lateral_m places the open scene's objects; the {self.scene} scene has none of them")
        if lateral is not None and not 0.0 <= lateral[0] < lateral[1]:
            raise ValueError("open_object_lateral_m must be (min, max) with 0 <= min < max")
        if lateral is not None and lateral[0] < OPEN_OBJECT_CLEARANCE_M:
            raise ValueError(f"open_object_lateral_m min {lateral[0]:g} m would put the open scene's boxes (up to 6 x 6 m, "
                             f"turned any way) across the path: at least {OPEN_OBJECT_CLEARANCE_M:g} m")
        if self.drive_length_m > MAX_DRIVE_M:
            raise ValueError(f"the drive is {self.drive_length_m / 1000:.4g} km long (speed_mps x n_frames / frame_rate_hz, plus "
                             f"the scene around its ends); at most {MAX_DRIVE_M / 1000:g} km (~1 GB of scene): fewer frames or a "
                             "lower speed")
        return self

    @property
    def drive_length_m(self) -> float:
        """Length of the path the scene is built along (the drive plus the sensor's reach around its ends)."""
        return self.speed_mps * (self.n_frames + 1) / self.frame_rate_hz + 2.0 * (self.max_range_m + 40.0)

    @property
    def sweeps_carry_point_times(self) -> bool:
        """Whether each sweep carries per-point times: asked for, and spread over the sweep (a snapshot, no motion
        distortion, has every point at one instant: zeros would read as a sweep's times)."""
        return self.point_times and self.motion_distortion

    @property
    def sweep_period_s(self) -> float:
        return 1.0 / self.frame_rate_hz


def check_terrain_slope(amplitude_m: float, wavelength_m: float) -> None:
    """ValueError for hills that are cliffs (amplitude and wavelength were bounded apart: 20 m every 60 m were allowed)."""
    slope = amplitude_m * 2.0 * np.pi / wavelength_m
    if slope > MAX_TERRAIN_SLOPE:
        raise ValueError(f"terrain_amplitude_m {amplitude_m:g} m every terrain_wavelength_m {wavelength_m:g} m makes slopes of "
                         f"{slope:.2f} (amplitude x 2 pi / wavelength; at most {MAX_TERRAIN_SLOPE:g}, ~27 deg): a lower amplitude "
                         f"or a wavelength of at least {amplitude_m * 2.0 * np.pi / MAX_TERRAIN_SLOPE:.3g} m")


def check_argument(value: object, kind: type, name: str, what: str | None = None) -> None:
    """ConfigError naming the argument ``name`` when ``value`` is no ``kind`` (a wrong kind of argument ended in an
    AttributeError deep inside)."""
    if not isinstance(value, kind):
        shown = f" {value!r}" if len(repr(value)) <= 40 else ""
        raise ConfigError(f"takes {what or 'a ' + kind.__name__}, got {type(value).__name__}{shown}", source=name)


def checked_times(times_s: object) -> np.ndarray:
    """``times_s`` as a 1-D float array, or one DataError naming ``times_s`` (a 2-D array, text or NaN ended in a
    ValueError / IndexError traceback or in NaN poses)."""
    try:
        t = np.asarray(times_s, dtype=np.float64)
    except (TypeError, ValueError):
        shown = f" {times_s!r}" if len(repr(times_s)) <= 40 else ""
        raise DataError(f"takes times in seconds (numbers), got {type(times_s).__name__}{shown}", source="times_s") from None
    if t.ndim > 1:
        raise DataError(f"takes one time or a 1-D array of times, got shape {t.shape}", source="times_s")
    t = np.atleast_1d(t)
    if not np.isfinite(t).all():
        k = int(np.flatnonzero(~np.isfinite(t))[0])
        raise DataError(f"time {t[k]} is not a finite number (s)", source="times_s", location=f"time {k}")
    return t


def checked_config(model: type[BaseModel], params: dict, source: str, options: dict[str, str] | None = None) -> BaseModel:
    """``model(**params)`` or one ConfigError naming ``source``: each problem by its field, or by the CLI option
    ``options`` maps it to (``{"n_frames": "--frames/-n"}``; a problem of one option alone is that option's error); the
    valid names are listed for an unknown key only (a bound listed all 23 of them), a tuple given as ``5,10`` is hinted
    as ``[5,10]``."""
    try:
        return model(**params)
    except ValidationError as err:
        options = options or {}
        named = []  # (the field, its option or "config"; what is wrong)
        for e in err.errors():
            field = str(e["loc"][0]) if e["loc"] else ""
            hint = f" (write it as [{e['input']}])" if e["type"] == "tuple_type" and isinstance(e["input"], str) else ""
            where = options.get(field) or ".".join(map(str, e["loc"])) or "config"
            named.append((where, e["msg"].removeprefix("Value error, ") + hint))
        valid = f" (valid: {', '.join(model.model_fields)})" if any(e["type"] == "extra_forbidden" for e in err.errors()) else ""
        if len(named) == 1 and named[0][0] in options.values():  # "--frames/-n: Input should be greater than or equal to 1"
            raise ConfigError(named[0][1], source=named[0][0]) from None
        raise ConfigError("; ".join(f"{where}: {what}" for where, what in named) + valid, source=source) from None


def make_config(**params: object) -> LidarSimConfig:
    """Validated :class:`LidarSimConfig`; bad or unknown parameters raise ConfigError (see :func:`checked_config`)."""
    return checked_config(LidarSimConfig, params, "lidar simulator")


# ---------------------------------------------------------------------------------------------------------------
# Path: a planar curve parametrised by arc length, curvature a smooth seeded sum of sinusoids.
# ---------------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PlanarPath:
    """Samples of a smooth planar path: arc length ``s_m`` (K,), ``xy_m`` (K, 2), ``heading_rad`` (K,)."""

    s_m: np.ndarray
    xy_m: np.ndarray
    heading_rad: np.ndarray

    @cached_property
    def _columns(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``s``, ``x``, ``y`` and heading as contiguous arrays: ``np.interp`` copies a strided column on every call,
        which made placing the thousands of objects of a long drive quadratic in its length."""
        return tuple(np.ascontiguousarray(a, dtype=np.float64) for a in (self.s_m, self.xy_m[:, 0], self.xy_m[:, 1], self.heading_rad))

    def at(self, s_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Position ``(M, 2)`` and heading ``(M,)`` at arc lengths ``s_m`` (linear interpolation)."""
        s = np.asarray(s_m, dtype=np.float64)
        s_path, x_path, y_path, heading_path = self._columns
        x = np.interp(s, s_path, x_path)
        y = np.interp(s, s_path, y_path)
        return np.stack([x, y], axis=-1), np.interp(s, s_path, heading_path)


def make_path(rng: np.random.Generator, s_begin_m: float, s_end_m: float, max_curvature_per_m: float, step_m: float = 0.1) -> PlanarPath:
    """A gentle curve through the origin heading along +x at ``s = 0``: |curvature| <= ``max_curvature_per_m``."""
    s = np.arange(s_begin_m, s_end_m + step_m, step_m)
    wavelengths = rng.uniform(120.0, 400.0, size=3)
    phases = rng.uniform(0.0, 2.0 * np.pi, size=3)
    weights = rng.uniform(0.5, 1.0, size=3)
    weights *= max_curvature_per_m / weights.sum()
    curvature = (weights[:, None] * np.sin(2.0 * np.pi * s[None, :] / wavelengths[:, None] + phases[:, None])).sum(axis=0)
    heading = _cumtrapz(curvature, step_m)
    heading -= np.interp(0.0, s, heading)
    xy = np.stack([_cumtrapz(np.cos(heading), step_m), _cumtrapz(np.sin(heading), step_m)], axis=1)
    xy -= np.array([np.interp(0.0, s, xy[:, 0]), np.interp(0.0, s, xy[:, 1])])
    return PlanarPath(s, xy, heading)


def _cumtrapz(values: np.ndarray, step: float) -> np.ndarray:
    out = np.zeros_like(values)
    out[1:] = np.cumsum(0.5 * (values[1:] + values[:-1]) * step)
    return out


# ---------------------------------------------------------------------------------------------------------------
# Terrain: a seeded sum of plane waves, zero at the origin (the world origin stays the sensor at the start).
# ---------------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Terrain:
    """Ground height ``h(x, y)`` above the start (m): ``A sum_k w_k (sin(k_k . xy + phi_k) - sin(phi_k))``.

    ``wave_vectors`` (K, 2) rad/m, ``phases`` (K,), ``weights`` (K,) summing to 1; amplitude 0 is flat ground.
    """

    amplitude_m: float
    wave_vectors: np.ndarray
    phases: np.ndarray
    weights: np.ndarray

    def height(self, xy_m: np.ndarray) -> np.ndarray:
        """``(M,)`` ground height at world ``xy_m`` (M, 2)."""
        xy = np.asarray(xy_m, dtype=np.float64).reshape(-1, 2)
        if self.amplitude_m == 0.0:
            return np.zeros(len(xy))
        arg = xy @ self.wave_vectors.T + self.phases
        return self.amplitude_m * ((np.sin(arg) - np.sin(self.phases)) @ self.weights)

    def gradient(self, xy_m: np.ndarray) -> np.ndarray:
        """``(M, 2)`` height gradient (dh/dx, dh/dy) at world ``xy_m`` (M, 2)."""
        xy = np.asarray(xy_m, dtype=np.float64).reshape(-1, 2)
        if self.amplitude_m == 0.0:
            return np.zeros((len(xy), 2))
        arg = xy @ self.wave_vectors.T + self.phases
        return self.amplitude_m * (np.cos(arg) * self.weights) @ self.wave_vectors

    @property
    def max_slope(self) -> float:
        """Upper bound of ``|grad h|`` (rise over run)."""
        return float(self.amplitude_m * (self.weights * np.linalg.norm(self.wave_vectors, axis=1)).sum())


def make_terrain(rng: np.random.Generator, amplitude_m: float, wavelength_m: float) -> Terrain:
    """Three plane waves in seeded directions with wavelengths 0.7..1.4 x ``wavelength_m``."""
    angle = rng.uniform(0.0, np.pi, size=3)
    wavelengths = wavelength_m * rng.uniform(0.7, 1.4, size=3)
    wave_vectors = (2.0 * np.pi / wavelengths)[:, None] * np.stack([np.cos(angle), np.sin(angle)], axis=1)
    weights = rng.uniform(0.5, 1.0, size=3)
    return Terrain(float(amplitude_m), wave_vectors, rng.uniform(0.0, 2.0 * np.pi, size=3), weights / weights.sum())


def _heightfield(terrain: Terrain, lo: np.ndarray, hi: np.ndarray, ground_z: float, spacing_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and triangles of the terrain sampled on a grid anchored at multiples of ``spacing_m``."""
    xs = np.arange(np.floor(lo[0] / spacing_m), np.ceil(hi[0] / spacing_m) + 1) * spacing_m
    ys = np.arange(np.floor(lo[1] / spacing_m), np.ceil(hi[1] / spacing_m) + 1) * spacing_m
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    xy = np.c_[gx.ravel(), gy.ravel()]
    verts = np.c_[xy, ground_z + terrain.height(xy)]
    nx, ny = len(xs), len(ys)
    i, j = np.meshgrid(np.arange(nx - 1), np.arange(ny - 1), indexing="ij")
    a = (i * ny + j).ravel()
    b, c, d = a + ny, a + ny + 1, a + 1
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return verts, faces


# ---------------------------------------------------------------------------------------------------------------
# Scene: triangle soup from numpy primitives (boxes, prisms, crowns) placed along the path.
# ---------------------------------------------------------------------------------------------------------------
_BOX_CORNERS = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (0.0, 1.0)])
_BOX_FACES = np.array(
    [[0, 2, 3], [0, 3, 1], [4, 5, 7], [4, 7, 6], [0, 1, 5], [0, 5, 4], [2, 6, 7], [2, 7, 3], [0, 4, 6], [0, 6, 2], [1, 3, 7], [1, 7, 5]]
)


def _prism(sides: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit-radius, unit-height prism (a cylinder with ``sides`` faces) standing on z = 0."""
    ang = 2.0 * np.pi * np.arange(sides) / sides
    ring = np.stack([np.cos(ang), np.sin(ang)], axis=1)
    verts = np.concatenate([np.c_[ring, np.zeros(sides)], np.c_[ring, np.ones(sides)], [[0, 0, 0], [0, 0, 1]]])
    i = np.arange(sides)
    j = (i + 1) % sides
    side = np.concatenate([np.stack([i, j, j + sides], 1), np.stack([i, j + sides, i + sides], 1)])
    caps = np.concatenate([np.stack([np.full(sides, 2 * sides), j, i], 1), np.stack([np.full(sides, 2 * sides + 1), i + sides, j + sides], 1)])
    return verts, np.concatenate([side, caps])


def _crown() -> tuple[np.ndarray, np.ndarray]:
    """Unit octahedron-like crown (a double cone of 8 sides), centred at the origin."""
    sides = 8
    ang = 2.0 * np.pi * np.arange(sides) / sides
    verts = np.concatenate([np.c_[np.cos(ang), np.sin(ang), np.zeros(sides)], [[0, 0, -1], [0, 0, 1]]])
    i = np.arange(sides)
    j = (i + 1) % sides
    faces = np.concatenate([np.stack([np.full(sides, sides), j, i], 1), np.stack([np.full(sides, sides + 1), i, j], 1)])
    return verts, faces


_PRISM = _prism(8)
_CROWN = _crown()


class _SceneBuilder:
    """Collects instances of unit primitives (scaled, yawed, translated) into one vertex/triangle array."""

    def __init__(self) -> None:
        self._verts: list[np.ndarray] = []
        self._faces: list[np.ndarray] = []
        self._reflectivity: list[np.ndarray] = []
        self._labels: list[np.ndarray] = []
        self._n_verts = 0

    def add(
        self, prim: tuple[np.ndarray, np.ndarray], scale_xyz: np.ndarray, yaw_rad: np.ndarray, origin_xyz: np.ndarray,
        reflectivity: float, vertex_scale: np.ndarray | None = None, label: str = "unlabeled",
    ) -> None:
        """Add M instances: ``scale_xyz`` (M, 3), ``yaw_rad`` (M,), ``origin_xyz`` (M, 3); ``vertex_scale``
        (M, V, 1) optionally scales each unit vertex (irregular shapes such as tree crowns)."""
        unit_verts, unit_faces = prim
        m = len(origin_xyz)
        if m == 0:
            return
        c, s = np.cos(yaw_rad), np.sin(yaw_rad)
        local = unit_verts[None, :, :] * scale_xyz[:, None, :]
        if vertex_scale is not None:
            local = local * vertex_scale
        world = np.empty_like(local)
        world[..., 0] = c[:, None] * local[..., 0] - s[:, None] * local[..., 1]
        world[..., 1] = s[:, None] * local[..., 0] + c[:, None] * local[..., 1]
        world[..., 2] = local[..., 2]
        world += origin_xyz[:, None, :]
        offsets = self._n_verts + len(unit_verts) * np.arange(m)
        self._verts.append(world.reshape(-1, 3))
        self._faces.append((unit_faces[None, :, :] + offsets[:, None, None]).reshape(-1, 3))
        self._reflectivity.append(np.full(m * len(unit_faces), reflectivity))
        self._labels.append(np.full(m * len(unit_faces), LABELS[label], dtype=np.uint8))
        self._n_verts += m * len(unit_verts)

    def add_mesh(self, verts: np.ndarray, faces: np.ndarray, reflectivity: float, label: str) -> None:
        """Add one mesh given in world coordinates."""
        self._verts.append(verts)
        self._faces.append(faces + self._n_verts)
        self._reflectivity.append(np.full(len(faces), reflectivity))
        self._labels.append(np.full(len(faces), LABELS[label], dtype=np.uint8))
        self._n_verts += len(verts)

    def build(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        return np.concatenate(self._verts), np.concatenate(self._faces), np.concatenate(self._reflectivity), np.concatenate(self._labels)


def _place_along(path: PlanarPath, s_m: np.ndarray, lateral_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World xy ``(M, 2)`` and path heading ``(M,)`` of points at arc length ``s_m``, ``lateral_m`` left of the path."""
    xy, heading = path.at(s_m)
    normal = np.stack([-np.sin(heading), np.cos(heading)], axis=1)
    return xy + lateral_m[:, None] * normal, heading


def _add_trees(
    builder: _SceneBuilder, xy: np.ndarray, ground_z: float | np.ndarray, crown_r: np.ndarray, yaw: np.ndarray, vertex_scale: np.ndarray,
    sink_m: float = 0.0,
) -> None:
    """Trunks (3 m prisms, ``sink_m`` more below ground) with irregular crowns of radius ``crown_r`` (M,) on top."""
    base = np.broadcast_to(np.asarray(ground_z, dtype=np.float64), (len(xy),))
    builder.add(_PRISM, np.tile([0.2, 0.2, 3.0 + sink_m], (len(xy), 1)), np.zeros(len(xy)), np.c_[xy, base - sink_m], 0.4, label="trunk")
    top = np.c_[xy, base + 3.0 + 1.1 * crown_r]
    builder.add(_CROWN, np.c_[crown_r, crown_r, 1.3 * crown_r], yaw, top, 0.3, vertex_scale=vertex_scale, label="vegetation")


def build_scene_mesh(config: LidarSimConfig, path: PlanarPath) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Vertices ``(V, 3)``, triangles ``(F, 3)`` and per-triangle reflectivity ``(F,)`` of the scene (world frame).

    Every object class draws from its own seeded stream, object by object along the path, so a longer
    sequence contains the scene of a shorter one with the same seed.
    """
    return build_labeled_scene_mesh(config, path, scene_terrain(config))[:3]


def scene_terrain(config: LidarSimConfig) -> Terrain:
    """The seeded terrain of a config (flat when ``terrain_amplitude_m`` is 0)."""
    return make_terrain(np.random.default_rng([config.seed, 3]), config.terrain_amplitude_m, config.terrain_wavelength_m)


def build_labeled_scene_mesh(
    config: LidarSimConfig, path: PlanarPath, terrain: Terrain
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`build_scene_mesh` plus the per-triangle label ``(F,)`` uint8 (codes of ``LABEL_NAMES``).

    Objects stand on the terrain: each base is sunk by ``max_slope x footprint radius`` (and made that much
    taller) so that no edge floats above a slope.
    """
    ground_z = -config.sensor_height_m
    slope = terrain.max_slope
    s0, s1 = float(path.s_m[0]), float(path.s_m[-1])
    builder = _SceneBuilder()
    # ground: one large quad covering the path plus the sensor range (extent rounded to 500 m)
    lo = np.floor((path.xy_m.min(axis=0) - config.max_range_m - 20.0) / 500.0) * 500.0
    hi = np.ceil((path.xy_m.max(axis=0) + config.max_range_m + 20.0) / 500.0) * 500.0
    if terrain.amplitude_m == 0.0:
        centre = np.r_[(lo + hi) / 2.0, ground_z - 1.0]
        builder.add((_BOX_CORNERS, _BOX_FACES), np.array([[hi[0] - lo[0], hi[1] - lo[1], 1.0]]), np.zeros(1), centre[None], 0.25, label="ground")
    else:
        spacing = min(2.0, config.terrain_wavelength_m / 25.0)
        from lidarkit.resources import check_memory

        # the grid covers the path's bounding box: ~300 B a vertex with its triangles, the scene's copies and the ray
        # caster's (3000 frames of 10 m hills, 37.5 M vertices, peaked at 11.5 GB; 100 km was a MemoryError traceback)
        n_vertices = float(np.prod(np.ceil((hi - lo) / spacing) + 2))
        check_memory(300.0 * n_vertices, f"the hills' ground mesh ({n_vertices:.3g} vertices every {spacing:g} m over "
                     f"{(hi[0] - lo[0]) / 1e3:g} x {(hi[1] - lo[1]) / 1e3:g} km around the path)",
                     "terrain_amplitude_m / terrain_wavelength_m / n_frames")
        builder.add_mesh(*_heightfield(terrain, lo, hi, ground_z, spacing), 0.25, label="ground")

    def stream(k: int) -> np.random.Generator:
        return np.random.default_rng([config.seed, 100 + k])

    def objects_along(k: int, spacing_m: float, lateral_lo: float, lateral_hi: float, jitter_m: float, n_extra: int = 0):
        """Objects every ``spacing_m`` (jittered) on a random side: world xy (M, 2), heading (M,), extra uniforms (M, n_extra)."""
        s = np.arange(s0 + 5.0, s1 - 5.0, spacing_m)
        u = stream(k).uniform(size=(len(s), 3 + n_extra))  # one row per object: prefix-stable
        s = s + jitter_m * (2.0 * u[:, 0] - 1.0)
        side = np.where(u[:, 1] < 0.5, -1.0, 1.0)
        lateral = side * (lateral_lo + (lateral_hi - lateral_lo) * u[:, 2])
        xy, heading = _place_along(path, s, lateral)
        return xy, heading, u[:, 3:]

    def ground_origin(xy: np.ndarray, sink_m: float = 0.0) -> np.ndarray:
        return np.c_[xy, ground_z + terrain.height(xy) - sink_m]

    n_crown = len(_CROWN[0])
    if config.scene == "street":
        # buildings: a row on each side, facades 9..13 m from the path, gaps between them, a cross street every
        # 90..130 m; pilasters/bays on the facades give the along-street structure real facades have
        for k, side in enumerate((-1.0, 1.0)):
            rng = stream(k)
            s = s0
            next_cross = s0 + rng.uniform(40.0, 130.0)
            while s < s1:
                if s > next_cross:
                    s += rng.uniform(14.0, 20.0)
                    next_cross = s + rng.uniform(90.0, 130.0)
                length, depth, height, setback, gap, bay_height = rng.uniform([8, 8, 6, 9, 2, 0.3], [28, 16, 20, 13, 9, 1.0])
                xy, heading = _place_along(path, np.array([s + length / 2.0]), np.array([side * (setback + depth / 2.0)]))
                sink = slope * 0.5 * float(np.hypot(length, depth))
                builder.add((_BOX_CORNERS, _BOX_FACES), np.array([[length, depth, height + sink]]), heading, ground_origin(xy, sink), 0.5, label="building")
                bay = rng.uniform([2.5, 0.3, 0.4], [6.0, 0.9, 1.2], size=(int(length / 2.5) + 1, 3))  # spacing, protrusion, width
                at = s + np.cumsum(bay[:, 0])
                bay = bay[at < s + length - 0.5]
                at = at[at < s + length - 0.5]
                xy, heading = _place_along(path, at, side * (setback - bay[:, 1] / 2.0))
                sink = slope * 0.8
                builder.add(
                    (_BOX_CORNERS, _BOX_FACES), np.c_[bay[:, 2], bay[:, 1], np.full(len(at), height * bay_height + sink)], heading,
                    ground_origin(xy, sink), 0.55, label="building",
                )
                s += length + gap
        xy, _, u = objects_along(2, 12.0, 5.5, 7.0, 3.0, 1)  # poles and signs
        sink = slope * 0.15
        builder.add(
            _PRISM, np.c_[np.full(len(xy), 0.15), np.full(len(xy), 0.15), 2.5 + 4.5 * u[:, 0] + sink], np.zeros(len(xy)), ground_origin(xy, sink), 0.7,
            label="pole",
        )
        xy, _, u = objects_along(3, 15.0, 5.0, 7.5, 5.0, 2 + n_crown)  # trees: trunk + irregular crown
        _add_trees(builder, xy, ground_z + terrain.height(xy), 1.2 + 1.0 * u[:, 0], np.pi * u[:, 1], 0.6 + 0.7 * u[:, 2:, None], slope * 0.2)
        xy, heading, _ = objects_along(4, 13.0, 4.2, 5.0, 4.0)  # parked cars
        sink = slope * 2.4
        builder.add((_BOX_CORNERS, _BOX_FACES), np.tile([4.4, 1.8, 1.5 + sink], (len(xy), 1)), heading, ground_origin(xy, sink), 0.6, label="car")
    elif config.scene == "open":
        # ground dominates: a few sparse objects 8..40 m from the path (or open_object_lateral_m)
        near = config.open_object_lateral_m
        lat = ((8.0, 40.0), (10.0, 40.0), (8.0, 35.0)) if near is None else (near, near, near)
        xy, _, _ = objects_along(5, 25.0, *lat[0], 10.0)
        sink = slope * 0.2
        builder.add(_PRISM, np.tile([0.2, 0.2, 6.0 + sink], (len(xy), 1)), np.zeros(len(xy)), ground_origin(xy, sink), 0.7, label="pole")
        xy, heading, u = objects_along(6, 35.0, *lat[1], 15.0, 4)
        sink = slope * np.hypot(2 + 4 * u[:, 0], 2 + 4 * u[:, 1]) / 2.0
        builder.add(
            (_BOX_CORNERS, _BOX_FACES), np.c_[2 + 4 * u[:, 0], 2 + 4 * u[:, 1], 1.5 + 2.5 * u[:, 2] + sink], heading + np.pi * u[:, 3],
            ground_origin(xy) - np.c_[np.zeros((len(xy), 2)), sink], 0.5, label="building",
        )
        xy, _, u = objects_along(7, 40.0, *lat[2], 15.0, 2 + n_crown)
        _add_trees(builder, xy, ground_z + terrain.height(xy), 1.5 + 1.5 * u[:, 0], np.pi * u[:, 1], 0.6 + 0.7 * u[:, 2:, None], slope * 0.2)
    return builder.build()


# ---------------------------------------------------------------------------------------------------------------
# The sequence
# ---------------------------------------------------------------------------------------------------------------
class SimulatedLidarSequence:
    """A :class:`~lidarkit.io.base.ScanSequence` of simulated sweeps, deterministic per config (seed included).

    ``read_scan(i)`` casts all rays of sweep ``i`` in one ``RaycastingScene.cast_rays`` call. See the module
    docstring for frames and the instant ``ground_truth`` refers to.
    """

    def __init__(self, config: LidarSimConfig | None = None, **params: object):
        if config is not None and params:
            raise ConfigError("pass either a LidarSimConfig or keyword parameters, not both", source="lidar simulator")
        if config is not None:
            check_argument(config, LidarSimConfig, "config", "a LidarSimConfig (or keyword parameters)")
        self.config = config if config is not None else make_config(**params)
        cfg = self.config
        from lidarkit.resources import check_memory

        # per sweep: the ray directions and hits (float64) and the exported records, a few copies each (a sim: spec
        # or a library call asking for 1e10 rays was a 74 GiB MemoryError traceback)
        check_memory(cfg.n_beams * cfg.n_azimuths * SWEEP_BYTES_PER_RAY, f"a sweep of {cfg.n_beams}x{cfg.n_azimuths} rays", "n_beams / n_azimuths")
        self.name = f"sim:{cfg.scene}?seed={cfg.seed}"
        period = cfg.sweep_period_s
        s_end = cfg.speed_mps * period * (cfg.n_frames + 1) + cfg.max_range_m + 40.0
        self.path = make_path(np.random.default_rng([cfg.seed, 0]), -(cfg.max_range_m + 40.0), s_end, cfg.max_curvature_per_m)
        self.terrain = scene_terrain(cfg)
        self.vertices_xyz, self.triangles, self.reflectivity, self.triangle_labels = build_labeled_scene_mesh(cfg, self.path, self.terrain)
        sway = np.random.default_rng([cfg.seed, 2]).uniform(size=(3, 2))  # frequencies and phases of pitch, roll, heave
        self._sway_freq_hz = 0.4 + 0.8 * sway[:, 0]
        self._sway_phase = 2.0 * np.pi * sway[:, 1]
        self._scene = None
        # sensor ray directions in the sensor frame, column-major: (n_azimuths, n_beams, 3)
        elevation = np.deg2rad(np.linspace(cfg.elevation_max_deg, cfg.elevation_min_deg, cfg.n_beams))
        self.elevation_rad = elevation
        self.azimuth_rad = np.pi - 2.0 * np.pi * np.arange(cfg.n_azimuths) / cfg.n_azimuths
        ce, se = np.cos(elevation), np.sin(elevation)
        ca, sa = np.cos(self.azimuth_rad), np.sin(self.azimuth_rad)
        self.directions_sensor = np.stack(
            [ca[:, None] * ce[None, :], sa[:, None] * ce[None, :], np.broadcast_to(se[None, :], (cfg.n_azimuths, cfg.n_beams))], axis=-1
        )
        self.column_times_s = np.arange(cfg.n_azimuths) * (period / cfg.n_azimuths)
        reach_m = float(self.distance_at(np.array([cfg.n_frames * period]))[0])
        if reach_m > FLOAT32_EXACT_REACH_M:  # (the error grew unsaid: 2.5 mm median at 98 km, as large as the ICP errors measured)
            log.warning("%s: the drive reaches %.0f km from its start; the scene and rays are cast in float32 world coordinates, "
                        "so the points of sweeps beyond %.0f km lie more than ~0.3 mm (median; 1.3 mm at the 99th percentile) off "
                        "the exact surfaces, growing with the distance (2.5 mm median at 98 km)", self.name, reach_m / 1000,
                        FLOAT32_EXACT_REACH_M / 1000)

    # ---- geometry of the drive ------------------------------------------------------------------
    @property
    def scene(self):
        """The Open3D RaycastingScene (built on first use)."""
        if self._scene is None:
            import open3d as o3d

            scene = o3d.t.geometry.RaycastingScene()
            scene.add_triangles(
                o3d.core.Tensor(self.vertices_xyz.astype(np.float32)), o3d.core.Tensor(self.triangles.astype(np.uint32))
            )
            self._scene = scene
        return self._scene

    def distance_at(self, times_s: np.ndarray) -> np.ndarray:
        """Arc length (m) driven at absolute times ``times_s``: a smoothstep speed ramp from rest over
        ``accel_time_s`` (speed ``v (3u^2 - 2u^3)``, ``u = t / accel_time_s``), then constant ``speed_mps``."""
        t = np.asarray(times_s, dtype=np.float64)
        v, ramp = self.config.speed_mps, self.config.accel_time_s
        if ramp <= 0.0:
            return v * t
        u = np.clip(t / ramp, 0.0, 1.0)
        return np.where(t < ramp, v * ramp * (u**3 - 0.5 * u**4), v * ramp * 0.5 + v * (t - ramp))

    def poses_at(self, times_s: np.ndarray) -> np.ndarray:
        """``(M, 4, 4)`` poses ``T_world_lidar`` at absolute times ``times_s`` (M,) (t = 0: start of sweep 0); DataError
        naming ``times_s`` for times that are not a 1-D array of finite numbers (NaN gave NaN poses, unsaid)."""
        t = checked_times(times_s)
        xy, heading = self.path.at(self.distance_at(t))
        cfg = self.config
        # suspension: pitch, roll and heave oscillate (0.4..1.2 Hz, seeded) around the planar drive
        wave = np.sin(2.0 * np.pi * self._sway_freq_hz[:, None] * t[None, :] + self._sway_phase[:, None])
        wave -= np.sin(self._sway_phase)[:, None]  # zero at t = 0: the world origin is the sensor at the start
        pitch, roll = np.deg2rad(cfg.sway_deg) * wave[0], np.deg2rad(cfg.sway_deg) * wave[1]
        lift = np.zeros(len(t))
        if self.terrain.amplitude_m > 0.0:
            # on hills the body follows the ground: height, and pitch / roll from the slope along / across the heading
            grad = self.terrain.gradient(xy)
            forward = grad[:, 0] * np.cos(heading) + grad[:, 1] * np.sin(heading)
            left = -grad[:, 0] * np.sin(heading) + grad[:, 1] * np.cos(heading)
            pitch = pitch - np.arctan(forward)
            roll = roll + np.arctan(left)
            lift = self.terrain.height(xy)
        cy, sy, cp, sp, cr, sr = np.cos(heading), np.sin(heading), np.cos(pitch), np.sin(pitch), np.cos(roll), np.sin(roll)
        T = np.zeros((len(t), 4, 4))
        # R = Rz(heading) Ry(pitch) Rx(roll)
        T[:, 0, 0], T[:, 0, 1], T[:, 0, 2] = cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr
        T[:, 1, 0], T[:, 1, 1], T[:, 1, 2] = sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr
        T[:, 2, 0], T[:, 2, 1], T[:, 2, 2] = -sp, cp * sr, cp * cr
        T[:, 3, 3] = 1.0
        T[:, :2, 3] = xy
        T[:, 2, 3] = cfg.heave_m * wave[2] + lift
        return T

    def frame_times_s(self, instant: PoseInstant | None = None) -> np.ndarray:
        """``(n_frames,)`` absolute time of ``instant`` (default: ``pose_instant``) in every sweep."""
        instant = self._instant(instant)
        return (np.arange(self.config.n_frames) + _INSTANT_FRACTION[instant]) * self.config.sweep_period_s

    def ground_truth_at(self, instant: PoseInstant | None = None) -> Trajectory:
        """Ground truth ``T_world_lidar`` at ``instant`` of every sweep, with matching timestamps."""
        instant = self._instant(instant)
        times = self.frame_times_s(instant)
        return Trajectory(self.poses_at(times), times, name=f"{self.name} ground truth ({instant})", meta={"pose_instant": instant})

    def ground_truth_at_instant(self, instant: PoseInstant) -> Trajectory:
        """:meth:`ground_truth_at` under the name every reader that can re-time its ground truth offers
        (:class:`lidarkit.io.base.ScanSequence`)."""
        return self.ground_truth_at(instant)

    @property
    def ground_truth(self) -> Trajectory:
        return self.ground_truth_at(self.config.pose_instant)

    @property
    def timestamps_s(self) -> np.ndarray:
        return self.frame_times_s(self.config.pose_instant)

    @property
    def snapshot_sweeps(self) -> bool:
        """True when every sweep is cast at one instant (``motion_distortion=False``): there is nothing to deskew."""
        return not self.config.motion_distortion

    def _instant(self, instant: str | None) -> str:
        instant = self.config.pose_instant if instant is None else instant
        if instant not in POSE_INSTANTS:
            raise ConfigError(f"unknown pose instant {instant!r}; valid: {', '.join(POSE_INSTANTS)}", source="lidar simulator")
        return instant

    # ---- ScanSequence ---------------------------------------------------------------------------
    def __len__(self) -> int:
        return self.config.n_frames

    def __repr__(self) -> str:
        c = self.config
        return f"SimulatedLidarSequence({self.name!r}, {c.n_frames} sweeps of {c.n_beams}x{c.n_azimuths} rays)"

    def read_scan(self, index: int) -> Scan:
        """Cast sweep ``index`` (negative: from the end); points ``(N, 3)`` float64 in the sensor frame, ordered by
        firing time (exports round them to float32)."""
        return self._cast(index)[0]

    def read_scan_labels(self, index: int) -> tuple[Scan, np.ndarray]:
        """Sweep ``index`` and the ``(N,)`` uint8 label of each point: the class of the triangle its ray hit
        (codes of ``LABEL_NAMES``; ``GROUND_LABEL`` is the ground)."""
        scan, hit = self._cast(index)
        return scan, self.triangle_labels[hit]

    def _cast(self, index: int) -> tuple[Scan, np.ndarray]:
        """The scan of sweep ``index`` and the scene triangle index ``(N,)`` of each point."""
        cfg = self.config
        index = checked_index(index, cfg.n_frames, self.name, "frame")  # (-1 is the last sweep, as the file readers count)
        n_az, n_beams = cfg.n_azimuths, cfg.n_beams
        sweep_start = index * cfg.sweep_period_s
        if cfg.motion_distortion:
            poses = self.poses_at(sweep_start + self.column_times_s)  # (n_az, 4, 4): one pose per column
        else:
            pose = self.poses_at(np.array([self.frame_times_s()[index]]))
            poses = np.broadcast_to(pose, (n_az, 4, 4))
        dirs_world = np.einsum("aij,abj->abi", poses[:, :3, :3], self.directions_sensor)
        origins = np.broadcast_to(poses[:, None, :3, 3], (n_az, n_beams, 3))
        rays = np.concatenate([origins, dirs_world], axis=-1).reshape(-1, 6).astype(np.float32)
        import open3d as o3d

        hits = self.scene.cast_rays(o3d.core.Tensor(rays))
        range_m = hits["t_hit"].numpy().astype(np.float64)
        if cfg.range_noise_std_m > 0.0:
            noise_rng = np.random.default_rng([cfg.seed, 1, index])
            range_m = range_m + noise_rng.normal(0.0, cfg.range_noise_std_m, size=range_m.shape)
        keep = np.isfinite(range_m) & (range_m >= cfg.min_range_m) & (range_m <= cfg.max_range_m)
        if not keep.any():  # (exported as 0-byte scans that lidarkit's own readers then refused)
            # (said of sweep 54 of 300 as if the sensor never saw anything: the others had returns)
            raise DataError(
                f"sweep {index} has no return within {cfg.min_range_m:g}-{cfg.max_range_m:g} m: from where it is taken the "
                f"beams ({cfg.elevation_min_deg:g} to {cfg.elevation_max_deg:g} deg, the sensor {cfg.sensor_height_m:g} m up) "
                f"see nothing of the {cfg.scene} scene, and an empty sweep is no scan (raise max_range_m or widen the beams)",
                source=self.name,
                location=f"frame {index}",  # (the odometry runner passes an error placed at its frame through as it is)
            )
        dirs = self.directions_sensor.reshape(-1, 3)[keep]
        points = dirs * range_m[keep, None]
        # intensity: reflectivity of the hit triangle times the cosine of the incidence angle
        normals = hits["primitive_normals"].numpy()[keep].astype(np.float64)
        cos_inc = np.abs(np.einsum("ij,ij->i", normals, dirs_world.reshape(-1, 3)[keep]))
        hit = hits["primitive_ids"].numpy()[keep].astype(np.int64)
        intensity = (self.reflectivity[hit] * cos_inc).astype(np.float32)
        # a snapshot (no motion distortion) has no time spread to deskew: its column times would add one
        times = np.repeat(self.column_times_s, n_beams)[keep] if cfg.sweeps_carry_point_times else None
        scan = Scan(
            points_xyz=points,
            intensity=intensity,
            point_times_s=times,
            timestamp_s=float(self.timestamps_s[index]),
            frame=index,
            source=f"{self.name} frame {index}",
            stamp_instant=cfg.pose_instant,
        )
        return scan, hit


def open_sim(spec: str) -> SimulatedLidarSequence:
    """Sequence from a spec string ``sim:SCENE[?key=value&...]``, e.g. ``sim:street?frames=300&seed=0``.

    Keys are :class:`LidarSimConfig` fields; short aliases: ``frames`` (n_frames), ``beams`` (n_beams),
    ``azimuths`` (n_azimuths), ``noise`` (range_noise_std_m), ``distortion`` (motion_distortion),
    ``instant`` (pose_instant), ``speed`` (speed_mps).
    """
    from lidarkit.params import parse_kv

    check_argument(spec, str, "spec", "a 'sim:SCENE?key=value' string")
    if not spec.startswith("sim:"):
        raise ConfigError("a simulator spec starts with 'sim:'", source=spec)
    body = spec[len("sim:") :]
    scene, _, query = body.partition("?")
    params: dict[str, object] = {"scene": scene or "street"}
    aliases = {
        "frames": "n_frames",
        "beams": "n_beams",
        "azimuths": "n_azimuths",
        "noise": "range_noise_std_m",
        "distortion": "motion_distortion",
        "instant": "pose_instant",
        "speed": "speed_mps",
    }
    given_as: dict[str, str] = {"scene": f"sim:{params['scene']}"}
    for key, value in parse_kv(query, option="simulator option").items():
        name = aliases.get(key, key)
        if name not in LidarSimConfig.model_fields:  # (the config's list left out the short keys the help gives)
            raise ConfigError(f"unknown key {key!r}; short keys: {', '.join(f'{a} ({f})' for a, f in aliases.items())}; or any of: "
                              f"{', '.join(LidarSimConfig.model_fields)}", source=spec)
        if name in params:  # (it named the second spelling only: "n_frames is given twice (as n_frames)")
            raise ConfigError(f"{name} is given twice (as {given_as[name]} and {key})", source=spec)
        params[name] = value
        given_as[name] = key
    try:
        return SimulatedLidarSequence(**params)
    except ConfigError as err:
        raise ConfigError(err.reason, source=spec) from None


def export_kitti(
    sequence: SimulatedLidarSequence,
    out_dir: str | os.PathLike,
    on_frame: Callable[[int], None] | None = None,
) -> Path:
    """Write the sequence as a KITTI-style folder and return it.

    ``velodyne/NNNNNN.bin`` (float32 x, y, z, intensity: :meth:`~SimulatedLidarSequence.read_scan`'s float64 points
    rounded, as in the bags, so odometry over the folder differs slightly from odometry over the sequence itself),
    ``point_times/NNNNNN.npy`` (float32 per-point time from the sweep start, s), ``times.txt`` (stamps at
    ``pose_instant``), ``poses.txt`` (KITTI format, LiDAR frame, at ``pose_instant``), ``poses_start.txt`` /
    ``poses_mid.txt`` / ``poses_end.txt``, ``calib.txt`` (``Tr`` = identity: poses are already in the LiDAR frame) and
    ``sim.yaml`` (the resolved config).

    All or nothing: the folder appears complete or not at all (an interrupted export leaves nothing that reads as a
    sequence), and a folder that already holds files is refused (sweeps of two exports are never mixed), as is a
    symbolic link to a missing folder (never created where it points).
    """
    from lidarkit import atomic

    check_argument(sequence, SimulatedLidarSequence, "sequence")
    check_argument(out_dir, (str, os.PathLike), "out_dir", "a path")
    out = Path(out_dir)
    with atomic.export_folder(out, "sweeps") as tmp:
        _write_kitti(sequence, tmp, on_frame)
    return out


def _write_kitti(sequence: SimulatedLidarSequence, out: Path, on_frame: Callable[[int], None] | None) -> None:
    import yaml

    from lidarkit import atomic

    atomic.ensure_dir(out / "velodyne")
    if sequence.config.sweeps_carry_point_times:  # (a snapshot has none: an empty folder warned)
        atomic.ensure_dir(out / "point_times")
    for i in range(len(sequence)):
        scan = sequence.read_scan(i)
        data = np.empty((len(scan.points_xyz), 4), dtype=np.float32)
        data[:, :3] = scan.points_xyz
        data[:, 3] = scan.intensity
        atomic.write_bytes(out / "velodyne" / f"{i:06d}.bin", data.tobytes())
        if scan.point_times_s is not None:
            with atomic.atomic_path(out / "point_times" / f"{i:06d}.npy") as tmp:
                np.save(tmp, scan.point_times_s.astype(np.float32))
        if on_frame is not None:
            on_frame(i)
    # 17 significant digits: read back as the very stamps (7 left 3000 frames at 7 Hz up to 4.3e-5 s off)
    atomic.write_text(out / "times.txt", "".join(f"{t:.16e}\n" for t in sequence.timestamps_s))
    sequence.ground_truth.to_kitti(out / "poses.txt")
    for instant in POSE_INSTANTS:
        sequence.ground_truth_at(instant).to_kitti(out / f"poses_{instant}.txt")
    identity = " ".join(f"{v:.12e}" for v in np.eye(4)[:3].ravel())
    p0 = " ".join(f"{v:.12e}" for v in np.array([[500.0, 0, 500.0, 0], [0, 500.0, 200.0, 0], [0, 0, 1.0, 0]]).ravel())
    atomic.write_text(out / "calib.txt", "".join(f"P{k}: {p0}\n" for k in range(4)) + f"Tr: {identity}\n")
    cfg = sequence.config.model_dump()
    cfg["note"] = "poses are T_world_lidar at pose_instant of each sweep; point_times are seconds from the sweep start"
    atomic.write_text(out / "sim.yaml", yaml.safe_dump(cfg, sort_keys=False))


__all__ = [
    "GROUND_LABEL",
    "LABELS",
    "LABEL_NAMES",
    "POSE_INSTANTS",
    "SCENES",
    "Terrain",
    "build_labeled_scene_mesh",
    "make_terrain",
    "scene_terrain",
    "LidarSimConfig",
    "MAX_TERRAIN_SLOPE",
    "PlanarPath",
    "SimulatedLidarSequence",
    "build_scene_mesh",
    "check_argument",
    "check_terrain_slope",
    "checked_config",
    "export_kitti",
    "make_config",
    "make_path",
    "number_not_yes_or_no",
    "open_sim",
]
