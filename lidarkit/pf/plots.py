"""Figures for particle-filter runs (matplotlib, Agg backend; every file written atomically)."""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np

from lidarkit.atomic import atomic_path, save_figure


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _draw_scene(ax, result, upto: int | None = None) -> None:
    end = None if upto is None else upto + 1
    ax.scatter(*result.landmarks_xy.T, marker="*", s=140, c="gold", edgecolors="k", zorder=5, label="landmarks")
    if result.ground_truth is not None:
        ax.plot(*result.ground_truth[:end, :2].T, "k-", lw=1.5, label="ground truth")
    label = "noisy odometry" if result.ground_truth is not None else "dead reckoning"
    ax.plot(*result.dead_reckoning[:end, :2].T, "--", c="tab:gray", lw=1, label=label)
    for name, color in (("mean", "tab:blue"), ("best", "tab:red")):
        if name in result.estimates:
            ax.plot(*result.estimates[name][:end, :2].T, c=color, lw=1.2, label=f"PF estimate ({name})")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(alpha=0.3)


def plot_trajectory(result, path: str | os.PathLike, title: str | None = None) -> Path:
    """Ground truth, noisy odometry (dead reckoning), PF estimate(s) and landmarks in the plane."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7, 6))
    _draw_scene(ax, result)
    mse = result.metrics.get("mse_m2", {})
    subtitle = ", ".join(f"MSE {k} {v:.3f} m²" for k, v in mse.items())
    ax.set_title(title or f"particle filter, N={result.config.particle_count_label()}" + (f"\n{subtitle}" if subtitle else ""))
    ax.legend(loc="best", fontsize=8)
    return _save(fig, path)


def plot_snapshots(result, path: str | os.PathLike, steps: Sequence[int] | None = None) -> Path:
    """Particle clouds (weight-coloured, heading arrows) at chosen steps, one panel each."""
    plt = _pyplot()
    steps = sorted(result.snapshots) if steps is None else [s for s in steps if s in result.snapshots]
    if not steps:
        raise ValueError("no snapshots recorded for the requested steps (run with snapshot_steps=...)")
    cols = min(3, len(steps))
    rows = int(np.ceil(len(steps) / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(5 * cols, 4.6 * rows), squeeze=False)
    for ax, step in zip(axes.ravel(), steps):
        _draw_particles(ax, result, step)
    for ax in axes.ravel()[len(steps):]:
        ax.axis("off")
    axes.ravel()[0].legend(loc="best", fontsize=7)
    return _save(fig, path)


def _draw_particles(ax, result, step: int, max_arrows: int = 300) -> None:
    particles, weights = result.snapshots[step]
    _draw_scene(ax, result, upto=step)
    order = np.argsort(weights)
    ax.scatter(particles[order, 0], particles[order, 1], c=weights[order], s=4, cmap="viridis", zorder=3)
    k = order[-max_arrows:]
    ax.quiver(particles[k, 0], particles[k, 1], np.cos(particles[k, 2]), np.sin(particles[k, 2]), color="tab:purple",
              alpha=0.4, scale=40, width=0.003, zorder=4)
    if result.ground_truth is not None:
        ax.plot(*result.ground_truth[step, :2], "ko", ms=7, mfc="none", mew=2, zorder=6)
    ax.set_title(f"step {step}")


def frame_limits(result, margin: float = 0.05) -> tuple[tuple[float, float], tuple[float, float]]:
    """``((xmin, xmax), (ymin, ymax))`` holding everything any frame of :func:`animate` draws (landmarks, paths, every
    snapshot's particles), widened by ``margin`` of the span on each side."""
    paths = [result.landmarks_xy, result.dead_reckoning[:, :2], *(e[:, :2] for e in result.estimates.values())]
    if result.ground_truth is not None:
        paths.append(result.ground_truth[:, :2])
    paths += [particles[:, :2] for particles, _ in result.snapshots.values()]
    xy = np.concatenate([np.asarray(p, dtype=np.float64) for p in paths])
    xy = xy[np.isfinite(xy).all(axis=1)]
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    pad = np.maximum(hi - lo, 1.0) * margin
    return (float(lo[0] - pad[0]), float(hi[0] + pad[0])), (float(lo[1] - pad[1]), float(hi[1] + pad[1]))


def animate(result, path: str | os.PathLike, fps: int = 10, on_frame: Callable[[], None] | None = None) -> Path:
    """GIF of the particle cloud over every recorded snapshot (matplotlib PillowWriter); ``on_frame``: called after
    each frame is drawn (progress)."""
    plt = _pyplot()
    from matplotlib.animation import PillowWriter

    steps = sorted(result.snapshots)
    if not steps:
        raise ValueError("no snapshots recorded (run with snapshot_steps=...)")
    fig, ax = plt.subplots(figsize=(6, 5.5))
    writer = PillowWriter(fps=fps)
    path = Path(path)
    (x0, x1), (y0, y1) = frame_limits(result)
    with atomic_path(path) as tmp:
        with writer.saving(fig, str(tmp), dpi=70):
            for step in steps:
                ax.clear()
                _draw_particles(ax, result, step)
                ax.set_xlim(x0, x1)  # the same box every frame (rescaled to each frame's cloud, the map jumped)
                ax.set_ylim(y0, y1)
                writer.grab_frame()
                if on_frame is not None:
                    on_frame()
    plt.close(fig)
    return path


def plot_mse_vs_n(
    series: Mapping[str, tuple[Sequence[int], Sequence[float], Sequence[float]]],
    path: str | os.PathLike,
    *,
    reference: Mapping[str, float] | None = None,
    title: str = "position MSE vs number of particles",
) -> Path:
    """One line (mean +- std over seeds) per configuration: ``{label: (n_values, mean, std)}``; log-scale MSE."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(8, 5))
    for label, (ns, mean, std) in series.items():
        ns, mean, std = np.asarray(ns), np.asarray(mean), np.asarray(std)
        ax.plot(ns, mean, marker="o", ms=3, label=label)
        ax.fill_between(ns, np.maximum(mean - std, mean / 3), mean + std, alpha=0.12)
    for label, value in (reference or {}).items():
        ax.axhline(value, ls=":", c="k", lw=1)
        ax.text(ax.get_xlim()[1], value, f" {label}", va="center", fontsize=7)
    ax.set_yscale("log")
    ax.set_xlabel("number of particles N")
    ax.set_ylabel("position MSE from step 10 [m²]")
    ax.set_title(title)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7, ncol=2)
    return _save(fig, path)


def plot_particle_count(
    counts: Mapping[str, np.ndarray], path: str | os.PathLike, title: str = "particles per step",
    errors_m: Mapping[str, np.ndarray] | None = None, mark_step: int | None = None,
) -> Path:
    """Particle count per step (KLD-sampling) for one or more runs, optionally with their position errors below."""
    plt = _pyplot()
    rows = 2 if errors_m else 1
    fig, axes = plt.subplots(rows, 1, figsize=(8, 3.2 * rows), sharex=True, squeeze=False)
    ax = axes[0, 0]
    for label, n in counts.items():
        ax.step(np.arange(len(n)), n, where="post", lw=1.2, label=label)
    ax.set_yscale("log")
    ax.set_ylabel("particles N")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    ax.set_title(title)
    if errors_m:
        ax2 = axes[1, 0]
        for label, e in errors_m.items():
            ax2.plot(np.arange(len(e)), e, lw=1, label=label)
        ax2.axhline(0.5, c="k", ls=":", lw=1)
        ax2.set_yscale("log")
        ax2.set_ylabel("position error [m]")
        ax2.grid(alpha=0.3, which="both")
    for a in axes[:, 0]:
        if mark_step is not None:
            a.axvline(mark_step, c="tab:red", ls="--", lw=1)
    axes[-1, 0].set_xlabel("step")
    return _save(fig, path)


def _save(fig, path: str | os.PathLike) -> Path:
    plt = _pyplot()
    fig.tight_layout()
    save_figure(fig, path, dpi=110)
    plt.close(fig)
    return Path(path)


__all__ = ["animate", "frame_limits", "plot_mse_vs_n", "plot_particle_count", "plot_snapshots", "plot_trajectory"]
