"""Synthetic pinhole camera: textured planes rendered at known poses by homography warps (exact ground truth).

A :class:`PlaneScene` holds rectangles with seeded random textures at several depths, so two views of it give a
well-posed essential matrix. ``render(T_world_cam, K, size_wh)`` draws the planes far-to-near (painter's algorithm;
planes must not intersect and must lie entirely in front of the camera). Camera frame: x right, y down, z forward.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from lidarkit.errors import ConfigError
from lidarkit.geometry import make_se3, se3_inverse, so3_exp
from lidarkit.trajectory import Trajectory


def random_texture(rng: np.random.Generator, size_px: int = 512, octaves: int = 6) -> np.ndarray:
    """Seeded multi-scale noise texture ``(size_px, size_px)`` uint8 with corners at many scales."""
    tex = np.zeros((size_px, size_px), np.float64)
    for octave in range(octaves):
        cells = 4 * 2**octave
        coarse = rng.random((cells, cells))
        tex += cv2.resize(coarse, (size_px, size_px), interpolation=cv2.INTER_CUBIC) / 2**octave
    tex += 0.6 * (rng.random((size_px, size_px)) > 0.985)  # sparse bright dots: crisp corners
    tex = cv2.GaussianBlur(tex, (0, 0), 1.0)
    tex -= tex.min()
    return np.clip(255.0 * tex / max(tex.max(), 1e-12), 0, 255).astype(np.uint8)


@dataclass(frozen=True)
class TexturedPlane:
    """A rectangle in the world: ``origin_xyz`` is its corner, ``axis_u``/``axis_v`` unit edge directions,
    ``size_m`` its (width, height), ``texture`` a uint8 image stretched over it."""

    origin_xyz: np.ndarray
    axis_u: np.ndarray
    axis_v: np.ndarray
    size_m: tuple[float, float]
    texture: np.ndarray

    def corners_xyz(self) -> np.ndarray:
        """``(4, 3)`` world corners."""
        w, h = self.size_m
        return np.array([self.origin_xyz, self.origin_xyz + w * self.axis_u, self.origin_xyz + w * self.axis_u
                         + h * self.axis_v, self.origin_xyz + h * self.axis_v])

    def homography(self, T_cam_world: np.ndarray, K: np.ndarray) -> np.ndarray:
        """``(3, 3)`` map from texture pixels (col, row) to image pixels."""
        th, tw = self.texture.shape[:2]
        su, sv = self.size_m[0] / tw, self.size_m[1] / th
        R, t = T_cam_world[:3, :3], T_cam_world[:3, 3]
        return K @ np.column_stack([R @ self.axis_u * su, R @ self.axis_v * sv, R @ self.origin_xyz + t])


@dataclass(frozen=True)
class PlaneScene:
    """A set of textured planes; build one with :func:`make_plane_scene`."""

    planes: tuple[TexturedPlane, ...]
    background: int = 0

    def render(self, T_world_cam: np.ndarray, K: np.ndarray, size_wh: tuple[int, int]) -> np.ndarray:
        """Grayscale uint8 image ``(h, w)`` seen by a camera at ``T_world_cam`` with intrinsics ``K``."""
        w, h = size_wh
        T_cam_world = se3_inverse(np.asarray(T_world_cam, np.float64))
        depths = []
        for plane in self.planes:
            corners_cam = plane.corners_xyz() @ T_cam_world[:3, :3].T + T_cam_world[:3, 3]
            if np.any(corners_cam[:, 2] <= 0.1):
                raise ConfigError("a plane reaches behind the camera; keep every plane in front of all poses",
                                  source="PlaneScene.render")
            depths.append(float(corners_cam[:, 2].mean()))
        image = np.full((h, w), self.background, np.uint8)
        for index in np.argsort(depths)[::-1]:  # far to near
            plane = self.planes[index]
            H = plane.homography(T_cam_world, K)
            warped = cv2.warpPerspective(plane.texture, H, (w, h), flags=cv2.INTER_LINEAR)
            mask = cv2.warpPerspective(np.full(plane.texture.shape[:2], 255, np.uint8), H, (w, h),
                                       flags=cv2.INTER_NEAREST)
            image[mask > 0] = warped[mask > 0]
        return image


def make_plane_scene(rng: np.random.Generator, n_planes: int = 6, texture_px: int = 512) -> PlaneScene:
    """Planes in front of a camera at the origin looking along +z: a large back wall at 40 m and
    ``n_planes - 1`` tilted panels between 6 and 25 m spread over the field of view."""
    planes = [TexturedPlane(np.array([-40.0, -25.0, 40.0]), np.array([1.0, 0, 0]), np.array([0, 1.0, 0]),
                            (80.0, 50.0), random_texture(rng, texture_px))]
    depths = np.linspace(6.0, 25.0, max(n_planes - 1, 0))
    for i, depth in enumerate(depths):
        angle = i * 2.39996  # golden angle: spread the panels around the view axis
        lateral = 0.35 * depth * np.array([np.cos(angle), 0.6 * np.sin(angle)])
        size = 0.35 * depth
        tilt = so3_exp(rng.uniform(-0.5, 0.5, 3) * np.array([1.0, 1.0, 0.3]))
        u, v = tilt[:, 0], tilt[:, 1]
        center = np.array([lateral[0], lateral[1], depth])
        origin = center - 0.5 * size * (u + v)
        planes.append(TexturedPlane(origin, u, v, (size, size), random_texture(rng, texture_px)))
    return PlaneScene(tuple(planes))


def forward_trajectory(n_frames: int, step_m: float = 0.5, yaw_rate_deg: float = 0.5, lateral_m: float = 0.05,
                       rng: np.random.Generator | None = None) -> Trajectory:
    """Camera poses ``T_world_cam`` moving mostly forward (+z) with a little yaw and sideways wobble."""
    poses = []
    for k in range(n_frames):
        jitter = rng.normal(0, 0.02, 3) if rng is not None else np.zeros(3)
        t = np.array([lateral_m * np.sin(0.7 * k), 0.02 * np.cos(0.5 * k), step_m * k]) + jitter * (k > 0)
        R = so3_exp(np.radians([0.2 * np.sin(0.9 * k), yaw_rate_deg * k, 0.1 * np.cos(0.4 * k)]))
        poses.append(make_se3(R, t))
    return Trajectory(np.array(poses), np.arange(n_frames) * 0.1, name="sim_camera")


def default_K(size_wh: tuple[int, int] = (640, 480), focal_px: float = 500.0) -> np.ndarray:
    """Intrinsics with the principal point at the image centre."""
    w, h = size_wh
    return np.array([[focal_px, 0, (w - 1) / 2.0], [0, focal_px, (h - 1) / 2.0], [0, 0, 1.0]])


def render_sequence(scene: PlaneScene, trajectory: Trajectory, K: np.ndarray,
                    size_wh: tuple[int, int] = (640, 480)) -> list[np.ndarray]:
    """One rendered image per pose of ``trajectory``."""
    return [scene.render(T, K, size_wh) for T in trajectory.poses_se3]
