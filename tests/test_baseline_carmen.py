"""Baselines and suites of CARMEN logs: the ``.relations`` file the reader finds beside the log is part of the data
(pinned, and looked up beside the path as given, not beside a linked log's target)."""

from __future__ import annotations

import shutil
import textwrap
from pathlib import Path

from conftest import shared_path

from lidarkit.bench.baseline import check, dataset_checksums, record
from lidarkit.bench.suite import load_suite

#: 60 ACES scans that 8 of its relations fall within
FRAMES = "130:190"


def _write_suite(folder: Path, log: str) -> Path:
    path = folder / "suite.yaml"
    path.write_text(textwrap.dedent(f"""
        name: aces
        datasets:
          aces: {{kind: carmen, path: {log}}}
        experiments:
          - name: aces_odo
            task: odometry
            dataset: aces
            options: {{frames: "{FRAMES}", init: odometry}}
            methods:
              - {{name: vanilla, params: {{planar: true, max_correspondence_distance_m: 0.5}}}}
        """))
    return path


def _aces_copy(folder: Path) -> Path:
    folder.mkdir()
    for name in ("aces.clf.bz2", "aces.relations"):
        shutil.copy(shared_path("carmen_2d", name), folder / name)
    return folder / "aces.clf.bz2"


def test_a_changed_relations_file_beside_the_log_is_a_changed_protocol_not_a_regression(tmp_path):
    """An edited ``aces.relations`` read as "regression: relation_trans_mean_m = 0.0625, baseline 0.0327" (the method
    blamed) and a deleted one as the metric "missing now": the reader's relations file was not hashed."""
    log = _aces_copy(tmp_path / "acescopy")
    suite = _write_suite(tmp_path, "acescopy/aces.clf.bz2")
    baseline = record(suite, tmp_path / "baseline", repeats=1)
    pinned = baseline.jobs[0]["protocol"]["checksums"]
    assert sorted(pinned) == ["aces.clf.bz2", "aces.relations"]
    assert baseline.jobs[0]["metrics"]["relation_n_used"] == 8

    relations = log.with_name("aces.relations")
    rows = relations.read_text().splitlines()
    relations.write_text("\n".join(rows[:-1]) + "\n")  # one relation fewer (not one the job scores)
    lines = check(baseline.path).lines()
    assert len(lines) == 1 and lines[0].startswith("protocol changed: ") and ": data.aces.relations: " in lines[0], lines

    relations.unlink()
    lines = check(baseline.path).lines()
    assert len(lines) == 1 and lines[0].startswith("protocol changed: ") and ": data.aces.relations: " in lines[0] \
        and lines[0].endswith(" -> <absent>"), lines



def test_a_carmen_baseline_recorded_before_the_relations_were_hashed_is_checked_with_a_note(tmp_path):
    """A baseline pinned before the relations beside a log were hashed read "protocol changed: data.aces.relations:
    <absent> -> ..." and its job was skipped: a note, and the job checked."""
    import json

    _aces_copy(tmp_path / "acescopy")
    baseline = record(_write_suite(tmp_path, "acescopy/aces.clf.bz2"), tmp_path / "baseline", repeats=1)
    manifest_path = baseline.path / "manifest.json"
    manifest = json.loads(manifest_path.read_text())
    del manifest["jobs"][0]["protocol"]["checksums"]["aces.relations"]
    manifest_path.write_text(json.dumps(manifest))
    result = check(baseline.path)
    notes = [f.message for f in result.findings if f.kind == "note" and "aces.relations" in f.message]
    assert notes and "recorded before lidarkit hashed it" in notes[0]
    assert not [f for f in result.findings if f.kind == "protocol changed"] and result.measured, result.lines()


def test_relations_none_or_given_elsewhere_does_not_pin_the_file_beside_the_log(tmp_path):
    """Only the file the reader reads is pinned: ``relations: none`` reads none; a relations file given by path is
    pinned as an option's file."""
    log = _aces_copy(tmp_path / "acescopy")
    assert sorted(dataset_checksums({"kind": "carmen", "path": str(log), "relations": "none"})) == ["aces.clf.bz2"]
    other = tmp_path / "other.relations"
    shutil.copy(log.with_name("aces.relations"), other)
    assert list(dataset_checksums({"kind": "carmen", "path": str(log), "relations": str(other)})) == [
        "aces.clf.bz2", str(other)]


def test_a_log_linked_into_a_folder_with_its_own_relations_is_scored_on_those(tmp_path):
    """The suite's dataset path was resolved through the link: the reader looked for ``aces.relations`` beside the
    link's target (none there), the job recorded ``relations: null`` and scored nothing, where the CLI, given the link,
    scores the relations beside it."""
    from lidarkit.bench.runner import run_suite

    store, linked = tmp_path / "store", tmp_path / "linked"
    store.mkdir()
    linked.mkdir()
    shutil.copy(shared_path("carmen_2d", "aces.clf.bz2"), store / "aces.clf.bz2")
    (linked / "aces.clf.bz2").symlink_to(store / "aces.clf.bz2")
    shutil.copy(shared_path("carmen_2d", "aces.relations"), linked / "aces.relations")
    suite = load_suite(_write_suite(tmp_path, "linked/aces.clf.bz2"))
    assert suite.jobs[0].dataset["path"] == str(linked / "aces.clf.bz2")
    records = []
    run_suite(suite, tmp_path / "out", executor="serial", on_result=lambda job, record: records.append(record))
    (record,) = records
    assert record["metrics"]["relation_n_used"] == 8
    assert record["info"]["config"]["run"]["effective"]["reader"]["relations"] == str(linked / "aces.relations")
