"""ICP registration: a registry of variants sharing one interface and one result type.

>>> from lidarkit.registration import get_icp
>>> result = get_icp("vanilla", max_correspondence_distance_m=1.0).align(source_xyz, target_xyz)
>>> result.T_target_source, result.degeneracy.degenerate
"""

from __future__ import annotations

from lidarkit.registration.base import (
    DEGENERACY_RATIO_THRESHOLD,
    Degeneracy,
    Registration,
    RegistrationConfig,
    RegistrationResult,
)
from lidarkit.registration.registry import (
    ENTRY_POINT_GROUP,
    available_icp,
    config_fields,
    get_icp,
    get_icp_class,
    register_icp,
    reload_plugins,
)

# Built-in variants register themselves on import (explicit list, no file scanning).
from lidarkit.registration import vanilla  # noqa: E402,F401
from lidarkit.registration import ground_filtered  # noqa: E402,F401
from lidarkit.registration import knn  # noqa: E402,F401
from lidarkit.registration import kiss  # noqa: E402,F401
from lidarkit.registration import open3d_icp  # noqa: E402,F401
from lidarkit.registration import small_gicp_icp  # noqa: E402,F401  (registers only if small_gicp imports)
from lidarkit.registration import pipeline  # noqa: E402,F401
from lidarkit.registration import genz  # noqa: E402,F401  (registers only if genz_icp imports)

__all__ = [
    "DEGENERACY_RATIO_THRESHOLD",
    "ENTRY_POINT_GROUP",
    "Degeneracy",
    "Registration",
    "RegistrationConfig",
    "RegistrationResult",
    "available_icp",
    "config_fields",
    "get_icp",
    "get_icp_class",
    "register_icp",
    "reload_plugins",
]
