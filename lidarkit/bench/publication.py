"""Publication tables of a bench results folder: KITTI drift per dataset x method with the devkit average row,
per length, per speed, APE/RPE, and box plots of the per-segment errors (odometry results only).

Seeds of one (dataset, method) are pooled: their segments together, their APE/RPE averaged.
"""

from __future__ import annotations

import dataclasses
import logging
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from lidarkit.bench.jobs import Job
from lidarkit.bench.results import dataset_labels, ground_truth_instant
from lidarkit.eval.statistics import DEFAULT_ALPHA, min_units, spread_is_round_off
from lidarkit.eval.tables import PubTable, SegmentErrors, publication_tables

log = logging.getLogger(__name__)

TABLES_DIR = "tables"


@dataclass
class Publication:
    """The tables (also written as ``tables/<name>.{md,csv,tex}``) and the box-plot files of a report."""

    tables: list[PubTable] = field(default_factory=list)
    files: list[Path] = field(default_factory=list)
    boxplots: list[tuple[str, Path]] = field(default_factory=list)  # (caption, png path)
    comparisons: list[tuple[str, Any]] = field(default_factory=list)  # (dataset, PairedComparison) vs the reference
    not_compared: list[str] = field(default_factory=list)  # "dataset, kiss vs X: why no comparison was made"


def odometry_labels(records: list[dict[str, Any]]) -> dict[int, str]:
    """Dataset labels of the odometry records, told apart among those alone as the report's odometry section does
    (another task's options on the same dataset labelled them "K00(frames=0:3)" where the section said K00)."""
    return dataset_labels([r for r in records if r["job"]["task"] == "odometry"])


@dataclass
class _Grids:
    """What the publication tables are built from, per (dataset, method) unless said otherwise."""

    segments: dict[tuple[str, str], SegmentErrors]
    ape: dict[tuple[str, str], float]
    rpe: dict[tuple[str, str], float]
    seeds_note: str
    rpe_step: dict[str, str]  # dataset -> "frame" | "selected frame" (the step of its RPE)
    selection: dict[str, str]  # dataset -> its frame selection as the suite wrote it ('' for every frame)
    steps: dict[str, tuple[int, ...] | None]  # dataset -> the dataset frames between its selected frames (step_pattern)
    not_registered: dict[tuple[str, str], str]  # runs most of whose frames did not register -> what to say of them


def _grids(records: list[dict[str, Any]]) -> _Grids:
    """Per (dataset, method): KITTI segments pooled over seeds, mean APE and RPE, over the seeds every method of the
    dataset has a result for (as ``lidarkit compare`` pairs them: a method over seeds 1 and 3 was set bold against
    kiss over 0-4, where on seeds 1 and 3 kiss was better); a note naming what was left out ('' when nothing); each
    dataset's RPE step; and the cells whose runs mostly did not register (their poses the fallback motion's)."""
    from lidarkit.bench.tasks.odometry import SELECTED_FRAME

    segments: dict[tuple[str, str], list[SegmentErrors]] = defaultdict(list)
    ape: dict[tuple[str, str], list[float]] = defaultdict(list)
    rpe: dict[tuple[str, str], list[float]] = defaultdict(list)
    label = odometry_labels(records)
    ok = [r for r in records if r.get("status") == "ok" and r["job"]["task"] == "odometry"]
    seeds: dict[str, dict[str, set[int]]] = defaultdict(lambda: defaultdict(set))
    for r in ok:
        seeds[label[id(r)]][Job.from_spec(r["job"]).method_label].add(int(r["job"]["seed"]))
    common = {dataset: set.intersection(*methods.values()) for dataset, methods in seeds.items()}
    left = {dataset: {method: sorted(s - common[dataset]) for method, s in methods.items() if s - common[dataset]}
            for dataset, methods in seeds.items() if common[dataset]}
    note = "; ".join([f"{dataset}: seeds {_seed_list(common[dataset])} of every method (left out: "
                      + ", ".join(f"{method} {_seed_list(s)}" for method, s in sorted(methods.items())) + ")"
                      for dataset, methods in sorted(left.items()) if methods]
                     + [f"{dataset}: no seed common to every method (each over its own seeds)"
                        for dataset in sorted(common) if not common[dataset]])
    rpe_step: dict[str, str] = {}
    selection: dict[str, str] = {}
    steps: dict[str, tuple[int, ...] | None] = {}
    registration: dict[tuple[str, str], list[tuple[int, int]]] = defaultdict(list)  # (not registered, registrations)
    for r in ok:
        job = Job.from_spec(r["job"])
        key = (label[id(r)], job.method_label)
        if common[key[0]] and job.seed not in common[key[0]]:  # (no seed in common: each method over its own)
            continue
        seg = (r.get("series") or {}).get("drift_segments")
        if seg:
            segments[key].append(SegmentErrors.from_dict(seg))
        metrics = r.get("metrics") or {}
        if _has_value(metrics.get("ape_rmse_m")):
            ape[key].append(float(metrics["ape_rmse_m"]))
        if _has_value(metrics.get("rpe_trans_rmse_m")):
            rpe[key].append(float(metrics["rpe_trans_rmse_m"]))
        # (the RPE of a run over a frame selection that skips frames is per selected frame)
        skips = ((r.get("info") or {}).get("metric_alignment") or {}).get("rpe_trans_rmse_m") == SELECTED_FRAME
        if skips or key[0] not in rpe_step:
            rpe_step[key[0]] = "selected frame" if skips else "frame"
        selection.setdefault(key[0], _selection_text(job.options.get("frames")))
        steps.setdefault(key[0], step_pattern(job.options.get("frames")))
        if _has_value(metrics.get("n_not_converged")) and _has_value(metrics.get("n_frames")):
            registration[key].append((int(metrics["n_not_converged"]), max(int(metrics["n_frames"]) - 1, 0)))
    merged = {k: SegmentErrors(*(np.concatenate([getattr(s, f) for s in v]) for f in
                                 ("length_m", "translation_pct", "rotation_deg_per_100m", "speed_mps")))
              for k, v in segments.items()}
    return _Grids(merged, {k: float(np.mean(v)) for k, v in ape.items()}, {k: float(np.mean(v)) for k, v in rpe.items()},
                  note, rpe_step, selection, steps, _not_registered(registration))


def _not_registered(registration: dict[tuple[str, str], list[tuple[int, int]]]) -> dict[tuple[str, str], str]:
    """The cells one of whose runs did not register more than half of its frames after the first (each such frame's
    pose is the fallback motion's: a run that never registered stays at the origin, and on a short drive its APE was
    set bold as the best), with what their mark says: "no frame registered" or "N of the M frames after the first not
    registered" (over the cell's seeds)."""
    out = {}
    for key, runs in registration.items():
        if not any(attempted and 2 * failed > attempted for failed, attempted in runs):
            continue
        failed, attempted = (sum(x) for x in zip(*runs))
        seeds = f" (over {len(runs)} seeds)" if len(runs) > 1 else ""
        out[key] = ("no frame registered" if failed >= attempted
                    else f"{failed} of the {attempted} frames after the first not registered") + seeds
    return out


def _selection_text(frames: Any) -> str:
    """A frame selection as the suite wrote it, short ('' for every frame)."""
    if frames is None:
        return ""
    if isinstance(frames, list):
        shown = ", ".join(str(f) for f in frames[:6])
        return f"[{shown}{', ...' if len(frames) > 6 else ''}]"
    return str(frames)


def step_pattern(frames: Any) -> tuple[int, ...] | None:
    """The dataset frames between consecutive frames of a selection as the suite wrote it: one number for a constant
    step (``"0:10:3"`` and ``[0, 3, 6]``: ``(3,)``; every frame: ``(1,)``), each step otherwise (``[0, 3, 4, 9]``:
    ``(3, 1, 5)``); None for a selection not read here. RPEs per selected frame of two patterns are over other steps."""
    if frames is None:
        return (1,)
    if isinstance(frames, str):
        parts = frames.split(":")
        if len(parts) not in (2, 3):
            return None
        step = parts[2].strip() if len(parts) == 3 else ""
        if not step:
            return (1,)
        return (int(step),) if step.isdigit() else None
    if isinstance(frames, list) and len(frames) > 1 and all(isinstance(f, int) for f in frames):
        diffs = tuple(int(d) for d in np.diff(frames))
        return diffs[:1] if len(set(diffs)) == 1 else diffs
    return None


def _pattern_text(steps: tuple[int, ...] | None) -> str:
    """A :func:`step_pattern` in words: "a step of 3 frames", "steps of 3, 1, 5 frames"."""
    if steps is None:
        return "steps not known"
    if len(steps) == 1:
        return f"a step of {steps[0]} frame{'s' * (steps[0] != 1)}"
    shown = ", ".join(str(d) for d in steps[:8]) + (", ..." if len(steps) > 8 else "")
    return f"steps of {shown} frames"


def _has_value(x: Any) -> bool:
    """A finite number: NaN and inf are no value, as in report.csv (one NaN seed made a method's mean NaN, shown as
    "–", and the other method bold)."""
    return x is not None and np.isfinite(float(x))


def _seed_list(seeds: Any) -> str:
    return ", ".join(str(s) for s in sorted(seeds))


REFERENCE_METHOD = "kiss"
#: said of a comparison over KITTI segments (fewer seeds than the test needs to reach p < alpha: ``min_units``)
OVERLAPPING_SEGMENTS = ("the segments overlap (one starts every 10 frames): they are not independent units and the p-value "
                        f"is optimistic; with {min_units(DEFAULT_ALPHA)} or more seeds the units are the seeds (lidarkit "
                        "compare)")


def reference_comparisons(records: list[dict[str, Any]], reference: str = REFERENCE_METHOD, *,
                          not_compared: list[str] | None = None) -> list[tuple[str, Any]]:
    """Paired Wilcoxon comparisons of the reference method with every other method, per dataset.

    Units: the common seeds when they are enough for the test to reach p < 0.05 (``min_units``: 6; 5 give 0.0625 at
    best, and their "no significant difference" could not be otherwise), their KITTI drift, else APE RMSE (the first
    with a value on both sides of every common seed, else of enough of them; ``lidarkit compare`` pairs the same units
    and defaults to the report's headline metric); with fewer, the KITTI segments of
    every common seed (same ground truth, so the same segments), with a note that they overlap (one starts every 10
    frames: not independent, the p-value is optimistic; the report said "kiss better" where compare, over the 2 seeds,
    said no difference); a dataset without enough units is left out, and why is appended to ``not_compared`` (the
    section had vanished without a word).
    """
    from lidarkit.bench.tasks.odometry import METRIC_ALIGNMENT_BY_NAME
    from lidarkit.errors import LidarKitError
    from lidarkit.eval.statistics import paired_test

    # the metrics a comparison over seeds pairs, in the order it prefers them, by their units' label; the label names
    # the APE's alignment as every APE label does ("APE RMSE m" read as the headline SE(3)-aligned APE)
    seed_metrics = {"drift_translation_pct": "KITTI drift %",
                    "ape_rmse_m": f"APE RMSE ({METRIC_ALIGNMENT_BY_NAME['ape_rmse_m']}) m"}

    per: dict[str, dict[str, dict[int, dict[str, Any]]]] = defaultdict(lambda: defaultdict(dict))
    ran: dict[str, dict[str, str]] = defaultdict(dict)  # dataset -> method label -> its method, ok or not
    label = odometry_labels(records)
    for r in records:
        if r["job"]["task"] != "odometry":
            continue
        job = Job.from_spec(r["job"])
        ran[label[id(r)]][job.method_label] = job.method
        if r.get("status") == "ok":
            per[label[id(r)]][job.method_label][job.seed] = r
    out = []
    for dataset, methods in per.items():
        if reference not in methods:
            # (the dataset's comparisons were gone without a word; a suite that runs no reference at all is left be)
            why = _no_reference_reason(reference, ran[dataset], ran)
            # (without a plain reference row, its runs with params are the reference's, not methods compared with it)
            others = [m for m in sorted(methods) if reference in ran[dataset] or ran[dataset][m] != reference]
            for other in others if why and not_compared is not None else ():
                log.info("no paired comparison %s vs %s on %s: %s", reference, other, dataset, why)
                not_compared.append(f"{dataset}, {reference} vs {other}: {why}")
            continue
        ref = methods[reference]
        for label, runs in methods.items():
            if label == reference:
                continue
            seeds = sorted(set(ref) & set(runs))
            segs = [((ref[s].get("series") or {}).get("drift_segments"), (runs[s].get("series") or {}).get("drift_segments"))
                    for s in seeds]
            try:
                # the seeds with a value on both sides, per metric (a task's NaN is written as null: no value, as a
                # metric the run did not report); the first metric with one on every seed, else on enough of them
                valued_of = {metric: [s for s in seeds if all(_has_value(side[s]["metrics"].get(metric))
                                                              for side in (ref, runs))] for metric in seed_metrics}
                enough = [m for m in seed_metrics if len(valued_of[m]) >= min_units(DEFAULT_ALPHA)]
                metric = next((m for m in enough if len(valued_of[m]) == len(seeds)), enough[0] if enough else None)
                if metric is not None:
                    valued = valued_of[metric]
                    va = [ref[s]["metrics"][metric] for s in valued]
                    vb = [runs[s]["metrics"][metric] for s in valued]
                    result = paired_test(va, vb, name_a=reference, name_b=label, metric=seed_metrics[metric],
                                         pairing="seed")
                    notes = [f"seed(s) {_seed_list(set(seeds) - set(valued))} left out: no value (NaN, inf) on one side"
                             ] if len(valued) < len(seeds) else []
                elif seeds and (paired := _paired_segments(segs)) is not None:
                    va, vb, left, once = paired
                    result = paired_test(va, vb, name_a=reference, name_b=label, metric="KITTI drift %", pairing="segment")
                    notes = [OVERLAPPING_SEGMENTS] + ([f"{left} KITTI segment(s) on only one side's ground truth left out "
                                                        "(paired by first frame and length)"] if left else [])
                    notes += [f"the {len(seeds)} seeds ran the same data (each side's segments alike on every seed): "
                              "their segments counted once"] if once else []
                else:
                    why = _no_comparison_reason(ref, runs, seeds, valued_of)
                    log.info("no paired comparison %s vs %s on %s: %s", reference, label, dataset, why)
                    if not_compared is not None:
                        not_compared.append(f"{dataset}, {reference} vs {label}: {why}")
                    continue
                instants = [sorted({ground_truth_instant(side[s]) for s in seeds} - {""}) for side in (ref, runs)]
                if all(instants) and instants[0] != instants[1]:  # (as lidarkit compare notes it)
                    notes.append(f"each side is scored against the ground truth at its own instant of the sweep ({reference}: "
                                 f"{' / '.join(instants[0])}, {label}: {' / '.join(instants[1])})")
                out.append((dataset, dataclasses.replace(result, note="; ".join(notes))))
            except LidarKitError as err:  # (said in the report: the section had vanished, the reason only logged)
                log.info("no paired comparison %s vs %s on %s: %s", reference, label, dataset, err)
                if not_compared is not None:
                    not_compared.append(f"{dataset}, {reference} vs {label}: {err}")
    return out


def _no_reference_reason(reference: str, on_dataset: dict[str, str], every: dict[str, dict[str, str]]) -> str:
    """Why a dataset has no ok run of the plain ``reference`` (``on_dataset``: its method labels -> their method;
    ``every``: those of every dataset): its runs failed, it ran with params only (the comparison pairs the plain
    method's row), or it did not run there; '' where the suite runs the reference nowhere."""
    if reference in on_dataset:
        return f"{reference} has no ok result on this dataset"
    with_params = sorted(label for label, method in on_dataset.items() if method == reference)
    if with_params:
        return f"no plain {reference} row (it ran as {', '.join(with_params)})"
    if any(method == reference for labels in every.values() for method in labels.values()):
        return f"{reference} did not run on this dataset"
    return ""


def _no_comparison_reason(ref: dict[int, dict[str, Any]], runs: dict[int, dict[str, Any]], seeds: list[int],
                          valued_of: dict[str, list[int]]) -> str:
    """Why two methods' runs on one dataset were not compared: too few common seeds with a value on both sides of a
    metric a comparison over seeds pairs (``valued_of``: metric -> those seeds; the seeds without one named) and no
    KITTI segments, or that the dataset has no APE nor KITTI drift (a CARMEN log scored by its relations was said to
    have "6 common seed(s) (a comparison over seeds needs 6)")."""
    needs = f"a comparison over seeds needs {min_units(DEFAULT_ALPHA)}"
    if not seeds:
        return f"0 common seed(s) ({needs})"
    if not any(m in side[s]["metrics"] for m in valued_of for side in (ref, runs) for s in seeds):
        relations = any("relation_trans_mean_m" in side[s]["metrics"] for side in (ref, runs) for s in seeds)
        return "no APE or KITTI drift on this dataset" + (" (relation ground truth only)" if relations else "")
    metric = max(valued_of, key=lambda m: len(valued_of[m]))  # (the one with a value on the most seeds; the first of equals)
    valued = valued_of[metric]
    if len(valued) >= 2 and all(spread_is_round_off(np.array([side[s]["metrics"][metric] for s in valued], dtype=float))
                                for side in (ref, runs)):  # (it advised 6 seeds, which then made "one measurement repeated")
        return (f"the {len(valued)} seeds gave each side one value (deterministic methods on fixed data): one measurement "
                "repeated, which more seeds do not change; more datasets or sequences make more measurements")
    without = sorted(set(seeds) - set(valued))
    counted = (f"{len(valued)} common seed(s) with a value (seed(s) {_seed_list(without)} without one on a side; {needs})"
               if without else f"{len(seeds)} common seed(s) ({needs})")
    return counted + " and no KITTI segments to pair (a path under 100 m)"


def _paired_segments(segs: list[tuple[Any, Any]]) -> tuple[np.ndarray, np.ndarray, int, bool] | None:
    """Two methods' per-segment drift over the segments both have, seed by seed, how many were on one side only, and
    whether the seeds ran the same data (every seed's segments alike on both sides: counted once, as ``lidarkit
    compare`` counts such seeds; 3 seeds of an unseeded drive made 6 units of 2 segments, p = 0.031 where 2 give 0.5).
    Segments pair by first frame and length (two runs scored at other sweep instants measure the path on other truths:
    one has a 200 m segment the other lacks, and by position they covered other frames); records written before the
    first frames were kept pair by position when their counts agree. None: a seed without segments, or none pair."""
    va, vb, left = [], [], 0
    for a, b in segs:
        if not a or not b:
            return None
        ta, tb = np.asarray(a["translation_pct"], dtype=np.float64), np.asarray(b["translation_pct"], dtype=np.float64)
        if any(side.get(k) is None for side in (a, b) for k in ("first_frame", "length_m")):
            if len(ta) != len(tb):
                return None
            va.append(ta)
            vb.append(tb)
            continue
        keys_a, keys_b = (list(zip(side["first_frame"], side["length_m"])) for side in (a, b))
        index_b = {key: k for k, key in enumerate(keys_b)}
        common = [(k, index_b[key]) for k, key in enumerate(keys_a) if key in index_b]
        left += len(keys_a) + len(keys_b) - 2 * len(common)
        if common:
            ia, ib = (list(i) for i in zip(*common))
            va.append(ta[ia])
            vb.append(tb[ib])
    if not va:
        return None
    once = len(va) > 1 and _alike(va) and _alike(vb)
    if once:
        va, vb = va[:1], vb[:1]
    return np.concatenate(va), np.concatenate(vb), left, once


def _alike(values: list[np.ndarray]) -> bool:
    """Every array equal to the first (to rounding): one measurement, whatever the seed."""
    return all(v.shape == values[0].shape and np.allclose(v, values[0], rtol=1e-9, atol=1e-12) for v in values[1:])


#: the RPE table of runs over a frame selection that skips frames: its step is one selected frame, not one frame
RPE_SELECTED_FRAME_TABLE = "rpe_rmse_selected_frame"
#: the step of each RPE table, by the table's name (one table per step: a mean over two steps means neither)
RPE_TABLES = {"frame": "rpe_rmse", "selected frame": RPE_SELECTED_FRAME_TABLE}


@dataclass
class MarkedTable(PubTable):
    """A publication table some of whose cells carry a footnote mark, ``marks[(i, j)]`` (``"a"``): such a cell
    shows its value and the mark, ``0.512 (a)``, and is never set bold (a run that did not register, which stayed at
    the origin, was the best on a short drive)."""

    marks: dict[tuple[int, int], str] = field(default_factory=dict)

    def best_mask(self) -> np.ndarray:
        values = self.values.copy()
        for i, j in self.marks:
            values[i, j] = np.nan
        return PubTable.best_mask(dataclasses.replace(self, values=values, marks={}))

    def cell(self, i: int, j: int) -> str:
        mark = self.marks.get((i, j))
        return super().cell(i, j) + (f" ({mark})" if mark else "")

    def csv_extra_columns(self) -> dict[str, list[str]]:
        """A ``marks`` column naming each row's marked cells (``ground_filtered (a)``): a CSV reader saw the value of a
        run that did not register as any other."""
        return {"marks": ["; ".join(f"{self.col_labels[j]} ({mark})" for (row, j), mark in sorted(self.marks.items()) if row == i)
                          for i in range(len(self.row_labels))]}


def remove_stale_tables(out_dir: Path, pub: Publication) -> None:
    """Remove an earlier report's tables that ``pub`` does not hold (a run over shorter sequences has no drift tables),
    so that tables/ never mixes two reports; called once the report files are written (other files are left)."""
    from lidarkit.eval import tables

    own = (*tables.TABLE_FILES, *(f"{RPE_SELECTED_FRAME_TABLE}{suffix}" for suffix in tables.TABLE_SUFFIXES))
    tables.remove_stale_tables(out_dir / TABLES_DIR, (path.name for path in pub.files), names=own)


def _marked_value_table(grid: dict[tuple[str, str], float], not_registered: dict[tuple[str, str], str], title: str, *,
                        name: str, digits: int, no_mean: str = "") -> PubTable:
    """:func:`value_table` of ``grid`` whose cells of runs that did not register carry a mark, are not set bold, and
    leave their dataset out of the Mean (as a method without a value there does: the Mean is over the same data);
    ``no_mean``: why the table has no Mean row (its note says it instead)."""
    from lidarkit.eval.tables import value_table

    table = value_table({k: np.nan if k in not_registered else v for k, v in grid.items()}, title, name=name, digits=digits)
    if no_mean:
        table = dataclasses.replace(table, row_labels=table.row_labels[:-1], values=table.values[:-1], n_summary_rows=0,
                                    note=f"No Mean: {no_mean}.")
    flagged = sorted(((table.row_labels.index(d), table.col_labels.index(m)), why)
                     for (d, m), why in not_registered.items() if (d, m) in grid)
    if not flagged:
        return table
    values = table.values.copy()
    marks, notes = {}, []
    for k, ((i, j), why) in enumerate(flagged):
        values[i, j] = grid[(table.row_labels[i], table.col_labels[j])]
        marks[(i, j)] = _mark(k)
        notes.append(f"({marks[(i, j)]}) {table.row_labels[i]}, {table.col_labels[j]}: {why}")
    note = (f"{table.note} {'; '.join(notes)}. A frame that does not register takes the fallback motion's pose: a "
            "marked cell is not set bold" + ("." if no_mean else " and its sequence is left out of the Mean."))
    fields = {f.name: getattr(table, f.name) for f in dataclasses.fields(PubTable)}
    return MarkedTable(**{**fields, "values": values, "note": note}, marks=marks)


def _mark(k: int) -> str:
    """The ``k``-th footnote mark: a, b, ..., z, aa, ab, ..."""
    letters = "abcdefghijklmnopqrstuvwxyz"
    return letters[k] if k < len(letters) else _mark(k // len(letters) - 1) + letters[k % len(letters)]


def _rpe_tables(grids: _Grids) -> list[PubTable]:
    """One RPE table per step (``rpe_rmse``: one frame; ``rpe_rmse_selected_frame``: one selected frame of a selection
    that skips frames, its rows marked ``*`` and their selections named): one table averaged a 1-frame and a
    2-frame RPE into its Mean. Selections that step differently (:func:`step_pattern`) have no Mean, and the note says
    why."""
    out = []
    for step, name in RPE_TABLES.items():
        rows = {d for d, s in grids.rpe_step.items() if s == step}
        rpe = {k: v for k, v in grids.rpe.items() if k[0] in rows}
        if not rpe:
            continue
        shown = {d: f"{d} *" if step == "selected frame" else d for d in rows}
        # (selections of other steps, frames 0:10:3 and [0, 3, 4, 9], were averaged into one Mean per selected frame)
        patterns = {d: grids.steps.get(d) for d in sorted({d for d, _ in rpe})} if step == "selected frame" else {}
        no_mean = ("the selections step differently (" + "; ".join(f"{d}: {_pattern_text(p)}" for d, p in patterns.items())
                   + "), and a Mean is never over two steps") if len(set(patterns.values())) > 1 else ""
        table = _marked_value_table({(shown[d], m): v for (d, m), v in rpe.items()},
                                    {(shown[d], m): why for (d, m), why in grids.not_registered.items() if d in rows},
                                    f"RPE translation RMSE (m per {step})", name=name, digits=4, no_mean=no_mean)
        if step == "selected frame":
            selections = "; ".join(f"{d}: frames {grids.selection[d]}" for d in sorted(rows)
                                   if grids.selection.get(d) and f"frames={grids.selection[d]}" not in d)  # (said once)
            table = dataclasses.replace(table, note="*: over one selected frame of the row's frame selection, not one "
                                                    "dataset frame" + (f" ({selections})" if selections else "")
                                                    + f". {table.note}")
        out.append(table)
    return out


def build_publication(records: list[dict[str, Any]], out_dir: Path, *, plots: bool = True) -> Publication:
    """Tables (and box plots with ``plots``) of the odometry records, written under ``out_dir``; paired
    comparisons with the reference (kiss)."""
    from lidarkit.bench.tasks.odometry import METRIC_ALIGNMENT_BY_NAME

    grids = _grids(records)
    segments = grids.segments
    tables = publication_tables(segments or None).tables
    if grids.ape:
        tables.append(_marked_value_table(grids.ape, grids.not_registered,
                                          f"APE translation RMSE (m, {METRIC_ALIGNMENT_BY_NAME['ape_rmse_m']})",
                                          name="ape_rmse", digits=3))
    tables += _rpe_tables(grids)
    if grids.seeds_note:  # (said in every table, its .md, .csv and .tex: a table is copied into a paper alone)
        tables = [dataclasses.replace(t, note=f"{t.note} Means over common seeds, {grids.seeds_note}.".strip())
                  for t in tables]
    pub = Publication(tables)
    pub.comparisons = reference_comparisons(records, not_compared=pub.not_compared)
    # (an earlier report's tables that these do not replace are removed by remove_stale_tables, after the report files)
    pub.files += [path for t in pub.tables for path in t.write(out_dir / TABLES_DIR)]
    if not pub.tables:
        return pub
    if plots and segments:
        from lidarkit.eval.plots import plot_segment_boxplots, segment_counts_text

        for quantity, what in (("translation_pct", "translational"), ("rotation_deg_per_100m", "rotational")):
            path = plot_segment_boxplots(segments, out_dir / "plots" / f"segments_{quantity}.png", quantity)
            # (it said "8 segments (100-800 m)" where each of two methods had 4 of 100 m)
            pub.boxplots.append((f"Per-segment KITTI {what} drift per method: {segment_counts_text(segments)}, pooled "
                                 "over datasets and seeds; box = quartiles, whiskers = 1.5 IQR.", path))
    return pub
