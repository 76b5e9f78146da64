"""``lidarkit icp --out``: what the written figures say about the run."""

from __future__ import annotations

import json

import numpy as np
from matplotlib.image import imread

from conftest import cli_exit_code

from lidarkit.registration import available_icp, get_icp
from lidarkit.registration.plots import save_rmse_history
from lidarkit.samples import sample_path

SOURCE = sample_path("kitti_pair", "000095.npy")
TARGET = sample_path("kitti_pair", "000094.npy")
ASSESS_FALSE_NOTE = "no RMSE: the assessment was left out (assess=False)"


def _far_init_T() -> np.ndarray:
    """An initial guess 1000 m off: no initial overlap."""
    T = np.eye(4)
    T[0, 3] = 1000.0
    return T


def test_rmse_png_of_an_assessed_run_without_rmse_does_not_say_assess_false(tmp_path, capsys):
    """vanilla (always assessed) from an init 1000 m off has no RMSE, and rmse.png said "the assessment was left out
    (assess=False)": the figure written differs from that one."""
    init = tmp_path / "far_init.txt"
    np.savetxt(init, _far_init_T())
    source, target = tmp_path / "source.npy", tmp_path / "target.npy"  # every 10th point: a quicker bird's-eye plot
    np.save(source, np.load(SOURCE)[::10])
    np.save(target, np.load(TARGET)[::10])
    out = tmp_path / "run"
    assert cli_exit_code(["icp", str(source), str(target), "-m", "vanilla", "--init", str(init), "--out", str(out)]) == 0
    capsys.readouterr()
    result = json.loads((out / "result.json").read_text())
    assert result["rmse_history"] == [] and result["reason"].startswith("no initial overlap")
    assess_false = save_rmse_history(tmp_path / "assess_false.png", {"vanilla": []}, title="vanilla: source.npy -> target.npy",
                                     empty_note=ASSESS_FALSE_NOTE)
    written, wrong = imread(out / "rmse.png"), imread(assess_false)
    assert written.shape == wrong.shape and not np.array_equal(written, wrong)


def test_the_no_rmse_note_is_assess_false_only_for_an_unassessed_result():
    from lidarkit.cli.icp_cmd import no_rmse_note

    far = get_icp("vanilla").align(np.load(SOURCE), np.load(TARGET), init_T=_far_init_T())
    note = no_rmse_note(far)
    assert " ".join(note.split()) == f"no RMSE: {far.reason}" and "assess=False" not in note
    if "kiss" in available_icp():  # a run that was not assessed keeps the assess=False wording
        unassessed = get_icp("kiss", assess=False).align(np.load(SOURCE), np.load(TARGET))
        assert unassessed.extra["assessed"] is False
        assert no_rmse_note(unassessed) == ASSESS_FALSE_NOTE


def _listed_descriptions(out: str) -> dict[str, str]:
    """``{row name: its description line}`` of a listing printed wide enough not to wrap (the first line of each row)."""
    rows = {}
    for line in out.splitlines():
        cells = [cell.strip() for cell in line.strip().strip("│").split("│")]
        if len(cells) == 2 and cells[0]:
            rows[cells[0]] = cells[1]
    return rows


def test_every_listed_description_is_a_whole_sentence(capsys, monkeypatch):
    """The listings took a docstring's first physical line: plane_to_plane's row ended "... surface covariances. The
    covariances are". Each description is now the first sentence, joined over lines."""
    from lidarkit.registration.components import Kernel, registry
    from lidarkit.registration.components.kernels import KernelConfig

    class WrappedKernel(Kernel):
        """A kernel whose first sentence runs
        over two lines. Its second is left out."""
        Config = KernelConfig
        name = "wrapped_test"

    monkeypatch.setitem(registry._COMPONENTS["kernel"], "wrapped_test", WrappedKernel)  # (gone after the test)
    monkeypatch.setenv("COLUMNS", "400")
    assert cli_exit_code(["icp", "--list-components"]) == 0
    components = _listed_descriptions(capsys.readouterr().out)
    assert components["kernel / wrapped_test"] == "A kernel whose first sentence runs over two lines."
    assert components["residual / plane_to_plane"] == \
        "Generalized-ICP: Mahalanobis distance under the summed source and map surface covariances."
    assert cli_exit_code(["icp", "--list"]) == 0
    methods = _listed_descriptions(capsys.readouterr().out)
    assert len(components) >= 15 and "kiss (stateful)" in methods
    unfinished = {name: text for name, text in {**components, **methods}.items() if not text.endswith(".")}
    assert unfinished == {}


def test_the_iterations_row_of_kiss_says_the_backend_reports_none_with_or_without_the_assessment(capsys):
    """kiss (and Open3D) never report an iteration count, yet with assess=false the row read "not recorded
    (assess=False)", as if the assessment would have given one."""
    for assess in ("true", "false"):
        code = cli_exit_code(["icp", str(SOURCE), str(TARGET), "-m", "kiss", "-p", f"assess={assess}"])
        out = " ".join(capsys.readouterr().out.replace("│", " ").split())
        assert code == 0 and "iterations not reported by the backend " in out and "not recorded" not in out, assess


def test_kiss_at_a_lowered_cap_names_the_cap_with_or_without_the_assessment(capsys):
    """``-p max_num_iterations=1 -p assess=false`` printed "converged False (kiss reports no convergence)", the cap's
    reason being built by the assessment alone."""
    for assess in ("true", "false"):
        code = cli_exit_code(["icp", str(SOURCE), str(TARGET), "-m", "kiss", "-p", "max_num_iterations=1", "-p", f"assess={assess}"])
        out = " ".join(capsys.readouterr().out.replace("│", " ").split())
        assert code == 0 and "converged False (kiss-icp stopped at max_num_iterations=1:" in out, assess
        assert "reports no convergence" not in out, assess


def test_the_component_listing_names_preprocess_and_the_ranges_the_pipeline_passes_range_crop(capsys, monkeypatch):
    """The title named residual=|kernel=|threshold=|deskew=|map= but not preprocess=[...], and range_crop's ranges read as
    its own defaults, though the pipeline passes its min_range_m / max_range_m (as voxel_hash's voxel size said)."""
    monkeypatch.setenv("COLUMNS", "400")
    assert cli_exit_code(["icp", "--list-components"]) == 0
    lines = [" ".join(line.replace("│", " ").split()) for line in capsys.readouterr().out.splitlines()]
    title = next(line for line in lines if line.startswith("pipeline components"))
    assert "-p 'preprocess=[NAME, ...]'" in title
    start = next(i for i, line in enumerate(lines) if line.startswith("preprocess / range_crop"))
    crop = [line for line in lines[start:start + 3] if line.split(":")[0].endswith("_range_m")]
    assert crop == ["min_range_m: float = 0.0 — drop points at or closer than this (m); the pipeline passes its own",
                    "max_range_m: float = 100.0 — drop points at or beyond this (m); the pipeline passes its own"]


def test_a_bad_init_is_refused_before_either_cloud_is_read(tmp_path, capsys):
    """A scaled rotation or a 1e8 m translation as --init was refused only after both clouds were read (their warnings
    printed first): with a source cloud that does not exist, the --init error comes first."""
    scaled, far = np.eye(4), np.eye(4)
    scaled[0, 0] = 2.0
    far[0, 3] = 1e8
    missing = tmp_path / "missing.npy"
    for name, T, reason in (("scaled.txt", scaled, "the 3x3 block is not a rotation"),
                            ("far.txt", far, "the translation has a coordinate of 1e+08 m, beyond 1e+07 m")):
        np.savetxt(tmp_path / name, T)
        assert cli_exit_code(["icp", str(missing), str(TARGET), "--init", str(tmp_path / name)]) == 1
        err = " ".join(capsys.readouterr().err.split())
        assert err.startswith(f"error: {tmp_path / name}: {reason}"), err
    assert cli_exit_code(["icp", str(missing), str(TARGET), "--init", str(tmp_path)]) == 1  # a folder given for it
    assert capsys.readouterr().err == f"error: {tmp_path}: is a folder, not a 4x4 pose file\n"


def test_a_cloud_too_small_to_register_is_named_by_its_file(tmp_path, capsys):
    """`lidarkit icp one.npy ok.npy` said "source cloud: needs at least 3 points, got 1" without the file."""
    one, ok = tmp_path / "one.npy", tmp_path / "ok.npy"
    np.save(one, np.array([[1.0, 2.0, 3.0]]))
    np.save(ok, np.load(SOURCE)[::50])
    for argv, role in (([one, ok], "source cloud"), ([ok, one], "target cloud")):
        assert cli_exit_code(["icp", *map(str, argv)]) == 1
        err = " ".join(capsys.readouterr().err.split())
        assert err == f"error: {one} ({role}): needs at least 3 points, got 1", err
