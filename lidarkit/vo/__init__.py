"""Monocular visual odometry: configurable stages (preprocess, features, matching/KLT, two-view geometry, sanity,
scale), the :class:`MonoVO` pipeline and post-processing (Savitzky-Golay smoothing).

>>> from lidarkit.vo import MonoVO, preset
>>> result = MonoVO(preset("lidarkit"), K, ground_truth=gt).run(images)   # doctest: +SKIP

The names below are loaded on first use (module ``__getattr__``): ``lidarkit.vo.config``, which every CLI start reads
for the ``vo`` command's help, imports no OpenCV nor scipy.signal (every command crashed at import under a tight
``ulimit -v``, and a start took twice as long).
"""

from __future__ import annotations

import importlib
import importlib.util
from typing import TYPE_CHECKING, Any

#: public name -> the submodule that defines it
_HOME = {
    **dict.fromkeys(("FeatureConfig", "GeometryConfig", "MatchConfig", "PreprocessConfig", "SanityConfig",
                     "ScaleConfig", "SmoothingConfig", "VOConfig", "available_presets", "make_config", "preset"), "config"),
    "evaluate_vo": "evaluation",
    **dict.fromkeys(("get_detector", "get_preprocessor"), "features"),
    **dict.fromkeys(("K_from_image_size", "K_matrix"), "intrinsics"),
    **dict.fromkeys(("get_matcher", "track_klt"), "matching"),
    **dict.fromkeys(("FrameDiagnostics", "MonoVO", "VOResult", "images_in_memory", "run_vo"), "pipeline"),
    "check_pose": "sanity",
    "smooth_translations": "smoothing",
    **dict.fromkeys(("TwoViewEstimate", "estimate_two_view"), "two_view"),
}

__all__ = sorted(_HOME)


def __getattr__(name: str) -> Any:
    """A public name from its submodule, imported now (OpenCV with the first name that needs it), or a submodule."""
    home = _HOME.get(name)
    if home is None:
        if not name.startswith("_") and importlib.util.find_spec(f"{__name__}.{name}") is not None:
            return importlib.import_module(f"{__name__}.{name}")  # (a submodule, as ``lidarkit.vo.pipeline`` was)
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{home}"), name)
    globals()[name] = value  # (looked up once)
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_HOME})


if TYPE_CHECKING:  # (for type checkers and editors: the same names, imported eagerly)
    from lidarkit.vo.config import (
        FeatureConfig, GeometryConfig, MatchConfig, PreprocessConfig, SanityConfig, ScaleConfig, SmoothingConfig,
        VOConfig, available_presets, make_config, preset,
    )
    from lidarkit.vo.evaluation import evaluate_vo
    from lidarkit.vo.features import get_detector, get_preprocessor
    from lidarkit.vo.intrinsics import K_from_image_size, K_matrix
    from lidarkit.vo.matching import get_matcher, track_klt
    from lidarkit.vo.pipeline import FrameDiagnostics, MonoVO, VOResult, images_in_memory, run_vo
    from lidarkit.vo.sanity import check_pose
    from lidarkit.vo.smoothing import smooth_translations
    from lidarkit.vo.two_view import TwoViewEstimate, estimate_two_view
