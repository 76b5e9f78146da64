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
    rejected (not converged) and the frame's pose uses the previous relative motion (constant velocity).
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
    min_eigenvalue: np.ndarray | None = None

    def to_csv(self) -> str:
        buf = io.StringIO()
        writer = csv.writer(buf, lineterminator="\n")
        writer.writerow([
            "frame", "read_s", "register_s", "n_points", "converged", "iterations", "rmse_m", "n_correspondences", "degenerate",
            "constant_velocity_fallback", "min_eigenvalue", "reason",
        ])
        min_eig = self.min_eigenvalue if self.min_eigenvalue is not None else np.full(len(self.frame), np.nan)
        for k in range(len(self.frame)):
            measured = bool(self.measured[k])
            writer.writerow([
                int(self.frame[k]), f"{self.read_s[k]:.6f}", f"{self.register_s[k]:.6f}", int(self.n_points[k]),
                int(self.converged[k]) if measured else "n/a", int(self.iterations[k]) if measured else "n/a",
                f"{self.rmse_m[k]:.6g}" if measured else "n/a", int(self.n_correspondences[k]) if measured else "n/a",
                int(self.degenerate[k]) if measured else "n/a", int(self.fallback[k]),
                f"{min_eig[k]:.6g}" if np.isfinite(min_eig[k]) else "n/a", self.reason[k],
            ])
        return buf.getvalue()


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
    def convergence_measured(self) -> bool:
        """False for stateful variants (kiss): they report no per-frame convergence verdict."""
        return not self.config.get("run", {}).get("stateful", False)
