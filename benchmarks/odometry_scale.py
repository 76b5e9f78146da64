"""KITTI-length odometry: frame rate and peak memory over a 4541-sweep simulated sequence read from disk.

The benchmark writes the sequence itself (KITTI layout, lidarkit's simulator: street scene, by default 32 beams x 360
columns, ~0.15 MB per sweep, under 1 GB in all; ``--beams``/``--azimuths`` for another sensor; never committed) and runs each of these in its own process,
one after the other, on the same files:

* ``lidarkit:kiss``: ``lidarkit.odometry.run`` (reader thread + kiss through lidarkit);
* ``kiss-icp``: kiss-icp's own ``OdometryPipeline`` over its ``generic`` loader on the same ``velodyne/*.bin``;
* ``lidarkit:small_gicp``: ``lidarkit.odometry.run`` with small_gicp;
* ``small_gicp``: small_gicp's own scan-to-scan loop (``preprocess_points`` once per sweep, ``align`` on the
  previous sweep's cloud and KdTree, constant-velocity guess), as its odometry example does;
* on request (``--runners``), ``lidarkit:small_gicp:lean`` and ``lidarkit:kiss:lean``: the wrapper alone, the
  assessment (``assess=False``, small_gicp) and the frame check's fitness test (``n_sample=0``) left out.

The exported sweeps have no per-point times (``point_times=false``) because kiss-icp's generic loader reads
none: both kiss runs then do exactly the same computation (their final poses are compared). Frame rate
(frames / wall time including reading) and peak RSS are recorded when the run passes 500 and 2000 frames and
at the end (4541, after the run's own end work: metrics, trajectory). Ratios are lidarkit / library in the
same run. Acceptance (issue 10): peak RSS at 4541 within 1.2x of 500 (plus the trajectory's size), lidarkit
kiss >= 0.95x kiss-icp's pipeline, lidarkit small_gicp >= 0.9x small_gicp's own loop.

    nice -n 10 .venv/bin/python benchmarks/odometry_scale.py [--frames 4541] [--beams 32 --azimuths 360] [--data /tmp/lidarkit_scale] [--keep-data]

Writes ``benchmarks/results/odometry/odometry_scale[_TAG].{md,json}`` (after every runner, so an interrupted run
keeps the runners it finished).
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import resource
import shlex
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / "benchmarks" / "results" / "odometry"
CHECKPOINTS = (500, 2000)
RUNNERS = ("lidarkit:kiss", "kiss-icp", "lidarkit:small_gicp", "small_gicp")
#: (lidarkit runner, the library runner it is compared with)
LIBRARY_OF = (("lidarkit:kiss", "kiss-icp"), ("lidarkit:small_gicp", "small_gicp"), ("lidarkit:kiss:lean", "kiss-icp"),
              ("lidarkit:small_gicp:lean", "small_gicp"))
SIM = dict(scene="street", n_beams=32, n_azimuths=360, range_noise_std_m=0.02, seed=0, point_times=False)


def peak_rss_mb() -> float:
    """This process's peak resident memory (MB): ``VmHWM`` of its own address space. ``ru_maxrss`` is not used where
    ``VmHWM`` exists: it survives ``execve`` and a runner forked from a parent that just wrote the sequence started
    with the parent's peak (256 MB in the run of 2026-11-25, where the run itself peaked at ~108 MB)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024.0  # kB
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # KiB on Linux


class Checkpoints:
    """Frame rate and peak RSS when the run has read frame 500, 2000, ... (reads are at most a few frames ahead)."""

    def __init__(self, start: float):
        self.start = start
        self.rows: list[dict] = []

    def seen(self, index: int) -> None:
        if index + 1 in CHECKPOINTS:
            wall = time.perf_counter() - self.start
            self.rows.append({"frames": index + 1, "wall_s": wall, "fps": (index + 1) / wall, "peak_rss_mb": peak_rss_mb()})


def child(runner: str, data: Path, n: int) -> dict:
    """One run in this process; returns its checkpoints, end figures and final pose."""
    rss_before = peak_rss_mb()
    if runner.startswith("lidarkit:"):
        from lidarkit.io.kitti import KittiOdometry
        from lidarkit.odometry import run

        class Counted(KittiOdometry):
            def read_scan(self, index):
                marks.seen(index)
                return super().read_scan(index)

        from lidarkit.odometry import FrameCheckConfig

        seq = Counted(data)
        method, _, mode = runner.split(":", 1)[1].partition(":")
        lean = {"params": None if method == "kiss" else {"assess": False}, "frame_check": FrameCheckConfig(n_sample=0)} if mode == "lean" else {}
        rss_before = peak_rss_mb()
        marks = Checkpoints(time.perf_counter())
        result = run(seq, method, frames=f"0:{n}", **lean)
        wall = time.perf_counter() - marks.start
        final = result.trajectory.poses_se3[-1]
        loop_fps = result.fps
        loop_cpu = result.total_cpu_s
    elif runner == "kiss-icp":
        from kiss_icp.datasets.generic import GenericDataset
        from kiss_icp.pipeline import OdometryPipeline

        class Counted(GenericDataset):
            def __getitem__(self, idx):
                marks.seen(idx)
                return super().__getitem__(idx)

        dataset = Counted(data / "velodyne")
        pipeline = OdometryPipeline(dataset, n_scans=n)
        rss_before = peak_rss_mb()
        marks = Checkpoints(time.perf_counter())
        cpu0 = time.process_time()
        pipeline._run_pipeline()  # the odometry loop (its run() adds evaluation and result files)
        wall = time.perf_counter() - marks.start
        loop_cpu = time.process_time() - cpu0
        final = pipeline.poses[-1]
        loop_fps = n / wall
    elif runner == "small_gicp":
        import small_gicp

        from lidarkit.registration.small_gicp_icp import SmallGICPConfig

        c = SmallGICPConfig()
        files = sorted((data / "velodyne").glob("*.bin"))[:n]
        marks = Checkpoints(time.perf_counter())
        cpu0 = time.process_time()
        pose, motion, previous = np.eye(4), np.eye(4), None
        poses = np.empty((n, 4, 4))
        for k, path in enumerate(files):
            marks.seen(k)
            points = np.fromfile(path, dtype=np.float32).reshape(-1, 4)[:, :3].astype(np.float64)
            cloud, tree = small_gicp.preprocess_points(points, c.downsampling_resolution_m, num_threads=c.num_threads)
            if previous is not None:
                out = small_gicp.align(previous[0], cloud, previous[1], motion, registration_type=c.registration_type,
                                       max_correspondence_distance=c.max_correspondence_distance_m, num_threads=c.num_threads,
                                       max_iterations=c.max_iterations)
                if out.converged:
                    motion = np.asarray(out.T_target_source)
                pose = pose @ motion
            poses[k] = pose
            previous = (cloud, tree)
        wall = time.perf_counter() - marks.start
        loop_cpu = time.process_time() - cpu0
        final = poses[-1]
        loop_fps = n / wall
    else:
        raise SystemExit(f"unknown runner {runner}")
    return {
        "runner": runner, "frames": n, "wall_s": wall, "fps": n / wall, "loop_fps": loop_fps, "loop_cpu_s": loop_cpu,
        "peak_rss_mb": peak_rss_mb(), "rss_before_loop_mb": rss_before, "checkpoints": marks.rows,
        "final_position_m": [float(x) for x in np.asarray(final)[:3, 3]],
    }


def make_data(data: Path, n: int) -> float:
    """Write the sequence unless a complete one is there; returns its size in GB."""
    from lidarkit.sim.lidar import SimulatedLidarSequence, export_kitti

    done = data / "velodyne" / f"{n - 1:06d}.bin"
    if not (done.is_file() and (data / "sim.yaml").is_file() and _same_sensor(data / "sim.yaml")):
        shutil.rmtree(data, ignore_errors=True)
        t0 = time.perf_counter()
        export_kitti(SimulatedLidarSequence(n_frames=n, **SIM), data)
        print(f"wrote {n} sweeps to {data} in {time.perf_counter() - t0:.0f} s", flush=True)
    return sum(p.stat().st_size for p in data.rglob("*") if p.is_file()) / 1e9


def _same_sensor(sim_yaml: Path) -> bool:
    """Whether the sequence there was written with this run's sensor (a folder of another size is written again)."""
    import yaml

    written = yaml.safe_load(sim_yaml.read_text()) or {}
    return all(written.get(key) == SIM[key] for key in ("n_beams", "n_azimuths", "scene", "seed"))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=4541)
    parser.add_argument("--data", type=Path, default=Path("/tmp/lidarkit_scale"))
    parser.add_argument("--runners", default=",".join(RUNNERS))
    parser.add_argument("--keep-data", action="store_true", help="keep the written sequence (default: delete it at the end)")
    parser.add_argument("--tag", default="", help="results go to odometry_scale[_TAG].{md,json} (runs of different sizes side by side)")
    parser.add_argument("--interleaved", type=int, default=0, metavar="N",
                        help="instead: frame-rate ratios from N-frame runs, lidarkit and library alternately (--repeats each)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--beams", type=int, default=SIM["n_beams"], help="the simulated sensor's rows (default %(default)s)")
    parser.add_argument("--azimuths", type=int, default=SIM["n_azimuths"], help="its columns, rays a row per sweep (default %(default)s)")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args()
    SIM.update(n_beams=args.beams, n_azimuths=args.azimuths)
    if args.child:
        print(json.dumps(child(args.child, args.data, args.frames)))
        return

    size_gb = make_data(args.data, args.frames)
    if args.interleaved:
        interleaved(args, size_gb)
        return
    rows = []
    for runner in args.runners.split(","):
        t0 = time.perf_counter()
        proc = subprocess.run([sys.executable, __file__, "--child", runner, "--data", str(args.data), "--frames", str(args.frames)],
                              capture_output=True, text=True, env={**os.environ, "PYTHONPATH": str(REPO)})
        if proc.returncode != 0:
            raise SystemExit(f"{runner} failed:\n{proc.stderr[-3000:]}")
        row = json.loads(proc.stdout.strip().splitlines()[-1])
        rows.append(row)
        print(f"{runner}: {row['fps']:.2f} fps, peak RSS {row['peak_rss_mb']:.0f} MB ({time.perf_counter() - t0:.0f} s)", flush=True)
        write_results(rows, args, size_gb)  # after every runner: a partial table survives an interrupted run
    if not args.keep_data:
        shutil.rmtree(args.data, ignore_errors=True)


def run_child(runner: str, data: Path, n: int) -> dict:
    proc = subprocess.run([sys.executable, __file__, "--child", runner, "--data", str(data), "--frames", str(n)],
                          capture_output=True, text=True, env={**os.environ, "PYTHONPATH": str(REPO)})
    if proc.returncode != 0:
        raise SystemExit(f"{runner} failed:\n{proc.stderr[-3000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def interleaved(args, size_gb: float) -> None:
    """Frame-rate ratio lidarkit / library from short runs taken alternately, so that a machine whose load drifts
    over a long run charges both sides alike; median over the repeats."""
    from lidarkit import atomic
    from lidarkit.bench.machine import describe_machine, machine_info

    runners = args.runners.split(",")
    pairs = [(a, b) for a, b in LIBRARY_OF if a in runners and b in runners]
    fps: dict[str, dict[str, list[float]]] = {f"{a} / {b}": {a: [], b: []} for a, b in pairs}  # a library run per pair
    cpu: dict[str, dict[str, list[float]]] = {f"{a} / {b}": {a: [], b: []} for a, b in pairs}  # loop CPU s (all threads)
    load_start = os.getloadavg()[0]
    for _ in range(args.repeats):
        for a, b in pairs:
            for runner in (a, b):
                row = run_child(runner, args.data, args.interleaved)
                fps[f"{a} / {b}"][runner].append(row["loop_fps"])
                cpu[f"{a} / {b}"][runner].append(row["loop_cpu_s"])
                print(f"{runner}: {row['loop_fps']:.2f} fps, {row['loop_cpu_s']:.2f} CPU-s", flush=True)
    ratios = {}
    for a, b in pairs:
        side, used = fps[f"{a} / {b}"], cpu[f"{a} / {b}"]
        cpu_ratios = np.divide(used[b], used[a])  # library CPU / lidarkit CPU: the same sense as the frame rates
        ratios[f"{a} / {b}"] = {"median_ratio": float(np.median(np.divide(side[a], side[b]))), "ratios": list(np.divide(side[a], side[b])),
                                "median_cpu_ratio": float(np.median(cpu_ratios)), "cpu_ratios": list(cpu_ratios)}
    command = _command(args)
    payload = {"date_utc": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"), "machine": describe_machine(machine_info()),
               "command": command, "sim": SIM, "data_size_gb": size_gb, "frames_per_run": args.interleaved, "repeats": args.repeats,
               "load_average_start_end": [load_start, os.getloadavg()[0]], "loop_fps": fps, "loop_cpu_s": cpu, "ratios": ratios}
    stem = "odometry_scale_interleaved" + (f"_{args.tag}" if args.tag else "")
    RESULTS.mkdir(parents=True, exist_ok=True)
    atomic.write_text(RESULTS / f"{stem}.json", json.dumps(payload, indent=2) + "\n")
    lines = ["# Odometry frame rate, lidarkit / library, interleaved short runs (issue 10)", "",
             f"{payload['date_utc']} on {payload['machine']}; `{command}`", "",
             f"{args.interleaved}-frame runs from disk ({SIM['n_beams']}x{SIM['n_azimuths']}-ray simulated street sweeps, "
             f"{size_gb / args.frames * 1e3:.2f} MB each), each in its own process, lidarkit "
             f"and the library alternately, {args.repeats} times; loop frame rate (reading + registration); load average "
             f"{load_start:.1f} at the start, {payload['load_average_start_end'][1]:.1f} at the end. CPU: the library loop's "
             "process CPU time (all threads) over lidarkit's, the steadier figure on a loaded machine (it does not credit "
             "work done beside the registration on an idle core).", "",
             "| ratio | median | per repeat | CPU median | CPU per repeat |", "|---|---|---|---|---|"]
    for name, v in ratios.items():
        lines.append(f"| {name} | {v['median_ratio']:.3f} | {', '.join(f'{x:.3f}' for x in v['ratios'])} | {v['median_cpu_ratio']:.3f} | "
                     f"{', '.join(f'{x:.3f}' for x in v['cpu_ratios'])} |")
    atomic.write_text(RESULTS / f"{stem}.md", "\n".join(lines) + "\n")


def _command(args) -> str:
    """The command line as run (its niceness; the scratch data folder named SCRATCH_DIR: no machine paths in results)."""
    niceness = os.nice(0)
    words = [("SCRATCH_DIR" if a == str(args.data) else a) for a in sys.argv[1:]]
    return (f"nice -n {niceness} " if niceness else "") + ".venv/bin/python benchmarks/odometry_scale.py " + " ".join(shlex.quote(a) for a in words)


def write_results(rows: list[dict], args, size_gb: float) -> None:
    from lidarkit import atomic
    from lidarkit.bench.machine import describe_machine, machine_info

    by = {r["runner"]: r for r in rows}
    ratios = {}
    for ours, lib in LIBRARY_OF:
        if ours in by and lib in by:
            ratios[f"{ours} / {lib}"] = {
                "fps_ratio": by[ours]["loop_fps"] / by[lib]["loop_fps"],
                "whole_run_fps_ratio": by[ours]["fps"] / by[lib]["fps"],
                "fps_ratio_at": {str(a["frames"]): a["fps"] / b["fps"] for a, b in zip(by[ours]["checkpoints"], by[lib]["checkpoints"])},
                "final_position_gap_m": float(np.linalg.norm(np.subtract(by[ours]["final_position_m"], by[lib]["final_position_m"]))),
            }
    rss = {}
    for r in rows:
        first = r["checkpoints"][0] if r["checkpoints"] else None
        trajectory_mb = r["frames"] * (16 * 8 * 2 + 8) / 1e6  # estimate + ground truth 4x4 float64 and stamps
        if first:
            rss[r["runner"]] = {"at_500_mb": first["peak_rss_mb"], "at_end_mb": r["peak_rss_mb"],
                                "ratio_end_over_500": r["peak_rss_mb"] / first["peak_rss_mb"],
                                "ratio_end_minus_trajectory_over_500": (r["peak_rss_mb"] - trajectory_mb) / first["peak_rss_mb"]}
    command = _command(args)
    payload = {"date_utc": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"), "machine": describe_machine(machine_info()),
               "command": command, "frames": args.frames, "sim": SIM, "data_size_gb": size_gb, "runs": rows, "ratios": ratios, "rss": rss}
    RESULTS.mkdir(parents=True, exist_ok=True)
    stem = "odometry_scale" + (f"_{args.tag}" if args.tag else "")
    atomic.write_text(RESULTS / f"{stem}.json", json.dumps(payload, indent=2) + "\n")
    lines = [
        "# Odometry at KITTI length (issue 10)", "",
        f"{payload['date_utc']} on {payload['machine']}; `{command}`", "",
        f"{args.frames} simulated sweeps ({SIM['n_beams']}x{SIM['n_azimuths']} rays, street, no per-point times), "
        f"{size_gb:.2f} GB on disk, written by the benchmark and deleted after. Each runner in its own process, one "
        "after the other, on a shared 2-core machine: compare ratios, not absolute rates.", "",
        "| runner | fps @500 | fps @2000 | fps @end | peak RSS @500 (MB) | @2000 | @end |", "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        cp = {c["frames"]: c for c in r["checkpoints"]}
        cell = lambda k, key: f"{cp[k][key]:.{1 if key == 'fps' else 0}f}" if k in cp else "-"  # noqa: E731
        lines.append(f"| {r['runner']} | {cell(500, 'fps')} | {cell(2000, 'fps')} | {r['fps']:.1f} | {cell(500, 'peak_rss_mb')} | "
                     f"{cell(2000, 'peak_rss_mb')} | {r['peak_rss_mb']:.0f} |")
    lines += ["", "fps (loop): frames / time of the odometry loop (reading + registration); whole run: also the run's set-up",
              "and end work (lidarkit: metrics against ground truth, trajectory); at 500 / 2000: loop rate up to that frame.", "",
              "| ratio | fps (loop) | fps (whole run) | at 500 / 2000 | final position gap (m) |", "|---|---|---|---|---|"]
    for name, v in ratios.items():
        at = " / ".join(f"{x:.3f}" for x in v["fps_ratio_at"].values())
        lines.append(f"| {name} | {v['fps_ratio']:.3f} | {v['whole_run_fps_ratio']:.3f} | {at} | {v['final_position_gap_m']:.2e} |")
    lines += ["", "| runner | peak RSS end / 500 | (end - trajectory) / 500 |", "|---|---|---|"]
    for name, v in rss.items():
        lines.append(f"| {name} | {v['ratio_end_over_500']:.3f} | {v['ratio_end_minus_trajectory_over_500']:.3f} |")
    atomic.write_text(RESULTS / f"{stem}.md", "\n".join(lines) + "\n")


if __name__ == "__main__":
    from lidarkit.cli import run_script

    run_script(main)
