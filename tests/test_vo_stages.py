"""VO stages one by one: config, preprocessing, detection with bucketing, matching, two-view geometry (incl. the
OpenCV 5 USAC_MAGSAC pixel-coordinate failure), sanity checks, relative scale, smoothing, intrinsics."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from conftest import shared_path

from lidarkit.errors import ConfigError, DataError
from lidarkit.geometry import make_se3, skew, so3_exp
from lidarkit.trajectory import Trajectory
from lidarkit.vo import (
    GeometryConfig,
    K_from_image_size,
    SanityConfig,
    VOConfig,
    available_presets,
    check_pose,
    estimate_two_view,
    get_detector,
    get_matcher,
    get_preprocessor,
    make_config,
    preset,
    smooth_translations,
    track_klt,
)
from lidarkit.vo.config import FeatureConfig
from lidarkit.vo.features import bucket_indices
from lidarkit.vo.scale import relative_scale
from lidarkit.sim.camera import (
    PlaneScene,
    TexturedPlane,
    default_K,
    forward_trajectory,
    make_plane_scene,
    random_texture,
)
from lidarkit.vo.two_view import (
    TwoViewEstimate,
    correspondence_rng,
    normalize_points,
    rotation_error_deg,
    sampson_residuals,
    triangulate,
)


def _kitti_pair(seq="06", i=10):
    folder = shared_path("kitti_images", "sequences", seq)
    from lidarkit.io.kitti import KittiOdometry

    ds = KittiOdometry(folder).as_image_sequence()
    return ds.read_image(i), ds.read_image(i + 1), ds.K


def _synthetic_correspondences(rng, n=300, R=None, t=np.array([0.1, 0.0, 1.0]), K=None):
    K = K if K is not None else np.array([[700.0, 0, 600], [0, 700, 180], [0, 0, 1]])
    X = np.column_stack([rng.uniform(-20, 20, n), rng.uniform(-3, 3, n), rng.uniform(5, 40, n)])
    R = np.eye(3) if R is None else R
    Xc = X @ R.T + t
    x0 = X @ K.T
    x1 = Xc @ K.T
    return x0[:, :2] / x0[:, 2:], x1[:, :2] / x1[:, 2:], K


# ---- config ----------------------------------------------------------------------------------------------------
def test_presets_and_dotted_updates():
    assert {"lidarkit", "report_sift", "report_orb"} <= set(available_presets())
    sift = preset("report_sift")
    assert sift.features.detector == "sift" and sift.matching.method == "bf_cross" and sift.scale.mode == "gt"
    orb = preset("report_orb")
    assert orb.preprocess.method == "clahe" and orb.features.max_features == 3000
    assert orb.geometry.estimators == ("magsac",) and orb.sanity.max_rotation_deg == 60
    cfg = VOConfig().updated(**{"scale.mode": "gt", "features.max_features": 500})
    assert cfg.scale.mode == "gt" and cfg.features.max_features == 500
    assert VOConfig().scale.mode == "relative"  # unchanged original (frozen)


@pytest.mark.parametrize("bad,match", [
    ({"features": {"detector": "surf"}}, "features.detector"),
    ({"smoothing": {"window": 5, "polyorder": 5}}, "polyorder"),
    ({"matching": {"method": "knn_ratio"}}, "needs descriptors"),
    ({"geometry": {"estimators": []}}, "estimators"),
    ({"bogus": 1}, "bogus"),
])
def test_bad_config_raises_config_error(bad, match):
    with pytest.raises(ConfigError, match=match):
        make_config(bad)


def test_building_a_config_directly_raises_config_error_naming_the_field():
    """VOConfig(features={"detector": "surf"}) raised pydantic's ValidationError (a multi-line traceback), where
    preset() and make_config() give a ConfigError for the same value; a stage built on its own names its section."""
    from lidarkit.vo import FeatureConfig

    for build, line in (
        (lambda: VOConfig(features={"detector": "surf"}),
         "vo config features.detector: Input should be 'gftt', 'fast', 'orb', 'sift' or 'akaze' (got 'surf')"),
        (lambda: FeatureConfig(max_features=3), "vo config features.max_features: Input should be greater than or equal "
                                                "to 8 (got 3)"),
        (lambda: VOConfig(matching={"method": "knn_ratio"}), "vo config: matching 'knn_ratio' needs descriptors; "
                                                            "detector 'gftt' has none (use orb, sift or akaze, or matching 'klt')"),
        (lambda: VOConfig(seed=-1), "vo config seed: Input should be greater than or equal to 0 (got -1)"),
    ):
        with pytest.raises(ConfigError) as err:
            build()
        assert str(err.value) == line
    assert VOConfig(features={"detector": "orb"}).features.detector == "orb"


def test_unknown_names_list_the_known_ones():
    with pytest.raises(ConfigError, match="known: .*lidarkit"):
        preset("best")
    with pytest.raises(ConfigError, match="known: gftt"):
        get_detector("surf")
    with pytest.raises(ConfigError, match="known: klt"):
        get_matcher("flann")
    with pytest.raises(ConfigError, match="known: none, clahe"):
        get_preprocessor("sharpen")
    with pytest.raises(ConfigError, match="unknown config field"):
        VOConfig().updated(**{"features.budget": 3})


# ---- preprocessing and features --------------------------------------------------------------------------------
def test_clahe_raises_local_contrast():
    rng = np.random.default_rng(0)
    low = (100 + 10 * rng.random((120, 160))).astype(np.uint8)
    out = get_preprocessor("clahe")(low)
    assert out.shape == low.shape and out.dtype == np.uint8 and out.std() > 2 * low.std()
    assert get_preprocessor("none")(low) is low
    for name in ("gaussian", "bilateral"):  # the report found blurring lowers inliers: it stays available, off
        blurred = get_preprocessor(name)(low)
        assert blurred.shape == low.shape and blurred.std() < low.std()


def test_an_even_blur_kernel_is_refused_not_run_as_the_next_odd_one():
    """preprocess.blur_kernel_px 4 ran a 5 x 5 blur (``| 1``) while config.yaml recorded 4; even sizes are refused by
    name, as smoothing.window's are, and an odd size is the kernel run."""
    from lidarkit.vo.config import PreprocessConfig

    for method in ("gaussian", "bilateral"):
        with pytest.raises(ConfigError) as err:
            preset("lidarkit", **{"preprocess.method": method, "preprocess.blur_kernel_px": 4})
        assert str(err.value) == ("vo config preprocess.blur_kernel_px: must be odd (the kernel is centred on each "
                                  "pixel) (got 4)")
    low = (100 + 10 * np.random.default_rng(0).random((60, 80))).astype(np.uint8)
    blurred = get_preprocessor(PreprocessConfig(method="gaussian", blur_kernel_px=3))(low)
    assert np.array_equal(blurred, cv2.GaussianBlur(low, (3, 3), 0))


def test_bucket_indices_keeps_best_per_cell():
    pts = np.array([[1, 1], [2, 2], [3, 3], [90, 90], [91, 91]], np.float32)
    scores = np.array([1.0, 5.0, 3.0, 2.0, 4.0])
    keep = bucket_indices(pts, scores, (100, 100), 2, 2, per_cell=2)
    assert keep.tolist() == [1, 2, 4, 3] or sorted(keep.tolist()) == [1, 2, 3, 4]
    assert 0 not in keep


def test_grid_bucketing_spreads_orb_features():
    """On a KITTI image, bucketed ORB features occupy many more grid cells than the plain top-N."""
    img, _, _ = _kitti_pair()
    h, w = img.shape

    def occupied(points):
        cells = (points[:, 1] * 4 // h).astype(int) * 8 + (points[:, 0] * 8 // w).astype(int)
        return len(np.unique(cells))

    plain, _ = get_detector(FeatureConfig(detector="orb", max_features=500, grid_rows=1, grid_cols=1)).detect(img)
    grid, desc = get_detector(FeatureConfig(detector="orb", max_features=500, grid_rows=4, grid_cols=8)).detect(img)
    assert len(grid) <= 500 + 32 and desc.shape[0] == len(grid)
    assert occupied(grid) >= occupied(plain) + 3


def test_klt_forward_backward_rejects_occluded_points():
    img0, img1, _ = _kitti_pair()
    pts, _ = get_detector("gftt").detect(img0)
    p1, ok = track_klt(img0, img1, pts)
    assert ok.mean() > 0.5
    _, ok_black = track_klt(img0, np.zeros_like(img1), pts)
    assert ok_black.sum() < 0.05 * len(pts)


# ---- two-view geometry ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("estimator", ["ransac", "magsac", "lmeds"])
def test_two_view_exact_on_synthetic_points(estimator):
    rng = np.random.default_rng(3)
    R = so3_exp(np.radians([0.5, 2.0, -0.3]))
    t = np.array([0.2, -0.05, 1.0])
    x0, x1, K = _synthetic_correspondences(rng, R=R, t=t)
    cv2.setRNGSeed(1)
    est = estimate_two_view(x0, x1, K, GeometryConfig(estimators=(estimator,)))
    assert est.ok and est.n_inliers > 250
    np.testing.assert_allclose(est.R_cur_ref, R, atol=1e-6)
    np.testing.assert_allclose(est.t_cur_ref, t / np.linalg.norm(t), atol=1e-5)


def test_magsac_needs_normalized_points_with_opencv5():
    """OpenCV 5: USAC_MAGSAC on KITTI pixel coordinates finds no essential matrix; normalized coordinates work.
    Either way the outcome is recorded (never a silent skip)."""
    img0, img1, K = _kitti_pair()
    pts, _ = get_detector("gftt").detect(img0)
    p1, ok = track_klt(img0, img1, pts)
    pixel = GeometryConfig(estimators=("magsac",), normalize=False, fundamental_fallback=False)
    cv2.setRNGSeed(0)
    est_px = estimate_two_view(pts[ok], p1[ok], K, pixel)
    cv2.setRNGSeed(0)
    est_norm = estimate_two_view(pts[ok], p1[ok], K, GeometryConfig(estimators=("magsac",)))
    assert est_norm.ok and est_norm.n_inliers > 300 and est_norm.method == "E-magsac"
    if est_px.ok:  # a future OpenCV may fix it: then both must agree
        assert np.degrees(np.arccos(np.clip(est_px.t_cur_ref @ est_norm.t_cur_ref, -1, 1))) < 2
    else:
        assert "E-magsac: no solution" in est_px.failure
    fallback = estimate_two_view(pts[ok], p1[ok], K, pixel.model_copy(update={"fundamental_fallback": True}))
    assert fallback.ok and fallback.method in ("E-magsac", "F-fallback")


def test_two_view_reports_failures_instead_of_raising():
    K = np.array([[700.0, 0, 600], [0, 700, 180], [0, 0, 1]])
    few = estimate_two_view(np.zeros((3, 2)), np.ones((3, 2)), K)
    assert not few.ok and "too few correspondences" in few.failure
    rng = np.random.default_rng(0)
    noise = estimate_two_view(rng.uniform(0, 1000, (100, 2)), rng.uniform(0, 1000, (100, 2)), K,
                              GeometryConfig(fundamental_fallback=False))
    assert check_pose(noise, SanityConfig()) is not None



def test_two_view_takes_opencv_shaped_points_and_names_each_bad_input():
    """(2, N) points (p0.T, p1.T) were flattened into N scrambled pairs and gave a wrong pose marked ok; unequal
    lengths, NaN points and a bad K were raw IndexError / ValueError / LinAlgError. (N, 1, 2) gives the (N, 2) pose."""
    R = so3_exp(np.radians([0.0, 2.0, 0.0]))
    t = np.array([0.05, 0.0, 1.0])
    x0, x1, K = _synthetic_correspondences(np.random.default_rng(0), n=200, R=R, t=t)
    flat = estimate_two_view(x0, x1, K)
    column = estimate_two_view(x0[:, None], x1[:, None], K.tolist())
    assert flat.ok and column.ok and np.allclose(column.R_cur_ref, flat.R_cur_ref) and np.allclose(column.R_cur_ref, R, atol=1e-6)
    bad = {
        "transposed": ((x0.T, x1.T, K), DataError, "points_ref_px: must be (N, 2) or (N, 1, 2) pixel coordinates, got "
                       "shape (2, 200) (one point per column: give its transpose)"),
        "unequal": ((x0, x1[:-5], K), DataError, "points_cur_px: 195 points for the 200 of points_ref_px: one per correspondence"),
        "odd count": ((x0.ravel()[:-1], x1.ravel()[:-1], K), DataError,
                      "points_ref_px: must be (N, 2) or (N, 1, 2) pixel coordinates, got shape (399,)"),
        "nan point": ((x0, np.r_[x1[:-1], [[np.nan, 1.0]]], K), DataError,
                      "points_cur_px: NaN or infinite coordinates in 1 of 200 points (first: row 199)"),
        "K 3x4": ((x0, x1, np.c_[K, np.zeros(3)]), DataError, "K: K must be a 3x3 matrix, got shape (3, 4)"),
        "K nan": ((x0, x1, K * np.nan), DataError, "K: K must be finite, got 9 NaN or infinite entries"),
    }
    for case, (args, kind, message) in bad.items():
        with pytest.raises(kind) as refused:
            estimate_two_view(*args)
        assert str(refused.value) == message, case

def test_sanity_checks_each_reason():
    good = TwoViewEstimate(np.eye(3), np.array([0, 0, 1.0]), np.ones(100, bool), "E-ransac", 100, 5.0)
    cfg = SanityConfig(min_inliers=30, max_rotation_deg=30, min_parallax_px=0.5)
    assert check_pose(good, cfg) is None
    flip = TwoViewEstimate(so3_exp(np.array([0, np.pi * 0.9, 0])), np.array([0, 0, 1.0]), good.inliers, "E", 100, 5.0)
    assert "flip guard" in check_pose(flip, cfg)
    few = TwoViewEstimate(np.eye(3), np.array([0, 0, 1.0]), good.inliers, "E", 10, 5.0)
    assert "too few inliers" in check_pose(few, cfg)
    rotation_only = TwoViewEstimate(np.eye(3), np.array([0, 0, 1.0]), good.inliers, "E", 100, 0.1)
    assert "insufficient parallax" in check_pose(rotation_only, cfg)
    nan = TwoViewEstimate(np.full((3, 3), np.nan), np.array([0, 0, 1.0]), good.inliers, "E", 100, 5.0)
    assert "non-finite" in check_pose(nan, SanityConfig(enabled=False))
    bad_det = TwoViewEstimate(-np.eye(3), np.array([0, 0, 1.0]), good.inliers, "E", 100, 5.0)
    assert "det(R)" in check_pose(bad_det, SanityConfig(enabled=False))
    assert check_pose(flip, SanityConfig(enabled=False)) is None  # checks off: only finite/det remain


def test_pure_rotation_pair_is_flagged():
    rng = np.random.default_rng(5)
    R = so3_exp(np.radians([0.0, 3.0, 0.0]))
    x0, x1, K = _synthetic_correspondences(rng, R=R, t=np.zeros(3))
    est = estimate_two_view(x0, x1, K)
    assert est.rotation_only_px < 0.01 and est.homography_share == 1.0 and est.rotation_homography_px < 0.01
    assert "pure rotation / no parallax: homography explains 100.0%" in check_pose(est, SanityConfig())
    # the K-based measure alone (homography test switched off) flags it too when K is right
    k_based = check_pose(est, SanityConfig(max_rotation_homography_px=0.0))
    assert k_based.startswith("insufficient parallax (0.00 px < 0.5 px)")



# ---- pure rotation without trusting K (homography vs fundamental matrix, rotation-conjugate homography) ------------
KITTI_06_FOCAL_PX = 707.0912


def _klt_pair(img0, img1):
    pts, _ = get_detector("gftt").detect(img0)
    p1, ok = track_klt(img0, img1, pts)
    return pts[ok], p1[ok]


@pytest.fixture(scope="module")
def kitti_rotation_warp():
    """The reviewer's construction: KITTI 06 frame 15 and the same frame warped by the rotation homography
    K R K^-1 (1.5 deg yaw, true K): no translation at all."""
    img, _, K = _kitti_pair(i=15)
    h, w = img.shape
    R = so3_exp(np.radians([0.0, 1.5, 0.0]))
    warped = cv2.warpPerspective(img, K @ R @ np.linalg.inv(K), (w, h))
    return (*_klt_pair(img, warped), K, (w, h))


def _scaled_focal(K, factor):
    out = K.copy()
    out[0, 0] *= factor
    out[1, 1] *= factor
    return out


@pytest.mark.parametrize("k_case", ["calib", "guess", "f-20%", "f-10%", "f+10%", "f+20%"])
def test_kitti_rotation_warp_is_rejected_whatever_K(kitti_rotation_warp, k_case):
    """Guessed K (fx = 1117 px against the true 707) or K off by 10-20 %: the homography explains the pair and is a
    pure rotation within 0.1 px, its self-calibrated focal length is the true one within 2 %."""
    a, b, K_true, (w, h) = kitti_rotation_warp
    factors = {"calib": 1.0, "f-20%": 0.8, "f-10%": 0.9, "f+10%": 1.1, "f+20%": 1.2}
    K = K_from_image_size(w, h) if k_case == "guess" else _scaled_focal(K_true, factors[k_case])
    est = estimate_two_view(a, b, K, GeometryConfig(), rng=correspondence_rng(0, 16))
    reason = check_pose(est, SanityConfig())
    assert reason is not None and "pure rotation / no parallax: homography explains" in reason
    assert est.homography_share >= 0.99 and est.fundamental_inliers >= 0.95 * len(a)
    assert est.rotation_homography_px < 0.1
    assert est.rotation_focal_px == pytest.approx(KITTI_06_FOCAL_PX, rel=0.02)


def test_kitti_rotation_warp_passes_the_K_based_check_with_guessed_K(kitti_rotation_warp):
    """Why the K-free test is needed: with the guessed K, for half of the seeds (measured 4 of 8) the essential matrix
    'explains' the pure rotation (nearly all inliers, tens of px of apparent parallax) and the K-based checks accept
    it; the homography test rejects every seed."""
    a, b, _, (w, h) = kitti_rotation_warp
    K_guess = K_from_image_size(w, h)
    k_based_accepted = 0
    for seed in range(8):
        est = estimate_two_view(a, b, K_guess, GeometryConfig(), rng=correspondence_rng(seed, 16))
        assert "pure rotation / no parallax" in check_pose(est, SanityConfig())
        if check_pose(est, SanityConfig(max_rotation_homography_px=0.0)) is None:  # homography test off
            assert est.n_inliers >= 0.9 * len(a) and est.parallax_px > 5 and est.rotation_only_px > 0.5
            k_based_accepted += 1
    assert k_based_accepted >= 2


def test_reviewer_sequence_rejects_the_rotation_frame_with_guessed_K():
    """KITTI 06 frames 10-20, frame 16 replaced by frame 15 rotated 1.5 deg; K guessed from the image size: frame 16
    is the only rejection, with the homography reason; the frame after it is matched to frame 15 and the relative
    scale carries on (step lengths after/before the frame vs the ground truth: 1.00; with the homography test off
    the reference moves to the rotated frame and later steps come out about half as long)."""
    from lidarkit.io.kitti import KittiOdometry
    from lidarkit.vo import MonoVO

    ds = KittiOdometry(shared_path("kitti_images", "sequences", "06")).as_image_sequence()
    images = [ds.read_image(i) for i in range(10, 21)]  # frames 10..20; index 6 is frame 16
    h, w = images[0].shape
    K = ds.K
    images[6] = cv2.warpPerspective(images[5], K @ so3_exp(np.radians([0.0, 1.5, 0.0])) @ np.linalg.inv(K), (w, h))
    result = MonoVO(preset("lidarkit"), K_from_image_size(w, h)).run(images)
    assert [d.frame for d in result.rejected] == [6]
    assert "pure rotation / no parallax" in result.diagnostics[6].reason
    assert result.diagnostics[7].ref_frame == 5
    steps = np.linalg.norm(np.diff(result.trajectory.positions_xyz, axis=0), axis=1)
    true_steps = np.linalg.norm(np.diff(ds.ground_truth.positions_xyz[10:21], axis=0), axis=1)
    ratio = steps / true_steps
    assert ratio[7:].mean() / ratio[:5].mean() == pytest.approx(1.0, abs=0.05)


@pytest.mark.parametrize("axis_deg", [(0.0, 2.0, 0.0), (1.5, 0.0, 0.0), (0.5, 1.0, 0.8)])
@pytest.mark.parametrize("focal_factor", [0.8, 1.0, 1.2])
def test_sim_pure_rotation_is_rejected_with_wrong_K(axis_deg, focal_factor):
    """lidarkit.sim.camera renders of a camera that only rotates; estimated with K off by -20/0/+20 %."""
    K = default_K()
    scene = make_plane_scene(np.random.default_rng(0))
    img0 = scene.render(np.eye(4), K, (640, 480))
    img1 = scene.render(make_se3(so3_exp(np.radians(axis_deg)), np.zeros(3)), K, (640, 480))
    a, b = _klt_pair(img0, img1)
    est = estimate_two_view(a, b, _scaled_focal(K, focal_factor), GeometryConfig(), rng=correspondence_rng(0, 1))
    assert "pure rotation / no parallax" in check_pose(est, SanityConfig())
    assert est.rotation_homography_px < 0.3


@pytest.mark.parametrize("guess_K", [False, True])
def test_sim_forward_motion_is_never_rejected(guess_K):
    """Forward motion (0.5 m steps) through the textured-plane scene: no pair is flagged, with the true or a guessed
    K; the homography explains well under the 90 % share (measured <= 0.46)."""
    K = default_K()
    scene = make_plane_scene(np.random.default_rng(0))
    images = [scene.render(T, K, (640, 480)) for T in forward_trajectory(6, rng=np.random.default_rng(1)).poses_se3]
    K_used = K_from_image_size(640, 480) if guess_K else K
    for k in range(len(images) - 1):
        a, b = _klt_pair(images[k], images[k + 1])
        est = estimate_two_view(a, b, K_used, GeometryConfig(), rng=correspondence_rng(0, k + 1))
        assert check_pose(est, SanityConfig()) is None, k
        assert est.homography_share < 0.7 and est.rotation_homography_px > 3.0


def _single_plane(origin, u, v, size_m):
    tex = random_texture(np.random.default_rng(4), 1024)
    return PlaneScene((TexturedPlane(np.array(origin, float), np.array(u, float), np.array(v, float), size_m, tex),))


_COS30, _SIN30 = np.cos(np.radians(30)), np.sin(np.radians(30))
_PLANES = {  # (scene, camera translation): the homography explains every correspondence, yet the camera translated
    "wall, forward 0.2 m": (([-15, -12, 10], [1, 0, 0], [0, 1, 0], (30, 24)), [0.0, 0.0, 0.2]),
    "tilted wall, sideways 0.3 m": (([-15 * _COS30, -12, 10 + 15 * _SIN30], [_COS30, 0, -_SIN30], [0, 1, 0], (30, 24)),
                                    [0.3, 0.0, 0.0]),
    "ground, forward 0.2 m": (([-20, 1.5, 1.0], [1, 0, 0], [0, 0, 1], (40, 60)), [0.0, 0.0, 0.2]),
}


@pytest.mark.parametrize("case", list(_PLANES))
def test_plane_under_translation_is_not_a_rotation(case):
    """A single textured plane seen under translation is explained by a homography (share >= 0.85) but not by a
    rotation-conjugate one, so the pair is kept (guessed K)."""
    plane, t = _PLANES[case]
    scene = _single_plane(*plane)
    K = default_K()
    T = make_se3(so3_exp(np.radians([0.0, 0.5, 0.0])), np.array(t))
    a, b = _klt_pair(scene.render(np.eye(4), K, (640, 480)), scene.render(T, K, (640, 480)))
    est = estimate_two_view(a, b, K_from_image_size(640, 480), GeometryConfig(), rng=correspondence_rng(0, 1))
    assert est.homography_share >= 0.85
    assert est.rotation_homography_px > 3.0
    assert check_pose(est, SanityConfig()) is None


def test_focal_ratio_bounds_the_sideways_wall_ambiguity():
    """A fronto-parallel wall passed sideways moves the image like a rotation of a camera with a longer focal length:
    with K trusted to 25 % (rotation_focal_ratio=1.25) the pair is kept, with the default 2x range it is flagged."""
    scene = _single_plane([-15, -12, 10], [1, 0, 0], [0, 1, 0], (30, 24))
    K = default_K()
    T = make_se3(so3_exp(np.radians([0.0, 0.5, 0.0])), np.array([0.3, 0.0, 0.0]))
    a, b = _klt_pair(scene.render(np.eye(4), K, (640, 480)), scene.render(T, K, (640, 480)))
    trusted = estimate_two_view(a, b, K, GeometryConfig(rotation_focal_ratio=1.25), rng=correspondence_rng(0, 1))
    assert check_pose(trusted, SanityConfig()) is None and trusted.rotation_homography_px > 1.5
    loose = estimate_two_view(a, b, K, GeometryConfig(), rng=correspondence_rng(0, 1))
    assert "pure rotation / no parallax" in check_pose(loose, SanityConfig())
    assert loose.rotation_focal_px > 1.5 * K[0, 0]


@pytest.mark.parametrize("seq", ["06", "01"])
def test_kitti_forward_pairs_are_not_flagged(seq):
    """Every 5th consecutive pair of the 51-frame KITTI excerpts, calibrated and guessed K: never flagged as a
    rotation, the homography explains at most 75 % (measured max 0.39 on 06, 0.61 on 01)."""
    from lidarkit.io.kitti import KittiOdometry

    ds = KittiOdometry(shared_path("kitti_images", "sequences", seq)).as_image_sequence()
    h, w = ds.read_image(0).shape
    for i in range(0, 50, 5):
        a, b = _klt_pair(ds.read_image(i), ds.read_image(i + 1))
        for K in (ds.K, K_from_image_size(w, h)):
            est = estimate_two_view(a, b, K, GeometryConfig(), rng=correspondence_rng(0, i + 1))
            assert est.homography_share < 0.75, (seq, i)
            reason = check_pose(est, SanityConfig())
            assert reason is None or "pure rotation" not in reason, (seq, i, reason)


# ---- seeds: the correspondence order drives OpenCV's samples ------------------------------------------------------
@pytest.mark.parametrize("estimator", ["ransac", "magsac", "lmeds"])
def test_seed_selects_the_robust_samples(estimator):
    """OpenCV 5's estimators ignore cv2.setRNGSeed; the seeded permutation makes the seed real: the same seed gives
    bit-identical results, seed 7 other inlier sets, both accurate against the KITTI ground truth (frames 30 -> 31)."""
    from lidarkit.geometry import se3_inverse
    from lidarkit.io.kitti import KittiOdometry

    ds = KittiOdometry(shared_path("kitti_images", "sequences", "06")).as_image_sequence()
    a, b = _klt_pair(ds.read_image(30), ds.read_image(31))
    gt = ds.ground_truth.poses_se3
    T_true = se3_inverse(gt[31]) @ gt[30]
    cfg = GeometryConfig(estimators=(estimator,))
    first = estimate_two_view(a, b, ds.K, cfg, rng=correspondence_rng(0, 31))
    again = estimate_two_view(a, b, ds.K, cfg, rng=correspondence_rng(0, 31))
    other = estimate_two_view(a, b, ds.K, cfg, rng=correspondence_rng(7, 31))
    assert np.array_equal(first.inliers, again.inliers) and np.array_equal(first.R_cur_ref, again.R_cur_ref)
    assert np.array_equal(first.t_cur_ref, again.t_cur_ref)
    assert not np.array_equal(first.inliers, other.inliers)
    t_true = T_true[:3, 3] / np.linalg.norm(T_true[:3, 3])
    for est in (first, other):
        assert rotation_error_deg(est.R_cur_ref, T_true[:3, :3]) < 0.1
        assert np.degrees(np.arccos(np.clip(est.t_cur_ref @ t_true, -1, 1))) < 1.5
        # the inlier mask is in the caller's order: its points satisfy the estimated epipolar geometry
        E = skew(est.t_cur_ref) @ est.R_cur_ref
        sampson_px = np.abs(sampson_residuals(E, normalize_points(a[est.inliers], ds.K),
                                              normalize_points(b[est.inliers], ds.K))) * ds.K[0, 0]
        assert np.median(sampson_px) < 0.3


# ---- scale, smoothing, intrinsics -------------------------------------------------------------------------------
def test_relative_scale_recovers_depth_ratio():
    rng = np.random.default_rng(2)
    R = so3_exp(np.radians([0.0, 1.0, 0.0]))
    t = np.array([0.0, 0.0, 1.0])
    x0, x1, K = _synthetic_correspondences(rng, R=R, t=t * 1.3)  # true step 1.3 m
    X_ref, X_cur, angle = triangulate(R, t, normalize_points(x0, K), normalize_points(x1, K))
    true_depth = X_ref[:, 2] * 1.3  # depths the previous pair would have given, in metres
    true_depth[:10] = np.nan  # unknown for some
    scale, n = relative_scale(true_depth, X_ref, angle, np.ones(len(x0), bool))
    assert n > 100 and scale == pytest.approx(1.3, rel=1e-6)
    none, n_few = relative_scale(np.full(len(x0), np.nan), X_ref, angle, np.ones(len(x0), bool))
    assert none is None and n_few == 0


def test_smoothing_changes_translations_only():
    rng = np.random.default_rng(0)
    n = 30
    poses = np.array([make_se3(so3_exp(rng.normal(0, 0.05, 3)), np.array([k, 0.0, 0.0]) + rng.normal(0, 0.1, 3))
                      for k in range(n)])
    traj = Trajectory(poses)
    smooth = smooth_translations(traj, 9, 2)
    np.testing.assert_allclose(smooth.poses_se3[:, :3, :3], traj.poses_se3[:, :3, :3], atol=1e-12)
    line = np.column_stack([np.arange(n), np.zeros(n), np.zeros(n)])
    assert np.abs(smooth.positions_xyz - line).mean() < 0.8 * np.abs(traj.positions_xyz - line).mean()
    short = smooth_translations(traj[:3], 9, 2)
    np.testing.assert_allclose(short.poses_se3, traj[:3].poses_se3, atol=1e-12)



def test_smoothing_settings_follow_the_smoothing_config_rules():
    """smooth_translations checked nothing: polyorder 2.5 fitted a cubic while its note said 2.5, window 8 ran with 7
    and blamed the pose count, window 0 said "30 poses leave no odd window", polyorder -1 was an IndexError. Each is the
    ConfigError SmoothingConfig gives, naming the argument; a valid window longer than the trajectory still shrinks."""
    rng = np.random.default_rng(0)
    poses = np.tile(np.eye(4), (30, 1, 1))
    poses[:, :3, 3] = np.cumsum(rng.normal(size=(30, 3)), axis=0)
    traj = Trajectory(poses, 0.1 * np.arange(30))
    refusals = {
        (9, 2.5): "polyorder: Input should be a valid integer, got a number with a fractional part (got 2.5)",
        (8, 2): "smooth_translations: window must be odd (the filter is centred on each pose), got 8",
        (0, 2): "window: Input should be greater than or equal to 3 (got 0)",
        (-3, 2): "window: Input should be greater than or equal to 3 (got -3)",
        (9, -1): "polyorder: Input should be greater than or equal to 1 (got -1)",
        (9, 8): "smooth_translations: polyorder (8) must be below window - 1 (8): a polynomial of that order passes "
                "through every pose of the window and smooths nothing",
    }
    for (window, polyorder), message in refusals.items():
        with pytest.raises(ConfigError) as refused:
            smooth_translations(traj, window, polyorder)
        assert str(refused.value) == message
    assert smooth_translations(traj, 31, 2).meta["smoothing"] == "window 29, polyorder 2 (window 31 shrunk to fit 30 poses)"
    whole = smooth_translations(traj, 9.0, 2)  # (a whole number, as SmoothingConfig takes it)
    assert whole.meta["smoothing"] == "window 9, polyorder 2"
    np.testing.assert_array_equal(whole.positions_xyz, smooth_translations(traj, 9, 2).positions_xyz)

def test_intrinsics_guess_and_files(tmp_path):
    K = K_from_image_size(1241, 376)
    assert K[0, 0] == pytest.approx(0.9 * 1241) and K[0, 2] == pytest.approx(620.0) and K[1, 2] == pytest.approx(187.5)
    from lidarkit.io.images import read_intrinsics

    (tmp_path / "k9.txt").write_text("700 0 600\n0 700 180\n0 0 1\n")
    (tmp_path / "k4.txt").write_text("# fx fy cx cy\n700 710 600 180\n")
    (tmp_path / "bad.txt").write_text("700 0 600\n")
    np.testing.assert_allclose(read_intrinsics(tmp_path / "k9.txt")[0], [700, 0, 600])
    assert read_intrinsics(tmp_path / "k4.txt")[1, 1] == 710
    kitti = read_intrinsics(shared_path("kitti_images", "sequences", "06", "calib.txt"))
    assert kitti[0, 0] == pytest.approx(707.0912)
    with pytest.raises(DataError, match="expected 9 numbers"):
        read_intrinsics(tmp_path / "bad.txt")
    with pytest.raises(DataError, match="invalid image size"):
        K_from_image_size(0, 10)


def test_intrinsics_that_are_no_numbers_are_data_errors():
    """A str focal length was a raw ValueError, a str image size a raw TypeError, a str focal factor was repeated
    max(w, h) times: each is the one-line DataError of the value it names."""
    from lidarkit.vo import K_matrix

    with pytest.raises(DataError) as err:
        K_matrix("a", 1, 2, 3)
    assert str(err.value) == "intrinsics: invalid intrinsics fx='a', fy=1, cx=2, cy=3"
    with pytest.raises(DataError) as err:
        K_from_image_size("1241", "376")
    assert str(err.value) == "intrinsics: invalid image size width='1241', height='376'"
    with pytest.raises(DataError) as err:
        K_from_image_size(1241, 376, focal_factor="0.9")
    assert str(err.value) == "intrinsics: invalid focal factor '0.9': must be a finite number > 0"
    with pytest.raises(DataError, match="invalid intrinsics"):
        K_matrix(np.array([700.0, 710.0]), 700, 600, 180)
    K = K_matrix(np.float32(700), np.int64(710), np.array(600.0), 180)
    np.testing.assert_array_equal(K, [[700, 0, 600], [0, 710, 180], [0, 0, 1]])
    assert K.dtype == np.float64 and K_from_image_size(1241.0, 376)[0, 0] == pytest.approx(0.9 * 1241)


def test_few_pose_inliers_with_most_correspondences_explained_is_insufficient_parallax():
    """A pair whose essential matrix explains nearly all correspondences (>= 90 %) but gives few pose inliers (at
    walking pace, or a standstill) was "too few (pose) inliers", which moves the reference on, so the baseline never
    grew. With the checks on it is insufficient parallax (the reference stays); with them off the estimator's failure
    is kept, and a pair whose matrix leaves more unexplained (lost tracking, noisy matches) stays too few inliers."""
    from dataclasses import replace

    from lidarkit.vo.two_view import TwoViewEstimate

    cfg = SanityConfig(min_inliers=30)
    explained = TwoViewEstimate(np.eye(3), np.zeros(3), np.zeros(1200, bool), "none", 0, 0.0,
                                "too few pose inliers (2) from E-ransac", epipolar_inliers=1100)
    assert check_pose(explained, cfg) == (
        "insufficient parallax (the essential matrix explains 1100 of 1200 correspondences; too few pose inliers (2) "
        "from E-ransac): baseline short for the scene depth, translation direction undefined")
    assert check_pose(explained, SanityConfig(enabled=False)) == "too few pose inliers (2) from E-ransac"
    lost = TwoViewEstimate(np.eye(3), np.zeros(3), np.zeros(1200, bool), "none", 0, 0.0,
                           "too few pose inliers (2) from E-ransac", epipolar_inliers=800)  # 67 %: noisy or lost
    assert check_pose(lost, cfg) == "too few pose inliers (2) from E-ransac"
    near_few = TwoViewEstimate(np.eye(3), np.array([0, 0, 1.0]), np.ones(1200, bool), "E-ransac", 12, 5.0,
                               epipolar_inliers=1150)
    assert check_pose(near_few, cfg) == (
        "insufficient parallax (the essential matrix explains 1150 of 1200 correspondences; too few inliers (12 < 30)): "
        "baseline short for the scene depth, translation direction undefined")
    assert check_pose(replace(near_few, epipolar_inliers=1000), cfg) == "too few inliers (12 < 30)"


def test_the_feature_budget_is_shared_over_the_grid_cells_as_documented():
    """The budget is no upper bound: each of the grid's cells keeps up to ceil(budget / cells) (gftt on a KITTI frame:
    32 corners for a budget of 8, 128 for 100, with the 4 x 8 grid); the detector, the config and the docs say so."""
    from pathlib import Path

    image = _kitti_pair("06", 0)[0]
    for budget, expected in ((8, 32), (100, 128)):
        for detector in ("gftt", "fast", "orb"):
            det = get_detector(detector, max_features=budget)
            assert det.per_cell_budget == -(-budget // 32)
            found = len(det.detect(image)[0])
            assert found <= 32 * det.per_cell_budget, (detector, budget, found)
            if detector == "gftt":
                assert found == expected
    alone = get_detector("gftt", max_features=100, grid_rows=1, grid_cols=1)
    assert alone.per_cell_budget == 100 and len(alone.detect(image)[0]) == 100
    assert "ceil(max_features / cells)" in FeatureConfig.model_fields["max_features"].description
    docs = (Path(__file__).resolve().parents[1] / "docs" / "visual_odometry.md").read_text()
    row = next(line for line in docs.splitlines() if line.startswith("| detector / descriptor |"))
    assert "ceil(budget / cells)" in row and "32 corners for a budget of 8 and 128 for 100" in row


def test_check_pose_refuses_what_is_no_two_view_estimate():
    """check_pose(None) raised AttributeError ('NoneType' object has no attribute 'fundamental_inliers'), a dict as the
    config another: one-line ConfigErrors naming the argument; a real estimate is still judged."""
    rng = np.random.default_rng(3)
    x0, x1, K = _synthetic_correspondences(rng, t=np.array([0.2, -0.05, 1.0]))
    cv2.setRNGSeed(1)
    estimate = estimate_two_view(x0, x1, K)
    assert estimate.ok and check_pose(estimate) is None and check_pose(estimate, SanityConfig()) is None
    with pytest.raises(ConfigError) as refused:
        check_pose(None)
    assert str(refused.value) == ("estimate: estimate must be a TwoViewEstimate (lidarkit.vo.estimate_two_view), "
                                  "got NoneType None")
    with pytest.raises(ConfigError) as refused:
        check_pose(estimate, {"enabled": False})
    assert str(refused.value) == "cfg: cfg must be a SanityConfig or None, got dict {'enabled': False}"
