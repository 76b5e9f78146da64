"""Camera intrinsics: building K, and a guess from the image size when no calibration is given."""

from __future__ import annotations

import numpy as np

from lidarkit.errors import DataError

#: focal length guess as a fraction of the larger image side: fx = fy = 0.9 * max(w, h), i.e. a horizontal field of
#: view of about 58 degrees for landscape images (typical of webcams and phones; KITTI's is 81 deg: factor 0.58)
DEFAULT_FOCAL_FACTOR = 0.9


def _as_numbers(*values: object) -> np.ndarray | None:
    """The values as float64, or None when one is no number (a str failed in a comparison or was read digit-wise)."""
    if any(isinstance(v, (str, bytes)) for v in values):
        return None
    try:
        numbers = np.array(values, dtype=np.float64)
    except (TypeError, ValueError):
        return None
    return numbers if numbers.shape == (len(values),) else None


def _shown(value: object) -> str:
    return repr(value) if isinstance(value, (str, bytes)) else str(value)


def K_matrix(fx: float, fy: float, cx: float, cy: float) -> np.ndarray:
    """``(3, 3)`` pinhole intrinsics."""
    values = _as_numbers(fx, fy, cx, cy)
    if values is None or not np.all(np.isfinite(values)) or values[0] <= 0 or values[1] <= 0:
        raise DataError(f"invalid intrinsics fx={_shown(fx)}, fy={_shown(fy)}, cx={_shown(cx)}, cy={_shown(cy)}",
                        source="intrinsics")
    fx, fy, cx, cy = values
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


def K_from_image_size(width: int, height: int, focal_factor: float = DEFAULT_FOCAL_FACTOR) -> np.ndarray:
    """Intrinsics guess for an uncalibrated camera: square pixels, principal point at the image centre,
    ``fx = fy = focal_factor * max(width, height)``."""
    size = _as_numbers(width, height)
    if size is None or not np.all(np.isfinite(size)) or size.min() <= 0:
        raise DataError(f"invalid image size width={_shown(width)}, height={_shown(height)}", source="intrinsics")
    factor = _as_numbers(focal_factor)
    if factor is None or not np.isfinite(factor[0]) or factor[0] <= 0:  # (a str was repeated max(w, h) times)
        raise DataError(f"invalid focal factor {_shown(focal_factor)}: must be a finite number > 0",
                        source="intrinsics")
    width, height = size
    f = factor[0] * max(width, height)
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
