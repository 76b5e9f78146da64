"""PNG plots: written atomically, readable, right projection plane; bad plane name is a ConfigError."""

from __future__ import annotations

import numpy as np
import pytest

from lidarkit.errors import ConfigError
from lidarkit.eval import ape, rpe
from lidarkit.eval.plots import choose_plane, plot_errors, plot_trajectories
from lidarkit.geometry import make_se3
from lidarkit.trajectory import Trajectory


def circle(n: int = 60, axes: tuple[int, int] = (0, 1), name: str = "") -> Trajectory:
    poses = np.tile(np.eye(4), (n, 1, 1))
    angle = np.linspace(0, 1.5 * np.pi, n)
    poses[:, axes[0], 3] = 20 * np.cos(angle)
    poses[:, axes[1], 3] = 10 * np.sin(angle)
    return Trajectory(poses, np.arange(n) * 0.1, name)


def test_choose_plane_follows_the_spread():
    assert choose_plane(circle(axes=(0, 1))) == "xy"
    assert choose_plane(circle(axes=(0, 2))) == "xz"  # KITTI camera frame: x right, z forward
    assert choose_plane(circle(axes=(0, 2)), "yz") == "yz"
    with pytest.raises(ConfigError, match="unknown plot plane 'top'"):
        choose_plane(circle(), "top")


def test_plots_are_png_files_without_leftovers(tmp_path):
    import matplotlib.image

    ref = circle(name="ref")
    est = ref.transformed(T_left=make_se3(translation=[0.5, 0.0, 0.0])).with_name("est")
    result = ape(ref, est, align="none")
    traj_png = plot_trajectories(ref, result.est_aligned, tmp_path / "traj.png", title="demo")
    err_png = plot_errors(result, tmp_path / "sub" / "ape.png")
    rpe_png = plot_errors(rpe(ref, est, delta=5), tmp_path / "rpe.png")
    for png in (traj_png, err_png, rpe_png):
        image = matplotlib.image.imread(png)
        assert image.ndim == 3 and image.shape[0] > 200 and image.shape[1] > 400
    assert sorted(p.name for p in tmp_path.rglob("*") if p.is_file()) == ["ape.png", "rpe.png", "traj.png"]


def test_a_long_evo_title_is_wrapped_to_its_panel():
    """evo's RPE title (~100 characters with the alignment) ran past its panel of the evaluation figure into the
    next one; it is wrapped to the panel's width."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from lidarkit.eval.plots import _draw_errors

    ref = circle(name="ref")
    result = rpe(ref, ref.transformed(T_left=make_se3(translation=[0.5, 0.0, 0.0])), delta=1, align="sim3")
    assert len(result.title) > 90  # the title evo gives, on one line
    fig = Figure(figsize=(12.0, 9.0))  # the evaluation figure's size and grid (plot_evaluation)
    FigureCanvasAgg(fig)
    ax = fig.subplots(2, 2)[1, 0]
    _draw_errors(ax, result)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    title, panel = ax.title.get_window_extent(renderer), ax.get_window_extent(renderer)
    assert title.width <= panel.width and "\n" in ax.get_title()


def test_the_drift_panel_draws_each_length_in_its_own_slot_in_ascending_order():
    """Bars were placed at the lengths themselves, 0.4x the first gap wide: lengths given as (800, 100) gave -280 m
    bars (the 100 m one drawn over 100-380 m, the axis from -200 m), and (100, 110, 800) 4 m bars. One slot a length
    now, labelled, ascending whatever the order given."""
    from conftest import shared_path
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from lidarkit.eval import evaluate
    from lidarkit.eval.plots import _draw_drift

    gt = Trajectory.from_kitti(shared_path("evo_testdata", "KITTI_00_gt.txt"))
    orb = Trajectory.from_kitti(shared_path("evo_testdata", "KITTI_00_ORB.txt"))
    ev = evaluate(gt, orb, drift_lengths_m=(800, 100))
    fig = Figure()
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    _draw_drift(ax, ev, scaled=False)
    bars = ax.patches
    assert [round(b.get_x() + b.get_width() / 2, 6) for b in bars] == [-0.2, 0.8]
    assert min(b.get_width() for b in bars) == pytest.approx(0.4)
    assert [t.get_text() for t in ax.get_xticklabels()] == ["100", "800"]
    by_length = {r.length_m: r.translation_pct for r in ev.drift.per_length}
    assert [b.get_height() for b in bars] == pytest.approx([by_length[100.0], by_length[800.0]])


def test_the_segment_box_plot_title_of_one_method_is_wrapped_inside_the_figure(tmp_path):
    """``--tables``' box plot of one method is 4 in wide: its title "per-segment KITTI translational drift (%) (3283
    segments)" was cut at the image's edge ("... (3283 segment"); it is wrapped like the RPE panel titles."""
    import matplotlib.image

    from lidarkit.eval.plots import plot_segment_boxplots
    from lidarkit.eval.tables import SegmentErrors

    rng = np.random.default_rng(3)
    n = 3283
    segments = SegmentErrors(np.full(n, 100.0), rng.gamma(2.0, 0.4, n), rng.gamma(2.0, 0.1, n), np.full(n, 8.0))
    png = plot_segment_boxplots({("00", "KITTI_00_ORB"): segments}, tmp_path / "box.png")
    image = matplotlib.image.imread(png)[..., :3]
    assert image.shape[:2] == (360, 400)
    band = image[:40]  # the title's rows: ink (dark pixels) in the middle, none at either edge of the image
    assert band[:, 150:250].min() < 0.5
    assert band[:, :4].min() == 1.0 and band[:, -4:].min() == 1.0
