"""Typed configuration of the monocular VO pipeline: one sub-model per stage, defaults in one place.

``VOConfig()`` is lidarkit's best pipeline (KLT tracking on a bucketed corner grid, E-RANSAC on
normalized coordinates, Sampson refinement); ``preset(name)`` gives the two reports' pipelines.
"""

from __future__ import annotations

from typing import Any, Literal, Optional, get_args

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from lidarkit.errors import ConfigError


class _Stage(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)

    def __init__(self, **data: Any) -> None:
        """Invalid values raise ConfigError naming the field, as every lidarkit config's do (``VOConfig(features=
        {"detector": "surf"})`` raised pydantic's ValidationError, where ``preset()`` gave a ConfigError)."""
        try:
            super().__init__(**data)
        except ValidationError as err:
            section = next((name for name, f in VOConfig.model_fields.items() if f.annotation is type(self)), "")
            raise _config_error(err, section) from None


class PreprocessConfig(_Stage):
    """Image filter applied before detection: none, CLAHE (contrast), Gaussian or bilateral blur."""

    method: Literal["none", "clahe", "gaussian", "bilateral"] = "none"
    clahe_clip_limit: float = Field(2.0, gt=0)
    clahe_tile_grid: int = Field(8, ge=1)
    blur_kernel_px: int = Field(5, ge=1)

    @field_validator("blur_kernel_px")
    @classmethod
    def _odd_kernel(cls, size: int) -> int:
        if size % 2 == 0:  # (an even size ran as the odd one above it, recorded as asked)
            raise ValueError("must be odd (the kernel is centred on each pixel)")
        return size


class FeatureConfig(_Stage):
    """Detector/descriptor, feature budget and grid bucketing (features spread over ``grid_rows x grid_cols`` cells).

    ``max_features`` is shared out, not capped: each cell keeps up to ``ceil(max_features / cells)``, so a frame can
    give up to ``cells x`` that (gftt on a KITTI frame: 32 for a budget of 8, 128 for 100, with the 4 x 8 grid);
    with one cell the detector's own limit applies (OpenCV's SIFT keeps a few more at equal responses)."""

    detector: Literal["gftt", "fast", "orb", "sift", "akaze"] = "gftt"
    max_features: int = Field(1200, ge=8, description="feature budget: up to ceil(max_features / cells) per grid cell, "
                              "so up to cells x that per frame")
    grid_rows: int = Field(4, ge=1)
    grid_cols: int = Field(8, ge=1)
    subpixel: bool = False
    gftt_quality: float = Field(0.01, gt=0, lt=1)
    min_distance_px: float = Field(7.0, ge=0)
    fast_threshold: int = Field(20, ge=1)
    akaze_threshold: float = Field(1e-3, gt=0)

    @model_validator(mode="after")
    def _subpixel_for_corners(self) -> FeatureConfig:
        if self.subpixel and self.detector in ("sift", "akaze"):
            raise ValueError(f"subpixel (cornerSubPix) refines corners (gftt, fast, orb); {self.detector} keypoints are "
                             "scale-space blobs already interpolated to sub-pixel: set subpixel to false")
        return self


class MatchConfig(_Stage):
    """Correspondences: KLT tracking (forward-backward checked) or descriptor matching (BF cross-check, KNN + ratio)."""

    method: Literal["klt", "bf_cross", "knn_ratio"] = "klt"
    ratio: float = Field(0.75, gt=0, le=1)
    klt_window_px: int = Field(15, ge=5)
    klt_levels: int = Field(3, ge=0)
    klt_fb_max_px: float = Field(0.5, gt=0)


class GeometryConfig(_Stage):
    """Two-view geometry: essential matrix (each estimator in ``estimators`` tried, the most inliers kept), recoverPose,
    optional Sampson-error refinement on the inliers and a fundamental-matrix fallback.

    ``normalize`` estimates E on K^-1-normalized points (K = identity, threshold / fx): with OpenCV 5 USAC_MAGSAC on
    pixel coordinates returns no solution on KITTI pairs, normalized coordinates work. ``inliers``: the
    correspondences kept for refinement and scale: ``cheirality`` (recoverPose's: in front of both cameras and
    nearer than 50 baselines; with the sanity checks on, at any distance when fewer than sanity.min_inliers are that
    near and those move: walking pace) or ``epipolar`` (all RANSAC inliers, far points included).
    """

    estimators: tuple[Literal["ransac", "magsac", "lmeds"], ...] = ("ransac",)
    threshold_px: float = Field(0.5, gt=0)
    confidence: float = Field(0.999, gt=0, lt=1)
    normalize: bool = True
    inliers: Literal["cheirality", "epipolar"] = "cheirality"
    refine: bool = True
    fundamental_fallback: bool = True
    # K-free degeneracy measure (pure rotation / standstill): homography and fundamental matrix fitted by RANSAC on
    # the pixel correspondences with this threshold; the homography is compared with a pure rotation K' R K'^-1 whose
    # focal length may differ from K's by up to ``rotation_focal_ratio`` (either way) - K may be a guess
    degeneracy_threshold_px: float = Field(1.0, gt=0)
    rotation_focal_ratio: float = Field(2.0, ge=1)

    @model_validator(mode="after")
    def _non_empty(self) -> GeometryConfig:
        if not self.estimators:
            raise ValueError("estimators must name at least one of ransac, magsac, lmeds")
        return self


class SanityConfig(_Stage):
    """Pose checks; every rejected frame records its reason. ``enabled=False`` drops the inlier minimum, the flip guard
    and the parallax tests; the finite/det checks, ``min_features`` and ``min_matches`` (a frame without them has
    nothing to estimate from) always apply, and ``min_inliers`` always starts the fundamental-matrix fallback."""

    enabled: bool = True
    min_features: int = Field(30, ge=5)
    min_matches: int = Field(30, ge=5)
    min_inliers: int = Field(30, ge=5)
    max_rotation_deg: float = Field(30.0, gt=0, le=180)
    min_parallax_px: float = Field(0.5, ge=0)
    # pure rotation / no parallax without trusting K: rejected when the homography explains at least this share of
    # the fundamental-matrix inliers AND is a pure rotation (self-calibrated focal) within max_rotation_homography_px
    max_homography_share: float = Field(0.9, ge=0.5, le=1)
    max_rotation_homography_px: float = Field(1.0, ge=0)


#: How the VO trajectory gets its scale (``ScaleConfig.mode``); also what the evaluation aligns by.
ScaleMode = Literal["gt", "none", "relative"]
SCALE_MODES = get_args(ScaleMode)


class ScaleConfig(_Stage):
    """Translation scale: ``gt`` (per-step norm of the ground truth), ``none`` (unit steps) or ``relative`` (one global
    unknown scale propagated through depths of points triangulated in consecutive pairs).

    ``relative``: points with a triangulation angle >= ``min_triangulation_angle_deg`` carry depth to the next
    pair (at most ``max_carried_points``); a step needs ``min_common_points`` of them. ``points``: which points carry
    depth: ``features`` (the pipeline's own correspondences) or ``corners`` (a dedicated bucketed corner set
    followed by KLT, used by every pipeline except KLT on corners, which is the same thing already: ORB keypoints
    cluster on few objects and descriptor re-matching keeps only a few depth points); a corner's depth is the
    running (log) mean over up to ``max_depth_views`` pairs (1 = last pair only), less noisy than one pair's, so
    corners need only ``corner_min_angle_deg`` (more, farther static points vote). A per-frame scale changing by
    more than the factor ``max_step_change`` from the previous step is not accepted: the previous scale is kept
    with a note (``VOResult.n_scale_kept`` counts those frames). ``corner_pose``: the pose the corners are
    triangulated with: ``pair`` (the pipeline's pose) or ``corners`` (the pair's pose estimated again on the
    tracked corners with the default geometry, E-RANSAC 0.5 px + Sampson refinement; the pair's pose when that
    fails). Only the scale path uses it; the trajectory keeps the pipeline's rotation and translation direction.
    ``report_orb`` sets ``corners``: its unrefined ORB + MAGSAC translation direction (~2 deg off) biases the corner
    depths and its scale drifted; poses that explain the corners about as well (SIFT, ORB + KLT) keep ``pair``."""

    mode: ScaleMode = "relative"
    min_triangulation_angle_deg: float = Field(1.0, gt=0)
    min_common_points: int = Field(15, ge=3)
    max_carried_points: int = Field(1500, ge=10)
    max_step_change: float = Field(3.0, gt=1)
    points: Literal["corners", "features"] = "corners"
    max_depth_views: int = Field(10, ge=1)
    corner_min_angle_deg: float = Field(0.5, gt=0)
    corner_pose: Literal["corners", "pair"] = "pair"


class SmoothingConfig(_Stage):
    """Savitzky-Golay smoothing of translations only (rotations untouched), applied as post-processing."""

    window: int = Field(9, ge=3)
    polyorder: int = Field(2, ge=1)

    @model_validator(mode="after")
    def _order_below_window(self) -> SmoothingConfig:
        if self.window % 2 == 0:  # (an even window ran as the odd one below it, recorded as asked)
            raise ValueError(f"window must be odd (the filter is centred on each pose), got {self.window}")
        if self.polyorder >= self.window - 1:  # a polynomial through every point of the window reproduces them
            raise ValueError(f"polyorder ({self.polyorder}) must be below window - 1 ({self.window - 1}): a polynomial of "
                             "that order passes through every pose of the window and smooths nothing")
        return self


class VOConfig(_Stage):
    """The whole pipeline; ``on_reject`` is the motion given to a rejected frame (``constant_velocity`` or ``identity``)."""

    preprocess: PreprocessConfig = PreprocessConfig()
    features: FeatureConfig = FeatureConfig()
    matching: MatchConfig = MatchConfig()
    geometry: GeometryConfig = GeometryConfig()
    sanity: SanityConfig = SanityConfig()
    scale: ScaleConfig = ScaleConfig()
    smoothing: SmoothingConfig = SmoothingConfig()
    on_reject: Literal["constant_velocity", "identity"] = "constant_velocity"
    # the order in which correspondences reach OpenCV's RANSAC/MAGSAC/LMedS (their own RNG ignores cv2.setRNGSeed):
    # None keeps the detection order (deterministic; what the two reports ran, so their figures are reproduced),
    # a seed shuffles it: same seed -> identical poses, another seed -> other (equally valid) samples
    seed: Optional[int] = Field(None, ge=0)

    @model_validator(mode="after")
    def _descriptor_for_matching(self) -> VOConfig:
        if self.matching.method != "klt" and self.features.detector in ("gftt", "fast"):
            raise ValueError(f"matching {self.matching.method!r} needs descriptors; detector {self.features.detector!r} has none "
                             "(use orb, sift or akaze, or matching 'klt')")
        return self

    def updated(self, **changes: Any) -> VOConfig:
        """Copy with dotted-path changes, e.g. ``cfg.updated(**{"features.detector": "orb", "scale.mode": "gt"})``."""
        data = self.model_dump()
        for key, value in changes.items():
            node = data
            *parents, leaf = key.split(".")
            for part in parents:
                if part not in node or not isinstance(node[part], dict):
                    raise ConfigError(f"unknown config section {part!r}", source=key)
                node = node[part]
            if leaf not in node:
                raise ConfigError(f"unknown config field {leaf!r}; known: {', '.join(sorted(node))}", source=key)
            node[leaf] = value
        return make_config(data)


def make_config(data: dict[str, Any] | None = None) -> VOConfig:
    """Validate a (nested) dict into a VOConfig; invalid values raise ConfigError naming the field (every stage's
    construction does, also for the dicts pydantic validates nested)."""
    return VOConfig.model_validate(data or {})


def _config_error(err: ValidationError, section: str = "") -> ConfigError:
    """The ConfigError of a config's first problem, its source ``vo config SECTION.FIELD``."""
    first = err.errors()[0]
    field = ".".join([*([section] if section else []), *(str(p) for p in first["loc"])])
    where = f"vo config {field}".strip()
    message = first["msg"].removeprefix("Value error, ")
    value = first.get("input")
    # (--set geometry.estimators=magsac said only "Input should be a valid tuple")
    hint = f"; give a list: [{value}]" if first["type"] == "tuple_type" and isinstance(value, str) else ""
    # a field's value is shown; a whole section's (a check across its fields) would repeat every setting
    return ConfigError((message if isinstance(value, dict) else f"{message} (got {value!r})") + hint, source=where)


_PRESETS: dict[str, dict[str, Any]] = {
    # lidarkit's best: KLT on a bucketed corner grid, E-RANSAC on normalized points + Sampson refinement
    "lidarkit": {},
    # report 1 (seed 000 part 3): SIFT (no budget: 100000 stands for all) + brute force with cross-check, E with
    # RANSAC, recoverPose, ground-truth scale
    "report_sift": {
        "features": {"detector": "sift", "max_features": 100000, "grid_rows": 1, "grid_cols": 1, "subpixel": False},
        "matching": {"method": "bf_cross"},
        "geometry": {"estimators": ("ransac",), "threshold_px": 1.0, "refine": False, "fundamental_fallback": False},
        "sanity": {"enabled": False},
        "scale": {"mode": "gt"},
    },
    # report 2 (seed 004): CLAHE + ORB 3000 + KNN ratio, USAC_MAGSAC (normalized), sanity checks (60 deg flip guard),
    # F fallback, unit steps
    "report_orb": {
        "preprocess": {"method": "clahe"},
        "features": {"detector": "orb", "max_features": 3000, "grid_rows": 1, "grid_cols": 1, "subpixel": False},
        "matching": {"method": "knn_ratio", "ratio": 0.75},
        "geometry": {"estimators": ("magsac",), "threshold_px": 1.0, "refine": False, "fundamental_fallback": True},
        "sanity": {"enabled": True, "max_rotation_deg": 60.0, "min_parallax_px": 0.0},
        # corner_pose: relative scale triangulates its corners with their own pose, not the unrefined MAGSAC one
        "scale": {"mode": "none", "corner_pose": "corners"},
    },
}


def available_presets() -> list[str]:
    """Names accepted by :func:`preset`."""
    return sorted(_PRESETS)


def preset(name: str, **changes: Any) -> VOConfig:
    """A named pipeline (``lidarkit``, ``report_sift``, ``report_orb``), optionally with dotted-path changes."""
    if name not in _PRESETS:
        raise ConfigError(f"unknown VO preset {name!r}; known: {', '.join(available_presets())}", source="preset")
    cfg = make_config(_PRESETS[name])
    return cfg.updated(**changes) if changes else cfg


#: Scale settings of the separate corner path, which KLT on corners (gftt + klt) does not build: its own tracks carry
#: the depth.
CORNER_PATH_SETTINGS = ("points", "max_depth_views", "corner_min_angle_deg", "corner_pose")


#: Sanity settings of the checks ``sanity.enabled`` switches off (the feature, match and inlier counts gate every pair).
SANITY_CHECK_SETTINGS = ("max_rotation_deg", "min_parallax_px", "max_homography_share", "max_rotation_homography_px")

#: Geometry settings that feed only the sanity stage's K-free pure-rotation check (the homography's share of the
#: fundamental-matrix inliers and its distance from a rotation): no pose, inlier set or fallback reads them.
SANITY_GEOMETRY_SETTINGS = ("degeneracy_threshold_px", "rotation_focal_ratio")

#: KLT settings: used by KLT matching and by the relative scale's corner path, which tracks its corners by KLT.
KLT_SETTINGS = ("klt_window_px", "klt_levels", "klt_fb_max_px")


#: Settings of one choice of a stage: ``setting -> (the choosing field, the choices that use the setting)``.
CHOICE_SETTINGS = {
    "preprocess.clahe_clip_limit": ("preprocess.method", ("clahe",)),
    "preprocess.clahe_tile_grid": ("preprocess.method", ("clahe",)),
    "preprocess.blur_kernel_px": ("preprocess.method", ("gaussian", "bilateral")),
    "features.gftt_quality": ("features.detector", ("gftt",)),
    "features.min_distance_px": ("features.detector", ("gftt",)),
    "features.fast_threshold": ("features.detector", ("fast",)),
    "features.akaze_threshold": ("features.detector", ("akaze",)),
    "matching.ratio": ("matching.method", ("knn_ratio",)),
}


def inert_settings(cfg: VOConfig, keys: Any) -> list[tuple[str, str]]:
    """``(setting, why)`` for the dotted settings among ``keys`` that ``cfg`` does not use (``--set
    scale.corner_pose=corners`` or ``--set matching.ratio=0.1`` left the default pipeline's poses byte-identical
    without a word, as did ``--no-sanity --set sanity.min_parallax_px=50`` or ``geometry.rotation_focal_ratio`` and
    ``matching.klt_levels`` with descriptor matching, ``scale.min_triangulation_angle_deg`` beside the corners' own
    angle and ``geometry.threshold_px`` with LMedS alone)."""
    own = cfg.matching.method == "klt" and cfg.features.detector == "gftt"
    corner_path = cfg.scale.mode == "relative" and cfg.scale.points == "corners" and not own
    # OpenCV's LMedS takes no threshold (it derives one from the median error): the setting then reaches only the
    # fundamental-matrix fallback and the corners' epipolar filter
    lmeds_only = set(cfg.geometry.estimators) == {"lmeds"}
    notes = []
    for key in keys:
        if str(key) in CHOICE_SETTINGS:
            chooser, users = CHOICE_SETTINGS[str(key)]
            stage, _, field = chooser.partition(".")
            chosen = getattr(getattr(cfg, stage), field)
            if chosen not in users:
                notes.append((str(key), f"{chooser} is {chosen}: the setting acts with {' or '.join(users)}"))
            continue
        section, _, field = str(key).partition(".")
        if section == "sanity" and field in SANITY_CHECK_SETTINGS and not cfg.sanity.enabled:
            notes.append((str(key), "sanity.enabled is false: the pose checks are off"))
        elif section == "geometry" and field in SANITY_GEOMETRY_SETTINGS and not cfg.sanity.enabled:
            notes.append((str(key), "sanity.enabled is false: the setting feeds only its pure-rotation check"))
        elif str(key) == "geometry.threshold_px" and lmeds_only and not cfg.geometry.fundamental_fallback and not corner_path:
            notes.append((str(key), "geometry.estimators is lmeds (it sets its own threshold from the median error), "
                                    "geometry.fundamental_fallback is false and the relative scale tracks no corners"))
        elif section == "matching" and field in KLT_SETTINGS and cfg.matching.method != "klt" and not corner_path:
            notes.append((str(key), f"matching.method is {cfg.matching.method}: the setting acts with klt or with the "
                                    "relative scale's corners (scale.points corners)"))
        if section != "scale" or field == "mode":
            continue
        if cfg.scale.mode != "relative":
            notes.append((str(key), f"scale mode {cfg.scale.mode}: the scale settings act with relative"))
        elif field in CORNER_PATH_SETTINGS and own:
            notes.append((str(key), "KLT on corners carries depth with its own tracks: no separate corner path"))
        elif field in CORNER_PATH_SETTINGS and field != "points" and not corner_path:
            notes.append((str(key), "scale.points is features: the pipeline's correspondences carry depth, no corners"))
        elif field == "min_triangulation_angle_deg" and corner_path:
            notes.append((str(key), "scale.points is corners: the corners use scale.corner_min_angle_deg"))
        elif field == "max_carried_points" and cfg.matching.method != "klt" and not corner_path:
            notes.append((str(key), f"matching.method is {cfg.matching.method}: descriptor matches keep every depth; the "
                                    "limit acts on KLT tracks and on the relative scale's corners"))
    return notes
