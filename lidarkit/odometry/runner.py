"""The odometry loop: any registered variant over a scan sequence, chained or through its own map."""

from __future__ import annotations

import logging
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from lidarkit.errors import ConfigError, DataError, EvaluationError, LidarKitError, RegistrationError
from lidarkit.geometry import orthonormalize_se3
from lidarkit.io.base import Scan, ScanSequence
from lidarkit.odometry.inputs import FrameSelection, frames_repr, open_sequence, parse_frames
from lidarkit.odometry.metrics import odometry_metrics
from lidarkit.odometry.result import FrameStats, OdometryResult
from lidarkit.odometry.run_folder import write_run
from lidarkit.trajectory import Trajectory

log = logging.getLogger(__name__)


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
            previous_times = None
            for k, idx in enumerate(indices):
                t0 = clock()
                try:
                    scan = _read_nonempty_scan(sequence, int(idx))
                    points = scan.points_xyz
                    t1 = clock()
                    if previous is None:
                        poses[k] = np.eye(4)
                    else:
                        if getattr(registration, "accepts_point_times", False):  # e.g. ground_filtered deskews with them
                            result = registration.align(
                                points, previous, init_T=motion, source_times_s=scan.point_times_s, target_times_s=previous_times
                            )
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
                previous, previous_times = points, scan.point_times_s
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
            "frames": frames_repr(frames, indices),
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
