"""``pf``: the particle-filter report's protocol on Freiburg landmark data (``lidarkit.pf`` run_protocol).

Method ``particle_filter``; its params are the filter's config fields (``n_particles``, ``likelihood``,
``estimator``, ``resampler``, ``ess_threshold``, ``roughening``, ...), validated by ``PFConfig.make``.
Options: ``visible`` (``recorded`` | ``all``), ``mse_start`` (first step scored). The job seed drives
both the simulated readings and the filter, so jobs with the same seed and different N see the same data.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from lidarkit.bench.jobs import Job
from lidarkit.bench.tasks import Metric, Task, TaskOutput, WholeInt, import_module_for_task
from lidarkit.bench.tasks._datasets import check_reader_options, open_dataset_spec, options_model
from lidarkit.errors import ConfigError

METHODS = ("particle_filter",)


class PFOptions(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)
    visible: str = "recorded"
    mse_start: WholeInt = Field(10, ge=0)  # (YAML's true was step 1)


def _pf_api() -> tuple[Any, Any]:
    """``(PFConfig, run_protocol)`` from the package, or its public submodules while the package exports nothing."""
    pf = import_module_for_task("pf", "lidarkit.pf")
    config_cls, run_protocol = getattr(pf, "PFConfig", None), getattr(pf, "run_protocol", None)
    if config_cls is None or run_protocol is None:
        config_cls = import_module_for_task("pf", "lidarkit.pf.config").PFConfig
        run_protocol = import_module_for_task("pf", "lidarkit.pf.protocol").run_protocol
    return config_cls, run_protocol


class ParticleFilterTask(Task):
    description = "landmark particle filter, report protocol (position MSE, APE, runtime)"
    dataset_kinds = ("landmarks",)
    metrics = (
        Metric("mse_m2", "position MSE [m²]"),
        Metric("ape_rmse_m", "APE RMSE [m]"),
        Metric("mse_dead_reckoning_m2", "dead-reckoning MSE [m²]"),
        Metric("filter_time_s", "filter time [s]", kind="speed"),
        Metric("hz", "steps/s", kind="speed", better="higher"),
    )
    sweep_plots = (("n_particles", "mse_m2"),)

    def require(self) -> None:
        _pf_api()

    def available_methods(self) -> list[str] | None:
        return list(METHODS)

    def validate_options(self, options: dict[str, Any]) -> None:
        opts = options_model(PFOptions, options, "pf")
        from lidarkit.pf.protocol import VISIBILITY

        if opts.visible not in VISIBILITY:
            raise ConfigError(f"visible must be one of {', '.join(VISIBILITY)}, got {opts.visible!r}", source="options")

    def resolved_options(self, options: dict[str, Any]) -> dict[str, Any]:
        """The options with their defaults (``visible``, ``mse_start``) written out."""
        self.validate_options(options)
        return PFOptions(**options).model_dump(mode="json")

    def validate_dataset(self, dataset: dict[str, Any], options: dict[str, Any]) -> None:
        check_reader_options(dataset)
        mse_start = PFOptions(**options).mse_start
        data = open_dataset_spec(dataset)  # (a few hundred steps: read at once) the steps the MSE is taken over
        # run_protocol's rule: T steps give poses 0..T, the MSE from pose T on is one pose's (T itself was refused here);
        # past it every job failed at its end, after the whole filter run
        if mse_start > len(data):
            raise ConfigError(f"mse_start {mse_start} is not below the data's {len(data)} steps plus one (its poses are 0..{len(data)})",
                              source="options")

    def validate(self, method: str, params: dict[str, Any], dataset: dict[str, Any], options: dict[str, Any]) -> None:
        if method not in METHODS:
            raise ConfigError(f"unknown pf method {method!r}; known: {', '.join(METHODS)}", source="method")
        config_cls, _ = _pf_api()
        from lidarkit.pf.protocol import check_config_memory

        check_config_memory(config_cls.make(**params))  # refused when the suite loads, not in every job

    def run(self, job: Job) -> TaskOutput:
        config_cls, run_protocol = _pf_api()
        options = options_model(PFOptions, job.options, "pf")  # (a pinned spec re-run: one line, not pydantic's dump)
        config = config_cls.make(**job.params)
        data = open_dataset_spec(job.dataset)
        result = run_protocol(data, config.n_particles, job.seed, config=config, visible=options.visible, mse_start=options.mse_start)
        m = result.metrics
        estimator = config.estimator
        ape = (m.get("ape_translation_m") or {}).get(estimator) or {}
        n_steps = int(result.n_steps)
        metrics = {
            "mse_m2": float(m["mse_m2"][estimator]),
            "mse_dead_reckoning_m2": float(m["mse_dead_reckoning_m2"]),
            "filter_time_s": float(result.runtime_s),
            "hz": n_steps / result.runtime_s if result.runtime_s > 0 else float("nan"),
        }
        if "rmse" in ape:
            metrics["ape_rmse_m"] = float(ape["rmse"])
        est_xy = np.asarray(result.estimate, dtype=float)[:, :2]
        gt_xy = np.asarray(result.ground_truth, dtype=float)[:, :2]
        errors = np.linalg.norm(est_xy - gt_xy, axis=1)
        series = {
            "trajectory_xy": {"ref": gt_xy.round(4).tolist(), "est": est_xy.round(4).tolist()},
            "error_over_time": {"t": np.arange(len(errors), dtype=float).tolist(), "error": errors.round(6).tolist(), "label": "position error [m]",
                                "t_label": "step"},
        }
        return TaskOutput(metrics=metrics, series=series, info={"run": result.to_dict(), "metric_alignment": {"ape_rmse_m": "unaligned"}})
