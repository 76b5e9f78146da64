"""Registration covariance: convention, positive semi-definiteness, degenerate directions named, propagation."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from lidarkit.errors import ConfigError
from lidarkit.geometry import se3_exp, se3_inverse, se3_log, transform_points
from lidarkit.odometry.covariance import propagate, relative_errors
from lidarkit.registration import available_icp, get_icp
from lidarkit.registration.covariance import (
    CALIBRATION, CALIBRATION_WITHOUT_STEP, AxisCalibration, CovarianceModel, adjoint, apply_calibration, calibrate, covariance_and_step, effective_observations,
    left_jacobians, nees, principal_turn, registration_covariance, safe_inverse,
)
from lidarkit.registration.degeneracy import describe_direction, matched_constraints, surface_constraints
from lidarkit.sim.scan_pairs import ScanPairs
from registration_helpers import kitti_pair as _kitti_pair


@pytest.fixture(scope="module")
def kitti_pair():
    from conftest import shared_path

    return _kitti_pair(shared_path, 94, 95)


def _is_psd(S: np.ndarray) -> bool:
    return S.shape == (6, 6) and np.all(np.isfinite(S)) and np.allclose(S, S.T, atol=1e-12 * max(1.0, np.abs(S).max())) and (
        np.linalg.eigvalsh(0.5 * (S + S.T)).min() >= -1e-9 * max(1.0, np.abs(S).max()))


def test_left_jacobian_matches_finite_differences_of_the_left_perturbation():
    rng = np.random.default_rng(0)
    p = rng.normal(size=(5, 3)) * 4
    J = left_jacobians(p)
    eps = 1e-6
    for j in range(6):
        xi = np.zeros(6)
        xi[j] = eps
        moved = transform_points(se3_exp(xi), p)
        np.testing.assert_allclose((moved - p) / eps, J[:, :, j], atol=1e-4)


def test_adjoint_moves_a_twist_between_frames():
    rng = np.random.default_rng(1)
    T = se3_exp(rng.normal(size=6))
    xi = rng.normal(size=6) * 1e-3
    np.testing.assert_allclose(se3_exp(adjoint(T) @ xi), T @ se3_exp(xi) @ se3_inverse(T), atol=1e-9)


def _plane_pair(rng, n=3000, noise=0.01):
    """A noisy floor patch (z = 0) seen twice: x, y and yaw are unconstrained."""
    pts = np.column_stack([rng.uniform(-10, 10, n), rng.uniform(-10, 10, n), np.zeros(n)])
    return pts + np.column_stack([np.zeros((n, 2)), rng.normal(0, noise, n)]), pts


def test_plane_leaves_translation_in_the_plane_and_yaw_unconstrained():
    rng = np.random.default_rng(2)
    src, dst = _plane_pair(rng)
    M = surface_constraints(np.stack([dst[np.argsort(np.linalg.norm(dst[:, :2] - q[:2], axis=1))[:20]] for q in dst[:200]]))
    cov = registration_covariance(src[:200], dst[:200], M, np.eye(4))
    sigma = np.sqrt(np.diag(cov))
    # z, roll and pitch are constrained by the plane; x, y and yaw are not (huge variance, still finite)
    assert sigma[0] > 1e3 * sigma[2] and sigma[1] > 1e3 * sigma[2] and sigma[5] > 1e3 * sigma[3]
    assert np.all(np.isfinite(cov)) and _is_psd(cov)
    # z is known to about the noise over sqrt(number of independent samples)
    assert 0.01 / np.sqrt(200) / 3 < sigma[2] < 0.01 * 3


def test_describe_direction_names_axes():
    assert describe_direction([1, 0, 0, 0, 0, 0]) == "translation along x"
    assert describe_direction([0, 0, 0, 0, 0, -1]) == "rotation about z (yaw)"
    assert describe_direction([0.7, 0.7, 0, 0, 0, 0]).startswith("translation along (0.71, 0.71")


@pytest.mark.parametrize("method", ["censi", "gauss_newton"])
def test_residual_variance_recovers_the_noise_of_a_plane(method):
    """On a plane with noise only across it, the variance along the normal is the noise over the sample size."""
    rng = np.random.default_rng(5)
    src, dst = _plane_pair(rng, n=4000, noise=0.02)
    M = np.broadcast_to(np.diag([0.0, 0.0, 1.0]), (len(src), 3, 3))
    T = np.eye(4)
    T[:3, 3] = [0.0, 0.0, 50.0]  # source sensor far above: its rays hit the plane head-on, as the noise model assumes
    cov = registration_covariance(src + [0, 0, 0], dst, M, T, CovarianceModel(method=method, correlation_voxel_m=None))
    expected = 0.02**2 / len(src)
    assert 0.5 * expected < cov[2, 2] < 2.0 * expected, (cov[2, 2], expected)


def test_corridor_axis_is_the_least_known_translation():
    """A featureless tunnel along x: the covariance along the axis is far larger than across it."""
    pairs = ScanPairs("corridor", seed=0, n_frames=4, n_beams=32, n_azimuths=1024)
    for i in range(2):
        pair = pairs.draw(i)
        res = get_icp("small_gicp").align(pair.source_xyz, pair.target_xyz, init_T=pair.init_T)
        cov = res.covariance
        assert cov[0, 0] >= 10 * cov[1, 1], np.diag(cov)
        assert np.argmax(np.diag(cov)[:3]) == 0


@pytest.mark.parametrize("variant", ["kiss", "open3d_point_to_plane", "small_gicp"])
def test_corridor_weakest_direction_is_named_the_corridor_axis(variant):
    """The weakest eigen-direction of the normal matrix is the translation along the tunnel (x) in every draw: the
    wall-floor corners constrain only their best plane's normal, and roll is measured at its own lever arm (the
    tunnel's half-width), not at the points' distance along the tunnel."""
    pairs = ScanPairs("corridor", seed=2, n_frames=6, n_beams=32, n_azimuths=1024)
    icp = get_icp(variant)
    for i in range(4):
        pair = pairs.draw(i)
        deg = icp.align(pair.source_xyz, pair.target_xyz, init_T=pair.init_T).degeneracy
        assert deg.weakest_name == "translation along x", (i, deg.eigenvalues, deg.weakest_direction)
        assert abs(deg.weakest_direction[0]) > 0.95


def test_corner_constrains_only_its_best_plane_normal():
    """Points on a wall-floor edge along x (an L in y-z): no constraint along x, the edge's direction."""
    rng = np.random.default_rng(4)
    x = rng.uniform(-1, 1, 40)
    t = rng.uniform(0, 1, 40)
    on_floor = rng.random(40) < 0.5
    pts = np.column_stack([x, np.where(on_floor, t, 0.0), np.where(on_floor, 0.0, t)])
    M = surface_constraints(pts[None])[0]
    assert abs(M[0, 0]) < 1e-3 and np.linalg.matrix_rank(M, tol=1e-6) == 1  # the normal of the L's best plane only


def test_every_variant_returns_a_psd_covariance_and_its_information(kitti_pair):
    src, dst, T_gt = kitti_pair
    for name in ("vanilla", "small_gicp", "kiss", "open3d_point_to_plane"):
        res = get_icp(name).align(src, dst, init_T=T_gt)
        assert _is_psd(res.covariance), name
        np.testing.assert_allclose(res.information @ res.covariance, np.eye(6), atol=1e-6)
        # the true error (init = ground truth, so the error is the registration's own) is within a few sigma
        err = se3_log(T_gt @ se3_inverse(res.T_target_source))
        assert nees(err, res.covariance) < 200, name
        assert res.to_dict()["covariance"] is not None


def test_no_covariance_when_asked_for_none(kitti_pair):
    src, dst, T_gt = kitti_pair
    assert get_icp("small_gicp", covariance="none").align(src, dst, init_T=T_gt).covariance is None
    with pytest.raises(ConfigError):
        get_icp("small_gicp", covariance="magic")
    with pytest.raises(ConfigError):
        CovarianceModel(method="magic")


clouds = st.integers(min_value=0, max_value=10_000).flatmap(lambda seed: st.sampled_from(["random", "plane", "line", "point", "two"]).map(lambda kind: (seed, kind)))


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(clouds)
def test_covariance_is_always_symmetric_psd(case):
    seed, kind = case
    rng = np.random.default_rng(seed)
    n = int(rng.integers(3, 300))
    if kind == "random":
        pts = rng.normal(size=(n, 3)) * rng.uniform(0.01, 50)
    elif kind == "plane":
        pts = np.column_stack([rng.uniform(-5, 5, (n, 2)), np.zeros(n)])
    elif kind == "line":
        pts = np.outer(rng.uniform(-5, 5, n), rng.normal(size=3))
    elif kind == "point":
        pts = np.tile(rng.normal(size=3), (n, 1))
    else:
        pts = np.vstack([np.zeros((n // 2 + 1, 3)), np.ones((n - n // 2 - 1 + 2, 3))])[:n]
    dst = pts + rng.normal(0, rng.uniform(0, 0.1), pts.shape)
    T = se3_exp(rng.normal(size=6) * 0.1)
    src = transform_points(se3_inverse(T), dst) + rng.normal(0, 0.01, pts.shape)
    aligned = transform_points(T, src)
    _, pick_M, thickness = matched_constraints(aligned, dst, np.arange(len(dst)), k=min(10, len(dst)), return_thickness=True)
    assert np.all(np.isfinite(thickness)) and np.all(thickness >= 0)
    for method in ("censi", "gauss_newton"):
        cov = registration_covariance(aligned, dst, pick_M, T, CovarianceModel(method=method),
                                      n_effective=effective_observations(aligned, 1.0), surface_variance=thickness)
        assert _is_psd(cov), (kind, method)
        assert _is_psd(safe_inverse(cov))
        assert _is_psd(calibrate(cov, "small_gicp"))


def test_propagated_covariance_grows_along_the_path():
    rng = np.random.default_rng(3)
    step = se3_exp(np.array([1.0, 0, 0, 0, 0, 0.02]))
    poses = np.stack([np.linalg.matrix_power(step, k) for k in range(30)])
    rel = np.broadcast_to(np.diag([1e-4, 1e-4, 1e-4, 1e-6, 1e-6, 1e-6]), (30, 6, 6)).copy()
    rel[0] = np.nan
    cov = propagate(poses, rel)
    trace = np.trace(cov[:, :3, :3], axis1=1, axis2=2)
    assert trace[0] == 0 and np.all(np.diff(trace) > 0)
    # heading uncertainty turns into lateral uncertainty: growth faster than linear in the number of steps
    assert trace[-1] > 29 * 3e-4 * 1.5
    # a frame missing one that did not fall back (a stateful variant's, unassessed) reuses the previous covariance
    none_fell_back = np.zeros(30, dtype=bool)
    rel[10] = np.nan
    np.testing.assert_allclose(propagate(poses, rel, fell_back=none_fell_back), cov)
    # missing from frame 1 (every pose after was NaN): the first frame's that has one
    rel[1:3] = np.nan
    np.testing.assert_allclose(propagate(poses, rel, fell_back=none_fell_back), cov)
    assert np.isnan(propagate(poses, np.full_like(rel, np.nan))[1:]).all()  # none at all: NaN, as the runner says
    # relative errors in the same convention recover a known perturbation
    noisy = poses.copy()
    for k in range(1, 30):
        noisy[k] = noisy[k - 1] @ se3_inverse(poses[k - 1]) @ poses[k]
    assert np.abs(relative_errors(poses, noisy)).max() < 1e-9
    del rng


def test_odometry_writes_pose_covariance_and_min_eigenvalue(tmp_path):
    from lidarkit.odometry import run

    result = run("sim:street?frames=6&seed=4&n_beams=16&n_azimuths=512&range_noise_std_m=0.02", "small_gicp", out_dir=tmp_path / "run")
    cov = result.pose_covariance
    assert cov.shape == (6, 6, 6) and all(_is_psd(c) for c in cov)
    trace = np.trace(cov[:, :3, :3], axis1=1, axis2=2)
    assert np.all(np.diff(trace) > 0)
    metrics = result.metrics["pose_covariance"]
    assert metrics["frames_with_covariance"] == 5 and metrics["relative_nees_mean"] > 0
    rows = np.loadtxt(tmp_path / "run" / "pose_covariance.txt")
    np.testing.assert_allclose(rows.reshape(-1, 6, 6), cov, rtol=1e-8, atol=1e-15)
    header = (tmp_path / "run" / "timing.csv").read_text().splitlines()[0].split(",")
    assert "min_eigenvalue" in header


def test_odometry_widens_the_frame_covariance_of_distorted_sweeps_registered_as_they_are(monkeypatch):
    """A scan-to-scan variant without deskew on sweeps with per-point times: each frame covariance gains
    ``diag((d * |t|)^2)`` (``DISTORTION_SIGMA``, ``|t|`` the frame's translation); without per-point times (a snapshot)
    nothing is added, and the poses are the same either way."""
    from lidarkit.odometry import run
    from lidarkit.registration import covariance as covariance_module
    from lidarkit.sim.lidar import SimulatedLidarSequence

    sim = dict(scene="street", n_frames=5, seed=4, n_beams=16, n_azimuths=512, range_noise_std_m=0.02, accel_time_s=0.0)
    d = np.array([0.01, 0.002, 0.003, 0.0005, 0.001, 0.0002])
    monkeypatch.setitem(covariance_module.DISTORTION_SIGMA, "small_gicp", tuple(d))
    distorted = SimulatedLidarSequence(**sim)
    widened = run(distorted, "small_gicp", pose_covariance=True)
    monkeypatch.delitem(covariance_module.DISTORTION_SIGMA, "small_gicp")
    plain = run(distorted, "small_gicp", pose_covariance=True)
    np.testing.assert_allclose(widened.trajectory.poses_se3, plain.trajectory.poses_se3, atol=1e-12)
    motion_m = np.linalg.norm(plain.trajectory.relative_motions()[:, :3, 3], axis=1)
    added = widened.covariances[0][1:] - plain.covariances[0][1:]
    np.testing.assert_allclose(added, np.einsum("ni,ij->nij", (d[None, :] * motion_m[:, None]) ** 2, np.eye(6)), rtol=1e-9, atol=1e-15)
    assert motion_m.min() > 0.5  # the drive is at speed: the floor is not negligible
    assert widened.metrics["pose_covariance"]["distortion_floor"].startswith("4 frames: motion-distorted sweeps")
    assert "distortion_floor" not in plain.metrics["pose_covariance"]
    monkeypatch.setitem(covariance_module.DISTORTION_SIGMA, "small_gicp", tuple(d))
    snapshot = SimulatedLidarSequence(**sim, motion_distortion=False, point_times=False)
    with_entry = run(snapshot, "small_gicp", pose_covariance=True)
    monkeypatch.delitem(covariance_module.DISTORTION_SIGMA, "small_gicp")
    np.testing.assert_allclose(with_entry.covariances[0][1:], run(snapshot, "small_gicp", pose_covariance=True).covariances[0][1:], rtol=1e-9)


def test_distortion_floor_only_for_variants_that_register_sweeps_as_they_are_or_deskew_at_constant_velocity():
    from lidarkit.odometry.settings import deskew_requested
    from lidarkit.registration import available_icp, get_icp
    from lidarkit.registration.covariance import DISTORTION_SIGMA

    assert {"open3d_point_to_plane", "small_gicp", "ground_filtered"} <= set(DISTORTION_SIGMA)
    for name, sigma in DISTORTION_SIGMA.items():
        if name not in available_icp():
            continue
        icp = get_icp(name)
        assert len(sigma) == 6 and min(sigma) >= 0.0 and max(sigma[:3]) < 0.5  # m per m of motion
        assert not getattr(icp, "stateful", False)
        if name == "ground_filtered":  # its constant-velocity deskew leaves the changes of motion within the sweep
            assert getattr(icp, "deskew_instant", None) == "end"
        else:
            assert deskew_requested(icp) is None and not getattr(icp, "accepts_point_times", False)


def test_a_constant_velocity_deskew_gets_its_floor_too():
    """ground_filtered deskews distorted sweeps at constant velocity; what that leaves (roll and pitch above all) made
    its 1-frame NEES 268-804 on distorted streets (benchmarks/results/covariance/distortion_ground_filtered): its frame
    covariances get DISTORTION_SIGMA["ground_filtered"] added, and the run says which frames and why."""
    from lidarkit.odometry import run
    from lidarkit.registration.covariance import DISTORTION_SIGMA
    from lidarkit.sim.lidar import SimulatedLidarSequence

    sim = SimulatedLidarSequence(scene="street", n_frames=5, seed=4, n_beams=16, n_azimuths=512, range_noise_std_m=0.02, accel_time_s=0.0)
    result = run(sim, "ground_filtered", pose_covariance=True)
    floor = result.metrics["pose_covariance"]["distortion_floor"]
    assert floor.startswith("4 frames: motion-distorted sweeps registered with a constant-velocity deskew") and "ground_filtered" in floor
    motion_m = np.linalg.norm(result.trajectory.relative_motions()[:, :3, 3], axis=1)
    d = np.asarray(DISTORTION_SIGMA["ground_filtered"])
    variances = np.einsum("nii->ni", result.covariances[0][1:])
    assert (variances >= (d[None, :] * motion_m[:, None]) ** 2 * (1 - 1e-9)).all()


def test_surface_thickness_adds_the_map_noise():
    """A target surface known only to 5 cm across it: the height of the plane is known to 0.05^2 / n, not to the
    (here negligible) range noise over n; without the term only the range noise remains."""
    rng = np.random.default_rng(7)
    src, dst = _plane_pair(rng, n=2000, noise=0.0)
    M = np.broadcast_to(np.diag([0.0, 0.0, 1.0]), (len(src), 3, 3))
    T = np.eye(4)
    T[:3, 3] = [0.0, 0.0, 50.0]
    thickness = np.full(len(src), 0.05**2)
    for surface_noise, expected in ((True, 0.05**2 / len(src)), (False, 1e-6**2 / len(src))):
        model = CovarianceModel(range_noise_m=1e-6, correlation_voxel_m=None, surface_noise=surface_noise)
        cov = registration_covariance(src, dst, M, T, model, surface_variance=thickness)
        assert 0.9 * expected < cov[2, 2] < 1.1 * expected, (surface_noise, cov[2, 2], expected)


def _pairs_at(T_est: np.ndarray, pair, max_distance_m: float = 1.0):
    """Matched pairs (aligned source, nearest target point) and their surface projectors at the pose ``T_est``."""
    from scipy.spatial import cKDTree

    aligned = transform_points(T_est, pair.source_xyz)
    d, idx = cKDTree(pair.target_xyz).query(aligned)
    keep = d <= max_distance_m
    pick, M = matched_constraints(aligned[keep], pair.target_xyz, idx[keep], max_points=5000)
    return aligned[keep][pick], pair.target_xyz[idx[keep][pick]], M


@pytest.mark.parametrize("seed", [3, 5])
def test_surface_step_follows_a_pose_error(seed):
    """Moving the pose off by a known small error moves the point-to-surface step (no ground truth used) by that
    error: within 30 % of its size, direction within 20 degrees. At the true pose the step is the surfaces' own
    preference, which can be several cm along the street (its weak axis: ring sampling, few walls across it)."""
    pair = ScanPairs("street", seed=seed, n_frames=3).draw(0)
    xi = np.array([0.06, -0.04, 0.02, 0.002, -0.0015, 0.004])
    steps = []
    for T in (se3_exp(-xi) @ pair.T_target_source, pair.T_target_source):
        p, q, M = _pairs_at(T, pair)
        steps.append(covariance_and_step(p, q, M, pair.T_target_source)[1])
    response = steps[0] - steps[1]
    assert np.linalg.norm(response - xi) < 0.3 * np.linalg.norm(xi), (response, xi)
    assert response @ xi / np.linalg.norm(response) / np.linalg.norm(xi) > np.cos(np.radians(20))
    assert np.abs(steps[1][1:3]).max() < 0.01 and np.abs(steps[1][3:]).max() < 1e-3, steps[1]


def test_surface_step_ignores_far_pairs_and_unconstrained_directions():
    """Pairs beyond STEP_PAIR_DISTANCE_M do not steer the step (the covariance still uses them); on one plane the step
    has no component along the plane (nothing there to step to), and too few pairs give NaN."""
    from lidarkit.registration.covariance import STEP_PAIR_DISTANCE_M

    rng = np.random.default_rng(4)
    q = np.column_stack([rng.uniform(-10, 10, 400), rng.uniform(-10, 10, 400), np.zeros(400)])
    M = np.broadcast_to(np.diag([0.0, 0.0, 1.0]), (400, 3, 3)).copy()
    p = q + [0.3, -0.2, 0.05]  # off by 5 cm across the plane, 36 cm along it
    _, step = covariance_and_step(p, q, M, np.eye(4))
    assert step[2] == pytest.approx(-0.05, abs=1e-9)
    np.testing.assert_allclose(step[[0, 1, 5]], 0.0, atol=1e-9)  # along the plane and its yaw: unconstrained
    far = p.copy()
    far[:40, 2] += 2.0 * STEP_PAIR_DISTANCE_M  # wrong matches 2 m off: they change the covariance, not the step
    cov_far, step_far = covariance_and_step(far, q, M, np.eye(4))
    assert step_far[2] == pytest.approx(-0.05, abs=1e-9)
    assert not np.allclose(cov_far, covariance_and_step(p, q, M, np.eye(4))[0])
    assert np.isnan(covariance_and_step(p[:5], q[:5], M[:5], np.eye(4))[1]).all()


def test_step_term_adds_the_predicted_error_as_a_rank_one_term():
    rng = np.random.default_rng(10)
    A = rng.normal(size=(6, 6))
    cov = A @ A.T * 1e-4
    factors, sigmas, gains = (0.5, 2.0, 1.0, 3.0, 0.1, 1.0), (0.01, 0.0, 0.02, 0.0, 0.001, 0.0), (1.5, 1.4, 0.0, 0.8, 0.0, 1.3)
    step = np.array([0.2, -0.05, 0.3, 0.001, 0.002, -0.004])
    base = apply_calibration(cov, AxisCalibration(factors, sigmas, 1.3))
    out = apply_calibration(cov, AxisCalibration(factors, sigmas, 1.3, None, gains), step)
    bias = np.asarray(gains) * step
    np.testing.assert_allclose(out, base + 1.3 * np.outer(bias, bias), rtol=1e-9, atol=1e-15)
    assert _is_psd(out)
    # the error the step predicts is inside the bound: its NEES drops from far outside to below 1 / 1.3
    assert nees(bias, base) > 100 and nees(bias, out) < 1 / 1.3 + 1e-9
    # no step (or a NaN one): the entry without its step term
    np.testing.assert_allclose(apply_calibration(cov, AxisCalibration(factors, sigmas, 1.3, None, gains)), base, rtol=1e-12)
    np.testing.assert_allclose(apply_calibration(cov, AxisCalibration(factors, sigmas, 1.3, None, gains), np.full(6, np.nan)), base,
                               rtol=1e-12)


def test_every_variant_reports_its_surface_step(kitti_pair):
    """Each result carries the step of its own final correspondences (finite, in the covariance's convention), and the
    calibrated covariance includes it where the variant's entry has step gains."""
    from lidarkit.registration import available_icp

    src, dst, T_gt = kitti_pair
    for name in ("vanilla", "open3d_point_to_point", "kiss", "small_gicp"):
        res = get_icp(name).align(src, dst, init_T=T_gt)
        assert res.surface_step.shape == (6,) and np.all(np.isfinite(res.surface_step)), name
        assert np.linalg.norm(res.surface_step[:3]) < 0.5, name  # a correction, not a jump
        assert res.to_dict()["surface_step"] == pytest.approx(res.surface_step.tolist())
        raw = get_icp(name, calibrated_covariance=False).align(src, dst, init_T=T_gt)
        np.testing.assert_allclose(res.covariance, calibrate(raw.covariance, name, raw.surface_step), rtol=1e-9, atol=1e-18)
    assert any(CALIBRATION[n].step_gains is not None for n in available_icp())


def test_calibrate_scales_each_axis_variance(monkeypatch):
    from lidarkit.registration import covariance as covariance_module

    rng = np.random.default_rng(8)
    A = rng.normal(size=(6, 6))
    cov = A @ A.T
    sigmas = np.array([0.1, 0.0, 0.0, 0.0, 0.01, 0.0])
    monkeypatch.setitem(covariance_module.CALIBRATION, "test_variant", AxisCalibration((1.0, 4.0, 9.0, 0.25, 1.0, 16.0), tuple(sigmas)))
    out = calibrate(cov, "test_variant")
    np.testing.assert_allclose(np.diag(out), np.diag(cov) * [1, 4, 9, 0.25, 1, 16] + sigmas**2, rtol=1e-9)
    # off-diagonal terms keep the closed form's correlations (scaled): a weak direction off the axes stays weak
    np.testing.assert_allclose(out[0, 1], cov[0, 1] * 2.0, rtol=1e-9)
    assert _is_psd(out)
    np.testing.assert_array_equal(calibrate(cov, "no_such_variant"), cov)


def test_coverage_scalar_scales_the_whole_calibrated_matrix():
    rng = np.random.default_rng(9)
    A = rng.normal(size=(6, 6))
    cov = A @ A.T
    factors, sigmas = (0.5, 2.0, 1.0, 3.0, 0.1, 1.0), (0.01, 0.0, 0.02, 0.0, 0.001, 0.0)
    base = apply_calibration(cov, AxisCalibration(factors, sigmas))
    out = apply_calibration(cov, AxisCalibration(factors, sigmas, coverage=1.7))
    np.testing.assert_allclose(out, 1.7 * base, rtol=1e-9, atol=1e-15)
    # NEES scales by 1 / c: the share inside the bound is what the scalar was chosen for
    xi = rng.normal(size=6)
    assert nees(xi, out) == pytest.approx(nees(xi, base) / 1.7, rel=1e-9)


def test_variance_beyond_the_training_range_is_not_shrunk():
    """A factor < 1 measured where an axis was constrained applies only up to the training range v: the excess (a
    corridor's axis) keeps its closed-form size, so the axis stays >= 10x the constrained ones after calibration."""
    entry = AxisCalibration((0.01, 0.01, 0.01, 1.0, 1.0, 1.0), (0.004, 0.004, 0.001, 0.0, 0.0, 0.0), 1.0, (1e-3, 1e-3, 1e-3, 1.0, 1.0, 1.0))
    cov = np.diag([0.01, 3e-4, 3e-4, 1e-6, 1e-6, 1e-6])  # x far beyond the training range, y and z within it
    out = apply_calibration(cov, entry)
    assert out[0, 0] == pytest.approx(0.01 * 1e-3 + (0.01 - 1e-3) + 0.004**2, rel=1e-9)
    assert out[1, 1] == pytest.approx(0.01 * 3e-4 + 0.004**2, rel=1e-9)
    assert out[0, 0] >= 10 * out[1, 1]
    no_guard = apply_calibration(cov, AxisCalibration(entry.factors, entry.sigmas, 1.0, None))
    assert no_guard[0, 0] < 10 * no_guard[1, 1]  # without it the floor of y swamps the ratio
    # a factor > 1 still applies to the excess (never shrunk, never less than the closed form times f)
    big = apply_calibration(cov, AxisCalibration((4.0,) * 6, (0.0,) * 6, 1.0, (1e-3,) * 6))
    np.testing.assert_allclose(np.diag(big), 4.0 * np.diag(cov), rtol=1e-9)


def _turn_about_z(degrees: float) -> np.ndarray:
    """``blockdiag(R, R)``: how a left perturbation of the target frame changes when the frame is turned about z."""
    a = np.radians(degrees)
    R = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
    P = np.zeros((6, 6))
    P[:3, :3] = P[3:, 3:] = R
    return P


def test_principal_turn_puts_the_weakest_horizontal_direction_on_x():
    cov = np.diag([4e-2, 1e-4, 1e-5, 1e-6, 2e-6, 3e-6])
    np.testing.assert_allclose(principal_turn(cov), np.eye(6), atol=1e-12)  # already along x
    for degrees in (30.0, 45.0, 90.0, 135.0):
        P = _turn_about_z(degrees)
        turned = P @ cov @ P.T
        back = principal_turn(turned) @ turned @ principal_turn(turned).T
        np.testing.assert_allclose(back, cov, atol=1e-12)
    np.testing.assert_allclose(principal_turn(np.diag([1e-3, 1e-3, 1, 1, 1, 1])), np.eye(6), atol=1e-12)  # isotropic: the frame's axes


@pytest.mark.parametrize("table", ["with step", "without step"])
def test_every_calibration_is_the_same_however_the_scene_is_turned(table):
    """The shipped calibrations are learned in the principal axes: turning the scene in the target frame turns the
    calibrated covariance with it (per-axis factors in the frame's axes gave a corridor turned by 45 degrees a 16x
    larger sigma across it)."""
    entries = CALIBRATION if table == "with step" else CALIBRATION_WITHOUT_STEP
    rng = np.random.default_rng(12)
    A = rng.normal(size=(6, 6)) * np.array([3e-2, 1e-2, 5e-3, 1e-3, 1e-3, 2e-3])
    cov = A @ A.T
    step = rng.normal(size=6) * np.array([0.05, 0.02, 0.01, 1e-3, 1e-3, 2e-3])
    for name, entry in entries.items():
        assert entry.axes == "principal", name
        for degrees in (30.0, 45.0, 90.0):
            P = _turn_about_z(degrees)
            np.testing.assert_allclose(apply_calibration(P @ cov @ P.T, entry, P @ step), P @ apply_calibration(cov, entry, step) @ P.T,
                                       rtol=1e-9, atol=1e-15, err_msg=f"{name} {degrees}")


def test_target_axes_calibration_applies_the_factors_to_the_frame_axes():
    """An entry in the target frame's axes (the default of :class:`AxisCalibration`) scales the frame's x and y, an
    entry in the principal axes the covariance's own weak and strong horizontal directions."""
    cov = np.diag([1e-2, 1e-4, 1e-4, 1e-6, 1e-6, 1e-6])
    P = _turn_about_z(90.0)  # the weak direction on y
    factors = (9.0, 1.0, 1.0, 1.0, 1.0, 1.0)
    target = apply_calibration(P @ cov @ P.T, AxisCalibration(factors, (0.0,) * 6))
    principal = apply_calibration(P @ cov @ P.T, AxisCalibration(factors, (0.0,) * 6, axes="principal"))
    assert target[1, 1] == pytest.approx(1e-2) and target[0, 0] == pytest.approx(9e-4)
    assert principal[1, 1] == pytest.approx(9e-2) and principal[0, 0] == pytest.approx(1e-4)
    with pytest.raises(ConfigError, match="axes"):
        AxisCalibration(factors, (0.0,) * 6, axes="sensor")


def test_calibrated_sigma_across_a_corridor_does_not_depend_on_its_heading():
    """The same corridor pair with both scans turned by 45 degrees about the sensor: small_gicp's calibrated sigma
    across the corridor stays within 1.5x of the unturned pair's (it was 12x with per-axis factors in the frame's axes)."""
    pairs = ScanPairs("corridor", seed=1, n_frames=4, n_beams=32, n_azimuths=1024)
    icp = get_icp("small_gicp")
    T = np.eye(4)
    a = np.radians(45.0)
    T[:3, :3] = [[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]]
    for i in range(2):
        pair = pairs.draw(i)
        cov = icp.align(pair.source_xyz, pair.target_xyz, init_T=pair.init_T).covariance
        turned = icp.align(transform_points(T, pair.source_xyz), transform_points(T, pair.target_xyz),
                           init_T=T @ pair.init_T @ se3_inverse(T)).covariance
        across, across_turned = np.array([0.0, 1.0, 0.0]), T[:3, :3] @ np.array([0.0, 1.0, 0.0])
        sigma, sigma_turned = np.sqrt(across @ cov[:3, :3] @ across), np.sqrt(across_turned @ turned[:3, :3] @ across_turned)
        assert 1 / 1.5 < sigma_turned / sigma < 1.5, (i, sigma, sigma_turned)


@pytest.mark.parametrize("variant", ["open3d_gicp", "small_gicp"])
def test_calibrated_corridor_axis_is_ten_times_the_across_axis(variant):
    """The default (calibrated) covariance of a corridor pair: along the tunnel >= 10x across it."""
    pairs = ScanPairs("corridor", seed=1, n_frames=4, n_beams=32, n_azimuths=1024)
    for i in range(2):
        pair = pairs.draw(i)
        cov = get_icp(variant).align(pair.source_xyz, pair.target_xyz, init_T=pair.init_T).covariance
        assert cov[0, 0] >= 10 * cov[1, 1], (i, np.diag(cov))


def test_step_spread_widens_every_axis_with_the_size_of_the_step():
    """What the step leaves grows with the step: ``h_j^2 |step_t|^2`` on the diagonal, on top of the rank-one term,
    zero for a zero step, and only with a step term (an entry without gains ignores it)."""
    cov = np.diag([1e-4, 2e-4, 1e-5, 1e-6, 2e-6, 1e-6])
    factors, sigmas, gains = (1.0,) * 6, (0.0,) * 6, (1.5, 1.4, 0.0, 0.0, 0.0, 1.3)
    spread = (0.1, 0.2, 0.05, 0.01, 0.0, 0.003)
    step = np.array([0.3, -0.4, 0.0, 0.001, 0.002, -0.004])  # |step_t| = 0.5 m
    with_gains = apply_calibration(cov, AxisCalibration(factors, sigmas, 1.3, None, gains), step)
    out = apply_calibration(cov, AxisCalibration(factors, sigmas, 1.3, None, gains, spread), step)
    np.testing.assert_allclose(out - with_gains, 1.3 * np.diag(np.square(spread) * 0.25), rtol=1e-9, atol=1e-12)
    assert _is_psd(out)
    np.testing.assert_allclose(apply_calibration(cov, AxisCalibration(factors, sigmas, 1.3, None, gains, spread), np.zeros(6)),
                               apply_calibration(cov, AxisCalibration(factors, sigmas, 1.3)), rtol=1e-12)
    np.testing.assert_allclose(apply_calibration(cov, AxisCalibration(factors, sigmas, 1.3, None, None, spread), step),
                               apply_calibration(cov, AxisCalibration(factors, sigmas, 1.3)), rtol=1e-12)


def test_fit_learns_the_step_spread_from_errors_that_grow_with_the_step(tmp_path):
    """The calibration fit recovers a known spread: errors drawn as ``g step + N(0, Sigma) + N(0, h^2 |step_t|^2)``."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from covariance_fit import factor_floor

    rng = np.random.default_rng(3)
    n, h_true = 4000, np.array([0.3, 0.1, 0.05, 0.0, 0.0, 0.0])
    steps = np.zeros((n, 6))
    steps[:, :3] = rng.normal(scale=0.2, size=(n, 3))
    sd = np.array([0.01, 0.01, 0.005, 1e-3, 1e-3, 1e-3])
    covs = np.repeat(np.diag(sd**2)[None], n, axis=0) * rng.uniform(0.5, 2.0, size=(n, 1, 1))
    norms = np.linalg.norm(steps[:, :3], axis=1)
    errors = 1.2 * steps + rng.normal(size=(n, 6)) * np.sqrt(np.einsum("nii->ni", covs)) \
        + rng.normal(size=(n, 6)) * h_true * norms[:, None]
    entry = factor_floor([{"errors": errors[: n // 2], "covs": covs[: n // 2], "steps": steps[: n // 2]},
                          {"errors": errors[n // 2:], "covs": covs[n // 2:], "steps": steps[n // 2:]}])
    np.testing.assert_allclose(entry.step_gains[:3], 1.2, atol=0.05)
    np.testing.assert_allclose(entry.step_spread[:3], h_true[:3], atol=0.03)
    np.testing.assert_allclose(entry.step_spread[3:], 0.0, atol=2e-3)
    np.testing.assert_allclose(entry.factors[3:], 1.0, atol=0.15)  # the axes without spread keep their factor


def test_every_variant_has_a_calibration():
    from lidarkit.registration import available_icp

    for name in available_icp():
        entry = CALIBRATION[name]
        assert len(entry.factors) == len(entry.sigmas) == len(entry.trained_variance) == 6
        assert 0.5 < entry.coverage < 2.0
        if entry.step_gains is not None:  # and the entry for a covariance without its step
            assert len(entry.step_gains) == 6 and CALIBRATION_WITHOUT_STEP[name].step_gains is None


def test_a_covariance_without_its_step_gets_the_entry_learned_without_it():
    """The step-trained factors and floors are smaller (the step term carries part of the error): applied without
    the step they would under-state it, so ``calibrate`` without a step uses ``CALIBRATION_WITHOUT_STEP``."""
    cov = np.diag([1e-4, 1e-4, 1e-5, 1e-6, 1e-6, 1e-6])
    step = np.array([0.05, -0.02, 0.01, 0.001, 0.0005, -0.001])
    for name in ("vanilla", "kiss"):
        np.testing.assert_allclose(calibrate(cov, name), apply_calibration(cov, CALIBRATION_WITHOUT_STEP[name]), rtol=1e-12)
        np.testing.assert_allclose(calibrate(cov, name, np.full(6, np.nan)), calibrate(cov, name), rtol=1e-12)
        np.testing.assert_allclose(calibrate(cov, name, step), apply_calibration(cov, CALIBRATION[name], step), rtol=1e-12)
    # a variant without step gains has one entry either way
    np.testing.assert_allclose(calibrate(cov, "open3d_point_to_plane"), calibrate(cov, "open3d_point_to_plane", step), rtol=1e-12)


@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(min_value=0, max_value=10_000), st.sampled_from(["random", "plane", "line"]))
def test_every_variant_returns_a_psd_calibrated_covariance(seed, kind):
    """Every registered variant's own ``align`` (calibration applied) on random and degenerate clouds: the covariance it
    returns, if any, is symmetric positive semi-definite and finite."""
    from lidarkit.errors import LidarKitError
    from lidarkit.registration import available_icp

    rng = np.random.default_rng(seed)
    n = 400
    if kind == "random":
        dst = rng.normal(size=(n, 3)) * 5
    elif kind == "plane":
        dst = np.column_stack([rng.uniform(-10, 10, (n, 2)), np.zeros(n)])
    else:
        dst = np.outer(rng.uniform(-10, 10, n), [1.0, 0.3, 0.0])
    dst = dst + rng.normal(0, 0.01, dst.shape)
    T = se3_exp(np.r_[rng.normal(0, 0.1, 3), rng.normal(0, 0.01, 3)])
    src = transform_points(se3_inverse(T), dst)
    for name in available_icp():
        try:
            res = get_icp(name).align(src, dst, init_T=np.eye(4))
        except LidarKitError:
            continue  # a clear refusal (too few points for a variant's own preprocessing) is fine here
        if res.covariance is not None:
            assert _is_psd(res.covariance), (name, kind)


def _calibration_study():
    """``benchmarks/covariance_calibration.py`` as a module."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "benchmarks" / "covariance_calibration.py"
    spec = importlib.util.spec_from_file_location("covariance_calibration", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    return bench


def test_calibration_study_scores_only_converged_draws(tmp_path):
    """The study caches each draw's ``converged`` flag with its error, raw covariance, step and reference, and scores
    only the draws the variant reports converged: a flagged draw leaves every per-draw array together (the same draws
    drop out of each) and is counted apart."""
    bench = _calibration_study()
    run = bench.collect("street", 0, 3, "small_gicp", tmp_path, log=lambda msg: None)
    assert run["converged"].dtype == bool and run["converged"].all() and len(run["converged"]) == len(run["errors"]) == 3
    assert int(run["failed"]) == 0 and run["weakest_without_covariance"].shape == (0,)  # names of draws without a covariance
    cached = np.load(next(tmp_path.glob("street_s0_small_gicp_3.npz")))
    np.testing.assert_array_equal(cached["converged"], run["converged"])
    flagged = {**run, "converged": np.array([True, False, True])}
    kept = bench.converged_only(flagged)
    assert int(kept["flagged"]) == 1
    for key in ("errors", "covs", "steps", "refs", "weakest", "index"):
        np.testing.assert_array_equal(kept[key], run[key][[0, 2]])
    row = bench.row(kept, CALIBRATION["small_gicp"], CALIBRATION_WITHOUT_STEP["small_gicp"], np.ones(6))
    assert row["flagged"] == 1 and row["calibrated"]["n"] == 2 and row["raw"]["n"] == 2


def test_calibration_pose_features_measure_the_correction_and_the_residuals():
    """The per-pair features of the calibration study (no ground truth used): the correction is exactly the injected
    guess perturbation, the residual RMS is smaller at the true pose than at the perturbed guess, and at the true pose
    the point-to-surface residual sigma is at least the simulated 2 cm range noise (the sampling of the surface adds to
    it, so it is not equal) and below its value at the guess."""
    bench = _calibration_study()
    pair = ScanPairs("street", seed=0, n_frames=3, n_beams=16, n_azimuths=512).draw(0)
    at_truth = bench.pose_features(pair.source_xyz, pair.target_xyz, pair.T_target_source, pair.init_T, 0.02)
    at_guess = bench.pose_features(pair.source_xyz, pair.target_xyz, pair.init_T, pair.init_T, 0.02)
    injected = se3_log(pair.T_target_source @ se3_inverse(pair.init_T))
    assert at_truth["correction_t"] == pytest.approx(np.linalg.norm(injected[:3]), rel=1e-9)
    assert at_truth["correction_r"] == pytest.approx(np.linalg.norm(injected[3:]), rel=1e-9)
    assert at_guess["correction_t"] == pytest.approx(0.0, abs=1e-12)
    assert at_truth["plane_rms"] < at_guess["plane_rms"]
    assert 1.0 <= at_truth["sigma_ratio"] < at_guess["sigma_ratio"]
    assert 0 < at_truth["n_eff"] <= at_truth["n_matched"] and 0 < at_truth["fit1"] <= 1
    assert set(at_truth) == set(bench.POSE_FEATURES)


def test_default_pipeline_is_calibrated_like_kiss():
    """The default pipeline composition registers a pair exactly as kiss does (same pose, same raw covariance), so its
    calibration entry is kiss's and the calibrated covariances agree to rounding."""
    pair = ScanPairs("street", seed=1, n_frames=3, n_beams=16, n_azimuths=512).draw(0)
    kiss = get_icp("kiss").align(pair.source_xyz, pair.target_xyz, init_T=pair.init_T)
    pipe = get_icp("pipeline").align(pair.source_xyz, pair.target_xyz, init_T=pair.init_T)
    np.testing.assert_allclose(pipe.T_target_source, kiss.T_target_source, atol=1e-9)
    np.testing.assert_allclose(pipe.covariance, kiss.covariance, rtol=1e-6, atol=1e-15)


@pytest.mark.parametrize("method", ["vanilla", "small_gicp"])
def test_the_covariance_of_a_georeferenced_pair_is_the_same_covariance_moved_to_its_frame(method, kitti_pair):
    """Both clouds shifted by c (UTM-like): the pose moves as C T C^-1 and the covariance as Ad(C) Sigma Ad(C)^T. The
    closed form at 1e6 m lost the rotation to rounding (an 8x too small yaw sigma, mm translation sigmas where the
    lever arm makes them km); it is now computed around a local origin and moved."""
    from lidarkit.registration.covariance import adjoint

    source, target = kitti_pair[0][::10], kitti_pair[1][::10]
    for offset in (np.array([5000.0, 5000.0, 0.0]), np.array([500000.0, 4500000.0, 100.0])):
        C = np.eye(4)
        C[:3, 3] = offset
        at_origin = get_icp(method, calibrated_covariance=False).align(source, target)
        far = get_icp(method, calibrated_covariance=False).align(source + offset, target + offset)
        expected = adjoint(C) @ at_origin.covariance @ adjoint(C).T
        ratio = np.sqrt(np.diag(far.covariance) / np.diag(expected))
        np.testing.assert_allclose(ratio, 1.0, atol=0.05)  # (was 0.06 at 7 km and 0.13 in yaw at 4.5e6 m)
        assert np.linalg.norm(np.asarray(far.extra["covariance_origin_m"]) - offset) < 20.0  # near the target's sensor
        assert np.linalg.eigvalsh(0.5 * (far.covariance + far.covariance.T)).min() >= -1e-9 * np.abs(far.covariance).max()
    assert "covariance_origin_m" not in at_origin.extra


@pytest.mark.parametrize("method", ["vanilla", "small_gicp", "open3d_point_to_plane"])
def test_the_calibrated_covariance_moves_with_the_frame(method):
    """Both clouds of a street pair moved by 300 m, 900 m or to UTM coordinates: the calibrated covariance moved back
    with the adjoint is the one at the sensor frame (sigmas within 1.3x). Calibrated around the frame's origin (or a
    georeferenced cloud's rounded mean, hundreds of metres from the sensor), the per-axis factors mixed the rotation
    into the translation: small_gicp's 1.5 mm became 0.2-3.6 m, vanilla's variances up to 4.7e5x."""
    from lidarkit.registration.covariance import adjoint

    pair = ScanPairs("street", seed=9, n_frames=201, n_beams=32, n_azimuths=1024).draw(3)
    at_origin = get_icp(method).align(pair.source_xyz, pair.target_xyz, init_T=pair.init_T)
    for offset in (np.array([300.0, 0.0, 0.0]), np.array([0.0, 900.0, 0.0]), np.array([500432.7, 4500217.3, 35.2])):
        C = np.eye(4)
        C[:3, 3] = offset
        far = get_icp(method).align(pair.source_xyz + offset, pair.target_xyz + offset, init_T=C @ pair.init_T @ se3_inverse(C))
        back = adjoint(se3_inverse(C)) @ far.covariance @ adjoint(se3_inverse(C)).T
        ratio = np.sqrt(np.diag(back) / np.diag(at_origin.covariance))
        assert np.all((ratio > 1 / 1.3) & (ratio < 1.3)), (offset, ratio)


@pytest.mark.parametrize("method", ["small_gicp", "open3d_gicp"])
def test_the_calibrated_covariance_of_a_moved_kitti_pair_is_taken_around_its_raw_scan_sensor(method, kitti_pair):
    """The sensor proxy was the median of the clouds the backend assessed, voxelized: on KITTI's scans 6-12 m from the
    sensor (the dense returns around it thin out), and the covariance moved back was 2.2x (small_gicp) and 3.3x
    (Open3D's GICP) off in z. It is the median of the scans as given, within 2 m of the sensor."""
    from lidarkit.registration.covariance import adjoint

    source, target, _ = kitti_pair
    at_origin = get_icp(method).align(source, target)
    for offset in (np.array([300.0, 0.0, 0.0]), np.array([500432.7, 4500217.3, 35.2])):
        C = np.eye(4)
        C[:3, 3] = offset
        far = get_icp(method).align(source + offset, target + offset)
        assert np.linalg.norm(np.asarray(far.extra["covariance_origin_m"]) - offset) < 2.0
        back = adjoint(se3_inverse(C)) @ far.covariance @ adjoint(se3_inverse(C)).T
        ratio = np.sqrt(np.diag(back) / np.diag(at_origin.covariance))
        assert np.all((ratio > 1 / 1.3) & (ratio < 1.3)), (offset, ratio)


def test_a_per_frame_bias_is_told_from_noise():
    """The mean frame error chained along a straight path rebuilds the end error whatever the errors are (white noise
    gave end_error_bias_share 1.0); per_frame_bias_z says whether the mean is a bias at all: small for noise, large
    for a bias of a third of the noise."""
    from lidarkit.odometry.covariance import covariance_metrics

    rng = np.random.default_rng(1)
    n = 300
    step = np.eye(4)
    step[0, 3] = 1.0
    ref = np.stack([np.linalg.matrix_power(step, k) for k in range(n)])
    cov = np.tile(np.diag([4e-4] * 3 + [1e-8] * 3), (n, 1, 1))
    cov[0] = 0.0
    for bias_m, expect_bias in ((0.0, False), (0.007, True)):
        est = [np.eye(4)]
        for _ in range(1, n):
            est.append(est[-1] @ step @ se3_exp(np.r_[rng.normal(bias_m, 0.02, 3), rng.normal(0.0, 1e-4, 3)]))
        m = covariance_metrics(np.stack(est), cov, np.cumsum(cov, axis=0), ref)
        assert (m["per_frame_bias_z"] > 3) == expect_bias, (bias_m, m["per_frame_bias_z"])
        if not expect_bias:
            assert m["end_error_bias_share"] > 0.9  # the share alone would have called the noise a bias


def test_the_degeneracy_summary_names_the_same_direction_at_any_heading():
    """A corridor pair turned about z by 0, 30, 45 and 90 degrees: the weakest direction, turned back, is the corridor's
    axis every time, with the same flag (lever arms about the frame's x and y named roll, degenerate, at 30-45)."""
    from lidarkit.geometry import make_se3, so3_exp

    pair = ScanPairs("corridor", seed=3, n_frames=201, n_beams=32, n_azimuths=1024).draw(0)
    flags, ratios = set(), []
    for degrees in (0.0, 30.0, 45.0, 90.0):
        G = make_se3(so3_exp([0.0, 0.0, np.radians(degrees)]), np.zeros(3))
        res = get_icp("open3d_point_to_plane").align(transform_points(G, pair.source_xyz), transform_points(G, pair.target_xyz),
                                                    init_T=G @ pair.init_T @ se3_inverse(G))
        weakest = np.asarray(res.degeneracy.weakest_direction)
        back = np.concatenate([G[:3, :3].T @ weakest[:3], G[:3, :3].T @ weakest[3:]])
        assert abs(back[0]) > 0.95, (degrees, np.round(back, 2))  # translation along the corridor
        flags.add(res.degeneracy.degenerate)
        ratios.append(res.degeneracy.ratio)
    assert len(flags) == 1 and max(ratios) / min(ratios) < 2.5


def test_the_principal_calibration_is_continuous_where_the_horizontal_block_turns_isotropic():
    """A horizontal block whose two variances differ by 2 % either way: the calibrated covariance changes by a few
    percent, not by swapping the factors of the two axes (a 3-7x jump in sigma)."""
    rng = np.random.default_rng(3)
    A = rng.normal(size=(6, 6)) * np.array([1e-2, 1e-2, 5e-3, 1e-3, 1e-3, 2e-3])
    base = A @ A.T
    base[:2, :2] = np.diag([1e-4, 1e-4])
    base[:2, 2:] = base[2:, :2].T * 0.0
    step = rng.normal(size=6) * 1e-3
    for name in ("open3d_gicp", "small_gicp", "vanilla"):
        out = []
        for ratio in (0.98, 1.02):
            cov = base.copy()
            cov[0, 0] = 1e-4 * ratio
            out.append(apply_calibration(cov, CALIBRATION[name], step))
        change = np.sqrt(np.diag(out[1]) / np.diag(out[0]))
        assert np.all(np.abs(change - 1) < 0.1), (name, np.round(change, 3))


def test_a_subclass_of_a_variant_inherits_its_calibration_and_says_so(kitti_pair):
    """A plugin deriving from vanilla got the raw closed form under its own name (relative NEES ~470 on a street);
    it now gets vanilla's calibration, and a variant with none learned is told so in the result."""
    from lidarkit.registration import Registration, RegistrationConfig
    from lidarkit.registration.assessment import assess_alignment
    from lidarkit.registration.vanilla import VanillaICP

    class MyVanilla(VanillaICP):
        name = "my_vanilla"

    class MyICP(Registration):
        name = "my_icp"
        Config = RegistrationConfig

        def _align(self, source_xyz, target_xyz, init_T):
            return assess_alignment(source_xyz, target_xyz, init_T, 1.0).to_result(init_T, iterations=1)

    source, target, _ = kitti_pair
    own = get_icp("vanilla", voxel_size_m=0.5).align(source, target)
    derived = MyVanilla(voxel_size_m=0.5).align(source, target)
    np.testing.assert_allclose(derived.covariance, own.covariance, rtol=1e-12)
    assert own.extra["covariance_calibration"] == "vanilla"
    assert derived.extra["covariance_calibration"] == "vanilla's (inherited by my_vanilla)"
    raw = get_icp("vanilla", voxel_size_m=0.5, calibrated_covariance=False).align(source, target)
    assert not np.allclose(raw.covariance, own.covariance) and "covariance_calibration" not in raw.extra
    mine = MyICP().align(source, target, own.T_target_source)
    assert mine.covariance is not None and mine.extra["covariance_calibration"].startswith("none learned for my_icp")


@pytest.mark.parametrize("method", ["vanilla", "small_gicp"])
def test_nees_and_the_covariance_about_the_local_origin_are_exact_at_utm_coordinates(method):
    """At UTM coordinates the covariance about the frame's origin spans more than float64 resolves (eigenvalues 1e-18
    to 3e8): its inverse, and the NEES from it, were wrong. The result keeps the covariance as calibrated about its
    local origin and scores an error there: the same NEES as the pair in its sensor frame."""
    from lidarkit.registration.covariance import nees

    pair = ScanPairs("street", seed=9, n_frames=201, n_beams=32, n_azimuths=1024).draw(8)
    at_origin = get_icp(method).align(pair.source_xyz, pair.target_xyz, init_T=pair.init_T)
    reference = at_origin.nees(pair.T_target_source)
    assert reference == pytest.approx(nees(se3_log(pair.T_target_source @ se3_inverse(at_origin.T_target_source)), at_origin.covariance))
    offset = np.array([500432.7, 4500217.3, 35.2])
    C = np.eye(4)
    C[:3, 3] = offset
    far = get_icp(method).align(pair.source_xyz + offset, pair.target_xyz + offset, init_T=C @ pair.init_T @ se3_inverse(C))
    T_true_far = C @ pair.T_target_source @ se3_inverse(C)
    origin = np.asarray(far.extra["covariance_origin_m"])
    local = far.covariance_about(origin)
    assert np.array_equal(local, np.asarray(far.extra["covariance_about_origin"]))
    np.testing.assert_allclose(far.covariance_about(origin + 1e-9), local, rtol=0.5)  # moved back: roughly, not exactly
    local_ratio = far.nees(T_true_far) / reference  # (a calibrated covariance moves within 1.3x: NEES within ~1.7x)
    frame_ratio = nees(se3_log(T_true_far @ se3_inverse(far.T_target_source)), far.covariance) / reference
    assert 0.6 < local_ratio < 1.7 and frame_ratio < 0.5  # the frame-origin route: 0.26x (vanilla), 0.39x (small_gicp)
    # information is the inverse about that origin, moved: its quadratic form on the error in the frame's convention is
    # the NEES (the floored inverse of the stored matrix, conditioned ~1e25, kept ~1e-14 of it in some directions)
    xi = se3_log(T_true_far @ se3_inverse(far.T_target_source))
    assert float(xi @ far.information @ xi) == pytest.approx(far.nees(T_true_far), rel=1e-3)
    xi = se3_log(pair.T_target_source @ se3_inverse(at_origin.T_target_source))
    assert float(xi @ at_origin.information @ xi) == pytest.approx(reference, rel=1e-6)


def test_nees_and_covariance_about_refuse_what_is_not_a_pose_or_a_point(rng):
    """A 3x3 raised numpy's matmul error, a NaN pose "SVD did not converge", a scaled pose gave a number, and a NaN
    origin a NaN matrix without a word."""
    from lidarkit.errors import ConfigError

    pts = rng.uniform(-10, 10, (400, 3))
    result = get_icp("vanilla").align(pts + [0.1, 0.0, 0.0], pts)
    assert result.covariance is not None and np.isfinite(result.nees(np.eye(4)))
    scaled = np.diag([2.0, 2.0, 2.0, 1.0])
    for bad in (np.eye(3), np.full((4, 4), np.nan), scaled):
        with pytest.raises(ConfigError, match="T_target_source_true must be a finite 4x4 rigid transform"):
            result.nees(bad)
    for bad in ([np.nan, 0, 0], [1, 2], "abc"):
        with pytest.raises(ConfigError, match="origin_m must be 3 finite numbers"):
            result.covariance_about(bad)


@pytest.fixture(scope="module")
def street_pair():
    """Frames 5 -> 4 of a simulated street (seed 1, a held-out seed): ``(source, target, T_target_source true)``."""
    from lidarkit.sim.lidar import SimulatedLidarSequence

    sim = SimulatedLidarSequence(scene="street", seed=1, n_frames=6, n_beams=32, n_azimuths=1024, range_noise_std_m=0.02,
                                 motion_distortion=False, point_times=False)
    poses = sim.ground_truth.poses_se3
    return sim.read_scan(5).points_xyz, sim.read_scan(4).points_xyz, se3_inverse(poses[4]) @ poses[5]


def test_a_calibration_applies_only_to_the_configuration_it_was_learned_at(street_pair):
    """small_gicp's ICP and PLANE_ICP took GICP's calibration (the variant was picked by class name): ICP 4.8 cm off
    with a 1.3 mm sigma, NEES 1716; a pipeline composition other than kiss's took kiss's entry. They get the closed
    form now, and the note names the setting."""
    if "small_gicp" not in available_icp():
        pytest.skip("small_gicp not installed")
    source, target, T_true = street_pair
    gicp, icp = (get_icp("small_gicp", registration_type=kind) for kind in ("GICP", "ICP"))
    assert (gicp.calibration_variant(), icp.calibration_variant()) == ("small_gicp", None)
    learned, point_to_point = gicp.align(source, target), icp.align(source, target)
    assert learned.extra["covariance_calibration"] == "small_gicp" and learned.nees(T_true) == pytest.approx(4.7, abs=0.1)
    assert point_to_point.extra["covariance_calibration"] == (
        "none learned for small_gicp (registration_type=ICP): the closed form as computed (typically over-confident)")
    raw = get_icp("small_gicp", registration_type="ICP", calibrated_covariance=False).align(source, target)
    np.testing.assert_allclose(point_to_point.covariance, raw.covariance, rtol=1e-9, atol=1e-18)
    assert point_to_point.nees(T_true) == pytest.approx(15.0, abs=0.5)  # (1716 under GICP's entry)

    kiss_like, vanilla_seq = (get_icp("pipeline", preset=p) for p in ("kiss_like", "vanilla_seq"))
    assert (kiss_like.calibration_variant(), vanilla_seq.calibration_variant()) == ("pipeline", None)
    note = vanilla_seq.align(source, target).extra["covariance_calibration"]
    assert note.startswith("none learned for pipeline (kernel=none, threshold={'name': 'fixed', 'max_distance_m': None}, ")
    # kiss's own composition written as specs, or with another range crop or voxel size, is the one it was learned at
    # (a dict spec of the default threshold read "none learned": sigmas 0.028 m where the calibration gives 0.061 m)
    for params in ({"threshold": {"name": "adaptive"}}, {"map": {"name": "voxel_hash"}}, {"max_range_m": 50.0},
                   {"voxel_size_m": 0.5}):
        assert get_icp("pipeline", **params).calibration_variant() == "pipeline", params
    assert get_icp("pipeline", kernel="none").calibration_variant() is None


def test_kiss_composition_keeps_kiss_entry_whatever_kiss_own_parameters(street_pair):
    """A parameter kiss takes as its own (the adaptive threshold's start, points per voxel, map threads, neighbour
    tracking, deskew off) leaves the pipeline kiss's composition: it gave kiss's pose bit for bit yet read "none
    learned" with the closed form (28 mm x sigma where kiss's entry gives 60 mm). Another composition still does not
    take the entry."""
    source, target, _ = street_pair
    kiss = get_icp("kiss", initial_threshold_m=3.0).align(source, target)
    pipe = get_icp("pipeline", preset="kiss_like", threshold={"name": "adaptive", "initial_threshold_m": 3.0}).align(source, target)
    np.testing.assert_allclose(pipe.T_target_source, kiss.T_target_source, atol=1e-9)
    assert pipe.extra["covariance_calibration"] == "pipeline"
    np.testing.assert_allclose(pipe.covariance, kiss.covariance, rtol=1e-6, atol=1e-15)
    for params in ({"map": {"name": "voxel_hash", "max_points_per_voxel": 30}},
                   {"map": {"name": "voxel_hash", "track_neighbors": False}}, {"map": {"name": "voxel_hash", "workers": 1}},
                   {"deskew": {"name": "constant_velocity", "deskew": False}}):
        assert get_icp("pipeline", preset="kiss_like", **params).calibration_variant() == "pipeline", params
    other = get_icp("pipeline", map={"name": "voxel_hash", "search": "kdtree"}, map_voxel_factor=1.0)
    assert other.calibration_variant() is None
    assert other._calibration()[1] == ["map={'name': 'voxel_hash', 'search': 'kdtree'}", "map_voxel_factor=1.0"]


def test_a_plane_based_entry_applies_only_near_the_gate_and_voxel_it_was_learned_at(street_pair):
    """small_gicp's entry (learned at a 1 m gate and 0.25 m voxels) applied at any: at a 3 m gate mean NEES 16.5 with 47 %
    inside the 95 % bound (its closed form 4.0 / 97 %), at 0.1 m voxels 12.0 / 63 %, and the note named the entry. Beyond
    the band measured around the learned value the closed form is returned and the note names the setting; the default,
    and a value within the band, keep the entry."""
    if "small_gicp" not in available_icp():
        pytest.skip("small_gicp not installed")
    source, target, T_true = street_pair
    wide = get_icp("small_gicp", max_correspondence_distance_m=3.0)
    assert wide.calibration_variant() is None
    result = wide.align(source, target)
    assert result.extra["covariance_calibration"] == (
        "none learned for small_gicp (max_correspondence_distance_m=3.0): the closed form as computed (typically over-confident)")
    raw = get_icp("small_gicp", max_correspondence_distance_m=3.0, calibrated_covariance=False).align(source, target)
    np.testing.assert_allclose(result.covariance, raw.covariance, rtol=1e-9, atol=1e-18)
    default = get_icp("small_gicp").align(source, target)
    assert default.extra["covariance_calibration"] == "small_gicp" and default.nees(T_true) == pytest.approx(4.7, abs=0.1)
    learned_at = {(name, key, value): get_icp(name, **{key: value}).calibration_variant() for name, key, value in (
        ("small_gicp", "downsampling_resolution_m", 0.1), ("small_gicp", "downsampling_resolution_m", 0.3),
        ("small_gicp", "max_correspondence_distance_m", 0.75), ("open3d_point_to_plane", "max_correspondence_distance_m", 3.0),
        ("open3d_point_to_plane", "voxel_size_m", 0.75), ("open3d_gicp", "max_correspondence_distance_m", 3.0),
        ("open3d_gicp", "voxel_size_m", None), ("open3d_gicp", "max_correspondence_distance_m", 1.5))}
    assert learned_at == {
        ("small_gicp", "downsampling_resolution_m", 0.1): None, ("small_gicp", "downsampling_resolution_m", 0.3): "small_gicp",
        ("small_gicp", "max_correspondence_distance_m", 0.75): "small_gicp",
        ("open3d_point_to_plane", "max_correspondence_distance_m", 3.0): None,
        ("open3d_point_to_plane", "voxel_size_m", 0.75): "open3d_point_to_plane",
        ("open3d_gicp", "max_correspondence_distance_m", 3.0): None, ("open3d_gicp", "voxel_size_m", None): None,
        ("open3d_gicp", "max_correspondence_distance_m", 1.5): "open3d_gicp"}
    # the point-to-point variants' entries stay nearer the truth than their closed forms at other gates and voxel sizes
    point_to_point = [name for name in ("vanilla", "kiss", "genz") if name in available_icp()]
    assert [get_icp(name, voxel_size_m=0.5).calibration_variant() for name in point_to_point] == point_to_point


def test_nees_and_covariance_about_say_what_they_got_in_one_line(rng):
    """``nees("x")`` raised numpy's bare ValueError ("could not convert string to float"); ``covariance_about`` of a
    3x3 or a NaN 4x4 put numpy's multi-line repr of the array in its message (one line from the CLI)."""
    pts = rng.uniform(-10, 10, (400, 3))
    result = get_icp("vanilla").align(pts + [0.1, 0.0, 0.0], pts)
    with pytest.raises(ConfigError) as err:
        result.nees("x")
    assert str(err.value) == "nees: T_target_source_true must be a finite 4x4 rigid transform, got 'x'"
    said = {}
    for name, bad in (("eye", np.eye(3)), ("nan", np.full((4, 4), np.nan)), ("long", "x" * 100)):
        with pytest.raises(ConfigError) as err:
            result.covariance_about(bad)
        said[name] = str(err.value).removeprefix("covariance_about: origin_m must be 3 finite numbers (m), got ")
    assert said == {"eye": "an array of shape (3, 3)", "nan": "an array of shape (4, 4) with 16 NaN or infinite entries",
                    "long": "'" + "x" * 56 + "..."}


def test_ground_filtered_without_its_ground_refinement_is_not_calibrated(street_pair):
    """ground_filtered's entry was learned with the ground refinement on (z, roll and pitch factors of 4.5e-6 to 3.8e-5):
    ``ground_refine=False`` took it as well and stated a 0.3 mm z sigma for a 1.5 cm error (mean NEES ~7500 on a street).
    It gets the closed form now, and the note names the setting."""
    source, target, T_true = street_pair
    refined, unrefined = (get_icp("ground_filtered", ground_refine=flag) for flag in (True, False))
    assert (refined.calibration_variant(), unrefined.calibration_variant()) == ("ground_filtered", None)
    result = unrefined.align(source, target)
    assert result.extra["covariance_calibration"] == (
        "none learned for ground_filtered (ground_refine=False): the closed form as computed (typically over-confident)")
    raw = get_icp("ground_filtered", ground_refine=False, calibrated_covariance=False).align(source, target)
    np.testing.assert_allclose(result.covariance, raw.covariance, rtol=1e-9, atol=1e-18)
    assert result.nees(T_true) < 50  # (thousands under the refined fit's entry)
    assert refined.align(source, target).extra["covariance_calibration"] == "ground_filtered"
