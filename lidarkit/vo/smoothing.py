"""Savitzky-Golay smoothing of trajectory translations (rotations are left untouched)."""

from __future__ import annotations

import numpy as np
from scipy.signal import savgol_filter

from lidarkit.errors import ConfigError
from lidarkit.trajectory import Trajectory
from lidarkit.vo.config import SmoothingConfig


def smooth_translations(trajectory: Trajectory, window: int = 9, polyorder: int = 2) -> Trajectory:
    """Copy of ``trajectory`` with its positions filtered by a Savitzky-Golay filter (``window`` poses, ``polyorder``).

    With time stamps the polynomials are fitted against the stamps, so a dropped frame is a longer step, not a jump
    (fitted over the frame index, one frame missing from a simulated drive raised the APE 26-fold); without them
    ``savgol_filter`` runs over the frame index. The window shrinks to the largest odd length that fits; a trajectory
    too short for a window above ``polyorder + 1`` (which a polynomial of that order fits exactly) is returned
    unchanged. ``meta["smoothing"]`` says what was applied (the window used, or why nothing was). ``window`` and
    ``polyorder`` follow :class:`SmoothingConfig`'s rules (ConfigError otherwise: polyorder 2.5 fitted a cubic).
    """
    window, polyorder = _checked(window, polyorder)
    n = len(trajectory)
    win = min(window, n if n % 2 else n - 1)
    if win % 2 == 0:
        win -= 1
    name = trajectory.name + "_smoothed"
    if win <= polyorder + 1:  # (polyorder + 1 points: the polynomial passes through each of them)
        note = f"not smoothed: {n} poses leave no odd window above polyorder + 1 ({polyorder + 1})"
        return Trajectory(trajectory.poses_se3.copy(), trajectory.timestamps_s, name=name, meta={**trajectory.meta, "smoothing": note})
    poses = trajectory.poses_se3.copy()
    if trajectory.timestamps_s is None:
        poses[:, :3, 3] = savgol_filter(poses[:, :3, 3], win, polyorder, axis=0, mode="interp")
    else:
        poses[:, :3, 3] = _savgol_over_time(poses[:, :3, 3], trajectory.timestamps_s, win, polyorder)
    note = f"window {win}, polyorder {polyorder}" + (f" (window {window} shrunk to fit {n} poses)" if win != window else "")
    return Trajectory(poses, trajectory.timestamps_s, name=name, meta={**trajectory.meta, "smoothing": note})


def _checked(window: int, polyorder: int) -> tuple[int, int]:
    """``window``, ``polyorder`` as :class:`SmoothingConfig` accepts them; its ConfigError, naming the argument."""
    try:
        cfg = SmoothingConfig(window=window, polyorder=polyorder)
    except ConfigError as err:
        field = (err.source or "").removeprefix("vo config smoothing").removeprefix(".")
        raise ConfigError(err.reason, source=field or "smooth_translations") from None
    return cfg.window, cfg.polyorder


def _savgol_over_time(values: np.ndarray, timestamps_s: np.ndarray, window: int, polyorder: int) -> np.ndarray:
    """``values (N, D)`` smoothed by least-squares polynomials in time over ``window`` consecutive samples: centred on
    each sample, and the first / last ``window`` samples' fit for the ends (``savgol_filter``'s ``mode="interp"``,
    which this equals for evenly spaced stamps). ``window <= N``."""
    n = len(values)
    first = np.clip(np.arange(n) - window // 2, 0, n - window)  # each sample's window start
    members = first[:, None] + np.arange(window)  # (N, window)
    step_s = float(np.median(np.diff(timestamps_s)))
    # times relative to the smoothed sample, in steps (conditioning): the fit's constant term is its value there
    dt = (timestamps_s[members] - timestamps_s[:, None]) / step_s
    vandermonde = dt[:, :, None] ** np.arange(polyorder + 1)  # (N, window, polyorder + 1)
    weights = np.linalg.pinv(vandermonde)[:, 0, :]  # (N, window): row of the constant term
    return np.einsum("nw,nwd->nd", weights, values[members])
