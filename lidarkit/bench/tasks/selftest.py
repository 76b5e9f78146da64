"""``selftest``: cheap, dependency-free jobs that exercise the harness (tests, overhead benchmark, demo fallback).

Methods: ``random_walk`` (seeded drifting estimate of a seeded ground-truth path: APE-like metrics, a
trajectory, an error curve and a fake RMSE history), ``sleep`` (waits), ``fail`` (raises), ``burn``
(fixed numpy work, for overhead measurements).
"""

from __future__ import annotations

import logging
import time
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from lidarkit.bench.datasets import dataset_options
from lidarkit.bench.jobs import Job
from lidarkit.bench.tasks import Metric, Task, TaskOutput
from lidarkit.errors import ConfigError, validation_problems

log = logging.getLogger(__name__)


class _Params(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class RandomWalkParams(_Params):
    steps: int = Field(60, ge=2, le=100_000)
    noise_m: float = Field(0.05, ge=0.0)


class SleepParams(_Params):
    seconds: float = Field(0.1, ge=0.0, le=3600.0)
    log_warning: str | None = Field(None, description="log this as a WARNING (tests warning capture)")


class FailParams(_Params):
    message: str = "selftest failure"


class BurnParams(_Params):
    size: int = Field(200, ge=1, le=5000)
    repeats: int = Field(10, ge=1)


METHODS: dict[str, type[_Params]] = {
    "random_walk": RandomWalkParams,
    "sleep": SleepParams,
    "fail": FailParams,
    "burn": BurnParams,
}


def selftest_config(method: str, **params: Any) -> _Params:
    """Validated params for a selftest method; ConfigError lists known methods / params."""
    if method not in METHODS:
        raise ConfigError(f"unknown selftest method {method!r}; known: {', '.join(sorted(METHODS))}", source="method")
    model = METHODS[method]
    try:
        return model(**params)
    except ValidationError as err:
        known = ", ".join(model.model_fields)
        problems = validation_problems(err)
        raise ConfigError(f"{problems} (params of {method!r}: {known})", source=f"method {method}") from None


def run_selftest(method: str, params: dict[str, Any], seed: int) -> TaskOutput:
    """The job function of every selftest method (module level, so it is callable without the harness)."""
    config = selftest_config(method, **params)
    if isinstance(config, SleepParams):
        if config.log_warning:
            log.warning("%s", config.log_warning)
        time.sleep(config.seconds)
        return TaskOutput(metrics={"slept_s": config.seconds})
    if isinstance(config, FailParams):
        raise RuntimeError(config.message)
    if isinstance(config, BurnParams):
        rng = np.random.default_rng(seed)
        a = rng.standard_normal((config.size, config.size))
        total = 0.0
        for _ in range(config.repeats):
            a = np.tanh(a @ a.T / config.size)
            total += float(a.sum())
        return TaskOutput(metrics={"checksum": total})
    assert isinstance(config, RandomWalkParams)
    return _random_walk(config, seed)


def _random_walk(config: RandomWalkParams, seed: int) -> TaskOutput:
    t_s = np.arange(config.steps) * 0.1
    ref_xy = np.column_stack([np.linspace(0.0, 20.0, config.steps), 3.0 * np.sin(t_s / 2.0)])
    rng = np.random.default_rng(seed)
    drift_xy = np.cumsum(rng.normal(0.0, config.noise_m, size=(config.steps, 2)), axis=0)
    est_xy = ref_xy + drift_xy
    errors_m = np.linalg.norm(est_xy - ref_xy, axis=1)
    rmse_history = (config.noise_m + np.exp(-np.arange(8) / 2.0)).tolist()
    return TaskOutput(
        metrics={
            "ape_rmse_m": float(np.sqrt(np.mean(errors_m**2))),
            "final_error_m": float(errors_m[-1]),
        },
        series={
            "trajectory_xy": {"ref": ref_xy.round(4).tolist(), "est": est_xy.round(4).tolist()},
            "error_over_time": {"t": t_s.round(4).tolist(), "error": errors_m.round(6).tolist(), "label": "position error [m]"},
            "rmse_history": rmse_history,
        },
        info={"frames": config.steps},
    )


class SelfTestTask(Task):
    description = "harness self-test jobs (sleep, fail, burn, random_walk)"
    dataset_kinds = ("synthetic",)
    metrics = (
        Metric("ape_rmse_m", "APE RMSE [m]"),
        Metric("final_error_m", "final error [m]"),
        Metric("slept_s", "slept [s]", kind="speed"),
        Metric("checksum", "checksum", better="higher"),
    )
    sweep_plots = (("noise_m", "ape_rmse_m"),)

    def available_methods(self) -> list[str] | None:
        return sorted(METHODS)

    def validate_dataset(self, dataset: dict[str, Any], options: dict[str, Any]) -> None:
        """Its jobs read nothing of the dataset: an option in it is a typo (``foo: 1`` passed; other tasks taking
        ``synthetic`` may read theirs, so the kind itself takes any)."""
        unknown = sorted(dataset_options(dataset))
        if unknown:
            raise ConfigError(f"unknown option(s) {', '.join(unknown)} for dataset kind 'synthetic' of task 'selftest'; "
                              "it takes none (only a name)", source="dataset")

    def validate(self, method: str, params: dict[str, Any], dataset: dict[str, Any], options: dict[str, Any]) -> None:
        selftest_config(method, **params)

    def run(self, job: Job) -> TaskOutput:
        return run_selftest(job.method, job.params, job.seed)
