"""Acceptance gate (min_fitness / min_correspondences), initial-guess validation and strict-JSON results."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from conftest import shared_path
from registration_helpers import structured_cloud

from lidarkit.errors import DataError
from lidarkit.geometry import make_se3, so3_exp, transform_points
from lidarkit.registration import available_icp, get_icp
from lidarkit.registration.base import DEFAULT_MIN_FITNESS, Degeneracy, RegistrationResult


@pytest.fixture(scope="module")
def lidar_pair():
    from lidarkit.io.pointfile import read_point_file

    folder = shared_path("lidar_pairs")
    return read_point_file(folder / "251371071.pcd").points_xyz, read_point_file(folder / "251370668.pcd").points_xyz


@pytest.mark.parametrize("name", ["open3d_point_to_point", "kiss"])
def test_start_30m_off_is_not_converged(lidar_pair, name):
    """Started 30 m off, these variants land in a wrong minimum with fitness 0.005-0.2: must not count as converged."""
    source, target = lidar_pair
    init = np.eye(4)
    init[0, 3] = 30.0
    icp = get_icp(name)
    bad = icp.align(source, target, init_T=init)
    assert not bad.converged and bad.fitness < DEFAULT_MIN_FITNESS
    assert "min_fitness" in bad.reason, bad.reason
    good = icp.align(source, target)
    assert good.converged and good.fitness > 0.8, (good.fitness, good.reason)


def test_every_variant_has_the_gate_in_its_config():
    for name in available_icp():
        fields = get_icp(name).config.model_dump()
        assert fields["min_fitness"] == DEFAULT_MIN_FITNESS and fields["min_correspondences"] >= 3, name


@pytest.mark.parametrize("name", ["vanilla", "ground_filtered", "knn", "open3d_point_to_point", "open3d_gicp", "small_gicp", "kiss"])
def test_min_fitness_and_min_correspondences_are_applied(name):
    if name not in available_icp():
        pytest.skip(f"{name} not installed")
    rng = np.random.default_rng(3)
    target = structured_cloud(rng, n=12000)
    target = target[target[:, 2] > -1.5] if name == "ground_filtered" else target
    T = make_se3(so3_exp([0, 0, 0.02]), [0.3, 0.1, 0.0])
    outliers = rng.uniform(-20, 20, (len(target) // 8, 3)) + [0.0, 0.0, 60.0]  # never matched (within kiss range): fitness <= 0.89
    source = np.vstack([transform_points(np.linalg.inv(T), target), outliers])
    # the vanilla family uses every nearest neighbour by default: cap the distance so the outliers stay unmatched
    params = {"max_correspondence_distance_m": 1.0} if name in ("vanilla", "ground_filtered", "knn") else {}
    assert get_icp(name, **params).align(source, target, init_T=T).converged
    picky = get_icp(name, min_fitness=0.95, **params).align(source, target, init_T=T)
    assert not picky.converged and "min_fitness" in picky.reason, picky.reason
    greedy = get_icp(name, min_correspondences=10**7, **params).align(source, target, init_T=T)
    assert not greedy.converged and "correspondences" in greedy.reason, greedy.reason


def test_open3d_zero_fitness_is_a_failure():
    rng = np.random.default_rng(4)
    target = structured_cloud(rng, n=3000)
    far = target + [1000.0, 0.0, 0.0]
    icp = get_icp("open3d_point_to_point", min_fitness=0.0, min_correspondences=3)
    res = icp.align(far, target)  # flagged before Open3D runs: the boxes are 1 km apart
    assert not res.converged and res.fitness == 0.0 and "no initial overlap" in res.reason
    from lidarkit.registration.base import accept

    res = accept(icp._align(far, target, np.eye(4)), icp.config)  # Open3D's own zero-fitness result is a failure too
    assert not res.converged and res.fitness == 0.0 and "fitness" in res.reason


# ---------------------------------------------------------------- initial guess


@pytest.mark.parametrize(
    "bad",
    [
        2 * np.eye(4),
        np.diag([2.0, 2.0, 2.0, 1.0]),
        np.vstack([np.eye(4)[:3], [0.1, 0.0, 0.0, 1.0]]),
        np.diag([1.0, 1.0, -1.0, 1.0]),  # reflection
    ],
)
def test_non_rigid_initial_guess_is_refused(bad):
    rng = np.random.default_rng(5)
    cloud = structured_cloud(rng, n=600)
    with pytest.raises(DataError, match="init_T"):
        get_icp("vanilla").align(cloud, cloud, init_T=bad)


def test_rounded_initial_guess_is_still_accepted():
    rng = np.random.default_rng(6)
    cloud = structured_cloud(rng, n=600)
    T = make_se3(so3_exp([0.1, -0.2, 0.3]), [1, 2, 3])
    T[:3, :3] = np.round(T[:3, :3], 4)
    res = get_icp("vanilla", max_iterations=1).align(cloud, cloud, init_T=T)
    R = res.T_target_source[:3, :3]
    assert np.abs(R.T @ R - np.eye(3)).max() < 1e-12


def test_cli_init_file_with_scaled_matrix_is_refused(tmp_path, capsys):
    from lidarkit.cli import main
    from lidarkit.samples import sample_path

    init = tmp_path / "init.txt"
    np.savetxt(init, np.diag([2.0, 2.0, 2.0, 1.0]))
    with pytest.raises(SystemExit) as exc:
        main(["icp", str(sample_path("kitti_pair", "000095.npy")), str(sample_path("kitti_pair", "000094.npy")), "--init", str(init)])
    assert exc.value.code == 1 and "not a rotation" in capsys.readouterr().err


# ---------------------------------------------------------------- strict JSON


def test_to_dict_maps_non_finite_to_none():
    res = RegistrationResult(
        T_target_source=np.eye(4), converged=False, iterations=0, rmse_history=(), n_correspondences=0,
        runtime_s=0.0, fitness=float("nan"), degeneracy=Degeneracy.unknown(), reason="none",
        extra={"x": float("inf"), "arr": np.array([1.0, np.nan])},
    )
    d = res.to_dict()
    assert d["rmse_m"] is None and d["fitness"] is None and d["degeneracy"]["condition_number"] is None
    assert d["extra"] == {"x": None, "arr": [1.0, None]}
    text = json.dumps(d, allow_nan=False)
    assert "NaN" not in text and "Infinity" not in text
    assert not any(isinstance(v, float) and not math.isfinite(v) for v in d["degeneracy"]["eigenvalues"])


def test_cli_result_json_is_strict_when_registration_fails(tmp_path, capsys):
    from lidarkit.cli import main

    rng = np.random.default_rng(9)
    target = structured_cloud(rng, n=2000)
    np.save(tmp_path / "t.npy", target)
    np.save(tmp_path / "s.npy", target + [500.0, 0.0, 0.0])
    out = tmp_path / "out"
    try:
        main(["icp", str(tmp_path / "s.npy"), str(tmp_path / "t.npy"), "-m", "open3d_point_to_point", "--out", str(out)])
    except SystemExit as exc:
        assert not exc.code, capsys.readouterr().err
    text = (out / "result.json").read_text()
    result = json.loads(text, parse_constant=lambda c: pytest.fail(f"non-standard JSON constant {c}"))
    assert result["converged"] is False and result["rmse_m"] is None


# ---------------------------------------------------------------- staged ICP bookkeeping


def test_staged_icp_assesses_only_the_final_stage(monkeypatch):
    from lidarkit.registration import vanilla

    calls = []
    real = vanilla.assess_alignment
    monkeypatch.setattr(vanilla, "assess_alignment", lambda *a, **k: calls.append(len(a[0])) or real(*a, **k))
    rng = np.random.default_rng(11)
    target = structured_cloud(rng, n=12000)
    T = make_se3(so3_exp([0, 0, 0.02]), [0.3, 0.1, 0.0])
    res = get_icp("vanilla", coarse_stride=8).align(transform_points(np.linalg.inv(T), target), target)
    assert res.extra["coarse_iterations"] > 0 and res.converged
    assert calls == [len(target)]  # once, on the full-resolution stage
    # one RMSE at the initial guess and one after each iteration of either stage, as with one stage
    assert len(res.rmse_history) == res.iterations + 1 and res.rmse_history[0] > res.rmse_history[-1]
