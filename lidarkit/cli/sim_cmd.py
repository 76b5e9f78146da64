"""``lidarkit sim lidar``: write a simulated LiDAR sequence as a KITTI-style folder, a ROS 1/2 bag or an MCAP file.
``lidarkit sim camera``: write a simulated camera sequence (textured street canyon) as a KITTI-odometry-like folder.

The ``sim`` command group is ``sim_app``; other simulators attach their own sub-commands to it.
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Optional

import typer

from lidarkit.cli.app import app, stdout

#: simulator fields with an option of their own (named in their errors; refused as --param)
OWN_OPTIONS = {"scene": "--scene", "n_frames": "--frames/-n", "seed": "--seed"}


def _config(model, scene: str, frames: int, seed: int, params: dict, source: str):
    """Both simulators' config from their options and ``--param`` settings (those with an option of their own refused)."""
    from lidarkit.errors import ConfigError
    from lidarkit.sim.lidar import checked_config

    for key in sorted(OWN_OPTIONS.keys() & params.keys()):
        raise ConfigError(f"{key} has its own option: use {OWN_OPTIONS[key]} instead of --param {key}=...", source=f"--param {key}")
    return checked_config(model, dict(scene=scene, n_frames=frames, seed=seed, **params), source, OWN_OPTIONS)


sim_app = typer.Typer(help="Ground-truth simulators.", no_args_is_help=True)
app.add_typer(sim_app, name="sim")


@sim_app.command("lidar")
def sim_lidar(
    out: Path = typer.Option(..., "--out", "-o", help="Output: a folder for kitti (velodyne/*.bin, point_times/*.npy, poses*.txt, times.txt, calib.txt, sim.yaml), a .bag file for rosbag1, a bag folder for rosbag2, a .mcap file for mcap."),
    fmt: str = typer.Option("kitti", "--format", "-f", help="kitti | rosbag1 | rosbag2 | mcap (bags: PointCloud2 on /points with per-point 'time' float32 s and 't' uint32 ns, nav_msgs/Odometry ground truth on /ground_truth)."),
    storage: Optional[str] = typer.Option(None, "--storage", help="ROS 2 bag storage: sqlite3 (default) | mcap (only with --format rosbag2)."),
    frames: int = typer.Option(300, "--frames", "-n", help="Number of sweeps."),
    scene: str = typer.Option("street", "--scene", help="street | open | ground"),
    seed: int = typer.Option(0, "--seed", help="Seeds the scene, the path and the range noise."),
    param: list[str] = typer.Option([], "--param", "-p", help="Any other simulator field KEY=VALUE (e.g. n_beams=32, range_noise_std_m=0.02, pose_instant=mid, motion_distortion=false)."),
    progress: bool = typer.Option(True, "--progress/--no-progress", help="Progress bar on stderr."),
) -> None:
    """Simulate a spinning LiDAR driving through a procedural scene; poses are T_world_lidar at the sweep end by default."""
    from lidarkit.cli.app import parse_params
    from lidarkit.errors import ConfigError
    from lidarkit.sim.bag_export import BAG_FORMATS, STORAGES, check_bag_target, export_bag
    from lidarkit.sim.lidar import LidarSimConfig, SimulatedLidarSequence, export_kitti

    if fmt not in ("kitti", *BAG_FORMATS):
        raise ConfigError(f"unknown format {fmt!r}; known: kitti, {', '.join(BAG_FORMATS)}", source="--format")
    if storage is not None and fmt != "rosbag2":  # (given at its default value too: it would say nothing)
        raise ConfigError("--storage applies to --format rosbag2 only", source="--storage")
    if storage is not None and storage not in STORAGES:  # (the library's message named "storage", after the scene was built)
        raise ConfigError(f"unknown ROS 2 storage {storage!r}; known: {', '.join(STORAGES)}", source="--storage")
    storage = storage or "sqlite3"

    from lidarkit.atomic import check_target

    if fmt != "kitti":  # before the simulation: a bag's name and that it is not there yet
        check_bag_target(out, fmt, option="--out")
    elif out.suffix.lower() in (".bag", ".mcap"):  # (a KITTI folder named run.bag was written)
        raise ConfigError(f"{out.name} is named like a {'ROS 1 bag' if out.suffix.lower() == '.bag' else 'MCAP file'}, but --format is "
                          f"kitti (a folder): add -f {'rosbag1' if out.suffix.lower() == '.bag' else 'mcap'}, or name a folder", source="--out")
    check_target(out, "file" if fmt in ("rosbag1", "mcap") else "folder")
    params = parse_params(param)
    config = _config(LidarSimConfig, scene, frames, seed, params, "lidar simulator")
    from lidarkit.resources import check_memory
    from lidarkit.sim.lidar import SWEEP_BYTES_PER_RAY

    check_memory(config.n_beams * config.n_azimuths * SWEEP_BYTES_PER_RAY, f"a sweep of {config.n_beams}x{config.n_azimuths} rays",
                 "--param n_beams / n_azimuths")
    sequence = SimulatedLidarSequence(config)
    def export(on_frame=None):
        if fmt == "kitti":
            return export_kitti(sequence, out, on_frame=on_frame)
        return export_bag(sequence, out, fmt, storage=storage, on_frame=on_frame)

    folder = _with_progress(export, frames, f"sim {scene}", "sweeps") if progress else export()
    gt = sequence.ground_truth
    stdout().print(
        f"wrote {frames} sweeps of the {scene} scene to {folder} "
        f"({config.n_beams}x{config.n_azimuths} rays, path {gt.length_m:.1f} m, poses at the sweep {config.pose_instant}; "
        + ("also poses_start/mid/end.txt)" if fmt == "kitti" else f"{fmt} with /points and /ground_truth)")
    )


@sim_app.command("camera")
def sim_camera(
    out: Path = typer.Option(..., "--out", "-o", help="Output folder: image_0/NNNNNN.png, calib.txt, poses.txt (T_cam0_camk), times.txt, sim.yaml."),
    frames: int = typer.Option(500, "--frames", "-n", help="Number of images."),
    scene: str = typer.Option("street", "--scene", help="street"),
    seed: int = typer.Option(0, "--seed", help="Seeds the scene, its textures, the drive and the nuisances."),
    param: list[str] = typer.Option([], "--param", "-p", help="Any other simulator field KEY=VALUE (e.g. noise_std=2, motion_blur_s=0.01, gain_std=0.05, vignetting=0.3, occluder=true, trees=true; width=640 with cx=null cy=null centres the principal point, else KITTI's stays)."),
    progress: bool = typer.Option(True, "--progress/--no-progress", help="Progress bar on stderr."),
) -> None:
    """Simulate a camera driving through a textured street canyon (KITTI image size and intrinsics by default);
    read the folder back with `lidarkit vo OUT` (or skip the files: `lidarkit vo 'simcam:street?frames=500&seed=0'`)."""
    from lidarkit.atomic import check_target
    from lidarkit.cli.app import parse_params
    from lidarkit.sim.street_camera import CameraSimConfig, SimulatedCameraSequence, export_kitti_images

    check_target(out, "folder")
    params = parse_params(param)
    config = _config(CameraSimConfig, scene, frames, seed, params, "camera simulator")
    sequence = SimulatedCameraSequence(config)
    export = functools.partial(export_kitti_images, sequence, out)
    folder = _with_progress(export, frames, f"simcam {scene}", "images") if progress else export()
    cfg = sequence.config
    stdout().print(f"wrote {frames} images of the {scene} scene to {folder} ({cfg.width}x{cfg.height}, fx {cfg.fx:g} px, "
                   f"path {sequence.ground_truth.length_m:.1f} m)")


def _with_progress(export, total: int, label: str, unit: str):
    """``export(on_frame=...)`` with progress on stderr: a bar on a terminal, a line every tenth elsewhere (a log, CI:
    a 3000-sweep export was minutes without a word)."""
    from lidarkit.progress import progress_bar

    bar, task = progress_bar(total, label, unit)
    try:
        return export(on_frame=lambda _i: bar.advance(task))
    finally:
        bar.stop()


__all__ = ["sim_app"]
