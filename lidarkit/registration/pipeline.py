"""``pipeline``: an odometry / registration pipeline composed of components (see :mod:`.components`).

One frame goes through the stages kiss-icp 1.3 runs, each stage a component chosen by name:

1. ``deskew`` (a *motion* component): correct the sweep's motion distortion with the last relative motion;
2. ``preprocess``: the listed steps in order (range crop, ground filter, ...);
3. voxelization: the map points are the sweep downsampled at ``map_voxel_factor * voxel`` (one point per voxel,
   kiss-icp's rule), the registered points that cloud downsampled again at ``source_voxel_factor * voxel``;
4. ICP against the ``map`` from the motion model's prediction: ``residual`` correspondences within the
   ``threshold``'s distance, Gauss-Newton steps on SE(3) weighted by the ``kernel``, until ``|dx| <
   convergence_criterion`` or ``max_iterations``;
5. update: the threshold sees the model deviation ``inv(prediction) @ estimate``, the map adds the map points.

Presets name compositions: ``kiss_like`` (kiss-icp's published choices and defaults) and ``vanilla_seq`` (the
report's vanilla ICP, point-to-point on every nearest neighbour without kernel, chained scan to scan with a
constant-velocity guess). Explicit parameters override the preset's. What decides how a run reads its data (on KITTI,
kiss's vertical-angle correction) is the composition as resolved, not the preset's name (:func:`is_kiss_composition`).

>>> icp = get_icp("pipeline", preset="kiss_like", kernel="none")      # kiss without its robust kernel
>>> icp = get_icp("pipeline", residual="point_to_plane", kernel={"name": "huber", "scale_m": 0.2})
"""

from __future__ import annotations

import copy
import inspect
from typing import Any, Literal

import numpy as np
from pydantic import Field, model_validator
from scipy.spatial import cKDTree

from lidarkit.errors import ConfigError, RegistrationError
from lidarkit.geometry import as_points, orthonormalize_se3, se3_fraction, se3_inverse, transform_points
from lidarkit.params import changed_fields
from lidarkit.registration import local_origin
from lidarkit.registration.assessment import assess_alignment
from lidarkit.registration.base import (
    Degeneracy, Registration, RegistrationConfig, RegistrationResult, as_point_times, check_init_T, check_point_times,
    check_sweeps_apart, use_backend,
)
from lidarkit.registration.components import make_component
from lidarkit.registration.components.registry import get_component_class, output_error, split_spec
from lidarkit.registration.planar import refuse_2d
from lidarkit.registration.components.maps import first_per_voxel, pca_geometry
from lidarkit.registration.components.motion import se3_exp_batch
from lidarkit.registration.components.residuals import plane_regularized
from lidarkit.registration.registry import register_icp

#: Inlier distance for fitness when the threshold is unlimited (m).
UNLIMITED_INLIER_DISTANCE_M = 1.0

#: Fewest correspondences a Gauss-Newton step is taken from (6 unknowns); fewer end the ICP, not converged.
MIN_ICP_CORRESPONDENCES = 6

#: Named compositions; a preset's values are defaults that explicit parameters override.
PRESETS: dict[str, dict[str, Any]] = {
    "kiss_like": {
        "residual": "point_to_point",
        "kernel": {"name": "geman_mcclure", "scale_m": "kiss"},
        "threshold": "adaptive",
        "deskew": {"name": "constant_velocity", "deskew": True, "reference": "end"},
        "map": "voxel_hash",
        "preprocess": ["range_crop"],
    },
    "vanilla_seq": {
        "residual": "point_to_point",
        "kernel": "none",
        "threshold": {"name": "fixed", "max_distance_m": None},
        "deskew": {"name": "constant_velocity", "deskew": False},
        "map": "scan_to_scan",
        "preprocess": [],
        "map_voxel_factor": None,
        "source_voxel_factor": None,
    },
}

Spec = str | dict[str, Any]

#: The pipeline's shared settings each kind of component is handed (a component takes those its config has).
SHARED_SETTINGS: dict[str, tuple[str, ...]] = {
    "threshold": ("max_range_m",),
    "map": ("max_range_m", "min_range_m", "voxel_size_m"),
    "preprocess": ("max_range_m", "min_range_m"),
}


class PipelineConfig(RegistrationConfig):
    """The composition (component names or ``{"name": ..., **params}``) and the shared settings."""

    preset: Literal["kiss_like", "vanilla_seq"] | None = Field(None, description="named composition whose values are the defaults")
    residual: Spec = Field("point_to_point", description="residual component")
    kernel: Spec = Field({"name": "geman_mcclure", "scale_m": "kiss"}, description="robust kernel component")
    threshold: Spec = Field("adaptive", description="association threshold component")
    deskew: Spec = Field({"name": "constant_velocity", "deskew": True, "reference": "end"}, description="motion prediction / deskew component")
    map: Spec = Field("voxel_hash", description="map component")
    preprocess: list[Spec] = Field(["range_crop"], description="preprocessing steps, in order")
    max_range_m: float = Field(100.0, gt=0, description="shared by range_crop, voxel_hash (far-voxel removal) and adaptive")
    min_range_m: float = Field(0.0, ge=0, description="shared by range_crop")
    voxel_size_m: float | None = Field(None, gt=0, description="map voxel (m); None: max_range_m / 100 (kiss-icp)")
    map_voxel_factor: float | None = Field(0.5, gt=0, description="map points: one per (factor x voxel) cell; None: all points")
    source_voxel_factor: float | None = Field(1.5, gt=0, description="registered points: one per (factor x voxel) cell of the map points; None: all")
    voxel_backend: Literal["auto", "kiss_icp", "numpy"] = Field(
        "auto", description="voxel downsampling in kiss-icp's compiled code (same points, same order; auto: when installed) or numpy"
    )
    voxel_order: Literal["kiss_hash", "input"] = Field(
        "kiss_hash", description="order of the downsampled points: kiss-icp's hash-table order (decides which points its map keeps) or input order"
    )
    max_iterations: int = Field(500, ge=1, description="ICP iterations per frame")
    convergence_criterion: float = Field(1e-4, gt=0, description="stop when the norm of the Gauss-Newton step is below this")
    source_covariance_neighbors: int = Field(10, ge=3, description="neighbours per source covariance (plane_to_plane)")

    @model_validator(mode="before")
    @classmethod
    def _apply_preset(cls, data: Any) -> Any:
        if isinstance(data, dict) and isinstance(data.get("preset"), str) and data["preset"] in PRESETS:  # ([] was unhashable)
            return {**copy.deepcopy(PRESETS[data["preset"]]), **data}
        return data

    @model_validator(mode="after")
    def _components(self) -> "PipelineConfig":
        if self.max_range_m <= self.min_range_m:
            raise ValueError(f"max_range_m ({self.max_range_m}) must exceed min_range_m ({self.min_range_m})")
        components = build_components(self)  # unknown names / params raise ConfigError listing the valid ones
        unread = unread_settings(self)
        # (accepted and ignored: a range crop without range_crop, config.json recording it)
        problems = [f"{name} is not read by this composition: {unread[name]}" for name in changed_fields(self, unread)]
        problems += [f"{name} is not read by this composition: {why}"
                     for name, why in unread_component_parameters(self, components).items()]
        problems += split_shared_settings(self, components)
        unscaled = unscaled_kernel(components)
        if unscaled:  # (huber, tukey, ... gave kernel=none's pose bit for bit, recorded as applied)
            problems.append(unscaled)
        if problems:  # (as a ConfigError of its own: get_icp's wrapping listed the bare pipeline's defaults as "valid")
            raise ConfigError("; ".join(problems), source="method 'pipeline'")
        return self

    @property
    def resolved_voxel_size_m(self) -> float:
        return self.voxel_size_m if self.voxel_size_m is not None else self.max_range_m / 100.0


def build_components(config: PipelineConfig) -> dict[str, Any]:
    """Fresh component instances for ``config``, shared settings passed where a component takes them."""
    values = {"max_range_m": config.max_range_m, "min_range_m": config.min_range_m, "voxel_size_m": config.resolved_voxel_size_m}

    def shared(kind: str) -> dict[str, Any]:
        return {name: values[name] for name in SHARED_SETTINGS[kind]}

    return {
        "residual": make_component("residual", config.residual),
        "kernel": make_component("kernel", config.kernel),
        "threshold": make_component("threshold", config.threshold, **shared("threshold")),
        "deskew": make_component("motion", config.deskew),
        "map": make_component("map", config.map, **shared("map")),
        "preprocess": [make_component("preprocess", step, **shared("preprocess")) for step in config.preprocess],
    }


def _takes(kind: str, spec: Spec, setting: str) -> bool:
    """Whether component ``spec`` takes the shared ``setting``: it is handed it, its config has it and ``spec`` does
    not set its own."""
    name, params = split_spec(kind, spec)
    return setting in SHARED_SETTINGS.get(kind, ()) and setting in get_component_class(kind, name).Config.model_fields \
        and setting not in params


def unread_settings(config: PipelineConfig) -> dict[str, str]:
    """The shared settings ``config``'s composition does not read, each with why (a value given for one is refused)."""
    specs = [("threshold", config.threshold), ("map", config.map), *(("preprocess", step) for step in config.preprocess)]

    def taken(setting: str) -> bool:
        return any(_takes(kind, spec, setting) for kind, spec in specs)

    voxelized = config.map_voxel_factor is not None or config.source_voxel_factor is not None
    unread = {}
    no_factor = "map_voxel_factor and source_voxel_factor are None (nothing is voxelized)"
    if not voxelized:
        unread["voxel_order"] = unread["voxel_backend"] = no_factor
    if not (voxelized or taken("voxel_size_m")):
        unread["voxel_size_m"] = f"{no_factor} and the map has no voxels (voxel_hash has)"
    voxel_from_range = config.voxel_size_m is None and "voxel_size_m" not in unread
    if not (taken("max_range_m") or voxel_from_range):
        unread["max_range_m"] = ("no component takes it (range_crop, voxel_hash and adaptive do) and no voxel size is "
                                 "derived from it")
    if not taken("min_range_m"):
        unread["min_range_m"] = "no component takes it (range_crop does)"
    residual = split_spec("residual", config.residual)[0]
    if not getattr(get_component_class("residual", residual), "needs_covariances", False):
        unread["source_covariance_neighbors"] = (f"the {residual} residual uses no source covariances (plane_to_plane "
                                                 "does)")
    return unread


def split_shared_settings(config: PipelineConfig, components: dict[str, Any] | None = None) -> list[str]:
    """A component's own value of a shared setting other than the pipeline's while the pipeline's value is read too
    (by another component, the sweep's voxelization or the voxel size derived from ``max_range_m``), each as why: the
    run then matched no single setting yet read as kiss's composition (a ``voxel_hash`` map at 0.5 m over sweeps
    voxelized at 1 m matched kiss at neither size, 9.5 / 10.2 mm apart on 6 KITTI scans). ``components``:
    ``build_components(config)``, when built already."""
    c = components or build_components(config)
    entries = [("threshold", config.threshold, c["threshold"]), ("map", config.map, c["map"]),
               *(("preprocess", spec, step) for spec, step in zip(config.preprocess, c["preprocess"]))]
    voxelized = config.map_voxel_factor is not None or config.source_voxel_factor is not None
    derived = config.voxel_size_m is None
    pipeline_values = {"max_range_m": config.max_range_m, "min_range_m": config.min_range_m,
                       "voxel_size_m": config.resolved_voxel_size_m}
    problems = []
    for setting, value in pipeline_values.items():
        readers = [f"{kind} {split_spec(kind, spec)[0]}" for kind, spec, _ in entries if _takes(kind, spec, setting)]
        if setting == "voxel_size_m" and voxelized:
            readers.append("the sweep's voxelization")
        if setting == "max_range_m" and voxelized and derived:
            readers.append("the voxel size (voxel_size_m=None: max_range_m / 100)")
        if not readers:
            continue
        shown = f"{value:g} = max_range_m / 100" if setting == "voxel_size_m" and derived else f"{value:g}"
        for kind, spec, component in entries:
            name, params = split_spec(kind, spec)
            own = getattr(component.config, setting, None)
            if setting in params and setting in SHARED_SETTINGS.get(kind, ()) and own is not None and own != value:
                problems.append(f"{kind} {name} {setting}={own:g} differs from the pipeline's {setting} ({shown}), read "
                                f"also by {', '.join(readers)}: set the pipeline's {setting}={own:g} instead (one value "
                                "for every stage)")
    return problems


def describe_components(components: dict[str, Any]) -> dict[str, Any]:
    """Every component of ``components`` (:func:`build_components`) with its resolved parameters."""
    out = {k: components[k].describe() for k in ("residual", "kernel", "threshold", "deskew", "map")}
    out["preprocess"] = [step.describe() for step in components["preprocess"]]
    return out


#: Component parameters that leave a composition what it is: values kiss takes as parameters of its own (the shared
#: ranges and voxel size, points per voxel, the adaptive threshold's start and minimum motion, deskew on or off), and
#: choices of how a map answers the same question (its nearest-neighbour backend, threads, neighbour tracking).
PARAMETERS_OUTSIDE_COMPOSITION = frozenset({
    "max_range_m", "min_range_m", "voxel_size_m", "max_points_per_voxel", "initial_threshold_m", "min_motion_m", "deskew",
    "nn_backend", "workers", "track_neighbors",
})
#: The pipeline's own settings that belong to its composition (kiss_like's are kiss's voxelization of each sweep).
COMPOSITION_SETTINGS = ("map_voxel_factor", "source_voxel_factor", "voxel_order")


def composition(config: PipelineConfig) -> dict[str, Any]:
    """What ``config`` composes, as resolved: each component's description without
    :data:`PARAMETERS_OUTSIDE_COMPOSITION`, and :data:`COMPOSITION_SETTINGS` (compared, not the preset's name: two
    configs alike but for ``preset`` read KITTI two ways)."""
    def own(described: dict[str, Any]) -> dict[str, Any]:
        return {k: v for k, v in described.items() if k not in PARAMETERS_OUTSIDE_COMPOSITION}

    described = describe_components(build_components(config))
    out: dict[str, Any] = {kind: own(d) for kind, d in described.items() if kind != "preprocess"}
    out["preprocess"] = [own(d) for d in described["preprocess"]]
    return {**out, **{name: getattr(config, name) for name in COMPOSITION_SETTINGS}}


def is_kiss_composition(config: PipelineConfig) -> bool:
    """Whether ``config`` composes what kiss runs: :func:`composition` equal to preset kiss_like's."""
    return composition(config) == composition(PipelineConfig(preset="kiss_like"))


def composition_changes(config: PipelineConfig) -> list[str]:
    """Where ``config``'s composition departs from kiss's (:func:`composition`), as ``"name=value"`` each: empty for
    kiss's own, whatever the values of :data:`PARAMETERS_OUTSIDE_COMPOSITION` (kiss's own parameters)."""
    mine, kiss = composition(config), composition(PipelineConfig(preset="kiss_like"))
    return [f"{name}={getattr(config, name)}" for name in mine if mine[name] != kiss.get(name)]


def _given(kind: str, spec: Spec, param: str) -> Any:
    """The value ``spec`` gives its component's ``param`` when other than the component's default, else None (a value
    equal to the default changes nothing, and a written config gives every parameter)."""
    name, params = split_spec(kind, spec)
    field = get_component_class(kind, name).Config.model_fields.get(param)
    if field is None or param not in params or params[param] == field.get_default(call_default_factory=True):
        return None
    return params[param]


def unread_component_parameters(config: PipelineConfig, components: dict[str, Any] | None = None) -> dict[str, str]:
    """The component parameters ``config`` gives at a value other than their default that its composition does not
    read, ``"KIND PARAM=VALUE"`` each with why: a map's ``neighbors`` without a residual built on normals or
    covariances, a deskew ``reference`` with ``deskew`` false (each gave the same pose for every value).
    ``components``: ``build_components(config)``, when built already."""
    c = components or build_components(config)
    residual, motion = c["residual"], c["deskew"]
    unread = {}
    neighbors = _given("map", config.map, "neighbors")
    if neighbors is not None and not (getattr(residual, "needs_normals", False) or getattr(residual, "needs_covariances", False)):
        unread[f"map neighbors={neighbors!r}"] = (f"the {residual.name} residual uses no map normals or covariances "
                                                  "(point_to_plane and plane_to_plane do)")
    reference = _given("motion", config.deskew, "reference")
    if reference is not None and getattr(motion.config, "deskew", True) is False:
        unread[f"deskew reference={reference!r}"] = (f"{motion.name} with deskew=False deskews no sweep (the reference is "
                                                     "the instant a deskewed sweep and its pose refer to)")
    return unread


def unscaled_kernel(components: dict[str, Any]) -> str | None:
    """Why the kernel cannot weigh anything, or None: one whose scale follows the threshold's sigma (``scale_m``
    adaptive or kiss) under a threshold without a finite one (fixed, ``max_distance_m=None``) weighs every
    correspondence 1, kernel=none's least squares under another name."""
    kernel, threshold = components["kernel"], components["threshold"]
    if "scale_m" not in type(kernel.config).model_fields:  # (none; a plugin kernel without a scale)
        return None
    try:
        sigma = float(threshold.sigma_m)
    except (TypeError, ValueError, NotImplementedError):  # (a plugin threshold's answer is checked when it runs)
        return None
    if np.isfinite(sigma) or np.isfinite(kernel.scale(sigma)):
        return None
    return (f"kernel={kernel.describe()} takes its scale from the threshold, and threshold={threshold.describe()} gives "
            "an infinite sigma: every correspondence would weigh 1, as with kernel=none (give the kernel a scale_m in "
            "metres, or the threshold a max_distance_m)")


def _applied(step: Any, points_xyz: np.ndarray) -> np.ndarray:
    """A preprocess step's output, checked to be ``(M, 3)`` points (a plugin's other shape failed further on in numpy,
    naming no step)."""
    out = step.apply(points_xyz)
    if not isinstance(out, np.ndarray) or out.ndim != 2 or out.shape[1] != 3:
        raise output_error(step, f"{type(out).__name__} of shape {np.shape(out)}, not (M, 3) points")
    return out


def _steps_text(components: dict[str, Any]) -> str:
    """The preprocess steps as a message names them: ``range_crop [0, 100] m``, ``no preprocess steps``."""
    steps = []
    for step in components["preprocess"]:
        described = step.describe()
        crop = [described.get("min_range_m"), described.get("max_range_m")]
        steps.append(described.get("name", type(step).__name__) + (f" [{crop[0]:g}, {crop[1]:g}] m" if None not in crop else ""))
    return ", ".join(steps) if steps else "no preprocess steps"


def _pose(component: Any, T: Any, what: str) -> np.ndarray:
    """A motion component's pose ``what``, checked to be a finite 4x4 matrix (a plugin's 3x3 failed in numpy further
    on, naming no component)."""
    if not isinstance(T, np.ndarray) or T.shape != (4, 4):
        raise output_error(component, f"a {what} of shape {np.shape(T)}, not a 4x4 pose")
    if not np.all(np.isfinite(T)):
        raise output_error(component, f"a {what} with non-finite entries")
    return T


def _deskewed(motion: Any, frame: np.ndarray, point_times_s: np.ndarray | None, delta: np.ndarray) -> np.ndarray:
    """The deskewed sweep, checked to keep every point (``(N, 3)`` for N points in)."""
    out = motion.deskew(frame, point_times_s, delta)
    if not isinstance(out, np.ndarray) or out.shape != frame.shape:
        raise output_error(motion, f"a deskewed sweep of shape {np.shape(out)} for {len(frame)} points, not {frame.shape}")
    return out


def _distances(threshold: Any) -> tuple[float, float]:
    """``(sigma_m, max_distance_m)`` of a threshold component, checked to be > 0 (inf: no kernel scale / no gate)."""
    sigma, gate = threshold.sigma_m, threshold.max_distance_m
    try:
        sigma, gate = float(sigma), float(gate)
    except (TypeError, ValueError):
        raise output_error(threshold, f"sigma_m {sigma!r} and max_distance_m {gate!r}, not numbers") from None
    if not sigma > 0 or not gate > 0:
        raise output_error(threshold, f"sigma_m {sigma:g} and max_distance_m {gate:g}, not both > 0")
    return sigma, gate


def _matches(local_map: Any, moved: np.ndarray, max_distance_m: float, track: dict | None) -> tuple[np.ndarray, np.ndarray]:
    """``(index, valid)`` of a map component's nearest points, checked: one entry per query, indices into its points."""
    out = local_map.nearest(moved, max_distance_m) if track is None else local_map.nearest(moved, max_distance_m, state=track)
    n = len(moved)
    try:
        _, index, valid = out
        index, valid = np.asarray(index), np.asarray(valid, dtype=bool)
        fits = index.shape == (n,) and valid.shape == (n,) and np.issubdtype(index.dtype, np.integer)
    except (TypeError, ValueError):
        fits = False
    if not fits:
        shapes = [np.shape(x) for x in out] if isinstance(out, tuple) else type(out).__name__
        raise output_error(local_map, f"nearest points {shapes} for {n} queries, not (dist, index, valid) of ({n},) each (integer indices)")
    if valid.any():
        picked = index[valid]
        if picked.min() < 0 or picked.max() >= len(local_map.points_xyz):
            raise output_error(local_map, f"indices up to {int(picked.max())} into a map of {len(local_map.points_xyz)} points")
    return index, valid


@register_icp("pipeline")
class PipelineRegistration(Registration):
    """Composable ICP: residual, kernel, threshold, deskew, map and preprocessing components (presets kiss_like, vanilla_seq)."""

    Config = PipelineConfig
    stateful = True
    #: ``register_frame`` takes ``sweeps_apart`` (frames that skip sweeps: its deskew motion is scaled to one sweep)
    accepts_sweeps_apart = True

    def __init__(self, config: PipelineConfig | None = None, **params):
        super().__init__(config, **params)
        self.reset()

    @property
    def deskew_instant(self) -> str | None:
        """The instant of the sweep deskewed poses refer to: the deskew component's ``reference`` (None: it does not
        deskew)."""
        motion = self._components["deskew"]
        if not getattr(getattr(motion, "config", None), "deskew", False):
            return None
        return {"start": "start", "middle": "mid", "end": "end"}.get(str(motion.reference))

    @property
    def reads_data_as(self) -> str | None:
        """``"kiss"`` for kiss's composition (:func:`is_kiss_composition`: kiss_like's as resolved, whatever the preset's
        name), else None: a reader prepares the data as for kiss (on KITTI under ``vertical_correction=auto``, the
        vertical-angle correction), so the two see the same points. It followed the preset's name: vanilla_seq on kiss's
        voxelization and kiss_like with vanilla's components, alike in every setting, read KITTI two ways (4.7 cm apart)."""
        return "kiss" if is_kiss_composition(self.config) else None

    def describe(self) -> dict[str, Any]:
        """Every component with its resolved parameters."""
        return describe_components(self._components)

    def _calibration(self) -> tuple[str | None, list[str]]:
        """kiss's entry wherever the composition is kiss's (:func:`is_kiss_composition`, the rule :attr:`reads_data_as`
        follows): a parameter kiss takes as its own (an adaptive threshold starting at 3 m, 30 points per voxel, one
        thread) gave kiss's pose bit for bit and kiss keeps its entry at any value, yet read "none learned" (28 mm x
        sigma where kiss gives 60 mm)."""
        learned, unlearned = super()._calibration()
        if learned != "pipeline":  # (a plugin subclass under an entry of its own)
            return learned, unlearned
        return learned, composition_changes(self.config)

    # ------------------------------------------------------------------ sequence mode
    def reset(self, T_world_lidar_initial: np.ndarray | None = None) -> None:
        """Start a new sequence: empty map, zero velocity, first pose ``T_world_lidar_initial`` (identity), checked as
        ``align``'s ``init_T`` (a reflection or a scaled matrix was projected onto the identity without a word)."""
        self._components = build_components(self.config)
        self.last_pose = np.eye(4) if T_world_lidar_initial is None else check_init_T(T_world_lidar_initial, "T_world_lidar_initial")
        self.last_delta = np.eye(4)
        self._delta_sweeps = 1.0  # sweeps spanned by last_delta (the previous frame's sweeps_apart)
        self.last_frame: dict[str, Any] = {}
        self._frames_registered = 0
        self._first_pose = self.last_pose  # (the first frame's pose as registered, at its sweep's end)
        #: the first frame's pose at the reference instant, known once the second frame gives the sweep's motion (a
        #: run replaces the first pose returned, at the sweep's end, by it); None: the first pose returned is at it
        self.restated_first_pose: np.ndarray | None = None

    def register_frame(self, points_xyz: np.ndarray, point_times_s: np.ndarray | None = None, sweeps_apart: float = 1.0) -> np.ndarray:
        """Register one sweep into the map; returns ``T_world_lidar`` at the deskew reference instant (the first sweep's
        at its end, no motion being known: :attr:`restated_first_pose` has it at the reference once the second sweep
        is registered; the second, deskewed with no motion known too, is restated alike when returned). A component's
        failure (a plugin kernel's NaN weights in scipy) is a RegistrationError naming the variant, as in ``align``.
        ``sweeps_apart``: sweeps since the previous frame (frames that skip scans): the deskew takes the motion between
        frames scaled to one sweep (taken whole, N sweeps apart deskewed N times too much); the prediction the previous
        motion at its rate over this frame's sweeps."""
        with use_backend(self.name, f"{self.name} (frame of {len(points_xyz)} points)"):
            return self._register_frame(points_xyz, point_times_s, check_sweeps_apart(sweeps_apart))

    def _register_frame(self, points_xyz: np.ndarray, point_times_s: np.ndarray | None = None, sweeps_apart: float = 1.0) -> np.ndarray:
        c = self._components
        frame = as_points(points_xyz, "frame", min_points=1)
        if point_times_s is not None:
            point_times_s = as_point_times(point_times_s)
            point_times_s = None if len(point_times_s) == 0 else check_point_times(point_times_s, len(frame))
        if c["map"].empty:  # the first frame says what the sequence is
            self._refuse_2d(frame, frame)
        raw = frame
        frame = _deskewed(c["deskew"], frame, point_times_s, se3_fraction(self.last_delta, self._delta_sweeps))
        map_points, source = self._voxelize(self._preprocess(frame))
        # the previous motion at its rate over this frame's sweeps (after a gap of dropped scans, the whole gap's)
        velocity = se3_fraction(self.last_delta, self._delta_sweeps / sweeps_apart)
        guess = _pose(c["deskew"], c["deskew"].predict(self.last_pose, velocity), "predicted pose")
        threshold = c["threshold"]
        sigma, gate = _distances(threshold)
        if len(source) == 0 and c["map"].empty:  # (every frame returned the prediction: a 0 m path, no warning)
            raise RegistrationError("no point of the sweep is left after preprocessing (max_range_m / min_range_m, the "
                                    f"preprocess steps; {local_origin.where_cloud_lies(raw)}): there is nothing to register",
                                    source="pipeline")
        if c["map"].empty or len(source) == 0:
            T, info = guess, {"iterations": 0, "n_correspondences": 0, "rmse_history": ()}
        else:
            T, info = self._icp(c, source, map_points, guess, sigma, gate)
        threshold.update(se3_inverse(guess) @ T)
        c["map"].update(map_points, T)
        self.last_delta = se3_inverse(self.last_pose) @ T
        self._delta_sweeps = sweeps_apart
        if self._frames_registered == 0:
            self._first_pose = T
        self.last_pose = T
        self.last_frame = {**info, "sigma_m": sigma, "source_points": len(source), "map_points": len(c["map"].points_xyz)}
        self._frames_registered += 1
        if frame is raw:  # undeskewed: the pose as registered
            return T.copy()
        sweep_motion = se3_fraction(self.last_delta, sweeps_apart)
        motion = c["deskew"]
        if self._frames_registered == 2:  # the first two sweeps, deskewed with no motion known (the identity), refer to
            # one instant: both restated alike by this frame's motion over one sweep (the caller replaces the first);
            # this frame reported as a deskewed one, the middle run's first step read 1.49 m for a true 1.00 m
            first = _pose(motion, motion.first_reported(self._first_pose, sweep_motion), "restated first pose")
            self.restated_first_pose = None if np.array_equal(first, self._first_pose) else first
            return _pose(motion, motion.first_reported(T, sweep_motion), "reported pose").copy()
        # the pose at the reference instant (the deskew component may register at another one); a copy: a component
        # that reports the pose as registered handed back last_pose itself, and a caller's edit moved every later frame
        return _pose(motion, motion.reported(T, sweep_motion), "reported pose").copy()

    # ------------------------------------------------------------------ stages
    def _refuse_2d(self, source_xyz: np.ndarray, target_xyz: np.ndarray, components: dict[str, Any] | None = None) -> None:
        """A residual built on normals or covariances is undefined on a 2D scan (point_to_plane returned the initial
        guess as converged)."""
        residual = (components or self._components)["residual"]
        if getattr(residual, "needs_normals", False) or getattr(residual, "needs_covariances", False):
            refuse_2d(self.name or "pipeline", source_xyz, target_xyz,
                      f"the {residual.describe().get('name', 'residual')} residual needs normals / covariances, undefined on a 2D scan (residual=point_to_point works)")

    def _preprocess(self, points_xyz: np.ndarray) -> np.ndarray:
        for step in self._components["preprocess"]:
            points_xyz = _applied(step, points_xyz)
        return points_xyz

    def _voxelize(self, frame: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        cfg, v = self.config, self.config.resolved_voxel_size_m
        order = cfg.voxel_order
        map_points = frame if cfg.map_voxel_factor is None else first_per_voxel(frame, cfg.map_voxel_factor * v, order, cfg.voxel_backend)
        source = map_points if cfg.source_voxel_factor is None else first_per_voxel(map_points, cfg.source_voxel_factor * v, order, cfg.voxel_backend)
        return map_points, source

    def _source_covariances(self, residual: Any, source: np.ndarray, dense: np.ndarray) -> np.ndarray | None:
        if not residual.needs_covariances:
            return None
        _, cov = pca_geometry(dense, cKDTree(dense), source, self.config.source_covariance_neighbors)
        return plane_regularized(cov, getattr(residual.config, "epsilon", 1e-3))

    def _icp(
        self, c: dict[str, Any], source: np.ndarray, dense: np.ndarray, guess: np.ndarray, sigma_m: float, max_distance_m: float
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Gauss-Newton ICP of ``source`` (sensor frame) against the map of components ``c`` from ``guess``; returns
        ``T_world_lidar``. ``c`` is passed, not read from the instance: a pairwise alignment runs on components of its
        own, and two run from two threads on one instance read each other's map (poses 0.7 m off, reported converged)."""
        local_map, residual, kernel = c["map"], c["residual"], c["kernel"]
        cov_local = self._source_covariances(residual, source, dense)
        moved = transform_points(guess, source)
        T_icp = np.eye(4)
        history: list[float] = []
        n = 0
        iterations = 0
        converged = False
        reason = ""
        # the same points move a little each iteration: the map may keep their nearest points between searches
        tracks = getattr(local_map.config, "track_neighbors", False) and "state" in inspect.signature(local_map.nearest).parameters
        track = {} if tracks else None
        for _ in range(self.config.max_iterations):
            index, valid = _matches(local_map, moved, max_distance_m, track)
            n = int(valid.sum())
            if n < MIN_ICP_CORRESPONDENCES:  # (the reason said "no convergence within 0 iterations", naming neither)
                within = f" within {max_distance_m:g} m" if np.isfinite(max_distance_m) else ""
                after = f" after {iterations} iterations" if iterations else ""
                reason = f"only {n} correspondences{within}{after} (need {MIN_ICP_CORRESPONDENCES})"
                break
            R = (T_icp @ guess)[:3, :3]
            cov = None if cov_local is None else np.einsum("ij,njk,lk->nil", R, cov_local[valid], R)
            JTJ, JTr, r2 = residual.normal_equations(
                moved[valid], local_map.points_xyz[index[valid]], index[valid], local_map, cov, kernel, sigma_m
            )
            if np.shape(JTJ) != (6, 6) or np.shape(JTr) != (6,) or np.shape(r2) != (n,):
                raise output_error(residual, f"normal equations of shapes {np.shape(JTJ)}, {np.shape(JTr)} and {np.shape(r2)} "
                                             f"for {n} correspondences, not (6, 6), (6,) and ({n},)")
            history.append(float(np.sqrt(r2.mean())))
            if not np.any(JTJ):  # the kernel gave every correspondence zero weight: there is nothing to solve for
                reason = f"no correspondence carried weight ({n} matched; the kernel's scale rejects them all)"
                break
            try:
                dx = np.linalg.solve(JTJ, -JTr)
            except np.linalg.LinAlgError:
                dx = np.linalg.lstsq(JTJ, -JTr, rcond=None)[0]
            Rs, ts = se3_exp_batch(dx[None, :])
            step = np.eye(4)
            step[:3, :3], step[:3, 3] = Rs[0], ts[0]
            moved = np.einsum("ij,nj->ni", step[:3, :3], moved) + step[:3, 3]
            T_icp = step @ T_icp
            iterations += 1
            if np.linalg.norm(dx) < self.config.convergence_criterion:
                converged = True
                break
        T = orthonormalize_se3(T_icp @ guess)
        return T, {"iterations": iterations, "n_correspondences": n, "rmse_history": tuple(history), "converged": converged,
                   "reason": reason}

    # ------------------------------------------------------------------ pairwise mode
    def _align(self, source_xyz: np.ndarray, target_xyz: np.ndarray, init_T: np.ndarray) -> RegistrationResult:
        """Pairwise: the map is built from the target alone; the threshold is its initial value (no motion seen)."""
        c = build_components(self.config)
        self._refuse_2d(source_xyz, target_xyz, c)
        given = {"source cloud": source_xyz, "target cloud": target_xyz}
        for step in c["preprocess"]:
            source_xyz, target_xyz = _applied(step, source_xyz), _applied(step, target_xyz)
        for name, cloud in (("source cloud", source_xyz), ("target cloud", target_xyz)):
            if len(cloud) < 3:  # (a far cloud: nothing within a range crop around the frame's origin)
                raise RegistrationError(f"only {len(cloud)} points left after preprocessing ({_steps_text(c)}; "
                                        f"{local_origin.where_cloud_lies(given[name])})", source=name)
        target_map, _ = self._voxelize(target_xyz)
        dense, source = self._voxelize(source_xyz)
        c["map"].update(target_map, np.eye(4))
        threshold = c["threshold"]
        T, info = self._icp(c, source, dense, init_T, *_distances(threshold))
        inlier = threshold.max_distance_m if np.isfinite(threshold.max_distance_m) else UNLIMITED_INLIER_DISTANCE_M
        assessment = assess_alignment(source, c["map"].points_xyz, T, inlier)
        result = assessment.to_result(
            T,
            converged=bool(info["converged"]),
            reason="" if info["converged"] else info.get("reason") or f"no convergence within {info['iterations']} iterations "
                                                                              f"({info['n_correspondences']} correspondences)",
            iterations=int(info["iterations"]),
            # ends with the RMSE at the final pose over the assessment's pairs (the fitness's, and kiss's RMSE): the loop's
            # own voxel-neighbourhood pairs alone read 0.012 m beside a fitness of 0.999 for a pose 0.46 m off
            rmse_history=(*info["rmse_history"], assessment.rmse_m),
            extra={"threshold_sigma_m": threshold.sigma_m, "source_points": len(source), "components": describe_components(c)},
        )
        if assessment.n_correspondences < 3:
            import dataclasses

            result = dataclasses.replace(result, degeneracy=Degeneracy.unknown("too few correspondences"))
        return result


__all__ = [
    "COMPOSITION_SETTINGS", "PARAMETERS_OUTSIDE_COMPOSITION", "PRESETS", "SHARED_SETTINGS", "PipelineConfig",
    "PipelineRegistration", "build_components", "composition", "composition_changes", "describe_components", "is_kiss_composition",
    "split_shared_settings", "unread_component_parameters", "unread_settings", "unscaled_kernel",
]
