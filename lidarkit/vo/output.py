"""Run folder of a VO run: poses (raw + smoothed, KITTI + TUM), diagnostics CSV, resolved config, metrics, plot, GIF.

Everything is written atomically. matplotlib and Pillow are imported only by the plot / GIF writers.
"""

from __future__ import annotations

import csv
import io
import logging
import os
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import yaml

from lidarkit import atomic
from lidarkit.geometry import se3_inverse
from lidarkit.run_files import RUN_FILES
from lidarkit.trajectory import Trajectory
from lidarkit.vo.pipeline import FrameDiagnostics, VOResult

log = logging.getLogger(__name__)

NO_TIMESTAMPS_NOTE = "no time stamps given: poses_tum.txt and poses_smoothed_tum.txt use frame numbers as seconds"


def diagnostics_csv(rows: list[FrameDiagnostics]) -> str:
    """CSV text with one row per frame (features, matches, inliers, method, scale, accepted, reason, runtime)."""
    buf = io.StringIO()
    fields = list(FrameDiagnostics.__dataclass_fields__)
    writer = csv.DictWriter(buf, fieldnames=fields, lineterminator="\n")
    writer.writeheader()
    for d in rows:
        writer.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in d.__dict__.items()})
    return buf.getvalue()


def plot_vo_trajectories(path: str | os.PathLike, trajectories: dict[str, Trajectory], title: str = "") -> Path:
    """Top view (x-z plane of the first camera, see :func:`draw_top_view`) of several trajectories, e.g. ground truth,
    raw and smoothed."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6.5, 5.0), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    draw_top_view(ax, trajectories)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("z (forward) [m]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    if title:
        ax.set_title(title, fontsize=9)
    return atomic.save_figure(fig, path)


def draw_top_view(ax: Any, trajectories: dict[str, Trajectory]) -> None:
    """One curve per trajectory on the matplotlib axes ``ax``, its end marked by a dot of its colour (the marker was
    derived from the line style, and "C0-" gave none). Every curve is drawn in the camera frame of the ground truth's
    first pose (the curve labelled "ground truth...", else the first curve), x against z: a top view whatever the
    world's axes (world x against z drew a TUM run, whose mocap world has z up, from the side)."""
    styles = ["k-", "C0-", "C1--", "C2-", "C3-.", "C4:"]
    if not trajectories:
        return
    reference = next((traj for label, traj in trajectories.items() if label.startswith("ground truth")),
                     next(iter(trajectories.values())))
    T_first_world = se3_inverse(reference.poses_se3[0])
    for (label, traj), style in zip(trajectories.items(), styles * 3):
        xyz = (T_first_world @ traj.poses_se3)[:, :3, 3]
        (line,) = ax.plot(xyz[:, 0], xyz[:, 2], style, lw=1.4, label=label)
        ax.plot(xyz[-1, 0], xyz[-1, 2], "o", color=line.get_color(), ms=4)


def aligned_to_ground_truth(ground_truth: Trajectory, trajectories: dict[str, Trajectory], first_frame: int = 0,
                            align: str = "sim3") -> dict[str, Trajectory]:
    """The ground truth and ``trajectories`` aligned onto it (labels end in e.g. "(Sim(3)-aligned)", the table's
    wording), each by the alignment fitted on its frames from ``first_frame`` on, as the scores fit it, then applied
    to all its frames. Frames before it (unreadable at the start) only hold the start pose: fitted with them, the
    plotted VO end lay 1.15 m beyond the GT end of a run scored at APE 0.014 m. EvaluationError if none aligns."""
    from lidarkit.eval import align_trajectory
    from lidarkit.eval.ape_rpe import alignment_label

    curves = {"ground truth": ground_truth}
    for label, traj in trajectories.items():
        _, T = align_trajectory(ground_truth[first_frame:], traj[first_frame:], align)
        curves[f"{label} ({alignment_label(align)})"] = T.applied_to(traj)
    return curves


def _drawable(image: np.ndarray) -> np.ndarray:
    """A BGR copy of a frame MonoVO accepts, grey or colour (BGR / BGRA): colour frames crashed the GIF
    (cv2 "Bad number of channels") and the whole run folder was lost."""
    image = np.asarray(image)
    if image.ndim == 2:
        return cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    return cv2.cvtColor(image, cv2.COLOR_BGRA2BGR) if image.shape[2] == 4 else image.copy()


def write_feature_gif(path: str | os.PathLike, images: Any, tracks: list[tuple[int, np.ndarray, np.ndarray]],
                      max_frames: int = 60, width_px: int = 640, fps: float = 8.0) -> Path:
    """Animated GIF of the inlier tracks (reference -> current position) drawn on the first ``max_frames`` accepted
    frames (a GIF of a whole sequence is too large to open; the log says when it stops early)."""
    from PIL import Image

    if len(tracks) > max_frames:
        log.info("features.gif: the first %d of %d accepted frames", max_frames, len(tracks))

    read = images.read_image if hasattr(images, "read_image") else (lambda i: images[i])
    frames = []
    for frame, pts_ref, pts_cur in tracks[:max_frames]:
        image = _drawable(read(frame))
        for (x0, y0), (x1, y1) in zip(pts_ref.astype(int), pts_cur.astype(int)):
            cv2.line(image, (x0, y0), (x1, y1), (0, 200, 0), 1)
            cv2.circle(image, (x1, y1), 2, (0, 0, 255), -1)
        scale = width_px / image.shape[1]
        image = cv2.resize(image, (width_px, int(round(image.shape[0] * scale))), interpolation=cv2.INTER_AREA)
        frames.append(Image.fromarray(cv2.cvtColor(image, cv2.COLOR_BGR2RGB)).convert("P", palette=Image.ADAPTIVE))
    with atomic.atomic_path(path) as tmp:
        if frames:
            frames[0].save(tmp, format="GIF", save_all=True, append_images=frames[1:], duration=int(1000 / fps), loop=0)
        else:
            Image.new("P", (8, 8)).save(tmp, format="GIF")
    return Path(path)


def write_run(result: VOResult, out_dir: str | os.PathLike, *, ground_truth: Trajectory | None = None,
              metrics: dict[str, Any] | None = None, extra_config: dict[str, Any] | None = None,
              plot: bool = True, gif_images: Any = None, frame_numbers: Any = None) -> dict[str, Path]:
    """Write the run folder and return ``{name: path}``; ``frame_numbers``: the input's number of each frame (a run
    from ``--start 10`` is frames 10, 11, ...), the TUM files' stamps when the input has no time stamps (else 0, 1, ...).

    Files: ``poses_kitti.txt``, ``poses_tum.txt``, ``poses_smoothed_kitti.txt``, ``poses_smoothed_tum.txt``,
    ``diagnostics.csv``, ``config.yaml`` (resolved config + intrinsics + ``extra_config``), ``metrics.json``
    (summary + ``metrics``), ``trajectory.png`` (if ``plot``), ``features.gif`` (if ``gif_images`` and tracks).
    Without time stamps the TUM files count frames as seconds: logged once and noted in config and metrics.
    A folder that never held a run but holds files named like a run's is refused, as ``lidarkit vo --out`` refuses it
    (a user's own metrics.json was replaced).
    """
    final = Path(out_dir)
    atomic.check_target(final, "folder", files=RUN_FILES, replaces=RUN_FILES)
    with atomic.run_folder(final, replaces=RUN_FILES) as tmp:
        paths = _write_files(result, tmp, ground_truth=ground_truth, metrics=metrics, extra_config=extra_config,
                             plot=plot, gif_images=gif_images, frame_numbers=frame_numbers)
    return {name: final / path.relative_to(tmp) for name, path in paths.items()}


def _write_files(result: VOResult, out: Path, *, ground_truth: Trajectory | None, metrics: dict[str, Any] | None,
                 extra_config: dict[str, Any] | None, plot: bool, gif_images: Any, frame_numbers: Any = None) -> dict[str, Path]:
    notes = {}
    trajectory, smoothed = result.trajectory, result.smoothed()
    if trajectory.timestamps_s is None:
        log.warning(NO_TIMESTAMPS_NOTE)
        notes["timestamps"] = NO_TIMESTAMPS_NOTE
        if frame_numbers is not None:  # (a run from --start 10 was stamped 0, 1, ...: paired with another run's frame 0)
            stamps = np.asarray(frame_numbers, dtype=np.float64)
            trajectory, smoothed = trajectory.with_timestamps(stamps), smoothed.with_timestamps(stamps)
    paths = {
        "poses_kitti": trajectory.to_kitti(out / "poses_kitti.txt"),
        "poses_tum": trajectory.to_tum(out / "poses_tum.txt"),
        "poses_smoothed_kitti": smoothed.to_kitti(out / "poses_smoothed_kitti.txt"),
        "poses_smoothed_tum": smoothed.to_tum(out / "poses_smoothed_tum.txt"),
        "diagnostics": atomic.write_text(out / "diagnostics.csv", diagnostics_csv(result.diagnostics)),
    }
    from lidarkit.provenance import code_version

    config = {"lidarkit_version": code_version(), "vo": result.config.model_dump(mode="json"), "K": np.asarray(result.K).tolist(),
              **(extra_config or {}), **notes}
    paths["config"] = atomic.write_text(out / "config.yaml", yaml.safe_dump(config, sort_keys=False))
    summary = {**result.summary(), **(metrics or {}), **notes}
    from lidarkit.eval.report import write_json

    paths["metrics"] = write_json(summary, out / "metrics.json")
    if plot:
        trajs = {"ground truth": ground_truth} if ground_truth is not None else {}
        trajs.update({"VO raw": result.trajectory, "VO smoothed": smoothed})
        if ground_truth is not None and result.config.scale.mode != "gt":
            from lidarkit.errors import EvaluationError

            try:  # a ground truth on a straight line has no Sim(3) alignment: the run is unscored, its plot unaligned
                trajs = aligned_to_ground_truth(ground_truth, {"VO raw": result.trajectory, "VO smoothed": smoothed},
                                                first_frame=int(result.meta.get("start_frame", 0)))
            except EvaluationError as err:
                log.warning("trajectory plot not aligned to the ground truth: %s", err.reason)
        paths["plot"] = plot_vo_trajectories(out / "trajectory.png", {k: v for k, v in trajs.items() if v is not None},
                                             title=result.trajectory.name)
    if gif_images is not None and result.tracks:
        paths["gif"] = write_feature_gif(out / "features.gif", gif_images, result.tracks)
    return paths
