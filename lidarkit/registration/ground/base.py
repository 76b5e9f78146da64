"""The ground segmenter interface and its registry: ``segment(points_xyz) -> (N,) bool mask of ground points``.

Segmenters are preprocessing components: ``ground_filtered`` takes one by name, and any other variant or
pipeline can call one the same way. Like the ICP registry, a class registers itself under a name and
validates its parameters with a frozen pydantic config.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, ClassVar

import numpy as np
import pydantic
from pydantic import BaseModel, ConfigDict, model_validator

from lidarkit.errors import ConfigError, DataError, validation_problems
from lidarkit.geometry import as_points
from lidarkit.params import refuse_yes_no_numbers, shown_default
from lidarkit.plugins import checked_name, claim_name
from lidarkit.registration import local_origin

#: Mounting height of KITTI's Velodyne HDL-64E above the road (m).
KITTI_SENSOR_HEIGHT_M = 1.73


class GroundConfig(BaseModel):
    """Base of every segmenter's config: frozen, unknown keys rejected, numbers finite and not given as yes/no
    (``ground_params={sensor_height_m: yes}`` ran with a 1 m sensor height)."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    @model_validator(mode="before")
    @classmethod
    def _numbers_are_not_yes_or_no(cls, data: Any) -> Any:
        return refuse_yes_no_numbers(cls, data)


class GroundSegmenter:
    """Base class: subclasses set ``name`` and ``Config`` and implement :meth:`_segment`."""

    name: ClassVar[str] = ""
    Config: ClassVar[type[GroundConfig]] = GroundConfig
    #: Whether the segmenter measures heights from the sensor (``z = 0`` at the sensor, e.g. a fixed level below it).
    #: A cloud that is not in its sensor frame (georeferenced, a map frame: see
    #: :func:`lidarkit.registration.local_origin.sensor_proxy`) is then refused; one that judges heights against the
    #: points themselves (False) gets the cloud moved to where its sensor likely is, so that its ranges are the sensor's.
    heights_from_sensor: ClassVar[bool] = True

    def __init__(self, config: GroundConfig | None = None, **params: Any):
        if config is not None and params:
            raise TypeError("pass either a config object or keyword parameters, not both")
        self.config = config if config is not None else self.Config(**params)

    def segment(self, points_xyz: np.ndarray) -> np.ndarray:
        """``(N,)`` bool mask of the ground points of an ``(N, 3)`` cloud in the sensor frame (z up)."""
        # the registration backends' own input check: shape, dtype, NaN (the cloth filter crashed the process on one)
        pts = as_points(points_xyz, f"ground segmenter {self.name!r}")
        if len(pts) == 0:
            return np.zeros(0, dtype=bool)
        sensor = local_origin.sensor_proxy(pts)
        if sensor is not None:  # (segmented as given, a cloud 300 m out kept all its ground: every point beyond max range)
            if self.heights_from_sensor:
                raise DataError(
                    f"the cloud's middle lies {float(np.linalg.norm(sensor)):.3g} m from its frame's origin (read as georeferenced or a "
                    f"map frame; or a sensor that high above its ground) and ground method {self.name!r} measures heights from the "
                    f"sensor: give scans in their sensor frame, or use a method that does not "
                    f"({', '.join(n for n, k in sorted(_REGISTRY.items()) if not k.heights_from_sensor)})",
                    source=f"ground segmenter {self.name!r}",
                )
            # by whole metres: a grid-based segmenter (local_plane's 1 m cells) then sees a cloud moved by whole metres
            # on the grid it has in its own frame (moved by the unrounded median, 300 m out, ground_filtered's
            # calibrated x/y sigmas came out 0.3x the sensor frame's)
            pts = pts - np.round(sensor)
        mask = np.asarray(self._segment(pts), dtype=bool)
        if mask.shape != (len(pts),):
            raise DataError(f"segmenter returned a mask of shape {mask.shape} for {len(pts)} points", source=self.name)
        return mask

    def _segment(self, points_xyz: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.config!r})"


_REGISTRY: dict[str, type[GroundSegmenter]] = {}


def register_ground_segmenter(name: str) -> Callable[[type[GroundSegmenter]], type[GroundSegmenter]]:
    """Class decorator: register a :class:`GroundSegmenter` subclass under ``name`` (the naming rule:
    :mod:`lidarkit.plugins`)."""
    checked_name(name, "a ground segmenter name", "register_ground_segmenter")

    def decorator(cls: type[GroundSegmenter]) -> type[GroundSegmenter]:
        if not (isinstance(cls, type) and issubclass(cls, GroundSegmenter)):
            raise ConfigError(f"{cls!r} is not a GroundSegmenter subclass", source=f"register_ground_segmenter({name!r})")
        claim_name(_REGISTRY, name, cls, f"register_ground_segmenter({name!r})")
        cls.name = name
        _REGISTRY[name] = cls
        return cls

    return decorator


def available_ground_segmenters() -> list[str]:
    """Registered segmenter names, sorted (wrapped libraries are listed even when not installed)."""
    return sorted(_REGISTRY)


def get_ground_segmenter_class(name: str) -> type[GroundSegmenter]:
    """The class registered as ``name``; an unknown name raises ConfigError listing the known ones."""
    try:
        return _REGISTRY[name]
    except KeyError:
        raise ConfigError(
            f"unknown ground segmenter {name!r}; available: {', '.join(available_ground_segmenters())}", source="ground segmenter"
        ) from None


def ground_config_fields(name: str) -> dict[str, tuple[str, Any, str]]:
    """``{param: (type, default, description)}`` of a segmenter's config, generated from the model."""
    from lidarkit.registration.registry import _type_name

    cls = get_ground_segmenter_class(name)
    return {
        key: (_type_name(info.annotation), info.get_default(call_default_factory=True), info.description or "")
        for key, info in cls.Config.model_fields.items()
    }


def ground_config(name: str, **params: Any) -> GroundConfig:
    """Segmenter ``name``'s validated config; bad or unknown params raise ConfigError listing the valid ones (the one
    check of the segmenters and of the mask functions that take the settings as arguments: ``ground_mask_by_plane(pts,
    num_iterations=0)`` marked no ground without a word)."""
    cls = get_ground_segmenter_class(name)
    try:
        return cls.Config(**params)
    except pydantic.ValidationError as err:
        from lidarkit.registration.components.registry import glued_yaml_hint

        valid = ", ".join(f"{k}={shown_default(v[1])}" for k, v in ground_config_fields(name).items()) or "(none)"
        raise ConfigError(f"invalid parameters ({validation_problems(err, unnamed='')}){glued_yaml_hint(params)}; "
                          f"valid parameters: {valid}", source=f"ground segmenter {name!r}") from None


def get_ground_segmenter(name: str, **params: Any) -> GroundSegmenter:
    """A configured segmenter; bad or unknown params raise ConfigError listing the valid ones."""
    return get_ground_segmenter_class(name)(config=ground_config(name, **params))
