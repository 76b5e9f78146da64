"""Property tests for SE(3)/SO(3) helpers and Kabsch/Umeyama alignment."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lidarkit.errors import DataError
from lidarkit.geometry import (
    is_rotation,
    kabsch_umeyama,
    make_se3,
    orthonormalize,
    orthonormalize_se3,
    pose_error,
    random_se3,
    rotation_angle_deg,
    se3_exp,
    se3_inverse,
    se3_log,
    so3_exp,
    so3_log,
    transform_points,
)

seeds = st.integers(min_value=0, max_value=2**32 - 1)
SETTINGS = settings(max_examples=60, deadline=None)


@SETTINGS
@given(seeds)
def test_inverse_and_compose_identities(seed):
    rng = np.random.default_rng(seed)
    A, B = random_se3(rng, 50.0), random_se3(rng, 50.0)
    np.testing.assert_allclose(A @ se3_inverse(A), np.eye(4), atol=1e-9)
    np.testing.assert_allclose(se3_inverse(A @ B), se3_inverse(B) @ se3_inverse(A), atol=1e-9)
    np.testing.assert_allclose(se3_inverse(se3_inverse(A)), A, atol=1e-12)
    stack = np.stack([A, B])
    np.testing.assert_allclose(se3_inverse(stack), np.stack([np.linalg.inv(A), np.linalg.inv(B)]), atol=1e-9)


@SETTINGS
@given(seeds)
def test_exp_log_round_trip(seed):
    rng = np.random.default_rng(seed)
    T = random_se3(rng, 10.0, max_angle_rad=np.pi - 1e-3)
    np.testing.assert_allclose(se3_exp(se3_log(T)), T, atol=1e-8)
    xi = rng.normal(size=6) * np.array([5, 5, 5, 0.5, 0.5, 0.5])
    np.testing.assert_allclose(se3_log(se3_exp(xi)), xi, atol=1e-8)
    R = T[:3, :3]
    np.testing.assert_allclose(so3_exp(so3_log(R)), R, atol=1e-9)


def test_se3_exp_matches_matrix_exponential():
    from scipy.linalg import expm

    xi = np.array([1.0, -2.0, 0.5, 0.3, -0.2, 0.9])
    hat = np.zeros((4, 4))
    hat[:3, :3] = np.array([[0, -xi[5], xi[4]], [xi[5], 0, -xi[3]], [-xi[4], xi[3], 0]])
    hat[:3, 3] = xi[:3]
    np.testing.assert_allclose(se3_exp(xi), expm(hat), atol=1e-12)


def test_rotation_angle_and_pose_error():
    R = so3_exp(np.array([0.0, 0.0, np.radians(30.0)]))
    assert rotation_angle_deg(R) == pytest.approx(30.0, abs=1e-9)
    T_ref = make_se3(R, [1.0, 2.0, 3.0])
    T_est = T_ref @ make_se3(so3_exp([np.radians(2.0), 0, 0]), [0.3, 0.4, 0.0])
    t_err, r_err = pose_error(T_est, T_ref)
    assert t_err == pytest.approx(0.5, abs=1e-12)
    assert r_err == pytest.approx(2.0, abs=1e-9)


@SETTINGS
@given(seeds, st.floats(min_value=0.0, max_value=0.02))
def test_kabsch_recovers_rigid_transform_from_noisy_pairs(seed, noise):
    rng = np.random.default_rng(seed)
    T = random_se3(rng, 20.0)
    src = rng.uniform(-10, 10, size=(200, 3))
    dst = transform_points(T, src) + rng.normal(scale=noise, size=src.shape)
    fit = kabsch_umeyama(src, dst)
    t_err, r_err = pose_error(fit.T, T)
    # noise sigma over 200 points spread over 20 m: error bounds well above the estimator's spread
    assert t_err < 1e-9 + 10 * noise / np.sqrt(200) * 3
    assert r_err < 1e-7 + np.degrees(10 * noise / np.sqrt(200) / 5)
    assert is_rotation(fit.rotation, tol=1e-10)
    assert fit.scale == 1.0


@SETTINGS
@given(seeds, st.floats(min_value=0.1, max_value=10.0))
def test_umeyama_recovers_similarity(seed, scale):
    rng = np.random.default_rng(seed)
    T = random_se3(rng, 20.0)
    src = rng.normal(size=(100, 3)) * 5
    dst = scale * src @ T[:3, :3].T + T[:3, 3] + rng.normal(scale=1e-3, size=src.shape)
    fit = kabsch_umeyama(src, dst, with_scale=True)
    assert fit.scale == pytest.approx(scale, rel=2e-3)
    assert rotation_angle_deg(fit.rotation.T @ T[:3, :3]) < 0.05
    np.testing.assert_allclose(fit.apply(src), dst, atol=0.02 * max(scale, 1.0))


def test_kabsch_never_returns_a_reflection():
    # a mirrored point set: the best orthogonal map is a reflection, the result must still be a rotation
    rng = np.random.default_rng(3)
    src = rng.normal(size=(50, 3))
    dst = src * np.array([1.0, 1.0, -1.0])
    fit = kabsch_umeyama(src, dst)
    assert np.linalg.det(fit.rotation) == pytest.approx(1.0, abs=1e-12)


def test_kabsch_weights_ignore_outliers():
    rng = np.random.default_rng(4)
    T = random_se3(rng, 5.0)
    src = rng.normal(size=(60, 3))
    dst = transform_points(T, src)
    dst[:10] += 100.0
    w = np.ones(60)
    w[:10] = 0.0
    t_err, r_err = pose_error(kabsch_umeyama(src, dst, weights=w).T, T)
    assert t_err < 1e-9 and r_err < 1e-6


@pytest.mark.parametrize(
    "src, dst, match",
    [
        (np.zeros((2, 3)), np.zeros((2, 3)), "at least 3 points"),
        (np.zeros((5, 3)), np.zeros((6, 3)), "differ in shape"),
        (np.full((5, 3), np.nan), np.zeros((5, 3)), "NaN"),
        (np.zeros((5, 2)), np.zeros((5, 2)), r"\(N, 3\)"),
    ],
)
def test_kabsch_bad_input(src, dst, match):
    with pytest.raises(DataError, match=match):
        kabsch_umeyama(src, dst)


def test_orthonormalize_repairs_rounded_rotations(rng):
    T = random_se3(rng)
    noisy = T.copy()
    noisy[:3, :3] = np.round(noisy[:3, :3], 4)
    assert not is_rotation(noisy[:3, :3], tol=1e-9)
    fixed = orthonormalize_se3(noisy)
    assert is_rotation(fixed[:3, :3], tol=1e-12)
    assert rotation_angle_deg(fixed[:3, :3].T @ T[:3, :3]) < 0.01
    stack = orthonormalize(np.stack([noisy[:3, :3]] * 3))
    assert stack.shape == (3, 3, 3) and is_rotation(stack, tol=1e-12)


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
@pytest.mark.parametrize("case", ["street", "far", "nan", "inf", "over", "under", "at_limit", "strided"])
def test_within_limits_equals_the_exact_test(dtype, case):
    """The flat test gives the exact answer: NaN, inf and out-of-range values anywhere, contiguous or not."""
    from lidarkit.geometry import MAX_ABS_COORDINATE_M, _within_limits

    pts = np.random.default_rng(3).normal(scale=30.0, size=(50_000, 3))
    if case == "far":  # a legitimate cloud 500 km out
        pts += 5e5
    elif case == "nan":
        pts[777, 1] = np.nan
    elif case == "inf":
        pts[12, 2] = -np.inf
    elif case == "over":
        pts[40_000, 0] = 1.0001 * MAX_ABS_COORDINATE_M
    elif case == "under":
        pts[3, 2] = -1.0001 * MAX_ABS_COORDINATE_M
    elif case == "at_limit":
        pts[9, 0] = MAX_ABS_COORDINATE_M
    arr = pts.astype(dtype)
    if case == "strided":
        arr = np.c_[arr, arr[:, :1]][:, :3]
        assert not arr.flags.c_contiguous
    exact = bool(np.isfinite(arr).all() and np.abs(arr).max() <= MAX_ABS_COORDINATE_M)
    assert _within_limits(arr) is exact
    assert exact is (case in ("street", "far", "at_limit", "strided"))
