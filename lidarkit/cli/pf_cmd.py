"""``lidarkit pf DATA_DIR``: the particle-filter report's protocol (or the recorded readings) as one command."""

from __future__ import annotations

import contextlib
import logging
import math
from pathlib import Path

import numpy as np
import typer
import yaml
from rich.table import Table

from lidarkit.cli.app import app, stderr, stdout
from lidarkit.errors import ConfigError
from lidarkit.pf.config import MAX_PARTICLES, MIN_KLD_BIN, PFConfig, q_problem
from lidarkit.run_files import RUN_FILES

_D = PFConfig()

log = logging.getLogger(__name__)


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
        steps = tuple(int(s) for s in text.split(",") if s.strip())
    except ValueError:
        raise ConfigError(f"snapshot steps must be comma-separated integers, got {text!r}", source="--snapshots") from None
    if any(s < 0 for s in steps):
        raise ConfigError(f"snapshot steps must be >= 0, got {text!r}", source="--snapshots")
    if not steps:  # (',' drew no particles.png, without a word)
        raise ConfigError(f"no snapshot step in {text!r}", source="--snapshots")
    if len(set(steps)) != len(steps):  # (step 0 was drawn twice)
        raise ConfigError(f"a snapshot step is listed twice: {text!r}", source="--snapshots")
    return steps


MAX_SEEDS = 10_000


def _counts(text: str) -> list[int]:
    """``--particles``: one count or a comma-separated list, each in 1..MAX_PARTICLES."""
    try:
        values = [int(s) for s in text.split(",")]
    except ValueError:
        values = []
    if len(set(values)) != len(values):
        raise ConfigError(f"a particle count is listed twice: {text!r}", source="--particles")
    if not values or any(not 1 <= v <= MAX_PARTICLES for v in values):
        raise ConfigError(f"n_particles must be >= 1 and <= {MAX_PARTICLES} (one count or a comma-separated list), got {text!r}",
                          source="--particles")
    return values


@app.command("pf")
def pf_command(
    ctx: typer.Context,
    data_dir: Path = typer.Argument(..., help="Folder with world.dat and sensor_data.dat (Freiburg landmark data)."),
    particles: str = typer.Option(str(_D.n_particles), "--particles", "-n", help="Number of particles N, or a list '50,100,1000' (a study)."),
    seeds: int = typer.Option(1, "--seeds", help="Number of seeds (seed, seed+1, ...); > 1 or several N prints a mean ± std table."),
    protocol: str = typer.Option("default", "--protocol", help="default | report: the first report's choices (nearest landmark per particle, best particle, Q as std)."),
    likelihood: str = typer.Option(_D.likelihood, help="all: every reading of the step; nearest: the closest landmark only."),
    nearest_association: str = typer.Option(_D.nearest_association, help="nearest likelihood: known landmark id, or per_particle (no ids)."),
    estimator: str = typer.Option(_D.estimator, help="mean: weighted mean; best: highest-weight particle."),
    resampler: str = typer.Option(_D.resampler, help="multinomial | systematic | stratified | residual."),
    kernel: str = typer.Option(_D.kernel, help="point: classic particles; kalman: Kalman-particle kernels (few N; N=1 is an EKF)."),
    ess_threshold: float = typer.Option(_D.ess_threshold, help="Resample when ESS < threshold*N (>= 1: every step)."),
    roughening: float = typer.Option(_D.roughening, help="Gordon roughening constant K (0 = off)."),
    q: str = typer.Option(",".join(str(v) for v in _D.q), "--q", help="Measurement noise Q diagonal 'range,bearing'."),
    q_as: str = typer.Option(_D.q_as, "--q-as", help="Read Q as variances (a covariance, default) or standard deviations."),
    init: str = typer.Option(_D.init, help="gaussian: around the start pose; uniform: global localization over the map box, all headings."),
    augmented: bool = typer.Option(False, "--augmented", help="Augmented MCL: inject uniform particles when the short-term likelihood drops."),
    alpha_slow: float = typer.Option(_D.alpha_slow, help="Augmented MCL long-term averaging rate."),
    alpha_fast: float = typer.Option(_D.alpha_fast, help="Augmented MCL short-term averaging rate."),
    kld: bool = typer.Option(False, "--kld", help="KLD-sampling: adapt N per step (N from --particles is the initial count)."),
    kld_epsilon: float = typer.Option(_D.kld_epsilon, help="KLD error bound epsilon."),
    kld_z: float = typer.Option(_D.kld_z, help="KLD upper standard normal quantile z (2.326: 99%)."),
    kld_bin: str = typer.Option(f"{_D.kld_bin_m},{math.degrees(_D.kld_bin_rad):g}", help="KLD bin size 'metres,degrees'."),
    kld_min: int = typer.Option(_D.kld_min_n, help="KLD minimum particle count."),
    kld_max: int = typer.Option(_D.kld_max_n, help="KLD maximum particle count."),
    kld_unconverged: int = typer.Option(_D.kld_unconverged_n, help="KLD minimum count until the belief is narrow (global localization)."),
    innovation_gate: float = typer.Option(_D.innovation_gate, help="Kalman kernels: chi-square gate on each reading (9.21 = 99%; 0 = off)."),
    visible: str = typer.Option("recorded", help="Simulated readings: recorded landmark ids per step, or all landmarks every step."),
    kidnap_at: int | None = typer.Option(None, "--kidnap-at", help="Teleport the simulated robot after this step."),
    kidnap_offset: str = typer.Option("0,-5,-90", "--kidnap-offset", help="Kidnap offset 'dx_m,dy_m,dtheta_deg' (world frame)."),
    seed: int = typer.Option(0, help="First seed for the simulated data and the filter."),
    recorded: bool = typer.Option(False, "--recorded", help="Run on the recorded SENSOR readings (no ground truth); prints the NIS verdict on Q."),
    fit_q: bool = typer.Option(False, "--fit-q", help="With --recorded: fit Q to the innovations (maximum likelihood), re-run, show the NIS after."),
    out: Path | None = typer.Option(None, "--out", "-o", help="Write poses, config, metrics and plots into this folder."),
    snapshots: str = typer.Option("0,10,50,150,250,331", help="Steps for the particle-snapshot figure."),
    gif: bool = typer.Option(False, "--gif", help="Also write animation.gif (needs --out)."),
) -> None:
    """Localize with a particle filter on Freiburg landmark data and score it (MSE from step 10, APE, RPE), or run a study."""
    from lidarkit.io import open_dataset
    from lidarkit.pf.protocol import (check_filter_memory, data_files, filter_bytes_per_particle, kidnap_offset_record,
                                      most_readings_per_step, run_protocol)
    from lidarkit.pf.study import protocol_config, run_study

    from lidarkit.atomic import check_target

    check_target(out, "folder", files=RUN_FILES, replaces=RUN_FILES)
    counts = _counts(particles)
    if not 1 <= seeds <= MAX_SEEDS:
        raise ConfigError(f"must be in 1..{MAX_SEEDS}, got {seeds}", source="--seeds")
    if seed < 0:
        raise ConfigError(f"must be >= 0, got {seed}", source="--seed")
    from lidarkit.pf.study import PROTOCOLS

    study = len(counts) > 1 or seeds > 1
    _refuse_unused_options(ctx, kld=kld, augmented=augmented, kernel=kernel, kidnap_at=kidnap_at, study=study,
                           likelihood=PROTOCOLS.get(protocol, {}).get("likelihood", likelihood))  # (the report protocol's is nearest)
    # (these rules across options named "pf config"); each rate's own range is checked first, by the config: a NaN rate
    # was named in the other's error ("--alpha-slow: must be below --alpha-fast nan")
    if augmented and all(0 < a <= 1 for a in (alpha_slow, alpha_fast)) and not alpha_slow < alpha_fast:
        raise ConfigError(f"must be below --alpha-fast {alpha_fast:g}, got {alpha_slow:g}", source="--alpha-slow")
    if (kld or augmented) and kernel == "kalman":
        raise ConfigError("KLD-sampling and augmented MCL need point particles (--kernel point)", source="--kld" if kld else "--augmented")
    largest, option = max(counts), "--particles"
    if kld:  # KLD-sampling grows the set up to these counts
        for name, value in (("--kld-max", kld_max), ("--kld-unconverged", kld_unconverged)):
            if value > MAX_PARTICLES:
                raise ConfigError(f"must be <= {MAX_PARTICLES}, got {value}", source=name)
            if value > largest:
                largest, option = value, name
        for name, value in (("kld_min", kld_min), ("kld_unconverged", kld_unconverged)):
            if value > kld_max:  # (it said "pf config: kld_min_n 6000 > kld_max_n 5000"); named: the one given
                option = f"--{name.replace('_', '-')}"
                if _given(ctx, name):
                    raise ConfigError(f"{value} is above --kld-max {kld_max}", source=option)
                raise ConfigError(f"{kld_max} is below {option} {value}", source="--kld-max")
        if max(counts) > kld_max:  # (KLD-sampling's first count: 20000 ran above the 5000 of its title, without a word)
            if _given(ctx, "particles"):
                raise ConfigError(f"{max(counts)} (KLD-sampling's first count) is above --kld-max {kld_max}", source="--particles")
            raise ConfigError(f"{kld_max} is below --particles {max(counts)} (KLD-sampling's first count)", source="--kld-max")
    snapshot_steps = _steps(snapshots)  # checked whether or not there is a run folder to draw them in
    if gif and out is None:
        raise ConfigError("needs --out DIR", source="--gif")
    if _given(ctx, "snapshots") and out is None:  # (they are figures of the run folder: without one, ignored in silence)
        raise ConfigError("needs --out DIR", source="--snapshots")
    if fit_q and not recorded:
        raise ConfigError("needs --recorded", source="--fit-q")
    bin_m, bin_deg = _floats(kld_bin, 2, "--kld-bin")
    if not all(math.isfinite(v) and v >= MIN_KLD_BIN for v in (bin_m, bin_deg)):  # (1e-310: its reciprocal overflowed)
        raise ConfigError(f"both bin sizes must be finite and >= {MIN_KLD_BIN:g} (metres, degrees), got {kld_bin!r}",
                          source="--kld-bin")
    q_values = _floats(q, 2, "--q")
    problem = q_problem(q_values, PROTOCOLS.get(protocol, {}).get("q_as", q_as))  # (--protocol report reads Q as std)
    if problem:
        raise ConfigError(problem, source="--q")
    settings = dict(
        n_particles=counts[0], likelihood=likelihood, nearest_association=nearest_association, estimator=estimator,
        resampler=resampler, kernel=kernel, ess_threshold=ess_threshold, roughening=roughening, q=q_values, q_as=q_as,
        init=init, augmented=augmented, alpha_slow=alpha_slow, alpha_fast=alpha_fast, kld=kld, kld_epsilon=kld_epsilon,
        kld_z=kld_z, kld_bin_m=bin_m, kld_bin_rad=math.radians(bin_deg), kld_min_n=kld_min, kld_max_n=kld_max,
        kld_unconverged_n=kld_unconverged, innovation_gate=innovation_gate,
    )
    try:
        cfg = PFConfig.make(**settings)
    except ConfigError as err:  # a setting's error names its option, not the config field ("pf config q")
        field = str(err.source or "").removeprefix("pf config").strip()
        option = OPTION_OF.get(field, f"--{field.replace('_', '-')}") if field in settings else err.source
        raise ConfigError(err.reason, source=option) from None
    _refuse_protocol_clashes(ctx, protocol, dict(likelihood=likelihood, nearest_association=nearest_association,
                                                 estimator=estimator, q_as=q_as))
    if protocol not in PROTOCOLS:
        raise ConfigError(f"unknown protocol {protocol!r}; known: {', '.join(PROTOCOLS)}", source="--protocol")
    cfg = protocol_config(cfg, protocol)
    scenario = _scenario(visible, kidnap_at, kidnap_offset)
    data = open_dataset("landmarks", data_dir)  # loaded once: its warnings (negative range) appear once per command
    if kidnap_at is not None and kidnap_at > len(data):
        raise ConfigError(f"must be a step in 1..{len(data)} of the data, got {kidnap_at}", source="--kidnap-at")
    if not _given(ctx, "snapshots"):  # the default steps past a short recording's end are dropped without a word, and
        # its last step is drawn (a 15-step recording showed steps 0 and 10 only)
        snapshot_steps = tuple(sorted({s for s in snapshot_steps if s <= len(data)} | {len(data)}))
    elif min(snapshot_steps) > len(data):  # (the run went ahead and wrote no particles.png, exit 0)
        raise ConfigError(f"no snapshot step within 0..{len(data)} (the data's steps), got {snapshots!r}", source="--snapshots")
    # the filter plus the particle clouds kept for the figures (the run's steps are known now: a GIF keeps every other
    # one and the last); checked here to name the option, before the library checks it again naming the config field
    n_snapshots = len(_kept_steps(snapshot_steps, gif, len(data), out))
    per_particle = filter_bytes_per_particle(cfg, most_readings_per_step(data, "recorded" if recorded else visible),
                                             len(data.landmarks.positions_xy))
    check_filter_memory(largest, n_snapshots, option, per_particle)
    seed_list = list(range(seed, seed + seeds))
    if recorded:
        if len(counts) > 1 or seeds > 1:
            raise ConfigError("runs one filter: give one --particles value and --seeds 1", source="--recorded")
        simulated_only = [f"--{name.replace('_', '-')}" for name in ("visible", "kidnap_at", "kidnap_offset")
                          if _given(ctx, name)]
        if simulated_only:
            also = f" (as does {', '.join(simulated_only[1:])}, also given)" if len(simulated_only) > 1 else ""
            raise ConfigError(f"applies to the simulated readings, not to --recorded{also}", source=simulated_only[0])
        _recorded(data, cfg, seed, fit_q, out, snapshot_steps, gif)
        return
    if len(counts) > 1 or seeds > 1:
        if gif:  # (it was ignored)
            raise ConfigError("animates one run; a study (several --particles or --seeds) writes its table only", source="--gif")
        from lidarkit.progress import progress_bar

        bar, task = progress_bar(len(counts) * len(seed_list), "pf study", unit="runs")
        try:
            rows = run_study(data, counts, seed_list, config=cfg, on_run=lambda: bar.advance(task), **scenario)
        finally:
            bar.stop()
        if out is not None:  # the run folder before the table: a stdout that refuses it (> /dev/full) lost the run
            recorded = {**scenario, "kidnap_offset": kidnap_offset_record(scenario["kidnap_offset"]) if kidnap_at is not None else None}
            _write_study(rows, cfg, protocol, {**recorded, **data_files(data), "n_particles": counts, "seeds": seed_list}, out,
                         warnings=_read_warnings(data))
        _print_study(rows, cfg, protocol, kidnap_at, len(data))
        if out is not None:
            stderr().print(f"results written to {out}")
        return
    snap = _kept_steps(snapshot_steps, gif, len(data), out)
    with _step_progress(cfg, len(data), "pf run") as on_step:
        result = run_protocol(data, counts[0], seed, config=cfg, estimators=tuple(dict.fromkeys((cfg.estimator, "mean", "best"))),
                              snapshot_steps=snap, on_step=on_step, **scenario)
    if out is not None:  # the run folder before the table: a stdout that refuses it (> /dev/full) lost the run
        _write(result, out, snap_steps=snapshot_steps, warnings=_read_warnings(data))
    _print(result)
    if out is not None:
        if gif:  # after the table, into the finished folder: an interrupt while it is drawn loses the GIF alone
            _write_gif(result, out)
        stderr().print(f"results written to {out}")


def _scenario(visible: str, kidnap_at: int | None, kidnap_offset: str) -> dict:
    """The simulated scenario of ``run_protocol`` from its options, each refused naming its option (the protocol named
    its parameters: "kidnap_offset: ... dtheta_rad" for an option given in degrees)."""
    from lidarkit.pf.protocol import MAX_KIDNAP_OFFSET_M, VISIBILITY

    if visible not in VISIBILITY:
        raise ConfigError(f"must be one of {', '.join(VISIBILITY)}, got {visible!r}", source="--visible")
    if kidnap_at is not None and kidnap_at < 1:
        raise ConfigError(f"must be a step >= 1 (the robot is moved after that motion), got {kidnap_at}", source="--kidnap-at")
    dx, dy, dth = _floats(kidnap_offset, 3, "--kidnap-offset")
    if not all(math.isfinite(v) for v in (dx, dy, dth)) or max(abs(dx), abs(dy)) > MAX_KIDNAP_OFFSET_M or abs(dth) > 360:
        raise ConfigError(f"'dx_m,dy_m,dtheta_deg' must be finite with |dx|, |dy| <= {MAX_KIDNAP_OFFSET_M:g} m and "
                          f"|dtheta| <= 360 deg, got {kidnap_offset!r}", source="--kidnap-offset")
    return dict(visible=visible, kidnap_at_step=kidnap_at, kidnap_offset=(dx, dy, math.radians(dth)))


def _given(ctx: typer.Context, name: str) -> bool:
    """Whether option ``name`` was given on the command line (not left at its default)."""
    source = ctx.get_parameter_source(name)
    return source is not None and source.name == "COMMANDLINE"


#: The option of a PFConfig field whose name differs from it (the rest are --FIELD-NAME).
OPTION_OF = {"n_particles": "--particles", "kld_min_n": "--kld-min", "kld_max_n": "--kld-max", "kld_unconverged_n": "--kld-unconverged",
             "kld_bin_m": "--kld-bin", "kld_bin_rad": "--kld-bin"}


def _refuse_unused_options(ctx: typer.Context, *, kld: bool, augmented: bool, kernel: str, likelihood: str, kidnap_at: int | None,
                           study: bool) -> None:
    """An option given on the command line that the rest of the command would ignore is a ConfigError (they changed
    nothing, without a word)."""
    needs = (
        (("kld_epsilon", "kld_z", "kld_bin", "kld_min", "kld_max", "kld_unconverged"), "--kld", kld),
        (("alpha_slow", "alpha_fast"), "--augmented", augmented),
        (("innovation_gate",), "--kernel kalman", kernel == "kalman"),
        (("roughening",), "--kernel point (the Kalman kernels resample by splitting)", kernel != "kalman"),
        (("nearest_association",), "--likelihood nearest", likelihood == "nearest"),
        (("kidnap_offset",), "--kidnap-at", kidnap_at is not None),
        (("snapshots",), "one run (a study writes its table only)", not study),
    )
    for names, needed, on in needs:
        given = [f"--{name.replace('_', '-')}" for name in names if _given(ctx, name)]
        if given and not on:  # (named before the reason and in it: "--roughening: --roughening only acts with ...")
            also = f" (as does {', '.join(given[1:])}, also given)" if len(given) > 1 else ""
            raise ConfigError(f"only acts with {needed}{also}", source=given[0])


def _refuse_protocol_clashes(ctx: typer.Context, protocol: str, given: dict[str, str]) -> None:
    """An option given on the command line that the protocol sets otherwise is a ConfigError (the protocol used to
    override it without a word)."""
    from lidarkit.pf.study import PROTOCOLS

    clashes = [f"--{name.replace('_', '-')} {value}" for name, value in given.items()
               if _given(ctx, name)
               and PROTOCOLS.get(protocol, {}).get(name, value) != value]
    if clashes:
        sets = ", ".join(f"{k.replace('_', '-')} {v}" for k, v in PROTOCOLS[protocol].items())
        raise ConfigError(f"{protocol} sets {sets}; {', '.join(clashes)} conflicts with it", source="--protocol")


#: Particles from which a run shows its progress (100,000 particles take ~10 s over the report's 331 steps).
PROGRESS_FROM_PARTICLES = 100_000


@contextlib.contextmanager
def _step_progress(cfg: PFConfig, n_steps: int, label: str, runs: int = 1):
    """An ``on_step`` callback drawing the steps of ``runs`` filter runs on stderr, or None for a run too short to need
    it (a million particles ran 2 minutes without a line). A KLD run is judged by the most particles it may reach (its
    --particles is only the start)."""
    if max(cfg.n_particles, cfg.kld_max_n if cfg.kld else 0) < PROGRESS_FROM_PARTICLES:
        yield None
        return
    from lidarkit.progress import progress_bar

    bar, task = progress_bar(n_steps * runs, f"{label}, {cfg.particle_count_label()} particles", unit="steps")
    done = 0

    def on_step(_done: int, _total: int) -> None:
        nonlocal done
        done += 1
        bar.advance(task)

    try:
        yield on_step
        if done < n_steps * runs:  # fewer runs than it may take (--fit-q settled early): end at 100 %, not at "50 %, ~110 s left"
            bar.update(task, total=done, refresh=True)
    finally:
        bar.stop()


def _kept_steps(snap_steps: tuple[int, ...], gif: bool, n_steps: int, out: Path | None) -> tuple[int, ...]:
    """Steps whose particle clouds a run keeps: those of the snapshot figure and, for ``--gif``, every other step and the
    last (a 15-step recording's GIF ended at step 14); none without a run folder (they are its figures only)."""
    if out is None:
        return ()
    kept = set(snap_steps) | ({*range(0, n_steps + 1, 2), n_steps} if gif else set())
    return tuple(sorted(s for s in kept if 0 <= s <= n_steps))


def _recorded(data, cfg: PFConfig, seed: int, fit_q: bool, out: Path | None, snap_steps: tuple[int, ...], gif: bool) -> None:
    from lidarkit.pf.protocol import fit_q_recorded, run_recorded

    snap = _kept_steps(snap_steps, gif, len(data), out)
    if not fit_q:
        with _step_progress(cfg, len(data), "pf run") as on_step:
            result = run_recorded(data, None, seed, config=cfg, snapshot_steps=snap, on_step=on_step)
    else:
        with _step_progress(cfg, len(data), "pf --fit-q (up to 6 runs)", runs=6) as on_step:
            first, runs = fit_q_recorded(data, None, seed, config=cfg, on_step=on_step)
        last = runs[-1] if runs else first  # (none: the run with the given Q lost track and was not fitted)
        result = last
        if snap:  # a re-run of the last fit that keeps the particle clouds of the figures
            with _step_progress(cfg, len(data), "pf run for the snapshots") as on_step:
                result = run_recorded(data, None, seed, config=last.config, snapshot_steps=snap, warn_lost=False,  # (the fit's own warned)
                                      on_step=on_step)
        # a re-run for the snapshots: the fit's own verdict and Q (its one-round fit of its own, a Q no run used, sat
        # beside the fitted Q with nothing saying which was the answer)
        for key in ("q_verdict", "q_fit_settled", "q_fitted", "q_fit_one_round"):
            if key in last.metrics:
                result.metrics[key] = last.metrics[key]
            else:
                result.metrics.pop(key, None)
        # the run folder holds the last fit's run: the Q given and each fit are kept beside it (metrics.json, "fit_q")
        result.metrics["fit_q"] = [{"run": "given Q" if i == 0 else f"fit {i}", "q_cov": r.settings["q_cov"], "nis_mean": r.metrics["nis_mean"],
                                    "nis_fraction_below_chi2_95": r.metrics["nis_fraction_below_chi2_95"]} for i, r in enumerate([first, *runs])]
    if out is not None:  # the run folder before the tables: a stdout that refuses them (> /dev/full) lost the run
        _write(result, out, snap_steps=snap_steps, warnings=_read_warnings(data))
    if not fit_q:
        _print(result)
        stdout().print(result.metrics["q_verdict"]["text"])
    else:
        _print(first)
        stdout().print(("before: " if runs else "") + first.metrics["q_verdict"]["text"])
        table = Table(title="--fit-q: maximum-likelihood Q from the innovations, filter re-run")
        for col in ("run", "Q range variance [m²]", "Q bearing variance [rad²]", "NIS mean", "NIS < 5.99"):
            table.add_column(col, justify="right")
        for i, r in enumerate([first, *runs]):
            qc = r.settings["q_cov"]
            table.add_row("given Q" if i == 0 else f"fit {i}", f"{qc[0][0]:.4g}", f"{qc[1][1]:.4g}", f"{r.metrics['nis_mean']:.3f}",
                          f"{r.metrics['nis_fraction_below_chi2_95']:.3f}")
        stdout().print(table)
        if runs:
            stdout().print("after: " + last.metrics["q_verdict"]["text"])
    if out is not None:
        if gif:
            _write_gif(result, out)
        stderr().print(f"results written to {out}")


def _print_study(rows, cfg: PFConfig, protocol: str, kidnap_at: int | None, n_steps: int) -> None:
    from lidarkit.pf.study import RECOVERED_WITHIN_STEPS

    seeds = rows[0].seeds
    title = (f"particle filter study ({protocol} protocol, {cfg.likelihood}"
             f"{'/' + cfg.nearest_association if cfg.likelihood == 'nearest' else ''}, estimator {cfg.estimator}, "
             f"init {cfg.init}{', augmented MCL' if cfg.augmented else ''}{', KLD' if cfg.kld else ''}), seeds {seeds[0]}..{seeds[-1]}")
    table = Table(title=title)
    for col in ("N", "MSE [m²] mean ± std", "mean N", "localized", "lost", "s/run"):
        table.add_column(col, justify="right")
    if kidnap_at is not None:
        table.add_column("recovered", justify="right")
    table.caption = (f"MSE: position, from step 10, over {len(seeds)} seeds (std ddof=0); mean N: particles per step; "
                     "localized: seeds with error < 0.5 m at >= 95% of the steps from 50 on; lost: seeds with a step beyond "
                     "the chi-square 99.9% gate after the first convergence" + (f"; recovered: seeds back below 0.5 m for good within {RECOVERED_WITHIN_STEPS} "
                                                    "steps of the kidnap" if kidnap_at is not None else ""))
    not_judged = sum(k is None for r in rows for k in r.recovered)
    if not_judged:  # (they counted as not recovered: a kidnap at the last step gave "0 / 3")
        table.caption += (f"; {not_judged} run(s) left out of recovered: not back by the last step, only {n_steps - kidnap_at} "
                          f"steps after the kidnap (the window is {RECOVERED_WITHIN_STEPS})")
    for r in rows:
        judged = [f for f in r.localized if np.isfinite(f)]  # NaN: no step from 50 on to judge (a shorter recording)
        localized = f"{sum(f >= 0.95 for f in judged)} / {len(judged)}" if judged else "n/a"
        cells = [str(r.n_particles), f"{r.mse_mean:.4g} ± {r.mse_std:.3g}", f"{np.mean(r.mean_count):.0f}",
                 localized, f"{r.lost_seeds} / {len(seeds)}", f"{np.mean(r.runtime_s):.3f}"]
        if kidnap_at is not None:
            recovered = [k for k in r.recovered if k is not None]
            cells.append(f"{sum(recovered)} / {len(recovered)}" if recovered else "n/a")
        table.add_row(*cells)
    stdout().print(table)


def _read_warnings(data) -> list[str]:
    """What the landmark reader warned of (a file cut inside its last number), for the run's ``warnings``: it was
    logged only, and a run on a cut recording recorded nothing."""
    return [str(w) for w in getattr(data, "reader_warnings", None) or ()]


def _write_study(rows, cfg: PFConfig, protocol: str, scenario: dict, out: Path, *, warnings: list[str] = ()) -> None:
    from lidarkit import atomic

    with atomic.run_folder(out, replaces=RUN_FILES) as tmp:
        _write_study_files(rows, cfg, protocol, scenario, tmp, warnings=warnings)


def _write_study_files(rows, cfg: PFConfig, protocol: str, scenario: dict, out: Path, *, warnings: list[str] = ()) -> None:
    from lidarkit import atomic
    from lidarkit.eval.report import write_json

    from lidarkit.provenance import code_version

    # the filter settings of every row: n_particles is the study's list of counts (it said the first alone)
    settings = {**cfg.model_dump(mode="json"), "n_particles": [r.n_particles for r in rows]}
    atomic.write_text(out / "config.yaml", yaml.safe_dump({"lidarkit_version": code_version(), "pf": settings, "protocol": protocol,
                                                            "scenario": {k: (list(v) if isinstance(v, tuple) else v) for k, v in scenario.items()}},
                                                           sort_keys=False))
    write_json({"protocol": protocol, "rows": [r.to_dict() for r in rows], **({"warnings": list(warnings)} if warnings else {})},
               out / "study.json")


def _row(table: Table, label: str, value: str) -> None:
    table.add_row(label, value)


def _print(result) -> None:
    m = result.metrics
    table = Table(title=f"particle filter ({result.settings['mode']}), N={result.config.particle_count_label()}, seed {result.settings['seed']}")
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
        if m.get("n_readings_before_convergence"):  # (a uniform start's first steps were counted as lost track)
            start = m["nis_from_step"]
            table.caption = (f"NIS from step {start}, after the filter first converged: the {m['n_readings_before_convergence']} "
                             f"readings of steps 1-{start - 1} are left out of the NIS and the lost count")
    if result.n_particles is not None and (result.config.kld or result.n_particles.min() != result.n_particles.max()):
        n = result.n_particles[1:]
        _row(table, "particles per step (mean / min / max)", f"{n.mean():.0f} / {n.min()} / {n.max()}")
    if result.injected is not None and result.config.augmented:
        _row(table, "particles injected (augmented MCL)", str(int(result.injected.sum())))
    if result.ground_truth is not None:
        err = result.position_error_m()
        _row(table, "position error at the last step [m]", f"{err[-1]:.3f}")
    if "kidnap_recovery" in m:  # the study's "recovered", for one run
        kr = m["kidnap_recovery"]
        if kr["recovered"] is None:  # (a kidnap at the last step read "no, never")
            verdict = f"n/a: only {result.n_steps - result.settings['kidnap_at_step']} steps after the kidnap (the window is {kr['within_steps']})"
        elif kr["steps_to_recover"] is None:
            verdict = "no, never"
        else:
            verdict = f"{'yes' if kr['recovered'] else 'no'}, {kr['steps_to_recover']} steps"
        _row(table, f"kidnap recovered (< 0.5 m for good, <= {kr['within_steps']} steps)", verdict)
    _row(table, "filter runtime [s]", f"{result.runtime_s:.3f}")
    _row(table, "resamples / steps", f"{int(result.resampled.sum())} / {result.n_steps}")
    if result.n_weight_resets:
        _row(table, "weight resets (all likelihoods non-finite)", str(result.n_weight_resets))
    stdout().print(table)


def _write(result, out: Path, *, snap_steps: tuple[int, ...], warnings: list[str] = ()) -> None:
    """The run folder, all or nothing, without animation.gif (:func:`_write_gif` adds it once the folder is in place);
    ``warnings``: what the readers warned of, in metrics.json."""
    from lidarkit import atomic

    with atomic.run_folder(out, replaces=RUN_FILES) as tmp:
        _write_files(result, tmp, snap_steps=snap_steps, warnings=warnings)


def _write_gif(result, out: Path) -> None:
    """animation.gif into the finished run folder ``out``, on its own (atomically). Drawing it takes 30-50 s after a run
    of 0.07 s: written with the other files, a Ctrl-C while it was drawn threw away the whole folder and the table; now
    it leaves the folder whole, without the GIF, and says so (exit 130)."""
    from lidarkit.lifetime import Interrupted, interrupt_handled
    from lidarkit.pf import plots
    from lidarkit.progress import progress_bar

    bar, task = progress_bar(len(result.snapshots), "animation.gif")
    try:
        plots.animate(result, out / "animation.gif", on_frame=lambda: bar.advance(task))
    except (KeyboardInterrupt, Interrupted) as stop:
        interrupt_handled()
        bar.stop()
        what = stop if isinstance(stop, Interrupted) else "SIGINT"
        stderr().print(f"interrupted by {what} while drawing animation.gif: {out} holds the whole run without it "
                       "(run the command again with --gif for the animation)", soft_wrap=True)
        raise typer.Exit(getattr(stop, "exit_code", 130)) from None
    finally:
        bar.stop()


def _write_files(result, out: Path, *, snap_steps: tuple[int, ...], warnings: list[str] = ()) -> None:
    from lidarkit import atomic
    from lidarkit.eval.report import write_json
    from lidarkit.pf import plots

    from lidarkit.provenance import code_version

    atomic.write_text(out / "config.yaml", yaml.safe_dump({"lidarkit_version": code_version(), "pf": result.config.model_dump(mode="json"),
                                                            "run": result.settings}, sort_keys=False))
    write_json({**result.to_dict(), **({"warnings": list(warnings)} if warnings else {})}, out / "metrics.json")
    est = result.trajectory("estimate")
    est.to_kitti(out / "poses_kitti.txt")
    est.to_tum(out / "poses_tum.txt")
    result.trajectory("dead_reckoning").to_tum(out / "dead_reckoning_tum.txt")
    if result.ground_truth is not None:
        result.trajectory("ground_truth").to_tum(out / "ground_truth_tum.txt")
    plots.plot_trajectory(result, out / "trajectory.png")
    steps = [s for s in snap_steps if s in result.snapshots]
    beyond = [s for s in snap_steps if s not in result.snapshots]
    if beyond:
        log.warning("--snapshots %s: past the last step (%d), left out of particles.png", ",".join(map(str, beyond)), result.n_steps)
    if steps:
        plots.plot_snapshots(result, out / "particles.png", steps)
    if result.n_particles is not None and (result.config.kld or result.config.augmented):
        errors = {"position error": result.position_error_m()} if result.ground_truth is not None else None
        plots.plot_particle_count({"particles": result.n_particles}, out / "particles_per_step.png", errors_m=errors,
                                  mark_step=result.settings.get("kidnap_at_step"))
