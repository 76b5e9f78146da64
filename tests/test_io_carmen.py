"""CARMEN reader options and relations files: values the reader once took in a wrong sense (a bool as 1 m, a relation
of a time with itself)."""

from __future__ import annotations

import bz2

import pytest

from conftest import cli_exit_code, shared_path
from lidarkit.errors import ConfigError, DataError
from lidarkit.io import open_dataset
from lidarkit.io.carmen import CarmenLog, Relations


@pytest.fixture(scope="module")
def aces_head(tmp_path_factory):
    """The first 400 lines of the real ACES log (193 FLASER scans) as a plain ``.clf``."""
    text = bz2.decompress(shared_path("carmen_2d", "aces.clf.bz2").read_bytes()).decode().splitlines()
    path = tmp_path_factory.mktemp("carmen") / "head.clf"
    path.write_text("\n".join(text[:400]) + "\n")
    return path


def test_a_bool_range_option_is_refused_not_read_as_metres(aces_head, capsys):
    """``min_range_m=true`` ran with min_range_m 1.0: pydantic's lax float read True as 1.0 in open_dataset, and
    CarmenLog's own check (np.isfinite) let True through as 1 m; text raised a TypeError from np.isfinite."""
    with pytest.raises(ConfigError) as err:
        open_dataset("carmen", aces_head, min_range_m=True)
    assert str(err.value) == "carmen dataset option min_range_m: must be a number, not a bool, got True"
    with pytest.raises(ConfigError) as err:
        open_dataset("carmen", aces_head, max_range_m=False)
    assert str(err.value) == "carmen dataset option max_range_m: must be a number, not a bool, got False"
    with pytest.raises(ConfigError) as err:
        CarmenLog(aces_head, min_range_m=True)
    assert str(err.value) == "carmen dataset options: min_range_m must be a finite number >= 0, got True"
    with pytest.raises(ConfigError) as err:
        CarmenLog(aces_head, max_range_m="40")
    assert str(err.value) == "carmen dataset options: max_range_m must be a finite number above min_range_m (0.0), got '40'"
    assert cli_exit_code(["odometry", f"carmen:{aces_head}?min_range_m=true", "--method", "vanilla",
                          "--out", str(aces_head.parent / "run")]) == 1
    assert "error: carmen dataset option min_range_m: must be a number, not a bool, got True" in capsys.readouterr().err
    assert not (aces_head.parent / "run").exists()
    # numbers still work, an int as its float
    log = open_dataset("carmen", aces_head, min_range_m=1, max_range_m=40)
    assert (log.min_range_m, float(log.max_range_m[0]), len(log)) == (1.0, 40.0, 193)


def test_a_relation_of_a_time_with_itself_is_refused_naming_its_line(tmp_path):
    """A row with t1 == t2 was read, then scored as "the same estimated pose nearest both their time stamps ... left
    out": a fault of the file blamed on the estimate."""
    path = tmp_path / "same.relations"
    path.write_text("# t1 t2 x y z roll pitch yaw\n90.239599 90.719599 0.42233 -0.00075 0 0 0 0.01726\n\n"
                    "94.3996 94.3996 0 0 0 0 0 0\n")
    with pytest.raises(DataError) as err:
        Relations.read(path)
    assert str(err.value) == f"{path} (line 4): t1 equals t2 (relation 2)"
    assert len(Relations.read(shared_path("carmen_2d", "aces.relations"))) == 1279  # the real file has none


def test_the_logs_odometry_is_the_callers_own_copy(aces_head):
    """One cached Trajectory was shared: a caller moving its poses in place moved what the next caller (a run's
    --init odometry) read."""
    log = open_dataset("carmen", aces_head)
    first = log.odometry
    kept = first.poses_se3.copy()
    first.poses_se3[:, 0, 3] += 100.0
    import numpy as np

    np.testing.assert_array_equal(log.odometry.poses_se3, kept)
