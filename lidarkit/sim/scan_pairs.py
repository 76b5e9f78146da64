"""Scan pairs with exact relative poses and controlled range noise, for calibrating registration covariances.

Three scenes: ``street`` and ``open`` are the LiDAR simulator's (static sweeps, no motion distortion, along its
path); ``corridor`` is a straight 4 m wide, 3.2 m high tunnel along x with featureless walls, so the translation
along x is unconstrained by geometry. The noise-free ranges of each frame are cast once; every draw adds fresh
Gaussian range noise along the rays (its own seed), so the only randomness between draws is the noise, the frame
and the initial guess.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from lidarkit.errors import ConfigError
from lidarkit.geometry import make_se3, se3_exp, se3_inverse
from lidarkit.params import is_integer

PAIR_SCENES = ("street", "open", "corridor")


@dataclass(frozen=True)
class ScanPair:
    """``target ~= T_target_source @ source``; ``init_T``: a perturbed guess of it."""

    source_xyz: np.ndarray
    target_xyz: np.ndarray
    T_target_source: np.ndarray
    init_T: np.ndarray
    frame: int


class ScanPairs:
    """Pairs ``(frame k+1 -> frame k)`` of one scene; :meth:`draw` adds noise and an initial-guess perturbation.

    The two sensor poses of a pair are about 1 m apart (the corridor's frames 1 m along x; the street and open scenes
    the simulator's drive at its default 10 m/s and 10 Hz); ``init_sigma``: std of the guess perturbation
    ``(translation m, rotation rad)``.
    """

    def __init__(self, scene: str = "street", seed: int = 0, n_frames: int = 40, range_noise_m: float = 0.02,
                 n_beams: int = 32, n_azimuths: int = 1024, init_sigma: tuple[float, float] = (0.05, 0.005)):
        if scene not in PAIR_SCENES:
            raise ConfigError(f"unknown pair scene {scene!r}; valid: {', '.join(PAIR_SCENES)}", source="scan pairs")
        from lidarkit.sim.lidar import SimulatedLidarSequence

        for name, value in (("n_frames", n_frames), ("seed", seed)):  # (n_frames=2.7 was truncated to 2 without a word)
            if not is_integer(value):
                raise ConfigError(f"{name} must be an integer, got {value!r}", source="scan pairs")
        self.scene, self.seed, self.n_frames = scene, int(seed), int(n_frames)
        self.range_noise_m, self.init_sigma = float(range_noise_m), tuple(float(s) for s in init_sigma)
        # checked here, not at the first draw (ZeroDivisionError or numpy's bare "scale < 0" came from draw)
        if self.n_frames < 2:
            raise ConfigError(f"n_frames must be at least 2 (a pair is two frames), got {self.n_frames}", source="scan pairs")
        if not np.isfinite(self.range_noise_m) or self.range_noise_m < 0:
            raise ConfigError(f"range_noise_m must be a finite std >= 0, got {self.range_noise_m:g}", source="scan pairs")
        if len(self.init_sigma) != 2 or not all(np.isfinite(s) and s >= 0 for s in self.init_sigma):
            raise ConfigError(f"init_sigma must be two finite stds >= 0 (translation m, rotation rad), got {init_sigma}",
                              source="scan pairs")
        sim_scene = "street" if scene == "corridor" else scene
        self._sim = SimulatedLidarSequence(
            scene=sim_scene, seed=self.seed, n_frames=self.n_frames, motion_distortion=False, range_noise_std_m=0.0,
            n_beams=n_beams, n_azimuths=n_azimuths, accel_time_s=0.0, point_times=False,
        )
        self._cache: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    @cached_property
    def poses(self) -> np.ndarray:
        """``(n_frames, 4, 4)`` world poses of the sensor."""
        if self.scene != "corridor":
            return self._sim.ground_truth_at(None).poses_se3
        rng = np.random.default_rng([self.seed, 7])
        x = np.arange(self.n_frames) * 1.0
        y = rng.uniform(-0.3, 0.3, self.n_frames)
        yaw = rng.uniform(-0.03, 0.03, self.n_frames)
        from lidarkit.geometry import so3_exp

        return np.stack([make_se3(so3_exp([0.0, 0.0, a]), [xi, yi, 0.0]) for xi, yi, a in zip(x, y, yaw)])

    @cached_property
    def _corridor_scene(self):
        import open3d as o3d

        # 100 m beyond the path's ends, past the 80 m the rays reach (a fixed 400 m tunnel ended at x = 300: frames past
        # it drew empty clouds)
        half_width, floor, ceiling = 2.0, -1.73, 1.5
        x0, x1 = -100.0, float(self.poses[:, 0, 3].max()) + 100.0
        quads = [  # floor, ceiling, left wall, right wall
            [(x0, -half_width, floor), (x1, -half_width, floor), (x1, half_width, floor), (x0, half_width, floor)],
            [(x0, -half_width, ceiling), (x1, -half_width, ceiling), (x1, half_width, ceiling), (x0, half_width, ceiling)],
            [(x0, half_width, floor), (x1, half_width, floor), (x1, half_width, ceiling), (x0, half_width, ceiling)],
            [(x0, -half_width, floor), (x1, -half_width, floor), (x1, -half_width, ceiling), (x0, -half_width, ceiling)],
        ]
        vertices = np.array([v for q in quads for v in q], dtype=np.float32)
        triangles = np.array([[4 * i, 4 * i + 1, 4 * i + 2] for i in range(4)] + [[4 * i, 4 * i + 2, 4 * i + 3] for i in range(4)],
                             dtype=np.uint32)
        scene = o3d.t.geometry.RaycastingScene()
        scene.add_triangles(o3d.core.Tensor(vertices), o3d.core.Tensor(triangles))
        return scene

    def _clean(self, frame: int) -> tuple[np.ndarray, np.ndarray]:
        """Noise-free points ``(N, 3)`` in the sensor frame and their unit ray directions."""
        if frame not in self._cache:
            if self.scene == "corridor":
                import open3d as o3d

                pose = self.poses[frame]
                dirs = self._sim.directions_sensor.reshape(-1, 3)
                rays = np.concatenate([np.broadcast_to(pose[:3, 3], dirs.shape), dirs @ pose[:3, :3].T], axis=1)
                t_hit = self._corridor_scene.cast_rays(o3d.core.Tensor(rays.astype(np.float32)))["t_hit"].numpy().astype(np.float64)
                keep = np.isfinite(t_hit) & (t_hit >= 1.0) & (t_hit <= 80.0)
                points, dirs = dirs[keep] * t_hit[keep, None], dirs[keep]
            else:
                points = self._sim.read_scan(frame).points_xyz
                dirs = points / np.linalg.norm(points, axis=1, keepdims=True)
            self._cache[frame] = (points, dirs)
        return self._cache[frame]

    def noisy(self, frame: int, rng: np.random.Generator) -> np.ndarray:
        points, dirs = self._clean(frame)
        return points + dirs * rng.normal(0.0, self.range_noise_m, size=(len(points), 1))

    def draw(self, index: int) -> ScanPair:
        """Pair number ``index``: frames ``(k + 1 -> k)`` with ``k = index % (n_frames - 1)``, fresh noise on both
        scans and a perturbed initial guess, all from ``(seed, index)``. Any integer ``index >= 0``: it seeds the draw
        (-1 raised numpy's bare ValueError, 2.7 was truncated and '1' read as 1)."""
        if not is_integer(index) or index < 0:
            raise ConfigError(f"index must be an integer >= 0, got {index!r}", source="scan pairs")
        k = int(index) % (self.n_frames - 1)
        rng = np.random.default_rng([self.seed, 11, int(index)])
        target, source = self.noisy(k, rng), self.noisy(k + 1, rng)
        T = se3_inverse(self.poses[k]) @ self.poses[k + 1]
        xi = np.concatenate([rng.normal(0, self.init_sigma[0], 3), rng.normal(0, self.init_sigma[1], 3)])
        return ScanPair(source, target, T, se3_exp(xi) @ T, k)


__all__ = ["PAIR_SCENES", "ScanPair", "ScanPairs"]
