"""The particle-filter report's evaluation protocol as one call, plus a run on the recorded readings.

Protocol (``run_protocol``): ground truth = the data's clean odometry integrated from (0, 0, 0);
the filter receives that odometry with added noise (std 0.01 rad, 0.1 m, 0.01 rad on r1, t, r2) and
range-bearing readings simulated from the ground truth with noise Q (the landmarks the data set
recorded at each step; ``visible="all"`` simulates every landmark every step). ``likelihood="nearest"``
gives the filter a single reading per step, of the landmark truly nearest the robot (the report).
Score: position MSE from step 10 on, plus APE/RPE through ``lidarkit.eval``.

Recorded mode (``run_recorded``): the data's own odometry and SENSOR readings, no ground truth;
consistency is reported as normalized innovation squared (NIS) statistics against chi-square(2)
and the distance between the estimate and dead reckoning.
"""

from __future__ import annotations

import os

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from lidarkit.errors import ConfigError, DataError
from lidarkit.params import is_integer, is_real_number
from lidarkit.pf.base import check_landmark_index
from lidarkit.pf.config import ESTIMATORS, PFConfig
from lidarkit.pf.consistency import Q_VARIANCE_BOUNDS, at_lower_bound, fit_q, localization_problem, q_verdict
from lidarkit.pf.filter import ParticleFilter, check_config_type, make_filter, nis_values
from lidarkit.pf.models import integrate_odometry, resolve_q, wrap_angle
from lidarkit.trajectory import Trajectory

if TYPE_CHECKING:
    from lidarkit.io.landmarks import LandmarkData

log = logging.getLogger(__name__)

ODOMETRY_NOISE_STD = (0.01, 0.1, 0.01)
MSE_START_STEP = 10
VISIBILITY = ("recorded", "all")
CHI2_2DOF_95 = 5.991464547107979  # chi-square(2) 95% quantile
CHI2_2DOF_999 = 13.815510557964274  # chi-square(2) 99.9% quantile: "lost" threshold per reading
KIDNAP_OFFSET = (0.0, -5.0, -np.pi / 2)  # 5 m and 90 deg; from step 150 on the robot stays inside the map box
#: Largest kidnap jump (m per axis): 1000 km is past any landmark map; 1e30 m overflowed the filter's float32 squares
#: (MSE 5.6e58, exit 0). The turn is at most a full circle (2 pi).
MAX_KIDNAP_OFFSET_M = 1e6
#: Memory a point-particle filter takes per particle (bytes) when the readings per step are unknown (the bench validates
#: its tasks before any data is loaded): state, weights, resampling copies and a likelihood workspace of ~16 readings.
FILTER_BYTES_PER_PARTICLE = 320.0
#: Point particles without their likelihood workspace (bytes a particle): tracemalloc peaks of 220 B (Freiburg, 7
#: readings at most a step) and 1,325 B (100 landmarks all visible), 200,000 float32 particles, are ~124 B plus 3 x 4 B
#: a workspace reading; 100 B of margin, so a workspace of 8 readings (the smallest) gives FILTER_BYTES_PER_PARTICLE.
POINT_BASE_BYTES_PER_PARTICLE = 224.0
#: Each reading of a step adds a (3, N) row to the likelihood workspace (per-particle nearest association: each landmark).
WORKSPACE_ARRAYS_PER_READING = 3
WORKSPACE_MIN_READINGS = 8  # the workspace is never allocated smaller (ParticleFilter.log_likelihood)
#: A Kalman kernel per particle (bytes; float64 mean, covariance, Jacobians; it weighs the readings one at a time):
#: measured ~520 B (tracemalloc peak, Freiburg, 20,000 kernels, every landmark visible).
KALMAN_BYTES_PER_PARTICLE = 640.0
#: Memory per particle of each particle cloud a run keeps for its figures (bytes: an (N, 3) float64 copy).
CLOUD_BYTES_PER_PARTICLE = 24.0
#: The advice ``q_verdict`` ends a "too large" / "too small" verdict with; the runs of ``fit_q_recorded`` leave it out
#: (``--fit-q`` printed "before: Q too large by about 56x (...); --fit-q estimates Q" above the fit's own table).
FIT_Q_ADVICE = "; --fit-q estimates Q"


@dataclass(frozen=True, eq=False)
class StepReadings:
    """Readings grouped by step (CSR): ``landmark_index`` ``(K,)``, ``z`` ``(K, 2)`` [range_m, bearing_rad];
    step t's readings are rows ``offsets[t]:offsets[t+1]`` (``offsets`` ``(T+1,)``)."""

    landmark_index: np.ndarray
    z: np.ndarray
    offsets: np.ndarray

    def at(self, t: int) -> tuple[np.ndarray, np.ndarray]:
        a, b = int(self.offsets[t]), int(self.offsets[t + 1])
        return self.landmark_index[a:b], self.z[a:b]

    @classmethod
    def from_flat(cls, step: np.ndarray, landmark_index: np.ndarray, z: np.ndarray, n_steps: int) -> StepReadings:
        order = np.argsort(step, kind="stable")
        counts = np.bincount(step, minlength=n_steps)
        offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        return cls(np.asarray(landmark_index)[order], np.asarray(z, dtype=np.float64)[order], offsets)


def kidnapped_ground_truth(odometry: np.ndarray, kidnap_at_step: int | None, kidnap_offset: tuple[float, float, float]) -> np.ndarray:
    """Clean odometry integrated from (0, 0, 0) ``(T+1, 3)``, with pose ``kidnap_at_step`` moved by ``kidnap_offset`` (if given)."""
    T = len(odometry)
    if kidnap_at_step is None:
        return integrate_odometry(odometry)
    if not is_integer(kidnap_at_step):  # (1.5 ran as step 1, "150" as 150)
        raise ConfigError(f"kidnap step must be an integer in 1..{T}, got {kidnap_at_step!r}", source="kidnap_at_step")
    k = int(kidnap_at_step)
    try:
        offset = np.asarray(kidnap_offset, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):  # (text, a mapping, ragged lists: numpy's own error escaped)
        offset = np.full(0, np.nan)
    if not 1 <= k <= T:
        raise ConfigError(f"kidnap step must be in 1..{T}, got {k}", source="kidnap_at_step")
    if (offset.shape != (3,) or not np.isfinite(offset).all() or np.abs(offset[:2]).max() > MAX_KIDNAP_OFFSET_M
            or abs(offset[2]) > 2 * np.pi):
        raise ConfigError(f"kidnap offset must be 3 finite values (dx_m, dy_m, dtheta_rad), |dx|, |dy| <= {MAX_KIDNAP_OFFSET_M:g} m "
                          f"and |dtheta| <= 2 pi, got {kidnap_offset!r}", source="kidnap_offset")
    before = integrate_odometry(odometry[:k])
    after = integrate_odometry(odometry[k:], before[-1] + offset)
    return np.concatenate([before[:-1], after])


def kidnap_offset_record(kidnap_offset: tuple[float, float, float]) -> dict[str, float]:
    """``(dx_m, dy_m, dtheta_rad)`` as a run folder records it: units in the names, the turn in degrees as
    ``--kidnap-offset`` takes it (a bare list in radians, copied back into the option, turned 1.57 deg)."""
    dx, dy, dtheta = (float(v) for v in np.asarray(kidnap_offset, dtype=np.float64).reshape(3))
    return {"dx_m": dx, "dy_m": dy, "dtheta_deg": float(np.degrees(dtheta))}


@dataclass(frozen=True, eq=False)
class SimulatedData:
    """The protocol's inputs for one seed: ``ground_truth`` ``(T+1, 3)``, ``odometry_noisy`` ``(T, 3)``,
    ``dead_reckoning`` ``(T+1, 3)``, all-readings and nearest-reading sets."""

    ground_truth: np.ndarray
    odometry_noisy: np.ndarray
    dead_reckoning: np.ndarray
    readings: StepReadings
    nearest: StepReadings


def simulate(
    data,
    rng: np.random.Generator,
    q_cov: np.ndarray,
    *,
    odometry_noise_std: tuple[float, float, float] = ODOMETRY_NOISE_STD,
    visible: str = "recorded",
    kidnap_at_step: int | None = None,
    kidnap_offset: tuple[float, float, float] = KIDNAP_OFFSET,
) -> SimulatedData:
    """Ground truth, noisy odometry and simulated readings (range, bearing) + N(0, Q) for one data set.

    ``kidnap_at_step`` = k: right after its k-th motion the robot is teleported by ``kidnap_offset``
    ``(dx_m, dy_m, dtheta_rad)`` (world frame) and drives on from there with the same odometry; the
    filter's odometry does not show the jump (the readings from step k on do).
    """
    if visible not in VISIBILITY:
        raise ConfigError(f"visible must be one of {VISIBILITY}, got {visible!r}", source="visible")
    odo = np.asarray(data.odometry, dtype=np.float64)
    T = len(odo)
    gt = kidnapped_ground_truth(odo, kidnap_at_step, kidnap_offset)
    noisy = odo + rng.standard_normal((T, 3)) * np.asarray(odometry_noise_std, dtype=np.float64)
    lm = np.asarray(data.landmarks.positions_xy, dtype=np.float64)
    if visible == "recorded":
        step = np.asarray(data.meas_step, dtype=np.int64)
        idx = np.asarray(data.meas_landmark_index, dtype=np.int64)
    else:
        step = np.repeat(np.arange(T), len(lm))
        idx = np.tile(np.arange(len(lm)), T)
    pose = gt[step + 1]
    d = lm[idx] - pose[:, :2]
    true_z = np.stack([np.hypot(d[:, 0], d[:, 1]), wrap_angle(np.arctan2(d[:, 1], d[:, 0]) - pose[:, 2])], axis=1)
    chol = np.linalg.cholesky(q_cov)
    z = true_z + rng.standard_normal(true_z.shape) @ chol.T
    z[:, 1] = wrap_angle(z[:, 1])
    readings = StepReadings.from_flat(step, idx, z, T)
    # nearest: per step, the reading whose landmark is truly closest to the robot
    order = np.lexsort((true_z[:, 0], step))
    first = np.ones(len(order), dtype=bool)
    first[1:] = step[order][1:] != step[order][:-1]
    keep = order[first]
    nearest = StepReadings.from_flat(step[keep], idx[keep], z[keep], T)
    return SimulatedData(gt, noisy, integrate_odometry(noisy), readings, nearest)


@dataclass(eq=False)
class PFRunResult:
    """One filter run: estimates ``(T+1, 3)`` per estimator, ground truth / dead reckoning, scores, diagnostics."""

    config: PFConfig
    settings: dict[str, Any]
    landmarks_xy: np.ndarray
    estimates: dict[str, np.ndarray]
    dead_reckoning: np.ndarray
    ground_truth: np.ndarray | None
    runtime_s: float
    ess: np.ndarray
    resampled: np.ndarray
    max_loglik: np.ndarray
    n_weight_resets: int
    lost_steps: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    n_recoveries: int = 0
    n_particles: np.ndarray | None = None  # (T+1,) particle count after each step's resampling (row 0: initial)
    injected: np.ndarray | None = None  # (T,) particles replaced by uniform draws per step (augmented MCL)
    odometry_used: np.ndarray | None = field(default=None, repr=False)
    snapshots: dict[int, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict, repr=False)
    metrics: dict[str, Any] = field(default_factory=dict)
    #: ``(2, 2)`` one-round ML Q of a recorded run's innovations, kept even when the run lost track (a round of
    #: ``fit_q_recorded`` goes on from it); ``metrics`` shows it only for a run that did not
    innovation_q_fit: np.ndarray | None = field(default=None, repr=False)

    def __repr__(self) -> str:
        """One line of the key figures (the generated one printed every array: 77,852 characters on the Freiburg sample)."""
        name = self.config.estimator if self.config.estimator in self.estimates else next(iter(self.estimates), "")
        mse = (self.metrics.get("mse_m2") or {}).get(name)
        nis = self.metrics.get("nis_mean")
        score = (f", position MSE {mse:.4g} m^2 ({name})" if is_real_number(mse)
                 else f", NIS mean {nis:.3g}" if is_real_number(nis) else ", not scored")
        lost = f", lost on {len(self.lost_steps)} steps" if len(self.lost_steps) else ""
        return (f"PFRunResult({self.settings.get('mode', 'run')}, {self.n_steps} steps, {self.config.particle_count_label()} "
                f"particles in {self.runtime_s:.3g} s{score}{lost})")

    @property
    def estimate(self) -> np.ndarray:
        """The config's estimator's poses (another estimator in its place was scored and labelled as it)."""
        if self.config.estimator not in self.estimates:
            raise ConfigError(f"the config's estimator {self.config.estimator!r} was not recorded; this run has "
                              f"{', '.join(self.estimates) or 'none'}", source="estimate")
        return self.estimates[self.config.estimator]

    @property
    def n_steps(self) -> int:
        return len(self.dead_reckoning) - 1

    @property
    def lost_after_convergence(self) -> np.ndarray:
        """Indices of the lost steps from the run's first convergence on (:func:`first_converged_step`): a uniform
        start's first steps are its convergence, not lost track (``lost_steps`` holds them all)."""
        return _lost_from(self, first_converged_step(self))

    def position_error_m(self, which: str = "estimate") -> np.ndarray:
        """``(T+1,)`` distance between an estimate and the ground truth (protocol runs only)."""
        if self.ground_truth is None:
            raise ConfigError("no ground truth in a recorded run", source="position_error_m")
        est = self.estimate if which == "estimate" else self.estimates[which]
        return np.hypot(*(est[:, :2] - self.ground_truth[:, :2]).T)

    def trajectory(self, which: str = "estimate") -> Trajectory:
        """``estimate`` / ``mean`` / ``best`` / ``ground_truth`` / ``dead_reckoning`` as an SE(3) Trajectory (z = 0)."""
        if which == "estimate":
            return poses_to_trajectory(self.estimate, name=which)
        kept = {"ground_truth": self.ground_truth, "dead_reckoning": self.dead_reckoning, **self.estimates}
        poses = kept.get(which)
        if poses is None:  # (it said only "no trajectory 'best' in this run": a run records only the estimators asked for)
            available = ", ".join(["estimate", *(k for k, v in kept.items() if v is not None)])
            raise ConfigError(f"no trajectory {which!r} in this run; it has {available} (run_protocol records the config's "
                              "estimator and the estimators= it is given: estimators=('mean', 'best') keeps both)",
                              source="trajectory")
        return poses_to_trajectory(poses, name=which)

    def to_dict(self) -> dict[str, Any]:
        return {
            "config": self.config.model_dump(),
            "settings": self.settings,
            "runtime_s": self.runtime_s,
            "n_steps": self.n_steps,
            "n_resamples": int(self.resampled.sum()),
            "mean_ess": float(self.ess.mean()) if len(self.ess) else None,
            "n_weight_resets": self.n_weight_resets,
            "n_lost_steps": int(len(self.lost_steps)),
            "n_recoveries": self.n_recoveries,
            "n_particles_mean": float(self.n_particles[1:].mean()) if self.n_particles is not None and len(self.n_particles) > 1 else None,
            "n_particles_per_step": self.n_particles.tolist() if self.n_particles is not None else None,
            "n_injected": int(self.injected.sum()) if self.injected is not None else 0,
            "first_lost_step": int(self.lost_steps[0]) + 1 if len(self.lost_steps) else None,
            "metrics": self.metrics,
        }


def poses_to_trajectory(poses_xytheta: np.ndarray, name: str = "") -> Trajectory:
    """``(T, 3)`` planar poses -> Trajectory of SE(3) poses (rotation about z, z = 0); timestamps = step index."""
    p = np.asarray(poses_xytheta, dtype=np.float64)
    c, s = np.cos(p[:, 2]), np.sin(p[:, 2])
    T = np.zeros((len(p), 4, 4))
    T[:, 0, 0], T[:, 0, 1], T[:, 1, 0], T[:, 1, 1] = c, -s, s, c
    T[:, 2, 2] = T[:, 3, 3] = 1.0
    T[:, 0, 3], T[:, 1, 3] = p[:, 0], p[:, 1]
    return Trajectory(T, np.arange(len(p), dtype=np.float64), name=name)


def run_filter(
    pf: ParticleFilter | Any,
    odometry: np.ndarray,
    readings: StepReadings,
    *,
    estimators: tuple[str, ...] = ("mean",),
    snapshot_steps: tuple[int, ...] = (),
    nis: bool = False,
    on_step: Callable[[int, int], None] | None = None,
) -> dict[str, Any]:
    """The filter loop over ``odometry`` ``(T, 3)``: predict, update (if readings), estimate, resample; ``on_step(done,
    T)`` after each step (a progress bar: a million particles take minutes).

    Returns estimates ``(T+1, 3)`` per estimator (row 0 = the initial particle set), ESS before
    resampling, resample flags, best log-likelihood per step, snapshots and (optionally) NIS values.
    """
    odometry = np.asarray(odometry, dtype=np.float64).reshape(-1, 3)
    bad = ~np.isfinite(odometry).all(axis=1)
    if bad.any():
        raise DataError(f"non-finite odometry at step {int(np.argmax(bad))}", source="odometry")
    bad = ~np.isfinite(readings.z).all(axis=1)
    if bad.any():
        raise DataError(f"non-finite reading {int(np.argmax(bad))}", source="readings")
    if len(readings.offsets) != len(odometry) + 1:
        raise DataError(f"{len(readings.offsets) - 1} reading steps for {len(odometry)} odometry steps", source="readings")
    # once here: the loop updates unchecked (-1 weighed the last landmark, 7 of 3 was a bare IndexError)
    lm_index = check_landmark_index(readings.landmark_index, len(pf.landmarks_xy), "readings", readings.offsets)
    T = len(odometry)
    snapshot_steps = checked_snapshot_steps(snapshot_steps)
    odd = [s for s in snapshot_steps if not is_integer(s) or not 0 <= s <= T]
    if odd:  # (-1 and steps past the end were left out without a word)
        raise ConfigError(f"snapshot steps must be integers in 0..{T} (the run's steps), got {', '.join(map(str, odd))}",
                          source="snapshot_steps")
    odometry_rows = [tuple(float(v) for v in row) for row in odometry]
    z_all = readings.z.astype(pf.states.dtype)
    est = {k: np.empty((T + 1, 3)) for k in estimators}
    for k in estimators:
        est[k][0] = pf.estimate(k)
    ess = np.full(T, float(pf.n))
    resampled = np.zeros(T, dtype=bool)
    n_particles = np.empty(T + 1, dtype=np.int64)  # count after each step's resampling (row 0: initial)
    n_particles[0] = pf.n
    injected = np.zeros(T, dtype=np.int64)
    max_ll = np.full(T, np.nan)
    snaps: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    snapshot_set = set(int(s) for s in snapshot_steps)
    if 0 in snapshot_set:
        snaps[0] = (pf.particles.astype(np.float64), pf.weights.copy())
    innovations: list[np.ndarray] = []
    spreads: list[np.ndarray] = []
    offsets = readings.offsets.tolist()
    sequence = hasattr(pf, "begin_odometry")
    if sequence:
        pf.begin_odometry(odometry)
    recover = pf.config.recovery == "reinit"
    nearest = pf.config.likelihood == "nearest"
    n_recoveries = 0
    t0 = time.perf_counter()
    for t in range(T):
        if sequence:
            pf.predict_next()
        else:
            pf.predict(odometry_rows[t], check=False)
        a, b = offsets[t], offsets[t + 1]
        if b > a:
            idx, z = lm_index[a:b], z_all[a:b]
            if nis:
                nu, P = pf.innovation_stats(idx, readings.z[a:b], check=False)
                innovations.append(nu)
                spreads.append(P)
            pf.update(idx, z, check=False)
            max_ll[t] = pf.last_max_loglik
            if recover and _is_lost(pf.last_max_loglik, 1 if nearest else b - a):
                pf.initialize_uniform()
                pf.update(idx, z, check=False)
                n_recoveries += 1
        for k in estimators:
            est[k][t + 1] = pf.estimate(k)
        if t + 1 in snapshot_set:
            snaps[t + 1] = (pf.particles.astype(np.float64), pf.weights.copy())
        ess[t] = pf.ess
        resampled[t] = pf.resample()
        n_particles[t + 1] = pf.n
        injected[t] = pf.last_injected if resampled[t] else 0
        if on_step is not None:
            on_step(t + 1, T)
    runtime = time.perf_counter() - t0
    n_readings = np.ones(T) if nearest else np.diff(readings.offsets)
    lost = np.flatnonzero(_is_lost(max_ll, n_readings))
    return {
        "n_recoveries": n_recoveries,
        "lost_steps": lost,
        "estimates": est,
        "ess": ess,
        "resampled": resampled,
        "n_particles": n_particles,
        "injected": injected,
        "max_loglik": max_ll,
        "snapshots": snaps,
        "runtime_s": runtime,
        "innovations": np.concatenate(innovations) if innovations else np.zeros((0, 2)),
        "innovation_spread": np.concatenate(spreads) if spreads else np.zeros((0, 2, 2)),
    }


def _is_lost(max_loglik, n_readings):
    """True where even the best particle's mean Mahalanobis^2 per reading is beyond the chi-square(2) 99.9% gate."""
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.asarray(-2.0 * np.asarray(max_loglik) / np.maximum(n_readings, 1) > CHI2_2DOF_999)


def _resolve_config(config: PFConfig | None, n_particles: int | None, changes: dict[str, Any], source: str) -> PFConfig:
    """``config`` (default ``PFConfig()``) with ``changes``; ``n_particles`` overrides the config's only when given.
    Anything but a PFConfig is a ConfigError naming ``source``, the calling function."""
    check_config_type(config, source)
    if n_particles is not None:
        changes = {**changes, "n_particles": n_particles}
    base = config if config is not None else PFConfig.make()
    return base.replace(**changes) if changes else base


def _filter_outputs(out: dict, pf) -> dict:
    """The PFRunResult fields that come straight from a ``run_filter`` output and the filter."""
    keys = ("estimates", "runtime_s", "ess", "resampled", "max_loglik", "lost_steps", "n_recoveries", "snapshots", "n_particles", "injected")
    return {**{key: out[key] for key in keys}, "n_weight_resets": pf.n_weight_resets}


def data_files(data: Any) -> dict[str, str]:
    """The files a run read, as absolute paths (``data``: their folder; a sensor file passed in place of the folder is
    named, not only the folder, whose own sensor_data.dat may be another recording)."""
    out = {"data": str(Path(getattr(data, "root", "")).resolve()) if getattr(data, "root", None) is not None else ""}
    for key, attr in (("world_file", "world_path"), ("sensor_file", "sensor_path")):
        if getattr(data, attr, None) is not None:
            out[key] = str(Path(getattr(data, attr)).resolve())
    return out


def _sensor_source(data: Any) -> str:
    """The file an error about the recording names: its sensor file (else its folder)."""
    return str(getattr(data, "sensor_path", None) or getattr(data, "root", None) or "recorded data")


def most_readings_per_step(data: Any, visible: str = "recorded") -> int:
    """The most readings any step of a run on ``data`` weighs: every landmark when all are visible, else the
    recording's busiest step."""
    if visible == "all":
        return len(data.landmarks.positions_xy)
    offsets = np.asarray(data.step_offsets)
    return int(np.diff(offsets).max()) if len(offsets) > 1 else 0


def filter_bytes_per_particle(cfg: PFConfig, most_readings: int | None = None, n_landmarks: int | None = None) -> float:
    """Bytes a particle of a ``cfg`` filter takes; the likelihood workspace grows with ``most_readings`` (the most in
    any step; None: unknown, the :data:`FILTER_BYTES_PER_PARTICLE` guess), or with ``n_landmarks`` for the per-particle
    nearest association (a 100-landmark map took 1,325 B a particle, four times the old flat 320 B)."""
    if cfg.kernel == "kalman":
        return KALMAN_BYTES_PER_PARTICLE
    if cfg.likelihood == "nearest":
        rows = n_landmarks if cfg.nearest_association == "per_particle" else 1
    else:
        rows = most_readings
    if rows is None:
        return FILTER_BYTES_PER_PARTICLE
    itemsize = np.dtype(cfg.dtype).itemsize
    return POINT_BASE_BYTES_PER_PARTICLE + WORKSPACE_ARRAYS_PER_READING * itemsize * max(rows, WORKSPACE_MIN_READINGS)


def check_filter_memory(n_particles: int, n_kept_clouds: int, source: str,
                        bytes_per_particle: float = FILTER_BYTES_PER_PARTICLE) -> None:
    """ConfigError naming ``source`` when a filter of ``n_particles`` keeping ``n_kept_clouds`` particle clouds would not
    fit in the available memory: refused before the filter allocates (numpy's MemoryError, or swapping)."""
    from lidarkit.resources import check_memory

    needed_bytes = n_particles * (bytes_per_particle + CLOUD_BYTES_PER_PARTICLE * n_kept_clouds)
    check_memory(needed_bytes, f"a filter of {n_particles:,} particles", source)


def check_config_memory(cfg: PFConfig, n_kept_clouds: int = 0, data: Any = None, visible: str = "recorded") -> None:
    """:func:`check_filter_memory` for the largest particle count of ``cfg`` (a KLD run may grow to ``kld_max_n``), naming
    that setting: the library and the bench check a run as ``lidarkit pf`` does (3e9 particles reached numpy's
    MemoryError). With ``data`` (and ``visible``) the estimate counts its readings per step."""
    largest, source = (cfg.kld_max_n, "kld_max_n") if cfg.kld else (cfg.n_particles, "n_particles")
    per_particle = (filter_bytes_per_particle(cfg, most_readings_per_step(data, visible), len(data.landmarks.positions_xy))
                    if data is not None else filter_bytes_per_particle(cfg))
    check_filter_memory(largest, n_kept_clouds, source, per_particle)


def checked_snapshot_steps(snapshot_steps: Any) -> tuple:
    """``snapshot_steps`` as a tuple, read once (a generator counted for the memory check was empty for the filter)."""
    if isinstance(snapshot_steps, (str, bytes)):
        raise ConfigError(f"must be an iterable of step numbers, got {snapshot_steps!r:.60}", source="snapshot_steps")
    try:
        return tuple(snapshot_steps)
    except TypeError:
        raise ConfigError(f"must be an iterable of step numbers, got {snapshot_steps!r:.60}", source="snapshot_steps") from None


def checked_estimators(estimators: Any) -> tuple[str, ...]:
    """``estimators`` (None, one name or an iterable of names) as a tuple of known names; anything else is a ConfigError
    naming ``estimators`` (5 was "Value after * must be an iterable", "median" was named only once the run began)."""
    if estimators is None:
        return ()
    if isinstance(estimators, str):  # (tuple("best") ran the estimators 'b', 'e', 's', 't')
        estimators = (estimators,)
    try:
        names = tuple(estimators)
    except TypeError:
        names = None
    if names is None or any(not isinstance(name, str) or name not in ESTIMATORS for name in names):
        raise ConfigError(f"must be one of {', '.join(ESTIMATORS)} or an iterable of them, got {estimators!r:.60}",
                          source="estimators")
    return names


def checked_seed(seed: Any) -> int:
    """``seed`` as the integer >= 0 a reproducible run needs (None would draw fresh entropy: refused)."""
    if not is_integer(seed) or seed < 0:
        raise ConfigError(f"seed must be an integer >= 0 (the same seed gives the same run), got {seed!r}", source="seed")
    return int(seed)


def landmark_data(data: Any) -> LandmarkData:
    """``data`` as the LandmarkData a run reads: a path opens the dataset there; anything else is a ConfigError (a path
    failed "'str' object has no attribute 'odometry'", or 'meas_range_m' in the recorded mode)."""
    from lidarkit.io.landmarks import LandmarkData

    if isinstance(data, (str, os.PathLike)):
        return LandmarkData(data)
    if not isinstance(data, LandmarkData):
        raise ConfigError(f"data must be a LandmarkData or the path of a landmark dataset, got {type(data).__name__} "
                          f"{data!r:.60}", source="data")
    return data


def run_protocol(
    data,
    n_particles: int | None = None,
    seed: int = 0,
    *,
    config: PFConfig | None = None,
    likelihood: str | None = None,
    estimator: str | None = None,
    resampler: str | None = None,
    q_as: str | None = None,
    estimators: str | tuple[str, ...] | None = None,
    visible: str = "recorded",
    snapshot_steps: tuple[int, ...] = (),
    mse_start: int = MSE_START_STEP,
    with_ape_rpe: bool = True,
    kidnap_at_step: int | None = None,
    kidnap_offset: tuple[float, float, float] = KIDNAP_OFFSET,
    warn_lost: bool = True,
    on_step: Callable[[int, int], None] | None = None,
    **config_overrides: Any,
) -> PFRunResult:
    """Simulate the report's protocol on ``data`` (a LandmarkData or its path) and run the filter once.

    ``seed`` derives two independent streams: the simulated data (noisy odometry, readings) and the
    filter; so runs with the same seed and different N see the same data. Readings are simulated with
    the same Q the filter uses (``q``/``q_as`` of the config). ``n_particles`` (if given) overrides the
    config's. ``estimators`` (one name or several) are recorded beside the config's estimator, which is always
    recorded: it is the run's estimate, the one APE / RPE score. MSE uses ``lidarkit.eval.position_mse`` from step
    ``mse_start`` on, for every estimator.
    ``kidnap_at_step`` / ``kidnap_offset``: teleport the simulated robot (see :func:`simulate`); the steps it took to
    recover are ``metrics["kidnap_recovery"]``.
    """
    data = landmark_data(data)
    overrides = {k: v for k, v in dict(likelihood=likelihood, estimator=estimator, resampler=resampler, q_as=q_as).items() if v is not None}
    cfg = _resolve_config(config, n_particles, {**overrides, **config_overrides}, "run_protocol")
    seed = checked_seed(seed)
    # (without the config's estimator, the first one given stood in for it: the best particle's APE filed under "mean")
    estimators = tuple(dict.fromkeys((*checked_estimators(estimators), cfg.estimator)))
    if not is_integer(mse_start) or mse_start < 0:  # (checked after the run)
        raise ConfigError(f"mse_start must be an integer step >= 0, got {mse_start!r}", source="mse_start")
    if len(data.odometry) < mse_start:  # (the whole filter ran first, then the MSE failed counting poses: "has 10" for 9 steps)
        raise DataError(f"{len(data.odometry)} steps: the protocol scores the position MSE from step {mse_start} on, so it needs "
                        f"at least {mse_start}", source=_sensor_source(data))
    snapshot_steps = checked_snapshot_steps(snapshot_steps)
    check_config_memory(cfg, len(snapshot_steps), data, visible)
    data_seq, filter_seq = np.random.SeedSequence(seed).spawn(2)
    q_cov = resolve_q(cfg.q, cfg.q_as)
    sim = simulate(data, np.random.default_rng(data_seq), q_cov, visible=visible, kidnap_at_step=kidnap_at_step, kidnap_offset=kidnap_offset)
    pf = make_filter(data.landmarks.positions_xy, cfg, np.random.default_rng(filter_seq))
    readings = sim.nearest if cfg.likelihood == "nearest" else sim.readings
    out = run_filter(pf, sim.odometry_noisy, readings, estimators=estimators, snapshot_steps=snapshot_steps, on_step=on_step)
    result = PFRunResult(
        config=cfg,
        settings={
            "mode": "protocol",
            "seed": seed,
            "visible": visible,
            "mse_start": mse_start,
            "kidnap_at_step": int(kidnap_at_step) if kidnap_at_step is not None else None,
            "kidnap_offset": kidnap_offset_record(kidnap_offset) if kidnap_at_step is not None else None,
            "odometry_noise_std": list(ODOMETRY_NOISE_STD),
            "q_cov": q_cov.tolist(),
            **data_files(data),
        },
        landmarks_xy=np.asarray(data.landmarks.positions_xy, dtype=np.float64),
        dead_reckoning=sim.dead_reckoning,
        ground_truth=sim.ground_truth,
        odometry_used=sim.odometry_noisy,
        **_filter_outputs(out, pf),
    )
    result.metrics = score_against_ground_truth(result, mse_start=mse_start, with_ape_rpe=with_ape_rpe)
    if kidnap_at_step is not None:  # (only a study's table said whether a kidnap was recovered from)
        from lidarkit.pf.study import kidnap_recovery

        result.metrics["kidnap_recovery"] = kidnap_recovery(result.position_error_m(), int(kidnap_at_step))
    if warn_lost:
        _warn_lost(result)
    return result


def _warn_lost(result: PFRunResult, which: str = "") -> None:
    """One warning if ``result`` lost track; ``which`` names the run among several (" with the given Q"). Counted from
    the run's first convergence (:func:`first_converged_step`), in the protocol as on recorded readings (a uniform
    start's first step was "lost on 1 of 331 steps" in the protocol only)."""
    start = first_converged_step(result)
    lost = result.lost_after_convergence
    if len(lost):
        after = f" from step {start + 1}, after it first converged" if start else ""
        log.warning(
            "filter lost on %d of %d steps%s%s (first at step %d): even the best particle is beyond the chi-square 99.9%% gate",
            len(lost), result.n_steps - start, after, which, int(lost[0]) + 1,
        )


def score_against_ground_truth(result: PFRunResult, *, mse_start: int = MSE_START_STEP, with_ape_rpe: bool = True) -> dict[str, Any]:
    """Position MSE (from ``mse_start``) for every estimate and dead reckoning; APE / RPE (translation, no alignment)."""
    from lidarkit.eval import ape, position_mse, rpe

    gt = result.trajectory("ground_truth")
    metrics: dict[str, Any] = {"mse_m2": {}, "mse_start": mse_start}
    dr = result.trajectory("dead_reckoning")
    metrics["mse_dead_reckoning_m2"] = position_mse(gt, dr, start=mse_start)
    for name in result.estimates:
        metrics["mse_m2"][name] = position_mse(gt, result.trajectory(name), start=mse_start)
    if with_ape_rpe:
        for name, traj in [(result.config.estimator, result.trajectory(result.config.estimator)), ("dead_reckoning", dr)]:
            metrics.setdefault("ape_translation_m", {})[name] = ape(gt, traj).to_dict()["stats"]
            metrics.setdefault("rpe_translation_m", {})[name] = rpe(gt, traj, delta=1).to_dict()["stats"]
    return metrics


def run_recorded(
    data,
    n_particles: int | None = None,
    seed: int = 0,
    *,
    config: PFConfig | None = None,
    snapshot_steps: tuple[int, ...] = (),
    warn_lost: bool = True,
    on_step: Callable[[int, int], None] | None = None,
    **config_overrides: Any,
) -> PFRunResult:
    """Run on the data's own odometry and SENSOR readings (``data``: a LandmarkData or its path); report NIS
    consistency and distance to dead reckoning."""
    data = landmark_data(data)
    if len(data.meas_range_m) < 2:
        raise DataError(f"{len(data.meas_range_m)} SENSOR readings: the recorded mode needs at least 2 to judge Q by",
                        source=_sensor_source(data))
    seed = checked_seed(seed)
    cfg = _resolve_config(config, n_particles, config_overrides, "run_recorded")
    snapshot_steps = checked_snapshot_steps(snapshot_steps)
    check_config_memory(cfg, len(snapshot_steps), data)
    pf = make_filter(data.landmarks.positions_xy, cfg, np.random.default_rng(seed))
    odo = np.asarray(data.odometry, dtype=np.float64)
    readings = StepReadings(
        np.asarray(data.meas_landmark_index, dtype=np.int64),
        np.stack([data.meas_range_m, data.meas_bearing_rad], axis=1).astype(np.float64),
        np.asarray(data.step_offsets, dtype=np.int64),
    )
    estimators = tuple(dict.fromkeys((cfg.estimator, "mean", "best")))
    out = run_filter(pf, odo, readings, estimators=estimators, snapshot_steps=snapshot_steps, nis=True, on_step=on_step)
    dr = integrate_odometry(odo)
    result = PFRunResult(
        config=cfg,
        settings={"mode": "recorded", "seed": seed, "q_cov": resolve_q(cfg.q, cfg.q_as).tolist(), **data_files(data)},
        landmarks_xy=np.asarray(data.landmarks.positions_xy, dtype=np.float64),
        dead_reckoning=dr,
        ground_truth=None,
        odometry_used=odo,
        **_filter_outputs(out, pf),
    )
    q_cov = resolve_q(cfg.q, cfg.q_as)
    # the initial convergence (a uniform start failing the gate on its first steps) is no lost track: its readings are
    # left out of the NIS, the fit and the lost count
    start = first_converged_step(result)
    skipped = int(readings.offsets[start])
    innovations, spread = out["innovations"][skipped:], out["innovation_spread"][skipped:]
    nis = nis_values(innovations, spread + q_cov)
    result.metrics = consistency_metrics(nis, result.estimate, dr, data, q_cov)
    result.metrics["nis_from_step"] = start + 1
    result.metrics["n_readings_before_convergence"] = skipped
    if len(nis) >= 2:
        result.innovation_q_fit = fit_q(innovations, spread, q_cov)
        lost = localization_problem(len(_lost_from(result, start)), result.n_steps - start, from_step=start + 1)
        verdict = q_verdict(result.metrics["nis_mean"], q_cov, lost=lost, nis_from_step=start + 1 if skipped else None)
        if not lost:  # (a lost run's fit is of localization error: 308 of 331 steps lost gave a range variance of 19.9 m^2)
            result.metrics["q_fit_one_round"] = _one_round_fit_record(result.innovation_q_fit)
        result.metrics["q_verdict"] = {"status": verdict.status, "factor": verdict.factor, "text": verdict.text}
    if warn_lost:
        _warn_lost(result)
    return result


def first_converged_step(result: PFRunResult) -> int:
    """Index ``t`` of the first step whose readings a filter from a uniform (global) start passed the chi-square 99.9 %
    gate on (the pose after it is step ``t + 1``), the end of its initial convergence; 0 when it never passed (the whole
    run counts) and for a known (Gaussian) start, which counts as converged from the start (as KLD's test counts it: a
    tracking filter that fails the gate on its first steps, with a Q far too small, has lost track)."""
    if result.config.init != "uniform":
        return 0
    passed = np.isfinite(result.max_loglik)  # a step with readings
    passed[result.lost_steps] = False
    first = np.flatnonzero(passed)
    return int(first[0]) if len(first) else 0


def _lost_from(result: PFRunResult, start: int) -> np.ndarray:
    """The lost steps from index ``start`` on (``result``'s recorded-mode count: from its first convergence)."""
    return result.lost_steps[result.lost_steps >= start]


def _one_round_fit_record(q_fit: np.ndarray) -> dict[str, Any]:
    """A run's one-round ML Q as ``metrics["q_fit_one_round"]`` records it: the matrix and what it is (it was stored bare
    as "q_fit_ml", read as the Q to use although a re-run with it has another particle spread)."""
    floor = at_lower_bound(q_fit)
    note = ("maximum-likelihood Q of this run's innovations in one round, with the particle spread held fixed; a re-run "
            "with it has another spread, so it is no estimate of Q (fit_q_recorded / --fit-q iterate fit and re-run)")
    if floor:
        note += (f"; a variance at the search floor {Q_VARIANCE_BOUNDS[0]:g}: the particle spread alone over-explains "
                 "the innovations")
    return {"q_cov": np.asarray(q_fit, dtype=np.float64).tolist(), "at_search_floor": floor, "note": note}


def _fitted_q_record(result: PFRunResult, n_fits: int) -> dict[str, Any] | None:
    """The Q ``fit_q_recorded`` reports, as ``metrics["q_fitted"]`` records it: the Q its last run (``result``, fit
    ``n_fits``) used; None when nothing was fitted."""
    if not n_fits:
        return None
    return {"q_cov": result.settings["q_cov"], "run": f"fit {n_fits}",
            "note": "the Q this run used, the last re-run of the fit (settled or not: q_fit_settled)"}


def fit_q_recorded(data, n_particles: int | None = None, seed: int = 0, *, config: PFConfig | None = None,
                   max_rounds: int = 5, warn_lost: bool = True, on_step: Callable[[int, int], None] | None = None,
                   **config_overrides: Any) -> tuple[PFRunResult, list[PFRunResult]]:
    """``--fit-q``: run on the recorded readings of ``data`` (a LandmarkData or its path), take the ML Q of the
    innovations, run again with it; repeat (the particle spread changes with Q) until the NIS mean is within
    [1.5, 2.5], the fit repeats itself, or ``max_rounds`` re-runs. A first run that lost track is not fitted (no verdict
    on Q; a last run that did is not settled). The last run's ``metrics["q_fit_settled"]`` says whether it got there
    (its verdict says so when not). ``warn_lost``: warn if the run with the given Q or the last fit lost track, naming
    which (a discarded round between them, often lost with its too small Q, says nothing).

    Returns the first run and the re-runs (the last one is the answer; its config holds the fitted Q as variances, its
    ``metrics["q_fitted"]`` too, and it has no one-round fit of its own: a further round, never run, is no answer).
    """
    from lidarkit.pf.consistency import NIS_CONSISTENT, scale_fit

    if not is_integer(max_rounds) or max_rounds < 1:  # (0 fitted nothing)
        raise ConfigError(f"max_rounds must be an integer >= 1 (re-runs with a fitted Q), got {max_rounds!r}", source="max_rounds")
    data = landmark_data(data)  # (a path is opened here once, not again for every re-run)
    first = run_recorded(data, n_particles, seed, config=config, warn_lost=False, on_step=on_step, **config_overrides)
    if "q_verdict" in first.metrics:  # (the run with the given Q advised the fit being run: "before: ...; --fit-q estimates Q")
        first.metrics["q_verdict"]["text"] = first.metrics["q_verdict"]["text"].replace(FIT_Q_ADVICE, "")
    runs: list[PFRunResult] = []
    current = first
    # a lost first run: its innovations are localization error, and a Q fitted to them only widens the cloud
    for _ in range(0 if _lost(first) else max_rounds):
        if current.innovation_q_fit is None:
            raise DataError("no readings to fit Q on", source="fit_q")
        q_fit = current.innovation_q_fit  # (a discarded round that lost track still leads to the next)
        if at_lower_bound(q_fit):  # the spread alone over-explains the innovations: scale Q by the ML scale instead
            q_fit = np.asarray(current.settings["q_cov"]) * scale_fit(current.metrics["nis_mean"])
        q_diag = np.diag(q_fit)
        if runs and np.allclose(q_fit, current.settings["q_cov"], rtol=1e-9, atol=0.0):
            break  # the fit gives the Q it ran with: another re-run would repeat this one
        cfg = current.config.replace(q=(float(q_diag[0]), float(q_diag[1])), q_as="variance")
        current = run_recorded(data, None, seed, config=cfg, warn_lost=False, on_step=on_step)
        runs.append(current)
        lo, hi = NIS_CONSISTENT
        if lo <= current.metrics["nis_mean"] <= hi and not _lost(current):
            break
    last = runs[-1] if runs else first
    lo, hi = NIS_CONSISTENT
    settled = lo <= last.metrics["nis_mean"] <= hi and not _lost(last)
    last.metrics["q_fit_settled"] = settled
    last.metrics["q_fitted"] = _fitted_q_record(last, len(runs))
    if runs:  # (its one-round fit, a Q no run used, sat beside the fitted Q with nothing saying which was the answer)
        last.metrics.pop("q_fit_one_round", None)
    if warn_lost:
        _warn_lost(first, " with the given Q")
        if runs:
            _warn_lost(last, f" with the fitted Q (fit {len(runs)})")
    if _lost(last):
        last.metrics["q_verdict"]["text"] += (f"; the fit stopped after {len(runs)} re-run(s)" if runs else "; no Q fit")
    elif not settled and "q_verdict" in last.metrics:  # said, and not "--fit-q estimates Q" after --fit-q has run
        history = " -> ".join(f"{r.metrics['nis_mean']:.3g}" for r in [first, *runs])
        text = last.metrics["q_verdict"]["text"].replace(FIT_Q_ADVICE, "")
        last.metrics["q_verdict"]["text"] = (f"{text}; the fit did not settle within [{lo:g}, {hi:g}] in {len(runs)} re-run(s) "
                                             f"(NIS mean {history}): Q is not all that the innovations say")
    return first, runs


def _lost(result: PFRunResult) -> bool:
    """True when ``result``'s verdict is none: it lost track (see :func:`lidarkit.pf.consistency.localization_problem`)."""
    return result.metrics.get("q_verdict", {}).get("status") == "lost"


def consistency_metrics(nis: np.ndarray, estimate: np.ndarray, dead_reckoning: np.ndarray, data, q_cov: np.ndarray) -> dict[str, Any]:
    """NIS statistics vs chi-square(2) (mean 2, 95% inside 5.99), the same for dead reckoning with S = Q,
    the empirical residual std of the readings at the estimate, and estimate-vs-dead-reckoning distance."""
    lm = np.asarray(data.landmarks.positions_xy)[data.meas_landmark_index]
    pose = estimate[np.asarray(data.meas_step) + 1]
    pose_dr = dead_reckoning[np.asarray(data.meas_step) + 1]
    z = np.stack([data.meas_range_m, data.meas_bearing_rad], axis=1)
    info = np.linalg.inv(q_cov)

    def residual(p: np.ndarray) -> np.ndarray:
        d = lm - p[:, :2]
        h = np.stack([np.hypot(d[:, 0], d[:, 1]), np.arctan2(d[:, 1], d[:, 0]) - p[:, 2]], axis=1)
        e = z - h
        e[:, 1] = wrap_angle(e[:, 1])
        return e

    e_est, e_dr = residual(pose), residual(pose_dr)
    nis_dr = np.einsum("ki,ij,kj->k", e_dr, info, e_dr)
    dist = np.hypot(*(estimate[:, :2] - dead_reckoning[:, :2]).T)
    return {
        "nis_mean": float(nis.mean()) if len(nis) else None,
        "nis_median": float(np.median(nis)) if len(nis) else None,
        "nis_fraction_below_chi2_95": float((nis < CHI2_2DOF_95).mean()) if len(nis) else None,
        "nis_expected_mean": 2.0,
        "nis_expected_fraction": 0.95,
        "n_readings": int(len(nis)),
        "dead_reckoning_nis_mean": float(nis_dr.mean()),
        "dead_reckoning_nis_fraction_below_chi2_95": float((nis_dr < CHI2_2DOF_95).mean()),
        "residual_std_at_estimate": {"range_m": float(e_est[:, 0].std()), "bearing_rad": float(e_est[:, 1].std())},
        "residual_std_at_dead_reckoning": {"range_m": float(e_dr[:, 0].std()), "bearing_rad": float(e_dr[:, 1].std())},
        "estimate_vs_dead_reckoning_m": {"mean": float(dist.mean()), "max": float(dist.max()), "final": float(dist[-1])},
    }


__all__ = [
    "CLOUD_BYTES_PER_PARTICLE",
    "FILTER_BYTES_PER_PARTICLE",
    "KALMAN_BYTES_PER_PARTICLE",
    "MAX_KIDNAP_OFFSET_M",
    "MSE_START_STEP",
    "ODOMETRY_NOISE_STD",
    "POINT_BASE_BYTES_PER_PARTICLE",
    "PFRunResult",
    "SimulatedData",
    "StepReadings",
    "check_config_memory",
    "check_filter_memory",
    "checked_estimators",
    "checked_snapshot_steps",
    "consistency_metrics",
    "filter_bytes_per_particle",
    "first_converged_step",
    "fit_q_recorded",
    "kidnap_offset_record",
    "landmark_data",
    "most_readings_per_step",
    "poses_to_trajectory",
    "run_filter",
    "run_protocol",
    "run_recorded",
    "simulate",
]
