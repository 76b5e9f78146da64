"""Registry, result contract, synthetic accuracy, bad input and degeneracy of the ICP variants."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from conftest import cli_exit_code
from registration_helpers import structured_cloud

from lidarkit.errors import ConfigError, DataError, RegistrationError
from lidarkit.geometry import make_se3, pose_error, random_se3, so3_exp, transform_points
from lidarkit.registration import (
    ENTRY_POINT_GROUP,
    Registration,
    RegistrationResult,
    available_icp,
    config_fields,
    get_icp,
    register_icp,
    reload_plugins,
)
from lidarkit.registration import registry as registry_module
from lidarkit.registration.kiss import kiss_safe_pose
from lidarkit.registration.preprocess import (
    crop_range,
    ground_mask_by_height,
    ground_mask_by_plane,
    voxel_downsample,
)

BUILTIN = {"vanilla", "ground_filtered", "knn", "kiss", "open3d_point_to_point", "open3d_point_to_plane", "open3d_gicp"}

# per-variant params for small synthetic clouds (defaults are tuned for KITTI-sized scans)
SYNTH_PARAMS = {
    "vanilla": {"max_correspondence_distance_m": 1.0},
    "ground_filtered": {"max_correspondence_distance_m": 1.0, "ground_method": "ransac"},
    "knn": {"max_correspondence_distance_m": 1.0, "leafsize": 1},
    "kiss": {"voxel_size_m": 0.25, "initial_threshold_m": 0.5},
    "open3d_point_to_point": {"max_correspondence_distance_m": 1.0},
    "open3d_point_to_plane": {"voxel_size_m": 0.1, "normal_radius_m": 0.5},
    "open3d_gicp": {"voxel_size_m": 0.1, "normal_radius_m": 0.5},
    "small_gicp": {"downsampling_resolution_m": 0.1},
}


# ---------------------------------------------------------------- registry


def test_registry_lists_builtins_and_small_gicp_when_installed():
    names = set(available_icp())
    assert BUILTIN <= names
    try:
        import small_gicp  # noqa: F401
    except ImportError:
        assert "small_gicp" not in names
    else:
        assert "small_gicp" in names


def test_unknown_method_lists_available_names():
    with pytest.raises(ConfigError) as err:
        get_icp("no_such_icp")
    msg = str(err.value)
    assert "no_such_icp" in msg and "vanilla" in msg and "kiss" in msg


@pytest.mark.parametrize(
    "params, fragment",
    [({"max_iterationz": 3}, "max_iterationz"), ({"max_iterations": 0}, "max_iterations"), ({"nn_backend": "gpu"}, "nn_backend"),
     ({"workers": 0}, "workers must be -1"), ({"workers": -2}, "workers must be -1")],
)
def test_bad_params_raise_config_error_listing_valid_params(params, fragment):
    with pytest.raises(ConfigError) as err:
        get_icp("vanilla", **params)
    msg = str(err.value)
    assert fragment in msg and "epsilon_m2=" in msg and "max_correspondence_distance_m=" in msg


def test_listed_defaults_are_written_as_they_are_typed_back(capsys):
    """The listing showed voxel_size_m=None, and `-p voxel_size_m=None` copied from it was refused as "not a valid
    number"; a None default is listed as null, which -p reads as None."""
    from lidarkit.params import parse_value

    with pytest.raises(ConfigError) as err:
        get_icp("vanilla", max_iterations=0)
    assert "voxel_size_m=null" in str(err.value) and "=None" not in str(err.value)
    assert get_icp("vanilla", voxel_size_m=parse_value("null")).config.voxel_size_m is None
    assert cli_exit_code(["icp", "--list"]) == 0
    listed = capsys.readouterr().out
    assert "voxel_size_m: float | None = null" in " ".join(listed.split()) or "= null" in listed


def test_config_is_resolved_frozen_and_described():
    icp = get_icp("vanilla", max_iterations=7)
    assert icp.config.max_iterations == 7 and icp.config.epsilon_m2 == 1e-6
    with pytest.raises(Exception):
        icp.config.max_iterations = 3
    fields = config_fields("kiss")
    assert fields["max_range_m"][1] == 100.0 and fields["deskew"][1] is True
    assert all(desc for _, _, desc in fields.values())
    assert fields["max_range_m"][0] == "float"
    # a container reads as one (dict[str, Any], not "str | Any"); only unions join with |
    ground = config_fields("ground_filtered")
    assert ground["ground_params"][0] == "dict[str, Any]"
    assert ground["max_correspondence_distance_m"][0] == "float | None"
    assert config_fields("pipeline")["preprocess"][0] == "list[str | dict[str, Any]]"


def test_a_variant_given_another_variants_config_or_a_dict_is_refused_naming_it():
    """vanilla built with small_gicp's Config, or with a dict, failed at its first align with an AttributeError
    traceback; a config and keyword parameters together were a plain TypeError."""
    from lidarkit.registration import get_icp_class

    V, G = get_icp_class("vanilla"), get_icp_class("small_gicp")
    for config, got in ((G.Config(), G.Config.__name__), ({"max_iterations": 5}, "dict")):
        with pytest.raises(ConfigError, match=f"vanilla: config must be a {V.Config.__name__}, got {got}"):
            V(config)
    with pytest.raises(ConfigError, match="vanilla: pass either a config object or keyword parameters, not both"):
        V(V.Config(), max_iterations=3)
    assert V(V.Config(max_iterations=3)).config.max_iterations == 3


def test_a_variant_config_built_directly_is_one_config_error_saying_what_get_icp_says():
    """get_icp_class("vanilla").Config(max_iterations=0) raised pydantic's ValidationError (lines long, with a URL)
    where get_icp and the variant's constructor each said the problem in one line; the three say the same problem."""
    from lidarkit.registration import get_icp_class

    for name, params, problem in (
        ("vanilla", {"max_iterations": 0}, "max_iterations: Input should be greater than or equal to 1"),
        ("kiss", {"voxel_size_m": -1}, "voxel_size_m: Input should be greater than 0"),
        ("vanilla", {"max_iterations": 0, "voxel_size_m": -1},
         "max_iterations: Input should be greater than or equal to 1; voxel_size_m: Input should be greater than 0"),
        ("kiss", {"assess": False, "min_fitness": 0.5}, "min_fitness set(s) the assessment, which assess=False leaves out"),
    ):
        cls = get_icp_class(name)
        with pytest.raises(ConfigError) as direct:
            cls.Config(**params)
        assert str(direct.value) == problem
        if name == "vanilla":  # (kiss registers apart from its assessment: its constructor takes assess=False)
            with pytest.raises(ConfigError) as built:
                cls(**params)
            assert str(built.value) == f"{name}: invalid parameters ({problem})"
        with pytest.raises(ConfigError) as named:
            get_icp(name, **params)
        assert str(named.value).startswith(f"method {name!r}: invalid parameters ({problem}); valid parameters: min_fitness=0.3, ")


def test_register_icp_rejects_non_registration_and_name_clash():
    with pytest.raises(ConfigError):
        register_icp("bogus")(object)

    class Other(Registration):
        pass

    with pytest.raises(ConfigError, match="already taken"):
        register_icp("vanilla")(Other)


PLUGIN_SOURCE = textwrap.dedent(
    '''
    import numpy as np
    from lidarkit.registration import Registration, RegistrationConfig, RegistrationResult
    from lidarkit.registration.base import Degeneracy

    class IdentityConfig(RegistrationConfig):
        offset_m: float = 0.0

    class IdentityICP(Registration):
        Config = IdentityConfig
        def _align(self, source_xyz, target_xyz, init_T):
            T = init_T.copy(); T[0, 3] += self.config.offset_m
            return RegistrationResult(T, False, 0, (), 0, 0.0, 0.0, Degeneracy.unknown("plugin"), reason="identity plugin")
    '''
)


def _install_dist_info(site, monkeypatch, name, target, entry_name=None):
    dist = site / f"{name}-0.1.dist-info"
    dist.mkdir(parents=True)
    (dist / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text(f"[{ENTRY_POINT_GROUP}]\n{entry_name or name.replace('-', '_')} = {target}\n")
    monkeypatch.syspath_prepend(str(site))


def test_entry_point_plugin_is_discovered_and_configurable(tmp_path, monkeypatch):
    site = tmp_path / "site"
    site.mkdir()
    (site / "lk_identity_plugin.py").write_text(PLUGIN_SOURCE)
    _install_dist_info(site, monkeypatch, "lk-identity-plugin", "lk_identity_plugin:IdentityICP")
    try:
        reload_plugins()
        assert "lk_identity_plugin" in available_icp()
        icp = get_icp("lk_identity_plugin", offset_m=0.5)
        res = icp.align(np.eye(3) * 2 + 1, np.eye(3) * 3)
        assert res.method == "lk_identity_plugin" and res.T_target_source[0, 3] == 0.5 and not res.converged
        with pytest.raises(ConfigError, match="offset_m"):
            get_icp("lk_identity_plugin", offset=1)
    finally:
        registry_module._VARIANTS.pop("lk_identity_plugin", None)


def test_broken_plugin_is_left_out_and_named_when_asked_for(tmp_path, monkeypatch, caplog):
    """One broken plugin made every lookup fail (available_icp, `icp --list`, a typo's message): now it is left out
    with a warning, the rest works, and asking for it says why it is missing."""
    site = tmp_path / "site"
    site.mkdir()
    (site / "lk_broken_plugin.py").write_text("raise RuntimeError('boom at import')\n")
    _install_dist_info(site, monkeypatch, "lk-broken-plugin", "lk_broken_plugin:Nope")
    try:
        with caplog.at_level("WARNING", logger="lidarkit.registration.registry"):
            reload_plugins()
        assert "lk_broken_plugin" in caplog.text and "boom at import" in caplog.text
        assert "vanilla" in available_icp() and "lk_broken_plugin" not in available_icp()
        with pytest.raises(ConfigError, match=r"ICP plugin 'lk_broken_plugin': this plugin is installed but could not be loaded: .*boom at import"):
            get_icp("lk_broken_plugin")
        with pytest.raises(ConfigError, match="unknown ICP method 'kis'; available: .*kiss"):
            get_icp("kis")
        assert cli_exit_code(["icp", "--list"]) == 0
    finally:
        monkeypatch.undo()
        reload_plugins()


def test_a_plugin_named_like_a_built_in_is_said_to_be_left_out(tmp_path, monkeypatch, caplog):
    """An entry point named 'vanilla' was dropped without a word (nor listed by --list among the plugins left out);
    the built-in keeps answering to the name."""
    from lidarkit.registration.registry import broken_plugins

    site = tmp_path / "site"
    site.mkdir()
    (site / "lk_shadow_plugin.py").write_text(PLUGIN_SOURCE)
    _install_dist_info(site, monkeypatch, "lk-shadow-plugin", "lk_shadow_plugin:IdentityICP", entry_name="vanilla")
    try:
        with caplog.at_level("WARNING", logger="lidarkit.registration.registry"):
            reload_plugins()
        assert "ICP plugin 'vanilla' left out: its name is a built-in variant's" in caplog.text
        assert "rename the entry point" in broken_plugins()["vanilla"]
        assert type(get_icp("vanilla")).__module__ == "lidarkit.registration.vanilla"
    finally:
        monkeypatch.undo()
        reload_plugins()


def test_a_plugin_returning_a_bare_pose_or_a_plain_config_is_refused_naming_it():
    """``_align`` returning a 4x4 array was an AttributeError from lidarkit's internals; a Config that is a plain
    pydantic model was accepted, then failed on its first use."""
    import pydantic

    from lidarkit.errors import RegistrationError
    from lidarkit.registration import Registration, RegistrationConfig, register_icp

    class BarePose(Registration):
        name = "bare_pose"
        Config = RegistrationConfig

        def _align(self, source_xyz, target_xyz, init_T):
            return init_T

    with pytest.raises(RegistrationError, match=r"bare_pose: BarePose._align returned ndarray, not a RegistrationResult"):
        BarePose().align(np.eye(3) * 2 + 1, np.eye(3) * 3)

    class Plain(pydantic.BaseModel):
        offset_m: float = 0.0

    class PlainConfig(Registration):
        Config = Plain

    with pytest.raises(ConfigError, match="PlainConfig.Config must derive from lidarkit.registration.RegistrationConfig"):
        register_icp("plain_config")(PlainConfig)
    assert "plain_config" not in available_icp()
    # a scaled rotation was accepted ("converged"); register_icp(None) broke every later unknown-name error (sorting)
    scaled = get_icp("vanilla").align(np.eye(3) * 2 + 1, np.eye(3) * 3)

    class Scaled(Registration):
        name = "scaled"
        Config = RegistrationConfig

        def _align(self, source_xyz, target_xyz, init_T):
            import dataclasses

            T = np.eye(4)
            T[:3, :3] *= 2
            return dataclasses.replace(scaled, T_target_source=T)

    with pytest.raises(RegistrationError, match=r"scaled .*: scaled returned a pose that is not a rigid transform"):
        Scaled().align(np.eye(3) * 2 + 1, np.eye(3) * 3)
    for bad in (None, "", " vanilla"):
        with pytest.raises(ConfigError, match="register_icp: a variant name must be a non-empty word"):
            register_icp(bad)
    assert all(isinstance(n, str) for n in available_icp())


# ---------------------------------------------------------------- result contract and synthetic accuracy


@pytest.fixture(scope="module")
def synthetic_pair():
    rng = np.random.default_rng(7)
    target = structured_cloud(rng, n=12000)
    T_gt = make_se3(so3_exp(np.radians([0.3, -0.4, 4.0])), [0.6, -0.25, 0.05])  # vehicle-like: small roll/pitch
    # source = the scene seen from the moved sensor, independently sampled (no exact point pairs)
    source = transform_points(np.linalg.inv(T_gt), structured_cloud(np.random.default_rng(8), n=12000))
    return source, target, T_gt


@pytest.mark.parametrize("name", sorted(SYNTH_PARAMS))
def test_every_variant_recovers_a_known_motion_on_a_structured_scene(name, synthetic_pair):
    if name not in available_icp():
        pytest.skip(f"{name} not installed")
    source, target, T_gt = synthetic_pair
    res = get_icp(name, **SYNTH_PARAMS[name]).align(source, target)
    assert isinstance(res, RegistrationResult) and res.method == name
    dt, dr = pose_error(res.T_target_source, T_gt)
    # independent samplings of the same surfaces: a few cm / a few hundredths of a degree
    assert dt < 0.05 and dr < 0.15, (name, dt, dr)
    assert res.converged and not res.degeneracy.degenerate, res.reason
    assert res.runtime_s > 0 and res.n_correspondences > 1000 and 0.5 < res.fitness <= 1.0
    assert len(res.degeneracy.eigenvalues) == 6 and res.degeneracy.condition_number < 1e3
    d = json.loads(json.dumps(res.to_dict()))
    assert d["method"] == name and np.allclose(d["T_target_source"], res.T_target_source)


@pytest.mark.parametrize("seed", [100, 101, 102])
@pytest.mark.parametrize("name", sorted(SYNTH_PARAMS))
def test_random_se3_on_exact_copy_recovered_tightly(name, seed):
    """Property: a random motion (<= 0.5 m, <= 5 deg) of a noise-free structured cloud is recovered
    to 2 mm / 0.01 deg by every variant (measured worst case: 0.3 mm / 0.004 deg)."""
    if name not in available_icp():
        pytest.skip(f"{name} not installed")
    rng = np.random.default_rng(seed)
    target = structured_cloud(rng, n=12000)
    T_gt = random_se3(rng, max_translation=0.5, max_angle_rad=np.radians(5))
    res = get_icp(name, **SYNTH_PARAMS[name]).align(transform_points(np.linalg.inv(T_gt), target), target)
    dt, dr = pose_error(res.T_target_source, T_gt)
    assert dt < 2e-3 and dr < 0.01, (name, seed, dt, dr)
    assert res.converged and not res.degeneracy.degenerate


def test_vanilla_exact_pairs_random_se3_tight(rng):
    """Source = rigidly moved copy of the target: point-to-point ICP must recover T to ~1e-6."""
    target = structured_cloud(rng, n=6000)
    icp = get_icp("vanilla", epsilon_m2=1e-14, max_iterations=200, coarse_stride=1)
    for _ in range(3):
        T_gt = random_se3(rng, max_translation=0.3, max_angle_rad=np.radians(3))
        source = transform_points(np.linalg.inv(T_gt), target)
        res = icp.align(source, target)
        dt, dr = pose_error(res.T_target_source, T_gt)
        assert dt < 1e-6 and dr < 1e-5
        assert res.rmse_history[-1] < 1e-6 and res.rmse_history[0] > res.rmse_history[-1]


def test_vanilla_rmse_history_and_stop_rule(synthetic_pair):
    source, target, _ = synthetic_pair
    res = get_icp("vanilla", epsilon_m2=1e-6, coarse_stride=1).align(source, target)
    h = np.asarray(res.rmse_history)
    assert len(h) == res.iterations + 1  # one RMSE per correspondence step, the last one triggers the stop
    assert abs(h[-1] ** 2 - h[-2] ** 2) < 1e-6 and abs(h[-2] ** 2 - h[-3] ** 2) >= 1e-6
    capped = get_icp("vanilla", max_iterations=2, epsilon_m2=0.0, coarse_stride=1).align(source, target)
    assert capped.iterations == 2 and not capped.converged and "max_iterations" in capped.reason


def test_small_gicp_counts_the_updates_it_ran(synthetic_pair):
    """small_gicp reports the 0-based index of its last Gauss-Newton update: max_iterations=1 said "did not converge
    in 0 iterations" and timing.csv gave 0, 1, 2 for max_iterations 1, 2, 3; the count is now the updates run."""
    if "small_gicp" not in available_icp():
        pytest.skip("small_gicp not installed")
    source, target, _ = synthetic_pair
    for cap in (1, 2):
        res = get_icp("small_gicp", max_iterations=cap, **SYNTH_PARAMS["small_gicp"]).align(source, target)
        assert res.iterations == cap and not res.converged
        assert res.reason == f"small_gicp did not converge in {cap} iterations"
    free = get_icp("small_gicp", **SYNTH_PARAMS["small_gicp"]).align(source, target)
    assert free.converged and 1 <= free.iterations < 50


def test_nn_backends_agree(rng):
    target = structured_cloud(rng, n=4000)
    source = transform_points(make_se3(so3_exp([0, 0, 0.03]), [0.3, 0.1, 0]), structured_cloud(rng, n=4000))
    poses = [
        get_icp("knn", nn_backend=b, leafsize=leaf, voxel_size_m=0.5).align(source, target).T_target_source
        for b, leaf in (("scipy", 1), ("scipy", 16), ("scipy", 200), ("open3d", 16), ("brute", 16))
    ]
    for T in poses[1:]:
        assert np.allclose(T, poses[0], atol=1e-6)


def test_init_guess_is_used_and_orthonormalized(synthetic_pair):
    source, target, T_gt = synthetic_pair
    sloppy = T_gt.copy()
    sloppy[:3, :3] = np.round(sloppy[:3, :3], 3)  # as read back from a short text file
    res = get_icp("vanilla", max_iterations=1, coarse_stride=1).align(source, target, init_T=sloppy)
    assert pose_error(res.T_target_source, T_gt)[0] < 0.05
    with pytest.raises(DataError, match="init_T"):
        get_icp("vanilla").align(source, target, init_T=np.eye(3))
    for not_numbers in ("identity", [[1, 0, 0, 0]] * 3 + [[0, 0, 1]], {"x": 1}):
        with pytest.raises(DataError, match="init_T.*4x4 matrix"):
            get_icp("vanilla").align(source, target, init_T=not_numbers)


# ---------------------------------------------------------------- bad input


@pytest.mark.parametrize("name", ["vanilla", "kiss", "open3d_gicp"])
def test_bad_clouds_name_the_cloud(name, rng):
    good = structured_cloud(rng, n=600)
    icp = get_icp(name)
    with pytest.raises(DataError, match="source cloud"):
        icp.align(np.zeros((0, 3)), good)
    with pytest.raises(DataError, match="target cloud"):
        icp.align(good, good[:2])
    nan = good.copy()
    nan[5, 1] = np.nan
    with pytest.raises(DataError, match="target cloud.*NaN"):
        icp.align(good, nan)
    with pytest.raises(DataError, match="source cloud.*shape"):
        icp.align(good[:, :2], good)
    with pytest.raises(DataError, match="source cloud.*numeric"):
        icp.align(good.astype(str), good)


def test_float32_input_is_accepted(synthetic_pair):
    source, target, T_gt = synthetic_pair
    res = get_icp("vanilla", max_correspondence_distance_m=1.0).align(source.astype(np.float32), target.astype(np.float32))
    assert pose_error(res.T_target_source, T_gt)[0] < 0.05


@pytest.mark.parametrize("name", ["kiss", "open3d_point_to_plane", "genz"])
def test_read_only_clouds_are_accepted(name, synthetic_pair):
    """A memory-mapped .npy is read-only: kiss, genz and the Open3D variants failed "array is not writeable" (kiss's
    register_frame with a bare ValueError); the points boundary copies such an array."""
    if name not in available_icp():
        pytest.skip(f"{name} not installed")
    source, target, T_gt = synthetic_pair
    frozen = [np.array(c) for c in (source, target)]
    for c in frozen:
        c.flags.writeable = False
    res = get_icp(name, **SYNTH_PARAMS.get(name, {})).align(*frozen)
    # (genz's accuracy depends on what genz-icp instances ran before in the process: the crash is what is tested)
    assert np.isfinite(res.T_target_source).all() and (name == "genz" or pose_error(res.T_target_source, T_gt)[0] < 0.05)
    if name == "kiss":
        kiss = get_icp("kiss")
        kiss.register_frame(frozen[1])
        assert np.isfinite(kiss.register_frame(frozen[0])).all()


def test_too_few_correspondences_is_not_converged_with_reason(rng):
    target = structured_cloud(rng, n=2000)
    far = target + [500.0, 0.0, 0.0]
    res = get_icp("vanilla", max_correspondence_distance_m=1.0).align(far, target)
    # 500 m apart the bounding boxes do not even overlap: flagged before any iteration
    assert not res.converged and "no initial overlap" in res.reason and res.n_correspondences == 0
    assert not res.degeneracy.degenerate and res.degeneracy.kind == "unknown (no initial overlap)"  # (nothing to judge)


def test_no_correspondences_is_said_first_and_not_flagged_degenerate():
    """A KITTI scan scaled x100 onto itself (0 correspondences) read "degenerate geometry: min/max eigenvalue 0.00e+00
    < 0.01; only 0 correspondences ..." and was counted DEGENERATE: without correspondences there is no geometry to
    judge; the count comes first and the degeneracy is unknown (NaN eigenvalues), not flagged."""
    from conftest import shared_path
    from registration_helpers import read_kitti_bin

    target = read_kitti_bin(shared_path("kitti_odometry", "sequences", "00", "velodyne", "000000.bin"))
    res = get_icp("vanilla").align(100.0 * target, target)
    assert not res.converged and res.n_correspondences == 0
    assert res.reason == "only 0 correspondences (min_correspondences=10); fitness 0.000 below min_fitness=0.3"
    assert not res.degeneracy.degenerate and res.degeneracy.kind == "unknown (too few correspondences)"
    assert np.isnan(res.degeneracy.ratio) and res.to_dict()["degeneracy"]["eigenvalues"] == [None] * 6


def test_an_os_error_in_a_plugin_is_a_registration_error_and_lidarkits_own_pass_unchanged(rng):
    """An OSError raised in a plugin's _align ended in a traceback (not in the backend errors); lidarkit's own errors,
    an OutputError among them, are no OSError and still pass unchanged."""
    from lidarkit.errors import OutputError

    raised = {"os": OSError("disk gone"), "own": OutputError("disk full", source="my.txt"),
              # (a plugin importing its backend lazily, a typo, a generator run dry: tracebacks from `lidarkit icp`)
              "import": ModuleNotFoundError("No module named 'optional_backend'"), "name": NameError("name 'x' is not defined"),
              "stop": StopIteration("x")}

    class FailICP(Registration):
        name = "fail_test"

        def _align(self, source_xyz, target_xyz, init_T):
            raise raised[self.which]

    pts = structured_cloud(rng, n=500)
    icp = FailICP()
    icp.which = "os"
    with pytest.raises(RegistrationError) as err:
        icp.align(pts, pts)
    n = len(pts)
    assert str(err.value) == f"fail_test ({n} source / {n} target points): the fail_test backend failed on this pair: OSError: disk gone"
    for which, said in (("import", "ModuleNotFoundError: No module named 'optional_backend'"),
                        ("name", "NameError: name 'x' is not defined"), ("stop", "StopIteration: x")):
        icp.which = which
        with pytest.raises(RegistrationError) as err:
            icp.align(pts, pts)
        assert str(err.value).endswith(f"the fail_test backend failed on this pair: {said}")
    icp.which = "own"
    with pytest.raises(OutputError) as err:
        icp.align(pts, pts)
    assert err.value is raised["own"] and str(err.value) == "my.txt: disk full"


def test_ground_filter_with_nothing_left_is_flagged_not_converged(rng):
    flat = np.c_[rng.uniform(-10, 10, (500, 2)), -1.73 + rng.normal(0, 0.01, 500)]  # ground with 1 cm noise (an exactly planar cloud is a 2D scan)
    for method in ("height", "local_plane"):
        res = get_icp("ground_filtered", ground_method=method).align(flat, flat, init_T=make_se3(np.eye(3), [0.5, 0, 0]))
        assert not res.converged and res.reason.startswith("too little left after ground removal"), res.reason
        assert "constant-velocity" not in res.reason  # (a pairwise alignment falls back to no motion: the runner's to say)
        assert res.extra["ground_removal_flagged"] and res.extra["source_points_kept"] == 0
        np.testing.assert_allclose(res.T_target_source[:3, 3], [0.5, 0, 0])  # the guess, for the runner to replace


# ---------------------------------------------------------------- degeneracy


@pytest.mark.parametrize("name", ["vanilla", "open3d_point_to_plane", "small_gicp", "kiss"])
def test_flat_ground_patch_is_flagged_degenerate(name, rng):
    if name not in available_icp():
        pytest.skip(f"{name} not installed")
    plane = np.c_[rng.uniform(-15, 15, (8000, 2)), rng.normal(-1.73, 0.01, 8000)]
    moved = transform_points(make_se3(so3_exp([0, 0, 0.02]), [0.3, 0.1, 0.0]), plane)
    params = {"voxel_size_m": 0.3, "initial_threshold_m": 0.5} if name == "kiss" else {}
    res = get_icp(name, **params).align(moved, plane)
    assert res.degeneracy.degenerate, res.degeneracy
    assert "degenerate" in res.reason or not res.converged
    # the unconstrained directions are in-plane translation and yaw: weakest direction lives there
    w = np.abs(np.asarray(res.degeneracy.weakest_direction))
    assert w[[0, 1, 5]].sum() > 0.95 * w.sum()
    assert sum(e < 1e-3 * res.degeneracy.eigenvalues[-1] for e in res.degeneracy.eigenvalues) == 3


@pytest.mark.parametrize("name", ["vanilla", "small_gicp", "open3d_gicp", "knn"])
def test_a_flat_grounds_weak_directions_are_named_as_one_subspace(name):
    """On a flat ground the three weak eigenvalues are near-equal (6e-6, 6e-6, 7e-6) and their eigenvectors an
    arbitrary mix of x, y and yaw: small_gicp named three "translation along (0.52, 0.86, 0.00) coupled with
    rotation" and no yaw, vanilla "rotation about z (yaw) coupled with translation", ...; the subspace is named now."""
    if name not in available_icp():
        pytest.skip(f"{name} not installed")
    rng = np.random.default_rng(0)
    ground, other = (np.c_[rng.uniform(-20, 20, (5000, 2)), rng.normal(0, 0.01, 5000) - 1.7] for _ in range(2))
    deg = get_icp(name).align(ground, other).degeneracy
    assert deg.weak_directions == ("translation along x and y, rotation about z (yaw)",)
    assert sum(e < 1e-4 for e in deg.eigenvalues) == 3


@pytest.mark.parametrize("name", ["kiss", "small_gicp", "vanilla", "open3d_gicp"])
def test_the_kitti_road_s_weak_directions_are_named_as_one_subspace(name):
    """The road alone (KITTI 00, z < -1.5 m, 8-40 m around the car): x and y below the threshold, yaw 2-6x above it.
    The two weak ones alone are a mix of x, y and yaw, and were named as one or two raw vectors ("translation along
    (-0.68, 0.73, -0.00) coupled with rotation"), other ones on every pair and variant; with yaw they are one subspace.
    open3d_gicp on 7 -> 6: yaw 3.1x above the larger weak eigenvalue but 10.1x above the smaller was left out (two raw
    vectors): the directions above the threshold are joined within a factor of the weak ones' largest."""
    if name not in available_icp():
        pytest.skip(f"{name} not installed")
    from conftest import shared_path
    from registration_helpers import read_kitti_bin

    def road(frame):
        p = read_kitti_bin(shared_path("kitti_odometry", "sequences", "00", "velodyne", f"{frame:06d}.bin"))
        r = np.hypot(p[:, 0], p[:, 1])
        return p[(p[:, 2] < -1.5) & (r > 8) & (r < 40)]

    scans = [road(frame) for frame in range(10)]
    for k in range(9):
        deg = get_icp(name).align(scans[k + 1], scans[k]).degeneracy
        assert deg.degenerate and deg.weak_directions == ("translation along x and y, rotation about z (yaw)",), (k, deg)


def test_points_on_a_line_are_flagged_degenerate(rng):
    line = np.c_[rng.uniform(-10, 10, 3000), np.zeros(3000), np.zeros(3000)] + rng.normal(0, 1e-3, (3000, 3))
    res = get_icp("vanilla").align(line + [0.05, 0.02, 0.0], line)
    assert res.degeneracy.degenerate and "degenerate" in res.reason
    # translation along the line (x) and rotation about it (rx) are unconstrained
    assert sum(e < 1e-3 * res.degeneracy.eigenvalues[-1] for e in res.degeneracy.eigenvalues) == 2


# ---------------------------------------------------------------- kiss orthonormalization guard


NON_ORTHONORMAL_SCRIPT = textwrap.dedent(
    """
    import numpy as np, sys
    from kiss_icp.kiss_icp import KissICP
    from lidarkit.registration import get_icp
    rng = np.random.default_rng(0)
    pts = rng.uniform(-20, 20, (4000, 3))
    bad = np.eye(4); bad[:3, :3] = [[1.00002, 0, 0], [0, 1.00002, 0], [0, 0, 1]]  # R not orthogonal
    if sys.argv[1] == "direct":
        k = KissICP(get_icp("kiss").kiss_config)
        k.register_frame(pts, np.array([])); k.last_delta = bad
        k.register_frame(pts, np.array([]))
    else:
        icp = get_icp("kiss")
        icp.register_frame(pts); icp.pipeline.last_delta = bad
        icp.register_frame(pts)
        icp.reset(bad)
        icp.register_frame(pts)
        r = icp.align(pts, pts, init_T=bad)
        assert np.allclose(r.T_target_source, np.eye(4), atol=1e-3), r.T_target_source
    print("survived")
    """
)


@pytest.mark.slow
def test_kiss_non_orthonormal_pose_aborts_kiss_but_not_lidarkit(tmp_path):
    script = tmp_path / "kiss_abort.py"
    script.write_text(NON_ORTHONORMAL_SCRIPT)
    direct = subprocess.run([sys.executable, str(script), "direct"], capture_output=True, text=True, timeout=120)
    assert direct.returncode != 0 and "not orthogonal" in direct.stderr + direct.stdout
    wrapped = subprocess.run([sys.executable, str(script), "lidarkit"], capture_output=True, text=True, timeout=120)
    assert wrapped.returncode == 0 and "survived" in wrapped.stdout, wrapped.stderr


def test_kiss_safe_pose_leaves_exact_poses_bitwise_and_fixes_sloppy_ones():
    T = make_se3(so3_exp([0.1, -0.2, 0.3]), [1, 2, 3])
    assert kiss_safe_pose(T) is not None and np.array_equal(kiss_safe_pose(T), T)
    sloppy = T.copy()
    sloppy[:3, :3] = np.round(sloppy[:3, :3], 4)
    fixed = kiss_safe_pose(sloppy)
    assert np.abs(fixed[:3, :3].T @ fixed[:3, :3] - np.eye(3)).max() < 1e-12
    assert np.abs(fixed - sloppy).max() < 1e-3


def test_kiss_sequence_mode_matches_kiss_icp_directly(rng):
    from kiss_icp.kiss_icp import KissICP

    scene = structured_cloud(rng, n=20000)
    frames = [transform_points(np.linalg.inv(make_se3(so3_exp([0, 0, 0.01 * k]), [0.5 * k, 0, 0])), scene) for k in range(4)]
    icp = get_icp("kiss", voxel_size_m=0.5)
    direct = KissICP(icp.kiss_config)
    icp.reset()
    twin = KissICP(icp.kiss_config)
    for f in frames:
        ours = icp.register_frame(f)
        direct.register_frame(f, np.array([]))
        twin.register_frame(f, np.array([]))
        # kiss-icp itself is not bit-reproducible (parallel reductions): two KissICP instances differ by
        # ~1e-16; lidarkit must add nothing beyond that jitter
        jitter = np.abs(direct.last_pose - twin.last_pose).max()
        assert np.abs(ours - direct.last_pose).max() <= max(1e-12, 10 * jitter)
    assert pose_error(ours, make_se3(so3_exp([0, 0, 0.03]), [1.5, 0, 0]))[0] < 0.05


def test_kiss_motion_guess_is_checked_as_init_T():
    """register_frame(motion_guess=...) re-orthonormalized any 4x4: a reflection diag(-1, 1, 1, 1) on KITTI 00 scans 0/1
    gave t = [0.247, 0.033, -3.129] (true ~[0.697, 0.008, 0.018]), diag(2, 1, 1, 1) and a zero matrix were quietly
    replaced, and a 3x3 read "last_delta: expected a 4x4 pose". Now refused as align's init_T, naming motion_guess;
    a guess rounded to 4 decimals (kiss_safe_pose's job) still registers."""
    from conftest import shared_path
    from registration_helpers import read_kitti_bin

    scans = [read_kitti_bin(shared_path("kitti_odometry", "sequences", "00", "velodyne", f"{k:06d}.bin")) for k in (0, 1)]
    not_rotation = "motion_guess: the 3x3 block is not a rotation (R^T R = I within 0.001, det > 0)"
    for guess, line in (
        (np.diag([-1.0, 1, 1, 1]), not_rotation),
        (np.diag([2.0, 1, 1, 1]), not_rotation),
        (np.zeros((4, 4)), "motion_guess: last row must be [0, 0, 0, 1], got [0.0, 0.0, 0.0, 0.0]"),
        (np.eye(3), "motion_guess: expected a 4x4 matrix, got shape (3, 3)"),
    ):
        icp = get_icp("kiss")
        icp.register_frame(scans[0])
        with pytest.raises(DataError) as exc:
            icp.register_frame(scans[1], motion_guess=guess)
        assert str(exc.value) == line
    rounded = np.round(make_se3(so3_exp([0.0, 0.0, 0.001]), [0.7, 0.0, 0.0]), 4)
    icp = get_icp("kiss")
    icp.register_frame(scans[0])
    t = icp.register_frame(scans[1], motion_guess=rounded)[:3, 3]
    assert np.abs(t - [0.697, 0.008, 0.018]).max() < 0.01, t


@pytest.mark.parametrize("method", ["kiss", "genz", "pipeline"])
def test_per_point_times_that_are_not_numbers_are_a_named_error(method):
    """register_frame(points, "abc") raised a raw ValueError "could not convert string to float: 'abc'"."""
    if method not in available_icp():
        pytest.skip(f"{method} not installed")
    scan = structured_cloud(np.random.default_rng(0), n=2000)
    with pytest.raises(DataError) as exc:
        get_icp(method).register_frame(scan, "abc")
    assert str(exc.value) == "point_times_s: expected per-point times in seconds (numbers), got str 'abc'"


# ---------------------------------------------------------------- preprocessing


def test_voxel_downsample_centroids(rng):
    pts = np.array([[0.1, 0.1, 0.1], [0.3, 0.3, 0.3], [1.5, 0.2, 0.2]])
    out = voxel_downsample(pts, 1.0)
    assert out.shape == (2, 3) and np.allclose(out[0], [0.2, 0.2, 0.2]) and np.allclose(out[1], [1.5, 0.2, 0.2])
    big = rng.uniform(-50, 50, (50000, 3))
    assert len(voxel_downsample(big, 10.0)) == 1000
    with pytest.raises(ConfigError):
        voxel_downsample(pts, 0.0)


def test_crop_and_ground_masks(rng):
    scene = structured_cloud(rng, n=6000)
    by_height = ground_mask_by_height(scene)  # z < -1.73 + 0.73 = -1 m
    assert np.array_equal(by_height, scene[:, 2] < -1.0)
    by_plane = ground_mask_by_plane(scene, seed=3)
    near_ground = np.abs(scene[:, 2] + 1.7) <= 0.2  # the ground itself and the feet of walls / boxes
    assert (by_plane == near_ground).mean() > 0.99 and by_plane[np.isclose(scene[:, 2], -1.7)].all()
    wall_only = scene[np.isclose(scene[:, 1], 8.0)]
    assert not ground_mask_by_plane(wall_only + [0, 0, -3.0]).any()  # vertical plane is never ground
    r = np.linalg.norm(crop_range(scene, 5.0, 15.0), axis=1)
    assert r.min() >= 5.0 and r.max() <= 15.0


def test_kiss_range_crop_leaving_nothing_names_the_cloud(rng):
    near = structured_cloud(rng, n=600) * 0.01  # everything within 0.3 m of the sensor
    with pytest.raises(RegistrationError, match="source cloud.*within"):
        get_icp("kiss", min_range_m=1.0).align(near, structured_cloud(rng, n=600))


def test_small_gicp_missing_is_unlisted_with_a_logged_note():
    code = textwrap.dedent(
        """
        import logging, sys
        logging.basicConfig(level=logging.INFO, format="%(name)s %(message)s")
        sys.modules["small_gicp"] = None  # import fails as if not installed
        from lidarkit.registration import available_icp, get_icp
        from lidarkit.errors import ConfigError
        assert "small_gicp" not in available_icp() and "vanilla" in available_icp()
        try:
            get_icp("small_gicp")
        except ConfigError as err:
            print("config error:", err)
        try:
            get_icp("smal_gicp")
        except ConfigError as err:
            print("typo:", err)
        from lidarkit.cli import main
        try:
            main(["icp", "--list"])
        except SystemExit:
            pass
        """
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "small_gicp not installed" in out.stderr
    # a typo and the listing say the variant exists and how to install it (neither said a word of it)
    assert "unknown ICP method 'smal_gicp'; available: " in out.stdout
    assert "(not installed: small_gicp, pip install 'lidarkit[gicp]'" in out.stdout
    assert "'small_gicp' not installed: pip install 'lidarkit[gicp]'" in out.stdout
    # named with its pip line (it read as a typo: "unknown ICP method 'small_gicp'")
    assert "the 'small_gicp' variant needs the Python package 'small_gicp', not installed here: pip install 'lidarkit[gicp]'" in out.stdout


def test_initial_gap_probe_path_matches_the_exact_boxes():
    """initial_gap_m settles overlap on a few moved points first: over random poses near and far, its answer equals
    the distance between the exact boxes of the moved source and the target (None within the margin)."""
    from lidarkit.registration.base import NO_OVERLAP_MARGIN, bounds, initial_gap_m

    rng = np.random.default_rng(3)
    cloud = rng.uniform(-20, 20, size=(5000, 3)) * [1.0, 1.0, 0.1]
    seen = {"none": 0, "gap": 0}
    for _ in range(200):
        T = make_se3(so3_exp(rng.normal(size=3) * rng.uniform(0, 1.5)), rng.normal(size=3) * rng.uniform(0, 60))
        lo_s, hi_s = bounds(transform_points(T, cloud))
        lo_t, hi_t = bounds(cloud)
        margin = max(1.0, NO_OVERLAP_MARGIN * float(np.linalg.norm(hi_t - lo_t)))
        exact = float(np.linalg.norm(np.maximum(0.0, np.maximum(lo_s - hi_t, lo_t - hi_s))))
        got = initial_gap_m(cloud, cloud, T)
        if exact > margin:
            assert got == pytest.approx(exact, rel=1e-12)
            seen["gap"] += 1
        else:
            assert got is None
            seen["none"] += 1
    assert min(seen.values()) > 20  # both branches exercised


def test_surface_neighbours_match_scipy_on_a_kitti_scan():
    """The local surfaces of the degeneracy summary / covariance come from small_gicp's KdTree when installed: on a
    KITTI scan the k nearest neighbours are the same sets as scipy's exact tree, so the projectors are identical."""
    from conftest import shared_path
    from scipy.spatial import cKDTree

    from lidarkit.registration import degeneracy

    if degeneracy._small_gicp is None:
        pytest.skip("small_gicp not installed: scipy's tree is the only path")
    scan = np.fromfile(shared_path("kitti_odometry", "sequences", "00", "velodyne", "000000.bin"), dtype=np.float32)
    points = scan.reshape(-1, 4)[::4, :3].astype(np.float64)
    queries = points[np.random.default_rng(0).choice(len(points), 1500, replace=False)]
    ours = degeneracy._knn(points, queries, 20)
    _, ref = cKDTree(points).query(queries, k=20)
    assert all(set(a) == set(b) for a, b in zip(ours, ref))
    assert np.array_equal(degeneracy.surface_constraints(points[np.sort(ours, axis=1)]),
                          degeneracy.surface_constraints(points[np.sort(ref, axis=1)]))


@pytest.mark.parametrize("method", ["open3d_gicp", "small_gicp"])
def test_an_array_changed_in_place_is_prepared_again(method):
    """The prepared-cloud cache finds a cloud again by its array: an array changed in place since (the same object,
    the same address, 31 of every 32 rows moved 5 m) gets the answer a fresh instance gives, not the cached one's."""
    from lidarkit.samples import sample_path

    if method not in available_icp():
        pytest.skip(f"{method} not installed")
    target = np.load(sample_path("kitti_pair", "000094.npy")).astype(np.float64)
    source = np.load(sample_path("kitti_pair", "000095.npy")).astype(np.float64)
    icp = get_icp(method)
    icp.align(source, target)
    moved = np.ones(len(source), dtype=bool)
    moved[:: len(source) // 32] = False
    source[moved] += [5.0, 0.0, 0.0]
    np.testing.assert_allclose(icp.align(source, target).T_target_source, get_icp(method).align(source, target).T_target_source,
                               atol=1e-9)


def test_a_variant_whose_backend_returns_nan_raises_a_registration_error():
    import dataclasses

    from lidarkit.registration.open3d_icp import Open3DPointToPlane

    class NanICP(Open3DPointToPlane):
        def _align(self, source_xyz, target_xyz, init_T):
            return dataclasses.replace(super()._align(source_xyz, target_xyz, init_T), T_target_source=np.full((4, 4), np.nan))

    rng = np.random.default_rng(0)
    cloud = rng.uniform(-10, 10, size=(500, 3))
    with pytest.raises(RegistrationError, match="returned a pose with NaN or infinite entries, not a finite 4x4 matrix"):
        NanICP().align(cloud, cloud)


@pytest.mark.parametrize("method", ["small_gicp", "open3d_gicp", "open3d_point_to_plane"])
def test_georeferenced_clouds_register_as_at_the_origin(method):
    """The real KITTI pair 1000 km out (UTM-like coordinates): small_gicp's voxel grid overflowed (no correspondences,
    100k warnings) and Open3D's GICP / point-to-plane drifted metres off. The backends now work around a local origin:
    the same pose as at the origin (moved by the offset), the same fitness."""
    from lidarkit.registration.local_origin import into
    from lidarkit.samples import sample_path

    if method not in available_icp():
        pytest.skip(f"{method} not installed")
    target = np.load(sample_path("kitti_pair", "000094.npy")).astype(np.float64)
    source = np.load(sample_path("kitti_pair", "000095.npy")).astype(np.float64)
    offset = np.array([1e6, 2e6, 50.0])
    near = get_icp(method).align(source, target)
    far = get_icp(method).align(source + offset, target + offset)
    assert far.converged and far.fitness == pytest.approx(near.fitness, abs=1e-6)
    np.testing.assert_allclose(into(far.T_target_source, offset, offset), near.T_target_source, atol=1e-8)
    # only the source far out, init_T bringing it back: each cloud works around its own origin
    T0 = np.eye(4)
    T0[:3, 3] = -offset
    apart = get_icp(method).align(source + offset, target, init_T=T0)
    assert apart.converged and apart.fitness == pytest.approx(near.fitness, abs=1e-3)
    np.testing.assert_allclose(into(apart.T_target_source, None, offset), near.T_target_source, atol=1e-6)


def test_a_cloud_that_is_one_point_repeated_is_refused():
    """1000 copies of one point is a 1-point cloud: vanilla, knn and genz returned 'converged' with an arbitrary pose."""
    rng = np.random.default_rng(0)
    for method in ("vanilla", "knn", "open3d_point_to_plane"):
        with pytest.raises(DataError, match=r"source cloud: all 1000 points are one point \(1, 1, 1\): nothing to register"):
            get_icp(method).align(np.ones((1000, 3)), rng.uniform(-5, 5, (500, 3)))


def test_scipy_tree_settings_for_another_search_are_refused():
    """The report's leaf-size experiment under the default backend (Open3D's search) compared identical runs:
    leafsize was recorded and did nothing."""
    from lidarkit.registration.neighbors import resolved_backend

    if resolved_backend("auto") != "scipy":
        with pytest.raises(ConfigError, match=r"leafsize sets scipy's KD-tree, which nn_backend='auto' \(open3d here\) does not use"):
            get_icp("vanilla", leafsize=1)
    with pytest.raises(ConfigError, match="leafsize and workers set scipy's KD-tree, which nn_backend='open3d' does not use"):
        get_icp("vanilla", nn_backend="open3d", leafsize=1, workers=1)
    with pytest.raises(ConfigError, match="leafsize sets scipy's KD-tree, which exact=true does not use: leave exact out"):
        get_icp("knn", exact=True, leafsize=1)
    assert get_icp("knn", leafsize=1).config.leafsize == 1  # knn searches with scipy by default
    assert get_icp("vanilla", nn_backend="scipy", leafsize=1).config.leafsize == 1


def test_exact_search_over_a_full_scan_pair_is_refused_at_once():
    """knn exact=true on the bundled KITTI pair (3.0e9 point pairs a pass, 41 s each) ran for ten minutes and more."""
    from lidarkit.errors import RegistrationError
    from lidarkit.registration.knn import MAX_BRUTE_FORCE_PAIRS
    from lidarkit.samples import sample_path

    pair = sample_path("kitti_pair")
    src, dst = np.load(pair / "000095.npy")[:, :3], np.load(pair / "000094.npy")[:, :3]
    assert float(len(src)) * len(dst) > MAX_BRUTE_FORCE_PAIRS == 2e8
    with pytest.raises(RegistrationError, match="exact search over .* points is too slow; set voxel_size_m to subsample"):
        get_icp("knn", exact=True).align(src, dst)


@pytest.mark.parametrize("method, params, option", [
    ("vanilla", {"nn_backend": "brute"}, "vanilla nn_backend='brute'"), ("knn", {"nn_backend": "brute"}, "knn nn_backend='brute'"),
    ("knn", {"exact": True}, "knn exact=true"),
])
def test_brute_force_over_a_pair_too_large_is_refused_naming_the_option_given(method, params, option):
    """vanilla's nn_backend='brute' ran for minutes on the bundled KITTI pair where knn refused it, naming exact=true
    though the user set nn_backend. Both refuse beyond MAX_BRUTE_FORCE_PAIRS before the first pass, naming the option;
    so does the brute-force index itself, queried directly."""
    from lidarkit.errors import RegistrationError
    from lidarkit.registration.knn import MAX_BRUTE_FORCE_PAIRS
    from lidarkit.registration.neighbors import NearestNeighbors
    from lidarkit.samples import sample_path

    pair = sample_path("kitti_pair")
    src, dst = np.load(pair / "000095.npy")[:15000, :3], np.load(pair / "000094.npy")[:13400, :3]
    assert MAX_BRUTE_FORCE_PAIRS < float(len(src)) * len(dst) < 1.01 * MAX_BRUTE_FORCE_PAIRS
    with pytest.raises(RegistrationError, match=rf"^{re.escape(option)}: exact search over 15000 x 13400 points is too slow; "
                                                 "set voxel_size_m to subsample"):
        get_icp(method, max_iterations=1, coarse_stride=1, **params).align(src, dst)
    with pytest.raises(RegistrationError, match=r"^nn_backend='brute': exact search over 15000 x 13400 points"):
        NearestNeighbors(dst, backend="brute").query(src)


def test_a_variant_whose_extra_is_missing_names_the_pip_line(monkeypatch):
    """Without small_gicp installed, '-m small_gicp' read as a typo ("unknown ICP method 'small_gicp'; available: ...")."""
    monkeypatch.delitem(registry_module._VARIANTS, "small_gicp", raising=False)
    with pytest.raises(ConfigError, match=r"the 'small_gicp' variant needs the Python package 'small_gicp', not installed here: "
                                          r"pip install 'lidarkit\[gicp\]'"):
        get_icp("small_gicp")


def test_an_unregistered_plugin_is_named_by_its_class():
    """The docs' plugin class used without @register_icp: result.method was '' and the calibration note read
    "none learned for : ..."."""
    from lidarkit.registration import Registration, RegistrationConfig
    from lidarkit.registration.assessment import assess_alignment

    class MyICP(Registration):
        Config = RegistrationConfig

        def _align(self, source_xyz, target_xyz, init_T):
            return assess_alignment(source_xyz, target_xyz, init_T, 1.0).to_result(init_T, iterations=1)

    cloud = np.random.default_rng(0).normal(size=(500, 3)) * 5
    result = MyICP().align(cloud, cloud)
    assert result.method == "MyICP"
    assert result.extra["covariance_calibration"].startswith("none learned for MyICP: the closed form")


def test_a_georeferenced_cloud_held_at_float32_precision_is_said_once(caplog):
    """A UTM cloud stored as float32 (.npy, .pcd) is 0.5 m coarse at a 4.5e6 m northing: small_gicp said converged with a
    1 mm sigma, 4.5 cm off, without a word. The same cloud in float64, or float32 near its origin, says nothing."""
    import logging

    from lidarkit import geometry

    rng = np.random.default_rng(3)
    local = rng.uniform(-20, 20, (2000, 3))
    far = local + np.array([500000.0, 4500000.0, 100.0])
    geometry._SAID_FLOAT32.discard("far cloud")
    with caplog.at_level(logging.WARNING, logger="lidarkit.geometry"):
        geometry.as_points(local.astype(np.float32), "near cloud")
        geometry.as_points(far, "far cloud")
        assert not caplog.records
        for _ in range(2):
            geometry.as_points(far.astype(np.float32), "far cloud")
    said = [r.getMessage() for r in caplog.records]
    assert said == ["far cloud: coordinates up to 4.5e+06 m held at float32 precision (steps of 0.5 m there): store "
                    "georeferenced clouds as float64, or shift them to a local origin before storing them"]


def test_settings_the_chosen_configuration_does_not_read_are_refused():
    """small_gicp's voxel_resolution_m with GICP, kiss's initial_threshold_m beside fixed_threshold_m, and min_fitness /
    covariance with assess=False were accepted and changed nothing (vanilla already refused leafsize off scipy)."""
    for method, params, named in (
        ("small_gicp", {"voxel_resolution_m": 5.0}, "voxel_resolution_m is VGICP's voxel size; registration_type GICP has none"),
        ("kiss", {"fixed_threshold_m": 1.0, "initial_threshold_m": 5.0}, "initial_threshold_m / min_motion_th_m set the adaptive"),
        ("small_gicp", {"assess": False, "min_fitness": 0.99}, "min_fitness set(s) the assessment, which assess=False leaves out"),
        ("kiss", {"assess": False, "covariance": "gauss_newton"}, "covariance set(s) the assessment"),
    ):
        if method not in available_icp():
            continue
        with pytest.raises(ConfigError, match=re.escape(named)):
            get_icp(method, **params)
    if "small_gicp" in available_icp():
        assert get_icp("small_gicp", registration_type="VGICP", voxel_resolution_m=2.0).config.voxel_resolution_m == 2.0
        assert get_icp("small_gicp", assess=False).config.assess is False
    assert get_icp("kiss", fixed_threshold_m=1.0).config.fixed_threshold_m == 1.0


@pytest.mark.parametrize("method, params", [
    *[(name, {}) for name in sorted(BUILTIN | {"pipeline", "genz", "small_gicp"})],
    ("small_gicp", {"registration_type": "VGICP", "voxel_resolution_m": 2.0}),
    ("small_gicp", {"assess": False}),
    ("kiss", {"fixed_threshold_m": 1.0}),
    ("kiss", {"assess": False}),
    ("open3d_gicp", {"assess": False}),
    ("ground_filtered", {"ground_method": "height", "sensor_height_m": 2.0}),
    ("ground_filtered", {"ground_method": "ransac", "ransac_iterations": 50}),
    ("small_gicp", {"covariance": "none"}),
    ("vanilla", {"covariance": "gauss_newton", "calibrated_covariance": True}),
    ("ground_filtered", {"fallback": "with_ground"}),
    ("ground_filtered", {"fallback": "thinned_ground", "fallback_ground_share": 0.2, "fallback_ground_range_m": 20.0}),
    ("open3d_point_to_plane", {"voxel_size_m": None, "normal_radius_m": 0.1}),
])
def test_a_written_config_loads_again(method, params):
    """The config.json of `lidarkit icp --out` (every field, defaults included) was refused when fed back: the checks of
    unread settings counted every field given, so ground_filtered's default ransac / height fields, small_gicp's
    voxel_resolution_m, kiss's initial_threshold_m beside fixed_threshold_m and the assessment's defaults under
    assess=False read as set. Only values other than the default are refused now."""
    if method not in available_icp():
        pytest.skip(f"{method} not installed")
    config = get_icp(method, **params).config
    written = json.loads(json.dumps(config.model_dump(mode="json")))
    assert get_icp(method, **written).config == config


@pytest.mark.parametrize("method", ["pipeline", "kiss", "genz"])
def test_a_stateful_variant_starts_from_a_rigid_pose_only(method):
    """reset(T_world_lidar_initial) took a reflection, a scaled matrix or a projective last row and started from the
    identity without a word (pipeline: IndexError / LinAlgError / ValueError for a 3x3, NaN, text; genz: TypeError, it
    took no pose). Now every stateful variant checks it as align's init_T, and starts from a rigid one."""
    from lidarkit.samples import sample_path

    if method not in available_icp():
        pytest.skip(f"{method} not installed")
    scan = np.load(sample_path("kitti_pair", "000094.npy")).astype(np.float64)
    icp = get_icp(method)
    projective = np.eye(4)
    projective[3] = 1.0
    for T, said in ((np.diag([1.0, 1.0, -1.0, 1.0]), "the 3x3 block is not a rotation (R^T R = I within 0.001, det > 0)"),
                    (np.diag([2.0, 2.0, 2.0, 1.0]), "the 3x3 block is not a rotation"),
                    (projective, "last row must be [0, 0, 0, 1], got [1.0, 1.0, 1.0, 1.0]"),
                    (np.eye(3), "expected a 4x4 matrix, got shape (3, 3)"),
                    (np.full((4, 4), np.nan), "16 of its 16 entries are NaN or infinite"),
                    ("x", "expected a 4x4 matrix of numbers, got str 'x'")):
        with pytest.raises(DataError, match=re.escape(f"T_world_lidar_initial: {said}")):
            icp.reset(T)
    start = make_se3(so3_exp([0.0, 0.0, 0.5]), [10.0, -5.0, 1.0])
    icp.reset(start)
    np.testing.assert_allclose(icp.register_frame(scan), start, atol=1e-9)


@pytest.mark.parametrize("method", ["open3d_point_to_plane", "open3d_gicp"])
def test_a_normal_radius_below_the_voxel_spacing_is_refused(method):
    """normal_radius_m=0.1 beside the default voxel_size_m=0.5 left every downsampled point without a neighbour to
    estimate its normal from: open3d_point_to_plane stayed at the guess (0.48 m off on the bundled pair), converged.
    Such a radius is refused, naming both settings; one at the voxel spacing registers the pair."""
    from lidarkit.samples import sample_path

    with pytest.raises(ConfigError, match=re.escape("normal_radius_m (0.1) is below voxel_size_m (0.5): after downsampling most "
                                                    "points have no neighbour within it to estimate a normal from")):
        get_icp(method, normal_radius_m=0.1)
    assert get_icp(method, normal_radius_m=0.1, voxel_size_m=None).config.normal_radius_m == 0.1  # no downsampling
    source = np.load(sample_path("kitti_pair", "000095.npy")).astype(np.float64)
    target = np.load(sample_path("kitti_pair", "000094.npy")).astype(np.float64)
    result = get_icp(method, normal_radius_m=0.5).align(source, target)
    truth = np.loadtxt(sample_path("kitti_pair", "T_target_source.txt"))
    assert result.converged and pose_error(result.T_target_source, truth)[0] < 0.02


def test_the_calibration_and_the_thinned_ground_settings_are_refused_where_nothing_reads_them():
    """calibrated_covariance=False beside covariance='none' or 'gauss_newton' (calibrated: censi only), and
    ground_filtered's fallback_ground_share / fallback_ground_range_m beside another fallback than 'thinned_ground'
    (the only one that reads them) were accepted and changed nothing. At their defaults they still load (config.json)."""
    for method, params, named in (
        ("vanilla", {"covariance": "none", "calibrated_covariance": False},
         "calibrated_covariance sets the calibration of covariance='censi' (learned on it), not 'none'"),
        ("vanilla", {"covariance": "gauss_newton", "calibrated_covariance": False}, "not 'gauss_newton'"),
        ("ground_filtered", {"fallback": "with_ground", "fallback_ground_share": 0.2},
         "fallback_ground_share set(s) the 'thinned_ground' fallback, not 'with_ground'"),
        ("ground_filtered", {"fallback_ground_range_m": 20.0, "fallback_ground_share": 0.5},
         "fallback_ground_range_m, fallback_ground_share set(s) the 'thinned_ground' fallback, not 'constant_velocity'"),
    ):
        with pytest.raises(ConfigError, match=re.escape(named)):
            get_icp(method, **params)
    assert get_icp("vanilla", covariance="censi", calibrated_covariance=False).config.calibrated_covariance is False


@pytest.mark.parametrize("method", ["pipeline", "kiss", "genz", "ground_filtered"])
def test_per_point_times_say_what_is_wrong_with_them(method):
    """NaN per-point times read "need 54850 finite per-point times, got 54850" (ground_filtered: "54850 finite per-point
    times expected for 54850 points"): the counts agreed and the message did not say that some times were NaN."""
    if method not in available_icp():
        pytest.skip(f"{method} not installed")
    scan = structured_cloud(np.random.default_rng(0), n=2000)
    times = np.linspace(0.0, 0.1, len(scan))
    times[::100] = np.nan
    icp = get_icp(method)
    run = (lambda t: icp.align(scan, scan, source_times_s=t, target_times_s=np.linspace(0.0, 0.1, len(scan)))) \
        if method == "ground_filtered" else (lambda t: icp.register_frame(scan, t))
    where = "source times" if method == "ground_filtered" else "point_times_s"
    assert len(scan) == 1664
    with pytest.raises(DataError, match=re.escape(f"{where}: 17 of the 1664 per-point times are NaN or infinite")):
        run(times)
    with pytest.raises(DataError, match=re.escape(f"{where}: 5 per-point times for 1664 points: one per point is needed")):
        run(times[:5])


def test_a_result_prints_as_one_line_of_its_headline_figures(synthetic_pair):
    """repr(RegistrationResult) printed the whole rmse_history, the 6x6 covariance and the degeneracy (~2000
    characters); now one line whose figures are the result's own."""
    source, target, _ = synthetic_pair
    res = get_icp("vanilla", max_iterations=2, epsilon_m2=0.0, coarse_stride=1).align(source, target)
    t = ", ".join(f"{v:.4g}" for v in res.T_target_source[:3, 3])
    angle = pose_error(res.T_target_source, np.eye(4))[1]
    assert repr(res) == (f"RegistrationResult('vanilla', not converged in 2 iterations, t [{t}] m, rotation {angle:.4g} deg, "
                         f"rmse {res.rmse:.4g} m, fitness {res.fitness:.3g}, {res.n_correspondences} correspondences, "
                         f"{res.runtime_s:.3g} s, reason {res.reason!r})")
    assert len(repr(res)) < 300 and "max_iterations" in repr(res)
    # a backend that reports no iteration count (Open3D, kiss, genz) read "converged in 0 iterations"
    o3d = get_icp("open3d_point_to_plane").align(source, target)
    assert repr(o3d).startswith("RegistrationResult('open3d_point_to_plane', converged (iterations not reported), t [")


def test_the_stateful_calls_of_a_stateless_variant_are_one_line_config_errors(capsys):
    """get_icp('vanilla').register_frame(points) raised a bare NotImplementedError "vanilla is stateless", which said
    neither what to call instead nor, through a script, in one line."""
    vanilla = get_icp("vanilla")
    for call in (lambda: vanilla.register_frame(np.random.default_rng(0).random((100, 3))), vanilla.reset):
        with pytest.raises(ConfigError) as err:
            call()
        assert err.value.source == "vanilla"
    assert str(err.value) == ("vanilla: reset() needs a stateful variant (one with a map of its own); vanilla is stateless: "
                              "align a pair of scans with align(), or run odometry with lidarkit.odometry.run()")


def test_voxel_downsample_refuses_what_it_cannot_average():
    """The documented voxel_downsample let a NaN point through as an all-NaN centroid (with numpy's cast warning), an
    infinite one as an infinite centroid, and met (3, N) points or a size given as text with numpy's or Python's own
    errors: each is one line naming the argument now."""
    from lidarkit.errors import ConfigError, DataError
    from lidarkit.registration.preprocess import voxel_downsample

    points = np.random.default_rng(0).normal(size=(100, 3))
    assert np.isfinite(voxel_downsample(points, 0.5)).all()
    for bad in (np.r_[points, [[np.nan, 0, 0]]], np.r_[points, [[np.inf, 0, 0]]]):
        with pytest.raises(DataError, match=r"^points: 1 point\(s\) with NaN or infinite coordinates$"):
            voxel_downsample(bad, 0.5)
    for bad in (points.T, np.c_[points, points[:, 0]]):
        with pytest.raises(DataError, match=r"^points: expected an \(N, 3\) point array, got shape"):
            voxel_downsample(bad, 0.5)
    for size in ("0.5", None, float("inf"), True, 0):
        with pytest.raises(ConfigError, match=r"^voxel_size_m: voxel size must be a finite number > 0"):
            voxel_downsample(points, size)


def test_voxel_downsample_says_when_finite_points_are_too_large_to_average():
    """The finite-coordinates check summed the points: two points at 1e308 overflowed it (numpy's warning) and were
    refused as "0 point(s) with NaN or infinite coordinates"; their centroid would overflow as well."""
    import warnings

    from lidarkit.errors import DataError
    from lidarkit.registration.preprocess import voxel_downsample

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(DataError, match=r"^points: coordinates too large to average \(their sum overflows float64\)$"):
            voxel_downsample(np.full((2, 3), 1e308), 1e300)
