"""`lidarkit bench` and `lidarkit demo` refuse a report path in the way before any job runs."""

from __future__ import annotations

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
