"""``lidarkit icp SOURCE TARGET --method NAME``: register two scans, print the result, write JSON + BEV plot."""

from __future__ import annotations

import contextlib
import inspect
import json
import re
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Optional

import numpy as np
import typer
from rich.table import Table
from rich.text import Text


from lidarkit.cli.app import app, stdout
from lidarkit.errors import ConfigError, DataError
from lidarkit.params import shown_default

if TYPE_CHECKING:
    from lidarkit.registration.base import RegistrationResult


def read_init_pose(path: Path) -> np.ndarray:
    """A 4x4 pose from a text file: 4 (or 3) rows of 4 numbers, or one row of 12 (KITTI) or 16 numbers; numpy's print of
    a matrix (``[[1. 0. 0. 0.5] ...]``, or its repr ``array([[...]])``) or a JSON list of rows is read without its brackets. A JSON file of anything
    else (a run's result.json) or a first line of words is said to be one ("expected 4 or 12 or 16 numbers, found 1"
    did not)."""
    from lidarkit.textfile import is_number, read_lines, read_numeric_table

    lines = [line.strip() for line in read_lines(path, "4x4 pose file") if line.strip() and not line.strip().startswith("#")]
    shown = re.fullmatch(r"array\((.*?)(?:,\s*dtype=\w+)?\)", "\n".join(lines), re.DOTALL)
    if shown:  # numpy's repr, as a notebook shows a matrix (its "array([[" was counted as a fifth number)
        lines = [line.strip() for line in shown.group(1).splitlines() if line.strip()]
    first = lines[0] if lines else ""
    wanted = "--init takes a 4x4 or 3x4 text matrix, or one row of 12 (KITTI) or 16 numbers"
    T = np.eye(4)
    if first.startswith(("{", "[")):
        numbers = _bracketed_numbers(path, "\n".join(lines), wanted)
        T[: len(numbers) // 4] = numbers.reshape(-1, 4)
    else:
        if first and not any(is_number(field) for field in first.replace(",", " ").split()):
            raise DataError(f"its first line holds no numbers ({first[:40]!r}): {wanted}", source=path)
        table = read_numeric_table(path, (4, 12, 16))
        if table.shape[1] == 4 and len(table) in (3, 4):
            T[: len(table)] = table
        elif table.shape[1] in (12, 16) and len(table) == 1:
            T[: table.shape[1] // 4] = table.reshape(-1, 4)
        else:
            raise DataError(f"expected a 4x4 / 3x4 matrix or one row of 12 or 16 numbers, got {table.shape}", source=path)
    from lidarkit.registration.base import check_init_T

    return check_init_T(T, source=str(path))


def _bracketed_numbers(path: Path, text: str, wanted: str) -> np.ndarray:
    """The numbers of a bracketed matrix, row by row: numpy's print, which is no JSON (no commas), or a JSON list of
    rows; the innermost brackets are its rows (3 or 4 of 4 numbers, or one of 12 or 16). Only JSON that is something
    else is called JSON: numpy's print was "holds JSON"."""
    from lidarkit.textfile import is_number

    try:
        parsed = json.loads(text)
    except ValueError:
        parsed = None
    fields = text.translate(str.maketrans("[],", "   ")).split()
    words = [field for field in fields if not is_number(field)]
    if text.startswith("{") or isinstance(parsed, dict) or (parsed is not None and words):
        raise DataError(f"holds JSON (a run's result.json?), not a text matrix: {wanted}", source=path)
    if words:
        raise DataError(f"holds {words[0][:20]!r} within its brackets, not a matrix of numbers: {wanted}", source=path)
    rows = [row.replace(",", " ").split() for row in re.findall(r"\[([^\[\]]*)\]", text)]
    widths = sorted({len(row) for row in rows})
    if not ((widths == [4] and len(rows) in (3, 4)) or (widths in ([12], [16]) and len(rows) == 1)):
        got = ", ".join(str(len(row)) for row in rows)
        raise DataError(f"holds bracketed rows of {got} numbers, not 4 (or 3) rows of 4 or one of 12 or 16: {wanted}", source=path)
    return np.array([float(field) for row in rows for field in row], dtype=np.float64)


def _list_methods() -> None:
    from lidarkit.registration import available_icp, config_fields, get_icp_class
    from lidarkit.registration.registry import broken_plugins
    from lidarkit.registration.base import assessed_apart

    table = Table(title="ICP variants (lidarkit icp --method NAME --param key=value)", show_lines=True)
    table.add_column("method", style="bold")
    table.add_column("parameters (default) — description")
    for name in available_icp():
        cls = get_icp_class(name)
        doc = first_sentence(cls.__doc__)
        cell = Text(doc, style="italic") if doc else Text()
        for key, (type_name, default, desc) in config_fields(name).items():
            if key == "assess" and not assessed_apart(cls):
                continue  # refused by the variants that score their result within their own iterations
            cell.append(("\n" if cell else "") + f"{key}: {type_name} = {shown_default(default)} — {desc}")
        table.add_row(name + (" (stateful)" if cls.stateful else ""), cell)
    stdout().print(table)
    _print_left_out(broken_plugins())
    from lidarkit.registration.registry import missing_optional_variants

    for name, pip in missing_optional_variants().items():  # (left out without a word)
        stdout().print(f"{name!r} not installed: {pip}", style="yellow", markup=False, highlight=False)
    _list_ground_segmenters()


def _list_ground_segmenters() -> None:
    from lidarkit.registration.ground import available_ground_segmenters, get_ground_segmenter_class, ground_config_fields

    table = Table(title="Ground segmenters of ground_filtered (-p ground_method=NAME -p 'ground_params={key: value}')", show_lines=True)
    table.add_column("segmenter", style="bold")
    table.add_column("parameters (default) — description")
    for name in available_ground_segmenters():
        lines = [f"{key}: {type_name} = {shown_default(default)} — {desc}" for key, (type_name, default, desc) in ground_config_fields(name).items()]
        table.add_row(name, _described(first_sentence(get_ground_segmenter_class(name).__doc__), lines))
    stdout().print(table)


def _list_components() -> None:
    from lidarkit.registration.components import KINDS, available_components, component_fields, get_component_class

    table = Table(title="pipeline components (-m pipeline -p residual=|kernel=|threshold=|deskew=|map=NAME -p 'preprocess=[NAME, ...]'; "
                        "motion goes in deskew=)", show_lines=True)
    table.add_column("kind / name", style="bold")
    table.add_column("parameters (default) — description")
    for kind in KINDS:
        for name in available_components(kind):
            cls = get_component_class(kind, name)
            lines = [f"{key}: {type_name} = {shown_default(default)} — {desc}" for key, (type_name, default, desc) in component_fields(kind, name).items()]
            table.add_row(f"{kind} / {name}", _described(first_sentence(cls.__doc__), lines))
    stdout().print(table)
    from lidarkit.registration.components.registry import broken_component_plugins

    _print_left_out(broken_component_plugins())


def _print_left_out(broken: dict[str, str]) -> None:
    """One line per installed plugin that failed to load, with the reason (the listing above leaves it out)."""
    for name, reason in broken.items():
        stdout().print(f"plugin {name!r} left out: {reason}", style="yellow", markup=False, highlight=False)


def first_sentence(doc: str | None) -> str:
    """A docstring's first sentence, joined over its lines (up to ". " or the first blank line): its first physical
    line ended mid-sentence in the listings ("... The covariances are")."""
    paragraph = " ".join(inspect.cleandoc(doc or "").split("\n\n")[0].split())
    end = re.search(r"(?<!e\.g)(?<!i\.e)\.(\s|$)", paragraph)
    return paragraph[: end.start() + 1] if end else paragraph


def _described(doc: str, lines: list[str]):
    """A table cell: the docstring's first sentence in italics, then the parameter lines (plain text: the console prints
    no markup, so a markup tag would show as text)."""
    from rich.text import Text

    cell = Text(doc, style="italic")
    for line in lines:
        cell.append(("\n" if len(cell) else "") + line)
    return cell


def _result_table(result, source: Path, target: Path) -> Table:
    table = Table(title=f"{result.method}: {source.name} -> {target.name}", show_header=True)
    table.add_column("quantity")
    table.add_column("value", justify="right")
    T = result.T_target_source
    table.add_row("T_target_source", "\n".join(" ".join(f"{v: .6f}" for v in row) for row in T))
    table.add_row("converged", str(result.converged) + (f" ({result.reason})" if result.reason else ""))
    # with assess=False a result keeps every count its backend reports (small_gicp's): one without a count is a backend
    # that reports none (kiss, Open3D), whatever assess is ("not recorded (assess=False)" read as if assess=true gave one)
    reported = result.extra.get("iterations_reported", True)
    table.add_row("iterations", str(result.iterations) if reported else "not reported by the backend")
    if not result.extra.get("assessed", True):
        table.add_row("runtime (s)", f"{result.runtime_s:.3f}")
        table.add_row("assessment", "off (assess=False): no correspondences, fitness, RMSE, degeneracy or covariance")
        return table
    table.add_row("final RMSE (m)", f"{result.rmse:.4f}")
    table.add_row("correspondences / fitness", f"{result.n_correspondences} / {result.fitness:.3f}")
    table.add_row("runtime (s)", f"{result.runtime_s:.3f}")
    deg = result.degeneracy
    if not np.isfinite(deg.ratio):  # no correspondences: nothing to judge ("nan (ok, ...)" read as a verdict)
        table.add_row("degeneracy min/max eig", deg.kind)  # "unknown (too few correspondences)"
    else:
        table.add_row("degeneracy min/max eig", f"{deg.ratio:.2e} ({'DEGENERATE' if deg.degenerate else 'ok'}, threshold {deg.threshold:g})")
        table.add_row("eigenvalues", " ".join(f"{e:.3g}" for e in deg.eigenvalues))
        weakest = ", ".join(f"{n}={v:+.2f}" for n, v in zip(("tx", "ty", "tz", "rx", "ry", "rz"), deg.weakest_direction) if abs(v) > 0.1)
        table.add_row("weakest direction", (f"{deg.weakest_name} ({weakest})" if deg.weakest_name else weakest) or "-")
    if deg.weak_directions:
        table.add_row("degenerate directions", "; ".join(deg.weak_directions) + " (sensor frame of the target)")
    if result.covariance is not None:
        from lidarkit.registration.assessment import COVARIANCE_ORIGIN_KEY

        origin = result.extra.get(COVARIANCE_ORIGIN_KEY)
        # clouds far from their frame's origin (UTM): about that origin a rotation's lever arm is kilometres and the
        # translation sigmas read 355 / 39.5 / 1740 m; about the target's sensor they are the registration's own
        covariance = result.covariance if origin is None else result.covariance_about(origin)
        sigma = np.sqrt(np.clip(np.diag(covariance), 0, None))
        label = "1-sigma (m / deg)" if origin is None else "1-sigma (m / deg, about " + " ".join(f"{v:.1f}" for v in origin) + ")"
        table.add_row(label, "t " + " ".join(f"{v:.3g}" for v in sigma[:3]) + "  r " + " ".join(f"{np.degrees(v):.3g}" for v in sigma[3:]))
    return table


#: The flag (or argument) of each of icp's parameters that a run reads and a listing does not.
RUN_OPTIONS = {"source": "SOURCE", "target": "TARGET", "method": "--method", "param": "--param", "init": "--init", "out": "--out",
               "drop_nonfinite": "--drop-nonfinite"}


def _refuse_run_options(ctx: typer.Context, listing: str) -> None:
    """A run's argument or option given with a listing is a ConfigError (the listing ignored them and exited 0: no
    registration, no --out folder, an unknown --method said nothing)."""
    given = [flag for name, flag in RUN_OPTIONS.items()
             if (src := ctx.get_parameter_source(name)) is not None and src.name == "COMMANDLINE"]
    if given:
        raise ConfigError(f"lists and exits, registering nothing: {', '.join(given)} {'do' if len(given) > 1 else 'does'} not apply",
                          source=listing)


def _refuse_others_files(out: Optional[Path]) -> None:
    """OutputError when ``out`` holds files named like an icp run's but never held one (no config.json of an icp run):
    the run replaced a user's own result.json and bev.png; odometry, vo and pf refuse such a folder by its config.yaml."""
    import os

    from lidarkit.errors import OutputError
    from lidarkit.run_files import ICP

    if out is None or not out.is_dir() or _holds_an_icp_run(out):
        return
    own = sorted(name for name in ICP if os.path.lexists(out / name))
    if own:  # (config.json is moved in last: a run a SIGKILL cut off looks the same, the message says either)
        raise OutputError(f"holds files named like an icp run's ({', '.join(own)}) but no config.json written by lidarkit icp "
                          "(the user's own, or a run cut off before it was complete): a run would replace them; remove them "
                          "or give a new or empty folder", source=out)


def _holds_an_icp_run(out: Path) -> bool:
    """Whether ``out`` holds the config.json an icp run writes (a JSON object with its method and params)."""
    try:
        config = json.loads((out / "config.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return isinstance(config, dict) and {"method", "params"} <= config.keys()


@contextlib.contextmanager
def clouds_named(paths: dict[str, Path]) -> Iterator[None]:
    """An error the registration raises about a cloud by its role ("source cloud: needs at least 3 points, got 1") names
    the file it was read from: ``paths`` maps each role to its file."""
    from lidarkit.errors import LidarKitError

    try:
        yield
    except LidarKitError as err:
        path = paths.get(err.source or "")
        if path is None:
            raise
        location = err.source if err.location is None else f"{err.source}, {err.location}"
        raise type(err)(err.reason, source=path, location=location) from err


def no_rmse_note(result: RegistrationResult) -> str:
    """What rmse.png says when ``result`` holds no RMSE: assess=False only where the result says it
    was not assessed, else its reason (a run without initial overlap read "assess=False" though vanilla is always assessed)."""
    import textwrap

    if result.extra.get("assessed") is False:
        return "no RMSE: the assessment was left out (assess=False)"
    return textwrap.fill(f"no RMSE: {result.reason}" if result.reason else "no RMSE recorded", width=70)


@app.command("icp")
def icp(
    ctx: typer.Context,
    source: Optional[Path] = typer.Argument(None, help="Source scan (.bin KITTI, .pcd, .ply, .npy); moved onto the target."),
    target: Optional[Path] = typer.Argument(None, help="Target scan (same formats)."),
    method: str = typer.Option("vanilla", "--method", "-m", help="Registered ICP variant (see --list)."),
    param: list[str] = typer.Option([], "--param", "-p", help="Method parameter KEY=VALUE (repeatable)."),
    init: Optional[Path] = typer.Option(None, "--init", help="Initial T_target_source: 4x4 text file (numpy's print of one too) or one KITTI row."),
    out: Optional[Path] = typer.Option(None, "--out", "-o", help="Folder for result.json, config.json, bev.png and rmse.png (RMSE per iteration)."),
    drop_nonfinite: bool = typer.Option(
        False, "--drop-nonfinite", help="Drop NaN / infinite points (organized clouds' missing returns) instead of refusing the file."
    ),
    list_methods: bool = typer.Option(False, "--list", help="List the registered variants with their parameters and exit."),
    list_components: bool = typer.Option(
        False, "--list-components", help="List the components the 'pipeline' variant composes (by kind) and exit."
    ),
) -> None:
    """Register SOURCE onto TARGET with one ICP variant; prints T_target_source, iterations, RMSE, degeneracy."""
    if list_methods or list_components:
        _refuse_run_options(ctx, " ".join(flag for flag, on in (("--list", list_methods), ("--list-components", list_components)) if on))
        if list_methods:
            _list_methods()
        if list_components:  # (both flags print both listings)
            _list_components()
        return
    if source is None or target is None:
        raise ConfigError("give SOURCE and TARGET scan files (or --list)", source="lidarkit icp")
    from lidarkit.atomic import run_folder, write_text
    from lidarkit.cli.app import parse_params
    from lidarkit.io.pointfile import read_point_file
    from lidarkit.registration import get_icp

    from lidarkit.atomic import check_target

    from lidarkit.run_files import ICP

    check_target(out, "folder", files=ICP)
    _refuse_others_files(out)
    registration = get_icp(method, **parse_params(param))
    init_T = read_init_pose(init) if init is not None else None  # (a bad guess was refused after both clouds were read)
    source_xyz = read_point_file(source, drop_nonfinite=drop_nonfinite).points_xyz
    target_xyz = read_point_file(target, drop_nonfinite=drop_nonfinite).points_xyz
    with clouds_named({"source cloud": source, "target cloud": target}):
        result = registration.align(source_xyz, target_xyz, init_T=init_T)
    if out is not None:  # (written before anything is printed: a stdout that refuses it lost the folder)
        from lidarkit.registration.plots import save_bev_before_after, save_rmse_history

        payload = {"source": str(source), "target": str(target), "init": None if init is None else str(init),
                   "drop_nonfinite": drop_nonfinite, **result.to_dict()}
        with run_folder(out, replaces=ICP) as tmp:
            write_text(tmp / "result.json", json.dumps(payload, indent=2, allow_nan=False) + "\n")
            write_text(tmp / "config.json", json.dumps({"method": method, "params": registration.config.model_dump(mode="json")}, indent=2, allow_nan=False) + "\n")
            save_bev_before_after(
                tmp / "bev.png", source_xyz, target_xyz, result.T_target_source, init_T, title=f"{method}: {source.name} -> {target.name}"
            )
            # the report's RMSE-per-iteration figure (one point for a backend that reports its final RMSE only)
            coarse = result.extra.get("coarse_iterations")
            save_rmse_history(tmp / "rmse.png", {method: result.rmse_history}, title=f"{method}: {source.name} -> {target.name}",
                              coarse_iterations={method: coarse} if coarse else None,
                              empty_note=no_rmse_note(result))
    stdout().print(_result_table(result, source, target))
    if out is not None:
        stdout().print(f"wrote {', '.join(str(out / name) for name in ('result.json', 'config.json', 'bev.png', 'rmse.png'))}")
