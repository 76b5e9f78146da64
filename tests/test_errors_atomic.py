"""The error family's message format, atomic writes, and the CLI's one-line error handling."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from conftest import cli_exit_code
from lidarkit import atomic
from lidarkit.cli import main
from lidarkit.errors import ConfigError, DataError, LidarKitError, OutputError


def test_error_message_names_source_location_and_reason():
    err = DataError("truncated scan", source="seq/000001.bin", location="frame 1")
    assert str(err) == "seq/000001.bin (frame 1): truncated scan"
    assert isinstance(err, LidarKitError)
    assert str(ConfigError("unknown method 'foo'")) == "unknown method 'foo'"


def test_atomic_write_replaces_whole_file(tmp_path):
    target = tmp_path / "out" / "result.json"
    atomic.write_text(target, "first")
    assert target.read_text() == "first"
    atomic.write_text(target, "second")
    assert target.read_text() == "second"
    assert [p.name for p in target.parent.iterdir()] == ["result.json"]


def test_atomic_failure_keeps_previous_content(tmp_path):
    target = tmp_path / "result.txt"
    target.write_text("good")
    with pytest.raises(RuntimeError):
        with atomic.atomic_path(target) as tmp:
            tmp.write_text("half")
            raise RuntimeError("crash mid-write")
    assert target.read_text() == "good"
    assert os.listdir(tmp_path) == ["result.txt"]


def test_cli_prints_one_line_and_exits_1_on_lidarkit_error(tmp_path, capsys):
    missing = tmp_path / "nope.txt"
    with pytest.raises(SystemExit) as exc:
        main(["eval", str(missing), str(missing)])
    assert exc.value.code == 1
    err = capsys.readouterr().err
    assert "error:" in err and "nope.txt" in err and "Traceback" not in err
    # a library's message with line breaks (rosbags quoting a YAML parser) still prints as one line
    bag = tmp_path / "bag"
    bag.mkdir()
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information:\n  version: [\n")
    with pytest.raises(SystemExit) as exc:
        main(["odometry", f"rosbag:{bag}", "--no-progress"])
    err = capsys.readouterr().err
    assert exc.value.code == 1 and len(err.strip().splitlines()) == 1 and "not a readable ROS bag" in err


def test_cli_params_are_yaml_scalars_and_bad_ones_name_the_option():
    from lidarkit.cli.app import parse_params

    assert parse_params(["max_iterations=30", "voxel_size_m=0.5", "deskew=false", "name=abc", "x="]) == {
        "max_iterations": 30,
        "voxel_size_m": 0.5,
        "deskew": False,
        "name": "abc",
        "x": None,
    }
    with pytest.raises(ConfigError, match=r"--set 'novalue'.*expected KEY=VALUE"):
        parse_params(["novalue"], option="--set")


def test_a_running_outputs_temporary_folder_is_never_taken_for_a_killed_ones(tmp_path):
    """An export writing for over an hour lost its temporary folder to a second export's clean-up (the folder's own
    time stamp does not change while files are written inside it) and then said it wrote every sweep (2567 of 3000):
    a folder held by a running output is kept, one a killed run left behind is removed."""
    import subprocess
    import sys
    import time

    target = tmp_path / "run"
    two_hours_ago = time.time() - 7200
    with atomic.partial_folder(target) as writing:
        (writing / "velodyne").mkdir()
        os.utime(writing, (two_hours_ago, two_hours_ago))
        left = tmp_path / f".run{atomic.PARTIAL_MARK}killed"
        left.mkdir()
        os.utime(left, (two_hours_ago, two_hours_ago))
        cleanup = ("import sys; from lidarkit.atomic import remove_stale_partials; "
                   f"sys.exit(remove_stale_partials({str(target)!r}))")
        removed = subprocess.run([sys.executable, "-c", cleanup], timeout=120).returncode  # another process's clean-up
        assert removed == 1 and writing.is_dir() and (writing / "velodyne").is_dir() and not left.exists()
    assert not writing.exists()  # removed at the end (not renamed into place)
    with atomic.run_folder(target) as tmp:  # a run folder is held the same way while written
        os.utime(tmp, (two_hours_ago, two_hours_ago))
        assert atomic.remove_stale_partials(target) == 0 and tmp.is_dir()
        (tmp / "poses.txt").write_text("1\n")
    assert (target / "poses.txt").read_text() == "1\n"


def test_a_long_legal_name_is_written_through_a_temporary_name_that_fits(tmp_path):
    """A 250-byte name is legal (the disk takes 255), but its temporary ``.NAME.partial-XXXXXXXX`` folder (or
    ``.STEM.XXXXXXXX.json`` file) is not: `--out` of that length failed only after the run had done its work."""
    import time

    name = "y" * 250
    folder = tmp_path / name
    atomic.check_target(folder, "folder")
    with atomic.run_folder(folder) as tmp:
        assert len(tmp.name) <= 255 and atomic.PARTIAL_MARK in tmp.name
        (tmp / "poses.txt").write_text("1\n")
    assert (folder / "poses.txt").read_text() == "1\n"
    two_hours_ago = time.time() - 7200
    with atomic.partial_folder(tmp_path / ("y" * 249 + "z")) as other:  # shares the long start: another run's folder
        os.utime(other, (two_hours_ago, two_hours_ago))
        left = tmp_path / other.name.replace(other.name[-8:], "killed!!")  # a killed run of the same name
        left.mkdir()
        os.utime(left, (two_hours_ago, two_hours_ago))
        assert atomic.remove_stale_partials(folder) == 0 and left.is_dir()  # not this name's
        assert atomic.remove_stale_partials(tmp_path / ("y" * 249 + "z")) == 1 and other.is_dir() and not left.exists()
    atomic.write_text(tmp_path / f"{'z' * 250}.json", "{}")
    assert (tmp_path / f"{'z' * 250}.json").read_text() == "{}"
    assert sorted(p.name for p in tmp_path.iterdir()) == [name, f"{'z' * 250}.json"]


def test_an_export_into_the_working_folder_fills_it_in_place(tmp_path, monkeypatch):
    """`lidarkit sim lidar -o .` in an empty folder failed after the whole export ("the folder filled while this export
    was written": its temporary folder was made inside "."), and `-o $PWD` renamed a new folder over the shell's own
    working folder: an existing folder is filled in place, never replaced."""
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    inode = work.stat().st_ino
    with atomic.export_folder(".", "sweeps") as tmp:
        (tmp / "poses.txt").write_text("1\n")
    assert sorted(p.name for p in work.iterdir()) == ["poses.txt"] and work.stat().st_ino == inode
    with atomic.run_folder(work) as tmp:
        (tmp / "metrics.json").write_text("{}")
    assert sorted(p.name for p in work.iterdir()) == ["metrics.json", "poses.txt"] and work.stat().st_ino == inode
    with pytest.raises(OutputError, match="the folder already holds files"):
        with atomic.export_folder(".", "sweeps"):
            pass


def test_a_folder_where_a_run_file_goes_is_refused_before_the_work(tmp_path, capsys):
    """A folder named ape.png inside --out was found only after the run (13 s of KITTI lost): the names a run writes or
    replaces are checked with the folder."""
    out = tmp_path / "run"
    (out / "ape.png").mkdir(parents=True)
    with pytest.raises(OutputError, match=r"run/ape.png: cannot write: is a folder"):
        atomic.check_target(out, "folder", files=("poses_kitti.txt", "ape.png"))
    from lidarkit.samples import sample_path

    pair = sample_path("kitti_pair")
    for blocked, command in (("ape.png", ["odometry", "sim:street?frames=2", "-m", "vanilla", "--no-progress"]),
                             ("bev.png", ["icp", str(pair / "000095.npy"), str(pair / "000094.npy")]),
                             ("trajectory.png", ["vo", "simcam:street?frames=3", "--no-progress"])):
        (out / blocked).mkdir(exist_ok=True)
        with pytest.raises(SystemExit):
            main([*command, "-o", str(out)])
        printed, err = capsys.readouterr()
        assert f"run/{blocked}: cannot write: is a folder" in " ".join(err.split()), command
        assert printed == "", command  # refused before the work: no result table printed
        (out / blocked).rmdir()


def test_a_folder_of_a_users_own_files_under_run_file_names_is_refused_before_the_work(tmp_path):
    """A user's own config.yaml and metrics.json in a folder that never held a run were replaced by an odometry run
    (exit 0; the docs said other files stay). A folder that held a run (its config.yaml names the lidarkit version)
    or a command that replaces nothing (``icp``: no ``replaces``) is not refused."""
    out = tmp_path / "proj"
    out.mkdir()
    (out / "config.yaml").write_text("lr: 0.1\n")
    (out / "metrics.json").write_text("notes\n")
    (out / "notes.txt").write_text("mine\n")
    with pytest.raises(OutputError) as refused:
        atomic.check_target(out, "folder", files=("config.yaml",), replaces=("poses_kitti.txt", "metrics.json", "config.yaml"))
    assert str(refused.value) == (f"{out}: holds files named like a run's (config.yaml, metrics.json) but no config.yaml "
                                  "written by lidarkit (the user's own, or a run cut off before it was complete): a run would "
                                  "replace them; remove them or give a new or empty folder")
    atomic.check_target(out, "folder", files=("config.yaml", "metrics.json"))
    (out / "config.yaml").write_text("lidarkit_version: 0.1\n")
    atomic.check_target(out, "folder", replaces=("metrics.json", "config.yaml"))
    assert (out / "metrics.json").read_text() == "notes\n"


def test_a_run_folder_through_a_link_or_in_a_parent_it_cannot_write(tmp_path, monkeypatch):
    """--out LINK renamed the run onto the link (a cross-device error after the work, or "the folder filled while this
    export was written" for an export into an empty folder); a writable folder in a parent the user cannot write to (a
    mount point) failed after the work: written beside the folder the link names, or inside the folder, file by file."""
    real = tmp_path / "real"
    real.mkdir()
    link = tmp_path / "link"
    link.symlink_to(real)
    with atomic.export_folder(link, "sweeps") as tmp:
        (tmp / "velodyne").mkdir()
        (tmp / "velodyne" / "000000.bin").write_bytes(b"1234")
    assert link.is_symlink() and (real / "velodyne" / "000000.bin").read_bytes() == b"1234"
    with atomic.run_folder(link) as tmp:  # a link to a folder that holds a run: files moved in
        (tmp / "poses.txt").write_text("p\n")
    assert sorted(p.name for p in real.iterdir()) == ["poses.txt", "velodyne"]

    mount = tmp_path / "mount"
    mount.mkdir()
    (mount / "mine.txt").write_text("kept\n")
    monkeypatch.setattr(atomic, "_writable", lambda folder: Path(folder) != tmp_path)  # the parent is not writable
    with atomic.run_folder(mount) as tmp:
        assert tmp.parent == mount
        (tmp / "plots").mkdir()
        (tmp / "plots" / "a.png").write_bytes(b"png")
        (tmp / "config.yaml").write_text("lidarkit_version: x\n")
    assert sorted(p.name for p in mount.iterdir()) == ["config.yaml", "mine.txt", "plots"]
    assert (mount / "plots" / "a.png").read_bytes() == b"png"
    empty = tmp_path / "empty_mount"
    empty.mkdir()
    with pytest.raises(LidarKitError, match="the folder filled while this export was written"):
        with atomic.export_folder(empty, "sweeps") as tmp:
            assert tmp.parent == empty
            (empty / "other.bin").write_bytes(b"x")  # another export's file arrived meanwhile
            (tmp / "mine.bin").write_bytes(b"y")
    assert sorted(p.name for p in empty.iterdir()) == ["other.bin"]


def test_files_written_together_replace_none_when_one_fails(tmp_path):
    """A bench report's report.md and report.csv were replaced by the new suite's while report.html, which failed (a
    full disk, a folder in the way), stayed the old one: files that belong together are all replaced or none."""
    for name in ("report.md", "report.csv"):
        (tmp_path / name).write_text("old\n")
    (tmp_path / "report.html").mkdir()  # in the way
    with pytest.raises(LidarKitError, match="report.html: cannot write: is a folder"):
        atomic.write_texts({tmp_path / "report.md": "new\n", tmp_path / "report.csv": "new\n", tmp_path / "report.html": "new\n"})
    assert [(tmp_path / n).read_text() for n in ("report.md", "report.csv")] == ["old\n", "old\n"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["report.csv", "report.html", "report.md"]  # no temporary left
    (tmp_path / "report.html").rmdir()
    written = atomic.write_texts({tmp_path / "report.md": "new\n", tmp_path / "report.html": "<p>new</p>\n"})
    assert written == [tmp_path / "report.md", tmp_path / "report.html"]
    assert (tmp_path / "report.md").read_text() == "new\n" and (tmp_path / "report.html").read_text() == "<p>new</p>\n"


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="needs /dev/full (a device that is always full)")
def test_a_full_disk_on_stdout_is_one_line_and_the_files_asked_for_are_still_written(tmp_path):
    """`lidarkit version > /dev/full` (so `--version`, `icp --list`, `eval ... --json m.json`) ended in a 70-line
    traceback ("OSError: [Errno 28] No space left on device"), and eval, which printed its table before writing its
    outputs, wrote no m.json. A closed pipe (`| head -1`) stays quiet, as before."""
    import json
    import subprocess
    import sys

    from conftest import shared_path

    gt, est = (str(shared_path("evo_testdata", name)) for name in ("KITTI_00_gt.txt", "KITTI_00_ORB.txt"))

    def run(args, stdout):
        return subprocess.run([sys.executable, "-m", "lidarkit", *map(str, args)], stdout=stdout, stderr=subprocess.PIPE,
                              text=True, timeout=300)

    with open("/dev/full", "w") as full:
        for args in (["version"], ["--version"], ["icp", "--list"], ["eval", gt, est, "--no-drift", "--json", tmp_path / "m.json"]):
            done = run(args, full)
            assert (done.returncode, done.stderr) == (1, "error: stdout: cannot write: no space left on the device\n"), args
    written = json.loads((tmp_path / "m.json").read_text())
    assert written["ape"]["stats"]["rmse"] == pytest.approx(1.30345, abs=1e-5) and written["est_path"] == est
    read, write = os.pipe()
    os.close(read)  # the reader is gone: a broken pipe
    done = run(["version"], write)
    os.close(write)
    assert (done.returncode, done.stderr) == (1, "")


def test_a_file_output_given_as_a_link_is_written_where_the_link_points(tmp_path, capsys):
    """`--json LINK` renamed the result onto the link: the link became a plain file and the file it named kept the
    earlier result (exit 0). A run folder given as a link was already written where it points; a file now is too."""
    import json

    from conftest import shared_path

    real = tmp_path / "real.json"
    real.write_text('{"old": 1}\n')
    (tmp_path / "sub").mkdir()
    link = tmp_path / "sub" / "lj"
    link.symlink_to("../real.json")  # relative to the link's folder, as `ln -s ../real.json sub/lj` makes it
    atomic.write_text(link, "new\n")
    assert link.is_symlink() and real.read_text() == "new\n"
    gt, est = (str(shared_path("evo_testdata", name)) for name in ("KITTI_00_gt.txt", "KITTI_00_ORB.txt"))
    with pytest.raises(SystemExit) as exc:
        main(["eval", gt, est, "--no-drift", "--json", str(link)])
    assert exc.value.code in (0, None) and f"wrote {link}" in capsys.readouterr().out
    assert link.is_symlink() and json.loads(real.read_text())["ape"]["stats"]["rmse"] == pytest.approx(1.30345, abs=1e-5)
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["lj", "real.json", "sub"]  # no temporary file left


def test_an_output_that_is_a_device_or_a_fifo_is_written_into_not_replaced(tmp_path, capsys):
    """`--json mynull --plot f.png` on a character device and a FIFO renamed plain files over both (as root, `--json
    /dev/null` replaced the system's /dev/null), and a reader of the FIFO hung on the unlinked pipe. A stream is written
    into, once the output is complete (a PNG writer needs to seek, a FIFO cannot)."""
    import stat
    import threading

    from conftest import shared_path

    null, fifo = tmp_path / "mynull", tmp_path / "f.png"
    try:
        os.mknod(null, 0o666 | stat.S_IFCHR, os.makedev(1, 3))  # (the device /dev/null is)
    except PermissionError:  # (not root: the system's own)
        null = Path("/dev/null")
    os.mkfifo(fifo)
    received = []
    reader = threading.Thread(target=lambda: received.append(fifo.read_bytes()), daemon=True)
    reader.start()
    gt, est = (str(shared_path("evo_testdata", name)) for name in ("freiburg1_xyz-groundtruth.txt", "freiburg1_xyz-rgbdslam.txt"))
    with pytest.raises(SystemExit) as exc:
        main(["eval", gt, est, "-f", "tum", "--associate", "--no-drift", "--json", str(null), "--plot", str(fifo)])
    reader.join(timeout=30)
    assert exc.value.code in (0, None), capsys.readouterr().err
    assert stat.S_ISCHR(null.stat().st_mode) and stat.S_ISFIFO(fifo.stat().st_mode)  # still what they were
    assert received and received[0].startswith(b"\x89PNG\r\n\x1a\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(p.name for p in (null, fifo) if p.parent == tmp_path)


def test_a_run_file_that_cannot_be_replaced_leaves_the_earlier_run_whole(tmp_path, monkeypatch):
    """Moving a run into a folder holding an earlier one, a file that could not be replaced (owned by another user in a
    shared sticky folder, immutable) stopped the move half-way: the folder held the new metrics.json beside the earlier
    config.yaml, and read as a finished run. The files replaced before it are put back, and the message names the file."""
    run = tmp_path / "run"
    with atomic.run_folder(run) as tmp:
        for name in ("metrics.json", "poses_tum.txt", "timing.csv", "config.yaml"):
            (tmp / name).write_text(f"earlier {name}\n")
    before = {p.name: p.read_text() for p in run.iterdir()}
    real_replace = os.replace

    def refusing(src, dst, *args, **kwargs):  # (what the file system says of a file this user may not replace)
        if Path(dst).name == "poses_tum.txt" and Path(dst).parent == run:
            raise PermissionError(1, "Operation not permitted")
        return real_replace(src, dst, *args, **kwargs)

    monkeypatch.setattr(os, "replace", refusing)
    with pytest.raises(OutputError) as caught:
        with atomic.run_folder(run) as tmp:
            for name in ("metrics.json", "poses_tum.txt", "timing.csv", "config.yaml"):
                (tmp / name).write_text(f"new {name}\n")
    assert str(caught.value) == f"{run / 'poses_tum.txt'}: cannot replace it (permission denied): the folder is left as it was"
    assert {p.name: p.read_text() for p in run.iterdir()} == before  # (no temporary left either)


def test_files_written_together_are_all_renamed_in_when_interrupted_between_renames(tmp_path, monkeypatch):
    """Ctrl-C between the renames of files that belong together (an evaluation's JSON and Markdown) left the first one
    new beside the other one old: the renames finish, then the interrupt is raised."""
    import signal

    for name in ("r.json", "r.md"):
        (tmp_path / name).write_text("old\n")
    real_replace = os.replace

    def replace(src, dst):  # a real SIGINT right after each rename
        real_replace(src, dst)
        os.kill(os.getpid(), signal.SIGINT)

    monkeypatch.setattr(os, "replace", replace)
    with pytest.raises(KeyboardInterrupt):
        atomic.write_texts({tmp_path / "r.json": "new\n", tmp_path / "r.md": "new\n"})
    assert [(tmp_path / n).read_text() for n in ("r.json", "r.md")] == ["new\n", "new\n"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.json", "r.md"]


@pytest.mark.parametrize("argv", [["vo", "/nonexistent-images"], ["pf", "/nonexistent-landmarks"]])
def test_vo_and_pf_refuse_a_folder_of_a_users_own_files_under_run_file_names(tmp_path, capsys, argv):
    """As odometry: `lidarkit vo ... -o proj` and `lidarkit pf ... -o proj` replaced a user's own config.yaml in a
    folder that never held a run. Refused before the data is opened, naming the files; the files are kept."""
    from conftest import cli_exit_code

    proj = tmp_path / "proj"
    proj.mkdir()
    (proj / "config.yaml").write_text("lr: 0.1\n")
    assert cli_exit_code([*argv, "-o", str(proj)]) == 1
    assert capsys.readouterr().err.strip().splitlines() == [
        f"error: {proj}: holds files named like a run's (config.yaml) but no config.yaml written by lidarkit (the "
        "user's own, or a run cut off before it was complete): a run would replace them; remove them or give a new or "
        "empty folder"]
    assert (proj / "config.yaml").read_text() == "lr: 0.1\n"


def test_a_pgf_plot_without_its_tex_program_is_refused_before_the_work(tmp_path, capsys, monkeypatch):
    """--plot out.pgf passed the pre-check and, after all the work, ended in a traceback "RuntimeError: 'xelatex' not
    found"; save_figure caught only ValueError."""
    from conftest import shared_path
    from matplotlib.figure import Figure

    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    monkeypatch.setenv("PATH", str(bin_dir))  # no TeX on the path
    gt = str(shared_path("evo_testdata", "KITTI_00_gt.txt"))
    with pytest.raises(SystemExit) as exc:
        main(["eval", gt, gt, "--json", str(tmp_path / "e.json"), "--plot", str(tmp_path / "e.pgf")])
    printed, err = capsys.readouterr()
    assert exc.value.code == 1 and printed == "" and sorted(os.listdir(tmp_path)) == ["bin"]
    assert err == (f"error: {tmp_path / 'e.pgf'}: cannot write the plot: the .pgf format needs 'xelatex' (matplotlib's "
                   "rcParams['pgf.texsystem']), which is not installed; use .pdf or .svg\n")
    with pytest.raises(OutputError, match=r"unknown plot format '\.txt'; use one of: .*\.pdf, \.png, \.ps, \.raw"):
        atomic.check_target(tmp_path / "e.txt", "figure")  # (.pgf no longer offered)
    # a TeX program that is found but cannot start (its interpreter is gone) fails inside savefig
    (bin_dir / "xelatex").write_text("#!/nonexistent/interpreter\n")
    (bin_dir / "xelatex").chmod(0o755)
    atomic.check_target(tmp_path / "e.pgf", "figure")
    fig = Figure()
    fig.add_subplot(1, 1, 1).plot([0, 1], [0, 1])
    with pytest.raises(OutputError) as caught:
        atomic.save_figure(fig, tmp_path / "e.pgf")
    assert str(caught.value) == (f"{tmp_path / 'e.pgf'}: cannot write the plot: 'xelatex' not found; install it or change "
                                 "rcParams['pgf.texsystem'] to an available TeX implementation")
    assert sorted(os.listdir(tmp_path)) == ["bin"]
    # one that starts and fails (a broken TeX installation, a missing package) raised matplotlib's LatexError: a traceback
    (bin_dir / "xelatex").write_text("#!/bin/sh\necho '! LaTeX Error: File `fontspec.sty' not found.'\nexit 1\n")
    with pytest.raises(OutputError) as caught:
        atomic.save_figure(fig, tmp_path / "e.pgf")
    assert str(caught.value).startswith(f"{tmp_path / 'e.pgf'}: cannot write the plot: LaTeX errored")
    assert "\n" not in str(caught.value) and sorted(os.listdir(tmp_path)) == ["bin"]


def test_a_folder_output_through_a_link_to_a_missing_folder_is_refused_as_a_bag_is(tmp_path, capsys):
    """ln -s /nonexistent/x dangle; lidarkit sim lidar --out dangle made /nonexistent/x with its parents (bags refused the
    same link); every run folder did the same: refused, before the work, and nothing is made where the link points."""
    from lidarkit.sim.lidar import SimulatedLidarSequence, export_kitti

    dangle = tmp_path / "dangle"
    dangle.symlink_to(tmp_path / "gone" / "x")
    said = f"{dangle}: a symbolic link to a missing file is in the way (-> {tmp_path / 'gone' / 'x'}): remove it or name another folder"
    for argv in (["sim", "lidar", "-p", "n_beams=8", "-p", "n_azimuths=90"], ["sim", "camera", "-p", "width=64", "-p", "height=48",
                                                                               "-p", "cx=null", "-p", "cy=null"]):
        with pytest.raises(SystemExit) as exc:
            main([*argv, "--frames", "2", "--out", str(dangle), "--no-progress"])
        assert (exc.value.code, capsys.readouterr().err) == (1, f"error: {said}\n")
    frames = []
    with pytest.raises(OutputError) as caught:
        export_kitti(SimulatedLidarSequence(n_frames=2, n_beams=8, n_azimuths=90), dangle, on_frame=frames.append)
    assert str(caught.value) == said and frames == []  # refused before the first sweep
    for refuse in (lambda: atomic.check_target(dangle, "folder"), lambda: atomic.run_folder(dangle).__enter__(),
                   lambda: atomic.export_folder(dangle, "sweeps").__enter__()):
        with pytest.raises(OutputError) as caught:
            refuse()
        assert str(caught.value) == said
    # a link to a missing folder above the output: named, never followed
    with pytest.raises(OutputError) as caught:
        atomic.check_target(dangle / "run", "folder")
    assert str(caught.value) == said
    with pytest.raises(OutputError) as caught, atomic.run_folder(dangle / "run"):
        pass
    assert str(caught.value) == said
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dangle"] and dangle.is_symlink()
    # a link to a folder that exists is written through, as before
    (tmp_path / "gone" / "x").mkdir(parents=True)
    with atomic.run_folder(dangle / "run") as tmp:
        (tmp / "poses.txt").write_text("p\n")
    assert (tmp_path / "gone" / "x" / "run" / "poses.txt").read_text() == "p\n"


def test_a_run_that_finished_into_the_folder_meanwhile_is_replaced_whole(tmp_path):
    """Two runs into one new folder: B began first, A finished first, then B. B read "no earlier run" when it began,
    so it kept A's pose_covariance.txt beside its own config.yaml (a kiss run folder with vanilla's covariances)."""
    from lidarkit.run_files import RUN_FILES

    folder = tmp_path / "race"
    with atomic.run_folder(folder, replaces=RUN_FILES) as b:
        with atomic.run_folder(folder, replaces=RUN_FILES) as a:
            atomic.write_text(a / "config.yaml", "method: vanilla\nlidarkit_version: x\n")
            atomic.write_text(a / "poses_kitti.txt", "A\n")
            atomic.write_text(a / "pose_covariance.txt", "A's covariances\n")
        atomic.write_text(b / "config.yaml", "method: kiss\nlidarkit_version: x\n")
        atomic.write_text(b / "poses_kitti.txt", "B\n")
    assert {p.name: p.read_text() for p in folder.iterdir()} == {"config.yaml": "method: kiss\nlidarkit_version: x\n",
                                                                 "poses_kitti.txt": "B\n"}


_RUN_INTO = """
import sys, time
from pathlib import Path
from lidarkit import atomic

tag, out, n = sys.argv[1], Path(sys.argv[2]), int(sys.argv[3])
every = [f"{t}{i:04d}.txt" for t in "ab" for i in range(n)] + ["config.yaml"]
with atomic.run_folder(out, replaces=every) as tmp:
    for i in range(n):
        (tmp / f"{tag}{i:04d}.txt").write_text(tag)
    (tmp / "config.yaml").write_text(f"lidarkit_version: test\\nrun: {tag}\\n")
    (out.parent / f"ready-{tag}").touch()
    deadline = time.monotonic() + 30
    while len(list(out.parent.glob("ready-*"))) < 2 and time.monotonic() < deadline:  # both move in at once
        time.sleep(0.0005)
"""


def test_two_runs_moving_into_one_folder_at_once_leave_one_runs_files(tmp_path):
    """Two runs finishing into one existing folder at the same moment moved their files in one rename each, side by
    side: the folder held one run's config.yaml beside the other's files, or each run removed the other's files as an
    earlier run's. The second waits for the first: the folder holds the whole of one run, nothing of the other."""
    import subprocess
    import sys

    n = 300
    script = tmp_path / "run_into.py"
    script.write_text(_RUN_INTO)
    for trial in range(3):
        place = tmp_path / f"trial{trial}"
        out = place / "run"
        out.mkdir(parents=True)
        (out / "config.yaml").write_text("lidarkit_version: test\nrun: earlier\n")
        runs = [subprocess.Popen([sys.executable, str(script), tag, str(out), str(n)]) for tag in "ab"]
        assert [run.wait(timeout=60) for run in runs] == [0, 0]
        names = sorted(p.name for p in out.iterdir())
        last = (out / "config.yaml").read_text().split("run: ")[1].strip()
        assert last in ("a", "b")
        assert names == sorted([f"{last}{i:04d}.txt" for i in range(n)] + ["config.yaml"])
        assert {(out / name).read_text() for name in names if name != "config.yaml"} == {last}
        assert sorted(p.name for p in place.iterdir()) == ["ready-a", "ready-b", "run"]  # (no lock file left)


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="needs /dev/full (a device that is always full)")
def test_icp_and_bench_write_their_outputs_before_a_stdout_that_refuses_them(tmp_path):
    """`lidarkit icp A B --out DIR > /dev/full` printed its table before writing DIR: one line, exit 1, and no folder;
    `lidarkit bench SUITE --out OUT > /dev/full` printed its summary before the report: jobs/ only, no report.md and no
    word of it. Both are written first now, as odometry, vo and pf do."""
    import subprocess
    import sys
    import textwrap

    from lidarkit.samples import sample_path

    def run(args):
        with open("/dev/full", "w") as full:
            return subprocess.run([sys.executable, "-m", "lidarkit", *map(str, args)], stdout=full, stderr=subprocess.PIPE,
                                  text=True, timeout=300)

    pair = [sample_path("kitti_pair", "000095.npy"), sample_path("kitti_pair", "000094.npy")]
    done = run(["icp", *pair, "-m", "small_gicp", "--out", tmp_path / "icp"])
    assert (done.returncode, done.stderr.splitlines()[-1]) == (1, "error: stdout: cannot write: no space left on the device")
    assert sorted(p.name for p in (tmp_path / "icp").iterdir()) == ["bev.png", "config.json", "result.json", "rmse.png"]
    (tmp_path / "suite.yaml").write_text(textwrap.dedent("""
        name: tiny
        experiments:
          - {name: s, task: odometry, dataset: {kind: sim_lidar, n_frames: 4, n_beams: 16, n_azimuths: 360}, methods: [kiss]}
    """))
    done = run(["bench", tmp_path / "suite.yaml", "--out", tmp_path / "bench", "-e", "serial", "--no-progress"])
    assert (done.returncode, done.stderr.splitlines()[-1]) == (1, "error: stdout: cannot write: no space left on the device")
    assert {"report.md", "report.csv", "report.html"} <= {p.name for p in (tmp_path / "bench").iterdir()}


_KILLED_MOVING_IN = """
import os, signal, sys
from pathlib import Path
from lidarkit import atomic
from lidarkit.run_files import RUN_FILES

out, mode = Path(sys.argv[1]), sys.argv[2]
real_replace, moved_in = os.replace, []

def replace(src, dst, *args, **kwargs):  # the third file of the run moved in, then a SIGKILL (or a failure)
    real_replace(src, dst, *args, **kwargs)
    if Path(dst).parent == out:
        moved_in.append(Path(dst).name)
        if len(moved_in) == 3:
            if mode == "kill":
                os.kill(os.getpid(), signal.SIGKILL)
            raise PermissionError(1, "Operation not permitted")

os.replace = replace
with atomic.run_folder(out, replaces=RUN_FILES) as tmp:
    for name in ("ape.png", "config.yaml", "ground_truth_kitti.txt", "metrics.json", "poses_kitti.txt", "timing.csv"):
        (tmp / name).write_text(f"kiss {name}\\n" if name != "config.yaml" else "method: kiss\\nlidarkit_version: x\\n")
"""


@pytest.mark.parametrize("mode", ["kill", "fail"])
def test_a_run_cut_off_moving_into_an_earlier_runs_folder_lacks_the_earlier_config(tmp_path, mode):
    """A SIGKILL after three of a kiss run's files had moved into a small_gicp run's folder left small_gicp's config.yaml
    beside kiss's metrics.json and ground truth: a folder that looked finished, compared as one run. The earlier
    config.yaml and metrics.json leave before the first file moves in (and the new ones come last), so the cut-off
    folder has neither: a later run and `lidarkit compare` refuse it. A failure that can be caught still puts the
    earlier run back whole."""
    import subprocess
    import sys

    from lidarkit.run_files import RUN_FILES

    out = tmp_path / "run"
    with atomic.run_folder(out, replaces=RUN_FILES) as tmp:
        for name in ("ape.png", "config.yaml", "ground_truth_kitti.txt", "metrics.json", "poses_kitti.txt", "timing.csv"):
            (tmp / name).write_text(f"small_gicp {name}\n" if name != "config.yaml" else "method: small_gicp\nlidarkit_version: x\n")
    earlier = {p.name: p.read_text() for p in out.iterdir()}
    script = tmp_path / "killed_moving_in.py"
    script.write_text(_KILLED_MOVING_IN)
    done = subprocess.run([sys.executable, str(script), str(out), mode], capture_output=True, text=True, timeout=120)
    if mode == "fail":
        assert done.returncode == 1 and "cannot replace it (permission denied): the folder is left as it was" in done.stderr
        assert {p.name: p.read_text() for p in out.iterdir()} == earlier
        return
    assert done.returncode == -9
    now = {p.name: p.read_text() for p in out.iterdir()}
    assert "config.yaml" not in now and "metrics.json" not in now  # (the earlier run's were left in place)
    assert sorted(name for name in now if now[name].startswith("kiss")) == ["ape.png", "ground_truth_kitti.txt",
                                                                           "poses_kitti.txt"]
    with pytest.raises(OutputError, match="holds files named like a run's .* but no config.yaml written by lidarkit"):
        atomic.check_target(out, "folder", files=RUN_FILES, replaces=RUN_FILES)
    from lidarkit.eval.compare import load_odometry_run

    with pytest.raises(DataError, match="no metrics.json: not a finished odometry run folder"):
        load_odometry_run(out)  # (`lidarkit compare` scored the mixed folder)


def test_a_folder_given_as_a_text_input_is_called_a_folder(tmp_path, capsys):
    """`lidarkit eval gt.txt FOLDER` read "FOLDER: not a regular file", which did not say that a folder was given where a
    file is read; the readers can name the kind of file they expected."""
    from lidarkit.textfile import read_lines, read_numeric_table

    gt, folder = tmp_path / "gt.txt", tmp_path / "results"
    folder.mkdir()
    rows = np.tile(np.eye(4)[:3].ravel(), (5, 1))
    rows[:, 3] = np.arange(5.0)
    np.savetxt(gt, rows)
    assert cli_exit_code(["eval", str(gt), str(folder)]) == 1
    assert capsys.readouterr().err == f"error: {folder}: is a folder, not a trajectory file\n"
    with pytest.raises(DataError) as caught:
        read_numeric_table(folder, 12, what="trajectory file")
    assert str(caught.value) == f"{folder}: is a folder, not a trajectory file"
    with pytest.raises(DataError, match="missing.txt: file not found$"):  # (other reasons as they were)
        read_lines(tmp_path / "missing.txt")


def test_an_svgz_plot_names_its_svg_not_the_temporary_file(tmp_path):
    """gzip's header named the hidden temporary file the plot was written to ("..out.681uyaa9.svgz"): gunzip -N
    restored a hidden file; it names out.svg now, and the content is the figure's SVG."""
    import gzip

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])
    target = atomic.save_figure(fig, tmp_path / "out.svgz")
    plt.close(fig)
    raw = target.read_bytes()
    assert raw[:2] == b"\x1f\x8b" and raw[3] & 0x08  # gzip with a stored name
    name = raw[10:raw.index(b"\0", 10)].decode()
    assert name == "out.svg"
    assert gzip.decompress(raw).lstrip().startswith(b"<?xml") and b"<svg" in gzip.decompress(raw)
    assert [p.name for p in tmp_path.iterdir()] == ["out.svgz"]


def test_a_loop_of_links_in_the_way_of_an_output_is_called_a_loop(tmp_path, capsys):
    """`lidarkit sim lidar -o loop` (ln -s loop loop) said "a symbolic link to a missing file is in the way (-> loop)":
    a loop is said as one, the link named as given; a link to a missing file keeps its wording."""
    loop = tmp_path / "loop"
    loop.symlink_to("loop")
    with pytest.raises(SystemExit) as exc:
        main(["sim", "lidar", "-p", "n_beams=8", "-p", "n_azimuths=90", "--frames", "2", "--out", str(loop), "--no-progress"])
    assert (exc.value.code, capsys.readouterr().err) == (
        1, f"error: {loop}: {atomic.LINK_LOOP} is in the way (-> loop): remove it or name another folder\n")
    with pytest.raises(OutputError) as caught:
        atomic.refuse_dangling_link(loop / "run", "file")
    assert str(caught.value) == f"{loop}: {atomic.LINK_LOOP} is in the way (-> loop): remove it or name another folder"
    dangle = tmp_path / "dangle.bin"
    dangle.symlink_to("nowhere.bin")
    with pytest.raises(OutputError) as caught:
        atomic.refuse_dangling_link(dangle, "file")
    assert str(caught.value) == (f"{dangle}: a symbolic link to a missing file is in the way (-> nowhere.bin): remove it "
                                 "or name another file")


def test_atomic_writes_refuse_the_wrong_content_type_in_one_line(tmp_path):
    """write_text(path, b"a") was an AttributeError (bytes have no encode), write_bytes(path, "a") a TypeError from
    the file's write; each is a ConfigError naming the type, and nothing is written (write_texts checks every text first)."""
    refusals = (
        (lambda: atomic.write_text(tmp_path / "a.txt", b"a"),
         f"{tmp_path / 'a.txt'}: write_text: text must be a str, got bytes (write_bytes writes bytes)"),
        (lambda: atomic.write_bytes(tmp_path / "b.bin", "a"),
         f"{tmp_path / 'b.bin'}: write_bytes: data must be bytes, got str (write_text writes a str)"),
        (lambda: atomic.write_text(tmp_path / "c.txt", None), f"{tmp_path / 'c.txt'}: write_text: text must be a str, got NoneType"),
        (lambda: atomic.write_texts({tmp_path / "d.md": "fine", tmp_path / "d.csv": 3}),
         f"{tmp_path / 'd.csv'}: write_texts: text must be a str, got int"),
    )
    for call, message in refusals:
        with pytest.raises(ConfigError) as err:
            call()
        assert str(err.value) == message
    assert list(tmp_path.iterdir()) == []
    atomic.write_bytes(tmp_path / "e.bin", bytearray(b"\x00\x01"))
    assert (tmp_path / "e.bin").read_bytes() == b"\x00\x01"
