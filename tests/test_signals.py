"""Killing `lidarkit bench` (process pool): SIGTERM mid-run and SIGKILL of the parent alone. A few kills here;
the 20-per-signal run over both executors is benchmarks/bench_kill.py (results in benchmarks/results/reliability)."""

from __future__ import annotations

import signal
import sys
import textwrap
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import bench_kill  # noqa: E402

pytestmark = pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads the process table from /proc")


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL])
def test_killed_bench_leaves_no_orphans_no_corrupt_results_and_resumes(tmp_path, sig):
    suite = tmp_path / "suite.yaml"
    suite.write_text(textwrap.dedent(bench_kill.SUITE.format(n_jobs=8, job_s=0.3)))
    trial = bench_kill.kill_trial(suite, tmp_path / "out", "process", sig, delay_s=1.0, n_jobs=8)
    assert not trial["finished_before_signal"], trial  # the signal landed while jobs were running
    assert trial["returncode"] == bench_kill.expected_returncode(sig), trial
    assert trial["orphans"] == [], trial  # nothing alive 5 s after the parent ended (workers, fork server, tracker)
    assert trial["corrupt"] == 0 and not trial["traceback"], trial
    if sig == signal.SIGTERM:
        assert trial["message"].startswith("interrupted by SIGTERM") and "run the same command again" in trial["message"]
    assert trial["rerun_complete"], trial
    assert bench_kill.trial_ok(trial)
