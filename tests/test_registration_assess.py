"""``assess=False``: the wrapped libraries' pose and verdict without lidarkit's after-the-fact assessment."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import cli_exit_code, shared_path
from registration_helpers import kitti_pair

from lidarkit.errors import ConfigError
from lidarkit.odometry import run
from lidarkit.registration import available_icp, get_icp

SPLIT = ["kiss", "small_gicp", "open3d_point_to_plane", "open3d_gicp"]


@pytest.fixture(scope="module")
def pair():
    src, dst, T_gt = kitti_pair(shared_path, 94, 95)
    return src, dst, T_gt


@pytest.mark.parametrize("name", SPLIT)
def test_the_pose_is_the_assessed_one_and_nothing_is_scored(pair, name):
    src, dst, T_gt = pair
    assessed = get_icp(name).align(src, dst)
    bare = get_icp(name, assess=False).align(src, dst)
    np.testing.assert_allclose(bare.T_target_source, assessed.T_target_source, atol=1e-9)
    assert np.linalg.norm(bare.T_target_source[:3, 3] - T_gt[:3, 3]) < 0.1  # the backend's own alignment, right
    assert bare.converged and assessed.converged
    assert bare.covariance is None and assessed.covariance is not None
    assert bare.n_correspondences == -1 and np.isnan(bare.fitness) and np.isnan(bare.rmse)
    assert bare.degeneracy.kind.startswith("not assessed") and not bare.degeneracy.degenerate
    assert np.isnan(bare.degeneracy.eigenvalues).all() and bare.extra["assessed"] is False
    assert bare.method == name and bare.runtime_s > 0


def test_variants_that_score_within_their_iterations_refuse_it():
    with pytest.raises(ConfigError, match=r"vanilla.*assess=False is for the variants that register apart from their "
                                          r"assessment \(.*kiss.*small_gicp.*\); vanilla scores its result within"):
        get_icp("vanilla", assess=False)


def test_odometry_without_assessment_gives_the_same_trajectory_and_no_covariance():
    spec = f"kitti:{shared_path('kitti_odometry')}?sequence=00"
    assessed = run(spec, "small_gicp", progress=False)
    bare = run(spec, "small_gicp", params={"assess": False}, progress=False)
    np.testing.assert_allclose(bare.trajectory.poses_se3, assessed.trajectory.poses_se3, atol=1e-9)
    assert bare.covariances is None and "pose_covariance" not in bare.metrics
    assert bare.metrics["n_degenerate"] is None and bare.metrics["n_not_converged"] == 0  # not assessed, not 0
    assert (bare.stats.n_correspondences[1:] == -1).all() and np.isnan(bare.stats.min_eigenvalue).all()
    assert np.isfinite(bare.stats.fitness[1:]).all()  # the independent frame check still runs
    assert bare.config["method_config"]["assess"] is False
    with pytest.raises(ConfigError, match="pose_covariance needs each frame's covariance, which assess=False leaves out"):
        run(spec, "small_gicp", params={"assess": False}, pose_covariance=True, progress=False)
    with pytest.raises(ConfigError, match="pose_covariance needs each frame's covariance, which assess=False leaves out"):
        run(spec, "kiss", params={"assess": False}, pose_covariance=True, progress=False)  # stateful too


def test_odometry_with_covariance_none_writes_no_pose_covariance(tmp_path):
    spec = f"kitti:{shared_path('kitti_odometry')}?sequence=00"
    result = run(spec, "small_gicp", params={"covariance": "none"}, frames="0:4", out_dir=tmp_path / "run", progress=False)
    assert result.covariances is None and "pose_covariance" not in result.metrics  # was: all-NaN rows and an empty block
    assert not (tmp_path / "run" / "pose_covariance.txt").exists() and (tmp_path / "run" / "poses_kitti.txt").exists()
    with pytest.raises(ConfigError, match="which covariance='none' leaves out"):
        run(spec, "small_gicp", params={"covariance": "none"}, pose_covariance=True, progress=False)



def test_a_variant_whose_results_carry_no_covariance_writes_no_pose_covariance(tmp_path, caplog):
    """A plugin built on the docs' earlier template (a RegistrationResult without covariance): all-NaN rows were
    written as its pose covariance; now a warning says there is none."""
    import dataclasses
    import logging

    from lidarkit.registration.open3d_icp import Open3DPointToPlane

    class NoCovariance(Open3DPointToPlane):
        def _align(self, source_xyz, target_xyz, init_T):
            return dataclasses.replace(super()._align(source_xyz, target_xyz, init_T), covariance=None, surface_step=None)

    spec = f"kitti:{shared_path('kitti_odometry')}?sequence=00"
    with caplog.at_level(logging.WARNING):
        result = run(spec, NoCovariance(), frames="0:4", out_dir=tmp_path / "run", progress=False)
    assert result.covariances is None and "pose_covariance" not in result.metrics
    assert not (tmp_path / "run" / "pose_covariance.txt").exists() and "no frame's registration gave a covariance" in caplog.text


@pytest.mark.parametrize("value", [float("inf"), float("nan")])
def test_no_variant_takes_a_non_finite_setting(value):
    """``voxel_size_m=inf`` passed ``gt=0``: every variant's config refuses NaN and infinity (no limit is None)."""
    from lidarkit.registration import available_icp

    for method in ("kiss", "vanilla", "open3d_point_to_plane"):
        assert method in available_icp()
        with pytest.raises(ConfigError, match="voxel_size_m: Input should be a finite number"):
            get_icp(method, voxel_size_m=value)


def test_cli_says_the_assessment_is_off(capsys):
    velodyne = shared_path("kitti_odometry", "extra_frames", "00", "velodyne")
    code = cli_exit_code(["icp", str(velodyne / "000095.bin"), str(velodyne / "000094.bin"), "-m", "open3d_gicp", "-p", "assess=false"])
    out = capsys.readouterr().out
    assert code == 0
    assert "off (assess=False)" in out and "correspondences / fitness" not in out and "eigenvalues" not in out
    assert "not reported by the backend" in out and "not recorded" not in out  # (Open3D reports no count, assessed or not)


def test_the_variant_list_offers_assess_only_where_it_is_taken(capsys):
    from lidarkit.registration import available_icp, get_icp_class
    from lidarkit.registration.base import assessed_apart

    assert cli_exit_code(["icp", "--list"]) == 0
    out = capsys.readouterr().out
    apart = [n for n in available_icp() if assessed_apart(get_icp_class(n))]
    assert set(SPLIT) <= set(apart) and "vanilla" not in apart and "genz" not in apart
    assert out.count("assess: bool = True") == len(apart)


def test_an_unassessed_run_keeps_what_the_backend_reports_and_claims_nothing_else(tmp_path, capsys):
    """With assess=False small_gicp's own iteration count was dropped (0, "not recorded") though small_gicp reports it,
    result.json gave degeneracy.ratio 0.0 beside null eigenvalues and degenerate false, and rmse.png was an empty plot
    labelled "final RMSE only". Now: the backend's count, ratio null, and a figure that says there is no RMSE."""
    import json

    from lidarkit.registration.plots import save_rmse_history
    from lidarkit.samples import sample_path

    if "small_gicp" not in available_icp():
        pytest.skip("small_gicp not installed")
    pair = sample_path("kitti_pair")
    source, target = np.load(pair / "000095.npy").astype(np.float64), np.load(pair / "000094.npy").astype(np.float64)
    assessed = get_icp("small_gicp").align(source, target)
    code = cli_exit_code(["icp", str(pair / "000095.npy"), str(pair / "000094.npy"), "-m", "small_gicp", "-p", "assess=false",
                          "--out", str(tmp_path / "run")])
    out = " ".join(capsys.readouterr().out.replace("│", " ").split())
    assert code == 0 and f"iterations {assessed.iterations} " in out and "not recorded" not in out
    result = json.loads((tmp_path / "run" / "result.json").read_text())
    assert result["iterations"] == assessed.iterations >= 1 and result["extra"]["iterations_reported"] is True
    assert result["degeneracy"]["ratio"] is None and result["degeneracy"]["eigenvalues"] == [None] * 6
    stopped = get_icp("small_gicp", assess=False, max_iterations=1).align(source, target)
    assert (stopped.converged, stopped.iterations, stopped.reason) == (False, 1, "small_gicp reports no convergence in 1 iterations")

    def drawn(png):
        import matplotlib.image

        return int((np.abs(matplotlib.image.imread(png)[..., :3] - 1.0).sum(axis=2) > 0.3).sum())

    title = "small_gicp: 000095.npy -> 000094.npy"  # the CLI's
    save_rmse_history(tmp_path / "axes.png", {}, title=title, empty_note="")
    save_rmse_history(tmp_path / "unassessed.png", {"small_gicp": ()}, title=title, empty_note="")
    assert drawn(tmp_path / "unassessed.png") == drawn(tmp_path / "axes.png")  # no marker, no "final RMSE only" legend
    assert drawn(tmp_path / "run" / "rmse.png") > drawn(tmp_path / "axes.png") + 500  # the note: no RMSE, assess=False
