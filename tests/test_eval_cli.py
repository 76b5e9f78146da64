"""``lidarkit eval`` and ``lidarkit demo``: evo's stored numbers through the CLI, files written, bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import shared_path
from test_eval_metrics import STATS, load_evo_result

from lidarkit import samples
from lidarkit.cli import main
from lidarkit.errors import DataError
from lidarkit.eval import evaluate, report
from lidarkit.eval.demo import run_eval_demo
from lidarkit.trajectory import Trajectory

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def run_cli(argv: list[str], capsys) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as exc:
        main(argv)
    out, err = capsys.readouterr()
    return int(exc.value.code or 0), out, err


@pytest.mark.parametrize("est_name,prefix", [("ORB", "orb"), ("SPTAM", "sptam")])
def test_cli_reproduces_evo_stored_ape_and_rpe(tmp_path, capsys, est_name, prefix):
    gt = shared_path("evo_testdata", "KITTI_00_gt.txt")
    est = shared_path("evo_testdata", f"KITTI_00_{est_name}.txt")
    out_json = tmp_path / "metrics.json"
    code, out, _ = run_cli(
        ["eval", str(gt), str(est), "--format", "kitti", "--align", "se3", "--delta", "10", "--delta-unit", "meters",
         "--legacy-pairs", "--json", str(out_json)],
        capsys,
    )
    assert code == 0
    data = json.loads(out_json.read_text())
    _, ape_stats, _ = load_evo_result(f"{prefix}_ape")
    _, rpe_stats, rpe_errors = load_evo_result(f"{prefix}_rpe")
    for stat in STATS:
        assert data["ape"]["stats"][stat] == pytest.approx(ape_stats[stat], rel=1e-4), stat
        # the stored RPE was not aligned; a rigid alignment leaves relative motions unchanged
        assert data["rpe"]["stats"][stat] == pytest.approx(rpe_stats[stat], rel=1e-4), stat
    assert data["rpe"]["n_errors"] == len(rpe_errors)
    assert data["kitti_drift"]["n_segments"] == 3283
    assert f"{ape_stats['rmse']:.5g}" in out  # printed table shows the rmse (5 significant digits)
    assert "KITTI drift" in out


def test_cli_tum_associate_plot_markdown_and_format_override(tmp_path, capsys):
    ref = shared_path("evo_testdata", "freiburg1_xyz-groundtruth.txt")
    est = shared_path("evo_testdata", "freiburg1_xyz-rgbdslam.txt")
    code, _, err = run_cli(["eval", str(ref), str(est), "--format", "tum"], capsys)
    assert code == 1 and "differ in length (3000 reference vs 788" in err and "associate" in err
    assert err.count("\n") == 1  # one line, no traceback

    # an estimate written in KITTI format (frames of the associated reference) via --est-format
    ref_traj = Trajectory.from_tum(ref)
    est_kitti = tmp_path / "est_kitti.txt"
    Trajectory.from_tum(est).to_kitti(est_kitti)
    code, _, err = run_cli(["eval", str(ref), str(est_kitti), "--format", "tum", "--est-format", "kitti"], capsys)
    assert code == 1 and "differ in length" in err

    plot, md, js = tmp_path / "p.png", tmp_path / "r.md", tmp_path / "r.json"
    code, out, _ = run_cli(
        ["eval", str(ref), str(est), "--format", "tum", "--associate", "--max-diff", "0.01", "--align", "sim3",
         "--plot", str(plot), "--markdown", str(md), "--json", str(js)],
        capsys,
    )
    assert code == 0
    assert "KITTI drift not computed" in out  # fr1/xyz moves a few metres only
    assert plot.read_bytes()[:8] == PNG_MAGIC and plot.stat().st_size < 300_000
    assert "| rmse |" in md.read_text()
    data = json.loads(js.read_text())
    assert data["kitti_drift"] is None and data["ape"]["align"] == "sim3" and data["ape"]["associated"]
    assert data["n_poses"] <= 788 and len(ref_traj) == 3000
    assert not list(tmp_path.glob(".*"))  # no temporary files left behind


def test_cli_bad_files_are_one_line_errors(tmp_path, capsys, copy_of):
    gt = shared_path("evo_testdata", "KITTI_00_gt.txt")
    code, _, err = run_cli(["eval", str(gt), str(tmp_path / "missing.txt")], capsys)
    assert code == 1 and "missing.txt: file not found" in err and "Traceback" not in err

    broken = copy_of(shared_path("evo_testdata", "KITTI_00_ORB.txt"))
    lines = broken.read_text().splitlines()
    lines[6] = " ".join(lines[6].split()[:11])
    broken.write_text("\n".join(lines) + "\n")
    code, _, err = run_cli(["eval", str(gt), str(broken)], capsys)
    assert code == 1 and "KITTI_00_ORB.txt (line 7): expected 12 numbers, found 11" in err

    code, _, err = run_cli(["eval", str(gt), str(gt), "--format", "g2o"], capsys)
    assert code == 1 and "unknown trajectory format 'g2o'" in err
    code, _, err = run_cli(["eval", str(gt), str(gt), "--delta-unit", "parsecs"], capsys)
    assert code == 1 and "unknown delta unit 'parsecs'" in err
    # misused options: one line and exit code 1 as every other error (not a usage box and exit code 2)
    tum = shared_path("evo_testdata", "freiburg1_xyz-groundtruth.txt")
    code, _, err = run_cli(["eval", str(tum), str(tum), "--format", "tum", "--ref-times", str(gt)], capsys)
    assert code == 1 and err.strip() == ("error: --ref-times: times files apply to KITTI-format trajectories only (this one "
                                         "is read as tum)")
    code, _, err = run_cli(["eval", str(gt)], capsys)
    assert code == 1 and "missing EST" in err and len(err.strip().splitlines()) == 1


def test_sample_accessor(tmp_path):
    gz = samples.sample_path("evo_kitti00", "KITTI_00_gt.txt.gz")
    assert gz.is_file() and samples.path("evo_kitti00/KITTI_00_gt.txt.gz") == gz
    assert "evo_kitti00" in samples.available_samples()
    plain = samples.extract_sample("evo_kitti00", "KITTI_00_gt.txt", dest_dir=tmp_path)
    assert plain.read_bytes() == shared_path("evo_testdata", "KITTI_00_gt.txt").read_bytes()
    with pytest.raises(DataError, match="nothing/here.txt: bundled sample not found"):
        samples.sample_path("nothing", "here.txt")
    with pytest.raises(DataError, match="relative"):
        samples.sample_path("../errors.py")
    sizes = sum(p.stat().st_size for p in samples.sample_path("evo_kitti00").iterdir())
    assert sizes < 1_200_000


def test_eval_demo_library_and_tables(tmp_path):
    result = run_eval_demo(tmp_path / "demo")
    (ev,) = result.evaluations
    assert ev.n_poses == 4541 and ev.ape.rmse == pytest.approx(1.3034497, rel=1e-6)
    assert ev.drift is not None and ev.drift.translation_pct == pytest.approx(0.69973, abs=5e-5)
    assert set(result.files) == {"metrics", "report", "plot"}
    assert json.loads(result.files["metrics"].read_text())["evaluations"][0]["ape"]["stats"]["rmse"] == ev.ape.rmse
    assert result.files["plot"].read_bytes()[:8] == PNG_MAGIC

    # the tables ``lidarkit demo`` prints for it (the full demo command runs the benchmark suite too)
    from rich.console import Console

    console = Console(record=True, width=100)
    console.print(report.evaluation_table(ev))
    console.print(report.drift_table(ev))
    text = console.export_text()
    assert "1.3034" in text and "APE transl." in text and "KITTI drift" in text and "0.69973" in text


def test_summary_table_of_several_evaluations(rng):
    n = 50
    motions = np.tile(np.eye(4), (n - 1, 1, 1))
    motions[:, 0, 3] = 1.0
    ref = Trajectory.from_relative_motions(motions, name="ref")
    noisy = ref.positions_xyz + rng.normal(0, 0.1, (n, 3))
    poses = ref.poses_se3.copy()
    poses[:, :3, 3] = noisy
    est = Trajectory(poses, name="noisy")
    evs = [evaluate(ref, est, align="none"), evaluate(ref, ref.with_name("perfect"), align="none")]
    header, rows = report.summary_rows(evs)
    assert rows[1][0] == "perfect" and rows[1][3] == "0" and rows[0][-1] == "–"
    md = report.markdown_table(header, rows)
    assert md.count("\n") == 4 and md.startswith("| estimate |")


def test_relations_settings_without_relations_and_a_tum_file_read_as_kitti_say_so(capsys):
    from conftest import cli_exit_code

    gt, orb, tum = (str(shared_path("evo_testdata", f)) for f in ("KITTI_00_gt.txt", "KITTI_00_ORB.txt", "fr2_desk_ORB.txt"))
    assert cli_exit_code(["eval", gt, orb, "--relation-max-diff", "0.5"]) == 1  # accepted and ignored before
    assert "--relation-max-diff applies to --relations only" in capsys.readouterr().err
    aces = str(shared_path("carmen_2d", "aces.relations"))
    assert cli_exit_code(["eval", "--relations", aces, tum, "--relation-max-diff", "-1"]) == 1  # (named max_time_diff_s)
    assert capsys.readouterr().err.strip() == "error: --relation-max-diff: must be a finite number of seconds >= 0, got -1"
    assert cli_exit_code(["eval", tum, tum]) == 1
    assert "expected 12 numbers, found 8 (a TUM trajectory? read it as tum" in capsys.readouterr().err
    # of a KITTI / TUM pair, the option that reads the one file as its format (--format tum then failed on the other,
    # whose hint said --format kitti: round in a loop)
    assert cli_exit_code(["eval", gt, tum]) == 1
    assert capsys.readouterr().err.strip() == (f"error: {tum} (line 1): expected 12 numbers, found 8 (a TUM trajectory? "
                                                "read it as tum: --est-format tum, Trajectory.from_tum)")
    assert cli_exit_code(["eval", tum, gt, "--format", "tum"]) == 1
    assert capsys.readouterr().err.strip() == (f"error: {gt} (line 1): expected 8 numbers, found 12 (a KITTI trajectory? "
                                                "read it as kitti: --est-format kitti, Trajectory.from_kitti)")


def test_associating_kitti_files_without_times_points_to_them(capsys):
    from conftest import cli_exit_code

    gt, orb = (str(shared_path("evo_testdata", f)) for f in ("KITTI_00_gt.txt", "KITTI_00_ORB.txt"))
    assert cli_exit_code(["eval", gt, orb, "--associate"]) == 1
    assert "has no timestamps (a KITTI pose file has none: give its times.txt, --ref-times / --est-times" in capsys.readouterr().err


def test_tum_files_paired_by_index_whose_stamps_disagree_are_said_to_be(tmp_path, capsys, caplog):
    """Two TUM files of equal length, the estimate starting 1 s later: scored pose by pose without a word (APE 0.27 m,
    where evo associates TUM files by time and gives ~0); --max-diff without --associate was recorded and ignored."""
    from conftest import cli_exit_code

    lines = [ln for ln in shared_path("evo_testdata", "freiburg1_xyz-groundtruth.txt").read_text().splitlines() if not ln.startswith("#")]
    (tmp_path / "a.txt").write_text("\n".join(lines[:300]) + "\n")
    (tmp_path / "b.txt").write_text("\n".join(lines[100:400]) + "\n")
    a, b = str(tmp_path / "a.txt"), str(tmp_path / "b.txt")
    with caplog.at_level("WARNING"):
        assert cli_exit_code(["eval", "-f", "tum", a, b, "--align", "none"]) == 0
    assert "poses paired by index, but their stamps differ by up to 1.0" in caplog.text and "--associate" in caplog.text
    caplog.clear()
    with caplog.at_level("WARNING"):
        assert cli_exit_code(["eval", "-f", "tum", a, a, "--align", "none"]) == 0  # the same stamps: nothing to say
    assert "paired by index" not in caplog.text
    assert cli_exit_code(["eval", "-f", "tum", a, b, "--max-diff", "3"]) == 1
    assert "error: --max-diff: --max-diff is the time window of --associate" in capsys.readouterr().err
    # bad values name the option (it was "b vs a: max_diff_s must be > 0", an EvaluationError of the file pair)
    assert cli_exit_code(["eval", "-f", "tum", a, b, "--associate", "--max-diff", "0"]) == 1
    assert capsys.readouterr().err.strip() == "error: --max-diff: must be a finite number of seconds > 0, got 0"
    assert cli_exit_code(["eval", "-f", "tum", a, b, "--delta", "0"]) == 1
    assert capsys.readouterr().err.strip() == "error: --delta: must be a finite number > 0, got 0"
    from lidarkit.errors import ConfigError
    from lidarkit.eval.pairing import paired

    with pytest.raises(ConfigError, match=r"max_diff_s: max_diff_s must be a finite number of seconds > 0, got 0"):
        paired(Trajectory.from_tum(a), Trajectory.from_tum(b), associate=True, max_diff_s=0)


def test_outputs_never_replace_inputs_and_settings_are_named_by_their_options(tmp_path, capsys):
    """`--markdown EST` overwrote the estimate and `--json X --markdown X` the JSON (exit 0); --delta 1.5 read
    "delta: ..." and --est-format TUM "format: ...", the library's names."""
    gt = shared_path("evo_testdata", "KITTI_00_gt.txt")
    est = tmp_path / "est.txt"
    est.write_bytes(shared_path("evo_testdata", "KITTI_00_ORB.txt").read_bytes())
    before = est.read_bytes()
    for args, line in ((["--markdown", str(est)], f"--markdown: {est} is also EST (an input)"),
                       (["--json", str(tmp_path / "x"), "--markdown", str(tmp_path / "x")], f"--markdown: {tmp_path / 'x'} is also --json"),
                       (["--tables", str(gt)], f"--tables: {gt} is also REF (an input)"),
                       (["--delta", "1.5"], "--delta: delta in frames must be an integer, got 1.5"),
                       (["--delta-unit", "km"], "--delta-unit: unknown delta unit 'km'"),
                       (["--est-format", "TUM"], "--est-format: unknown trajectory format 'TUM'")):
        with pytest.raises(SystemExit) as exc:
            main(["eval", str(gt), str(est), *args])
        err = " ".join(capsys.readouterr().err.split())
        assert exc.value.code == 1 and f"error: {line}" in err, (args, err)
    assert est.read_bytes() == before and not (tmp_path / "x").exists()


def test_outputs_and_inputs_named_like_a_tables_file_are_refused(tmp_path, capsys):
    """`--tables T --markdown T/ape_rmse.md` (or --json T/kitti_translation_pct.md, --plot T/segments_translation_pct.png)
    was reported written, then replaced (or removed) by the tables; an estimate T/rpe_rmse.csv was replaced too."""
    gt = shared_path("evo_testdata", "KITTI_00_gt.txt")
    folder = tmp_path / "T"
    folder.mkdir()
    est = folder / "rpe_rmse.csv"
    est.write_bytes(shared_path("evo_testdata", "KITTI_00_ORB.txt").read_bytes())
    for args, option, name in ((["--markdown", str(folder / "ape_rmse.md")], "--markdown", "ape_rmse.md"),
                               (["--json", str(folder / "kitti_translation_pct.md")], "--json", "kitti_translation_pct.md"),
                               (["--plot", str(folder / "segments_translation_pct.png")], "--plot", "segments_translation_pct.png")):
        with pytest.raises(SystemExit) as exc:
            main(["eval", str(gt), str(gt), "--tables", str(folder), *args])
        err = " ".join(capsys.readouterr().err.split())
        assert exc.value.code == 1 and err == (f"error: {option}: {folder / name} is one of the files --tables writes or "
                                               f"removes in {folder}: an output never replaces it"), err
    with pytest.raises(SystemExit) as exc:
        main(["eval", str(gt), str(est), "--tables", str(folder)])
    err = " ".join(capsys.readouterr().err.split())
    assert exc.value.code == 1 and err.startswith(f"error: EST: {est} is one of the files --tables writes or removes"), err
    assert [p.name for p in folder.iterdir()] == ["rpe_rmse.csv"]


def test_an_angle_delta_beyond_half_a_turn_is_refused_before_any_work(tmp_path, capsys):
    """`--delta 200 --delta-unit deg` computed the KITTI drift, then failed as "orb50 vs gt50: RPE failed: delta angle
    must be within [0.0, 180.0]" (evo's words); it is now refused with the settings, before the files are read."""
    from lidarkit.errors import ConfigError
    from lidarkit.eval import EvaluationSettings

    gt = shared_path("evo_testdata", "KITTI_00_gt.txt")
    for delta, unit, line in (("200", "deg", "delta in degrees must be at most 180 (a rotation angle), got 200"),
                              ("3.2", "rad", "delta in radians must be at most 3.14159 (a rotation angle), got 3.2")):
        with pytest.raises(SystemExit) as exc:
            main(["eval", str(gt), str(tmp_path / "not_read.txt"), "--delta", delta, "--delta-unit", unit])
        assert exc.value.code == 1 and capsys.readouterr().err.strip() == f"error: --delta: {line}"
    with pytest.raises(ConfigError, match=r"^delta: delta in degrees must be at most 180 \(a rotation angle\), got 181$"):
        EvaluationSettings(delta=181, delta_unit="degrees")
    assert EvaluationSettings(delta=180, delta_unit="deg").delta == 180  # evo's own bound is inclusive


def test_legacy_pairs_where_they_cannot_apply_are_refused_before_any_work(tmp_path, capsys):
    """`--legacy-pairs` with a delta in frames, or beside `--all-pairs`, was accepted with the settings and refused by
    the RPE only after the files were read, paired and the KITTI drift computed; the settings refuse it now."""
    from lidarkit.errors import ConfigError
    from lidarkit.eval import EvaluationSettings

    gt = shared_path("evo_testdata", "KITTI_00_gt.txt")
    for flags, line in (([], "legacy_pairs applies to consecutive pairs with a path or angle delta, not to a delta in frames"),
                        (["--delta", "10", "--delta-unit", "m", "--all-pairs"],
                         "legacy_pairs applies to consecutive pairs with a path or angle delta, not to all pairs")):
        with pytest.raises(SystemExit) as exc:  # (the estimate does not exist: the settings are refused before reading)
            main(["eval", str(gt), str(tmp_path / "not_read.txt"), "--legacy-pairs", *flags])
        assert exc.value.code == 1 and capsys.readouterr().err.strip() == f"error: --legacy-pairs: {line}"
    for settings in (dict(legacy_pairs=True), dict(legacy_pairs=True, delta=5, delta_unit="frames"),
                     dict(legacy_pairs=True, delta=10, delta_unit="deg", all_pairs=True)):
        with pytest.raises(ConfigError, match="^legacy_pairs: legacy_pairs applies to consecutive pairs"):
            EvaluationSettings(**settings)
    assert EvaluationSettings(legacy_pairs=True, delta=10, delta_unit="m").legacy_pairs  # what they are for


def test_associated_poses_are_reported_against_the_whole_reference(tmp_path, capsys):
    """With --associate the reference length was the line through the 118 matched keyframes of fr2/desk, "118 poses,
    15.6 m", where the reference travels 20.3 m (18.5 m of it between the first and last keyframe matched)."""
    gt = shared_path("evo_testdata", "fr2_desk_groundtruth.txt")
    est = shared_path("evo_testdata", "fr2_desk_ORB_kf_mono.txt")
    code, out, _ = run_cli(["eval", str(gt), str(est), "-f", "tum", "--associate", "--align", "sim3",
                            "--markdown", str(tmp_path / "m.md"), "--json", str(tmp_path / "m.json")], capsys)
    assert code == 0
    whole = Trajectory.from_tum(gt)
    data = json.loads((tmp_path / "m.json").read_text())
    assert data["n_poses"] == 118 and data["ref_length_m"] == pytest.approx(whole.length_m, rel=1e-12)  # 20.34 m
    first, last = np.searchsorted(whole.timestamps_s, [1311868171.1301, 1311868262.1509])  # the keyframes matched
    assert data["scored_path_m"] == pytest.approx(whole.distances_m[last] - whole.distances_m[first], rel=1e-12)  # 18.53 m
    text = (tmp_path / "m.md").read_text()
    assert "118 associated poses over 18.5 m of a 20.3 m reference; align=sim3" in text
    assert "KITTI drift not computed: the associated poses span 18.5 m of the 20.3 m reference path, not longer than 100 m." in text
    assert "15.6" not in text + out


def test_association_without_overlap_in_time_states_both_spans(tmp_path, capsys):
    """A TUM estimate stamped from 0 s failed in evo's words: "found no matching timestamps between first trajectory
    and second trajectory with max. time diff 0.01 (s) and time offset 0.0 (s)", naming neither file nor time."""
    gt = shared_path("evo_testdata", "freiburg1_xyz-groundtruth.txt")
    est = Trajectory.from_tum(shared_path("evo_testdata", "freiburg1_xyz-rgbdslam.txt"))
    from_zero = tmp_path / "est_from0.txt"
    est.with_timestamps(est.timestamps_s - est.timestamps_s[0]).to_tum(from_zero)
    with pytest.raises(SystemExit) as exc:
        main(["eval", "-f", "tum", str(gt), str(from_zero), "--associate"])
    assert exc.value.code == 1 and capsys.readouterr().err.strip() == (
        "error: est_from0 vs freiburg1_xyz-groundtruth: timestamp association failed: no pose has a partner within 0.01 s "
        "(reference spans 1305031098.666..1305031128.756 s, estimate spans 0.000..26.563 s): are both stamped by the same clock?")


def test_tables_given_a_file_say_a_folder_is_needed_not_a_run_folder(tmp_path, capsys):
    """`--tables FILE` said "cannot write the run folder" though eval writes no run: the tables' folder is meant."""
    gt = shared_path("evo_testdata", "KITTI_00_gt.txt")
    in_the_way = tmp_path / "tables"
    in_the_way.write_text("notes\n")
    with pytest.raises(SystemExit) as exc:
        main(["eval", str(gt), str(shared_path("evo_testdata", "KITTI_00_ORB.txt")), "--tables", str(in_the_way)])
    err = " ".join(capsys.readouterr().err.split())
    assert exc.value.code == 1 and f"error: {in_the_way}: cannot write the folder: a file is in the way" in err, err
    assert in_the_way.read_text() == "notes\n"


def test_library_settings_that_cannot_apply_are_refused():
    """rpe(pairs=...) with point_distance scored evo's own 199 pairs and reported the 3 given; evaluate() with no drift
    lengths or a single number was a traceback; "no" / "false" switches were taken as true."""
    from lidarkit.errors import ConfigError
    from lidarkit.eval import rpe

    ref = Trajectory.from_kitti(shared_path("evo_testdata", "KITTI_00_gt.txt"))[:200]
    est = Trajectory.from_kitti(shared_path("evo_testdata", "KITTI_00_ORB.txt"))[:200]
    with pytest.raises(ConfigError, match="pairs: pairs= is not supported for the point_distance relation"):
        rpe(ref, est, relation="point_distance", pairs=[(0, 5), (3, 9), (10, 50)])
    assert rpe(ref, est, pairs=[(0, 5), (3, 9), (10, 50)]).n_errors == 3
    for lengths in ((), 100.0, (100.0, -5.0), ("a",)):
        with pytest.raises(ConfigError, match="drift_lengths_m: drift segment lengths must be a non-empty list of positive numbers"):
            evaluate(ref, est, drift_lengths_m=lengths)
    for setting in ("all_pairs", "associate", "drift"):
        with pytest.raises(ConfigError, match=f"{setting}: {setting} must be True or False, got 'no'"):
            evaluate(ref, est, **{setting: "no"})
    with pytest.raises(ConfigError, match="all_pairs: all_pairs must be True or False"):
        rpe(ref, est, 5, all_pairs="no")
    assert rpe(ref, est, 5, all_pairs=False).n_errors == 39


def test_evaluation_settings_check_max_diff_and_a_delta_given_as_a_switch():
    """EvaluationSettings left max_diff_s unchecked: without associate, "x" and None were numpy/Python TypeErrors in
    the stamp check, -1 warned "stamps differ by up to 0 s (more than -1 s)" and NaN never warned; delta=True was a
    delta of 1."""
    from lidarkit.errors import ConfigError
    from lidarkit.eval import EvaluationSettings

    for value in ("x", None, -1.0, 0.0, float("nan"), float("inf"), True):
        with pytest.raises(ConfigError) as caught:
            EvaluationSettings(max_diff_s=value)
        assert str(caught.value) == f"max_diff_s: max_diff_s must be a finite number of seconds > 0, got {value!r}"
    assert EvaluationSettings(max_diff_s=np.float64(0.02)).max_diff_s == 0.02
    with pytest.raises(ConfigError, match=r"^delta: delta must be a number, got True$"):
        EvaluationSettings(delta=True)


def test_a_delta_given_as_text_is_refused_by_the_settings_and_by_rpe():
    """EvaluationSettings(delta="10") was kept as text ("delta": "10" in the JSON) and the Markdown report failed on
    it ("Unknown format code 'g'"); rpe(delta="10") scored as if 10 had been given."""
    from lidarkit.errors import ConfigError
    from lidarkit.eval import EvaluationSettings, rpe

    ref = Trajectory(np.tile(np.eye(4), (30, 1, 1)))
    for value in ("10", b"10", [10], None):
        with pytest.raises(ConfigError) as caught:
            EvaluationSettings(delta=value)
        assert str(caught.value) == f"delta: delta must be a number, got {value!r}"
        with pytest.raises(ConfigError) as caught:
            rpe(ref, ref, delta=value)
        assert str(caught.value) == f"delta: delta must be a number, got {value!r}"
    assert EvaluationSettings(delta=np.int64(10)).to_dict()["delta"] == 10  # numbers of any kind stay numbers


def test_outputs_of_one_evaluation_are_replaced_together_or_not_at_all(tmp_path):
    """A full disk at the figure (a file-size limit here) left the new JSON, Markdown and tables beside the earlier
    evaluation's figure, exit 1 after "wrote r.json": every output is written aside and moved in together."""
    import resource
    import subprocess
    import sys

    gt = shared_path("evo_testdata", "KITTI_00_gt.txt")
    outputs = ["--json", tmp_path / "r.json", "--markdown", tmp_path / "r.md", "--plot", tmp_path / "r.png",
               "--tables", tmp_path / "t"]

    def evaluate(est, limit=None):
        limits = (lambda: resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))) if limit else None
        return subprocess.run([sys.executable, "-m", "lidarkit", "eval", str(gt), str(shared_path("evo_testdata", est)),
                               *map(str, outputs)], capture_output=True, text=True, timeout=600, preexec_fn=limits)

    assert evaluate("KITTI_00_ORB.txt").returncode == 0
    before = {p.relative_to(tmp_path): p.read_bytes() for p in sorted(tmp_path.rglob("*")) if p.is_file()}
    assert (tmp_path / "r.png").stat().st_size > 120_000 > (tmp_path / "r.json").stat().st_size
    failed = evaluate("KITTI_00_SPTAM.txt", limit=120_000)  # the figure cannot be written, the rest can
    assert failed.returncode == 1 and f"error: {tmp_path / 'r.png'}: cannot write: file too large" in " ".join(failed.stderr.split())
    after = {p.relative_to(tmp_path): p.read_bytes() for p in sorted(tmp_path.rglob("*")) if p.is_file()}
    assert after == before  # the ORB evaluation whole: no SPTAM JSON, tables or Markdown beside its figure, no leftovers


def test_a_plot_path_without_a_suffix_is_written_as_png(tmp_path, capsys):
    """`--plot fig` (the docs: no suffix is PNG) failed after the work with "unknown plot format '.nrp562oi'" (the
    temporary name's random part read as a suffix), and the JSON and Markdown written with it were lost."""
    from lidarkit import atomic

    gt, orb = shared_path("evo_testdata", "KITTI_00_gt.txt"), shared_path("evo_testdata", "KITTI_00_ORB.txt")
    code, _, err = run_cli(["eval", str(gt), str(orb), "--plot", str(tmp_path / "fig"), "--markdown", str(tmp_path / "r.md"),
                            "--no-drift"], capsys)
    assert code == 0, err
    assert (tmp_path / "fig").read_bytes().startswith(b"\x89PNG\r\n\x1a\n") and (tmp_path / "r.md").is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fig", "r.md"]  # (no temporary left)
    for name in ("notes", ".hidden"):  # the temporary name has no suffix either
        with atomic.atomic_path(tmp_path / name) as tmp:
            assert tmp.suffix == "" and tmp.name.startswith(f".{name.lstrip('.')}-")


def test_an_output_onto_the_trajectory_scored_by_relations_names_it_est(tmp_path, capsys):
    """`eval --relations R EST --json EST` said "is also REF (an input)": with --relations the one trajectory given
    is EST, as the help says."""
    est = tmp_path / "poses_tum.txt"
    est.write_bytes(shared_path("evo_testdata", "freiburg1_xyz-groundtruth.txt").read_bytes())
    code, out, err = run_cli(["eval", "--relations", str(shared_path("carmen_2d", "aces.relations")), str(est),
                              "--json", str(est)], capsys)
    assert (code, out) == (1, "")
    assert " ".join(err.split()) == f"error: --json: {est} is also EST (an input): an output never replaces it"


def test_association_that_pairs_a_small_part_of_the_trajectories_is_said_to(tmp_path, capsys, caplog):
    """--associate scoring the first 454 of 4541 reference poses (or 96 pairs of frame numbers read as seconds) said
    nothing: only the table's title showed the count (logged at INFO). A reference denser than the estimate (100 Hz
    truth, every third pose estimated) is covered and says nothing."""
    lines = [ln for ln in shared_path("evo_testdata", "freiburg1_xyz-groundtruth.txt").read_text().splitlines() if not ln.startswith("#")]
    ref = shared_path("evo_testdata", "freiburg1_xyz-groundtruth.txt")
    (tmp_path / "first.txt").write_text("\n".join(lines[:300]) + "\n")
    (tmp_path / "third.txt").write_text("\n".join(lines[::3]) + "\n")
    with caplog.at_level("WARNING"):
        code, _, _ = run_cli(["eval", "-f", "tum", str(ref), str(tmp_path / "first.txt"), "--associate", "--json",
                              str(tmp_path / "first.json")], capsys)
    said = ("only 300 pose pairs associated within 0.01 s (over 1305031098.666..1305031101.656 s), of 3000 reference poses "
            "over 1305031098.666..1305031128.756 s and 300 estimated poses over 1305031098.666..1305031101.656 s: the "
            "scores cover those only")
    assert code == 0 and [(r.levelname, r.getMessage()) for r in caplog.records] == [
        ("WARNING", f"first vs freiburg1_xyz-groundtruth: {said}")]
    data = json.loads((tmp_path / "first.json").read_text())
    assert (data["n_poses"], data["n_ref_poses"], data["n_est_poses"], data["warnings"]) == (300, 3000, 300, [said])
    caplog.clear()
    with caplog.at_level("WARNING"):
        code, _, _ = run_cli(["eval", "-f", "tum", str(ref), str(tmp_path / "third.txt"), "--associate", "--json",
                              str(tmp_path / "third.json")], capsys)
    data = json.loads((tmp_path / "third.json").read_text())
    assert code == 0 and caplog.records == []
    assert (data["n_poses"], data["n_ref_poses"], data["n_est_poses"], data["warnings"]) == (1000, 3000, 1000, [])


def test_option_messages_name_the_option_given_and_the_finite_bound(tmp_path, capsys):
    """--delta inf said "must be a number > 0, got inf"; --est-times with a TUM estimate was named
    "--ref-times/--est-times" together."""
    tum = str(shared_path("evo_testdata", "freiburg1_xyz-groundtruth.txt"))
    times = str(shared_path("evo_testdata", "KITTI_00_gt_times.txt"))
    code, _, err = run_cli(["eval", tum, tum, "-f", "tum", "--delta", "inf"], capsys)
    assert code == 1 and err == "error: --delta: must be a finite number > 0, got inf\n"
    code, _, err = run_cli(["eval", tum, tum, "-f", "tum", "--est-times", times], capsys)
    assert code == 1 and err == ("error: --est-times: times files apply to KITTI-format trajectories only (this one is "
                                 "read as tum)\n")


def test_frame_numbers_against_seconds_are_not_told_to_associate(tmp_path, caplog):
    """KITTI_00_ORB written as TUM with stamps 0, 1, 2 (frame numbers) against the ground truth's seconds: the warning
    advised --associate, which then paired 96 poses of 4541 and misaligned them."""
    from conftest import cli_exit_code

    orb = Trajectory.from_kitti(shared_path("evo_testdata", "KITTI_00_ORB.txt"))
    frames = Trajectory(orb.poses_se3, np.arange(len(orb), dtype=np.float64))
    frames.to_tum(tmp_path / "orb_frames_tum.txt")
    gt, times = (str(shared_path("evo_testdata", f)) for f in ("KITTI_00_gt.txt", "KITTI_00_gt_times.txt"))
    with caplog.at_level("WARNING"):
        assert cli_exit_code(["eval", gt, str(tmp_path / "orb_frames_tum.txt"), "--ref-times", times, "--est-format", "tum",
                              "--no-drift"]) == 0
    assert [r.getMessage() for r in caplog.records if r.levelname == "WARNING"] == [
        "orb_frames_tum vs KITTI_00_gt: poses paired by index, but their stamps differ by up to 4069.42 s (pose 4540: "
        "reference 470.581600 s, estimate 4540.000000 s; more than 0.01 s), and the estimate's stamps step by 1 s against "
        "the reference's 0.1036 s (median): the two clocks or units differ (frame numbers against seconds?); pairing by "
        "index, as here, is right when pose i of each is the same frame; --associate would pair the wrong poses"]


def test_an_alignment_of_collinear_positions_names_the_command_line_option(tmp_path, capsys):
    """A straight-line path cannot be aligned; the message said "use align='none'", the library's words, to a command
    line user who needs --align none."""
    poses = np.tile(np.eye(4), (20, 1, 1))
    poses[:, 0, 3] = np.arange(20.0)
    line = Trajectory(poses).to_kitti(tmp_path / "line.txt")
    with pytest.raises(SystemExit) as exc:
        main(["eval", str(line), str(line)])
    err = " ".join(capsys.readouterr().err.split())
    assert exc.value.code == 1 and err.endswith("(positions collinear or constant? use align='none', --align none)")
    with pytest.raises(SystemExit) as exc:
        main(["eval", str(line), str(line), "--align", "none"])
    assert exc.value.code == 0


def test_a_missing_trajectory_is_one_line_with_relations_too(capsys):
    """`lidarkit eval --relations R` with no trajectory printed a usage box "Missing argument 'ref'" (exit 2), though
    with --relations the one file given is EST; `lidarkit eval REF` alone already gave one line."""
    for args, line in ((["--relations", str(shared_path("carmen_2d", "aces.relations"))],
                        "error: EST: missing EST (the trajectory to score): lidarkit eval --relations FILE EST"),
                       ([], "error: REF: missing REF and EST (the trajectory files): lidarkit eval REF EST")):
        with pytest.raises(SystemExit) as exc:
            main(["eval", *args])
        assert exc.value.code == 1 and capsys.readouterr().err.strip() == line


def test_relations_and_trajectory_swapped_name_the_order(tmp_path, capsys):
    """`eval --relations EST RELATIONS` read the relations file as a TUM trajectory: "quaternion norm 0.0173 is not 1"."""
    relations = shared_path("carmen_2d", "aces.relations")
    est = tmp_path / "est.tum"
    Trajectory(np.tile(np.eye(4), (3, 1, 1)), np.array([0.0, 1.0, 2.0])).to_tum(est)
    with pytest.raises(SystemExit) as exc:
        main(["eval", "--relations", str(est), str(relations)])
    assert exc.value.code == 1 and capsys.readouterr().err.strip() == (
        f"error: --relations: {relations} is a relations file: the order is lidarkit eval --relations RELATIONS EST "
        f"(lidarkit eval --relations {relations} {est})")


def test_a_kitti_trajectory_scored_by_relations_is_told_the_times_it_needs(tmp_path, capsys):
    """A run's poses_kitti.txt given to --relations was told "read it as kitti: --format kitti, ...", which failed next
    ("the relations metric needs the estimate's timestamps"): the hint names --est-times and poses_tum.txt."""
    relations = shared_path("carmen_2d", "aces.relations")
    est = tmp_path / "poses_kitti.txt"
    Trajectory(np.tile(np.eye(4), (3, 1, 1)), np.array([0.0, 1.0, 2.0])).to_kitti(est)
    with pytest.raises(SystemExit) as exc:
        main(["eval", "--relations", str(relations), str(est)])
    err = capsys.readouterr().err.strip()
    assert exc.value.code == 1 and err.endswith("(a KITTI trajectory? read it as kitti: --format kitti --est-times TIMES.txt "
                                                "(the relations metric pairs poses by time), or a run folder's poses_tum.txt)")


@pytest.mark.parametrize("position", ["REF", "EST", "--json", "--markdown", "--ref-times", "--tables", "--relations"])
def test_a_loop_of_symbolic_links_is_one_line_naming_it(tmp_path, capsys, monkeypatch, position):
    """`ln -s loop loop` given as an input or an output printed a traceback (RuntimeError: Symlink loop, from
    Path.resolve); it is a DataError (input) or OutputError (output) naming the path, exit 1."""
    gt = str(shared_path("evo_testdata", "KITTI_00_gt.txt"))
    est = str(shared_path("evo_testdata", "KITTI_00_ORB.txt"))
    monkeypatch.chdir(tmp_path)
    (tmp_path / "loop").symlink_to("loop")
    argv = {"REF": ["eval", "loop", est], "EST": ["eval", gt, "loop"], "--relations": ["eval", "--relations", "loop", est]}
    code, out, err = run_cli(argv.get(position, ["eval", gt, est, position, "loop"]), capsys)
    verb = "cannot write" if position in ("--json", "--markdown", "--tables") else "cannot read it"
    assert (code, out) == (1, "")
    assert err == f"error: loop: {verb}: a loop of symbolic links (a link that leads back to itself)\n"


def test_json_to_stdout_is_the_whole_of_stdout(tmp_path, capsys):
    """`lidarkit eval REF EST --json /dev/stdout | jq` could not parse: the results table followed the JSON on
    stdout. With an output on stdout the table and the `wrote` line go to stderr."""
    import subprocess
    import sys

    gt, est = tmp_path / "gt.txt", tmp_path / "est.txt"  # the first 300 poses of KITTI 00 and of ORB-SLAM's estimate
    for name, path in (("KITTI_00_gt.txt", gt), ("KITTI_00_ORB.txt", est)):
        path.write_text("".join(shared_path("evo_testdata", name).read_text().splitlines(keepends=True)[:300]))
    rmse = evaluate(Trajectory.read(gt, "kitti"), Trajectory.read(est, "kitti")).ape.rmse
    for target in ("/dev/stdout", "/dev/fd/1"):
        done = subprocess.run([sys.executable, "-m", "lidarkit", "eval", str(gt), str(est), "--json", target],
                              capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stderr
        assert json.loads(done.stdout)["ape"]["stats"]["rmse"] == pytest.approx(rmse, rel=1e-9)
        assert "APE transl. (m)" in done.stderr and done.stderr.rstrip().endswith(f"wrote {target}")
    code, out, err = run_cli(["eval", str(gt), str(est), "--json", str(tmp_path / "m.json")], capsys)
    assert code == 0 and "APE transl. (m)" in out and "APE" not in err  # a file: the table stays on stdout


def test_a_bad_times_file_is_named_by_line_in_plain_words(tmp_path, capsys):
    """A times.txt line of two numbers read "expected 1 numbers", and a stamp going back "(line 3 (frame 2))"."""
    poses = np.tile(np.eye(4), (3, 1, 1))
    poses[:, 0, 3] = [0.0, 1.0, 2.0]
    kitti = Trajectory(poses).to_kitti(tmp_path / "poses.txt")
    (tmp_path / "two.txt").write_text("0.0\n0.1 0.2\n0.2\n")
    (tmp_path / "back.txt").write_text("# times\n0.0\n0.2\n0.1\n")
    code, _, err = run_cli(["eval", str(kitti), str(kitti), "--ref-times", str(tmp_path / "two.txt"), "--align", "none"], capsys)
    assert code == 1 and err.strip() == f"error: {tmp_path / 'two.txt'} (line 2): expected 1 number, found 2"
    code, _, err = run_cli(["eval", str(kitti), str(kitti), "--ref-times", str(tmp_path / "back.txt"), "--align", "none"], capsys)
    assert code == 1 and err.strip().startswith(f"error: {tmp_path / 'back.txt'} (line 4, frame 2): ")


def test_eval_refuses_nanosecond_stamps_in_one_line(tmp_path, capsys):
    """fr1/xyz's ground truth and estimate with stamps in nanoseconds, --associate: read as seconds, the 0.01 s window was
    0.01 ns (only identical stamps paired; here none) and the error asked whether both had the same clock. The file and
    the unit are named now, in one line."""
    for name in ("freiburg1_xyz-groundtruth.txt", "freiburg1_xyz-rgbdslam.txt"):
        rows = np.loadtxt(shared_path("evo_testdata", name))
        lines = [" ".join([str(round(row[0] * 1e9)), *(f"{v:.6f}" for v in row[1:])]) for row in rows]
        (tmp_path / name).write_text("\n".join(lines) + "\n")
    code, out, err = run_cli(["eval", str(tmp_path / "freiburg1_xyz-groundtruth.txt"), str(tmp_path / "freiburg1_xyz-rgbdslam.txt"),
                              "-f", "tum", "--associate", "--json", str(tmp_path / "out.json")], capsys)
    assert code == 1 and out == "" and err.count("\n") == 1, err
    assert "freiburg1_xyz-groundtruth.txt (line 1, frame 0): time stamp 1305031098" in err
    assert "they look like nanoseconds (or micro/milliseconds): write seconds, e.g. divide by 1e9" in err
    assert not (tmp_path / "out.json").exists()


def test_poses_a_reader_left_out_are_on_file_in_the_json_and_the_markdown(tmp_path, capsys):
    """An estimate with a pose stamped like the one before it (evo's V1_02 has four): the reader left it out with a
    warning on stderr only, and the --json's "warnings" read [] and the Markdown had no note, so a figure that differs
    from evo's had nothing on file. The reader's warning is now among the evaluation's warnings."""
    n = 40
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, :3, 3] = np.column_stack([0.5 * np.arange(n), np.sin(0.3 * np.arange(n)), 0.1 * np.cos(0.2 * np.arange(n))])
    stamps = 0.1 * np.arange(n)
    Trajectory(poses, stamps).to_tum(tmp_path / "ref.tum")
    lines = Trajectory(poses, stamps).to_tum(tmp_path / "est.tum").read_text().splitlines()
    repeat = lines[11].split()
    lines[12] = " ".join([repeat[0], *lines[12].split()[1:]])  # pose 11 (line 13) repeats pose 10's stamp
    (tmp_path / "est.tum").write_text("\n".join(lines) + "\n")
    est = Trajectory.from_tum(tmp_path / "est.tum")
    said = f"{tmp_path / 'est.tum'}: 1 pose(s) repeat the timestamp of the pose before them (line 13): each left out"
    assert len(est) == n - 1 and est.meta["read_warnings"] == [said] and est[:5].meta["read_warnings"] == [said]
    assert evaluate(Trajectory.from_tum(tmp_path / "ref.tum"), est, associate=True).warnings == (said,)
    code, _, _ = run_cli(["eval", str(tmp_path / "ref.tum"), str(tmp_path / "est.tum"), "-f", "tum", "--associate",
                          "--json", str(tmp_path / "out.json"), "--markdown", str(tmp_path / "out.md")], capsys)
    assert code == 0
    assert json.loads((tmp_path / "out.json").read_text())["warnings"] == [said]
    assert f"Warning: {said}." in (tmp_path / "out.md").read_text()
    # a file read clean leaves nothing on file
    assert evaluate(Trajectory.from_tum(tmp_path / "ref.tum"), Trajectory.from_tum(tmp_path / "ref.tum")).warnings == ()


def _wavy_kitti(path, n: int = 100, far: float | None = None):
    """A 3-D wavy path of ``n`` poses 1 m apart along x written as KITTI; ``far``: pose 40's y coordinate."""
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, :3, 3] = np.column_stack([np.arange(n), np.sin(0.2 * np.arange(n)), 0.3 * np.cos(0.1 * np.arange(n))])
    if far is not None:
        poses[40, 1, 3] = far
    return Trajectory(poses).to_kitti(path)


def test_statistics_that_overflow_are_refused_and_large_ones_print_in_e_notation(tmp_path, capsys):
    """An estimate with one coordinate of 1e300: numpy printed RuntimeWarnings over several lines, the table "–", the
    JSON null, exit 0; now one line names the pair and the coordinate. One of 1e30 printed cells "49989998999799…"
    (its 31 digits cut); such values print in e notation, ordinary ones as before."""
    _wavy_kitti(tmp_path / "ref.txt")
    _wavy_kitti(tmp_path / "huge.txt", far=1e300)
    code, out, err = run_cli(["eval", str(tmp_path / "ref.txt"), str(tmp_path / "huge.txt"), "--json", str(tmp_path / "h.json")],
                             capsys)
    assert code == 1 and out == "" and err.count("\n") == 1, err
    assert err.startswith("error: huge vs ref: RPE (translation) statistics are not finite (rmse inf, ")
    assert err.rstrip().endswith("the largest coordinate is 1e+300 m (estimate, pose 40), too large to score in float64")
    assert not (tmp_path / "h.json").exists()
    _wavy_kitti(tmp_path / "big.txt", far=1e30)
    code, out, _ = run_cli(["eval", str(tmp_path / "ref.txt"), str(tmp_path / "big.txt"), "--align", "none"], capsys)
    assert code == 0 and "…" not in out
    assert "│ max    │           1e+30 │" in out  # (was 1000000000000000019884624838656.0, cut to fit)
    assert [report._fmt(v) for v in (0.0123456, 9999.94, 12345.678, 999999.94, 4.99899e29, -3.2e7)] == [
        "0.012346", "9999.9", "12345.7", "999999.9", "4.999e+29", "-3.2e+07"]
