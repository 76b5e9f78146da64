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
