"""lidarkit: LiDAR registration, particle-filter localization and monocular VO, scored by one evaluation layer."""

from lidarkit.errors import ConfigError, DataError, EvaluationError, LidarKitError, OutputError, RegistrationError

__version__ = "0.1.0"


def __getattr__(name: str):
    # Trajectory (numpy, scipy) loads on first use, so `lidarkit` starts fast enough to handle Ctrl-C from the start
    if name == "Trajectory":
        from lidarkit.trajectory import Trajectory

        return Trajectory
    raise AttributeError(f"module 'lidarkit' has no attribute {name!r}")


def __dir__() -> list[str]:
    """The names loaded on first use too (tab completion offered no ``Trajectory``), without loading them."""
    return sorted(set(globals()) | set(__all__))


__all__ = ["ConfigError", "DataError", "EvaluationError", "LidarKitError", "OutputError", "RegistrationError", "Trajectory", "__version__"]
