"""``lidarkit icp``: every registered method through the CLI on the bundled KITTI sample pair."""

from __future__ import annotations

import json

import numpy as np
import pytest

from conftest import cli_exit_code

from lidarkit.geometry import pose_error
from lidarkit.registration import available_icp, config_fields
from lidarkit.samples import sample_path

SOURCE = sample_path("kitti_pair", "000095.npy")
TARGET = sample_path("kitti_pair", "000094.npy")
T_GT = np.loadtxt(sample_path("kitti_pair", "T_target_source.txt"))


def run_cli(capsys, *args: str) -> tuple[int, str, str]:
    code = cli_exit_code(["icp", *args])
    out = capsys.readouterr()
    return code, out.out, out.err


def test_sample_pair_is_small_and_consistent():
    total = sum(p.stat().st_size for p in sample_path("kitti_pair").iterdir())
    assert total < 2.5e6
    src, dst = np.load(SOURCE), np.load(TARGET)
    assert src.dtype == np.float32 and src.shape[1] == 3 and len(src) > 50_000 and len(dst) > 50_000
    assert pose_error(np.eye(4), T_GT)[0] > 0.4  # the identity is clearly wrong: registration has work to do


@pytest.mark.parametrize("method", available_icp())
def test_every_method_through_the_cli(method, capsys, tmp_path):
    code, out, err = run_cli(capsys, str(SOURCE), str(TARGET), "--method", method, "--out", str(tmp_path))
    assert code == 0, err
    assert "T_target_source" in out and "degeneracy" in out
    result = json.loads((tmp_path / "result.json").read_text())
    assert result["method"] == method and result["converged"] and not result["degeneracy"]["degenerate"]
    dt, dr = pose_error(np.asarray(result["T_target_source"]), T_GT)
    assert dt < 0.06 and dr < 0.15, (method, dt, dr)
    config = json.loads((tmp_path / "config.json").read_text())
    assert config["method"] == method and set(config["params"]) == set(config_fields(method))
    png = (tmp_path / "bev.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000
    assert (tmp_path / "rmse.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"  # the report's RMSE-per-iteration figure
    if result.get("covariance") is not None:  # sigmas to 3 significant digits (a fixed .4f printed 1 mm as 0.0011, 0.04 mm as 0.0000)
        sigma = np.sqrt(np.diag(np.asarray(result["covariance"])))
        assert f"t {sigma[0]:.3g} " in " ".join(out.split()), (method, sigma[0])


def test_params_and_init_file(capsys, tmp_path):
    init = tmp_path / "init.txt"
    np.savetxt(init, np.round(T_GT, 4))  # rounded rotation: re-orthonormalized on the way in
    code, _, err = run_cli(
        capsys, str(SOURCE), str(TARGET), "-m", "vanilla", "-p", "max_iterations=1", "-p", "coarse_stride=1",
        "--init", str(init), "--out", str(tmp_path),
    )
    assert code == 0, err
    result = json.loads((tmp_path / "result.json").read_text())
    assert result["iterations"] <= 1 and pose_error(np.asarray(result["T_target_source"]), T_GT)[0] < 0.03
    kitti_row = tmp_path / "row.txt"
    kitti_row.write_text(" ".join(f"{v:.9f}" for v in T_GT[:3].ravel()) + "\n")
    assert run_cli(capsys, str(SOURCE), str(TARGET), "-m", "open3d_gicp", "--init", str(kitti_row))[0] == 0


def test_list_shows_every_method_and_its_defaults(capsys):
    code, out, _ = run_cli(capsys, "--list")
    assert code == 0
    flat = " ".join(out.split())
    for name in available_icp():
        assert name in flat
    assert "epsilon_m2" in flat and "1e-06" in flat and "max_range_m" in flat
    from lidarkit.registration.ground import available_ground_segmenters

    for name in available_ground_segmenters():  # the ground segmenters ground_filtered can use, with their parameters
        assert name in flat
    assert "[italic]" not in out and "[/" not in out  # the docstrings are styled, not printed with markup tags
    code, out, _ = run_cli(capsys, "--list-components")
    assert code == 0 and "Constant-velocity prediction" in out and "[italic]" not in out
    assert "cell_size_m" in flat and "cloth_resolution_m" in flat



def test_a_listing_refuses_the_options_of_a_run(capsys, tmp_path):
    """`icp SOURCE TARGET -m vanilla -o DIR --list-components` printed the table and exited 0 (no registration, no
    DIR), `--list -m nosuch -p bogus=1` every variant: the run's arguments given with a listing are now refused, named."""
    out_dir = tmp_path / "newdir"
    code, out, err = run_cli(capsys, str(SOURCE), str(TARGET), "-m", "vanilla", "-o", str(out_dir), "--list-components")
    assert (code, out) == (1, "") and not out_dir.exists()
    assert " ".join(err.split()) == "error: --list-components: lists and exits, registering nothing: SOURCE, TARGET, --method, --out do not apply"
    code, out, err = run_cli(capsys, "--list", "-m", "nosuch", "-p", "bogus=1", "--init", "/nonexistent", "--drop-nonfinite")
    assert (code, out) == (1, "")
    assert " ".join(err.split()) == "error: --list: lists and exits, registering nothing: --method, --param, --init, --drop-nonfinite do not apply"
    code, out, _ = run_cli(capsys, "--list", "--list-components")  # both flags: both listings
    assert code == 0 and "ICP variants" in out and "pipeline components" in out

@pytest.mark.parametrize(
    "args, fragment",
    [
        (["--method", "nope"], "unknown ICP method 'nope'"),
        (["-p", "max_iterationz=3"], "max_iterationz"),
        (["-p", "novalue"], "KEY=VALUE"),
    ],
)
def test_cli_errors_are_one_line(capsys, args, fragment):
    code, _, err = run_cli(capsys, str(SOURCE), str(TARGET), *args)
    assert code == 1 and fragment in " ".join(err.split()) and "Traceback" not in err


def test_cli_bad_files(capsys, tmp_path):
    code, _, err = run_cli(capsys, str(tmp_path / "missing.bin"), str(TARGET))
    assert code == 1 and "missing.bin" in err
    bad_init = tmp_path / "init.txt"
    bad_init.write_text("1 2 3\n")
    code, _, err = run_cli(capsys, str(SOURCE), str(TARGET), "--init", str(bad_init))
    assert code == 1 and "init.txt" in err
    code, _, err = run_cli(capsys, str(SOURCE))
    assert code == 1 and "SOURCE and TARGET" in err


def test_nan_points_refused_with_advice_the_cli_can_follow(capsys, tmp_path):
    source = np.load(SOURCE).astype(np.float64)[:, :3]
    source[::50] = np.nan  # an organized cloud's missing returns
    path = tmp_path / "holes.npy"
    np.save(path, source)
    code, _, err = run_cli(capsys, str(path), str(TARGET), "-m", "small_gicp")
    assert code == 1 and "holes.npy" in err and "NaN" in err and "--drop-nonfinite" in err
    assert "frame 0" not in err  # (both clouds were "frame 0", the target included: two files are no sequence)
    code, _, err = run_cli(capsys, str(TARGET), str(path), "-m", "small_gicp")
    assert code == 1 and err.strip().startswith(f"error: {path}: ") and "frame" not in err
    code, _, err = run_cli(capsys, str(path), str(TARGET), "-m", "small_gicp", "--drop-nonfinite", "--out", str(tmp_path / "run"))
    assert code == 0, err
    result = json.loads((tmp_path / "run" / "result.json").read_text())
    assert result["drop_nonfinite"] is True and pose_error(np.asarray(result["T_target_source"]), T_GT)[0] < 0.05


def _drawn_pixels(png) -> int:
    import matplotlib.image

    image = matplotlib.image.imread(png)[..., :3]
    return int((np.abs(image - 1.0).sum(axis=2) > 0.3).sum())  # not white (axes, text and points)


def test_bev_of_a_georeferenced_pair_is_drawn_around_the_clouds(tmp_path):
    from lidarkit.registration.plots import save_bev_before_after

    source, target = np.load(SOURCE)[:, :3].astype(np.float64), np.load(TARGET)[:, :3].astype(np.float64)
    far = np.array([500000.0, 4500000.0, 100.0])  # UTM-like coordinates
    save_bev_before_after(tmp_path / "near.png", source, target, T_GT)
    save_bev_before_after(tmp_path / "far.png", source + far, target + far, T_GT)
    empty_target = np.array([[1000.0, 1000.0, 0.0]] * 3)  # only the axes and labels get drawn
    save_bev_before_after(tmp_path / "axes.png", empty_target, empty_target, np.eye(4))
    axes_only = _drawn_pixels(tmp_path / "axes.png")
    near, far_drawn = _drawn_pixels(tmp_path / "near.png"), _drawn_pixels(tmp_path / "far.png")
    assert near > 3 * axes_only and far_drawn > 0.8 * near  # the far pair is drawn as the near one (was: empty panels)


def test_a_folder_given_as_a_cloud_and_a_missing_results_folder_say_so(tmp_path, capsys):
    code, _, err = run_cli(capsys, str(tmp_path), str(TARGET))
    assert code == 1 and "a folder, not a point file" in err  # was "unsupported point file type ''"
    from conftest import cli_exit_code

    assert cli_exit_code(["report", str(tmp_path / "nope")]) == 1
    assert "nope: folder not found" in capsys.readouterr().err  # was "not a bench results folder (no jobs/ inside)"


def test_the_sigma_row_of_a_georeferenced_pair_is_about_the_target_s_sensor(tmp_path, capsys):
    """The bundled pair moved to UTM coordinates: the row showed the covariance about the frame's origin, where a
    rotation's lever arm is kilometres (t 355 / 39.5 / 1740 m); it is the one about the target's sensor, and says so."""
    pair = sample_path("kitti_pair")
    offset = np.array([500000.0, 4500000.0, 100.0])
    for name in ("000094", "000095"):
        points = np.load(pair / f"{name}.npy")
        points[:, :3] += offset
        np.save(tmp_path / f"{name}.npy", points)
    code, out, err = run_cli(capsys, str(tmp_path / "000095.npy"), str(tmp_path / "000094.npy"), "-m", "vanilla")
    assert code == 0, err
    text = " ".join(out.replace("│", " ").split())
    assert "1-sigma (m / deg, about 5000" in text
    t_sigma = [float(v) for v in text.split(" t ")[1].split(" r ")[0].split()[:3]]
    assert max(t_sigma) < 0.05  # centimetres, not the frame-origin kilometres
    code, out, _ = run_cli(capsys, str(pair / "000095.npy"), str(pair / "000094.npy"), "-m", "vanilla")
    assert "1-sigma (m / deg) " in " ".join(out.replace("│", " ").split()) + " "


def test_a_yes_or_no_word_for_a_number_setting_is_refused(capsys, tmp_path):
    """`-p max_iterations=yes` (YAML reads yes / on / true as True) ran 1 iteration, and get_icp("vanilla",
    max_iterations=True) was accepted: pydantic turned the bool into 1. A number setting now refuses it, by name;
    numbers still parse."""
    from lidarkit.errors import ConfigError
    from lidarkit.registration import get_icp

    code, _, err = run_cli(capsys, str(SOURCE), str(TARGET), "-p", "max_iterations=yes")
    assert code == 1 and "max_iterations (True): takes a number, not a yes/no value" in " ".join(err.split())
    for params in ({"max_iterations": True}, {"min_fitness": False}, {"max_correspondence_distance_m": np.True_}):
        with pytest.raises(ConfigError, match=f"{next(iter(params))} \\((True|False)\\): takes a number, not a yes/no value"):
            get_icp("vanilla", **params)
    code, _, err = run_cli(capsys, str(SOURCE), str(TARGET), "-p", "max_iterations=3", "-p", "coarse_stride=1",
                           "-p", "min_fitness=0.5", "-p", "planar=no", "--out", str(tmp_path))
    assert code == 0, err
    params = json.loads((tmp_path / "config.json").read_text())["params"]
    assert (params["max_iterations"], params["min_fitness"], params["planar"]) == (3, 0.5, False)
    assert json.loads((tmp_path / "result.json").read_text())["iterations"] == 3


def test_an_init_file_that_holds_json_or_words_says_so(capsys, tmp_path):
    """`--init run1/result.json` read "(line 1): expected 4 or 12 or 16 numbers, found 1" (its "{"), a line of words
    "found 2": the message now says the file holds JSON, or no numbers, and what --init takes."""
    code, _, _ = run_cli(capsys, str(SOURCE), str(TARGET), "--out", str(tmp_path / "run1"))
    assert code == 0
    words = tmp_path / "words.txt"
    words.write_text("# my guess\nhello world\n")
    takes = "--init takes a 4x4 or 3x4 text matrix, or one row of 12 (KITTI) or 16 numbers"
    for init, said in ((tmp_path / "run1" / "result.json", "holds JSON (a run's result.json?), not a text matrix"),
                       (words, "its first line holds no numbers ('hello world')")):
        code, _, err = run_cli(capsys, str(SOURCE), str(TARGET), "--init", str(init))
        assert code == 1 and " ".join(err.split()) == f"error: {init}: {said}: {takes}"


def test_an_init_file_with_numpys_print_of_a_matrix_is_read(capsys, tmp_path):
    """`--init` of numpy's print of a 4x4 ("[[1. 0. 0. 0.5]\\n [0. 1. ...]]") said "holds JSON (a run's result.json?)" (any
    first line starting with "[" was JSON): it is read as the matrix now, so is a JSON list of rows, and a bracketed
    matrix of another shape says what it holds."""
    from lidarkit.cli.icp_cmd import read_init_pose

    T = np.eye(4)
    T[:3, 3] = (0.5, -0.25, 0.125)
    printed, listed, three_by_four, wrong = (tmp_path / f"{name}.txt" for name in ("printed", "listed", "three_by_four", "wrong"))
    printed.write_text(str(T) + "\n")
    listed.write_text(json.dumps(T.tolist()))
    three_by_four.write_text(str(T[:3]) + "\n")
    wrong.write_text(str(np.eye(3)) + "\n")
    for path in (printed, listed, three_by_four):
        np.testing.assert_array_equal(read_init_pose(path), T)
    # numpy's repr, as a notebook shows it ("array([[" was counted as a fifth number: "found 5")
    for name, matrix in (("repr", T), ("repr32", T.astype(np.float32))):
        (tmp_path / f"{name}.txt").write_text(repr(matrix) + "\n")
        np.testing.assert_array_equal(read_init_pose(tmp_path / f"{name}.txt"), T)
    target_xyz = np.random.default_rng(0).uniform(-10.0, 10.0, (2000, 3))
    source, target = tmp_path / "source.npy", tmp_path / "target.npy"
    np.save(target, target_xyz)
    np.save(source, target_xyz - T[:3, 3])  # T_target_source is T: the guess is the answer
    code, _, err = run_cli(capsys, str(source), str(target), "-m", "vanilla", "--init", str(printed), "--out", str(tmp_path / "run"))
    assert code == 0, err
    result = json.loads((tmp_path / "run" / "result.json").read_text())
    assert result["init"] == str(printed) and np.allclose(result["T_target_source"], T, atol=1e-9)
    code, _, err = run_cli(capsys, str(SOURCE), str(TARGET), "--init", str(wrong))
    assert code == 1 and " ".join(err.split()) == (
        f"error: {wrong}: holds bracketed rows of 3, 3, 3 numbers, not 4 (or 3) rows of 4 or one of 12 or 16: "
        "--init takes a 4x4 or 3x4 text matrix, or one row of 12 (KITTI) or 16 numbers")


def test_small_gicp_on_a_tiny_cloud_leaves_stderr_to_the_error_line(capfd, tmp_path):
    """small_gicp's C++ "warning: source point cloud is too small. |source|=3" went raw to stderr (fd 2) beside the
    result, which says why it failed; it is silenced as the ground segmenters' C++ output is."""
    if "small_gicp" not in available_icp():
        pytest.skip("small_gicp not installed")
    target_xyz = np.random.default_rng(0).uniform(-10.0, 10.0, (2000, 3))
    source, target = tmp_path / "source.npy", tmp_path / "target.npy"
    np.save(target, target_xyz)
    np.save(source, target_xyz[:3])
    code = cli_exit_code(["icp", str(source), str(target), "-m", "small_gicp", "--out", str(tmp_path / "run")])
    captured = capfd.readouterr()
    assert code == 0 and captured.err == ""
    assert json.loads((tmp_path / "run" / "result.json").read_text())["converged"] is False


def _asserts():
    raise AssertionError("my assert")  # (an assert statement here would be rewritten by pytest)


@pytest.mark.parametrize("fault, said", [
    (lambda: 1 / 0, "ZeroDivisionError: division by zero"),
    (lambda: {}["x"], "KeyError: 'x'"),
    (lambda: "".foo, "AttributeError: 'str' object has no attribute 'foo'"),
    (_asserts, "AssertionError: my assert"),
    (lambda: open("/nonexistent/lidarkit.txt"), "FileNotFoundError: [Errno 2] No such file or directory: '/nonexistent/lidarkit.txt'"),
    (lambda: "a".encode("no-such-codec"), "LookupError: unknown encoding: no-such-codec"),
])
def test_a_plugin_failing_with_any_plain_error_is_one_line(capsys, fault, said):
    """A plugin whose _align raised ZeroDivisionError, KeyError or AttributeError gave a 70-line traceback (the
    odometry runner said a ZeroDivisionError in one line; a RuntimeError was one line here too); an AssertionError,
    an OSError or a LookupError still did."""
    from lidarkit.registration import Registration, RegistrationConfig, register_icp
    from lidarkit.registration import registry as registry_module

    class SlipICP(Registration):
        """Fails inside its own code."""
        Config = RegistrationConfig

        def _align(self, source_xyz, target_xyz, init_T):
            return fault()

    register_icp("slip_test")(SlipICP)
    try:
        code, _, err = run_cli(capsys, str(SOURCE), str(TARGET), "-m", "slip_test")
    finally:
        registry_module._VARIANTS.pop("slip_test", None)
    assert code == 1 and "Traceback" not in err
    assert " ".join(err.split()) == (
        f"error: slip_test (54850 source / 54478 target points): the slip_test backend failed on this pair: {said}")


def test_a_folder_of_the_users_own_files_named_like_an_icp_runs_is_refused_and_kept(tmp_path, capsys):
    """`lidarkit icp SRC TGT -o ui` replaced the user's own ui/result.json and bev.png (exit 0), in a folder that never
    held an icp run; odometry, vo and pf refuse such a folder. It is refused before the work, untouched; an icp run's
    own folder is written again."""
    mine = tmp_path / "ui"
    mine.mkdir()
    (mine / "result.json").write_text("mine\n")
    (mine / "bev.png").write_text("my figure\n")
    code, out, err = run_cli(capsys, str(SOURCE), str(TARGET), "-m", "vanilla", "-o", str(mine))
    assert (code, out) == (1, "")
    assert err == (f"error: {mine}: holds files named like an icp run's (bev.png, result.json) but no config.json written by "
                   "lidarkit icp (the user's own, or a run cut off before it was complete): a run would replace them; remove "
                   "them or give a new or empty folder\n")
    assert sorted(p.name for p in mine.iterdir()) == ["bev.png", "result.json"] and (mine / "result.json").read_text() == "mine\n"
    run = tmp_path / "run"
    for _ in range(2):  # a new folder, then the folder of that run
        code, _, err = run_cli(capsys, str(SOURCE), str(TARGET), "-m", "vanilla", "-p", "max_iterations=3", "-o", str(run))
        assert code == 0, err
    assert json.loads((run / "config.json").read_text())["params"]["max_iterations"] == 3


def test_a_pair_without_correspondences_has_no_degeneracy_verdict_in_the_table(capsys, tmp_path):
    """A scan scaled x100 onto itself (0 correspondences): the table read "nan (ok, threshold 0.01)" as if the geometry
    had been judged sound; it says the degeneracy is unknown and why."""
    from conftest import shared_path
    from registration_helpers import read_kitti_bin

    target = read_kitti_bin(shared_path("kitti_odometry", "sequences", "00", "velodyne", "000000.bin"))
    np.save(tmp_path / "big.npy", 100.0 * target)
    np.save(tmp_path / "t.npy", target)
    assert cli_exit_code(["icp", str(tmp_path / "big.npy"), str(tmp_path / "t.npy"), "-m", "vanilla"]) == 0
    rows = {line.split("│")[1].strip(): line.split("│")[2].strip() for line in capsys.readouterr().out.splitlines()
            if line.count("│") >= 3}
    assert rows["degeneracy min/max eig"] == "unknown (too few correspondences)"
    assert "eigenvalues" not in rows and "weakest direction" not in rows
