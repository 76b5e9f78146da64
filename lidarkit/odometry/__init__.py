"""Sequence odometry: run any registered ICP variant over a scan sequence.

>>> from lidarkit.odometry import run
>>> result = run("sim:street?frames=150", "kiss", out_dir="results/kiss_street")  # ~140 m: one 100 m drift segment
>>> result.trajectory          # Trajectory of T_world_lidar, first pose = identity
>>> result.metrics["kitti_drift"]["translation_pct"], result.fps

``run`` returns an :class:`OdometryResult` (the trajectory plus per-frame timing and registration
diagnostics, the resolved config and the metrics) rather than a bare Trajectory, so that one call
gives everything a run folder holds. Stateless variants are chained scan-to-scan with a
constant-velocity initial guess (``init = previous relative motion``); stateful ones (``kiss``) get
every frame through ``register_frame`` and keep their own map. Every run records what it really applied
(``metrics["effective"]``: deskew and why, instants, reader corrections), names the alignment of every score,
and counts the frames failing an independent per-frame check (``metrics["frame_check"]``) for every variant.
"""

from lidarkit.odometry.frame_check import FrameCheckConfig
from lidarkit.odometry.inputs import FrameSelection, open_sequence, parse_frames
from lidarkit.odometry.metrics import odometry_metrics
from lidarkit.odometry.result import FrameStats, OdometryResult
from lidarkit.odometry.run_folder import write_run
from lidarkit.odometry.runner import config_dict, run

__all__ = ["FrameCheckConfig", "FrameSelection", "FrameStats", "OdometryResult", "config_dict", "odometry_metrics", "open_sequence", "parse_frames", "run", "write_run"]
