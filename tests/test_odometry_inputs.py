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
    for query, line in (("suffixes=", "folder dataset option: suffixes= has no value; give one, or leave suffixes out for its default"),
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


def test_a_run_name_that_is_no_text_is_refused_and_a_numpy_string_titles_the_run(tmp_path):
    """name=np.str_ finished the run, then failed writing config.yaml (yaml cannot represent it: the result lost);
    name=5 titled the run "vanilla on 5"."""
    from lidarkit.odometry import run

    spec = "sim:street?frames=3&beams=8&azimuths=180"
    with pytest.raises(ConfigError, match=r"^name: name must be a text, got int 5$"):
        run(spec, "vanilla", name=5)
    result = run(spec, "vanilla", name=np.array(["street_a"])[0], out_dir=tmp_path / "run")
    assert result.trajectory.name == "vanilla on street_a" and (tmp_path / "run" / "config.yaml").is_file()


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


# ---- CARMEN logs ----------------------------------------------------------------------------------


def test_a_run_over_a_restamped_log_scores_its_relations_through_the_reader(tmp_path):
    """The Intel run's note sent users to `lidarkit eval --relations FILE poses_tum.txt`, which matches the file's
    times as logged against the stamps the reader moved (364 of 499 relations scored, some on the wrong scan). A log
    whose stamps were moved is now scored in the run, through the reader, whose relations move with its scans."""
    import bz2

    from conftest import shared_path

    from lidarkit.eval.relations import relation_error
    from lidarkit.io.carmen import parse_log
    from lidarkit.odometry import run

    text = bz2.decompress(shared_path("carmen_2d", "intel.clf.bz2").read_bytes()).decode()
    lines = text.splitlines(keepends=True)
    last = [k for k, line in enumerate(lines) if line.startswith("FLASER")][39]
    log = tmp_path / "intel.clf"  # Intel's first 40 scans: the reader moves the stamps of scans 26 and 27
    log.write_text("".join(lines[:last + 1]))
    logged = parse_log(log).timestamps_s  # the file's own times, which a .relations file holds
    odometry = open_dataset("carmen", log).odometry.poses_se3
    rows = []
    for i in range(20, 39):
        T = np.linalg.solve(odometry[i], odometry[i + 1])
        rows.append(f"{logged[i]:.6f} {logged[i + 1]:.6f} {T[0, 3]:.6f} {T[1, 3]:.6f} 0 0 0 {np.arctan2(T[1, 0], T[0, 0]):.6f}")
    (tmp_path / "intel.relations").write_text("\n".join(rows) + "\n")
    result = run(f"carmen:{log}", "vanilla", params={"planar": True, "max_correspondence_distance_m": 0.5}, init="odometry",
                 frames="20:40")
    scored = relation_error(result.trajectory, open_dataset("carmen", log).relations)
    assert scored.n_used == 19 and scored.translation_abs["max"] < 0.05
    recorded = dict(result.metrics["relations"])  # (matched within half the log's smallest stamp gap: Intel's pool)
    assert recorded.pop("max_time_diff_s") < 0.01
    assert recorded == {k: v for k, v in scored.to_dict().items() if k != "max_time_diff_s"}
    assert result.metrics["ground_truth_note"] == (
        f"relations only, scored through the reader (metrics \"relations\"): 19 of 19, mean error "
        f"{scored.translation_abs['mean']:.4f} m / {scored.rotation_abs['mean']:.4f} deg; the reader moved 2 scan stamps and the "
        "relations' times with them (lidarkit eval --relations matches the file's times as logged: not for this log)")


def test_an_empty_scan_of_a_log_names_its_line_and_why(tmp_path, capsys):
    """A CARMEN scan whose readings were all 0.00 stopped the run with "error: blank (frame 10): empty scan (0 points)",
    naming neither the file's line nor why; the scan's own source and the reader's valid range now say both."""
    import bz2

    from conftest import shared_path

    lines = bz2.decompress(shared_path("carmen_2d", "aces.clf.bz2").read_bytes()).decode().splitlines(keepends=True)
    scans = [k for k, line in enumerate(lines) if line.startswith("FLASER")][:12]
    fields = lines[scans[10]].split(" ")
    fields[2:182] = ["0.00"] * 180  # FLASER 180 r1..r180 x y theta ...
    lines[scans[10]] = " ".join(fields)
    log = tmp_path / "blank.clf"
    log.write_text("".join(lines[:scans[-1] + 1]))
    assert _cli(["odometry", str(log), "-m", "vanilla", "-p", "planar=true", "--no-progress"]) == 1
    assert capsys.readouterr().err.strip().splitlines()[-1] == (
        f"error: {log}:{scans[10] + 1} (frame 10): empty scan (0 points): all 180 readings (0.00 m) lie outside the valid "
        "range, above min_range_m 0 m and below the maximum range 50 m (--frames can leave the frame out)")


def test_relations_whose_ends_meet_one_pose_are_left_out_and_counted(caplog):
    """With a loose tolerance (--relation-max-diff 2000 on a 600-scan estimate) relations past the estimate's end had
    both ends on its last pose and scored as no motion: 1279 of 1279 "matched", without a word. They are left out,
    counted in ``n_same_pose`` and in a warning."""
    from conftest import shared_path

    from lidarkit.eval.relations import relation_error
    from lidarkit.io.carmen import Relations

    aces = open_dataset("carmen", shared_path("carmen_2d", "aces.clf.bz2"))
    estimate = aces.odometry[:600]
    relations = Relations.read(shared_path("carmen_2d", "aces.relations"))
    loose = relation_error(estimate, relations, max_time_diff_s=2000)
    assert (loose.n_relations, loose.n_used, loose.n_same_pose) == (1279, 117, 1162)
    assert loose.to_dict()["n_same_pose"] == 1162
    assert "aces odometry: 1162 of 1279 relations have the same estimated pose nearest both their time stamps (within " \
           "2000 s; estimate spans 70.290..168.060 s): left out, they would score as no motion" in caplog.text
    tight = relation_error(estimate, relations)  # the default 0.01 s: none meets one pose
    assert (tight.n_used, tight.n_same_pose) == (103, 0)
    assert set(loose.used) > set(tight.used)  # the 103 scored at 0.01 s are among the 117


@pytest.mark.parametrize("frames, shown", [(slice(0.5, 3), "0.5:3"), (slice(None, None, 2.0), "::2.0"), (slice(True, 3), "True:3"),
                                           ("1:4:1.5", "1:4:1.5")])
def test_a_frame_slice_of_non_integers_is_a_config_error(frames, shown):
    """run(frames=slice(0.5, 3)) and slice(None, None, 2.0) raised numpy's bare "TypeError: slice indices must be
    integers..." (and slice(True, 3) ran from frame 1), where the string "1:4:1.5" was refused naming frames."""
    with pytest.raises(ConfigError) as info:
        parse_frames(frames, 10)
    assert str(info.value) == f"frames {shown!r}: frame bounds must be integers"
    assert list(parse_frames(slice(np.int64(1), np.int64(4)), 10)) == [1, 2, 3]  # numpy's integers are integers


class _OneBuffer:
    """A reader filling one array for every scan (``reuse``), or returning one unchanged array every time."""

    name = "one_buffer"

    def __init__(self, scans: list[np.ndarray], reuse: bool):
        self.scans, self.reuse, self.buffer = scans, reuse, np.array(scans[0])

    def __len__(self) -> int:
        return len(self.scans)

    def read_scan(self, i: int):
        from lidarkit.io.base import Scan

        if self.reuse:
            self.buffer[:] = self.scans[i]
        return Scan(self.buffer, frame=i, timestamp_s=0.1 * i)


@pytest.mark.parametrize("prefetch", [0, 4])
def test_a_reader_filling_one_buffer_for_every_scan_is_refused(prefetch):
    """Each read overwrote the scans still in use (read ahead, or kept as the next target): vanilla registered every
    scan against itself (final x 0.000 m for 1.9 m, the frame check passing), kiss lost 2 m of 4.9. A reader returning
    one unchanged array each time (a static scene) overwrites nothing and runs."""
    from lidarkit.errors import DataError
    from lidarkit.odometry import run
    from lidarkit.sim.lidar import SimulatedLidarSequence

    sim = SimulatedLidarSequence(scene="street", n_frames=4, seed=1, n_beams=16, n_azimuths=90)
    scans = [sim.read_scan(i).points_xyz[:1000] for i in range(4)]
    with pytest.raises(DataError) as err:
        run(_OneBuffer(scans, reuse=True), "vanilla", prefetch=prefetch)
    assert str(err.value) == ("one_buffer (frame 1): read_scan returned frame 1 in the array it returned for frame 0, which now "
                              "holds the new scan: each scan must be an array of its own (a reader that fills one buffer must "
                              "return a copy of it)")
    static = run(_OneBuffer(scans, reuse=False), "vanilla", prefetch=prefetch)
    assert np.abs(static.trajectory.poses_se3[:, :3, 3]).max() < 1e-6  # the same scan four times: no motion


def test_a_single_scan_file_is_pointed_to_its_folder(capsys):
    """A scan file as the dataset was told to name its kind, "e.g. carmen:000000.bin for a CARMEN log"."""
    from conftest import shared_path

    from lidarkit.errors import DataError

    velodyne = shared_path("kitti_odometry", "sequences", "00", "velodyne")
    for scan in (velodyne / "000000.bin", shared_path("lidar_pairs", "251370668.pcd")):
        with pytest.raises(DataError) as err:
            open_sequence(str(scan))
        assert str(err.value) == (f"{scan}: a single scan file: odometry needs a sequence of scans, e.g. the folder holding it "
                                  f"(folder:{scan.parent})")
    assert cli_exit_code(["odometry", str(velodyne / "000000.bin"), "-m", "kiss", "--no-progress"]) == 1
    assert capsys.readouterr().err.strip().endswith(f"(folder:{velodyne})")


def test_frame_messages_name_the_file_where_its_number_is_not_the_index(tmp_path, caplog):
    """A folder of KITTI scans 94, 95, 198, 199: "kmix (frame 1): registration did not converge" named a scan the folder
    has no file 000001.bin for (the index, which --frames selects), where its read errors name the file. The index
    stays, the file beside it; a scan numbered as its index is named as before."""
    import logging
    import shutil

    from conftest import shared_path

    from lidarkit.errors import RegistrationError
    from lidarkit.odometry import run
    from lidarkit.odometry.runner import frame_namer

    folder = tmp_path / "kmix"
    folder.mkdir()
    for n in (94, 95, 198):
        shutil.copy(shared_path("kitti_odometry", "extra_frames", "00", "velodyne", f"{n:06d}.bin"), folder / f"{n:06d}.bin")
    with pytest.raises(RegistrationError, match=r"^kmix \(frame 1, 000095\.bin\): registration did not converge \(reached max_iterations=1\)$"):
        run(f"folder:{folder}", "vanilla", params={"max_iterations": 1}, strict=True, progress=False)
    with caplog.at_level(logging.WARNING):
        run(f"folder:{folder}", "vanilla", params={"max_iterations": 1}, frames="0:2", progress=False)
    assert "kmix frame 1, 000095.bin: vanilla did not converge" in caplog.text
    assert frame_namer(open_sequence("sim:street?frames=3"))(2) == "frame 2"


def test_a_bare_dataset_path_that_is_a_loop_of_links_says_so(tmp_path):
    """`lidarkit odometry loopa` (a link leading back to itself) said "dataset not found"."""
    from lidarkit.errors import DataError

    (tmp_path / "loopa").symlink_to(tmp_path / "loopb")
    (tmp_path / "loopb").symlink_to(tmp_path / "loopa")
    with pytest.raises(DataError, match=r"loopa: cannot read it: a loop of symbolic links"):
        open_sequence(str(tmp_path / "loopa"))


def test_a_spec_path_option_that_reads_as_a_number_keeps_its_text(tmp_path):
    """velodyne_dir=1.50 looked for a folder '1.5' and timestamps=1e3 for a file '1000.0': the value parser read them as
    numbers, and the reader got the number back as other text. Options that take a path keep their value as written;
    a number option is still a number."""
    import shutil

    from conftest import shared_path

    velodyne = tmp_path / "sequences" / "00" / "1.50"
    velodyne.mkdir(parents=True)
    for n in (0, 1):
        shutil.copy(shared_path("kitti_odometry", "sequences", "00", "velodyne", f"{n:06d}.bin"), velodyne)
    shutil.copy(shared_path("kitti_odometry", "sequences", "00", "calib.txt"), tmp_path / "sequences" / "00")
    assert len(open_sequence(f"kitti:{tmp_path}?sequence=00&velodyne_dir=1.50")) == 2
    scans = tmp_path / "scans"
    shutil.copytree(velodyne, scans)
    (scans / "1e3").write_text("0.0\n0.1\n")
    folder = open_sequence(f"folder:{scans}?timestamps=1e3")
    np.testing.assert_allclose(folder.timestamps_s, [0.0, 0.1])
    assert len(open_sequence("sim:street?frames=3&beams=8&azimuths=180")) == 3  # numbers stay numbers


def test_scans_exactly_three_sweeps_apart_are_no_gap():
    """Frames 0, 1, 2, 3, 6 of a simulated drive are 3 sweeps apart at most, which the docs do not call a gap (more than
    3x); the float stamps made it 0.30000000000000004 s against 3 x 0.09999999999999998 s, and it was warned of. Four
    sweeps apart is a gap."""
    from lidarkit.odometry import run

    spec = "sim:street?frames=12&beams=8&azimuths=180&seed=1"
    three = run(spec, "vanilla", frames=[0, 1, 2, 3, 6]).metrics["warnings"]
    assert not [w for w in three if "gap(s)" in w]
    four = run(spec, "vanilla", frames=[0, 1, 2, 3, 7]).metrics["warnings"]
    assert [w for w in four if w.startswith("1 gap(s) in time between consecutive scans, the largest 0.4 s between frames 3 and 7")]
