"""The files each command writes into a run folder (``--out``), in one place.

A run into a folder replaces every file any of these commands writes there and that this run does not write (see
:func:`lidarkit.atomic.run_folder`'s ``replaces``): an earlier run's ground truth or plots, or another command's
files (a VO run into an odometry run's folder kept its ``ape.png`` and ``timing.csv`` beside the new poses), are never
read as this run's. A user's own files stay. The same files tell a folder of lidarkit's output given where a dataset
or a suite is read (:func:`output_folder_kind`).
"""

from __future__ import annotations

import os
from pathlib import Path

ODOMETRY = ("poses_kitti.txt", "poses_tum.txt", "ground_truth_kitti.txt", "config.yaml", "metrics.json", "timing.csv",
            "pose_covariance.txt", "trajectory.png", "ape.png")
VO = ("poses_kitti.txt", "poses_tum.txt", "poses_smoothed_kitti.txt", "poses_smoothed_tum.txt", "diagnostics.csv",
      "config.yaml", "metrics.json", "trajectory.png", "features.gif")
PF = ("config.yaml", "metrics.json", "study.json", "poses_kitti.txt", "poses_tum.txt", "dead_reckoning_tum.txt",
      "ground_truth_tum.txt", "trajectory.png", "particles.png", "particles_per_step.png", "animation.gif")

#: every name above: what a run into a folder replaces
RUN_FILES = tuple(sorted(set(ODOMETRY) | set(VO) | set(PF)))
#: what `lidarkit icp --out` writes (it replaces nothing else)
ICP = ("result.json", "config.json", "bev.png", "rmse.png")

#: what `lidarkit baseline record --out` writes beside its jobs/ and suite.yaml
BASELINE_MANIFEST = "manifest.json"


def run_kind(path: str | os.PathLike) -> str | None:
    """``"particle-filter"`` / ``"visual odometry"`` / ``"icp"`` / ``"odometry"`` for a run folder of ``lidarkit pf`` /
    ``vo`` / ``icp`` / ``odometry``, by the files only that command writes (an odometry run: metrics.json and
    config.yaml, none of the others'); None for any other folder."""
    path = Path(path)
    if (path / "dead_reckoning_tum.txt").is_file() or (path / "study.json").is_file():
        return "particle-filter"
    if (path / "poses_smoothed_kitti.txt").is_file() or (path / "diagnostics.csv").is_file():
        return "visual odometry"
    if (path / "result.json").is_file() and (path / "config.json").is_file() and not (path / "metrics.json").exists():
        return "icp"
    if (path / "metrics.json").is_file() and (path / "config.yaml").is_file():
        return "odometry"
    return None


def is_baseline_folder(path: str | os.PathLike) -> bool:
    """A folder ``lidarkit baseline record`` wrote (manifest.json, no suite.json)."""
    return (Path(path) / BASELINE_MANIFEST).is_file() and not (Path(path) / "suite.json").exists()


def is_bench_results_folder(path: str | os.PathLike) -> bool:
    """A folder ``lidarkit bench`` wrote its results into (jobs/ and suite.json)."""
    return (Path(path) / "jobs").is_dir() and (Path(path) / "suite.json").is_file()


def output_folder_kind(path: str | os.PathLike) -> str:
    """What lidarkit output the folder ``path`` holds, with the files that tell (``"an odometry run folder (metrics.json,
    config.yaml)"``), or '' for none: readers refuse such a folder as a dataset before any output is written (a VO run
    read an odometry run's plots as camera images; odometry said only "no scan files")."""
    path = Path(path)
    if is_bench_results_folder(path):
        return "a bench results folder (jobs/, suite.json)"
    if is_baseline_folder(path) and ((path / "jobs").is_dir() or (path / "suite.yaml").is_file()):
        return f"a baseline folder ({BASELINE_MANIFEST})"  # (a manifest.json alone is any sensor's or tool's)
    if path.name == "jobs" and is_bench_results_folder(path.parent):
        return "the jobs/ folder of bench results (beside suite.json)"
    kind = run_kind(path)
    if kind is None or not _written_together(path):
        return ""
    telling = ("metrics.json", "config.yaml", "study.json", "dead_reckoning_tum.txt", "diagnostics.csv", "result.json",
               "config.json")
    held = ", ".join(name for name in telling if (path / name).is_file())
    return f"{'an' if kind[0] in 'aeiou' else 'a'} {kind} run folder ({held})"


def _written_together(path: Path) -> bool:
    """Whether ``path`` holds files lidarkit writes together, not one name a user's own data may share (a scan folder
    beside its sensor's manifest.json, images beside a diagnostics.csv were refused as lidarkit's output): three of a
    run's files, or the pairs a particle-filter study and ``lidarkit icp`` write alone."""
    held = {name for name in (*RUN_FILES, *ICP) if (path / name).is_file()}
    return len(held) >= 3 or {"study.json", "config.yaml"} <= held or {"result.json", "config.json"} <= held


__all__ = ["BASELINE_MANIFEST", "ICP", "ODOMETRY", "PF", "RUN_FILES", "VO", "is_baseline_folder",
           "is_bench_results_folder", "output_folder_kind", "run_kind"]
