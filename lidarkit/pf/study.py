"""Studies instead of single runs: the protocol over several particle counts x seeds, mean +- std per count.

``PROTOCOLS["report"]`` is the first report's exact choice set (each particle compares the nearest reading
with its own nearest landmark, the highest-weight particle is the estimate, Q = (1, 0.1) read as standard
deviations); ``"default"`` changes nothing. Every run of a study shares the loaded data (its warnings are
logged once), and per-seed "filter lost" warnings are summed into the study instead of logged per run.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from collections.abc import Callable
from typing import Any

import numpy as np

from lidarkit.errors import ConfigError
from lidarkit.params import is_integer
from lidarkit.pf.config import PFConfig

log = logging.getLogger(__name__)

PROTOCOLS: dict[str, dict[str, Any]] = {
    "default": {},
    "report": {"likelihood": "nearest", "nearest_association": "per_particle", "estimator": "best", "q_as": "std"},
}
LOCALIZED_TOL_M = 0.5  # a step counts as localized when the position error is below this
LOCALIZED_FROM_STEP = 50
RECOVERED_WITHIN_STEPS = 40  # a kidnapped filter counts as recovered when it gets back within this many steps


def protocol_config(config: PFConfig, protocol: str) -> PFConfig:
    """``config`` with the named protocol's choices applied (ConfigError for an unknown name)."""
    if protocol not in PROTOCOLS:
        raise ConfigError(f"unknown protocol {protocol!r}; known: {', '.join(PROTOCOLS)}", source="protocol")
    return config.replace(**PROTOCOLS[protocol]) if PROTOCOLS[protocol] else config


def localized_fraction(error_m: np.ndarray, start: int = LOCALIZED_FROM_STEP, tol_m: float = LOCALIZED_TOL_M) -> float:
    """Fraction of the steps from ``start`` on with position error below ``tol_m``."""
    e = np.asarray(error_m)[start:]
    return float((e < tol_m).mean()) if len(e) else float("nan")


def steps_to_recover(error_m: np.ndarray, kidnap_step: int, tol_m: float = LOCALIZED_TOL_M, relapse_m: float = 1.0) -> int | None:
    """Steps after ``kidnap_step`` until the error is below ``tol_m`` for good: the first such step after which the
    error never again reaches ``relapse_m``; None if the filter never gets there."""
    e = np.asarray(error_m)
    bad = np.flatnonzero(e[kidnap_step:] >= relapse_m)
    first_ok_region = kidnap_step + (int(bad[-1]) + 1 if len(bad) else 0)
    ok = np.flatnonzero(e[first_ok_region:] < tol_m)
    return int(first_ok_region + ok[0] - kidnap_step) if len(ok) else None


def kidnap_recovery(error_m: np.ndarray, kidnap_step: int) -> dict[str, Any]:
    """One run's kidnap figures: ``steps_to_recover`` (None: not by the last step) and ``recovered`` (within
    RECOVERED_WITHIN_STEPS, the study's count). ``recovered`` is None, not judged, for a run that ends less than the
    window after the kidnap without having recovered (a kidnap at the last step read "no, never")."""
    k = steps_to_recover(error_m, kidnap_step)
    if k is not None and k <= RECOVERED_WITHIN_STEPS:
        recovered: bool | None = True
    elif len(error_m) - 1 - kidnap_step < RECOVERED_WITHIN_STEPS:  # the window runs past the last step
        recovered = None
    else:
        recovered = False
    return {"steps_to_recover": k, "recovered": recovered, "within_steps": RECOVERED_WITHIN_STEPS}


@dataclass
class StudyRow:
    """One particle count over the seeds: per-seed MSE [m^2] (from step 10), mean particle count, runtime."""

    n_particles: int
    seeds: list[int]
    mse_m2: list[float]
    mean_count: list[float]
    runtime_s: list[float]
    lost_seeds: int = 0
    localized: list[float] = field(default_factory=list)  # fraction of steps >= 50 with error < 0.5 m, per seed
    recovered_in: list[int | None] = field(default_factory=list)  # kidnap runs: steps to recover per seed
    recovered: list[bool | None] = field(default_factory=list)  # kidnap runs: kidnap_recovery's "recovered" per seed

    @property
    def mse_mean(self) -> float:
        return float(np.mean(self.mse_m2))

    @property
    def mse_std(self) -> float:
        """Population std over the seeds (ddof=0, as in the benchmark tables)."""
        return float(np.std(self.mse_m2))

    def to_dict(self) -> dict[str, Any]:
        return {"n_particles": self.n_particles, "seeds": self.seeds, "mse_m2": self.mse_m2, "mse_mean": self.mse_mean,
                "mse_std": self.mse_std, "mean_count": self.mean_count, "runtime_s": self.runtime_s,
                "lost_seeds": self.lost_seeds, "localized_fraction": self.localized, "recovered_in_steps": self.recovered_in,
                "recovered": self.recovered}


def run_study(data, particles: list[int], seeds: list[int], *, config: PFConfig | None = None,
              on_run: Callable[[], None] | None = None, **protocol_kwargs: Any) -> list[StudyRow]:
    """``run_protocol`` for every particle count x seed; one :class:`StudyRow` per count. ``on_run``: called after
    each run (progress)."""
    from lidarkit.pf.protocol import check_config_memory, run_protocol

    if not particles or not seeds:
        raise ConfigError("a study needs at least one particle count and one seed", source="study")
    for name, values in (("particles", particles), ("seeds", seeds)):  # (a repeated seed gave mse_std 0.0 over one run twice)
        odd = [v for v in values if not is_integer(v)]
        if odd:  # (50.5 ran as 50 and seed 1.5 as 1: one run four times, after the repeat check had passed)
            raise ConfigError(f"each value must be an integer, got {odd[0]!r}", source=name)
        if len(set(values)) != len(values):
            raise ConfigError(f"each value must be listed once, got {list(values)}", source=name)
    cfg = config if config is not None else PFConfig.make()
    # every count checked before the first run (20,000,000 failed on the bound after every N=300 run had gone)
    try:
        configs = [cfg.replace(n_particles=int(n)) for n in particles]
    except ConfigError as err:
        raise ConfigError(err.reason, source="particles") from None
    try:
        check_config_memory(max(configs, key=lambda c: c.n_particles), data=data if hasattr(data, "step_offsets") else None,
                            visible=protocol_kwargs.get("visible", "recorded"))
    except ConfigError as err:
        raise ConfigError(err.reason, source="particles") from None
    kidnap = protocol_kwargs.get("kidnap_at_step")
    rows = []
    for n in particles:
        row = StudyRow(int(n), [int(s) for s in seeds], [], [], [], 0)
        for s in seeds:
            r = run_protocol(data, int(n), int(s), config=cfg, with_ape_rpe=False, warn_lost=False, **protocol_kwargs)
            row.mse_m2.append(float(r.metrics["mse_m2"][cfg.estimator]))
            row.mean_count.append(float(r.n_particles[1:].mean()))
            row.runtime_s.append(r.runtime_s)
            row.lost_seeds += int(len(r.lost_after_convergence) > 0)  # (a uniform start's convergence is no lost track)
            err = r.position_error_m()
            row.localized.append(localized_fraction(err))
            if kidnap is not None:
                kr = r.metrics["kidnap_recovery"]
                row.recovered_in.append(kr["steps_to_recover"])
                row.recovered.append(kr["recovered"])
            if on_run is not None:
                on_run()
        rows.append(row)
    lost = sum(r.lost_seeds for r in rows)
    if lost:
        log.warning("filter lost (best particle beyond the chi-square 99.9%% gate) in %d of %d runs", lost, len(particles) * len(seeds))
    return rows


__all__ = ["PROTOCOLS", "RECOVERED_WITHIN_STEPS", "StudyRow", "kidnap_recovery", "localized_fraction", "protocol_config", "run_study", "steps_to_recover"]
