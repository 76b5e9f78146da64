"""Camera intrinsics: building K, and a guess from the image size when no calibration is given."""

from __future__ import annotations

import numpy as np

from lidarkit.errors import DataError

#: focal length guess as a fraction of the larger image side: fx = fy = 0.9 * max(w, h), i.e. a horizontal field of
#: view of about 58 degrees for landscape images (typical of webcams and phones; KITTI's is 81 deg: factor 0.58)
DEFAULT_FOCAL_FACTOR = 0.9


def K_matrix(fx: float, fy: float, cx: float, cy: float) -> np.ndarray:
    """``(3, 3)`` pinhole intrinsics."""
    values = np.array([fx, fy, cx, cy], dtype=np.float64)
    if not np.all(np.isfinite(values)) or fx <= 0 or fy <= 0:
        raise DataError(f"invalid intrinsics fx={fx}, fy={fy}, cx={cx}, cy={cy}", source="intrinsics")
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


def K_from_image_size(width: int, height: int, focal_factor: float = DEFAULT_FOCAL_FACTOR) -> np.ndarray:
    """Intrinsics guess for an uncalibrated camera: square pixels, principal point at the image centre,
    ``fx = fy = focal_factor * max(width, height)``."""
    if width <= 0 or height <= 0:
        raise DataError(f"invalid image size {width}x{height}", source="intrinsics")
    f = focal_factor * max(width, height)
    return K_matrix(f, f, (width - 1) / 2.0, (height - 1) / 2.0)


def validate_K(K: np.ndarray, source: str = "intrinsics") -> np.ndarray:
    """Check a ``(3, 3)`` upper-triangular intrinsics matrix with positive focal lengths; returns float64 copy."""
    K = np.asarray(K, dtype=np.float64)
    if K.shape != (3, 3):
        raise DataError(f"K must be a 3x3 matrix, got shape {K.shape}", source=source)
    if not np.all(np.isfinite(K)):
        raise DataError(f"K must be finite, got {int((~np.isfinite(K)).sum())} NaN or infinite entries", source=source)
    if K[0, 0] <= 0 or K[1, 1] <= 0 or not np.allclose(K[2], [0, 0, 1]) or K[1, 0] != 0 or K[2, 0] != 0:
        raise DataError("K must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0", source=source)
    return K.copy()
