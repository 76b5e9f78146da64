"""``icp_pair``: pairwise registration of chosen scan pairs against ground truth, any registered ICP variant.

Datasets: every kind that gives LiDAR scans, as for odometry (:func:`lidarkit.bench.datasets.scan_kinds`); one without
ground-truth poses (a bag without its odometry topic; a CARMEN log, which has relations only: refused at load) needs
``ground_truth_file``.
Options (per experiment): ``pairs`` — ``[[target, source], ...]`` (KITTI, kind ``kitti``: frame numbers, e.g.
``[[94, 95]]``, with ``ground_truth_file`` too; other kinds: scan indices; two different scans); default, and only
without ``pairs``: the first ``max_pairs`` pairs of consecutive frame numbers (never across a gap in the files; fewer:
a warning).
``init_noise_m`` / ``init_noise_deg`` — start from the ground-truth motion perturbed by a seeded random
motion of that size (finite, >= 0; 0 = start from identity, the default). ``ground_truth_file`` — a 4x4 ``T_target_source``
text file for a dataset without poses holding one pair, e.g. the bundled ``sample:kitti_pair`` folder with
``pairs: [[0, 1]]``; a relative path is looked up in the dataset folder only (a bag or pcap file: the folder holding
it; not beside the suite file, as reader path options are): give an absolute path for a file elsewhere.

The scans are read as the method reads them, as in the odometry task (KITTI under ``vertical_correction: auto``:
kiss-icp's vertical-angle correction for kiss); the record's ``info["effective"]`` names the reader's corrections.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationInfo, field_validator

from lidarkit.bench.jobs import Job
from lidarkit.bench.tasks import Metric, Task, TaskOutput, WholeInt, import_module_for_task
from lidarkit.bench.tasks._datasets import (OPENED_AT_LOAD, check_reader_options, open_dataset_spec, options_model,
                                             scan_count_at_load, seeded_dataset)
from lidarkit.bench.datasets import dataset_label, dataset_path, scan_kinds
from lidarkit.errors import ConfigError, DataError, index_runs

log = logging.getLogger(__name__)

#: kinds whose reader never gives ground-truth poses (a CARMEN log: relations only): refused at suite load without
#: opening them, unless a ``ground_truth_file`` gives the motion (every job failed when they ran, after --dry-run passed)
KINDS_WITHOUT_POSES = frozenset({"carmen"})


def no_poses_reason(name: str) -> str:
    """Why a dataset without ground-truth poses cannot be scored, and what to give instead (at load and in a job)."""
    return (f"icp_pair scores against ground-truth poses and {name} has none: give the dataset its poses (a folder's "
            "`poses` option, a KITTI sequence's poses/NN.txt; a CARMEN log has relations only), or one pair's motion as "
            "the task option ground_truth_file")


class IcpPairOptions(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)
    # strict numbers: YAML's yes/true was taken as 1 (init_noise_m: yes a 1 m noise, pairs [[true, 2]] frames 1 and 2)
    pairs: list[tuple[WholeInt, WholeInt]] | None = None
    ground_truth_file: str | None = None
    max_pairs: WholeInt = Field(1, ge=1)
    # (.inf passed, and the suite was refused at its methods as "values must be plain numbers", naming no option)
    init_noise_m: float = Field(0.0, ge=0.0, allow_inf_nan=False, strict=True)
    init_noise_deg: float = Field(0.0, ge=0.0, allow_inf_nan=False, strict=True)

    @field_validator("pairs")
    @classmethod
    def _no_scan_with_itself(cls, pairs: list[tuple[int, int]] | None) -> list[tuple[int, int]] | None:
        """A scan registered to itself measures nothing about a method (``[[1, 1]]`` was accepted)."""
        same = [list(p) for p in pairs or () if p[0] == p[1]]
        if same:
            raise ValueError(f"{', '.join(map(str, same))} registers a scan with itself: give two different scans")
        return pairs

    @field_validator("max_pairs")
    @classmethod
    def _max_pairs_without_pairs(cls, max_pairs: int, info: ValidationInfo) -> int:
        """``max_pairs`` only counts the default consecutive pairs: beside ``pairs`` it was ignored without a word.
        (A validator of a field: a model-level one has no name for the error to point at.)"""
        if info.data.get("pairs"):
            raise ValueError("only applies without 'pairs' (the first max_pairs consecutive pairs): give one of them")
        return max_pairs


def read_T_target_source(path: Path) -> np.ndarray:
    """A 4x4 (or 3x4) transform from a text file (``#`` comments allowed); DataError if it is not one."""
    from lidarkit.geometry import is_rotation
    from lidarkit.textfile import read_numeric_table

    table = np.asarray(read_numeric_table(path, ncols=4), dtype=np.float64)
    if table.shape == (3, 4):
        table = np.vstack([table, [0.0, 0.0, 0.0, 1.0]])
    if table.shape != (4, 4) or not np.allclose(table[3], [0, 0, 0, 1]) or not is_rotation(table[:3, :3], tol=1e-6):
        raise DataError(f"expected a 4x4 rigid transform, found a {table.shape[0]}x4 table that is not one", source=path)
    return table


def ground_truth_path(dataset: dict[str, Any], options: IcpPairOptions) -> Path:
    """``options.ground_truth_file``, relative to the dataset folder, the folder holding it for a dataset that is one file
    (a bag: ``run.bag/T.txt`` was looked for); a task option: the suite resolves reader path options beside the suite
    file too, task options it does not."""
    folder = dataset_path(dataset)
    if folder.is_file():
        folder = folder.parent
    return folder / Path(options.ground_truth_file).expanduser()


def pairs_truth(dataset: Any, method: str) -> Any:
    """The dataset's ground truth at the instant a pairwise alignment of its sweeps refers to, by the rule odometry
    scores with (:mod:`lidarkit.odometry.instants`: ``align`` deskews nothing, so over sweeps measured while moving
    the pose lands about mid-sweep): re-timed where the dataset can (a simulated street pair scored against sweep-end
    truth read 0.031 m for small_gicp where mid gives 0.004; so did the simulator's KITTI-layout export), else None:
    the dataset's own, as it gives it (a note logged when its instant is another)."""
    from lidarkit.odometry.instants import estimate_instant, like_with_like

    gt = dataset.ground_truth
    if gt is None or len(dataset) == 0:
        return None
    truth, note = like_with_like(gt, estimate_instant(None, dataset.read_scan(0)), sequence=dataset, own_ground_truth=True,
                                 method=method, deskewed=False)
    if truth is gt:
        if note:
            log.warning("%s", note)
        return None
    return truth


def read_as_method(dataset: Any, registration: Any, method: str) -> Any:
    """The dataset reading its points as ``method`` does, as an odometry run configures it (KITTI's vertical-angle
    correction for kiss: scored on the stored points, kiss read 0.0085 m on KITTI 00 198 -> 199 where kiss-icp gives
    0.0132 m); a copy, for the opened dataset is cached and shared by the other methods' jobs."""
    if not callable(getattr(dataset, "configure_for_method", None)):
        return dataset
    import copy

    configured = copy.copy(dataset)
    configured.configure_for_method(getattr(registration, "reads_data_as", None) or getattr(registration, "name", None) or method)
    return configured


def _pair_data(dataset: Any, target: int, source: int, T_gt_file: np.ndarray | None = None,
               truth: Any = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(source_xyz, target_xyz, T_target_source ground truth) of one pair; ``truth``: the dataset's ground truth to use
    (:func:`pairs_truth`; default its own). KITTI's pairs are frame numbers, with a ground-truth file too (they were
    read as scan indices there: [[94, 95]] refused on a folder of frames 94, 95, 198, 199)."""
    by_frame = hasattr(dataset, "relative_pose") and hasattr(dataset, "read_scan_by_frame")  # KITTI: frame numbers
    if T_gt_file is not None:
        read = dataset.read_scan_by_frame if by_frame else dataset.read_scan
        return read(source).points_xyz, read(target).points_xyz, T_gt_file
    if by_frame:
        if truth is None:
            T_gt = np.asarray(dataset.relative_pose(target, source), dtype=np.float64)
        else:  # (its rows follow the folder's frames)
            from lidarkit.geometry import se3_inverse

            row = {int(f): k for k, f in enumerate(dataset.frames)}
            T_gt = se3_inverse(truth.poses_se3[row[target]]) @ truth.poses_se3[row[source]]
        return dataset.read_scan_by_frame(source).points_xyz, dataset.read_scan_by_frame(target).points_xyz, T_gt
    gt = dataset.ground_truth if truth is None else truth
    name = getattr(dataset, "name", "dataset")
    if gt is None:
        raise DataError(no_poses_reason(name), source=name)
    n = len(dataset)
    for idx in (target, source):
        if not 0 <= idx < n:
            raise DataError(f"scan index {idx} out of range (0..{n - 1})", source=name)
    from lidarkit.geometry import se3_inverse

    T_gt = se3_inverse(gt.poses_se3[target]) @ gt.poses_se3[source]
    return dataset.read_scan(source).points_xyz, dataset.read_scan(target).points_xyz, T_gt


def _pairs(options: IcpPairOptions, dataset: Any) -> list[tuple[int, int]]:
    """``pairs`` as given, else the first ``max_pairs`` scans followed by the next frame number (frame numbers for KITTI,
    else scan indices): the next file across a gap was paired (KITTI frames 94, 95, 198, 199 scored 95 -> 198, 103
    frames apart, without a word). Fewer than asked is a warning in the job's record."""
    if options.pairs:
        return [tuple(p) for p in options.pairs]
    frames = [int(f) for f in getattr(dataset, "frames", range(len(dataset)))]  # (folders, sims: 0..N-1)
    by_frame = hasattr(dataset, "read_scan_by_frame")
    pairs = [(frames[k], frames[k + 1]) if by_frame else (k, k + 1)
             for k in range(len(frames) - 1) if frames[k + 1] == frames[k] + 1][:options.max_pairs]
    if len(pairs) < options.max_pairs:
        log.warning("%s: max_pairs %d, but it has %d pair(s) of consecutive frames (frames %s)",
                    getattr(dataset, "name", "dataset"), options.max_pairs, len(pairs), index_runs(frames))
    return pairs


def check_pairs(options: IcpPairOptions, spec: dict[str, Any]) -> None:
    """Pairs naming a scan the dataset lacks are a ConfigError with the suite (each job failed "no scan for frame 95",
    exit 0); checked for the datasets whose length is known at suite load (:func:`scan_count_at_load`: those opened
    then, and simulated drives by their ``n_frames``; KITTI: frame numbers, else scan indices)."""
    n_scans = scan_count_at_load(spec)
    if n_scans is None:
        return
    if not options.pairs:  # the default consecutive pairs: none in a one-scan dataset (each job failed, exit 0)
        if n_scans < 2:
            raise ConfigError(f"the dataset has {n_scans} scan(s): no pair of scans to register", source="options")
        return
    dataset = open_dataset_spec(spec) if spec["kind"] in OPENED_AT_LOAD else None
    if hasattr(dataset, "read_scan_by_frame"):
        frames = [int(f) for f in dataset.frames]
        missing = sorted({i for pair in options.pairs for i in pair} - set(frames))
        have = f"frames {frames[0]}..{frames[-1]}" if frames else "no scans"
        what = "frames"
    else:
        missing = sorted({i for pair in options.pairs for i in pair if not 0 <= i < n_scans})
        have = f"scan indices 0..{n_scans - 1}"
        what = "scan indices"
    if missing:
        raise ConfigError(f"pairs name {what} the dataset lacks: {', '.join(map(str, missing))} (it has {have})", source="options")


class IcpPairTask(Task):
    description = "pairwise ICP on scan pairs with ground truth (final error, iterations, runtime, RMSE history)"

    @property
    def dataset_kinds(self) -> tuple[str, ...]:  # type: ignore[override]
        """Every kind that gives scans (:func:`scan_kinds`), as odometry: a pair is read with ``read_scan``."""
        return scan_kinds()

    metrics = (
        Metric("translation_error_m", "trans. error [m]"),
        Metric("rotation_error_deg", "rot. error [deg]"),
        # (diagnostic: a wider correspondence distance raises the RMSE, one more iteration is no worse alignment; a
        # baseline pinned both and read either as a regression while the pose errors stayed in band)
        Metric("iterations", "iterations", kind="diagnostic"),
        Metric("converged_fraction", "converged", better="higher"),
        Metric("final_rmse_m", "final RMSE [m]", kind="diagnostic"),
        Metric("align_time_s", "align time [s]", kind="speed"),
        Metric("hz", "pairs/s", kind="speed", better="higher"),
    )

    def require(self) -> None:
        import_module_for_task("icp_pair", "lidarkit.registration")

    def available_methods(self) -> list[str] | None:
        from lidarkit.registration import available_icp

        return available_icp()

    def optional_methods(self) -> tuple[str, ...]:
        from lidarkit.registration.registry import OPTIONAL_VARIANTS

        return tuple(OPTIONAL_VARIANTS)

    def validate_options(self, options: dict[str, Any]) -> None:
        opts = options_model(IcpPairOptions, options, "icp_pair")
        if opts.ground_truth_file is not None and (not opts.pairs or len(opts.pairs) != 1):
            raise ConfigError("ground_truth_file gives one pair's motion: set exactly one pair in 'pairs'", source="options")

    def resolved_options(self, options: dict[str, Any]) -> dict[str, Any]:
        """The options with their defaults (``max_pairs``, ``init_noise_m``, ``init_noise_deg``) written out."""
        self.validate_options(options)
        return IcpPairOptions(**options).model_dump(mode="json")

    def option_files(self, dataset: dict[str, Any], options: dict[str, Any]) -> list[Path]:
        """The ``ground_truth_file`` the job scores against, resolved as its run resolves it."""
        opts = options_model(IcpPairOptions, options, "icp_pair")
        return [] if opts.ground_truth_file is None else [ground_truth_path(dataset, opts)]

    def validate_dataset(self, dataset: dict[str, Any], options: dict[str, Any]) -> None:
        check_reader_options(dataset)
        opts = IcpPairOptions(**options)
        if opts.ground_truth_file is not None:
            path = ground_truth_path(dataset, opts)
            # an error of the option, not of the dataset: it blamed experiments[0].dataset, and under the demo's
            # skip_unavailable a DataError on a bundled sample read "bundled sample ... is not installed" (exit 0)
            if not path.is_file():
                raise ConfigError(f"ground_truth_file {path}: file not found (a relative path is looked up in the dataset "
                                  "folder, not beside the suite file: give an absolute path for a file elsewhere)", source="options")
            try:
                read_T_target_source(path)
            except DataError as err:
                raise ConfigError(f"ground_truth_file {err}", source="options") from None
        elif dataset["kind"] in KINDS_WITHOUT_POSES:
            raise ConfigError(no_poses_reason(dataset_label(dataset)), source="dataset")
        elif dataset["kind"] in OPENED_AT_LOAD:  # (opened anyway: a dataset without poses failed every job, exit 0)
            opened = open_dataset_spec(dataset)
            if len(opened) and opened.ground_truth is None:
                raise ConfigError(no_poses_reason(getattr(opened, "name", "the dataset")), source="dataset")
        check_pairs(opts, dataset)

    def validate(self, method: str, params: dict[str, Any], dataset: dict[str, Any], options: dict[str, Any]) -> None:
        from lidarkit.registration import get_icp

        get_icp(method, **params)

    def run(self, job: Job) -> TaskOutput:
        from lidarkit.geometry import pose_error, se3_exp
        from lidarkit.registration import get_icp

        options = options_model(IcpPairOptions, job.options, "icp_pair")  # (a pinned spec re-run: one line, not pydantic's dump)
        registration = get_icp(job.method, **job.params)
        # a simulated dataset without its own seed is seeded by the job's, as for odometry (the docs' "seeds: 10
        # simulates ten different drives"; each seed drew the same pair, and compare counted one value many times)
        dataset = read_as_method(open_dataset_spec(seeded_dataset(job)), registration, job.method)
        rng = np.random.default_rng(job.seed)
        T_gt_file = None
        if options.ground_truth_file is not None:
            T_gt_file = read_T_target_source(ground_truth_path(job.dataset, options))
        from lidarkit.odometry.settings import deskew_requested

        if deskew_requested(registration):  # (kiss and kiss deskew=false gave bit-identical rows, without a word)
            log.warning("%s: deskew has no effect on a pair (align takes no per-point times): the sweeps are registered "
                        "as they are", job.method)
        truth = None if T_gt_file is not None else pairs_truth(dataset, job.method)
        rows, histories = [], []
        from lidarkit.registration.assessment import FINAL_RMSE_ONLY_KEY

        for target, source in _pairs(options, dataset):
            source_xyz, target_xyz, T_gt = _pair_data(dataset, target, source, T_gt_file, truth)
            init_T = None
            if options.init_noise_m > 0 or options.init_noise_deg > 0:
                twist = np.concatenate([rng.normal(0, options.init_noise_m, 3), np.deg2rad(rng.normal(0, options.init_noise_deg, 3))])
                init_T = T_gt @ se3_exp(twist)
            result = registration.align(source_xyz, target_xyz, init_T=init_T)
            trans_m, rot_deg = pose_error(np.asarray(result.T_target_source), T_gt)
            rows.append({
                "target": int(target), "source": int(source),
                "translation_error_m": float(trans_m), "rotation_error_deg": float(rot_deg),
                # (kiss, genz, Open3D's legacy loop report no count: not a measured 0)
                "iterations": int(result.iterations) if result.extra.get("iterations_reported", True) else None,
                "converged": bool(result.converged),
                "final_rmse_m": float(result.rmse), "runtime_s": float(result.runtime_s),
                "n_correspondences": int(result.n_correspondences),
                "degenerate": bool(getattr(result.degeneracy, "degenerate", False)), "reason": result.reason,
                FINAL_RMSE_ONLY_KEY: bool(result.extra.get(FINAL_RMSE_ONLY_KEY, False)),  # (no curve to draw)
            })
            histories.append([float(x) for x in result.rmse_history])
        if not rows:
            raise DataError("no scan pair to register", source=job.dataset_name)
        align_s = float(np.mean([r["runtime_s"] for r in rows]))
        metrics = {
            "translation_error_m": float(np.mean([r["translation_error_m"] for r in rows])),
            "rotation_error_deg": float(np.mean([r["rotation_error_deg"] for r in rows])),
            "iterations": float(np.mean([r["iterations"] for r in rows])) if all(r["iterations"] is not None for r in rows) else float("nan"),
            "converged_fraction": float(np.mean([r["converged"] for r in rows])),
            "final_rmse_m": float(np.mean([r["final_rmse_m"] for r in rows])),
            "align_time_s": align_s,
            "hz": 1.0 / align_s if align_s > 0 else float("nan"),
        }
        config = registration.config.model_dump(mode="json") if hasattr(registration.config, "model_dump") else {}
        from lidarkit.odometry.settings import corrections, reader_settings

        reader = reader_settings(dataset)  # (recorded as an odometry run records it: its "effective" reader settings)
        return TaskOutput(metrics=metrics, series={"rmse_history": histories},
                          info={"pairs": rows, "method_config": config,
                                "effective": {"reader": reader, "corrections": corrections(reader)}})
