"""``lidarkit pf DATA_DIR``: the particle-filter report's protocol (or the recorded readings) as one command."""

from __future__ import annotations

from pathlib import Path

import typer
import yaml
from rich.table import Table

from lidarkit.cli.app import app, stderr, stdout
from lidarkit.errors import ConfigError
from lidarkit.pf.config import PFConfig

_D = PFConfig()


def _floats(text: str, n: int, option: str) -> tuple[float, ...]:
    try:
        values = tuple(float(s) for s in text.split(","))
    except ValueError:
        values = ()
    if len(values) != n:
        raise ConfigError(f"expected {n} comma-separated numbers, got {text!r}", source=option)
    return values


def _steps(text: str) -> tuple[int, ...]:
    try:
        return tuple(int(s) for s in text.split(",") if s.strip())
    except ValueError:
        raise ConfigError(f"snapshot steps must be comma-separated integers, got {text!r}", source="--snapshots") from None


@app.command("pf")
def pf_command(
    data_dir: Path = typer.Argument(..., help="Folder with world.dat and sensor_data.dat (Freiburg landmark data)."),
    particles: int = typer.Option(_D.n_particles, "--particles", "-n", help="Number of particles N."),
    likelihood: str = typer.Option(_D.likelihood, help="all: every reading of the step; nearest: the closest landmark only."),
    estimator: str = typer.Option(_D.estimator, help="mean: weighted mean; best: highest-weight particle."),
    resampler: str = typer.Option(_D.resampler, help="multinomial | systematic | stratified | residual."),
    kernel: str = typer.Option(_D.kernel, help="point: classic particles; kalman: Kalman-particle kernels (few N)."),
    ess_threshold: float = typer.Option(_D.ess_threshold, help="Resample when ESS < threshold*N (>= 1: every step)."),
    roughening: float = typer.Option(_D.roughening, help="Gordon roughening constant K (0 = off)."),
    q: str = typer.Option(",".join(str(v) for v in _D.q), "--q", help="Measurement noise Q diagonal 'range,bearing'."),
    q_as: str = typer.Option(_D.q_as, "--q-as", help="Read Q as variances (a covariance, default) or standard deviations."),
    seed: int = typer.Option(0, help="Seed for the simulated data and the filter."),
    recorded: bool = typer.Option(False, "--recorded", help="Run on the recorded SENSOR readings (no ground truth)."),
    out: Path | None = typer.Option(None, "--out", help="Write poses, config, metrics and plots into this folder."),
    snapshots: str = typer.Option("0,10,50,150,250,331", help="Steps for the particle-snapshot figure."),
    gif: bool = typer.Option(False, "--gif", help="Also write animation.gif (needs --out)."),
) -> None:
    """Localize with a particle filter on Freiburg landmark data and score it (MSE from step 10, APE, RPE)."""
    from lidarkit.io import open_dataset
    from lidarkit.pf.protocol import run_protocol, run_recorded

    from lidarkit.atomic import check_target

    check_target(out, "folder")
    data = open_dataset("landmarks", data_dir)
    cfg = PFConfig.make(
        n_particles=particles, likelihood=likelihood, estimator=estimator, resampler=resampler, kernel=kernel,
        ess_threshold=ess_threshold, roughening=roughening, q=_floats(q, 2, "--q"), q_as=q_as,
    )
    if gif and out is None:
        raise ConfigError("--gif needs --out DIR", source="--gif")
    snap = set(_steps(snapshots))
    if gif:
        snap |= set(range(0, len(data) + 1, 2))
    snap = tuple(sorted(s for s in snap if 0 <= s <= len(data)))
    if recorded:
        result = run_recorded(data, particles, seed, config=cfg, snapshot_steps=snap)
    else:
        result = run_protocol(data, particles, seed, config=cfg, estimators=("mean", "best"), snapshot_steps=snap)
    _print(result)
    if out is not None:
        _write(result, out, snap_steps=_steps(snapshots), gif=gif)
        stderr().print(f"results written to {out}")


def _row(table: Table, label: str, value: str) -> None:
    table.add_row(label, value)


def _print(result) -> None:
    m = result.metrics
    table = Table(title=f"particle filter ({result.settings['mode']}), N={result.config.n_particles}, seed {result.settings['seed']}")
    table.add_column("metric")
    table.add_column("value", justify="right")
    if result.ground_truth is not None:
        for name, v in m["mse_m2"].items():
            _row(table, f"position MSE from step {m['mse_start']} ({name}) [m²]", f"{v:.4f}")
        _row(table, "position MSE dead reckoning [m²]", f"{m['mse_dead_reckoning_m2']:.4f}")
        for name, stats in m.get("ape_translation_m", {}).items():
            _row(table, f"APE translation RMSE ({name}) [m]", f"{stats['rmse']:.4f}")
        for name, stats in m.get("rpe_translation_m", {}).items():
            _row(table, f"RPE translation RMSE, 1 step ({name}) [m]", f"{stats['rmse']:.4f}")
    else:
        _row(table, "NIS mean (chi²(2) expects 2.0)", f"{m['nis_mean']:.3f}")
        _row(table, "NIS fraction < 5.99 (expects 0.95)", f"{m['nis_fraction_below_chi2_95']:.3f}")
        _row(table, "dead-reckoning NIS mean (S = Q)", f"{m['dead_reckoning_nis_mean']:.3f}")
        r = m["residual_std_at_estimate"]
        _row(table, "reading residual std at estimate (range m, bearing rad)", f"{r['range_m']:.3f}, {r['bearing_rad']:.3f}")
        d = m["estimate_vs_dead_reckoning_m"]
        _row(table, "estimate vs dead reckoning (mean / max) [m]", f"{d['mean']:.3f} / {d['max']:.3f}")
    _row(table, "filter runtime [s]", f"{result.runtime_s:.3f}")
    _row(table, "resamples / steps", f"{int(result.resampled.sum())} / {result.n_steps}")
    if result.n_weight_resets:
        _row(table, "weight resets (all likelihoods non-finite)", str(result.n_weight_resets))
    stdout().print(table)


def _write(result, out: Path, *, snap_steps: tuple[int, ...], gif: bool) -> None:
    from lidarkit import atomic
    from lidarkit.eval.report import write_json
    from lidarkit.pf import plots

    with atomic.run_folder(out) as tmp:
        _write_files(result, tmp, snap_steps=snap_steps, gif=gif)


def _write_files(result, out: Path, *, snap_steps: tuple[int, ...], gif: bool) -> None:
    from lidarkit import atomic
    from lidarkit.eval.report import write_json
    from lidarkit.pf import plots

    atomic.write_text(out / "config.yaml", yaml.safe_dump({"pf": result.config.model_dump(mode="json"), "run": result.settings}, sort_keys=False))
    write_json(result.to_dict(), out / "metrics.json")
    est = result.trajectory("estimate")
    est.to_kitti(out / "poses_kitti.txt")
    est.to_tum(out / "poses_tum.txt")
    result.trajectory("dead_reckoning").to_tum(out / "dead_reckoning_tum.txt")
    if result.ground_truth is not None:
        result.trajectory("ground_truth").to_tum(out / "ground_truth_tum.txt")
    plots.plot_trajectory(result, out / "trajectory.png")
    steps = [s for s in snap_steps if s in result.snapshots]
    if steps:
        plots.plot_snapshots(result, out / "particles.png", steps)
    if gif:
        plots.animate(result, out / "animation.gif")
