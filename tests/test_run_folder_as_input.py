"""Folders lidarkit wrote (run folders, bench results, baselines) given where a dataset is read: refused by name, before
any output is written."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from lidarkit.cli import main
from lidarkit.errors import DataError
from lidarkit.io.folder import ScanFolder
from lidarkit.io.images import ImageFolder


def _run_cli(argv: list[str], capsys) -> tuple[int, str]:
    with pytest.raises(SystemExit) as exc:
        main(argv)
    return int(exc.value.code or 0), capsys.readouterr().err


def _odometry_run(root: Path) -> Path:
    """A folder as ``lidarkit odometry --out`` leaves it: poses, config, metrics and two plots of other sizes."""
    folder = root / "run"
    folder.mkdir()
    (folder / "metrics.json").write_text(json.dumps({"method": "kiss", "n_frames": 2}))
    (folder / "config.yaml").write_text("method: kiss\n")
    np.savetxt(folder / "poses_kitti.txt", np.tile(np.eye(4)[:3].ravel(), (2, 1)))
    cv2.imwrite(str(folder / "trajectory.png"), np.zeros((350, 800), np.uint8))
    cv2.imwrite(str(folder / "ape.png"), np.zeros((600, 650), np.uint8))
    return folder


def _bench_results(root: Path) -> Path:
    folder = root / "results"
    (folder / "jobs").mkdir(parents=True)
    (folder / "suite.json").write_text(json.dumps({"jobs": [], "lidarkit_version": "0", "suite_file": str(root / "s.yaml")}))
    return folder


def _baseline(root: Path) -> Path:
    folder = root / "baseline"
    (folder / "jobs").mkdir(parents=True)
    (folder / "manifest.json").write_text(json.dumps({"schema": "lidarkit-baseline/1", "jobs": []}))
    (folder / "suite.yaml").write_text("name: s\nexperiments: []\n")
    return folder


KINDS = [
    (_odometry_run, "an odometry run folder (metrics.json, config.yaml)"),
    (_bench_results, "a bench results folder (jobs/, suite.json)"),
    (_baseline, "a baseline folder (manifest.json)"),
]


def test_vo_over_an_odometry_run_folder_is_refused_before_its_run_folder_is_written(tmp_path, capsys):
    """`lidarkit vo RUN_FOLDER` read the run's plots as camera images, wrote a VO run and then failed on their sizes."""
    run = _odometry_run(tmp_path)
    code, err = _run_cli(["vo", str(run), "--out", str(tmp_path / "vo"), "--no-progress"], capsys)
    assert (code, err) == (1, f"error: {run}: an odometry run folder (metrics.json, config.yaml): lidarkit's output, "
                              "not an image sequence\n")
    assert not (tmp_path / "vo").exists()


@pytest.mark.parametrize("make, kind", KINDS)
def test_odometry_over_lidarkit_output_names_what_the_folder_is(tmp_path, capsys, make, kind):
    """`lidarkit odometry RUN_FOLDER` (or a bench results folder, a baseline) said only "no scan files (.bin, ...)"."""
    folder = make(tmp_path)
    code, err = _run_cli(["odometry", str(folder), "--out", str(tmp_path / "out"), "--no-progress"], capsys)
    assert (code, err) == (1, f"error: {folder}: {kind}: lidarkit's output, not a scan sequence\n")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("make, kind", KINDS)
def test_the_readers_refuse_lidarkit_output_by_name(tmp_path, make, kind):
    folder = make(tmp_path)
    with pytest.raises(DataError) as exc:
        ImageFolder(folder)
    assert str(exc.value) == f"{folder}: {kind}: lidarkit's output, not an image sequence"
    with pytest.raises(DataError) as exc:
        ScanFolder(folder)
    assert str(exc.value) == f"{folder}: {kind}: lidarkit's output, not a scan sequence"


def test_a_vo_run_folder_and_a_results_jobs_folder_are_named_too(tmp_path):
    vo = tmp_path / "vo"
    vo.mkdir()
    for name in ("metrics.json", "config.yaml", "diagnostics.csv"):
        (vo / name).write_text("{}\n")
    cv2.imwrite(str(vo / "trajectory.png"), np.zeros((40, 60), np.uint8))
    with pytest.raises(DataError, match=r"a visual odometry run folder \(metrics.json, config.yaml, diagnostics.csv\): "
                                        "lidarkit's output, not an image sequence$"):
        ImageFolder(vo)
    with pytest.raises(DataError, match=r"the jobs/ folder of bench results \(beside suite.json\): lidarkit's output"):
        ScanFolder(_bench_results(tmp_path) / "jobs")


def test_an_image_folder_beside_other_files_is_still_read(tmp_path):
    """Only the files lidarkit's commands write together make a folder lidarkit's output: a config.yaml of the user's
    beside the images is no run."""
    for i in range(2):
        cv2.imwrite(str(tmp_path / f"{i:06d}.png"), np.zeros((40, 60), np.uint8))
    (tmp_path / "config.yaml").write_text("camera: mine\n")
    assert len(ImageFolder(tmp_path)) == 2


def test_a_users_folder_sharing_one_file_name_with_lidarkits_output_is_still_read(tmp_path):
    """One common name (a sensor's manifest.json beside the scans, a diagnostics.csv beside the images) marked the folder
    as lidarkit's output and refused it, with no way around: output is told by the files lidarkit writes together."""
    import shutil

    from conftest import shared_path

    from lidarkit.io.folder import ScanFolder
    from lidarkit.io.images import ImageFolder

    scans, images = tmp_path / "scans", tmp_path / "images"
    scans.mkdir()
    images.mkdir()
    for n in range(2):
        shutil.copy(shared_path("kitti_odometry", "sequences", "00", "velodyne", f"{n:06d}.bin"), scans)
        shutil.copy(shared_path("kitti_images", "sequences", "06", "image_0", f"{n:06d}.png"), images)
    (scans / "manifest.json").write_text('{"sensor": "os1"}\n')
    (images / "diagnostics.csv").write_text("frame,exposure\n0,1\n")
    assert len(ScanFolder(scans)) == 2 and len(ImageFolder(images)) == 2
