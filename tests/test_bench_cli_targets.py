"""`lidarkit bench` and `lidarkit demo` refuse a report path in the way before any job runs."""

from __future__ import annotations

import pytest
from conftest import cli_exit_code

SUITE = """name: tiny
seeds: [0]
experiments:
  - task: selftest
    dataset: {kind: synthetic, name: synth}
    methods:
      - name: random_walk
        params: {steps: 10}
"""


def test_a_file_named_tables_is_refused_before_any_job(tmp_path, capsys):
    """A file named tables (the publication tables' folder) in a results folder: every job ran, then "cannot create the
    folder"."""
    suite = tmp_path / "suite.yaml"
    suite.write_text(SUITE)
    out = tmp_path / "out"
    (out / "jobs").mkdir(parents=True)  # (a results folder, as an earlier run leaves it)
    (out / "tables").write_text("mine\n")
    code = cli_exit_code(["bench", str(suite), "--out", str(out), "--executor", "serial", "--no-progress"])
    err = capsys.readouterr().err.strip()
    assert list((out / "jobs").iterdir()) == []  # (no job ran)
    assert code == 1
    assert err.startswith(f"error: {out / 'tables'}: cannot ") and len(err.splitlines()) == 1
    assert (out / "tables").read_text() == "mine\n"


def test_the_demo_refuses_a_file_named_tables_before_any_job(tmp_path, capsys):
    """The demo writes the same report (and its evaluation in eval/): a file in the way is refused before its jobs."""
    suite = tmp_path / "suite.yaml"
    suite.write_text(SUITE)
    for name in ("tables", "eval"):
        out = tmp_path / f"demo_{name}"
        (out / "jobs").mkdir(parents=True)
        (out / name).write_text("mine\n")
        code = cli_exit_code(["demo", "--suite", str(suite), "--out", str(out), "--executor", "serial", "--no-progress"])
        err = capsys.readouterr().err.strip()
        assert list((out / "jobs").iterdir()) == []  # (no job ran)
        assert code == 1
        assert err.startswith(f"error: {out / name}: cannot ") and len(err.splitlines()) == 1


def test_a_suite_argument_that_is_a_dangling_link_is_named_as_given(tmp_path, capsys):
    """`lidarkit bench dang --dry-run` named the link's target ("nowhere: suite file not found"), not the argument."""
    dang = tmp_path / "dang"
    dang.symlink_to("nowhere")
    assert cli_exit_code(["bench", str(dang), "--dry-run", "--out", str(tmp_path / "out")]) == 1
    assert capsys.readouterr().err == f"error: {dang}: a symbolic link to a missing file (-> nowhere)\n"
    assert cli_exit_code(["bench", str(tmp_path / "absent.yaml"), "--dry-run", "--out", str(tmp_path / "out")]) == 1
    assert capsys.readouterr().err == f"error: {tmp_path / 'absent.yaml'}: suite file not found\n"


def test_a_suite_given_as_a_pipe_is_refused_naming_the_argument(tmp_path, capsys):
    """`lidarkit bench <(cat suite.yaml)` followed /dev/fd/63 to "/proc/<pid>/fd/pipe:[...]: suite file not found"."""
    import os

    read_end, write_end = os.pipe()
    try:
        os.write(write_end, SUITE.encode())
        piped = f"/dev/fd/{read_end}"
        assert cli_exit_code(["bench", piped, "--dry-run", "--out", str(tmp_path / "out")]) == 1
        assert capsys.readouterr().err == f"error: {piped}: a pipe (e.g. <(...)): save it to a file first\n"
        from lidarkit.bench.baseline import record  # (the library's record resolved it first: "suite file not found")
        from lidarkit.errors import DataError

        with pytest.raises(DataError) as info:
            record(piped, tmp_path / "baseline")
        assert str(info.value) == f"{piped}: a pipe (e.g. <(...)): save it to a file first"
    finally:
        os.close(read_end)
        os.close(write_end)


def test_a_point_file_given_as_a_pipe_is_refused_naming_the_argument(tmp_path, capsys):
    """`lidarkit icp <(cat X.pcd) Y.pcd` read "/dev/fd/63: unsupported point file type ''"."""
    import os

    import numpy as np

    target = tmp_path / "target.npy"
    np.save(target, np.random.default_rng(0).normal(size=(100, 3)))
    read_end, write_end = os.pipe()
    try:
        piped = f"/dev/fd/{read_end}"
        assert cli_exit_code(["icp", piped, str(target)]) == 1
        assert capsys.readouterr().err == f"error: {piped}: a pipe (e.g. <(...)): save it to a file first\n"
    finally:
        os.close(read_end)
        os.close(write_end)
