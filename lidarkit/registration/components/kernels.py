"""Robust kernels: per-correspondence weights ``w(r^2)`` of iteratively reweighted least squares.

Each kernel has a scale ``c``: a fixed length (``scale_m``), or tied to the threshold's current sigma
(``scale_m="adaptive"``: ``c = sigma``), or ``"kiss"``: kiss-icp 1.3 weighs a squared residual ``r^2`` by
``sigma^2 / (sigma + r^2)^2``, which is the Geman-McClure weight ``c^4 / (c^2 + r^2)^2`` with ``c^2 = sigma * 1 m``.
Weights are scaled so that ``w(0) = 1``; a common factor does not change the Gauss-Newton step.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field, field_validator

from lidarkit.registration.components.registry import (
    Component, ComponentConfig, component_base, output_error, register_component,
)


class KernelConfig(ComponentConfig):
    scale_m: float | Literal["adaptive", "kiss"] = Field(
        "adaptive", description="kernel scale c (m); 'adaptive': the threshold's sigma; 'kiss': c^2 = sigma x 1 m (kiss-icp 1.3)"
    )

    @field_validator("scale_m")
    @classmethod
    def _positive(cls, value):
        if not isinstance(value, str) and not value > 0:
            raise ValueError(f"must be > 0, got {value}")
        return value


@component_base("kernel")
class Kernel(Component):
    """Maps squared residuals ``(N,)`` m^2 to IRLS weights ``(N,)``."""

    Config = KernelConfig

    def scale(self, sigma_m: float) -> float:
        """The kernel scale ``c`` (m) for the threshold's current ``sigma_m``."""
        s = self.config.scale_m
        if s == "adaptive":
            return float(sigma_m)
        if s == "kiss":
            return float(np.sqrt(sigma_m))
        return float(s)

    def weights(self, residual2: np.ndarray, sigma_m: float) -> np.ndarray:
        c = self.scale(sigma_m)
        if not np.isfinite(c):
            return np.ones_like(residual2)
        return self._weights(np.asarray(residual2, dtype=np.float64), c)

    def _weights(self, r2: np.ndarray, c: float) -> np.ndarray:
        raise NotImplementedError


def checked_weights(kernel: Kernel, residual2: np.ndarray, sigma_m: float) -> np.ndarray:
    """``kernel.weights``, checked to give one weight per residual (a plugin's 3 weights for 2365 residuals was
    numpy's "matmul: ... mismatch", naming no kernel)."""
    w = np.asarray(kernel.weights(residual2, sigma_m))
    if w.shape != residual2.shape:
        raise output_error(kernel, f"{w.size} weights for {len(residual2)} residuals (one per residual expected)")
    bad = ~(np.isfinite(w) & (w >= 0))  # (NaN weights were scipy's "'x' must be finite", naming no kernel)
    if bad.any():
        raise output_error(kernel, f"{int(bad.sum())} of {w.size} weights that are not finite numbers >= 0")
    return w


class NoKernelConfig(ComponentConfig):
    pass


@register_component("kernel", "none")
class NoKernel(Kernel):
    """Plain least squares: every correspondence weighs 1."""

    Config = NoKernelConfig

    def weights(self, residual2: np.ndarray, sigma_m: float) -> np.ndarray:
        return np.ones_like(np.asarray(residual2, dtype=np.float64))


@register_component("kernel", "huber")
class HuberKernel(Kernel):
    """Quadratic within ``c``, linear beyond: ``w = min(1, c / |r|)``."""

    def _weights(self, r2: np.ndarray, c: float) -> np.ndarray:
        r = np.sqrt(r2)
        return np.where(r <= c, 1.0, c / np.maximum(r, 1e-300))


@register_component("kernel", "cauchy")
class CauchyKernel(Kernel):
    """``w = 1 / (1 + r^2 / c^2)``: heavy-tailed, never zero."""

    def _weights(self, r2: np.ndarray, c: float) -> np.ndarray:
        return 1.0 / (1.0 + r2 / (c * c))


@register_component("kernel", "geman_mcclure")
class GemanMcClureKernel(Kernel):
    """``w = c^4 / (c^2 + r^2)^2``: redescending; with ``scale_m='kiss'`` exactly kiss-icp's weighting."""

    def _weights(self, r2: np.ndarray, c: float) -> np.ndarray:
        c2 = c * c
        return (c2 * c2) / np.square(c2 + r2)


@register_component("kernel", "tukey")
class TukeyKernel(Kernel):
    """Tukey biweight ``w = (1 - r^2 / c^2)^2`` within ``c``, 0 beyond."""

    def _weights(self, r2: np.ndarray, c: float) -> np.ndarray:
        return np.square(np.clip(1.0 - r2 / (c * c), 0.0, None))


__all__ = ["CauchyKernel", "GemanMcClureKernel", "HuberKernel", "Kernel", "KernelConfig", "NoKernel", "TukeyKernel"]
