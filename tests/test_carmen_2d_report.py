"""benchmarks/carmen_2d.py's report: --report-only without a results.json, and the "not conv." column."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import pytest

from lidarkit.errors import DataError

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "carmen_2d.py"
COMMITTED = SCRIPT.parent / "results" / "carmen_2d" / "results.json"


@pytest.fixture(scope="module")
def carmen_2d():
    spec = importlib.util.spec_from_file_location("carmen_2d_script", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_report_only_without_results_is_one_error_line(tmp_path):
    """--report-only on a folder without results.json ended in a FileNotFoundError traceback: one line, exit 1."""
    done = subprocess.run([sys.executable, str(SCRIPT), "--report-only", "--out", str(tmp_path)],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 1
    assert done.stderr.strip().splitlines() == [
        f"error: {tmp_path / 'results.json'}: no results.json: run the benchmark without --report-only first"]
    assert not (tmp_path / "README.md").exists()


def test_results_without_the_report_keys_are_a_data_error(tmp_path, carmen_2d):
    """A results.json of `{}` raised KeyError 'aces_rows'; one not JSON raised JSONDecodeError."""
    path = tmp_path / "results.json"
    path.write_text("{}\n")
    with pytest.raises(DataError) as err:
        carmen_2d.read_results(path)
    assert (err.value.source, err.value.reason) == (str(path), "not a results.json of this benchmark: no "
                                                    + ", ".join(carmen_2d.REPORT_KEYS))
    path.write_text("x{")
    with pytest.raises(DataError, match=r"results.json: not a readable JSON file \(Expecting value: line 1 column 1"):
        carmen_2d.read_results(path)


def test_a_variant_without_a_convergence_verdict_reads_n_a(carmen_2d):
    """kiss gives no verdict (metrics n_not_converged None), and `int(... or 0)` printed it as "not conv. 0"."""
    data = json.loads(COMMITTED.read_text())
    for row in data["aces_rows"]:
        if row["name"].startswith("kiss"):
            row["n_not_converged"] = None
    table = {line.split(" | ")[0][2:]: line for line in carmen_2d.report(data).splitlines() if line.startswith("| ")}
    assert table["kiss voxel 0.05 m, odometry guess"].endswith("| 64 | n/a |")
    assert table["kiss voxel 0.1 m, constant velocity"].endswith("| 83 | n/a |")
    assert table["vanilla planar"].endswith("| 94 | 0 |")
    assert table["raw odometry (baseline)"].endswith("| - | - |")


def test_rows_the_report_reads_are_checked_before_it_is_written(tmp_path, carmen_2d):
    """A row without one of the keys the report reads was a KeyError traceback, a best naming no row a StopIteration;
    the committed results still read."""
    committed = json.loads(COMMITTED.read_text())
    assert carmen_2d.read_results(COMMITTED)["best"] == committed["best"]
    path = tmp_path / "results.json"
    lacking = json.loads(COMMITTED.read_text())
    del lacking["aces_rows"][0]["rot_sq_mean_deg2"]
    path.write_text(json.dumps(lacking))
    with pytest.raises(DataError) as err:
        carmen_2d.read_results(path)
    assert err.value.reason == (f"not a results.json of this benchmark: aces_rows row {committed['aces_rows'][0]['name']!r} "
                                "has no rot_sq_mean_deg2")
    unknown = {**committed, "best": "nonexistent"}
    path.write_text(json.dumps(unknown))
    with pytest.raises(DataError, match="best 'nonexistent' names none of its aces_rows"):
        carmen_2d.read_results(path)


def test_a_value_the_report_formats_that_is_no_number_is_a_data_error(tmp_path, carmen_2d):
    """A null drift fps or a text improvement made the report's formatting raise TypeError / ValueError: one line naming
    the value. The raw odometry's ACES fps is null by design and still reads."""
    data = json.loads(COMMITTED.read_text())
    assert data["aces_rows"][0]["fps"] is None
    path = tmp_path / "results.json"
    path.write_text(json.dumps(data))
    assert carmen_2d.read_results(path)["best"] == data["best"]
    for change, said in ((lambda d: d["drift_vs_odometry"][0].update(fps=None), "drift_vs_odometry row 'aces' fps is None"),
                         (lambda d: d.update(improvement_over_odometry="x"), "improvement_over_odometry is 'x'")):
        bad = json.loads(COMMITTED.read_text())
        change(bad)
        path.write_text(json.dumps(bad))
        with pytest.raises(DataError, match=f"not a results.json of this benchmark: {said}, not a number"):
            carmen_2d.read_results(path)
