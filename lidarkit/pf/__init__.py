"""Particle-filter localization against point landmarks (the Freiburg range-bearing data).

Core math only (no plotting, no file reading): motion and sensor models (:mod:`models`),
resampling schemes (:mod:`resampling`), the vectorized :class:`ParticleFilter`, the
Kalman-particle kernel variant (:mod:`kalman_kernel`), and the report's protocol (:mod:`protocol`).
Plots live in :mod:`lidarkit.pf.plots` (matplotlib, imported only there).
"""

from lidarkit.pf.config import PFConfig
from lidarkit.pf.filter import ParticleFilter, make_filter
from lidarkit.pf.models import OdometryMotionModel, RangeBearingModel, integrate_odometry, resolve_q, wrap_angle
from lidarkit.pf.protocol import PFRunResult, run_protocol, run_recorded
from lidarkit.pf.resampling import available_resamplers, effective_sample_size, get_resampler

__all__ = [
    "OdometryMotionModel",
    "PFConfig",
    "PFRunResult",
    "ParticleFilter",
    "RangeBearingModel",
    "available_resamplers",
    "effective_sample_size",
    "get_resampler",
    "integrate_odometry",
    "make_filter",
    "resolve_q",
    "run_protocol",
    "run_recorded",
    "wrap_angle",
]
