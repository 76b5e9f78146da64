"""2D scans (all points at z = 0) and the SE(2) constraint (solve x, y, yaw only).

A planar laser scan gives a well-posed point-to-point problem in 3D as well (a tilt moves the points out of the
plane, which costs), so point-to-point variants accept 2D scans as they are. Residuals built from local surfaces
(point-to-plane, GICP covariances, plane normals) are undefined on a 2D scan: its neighbourhoods are lines, and
the "normal" of a line in 3D is any vector perpendicular to it. Such variants call :func:`refuse_2d`.
"""

from __future__ import annotations

import numpy as np

from lidarkit.errors import ConfigError

#: A cloud is a 2D scan when the spread of its z coordinates is at most this (m).
PLANAR_Z_TOL_M = 1e-9


def is_2d_scan(points_xyz: np.ndarray, tol_m: float = PLANAR_Z_TOL_M) -> bool:
    """True when every point of the ``(N, 3)`` cloud lies in one horizontal plane (a 2D laser scan)."""
    z = np.asarray(points_xyz)[:, 2]
    return bool(len(z) > 0 and float(z.max() - z.min()) <= tol_m)


def refuse_2d(method: str, source_xyz: np.ndarray, target_xyz: np.ndarray, why: str) -> None:
    """Raise ConfigError when either cloud is a 2D scan: ``method`` cannot give a meaningful 3D result on it."""
    for name, pts in (("source", source_xyz), ("target", target_xyz)):
        if is_2d_scan(pts):
            raise ConfigError(
                f"not applicable to 2D scans ({name} cloud has all points at one z): {why}; "
                "use a point-to-point variant (vanilla or knn, with planar=True for x, y and yaw only; open3d_point_to_point; "
                "small_gicp with registration_type=ICP; kiss)",
                source=f"method {method!r}",
            )


def planar_kabsch(source_xyz: np.ndarray, target_xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares rotation about z and translation in x, y taking ``source`` onto ``target`` (paired rows).

    Returns a ``(3, 3)`` rotation and a ``(3,)`` translation with zero z, i.e. an SE(2) motion embedded in SE(3).
    The z coordinates are ignored: under this motion their residual is constant, so the 2D fit is the
    constrained optimum of the 3D point-to-point cost.
    """
    a = np.asarray(source_xyz, dtype=np.float64)[:, :2]
    b = np.asarray(target_xyz, dtype=np.float64)[:, :2]
    mu_a, mu_b = a.mean(axis=0), b.mean(axis=0)
    ac, bc = a - mu_a, b - mu_b
    # cross terms of sum(bc_i . R ac_i): maximised by yaw = atan2(sum a x b, sum a . b)
    dot = float(np.einsum("ij,ij->", ac, bc))
    cross = float((ac[:, 0] * bc[:, 1] - ac[:, 1] * bc[:, 0]).sum())
    yaw = np.arctan2(cross, dot)
    c, s = np.cos(yaw), np.sin(yaw)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    t2 = mu_b - R[:2, :2] @ mu_a
    return R, np.array([t2[0], t2[1], 0.0])


def se2_of(T: np.ndarray) -> tuple[float, float, float]:
    """``(x, y, yaw)`` of a pose (yaw from the rotation's first column projected on the xy plane)."""
    T = np.asarray(T, dtype=np.float64)
    return float(T[0, 3]), float(T[1, 3]), float(np.arctan2(T[1, 0], T[0, 0]))


__all__ = ["PLANAR_Z_TOL_M", "is_2d_scan", "planar_kabsch", "refuse_2d", "se2_of"]
