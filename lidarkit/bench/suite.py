"""Benchmark suites: a YAML file of experiments, validated (pydantic + each task's own validators) and expanded into jobs.

Everything that can be wrong with a suite (bad YAML, unknown key, task, method or param, missing
dataset) is reported here as a ConfigError / DataError naming the file, the key and the reason,
before any job runs.
"""

from __future__ import annotations

import errno
import itertools
import logging
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from lidarkit.bench.datasets import SAMPLE_PREFIX, dataset_label, dataset_options, resolve_dataset, resolve_option_paths
from lidarkit.bench.jobs import Job, canonical_json, distinct_labels, whole_floats_as_ints
from lidarkit.bench.tasks import WholeInt, get_task
from lidarkit.errors import ConfigError, DataError, LidarKitError

log = logging.getLogger(__name__)

MAX_JOBS = 100_000  # a suite expanding to more jobs is refused before expansion (load_suite(max_jobs=...), --max-jobs)


class MethodSpec(BaseModel):
    """A method with fixed ``params`` and a ``grid`` (param -> list of values, expanded as a cartesian product)."""

    model_config = ConfigDict(extra="forbid")
    name: str = Field(min_length=1)
    params: dict[str, Any] = Field(default_factory=dict)
    grid: dict[str, list[Any]] = Field(default_factory=dict)

    @field_validator("grid")
    @classmethod
    def _grid_nonempty(cls, grid: dict[str, list[Any]]) -> dict[str, list[Any]]:
        for key, values in grid.items():
            if not values:
                raise ValueError(f"grid values of {key!r} are empty")
        return grid


class DatasetSpec(BaseModel):
    """``kind`` (reader or simulator), ``path`` (absent for simulators), ``name`` (report label), reader options."""

    model_config = ConfigDict(extra="allow")
    kind: str = Field(min_length=1)
    path: str | None = None
    name: str | None = None


class Experiment(BaseModel):
    """One task run over its datasets x methods (x grid) x seeds."""

    model_config = ConfigDict(extra="forbid")
    name: str | None = None
    task: str
    dataset: DatasetSpec | str | None = None
    datasets: list[DatasetSpec | str] | None = None
    methods: list[MethodSpec | str] = Field(min_length=1)
    seeds: list[WholeInt] | WholeInt | None = None
    options: dict[str, Any] = Field(default_factory=dict)


class SuiteModel(BaseModel):
    """The whole YAML file."""

    model_config = ConfigDict(extra="forbid")
    name: str = "suite"
    description: str = ""
    seeds: list[WholeInt] | WholeInt = Field(default_factory=lambda: [0])
    datasets: dict[str, DatasetSpec] = Field(default_factory=dict)
    experiments: list[Experiment] = Field(min_length=1)


@dataclass
class Suite:
    """A validated suite: its jobs in a stable order, plus experiments skipped because their task is unavailable."""

    name: str
    path: Path | None
    jobs: list[Job]
    description: str = ""
    skipped: list[tuple[str, str]] = field(default_factory=list)

    def __repr__(self) -> str:
        """One line of counts (the generated one printed every job: 2,300 characters for 9 jobs)."""
        def count(n: int, what: str) -> str:
            return f"{n:,} {what}" + ("" if n == 1 else "s")

        experiments = len({job.experiment for job in self.jobs})
        skipped = f", {len(self.skipped)} skipped" if self.skipped else ""
        where = f", {str(self.path)!r}" if self.path is not None else ""
        return f"Suite({self.name!r}, {count(len(self.jobs), 'job')}, {count(experiments, 'experiment')}{skipped}{where})"


def _seeds(value: list[int] | int) -> list[int]:
    return list(range(value)) if isinstance(value, int) else list(value)


def _loc_text(loc: tuple[Any, ...]) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        elif part in ("DatasetSpec", "MethodSpec", "str", "list[int]", "int") or "[" in str(part):
            continue  # pydantic union branch names
        else:
            out += f".{part}" if out else str(part)
    return out or "(top level)"


def _line_of(root: yaml.Node | None, loc: tuple[Any, ...]) -> int | None:
    """1-based line of the YAML node at ``loc`` (walks the composed node tree; None if not found)."""
    node, line = root, None
    for part in loc:
        if isinstance(node, yaml.MappingNode) and isinstance(part, str):
            for key_node, value_node in node.value:
                if key_node.value == part:
                    line, node = key_node.start_mark.line + 1, value_node
                    break
            else:
                continue  # e.g. a pydantic union branch name
        elif isinstance(node, yaml.SequenceNode) and isinstance(part, int) and part < len(node.value):
            node = node.value[part]
            line = node.start_mark.line + 1
    return line


class _Locator:
    """Builds ``file (key, line N)`` errors for one suite file."""

    def __init__(self, path: Path, root: yaml.Node | None):
        self.path, self.root = path, root

    def location(self, loc: tuple[Any, ...]) -> str:
        text = _loc_text(loc)
        line = _line_of(self.root, loc)
        return f"{text}, line {line}" if line else text

    def error(self, err: LidarKitError, loc: tuple[Any, ...]) -> LidarKitError:
        if err.source == str(self.path):  # already located
            return err
        reason = err.reason if err.source in (None, "task", "dataset", "method", "options") else str(err)
        return type(err)(reason, source=self.path, location=self.location(loc))


def read_suite_file(path: str | Path) -> tuple[SuiteModel, _Locator]:
    """Parse and schema-check a suite file (no task validation yet)."""
    path = Path(path)
    if path.is_dir():  # (it read "cannot read suite file: [Errno 21] Is a directory")
        raise DataError(_folder_given(path), source=path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        from lidarkit.atomic import missing_reason

        raise DataError(missing_reason(path, "suite file not found"), source=path) from None
    except (OSError, UnicodeDecodeError) as err:
        raise DataError(f"cannot read suite file: {err}", source=path) from None
    try:
        root = yaml.compose(text)
        raw = yaml.safe_load(text)
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f"line {mark.line + 1}, column {mark.column + 1}" if mark else None
        problem = getattr(err, "problem", None) or str(err).splitlines()[0]
        raise ConfigError(f"malformed YAML: {problem}", source=path, location=where) from None
    locator = _Locator(path, root)
    _refuse_duplicate_keys(root, path)
    if not isinstance(raw, dict):
        raise ConfigError("a suite is a YAML mapping with an 'experiments' list", source=path)
    record = _record_given(raw)
    if record:  # (bench's suite.json read "unknown key 'jobs'; unknown key 'lidarkit_version' ...")
        raise ConfigError(record, source=path)
    try:
        model = SuiteModel.model_validate(raw)
    except ValidationError as err:
        # a mapping given where a mapping or a name fits: its mapping branch explains it ("Input should be a valid
        # string" of the name branch was added to "grid values of 'seconds' are empty")
        errors = [e for e in err.errors() if e["loc"][-1:] != ("str",) or not isinstance(e["input"], dict)] or err.errors()
        errors = sorted(errors, key=lambda e: e["type"] != "extra_forbidden")  # a typo explains a "missing"
        first = errors[0]
        messages = []
        for e in errors[:3]:
            if e["type"] == "extra_forbidden":
                msg = f"unknown key {e['loc'][-1]!r}"
            elif e["type"] == "missing":
                msg = f"missing key {e['loc'][-1]!r}"
            else:
                msg = f"{_loc_text(tuple(e['loc']))}: {e['msg'].removeprefix('Value error, ')}"  # (a validator's own)
            messages.append(msg)
        more = f" (+{len(errors) - 3} more)" if len(errors) > 3 else ""
        raise ConfigError("; ".join(messages) + more, source=path, location=locator.location(tuple(first["loc"]))) from None
    return model, locator


#: where a suite is described, named when something else is given as one
_SUITE_DOCS = "a suite is a YAML file with an 'experiments' list (docs/benchmarks.md)"


def _suite_file_of(results: Path) -> str:
    """The suite file a bench results folder ran, as its suite.json records it; '' when it does not say."""
    import json

    try:
        recorded = json.loads((results / "suite.json").read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError):
        return ""
    suite_file = recorded.get("suite_file") if isinstance(recorded, dict) else None
    return suite_file if isinstance(suite_file, str) else ""


def _folder_given(path: Path) -> str:
    """Why the folder ``path`` is no suite file, naming what it is and, for lidarkit's own output, the file to give."""
    from lidarkit.run_files import is_baseline_folder, is_bench_results_folder, output_folder_kind

    if is_baseline_folder(path):
        return f"a baseline folder (manifest.json), not a suite file: give its suite.yaml ({path / 'suite.yaml'})"
    if is_bench_results_folder(path):
        suite_file = _suite_file_of(path)
        ran = f" ({suite_file})" if suite_file else ""
        return (f"a bench results folder (jobs/, suite.json), not a suite file: give the suite file it ran{ran}; "
                "its suite.json is bench's record of that run, not a suite")
    kind = output_folder_kind(path)
    return f"{kind or 'a folder'}, not a suite file: {_SUITE_DOCS}"


def _record_given(raw: dict[str, Any]) -> str:
    """Why the mapping ``raw`` is lidarkit's record of a run rather than a suite (bench's suite.json, a baseline's
    manifest.json), naming the file to give; '' for anything else."""
    if "experiments" in raw:
        return ""
    if str(raw.get("schema", "")).startswith("lidarkit-baseline/"):
        return "a baseline's manifest.json, not a suite: give the suite.yaml beside it"
    if "jobs" in raw and "lidarkit_version" in raw:
        suite_file = raw.get("suite_file")
        ran = f" ({suite_file})" if isinstance(suite_file, str) and suite_file else ""
        return f"bench's record of the jobs it ran (a results folder's suite.json), not a suite: give the suite file it ran{ran}"
    return ""


def _refuse_duplicate_keys(node: yaml.Node | None, path: Path) -> None:
    """A mapping that names a key twice (YAML keeps the last value silently) is a ConfigError naming both lines."""
    stack = [node]
    while stack:
        node = stack.pop()
        if isinstance(node, yaml.MappingNode):
            first: dict[str, int] = {}
            for key_node, value_node in node.value:
                if isinstance(key_node, yaml.ScalarNode):
                    line = key_node.start_mark.line + 1
                    if key_node.value in first:
                        raise ConfigError(f"duplicate key {key_node.value!r} (first on line {first[key_node.value]})",
                                          source=path, location=f"line {line}")
                    first[key_node.value] = line
                stack.append(value_node)
        elif isinstance(node, yaml.SequenceNode):
            stack.extend(node.value)


def _count_jobs(model: SuiteModel) -> int:
    """Jobs the suite expands to (datasets x grid points x seeds per method), computed without expanding."""
    total = 0
    for exp in model.experiments:
        n_datasets = 1 if exp.dataset is not None else len(exp.datasets or [])
        seeds = exp.seeds if exp.seeds is not None else model.seeds
        n_seeds = seeds if isinstance(seeds, int) else len(seeds)
        for method in exp.methods:
            n_grid = 1
            if isinstance(method, MethodSpec):
                for values in method.grid.values():
                    n_grid *= len(values)
            total += n_datasets * n_grid * max(n_seeds, 0)
    return total


def _same_value(value: Any, strings: bool = False) -> Any:
    """``value`` with whole floats as ints (``100.0`` and ``100`` make one job), recursively; ``strings``: numeric strings
    as numbers too (``"50"`` and ``50``: what the validators make of them), but not "nan" / "inf" (no JSON number)."""
    if strings and isinstance(value, str):
        try:
            number = float(value)
        except ValueError:
            return value
        if not math.isfinite(number):
            return value
        value = number
    if isinstance(value, float) and value.is_integer():
        return int(value)
    if isinstance(value, dict):
        return {k: _same_value(v, strings) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_same_value(v, strings) for v in value]
    return value


def _written_two_ways(a: Any, b: Any) -> bool:
    """True when ``a`` and ``b`` are one value with its numbers written differently (1 and 1.0, 50 and "50"), recursively.
    Two strings are one value only when equal: "1" and "1.0" are two texts to a text parameter (they were refused)."""
    if isinstance(a, str) and isinstance(b, str):
        return a == b
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_written_two_ways(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(map(_written_two_ways, a, b))
    return canonical_json(_same_value(a, strings=True)) == canonical_json(_same_value(b, strings=True))


def experiment_name(exp: Experiment, index: int) -> str:
    """The name an experiment's jobs carry: its own, else its task and its index in the suite (``odometry_2``)."""
    return exp.name or f"{exp.task}_{index}"


def _refuse_duplicates(model: SuiteModel, locator: _Locator) -> None:
    """Duplicate experiment names, methods (same name and settings), datasets or seeds would run the same jobs
    twice: a ConfigError naming the file and line."""
    def fail(what: str, loc: tuple[Any, ...]) -> None:
        raise ConfigError(what, source=locator.path, location=locator.location(loc))

    # on the names the jobs get: an explicit 'selftest_1' and the default name of experiments[1] merged their jobs
    names: dict[str, int] = {}
    for i, exp in enumerate(model.experiments):
        name = experiment_name(exp, i)
        first = names.setdefault(name, i)
        if first == i:
            continue
        if exp.name is None:
            fail(f"duplicate experiment name {name!r}: the default name of experiments[{i}] (its task and index) is the "
                 f"name of experiments[{first}]; give experiments[{i}] a name of its own", ("experiments", i))
        if model.experiments[first].name is None:
            fail(f"duplicate experiment name {name!r} (also the default name of experiments[{first}], its task and "
                 f"index): give one of them a name of its own", ("experiments", i, "name"))
        fail(f"duplicate experiment name {name!r} (also experiments[{first}])", ("experiments", i, "name"))
    for i, exp in enumerate(model.experiments):
        methods: dict[str, int] = {}
        for j, method in enumerate(exp.methods):
            m = MethodSpec(name=method) if isinstance(method, str) else method
            ident = repr((m.name, sorted(_same_value(m.params).items(), key=str), sorted(_same_value(m.grid).items(), key=str)))
            if ident in methods:
                fail(f"duplicate method {m.name!r} with the same params and grid (also methods[{methods[ident]}])",
                     ("experiments", i, "methods", j))
            methods[ident] = j
            for key, values in m.grid.items():
                reprs = [repr(_same_value(v)) for v in values]
                if len(set(reprs)) != len(reprs):
                    fail(f"grid {key!r} lists a value twice: {values}", ("experiments", i, "methods", j, "grid", key))
        if exp.datasets:
            seen_ds: dict[str, int] = {}
            for k, d in enumerate(exp.datasets):
                ident = d if isinstance(d, str) else repr(sorted(d.model_dump(exclude_none=True).items(), key=str))
                if ident in seen_ds:
                    fail(f"duplicate dataset (also datasets[{seen_ds[ident]}])", ("experiments", i, "datasets", k))
                seen_ds[ident] = k
        for seeds, loc in ((exp.seeds, ("experiments", i, "seeds")), (model.seeds, ("seeds",))):
            if isinstance(seeds, list) and len(set(seeds)) != len(seeds):
                dup = sorted({s for s in seeds if seeds.count(s) > 1})
                fail(f"duplicate seeds {dup}", loc)
            if seeds == []:  # (named here, where it is written: a suite's [] was blamed on the experiment using it)
                fail("no seeds", loc)
            if isinstance(seeds, int) and seeds < 1:
                fail(f"seeds must be >= 1 (a count) or a list, got {seeds}", loc)
            if isinstance(seeds, list) and any(s < 0 for s in seeds):
                fail(f"seeds must be >= 0, got {[s for s in seeds if s < 0]}", loc)


def load_suite(path: str | Path, *, skip_unavailable: bool = False, only_tasks: set[str] | None = None,
               max_jobs: int = MAX_JOBS) -> Suite:
    """Read, validate and expand a suite file into jobs; raise on the first problem, before anything runs.

    ``skip_unavailable``: experiments whose task module or bundled ``sample:`` dataset is not installed, and
    methods the task does not have here (an optional extra such as ``small_gicp``), are skipped (listed in
    ``Suite.skipped``) instead of refused — what ``lidarkit demo`` does. ``only_tasks`` keeps only those tasks.
    A suite expanding to more than ``max_jobs`` jobs is refused before expansion.
    """
    from lidarkit.atomic import missing_reason, resolved_path, stream_reason
    from lidarkit.bench.results import path_argument
    from lidarkit.params import is_integer

    given = path_argument(path, "path")
    try:  # a missing file named as given (resolved first, a dangling link's target was named "not found")
        os.stat(given)
    except OSError as err:
        if err.errno in (errno.ENOENT, errno.ELOOP):
            raise DataError(missing_reason(given, "suite file not found"), source=given) from None
    streamed = stream_reason(given)  # (<(cat suite.yaml) resolved to /proc/<pid>/fd/pipe:[...]: "suite file not found")
    if streamed:
        raise DataError(streamed, source=given)
    path = resolved_path(given, output=False)  # (a loop of links was a RuntimeError traceback)
    if not is_integer(max_jobs):  # ("2" failed comparing with the job count: "'>' not supported")
        raise ConfigError(f"must be an integer, got {type(max_jobs).__name__} {max_jobs!r}", source="max_jobs")
    if max_jobs < 1:
        raise ConfigError(f"must be >= 1, got {max_jobs}", source="max_jobs")
    model, locator = read_suite_file(path)
    _refuse_duplicates(model, locator)
    n_jobs = _count_jobs(model)
    if n_jobs > max_jobs:
        raise ConfigError(f"expands to {n_jobs:,} jobs, above the limit of {max_jobs:,} (split the suite, or raise "
                          "the limit with --max-jobs)", source=path)
    base_dir = path.parent
    jobs: list[Job] = []
    seen: dict[str, tuple[int, int]] = {}  # job key -> (experiment, method) indices of the method that gave it first
    # a job's spec with its numbers written one way -> (experiment, method, params) of the jobs so far
    alike: dict[str, list[tuple[int, int, dict[str, Any]]]] = {}
    skipped: list[tuple[str, str]] = []
    validated: set[str] = set()
    for i, exp in enumerate(model.experiments):
        exp_loc: tuple[Any, ...] = ("experiments", i)
        exp_name = experiment_name(exp, i)
        if only_tasks is not None and exp.task not in only_tasks:
            skipped.append((exp_name, f"task {exp.task} not selected"))
            continue
        try:
            task = get_task(exp.task)
            task.require()
        except ConfigError as err:
            if skip_unavailable and exp.task in _known_tasks():
                skipped.append((exp_name, err.reason))
                log.info("skipping experiment %s: %s", exp_name, err.reason)
                continue
            raise locator.error(err, (*exp_loc, "task")) from None

        _check(locator, (*exp_loc, "options"), task.validate_options, dict(exp.options))
        options = _options_as_read(task, exp.options)
        datasets = _experiment_datasets(exp, model, locator, exp_loc)
        resolved: list[dict[str, Any]] = []
        resolved_locs: list[tuple[Any, ...]] = []
        missing_sample = None
        for loc, spec in datasets:
            try:
                spec = resolve_option_paths(resolve_dataset(spec, base_dir), base_dir)
                if task.dataset_kinds and spec["kind"] not in task.dataset_kinds:
                    raise ConfigError(
                        f"task {exp.task!r} does not take dataset kind {spec['kind']!r}; it takes: {', '.join(task.dataset_kinds)}",
                        source="dataset",
                    )
                _check(locator, loc, task.validate_dataset, spec, options, options_loc=(*exp_loc, "options"))
            except DataError as err:
                if skip_unavailable and str(spec.get("path", "")).startswith(SAMPLE_PREFIX):
                    missing_sample = f"bundled sample {spec['path']} is not installed ({err.reason})"
                    break
                raise locator.error(err, loc) from None
            except LidarKitError as err:
                raise locator.error(err, loc) from None
            resolved.append(spec)
            resolved_locs.append(loc)
        if missing_sample is not None:
            skipped.append((exp_name, missing_sample))
            log.info("skipping experiment %s: %s", exp_name, missing_sample)
            continue
        _refuse_datasets_written_two_ways(resolved, resolved_locs, locator)

        seeds = _seeds(exp.seeds if exp.seeds is not None else model.seeds)
        installed = task.available_methods() if skip_unavailable else None
        for j, method in enumerate(exp.methods):
            method = MethodSpec(name=method) if isinstance(method, str) else method
            m_loc = (*exp_loc, "methods", j)
            if installed is not None and method.name not in installed and method.name in task.optional_methods():
                # (an optional extra absent here; any other name is validated below: a typo was "not installed", exit 0)
                reason = _not_installed(task, method, resolved[0], options, installed)
                skipped.append((f"{exp_name}: {method.name}", reason))
                log.info("skipping %s in %s: %s", method.name, exp_name, reason)
                continue
            overlap = set(method.params) & set(method.grid)
            if overlap:
                raise ConfigError(f"{', '.join(sorted(overlap))} given both in params and grid", source=path, location=locator.location(m_loc))
            for params in _grid(method):
                for spec, label in zip(resolved, distinct_labels([dataset_label(d) for d in resolved], resolved)):
                    check_key = repr((exp.task, method.name, sorted(params.items()), sorted(spec.items()), sorted(options.items())))
                    if check_key not in validated:
                        _check(locator, m_loc, task.validate, method.name, params, spec, options)
                        validated.add(check_key)
                    for seed in seeds:
                        job = Job(
                            task=exp.task,
                            experiment=exp_name,
                            dataset_name=label,
                            dataset=spec,
                            method=method.name,
                            params=params,
                            seed=int(seed),
                            options=options,
                        )
                        try:
                            key = job.key()
                        except (TypeError, ValueError) as err:  # a YAML date, .nan, ...: not plain JSON
                            raise ConfigError(f"values must be plain numbers, strings, lists and mappings ({err})",
                                              source=path, location=locator.location(m_loc)) from None
                        same = canonical_json({**job.spec(), "params": _same_value(params, strings=True)})
                        for first_i, first_j, first in alike.get(same, []):
                            # 1 and 1.0 (one key), "50" and 50 (two keys): one job written two ways
                            if canonical_json(params) != canonical_json(first) and _written_two_ways(params, first):
                                raise ConfigError(f"{job.method_label} runs the same job as experiments[{first_i}].methods"
                                                  f"[{first_j}] (a value written two ways, e.g. 1 and 1.0): give it once",
                                                  source=path, location=locator.location(m_loc))
                        if key in seen:  # (it was left out without a word: params {x: 1} beside grid {x: [1, 2]})
                            first_i, first_j = seen[key]
                            raise ConfigError(f"{job.method_label} on {label} runs the same job as experiments[{first_i}]"
                                              f".methods[{first_j}] (in params of one and a grid of the other, or in two "
                                              "grids): give it once", source=path, location=locator.location(m_loc))
                        alike.setdefault(same, []).append((i, j, params))
                        seen[key] = (i, j)
                        jobs.append(job)
    return Suite(name=model.name, path=path, jobs=jobs, description=model.description, skipped=skipped)


def _refuse_datasets_written_two_ways(specs: list[dict[str, Any]], locs: list[tuple[Any, ...]], locator: _Locator) -> None:
    """ConfigError naming file and line for two datasets of an experiment that are one dataset written two ways
    (``speed_mps: 10`` and ``10.0``, a default written out beside one left out): their jobs were merged into one without
    a word, or ran twice under two labels."""
    first: dict[str, int] = {}
    for k, spec in enumerate(specs):
        k0 = first.setdefault(_dataset_identity(spec), k)
        if k0 != k:
            a, b = specs[k0], spec
            ways = [f"{key}: {a[key]!r} and {b[key]!r} are one value" if key in a and key in b
                    else f"{key}: {a.get(key, b.get(key))!r} is its default"
                    for key in sorted(set(a) | set(b)) if key not in a or key not in b or repr(a[key]) != repr(b[key])]
            raise ConfigError(f"duplicate dataset (also {_loc_text(locs[k0][2:])}, written another way: {'; '.join(ways)}): "
                              "give it once", source=locator.path, location=locator.location(locs[k]))


def _dataset_identity(spec: dict[str, Any]) -> str:
    """A resolved dataset spec as the data it opens: its settings as its kind reads them, whole floats as ints, those
    equal to their default left out. A simulated drive's ``seed`` always counts: without one, the job's seed seeds it."""
    as_read, defaults = _dataset_settings(spec)
    kept = {key: as_read.get(key, value) for key, value in spec.items() if key == "seed" or key not in defaults}
    try:
        return canonical_json(whole_floats_as_ints(kept))
    except (TypeError, ValueError):  # (a YAML date, .nan: refused with the jobs, naming the line)
        return repr(sorted(kept.items(), key=str))


def _dataset_settings(spec: dict[str, Any]) -> tuple[dict[str, Any], set[str]]:
    """The options of ``spec`` as its kind reads them (a simulator's validated config; a reader's as written) and the
    names of those equal to the kind's default (none where the kind cannot tell: ``synthetic``, a kind that fails to
    load)."""
    import inspect

    options = dataset_options(spec)
    try:
        if spec["kind"] in ("sim_lidar", "sim_camera"):
            if spec["kind"] == "sim_lidar":
                from lidarkit.sim.lidar import LidarSimConfig as config_type, make_config
            else:
                from lidarkit.sim.street_camera import CameraSimConfig as config_type, make_camera_config as make_config
            read, default = make_config(**options).model_dump(mode="json"), config_type().model_dump(mode="json")
            read = {key: read[key] for key in options if key in read}
            return read, {key for key in read if _one_plain_value(read[key], default[key])}
        if spec["kind"] == "synthetic":
            return options, set()
        from lidarkit.io import get_reader

        params = inspect.signature(get_reader(spec["kind"])).parameters
    except (LidarKitError, TypeError, ValueError):
        return options, set()
    return options, {key for key in options if key in params and params[key].default is not inspect.Parameter.empty
                     and _one_plain_value(options[key], params[key].default)}


def _one_plain_value(a: Any, b: Any) -> bool:
    """Whether ``a`` and ``b`` are one plain value, whole floats as ints (a value that is no plain JSON is no match)."""
    try:
        return canonical_json(whole_floats_as_ints(a)) == canonical_json(whole_floats_as_ints(b))
    except (TypeError, ValueError):
        return False


def _options_as_read(task: Any, options: dict[str, Any]) -> dict[str, Any]:
    """The experiment's ``options`` (validated) with each value as the task reads it (its ``resolved_options``), the
    defaults it fills in left out: ``max_frames: 2.0`` is the integer 2 in the jobs, their results and keys, one job with
    ``max_frames: 2``."""
    resolved = task.resolved_options(dict(options))
    return {key: resolved.get(key, value) for key, value in options.items()}


def _check(locator: _Locator, loc: tuple[Any, ...], fn: Any, *args: Any, options_loc: tuple[Any, ...] | None = None) -> None:
    """Call a task validator; its errors (and a validator bug) become errors naming file, key and line (``options_loc``
    for an error about the options, e.g. a dataset check of ``pairs`` against the dataset's scans)."""
    try:
        fn(*args)
    except LidarKitError as err:
        raise locator.error(err, options_loc if options_loc is not None and err.source == "options" else loc) from None
    except Exception as err:  # noqa: BLE001 - a validator bug must still name the place
        raise ConfigError(f"{type(err).__name__}: {err}", source=locator.path, location=locator.location(loc)) from None


def _not_installed(task: Any, method: MethodSpec, dataset: dict[str, Any], options: dict[str, Any], installed: list[str]) -> str:
    """Why an optional method is skipped: the task's own refusal (the line ``lidarkit bench`` prints, with its
    ``pip install 'lidarkit[gicp]'``), else that it is not installed with the methods that are."""
    try:
        task.validate(method.name, dict(method.params), dataset, options)
    except LidarKitError as err:
        return err.reason
    except Exception:  # noqa: BLE001 - a validator bug: the plain reason below
        pass
    return f"method {method.name!r} is not installed (available: {', '.join(installed)})"


def _known_tasks() -> set[str]:
    from lidarkit.bench.tasks import available_tasks

    return set(available_tasks())


def _experiment_datasets(exp: Experiment, model: SuiteModel, locator: _Locator, exp_loc: tuple[Any, ...]) -> list[tuple[tuple[Any, ...], dict[str, Any]]]:
    if exp.dataset is not None and exp.datasets is not None:
        raise ConfigError("give either 'dataset' or 'datasets', not both", source=locator.path, location=locator.location(exp_loc))
    if exp.dataset is not None:
        entries = [((*exp_loc, "dataset"), exp.dataset)]
    elif exp.datasets:
        entries = [((*exp_loc, "datasets", k), d) for k, d in enumerate(exp.datasets)]
    else:
        raise ConfigError("experiment has no 'dataset'", source=locator.path, location=locator.location(exp_loc))
    out = []
    for loc, entry in entries:
        if isinstance(entry, str):
            if entry not in model.datasets:
                known = ", ".join(sorted(model.datasets)) or "none defined"
                raise ConfigError(f"unknown dataset {entry!r}; suite datasets: {known}", source=locator.path, location=locator.location(loc))
            spec = model.datasets[entry].model_dump(exclude_none=True)
            spec.setdefault("name", entry)
        else:
            spec = entry.model_dump(exclude_none=True)
        out.append((loc, spec))
    return out


def _grid(method: MethodSpec) -> list[dict[str, Any]]:
    if not method.grid:
        return [dict(method.params)]
    keys = list(method.grid)
    return [{**method.params, **dict(zip(keys, combo))} for combo in itertools.product(*(method.grid[k] for k in keys))]


__all__ = ["DatasetSpec", "Experiment", "MethodSpec", "Suite", "SuiteModel", "load_suite", "read_suite_file"]
