"""Every command's --help reads as plain text: the docstrings' reST markup (``code``, :func:`x`) stays out of it."""

from __future__ import annotations

import re

from conftest import cli_exit_code


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
