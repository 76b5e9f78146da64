"""Sequence odometry benchmark: KITTI seq-00 (10 scans), kiss overhead, and simulated street / open sequences.

Sections (all through ``lidarkit.odometry.run``):
  A. the 10 consecutive KITTI seq-00 scans, every registered variant, end-point error vs SemanticKITTI;
  B. overhead: kiss through lidarkit.odometry vs calling kiss_icp.KissICP directly on the same in-memory frames,
     interleaved repeats, reported as a frame-rate ratio (target >= 0.95);
  C. simulated street and open sequences (motion distortion, range noise): kiss with vs without deskew, each
     scored against the sweep-END and the MID-sweep ground truth (kiss-icp deskews to the sweep end);
  D. vanilla vs ground_filtered (full clouds, reduced resolution: full-cloud vanilla is slow) on street and open;
  E. simulated pairs fed to the ICP engineer's pairwise benchmark through ``icp_variants.run_pairs``.

    .venv/bin/python benchmarks/odometry_sim.py                 # full size: 300 sweeps of 64 x 2000 rays
    .venv/bin/python benchmarks/odometry_sim.py --quick         # 120 sweeps of 32 x 720 rays (a smoke run)

Writes ``results.json``, ``README.md`` (tables with date, machine, command) and a few PNGs to ``--out``.
"""

from __future__ import annotations

import argparse
import datetime as dt
import importlib.util
import json
import sys
import time
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from lidarkit.atomic import write_text
from lidarkit.bench.machine import describe_machine, machine_info
from lidarkit.errors import DataError
from lidarkit.io.base import Scan
from lidarkit.odometry import run
from lidarkit.registration import available_icp, get_icp

REPO = Path(__file__).resolve().parents[1]
DEFAULT_DATA = REPO.parent / "shared" / "data"
DEFAULT_OUT = REPO / "benchmarks" / "results" / "odometry"
#: section letter -> its key in results.json
SECTIONS = {"A": "kitti", "B": "overhead", "C": "deskew", "D": "ground", "E": "pairs"}


def log(msg: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


class InMemory:
    """A ScanSequence over pre-read scans (so timing compares registration loops, not disk reads)."""

    def __init__(self, sequence, n: int | None = None):
        n = len(sequence) if n is None else n
        self.name = f"{sequence.name} (in memory)"
        self.scans: list[Scan] = [sequence.read_scan(i) for i in range(n)]
        ts = sequence.timestamps_s
        self._ts = None if ts is None else np.asarray(ts)[:n]
        gt = sequence.ground_truth
        self._gt = None if gt is None else gt[np.arange(n)]

    def __len__(self) -> int:
        return len(self.scans)

    def read_scan(self, index: int) -> Scan:
        return self.scans[index]

    @property
    def timestamps_s(self):
        return self._ts

    @property
    def ground_truth(self):
        return self._gt


def summary(result, extra: dict | None = None) -> dict:
    m = result.metrics
    drift = m.get("kitti_drift")
    row = {
        "method": result.method,
        "n_frames": m["n_frames"],
        "fps": m["fps"],
        "final_error_m": m.get("final_error", {}).get("translation_m"),
        "final_error_deg": m.get("final_error", {}).get("rotation_deg"),
        "estimated_length_m": m["estimated_length_m"],
        "gt_length_m": m.get("ground_truth_length_m"),
        "ape_rmse_m": m.get("ape_translation_m", {}).get("stats", {}).get("rmse"),
        "drift_pct": None if not drift else drift["translation_pct"],
        "drift_deg_per_100m": None if not drift else drift["rotation_deg_per_100m"],
        "n_not_converged": "n/a" if m["n_not_converged"] is None else m["n_not_converged"],  # None: stateful (kiss), not measured
    }
    row.update(extra or {})
    return row


def section_kitti(data: Path) -> list[dict]:
    from lidarkit.io.kitti import KittiOdometry

    folder = data / "kitti_odometry" / "sequences" / "00"
    seq = InMemory(KittiOdometry(folder, poses_file=folder / "poses_semantickitti.txt"))
    rows = []
    for name in available_icp():
        log(f"A. KITTI 10 scans: {name}")
        rows.append(summary(run(seq, name)))
    return rows


def section_overhead(data: Path, sim_seq, repeats: int) -> list[dict]:
    """Frame rate of kiss through lidarkit.odometry / frame rate of a bare KissICP loop, interleaved."""
    from kiss_icp.kiss_icp import KissICP

    from lidarkit.io.kitti import KittiOdometry

    sources = [("KITTI 00, 10 scans", InMemory(KittiOdometry(data / "kitti_odometry" / "sequences" / "00")), {})]
    sources.append((f"sim street, {len(sim_seq)} sweeps", sim_seq, {"voxel_size_m": 1.0}))
    rows = []
    for label, seq, params in sources:
        method = get_icp("kiss", **params)
        config = method.kiss_config
        direct_s, lidarkit_s, loop_s = [], [], []
        for _ in range(repeats):
            kiss = KissICP(config)
            start = time.perf_counter()
            for i in range(len(seq)):
                scan = seq.read_scan(i)
                kiss.register_frame(scan.points_xyz, np.array([]) if scan.point_times_s is None else scan.point_times_s)
            direct_s.append(time.perf_counter() - start)
            start = time.perf_counter()
            result = run(seq, method)
            lidarkit_s.append(time.perf_counter() - start)
            loop_s.append(result.total_time_s)
        n = len(seq)
        fps_direct, fps_loop, fps_call = (n / float(np.median(x)) for x in (direct_s, loop_s, lidarkit_s))
        log(f"B. overhead on {label}: direct {fps_direct:.2f} Hz, lidarkit loop {fps_loop:.2f} Hz, whole call {fps_call:.2f} Hz")
        rows.append({"data": label, "repeats": repeats, "fps_kiss_icp_direct": fps_direct, "fps_lidarkit_odometry": fps_loop,
                     "ratio": fps_loop / fps_direct, "fps_lidarkit_whole_call": fps_call, "ratio_whole_call": fps_call / fps_direct,
                     "direct_s": direct_s, "lidarkit_loop_s": loop_s, "lidarkit_call_s": lidarkit_s})
    return rows


def section_deskew(sequences: dict) -> list[dict]:
    from lidarkit import eval as leval

    rows = []
    for scene, seq in sequences.items():
        for deskew in (True, False):
            log(f"C. {scene}: kiss deskew={deskew}")
            result = run(seq, "kiss", params={"deskew": deskew, "voxel_size_m": 1.0})
            for instant in ("end", "mid"):
                ref = seq.ground_truth_at(instant).relative_to_first().with_timestamps(result.trajectory.timestamps_s)
                drift = leval.kitti_drift(ref, result.trajectory)
                ape = leval.ape(ref, result.trajectory)
                rows.append({"scene": scene, "deskew": deskew, "scored_at": instant, "drift_pct": drift.translation_pct,
                             "drift_deg_per_100m": drift.rotation_deg_per_100m, "ape_rmse_m": ape.rmse, "fps": result.fps})
    return rows


def section_ground(sequences: dict, voxel_m: float | None) -> list[dict]:
    rows = []
    params = {} if voxel_m is None else {"voxel_size_m": voxel_m}
    for scene, seq in sequences.items():
        for name in ("vanilla", "ground_filtered"):
            log(f"D. {scene}: {name} ({params or 'defaults: full clouds'})")
            result = run(seq, name, params=params)
            rows.append(summary(result, {"scene": scene, "voxel_size_m": voxel_m, "beams": seq.config.n_beams,
                                         "azimuths": seq.config.n_azimuths}))
    return rows


def section_pairs(sequences: dict) -> list[dict]:
    """Simulated pairs (frame 100 -> 101 and 200 -> 201 of each scene) through icp_variants.run_pairs."""
    spec = importlib.util.spec_from_file_location("icp_variants", REPO / "benchmarks" / "icp_variants.py")
    icp_variants = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(icp_variants)
    pairs = []
    for scene, seq in sequences.items():
        gt = seq.ground_truth
        for a in (100, 200):
            if a + 1 >= len(seq):
                continue
            T_gt = np.linalg.inv(gt.poses_se3[a]) @ gt.poses_se3[a + 1]
            pairs.append((seq.read_scan(a + 1).points_xyz, seq.read_scan(a).points_xyz, T_gt, f"sim {scene} {a}->{a + 1}"))
    log(f"E. {len(pairs)} simulated pairs through icp_variants.run_pairs")
    rows = icp_variants.run_pairs(pairs)
    for row in rows:
        row.pop("rmse_history", None)
        row.pop("T_target_source", None)
    return rows


def _f(x, spec=".3f", none="-") -> str:
    return none if x is None else format(x, spec)


def markdown(report: dict) -> str:
    s = report["settings"]
    lines = [
        "# Sequence odometry benchmark",
        "",
        f"- date: {report['date']}",
        f"- machine: {report['machine']}",
        f"- command: `{report['command']}`",
        f"- simulated sequences: {s['frames']} sweeps of {s['beams']} x {s['azimuths']} rays, seed {s['seed']}, motion distortion on, "
        f"range noise {s['noise_m']} m, 10 m/s after a 2 s start from rest; ground truth at the sweep end unless stated",
        "",
        "## A. KITTI seq 00, the 10 consecutive scans (vs SemanticKITTI poses, LiDAR frame)",
        "",
        "| method | end error m | end error deg | est. path m | GT path m | frame rate Hz | not converged |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for r in report["kitti"]:
        lines.append(f"| {r['method']} | {_f(r['final_error_m'])} | {_f(r['final_error_deg'])} | {_f(r['estimated_length_m'], '.2f')} | "
                     f"{_f(r['gt_length_m'], '.2f')} | {_f(r['fps'], '.1f')} | {r['n_not_converged']} |")
    lines += ["", "Acceptance: kiss, ground_filtered, open3d_gicp, small_gicp within 0.10 m; vanilla's deviation is the report's point "
              "(point-to-point ICP on full scans is pulled short by the road).", "",
              "## B. Overhead: kiss through lidarkit.odometry vs kiss_icp.KissICP directly (same in-memory frames, interleaved)", "",
              "Frame rate = frames / wall time of the frame loop (median of the repeats). `whole call` also counts what `run` does once",
              "after the loop (trajectory, APE/RPE/drift through evo), which a 10-frame run cannot amortize.", "",
              "| data | repeats | kiss_icp direct Hz | lidarkit.odometry loop Hz | ratio (target >= 0.95) | whole call Hz | ratio whole call |",
              "|---|---:|---:|---:|---:|---:|---:|"]
    for r in report["overhead"]:
        lines.append(f"| {r['data']} | {r['repeats']} | {r['fps_kiss_icp_direct']:.2f} | {r['fps_lidarkit_odometry']:.2f} | {r['ratio']:.3f} | "
                     f"{r['fps_lidarkit_whole_call']:.2f} | {r['ratio_whole_call']:.3f} |")
    lines += ["", "## C. kiss with vs without deskew, scored at the sweep end and mid-sweep", "",
              "| scene | deskew | scored at | KITTI drift % | deg/100 m | APE RMSE m (unaligned, first pose anchored) | frame rate Hz |", "|---|---|---|---:|---:|---:|---:|"]
    for r in report["deskew"]:
        lines.append(f"| {r['scene']} | {r['deskew']} | {r['scored_at']} | {_f(r['drift_pct'])} | {_f(r['drift_deg_per_100m'], '.4f')} | "
                     f"{r['ape_rmse_m']:.3f} | {r['fps']:.1f} |")
    voxel = report["settings"]["voxel_m"]
    lines += ["", f"## D. vanilla vs ground_filtered ({'full clouds' if voxel is None else f'both voxel {voxel} m'}), street vs open, "
              f"{s['frames']} sweeps of {s['d_beams']} x {s['d_azimuths']} rays", "",
              "| scene | method | KITTI drift % | deg/100 m | est. path m | GT path m | end error m | not converged | frame rate Hz |",
              "|---|---|---:|---:|---:|---:|---:|---:|---:|"]
    for r in report["ground"]:
        lines.append(f"| {r['scene']} | {r['method']} | {_f(r['drift_pct'])} | {_f(r['drift_deg_per_100m'], '.4f')} | "
                     f"{_f(r['estimated_length_m'], '.1f')} | {_f(r['gt_length_m'], '.1f')} | {_f(r['final_error_m'], '.2f')} | "
                     f"{r['n_not_converged']} | {_f(r['fps'], '.2f')} |")
    if report.get("pairs"):
        lines += ["", "## E. Simulated pairs through icp_variants.run_pairs (distorted sweeps, GT at the sweep end)", "",
                  "| pair | variant | error m | error deg | iterations | runtime s | degenerate |", "|---|---|---:|---:|---:|---:|---|"]
        for r in report["pairs"]:
            lines.append(f"| {r['pair']} | {r['variant']} | {r['error_m']:.3f} | {r['error_deg']:.3f} | {r['iterations'] if r['iterations'] is not None else '-'} | "
                         f"{r['runtime_s']:.2f} | {r['degenerate']} |")
    lines += ["", "## Findings", ""] + findings(report)
    again = [f"- section {letter} measured again on {m['date']}: `{m['command']}`"
             for letter, key in SECTIONS.items() if (m := report.get(f"{key}_measured"))]
    if again:
        lines += ["", "## Sections run later (merged into this report)", ""] + again
    lines += ["", "Raw numbers: `results.json`. Plots: `kiss_street_deskew.png` (top view, deskewed kiss vs GT at the sweep end)."]
    return "\n".join(lines) + "\n"


def findings(report: dict) -> list[str]:
    """One line per acceptance point, computed from the numbers above."""
    out = []
    k = {r["method"]: r for r in report.get("kitti", [])}
    if k:
        good = ", ".join(f"{m} {k[m]['final_error_m']:.3f} m" for m in ("kiss", "ground_filtered", "open3d_gicp", "small_gicp") if m in k)
        out.append(f"- KITTI 10 scans, end error vs SemanticKITTI: {good} (target < 0.10 m); vanilla "
                   f"{k['vanilla']['final_error_m']:.3f} m with its path {k['vanilla']['estimated_length_m']:.2f} m of "
                   f"{k['vanilla']['gt_length_m']:.2f} m: pulled short by the road." if "vanilla" in k else "")
    for r in report.get("overhead", []):
        out.append(f"- kiss overhead on {r['data']}: lidarkit.odometry runs at {r['ratio']:.3f}x the frame rate of kiss_icp directly (target >= 0.95).")
    d = {(r["scene"], r["deskew"], r["scored_at"]): r["drift_pct"] for r in report.get("deskew", [])}
    for scene in ("street", "open"):
        if (scene, True, "end") in d:
            end, mid = d[(scene, True, "end")], d[(scene, True, "mid")]
            inflated = end is not None and mid is not None and mid > 1.1 * end
            out.append(f"- {scene}: kiss with deskew scored at the sweep end drifts {_f(end, none='n/a')} % vs "
                       f"{_f(d[(scene, False, 'end')], none='n/a')} % without deskew; the same deskewed estimate scored against mid-sweep poses "
                       f"reads {_f(mid, none='n/a')} %{' (a mismatched instant inflates it)' if inflated else ''}; without deskew the mid-sweep score is "
                       f"{_f(d[(scene, False, 'mid')], none='n/a')} %.")
    g = {(r["scene"], r["method"]): r for r in report.get("ground", [])}
    for scene in ("street", "open"):
        if (scene, "vanilla") in g:
            v, f = g[(scene, "vanilla")], g[(scene, "ground_filtered")]
            out.append(f"- {scene}: full-cloud vanilla drifts {_f(v['drift_pct'], '.1f', 'n/a')} % (path {v['estimated_length_m']:.0f} m of "
                       f"{v['gt_length_m']:.0f} m, {v['n_not_converged']} frames not converged); ground_filtered {_f(f['drift_pct'], '.1f', 'n/a')} % "
                       f"(path {f['estimated_length_m']:.0f} m).")
    return [line for line in out if line]


def read_results(path: Path) -> dict:
    """An earlier run's results.json (for --rerender and to merge into): a DataError naming it when it is missing or
    unreadable (a FileNotFoundError traceback before)."""
    if not path.is_file():
        raise DataError("not found: run the benchmark into this --out first", source=path)
    try:
        data = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise DataError(f"not a readable JSON file ({err})", source=path) from None
    if not isinstance(data, dict) or "settings" not in data:
        raise DataError("not a results.json of this benchmark: no settings", source=path)
    return data


def merged(report: dict, previous: dict, sections: Iterable[str]) -> dict:
    """``previous`` with this run's sections put in (a --sections run rewrote results.json with the others emptied);
    refused when the settings differ, as one header would then describe numbers of other sequences."""
    if previous["settings"] != report["settings"]:
        diff = ", ".join(f"{k} {previous['settings'].get(k)} there, {v} here" for k, v in report["settings"].items()
                         if previous["settings"].get(k) != v)
        raise DataError(f"holds results of other settings ({diff}): use another --out or the same settings", source="--out")
    out = dict(previous)
    for letter in sections:
        out[SECTIONS[letter]] = report[SECTIONS[letter]]
        out[f"{SECTIONS[letter]}_measured"] = {k: report[k] for k in ("date", "machine", "command")}
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    parser.add_argument("--frames", type=int, default=300)
    parser.add_argument("--beams", type=int, default=64)
    parser.add_argument("--azimuths", type=int, default=2000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--noise", type=float, default=0.02, help="range noise std (m)")
    parser.add_argument("--voxel", type=float, default=None, help="voxel size (m) of vanilla and ground_filtered in section D (default: none)")
    parser.add_argument("--d-beams", type=int, default=32, help="beams of the section-D sequences (full-cloud vanilla is slow)")
    parser.add_argument("--d-azimuths", type=int, default=720, help="azimuths of the section-D sequences")
    parser.add_argument("--repeats", type=int, default=5, help="interleaved repeats of the overhead measurement")
    parser.add_argument("--quick", action="store_true", help="120 sweeps of 32 x 720 rays")
    parser.add_argument("--sections", default="ABCDE", help="letters of the sections to run; the others are kept from an "
                        "existing --out/results.json")
    parser.add_argument("--rerender", action="store_true", help="only rewrite README.md from --out/results.json")
    args = parser.parse_args(argv)
    if not args.sections or set(args.sections) - set(SECTIONS):  # (--sections xyz ran nothing and exited 0)
        parser.error(f"--sections takes letters of {''.join(SECTIONS)}, not {args.sections!r}")
    if args.rerender:
        write_text(args.out / "README.md", markdown(read_results(args.out / "results.json")))
        return 0
    if args.quick:
        args.frames, args.beams, args.azimuths = 120, 32, 720
    from lidarkit.sim.lidar import SimulatedLidarSequence

    sims = {
        scene: SimulatedLidarSequence(scene=scene, n_frames=args.frames, n_beams=args.beams, n_azimuths=args.azimuths,
                                      range_noise_std_m=args.noise, seed=args.seed)
        for scene in ("street", "open")
    }
    report: dict = {
        "date": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"),
        "machine": describe_machine(machine_info()),
        "command": "python benchmarks/odometry_sim.py " + " ".join(argv if argv is not None else sys.argv[1:]),
        "settings": {"frames": args.frames, "beams": args.beams, "azimuths": args.azimuths, "seed": args.seed, "noise_m": args.noise,
                     "voxel_m": args.voxel, "d_beams": args.d_beams, "d_azimuths": args.d_azimuths},
        "kitti": [], "overhead": [], "deskew": [], "ground": [], "pairs": [],
    }
    every = set(args.sections) == set(SECTIONS)
    previous = None if every or not (args.out / "results.json").exists() else read_results(args.out / "results.json")
    if previous is not None:
        merged(report, previous, ())  # (refuses other settings before hours of work)
    args.out.mkdir(parents=True, exist_ok=True)
    ran: list[str] = []

    def save(section: str | None = None) -> None:
        ran.extend([section] if section else [])
        whole = report if previous is None else merged(report, previous, ran)
        write_text(args.out / "results.json", json.dumps(whole, indent=2, default=float) + "\n")
        write_text(args.out / "README.md", markdown(whole))

    if "A" in args.sections:
        report["kitti"] = section_kitti(args.data)
        save("A")
    if "B" in args.sections:
        report["overhead"] = section_overhead(args.data, InMemory(sims["street"], min(100, args.frames)), args.repeats)
        save("B")
    if "C" in args.sections:
        report["deskew"] = section_deskew(sims)
        save("C")
        from lidarkit.eval import plots

        result = run(sims["street"], "kiss", params={"voxel_size_m": 1.0})
        plots.plot_trajectories(result.ground_truth.with_name("ground truth (sweep end)"), result.trajectory,
                                args.out / "kiss_street_deskew.png", title="kiss (deskew) on the simulated street")
    if "D" in args.sections:
        d_sims = {
            scene: SimulatedLidarSequence(scene=scene, n_frames=args.frames, n_beams=args.d_beams, n_azimuths=args.d_azimuths,
                                          range_noise_std_m=args.noise, seed=args.seed)
            for scene in ("street", "open")
        }
        report["ground"] = section_ground(d_sims, args.voxel)
        save("D")
    if "E" in args.sections:
        report["pairs"] = section_pairs(sims)
        save("E")
    log(f"wrote {args.out / 'README.md'}")
    return 0


if __name__ == "__main__":
    from lidarkit.cli import run_script

    run_script(main)
