"""``lidarkit vo`` on the bundled KITTI sample and on plain image folders: summary, run folder, errors."""

from __future__ import annotations

import json
import shutil

import cv2
import numpy as np
import pytest
import yaml

from lidarkit.cli import main
from lidarkit.errors import DataError
from lidarkit.samples import sample_path
from lidarkit.trajectory import Trajectory
from lidarkit.vo.inputs import detect_kind, open_vo_input


def _run(argv, capsys):
    if argv[0] == "vo" and "--progress" not in argv:  # (progress lines on stderr are tested on their own)
        argv = [*argv, "--no-progress"]
    with pytest.raises(SystemExit) as exc:
        main(argv)
    out = capsys.readouterr()
    return exc.value.code, out.out, out.err


def test_vo_on_bundled_kitti_sample_writes_run_folder(tmp_path, capsys):
    seq = sample_path("kitti_vo", "06")
    out = tmp_path / "run"
    code, stdout, _ = _run(["vo", str(seq), "--scale", "gt", "--out", str(out), "--gif",
                            "--set", "matching.klt_window_px=17"], capsys)
    assert code in (0, None)
    assert "frames" in stdout and "APE raw (SE(3)-aligned)" in stdout
    assert "RPE raw 1 frame (alignment-free)" in stdout  # (an SE(3) alignment leaves relative poses as they are)
    for name in ("poses_kitti.txt", "poses_tum.txt", "poses_smoothed_kitti.txt", "poses_smoothed_tum.txt",
                 "diagnostics.csv", "config.yaml", "metrics.json", "trajectory.png", "features.gif"):
        assert (out / name).is_file(), name
    est = Trajectory.from_kitti(out / "poses_kitti.txt")
    gt = Trajectory.from_kitti(seq / "poses.txt")
    assert len(est) == len(gt) == 8
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["rejected"] == 0 and metrics["raw"]["ape_rmse_m"] < 0.03
    config = yaml.safe_load((out / "config.yaml").read_text())
    assert config["vo"]["scale"]["mode"] == "gt" and config["K_source"] == "kitti calibration"
    assert config["vo"]["matching"]["klt_window_px"] == 17
    csv = (out / "diagnostics.csv").read_text().splitlines()
    assert csv[0].startswith("frame,ref_frame,n_features,n_matches,n_inliers") and len(csv) == 9
    # the same folder without --gif: the earlier run's features.gif goes (it was left beside the new run)
    code, _, _ = _run(["vo", str(seq), "--scale", "gt", "--max-frames", "4", "--out", str(out)], capsys)
    assert code in (0, None) and not (out / "features.gif").exists() and len(Trajectory.from_kitti(out / "poses_kitti.txt")) == 4


def test_vo_relative_scale_reports_kept_scale_frames(tmp_path, capsys):
    """The kept-scale count (VOResult.n_scale_kept) reaches the CLI table and metrics.json, and equals the
    diagnostics rows noting it."""
    out = tmp_path / "run"
    code, stdout, _ = _run(["vo", str(sample_path("kitti_vo", "06")), "--scale", "relative", "--preset", "report_orb",
                            "--out", str(out)], capsys)
    assert code in (0, None) and "scale kept from the previous step" in stdout
    metrics = json.loads((out / "metrics.json").read_text())
    notes = [row.split(",") for row in (out / "diagnostics.csv").read_text().splitlines()[1:]]
    assert metrics["scale_kept_frames"] == sum("scale kept from the previous step" in ",".join(r) for r in notes)


def test_vo_on_plain_image_folder_guesses_intrinsics(tmp_path, capsys, caplog):
    src = sample_path("kitti_vo", "06", "image_0")
    folder = tmp_path / "imgs"
    shutil.copytree(src, folder)
    assert detect_kind(folder) == "images"
    vo_input = open_vo_input(folder)
    assert "guess" in vo_input.K_source and vo_input.K[0, 0] == pytest.approx(0.9 * 1226)
    caplog.clear()
    out = tmp_path / "run"
    code, stdout, err = _run(["vo", str(folder), "--scale", "none", "--preset", "report_orb", "--out", str(out)], capsys)
    assert code in (0, None) and "frames" in stdout
    # each assumption is said once (a log warning), not also printed by the command
    said = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"] + err.splitlines()
    assert sum("no intrinsics given" in line for line in said) == 1
    assert sum("frame numbers as seconds" in line for line in said) == 1
    note = "no time stamps given: poses_tum.txt and poses_smoothed_tum.txt use frame numbers as seconds"
    assert json.loads((out / "metrics.json").read_text())["timestamps"] == note
    assert yaml.safe_load((out / "config.yaml").read_text())["timestamps"] == note
    # from --start 3 the stamps are the input's frame numbers, as diagnostics.csv's (they began at 0: another run's
    # frame 0 was paired with this run's frame 3 when the two were associated by time)
    code, _, _ = _run(["vo", str(folder), "--scale", "none", "--preset", "report_orb", "--start", "3", "--out", str(tmp_path / "late")], capsys)
    stamps = np.loadtxt(tmp_path / "late" / "poses_tum.txt", comments="#")[:, 0]
    first = int((tmp_path / "late" / "diagnostics.csv").read_text().splitlines()[1].split(",")[0])
    assert code in (0, None) and first == 3 and stamps.tolist() == [3.0, 4.0, 5.0, 6.0, 7.0]
    assert np.loadtxt(tmp_path / "late" / "poses_smoothed_tum.txt", comments="#")[0, 0] == 3.0
    # an odd-sized first image neither rejects the others nor sets the guessed intrinsics
    cv2.imwrite(str(folder / "000000.png"), cv2.resize(cv2.imread(str(src / "000000.png"), 0), (640, 200)))
    assert open_vo_input(folder).K[0, 0] == pytest.approx(0.9 * 1226)  # not 0.9 * 640
    code, stdout, _ = _run(["vo", str(folder), "--scale", "none"], capsys)
    assert code in (0, None) and "accepted pairs" in stdout and "6 of 7" in stdout
    assert "frame 0 rejected: image size 640x200 differs from the sequence's 1226x370" in stdout
    # with the calibration file, K is read from it
    calib = sample_path("kitti_vo", "06", "calib.txt")
    assert open_vo_input(folder, calib=calib).K[0, 0] == pytest.approx(707.0912)


def test_vo_rejects_corrupt_frame_in_folder_and_reports_it(tmp_path, capsys):
    folder = tmp_path / "imgs"
    shutil.copytree(sample_path("kitti_vo", "06", "image_0"), folder)
    (folder / "000003.png").write_bytes(b"\x89PNG truncated")
    calib = sample_path("kitti_vo", "06", "calib.txt")
    code, stdout, _ = _run(["vo", str(folder), "--calib", str(calib)], capsys)
    assert code in (0, None)
    assert "frame 3 rejected: unreadable image" in stdout
    assert "6 of 7" in stdout and "top rejection reasons" in stdout and "unreadable image (1)" in stdout


def test_vo_without_any_accepted_pair_writes_diagnostics_and_fails(tmp_path, capsys):
    folder = tmp_path / "black"
    folder.mkdir()
    for i in range(5):
        cv2.imwrite(str(folder / f"{i}.png"), np.zeros((120, 160), np.uint8))
    out = tmp_path / "run"
    code, stdout, err = _run(["vo", str(folder), "--out", str(out)], capsys)
    assert code == 1 and len(err.strip().splitlines()) == 1, err
    assert err.startswith(f"error: {folder}: no frame pair accepted (4 of 5 frames rejected)")  # the input named (not vo_gftt_klt_...)
    assert "too few features in reference frame" in err and "diagnostics.csv" in err
    rows = (out / "diagnostics.csv").read_text().splitlines()
    assert len(rows) == 6 and sum(",False," in row for row in rows) == 4
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["accepted_pairs"] == 0 and metrics["rejection_reasons"] == {"too few features in reference frame": 4}
    assert not list(out.glob("*.tmp*"))  # written atomically, no leftovers


def test_vo_cli_errors_are_one_line(tmp_path, capsys):
    code, _, err = _run(["vo", str(tmp_path / "nope")], capsys)
    assert code == 1 and "input not found" in err
    code, _, err = _run(["vo", str(sample_path("kitti_vo", "06")), "--detector", "surf"], capsys)
    assert code == 1 and "error: --detector: " in err  # (the option given, not the config field)
    code, _, err = _run(["vo", str(sample_path("kitti_vo", "06")), "--set", "matching.window=3"], capsys)
    assert code == 1 and "unknown config field 'window'" in err
    empty = tmp_path / "empty"
    empty.mkdir()
    code, _, err = _run(["vo", str(empty), "--scale", "none"], capsys)
    assert code == 1 and "no images" in err
    code, _, err = _run(["vo", str(sample_path("kitti_vo", "06", "image_0")), "--kind", "images", "--scale", "gt"],
                        capsys)
    assert code == 1 and "error: --scale: scale gt needs ground-truth poses" in err
    # options checked before anything runs, whether or not this input would use them
    seq = str(sample_path("kitti_vo", "06"))
    for args, message in ((["--gif"], "--gif: --gif needs --out DIR"), (["--poses-format", "foo"], "--poses-format: unknown format 'foo'"),
                          (["--focal-factor", "0"], "--focal-factor: must be a finite number > 0, got 0.0"),
                          (["--start", "-1"], "--start: must be >= 0, got -1")):  # (it named the sequence)
        code, _, err = _run(["vo", seq, "--max-frames", "3", *args], capsys)
        assert code == 1 and message in err, args
    # options an input has no use for are refused, not dropped
    code, _, err = _run(["vo", seq, "--poses", str(sample_path("kitti_vo", "06", "poses.txt")), "--poses-format", "tum"], capsys)
    assert code == 1 and "a KITTI folder's poses are KITTI rows" in err


def test_library_inputs_are_checked_before_the_frames():
    """MonoVO({...}, K) was an AttributeError traceback; a NaN in K read "got shape (3, 3)"; time stamps of another
    length, NaN or decreasing failed only after every frame was processed."""
    from lidarkit.errors import ConfigError
    from lidarkit.vo import MonoVO, preset
    from lidarkit.vo.inputs import open_vo_input

    vo_input = open_vo_input(str(sample_path("kitti_vo", "06")))
    K, images = vo_input.K, vo_input.images
    with pytest.raises(ConfigError, match="MonoVO: config must be a VOConfig .*, got dict"):
        MonoVO({"scale": {"mode": "none"}}, K)
    with pytest.raises(DataError, match=r"K must be finite, got 1 NaN or infinite entries"):
        MonoVO(preset("lidarkit", **{"scale.mode": "none"}), K * np.array([[np.nan, 1, 1], [1, 1, 1], [1, 1, 1]]))
    vo = MonoVO(preset("lidarkit", **{"scale.mode": "none"}), K)
    seen = []
    for stamps in (np.arange(3.0), np.r_[0.0, np.nan, np.arange(2.0, len(images))], np.arange(len(images))[::-1] * 0.1):
        with pytest.raises(DataError, match="vo timestamps_s: .* time stamps for .* images, which must be finite and increasing"):
            vo.run(images, timestamps_s=stamps, on_frame=seen.append)
    with pytest.raises(DataError, match=r"^vo timestamps_s: time stamps must be numbers in seconds \(could not convert"):
        vo.run(images, timestamps_s=["a"] * len(images), on_frame=seen.append)  # (numpy's own ValueError)
    assert seen == []  # refused before the first frame


def test_image_folder_checks_counts(tmp_path):
    from lidarkit.io import open_dataset
    from lidarkit.io.images import ImageFolder  # noqa: F401  (registers kind "images")

    folder = tmp_path / "imgs"
    folder.mkdir()
    for i in range(3):
        cv2.imwrite(str(folder / f"f{i}.png"), np.full((10, 12), i * 50, np.uint8))
    (tmp_path / "t.txt").write_text("0\n0.1\n")
    with pytest.raises(DataError, match="2 time stamps for 3 images"):
        open_dataset("images", folder, timestamps=tmp_path / "t.txt")
    ds = open_dataset("images", folder)
    assert len(ds) == 3 and ds.read_image(2)[0, 0] == 100 and ds.K is None
    from lidarkit.io.base import ImageSequence

    assert isinstance(ds, ImageSequence)


def test_tum_poses_for_an_image_folder_give_their_stamps_or_say_they_disagree(tmp_path, caplog):
    """--poses-format tum: without --timestamps the images were stamped 0, 1, 2 ... s though the poses carry their
    times; with stamps 100 s from the poses' they were paired pose by pose without a word."""
    import logging

    from lidarkit.io import open_dataset
    from lidarkit.io.images import ImageFolder  # noqa: F401  (registers kind "images")

    folder = tmp_path / "imgs"
    folder.mkdir()
    for i in range(3):
        cv2.imwrite(str(folder / f"f{i}.png"), np.full((10, 12), i * 50, np.uint8))
    rows = [f"{t:.2f} {t:.1f} 0 0 0 0 0 1" for t in (5.0, 5.1, 5.2)]
    (tmp_path / "gt.txt").write_text("\n".join(rows) + "\n")
    ds = open_dataset("images", folder, poses=tmp_path / "gt.txt", poses_format="tum")
    np.testing.assert_allclose(ds.timestamps_s, [5.0, 5.1, 5.2])
    (tmp_path / "t.txt").write_text("0\n0.1\n0.2\n")
    with caplog.at_level(logging.WARNING, logger="lidarkit.io.images"):
        ds = open_dataset("images", folder, poses=tmp_path / "gt.txt", poses_format="tum", timestamps=tmp_path / "t.txt")
    np.testing.assert_allclose(ds.timestamps_s, [0.0, 0.1, 0.2])
    assert any("pose 0 is stamped 5.000 s from its image (half a frame is 0.050 s)" in r.getMessage() for r in caplog.records)
    caplog.clear()
    (tmp_path / "t.txt").write_text("5.01\n5.1\n5.2\n")
    with caplog.at_level(logging.WARNING, logger="lidarkit.io.images"):
        open_dataset("images", folder, poses=tmp_path / "gt.txt", poses_format="tum", timestamps=tmp_path / "t.txt")
    assert not caplog.records  # within half a frame: paired as given


def test_poses_of_the_other_format_name_the_poses_format_option(tmp_path, capsys):
    """KITTI poses given as --poses-format tum (and TUM poses as kitti) advised "--format kitti, Trajectory.from_kitti",
    options of eval, not of vo: the hint names --poses-format (and the library's poses_format)."""
    seq = sample_path("kitti_vo", "06")
    tum = Trajectory.from_kitti(seq / "poses.txt").with_timestamps(np.arange(8) * 0.1).to_tum(tmp_path / "gt.tum")
    for poses, fmt, line in (
        (seq / "poses.txt", "tum", f"error: {seq / 'poses.txt'} (line 1): expected 8 numbers, found 12 (a KITTI "
                                   "trajectory? read it as kitti: --poses-format kitti)"),
        (tum, "kitti", f"error: {tum} (line 2): expected 12 numbers, found 8 (a TUM trajectory? read it as tum: "
                       "--poses-format tum)"),
    ):
        code, _, err = _run(["vo", str(seq / "image_0"), "--kind", "images", "--calib", str(seq / "calib.txt"), "--poses", str(poses),
                             "--poses-format", fmt], capsys)
        assert code == 1 and err.strip() == line, err


def test_poses_of_the_other_format_name_the_option_in_the_cli_and_the_keyword_in_the_library(tmp_path, capsys):
    """The command's hint repeated itself in Python ("--poses-format kitti (poses_format='kitti')"): the command names
    its option only (a relative --poses path too), the library's ImageFolder its keyword only."""
    from lidarkit.io.images import ImageFolder

    seq = sample_path("kitti_vo", "06")
    shutil.copy(seq / "poses.txt", tmp_path / "gt.txt")
    with pytest.raises(DataError) as caught:
        ImageFolder(seq / "image_0", poses=tmp_path / "gt.txt", poses_format="tum")
    assert caught.value.reason.endswith("(a KITTI trajectory? read it as kitti: poses_format='kitti')"), caught.value
    code, _, err = _run(["vo", str(seq / "image_0"), "--kind", "images", "--calib", str(seq / "calib.txt"),
                         "--poses", str(tmp_path / "gt.txt"), "--poses-format", "tum"], capsys)
    assert code == 1 and err.endswith("(a KITTI trajectory? read it as kitti: --poses-format kitti)\n"), err


def test_vo_on_synthetic_tum_folder_with_calib_file(tmp_path, capsys):
    """A TUM-layout folder (rgb.txt, rgb/*.png, groundtruth.txt) rendered by the synthetic camera."""
    from lidarkit.sim.camera import default_K, forward_trajectory, make_plane_scene, render_sequence

    traj = forward_trajectory(6)
    K = default_K()
    images = render_sequence(make_plane_scene(np.random.default_rng(3)), traj, K)
    folder = tmp_path / "synthetic_tum"
    (folder / "rgb").mkdir(parents=True)
    lines = []
    for i, (stamp, image) in enumerate(zip(traj.timestamps_s + 100.0, images)):
        cv2.imwrite(str(folder / "rgb" / f"{stamp:.6f}.png"), cv2.cvtColor(image, cv2.COLOR_GRAY2BGR))
        lines.append(f"{stamp:.6f} rgb/{stamp:.6f}.png")
    (folder / "rgb.txt").write_text("# timestamp filename\n" + "\n".join(lines) + "\n")
    Trajectory(traj.poses_se3, traj.timestamps_s + 100.0).to_tum(folder / "groundtruth.txt")
    (tmp_path / "K.txt").write_text(" ".join(f"{v:.6f}" for v in K.ravel()) + "\n")
    assert detect_kind(folder) == "tum"
    out = tmp_path / "run"
    code, stdout, _ = _run(["vo", str(folder), "--calib", str(tmp_path / "K.txt"), "--scale", "gt", "--out", str(out)],
                           capsys)
    assert code in (0, None) and "(tum," in stdout.replace("\n", "")
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["rejected"] == 0 and metrics["raw"]["ape_rmse_m"] < 0.01
    est = Trajectory.from_tum(out / "poses_tum.txt")
    np.testing.assert_allclose(est.timestamps_s, traj.timestamps_s + 100.0, atol=1e-6)
    # its own ground truth and stamps: --poses / --timestamps are refused (they were dropped, silently)
    code, _, err = _run(["vo", str(folder), "--calib", str(tmp_path / "K.txt"), "--poses", str(folder / "groundtruth.txt")], capsys)
    assert code == 1 and "a TUM RGB-D folder has its own groundtruth.txt; drop --poses" in err


def test_frame_count_below_one_is_a_config_error(capsys):
    from lidarkit.errors import ConfigError
    from lidarkit.vo.inputs import FrameRange, frame_range

    vo_input = open_vo_input(sample_path("kitti_vo", "06"))
    for count in (0, -3):
        with pytest.raises(ConfigError, match=rf"max_frames.*>= 1, got {count}"):
            frame_range(vo_input, 0, count)
        with pytest.raises(ConfigError, match="max_frames"):
            FrameRange(vo_input.images, 2, count)
    assert len(frame_range(vo_input, 1, 3).images) == 3
    code, _, err = _run(["vo", str(sample_path("kitti_vo", "06")), "--max-frames", "0"], capsys)
    assert code == 1 and "--max-frames" in err and ">= 1, got 0" in err and len(err.strip().splitlines()) == 1


def test_metrics_json_is_strict_json_with_non_finite_values_as_null(tmp_path):
    from lidarkit.vo import preset, run_vo
    from lidarkit.vo.output import write_run

    vo_input = open_vo_input(sample_path("kitti_vo", "06"))
    images = [vo_input.images.read_image(i) for i in range(4)]
    result = run_vo(images, vo_input.K, preset("lidarkit", **{"scale.mode": "gt"}), ground_truth=vo_input.ground_truth[:4])
    paths = write_run(result, tmp_path, metrics={"final_error_m": float("nan"), "ape": np.array([0.5, np.inf])}, plot=False)

    def refuse(name):
        raise ValueError(f"invalid JSON constant {name}")

    metrics = json.loads(paths["metrics"].read_text(), parse_constant=refuse)
    assert metrics["final_error_m"] is None and metrics["ape"] == [0.5, None] and metrics["frames"] == 4


def test_vo_self_calibration_falls_back_and_says_why(tmp_path, capsys, caplog):
    """7 straight KITTI 06 frames give one window: self-calibration cannot constrain f; the size guess stays, the
    reason is logged once and shown in the summary, and config.yaml records it."""
    folder = tmp_path / "imgs"
    shutil.copytree(sample_path("kitti_vo", "06", "image_0"), folder)
    out = tmp_path / "run"
    code, stdout, err = _run(["vo", str(folder), "--scale", "none", "--self-calibrate", "--out", str(out)], capsys)
    assert code in (0, None)
    said = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"] + err.splitlines()
    assert sum("focal length self-calibration" in line for line in said) == 1
    assert "not constrained" in stdout
    recorded = yaml.safe_load((out / "config.yaml").read_text())["self_calibration"]
    assert recorded["constrained"] is False and recorded["sigma_px"] is None
    assert recorded["focal_px"] == pytest.approx(0.9 * 1226)


def test_timestamps_file_is_used_and_checked(tmp_path, capsys):
    """``--timestamps`` (it raised an ImportError on every file): the stamps reach poses_tum.txt; stamps that go back
    are a one-line error naming the file's line, before the run."""
    seq = sample_path("kitti_vo", "06")
    stamps = tmp_path / "stamps.txt"
    stamps.write_text("".join(f"{100.0 + 0.1 * k:.3f}\n" for k in range(8)))
    out = tmp_path / "run"
    code, _, err = _run(["vo", str(seq), "--scale", "gt", "--timestamps", str(stamps), "--out", str(out)], capsys)
    assert code in (0, None), err
    est = Trajectory.from_tum(out / "poses_tum.txt")
    np.testing.assert_allclose(est.timestamps_s, 100.0 + 0.1 * np.arange(8), atol=1e-6)
    stamps.write_text("".join(f"{100.0 + 0.1 * k:.3f}\n" for k in (0, 1, 2, 1, 4, 5, 6, 7)))
    code, _, err = _run(["vo", str(seq), "--timestamps", str(stamps)], capsys)
    assert code == 1 and "stamps.txt (line 4, frame 3): time stamps are not strictly increasing" in err and len(err.strip().splitlines()) == 1


def test_too_few_time_stamps_for_a_kitti_image_sequence_say_how_many_images_need_them(tmp_path, capsys):
    """5 stamps for KITTI 06's 51 images read "1101 poses in .../poses/06.txt but 5 time stamps (and the shorter file
    does not end at the last frame present, 50)": never that the images need 51 (an image folder says "5 time stamps
    for 12 images"). Without poses it read "5 time stamps but image 000050.png is frame 50"."""
    from conftest import shared_path

    stamps = tmp_path / "t5.txt"
    stamps.write_text("".join(f"{0.1 * k:.1f}\n" for k in range(5)))
    seq = shared_path("kitti_images", "sequences", "06")
    code, _, err = _run(["vo", str(seq), "--timestamps", str(stamps)], capsys)
    assert code == 1 and err.strip() == f"error: {stamps}: 5 time stamps for 51 images (frames 0-50: 51 needed, one per frame from 0)"
    no_poses = tmp_path / "06"
    shutil.copytree(sample_path("kitti_vo", "06"), no_poses)
    (no_poses / "poses.txt").unlink()
    (no_poses / "image_0" / "000003.png").unlink()  # frames 0-2, 4-7: 8 stamps needed for 7 images
    code, _, err = _run(["vo", str(no_poses), "--timestamps", str(stamps)], capsys)
    assert code == 1 and err.strip() == f"error: {stamps}: 5 time stamps for 7 images (frames 0-7: 8 needed, one per frame from 0)"


def test_a_non_finite_time_stamp_of_an_image_folder_names_its_line(tmp_path, capsys):
    """nan on line 5 of an image folder's --timestamps read "not strictly increasing (nan after 3)", inf there
    blamed line 6, and inf on the last line "vo timestamps_s: 8 time stamps for 8 images, which must be finite and
    increasing" (neither file nor line)."""
    folder = tmp_path / "imgs"
    shutil.copytree(sample_path("kitti_vo", "06") / "image_0", folder)
    stamps = tmp_path / "stamps.txt"
    for bad, line in (("nan", 5), ("inf", 5), ("inf", 8)):
        stamps.write_text("".join(f"{bad if k == line - 1 else k}\n" for k in range(8)))
        code, _, err = _run(["vo", str(folder), "--timestamps", str(stamps)], capsys)
        assert code == 1 and err.strip().splitlines()[-1] == f"error: {stamps} (line {line}): NaN or infinite value", err


def test_a_run_folder_that_is_the_image_folder_is_refused(tmp_path, capsys):
    """lidarkit vo imgs -o imgs wrote trajectory.png among the images, and the next run read it as a frame."""
    folder = tmp_path / "imgs"
    shutil.copytree(sample_path("kitti_vo", "06") / "image_0", folder)
    code, _, err = _run(["vo", str(folder), "-o", str(folder / ".." / "imgs")], capsys)
    assert code == 1 and err.strip().splitlines()[-1] == (
        f"error: --out: the run folder is the image folder {folder.resolve()}: the next run would read its "
        "trajectory.png as a frame; give another folder")
    assert sorted(p.name for p in folder.iterdir()) == [f"{i:06d}.png" for i in range(8)]


def test_a_kitti_root_with_several_sequences_is_refused(tmp_path, capsys):
    """--kind kitti on a root holding sequences 00 and 06 ran sequence 00 without saying so."""
    for number in ("00", "06"):
        shutil.copytree(sample_path("kitti_vo", "06"), tmp_path / "sequences" / number)
    code, _, err = _run(["vo", str(tmp_path), "--kind", "kitti"], capsys)
    assert code == 1 and err.strip().splitlines()[-1] == (
        f"error: {tmp_path}: a KITTI root with 2 sequences (00, 06): give one sequence's folder, e.g. "
        f"{tmp_path / 'sequences' / '00'}")
    code, stdout, err = _run(["vo", str(tmp_path / "sequences" / "06"), "--scale", "gt"], capsys)
    assert code in (0, None) and "APE raw" in stdout, err


def test_a_missing_image_is_a_rejected_frame_not_a_frame_left_out(tmp_path, capsys):
    """000003.png gone from image_0/: frame 3 is rejected as unreadable (before, the frames after it were renumbered
    and the smoothing took frames 2 and 4 as one step apart: smoothed APE 40x the raw one)."""
    seq = tmp_path / "06"
    shutil.copytree(sample_path("kitti_vo", "06"), seq)
    (seq / "image_0" / "000003.png").unlink()
    out = tmp_path / "run"
    code, stdout, err = _run(["vo", str(seq), "--scale", "gt", "--out", str(out)], capsys)
    assert code in (0, None), err
    assert "frame 3 rejected: unreadable image" in stdout + err and "000003.png (frame 3): image file not found" in stdout + err
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["rejected"] == 1 and len(Trajectory.from_kitti(out / "poses_kitti.txt")) == 8
    assert metrics["smoothed"]["ape_rmse_m"] < 2 * metrics["raw"]["ape_rmse_m"] + 0.01


def test_frames_are_named_by_their_number_in_the_input_and_one_frame_is_refused(tmp_path, capsys):
    """--start 3: a rejected frame is named by its number in the input in the message and diagnostics.csv (it said
    "frame 2 rejected: ... 000005.png (frame 5)"); a single frame is an error, not an empty success."""
    seq = tmp_path / "06"
    shutil.copytree(sample_path("kitti_vo", "06"), seq)
    (seq / "image_0" / "000005.png").write_bytes(b"not a png")
    out = tmp_path / "run"
    code, stdout, err = _run(["vo", str(seq), "--scale", "gt", "--start", "3", "--out", str(out)], capsys)
    assert code in (0, None), err
    assert "frame 5 rejected: unreadable image" in stdout
    rows = [line.split(",") for line in (out / "diagnostics.csv").read_text().splitlines()[1:]]
    assert [int(r[0]) for r in rows] == [3, 4, 5, 6, 7] and int(rows[1][1]) == 3
    code, _, err = _run(["vo", str(seq), "--start", "7"], capsys)
    assert code == 1 and "1 frame from frame 7 on: VO needs two frames or more" in err


def test_progress_lines_on_stderr(capsys):
    code, _, err = _run(["vo", str(sample_path("kitti_vo", "06")), "--scale", "gt", "--progress"], capsys)
    assert code in (0, None)
    lines = [line for line in err.splitlines() if " frames (" in line]
    assert len(lines) == 8 and lines[-1].endswith("s left") and "8/8 frames (100 %)" in lines[-1]


def test_options_that_replace_a_guessed_focal_length_say_when_they_are_not_used(capsys):
    code, _, err = _run(["vo", str(sample_path("kitti_vo", "06")), "--self-calibrate", "--focal-factor", "1.2"], capsys)
    assert code in (0, None)
    assert "note: --self-calibrate and --focal-factor not used: the intrinsics are known (kitti calibration)" in err


def test_frames_keep_their_file_numbers_when_the_first_images_are_missing(tmp_path, capsys):
    seq = tmp_path / "06"
    shutil.copytree(sample_path("kitti_vo", "06"), seq)
    (seq / "image_0" / "000000.png").unlink()  # the sequence's images start at frame 1
    (seq / "image_0" / "000004.png").write_bytes(b"not a png")
    out = tmp_path / "run"
    code, stdout, err = _run(["vo", str(seq), "--scale", "none", "--start", "2", "--out", str(out)], capsys)
    assert code in (0, None), err
    assert "frame 4 rejected: unreadable image" in stdout  # (position 3 of the run: it said "frame 2" for 000003.png before)
    assert [int(r.split(",")[0]) for r in (out / "diagnostics.csv").read_text().splitlines()[1:]] == [3, 4, 5, 6, 7]


def test_start_is_an_image_index_and_messages_name_the_frame_numbers_beside_it(tmp_path, capsys):
    """A KITTI folder whose images are 000010..000017: --start 8 said "frame 8 is past the last frame 7" (an index
    read as a frame number, the folder's frames being 10-17) and --start 2 ran from frame 12 with config.yaml saying
    only start: 2. Messages name the image index and its frame; config.yaml records both."""
    sample = sample_path("kitti_vo", "06")
    seq = tmp_path / "late"
    (seq / "image_0").mkdir(parents=True)
    shutil.copy(sample / "calib.txt", seq / "calib.txt")
    for k in range(8):
        shutil.copy(sample / "image_0" / f"{k:06d}.png", seq / "image_0" / f"{k + 10:06d}.png")
    code, _, err = _run(["vo", str(seq), "--start", "8"], capsys)
    assert code == 1 and err.strip() == (f"error: --start: image index 8 is past the last index 7 of {seq} (its 8 images "
                                         "are frames 10-17; --start counts images from 0)"), err
    code, _, err = _run(["vo", str(seq), "--start", "7"], capsys)
    assert code == 1 and "1 frame from image index 7 (frame 17) on: VO needs two frames or more" in err, err
    out = tmp_path / "run"
    code, _, err = _run(["vo", str(seq), "--start", "5", "--max-frames", "4", "--scale", "none", "--out", str(out)], capsys)
    said = "--max-frames 4 from image index 5 (frame 15) ends after the last image, index 7 (frame 17): ran 3"
    assert code in (0, None) and f"warning: {said}" in " ".join(err.split()), err
    config = yaml.safe_load((out / "config.yaml").read_text())
    assert (config["start"], config["start_frame"], config["frames_cut"]) == (5, 15, said)
    assert [int(r.split(",")[0]) for r in (out / "diagnostics.csv").read_text().splitlines()[1:]] == [15, 16, 17]


def test_a_vo_run_into_an_odometry_run_folder_leaves_no_odometry_file(tmp_path, capsys):
    """Each command removed only its own earlier files: vo into an odometry folder kept its ape.png, timing.csv and
    ground truth beside the new poses ("wrote 8 files" beside 12)."""
    from conftest import shared_path

    from lidarkit.odometry import run

    out = tmp_path / "run"
    run(f"kitti:{shared_path('kitti_odometry')}?sequence=00", "small_gicp", frames="0:3", out_dir=out, progress=False)
    assert (out / "timing.csv").exists() and (out / "ground_truth_kitti.txt").exists()
    (out / "notes.txt").write_text("mine")
    code, _, err = _run(["vo", str(sample_path("kitti_vo", "06")), "--scale", "gt", "--out", str(out)], capsys)
    assert code in (0, None), err
    names = sorted(p.name for p in out.iterdir())
    assert "timing.csv" not in names and "ground_truth_kitti.txt" not in names and "ape.png" not in names
    assert "diagnostics.csv" in names and "notes.txt" in names


def test_a_matcher_keeps_the_presets_descriptor_detector(tmp_path, capsys):
    """--matcher bf_cross on report_sift (its own matcher) ran ORB instead of SIFT, silently; the default preset's
    detector has no descriptors, so there ORB is taken, with a note."""
    seq = str(sample_path("kitti_vo", "06"))
    out = tmp_path / "run"
    code, stdout, err = _run(["vo", seq, "--preset", "report_sift", "--matcher", "bf_cross", "--max-frames", "3", "--out", str(out)], capsys)
    assert code in (0, None) and "sift + bf_cross" in " ".join(stdout.split()) and "note:" not in err
    assert yaml.safe_load((out / "config.yaml").read_text())["vo"]["features"]["detector"] == "sift"
    code, stdout, err = _run(["vo", seq, "--matcher", "knn_ratio", "--max-frames", "3"], capsys)
    assert code in (0, None) and "orb + knn_ratio" in " ".join(stdout.split())
    assert "note: --matcher knn_ratio needs descriptors, which gftt has none of: detector orb" in err


def test_smoothing_settings_that_cannot_apply_are_refused_or_said(tmp_path, capsys):
    """window=10 ran as 9 and window=4 with polyorder 3 smoothed nothing, both recorded as asked and the smoothed APE
    printed as if applied."""
    seq = str(sample_path("kitti_vo", "06"))
    code, _, err = _run(["vo", seq, "--set", "smoothing.window=10"], capsys)
    assert err.strip() == "error: vo config smoothing: window must be odd (the filter is centred on each pose), got 10" and code == 1
    out = tmp_path / "run"
    code, stdout, _ = _run(["vo", seq, "--scale", "gt", "--set", "smoothing.window=21", "--out", str(out)], capsys)
    assert code in (0, None) and "smoothing" in stdout and "shrunk" in stdout
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["smoothed"]["smoothing"] == "window 7, polyorder 2 (window 21 shrunk to fit 8 poses)"
    from lidarkit.trajectory import Trajectory as T
    from lidarkit.vo.smoothing import smooth_translations

    short = smooth_translations(T(np.tile(np.eye(4), (2, 1, 1))), window=9, polyorder=2)
    assert short.meta["smoothing"] == "not smoothed: 2 poses leave no odd window above polyorder + 1 (3)"
    three = smooth_translations(T(np.tile(np.eye(4), (3, 1, 1))), window=9, polyorder=2)  # window 3 = order + 1: exact fit
    assert three.meta["smoothing"].startswith("not smoothed: 3 poses")
    code, _, err = _run(["vo", seq, "--set", "smoothing.window=3"], capsys)
    assert code == 1 and "polyorder (2) must be below window - 1 (2)" in err


@pytest.mark.slow
def test_self_calibration_shows_progress(tmp_path, capsys):
    """--self-calibrate took 20-45 s per 50 frames before the first progress line. (10 frames: two windows, both
    tracked and adjusted, the fewest that do.)"""
    import shutil

    from conftest import shared_path

    folder = tmp_path / "imgs"
    folder.mkdir()
    for png in sorted(shared_path("kitti_images", "sequences", "06", "image_0").glob("*.png"))[:10]:
        shutil.copy2(png, folder / png.name)
    code, _, err = _run(["vo", str(folder), "--self-calibrate", "--progress"], capsys)
    assert code in (0, None) and "self-calibrating the focal length:" in err


def test_an_unreadable_first_frame_is_not_scored_as_an_estimate(tmp_path, capsys):
    """000000.png corrupt: frame 0 only holds the start pose (frame 1's). Scored as an estimate, with the smoothing run
    across it, it raised the APE of the same frames 67-fold (0.0048 -> 0.32 m, smoothed 0.004 -> 0.12 m)."""
    seq = tmp_path / "06"
    shutil.copytree(sample_path("kitti_vo", "06"), seq)
    (seq / "image_0" / "000000.png").write_bytes(b"not a png")
    runs = {}
    for name, extra in (("bad_first", []), ("from_1", ["--start", "1"])):
        code, stdout, err = _run(["vo", str(seq), "--out", str(tmp_path / name), *extra], capsys)
        assert code in (0, None), err
        runs[name] = json.loads((tmp_path / name / "metrics.json").read_text())
    bad, clean = runs["bad_first"], runs["from_1"]
    assert bad["scored_from_frame"] == 1 and "scored_from_frame" not in clean
    for variant in ("raw", "smoothed"):
        assert bad[variant]["ape_rmse_m"] == pytest.approx(clean[variant]["ape_rmse_m"], rel=1e-6), variant


@pytest.mark.parametrize("scale", ["gt", "relative"])
def test_an_unreadable_frame_before_the_first_pair_is_placed_on_its_motion(tmp_path, capsys, scale):
    """000001.png corrupt: frame 1 had no velocity to predict from and kept frame 0's pose (1.2 m off); scored, it
    raised the APE of the 8-frame sample ~100-fold (gt 0.0036 -> 0.40 m, relative 0.0050 -> 0.34 m). It is now
    placed on the motion of the first accepted pair (0 -> 2), in gt mode with the ground-truth step length."""
    seq = tmp_path / "06"
    shutil.copytree(sample_path("kitti_vo", "06"), seq)
    (seq / "image_0" / "000001.png").write_bytes(b"not a png")
    runs = {}
    for name, data in (("clean", sample_path("kitti_vo", "06")), ("bad", seq)):
        code, _, err = _run(["vo", str(data), "--scale", scale, "--out", str(tmp_path / name)], capsys)
        assert code in (0, None), err
        runs[name] = json.loads((tmp_path / name / "metrics.json").read_text())
    assert runs["bad"]["rejected"] == 1 and runs["bad"]["accepted_pairs"] == 6
    assert runs["bad"]["raw"]["ape_rmse_m"] < 1.5 * runs["clean"]["raw"]["ape_rmse_m"] < 0.01
    rows = (tmp_path / "bad" / "diagnostics.csv").read_text().splitlines()
    assert "placed on the first accepted motion" in rows[2]


@pytest.mark.parametrize("scale, alignment", [("gt", "se3"), ("relative", "sim3")])
def test_a_ground_truth_that_cannot_align_leaves_the_run_unscored_not_lost(tmp_path, capsys, scale, alignment):
    """Ground truth on a straight line (Umeyama's rotation undefined): the finished run ended in an error and --out
    wrote nothing; its poses are written, and the output says why it is not scored. Relative scale failed again in
    its plot (aligned to the ground truth by Sim(3)): the plot is drawn unaligned."""
    seq = tmp_path / "06"
    shutil.copytree(sample_path("kitti_vo", "06"), seq)
    n = len(list((seq / "image_0").glob("*.png")))
    line = "\n".join(f"1 0 0 0 0 1 0 0 0 0 1 {0.85 * i}" for i in range(n)) + "\n"
    (tmp_path / "line.txt").write_text(line)
    out = tmp_path / "run"
    code, stdout, err = _run(["vo", str(seq), "--poses", str(tmp_path / "line.txt"), "--scale", scale, "--out", str(out)], capsys)
    assert code in (0, None), err
    assert f"not scored against the ground truth: {alignment} alignment failed" in stdout
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["not_scored"].startswith(f"{alignment} alignment failed") and "raw" not in metrics
    assert len(Trajectory.from_kitti(out / "poses_kitti.txt")) == n
    assert (out / "trajectory.png").stat().st_size > 10_000


@pytest.mark.parametrize("detector", ["orb", "akaze"])
def test_images_too_small_for_feature_detection_are_one_line(tmp_path, capsys, detector):
    """200 x 1 px frames: ORB and AKAZE asserted inside OpenCV (a traceback; AKAZE tried to allocate 18 EB)."""
    folder = tmp_path / "tiny"
    folder.mkdir()
    rng = np.random.default_rng(0)
    for i in range(4):
        cv2.imwrite(str(folder / f"{i:06d}.png"), (255 * rng.random((1, 200))).astype(np.uint8))
    code, _, err = _run(["vo", str(folder), "--detector", detector, "--matcher", "knn_ratio"], capsys)
    assert code == 1 and err.strip() == "error: tiny: images of 200 x 1 px: too small for feature detection (at least 32 px a side)"


def test_intrinsics_of_other_images_are_warned_about(tmp_path, capsys, caplog):
    """The sequence's images at half size with its full-size calib.txt: the run went through without a word (APE
    looked fine, RPE was 0.48 m a frame). The principal point far from the images' centre is warned about; the
    sequence as it is gives no such warning."""
    import logging

    seq = tmp_path / "06"
    shutil.copytree(sample_path("kitti_vo", "06"), seq)
    for path in sorted((seq / "image_0").glob("*.png")):
        image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        cv2.imwrite(str(path), cv2.resize(image, (image.shape[1] // 2, image.shape[0] // 2)))
    with caplog.at_level(logging.WARNING):
        code, _, err = _run(["vo", str(seq), "--scale", "gt"], capsys)
    assert code in (0, None), err
    assert any("is far from the centre of the 613 x 185 px images: intrinsics of other" in r.getMessage() for r in caplog.records)
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        _run(["vo", str(sample_path("kitti_vo", "06")), "--scale", "gt"], capsys)
    assert not any("far from the centre" in r.getMessage() for r in caplog.records)


def test_self_calibration_counts_the_windows_a_bad_frame_bars(tmp_path, capsys, caplog):
    """10 KITTI 06 frames, frame 7 unreadable: the window at 5 holds it; the one at 0 is clean (its longer window
    reached frame 7 and barred it too), and the reason blamed the motion: "0 of 2 windows show translation
    parallax". The clean window is tracked, and the reason counts the window the bad frame bars."""
    from conftest import shared_path

    folder = tmp_path / "imgs"
    folder.mkdir()
    for i in range(10):
        shutil.copy(shared_path("kitti_images", "sequences", "06", "image_0", f"{i:06d}.png"), folder / f"{i:06d}.png")
    (folder / "000007.png").write_bytes(b"not a png")
    import logging

    with caplog.at_level(logging.WARNING):
        code, _, err = _run(["vo", str(folder), "--scale", "none", "--self-calibrate"], capsys)
    assert code in (0, None), err
    said = [r.getMessage() for r in caplog.records if "focal length self-calibration" in r.getMessage()]
    assert len(said) == 1 and "1 of 1 windows show translation parallax" in said[0], said
    assert "1 more hold an unreadable or odd-sized frame" in said[0]
    assert "no motion or pure rotation" not in said[0]  # (the usable window showed parallax: the bad frame is the cause)


def test_scale_settings_the_pipeline_does_not_use_are_said(capsys):
    """--set scale.corner_pose=corners left the default pipeline's poses byte-identical without a word (KLT on corners
    builds no separate corner path), as did any scale setting under --scale gt."""
    seq = str(sample_path("kitti_vo", "06"))
    code, _, err = _run(["vo", seq, "--set", "scale.corner_pose=corners", "--set", "scale.min_common_points=20"], capsys)
    assert code in (0, None) and err.count("note: --set") == 1
    assert "note: --set scale.corner_pose not used: KLT on corners carries depth with its own tracks" in err
    code, _, err = _run(["vo", seq, "--scale", "gt", "--set", "scale.min_common_points=20"], capsys)
    assert "note: --set scale.min_common_points not used: scale mode gt: the scale settings act with relative" in err
    code, _, err = _run(["vo", seq, "--detector", "orb", "--set", "scale.corner_pose=corners"], capsys)
    assert "note: --set" not in err  # ORB + KLT builds the corner path: the setting acts


def test_settings_of_a_stage_choice_not_taken_are_said_and_options_set_twice_refused(capsys):
    """--set matching.ratio=0.1 (knn_ratio's), features.fast_threshold=200 (fast's) and preprocess.clahe_clip_limit=40
    (clahe's) gave the default pipeline's poses byte for byte without a word; --scale relative --set scale.mode=gt ran
    gt (the --set value replaced the option's silently)."""
    seq = str(sample_path("kitti_vo", "06"))
    code, _, err = _run(["vo", seq, "--max-frames", "3", "--set", "matching.ratio=0.1", "--set", "features.fast_threshold=200",
                         "--set", "preprocess.clahe_clip_limit=40"], capsys)
    assert code in (0, None) and err.count("note: --set") == 3, err
    assert "note: --set matching.ratio not used: matching.method is klt: the setting acts with knn_ratio" in err
    assert "note: --set preprocess.clahe_clip_limit not used: preprocess.method is none: the setting acts with clahe" in err
    code, _, err = _run(["vo", seq, "--max-frames", "3", "--detector", "fast", "--preprocess", "gaussian",
                         "--set", "features.fast_threshold=30", "--set", "preprocess.blur_kernel_px=3"], capsys)
    assert code in (0, None) and "note: --set" not in err, err
    for option, named, setting in ((["--scale", "relative"], "--scale", "scale.mode=gt"),
                                   (["--no-sanity"], "--sanity/--no-sanity", "sanity.enabled=true"),
                                   (["--features", "900"], "--features", "features.max_features=500")):
        code, _, err = _run(["vo", seq, "--max-frames", "3", *option, "--set", setting], capsys)
        key = setting.split("=")[0]
        assert code == 1 and f"error: --set {key}: given twice, by {named} and by --set {key}=...: give it once" in err, err


def test_sanity_and_klt_settings_the_pipeline_does_not_use_are_said(capsys):
    """--no-sanity --set sanity.min_parallax_px=50 and --preset report_sift --set matching.klt_levels=0 (descriptor
    matching, gt scale: no KLT anywhere) gave byte-identical poses without the "not used" note."""
    seq = str(sample_path("kitti_vo", "06"))
    code, _, err = _run(["vo", seq, "--max-frames", "3", "--no-sanity", "--set", "sanity.min_parallax_px=50",
                         "--set", "sanity.min_inliers=40"], capsys)
    assert code in (0, None) and err.count("note: --set") == 1, err  # the inlier count gates every pair
    assert "note: --set sanity.min_parallax_px not used: sanity.enabled is false: the pose checks are off" in err
    code, _, err = _run(["vo", seq, "--max-frames", "3", "--preset", "report_sift", "--set", "matching.klt_levels=0"],
                        capsys)
    assert code in (0, None) and ("note: --set matching.klt_levels not used: matching.method is bf_cross: the setting "
                                  "acts with klt or with the relative scale's corners (scale.points corners)") in err, err
    code, _, err = _run(["vo", seq, "--max-frames", "3", "--preset", "report_sift", "--scale", "relative",
                         "--set", "matching.klt_levels=2"], capsys)
    assert code in (0, None) and "note: --set" not in err, err  # the relative scale tracks its corners by KLT


def test_geometry_settings_of_the_pure_rotation_check_are_said_unused_without_sanity(capsys):
    """geometry.degeneracy_threshold_px and geometry.rotation_focal_ratio feed only the sanity stage's pure-rotation
    check: with --no-sanity they left the poses byte-identical without the "not used" note; with the checks on they act."""
    seq = str(sample_path("kitti_vo", "06"))
    settings = ["--set", "geometry.degeneracy_threshold_px=3", "--set", "geometry.rotation_focal_ratio=1.25"]
    code, _, err = _run(["vo", seq, "--max-frames", "3", "--no-sanity", *settings], capsys)
    assert code in (0, None) and err.count("note: --set") == 2, err
    for key in ("geometry.degeneracy_threshold_px", "geometry.rotation_focal_ratio"):
        assert (f"note: --set {key} not used: sanity.enabled is false: the setting feeds only its pure-rotation "
                "check") in err, err
    code, _, err = _run(["vo", seq, "--max-frames", "3", *settings], capsys)
    assert code in (0, None) and "note: --set" not in err, err


def test_triangulation_angle_and_threshold_settings_the_pipeline_does_not_use_are_said(capsys):
    """--set scale.min_triangulation_angle_deg gave byte-identical poses without a note wherever the relative scale
    tracks corners (they use scale.corner_min_angle_deg), as did geometry.threshold_px with LMedS alone (OpenCV's LMedS
    takes no threshold) and neither the fundamental-matrix fallback nor the scale's corners."""
    seq = str(sample_path("kitti_vo", "06"))
    code, _, err = _run(["vo", seq, "--preset", "report_orb", "--scale", "relative", "--max-frames", "3",
                         "--set", "scale.min_triangulation_angle_deg=5"], capsys)
    assert code in (0, None) and err.count("note: --set") == 1, err
    assert ("note: --set scale.min_triangulation_angle_deg not used: scale.points is corners: the corners use "
            "scale.corner_min_angle_deg") in err, err
    lmeds = ["--estimator", "lmeds", "--set", "geometry.fundamental_fallback=false", "--set", "geometry.threshold_px=3"]
    code, _, err = _run(["vo", seq, "--max-frames", "3", *lmeds, "--set", "scale.min_triangulation_angle_deg=2"], capsys)
    assert code in (0, None) and err.count("note: --set") == 1, err  # KLT on corners: its own tracks use the angle
    assert ("note: --set geometry.threshold_px not used: geometry.estimators is lmeds (it sets its own threshold from "
            "the median error), geometry.fundamental_fallback is false and the relative scale tracks no corners") in err


def test_threshold_and_scale_settings_are_said_unused_exactly_where_no_stage_reads_them():
    """inert_settings names geometry.threshold_px only where no F fallback or corner filter reads it, and the corner
    path's settings (and the carried-depth limit with descriptor matches) where scale.points is features."""
    from lidarkit.vo.config import inert_settings, preset

    def unused(name, *keys, **changes):
        return [key for key, _ in inert_settings(preset(name, **changes), keys)]

    lmeds = {"geometry.estimators": ("lmeds",)}
    assert unused("lidarkit", "geometry.threshold_px", **lmeds) == []  # the F fallback reads it
    assert unused("report_sift", "geometry.threshold_px", **lmeds) == ["geometry.threshold_px"]  # no fallback
    assert unused("report_sift", "geometry.threshold_px", **lmeds, **{"scale.mode": "relative"}) == []  # corner filter
    assert unused("report_sift", "geometry.threshold_px") == []  # RANSAC reads it
    orb_features = {"features.detector": "orb", "scale.points": "features"}
    assert unused("lidarkit", "scale.points", "scale.corner_pose", "scale.max_depth_views", "scale.corner_min_angle_deg",
                  "scale.min_triangulation_angle_deg", "scale.max_carried_points", **orb_features) == [
        "scale.corner_pose", "scale.max_depth_views", "scale.corner_min_angle_deg"]
    assert unused("report_orb", "scale.max_carried_points", "scale.min_triangulation_angle_deg",
                  **{"scale.mode": "relative", "scale.points": "features"}) == ["scale.max_carried_points"]
    assert unused("report_orb", "scale.max_carried_points", "scale.corner_min_angle_deg",
                  "scale.min_triangulation_angle_deg", **{"scale.mode": "relative"}) == ["scale.min_triangulation_angle_deg"]


def test_the_run_folder_records_the_input_poses_and_time_stamps_it_read(tmp_path, capsys, monkeypatch):
    """config.yaml named the input as typed and neither the ground truth the run was scored against nor its time
    stamps (--poses, --poses-format, --timestamps, or the dataset's own files): both files now record them, resolved."""
    seq = sample_path("kitti_vo", "06")
    work = tmp_path / "work"
    work.mkdir()
    shutil.copy(seq / "poses.txt", work / "gt.txt")
    (work / "stamps.txt").write_text("".join(f"{10 + 0.1 * k:.1f}\n" for k in range(8)))
    monkeypatch.chdir(work)
    code, _, err = _run(["vo", str(seq / "image_0"), "--kind", "images", "--calib", str(seq / "calib.txt"), "--poses",
                         "gt.txt", "--timestamps", "stamps.txt", "--max-frames", "3", "--out", "run"], capsys)
    assert code in (0, None), err
    read = {"input": str((seq / "image_0").resolve()), "poses": str((work / "gt.txt").resolve()), "poses_format": "kitti",
            "timestamps": str((work / "stamps.txt").resolve())}
    config = yaml.safe_load((work / "run" / "config.yaml").read_text())
    metrics = json.loads((work / "run" / "metrics.json").read_text())
    assert {key: config[key] for key in read} == read and {key: metrics[key] for key in read} == read
    code, _, err = _run(["vo", str(seq), "--max-frames", "3", "--out", "own"], capsys)
    config = yaml.safe_load((work / "own" / "config.yaml").read_text())
    assert code in (0, None) and {key: config[key] for key in read} == {
        "input": str(seq.resolve()), "poses": f"the dataset's own {(seq / 'poses.txt').resolve()}", "poses_format": "kitti",
        "timestamps": f"the dataset's own {(seq / 'times.txt').resolve()}"}, err


def test_gt_scale_without_ground_truth_is_refused_before_self_calibration(tmp_path, capsys, caplog):
    """--scale gt on an image folder without poses was refused by MonoVO ("vo scale.mode: scale mode 'gt' needs a
    ground-truth trajectory") only after --self-calibrate had run (46 s on 50 frames)."""
    from conftest import shared_path

    folder = tmp_path / "imgs"
    folder.mkdir()
    for i in range(8):
        shutil.copy(shared_path("kitti_images", "sequences", "06", "image_0", f"{i:06d}.png"), folder / f"{i:06d}.png")
    import logging

    with caplog.at_level(logging.INFO):
        code, _, err = _run(["vo", str(folder), "--scale", "gt", "--self-calibrate"], capsys)
    assert code == 1 and err.strip().splitlines()[-1] == (
        f"error: --scale: scale gt needs ground-truth poses and the input {folder} has none: give --poses FILE or "
        "--scale none|relative")
    assert not any("self-calibration" in r.getMessage() for r in caplog.records)


def test_start_kind_and_a_bare_list_value_are_named_in_their_errors(capsys):
    """--start 8 on the 8-frame sample read "kitti_06_image_0: start frame 8 outside 0..7" and --kind bogus "vo input
    kind: ..." (neither named the option); --set geometry.estimators=magsac read "Input should be a valid tuple"
    without the [magsac] form that works."""
    data = str(sample_path("kitti_vo", "06"))
    for args, line in (
        (["--start", "8"], f"error: --start: frame 8 is past the last frame 7 of {data}"),
        (["--kind", "bogus"], "error: --kind: unknown input kind 'bogus'; known: auto, kitti, tum, images"),
        (["--set", "geometry.estimators=magsac"],
         "error: vo config geometry.estimators: Input should be a valid tuple (got 'magsac'); give a list: [magsac]"),
    ):
        code, _, err = _run(["vo", data, *args], capsys)
        assert code == 1 and err.strip() == line, err


def test_a_bad_value_of_an_option_names_the_option(capsys):
    """--scale relatve read "vo config scale.mode: ..." (the config field, not the option given); --set keeps the field."""
    data = str(sample_path("kitti_vo", "06"))
    for args, line in (
        (["--scale", "relatve"], "error: --scale: Input should be 'gt', 'none' or 'relative' (got 'relatve')"),
        (["--detector", "orbb"], "error: --detector: Input should be 'gftt', 'fast', 'orb', 'sift' or 'akaze' (got 'orbb')"),
        (["--estimator", "magsacc"], "error: --estimator: Input should be 'ransac', 'magsac' or 'lmeds' (got 'magsacc')"),
        (["--set", "scale.mode=x"], "error: vo config scale.mode: Input should be 'gt', 'none' or 'relative' (got 'x')"),
    ):
        with pytest.raises(SystemExit) as exc:
            main(["vo", data, *args])
        assert exc.value.code == 1 and capsys.readouterr().err.strip() == line


def test_kind_preset_and_a_matcher_without_descriptors_are_named_as_given(tmp_path, capsys):
    """--kind kitti on an image folder read "sequence 00 not found" (00 was never asked for), --matcher knn_ratio
    --detector gftt "vo config: ..." and --preset ORB "preset: ..." (the library's names, not the options)."""
    folder = tmp_path / "plain"
    shutil.copytree(sample_path("kitti_vo", "06", "image_0"), folder)
    for args, line in (
        (["--kind", "kitti"], f"error: {folder}: not a KITTI sequence folder (no image_0/) nor a KITTI root (no "
                              "sequences/NN/image_0/)"),
        (["--matcher", "knn_ratio", "--detector", "gftt"], "error: --matcher and --detector: matching 'knn_ratio' needs "
         "descriptors; detector 'gftt' has none (use orb, sift or akaze, or matching 'klt')"),
        (["--preset", "report_orb", "--detector", "fast"], "error: --detector: matching 'knn_ratio' needs descriptors; "
         "detector 'fast' has none (use orb, sift or akaze, or matching 'klt')"),
        (["--preset", "ORB"], "error: --preset: unknown VO preset 'ORB'; known: lidarkit, report_orb, report_sift"),
    ):
        code, _, err = _run(["vo", str(folder), *args], capsys)
        assert code == 1 and err.strip() == line, err
    # a KITTI root holding one sequence opens that one (it looked for sequence 00 too)
    root = tmp_path / "root"
    shutil.copytree(sample_path("kitti_vo", "06"), root / "sequences" / "06")
    code, stdout, err = _run(["vo", str(root), "--kind", "kitti", "--scale", "gt"], capsys)
    assert code in (0, None) and "7 of 7" in stdout, err


def test_every_plotted_trajectory_ends_in_a_dot_of_its_colour():
    """The end marker was derived from the line style: "C0-"[:2] is "C0", so the VO curves' ends had no marker
    (only the ground truth's "k-" became "ko")."""
    from matplotlib.figure import Figure

    from lidarkit.vo.output import draw_top_view

    poses = np.repeat(np.eye(4)[None], 3, axis=0)
    poses[:, 2, 3] = [0.0, 1.0, 2.5]
    trajs = {name: Trajectory(poses) for name in ("ground truth", "VO raw", "VO smoothed")}
    ax = Figure().add_subplot(1, 1, 1)
    draw_top_view(ax, trajs)
    curves, ends = ax.lines[0::2], ax.lines[1::2]
    assert [e.get_marker() for e in ends] == ["o", "o", "o"]
    from matplotlib.colors import to_hex

    assert [to_hex(e.get_color()) for e in ends] == [to_hex(c.get_color()) for c in curves]
    assert [to_hex(c.get_color()) for c in curves] == [to_hex(c) for c in ("k", "C0", "C1")]
    assert [float(e.get_ydata()[0]) for e in ends] == [2.5, 2.5, 2.5]


@pytest.mark.skipif(not __import__("os").path.exists("/dev/full"), reason="needs /dev/full (a device that is always full)")
def test_a_stdout_that_refuses_the_table_still_gets_the_run_folder_written(tmp_path):
    """`lidarkit vo SEQ -o fv > /dev/full` printed the table before writing the run folder: the print failed (one line,
    exit 1) and no fv/ was left, the whole run lost. The folder is written first, as odometry's is."""
    import subprocess
    import sys

    out = tmp_path / "fv"
    with open("/dev/full", "w") as full:
        done = subprocess.run([sys.executable, "-m", "lidarkit", "vo", str(sample_path("kitti_vo", "06")), "--scale", "gt",
                               "--max-frames", "4", "-o", str(out), "--no-progress"], stdout=full, stderr=subprocess.PIPE,
                              text=True, timeout=300)
    assert (done.returncode, done.stderr) == (1, "error: stdout: cannot write: no space left on the device\n")
    assert len(Trajectory.from_kitti(out / "poses_kitti.txt")) == 4
    metrics = json.loads((out / "metrics.json").read_text())
    assert (metrics["frames"], metrics["accepted_pairs"]) == (4, 3) and metrics["raw"]["ape_rmse_m"] < 0.03
    assert yaml.safe_load((out / "config.yaml").read_text())["max_frames"] == 4 and (out / "trajectory.png").is_file()


def test_the_plot_is_aligned_on_the_frames_the_scores_use(tmp_path, capsys):
    """Frames 0-1 unreadable (they only hold frame 2's pose): the plot's Sim(3) fit used every pose, so its VO curve was
    not the one scored (on 20 KITTI frames with 6 bad its end lay 1.15 m beyond the GT end, APE 0.014 m). The plotted
    curves are fitted from the first scored frame on, and labelled as the table ("Sim(3)-aligned", not "Sim3")."""
    from lidarkit.eval import align_trajectory, ape
    from lidarkit.vo.output import aligned_to_ground_truth

    seq = tmp_path / "06"
    shutil.copytree(sample_path("kitti_vo", "06"), seq)
    for name in ("000000.png", "000001.png"):
        (seq / "image_0" / name).write_bytes(b"not a png")
    code, _, err = _run(["vo", str(seq), "--out", str(tmp_path / "run")], capsys)
    assert code in (0, None), err
    metrics = json.loads((tmp_path / "run" / "metrics.json").read_text())
    first = metrics["scored_from_frame"]
    assert first == 2
    gt = Trajectory.from_kitti(seq / "poses.txt")
    raw, smoothed = (Trajectory.from_kitti(tmp_path / "run" / f) for f in ("poses_kitti.txt", "poses_smoothed_kitti.txt"))
    curves = aligned_to_ground_truth(gt, {"VO raw": raw, "VO smoothed": smoothed}, first_frame=first)
    assert list(curves) == ["ground truth", "VO raw (Sim(3)-aligned)", "VO smoothed (Sim(3)-aligned)"]
    for variant in ("raw", "smoothed"):
        plotted = curves[f"VO {variant} (Sim(3)-aligned)"]
        assert len(plotted) == len(gt)  # the whole trajectory, frames before the first scored one too
        assert ape(gt[first:], plotted[first:]).rmse == pytest.approx(metrics[variant]["ape_rmse_m"], rel=1e-4)
    fitted_on_all = align_trajectory(gt, raw, "sim3")[0]  # (the old plot's fit: scored frames much further off)
    assert ape(gt[first:], fitted_on_all[first:]).rmse > 3 * metrics["raw"]["ape_rmse_m"]


def test_calib_reads_a_kitti_raw_calibration_and_a_k_label_and_says_what_it_reads(tmp_path, capsys):
    """--calib calib_cam_to_cam.txt (KITTI raw) was read as an odometry calib.txt: "(line 1): calib_time: not a number";
    "K: 9 numbers" read "no P0 projection matrix" though --help offers 9 numbers (K). The raw file gives the left 3x3
    of P_rect_00 (the kitti_raw reader's K), "K:" its 9 numbers, and other labels one line saying what is read."""
    from conftest import shared_path

    from lidarkit.io.images import read_intrinsics
    from lidarkit.io.kitti_raw import KittiRaw

    date = shared_path("kitti_raw", "2011_09_26")
    K = read_intrinsics(date / "calib_cam_to_cam.txt")
    np.testing.assert_array_equal(K, KittiRaw(date.parent, "2011_09_26", "0001").K)
    assert (K[0, 0], K[0, 2], K[1, 2]) == (721.5377, 609.5593, 172.854)
    (tmp_path / "k.txt").write_text("K: 707.0912 0 601.8873 0 707.0912 183.1104 0 0 1\n")
    np.testing.assert_array_equal(read_intrinsics(tmp_path / "k.txt"),
                                  [[707.0912, 0, 601.8873], [0, 707.0912, 183.1104], [0, 0, 1]])
    (tmp_path / "c.yaml").write_text("fx: 707\nfy: 707\n")
    code, _, err = _run(["vo", str(sample_path("kitti_vo", "06")), "--calib", str(tmp_path / "c.yaml")], capsys)
    assert code == 1 and err == (f"error: {tmp_path / 'c.yaml'}: no P0:, P_rect_00: or K: line; intrinsics files hold 9 numbers "
                                 "(K row-major, bare or after 'K:'), 4 (fx fy cx cy), a KITTI odometry calib.txt (P0) or a "
                                 "KITTI raw calib_cam_to_cam.txt (P_rect_00)\n")


def test_tum_poses_for_an_image_0_folder_name_the_kind_that_reads_it_as_images(tmp_path, capsys):
    """`lidarkit vo SEQ/image_0 --poses-format tum` said "--poses-format tum is for image folders" to a user who had
    given an image folder (an image_0/ beside calib.txt is read as its sequence): the error names --kind images."""
    seq = sample_path("kitti_vo", "06")
    tum = Trajectory.from_kitti(seq / "poses.txt").with_timestamps(np.arange(8) * 0.1).to_tum(tmp_path / "gt.tum")
    code, _, err = _run(["vo", str(seq / "image_0"), "--poses", str(tum), "--poses-format", "tum"], capsys)
    assert code == 1 and err == (f"error: {seq / 'image_0'}: read as its KITTI sequence (an image_0/ beside calib.txt), whose "
                                 "poses are KITTI rows (12 numbers, one per image): --poses-format tum is for image folders: "
                                 "add --kind images (kind='images')\n")
    code, stdout, err = _run(["vo", str(seq / "image_0"), "--poses", str(tum), "--poses-format", "tum", "--kind", "images",
                              "--calib", str(seq / "calib.txt")], capsys)
    assert code in (0, None) and "APE raw (Sim(3)-aligned)" in stdout, err
    assert "RPE raw 1 frame (Sim(3)-aligned)" in stdout  # (its scale scales every relative pose)


def test_tum_poses_given_to_a_kitti_sequence_name_a_vo_command_that_reads_them(tmp_path, capsys):
    """A TUM file as a KITTI sequence's --poses advised "read it as tum: --format tum, Trajectory.from_tum": no option
    of lidarkit vo. The hint is a vo command (its images as an image folder with --poses-format tum), and it runs."""
    import shlex

    seq = tmp_path / "06"
    shutil.copytree(sample_path("kitti_vo", "06"), seq)
    tum = Trajectory.from_kitti(seq / "poses.txt").with_timestamps(np.arange(8) * 0.1).to_tum(tmp_path / "gt.tum")
    code, _, err = _run(["vo", str(seq), "--poses", str(tum)], capsys)
    advised = (f"lidarkit vo {seq / 'image_0'} --kind images --calib {seq / 'calib.txt'} --poses {tum} "
               "--poses-format tum")
    assert code == 1 and err == (f"error: {tum} (line 2): expected 12 numbers, found 8 (a TUM trajectory? read it as tum: "
                                 "a KITTI sequence's poses are KITTI rows; give its images as an image folder: "
                                 f"{advised} (ImageFolder(..., poses_format='tum')))\n"), err
    code, stdout, err = _run(shlex.split(advised)[1:], capsys)
    assert code in (0, None) and "APE raw (Sim(3)-aligned)" in stdout, err


def test_poses_shorter_than_the_image_folder_say_they_pair_before_the_frames_are_picked(tmp_path, capsys):
    """15 poses for a 51-image folder run with --max-frames 10 read "15 poses for 51 images": the user, who asked for
    10 frames, could not tell why 15 were too few. The error says poses pair one per image of the folder, in order,
    before --start/--max-frames pick frames (time stamps alike)."""
    seq = sample_path("kitti_vo", "06")
    (tmp_path / "p5.txt").write_text("".join((seq / "poses.txt").read_text().splitlines(keepends=True)[:5]))
    (tmp_path / "t5.txt").write_text("0\n0.1\n0.2\n0.3\n0.4\n")
    why = "(one per image of the folder, in order from its first: --start and --max-frames pick frames after pairing)"
    for option, short, what in (("--poses", "p5.txt", "poses"), ("--timestamps", "t5.txt", "time stamps")):
        code, _, err = _run(["vo", str(seq / "image_0"), "--kind", "images", "--calib", str(seq / "calib.txt"), option,
                             str(tmp_path / short), "--max-frames", "3"], capsys)
        assert code == 1 and err == f"error: {tmp_path / short}: 5 {what} for 8 images {why}\n", err


def test_max_frames_past_the_end_says_how_many_ran(tmp_path, capsys):
    """--start 6 --max-frames 5 on 8 frames ran 2 without a word, config.yaml recording max_frames 5 (odometry says a
    frame slice past the end); it is said on stderr and recorded."""
    code, _, err = _run(["vo", str(sample_path("kitti_vo", "06")), "--start", "6", "--max-frames", "5", "--no-progress",
                         "--out", str(tmp_path / "run")], capsys)
    said = "--max-frames 5 from frame 6 ends after the last frame (7): ran 2"
    assert code in (0, None) and f"warning: {said}" in " ".join(err.split())
    assert yaml.safe_load((tmp_path / "run" / "config.yaml").read_text())["frames_cut"] == said


def test_10_and_12_bit_images_in_16_bit_files_keep_their_grey_levels(tmp_path, capsys):
    """A 12-bit (10-bit) image in a 16-bit PNG was read with 16 (4) grey levels (OpenCV divides by 256): APE 0.0291 m
    for 0.0159 m on KITTI 06, and a 10-bit folder failed "no frame pair accepted". 16-bit images are scaled by the
    bits their values use; full-range and colour 16-bit images read as before."""
    from lidarkit.io.kitti import read_gray_image

    src = sample_path("kitti_vo", "06")
    gray = cv2.imread(str(src / "image_0" / "000000.png"), cv2.IMREAD_GRAYSCALE)
    for name, image in (("g12.png", gray.astype(np.uint16) * 16), ("g10.png", gray.astype(np.uint16) * 4),
                        ("g16.png", gray.astype(np.uint16) * 257),
                        ("c12.png", cv2.cvtColor(gray, cv2.COLOR_GRAY2BGR).astype(np.uint16) * 16)):
        cv2.imwrite(str(tmp_path / name), image)
        np.testing.assert_array_equal(read_gray_image(tmp_path / name), gray, err_msg=name)
    folder = tmp_path / "g10"
    folder.mkdir()
    for path in sorted((src / "image_0").glob("*.png")):
        cv2.imwrite(str(folder / path.name), cv2.imread(str(path), cv2.IMREAD_GRAYSCALE).astype(np.uint16) * 4)
    code, _, err = _run(["vo", str(folder), "--calib", str(src / "calib.txt"), "--poses", str(src / "poses.txt"),
                         "--scale", "gt", "--out", str(tmp_path / "run")], capsys)
    metrics = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert code in (0, None) and metrics["rejected"] == 0 and metrics["raw"]["ape_rmse_m"] < 0.03, err


def test_the_feature_gif_of_colour_frames_is_written_and_leaves_them_undrawn(tmp_path):
    """write_run(gif_images=colour frames) raised cv2's "Bad number of channels" (it converted every frame as grey)
    and the whole run folder was lost, though MonoVO had run on those frames."""
    from PIL import Image

    from lidarkit.vo import MonoVO, preset
    from lidarkit.vo.output import write_run

    vo_input = open_vo_input(sample_path("kitti_vo", "06"))
    gray = [vo_input.images.read_image(i) for i in range(4)]
    for code, name in ((cv2.COLOR_GRAY2BGR, "bgr"), (cv2.COLOR_GRAY2BGRA, "bgra")):
        colour = [cv2.cvtColor(image, code) for image in gray]
        before = [image.copy() for image in colour]
        result = MonoVO(preset("lidarkit"), vo_input.K).run(colour, keep_tracks=True)
        paths = write_run(result, tmp_path / name, gif_images=colour, plot=False)
        with Image.open(paths["gif"]) as gif:
            assert gif.n_frames == result.summary()["accepted_pairs"] == 3
        assert all(np.array_equal(a, b) for a, b in zip(colour, before))


def test_nanosecond_time_stamps_are_read_as_nanoseconds_and_said(tmp_path, capsys, caplog):
    """A EuRoC-style data.csv ("#timestamp [ns],filename", 1403636579763555584,000000.png) given as --timestamps was
    read as seconds: poses_tum.txt was stamped 1403636579763555584.000000."""
    folder = tmp_path / "imgs"
    shutil.copytree(sample_path("kitti_vo", "06", "image_0"), folder)
    stamps = tmp_path / "data.csv"
    stamps.write_text("#timestamp [ns],filename\n" + "".join(f"{1403636579763555584 + k * 100_000_000},{k:06d}.png\n"
                                                             for k in range(8)))
    out = tmp_path / "run"
    caplog.clear()
    code, _, err = _run(["vo", str(folder), "--calib", str(sample_path("kitti_vo", "06", "calib.txt")), "--scale", "none",
                         "--timestamps", str(stamps), "--out", str(out)], capsys)
    assert code in (0, None), err
    np.testing.assert_allclose(Trajectory.from_tum(out / "poses_tum.txt").timestamps_s,
                               1403636579.763555584 + 0.1 * np.arange(8), rtol=0, atol=2e-6)
    said = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
    assert f"{stamps}: time stamps above 1e+15 read as nanoseconds (the first is 1403636579.763556 s)" in said


def test_millisecond_time_stamps_of_an_image_folder_are_refused_naming_the_unit(tmp_path):
    """Stamps in milliseconds (1403636579763.555) were read as seconds, and the run's poses_tum.txt was refused by
    lidarkit eval; the reader refuses them as a KITTI sequence's times.txt, naming the file, line and unit."""
    from lidarkit.io.images import ImageFolder

    stamps = tmp_path / "ms.txt"
    stamps.write_text("# ms\n" + "".join(f"{1403636579763.555 + 100 * k:.3f}\n" for k in range(8)))
    with pytest.raises(DataError, match=r"ms\.txt \(line 2, frame 0\): time stamp 1403636579763\.555 is beyond 1e\+11 s "
                                        r"\(after the year 5000\): milliseconds\? \(stamps above 1e\+15 are read as nanoseconds\): "
                                        r"write seconds, e\.g\. divide by 1e3$"):
        ImageFolder(sample_path("kitti_vo", "06", "image_0"), timestamps=stamps)


def test_images_read_in_memory_keep_an_unreadable_frames_reason(tmp_path):
    """A bench vo job reads its images first (images_in_memory): an unreadable file became None and its frame was
    rejected as "unreadable image (missing)" though the file was there; now the reader's reason is kept."""
    from lidarkit.vo import images_in_memory, preset, run_vo

    seq = tmp_path / "06"
    shutil.copytree(sample_path("kitti_vo", "06"), seq)
    (seq / "image_0" / "000003.png").write_bytes(b"\x89PNG\r\n\x1a\n truncated")
    sequence = open_vo_input(str(seq)).images
    images = images_in_memory(sequence)
    assert isinstance(images[3], DataError) and all(isinstance(image, np.ndarray) for k, image in enumerate(images) if k != 3)
    result = run_vo(images, sequence.K, preset("lidarkit", **{"scale.mode": "gt"}), ground_truth=sequence.ground_truth)
    reason = result.diagnostics[3].reason
    assert not result.diagnostics[3].accepted and reason.startswith("unreadable image: ") and "000003.png" in reason, reason
