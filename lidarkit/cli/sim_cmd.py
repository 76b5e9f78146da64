"""``lidarkit sim lidar``: write a simulated LiDAR sequence as a KITTI-style folder.

The ``sim`` command group is ``sim_app``; other simulators attach their own sub-commands to it.
"""

from __future__ import annotations

from pathlib import Path

import typer
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

from lidarkit.cli.app import app, stderr, stdout

sim_app = typer.Typer(help="Ground-truth simulators.", no_args_is_help=True)
app.add_typer(sim_app, name="sim")


@sim_app.command("lidar")
def sim_lidar(
    out: Path = typer.Option(..., "--out", "-o", help="Output folder (velodyne/*.bin, point_times/*.npy, poses*.txt, times.txt, calib.txt, sim.yaml)."),
    frames: int = typer.Option(300, "--frames", "-n", help="Number of sweeps."),
    scene: str = typer.Option("street", "--scene", help="street | open | ground"),
    seed: int = typer.Option(0, "--seed", help="Seeds the scene, the path and the range noise."),
    param: list[str] = typer.Option([], "--param", "-p", help="Any other simulator field KEY=VALUE (e.g. n_beams=32, range_noise_std_m=0.02, pose_instant=mid, motion_distortion=false)."),
    progress: bool = typer.Option(True, "--progress/--no-progress", help="Progress bar on stderr."),
) -> None:
    """Simulate a spinning LiDAR driving through a procedural scene; poses are T_world_lidar at the sweep end by default."""
    from lidarkit.cli.app import parse_params
    from lidarkit.errors import ConfigError
    from lidarkit.sim.lidar import SimulatedLidarSequence, export_kitti, make_config

    from lidarkit.atomic import check_target

    check_target(out, "folder")
    params = parse_params(param)
    own = {"scene": "--scene", "n_frames": "--frames", "seed": "--seed"}
    for key in sorted(own.keys() & params.keys()):
        raise ConfigError(f"{key} has its own option: use {own[key]} instead of --param {key}=...", source=f"--param {key}")
    config = make_config(scene=scene, n_frames=frames, seed=seed, **params)
    sequence = SimulatedLidarSequence(config)
    if progress:
        with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(), console=stderr(), transient=True) as bar:
            task = bar.add_task(f"sim {scene}", total=frames)
            folder = export_kitti(sequence, out, on_frame=lambda _i: bar.advance(task))
    else:
        folder = export_kitti(sequence, out)
    gt = sequence.ground_truth
    stdout().print(
        f"wrote {frames} sweeps of the {scene} scene to {folder} "
        f"({config.n_beams}x{config.n_azimuths} rays, path {gt.length_m:.1f} m, poses at the sweep {config.pose_instant}; "
        f"also poses_start/mid/end.txt)"
    )


__all__ = ["sim_app"]
