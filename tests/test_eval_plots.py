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


def test_names_with_dollar_signs_are_drawn_as_written(tmp_path):
    """A method label with two "$" (a text parameter, drive_$1_$2) was read as math: matplotlib's parse error ended the
    box plot, and a file named so ended the evaluation plot."""
    from conftest import shared_path

    from lidarkit.eval import evaluate
    from lidarkit.eval.plots import plot_evaluation, plot_segment_boxplots
    from lidarkit.eval.tables import SegmentErrors

    rng = np.random.default_rng(3)
    segments = SegmentErrors(np.full(20, 100.0), rng.gamma(2.0, 0.4, 20), rng.gamma(2.0, 0.1, 20), np.full(20, 8.0))
    assert plot_segment_boxplots({("00", "vanilla(tag=drive_$1_$2)"): segments, ("00", "kiss"): segments},
                                 tmp_path / "box.png").exists()
    ref = Trajectory.from_kitti(shared_path("evo_testdata", "KITTI_00_gt.txt"))[:200].with_name("gt_$1_$2")
    est = ref.with_name("run_$^$")
    assert plot_evaluation(evaluate(ref, est), tmp_path / "eval.png").exists()


def test_the_drift_panel_legend_is_drawn_over_the_rotation_bars(tmp_path):
    """The rotation bars live on a twin axes drawn after the translation axes: the tallest bar (the longest length's,
    under the upper-right legend) was drawn over the legend. The legend's axes is now drawn last."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.colors import to_rgba
    from matplotlib.figure import Figure

    from lidarkit.eval import evaluate
    from lidarkit.eval.plots import _draw_drift

    n = 301  # 300 m along x; the estimate turns 2 deg per 100 m: the same rotational drift at every length
    ref_poses, est_poses = np.tile(np.eye(4), (n, 1, 1)), np.tile(np.eye(4), (n, 1, 1))
    ref_poses[:, 0, 3] = np.arange(n, dtype=float)
    heading = np.radians(0.02) * np.arange(n)
    est_poses[:, :2, :2] = np.stack([np.stack([np.cos(heading), -np.sin(heading)], -1),
                                     np.stack([np.sin(heading), np.cos(heading)], -1)], -2)
    est_poses[:, 0, 3], est_poses[:, 1, 3] = np.cumsum(np.cos(heading)) - 1, np.cumsum(np.sin(heading))
    ref = Trajectory.from_kitti(Trajectory(ref_poses).to_kitti(tmp_path / "ref.txt"))
    est = Trajectory.from_kitti(Trajectory(est_poses).to_kitti(tmp_path / "est.txt"))
    ev = evaluate(ref, est, align="none", drift_lengths_m=(50, 100, 200))
    fig = Figure(figsize=(6, 4), dpi=100)
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    _draw_drift(ax, ev, scaled=False)
    twin = next(other for other in fig.axes if other is not ax)
    legend = ax.get_legend()
    assert legend is not None and ax.get_zorder() > twin.get_zorder()
    assert not ax.patch.get_visible()  # (the twin's bars show through the translation axes)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    box, tallest = legend.get_window_extent(renderer), twin.patches[-1].get_window_extent(renderer)
    assert box.overlaps(tallest)
    # the legend's frame where it covers the bar: no pixel of the bar's own colour outside the legend's swatches and texts
    rgba = np.asarray(fig.canvas.buffer_rgba())
    height = rgba.shape[0]
    covered = np.zeros(rgba.shape[:2], dtype=bool)
    x0, x1 = int(max(box.x0, tallest.x0)) + 2, int(min(box.x1, tallest.x1)) - 2
    y0, y1 = int(max(box.y0, tallest.y0)) + 2, int(min(box.y1, tallest.y1)) - 2
    covered[height - y1:height - y0, x0:x1] = True
    for artist in [*legend.legend_handles, *legend.get_texts()]:
        e = artist.get_window_extent(renderer)
        covered[max(height - int(e.y1) - 3, 0):height - int(e.y0) + 3, max(int(e.x0) - 3, 0):int(e.x1) + 3] = False
    orange = np.round(np.array(to_rgba("tab:orange")) * 255).astype(np.uint8)
    assert covered.sum() > 50
    assert int((rgba[covered] == orange).all(axis=1).sum()) == 0
