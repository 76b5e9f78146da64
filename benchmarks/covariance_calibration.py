"""Calibration of the registration covariances: NEES against the true error on simulated pairs with known noise.

Pairs come from :class:`lidarkit.sim.scan_pairs.ScanPairs` (fresh 2 cm range noise on both scans, a perturbed
initial guess, frames along the path). Every variant registers each pair with its raw (uncalibrated) ``censi``
covariance; the error ``xi = se3_log(T_true inv(T_est))`` is scored against it: NEES ``xi^T Sigma^-1 xi`` (6 for a
calibrated covariance) and the share inside the chi-square(6) 95 % bound (12.59).

1. Training (``--train``, street seeds 0, 2, 4, 6 and 12-15 by default, 200 draws each, one frame pair per draw): per
   variant the calibration of ``covariance_fit.py`` over the pooled draws of all seeds: per-axis gains of the result's
   point-to-surface step (where it predicts the error), a variance factor ``f_j`` and a systematic sigma ``b_j`` of
   what the step leaves, the largest closed-form variance per axis (beyond it a factor does not shrink), and one
   coverage scalar ``c`` that puts 94.5 % of the pooled training NEES inside the 95 % bound (or their mean at 5 when
   heavy tails would push it lower) (``lidarkit.registration.covariance.CALIBRATION``). The leave-one-seed-out NEES
   (each training seed scored with the calibration learned on the others) are reported as the training-side estimate
   of the held-out spread. For comparison, from the same draws: the block factors (translation, rotation) and the
   previous calibration (the same without the step term).
2. Check (``--check``, scenes and seeds not used for training): the calibration applied unchanged. References
   measured on the same pairs: Open3D's ``get_information_matrix_from_point_clouds`` (times the known range variance)
   for the Open3D point-to-plane result, small_gicp's Hessian (inverse, moved to the left/target-frame convention)
   for small_gicp's result. The corridor rows also count how often the weakest direction is named "translation
   along x" (the corridor axis) and the ratio of the calibrated covariance along the axis to across it. Open ground
   (``open``: flat ground and a few far objects, several weak directions) is checked too, without a target.

Both steps score only the draws the variant reports converged (:func:`converged_only`): a covariance describes a
converged alignment, and a result flagged otherwise is one a user discards (the odometry runner keeps the previous
motion instead). Flagged draws are counted apart, as are draws without a covariance. The corridor's direction names
count every draw, converged or not, with a covariance or not (a variant's degeneracy summary names the weakest
direction when it returns no covariance too), the along / across ratios every draw with a covariance.

Raw draws are cached per (scene, seed, variant, draws) under ``<out>/draws/`` so the tables can be re-rendered
(``_f<n>``: training or check runs of ``--train-frames n`` / ``--check-frames n``, one frame pair per draw when ``n > draws``; ``_feat``: with the
per-pair features of :func:`collect`; ``_pose``: :func:`pose_features` replayed on a cache, see
``covariance_features.py``).

    .venv/bin/python benchmarks/covariance_calibration.py   # training street 0, 2, 4, 6, 12-15; check street 1, 3, 5, 7, 8,
                                                             # 9, 10, 11, corridor 1 and open 1; 200 draws each, one frame pair per draw
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from lidarkit.atomic import write_text
from lidarkit.bench.machine import describe_machine, machine_info
from lidarkit.geometry import se3_inverse, se3_log, so3_exp
from lidarkit.registration import available_icp, get_icp
from lidarkit.registration.covariance import AxisCalibration, adjoint, safe_inverse, twist_turn
from lidarkit.sim.scan_pairs import ScanPairs

sys.path.insert(0, str(Path(__file__).resolve().parent))
from covariance_fit import (  # noqa: E402,F401 - re-exported for covariance_features.py and covariance_odometry.py
    CHI2_6_95, MIN_MEAN_NEES, STEP_MIN_CORRELATION, TARGET_INSIDE, apply_all, block_factors, fit_calibration, nees_values, scaled,
)

REPO = Path(__file__).resolve().parents[1]
VARIANTS = ("vanilla", "ground_filtered", "open3d_point_to_point", "open3d_point_to_plane", "open3d_gicp", "small_gicp", "kiss", "genz")
AXES = ("tx", "ty", "tz", "rx", "ry", "rz")


def open3d_reference(pair, T_est: np.ndarray, range_noise_m: float, max_distance_m: float = 1.0) -> np.ndarray:
    """Open3D's information matrix (rotation first, unitless) as a left/target-frame covariance in m and rad."""
    import open3d as o3d

    src = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pair.source_xyz))
    dst = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pair.target_xyz))
    info = np.asarray(o3d.pipelines.registration.get_information_matrix_from_point_clouds(src, dst, max_distance_m, T_est))
    order = [3, 4, 5, 0, 1, 2]
    return range_noise_m**2 * safe_inverse(info[np.ix_(order, order)])


def small_gicp_reference(pair, T_est: np.ndarray) -> np.ndarray:
    """small_gicp's inverse Hessian (right perturbation, rotation first) as a left/target-frame covariance."""
    import small_gicp

    out = small_gicp.align(pair.target_xyz, pair.source_xyz, T_est, registration_type="GICP", downsampling_resolution=0.25,
                           max_correspondence_distance=1.0, num_threads=2, max_iterations=1)
    order = [3, 4, 5, 0, 1, 2]
    cov_right = safe_inverse(np.asarray(out.H)[np.ix_(order, order)])
    Ad = adjoint(T_est)
    return Ad @ cov_right @ Ad.T


#: per-pair features stored with the draws: observable without ground truth (the variant's own result, the size of
#: the correction it applied to the initial guess, and the final correspondences scored at one common inlier distance)
RESULT_FEATURES = ("fitness", "rmse", "n_correspondences", "iterations", "converged")
POSE_FEATURES = ("correction_t", "correction_r", "fit1", "rmse1", "n_matched", "n_eff", "plane_rms", "thickness", "sigma_ratio",
                 "eig_min", "eig_ratio", "logdet_raw")
FEATURE_SUFFIX = "feat"
FEATURE_DISTANCE_M = 1.0


def pose_features(source_xyz: np.ndarray, target_xyz: np.ndarray, T_est: np.ndarray, init_T: np.ndarray, range_noise_m: float,
                  raw_cov: np.ndarray | None = None) -> dict:
    """Features of a registered pair that need no ground truth: the correction applied to the guess
    (``se3_log(T_est inv(init_T))``, m and rad), and the final correspondences within ``FEATURE_DISTANCE_M`` scored
    the way the covariance sees them (public functions of ``degeneracy``/``covariance``, not the assessment): share
    and RMS of the matches, matched and effective (1 m voxel) counts, the point-to-surface residual RMS, the mean
    surface thickness, the residual sigma over the range noise (the censi residual variance estimate), the smallest
    eigenvalue of the normal matrix and its ratio to the largest, and the log-determinant of the raw covariance."""
    from lidarkit.geometry import transform_points
    from lidarkit.registration.covariance import effective_observations
    from lidarkit.registration.degeneracy import matched_constraints, normal_matrix
    from lidarkit.registration.neighbors import NearestNeighbors

    corr = se3_log(T_est @ se3_inverse(init_T))
    out = {"correction_t": float(np.linalg.norm(corr[:3])), "correction_r": float(np.linalg.norm(corr[3:]))}
    aligned = transform_points(T_est, source_xyz)
    dist2, index = NearestNeighbors(target_xyz, backend="scipy", workers=1).query(aligned)
    inlier = dist2 <= FEATURE_DISTANCE_M**2
    n = int(inlier.sum())
    out.update(fit1=n / max(len(source_xyz), 1), rmse1=float(np.sqrt(dist2[inlier].mean())) if n else float("nan"), n_matched=float(n))
    if n < 3:
        out.update({k: float("nan") for k in POSE_FEATURES if k not in out})
        return out
    matched, matched_index = aligned[inlier], index[inlier]
    pick, M, thickness = matched_constraints(matched, target_xyz, matched_index, return_thickness=True)
    p, q = matched[pick], target_xyz[matched_index[pick]]
    r = np.einsum("nij,nj->ni", M, p - q)
    dof = float(np.trace(M, axis1=1, axis2=2).sum())
    d_s = p - T_est[:3, 3]
    d_s /= np.linalg.norm(d_s, axis=1, keepdims=True)
    d_t = q / np.linalg.norm(q, axis=1, keepdims=True)
    Ms, Mt = np.einsum("nij,nj->ni", M, d_s), np.einsum("nij,nj->ni", M, d_t)
    unit_var = float((Ms * Ms).sum() + (Mt * Mt).sum())
    w = np.linalg.eigvalsh(normal_matrix(p, M))
    out.update(n_eff=float(effective_observations(matched, 1.0)), plane_rms=float(np.sqrt((r * r).sum() / max(dof, 1.0))),
               thickness=float(np.sqrt(np.mean(thickness))), sigma_ratio=float(np.sqrt((r * r).sum() / max(unit_var, 1e-12))) / range_noise_m,
               eig_min=float(w[0]), eig_ratio=float(w[0] / w[-1]) if w[-1] > 0 else 0.0,
               logdet_raw=float(np.linalg.slogdet(raw_cov)[1]) if raw_cov is not None else float("nan"))
    return out


#: frames per run: draw i uses frame pair i mod (N_FRAMES - 1), so 200 draws are 40 frame pairs x 5 draws
N_FRAMES = 41


def collect(scene: str, seed: int, draws: int, name: str, cache: Path, log, features: bool = False, n_frames: int = N_FRAMES) -> dict:
    """``draws`` registrations of one variant on one scene/seed with the raw covariance (cached). ``n_frames`` >
    ``draws``: every draw its own frame pair (a longer path through a longer scene of the same seed)."""
    frames_tag = "" if n_frames == N_FRAMES else f"_f{n_frames}"
    path = cache / f"{scene}_s{seed}_{name}_{draws}{frames_tag}{'_' + FEATURE_SUFFIX if features else ''}.npz"
    if path.exists():
        d = np.load(path, allow_pickle=False)
        if "converged" in d.files:  # (caches from before the convergence flag are drawn again)
            return {k: d[k] for k in d.files}
    pairs = ScanPairs(scene, seed=seed, n_frames=n_frames)
    icp = get_icp(name, calibrated_covariance=False)
    errors, covs, steps, refs, weak, feats, index, converged, weak_without = [], [], [], [], [], [], [], [], []
    failed, t0 = 0, time.perf_counter()
    for i in range(draws):
        pair = pairs.draw(i)
        res = icp.align(pair.source_xyz, pair.target_xyz, init_T=pair.init_T)
        if res.covariance is None:  # no covariance: too few points left or a fallback (ground removal in a corridor)
            failed += 1
            weak_without.append(res.degeneracy.weakest_name)  # its degeneracy summary still names the weakest direction
            continue
        errors.append(se3_log(pair.T_target_source @ se3_inverse(res.T_target_source)))
        covs.append(res.covariance)
        steps.append(res.surface_step)
        converged.append(bool(res.converged))
        weak.append(res.degeneracy.weakest_name)
        index.append(i)
        if features:
            f = {"fitness": res.fitness, "rmse": res.rmse, "n_correspondences": res.n_correspondences, "iterations": res.iterations,
                 "converged": float(res.converged)}
            f.update(pose_features(pair.source_xyz, pair.target_xyz, res.T_target_source, pair.init_T, pairs.range_noise_m, res.covariance))
            feats.append([f[k] for k in RESULT_FEATURES + POSE_FEATURES])
        if name == "open3d_point_to_plane":
            refs.append(open3d_reference(pair, res.T_target_source, pairs.range_noise_m))
        elif name == "small_gicp":
            refs.append(small_gicp_reference(pair, res.T_target_source))
    out = {"errors": np.array(errors).reshape(-1, 6), "covs": np.array(covs).reshape(-1, 6, 6), "steps": np.array(steps).reshape(-1, 6),
           "converged": np.array(converged, dtype=bool), "weakest": np.array(weak, dtype="U64"),
           "weakest_without_covariance": np.array(weak_without, dtype="U64"),
           "refs": np.array(refs).reshape(-1, 6, 6), "failed": np.array(failed), "seconds_per_pair": np.array((time.perf_counter() - t0) / draws), "index": np.array(index)}
    if features:
        out["features"] = np.array(feats, dtype=np.float64).reshape(-1, len(RESULT_FEATURES + POSE_FEATURES))
        out["feature_names"] = np.array(RESULT_FEATURES + POSE_FEATURES, dtype="U32")
    cache.mkdir(parents=True, exist_ok=True)
    np.savez(path, **out)
    log(f"{scene} seed {seed} {name}: {draws} draws, {failed} without covariance, {int((~out['converged']).sum())} flagged not converged, "
        f"{float(out['seconds_per_pair']):.2f} s/pair")
    return out


def converged_only(run: dict) -> dict:
    """The draws of ``run`` whose result the variant reports converged (``flagged``: how many it does not): a covariance
    describes a converged alignment, and a result flagged otherwise (an iteration limit reached, the acceptance gate's
    fitness or correspondence count missed) is one a user discards, as the runner does in odometry."""
    keep = np.asarray(run["converged"], dtype=bool)
    out = dict(run)
    for key in ("errors", "covs", "steps", "refs", "weakest", "index", "features"):  # refs: only for the reference variants
        if key in run and len(run[key]) == len(keep):
            out[key] = run[key][keep]
    out["flagged"] = np.array(int((~keep).sum()))
    return out


REPLAY_SUFFIX = "pose"


def replay_pose_features(scene: str, seed: int, draws: int, names: list[str], cache: Path, log) -> dict[str, np.ndarray]:
    """:func:`pose_features` for the cached draws of ``names`` without registering again: the estimate is
    ``se3_exp(-xi) T_true`` from the cached error, the pair is drawn again from ``(seed, index)``, and one draw serves
    every variant. Only for caches without failures (their order is then the draw index). Cached per variant."""
    from lidarkit.geometry import se3_exp

    out, todo = {}, {}
    for name in names:
        path = cache / f"{scene}_s{seed}_{name}_{draws}_{REPLAY_SUFFIX}.npz"
        if path.exists():
            out[name] = np.load(path)["features"]
            continue
        run = collect(scene, seed, draws, name, cache, log)
        if int(run["failed"]) == 0 and len(run["errors"]) == draws:
            todo[name] = run
    if not todo:
        return out
    pairs = ScanPairs(scene, seed=seed, n_frames=41)
    feats = {name: [] for name in todo}
    t0 = time.perf_counter()
    for i in range(draws):
        pair = pairs.draw(i)
        for name, run in todo.items():
            T_est = se3_exp(-run["errors"][i]) @ pair.T_target_source
            f = pose_features(pair.source_xyz, pair.target_xyz, T_est, pair.init_T, pairs.range_noise_m, run["covs"][i])
            feats[name].append([f[k] for k in POSE_FEATURES])
    for name, rows in feats.items():
        out[name] = np.array(rows, dtype=np.float64)
        np.savez(cache / f"{scene}_s{seed}_{name}_{draws}_{REPLAY_SUFFIX}.npz", features=out[name],
                 feature_names=np.array(POSE_FEATURES, dtype="U32"))
    log(f"{scene} seed {seed}: pose features of {len(todo)} variants replayed, {(time.perf_counter() - t0) / draws:.2f} s/draw")
    return out


def score(errors: np.ndarray, covs: np.ndarray) -> dict:
    values = nees_values(errors, covs)
    if len(values) == 0:
        return {"nees_mean": float("nan"), "nees_median": float("nan"), "inside_95": float("nan"), "n": 0}
    return {"nees_mean": float(values.mean()), "nees_median": float(np.median(values)), "inside_95": float((values < CHI2_6_95).mean()),
            "n": int(len(values))}


def row(run: dict, cal: AxisCalibration, before: AxisCalibration, blk: np.ndarray, every: dict | None = None) -> dict:
    """A run's scores (``run``: the draws scored, see :func:`converged_only`); the along / across ratio of the
    covariance is counted over ``every`` draw with a covariance (default ``run``), the weakest direction's name over
    every draw: they describe the geometry, which a result that stopped sliding along a corridor's axis shows as well
    as any."""
    every = run if every is None else every
    steps = run.get("steps")
    calibrated = apply_all(run["covs"], cal, steps)
    no_coverage = apply_all(run["covs"], AxisCalibration(cal.factors, cal.sigmas, 1.0, None, cal.step_gains, cal.step_spread), steps)
    previous = apply_all(run["covs"], before)
    out = {"failed": int(run["failed"]), "flagged": int(run.get("flagged", 0)), "seconds_per_pair": float(run["seconds_per_pair"]),
           "raw": score(run["errors"], run["covs"]), "block": score(run["errors"], scaled(run["covs"], blk)),
           "before": score(run["errors"], previous), "factor_floor": score(run["errors"], no_coverage),
           "calibrated": score(run["errors"], calibrated)}
    if len(run["errors"]):
        z2 = run["errors"] ** 2 / np.einsum("nii->ni", calibrated)
        out["z2_per_axis"] = z2.mean(axis=0).tolist()
        out["error_mean"] = run["errors"].mean(axis=0).tolist()
        out["error_std"] = run["errors"].std(axis=0).tolist()
    if len(every["errors"]):
        named = np.concatenate([every["weakest"], every.get("weakest_without_covariance", np.zeros(0, dtype="U64"))])
        out["named_draws"] = int(len(named))
        out["axis_named"] = float(np.mean([w == "translation along x" for w in named]))
        for key, covs in (("", apply_all(every["covs"], cal, every.get("steps"))), ("before_", apply_all(every["covs"], before))):
            out[f"{key}cov_xx_over_yy_median"] = float(np.median(covs[:, 0, 0] / covs[:, 1, 1]))
            out[f"{key}cov_xx_over_yy_min"] = float(np.min(covs[:, 0, 0] / covs[:, 1, 1]))
        names, counts = np.unique(named, return_counts=True)
        out["weakest_names"] = {str(n): int(c) for n, c in zip(names, counts)}
    if len(run["refs"]):
        out["reference"] = score(run["errors"], run["refs"])
    return out


TURNS_DEG = (0, 30, 45, 90)


def turned_scores(run: dict, principal: AxisCalibration, frame_axes: AxisCalibration) -> dict:
    """Scores of ``run`` with its target frame turned about z by each of :data:`TURNS_DEG` (covariances, errors and
    steps turned as a left perturbation is, ``blockdiag(R, R)``: the scene as it would read with the sensor turned),
    calibrated in the principal axes (the default, the same at every turn) and in the target frame's axes."""
    out: dict = {}
    for deg in TURNS_DEG:
        P = twist_turn(so3_exp([0.0, 0.0, np.radians(deg)]))
        covs = np.einsum("ij,njk,lk->nil", P, run["covs"], P)
        errors, steps = run["errors"] @ P.T, None if run.get("steps") is None else run["steps"] @ P.T
        out[str(deg)] = {"principal": score(errors, apply_all(covs, principal, steps)), "frame_axes": score(errors, apply_all(covs, frame_axes, steps))}
    return out


def parse_runs(text: str) -> list[tuple[str, int]]:
    return [(item.split(":")[0], int(item.split(":")[1])) for item in text.split(",") if item]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--train", default="street:0,street:2,street:4,street:6,street:12,street:13,street:14,street:15")
    ap.add_argument("--train-draws", type=int, default=200)
    ap.add_argument("--check", default="street:1,street:3,street:5,street:7,street:8,street:9,street:10,street:11,corridor:1,open:1")
    ap.add_argument("--draws", type=int, default=200)
    ap.add_argument("--variants", default=",".join(VARIANTS))
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "covariance")
    ap.add_argument("--cache", type=Path, default=None, help="draws cache (default: <out>/draws)")
    for which in ("train", "check"):
        ap.add_argument(f"--{which}-frames", type=int, default=201,
                        help=f"frames per {which} run (default 201: one frame pair per draw up to 200 draws; {N_FRAMES}: 40 frame "
                             "pairs, 5 draws each)")
    args = ap.parse_args(argv)
    variants = [v for v in args.variants.split(",") if v in available_icp()]
    log = lambda msg: print(msg, file=sys.stderr, flush=True)  # noqa: E731
    cache = args.cache if args.cache is not None else args.out / "draws"
    train = {name: [converged_only(collect(sc, sd, args.train_draws, name, cache, log, n_frames=args.train_frames)) for sc, sd in parse_runs(args.train)]
             for name in variants}
    fits = {name: fit_calibration(runs) for name, runs in train.items()}
    cal = {name: f[0] for name, f in fits.items()}
    # the previous calibration (without the step term) learned on the same training draws
    before = {name: fit_calibration(runs, use_step=False)[0] for name, runs in train.items()}
    blk = {name: block_factors(runs) for name, runs in train.items()}
    # the same model learned in the target frame's axes (the calibration before it moved to the principal axes), to show
    # what turning a scene in the frame does to each
    frame_axes = {name: fit_calibration(runs, axes="target")[0] for name, runs in train.items()}
    results = {
        "command": " ".join(["benchmarks/covariance_calibration.py", *(sys.argv[1:] if argv is None else argv)]),
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "machine": describe_machine(machine_info()),
        "load_average": os.getloadavg()[0], "sensor": "32 beams x 1024 columns, range noise 0.02 m"
        + "".join(f"; {w} runs: {n} frames (one frame pair per draw)" for w, n in (("training", args.train_frames), ("check", args.check_frames))
                  if n != N_FRAMES),
        "train": {"runs": args.train, "draws": args.train_draws,
                  "calibration": {n: {"factors": list(c.factors), "sigmas": list(c.sigmas), "coverage": c.coverage,
                                      "trained_variance": list(c.trained_variance),
                                      "step_gains": None if c.step_gains is None else list(c.step_gains),
                                      "step_spread": None if c.step_spread is None else list(c.step_spread), "axes": c.axes, **fits[n][1]}
                                  for n, c in cal.items()},
                  "rows": {f"{sc}:{sd}": {name: row(train[name][i], cal[name], before[name], blk[name]) for name in variants}
                           for i, (sc, sd) in enumerate(parse_runs(args.train))}},
        "calibration_without_step": {n: {"factors": list(c.factors), "sigmas": list(c.sigmas), "coverage": c.coverage,
                                         "trained_variance": list(c.trained_variance), "step_gains": None, "step_spread": None,
                                         "axes": c.axes}
                                     for n, c in before.items() if cal[n].step_gains is not None},
        "check": {},
    }
    for sc, sd in parse_runs(args.check):
        drawn = {name: collect(sc, sd, args.draws, name, cache, log, n_frames=args.check_frames) for name in variants}
        results["check"][f"{sc}:{sd}"] = {name: row(converged_only(drawn[name]), cal[name], before[name], blk[name], every=drawn[name])
                                          for name in variants}
        results.setdefault("turned", {})[f"{sc}:{sd}"] = {name: turned_scores(converged_only(drawn[name]), cal[name], frame_axes[name])
                                                          for name in variants}
    args.out.mkdir(parents=True, exist_ok=True)
    write_text(args.out / "results.json", json.dumps(results, indent=2) + "\n")
    write_text(args.out / "README.md", render(results))
    print(render(results))
    return 0


def _fmt(s: dict) -> str:
    return f"{s['nees_mean']:.2f} / {s['inside_95']:.3f}" if s["n"] else "-"


def _fmt2(s: dict) -> str:
    return f"{s['nees_mean']:.2f} / {s['inside_95']:.3f}"


def _g(v: float) -> str:
    return f"{v:.3g}"


def calibration_source(calibration: dict) -> str:
    """The ``CALIBRATION`` entries of ``lidarkit.registration.covariance`` as Python source (the step gains and spread
    only where the entry has them)."""
    lines = []
    for name, c in calibration.items():
        fields = [f'({", ".join(_g(v) for v in c["factors"])})', f'({", ".join(_g(v) for v in c["sigmas"])})',
                  f'{c["coverage"]:.3g}, ({", ".join(_g(v) for v in c["trained_variance"])})']
        fields += [f'({", ".join(_g(v) for v in c[key])})' for key in ("step_gains", "step_spread") if c.get(key) is not None]
        if c.get("axes", "target") != "target":
            fields[-1] += f', axes="{c["axes"]}"'  # a keyword after the positional fields, with or without the step terms

        lines += [f'    "{name}": AxisCalibration(', *(f"        {f}," for f in fields[:-1]), f"        {fields[-1]}),"]
    return "\n".join(lines)


def render(results: dict) -> str:
    tr = results["train"]
    lines = ["# Registration covariance calibration", "", f"Command: `{results['command']}`  ", f"Date: {results['date']}  ",
             f"Machine: {results['machine']}, load average at the end {results['load_average']:.1f}  ", f"Sensor: {results['sensor']}", "",
             "NEES = xi^T Sigma^-1 xi of the true error (6 when calibrated); inside = share below the chi-square(6) 95 % "
             "bound. Target on the well-constrained (street) scenes: mean NEES in [4.2, 9] and inside in [0.90, 0.98]. "
             "Columns: raw = the closed form (Censi with the target surface's thickness, correlation voxel 1 m); block = "
             "times one translation and one rotation factor; no step = the previous calibration (per-axis factor and floor, "
             "training-range guard, coverage scalar; no step term); step+factor+floor = the step term and the per-axis "
             "factor and floor of what it leaves, without the coverage scalar; **calibrated** (the default) = the same with "
             "the coverage scalar. All are learned on the training runs and applied unchanged to the check runs. Only the draws "
             "the variant reports converged are learned from and scored (a covariance describes a converged alignment); the "
             "draws it flags not converged, and those without a covariance, are counted apart.", "",
             f"## Training: {tr['runs']} ({tr['draws']} draws each)", "",
             "`Sigma' = c (S Sigma S + diag(b^2) + |step_t|^2 diag(h^2) + (g * step)(g * step)^T)`, `S = diag(sqrt(f))` while "
             "`Sigma_jj` is within the training range v (beyond it the excess is scaled by max(f, 1)); `step`: the result's "
             f"point-to-surface Gauss-Newton step (`surface_step`, `step_t` its translation), `g` its gain per axis where it "
             f"correlates with the error (r >= {STEP_MIN_CORRELATION:g}, else 0), `h` the spread of what the step leaves per "
             "metre of step (only with a step term). b in mm and mrad, h in mm and mrad per m; "
             f"c from the pooled training NEES (target {TARGET_INSIDE:.3f} "
             f"inside, mean NEES at least {MIN_MEAN_NEES:g}).", "",
             "| variant | step correlation r (tx ty tz rx ry rz) | g | h | " + " | ".join(f"f {a}" for a in AXES) + " | "
             + " | ".join(f"b {a}" for a in AXES) + " | c | pooled NEES / inside before c | after c | leave-one-seed-out, after c |",
             "|---|" + "---|" * 19]
    for name, c in tr["calibration"].items():
        gains = "-" if c.get("step_gains") is None else " ".join(f"{v:.2f}" for v in c["step_gains"])
        spread = "-" if c.get("step_spread") is None else " ".join(f"{1e3 * v:.2g}" for v in c["step_spread"])
        lines.append(f"| {name} | {' '.join(f'{v:+.2f}' for v in c['step_correlation'])} | {gains} | {spread} | "
                     + " | ".join(_g(v) for v in c["factors"]) + " | " + " | ".join(f"{1e3 * v:.2g}" for v in c["sigmas"])
                     + f" | {c['coverage']:.3f} | {_fmt2(c['pooled_before_coverage'])} | {_fmt2(c['pooled_after_coverage'])} | "
                     f"{_fmt2(c['leave_one_out_after_coverage'])} |")
    lines += ["", "Mean NEES / inside on the training runs themselves (in-sample):", "",
              "| run | variant | draws scored (not converged) | raw | block | no step | step+factor+floor | calibrated |", "|---|---|---|---|---|---|---|---|"]
    for run, rows in tr["rows"].items():
        for name, r in rows.items():
            lines.append(f"| {run} | {name} | {r['raw']['n']} ({r.get('flagged', 0)}) | {_fmt(r['raw'])} | {_fmt(r['block'])} | {_fmt(r['before'])} | "
                         f"{_fmt(r['factor_floor'])} | {_fmt(r['calibrated'])} |")
    for run, rows in results["check"].items():
        scene = run.split(":")[0]
        corridor = scene == "corridor"
        lines += ["", f"## Check: {run.replace(':', ', seed ')}", "",
                  "| variant | draws scored (no cov., not converged) | raw NEES / inside | block | no step | step+factor+floor | **calibrated** | reference | z^2 per axis (tx ty tz rx ry rz) | "
                  + ("weakest named 'translation along x' (every draw) | cov xx / yy median (min), no step, draws with a covariance | calibrated | " if corridor else "") + "s/pair |",
                  "|---|---|---|---|---|---|---|---|---|" + ("---|---|---|" if corridor else "") + "---|"]
        for name, r in rows.items():
            ref = _fmt(r["reference"]) if "reference" in r else "-"
            z2 = " ".join(f"{v:.2f}" for v in r.get("z2_per_axis", []))
            extra = ""
            if corridor:
                extra = (f"{r.get('axis_named', float('nan')):.2f} of {r.get('named_draws', 0)} | {r.get('before_cov_xx_over_yy_median', float('nan')):.0f} "
                         f"({r.get('before_cov_xx_over_yy_min', float('nan')):.0f}) | {r.get('cov_xx_over_yy_median', float('nan')):.0f} "
                         f"({r.get('cov_xx_over_yy_min', float('nan')):.0f}) | ")
            lines.append(f"| {name} | {r['raw']['n']} ({r['failed']}, {r.get('flagged', 0)}) | {_fmt(r['raw'])} | {_fmt(r['block'])} | {_fmt(r['before'])} | "
                         f"{_fmt(r['factor_floor'])} | **{_fmt(r['calibrated'])}** | {ref} | {z2} | {extra}{r['seconds_per_pair']:.2f} |")
    if results.get("turned"):
        lines += ["", "## Turned scenes", "",
                  "Each check run with its target frame turned about z (covariances, errors and steps turned as a left "
                  "perturbation is: the scene as a sensor turned by that angle reads it), mean NEES / inside. **principal** "
                  "(the default): the calibration learned in the principal axes (x along the weakest horizontal direction "
                  "of each closed form), the same at every turn; frame axes: the same model learned in the target frame's "
                  "axes, on the same training draws.", "",
                  "| run | variant | " + " | ".join(f"{d} deg principal | frame axes" for d in TURNS_DEG) + " |",
                  "|---|---|" + "---|---|" * len(TURNS_DEG)]
        for run, rows in results["turned"].items():
            for name, r in rows.items():
                lines.append(f"| {run} | {name} | " + " | ".join(f"**{_fmt(r[str(d)]['principal'])}** | {_fmt(r[str(d)]['frame_axes'])}"
                                                                for d in TURNS_DEG) + " |")
    lines += ["", "References (same pairs, same run): Open3D's `get_information_matrix_from_point_clouds` (times the known range "
              "variance) on the open3d_point_to_plane row, small_gicp's Hessian (inverse, moved to the left/target-frame "
              "convention) on the small_gicp row. z^2 per axis: mean of xi_j^2 / Sigma_jj after calibration (1 when that axis is "
              "calibrated).", "", "`CALIBRATION` entries (`lidarkit/registration/covariance.py`; factors, sigmas, coverage, training range, step gains, step spread):", "",
              "```python", calibration_source(tr["calibration"]), "```", "",
              "`CALIBRATION_WITHOUT_STEP` entries (the same learned without the step term, for a covariance without its step: "
              "the odometry frame covariance of a stateful variant):", "", "```python",
              calibration_source(results.get("calibration_without_step", {})), "```"]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    from lidarkit.cli import run_script

    run_script(main)
