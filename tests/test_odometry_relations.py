"""An odometry run over a CARMEN log with relations scores them itself, as the bench and `eval --relations` do."""

from __future__ import annotations

import json

import pytest

from conftest import cli_exit_code, shared_path
from lidarkit.eval.relations import relation_error
from lidarkit.io import open_dataset
from lidarkit.odometry import run

PARAMS = {"planar": True, "max_correspondence_distance_m": 0.5}


@pytest.fixture(scope="module")
def aces():
    return open_dataset("carmen", shared_path("carmen_2d", "aces.clf.bz2"))


def test_a_run_over_a_log_with_its_stamps_scores_its_relations(aces, tmp_path):
    """ACES (its stamps kept as logged) gave "none: no scores here" and the `eval --relations` command, while a bench
    job over the same frames scored the relations: run() now records the scores the bench and `eval --relations` give."""
    assert aces.n_restamped == 0
    out = tmp_path / "run"
    result = run(aces, "vanilla", params=PARAMS, init="odometry", frames="600:640", out_dir=out)
    written = json.loads((out / "metrics.json").read_text())
    assert "relations" in written, written["ground_truth_note"]
    recorded = written["relations"]
    bench = relation_error(result.trajectory, aces.relations).to_dict()  # as the bench task scores a job's run
    assert recorded == json.loads(json.dumps(bench))
    assert (recorded["n_used"], recorded["n_relations"]) == (9, 1279)
    # the eval --relations route on the run's poses_tum.txt: the same relations, the same errors (to the file's digits)
    evaluated = tmp_path / "eval.json"
    argv = ["eval", "--relations", str(shared_path("carmen_2d", "aces.relations")), str(out / "poses_tum.txt"),
            "--json", str(evaluated)]
    assert cli_exit_code(argv) == 0
    cli = json.loads(evaluated.read_text())
    assert cli["n_used"] == recorded["n_used"] and cli["n_same_pose"] == recorded["n_same_pose"]
    for key in ("translation_abs_m", "rotation_abs_deg"):
        for stat in ("mean", "std", "max"):
            assert cli[key][stat] == pytest.approx(recorded[key][stat], rel=1e-6, abs=1e-9)
    assert result.metrics["ground_truth_note"] == (
        f"relations only, scored through the reader (metrics \"relations\"): 9 of 1279, mean error "
        f"{recorded['translation_abs_m']['mean']:.4f} m / {recorded['rotation_abs_deg']['mean']:.4f} deg")


def test_a_run_whose_frames_meet_no_relation_says_why(aces):
    """Frames 0:3 lie before ACES's first relation: the note says so (no command that would score nothing either)."""
    result = run(aces, "vanilla", params=PARAMS, frames="0:3")
    assert "relations" not in result.metrics
    note = result.metrics["ground_truth_note"]
    assert note.startswith("none: no scores here; the relation ground truth scores nothing of this run (no relation has "
                           "estimated poses within 0.01 s of both its time stamps"), note
