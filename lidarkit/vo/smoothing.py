"""Savitzky-Golay smoothing of trajectory translations (rotations are left untouched)."""

from __future__ import annotations

from scipy.signal import savgol_filter

from lidarkit.trajectory import Trajectory


def smooth_translations(trajectory: Trajectory, window: int = 9, polyorder: int = 2) -> Trajectory:
    """Copy of ``trajectory`` with its positions filtered by ``savgol_filter(window, polyorder)`` along time.

    The window shrinks to the largest odd length that fits; a trajectory too short for a window above ``polyorder + 1``
    (which a polynomial of that order fits exactly) is returned unchanged. ``meta["smoothing"]`` says what was applied (the window used, or why nothing was).
    """
    n = len(trajectory)
    win = min(window, n if n % 2 else n - 1)
    if win % 2 == 0:
        win -= 1
    name = trajectory.name + "_smoothed"
    if win <= polyorder + 1:  # (polyorder + 1 points: the polynomial passes through each of them)
        note = f"not smoothed: {n} poses leave no odd window above polyorder + 1 ({polyorder + 1})"
        return Trajectory(trajectory.poses_se3.copy(), trajectory.timestamps_s, name=name, meta={**trajectory.meta, "smoothing": note})
    poses = trajectory.poses_se3.copy()
    poses[:, :3, 3] = savgol_filter(poses[:, :3, 3], win, polyorder, axis=0, mode="interp")
    note = f"window {win}, polyorder {polyorder}" + (f" (window {window} shrunk to fit {n} poses)" if win != window else "")
    return Trajectory(poses, trajectory.timestamps_s, name=name, meta={**trajectory.meta, "smoothing": note})
