"""lidarkit: LiDAR registration, particle-filter localization and monocular VO, scored by one evaluation layer."""

from lidarkit.errors import ConfigError, DataError, LidarKitError, RegistrationError
from lidarkit.trajectory import Trajectory

__version__ = "0.1.0"

__all__ = ["ConfigError", "DataError", "LidarKitError", "RegistrationError", "Trajectory", "__version__"]
