"""Opening a job's dataset inside a worker (cached per process) and checking reader options before the run."""

from __future__ import annotations

import inspect
import logging
from collections import OrderedDict
from typing import Any

from lidarkit.bench.datasets import dataset_options, dataset_path
from lidarkit.bench.jobs import Job, canonical_json
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
    if kind in OPENED_AT_LOAD:  # a sequence that is not there is refused with the suite, not when its jobs run
        open_dataset_spec(spec)  # (cached: require_kitti_data's look at the same sequence opens it once)


#: readers cheap to open (a folder listing, a list file) whose path or options name what must exist, e.g. KITTI's ``sequence``,
#: a scan folder's files: a dataset without them is refused with the suite (its jobs each failed), not when they run
OPENED_AT_LOAD = frozenset({"kitti", "kitti_raw", "folder", "tum"})


def scan_count_at_load(spec: dict[str, Any]) -> int | None:
    """The number of scans of a dataset known when the suite loads: a simulated drive's ``n_frames`` (default 300) read
    from its spec without simulating, a reader in :data:`OPENED_AT_LOAD`'s length; None for the others (known when their
    jobs run). Pairs and frames out of range are refused against it (on a simulated drive every job failed, exit 0)."""
    if spec["kind"] == "sim_lidar":
        from lidarkit.sim.lidar import make_config

        return int(make_config(**dataset_options(spec)).n_frames)
    if spec["kind"] in OPENED_AT_LOAD:
        return len(open_dataset_spec(spec))
    return None


class _Warnings(logging.Handler):
    """The warnings logged while a dataset opens (to log again for every job that uses the cached dataset)."""

    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.records: list[logging.LogRecord] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.records.append(record)


def open_dataset_spec(spec: dict[str, Any]) -> Any:
    """The reader / simulator object of a resolved dataset spec; the last few are kept per process. The warnings its
    opening logged are logged again for every job that takes it from the cache, so that each job's result holds them
    (they went to the first job of each worker only, and a report's warnings changed with the executor)."""
    cache_key = canonical_json(spec)
    if cache_key in _CACHE:
        _CACHE.move_to_end(cache_key)
        dataset, records = _CACHE[cache_key]
        for record in records:
            logging.getLogger(record.name).log(record.levelno, "%s", record.getMessage())
        return dataset
    kind = spec["kind"]
    options = dataset_options(spec)
    caught = _Warnings()
    root = logging.getLogger()
    root.addHandler(caught)
    try:
        if kind == "sim_lidar":
            from lidarkit.sim.lidar import SimulatedLidarSequence

            dataset = SimulatedLidarSequence(**options)
        else:
            from lidarkit.io import open_dataset

            dataset = open_dataset(kind, dataset_path(spec), **options)
    finally:
        root.removeHandler(caught)
    _CACHE[cache_key] = (dataset, caught.records)
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


def seeded_dataset(job: Job) -> dict[str, Any]:
    """The job's dataset spec; a simulated sequence without its own ``seed`` is seeded by the job's seed, so
    ``seeds: 10`` in a suite runs a method over 10 different simulated drives (the unit of a paired test)."""
    if job.dataset.get("kind") == "sim_lidar" and "seed" not in job.dataset:
        return {**job.dataset, "seed": int(job.seed)}
    return job.dataset


def require_kitti_data(dataset: dict[str, Any], what: str) -> None:
    """A KITTI dataset spec whose sequence lacks the ``what`` (``"scans"`` or ``"images"``) a task reads is a ConfigError
    before anything runs (every job failed with "sequence has no scans", exit 0). Other kinds are left to their run:
    opening them can cost (a simulator builds its scene, a bag is indexed)."""
    if dataset.get("kind") != "kitti":
        return
    sequence = open_dataset_spec(dataset)
    paths = getattr(sequence, "scan_paths" if what == "scans" else "image_paths", None)
    if paths is not None and not paths:
        folder = getattr(sequence, "sequence_dir", dataset.get("path"))
        raise ConfigError(f"the KITTI sequence {folder} has no {what} (velodyne/ for scans, image_0/ for images)", source="dataset")
