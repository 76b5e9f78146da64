"""A fake KITTI odometry root of short synthetic sequences (real KITTI layout, tiny scans) for suite-level tests.

The world is a ground plane plus random box-shaped buildings along a gently curving road; a scan holds the
world points within ``range_m`` of the sensor (no occlusion), so registration is easy, fast and deterministic.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def _world(rng: np.random.Generator, length_m: float) -> np.ndarray:
    parts = []
    gx, gy = np.meshgrid(np.arange(-20.0, length_m + 40.0, 1.5), np.arange(-25.0, 25.0, 1.5))
    ground = np.c_[gx.ravel(), gy.ravel(), np.zeros(gx.size)]
    ground[:, :2] += rng.uniform(-0.4, 0.4, (len(ground), 2))
    parts.append(ground)
    for x0 in np.arange(-10.0, length_m + 30.0, 7.0):
        for side in (-1.0, 1.0):
            w, d, h = rng.uniform(3, 6), rng.uniform(3, 6), rng.uniform(3, 10)
            cx, cy = x0 + rng.uniform(-1.5, 1.5), side * rng.uniform(9, 16)
            n = 220
            u = rng.uniform(-0.5, 0.5, (n, 3)) * [w, d, h]
            face = rng.integers(0, 4, n)
            u[face == 0, 0], u[face == 1, 0] = -w / 2, w / 2
            u[face == 2, 1], u[face == 3, 1] = -d / 2, d / 2
            parts.append(u + [cx, cy, h / 2])
    return np.concatenate(parts)


def write_fake_kitti_sequence(root: Path, seq: str, n_frames: int, *, step_m: float = 2.0, seed: int = 0,
                              range_m: float = 30.0) -> Path:
    """``root/sequences/<seq>/{velodyne,calib.txt,times.txt}`` and ``root/poses/<seq>.txt`` (Tr = identity)."""
    rng = np.random.default_rng(seed)
    world = _world(rng, n_frames * step_m)
    s = np.arange(n_frames) * step_m
    yaw = 0.15 * np.sin(s / 60.0 + seed)
    x = np.cumsum(np.r_[0.0, step_m * np.cos(yaw[:-1])])
    y = np.cumsum(np.r_[0.0, step_m * np.sin(yaw[:-1])])
    poses = np.tile(np.eye(4), (n_frames, 1, 1))
    c, sn = np.cos(yaw), np.sin(yaw)
    poses[:, 0, 0], poses[:, 0, 1], poses[:, 1, 0], poses[:, 1, 1] = c, -sn, sn, c
    poses[:, 0, 3], poses[:, 1, 3], poses[:, 2, 3] = x, y, 1.7
    seq_dir = root / "sequences" / seq
    (seq_dir / "velodyne").mkdir(parents=True, exist_ok=True)
    (root / "poses").mkdir(parents=True, exist_ok=True)
    for i, T in enumerate(poses):
        local = (world - T[:3, 3]) @ T[:3, :3]
        local = local[np.linalg.norm(local, axis=1) < range_m]
        local = local + rng.normal(0, 0.01, local.shape)
        data = np.c_[local, np.full(len(local), 0.5)].astype(np.float32)
        (seq_dir / "velodyne" / f"{i:06d}.bin").write_bytes(data.tobytes())
    ident = " ".join(f"{v:.6e}" for v in np.eye(4)[:3].ravel())
    p0 = " ".join(f"{v:.6e}" for v in np.array([[500.0, 0, 500, 0], [0, 500, 200, 0], [0, 0, 1, 0]]).ravel())
    (seq_dir / "calib.txt").write_text("".join(f"P{k}: {p0}\n" for k in range(4)) + f"Tr: {ident}\n")
    (seq_dir / "times.txt").write_text("".join(f"{0.1 * i:.6e}\n" for i in range(n_frames)))
    (root / "poses" / f"{seq}.txt").write_text(
        "".join(" ".join(f"{v:.9e}" for v in T[:3].ravel()) + "\n" for T in poses))
    return seq_dir


def write_fake_kitti_root(root: Path, sequences: dict[str, int], *, step_m: float = 2.0) -> Path:
    for k, (seq, n) in enumerate(sorted(sequences.items())):
        write_fake_kitti_sequence(root, seq, n, step_m=step_m, seed=k)
    return root
