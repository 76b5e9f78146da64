"""Sequence odometry: run any registered ICP variant over a scan sequence.

>>> from lidarkit.odometry import run
>>> result = run("sim:street?frames=100", "kiss", out_dir="results/kiss_street")
>>> result.trajectory          # Trajectory of T_world_lidar, first pose = identity
>>> result.metrics["kitti_drift"]["translation_pct"], result.fps

``run`` returns an :class:`OdometryResult` (the trajectory plus per-frame timing and registration
diagnostics, the resolved config and the metrics) rather than a bare Trajectory, so that one call
gives everything a run folder holds. Stateless variants are chained scan-to-scan with a
constant-velocity initial guess (``init = previous relative motion``); stateful ones (``kiss``) get
every frame through ``register_frame`` and keep their own map.
"""

from __future__ import annotations

import csv
import datetime as _dt
import io
import logging
import os
import platform
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from lidarkit import atomic
from lidarkit.errors import ConfigError, DataError, EvaluationError, LidarKitError, RegistrationError
from lidarkit.geometry import orthonormalize_se3, pose_error
from lidarkit.io.base import Scan, ScanSequence
from lidarkit.trajectory import Trajectory

log = logging.getLogger(__name__)

FrameSelection = slice | range | Sequence[int] | np.ndarray | str | None


@dataclass(frozen=True)
class FrameStats:
    """Per-frame diagnostics, one entry per processed frame (arrays of shape ``(n,)``).

    ``read_s`` / ``register_s``: wall time reading the scan and registering it; ``n_points``: points in
    the scan; for stateless variants ``converged``, ``iterations``, ``rmse_m``, ``n_correspondences``,
    ``degenerate`` and ``reason`` of the scan-to-scan alignment that produced the frame's pose;
    ``measured``: False where the runner has no convergence verdict (frame 0 of a stateless chain, every
    frame of a stateful variant such as kiss, which reports none): there ``converged`` is True only as a
    placeholder, iterations -1, rmse NaN, and the CSV / CLI show "n/a"; ``fallback``: the registration was
    rejected (not converged) and the frame's pose uses the previous relative motion (constant velocity).
    """

    frame: np.ndarray
    read_s: np.ndarray
    register_s: np.ndarray
    n_points: np.ndarray
    converged: np.ndarray
    iterations: np.ndarray
    rmse_m: np.ndarray
    n_correspondences: np.ndarray
    degenerate: np.ndarray
    reason: tuple[str, ...]
    measured: np.ndarray
    fallback: np.ndarray

    def to_csv(self) -> str:
        buf = io.StringIO()
        writer = csv.writer(buf, lineterminator="\n")
        writer.writerow([
            "frame", "read_s", "register_s", "n_points", "converged", "iterations", "rmse_m", "n_correspondences", "degenerate",
            "constant_velocity_fallback", "reason",
        ])
        for k in range(len(self.frame)):
            measured = bool(self.measured[k])
            writer.writerow([
                int(self.frame[k]), f"{self.read_s[k]:.6f}", f"{self.register_s[k]:.6f}", int(self.n_points[k]),
                int(self.converged[k]) if measured else "n/a", int(self.iterations[k]) if measured else "n/a",
                f"{self.rmse_m[k]:.6g}" if measured else "n/a", int(self.n_correspondences[k]) if measured else "n/a",
                int(self.degenerate[k]) if measured else "n/a", int(self.fallback[k]), self.reason[k],
            ])
        return buf.getvalue()


@dataclass(frozen=True)
class OdometryResult:
    """What :func:`run` produced: the estimate, how long each frame took, the settings and the scores.

    ``trajectory``: ``T_world_lidar`` of the processed frames (first pose = identity, timestamps from the
    dataset when it has them); ``ground_truth``: the reference it was scored against, expressed relative
    to its first pose (None without ground truth); ``metrics``: the content of ``metrics.json``.
    """

    trajectory: Trajectory
    method: str
    config: dict[str, Any]
    frames: np.ndarray
    stats: FrameStats
    total_time_s: float
    ground_truth: Trajectory | None = None
    metrics: dict[str, Any] = field(default_factory=dict)
    out_dir: Path | None = None

    @property
    def fps(self) -> float:
        """Frames per second of the whole loop (reading + registration)."""
        return len(self.frames) / self.total_time_s if self.total_time_s > 0 else float("inf")

    @property
    def n_not_converged(self) -> int:
        """Frames whose registration was measured and rejected (0 for stateful variants: not measured)."""
        return int((self.stats.measured & ~self.stats.converged).sum())

    @property
    def n_fallback(self) -> int:
        """Frames whose pose came from the constant-velocity motion because registration was rejected."""
        return int(self.stats.fallback.sum())

    @property
    def convergence_measured(self) -> bool:
        """False for stateful variants (kiss): they report no per-frame convergence verdict."""
        return not self.config.get("run", {}).get("stateful", False)


# ---------------------------------------------------------------------------------------------------------------
# Inputs: dataset specs, frame selections
# ---------------------------------------------------------------------------------------------------------------
def open_sequence(spec: str | os.PathLike | ScanSequence) -> ScanSequence:
    """A scan sequence from a spec, or the sequence itself.

    Specs: ``sim:SCENE?key=value&...`` (the simulator, see :func:`lidarkit.sim.lidar.open_sim`);
    ``KIND:PATH[?key=value&...]`` with KIND a :func:`lidarkit.io.available_datasets` reader
    (e.g. ``kitti:/data/kitti?sequence=05``); a plain folder path: a KITTI sequence / odometry root when it
    holds ``velodyne/`` or ``sequences/``, otherwise a folder of scan files.
    """
    if not isinstance(spec, (str, os.PathLike)):
        if isinstance(spec, ScanSequence):
            return spec
        raise ConfigError(f"expected a ScanSequence or a dataset spec, got {type(spec).__name__}", source="dataset")
    from lidarkit import io as lio

    text = os.fspath(spec)
    if text.startswith("sim:"):
        from lidarkit.sim.lidar import open_sim

        return open_sim(text)
    kind, sep, rest = text.partition(":")
    if sep and kind in lio.available_datasets() and len(kind) > 1:
        path, _, query = rest.partition("?")
        from lidarkit.params import parse_kv

        return lio.open_dataset(kind, path, **parse_kv(query, option=f"{kind} dataset option"))
    path = Path(text)
    if not path.exists():
        raise DataError("dataset not found (a folder, KIND:PATH or sim:SCENE?...)", source=text)
    if (path / "velodyne").is_dir() or (path / "sequences").is_dir():
        return lio.open_dataset("kitti", path)
    return lio.open_dataset("folder", path)


def parse_frames(frames: FrameSelection, n_frames: int) -> np.ndarray:
    """Dataset indices selected by ``frames``: None (all), a slice/range, an index list or ``"a:b[:step]"``."""
    if frames is None:
        return np.arange(n_frames)
    if isinstance(frames, str):
        parts = frames.split(":")
        if len(parts) not in (2, 3):
            raise ConfigError("expected START:STOP or START:STOP:STEP (each may be empty)", source=f"frames {frames!r}")
        try:
            frames = slice(*(int(p) if p.strip() else None for p in parts))
        except ValueError:
            raise ConfigError("frame bounds must be integers", source=f"frames {frames!r}") from None
    if isinstance(frames, slice):
        if frames.step == 0:
            raise ConfigError("the step of a frame slice must not be zero", source=f"frames {_frames_repr(frames, np.arange(0))!r}")
        return np.arange(n_frames)[frames]
    idx = np.asarray(list(frames) if isinstance(frames, range) else frames)
    if idx.ndim != 1 or (idx.size and not np.issubdtype(idx.dtype, np.integer)):
        raise ConfigError("frame indices must be a 1-D list of integers", source="frames")
    idx = idx.astype(np.int64)
    if idx.size and (idx.min() < 0 or idx.max() >= n_frames):
        raise ConfigError(f"frame indices must lie in 0..{n_frames - 1}", source="frames")
    if idx.size > 1 and not (np.diff(idx) > 0).all():
        raise ConfigError("frame indices must be strictly increasing", source="frames")
    return idx


def _resolve_method(method: Any, params: dict[str, Any] | None) -> Any:
    if isinstance(method, str):
        from lidarkit.registration import get_icp

        return get_icp(method, **(params or {}))
    if params:
        raise ConfigError("params only apply when the method is given by name", source="params")
    if not hasattr(method, "align") and not hasattr(method, "register_frame"):
        raise ConfigError(f"{type(method).__name__} is not a registration method (no align/register_frame)", source="method")
    return method


def config_dict(config: Any) -> dict[str, Any]:
    """A method's resolved config as plain data (pydantic model, dataclass or mapping)."""
    if config is None:
        return {}
    if hasattr(config, "model_dump"):
        return config.model_dump(mode="json")
    import dataclasses

    if dataclasses.is_dataclass(config):
        return dataclasses.asdict(config)
    return dict(config)


# ---------------------------------------------------------------------------------------------------------------
# The loop
# ---------------------------------------------------------------------------------------------------------------
#: Errors re-raised naming the frame: lidarkit's own and the RuntimeErrors that backends (Open3D, kiss-icp,
#: small_gicp) raise for bad input. Programming errors (AttributeError, TypeError, NotImplementedError, ...)
#: propagate unchanged.
_FRAME_ERRORS = (LidarKitError, RuntimeError)


def _read_nonempty_scan(sequence: ScanSequence, index: int) -> Scan:
    """Frame ``index`` of the sequence; a scan without points is a DataError (named by the caller)."""
    scan = sequence.read_scan(index)
    if len(scan.points_xyz) == 0:
        raise DataError("empty scan (0 points)")
    return scan


def _is_frame_error(err: BaseException) -> bool:
    return isinstance(err, _FRAME_ERRORS) and not isinstance(err, (NotImplementedError, RecursionError))


def _frame_error(err: Exception, dataset_name: str, frame: int) -> LidarKitError:
    """Re-raise an error of frame ``frame`` so that its message names the frame."""
    if isinstance(err, LidarKitError):
        try:
            return type(err)(str(err), source=dataset_name, location=f"frame {frame}")
        except TypeError:  # a subclass with another constructor
            return LidarKitError(str(err), source=dataset_name, location=f"frame {frame}")
    return RegistrationError(f"{type(err).__name__}: {err}", source=dataset_name, location=f"frame {frame}")


def run(
    dataset: ScanSequence | str | os.PathLike,
    method: Any,
    *,
    params: dict[str, Any] | None = None,
    frames: FrameSelection = None,
    out_dir: str | os.PathLike | None = None,
    progress: bool = False,
    ground_truth: Trajectory | None = None,
    strict: bool = False,
) -> OdometryResult:
    """Odometry of ``method`` (a registered name or a configured variant) over ``dataset``.

    ``frames`` selects dataset indices (default all); ``ground_truth`` overrides the dataset's own
    (either one pose per dataset frame or one per selected frame); ``out_dir`` writes the run folder
    (:func:`write_run`); ``progress`` shows a rich progress bar on stderr (the CLI sets it).
    An error in a frame is re-raised as a LidarKitError naming the frame. A stateless registration that
    does not converge is logged (warning naming the frame and the reason) and replaced by the
    constant-velocity motion (previous relative motion) for the frame's pose and the next guess; the
    frames are counted in ``metrics["n_not_converged"]`` / ``["n_constant_velocity_fallback"]``. With
    ``strict=True`` such a frame raises :class:`RegistrationError` naming it instead.
    """
    sequence = open_sequence(dataset)
    registration = _resolve_method(method, params)
    name = getattr(registration, "name", type(registration).__name__) or type(registration).__name__
    dataset_name = str(getattr(sequence, "name", "dataset"))
    n_total = len(sequence)
    if n_total == 0:
        raise DataError("the dataset has no scans", source=dataset_name)
    indices = parse_frames(frames, n_total)
    if len(indices) == 0:
        raise DataError(f"the frame selection {frames!r} selects no scan of {n_total}", source=dataset_name)
    stateful = bool(getattr(registration, "stateful", False))
    n = len(indices)
    poses = np.empty((n, 4, 4))
    read_s = np.zeros(n)
    register_s = np.zeros(n)
    n_points = np.zeros(n, dtype=np.int64)
    converged = np.ones(n, dtype=bool)
    measured = np.zeros(n, dtype=bool)
    fallback = np.zeros(n, dtype=bool)
    iterations = np.full(n, -1, dtype=np.int64)
    rmse_m = np.full(n, np.nan)
    n_corr = np.full(n, -1, dtype=np.int64)
    degenerate = np.zeros(n, dtype=bool)
    reasons = [""] * n

    bar = _progress_bar(n, f"{name} on {dataset_name}") if progress else None
    clock = time.perf_counter
    loop_start = clock()
    try:
        if stateful:
            registration.reset()
            for k, idx in enumerate(indices):
                t0 = clock()
                try:
                    scan = _read_nonempty_scan(sequence, int(idx))
                    points = scan.points_xyz
                    t1 = clock()
                    poses[k] = registration.register_frame(points, scan.point_times_s)
                except Exception as err:
                    if not _is_frame_error(err):
                        raise
                    raise _frame_error(err, dataset_name, int(idx)) from err
                t2 = clock()
                read_s[k], register_s[k], n_points[k] = t1 - t0, t2 - t1, len(points)
                if bar is not None:
                    bar[0].advance(bar[1])
        else:
            motion = np.eye(4)
            previous = None
            for k, idx in enumerate(indices):
                t0 = clock()
                try:
                    scan = _read_nonempty_scan(sequence, int(idx))
                    points = scan.points_xyz
                    t1 = clock()
                    if previous is None:
                        poses[k] = np.eye(4)
                    else:
                        result = registration.align(points, previous, init_T=motion)
                        measured[k] = True
                        converged[k] = bool(result.converged)
                        iterations[k] = int(result.iterations)
                        history = result.rmse_history
                        rmse_m[k] = float(history[-1]) if len(history) else np.nan
                        n_corr[k] = int(result.n_correspondences)
                        deg = getattr(result, "degeneracy", None)
                        degenerate[k] = bool(getattr(deg, "degenerate", False))
                        reasons[k] = str(getattr(result, "reason", "") or "")
                        if converged[k]:
                            motion = orthonormalize_se3(np.asarray(result.T_target_source, dtype=np.float64))
                        poses[k] = poses[k - 1] @ motion
                except Exception as err:
                    if not _is_frame_error(err):
                        raise
                    raise _frame_error(err, dataset_name, int(idx)) from err
                if measured[k] and not converged[k]:
                    why = reasons[k] or "no reason given"
                    if strict:
                        raise RegistrationError(f"registration did not converge ({why})", source=dataset_name, location=f"frame {int(idx)}")
                    fallback[k] = True
                    log.warning(
                        "%s frame %d: %s did not converge (%s); using the constant-velocity motion instead",
                        dataset_name, int(idx), name, why,
                    )
                elif degenerate[k]:
                    log.warning("%s frame %d: %s flagged degenerate geometry (%s)", dataset_name, int(idx), name, reasons[k] or "degenerate")
                t2 = clock()
                previous = points
                read_s[k], register_s[k], n_points[k] = t1 - t0, t2 - t1, len(points)
                if bar is not None:
                    bar[0].advance(bar[1])
    finally:
        if bar is not None:
            bar[0].stop()
    total = clock() - loop_start

    timestamps = sequence.timestamps_s
    timestamps = None if timestamps is None else np.asarray(timestamps, dtype=np.float64)[indices]
    trajectory = Trajectory(poses, timestamps, name=f"{name} on {dataset_name}", meta={"method": name, "dataset": dataset_name})
    reference = _reference(sequence, ground_truth, indices, dataset_name)
    stats = FrameStats(
        indices.copy(), read_s, register_s, n_points, converged, iterations, rmse_m, n_corr, degenerate, tuple(reasons), measured, fallback
    )
    config = {
        "method": name,
        "method_config": config_dict(getattr(registration, "config", None)),
        "run": {
            "dataset": dataset_name,
            "dataset_config": config_dict(getattr(sequence, "config", None)) if hasattr(getattr(sequence, "config", None), "model_dump") else None,
            "frames": _frames_repr(frames, indices),
            "n_frames": n,
            "stateful": stateful,
            "strict": strict,
            "initial_guess": "register_frame (own map and motion model)" if stateful else "constant velocity (previous relative motion)",
            "ground_truth": None if reference is None else reference.name,
            "ground_truth_meta": None if reference is None else _plain(reference.meta),
        },
    }
    result = OdometryResult(trajectory, name, config, indices.copy(), stats, total, reference)
    metrics = odometry_metrics(result)
    result = OdometryResult(trajectory, name, config, indices.copy(), stats, total, reference, metrics)
    if out_dir is not None:
        write_run(result, out_dir)
        result = OdometryResult(trajectory, name, config, indices.copy(), stats, total, reference, metrics, Path(out_dir))
    return result


def _progress_bar(total: int, label: str):
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    bar = Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(), console=Console(stderr=True), transient=True)
    bar.start()
    return bar, bar.add_task(label, total=total)


def _frames_repr(frames: FrameSelection, indices: np.ndarray) -> Any:
    if frames is None:
        return "all"
    if isinstance(frames, str):
        return frames
    if isinstance(frames, slice):
        return f"{'' if frames.start is None else frames.start}:{'' if frames.stop is None else frames.stop}" + (
            "" if frames.step is None else f":{frames.step}"
        )
    return [int(i) for i in indices]


def _plain(meta: dict) -> dict:
    return {str(k): (v if isinstance(v, (str, int, float, bool, type(None))) else str(v)) for k, v in meta.items()}


def _reference(sequence: ScanSequence, ground_truth: Trajectory | None, indices: np.ndarray, dataset_name: str) -> Trajectory | None:
    """Ground truth of the selected frames, relative to its first pose (the estimate starts at identity)."""
    gt = ground_truth if ground_truth is not None else sequence.ground_truth
    if gt is None:
        return None
    if len(gt) == len(sequence):
        gt = gt[indices]
    elif len(gt) != len(indices):
        raise EvaluationError(
            f"ground truth has {len(gt)} poses; expected one per dataset frame ({len(sequence)}) or per selected frame ({len(indices)})",
            source=gt.name or dataset_name,
        )
    return gt.relative_to_first()


# ---------------------------------------------------------------------------------------------------------------
# Scores and the run folder
# ---------------------------------------------------------------------------------------------------------------
def odometry_metrics(result: OdometryResult) -> dict[str, Any]:
    """Timing summary always; APE / RPE / final pose error against ground truth when there is one, and the
    KITTI drift when the path is long enough for at least one devkit segment (100 m)."""
    stats = result.stats
    out: dict[str, Any] = {
        "method": result.method,
        "n_frames": int(len(result.frames)),
        "fps": result.fps,
        "total_time_s": result.total_time_s,
        "register_time_s": {"mean": float(stats.register_s.mean()), "median": float(np.median(stats.register_s)), "max": float(stats.register_s.max())},
        "read_time_s_mean": float(stats.read_s.mean()),
        "convergence_measured": result.convergence_measured,
        "n_not_converged": result.n_not_converged if result.convergence_measured else None,
        "n_constant_velocity_fallback": result.n_fallback,
        "n_degenerate": int(stats.degenerate.sum()) if result.convergence_measured else None,
        "estimated_length_m": result.trajectory.length_m,
    }
    ref = result.ground_truth
    if ref is None:
        return out
    ref, est = _paired(ref, result.trajectory)
    from lidarkit import eval as leval

    trans_m, rot_deg = pose_error(est.poses_se3[-1], ref.poses_se3[-1])
    out["ground_truth"] = ref.name
    out["ground_truth_length_m"] = ref.length_m
    out["final_error"] = {"translation_m": float(trans_m), "rotation_deg": float(rot_deg)}
    if len(ref) >= 2:
        out["ape_translation_m"] = leval.ape(ref, est, align="none", relation="translation").to_dict(include_errors=False)
        out["rpe_translation_m"] = leval.rpe(ref, est, delta=1, delta_unit="frames", relation="translation").to_dict(include_errors=False)
        out["rpe_rotation_deg"] = leval.rpe(ref, est, delta=1, delta_unit="frames", relation="rotation_angle_deg").to_dict(include_errors=False)
    if leval.drift_segments_possible(ref):
        out["kitti_drift"] = leval.kitti_drift(ref, est).to_dict()
    else:
        out["kitti_drift"] = None
        out["kitti_drift_note"] = f"path {ref.length_m:.1f} m is shorter than the shortest devkit segment (100 m)"
    return out


def _paired(ref: Trajectory, est: Trajectory) -> tuple[Trajectory, Trajectory]:
    """Frame-aligned by construction: give both the same stamps so the metrics pair them one to one."""
    if ref.timestamps_s is None and est.timestamps_s is None:
        return ref, est
    stamps = ref.timestamps_s if ref.timestamps_s is not None else est.timestamps_s
    return ref.with_timestamps(stamps), est.with_timestamps(stamps)


def write_run(result: OdometryResult, out_dir: str | os.PathLike) -> Path:
    """Write the run folder: poses_kitti.txt, poses_tum.txt, config.yaml, metrics.json, timing.csv, and with
    ground truth ground_truth_kitti.txt, trajectory.png and ape.png; every file atomically."""
    import json

    import yaml

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    traj = result.trajectory
    traj.to_kitti(out / "poses_kitti.txt")
    tum = traj if traj.timestamps_s is not None else traj.with_timestamps(np.arange(len(traj), dtype=np.float64))
    tum.to_tum(out / "poses_tum.txt")
    if result.ground_truth is not None:
        result.ground_truth.to_kitti(out / "ground_truth_kitti.txt")
    from lidarkit import __version__

    config = dict(result.config)
    config["lidarkit_version"] = __version__
    config["created_utc"] = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    config["machine"] = f"{platform.node()} ({platform.machine()}, {os.cpu_count()} cpus, Python {platform.python_version()})"
    atomic.write_text(out / "config.yaml", yaml.safe_dump(config, sort_keys=False))
    atomic.write_text(out / "metrics.json", json.dumps(result.metrics, indent=2, default=_json_default) + "\n")
    atomic.write_text(out / "timing.csv", result.stats.to_csv())
    _write_plots(result, out)
    return out


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (np.floating, np.integer, np.bool_)):
        return obj.item()
    return str(obj)


def _write_plots(result: OdometryResult, out: Path) -> None:
    """``trajectory.png`` (top view, estimate vs ground truth) and ``ape.png`` (error over time), through
    ``lidarkit.eval.plots``; only when there is ground truth to compare with."""
    if result.ground_truth is None or len(result.frames) < 2:
        return
    from lidarkit import eval as leval
    from lidarkit.eval import plots

    ref, est = _paired(result.ground_truth, result.trajectory)
    plots.plot_trajectories(ref.with_name("ground truth"), est, out / "trajectory.png", title=result.trajectory.name)
    plots.plot_errors(leval.ape(ref, est, align="none", relation="translation"), out / "ape.png")


__all__ = ["FrameStats", "OdometryResult", "config_dict", "odometry_metrics", "open_sequence", "parse_frames", "run", "write_run"]
