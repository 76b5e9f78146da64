"""The odometry loop: any registered variant over a scan sequence, chained or through its own map."""

from __future__ import annotations

import dataclasses
import functools
import logging
import os
import time
from pathlib import Path
from collections.abc import Callable
from typing import Any

import numpy as np

from lidarkit.errors import ConfigError, DataError, EvaluationError, LidarKitError, RegistrationError, not_increasing
from lidarkit.geometry import as_points, float32_far_message, orthonormalize_se3, se3_fraction, se3_inverse, validated_points
from lidarkit.io.base import Scan, ScanSequence, read_warnings_of
from lidarkit.lifetime import raise_if_interrupted
from lidarkit.odometry.covariance import motion_prior_frames, motion_prior_summary, propagate
from lidarkit.odometry.frame_check import FrameChecker, FrameCheckConfig
from lidarkit.progress import progress_bar
from lidarkit.odometry.inputs import (FrameSelection, ReusedBufferCheck, frame_numbers, frames_past_the_end, frames_repr, open_sequence, parse_frames,
                                      time_gap_warning, typical_interval)
from lidarkit.odometry.instants import like_with_like, run_instant, stamps_at_instant
from lidarkit.odometry.metrics import odometry_metrics
from lidarkit.odometry.prefetch import DEFAULT_DEPTH, prefetched
from lidarkit.odometry.result import FrameStats, OdometryResult
from lidarkit.odometry.run_folder import refuse_replacing_inputs, write_run
from lidarkit.odometry.settings import deskew_requested, effective_settings, require_point_times, sweeps_apart
from lidarkit.params import is_integer
from lidarkit.registration.base import BACKEND_ERRORS, PendingAlignment, check_point_times
from lidarkit.registration.covariance import widen_for_distortion
from lidarkit.threads import Overlap
from lidarkit.trajectory import Trajectory

log = logging.getLogger(__name__)


def _resolve_method(method: Any, params: dict[str, Any] | None) -> Any:
    if params is not None and not isinstance(params, dict):
        raise ConfigError(f"params must be a mapping of parameter names to values, got {type(params).__name__}", source="params")
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


#: Errors re-raised naming the frame: lidarkit's own and what a variant raises on a frame it cannot register (its
#: backend's refusals, a plugin's NaN in scipy or division by zero): the kinds a pairwise alignment reports
#: (``BACKEND_ERRORS``). Programming errors (AttributeError, NotImplementedError, ...) propagate unchanged.
_FRAME_ERRORS = (LidarKitError, *BACKEND_ERRORS)


def _read_nonempty_scan(sequence: ScanSequence, index: int) -> Scan:
    """Frame ``index`` of the sequence; a scan without points is a DataError (named by the caller), and so is a reader's
    own failure (a user's sequence raising RuntimeError was reported as a registration error); a reader that returns
    no :class:`Scan` is a ConfigError (an AttributeError deep in the loop)."""
    try:
        scan = sequence.read_scan(index)
    except LidarKitError:
        raise
    except (OSError, EOFError, LookupError, *_FRAME_ERRORS) as err:  # (a reader's dict without the frame: KeyError; a cut gzip)
        raise DataError(f"cannot read the scan ({type(err).__name__}: {err})") from err
    if not isinstance(scan, Scan) and not isinstance(getattr(scan, "points_xyz", None), np.ndarray):
        raise ConfigError(f"read_scan({index}) returned a {type(scan).__name__}, not a lidarkit Scan (Scan(points_xyz) wraps an (N, 3) array)")
    if not isinstance(scan.points_xyz, np.ndarray):  # (a Scan of a list was called "a Scan, not a lidarkit Scan")
        raise ConfigError(f"read_scan({index}) returned a Scan whose points_xyz is a {type(scan.points_xyz).__name__}, not "
                          "an (N, 3) numpy array")
    if len(scan.points_xyz) == 0:  # named by its file and line where the reader gives them (a CARMEN log's blank scan
        # read "blank11 (frame 10): empty scan (0 points)"), else by the caller; the way past it where the reader tells
        # no reason of its own (a bag's empty message mid-recording said none, as a message of missing returns only does)
        why = _why_empty(sequence, index)  # (and the way past it, which a CARMEN log's reason did not give)
        raise DataError(f"empty scan (0 points){why} (--frames can leave the frame out)", source=scan.source or None,
                        location=f"frame {index}" if scan.source else None)
    return scan


def _check_scan_times(scan: Scan) -> None:
    """DataError for per-point times that are not one number per point (1-D, finite), checked here where every variant
    passes: kiss refused a wrong count, but flat times of the wrong count were dropped unchecked, and a variant that
    does not deskew took them as a sweep with times (its poses then scored as mid-sweep). An empty array: no times."""
    times = scan.point_times_s
    if times is None or np.size(times) == 0:
        return
    if np.ndim(times) != 1:
        raise DataError(f"per-point times of shape {np.shape(times)}: a 1-D array, one per point, is needed", source="point_times_s")
    check_point_times(times, len(scan.points_xyz))


def _why_empty(sequence: ScanSequence, index: int) -> str:
    """Why scan ``index`` holds no point, where a 2D log's reader can tell (``ranges_m``: its readings as logged), or ""."""
    ranges_of, low = getattr(sequence, "ranges_m", None), getattr(sequence, "min_range_m", None)
    if not callable(ranges_of) or low is None:
        return ""
    ranges = np.asarray(ranges_of(index), dtype=np.float64)
    if not len(ranges):
        return ": the message holds no readings"
    high = np.asarray(getattr(sequence, "max_range_m", np.nan), dtype=np.float64)
    high = float(high[index] if high.ndim else high)
    span = f"{ranges.min():.2f} m" if ranges.min() == ranges.max() else f"{ranges.min():.2f}..{ranges.max():.2f} m"
    return (f": all {len(ranges)} readings ({span}) lie outside the valid range, above min_range_m {low:g} m "
            f"and below the maximum range {high:g} m")


def _is_frame_error(err: BaseException) -> bool:
    return isinstance(err, _FRAME_ERRORS) and not isinstance(err, (NotImplementedError, RecursionError))


def _frame_error(err: Exception, dataset_name: str, frame: int, where: str | None = None) -> LidarKitError:
    """Re-raise an error of frame ``frame`` so that its message names the frame (as ``where`` says it, see
    :func:`frame_namer`)."""
    where = where or f"frame {frame}"
    if isinstance(err, LidarKitError):
        if err.location == f"frame {frame}":
            return err  # names the frame already (and its file: wrapped, it read "kt (frame 3): kt/velodyne/000003.bin (frame 3): ...")
        try:
            return type(err)(str(err), source=dataset_name, location=where)
        except TypeError:  # a subclass with another constructor
            return LidarKitError(str(err), source=dataset_name, location=where)
    return RegistrationError(f"{type(err).__name__}: {err}", source=dataset_name, location=where)


def frame_namer(sequence: Any) -> Callable[[int], str]:
    """How a run's messages name the scan at index ``idx``: ``frame idx`` (what --frames selects, timing.csv's rows and
    metrics' bad_frames count), with the scan's file or the recording's own number beside it where that differs (a
    folder of KITTI files 94, 95, 198: "frame 10" was file 000094.bin)."""
    numbers = frame_numbers(sequence)
    paths = getattr(sequence, "scan_paths", None)
    paths = paths if paths is not None and len(paths) == len(sequence) else None

    def name(idx: int) -> str:
        if numbers is None or int(numbers[idx]) == int(idx):
            return f"frame {idx}"
        return f"frame {idx}, {Path(paths[idx]).name}" if paths is not None else f"frame {idx}, recording frame {int(numbers[idx])}"
    return name


def _restated_first_pose(registration: Any, dataset_name: str, where: str) -> np.ndarray | None:
    """A stateful variant's first pose at the instant its other poses refer to, where the variant restates it once the
    second frame is registered (pipeline deskewing to the sweep's start or middle: its first sweep, registered with no
    motion known, is taken at its end, as its second is), checked; None where the first pose stands."""
    restated = getattr(registration, "restated_first_pose", None)
    if restated is None:
        return None
    restated = np.asarray(restated, dtype=np.float64)
    if restated.shape != (4, 4) or not np.isfinite(restated).all():
        raise RegistrationError(f"restated_first_pose is not a finite 4x4 pose (shape {restated.shape})",
                                source=dataset_name, location=where)
    return restated


def _calibration_of(registration: Any, name: str) -> str | None:
    """The variant whose learned covariance calibration applies to ``registration`` (its own, or the one it derives
    from), as its pairwise results use; a registration outside the registry by its name."""
    lookup = getattr(registration, "calibration_variant", None)
    return lookup() if callable(lookup) else name


def _stateful_covariance_settings(registration: Any, name: str) -> tuple[str | None, Any]:
    """``(calibration variant or None, covariance model)`` of a stateful variant's after-the-fact frame covariance, as
    its pairwise results take them: calibrated only with ``calibrated_covariance`` and the ``censi`` model the
    calibration was learned on (kiss and genz ignored both settings and config.yaml recorded them as given)."""
    config = getattr(registration, "config", None)
    make_model = getattr(config, "covariance_model", None)
    model = make_model() if callable(make_model) else "active"
    calibrated = bool(getattr(config, "calibrated_covariance", True)) and getattr(config, "covariance", "censi") == "censi"
    return (_calibration_of(registration, name) if calibrated else None), model


def _stateful_after(k: int, frame: int, previous: np.ndarray | None, scan: Scan, prepared: tuple, poses: np.ndarray,
                    checker: FrameChecker, want_covariance: bool, relative_cov: np.ndarray, min_eigenvalue: np.ndarray,
                    calibration: str | None, model: Any, dataset_name: str, voxelized: VoxelizedScans, where: str | None = None) -> None:
    """A stateful variant's frame k once its pose is known: the after-the-fact covariance (of ``model``, calibrated as
    the variant ``calibration``), then the frame check."""
    if want_covariance and k > 0:
        try:
            relative_cov[k], min_eigenvalue[k] = frame_covariance(previous, scan.points_xyz, poses[k - 1], poses[k], calibration, voxelized,
                                                                  model=model)
        except Exception as err:
            if not _is_frame_error(err):
                raise
            raise _frame_error(err, dataset_name, frame, where) from err
    checker.add(k, frame, scan.points_xyz, scan.point_times_s, poses, prepared)


def _run_stateless(stream, registration: Any, worker: Overlap, indices: np.ndarray, odometry_poses: np.ndarray | None,
                   poses: np.ndarray, checker: FrameChecker, strict: bool, name: str, dataset_name: str, bar,
                   validated: dict[int, np.ndarray], *,
                   read_s, register_s, n_points, converged, measured, fallback, iterations, rmse_m, n_corr, degenerate,
                   assessed, min_eigenvalue, relative_cov, reasons, widened: list[int], require_times=None,
                   sweeps: np.ndarray | None = None, frame_sweeps: np.ndarray | None = None,
                   name_frame: Callable[[int], str] = lambda idx: f"frame {idx}") -> Scan | None:
    """Scan-to-scan chaining, frame k's assessment overlapped with frame k+1's registration (``require_times``: the
    ``--strict`` refusal of a scan without per-point times, for a variant that deskews with them; ``sweeps``: each
    frame's sweeps since the previous one, for a variant that ``accepts_sweeps_apart``; ``frame_sweeps``: the same for
    every variant, which the constant-velocity guess and fallback are scaled by: a frame after a gap of dropped scans
    is predicted to have moved over the whole gap, the one after it over one sweep again).

    The only thing frame k+1 needs from frame k's assessment is its verdict: a result the acceptance gate turns down
    (too few correspondences, too low a fitness) is not converged, and the next guess is then the previous motion.
    Frame k+1 therefore registers from the guess the backend's own verdict implies (the usual case: both agree) and is
    registered again, from the right guess, when the assessment turns frame k down; every pose and result is the one
    of the in-line definition (``align`` frame after frame). ``widened`` collects the frames whose covariance got the
    distortion floor."""
    clock = time.perf_counter
    deferred = callable(getattr(registration, "align_deferred", None)) and not getattr(registration, "accepts_point_times", False)
    motion = np.eye(4)  # the motion of the last resolved frame (the in-line loop's `motion`)
    motion_sweeps = 1.0  # the sweeps `motion` spans

    def apart(k: int) -> float:
        return 1.0 if frame_sweeps is None else float(frame_sweeps[k])

    def predicted(k: int) -> np.ndarray:
        """Frame k's constant-velocity motion: the last resolved motion at its rate over frame k's sweeps (the same
        array for as many sweeps)."""
        return se3_fraction(motion, motion_sweeps / apart(k))
    pending = None  # the frame registered last, not resolved yet: dict(k, idx, out, future, register_s, guess, scan, prepared)
    first_scan = None
    previous = previous_times = None

    def register(k: int, idx: int, points: np.ndarray, times, guess: np.ndarray):
        t0 = clock()
        try:
            if deferred:
                out = registration.align_deferred(points, previous, init_T=guess)
            elif getattr(registration, "accepts_point_times", False):  # e.g. ground_filtered deskews with them
                apart = {"sweeps_apart": float(sweeps[k])} if sweeps is not None else {}
                out = PendingAlignment.done(registration.align(points, previous, init_T=guess, source_times_s=times,
                                                               target_times_s=previous_times, **apart))
            else:
                out = PendingAlignment.done(registration.align(points, previous, init_T=guess))
            if not np.isfinite(np.asarray(out.T_target_source, dtype=np.float64)).all():  # garbage instead of an error
                raise RegistrationError(f"{name} returned a pose with NaN or infinite entries")
        except Exception as err:
            if not _is_frame_error(err):
                raise
            raise _frame_error(err, dataset_name, idx, name_frame(idx)) from err
        return out, clock() - t0

    def assess(out, idx: int):
        def task():
            t0 = clock()
            try:
                return out.result(), clock() - t0
            except Exception as err:
                if not _is_frame_error(err):
                    raise
                raise _frame_error(err, dataset_name, idx, name_frame(idx)) from err
        return worker.submit(task)

    def resolve(item: dict) -> None:
        """Frame item["k"]: its result, its pose, the next guess; then its frame check (in the worker)."""
        nonlocal motion, motion_sweeps
        k, idx = item["k"], item["idx"]
        result, assess_s = item["future"].result()
        register_s[k] = item["register_s"] + assess_s
        measured[k] = True
        converged[k] = bool(result.converged)
        iterations[k] = int(result.iterations)
        history = result.rmse_history
        rmse_m[k] = float(history[-1]) if len(history) else np.nan
        n_corr[k] = int(result.n_correspondences)
        deg = getattr(result, "degeneracy", None)
        degenerate[k] = bool(getattr(deg, "degenerate", False))
        assessed[k] = (getattr(result, "extra", None) or {}).get("assessed", True) is not False  # (assess=False: no verdict)
        min_eigenvalue[k] = float(deg.eigenvalues[0]) if deg is not None else np.nan
        if relative_cov is not None and getattr(result, "covariance", None) is not None and converged[k]:
            relative_cov[k] = result.covariance
            if item["scan"].has_time_span():
                # a sweep skewed by the motion within it, registered as it is or deskewed at constant velocity: the skew
                # that does not cancel between two sweeps, or that the deskew leaves (changes of speed, turn rate, pitch
                # and roll within the sweep), is not in the pair calibration (DISTORTION_SIGMA, learned per variant by
                # benchmarks/covariance_distortion.py; a variant without an entry is left as it is)
                cov = widen_for_distortion(result.covariance, _calibration_of(registration, name),
                                           float(np.linalg.norm(result.T_target_source[:3, 3])))
                if cov is not result.covariance:
                    relative_cov[k] = cov
                    widened.append(k)
        reasons[k] = str(getattr(result, "reason", "") or "")
        if converged[k]:
            motion = orthonormalize_se3(np.asarray(result.T_target_source, dtype=np.float64))
        elif odometry_poses is not None:
            motion = item["guess"]
        else:
            motion = predicted(k)
        motion_sweeps = apart(k)
        poses[k] = poses[k - 1] @ motion
        if not converged[k]:
            why = reasons[k] or "no reason given"
            if strict:
                raise RegistrationError(f"registration did not converge ({why})", source=dataset_name, location=name_frame(idx))
            fallback[k] = True
            log.warning(
                "%s %s: %s did not converge (%s); using the %s motion instead",
                dataset_name, name_frame(idx), name, why, "odometry" if odometry_poses is not None else "constant-velocity",
            )
        elif degenerate[k]:
            log.warning("%s %s: %s flagged degenerate geometry (%s)", dataset_name, name_frame(idx), name, reasons[k] or "degenerate")

    checks = None  # the last frame check submitted (checks run in frame order in the one worker)

    def check(k: int, idx: int, scan: Scan, prepared: tuple) -> None:
        nonlocal checks
        if checks is not None:
            checks.result()  # done already (the worker runs tasks in order): raises its error, if any
        checks = worker.submit(functools.partial(checker.add, k, idx, scan.points_xyz, scan.point_times_s, poses, prepared))

    for k, (idx, payload, read_time, read_error) in enumerate(stream):
        raise_if_interrupted()  # (a Ctrl-C a library swallowed while it loaded: the run stops here)
        idx = int(idx)
        read_s[k] = read_time
        if read_error is not None:
            if pending is not None:  # the frames before the failed read come first, as in line
                resolve(pending)
            if checks is not None:
                checks.result()
            if not _is_frame_error(read_error):
                raise read_error
            raise _frame_error(read_error, dataset_name, idx, name_frame(idx)) from read_error
        scan, prepared = payload
        read_s[k] = read_time - prepared[1]  # the reading alone (the check's part is in check_s)
        first_scan = scan if k == 0 else first_scan
        points = scan.points_xyz
        n_points[k] = len(points)
        if require_times is not None:
            require_times(scan, frame=idx)
        if k == 0:
            poses[0] = np.eye(4)
            check(0, idx, scan, prepared)
        else:
            if odometry_poses is not None:
                guess = orthonormalize_se3(np.linalg.solve(odometry_poses[indices[k - 1]], odometry_poses[idx]))
            elif pending is not None and pending["out"].likely_converged:  # speculative: frame k-1's motion, at its rate
                guess = se3_fraction(orthonormalize_se3(np.asarray(pending["out"].T_target_source, dtype=np.float64)),
                                     apart(k - 1) / apart(k))
            else:
                guess = predicted(k)
            try:
                out, reg_s = register(k, idx, points, scan.point_times_s, guess)
            except BaseException:
                if pending is not None:
                    resolve(pending)  # an earlier frame's error (or strict refusal) comes first, as in line
                raise
            if pending is not None:
                resolve(pending)
                check(pending["k"], pending["idx"], pending["scan"], pending["prepared"])
                expected = predicted(k)
                if odometry_poses is None and guess is not expected and not np.array_equal(guess, expected):
                    # frame k-1 was turned down after all: register frame k again from the previous motion
                    guess = expected
                    out, again_s = register(k, idx, points, scan.point_times_s, guess)
                    reg_s += again_s
            pending = {"k": k, "idx": idx, "out": out, "future": assess(out, idx), "register_s": reg_s, "guess": guess,
                       "scan": scan, "prepared": prepared}
            validated.pop(id(previous), None)  # frame k-1's points: not passed to the backend again
        previous, previous_times = points, scan.point_times_s
        if bar is not None:
            bar[0].advance(bar[1])
    if pending is not None:
        resolve(pending)
        check(pending["k"], pending["idx"], pending["scan"], pending["prepared"])
    if checks is not None:
        checks.result()
    return first_scan


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
    name: str | None = None,
    frame_check: FrameCheckConfig | dict[str, Any] | None = None,
    prefetch: int = DEFAULT_DEPTH,
    init: str = "constant_velocity",
    pose_covariance: bool | None = None,
    overlap: bool = True,
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

    What was really applied is recorded in ``config["run"]["effective"]`` and ``metrics["effective"]``
    (:func:`lidarkit.odometry.settings.effective_settings`): deskew on/off and why, the instants compared,
    the reader's settings. A deskew the method requests but cannot apply (no per-point times) is a warning
    in ``metrics["warnings"]``, or with ``strict=True`` a :class:`DataError` naming the first such frame.
    Every frame also goes through the independent check of :mod:`lidarkit.odometry.frame_check`
    (``frame_check`` sets its thresholds: a FrameCheckConfig or a mapping of its settings, checked as the CLI checks
    them). ``name`` titles the run (default: the dataset's name, e.g. its folder). ``prefetch``: scans read
    ahead in a background thread (0: read inline). Ground truth whose instant of the sweep differs from the
    estimate's is re-timed with a note, else refused (deskewed) or compared as it is with a note (not deskewed; see
    :mod:`lidarkit.odometry.instants`).
    ``init``: the initial guess of each frame, ``"constant_velocity"`` (the previous relative motion; stateful
    variants: their own model) or ``"odometry"`` (the relative motion of the dataset's own ``odometry`` trajectory,
    e.g. a CARMEN log's wheel odometry; for a stateless variant it also replaces a non-converged registration; a
    stateful one gets it as ``register_frame(..., motion_guess=...)`` if it ``accepts_motion_guess``).
    ``pose_covariance``: propagate each frame's registration covariance into a covariance per pose
    (:mod:`lidarkit.odometry.covariance`); None = for stateless variants (whose results carry one, unless registered
    with ``assess=False``, which leaves it out: True is then an error), not for stateful ones (which need an extra
    assessment of each frame against the previous one: True asks for it). A
    variant registering sweeps that carry per-point times, without deskew or with a constant-velocity one, gets its
    learned distortion floor on each frame covariance (:func:`lidarkit.registration.covariance.widen_for_distortion`).
    ``overlap``: run each frame's after-the-fact work (assessment, covariance, frame check) in a worker thread while
    the next frame registers (:class:`lidarkit.threads.Overlap`; the same results as ``overlap=False``, which runs it in
    line). A variant whose backend holds the GIL (``overlap_assessment = False``: small_gicp, kiss) is assessed in line.
    """
    if not is_integer(prefetch) or prefetch < 0:
        raise ConfigError(f"prefetch must be a whole number of scans >= 0 (0: read in line), got {prefetch!r}", source="prefetch")
    for flag, value in (("pose_covariance", pose_covariance), ("strict", strict), ("progress", progress), ("overlap", overlap)):
        if not isinstance(value, (bool, np.bool_)) and not (flag == "pose_covariance" and value is None):
            # ("yes", "no": true strings; None, which only pose_covariance gives a meaning, was read as False)
            raise ConfigError(f"{flag} must be True or False, got {value!r}", source=flag)
    if out_dir is not None:  # before the work, as the CLI does (a file in the way was found after the whole run)
        from lidarkit.atomic import check_target

        if not isinstance(out_dir, (str, os.PathLike)):  # (5, b"x": a raw TypeError from pathlib)
            raise ConfigError(f"out_dir must be a folder path (str or Path), got {type(out_dir).__name__} {out_dir!r}",
                              source="out_dir")
        if isinstance(out_dir, str) and not out_dir.strip():  # (Path("") is ".": the run went into the current folder)
            raise ConfigError("empty path: give a folder ('.' for the current one)", source="out_dir")

        from lidarkit.run_files import RUN_FILES

        check_target(out_dir, "folder", files=RUN_FILES, replaces=RUN_FILES)
    sequence = open_sequence(dataset)
    if out_dir is not None:  # (its ground truth was replaced by the estimate: the next run scored 0.000)
        refuse_replacing_inputs(sequence, out_dir)
    registration = _resolve_method(method, params)
    method_name = getattr(registration, "name", type(registration).__name__) or type(registration).__name__
    dataset_name = str(getattr(sequence, "name", "dataset"))
    if name is not None and not isinstance(name, str):  # (a numpy string finished the run, then failed writing config.yaml)
        raise ConfigError(f"name must be a text, got {type(name).__name__} {name!r:.60}", source="name")
    title = str(name) if name and name.strip() else dataset_name  # (a blank name gave a blank title)
    name = method_name
    if callable(getattr(sequence, "configure_for_method", None)):  # e.g. KITTI's vertical-angle correction for kiss
        # (recorded below); a variant that stands for another (pipeline's kiss_like) gets that one's data. The caller's
        # own reader is configured on a copy: read directly after the run, its points came back corrected
        if sequence is dataset:
            import copy

            sequence = copy.copy(sequence)
        sequence.configure_for_method(getattr(registration, "reads_data_as", None) or method_name)
    n_total = len(sequence)
    if n_total == 0:
        raise DataError("the dataset has no scans", source=dataset_name)
    indices = parse_frames(frames, n_total)
    if len(indices) == 0:
        raise DataError(f"the frame selection {frames!r} selects no scan of {n_total}", source=dataset_name)
    stateful = bool(getattr(registration, "stateful", False))
    odometry_poses = _odometry_guess(sequence, init, registration, n_total, dataset_name)
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
    frame_assessed = np.ones(n, dtype=bool)
    min_eigenvalue = np.full(n, np.nan)
    relative_cov = np.full((n, 6, 6), np.nan)
    reasons = [""] * n
    config = getattr(registration, "config", None)
    assessed = bool(getattr(config, "assess", True))
    if pose_covariance and not assessed:
        raise ConfigError("pose_covariance needs each frame's covariance, which assess=False leaves out", source=name)
    no_covariance = getattr(config, "covariance", "censi") == "none"
    if pose_covariance and no_covariance:
        raise ConfigError("pose_covariance needs each frame's covariance, which covariance='none' leaves out", source=name)
    want_covariance = (not stateful and assessed and not no_covariance) if pose_covariance is None else bool(pose_covariance)
    widened: list[int] = []  # frames whose covariance got the distortion floor
    # frame k's after-the-fact work (assessment, covariance, frame check) runs in the worker below when the variant allows;
    # else the check's queries get a thread of their own (the registration holds the GIL for part of its calls, the
    # check's tree lets it run: kiss through lidarkit 0.79x kiss-icp's pipeline with the check in line)
    overlapped = overlap and bool(getattr(registration, "overlap_assessment", True))
    checker = FrameChecker(n, frame_check, overlap=overlap and not overlapped)
    # the ground truth is read before the run: a problem with it (too few poses in a bag, a bad pose file) is reported
    # now, not after registering every frame
    # (a sequence of the caller's own may have no stamps or ground truth: ScanSequence's other members are optional)
    _check_stamps(getattr(sequence, "timestamps_s", None), indices, dataset_name, len(sequence))  # now, not after every frame
    reference = _reference(sequence, ground_truth, indices, dataset_name)
    if ground_truth is not None and reference is not None and (reference.meta or {}).get("pose_instant"):
        # a caller's ground truth of another instant of the sweep than the estimate's is refused (it cannot be re-timed):
        # before the frames, from the first scan, not after registering all of them (taken for the run's frames: a run
        # whose most frames differ from it is judged by them after the run, below)
        probe = sequence.read_scan(int(indices[0]))
        probe_at, probe_deskewed = run_instant(registration, getattr(sequence, "stamp_instant", None) or probe.stamp_instant,
                                               [probe.has_time_span()])
        like_with_like(reference, probe_at, sequence=sequence, frames=indices, own_ground_truth=False, method=name,
                       deskewed=probe_deskewed)
    # sweeps between each frame and the previous one (a stepped selection, dropped scans): what a deskewing variant
    # that accepts it scales its motion between frames by, to one sweep's
    sweeps = sweeps_apart(getattr(sequence, "timestamps_s", None), frame_numbers(sequence), indices, n_total)
    sweeps_given = sweeps if getattr(registration, "accepts_sweeps_apart", False) else None
    need_times = strict and bool(deskew_requested(registration)) and (stateful or getattr(registration, "accepts_point_times", False))
    if strict and not stateful and deskew_requested(registration) and not getattr(registration, "accepts_point_times", False):
        raise ConfigError(f"deskew requested, but {name} runs scan-to-scan through align(), which takes no per-point times", source=name)

    # where the scans are stamped in their sweeps, asked before the frames: a recording that cannot say (a bag whose
    # point times are in another unit) stopped only after every frame registered
    getattr(sequence, "stamp_instant", None)
    bar = progress_bar(n, f"{name} on {title}") if progress else None
    clock = time.perf_counter
    loop_start, loop_cpu_start = clock(), time.process_time()
    first_scan = None
    # scans are read in a background thread, at most `prefetch` ahead (0: inline); only the previous scan is kept. The
    # thread also does the pose-free part of the frame check, overlapped with the registration of earlier frames
    # each scan's points are checked once, here in the reading thread (as_points), instead of again by the
    # registration as its source and once more as the next frame's target; an entry lives while its frame is in use
    validated: dict[int, np.ndarray] = {}

    first_pose_note = None  # frame 0's pose restated at the instant of the others'
    flat_times: list[int] = []  # frames whose per-point times are all equal: nothing to deskew with (kiss-icp would
    # normalize them by their zero span and abort the process), so they are read as scans without per-point times
    far_float32: list[tuple[int, float]] = []  # (frame, reach m) of scans far from their origin held at float32 precision
    # the scans a reused reader buffer would overwrite: those read ahead, and the ones registering and kept as a target
    reused = ReusedBufferCheck(depth=prefetch + 4)

    def read(i: int) -> tuple[Scan, tuple]:
        scan = _read_nonempty_scan(sequence, i)
        _check_scan_times(scan)
        if scan.point_times_s is not None and not scan.has_time_span():
            flat_times.append(i)
            scan = dataclasses.replace(scan, point_times_s=None)
        try:
            points = as_points(scan.points_xyz, "scan", on_float32_far=lambda reach: far_float32.append((i, reach)))
        except LidarKitError:
            points = None  # left to the registration, which refuses it naming the frame, as without this check
        if points is None:  # the check's histogram would fail first, on what the registration refuses by name
            return scan, (None, 0.0)
        scan = scan if points is scan.points_xyz else dataclasses.replace(scan, points_xyz=points)
        reused.check(i, (points, scan.point_times_s), dataset_name)  # (the arrays kept: a float32 buffer was converted)
        validated[id(points)] = points
        return scan, checker.prepare(i, scan.points_xyz)

    stream = prefetched(read, indices, prefetch)
    name_frame = frame_namer(sequence)
    # frame k's after-the-fact work (assessment, covariance, frame check) runs in one worker thread while frame k+1
    # registers; results are those of the same calls in line (see _run_stateless for the one decision that waits)
    worker = Overlap(overlapped)
    try:
        with validated_points(validated):
            if stateful:
                registration.reset()
                previous = None
                voxelized = VoxelizedScans()  # used by the worker thread only, one frame after another
                calibration, model = _stateful_covariance_settings(registration, name)
                inflight = None  # frame k-1's after-the-fact task
                anchor = None  # what moves the variant's poses to start at frame 0's restated pose
                for k, (idx, payload, read_time, read_error) in enumerate(stream):
                    raise_if_interrupted()  # (a Ctrl-C a library swallowed while it loaded: the run stops here)
                    read_s[k] = read_time
                    try:
                        if read_error is not None:
                            raise read_error
                        scan, prepared = payload
                        read_s[k] = read_time - prepared[1]  # the reading alone (the check's part is in check_s)
                        first_scan = scan if k == 0 else first_scan
                        points = scan.points_xyz
                        if need_times:
                            require_point_times(scan, sequence, dataset_name, int(idx), flat_times)
                        t1 = clock()
                        apart = {"sweeps_apart": float(sweeps_given[k])} if sweeps_given is not None else {}
                        if odometry_poses is not None and k > 0:
                            guess = orthonormalize_se3(np.linalg.solve(odometry_poses[indices[k - 1]], odometry_poses[idx]))
                            pose = registration.register_frame(points, scan.point_times_s, motion_guess=guess, **apart)
                        else:
                            pose = registration.register_frame(points, scan.point_times_s, **apart)
                        if pose is None or np.shape(pose) != (4, 4):  # (None read as "a pose with NaN entries")
                            raise RegistrationError(f"{name}.register_frame returned {type(pose).__name__}"
                                                    f"{'' if pose is None else f' of shape {np.shape(pose)}'}, not a 4x4 pose")
                        poses[k] = pose
                        if not np.isfinite(poses[k]).all():  # a variant (or plugin) returning garbage instead of raising
                            raise RegistrationError(f"{name} returned a pose with NaN or infinite entries")
                        t2 = clock()  # the variant's own time: the after-the-fact covariance below is not part of it
                    except Exception as err:
                        if inflight is not None:
                            inflight.result()  # an earlier frame's error comes first, as in line
                        if not _is_frame_error(err):
                            raise
                        raise _frame_error(err, dataset_name, int(idx), name_frame(int(idx))) from err
                    register_s[k], n_points[k] = t2 - t1, len(points)
                    if inflight is not None:
                        inflight.result()
                    if k == 1:  # (frame 0's work is done: its pose may change now)
                        restated = _restated_first_pose(registration, dataset_name, name_frame(int(indices[0])))
                        if restated is not None:
                            anchor = se3_inverse(restated)  # the run starts at frame 0's restated pose
                            poses[0] = anchor @ restated
                            instant = getattr(registration, "deskew_instant", None)
                            instant = {"mid": "middle", None: "reference instant"}.get(instant, instant)
                            first_pose_note = (f"{name_frame(int(indices[0]))}: its pose, registered with no motion known "
                                               f"at its sweep's end, moved back to the sweep's {instant} by "
                                               f"{name_frame(int(idx))}'s motion at constant velocity")
                    if anchor is not None:
                        poses[k] = anchor @ poses[k]
                    inflight = worker.submit(functools.partial(
                        _stateful_after, k, int(idx), previous, scan, prepared, poses, checker, want_covariance, relative_cov,
                        min_eigenvalue, calibration, model, dataset_name, voxelized, name_frame(int(idx)),
                    ))
                    validated.pop(id(points), None)  # registered: not passed to the backend again
                    previous = points
                    if bar is not None:
                        bar[0].advance(bar[1])
                if inflight is not None:
                    inflight.result()
            else:
                first_scan = _run_stateless(
                    stream, registration, worker, indices, odometry_poses, poses, checker, strict, name, dataset_name, bar, validated,
                    require_times=functools.partial(require_point_times, sequence=sequence, dataset_name=dataset_name,
                                                    flat=flat_times) if need_times else None,
                    read_s=read_s, register_s=register_s, n_points=n_points, converged=converged, measured=measured, fallback=fallback,
                    iterations=iterations, rmse_m=rmse_m, n_corr=n_corr, degenerate=degenerate, assessed=frame_assessed,
                    min_eigenvalue=min_eigenvalue,
                    relative_cov=relative_cov if want_covariance else None, reasons=reasons, widened=widened, sweeps=sweeps_given,
                    frame_sweeps=sweeps, name_frame=name_frame,
                )
    finally:
        worker.close()  # cancels what has not started, joins the worker thread, also on error
        checker.close()  # the same for the check's own thread
        stream.close()  # stops and joins the reading thread, also on error
        if bar is not None:
            bar[0].stop()
    total, total_cpu = clock() - loop_start, time.process_time() - loop_cpu_start

    all_stamps = getattr(sequence, "timestamps_s", None)
    timestamps = None if all_stamps is None else np.asarray(all_stamps, dtype=np.float64)[indices]
    # where in the sweep the scans are stamped: the recording's word over the first scan's (a recording begun
    # mid-rotation holds part of a sweep in its first message, which says no instant or a wrong one)
    recorded_instant = getattr(sequence, "stamp_instant", None)
    if first_scan is not None and recorded_instant is not None and recorded_instant != first_scan.stamp_instant:
        first_scan = dataclasses.replace(first_scan, stamp_instant=recorded_instant)
    # the instant most frames' poses refer to (frame 0 alone without per-point times put 19 frames deskewed to the
    # sweep end at its stamp's instant)
    estimate_at, deskewed = run_instant(registration, getattr(first_scan, "stamp_instant", None), checker.has_point_times)
    # the poses are stamped at the instant they refer to (a deskewing variant's), not at the one the scans' stamps do
    scan_stamps = timestamps
    # (a bag knows how long its sweeps last from its first scans' point times: the first scan alone, part of a sweep when
    # the recording began mid-rotation, said nothing and the stamps' spacing was taken for it)
    sweep_s = getattr(sequence, "sweep_duration_s", None)
    # (and where a sweep starts against its stamp: a bag stamped on receipt, after the sweep end, at no clear instant)
    sweep_offset_s = getattr(sequence, "sweep_offset_s", None)
    timestamps, stamp_note = stamps_at_instant(timestamps, first_scan, estimate_at, all_stamps, sweep_s=sweep_s,
                                               sweep_offset_s=sweep_offset_s)
    trajectory = Trajectory(poses, timestamps, name=f"{name} on {title}",
                            meta={"method": name, "dataset": dataset_name, **({"stamps": stamp_note} if stamp_note else {})})
    instant_note = unscored_note = None
    if reference is not None:  # score like with like: the estimate's and the ground truth's instant of the sweep
        try:
            retimed, instant_note = like_with_like(reference, estimate_at, sequence=sequence, frames=indices,
                                                   own_ground_truth=ground_truth is None, method=name,
                                                   deskewed=deskewed)
        except EvaluationError:
            if n > 1:
                raise
            # one frame scores nothing (its pose is the start): a one-sweep recording whose ground truth of another
            # instant cannot be re-timed (one pose) refused the whole run
            reference = None
            unscored_note = "none: one frame, nothing to score (the ground truth, of another instant of the sweep, left out)"
        if instant_note is not None and retimed is not reference:
            reference = _reference(sequence, retimed, indices, dataset_name)
    if reference is not None and n == 1:  # (it printed "final error, unaligned 0.000 / 0.000" as if scored)
        reference, instant_note = None, None
        unscored_note = "none: one frame, nothing to score (its pose is the start, where the estimate and the ground truth both begin)"
    all_numbers = frame_numbers(sequence)  # the recording's own frame numbers (KITTI's or a folder's file names), if any
    numbers = indices if all_numbers is None else all_numbers[indices]
    number_step = typical_interval(all_numbers if all_numbers is not None else np.arange(n_total))
    check_times = timestamps
    if timestamps is None:  # the frame numbers time the motion, a nominal period a step of the dataset's numbering (the
        # frame after a gap of 7 was checked as one period after the previous one, and failed though registered right)
        check_times = None if not number_step else (numbers - numbers[0]) / number_step * checker.config.nominal_period_s
    check = checker.finish(poses, check_times)
    why = tuple("+".join(w for w, bad in (("motion", m), ("fitness", f)) if bad) for m, f in zip(check.failed_motion, check.failed_fitness))
    stats = FrameStats(
        indices.copy(), read_s, register_s, n_points, converged, iterations, rmse_m, n_corr, degenerate, tuple(reasons), measured, fallback,
        checker.has_point_times, check.motion_dev_m, check.rotation_dev_deg, check.fitness, check.failed, why, checker.check_s,
        min_eigenvalue, frame_assessed, stateful=stateful,
    )
    past_the_end = frames_past_the_end(frames, n_total)
    effective, warnings = effective_settings(sequence, registration, name, stateful, checker.has_point_times, reference,
                                             stamp_instant=getattr(first_scan, "stamp_instant", None), n_flat_times=len(flat_times),
                                             frames=indices, sweeps_apart=sweeps)
    # the gaps are judged against the dataset's own interval (stamps, else file numbers): the run's may hold only two
    typical = typical_interval(all_stamps) if timestamps is not None else number_step
    if want_covariance and n > 1 and not np.isfinite(relative_cov[1:]).all(axis=(1, 2)).any():
        # (a plugin whose results carry no covariance, or no frame converged): no all-NaN pose covariance is written
        why = (f"every frame fell back to the {'odometry' if odometry_poses is not None else 'constant-velocity'} motion"
               if fallback[1:].all() else f"{name} returns none")
        warnings.append(f"no frame's registration gave a covariance ({why}): no pose covariance")
        want_covariance = False
    # ground truth of another instant compared as it is (its note says so): its stamps are held against the scans'
    # moved to its own instant (against the estimate's, a half-sweep gap was named; skipped, a 2 s offset was not)
    kept_as_is = instant_note is not None and retimed is reference
    truth_at = (reference.meta or {}).get("pose_instant") if kept_as_is else None
    at_truth = (stamps_at_instant(scan_stamps, first_scan, truth_at, all_stamps, sweep_s=sweep_s, sweep_offset_s=sweep_offset_s)[0]
                if kept_as_is else timestamps)
    apart = (_stamps_apart(reference, at_truth, all_stamps, numbers) if ground_truth is not None
             else _own_stamps_apart(reference, at_truth, all_stamps) if instant_note is None or kept_as_is else None)
    far = _far_float32_warning(far_float32, n)
    # what the reader found and left out (files it does not read, scans without ground truth): only logged before
    # and the ground truth's own reading (a pose file cut inside its last number, given as run(ground_truth=...))
    reader_warnings = read_warnings_of(sequence, reference)
    # the guess across a gap: the dataset's odometry, the motion before it at constant velocity, or (a stateful variant
    # whose own model predicts without the sweeps apart: genz) one sweep's motion
    across = ("odometry" if odometry_poses is not None
              else "one sweep" if stateful and not getattr(registration, "accepts_sweeps_apart", False) else "constant velocity")
    warnings = reader_warnings + [w for w in (past_the_end, time_gap_warning(timestamps, numbers, across, indices, typical),
                                              apart, far, first_pose_note) if w] + warnings
    if stateful:  # (accepted, recorded in config.yaml as given, and without effect on the run)
        gates = [f for f in ("min_fitness", "min_correspondences") if f in getattr(config, "model_fields_set", ())]
        if gates:
            warnings.append(f"{', '.join(gates)}: acceptance gates of a pairwise alignment (align); {name}'s odometry "
                            "(register_frame, its own local map) does not use them")
    # (covariance='none' is what turned it off, when it is: that has its effect)
    unused = [f for f in ("covariance", "calibrated_covariance", *(("assess",) if stateful else ()))
              if f in getattr(config, "model_fields_set", ()) and not want_covariance and not (f == "covariance" and no_covariance)]
    if unused:  # (recorded in config.yaml as if applied: the poses and metrics were those of a default run)
        asked = pose_covariance is None and assessed and not no_covariance  # (advice run() would refuse is not given)
        ask = " (--pose-covariance / pose_covariance=True asks for it)" if asked else ""
        warnings.append(f"{', '.join(unused)}: {'shapes' if len(unused) == 1 else 'shape'} each frame's covariance, which "
                        f"this run does not compute{ask}: no effect")
    if timestamps is not None and checker.config.nominal_period_s != FrameCheckConfig.nominal_period_s:
        # (accepted and recorded in config.yaml; the stamps time the motion check)
        warnings.append(f"nominal_period_s={checker.config.nominal_period_s:g}: the frame check's period for scans without time "
                        "stamps; this dataset has them, so it is not used")
    for message in warnings:
        if message not in reader_warnings:  # (logged by the reader when it opened)
            log.warning("%s: %s", title, message)
    # frames whose motion the pose covariance takes as known to the motion prior alone: fallbacks, and registrations the
    # run does not trust (a stateful variant's after-the-fact covariance at fitness 0.008 across KITTI's dropped scans
    # was one sweep's: end 1-sigma 0.6 m for a 40 m error)
    prior_reasons = motion_prior_frames(fallback, check.failed_fitness, sweeps)
    covariances = (relative_cov, propagate(poses, relative_cov, fell_back=np.logical_or.reduce(list(prior_reasons.values())),
                                           sweeps_apart=sweeps)) if want_covariance else None
    relations_note, relation_scores = _relations_note(sequence, trajectory) if reference is None else (None, None)
    config = {
        "method": name,
        "method_config": config_dict(getattr(registration, "config", None)),
        "run": {
            "name": title,
            "dataset": dataset_name,
            "dataset_config": config_dict(getattr(sequence, "config", None)) if hasattr(getattr(sequence, "config", None), "model_dump") else None,
            "dataset_options": _plain(getattr(sequence, "reader_options", None) or {}),
            "frames": frames_repr(frames, indices),
            "n_frames": n,
            "stateful": stateful,
            "strict": strict,
            "initial_guess": "dataset odometry (relative motion)" if odometry_poses is not None else (
                "register_frame (own map and motion model)" if stateful else "constant velocity (previous relative motion)"
            ),
            # the motion a frame the registration turned down takes (metrics read it: the guess's wording is for people)
            "fallback_motion": "dataset odometry" if odometry_poses is not None else "constant velocity",
            "ground_truth": None if reference is None else reference.name,
            "ground_truth_given": ground_truth is not None,  # by the caller (run(ground_truth=...)), not the dataset's
            "ground_truth_meta": None if reference is None else _plain(reference.meta),
            "ground_truth_note": unscored_note or relations_note,
            "effective": effective,
            "warnings": warnings,
            "frame_check": check.config.describe(),
            "ground_truth_instant_note": instant_note,
            "estimate_stamps_note": stamp_note,
            "covariance_distortion_floor": (
                f"{len(widened)} frames: motion-distorted sweeps registered "
                + ("with a constant-velocity deskew" if getattr(registration, "deskew_instant", None) else "without deskew")
                # (the entry applied: a subclass outside the registry, 'Frozen(vanilla)', is widened by vanilla's)
                + f", frame covariance widened by DISTORTION_SIGMA[{_calibration_of(registration, name)!r}]" if widened else None
            ),
        },
    }
    result = OdometryResult(trajectory, name, config, indices.copy(), stats, total, reference, covariances=covariances, total_cpu_s=total_cpu)
    metrics = odometry_metrics(result)
    if covariances is not None:
        metrics["pose_covariance"]["motion_prior_only"] = motion_prior_summary(indices, prior_reasons)
    if instant_note is not None:
        metrics["ground_truth_instant_note"] = instant_note
    if relation_scores is not None:
        metrics["relations"] = relation_scores
    result = dataclasses.replace(result, metrics=metrics)
    if out_dir is not None:
        write_run(result, out_dir)
        result = dataclasses.replace(result, out_dir=Path(out_dir))
    return result


#: Initial guesses of a run's registrations (``run(init=...)``).
INIT_GUESSES = ("constant_velocity", "odometry")


def _odometry_guess(sequence: ScanSequence, init: str, registration: Any, n_total: int, dataset_name: str) -> np.ndarray | None:
    """``(n_total, 4, 4)`` odometry poses for ``init="odometry"``, None for constant velocity."""
    if init not in INIT_GUESSES:
        raise ConfigError(f"unknown initial guess {init!r}; known: {', '.join(INIT_GUESSES)}", source="init")
    if init == "constant_velocity":
        return None
    if getattr(registration, "stateful", False) and not getattr(registration, "accepts_motion_guess", False):
        from lidarkit.registration.registry import available_icp, get_icp_class

        takers = [m for m in available_icp() if getattr(get_icp_class(m), "accepts_motion_guess", False)]
        name = getattr(registration, "name", type(registration).__name__)
        raise ConfigError(f"init='odometry': {name} is a stateful variant that keeps its own motion model (no motion_guess); "
                          f"{', '.join(takers) or 'no stateful variant'} and the stateless variants take the odometry",
                          source="init")
    odometry = getattr(sequence, "odometry", None)
    if odometry is None:
        raise ConfigError(f"init='odometry' needs a dataset with its own odometry (e.g. a CARMEN log); {dataset_name} has none", source="init")
    if len(odometry) != n_total:
        raise DataError(f"odometry has {len(odometry)} poses for {n_total} scans", source=dataset_name)
    return np.asarray(odometry.poses_se3, dtype=np.float64)


def _relations_note(sequence: ScanSequence, trajectory: Trajectory) -> tuple[str | None, dict[str, Any] | None]:
    """``(note, relation scores or None)`` of a run without ground truth over a log with relation ground truth (a
    CARMEN log's ``.relations``), or ``(None, None)``. The run scores them itself with the bench's function
    (:func:`lidarkit.eval.relations.relation_error` on the reader's relations, which carry its scan gap and move with
    the stamps it moved: Intel's 2042), so a run folder holds the figures a bench job and ``lidarkit eval --relations``
    give (the ACES run only named that command); the note says why when none is scored."""
    relations = (getattr(sequence, "reader_options", None) or {}).get("relations")
    if not relations:
        return None, None
    from lidarkit.eval.relations import DEFAULT_MAX_TIME_DIFF_S, relation_error

    n_moved = int(getattr(sequence, "n_restamped", 0) or 0)
    why = (f"; the reader moved {n_moved} scan stamps and the relations' times with them (lidarkit eval --relations "
           "matches the file's times as logged: not for this log)" if n_moved else "")
    ground_truth = getattr(sequence, "relations", None)
    if ground_truth is None:  # (a reader that names a relations file but gives none to score)
        return f"none: no scores here; the reader names relations ({os.path.normpath(relations)}) but gives none", None
    # relations that know their log's scan gap keep the tolerance under half of it (relation_error); others are kept
    # under half the run's own smallest gap: within the default 0.01 s a relation of a scan the estimate skips (--frames
    # A:B:2) took a neighbour's pose (164 of 297 on Intel's pooled stamps, 0.1 ms apart)
    tolerance = DEFAULT_MAX_TIME_DIFF_S
    if getattr(ground_truth, "scan_gap_s", None) is None:
        gaps = np.diff(np.sort(np.asarray(sequence.timestamps_s, dtype=np.float64)))
        gaps = gaps[gaps > 0]
        tolerance = min(DEFAULT_MAX_TIME_DIFF_S, 0.5 * float(gaps.min())) if gaps.size else DEFAULT_MAX_TIME_DIFF_S
    try:
        scored = relation_error(trajectory, ground_truth, max_time_diff_s=tolerance)
    except EvaluationError as err:
        return f"none: no scores here; the relation ground truth scores nothing of this run ({err.reason}){why}", None
    return (f"relations only, scored through the reader (metrics \"relations\"): {scored.n_used} of {scored.n_relations}, "
            f"mean error {scored.translation_abs['mean']:.4f} m / {scored.rotation_abs['mean']:.4f} deg{why}"), scored.to_dict()


def _plain(meta: dict) -> dict:
    return {str(k): (v if isinstance(v, (str, int, float, bool, type(None))) else str(v)) for k, v in meta.items()}


def _check_stamps(stamps: np.ndarray | None, indices: np.ndarray, dataset_name: str, n_scans: int) -> None:
    """DataError for stamps that are not one per scan (a caller's sequence one short was an IndexError), or naming the
    first selected frame whose time stamp does not come after the previous one's (a scan recorded twice, unset stamps):
    the trajectory could not be written after the run."""
    if stamps is None:
        return
    stamps = np.asarray(stamps, dtype=np.float64).reshape(-1)
    if len(stamps) != n_scans:
        raise DataError(f"{len(stamps)} time stamps for {n_scans} scans (timestamps_s needs one per scan)", source=dataset_name)
    if len(indices) < 2:
        return
    selected = stamps[indices]
    bad = np.flatnonzero(~(np.diff(selected) > 0))
    if len(bad):
        k = int(bad[0])
        why = not_increasing(selected[k + 1], selected[k], f"frame {int(indices[k])}")
        raise DataError(f"time stamps are not strictly increasing: {why}", source=dataset_name, location=f"frame {int(indices[k + 1])}")


def _far_float32_warning(frames_reach: list[tuple[int, float]], n: int) -> str | None:
    """The run's one warning for scans far from their origin held at float32 precision (naming the first such frame),
    or None; a georeferenced recording repeats it every frame, which the log would drown in."""
    if not frames_reach:
        return None
    first = min(frames_reach)[0]
    reach = max(r for _, r in frames_reach)
    count = f"{len(frames_reach)} of {n} scans" if len(frames_reach) > 1 else "1 scan"
    return f"{count}, first frame {first}: {float32_far_message(reach)}"


def _stamps_apart(reference: Trajectory | None, stamps_s: np.ndarray | None, all_stamps_s: np.ndarray | None,
                  frames: np.ndarray) -> str | None:
    """A caller's ground truth is paired with the scans by order: a warning when its stamps and the estimate's
    ``stamps_s`` disagree by more than half the dataset's frame interval (scans of 0-0.31 s were scored against poses
    of 0, 5, 10, 15 s without a word), or None. ``frames``: the run's frame numbers, as the warning names them."""
    interval = typical_interval(all_stamps_s)
    if reference is None or reference.timestamps_s is None or stamps_s is None or not interval:
        return None
    apart = np.abs(np.asarray(reference.timestamps_s, dtype=np.float64) - stamps_s)
    k = int(np.argmax(apart))
    if apart[k] <= 0.5 * interval:
        return None
    return (f"the ground-truth pose of frame {int(frames[k])} is stamped {apart[k]:.3f} s from its scan's pose (half a frame "
            f"is {0.5 * interval:.3f} s): the given ground truth is paired with the scans by order, one pose each, not by time")


def _own_stamps_apart(reference: Trajectory | None, stamps_s: np.ndarray | None, all_stamps_s: np.ndarray | None) -> str | None:
    """The dataset's own ground truth of an instant of the sweep it does not state, compared as it is: a warning when
    its stamps lie systematically more than a quarter of a frame from the estimate's ``stamps_s``, or None (a bag
    without per-point times, its poses a sweep after the scans, was scored one sweep out of step without a word)."""
    interval = typical_interval(all_stamps_s)
    if (reference is None or (reference.meta or {}).get("pose_instant") is not None or reference.timestamps_s is None
            or stamps_s is None or not interval):
        return None
    offset = float(np.median(np.asarray(reference.timestamps_s, dtype=np.float64) - stamps_s))
    if abs(offset) <= 0.25 * interval:
        return None
    return (f"the ground-truth poses are stamped a median {abs(offset):.3f} s {'after' if offset > 0 else 'before'} their scans "
            f"(a quarter of a frame is {0.25 * interval:.3f} s) at an instant of the sweep the reader does not state: they are "
            "paired with the scans by order, one pose each, and scored as they are")


def _reference(sequence: ScanSequence, ground_truth: Trajectory | None, indices: np.ndarray, dataset_name: str) -> Trajectory | None:
    """Ground truth of the selected frames, relative to its first pose (the estimate starts at identity)."""
    if ground_truth is not None:
        if not isinstance(ground_truth, Trajectory):  # (an (N, 4, 4) array was an AttributeError after the run)
            raise ConfigError(f"ground_truth must be a lidarkit Trajectory (Trajectory(poses_se3) wraps an (N, 4, 4) array), "
                              f"got {type(ground_truth).__name__}", source="ground_truth")
        gt = ground_truth
    elif callable(getattr(sequence, "ground_truth_of", None)):  # a recording's odometry paired with the selected scans only
        gt = sequence.ground_truth_of(indices)
    else:
        gt = getattr(sequence, "ground_truth", None)
    if gt is None:
        return None
    if ground_truth is None and getattr(sequence, "ground_truth_frame", None) == "camera":  # (KITTI's option: scored as
        # it was, every pose was off by the camera-LiDAR extrinsic, 10.5 m at the end of 10 scans where 0.998 m is right)
        raise ConfigError("the ground truth is in the camera frame but the estimate in the LiDAR frame; use "
                          "ground_truth_frame=lidar, the default for scans", source="ground_truth_frame=camera")
    if not isinstance(gt, Trajectory):
        raise ConfigError(f"the dataset's ground truth is a {type(gt).__name__}, not a lidarkit Trajectory", source=dataset_name)
    if len(gt) == len(sequence):
        gt = gt[indices]
    elif len(gt) != len(indices):
        raise EvaluationError(
            f"ground truth has {len(gt)} poses; expected one per dataset frame ({len(sequence)}) or per selected frame ({len(indices)})",
            source=gt.name or dataset_name,
        )
    return gt.relative_to_first()


#: voxel size (m) of the two scans a stateful variant's frame covariance is assessed on, and the pair distance
FRAME_COVARIANCE_VOXEL_M = 0.5
FRAME_COVARIANCE_INLIER_M = 1.0


class VoxelizedScans:
    """The scans a stateful variant's frame covariance is assessed on, voxelized at :data:`FRAME_COVARIANCE_VOXEL_M`;
    the last one is kept, since the scan of frame k is the target of frame k+1 (voxelized once, not twice)."""

    def __init__(self) -> None:
        self._last: tuple[np.ndarray | None, np.ndarray | None] = (None, None)

    def __call__(self, points_xyz: np.ndarray) -> np.ndarray:
        from lidarkit.registration.preprocess import voxel_downsample

        if self._last[0] is not points_xyz:
            self._last = (points_xyz, voxel_downsample(points_xyz, FRAME_COVARIANCE_VOXEL_M))
        return self._last[1]


def frame_covariance(previous_xyz: np.ndarray, points_xyz: np.ndarray, T_world_prev: np.ndarray, T_world_cur: np.ndarray,
                     variant: str | None, voxelized: VoxelizedScans | None = None, model: Any = "active") -> tuple[np.ndarray, float]:
    """Covariance (and smallest normal-matrix eigenvalue) of a stateful variant's frame-to-frame motion, assessed
    after the fact on the two voxelized scans at the motion it estimated (the variant itself exposes no Hessian),
    of the :class:`~lidarkit.registration.covariance.CovarianceModel` ``model`` (``"active"``: the default one),
    calibrated as ``variant``'s (None: as computed). ``voxelized``: the run's :class:`VoxelizedScans`, which has the previous scan voxelized already."""
    from lidarkit.geometry import se3_inverse
    from lidarkit.registration.assessment import assess_alignment
    from lidarkit.registration.covariance import calibrate

    voxelized = voxelized or VoxelizedScans()
    T_rel = se3_inverse(T_world_prev) @ T_world_cur
    target = voxelized(previous_xyz)
    source = voxelized(points_xyz)
    assessment = assess_alignment(source, target, T_rel, FRAME_COVARIANCE_INLIER_M, covariance_model=model)
    if assessment.covariance is None:
        return np.full((6, 6), np.nan), float("nan")
    # without the step (CALIBRATION_WITHOUT_STEP): the step of this pair of voxelized scans is not the variant's own
    covariance = assessment.covariance if variant is None else calibrate(assessment.covariance, variant)
    return covariance, float(assessment.degeneracy.eigenvalues[0])
