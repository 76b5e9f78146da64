"""The relations metric's warnings: kept in the result and its ``--json``, as the pose-by-pose evaluation's are."""

from __future__ import annotations

import json

import numpy as np
import pytest

from conftest import cli_exit_code, shared_path
from lidarkit.eval.relations import relation_error
from lidarkit.io import open_dataset
from lidarkit.io.carmen import Relations

SHIFTED_WARNING = ("only 11 of 1279 relations have estimated poses within 0.01 s of both their time stamps (estimate spans "
                   "70.290..1435.810 s, relations 1090.240..2410.780 s): the score covers those only")


@pytest.fixture(scope="module")
def aces_files(tmp_path_factory):
    """ACES odometry as a TUM file, and the real relations moved 1000 s later (11 of them still land on scans)."""
    folder = tmp_path_factory.mktemp("relations")
    aces = open_dataset("carmen", shared_path("carmen_2d", "aces.clf.bz2"))
    aces.odometry.to_tum(folder / "aces_odometry_tum.txt")
    rows = np.loadtxt(shared_path("carmen_2d", "aces.relations"))
    rows[:, :2] += 1000.0
    np.savetxt(folder / "shifted.relations", rows, fmt="%.6f")
    return aces, folder / "aces_odometry_tum.txt", folder / "shifted.relations"


def test_relations_warnings_are_kept_in_the_result_and_the_json(aces_files, tmp_path, caplog):
    """The warning that most relations were left out went to stderr only: ``eval --relations --json`` had no
    ``warnings`` field (the pose-by-pose --json has one), so a saved score of 11 of 1279 relations read as clean."""
    aces, est, shifted = aces_files
    err = relation_error(aces.odometry, Relations.read(shifted))
    assert (err.n_used, err.warnings) == (11, (SHIFTED_WARNING,))
    assert caplog.text.count(f"{aces.odometry.name}: {SHIFTED_WARNING}") == 1  # logged as before, once
    assert err.to_dict()["warnings"] == [SHIFTED_WARNING]
    assert relation_error(aces.odometry, aces.relations).warnings == ()  # all 1279 matched: nothing to warn of
    out = tmp_path / "shifted.json"
    assert cli_exit_code(["eval", "--relations", str(shifted), str(est), "--json", str(out)]) == 0
    data = json.loads(out.read_text())
    assert (data["n_used"], data["warnings"]) == (11, [SHIFTED_WARNING])
