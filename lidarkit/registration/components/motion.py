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

    def deskew(self, points_xyz: np.ndarray, point_times_s: np.ndarray | None, delta: np.ndarray) -> np.ndarray:
        if not self.config.deskew or point_times_s is None or len(point_times_s) == 0:
            return points_xyz
        times = np.asarray(point_times_s, dtype=np.float64).ravel()
        t0, t1 = float(times.min()), float(times.max())
        if not t1 > t0:
            return points_xyz
        s = (times - t0) / (t1 - t0) - REFERENCE_FRACTION[self.config.reference]
        omega = se3_log(delta)
        R, t = se3_exp_batch(s[:, None] * omega[None, :])
        return np.einsum("nij,nj->ni", R, points_xyz) + t


__all__ = ["REFERENCE_FRACTION", "ConstantVelocity", "Motion", "NoMotion", "se3_exp_batch"]
