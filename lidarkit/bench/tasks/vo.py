"""``vo``: monocular visual odometry (``lidarkit.vo``) on an image sequence, scored with ``lidarkit.eval``.

Methods are the VO presets (``lidarkit.vo.available_presets()``: ``lidarkit``, ``report_sift``, ``report_orb``);
params are dotted-path changes to the preset (``scale.mode: relative``, ``features.detector: orb``), validated
by ``lidarkit.vo.preset``. The job seed becomes the config's ``seed``. Options: ``max_frames`` (first N
images), ``align`` (``auto``: SE(3) for ground-truth scale, Sim(3) otherwise; or ``none``/``se3``/``sim3``),
``smoothed`` (score the Savitzky-Golay smoothed trajectory). Metrics come from ``lidarkit.vo.evaluation``; the RPE
over 1 frame is labelled alignment-free for ``se3`` and ``none`` (a rigid alignment leaves it as it is), Sim(3)-aligned
for ``sim3`` (its scale scales it); ``final_error_m`` is the last position's error after the row's alignment, as APE's
(the CLI's final error is raw for ground-truth scale: in a table of methods with other scale modes, raw and aligned
rows made the best method look 5x worse). The scores start at the first estimated frame (``scored_from_frame`` in the
job's info, as ``lidarkit vo`` scores): unreadable first images only hold its pose. Images are read into memory before
the run, so frames/s is the pipeline's speed.

Datasets: ``kitti`` (its image sequence), ``tum`` (K from its ``K:`` option, else from the freiburg camera its folder
name gives: a folder naming none is refused before any job runs), and ``sim_camera``, the camera simulator as
``lidarkit vo`` opens ``simcam:street?key=value`` (options: ``lidarkit.sim.street_camera.CameraSimConfig`` fields; its
exact K and ground truth); a simulated drive without its own ``seed`` is seeded by the job's, as ``sim_lidar`` is for
odometry.
"""

from __future__ import annotations

import logging
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from lidarkit.bench.datasets import dataset_label, dataset_options
from lidarkit.bench.jobs import Job
from lidarkit.bench.tasks import Metric, Task, TaskOutput, WholeInt, import_module_for_task
from lidarkit.bench.tasks._datasets import (OPENED_AT_LOAD, check_reader_options, open_dataset_spec, options_model,
                                             require_kitti_data)
from lidarkit.errors import ConfigError, EvaluationError

log = logging.getLogger(__name__)


class VOOptions(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)
    max_frames: WholeInt | None = Field(None, ge=2)  # (YAML's true was read as the number 1)
    align: Literal["auto", "none", "se3", "sim3"] = "auto"
    smoothed: bool = False


def _vo_api() -> Any:
    vo = import_module_for_task("vo", "lidarkit.vo")
    import_module_for_task("vo", "lidarkit.vo.pipeline")  # (OpenCV: the package loads it on first use, past this check)
    for name in ("preset", "available_presets", "run_vo", "images_in_memory"):
        if not hasattr(vo, name):
            raise ConfigError(f"lidarkit.vo has no {name}() yet", source="task")
    return vo


def _config(vo: Any, method: str, params: dict[str, Any], seed: int | None = None) -> Any:
    changes = dict(params)
    if seed is not None and "seed" not in changes:
        changes["seed"] = seed
    return vo.preset(method, **changes)


class VisualOdometryTask(Task):
    description = "monocular visual odometry (APE, RPE, final error after alignment, frames/s)"
    dataset_kinds = ("kitti", "tum", "sim_camera")
    metrics = (
        Metric("ape_rmse_m", "APE RMSE [m]"),
        Metric("rpe_trans_rmse_m", "RPE trans. [m/frame]"),
        Metric("final_error_m", "final error [m]"),
        Metric("rejected_frames", "rejected frames"),
        Metric("hz", "frames/s", kind="speed", better="higher"),
    )

    def require(self) -> None:
        _vo_api()

    def validate(self, method: str, params: dict[str, Any], dataset: dict[str, Any], options: dict[str, Any]) -> None:
        vo = _vo_api()
        if method not in vo.available_presets():
            raise ConfigError(f"unknown VO method {method!r}; known presets: {', '.join(vo.available_presets())}", source="method")
        config = _config(vo, method, params)
        if config.scale.mode == "gt" and _has_ground_truth(dataset) is False:  # (every job failed, exit 0)
            given = "its params" if "scale.mode" in params else "the preset's default"
            raise ConfigError(f"{method} scales each step by the ground truth (scale.mode gt, {given}) and the dataset "
                              f"{dataset_label(dataset)} has no ground-truth poses: give the dataset its poses, or the "
                              "method params {scale.mode: relative} (or none)", source="method")

    def available_methods(self) -> list[str] | None:
        return list(_vo_api().available_presets())

    def resolved_options(self, options: dict[str, Any]) -> dict[str, Any]:
        """The options with their defaults (``max_frames``, ``align``, ``smoothed``) written out, as a baseline pins them."""
        self.validate_options(options)
        return VOOptions(**options).model_dump(mode="json")

    def validate_options(self, options: dict[str, Any]) -> None:
        options_model(VOOptions, options, "vo")

    def validate_dataset(self, dataset: dict[str, Any], options: dict[str, Any]) -> None:
        if dataset["kind"] == "sim_camera":  # (no reader: its options are the simulator's config, checked without rendering)
            from lidarkit.sim.street_camera import make_camera_config

            make_camera_config(**dataset_options(dataset))
            return
        check_reader_options(dataset)
        require_kitti_data(dataset, "images")
        if dataset["kind"] == "tum" and dataset.get("K") is None:  # (every job failed: "MonoVO: intrinsics K are required")
            from lidarkit.io.tum import tum_intrinsics_for

            if tum_intrinsics_for(dataset["path"]) is None:
                raise ConfigError(f"the TUM folder {dataset['path']} names no freiburg camera (freiburg1/2/3 or fr1/2/3) "
                                  "to take the intrinsics of: give the dataset's K: option (3x3)", source="dataset")

    def run(self, job: Job) -> TaskOutput:
        vo = _vo_api()
        options = options_model(VOOptions, job.options, "vo")  # (a pinned spec re-run: one line, not pydantic's dump)
        config = _config(vo, job.method, job.params, job.seed)
        sequence = _open_images(job)
        if hasattr(sequence, "as_image_sequence"):
            sequence = sequence.as_image_sequence()
        if options.max_frames is not None:
            from lidarkit.vo.inputs import FrameRange

            sequence = FrameRange(sequence, 0, options.max_frames)  # read only the frames used
        images = vo.images_in_memory(sequence)
        gt = sequence.ground_truth
        timestamps = sequence.timestamps_s
        timestamps = None if timestamps is None else np.asarray(timestamps, dtype=float)
        result = vo.run_vo(images, sequence.K, config, ground_truth=gt, timestamps_s=timestamps)
        est = result.smoothed() if options.smoothed else result.trajectory
        summary = result.summary()
        metrics: dict[str, Any] = {
            "hz": float(result.frames_per_s),
            "rejected_frames": float(summary["rejected"]),
            "n_frames": float(result.n_frames),
        }
        series: dict[str, Any] = {}
        scores, unscored, first = _scores(result, est, gt, config.scale.mode, options.align)
        if unscored is not None:  # (as `lidarkit vo` says it: the job is ok, its poses without an accuracy metric)
            log.warning("%s on %s: %s; the job has no accuracy metric", job.method_label, job.dataset_name, unscored)
        if scores is not None:
            align, ape = scores.metrics["align"], scores.ape
            metrics.update({k: scores.metrics[k] for k in ("ape_rmse_m", "rpe_trans_rmse_m")})
            metrics["final_error_m"] = scores.metrics["final_error_aligned_m"]  # (aligned as APE is, on every row)
            # camera frame: x right, z forward -> the ground plane is x-z
            ref_xz = np.asarray(ape.ref.positions_xyz)[:, [0, 2]]
            est_xz = np.asarray(ape.est_aligned.positions_xyz)[:, [0, 2]]
            frames = np.arange(first, first + len(ape.errors))
            t = frames.astype(float) if timestamps is None else timestamps[frames] - timestamps[0]
            series = {
                "trajectory_xy": {"ref": ref_xz.round(4).tolist(), "est": est_xz.round(4).tolist()},
                "error_over_time": {"t": np.round(t, 4).tolist(), "error": np.round(ape.errors, 6).tolist(),
                                    "label": f"APE ({align} aligned) [m]", **({"t_label": "frame"} if timestamps is None else {})},
            }
            info_align, scored = align, {"scored_from_frame": first}
        else:
            info_align, scored = None, {} if unscored is None else {"ground_truth_note": unscored}
        return TaskOutput(metrics=metrics, series=series,
                          info={"summary": summary, "align": info_align, "config": config.model_dump(mode="json"),
                                "metric_alignment": _alignment_labels(info_align), **scored})


def _scores(result: Any, est: Any, gt: Any, scale_mode: str, align: str) -> tuple[Any, str | None, int]:
    """``(scores, None, first)`` of the estimate ``est`` from the first estimated frame on (``first``), as ``lidarkit vo``
    scores it; ``(None, why, first)`` where they cannot be computed (fewer than 3 poses: ``max_frames: 2`` failed every
    job with "se3 alignment needs at least 3 poses"; a ground truth that leaves the alignment undefined);
    ``(None, None, 0)`` without ground truth."""
    from lidarkit.vo.evaluation import score_vo, scored_frames

    if gt is None:
        return None, None, 0
    first, tail, why = scored_frames(result, len(gt))  # (the frames before it hold its pose: scored, APE 0.29 m, not 0.008)
    if tail is None:
        return None, why, first
    try:
        return score_vo(est[tail], gt[tail], scale_mode, None if align == "auto" else align), None, first
    except EvaluationError as err:
        return None, err.reason, first


def _has_ground_truth(dataset: dict[str, Any]) -> bool | None:
    """Whether a dataset has ground-truth poses, for the kinds known at suite load (the simulator's are exact; a
    reader of :data:`OPENED_AT_LOAD` is open already); None for the others, known when their jobs run."""
    if dataset["kind"] == "sim_camera":
        return True
    if dataset["kind"] not in OPENED_AT_LOAD:
        return None
    sequence = open_dataset_spec(dataset)
    if hasattr(sequence, "poses_path"):  # a KITTI sequence: its pose file (the images' poses are read when a job runs)
        return sequence.poses_path is not None
    return getattr(sequence, "ground_truth", None) is not None


def camera_config(job: Job) -> Any:
    """The camera simulator's whole config of a ``sim_camera`` job: its spec's settings, seeded by the job's seed unless
    the spec gives one (``seeds: 5`` drives five different streets), today's defaults for the rest."""
    from lidarkit.sim.street_camera import make_camera_config

    return make_camera_config(**{"seed": int(job.seed), **dataset_options(job.dataset)})


def _open_images(job: Job) -> Any:
    """The job's image sequence: a reader's, or the camera simulator's (:func:`camera_config`)."""
    if job.dataset["kind"] != "sim_camera":
        return open_dataset_spec(job.dataset)
    from lidarkit.sim.street_camera import SimulatedCameraSequence

    return SimulatedCameraSequence(camera_config(job))


def _alignment_labels(align: str | None) -> dict[str, str]:
    """Alignment of the metrics for the report labels ("Sim(3)-aligned", "unaligned"). The RPE over 1 frame is
    alignment-free under an SE(3) alignment or none (one rigid motion of every pose cancels in each relative pose), and
    is labelled so, as the odometry task's is (it read "SE(3)-aligned" where ``lidarkit vo`` names no alignment); a
    Sim(3) alignment's scale scales it."""
    from lidarkit.bench.tasks.odometry import METRIC_ALIGNMENT_BY_NAME
    from lidarkit.eval.ape_rpe import alignment_label

    if align is None:
        return {}
    text = alignment_label(align)
    rpe = METRIC_ALIGNMENT_BY_NAME["rpe_trans_rmse_m"] if align in ("none", "se3") else f"1 frame, {text}"
    return {"ape_rmse_m": text, "rpe_trans_rmse_m": rpe, "final_error_m": text}
