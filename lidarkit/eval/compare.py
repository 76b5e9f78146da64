"""Paired comparison of two runs: odometry run folders (per KITTI segment or per frame) or bench results (per seed).

``compare(a, b)`` loads both sides, checks they ran over the same data (same ground truth, or the same
dataset specs and seeds), pairs the units and returns a :class:`~lidarkit.eval.statistics.PairedComparison`
whose ``verdict()`` says plainly who is better or that the difference does not stand out of the noise.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import re
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from lidarkit.errors import ConfigError, DataError, EvaluationError, LidarKitError
from lidarkit.eval.statistics import DEFAULT_ALPHA, PairedComparison, check_number, paired_test, spread_is_round_off
from lidarkit.trajectory import Trajectory

if TYPE_CHECKING:
    from lidarkit.bench.report import MetricInfo

#: the default bench metric of a task that declares none of its metrics (a plugin not installed here), first present wins,
#: and which task's headline is compared when the units of several tasks pair without --task; a task that declares its
#: metrics is compared on its first accuracy metric, the report's headline (odometry: the SE(3)-aligned APE)
DEFAULT_BENCH_METRICS = ("ape_se3_rmse_m", "drift_translation_pct", "mse_m2", "ape_rmse_m", "translation_error_m")
RUN_METRICS = ("segment_translation_pct", "segment_rotation_deg_per_100m", "rpe_translation_m", "rpe_rotation_deg")
#: the task options that choose which part of a dataset a job runs over (odometry's frames, icp_pair's scan pairs): two
#: experiments of a task that differ in them ran other units, pooled as experiments over other datasets are; options
#: that change how a method runs over the same data (pf's mse_start, icp_pair's init_noise_m) are not seeds of one
DATA_SELECTING_OPTIONS = {"odometry": ("frames",), "icp_pair": ("pairs", "max_pairs")}


@dataclass
class OdometryRun:
    """An odometry run folder: its estimate, its ground truth and its metrics.json."""

    path: Path
    name: str
    estimate: Trajectory
    ground_truth: Trajectory
    metrics: dict[str, Any]


@dataclass
class BenchRuns:
    """Successful bench results of one method label, keyed by (task, experiment, dataset spec, task options, seed); compare
    keys them without the experiment (:func:`_by_experiment`)."""

    path: Path
    name: str
    values: dict[str, dict[str, Any]] = field(default_factory=dict)  # pair key -> metrics
    labels: dict[str, str] = field(default_factory=dict)  # pair key -> "dataset, seed N"
    n_left_out: int = 0  # results in jobs/ not compared: of jobs outside the folder's suite.json (an earlier suite) ...
    n_earlier_version: int = 0  # ... or, of those, of the compared jobs run by another lidarkit version (as the report counts)
    versions: dict[str, str] = field(default_factory=dict)  # pair key -> lidarkit version of its result
    higher_is_better: set[str] = field(default_factory=set)  # metrics the results say are better higher (their task's word)
    speed_metrics: set[str] = field(default_factory=set)  # metrics the results say are speeds (times, rates: their task's word)
    experiments: dict[str, set[str]] = field(default_factory=dict)  # pair key -> the experiments its results are of
    alignments: dict[str, dict[str, str]] = field(default_factory=dict)  # pair key -> metric -> alignment its job states
    failed: set[str] = field(default_factory=set)  # pair keys whose job failed
    not_run: set[str] = field(default_factory=set)  # pair keys of the suite's jobs without a readable result (not run yet)
    instants: dict[str, str] = field(default_factory=dict)  # pair key -> sweep instant of the ground truth it was scored against
    records: list[dict[str, Any]] = field(default_factory=list, repr=False)  # the folder's latest records, read once
    unknown_tasks: dict[str, str] = field(default_factory=dict)  # task -> why its module (its metrics' meaning) is unknown here
    selections: dict[str, str] = field(default_factory=dict)  # pair key -> the part of its dataset it ran (frames, pairs)
    written_paths: dict[str, str] = field(default_factory=dict)  # a dataset path as it pairs (links followed) -> as written


def load_odometry_run(path: str | os.PathLike) -> OdometryRun:
    """A run folder written by ``lidarkit odometry --out`` (``poses_kitti.txt``, ``ground_truth_kitti.txt``,
    ``metrics.json``); DataError naming what is missing."""
    from lidarkit.atomic import missing_reason, resolved_path

    path = Path(path)
    resolved_path(path, output=False)  # (a loop of symbolic links read "does not exist")
    if not path.is_dir():  # (a dangling link read "run folder does not exist")
        raise DataError(missing_reason(path, "run folder does not exist") if not path.exists() else "run folder does not exist",
                        source=path)
    refused = _not_an_odometry_run(path)
    if refused:  # ("no ground_truth_kitti.txt" for a pf run folder, which holds its ground truth as TUM; "no metrics.json"
        # for a pf study folder, read as an unfinished odometry run, and for an icp run or a bench folder's jobs/)
        raise DataError(refused, source=path)
    metrics_file = path / "metrics.json"
    if not metrics_file.is_file():
        raise DataError("no metrics.json: not a finished odometry run folder", source=path)
    try:
        metrics = json.loads(metrics_file.read_text(encoding="utf-8"))
    except (OSError, ValueError) as err:
        raise DataError(f"unreadable metrics.json ({err})", source=metrics_file) from None
    if not isinstance(metrics, dict):
        raise DataError("metrics.json is not a JSON object", source=metrics_file)
    for name in ("poses_kitti.txt", "ground_truth_kitti.txt"):
        if not (path / name).is_file():
            raise DataError(f"no {name}: a paired comparison needs the estimate and its ground truth", source=path)
    name = _run_label(path, str(metrics.get("method") or path.name))
    return OdometryRun(
        path, name,
        Trajectory.from_kitti(path / "poses_kitti.txt", name=name),
        Trajectory.from_kitti(path / "ground_truth_kitti.txt", name="ground truth"),
        metrics,
    )


def load_bench_runs(path: str | os.PathLike, method: str | None = None, every_result: bool = False,
                    records: list[dict[str, Any]] | None = None) -> BenchRuns:
    """The successful results of one method of a bench folder; ``method`` is a method label (``kiss``,
    ``vanilla(voxel_size_m=0.5)``) or a bare method name when only one label has it. ConfigError lists the
    labels when the choice is ambiguous. As the report, only the jobs of the folder's ``suite.json`` (results an
    earlier suite, or an earlier lidarkit version, left in a reused folder are counted in ``n_left_out``, the latter in
    ``n_earlier_version`` too); ``every_result``: all of them, the latest of each job. ``records``:
    the folder's records when already read (the same folder given twice warned of each bad result twice)."""
    from lidarkit.bench.jobs import Job, canonical_json
    from lidarkit.bench.report import import_task_modules, latest_per_job, left_out_counts, suite_manifest
    from lidarkit.bench.report import suite_jobs as read_suite_jobs
    from lidarkit.bench.results import load_results, results_folder

    path = results_folder(path)
    every = load_results(path) if records is None else records
    suite_jobs = {} if every_result else read_suite_jobs(path)
    suite = set(suite_jobs)
    # as build_report: the suite's jobs, the latest result of each; a result left out with the spec of a job held here
    # is that job run by another lidarkit version (they were called "an earlier suite"'s, and counted after one per spec)
    latest = latest_per_job([r for r in every if not suite or r["key"] in suite])
    n_left_out, n_earlier_version = left_out_counts(every, latest, suite_jobs.values())
    # the modules of tasks registered in code, as the report imports them (a plugin task's headline and labels were
    # unknown to compare: "no default metric in these results" while its report ranked by them); those still unknown
    # are said in the errors that need them
    unknown_tasks = import_task_modules(latest, suite_manifest(path))
    records = [r for r in latest if r.get("status") == "ok"]
    every_ok = [r for r in every if r.get("status") == "ok"]
    if not records:
        raise DataError("no successful job results in jobs/" + (" for the jobs of suite.json (--all: every result)" if suite else ""),
                        source=path)
    labels = sorted({Job.from_spec(r["job"]).method_label for r in records})
    given = method  # (named as given in messages)
    if method is not None and method not in labels:  # ("vanilla(voxel_size_m=1.0)" was "not found" beside its label)
        method = _as_label(method)
    if method is None:
        if len(labels) > 1:
            raise ConfigError(f"{len(labels)} methods in this folder; choose one of: {', '.join(labels)}", source=path)
        chosen = labels[0]
    elif method in labels:
        chosen = method
    else:
        named = sorted({Job.from_spec(r["job"]).method_label for r in records if r["job"]["method"] == method})
        failed = [r for r in latest if r.get("status") != "ok" and (not suite or r["key"] in suite)
                  and method in (r["job"]["method"], Job.from_spec(r["job"]).method_label)]
        if not named and failed:  # (it read "not found")
            raise DataError(f"method {given!r} has no successful result: its {len(failed)} job(s) here failed "
                            "(lidarkit report lists why)", source=path)
        if len(named) != 1:
            known = ", ".join(labels)
            earlier = not named and any(method in (r["job"]["method"], Job.from_spec(r["job"]).method_label) for r in every_ok)
            raise ConfigError(f"method {given!r} {'is ambiguous' if named else 'not found'}; this folder has: {known}"
                              + (" (it is in results of an earlier suite here: --all compares every result)" if earlier else ""),
                              source=path)
        chosen = named[0]
    runs = BenchRuns(path, chosen, n_left_out=n_left_out, records=every, n_earlier_version=n_earlier_version,
                     unknown_tasks=unknown_tasks)
    jobs = [(r, job) for r in latest
            if (job := Job.from_spec(r["job"])).method_label == chosen and (not suite or r["key"] in suite)]
    several = len({job.experiment for _, job in jobs}) > 1  # (labels name the experiment then)
    specs: dict[str, dict[str, Any]] = {}
    for r, job in jobs:
        dataset = _dataset_unit(job.dataset, specs, runs.written_paths)
        options = _options_unit(job.task, job.options, dataset, r)
        key = canonical_json({"task": job.task, "experiment": job.experiment, "dataset": dataset,
                              "options": options, "seed": job.seed})
        runs.experiments[key] = {job.experiment}
        runs.selections.setdefault(key, _data_selection(job.task, options, r))
        if r.get("status") != "ok":
            runs.failed.add(key)
        elif key not in runs.values:
            runs.values[key] = dict(r.get("metrics") or {})
            runs.labels[key] = f"{job.experiment + ': ' if several else ''}{job.dataset_name}, seed {job.seed}"
            runs.alignments[key] = dict(((r.get("info") or {}).get("metric_alignment")) or {})
            runs.versions[key] = str(r.get("lidarkit_version") or "unknown")
            effective = (((r.get("info") or {}).get("odometry_metrics") or {}).get("effective")) or {}
            if effective.get("ground_truth_instant"):
                runs.instants[key] = str(effective["ground_truth_instant"])
            runs.higher_is_better.update(r.get("higher_is_better") or ())
            runs.speed_metrics.update(r.get("speed_metrics") or ())
    runs.failed -= set(runs.values)
    runs.not_run = _not_run_units(suite_jobs, {r["key"] for r in latest}, chosen, latest, specs)
    runs.not_run -= set(runs.values) | runs.failed
    return runs


def _not_run_units(suite_jobs: dict[str, dict[str, Any]], held: set[str], label: str, latest: list[dict[str, Any]],
                   specs: dict[str, dict[str, Any]]) -> set[str]:
    """The pair keys of the suite's jobs of method ``label`` with no readable result among ``held`` keys (not run yet,
    or a result file that cannot be read: the report's "not run yet"); their units were counted "only in B" when B had
    them. A job's frames are made indices with a result of the same task, dataset and options, as its own would be."""
    from lidarkit.bench.jobs import Job, canonical_json

    out = set()
    for key, spec in suite_jobs.items():
        if key in held:
            continue
        try:
            job = Job.from_spec(spec)
            if job.method_label != label:
                continue
            dataset = _dataset_unit(job.dataset, specs)
        except (TypeError, ValueError, AttributeError, LidarKitError):  # (a suite.json edited by hand: its report says so)
            continue
        alike = next((r for r in latest if r["job"].get("task") == job.task and r["job"].get("dataset") == job.dataset
                      and r["job"].get("options") == job.options), {})
        out.add(canonical_json({"task": job.task, "experiment": job.experiment, "dataset": dataset,
                                "options": _options_unit(job.task, job.options, dataset, alike), "seed": job.seed}))
    return out


def _as_label(method: str) -> str:
    """A method label as given (``kiss(deskew=false)``, ``vanilla(voxel_size_m=1.0)``) written as bench writes its labels
    (:func:`lidarkit.bench.jobs.method_label`: params sorted, values as their type prints them); as given when it does
    not read as ``name(key=value, ...)``."""
    from lidarkit.bench.jobs import method_label
    from lidarkit.params import parse_kv

    match = re.fullmatch(r"\s*([^\s()]+)\s*\((.*)\)\s*", method)
    if match is None or not match.group(2).strip():
        return method
    try:
        params = parse_kv(re.split(r",\s*(?=[^,=\s]+\s*=)", match.group(2).strip()), option="method")
    except LidarKitError:
        return method
    return method_label(match.group(1), params)


def _options_unit(task: str, options: dict[str, Any], dataset: dict[str, Any], record: dict[str, Any]) -> dict[str, Any]:
    """A job's task options as the data they select: the odometry ``frames`` as the dataset indices the run registered,
    written as one selection ("0:10" and "0:10:1" are one, and "all" and "0:30" over 30 sweeps: they read "runs with
    different task options"), as run folders are compared (:func:`_frames_of`); as written when the record does not
    say which indices those are. Whole floats count as ints (``init_noise_m: 1.0`` and ``1`` are one bench job)."""
    from lidarkit.bench.jobs import whole_floats_as_ints

    options = whole_floats_as_ints(options)
    if task != "odometry":
        return options
    frames = _selected_frames(options.get("frames"), dataset, record)
    return options if frames is None else {**options, "frames": _as_selection(frames)}


def _selected_frames(selection: Any, dataset: dict[str, Any], record: dict[str, Any]) -> np.ndarray | None:
    """The dataset indices an odometry job's ``frames`` selected: against the dataset's length when known (a simulated
    drive's ``n_frames``, or the run's own count for every frame), else a slice of non-negative bounds the run registered
    all of; None when the record leaves it open (a slice counting from the end of a KITTI sequence)."""
    from lidarkit.odometry.inputs import parse_frames

    run = (((record.get("info") or {}).get("config") or {}).get("run")) or {}
    n_run = run.get("n_frames", (record.get("metrics") or {}).get("n_frames"))
    n_run = int(n_run) if isinstance(n_run, (int, float)) and not isinstance(n_run, bool) and float(n_run).is_integer() else None
    settings = run.get("dataset_config") if isinstance(run.get("dataset_config"), dict) else {}
    lengths = (settings.get("n_frames"), dataset.get("n_frames") if dataset.get("kind") == "sim_lidar" else None)
    length = next((n for n in lengths if isinstance(n, int) and not isinstance(n, bool)), None)
    every = selection is None or selection == "all"
    if every and length is None:
        length = n_run
    try:
        if length is not None:
            indices = parse_frames(None if every else selection, length)
        elif isinstance(selection, list) or (isinstance(selection, str) and _bounded_slice(selection)):
            indices = parse_frames(selection, _bounded_slice(selection) or 1 + max(selection, default=-1))
        else:
            return None
    except (LidarKitError, TypeError, ValueError):
        return None
    return indices if len(indices) and (n_run is None or len(indices) == n_run) else None


def _bounded_slice(selection: Any) -> int:
    """The stop of a ``"START:STOP[:STEP]"`` selection whose bounds are non-negative (its indices do not depend on the
    dataset's length when the run registered them all), else 0."""
    if not isinstance(selection, str):
        return 0
    try:
        bounds = [int(part) if part.strip() else None for part in selection.split(":")]
    except ValueError:
        return 0
    if len(bounds) not in (2, 3) or bounds[1] is None or any(b is not None and b < 0 for b in bounds):
        return 0
    return bounds[1]


def _as_selection(frames: np.ndarray) -> str | list[int]:
    """Dataset indices written as the one selection that reads them: ``"0:10"``, ``"4:10:2"``, else the list."""
    steps = np.unique(np.diff(frames))
    if len(steps) > 1:
        return [int(i) for i in frames]
    step = int(steps[0]) if len(steps) else 1
    return f"{int(frames[0])}:{int(frames[-1]) + step}" + (f":{step}" if step != 1 else "")


def _dataset_unit(spec: dict[str, Any], done: dict[str, dict[str, Any]],
                  written_paths: dict[str, str] | None = None) -> dict[str, Any]:
    """A job's dataset spec as the data it names, so that two suites that write one dataset apart pair: its ``name`` left
    out (a label, as its readers take it); a simulated lidar's settings with their defaults written out
    (``range_noise_std_m: 0.0`` in one suite only read "runs over different data" with the same labels on both sides);
    a KITTI root given with ``sequence:`` as the sequence folder its reader opens (``path: kitti_odometry, sequence: "00"``
    is ``path: kitti_odometry/sequences/00``); whole floats as ints, as a bench job's key counts them (``n_frames: 30.0``
    is ``30``); a path through symbolic links as the folder it reaches (:func:`_linked_path`: the same KITTI data through a
    link read "runs over different data"). A spec this lidarkit cannot resolve (data not here, a simulator setting it
    does not know) is kept as written. ``done``: the specs resolved so far, by their text; ``written_paths``: filled
    with each path as it pairs -> as written (with a KITTI root's sequence folder), for messages."""
    from lidarkit.bench.jobs import canonical_json, whole_floats_as_ints

    written = whole_floats_as_ints({k: v for k, v in spec.items() if k != "name"})
    text = canonical_json(written)
    if text not in done:
        done[text] = written
        try:
            if written.get("kind") == "sim_lidar":
                from lidarkit.bench.datasets import dataset_options
                from lidarkit.odometry import config_dict
                from lidarkit.sim.lidar import make_config

                settings = config_dict(make_config(**dataset_options(written)))
                if "seed" not in written:  # (the job's seed seeds it: not the simulator's default seed 0)
                    settings.pop("seed", None)
                done[text] = {"kind": "sim_lidar", **settings}
            elif written.get("sequence") is not None and written.get("path") is not None:
                from lidarkit.bench.baseline import dataset_folder

                folder = dataset_folder(written)
                done[text] = {**{k: v for k, v in written.items() if k != "sequence"}, "path": str(folder)}
        except (LidarKitError, OSError):  # (compared as written)
            pass
        shown = done[text]
        done[text] = {k: _linked_path(v) for k, v in shown.items()}
        if written_paths is not None:
            for k, v in shown.items():
                if done[text][k] != v:
                    written_paths.setdefault(done[text][k], v)
    return done[text]


def _linked_path(value: Any) -> Any:
    """An absolute path of a dataset spec with the symbolic links of its folders followed, its own name kept (readers
    look beside it: a CARMEN log's ``.relations``, a KITTI sequence folder's ``poses/`` two folders up, which a linked
    file or sequence folder does not share with its target); any other value as it is."""
    if not isinstance(value, str) or not os.path.isabs(value):
        return value
    folder, name = os.path.split(os.path.normpath(value))
    return os.path.join(os.path.realpath(folder), name) if name else value


def _few(labels: list[str], n: int = 3) -> str:
    """The first ``n`` of ``labels`` and how many there are (every seed of a 10-seed suite was listed)."""
    text = "; ".join(labels[:n])
    return f"{text}; ... ({len(labels)} in all)" if len(labels) > n else text


def _same_ground_truth(a: OdometryRun, b: OdometryRun, names: tuple[str, str]) -> str:
    """"" when both runs were scored against the same ground truth; a note when they ran over the same dataset and
    frames but each against the truth at its own instant of the sweep (the run re-timed it: e.g. kiss deskews to the
    sweep end, small_gicp lands mid-sweep), the runs called by ``names`` (as the header: "kiss (A)", "kiss
    (B)" when both are kiss); EvaluationError otherwise."""
    ga, gb = a.ground_truth, b.ground_truth
    if len(ga) == len(gb) and np.allclose(ga.poses_se3, gb.poses_se3, atol=1e-6):
        return ""
    instants = [(run.metrics.get("effective") or {}).get("ground_truth_instant") for run in (a, b)]
    data = [_data_of(run) for run in (a, b)]
    differ = _how_data_differ(data[0], data[1]) if None not in data else None
    if len(ga) == len(gb) and None not in instants and instants[0] != instants[1] and differ == "":
        return (f"each run is scored against the ground truth at its own instant of the sweep ({names[0]}: {instants[0]}, "
                f"{names[1]}: {instants[1]}), over the same dataset and frames ({data[0].dataset}, frames "
                f"{_frames_text(data[0].frames)})")
    # a folder whose config.yaml is missing or unreadable (a run cut off before it was moved in, a folder made by hand)
    # does not say what it ran over: its truth at another instant read as "different data" without a word why
    unknown = [str(run.path) for run, said in zip((a, b), data) if said is None]
    why = (f"; {' and '.join(unknown)} {'has' if len(unknown) == 1 else 'have'} no readable config.yaml (a run cut off "
           "before it finished, or a folder made by hand): the dataset, frames and sweep instant it ran over are unknown"
           if unknown and len(ga) == len(gb) else "")
    if differ == "":  # (two pose files of one KITTI sequence read "with other values" and nothing more)
        differ = _reader_options_differ(a, b)
    if all(i in ("start", "mid", "end") for i in instants) and instants[0] != instants[1]:  # (said on the same-dataset
        # branch only: two exports of the same sweeps, kiss at the end against small_gicp mid-sweep, read "with other
        # values" and nothing more)
        differ = "; ".join(t for t in (differ, f"ground truth at the sweep {instants[0]} in A, {instants[1]} in B") if t)
    raise EvaluationError(
        f"runs over different data: {a.path} has {len(ga)} ground-truth poses, {b.path} has {len(gb)}"
        + (" with other values" if len(ga) == len(gb) else "") + (f" ({differ})" if differ else "") + why,
        source="compare",
    )


def _reader_options_differ(a: OdometryRun, b: OdometryRun) -> str:
    """The reader options two runs' config.yaml record differently (``run.dataset_options``: the poses file a KITTI
    reader read), as "their reader options differ in ...", or ''."""
    import yaml

    options = []
    for run in (a, b):
        try:
            recorded = yaml.safe_load((run.path / "config.yaml").read_text(encoding="utf-8"))["run"]["dataset_options"]
        except (OSError, yaml.YAMLError, KeyError, TypeError):
            return ""
        if not isinstance(recorded, dict):
            return ""
        options.append(recorded)
    return f"their reader options differ in {_fields_apart(*options)}" if options[0] != options[1] else ""


def _fields_apart(a: dict[str, Any], b: dict[str, Any]) -> str:
    """The first three fields two recorded mappings hold differently, with both values: ``speed (10 in A, 20 in B)``."""
    fields = sorted(k for k in a.keys() | b.keys() if a.get(k, ...) != b.get(k, ...))
    return ", ".join(f"{k} ({_field_value(a, k)} in A, {_field_value(b, k)} in B)" for k in fields[:3])


@dataclass(frozen=True)
class _RunData:
    """What a run folder ran over: the dataset as named, the reader's settings when recorded (a simulated drive's
    speed is not in its name), and the dataset frames registered."""

    dataset: str
    settings: dict[str, Any] | None
    frames: tuple[int, ...]


def _data_of(run: OdometryRun) -> _RunData | None:
    """The data a run folder ran over, from its config.yaml and timing.csv; None when they do not say."""
    import yaml

    try:
        cfg = yaml.safe_load((run.path / "config.yaml").read_text(encoding="utf-8"))
        given = cfg["run"]
        dataset = str(given["dataset"])
    except (OSError, yaml.YAMLError, KeyError, TypeError):
        return None
    settings = given.get("dataset_config")
    frames = _frames_of(run, given)
    if frames is None:
        return None
    return _RunData(dataset, settings if isinstance(settings, dict) else None, frames)


def _frames_of(run: OdometryRun, given: dict[str, Any]) -> tuple[int, ...] | None:
    """The dataset frames a run registered: timing.csv's frame column (one row per frame), else its config.yaml
    selection made indices ("all" and "0:160" over 160 frames are one selection: they were compared as text and refused
    as other data); None when neither says."""
    import csv

    n_poses = len(run.ground_truth)
    try:
        with open(run.path / "timing.csv", newline="", encoding="utf-8") as file:
            rows = csv.reader(file)
            column = next(rows).index("frame")
            frames = tuple(int(row[column]) for row in rows if row)
        if len(frames) == n_poses:
            return frames
    except (OSError, ValueError, StopIteration, IndexError):
        pass
    from lidarkit.odometry.inputs import parse_frames

    selection, n_run = given.get("frames"), given.get("n_frames")
    if isinstance(selection, list):  # (an index list is recorded as the indices)
        listed = tuple(i for i in selection if isinstance(i, int) and not isinstance(i, bool))
        return listed if len(listed) == len(selection) == n_poses else None
    settings = given.get("dataset_config") if isinstance(given.get("dataset_config"), dict) else {}
    # a slice with bounds of its own ("0:10") needs no dataset length (a KITTI run without timing.csv was called one
    # "with no readable config.yaml")
    length = settings.get("n_frames", n_run if selection == "all" else _bounded_slice(selection) or None)
    if not isinstance(length, int) or isinstance(length, bool):
        return None
    try:
        frames = tuple(int(i) for i in parse_frames(None if selection == "all" else selection, length))
    except (LidarKitError, TypeError, ValueError):
        return None
    return frames if len(frames) == n_poses else None


def _how_data_differ(a: _RunData, b: _RunData) -> str:
    """'' when two runs ran over the same data, else what differs (the dataset's name, a setting, the frames)."""
    if a.dataset != b.dataset:
        return f"datasets {a.dataset} and {b.dataset}"
    if a.settings is not None and b.settings is not None and a.settings != b.settings:
        return f"their dataset settings differ in {_fields_apart(a.settings, b.settings)}"
    if a.frames != b.frames:
        return f"they ran other frames ({_frames_text(a.frames)} in A, {_frames_text(b.frames)} in B)"
    return ""


def _frames_text(frames: tuple[int, ...]) -> str:
    """Frame indices as a selection reads: ``0:160``, ``4:10:2``, or how many and their range when not evenly spaced."""
    if len(frames) < 2:
        return ", ".join(str(i) for i in frames) or "none"
    steps = np.unique(np.diff(np.asarray(frames)))
    if len(steps) == 1:
        step = int(steps[0])
        # (the stop one past the last frame: frames[-1] + step named 2:14:3 for a run over 2:12:3 of a 12-sweep drive)
        return f"{frames[0]}:{frames[-1] + 1}" + (f":{step}" if step != 1 else "")
    return f"{len(frames)} frames from {frames[0]} to {frames[-1]}"


def _run_units(run: OdometryRun, metric: str) -> tuple[list[tuple[int, float]] | None, np.ndarray]:
    """Per-unit errors of a run folder, per KITTI segment (``segment_*``) or per frame pair (``rpe_*``):
    ``(each segment's (first frame, length), or None per frame, errors)``."""
    from lidarkit import eval as leval

    ref, est = run.ground_truth, run.estimate
    if len(ref) != len(est):
        raise DataError(f"{len(est)} estimated poses for {len(ref)} ground-truth poses", source=run.path)
    if metric.startswith("segment_"):
        drift = leval.kitti_drift(ref, est, allow_empty=True)
        keys = list(zip(drift.segment_first_frame.tolist(), drift.segment_length_m.tolist()))
        return keys, drift.segment_translation_pct if metric == "segment_translation_pct" else drift.segment_rotation_deg_per_100m
    relation = "translation" if metric == "rpe_translation_m" else "rotation_angle_deg"
    return None, np.asarray(leval.rpe(ref, est, delta=1, delta_unit="frames", relation=relation).errors, dtype=np.float64)


def _paired_segments(a: OdometryRun, b: OdometryRun, metric: str) -> tuple[np.ndarray, np.ndarray, str]:
    """The two runs' errors over the units both have, and a note when some were left out: segments pair by their first
    frame and length (two runs scored at other instants of the sweep measure the path on other truths: 200.0 m against
    199.5 m gave one run a 200 m segment the other lacks, and segments paired by position covered other frames)."""
    keys_a, va = _run_units(a, metric)
    keys_b, vb = _run_units(b, metric)
    if keys_a is None or keys_a == keys_b:
        if len(va) != len(vb):
            raise EvaluationError(f"{len(va)} frame pairs in one run, {len(vb)} in the other", source="compare")
        if not len(va):
            raise EvaluationError(f"no KITTI segment on either run's ground truth ({a.ground_truth.length_m:.1f} m; "
                                  "segments need more than 100 m): compare per frame (--metric rpe_translation_m)",
                                  source="compare")
        return va, vb, ""
    index_b = {key: k for k, key in enumerate(keys_b)}
    common = [(k, index_b[key]) for k, key in enumerate(keys_a) if key in index_b]
    if not common:
        raise EvaluationError("no KITTI segment (first frame, length) in common between the two runs' ground truths: "
                              "compare per frame (--metric rpe_translation_m)", source="compare")
    ia, ib = (np.array(i, dtype=np.int64) for i in zip(*common))
    left = len(keys_a) + len(keys_b) - 2 * len(common)
    note = (f"{left} KITTI segment(s) on only one run's ground truth left out (paired by first frame and length)"
            if left else "")
    return va[ia], vb[ib], note


def compare(
    a: str | os.PathLike | OdometryRun | BenchRuns,
    b: str | os.PathLike | OdometryRun | BenchRuns,
    *,
    metric: str | None = None,
    method_a: str | None = None,
    method_b: str | None = None,
    alpha: float = DEFAULT_ALPHA,
    noise: float = 0.0,
    noise_from: str | os.PathLike | None = None,
    seed: int = 0,
    every_result: bool = False,
    task: str | None = None,
    experiment: str | None = None,
) -> PairedComparison:
    """Paired Wilcoxon comparison of run ``a`` against run ``b`` (``diff = a - b``).

    ``noise_from``: a baseline folder whose band for the compared metric (the default one too) raises ``noise``: its
    widest over the jobs of the compared task (and methods, when it pinned them); ConfigError when it has none.

    Odometry run folders pair per KITTI segment (``metric="segment_translation_pct"``, the default when both
    paths share 2 segments of 100 m or more) or per frame (``rpe_translation_m``, the default otherwise). Bench results
    folders pair per (dataset, seed) on a job metric (default: the task's headline, as its report ranks: odometry's
    SE(3)-aligned APE); ``method_a`` / ``method_b`` pick a method when a folder holds several (the same folder may be
    given twice); only the jobs of each
    folder's ``suite.json`` are compared, as its report holds them (``every_result``: every result in the folder);
    ``task``: the units of that task (needed when several tasks of the folders report the metric). Units pair without
    their experiment's name (the experiments of a task over other datasets or seeds are pooled); ``experiment``: the
    units of that experiment, or of ``"A_NAME,B_NAME"`` each side's own (needed when several experiments of a side ran
    the same (dataset, seed): their units are not seeds of one).
    Runs over different data raise EvaluationError; two runs over the same dataset and frames, each scored against the
    ground truth at its own instant of the sweep, are compared with a ``note`` saying so.
    """
    alpha, noise = check_number(alpha, "alpha"), check_number(noise, "noise")  # (before any work)
    for name, given in (("metric", metric), ("task", task), ("experiment", experiment), ("method_a", method_a),
                        ("method_b", method_b)):
        if given is not None and not isinstance(given, str):  # (a list was a bare TypeError: unhashable type)
            raise ConfigError(f"must be a name (text) or None, got {type(given).__name__} {given!r}", source=name)
    from lidarkit.atomic import resolved_path
    from lidarkit.bench.results import path_argument
    from lidarkit.eval.ape_rpe import check_flags

    check_flags(every_result=every_result)  # ("no" was read as true)
    if noise_from is not None:  # (5 was a TypeError after both folders were loaded)
        path_argument(noise_from, "noise_from")
    for side, method, name in ((a, method_a, "method_a"), (b, method_b, "method_b")):  # (they were ignored without a word)
        if isinstance(side, (OdometryRun, BenchRuns)) and (method is not None or every_result):
            raise ConfigError(f"applies to paths only: a loaded {type(side).__name__} is compared as loaded (load_bench_runs "
                              "picks a method, and every result)", source=name if method is not None else "every_result")
    kinds = (_kind(a), _kind(b))  # (checked first: "2 methods in this folder; choose one" hid the real reason)
    if None not in kinds and kinds[0] is not kinds[1]:
        raise EvaluationError(_kinds_differ((a, b), kinds), source="compare")
    side_a = _load(a, method_a, every_result)
    same = (isinstance(side_a, BenchRuns) and isinstance(b, (str, os.PathLike))
            and resolved_path(b, output=False) == side_a.path.resolve())
    side_b = load_bench_runs(b, method_b, every_result, side_a.records) if same else _load(b, method_b, every_result)
    if type(side_a) is not type(side_b):
        raise EvaluationError(_kinds_differ((a, b), (type(side_a), type(side_b))), source="compare")
    name_a, name_b = side_a.name, side_b.name
    if name_a == name_b:
        name_a, name_b = f"{name_a} (A)", f"{name_b} (B)"
    if isinstance(side_a, OdometryRun):
        for given, what, name in ((task, "a task", "task"), (experiment, "an experiment", "experiment")):  # (it would be ignored)
            if given is not None:
                raise ConfigError(f"{what} applies to bench results folders only", source=name)
        if every_result:  # (--all was ignored without a word)
            raise ConfigError("every result (--all) applies to bench results folders only", source="all")
        note = _same_ground_truth(side_a, side_b, (name_a, name_b))
        given_metric = metric
        if metric is None:  # (segments on both truths: A's alone made the default depend on the order given)
            from lidarkit.eval import drift_segments_possible

            both = all(drift_segments_possible(side.ground_truth) for side in (side_a, side_b))
            metric = "segment_translation_pct" if both else "rpe_translation_m"
        if metric not in RUN_METRICS:
            raise ConfigError(f"unknown run metric {metric!r}; choose one of: {', '.join(RUN_METRICS)}", source="metric")
        if noise_from is not None:  # a baseline's bands are of whole-run metrics, not of one segment or frame
            raise ConfigError("a baseline's bands are of bench metrics (one value per run); two run folders are compared "
                              f"per {'segment' if metric.startswith('segment_') else 'frame'}: give that noise with --noise",
                              source="--noise-from")
        va, vb, left_out = _paired_segments(side_a, side_b, metric)
        if given_metric is None and len(va) < 2 and metric.startswith("segment_"):  # (paths just over 100 m: one segment)
            left_out = f"{len(va)} KITTI segment in common (a paired test needs 2): compared per frame (rpe_translation_m)"
            metric = "rpe_translation_m"
            va, vb, _ = _paired_segments(side_a, side_b, metric)
        note = "; ".join(n for n in (note, left_out) if n)
        pairing = "segment" if metric.startswith("segment_") else "frame"
        result = paired_test(va, vb, name_a=name_a, name_b=name_b, metric=metric, pairing=pairing,
                             alpha=alpha, noise=noise, seed=seed)
        return dataclasses.replace(result, note=note) if note else result
    side_a, side_b = _by_experiment(side_a, side_b, experiment)
    held = [sorted({_task_of(k) for k in side.values}) for side in (side_a, side_b)]
    if task is not None:  # (first: the default metric was another task's, then refused as unknown; the units of other
        # tasks were counted "only in A")
        if task not in held[0] or task not in held[1]:
            holds = (f"these results hold: {', '.join(held[0])}" if held[0] == held[1] else
                     f"{side_a.path} ({side_a.name}) holds {', '.join(held[0])}, {side_b.path} ({side_b.name}) holds "
                     f"{', '.join(held[1])}")
            raise ConfigError(f"no unit of task {task!r} in both; {holds}", source="task")
        side_a, side_b = _of_tasks(side_a, {task}), _of_tasks(side_b, {task})
    keys_a, keys_b = set(side_a.values), set(side_b.values)
    common = sorted(keys_a & keys_b)
    if not common:
        if not set(held[0]) & set(held[1]):  # (it read "runs over different data", listing the same datasets and seeds)
            raise EvaluationError(f"{side_a.path} ({side_a.name}) holds task(s) {', '.join(held[0])}, {side_b.path} "
                                  f"({side_b.name}) holds {', '.join(held[1])}: compare units of one task", source="compare")
        _other_options(side_a, side_b)
        raise EvaluationError(
            f"runs over different data: no (dataset, seed) in common between {side_a.path} ({side_a.name}: "
            f"{_few(sorted(set(side_a.labels.values())))}) and {side_b.path} ({side_b.name}: "
            f"{_few(sorted(set(side_b.labels.values())))})" + _other_datasets(side_a, side_b),
            source="compare",
        )
    def has(k: str, name: str) -> bool:
        return _usable(side_a.values[k].get(name)) and _usable(side_b.values[k].get(name))

    if metric is None:
        metric = _default_metric(common, side_a, side_b)
    if not any(has(k, metric) for k in common):  # in no unit: a misspelt metric, not results that lack it
        present = set.union(*(set(side_a.values[k]) & set(side_b.values[k]) for k in common))
        if metric in present:  # (it read "unknown metric 'iterations'; these results have: ..., iterations, ...")
            silent = [side for side in (side_a, side_b) if not any(_usable(side.values[k].get(metric)) for k in common)]
            # (values present but NaN or infinite read "(null) ... the method reports none")
            stated = any(side.values[k].get(metric) is not None for side in silent for k in common)
            what = "no finite value (null, NaN or infinite)" if stated else "no value (null)"
            raise EvaluationError(f"metric {metric!r} has {what} in any result of {' and '.join(s.name for s in silent)}"
                                  + ("" if stated else ": the method reports none"), source="compare")
        held_apart = _why_no_unit_holds(metric, side_a, side_b, common)
        if held_apart:  # (a declared metric no run reached, or one only A's extra task reports, read "unknown metric")
            raise EvaluationError(f"metric {metric!r}: {held_apart}", source="compare")
        raise ConfigError(f"unknown metric {metric!r}; these results have: {', '.join(sorted(present))}", source="metric")
    # units of a task that never reports the metric (an icp_pair experiment beside an odometry one) are another
    # experiment: left out, said; a unit of a task that reports it elsewhere lacks it: an error
    tasks_with = {_task_of(k) for k in common if has(k, metric)}
    if len(tasks_with) > 1:  # (pooled into one test: icp_pair pairs/s and odometry frames/s as 6 units of "hz")
        raise ConfigError(f"metric {metric!r} is reported by tasks {', '.join(sorted(tasks_with))} of these results, each its own "
                          "experiment: --task picks one", source="metric")
    compared_task = next(iter(tasks_with))
    _one_experiment(side_a, side_b, [k for k in common if _task_of(k) in tasks_with], compared_task)
    other_tasks = _other_tasks_note(side_a, side_b, tasks_with, metric)
    side_a, side_b = _of_tasks(side_a, tasks_with), _of_tasks(side_b, tasks_with)
    keys_a, keys_b = set(side_a.values), set(side_b.values)
    common = [k for k in common if _task_of(k) in tasks_with]
    missing = [k for k in common if not has(k, metric)]
    # units without the metric on a side are left out and named, as the report leaves out such seeds (one null APE of 7
    # seeds refused the comparison the report made); fewer than 2 left: the error says why
    without_metric = _without_metric_note(missing, common, metric, (side_a, side_b), (name_a, name_b), has) if missing else ""
    common = [k for k in common if has(k, metric)]
    _same_alignment(side_a, side_b, common, metric)
    from lidarkit.bench.tasks import higher_is_better  # (as the task that wrote the results declares it)

    va = np.array([side_a.values[k][metric] for k in common], dtype=np.float64)
    vb = np.array([side_b.values[k][metric] for k in common], dtype=np.float64)
    varies = _seeds_vary(common, side_a, side_b, metric)
    one_each = len(varies) > 1 and len(varies) == len(common)  # one seed per dataset: the units are datasets
    pairing, collapsed = "dataset" if one_each else "seed", _one_unit_per_dataset(common, va, vb, varies)
    if collapsed is not None:  # the seeds change nothing within a dataset: its seeds are one measurement
        va, vb, pairing = collapsed
    notes = [without_metric] if without_metric else []
    if pairing == "unit":  # (a fixed dataset beside seeded ones)
        notes.append("the seeds of a dataset that gives each side one value whatever the seed count as one unit")
    if other_tasks:
        notes.append(f"{other_tasks}: {len(common)} paired")
    failed_a, failed_b = len(keys_b & side_a.failed), len(keys_a & side_b.failed)  # (read "only in A" when B failed there)
    # (a job of A's suite not run yet, or whose result file cannot be read, read as a unit "only in B")
    only_a = len(keys_a - keys_b) - failed_b - len(keys_a & side_b.not_run)
    only_b = len(keys_b - keys_a) - failed_a - len(keys_b & side_a.not_run)
    if only_a or only_b:  # the pairs are those both have: say what was left out
        notes.append(f"{only_a} (dataset, seed) units only in A and {only_b} only in B are left out: {len(common)} paired")
    for n, side in ((failed_a, "A"), (failed_b, "B")):
        if n:
            notes.append(f"{n} (dataset, seed) unit(s) where {side}'s job failed are left out (lidarkit report lists why)")
    for n, side in ((len(side_a.not_run), "A"), (len(side_b.not_run), "B")):  # (worded as the report words them)
        if n:
            notes.append(f"{n} (dataset, seed) unit(s) of {side}'s suite not run yet or unreadable "
                         "(`lidarkit bench` resumes them)")
    notes += _mixed_versions(side_a, side_b, common)
    instants = [sorted({side.instants[k] for k in common if k in side.instants}) for side in (side_a, side_b)]
    if all(instants) and instants[0] != instants[1]:  # (said for run folders, not for bench pairs: kiss end, deskew=False mid)
        notes.append(f"each side is scored against the ground truth at its own instant of the sweep ({name_a}: "
                     f"{' / '.join(instants[0])}, {name_b}: {' / '.join(instants[1])})")
    for folder, side in {side_a.path: side_a, side_b.path: side_b}.items():  # (worded as the report words them)
        if side.n_earlier_version:
            notes.append(f"{side.n_earlier_version} result(s) in {folder} of these jobs from an earlier lidarkit version left out")
        if side.n_left_out - side.n_earlier_version:
            notes.append(f"{side.n_left_out - side.n_earlier_version} result(s) in {folder} of jobs not in its suite.json "
                         "(an earlier suite) left out (--all: every result)")
    try:
        result = paired_test(va, vb, name_a=name_a, name_b=name_b, metric=metric, pairing=pairing,
                             lower_is_better=not (metric in side_a.higher_is_better | side_b.higher_is_better or higher_is_better(metric)),
                             alpha=alpha, seed=seed,
                             noise=_with_measured_noise(noise, noise_from, metric, compared_task, (side_a.name, side_b.name)),
                             repeated=False if pairing == "seed" and any(varies.values()) else None)
    except EvaluationError as err:  # too few pairs: the notes say why ("got 1" of a suite of 8 seeds, 7 of B's jobs failed)
        if notes and va.size < 2:
            raise EvaluationError(f"{err.reason}; {'; '.join(notes)}", source=err.source) from None
        raise
    label = _metric_label(compared_task, metric, side_a, side_b, common)
    return dataclasses.replace(result, note="; ".join(notes), metric_label=label)


def _kinds_differ(given: tuple[Any, Any], kinds: tuple[type, type]) -> str:
    """Which of the two sides is an odometry run and which bench results (it read "compare an odometry run folder with
    another run folder, a bench folder with a bench folder", naming neither)."""
    what = {OdometryRun: "an odometry run folder", BenchRuns: "a bench results folder"}
    sides = [f"{side} ({what[kind]})" if isinstance(side, (str, os.PathLike)) else f"a loaded {kind.__name__}"
             for side, kind in zip(given, kinds)]
    return (f"A is {sides[0]}, B is {sides[1]}: compare an odometry run folder with another run folder, bench results "
            "with bench results")


def _without_metric_note(missing: list[str], common: list[str], metric: str, sides: tuple[BenchRuns, BenchRuns],
                         names: tuple[str, str], has: Callable[[str, str], bool]) -> str:
    """The note on the ``missing`` units of ``common`` left out for a side's null, NaN or infinite ``metric``: how many,
    which side (by its ``names``), which units, and why KITTI drift may be missing or which metric every unit holds."""
    lacking = [name for side, name in zip(sides, names) if not all(_usable(side.values[k].get(metric)) for k in missing)]
    nan = any((v := side.values[k].get(metric)) is not None and not _usable(v) for side in sides for k in missing)
    what = "no finite value (null, NaN or infinite)" if nan else "no value (null)"
    hints = ["KITTI drift needs 100 m of path"] if metric.startswith("drift_") else []
    if metric != "ape_rmse_m" and all(has(k, "ape_rmse_m") for k in common):
        hints.append("--metric ape_rmse_m compares every unit")
    verb = "has" if len(lacking) == 1 else "have"
    return (f"{len(missing)} of {len(common)} (dataset, seed) unit(s) left out: {' and '.join(lacking)} {verb} {what} of "
            f"{metric} there ({_few([sides[0].labels[k] for k in missing])})" + (f": {', '.join(hints)}" if hints else ""))


def _default_metric(keys: list[str], side_a: BenchRuns, side_b: BenchRuns) -> str:
    """The metric compared when none is given: the task's headline, its first declared accuracy metric the units
    report, which the report's Summary ranks by (odometry: the SE(3)-aligned APE; it compared KITTI drift, or the
    unaligned APE, where the report ranked by another); the first of DEFAULT_BENCH_METRICS for a task that declares none
    of them. Of several tasks, the one whose headline comes first in DEFAULT_BENCH_METRICS."""
    present: dict[str, set[str]] = {}
    for key in keys:
        present.setdefault(_task_of(key), set()).update(set(side_a.values[key]) & set(side_b.values[key]))
    headlines = []
    for task, names in present.items():
        declared = [m.name for m in _declared_metrics(task, side_a, side_b) if m.kind == "accuracy"]
        headline = next((m for m in [*declared, *DEFAULT_BENCH_METRICS] if m in names), None)
        if headline is not None:
            headlines.append(headline)
    if not headlines:
        named = sorted(set().union(*present.values()))
        unknown = {**side_a.unknown_tasks, **side_b.unknown_tasks}
        why = "; ".join(f"task {t}: {unknown[t]}" for t in sorted(present) if t in unknown)
        raise EvaluationError(f"no default metric in these results{f' ({why})' if why else ''}; pass one of: "
                              f"{', '.join(named)}", source="compare")
    rank = {m: i for i, m in enumerate(DEFAULT_BENCH_METRICS)}
    return min(headlines, key=lambda m: (rank.get(m, len(rank)), m))


def _why_no_unit_holds(metric: str, side_a: BenchRuns, side_b: BenchRuns, common: list[str]) -> str:
    """Why no paired unit holds ``metric`` on both sides when it is no misspelt name: one side reports it (in a task the
    other did not run), or a task of these results declares it but no result holds it (KITTI drift on a path under
    100 m); '' otherwise."""
    sides = (("A", side_a), ("B", side_b))
    reported = {name: sorted({_task_of(k) for k, v in side.values.items() if _usable(v.get(metric))}) for name, side in sides}
    if bool(reported["A"]) != bool(reported["B"]):
        (one, side), (other, other_side) = sides if reported["A"] else sides[::-1]
        ran = {_task_of(k) for k in other_side.values}
        paired = {_task_of(k) for k in common}
        tasks = reported[one]
        if not set(tasks) & ran:
            why = f"task {', '.join(tasks)}, which {other} did not run"
        elif set(tasks) & paired:
            why = f"{other}'s results of task {', '.join(sorted(set(tasks) & paired))} hold no value of it"
        else:
            why = f"task {', '.join(tasks)}, which {other} ran over no (dataset, seed) of {one}'s"
        return f"only {one} ({side.name}) reports it ({why})"
    if reported["A"]:
        return (f"A and B report it (task {', '.join(sorted(set(reported['A']) | set(reported['B'])))}) over no (dataset, "
                "seed) in common")
    held = sorted({_task_of(k) for _, side in sides for k in side.values})
    declared = [task for task in held if any(m.name == metric for m in _declared_metrics(task, side_a, side_b))]
    if not declared:
        return ""
    return (f"declared by {', '.join(declared)} but in no result"
            + (" (KITTI drift needs 100 m of path)" if metric.startswith("drift_") else ""))


def _metric_label(task: str, metric: str, side_a: BenchRuns, side_b: BenchRuns, keys: list[str]) -> str:
    """``metric``'s label as the report heads its column, without the unit and naming the alignment the results state
    ("APE RMSE (SE(3)-aligned)"); '' when the task declares none beyond the name (and its unit)."""
    from lidarkit.bench.report import MetricInfo, label_alignment

    declared = next((m for m in _declared_metrics(task, side_a, side_b) if m.name == metric), None)
    if declared is None or declared.label == metric:
        return ""
    records = [{"info": {"metric_alignment": side.alignments.get(k) or {}}} for side in (side_a, side_b) for k in keys]
    label = label_alignment(MetricInfo(metric, declared.label), records).label
    head, sep, _ = label.rpartition(" [")
    label = head if sep and label.endswith("]") else label
    return "" if label == metric else label  # ("score [pts]": "score [score]" named it twice)


def _declared_metrics(task: str, side_a: BenchRuns, side_b: BenchRuns) -> list[MetricInfo]:
    """The metrics ``task`` declares, in its order: its module's, else as its results record them (``metric_labels``:
    a plugin not installed here, whose report heads it by its first declared accuracy metric while compare tested
    another and named it by its bare name)."""
    from lidarkit.bench.report import recorded_metrics, task_meta

    declared = task_meta(task)[0]
    if declared:
        return declared
    records = side_a.records if side_a.records is side_b.records else [*side_a.records, *side_b.records]
    return recorded_metrics([r for r in records if r.get("status") == "ok" and r["job"]["task"] == task])


def _of_tasks(side: BenchRuns, tasks: set[str]) -> BenchRuns:
    """``side`` with the units (and failed and not run units) of ``tasks`` only."""
    return dataclasses.replace(side, values={k: v for k, v in side.values.items() if _task_of(k) in tasks},
                               failed={k for k in side.failed if _task_of(k) in tasks},
                               not_run={k for k in side.not_run if _task_of(k) in tasks})


def _other_tasks_note(side_a: BenchRuns, side_b: BenchRuns, compared: set[str], metric: str) -> str:
    """``"N (dataset, seed) units of icp_pair (no ape_se3_rmse_m) left out"`` for the units (of either side, paired or
    not) of tasks other than the ``compared`` one, else '' (two folders counted them "only in A")."""
    units: dict[str, set[str]] = {}
    for side in (side_a, side_b):
        for key in side.values:
            if _task_of(key) not in compared:
                units.setdefault(_task_of(key), set()).add(key)
    groups: dict[str, list[str]] = {}
    for task, keys in sorted(units.items()):
        in_a, in_b = any(k in side_a.values for k in keys), any(k in side_b.values for k in keys)
        reports = any(_usable(side.values[k].get(metric)) for side in (side_a, side_b) for k in keys if k in side.values)
        why = f"no {metric}" if not reports else "only in A" if not in_b else "only in B" if not in_a else "none paired"
        groups.setdefault(why, []).append(task)
    return ", ".join(f"{sum(len(units[t]) for t in tasks)} (dataset, seed) units of {', '.join(tasks)} ({why}) left out"
                     for why, tasks in groups.items())


#: metrics that vary from run to run on the same data (times, rates): they say nothing about whether the seeds ran
#: other data
_TIMING_METRIC = re.compile(r"(_s|hz|fps)$|time|speed")


def _usable(value: Any) -> bool:
    """A finite number: a NaN or an infinity in a job result is a missing value (a NaN read "1 non-finite value(s)
    among 8", naming neither the metric nor the unit)."""
    return isinstance(value, (int, float)) and math.isfinite(value)


def _other_options(side_a: BenchRuns, side_b: BenchRuns) -> None:
    """EvaluationError naming each side's task options when the units would pair but for them (``mse_start: 10``, the
    pf task's default, written in one suite only read "runs over different data" with the same labels on both sides)."""
    import yaml

    def by_unit(side: BenchRuns) -> dict[str, dict[str, Any]]:
        return {json.dumps({k: v for k, v in json.loads(key).items() if k != "options"}, sort_keys=True):
                json.loads(key).get("options") or {} for key in side.values}

    units_a, units_b = by_unit(side_a), by_unit(side_b)
    both = units_a.keys() & units_b.keys()
    if both:
        shown = [" / ".join(sorted({yaml.safe_dump(units[k], default_flow_style=True).strip() for k in both}))
                 for units in (units_a, units_b)]
        raise EvaluationError(f"runs with different task options over the same (dataset, seed) units: {shown[0]} in "
                              f"{side_a.path} ({side_a.name}), {shown[1]} in {side_b.path} ({side_b.name}): units pair only when "
                              "their options are written alike (an option set to its default value is not one left out)",
                              source="compare")


def _other_datasets(side_a: BenchRuns, side_b: BenchRuns) -> str:
    """``": their dataset specs differ in FIELD (X in A, Y in B), ..."`` when the units would pair but for their
    datasets (the error showed the same labels on both sides: "st, seed 0; st, seed 1"), else ''."""
    def by_unit(side: BenchRuns) -> dict[str, list[dict[str, Any]]]:
        out: dict[str, list[dict[str, Any]]] = {}
        for key in side.values:
            unit = json.loads(key)
            out.setdefault(json.dumps({k: v for k, v in unit.items() if k != "dataset"}, sort_keys=True), []).append(unit["dataset"])
        return out

    units_a, units_b = by_unit(side_a), by_unit(side_b)
    shown: list[str] = []
    for rest in sorted(units_a.keys() & units_b.keys()):
        for spec_a in units_a[rest]:
            diffs = [[k for k in sorted(spec_a.keys() | spec_b.keys()) if spec_a.get(k, ...) != spec_b.get(k, ...)]
                     for spec_b in units_b[rest]]
            fields, spec_b = min(zip(diffs, units_b[rest]), key=lambda d: len(d[0]))
            # (paths as each suite wrote them: they pair with their links followed)
            shown_a, shown_b = ({k: side.written_paths.get(v, v) if isinstance(v, str) else v for k, v in spec.items()}
                                for side, spec in ((side_a, spec_a), (side_b, spec_b)))
            text = ", ".join(f"{k} ({_field_value(shown_a, k)} in A, {_field_value(shown_b, k)} in B)" for k in fields)
            if text not in shown:
                shown.append(text)
    return f": their dataset specs differ in {'; '.join(shown[:3])}" if shown else ""


def _field_value(spec: dict[str, Any], name: str) -> str:
    return json.dumps(spec[name]) if name in spec else "not written"


def _dataset_of(key: str) -> str:
    unit = json.loads(key)
    unit.pop("seed", None)
    return json.dumps(unit, sort_keys=True)


def _seeds_vary(keys: list[str], side_a: BenchRuns, side_b: BenchRuns, metric: str) -> dict[str, bool]:
    """Per dataset (a unit key without its seed): whether another of its accuracy metrics changes with the seed on
    either side, i.e. the seeds ran other data or other draws. A count that is 0 for one method and 7 for the other on
    each of 6 simulated drives is flat on both sides, and was taken for one measurement repeated (no test)."""
    groups: dict[str, list[str]] = {}
    for key in keys:
        groups.setdefault(_dataset_of(key), []).append(key)
    out = {}
    for dataset, group in groups.items():
        varies = False
        for side in (side_a, side_b):
            names = set.intersection(*(set(side.values[k]) for k in group)) - {metric}
            # (a speed its task declares, ``latency_ms``, made 6 seeds of one deterministic measurement a p = 0.031
            # winner; the name pattern catches the timings of results that do not record their task's speeds)
            speeds = side_a.speed_metrics | side_b.speed_metrics
            for name in sorted(n for n in names if n not in speeds and not _TIMING_METRIC.search(n)):
                values = [side.values[k][name] for k in group]
                if all(isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v) for v in values):
                    v = np.asarray(values, dtype=np.float64)
                    varies = varies or len(v) > 1 and not spread_is_round_off(v)
        out[dataset] = varies
    return out


def _one_unit_per_dataset(keys: list[str], va: np.ndarray, vb: np.ndarray,
                          varies: dict[str, bool] | None = None) -> tuple[np.ndarray, np.ndarray, str] | None:
    """``(values a, values b, pairing)`` with one unit per dataset whose seeds give both sides one value whatever the seed
    (a simulated dataset the task does not seed: 5 seeds of 2 datasets were tested as 10 independent units, p = 0.002,
    from 2 measurements), the seeds of the others kept (one fixed dataset beside a seeded one counted its one value 6
    times); pairing ``"dataset"`` when every dataset collapsed, else ``"unit"``. None when there are not several
    datasets or none collapses (one dataset repeated is :func:`paired_test`'s "one measurement")."""
    groups: dict[str, list[int]] = {}
    for i, key in enumerate(keys):
        groups.setdefault(_dataset_of(key), []).append(i)
    if len(groups) < 2 or all(len(g) == 1 for g in groups.values()):
        return None
    # (each side's seeds of a dataset at their own scale: a drive that diverged on another dataset widened the tolerance
    # of all, and seeds that differ became one measurement)
    fixed = [len(g) > 1 and spread_is_round_off(va[g]) and spread_is_round_off(vb[g]) and not (varies or {}).get(d, False)
             for d, g in groups.items()]
    if not any(fixed):
        return None
    keep = sorted(i for g, one in zip(groups.values(), fixed) for i in (g[:1] if one else g))
    return va[keep], vb[keep], "dataset" if all(fixed) else "unit"


def _same_alignment(side_a: BenchRuns, side_b: BenchRuns, keys: list[str], metric: str) -> None:
    """ConfigError when the two sides' jobs state different alignments of the metric (a Sim(3)-aligned APE against an
    SE(3)-aligned one was ranked without a word; the report never ranks across them)."""
    stated = [sorted({str(a) for k in keys if (a := side.alignments.get(k, {}).get(metric))}) for side in (side_a, side_b)]
    if all(stated) and stated[0] != stated[1]:
        raise ConfigError(f"{side_a.name} states {metric} {' / '.join(stated[0])}, {side_b.name} {' / '.join(stated[1])}: "
                          "values under different alignments are not compared", source="metric")


def _mixed_versions(side_a: BenchRuns, side_b: BenchRuns, keys: list[str]) -> list[str]:
    """A note when a side's paired results come from several lidarkit versions (--all over a folder reused after a
    source change paired seeds 0-4 of the new code with seed 5 of the old, without a word). It counts results, not
    units: the seeds of a dataset that collapse to one unit may come from several versions ("the 12 pairs" read beside
    "7 paired units")."""
    mixes = {}
    for name, side in (("A", side_a), ("B", side_b)):
        counts = Counter(side.versions.get(k, "unknown") for k in keys)
        if len(counts) > 1:
            mixes[name] = ", ".join(f"{n} of {v}" for v, n in counts.most_common())
    if not mixes:
        return []
    text = "; ".join(f"{name}: {mix}" for name, mix in mixes.items())
    if len(mixes) == 2 and mixes["A"] == mixes["B"]:
        text = f"A: {mixes['A']}; B: the same"
    return [f"the {len(keys)} paired results mix lidarkit versions ({text})"]


def _task_of(unit_key: str) -> str:
    """The bench task of a (task, experiment, dataset, options, seed) unit key."""
    return str(json.loads(unit_key).get("task", ""))


def _experiments(side: BenchRuns) -> dict[str, set[str]]:
    """Task -> the experiments ``side``'s units (failed ones too) are of."""
    out: dict[str, set[str]] = {}
    for key in set(side.values) | side.failed:
        unit = json.loads(key)
        out.setdefault(str(unit.get("task", "")), set()).add(str(unit.get("experiment", "")))
    return out


def _experiment_per_side(side_a: BenchRuns, side_b: BenchRuns, experiment: str | None) -> tuple[str | None, str | None]:
    """The experiment ``experiment`` names on each side: one name both sides have, or ``A_NAME,B_NAME`` (two suites
    that name one experiment apart); ConfigError naming a side without it and the experiments it has."""
    if experiment is None:
        return None, None
    held = [set().union(*_experiments(side).values()) for side in (side_a, side_b)]
    parts = experiment.split(",")
    names = (experiment, experiment)
    if len(parts) == 2 and not any(experiment in h for h in held):
        names = (parts[0].strip(), parts[1].strip())
    for side, name, own, other in ((side_a, names[0], held[0], held[1]), (side_b, names[1], held[1], held[0])):
        if name not in own:
            hint = ""
            if names[0] == names[1] and name in other and len(own) == 1:  # (one suite calls "recorded" what another calls "pf_rec")
                pair = (name, *own) if side is side_b else (*own, name)
                hint = f" (--experiment {pair[0]},{pair[1]} names each side's own)"
            raise ConfigError(f"no result of {side.name} in experiment {name!r}; it has results in: "
                              f"{', '.join(sorted(own))}{hint}", source=side.path)
    return names


def _by_experiment(side_a: BenchRuns, side_b: BenchRuns, experiment: str | None) -> tuple[BenchRuns, BenchRuns]:
    """Both sides keyed for pairing without the experiment's name (two suites name an experiment apart; one suite may run
    a task in one experiment per dataset): the units of ``experiment`` only, when given (see
    :func:`_experiment_per_side`). A unit two experiments of a side both ran keeps the result of the first and the names
    of both (:func:`_one_experiment` refuses it when it is compared)."""
    from lidarkit.bench.jobs import canonical_json

    chosen = _experiment_per_side(side_a, side_b, experiment)

    def rekeyed(side: BenchRuns, name: str | None) -> BenchRuns:
        new, experiments = {}, {}
        for key in sorted(set(side.values) | side.failed | side.not_run):
            unit = json.loads(key)
            if name is None or unit.get("experiment") == name:
                new[key] = canonical_json({k: v for k, v in unit.items() if k != "experiment"})
                if key in side.values:
                    experiments.setdefault(new[key], set()).update(side.experiments.get(key) or {str(unit.get("experiment", ""))})

        def kept(by_key: dict[str, Any]) -> dict[str, Any]:
            out: dict[str, Any] = {}
            for k in sorted(by_key):
                if k in new and k in side.values:
                    out.setdefault(new[k], by_key[k])
            return out

        values = kept(side.values)
        return dataclasses.replace(side, values=values, labels=kept(side.labels), versions=kept(side.versions),
                                   alignments=kept(side.alignments), instants=kept(side.instants),
                                   selections=kept(side.selections),
                                   failed={new[k] for k in side.failed if k in new} - set(values), experiments=experiments,
                                   not_run={new[k] for k in side.not_run if k in new} - set(values))

    return rekeyed(side_a, chosen[0]), rekeyed(side_b, chosen[1])


def _one_experiment(side_a: BenchRuns, side_b: BenchRuns, keys: list[str], task: str) -> None:
    """ConfigError when the paired units ``keys`` of ``task`` hold one (dataset, seed) and the same part of it (frames,
    pairs: :data:`DATA_SELECTING_OPTIONS`) of a side from several of its experiments: two pf experiments differing in
    ``mse_start`` only were paired as 6 seeds of one (p = 0.031, a winner), over 3 seeds giving one APE each; the error
    names the options they differ in. Experiments over other datasets, seeds, frames or pairs are pooled (two odometry
    experiments over frames 0:5 and 5:10 of one sequence were refused as "the same (dataset, seed) units")."""
    for side in (side_a, side_b):
        by_data: dict[str, list[str]] = {}  # (task, dataset, seed, data selected) -> its units (of other options)
        for key in keys:
            unit = {k: v for k, v in json.loads(key).items() if k != "options"}
            selected = side.selections.get(key) or _data_selection(task, json.loads(key).get("options") or {}, {})
            by_data.setdefault(json.dumps({**unit, "selected": selected}, sort_keys=True), []).append(key)
        groups = [group for group in by_data.values() if len(group) > 1 or len(side.experiments.get(group[0], ())) > 1]
        names = sorted(set().union(*(side.experiments.get(k, set()) for group in groups for k in group)))
        if len(names) > 1:
            selecting = DATA_SELECTING_OPTIONS.get(task, ())
            apart = sorted({item for group in groups for item in _options_apart(side, group)})
            raise ConfigError(f"{side.name} has results in {len(names)} experiments of task {task} ({', '.join(names)}) over "
                              f"the same (dataset, seed) units{f' and {selecting[0]}' if selecting else ''}, each its own "
                              f"(task options: {'; '.join(apart[:3])}{'; ...' if len(apart) > 3 else ''}): --experiment "
                              "picks one", source=side.path)


def _data_selection(task: str, options: dict[str, Any], record: dict[str, Any]) -> str:
    """The part of its dataset a unit ran, as text: icp_pair's scan pairs as its record lists them (``pairs: [[0, 1]]``
    and the default first pair are one), else the task's data-selecting options as the unit key writes them (odometry's
    frames made dataset indices by :func:`_options_unit`); '' for a task that selects no part."""
    from lidarkit.bench.jobs import canonical_json

    names = DATA_SELECTING_OPTIONS.get(task, ())
    if not names:
        return ""
    rows = (record.get("info") or {}).get("pairs") if task == "icp_pair" else None
    if isinstance(rows, list) and rows and all(isinstance(row, dict) for row in rows):
        ran = [[row.get("target"), row.get("source")] for row in rows]
        if all(isinstance(i, int) and not isinstance(i, bool) for pair in ran for i in pair):
            return canonical_json({"pairs": ran})
    return canonical_json({name: options.get(name) for name in names})


def _options_apart(side: BenchRuns, keys: list[str]) -> list[str]:
    """How the experiments of ``side`` that ran the units ``keys`` (one dataset, seed and part of it) differ: each task
    option they write differently, ``mse_start 10 in early, 100 in late``, or ``early and late alike``."""
    by_experiment: dict[str, dict[str, Any]] = {}
    for key in keys:
        for name in side.experiments.get(key, ()):
            by_experiment[name] = json.loads(key).get("options") or {}
    by_experiment = dict(sorted(by_experiment.items()))
    fields = sorted({k for options in by_experiment.values() for k in options
                     if len({_field_value(o, k) for o in by_experiment.values()}) > 1})
    if not fields:
        return [f"{' and '.join(by_experiment)} alike"]
    return [f"{k} {', '.join(f'{_field_value(o, k)} in {name}' for name, o in by_experiment.items())}" for k in fields]


def _with_measured_noise(noise: float, noise_from: str | os.PathLike | None, metric: str, task: str,
                         methods: tuple[str, ...]) -> float:
    """``noise``, or the baseline's band for the compared task, metric (and methods, when it pinned them) if larger."""
    if noise_from is None:
        return noise
    from lidarkit.bench.baseline import measured_noise

    return max(noise, measured_noise(noise_from, metric, task, methods))


def _run_label(path: Path, method: str) -> str:
    """``method(p=v, ...)`` with the settings config.yaml records away from the variant's defaults, as bench labels its
    rows (two kiss runs, one without deskew, read "kiss (A)" vs "kiss (B)"); ``method`` when they cannot be read."""
    try:
        import yaml

        from lidarkit.bench.jobs import method_label
        from lidarkit.registration import get_icp_class

        given = (yaml.safe_load((path / "config.yaml").read_text(encoding="utf-8")) or {}).get("method_config") or {}
        defaults = get_icp_class(method).Config().model_dump()
        changed = {k: v for k, v in given.items() if k in defaults and v != defaults[k]}
        return method_label(method, changed)
    except Exception:  # noqa: BLE001 - a label only: an older folder, a plugin not installed, a hand-written config
        return method


def _other_run_kind(path: Path) -> str | None:
    """``"particle-filter"`` / ``"visual odometry"`` / ``"icp"`` for a run folder of ``lidarkit pf`` / ``lidarkit vo`` /
    ``lidarkit icp`` (:func:`lidarkit.run_files.run_kind`), else None."""
    from lidarkit.run_files import run_kind

    kind = run_kind(path)
    return None if kind == "odometry" else kind


def _not_an_odometry_run(path: Path) -> str:
    """Why the folder ``path`` is neither a run folder compare pairs nor a bench results folder, by the files it holds
    (each read "no metrics.json: not a finished odometry run folder"); '' when it may be one."""
    if path.name == "jobs" and (path.parent / "suite.json").is_file():
        results = path.absolute().parent if path.parent == Path(".") else path.parent  # (`compare jobs jobs` read "give .")
        return f"the jobs/ folder of the bench results {results}: give {results}"
    other = _other_run_kind(path)
    if other:
        return (f"{'an' if other[0] in 'aeiou' else 'a'} {other} run folder: compare pairs odometry run folders, or bench "
                "results folders (the seeds of a suite: lidarkit bench)")
    carmen = _carmen_run(path)
    if carmen:
        return carmen
    layout, images = _dataset_layout(path)
    if "CARMEN log" in layout:  # (an odometry run of it is no run compare pairs either)
        return f"a dataset folder ({layout}): compare takes run folders; {CARMEN_ADVICE}"
    if images:  # (odometry does not read images: a VO suite's bench results compare)
        return (f"a dataset folder ({layout}): compare takes run folders; an image sequence compares as bench results "
                "(a suite with a vo experiment over it: lidarkit bench)")
    if layout:
        # a KITTI sequence's velodyne/ alone has no ground truth: its sequence folder has (the advice led to a run
        # compare refused, "no ground_truth_kitti.txt")
        sequence = path.parent if path.name == "velodyne" and _dataset_layout(path.parent)[0] else path
        return f"a dataset folder ({layout}): compare takes run folders; run lidarkit odometry {sequence} --out DIR first"
    return ""


#: what to run instead of comparing CARMEN odometry runs (their ground truth is relations, not poses to pair by)
CARMEN_ADVICE = ("CARMEN runs are compared only as bench results: run a suite with an odometry experiment over the log "
                 "(lidarkit bench SUITE, docs/benchmarks.md), then lidarkit compare RESULTS RESULTS --method-a A --method-b B")


def _carmen_run(path: Path) -> str:
    """Why the folder ``path`` is an odometry run over a CARMEN log that compare does not pair (its truth is the log's
    relations, scored by the run, not ground-truth poses: it read "no ground_truth_kitti.txt"), else ''."""
    import yaml

    if (path / "ground_truth_kitti.txt").exists() or not (path / "config.yaml").is_file():
        return ""
    try:
        options = (yaml.safe_load((path / "config.yaml").read_text(encoding="utf-8")) or {})["run"]["dataset_options"]
    except (OSError, UnicodeDecodeError, yaml.YAMLError, KeyError, TypeError):
        return ""
    if not isinstance(options, dict) or options.get("kind") != "carmen":
        return ""
    log = Path(str(options.get("path") or "")).name or "?"
    truth = "its ground truth: relations between scan times, no poses" if options.get("relations") else "no ground truth"
    return (f"an odometry run over the CARMEN log {log} ({truth}): compare pairs run folders by their ground-truth "
            f"poses; {CARMEN_ADVICE}")


def _carmen_logs(path: Path) -> list[str]:
    """The CARMEN logs (``.clf``, also compressed) in the folder ``path``, by name."""
    from lidarkit.io import CARMEN_COMPRESSED

    try:
        names = sorted(p.name for p in path.iterdir() if p.is_file())
    except OSError:
        return []
    return [n for n in names if n.lower().endswith(".clf") or any(n.lower().endswith(f".clf{s}") for s in CARMEN_COMPRESSED)]


def _dataset_layout(path: Path) -> tuple[str, bool]:
    """The dataset layout of the folder ``path`` by the files it holds (``"KITTI layout: velodyne/, times.txt"``,
    ``"12 .bin scan files"``) and whether it holds images only (no input of ``lidarkit odometry``); ``("", False)`` for a
    folder that may be a run (a dataset given to compare read "no metrics.json: not a finished odometry run folder"). A
    folder holding a run's own files is never called a dataset: an odometry run cut off before its metrics has plots
    (.png) beside its poses."""
    from lidarkit.io.images import IMAGE_SUFFIXES
    from lidarkit.io.pointfile import POINT_FILE_SUFFIXES

    run_files = ("metrics.json", "config.yaml", "poses_kitti.txt", "poses_tum.txt", "ground_truth_kitti.txt", "timing.csv")
    if any((path / name).exists() for name in run_files):
        return "", False
    folders = [name for name in ("velodyne", "image_0", "image_2") if (path / name).is_dir()]
    files = [name for name in ("sim.yaml", "times.txt", "poses.txt", "calib.txt") if (path / name).is_file()]
    held = ", ".join([f"{name}/" for name in folders] + files)
    if folders:
        what = "a simulated drive in KITTI layout" if "sim.yaml" in files else "KITTI layout"
        return f"{what}: {held}", "velodyne" not in folders
    if (path / "rgb.txt").is_file():
        return "TUM RGB-D layout: rgb.txt", True
    logs = _carmen_logs(path)
    if logs:
        relations = sorted(p.name for p in path.glob("*.relations") if p.is_file())
        what = "a CARMEN log" if len(logs) == 1 else f"{len(logs)} CARMEN logs"
        return f"{what}: {', '.join([*logs[:3], *relations[:3]])}", False
    if (path / "sequences").is_dir():
        scans = any((path / "sequences").glob("*/velodyne"))
        return "a KITTI odometry root: sequences/", not scans and any((path / "sequences").glob("*/image_[02]"))
    try:
        counts = Counter(p.suffix.lower() for p in path.iterdir() if p.is_file() and not p.name.startswith("."))
    except OSError:  # (an unreadable folder: said by the reader that needs it)
        return "", False
    for suffixes, what, images in ((POINT_FILE_SUFFIXES, "scan files", False), (IMAGE_SUFFIXES, "images", True)):
        held_suffixes = sorted(suffix for suffix in counts if suffix in suffixes)
        n = sum(counts[suffix] for suffix in held_suffixes)
        if n >= 2:  # (one file beside others is no sequence)
            return f"{n} {'/'.join(held_suffixes)} {what}", images
    return "", False


def _kind(side: Any) -> type | None:
    """OdometryRun or BenchRuns: what ``side`` is, read before it is loaded; None when ``_load`` will refuse it."""
    if isinstance(side, (OdometryRun, BenchRuns)):
        return type(side)
    from lidarkit.run_files import is_baseline_folder

    if not isinstance(side, (str, os.PathLike)) or not Path(side).is_dir() or is_baseline_folder(side) or _not_an_odometry_run(Path(side)):
        return None
    return BenchRuns if (Path(side) / "jobs").is_dir() else OdometryRun


def _load(side: Any, method: str | None, every_result: bool = False) -> OdometryRun | BenchRuns:
    if isinstance(side, (OdometryRun, BenchRuns)):
        return side
    if not isinstance(side, (str, os.PathLike)):  # (None: a TypeError traceback)
        raise ConfigError(f"a run folder path is needed, got {side!r}", source="compare")
    from lidarkit.atomic import missing_reason, resolved_path

    path = Path(side)
    resolved_path(path, output=False)  # (a loop of symbolic links read "does not exist")
    if not path.exists():  # (a dangling link read "does not exist")
        raise DataError(missing_reason(path, "does not exist"), source=path)
    if not path.is_dir():  # (report.csv given: it read "run folder does not exist")
        raise DataError("is a file: compare takes an odometry run folder or a bench results folder", source=path)
    from lidarkit.run_files import is_baseline_folder

    if is_baseline_folder(path):  # (read "no successful job results")
        raise DataError("a baseline folder (lidarkit baseline record): compare takes bench results folders or odometry run "
                        "folders (a baseline gives its noise: --noise-from)", source=path)
    if (path / "jobs").is_dir():
        return load_bench_runs(path, method, every_result)
    refused = _not_an_odometry_run(path)
    if refused:  # (before --method: "a method applies to bench results folders only" of a bench folder's jobs/)
        raise DataError(refused, source=path)
    if method is not None:
        raise ConfigError("a method applies to bench results folders only", source=path)
    return load_odometry_run(path)
