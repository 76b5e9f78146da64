"""``assert_trajectory_close`` and ``assert_no_worse_than``: AssertionErrors whose message says by how much."""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from lidarkit.errors import ConfigError, EvaluationError, LidarKitError, index_runs
from lidarkit.geometry import rotation_angle_deg
from lidarkit.params import is_real_number
from lidarkit.trajectory import Trajectory


def assert_trajectory_close(
    actual: Trajectory,
    expected: Trajectory,
    *,
    atol_m: float = 1e-3,
    atol_deg: float = 0.05,
    align: str = "none",
) -> None:
    """Every pose of ``actual`` within ``atol_m`` (position) and ``atol_deg`` (rotation angle) of ``expected``.

    ``align`` ("none", "se3", "sim3") first aligns ``actual`` onto ``expected`` (evo's Umeyama); the message
    names the worst frame. Different lengths fail as an AssertionError too.
    """
    for name, value in (("atol_m", atol_m), ("atol_deg", atol_deg)):  # (True read as 1 m; numpy's float32 was refused)
        if not (is_real_number(value) and math.isfinite(value) and value >= 0):
            raise ConfigError(f"{name} must be a finite number >= 0, got {value!r}", source="assert_trajectory_close")
    for name, value in (("actual", actual), ("expected", expected)):
        if not isinstance(value, Trajectory):  # (an (N, 4, 4) array: Trajectory(poses) makes one)
            raise ConfigError(f"{name} must be a lidarkit Trajectory (Trajectory(poses_se3) wraps an (N, 4, 4) array), got "
                              f"{type(value).__name__}", source="assert_trajectory_close")
    if len(actual) != len(expected):
        raise AssertionError(f"trajectories differ in length: {len(actual)} poses vs {len(expected)} expected")
    if align != "none":
        from lidarkit.eval import align_trajectory

        actual = align_trajectory(expected, actual, align)[0]
    A, E = actual.poses_se3, expected.poses_se3
    d_m = np.linalg.norm(A[:, :3, 3] - E[:, :3, 3], axis=1)
    # (robust near 0: arccos of the trace read 0.00085 deg between a trajectory and its own text copy)
    d_deg = rotation_angle_deg(np.einsum("nji,njk->nik", E[:, :3, :3], A[:, :3, :3]))
    bad_t, bad_r = d_m > atol_m, d_deg > atol_deg
    if bad_t.any() or bad_r.any():
        i = int(np.argmax(d_m)) if bad_t.any() else int(np.argmax(d_deg))
        raise AssertionError(
            f"{int((bad_t | bad_r).sum())} of {len(A)} poses differ: worst at frame {i}: {d_m[i]:.4g} m, {d_deg[i]:.4g} deg "
            f"(tolerance {atol_m:g} m, {atol_deg:g} deg; max over all: {d_m.max():.4g} m, {d_deg.max():.4g} deg)")


def metrics_of(result: Any) -> dict[str, float]:
    """Scalar metrics of an odometry result, a bench record, a baseline job or a plain mapping. A failed bench record
    is an EvaluationError with its error (it read as a record without the metric: "it has: ")."""
    from lidarkit.odometry.result import OdometryResult

    if isinstance(result, OdometryResult):
        from lidarkit.bench.tasks.odometry import scalar_metrics

        return scalar_metrics(result)
    if isinstance(result, Mapping):
        if isinstance(result.get("status"), str) and result["status"] != "ok":
            error = result.get("error") if isinstance(result.get("error"), Mapping) else {}
            raise EvaluationError(f"the job {result['status']}: {error.get('type', '?')}: {error.get('message', '')}",
                                  source="assert_no_worse_than")
        inner = result.get("metrics") if isinstance(result.get("metrics"), Mapping) else result
        # (numpy's float32 was left out: "metric not in the result")
        return {k: float(v) for k, v in inner.items() if is_real_number(v)}
    raise ConfigError(f"cannot read metrics from a {type(result).__name__}", source="assert_no_worse_than")


def assert_no_worse_than(
    result: Any,
    baseline: Any,
    *,
    metric: str = "drift_translation_pct",
    tolerance: float | None = None,
    method: str | None = None,
    dataset: str | None = None,
    seed: int | None = None,
    experiment: str | None = None,
    task: str | None = None,
) -> None:
    """``result``'s ``metric`` is at most ``tolerance`` worse than ``baseline``'s (lower is better unless the metric
    is a rate).

    ``result``: an OdometryResult, a bench record or a metrics mapping. ``baseline``: a baseline folder (path or
    :class:`lidarkit.bench.baseline.Baseline`; ``method`` / ``dataset`` / ``seed`` / ``experiment`` / ``task`` pick the
    pinned job) or a metrics mapping (which takes none of them: ConfigError). A result over other data than the pinned
    job's (frames, dataset, seed) is an EvaluationError; so is a frame-check count (``n_bad_frames``) counted under
    other frame-check thresholds.
    ``tolerance`` None uses the baseline's recorded band (from its run-to-run noise); with a plain mapping it is 0.
    A difference within floating-point round-off (1e-9 of the value) is a tie, as in ``lidarkit baseline check``.
    """
    from lidarkit.bench.baseline import Baseline, load_baseline

    band = 0.0
    if isinstance(baseline, (str, os.PathLike)):
        baseline = load_baseline(Path(baseline))
    now_metrics = metrics_of(result)
    if isinstance(baseline, Baseline):
        job = baseline.job(method, dataset, seed, experiment=experiment, task=task)
        ref_given: Any = job
        ref_metrics = {k: float(v) for k, v in job["metrics"].items() if isinstance(v, (int, float))}
        band = float(job.get("bands", {}).get(metric, 0.0))
        _check_same_data(result, now_metrics, job, ref_metrics)
        _check_same_frame_check(result, job, metric)
    else:
        picks = {k: v for k, v in (("method", method), ("dataset", dataset), ("seed", seed), ("experiment", experiment),
                                   ("task", task)) if v is not None}
        if picks:  # (ignored: a wrong method name passed against the plain mapping)
            raise ConfigError(f"{', '.join(picks)} pick a job of a baseline folder; the baseline given is a plain "
                              f"{type(baseline).__name__}", source="assert_no_worse_than")
        ref_metrics, ref_given = metrics_of(baseline), baseline
    for which, numbers, given in (("result", now_metrics, result), ("baseline", ref_metrics, ref_given)):
        if metric not in numbers:
            raise EvaluationError(_missing_metric(metric, which, numbers, given), source="assert_no_worse_than")
    try:
        tol = band if tolerance is None else float(tolerance)
    except (TypeError, ValueError):
        tol = float("nan")
    if isinstance(tolerance, bool) or not tol >= 0 or not math.isfinite(tol):
        raise ConfigError(f"tolerance must be a finite number >= 0, got {tolerance!r}", source="assert_no_worse_than")
    now, ref = now_metrics[metric], ref_metrics[metric]
    if not math.isfinite(ref):  # (every result passed against a NaN baseline: no comparison is false)
        raise EvaluationError(f"the baseline's {metric} is {ref}: nothing to hold the result against", source="assert_no_worse_than")
    from lidarkit.bench.tasks import higher_is_better
    from lidarkit.eval.statistics import tie_tolerance

    worse_by = (ref - now) if higher_is_better(metric) else (now - ref)
    # round-off is a tie whatever the tolerance, as `baseline check` takes it (0.1 + 0.2 against 0.3 failed at 0)
    if not math.isfinite(now) or worse_by > max(tol, tie_tolerance(np.array([now]), np.array([ref]))):
        raise AssertionError(f"regression: {metric} = {now:.6g}, baseline {ref:.6g} (worse by {worse_by:.4g}, "
                             f"tolerance {tol:.4g})")


def _missing_metric(metric: str, which: str, numbers: Mapping[str, float], given: Any) -> str:
    """Why ``metric`` is not among the ``numbers`` read from ``given``: the keys it has, those it holds as None
    apart (a None value read "it has: "), and for a drift metric the reason the result records for leaving it out
    (a path shorter than the devkit's 100 m segments read as a metric missing for no reason)."""
    from lidarkit.odometry.result import OdometryResult

    inner: Mapping[str, Any] = {}
    notes: dict[str, Any] = {}
    if isinstance(given, OdometryResult):
        notes = dict(given.metrics)
    elif isinstance(given, Mapping):
        inner = given.get("metrics") if isinstance(given.get("metrics"), Mapping) else given
        info = given.get("info") if isinstance(given.get("info"), Mapping) else {}
        odometry = info.get("odometry_metrics") if isinstance(info.get("odometry_metrics"), Mapping) else {}
        notes = {**odometry, **inner}  # (a bench record keeps the run's notes with its odometry metrics)
    has = [f"it has: {', '.join(sorted(numbers))}" if numbers else "it has no numeric metric"]
    nones = sorted(str(k) for k, v in inner.items() if v is None)
    if nones:
        has.append(f"present but None: {', '.join(nones)}")
    message = f"metric {metric!r} not in the {which} ({'; '.join(has)})"
    note = notes.get("kitti_drift_note") if metric.startswith("drift_") else None
    return f"{message}; KITTI drift not computed: {note}" if isinstance(note, str) and note else message


def _check_same_data(result: Any, now_metrics: dict[str, float], job: Mapping[str, Any], ref_metrics: dict[str, float]) -> None:
    """EvaluationError when ``result`` did not run on the pinned job's data: another number of frames, other frames,
    another dataset kind or path (a KITTI root and ``sequence:`` compared as the sequence folder they resolve to, the
    sequence as its number; a ROS 2 bag's ``metadata.yaml`` as its folder), other
    files the reader read (ground truth, calibration, times), another applied KITTI angle correction, (a simulated run)
    another simulator setting, or (a bench record) another dataset, task options (odometry frames as the indices they select) or seed than the pinned job's spec. A metric is comparable on the same data only: 3 sweeps of the
    pinned 8-sweep drive, the sweeps 4-12 of it, or a simulated run against a pinned KITTI job passed against it."""
    label = job.get("label", "")

    def refuse(what: str, detail: str) -> None:
        verb = "differ" if what in ("frames", "job options") else "differs"
        raise EvaluationError(f"the result's {what} {verb} from the pinned job {label!r}: {detail}", source="assert_no_worse_than")

    if "n_frames" in now_metrics and "n_frames" in ref_metrics and now_metrics["n_frames"] != ref_metrics["n_frames"]:
        raise EvaluationError(f"the result ran over {now_metrics['n_frames']:g} frames, the pinned job {label!r} over "
                              f"{ref_metrics['n_frames']:g}: not the pinned data", source="assert_no_worse_than")
    spec = job.get("spec") if isinstance(job.get("spec"), Mapping) else {}
    pinned = spec.get("dataset") if isinstance(spec.get("dataset"), Mapping) else {}
    # a bench record: its own job spec; a pinned job's mapping (load_baseline(...).job(...)): its spec (another
    # baseline's job over other data passed on its frame count alone)
    ran_job = next((result[key] for key in ("job", "spec") if isinstance(result, Mapping) and isinstance(result.get(key), Mapping)), None)
    if ran_job is not None:
        from lidarkit.bench.jobs import canonical_json

        ran_data = pinned_data = None
        for key in ("task", "dataset", "options", "seed"):
            a, b = ran_job.get(key), spec.get(key)
            if key == "dataset" and isinstance(a, Mapping) and isinstance(b, Mapping):
                ran_data, pinned_data = _data_of_spec(a, ran_job.get("seed")), _data_of_spec(b, spec.get("seed"))
                # (named field by field: a simulator's whole configuration printed twice hid the one setting apart)
                shown = (lambda d, k: repr(d[k]) if k in d else "<absent>")
                differ = [f"{k} {shown(ran_data, k)} (pinned {shown(pinned_data, k)})"
                          for k in [*pinned_data, *(k for k in ran_data if k not in pinned_data)]
                          if (k in ran_data) != (k in pinned_data)
                          or canonical_json({"v": ran_data[k]}) != canonical_json({"v": pinned_data[k]})]
                if differ:
                    refuse("job dataset", ", ".join(differ))
                continue
            if key == "options" and isinstance(a, Mapping) and isinstance(b, Mapping):
                # odometry frames as the indices they select, as compare pairs runs (":6" and [0, ..., 5] select what
                # "0:6" does: they were refused, compared as written)
                from lidarkit.eval.compare import _options_unit

                task = str(spec.get("task"))
                a = _options_unit(task, dict(a), ran_data or {}, dict(result))
                b = _options_unit(task, dict(b), pinned_data or {}, dict(job))
                if canonical_json({"v": a}) != canonical_json({"v": b}):
                    refuse("job options", f"{ran_job.get(key)!r} (pinned {spec.get(key)!r})")
                continue
            if canonical_json({"v": a}) != canonical_json({"v": b}):
                refuse(f"job {key}", f"{a!r} (pinned {b!r})")
        return
    config = getattr(result, "config", None)
    run = (config or {}).get("run") if isinstance(config, Mapping) else None
    if not isinstance(run, Mapping) or not pinned:
        return
    if run.get("ground_truth_given"):  # (a method scored against its own estimate passed against kiss's pinned drift)
        refuse("ground truth", f"{run.get('ground_truth')!r}, given to run() by the caller, not the dataset's")
    sim = run.get("dataset_config") if isinstance(run.get("dataset_config"), Mapping) else None
    options = run.get("dataset_options") if isinstance(run.get("dataset_options"), Mapping) else {}
    ran_kind = options.get("kind") or ("sim_lidar" if sim is not None else None)
    if ran_kind is not None and pinned.get("kind") is not None and ran_kind != pinned["kind"]:
        refuse("dataset", f"kind {ran_kind} (pinned {pinned['kind']})")
    opened = _pinned_dataset(spec) if sim is None else None
    ran = sim if sim is not None else options
    expected = None
    if pinned.get("kind") == "sim_lidar":  # as recorded (a later default is other data); older baselines: rebuilt
        expected = (job.get("protocol") or {}).get("simulation") or _pinned_simulation(job)
    if expected is not None:  # every setting, those left at their defaults too (a noisier sensor is other data)
        differ = [f"{k} {ran.get(k)!r} (pinned {v!r})" for k, v in expected.items() if ran.get(k) != v]
    else:
        if "path" in ran and "path" in pinned:  # both as the folder their reader reads (a root and its sequence)
            pinned = {**pinned, "path": _read_folder(pinned)}
            ran = {**ran, "path": _read_folder({"kind": ran.get("kind") or pinned.get("kind"), "path": ran["path"],
                                                "sequence": ran.get("sequence")})}
        differ = [f"{k} {ran[k]!r} (pinned {v!r})" for k, v in pinned.items()
                  if k not in ("kind", "name") and k in ran and not _same_value(k, ran[k], v)]
        applied = (job.get("protocol") or {}).get("kitti_angle_correction")
        if isinstance(applied, bool) and ran.get("vertical_correction_applied", applied) != applied:
            differ.append(f"vertical_correction_applied {ran['vertical_correction_applied']!r} (pinned {applied!r})")
        differ += _other_files(run, opened)
    if differ:  # (before the frames: 8 frames of a 10-frame drive against the 8-frame drive read as other frames)
        refuse("dataset", ", ".join(differ))
    # the pinned selection resolved on the pinned data's length (a simulated drive: its pinned n_frames)
    n_total = ((expected or {}).get("n_frames", sim.get("n_frames")) if sim is not None
               else len(opened) if hasattr(opened, "__len__") else None)
    _check_same_frames(getattr(result, "frames", None), spec, n_total, refuse)


def _data_of_spec(dataset: Mapping[str, Any], job_seed: Any) -> dict[str, Any]:
    """A job's dataset spec as the data it names, as ``lidarkit compare`` pairs it: a simulator setting written at its
    default, or a KITTI root with ``sequence:`` beside its sequence folder, is the same data (both were refused as
    another dataset). A simulated drive without its own seed is the job seed's drive (the job seed is compared too)."""
    from lidarkit.eval.compare import _dataset_unit

    if dataset.get("kind") == "sim_lidar" and "seed" not in dataset and isinstance(job_seed, int):
        dataset = {**dataset, "seed": job_seed}
    return _dataset_unit(dict(dataset), {})


def _check_same_frame_check(result: Any, job: Mapping[str, Any], metric: str) -> None:
    """EvaluationError when ``metric`` counts frames of the per-frame check and ``result`` ran it under other thresholds
    than the pinned job (a baseline recorded before they were pinned: today's defaults, which bench jobs run under):
    3 bad frames passed against 0 once the thresholds were loosened. A plain metrics mapping records none: not held."""
    from lidarkit.bench.baseline import FRAME_CHECK_METRICS, frame_check_thresholds

    if metric not in FRAME_CHECK_METRICS:
        return
    if isinstance(result, Mapping) and isinstance(result.get("protocol"), Mapping):  # a pinned job's mapping
        ran = result["protocol"].get("frame_check") or frame_check_thresholds()
    else:  # an OdometryResult's run config, or a bench record's (in its info)
        info = result.get("info") if isinstance(result, Mapping) else None
        config = info.get("config") if isinstance(info, Mapping) else getattr(result, "config", None)
        run = config.get("run") if isinstance(config, Mapping) else None
        ran = run.get("frame_check") if isinstance(run, Mapping) else None
    if not isinstance(ran, Mapping):
        return
    ran = frame_check_thresholds(ran)
    pinned = frame_check_thresholds((job.get("protocol") or {}).get("frame_check") or None)
    differ = [f"{k} {ran.get(k, '<absent>')!r} (pinned {pinned.get(k, '<absent>')!r})"
              for k in [*pinned, *(k for k in ran if k not in pinned)] if ran.get(k) != pinned.get(k)]
    if differ:
        raise EvaluationError(f"the result's frame check differs from the pinned job {job.get('label', '')!r}: "
                              f"{', '.join(differ)} ({metric} counts under other thresholds)", source="assert_no_worse_than")


def _read_folder(spec: Mapping[str, Any]) -> Any:
    """The folder (or file) a dataset spec's reader reads, as a baseline hashes it (a KITTI root with ``sequence:``: the
    sequence folder, whichever reader records which; a ROS 2 bag's ``metadata.yaml``: its folder); the path as given
    when it cannot be resolved (the data moved away: compared as written)."""
    from lidarkit.bench.baseline import dataset_folder

    try:
        return str(dataset_folder({k: v for k, v in spec.items() if v is not None}))
    except (LidarKitError, TypeError, ValueError):
        return spec.get("path")


def _same_value(key: str, ran: Any, pinned: Any) -> bool:
    if key == "sequence":  # (0, "0" and "00" name one sequence: the readers write it as they please)
        return _sequence_number(ran) == _sequence_number(pinned)
    if key.endswith("path") or key.endswith("_file") or key.endswith("_dir"):
        try:
            return Path(str(ran)).resolve() == Path(str(pinned)).resolve()
        except (OSError, ValueError):
            return ran == pinned
    return ran == pinned


def _sequence_number(value: Any) -> Any:
    """A sequence as its number when it is one (``"00"`` -> 0), else as given."""
    if isinstance(value, int) and not isinstance(value, bool):
        return value
    if isinstance(value, str):
        try:
            return int(value)
        except ValueError:
            return value
    return value


def _pinned_dataset(spec: Mapping[str, Any]) -> Any:
    """The pinned job's dataset opened (its length resolves ``frames: ":-2"``, its reader names the files it reads);
    None for a generated one."""
    from lidarkit.bench.datasets import PATHLESS_KINDS
    from lidarkit.bench.jobs import Job
    from lidarkit.bench.tasks._datasets import open_dataset_spec, seeded_dataset

    if not isinstance(spec.get("dataset"), Mapping) or spec["dataset"].get("kind") in PATHLESS_KINDS:
        return None
    return open_dataset_spec(dict(seeded_dataset(Job.from_spec(dict(spec)))))


def _other_files(run: Mapping[str, Any], opened: Any) -> list[str]:
    """The files and folders the run's reader read (its ground truth, calibration, times, scans) that are not the pinned
    dataset's: another ``poses_file`` scored the run against another truth."""
    from lidarkit.odometry.settings import reader_settings

    effective = run.get("effective") if isinstance(run.get("effective"), Mapping) else {}
    ran = effective.get("reader")
    if opened is None or not isinstance(ran, Mapping):
        return []
    pinned = reader_settings(opened)
    return [f"{k} {ran[k]!r} (pinned {v!r})" for k, v in pinned.items()
            if k.endswith(("_path", "_file", "_dir")) and k in ran and not _same_value(k, ran[k], v)]


def _check_same_frames(frames: Any, spec: Mapping[str, Any], n_total: int | None, refuse) -> None:
    """The dataset frames the result ran over (``OdometryResult.frames``) against the pinned job's ``frames`` option
    (all frames when it has none) resolved on the pinned dataset's ``n_total`` frames (resolved on the frames the
    result ran, ``":-2"`` refused the pinned run itself)."""
    from lidarkit.odometry.inputs import parse_frames

    if frames is None or not len(frames):
        return
    ran = [int(f) for f in np.asarray(frames).reshape(-1)]
    selection = (spec.get("options") or {}).get("frames") if isinstance(spec.get("options"), Mapping) else None
    n_total = int(max(ran)) + 1 if n_total is None else int(n_total)  # (a dataset with no length)
    try:
        expected = parse_frames(selection, n_total).tolist()
    except LidarKitError:
        return
    if ran != expected:
        shown, pinned_shown = (index_runs(frames, max_runs=5) or "none" for frames in (ran, expected))
        detail = f"{shown} (pinned {selection or 'all'}: {pinned_shown})"
        if "..." in shown + pinned_shown:  # (the runs shown may read alike: name the first frame apart)
            first = next((k for k, (a, b) in enumerate(zip(ran, expected)) if a != b), min(len(ran), len(expected)))
            at = (lambda f: str(f[first]) if first < len(f) else "none")
            detail += f", first apart at selected frame {first}: {at(ran)} (pinned {at(expected)})"
        refuse("frames", detail)


def _pinned_simulation(job: Mapping[str, Any]) -> dict[str, Any] | None:
    """The whole simulator configuration a pinned job recorded before lidarkit pinned it, rebuilt (its spec's settings,
    today's defaults for the rest, its seed); None when it cannot be rebuilt."""
    from lidarkit.bench.baseline import simulation_config
    from lidarkit.bench.jobs import Job

    try:
        return simulation_config(Job.from_spec(dict(job["spec"])))
    except (LidarKitError, KeyError, TypeError, ValueError):
        return None
