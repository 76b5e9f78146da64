"""The files each command writes into a run folder (``--out``), in one place.

A run into a folder replaces every file any of these commands writes there and that this run does not write (see
:func:`lidarkit.atomic.run_folder`'s ``replaces``): an earlier run's ground truth or plots, or another command's
files (a VO run into an odometry run's folder kept its ``ape.png`` and ``timing.csv`` beside the new poses), are never
read as this run's. A user's own files stay.
"""

from __future__ import annotations

ODOMETRY = ("poses_kitti.txt", "poses_tum.txt", "ground_truth_kitti.txt", "config.yaml", "metrics.json", "timing.csv",
            "pose_covariance.txt", "trajectory.png", "ape.png")
VO = ("poses_kitti.txt", "poses_tum.txt", "poses_smoothed_kitti.txt", "poses_smoothed_tum.txt", "diagnostics.csv",
      "config.yaml", "metrics.json", "trajectory.png", "features.gif")
PF = ("config.yaml", "metrics.json", "study.json", "poses_kitti.txt", "poses_tum.txt", "dead_reckoning_tum.txt",
      "ground_truth_tum.txt", "trajectory.png", "particles.png", "particles_per_step.png", "animation.gif")

#: every name above: what a run into a folder replaces
RUN_FILES = tuple(sorted(set(ODOMETRY) | set(VO) | set(PF)))
#: what `lidarkit icp --out` writes (it replaces nothing else)
ICP = ("result.json", "config.json", "bev.png", "rmse.png")

__all__ = ["ICP", "ODOMETRY", "PF", "RUN_FILES", "VO"]
