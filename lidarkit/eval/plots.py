"""PNG plots of evaluation results (matplotlib, Agg canvas; no global backend change, nothing shown).

Only this module imports matplotlib; every file is written atomically.
"""

from __future__ import annotations

import os
import textwrap
from pathlib import Path

import numpy as np

from lidarkit.atomic import save_figure
from lidarkit.errors import ConfigError
from lidarkit.eval.ape_rpe import APEResult, RPEResult
from lidarkit.eval.evaluate import Evaluation
from lidarkit.trajectory import Trajectory

PLANES = ("auto", "xy", "xz", "yz")
_AXIS = {"x": 0, "y": 1, "z": 2}


def literal_text(text: object) -> str:
    """``text`` (a name from a file, a suite or a record) as matplotlib draws it, letter for letter: two ``$`` in it
    (``drive_$1_$2``) were read as math, and its parse error ended the plot."""
    return str(text).replace("$", r"\$")


def _figure(width_in: float, height_in: float):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width_in, height_in), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _wrapped(title: str, width_in: float, fontsize: float) -> str:
    """``title`` broken into lines that fit ``width_in`` inches at ``fontsize`` pt (~0.8 em a character): a long title
    is cut at the figure's edge otherwise."""
    return textwrap.fill(title, max(20, int(width_in * 72 / (0.8 * fontsize))))


def choose_plane(ref: Trajectory, plane: str = "auto") -> str:
    """The two axes to draw: as given, or (``auto``) the two along which the reference spreads most.

    ``auto`` gives ``xy`` for usual world/LiDAR frames (z up) and ``xz`` for KITTI camera-frame poses (y down).
    """
    if plane not in PLANES:
        raise ConfigError(f"unknown plot plane {plane!r}; known: {', '.join(PLANES)}", source="plane")
    if plane != "auto":
        return plane
    spread = np.ptp(ref.positions_xyz, axis=0) if len(ref) else np.ones(3)
    keep = sorted(np.argsort(spread)[1:])
    return "".join("xyz"[i] for i in keep)


def _draw_trajectories(ax, ref: Trajectory, est: Trajectory, plane: str, est_label: str) -> None:
    i, j = _AXIS[plane[0]], _AXIS[plane[1]]
    p_ref, p_est = ref.positions_xyz, est.positions_xyz
    ax.plot(p_ref[:, i], p_ref[:, j], "--", color="0.3", lw=1.2, label=literal_text(ref.name or "reference"))
    ax.plot(p_est[:, i], p_est[:, j], "-", color="tab:blue", lw=1.0, label=literal_text(est_label))
    ax.plot(p_ref[:1, i], p_ref[:1, j], "ko", ms=4, label="start")
    ax.set_xlabel(f"{plane[0]} (m)")
    ax.set_ylabel(f"{plane[1]} (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, lw=0.3)
    ax.legend(fontsize=8, loc="best")


def _error_axis(result: APEResult | RPEResult) -> tuple[np.ndarray, str]:
    """x values of each error: seconds from start when timestamps exist, else frame index."""
    frames = result.pairs[:, 1] if isinstance(result, RPEResult) else np.arange(result.n_errors)
    ts = result.ref.timestamps_s
    if ts is not None and len(frames):
        return ts[frames] - ts[0], "time from start (s)"
    return frames.astype(float), "frame"


def _draw_errors(ax, result: APEResult | RPEResult) -> None:
    x, xlabel = _error_axis(result)
    ax.plot(x, result.errors, lw=0.8, color="tab:red")
    ax.axhline(result.rmse, color="k", lw=0.8, ls="--", label=f"rmse {result.rmse:.4g}")
    ax.axhline(result.mean, color="tab:green", lw=0.8, ls=":", label=f"mean {result.mean:.4g}")
    kind = "APE" if isinstance(result, APEResult) else "RPE"
    ax.set_xlabel(xlabel)
    ax.set_ylabel(f"{kind} {result.relation} ({result.unit})")
    # evo's RPE title runs to ~100 characters ("... for delta = 1 (frames) using consecutive pairs (with SE(3) Umeyama
    # alignment)"), wider than a panel of the evaluation figure: wrapped to the panel's width (6 in), not cut at its edge
    ax.set_title(_wrapped(result.title, 6.0, 8), fontsize=8)
    ax.grid(True, lw=0.3)
    ax.legend(fontsize=8, loc="upper left")


def plot_trajectories(
    ref: Trajectory, est: Trajectory, path: str | os.PathLike, *, plane: str = "auto", title: str = ""
) -> Path:
    """Top view of both trajectories (pass the aligned estimate, e.g. ``APEResult.est_aligned``) as a PNG."""
    plane = choose_plane(ref, plane)
    fig = _figure(6.5, 6.0)
    ax = fig.add_subplot(1, 1, 1)
    _draw_trajectories(ax, ref, est, plane, est.name or "estimate")
    if title:
        ax.set_title(title, fontsize=9)
    return save_figure(fig, path)


def plot_errors(result: APEResult | RPEResult, path: str | os.PathLike) -> Path:
    """Error over time (or frames) of an APE/RPE result, with its rmse and mean, as a PNG."""
    fig = _figure(8.0, 3.5)
    _draw_errors(fig.add_subplot(1, 1, 1), result)
    return save_figure(fig, path)


def plot_evaluation(evaluation: Evaluation, path: str | os.PathLike, *, plane: str = "auto") -> Path:
    """Four panels: trajectories after alignment, APE and RPE over time, KITTI drift per segment length."""
    ape_res = evaluation.ape
    plane = choose_plane(ape_res.ref, plane)
    fig = _figure(12.0, 9.0)
    axes = fig.subplots(2, 2)
    from lidarkit.eval.ape_rpe import alignment_label

    transform = ape_res.alignment
    scaled = transform is not None and transform.rescaled
    est_label = f"{evaluation.est_name or 'estimate'} ({alignment_label(ape_res.align)}" + (f", scale {transform.scale:.4g})" if scaled else ")")
    _draw_trajectories(axes[0, 0], ape_res.ref, ape_res.est_aligned, plane, est_label)
    axes[0, 0].set_title(literal_text(f"{evaluation.est_name} vs {evaluation.ref_name}"), fontsize=9)
    _draw_errors(axes[0, 1], ape_res)
    _draw_errors(axes[1, 0], evaluation.rpe)
    _draw_drift(axes[1, 1], evaluation, scaled)
    return save_figure(fig, path)


def _draw_drift(ax, evaluation: Evaluation, scaled: bool) -> None:
    """KITTI drift per segment length, translation and rotation side by side (or why it was not computed)."""
    drift = evaluation.drift
    if drift is None or not drift.valid:
        ax.text(0.5, 0.5, f"KITTI drift not computed:\n{evaluation.drift_note}", ha="center", va="center", fontsize=9)
        ax.set_axis_off()
    else:
        # one slot per length, in ascending order (bars placed at the lengths themselves were 4 m wide for lengths
        # 100, 110, 800, and lengths given as (800, 100) drew each bar at the other's length)
        rows = sorted((r for r in drift.per_length if r.n_segments), key=lambda r: r.length_m)
        slots = np.arange(len(rows), dtype=np.float64)
        ax.bar(slots - 0.2, [r.translation_pct for r in rows], 0.4, color="tab:blue", label="translation (%)")
        ax2 = ax.twinx()
        ax2.bar(slots + 0.2, [r.rotation_deg_per_100m for r in rows], 0.4, color="tab:orange",
                label="rotation (deg/100 m)")
        ax.set_xticks(slots, [f"{r.length_m:g}" for r in rows])
        ax.set_xlabel("segment length (m)")
        ax.set_ylabel("translational error (%)")
        ax2.set_ylabel("rotational error (deg/100 m)")
        ax.set_title(
            f"KITTI drift: {drift.translation_pct:.3f} %, {drift.rotation_deg_per_100m:.3f} deg/100 m "
            f"({drift.n_segments} segments" + (", estimate unscaled)" if scaled else ")"),
            fontsize=9,
        )
        handles = ax.get_legend_handles_labels()[0] + ax2.get_legend_handles_labels()[0]
        # the twin is drawn after ``ax``, its rotation bars over ``ax``'s legend: ``ax`` (without its background) on top
        ax.set_zorder(ax2.get_zorder() + 1)
        ax.patch.set_visible(False)
        ax.legend(handles, [h.get_label() for h in handles], fontsize=8, loc="upper right")


def segment_counts_text(grid) -> str:
    """How many segments each method's box holds and their lengths: "4 segments per method (100 m)" or "kiss 4,
    vanilla 6 segments (100-300 m)" (a total over the methods beside "100-800 m" read as 8 segments of every length
    where each of two methods had 4 of 100 m). ``grid`` as in :func:`plot_segment_boxplots`."""
    counts: dict[str, int] = {}
    for (_, method), s in grid.items():
        counts[method] = counts.get(method, 0) + int(np.asarray(s.length_m).size)
    lengths = sorted({float(x) for s in grid.values() for x in np.asarray(s.length_m).ravel()})
    if len(set(counts.values())) <= 1:
        n = next(iter(counts.values()), 0)
        text = f"{n} segment{'s' * (n != 1)}" + (" per method" if len(counts) > 1 else "")
    else:
        text = ", ".join(f"{method} {n}" for method, n in counts.items()) + " segments"
    if not lengths:
        return text
    steps = np.diff(lengths)
    if len(lengths) > 2 and np.allclose(steps, steps[0]):
        return f"{text} ({lengths[0]:g}-{lengths[-1]:g} m)"
    return f"{text} ({', '.join(f'{x:g}' for x in lengths)} m)"


def plot_segment_boxplots(grid, path: str | os.PathLike, quantity: str = "translation_pct") -> Path:
    """Box plots of the per-segment KITTI errors, one box per method (segments pooled over sequences).

    ``grid`` maps ``(sequence, method)`` to :class:`lidarkit.eval.tables.SegmentErrors`.
    """
    from lidarkit.eval.tables import QUANTITIES

    methods = list(dict.fromkeys(m for _, m in grid))
    data = [np.concatenate([getattr(s, quantity) for (_, m), s in grid.items() if m == method] or [np.zeros(0)])
            for method in methods]
    width_in = max(4.0, 0.9 * len(methods) + 2.0)
    fig = _figure(width_in, 3.6)
    ax = fig.add_subplot(1, 1, 1)
    ax.boxplot([d if d.size else [np.nan] for d in data], showfliers=True, flierprops={"markersize": 2})
    ax.set_xticks(range(1, len(methods) + 1), [literal_text(m) for m in methods], rotation=20, ha="right", fontsize=8)
    ax.set_ylabel(QUANTITIES.get(quantity, quantity))
    title = f"per-segment KITTI {QUANTITIES.get(quantity, quantity)}: {segment_counts_text(grid)}"
    ax.set_title(literal_text(_wrapped(title, width_in, 9)), fontsize=9)  # (cut at the edge of the 4 in figure of one method)
    ax.grid(axis="y", alpha=0.3)
    return save_figure(fig, path)
