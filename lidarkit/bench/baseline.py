"""Golden baselines: a suite's results pinned under a protocol manifest, and a check that re-runs and compares.

``record(suite, out)`` runs every job ``repeats`` times (in this process, one after the other), keeps the
first run's trajectory and metrics, and measures the run-to-run spread (kiss-icp is not bit-reproducible
across thread schedules) to set each metric's band. The manifest pins what makes a number reproducible:
library versions, the method's resolved config, the task options with their defaults, checksums of the dataset files
(of a KITTI sequence, those the job's task reads) and of the files the task options name (a simulated dataset: its
whole simulator config), the KITTI angle correction and deskew as the run applied them, the instant poses refer to, the frame-check thresholds (``n_bad_frames`` counts
under them), the evaluation settings and the platform.

``check(folder)`` re-runs the pinned jobs. A job whose protocol differs reports ``protocol changed: ...``
(its numbers are not comparable, whatever they are); a rerun that scored another number of frames is ``failed: ...``
naming both counts; otherwise a metric outside its band on the worse side
is ``regression: ...``; outside on the better side ``improved: ...`` (passes; re-record to tighten). A job with no
accuracy metric (data without ground truth) is held on its trajectory: one differing from the pinned one by more than
the band its repeats set is ``regression: ...``. A job that raises is ``failed: ...`` with its error, and the other jobs
are still checked.

Layout: ``DIR/manifest.json``, ``DIR/suite.yaml`` (the suite as recorded, its relative dataset paths made absolute so
that it records again from there), ``DIR/jobs/<key>/metrics.json``
and, for odometry jobs, ``DIR/jobs/<key>/poses_kitti.txt``.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import logging
import math
import os
import platform
import shutil
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from lidarkit import atomic
from lidarkit.bench.jobs import Job, canonical_json
from lidarkit.bench.tasks import higher_is_better
from lidarkit.errors import ConfigError, DataError, LidarKitError, OutputError, RegistrationError
from lidarkit.eval.statistics import RELATIVE_TIE_TOLERANCE, tie_tolerance
from lidarkit.params import is_integer
from lidarkit.run_files import BASELINE_MANIFEST

log = logging.getLogger(__name__)

SCHEMA = "lidarkit-baseline/1"
MANIFEST = BASELINE_MANIFEST
#: packages whose version is part of the protocol (lidarkit itself is what a check tests: noted, not a change); OpenCV
#: is pinned apart, as ``opencv`` (see OPENCV_DISTRIBUTIONS)
PROTOCOL_PACKAGES = ("kiss-icp", "open3d", "numpy", "scipy", "evo", "small_gicp")
#: the distributions that install ``cv2`` (VO jobs, the camera simulator and image decoding run on it): the one that
#: wrote the ``cv2`` folder gives the ``opencv`` version, whatever its name
OPENCV_DISTRIBUTIONS = ("opencv-python", "opencv-python-headless", "opencv-contrib-python", "opencv-contrib-python-headless")
#: packages only some jobs run on: another version voids those jobs only (see :func:`uses_package`); the others'
#: changes void every job
SCOPED_PACKAGES = ("opencv", "small_gicp")
#: band = max(NOISE_FACTOR * run-to-run std, ABSOLUTE_FLOOR[metric], RELATIVE_FLOOR * |value|)
NOISE_FACTOR = 4.0
RELATIVE_FLOOR = 0.02
ABSOLUTE_FLOOR = {
    "drift_translation_pct": 0.05,  # re-runs of one method on KITTI differ by 0.05-0.1 pp across setups
    "drift_rotation_deg_per_100m": 0.005,
    "ape_rmse_m": 0.01,
    "ape_se3_rmse_m": 0.01,
    "final_error_m": 0.01,
    "rpe_trans_rmse_m": 0.001,
    "rpe_rot_rmse_deg": 0.001,
}
DEFAULT_FLOOR = 1e-9
#: floors of tasks whose numbers lie on another scale than LiDAR odometry's (metric -> floor; a task not listed takes
#: ABSOLUTE_FLOOR): vo on a simulated camera reaches 1 mm APE, and 1 cm let 8x worse pass; its band is its noise and 2 %.
TASK_FLOOR: dict[str, dict[str, float]] = {"vo": {}}
#: a job with no accuracy metric (data without ground truth: its check held n_bad_frames only) is held on its trajectory:
#: position band = max(NOISE_FACTOR * the repeats' largest difference, TRAJECTORY_RELATIVE_FLOOR * path length,
#: TRAJECTORY_FLOOR_M); rotation band = max(NOISE_FACTOR * theirs, TRAJECTORY_FLOOR_DEG). kiss's threads sum in another
#: order from run to run and its poses differ in the last bits (1e-15 m over 8-10 scans); a changed method (one ICP
#: iteration, another voxel size) moves them by millimetres to decimetres: the floors lie far from both.
TRAJECTORY_RELATIVE_FLOOR = 1e-6
TRAJECTORY_FLOOR_M = 1e-6
TRAJECTORY_FLOOR_DEG = 1e-4


def _utc() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")


def environment() -> dict[str, Any]:
    """Versions of lidarkit and the protocol packages, and the platform."""
    from importlib.metadata import PackageNotFoundError, version

    from lidarkit.provenance import code_version

    packages = {}
    for name in PROTOCOL_PACKAGES:
        try:
            packages[name] = version(name)
        except PackageNotFoundError:
            packages[name] = None
    packages["opencv"] = opencv_version()
    return {
        "lidarkit": code_version(),
        "packages": packages,
        "platform": {"system": platform.system(), "machine": platform.machine()},
        "python": platform.python_version(),
    }


def opencv_version() -> str | None:
    """The version of the distribution that wrote the ``cv2`` folder (``4.10.0.84``), read from its ``cv2/version.py``
    without importing OpenCV (one distribution or several installed over each other: the last one's, as it is the
    ``cv2`` that runs; the version of the one distribution installed or ``cv2.__version__`` were pinned by turns, and a
    second distribution read as another OpenCV); ``cv2.__version__`` for a build without that file (from source); None
    without OpenCV."""
    import importlib.util
    import re

    try:
        found = importlib.util.find_spec("cv2")
    except (ImportError, ValueError):
        found = None
    if found is None:
        return None
    folders = list(found.submodule_search_locations or [])
    for folder in folders:
        try:
            text = (Path(folder) / "version.py").read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError):
            continue
        written = re.search(r"""^opencv_version\s*=\s*["']([^"']+)["']""", text, flags=re.MULTILINE)
        if written:
            return written[1]
    try:
        import cv2
    except ImportError:
        return None
    return str(cv2.__version__)


def same_opencv(pinned: Any, now: Any) -> bool:
    """Whether two pinned ``opencv`` versions name one OpenCV: equal, or one the other with its build number
    (``4.10.0`` and ``4.10.0.84``: a baseline recorded when lidarkit read ``cv2.__version__`` with several
    distributions installed)."""
    if pinned == now:
        return True
    if not (isinstance(pinned, str) and isinstance(now, str)):
        return False
    return pinned.startswith(now + ".") or now.startswith(pinned + ".")


def uses_package(package: str, spec: Mapping[str, Any]) -> bool:
    """Whether the job of ``spec`` (``Job.spec()``) runs on ``package`` of :data:`SCOPED_PACKAGES`: OpenCV, a ``vo`` job
    or one on the camera simulator; small_gicp, a ``small_gicp`` method (a variant derived from it too). Another
    version of either voided every job (kiss on a simulated LiDAR: "protocol changed", FAILED, nothing run)."""
    if package == "opencv":
        dataset = spec.get("dataset") if isinstance(spec.get("dataset"), Mapping) else {}
        return spec.get("task") == "vo" or dataset.get("kind") == "sim_camera"
    if package == "small_gicp":
        method = spec.get("method")
        if method == "small_gicp":
            return True
        if spec.get("task") not in ("odometry", "icp_pair"):
            return False
        try:
            from lidarkit.registration import get_icp_class

            return any(vars(k).get("name") == "small_gicp" for k in get_icp_class(str(method)).__mro__)
        except Exception:  # noqa: BLE001 - a method not known here: its run says so
            return False
    return True


def evaluation_settings() -> dict[str, Any]:
    """How the odometry metrics are computed (what ``lidarkit.odometry.odometry_metrics`` does)."""
    from lidarkit.eval.kitti_drift import KITTI_LENGTHS_M, KITTI_STEP_FRAMES

    return {"kitti_segment_lengths_m": list(KITTI_LENGTHS_M), "kitti_step_frames": KITTI_STEP_FRAMES,
            "ape_alignment": "none", "rpe_delta": "1 frame", "frame_pairing": "by index"}


#: counts of the independent per-frame check (lidarkit.odometry.frame_check): comparable under the same thresholds only
FRAME_CHECK_METRICS = ("n_bad_frames", "n_bad_motion", "n_bad_fitness", "n_motion_checked", "n_fitness_checked",
                       "n_said_converged_but_bad")


def frame_check_thresholds(described: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The frame-check thresholds a run recorded (``config["run"]["frame_check"]``, its rules in words left out), or
    today's defaults (what a bench job runs under) when None."""
    if described is None:
        from dataclasses import asdict

        from lidarkit.odometry.frame_check import FrameCheckConfig

        return asdict(FrameCheckConfig())
    return {k: v for k, v in described.items() if not k.endswith("_rule")}


# ---------------------------------------------------------------- protocol of one job


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


def dataset_files(spec: Mapping[str, Any], task: str | None = None) -> list[Path]:
    """The files a dataset spec reads: every file under its path (a bag or MCAP file: itself; a ROS 2 bag, given as its
    folder or its ``metadata.yaml``: its folder's files), or under ``sequences/NN`` of a KITTI root given with
    ``sequence: NN`` (not the other sequences); a KITTI sequence also its ``poses/NN.txt``; a CARMEN log the
    ``.relations`` file found beside it; and the files of options that name an existing path (a ``poses`` file kept
    elsewhere). A KITTI-layout sequence read by ``task`` odometry, icp_pair or vo: only what that task's reader reads
    (:func:`kitti_reads`). DataError when the path does not exist."""
    from lidarkit.bench.datasets import PATHLESS_KINDS, dataset_options

    if spec.get("kind") in PATHLESS_KINDS:
        return []
    reads = kitti_reads(spec, task)
    if reads is not None:
        files: dict[Path, None] = {}  # (a poses file named twice, as the one in use and a simulator's: hashed once)
        for path in reads[0]:
            if path.exists():
                files.update(dict.fromkeys(_files_under(path)))
        return list(files)
    root = dataset_folder(spec)
    files = _files_under(root)
    if root.is_dir() and root.parent.name == "sequences":
        poses = root.parent.parent / "poses" / f"{root.name}.txt"
        if poses.is_file():
            files.append(poses)
    companion = _companion_file(spec, root)
    if companion is not None and companion not in files:
        files.append(companion)
    seen = set(files)
    for value in dataset_options(dict(spec)).values():
        if isinstance(value, str) and os.path.isabs(value) and Path(value).exists():
            extra = [f for f in _files_under(Path(value)) if f not in seen]
            files += extra
            seen.update(extra)
    return files


#: KITTI-layout kinds whose files a job hashes as its task reads them (:func:`kitti_reads`)
KITTI_LAYOUT_KINDS = ("kitti", "kiss_kitti")
#: tasks that read a KITTI sequence's scans, and those that read its images
SCAN_TASKS = ("odometry", "icp_pair")
IMAGE_TASKS = ("vo",)


def kitti_reads(spec: Mapping[str, Any], task: str | None) -> tuple[list[Path], list[Path]] | None:
    """What a job of ``task`` reads of a KITTI-layout sequence: (the folders and files it reads, hashed; the paths it
    would read were they there, a point-time folder or a poses file, which a pinned file under them is still compared
    on). Scans (odometry, icp_pair): ``velodyne/``, the point-time folder found, ``times.txt``, ``calib.txt``, the poses
    file in use (and a simulator folder's ``sim.yaml`` and ``poses_<instant>.txt``); images (vo): the image folder in its
    place. None for another kind or task: its whole folder is hashed (every image of a sequence was hashed for a LiDAR
    job, GBs on a full KITTI sequence, and a camera folder added later read as changed data)."""
    if spec.get("kind") not in KITTI_LAYOUT_KINDS or task not in SCAN_TASKS + IMAGE_TASKS:
        return None
    folder = Path(os.path.abspath(dataset_folder(spec)))
    if not folder.is_dir():
        return None
    in_sequences = folder.parent.name == "sequences"
    if spec.get("kind") == "kiss_kitti":  # (kiss-icp's loader: scans, calib, times and poses/NN.txt of the root)
        reads = [folder / "velodyne", folder / "calib.txt", folder / "times.txt"]
        return reads + ([folder.parent.parent / "poses" / f"{folder.name}.txt"] if in_sequences else []), []
    from lidarkit.bench.tasks._datasets import open_dataset_spec
    from lidarkit.io.base import INSTANT_FRACTION
    from lidarkit.io.kitti import POINT_TIME_FOLDERS

    reader = open_dataset_spec(dict(spec))
    sequence = Path(os.path.abspath(reader.sequence_dir))
    absolute = (lambda path: Path(os.path.abspath(path)))
    reads = [absolute(reader.calib_path), absolute(reader.times_path), sequence / "sim.yaml",
             *(sequence / f"poses_{instant}.txt" for instant in INSTANT_FRACTION)]
    if reader.poses_path is not None:
        reads.append(absolute(reader.poses_path))
    could = []
    if spec.get("poses_file") is None:  # (where the reader looks for poses: one added or removed since is compared)
        could += [sequence / "poses.txt"] + ([sequence.parent.parent / "poses" / f"{reader.sequence}.txt"] if
                                             sequence.parent.name == "sequences" else [])
    if task in IMAGE_TASKS:
        reads.append(absolute(reader.image_dir))
    else:
        reads.append(absolute(reader.velodyne_dir))
        if reader.point_times_dir is not None:
            reads.append(absolute(reader.point_times_dir))
        could += [absolute(where) / name for where in reader.point_time_search_dirs for name in POINT_TIME_FOLDERS]
    return reads, could


def _whole_folder_covers(spec: Mapping[str, Any], path: Path) -> bool:
    """Whether the whole-folder rule of :func:`dataset_files` (baselines recorded before :func:`kitti_reads`) hashed
    ``path``: under the dataset's folder, its ``poses/NN.txt``, or under an absolute path an option names."""
    from lidarkit.bench.datasets import dataset_options

    folder = Path(os.path.abspath(dataset_folder(spec)))
    covered = [folder] + ([folder.parent.parent / "poses" / f"{folder.name}.txt"] if folder.parent.name == "sequences" else [])
    covered += [Path(os.path.abspath(v)) for v in dataset_options(dict(spec)).values() if isinstance(v, str) and os.path.isabs(v)]
    return any(path == c or path.is_relative_to(c) for c in covered)


def _companion_file(spec: Mapping[str, Any], root: Path) -> Path | None:
    """A file beside the dataset's path that its reader reads unasked: a CARMEN log's ``NAME.relations`` under
    ``relations: auto`` (left unhashed, an edited one read as a regression of the method, a deleted one as its metric
    missing)."""
    if spec.get("kind") != "carmen" or spec.get("relations", "auto") != "auto":
        return None
    from lidarkit.io.carmen import relations_beside

    return relations_beside(root)


#: kinds whose reader opens a ROS 2 bag given as its ``metadata.yaml`` as the bag's folder
BAG_KINDS = ("rosbag", "mcap")


def _read_path(spec: Mapping[str, Any]) -> Path:
    """The path a dataset spec's reader opens: its path, a ROS 2 bag's ``metadata.yaml`` being its folder (hashed as
    that one file, changed scans read as a regression of the method)."""
    from lidarkit.bench.datasets import dataset_path
    from lidarkit.io.rosbag import bag_path

    path = Path(dataset_path(dict(spec)))
    return bag_path(path) if spec.get("kind") in BAG_KINDS else path


def dataset_folder(spec: Mapping[str, Any]) -> Path:
    """The folder (or file) a dataset spec reads: its path (a ROS 2 bag's ``metadata.yaml``: the bag's folder), or for a
    root given with ``sequence:`` the sequence folder the reader itself resolves (``sequence: 0`` is ``sequences/00``:
    ``str(0)`` hashed the whole root). DataError when the path does not exist."""
    from lidarkit.bench.tasks._datasets import open_dataset_spec

    root = _read_path(spec)
    if not root.exists():
        raise DataError("dataset path does not exist (a baseline pins the paths it was recorded with: put the data back "
                        "there or record again)", source=root)
    if spec.get("sequence") is None:
        return root
    folder = getattr(open_dataset_spec(dict(spec)), "sequence_dir", None)
    if folder is None and spec.get("kind") == "kiss_kitti":  # kiss-icp's loader of the same layout (the whole root was hashed)
        folder = root / "sequences" / f"{int(spec['sequence']):02d}"
    return root if folder is None else Path(folder)


def _files_under(path: Path) -> list[Path]:
    """Every file under ``path``, through linked folders too (a sequence whose ``velodyne`` links to the scans kept
    elsewhere: rglob left its scans out, and changed scans read as a regression of the code); a folder met again
    through a loop of links is walked once. A folder below ``path`` holding a baseline's manifest is left out: a
    baseline written inside the data (before record refused that) pinned its own files, and its check always read
    ``protocol changed: data.DATA/baseline/manifest.json: <absent> -> ...``."""
    if path.is_file():
        return [path]
    files, seen = [], set()
    for folder, subfolders, names in os.walk(path, followlinks=True):
        real = os.path.realpath(folder)
        if real in seen or (MANIFEST in names and Path(folder) != path and _is_baseline_manifest(Path(folder) / MANIFEST)):
            subfolders[:] = []
            continue
        seen.add(real)
        subfolders.sort()
        files += [Path(folder) / name for name in names if (Path(folder) / name).is_file()]
    return sorted(files)


def dataset_checksums(spec: Mapping[str, Any], cache: dict[str, str] | None = None, task: str | None = None) -> dict[str, str]:
    """``{relative file: sha256}`` of a dataset spec's files (those ``task`` reads: :func:`dataset_files`); a generated
    dataset gives its config's hash."""
    from lidarkit.bench.datasets import PATHLESS_KINDS

    if spec.get("kind") in PATHLESS_KINDS:
        return {"<generated>": hashlib.sha256(canonical_json(dict(spec)).encode()).hexdigest()}
    return _checksums(dataset_files(spec, task), _checksum_base(spec), cache)


def _pinned_file(spec: Mapping[str, Any], key: str) -> Path:
    """The file a checksum key names (relative to :func:`_checksum_base`, or absolute)."""
    return Path(key) if os.path.isabs(key) else Path(os.path.abspath(_checksum_base(spec))) / key


def _files_read_apart(job: Job, pinned: dict[str, str], now: dict[str, str], name: str
                      ) -> tuple[dict[str, str], dict[str, str], list[Finding]]:
    """``pinned`` and ``now`` checksums cut to the files both rules of :func:`dataset_files` cover, for a KITTI-layout job
    whose task's reads are known (:func:`kitti_reads`): a baseline recorded when the whole sequence folder was hashed
    pinned camera images a LiDAR job never reads (not compared, said in a note), and none of a poses file kept outside
    the folder (not compared either). Other jobs: unchanged, no note."""
    reads = kitti_reads(job.dataset, job.task)
    if reads is None:
        return pinned, now, []
    from lidarkit.bench.tasks import get_task

    try:  # (a ground truth an icp_pair option names inside the folder: pinned with the folder's files before)
        option_files = list(get_task(job.task).option_files(dict(job.dataset), dict(job.options)))
    except LidarKitError:
        option_files = []
    covered = [Path(os.path.abspath(p)) for p in reads[0] + reads[1] + option_files]
    read_now = (lambda key: any((path := _pinned_file(job.dataset, key)) == c or path.is_relative_to(c) for c in covered))
    left_out = sorted(k for k in pinned if not read_now(k))
    unpinned = [k for k in now if k not in pinned and not _whole_folder_covers(job.dataset, _pinned_file(job.dataset, k))]
    notes = []
    if left_out:
        shown = ", ".join(left_out[:3]) + (f" and {len(left_out) - 3} more" if len(left_out) > 3 else "")
        files = "file" if len(left_out) == 1 else "files"
        notes.append(Finding("note", name, f"the baseline pinned {len(left_out)} {files} its {job.task} job does not read "
                                           f"({shown}; recorded when lidarkit hashed the whole sequence folder): not compared"))
    if unpinned:
        notes.append(Finding("note", name, f"the baseline pinned no checksum of {', '.join(unpinned)} (recorded before "
                                           "lidarkit hashed the files the job reads outside its folder): not compared; "
                                           "record it again to pin them"))
    return ({k: v for k, v in pinned.items() if k not in left_out}, {k: v for k, v in now.items() if k not in unpinned},
            notes)


def option_checksums(job: Job, cache: dict[str, str] | None = None) -> dict[str, str]:
    """``{file: sha256}`` of the files the job's task options make it read (:meth:`lidarkit.bench.tasks.Task.option_files`:
    an icp_pair ``ground_truth_file``), named as the dataset's files are; one missing now is left out (it reads as
    ``<absent>``). An edited ground truth kept outside the dataset folder read as a regression of the method."""
    from lidarkit.bench.datasets import PATHLESS_KINDS
    from lidarkit.bench.tasks import get_task

    files = [Path(os.path.abspath(f)) for f in get_task(job.task).option_files(dict(job.dataset), dict(job.options))]
    base = None if job.dataset.get("kind") in PATHLESS_KINDS else Path(os.path.abspath(_checksum_base(job.dataset)))
    return _checksums([f for f in files if f.is_file()], base, cache)


def _checksum_base(spec: Mapping[str, Any]) -> Path:
    """The folder a dataset's checksums are named from: the parent of the path its reader opens (a KITTI sequence: its
    root; a ROS 2 bag given as its ``metadata.yaml``: the bag folder's parent, as the folder given itself)."""
    root = _read_path(spec)
    return root.parent.parent if root.parent.name == "sequences" else root.parent


def _checksums(files: list[Path], base: Path | None, cache: dict[str, str] | None) -> dict[str, str]:
    out = {}
    for path in files:
        key = str(path)
        if cache is not None and key in cache:
            digest = cache[key]
        else:
            digest = _sha256(path)
            if cache is not None:
                cache[key] = digest
        out[str(path.relative_to(base)) if base is not None and path.is_relative_to(base) else str(path)] = digest
    return out


def simulation_config(job: Job) -> dict[str, Any]:
    """The whole simulator configuration a ``sim_lidar`` job runs on: its spec's settings, today's defaults for the
    rest, its seed (as a run records it in ``config["run"]["dataset_config"]``)."""
    from lidarkit.bench.datasets import dataset_options
    from lidarkit.bench.tasks._datasets import seeded_dataset
    from lidarkit.odometry import config_dict
    from lidarkit.sim.lidar import make_config

    return _jsonable(config_dict(make_config(**dataset_options(seeded_dataset(job)))))


def _pose_instant(dataset: Any, result: Any) -> Any:
    gt = getattr(result, "ground_truth", None)
    if gt is not None and isinstance(getattr(gt, "meta", None), dict) and gt.meta.get("pose_instant"):
        return gt.meta["pose_instant"]
    config = getattr(dataset, "config", None)
    return getattr(config, "pose_instant", None)


def _jsonable(value: Any) -> Any:
    from lidarkit.eval.report import json_safe

    return json_safe(value)


@dataclass
class JobRun:
    """One execution of a job: metrics, the estimated trajectory (odometry) and the job's protocol."""

    metrics: dict[str, float]
    trajectory: Any
    protocol: dict[str, Any]


def run_job(job: Job, checksum_cache: dict[str, str] | None = None) -> JobRun:
    """Run ``job`` in this process and collect its protocol (config, data checksums, angle correction, instant).
    A job that fails raises a LidarKitError naming the job (a method's own exception type and message kept in it)."""
    try:
        return _run_job(job, checksum_cache)
    except LidarKitError as err:
        if str(err.source) == str(_job_name(job)):
            raise
        raise type(err)(_reason_within_job(err, job), source=_job_name(job)) from err
    except (KeyboardInterrupt, SystemExit, MemoryError):
        raise
    except Exception as err:  # noqa: BLE001 - a method's or plugin's own failure: one line naming the job
        raise RegistrationError(f"the job failed: {type(err).__name__}: {err}", source=_job_name(job)) from err


def _reason_within_job(err: LidarKitError, job: Job) -> str:
    """``err`` as told after the job's name: its source left out where that name already says it (the dataset's name:
    "kiss on mc (seed 0): mc: frames: ..."); a file or an option it names is kept."""
    if err.source is not None and err.source not in (job.dataset_name, job.method_label, job.experiment):
        return str(err)
    return f"{err.location}: {err.reason}" if err.location else err.reason


def _validate_pinned_options(job: Job) -> None:
    """A pinned job's task options checked as a suite file's are when it loads, before the job re-runs: an option this
    lidarkit no longer knows is one ConfigError naming the valid ones (the task's run printed pydantic's 4-line dump)."""
    from lidarkit.bench.tasks import get_task

    try:
        get_task(job.task).validate_options(dict(job.options))
    except LidarKitError as err:
        raise ConfigError(str(err), source=_job_name(job)) from None
    except Exception as err:  # noqa: BLE001 - a plugin task's validator bug: one line naming the job, as its run's
        raise ConfigError(f"its options could not be checked: {type(err).__name__}: {err}", source=_job_name(job)) from None


def _job_name(job: Job) -> str:
    return f"{job.experiment}: {job.method_label} on {job.dataset_name} (seed {job.seed})"


def _run_job(job: Job, checksum_cache: dict[str, str] | None) -> JobRun:
    from lidarkit.bench.tasks import get_task

    protocol: dict[str, Any] = {"dataset": dict(job.dataset), "checksums": dataset_checksums(job.dataset, checksum_cache, job.task)}
    # the files its options name (a ground truth kept outside the dataset folder), those the dataset's hold apart
    option_files = option_checksums(job, checksum_cache)
    protocol["option_files"] = {k: v for k, v in option_files.items() if k not in protocol["checksums"]}
    # every option with the default it ran under (a later default read as a regression of the method)
    protocol["task_options"] = _jsonable(get_task(job.task).resolved_options(dict(job.options)))
    if job.dataset.get("kind") == "sim_lidar":  # every setting (its checksum hashes the suite's only: a changed default)
        protocol["simulation"] = simulation_config(job)
    elif job.dataset.get("kind") == "sim_camera":  # (the same, for the camera simulator of the vo task)
        from lidarkit.bench.tasks.vo import camera_config

        protocol["simulation"] = _jsonable(camera_config(job).model_dump(mode="json"))
    if job.task == "odometry":
        from lidarkit.bench.tasks._datasets import open_dataset_spec
        from lidarkit.bench.tasks._datasets import seeded_dataset
        from lidarkit.bench.tasks.odometry import run_odometry_job

        result, output = run_odometry_job(job)
        dataset = open_dataset_spec(seeded_dataset(job))
        config = dict(result.config.get("method_config", result.config)) if isinstance(result.config, dict) else {}
        # what the run applied, not what an unconfigured reader or the method's config asks for (kiss on KITTI: the
        # correction "auto" is applied; deskew requested, not applied without per-point times)
        run_config = result.config.get("run") if isinstance(result.config, dict) else None
        effective = (run_config or {}).get("effective") or {}
        protocol.update(
            method_config=_jsonable(config),
            kitti_angle_correction=(effective.get("corrections") or {}).get("vertical_correction_applied"),
            pose_instant=_pose_instant(dataset, result),
            deskew=(effective.get("deskew") or {}).get("applied"),
            # (n_bad_frames under loosened thresholds passed as no regression)
            frame_check=_jsonable(frame_check_thresholds((run_config or {}).get("frame_check"))),
        )
        return JobRun(dict(output.metrics), result.trajectory, protocol)
    output = get_task(job.task).run(job)
    # where each task keeps the resolved config of its method (the pf task: info["run"]["config"])
    run_info = output.info.get("run") if isinstance(output.info.get("run"), dict) else {}
    protocol["method_config"] = _jsonable(output.info.get("method_config") or output.info.get("config") or run_info.get("config") or {})
    corrections = (output.info.get("effective") or {}).get("corrections") or {}
    if corrections.get("vertical_correction_applied"):  # (icp_pair: kiss reads KITTI corrected, pinned as odometry's;
        # absent where no correction applies, so the protocols of other methods and tasks are as they were)
        protocol["kitti_angle_correction"] = True
    return JobRun(dict(output.metrics), None, protocol)


def _band(metric: str, value: float, std: float, task: str) -> float:
    floor = TASK_FLOOR.get(task, ABSOLUTE_FLOOR).get(metric, DEFAULT_FLOOR)
    return float(max(NOISE_FACTOR * std, floor, RELATIVE_FLOOR * abs(value)))


def holds_accuracy(checked: list[str]) -> bool:
    """Whether a job's checked metrics hold its accuracy (not only the counts of the per-frame check: data without
    ground truth)."""
    return bool(set(checked) - set(FRAME_CHECK_METRICS))


def trajectory_difference(actual: Any, pinned: Any) -> tuple[np.ndarray, np.ndarray]:
    """Per pose: position difference (m) and rotation angle between the two (deg) of two trajectories of one length."""
    from lidarkit.geometry import rotation_angle_deg

    A, P = actual.poses_se3, pinned.poses_se3
    d_m = np.linalg.norm(A[:, :3, 3] - P[:, :3, 3], axis=1)
    return d_m, np.asarray(rotation_angle_deg(np.einsum("nji,njk->nik", P[:, :3, :3], A[:, :3, :3])), dtype=np.float64)


def _trajectory_band(trajectories: list[Any], source: str) -> dict[str, Any]:
    """The band a rerun's trajectory is held in (see TRAJECTORY_RELATIVE_FLOOR), from the repeats' largest difference
    to the first run's."""
    first = trajectories[0]
    spread_m = spread_deg = 0.0
    for other in trajectories[1:]:
        if len(other) != len(first):
            raise RegistrationError(f"its repeats gave trajectories of {len(first)} and {len(other)} poses: no band can "
                                    "be set on its trajectory", source=source)
        d_m, d_deg = trajectory_difference(other, first)
        spread_m, spread_deg = max(spread_m, float(d_m.max())), max(spread_deg, float(d_deg.max()))
    length_m = float(np.linalg.norm(np.diff(first.poses_se3[:, :3, 3], axis=0), axis=1).sum())
    return {"position_m": max(NOISE_FACTOR * spread_m, TRAJECTORY_RELATIVE_FLOOR * length_m, TRAJECTORY_FLOOR_M),
            "rotation_deg": max(NOISE_FACTOR * spread_deg, TRAJECTORY_FLOOR_DEG),
            "noise_position_m": spread_m, "noise_rotation_deg": spread_deg, "path_length_m": length_m,
            "rule": f"max({NOISE_FACTOR:g} x the repeats' largest difference, {TRAJECTORY_RELATIVE_FLOOR:g} x path length, "
                    f"{TRAJECTORY_FLOOR_M:g} m; {TRAJECTORY_FLOOR_DEG:g} deg)"}


def checked_metrics(task: str, metrics: Mapping[str, Any]) -> list[str]:
    """The accuracy metrics of ``task`` present in ``metrics`` (speed depends on the machine, a diagnostic metric moves
    with a setting while the accuracy holds: never checked; see :data:`lidarkit.bench.tasks.METRIC_KINDS`)."""
    unchecked = unchecked_metrics(task)
    try:
        from lidarkit.bench.tasks import CHECKED_KINDS, get_task

        declared = [m.name for m in get_task(task).metrics if m.kind in CHECKED_KINDS]
    except LidarKitError:
        declared = []
    names = [m for m in declared if _finite_number(metrics.get(m))]
    return names or sorted(k for k, v in metrics.items() if _finite_number(v) and k not in ("hz", "n_frames", *unchecked))


def unchecked_metrics(task: str) -> dict[str, str]:
    """``{metric: kind}`` of the metrics ``task`` declares of a kind a baseline does not check ({} for a task not known
    here)."""
    try:
        from lidarkit.bench.tasks import CHECKED_KINDS, get_task

        return {m.name: m.kind for m in get_task(task).metrics if m.kind not in CHECKED_KINDS}
    except LidarKitError:
        return {}


def _finite_number(value: Any) -> bool:
    """A metric a band can be set on: a finite number (kiss reports no ``iterations`` in an icp_pair job: NaN, which
    the manifest stored as null and then refused to read)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


# ---------------------------------------------------------------- record


@dataclass
class Baseline:
    """A loaded baseline folder."""

    path: Path
    manifest: dict[str, Any]

    @property
    def jobs(self) -> list[dict[str, Any]]:
        return self.manifest["jobs"]

    def job(self, method: str | None = None, dataset: str | None = None, seed: int | None = None, *,
            experiment: str | None = None, task: str | None = None) -> dict[str, Any]:
        """The one pinned job with this method label (or name), dataset name, seed, experiment and task; DataError if
        none; ConfigError naming the keywords that tell them apart if several (an argument missing: two seeds,
        ``seed=``; two experiments of one method on one dataset, e.g. over other frames, ``experiment=``). A label
        matches as bench writes it, as in ``compare``: ``kiss(deskew=false)`` finds ``kiss(deskew=False)``."""
        # (compare's reading of a label; private to lidarkit.eval.compare, shared here so that the two read labels alike)
        from lidarkit.eval.compare import _as_label

        if seed is not None and not is_integer(seed):  # ("1" matched no job: "0 pinned jobs match ...; pinned: (seed 1)")
            raise ConfigError(f"seed must be an integer, got {seed!r}", source="seed")
        # (written otherwise, "vanilla(voxel_size_m=0.50)" found no "vanilla(voxel_size_m=0.5)")
        labels = {method, _as_label(method)} if isinstance(method, str) else {method}

        def same_label(j: dict[str, Any]) -> bool:
            return bool(labels & {j["label"], _as_label(j["label"])})

        found = [j for j in self.jobs if (method is None or same_label(j) or method == j["spec"]["method"])
                 and (dataset is None or j["spec"]["dataset_name"] == dataset) and (seed is None or j["spec"].get("seed") == seed)
                 and (experiment is None or j["spec"].get("experiment") == experiment)
                 and (task is None or j["spec"].get("task") == task)]
        exact = [j for j in found if method is not None and same_label(j)]
        if exact:  # "vanilla" beside "vanilla(voxel_size_m=0.5)": the label, not every job of the method (as compare)
            found = exact
        asked = ", ".join(f"{k}={v!r}" for k, v in (("method", method), ("dataset", dataset), ("seed", seed),
                                                     ("experiment", experiment), ("task", task)) if v is not None)
        if len(found) > 1:  # an argument missing, not a fault of the baseline
            matching = f"{len(found)} pinned jobs match {asked}" if asked else f"{len(found)} pinned jobs"
            raise ConfigError(f"{matching}: {_pick_hint(found)}", source=self.path)
        if not found:
            labels = ", ".join(job_name(j, self.jobs) for j in self.jobs)
            raise DataError(f"0 pinned jobs match {asked or 'no choice'}; pinned: {labels}", source=self.path)
        return found[0]

    def metrics(self, method: str | None = None, dataset: str | None = None, seed: int | None = None, **pick: str | None
                ) -> dict[str, float]:
        """The pinned job's metrics (``pick``: ``experiment=``, ``task=`` as :meth:`job`)."""
        return dict(self.job(method, dataset, seed, **pick)["metrics"])

    def trajectory(self, method: str | None = None, dataset: str | None = None, seed: int | None = None, **pick: str | None):
        from lidarkit.trajectory import Trajectory

        job = self.job(method, dataset, seed, **pick)
        path = self.path / "jobs" / job["key"] / "poses_kitti.txt"
        if not path.is_file():
            why = ("not an odometry job" if job["spec"].get("task") != "odometry"
                   else "its poses_kitti.txt is missing from the baseline folder: record it again")
            raise DataError(f"this pinned job has no trajectory ({why})", source=path)
        trajectory = Trajectory.from_kitti(path, name=job["label"])
        problem = _damaged_trajectory(trajectory, job)
        if problem:  # (a file cut short was returned as the pinned run, and a test held a result against it)
            raise DataError(problem, source=path)
        return trajectory


def _damaged_trajectory(trajectory: Any, pinned: Mapping[str, Any]) -> str:
    """Why a pinned trajectory does not match its job's pinned frame count (a file cut short), or ''."""
    n_pinned = pinned["metrics"].get("n_frames")
    if _finite_number(n_pinned) and len(trajectory) != n_pinned:
        return (f"its pinned trajectory has {len(trajectory)} poses for the pinned {n_pinned:g} frames (damaged): record the "
                "baseline again")
    from lidarkit.trajectory import READ_WARNINGS

    cut = (getattr(trajectory, "meta", None) or {}).get(READ_WARNINGS)
    if cut:  # (a file cut inside its last number, which lidarkit never writes: it was blamed on the method, 2.8 m off)
        return f"its pinned trajectory is damaged ({cut[0]}): record the baseline again"
    return ""


def _pick_hint(found: list[dict[str, Any]]) -> str:
    """The keywords of :meth:`Baseline.job` that tell the ``found`` jobs apart, with their values: "pick one with
    method= (kiss, small_gicp)", "... and seed= (0, 1)"; "... or experiment= (sim, bag)" where each alone does (it
    read "and", as if both were needed)."""
    keywords = (("method", lambda j: j["label"]), ("dataset", lambda j: j["spec"]["dataset_name"]),
                ("seed", lambda j: j["spec"].get("seed")), ("experiment", lambda j: j["spec"].get("experiment")),
                ("task", lambda j: j["spec"].get("task")))
    hints, alone = [], []
    for keyword, value_of in keywords:
        values = list(dict.fromkeys(value_of(j) for j in found))
        if len(values) > 1:
            hints.append(f"{keyword}= ({', '.join(map(str, values))})")
            if len(values) == len(found):  # one value per job: this keyword alone picks any of them
                alone.append(hints[-1])
    if not hints:  # (alike in every keyword: a manifest edited by hand)
        return "pinned: " + ", ".join(job_name(j, found) for j in found)
    return "pick one with " + (" or ".join(alone) if alone else " and ".join(hints))


def job_name(pinned: Mapping[str, Any], jobs: list[dict[str, Any]]) -> str:
    """``kiss on k00 (seed 0)``, naming the experiment when another experiment pins the same method on the same dataset
    (``kiss on k00 (seed 0, experiment short)``): the two read alike."""
    spec, label = pinned["spec"], Job.from_spec(pinned["spec"]).method_label  # (as its spec says now)
    twin = any(j["label"] == pinned["label"] and j["spec"]["dataset_name"] == spec["dataset_name"]
               and j["spec"].get("experiment") != spec.get("experiment") for j in jobs)
    return f"{label} on {spec['dataset_name']} (seed {spec.get('seed')}" + (
        f", experiment {spec.get('experiment')})" if twin else ")")


def record(
    suite_path: str | os.PathLike,
    out_dir: str | os.PathLike,
    *,
    repeats: int = 3,
    on_job: Callable[[Job, int], None] | None = None,
) -> Baseline:
    """Run ``suite_path`` ``repeats`` times and write the baseline folder ``out_dir`` (all or nothing, through
    :func:`lidarkit.atomic.run_folder`: a failed run leaves no partial baseline). An earlier baseline in ``out_dir``
    is replaced whole (its pinned jobs that this one does not pin are removed); a folder holding anything else (a
    bench results folder) is refused rather than merged into."""
    from lidarkit.bench.results import path_argument
    from lidarkit.bench.runner import task_origin
    from lidarkit.bench.suite import load_suite

    if int(repeats) != repeats or repeats < 1:
        raise ConfigError(f"repeats must be a positive integer, got {repeats}", source="repeats")
    # (a loop of symbolic links: one line naming it, not a RuntimeError traceback)
    given = path_argument(suite_path, "suite_path")
    streamed = atomic.stream_reason(given)  # (resolved first, <(cat suite.yaml) read "suite file not found")
    if streamed:
        raise DataError(streamed, source=given)
    suite_path = atomic.resolved_path(given, output=False)
    suite = load_suite(suite_path)
    out = Path(out_dir)
    atomic.check_target(out, "folder")
    _refuse_out_inside_data(out, suite.jobs)
    if out.is_dir() and any(out.iterdir()) and not (out / MANIFEST).is_file():
        raise OutputError(f"the folder holds files but no {MANIFEST}: not a baseline to replace (a bench results folder?); "
                          "choose a new folder", source=out)
    if (out / MANIFEST).is_file() and not _is_baseline_manifest(out / MANIFEST):
        raise OutputError(f"its {MANIFEST} is not a lidarkit baseline's (schema {SCHEMA!r}): not a baseline to replace; "
                          "choose a new folder", source=out)
    cache: dict[str, str] = {}
    jobs = []
    with atomic.run_folder(out) as tmp:
        for job in suite.jobs:
            runs = []
            for r in range(int(repeats)):
                if on_job is not None:
                    on_job(job, r)
                runs.append(run_job(job, cache))
            first = runs[0]
            key = job.key()
            # a metric checked needs a value in every repeat (a NaN in a later one would make its band NaN)
            names = [m for m in checked_metrics(job.task, first.metrics) if all(_finite_number(run.metrics.get(m)) for run in runs)]
            noise = {m: float(np.std([run.metrics[m] for run in runs], ddof=1)) if len(runs) > 1 else 0.0 for m in names}
            bands = {m: _band(m, float(first.metrics[m]), noise[m], job.task) for m in names}
            held_on = {}
            if not holds_accuracy(names) and first.trajectory is not None:  # (no ground truth: the bad-frame count alone
                # let a method regression pass)
                held_on["trajectory_band"] = _trajectory_band([run.trajectory for run in runs], _job_name(job))
            elif not holds_accuracy(names):
                log.warning("%s: no accuracy metric and no trajectory to pin: its check holds only %s", _job_name(job),
                            ", ".join(names) or "whether it runs")
            folder = tmp / "jobs" / key
            atomic.write_text(folder / "metrics.json", json.dumps(_jsonable(first.metrics), indent=1, sort_keys=True) + "\n")
            if first.trajectory is not None:
                first.trajectory.to_kitti(folder / "poses_kitti.txt")
            # a task registered in code: where its module is, as bench results keep it, for a check to import it
            origin = task_origin(job.task)
            jobs.append({
                "key": key, "label": job.method_label, "spec": job.spec(), "protocol": first.protocol,
                "metrics": _jsonable(first.metrics), "checked": names, "noise_std": noise, "bands": bands,
                "repeats": [_jsonable(run.metrics) for run in runs], **held_on,
                **({"task_module": origin} if origin else {}),
            })
        atomic.write_text(tmp / "suite.yaml", suite_copy_text(suite_path))
        manifest = {"schema": SCHEMA, "created_utc": _utc(), "suite": suite.name, "repeats": int(repeats),
                    "environment": environment(), "evaluation": evaluation_settings(),
                    "band_rule": f"max({NOISE_FACTOR:g} x run-to-run std, per-metric floor, {RELATIVE_FLOOR:g} x value)",
                    "jobs": jobs}
        atomic.write_text(tmp / MANIFEST, json.dumps(_jsonable(manifest), indent=1) + "\n")
        load_baseline(tmp)  # what a check will read, read before it replaces the earlier baseline
    pinned = {job["key"] for job in jobs}
    for folder in sorted((out / "jobs").iterdir()):  # an earlier baseline's jobs this one does not pin
        if folder.is_dir() and folder.name not in pinned:
            shutil.rmtree(folder)
    return load_baseline(out)


def _refuse_out_inside_data(out: Path, jobs: list[Job]) -> None:
    """OutputError when the baseline folder ``out`` lies inside a folder a job's checksums cover (its dataset folder, or
    a folder a reader option names): the baseline would pin its own files, and every check read ``protocol changed:
    data.DATA/baseline/manifest.json: <absent> -> ...``."""
    from lidarkit.bench.datasets import PATHLESS_KINDS, dataset_options

    where = Path(os.path.realpath(out))
    for job in jobs:
        if job.dataset.get("kind") in PATHLESS_KINDS:
            continue
        try:
            folders = [dataset_folder(job.dataset)]
        except LidarKitError:  # (a dataset not there: its run says so)
            continue
        folders += [Path(v) for v in dataset_options(dict(job.dataset)).values()
                    if isinstance(v, str) and os.path.isabs(v) and Path(v).is_dir()]
        for folder in folders:
            if folder.is_dir() and where.is_relative_to(os.path.realpath(folder)):
                raise OutputError(f"inside the dataset folder {folder} of the job {_job_name(job)}: the baseline would pin "
                                  "its own files as the job's data (its check always reads 'protocol changed'); choose a "
                                  "folder outside the data", source=out)


def suite_copy_text(suite_path: str | os.PathLike) -> str:
    """The suite file's text with its dataset paths (and reader path options) written as its jobs resolved them, as the
    manifest stores them, for the baseline folder's ``suite.yaml``: copied verbatim, a relative ``path: kd`` resolved
    against the baseline folder ("dataset path does not exist: .../baseline/kd") and the copy could not record again.
    Only those values change (comments and layout kept), under a header comment saying so."""
    import yaml

    from lidarkit.bench.datasets import resolve_dataset, resolve_option_paths

    suite_path = atomic.resolved_path(suite_path, output=False)
    text = suite_path.read_text(encoding="utf-8")
    header = "# the suite recorded from "
    copied = text.startswith(header)  # a baseline's own copy recorded again: its header named the file copied first
    if copied:
        lines = text.splitlines(keepends=True)
        text = "".join(lines[2:] if len(lines) > 1 and lines[1].startswith("# ") else lines[1:])
    try:
        root, data = yaml.compose(text), yaml.safe_load(text)
    except yaml.YAMLError:  # (load_suite read it: not reached)
        return text
    edits: dict[int, tuple[int, str]] = {}  # start of a value in the text -> (its end, the resolved value)
    for node, spec in _dataset_entries(root, data):
        try:
            resolved = resolve_option_paths(resolve_dataset(dict(spec), suite_path.parent), suite_path.parent)
        except (LidarKitError, TypeError, ValueError):  # (kept as written: a spec load_suite took otherwise)
            continue
        for key, value in spec.items():  # (the relative ones: an absolute path reads the same from here)
            value_node = _mapping_value(node, key)
            if (isinstance(value, str) and isinstance(resolved.get(key), str) and resolved[key] != value
                    and not Path(value).expanduser().is_absolute() and isinstance(value_node, yaml.ScalarNode)):
                edits[value_node.start_mark.index] = (value_node.end_mark.index, json.dumps(resolved[key]))
    if not edits and not copied:
        return text
    for start in sorted(edits, reverse=True):
        end, value = edits[start]
        text = text[:start] + value + text[end:]
    return (f"{header}{suite_path}, its relative dataset paths written as the baseline resolved them (from that\n"
            "# file's folder), so that this copy records again from here\n" + text)


def _dataset_entries(root: Any, data: Any) -> list[tuple[Any, dict[str, Any]]]:
    """``(YAML mapping node, its spec)`` of every dataset a suite writes out: under ``datasets:``, and an experiment's
    ``dataset:`` or ``datasets:`` entries given as mappings (not by name)."""
    if not isinstance(data, dict):
        return []
    out = []
    named = data.get("datasets")
    if isinstance(named, dict):
        out += [(_mapping_value(_mapping_value(root, "datasets"), name), spec) for name, spec in named.items()]
    experiments = data.get("experiments")
    exp_nodes = _mapping_value(root, "experiments")
    for i, exp in enumerate(experiments if isinstance(experiments, list) else []):
        exp_node = exp_nodes.value[i] if exp_nodes is not None and i < len(exp_nodes.value) else None
        if not isinstance(exp, dict):
            continue
        out.append((_mapping_value(exp_node, "dataset"), exp.get("dataset")))
        listed, list_node = exp.get("datasets"), _mapping_value(exp_node, "datasets")
        for k, spec in enumerate(listed if isinstance(listed, list) else []):
            out.append((list_node.value[k] if list_node is not None and k < len(list_node.value) else None, spec))
    return [(node, spec) for node, spec in out if isinstance(spec, dict) and node is not None]


def _mapping_value(node: Any, key: str) -> Any:
    """The value node of ``key`` in a YAML mapping node (a key merged in with ``<<:`` too); None when absent."""
    import yaml

    if not isinstance(node, yaml.MappingNode):
        return None
    merged = []
    for key_node, value_node in node.value:
        if isinstance(key_node, yaml.ScalarNode) and key_node.value == key:
            return value_node
        if isinstance(key_node, yaml.ScalarNode) and key_node.value == "<<":
            merged += value_node.value if isinstance(value_node, yaml.SequenceNode) else [value_node]
    return next((found for source in merged if (found := _mapping_value(source, key)) is not None), None)


def _is_baseline_manifest(path: Path) -> bool:
    """Whether ``path`` is a baseline manifest (any readable JSON with this schema, corrupt fields or not): record
    replaces such a folder whole, and nothing else."""
    try:
        manifest = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError):
        return False
    return isinstance(manifest, dict) and manifest.get("schema") == SCHEMA


def load_baseline(path: str | os.PathLike) -> Baseline:
    """A baseline folder; DataError when the folder, its manifest or a field of it is missing or corrupt."""
    path = Path(path)
    if path.is_file():
        raise DataError("a file, not a baseline folder (give the folder `lidarkit baseline record --out` wrote)", source=path)
    if not path.is_dir():  # (a dangling link or a loop of links read "does not exist")
        from lidarkit.atomic import missing_reason

        raise DataError(missing_reason(path, "baseline folder does not exist"), source=path)
    manifest_path = path / MANIFEST
    if not manifest_path.is_file():
        raise DataError(f"no {MANIFEST}: not a baseline folder (write one with `lidarkit baseline record`)", source=path)
    try:
        manifest = json.loads(manifest_path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as err:
        raise DataError(f"corrupt manifest: not readable JSON ({err})", source=manifest_path) from None
    if not isinstance(manifest, dict) or manifest.get("schema") != SCHEMA:
        found = manifest.get("schema") if isinstance(manifest, dict) else type(manifest).__name__
        raise DataError(f"corrupt manifest: schema {found!r}, expected {SCHEMA!r}", source=manifest_path)
    for key in ("environment", "evaluation", "jobs"):
        if key not in manifest:
            raise DataError(f"corrupt manifest: no {key!r}", source=manifest_path)
    for key in ("environment", "evaluation"):
        if not isinstance(manifest[key], dict):
            raise DataError(f"corrupt manifest: {key!r} is {manifest[key]!r}, not a mapping", source=manifest_path)
    if not isinstance(manifest["jobs"], list) or not manifest["jobs"]:
        raise DataError("corrupt manifest: no pinned jobs", source=manifest_path)
    for i, job in enumerate(manifest["jobs"]):
        problem = _pinned_job_problem(job)
        if problem:
            raise DataError(f"corrupt manifest: job {i} {problem}", source=manifest_path)
    first_of_key: dict[str, int] = {}
    for i, job in enumerate(manifest["jobs"]):  # (a job listed twice was checked twice: "5 pinned jobs" for 4 jobs)
        if job["key"] in first_of_key:
            raise DataError(f"corrupt manifest: job {i} ({job_name(job, manifest['jobs'])}) repeats the key "
                            f"{job['key']} of job {first_of_key[job['key']]}", source=manifest_path)
        first_of_key[job["key"]] = i
    return Baseline(path, manifest)


def _pinned_job_problem(job: Any) -> str:
    """What is wrong with one pinned job of a manifest (edited by hand, cut short), or ''."""
    if not isinstance(job, dict):
        return f"is {job!r}, not a mapping"
    missing = [k for k in ("key", "label", "spec", "protocol", "metrics", "checked", "bands") if k not in job]
    if missing:
        return f"lacks {', '.join(missing)}"
    if not isinstance(job["key"], str) or not job["key"]:  # (it names the job's folder under jobs/)
        return f"key is {job['key']!r}, not a job key"
    if job["key"] in (".", "..") or any(sep in job["key"] for sep in "/\\"):  # ("../../x" read files outside the folder)
        return f"key {job['key']!r} is not a plain name (it names the job's folder under jobs/)"
    try:
        Job.from_spec(job["spec"])
    except (TypeError, ValueError, AttributeError) as err:
        return f"has a bad spec ({err})"
    if not isinstance(job["label"], str) or not job["label"]:  # (5 was a TypeError traceback from Baseline.job)
        return f"label is {job['label']!r}, not a method label"
    spec = job["spec"]
    for key, kind in (("dataset", dict), ("params", dict), ("options", dict), ("method", str), ("task", str),
                      ("experiment", str), ("dataset_name", str)):
        if key in spec and not isinstance(spec[key], kind):  # (a string dataset failed later, an AttributeError traceback)
            return f"spec {key} is {spec[key]!r}, not a {'mapping' if kind is dict else 'string'}"
    dataset = spec.get("dataset", {})
    for key in ("kind", "path", "name"):  # (a path of 5 was a TypeError traceback where the check hashed its files)
        if (key == "kind" or dataset.get(key) is not None) and (not isinstance(dataset.get(key), str) or not dataset[key]):
            return f"spec dataset {key} is {dataset.get(key, '<absent>')!r}, not a string"
    if "seed" in spec and (not isinstance(spec["seed"], int) or isinstance(spec["seed"], bool)):  # (read as the job failing)
        return f"spec seed is {spec['seed']!r}, not an integer"
    if spec.get("seed", 0) < 0:  # (read as the job failing: "ValueError: expected non-negative integer")
        return f"spec seed is {spec['seed']}, not a non-negative integer"
    for key in ("protocol", "metrics", "bands"):
        if not isinstance(job[key], dict):
            return f"{key} is {job[key]!r}, not a mapping"
    problem = _pinned_protocol_problem(job["protocol"])
    if problem:
        return problem
    if not isinstance(job["checked"], list):
        return f"checked is {job['checked']!r}, not a list"
    repeated = next((m for k, m in enumerate(job["checked"]) if m in job["checked"][:k]), None)
    if repeated is not None:  # (its finding was reported twice)
        return f"checks {repeated!r} twice"
    for metric in job["checked"]:
        for where in ("metrics", "bands"):
            value = job[where].get(metric) if isinstance(metric, str) else None
            if not _finite_number(value):
                return f"checks {metric!r} but its {where[:-1]} is {value!r}, not a finite number"
        if job["bands"][metric] < 0:
            return f"band of {metric!r} is negative ({job['bands'][metric]!r})"
    if "task_module" in job and not (isinstance(job["task_module"], dict) and isinstance(job["task_module"].get("module"), str)):
        return f"task_module is {job['task_module']!r}, not a mapping naming a module"
    if "trajectory_band" in job:
        band = job["trajectory_band"]
        if not isinstance(band, dict):
            return f"trajectory_band is {band!r}, not a mapping"
        for key in ("position_m", "rotation_deg"):
            if not _finite_number(band.get(key)) or band[key] < 0:
                return f"trajectory_band {key} is {band.get(key, '<absent>')!r}, not a finite number >= 0"
    return ""


def _pinned_protocol_problem(protocol: dict[str, Any]) -> str:
    """What is wrong with the fields of a pinned protocol that check reads as mappings, or '' (checksums of None read
    as a TypeError traceback; option_files of "x" as "not pinned", its files never compared)."""
    for key in ("checksums", "option_files"):  # {file: sha256}
        if key not in protocol:
            continue
        value = protocol[key]
        if not isinstance(value, dict):
            return f"protocol {key} is {value!r}, not a mapping"
        bad = next(((k, v) for k, v in value.items() if not isinstance(v, str)), None)
        if bad is not None:
            return f"protocol {key} gives {bad[0]!r} the checksum {bad[1]!r}, not a string"
    for key in ("task_options", "frame_check", "simulation", "method_config"):
        if key in protocol and not isinstance(protocol[key], dict):
            return f"protocol {key} is {protocol[key]!r}, not a mapping"
    return ""


def measured_noise(path: str | os.PathLike, metric: str | None, task: str | None = None,
                   methods: tuple[str, ...] = ()) -> float:
    """The widest band a baseline folder recorded for ``metric`` (its run-to-run noise allowance, metric unit) over its
    jobs of ``task``, and of ``methods`` (labels or names) when it pinned any; ConfigError when no such job checks that
    metric (random_walk's band of a self-test was taken as the noise of a particle filter's APE)."""
    baseline = load_baseline(path)
    jobs = [job for job in baseline.jobs if metric in job.get("bands", {}) and task in (None, job["spec"]["task"])]
    if not jobs:
        known = sorted({f"{job['spec']['task']}: {m}" if task else m for job in baseline.jobs for m in job.get("bands", {})})
        of_task = f" of task {task!r}" if task else ""
        raise ConfigError(f"no band for metric {metric!r}{of_task} in this baseline (it has: {', '.join(known)}): it did not "
                          "check that metric" + (" on that task (--noise-from)" if task else ""), source=baseline.path)
    mine = [job for job in jobs if {job["label"], job["spec"]["method"]} & set(methods)]
    return max(float(job["bands"][metric]) for job in mine or jobs)


# ---------------------------------------------------------------- check


@dataclass
class Finding:
    """One finding of a check; its job and message are kept on one line (a plugin's exception message with a newline
    ran over several lines of the report)."""

    kind: str  # "protocol changed" | "failed" | "regression" | "improved" | "note"
    job: str
    message: str

    def __post_init__(self) -> None:
        self.job, self.message = (" ".join(str(text).split()) for text in (self.job, self.message))

    def line(self) -> str:
        return f"{self.kind}: {self.job}: {self.message}"


@dataclass
class CheckResult:
    """Findings of a check; ``passed`` unless a protocol changed, a job failed or a metric regressed."""

    path: Path
    findings: list[Finding] = field(default_factory=list)
    n_jobs: int = 0
    measured: dict[str, dict[str, float]] = field(default_factory=dict)  # job key -> metrics now

    @property
    def passed(self) -> bool:
        return not any(f.kind in ("protocol changed", "failed", "regression") for f in self.findings)

    def lines(self) -> list[str]:
        order = {"protocol changed": 0, "failed": 1, "regression": 2, "improved": 3, "note": 4}
        return [f.line() for f in sorted(self.findings, key=lambda f: order[f.kind])]


def _diff(prefix: str, old: Any, new: Any) -> list[str]:
    if isinstance(old, dict) and isinstance(new, dict):
        out = []
        for key in sorted(set(old) | set(new), key=str):
            out += _diff(f"{prefix}.{key}" if prefix else str(key), old.get(key, "<absent>"), new.get(key, "<absent>"))
        return out
    if old != new and not (isinstance(old, float) and isinstance(new, float) and math.isclose(old, new, rel_tol=1e-12)):
        return [f"{prefix}: {' -> '.join(_shown_apart(old, new))}"]
    return []


def _short(value: Any) -> str:
    text = json.dumps(value) if not isinstance(value, str) else value
    return text if len(text) <= 24 else text[:10] + "..." + text[-8:]


def _shown_apart(old: Any, new: Any) -> tuple[str, str]:
    """Two differing values as a finding shows them, told apart where they print alike: with their types (a number
    stored as text read "kitti_step_frames: 10 -> 10"), or in full when cut short alike."""
    old_text, new_text = _short(old), _short(new)
    if old_text != new_text:
        return old_text, new_text
    if type(old) is not type(new):
        return f"{old_text} ({type(old).__name__})", f"{new_text} ({type(new).__name__})"
    return json.dumps(old), json.dumps(new)


def _import_pinned_tasks(jobs: list[dict[str, Any]]) -> dict[str, str]:
    """Import the module of each pinned task registered in code (``task_module``, as record pinned it); ``{task: why}``
    of the tasks still unknown here."""
    from lidarkit.bench.report import _import_task_module
    from lidarkit.bench.tasks import available_tasks, get_task

    origins: dict[str, Any] = {}
    for job in jobs:
        task = job["spec"].get("task", "")
        origins[task] = origins.get(task) or job.get("task_module")
    unknown = {}
    for task, origin in origins.items():
        if task in available_tasks():
            continue
        if not origin:
            unknown[task] = (f"task {task!r} is not known here and the baseline names no module defining it (recorded "
                             "before lidarkit pinned a task's module): import the module that registers it and call "
                             "lidarkit.bench.baseline.check() from Python, or record the baseline again")
            continue
        if origin.get("module") == "__main__":  # (a script's own task: no process but that script's can import it)
            unknown[task] = (f"task {task!r} was registered in the script that recorded the baseline "
                             f"({origin.get('script') or '__main__'}): run check() from it, or define the task in a module")
            continue
        why = _import_task_module(task, origin)
        if not why and task not in available_tasks():
            why = f"its module {origin['module']} registers no task {task!r}"
        if not why:
            try:
                get_task(task)
            except Exception as err:  # noqa: BLE001 - a task class that fails to build: said for its jobs
                why = f"{type(err).__name__}: {err}"
        if why:
            unknown[task] = f"task {task!r}: {why}"
    return unknown


def parse_tolerances(items: list[str] | Mapping[str, float] | None) -> dict[str, float]:
    """``["metric=band", ...]`` (absolute bands in the metric's unit) -> dict; ConfigError on a bad item."""
    if items is None:
        return {}
    if isinstance(items, Mapping):
        pairs = list(items.items())
    else:
        pairs = []
        for item in items:
            name, sep, value = str(item).partition("=")
            if not sep or not name.strip():
                raise ConfigError(f"expected METRIC=BAND, got {item!r}", source="--tolerance")
            pairs.append((name.strip(), value))
    out = {}
    for name, value in pairs:
        if name in out:  # (the last one was kept silently)
            raise ConfigError(f"{name!r} given twice: one band per metric", source="--tolerance")
        try:
            band = float(value)
        except (TypeError, ValueError):
            raise ConfigError(f"band of {name!r} is not a number: {value!r}", source="--tolerance") from None
        if not band >= 0 or not math.isfinite(band):
            raise ConfigError(f"band of {name!r} must be a finite number >= 0, got {value!r}", source="--tolerance")
        out[name] = band
    return out


def check(
    path: str | os.PathLike,
    *,
    tolerances: list[str] | Mapping[str, float] | None = None,
    on_job: Callable[[Job], None] | None = None,
) -> CheckResult:
    """Re-run the pinned jobs of the baseline at ``path`` and compare (see the module docstring).

    ``tolerances`` overrides bands: ``{"drift_translation_pct": 0.2}`` or ``["drift_translation_pct=0.2"]``.
    """
    baseline = load_baseline(path)
    bands_override = parse_tolerances(tolerances)
    unknown_tasks = _import_pinned_tasks(baseline.jobs)
    checked = sorted({m for job in baseline.jobs for m in job["checked"]
                      if m not in unchecked_metrics(job["spec"].get("task", ""))})
    if any("trajectory_band" in job for job in baseline.jobs):  # (jobs without ground truth: their trajectory's band)
        checked += list(TRAJECTORY_TOLERANCES)
    unknown = sorted(set(bands_override) - set(checked))
    if unknown:
        raise ConfigError(f"no pinned job checks {', '.join(unknown)}; checked metrics: {', '.join(checked)}", source="--tolerance")
    result = CheckResult(baseline.path, n_jobs=len(baseline.jobs))
    env_then, env_now = baseline.manifest["environment"], environment()
    packages_then = env_then.get("packages")
    unpinned = sorted(set(env_now["packages"]) - set(packages_then)) if isinstance(packages_then, dict) else []
    if unpinned:  # (a package lidarkit pinned later, OpenCV: held as today's, said in a note)
        packages_then = {**packages_then, **{name: env_now["packages"][name] for name in unpinned}}
        package_notes = [Finding("note", "environment", f"the baseline pinned no {name} version (recorded before lidarkit "
                                                       f"pinned it): not compared; {name} is {env_now['packages'][name]} now")
                        for name in unpinned]
    else:
        package_notes = []
    if isinstance(packages_then, dict) and same_opencv(packages_then.get("opencv"), env_now["packages"].get("opencv")):
        packages_then = {**packages_then, "opencv": env_now["packages"].get("opencv")}  # (one OpenCV, read two ways)
    # a package only some jobs run on voids those jobs only (see uses_package); the others' and the platform's, every job
    scoped_then = {k: v for k, v in packages_then.items() if k in SCOPED_PACKAGES} if isinstance(packages_then, dict) else {}
    scoped_now = {k: v for k, v in env_now["packages"].items() if k in SCOPED_PACKAGES}
    scoped_changes = {package: _diff(f"packages.{package}", scoped_then.get(package, "<absent>"), scoped_now.get(package, "<absent>"))
                      for package in SCOPED_PACKAGES}
    scoped_changes = {package: lines for package, lines in scoped_changes.items() if lines}
    unscoped = (lambda packages: {k: v for k, v in packages.items() if k not in SCOPED_PACKAGES}
                if isinstance(packages, dict) else packages)
    env_changes = _diff("", {"packages": unscoped(packages_then), "platform": env_then.get("platform")},
                        {"packages": unscoped(env_now["packages"]), "platform": env_now["platform"]})
    for line in env_changes:
        result.findings.append(Finding("protocol changed", "environment", line))
    for package, lines in scoped_changes.items():
        if not any(uses_package(package, job["spec"]) for job in baseline.jobs):
            result.findings += [Finding("note", "environment", f"{line} (no pinned job runs on {package}: not compared)")
                                for line in lines]
    result.findings += package_notes
    if env_then.get("lidarkit") != env_now["lidarkit"]:
        result.findings.append(Finding("note", "environment", f"lidarkit {env_then.get('lidarkit')} -> {env_now['lidarkit']}"))
    eval_changes = _diff("", baseline.manifest["evaluation"], evaluation_settings())
    for line in eval_changes:
        result.findings.append(Finding("protocol changed", "evaluation", line))
    cache: dict[str, str] = {}
    for pinned in baseline.jobs:
        job = Job.from_spec(pinned["spec"])
        name = job_name(pinned, baseline.jobs)
        if on_job is not None:
            on_job(job)
        if job.task in unknown_tasks:  # (read "task: unknown task 'my_task'")
            result.findings.append(Finding("failed", name, unknown_tasks[job.task]))
            continue
        try:
            checksums_now = dataset_checksums(job.dataset, cache, job.task)
            pinned_checksums, checksums_now, read_notes = _files_read_apart(
                job, dict(pinned["protocol"].get("checksums", {})), checksums_now, name)
        except (DataError, ConfigError) as err:
            result.findings.append(Finding("protocol changed", name, f"dataset not readable: {err}"))
            continue
        result.findings += read_notes
        unpinned = [k for k in checksums_now if k.endswith(".relations") and k not in pinned_checksums
                    and job.dataset.get("kind") == "carmen"]
        if unpinned:  # (a CARMEN baseline recorded before the relations beside its log were hashed: not a change)
            result.findings.append(Finding("note", name, f"the baseline pinned no checksum of {', '.join(unpinned)} (recorded "
                                                          "before lidarkit hashed it): not compared; record it again to pin it"))
            checksums_now = {k: v for k, v in checksums_now.items() if k not in unpinned}
        pinned_option_files = pinned["protocol"].get("option_files")
        try:
            option_files_now = {k: v for k, v in option_checksums(job, cache).items() if k not in checksums_now}
        except LidarKitError:  # (options this lidarkit refuses: the job's "failed" finding below names them)
            option_files_now = {}
        if isinstance(pinned_option_files, dict):
            pinned_checksums.update(pinned_option_files)
            checksums_now = {**checksums_now, **option_files_now}
        else:  # (a baseline recorded before lidarkit hashed them apart: one inside the dataset folder was pinned with
            # its files, and is compared there; the others are not a change)
            checksums_now.update({k: v for k, v in option_files_now.items() if k in pinned_checksums})
            unpinned = [k for k in option_files_now if k not in pinned_checksums]
            if unpinned:
                result.findings.append(Finding("note", name, "the baseline pinned no checksum of the files its task options "
                                                              f"name ({', '.join(unpinned)}; recorded before lidarkit "
                                                              "hashed them): not compared; record it again to pin them"))
        data_changes = _diff("data", pinned_checksums, checksums_now)
        if data_changes:
            for line in data_changes[:10]:
                result.findings.append(Finding("protocol changed", name, line))
            if len(data_changes) > 10:
                result.findings.append(Finding("protocol changed", name, f"... {len(data_changes) - 10} more data files"))
            continue
        package_changes = [line for package, lines in scoped_changes.items() if uses_package(package, pinned["spec"])
                           for line in lines]
        for line in package_changes:  # (a package this job runs on: its numbers are not comparable; the others' are)
            result.findings.append(Finding("protocol changed", name, line))
        if env_changes or eval_changes or package_changes:
            continue  # numbers under another environment or evaluation are not comparable: do not spend the run
        try:
            _validate_pinned_options(job)
            run = run_job(job, cache)
        except LidarKitError as err:  # one job failing is its finding: the others are still checked and reported
            result.findings.append(Finding("failed", name, err.reason))
            continue
        result.measured[pinned["key"]] = run.metrics
        compared_apart = ("checksums", "option_files", "method_config")
        then = {k: v for k, v in pinned["protocol"].items() if k not in compared_apart}
        if isinstance(then.get("deskew"), dict):  # (recorded before the applied deskew was pinned: the run's deskew record)
            then["deskew"] = then["deskew"].get("applied")
        # (a baseline recorded before lidarkit pinned the whole simulator config, or the task options with their
        # defaults: not a change)
        now = {k: v for k, v in run.protocol.items() if k not in compared_apart
               and (k in then or k not in ("simulation", "task_options"))}
        added = sorted(set(now.get("task_options") or {}) - set(then.get("task_options") or {})) if isinstance(
            then.get("task_options"), dict) and isinstance(now.get("task_options"), dict) else []
        if added:  # an option the task gained since (odometry's init): the pinned job ran as its default does
            then["task_options"] = {**then["task_options"], **{k: now["task_options"][k] for k in added}}
            result.findings.append(Finding("note", name, f"the baseline pinned no task option {', '.join(added)} (recorded "
                                                          "before the task had it): held under today's default"))
        if "frame_check" in now and "frame_check" not in then:  # (recorded before lidarkit pinned them: today's defaults)
            then["frame_check"] = frame_check_thresholds()
            result.findings.append(Finding("note", name, "the baseline pinned no frame-check thresholds (recorded before "
                                                          "lidarkit pinned them): held under today's defaults"))
        protocol_changes = _diff("", then, now)
        for line in protocol_changes:
            result.findings.append(Finding("protocol changed", name, line))
        pinned_config = pinned["protocol"].get("method_config", {})
        if not pinned_config and run.protocol.get("method_config"):  # (one note, not one per setting)
            result.findings.append(Finding("note", name, "the baseline pinned no method config (recorded before lidarkit "
                                                          "pinned this task's); record it again to compare settings"))
        else:
            for line in _diff("method config", pinned_config, run.protocol.get("method_config", {})):
                result.findings.append(Finding("note", name, line))
        if protocol_changes:
            continue
        scored_apart = _scored_count_difference(baseline, pinned, run)
        if scored_apart:  # (7 frames against 8 read as 14 "improved" lines)
            result.findings.append(Finding("failed", name, scored_apart))
            continue
        dropped = {m: kind for m, kind in unchecked_metrics(pinned["spec"]["task"]).items() if m in pinned["checked"]}
        if dropped:  # (a baseline recorded when the task declared them accuracy metrics)
            kinds = ", ".join(sorted(set(dropped.values())))
            result.findings.append(Finding("note", name, f"the baseline pinned {', '.join(dropped)} (recorded when "
                                                          f"{pinned['spec']['task']} declared them accuracy metrics): "
                                                          f"not checked any more ({kinds} metrics)"))
        for metric in [m for m in pinned["checked"] if m not in dropped]:
            ref = float(pinned["metrics"][metric])
            band = bands_override.get(metric, float(pinned["bands"][metric]))
            value = run.metrics.get(metric)
            if value is None or not math.isfinite(float(value)):
                result.findings.append(Finding("regression", name, f"{metric} is missing now (baseline {ref:.6g})"))
                continue
            delta = float(value) - ref
            # round-off is a tie whatever the band, as compare takes it (-t M=0 made 1e-16 a regression)
            if abs(delta) <= max(band, tie_tolerance(np.array([float(value)]), np.array([ref]))):
                continue
            worse = (delta < 0) if higher_is_better(metric, pinned["spec"]["task"]) else (delta > 0)
            text = f"{metric} = {float(value):.6g}, baseline {ref:.6g} ± {band:.3g} (change {delta:+.3g})"
            result.findings.append(Finding("regression" if worse else "improved", name, text))
        result.findings += _trajectory_findings(baseline, pinned, run, name, bands_override)
    return result


def _scored_count_difference(baseline: Baseline, pinned: Mapping[str, Any], run: JobRun) -> str:
    """Why the rerun's numbers were not scored over the pinned job's frames, or '': another ``n_frames`` (its
    metrics are then of other frames, better or worse by that alone), or, where no count was pinned, a trajectory of
    another length than the pinned ``poses_kitti.txt``."""
    then, now = pinned["metrics"].get("n_frames"), run.metrics.get("n_frames")
    if _finite_number(then) and _finite_number(now):
        if float(then) != float(now):
            return (f"scored {float(now):g} frames, the baseline {float(then):g} (n_frames): its metrics are of other "
                    "frames and are not compared")
        return ""
    path = baseline.path / "jobs" / str(pinned["key"]) / "poses_kitti.txt"
    if run.trajectory is None or _finite_number(then) or not path.is_file():
        return ""
    try:
        n_then = sum(1 for line in path.read_text(encoding="utf-8").splitlines() if line.strip())
    except (OSError, UnicodeDecodeError):
        return ""  # (_trajectory_findings says why it cannot be read)
    if n_then != len(run.trajectory):
        return (f"its trajectory has {len(run.trajectory)} poses, the pinned one {n_then}: its metrics are of other frames "
                "and are not compared")
    return ""


#: ``--tolerance`` names of a trajectory band (a job without ground truth): its position (m) and rotation (deg) parts
TRAJECTORY_TOLERANCES = {"trajectory_m": "position_m", "trajectory_deg": "rotation_deg"}


def _trajectory_findings(
    baseline: Baseline, pinned: dict[str, Any], run: JobRun, name: str, bands_override: Mapping[str, float] | None = None,
) -> list[Finding]:
    """A job without an accuracy metric held on its trajectory: ``regression`` when the rerun's differs from the pinned
    one by more than the recorded band, or the band ``--tolerance trajectory_m=/trajectory_deg=`` give (its bad-frame
    count alone let a method regression pass); a baseline recorded before lidarkit pinned that band is said in a note."""
    from lidarkit.trajectory import Trajectory

    if run.trajectory is None or holds_accuracy(pinned["checked"]):
        return []
    band = pinned.get("trajectory_band")
    if band is None:
        return [Finding("note", name, "no accuracy metric (no ground truth) and no trajectory band pinned (recorded "
                                      "before lidarkit pinned one): held on its bad-frame count only; record it again "
                                      "to compare its trajectory")]
    path = baseline.path / "jobs" / pinned["key"] / "poses_kitti.txt"
    try:
        then = Trajectory.from_kitti(path)
    except LidarKitError as err:
        return [Finding("failed", name, f"its pinned trajectory is not readable ({err}): record the baseline again")]
    damaged = _damaged_trajectory(then, pinned)
    if damaged:  # (a file cut short read as the method's regression)
        return [Finding("failed", name, damaged)]
    if len(then) != len(run.trajectory):
        return [Finding("regression", name, f"trajectory has {len(run.trajectory)} poses, the pinned one {len(then)}")]
    d_m, d_deg = trajectory_difference(run.trajectory, then)
    override = bands_override or {}
    band = {**band, **{key: override[option] for option, key in TRAJECTORY_TOLERANCES.items() if option in override}}
    band_m, band_deg = float(band["position_m"]), float(band["rotation_deg"])
    # round-off is a tie whatever the band, as for metrics (-t trajectory_m=0 made kiss's 4e-15 m a regression): 1e-9 of
    # the largest position or the path length, and 1e-9 rad
    positions = np.concatenate([run.trajectory.poses_se3[:, :3, 3], then.poses_se3[:, :3, 3]])
    path_m = float(np.linalg.norm(np.diff(then.poses_se3[:, :3, 3], axis=0), axis=1).sum())
    tie_m = tie_tolerance(np.linalg.norm(positions, axis=1), np.array([path_m]))
    tie_deg = math.degrees(RELATIVE_TIE_TOLERANCE)
    if d_m.max() <= max(band_m, tie_m) and d_deg.max() <= max(band_deg, tie_deg):
        return []
    worst = int(np.argmax(d_m)) if d_m.max() > max(band_m, tie_m) else int(np.argmax(d_deg))
    return [Finding("regression", name, f"trajectory differs from the pinned one by {d_m.max():.4g} m, {d_deg.max():.4g} "
                                        f"deg (worst at pose {worst}; band {band_m:.2g} m, {band_deg:.2g} deg)")]
