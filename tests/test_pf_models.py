"""Particle-filter building blocks: models, log-weight normalization, resamplers, the filter's steps."""

from __future__ import annotations

import numpy as np
import pytest

from lidarkit.errors import ConfigError, DataError
from lidarkit.pf import PFConfig, ParticleFilter, get_resampler, integrate_odometry, make_filter, resolve_q, wrap_angle
from lidarkit.pf.kalman_kernel import KalmanParticleFilter
from lidarkit.pf.models import OdometryMotionModel, RangeBearingModel, standard_normal
from lidarkit.pf.resampling import available_resamplers, effective_sample_size

LANDMARKS = np.array([[2.0, 1.0], [0.0, 4.0], [2.0, 7.0], [9.0, 2.0], [5.0, 5.0]])


# ---- models -------------------------------------------------------------------------------------------
def test_wrap_angle_range_and_identity():
    a = np.linspace(-20, 20, 4001)
    w = wrap_angle(a)
    assert (w >= -np.pi).all() and (w < np.pi).all()
    np.testing.assert_allclose(np.sin(w), np.sin(a), atol=1e-12)
    np.testing.assert_allclose(np.cos(w), np.cos(a), atol=1e-12)


def test_integrate_odometry_square():
    # four times: turn 90 deg, drive 1 m -> back at the start, heading back to 0 (after 4 turns)
    odo = np.array([[np.pi / 2, 1.0, 0.0]] * 4)
    poses = integrate_odometry(odo)
    np.testing.assert_allclose(poses[1], [0.0, 1.0, np.pi / 2], atol=1e-12)
    np.testing.assert_allclose(poses[2], [-1.0, 1.0, -np.pi], atol=1e-12)
    np.testing.assert_allclose(poses[4, :2], [0.0, 0.0], atol=1e-12)
    assert abs(wrap_angle(poses[4, 2])) < 1e-12


def test_motion_model_matches_integration_without_noise_and_has_the_stated_spread(rng):
    odo = np.array([0.3, 0.5, -0.1])
    states = np.zeros((3, 20000), dtype=np.float64)
    OdometryMotionModel.apply(states, odo, None)
    np.testing.assert_allclose(states[:, 0], integrate_odometry(odo[None])[1], atol=1e-12)
    model = OdometryMotionModel((0.01, 0.1, 0.02))
    states = np.zeros((3, 20000), dtype=np.float32)
    controls = model.controls_block(rng, odo[None], 4, 20000, np.float32)
    assert controls.shape == (1, 3, 20000)  # noise drawn for 4 steps, 1 step of odometry left
    model.apply_controls(states, controls[0])
    travel = np.hypot(states[0], states[1])
    assert np.std(travel) == pytest.approx(0.1, rel=0.05)
    assert np.std(states[2]) == pytest.approx(np.hypot(0.01, 0.02), rel=0.05)
    assert np.mean(states[2]) == pytest.approx(0.2, abs=0.001)


def test_box_muller_float32_is_standard_normal(rng):
    x = standard_normal(rng, (200001,), np.float32)
    assert x.dtype == np.float32 and x.shape == (200001,)
    assert abs(x.mean()) < 0.01 and x.std() == pytest.approx(1.0, abs=0.01)
    # tail probability P(|x| > 2) = 0.0455
    assert (np.abs(x) > 2).mean() == pytest.approx(0.0455, abs=0.003)


def test_resolve_q_variance_vs_std():
    np.testing.assert_allclose(resolve_q((1.0, 0.1), "variance"), np.diag([1.0, 0.1]))
    np.testing.assert_allclose(resolve_q((1.0, 0.1), "std"), np.diag([1.0, 0.01]))
    with pytest.raises(ConfigError, match="q_as"):
        resolve_q((1.0, 0.1), "sigma")
    with pytest.raises(ConfigError, match="positive definite"):
        resolve_q((1.0, -0.1))


def test_sensor_loglik_matches_direct_gaussian_and_wraps_bearing():
    model = RangeBearingModel(np.array([[0.5, 0.1], [0.1, 0.2]]))
    states = np.array([[0.0, 1.0, 3.0], [0.0, -1.0, 2.0], [0.1, 3.0, -3.1]])
    z = np.array([[2.0, 3.1], [4.0, -3.0]])  # bearings near +-pi: residuals must wrap
    lm = LANDMARKS[[0, 1]]
    ll = model.log_likelihood_all(states, lm, z)
    info = np.linalg.inv(model.q_cov)
    for i in range(3):
        total = 0.0
        for m in range(2):
            h = RangeBearingModel.expected(states[:, i], lm[m : m + 1])[0]
            e = z[m] - h
            e[1] = (e[1] + np.pi) % (2 * np.pi) - np.pi
            assert abs(e[1]) <= np.pi
            total += -0.5 * e @ info @ e
        assert ll[i] == pytest.approx(total, rel=1e-9)


def test_nearest_per_particle_association_uses_each_particles_closest_landmark():
    model = RangeBearingModel(np.diag([0.1, 0.1]))
    # particle 0 next to landmark 0, particle 1 next to landmark 4
    states = np.array([[2.0, 5.0], [0.0, 4.0], [0.0, 0.0]])
    z = np.array([1.0, np.pi / 2])  # 1 m straight to the left
    ll = model.log_likelihood_nearest(states, LANDMARKS, z)
    np.testing.assert_allclose(ll, [0.0, 0.0], atol=1e-12)


# ---- weights ------------------------------------------------------------------------------------------
def test_far_away_particles_do_not_underflow_and_closest_wins():
    cfg = PFConfig.make(n_particles=5, dtype="float64", q=(0.01, 0.001))
    pf = ParticleFilter(LANDMARKS, cfg, 0)
    far = np.array([[1e4, 1e4, 0.0], [2e4, 1e4, 0.0], [1e4, 3e4, 0.0], [5e4, 5e4, 1.0], [1e5, 0.0, 0.0]])
    pf.set_particles(far)
    naive = np.exp(pf.log_likelihood(np.array([0, 1]), np.array([[1.0, 0.0], [2.0, 0.5]])))
    assert (naive == 0).all()  # what a plain exp would give
    assert pf.update(np.array([0, 1]), np.array([[1.0, 0.0], [2.0, 0.5]]))
    assert np.isfinite(pf.weights).all() and pf.weights.sum() == pytest.approx(1.0)
    assert int(np.argmax(pf.weights)) == 0
    assert np.isfinite(pf.estimate("mean")).all() and pf.n_weight_resets == 0
    assert pf.resample() and np.isfinite(pf.particles).all()


def test_all_non_finite_likelihoods_reset_to_uniform_and_are_counted():
    pf = ParticleFilter(LANDMARKS, PFConfig.make(n_particles=4), 0)
    pf.apply_log_likelihood(np.full(4, np.nan))
    assert pf.n_weight_resets == 1
    np.testing.assert_allclose(pf.weights, 0.25)
    pf.apply_log_likelihood(np.array([np.nan, -np.inf, 0.0, -1.0]))  # partly broken: use the finite ones
    assert pf.weights[0] == 0 and pf.weights[1] == 0 and pf.weights[2] > pf.weights[3] > 0
    assert pf.n_weight_resets == 1


def test_ess():
    assert effective_sample_size(np.full(10, 0.1)) == pytest.approx(10)
    assert effective_sample_size(np.eye(10)[3]) == pytest.approx(1)


# ---- resamplers ---------------------------------------------------------------------------------------
WEIGHTS = np.array([0.31, 0.005, 0.2, 0.075, 0.13, 0.01, 0.27])


@pytest.mark.parametrize("name", ["multinomial", "systematic", "stratified", "residual"])
def test_resampler_counts_are_unbiased_with_bounded_variance(name):
    rng = np.random.default_rng(2024)
    n, reps = len(WEIGHTS) * 10, 4000
    resample = get_resampler(name)
    counts = np.stack([np.bincount(resample(WEIGHTS, rng, n), minlength=len(WEIGHTS)) for _ in range(reps)])
    assert (counts.sum(axis=1) == n).all()
    expected = n * WEIGHTS
    var_multinomial = n * WEIGHTS * (1 - WEIGHTS)
    # E[count_i] = n w_i: within 4 standard errors of the multinomial bound
    np.testing.assert_array_less(np.abs(counts.mean(axis=0) - expected), 4 * np.sqrt(var_multinomial / reps) + 1e-9)
    var = counts.var(axis=0)
    if name == "multinomial":
        np.testing.assert_allclose(var, var_multinomial, rtol=0.12)
    else:
        assert (var <= var_multinomial * 1.05).all()
    if name == "systematic":  # every count is floor or ceil of n w_i
        assert ((counts == np.floor(expected)) | (counts == np.ceil(expected))).all()
        assert (var <= 0.25 + 1e-9).all()
    if name == "residual":
        assert (counts >= np.floor(expected)).all()
    if name == "stratified":
        assert ((counts >= np.floor(expected) - 1) & (counts <= np.ceil(expected) + 1)).all()


def test_resampler_factory_and_edge_cases(rng):
    assert available_resamplers() == ["multinomial", "systematic", "stratified", "residual"]
    with pytest.raises(ConfigError, match="known: multinomial"):
        get_resampler("roulette")
    one_hot = np.zeros(50)
    one_hot[17] = 1.0
    for name in available_resamplers():
        idx = get_resampler(name)(one_hot, rng)
        assert idx.shape == (50,) and (idx == 17).all()
        assert get_resampler(name)(np.ones(1), rng).tolist() == [0]


# ---- filter -------------------------------------------------------------------------------------------
def test_config_validation():
    with pytest.raises(ConfigError, match="n_particles"):
        PFConfig.make(n_particles=0)
    with pytest.raises(ConfigError, match="resampler"):
        PFConfig.make(resampler="roulette")
    with pytest.raises(ConfigError, match="ess_threshold"):
        PFConfig.make(ess_threshold=-1)


def test_predict_rejects_non_finite_odometry_and_empty_update_is_predict_only():
    pf = ParticleFilter(LANDMARKS, PFConfig.make(n_particles=100), 1)
    with pytest.raises(DataError, match="non-finite odometry"):
        pf.predict(np.array([0.0, np.nan, 0.0]))
    pf.predict(np.array([0.0, 0.1, 0.0]))
    assert pf.update(np.zeros(0, dtype=int), np.zeros((0, 2))) is False
    assert not pf.resample() and pf.n_resamples == 0  # uniform weights: nothing to resample


def test_filter_localizes_a_simulated_robot_with_every_kernel_and_estimator():
    rng = np.random.default_rng(7)
    odo = np.tile([0.05, 0.1, 0.0], (60, 1))
    truth = integrate_odometry(odo, (1.0, 1.0, 0.0))
    model = RangeBearingModel(np.diag([0.05, 0.01]))
    for kernel, n in (("point", 500), ("kalman", 20)):
        cfg = PFConfig.make(n_particles=n, kernel=kernel, q=(0.05, 0.01), init_mean=(1.0, 1.0, 0.0), init_std=(0.3, 0.3, 0.1))
        pf = make_filter(LANDMARKS, cfg, 3)
        assert isinstance(pf, KalmanParticleFilter if kernel == "kalman" else ParticleFilter)
        errors = []
        for t in range(60):
            pf.predict(odo[t])
            z = model.expected(truth[t + 1], LANDMARKS) + rng.normal(0, [np.sqrt(0.05), 0.1], (5, 2))
            pf.update(np.arange(5), z)
            errors.append(np.hypot(*(pf.estimate("mean")[:2] - truth[t + 1, :2])))
            assert np.hypot(*(pf.estimate("best")[:2] - truth[t + 1, :2])) < 1.0
            pf.resample()
        assert np.mean(errors[10:]) < 0.15, kernel


def test_identical_seeds_identical_results_and_different_seeds_differ():
    def run(seed: int, **kw) -> np.ndarray:
        pf = ParticleFilter(LANDMARKS, PFConfig.make(n_particles=300, **kw), seed)
        for _ in range(5):
            pf.predict([0.1, 0.2, 0.0])
            pf.update(np.array([0, 4]), np.array([[2.0, 0.3], [5.0, 0.8]]))
            pf.resample()
        return pf.particles.copy()

    for kw in ({}, {"resampler": "residual", "roughening": 0.1, "antithetic": True}, {"moment_matching": "mean_cov"}):
        np.testing.assert_array_equal(run(5, **kw), run(5, **kw))
    assert not np.array_equal(run(5), run(6))


def test_roughening_jitters_a_cloud_facing_pi_as_one_facing_zero():
    """Gordon's roughening scales the jitter by the cloud's spread: a tight cloud whose headings straddle +-pi spans a
    few degrees, not 2 pi (its heading jitter was 10x the same cloud's at heading 0)."""
    rng = np.random.default_rng(0)
    cloud = np.column_stack([rng.normal(0, 0.1, 1000), rng.normal(0, 0.1, 1000), rng.normal(0, 0.05, 1000)])
    out = {}
    for heading in (0.0, np.pi):
        pf = ParticleFilter(LANDMARKS, PFConfig.make(n_particles=1000, roughening=0.1, dtype="float64"), 1)
        turned = cloud.copy()
        turned[:, 2] = wrap_angle(turned[:, 2] + heading)
        pf.set_particles(turned, np.ones(1000))
        pf.resample(force=True)
        out[heading] = pf.particles.copy()
    np.testing.assert_allclose(out[np.pi][:, :2], out[0.0][:, :2], atol=1e-12)
    np.testing.assert_allclose(wrap_angle(out[np.pi][:, 2] - np.pi), out[0.0][:, 2], atol=1e-9)


def test_uniform_init_covers_the_map_and_ess_threshold_skips_resampling():
    pf = ParticleFilter(LANDMARKS, PFConfig.make(n_particles=4000, ess_threshold=0.5), 0)
    pf.initialize_uniform()
    p = pf.particles
    assert p[:, 0].min() >= -2 and p[:, 0].max() <= 11 and p[:, 1].min() >= -1 and p[:, 1].max() <= 9
    assert np.ptp(p[:, 2]) > 6.0
    pf.apply_log_likelihood(np.full(4000, -3.0) + 1e-3 * np.arange(4000) / 4000)  # nearly flat: ESS ~ N
    assert not pf.resample() and pf.n_resamples == 0
    pf.apply_log_likelihood(-0.5 * ((pf.states[0] - 5.0) / 0.5) ** 2)  # peaked: ESS << N/2
    assert pf.ess < 2000 and pf.resample() and pf.n_resamples == 1


def test_moment_matching_preserves_weighted_mean_and_covariance():
    pf = ParticleFilter(LANDMARKS, PFConfig.make(n_particles=2000, moment_matching="mean_cov", dtype="float64"), 0)
    pf.apply_log_likelihood(-0.5 * ((pf.states[0] - 1.0) / 0.7) ** 2)
    mean_b, cov_b, _ = pf._moments(pf.weights, True)
    pf.resample()
    mean_a, cov_a, _ = pf._moments(pf.weights, True)
    np.testing.assert_allclose(mean_a[:2], mean_b[:2], atol=1e-9)
    assert mean_a[2] == pytest.approx(mean_b[2], abs=1e-4)  # circular mean: matched to first order
    np.testing.assert_allclose(cov_a, cov_b, atol=1e-6)


def test_systematic_count_path_matches_search_path():
    rng = np.random.default_rng(11)
    w = rng.random(30000) ** 4
    w /= w.sum()
    idx = get_resampler("systematic")(w, np.random.default_rng(5))  # counts + repeat, no search
    u0 = np.random.default_rng(5).random()
    cdf = np.cumsum(w) * 30000 / w.sum()
    cdf[-1] = 30000
    expected = np.minimum(np.searchsorted(cdf, np.arange(30000) + u0, side="left"), 29999)
    np.testing.assert_array_equal(idx, expected)


def test_sequence_prediction_equals_step_by_step_prediction():
    odo = np.array([[0.1, 0.2, -0.05], [0.0, 0.1, 0.02], [-0.2, 0.3, 0.0]] * 5)
    cfg = PFConfig.make(n_particles=500, dtype="float64", noise_block_elements=3 * 500 * 4)
    a, b = ParticleFilter(LANDMARKS, cfg, 9), ParticleFilter(LANDMARKS, cfg, 9)
    b.begin_odometry(odo)
    for u in odo:
        a.predict(u)
        b.predict_next()
    np.testing.assert_allclose(a.particles, b.particles, atol=1e-12)
    with pytest.raises(DataError, match="no odometry left"):
        b.predict_next()


def test_update_rejects_landmark_indices_outside_the_map_with_every_kernel():
    z = np.array([[1.0, 0.1]])
    for kernel in ("point", "kalman"):
        pf = make_filter(LANDMARKS, PFConfig.make(n_particles=50, kernel=kernel), 1)
        for bad in (-1, len(LANDMARKS)):
            with pytest.raises(DataError, match=rf"landmark index {bad} outside 0\.\.4"):
                pf.update(np.array([bad]), z)
        assert pf.update(np.array([len(LANDMARKS) - 1]), z) is True


@pytest.mark.parametrize("sequence", [False, True])
def test_headings_stay_wrapped_and_precise_over_many_turning_steps(sequence):
    # 4000 steps of 0.6 rad turn: unwrapped, float32 theta reaches 2400 rad (resolution 2.4e-4 rad) and drifts
    odo = np.tile([0.3, 0.05, 0.3], (4000, 1))
    cfg = PFConfig.make(n_particles=20, motion_noise_std=(0.0, 0.0, 0.0), estimator="best")
    pf = ParticleFilter(LANDMARKS, cfg, 3)
    pf.initialize_gaussian(mean=np.zeros(3), std=np.zeros(3))
    truth = integrate_odometry(odo)
    if sequence:
        pf.begin_odometry(odo)
    for u in odo:
        pf.predict_next() if sequence else pf.predict(u)
    theta = pf.particles[:, 2]
    assert (np.abs(theta) <= np.float32(np.pi)).all()
    best = pf.estimate("best")
    assert -np.pi <= best[2] < np.pi
    assert abs(wrap_angle(best[2] - truth[-1, 2])) < 1e-3
    np.testing.assert_allclose(best[:2], truth[-1, :2], atol=1e-3)


@pytest.mark.parametrize("field, value", [("init_mean", (1e20, 0.0, 0.0)), ("init_mean", (1e39, 0.0, 0.0)), ("init_std", (1.0, 1e20, 1.0)),
                                          ("uniform_margin_m", 1e30), ("motion_noise_std", (0.0, 1e20, 0.0))])
def test_pose_scales_beyond_any_map_are_refused(field, value):
    """init_mean / init_std / uniform_margin_m / motion_noise_std 1e20 ran 331 weight resets (MSE 1e40, exit 0); init_mean
    1e39 overflowed float32 and failed later as "pose is NaN". Refused up front naming the field, as Q is."""
    with pytest.raises(ConfigError) as exc:
        PFConfig.make(**{field: value})
    assert exc.value.source == f"pf config {field}"
    assert str(exc.value) == (f"pf config {field}: values must be at most 1e+06 in magnitude (m or rad: 1000 km is past any map), "
                              f"got {value}")
    assert PFConfig.make(init_mean=(1e6, -1e6, 0.1), uniform_margin_m=1e6).init_mean == (1e6, -1e6, 0.1)  # the bound itself is fine


def test_kld_title_range_includes_a_first_count_below_kld_min():
    """-n 100 --kld: the title read "N=200..5,000 (KLD)" while the run started with 100 particles."""
    assert PFConfig.make(n_particles=100, kld=True).particle_count_label() == "100..5,000 (KLD)"
    assert PFConfig.make(n_particles=1000, kld=True).particle_count_label() == "200..5,000 (KLD)"


def test_innovation_nis_and_stats_check_their_readings_as_update_does():
    """innovation_nis / innovation_stats took index -1 as the last landmark (the same NIS as index 4), index 9 was a
    bare IndexError, a NaN reading gave NIS nan and a count mismatch went unseen: they now check as update() does."""
    z = np.array([[2.0, 0.3]])
    for kernel in ("point", "kalman"):
        pf = make_filter(LANDMARKS, PFConfig.make(n_particles=50, kernel=kernel), 1)
        for call, line in (
            (lambda: pf.innovation_nis([-1], z), "innovation_nis: landmark index -1 outside 0..4 (reading 0)"),
            (lambda: pf.innovation_nis([9], z), "innovation_nis: landmark index 9 outside 0..4 (reading 0)"),
            (lambda: pf.innovation_nis([0], [[np.nan, 0.3]]), "innovation_nis: non-finite measurement"),
            (lambda: pf.innovation_stats([0, 1.5], [[1.0, 0.1], [2.0, 0.2]]),
             "innovation_stats: landmark index must be an integer, got 1.5 (reading 1)"),
            (lambda: pf.innovation_stats([0, 1], z), "innovation_stats: 2 landmark indices for 1 readings"),
        ):
            with pytest.raises(DataError) as exc:
                call()
            assert str(exc.value) == line, kernel
        nis = pf.innovation_nis([4], z)
        assert nis.shape == (1,) and np.isfinite(nis).all() and nis[0] > 0.0


def test_update_refuses_a_landmark_index_that_is_no_integer():
    """update([1.9], z) weighed landmark 1 (the int64 cast cut 1.9 to 1), True read as 1: both are refused; a whole
    number given as a float (2.0, as a text file reads it) is still index 2."""
    z = np.array([[2.0, 0.3]])
    for kernel in ("point", "kalman"):
        for bad in (1.9, True, np.inf, "a"):
            pf = make_filter(LANDMARKS, PFConfig.make(n_particles=50, kernel=kernel), 1)
            with pytest.raises(DataError) as exc:
                pf.update(np.array([bad]), z)
            assert str(exc.value) == f"update: landmark index must be an integer, got {bad!r} (reading 0)", kernel
            assert pf.n_updates == 0
        a = make_filter(LANDMARKS, PFConfig.make(n_particles=50, kernel=kernel), 1)
        b = make_filter(LANDMARKS, PFConfig.make(n_particles=50, kernel=kernel), 1)
        assert a.update(np.array([2.0]), z) and b.update(np.array([2]), z)
        np.testing.assert_array_equal(a.weights, b.weights)


def test_noise_block_elements_must_be_an_integer_of_at_least_one():
    """noise_block_elements -5, 0 and True were taken (written to config.yaml; the filter drew blocks of 1 instead)."""
    for value in (-5, 0, True, 2.5):
        with pytest.raises(ConfigError) as exc:
            PFConfig.make(noise_block_elements=value)
        assert str(exc.value) == f"pf config noise_block_elements: must be an integer >= 1, got {value!r}"
    assert PFConfig.make(noise_block_elements=np.int64(3000)).noise_block_elements == 3000


def test_initialize_gaussian_refuses_a_mean_or_std_that_config_would_refuse():
    """initialize_gaussian([nan, 0, 0]) and std [-1, -1, -1] were taken: the next update logged "no particle has a
    finite log-likelihood" and the estimate was NaN; a mean of 2 values was numpy's "cannot reshape"."""
    for kernel in ("point", "kalman"):
        pf = make_filter(LANDMARKS, PFConfig.make(n_particles=50, kernel=kernel), 1)
        for call, line in (
            (lambda: pf.initialize_gaussian(np.array([np.nan, 0, 0])),
             "initialize_gaussian: mean must be 3 finite values [x_m, y_m, theta_rad], got [nan, 0.0, 0.0]"),
            (lambda: pf.initialize_gaussian(std=[-1, -1, -1]),
             "initialize_gaussian: std must be 3 finite values >= 0 [x_m, y_m, theta_rad], got [-1, -1, -1]"),
            (lambda: pf.initialize_gaussian([1.0, 2.0]),
             "initialize_gaussian: mean must be 3 finite values [x_m, y_m, theta_rad], got [1.0, 2.0]"),
        ):
            with pytest.raises(ConfigError) as exc:
                call()
            assert str(exc.value) == line, kernel
        pf.initialize_gaussian([1.0, 2.0, 0.0], [0.0, 0.0, 0.0])
        np.testing.assert_allclose(pf.estimate("mean"), [1.0, 2.0, 0.0], atol=1e-6)


def test_readings_of_the_wrong_shape_or_text_are_a_data_error_naming_the_method():
    """update([0], [1.0, 0.1, 0.3]) (or [[1.0, 0.1, 0.3]], or text) failed with numpy's "cannot reshape array of size 3
    into shape (2)" / "could not convert string to float", not a DataError as a count mismatch gets."""
    for kernel in ("point", "kalman"):
        pf = make_filter(LANDMARKS, PFConfig.make(n_particles=50, kernel=kernel), 1)
        for method in ("update", "innovation_nis", "innovation_stats"):
            for z, reason in (([1.0, 0.1, 0.3], "readings must be an (M, 2) array [range_m, bearing_rad], got shape (3,)"),
                              ([[1.0, 0.1, 0.3]], "readings must be an (M, 2) array [range_m, bearing_rad], got shape (1, 3)"),
                              ([["a", "b"]], "readings must be numbers [range_m, bearing_rad], got ['a', 'b']")):
                with pytest.raises(DataError) as exc:
                    getattr(pf, method)(np.array([0]), z)
                assert str(exc.value) == f"{method}: {reason}", kernel
        assert pf.n_updates == 0
        assert pf.update(np.array([0]), [2.0, 0.3]) is True  # one reading as (2,) is still one reading
        assert pf.update(np.array([], dtype=np.int64), []) is False


# ---- bad arguments ------------------------------------------------------------------------------------
def test_pf_config_built_directly_is_the_one_line_config_error_make_gives():
    """docs/particle_filter.md builds PFConfig(...) directly: PFConfig(kernel="kalmann") raised pydantic's ValidationError
    (lines long, with a URL) where PFConfig.make said it in one line."""
    for values, message in (
        ({"kernel": "kalmann"}, "pf config kernel: Input should be 'point' or 'kalman' (got 'kalmann')"),
        ({"n_particles": 0}, "pf config n_particles: n_particles must be >= 1 and <= 10000000, got 0"),
        ({"kld": True, "kld_min_n": 10, "kld_max_n": 5}, "pf config: kld_min_n 10 > kld_max_n 5"),
    ):
        for build in (PFConfig, PFConfig.make, lambda **v: PFConfig.model_validate(v), PFConfig().replace):
            with pytest.raises(ConfigError) as err:
                build(**values)
            assert str(err.value) == message
    with pytest.raises(ConfigError, match=r"^pf config: unknown setting 'n_partcles'; valid: alpha_fast, alpha_slow, "):
        PFConfig(n_partcles=10)
    assert PFConfig(n_particles=7) == PFConfig.make(n_particles=7)


def test_particle_filter_arguments_of_the_wrong_kind_are_one_line_errors_naming_them():
    """rng="x" was numpy's TypeError, rng=-1 its ValueError, a dict config an AttributeError (MonoVO and the ICP
    variants refuse a dict config too) and predict("abc") a ValueError."""
    rng_rule = "rng: rng must be a numpy.random.Generator, an integer seed >= 0 or None, got"
    for call, error, message in (
        (lambda: ParticleFilter(LANDMARKS, rng="x"), ConfigError, f"{rng_rule} 'x'"),
        (lambda: ParticleFilter(LANDMARKS, rng=-1), ConfigError, f"{rng_rule} -1"),
        (lambda: ParticleFilter(LANDMARKS, rng=1.5), ConfigError, f"{rng_rule} 1.5"),
        (lambda: ParticleFilter(LANDMARKS, rng=True), ConfigError, f"{rng_rule} True"),
        (lambda: ParticleFilter(LANDMARKS, config={"n_particles": 10}), ConfigError,
         "ParticleFilter: config must be a PFConfig (PFConfig(...) or PFConfig.make(...)), got dict"),
        (lambda: KalmanParticleFilter(LANDMARKS, config={"n_particles": 10}), ConfigError,
         "KalmanParticleFilter: config must be a PFConfig (PFConfig(...) or PFConfig.make(...)), got dict"),
        (lambda: ParticleFilter(LANDMARKS, PFConfig.make(n_particles=10)).predict("abc"), DataError,
         "predict: odometry must be numbers [r1, t, r2], got 'abc'"),
        (lambda: ParticleFilter(LANDMARKS, PFConfig.make(n_particles=10)).predict([1.0, 2.0]), DataError,
         "predict: odometry must be [r1, t, r2], got shape (2,)"),
        (lambda: ParticleFilter("abc"), DataError, "landmarks: landmarks must be numbers, an (L, 2) array or a LandmarkMap, got 'abc'"),
    ):
        with pytest.raises(error) as err:
            call()
        assert str(err.value) == message
    # a seed given as numpy's integer and the Generator it seeds give the same particles; None draws fresh entropy
    cfg = PFConfig.make(n_particles=20)
    seeded = ParticleFilter(LANDMARKS, cfg, np.int64(4))
    np.testing.assert_array_equal(seeded.states, ParticleFilter(LANDMARKS, cfg, np.random.default_rng(4)).states)
    assert ParticleFilter(LANDMARKS, cfg, None).states.shape == (3, 20)


def test_kalman_kernel_predict_refuses_bad_odometry_in_one_line_as_the_particle_filter_does():
    """KalmanParticleFilter.predict("abc") raised numpy's ValueError; it now checks its odometry with the particle
    filter's checked_odometry, and a good step still moves the kernels."""
    for odometry, message in (("abc", "predict: odometry must be numbers [r1, t, r2], got 'abc'"),
                              ([1.0, 2.0], "predict: odometry must be [r1, t, r2], got shape (2,)"),
                              ([0.0, np.nan, 0.0], "predict: non-finite odometry [0.0, nan, 0.0]")):
        kalman = KalmanParticleFilter(LANDMARKS, PFConfig.make(kernel="kalman", n_particles=5), 0)
        with pytest.raises(DataError) as err:
            kalman.predict(odometry)
        assert str(err.value) == message
    kalman = KalmanParticleFilter(LANDMARKS, PFConfig.make(kernel="kalman", n_particles=5), 0)
    before = kalman.states.copy()
    kalman.predict([0.0, 2.0, 0.0])
    np.testing.assert_allclose(kalman.states[:2], before[:2] + 2.0 * np.stack([np.cos(before[2]), np.sin(before[2])]))


def test_ess_takes_array_likes_and_refuses_weights_that_are_none():
    """A list was an AttributeError, an empty array inf (with a RuntimeWarning), negative weights a number."""
    import warnings

    assert effective_sample_size([0.25] * 4) == pytest.approx(4)
    assert effective_sample_size([1, 1, 1, 1]) == pytest.approx(4)  # Kish's (sum w)^2 / sum w^2: normalized or not
    assert effective_sample_size(np.float32([0.5, 0.5, 0.0])) == pytest.approx(2)
    for weights, message in (
        (np.array([]), "weights: the effective sample size needs weights of shape (N,) with N >= 1, got shape (0,)"),
        ([[0.5, 0.5]], "weights: the effective sample size needs weights of shape (N,) with N >= 1, got shape (1, 2)"),
        ([-1.0, 2.0], "weights: the effective sample size needs finite weights >= 0 that are not all zero (sum 1, smallest -1)"),
        ([np.nan, 1.0], "weights: the effective sample size needs finite weights >= 0 that are not all zero (sum nan, smallest nan)"),
        ("abc", "weights: weights must be numbers, got 'abc'"),
    ):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            with pytest.raises(DataError) as err:
                effective_sample_size(weights)
        assert str(err.value) == message
    # the resamplers take a list too, and name an empty one (it failed in numpy's min)
    assert get_resampler("systematic")([0.0, 1.0], np.random.default_rng(0)).tolist() == [1, 1]
    with pytest.raises(DataError, match=r"^weights: resampling needs weights of shape \(N,\) with N >= 1, got shape \(0,\)$"):
        get_resampler("multinomial")([], np.random.default_rng(0))


def test_integrate_odometry_checks_shapes_and_values():
    """A (1, 6) array was read as two steps without a word; start_pose=(1, 2) failed in numpy's reshape."""
    for odometry, start, error in (
        (np.array([[0, 1, 0, 0, 1, 0]]), (0, 0, 0),
         "odometry: odometry must be a (T, 3) array [r1_rad, t_m, r2_rad], got shape (1, 6)"),
        (np.zeros((2, 3, 1)), (0, 0, 0), "odometry: odometry must be a (T, 3) array [r1_rad, t_m, r2_rad], got shape (2, 3, 1)"),
        ([[0, 1, 0], [0, np.nan, 0]], (0, 0, 0), "odometry: non-finite odometry at step 1: [0.0, nan, 0.0]"),
        ("abc", (0, 0, 0), "odometry: odometry must be numbers, a (T, 3) array [r1_rad, t_m, r2_rad], got 'abc'"),
        (np.zeros((2, 3)), (1, 2), "start_pose: start_pose must be 3 finite values [x_m, y_m, theta_rad], got [1.0, 2.0]"),
        (np.zeros((2, 3)), (0, 0, np.inf), "start_pose: start_pose must be 3 finite values [x_m, y_m, theta_rad], got [0.0, 0.0, inf]"),
    ):
        with pytest.raises(DataError) as err:
            integrate_odometry(odometry, start)
        assert str(err.value) == error
    # lists, one step given as (3,), no steps at all
    np.testing.assert_allclose(integrate_odometry([[0, 1, 0]], [1, 2, 0]), [[1, 2, 0], [2, 2, 0]])
    np.testing.assert_allclose(integrate_odometry([0, 1, 0]), [[0, 0, 0], [1, 0, 0]])
    np.testing.assert_allclose(integrate_odometry(np.zeros((0, 3)), (1, 2, 0.5)), [[1, 2, 0.5]])


def test_kalman_kernels_refuse_an_explicit_float32_they_would_ignore():
    """PFConfig(kernel="kalman", dtype="float32") was accepted and run in float64; the default dtype (unset, also through
    replace) and an explicit float64 still build a Kalman-kernel filter, which runs float64."""
    with pytest.raises(ConfigError) as err:
        PFConfig(kernel="kalman", dtype="float32")
    assert str(err.value) == ("pf config: dtype float32 is for point particles; the Kalman kernels (kernel='kalman') run "
                              "float64 (leave dtype unset)")
    with pytest.raises(ConfigError, match="dtype float32 is for point particles"):
        PFConfig(dtype="float32").replace(kernel="kalman")
    landmarks_xy = np.array([[0.0, 5.0], [5.0, 0.0]])
    for cfg in (PFConfig(kernel="kalman"), PFConfig(kernel="kalman", dtype="float64"), PFConfig().replace(kernel="kalman"),
                PFConfig(kernel="kalman").replace(likelihood="nearest", estimator="best", q_as="std")):
        pf = make_filter(landmarks_xy, cfg.replace(n_particles=4), rng=0)
        pf.initialize_gaussian()
        assert isinstance(pf, KalmanParticleFilter) and pf.states.dtype == np.float64
    assert PFConfig(kernel="kalman").replace(kernel="point").dtype == "float32"


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_antithetic_noise_pairs_neighbouring_particles_and_every_step_sums_to_zero(dtype):
    """Antithetic noise paired particle k with k + ceil(N/2), not 2k with 2k+1 as documented, and an odd N's set was not
    zero-mean (0.0099 m for N=5 at a std of 0.1 m): the unpaired last particle now gets none."""
    motion = OdometryMotionModel((0.1, 0.1, 0.1))
    for n in (2, 5, 6, 101):
        eps = motion.sample_noise(np.random.default_rng(3), 40, n, dtype, antithetic=True)
        pairs = n // 2
        assert eps.shape == (40, 3, n) and eps.dtype == dtype
        np.testing.assert_array_equal(eps[:, :, 1 : 2 * pairs : 2], -eps[:, :, 0 : 2 * pairs : 2])
        if n % 2:
            np.testing.assert_array_equal(eps[:, :, -1], 0.0)
        assert np.all(eps.sum(axis=2) == 0.0)
    wide = motion.sample_noise(np.random.default_rng(3), 50, 2000, dtype, antithetic=True)
    assert wide[:, :, 0::2].std() == pytest.approx(0.1, rel=0.02)  # the drawn half keeps the model's std


def test_antithetic_prediction_keeps_the_mean_heading_of_an_odd_particle_set():
    """The heading moves by r1 + r2 plus the summed noise, so an antithetic set's mean heading follows the odometry
    exactly; with N=5 the unpaired third particle had shifted it."""
    cfg = PFConfig.make(n_particles=5, antithetic=True, dtype="float64", motion_noise_std=(0.1, 0.1, 0.1))
    pf = make_filter(np.array([[0.0, 5.0], [5.0, 0.0]]), cfg, rng=4)
    pf.initialize_gaussian(mean=np.zeros(3), std=np.zeros(3))
    pf.predict(np.array([0.2, 1.0, 0.1]))
    assert pf.states[2].mean() == pytest.approx(0.3, abs=1e-12)


def test_every_count_setting_of_the_config_refuses_a_bool():
    """kld_min_n=True and kld_converged_steps=True were read as 1 while n_particles=True was refused."""
    counts = [name for name, field in PFConfig.model_fields.items() if field.annotation is int]
    assert {"n_particles", "kld_min_n", "kld_max_n", "kld_unconverged_n", "kld_converged_steps"} <= set(counts)
    for name in counts:
        for value in (True, False):
            with pytest.raises(ConfigError) as err:
                PFConfig(**{name: value})
            assert str(err.value).startswith(f"pf config {name}: ") and str(err.value).endswith(f"got {value}")
            assert "\n" not in str(err.value)
    assert PFConfig(kld_min_n=3, kld_converged_steps=2).kld_min_n == 3  # an integer still is one


@pytest.mark.parametrize("kernel", ["point", "kalman"])
def test_initialize_uniform_refuses_bounds_that_are_no_finite_box_within_the_pose_bound(kernel):
    """(0, inf, 0, 1) was taken (an estimate of inf; the Kalman kernels' NaN at the next update), (0, 1e30, 0, 1) gave an
    estimate of 5.6e29; text, three values and a bare number were numpy's ValueError or TypeError."""
    pf = make_filter(LANDMARKS, PFConfig(n_particles=50, kernel=kernel), 0)
    for bounds in ((0, np.inf, 0, 1), (0, 1e30, 0, 1), (0, np.nan, 0, 1), (-2e6, 0, 0, 1), (1, 0, 0, 1), ("a", 1, 0, 1),
                   (0, 1, 0), 5):
        with pytest.raises(ConfigError) as err:
            pf.initialize_uniform(bounds)
        assert err.value.source == "initialize_uniform" and "\n" not in str(err.value), bounds
        assert err.value.reason.startswith("bounds_xy must be 4 finite numbers (xmin, xmax, ymin, ymax) with each min "
                                           "below its max and |value| <= 1e+06 m, got "), bounds
    pf.initialize_uniform((-1e6, 1e6, 2, 3))  # the bound itself is a box
    assert (np.abs(pf.particles[:, 0]) <= 1e6).all() and ((pf.particles[:, 1] >= 2) & (pf.particles[:, 1] <= 3)).all()
    assert np.isfinite(pf.estimate()).all()


def test_kalman_update_refuses_indices_without_readings_as_the_point_filter_does():
    """KalmanParticleFilter.update([1], []) returned False in silence (it returned on the empty readings before checking
    them) where the point filter says the counts differ; no readings and no indices is a step without readings in both."""
    for kernel in ("point", "kalman"):
        pf = make_filter(LANDMARKS, PFConfig(n_particles=20, kernel=kernel), 0)
        with pytest.raises(DataError) as err:
            pf.update([1], [])
        assert str(err.value) == "update: 1 landmark indices for 0 readings", kernel
        assert pf.update([], []) is False and pf.update([], np.zeros((0, 2))) is False and pf.n_updates == 0
