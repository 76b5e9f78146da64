"""Particle filter on the Freiburg landmark data: the report's MSE-vs-N table, the few-particles ablation, speed.

    .venv/bin/python benchmarks/pf_particles.py [--data ../shared/data] [--variant robot_mapping_stachniss]
        [--seeds 10] [--workers 2] [--out benchmarks/results/pf] [--quick]

1. Table: N = 50, 100, 200, ..., 1000 x likelihood (all, nearest) x resampler (4 schemes) x estimator
   (weighted mean, highest weight), mean +- std of the position MSE from step 10 over the seeds, plus
   runtime per run; also the report's own choices (nearest landmark associated per particle, best
   particle, Q read as std) for comparison with its table.
2. Ablation at N=100 against N=10000 on the same seeds (same simulated data per seed).
3. Speed: full 331-step runs at N=1000 and N=100000 against a plain vectorized numpy filter
   (``plain_reference_pf`` below) timed in the same process, same data.
Writes pf_particles.md, pf_particles.json, mse_vs_n.png (atomically) into --out.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

# One BLAS thread for both filters: on a shared 2-core machine OpenBLAS threads spin against other jobs
# and make small matrix-vector products 100x slower (the plain reference uses w @ p).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from lidarkit.bench.machine import describe_machine, machine_info  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
DEFAULT_DATA = REPO.parent / "shared" / "data"
N_VALUES = [50, 100, 200, 300, 400, 500, 600, 700, 800, 900, 1000]
RESAMPLERS = ["systematic", "stratified", "residual", "multinomial"]
LIKELIHOODS = ["all", "nearest"]
REFERENCE = {"all/mean N=100": 0.062, "all/mean N=500": 0.052, "all/mean N=1000": 0.051, "nearest/mean N=100": 0.092,
             "nearest/mean N=1000": 0.067, "dead reckoning": 1.25}
REPORT_TABLE = {50: 29.4, 100: 0.045, 200: 0.043, 300: 0.06, 400: 0.106, 500: 0.09, 600: 0.066, 700: 0.077, 800: 0.1,
                900: 0.091, 1000: 1.6}
ABLATION = [
    ("point, systematic every step (baseline)", dict()),
    ("point, systematic, ESS < N/2", dict(ess_threshold=0.5)),
    ("point, residual, ESS < N/2", dict(ess_threshold=0.5, resampler="residual")),
    ("point, roughening K=0.1", dict(roughening=0.1)),
    ("point, Liu-West regularization h=0.4", dict(regularization=0.4)),
    ("point, moment matching (mean+cov)", dict(moment_matching="mean_cov")),
    ("point, antithetic motion noise", dict(antithetic=True)),
    ("point, antithetic + moment matching + ESS < N/2", dict(antithetic=True, moment_matching="mean_cov", ess_threshold=0.5)),
    ("kalman kernels, ESS < N/2", dict(kernel="kalman", ess_threshold=0.5)),
    ("kalman kernels, every step", dict(kernel="kalman")),
]

_DATA = None


def _data(path: str):
    global _DATA
    if _DATA is None or str(_DATA.root) != path:
        from lidarkit.io.landmarks import LandmarkData

        _DATA = LandmarkData(path, negative_range="keep")
    return _DATA


def _run(job: tuple) -> dict:
    """One protocol run in a worker: returns MSE per estimator, dead-reckoning MSE, runtime."""
    from lidarkit.pf.protocol import run_protocol

    path, n, seed, kwargs = job
    r = run_protocol(_data(path), n, seed, estimators=("mean", "best"), with_ape_rpe=False, **kwargs)
    return {"mse": r.metrics["mse_m2"], "dr": r.metrics["mse_dead_reckoning_m2"], "runtime_s": r.runtime_s}


def plain_reference_pf(landmarks_xy, odometry, offsets, lm_index, z, n, q_cov, motion_std, seed):
    """A plain vectorized numpy particle filter: (N, 3) float64 particles, rng.normal per step,
    np.hypot / np.arctan2, weights by exp, weighted mean, systematic resampling with searchsorted."""
    rng = np.random.default_rng(seed)
    p = np.column_stack([rng.normal(0, np.sqrt(2), n), rng.normal(0, np.sqrt(2), n), rng.normal(0.1, np.sqrt(0.1), n)])
    w = np.full(n, 1.0 / n)
    qi = np.linalg.inv(q_cov)
    est = np.zeros((len(odometry) + 1, 3))
    for t, (r1, tr, r2) in enumerate(odometry):
        noise = rng.normal(0.0, motion_std, size=(n, 3))
        r1n, trn, r2n = r1 + noise[:, 0], tr + noise[:, 1], r2 + noise[:, 2]
        p[:, 0] += trn * np.cos(p[:, 2] + r1n)
        p[:, 1] += trn * np.sin(p[:, 2] + r1n)
        p[:, 2] += r1n + r2n
        a, b = offsets[t], offsets[t + 1]
        if b > a:
            lm = landmarks_xy[lm_index[a:b]]
            dx = lm[None, :, 0] - p[:, None, 0]
            dy = lm[None, :, 1] - p[:, None, 1]
            er = z[None, a:b, 0] - np.hypot(dx, dy)
            eb = z[None, a:b, 1] - (np.arctan2(dy, dx) - p[:, None, 2])
            eb = (eb + np.pi) % (2 * np.pi) - np.pi
            ll = -0.5 * (qi[0, 0] * er**2 + 2 * qi[0, 1] * er * eb + qi[1, 1] * eb**2).sum(axis=1)
            w = np.exp(ll - ll.max())
            w /= w.sum()
        est[t + 1, :2] = w @ p[:, :2]
        est[t + 1, 2] = np.arctan2(w @ np.sin(p[:, 2]), w @ np.cos(p[:, 2]))
        positions = (rng.random() + np.arange(n)) / n
        idx = np.minimum(np.searchsorted(np.cumsum(w), positions), n - 1)
        p = p[idx]
        w = np.full(n, 1.0 / n)
    return est


def _agg(values: list[float]) -> tuple[float, float]:
    return float(np.mean(values)), float(np.std(values))


def table_jobs(path: str, seeds: list[int], n_values: list[int]) -> list[tuple]:
    jobs = []
    for lk in LIKELIHOODS:
        for rs in RESAMPLERS:
            for n in n_values:
                for s in seeds:
                    jobs.append((path, n, s, dict(likelihood=lk, resampler=rs)))
    # the report's choices: nearest landmark compared with each particle's own nearest, Q as std
    for n in n_values:
        for s in seeds:
            jobs.append((path, n, s, dict(likelihood="nearest", nearest_association="per_particle", q_as="std")))
            jobs.append((path, n, s, dict(q_as="std")))
    return jobs


def speed(data, seeds: list[int], n: int, repeats: int) -> dict:
    """Min / median wall time of full runs: lidarkit ParticleFilter vs the plain reference, same simulated data."""
    from lidarkit.pf import PFConfig, make_filter
    from lidarkit.pf.models import resolve_q
    from lidarkit.pf.protocol import run_filter, simulate

    q = resolve_q((1.0, 0.1), "variance")
    sim = simulate(data, np.random.default_rng(seeds[0]), q)
    r = sim.readings
    ours, plain, mse_ours, mse_plain = [], [], [], []
    for k in range(repeats):
        pf = make_filter(data.landmarks.positions_xy, PFConfig.make(n_particles=n), k)
        out = run_filter(pf, sim.odometry_noisy, r)
        ours.append(out["runtime_s"])
        mse_ours.append(float(np.mean(np.sum((out["estimates"]["mean"][10:, :2] - sim.ground_truth[10:, :2]) ** 2, axis=1))))
        t0 = time.perf_counter()
        est = plain_reference_pf(data.landmarks.positions_xy, sim.odometry_noisy, r.offsets, r.landmark_index, r.z, n, q,
                                 np.array([0.01, 0.1, 0.01]), k)
        plain.append(time.perf_counter() - t0)
        mse_plain.append(float(np.mean(np.sum((est[10:, :2] - sim.ground_truth[10:, :2]) ** 2, axis=1))))
    return {
        "n_particles": n,
        "repeats": repeats,
        "lidarkit_s": {"min": min(ours), "median": float(np.median(ours))},
        "plain_s": {"min": min(plain), "median": float(np.median(plain))},
        "speedup_min": min(plain) / min(ours),
        "speedup_median": float(np.median(plain) / np.median(ours)),
        "mse_lidarkit": float(np.mean(mse_ours)),
        "mse_plain": float(np.mean(mse_plain)),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA)
    ap.add_argument("--variant", default="robot_mapping_stachniss")
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1))
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "pf")
    ap.add_argument("--quick", action="store_true", help="few N values, 3 seeds, small speed runs (smoke test)")
    ap.add_argument("--speed-only", action="store_true", help="re-measure only the speed section of an existing result")
    args = ap.parse_args(argv)
    if args.workers < 1 or args.seeds < 1:
        ap.error(f"--workers and --seeds must be >= 1, got {args.workers} and {args.seeds}")

    from lidarkit.lifetime import Interrupted, handle_signals

    try:
        with handle_signals():  # SIGINT / SIGTERM: one line, the workers stopped, nothing half-written
            return _main(args)
    except Interrupted as stop:
        print(f"pf_particles: interrupted by {stop}; no result written", file=sys.stderr)
        return stop.exit_code


def _main(args: argparse.Namespace) -> int:
    from lidarkit import atomic
    from lidarkit.io.landmarks import LandmarkData
    from lidarkit.pf.plots import plot_mse_vs_n

    path = str(args.data / "pf" / args.variant)
    data = LandmarkData(path)
    seeds = list(range(3 if args.quick else args.seeds))
    n_values = [50, 100, 1000] if args.quick else N_VALUES
    info = {"command": " ".join([Path(sys.executable).name, *sys.argv]), "date_utc": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"),
            "machine": machine_info(), "data": f"pf/{args.variant}", "seeds": seeds}
    t_start = time.perf_counter()
    if args.speed_only:
        payload = json.loads((args.out / "pf_particles.json").read_text())
        payload["speed"] = [speed(data, seeds, 1000, 20), speed(data, seeds, 100000, 3)]
        payload["speed_measured"] = {"command": info["command"], "date_utc": info["date_utc"], "machine": info["machine"]}
        atomic.write_text(args.out / "pf_particles.json", json.dumps(payload, indent=1))
        atomic.write_text(args.out / "pf_particles.md", markdown(payload, [int(n) for n in next(iter(payload["table"].values()))]))
        print((args.out / "pf_particles.md").read_text())
        return 0

    # 1. table + 2. ablation (process pool)
    jobs = table_jobs(path, seeds, n_values)
    abl_n, ref_n = 100, 10000
    abl_jobs = [(path, abl_n, s, kw) for _, kw in ABLATION for s in seeds] + [(path, ref_n, s, {}) for s in seeds]
    abl_jobs += [(path, 20, s, dict(kernel="kalman", ess_threshold=0.5)) for s in seeds]
    from lidarkit.bench.executors import stop_pool
    from lidarkit.lifetime import init_worker

    # workers die with this process (SIGTERM to it left them waiting for work that never came)
    pool = ProcessPoolExecutor(max_workers=args.workers, initializer=init_worker, initargs=(os.getpid(),))
    try:
        results = list(pool.map(_run, jobs + abl_jobs, chunksize=4))
    finally:  # interrupted or failed: the workers are stopped now instead of finishing their jobs
        stop_pool(pool)
    table_res, abl_res = results[: len(jobs)], results[len(jobs):]

    rows: dict[str, dict] = {}
    for job, res in zip(jobs, table_res):
        _, n, _, kw = job
        if "q_as" in kw:
            prefix = "report choices: nearest per-particle, Q as std" if kw.get("likelihood") == "nearest" else "all / systematic, Q as std"
            for est in ("mean", "best"):
                cell = rows.setdefault(f"{prefix} / {est}", {}).setdefault(n, {"mse": [], "rt": []})
                cell["mse"].append(res["mse"][est])
                cell["rt"].append(res["runtime_s"])
            continue
        for est in ("mean", "best"):
            label = f"{kw['likelihood']} / {kw['resampler']} / {est}"
            cell = rows.setdefault(label, {}).setdefault(n, {"mse": [], "rt": []})
            cell["mse"].append(res["mse"][est])
            cell["rt"].append(res["runtime_s"])
    dr = [r["dr"] for j, r in zip(jobs, table_res) if j[1] == n_values[0] and j[3] == dict(likelihood="all", resampler="systematic")]

    table = {label: {str(n): {"mse_mean": _agg(c["mse"])[0], "mse_std": _agg(c["mse"])[1], "runtime_s": float(np.mean(c["rt"]))}
                     for n, c in sorted(cells.items())} for label, cells in rows.items()}

    abl = {}
    k = 0
    for label, kw in ABLATION:
        vals = abl_res[k : k + len(seeds)]
        k += len(seeds)
        abl[label] = {"n": abl_n, "config": kw, "mse": [v["mse"]["mean"] for v in vals], "runtime_s": float(np.mean([v["runtime_s"] for v in vals]))}
    ref_vals = abl_res[k : k + len(seeds)]
    k += len(seeds)
    kp20 = abl_res[k : k + len(seeds)]
    abl["kalman kernels N=20, ESS < N/2"] = {"n": 20, "config": dict(kernel="kalman", ess_threshold=0.5), "mse": [v["mse"]["mean"] for v in kp20],
                                             "runtime_s": float(np.mean([v["runtime_s"] for v in kp20]))}
    ref_mse = [v["mse"]["mean"] for v in ref_vals]
    ref_mean = float(np.mean(ref_mse))
    for entry in abl.values():
        m = np.asarray(entry["mse"])
        entry["mse_mean"] = float(m.mean())
        entry["ratio_to_n10000"] = float(m.mean() / ref_mean)
        entry["paired_excess_std"] = float(np.std(m - np.asarray(ref_mse)) / np.sqrt(len(m)))
    reference_n10000 = {"n": ref_n, "mse": ref_mse, "mse_mean": ref_mean, "runtime_s": float(np.mean([v["runtime_s"] for v in ref_vals]))}

    # 3. speed (serial, after the pool is gone)
    speeds = [speed(data, seeds, 1000, 3 if args.quick else 20), speed(data, seeds, 20000 if args.quick else 100000, 1 if args.quick else 3)]
    info["wall_time_s"] = time.perf_counter() - t_start

    payload = {**info, "reference_figures": REFERENCE, "report_table": REPORT_TABLE, "dead_reckoning_mse": _agg(dr), "table": table,
               "ablation": abl, "ablation_reference": reference_n10000, "speed": speeds}
    args.out.mkdir(parents=True, exist_ok=True)
    atomic.write_text(args.out / "pf_particles.json", json.dumps(payload, indent=1))
    series = {}
    for label in ("all / systematic / mean", "all / systematic / best", "nearest / systematic / mean", "nearest / systematic / best",
                  "all / systematic, Q as std / mean"):
        if label in table:
            ns = [int(n) for n in table[label]]
            series[label] = (ns, [table[label][str(n)]["mse_mean"] for n in ns], [table[label][str(n)]["mse_std"] for n in ns])
    plot_mse_vs_n(series, args.out / "mse_vs_n.png", reference={"dead reckoning (ours)": _agg(dr)[0], "N=10000 all/mean": ref_mean},
                  title=f"Freiburg {args.variant}: position MSE vs N (mean ± std over {len(seeds)} seeds)")
    atomic.write_text(args.out / "pf_particles.md", markdown(payload, n_values))
    print((args.out / "pf_particles.md").read_text())
    return 0


def markdown(p: dict, n_values: list[int]) -> str:
    m = p["machine"]
    lines = [
        "# Particle filter: MSE vs number of particles (Freiburg landmark data)",
        "",
        f"- command: `{p['command']}`",
        f"- date (UTC): {p['date_utc']}; wall time {p['wall_time_s']:.0f} s",
        f"- machine: {describe_machine(m)}",
        f"- data: `{p['data']}`; protocol: ground truth = clean odometry from (0,0,0), odometry noise std (0.01, 0.1, 0.01), "
        "readings of the recorded landmarks simulated with Q = diag(1, 0.1) read as a covariance (unless noted), "
        f"position MSE from step 10; seeds {p['seeds'][0]}..{p['seeds'][-1]} (each seed: its own noisy odometry and readings, shared by every N)",
        f"- dead reckoning (noisy odometry) MSE: {p['dead_reckoning_mse'][0]:.2f} ± {p['dead_reckoning_mse'][1]:.2f} m² "
        f"(issue reference: {p['reference_figures']['dead reckoning']} m²)",
        "",
        "## MSE [m²], mean ± std over seeds (likelihood / resampler / estimator); last column: runtime per run at N=1000",
        "",
        "| configuration | " + " | ".join(f"N={n}" for n in n_values) + " | s/run |",
        "|---|" + "---|" * (len(n_values) + 1),
    ]
    for label, cells in p["table"].items():
        vals = [f"{cells[str(n)]['mse_mean']:.3f} ± {cells[str(n)]['mse_std']:.3f}" if str(n) in cells else "" for n in n_values]
        rt = cells.get(str(n_values[-1]), {}).get("runtime_s", float("nan"))
        lines.append(f"| {label} | " + " | ".join(vals) + f" | {rt:.3f} |")
    lines.append("| report's table (one run each) | " + " | ".join(str(p["report_table"].get(n, "")) for n in n_values) + " | |")
    lines += ["", "Issue reference figures (other noise realizations): " + ", ".join(f"{k}: {v}" for k, v in p["reference_figures"].items()), ""]
    ref = p["ablation_reference"]
    lines += [
        f"## Few particles vs the large-N limit (N=100 unless noted; reference N={ref['n']} point particles, all/systematic/mean: "
        f"{ref['mse_mean']:.4f} m², {ref['runtime_s']:.2f} s/run)",
        "",
        "| configuration | MSE mean [m²] | ratio to N=10000 | ± (paired SE) | s/run |",
        "|---|---|---|---|---|",
    ]
    for label, e in p["ablation"].items():
        suffix = "" if e["n"] == 100 else f" (N={e['n']})"
        lines.append(f"| {label}{suffix} | {e['mse_mean']:.4f} | {e['ratio_to_n10000']:.3f} | "
                     f"{e['paired_excess_std'] / ref['mse_mean']:.3f} | {e['runtime_s']:.3f} |")
    sm = p.get("speed_measured")
    when = f" (re-measured {sm['date_utc']} on {describe_machine(sm['machine'])}: `{sm['command']}`)" if sm else ""
    lines += ["", f"## Speed: full 331-step run (`all` likelihood, weighted mean, systematic every step), same data, same process{when}", "",
              "| N | lidarkit min / median [s] | plain numpy reference min / median [s] | speed-up (min, median) | MSE lidarkit / plain [m²] |",
              "|---|---|---|---|---|"]
    for s in p["speed"]:
        lines.append(f"| {s['n_particles']} | {s['lidarkit_s']['min']:.4f} / {s['lidarkit_s']['median']:.4f} | "
                     f"{s['plain_s']['min']:.4f} / {s['plain_s']['median']:.4f} | {s['speedup_min']:.2f}x, {s['speedup_median']:.2f}x | "
                     f"{s['mse_lidarkit']:.4f} / {s['mse_plain']:.4f} |")
    lines += ["", "![MSE vs N](mse_vs_n.png)", ""]
    return "\n".join(lines)


if __name__ == "__main__":
    from lidarkit.cli import run_script

    run_script(main)
