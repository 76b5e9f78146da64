"""Pipeline components (lidarkit.registration.components): registries, and each component against kiss-icp's own
primitives where kiss-icp has one (voxel downsampling, voxel-hash map, adaptive threshold, deskew, kernel)."""

from __future__ import annotations

import textwrap

import numpy as np
import pytest
from scipy.spatial import cKDTree

from conftest import cli_exit_code, shared_path

from lidarkit.errors import ConfigError
from lidarkit.geometry import make_se3, se3_exp, so3_exp
from lidarkit.registration import get_icp
from lidarkit.registration.components import (
    ENTRY_POINT_GROUP,
    KINDS,
    available_components,
    make_component,
    registry as component_registry,
    reload_component_plugins,
)
from lidarkit.registration.components.maps import VoxelHashMap, first_per_voxel


@pytest.fixture(scope="module")
def kitti_frame():
    from lidarkit.io.kitti import KittiOdometry

    folder = shared_path("kitti_odometry", "sequences", "00")
    seq = KittiOdometry(folder)
    return [seq.read_scan(i).points_xyz for i in (0, 1)]


def test_every_kind_lists_its_builtins():
    names = available_components()
    assert set(names) == set(KINDS)
    assert names["residual"] == ["plane_to_plane", "point_to_plane", "point_to_point"]
    assert names["kernel"] == ["cauchy", "geman_mcclure", "huber", "none", "tukey"]
    assert names["threshold"] == ["adaptive", "fixed"]
    assert names["motion"] == ["constant_velocity", "none"]
    assert names["map"] == ["scan_to_scan", "voxel_hash"]
    assert {"range_crop", "voxel_downsample", "ground_filter"} <= set(names["preprocess"])


def test_unknown_names_and_params_raise_config_error_listing_valid_ones():
    with pytest.raises(ConfigError, match="available: cauchy, geman_mcclure, huber, none, tukey"):
        make_component("kernel", "welsch")
    with pytest.raises(ConfigError, match="scale_m="):
        make_component("kernel", {"name": "huber", "scale": 0.3})
    with pytest.raises(ConfigError, match="scale_m"):
        make_component("kernel", {"name": "huber", "scale_m": -1.0})
    with pytest.raises(ConfigError, match="kinds: motion"):
        available_components("solver")
    for name in ("voxel_hash", "scan_to_scan"):  # scipy's threads: 0 failed at the first pair, as the pair's failure
        with pytest.raises(ConfigError, match="workers must be -1 \\(all cores\\) or >= 1, got 0"):
            make_component("map", {"name": name, "workers": 0})
    # through the pipeline variant: the component's kind and its valid names / parameters are named
    with pytest.raises(ConfigError, match="unknown residual component 'point_to_line'; available: plane_to_plane"):
        get_icp("pipeline", residual="point_to_line")
    with pytest.raises(ConfigError, match="valid parameters: voxel_size_m="):
        get_icp("pipeline", map={"name": "voxel_hash", "max_points": 3})
    with pytest.raises(ConfigError, match="preset"):
        get_icp("pipeline", preset="kiss")
    with pytest.raises(ConfigError, match="unknown ground segmenter 'plane'; available: .*height"):
        get_icp("pipeline", preprocess=[{"name": "ground_filter", "method": "plane"}])
    icp = get_icp("pipeline", preprocess=["range_crop", {"name": "ground_filter", "method": "ransac"}])
    assert icp.describe()["preprocess"][1] == {"name": "ground_filter", "method": "ransac", "options": {}}


def test_component_numbers_refuse_yes_no_values_and_infinity(tmp_path, capsys):
    """Inside a pipeline's components a yes/no value was read as 1 or 0 (``map={..., max_points_per_voxel: yes}`` ran
    with 1 point per voxel) and ``.inf`` passed ``gt=0``; a variant's own numbers refused both. Now the components
    refuse them the same way, by name, in one line, and no run folder is written."""
    from lidarkit.samples import sample_path

    yes_no = {
        "kernel": ({"name": "huber", "scale_m": True}, "scale_m"),
        "map": ({"name": "voxel_hash", "max_points_per_voxel": True}, "max_points_per_voxel"),
        "threshold": ({"name": "adaptive", "initial_threshold_m": True}, "initial_threshold_m"),
        "preprocess": ([{"name": "voxel_downsample", "voxel_size_m": True}], "voxel_size_m"),
    }
    for kind, (spec, field) in yes_no.items():
        with pytest.raises(ConfigError) as err:
            get_icp("pipeline", **{kind: spec})
        assert f"invalid parameters ({field} (True): takes a number, not a yes/no value)" in str(err.value), kind
    with pytest.raises(ConfigError, match=r"invalid parameters \(max_distance_m \(False\): takes a number"):
        make_component("threshold", {"name": "fixed", "max_distance_m": np.bool_(False)})
    for kind, spec in (("threshold", {"name": "adaptive", "initial_threshold_m": float("inf")}),
                       ("map", {"name": "voxel_hash", "min_point_spacing_m": float("nan")}),
                       ("preprocess", {"name": "range_crop", "max_range_m": float("inf")})):
        with pytest.raises(ConfigError, match="should be a finite number"):
            make_component(kind, spec)
    # through the CLI, as YAML reads `yes`
    folder, out = sample_path("kitti_pair"), tmp_path / "run"
    argv = ["icp", str(folder / "000095.npy"), str(folder / "000094.npy"), "-m", "pipeline", "-o", str(out),
            "-p", "map={name: voxel_hash, max_points_per_voxel: yes}"]
    assert cli_exit_code(argv) == 1
    said = capsys.readouterr().err.strip()
    assert said.startswith("error: map component 'voxel_hash': invalid parameters (max_points_per_voxel (True): takes a number, "
                           "not a yes/no value); valid parameters: ") and "\n" not in said
    assert not out.exists()


def test_a_components_model_level_problem_is_not_named_by_a_question_mark():
    """A problem of the whole config (a validator of the model, not of one field) read "(?: unknown ground segmenter
    'nosuch'; ...)"."""
    with pytest.raises(ConfigError) as err:
        get_icp("pipeline", preprocess=[{"name": "ground_filter", "method": "nosuch"}])
    assert str(err.value).startswith("preprocess component 'ground_filter': invalid parameters (unknown ground segmenter "
                                     "'nosuch'; available: csf, height, local_plane, patchworkpp, ransac); valid parameters: ")
    with pytest.raises(ConfigError) as err:
        make_component("preprocess", {"name": "range_crop", "min_range_m": 5.0, "max_range_m": 2.0})
    assert "invalid parameters (max_range_m (2.0) must exceed min_range_m (5.0));" in str(err.value)


def test_kernel_weights():
    r2 = np.array([0.0, 0.01, 0.25, 1.0, 4.0])
    sigma = 0.4
    gm = make_component("kernel", {"name": "geman_mcclure", "scale_m": "kiss"}).weights(r2, sigma)
    kiss = sigma**2 / (sigma + r2) ** 2  # kiss-icp 1.3's weight, kernel = sigma
    np.testing.assert_allclose(gm, kiss / kiss[0], rtol=1e-12)
    np.testing.assert_allclose(make_component("kernel", {"name": "huber", "scale_m": 0.5}).weights(r2, sigma), [1, 1, 1, 0.5, 0.25])
    np.testing.assert_allclose(make_component("kernel", {"name": "cauchy", "scale_m": 1.0}).weights(r2, sigma), 1 / (1 + r2))
    np.testing.assert_allclose(make_component("kernel", {"name": "tukey", "scale_m": 1.0}).weights(r2, sigma), [1, 0.99**2, 0.75**2, 0, 0])
    np.testing.assert_allclose(make_component("kernel", "cauchy").weights(r2, sigma), 1 / (1 + r2 / sigma**2))  # adaptive: c = sigma
    assert (make_component("kernel", "none").weights(r2, sigma) == 1).all()


def test_adaptive_threshold_equals_kiss_icp():
    from kiss_icp.config import KISSConfig
    from kiss_icp.threshold import AdaptiveThreshold

    reference = AdaptiveThreshold(KISSConfig())
    ours = make_component("threshold", "adaptive")
    rng = np.random.default_rng(3)
    assert ours.sigma_m == reference.get_threshold() == 2.0 and ours.max_distance_m == 6.0
    for k in range(30):
        scale = 0.3 if k % 3 else 0.01  # some deviations below min_motion_th (not counted)
        deviation = se3_exp(np.r_[rng.normal(0, scale, 3), rng.normal(0, scale / 100, 3)])
        reference.update_model_deviation(deviation)
        ours.update(deviation)
        assert ours.sigma_m == pytest.approx(reference.get_threshold(), rel=1e-12)
    fixed = make_component("threshold", {"name": "fixed", "max_distance_m": 1.5})
    assert fixed.max_distance_m == 1.5 and fixed.sigma_m == 0.5
    assert make_component("threshold", {"name": "fixed", "max_distance_m": None}).max_distance_m == np.inf


def test_voxel_downsampling_and_map_equal_kiss_icp(kitti_frame):
    from kiss_icp.mapping import VoxelHashMap as KissMap
    from kiss_icp.voxelization import voxel_down_sample

    frame0, frame1 = kitti_frame
    kiss_down = voxel_down_sample(frame0, 0.5)
    ours = first_per_voxel(frame0, 0.5, order="kiss_hash")
    np.testing.assert_array_equal(ours, kiss_down)  # same points in the same (hash-table) order
    assert set(map(tuple, first_per_voxel(frame0, 0.5))) == set(map(tuple, kiss_down))
    T1 = make_se3(so3_exp([0.0, 0.0, 0.02]), [0.7, 0.01, 0.0])
    reference = KissMap(voxel_size=1.0, max_distance=30.0, max_points_per_voxel=20)
    local_map = VoxelHashMap(voxel_size_m=1.0, max_range_m=30.0, max_points_per_voxel=20)
    for frame, T in ((frame0, np.eye(4)), (frame1, T1)):
        down = voxel_down_sample(frame, 0.5)
        reference.update(down, T)
        local_map.update(down, T)
        expected = reference.point_cloud()
        assert len(local_map.points_xyz) == len(expected)
        # the same points (up to the rounding of kiss-icp's own transform): far voxels removed alike
        gap, _ = cKDTree(expected).query(local_map.points_xyz)
        assert gap.max() < 1e-9
    assert np.linalg.norm(local_map.points_xyz - T1[:3, 3], axis=1).max() < 30.0 + 2 * np.sqrt(3)


def test_constant_velocity_deskew_equals_kiss_icp_and_moves_the_reference_instant(rng):
    from kiss_icp.preprocess import Preprocessor

    points = rng.uniform(-30, 30, (2000, 3))
    times = np.sort(rng.uniform(0.0, 0.1, 2000))
    delta = se3_exp([0.9, 0.05, 0.01, 0.001, 0.002, 0.03])
    kiss = Preprocessor(max_range=1e3, min_range=0.0, deskew=True, max_num_threads=1).preprocess(points, times, delta)
    end = make_component("motion", "constant_velocity").deskew(points, times, delta)
    np.testing.assert_allclose(end, kiss, atol=1e-9)
    middle = make_component("motion", {"name": "constant_velocity", "reference": "middle"}).deskew(points, times, delta)
    half = se3_exp(0.5 * np.asarray([0.9, 0.05, 0.01, 0.001, 0.002, 0.03]))  # exact for a constant twist
    np.testing.assert_allclose(middle, end @ half[:3, :3].T + half[:3, 3], atol=1e-9)
    assert make_component("motion", {"name": "constant_velocity", "deskew": False}).deskew(points, times, delta) is points
    assert make_component("motion", "none").predict(np.eye(4), delta) == pytest.approx(np.eye(4))


@pytest.mark.parametrize(
    "residual, kernel",
    [(r, "geman_mcclure") for r in ("point_to_point", "point_to_plane", "plane_to_plane")]
    + [("point_to_plane", k) for k in ("none", "huber", "cauchy", "tukey")],
)
def test_each_residual_and_kernel_recovers_a_known_motion(residual, kernel):
    """A structured synthetic scene, sampled twice independently: every residual x kernel finds the motion."""
    from registration_helpers import structured_cloud

    from lidarkit.geometry import pose_error, transform_points

    target = structured_cloud(np.random.default_rng(7), n=12000)
    T_gt = make_se3(so3_exp(np.radians([0.3, -0.4, 4.0])), [0.6, -0.25, 0.05])
    source = transform_points(np.linalg.inv(T_gt), structured_cloud(np.random.default_rng(8), n=12000))
    icp = get_icp(
        "pipeline", residual=residual, kernel=kernel, threshold={"name": "fixed", "max_distance_m": 2.0},
        voxel_size_m=0.2, map={"name": "voxel_hash", **({} if residual == "point_to_point" else {"neighbors": 12})},
    )
    result = icp.align(source, target)
    dt, dr = pose_error(result.T_target_source, T_gt)
    assert dt < 0.05 and dr < 0.15, (residual, kernel, dt, dr)
    assert result.converged and result.iterations < 100


PLUGIN_SOURCE = textwrap.dedent(
    '''
    import numpy as np
    from lidarkit.registration.components import Kernel
    from lidarkit.registration.components.kernels import KernelConfig

    class HalfConfig(KernelConfig):
        floor: float = 0.5

    class HalfKernel(Kernel):
        """Weight 1 within the scale, ``floor`` beyond."""
        Config = HalfConfig
        def _weights(self, r2, c):
            return np.where(r2 <= c * c, 1.0, self.config.floor)
    '''
)


def _install_plugin(tmp_path, monkeypatch, package: str, entry_points: str, source: str | None = None) -> None:
    """A package with ``entry_points`` (lines of the lidarkit components group) found on sys.path, as pip installs one."""
    site = tmp_path / "site"
    site.mkdir()
    if source is not None:
        (site / f"{package}.py").write_text(source)
    dist = site / f"{package}-0.1.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {package.replace('_', '-')}\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text(f"[{ENTRY_POINT_GROUP}]\n{entry_points}\n")
    monkeypatch.syspath_prepend(str(site))


def test_component_plugin_from_an_installed_package_is_discovered(tmp_path, monkeypatch, capsys):
    _install_plugin(tmp_path, monkeypatch, "lk_kernel_plugin", "kernel.half = lk_kernel_plugin:HalfKernel", PLUGIN_SOURCE)
    try:
        reload_component_plugins()
        assert "half" in available_components("kernel")
        kernel = make_component("kernel", {"name": "half", "scale_m": 1.0, "floor": 0.25})
        np.testing.assert_allclose(kernel.weights(np.array([0.5, 2.0]), 1.0), [1.0, 0.25])
        icp = get_icp("pipeline", kernel={"name": "half", "floor": 0.1})
        assert icp.describe()["kernel"] == {"name": "half", "scale_m": "adaptive", "floor": 0.1}
        with pytest.raises(ConfigError, match="floor="):
            make_component("kernel", {"name": "half", "flor": 1})
        assert cli_exit_code(["icp", "--list-components"]) == 0
        assert "kernel / half" in capsys.readouterr().out
    finally:
        component_registry._COMPONENTS["kernel"].pop("half", None)


def test_broken_component_plugin_is_left_out_and_names_itself(tmp_path, monkeypatch, caplog, capsys):
    """A broken component plugin made --list-components, available_components and a kernel name's typo fail with its
    error: it is left out with a warning now, and named when asked for."""
    _install_plugin(tmp_path, monkeypatch, "lk_bad_components", "solver.fast = os:getcwd\nkernel.broken = nosuchmodule:K")
    try:
        with caplog.at_level("WARNING", logger="lidarkit.registration.components.registry"):
            reload_component_plugins()
        assert "KIND.NAME" in caplog.text and "nosuchmodule" in caplog.text
        assert "huber" in available_components("kernel") and "broken" not in available_components("kernel")
        with pytest.raises(ConfigError, match=r"component plugin kernel\.broken: this plugin is installed but could not be loaded"):
            make_component("kernel", {"name": "broken"})
        with pytest.raises(ConfigError, match="unknown kernel component 'hubr'"):
            make_component("kernel", {"name": "hubr"})
        assert cli_exit_code(["icp", "--list-components"]) == 0
        assert "kernel.broken" in capsys.readouterr().out
    finally:
        monkeypatch.undo()
        reload_component_plugins()


def test_a_component_plugin_named_like_a_built_in_is_said_to_be_left_out(tmp_path, monkeypatch, caplog, capsys):
    """An entry point named 'kernel.huber' was dropped without a word (nor listed by --list-components among the
    plugins left out), as ICP plugins named like a built-in variant were; the built-in keeps answering to the name."""
    from lidarkit.registration.components.kernels import HuberKernel
    from lidarkit.registration.components.registry import broken_component_plugins, get_component_class

    _install_plugin(tmp_path, monkeypatch, "lk_shadow_kernel", "kernel.huber = lk_shadow_kernel:HalfKernel", PLUGIN_SOURCE)
    try:
        with caplog.at_level("WARNING", logger="lidarkit.registration.components.registry"):
            reload_component_plugins()
        assert "component plugin 'kernel.huber' left out: its name is a built-in kernel's" in caplog.text
        assert broken_component_plugins() == {
            "kernel.huber": "its name is a built-in kernel's: 'lk_shadow_kernel:HalfKernel' left out (rename the entry point)"
        }
        assert get_component_class("kernel", "huber") is HuberKernel
        assert cli_exit_code(["icp", "--list-components"]) == 0
        assert "plugin 'kernel.huber' left out" in capsys.readouterr().out
    finally:
        monkeypatch.undo()
        reload_component_plugins()


def test_voxel_hash_nearest_follows_kiss_icps_27_voxel_rule(rng):
    # kiss-icp answers a query with the closest map point of the 3 x 3 x 3 voxels around the query's voxel, even
    # when a closer point lies outside them; a plain KD-tree answer would differ (the open scene diverged so)
    v = 1.0
    local_map = VoxelHashMap(voxel_size_m=v, max_range_m=1e3, max_points_per_voxel=20, min_point_spacing_m=0.0)
    pts = rng.uniform(-6.0, 6.0, size=(400, 3))
    local_map.update(pts, np.eye(4))
    queries = rng.uniform(-8.0, 8.0, size=(3000, 3))
    qk = np.floor(queries / v).astype(np.int64)
    pk = np.floor(local_map.points_xyz / v).astype(np.int64)
    diff = queries[:, None, :] - local_map.points_xyz[None, :, :]
    d_all = np.sqrt(np.einsum("qpi,qpi->qp", diff, diff))
    in_block = np.abs(qk[:, None, :] - pk[None, :, :]).max(axis=2) <= 1
    expected = np.where(in_block, d_all, np.inf).min(axis=1)
    for max_d in (np.inf, 1.2, 2.5):
        dist, idx, valid = local_map.nearest(queries, max_d)
        np.testing.assert_array_equal(valid, expected < max_d)
        np.testing.assert_allclose(dist[valid], expected[valid], rtol=0, atol=1e-12)
        np.testing.assert_allclose(d_all[valid, idx[valid]], expected[valid], rtol=0, atol=1e-12)
    # the case the rule exists for: the global nearest is outside the block, and the answers differ
    differs = np.isfinite(expected) & (d_all.min(axis=1) < expected - 1e-9)
    assert differs.sum() > 20
    kd = VoxelHashMap(voxel_size_m=v, max_range_m=1e3, max_points_per_voxel=20, min_point_spacing_m=0.0, search="kdtree")
    kd.update(pts, np.eye(4))
    d_kd, _, _ = kd.nearest(queries, np.inf)
    np.testing.assert_allclose(d_kd, d_all.min(axis=1), rtol=0, atol=1e-12)
    assert np.all(d_kd[differs] < dist[differs])


def test_27_voxel_rule_holds_behind_a_crowd_of_closer_points_outside_the_block(rng):
    # 60 points just outside the query's block, closer than the only point inside it: the answer is still the
    # inside point (a search among the k nearest would give up when the crowd is larger than k)
    crowd = np.array([2.05, 0.5, 0.5]) + rng.uniform(-0.04, 0.04, size=(60, 3))
    inside = np.array([[-0.95, 0.5, 0.5]])
    local_map = VoxelHashMap(voxel_size_m=1.0, max_range_m=1e3, max_points_per_voxel=100, min_point_spacing_m=0.0)
    local_map.update(np.vstack([crowd, inside]), np.eye(4))
    dist, idx, valid = local_map.nearest(np.array([[0.9, 0.5, 0.5]]), 5.0)
    assert valid[0] and abs(dist[0] - 1.85) < 1e-12
    np.testing.assert_array_equal(local_map.points_xyz[idx[0]], inside[0])
    dist, _, valid = local_map.nearest(np.array([[0.9, 0.5, 0.5]]), 1.8)  # inside point beyond the threshold
    assert not valid[0]


@pytest.mark.parametrize("kind", ["voxel_hash", "scan_to_scan"])
def test_tracked_nearest_gives_the_fresh_answers_with_fewer_searches(rng, kind):
    # ICP iterations query the same points moved a little; the map keeps a point's nearest while it provably
    # stays the nearest (moved less than half the gap to the second nearest): the answers must equal new searches
    params = {"voxel_size_m": 1.0, "max_range_m": 1e3, "max_points_per_voxel": 20, "min_point_spacing_m": 0.0} if kind == "voxel_hash" else {}
    local_map = make_component("map", {"name": kind, **params})
    local_map.update(rng.uniform(-10.0, 10.0, size=(3000, 3)), np.eye(4))
    source = rng.uniform(-11.0, 11.0, size=(2000, 3))
    for max_d in (np.inf, 2.5):  # a point with nothing within max_d is searched again every time
        state: dict = {}
        T = np.eye(4)
        searched = []
        for step_m, step_rad in [(0.0, 0.0), (0.3, 0.02), (0.05, 0.005), (0.01, 1e-3), (1e-3, 1e-4), (1e-4, 0.0), (0.5, 0.05), (1e-5, 1e-6)]:
            T = make_se3(so3_exp(rng.normal(size=3) * step_rad), rng.normal(size=3) * step_m) @ T
            moved = source @ T[:3, :3].T + T[:3, 3]
            fresh = local_map.nearest(moved, max_d)
            tracked = local_map.nearest(moved, max_d, state=state)
            np.testing.assert_array_equal(tracked[2], fresh[2])
            np.testing.assert_array_equal(tracked[1], fresh[1])
            np.testing.assert_allclose(tracked[0][fresh[2]], fresh[0][fresh[2]], rtol=0, atol=1e-12)
            searched.append(state["searched"])
        assert searched[0] == len(source)
        assert searched[4] < 0.05 * len(source) and searched[5] < 0.05 * len(source)  # tiny steps: almost no search


def test_deskew_with_one_rotation_axis_equals_the_per_point_exponential():
    """``exp_scaled_twist_apply`` (Rodrigues with the one axis, per-point scalars) against ``se3_exp_batch`` (a 3x3
    exponential per point): equal to 1e-10 m for a curve, a pure translation, a rotation of a few nano-radians (its
    series branch) and a fast turn; the sweep-end point stays, the sweep start moves back by the whole motion."""
    from lidarkit.geometry import se3_exp
    from lidarkit.registration.components.motion import deskew_constant_velocity, exp_scaled_twist_apply, se3_exp_batch

    rng = np.random.default_rng(4)
    points = rng.normal(size=(5000, 3)) * 20.0
    s = np.sort(rng.uniform(-1.0, 0.3, len(points)))
    s[:5], s[5:10] = 0.0, 1e-7
    for xi in ([1.0, 0.02, 0.01, 0.001, 0.002, 0.02], [0.5, 0.0, 0.0, 0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 3e-9, 0.0, 0.0],
               [0.3, -0.2, 0.1, 0.3, -0.5, 1.2]):
        xi = np.asarray(xi)
        R, t = se3_exp_batch(s[:, None] * xi[None, :])
        np.testing.assert_allclose(exp_scaled_twist_apply(xi, s, points), np.einsum("nij,nj->ni", R, points) + t, atol=1e-10)
    delta = se3_exp(np.array([1.0, 0.05, 0.0, 0.0, 0.01, 0.03]))
    times = np.linspace(0.0, 0.1, len(points))
    moved = deskew_constant_velocity(points, times, delta, "end")
    np.testing.assert_allclose(moved[-1], points[-1], atol=1e-12)
    np.testing.assert_allclose(moved[0], np.linalg.inv(delta)[:3, :3] @ points[0] + np.linalg.inv(delta)[:3, 3], atol=1e-10)
    assert deskew_constant_velocity(points, None, delta) is points


def test_a_component_failing_inside_register_frame_is_a_registration_error():
    """A kernel plugin returning NaN weights made scipy raise a bare ValueError out of register_frame (the odometry
    runner named the frame, a direct call gave the ValueError)."""
    from lidarkit.errors import RegistrationError
    from lidarkit.registration.components import Kernel, register_component
    from lidarkit.registration.components.kernels import KernelConfig

    class NaNKernel(Kernel):
        """Weights that are not numbers."""
        Config = KernelConfig

        def _weights(self, r2, c):
            return np.full_like(r2, np.nan)

    register_component("kernel", "nan_test")(NaNKernel)
    try:
        icp = get_icp("pipeline", kernel="nan_test")
        rng = np.random.default_rng(0)
        cloud = rng.uniform(-20, 20, size=(3000, 3))
        icp.register_frame(cloud)
        with pytest.raises(RegistrationError) as err:
            icp.register_frame(cloud + [0.3, 0.0, 0.0])
        # (named the kernel: it read "the pipeline backend failed ...: ValueError: 'x' must be finite")
        assert str(err.value).startswith("pipeline: kernel 'nan_test' returned ") and "weights that are not finite numbers >= 0" in str(err.value)
    finally:
        component_registry._COMPONENTS["kernel"].pop("nan_test", None)


def test_a_component_returning_the_wrong_shape_is_named():
    """A kernel plugin returning 3 weights for 2365 residuals was "the pipeline backend failed on this pair:
    ValueError: matmul: ... mismatch ...", naming no component; so was a preprocess step dropping a column."""
    from lidarkit.errors import RegistrationError
    from lidarkit.registration.components import Kernel, Preprocess, register_component
    from lidarkit.registration.components.kernels import KernelConfig

    class ShortKernel(Kernel):
        """Three weights whatever the residuals."""
        Config = KernelConfig

        def _weights(self, r2, c):
            return np.ones(3)

    class FlatStep(Preprocess):
        """Drops z."""

        def apply(self, points_xyz):
            return points_xyz[:, :2]

    register_component("kernel", "short_test")(ShortKernel)
    register_component("preprocess", "flat_test")(FlatStep)
    try:
        cloud = np.random.default_rng(0).uniform(-20, 20, size=(3000, 3))
        with pytest.raises(RegistrationError) as err:
            get_icp("pipeline", kernel="short_test").align(cloud + [0.3, 0.0, 0.0], cloud)
        assert str(err.value) == "pipeline: kernel 'short_test' returned 3 weights for 2779 residuals (one per residual expected)"
        with pytest.raises(RegistrationError) as err:
            get_icp("pipeline", preprocess=["flat_test"]).align(cloud, cloud)
        assert str(err.value) == "pipeline: preprocess 'flat_test' returned ndarray of shape (3000, 2), not (M, 3) points"
    finally:
        component_registry._COMPONENTS["kernel"].pop("short_test", None)
        component_registry._COMPONENTS["preprocess"].pop("flat_test", None)


def test_map_threshold_and_motion_components_returning_the_wrong_shape_are_named():
    """A map plugin's nearest points, a threshold's distances and a motion model's poses and deskewed sweep were not
    checked: a 3x3 prediction or a map returning two arrays failed in numpy further on ("the pipeline backend failed
    ...: ValueError: matmul ...") or, a threshold of sigma 0, ran ICP with NaN weights, naming no component."""
    from lidarkit.errors import RegistrationError
    from lidarkit.registration.components import register_component
    from lidarkit.registration.components.maps import ScanToScanMap
    from lidarkit.registration.components.motion import ConstantVelocity
    from lidarkit.registration.components.thresholds import FixedThreshold

    class PairMap(ScanToScanMap):
        """Returns (index, valid) only."""

        def nearest(self, query_xyz, max_distance_m, state=None):
            return super().nearest(query_xyz, max_distance_m)[1:]

    class FarMap(ScanToScanMap):
        """Indices past its points."""

        def nearest(self, query_xyz, max_distance_m, state=None):
            dist, index, valid = super().nearest(query_xyz, max_distance_m)
            return dist, index + len(self.points_xyz), valid

    class ZeroThreshold(FixedThreshold):
        @property
        def sigma_m(self):
            return 0.0

    class FlatMotion(ConstantVelocity):
        """A 3x3 prediction; a deskew dropping the last point."""

        def predict(self, last_pose, last_delta):
            return np.eye(3)

    class ShortDeskew(ConstantVelocity):
        def deskew(self, points_xyz, point_times_s, delta):
            return points_xyz[:-1]

    added = {"map": ["pair_test", "far_test"], "threshold": ["zero_test"], "motion": ["flat_test", "short_test"]}
    register_component("map", "pair_test")(PairMap)
    register_component("map", "far_test")(FarMap)
    register_component("threshold", "zero_test")(ZeroThreshold)
    register_component("motion", "flat_test")(FlatMotion)
    register_component("motion", "short_test")(ShortDeskew)
    try:
        cloud = np.random.default_rng(0).uniform(-20, 20, size=(3000, 3))
        moved = cloud + [0.3, 0.0, 0.0]

        def error_of(make, run):
            with pytest.raises(RegistrationError) as err:
                run(make())
            return str(err.value)

        def sequence(icp):
            icp.register_frame(cloud)
            icp.register_frame(moved, np.linspace(0.0, 0.1, len(moved)))

        def pairwise(icp):
            icp.align(moved, cloud)

        assert error_of(lambda: get_icp("pipeline", map="pair_test"), pairwise) == (
            "pipeline: map 'pair_test' returned nearest points [(2779,), (2779,)] for 2779 queries, not (dist, index, "
            "valid) of (2779,) each (integer indices)")
        assert error_of(lambda: get_icp("pipeline", map="far_test"), pairwise).startswith(
            "pipeline: map 'far_test' returned indices up to ")
        assert error_of(lambda: get_icp("pipeline", threshold="zero_test"), pairwise) == (
            "pipeline: threshold 'zero_test' returned sigma_m 0 and max_distance_m 1, not both > 0")
        assert error_of(lambda: get_icp("pipeline", deskew="flat_test"), sequence) == (
            "pipeline: motion 'flat_test' returned a predicted pose of shape (3, 3), not a 4x4 pose")
        assert error_of(lambda: get_icp("pipeline", deskew="short_test"), sequence) == (
            "pipeline: motion 'short_test' returned a deskewed sweep of shape (2999, 3) for 3000 points, not (3000, 3)")
    finally:
        for kind, names in added.items():
            for name in names:
                component_registry._COMPONENTS[kind].pop(name, None)


def test_the_voxel_map_keeps_neighbouring_voxels_apart_at_utm_coordinates():
    """The 21-bit voxel-key fields spilled into each other beyond 2^20 voxels: at a UTM northing (4.2e6 m, 1 m voxels)
    voxels x and x + 1 got one code, shared one point budget and one 27-voxel block, and kiss_like left kiss-icp's
    path by 5 mm over 10 KITTI scans. The codes are relative to the map's first voxel now."""
    from lidarkit.registration.components import make_component
    from lidarkit.registration.components.maps import encode_keys

    far = np.array([[0, 1_100_000, 0], [1, 1_100_000, 0]])
    assert len(set(encode_keys(far).tolist())) == 2  # (one code before)
    voxel_map = make_component("map", {"name": "voxel_hash", "max_points_per_voxel": 1, "voxel_size_m": 1.0})
    T = np.eye(4)
    T[:3, 3] = [500000.0, 4200000.0, 0.0]  # the sensor at a UTM position, the points in its frame
    voxel_map.update(np.array([[0.5, 0.5, 0.5], [1.5, 0.5, 0.5], [1.6, 0.6, 0.6]]), T)
    assert len(voxel_map.points_xyz) == 2  # one per voxel (the second voxel's point was dropped as the first's)
    d, i = voxel_map.block_nearest(np.array([[500001.4, 4200000.5, 0.5]]), np.array([[500001, 4200000, 0]]))
    assert i[0] == 1 and d[0] == pytest.approx(0.1)


def test_the_voxel_map_codes_follow_a_long_drive():
    """Codes relative to the map's first voxel stopped a drive 53 km on at 5 cm voxels (2^20 voxel edges): the
    codes move with the drive, the kept voxels encoded again, and the nearest-point search still finds them."""
    from lidarkit.registration.components import make_component

    voxel_map = make_component("map", {"name": "voxel_hash", "voxel_size_m": 0.05, "max_range_m": 100.0})
    scan = np.random.default_rng(0).uniform(-20, 20, size=(2000, 3))
    for x in (0.0, 30_000.0, 52_000.0, 53_000.0, 53_010.0):
        T = np.eye(4)
        T[0, 3] = x
        voxel_map.update(scan, T)
    world = scan + [53_010.0, 0.0, 0.0]
    probe = world[:5] + 0.001
    d, i = voxel_map.block_nearest(probe, np.floor(probe / 0.05).astype(np.int64))
    np.testing.assert_allclose(voxel_map.points_xyz[i], world[:5])  # each probe's own point (1.7 mm away)
    assert d.max() < 0.002


def test_a_component_mapping_without_spaces_after_colons_says_what_yaml_read():
    """-p "kernel={name:huber,scale_m:0.5}": YAML reads each "key:value" as one key with no value, and the message said
    the mapping needs a 'name' key, which the user had written. It says what YAML needs now."""
    from lidarkit.cli.app import parse_params
    from lidarkit.registration import get_icp

    with pytest.raises(ConfigError, match=r"needs a 'name' key \(one of: .*\) \(YAML needs a space after ':': "
                                          r"\{name: huber, scale_m: 0\.5\}\)$"):
        get_icp("pipeline", **parse_params(["kernel={name:huber,scale_m:0.5}"]))
    assert get_icp("pipeline", **parse_params(["kernel={name: huber, scale_m: 0.5}"])).config.kernel == {"name": "huber", "scale_m": 0.5}


def test_a_component_parameter_without_a_space_after_its_colon_says_what_yaml_read():
    """-p "kernel={name: huber, scale_m:0.3}": the name was read, and "scale_m:0.3" became a key with no value, refused
    as an extra input with no word of why (the name key alone had the hint)."""
    import yaml

    from lidarkit.cli.app import parse_params

    with pytest.raises(ConfigError, match=r"^kernel component 'huber': invalid parameters \(scale_m:0\.3: Extra inputs are not "
                                          r"permitted\) \(YAML needs a space after ':': \{scale_m: 0\.3\}\); valid parameters: "):
        get_icp("pipeline", **parse_params(["kernel={name: huber, scale_m:0.3}"]))
    with pytest.raises(ConfigError, match=r"\(YAML needs a space after ':': \{max_iterations: 30\}\); valid parameters: "):
        get_icp("vanilla", **yaml.safe_load("{max_iterations:30}"))  # (a variant's settings as a YAML mapping)
    with pytest.raises(ConfigError, match=r"invalid parameters \(scale_m: .*\); valid parameters: ") as plain:
        make_component("kernel", {"name": "huber", "scale_m": -1.0})
    assert "YAML" not in str(plain.value)  # (a wrong value, not a glued key: no hint)
