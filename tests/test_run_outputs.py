"""The library's run-folder writers (``lidarkit.odometry.write_run``, ``lidarkit.vo.output.write_run``) refuse a folder
of the user's own files named like a run's, as ``run(out_dir=...)`` and the CLI commands do."""

from __future__ import annotations

import pytest
from conftest import shared_path

from lidarkit.errors import OutputError
from lidarkit.samples import sample_path


def _refused_message(folder) -> str:
    return (f"{folder}: holds files named like a run's (metrics.json) but no config.yaml written by lidarkit (the user's "
            "own, or a run cut off before it was complete): a run would replace them; remove them or give a new or empty folder")


def _users_folder(tmp_path):
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "metrics.json").write_text("mine\n")
    return mine


def test_odometry_write_run_refuses_a_folder_of_the_users_own_files(tmp_path):
    """`write_run(run(...), "userdir3")` replaced the user's own userdir3/metrics.json (run(out_dir=...) refused that
    folder, write_run skipped the check). Refused, untouched; a new folder and then that run's folder are written."""
    from lidarkit.odometry import run, write_run

    result = run(str(shared_path("kitti_odometry", "sequences", "00")), "vanilla", frames="0:2")
    mine = _users_folder(tmp_path)
    with pytest.raises(OutputError) as info:
        write_run(result, mine)
    assert str(info.value) == _refused_message(mine)
    assert [p.name for p in mine.iterdir()] == ["metrics.json"] and (mine / "metrics.json").read_text() == "mine\n"
    for _ in range(2):  # a new folder, then the folder of that run
        assert write_run(result, tmp_path / "run") == tmp_path / "run"
    assert len((tmp_path / "run" / "poses_kitti.txt").read_text().splitlines()) == 2


def test_vo_write_run_refuses_a_folder_of_the_users_own_files(tmp_path):
    """lidarkit.vo.output.write_run replaced the user's own metrics.json, which `lidarkit vo --out` refuses. Refused,
    untouched; a new folder and then that run's folder are written."""
    from lidarkit.vo import preset, run_vo
    from lidarkit.vo.inputs import open_vo_input
    from lidarkit.vo.output import write_run

    vo_input = open_vo_input(sample_path("kitti_vo", "06"))
    images = [vo_input.images.read_image(i) for i in range(3)]
    result = run_vo(images, vo_input.K, preset("lidarkit", **{"scale.mode": "gt"}), ground_truth=vo_input.ground_truth[:3])
    mine = _users_folder(tmp_path)
    with pytest.raises(OutputError) as info:
        write_run(result, mine, plot=False)
    assert str(info.value) == _refused_message(mine)
    assert [p.name for p in mine.iterdir()] == ["metrics.json"] and (mine / "metrics.json").read_text() == "mine\n"
    for _ in range(2):  # a new folder, then the folder of that run
        paths = write_run(result, tmp_path / "run", plot=False)
    assert paths["metrics"] == tmp_path / "run" / "metrics.json"
    assert len((tmp_path / "run" / "poses_kitti.txt").read_text().splitlines()) == 3
