"""Evaluation results as tables (rich, Markdown) and JSON files (written atomically)."""

from __future__ import annotations

import json
import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from lidarkit import atomic
from lidarkit.eval.evaluate import Evaluation

STAT_COLUMNS = ("rmse", "mean", "median", "std", "min", "max")


#: table cells at or beyond this size print in e notation (1e30 printed its 31 digits, cut to "49989998999799…")
E_NOTATION_FROM = 1e6


def _fmt(value: float | None, digits: int = 5) -> str:
    """A table cell: ``digits`` significant figures, one decimal from 1e4 (12345.6), e notation from
    :data:`E_NOTATION_FROM` (4.999e+29)."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "–"
    return f"{value:.{digits}g}" if abs(value) < 1e4 or abs(value) >= E_NOTATION_FROM else f"{value:.1f}"


def metric_rows(evaluation: Evaluation) -> tuple[list[str], list[list[str]]]:
    """Header and rows of the APE/RPE table: one column per metric, one row per statistic."""
    results = (evaluation.ape, evaluation.ape_rotation, evaluation.rpe, evaluation.rpe_rotation)
    names = ("APE transl.", "APE rot.", "RPE transl.", "RPE rot.")
    header = ["", *(f"{name} ({res.unit})" for name, res in zip(names, results))]
    rows = [[stat, *(_fmt(getattr(res, stat)) for res in results)] for stat in STAT_COLUMNS]
    rows.append(["n", *(str(res.n_errors) for res in results)])
    return header, rows


def drift_rows(evaluation: Evaluation) -> tuple[list[str], list[list[str]]]:
    """Header and rows of the KITTI drift table: one row per segment length, then all segments pooled."""
    header = ["length (m)", "segments", "t_err (%)", "r_err (deg/100m)"]
    drift = evaluation.drift
    if drift is None:
        return header, []
    rows = [
        [f"{r.length_m:g}", str(r.n_segments), _fmt(r.translation_pct), _fmt(r.rotation_deg_per_100m)]
        for r in drift.per_length
    ]
    rows.append(["all", str(drift.n_segments), _fmt(drift.translation_pct), _fmt(drift.rotation_deg_per_100m)])
    return header, rows


def _settings_line(evaluation: Evaluation) -> str:
    s = evaluation.settings
    pairs = "all pairs" if s.all_pairs else ("legacy pairs" if s.legacy_pairs else "consecutive pairs")
    transform = evaluation.ape.alignment
    align = f"align={s.align}" + (f" (scale {transform.scale:.4g})" if transform is not None and transform.rescaled else "")
    return f"{align}, RPE delta={s.delta:g} {s.delta_unit} ({pairs})" + (", associated" if s.associate else "")


def _poses_line(evaluation: Evaluation, length_label: str = "") -> str:
    """How many poses were scored over how much of the reference: associated poses against the whole reference's path
    (the line through 118 matched keyframes of fr2/desk read "15.6 m" for a reference of 20.3 m)."""
    if evaluation.settings.associate:
        return (f"{evaluation.n_poses} associated poses over {evaluation.scored_path_m:.1f} m of a "
                f"{evaluation.ref_length_m:.1f} m reference")
    return f"{evaluation.n_poses} poses, {length_label}{evaluation.ref_length_m:.1f} m"


def evaluation_notes(evaluation: Evaluation) -> list[str]:
    """What a reader of the table must know to read it right: orientation errors after an alignment the positions
    hardly fix, and KITTI drift beside a scale-corrected APE (the devkit metric takes the estimate as given)."""
    notes = [evaluation.ape_rotation.warning] if evaluation.ape_rotation.warning else []
    transform = evaluation.ape.alignment
    if evaluation.drift is not None and transform is not None and transform.rescaled:
        notes.append(f"KITTI drift is the devkit's, on the estimate as given (unscaled); APE and RPE above are on the "
                     f"estimate scaled by {transform.scale:.4g}")
    return notes


def summary_rows(evaluations: Sequence[Evaluation]) -> tuple[list[str], list[list[str]]]:
    """One row per evaluation: headline numbers for comparing several estimates."""
    header = ["estimate", "reference", "poses", "APE rmse (m)", "APE rot rmse (deg)", "RPE rmse (m)",
              "RPE rot rmse (deg)", "drift t (%)", "drift r (deg/100m)"]
    rows = []
    for ev in evaluations:
        d = ev.drift if ev.drift is not None and ev.drift.valid else None
        rows.append([
            ev.est_name, ev.ref_name, str(ev.n_poses), _fmt(ev.ape.rmse), _fmt(ev.ape_rotation.rmse),
            _fmt(ev.rpe.rmse), _fmt(ev.rpe_rotation.rmse),
            _fmt(None if d is None else d.translation_pct), _fmt(None if d is None else d.rotation_deg_per_100m),
        ])
    return header, rows


def _rich(title: str, header: list[str], rows: list[list[str]]):
    from rich.table import Table

    table = Table(title=title, title_style="bold", header_style="bold")
    for i, name in enumerate(header):
        table.add_column(name, justify="left" if i == 0 else "right")
    for row in rows:
        table.add_row(*row)
    return table


def evaluation_table(evaluation: Evaluation):
    """rich Table of one evaluation's metrics."""
    title = f"{evaluation.est_name} vs {evaluation.ref_name}: {_poses_line(evaluation)}\n{_settings_line(evaluation)}"
    return _rich(title, *metric_rows(evaluation))


def drift_table(evaluation: Evaluation):
    """rich Table of the KITTI drift per segment length."""
    return _rich("KITTI drift (devkit metric)", *drift_rows(evaluation))


def summary_table(evaluations: Sequence[Evaluation], title: str = "Evaluation summary"):
    """rich Table comparing several evaluations."""
    return _rich(title, *summary_rows(evaluations))


def markdown_table(header: list[str], rows: list[list[str]]) -> str:
    """GitHub-flavoured Markdown table; a ``|`` inside a cell (a dataset named ``a|b``) is escaped."""
    def line(cells: list[str]) -> str:
        return "| " + " | ".join(str(c).replace("|", "\\|") for c in cells) + " |"

    return "\n".join([line(header), "|" + "|".join("---" for _ in header) + "|", *map(line, rows)]) + "\n"


def evaluation_markdown(evaluation: Evaluation) -> str:
    """Markdown report of one evaluation: metric table plus KITTI per-length table."""
    parts = [
        f"### {evaluation.est_name} vs {evaluation.ref_name}\n",
        f"{_poses_line(evaluation, 'reference path ')}; {_settings_line(evaluation)}.\n",
        markdown_table(*metric_rows(evaluation)),
        *(f"\nNote: {note}.\n" for note in evaluation_notes(evaluation)),
        # what the pairing warned of (logged on the terminal; the JSON holds it too): the filed report read clean
        *(f"\nWarning: {warning}.\n" for warning in evaluation.warnings),
    ]
    if evaluation.drift is not None:
        parts += ["\nKITTI drift (devkit metric) per segment length:\n", markdown_table(*drift_rows(evaluation))]
    elif evaluation.drift_note:
        parts.append(f"\nKITTI drift not computed: {evaluation.drift_note}.\n")
    return "\n".join(parts)


def json_safe(value: Any) -> Any:
    """``value`` as plain JSON data: numpy scalars/arrays to Python, non-finite floats (NaN, inf) to None."""
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if hasattr(value, "tolist") and not isinstance(value, (str, bytes)):
        return json_safe(value.tolist())
    if isinstance(value, bool) or value is None or isinstance(value, (int, str)):
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    try:
        f = float(value)
    except (TypeError, ValueError):
        return str(value)
    return f if math.isfinite(f) else None


def write_json(data: dict[str, Any] | list[Any], path: str | os.PathLike) -> Path:
    """Write ``data`` (e.g. ``evaluation.to_dict()``) as indented, strictly valid JSON, atomically
    (through :func:`json_safe`: NaN / infinity become null)."""
    return atomic.write_text(path, json.dumps(json_safe(data), indent=2, allow_nan=False) + "\n")
