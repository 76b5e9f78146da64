"""Savitzky-Golay smoothing of trajectory translations (rotations are left untouched)."""

from __future__ import annotations

from scipy.signal import savgol_filter

from lidarkit.trajectory import Trajectory


def smooth_translations(trajectory: Trajectory, window: int = 9, polyorder: int = 2) -> Trajectory:
    """Copy of ``trajectory`` with its positions filtered by ``savgol_filter(window, polyorder)`` along time.

    The window shrinks to the largest odd length that fits; trajectories shorter than ``polyorder + 2`` poses are
    returned unchanged.
    """
    n = len(trajectory)
    win = min(window, n if n % 2 else n - 1)
    if win % 2 == 0:
        win -= 1
    if win <= polyorder:
        return trajectory.with_name(trajectory.name + "_smoothed")
    poses = trajectory.poses_se3.copy()
    poses[:, :3, 3] = savgol_filter(poses[:, :3, 3], win, polyorder, axis=0, mode="interp")
    return Trajectory(poses, trajectory.timestamps_s, name=trajectory.name + "_smoothed", meta=dict(trajectory.meta))
