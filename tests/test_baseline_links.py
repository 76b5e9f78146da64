"""A baseline folder given as a symbolic link that leads nowhere is named as given, with what is wrong with it."""

from __future__ import annotations

from conftest import cli_exit_code

from lidarkit.atomic import LINK_LOOP


def test_a_dangling_or_looping_baseline_link_says_so(tmp_path, capsys):
    """`lidarkit baseline check dang` (a link to a missing folder) and a loop of links both said "baseline folder does
    not exist"; a folder that is not there at all still does."""
    dang = tmp_path / "dang"
    dang.symlink_to("nowhere")
    loop = tmp_path / "loop"
    loop.symlink_to("loop")
    said = {dang: "a symbolic link to a missing file (-> nowhere)", loop: f"cannot read it: {LINK_LOOP}",
            tmp_path / "absent": "baseline folder does not exist"}
    for path, reason in said.items():
        assert cli_exit_code(["baseline", "check", str(path)]) == 1
        assert capsys.readouterr().err == f"error: {path}: {reason}\n"
