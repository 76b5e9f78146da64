"""Motion prediction and deskew: the initial guess of each frame and the correction of its motion distortion.

``constant_velocity`` predicts ``T_k = T_(k-1) @ delta`` with ``delta = inv(T_(k-2)) @ T_(k-1)`` and, when a
sweep has per-point times, moves every point to the ``reference`` instant of its sweep assuming the sweep
moved by ``delta``: a point at normalised time ``s`` in ``[0, 1]`` becomes ``exp((s - s_ref) log(delta)) p``,
``s_ref`` 0 / 0.5 / 1 for ``start`` / ``middle`` / ``end``. Times are normalised by the sweep's own first and
last point time (as kiss-icp 1.3, which deskews to the ``end``); the returned poses refer to that instant.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field

from lidarkit.geometry import se3_log
from lidarkit.registration.components.registry import Component, ComponentConfig, component_base, register_component

#: Normalised time of each deskew reference instant within the sweep.
REFERENCE_FRACTION = {"start": 0.0, "middle": 0.5, "end": 1.0}


def se3_exp_batch(xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotations ``(N, 3, 3)`` and translations ``(N, 3)`` of twists ``(N, 6)`` (translation part first)."""
    xi = np.asarray(xi, dtype=np.float64).reshape(-1, 6)
    rho, phi = xi[:, :3], xi[:, 3:]
    theta = np.linalg.norm(phi, axis=1)
    K = np.zeros((len(xi), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -phi[:, 2], phi[:, 1], -phi[:, 0]
    K[:, 1, 0], K[:, 2, 0], K[:, 2, 1] = phi[:, 2], -phi[:, 1], phi[:, 0]
    K2 = K @ K
    small = theta < 1e-10
    t = np.where(small, 1.0, theta)
    a = np.where(small, 1.0, np.sin(t) / t)
    b = np.where(small, 0.5, (1.0 - np.cos(t)) / t**2)
    c = np.where(small, 1.0 / 6.0, (t - np.sin(t)) / t**3)
    eye = np.eye(3)
    R = eye + a[:, None, None] * K + b[:, None, None] * K2
    V = eye + b[:, None, None] * K + c[:, None, None] * K2
    return R, np.einsum("nij,nj->ni", V, rho)


@component_base("motion")
class Motion(Component):
    """Predicts the next pose from the last two and deskews a sweep given the last relative motion."""

    #: the instant of the sweep the returned poses refer to (when the sweep is deskewed)
    reference: str = "end"

    def predict(self, last_pose: np.ndarray, last_delta: np.ndarray) -> np.ndarray:
        return np.array(last_pose, dtype=np.float64)

    def deskew(self, points_xyz: np.ndarray, point_times_s: np.ndarray | None, delta: np.ndarray) -> np.ndarray:
        return points_xyz

    def reported(self, T_world_lidar: np.ndarray, delta: np.ndarray) -> np.ndarray:
        """The pose to report for a deskewed sweep registered at ``T_world_lidar`` that moved by ``delta``."""
        return T_world_lidar

    def first_reported(self, T_world_lidar: np.ndarray, delta: np.ndarray) -> np.ndarray:
        """The pose at the reported instant of one of the first two sweeps, deskewed with no motion known (the
        identity), once the sweep's motion ``delta`` is known: both are taken at their end (kiss-icp's convention, the
        instant of its poses) and restated alike, so that the step between them stays the one registered."""
        return T_world_lidar


class NoMotionConfig(ComponentConfig):
    pass


@register_component("motion", "none")
class NoMotion(Motion):
    """No prediction (the initial guess is the previous pose) and no deskew."""

    Config = NoMotionConfig


class ConstantVelocityConfig(ComponentConfig):
    deskew: bool = Field(True, description="correct the motion distortion when per-point times are given")
    reference: Literal["start", "middle", "end"] = Field("end", description="instant each deskewed sweep (and its pose) refers to")


@register_component("motion", "constant_velocity")
class ConstantVelocity(Motion):
    """Constant-velocity prediction and (optional) deskew to the sweep's ``reference`` instant."""

    Config = ConstantVelocityConfig

    @property
    def reference(self) -> str:  # type: ignore[override]
        return self.config.reference

    def predict(self, last_pose: np.ndarray, last_delta: np.ndarray) -> np.ndarray:
        return np.asarray(last_pose, dtype=np.float64) @ np.asarray(last_delta, dtype=np.float64)

    @property
    def registered_at(self) -> str:
        """The instant a sweep is deskewed to and registered at: the reference, except that a sweep reported at its
        ``start`` is registered at its end. Deskewed to the start with the last motion, the pose error is not damped
        (the error left by a wrong motion estimate feeds the next one with the opposite sign: it alternated and grew,
        8.8 m / 90 deg after 60 simulated sweeps against 0.22 m at the end)."""
        return "end" if self.config.reference == "start" else self.config.reference

    def deskew(self, points_xyz: np.ndarray, point_times_s: np.ndarray | None, delta: np.ndarray) -> np.ndarray:
        if not self.config.deskew:
            return points_xyz
        return deskew_constant_velocity(points_xyz, point_times_s, delta, self.registered_at)

    def reported(self, T_world_lidar: np.ndarray, delta: np.ndarray) -> np.ndarray:
        """A sweep registered at its end and reported at its start: the end pose moved back by the sweep's motion."""
        if self.config.reference != "start":
            return T_world_lidar
        from lidarkit.geometry import se3_inverse

        return np.asarray(T_world_lidar, dtype=np.float64) @ se3_inverse(delta)

    def first_reported(self, T_world_lidar: np.ndarray, delta: np.ndarray) -> np.ndarray:
        """One of the first two sweeps' poses, taken at the sweep's end, moved back to the reference instant at constant
        velocity (left at its end, a run reported at the start anchored one sweep ahead of its other poses: 1.05 m at
        the end of 12 simulated sweeps at 10 m/s, against 0.10 m reported at the end). The end is a convention: the
        two sweeps, deskewed by nothing, fit each other at one instant, which the later (deskewed) sweeps place about
        mid-sweep on a 32 x 1024 street and about the end on a 16 x 360 one (where the first step is registered 12-37 %
        short); taken at the end, start and middle runs track the end run's error on both."""
        to_end = 1.0 - REFERENCE_FRACTION[self.config.reference]
        if to_end == 0.0:
            return T_world_lidar
        from lidarkit.geometry import se3_fraction, se3_inverse

        return np.asarray(T_world_lidar, dtype=np.float64) @ se3_inverse(se3_fraction(delta, 1.0 / to_end))


def deskew_constant_velocity(points_xyz: np.ndarray, point_times_s: np.ndarray | None, delta: np.ndarray,
                             reference: str = "end") -> np.ndarray:
    """``points_xyz`` moved to the ``reference`` instant of their sweep (start / middle / end) for a sensor that moved
    by ``delta`` over the sweep at constant velocity (see the module doc); unchanged without per-point times or when
    they span no time."""
    if point_times_s is None or len(point_times_s) == 0:
        return points_xyz
    times = np.asarray(point_times_s, dtype=np.float64).ravel()
    t0, t1 = float(times.min()), float(times.max())
    if not t1 > t0:
        return points_xyz
    s = (times - t0) / (t1 - t0) - REFERENCE_FRACTION[reference]
    return exp_scaled_twist_apply(se3_log(delta), s, np.asarray(points_xyz, dtype=np.float64))


def exp_scaled_twist_apply(xi: np.ndarray, s: np.ndarray, points_xyz: np.ndarray) -> np.ndarray:
    """``exp(s_i xi) p_i`` for one twist ``xi`` (translation first) scaled per point by ``s`` ``(N,)``: Rodrigues'
    formula with the one rotation axis, so only per-point scalars are formed (the same as :func:`se3_exp_batch`
    applied point by point, ~4x faster than its ``(N, 3, 3)`` matrices on a 32k-point sweep)."""
    rho, phi = np.asarray(xi[:3], dtype=np.float64), np.asarray(xi[3:], dtype=np.float64)
    w = float(np.linalg.norm(phi))
    if w < 1e-12:
        return points_xyz + s[:, None] * rho[None, :]
    K = np.array([[0.0, -phi[2], phi[1]], [phi[2], 0.0, -phi[0]], [-phi[1], phi[0], 0.0]]) / w  # [u]x, u the unit axis
    theta = s * w
    sin, versine = np.sin(theta), 2.0 * np.sin(0.5 * theta) ** 2  # 1 - cos, without its cancellation
    rotated = points_xyz + sin[:, None] * (points_xyz @ K.T) + versine[:, None] * (points_xyz @ (K @ K).T)
    # V(s phi) (s rho) = s rho + (1 - cos) / w^2 (phi x rho) + (theta - sin) / w^3 (phi x (phi x rho)); near theta = 0
    # the two coefficients by their series (s^2 / 2 and s^3 / 6 to the next order), free of cancellation
    b, c = versine / w**2, (theta - sin) / w**3
    small = np.flatnonzero(np.abs(theta) < 1e-4)
    if small.size:
        s2 = s[small] * s[small]
        b[small] = s2 * (0.5 - s2 * w * w / 24.0)
        c[small] = s2 * s[small] * (1.0 / 6.0 - s2 * w * w / 120.0)
    pr = np.cross(phi, rho)
    return rotated + s[:, None] * rho + b[:, None] * pr + c[:, None] * np.cross(phi, pr)


__all__ = ["REFERENCE_FRACTION", "ConstantVelocity", "Motion", "NoMotion", "deskew_constant_velocity", "exp_scaled_twist_apply", "se3_exp_batch"]
