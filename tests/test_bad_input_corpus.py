"""The bad-input corpus: each case builds a bad input or a faulty output place in a temp folder and runs the CLI.

Every case must end as one ``error:`` line naming the culprit, exit code 1, no traceback and nothing
half-written. Grouped by family (issue #16): output paths, rich markup, backends, suites, parameter bounds,
messages that name the culprit.
"""

from __future__ import annotations

import errno
import gzip
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from lidarkit import atomic
from lidarkit.cli import main
from lidarkit.errors import LidarKitError, OutputError
from lidarkit.samples import sample_path

PAIR = sample_path("kitti_pair")
FREIBURG = sample_path("freiburg_pf")


def run_cli(args: list[str], capsys) -> tuple[int, str, str]:
    """Run ``lidarkit ARGS`` in this process; (exit code, stdout, stderr). Any other exception fails the test."""
    capsys.readouterr()
    try:
        main([str(a) for a in args])
        code = 0
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else 1
    out, err = capsys.readouterr()
    return code, out, err


def assert_one_line_error(code: int, err: str, *names: str) -> str:
    assert code == 1, err
    assert "Traceback" not in err
    lines = [line for line in err.splitlines() if line.startswith("error:")]
    assert len(lines) == 1, err
    text = " ".join(err.split())  # rich may wrap a long line
    for name in names:
        assert name in text, (name, err)
    return text


@pytest.fixture
def gt_file(tmp_path) -> Path:
    path = tmp_path / "gt.txt"
    with gzip.open(sample_path("evo_kitti00", "KITTI_00_gt.txt.gz"), "rt") as fh:
        path.write_text("".join(fh.readlines()[:30]))
    return path


# ---------------------------------------------------------------- output paths (Found 1)

def test_out_is_an_existing_file_icp(tmp_path, capsys):
    blocker = tmp_path / "taken"
    blocker.write_text("keep me")
    code, _, err = run_cli(["icp", PAIR / "000094.npy", PAIR / "000095.npy", "--out", blocker], capsys)
    assert_one_line_error(code, err, "taken", "a file is in the way")
    assert blocker.read_text() == "keep me"


def test_out_below_an_existing_file_pf(tmp_path, capsys):
    blocker = tmp_path / "taken"
    blocker.write_text("x")
    code, _, err = run_cli(["pf", FREIBURG, "-n", "20", "--out", blocker / "run"], capsys)
    assert_one_line_error(code, err, "taken", "a file is in the way")


def test_json_names_an_existing_directory(tmp_path, gt_file, capsys):
    (tmp_path / "adir").mkdir()
    code, _, err = run_cli(["eval", gt_file, gt_file, "--json", tmp_path / "adir"], capsys)
    assert_one_line_error(code, err, "adir", "is a folder")
    assert list((tmp_path / "adir").iterdir()) == []


def test_plot_with_an_unknown_suffix(tmp_path, gt_file, capsys):
    code, _, err = run_cli(["eval", gt_file, gt_file, "--plot", tmp_path / "out.txt", "--json", tmp_path / "e.json"], capsys)
    assert_one_line_error(code, err, "out.txt", "unknown plot format", ".png")
    assert not (tmp_path / "e.json").exists()  # refused before anything was written


def test_odometry_out_is_an_existing_file(tmp_path, capsys):
    blocker = tmp_path / "run"
    blocker.write_text("x")
    code, _, err = run_cli(["odometry", "sim:open?frames=3", "--out", blocker, "--no-progress"], capsys)
    assert_one_line_error(code, err, str(blocker), "a file is in the way")


def test_bench_out_is_an_existing_file(tmp_path, capsys):
    suite = tmp_path / "s.yaml"
    suite.write_text("experiments:\n  - task: selftest\n    dataset: {kind: synthetic}\n    methods: [random_walk]\n")
    blocker = tmp_path / "res"
    blocker.write_text("x")
    code, _, err = run_cli(["bench", suite, "--out", blocker, "--executor", "serial"], capsys)
    assert_one_line_error(code, err, "res", "a file is in the way")


def test_disk_full_while_writing_is_an_output_error(tmp_path, monkeypatch):
    def full(_fd):
        raise OSError(errno.ENOSPC, "No space left on device")

    target = tmp_path / "r.json"
    target.write_text("previous")
    monkeypatch.setattr(os, "fsync", full)
    with pytest.raises(OutputError, match="r.json: cannot write: no space left"):
        atomic.write_text(target, "new")
    assert target.read_text() == "previous"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.json"]


def test_failed_run_leaves_no_run_folder(tmp_path):
    out = tmp_path / "run"
    with pytest.raises(RuntimeError):
        with atomic.run_folder(out) as tmp:
            atomic.write_text(tmp / "config.yaml", "a: 1\n")
            raise RuntimeError("plotting failed")
    assert list(tmp_path.iterdir()) == []


def test_run_folder_into_an_existing_folder_keeps_other_files(tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    with atomic.run_folder(out) as tmp:
        atomic.write_text(tmp / "metrics.json", "{}")
        atomic.write_text(tmp / "plots" / "a.png", "png")
    assert sorted(str(p.relative_to(out)) for p in out.rglob("*")) == ["metrics.json", "notes.txt", "plots", "plots/a.png"]
    assert [p.name for p in tmp_path.iterdir()] == ["run"]


def test_pf_disk_full_mid_write_leaves_nothing(tmp_path, capsys, monkeypatch):
    """The disk fills up after the pf run folder's first two files: no folder that looks like a finished run."""
    calls = []
    real_fsync = os.fsync

    def fsync(fd):
        calls.append(fd)
        if len(calls) > 2:
            raise OSError(errno.ENOSPC, "No space left on device")
        real_fsync(fd)

    monkeypatch.setattr(os, "fsync", fsync)
    out = tmp_path / "pfrun"
    code, _, err = run_cli(["pf", FREIBURG, "-n", "20", "--out", out], capsys)
    assert_one_line_error(code, err, "pfrun", "no space left")
    assert len(calls) == 3
    assert list(tmp_path.iterdir()) == []


def _unshare_available() -> bool:
    if shutil.which("unshare") is None or sys.platform != "linux":
        return False
    probe = subprocess.run(["unshare", "-m", "sh", "-c", "mount -t tmpfs -o size=8k tmpfs /mnt"], capture_output=True)
    return probe.returncode == 0


needs_mount = pytest.mark.skipif(not _unshare_available(), reason="needs unshare -m and mount (root in a private mount namespace)")


def _in_private_tmpfs(tmp_path: Path, mount_opts: str, command: str) -> subprocess.CompletedProcess:
    """Run ``command`` with ``tmp_path/fs`` mounted as a small tmpfs in a private mount namespace (nothing leaks)."""
    (tmp_path / "fs").mkdir()
    script = f"mount -t tmpfs -o {mount_opts} tmpfs fs && {command}"
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    return subprocess.run(["unshare", "-m", "sh", "-c", script], cwd=tmp_path, capture_output=True, text=True, env=env,
                          timeout=120)


@needs_mount
def test_read_only_file_system(tmp_path, gt_file):
    proc = _in_private_tmpfs(tmp_path, "size=64k,ro", f"{sys.executable} -m lidarkit.cli eval {gt_file} {gt_file} --json fs/e.json")
    assert_one_line_error(proc.returncode, proc.stderr, "fs/e.json", "read-only file system")


@needs_mount
def test_disk_fills_up_during_bench(tmp_path):
    """The result folder on a 24 KiB file system: the run stops with one line naming the file; every result file
    that exists is complete JSON; nothing is left running."""
    suite = tmp_path / "s.yaml"
    suite.write_text(textwrap.dedent("""
        experiments:
          - task: selftest
            dataset: {kind: synthetic}
            methods: [{name: random_walk, params: {steps: 400}}]
            seeds: 40
    """))
    proc = _in_private_tmpfs(tmp_path, "size=24k", f"{sys.executable} -m lidarkit.cli bench {suite} --out fs/res "
                             f"--executor process -j 2 --no-report; rc=$?; "
                             f"{sys.executable} -c \"import json,glob; [json.load(open(p)) for p in glob.glob('fs/res/jobs/*.json')]\" "
                             f"|| echo CORRUPT; exit $rc")
    assert "CORRUPT" not in proc.stdout
    assert_one_line_error(proc.returncode, proc.stderr, "fs/res", "no space left")


# ---------------------------------------------------------------- rich markup in user strings (Found 3)

@pytest.mark.parametrize("name", ["bad[/red].txt", "scan[v2].txt", "[bold]x[/bold].txt"])
def test_markup_in_a_file_name_is_printed_verbatim(tmp_path, capsys, name):
    missing = tmp_path / name
    code, _, err = run_cli(["eval", missing, missing], capsys)
    assert_one_line_error(code, err, name)


def test_markup_in_a_bad_file_name_in_a_table(tmp_path, gt_file, capsys):
    named = tmp_path / "est[v2][bold red].txt"
    shutil.copy(gt_file, named)
    code, out, err = run_cli(["eval", gt_file, named], capsys)
    assert code == 0, err
    assert "est[v2][bold red]" in out


# ---------------------------------------------------------------- suites (Found 5: silent acceptance)

SUITE_OK = """\
name: s
seeds: [0, 1]
experiments:
  - name: a
    task: selftest
    dataset: {kind: synthetic}
    methods: [random_walk]
"""


@pytest.mark.parametrize("text, line, reason", [
    (SUITE_OK.replace("name: s\n", "name: s\nname: t\n"), 2, "duplicate key 'name' (first on line 1)"),
    (SUITE_OK.replace("    task: selftest\n", "    task: selftest\n    task: selftest\n"), 6, "duplicate key 'task'"),
    (SUITE_OK.replace("seeds: [0, 1]", "seeds: [0, 1, 1]"), 2, "duplicate seeds [1]"),
    (SUITE_OK.replace("methods: [random_walk]", "methods: [random_walk, random_walk]"), 7, "duplicate method 'random_walk'"),
    (SUITE_OK + SUITE_OK[SUITE_OK.index("  - name: a"):], 8, "duplicate experiment name 'a'"),
    (SUITE_OK.replace("methods: [random_walk]", "methods: [{name: random_walk, grid: {steps: [5, 5]}}]"), 7,
     "grid 'steps' lists a value twice"),
    (SUITE_OK.replace("seeds: [0, 1]", "seeds: [-1]"), 2, "seeds must be >= 0"),
])
def test_suite_duplicates_are_refused_with_file_and_line(tmp_path, capsys, text, line, reason):
    path = tmp_path / "suite.yaml"
    path.write_text(text)
    code, _, err = run_cli(["bench", path, "--dry-run"], capsys)
    assert_one_line_error(code, err, "suite.yaml", f"line {line}", reason)


def test_a_huge_grid_is_refused_instantly_with_its_count(tmp_path, capsys):
    import time

    path = tmp_path / "suite.yaml"
    grid = "{noise_m: [" + ", ".join(str(i / 1000) for i in range(1000)) + "], steps: [" + ", ".join(str(i) for i in range(2, 102)) + "]}"
    path.write_text(SUITE_OK.replace("methods: [random_walk]", f"methods: [{{name: random_walk, grid: {grid}}}]").replace(
        "seeds: [0, 1]", "seeds: 10"))
    t0 = time.perf_counter()
    code, _, err = run_cli(["bench", path, "--dry-run"], capsys)
    assert time.perf_counter() - t0 < 5.0
    assert_one_line_error(code, err, "suite.yaml", "1,000,000 jobs", "limit of 100,000", "--max-jobs")
    code, _, err = run_cli(["bench", path, "--dry-run", "--max-jobs", "999"], capsys)
    assert_one_line_error(code, err, "1,000,000 jobs", "limit of 999")
