"""Focal length self-calibration from the image sequence when no intrinsics are given.

Assumption: square pixels (``fx = fy = f``), no skew, principal point at the image centre, no lens distortion, a
static scene. Method: short-window bundle adjustment. In windows of ``window`` consecutive frames, corners are
followed by KLT through the whole window; for each focal length of a geometric grid the window's poses and the
points' inverse depths (anchored in the window's first frame) are adjusted (``scipy.optimize.least_squares``, sparse
Jacobian, robust Huber loss). A window grows from ``window`` to ``long_window`` frames when every corner survives
its short span (slow image motion, e.g. a simulated car braking through a corner: 5 frames gave +3.0 / +7.5 %, 10 frames
-0.2..+2.9 % on three seeds, principal point centred); on KITTI 06 and 01 corners are lost faster and the windows stay short. Each window's
focal length is the minimum of its cost profile (parabola in log f); the estimate is the median over windows and its 1-sigma 1.4826 MAD / sqrt(n) in log f (single windows' adjustments can
land in different basins, so summing their costs would let one bad window decide).

Two-view criteria are almost flat in f for car motion (yaw plus forward translation is close to a critical motion);
several frames with a growing baseline constrain it better, but not always: the profile is then flat and the
estimate falls back to the image-size guess with the reason (windows disagreeing by more than
``max_relative_sigma``, or too few windows with an interior minimum). Each adjustment is a plain least-squares solve
followed by the robust one (see ``_WindowBA.solve``). Measured in benchmarks/results/vo_autocalib (KITTI 01 and 06
frames 0-50 within 5 %); the 1-sigma is the windows' spread only: the principal-point assumption (KITTI's is 13 px
off the centre) adds a bias it does not include. A window counts only when its first and last frames show
translation parallax (not explained by a homography); no motion or pure rotation throughout leaves no window, and
the estimate falls back.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import lil_matrix

from lidarkit.errors import ConfigError
from lidarkit.geometry import so3_exp, so3_log
from lidarkit.vo.config import FeatureConfig, GeometryConfig, MatchConfig
from lidarkit.vo.features import get_detector
from lidarkit.vo.intrinsics import DEFAULT_FOCAL_FACTOR, K_from_image_size, K_matrix
from lidarkit.vo.matching import track_klt
from lidarkit.vo.two_view import degeneracy_measures, estimate_two_view, normalize_points

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class FocalEstimate:
    """Result of :func:`estimate_focal`. ``focal_px`` is the estimate when ``constrained`` and the size-based guess
    otherwise; ``sigma_px`` its 1-sigma uncertainty (inf when not constrained); ``reason`` says why not; ``profile``
    maps grid focal lengths (px) to the summed reprojection cost; ``windows`` the windows used."""

    focal_px: float
    sigma_px: float
    constrained: bool
    reason: str
    guess_px: float
    windows: int = 0
    window_focals_px: tuple[float, ...] = ()
    profile: dict[float, float] = field(default_factory=dict)

    def K(self, width: int, height: int) -> np.ndarray:
        """``(3, 3)`` intrinsics with the principal point at the centre of a ``width x height`` image."""
        return K_matrix(self.focal_px, self.focal_px, (width - 1) / 2.0, (height - 1) / 2.0)

    def describe(self) -> str:
        if self.constrained:
            return (f"self-calibrated: fx = fy = {self.focal_px:.1f} +/- {self.sigma_px:.1f} px from {self.windows} "
                    "windows, principal point at centre")
        return f"guess: fx = fy = {self.focal_px:.1f} px (self-calibration could not constrain f: {self.reason})"


@dataclass(frozen=True)
class AutocalibConfig:
    """Windows of ``window`` frames starting every ``stride`` frames (at most ``max_windows``); the focal grid spans
    ``focal_range`` times ``max(w, h)`` in ``grid_steps`` geometric steps. A window grows to ``long_window`` frames
    when all ``max_tracks`` corners survive its first ``window`` frames (slow image motion) and ``long_min_tracks``
    survive the long one; a window needs ``min_tracks`` corners
    tracked through it and translation parallax (homography share below ``max_homography_share``); the estimate is
    accepted when its relative 1-sigma uncertainty is at most ``max_relative_sigma`` and its minimum is inside the
    grid."""

    window: int = 5
    long_window: int = 10
    long_min_tracks: int = 80
    stride: int = 5
    max_windows: int = 6
    max_tracks: int = 150
    min_tracks: int = 40
    focal_range: tuple[float, float] = (0.35, 1.6)
    grid_steps: int = 13
    max_homography_share: float = 0.9
    huber_px: float = 1.0
    outlier_px: float = 3.0
    max_relative_sigma: float = 0.1
    min_windows: int = 3


def _window_tracks(images: list[np.ndarray], cfg: AutocalibConfig) -> np.ndarray | None:
    """``(W, N, 2)`` positions of corners of the first image followed through all images (None if too few)."""
    pts = get_detector(FeatureConfig(max_features=cfg.max_tracks * 2)).detect(images[0])[0]
    track = [pts]
    alive = np.ones(len(pts), bool)
    for a, b in zip(images[:-1], images[1:]):
        nxt, ok = track_klt(a, b, track[-1], MatchConfig())
        alive &= ok
        track.append(nxt)
    obs = np.stack(track)[:, alive]
    # static-scene tracks only: fundamental-matrix inliers (pixel RANSAC, K-free) of consecutive and first-last pairs
    for a, b in [(k, k + 1) for k in range(len(images) - 1)] + [(0, len(images) - 1)]:
        if obs.shape[1] < 8:
            return None
        F, mask = cv2.findFundamentalMat(obs[a], obs[b], cv2.FM_RANSAC, 1.0, 0.999)
        if F is None or mask is None:
            return None
        obs = obs[:, mask.ravel() > 0]
    if obs.shape[1] < cfg.min_tracks:
        return None
    if obs.shape[1] > cfg.max_tracks:
        keep = np.linspace(0, obs.shape[1] - 1, cfg.max_tracks).astype(int)
        obs = obs[:, keep]
    return obs.astype(np.float64)


class _WindowBA:
    """Bundle adjustment of one window with the focal length fixed: poses of frames 1..W-1 (rotation vector and
    translation, the last translation's norm held at 1) and one inverse depth per point anchored in frame 0."""

    def __init__(self, obs_px: np.ndarray, center: np.ndarray, huber_px: float):
        self.obs = obs_px
        self.c = center
        self.W, self.N = obs_px.shape[:2]
        self.huber = huber_px
        self.x: np.ndarray | None = None
        self._fresh: dict[float, Any] = {}  # focal -> solution from the fresh two-view start (None: no start)
        n_pose = 6 * (self.W - 1)
        rows = 2 * self.N * (self.W - 1) + 1
        S = lil_matrix((rows, n_pose + self.N), dtype=np.int8)
        for k in range(1, self.W):
            r0 = 2 * self.N * (k - 1)
            S[r0:r0 + 2 * self.N, 6 * (k - 1):6 * k] = 1
            idx = np.arange(self.N)
            S[r0 + 2 * idx, n_pose + idx] = 1
            S[r0 + 2 * idx + 1, n_pose + idx] = 1
        S[rows - 1, 6 * (self.W - 2) + 3:6 * (self.W - 1)] = 1
        self.sparsity = S.tocsr()

    def initial(self, f: float) -> np.ndarray | None:
        """Poses interpolated from the first-last two-view estimate; inverse depths from its triangulation."""
        K = K_matrix(f, f, *self.c)
        est = estimate_two_view(self.obs[0], self.obs[-1], K, GeometryConfig(), min_inliers=8)
        if not est.ok:
            return None
        w, t = so3_log(est.R_cur_ref), est.t_cur_ref / np.linalg.norm(est.t_cur_ref)
        poses = [np.concatenate([w * k / (self.W - 1), t * k / (self.W - 1)]) for k in range(1, self.W)]
        n0, n1 = normalize_points(self.obs[0], K), normalize_points(self.obs[-1], K)
        rays = np.column_stack([n0, np.ones(self.N)])
        # depth along the frame-0 ray from the two-view pose (linear least squares per point)
        Rr = rays @ est.R_cur_ref.T
        a = Rr[:, :2] - n1 * Rr[:, 2:3]
        b = n1 * t[2] - t[:2]
        depth = np.sum(a * b, axis=1) / np.maximum(np.sum(a * a, axis=1), 1e-12)
        inv = 1.0 / np.clip(depth, 0.5, 1e4)
        return np.concatenate(poses + [inv])

    def residuals(self, x: np.ndarray, f: float) -> np.ndarray:
        """All frames at once: the finite-difference Jacobian calls this once per column group at every step, and a
        loop over frames, one rotation each, spent over half of it in scipy's per-call overhead. (A stacked matmul
        gives the same bits as the per-frame one; einsum sums in another order.)"""
        n_pose = 6 * (self.W - 1)
        poses = x[:n_pose].reshape(self.W - 1, 6)
        inv = x[n_pose:]
        rays = np.column_stack([(self.obs[0] - self.c) / f, np.ones(self.N)])
        # (R ray + rho t) / rho, scaled by rho: (W-1, N, 3)
        X = rays @ so3_exp(poses[:, :3]).transpose(0, 2, 1) + inv[None, :, None] * poses[:, None, 3:]
        z = np.where(np.abs(X[..., 2]) < 1e-9, 1e-9, X[..., 2])
        proj = f * X[..., :2] / z[..., None] + self.c
        t_last = x[n_pose - 3:n_pose]
        return np.concatenate([(proj - self.obs[1:]).ravel(), [100.0 * (float(t_last @ t_last) - 1.0)]])

    def solve(self, x0: np.ndarray, f: float):
        """Plain least squares first, then the robust (Huber) adjustment from its solution. Started far from the
        minimum, scipy's robust trust-region step stalls (it stops on ``ftol`` with tens of points still reprojected
        pixels off, KITTI 01: cost 1390 where the same start reaches 24 without the robust loss), which made the
        window minima land far from the true focal length; the plain solve reaches the basin, the robust one then
        discounts the remaining outliers."""
        kw = dict(args=(f,), jac_sparsity=self.sparsity, x_scale="jac", method="trf", ftol=1e-5, xtol=1e-6)
        plain = least_squares(self.residuals, x0, loss="linear", max_nfev=50, **kw)
        return least_squares(self.residuals, plain.x, loss="huber", f_scale=self.huber, max_nfev=100, **kw)

    def drop_outliers(self, f: float, max_px: float) -> None:
        """Keep the points that the robust adjustment at ``f`` reprojects within ``max_px`` in every frame at a
        positive inverse depth (moving objects and wrong tracks go); points behind the first camera at the two-view
        start go first."""
        x0 = self.initial(f)
        if x0 is None:
            return
        n_pose = 6 * (self.W - 1)
        front = x0[n_pose:] < 1.99
        self.__init__(self.obs[:, front], self.c, self.huber)
        x0 = np.concatenate([x0[:n_pose], x0[n_pose:][front]])
        sol = self.solve(x0, f)
        r = np.abs(sol.fun[:-1].reshape(self.W - 1, self.N, 2)).max(axis=(0, 2))
        keep = (r < max_px) & (sol.x[n_pose:] > 0)
        self.__init__(self.obs[:, keep], self.c, self.huber)

    def cost(self, f: float) -> float:
        """Robust reprojection cost at focal ``f`` (warm-started from the previous solution); inf if it fails. The
        fresh two-view start's solution at ``f`` is kept: the other sweep would solve the same start again."""
        best = None if self.x is None else self.solve(self.x, f)
        if f not in self._fresh:
            x0 = self.initial(f)
            self._fresh[f] = None if x0 is None else self.solve(x0, f)
        fresh = self._fresh[f]  # (warm start and fresh two-view start: the lower cost wins)
        if fresh is not None and (best is None or fresh.cost < best.cost):
            best = fresh
        if best is None:
            return float("inf")
        self.x = best.x
        return float(2.0 * best.cost)


def _grid_costs(ba: _WindowBA, grid: np.ndarray) -> np.ndarray:
    """``(len(grid),)`` lower envelope over basins of one window's cost: at every grid focal the adjustment starts
    from a fresh two-view estimate and from the neighbouring grid focal's solution, in an upward and a downward
    sweep; the lowest cost counts. (A pool worker's job: the windows are independent.)"""
    costs = np.full(len(grid), np.inf)
    for sweep in (range(len(grid)), range(len(grid) - 1, -1, -1)):
        ba.x = None
        for gi in sweep:
            costs[gi] = min(costs[gi], ba.cost(grid[gi]))
    return costs


class _WindowPool:
    """The windows' grid sweeps on ``workers`` processes (None: the CPUs available), at most ``jobs``, started at
    the first job (forkserver on Linux, as :class:`lidarkit.bench.executors.ProcessExecutor`; each worker loads
    lidarkit once); with one worker, in this process when the results are asked for (never, if the estimate falls
    back first). The workers ignore Ctrl-C and die with this process; leaving the block (an error, an interrupt, a
    fallback) stops them and drops the jobs not yet run. A pool that breaks (a worker killed, or one that could not
    start: a script that calls this without ``if __name__ == "__main__":``) leaves its jobs to this process. Every job
    is the same computation wherever it runs, so the estimate does not depend on ``workers``."""

    def __init__(self, workers: int | None, jobs: int):
        from lidarkit.bench.executors import default_workers

        self.workers = min(default_workers() if workers is None else workers, jobs)
        self.jobs: list[tuple[Any, tuple]] = []
        self._futures: list[Any] = []
        self._pool: Any = None
        self._in_process = self.workers <= 1  # (and once a pool broke)

    def __enter__(self) -> "_WindowPool":
        return self

    def __exit__(self, *exc: Any) -> None:
        self._stop()

    def submit(self, fn: Any, *args: Any) -> None:
        """Queue ``fn(*args)``; a pool starts on it now."""
        from concurrent.futures.process import BrokenProcessPool

        self.jobs.append((fn, args))
        if not self._in_process:
            if self._pool is None:
                self._pool = self._start()
            try:
                self._futures.append(self._pool.submit(fn, *args))
            except BrokenProcessPool:
                self._broken()

    def results(self) -> Iterator[tuple[int, Any]]:
        """``(job index, result)`` of every job as it ends."""
        from concurrent.futures import as_completed
        from concurrent.futures.process import BrokenProcessPool

        left = set(range(len(self.jobs)))
        if not self._in_process:
            index = {future: i for i, future in enumerate(self._futures)}
            try:
                for future in as_completed(self._futures):
                    yield index[future], future.result()
                    left.discard(index[future])
            except BrokenProcessPool:
                self._broken()
        for i in sorted(left):
            fn, args = self.jobs[i]
            yield i, fn(*args)

    def _broken(self) -> None:
        log.warning("focal length self-calibration: a worker process died or could not start (a script needs "
                    "`if __name__ == \"__main__\":`); adjusting the windows left in this process")
        self._in_process = True
        self._stop()

    def _stop(self) -> None:
        if self._pool is not None:
            from lidarkit.bench.executors import stop_pool

            stop_pool(self._pool)
            self._pool = None

    def _start(self) -> Any:
        from lidarkit.bench.executors import pool_context, worker_pool

        return worker_pool(self.workers, pool_context())


def _has_parallax(obs: np.ndarray, guess_K: np.ndarray, cfg: AutocalibConfig) -> bool:
    deg = degeneracy_measures(obs[0].astype(np.float32), obs[-1].astype(np.float32), guess_K, GeometryConfig())
    return deg.fundamental_inliers >= 8 and deg.homography_share < cfg.max_homography_share


def _parabola_min(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Vertex and second derivative of the parabola through three points."""
    A = np.column_stack([x * x, x, np.ones(3)])
    a, b, _ = np.linalg.solve(A, y)
    return (-b / (2 * a) if a > 0 else float(x[1])), 2 * a


def estimate_focal(images: Any, cfg: AutocalibConfig | None = None, focal_factor: float = DEFAULT_FOCAL_FACTOR,
                   on_step: Any = None, workers: int | None = 1) -> FocalEstimate:
    """Estimate ``fx = fy`` of an uncalibrated image sequence (``len`` + ``read_image(i)``, or a list of uint8
    ``(H, W)`` arrays). Falls back to ``focal_factor * max(w, h)`` with the reason when the motion does not
    constrain it; never raises for degenerate motion. ``on_step(done, total)``: called as the windows are tracked
    and adjusted (two steps a window), for progress. ``workers``: processes adjusting the windows while the next ones
    are tracked (1, the default: all in this process; None: the CPUs available, as ``lidarkit vo`` runs it); the
    estimate is the same for any number. More than one needs the calling script guarded by
    ``if __name__ == "__main__":`` (the workers import it again), as any process pool does."""
    cfg = cfg or AutocalibConfig()
    if workers is not None and workers < 1:
        raise ConfigError(f"must be >= 1, got {workers}", source="workers")
    if cfg.window < 3:
        raise ConfigError(f"window must be >= 3 frames, got {cfg.window}", source="autocalib")
    from lidarkit.vo.pipeline import MonoVO, sequence_image_shape

    read = images.read_image if hasattr(images, "read_image") else (lambda i: images[i])
    n = len(images)
    h, w = sequence_image_shape(images)[:2]
    guess = float(K_from_image_size(w, h, focal_factor)[0, 0])
    center = np.array([(w - 1) / 2.0, (h - 1) / 2.0])
    guess_K = K_from_image_size(w, h, focal_factor)

    def fallback(reason: str, **kw) -> FocalEstimate:
        return FocalEstimate(guess, float("inf"), False, reason, guess, **kw)

    if n < cfg.window:
        return fallback(f"{n} frames, a window needs {cfg.window}")
    if n < cfg.window + cfg.stride:
        return fallback(f"{n} frames hold one window of {cfg.window} frames (stride {cfg.stride}); at least 2 are "
                        "needed")
    starts = list(range(0, n - cfg.window + 1, cfg.stride))
    if len(starts) > cfg.max_windows:
        starts = [starts[i] for i in np.linspace(0, len(starts) - 1, cfg.max_windows).astype(int)]
    steps = 2 * len(starts)

    def step(done: int) -> None:
        if on_step is not None:
            on_step(done, steps)

    side = max(w, h)
    grid = side * np.geomspace(cfg.focal_range[0], cfg.focal_range[1], cfg.grid_steps)
    unusable = 0  # windows with an unreadable or odd-sized frame among the frames they track
    with _WindowPool(workers, len(starts)) as pool:  # each window's costs on the grid: a worker adjusts one as the next is tracked
        for k, s in enumerate(starts):
            step(k)
            frames = [MonoVO._load(read, i)[0] for i in range(s, min(s + max(cfg.long_window, cfg.window), n))]
            good = [f is not None and f.shape[:2] == (h, w) for f in frames]
            if not all(good[:cfg.window]):
                unusable += 1  # (a bad frame beyond the window only bars the longer window: it dropped clean windows)
                continue
            frames = frames[:next((i for i, g in enumerate(good) if not g), len(frames))]  # the longer window ends before it
            obs = _window_tracks(frames[:cfg.window], cfg)
            if obs is not None and obs.shape[1] >= cfg.max_tracks and len(frames) > cfg.window:
                # every corner survived: the image moves slowly, and a longer window adds baseline and rotation
                long_obs = _window_tracks(frames, cfg)
                if long_obs is not None and long_obs.shape[1] >= cfg.long_min_tracks:
                    obs = long_obs
            if obs is not None and _has_parallax(obs, guess_K, cfg):
                ba = _WindowBA(obs, center, cfg.huber_px)
                ba.drop_outliers(guess, cfg.outlier_px)
                if ba.N >= cfg.min_tracks:
                    pool.submit(_grid_costs, ba, grid)
        if len(pool.jobs) < 2:
            skipped = f", {unusable} more hold an unreadable or odd-sized frame" if unusable else ""
            usable = len(starts) - unusable
            why = " (no motion or pure rotation)" if len(pool.jobs) < usable else ""  # (not when every usable one does)
            return fallback(f"{len(pool.jobs)} of {usable} windows show translation parallax{why}{skipped}; at least 2 "
                            "are needed")
        # lower envelope over basins (see _grid_costs); progress as the windows' adjustments end
        step(len(starts))
        rows = {}
        for i, row in pool.results():
            rows[i] = row
            step(len(starts) + round(len(rows) * len(starts) / len(pool.jobs)))
        costs = np.array([rows[i] for i in range(len(rows))])
    usable = np.all(np.isfinite(costs), axis=1)
    costs = costs[usable]
    if len(costs) < 2:
        return fallback("the window adjustments failed")
    total = costs.sum(axis=0)
    profile = {float(g): float(c) for g, c in zip(grid, total)}
    logg = np.log(grid)
    # each window's own minimum (parabola in log f through the lowest grid point and its neighbours); a window whose
    # cost still falls at a grid edge does not constrain f. The windows' adjustments can land in different basins, so
    # their minima are combined robustly (median, spread by the MAD) rather than by summing the costs.
    per_window = []
    for row in costs:
        i = int(np.argmin(row))
        if 0 < i < len(grid) - 1:
            per_window.append(float(np.exp(_parabola_min(logg[i - 1:i + 2], row[i - 1:i + 2])[0])))
    kw = dict(windows=len(costs), window_focals_px=tuple(per_window), profile=profile)
    if len(per_window) < cfg.min_windows:
        skipped = f" ({unusable} more hold an unreadable or odd-sized frame)" if unusable else ""
        return fallback(f"only {len(per_window)} of {len(costs)} windows{skipped} have a reprojection-cost minimum inside the "
                        f"focal grid ({grid[0]:.0f}-{grid[-1]:.0f} px); at least {cfg.min_windows} are needed", **kw)
    logs = np.log(per_window)
    log_f = float(np.median(logs))
    sigma_log = float(1.4826 * np.median(np.abs(logs - log_f)) / np.sqrt(len(logs)))
    f = float(np.exp(log_f))
    sigma = f * sigma_log
    if not sigma_log <= cfg.max_relative_sigma:
        return fallback(f"the windows disagree (median {f:.0f} px, 1-sigma {100 * sigma_log:.0f} % > "
                        f"{100 * cfg.max_relative_sigma:.0f} %)", **kw)
    return FocalEstimate(f, sigma, True, "", guess, **kw)
