"""`lidarkit compare` given CARMEN odometry runs or a CARMEN log's folder: what it says to run instead."""

from __future__ import annotations

import bz2
import shutil

import pytest

from conftest import shared_path
from lidarkit.cli import main

CARMEN_ADVICE = ("CARMEN runs are compared only as bench results: run a suite with an odometry experiment over the log "
                 "(lidarkit bench SUITE, docs/benchmarks.md), then lidarkit compare RESULTS RESULTS --method-a A --method-b B")


@pytest.fixture
def short_aces(tmp_path):
    """A folder holding ACES's first 10 scans as a CARMEN log and the ACES relations beside it."""
    lines = bz2.decompress(shared_path("carmen_2d", "aces.clf.bz2").read_bytes()).decode().splitlines(keepends=True)
    last = [k for k, line in enumerate(lines) if line.startswith("FLASER")][9]
    data = tmp_path / "data"
    data.mkdir()
    (data / "aces.clf").write_text("".join(lines[:last + 1]))
    shutil.copy(shared_path("carmen_2d", "aces.relations"), data / "aces.relations")
    return data


def _error_of(argv, capsys) -> str:
    with pytest.raises(SystemExit) as exc:
        main(argv)
    out, err = capsys.readouterr()
    assert (int(exc.value.code or 0), out) == (1, "")
    return err


def test_carmen_runs_are_named_as_such_with_the_bench_route(short_aces, tmp_path, capsys):
    """Two ACES run folders read "no ground_truth_kitti.txt: a paired comparison needs the estimate and its ground
    truth", not saying that CARMEN runs are compared only as bench results, nor what to run."""
    from lidarkit.odometry import run

    runs = [tmp_path / name for name in ("a", "b")]
    run(f"carmen:{short_aces / 'aces.clf'}", "vanilla", params={"planar": True}, frames="0:3", out_dir=runs[0])
    shutil.copytree(runs[0], runs[1])
    said = (f"an odometry run over the CARMEN log aces.clf (its ground truth: relations between scan times, no poses): "
            f"compare pairs run folders by their ground-truth poses; {CARMEN_ADVICE}")
    assert _error_of(["compare", str(runs[0]), str(runs[1])], capsys) == f"error: {runs[0]}: {said}\n"
    assert _error_of(["compare", str(runs[1]), str(runs[0])], capsys) == f"error: {runs[1]}: {said}\n"


def test_a_carmen_log_folder_is_named_as_a_dataset_folder(short_aces, tmp_path, capsys):
    """A folder holding a CARMEN log read "no metrics.json: not a finished odometry run folder", where a KITTI or scan
    folder is named as a dataset folder with what to run."""
    other = tmp_path / "other"
    other.mkdir()
    err = _error_of(["compare", str(short_aces), str(other)], capsys)
    assert err == (f"error: {short_aces}: a dataset folder (a CARMEN log: aces.clf, aces.relations): compare takes run "
                   f"folders; {CARMEN_ADVICE}\n")
    logs = shared_path("carmen_2d")
    err = _error_of(["compare", str(logs), str(logs)], capsys)
    assert err.startswith(f"error: {logs}: a dataset folder (3 CARMEN logs: aces.clf.bz2, fr079.clf.bz2, intel.clf.bz2, "
                          "aces.relations): compare takes run folders; CARMEN runs are compared only as bench results")
