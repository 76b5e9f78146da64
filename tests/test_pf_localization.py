"""Global localization, kidnapped-robot recovery (augmented MCL), KLD-sampling, the Q verdict and the CLI studies.

Cheap versions (3-10 seeds) of the acceptance figures that benchmarks/pf_localization.py measures on 50 seeds.
"""

from __future__ import annotations

import logging

import numpy as np
import pytest
from conftest import shared_path

from lidarkit.cli import main
from lidarkit.errors import ConfigError
from lidarkit.io.landmarks import LandmarkData
from lidarkit.pf import PFConfig
from lidarkit.pf.augmented import LikelihoodAverages
from lidarkit.pf.consistency import fit_q, q_verdict
from lidarkit.pf.kld import bin_keys, kld_bound, kld_sample_size
from lidarkit.pf.protocol import kidnapped_ground_truth, run_protocol
from lidarkit.pf.study import localized_fraction, steps_to_recover

SEEDS = [0, 1, 2]


@pytest.fixture(scope="module")
def stachniss() -> LandmarkData:
    return LandmarkData(shared_path("pf", "robot_mapping_stachniss"))


def _fox_loop(states, weights, seed, **kw):
    """Fox's algorithm one sample at a time (the definition the vectorized version must reproduce)."""
    rng = np.random.default_rng(seed)
    ids = bin_keys(states, kw["bin_m"], kw["bin_rad"])
    draws, total, chunk = [], 0, min(kw["n_max"], max(kw["n_min"], len(weights)))
    seen: set[int] = set()
    while True:
        cdf = np.cumsum(weights)
        u = rng.random(chunk) * cdf[-1]
        draws.append(ids[np.minimum(np.searchsorted(cdf, u, side="right"), len(weights) - 1)])
        for i, b in enumerate(draws[-1]):
            seen.add(int(b))
            n = total + i + 1
            if n >= kw["n_min"] and n >= kld_bound(len(seen), kw["epsilon"], kw["z"]):
                return n, len(seen)
        total += chunk
        if total >= kw["n_max"]:
            return kw["n_max"], len(seen)
        chunk = min(kw["n_max"] - total, total)


@pytest.mark.parametrize("spread", [0.05, 0.3, 2.0])
def test_kld_sample_size_is_fox_one_sample_at_a_time(spread):
    rng = np.random.default_rng(3)
    states = rng.normal(size=(3, 400)) * spread
    w = rng.random(400)
    w /= w.sum()
    kw = dict(epsilon=0.05, z=2.326, bin_m=0.5, bin_rad=np.radians(10), n_min=50, n_max=5000)
    assert kld_sample_size(states, w, np.random.default_rng(7), **kw) == _fox_loop(states, w, 7, **kw)


def test_kld_bound_values():
    # (k - 1) / (2 eps) * (1 - 2/(9(k-1)) + sqrt(2/(9(k-1))) z)^3, computed by hand for k = 2 and 10
    assert kld_bound(2, 0.05, 2.326) == pytest.approx(10 * (1 - 2 / 9 + np.sqrt(2 / 9) * 2.326) ** 3)
    assert kld_bound(10, 0.05, 2.326) == pytest.approx(90 * (1 - 2 / 81 + np.sqrt(2 / 81) * 2.326) ** 3)
    assert kld_bound(1, 0.05, 2.326) == 1.0


def test_global_localization_all_converges_and_without_ids_a_single_ekf_does_not(stachniss):
    for s in SEEDS:
        pf = run_protocol(stachniss, 3000, s, init="uniform", with_ape_rpe=False)
        assert pf.n_particles[0] == 3000
        assert localized_fraction(pf.position_error_m()) >= 0.9, s
        # with landmark ids the posterior is unimodal after a few readings: even one EKF from the uniform prior converges
        ekf = run_protocol(stachniss, 1, s, init="uniform", kernel="kalman", with_ape_rpe=False)
        assert localized_fraction(ekf.position_error_m()) >= 0.9, s
        # without ids (each hypothesis associates the nearest reading with its own nearest landmark) it does not
        ekf = run_protocol(stachniss, 1, s, init="uniform", kernel="kalman", likelihood="nearest", nearest_association="per_particle",
                           with_ape_rpe=False)
        assert localized_fraction(ekf.position_error_m()) < 0.5, s


def test_kidnapped_robot_is_recovered_with_augmented_mcl_only(stachniss):
    for s in SEEDS:
        aug = run_protocol(stachniss, 1000, s, kidnap_at_step=150, visible="all", augmented=True, with_ape_rpe=False)
        assert aug.injected[150:160].sum() > 0
        k = steps_to_recover(aug.position_error_m(), 150)
        assert k is not None and k <= 40, (s, k)
        plain = run_protocol(stachniss, 1000, s, kidnap_at_step=150, visible="all", with_ape_rpe=False)
        k = steps_to_recover(plain.position_error_m(), 150)
        assert plain.injected.sum() == 0 and (k is None or k > 40), (s, k)


def test_kidnapped_ground_truth_jumps_by_the_offset(stachniss):
    clean = kidnapped_ground_truth(stachniss.odometry, None, (0, 0, 0))
    gt = kidnapped_ground_truth(stachniss.odometry, 150, (0.0, -5.0, -np.pi / 2))
    np.testing.assert_allclose(gt[:150], clean[:150])
    np.testing.assert_allclose(gt[150, :2], clean[150, :2] + [0.0, -5.0], atol=1e-12)
    assert np.hypot(*(gt[151, :2] - gt[150, :2])) == pytest.approx(np.hypot(*(clean[151, :2] - clean[150, :2])))
    with pytest.raises(ConfigError):
        kidnapped_ground_truth(stachniss.odometry, 0, (0, 0, 0))


def test_kld_tracking_uses_few_particles_and_global_localization_many(stachniss):
    kld, fixed = [], []
    for s in SEEDS:
        r = run_protocol(stachniss, 1000, s, kld=True, with_ape_rpe=False)
        assert r.n_particles[1:].mean() <= 300
        kld.append(r.metrics["mse_m2"]["mean"])
        fixed.append(run_protocol(stachniss, 1000, s, with_ape_rpe=False).metrics["mse_m2"]["mean"])
    # 50 seeds (benchmark): within 10 %; 3 seeds carry ~5 % paired noise, hence 20 % here
    assert np.mean(kld) <= 1.2 * np.mean(fixed)
    g = run_protocol(stachniss, 5000, 0, init="uniform", kld=True, with_ape_rpe=False)
    # with ids, one update already makes the posterior unimodal: >= 1000 particles only on the first steps
    assert g.n_particles[0] == 5000 and g.n_particles[1] >= 1000 and g.n_particles[-100:].mean() <= 300
    assert localized_fraction(g.position_error_m()) >= 0.9


def test_likelihood_averages_inject_after_a_drop_only():
    avg = LikelihoodAverages(0.001, 0.1)
    for _ in range(100):
        avg.update(np.log(0.5))
    assert avg.injection_probability() == pytest.approx(0.0, abs=1e-9)
    for _ in range(5):
        avg.update(np.log(1e-6))
    # fast fell to 0.9^5 of its level, slow barely moved: p = 1 - fast / slow in (0.35, 0.42)
    assert 0.35 < avg.injection_probability() < 0.42


def test_augmented_and_kld_config_errors():
    with pytest.raises(ConfigError, match="alpha_slow < alpha_fast"):
        PFConfig.make(augmented=True, alpha_slow=0.2, alpha_fast=0.1)
    with pytest.raises(ConfigError, match="kld_min_n"):
        PFConfig.make(kld=True, kld_min_n=600, kld_max_n=500)
    with pytest.raises(ConfigError, match="point particles"):
        PFConfig.make(kld=True, kernel="kalman")
    with pytest.raises(ConfigError):
        PFConfig.make(kld_epsilon=0.0)


def test_fit_q_recovers_the_noise_of_synthetic_innovations():
    rng = np.random.default_rng(0)
    m = 4000
    P = np.zeros((m, 2, 2))
    P[:, 0, 0], P[:, 1, 1] = rng.uniform(0.001, 0.01, m), rng.uniform(1e-4, 1e-3, m)
    q_true = np.diag([0.01, 0.002])
    nu = np.stack([rng.multivariate_normal([0, 0], P[i] + q_true) for i in range(m)])
    q = fit_q(nu, P, np.diag([1.0, 0.1]))
    np.testing.assert_allclose(np.diag(q), np.diag(q_true), rtol=0.1)
    v = q_verdict(0.035, np.diag([1.0, 0.1]))
    assert v.status == "too large" and "Q too large by about 57x" in v.text
    assert q_verdict(8.0, np.diag([1.0, 0.1])).text.startswith("Q too small by about 4.0x")
    assert q_verdict(2.1, np.diag([1.0, 0.1])).status == "consistent"


def test_cli_recorded_prints_the_verdict_and_fit_q_makes_nis_consistent(capsys):
    data = shared_path("pf", "robot_mapping_stachniss")
    with pytest.raises(SystemExit) as exc:
        main(["pf", str(data), "--recorded", "-n", "500", "--fit-q"])
    assert exc.value.code in (0, None)
    out = " ".join(capsys.readouterr().out.split())
    assert "before: Q too large by about" in out
    after = out.split("after:")[1]
    assert after.strip().startswith("Q consistent with the readings")
    nis_after = float(after.split("NIS mean")[1].split(",")[0])
    assert 1.5 <= nis_after <= 2.5


def test_cli_report_protocol_reproduces_the_committed_figure_and_warns_once(capsys, caplog):
    data = shared_path("pf", "robot_mapping_stachniss")
    with caplog.at_level(logging.WARNING):
        with pytest.raises(SystemExit) as exc:
            main(["pf", str(data), "--particles", "50", "--seeds", "10", "--protocol", "report"])
    assert exc.value.code in (0, None)
    out = capsys.readouterr().out
    # benchmarks/results/pf/pf_particles.md, report choices / best, N=50: 28.789 ± 23.113
    assert "28.79 ± 23.1" in out
    assert sum("negative range" in r.getMessage() for r in caplog.records) == 1


def test_cli_study_table_over_particle_counts(capsys):
    data = shared_path("pf", "burgard_particle_filter")
    with pytest.raises(SystemExit) as exc:
        main(["pf", str(data), "--particles", "50,200", "--seeds", "3"])
    assert exc.value.code in (0, None)
    out = capsys.readouterr().out
    rows = [line for line in out.splitlines() if line.startswith("│")]
    assert [r.split("│")[1].strip() for r in rows] == ["50", "200"]
    for r in rows:
        mean = float(r.split("│")[2].split("±")[0])
        assert 0.0 < mean < 0.2


def test_cli_bad_study_and_kidnap_options(capsys):
    data = shared_path("pf", "burgard_particle_filter")
    for args, pattern in (
        (["--particles", "50,x"], "n_particles"),
        (["--seeds", "0"], "--seeds"),
        (["--fit-q"], "--fit-q needs --recorded"),
        (["--kidnap-at", "5000"], "kidnap step"),
        (["--kidnap-offset", "1,2"], "--kidnap-offset"),
        (["--protocol", "paper"], "unknown protocol"),
    ):
        with pytest.raises(SystemExit) as exc:
            main(["pf", str(data), *args])
        assert exc.value.code == 1, args
        err = capsys.readouterr().err
        assert "error:" in err and pattern in err and "Traceback" not in err, (args, err)


def test_kld_relocalization_spreads_the_maximum_count(stachniss):
    from lidarkit.pf import make_filter

    pf = make_filter(stachniss.landmarks.positions_xy, PFConfig.make(n_particles=1000, kld=True), 0)
    pf.predict(np.array(stachniss.odometry[0]))
    pf.update(np.array([0, 7]), np.array([[2.2, 0.5], [7.1, 0.8]]))
    pf.resample()
    assert 200 <= pf.n < 5000 and pf.n != 1000 and pf.states.shape == (3, pf.n)
    pf.initialize_uniform()  # what recovery="reinit" does when the filter is lost
    assert pf.n == 5000 and pf.states.shape == (3, 5000) and pf.weights.shape == (5000,)
    pf.predict(np.array(stachniss.odometry[1]))
    assert np.isfinite(pf.estimate()).all()


def test_cli_recorded_without_readings_is_one_line_error(tmp_path, capsys):
    src = shared_path("pf", "burgard_ekf")
    (tmp_path / "world.dat").write_text((src / "world.dat").read_text())
    odometry = [line for line in (src / "sensor_data.dat").read_text().splitlines() if line.startswith("ODOMETRY")][:20]
    (tmp_path / "sensor_data.dat").write_text("\n".join(odometry) + "\n")
    for extra in ([], ["--fit-q"]):
        with pytest.raises(SystemExit) as exc:
            main(["pf", str(tmp_path), "--recorded", *extra])
        assert exc.value.code == 1
        err = capsys.readouterr().err
        assert "0 SENSOR readings" in err and "Traceback" not in err
