"""Components a registration pipeline is composed of, one small registry per kind.

Kinds (:data:`KINDS`): ``motion`` (prediction and deskew), ``preprocess`` (range crop, voxel downsample,
ground filter), ``map`` (scan-to-scan or voxel-hash local map), ``residual`` (point-to-point, point-to-plane,
plane-to-plane), ``kernel`` (none, Huber, Cauchy, Geman-McClure, Tukey) and ``threshold`` (fixed, adaptive).

>>> from lidarkit.registration.components import available_components, make_component
>>> available_components("kernel")
['cauchy', 'geman_mcclure', 'huber', 'none', 'tukey']
>>> import numpy as np
>>> huber = make_component("kernel", {"name": "huber", "scale_m": 0.3})
>>> huber.weights(np.array([0.01, 1.0]), sigma_m=1.0)  # squared residuals (m^2): residuals of 0.1 and 1 m
array([1. , 0.3])

Third-party components: subclass the kind's base (``Kernel``, ``Residual``, ...) and declare an entry point
``KIND.NAME = "pkg.module:Class"`` in the group ``lidarkit.components``.
"""

from __future__ import annotations

from lidarkit.registration.components.registry import (
    ENTRY_POINT_GROUP,
    KINDS,
    Component,
    ComponentConfig,
    available_components,
    component_fields,
    get_component_class,
    make_component,
    register_component,
    reload_component_plugins,
)

# Built-in components register on import (explicit list, no file scanning).
from lidarkit.registration.components.kernels import Kernel  # noqa: E402
from lidarkit.registration.components.maps import Map  # noqa: E402
from lidarkit.registration.components.motion import Motion  # noqa: E402
from lidarkit.registration.components.preprocessing import Preprocess  # noqa: E402
from lidarkit.registration.components.residuals import Residual  # noqa: E402
from lidarkit.registration.components.thresholds import Threshold  # noqa: E402

__all__ = [
    "ENTRY_POINT_GROUP",
    "KINDS",
    "Component",
    "ComponentConfig",
    "Kernel",
    "Map",
    "Motion",
    "Preprocess",
    "Residual",
    "Threshold",
    "available_components",
    "component_fields",
    "get_component_class",
    "make_component",
    "register_component",
    "reload_component_plugins",
]
