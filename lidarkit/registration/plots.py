"""Figures for registration results: bird's-eye view before/after, RMSE per iteration.

Kept apart from the algorithms (matplotlib is imported only here, lazily, with the Agg backend);
every figure is written atomically.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from lidarkit.atomic import save_figure
from lidarkit.geometry import transform_points


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _thin(points_xyz: np.ndarray, max_points: int, seed: int = 0) -> np.ndarray:
    if len(points_xyz) <= max_points:
        return points_xyz
    return points_xyz[np.random.default_rng(seed).choice(len(points_xyz), max_points, replace=False)]


def save_bev_before_after(
    path: str | os.PathLike,
    source_xyz: np.ndarray,
    target_xyz: np.ndarray,
    T_target_source: np.ndarray,
    init_T: np.ndarray | None = None,
    title: str = "",
    extent_m: float = 40.0,
    max_points: int = 60000,
) -> Path:
    """Two BEV panels (x forward, y left, target frame): source at ``init_T`` and at the estimate, ``extent_m``
    around the sensor, or around the target's median point when that lies farther out (a georeferenced cloud; the
    axes then count from that point)."""
    plt = _pyplot()
    src = _thin(np.asarray(source_xyz, dtype=np.float64), max_points, 1)
    dst = _thin(np.asarray(target_xyz, dtype=np.float64), max_points, 2)
    centre = np.median(dst[:, :2], axis=0)
    if np.abs(centre).max() <= extent_m:
        centre = np.zeros(2)
    shift = np.array([*centre, 0.0])
    before = transform_points(np.eye(4) if init_T is None else init_T, src) - shift
    after = transform_points(T_target_source, src) - shift
    dst = dst - shift
    fig, axes = plt.subplots(1, 2, figsize=(12, 6), sharex=True, sharey=True)
    for ax, moved, label in ((axes[0], before, "before"), (axes[1], after, "after")):
        ax.scatter(dst[:, 0], dst[:, 1], s=0.2, c="tab:blue", alpha=0.5, linewidths=0, label="target")
        ax.scatter(moved[:, 0], moved[:, 1], s=0.2, c="tab:red", alpha=0.5, linewidths=0, label="source")
        ax.set_title(f"{label} registration")
        ax.set_xlim(-extent_m, extent_m)
        ax.set_ylim(-extent_m, extent_m)
        ax.set_aspect("equal")
        ax.set_xlabel("x (m)" if not centre.any() else f"x - {centre[0]:.1f} (m)")
        ax.legend(loc="upper right", markerscale=20)
    axes[0].set_ylabel("y (m)" if not centre.any() else f"y - {centre[1]:.1f} (m)")
    if title:
        fig.suptitle(title)
    return _save(plt, fig, path)


def save_rmse_history(path: str | os.PathLike, histories: dict[str, Sequence[float]], title: str = "",
                      coarse_iterations: dict[str, int] | None = None, empty_note: str = "no RMSE recorded") -> Path:
    """RMSE of the correspondences (m) against iteration, one line per labelled run. ``coarse_iterations``: per run
    with a coarse-to-fine schedule (``result.extra["coarse_iterations"]``), where its history passes from every k-th
    source point to all of them: drawn dashed up to there and marked, since the two stages' RMSE are of other points
    (the full cloud's is higher at the same pose: the curve steps up at the switch). A run without any RMSE (not
    assessed) draws nothing; with none at all the figure says ``empty_note`` (an empty plot read "final RMSE only")."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7, 4.5))
    if not any(len(hist) for hist in histories.values()):
        ax.text(0.5, 0.5, empty_note, ha="center", va="center", transform=ax.transAxes)
    for label, hist in histories.items():
        hist = np.asarray(hist, dtype=float)
        if len(hist) == 0:
            continue
        if len(hist) == 1:  # a backend that reports its final RMSE only
            ax.plot(np.arange(len(hist)), hist, marker="o", linestyle="none", label=f"{label} (final RMSE only)")
            continue
        switch = (coarse_iterations or {}).get(label)
        if switch is None or not 0 < switch < len(hist) - 1:
            ax.plot(np.arange(len(hist)), hist, marker=".", label=label)
            continue
        line, = ax.plot(np.arange(switch + 1), hist[: switch + 1], marker=".", linestyle="--", label=f"{label} (coarse: subsampled source)")
        ax.plot(np.arange(switch + 1, len(hist)), hist[switch + 1:], marker=".", color=line.get_color(), label=f"{label} (all points)")
        ax.axvline(switch + 0.5, color=line.get_color(), linestyle=":", alpha=0.6)
    ax.set_xlabel("iteration")
    ax.set_ylabel("correspondence RMSE (m)")
    ax.grid(True, alpha=0.3)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=8)
    if title:
        ax.set_title(title)
    return _save(plt, fig, path)


def _save(plt, fig, path: str | os.PathLike) -> Path:
    fig.tight_layout()
    save_figure(fig, path, dpi=90)
    plt.close(fig)
    return Path(path)


__all__ = ["save_bev_before_after", "save_rmse_history"]
