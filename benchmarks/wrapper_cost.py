"""What a lidarkit variant costs next to the library it wraps, pairwise and in odometry, measured in one run.

Pairwise: the KITTI 00 94 -> 95 pair (../shared/data), ``get_icp(name).align`` (degeneracy summary on, as always)
against the library's own call with the same settings (same pose, checked), median of ``--repeats`` runs taken
alternately. Odometry: the 10 consecutive KITTI scans read from disk, ``lidarkit.odometry.run`` against the
library's own loop (kiss: kiss-icp's ``OdometryPipeline`` with its KITTI loader; small_gicp: ``preprocess_points``
once per scan + ``align`` on the previous scan's cloud and KdTree; Open3D: each scan downsampled (+ normals) once,
``registration_*`` on the previous one), both with a constant-velocity guess. Acceptance (issue 10): every ratio
(library time / lidarkit time) >= 0.9.

    nice -n 10 .venv/bin/python benchmarks/wrapper_cost.py [--repeats 5]

Writes ``benchmarks/results/icp/wrapper_cost.{md,json}``.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import shlex
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "data" / "kitti_odometry"
RESULTS = REPO / "benchmarks" / "results" / "icp"


def load_pair():
    from lidarkit.io.kitti import KittiOdometry

    ds = KittiOdometry(DATA, "00", velodyne_dir=DATA / "extra_frames" / "00" / "velodyne")
    return ds.read_scan_by_frame(95).points_xyz, ds.read_scan_by_frame(94).points_xyz  # source, target


def library_pairwise(name: str, cfg, source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The library's own call for variant ``name`` with the variant's settings; returns T_target_source."""
    init = np.eye(4)
    if name == "small_gicp":
        import small_gicp

        return np.asarray(small_gicp.align(target, source, init, registration_type=cfg.registration_type, voxel_resolution=cfg.voxel_resolution_m,
                                           downsampling_resolution=cfg.downsampling_resolution_m, max_correspondence_distance=cfg.max_correspondence_distance_m,
                                           num_threads=cfg.num_threads, max_iterations=cfg.max_iterations).T_target_source)
    if name.startswith("open3d"):
        import open3d as o3d

        reg = o3d.pipelines.registration
        clouds = []
        for pts in (source, target):
            pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
            if cfg.voxel_size_m is not None:
                pc = pc.voxel_down_sample(cfg.voxel_size_m)
            if name != "open3d_point_to_point":
                pc.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=cfg.normal_radius_m, max_nn=cfg.normal_max_nn))
            clouds.append(pc)
        criteria = reg.ICPConvergenceCriteria(cfg.relative_fitness, cfg.relative_rmse, cfg.max_iterations)
        if name == "open3d_gicp":
            out = reg.registration_generalized_icp(*clouds, cfg.max_correspondence_distance_m, init, reg.TransformationEstimationForGeneralizedICP(), criteria)
        else:
            est = reg.TransformationEstimationPointToPoint() if name == "open3d_point_to_point" else reg.TransformationEstimationPointToPlane()
            out = reg.registration_icp(*clouds, cfg.max_correspondence_distance_m, init, est, criteria)
        return np.asarray(out.transformation)
    if name == "kiss":
        from kiss_icp.mapping import get_voxel_hash_map
        from kiss_icp.preprocess import Preprocessor
        from kiss_icp.registration import get_registration
        from kiss_icp.voxelization import voxel_down_sample

        kcfg = cfg.to_kiss_config()
        crop = Preprocessor(cfg.max_range_m, cfg.min_range_m, False, cfg.max_num_threads)
        tgt = crop.preprocess(np.ascontiguousarray(target), np.array([]), init)
        src = crop.preprocess(np.ascontiguousarray(source), np.array([]), init)
        voxel = cfg.resolved_voxel_size_m
        local_map = get_voxel_hash_map(kcfg)
        local_map.update(voxel_down_sample(tgt, voxel * 0.5), init)
        src = voxel_down_sample(voxel_down_sample(src, voxel * 0.5), voxel * 1.5)
        sigma = cfg.initial_threshold_m
        return np.asarray(get_registration(kcfg).align_points_to_map(points=src, voxel_map=local_map, initial_guess=init,
                                                                   max_correspondance_distance=3.0 * sigma, kernel=sigma))
    raise ValueError(name)


def library_odometry(name: str, cfg) -> tuple[float, np.ndarray]:
    """The library's own odometry loop over the 10 scans read from disk: (loop time, final pose)."""
    files = sorted((DATA / "sequences" / "00" / "velodyne").glob("*.bin"))
    if name == "kiss":
        from kiss_icp.datasets.kitti import KITTIOdometryDataset
        from kiss_icp.pipeline import OdometryPipeline

        pipeline = OdometryPipeline(KITTIOdometryDataset(DATA, "00"))
        t0 = time.perf_counter()
        pipeline._run_pipeline()
        return time.perf_counter() - t0, pipeline.poses[-1]
    t0 = time.perf_counter()
    pose, motion, previous = np.eye(4), np.eye(4), None
    for path in files:
        points = np.fromfile(path, dtype=np.float32).reshape(-1, 4)[:, :3].astype(np.float64)
        if name == "small_gicp":
            import small_gicp

            cloud = small_gicp.preprocess_points(points, cfg.downsampling_resolution_m, num_threads=cfg.num_threads)
            if previous is not None:
                out = small_gicp.align(previous[0], cloud[0], previous[1], motion, registration_type=cfg.registration_type,
                                       max_correspondence_distance=cfg.max_correspondence_distance_m, num_threads=cfg.num_threads,
                                       max_iterations=cfg.max_iterations)
                motion = np.asarray(out.T_target_source) if out.converged else motion
                pose = pose @ motion
        else:
            import open3d as o3d

            reg = o3d.pipelines.registration
            cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
            if cfg.voxel_size_m is not None:
                cloud = cloud.voxel_down_sample(cfg.voxel_size_m)
            if name != "open3d_point_to_point":
                cloud.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=cfg.normal_radius_m, max_nn=cfg.normal_max_nn))
            if previous is not None:
                criteria = reg.ICPConvergenceCriteria(cfg.relative_fitness, cfg.relative_rmse, cfg.max_iterations)
                if name == "open3d_gicp":
                    out = reg.registration_generalized_icp(cloud, previous, cfg.max_correspondence_distance_m, motion,
                                                           reg.TransformationEstimationForGeneralizedICP(), criteria)
                else:
                    est = reg.TransformationEstimationPointToPoint() if name == "open3d_point_to_point" else reg.TransformationEstimationPointToPlane()
                    out = reg.registration_icp(cloud, previous, cfg.max_correspondence_distance_m, motion, est, criteria)
                motion = np.asarray(out.transformation) if out.fitness > 0 else motion
                pose = pose @ motion
        previous = cloud
    return time.perf_counter() - t0, pose


def timed(fn) -> tuple[float, object]:
    t0 = time.perf_counter()
    out = fn()
    return time.perf_counter() - t0, out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--variants", default="kiss,small_gicp,open3d_point_to_point,open3d_point_to_plane,open3d_gicp")
    args = parser.parse_args()

    from lidarkit import atomic
    from lidarkit.bench.machine import describe_machine, machine_info
    from lidarkit.odometry import run
    from lidarkit.registration import available_icp, get_icp

    source, target = load_pair()
    rows = []
    for name in args.variants.split(","):
        if name not in available_icp():
            continue
        icp = get_icp(name)
        cfg = icp.config
        lib_t, ours_t, lib_o, ours_o = [], [], [], []
        T_lib = T_ours = None
        for _ in range(args.repeats):
            t, T_lib = timed(lambda: library_pairwise(name, cfg, source, target))
            lib_t.append(t)
            fresh = get_icp(name)  # no cloud carried over between repeats
            t, res = timed(lambda: fresh.align(source, target, init_T=np.eye(4)))
            ours_t.append(t)
            T_ours = res.T_target_source
        for _ in range(max(1, args.repeats // 2)):
            t, final_lib = library_odometry(name, cfg)
            lib_o.append(t)
            result = run(f"kitti:{DATA}?sequence=00", name)
            ours_o.append(result.total_time_s)  # the odometry loop: reading + registration
            final_ours = result.trajectory.poses_se3[-1]
        rows.append({
            "variant": name,
            "pairwise_library_s": float(np.median(lib_t)), "pairwise_lidarkit_s": float(np.median(ours_t)),
            "pairwise_ratio": float(np.median(lib_t) / np.median(ours_t)),
            "pairwise_pose_gap_m": float(np.linalg.norm(np.asarray(T_lib)[:3, 3] - np.asarray(T_ours)[:3, 3])),
            "odometry_library_s": float(np.median(lib_o)), "odometry_lidarkit_s": float(np.median(ours_o)),
            "odometry_ratio": float(np.median(lib_o) / np.median(ours_o)),
            "odometry_final_gap_m": float(np.linalg.norm(np.asarray(final_lib)[:3, 3] - final_ours[:3, 3])),
        })
        print(json.dumps(rows[-1]), flush=True)
    command = "nice -n 10 .venv/bin/python benchmarks/wrapper_cost.py " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    payload = {"date_utc": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"), "machine": describe_machine(machine_info()),
               "command": command, "rows": rows}
    RESULTS.mkdir(parents=True, exist_ok=True)
    atomic.write_text(RESULTS / "wrapper_cost.json", json.dumps(payload, indent=2) + "\n")
    lines = ["# Wrapper cost: lidarkit variants against their libraries (issue 10)", "",
             f"{payload['date_utc']} on {payload['machine']}; `{command}`", "",
             "Ratio = library time / lidarkit time (1.0: free; acceptance >= 0.9). Pairwise: KITTI 00 94->95, median of "
             f"{args.repeats}; odometry: the 10 KITTI 00 scans from disk, the loop of `lidarkit.odometry.run` (reading + "
             "registration, `total_time_s`) against the library's own loop, median of "
             f"{max(1, args.repeats // 2)}. Gaps: translation between the two poses (same computation when ~0).", "",
             "| variant | pairwise library (s) | lidarkit (s) | ratio | pose gap (m) | odometry library (s) | lidarkit (s) | ratio | final gap (m) |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['variant']} | {r['pairwise_library_s']:.3f} | {r['pairwise_lidarkit_s']:.3f} | {r['pairwise_ratio']:.2f} | "
                     f"{r['pairwise_pose_gap_m']:.1e} | {r['odometry_library_s']:.2f} | {r['odometry_lidarkit_s']:.2f} | "
                     f"{r['odometry_ratio']:.2f} | {r['odometry_final_gap_m']:.1e} |")
    atomic.write_text(RESULTS / "wrapper_cost.md", "\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
