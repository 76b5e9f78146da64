"""Aggregate a results folder into tables (Markdown, CSV) and one self-contained HTML page with embedded plots.

Per task: rows = (dataset, method with params), columns = the task's metrics as mean ± std over seeds,
plus runtime. Plots come from the records' ``series`` (trajectories, error over time, ICP RMSE per
iteration) and from parameter sweeps declared by the task (e.g. PF MSE vs particle count).
"""

from __future__ import annotations

import base64
import csv
import html
import io
import json
import logging
import math
import re
import warnings
from collections import defaultdict
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

from lidarkit import atomic
from lidarkit.bench.jobs import Job, canonical_json
from lidarkit.bench.results import dataset_labels, ground_truth_instant, load_results, path_argument, result_path, results_folder
from lidarkit.errors import DataError, LidarKitError, OutputError
from lidarkit.eval.report import markdown_table
from lidarkit.eval.statistics import format_p, summarize

log = logging.getLogger(__name__)

#: Job warnings listed in a report (the rest are counted).
MAX_LISTED_WARNINGS = 100

MAX_LINES_PER_PLOT = 8


@dataclass
class MetricInfo:
    name: str
    label: str
    kind: str = "accuracy"
    by_alignment: dict[str, str] = field(default_factory=dict)
    """Where rows state different alignments of this metric (VO: SE(3) for GT scale, else Sim(3)): alignment -> the
    label naming it alone. Such rows are not ranked against each other."""


@dataclass
class Row:
    """One table row: a (experiment, dataset, method) cell aggregated over seeds."""

    task: str
    experiment: str
    dataset: str
    method: str
    n_ok: int
    n_failed: int
    stats: dict[str, tuple[float, float, int]]  # metric -> (mean, std, n)
    summaries: dict[str, Any] = field(default_factory=dict)  # metric -> lidarkit.eval.Summary (median, 95 % CI)
    n_missing: int = 0  # seeds of the suite with no result yet (an interrupted run)
    n_unreadable: int = 0  # of those, seeds whose result file is there but cannot be read
    alignment: dict[str, str] = field(default_factory=dict)  # metric -> the alignment its records state
    seeds: tuple[int, ...] = ()  # the seeds of its ok results (the ones its numbers are over)
    values: dict[str, dict[int, float]] = field(default_factory=dict, repr=False)  # metric -> seed -> its finite value
    n_rerun_failed: int = 0  # ok results kept after a --force rerun of their job failed (the record's rerun_failed)
    versions: tuple[str, ...] = ()  # the lidarkit versions its results were run by (two after a rerun under new code)


@dataclass
class TaskTable:
    task: str
    metrics: list[MetricInfo]
    rows: list[Row]
    higher_is_better: frozenset[str] = frozenset()
    """Metrics the results say are better higher (as their task declared them when it ran)."""


@dataclass
class Plot:
    title: str
    filename: str
    png: bytes = field(repr=False)  # (tens of kB: a repr of 54,846 characters)
    task: str = ""
    caption: str = ""


@dataclass(repr=False)
class Report:
    """What ``build_report`` computed and wrote."""

    out_dir: Path
    tables: list[TaskTable]
    plots: list[Plot] = field(default_factory=list)
    failures: list[dict[str, Any]] = field(default_factory=list)
    rerun_failures: list[dict[str, Any]] = field(default_factory=list)  # ok results kept after a failed --force rerun
    warnings: list[tuple[str, str]] = field(default_factory=list)  # (job label, message)
    skipped: list[tuple[str, str]] = field(default_factory=list)  # experiments the last run skipped (name, reason)
    n_records: int = 0
    n_expected: int = 0  # jobs of the suite (suite.json) the report is restricted to; 0: every result in the folder
    n_left_out: int = 0  # results in jobs/ the report does not hold (an earlier suite's, or an earlier version's)
    n_earlier_version: int = 0  # of those, results of the report's own jobs from another lidarkit version (another key)
    versions: dict[str, int] = field(default_factory=dict)  # lidarkit version -> results held of it, the latest first
    not_run: list[str] = field(default_factory=list)  # labels of the suite's jobs with no result
    n_unreadable: int = 0  # of those, the jobs whose result file is there but cannot be read
    publication: Any = None  # lidarkit.bench.publication.Publication (odometry tables, box plots)
    html_path: Path | None = None
    markdown_path: Path | None = None
    csv_path: Path | None = None

    def __repr__(self) -> str:
        """One line of counts (the tables, plots and publication in full were 58,095 characters)."""
        return (f"Report({str(self.out_dir)!r}, {len(self.tables)} tables, {len(self.plots)} plots, {self.n_records} "
                f"results, {len(self.failures)} failed, {len(self.not_run)} not run)")


def import_task_modules(records: list[dict[str, Any]], manifest: dict[str, Any]) -> dict[str, str]:
    """Import the module of each task of ``records`` registered in code (as the run recorded it, in each result or
    ``suite.json``), by name, else from the folder it was imported from when the suite ran; ``{task: why}`` of the tasks
    still unknown (the caller says what that costs it). Without the module a report showed bare metric names, no speed
    table, and removed the sweep figures an earlier report had drawn."""
    from lidarkit.bench.tasks import available_tasks, get_task

    recorded = manifest.get("task_modules") if isinstance(manifest.get("task_modules"), dict) else {}
    origins: dict[str, Any] = {}
    for r in records:  # (the first result that names one: results written before it was recorded name none)
        origins[r["job"]["task"]] = origins.get(r["job"]["task"]) or r.get("task_module") or recorded.get(r["job"]["task"])
    unknown: dict[str, str] = {}
    for task, origin in sorted(origins.items()):
        why = "" if task in available_tasks() else _import_task_module(task, origin if isinstance(origin, dict) else {})
        if not why and task not in available_tasks():
            why = f"its module {origin['module']} registers no task {task!r}"
        if not why:
            try:
                get_task(task)
            except Exception as err:  # noqa: BLE001 - (a built-in task whose own module cannot load here, too)
                why = str(err)
        if why:
            unknown[task] = why
    return unknown


def _import_task_module(task: str, origin: dict[str, Any]) -> str:
    """Import ``origin["module"]`` (:func:`import_task_modules`); '' once imported, else why it was not."""
    import importlib
    import sys

    module, folder = origin.get("module"), origin.get("folder")
    if not isinstance(module, str) or not module:
        return "the results name no module defining it (import the module that registers it before build_report)"
    if module == "__main__":
        return (f"it was registered in the script that ran the suite ({origin.get('script') or '__main__'}), which a "
                "report cannot import: define it in a module")
    try:
        try:
            importlib.import_module(module)
            return ""
        except ModuleNotFoundError as err:  # (not on sys.path here: the folder it was imported from when the suite ran)
            if not (err.name and (module == err.name or module.startswith(err.name + "."))):
                raise
            if not isinstance(folder, str) or not Path(folder).is_dir():
                return f"its module {module} cannot be imported here ({err})"
        sys.path.insert(0, folder)
        try:
            importlib.import_module(module)
        finally:
            sys.path.remove(folder)
        return ""
    except Exception as err:  # noqa: BLE001 - a module that fails to load is said, not a failed report
        return f"its module {module} cannot be imported here ({type(err).__name__}: {err})"


def task_meta(task: str) -> tuple[list[MetricInfo], tuple[tuple[str, str], ...]]:
    """The metrics ``task`` declares, in its order (the report's columns), and its sweep plots; none for a task whose
    module this lidarkit cannot load (results of a plugin not installed here: read by metric names)."""
    try:
        from lidarkit.bench.tasks import get_task

        t = get_task(task)
        return [MetricInfo(m.name, m.label, m.kind) for m in t.metrics], tuple(t.sweep_plots)
    except Exception as err:  # the report must work on results whose task module is absent here
        log.info("no task metadata for %s (%s); using metric names", task, err)
        return [], ()


def recorded_metrics(records: list[dict[str, Any]]) -> list[MetricInfo]:
    """The metrics the task declared as its results record them (``metric_labels``: name and label in its order,
    ``speed_metrics``), for a task whose module cannot be loaded here: read by name alone, every metric was an accuracy
    one sorted by name, and a speed metric (``align_time_s``) was the Summary's headline, the fastest method "best"."""
    speed = {name for r in records for name in _names(r.get("speed_metrics"))}
    metrics: dict[str, MetricInfo] = {}
    for r in records:
        pairs = r.get("metric_labels")
        for pair in pairs if isinstance(pairs, list) else ():
            if (isinstance(pair, (list, tuple)) and len(pair) == 2 and all(isinstance(x, str) for x in pair)
                    and pair[0] not in metrics):
                metrics[pair[0]] = MetricInfo(pair[0], pair[1], "speed" if pair[0] in speed else "accuracy")
    return list(metrics.values())


def _names(value: Any) -> list[str]:
    """The metric names of a record's list field (``speed_metrics``, ``higher_is_better``); none where it is not one."""
    return [x for x in value if isinstance(x, str)] if isinstance(value, list) else []


#: numbers that differ by at most this share of the larger magnitude are equal (round-off apart): a cell's seeds that
#: agree to the last bits have no spread, and Summary rows with such means are a tie
EQUAL_RELATIVE = 1e-12


def _stats(values: list[float]) -> tuple[float, float, int]:
    arr = np.asarray([v for v in values if v is not None and math.isfinite(v)], dtype=float)
    if arr.size == 0:
        return (math.nan, math.nan, 0)
    # values equal up to round-off (seeds that agree to the last bits) have no spread: 0, not "0.06198 ± 5.7e-15"
    spread = float(np.ptp(arr)) > EQUAL_RELATIVE * float(np.max(np.abs(arr)))
    std = float(arr.std(ddof=1)) if arr.size > 1 and spread else 0.0
    return (float(arr.mean()), std, int(arr.size))


def aggregate(records: list[dict[str, Any]], missing: list[dict[str, Any]] = (),
              unreadable: list[dict[str, Any]] = ()) -> list[TaskTable]:
    """Group records per task and job (all but the seed); mean ± std (sample std) over seeds. ``missing``: specs of
    the suite's jobs with no result (their rows say how many seeds were not run); ``unreadable``: those of them whose
    result file is there but cannot be read (said apart: they ran)."""
    missing_per_row: dict[str, int] = defaultdict(int)
    unreadable_per_row: dict[str, int] = defaultdict(int)
    unrun: dict[str, dict[str, dict[str, Any]]] = defaultdict(dict)  # task -> row -> a record holding only the job
    for spec in missing:
        ident = canonical_json({k: v for k, v in spec.items() if k != "seed"})
        missing_per_row[ident] += 1
        unrun[spec["task"]][ident] = {"job": spec}
    for spec in unreadable:
        unreadable_per_row[canonical_json({k: v for k, v in spec.items() if k != "seed"})] += 1
    by_task: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for r in records:
        by_task[r["job"]["task"]].append(r)
    tables = []
    # a task none of whose jobs has a result yet has its table too, of rows saying so (it had none: the task was absent)
    for task in sorted(set(by_task) | set(unrun)):
        recs = by_task[task]
        declared = task_meta(task)[0] or recorded_metrics(recs)
        recorded_speed = {name for r in recs for name in _names(r.get("speed_metrics"))}
        present = set()
        for r in recs:
            present.update(k for k, v in r.get("metrics", {}).items() if isinstance(v, (int, float)) or v is None)
        # rows are jobs that differ in their seed only (not rows that print alike: two datasets with one name, or a
        # folder reused after the suite's options changed); rows that would print alike are told apart by what differs
        groups: dict[str, list[dict[str, Any]]] = defaultdict(list)
        for r in recs:
            job = r["job"]
            groups[canonical_json({k: v for k, v in job.items() if k != "seed"})].append(r)
        # a row none of whose seeds has a result yet says so ("– (3 of 3 not run)"): it was in no table nor the CSV
        no_result = {ident: r for ident, r in unrun[task].items() if ident not in groups}
        # a method with no result at all yet may report any declared metric: an interrupted run kept only the metrics
        # of the methods that ran (a sleep's "slept [s]" led, the APE of the methods still to run was no column)
        unknown_method = {r["job"]["method"] for r in no_result.values()} - {r["job"]["method"] for r in recs}
        metrics = [m for m in declared if m.name in present or unknown_method or not recs]
        metrics += [MetricInfo(name, name, "speed" if name in recorded_speed else "accuracy")
                    for name in sorted(present - {m.name for m in metrics})]
        metrics = [label_alignment(m, recs) for m in metrics]
        metrics.append(MetricInfo("runtime_s", "runtime [s]", "speed"))
        first = {ident: items[0] for ident, items in groups.items()} | no_result
        jobs = {ident: Job.from_spec(r["job"]) for ident, r in first.items()}
        label_of = dataset_labels(recs + list(no_result.values()))
        dataset_of = {ident: label_of[id(r)] for ident, r in first.items()}
        order = {i: (jobs[i].experiment, dataset_of[i], jobs[i].method, _natural(jobs[i].params)) for i in jobs}
        rows = []
        for ident in sorted(jobs, key=lambda i: order[i]):
            items = groups[ident]
            experiment, dataset, method = jobs[ident].experiment, dataset_of[ident], jobs[ident].method_label
            ok = [r for r in items if r.get("status") == "ok"]
            stats, summaries, per_seed = {}, {}, {}
            for m in metrics:
                if m.name == "runtime_s":
                    values = [r.get("runtime_s") for r in ok]
                else:
                    values = [r["metrics"].get(m.name) for r in ok]
                stats[m.name] = _stats(values)
                summaries[m.name] = summarize([v for v in values if v is not None and math.isfinite(v)], seed=0)
                per_seed[m.name] = {int(r["job"]["seed"]): float(v) for r, v in zip(ok, values)
                                    if v is not None and math.isfinite(v)}
            rows.append(Row(task, experiment, dataset, method, len(ok), len(items) - len(ok), stats, summaries,
                            n_missing=missing_per_row.get(ident, 0), n_unreadable=unreadable_per_row.get(ident, 0),
                            alignment=_stated_alignment(ok),
                            seeds=tuple(sorted(int(r["job"]["seed"]) for r in ok)), values=per_seed,
                            n_rerun_failed=sum(bool(r.get("rerun_failed")) for r in ok),
                            versions=tuple(sorted({_version(r) for r in items}))))
        higher = frozenset(name for r in recs for name in _names(r.get("higher_is_better")))
        tables.append(TaskTable(task, metrics, rows, higher))
    return tables


def label_alignment(metric: MetricInfo, records: list[dict[str, Any]]) -> MetricInfo:
    """The metric's label naming the alignment its records state (``info["metric_alignment"][name]``), e.g.
    "APE RMSE [m]" -> "APE RMSE (sim3-aligned) [m]"; several alignments are all named (and ``by_alignment`` set);
    a label that already names it, or records that state none, keep the label."""
    stated = sorted({str(a) for r in records if (a := ((r.get("info") or {}).get("metric_alignment") or {}).get(metric.name))})
    if not stated or all(a in metric.label for a in stated):
        return metric
    by_alignment = {a: _label_naming(metric.label, a) for a in stated} if len(stated) > 1 else {}
    return MetricInfo(metric.name, _label_naming(metric.label, " / ".join(stated)), metric.kind, by_alignment)


def _label_naming(label: str, text: str) -> str:
    """``label`` with ``text`` before its unit: "APE RMSE [m]" -> "APE RMSE (Sim(3)-aligned) [m]"."""
    head, sep, unit = label.rpartition(" [")
    return f"{head} ({text}){sep}{unit}" if sep and label.endswith("]") else f"{label} ({text})"


def _stated_alignment(records: list[dict[str, Any]]) -> dict[str, str]:
    """Metric -> the alignment the records of one row state (seeds stating several: all of them named)."""
    stated: dict[str, set[str]] = defaultdict(set)
    for r in records:
        for name, a in (((r.get("info") or {}).get("metric_alignment")) or {}).items():
            stated[name].add(str(a))
    return {name: " / ".join(sorted(a)) for name, a in stated.items()}


def _alignment_note(row: Row, metric: MetricInfo) -> str:
    """`` [Sim(3)-aligned]`` in a cell of a column whose rows state different alignments, else ''."""
    a = row.alignment.get(metric.name)
    return f" [{a}]" if metric.by_alignment and a else ""


def _natural(params: dict[str, Any]) -> tuple:
    """Sort key of a param dict: numbers by value (50 < 100 < 1000), numbers written as text too (a grid of 20, "60",
    180 sorted 20, 180, 60), then everything else as text."""
    return tuple((k, _number_first(v)) for k, v in sorted(params.items()))


def _number_first(value: Any) -> tuple[int, float, str]:
    """A finite number, or text that reads as one, by its value; anything else (NaN too, which orders nothing) after."""
    number = math.nan
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        number = float(value)
    elif isinstance(value, str):
        try:
            number = float(value)
        except ValueError:
            pass
    return (0, number, value if isinstance(value, str) else "") if math.isfinite(number) else (1, 0.0, str(value))


def format_stat(stat: tuple[float, float, int], digits: int = 4) -> str:
    """``mean ± std`` with ``digits`` significant digits (the mean alone for one run, a dash for none)."""
    mean, std, n = stat
    if n == 0:
        return "–"
    if n == 1:
        return _fmt(mean, digits)
    return f"{_fmt(mean, digits)} ± {_fmt(std, min(digits, 2))}"


def _fmt(x: float, digits: int = 4) -> str:
    if x == 0 or not math.isfinite(x):
        return f"{x:g}"
    if abs(x) >= 1e5 or abs(x) < 1e-3:
        return f"{x:.{digits - 1}e}"
    return f"{x:.{digits}g}"


# ---------------------------------------------------------------- plots


def _png(fig) -> bytes:
    """The figure as PNG; a name the font cannot draw (CJK) is drawn as boxes, and matplotlib's warning of each missing
    glyph is silenced (it printed on stderr over the progress of a bench run)."""
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="Glyph .* missing from font", category=UserWarning)
        fig.savefig(buf, format="png", dpi=90, bbox_inches="tight")
    plt.close(fig)
    return buf.getvalue()


def _literal(text: Any) -> str:
    """``text`` (a name from a suite or a record) as matplotlib draws it (:func:`lidarkit.eval.plots.literal_text`): two
    ``$`` in a dataset name (``drive_$1_$2``) ended the report before any file was written."""
    from lidarkit.eval.plots import literal_text

    return literal_text(text)


@contextmanager
def _figure(filename: str, size: tuple[float, float]) -> Iterator[tuple[Any, Any]]:
    """A new figure and its axes; anything that fails while it is drawn becomes one OutputError naming the figure
    (a traceback of 274 lines ended the report), and the figure is closed either way."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=size)
    try:
        yield fig, ax
    except LidarKitError:
        raise
    except Exception as err:  # noqa: BLE001 - matplotlib's errors have no common base
        why = " ".join(str(err).split())
        raise OutputError(f"cannot be drawn ({type(err).__name__}: {why[:300]})", source=filename) from None
    finally:
        plt.close(fig)


#: the names of the figures a report draws (``traj_<slug>_<digest>.png``, ..., ``segments_<quantity>.png``): the only
#: files of plots/ an earlier report's clean-up removes
_OWN_FIGURE = re.compile(r"(traj|err|rmse|sweep)_.*_[0-9a-f]{8}\.png|segments_(translation_pct|rotation_deg_per_100m)\.png")


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("_")[:80] or "plot"


def _file_slug(text: str) -> str:
    """:func:`_slug` and a short digest of ``text``: a file name per text ("x y" and "x/y", two long names that share
    their first 80 characters each drew over the other's plot)."""
    import hashlib

    return f"{_slug(text)[:72]}_{hashlib.sha1(text.encode()).hexdigest()[:8]}"


def _first_ok_per_method(items: list[dict[str, Any]], series: str) -> tuple[dict[str, dict[str, Any]], str]:
    """The first seed's record of each method with ``series`` (by label), at most :data:`MAX_LINES_PER_PLOT`, and the
    caption's note naming the methods left out ("" when none is)."""
    out: dict[str, dict[str, Any]] = {}
    for r in sorted(items, key=lambda r: r["job"]["seed"]):
        if r.get("status") != "ok" or not r.get("series", {}).get(series):
            continue
        label = Job.from_spec(r["job"]).method_label
        out.setdefault(label, r)
    return _capped(dict(sorted(out.items())))


def _references(chosen: dict[str, dict[str, Any]]) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    """The references drawn with the chosen records, one per distinct path, by legend label, and each method's
    reference label. Each estimate is drawn with its own reference: a seeded simulation drives another path per seed,
    and a method whose poses refer to the sweep mid is scored against the truth re-timed to it. Labels name what tells
    the references apart ("reference (seed 1)", "reference (sweep mid)"); keyed by seed alone, the sweep-end and
    sweep-mid references of one seed were one, and kiss was drawn against small_gicp's mid-sweep truth."""
    by_path: dict[str, tuple[set[int], set[str], np.ndarray]] = {}
    path_of: dict[str, str] = {}
    for method, r in chosen.items():
        ref = r["series"]["trajectory_xy"].get("ref") or []
        if ref:
            path_of[method] = canonical_json(ref)
            seeds, instants, _ = by_path.setdefault(path_of[method], (set(), set(), np.asarray(ref, dtype=float)))
            seeds.add(int(r["job"]["seed"]))
            instants.add(ground_truth_instant(r))
    several_seeds = len({frozenset(seeds) for seeds, _, _ in by_path.values()}) > 1
    several_instants = len({frozenset(instants) for _, instants, _ in by_path.values()}) > 1
    label_of: dict[str, str] = {}
    for path, (seeds, instants, _) in by_path.items():
        told = [f"seed {', '.join(map(str, sorted(seeds)))}"] if several_seeds else []
        told += [" / ".join(sorted(i for i in instants if i))] if several_instants and any(instants) else []
        label = f"reference ({', '.join(told)})" if told else "reference"
        if len(by_path) > 1 and label in label_of.values():  # paths differing in nothing the records state
            label = f"{label} #{len(label_of) + 1}"
        label_of[path] = label
    return {label_of[path]: xy for path, (_, _, xy) in by_path.items()}, {m: label_of[p] for m, p in path_of.items()}


def _capped(lines: dict[str, Any]) -> tuple[dict[str, Any], str]:
    """At most :data:`MAX_LINES_PER_PLOT` of ``lines`` (a legend beyond that is unreadable) and a note naming the rest
    (12 methods were drawn as 8, the rest left out without a word)."""
    kept = dict(list(lines.items())[:MAX_LINES_PER_PLOT])
    left = [k for k in lines if k not in kept]
    note = f" {len(kept)} of {len(lines)} shown; left out: {', '.join(left)}." if left else ""
    return kept, note


def rmse_histories(items: list[dict[str, Any]]) -> tuple[dict[str, tuple[list[float], int]], list[str]]:
    """The RMSE history of the first pair of each method's first ok seed, by method label, with the iteration its first
    value is at (0: the starting pose, as lidarkit's own loops record it, ``iterations + 1`` values), and the methods
    whose history is the final RMSE alone (small_gicp, kiss, Open3D: drawn as one point at iteration 1, it read as an
    ICP that stopped after one step); a method without any RMSE (not assessed) is in neither."""
    from lidarkit.registration.assessment import FINAL_RMSE_ONLY_KEY

    drawn: dict[str, tuple[list[float], int]] = {}
    final_only: set[str] = set()
    for r in sorted(items, key=lambda r: r["job"]["seed"]):
        series = (r.get("series") or {}).get("rmse_history")
        label = Job.from_spec(r["job"]).method_label
        if r.get("status") != "ok" or not series or label in drawn or label in final_only:
            continue
        hist = series[0] if isinstance(series[0], list) else series  # (one history per pair: the first)
        pairs = (r.get("info") or {}).get("pairs")
        pair = pairs[0] if isinstance(pairs, list) and pairs and isinstance(pairs[0], dict) else {}
        iterations = pair.get("iterations")  # (None: the library reports no count)
        if not hist:
            continue
        if pair.get(FINAL_RMSE_ONLY_KEY) is True or (len(hist) == 1 and iterations != 0):
            final_only.add(label)
            continue
        counted = isinstance(iterations, int) and not isinstance(iterations, bool)
        values = [math.nan if v is None else float(v) for v in hist]  # (NaN is written as null)
        drawn[label] = (values, 0 if counted and len(hist) == iterations + 1 else 1)
    return dict(sorted(drawn.items())), sorted(final_only)


def make_plots(records: list[dict[str, Any]]) -> list[Plot]:
    """Trajectory, error-over-time and RMSE-per-iteration plots per (task, experiment, dataset); sweep plots per task.
    Every text from a suite or a record is drawn as written (:func:`_literal`); a figure that cannot be drawn is an
    OutputError naming it."""
    import matplotlib

    matplotlib.use("Agg")

    plots: list[Plot] = []
    groups: dict[tuple[str, str, str], list[dict[str, Any]]] = defaultdict(list)
    for r in records:
        j = r["job"]
        groups[(j["task"], j["experiment"], j["dataset_name"])].append(r)
    for (task, experiment, dataset), items in sorted(groups.items()):
        where = f"{task} · {experiment} · {dataset}"
        chosen, left_out = _first_ok_per_method(items, "trajectory_xy")
        if chosen:
            filename = f"traj_{_file_slug(where)}.png"
            with _figure(filename, (6, 4.5)) as (fig, ax):
                refs, ref_of = _references(chosen)
                for k, (ref_label, ref) in enumerate(refs.items()):
                    ax.plot(ref[:, 0], ref[:, 1], ("--", ":", "-.")[k % 3], color="k", lw=2, label=_literal(ref_label))
                for label, r in chosen.items():
                    est = np.asarray(r["series"]["trajectory_xy"]["est"], dtype=float)
                    against = f" vs {ref_of[label]}" if len(refs) > 1 and label in ref_of else ""
                    ax.plot(est[:, 0], est[:, 1], lw=1.2, label=_literal(f"{label} (seed {r['job']['seed']}){against}"))
                ax.set_xlabel("x [m]")
                ax.set_ylabel("z [m]" if task == "vo" else "y [m]")  # (a camera's ground plane is its x-z)
                ax.set_aspect("equal", adjustable="datalim")
                ax.legend(fontsize=7)
                ax.set_title(_literal(f"trajectories: {where}"), fontsize=9)
                png = _png(fig)
            plots.append(Plot(f"Trajectories — {where}", filename, png, task,
                              f"Top view of the estimated trajectories (first seed of each method) against the "
                              f"reference of that seed and sweep instant (black): {experiment}, {dataset}.{left_out}"))
        chosen, left_out = _first_ok_per_method(items, "error_over_time")
        if chosen:
            filename = f"err_{_file_slug(where)}.png"
            with _figure(filename, (6, 3.2)) as (fig, ax):
                xlabel = "time [s]"
                ylabel, line_notes = error_axis_label({label: r["series"]["error_over_time"].get("label", "error")
                                                       for label, r in chosen.items()})
                for label, r in chosen.items():
                    s = r["series"]["error_over_time"]
                    note = f" ({line_notes[label]})" if label in line_notes else ""
                    ax.plot(s["t"], s["error"], lw=1.2, label=_literal(label + note))
                    xlabel = s.get("t_label", xlabel)  # (a particle filter's steps were labelled seconds)
                ax.set_xlabel(_literal(xlabel))
                ax.set_ylabel(_literal(ylabel))
                ax.legend(fontsize=7)
                ax.set_title(_literal(f"error over time: {where}"), fontsize=9)
                png = _png(fig)
            per_line = f" ({'; '.join(f'{m}: {n}' for m, n in line_notes.items())})" if line_notes else ""
            plots.append(Plot(f"Error over time — {where}", filename, png, task,
                              f"{ylabel} over time per method{per_line}: {experiment}, {dataset}.{left_out}"))
        histories, final_only = rmse_histories(items)
        histories, left_out = _capped(histories)
        if histories:
            filename = f"rmse_{_file_slug(where)}.png"
            with _figure(filename, (6, 3.2)) as (fig, ax):
                for label, (hist, first_x) in histories.items():
                    ax.plot(np.arange(first_x, first_x + len(hist)), hist, marker=".", lw=1.2, label=_literal(label))
                ax.set_xlabel("iteration")
                ax.set_ylabel("RMSE [m]")
                ax.set_yscale("log")
                ax.legend(fontsize=7)
                ax.set_title(_literal(f"ICP RMSE vs iteration: {where}"), fontsize=9)
                png = _png(fig)
            start = " iteration 0 is the starting pose;" if any(x == 0 for _, x in histories.values()) else ""
            final = (f" Not drawn, their library reports the final RMSE alone: {', '.join(final_only)}."
                     if final_only else "")
            plots.append(Plot(f"RMSE vs iteration — {where}", filename, png, task,
                              f"Correspondence RMSE per ICP iteration (first pair, log scale;{start} first seed of each "
                              f"method): {experiment}, {dataset}.{left_out}{final}"))
        elif final_only:
            log.info("no RMSE-per-iteration figure for %s: %s report the final RMSE alone", where, ", ".join(final_only))
    plots.extend(_sweep_plots(records))
    return plots


def error_axis_label(labels: dict[str, str]) -> tuple[str, dict[str, str]]:
    """The y label of an error-over-time plot whose lines are labelled ``labels`` (method -> its series' label) and
    what each line's legend entry adds: one label is the axis's; labels that differ in one bracketed part ("APE (se3
    aligned) [m]", "APE (sim3 aligned) [m]") give the axis what they share ("APE [m]") and each line its part; other
    differing labels give a neutral "error" (with their shared unit) and each line its whole label. (The last line's
    label was the axis's: an SE(3)-aligned line read as Sim(3)-aligned.)"""
    if len(set(labels.values())) <= 1:
        return next(iter(labels.values()), "error"), {}
    parts = {method: re.fullmatch(r"(.*?)\s*\(([^()]*)\)(.*)", label) for method, label in labels.items()}
    shared = {" ".join(f"{m.group(1)}{m.group(3)}".split()) if m else None for m in parts.values()}
    if None not in shared and len(shared) == 1:
        return shared.pop(), {method: m.group(2).strip() for method, m in parts.items()}
    units = {u.group(0) if (u := re.search(r"\[[^\[\]]*\]$", label.strip())) else None for label in labels.values()}
    return "error" + (f" {units.pop()}" if len(units) == 1 and None not in units else ""), dict(labels)


def recorded_sweeps(records: list[dict[str, Any]]) -> tuple[tuple[str, str], ...]:
    """The sweep plots the task declared as its results record them (``sweep_plots``: ``[param, metric]`` pairs), for
    a task whose module cannot be loaded here (its figures stayed in plots/ but were gone from the report's pages)."""
    sweeps: dict[tuple[str, str], None] = {}
    for r in records:
        pairs = r.get("sweep_plots")
        for pair in pairs if isinstance(pairs, list) else ():
            if isinstance(pair, (list, tuple)) and len(pair) == 2 and all(isinstance(x, str) for x in pair):
                sweeps.setdefault((pair[0], pair[1]), None)
    return tuple(sweeps)


def _sweep_plots(records: list[dict[str, Any]]) -> list[Plot]:
    plots = []
    by_task: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for r in records:
        by_task[r["job"]["task"]].append(r)
    for task, recs in sorted(by_task.items()):
        declared, sweeps = task_meta(task)
        declared = declared or recorded_metrics(recs)
        label_of = {m.name: m.label for m in declared}
        for param, metric in sweeps or recorded_sweeps(recs):
            try:
                plot = _sweep_plot(task, recs, param, metric, label_of)
            except (TypeError, ValueError, OverflowError) as err:  # (a ValueError traceback ended the report)
                raise DataError(f"its sweep of {metric} over parameter {param!r} cannot be drawn "
                                f"({type(err).__name__}: {err})", source=f"task {task}") from err
            if plot is not None:
                plots.append(plot)
    return plots


def _sweep_plot(task: str, recs: list[dict[str, Any]], param: str, metric: str, label_of: dict[str, str]) -> Plot | None:
    """One sweep figure, ``metric`` against ``param`` (None: no line has two points). Values that are not all numbers
    (a grid of text, a list, null) are categories on the x axis, numbers first by value, then the rest by their text:
    read as numbers, ``mode: [fast, slow]`` ended the report with a ValueError."""
    experiments = {r["job"]["experiment"] for r in recs}
    # the metric's declared label, as the tables name it (the axis, title and caption read "mse_m2")
    metric_label = label_alignment(MetricInfo(metric, label_of.get(metric, metric)), recs).label
    chosen = [r for r in recs if r.get("status") == "ok" and param in r["job"]["params"]
              and r.get("metrics", {}).get(metric) is not None]
    values = [r["job"]["params"][param] for r in chosen]
    numeric = all(_sweep_number(v) is not None for v in values)
    categories = {} if numeric else sweep_categories(values)
    position = {key: float(k) for k, key in enumerate(categories)}
    lines: dict[str, dict[float, list[float]]] = defaultdict(lambda: defaultdict(list))
    for r, v in zip(chosen, values):
        others = {k: x for k, x in r["job"]["params"].items() if k != param}
        # one line per experiment, dataset and method (two experiments on one dataset were pooled into one)
        where = f"{r['job']['experiment']} · " if len(experiments) > 1 else ""
        label = f"{where}{r['job']['dataset_name']}: " + Job(task, "", "", {}, r["job"]["method"], others).method_label
        x = _sweep_number(v) if numeric else position[canonical_json(v)]
        lines[label][x].append(float(r["metrics"][metric]))
    lines = {k: v for k, v in sorted(lines.items()) if len(v) >= 2}
    if not lines:
        return None
    lines, left_out = _capped(lines)
    filename = f"sweep_{_file_slug(task + '_' + metric + '_' + param)}.png"
    with _figure(filename, (6, 3.6)) as (fig, ax):
        for label, points in lines.items():
            xs = sorted(points)
            means = [float(np.mean(points[x])) for x in xs]
            stds = [float(np.std(points[x], ddof=1)) if len(points[x]) > 1 else 0.0 for x in xs]
            # (categories have no order a line between them could follow: points alone)
            ax.errorbar(xs, means, yerr=stds, marker="o", capsize=3, lw=1.2, ls="-" if numeric else "none",
                        label=_literal(label))
        ax.set_xlabel(_literal(param))
        ax.set_ylabel(_literal(metric_label))
        if numeric:
            scale, scale_args, scale_note = sweep_x_scale([x for points in lines.values() for x in points])
            ax.set_xscale(scale, **scale_args)
        else:
            ax.set_xticks(list(position.values()), [_literal(text) for text in categories.values()])
            ax.set_xlim(-0.5, len(categories) - 0.5)
            scale_note = f"; the values of {param} as categories (numbers by value, then the rest by their text)"
        ax.legend(fontsize=7)
        ax.set_title(_literal(f"{task}: {metric_label} vs {param} (mean ± std over seeds)"), fontsize=9)
        png = _png(fig)
    return Plot(f"{metric_label} vs {param} — {task}", filename, png,
                task, f"{metric_label} against {param}: mean ± std over seeds, one line per experiment, dataset and "
                f"method{scale_note}.{left_out}")


def _sweep_number(value: Any) -> float | None:
    """A sweep value as a position on a number axis: a number, or text that reads as a finite one ("60"); None for
    anything else (text, a list, null, a bool: drawn as categories)."""
    if isinstance(value, bool):
        return None
    if isinstance(value, (int, float)):
        return float(value)
    if isinstance(value, str):
        try:
            number = float(value)
        except ValueError:
            return None
        return number if math.isfinite(number) else None
    return None


def sweep_categories(values: list[Any]) -> dict[str, str]:
    """The x axis of a sweep over values that are not all numbers: each distinct value (by its JSON text) -> its tick
    label, in axis order: numbers by value, then the rest by their text (a list or null by its JSON text)."""
    def text(value: Any) -> str:
        return value if isinstance(value, str) else canonical_json(value)

    def order(value: Any) -> tuple[int, float, str]:
        return _number_first(value if isinstance(value, (int, float)) and not isinstance(value, bool) else text(value))

    return {canonical_json(v): text(v) for v in sorted(values, key=order)}


def sweep_x_scale(xs: list[float]) -> tuple[str, dict[str, float], str]:
    """A sweep's x axis (matplotlib scale, its arguments, the caption's note): log where the values span a factor of
    10 or more; with a value <= 0 among them, symlog, linear up to the smallest positive value (a log axis dropped a
    noise_m of 0 without a word)."""
    positive = [x for x in xs if x > 0]
    if not positive or max(positive) / min(positive) < 10:
        return "linear", {}, ""
    if len(positive) == len(xs):
        return "log", {}, "; log x axis"
    return "symlog", {"linthresh": min(positive)}, f"; symmetric log x axis, linear within ±{min(positive):g}"


# ---------------------------------------------------------------- writers


def _table_rows(table: TaskTable) -> tuple[list[str], list[list[str]]]:
    header = ["experiment", "dataset", "method", "ok/failed"] + [m.label for m in table.metrics]
    rows = [
        [r.experiment, r.dataset, r.method, f"{r.n_ok}/{r.n_failed}" + _rerun_note(r)]
        + [format_stat(r.stats[m.name]) + _failed_note(r, m.name, failures=False) + _alignment_note(r, m) for m in table.metrics]
        for r in table.rows
    ]
    return header, rows


def _rerun_note(row: Row) -> str:
    """`` (1 kept after a failed rerun)`` beside a row's ok/failed counts (see :func:`_failed_note`), else ''."""
    return f" ({row.n_rerun_failed} kept after a failed rerun)" if row.n_rerun_failed else ""


def pivot(table: TaskTable, metric: str, datasets: list[str] | None = None) -> tuple[list[str], list[list[str]]]:
    """Methods x datasets for one metric (``experiment: method`` rows, dataset columns, mean ± std cells), over
    ``datasets`` (default: every dataset of the table)."""
    info = next((m for m in table.metrics if m.name == metric), MetricInfo(metric, metric))
    datasets = sorted({r.dataset for r in table.rows} if datasets is None else datasets)
    cells: dict[str, dict[str, str]] = {}
    one_experiment = len({r.experiment for r in table.rows}) == 1  # no prefix repeated on every row
    for r in table.rows:
        if r.dataset not in datasets:
            continue
        label = r.method if one_experiment else f"{r.experiment}: {r.method}"
        cells.setdefault(label, {})[r.dataset] = format_stat(r.stats[metric]) + _failed_note(r, metric) + _alignment_note(r, info)
    header = ["method"] + datasets
    return header, [[label] + [row.get(d, "") for d in datasets] for label, row in cells.items()]


def headline_metrics(table: TaskTable) -> dict[str, MetricInfo]:
    """Each dataset's headline: the first accuracy metric, in the task's order, with a value on that dataset's rows (a
    CARMEN log scored by its relations beside a KITTI sequence scored by APE: one headline for the whole table, the
    APE, left the log with no Summary row and a column of dashes); a dataset with no value of any takes the table's
    first accuracy metric. {} for a task without accuracy metrics."""
    accuracy = [m for m in table.metrics if m.kind == "accuracy"]
    if not accuracy:
        return {}
    rows_of: dict[str, list[Row]] = defaultdict(list)
    for r in table.rows:
        rows_of[r.dataset].append(r)
    return {dataset: next((m for m in accuracy if any(r.stats[m.name][2] > 0 for r in rows)), accuracy[0])
            for dataset, rows in rows_of.items()}


def _pivot_views(table: TaskTable) -> list[tuple[MetricInfo, list[str] | None]]:
    """The methods x datasets views: the headline accuracy metric (one view per headline, over the datasets it heads,
    where datasets have different ones; ``None``: every dataset) and the first speed metric."""
    headlines = headline_metrics(table)
    distinct = [m for m in table.metrics if m.name in {h.name for h in headlines.values()}]
    if len(distinct) > 1:
        first = [(m, sorted(d for d, h in headlines.items() if h.name == m.name)) for m in distinct]
    else:
        first = [(m, None) for m in [m for m in table.metrics if m.kind == "accuracy"][:1]]
    speed = [m for m in table.metrics if m.kind == "speed" and m.name != "runtime_s"][:1]
    return first + [(m, None) for m in (speed or [m for m in table.metrics if m.name == "runtime_s"])]


def _pivot_metrics(table: TaskTable) -> list[MetricInfo]:
    """The metrics of the methods x datasets views (:func:`_pivot_views`): the headline(s), then a speed metric."""
    return [m for m, _ in _pivot_views(table)]


def coverage_text(report: Report) -> str:
    """What the report holds against the suite: `` of the suite's 24 jobs (17 not run yet); 9 results of jobs not in
    suite.json left out`` ('' when it holds every job of the suite and nothing was left out). Results of the same jobs
    from an earlier lidarkit version (after a source change) are said to be that, not an earlier suite's; results
    shown from more than one version are counted per version."""
    text = ""
    if report.n_expected and report.n_records < report.n_expected:
        text += f" of the suite's {report.n_expected} jobs ({len(report.not_run) - report.n_unreadable} not run yet"
        text += f", {report.n_unreadable} with a result file that cannot be read)" if report.n_unreadable else ")"
    if report.n_earlier_version:
        text += f"; {report.n_earlier_version} results in jobs/ of these jobs from an earlier lidarkit version left out"
    n_other_jobs = report.n_left_out - report.n_earlier_version
    if n_other_jobs:
        text += (f"; {n_other_jobs} results in jobs/ of jobs not in the folder's suite.json (an earlier suite) left out"
                 if report.n_expected else f"; {n_other_jobs} results of jobs not in this run's suite left out")
    if len(report.versions) > 1:  # (--all after a rerun under new code: rows of two versions, said only "left out")
        counts = [f"{n} from {version}" + (" (the latest)" if k == 0 else "")
                  for k, (version, n) in enumerate(report.versions.items())]
        text += (f"; the {report.n_records} shown are from {len(report.versions)} lidarkit versions: {', '.join(counts)} "
                 "(report.csv's lidarkit_version names each row's)")
    return text


def _version(record: dict[str, Any]) -> str:
    return str(record.get("lidarkit_version") or "unknown")


def version_counts(records: list[dict[str, Any]]) -> dict[str, int]:
    """``{lidarkit version: results}`` of ``records``, the version of the most recently finished result first."""
    latest: dict[str, str] = {}
    counts: dict[str, int] = defaultdict(int)
    for r in records:
        version = _version(r)
        counts[version] += 1
        latest[version] = max(latest.get(version, ""), str(r.get("finished_utc") or ""))
    return {v: counts[v] for v in sorted(counts, key=lambda v: (latest[v], v), reverse=True)}


def _not_run_lines(report: Report, limit: int = 50) -> list[str]:
    lines = report.not_run[:limit]
    return lines + ([f"... and {len(report.not_run) - limit} more"] if len(report.not_run) > limit else [])


def _markdown(report: Report, title: str) -> str:
    out = [f"# {title}", "", f"Generated {datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC from {report.n_records} job results"
           f"{coverage_text(report)} in `{report.out_dir}`. Cells: mean ± std over seeds (sample std).", ""]
    header, rows = summary_rows(report)
    if rows:
        out += ["## Summary", "", markdown_table(header, rows)]
    for table in report.tables:
        out += [f"## {table.task}", ""]
        for m, datasets in _pivot_views(table):
            header, rows = pivot(table, m.name, datasets)
            out += [f"{m.label}, methods x datasets:", "", markdown_table(header, rows)]
        header, rows = _table_rows(table)
        out += ["All metrics:", "", markdown_table(header, rows)]
    pub = report.publication
    if pub is not None and pub.tables:
        out += ["## Publication tables", "", "Also as CSV and LaTeX (booktabs) in `tables/` beside this report.", ""]  # (its folder's last name read as a path)
        out += [t.to_markdown() for t in pub.tables]
        out += [f"![{caption}](plots/{path.name})\n\n{caption}\n" for caption, path in pub.boxplots]
    if pub is not None and (pub.comparisons or pub.not_compared):
        out += ["## Paired comparisons with the reference", ""]
        if pub.comparisons:
            out.append(markdown_table(*comparison_rows(pub.comparisons)))
        notes = comparison_notes(pub.comparisons) + [f"no comparison: {line}" for line in pub.not_compared]
        out += [f"- {line}" for line in notes] + ([""] if notes else [])
    if report.plots:
        # (each caption under its figure, as report.html has it: report.md had the titles alone)
        out += ["## Plots", ""] + [f"![{p.title}](plots/{p.filename})\n\n{_italic(p.caption or p.title)}\n"
                                   for p in report.plots]
    if report.skipped:
        out += ["## Experiments not run", ""] + [f"- {name}: {reason}" for name, reason in report.skipped] + [""]
    if report.not_run:
        out += ["## Jobs of the suite without a result", ""] + [f"- {line}" for line in _not_run_lines(report)] + [""]
    if report.warnings:
        out += ["## Warnings logged by jobs", ""] + [f"- {label}: {message}" for label, message in report.warnings] + [""]
    if report.failures or report.rerun_failures:
        out += ["## Failed jobs", ""] + [f"- `{f['key']}` {f['label']}: {f['error']}"
                                         for f in report.failures + report.rerun_failures] + [""]
    return "\n".join(out)


def _italic(text: str) -> str:
    """``text`` as one italic Markdown line; its own ``*``, ``$``, backslashes and ``_`` at a word's edge are escaped, so
    that a name holding them neither ends the emphasis, nor starts another, nor is read as math."""
    escaped = re.sub(r"([\\*$])", r"\\\1", text)
    escaped = re.sub(r"(?<![A-Za-z0-9])_|_(?![A-Za-z0-9])", r"\\_", escaped)
    return f"*{escaped}*"


def _csv_number(x: Any) -> str:
    """A CSV cell: the number, empty where there is none (NaN: a metric the method does not report)."""
    return "" if x is None or (isinstance(x, float) and not math.isfinite(x)) else repr(x)


def _csv(report: Report) -> str:
    """Long format, one row per (row, metric); ``alignment``: the one its records state (two ``ape_rmse_m`` rows of a VO
    suite, SE(3)- and Sim(3)-aligned, were told apart by nothing), empty where they state none; ``lidarkit_version``:
    the versions its results were run by, `` / ``-joined (a folder reused across code versions mixes them)."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(["task", "experiment", "dataset", "method", "metric", "mean", "std", "n", "n_ok", "n_failed",
                     "n_not_run", "median", "ci95_low", "ci95_high", "alignment",
                     "n_rerun_failed", "lidarkit_version"])  # (new columns go last: readers index them)
    for table in report.tables:
        for r in table.rows:
            for m in table.metrics:
                mean, std, n = r.stats[m.name]
                s = r.summaries.get(m.name)
                # one value has no spread: empty cells, not a std of 0 and a CI [v, v] of zero width
                extra = [_csv_number(s.median), repr(s.ci_low) if s.n > 1 else "", repr(s.ci_high) if s.n > 1 else ""] if s is not None else ["", "", ""]
                writer.writerow([r.task, r.experiment, r.dataset, r.method, m.name, _csv_number(mean), repr(std) if n > 1 else "",
                                 n, r.n_ok, r.n_failed, r.n_missing, *extra, r.alignment.get(m.name, ""), r.n_rerun_failed,
                                 " / ".join(r.versions)])
    return buf.getvalue()


_CSS = """
body{font-family:system-ui,sans-serif;margin:2em;max-width:1200px;color:#222}
table{border-collapse:collapse;margin:1em 0;font-size:0.9em}
th,td{border:1px solid #ccc;padding:3px 8px;text-align:right}
th{background:#f0f0f0} td.l,th.l{text-align:left}
figure{display:inline-block;margin:0.5em;vertical-align:top;max-width:560px}
figure.table{display:block;max-width:none}
section{margin-top:2em;border-top:1px solid #ddd}
details{margin:0.5em 0}
figcaption{font-size:0.85em;color:#555}
.failed{color:#a00}
tr.summary td{border-top:2px solid #444;font-style:italic}
caption{font-weight:600;text-align:left;padding:2px 0}
"""


def _pubtable_html(table) -> str:
    """A :class:`lidarkit.eval.tables.PubTable` as an HTML table (best per row bold, summary rows set apart)."""
    e = html.escape
    best = table.best_mask()
    rows = []
    n = len(table.row_labels)
    for i, label in enumerate(table.row_labels):
        cls = ' class="summary"' if i >= n - table.n_summary_rows else ""
        cells = "".join(f"<td><b>{e(table.cell(i, j))}</b></td>" if best[i, j] else f"<td>{e(table.cell(i, j))}</td>"
                        for j in range(len(table.col_labels)))
        rows.append(f'<tr{cls}><td class="l">{e(label)}</td>{cells}</tr>')
    head = f'<th class="l">{e(table.corner)}</th>' + "".join(f"<th>{e(c)}</th>" for c in table.col_labels)
    note = f"<figcaption>{e(table.note)}</figcaption>" if table.note else ""
    return (f'<figure class="table"><table><caption>{e(table.title)}</caption><thead><tr>{head}</tr></thead>'
            f"<tbody>{''.join(rows)}</tbody></table>{note}</figure>")


def _table_html(header: list[str], rows: list[list[str]], n_left: int = 1, caption: str = "") -> str:
    e = html.escape
    head = "".join(f'<th class="l">{e(h)}</th>' if i < n_left else f"<th>{e(h)}</th>" for i, h in enumerate(header))
    body = "".join(
        "<tr>" + "".join(f'<td class="l">{e(c)}</td>' if i < n_left else f"<td>{e(c)}</td>" for i, c in enumerate(row)) + "</tr>"
        for row in rows
    )
    cap = f"<caption>{e(caption)}</caption>" if caption else ""
    return f"<table>{cap}<thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def _figure_html(png: bytes, alt: str, caption: str) -> str:
    e = html.escape
    data = base64.b64encode(png).decode("ascii")
    return (f'<figure><img src="data:image/png;base64,{data}" alt="{e(alt)}" width="540">'
            f"<figcaption>{e(caption)}</figcaption></figure>")


def summary_rows(report: Report) -> tuple[list[str], list[list[str]]]:
    """The page's first table: per task and dataset, the best method on the dataset's headline accuracy metric
    (:func:`headline_metrics`; per alignment where the rows state different ones: an SE(3)- and a Sim(3)-aligned APE
    are not ranked together), and how many methods were ranked: those with a value (it counted a sleep and a failing
    method with none)."""
    header = ["section", "dataset", "headline metric", "best method", "value (mean ± std)", "methods ranked"]
    rows = []
    for table in report.tables:
        headlines = headline_metrics(table)
        groups: dict[tuple[str, str], list[Row]] = defaultdict(list)
        for r in table.rows:
            metric = headlines.get(r.dataset)
            if metric is not None and r.stats[metric.name][2] > 0:
                groups[(r.dataset, r.alignment.get(metric.name, "") if metric.by_alignment else "")].append(r)
        for (dataset, alignment), candidates in sorted(groups.items()):
            metric = headlines[dataset]
            better_higher = metric.name in table.higher_is_better or _better_higher(table.task, metric.name)
            # a method that failed on some seeds is not the best over one lucky seed: complete rows come first (a seed
            # with no value, NaN, counts as a failed one); a seed not run yet is no failure: rows are ranked on their
            # means over the seeds they share (a method whose best seed was not run yet lost to a worse complete one)
            ranked = [r for r in candidates if not (r.n_failed or _n_no_value(r, metric.name))] or candidates
            common = _common_seeds(ranked, metric.name)
            mean_of = {id(r): _mean_over(r, metric.name, common) for r in ranked}
            best = min(ranked, key=lambda r: -mean_of[id(r)] if better_higher else mean_of[id(r)])
            # rows whose means equal the best's are a tie, not a win by sort order (0 vs 0 bad frames named one best)
            tied = [r for r in ranked
                    if math.isclose(mean_of[id(r)], mean_of[id(best)], rel_tol=EQUAL_RELATIVE, abs_tol=0.0)]
            cells = {format_stat(r.stats[metric.name]) + _failed_note(r, metric.name) for r in tied}
            value = cells.pop() if len(cells) == 1 else f"{_fmt(mean_of[id(best)])} (each)"
            rows.append([table.task, dataset, metric.by_alignment.get(alignment, metric.label),
                         _short_label(best, table) if len(tied) == 1 else
                         "tie: " + ", ".join(_short_label(r, table) for r in tied),
                         value + _seeds_note(best, ranked, common, metric.name),
                         str(len({(r.experiment, r.method) for r in candidates}))])  # (rows: a method in 2 experiments is 2)
    return header, rows


def _common_seeds(rows: list[Row], metric: str) -> frozenset[int]:
    """The seeds on which every row has a value of ``metric`` (empty when they share none)."""
    return frozenset.intersection(*(frozenset(r.values.get(metric, ())) for r in rows)) if rows else frozenset()


def _mean_over(row: Row, metric: str, seeds: frozenset[int]) -> float:
    """``row``'s mean of ``metric`` over ``seeds`` (over all its seeds when ``seeds`` is empty)."""
    if not seeds:
        return row.stats[metric][0]
    return float(np.mean([row.values[metric][s] for s in sorted(seeds)]))


def _seeds_note(best: Row, ranked: list[Row], common: frozenset[int], metric: str) -> str:
    """What the Summary's ranking was over when the rows ranked ran other seeds (a method over seeds 1 and 3 was named
    best against kiss over 0-4, where on seeds 1 and 3 kiss was better), else '': the common seeds it ranked them on
    (and the best row's mean over them where its cell is over more), or that they share none."""
    seeds_of = [frozenset(r.values.get(metric, ())) for r in ranked]
    if len(set(seeds_of)) < 2:
        return ""
    if not common:
        return (f" (seeds {_seed_list(best.values.get(metric, ()))}; the others ran other seeds, none in common: each "
                "ranked over its own)")
    there = "" if common == frozenset(best.values.get(metric, ())) else f": {_fmt(_mean_over(best, metric, common))} there"
    return f" (ranked on the common seeds {_seed_list(common)}{there})"


def _seed_list(seeds: Any) -> str:
    return ", ".join(str(s) for s in sorted(seeds))


def _n_no_value(row: Row, metric: str) -> int:
    """Seeds that ran but gave ``metric`` no finite value (NaN, inf, null): left out of the cell's numbers. 0 when no
    seed has one (the cell is a dash: a metric the method does not report)."""
    n = row.stats[metric][2]
    return row.n_ok - n if n > 0 else 0


def _failed_note(row: Row, metric: str, failures: bool = True) -> str:
    """`` (3 of 5 failed)`` / `` (4 of 12 not run)`` / `` (1 of 3 unreadable)`` / `` (2 of 3 no value)`` for a row some
    of whose seeds failed, have no result yet, a result file that cannot be read (they ran: it was "not run") or gave
    ``metric`` no finite value (its numbers are over the others), and `` (1 of 3 kept after a failed rerun)`` for ok
    results a failed ``--force`` rerun left (it re-ran nothing they say), else ''; ``failures=False``: neither of those
    (a table whose ok/failed column says them; the seeds not run it does not)."""
    total = row.n_ok + row.n_failed + row.n_missing
    n_no_value = _n_no_value(row, metric)
    n_not_run = row.n_missing - row.n_unreadable
    notes = ([f"{row.n_failed} of {total} failed"] * bool(failures and row.n_failed)
             + [f"{n_not_run} of {total} not run"] * bool(n_not_run)
             + [f"{row.n_unreadable} of {total} unreadable"] * bool(row.n_unreadable)
             + [f"{n_no_value} of {total} no value"] * bool(n_no_value)
             + [f"{row.n_rerun_failed} of {total} kept after a failed rerun"] * bool(failures and row.n_rerun_failed))
    return f" ({', '.join(notes)})" if notes else ""


def _better_higher(task: str, metric: str) -> bool:
    from lidarkit.bench.tasks import higher_is_better

    return higher_is_better(metric, task)


def _short_label(row: Row, table: TaskTable) -> str:
    return row.method if len({r.experiment for r in table.rows}) == 1 else f"{row.experiment}: {row.method}"


def statistics_rows(table: TaskTable) -> tuple[list[str], list[list[str]]]:
    """Per (dataset, method): the dataset's headline metric's n, mean, std, median and 95 % CI of the mean over seeds
    (a ``headline metric`` column after the dataset where datasets have different ones), the header naming the
    interval's method (Student-t's)."""
    from lidarkit.eval.statistics import ci_methods

    headlines = headline_metrics(table)
    several = len({m.name for m in headlines.values()}) > 1
    header = ["dataset", *(["headline metric"] if several else []), "method", "n", "mean", "std", "median", "95 % CI"]
    if not headlines:
        return header, []
    method = ci_methods(r.summaries.get(headlines[r.dataset].name) for r in table.rows)
    header[-1] = f"95 % CI ({method})" if method else header[-1]
    rows = []
    for r in table.rows:
        metric = headlines[r.dataset]
        s = r.summaries.get(metric.name)
        if s is None or s.n == 0:
            continue
        std = r.stats[metric.name][1]  # (the cells' std: seeds equal up to round-off have none)
        rows.append([r.dataset, *([metric.label] if several else []), _short_label(r, table), str(s.n), _fmt(s.mean),
                     _fmt(std) if s.n > 1 else "–", _fmt(s.median),
                     f"[{_fmt(s.ci_low)}, {_fmt(s.ci_high)}]" if s.n > 1 else "–"])
    return header, rows


def _html(report: Report, title: str) -> str:
    """One self-contained page: summary table first, then one section per task (tables, statistics, plots with
    captions, and for odometry the publication tables and paired comparisons), then what did not run."""
    e = html.escape
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en">',
        "<head>",
        '<meta charset="utf-8">',
        f"<title>{e(title)}</title>",
        f"<style>{_CSS}</style>",
        "</head>",
        "<body>",
        f"<h1>{e(title)}</h1>",
        f"<p>Generated {datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC from {report.n_records} job results{e(coverage_text(report))}. "
        "Cells: mean ± std over seeds (sample std).</p>",
    ]
    header, rows = summary_rows(report)
    if rows:
        parts += ['<section id="summary">', "<h2>Summary</h2>",
                  _table_html(header, rows, n_left=4, caption="Best method per task and dataset on the headline metric"),
                  "</section>"]
    for table in report.tables:
        parts.append(f'<section id="task-{e(_slug(table.task))}">')
        parts.append(f"<h2>{e(table.task)}</h2>")
        description = _task_description(table.task)
        if description:
            parts.append(f"<p>{e(description)}</p>")
        for m, datasets in _pivot_views(table):
            header, rows = pivot(table, m.name, datasets)
            parts.append(_table_html(header, rows, caption=f"{m.label}: methods x datasets"))
        header, rows = statistics_rows(table)
        n_column = header.index("n")
        if rows and any(r[n_column] not in ("0", "1") for r in rows):
            parts.append(_table_html(header, rows, n_left=n_column, caption="Statistics over seeds of the headline "
                                     + ("metric" if n_column == 2 else "metric of each dataset")))
        header, rows = _table_rows(table)
        parts.append("<details><summary>All metrics</summary>")
        parts.append(_table_html(header, rows, n_left=4))
        parts.append("</details>")
        pub = report.publication
        if table.task == "odometry" and pub is not None:
            if pub.comparisons:
                parts.append(_table_html(*comparison_rows(pub.comparisons), n_left=3,
                                         caption="Paired comparisons with the reference (Wilcoxon signed-rank)"))
            notes = comparison_notes(pub.comparisons) + [f"no comparison: {line}" for line in pub.not_compared]
            if notes:
                parts += ["<ul>", *(f"<li>{e(line)}</li>" for line in notes), "</ul>"]
            if pub.tables:
                parts.append("<h3>Publication tables</h3>")
                parts.append("<p>Also as Markdown, CSV and LaTeX (booktabs) in <code>tables/</code>. "
                             "Bold: best method per row.</p>")
                parts += [_pubtable_html(t) for t in pub.tables]
                for caption, path in pub.boxplots:
                    parts.append(_figure_html(path.read_bytes(), caption, caption))
        task_plots = [p for p in report.plots if p.task == table.task]
        if task_plots:
            parts.append("<h3>Plots</h3>")
            parts += [_figure_html(p.png, p.title, p.caption or p.title) for p in task_plots]
        parts.append("</section>")
    other = [p for p in report.plots if p.task not in {t.task for t in report.tables}]
    if other:
        parts.append("<section><h2>Other plots</h2>")
        parts += [_figure_html(p.png, p.title, p.caption or p.title) for p in other]
        parts.append("</section>")
    sections = (
        ("Experiments not run", [f"<li>{e(name)}: {e(reason)}</li>" for name, reason in report.skipped]),
        ("Jobs of the suite without a result", [f"<li>{e(line)}</li>" for line in _not_run_lines(report)]),
        ("Warnings logged by jobs", [f"<li>{e(label)}: {e(message)}</li>" for label, message in report.warnings]),
        ("Failed jobs", [
            f'<li class="failed"><code>{e(f["key"])}</code> {e(f["label"])}: {e(f["error"])}</li>'
            for f in report.failures + report.rerun_failures
        ]),
    )
    for heading, items in sections:
        if items:
            parts += [f"<section><h2>{heading}</h2>", "<ul>", *items, "</ul></section>"]
    parts += ["</body>", "</html>", ""]
    return "\n".join(parts)


def comparison_rows(comparisons: list[Any]) -> tuple[list[str], list[list[str]]]:
    """Rows of paired comparisons ``(dataset, PairedComparison)``: who, units, means, p, effect, the median difference
    with its 95 % CI, verdict. A p below alpha beside "no significant difference" says why when the CI includes 0
    (compare's rule: p = 0.049 read as a contradiction without it); p is printed as compare prints it."""
    header = ["dataset", "A", "B", "paired units", "mean A", "mean B", "p", "effect", "median A - B (95 % CI)", "verdict"]
    rows = []
    for dataset, c in comparisons:
        verdict = (f"{c.name_a if c.better == 'a' else c.name_b} better" if c.better else "no significant difference")
        if not c.better and c.p_value < c.alpha and c.diff_ci_low <= 0 <= c.diff_ci_high:
            verdict += " (CI includes 0)"
        if not c.better:
            verdict += _too_few_units(c)
        if c.pairing == "segment":  # (overlapping KITTI segments of few seeds: see publication.OVERLAPPING_SEGMENTS)
            verdict += " (overlapping segments: p optimistic)"
        if c.repeated:  # (p = 0.031 and effect -1.00 beside "no significant difference"; compare prints no test)
            verdict = "one measurement repeated (every seed gave each side the same value): no test"
        rows.append([dataset, c.name_a, c.name_b, f"{c.n_pairs} {c.pairing}s ({c.metric})", _fmt(c.mean_a),
                     _fmt(c.mean_b), "–" if c.repeated else format_p(c.p_value, c.alpha),
                     "–" if c.repeated else f"{c.effect_size:+.2f}",
                     f"{c.median_diff:+.3g} [{c.diff_ci_low:+.3g}, {c.diff_ci_high:+.3g}]", verdict])
    return header, rows


def _too_few_units(c: Any) -> str:
    """`` (5 seeds: smallest possible p 0.0625)`` where the comparison's units cannot reach p < alpha whatever they show
    (``PairedComparison.verdict`` says it in full; the row said "no significant difference" alone), else ''."""
    from lidarkit.eval.statistics import min_units

    n_ranked = c.n_pairs - c.n_ties  # (tied units are not ranked)
    if n_ranked == 0:
        return " (every paired difference is zero)"
    if n_ranked >= min_units(c.alpha):
        return ""
    units = f"{n_ranked} {c.pairing}{'s' * (n_ranked > 1)}"
    units += "" if n_ranked == c.n_pairs else f" of {c.n_pairs} differing"
    return f" ({units}: smallest possible p {2.0 ** (1 - n_ranked):.3g})"


def comparison_notes(comparisons: list[Any]) -> list[str]:
    """What each paired comparison's table row cannot say ("dataset, A vs B: note"): segments that overlap or were left
    out, sides scored against the ground truth at other instants of the sweep."""
    return [f"{dataset}, {c.name_a} vs {c.name_b}: {c.note}" for dataset, c in comparisons if c.note]


def _task_description(task: str) -> str:
    try:
        from lidarkit.bench.tasks import get_task

        return get_task(task).description
    except Exception:  # noqa: BLE001 - metadata is optional for the report
        return ""


def latest_per_job(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """One record per job spec: results of the same job from other lidarkit versions are superseded by the
    most recently finished one (so a folder reused across versions does not count a seed twice)."""
    from lidarkit.bench.jobs import canonical_json

    latest: dict[str, dict[str, Any]] = {}
    for r in records:
        spec = canonical_json(r["job"])
        if spec not in latest or str(r.get("finished_utc", "")) > str(latest[spec].get("finished_utc", "")):
            latest[spec] = r
    kept = {id(r) for r in latest.values()}
    return [r for r in records if id(r) in kept]


def build_report(
    out_dir: str | Path, *, title: str | None = None, plots: bool = True, only_keys: set[str] | None = None, every_result: bool = False,
) -> Report:
    """Read ``out_dir/jobs/*.json`` and write ``report.md``, ``report.csv``, ``report.html`` and ``plots/*.png`` there.

    ``only_keys``: restrict to these job keys (e.g. the suite just run). By default the report holds the jobs of the
    folder's ``suite.json`` (the last suite run there: results an earlier suite left in the folder are counted as
    left out, and the suite's jobs without a result as not run); ``every_result``: every result in the folder.
    """
    from lidarkit.run_files import is_baseline_folder

    out_dir = path_argument(out_dir, "out_dir")
    if is_baseline_folder(out_dir):  # (read "no readable job results in jobs/")
        raise DataError("a baseline folder (lidarkit baseline record): report takes bench results folders (`lidarkit "
                        "baseline check` re-runs a baseline's jobs against it)", source=out_dir)
    out_dir = results_folder(out_dir)
    records = load_results(out_dir)
    if not records:  # (said before what suite.json would restrict them to)
        raise DataError("no readable job results in jobs/", source=out_dir)
    # (a damaged suite.json read as none: the report widened to every result in the folder, without a word)
    manifest = suite_manifest(out_dir) if every_result else read_suite_manifest(out_dir)
    suite_jobs = {} if every_result else _suite_jobs(manifest)
    if only_keys is None and suite_jobs:
        only_keys = set(suite_jobs)
    every_record = records
    if only_keys is not None:
        records = [r for r in records if r["key"] in only_keys]
    records = latest_per_job(records)
    if not records:
        raise DataError("no readable job results in jobs/" + (" for the jobs of suite.json (--all, or every_result=True: all of them)" if suite_jobs else ""),
                        source=out_dir)
    if title is None:
        title = _suite_title(manifest)
    done = {r["key"] for r in records}
    expected = {k: spec for k, spec in suite_jobs.items() if only_keys is None or k in only_keys}
    missing = {k: spec for k, spec in expected.items() if k not in done}
    unreadable = {k for k in missing if result_path(out_dir, k).exists()}  # (load_results logged why)
    n_left_out, n_earlier_version = left_out_counts(every_record, records, expected.values())
    unknown_tasks = import_task_modules(records + [{"job": spec} for spec in missing.values()], manifest)
    sweeps_unknown = set()  # tasks whose results predate the record of their sweeps: their earlier figures are kept
    for task, why in unknown_tasks.items():
        recs = [r for r in records if r["job"]["task"] == task]
        declared = recorded_metrics(recs)
        if not any(isinstance(r.get("sweep_plots"), list) for r in recs):
            sweeps_unknown.add(task)
            sweeps = " and its sweep figures in plots/ are kept"
        else:
            sweeps = " and its sweep figures drawn as its results record them" if recorded_sweeps(recs) else ""
        log.warning("task %r: %s; its metrics are shown %s%s", task, why,
                    "as its results declare them" if declared else "by name", sweeps)
    report = Report(out_dir=out_dir, tables=aggregate(records, list(missing.values()), [missing[k] for k in unreadable]),
                    n_records=len(records), skipped=_skipped(manifest), n_expected=len(expected), n_left_out=n_left_out,
                    n_earlier_version=n_earlier_version, versions=version_counts(records),
                    not_run=[_label({"job": spec}) + (" (its result file cannot be read: see the log)" if k in unreadable else "")
                             for k, spec in missing.items()], n_unreadable=len(unreadable))
    n_warnings = 0
    for r in records:
        for message in r.get("warnings") or []:
            n_warnings += 1
            if len(report.warnings) < MAX_LISTED_WARNINGS:
                report.warnings.append((_label(r), message))
        if r.get("status") != "ok":
            err = r.get("error") or {}
            report.failures.append({"key": r["key"], "label": _label(r), "error": f"{err.get('type')}: {err.get('message')}"})
        elif isinstance(r.get("rerun_failed"), dict):  # (the report said nothing of the failed rerun)
            err = r["rerun_failed"].get("error") or {}
            report.rerun_failures.append({"key": r["key"], "label": _label(r), "error": (
                f"forced rerun failed: {err.get('type')}: {err.get('message')}; the earlier ok result is shown")})
    if n_warnings > MAX_LISTED_WARNINGS:  # (the list stopped at 100 without a word)
        report.warnings.append(("...", f"and {n_warnings - MAX_LISTED_WARNINGS} more job warnings (each job's in jobs/<key>.json)"))
    texts = [out_dir / "report.md", out_dir / "report.csv", out_dir / "report.html"]
    for path in texts:  # (a report file that cannot be written is refused before any figure or table is)
        atomic.check_target(path)
    from lidarkit.bench.publication import build_publication, remove_stale_tables

    # figures, tables and texts are written aside and moved in together: a report that fails keeps the earlier one
    # whole (its texts stayed beside this one's new figures when tables/ could not be written)
    # (which figures, why) when figures cannot be drawn: the tables and texts are written without them, then it is said
    not_drawn: tuple[str, LidarKitError] | None = None
    with atomic.run_folder(out_dir) as tmp:
        if plots:
            try:
                report.plots = make_plots(records)
            except LidarKitError as err:
                not_drawn = ("no figures", err)
            for p in report.plots:
                atomic.write_bytes(tmp / "plots" / p.filename, p.png)
        try:
            report.publication = build_publication(records, tmp, plots=plots and not_drawn is None)
        except Exception as err:  # noqa: BLE001 - a box plot matplotlib cannot draw: the tables without it
            if not plots or not_drawn is not None or isinstance(err, OutputError):
                raise
            report.publication = build_publication(records, tmp, plots=False)  # (its own error, if not a figure's)
            not_drawn = ("no segment box plots", err if isinstance(err, LidarKitError) else OutputError(
                f"they cannot be drawn ({type(err).__name__}: {' '.join(str(err).split())[:300]})"))
        if not_drawn is not None:
            report.warnings.insert(0, ("report", f"{not_drawn[0]}: {not_drawn[1]}"))
        for path, text in zip(texts, (_markdown(report, title), _csv(report), _html(report, title))):
            atomic.write_text(tmp / path.name, text)
    report.markdown_path, report.csv_path, report.html_path = texts
    pub = report.publication
    pub.files = [out_dir / path.relative_to(tmp) for path in pub.files]
    pub.boxplots = [(caption, out_dir / path.relative_to(tmp)) for caption, path in pub.boxplots]
    # an earlier report's figures and tables this one does not draw go (all figures with plots=False); only files of
    # the names a report writes (a figure a user put in plots/ is kept), as run folders remove an earlier run's; the
    # sweep figures of a task whose module is not loaded here and whose results do not record its sweeps stay (this
    # report could not draw them)
    drawn = {p.filename for p in report.plots} | {path.name for _, path in pub.boxplots}
    undrawable = tuple(f"sweep_{_slug(task)[:72]}_" for task in sweeps_unknown)
    for stale in (out_dir / "plots").glob("*.png"):
        if stale.name not in drawn and _OWN_FIGURE.fullmatch(stale.name) and not stale.name.startswith(undrawable):
            stale.unlink()
    remove_stale_tables(out_dir, pub)
    if not_drawn is not None:
        what, err = not_drawn
        raise OutputError(f"{what} ({err}); report.md, report.csv and report.html are written without them",
                          source=out_dir)
    return report


def _label(record: dict[str, Any]) -> str:
    job = Job.from_spec(record["job"])
    return f"{job.task} | {job.experiment} | {job.dataset_name} | {job.method_label} | seed {job.seed}"


def suite_manifest(out_dir: Path) -> dict[str, Any]:
    """The folder's ``suite.json`` (the last suite run there), read once per report; {} without a readable one (what
    every result is read with: ``--all``, and the task modules it records)."""
    try:
        return read_suite_manifest(out_dir)
    except DataError:
        return {}


def read_suite_manifest(out_dir: Path) -> dict[str, Any]:
    """The folder's ``suite.json``, {} where there is none (every result is the folder's suite); DataError naming the
    file and why for one that cannot be read or lists no jobs (truncated, ``{``): read as none, a report widened to an
    earlier suite's results too and lost its title. ``--all`` takes every result without it."""
    path = Path(out_dir) / "suite.json"
    if not path.exists() and not path.is_symlink():
        return {}
    try:
        manifest = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as err:
        why = f"not valid JSON ({err.msg}, line {err.lineno} column {err.colno})"
    except UnicodeDecodeError:
        why = "not UTF-8 text"
    except OSError as err:
        why = f"cannot be read ({err.strerror or err})"
    else:
        if not isinstance(manifest, dict):
            why = f"holds a JSON {type(manifest).__name__}, not a suite's manifest"
        elif not _suite_jobs(manifest):
            why = "lists no jobs (its 'jobs' is missing, empty or malformed)"
        else:
            return manifest
    raise DataError(f"{why}: which results are this suite's is unknown (--all: every result in the folder)",
                    source=path)


def _suite_jobs(manifest: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """``{key: job spec}`` of a suite manifest, {} without a readable job list."""
    try:
        return {str(j["key"]): {k: v for k, v in j.items() if k != "key"} for j in manifest["jobs"]}
    except (KeyError, TypeError, AttributeError):
        return {}


def left_out_counts(every: list[dict[str, Any]], held: list[dict[str, Any]], specs: Any = ()) -> tuple[int, int]:
    """``(results of every not held, of those the results of a held job or a suite's ``specs`` from another lidarkit
    version)``: a job's key hashes its spec and the code's version, so a result left out with the spec of a job held
    here is that job run by another version (they were called an earlier suite's, and counted once per spec: too few).
    What the report and a comparison of the folder say they left out."""
    kept = {id(r) for r in held}
    own = {canonical_json(r["job"]) for r in held} | {canonical_json(spec) for spec in specs}
    left_out = [r for r in every if id(r) not in kept]
    return len(left_out), sum(canonical_json(r["job"]) in own for r in left_out)


def suite_jobs(out_dir: str | Path) -> dict[str, dict[str, Any]]:
    """``{key: job spec}`` of the folder's ``suite.json`` (the last suite run there); {} without one, DataError for one
    that cannot be read (:func:`read_suite_manifest`). What a report, and a comparison of the folder, is restricted to
    by default."""
    return _suite_jobs(read_suite_manifest(Path(out_dir)))


def _skipped(manifest: dict[str, Any]) -> list[tuple[str, str]]:
    try:
        return [(str(s["experiment"]), str(s["reason"])) for s in manifest.get("skipped_experiments", [])]
    except (KeyError, TypeError):
        return []


def _suite_title(manifest: dict[str, Any]) -> str:
    return f"lidarkit benchmark report: {manifest['suite']}" if "suite" in manifest else "lidarkit benchmark report"
