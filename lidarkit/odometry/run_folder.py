"""The run folder of an odometry run: poses (KITTI + TUM), config, metrics, timing and plots."""

from __future__ import annotations

import datetime as _dt
import os
import platform
import textwrap
from pathlib import Path
from typing import Any

import numpy as np

from lidarkit import atomic
from lidarkit.errors import ConfigError
from lidarkit.odometry.metrics import paired
from lidarkit.odometry.result import OdometryResult
from lidarkit.run_files import RUN_FILES


def write_run(result: OdometryResult, out_dir: str | os.PathLike) -> Path:
    """Write the run folder: poses_kitti.txt, poses_tum.txt, config.yaml, metrics.json, timing.csv, and with
    ground truth ground_truth_kitti.txt, trajectory.png and ape.png; the folder all-or-nothing (``atomic.run_folder``).
    An earlier run's files in the folder that this run does not write are removed (other files are left alone); a folder
    that never held a run but holds files named like a run's is refused, as ``run(out_dir=...)`` refuses it (a user's
    own metrics.json was replaced); so is a folder where the run would replace a file its dataset read, as recorded in
    ``result.config`` (its ground truth replaced by the estimate: the next run scored 3e-16 against itself)."""
    out = Path(out_dir)
    atomic.check_target(out, "folder", files=RUN_FILES, replaces=RUN_FILES)
    _refuse_inputs(_recorded_input_paths(result.config), out)
    with atomic.run_folder(out, replaces=RUN_FILES) as tmp:
        _write_files(result, tmp)
    return out


def refuse_replacing_inputs(sequence: Any, out_dir: str | os.PathLike) -> None:
    """ConfigError (naming ``out_dir``) when a file a run writes or removes in ``out_dir`` is one the dataset reads:
    ``-o g`` over ``folder:g?poses=g/poses_kitti.txt`` replaced the ground truth with the estimate (the next run scored
    0.000). As eval refuses an output that is one of its inputs."""
    _refuse_inputs(_input_paths(sequence), out_dir)


def _refuse_inputs(inputs: dict[Path, str], out_dir: str | os.PathLike) -> None:
    for name in RUN_FILES:
        setting = inputs.get((Path(out_dir) / name).resolve())
        if setting is not None:
            raise ConfigError(f"{Path(out_dir) / name} is an input of the dataset (its {setting}): a run never replaces it; "
                              "give another folder", source="out_dir")


def _input_paths(sequence: Any) -> dict[Path, str]:
    """``{resolved path: setting}`` of the files a reader names in its settings (poses, time stamps, ...): the absolute
    paths of its ``reader_options``, then its public path attributes (``poses_path``, ``times_path``)."""
    reported = getattr(sequence, "reader_options", None)
    items = list(reported.items()) if isinstance(reported, dict) else []
    items += [(k, v) for k, v in (vars(sequence).items() if hasattr(sequence, "__dict__") else ()) if not k.startswith("_")]
    return _absolute_paths(items)


def _recorded_input_paths(config: dict[str, Any]) -> dict[Path, str]:
    """``{resolved path: setting}`` of the files a run's config records its reader read: ``run.dataset_options`` (the
    reader's ``reader_options``) and ``run.effective.reader`` (its settings as applied); a result built without them
    names none."""
    run_config = config.get("run") if isinstance(config, dict) else None
    run_config = run_config if isinstance(run_config, dict) else {}
    effective = run_config.get("effective") if isinstance(run_config.get("effective"), dict) else {}
    items: list[tuple[str, Any]] = []
    for recorded in (run_config.get("dataset_options"), effective.get("reader")):
        items += list(recorded.items()) if isinstance(recorded, dict) else []
    return _absolute_paths(items)


def _absolute_paths(items: list[tuple[str, Any]]) -> dict[Path, str]:
    paths: dict[Path, str] = {}
    for key, value in items:
        if isinstance(value, os.PathLike) or (isinstance(value, str) and os.path.isabs(value)):
            paths.setdefault(Path(value).resolve(), key)
    return paths


def _write_files(result: OdometryResult, out: Path) -> None:
    import json

    import yaml

    traj = result.trajectory
    traj.to_kitti(out / "poses_kitti.txt")
    # without stamps, the frame numbers of timing.csv (rows 0, 1, 2 for --frames 4:10:2 read as frames 0-2)
    tum = traj if traj.timestamps_s is not None else traj.with_timestamps(np.asarray(result.frames, dtype=np.float64))
    tum.to_tum(out / "poses_tum.txt")
    if result.ground_truth is not None:
        result.ground_truth.to_kitti(out / "ground_truth_kitti.txt")
    from lidarkit.provenance import code_version

    config = dict(result.config)
    config["lidarkit_version"] = code_version()
    config["created_utc"] = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    config["machine"] = f"{platform.node()} ({platform.machine()}, {os.cpu_count()} cpus, Python {platform.python_version()})"
    atomic.write_text(out / "config.yaml", yaml.safe_dump(config, sort_keys=False))
    atomic.write_text(out / "metrics.json", json.dumps(result.metrics, indent=2, default=_json_default) + "\n")
    atomic.write_text(out / "timing.csv", result.stats.to_csv())
    if result.pose_covariance is not None:
        from lidarkit.odometry.covariance import POSE_COVARIANCE_PER_POSE  # (not the per-frame one: no such rows here)

        rows = result.pose_covariance.reshape(len(result.pose_covariance), 36)
        header = f"one row per pose: its 6x6 covariance, row-major; {POSE_COVARIANCE_PER_POSE}"
        atomic.write_text(out / "pose_covariance.txt", "# " + header + "\n" + "\n".join(" ".join(f"{v:.9g}" for v in row) for row in rows) + "\n")
    _write_plots(result, out)


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (np.floating, np.integer, np.bool_)):
        return obj.item()
    return str(obj)


def _write_plots(result: OdometryResult, out: Path) -> None:
    """``trajectory.png`` (top view, x-y of the LiDAR frame, estimate vs ground truth) and ``ape.png`` (error over
    time), through ``lidarkit.eval.plots``; only when there is ground truth to compare with."""
    if result.ground_truth is None or len(result.frames) < 2:
        return
    from lidarkit import eval as leval
    from lidarkit.eval import plots

    ref, est = paired(result.ground_truth, result.trajectory)
    # a long --name (300 characters) ran the title off the figure and the legend over the plot ("constrained_layout not
    # applied"): the title wrapped, as eval wraps evo's long titles, and cut at 4 lines; the legend names the method
    title = textwrap.fill(result.trajectory.name, 70, max_lines=4, placeholder=" ...")
    # the LiDAR frame has z up: seen from above (the plane the truth spreads most in was x-z on a straight, flat drive,
    # and the estimate's sideways drift was out of view)
    plots.plot_trajectories(ref.with_name("ground truth"), est.with_name(result.method), out / "trajectory.png", plane="xy",
                            title=title)
    plots.plot_errors(leval.ape(ref, est, align="none", relation="translation"), out / "ape.png")
