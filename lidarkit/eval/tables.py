"""Tables researchers publish: KITTI drift per sequence x method with the devkit's average row, per length,
per speed, APE/RPE; exported as Markdown, CSV and LaTeX (booktabs, best method per row in bold).

The average row follows the KITTI devkit (and the KISS-ICP paper): the segments of all sequences are pooled
and averaged together, so a long sequence weighs more than a short one (length-weighted), unlike the mean
of the per-sequence numbers.
"""

from __future__ import annotations

import csv
import io
import math
import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from lidarkit import atomic
from lidarkit.errors import EvaluationError
from lidarkit.eval.kitti_drift import DriftResult

#: devkit speed bins of a segment (m/s): the devkit's 2..25 m/s, in coarser steps that a table can hold
SPEED_BINS_MPS = (0.0, 5.0, 10.0, 15.0, 20.0, 25.0, math.inf)
#: the devkit's frame period, used to turn a segment's frame count into its duration when the poses have no stamps
KITTI_FRAME_PERIOD_S = 0.1


def frame_period_s(reference: Any) -> float:
    """The frame period of a trajectory's segments: its time stamps' median interval, :data:`KITTI_FRAME_PERIOD_S`
    without stamps (a segment's speed is its length over its frames' duration)."""
    stamps = getattr(reference, "timestamps_s", None)
    if stamps is None or len(stamps) < 2:
        return KITTI_FRAME_PERIOD_S
    return float(np.median(np.diff(np.asarray(stamps, dtype=np.float64))))


def scored_timestamps_s(*trajectories: Any) -> np.ndarray | None:
    """``(N,)`` stamps of the poses scored: those of the first of ``trajectories`` that has them (the reference, else
    the estimate paired with it by index: a TUM estimate against KITTI ground truth without times), None if none has."""
    for trajectory in trajectories:
        stamps = getattr(trajectory, "timestamps_s", None)
        if stamps is not None:
            return np.asarray(stamps, dtype=np.float64)
    return None


#: frame numbers start below this (stamps in seconds since 1970 start above 1e9, a frame count of a drive far below)
FRAME_NUMBERS_BELOW = 1e6


def frame_numbers_as_seconds(stamps: np.ndarray | None) -> bool:
    """Whether ``(N,)`` stamps are frame numbers written as seconds: small (the first below
    :data:`FRAME_NUMBERS_BELOW`, so 1 Hz stamps since 1970 are seconds) whole numbers stepping by a whole median step
    (``--frames 0:N:2`` gives 0, 2, 4), as ``lidarkit vo`` and ``lidarkit odometry`` stamp poses_tum.txt when their
    input has no times (read as seconds, KITTI's 0.1 s frames took 1 s each)."""
    if stamps is None or len(stamps) < 2:
        return False
    stamps = np.asarray(stamps, dtype=np.float64)
    if not (np.all(np.isfinite(stamps)) and 0 <= stamps[0] < FRAME_NUMBERS_BELOW and np.all(stamps == np.round(stamps))):
        return False
    steps = np.diff(stamps)
    median_step = float(np.median(steps))
    return bool(np.all(steps > 0) and median_step >= 1 and median_step == round(median_step))


@dataclass(frozen=True)
class SegmentClock:
    """What times the KITTI segments of a pair: ``timestamps_s`` (``(N,)`` of the poses scored, or None), the
    ``frame_period_s`` of a segment's last frame, and a ``note`` on how ('' when the stamps are taken as they are)."""

    timestamps_s: np.ndarray | None
    frame_period_s: float
    note: str = ""


def segment_clock(reference: Any, estimate: Any) -> SegmentClock:
    """The clock of the segments of ``estimate`` scored against ``reference`` (paired poses): the reference's stamps,
    else the estimate's; frame numbers as seconds in an estimate under a reference without stamps (KITTI ground
    truth) are frames of the devkit's :data:`KITTI_FRAME_PERIOD_S` (read as seconds, every segment was in 0-5 m/s),
    every k-th frame k x that apart."""
    for trajectory in (reference, estimate):
        stamps = scored_timestamps_s(trajectory)
        if stamps is None:
            continue
        if trajectory is estimate and frame_numbers_as_seconds(stamps):
            note = (f"the estimate's stamps are frame numbers ({stamps[0]:.0f}, {stamps[1]:.0f}, ...; lidarkit vo and odometry write them "
                    f"without time stamps) and the reference has none: segment speeds take the KITTI devkit's "
                    f"{KITTI_FRAME_PERIOD_S:g} s per frame")
            # every frame: the devkit's own count (stamps x 0.1 put some 100 m in 100 frames at 9.999... m/s, a row lower)
            if np.all(np.diff(stamps) == 1):
                return SegmentClock(None, KITTI_FRAME_PERIOD_S, note)
            seconds = stamps * KITTI_FRAME_PERIOD_S
            return SegmentClock(seconds, float(np.median(np.diff(seconds))), note)
        return SegmentClock(stamps, frame_period_s(trajectory))
    return SegmentClock(None, KITTI_FRAME_PERIOD_S)


QUANTITIES = {
    "translation_pct": "translational drift (%)",
    "rotation_deg_per_100m": "rotational drift (deg/100 m)",
}


@dataclass(frozen=True, eq=False)
class SegmentErrors:
    """Per-segment KITTI errors of one (sequence, method): ``(S,)`` float arrays."""

    length_m: np.ndarray
    translation_pct: np.ndarray
    rotation_deg_per_100m: np.ndarray
    speed_mps: np.ndarray
    first_frame: np.ndarray | None = None
    """Each segment's first frame (int): with ``length_m`` it names the segment, so two runs scored on other truths
    (other sweep instants) pair the same segments; None in records written before it was kept."""

    @classmethod
    def from_drift(cls, drift: DriftResult, frame_period_s: float = KITTI_FRAME_PERIOD_S, *,
                   timestamps_s: np.ndarray | None = None) -> SegmentErrors:
        """From a :class:`DriftResult`; a segment's speed is its length over its duration: with ``timestamps_s``
        (``(N,)``, those of the poses the drift was scored on) the time from its first to its last pose plus one
        ``frame_period_s``, as the devkit counts a segment's frames (a count of poses misses the frames association
        left out); without, the devkit's ``(last - first + 1) * frame_period_s``."""
        first = np.asarray(drift.segment_first_frame, dtype=np.int64)
        last = np.asarray(drift.segment_last_frame, dtype=np.int64)
        if timestamps_s is None:
            duration_s = (last - first + 1).astype(np.float64) * frame_period_s
        else:
            stamps = np.asarray(timestamps_s, dtype=np.float64).reshape(-1)
            if last.size and stamps.size <= last.max():
                raise EvaluationError(f"{stamps.size} stamps for segments that reach pose {int(last.max())}: give the "
                                      "stamps of the poses the drift was scored on", source="timestamps_s")
            duration_s = stamps[last] - stamps[first] + frame_period_s
        speed = drift.segment_length_m / np.maximum(duration_s, 1e-12)
        return cls(np.asarray(drift.segment_length_m, float), np.asarray(drift.segment_translation_pct, float),
                   np.asarray(drift.segment_rotation_deg_per_100m, float), speed, first)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> SegmentErrors:
        try:
            arrays = [np.asarray(data[k], dtype=np.float64).reshape(-1)
                      for k in ("length_m", "translation_pct", "rotation_deg_per_100m", "speed_mps")]
        except (KeyError, TypeError, ValueError) as err:
            raise EvaluationError(f"not a per-segment error record ({err})", source="segments") from None
        if data.get("first_frame") is not None:
            try:
                arrays.append(np.asarray(data["first_frame"], dtype=np.int64).reshape(-1))
            except (TypeError, ValueError) as err:
                raise EvaluationError(f"not a per-segment error record ({err})", source="segments") from None
        if len({a.size for a in arrays}) != 1:
            raise EvaluationError("per-segment arrays differ in length", source="segments")
        return cls(*arrays)

    def to_dict(self) -> dict[str, list[float]]:
        out = {"length_m": self.length_m.tolist(), "translation_pct": np.round(self.translation_pct, 6).tolist(),
               "rotation_deg_per_100m": np.round(self.rotation_deg_per_100m, 6).tolist(),
               "speed_mps": np.round(self.speed_mps, 4).tolist()}
        return out if self.first_frame is None else {**out, "first_frame": self.first_frame.tolist()}

    def __len__(self) -> int:
        return int(self.length_m.size)


def pooled(segments: Sequence[SegmentErrors], quantity: str = "translation_pct") -> float:
    """The devkit average: mean over the segments of all sequences together (NaN when there is none)."""
    values = np.concatenate([getattr(s, quantity) for s in segments]) if segments else np.zeros(0)
    return float(values.mean()) if values.size else float("nan")


@dataclass
class PubTable:
    """A table of numbers: ``values[i, j]`` for row ``row_labels[i]`` and column ``col_labels[j]`` (NaN = no value).

    The last ``n_summary_rows`` rows are summaries (the average row), set apart by a rule. ``bold_best`` marks the
    best value of each row across the columns (the methods), lower is better unless ``higher_is_better``.
    """

    title: str
    corner: str
    row_labels: list[str]
    col_labels: list[str]
    values: np.ndarray
    digits: int = 2
    n_summary_rows: int = 0
    higher_is_better: bool = False
    bold_best: bool = True
    note: str = ""
    name: str = "table"

    def best_mask(self) -> np.ndarray:
        v = np.where(np.isfinite(self.values), self.values, np.nan)
        mask = np.zeros(v.shape, dtype=bool)
        if not self.bold_best or v.shape[1] < 2:
            return mask
        for i, row in enumerate(v):
            if np.isfinite(row).any():
                best = np.nanmax(row) if self.higher_is_better else np.nanmin(row)
                # every cell that prints as the best does (1.004 and 1.006 printed 1.00 and 1.01, both bold)
                shown = f"{best:.{self.digits}f}"
                mask[i] = np.array([np.isfinite(x) and f"{x:.{self.digits}f}" == shown for x in row])
        return mask

    def cell(self, i: int, j: int) -> str:
        x = self.values[i, j]
        return "–" if not np.isfinite(x) else f"{x:.{self.digits}f}"

    def to_markdown(self) -> str:
        """A pipe table; a ``|`` in a label is escaped (a method named ``o|x`` split its column in two)."""
        best = self.best_mask()
        esc = _markdown_escape
        lines = [f"**{self.title}**", "", "| " + " | ".join([esc(self.corner), *map(esc, self.col_labels)]) + " |",
                 "|---|" + "---:|" * len(self.col_labels)]
        for i, label in enumerate(self.row_labels):
            cells = [f"**{self.cell(i, j)}**" if best[i, j] else self.cell(i, j) for j in range(len(self.col_labels))]
            label = f"**{esc(label)}**" if i >= len(self.row_labels) - self.n_summary_rows else esc(label)
            lines.append("| " + " | ".join([label, *cells]) + " |")
        if self.note:
            lines += ["", self.note]
        return "\n".join(lines) + "\n"

    def to_csv(self) -> str:
        buf = io.StringIO()
        writer = csv.writer(buf, lineterminator="\n")
        extra = self.csv_extra_columns()
        writer.writerow([self.corner, *self.col_labels, *extra])
        for i, label in enumerate(self.row_labels):
            writer.writerow([label, *("" if not np.isfinite(x) else repr(float(x)) for x in self.values[i]),
                             *(extra[name][i] for name in extra)])
        return buf.getvalue()

    def csv_extra_columns(self) -> dict[str, list[str]]:
        """Columns after the values in :meth:`to_csv`, each a text per row (none here)."""
        return {}

    def to_latex(self) -> str:
        """A booktabs ``tabular`` (needs ``\\usepackage{booktabs}``); the best value of each row in ``\\textbf``."""
        best = self.best_mask()
        esc = _latex_escape
        lines = [f"% {self.title}" + (f". {self.note}" if self.note else ""),
                 "\\begin{tabular}{l" + "r" * len(self.col_labels) + "}", "\\toprule",
                 " & ".join([esc(self.corner), *(esc(c) for c in self.col_labels)]) + " \\\\", "\\midrule"]
        for i, label in enumerate(self.row_labels):
            if self.n_summary_rows and i == len(self.row_labels) - self.n_summary_rows:
                lines.append("\\midrule")
            cells = [f"\\textbf{{{self.cell(i, j)}}}" if best[i, j] else self.cell(i, j).replace("–", "--")
                     for j in range(len(self.col_labels))]
            lines.append(" & ".join([esc(label), *cells]) + " \\\\")
        lines += ["\\bottomrule", "\\end{tabular}"]
        return "\n".join(lines) + "\n"

    def write(self, out_dir: str | os.PathLike, stem: str | None = None) -> list[Path]:
        """``<stem>.md``, ``<stem>.csv`` and ``<stem>.tex`` in ``out_dir``, each written atomically."""
        out = Path(out_dir)
        stem = stem or self.name
        return [atomic.write_text(out / f"{stem}.md", self.to_markdown()),
                atomic.write_text(out / f"{stem}.csv", self.to_csv()),
                atomic.write_text(out / f"{stem}.tex", self.to_latex())]


def _markdown_escape(text: str) -> str:
    """``text`` for a cell of a Markdown pipe table."""
    return text.replace("|", "\\|")


def _latex_escape(text: str) -> str:
    """``text`` for LaTeX's text mode under any font encoding (``^`` broke the compile, ``~`` became a space, ``<`` /
    ``>`` printed as inverted marks under OT1)."""
    out = []
    for ch in text:
        out.append({"\\": "\\textbackslash{}", "&": "\\&", "%": "\\%", "_": "\\_", "#": "\\#", "$": "\\$", "{": "\\{",
                    "}": "\\}", "^": "\\textasciicircum{}", "~": "\\textasciitilde{}", "<": "\\textless{}",
                    ">": "\\textgreater{}"}.get(ch, ch))
    return "".join(out)


Grid = Mapping[tuple[str, str], SegmentErrors]


def _axes(grid: Mapping[tuple[str, str], Any]) -> tuple[list[str], list[str]]:
    sequences = list(dict.fromkeys(seq for seq, _ in grid))
    methods = list(dict.fromkeys(method for _, method in grid))
    return sequences, methods


def _common_sequences(grid: Grid) -> tuple[list[str], str]:
    """The sequences on which every method has segments (so that pooled rows compare methods on the same data), and a
    note naming those left out ('' when none is)."""
    sequences, methods = _axes(grid)
    common = [seq for seq in sequences if all(grid.get((seq, m)) is not None and len(grid[(seq, m)]) for m in methods)]
    left = [seq for seq in sequences if seq not in common]
    return common, (f" Left out: {', '.join(left)} (not every method has segments there)." if left else "")


def drift_table(grid: Grid, quantity: str = "translation_pct", *, average_label: str = "Avg.") -> PubTable:
    """Sequences x methods table of the mean KITTI drift, plus the devkit average row (segments pooled)."""
    if quantity not in QUANTITIES:
        raise EvaluationError(f"unknown drift quantity {quantity!r}; use {', '.join(QUANTITIES)}", source="drift_table")
    sequences, methods = _axes(grid)
    values = np.full((len(sequences) + 1, len(methods)), np.nan)
    for j, method in enumerate(methods):
        for i, seq in enumerate(sequences):
            s = grid.get((seq, method))
            if s is not None and len(s):
                values[i, j] = float(getattr(s, quantity).mean())
    # pooled over the sequences where *every* method has segments, so methods are averaged on the same data
    common, left_out = _common_sequences(grid)
    for j, method in enumerate(methods):
        values[-1, j] = pooled([grid[(seq, method)] for seq in common], quantity)
    return PubTable(
        title=f"KITTI {QUANTITIES[quantity]} per sequence",
        corner="sequence", row_labels=[*sequences, average_label], col_labels=methods, values=values,
        digits=2 if quantity == "translation_pct" else 3, n_summary_rows=1, name=f"kitti_{quantity}",
        note=f"{average_label}: mean over the segments of the sequences pooled (KITTI devkit, length-weighted).{left_out}",
    )


def per_length_table(grid: Grid, quantity: str = "translation_pct", lengths_m: Sequence[float] | None = None) -> PubTable:
    """Segment length x method table, segments pooled over the sequences every method has segments on (those of
    the drift table's average row), plus the all-lengths row. ``lengths_m``: the rows; by default every length the
    segments have (the devkit's lengths left drift of 5 and 10 m segments with the "all" row only)."""
    _, methods = _axes(grid)
    common, left_out = _common_sequences(grid)
    if lengths_m is None:
        lengths_m = sorted({float(x) for s in grid.values() if s is not None for x in np.asarray(s.length_m).ravel()})
    values = np.full((len(lengths_m) + 1, len(methods)), np.nan)
    for j, method in enumerate(methods):
        segs = [grid[(seq, method)] for seq in common]
        length = np.concatenate([s.length_m for s in segs]) if segs else np.zeros(0)
        q = np.concatenate([getattr(s, quantity) for s in segs]) if segs else np.zeros(0)
        for i, L in enumerate(lengths_m):
            sel = length == L
            values[i, j] = q[sel].mean() if sel.any() else np.nan
        values[-1, j] = q.mean() if q.size else np.nan
    keep = np.isfinite(values).any(axis=1)
    keep[-1] = True  # lengths no sequence is long enough for are left out; the "all" row stays
    labels = [f"{L:g}" for L in lengths_m] + ["all"]
    return PubTable(
        title=f"KITTI {QUANTITIES[quantity]} per segment length", corner="length (m)",
        row_labels=[lab for lab, k in zip(labels, keep) if k], col_labels=methods, values=values[keep],
        digits=2 if quantity == "translation_pct" else 3, n_summary_rows=1, name=f"kitti_{quantity}_per_length",
        note=f"Segments pooled over the sequences.{left_out}",
    )


def per_speed_table(grid: Grid, quantity: str = "translation_pct", bins_mps: Sequence[float] = SPEED_BINS_MPS, *,
                    clock_note: str = "") -> PubTable:
    """Segment speed bin x method table (the devkit's error-vs-speed curve as rows), pooled over the sequences every
    method has segments on; ``clock_note``: how the segments were timed, if not by their stamps as they are."""
    _, methods = _axes(grid)
    common, left_out = _common_sequences(grid)
    edges = list(bins_mps)
    labels = [f"{lo:g}-{hi:g} m/s" if math.isfinite(hi) else f">= {lo:g} m/s" for lo, hi in zip(edges[:-1], edges[1:])]
    values = np.full((len(labels), len(methods)), np.nan)
    for j, method in enumerate(methods):
        segs = [grid[(seq, method)] for seq in common]
        if not segs:
            continue
        speed = np.concatenate([s.speed_mps for s in segs])
        q = np.concatenate([getattr(s, quantity) for s in segs])
        for i, (lo, hi) in enumerate(zip(edges[:-1], edges[1:])):
            sel = (speed >= lo) & (speed < hi)
            values[i, j] = q[sel].mean() if sel.any() else np.nan
    keep = np.isfinite(values).any(axis=1)
    return PubTable(
        title=f"KITTI {QUANTITIES[quantity]} per segment speed", corner="speed",
        row_labels=[lab for lab, k in zip(labels, keep) if k], col_labels=methods, values=values[keep],
        digits=2 if quantity == "translation_pct" else 3, name=f"kitti_{quantity}_per_speed",
        note=f"Segments pooled over the sequences; a segment's speed is its length over its duration: the time from its "
             f"first to its last pose's stamp plus one median interval (the devkit counts a segment's frames, first and "
             f"last included), or without stamps its frames x the KITTI devkit's frame period (0.1 s).{left_out}"
             + (f" Here {clock_note}." if clock_note else ""),
    )


#: significant figures a value table shows of its smallest value (APE 0.013470 m printed 0.013 at 3 decimals, and
#: 0.0081 and 0.0084 both printed 0.008, both bold)
VALUE_SIGNIFICANT_FIGURES = 3
#: values below this share of a table's largest are round-off, not sized for (every cell printed 15 decimals)
ROUND_OFF_SHARE = 1e-9
#: values at most this (in the table's unit: m, deg, %) are round-off whatever the others: float64 noise of positions
#: (a copy scored against itself, alone in its table, printed APE 0.000000000000035 m)
ROUND_OFF_ABS = 1e-9


def decimals_for(values: np.ndarray, at_least: int, significant: int = VALUE_SIGNIFICANT_FIGURES,
                 round_off: float = ROUND_OFF_ABS) -> int:
    """Decimals, at least ``at_least``, that show the smallest finite ``|value|`` above round-off (``round_off``, and
    :data:`ROUND_OFF_SHARE` of the largest) with ``significant`` figures: one count for the whole table, so that its
    columns line up."""
    magnitudes = np.abs(np.asarray(values, dtype=np.float64))
    magnitudes = magnitudes[np.isfinite(magnitudes) & (magnitudes > round_off)]
    if magnitudes.size:  # (round-off beside real values, a copy scored against itself at 3e-13, prints as 0)
        magnitudes = magnitudes[magnitudes > ROUND_OFF_SHARE * magnitudes.max()]
    if not magnitudes.size:
        return at_least
    needed = significant - 1 - math.floor(math.log10(float(magnitudes.min())))
    return int(min(max(at_least, needed), 15))  # (15: what a float64 holds)


def value_table(grid: Mapping[tuple[str, str], float], title: str, *, name: str, digits: int = 3,
                higher_is_better: bool = False, mean_label: str = "Mean") -> PubTable:
    """Sequences x methods table of one scalar per cell (APE RMSE, RPE RMSE, ...) with the mean over sequences;
    ``digits`` decimals, more where the smallest value needs them for :data:`VALUE_SIGNIFICANT_FIGURES` figures."""
    sequences, methods = _axes(grid)
    values = np.full((len(sequences) + 1, len(methods)), np.nan)
    for (seq, method), v in grid.items():
        values[sequences.index(seq), methods.index(method)] = np.nan if v is None else float(v)
    body = values[:-1]
    complete = np.isfinite(body).all(axis=1)
    values[-1] = body[complete].mean(axis=0) if complete.any() else np.nan
    return PubTable(title=title, corner="sequence", row_labels=[*sequences, mean_label], col_labels=methods,
                    values=values, digits=decimals_for(values, digits), n_summary_rows=1,
                    higher_is_better=higher_is_better, name=name,
                    note=f"{mean_label}: unweighted mean over the sequences every method completed.")


def short_method_labels(labels: Sequence[str]) -> dict[str, str]:
    """Method labels without the prefix they all share (``"icp_sim: kiss"`` -> ``"kiss"``), unchanged if none."""
    labels = list(labels)
    if len(labels) < 2:
        return {lab: lab.split(": ", 1)[-1] for lab in labels}
    prefix = os.path.commonprefix(labels)
    cut = max(prefix.rfind(": "), prefix.rfind(" | "))
    if cut < 0:
        return {lab: lab for lab in labels}
    return {lab: lab[cut + 2:].lstrip() or lab for lab in labels}


#: every table a :class:`PublicationTables` can hold, by file stem
TABLE_NAMES = (*(f"kitti_{q}{part}" for q in QUANTITIES for part in ("", "_per_length", "_per_speed")), "ape_rmse", "rpe_rmse")
TABLE_SUFFIXES = (".md", ".csv", ".tex")
#: every file a set of publication tables can write
TABLE_FILES = tuple(f"{stem}{suffix}" for stem in TABLE_NAMES for suffix in TABLE_SUFFIXES)


def remove_stale_tables(folder: str | os.PathLike, keep: Iterable[str], names: Iterable[str] = TABLE_FILES) -> None:
    """Remove from ``folder`` the files of ``names`` (an earlier set's tables) not in ``keep`` (the names just written), so
    that the folder never mixes two sets (a run over shorter sequences has no drift tables); other files stay."""
    keep = set(keep)
    for name in names:
        stale = Path(folder) / name
        if name not in keep and stale.is_file():
            stale.unlink()


@dataclass
class PublicationTables:
    """Every table for one set of runs, ready to write."""

    tables: list[PubTable] = field(default_factory=list)

    def write(self, out_dir: str | os.PathLike) -> list[Path]:
        """Each table's .md/.csv/.tex in ``out_dir``; an earlier set's tables that this one does not hold (a run over
        shorter sequences has no drift tables) are removed, so the folder never mixes two sets."""
        written = [p for t in self.tables for p in t.write(out_dir)]
        remove_stale_tables(out_dir, (p.name for p in written))
        return written

    def markdown(self) -> str:
        return "\n".join(t.to_markdown() for t in self.tables)


def publication_tables(segments: Grid | None = None, ape_rmse_m: Mapping[tuple[str, str], float] | None = None,
                       rpe_rmse_m: Mapping[tuple[str, str], float] | None = None, *, ape_alignment: str = "SE(3)-aligned",
                       rpe_delta: str = "1 frame", clock_note: str = "") -> PublicationTables:
    """Drift (translation, rotation), per-length, per-speed, APE and RPE tables from what is available; the APE and
    RPE titles state the alignment and the delta the values were computed with (one title for every kind read as
    SE(3)-aligned APE and 1-frame RPE), the per-speed table's note ``clock_note`` (:attr:`SegmentClock.note`)."""
    out = PublicationTables()
    if segments:
        for q in QUANTITIES:
            out.tables.append(drift_table(segments, q))
        out.tables.append(per_length_table(segments))
        out.tables.append(per_speed_table(segments, clock_note=clock_note))
    if ape_rmse_m:
        out.tables.append(value_table(ape_rmse_m, f"APE translation RMSE (m, {ape_alignment})", name="ape_rmse"))
    if rpe_rmse_m:
        out.tables.append(value_table(rpe_rmse_m, f"RPE translation RMSE (m per {rpe_delta})", name="rpe_rmse", digits=4))
    return out
