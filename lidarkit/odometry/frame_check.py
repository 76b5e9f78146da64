"""An independent per-frame check of an odometry estimate, the same for every variant (stateful ones included).

A variant's own verdict ("converged") says its optimizer stopped, not that the pose is right: point-to-point ICP
on an open scene "converges" every frame onto the ground rings while the trajectory falls metres behind. This
check uses only the estimated poses and the raw scans, never the variant's verdict:

* **motion**: the frame's relative motion against the constant-velocity prediction (the previous relative
  motion, its translation and rotation vector scaled by the ratio of the frame intervals). The deviation implies an acceleration ``d / dt^2``;
  a frame fails when it exceeds ``max_accel_mps2`` (translation) or ``max_angular_accel_dps2`` (rotation).
  Frame 1 has no prediction and is not checked for motion; nor is a frame whose stamps cannot time the motion (an
  interval under a quarter of the median, or 4 times longer or shorter than the previous one).
* **fitness**: scan ``k`` mapped into scan ``k-1`` by the estimated relative motion; the fraction of its
  above-ground points (a random subsample of ``n_sample``) whose nearest above-ground point of scan ``k-1``
  lies within ``max(inlier_min_m, inlier_range_fraction * range)``. A frame fails below ``min_fitness``.
  The ground is left out because a flat ground fits any in-plane slide, and its rings (fixed to the sensor)
  fit best at zero motion: they would reward exactly the failure the check looks for. The ground is the
  densest 0.1 m layer of heights within 30 m of the sensor (a roughly level sensor); a scan with fewer than
  ``min_points`` points above it is not checked for fitness.

Cost: each scan is subsampled to ``max_target_points`` (seeded), split at the ground, one KD-tree over its
above-ground points and ``n_sample`` queries, ~2.5 ms of CPU a KITTI scan (a tenth of kiss-icp's frame); the motion
part is vectorized over the whole run afterwards and costs nothing per frame. ``n_sample=0`` leaves the fitness part
out (every frame "not checked" for fitness) and keeps the motion part.

Where it runs: the pose-free part (:meth:`FrameChecker.prepare`) in the odometry run's reading thread, the queries
(:meth:`FrameChecker.add`) in a thread of the checker's own (``overlap=True``) while the next frame registers. The
tree is scipy's ``cKDTree``, whose build and queries let other Python threads run (``benchmarks/gil_probe.py``
probes both): small_gicp's ``KdTree``, used before, answered the queries in half the time but held the GIL while it
was built (``gil_probe.md``), and the registration in the main thread waited for it (kiss through lidarkit 0.79x
kiss-icp's pipeline with the check, 0.96x without). Both trees are exact: the same nearest distances, so the same fitness (scipy takes
the square root of the squared distance as small_gicp's caller did; a distance within rounding of a point's
tolerance is the only case the two could tell apart).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np

from lidarkit.params import is_real_number

#: The motion test skips a frame whose interval, or the previous one, is below this fraction of the run's median
#: interval, or whose interval differs from the previous one by more than this ratio: such stamps do not time the motion
#: (a 10 Hz sensor that drops a sweep, ratio 2, is still checked).
MIN_INTERVAL_FRACTION = 0.25
MAX_INTERVAL_RATIO = 4.0

#: Height bins (m) and horizontal radius (m) of the ground estimate.
_GROUND_BIN_M = 0.1
_GROUND_RADIUS_M = 30.0


@dataclass(frozen=True)
class FrameCheckConfig:
    """Thresholds of the per-frame check (a 10 Hz sensor gives 0.15 m and 3 deg)."""

    max_accel_mps2: float = 15.0
    """Largest plausible change of velocity per second (1.5 g; cars brake at <= 10 m/s^2)."""
    max_angular_accel_dps2: float = 300.0
    """Largest plausible change of turn rate per second (deg/s^2): an indoor robot starting to turn in place reaches
    ~200 (the ACES CARMEN log: 100 flagged 11 of 300 correctly registered frames, 200 none)."""
    nominal_period_s: float = 0.1
    """Frame interval used when the dataset has no time stamps, per step of its frame numbers (the odometry runner
    passes them as times: a frame after a gap in the numbers is timed across the gap)."""
    min_fitness: float = 0.3
    inlier_min_m: float = 0.2
    inlier_range_fraction: float = 0.02
    ground_clearance_m: float = 0.3
    n_sample: int = 1500
    """Points of scan k tested against scan k-1 (0: no fitness test, the motion test only)."""
    max_target_points: int = 20000
    """Scans are thinned (every k-th point) to at most this many points before the ground split and the KD-tree."""
    min_points: int = 50
    seed: int = 0

    def __post_init__(self) -> None:  # built by the CLI (make_frame_check) or by hand: checked alike
        _check_config(self)

    def describe(self) -> dict[str, Any]:
        """The thresholds in words and numbers (written to metrics.json)."""
        return {
            **asdict(self),
            "motion_rule": "fails when |t_k - t_pred| / dt^2 > max_accel_mps2 or angle(R_pred^T R_k) / dt^2 > max_angular_accel_dps2 "
            "(prediction: the previous relative motion; not checked: frame 1, and frames whose interval or the previous one is "
            f"below {MIN_INTERVAL_FRACTION:g} x the median interval, or differs from the previous one by more than {MAX_INTERVAL_RATIO:g}x)",
            "fitness_rule": "fails when fewer than min_fitness of the sampled above-ground points of scan k, mapped by the estimated "
            "motion, lie within max(inlier_min_m, inlier_range_fraction * range) of an above-ground point of scan k-1",
        }


def make_frame_check(**params: Any) -> FrameCheckConfig:
    """A :class:`FrameCheckConfig` from ``KEY=VALUE`` settings (e.g. the CLI's ``--check``, text or numbers); unknown
    keys raise ConfigError naming the valid keys, bad values as :class:`FrameCheckConfig` does."""
    from lidarkit.errors import ConfigError

    valid = [f.name for f in fields(FrameCheckConfig)]
    unknown = sorted(set(params) - set(valid))
    if unknown:
        raise ConfigError(f"unknown setting(s) {', '.join(unknown)}; valid: {', '.join(valid)}", source="frame check")
    values: dict[str, Any] = {}
    for key, value in params.items():
        try:
            if isinstance(value, bool):  # (the CLI reads "true" as True, which float() took for 1)
                raise TypeError
            number = float(value)
        except (TypeError, ValueError):
            raise ConfigError(f"{key} must be a number, got {value!r}", source="frame check") from None
        values[key] = int(number) if _WHOLE[key] and number.is_integer() else number  # (1.5 is refused, not cut to 1)
    return FrameCheckConfig(**values)


def _check_config(config: FrameCheckConfig) -> None:
    """ConfigError for a setting that is not a finite number of its kind, or settings under which nothing is checked."""
    from lidarkit.errors import ConfigError

    for f in fields(config):
        value = getattr(config, f.name)
        if not is_real_number(value):
            raise ConfigError(f"{f.name} must be a number, got {value!r}", source="frame check")
        if not np.isfinite(value):
            raise ConfigError(f"{f.name} must be a finite number, got {value!r}", source="frame check")
        if _WHOLE[f.name] and not float(value).is_integer():
            raise ConfigError(f"{f.name} must be a whole number, got {value!r}", source="frame check")
        may_be_zero = f.name in ("seed", "n_sample")  # n_sample=0: no fitness test
        if value < 0 if may_be_zero else value <= 0:
            raise ConfigError(f"{f.name} must be {'>= 0' if may_be_zero else 'positive'}, got {value!r}", source="frame check")
    if config.min_fitness > 1:
        raise ConfigError(f"min_fitness is a share of the sampled points, at most 1, got {config.min_fitness:g}", source="frame check")
    if 0 < config.n_sample < config.min_points:  # the test would skip every frame (fewer than min_points sampled)
        raise ConfigError(f"n_sample {config.n_sample} is below min_points {config.min_points}: no frame would be checked for "
                          "fitness (n_sample=0 turns the test off)", source="frame check")
    if config.n_sample and config.max_target_points < config.min_points:
        raise ConfigError(f"max_target_points {config.max_target_points} is below min_points {config.min_points}: no frame would "
                          "be checked for fitness", source="frame check")


def as_frame_check(value: Any) -> FrameCheckConfig:
    """The run's frame-check settings: None (the defaults), a :class:`FrameCheckConfig` or a mapping of its settings."""
    from lidarkit.errors import ConfigError

    if value is None:
        return FrameCheckConfig()
    if isinstance(value, FrameCheckConfig):
        return value
    if isinstance(value, dict):
        return make_frame_check(**value)
    raise ConfigError(f"frame_check must be a FrameCheckConfig or a mapping of its settings, got {type(value).__name__}", source="frame check")


#: settings that count things (whole numbers)
_WHOLE = {f.name: f.type in (int, "int") for f in fields(FrameCheckConfig)}


@dataclass
class ScanGeometry:
    """What the check keeps of a scan: its above-ground points (a target for the next frame, with their KD-tree)
    and the sampled above-ground points mapped onto the previous scan."""

    target_xyz: np.ndarray
    tree: Any
    sample_xyz: np.ndarray


def ground_height(points_xyz: np.ndarray) -> float | None:
    """Height of the densest ``0.1 m`` layer of points within 30 m of the sensor (the ground of a level sensor), or None."""
    near = points_xyz[np.einsum("ij,ij->i", points_xyz[:, :2], points_xyz[:, :2]) < _GROUND_RADIUS_M**2, 2]
    if len(near) < 50:
        return None
    lo = float(near.min())
    counts = np.bincount(((near - lo) / _GROUND_BIN_M).astype(np.int64))
    i = int(counts.argmax())
    if counts[i] < 0.1 * len(near):  # no dominant layer: no ground to leave out
        return None
    return lo + (i + 0.5) * _GROUND_BIN_M


def scan_geometry(points_xyz: np.ndarray, config: FrameCheckConfig, frame: int) -> ScanGeometry:
    """The check's view of one scan: every k-th point (at most ``max_target_points``) split at the ground height, and
    ``n_sample`` of its above-ground points drawn with a generator seeded by ``(seed, frame)`` (so the result does
    not depend on which frames were checked before)."""
    from scipy.spatial import cKDTree

    rng = np.random.default_rng([config.seed, int(frame)])
    points = points_xyz[:: -(-len(points_xyz) // config.max_target_points)]  # every k-th point: spread over the sweep
    g = ground_height(points)
    target = points if g is None else points[points[:, 2] > g + 0.5 * config.ground_clearance_m]
    # (above g + clearance is above g + clearance / 2, in floating point too: the same rows as from `points`, fewer to scan)
    candidates = target if g is None else target[target[:, 2] > g + config.ground_clearance_m]
    if len(candidates) > config.n_sample:
        candidates = candidates[rng.choice(len(candidates), size=config.n_sample, replace=False)]
    tree = None
    if len(target) >= config.min_points:
        # scipy's tree: built and queried with the GIL released, beside the registration (small_gicp's held it)
        tree = cKDTree(target, balanced_tree=False, compact_nodes=False)
    return ScanGeometry(target, tree, candidates)


def _nearest_distance(tree: Any, queries_xyz: np.ndarray, upper_m: float) -> np.ndarray:
    """Distance (m) from each query to its nearest point of ``tree`` (inf when farther than ``upper_m``)."""
    dist, _ = tree.query(queries_xyz, k=1, distance_upper_bound=upper_m)
    return dist


def scan_fitness(previous: ScanGeometry, current: ScanGeometry, T_previous_current: np.ndarray, config: FrameCheckConfig) -> float:
    """Fitness of the current scan's sample mapped by ``T_previous_current`` onto the previous scan's above-ground
    points; NaN when either has fewer than ``min_points`` above-ground points (not checked)."""
    sample = current.sample_xyz
    if previous.tree is None or len(sample) < config.min_points:
        return float("nan")
    mapped = sample @ T_previous_current[:3, :3].T + T_previous_current[:3, 3]
    tolerance = np.maximum(config.inlier_min_m, config.inlier_range_fraction * np.linalg.norm(sample, axis=1))
    dist = _nearest_distance(previous.tree, mapped, float(tolerance.max()))
    return float(np.mean(dist < tolerance))


def motion_deviation(poses_se3: np.ndarray, times_s: np.ndarray | None, config: FrameCheckConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per frame ``(n,)``: translation deviation (m) and rotation deviation (deg) of the relative motion from the
    constant-velocity prediction, and the frame interval used (s). NaN for frames 0 and 1 (no prediction)."""
    n = len(poses_se3)
    dev_t, dev_r = np.full(n, np.nan), np.full(n, np.nan)
    dt = np.full(n, np.nan)
    if n >= 2:
        if times_s is not None and len(times_s) == n and np.all(np.diff(times_s) > 0):
            dt[1:] = np.diff(np.asarray(times_s, dtype=np.float64))
        else:
            dt[1:] = config.nominal_period_s
    if n < 3:
        return dev_t, dev_r, dt
    rel = _relative(poses_se3)  # (n-1, 4, 4): motion of frame k in frame k-1, k = 1..n-1
    scale = dt[2:] / dt[1:-1]
    predicted_t = rel[:-1, :3, 3] * scale[:, None]
    dev_t[2:] = np.linalg.norm(rel[1:, :3, 3] - predicted_t, axis=1)
    from scipy.spatial.transform import Rotation

    # the predicted rotation turns at the previous rate: its rotation vector scaled by the interval ratio
    predicted_r = Rotation.from_rotvec(Rotation.from_matrix(rel[:-1, :3, :3]).as_rotvec() * scale[:, None])
    dev_r[2:] = np.degrees((predicted_r.inv() * Rotation.from_matrix(rel[1:, :3, :3])).magnitude())
    # intervals that cannot time the motion (stamps of delivery, not capture: Intel's CARMEN log has 109 frames 0.1-5 ms
    # after the previous one, and scaled the prediction 483-fold after one): not checked for motion
    shortest = MIN_INTERVAL_FRACTION * np.median(dt[1:])
    untimed = ~((dt[2:] >= shortest) & (dt[1:-1] >= shortest) & (scale <= MAX_INTERVAL_RATIO) & (scale >= 1.0 / MAX_INTERVAL_RATIO))
    dev_t[2:][untimed] = np.nan
    dev_r[2:][untimed] = np.nan
    return dev_t, dev_r, dt


def _relative(poses: np.ndarray) -> np.ndarray:
    """``T_{k-1}^-1 T_k`` for k = 1..n-1, vectorized (rigid inverse: R^T, -R^T t)."""
    R, t = poses[:-1, :3, :3], poses[:-1, :3, 3]
    inv = np.zeros_like(poses[:-1])
    inv[:, :3, :3] = np.transpose(R, (0, 2, 1))
    inv[:, :3, 3] = -np.einsum("nji,nj->ni", R, t)
    inv[:, 3, 3] = 1.0
    return np.einsum("nij,njk->nik", inv, poses[1:])


def motion_limits(dt_s: np.ndarray, config: FrameCheckConfig) -> tuple[np.ndarray, np.ndarray]:
    """Per-frame limits of the translation (m) and rotation (deg) deviation implied by the acceleration bounds."""
    return config.max_accel_mps2 * dt_s**2, config.max_angular_accel_dps2 * dt_s**2


@dataclass(frozen=True)
class FrameCheck:
    """Per-frame outcome ``(n,)`` arrays: deviations, limits, fitness, and which frames failed (and why)."""

    motion_dev_m: np.ndarray
    rotation_dev_deg: np.ndarray
    motion_limit_m: np.ndarray
    rotation_limit_deg: np.ndarray
    fitness: np.ndarray
    failed_motion: np.ndarray
    failed_fitness: np.ndarray
    config: FrameCheckConfig

    @property
    def failed(self) -> np.ndarray:
        return self.failed_motion | self.failed_fitness


class FrameChecker:
    """Runs the check frame by frame inside the odometry loop (fitness needs both scans); motion at the end.

    ``overlap=True``: frame k's nearest-neighbour queries run in a worker thread of the checker's own while the caller
    goes on (the next frame registers); :meth:`add` first waits for the previous frame's (raising its error, if any),
    :meth:`finish` for the last, and :meth:`close` (also on error or interrupt) joins the thread. The values are those
    of the same calls in line (``overlap=False``, the default: ``fitness`` is complete after each :meth:`add`).
    """

    def __init__(self, n_frames: int, config: FrameCheckConfig | None = None, *, overlap: bool = False):
        from lidarkit.threads import Overlap

        self.config = as_frame_check(config)
        self.fitness = np.full(n_frames, np.nan)
        self.has_point_times = np.zeros(n_frames, dtype=bool)
        self.check_s = np.zeros(n_frames)
        self._previous: ScanGeometry | None = None
        # (no thread when there are no queries to run: n_sample=0)
        self._overlap = bool(overlap) and self.config.n_sample > 0
        self._worker = Overlap(self._overlap)
        self._pending = None  # the last frame's queries, submitted to the worker

    def prepare(self, frame: int, points_xyz: np.ndarray) -> tuple[ScanGeometry | None, float]:
        """The scan's part of the check, which needs no pose (``(geometry, seconds)``): the odometry runner calls it
        in its reading thread, so it overlaps the registration of the previous frame."""
        import time

        if self.config.n_sample == 0:  # no fitness test: nothing to prepare
            return None, 0.0
        t0 = time.perf_counter()
        geometry = scan_geometry(points_xyz, self.config, frame)
        return geometry, time.perf_counter() - t0

    def add(
        self, k: int, frame: int, points_xyz: np.ndarray, point_times_s: np.ndarray | None, poses_se3: np.ndarray,
        prepared: tuple[ScanGeometry, float] | None = None,
    ) -> None:
        """Frame ``k`` of the run (dataset index ``frame``) once its pose ``poses_se3[k]`` is known; ``prepared``:
        :meth:`prepare`'s result for this scan if already computed (``check_s`` counts its time as well)."""
        import time

        t0 = time.perf_counter()
        self.has_point_times[k] = point_times_s is not None
        if self.config.n_sample == 0:  # the motion test only (at the end): fitness stays NaN, "not checked"
            return
        geometry, prepare_s = prepared if prepared is not None else (scan_geometry(points_xyz, self.config, frame), 0.0)
        if geometry is None:  # points the reading refused (left to the registration): not checked, nor the next frame
            self._previous = None
            return
        previous, self._previous = self._previous, geometry
        self._wait()  # the previous frame's queries (done by now: they ran while this frame registered)
        before_s = time.perf_counter() - t0 + prepare_s
        if k > 0 and previous is not None:
            self._pending = self._worker.submit(lambda: self._fitness(k, previous, geometry, poses_se3, before_s))
            if not self._overlap:
                self._wait()  # in line: its error now, as before
        else:
            self.check_s[k] = before_s

    def _fitness(self, k: int, previous: ScanGeometry, current: ScanGeometry, poses_se3: np.ndarray, before_s: float) -> None:
        """Frame k's fitness (in the worker thread when overlapped: ``poses_se3[k - 1 : k + 1]`` are final, the caller
        only writes later frames'); ``before_s``: the check's time spent before."""
        import time

        t0 = time.perf_counter()
        T = _relative(poses_se3[k - 1 : k + 1])[0]
        self.fitness[k] = scan_fitness(previous, current, T, self.config)
        self.check_s[k] = before_s + time.perf_counter() - t0

    def _wait(self) -> None:
        """Wait for the queries submitted last; raises their error."""
        pending, self._pending = self._pending, None
        if pending is not None:
            pending.result()

    def close(self) -> None:
        """Join the worker thread, the run's ``finally`` (also on error or interrupt): the last frame's queries, at most
        one frame's, finish first; their result or error stays for :meth:`finish`."""
        from concurrent.futures import wait

        if self._pending is not None:
            wait([self._pending])
        self._worker.close()

    def finish(self, poses_se3: np.ndarray, times_s: np.ndarray | None) -> FrameCheck:
        cfg = self.config
        try:
            self._wait()
        finally:
            self.close()
        dev_t, dev_r, dt = motion_deviation(poses_se3, times_s, cfg)
        lim_t, lim_r = motion_limits(dt, cfg)
        with np.errstate(invalid="ignore"):
            failed_motion = (dev_t > lim_t) | (dev_r > lim_r)
            failed_fitness = self.fitness < cfg.min_fitness
        self._previous = None
        return FrameCheck(dev_t, dev_r, lim_t, lim_r, self.fitness.copy(), failed_motion, failed_fitness, cfg)
