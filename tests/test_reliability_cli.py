"""The CLI's own output refused by the system: one line, whatever prints it."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="needs /dev/full (a device that is always full)")
@pytest.mark.parametrize("args", [["--help"], ["eval", "--help"], []])
def test_a_help_page_on_a_full_stdout_is_the_one_stdout_line(args):
    """`lidarkit --help > /dev/full` printed a 133-line traceback (rich, inside click's help, raised ENOSPC); it is the
    line `lidarkit version > /dev/full` gives, exit 1."""
    with open("/dev/full", "w") as full:
        done = subprocess.run([sys.executable, "-m", "lidarkit", *args], stdout=full, stderr=subprocess.PIPE, text=True,
                              timeout=120)
    assert (done.returncode, done.stderr) == (1, "error: stdout: cannot write: no space left on the device\n")


def test_help_still_prints_in_full_and_stdout_is_restored(capsys):
    """The command's stdout is wrapped only while it runs: the help page is printed as before."""
    from lidarkit.cli import main

    stream = sys.stdout
    with pytest.raises(SystemExit) as exc:
        main(["eval", "--help"])
    assert exc.value.code == 0 and "--json" in capsys.readouterr().out
    assert sys.stdout is stream
