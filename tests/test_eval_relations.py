"""The relations metric's warnings: kept in the result and its ``--json``, as the pose-by-pose evaluation's are."""

from __future__ import annotations

import json

import numpy as np
import pytest

from conftest import cli_exit_code, shared_path
from lidarkit.eval.relations import relation_error
from lidarkit.io import open_dataset
from lidarkit.io.carmen import Relations

SHIFTED_WARNING = ("only 11 of 1279 relations have estimated poses within 0.01 s of both their time stamps (estimate spans "
                   "70.290..1435.810 s, relations 1090.240..2410.780 s): the score covers those only")
# the 11 met scans 1000 s after their own, 8 of their 22 ends exactly (ACES stamps fall on a 0.01 s grid)
OFF_SCAN_WARNING = ("14 of the 22 time stamps of the scored relations met a pose 1e-06..0.01 s off, the other 8 exactly: if "
                    "the relation times are scan stamps, those are other scans' poses (an estimate that skips scans, or one on "
                    "another clock); a tolerance under 1e-06 s leaves them out (a log's own relations, "
                    "open_dataset(...).relations, know its scan spacing)")


@pytest.fixture(scope="module")
def aces_files(tmp_path_factory):
    """ACES odometry as a TUM file, and the real relations moved 1000 s later (11 of them still land on scans)."""
    folder = tmp_path_factory.mktemp("relations")
    aces = open_dataset("carmen", shared_path("carmen_2d", "aces.clf.bz2"))
    aces.odometry.to_tum(folder / "aces_odometry_tum.txt")
    rows = np.loadtxt(shared_path("carmen_2d", "aces.relations"))
    rows[:, :2] += 1000.0
    np.savetxt(folder / "shifted.relations", rows, fmt="%.6f")
    return aces, folder / "aces_odometry_tum.txt", folder / "shifted.relations"


def test_relations_warnings_are_kept_in_the_result_and_the_json(aces_files, tmp_path, caplog):
    """The warning that most relations were left out went to stderr only: ``eval --relations --json`` had no
    ``warnings`` field (the pose-by-pose --json has one), so a saved score of 11 of 1279 relations read as clean."""
    aces, est, shifted = aces_files
    err = relation_error(aces.odometry, Relations.read(shifted))
    assert (err.n_used, err.warnings) == (11, (OFF_SCAN_WARNING, SHIFTED_WARNING))
    assert caplog.text.count(f"{aces.odometry.name}: {SHIFTED_WARNING}") == 1  # logged as before, once
    assert err.to_dict()["warnings"] == [OFF_SCAN_WARNING, SHIFTED_WARNING]
    assert relation_error(aces.odometry, aces.relations).warnings == ()  # all 1279 matched: nothing to warn of
    out = tmp_path / "shifted.json"
    assert cli_exit_code(["eval", "--relations", str(shifted), str(est), "--json", str(out)]) == 0
    data = json.loads(out.read_text())
    assert (data["n_used"], data["warnings"]) == (11, [OFF_SCAN_WARNING, SHIFTED_WARNING])


@pytest.fixture(scope="module")
def intel_excerpt(tmp_path_factory):
    """Intel's scans 4050-4249 (66 of their gaps under 0.01 s, none going back) with relations from their own odometry,
    stamped with the scans' logged stamps as the Freiburg files are: (i, i+2), (i, i+3) and every two scans under 0.01 s
    apart."""
    import bz2

    folder = tmp_path_factory.mktemp("intel_relations")
    lines = bz2.decompress(shared_path("carmen_2d", "intel.clf.bz2").read_bytes()).decode().splitlines(keepends=True)
    scans = [k for k, line in enumerate(lines) if line.startswith("FLASER")]
    log = folder / "intel.clf"
    log.write_text("".join(lines[scans[4050]:scans[4249] + 1]))
    excerpt = open_dataset("carmen", log, relations=None)
    assert excerpt.n_restamped == 0  # the stamps as logged: the relations' times are the scans' own
    stamps, poses = excerpt.timestamps_s, excerpt.odometry.poses_se3
    close = np.flatnonzero(np.diff(stamps) < 0.01)
    pairs = [(i, i + 2) for i in range(0, 196, 3)] + [(i, i + 3) for i in range(1, 196, 5)] + [(k, k + 1) for k in close]
    rows = []
    for i, j in pairs:
        T = np.linalg.solve(poses[i], poses[j])
        rows.append(f"{stamps[i]:.6f} {stamps[j]:.6f} {T[0, 3]:.6f} {T[1, 3]:.6f} 0 0 0 {np.arctan2(T[1, 0], T[0, 0]):.6f}")
    (folder / "intel.relations").write_text("\n".join(rows) + "\n")
    return open_dataset("carmen", log), np.array(pairs)


def test_a_log_s_relations_score_an_estimate_that_skips_scans_on_its_own_scans_only(intel_excerpt):
    """Every 2nd Intel scan (--frames 0::2) scored relations of the skipped scans on a neighbour within the default
    0.01 s (Intel's stamps lie down to 0.1 ms apart): 0.038 m error for a perfect trajectory. The log's relations carry
    its smallest scan gap and the tolerance stays under half of it."""
    log, pairs = intel_excerpt
    gap = float(np.diff(log.timestamps_s).min())
    assert log.relations.scan_gap_s == gap and gap < 0.001
    full = relation_error(log.odometry, log.relations)
    assert full.n_used == len(pairs) and full.translation_abs["max"] < 1e-5
    every_second = relation_error(log.odometry[np.arange(0, len(log), 2)], log.relations)
    both_kept = (pairs % 2 == 0).all(axis=1)
    assert every_second.translation_abs["max"] < 1e-5 and every_second.rotation_abs["max"] < 1e-4  # only own scans
    assert every_second.n_used == int(both_kept.sum())
    assert (every_second.max_time_diff_s, every_second.scan_gap_s) == (0.5 * gap, gap)
    assert every_second.to_dict()["scan_gap_s"] == gap
    # an explicit looser tolerance is kept under the gap too
    assert relation_error(log.odometry[np.arange(0, len(log), 2)], log.relations, max_time_diff_s=0.05).n_used == both_kept.sum()


def test_a_relations_file_read_alone_warns_of_poses_met_off_its_times(intel_excerpt, tmp_path):
    """Read on its own (eval --relations), a file does not say how close the scans lie: the tolerance stays as given, and
    poses met off the relation times while others meet theirs exactly are warned of (they are neighbouring scans')."""
    log, pairs = intel_excerpt
    relations = Relations.read(log.path.with_name("intel.relations"))
    assert relations.scan_gap_s is None
    every_second = log.odometry[np.arange(0, len(log), 2)]
    err = relation_error(every_second, relations)
    assert err.max_time_diff_s == 0.01 and err.scan_gap_s is None
    assert err.translation_abs["max"] > 0.01  # relations of skipped scans scored on their neighbours: still so
    off = [w for w in err.warnings if "time stamps of the scored relations met a pose" in w]
    assert len(off) == 1 and "those are other scans' poses" in off[0]
    assert not any("met a pose" in w for w in relation_error(log.odometry, log.relations).warnings)
    est = tmp_path / "every_second_tum.txt"
    every_second.to_tum(est)
    out = tmp_path / "scores.json"
    assert cli_exit_code(["eval", "--relations", str(log.path.with_name("intel.relations")), str(est), "--json", str(out)]) == 0
    assert off[0] in json.loads(out.read_text())["warnings"]


def test_relations_refuse_a_scan_gap_that_is_not_a_positive_number():
    from lidarkit.errors import DataError

    fields = {"t1_s": [1.0], "t2_s": [2.0], "dx_m": [0.1], "dy_m": [0.0], "dyaw_rad": [0.0]}
    assert Relations(**fields, scan_gap_s=np.float32(0.07)).scan_gap_s == pytest.approx(0.07)
    for bad in (0.0, -0.1, float("nan"), "0.1", True):
        with pytest.raises(DataError, match=f"scan_gap_s must be a finite number of seconds > 0 or None, got {bad!r}"):
            Relations(**fields, scan_gap_s=bad)


def test_the_relations_span_is_over_both_stamps_when_relations_run_back_in_time():
    """A relation with t1 > t2 made the "no relation ..." error read "relations 80.000..70.000 s" (t1's least to t2's
    most)."""
    from lidarkit.errors import EvaluationError
    from lidarkit.trajectory import Trajectory

    relations = Relations(t1_s=np.array([80.0]), t2_s=np.array([70.0]), dx_m=np.array([1.0]), dy_m=np.array([0.0]),
                          dyaw_rad=np.array([0.0]))
    estimate = Trajectory(np.repeat(np.eye(4)[None], 3, axis=0), np.array([0.0, 1.0, 2.0]))
    with pytest.raises(EvaluationError, match=r"relations 70\.000\.\.80\.000 s\)"):
        relation_error(estimate, relations)
