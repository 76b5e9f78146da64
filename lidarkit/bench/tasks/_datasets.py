"""Opening a job's dataset inside a worker (cached per process) and checking reader options before the run."""

from __future__ import annotations

import inspect
from collections import OrderedDict
from typing import Any

from lidarkit.bench.datasets import dataset_options, dataset_path
from lidarkit.bench.jobs import canonical_json
from lidarkit.errors import ConfigError, validation_problems

_CACHE: OrderedDict[str, Any] = OrderedDict()
_CACHE_SIZE = 4


def check_reader_options(spec: dict[str, Any]) -> None:
    """Unknown reader options raise ConfigError listing the reader's keyword parameters (from its signature)."""
    kind = spec["kind"]
    options = dataset_options(spec)
    if kind == "sim_lidar":
        from lidarkit.sim.lidar import make_config

        make_config(**options)
        return
    from lidarkit.io import get_reader

    reader = get_reader(kind)
    params = inspect.signature(reader).parameters
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values()):
        return
    accepted = [name for name, p in params.items() if p.kind is not inspect.Parameter.POSITIONAL_ONLY][1:]
    unknown = sorted(set(options) - set(accepted))
    if unknown:
        raise ConfigError(
            f"unknown option(s) {', '.join(unknown)} for dataset kind {kind!r}; it takes: {', '.join(accepted)}",
            source="dataset",
        )


def open_dataset_spec(spec: dict[str, Any]) -> Any:
    """The reader / simulator object of a resolved dataset spec; the last few are kept per process."""
    cache_key = canonical_json(spec)
    if cache_key in _CACHE:
        _CACHE.move_to_end(cache_key)
        return _CACHE[cache_key]
    kind = spec["kind"]
    options = dataset_options(spec)
    if kind == "sim_lidar":
        from lidarkit.sim.lidar import SimulatedLidarSequence

        dataset = SimulatedLidarSequence(**options)
    else:
        from lidarkit.io import open_dataset

        dataset = open_dataset(kind, dataset_path(spec), **options)
    _CACHE[cache_key] = dataset
    while len(_CACHE) > _CACHE_SIZE:
        _CACHE.popitem(last=False)
    return dataset


def options_model(model: type, options: dict[str, Any], task: str) -> Any:
    """Validate task options with a pydantic model; errors become ConfigError listing the valid options."""
    from pydantic import ValidationError

    try:
        return model(**options)
    except ValidationError as err:
        problems = validation_problems(err)
        raise ConfigError(f"{problems} (options of task {task!r}: {', '.join(model.model_fields)})", source="options") from None
