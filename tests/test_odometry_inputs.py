"""Bad user input for the odometry / sim / dataset entry points: one clear ConfigError, never a raw Python error."""

from __future__ import annotations

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
