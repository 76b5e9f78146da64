"""Simulated monocular camera driving through a textured 3D street canyon, ray cast with Open3D (exact ground truth).

Scene (world frame: x/y horizontal, z up): a road strip along a planar path with 90-degree street corners and
gentle curves, ground tiles on rolling terrain (slopes), building blocks on both sides with gaps and open
intersections at the corners, poles, parked cars (boxes) and optional trees (trunk + irregular crown). Every
planar face is a *surface* with its own seeded texture of natural-image statistics (:mod:`lidarkit.sim.textures`)
mapped by per-vertex UV coordinates in metres; textures are generated when a surface is first seen.

Rendering: one ``RaycastingScene.cast_rays`` call per frame gives each pixel's triangle id and barycentric
coordinates, hence its exact texel; a mip level chosen from the pixel's footprint (distance and incidence) avoids
aliasing. Rays that hit nothing see the sky. Lambert shading per surface under a fixed sun.

Camera: KITTI's image size and intrinsics by default; camera frame x right, y down, z forward. Ground truth
``T_cam0_camk`` (KITTI poses convention: the first pose is the identity) at the frame time ``k / frame_rate_hz``.
The drive: cruise speeds drawn between ``speed_min_mps`` and ``speed_max_mps``, seeded stops, slowing down through
corners, smooth acceleration; the body follows the terrain (pitch/roll from its slope) and sways gently.

Nuisances (off by default, none changes the poses): sensor noise, motion blur (average of renders over the
exposure), per-frame gain changes, vignetting, a passing occluder (a textured panel crossing the image).

Everything is deterministic for a config (seed included).
"""

from __future__ import annotations

import logging
import math
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationInfo, field_validator, model_validator

from lidarkit.errors import ConfigError, DataError
from lidarkit.io.base import checked_index
from lidarkit.params import changed_fields
from lidarkit.sim.lidar import (PlanarPath, Terrain, check_argument, check_terrain_slope, checked_config, checked_times,
                                make_terrain, number_not_yes_or_no)
from lidarkit.sim.textures import TextureAtlas, mip_levels, natural_texture
from lidarkit.trajectory import Trajectory

log = logging.getLogger(__name__)

#: KITTI odometry (sequences 00-02) grey camera: image size and intrinsics.
KITTI_SIZE_WH = (1241, 376)
KITTI_K = np.array([[718.856, 0.0, 607.1928], [0.0, 718.856, 185.2157], [0.0, 0.0, 1.0]])

N_MIP_LEVELS = 6
_ROAD_HALF_M = 5.5  # two lanes and a parking lane each side
_ROAD_LIFT_M = 0.12  # road surface above the ground tiles (keeps it above their chords on hills)
_CROSSING_CLEAR_M = 19.0  # buildings start this far (along their street) from a crossing's centre
_SETBACK_M = (8.5, 10.0)  # building fronts this far from the street's centre line
_DEPTH_M = (6.0, 8.0)  # building depth: setback + depth < _CROSSING_CLEAR_M keeps the four corner blocks apart
_SUN = np.array([0.45, -0.35, 0.82]) / np.linalg.norm([0.45, -0.35, 0.82])
# body frame (x forward, y left, z up) -> camera frame (x right, y down, z forward): columns are the camera axes
_R_BODY_CAM = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


#: the longest drive a camera sequence may reach (m): its street is built before the first image
MAX_CAMERA_DRIVE_M = 50_000.0
#: the most a stretch's gentle curve may turn the heading away from the street's direction (deg): more bent a
#: stretch back on itself (curvature 0.05 per m over 360 m: up to 330 deg), the street through its own buildings
MAX_CURVE_TURN_DEG = 45.0


class CameraSimConfig(BaseModel):
    """Everything that defines a simulated camera sequence; equal configs give identical images and poses."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    scene: Literal["street"] = "street"
    n_frames: int = Field(500, ge=2, le=100_000, description="number of images (100000 at most: the drive is built "
                          "before the first image, ~1 min at that length)")
    seed: int = Field(0, ge=0, description="seeds the scene, its textures, the drive and the nuisances")
    # camera
    width: int = Field(KITTI_SIZE_WH[0], ge=16, le=8192)
    height: int = Field(KITTI_SIZE_WH[1], ge=16, le=8192)
    fx: float = Field(float(KITTI_K[0, 0]), gt=0.0)
    fy: float = Field(float(KITTI_K[1, 1]), gt=0.0)
    cx: float | None = Field(float(KITTI_K[0, 2]), description="principal point x (None: image centre)")
    cy: float | None = Field(float(KITTI_K[1, 2]), description="principal point y (None: image centre)")
    camera_height_m: float = Field(1.65, gt=0.2, le=10.0)
    frame_rate_hz: float = Field(10.0, gt=0.0, le=1000.0)
    # drive
    speed_min_mps: float = Field(4.0, ge=0.0, le=60.0, description="lowest cruise speed drawn")
    speed_max_mps: float = Field(15.0, ge=0.0, le=60.0, description="highest cruise speed drawn")
    stop_probability: float = Field(0.15, ge=0.0, le=1.0, description="chance that a speed change is a stop")
    accel_mps2: float = Field(1.5, gt=0.0, le=10.0)
    corner_speed_mps: float = Field(5.0, gt=0.0, le=30.0, description="speed limit through a street corner")
    corners: bool = Field(True, description="90-degree street corners between straight stretches")
    corner_spacing_m: tuple[float, float] = Field((120.0, 280.0), description="stretch length between corners")
    first_corner_m: float | None = Field(None, ge=10.0, le=1000.0,
                                         description="arc length to the first corner (None: drawn like the others)")
    curve_curvature_per_m: float = Field(1.0 / 500.0, ge=0.0, le=0.05, description="gentle curves within stretches")
    terrain_amplitude_m: float = Field(2.0, ge=0.0, le=20.0, description="rolling hills (slopes); 0: flat")
    terrain_wavelength_m: float = Field(250.0, ge=50.0)
    sway_deg: float = Field(0.2, ge=0.0, le=5.0, description="pitch and roll oscillation of the body")
    trees: bool = Field(False, description="trees (trunk + irregular crown) on the sidewalks")
    texel_scale: float = Field(1.0, ge=0.5, le=8.0, description="texel sizes times this (coarser: less memory; below 0.5 "
                               "a frame's textures overflowed the atlas, minutes into an export)")
    threads: int = Field(0, ge=0, description="ray casting threads (0: Open3D decides)")
    # nuisances
    noise_std: float = Field(0.0, ge=0.0, le=100.0, description="Gaussian sensor noise, grey levels")
    motion_blur_s: float = Field(0.0, ge=0.0, le=1.0, description="exposure time; > 0 averages renders over it")
    blur_samples: int = Field(4, ge=2, le=32)
    gain_std: float = Field(0.0, ge=0.0, le=1.0, description="std of the log gain between frames (exposure)")
    vignetting: float = Field(0.0, ge=0.0, le=0.95, description="brightness loss at the image corners")
    occluder: bool = Field(False, description="a textured panel crosses the image")
    occluder_start: int | None = Field(None, ge=0, description="first occluded frame (None: the middle)")
    occluder_frames: int = Field(15, ge=1, description="frames the occluder takes to cross")

    @field_validator("*", mode="before")
    @classmethod
    def _numbers_are_not_yes_or_no(cls, value: object, info: ValidationInfo) -> object:
        return number_not_yes_or_no(cls, value, info)

    @model_validator(mode="after")
    def _check(self) -> CameraSimConfig:
        if self.speed_min_mps > self.speed_max_mps:
            raise ValueError("speed_min_mps must not exceed speed_max_mps")
        if not 20.0 <= self.corner_spacing_m[0] <= self.corner_spacing_m[1]:
            raise ValueError("corner_spacing_m must be (min, max) with 20 <= min <= max")
        if self.speed_max_mps <= 0.0:
            raise ValueError("speed_max_mps must be > 0 (the camera must move)")
        check_terrain_slope(self.terrain_amplitude_m, self.terrain_wavelength_m)
        longest = self.speed_max_mps * (self.n_frames - 1) / self.frame_rate_hz
        if longest > MAX_CAMERA_DRIVE_M:  # (100 frames at 0.05 Hz built a 13 km street first, a billion frames 112 GiB)
            raise ValueError(f"the drive may reach {longest / 1000:.4g} km (speed_max_mps x n_frames / frame_rate_hz); at most "
                             f"{MAX_CAMERA_DRIVE_M / 1000:g} km: fewer frames, a higher frame rate or a lower speed")
        placed = changed_fields(self, ("occluder_start", "occluder_frames"))
        if not self.occluder and placed:  # (accepted and ignored); defaults pass: sim.yaml writes them back
            raise ValueError("occluder_start / occluder_frames place the occluder, and occluder=false draws none")
        if self.occluder and self.occluder_start is not None and self.occluder_start >= self.n_frames:
            raise ValueError(f"occluder_start {self.occluder_start} is beyond the {self.n_frames} frames: no frame is occluded")
        if not self.corners and self.first_corner_m is not None:
            raise ValueError("first_corner_m places the first corner, and corners=false draws none")
        if self.motion_blur_s == 0.0 and changed_fields(self, ("blur_samples",)):  # (accepted and ignored)
            raise ValueError("blur_samples samples the exposure of motion_blur_s, and motion_blur_s=0 blurs nothing")
        # a stretch of length L curves by curve_curvature_per_m x sin over one or two periods: the heading turns by up to
        # curvature x L / pi (one period); the first stretch starts 40 m behind the origin and reaches 40 m further
        longest = max(self.corner_spacing_m[1] + 80.0, (self.first_corner_m or 0.0) + 40.0)
        turn_deg = math.degrees(self.curve_curvature_per_m * longest / math.pi)
        if turn_deg > MAX_CURVE_TURN_DEG:
            most = math.radians(MAX_CURVE_TURN_DEG) * math.pi / longest
            raise ValueError(f"curve_curvature_per_m {self.curve_curvature_per_m:g} turns the street by up to {turn_deg:.1f} deg "
                             f"within a stretch of {longest:g} m (curvature x length / pi); at most {MAX_CURVE_TURN_DEG:g} deg: "
                             f"at most {most:.3g} with these corner_spacing_m / first_corner_m")
        return self

    @property
    def K(self) -> np.ndarray:
        cx = (self.width - 1) / 2.0 if self.cx is None else self.cx
        cy = (self.height - 1) / 2.0 if self.cy is None else self.cy
        return np.array([[self.fx, 0.0, cx], [0.0, self.fy, cy], [0.0, 0.0, 1.0]])


def make_camera_config(**params: object) -> CameraSimConfig:
    """Validated :class:`CameraSimConfig`; bad or unknown parameters raise ConfigError (see
    :func:`~lidarkit.sim.lidar.checked_config`)."""
    return checked_config(CameraSimConfig, params, "camera simulator")


# ---------------------------------------------------------------------------------------------------------------
# Path with street corners, and the drive along it
# ---------------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class StreetPath:
    """A planar path (arc length, xy, heading) and its corners ``(s_start, s_end)`` (m)."""

    path: PlanarPath
    corners: np.ndarray  # (C, 2)
    stretches: np.ndarray  # (S, 2) arc-length ranges between corners

    def at(self, s_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self.path.at(s_m)


def make_street_path(rng: np.random.Generator, s_begin_m: float, s_end_m: float, cfg: CameraSimConfig,
                     step_m: float = 0.1) -> StreetPath:
    """Stretches with gentle curves (sinusoidal curvature that returns the heading to its target) joined by
    90-degree corners of 12..20 m radius; the heading alternates between the start direction and +-90 degrees, so
    the path never comes back on itself. Heading 0 at ``s = 0``, which is the origin. ``first_corner_m`` puts the
    first corner that far ahead (short sequences that turn, as KITTI's do)."""
    s = np.arange(s_begin_m, s_end_m + step_m, step_m)
    kappa = np.zeros_like(s)
    corners, stretches = [], []
    start, heading_target, first = s_begin_m, 0.0, True
    while start < s_end_m:
        length = rng.uniform(*cfg.corner_spacing_m) + (-s_begin_m + 40.0 if first else 0.0)
        if first and cfg.corners and cfg.first_corner_m is not None:
            length = cfg.first_corner_m - s_begin_m  # drawn all the same: the seed's later draws stay put
        first = False
        end = start + length
        inside = (s >= start) & (s < end)
        periods = int(rng.integers(1, 3))
        amp = rng.uniform(-1.0, 1.0) * cfg.curve_curvature_per_m
        kappa[inside] += amp * np.sin(2.0 * np.pi * periods * (s[inside] - start) / length)
        stretches.append((start, end))
        if not cfg.corners:
            start = end
            continue
        turn = rng.choice([-1.0, 1.0]) * np.pi / 2 if heading_target == 0.0 else -heading_target
        radius = rng.uniform(12.0, 20.0)
        arc = abs(turn) * radius
        kappa[(s >= end) & (s < end + arc)] += np.sign(turn) / radius
        corners.append((end, end + arc))
        heading_target += turn
        start = end + arc
    box = max(int(round(3.0 / step_m)), 1)  # 3 m of smoothing: curvature ramps into a corner (steering)
    kappa = np.convolve(kappa, np.ones(box) / box, mode="same")
    heading = np.zeros_like(s)
    heading[1:] = np.cumsum(0.5 * (kappa[1:] + kappa[:-1]) * step_m)
    heading -= np.interp(0.0, s, heading)
    xy = np.zeros((len(s), 2))
    xy[1:, 0] = np.cumsum(0.5 * (np.cos(heading[1:]) + np.cos(heading[:-1])) * step_m)
    xy[1:, 1] = np.cumsum(0.5 * (np.sin(heading[1:]) + np.sin(heading[:-1])) * step_m)
    xy -= np.array([np.interp(0.0, s, xy[:, 0]), np.interp(0.0, s, xy[:, 1])])
    return StreetPath(PlanarPath(s, xy, heading), np.array(corners).reshape(-1, 2), np.array(stretches).reshape(-1, 2))


def simulate_speed(rng: np.random.Generator, duration_s: float, corners: np.ndarray, cfg: CameraSimConfig,
                   dt: float = 0.02) -> tuple[np.ndarray, np.ndarray]:
    """Times ``(M,)`` and arc lengths ``(M,)`` of a drive: cruise targets change every 4..15 s (sometimes a stop of
    2..6 s), the speed follows with bounded acceleration and brakes to ``corner_speed_mps`` before every corner.
    The drive starts moving at its first cruise speed, or slower when a corner is too close to brake for."""
    n = int(math.ceil(duration_s / dt)) + 2
    change_t, targets = [0.0], [rng.uniform(cfg.speed_min_mps, cfg.speed_max_mps)]
    while change_t[-1] < duration_s:
        change_t.append(change_t[-1] + rng.uniform(4.0, 15.0))
        if rng.random() < cfg.stop_probability:
            targets.append(0.0)
            change_t.append(change_t[-1] + rng.uniform(2.0, 6.0))
        targets.append(rng.uniform(cfg.speed_min_mps, cfg.speed_max_mps))
    change_t, targets = np.asarray(change_t), np.asarray(targets[: len(change_t)])
    times = np.arange(n) * dt
    target_at = targets[np.searchsorted(change_t, times, side="right") - 1]
    s_out = np.zeros(n)
    v, s_pos, a = float(targets[0]), 0.0, cfg.accel_mps2
    vc2 = cfg.corner_speed_mps**2
    ahead = corners[corners[:, 1] > 0.0]
    if len(ahead):  # a corner close ahead of the start: start no faster than braking for it allows
        v = min(v, float(np.sqrt(vc2 + 2.0 * a * max(ahead[0, 0], 0.0))))
    for k in range(n):  # a short scalar integration (M ~ 50 per second of drive), not a per-pixel loop
        s_out[k] = s_pos
        desired = target_at[k]
        ahead = corners[corners[:, 1] > s_pos]
        if len(ahead):
            limit = np.sqrt(vc2 + 2.0 * a * np.maximum(ahead[:, 0] - s_pos, 0.0)).min()
            desired = min(desired, limit)
        v += float(np.clip(desired - v, -a * dt, a * dt))
        s_pos += v * dt
    return times, s_out


# ---------------------------------------------------------------------------------------------------------------
# Scene: surfaces (textured faces) as triangles with UVs in metres
# ---------------------------------------------------------------------------------------------------------------
@dataclass
class _Surface:
    material: str
    size_texels: tuple[int, int]  # (h, w)
    texel_m: float
    seed_key: tuple[int, ...]
    shade: float


class _SceneBuilder:
    def __init__(self, seed: int, texel_scale: float):
        self.seed, self.texel_scale = seed, texel_scale
        self.tri_xyz: list[np.ndarray] = []
        self.tri_uv: list[np.ndarray] = []
        self.tri_surface: list[np.ndarray] = []
        self.surfaces: list[_Surface] = []

    def surface(self, xyz: np.ndarray, uv_m: np.ndarray, material: str, texel_m: float, key: tuple[int, ...]) -> None:
        """Triangles ``xyz`` (k, 3, 3) with per-vertex texture coordinates ``uv_m`` (k, 3, 2) in metres."""
        texel = texel_m * self.texel_scale
        uv_m = uv_m - uv_m.reshape(-1, 2).min(axis=0)
        extent = uv_m.reshape(-1, 2).max(axis=0)
        size = (int(math.ceil(extent[1] / texel)) + 1, int(math.ceil(extent[0] / texel)) + 1)
        normal = np.cross(xyz[0, 1] - xyz[0, 0], xyz[0, 2] - xyz[0, 0])
        normal /= max(float(np.linalg.norm(normal)), 1e-12)
        shade = 0.6 + 0.4 * abs(float(normal @ _SUN))
        self.tri_xyz.append(xyz)
        self.tri_uv.append(uv_m / texel)
        self.tri_surface.append(np.full(len(xyz), len(self.surfaces), np.int32))
        self.surfaces.append(_Surface(material, size, texel, (self.seed, *key), shade))

    def quad(self, p0, p1, p2, p3, material: str, texel_m: float, key: tuple[int, ...]) -> None:
        """Planar quad ``p0 p1 p2 p3`` (u along p0->p1, v along p0->p3)."""
        p = np.array([p0, p1, p2, p3], np.float64)
        u_axis = (p[1] - p[0]) / max(np.linalg.norm(p[1] - p[0]), 1e-12)
        v_axis = p[3] - p[0] - ((p[3] - p[0]) @ u_axis) * u_axis
        v_axis /= max(np.linalg.norm(v_axis), 1e-12)
        uv = np.stack([(p - p[0]) @ u_axis, (p - p[0]) @ v_axis], axis=1)
        faces = np.array([[0, 1, 2], [0, 2, 3]])
        self.surface(p[faces], uv[faces], material, texel_m, key)

    def box(self, footprint_xy: np.ndarray, z0: float, z1: float, materials: tuple[str, str], texels: tuple[float, float],
            key: tuple[int, ...]) -> None:
        """Prism over the 4-corner ``footprint_xy``: side faces (the first, corners 0->1, gets ``materials[0]``) and the
        top (``materials[1]``)."""
        c = np.asarray(footprint_xy, np.float64)
        for f in range(4):
            a, b = c[f], c[(f + 1) % 4]
            mat, tex = (materials[0], texels[0]) if f == 0 else (materials[1], texels[1])
            self.quad([*a, z1], [*b, z1], [*b, z0], [*a, z0], mat, tex, (*key, f))
        self.quad([*c[0], z1], [*c[1], z1], [*c[2], z1], [*c[3], z1], materials[1], texels[1], (*key, 4))

    def build(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[_Surface]]:
        return (np.concatenate(self.tri_xyz), np.concatenate(self.tri_uv), np.concatenate(self.tri_surface),
                self.surfaces)


def _frame_at(street: StreetPath, s: float | np.ndarray, lateral: float | np.ndarray) -> np.ndarray:
    """World xy of the point ``lateral`` metres left of the path at arc length ``s``."""
    xy, heading = street.at(np.atleast_1d(s))
    left = np.stack([-np.sin(heading), np.cos(heading)], axis=-1)
    return xy + np.asarray(lateral)[..., None] * left


def build_street_scene(cfg: CameraSimConfig, street: StreetPath, terrain: Terrain, s_lo: float, s_hi: float
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[_Surface]]:
    """Triangles, UVs (texels), triangle -> surface and the surfaces of the street canyon over ``[s_lo, s_hi]``."""
    b = _SceneBuilder(cfg.seed, cfg.texel_scale)

    def ground_z(xy: np.ndarray) -> np.ndarray:
        return terrain.height(xy)

    def near_corner(s: float, margin: float) -> bool:
        c = street.corners
        return bool(len(c)) and bool(np.any((s > c[:, 0] - margin) & (s < c[:, 1] + margin)))

    # road: 20 m segments of 1 m quads, lifted above the ground tiles
    seg_len, step = 20.0, 1.0
    for j, s0 in enumerate(np.arange(math.floor(s_lo / seg_len) * seg_len, s_hi, seg_len)):
        ss = np.arange(s0, s0 + seg_len + step / 2, step)
        left, right = _frame_at(street, ss, _ROAD_HALF_M), _frame_at(street, ss, -_ROAD_HALF_M)
        zl, zr = ground_z(left) + _ROAD_LIFT_M, ground_z(right) + _ROAD_LIFT_M
        L = np.c_[left, zl]
        R = np.c_[right, zr]
        a, bb, c, d = R[:-1], R[1:], L[1:], L[:-1]
        tri = np.concatenate([np.stack([a, bb, c], 1), np.stack([a, c, d], 1)])
        u = ss - s0
        uvR = np.c_[u, np.zeros_like(u)]
        uvL = np.c_[u, np.full_like(u, 2 * _ROAD_HALF_M)]
        uv = np.concatenate([np.stack([uvR[:-1], uvR[1:], uvL[1:]], 1), np.stack([uvR[:-1], uvL[1:], uvL[:-1]], 1)])
        b.surface(tri, uv, "road", 0.03, (1, int(round(s0 / seg_len)) + 100000))

    # ground tiles (8 m) within 80 m of the path, finer texels near it
    tile = 8.0
    samples = _frame_at(street, np.arange(s_lo, s_hi, 2.0), 0.0)
    lo, hi = samples.min(axis=0) - 80.0, samples.max(axis=0) + 80.0
    ix = np.arange(math.floor(lo[0] / tile), math.ceil(hi[0] / tile))
    iy = np.arange(math.floor(lo[1] / tile), math.ceil(hi[1] / tile))
    gx, gy = np.meshgrid(ix, iy, indexing="ij")
    centres = (np.c_[gx.ravel(), gy.ravel()] + 0.5) * tile
    from scipy.spatial import cKDTree

    dist, _ = cKDTree(samples).query(centres)
    for (i, j), d in zip(np.c_[gx.ravel(), gy.ravel()][dist < 80.0], dist[dist < 80.0]):
        corners = np.array([[i, j], [i + 1, j], [i + 1, j + 1], [i, j + 1]], np.float64) * tile
        p = np.c_[corners, ground_z(corners)]
        uv = corners - corners[0]
        faces = np.array([[0, 1, 2], [0, 2, 3]])
        b.surface(p[faces], uv[faces], "ground", 0.05 if d < 16.0 else 0.15, (2, int(i) + 2**20, int(j) + 2**20))

    # buildings: per stretch and side, consecutive blocks with gaps; every corner is a crossing, so the stretch
    # before it continues straight on past the crossing and the one after it continues backwards (no road there)
    def along_path(d: np.ndarray, lateral: float) -> np.ndarray:
        return _frame_at(street, d, lateral)

    path_xy = _frame_at(street, np.arange(s_lo, s_hi, 1.0), 0.0)  # where crossing blocks must not reach
    for side, sign in ((0, 1.0), (1, -1.0)):
        rng = np.random.default_rng([cfg.seed, 10 + side])
        for j, (a_s, b_s) in enumerate(street.stretches):
            if 0 < j <= len(street.corners):  # after a corner: start clear of the crossing (corners=false has none)
                a_s = street.corners[j - 1, 1] - _corner_radius(street.corners[j - 1]) + _CROSSING_CLEAR_M
            if j < len(street.corners):
                b_s = street.corners[j, 0] + _corner_radius(street.corners[j]) - _CROSSING_CLEAR_M
            _place_blocks(b, rng, along_path, max(a_s, s_lo), min(b_s, s_hi), sign, ground_z, (3, side, j))
        rng = np.random.default_rng([cfg.seed, 12 + side])
        for j, (c_a, c_b) in enumerate(street.corners):
            if c_a > s_hi:
                break
            centre, ahead, behind = _crossing(street, c_a, c_b)
            for k, direction in enumerate((ahead, behind)):
                def along_line(d: np.ndarray, lateral: float, u=direction) -> np.ndarray:
                    d = np.atleast_1d(d)
                    return centre + d[:, None] * u + lateral * np.array([-u[1], u[0]])

                reach = _clear_reach(path_xy, centre, direction)
                _place_blocks(b, rng, along_line, _CROSSING_CLEAR_M, reach, sign, ground_z, (7, side, j, k))

    # poles and parked cars along both sides (not inside corners)
    for side, sign in ((0, 1.0), (1, -1.0)):
        rng = np.random.default_rng([cfg.seed, 20 + side])
        s, n = s_lo + rng.uniform(0.0, 20.0), 0
        while s < s_hi:
            if not near_corner(s, 8.0):
                centre = _frame_at(street, s, sign * (_ROAD_HALF_M + 0.7))[0]
                radius, height = 0.12, rng.uniform(4.0, 7.0)
                ang = np.linspace(0.0, 2 * np.pi, 7)
                ring = centre + radius * np.c_[np.cos(ang), np.sin(ang)]
                z0 = ground_z(centre[None])[0] - 0.3
                bottom, top = np.c_[ring, np.full(7, z0)], np.c_[ring, np.full(7, z0 + height)]
                tri = np.concatenate([np.stack([bottom[:-1], bottom[1:], top[1:]], 1),
                                      np.stack([bottom[:-1], top[1:], top[:-1]], 1)])
                arc = np.arange(7) * radius * 2 * np.sin(np.pi / 6)
                ub, ut = np.c_[arc, np.zeros(7)], np.c_[arc, np.full(7, height)]
                uv = np.concatenate([np.stack([ub[:-1], ub[1:], ut[1:]], 1), np.stack([ub[:-1], ut[1:], ut[:-1]], 1)])
                b.surface(tri, uv, "pole", 0.01, (4, side, n))
            n += 1
            s += rng.uniform(18.0, 40.0)
        rng = np.random.default_rng([cfg.seed, 30 + side])
        s, n = s_lo, 0
        while s < s_hi:
            if rng.random() < 0.5 and not near_corner(s, 15.0):
                lat = sign * (_ROAD_HALF_M - 1.0 - rng.uniform(0.0, 0.3))
                ends = _frame_at(street, np.array([s, s + 4.3]), lat)
                fwd = (ends[1] - ends[0]) / max(np.linalg.norm(ends[1] - ends[0]), 1e-9)
                left = np.array([-fwd[1], fwd[0]])
                foot = np.array([ends[0] - 0.9 * left, ends[1] - 0.9 * left, ends[1] + 0.9 * left, ends[0] + 0.9 * left])
                z0 = ground_z(foot).min() + _ROAD_LIFT_M - 0.05
                b.box(foot, z0, z0 + rng.uniform(1.35, 1.6), ("car", "car"), (0.02, 0.02), (5, side, n))
            n += 1
            s += 6.5

    if cfg.trees:
        for side, sign in ((0, 1.0), (1, -1.0)):
            rng = np.random.default_rng([cfg.seed, 40 + side])
            s, n = s_lo + rng.uniform(0.0, 15.0), 0
            while s < s_hi:
                if not near_corner(s, 10.0):
                    _add_tree(b, rng, _frame_at(street, s, sign * (_ROAD_HALF_M + 1.8))[0], ground_z, (6, side, n))
                n += 1
                s += rng.uniform(10.0, 25.0)
    return b.build()


def _corner_radius(corner: np.ndarray) -> float:
    return float(corner[1] - corner[0]) / (np.pi / 2)


def _crossing(street: StreetPath, s_a: float, s_b: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centre of the crossing at the corner ``[s_a, s_b]`` (where the two streets' centre lines meet), the
    direction of the street before it (continuing ahead) and the backward direction of the street after it."""
    xy, heading = street.at(np.array([s_a, s_b]))
    radius = _corner_radius(np.array([s_a, s_b]))
    u_a = np.array([np.cos(heading[0]), np.sin(heading[0])])
    u_b = np.array([np.cos(heading[1]), np.sin(heading[1])])
    return xy[0] + radius * u_a, u_a, -u_b


def _clear_reach(path_xy: np.ndarray, centre: np.ndarray, u: np.ndarray) -> float:
    """How far (at most 80 m) blocks may line the straight street ``centre + d u`` past a crossing: they stop short
    of any part of the path ``path_xy`` (K, 2) passing near it (with short corner spacings the next-but-one stretch
    crossed them and the camera drove through buildings)."""
    rel = path_xy - centre
    along, lateral = rel @ u, rel @ np.array([-u[1], u[0]])
    band = _SETBACK_M[1] + _DEPTH_M[1] + _ROAD_HALF_M + 1.0  # block depth plus the other street's half width
    near = (along > 10.0) & (np.abs(lateral) < band)  # (the crossing's own streets and corner lie at along <= 0)
    return min(80.0, float(along[near].min(initial=np.inf)) - _ROAD_HALF_M - 1.0)


def _place_blocks(b: _SceneBuilder, rng: np.random.Generator, frame: Callable, d0: float, d1: float, sign: float,
                  ground_z: Callable, key: tuple) -> None:
    """Consecutive building blocks (8..25 m long, sometimes a 1..5 m gap) from ``d0`` to ``d1`` along a street whose
    ``frame(d, lateral)`` gives world xy; ``sign`` +1: left side, -1: right side. The front face faces the street."""
    d, n = d0, 0
    while d < d1:
        length, gap = rng.uniform(8.0, 25.0), (rng.uniform(1.0, 5.0) if rng.random() < 0.3 else 0.0)
        setback, height, depth = rng.uniform(*_SETBACK_M), rng.uniform(6.0, 22.0), rng.uniform(*_DEPTH_M)
        e = min(d + length, d1)
        if e - d > 3.0:
            front = frame(np.array([d, e]), sign * setback)
            chord = front[1] - front[0]
            out = sign * np.array([-chord[1], chord[0]]) / max(np.linalg.norm(chord), 1e-9)
            foot = np.array([front[0], front[1], front[1] + depth * out, front[0] + depth * out])
            if sign < 0:  # keep the front face first
                foot = foot[[1, 0, 3, 2]]
            zg = ground_z(foot)
            b.box(foot, zg.min() - 1.0, zg.max() + height, ("facade", "wall"), (0.04, 0.12), (*key, n))
        n += 1
        d = e + gap


def _add_tree(b: _SceneBuilder, rng: np.random.Generator, centre: np.ndarray, ground_z: Callable, key: tuple) -> None:
    """A square trunk and an irregular octahedral crown; every crown face is its own textured triangle."""
    z0 = ground_z(centre[None])[0] - 0.2
    trunk_h, r = rng.uniform(2.0, 3.5), 0.15
    foot = centre + r * np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], np.float64)
    b.box(foot, z0, z0 + trunk_h + 0.5, ("trunk", "trunk"), (0.01, 0.01), (*key, 0))
    radius = rng.uniform(1.3, 2.4)
    c = np.array([*centre, z0 + trunk_h + radius * 0.8])
    axes = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], np.float64)
    verts = c + axes * radius * rng.uniform(0.7, 1.3, (6, 1))
    faces = [(0, 2, 4), (2, 1, 4), (1, 3, 4), (3, 0, 4), (2, 0, 5), (1, 2, 5), (3, 1, 5), (0, 3, 5)]
    for f, (i, j, k) in enumerate(faces):
        p = verts[[i, j, k]]
        u_axis = (p[1] - p[0]) / np.linalg.norm(p[1] - p[0])
        v_axis = p[2] - p[0] - ((p[2] - p[0]) @ u_axis) * u_axis
        v_axis /= np.linalg.norm(v_axis)
        uv = np.stack([(p - p[0]) @ u_axis, (p - p[0]) @ v_axis], axis=1)
        b.surface(p[None], uv[None], "foliage", 0.02, (*key, 1, f))


# ---------------------------------------------------------------------------------------------------------------
# The sequence
# ---------------------------------------------------------------------------------------------------------------
class SimulatedCameraSequence:
    """An ``ImageSequence`` of rendered grey images with exact ``K`` and ground truth; images are rendered on demand
    (the last two are cached), the scene and its per-triangle data once."""

    def __init__(self, config: CameraSimConfig | None = None, **params: object):
        if config is not None and params:
            raise ConfigError("pass either a CameraSimConfig or keyword parameters, not both", source="camera simulator")
        if config is not None:
            check_argument(config, CameraSimConfig, "config", "a CameraSimConfig (or keyword parameters)")
        self.config = cfg = config if config is not None else make_camera_config(**params)
        from lidarkit.resources import check_memory

        # the renderer's per-pixel rays, hits and shading (float64, ~290 B a pixel measured: 4.9 GB at 4096 x 4096; the
        # largest size allowed was a MemoryError traceback)
        check_memory(300.0 * cfg.width * cfg.height, f"a {cfg.width}x{cfg.height} image", "width / height")
        self.name = f"simcam:{cfg.scene}?seed={cfg.seed}"
        duration = (cfg.n_frames - 1) / cfg.frame_rate_hz + cfg.motion_blur_s + 1.0
        reach = cfg.speed_max_mps * duration + 200.0
        self.street = make_street_path(np.random.default_rng([cfg.seed, 0]), -40.0, reach, cfg)
        self.terrain = make_terrain(np.random.default_rng([cfg.seed, 1]), cfg.terrain_amplitude_m,
                                    cfg.terrain_wavelength_m)
        self._drive_t, self._drive_s = simulate_speed(np.random.default_rng([cfg.seed, 2]), duration,
                                                      self.street.corners, cfg)
        sway = np.random.default_rng([cfg.seed, 3]).uniform(size=(3, 2))
        self._sway_freq_hz, self._sway_phase = 0.3 + 0.6 * sway[:, 0], 2 * np.pi * sway[:, 1]
        self.frame_times_s = np.arange(cfg.n_frames) / cfg.frame_rate_hz
        self._T_world_cam = self.poses_at(self.frame_times_s)
        s_hi = float(self._drive_s[-1]) + 150.0
        xyz, uv, tri_surface, surfaces = build_street_scene(cfg, self.street, self.terrain, -40.0, s_hi)
        self.triangles_xyz = xyz
        self.triangle_surface = tri_surface
        self.surfaces = surfaces
        texel_m = np.array([s.texel_m for s in surfaces])
        shade = np.array([s.shade for s in surfaces])
        self._tri_table = np.c_[uv[:, 0], uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0], 1.0 / texel_m[tri_surface],
                                shade[tri_surface]].astype(np.float32)
        # per (surface, level): atlas x, y of the level's texture, its last texel x, y, and the scale 2^-level
        self._mip_table = np.zeros((len(surfaces) * N_MIP_LEVELS, 5), np.float32)
        self._mip_table[:, 4] = np.tile(np.exp2(-np.arange(N_MIP_LEVELS)), len(surfaces))
        self._ready = np.zeros(len(surfaces), bool)
        self._mip_pairs_cache: np.ndarray | None = None
        self._buffers: dict[str, np.ndarray] = {}
        self.atlas = TextureAtlas()
        self._scene = None
        w, h = cfg.width, cfg.height
        u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
        K = cfg.K
        dirs = self.pixel_directions(np.c_[u.ravel(), v.ravel()]).astype(np.float64)
        self._dirs_cam = dirs.astype(np.float32)
        self._ray_norm = np.linalg.norm(dirs, axis=1).astype(np.float32)
        self._pixel_rad = 1.0 / math.sqrt(K[0, 0] * K[1, 1])
        r2 = ((u - K[0, 2]) ** 2 + (v - K[1, 2]) ** 2) / (0.25 * (w**2 + h**2))
        self._vignette = (1.0 - cfg.vignetting * np.clip(r2, 0.0, 1.0)).astype(np.float32)
        lg = np.random.default_rng([cfg.seed, 4]).standard_normal(cfg.n_frames)
        log_gain = np.zeros(cfg.n_frames)
        for k in range(1, cfg.n_frames):  # AR(1): stationary std gain_std, correlated over a few frames
            log_gain[k] = 0.7 * log_gain[k - 1] + math.sqrt(1 - 0.49) * cfg.gain_std * lg[k]
        self.gains = np.exp(log_gain)
        self._occluder_tex = None
        self._cache: dict[int, np.ndarray] = {}

    # ---- geometry ---------------------------------------------------------------------------------
    def poses_at(self, times_s: np.ndarray) -> np.ndarray:
        """``(M, 4, 4)`` world poses ``T_world_cam`` at times ``times_s`` (s from the first frame); DataError naming
        ``times_s`` for times that are not a 1-D array of finite numbers (NaN gave NaN poses, unsaid)."""
        cfg = self.config
        t = checked_times(times_s)
        s = np.interp(t, self._drive_t, self._drive_s)
        xy, heading = self.street.at(s)
        wave = np.sin(2 * np.pi * self._sway_freq_hz[:, None] * t[None, :] + self._sway_phase[:, None])
        wave -= np.sin(self._sway_phase)[:, None]
        pitch, roll = np.deg2rad(cfg.sway_deg) * wave[0], np.deg2rad(cfg.sway_deg) * wave[1]
        grad = self.terrain.gradient(xy)
        forward = grad[:, 0] * np.cos(heading) + grad[:, 1] * np.sin(heading)
        left = -grad[:, 0] * np.sin(heading) + grad[:, 1] * np.cos(heading)
        pitch, roll = pitch - np.arctan(forward), roll + np.arctan(left)
        cy, sy, cp, sp, cr, sr = np.cos(heading), np.sin(heading), np.cos(pitch), np.sin(pitch), np.cos(roll), np.sin(roll)
        R = np.zeros((len(t), 3, 3))
        R[:, 0, 0], R[:, 0, 1], R[:, 0, 2] = cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr
        R[:, 1, 0], R[:, 1, 1], R[:, 1, 2] = sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr
        R[:, 2, 0], R[:, 2, 1], R[:, 2, 2] = -sp, cp * sr, cp * cr
        T = np.zeros((len(t), 4, 4))
        T[:, :3, :3] = R @ _R_BODY_CAM
        T[:, :2, 3] = xy
        T[:, 2, 3] = self.terrain.height(xy) + _ROAD_LIFT_M + cfg.camera_height_m + 0.02 * wave[2]
        T[:, 3, 3] = 1.0
        return T

    @property
    def world_poses(self) -> np.ndarray:
        """``(n_frames, 4, 4)`` ``T_world_cam`` of every frame (the frame the scene triangles are given in)."""
        return self._T_world_cam.copy()

    @property
    def ground_truth(self) -> Trajectory:
        """``T_cam0_camk`` (KITTI convention, first pose identity) at the frame times."""
        T0_inv = np.linalg.inv(self._T_world_cam[0])
        return Trajectory(T0_inv @ self._T_world_cam, self.frame_times_s.copy(), name=f"{self.name} ground truth")

    @property
    def K(self) -> np.ndarray:
        return self.config.K

    @property
    def timestamps_s(self) -> np.ndarray:
        return self.frame_times_s.copy()

    def __len__(self) -> int:
        return self.config.n_frames

    def __repr__(self) -> str:
        c = self.config
        return f"SimulatedCameraSequence({self.name!r}, {c.n_frames} images of {c.width}x{c.height})"

    # ---- rendering --------------------------------------------------------------------------------
    @property
    def scene(self):
        """The Open3D RaycastingScene (built on first use)."""
        if self._scene is None:
            import open3d as o3d

            scene = o3d.t.geometry.RaycastingScene()
            n = len(self.triangles_xyz)
            scene.add_triangles(o3d.core.Tensor(self.triangles_xyz.reshape(-1, 3).astype(np.float32)),
                                o3d.core.Tensor(np.arange(3 * n, dtype=np.uint32).reshape(n, 3)))
            self._scene = scene
        return self._scene

    def pixel_directions(self, uv: np.ndarray) -> np.ndarray:
        """``(M, 3)`` float32 camera-frame ray directions ``K^-1 (u, v, 1)`` (z = 1) of pixel coordinates ``uv``
        (M, 2); pixel centres sit at integer coordinates (OpenCV convention). The renderer casts exactly these.
        DataError naming ``uv`` for any other shape or a non-finite coordinate (three numbers were numpy's reshape error)."""
        K = self.config.K
        try:
            uv = np.asarray(uv, np.float64)
        except (TypeError, ValueError):
            raise DataError(f"takes (M, 2) finite pixel coordinates, got {type(uv).__name__}", source="uv") from None
        if uv.ndim != 2 or uv.shape[1] != 2:
            raise DataError(f"takes (M, 2) finite pixel coordinates, got shape {uv.shape}", source="uv")
        if not np.isfinite(uv).all():
            row = int(np.flatnonzero(~np.isfinite(uv).all(axis=1))[0])
            raise DataError(f"takes (M, 2) finite pixel coordinates, row {row} is {uv[row].tolist()}", source="uv")
        return np.c_[(uv[:, 0] - K[0, 2]) / K[0, 0], (uv[:, 1] - K[1, 2]) / K[1, 1], np.ones(len(uv))].astype(np.float32)

    def cast_pixels(self, index: int, uv: np.ndarray) -> np.ndarray:
        """World points ``(M, 3)`` seen at pixel coordinates ``uv`` (M, 2) of frame ``index`` (NaN: sky); ``index`` is
        checked as :meth:`read_image` checks it (-1 cast from the last frame, 1.7 from frame 1)."""
        import open3d as o3d

        T = self._T_world_cam[checked_index(index, self.config.n_frames, self.name, "frame", from_end=False)]
        dirs = self.pixel_directions(uv) @ T[:3, :3].T.astype(np.float32)
        rays = np.c_[np.broadcast_to(T[:3, 3], dirs.shape), dirs].astype(np.float32)
        t_hit = self.scene.cast_rays(o3d.core.Tensor(rays), nthreads=self.config.threads)["t_hit"].numpy()
        hit = np.isfinite(t_hit)  # (a sky pixel's inf times a zero direction component warned of invalid values)
        points = np.full((len(t_hit), 3), np.nan)
        points[hit] = T[:3, 3] + t_hit[hit, None].astype(np.float64) * dirs[hit]
        return points

    def _ensure_textures(self, surfaces: np.ndarray) -> None:
        """Generate the textures of ``surfaces`` not in the atlas yet. A full atlas is cleared and refilled with
        just these: images do not depend on where a texture sits in the atlas, so this changes nothing visible."""
        from lidarkit.sim.textures import AtlasFullError

        try:
            self._generate(surfaces[~self._ready[surfaces]])
        except AtlasFullError:
            log.debug("texture atlas full: cleared and refilled with the %d surfaces in view", len(surfaces))
            self.atlas.clear()
            self._ready[:] = False
            try:
                self._generate(surfaces)
            except AtlasFullError:
                raise ConfigError("the textures one frame sees do not fit the texture atlas; use a larger texel_scale",
                                  source=self.name) from None

    def _generate(self, surfaces: np.ndarray) -> None:
        self._mip_pairs_cache = None
        for i in surfaces:
            surf = self.surfaces[i]
            tex = natural_texture(np.random.default_rng(list(surf.seed_key)), surf.size_texels, surf.texel_m,
                                  surf.material)
            levels = mip_levels(tex, N_MIP_LEVELS)
            for lev in range(N_MIP_LEVELS):
                img = levels[min(lev, len(levels) - 1)]
                if lev < len(levels):
                    x, y = self.atlas.add(img)
                self._mip_table[i * N_MIP_LEVELS + lev, :4] = (x, y, img.shape[1] - 1, img.shape[0] - 1)
            self._ready[i] = True

    def render_at(self, T_world_cam: np.ndarray) -> np.ndarray:
        """Noise-free float32 image ``(h, w)`` (grey levels) seen from world pose ``T_world_cam``.

        Whole-image arrays throughout (misses read triangle 0 and get the sky at the end), written into buffers
        kept between frames: fresh multi-megabyte temporaries per frame cost as much in page faults as the
        arithmetic itself."""
        import cv2
        import open3d as o3d

        cfg = self.config
        n = len(self._dirs_cam)
        buf = self._buffers
        if not buf:
            f32 = np.float32
            buf.update(rays=np.empty((n, 6), f32), tmp3=np.empty((n, 3), f32), surf=np.empty(n, np.int32), tab=np.empty((n, 8), f32),
                       tex=np.empty((n, 2), f32), coord=np.empty((n, 2), f32), tmp=np.empty((n, 2), f32),
                       mips=np.empty((n, 10), f32), foot=np.empty(n, f32), cos=np.empty(n, f32), q=np.empty(n, f32),
                       frac=np.empty(n, np.float64), weighted=np.empty(n, np.float64), image=np.empty(n, f32),
                       row=np.empty(n, np.int32))
        R, t = T_world_cam[:3, :3].astype(np.float32), T_world_cam[:3, 3].astype(np.float32)
        rays = buf["rays"]
        rays[:, :3] = t
        dirs, tmp3 = rays[:, 3:], buf["tmp3"]
        # R (x, y, 1) element-wise: a BLAS matmul with an inner dimension of 3 costs 5x more CPU (idle threads spin)
        np.multiply(self._dirs_cam[:, :1], R[:, 0], out=dirs)
        np.multiply(self._dirs_cam[:, 1:2], R[:, 1], out=tmp3)
        dirs += tmp3
        dirs += R[:, 2]
        hits = self.scene.cast_rays(o3d.core.Tensor.from_numpy(rays), nthreads=cfg.threads)
        tri = hits["primitive_ids"].numpy().view(np.int32)  # INVALID_ID (2^32 - 1) reads -1
        miss = tri < 0
        np.maximum(tri, 0, out=tri)
        surf = np.take(self.triangle_surface, tri, out=buf["surf"])
        seen = np.flatnonzero(np.bincount(surf[~miss], minlength=len(self.surfaces)))
        if not self._ready[seen].all():
            self._ensure_textures(seen)
        tab = np.take(self._tri_table, tri, axis=0, out=buf["tab"])  # uv0, e1, e2 (texels), 1 / texel, shade
        bary = hits["primitive_uvs"].numpy()
        tex, tmp = buf["tex"], buf["tmp"]
        np.multiply(bary[:, :1], tab[:, 2:4], out=tex)  # level-0 texel coordinates (uv0 + a e1) + b e2
        tex += tab[:, 0:2]
        np.multiply(bary[:, 1:], tab[:, 4:6], out=tmp)
        tex += tmp
        # footprint of a pixel in texels: distance / focal, stretched by the incidence (geometric mean of the axes)
        foot, cos = buf["foot"], buf["cos"]
        np.einsum("ij,ij->i", hits["primitive_normals"].numpy(), dirs, out=cos)
        np.abs(cos, out=cos)
        cos /= self._ray_norm
        np.maximum(cos, np.float32(0.02), out=cos)
        np.sqrt(cos, out=cos)
        np.multiply(hits["t_hit"].numpy(), self._ray_norm, out=foot)
        foot *= np.multiply(tab[:, 6], np.float32(self._pixel_rad), out=buf["q"])
        foot /= cos
        foot[miss] = 1.0
        level = np.log2(foot, out=foot)
        np.clip(level, 0.0, N_MIP_LEVELS - 1.001, out=level)
        row = buf["row"]
        np.copyto(row, level, casting="unsafe")  # floor (level >= 0)
        frac = np.subtract(level, row, out=buf["frac"])  # float64: the blend weight of the coarser level
        # one gather for both levels: row i of the pair table holds (surface, level) i and i + 1
        row += surf * N_MIP_LEVELS
        mips = np.take(self._mip_pairs(), row, axis=0, out=buf["mips"])
        shape = (cfg.height, cfg.width)
        image, coord, weighted = buf["image"], buf["coord"], buf["weighted"]
        for k, mip in enumerate((mips[:, :5], mips[:, 5:])):
            scale = mip[:, 4:5]
            np.reciprocal(scale, out=tmp)  # texel centres of a halved level sit between two finer ones
            tmp -= 1.0
            tmp *= 0.5
            np.subtract(tex, tmp, out=coord)
            coord *= scale
            np.clip(coord, 0.0, mip[:, 2:4], out=coord)
            # snapped to remap's 1/32 texel grid before the (integer) atlas offset is added, so the sampled value
            # does not depend on where in the atlas the texture landed (i.e. on the order frames are read)
            coord *= 32.0
            np.rint(coord, out=coord)
            coord *= 1.0 / 32.0
            coord += mip[:, 0:2]
            sampled = cv2.remap(self.atlas.image, coord.reshape(*shape, 2), None, cv2.INTER_LINEAR).reshape(-1)
            if k == 0:
                np.subtract(1.0, frac, out=weighted)
                weighted *= sampled
                np.copyto(image, weighted, casting="same_kind")
            else:
                np.multiply(frac, sampled, out=weighted)
                np.add(image, weighted, out=image, casting="same_kind")
        image *= tab[:, 7]
        # sky: brighter towards the zenith
        image[miss] = 185.0 + 55.0 * np.clip(dirs[miss, 2] / self._ray_norm[miss], 0.0, 1.0)
        return image.reshape(shape).copy()

    def _mip_pairs(self) -> np.ndarray:
        """``(S * L, 10)``: the mip table row of (surface, level) beside the row of the next level (cached)."""
        if self._mip_pairs_cache is None:
            table = self._mip_table
            self._mip_pairs_cache = np.hstack([table, np.vstack([table[1:], table[-1:]])])
        return self._mip_pairs_cache

    def read_image(self, index: int) -> np.ndarray:
        """Frame ``index`` as ``(h, w)`` uint8, with the configured nuisances."""
        cfg = self.config
        index = checked_index(index, cfg.n_frames, self.name, "frame", from_end=False)
        if index in self._cache:
            return self._cache[index].copy()
        t = self.frame_times_s[index]
        if cfg.motion_blur_s > 0.0:
            offsets = (np.arange(cfg.blur_samples) / (cfg.blur_samples - 1) - 0.5) * cfg.motion_blur_s
            poses = self.poses_at(t + offsets)
            image = sum(self.render_at(T) for T in poses) / cfg.blur_samples
        else:
            image = self.render_at(self._T_world_cam[index])
        if cfg.occluder:
            self._draw_occluder(image, index)
        if cfg.gain_std > 0.0:
            image *= self.gains[index]
        if cfg.vignetting > 0.0:
            image *= self._vignette
        if cfg.noise_std > 0.0:
            image += np.random.default_rng([cfg.seed, 5, index]).normal(0.0, cfg.noise_std, image.shape).astype(np.float32)
        out = np.clip(np.rint(image), 0, 255).astype(np.uint8)
        if len(self._cache) >= 2:
            self._cache.pop(next(iter(self._cache)))
        self._cache[index] = out
        return out.copy()

    def occluder_frames(self) -> range:
        """Frames the occluder is drawn in (empty without ``occluder``)."""
        cfg = self.config
        if not cfg.occluder:
            return range(0)
        start = cfg.n_frames // 2 if cfg.occluder_start is None else cfg.occluder_start
        return range(start, min(start + cfg.occluder_frames, cfg.n_frames))

    def _draw_occluder(self, image: np.ndarray, index: int) -> None:
        """A textured panel (a passing truck) sliding left to right across the lower 3/4 of the image."""
        frames = self.occluder_frames()
        if index not in frames:
            return
        h, w = image.shape
        ow, top = int(0.4 * w), int(0.25 * h)
        if self._occluder_tex is None:
            self._occluder_tex = natural_texture(np.random.default_rng([self.config.seed, 6]), (h - top, ow), 0.01,
                                                 "occluder").astype(np.float32)
        progress = (index - frames.start + 0.5) / self.config.occluder_frames
        x0 = int(round(-ow + progress * (w + ow)))
        a, b = max(x0, 0), min(x0 + ow, w)
        if b > a:
            image[top:, a:b] = self._occluder_tex[:, a - x0 : b - x0]


def open_simcam(spec: str) -> SimulatedCameraSequence:
    """Sequence from ``simcam:SCENE[?key=value&...]``, e.g. ``simcam:street?frames=500&seed=1``.

    Keys are :class:`CameraSimConfig` fields; short aliases: ``frames`` (n_frames), ``noise`` (noise_std),
    ``blur`` (motion_blur_s), ``gain`` (gain_std).
    """
    from lidarkit.params import parse_kv

    check_argument(spec, str, "spec", "a 'simcam:SCENE?key=value' string")
    if not spec.startswith("simcam:"):
        raise ConfigError("a camera simulator spec starts with 'simcam:'", source=spec)
    scene, _, query = spec[len("simcam:"):].partition("?")
    params: dict[str, object] = {"scene": scene or "street"}
    aliases = {"frames": "n_frames", "noise": "noise_std", "blur": "motion_blur_s", "gain": "gain_std"}
    given_as: dict[str, str] = {"scene": f"simcam:{params['scene']}"}
    for key, value in parse_kv(query, option="camera simulator option").items():
        name = aliases.get(key, key)
        if name not in CameraSimConfig.model_fields:  # (the config's list left out the short keys the docstring gives)
            raise ConfigError(f"unknown key {key!r}; short keys: {', '.join(f'{a} ({f})' for a, f in aliases.items())}; or any of: "
                              f"{', '.join(CameraSimConfig.model_fields)}", source=spec)
        if name in params:  # (it named the second spelling only: "n_frames is given twice (as n_frames)")
            raise ConfigError(f"{name} is given twice (as {given_as[name]} and {key})", source=spec)
        params[name] = value
        given_as[name] = key
    try:
        return SimulatedCameraSequence(**params)
    except ConfigError as err:
        raise ConfigError(err.reason, source=spec) from None


def export_kitti_images(sequence: SimulatedCameraSequence, out_dir: str | os.PathLike,
                        on_frame: Callable[[int], None] | None = None) -> Path:
    """Write a KITTI-odometry-like folder: ``image_0/NNNNNN.png``, ``calib.txt`` (P0..P3 = [K | 0], Tr identity),
    ``poses.txt`` (``T_cam0_camk``), ``times.txt`` and ``sim.yaml`` (the resolved config).

    All or nothing, as the LiDAR export: the folder appears complete or not at all, and a folder that already holds
    files is refused (an earlier export's images were left beside a shorter one's poses)."""
    from lidarkit import atomic

    check_argument(sequence, SimulatedCameraSequence, "sequence")
    check_argument(out_dir, (str, os.PathLike), "out_dir", "a path")
    out = Path(out_dir)
    with atomic.export_folder(out, "images") as tmp:
        _write_kitti_images(sequence, tmp, on_frame)
    return out


def _write_kitti_images(sequence: SimulatedCameraSequence, out: Path, on_frame: Callable[[int], None] | None) -> None:
    import cv2
    import yaml

    from lidarkit import atomic

    atomic.ensure_dir(out / "image_0")
    for i in range(len(sequence)):
        ok, data = cv2.imencode(".png", sequence.read_image(i))
        if not ok:
            raise DataError("PNG encoding failed", source=out / "image_0" / f"{i:06d}.png")
        atomic.write_bytes(out / "image_0" / f"{i:06d}.png", data.tobytes())
        if on_frame is not None:
            on_frame(i)
    P = np.hstack([sequence.K, np.zeros((3, 1))])
    p0 = " ".join(f"{v:.12e}" for v in P.ravel())
    identity = " ".join(f"{v:.12e}" for v in np.eye(4)[:3].ravel())
    atomic.write_text(out / "calib.txt", "".join(f"P{k}: {p0}\n" for k in range(4)) + f"Tr: {identity}\n")
    # 17 significant digits: read back as the very stamps (7 left 3000 frames at 7 Hz up to 4.3e-5 s off)
    atomic.write_text(out / "times.txt", "".join(f"{t:.16e}\n" for t in sequence.timestamps_s))
    sequence.ground_truth.to_kitti(out / "poses.txt")
    cfg = sequence.config.model_dump()
    cfg["note"] = "poses are T_cam0_camk (camera: x right, y down, z forward) at each frame's time"
    atomic.write_text(out / "sim.yaml", yaml.safe_dump(cfg, sort_keys=False))


__all__ = [
    "KITTI_K",
    "KITTI_SIZE_WH",
    "CameraSimConfig",
    "SimulatedCameraSequence",
    "StreetPath",
    "build_street_scene",
    "export_kitti_images",
    "make_camera_config",
    "make_street_path",
    "open_simcam",
    "simulate_speed",
]
