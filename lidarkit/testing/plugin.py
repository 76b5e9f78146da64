"""pytest plugin (entry point ``lidarkit`` in the ``pytest11`` group): baseline fixtures for users' test suites.

- ``--lidarkit-baseline=DIR`` (relative to the directory pytest runs in, as pytest's own path options) or the ini
  option ``lidarkit_baseline`` (relative to the ini file's directory): the default baseline folder. Written with a space,
  pytest takes DIR for a test path when it looks for its ini file (before plugin options are known): its rootdir moves
  and the project's pytest.ini can be left unread.
- ``lidarkit_baseline``: that folder loaded as a :class:`lidarkit.bench.baseline.Baseline` (skips the test with
  a reason when none is configured; a folder that is missing or not a baseline errors each test using it with one
  line naming the folder and where it was set).
- ``load_lidarkit_baseline``: a fixture whose value loads any baseline folder (relative paths from the ini file's
  folder, else from where pytest runs);
  outside pytest, ``lidarkit.testing.load_baseline``.
"""

from __future__ import annotations

from pathlib import Path

import pytest


def pytest_addoption(parser):
    group = parser.getgroup("lidarkit")
    group.addoption("--lidarkit-baseline", action="store", default=None, metavar="DIR",
                    help="baseline folder written by `lidarkit baseline record` (fixture lidarkit_baseline)")
    parser.addini("lidarkit_baseline", "baseline folder for the lidarkit_baseline fixture", default="")


@pytest.fixture(scope="session")
def load_lidarkit_baseline(pytestconfig):
    """``load(path)`` -> Baseline; a relative path from the ini file's folder, else from where pytest runs (not from
    pytest's rootdir, which moves with the paths pytest is given: ``--lidarkit-baseline DIR`` with a space gives DIR as
    one, and the same test loaded another folder)."""
    from lidarkit.bench.baseline import load_baseline

    base = Path(pytestconfig.inipath).parent if pytestconfig.inipath else Path(pytestconfig.invocation_params.dir)

    def load(path):
        path = Path(path)
        return load_baseline(path if path.is_absolute() else base / path)

    return load


@pytest.fixture(scope="session")
def lidarkit_baseline(pytestconfig, load_lidarkit_baseline):
    """The configured baseline folder (``--lidarkit-baseline`` or ini ``lidarkit_baseline``)."""
    from lidarkit.errors import LidarKitError

    given = pytestconfig.getoption("--lidarkit-baseline")
    if given:  # a command-line path: from where pytest was started
        path, where = Path(pytestconfig.invocation_params.dir) / given, "--lidarkit-baseline"
    else:
        ini = pytestconfig.getini("lidarkit_baseline")
        if not ini:
            pytest.skip("no baseline configured: pass --lidarkit-baseline DIR or set lidarkit_baseline in pytest.ini")
        base = Path(pytestconfig.inipath).parent if pytestconfig.inipath else Path(pytestconfig.rootpath)
        path, where = base / ini, f"lidarkit_baseline in {pytestconfig.inipath or 'the ini file'}"
    try:
        return load_lidarkit_baseline(path)
    except LidarKitError as err:  # one line naming the folder, not a traceback through the plugin per test
        problem = f"{err} (set by {where})"
    pytest.fail(problem, pytrace=False)  # (outside the except: else pytest shows the DataError it replaces too)
