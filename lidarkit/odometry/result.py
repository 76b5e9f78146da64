"""What an odometry run produced: the estimate, per-frame diagnostics, the settings and the scores."""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from lidarkit.trajectory import Trajectory


@dataclass(frozen=True)
class FrameStats:
    """Per-frame diagnostics, one entry per processed frame (arrays of shape ``(n,)``).

    ``read_s`` / ``register_s``: wall time reading the scan and registering it; ``n_points``: points in
    the scan; for stateless variants ``converged``, ``iterations``, ``rmse_m``, ``n_correspondences``,
    ``degenerate`` and ``reason`` of the scan-to-scan alignment that produced the frame's pose;
    ``min_eigenvalue``: smallest eigenvalue of the frame's normalised normal matrix (NaN where not assessed);
    ``measured``: False where the runner has no convergence verdict (frame 0 of a stateless chain, every
    frame of a stateful variant such as kiss, which reports none): there ``converged`` is True only as a
    placeholder, iterations -1, rmse NaN, and the CSV / CLI show "n/a"; ``fallback``: the registration was
    rejected (not converged) and the frame's pose uses the previous relative motion (constant velocity);
    ``assessed``: False where a measured frame's result was not assessed (``assess=False``: no RMSE, correspondences
    or degeneracy, shown "n/a" as for a frame without a verdict, not as 0 / not degenerate); None: all were.

    The independent check (:mod:`lidarkit.odometry.frame_check`, every variant): ``motion_dev_m`` /
    ``rotation_dev_deg`` (deviation from the constant-velocity prediction, NaN for frames 0-1), ``fitness``
    (above-ground fitness against the previous scan, NaN when not checked), ``check_failed`` and ``check_why``
    (``"motion"``, ``"fitness"``, ``"motion+fitness"`` or ``""``); ``has_point_times``: the scan came with
    per-point times; ``check_s``: time spent on the check.

    ``stateful``: True where the variant registers every frame, the first too, against its own map (kiss), False for a
    scan-to-scan chain, whose frame 0 is not registered; None (not said): every frame counted as registered, as the
    metrics count them for a run whose config does not say.
    """

    frame: np.ndarray
    read_s: np.ndarray
    register_s: np.ndarray
    n_points: np.ndarray
    converged: np.ndarray
    iterations: np.ndarray
    rmse_m: np.ndarray
    n_correspondences: np.ndarray
    degenerate: np.ndarray
    reason: tuple[str, ...]
    measured: np.ndarray
    fallback: np.ndarray
    has_point_times: np.ndarray | None = None
    motion_dev_m: np.ndarray | None = None
    rotation_dev_deg: np.ndarray | None = None
    fitness: np.ndarray | None = None
    check_failed: np.ndarray | None = None
    check_why: tuple[str, ...] = ()
    check_s: np.ndarray | None = None
    min_eigenvalue: np.ndarray | None = None
    assessed: np.ndarray | None = None
    stateful: bool | None = None

    def __repr__(self) -> str:
        """One line of counts (the generated one printed every array: 11,600 characters for 60 frames), of the frames
        metrics.json counts: the registration time of the frames registered, as ``register_time_s`` (frame 0's 0 s of a
        chain pulled it 25 % low over 4 frames), and no degenerate count without a verdict (a stateful variant's read
        "0 degenerate" where ``n_degenerate`` is null)."""
        from lidarkit.odometry.metrics import _register_times  # (metrics imports this module)

        n = len(self.frame)
        assessed = self.assessed if self.assessed is not None else np.ones(n, dtype=bool)
        degeneracy_known = bool(self.measured.any()) and bool(assessed[self.measured].all())
        counts = [f"{int(np.count_nonzero(self.fallback))} fallback",
                  f"{int(np.count_nonzero(self.degenerate & self.measured))} degenerate" if degeneracy_known else "degenerate n/a",
                  f"{int(np.count_nonzero(self.check_failed if self.check_failed is not None else ()))} failing the check"]
        mean_s = _register_times(self.register_s, stateful=self.stateful is not False)["mean"]
        mean = f", registration {mean_s:.3g} s a frame" if mean_s is not None else ""
        return f"FrameStats({n} frames: {', '.join(counts)}{mean}; to_csv() for every frame)"

    def to_csv(self) -> str:
        buf = io.StringIO()
        writer = csv.writer(buf, lineterminator="\n")
        writer.writerow([
            "frame", "read_s", "register_s", "n_points", "converged", "iterations", "rmse_m", "n_correspondences", "degenerate",
            "min_eigenvalue", "constant_velocity_fallback", "reason", "point_times", "motion_dev_m", "rotation_dev_deg", "fitness",
            "check_failed", "check_why",
        ])
        n = len(self.frame)
        nan = np.full(n, np.nan)
        has_times = self.has_point_times if self.has_point_times is not None else np.zeros(n, dtype=bool)
        dev_t = self.motion_dev_m if self.motion_dev_m is not None else nan
        dev_r = self.rotation_dev_deg if self.rotation_dev_deg is not None else nan
        fitness = self.fitness if self.fitness is not None else nan
        failed = self.check_failed if self.check_failed is not None else np.zeros(n, dtype=bool)
        why = self.check_why or ("",) * n
        min_eig = self.min_eigenvalue if self.min_eigenvalue is not None else nan
        assessed = self.assessed if self.assessed is not None else np.ones(n, dtype=bool)
        for k in range(n):
            measured = bool(self.measured[k])
            scored = measured and bool(assessed[k])
            writer.writerow([
                int(self.frame[k]), f"{self.read_s[k]:.6f}", f"{self.register_s[k]:.6f}", int(self.n_points[k]),
                int(self.converged[k]) if measured else "n/a", int(self.iterations[k]) if measured else "n/a",
                f"{self.rmse_m[k]:.6g}" if scored else "n/a", int(self.n_correspondences[k]) if scored else "n/a",
                int(self.degenerate[k]) if scored else "n/a", f"{min_eig[k]:.6g}" if np.isfinite(min_eig[k]) else "n/a",
                int(self.fallback[k]), self.reason[k],
                int(has_times[k]), _opt(dev_t[k], ".4f"), _opt(dev_r[k], ".4f"), _opt(fitness[k], ".3f"), int(failed[k]), why[k],
            ])
        return buf.getvalue()


def _opt(value: float, spec: str) -> str:
    return "n/a" if not np.isfinite(value) else format(value, spec)


@dataclass(frozen=True)
class OdometryResult:
    """What :func:`lidarkit.odometry.run` produced: the estimate, how long each frame took, the settings and the scores.

    ``trajectory``: ``T_world_lidar`` of the processed frames (first pose = identity, timestamps from the
    dataset when it has them); ``ground_truth``: the reference it was scored against, expressed relative
    to its first pose (None without ground truth); ``metrics``: the content of ``metrics.json``.
    """

    trajectory: Trajectory
    method: str
    config: dict[str, Any]
    frames: np.ndarray
    stats: FrameStats
    total_time_s: float
    ground_truth: Trajectory | None = None
    metrics: dict[str, Any] = field(default_factory=dict)
    out_dir: Path | None = None
    covariances: tuple[np.ndarray, np.ndarray] | None = None
    total_cpu_s: float | None = None
    """Process CPU time (all threads: reading, the backend's, the assessment's) of the same loop as ``total_time_s``."""

    def __repr__(self) -> str:
        """One line (the generated one printed every array: 57,000 characters for 20 frames)."""
        end = (self.metrics.get("final_error") or {}).get("translation_m")
        scored = f", end error {end:.4g} m" if isinstance(end, (int, float)) else ", not scored"
        where = f", written to {str(self.out_dir)!r}" if self.out_dir is not None else ""
        return f"OdometryResult({self.method!r}, {len(self.frames)} frames in {self.total_time_s:.3g} s{scored}{where})"

    @property
    def relative_covariance(self) -> np.ndarray | None:
        """``(n, 6, 6)`` covariance of each frame's relative motion (NaN where none; row 0 unused), or None."""
        return None if self.covariances is None else self.covariances[0]

    @property
    def pose_covariance(self) -> np.ndarray | None:
        """``(n, 6, 6)`` propagated covariance of each pose (see :mod:`lidarkit.odometry.covariance`), or None."""
        return None if self.covariances is None else self.covariances[1]

    @property
    def fps(self) -> float:
        """Frames per second of the whole loop (reading + registration)."""
        return len(self.frames) / self.total_time_s if self.total_time_s > 0 else float("inf")

    @property
    def n_not_converged(self) -> int:
        """Frames whose registration was measured and rejected (0 for stateful variants: not measured)."""
        return int((self.stats.measured & ~self.stats.converged).sum())

    @property
    def n_fallback(self) -> int:
        """Frames whose pose came from the constant-velocity motion because registration was rejected."""
        return int(self.stats.fallback.sum())

    @property
    def n_bad_frames(self) -> int:
        """Frames failing the independent per-frame check (every variant, stateful ones included)."""
        return 0 if self.stats.check_failed is None else int(self.stats.check_failed.sum())

    @property
    def convergence_measured(self) -> bool:
        """False for stateful variants (kiss): they report no per-frame convergence verdict."""
        return not self.config.get("run", {}).get("stateful", False)

    @property
    def degeneracy_assessed(self) -> bool:
        """False for stateful variants and for results registered with ``assess=False``: frames whose degeneracy is
        not known are not counted as "not degenerate" (the run read "0 degenerate")."""
        stats = self.stats
        return self.convergence_measured and (stats.assessed is None or bool(stats.assessed[stats.measured].all()))
