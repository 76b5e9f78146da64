"""lidarkit.params.parse_kv: the one KEY=VALUE parser behind --param/--set, dataset specs and simulator specs."""

from __future__ import annotations

import pytest

from lidarkit.cli.app import parse_params
from lidarkit.errors import ConfigError
from lidarkit.params import parse_kv


def test_values_are_yaml_scalars_with_safe_exceptions():
    got = parse_kv("a=1&b=x&c=true&e=null&f=0.5&g=1e-3&seq=05&date=2011_09_26&day=2011-09-26&amp=a%26b&plus=1+2")
    assert got == {
        "a": 1, "b": "x", "c": True, "e": None, "f": 0.5, "g": 0.001,
        "seq": "05", "date": "2011_09_26", "day": "2011-09-26", "amp": "a&b", "plus": "1+2",
    }
    assert parse_kv(["n_beams=32", "pose_instant=mid", "flag=false"]) == {"n_beams": 32, "pose_instant": "mid", "flag": False}


@pytest.mark.parametrize("bad", [["novalue"], ["=3"], ["a=1", "a=2"], "a=1&novalue", "a=1&a=2"])
def test_bad_items_name_the_option(bad):
    with pytest.raises(ConfigError, match="my-option"):
        parse_kv(bad, option="my-option")


def test_cli_parse_params_is_the_same_parser():
    assert parse_params(["a=05", "b=1e-3"]) == {"a": "05", "b": 0.001}
    with pytest.raises(ConfigError, match=r"--set 'x'"):
        parse_params(["x"], option="--set")


def test_dataset_and_simulator_specs_use_it(tmp_path):
    from lidarkit.odometry import open_sequence
    from lidarkit.sim.lidar import open_sim

    with pytest.raises(ConfigError, match="expected KEY=VALUE"):
        open_sequence(f"kitti:{tmp_path}?sequence")  # used to be read as sequence=None
    with pytest.raises(ConfigError, match="expected KEY=VALUE"):
        open_sim("sim:street?frames=2&beams")
    sim = open_sim("sim:street?frames=2&beams=8&azimuths=90&distortion=false&noise=0")
    assert sim.config.n_beams == 8 and sim.config.motion_distortion is False and sim.config.range_noise_std_m == 0
    with pytest.raises(ConfigError, match="given twice"):
        open_sim("sim:street?frames=2&n_frames=3")


def test_an_empty_value_in_a_spec_is_refused_naming_the_option(tmp_path):
    """rosbag:r1.bag?time_field= read no per-point times (config.yaml time_field: null), ?topic= meant auto,
    kitti:...?poses_file= the default poses and ?sequence= "Input should be a valid string, got None": an empty value
    read as None without a word."""
    from lidarkit.odometry import open_sequence

    with pytest.raises(ConfigError) as err:
        parse_kv("topic=/points&time_field=", option="rosbag dataset option")
    assert str(err.value) == "rosbag dataset option: time_field= has no value; give one, or leave time_field out for its default"
    with pytest.raises(ConfigError) as err:
        open_sequence(f"kitti:{tmp_path}?sequence=%20")
    assert str(err.value) == "kitti dataset option: sequence= has no value; give one, or leave sequence out for its default"
    assert parse_kv("time_field=null&topic=%2Fpoints") == {"time_field": None, "topic": "/points"}


@pytest.mark.parametrize("item, reason", [
    ("kernel={name: huber", "flow mapping not closed"),
    ("preprocess=[voxel, crop", "flow sequence not closed"),
    ("ground_params={sensor_height_m: 1.8}}", "text after the closing bracket at character 23"),
])
def test_a_braced_value_yaml_cannot_read_names_the_key_and_yaml_s_reason(item, reason, capsys):
    """Kept as text, ``kernel={name: huber`` failed later as "unknown kernel component '{name: huber'" and
    ``ground_params={...`` as "Input should be a valid dictionary"."""
    from conftest import cli_exit_code
    from lidarkit.samples import sample_path

    key, _, value = item.partition("=")
    said = f"--param {key}: {value!r} is not valid YAML ({reason})"
    with pytest.raises(ConfigError) as err:
        parse_params([item])
    assert str(err.value) == said
    pair = [str(sample_path("kitti_pair", name)) for name in ("000095.npy", "000094.npy")]
    assert cli_exit_code(["icp", *pair, "-m", "pipeline", "-p", item]) == 1
    assert capsys.readouterr().err.strip().splitlines() == [f"error: {said}"]
    assert parse_params(["kernel={name: huber}", "preprocess=[voxel, crop]"]) == {
        "kernel": {"name": "huber"}, "preprocess": ["voxel", "crop"]}


def test_a_spec_s_braced_value_yaml_cannot_read_is_refused_too():
    with pytest.raises(ConfigError, match=r"^simulator option kernel: '\{name: huber' is not valid YAML \(flow mapping not closed\)$"):
        parse_kv("n_beams=32&kernel=%7Bname: huber", option="simulator option")
