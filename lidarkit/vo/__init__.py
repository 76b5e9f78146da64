"""Monocular visual odometry: configurable stages (preprocess, features, matching/KLT, two-view geometry, sanity,
scale), the :class:`MonoVO` pipeline and post-processing (Savitzky-Golay smoothing).

>>> from lidarkit.vo import MonoVO, preset
>>> result = MonoVO(preset("lidarkit"), K, ground_truth=gt).run(images)   # doctest: +SKIP
"""

from lidarkit.vo.config import (
    FeatureConfig,
    GeometryConfig,
    MatchConfig,
    PreprocessConfig,
    SanityConfig,
    ScaleConfig,
    SmoothingConfig,
    VOConfig,
    available_presets,
    make_config,
    preset,
)
from lidarkit.vo.evaluation import evaluate_vo
from lidarkit.vo.features import get_detector, get_preprocessor
from lidarkit.vo.intrinsics import K_from_image_size, K_matrix
from lidarkit.vo.matching import get_matcher, track_klt
from lidarkit.vo.pipeline import FrameDiagnostics, MonoVO, VOResult, images_in_memory, run_vo
from lidarkit.vo.sanity import check_pose
from lidarkit.vo.smoothing import smooth_translations
from lidarkit.vo.two_view import TwoViewEstimate, estimate_two_view

__all__ = [
    "FeatureConfig", "FrameDiagnostics", "GeometryConfig", "K_from_image_size", "K_matrix", "MatchConfig", "MonoVO",
    "PreprocessConfig", "SanityConfig", "ScaleConfig", "SmoothingConfig", "TwoViewEstimate", "VOConfig", "VOResult",
    "available_presets", "check_pose", "estimate_two_view", "evaluate_vo", "get_detector", "get_matcher", "get_preprocessor",
    "images_in_memory", "make_config", "preset", "run_vo", "smooth_translations", "track_klt",
]
