"""``lidarkit eval REF EST``: APE, RPE and KITTI drift of an estimated trajectory against a reference."""

from __future__ import annotations

import contextlib
import math
from pathlib import Path
from typing import Optional

import typer

from lidarkit.cli.app import app, named_by_option
from lidarkit.cli.outputs import results_console
from lidarkit.errors import ConfigError, DataError
from lidarkit.eval.ape_rpe import ALIGNMENTS, DELTA_UNITS
from lidarkit.eval.evaluate import EvaluationSettings
from lidarkit.eval.relations import DEFAULT_MAX_TIME_DIFF_S
from lidarkit.trajectory import FORMATS

_D = EvaluationSettings()


@app.command("eval")
def eval_command(
    ref: Optional[Path] = typer.Argument(None, help="Reference (ground-truth) trajectory file (with --relations: EST)."),
    est: Optional[Path] = typer.Argument(None, help="Estimated trajectory file."),
    fmt: Optional[str] = typer.Option(
        None, "--format", "-f", help=f"Format of both files: {' | '.join(FORMATS)} (default kitti; tum with --relations)."
    ),
    ref_format: Optional[str] = typer.Option(None, help="Format of REF if it differs from --format."),
    est_format: Optional[str] = typer.Option(None, help="Format of EST if it differs from --format."),
    ref_times: Optional[Path] = typer.Option(None, help="times.txt for a KITTI-format REF (one time per pose)."),
    est_times: Optional[Path] = typer.Option(None, help="times.txt for a KITTI-format EST."),
    align: str = typer.Option(_D.align, help=f"Alignment of EST onto REF: {' | '.join(ALIGNMENTS)}."),
    delta: float = typer.Option(_D.delta, help="RPE pair distance, in --delta-unit."),
    delta_unit: str = typer.Option(_D.delta_unit, help=f"RPE delta unit: {' | '.join(dict.fromkeys(DELTA_UNITS))}."),
    all_pairs: bool = typer.Option(_D.all_pairs, help="RPE over all pairs instead of consecutive ones."),
    legacy_pairs: bool = typer.Option(
        _D.legacy_pairs,
        help="RPE path/angle pairs as the 2018 evo releases chose them (reproduces evo's stored results).",
    ),
    associate: bool = typer.Option(
        _D.associate, help="Match poses by timestamp (both need times) instead of by index."
    ),
    max_diff: float = typer.Option(_D.max_diff_s, help="Max. timestamp difference (s) for --associate."),
    drift: bool = typer.Option(_D.drift, help="KITTI drift (when the reference path is longer than 100 m)."),
    json_out: Optional[Path] = typer.Option(None, "--json", help="Write all results as JSON here."),
    plot: Optional[Path] = typer.Option(None, "--plot", help="Write a plot (format from the suffix: .png, .pdf, .svg, ...): trajectories, APE/RPE over time, drift."),
    markdown: Optional[Path] = typer.Option(None, "--markdown", help="Write a Markdown report here."),
    tables: Optional[Path] = typer.Option(
        None, "--tables", help="Write publication tables (KITTI drift per length/speed, APE/RPE) as .md/.csv/.tex "
        "and a per-segment box plot into this folder."),
    relations: Optional[Path] = typer.Option(
        None, "--relations", help="Score the one trajectory given against a .relations file (Kümmerle et al. 2009) instead."
    ),
    relation_max_diff: float = typer.Option(
        DEFAULT_MAX_TIME_DIFF_S, help="--relations: max. time difference (s) between a relation and the nearest pose."
    ),
) -> None:
    """Score EST against REF: APE and RPE (evo) in translation and rotation, and KITTI drift; print a table.

    With --relations R: score the single trajectory given (`lidarkit eval --relations aces.relations EST`).
    """
    from lidarkit import atomic
    from lidarkit.eval import evaluate, report
    from lidarkit.trajectory import Trajectory

    if ref is None:  # (a usage box "Missing argument 'ref'", exit 2: with --relations the one file given is EST)
        raise ConfigError("missing EST (the trajectory to score): lidarkit eval --relations FILE EST" if relations is not None
                          else "missing REF and EST (the trajectory files): lidarkit eval REF EST",
                          source="EST" if relations is not None else "REF")
    fmt = fmt or ("tum" if relations is not None else "kitti")

    def load(path: Path, kind: str | None, times: Path | None, times_option: str) -> Trajectory:
        kind = kind or fmt
        kwargs = {"timestamps_s": times} if times is not None and kind == "kitti" else {}
        if times is not None and kind != "kitti":  # (named "--ref-times/--est-times" whichever was given)
            raise ConfigError(f"times files apply to KITTI-format trajectories only (this one is read as {kind})",
                              source=times_option)
        if relations is None:  # one file of a KITTI/TUM pair in the other format: its own option reads it so
            side = "--ref-format" if path == ref else "--est-format"
            kwargs["format_hint"] = lambda other: f"{side} {other}, Trajectory.from_{other}"
        else:  # (the hint "--format kitti" alone failed next: the relations metric pairs poses by time)
            kwargs["format_hint"] = lambda other: (f"--format {other}" + (" --est-times TIMES.txt (the relations metric pairs "
                                                   "poses by time), or a run folder's poses_tum.txt" if other == "kitti" else ""))
        try:
            return Trajectory.read(path, kind, **kwargs)
        except ConfigError as err:
            if err.source != "format":
                raise
            raise ConfigError(err.reason, source="--ref-format" if path == ref and ref_format else
                              "--est-format" if path == est and est_format else "--format") from None

    given = {"EST": ref} if relations is not None else {"REF": ref, "EST": est}  # (with --relations the one given is EST)
    _distinct_outputs({**given, "--ref-times": ref_times, "--est-times": est_times, "--relations": relations},
                      {"--json": json_out, "--markdown": markdown, "--plot": plot, "--tables": tables})
    atomic.check_target(json_out, "file")
    if relations is not None:
        if est is not None:
            raise ConfigError("with --relations give one trajectory (EST) only", source="--relations")
        unused = [name for name, given in (
            ("--align", align != _D.align), ("--delta", delta != _D.delta), ("--delta-unit", delta_unit != _D.delta_unit),
            ("--all-pairs", all_pairs != _D.all_pairs), ("--legacy-pairs", legacy_pairs != _D.legacy_pairs),
            ("--associate", associate != _D.associate), ("--max-diff", max_diff != _D.max_diff_s), ("--no-drift", drift != _D.drift),
            ("--plot", plot is not None), ("--markdown", markdown is not None), ("--tables", tables is not None),
            ("--ref-times", ref_times is not None), ("--ref-format", ref_format is not None),
        ) if given]
        if unused:  # (they were accepted and did nothing: no plot, no Markdown file, exit code 0)
            raise ConfigError(f"{', '.join(unused)} do(es) not apply to the relations metric (it takes --json, "
                              "--relation-max-diff, --format/--est-format and --est-times)", source="--relations")
        if not (math.isfinite(relation_max_diff) and relation_max_diff >= 0):  # (named the library's max_time_diff_s)
            raise ConfigError(f"must be a finite number of seconds >= 0, got {relation_max_diff:g}", source="--relation-max-diff")
        try:
            est_traj = load(ref, est_format, est_times, "--est-times")
        except DataError as err:  # (the two files swapped read "quaternion norm 0.0173 is not 1" of the relations file)
            from lidarkit.errors import LidarKitError
            from lidarkit.io.carmen import Relations

            try:
                Relations.read(ref)
            except LidarKitError:
                raise err from None
            raise ConfigError(f"{ref} is a relations file: the order is lidarkit eval --relations RELATIONS EST "
                              f"(lidarkit eval --relations {ref} {relations})", source="--relations") from None
        _relations_report(est_traj, relations, relation_max_diff, json_out)
        return
    if relation_max_diff != DEFAULT_MAX_TIME_DIFF_S:  # (accepted and ignored without --relations)
        raise ConfigError("--relation-max-diff applies to --relations only (pose-by-pose matching by time: --associate --max-diff)",
                          source="--relation-max-diff")
    if est is None:
        raise ConfigError("missing EST (the estimated trajectory file): lidarkit eval REF EST", source="EST")
    if max_diff != _D.max_diff_s and not associate:  # (accepted, recorded in the JSON as if applied, and ignored)
        raise ConfigError("--max-diff is the time window of --associate; without it poses are paired by index", source="--max-diff")
    if not (math.isfinite(max_diff) and max_diff > 0):  # (the library's error named the file pair and max_diff_s)
        raise ConfigError(f"must be a finite number of seconds > 0, got {max_diff:g}", source="--max-diff")
    if not (math.isfinite(delta) and delta > 0):
        raise ConfigError(f"must be a finite number > 0, got {delta:g}", source="--delta")
    atomic.check_target(markdown, "file")
    atomic.check_target(plot, "figure")
    atomic.check_target(tables, "folder")
    with named_by_option(_OPTION_OF_SETTING):  # a setting named as the library calls it ("delta: ..."): by its option
        settings = EvaluationSettings(  # (checked before any work: --delta 200 --delta-unit deg failed after the drift)
            align=align,
            delta=delta,
            delta_unit=delta_unit,
            all_pairs=all_pairs,
            legacy_pairs=legacy_pairs,
            associate=associate,
            max_diff_s=max_diff,
            drift=drift,
        )
        ref_traj = load(ref, ref_format, ref_times, "--ref-times")
        est_traj = load(est, est_format, est_times, "--est-times")
        evaluation = evaluate(ref_traj, est_traj, settings)
    # the outputs of one evaluation are written aside and moved in together: a failure (a full disk at the plot) or an
    # interrupt leaves every earlier output as it was, never one new beside one old; and before anything is printed (a
    # full disk on stdout lost them)
    files = [path for path in (json_out, markdown, plot) if path is not None]
    console = results_console(files)  # (before the files are written: one renamed over is no longer fd 1's)
    with contextlib.ExitStack() as stack:
        aside = stack.enter_context(atomic.paths_together(files))
        folder = stack.enter_context(atomic.run_folder(tables)) if tables is not None else None
        written, clock_note = _write_outputs(evaluation, ref, est, ref_traj, est_traj, aside, json_out, markdown, plot,
                                             folder, align, delta, delta_unit)
    if tables is not None:  # an earlier evaluation's tables (and box plot) this one does not hold
        from lidarkit.eval.tables import TABLE_FILES, remove_stale_tables

        remove_stale_tables(tables, (p.name for p in written), names=(*TABLE_FILES, _BOXPLOT_NAME))
    console.print(report.evaluation_table(evaluation))
    if evaluation.drift is not None:
        console.print(report.drift_table(evaluation))
    elif evaluation.drift_note:
        console.print(f"KITTI drift not computed: {evaluation.drift_note}")
    for note in [*report.evaluation_notes(evaluation), *([clock_note] if clock_note else [])]:
        console.print(f"note: {note}", soft_wrap=True, markup=False, highlight=False)
    for path in files:
        console.print(f"wrote {path}")
    if tables is not None:
        console.print(f"wrote {len(written)} table/plot files to {tables}", soft_wrap=True)


def _write_outputs(evaluation, ref: Path, est: Path, ref_traj, est_traj, aside: dict[Path, Path], json_out: Path | None,
                   markdown: Path | None, plot: Path | None, folder: Path | None, align: str, delta: float,
                   delta_unit: str) -> tuple[list[Path], str]:
    """Each requested output written to its temporary path (``aside``) or into the tables' temporary ``folder``; the
    names written there, and a note on how the tables' segments were timed ('' when by their stamps as they are)."""
    from lidarkit import atomic
    from lidarkit.eval import report

    if json_out is not None:
        data = evaluation.to_dict()
        # the poses read beside the pairs scored (``n_poses``), and what the CLI warned of on stderr
        data.update(ref_path=str(ref), est_path=str(est), n_ref_poses=len(ref_traj), n_est_poses=len(est_traj),
                    warnings=list(evaluation.warnings))
        report.write_json(data, aside[Path(json_out)])
    if markdown is not None:
        atomic.write_text(aside[Path(markdown)], report.evaluation_markdown(evaluation))
    if plot is not None:
        from lidarkit.eval import plots

        plots.plot_evaluation(evaluation, aside[Path(plot)])
    written: list[Path] = []
    clock_note = ""
    if folder is not None:
        from lidarkit.eval.tables import SegmentErrors, publication_tables, segment_clock

        key = (ref_traj.name or ref.stem, est_traj.name or est.stem)
        # segment speeds from the stamps of the poses as paired: the reference's, else the estimate's (a KITTI ground
        # truth without times took 0.1 s a frame under a 5 Hz estimate; associated poses with gaps took the median one),
        # with one median interval of those stamps for the last frame, as bench times them (KITTI's 0.1 s at 1 Hz
        # moved segments of KITTI 00 at every 10th pose into the 10-15 m/s row); an estimate's frame numbers (lidarkit
        # vo without times) under a ground truth without stamps are the devkit's 0.1 s frames (read as seconds, every
        # segment was in 0-5 m/s)
        clock = segment_clock(evaluation.ape.ref, evaluation.ape.est_aligned)
        clock_note = clock.note if evaluation.drift is not None else ""
        segments = ({key: SegmentErrors.from_drift(evaluation.drift, clock.frame_period_s, timestamps_s=clock.timestamps_s)}
                    if evaluation.drift is not None else None)
        from lidarkit.eval.ape_rpe import DELTA_UNITS, alignment_label

        def scaled(result) -> str:  # a Sim(3) / scale alignment's factor belongs beside the figures it changed
            t = result.alignment
            return f", estimate scaled by {t.scale:.4g}" if t is not None and t.rescaled else ""

        aligned = alignment_label(align) + scaled(evaluation.ape)
        unit = DELTA_UNITS.get(delta_unit, delta_unit)
        per = "frame" if (delta, unit) == (1, "frames") else f"{delta:g} {unit}"
        # the pairs' choice too, as the printed table states it (all pairs and consecutive ones read the same title)
        chosen = ", all pairs" if evaluation.rpe.all_pairs else ", legacy pairs" if evaluation.rpe.legacy_pairs else ""
        pub = publication_tables(segments, {key: evaluation.ape.rmse}, {key: evaluation.rpe.rmse}, ape_alignment=aligned,
                                 rpe_delta=per + chosen + scaled(evaluation.rpe), clock_note=clock_note)
        written = pub.write(folder)
        if segments:
            from lidarkit.eval.plots import plot_segment_boxplots

            written.append(plot_segment_boxplots(segments, folder / _BOXPLOT_NAME))
    return written, clock_note


def _relations_report(est_traj, relations_path: Path, max_diff_s: float, json_out: Path | None) -> None:
    """Relations metric of one trajectory: a table as in the 2009 paper (absolute and squared errors)."""
    from rich.table import Table

    from lidarkit.eval import report
    from lidarkit.eval.relations import relation_error
    from lidarkit.io.carmen import Relations

    result = relation_error(est_traj, Relations.read(relations_path), max_time_diff_s=max_diff_s)
    table = Table(title=f"relations metric: {result.n_used} of {result.n_relations} relations (|dt| <= {max_diff_s:g} s)")
    for column in ("error", "mean", "std", "max"):
        table.add_column(column, justify="right" if column != "error" else "left")
    for label, stats in (
        ("translational |e| (m)", result.translation_abs),
        ("translational e^2 (m^2)", result.translation_sq),
        ("rotational |e| (deg)", result.rotation_abs),
        ("rotational e^2 (deg^2)", result.rotation_sq),
    ):
        table.add_row(label, *(report._fmt(stats[k]) for k in ("mean", "std", "max")))  # (".4f" printed 3.6e-6 m² as 0.0000)
    console = results_console([json_out])
    if json_out is not None:  # (before the table: a full disk on stdout lost it)
        report.write_json({**result.to_dict(), "relations_path": str(relations_path)}, json_out)
    console.print(table)
    if json_out is not None:
        console.print(f"wrote {json_out}")


#: the per-segment box plot ``--tables`` writes beside its tables (and removes when there is no drift)
_BOXPLOT_NAME = "segments_translation_pct.png"

#: evaluation settings -> the option that sets them (a library error names the setting)
_OPTION_OF_SETTING = {"delta": "--delta", "delta_unit": "--delta-unit", "legacy_pairs": "--legacy-pairs", "align": "--align",
                      "all_pairs": "--all-pairs", "max_diff_s": "--max-diff", "drift_lengths_m": "--no-drift"}


def _distinct_outputs(inputs: dict[str, Path | None], outputs: dict[str, Path | None]) -> None:
    """ConfigError when an output would replace an input or another output (`--markdown EST` overwrote the estimate,
    `--json X --markdown X` the JSON, both with exit 0), also where a file is one the ``--tables`` folder writes or
    removes (`--markdown T/ape_rmse.md` was reported written, then replaced by the table)."""
    from lidarkit.atomic import resolved_path
    from lidarkit.eval.tables import TABLE_FILES

    tables = outputs.get("--tables")
    folder = resolved_path(tables, "--tables" in outputs) if tables is not None else None
    tables_own = {*TABLE_FILES, _BOXPLOT_NAME}
    seen: dict[Path, str] = {}
    for name, path in {**inputs, **outputs}.items():
        if path is None:
            continue
        resolved = resolved_path(path, name in outputs)
        if resolved in seen and name in outputs:  # (REF and EST may be one file)
            kind = "an input" if seen[resolved] in inputs else "another output"
            raise ConfigError(f"{path} is also {seen[resolved]} ({kind}): an output never replaces it", source=name)
        if resolved.parent == folder and resolved.name in tables_own:
            raise ConfigError(f"{path} is one of the files --tables writes or removes in {tables}: an output never "
                              "replaces it", source=name)
        seen[resolved] = name
