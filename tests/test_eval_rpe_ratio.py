"""RPE of the point distance relations: each error at its own pair, and evo's progress kept off stdout."""

from __future__ import annotations

import json

import numpy as np
import pytest

from lidarkit.eval import rpe
from lidarkit.eval.plots import plot_errors
from lidarkit.trajectory import Trajectory


def reference_that_stands_still_and_moving_estimate() -> tuple[Trajectory, Trajectory]:
    """60 poses 0.1 s apart: the reference walks 0.1 m a step along x, stands still over frames 20..39 and walks on; the
    estimate keeps moving through the stop. Pairs over the stop have no distance-error ratio (evo drops them)."""
    n = 60
    x = np.r_[np.arange(20) * 0.1, np.full(20, 1.9), 1.9 + np.arange(1, 21) * 0.1]
    ref_poses = np.tile(np.eye(4), (n, 1, 1))
    ref_poses[:, 0, 3] = x
    ref_poses[:, 1, 3] = 0.01 * np.sin(np.arange(n))
    ref_poses[20:40, 1, 3] = ref_poses[19, 1, 3]
    est_poses = ref_poses.copy()
    est_poses[:, 0, 3] = x + np.r_[np.zeros(20), np.arange(20) * 0.03, np.full(20, 0.6)] + 0.001 * np.cos(np.arange(n))
    stamps = np.arange(n) * 0.1
    return Trajectory(ref_poses, stamps, "ref"), Trajectory(est_poses, stamps, "est")


def distance_error_ratio_percent(ref: Trajectory, est: Trajectory, pairs: np.ndarray) -> np.ndarray:
    """|ref distance - est distance| / ref distance in percent over ``pairs`` ``(M, 2)``, computed here from positions."""
    def distances(traj: Trajectory) -> np.ndarray:
        return np.linalg.norm(traj.positions_xyz[pairs[:, 1]] - traj.positions_xyz[pairs[:, 0]], axis=1)

    ref_m, est_m = distances(ref), distances(est)
    return np.abs(ref_m - est_m) / ref_m * 100.0


@pytest.mark.parametrize("mode,n_pairs", [({}, 18), ({"legacy_pairs": True}, 17), ({"all_pairs": True}, 40)],
                         ids=["consecutive", "legacy", "all"])
def test_distance_error_ratio_keeps_each_error_at_its_own_pair(mode, n_pairs, tmp_path):
    """Pairs over which the reference stood still stayed in ``pairs`` after evo dropped their errors (legacy pairs kept
    all, all-pairs kept (20, 27) as its end frame ended another pair too): 18 pairs for 17 errors, the JSON's pairs
    named the wrong pair from there on, and plot_errors raised matplotlib's ValueError."""
    from evo.core import metrics as evo_metrics
    from evo.core.units import Unit

    ref, est = reference_that_stands_still_and_moving_estimate()
    result = rpe(ref, est, delta=0.2, delta_unit="meters", relation="point_distance_error_ratio", **mode)
    pairs = np.asarray(result.pairs)
    assert result.n_errors == len(result.errors) == len(pairs) == n_pairs
    ref_m = np.linalg.norm(ref.positions_xyz[pairs[:, 1]] - ref.positions_xyz[pairs[:, 0]], axis=1)
    assert (ref_m > 0).all()
    np.testing.assert_allclose(result.errors, distance_error_ratio_percent(ref, est, pairs), rtol=1e-12, atol=0)
    assert json.loads(json.dumps(result.to_dict()))["pairs"] == pairs.tolist()
    if not mode.get("legacy_pairs"):  # (evo's own selection: legacy pairs are a lidarkit reduction of it)
        theirs = evo_metrics.RPE(evo_metrics.PoseRelation.point_distance_error_ratio, 0.2, Unit.meters, 0.1,
                                 bool(mode.get("all_pairs")))
        theirs.process_data((ref.to_evo(), est.to_evo()))
        np.testing.assert_array_equal(result.errors, np.asarray(theirs.error))
    written = plot_errors(result, tmp_path / "ratio.png")
    assert written.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def turning_pair(n: int = 80) -> tuple[Trajectory, Trajectory]:
    """A reference turning 3 degrees a step on a 1 m-step arc, and an estimate that turns 3.3 degrees a step."""
    def arc(step_deg: float) -> np.ndarray:
        yaw = np.radians(step_deg) * np.arange(n)
        poses = np.tile(np.eye(4), (n, 1, 1))
        poses[:, 0, 0], poses[:, 0, 1], poses[:, 1, 0], poses[:, 1, 1] = np.cos(yaw), -np.sin(yaw), np.sin(yaw), np.cos(yaw)
        poses[:, 0, 3], poses[:, 1, 3] = np.cumsum(np.cos(yaw)), np.cumsum(np.sin(yaw))  # (1 m forward each step)
        return poses

    stamps = np.arange(n) * 0.1
    return Trajectory(arc(3.0), stamps, "ref"), Trajectory(arc(3.3), stamps, "est")


@pytest.mark.parametrize("relation", ["point_distance", "point_distance_error_ratio"])
def test_point_distance_all_pairs_over_an_angle_keep_evo_s_progress_off_stdout(relation, capsys):
    """evo searches the pairs of the point distance relations again inside its process_data and printed "0 %" there:
    library rpe() wrote to stdout (into the tables a CLI prints there)."""
    ref, est = turning_pair()
    capsys.readouterr()
    result = rpe(ref, est, delta=10.0, delta_unit="degrees", all_pairs=True, relation=relation)
    said = capsys.readouterr()
    assert result.n_errors == len(result.pairs) > 0
    assert said.out == ""
