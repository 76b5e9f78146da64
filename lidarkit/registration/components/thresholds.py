"""Association thresholds: the distance within which a map point counts as a correspondence.

A threshold exposes ``sigma_m`` (the expected alignment error, which ``"adaptive"`` kernels scale with) and
``max_distance_m`` (``3 sigma`` as in kiss-icp). ``adaptive`` is kiss-icp's estimator: sigma is the RMS of the
model deviations (``inv(prediction) @ estimate``) seen so far whose size exceeds ``min_motion_m``, started with
one sample equal to ``initial_threshold_m``; a deviation's size is its translation plus the displacement its
rotation causes at ``max_range_m`` (``2 r sin(theta / 2)``).
"""

from __future__ import annotations

import numpy as np
from pydantic import Field

from lidarkit.geometry import rotation_angle_rad
from lidarkit.registration.components.registry import Component, ComponentConfig, component_base, register_component


@component_base("threshold")
class Threshold(Component):
    """Stateful: :meth:`update` sees every frame's model deviation; :meth:`reset` starts a new sequence."""

    def reset(self) -> None:
        pass

    @property
    def sigma_m(self) -> float:
        raise NotImplementedError

    @property
    def max_distance_m(self) -> float:
        return 3.0 * self.sigma_m

    def update(self, model_deviation: np.ndarray) -> None:
        pass


class FixedThresholdConfig(ComponentConfig):
    max_distance_m: float | None = Field(1.0, gt=0, description="correspondence distance (m); None: every nearest neighbour")


@register_component("threshold", "fixed")
class FixedThreshold(Threshold):
    """A constant distance; sigma is a third of it (infinite when unlimited: the pipeline refuses a kernel scaled by it)."""

    Config = FixedThresholdConfig

    @property
    def sigma_m(self) -> float:
        d = self.config.max_distance_m
        return float("inf") if d is None else d / 3.0

    @property
    def max_distance_m(self) -> float:
        d = self.config.max_distance_m
        return float("inf") if d is None else float(d)


class AdaptiveThresholdConfig(ComponentConfig):
    initial_threshold_m: float = Field(2.0, gt=0, description="sigma before any motion was seen (m)")
    min_motion_m: float = Field(0.1, ge=0, description="model deviations smaller than this are not counted (m)")
    max_range_m: float = Field(100.0, gt=0, description="range at which a rotation error is measured (m); the pipeline passes its own")


@register_component("threshold", "adaptive")
class AdaptiveThreshold(Threshold):
    """kiss-icp's adaptive threshold (RMS of the model deviations of past frames)."""

    Config = AdaptiveThresholdConfig

    def __init__(self, config=None, **params):
        super().__init__(config, **params)
        self.reset()

    def reset(self) -> None:
        self._sse_m2 = self.config.initial_threshold_m**2
        self._n = 1

    @property
    def sigma_m(self) -> float:
        return float(np.sqrt(self._sse_m2 / self._n))

    def update(self, model_deviation: np.ndarray) -> None:
        T = np.asarray(model_deviation, dtype=np.float64)
        theta = float(rotation_angle_rad(T[:3, :3]))
        error = float(np.linalg.norm(T[:3, 3])) + 2.0 * self.config.max_range_m * np.sin(theta / 2.0)
        if error > self.config.min_motion_m:
            self._sse_m2 += error * error
            self._n += 1


__all__ = ["AdaptiveThreshold", "FixedThreshold", "Threshold"]
