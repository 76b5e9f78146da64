"""Runs whose frames mix scans with and without per-point times: the instant of the sweep the poses are scored and
stamped at is the one most frames' poses refer to, not the first scan's.

One simulated KITTI-layout export (10 sweeps of 16 x 360 rays, stamped and posed mid-sweep, 10 m/s) is copied with
point_times/ cut down; kiss (deskewing to the sweep end) over each copy is compared with the consistent run.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from lidarkit.errors import EvaluationError
from lidarkit.io.kitti import KittiOdometry
from lidarkit.odometry import run
from lidarkit.sim.lidar import SimulatedLidarSequence, export_kitti

EXPORT = {"scene": "street", "n_frames": 10, "n_beams": 16, "n_azimuths": 360, "seed": 1, "pose_instant": "mid"}
#: kiss-icp deskews with the previous motion, which is none for frames 0 and 1: frame 0's times change no pose, so a
#: run without them gives the consistent run's poses to rounding
SAME_POSES = 1e-6


@pytest.fixture(scope="module")
def export(tmp_path_factory) -> Path:
    return export_kitti(SimulatedLidarSequence(**EXPORT), tmp_path_factory.mktemp("mixed") / "seq")


def _copy(export: Path, to: Path, keep_times: set[int] | None) -> Path:
    """The export with the per-point times of the frames ``keep_times`` only (None: all of them)."""
    folder = Path(shutil.copytree(export, to))
    if keep_times is not None:
        for path in sorted((folder / "point_times").glob("*.npy")):
            if int(path.stem) not in keep_times:
                path.unlink()
    return folder


def _scores(result) -> tuple[float, float]:
    return result.metrics["final_error"]["translation_m"], result.metrics["ape_translation_m"]["stats"]["rmse"]


def _tum_stamps(folder: Path) -> np.ndarray:
    return np.loadtxt(folder / "poses_tum.txt", comments="#")[:, 0]


def test_frame_0_without_point_times_leaves_the_run_deskewed_to_the_sweep_end(export, tmp_path):
    """9 of 10 frames deskewed to the sweep end: the first scan, without times, put the estimate at its stamp's
    instant (mid): ground truth not re-timed, final error 0.260 m where the consistent run's is 0.498 m, and
    poses_tum.txt stamped half a sweep early."""
    whole = run(_copy(export, tmp_path / "whole", None), "kiss", out_dir=tmp_path / "r_whole")
    mixed = run(_copy(export, tmp_path / "mixed", set(range(1, 10))), "kiss", out_dir=tmp_path / "r_mixed")
    np.testing.assert_allclose(_scores(mixed), _scores(whole), atol=SAME_POSES)
    scan_stamps = KittiOdometry(export).timestamps_s
    np.testing.assert_allclose(_tum_stamps(tmp_path / "r_mixed"), scan_stamps + 0.05, atol=1e-6)  # the sweep end
    np.testing.assert_allclose(_tum_stamps(tmp_path / "r_mixed"), _tum_stamps(tmp_path / "r_whole"), atol=1e-9)
    assert mixed.metrics["effective"]["estimate_instant"] == "end"
    assert mixed.metrics["effective"]["deskew"]["applied"] is True
    assert "to the sweep end" in mixed.metrics["ground_truth_instant_note"]
    mix = [w for w in mixed.metrics["warnings"] if "refer to different instants of the sweep" in w]
    assert len(mix) == 1 and "all are scored at the sweep end" in mix[0] and "for frame 0 " in mix[0]


def test_frame_0_alone_with_point_times_leaves_the_run_not_deskewed(export, tmp_path):
    """1 of 10 frames with times: the run is not deskewed, its poses are the stamps' instant (mid), as over a folder
    without any times (it read "deskew on", re-timed the ground truth to the sweep end and moved the stamps there:
    final error 0.776 m where 0.538 m is right)."""
    none = run(_copy(export, tmp_path / "none", set()), "kiss", out_dir=tmp_path / "r_none")
    mixed = run(_copy(export, tmp_path / "only0", {0}), "kiss", out_dir=tmp_path / "r_only0")
    np.testing.assert_allclose(_scores(mixed), _scores(none), atol=SAME_POSES)
    np.testing.assert_allclose(_tum_stamps(tmp_path / "r_only0"), KittiOdometry(export).timestamps_s, atol=1e-6)
    assert mixed.metrics.get("ground_truth_instant_note") is None  # the truth is at mid already
    deskew = mixed.metrics["effective"]["deskew"]
    assert (deskew["requested"], deskew["applied"], deskew["frames_with_point_times"]) == (True, False, 1)
    assert deskew["reason"].startswith("most frames ran without deskew: frames 1, 2, 3, 4, 5 and 4 more had no per-point")
    assert mixed.metrics["effective"]["estimate_instant"].startswith("mid")
    assert any("all are scored at the sweep mid" in w and "for frame 0 " in w for w in mixed.metrics["warnings"])


def test_a_callers_ground_truth_is_held_against_most_frames_instant(export, tmp_path):
    """A caller's ground truth (not re-timed) at the sweep middle over a run deskewed to the end but for frame 0: the
    first scan passed it and the end poses were scored against mid truth; it is refused, as over the whole folder."""
    folder = _copy(export, tmp_path / "mixed", set(range(1, 10)))
    truth_mid = KittiOdometry(folder, poses_file="poses_mid.txt").ground_truth
    with pytest.raises(EvaluationError, match="kiss's poses refer to the sweep end but the ground truth to the sweep mid"):
        run(folder, "kiss", ground_truth=truth_mid)
    truth_end = KittiOdometry(folder, poses_file="poses_end.txt").ground_truth
    scored = run(folder, "kiss", ground_truth=truth_end)
    whole = run(_copy(export, tmp_path / "whole", None), "kiss")
    np.testing.assert_allclose(_scores(scored), _scores(whole), atol=SAME_POSES)
