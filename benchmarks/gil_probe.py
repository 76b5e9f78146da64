"""Which library calls release Python's GIL: what a worker thread can overlap with them (issue 10's wrapper cost).

Each call runs repeatedly in a second thread while the main thread counts loop turns of pure Python; the count per
millisecond during the calls, against the count during ``time.sleep`` (which releases the GIL), is the share of
the call during which other Python code can run (~1: released, ~0: held; on 2 cores a call that keeps both
busy also lowers it). KITTI 00 94/95 (../shared/data), the variants' default settings, and the odometry frame
check's calls (its KD-tree, its nearest-neighbour queries) on inputs large enough to last > 10 ms: the whole scan 94
and scan 95's points as queries (a 1 ms call reads ~0 whether it releases the GIL or not, a woken thread needing a
moment to take it; what a call does with the GIL does not depend on its input's size).

    .venv/bin/python benchmarks/gil_probe.py          # on a quiet machine

Writes ``benchmarks/results/icp/gil_probe.{md,json}``.
"""

from __future__ import annotations

import datetime as dt
import json
import os
import threading
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / "benchmarks" / "results" / "icp"


def free_share(fn, repeats: int = 5) -> tuple[float, float]:
    """(median call time s, main-thread loop rate during the calls / its rate during sleep)."""

    def rate(call) -> tuple[float, float]:
        call()
        spans: list[tuple[float, float]] = []
        done = threading.Event()

        def work() -> None:
            for _ in range(repeats):
                t0 = time.perf_counter()
                call()
                spans.append((t0, time.perf_counter()))
            done.set()

        stamps = []
        thread = threading.Thread(target=work)
        thread.start()
        while not done.is_set():
            stamps.append(time.perf_counter())
        thread.join()
        s = np.array(stamps)
        per_s = [((s > a) & (s < b)).sum() / (b - a) for a, b in spans]
        return float(np.median([b - a for a, b in spans])), float(np.median(per_s))

    _, free = rate(lambda: time.sleep(0.02))
    took, during = rate(fn)
    return took, during / free


def main() -> None:
    import sys

    sys.path.insert(0, str(REPO / "benchmarks"))
    import open3d as o3d
    import small_gicp
    from kiss_icp.mapping import get_voxel_hash_map
    from kiss_icp.registration import get_registration
    from kiss_icp.voxelization import voxel_down_sample
    from wrapper_cost import load_pair

    from lidarkit import atomic
    from lidarkit.bench.machine import describe_machine, machine_info
    from lidarkit.registration import get_icp

    source, target = load_pair()
    calls = {}
    sg = get_icp("small_gicp").config
    tgt = small_gicp.voxelgrid_sampling(target, sg.downsampling_resolution_m, num_threads=sg.num_threads)
    tree = small_gicp.KdTree(tgt, num_threads=1)
    small_gicp.estimate_covariances(tgt, tree, num_neighbors=10, num_threads=sg.num_threads)
    src, _ = small_gicp.preprocess_points(source, sg.downsampling_resolution_m, num_threads=sg.num_threads)
    calls["small_gicp.voxelgrid_sampling"] = lambda: small_gicp.voxelgrid_sampling(source, sg.downsampling_resolution_m, num_threads=sg.num_threads)
    calls["small_gicp.KdTree"] = lambda: small_gicp.KdTree(tgt, num_threads=1)
    calls["small_gicp.estimate_covariances"] = lambda: small_gicp.estimate_covariances(tgt, tree, num_neighbors=10, num_threads=sg.num_threads)
    calls["small_gicp.align (preprocessed)"] = lambda: small_gicp.align(
        tgt, src, tree, np.eye(4), registration_type=sg.registration_type, max_correspondence_distance=sg.max_correspondence_distance_m,
        num_threads=sg.num_threads, max_iterations=sg.max_iterations)
    reg = o3d.pipelines.registration
    oc = get_icp("open3d_point_to_plane").config

    def cloud(points):
        pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points)).voxel_down_sample(oc.voxel_size_m)
        pc.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=oc.normal_radius_m, max_nn=oc.normal_max_nn))
        return pc

    S, T = cloud(source), cloud(target)
    criteria = reg.ICPConvergenceCriteria(oc.relative_fitness, oc.relative_rmse, oc.max_iterations)
    calls["open3d voxel_down_sample + estimate_normals"] = lambda: cloud(source)
    calls["open3d registration_icp (point to plane)"] = lambda: reg.registration_icp(
        S, T, oc.max_correspondence_distance_m, np.eye(4), reg.TransformationEstimationPointToPlane(), criteria)
    calls["open3d registration_generalized_icp"] = lambda: reg.registration_generalized_icp(
        S, T, oc.max_correspondence_distance_m, np.eye(4), reg.TransformationEstimationForGeneralizedICP(), criteria)
    kc = get_icp("kiss").config
    kcfg = kc.to_kiss_config()
    voxel = kc.resolved_voxel_size_m
    local_map = get_voxel_hash_map(kcfg)
    local_map.update(voxel_down_sample(target, voxel * 0.5), np.eye(4))
    down = voxel_down_sample(voxel_down_sample(source, voxel * 0.5), voxel * 1.5)
    calls["kiss-icp align_points_to_map"] = lambda: get_registration(kcfg).align_points_to_map(
        points=down, voxel_map=local_map, initial_guess=np.eye(4), max_correspondance_distance=3.0 * kc.initial_threshold_m,
        kernel=kc.initial_threshold_m)
    calls["kiss-icp map update"] = lambda: get_voxel_hash_map(kcfg).update(voxel_down_sample(target, voxel * 0.5), np.eye(4))
    # the odometry frame check (lidarkit.odometry.frame_check): its tree is built in the reading thread and queried in
    # a worker while the next frame registers, so both must let the main thread run. Its calls as it makes them
    # (cKDTree now, small_gicp's KdTree before), on the whole scans: a few ms per frame is too short to time
    from scipy.spatial import cKDTree

    queries = source[::4]
    ck = cKDTree(target, balanced_tree=False, compact_nodes=False)
    sg_tree = small_gicp.KdTree(target, num_threads=1)
    calls[f"frame check: scipy cKDTree ({len(target)} points)"] = lambda: cKDTree(target, balanced_tree=False, compact_nodes=False)
    calls[f"frame check: scipy cKDTree.query ({len(queries)} points)"] = lambda: ck.query(queries, k=1, distance_upper_bound=2.0)
    calls[f"frame check before: small_gicp.KdTree ({len(target)} points)"] = lambda: small_gicp.KdTree(target, num_threads=1)
    calls[f"frame check before: small_gicp batch_nearest_neighbor_search ({len(queries)} points)"] = \
        lambda: sg_tree.batch_nearest_neighbor_search(queries, num_threads=1)
    rows = []
    load_start = os.getloadavg()[0]
    for name, fn in calls.items():
        took, share = free_share(fn)
        rows.append({"call": name, "call_s": took, "python_runs_share": share})
        print(json.dumps(rows[-1]), flush=True)
    payload = {"date_utc": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"), "machine": describe_machine(machine_info()),
               "load_average_start_end": [load_start, os.getloadavg()[0]], "rows": rows}
    RESULTS.mkdir(parents=True, exist_ok=True)
    atomic.write_text(RESULTS / "gil_probe.json", json.dumps(payload, indent=2) + "\n")
    lines = ["# Which library calls let other Python threads run (GIL released)", "",
             f"{payload['date_utc']} on {payload['machine']}; load average {load_start:.1f} at the start; "
             "`.venv/bin/python benchmarks/gil_probe.py`", "",
             "Share: loop turns of pure Python in the main thread per ms while the call runs in another thread, over the same "
             "during `time.sleep` (~1: the call releases the GIL; ~0: it holds it, nothing else in Python runs). The frame check's "
             "rows: its calls (scipy's tree now, small_gicp's before) on the whole scan 94 and a quarter of scan 95's points as "
             "queries, to last long enough to be timed (per frame it builds a tree of <= 20000 points and makes 1500 queries).", "",
             "| call | median time (ms) | share of Python that still runs |", "|---|---|---|"]
    lines += [f"| {r['call']} | {1e3 * r['call_s']:.1f} | {r['python_runs_share']:.2f} |" for r in rows]
    atomic.write_text(RESULTS / "gil_probe.md", "\n".join(lines) + "\n")


if __name__ == "__main__":
    from lidarkit.cli import run_script

    run_script(main)
