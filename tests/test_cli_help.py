"""Every command's --help reads as plain text: the docstrings' reST markup (``code``, :func:`x`) stays out of it."""

from __future__ import annotations

import re

import pytest

from conftest import cli_exit_code

from lidarkit.cli import main


def _command_paths() -> list[list[str]]:
    import typer

    from lidarkit.cli import app

    paths: list[list[str]] = []

    def walk(command, path: list[str]) -> None:
        paths.append(path)
        if isinstance(getattr(command, "commands", None), dict):  # a group (typer's own click or click's)
            for name, sub in command.commands.items():
                walk(sub, [*path, name])

    walk(typer.main.get_command(app), [])
    return paths


def test_every_help_is_free_of_rest_markup(capsys):
    paths = _command_paths()
    assert ["sim", "camera"] in paths and ["baseline", "check"] in paths and len(paths) > 15
    markup = re.compile(r"``|:(?:func|class|mod|meth|attr):`")
    for path in paths:
        assert cli_exit_code([*path, "--help"]) == 0, path
        text = capsys.readouterr().out
        assert not markup.search(text), (path, markup.search(text).group(0))


def test_version_is_an_option_too_and_the_package_runs_as_a_module(tmp_path, capsys):
    """`lidarkit --version` was "No such option" and `python -m lidarkit` "cannot be directly executed"; `lidarkit demo
    --out FILE` said "cannot write the results folder (File exists)" where every other command names the file in the way."""
    import subprocess
    import sys

    from lidarkit import __version__
    from lidarkit.cli import main

    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code in (0, None) and capsys.readouterr().out.strip() == __version__
    proc = subprocess.run([sys.executable, "-m", "lidarkit", "version"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0 and proc.stdout.strip() == __version__
    (tmp_path / "f").write_text("")
    with pytest.raises(SystemExit) as exc:
        main(["demo", "--quick", "--out", str(tmp_path / "f")])
    assert exc.value.code == 1
    assert "f: cannot write the folder: a file is in the way (a folder is needed here)" in capsys.readouterr().err


def test_a_benchmark_script_missing_its_data_says_so_in_one_line(tmp_path):
    """The benchmark scripts printed a traceback ending in the LidarKitError's line; they run their main() as the CLI
    runs a command."""
    import subprocess
    import sys
    from pathlib import Path

    script = Path(__file__).resolve().parents[1] / "benchmarks" / "pf_particles.py"
    proc = subprocess.run([sys.executable, str(script), "--data", str(tmp_path / "nowhere"), "--out", str(tmp_path / "out")],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 1
    assert proc.stderr.strip().splitlines() == [f"error: {tmp_path / 'nowhere' / 'pf' / 'robot_mapping_stachniss'}: landmark dataset not found"]


def test_an_empty_argument_is_refused_not_read_as_the_current_folder(tmp_path, monkeypatch, capsys):
    """`lidarkit odometry SEQ -o ""` (an unset shell variable) wrote the run into the current folder: typer reads "" as
    "."; every empty argument is refused, naming its option or position, before anything runs."""
    from lidarkit.cli import main

    monkeypatch.chdir(tmp_path)
    for argv, named in ((["odometry", "kitti:x", "-o", ""], "-o:"), (["odometry", "kitti:x", "--out="], "--out:"),
                        (["odometry", ""], "argument 2 (after odometry):")):
        with pytest.raises(SystemExit) as exc:
            main(argv)
        assert exc.value.code == 1
        err = capsys.readouterr().err
        assert f"{named} empty value (an unset shell variable?)" in err and len(err.strip().splitlines()) == 1, err
    assert list(tmp_path.iterdir()) == []


def test_an_empty_title_is_not_asked_for_as_a_path(tmp_path, monkeypatch, capsys):
    """`lidarkit odometry SEQ --name ""` said "give a path or a value", though --name takes a title: the wording
    fits every option and argument."""
    from lidarkit.cli import main

    monkeypatch.chdir(tmp_path)
    for argv, named in ((["odometry", "kitti:x", "-m", "vanilla", "--name", ""], "--name"), (["odometry", "kitti:x", "--name="], "--name")):
        with pytest.raises(SystemExit) as exc:
            main(argv)
        assert exc.value.code == 1
        assert capsys.readouterr().err == f"error: {named}: empty value (an unset shell variable?): give a non-empty value\n"

def test_demo_help_offers_only_its_own_options(capsys):
    """`lidarkit demo --help` said "dask (--address, or a local Dask cluster)"; demo has no --address."""
    assert cli_exit_code(["demo", "--help"]) == 0
    # the help's box borders are left out: a phrase wrapped at the terminal's width reads whole
    text = " ".join(re.sub("[│╭╮╰╯─]", " ", capsys.readouterr().out).split())
    assert "--address" not in text and "dask (a local Dask cluster)" in text


def test_every_out_option_has_the_short_form():
    """`lidarkit pf ... -o DIR` was typer's "No such option: -o" while every other command took it."""
    import typer

    from lidarkit.cli import app

    def options(command, path):
        for param in getattr(command, "params", []):
            yield path, list(param.opts)
        for name, sub in (getattr(command, "commands", None) or {}).items():
            yield from options(sub, [*path, name])

    outs = [(path, opts) for path, opts in options(typer.main.get_command(app), []) if "--out" in opts]
    assert len(outs) >= 8 and ["pf"] in [path for path, _ in outs]
    assert [(path, opts) for path, opts in outs if "-o" not in opts] == []


@pytest.mark.parametrize("argv, line", [
    (["bench", "suite.yaml", "--no-such"],
     "error: lidarkit bench: No such option: --no-such (see lidarkit bench --help)"),
    (["odometry"], "error: lidarkit odometry: Missing argument 'data' (see lidarkit odometry --help)"),
    (["odometry", "x", "--frames"],
     "error: lidarkit odometry: Option '--frames' requires an argument (see lidarkit odometry --help)"),
    (["no-such-command"], "error: lidarkit: No such command 'no-such-command' (see lidarkit --help)"),
])
def test_usage_errors_are_one_line_naming_the_command_and_its_help(capsys, argv, line):
    """An unknown option or a missing argument printed the framework's five-line box (usage, hint, a framed error),
    where every other bad input is one ``error:`` line; exit code 2 as before, nothing on stdout."""
    with pytest.raises(SystemExit) as exc:
        main(argv)
    out, err = capsys.readouterr()
    assert exc.value.code == 2 and out == ""
    assert " ".join(err.split()) == line


def test_a_command_that_ends_well_still_exits_with_code_0(capsys):
    """main(argv) ends with SystemExit(0) on success, as the framework's standalone run did (callers rely on it)."""
    with pytest.raises(SystemExit) as exc:
        main(["version"])
    assert exc.value.code == 0 and capsys.readouterr().out.strip()


def test_no_help_cuts_a_cell_with_an_ellipsis_at_80_columns(capsys, monkeypatch):
    """At 80 columns the wide --x/--no-x pairs of odometry and vo left their help column too narrow: six cells ended in
    '…' (``--no-pose-covaria…``, ``max_angular_accel…``, ``matching.klt_level…``); a long word now folds instead."""
    import typer.rich_utils

    monkeypatch.setenv("COLUMNS", "80")
    monkeypatch.setattr(typer.rich_utils, "MAX_WIDTH", 80)  # (typer's own width override, read from TERMINAL_WIDTH)
    pages = {}
    for path in _command_paths():
        assert cli_exit_code([*path, "--help"]) == 0, path
        pages[" ".join(path)] = capsys.readouterr().out
    assert {max(len(line) for line in text.splitlines()) for text in pages.values()} == {80}
    assert [(path, line) for path, text in pages.items() for line in text.splitlines() if "…" in line] == []
    assert "--no-pose-covariance" in pages["odometry"] and "--no-self-calibrate" in pages["vo"]
    for path, start, word in (("odometry", "Threshold of the", "max_angular_accel_dps2=500"),
                              ("vo", "Any config field", "matching.klt_levels=4")):
        lines = pages[path].splitlines()
        column = next(line.index(start) for line in lines if start in line)  # the help column: a folded word, rejoined
        assert word in "".join(line[column:].rstrip("│ ") for line in lines), path
