"""Odometry suites on a CARMEN log: the ``init`` option (the log's odometry as each frame's guess) and the relations
metric scored in the job (the log has relation ground truth only: a job scored nothing and its report's headline was
"bad frames")."""

from __future__ import annotations

import textwrap
from pathlib import Path

import pytest
from conftest import shared_path

from lidarkit.bench.runner import run_suite
from lidarkit.bench.suite import load_suite
from lidarkit.errors import ConfigError

#: 60 ACES scans (90.2 s .. 100.2 s of the log) that 8 of its relations fall within
FRAMES = "130:190"
PARAMS = {"planar": True, "max_correspondence_distance_m": 0.5}


def aces_log() -> Path:
    return shared_path("carmen_2d", "aces.clf.bz2")


def write_suite(folder: Path, dataset: str, options: str, method: str = "vanilla") -> Path:
    path = folder / "suite.yaml"
    path.write_text(textwrap.dedent(f"""
        name: aces
        experiments:
          - name: aces_odo
            task: odometry
            dataset: {dataset}
            options: {options}
            methods:
              - {{name: {method}, params: {{planar: true, max_correspondence_distance_m: 0.5}}}}
        """))
    return path


def test_a_carmen_job_scores_the_relations_as_the_run_and_relation_error_do(tmp_path):
    from lidarkit.bench.report import build_report, summary_rows
    from lidarkit.eval.relations import relation_error
    from lidarkit.io import open_dataset
    from lidarkit.odometry import run

    log = aces_log()
    suite = load_suite(write_suite(tmp_path, f'{{kind: carmen, path: "{log}", name: ACES}}',
                                   f'{{frames: "{FRAMES}", init: odometry}}'))
    records = []
    run_suite(suite, tmp_path / "out", executor="serial", on_result=lambda job, record: records.append(record))
    (record,) = records
    metrics = record["metrics"]

    sequence = open_dataset("carmen", log)
    expected = relation_error(run(sequence, "vanilla", params=PARAMS, frames=FRAMES, init="odometry").trajectory,
                              sequence.relations)
    assert metrics["relation_trans_mean_m"] == pytest.approx(expected.translation_abs["mean"], rel=1e-9)
    assert metrics["relation_rot_mean_deg"] == pytest.approx(expected.rotation_abs["mean"], rel=1e-9)
    assert expected.n_used == 8 and metrics["relation_n_used"] == 8  # (how many relations the means are over)
    assert metrics["n_not_converged"] == 0  # (vanilla gives a verdict per frame; kiss's is left out: see below)
    odometry = record["info"]["odometry_metrics"]
    assert odometry["ground_truth_note"] == ("relations: 8 of 1279 scored (metrics relation_trans_mean_m, "
                                             "relation_rot_mean_deg)")
    assert record["info"]["config"]["run"]["initial_guess"] == "dataset odometry (relative motion)"
    _, rows = summary_rows(build_report(tmp_path / "out", plots=False))
    assert [row[2] for row in rows] == ["relations: mean trans. error [m]"]  # the headline, not "bad frames"


def test_init_odometry_is_refused_at_load_for_a_dataset_without_odometry(tmp_path):
    path = write_suite(tmp_path, "{kind: sim_lidar, n_frames: 5, name: sim}", "{init: odometry}")
    with pytest.raises(ConfigError) as caught:
        load_suite(path)
    assert "init: 'odometry' needs a dataset with its own odometry (e.g. a CARMEN log); kind 'sim_lidar' has none" in str(caught.value)


def test_an_unknown_init_is_refused_at_load_naming_the_known_ones(tmp_path):
    path = write_suite(tmp_path, "{kind: sim_lidar, n_frames: 5, name: sim}", "{init: imu}")
    with pytest.raises(ConfigError) as caught:
        load_suite(path)
    assert "init: unknown initial guess 'imu'; known: constant_velocity, odometry" in str(caught.value)


def test_the_default_init_is_pinned_with_the_task_options():
    from lidarkit.bench.tasks import get_task

    assert get_task("odometry").resolved_options({"frames": "0:5"}) == {"frames": "0:5", "init": "constant_velocity"}


def test_the_docs_odometry_row_names_init_and_the_relation_metrics():
    docs = Path(__file__).resolve().parents[1] / "docs" / "benchmarks.md"
    (row,) = [line for line in docs.read_text().splitlines() if line.startswith("| `odometry` |")]
    assert "`init` (`constant_velocity`, default, or `odometry`" in row
    assert "`relation_trans_mean_m`, `relation_rot_mean_deg`" in row


def test_a_run_whose_frames_meet_no_relation_says_why(tmp_path):
    """The note named "POSES_TUM (the run's poses_tum.txt, --out)", a file the run never wrote; the run scores the
    relations itself now, and says why none is scored over frames that meet none."""
    from lidarkit.io import open_dataset
    from lidarkit.odometry import run

    sequence = open_dataset("carmen", aces_log())
    result = run(sequence, "vanilla", params=PARAMS, frames="0:3")
    assert result.metrics["ground_truth_note"] == (
        "none: no scores here; the relation ground truth scores nothing of this run (no relation has estimated poses "
        "within 0.01 s of both its time stamps (estimate spans 70.290..70.521 s, relations 90.240..1410.780 s))")
    # the in-memory route gives the same reason: 3 frames meet no relation
    from lidarkit.errors import EvaluationError
    from lidarkit.eval import relation_error

    dataset = sequence
    with pytest.raises(EvaluationError, match="no relation has estimated poses within 0.01 s of both its time stamps"):
        relation_error(result.trajectory, dataset.relations)


def test_a_baseline_pinned_before_init_existed_is_checked_under_its_default(tmp_path):
    """A baseline whose odometry task options were pinned without ``init`` read "protocol changed: task_options.init:
    <absent> -> constant_velocity": the job ran as the default does."""
    import json

    from lidarkit.bench.baseline import check, record

    path = write_suite(tmp_path, "{kind: sim_lidar, n_frames: 3, n_beams: 16, n_azimuths: 360, name: sim}", "{}")
    baseline = record(path, tmp_path / "baseline", repeats=1)
    assert baseline.jobs[0]["protocol"]["task_options"] == {"frames": None, "init": "constant_velocity"}
    manifest_path = baseline.path / "manifest.json"
    manifest = json.loads(manifest_path.read_text())
    del manifest["jobs"][0]["protocol"]["task_options"]["init"]
    manifest_path.write_text(json.dumps(manifest))
    lines = check(baseline.path).lines()
    assert not any(line.startswith("protocol changed") for line in lines), lines
    assert any(line.startswith("note: ") and "the baseline pinned no task option init (recorded before the task had it)"
               in line for line in lines), lines


def test_a_carmen_job_whose_frames_cover_no_relation_warns_why_it_has_no_accuracy_metric(tmp_path):
    """ACES frames before its first relation: the job was "ok" with no accuracy metric, and why was only in its JSON's
    ``info.odometry_metrics.ground_truth_note``; it is now one of the job's warnings, listed in the report."""
    from lidarkit.bench.report import build_report

    suite = load_suite(write_suite(tmp_path, f'{{kind: carmen, path: "{aces_log()}", name: ACES}}', '{frames: "0:3"}'))
    records = []
    run_suite(suite, tmp_path / "out", executor="serial", on_result=lambda job, record: records.append(record))
    (record,) = records
    assert record["status"] == "ok" and "relation_trans_mean_m" not in record["metrics"]
    note = record["info"]["odometry_metrics"]["ground_truth_note"]
    assert note.startswith("relation ground truth, none scored over these frames: no relation has estimated poses "
                           "within 0.01 s of both its time stamps (estimate spans ")
    method = "vanilla(max_correspondence_distance_m=0.5, planar=True)"
    warning = f"WARNING lidarkit.bench.tasks.odometry: {method} on ACES: {note}; the job has no accuracy metric"
    assert warning in record["warnings"]
    report = build_report(tmp_path / "out", plots=False)
    assert (f"odometry | aces_odo | ACES | {method} | seed 0", warning) in report.warnings
    assert f"- odometry | aces_odo | ACES | {method} | seed 0: {warning}" in report.markdown_path.read_text()


def test_a_kiss_job_records_no_convergence_count(tmp_path):
    """kiss gives no convergence verdict: its bench jobs recorded n_not_converged 0.0 ("converged on every frame", and
    a baseline pinned it) where `lidarkit odometry` writes null; it is left out now."""
    from lidarkit.bench.jobs import Job
    from lidarkit.bench.tasks.odometry import run_odometry_job

    job = Job("odometry", "s", "street", {"kind": "sim_lidar", "n_frames": 3, "n_beams": 16, "n_azimuths": 360}, "kiss", {})
    result, output = run_odometry_job(job)
    assert not result.convergence_measured and "n_not_converged" not in output.metrics and "n_bad_frames" in output.metrics
