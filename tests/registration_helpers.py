"""Shared helpers for the registration tests: structured synthetic clouds and KITTI pairs."""

from __future__ import annotations

import numpy as np

from lidarkit.geometry import se3_inverse


def structured_cloud(rng: np.random.Generator, n: int = 6000, noise_m: float = 0.0) -> np.ndarray:
    """A street-like ``(n, 3)`` cloud: ground, two walls at different angles, a pole, boxes (all 6 DoF constrained)."""
    parts = []
    k = n // 6
    # ground z = -1.7 over 40 x 20 m
    parts.append(np.c_[rng.uniform(-20, 20, k), rng.uniform(-10, 10, k), np.full(k, -1.7)])
    # wall y = 8 and a slanted wall
    parts.append(np.c_[rng.uniform(-20, 20, k), np.full(k, 8.0), rng.uniform(-1.7, 4, k)])
    s = rng.uniform(0, 15, k)
    parts.append(np.c_[-5 + 0.8 * s, -9 + 0.3 * s, rng.uniform(-1.7, 3, k)])
    # a cylinder pole at (6, -3)
    th, z = rng.uniform(0, 2 * np.pi, k), rng.uniform(-1.7, 5, k)
    parts.append(np.c_[6 + 0.3 * np.cos(th), -3 + 0.3 * np.sin(th), z])
    # two boxes (faces) of different sizes
    for center, size in (((-8.0, 2.0, -0.7), (2.0, 1.5, 2.0)), ((12.0, 4.0, -1.2), (1.0, 3.0, 1.0))):
        face = rng.integers(0, 6, k // 2)
        u = rng.uniform(-0.5, 0.5, (k // 2, 3)) * size
        axis, sign = face // 2, np.where(face % 2, 1.0, -1.0)
        u[np.arange(len(u)), axis] = sign * 0.5 * np.asarray(size)[axis]
        parts.append(u + center)
    pts = np.vstack(parts)
    if noise_m:
        pts = pts + rng.normal(scale=noise_m, size=pts.shape)
    return pts


def read_kitti_bin(path) -> np.ndarray:
    """``(N, 3)`` float64 xyz of a KITTI Velodyne .bin."""
    return np.fromfile(path, dtype=np.float32).reshape(-1, 4)[:, :3].astype(np.float64)


def kitti_pair(shared_path, frame_target: int, frame_source: int):
    """(source_xyz, target_xyz, T_target_source ground truth) of two seq-00 scans, via lidarkit's KITTI reader."""
    from lidarkit.io.kitti import KittiOdometry

    seq = KittiOdometry(
        shared_path("kitti_odometry"),
        sequence="00",
        velodyne_dir=shared_path("kitti_odometry", "extra_frames", "00", "velodyne"),
    )
    src = seq.read_scan_by_frame(frame_source).points_xyz
    dst = seq.read_scan_by_frame(frame_target).points_xyz
    return src, dst, seq.relative_pose(frame_target, frame_source)


def kitti_pair_manual(shared_path, frame_target: int, frame_source: int):
    """Same as :func:`kitti_pair` with calib/poses parsed here (cross-check of the reader's convention)."""
    calib = {}
    for line in shared_path("kitti_odometry", "sequences", "00", "calib.txt").read_text().splitlines():
        if ":" in line:
            key, vals = line.split(":", 1)
            calib[key] = np.array(vals.split(), dtype=float)
    Tr = np.eye(4)
    Tr[:3, :4] = calib["Tr"].reshape(3, 4)
    P = np.loadtxt(shared_path("kitti_odometry", "poses", "00.txt")).reshape(-1, 3, 4)

    def T_world_lidar(i):
        T = np.eye(4)
        T[:3, :4] = P[i]
        return se3_inverse(Tr) @ T @ Tr

    return se3_inverse(T_world_lidar(frame_target)) @ T_world_lidar(frame_source)
