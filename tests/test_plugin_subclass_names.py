"""How a variant class outside the registry is recorded: a subclass of a built-in inherited its ``name``, so a vanilla
with another ``_align`` ran, was scored and was written to config.yaml as ``vanilla`` (re-running that config ran
vanilla); it is now ``Sub(vanilla)``, and asking for that name says why it cannot be run."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from lidarkit.errors import ConfigError
from lidarkit.odometry import run
from lidarkit.registration import get_icp
from lidarkit.registration import registry as icp_registry
from lidarkit.registration.kiss import KissRegistration
from lidarkit.registration.vanilla import VanillaICP
from lidarkit.sim.lidar import SimulatedLidarSequence


class Stretched(VanillaICP):
    """vanilla on a source scaled by 1 %: another algorithm under vanilla's name and config."""

    def _align(self, source_xyz, target_xyz, init_T):
        return super()._align(source_xyz * 1.01, target_xyz, init_T)


def _street() -> SimulatedLidarSequence:
    return SimulatedLidarSequence(scene="street", n_frames=4, seed=3, n_beams=16, n_azimuths=360)


def test_a_run_of_an_unregistered_subclass_records_what_it_derives_from_and_is_not_rerun_as_its_parent(tmp_path):
    result = run(_street(), Stretched(), out_dir=tmp_path / "run", progress=False)
    config = yaml.safe_load((tmp_path / "run" / "config.yaml").read_text())
    assert result.method == result.metrics["method"] == config["method"] == "Stretched(vanilla)"
    with pytest.raises(ConfigError, match=r"^method: 'Stretched\(vanilla\)' is how runs record Stretched, a subclass of vanilla "
                                          r"outside the registry: it cannot be run by name until it is registered"):
        get_icp(config["method"], **config["method_config"])  # (ran vanilla)


def test_the_calibration_note_names_the_unregistered_subclass_that_inherits_it():
    street = _street()
    target, source = street.read_scan(0).points_xyz, street.read_scan(1).points_xyz
    derived = Stretched(voxel_size_m=0.5).align(source, target)
    assert derived.method == "Stretched(vanilla)"
    assert derived.extra["covariance_calibration"] == "vanilla's (inherited by Stretched(vanilla))"  # (read "vanilla")


def test_the_distortion_floor_note_names_the_entry_an_unregistered_subclass_is_widened_by():
    """The run's note named DISTORTION_SIGMA['Stretched(vanilla)'], an entry that does not exist: the frames were
    widened by vanilla's, which the note now names."""
    from lidarkit.registration.covariance import DISTORTION_SIGMA

    street = SimulatedLidarSequence(scene="street", n_frames=3, seed=3, n_beams=16, n_azimuths=180)  # (point times)
    result = run(street, Stretched(), progress=False)  # (registered without deskew)
    note = result.config["run"]["covariance_distortion_floor"]
    assert "Stretched(vanilla)" not in DISTORTION_SIGMA
    assert note == ("2 frames: motion-distorted sweeps registered without deskew, frame covariance widened by "
                    "DISTORTION_SIGMA['vanilla']")


def test_registered_and_self_named_subclasses_keep_their_names_and_a_subclass_reads_data_as_its_parent(monkeypatch):
    class OwnName(VanillaICP):
        name = "own_vanilla"

    class Pretender(VanillaICP):
        name = "kiss"  # another variant's name, not registered for it

    class Registered(VanillaICP):
        pass

    class Quieter(KissRegistration):
        pass

    monkeypatch.setattr(Registered, "name", "registered_vanilla")
    monkeypatch.setitem(icp_registry._VARIANTS, "registered_vanilla", Registered)
    assert OwnName().name == "own_vanilla" and Registered().name == "registered_vanilla"
    assert Pretender().name == "Pretender(vanilla)" and get_icp("vanilla").name == "vanilla"
    # a reader prepares the data for the variant the subclass derives from (KITTI's vertical-angle correction for kiss)
    assert Quieter().name == "Quieter(kiss)" and Quieter().reads_data_as == "kiss"
    assert get_icp("kiss").reads_data_as is None and OwnName().reads_data_as is None


def test_a_list_or_mapping_for_a_choice_is_a_config_error():
    """preset=[] raised a bare "unhashable type: 'list'" from the preset lookup."""
    from lidarkit.registration.pipeline import PipelineRegistration

    for value in ([], {"kiss_like": 1}):
        with pytest.raises(ConfigError, match=r"^method 'pipeline': invalid parameters \(preset: one of 'kiss_like' \| "
                                              r"'vanilla_seq' \| None, got (list|dict) .*\); valid parameters: "):
            get_icp("pipeline", preset=value)
        with pytest.raises(ConfigError, match=r"^pipeline: invalid parameters \(preset: one of 'kiss_like'"):
            PipelineRegistration(preset=value)
    with pytest.raises(ConfigError, match=r"nn_backend: one of 'auto' \| 'scipy' \| 'open3d' \| 'brute', got list \['scipy'\]"):
        get_icp("vanilla", nn_backend=["scipy"])
    assert get_icp("pipeline", preset="kiss_like").config.preset == "kiss_like"
    assert np.isfinite(get_icp("vanilla", nn_backend="scipy").config.max_iterations)


def test_a_label_with_parameters_given_as_the_method_says_how_to_write_that_method():
    """``--method "vanilla(voxel_size_m=0.5)"`` (a report's row label) read as the record of a subclass "vanilla" of a
    variant "voxel_size_m=0.5" outside the registry. A parent is a plain variant name; a label says it is one."""
    with pytest.raises(ConfigError) as caught:
        get_icp("vanilla(voxel_size_m=0.5)")
    assert str(caught.value) == (
        "method: 'vanilla(voxel_size_m=0.5)' is a label (the variant vanilla with its parameters), not a method name: "
        "write the method as {name: vanilla, params: {voxel_size_m: 0.5}} (CLI: --method vanilla -p voxel_size_m=0.5)")
    with pytest.raises(ConfigError) as caught:
        get_icp("vanilla(max_iterations=5, voxel_size_m=0.5)")
    assert str(caught.value) == (
        "method: 'vanilla(max_iterations=5, voxel_size_m=0.5)' is a label (the variant vanilla with its parameters), not "
        "a method name: write the method as {name: vanilla, params: {max_iterations: 5, voxel_size_m: 0.5}} (CLI: "
        "--method vanilla -p max_iterations=5 -p voxel_size_m=0.5)")
    with pytest.raises(ConfigError, match=r"^method: 'Sub\(vanilla\)' is how runs record Sub, a subclass of vanilla"):
        get_icp("Sub(vanilla)")
