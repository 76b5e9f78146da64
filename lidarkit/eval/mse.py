"""Position mean squared error, the particle-filter report's score (``MSE from the 10th frame``)."""

from __future__ import annotations

import numpy as np

from lidarkit.errors import ConfigError, EvaluationError
from lidarkit.eval.ape_rpe import check_flags
from lidarkit.eval.pairing import pair_name, paired
from lidarkit.params import is_real_number
from lidarkit.trajectory import Trajectory


def position_mse(
    ref: Trajectory, est: Trajectory, start: int = 0, *, dims: int = 3, associate: bool = False, max_diff_s: float = 0.01
) -> float:
    """Mean over frames ``i >= start`` of the squared position error ``|p_est_i - p_ref_i|^2`` (m^2).

    No alignment. ``dims=3`` uses x, y, z; ``dims=2`` only x, y (planar filters; identical to 3 when z is 0).
    Trajectories must have equal length unless ``associate`` (timestamps, within ``max_diff_s``, as :func:`ape`);
    ``start`` skips the filter's convergence phase (counted in paired poses).
    """
    source = pair_name(ref, est)
    check_flags(associate=associate)
    if isinstance(dims, bool) or dims not in (2, 3):
        raise ConfigError(f"dims must be 2 or 3, got {dims!r}", source="dims")
    if not is_real_number(start):  # ("5": "got 5")
        raise ConfigError(f"start must be a frame index, got {start!r}", source="start")
    ref, est = paired(ref, est, associate=associate, max_diff_s=max_diff_s)
    if int(start) == start and start >= len(ref) >= 0 and start >= 0:
        raise EvaluationError(f"needs more than {int(start)} steps for the MSE from step {int(start)}; has {len(ref)}",
                              source=source)
    if int(start) != start or not 0 <= start < len(ref):
        raise EvaluationError(f"start must be a frame index in [0, {len(ref) - 1}], got {start}", source=source)
    diff = est.poses_se3[int(start):, :dims, 3] - ref.poses_se3[int(start):, :dims, 3]
    return float(np.mean(np.sum(diff * diff, axis=1)))
