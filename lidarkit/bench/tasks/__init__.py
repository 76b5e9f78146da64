"""Benchmark tasks: what one job computes. A registry maps task names to ``Task`` classes.

Built-in tasks are imported lazily (their modules pull in Open3D, OpenCV, ...); third-party tasks
register with :func:`register_task`. Each task validates a job through the owning module's own
validators (e.g. ``lidarkit.registration.get_icp``) so the suite is refused before anything runs.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, ClassVar

from pydantic import BeforeValidator, StrictInt

from lidarkit.bench.jobs import Job, whole_floats_as_ints
from lidarkit.errors import ConfigError
from lidarkit.plugins import checked_name, claim_name

_BUILTIN: dict[str, str] = {
    "selftest": "lidarkit.bench.tasks.selftest:SelfTestTask",
    "icp_pair": "lidarkit.bench.tasks.icp_pair:IcpPairTask",
    "odometry": "lidarkit.bench.tasks.odometry:OdometryTask",
    "pf": "lidarkit.bench.tasks.pf:ParticleFilterTask",
    "vo": "lidarkit.bench.tasks.vo:VisualOdometryTask",
}
_REGISTERED: dict[str, type[Task]] = {}
_INSTANCES: dict[str, Task] = {}

#: an integer of a suite (a task option that counts, ``seeds``): a whole float is that integer (YAML's ``2.0`` was
#: refused where a job key already read it as 2); a fraction, a boolean (YAML's ``true`` was read as 1) or text is not
WholeInt = Annotated[StrictInt, BeforeValidator(whole_floats_as_ints)]


#: what a metric says, ``Metric.kind``: ``accuracy`` (how well: a baseline holds it in its band), ``speed`` (depends on
#: the machine) and ``diagnostic`` (what the method did on its way, an ICP's iterations or final RMSE: another setting
#: moves it while the accuracy stays in band). Reports show all three; baselines check accuracy metrics only.
METRIC_KINDS = ("accuracy", "speed", "diagnostic")
#: the kinds a baseline pins and checks
CHECKED_KINDS = ("accuracy",)


@dataclass(frozen=True)
class Metric:
    """A scalar a task reports; ``better`` is ``"lower"`` or ``"higher"``; ``kind`` one of :data:`METRIC_KINDS`."""

    name: str
    label: str
    kind: str = "accuracy"
    better: str = "lower"


@dataclass
class TaskOutput:
    """What a task returns for one job.

    ``metrics``: scalar floats (names from ``Task.metrics``, extra ones allowed);
    ``series``: small JSON-ready arrays for plots, by convention
    ``trajectory_xy`` = ``{"ref": [[x, y], ...], "est": [[x, y], ...]}`` (metres),
    ``error_over_time`` = ``{"t": [...], "error": [...], "label": str}`` (and ``"t_label"`` when ``t`` is not seconds),
    ``rmse_history`` = ``[...]`` (one value per ICP iteration);
    ``info``: anything else worth recording (resolved config, counts).
    """

    metrics: dict[str, float] = field(default_factory=dict)
    series: dict[str, Any] = field(default_factory=dict)
    info: dict[str, Any] = field(default_factory=dict)


class Task:
    """Base class of a benchmark task. Subclasses set the class attributes and implement ``run``."""

    name: ClassVar[str] = ""
    description: ClassVar[str] = ""
    #: dataset kinds this task accepts (``kind`` in the suite's dataset spec)
    dataset_kinds: ClassVar[tuple[str, ...]] = ()
    #: metrics shown in report tables, in order
    metrics: ClassVar[tuple[Metric, ...]] = ()
    #: (param, metric) pairs plotted as metric vs param across a method's grid (e.g. PF MSE vs particles)
    sweep_plots: ClassVar[tuple[tuple[str, str], ...]] = ()

    def require(self) -> None:
        """Raise ConfigError when the modules this task needs are not installed / not there yet."""

    def available_methods(self) -> list[str] | None:
        """Method names usable here (e.g. registered ICP variants; optional extras may be absent), None if open."""
        return None

    def optional_methods(self) -> tuple[str, ...]:
        """Method names of optional extras, which a demo skips where they are absent (any other name is validated)."""
        return ()

    def validate_options(self, options: dict[str, Any]) -> None:
        """Raise ConfigError for bad experiment ``options``; called once per experiment before the run."""
        if options:
            raise ConfigError(f"task {self.name!r} takes no options, got {', '.join(sorted(options))}", source="options")

    def resolved_options(self, options: dict[str, Any]) -> dict[str, Any]:
        """``options`` validated, with every default the task fills in written out: what a job runs under, which a
        baseline pins (a later default then reads as a changed protocol, not as a regression of the method). A task
        whose options have defaults overrides it; this one returns the options as given."""
        self.validate_options(options)
        return dict(options)

    def option_files(self, dataset: dict[str, Any], options: dict[str, Any]) -> list[Path]:
        """The files a job's ``options`` make it read beside its dataset's (a ground-truth file an option names): a
        baseline hashes them with the dataset's files, so an edited one reads as changed data. None by default."""
        return []

    def validate_dataset(self, dataset: dict[str, Any], options: dict[str, Any]) -> None:
        """Raise ConfigError / DataError for a dataset spec this task cannot use; called once per dataset."""

    def validate(self, method: str, params: dict[str, Any], dataset: dict[str, Any], options: dict[str, Any]) -> None:
        """Raise ConfigError / DataError if this method + params could not run; called for every combination."""

    def run(self, job: Job) -> TaskOutput:  # pragma: no cover - abstract
        raise NotImplementedError


def register_task(name: str) -> Callable[[type[Task]], type[Task]]:
    """Class decorator registering a ``Task`` subclass under ``name`` (the naming rule: :mod:`lidarkit.plugins`)."""
    checked_name(name, "a task name", "register_task")

    def decorator(cls: type[Task]) -> type[Task]:
        # (int was taken and failed "cannot set 'name' attribute of immutable type 'int'")
        if not (isinstance(cls, type) and issubclass(cls, Task)):
            what = f"the class {cls.__qualname__}" if isinstance(cls, type) else f"{type(cls).__name__} {cls!r}"
            raise ConfigError(f"decorates a subclass of lidarkit.bench.tasks.Task, got {what}", source=f"register_task({name!r})")
        claim_name(_REGISTERED, name, cls, f"register_task({name!r})", _BUILTIN)
        cls.name = name
        _REGISTERED[name] = cls
        _INSTANCES.pop(name, None)
        return cls

    return decorator


def available_tasks() -> list[str]:
    """Names of every task a suite may use (whether or not its module has landed)."""
    return sorted(set(_BUILTIN) | set(_REGISTERED))


def task_module(name: str) -> str | None:
    """The module the task registered as ``name`` is defined in (None for a built-in or unknown name): a worker process
    knows only the built-ins and what it imported, so it imports this module before resolving the name."""
    cls = _REGISTERED.get(name)
    return cls.__module__ if cls is not None else None


def get_task(name: str, module: str | None = None) -> Task:
    """The task instance for ``name``, importing ``module`` first (see :func:`task_module`) when ``name`` is not known
    yet; unknown names raise ConfigError listing the known ones."""
    if name in _INSTANCES:
        return _INSTANCES[name]
    if module and module != "__main__" and name not in _REGISTERED:  # (a script's own __main__ is loaded already)
        import_module_for_task(name, module)  # (the task registers itself as its module loads)
    if name in _REGISTERED:
        cls = _REGISTERED[name]
    elif name in _BUILTIN:
        module_name, attr = _BUILTIN[name].split(":")
        cls = getattr(importlib.import_module(module_name), attr)
        cls.name = cls.name or name  # (a built-in class is not registered by name: its messages read "task ''")
    else:
        raise ConfigError(f"unknown task {name!r}; known: {', '.join(available_tasks())}", source="task")
    _INSTANCES[name] = cls()
    return _INSTANCES[name]


#: run-folder and library metrics that are better higher (the tasks declare theirs with ``Metric.better``)
HIGHER_IS_BETTER = frozenset({"hz", "converged_fraction"})


def higher_is_better(metric: str, task: str | None = None) -> bool:
    """Whether a larger ``metric`` is better: as ``task`` declares it (``Metric.better``), or as any task that can be
    loaded declares a metric of that name; else :data:`HIGHER_IS_BETTER`."""
    if metric in HIGHER_IS_BETTER:
        return True
    names = [task] if task is not None else available_tasks()
    for name in names:
        try:
            metrics = get_task(name).metrics
        except Exception:  # noqa: BLE001 - a task whose module cannot load here declares nothing
            continue
        if any(m.name == metric and m.better == "higher" for m in metrics):
            return True
    return False


def import_module_for_task(task: str, module: str) -> Any:
    """Import ``module`` for ``task``; a missing module becomes a ConfigError saying which task needs it."""
    try:
        return importlib.import_module(module)
    except ImportError as err:
        raise ConfigError(f"task {task!r} needs {module}, which is not available ({err})", source="task") from err


__all__ = ["CHECKED_KINDS", "HIGHER_IS_BETTER", "METRIC_KINDS", "Metric", "Task", "TaskOutput", "WholeInt", "available_tasks", "get_task", "higher_is_better", "import_module_for_task",
           "register_task", "task_module"]
