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


def _with_stamps(source, target, stamps_by_scan: dict[int, str]):
    """A copy of the log ``source`` with the ipc stamps of the given FLASER scans (0-based) replaced."""
    lines, scan = [], -1
    for line in source.read_text().splitlines():
        tokens = line.split()
        if tokens and tokens[0] == "FLASER":
            scan += 1
            if scan in stamps_by_scan:
                tokens[int(tokens[1]) + 8] = stamps_by_scan[scan]
                line = " ".join(tokens)
        lines.append(line)
    target.write_text("\n".join(lines) + "\n")
    return target


@pytest.mark.parametrize("scan, stamp", [(149, "0.0"), (2, "10.0")])
def test_one_glitched_stamp_moves_alone_to_between_its_neighbours(aces_head, tmp_path, scan, stamp):
    """ACES's 150th stamp set to 0.0 moved 34 stamps (27 correct ones by over 1 s, a 5.76 s gap made up at scan 149);
    the 3rd set to 10.0 moved scans 0-2 from 70.29 s to 50.23 s: the least-squares fit pooled the glitch with them. Only
    the glitch moves now, to halfway between its neighbours (by scan index)."""
    import numpy as np

    logged = CarmenLog(aces_head).timestamps_s
    log = CarmenLog(_with_stamps(aces_head, tmp_path / "glitch.clf", {scan: stamp}))
    others = np.arange(len(log)) != scan
    np.testing.assert_array_equal(log.timestamps_s[others], logged[others])
    assert log.timestamps_s[scan] == pytest.approx((logged[scan - 1] + logged[scan + 1]) / 2, abs=1e-9)
    assert logged[scan - 1] < log.timestamps_s[scan] < logged[scan + 1]
    assert (log.n_restamped, log.n_stamp_glitches) == (1, 1)
    assert abs(log.timestamps_s[scan] - logged[scan]) < 0.05  # (the stamp before the glitch: 93.3996 s, 70.5213 s)
    assert log.max_restamp_s == pytest.approx(log.timestamps_s[scan] - float(stamp))
    assert log.reader_options["stamps_corrected"].endswith("1 of them far from the stamps around them, placed between their neighbours)")
    np.testing.assert_array_equal(log.odometry.timestamps_s, log.timestamps_s)


def test_glitches_in_a_run_and_at_the_end_are_placed_by_scan_index(aces_head, tmp_path):
    """Three glitches in a row take the times between their good neighbours, a quarter of the gap apart; a glitch in
    the first or the last scan (no neighbour beyond it) is one scan period from the scan next to it; no correct stamp
    moves."""
    import numpy as np

    logged = CarmenLog(aces_head).timestamps_s
    last = len(logged) - 1
    glitches = {0: "5000.0", 100: "1.0", 101: "2.0", 102: "3.0", last: "0.5"}
    log = CarmenLog(_with_stamps(aces_head, tmp_path / "glitches.clf", glitches))
    bad = np.isin(np.arange(len(log)), list(glitches))
    np.testing.assert_array_equal(log.timestamps_s[~bad], logged[~bad])
    np.testing.assert_allclose(log.timestamps_s[100:103], logged[99] + (logged[103] - logged[99]) * np.array([1, 2, 3]) / 4, atol=1e-9)
    period = (logged[1] - log.timestamps_s[0], log.timestamps_s[last] - logged[last - 1])
    assert period[0] == pytest.approx(period[1]) and 0.1 < period[0] < 0.2  # (ACES: 0.156 s per scan)
    assert (log.n_restamped, log.n_stamp_glitches) == (5, 5)


def test_a_late_delivery_is_still_fitted_not_taken_for_a_glitch(aces_head, tmp_path):
    """A stamp 0.5 s late (3 scan periods; Intel's delivery times stray up to 5) is delivery jitter: pooled with its
    neighbours by the least-squares fit, as Intel's 2042 moved stamps are."""
    import numpy as np

    logged = CarmenLog(aces_head).timestamps_s
    log = CarmenLog(_with_stamps(aces_head, tmp_path / "late.clf", {149: f"{logged[149] + 0.5:.6f}"}))
    assert log.n_stamp_glitches == 0 and log.n_restamped > 1
    assert (np.diff(log.timestamps_s) > 0).all() and log.timestamps_s[149] < logged[149] + 0.5
    assert log.reader_options["stamps_corrected"].endswith("(they go back in file order)")
