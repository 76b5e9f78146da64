"""Residuals (correspondence metrics) and their Gauss-Newton normal equations on SE(3).

The increment ``dx = (upsilon, omega)`` perturbs the current source points ``p`` as ``exp(dx) p ~ p + upsilon +
omega x p``; each residual returns ``J^T W J`` (6x6) and ``J^T W r`` (6,) summed over the correspondences, with
the kernel's IRLS weights ``W`` evaluated on the squared residuals:

* ``point_to_point``: ``r = p - q`` (3 rows), ``J = [I, -[p]x]`` (kiss-icp's residual);
* ``point_to_plane``: ``r = n . (p - q)`` with the map normal ``n``, ``J = [n, p x n]``;
* ``plane_to_plane``: ``r = p - q`` weighed by ``(C_q + R C_p R^T + eps I)^-1`` with plane-regularised covariances
  of the map point and of the source point (Generalized-ICP).
"""

from __future__ import annotations

import numpy as np
from pydantic import Field

from lidarkit.registration.components.kernels import checked_weights
from lidarkit.registration.components.registry import Component, ComponentConfig, component_base, register_component


def _point_jacobians(p: np.ndarray) -> np.ndarray:
    """``(N, 3, 6)`` Jacobians ``[I, -[p]x]`` of ``exp(dx) p`` at ``dx = 0``."""
    J = np.zeros((len(p), 3, 6))
    J[:, 0, 0] = J[:, 1, 1] = J[:, 2, 2] = 1.0
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    # -[p]x = [[0, z, -y], [-z, 0, x], [y, -x, 0]]
    J[:, 0, 4], J[:, 0, 5] = z, -y
    J[:, 1, 3], J[:, 1, 5] = -z, x
    J[:, 2, 3], J[:, 2, 4] = y, -x
    return J


def plane_regularized(cov: np.ndarray, epsilon: float) -> np.ndarray:
    """Covariances ``(N, 3, 3)`` with eigenvalues replaced by ``(epsilon, 1, 1)`` (a plane's shape, GICP)."""
    _, vecs = np.linalg.eigh(cov)
    scale = np.array([epsilon, 1.0, 1.0])
    return np.einsum("nik,k,njk->nij", vecs, scale, vecs)


@component_base("residual")
class Residual(Component):
    """Builds the weighted normal equations for matched ``source`` (world frame) and map points."""

    needs_normals = False
    needs_covariances = False

    def normal_equations(
        self, source_xyz, target_xyz, map_index, local_map, source_cov, kernel, sigma_m
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(JTJ (6, 6), JTr (6,), squared residuals (N,))``."""
        raise NotImplementedError


class PointToPointConfig(ComponentConfig):
    pass


@register_component("residual", "point_to_point")
class PointToPoint(Residual):
    """Euclidean distance to the nearest map point."""

    Config = PointToPointConfig

    def normal_equations(self, source_xyz, target_xyz, map_index, local_map, source_cov, kernel, sigma_m):
        # closed form of sum_n w_n J_n^T J_n with J = [I, -[p]x]: [[W I, -[s]x], [[s]x, tr(S) I - S]],
        # s = sum w p, S = sum w p p^T; and J^T r = [r, p x r] (no (N, 3, 6) Jacobians needed)
        p = source_xyz
        r = p - target_xyz
        r2 = np.einsum("ni,ni->n", r, r)
        w = checked_weights(kernel, r2, sigma_m)
        s = w @ p
        S = np.einsum("n,ni,nj->ij", w, p, p)
        hat = np.array([[0.0, -s[2], s[1]], [s[2], 0.0, -s[0]], [-s[1], s[0], 0.0]])
        JTJ = np.empty((6, 6))
        JTJ[:3, :3] = w.sum() * np.eye(3)
        JTJ[:3, 3:] = -hat
        JTJ[3:, :3] = hat
        JTJ[3:, 3:] = np.trace(S) * np.eye(3) - S
        JTr = np.concatenate([w @ r, w @ np.cross(p, r)])
        return JTJ, JTr, r2


class PointToPlaneConfig(ComponentConfig):
    pass


@register_component("residual", "point_to_plane")
class PointToPlane(Residual):
    """Distance along the map point's normal (PCA of its map neighbours)."""

    Config = PointToPlaneConfig
    needs_normals = True

    def normal_equations(self, source_xyz, target_xyz, map_index, local_map, source_cov, kernel, sigma_m):
        n = local_map.normals(map_index)
        r = np.einsum("ni,ni->n", n, source_xyz - target_xyz)
        r2 = r * r
        w = checked_weights(kernel, r2, sigma_m)
        J = np.concatenate([n, np.cross(source_xyz, n)], axis=1)
        Jw = J * w[:, None]
        return Jw.T @ J, Jw.T @ r, r2


class PlaneToPlaneConfig(ComponentConfig):
    epsilon: float = Field(1e-3, gt=0, le=1, description="smallest eigenvalue of the plane-regularised covariances")


@register_component("residual", "plane_to_plane")
class PlaneToPlane(Residual):
    """Generalized-ICP: Mahalanobis distance under the summed source and map surface covariances.

    The covariances are plane-regularised to unit-free eigenvalues (epsilon, 1, 1), so the residual is not in metres (a
    normal offset d reads ~d / sqrt(2 epsilon)): a kernel's scale and the ICP's RMSE history are in those units."""

    Config = PlaneToPlaneConfig
    needs_covariances = True

    def normal_equations(self, source_xyz, target_xyz, map_index, local_map, source_cov, kernel, sigma_m):
        eps = self.config.epsilon
        C = plane_regularized(local_map.covariances(map_index), eps) + source_cov + 1e-9 * np.eye(3)
        M = np.linalg.inv(C)
        r = source_xyz - target_xyz
        Mr = np.einsum("nij,nj->ni", M, r)
        r2 = np.einsum("ni,ni->n", r, Mr)
        w = checked_weights(kernel, r2, sigma_m)
        J = _point_jacobians(source_xyz)
        MJ = np.einsum("nij,njk->nik", M, J) * w[:, None, None]
        return np.einsum("nki,nkj->ij", J, MJ), np.einsum("nki,nk->i", J, Mr * w[:, None]), r2


__all__ = ["PlaneToPlane", "PointToPlane", "PointToPoint", "Residual", "plane_regularized"]
