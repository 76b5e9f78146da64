"""``lidarkit.vo.output``: what trajectory.png draws."""

from __future__ import annotations

import numpy as np
from conftest import shared_path
from matplotlib.figure import Figure

from lidarkit.geometry import make_se3, so3_exp
from lidarkit.trajectory import Trajectory
from lidarkit.vo.output import draw_top_view


def _plotted_xz(trajectories: dict[str, Trajectory]) -> list[np.ndarray]:
    """``(N, 2)`` plotted data of each curve (its end dot left out)."""
    ax = Figure().add_subplot(1, 1, 1)
    draw_top_view(ax, trajectories)
    return [np.column_stack([line.get_xdata(), line.get_ydata()]) for line in ax.lines[0::2]]


def test_a_tum_ground_truth_is_drawn_from_above_in_its_first_camera_frame():
    """fr2_desk's mocap world has z up: world x against z drew its loop around the desk from the side, a 0.57 m band
    under "z (forward)". In the first camera's frame the loop spans 4.1 m across and 3.5 m forward."""
    gt = Trajectory.from_tum(shared_path("evo_testdata", "fr2_desk_groundtruth.txt"))
    shifted = gt.transformed(T_left=make_se3(so3_exp(np.array([0.0, 0.3, 0.0])), np.array([1.0, 0.0, 2.0])))
    curve, vo = _plotted_xz({"ground truth": gt, "VO raw": shifted})
    span = np.ptp(curve, axis=0)
    assert span[0] > 1.0 and span[1] > 1.0, span
    assert np.ptp(gt.positions_xyz[:, 2]) < 0.6  # (the world's z alone: the side view)
    np.testing.assert_allclose(curve[0], [0.0, 0.0], atol=1e-9)  # the first camera at the origin
    # another curve in the same world is moved by the same transform: where it lies relative to the ground truth stays
    world_to_first = np.linalg.inv(gt.poses_se3[0])
    expected = (world_to_first @ shifted.poses_se3)[:, :3, 3][:, [0, 2]]
    np.testing.assert_allclose(vo, expected, atol=1e-9)


def test_a_kitti_style_run_is_drawn_as_before_and_without_ground_truth_in_the_first_vo_frame():
    """A KITTI ground truth starts at the identity: its curves are the world's x and z, as they were. Without ground
    truth the first VO pose gives the frame."""
    steps = np.arange(10, dtype=float)
    poses = np.array([make_se3(so3_exp(np.array([0.0, 0.02 * k, 0.0])), np.array([0.3 * k, 0.05 * k, 1.2 * k]))
                      for k in steps])
    gt = Trajectory(poses)
    scaled = poses.copy()
    scaled[:, :3, 3] *= 1.1
    est = Trajectory(scaled)
    curve_gt, curve_est = _plotted_xz({"ground truth": gt, "VO raw": est})
    np.testing.assert_allclose(curve_gt, gt.positions_xyz[:, [0, 2]], atol=1e-12)
    np.testing.assert_allclose(curve_est, est.positions_xyz[:, [0, 2]], atol=1e-12)
    start = make_se3(so3_exp(np.array([1.2, 0.0, 0.4])), np.array([5.0, -3.0, 2.0]))
    (alone,) = _plotted_xz({"VO raw": gt.transformed(T_left=start)})
    np.testing.assert_allclose(alone, gt.positions_xyz[:, [0, 2]], atol=1e-9)
