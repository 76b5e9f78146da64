"""Bad user input for the odometry / sim / dataset entry points: one clear ConfigError, never a raw Python error."""

from __future__ import annotations

import re

import numpy as np
import pytest

from conftest import cli_exit_code

from lidarkit.errors import ConfigError
from lidarkit.io import open_dataset
from lidarkit.odometry import open_sequence, parse_frames


_cli = cli_exit_code


def test_open_dataset_unknown_option_lists_the_valid_ones(tmp_path):
    np.save(tmp_path / "000000.npy", np.zeros((5, 3)))
    with pytest.raises(ConfigError, match=r"folder dataset options.*'foo'.*valid options: .*poses"):
        open_dataset("folder", tmp_path, foo=1)
    with pytest.raises(ConfigError, match="valid options: .*sequence"):
        open_sequence(f"kitti:{tmp_path}?sequnce=05")


def test_cli_odometry_unknown_dataset_option_is_one_error_line(tmp_path, capsys):
    np.save(tmp_path / "000000.npy", np.zeros((5, 3)))
    assert _cli(["odometry", f"folder:{tmp_path}?foo=1", "-m", "vanilla", "--no-progress"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("error:") and "foo" in err and "valid options" in err and "Traceback" not in err


def test_spec_option_values_read_as_numbers_or_nothing_are_paths_again_or_refused(tmp_path):
    """A spec's value parser reads ``velodyne_dir=2`` as the number 2 and ``suffixes=`` as nothing: TypeError
    tracebacks in the readers ('NoneType' object is not iterable; expected str, bytes or os.PathLike object, not int),
    and ``kiss_kitti_raw``'s ``sequence=abc`` a ValueError. A number is a folder name again; nothing, a boolean or a
    sequence that is no number is refused naming the option."""
    from conftest import shared_path

    from lidarkit.io.kitti import KittiOdometry

    np.save(tmp_path / "000000.npy", np.zeros((5, 3)))
    for query, line in (("suffixes=", "folder dataset option suffixes: needs a value"),
                        ("suffixes=true", "folder dataset option suffixes: expected a path or text, got True"),
                        ("suffixes=5", "suffixes: unsupported scan suffix '5'")):
        with pytest.raises(ConfigError, match=re.escape(line)):
            open_sequence(f"folder:{tmp_path}?{query}")
    root = shared_path("kitti_odometry")
    with pytest.raises(ConfigError, match="kitti dataset option times_file: expected a path or text, got True"):
        open_sequence(f"kitti:{root}?times_file=true")
    seq = tmp_path / "seq"
    (seq / "2").mkdir(parents=True)  # a velodyne folder named "2"
    for name in ("000000.bin", "000001.bin"):
        (seq / "2" / name).write_bytes((root / "sequences" / "00" / "velodyne" / name).read_bytes())
    (seq / "calib.txt").write_bytes((root / "sequences" / "00" / "calib.txt").read_bytes())
    opened = open_sequence(f"kitti:{seq}?velodyne_dir=2")
    assert isinstance(opened, KittiOdometry) and len(opened) == 2
    with pytest.raises(ConfigError, match=r"kiss_kitti_raw dataset option sequence: a KITTI odometry sequence number \(0-10\), got 'abc'"):
        open_sequence(f"kiss_kitti_raw:{root}?sequence=abc")


def test_cli_sim_param_duplicating_an_option_is_a_config_error(tmp_path, capsys):
    assert _cli(["sim", "lidar", "-o", str(tmp_path / "s"), "-n", "2", "-p", "scene=open", "--no-progress"]) == 1
    err = " ".join(capsys.readouterr().err.split())
    assert err.startswith("error:") and "--scene" in err and "Traceback" not in err
    assert _cli(["sim", "lidar", "-o", str(tmp_path / "s"), "-p", "seed=3", "--no-progress"]) == 1
    assert "--seed" in capsys.readouterr().err


@pytest.mark.parametrize("frames", ["0:10:0", slice(0, 10, 0)])
def test_zero_frame_step_is_a_config_error(frames):
    with pytest.raises(ConfigError, match="step"):
        parse_frames(frames, 20)


def test_cli_odometry_zero_step(capsys):
    assert _cli(["odometry", "sim:street?frames=2&beams=8&azimuths=90", "-m", "vanilla", "--frames", "0:10:0", "--no-progress"]) == 1
    assert "step" in capsys.readouterr().err


def test_cli_odometry_prints_n_a_for_stateful_convergence(capsys):
    assert _cli(["odometry", "sim:street?frames=3&beams=8&azimuths=90", "-m", "kiss", "--no-progress"]) == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "not converged / degenerate │ n/a" in out


def test_spec_with_an_empty_path_is_refused(tmp_path, monkeypatch):
    """``KIND:`` with nothing after the colon passed "" to the reader, which read the current folder (a run over
    whatever scans lay there); refused naming the spec."""
    np.save(tmp_path / "000000.npy", np.zeros((5, 3)))
    monkeypatch.chdir(tmp_path)
    for spec, kind in (("folder:", "folder"), ("kitti:?sequence=00", "kitti"), ("rosbag:", "rosbag")):
        with pytest.raises(ConfigError) as refused:
            open_sequence(spec)
        assert str(refused.value) == f"{spec}: {kind}: with no path (expected {kind}:PATH[?key=value&...])"
    assert len(open_sequence(f"folder:{tmp_path}")) == 1
