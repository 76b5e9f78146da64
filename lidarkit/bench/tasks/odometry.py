"""``odometry``: any registered ICP variant over a scan sequence through ``lidarkit.odometry.run``, scored vs ground truth.

Datasets: every kind that gives LiDAR scans (:func:`lidarkit.bench.datasets.scan_kinds`: the simulator and each
``lidarkit.io`` scan reader, bags and MCAP files included), opened as ``lidarkit.odometry.run`` opens ``KIND:PATH?opt=v``.
Options: ``frames`` — a frame selection as ``lidarkit.odometry.run`` takes it (``"0:50"``, or a list of indices), of
2 scans or more (one scan is the start and scores nothing); ``init`` — the run's initial guess (``"constant_velocity"``,
or ``"odometry"`` on a dataset with its own odometry, e.g. a CARMEN log).
Metrics come from the odometry run's own scoring (APE / RPE / KITTI drift through ``lidarkit.eval``); every
label names its alignment (``info["metric_alignment"]`` too, for the report), and ``n_bad_frames`` counts the
frames failing the independent per-frame check (:mod:`lidarkit.odometry.frame_check`). A dataset with relation ground
truth and no poses (a CARMEN log's ``.relations``) is scored by the relations metric (:mod:`lidarkit.eval.relations`):
``relation_trans_mean_m`` / ``relation_rot_mean_deg`` over the relations the selected frames cover.
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, field_validator

from lidarkit.bench.datasets import scan_kinds
from lidarkit.bench.jobs import Job, whole_floats_as_ints
from lidarkit.bench.tasks import Metric, Task, TaskOutput, WholeInt, import_module_for_task
from lidarkit.bench.tasks._datasets import (check_reader_options, open_dataset_spec, options_model, require_kitti_data,
                                             scan_count_at_load, seeded_dataset)
from lidarkit.errors import ConfigError, DataError, EvaluationError

log = logging.getLogger(__name__)

MAX_SERIES_POINTS = 2000

#: Alignment of each APE / RPE metric of this task (read by the report's labelling, see ``lidarkit.bench.report``).
METRIC_ALIGNMENT_BY_NAME = {
    "ape_se3_rmse_m": "SE(3)-aligned",
    "ape_rmse_m": "unaligned, first pose anchored",
    "rpe_trans_rmse_m": "1 frame, alignment-free",
    "rpe_rot_rmse_deg": "1 frame, alignment-free",
    "final_error_m": "unaligned",
}
#: the RPE's step where the frame selection skips frames (``frames: [0, 5, 9]``): one selected frame, not one frame
SELECTED_FRAME = "1 selected frame, alignment-free"


def metric_alignment(frames: np.ndarray) -> dict[str, str]:
    """:data:`METRIC_ALIGNMENT_BY_NAME` of a run over dataset ``frames``: a selection that skips frames has its RPE over
    one selected frame (steps of 5 and 4 KITTI frames were labelled "1 frame"), by the run's own rule."""
    from lidarkit.odometry.settings import skips_frames

    if not skips_frames(frames):
        return dict(METRIC_ALIGNMENT_BY_NAME)
    return {**METRIC_ALIGNMENT_BY_NAME, "rpe_trans_rmse_m": SELECTED_FRAME, "rpe_rot_rmse_deg": SELECTED_FRAME}


class OdometryOptions(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)
    # YAML's true was taken as frame 1 ([true, 2, 3] ran frames 1, 2, 3)
    frames: str | list[WholeInt] | None = None
    init: str = "constant_velocity"

    @field_validator("frames", mode="before")
    @classmethod
    def _indices_or_text(cls, frames: Any) -> Any:
        """One reason for a list holding what is not an index (the union's two were "a valid string; a valid integer");
        a whole float is its index, as :data:`WholeInt` reads it."""
        if not isinstance(frames, list):
            return frames
        frames = whole_floats_as_ints(frames)
        for value in frames:
            if isinstance(value, bool) or not isinstance(value, int):
                raise ValueError(f"a list of frame indices holds {value!r}, not an integer (a slice is text: '0:10')")
        return frames


def _get(d: dict[str, Any] | None, *keys: str) -> float | None:
    for key in keys:
        if not isinstance(d, dict):
            return None
        d = d.get(key)
    return None if d is None else float(d)


def trajectory_series(ref_xyz: np.ndarray | None, est_xyz: np.ndarray, times_s: np.ndarray) -> dict[str, Any]:
    """``trajectory_xy`` and ``error_over_time`` series (decimated to at most MAX_SERIES_POINTS)."""
    step = max(1, int(np.ceil(len(est_xyz) / MAX_SERIES_POINTS)))
    sel = slice(None, None, step)
    series: dict[str, Any] = {
        "trajectory_xy": {"ref": [] if ref_xyz is None else ref_xyz[sel, :2].round(4).tolist(), "est": est_xyz[sel, :2].round(4).tolist()}
    }
    if ref_xyz is not None and len(ref_xyz) == len(est_xyz):
        errors = np.linalg.norm(est_xyz - ref_xyz, axis=1)
        series["error_over_time"] = {
            "t": (times_s[sel] - times_s[0]).round(4).tolist(),
            "error": errors[sel].round(6).tolist(),
            "label": "position error (no alignment) [m]",
        }
    return series


def drift_segments(result: Any) -> dict[str, list[float]] | None:
    """Per-segment KITTI errors of an odometry result (for pooled averages, per-speed tables and box plots)."""
    from lidarkit import eval as leval
    from lidarkit.eval.tables import SegmentErrors, frame_period_s
    from lidarkit.odometry.metrics import paired

    if result.ground_truth is None:
        return None
    ref, est = paired(result.ground_truth, result.trajectory)
    if not leval.drift_segments_possible(ref):
        return None
    # (timed by the stamps, as `lidarkit eval --tables` times them: a count of poses misses the frames a gap left out)
    return SegmentErrors.from_drift(leval.kitti_drift(ref, est), frame_period_s=frame_period_s(ref),
                                    timestamps_s=ref.timestamps_s).to_dict()


class OdometryTask(Task):
    description = "sequence odometry with an ICP variant (APE, RPE, KITTI drift, frame rate)"

    @property
    def dataset_kinds(self) -> tuple[str, ...]:  # type: ignore[override]
        """Every kind ``lidarkit.odometry.run`` reads scans from (:func:`scan_kinds`; a bag or MCAP file was refused
        though the run takes it), readers registered after this module loaded included."""
        return scan_kinds()

    metrics = (
        Metric("ape_se3_rmse_m", "APE RMSE (SE(3)-aligned) [m]"),
        Metric("ape_rmse_m", "APE RMSE (unaligned, first pose anchored) [m]"),
        Metric("rpe_trans_rmse_m", "RPE trans. [m/frame]"),  # (its step named by the records: 1 frame or 1 selected frame)
        Metric("rpe_rot_rmse_deg", "RPE rot. [deg/frame]"),
        Metric("drift_translation_pct", "KITTI drift [%]"),
        Metric("drift_rotation_deg_per_100m", "KITTI rot. [deg/100m]"),
        Metric("final_error_m", "final error (unaligned) [m]"),
        # (a log with relation ground truth only: the report's headline where no APE exists)
        Metric("relation_trans_mean_m", "relations: mean trans. error [m]"),
        Metric("relation_rot_mean_deg", "relations: mean rot. error [deg]"),
        Metric("n_bad_frames", "bad frames (independent check)"),
        Metric("hz", "frames/s", kind="speed", better="higher"),
    )

    def require(self) -> None:
        import_module_for_task("odometry", "lidarkit.registration")
        odometry = import_module_for_task("odometry", "lidarkit.odometry")
        if not hasattr(odometry, "run"):
            raise ConfigError("lidarkit.odometry has no run()", source="task")

    def available_methods(self) -> list[str] | None:
        from lidarkit.registration import available_icp

        return available_icp()

    def optional_methods(self) -> tuple[str, ...]:
        from lidarkit.registration.registry import OPTIONAL_VARIANTS

        return tuple(OPTIONAL_VARIANTS)

    def resolved_options(self, options: dict[str, Any]) -> dict[str, Any]:
        """The options with their defaults (``frames``, ``init``) written out, as a baseline pins them."""
        self.validate_options(options)
        return OdometryOptions(**options).model_dump(mode="json")

    def validate_options(self, options: dict[str, Any]) -> None:
        given = options_model(OdometryOptions, options, "odometry")
        from lidarkit.odometry.runner import INIT_GUESSES

        if given.init not in INIT_GUESSES:
            raise ConfigError(f"init: unknown initial guess {given.init!r}; known: {', '.join(INIT_GUESSES)}",
                              source="options")
        if given.frames is not None:  # its syntax, before anything runs (its range is the dataset's)
            from lidarkit.odometry.inputs import parse_frames

            frames = given.frames
            if isinstance(frames, list):
                # (a stand-in length named its own range: "must lie in 0..5" for [-2, 5] on 10 scans, "0..-1" for [-1])
                negative = next((f for f in frames if isinstance(f, int) and f < 0), None)
                if negative is not None:
                    raise ConfigError(f"frame indices must be >= 0, got {negative} (a slice such as '-3:' counts from "
                                      "the end)", source="frames")
            parse_frames(frames, 1 + max((f for f in frames if isinstance(f, int)), default=0) if isinstance(frames, list) else 1)
            if isinstance(frames, list) and len(frames) == 1:  # (whatever the dataset; a slice's count is known with it)
                raise ConfigError(f"{frames!r} selects 1 scan: {TOO_FEW_SCANS}", source="frames")

    def validate_dataset(self, dataset: dict[str, Any], options: dict[str, Any]) -> None:
        check_reader_options(dataset)
        require_kitti_data(dataset, "scans")
        given = options_model(OdometryOptions, options, "odometry")
        check_frames(given.frames, dataset)
        if given.init == "odometry" and not kind_gives_odometry(dataset["kind"]):
            raise ConfigError(f"init: 'odometry' needs a dataset with its own odometry (e.g. a CARMEN log); kind "
                              f"{dataset['kind']!r} has none", source="options")

    def validate(self, method: str, params: dict[str, Any], dataset: dict[str, Any], options: dict[str, Any]) -> None:
        from lidarkit.registration import get_icp

        registration = get_icp(method, **params)
        if (options.get("init") == "odometry" and getattr(registration, "stateful", False)
                and not getattr(registration, "accepts_motion_guess", False)):  # (as run() refuses it, before any job)
            raise ConfigError(f"init: 'odometry': {method} is stateful and keeps its own motion model (no motion_guess)",
                              source="options")

    def run(self, job: Job) -> TaskOutput:
        return run_odometry_job(job)[1]


def kind_gives_odometry(kind: str) -> bool:
    """False for a built-in dataset kind whose reader has no ``odometry`` (``init: odometry`` refused at suite load, as
    the CLI refuses it); True otherwise (a registered reader is left to its jobs' runs)."""
    from lidarkit.io import get_reader

    if kind == "sim_lidar":
        from lidarkit.sim.lidar import SimulatedLidarSequence

        return hasattr(SimulatedLidarSequence, "odometry")
    reader = get_reader(kind)
    built_in = isinstance(reader, type) and reader.__module__.startswith("lidarkit.")
    return not built_in or hasattr(reader, "odometry")


def relation_scores(result: Any, sequence: Any) -> tuple[dict[str, Any] | None, str | None]:
    """``(relation scores, None)`` of a run without ground truth over a dataset with relations (the run's own when it
    scored them, else :func:`lidarkit.eval.relations.relation_error` of its trajectory, as ``lidarkit eval --relations``
    scores its poses_tum.txt: only the relations the selected frames cover), ``(None, why)`` when none is covered, or
    ``(None, None)`` without relations."""
    if result.ground_truth is not None:
        return None, None
    scored = (result.metrics or {}).get("relations")
    if isinstance(scored, dict):
        return scored, None
    relations = getattr(sequence, "relations", None)
    if relations is None:
        return None, None
    from lidarkit.eval.relations import relation_error

    try:
        return relation_error(result.trajectory, relations).to_dict(), None
    except EvaluationError as err:
        return None, f"relation ground truth, none scored over these frames: {err.reason}"


#: why a run over fewer scans is refused (its one pose is the start: the job ran, "ok", and scored nothing)
TOO_FEW_SCANS = "odometry needs 2 scans or more (the first is the start, where nothing is scored)"


def too_few_scans(frames: Any, n_scans: int) -> str | None:
    """Why ``frames`` of a dataset of ``n_scans`` scans selects too few to score (fewer than 2), else None; a bad
    selection raises parse_frames' ConfigError."""
    from lidarkit.odometry.inputs import parse_frames

    n_selected = len(parse_frames(frames, n_scans))
    if n_selected >= 2:
        return None
    if frames is None:
        return f"the dataset has {n_selected or 'no'} scan{'s' if n_selected == 0 else ''}: {TOO_FEW_SCANS}"
    if n_selected == 0:
        return f"frames: {frames!r} selects no scan of the dataset's {n_scans}"
    return f"frames: {frames!r} selects 1 scan of the dataset's {n_scans}: {TOO_FEW_SCANS}"


def check_frames(frames: Any, spec: dict[str, Any]) -> None:
    """``frames`` checked against the length of a dataset known at suite load (:func:`scan_count_at_load`: a stand-in
    length let [50, 51, 52] through on a 10-scan sequence, and [0, 2, 20] on a 5-sweep simulated drive, and every job
    failed, exit 0), fewer than 2 scans refused (``"0:1"`` ran and scored nothing); a ConfigError naming the options.
    The others (bags, pcaps, logs) are checked when their jobs run."""
    n_scans = scan_count_at_load(spec)
    if n_scans is None:
        return
    try:
        problem = too_few_scans(frames, n_scans)
    except ConfigError as err:
        raise ConfigError(f"frames: {err.reason} (the dataset has {n_scans} scans)", source="options") from None
    if problem is not None:  # (a whole dataset of one scan: an error of the dataset, not of the options)
        raise ConfigError(problem, source="dataset" if frames is None else "options")


def scalar_metrics(result: Any) -> dict[str, float]:
    """The bench metrics (``ape_rmse_m``, ``drift_translation_pct``, ...) of an :class:`OdometryResult`."""
    m = result.metrics
    metrics = {
        "ape_se3_rmse_m": _get(m, "ape_translation_se3_m", "stats", "rmse"),
        "ape_rmse_m": _get(m, "ape_translation_m", "stats", "rmse"),
        "rpe_trans_rmse_m": _get(m, "rpe_translation_m", "stats", "rmse"),
        "rpe_rot_rmse_deg": _get(m, "rpe_rotation_deg", "stats", "rmse"),
        "drift_translation_pct": _get(m, "kitti_drift", "translation_pct"),
        "drift_rotation_deg_per_100m": _get(m, "kitti_drift", "rotation_deg_per_100m"),
        "final_error_m": _get(m, "final_error", "translation_m"),
        "hz": float(result.fps),
        "n_frames": float(len(result.frames)),
        # (None, not 0, where the variant gives no verdict: kiss read "converged on every frame")
        "n_not_converged": float(result.n_not_converged) if result.convergence_measured else None,
        "n_bad_frames": float(result.n_bad_frames),
    }
    metrics = {k: v for k, v in metrics.items() if v is not None}
    return metrics


def run_odometry_job(job: Job) -> tuple[Any, TaskOutput]:
    """The odometry result of ``job`` and its task output (metrics, plot series, config), for the task and for
    golden baselines (which also keep the trajectory)."""
    from lidarkit.odometry import run

    options = options_model(OdometryOptions, job.options, "odometry")  # (a pinned spec re-run: one line, not pydantic's dump)
    sequence = open_dataset_spec(seeded_dataset(job))
    problem = too_few_scans(options.frames, len(sequence))  # (a bag's length is known once opened, not at suite load)
    if problem is not None:
        raise DataError(problem, source=job.dataset_name)
    result = run(sequence, job.method, params=dict(job.params), frames=options.frames, init=options.init)
    m = result.metrics
    metrics = scalar_metrics(result)
    relations, unscored = relation_scores(result, sequence)
    if relations is not None:
        metrics["relation_trans_mean_m"] = float(relations["translation_abs_m"]["mean"])
        metrics["relation_rot_mean_deg"] = float(relations["rotation_abs_deg"]["mean"])
        # (how many relations the means are over: 103 for frames 0:600 of ACES, 2 for 0:600:3)
        metrics["relation_n_used"] = float(relations["n_used"])
    est = result.trajectory
    times = est.timestamps_s if est.timestamps_s is not None else np.arange(len(est)) * 0.1
    ref_xyz = None if result.ground_truth is None else result.ground_truth.positions_xyz
    series = trajectory_series(ref_xyz, est.positions_xyz, np.asarray(times, dtype=float))
    segments = drift_segments(result)
    if segments is not None:
        series["drift_segments"] = segments
    if relations is not None:  # (the run's note pointed at an eval of a poses_tum.txt a job never writes)
        m = {**m, "relations": relations, "ground_truth_note": f"relations: {relations['n_used']} of "
             f"{relations['n_relations']} scored (metrics relation_trans_mean_m, relation_rot_mean_deg)"}
    elif unscored is not None:
        m = {**m, "ground_truth_note": unscored}
        # (said in the job's warnings and so the report's: the job was "ok" with no accuracy metric, and why was only
        # in its JSON's info)
        log.warning("%s on %s: %s; the job has no accuracy metric", job.method_label, job.dataset_name, unscored)
    info = {"odometry_metrics": m, "config": result.config, "metric_alignment": metric_alignment(np.asarray(result.frames))}
    return result, TaskOutput(metrics=metrics, series=series, info=info)
