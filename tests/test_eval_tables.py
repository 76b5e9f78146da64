"""Publication tables: the devkit average row (segments pooled = length-weighted) against a hand computation."""

from __future__ import annotations

import numpy as np
import pytest

from lidarkit.errors import EvaluationError
from lidarkit.eval import kitti_drift
from lidarkit.eval.tables import SegmentErrors, drift_table, per_length_table, per_speed_table, value_table
from lidarkit.trajectory import Trajectory


def straight(n_frames: int, scale: float = 1.0, name: str = "") -> Trajectory:
    """Frames 1 m apart along x (``scale`` stretches the estimate: every segment's error is |scale - 1| * L)."""
    poses = np.tile(np.eye(4), (n_frames, 1, 1))
    poses[:, 0, 3] = scale * np.arange(n_frames, dtype=float)
    return Trajectory(poses, timestamps_s=0.1 * np.arange(n_frames), name=name)


def grid():
    # sequence "A": 151 frames (150 m), sequence "B": 400 frames (399 m); kiss 1 % / 3 % too long, other 2 % everywhere
    g = {}
    for seq, n, kiss_scale in (("A", 151, 1.01), ("B", 400, 1.03)):
        ref = straight(n)
        g[(seq, "kiss")] = SegmentErrors.from_drift(kitti_drift(ref, straight(n, kiss_scale)))
        g[(seq, "other")] = SegmentErrors.from_drift(kitti_drift(ref, straight(n, 1.02)))
    return g


def test_average_row_is_the_devkit_pooled_mean_checked_by_hand():
    g = grid()
    # by hand: A has 100 m segments starting at frames 0, 10, ..., 40 (the last frame must exceed start + 100 m
    # and exist): 5 segments. B (399 m): starts 0..290 for 100 m (30), 0..190 for 200 m (20), 0..90 for 300 m (10).
    assert len(g[("A", "kiss")]) == 5 and len(g[("B", "kiss")]) == 60
    # a segment of nominal length L spans L + 1 m (its last frame is the first beyond L), so a scale error s gives
    # s * (L + 1) / L; the devkit divides by the nominal L.
    seg_a = 5 * [1.0 * 101 / 100]
    seg_b = 30 * [3.0 * 101 / 100] + 20 * [3.0 * 201 / 200] + 10 * [3.0 * 301 / 300]
    seq_means = [np.mean(seg_a), np.mean(seg_b)]
    expected_avg = (sum(seg_a) + sum(seg_b)) / 65  # pooled: 2.867 %, not the mean of sequences (2.016 %)
    other_b = (30 * 101 / 100 + 20 * 201 / 200 + 10 * 301 / 300) * 2.0 / 60
    table = drift_table(g)
    assert table.row_labels == ["A", "B", "Avg."] and table.col_labels == ["kiss", "other"]
    np.testing.assert_allclose(table.values[:, 0], [*seq_means, expected_avg], atol=1e-9)
    np.testing.assert_allclose(table.values[:, 1], [2.02, other_b, (5 * 2.02 + 60 * other_b) / 65], atol=1e-9)
    assert abs(expected_avg - np.mean(seq_means)) > 0.8
    md = table.to_markdown()
    assert "| **Avg.** | 2.87 | **2.01** |" in md and "| A | **1.01** | 2.02 |" in md
    tex = table.to_latex()
    assert "\\toprule" in tex and "\\bottomrule" in tex and tex.count("\\midrule") == 2
    assert "Avg. & 2.87 & \\textbf{2.01} \\\\" in tex and "A & \\textbf{1.01} & 2.02 \\\\" in tex
    csv_lines = table.to_csv().splitlines()
    assert csv_lines[0] == "sequence,kiss,other" and csv_lines[-1].startswith(f"Avg.,{expected_avg!r}"[:15])
    rot = drift_table(g, "rotation_deg_per_100m")
    np.testing.assert_allclose(rot.values, 0.0, atol=1e-9)


def test_per_length_speed_and_value_tables():
    g = grid()
    lengths = per_length_table(g)
    # 100 m: 5 segments of A at 1 % and 30 of B at 3 %; 200 m and 300 m: B only
    np.testing.assert_allclose(lengths.values[:3, 0], [(5 + 90) / 35 * 1.01, 3.0 * 1.005, 3.0 * 301 / 300], atol=1e-9)
    assert lengths.row_labels == ["100", "200", "300", "all"]  # no sequence reaches 400 m: no empty rows
    speeds = per_speed_table(g)
    # 1 m per 0.1 s frame: the devkit duration (frames + 1) * 0.1 s gives just under 10 m/s
    assert speeds.row_labels == ["5-10 m/s"]
    apes = value_table({("A", "kiss"): 0.5, ("A", "other"): 0.7, ("B", "kiss"): 1.5, ("B", "other"): 1.0},
                       "APE", name="ape")
    np.testing.assert_allclose(apes.values[-1], [1.0, 0.85])
    assert apes.best_mask().tolist() == [[True, False], [False, True], [False, True]]


def test_eval_cli_writes_tables(tmp_path, capsys):
    from lidarkit.cli import main

    ref, est = straight(400), straight(400, 1.03)
    ref.to_kitti(tmp_path / "ref.txt")
    est.to_kitti(tmp_path / "est.txt")
    with pytest.raises(SystemExit) as exc:
        main(["eval", str(tmp_path / "ref.txt"), str(tmp_path / "est.txt"), "--align", "none", "--tables", str(tmp_path / "t")])
    assert exc.value.code in (0, None)
    text = (tmp_path / "t" / "kitti_translation_pct.md").read_text()
    assert "Avg." in text and "3.02" in text
    assert (tmp_path / "t" / "kitti_translation_pct.tex").read_text().count("\\toprule") == 1
    assert (tmp_path / "t" / "segments_translation_pct.png").read_bytes()[:4] == b"\x89PNG"
    # the titles say how the values were computed (every run read "APE ... (m)" and "RPE ... (m per frame)")
    assert (tmp_path / "t" / "ape_rmse.md").read_text().startswith("**APE translation RMSE (m, unaligned)**")
    assert (tmp_path / "t" / "rpe_rmse.md").read_text().startswith("**RPE translation RMSE (m per frame)**")
    # the same folder for a run too short for drift: the earlier drift tables and box plot go, the user's file stays
    (tmp_path / "t" / "notes.txt").write_text("mine")
    straight(40).to_kitti(tmp_path / "ref_short.txt")
    straight(40, 1.03).to_kitti(tmp_path / "est_short.txt")
    with pytest.raises(SystemExit) as exc:
        main(["eval", str(tmp_path / "ref_short.txt"), str(tmp_path / "est_short.txt"), "--align", "none", "--tables", str(tmp_path / "t")])
    assert exc.value.code in (0, None)
    assert sorted(p.name for p in (tmp_path / "t").iterdir()) == [
        "ape_rmse.csv", "ape_rmse.md", "ape_rmse.tex", "notes.txt", "rpe_rmse.csv", "rpe_rmse.md", "rpe_rmse.tex"]


def test_pooled_rows_compare_methods_on_the_sequences_all_of_them_ran():
    """B has no segments on 01: the drift table's Avg. row left 01 out, the per-length "all" row pooled A's 10 % there
    and bolded B as best (A 5.50 vs B 2.00 beside Avg. A 1.00 vs B 2.00). Every pooled row now uses the same
    sequences, and the notes name the one left out."""
    def seg(value):
        return SegmentErrors(np.full(3, 100.0), np.full(3, value), np.full(3, value / 10), np.full(3, 8.0))

    g = {("00", "A"): seg(1.0), ("00", "B"): seg(2.0), ("01", "A"): seg(10.0)}
    avg = drift_table(g).values[-1]
    for table in (per_length_table(g), per_speed_table(g)):
        np.testing.assert_allclose(table.values[-1], avg)
        assert "Left out: 01" in table.note
    assert "Left out: 01" in drift_table(g).note and drift_table(g).values[1, 0] == 10.0  # its own row stays


def test_segment_speeds_follow_the_time_stamps(tmp_path, capsys):
    """1 m per frame at 5 Hz is 5 m/s: the per-speed table took every sequence as 10 Hz (10 m/s)."""
    from lidarkit.cli import main

    ref, est = straight(400), straight(400, 1.03)
    Trajectory(ref.poses_se3, 0.2 * np.arange(400)).to_tum(tmp_path / "ref.tum")
    Trajectory(est.poses_se3, 0.2 * np.arange(400)).to_tum(tmp_path / "est.tum")
    with pytest.raises(SystemExit) as exc:
        main(["eval", str(tmp_path / "ref.tum"), str(tmp_path / "est.tum"), "-f", "tum", "--align", "none", "--tables", str(tmp_path / "t")])
    assert exc.value.code in (0, None)
    text = (tmp_path / "t" / "kitti_translation_pct_per_speed.md").read_text()
    assert "| 0-5 m/s |" in text and "5-10 m/s" not in text  # (100 m from the first stamp to the 101st after: 4.95 m/s)


def test_segment_speeds_of_an_estimate_with_dropped_frames_are_those_of_the_drive():
    """ORB-SLAM2 on KITTI 00 with 40 % of its poses dropped, associated by time: the per-speed table took a segment's
    duration as its associated poses x their median interval, so speeds read 1.65x too high (rows 15-20 and 20-25 m/s
    on a drive never faster than 12.9 m/s over a second). Its duration is now the time between its stamps."""
    from conftest import shared_path

    from lidarkit.eval.pairing import paired
    from lidarkit.eval.tables import scored_timestamps_s

    times = shared_path("evo_testdata", "KITTI_00_gt_times.txt")
    truth = Trajectory.from_kitti(shared_path("evo_testdata", "KITTI_00_gt.txt"), times)
    orb = Trajectory.from_kitti(shared_path("evo_testdata", "KITTI_00_ORB.txt"), times)
    fastest_second_mps = np.convolve(np.diff(truth.distances_m) / np.diff(truth.timestamps_s), np.ones(10) / 10, "valid").max()
    assert 12.8 < fastest_second_mps < 12.9
    keep = np.sort(np.random.default_rng(0).choice(len(orb), int(0.6 * len(orb)), replace=False))
    ref, est = paired(truth, orb[keep], associate=True)
    dropped = SegmentErrors.from_drift(kitti_drift(ref, est, path_along=truth), timestamps_s=scored_timestamps_s(ref, est))
    every = SegmentErrors.from_drift(kitti_drift(truth, orb), timestamps_s=scored_timestamps_s(truth, orb))
    assert 4.7 < dropped.speed_mps.min() and dropped.speed_mps.max() < fastest_second_mps  # (was 8.0 .. 23.5 m/s)
    assert np.median(dropped.speed_mps) == pytest.approx(np.median(every.speed_mps), rel=0.01)  # (was 1.65x)
    assert per_speed_table({("00", "orb"): dropped}).row_labels == ["0-5 m/s", "5-10 m/s", "10-15 m/s"]
    # every frame kept: the table lidarkit eval --tables wrote before (frames x the stamps' median interval)
    assert "| 0-5 m/s | 0.73 |\n| 5-10 m/s | 0.67 |\n| 10-15 m/s | 1.10 |" in per_speed_table({("00", "orb"): every}).to_markdown()
    with pytest.raises(EvaluationError, match=r"^timestamps_s: 100 stamps for segments that reach pose 4540"):
        SegmentErrors.from_drift(kitti_drift(truth, orb), timestamps_s=truth.timestamps_s[:100])


def test_segment_speeds_of_a_reference_without_stamps_follow_the_estimates_stamps(tmp_path):
    """A KITTI ground truth without times and a TUM estimate at 5 Hz, paired by index: the speeds took 0.1 s a frame
    (just under 10 m/s for 1 m a frame) as only the reference's stamps were looked at; they are the estimate's."""
    straight(400).to_kitti(tmp_path / "ref.txt")
    Trajectory(straight(400, 1.03).poses_se3, 0.2 * np.arange(400)).to_tum(tmp_path / "est.tum")
    rows = _per_speed_rows(tmp_path, "ref.txt", "est.tum", "--est-format", "tum")
    assert len(rows) == 2 and rows[1].startswith("0-5 m/s,"), rows  # 100 m in 101 frames of 0.2 s: 4.95 m/s


def test_segment_speeds_of_associated_poses_with_gaps_follow_their_stamps(tmp_path):
    """A 12 m/s drive whose estimate lost 40 % of its frames at random, --associate: the speeds counted the associated
    poses at their median interval (0.1 s), ~1.65x too fast (20-25 m/s); they are the time between the stamps."""
    ref = straight(800, 1.2)  # 1.2 m a 0.1 s frame: 12 m/s
    keep = np.sort(np.random.default_rng(0).choice(800, 480, replace=False))
    ref.to_tum(tmp_path / "ref.txt")
    straight(800, 1.2 * 1.03)[keep].to_tum(tmp_path / "est.txt")
    rows = _per_speed_rows(tmp_path, "ref.txt", "est.txt", "-f", "tum", "--associate")
    assert len(rows) == 2 and rows[1].startswith("10-15 m/s,"), rows


def test_latex_cells_escape_what_would_break_or_misprint():
    from lidarkit.eval.tables import _latex_escape

    assert _latex_escape("a^2 ~b >= 25 m/s_x") == "a\\textasciicircum{}2 \\textasciitilde{}b \\textgreater{}= 25 m/s\\_x"
    tex = per_speed_table(grid()).to_latex()
    assert ">=" not in tex and "^" not in tex.replace("\\textasciicircum", "")


def test_only_cells_that_print_as_the_best_are_bold():
    from lidarkit.eval.tables import PubTable

    table = PubTable(title="t", corner="s", row_labels=["00"], col_labels=["A", "B", "C"], values=np.array([[1.004, 1.006, 1.0041]]),
                     digits=2)
    assert table.best_mask().tolist() == [[True, False, True]]  # 1.00, 1.01, 1.00 (1.01 was bold too)
    assert "| 00 | **1.00** | 1.01 | **1.00** |" in table.to_markdown()


def test_value_tables_show_three_significant_figures_of_their_smallest_value(tmp_path):
    """APE tables printed 3 decimals: fr2/desk ORB-SLAM2's 0.008119 m read 0.008, and two methods at 0.0081 and 0.0084
    both read 0.008, both bold. The decimals now show the smallest value to 3 figures (one count for the table); a
    KITTI-scale table keeps its 3 decimals."""
    from conftest import shared_path

    from lidarkit.cli import main

    tum = {"ORB": 0.008119, "other": 0.008412}
    table = value_table({("fr2/desk", m): v for m, v in tum.items()} | {("fr1/xyz", "ORB"): 0.01347, ("fr1/xyz", "other"): 0.0210},
                        "APE", name="ape")
    markdown = table.to_markdown()
    assert "| fr2/desk | **0.00812** | 0.00841 |" in markdown and "| fr1/xyz | **0.01347** | 0.02100 |" in markdown, markdown
    assert "fr2/desk & \\textbf{0.00812} & 0.00841 \\\\" in table.to_latex()
    kitti = value_table({("00", "orb"): 1.30345, ("00", "sptam"): 3.73849}, "APE", name="ape").to_markdown()
    assert "| 00 | **1.303** | 3.738 |" in kitti
    assert "| 00 | **0.0281** | 0.0470 |" in value_table({("00", "orb"): 0.02814, ("00", "sptam"): 0.04701}, "RPE", name="rpe",
                                                           digits=4).to_markdown()
    # lidarkit eval --tables on TUM fr2/desk (ORB-SLAM2 keyframes associated with the ground truth)
    with pytest.raises(SystemExit) as exc:
        main(["eval", str(shared_path("evo_testdata", "fr2_desk_groundtruth.txt")), str(shared_path("evo_testdata", "fr2_desk_ORB.txt")),
              "-f", "tum", "--associate", "--tables", str(tmp_path / "t")])
    assert exc.value.code in (0, None)
    assert "| fr2_desk_groundtruth | 0.00812 |" in (tmp_path / "t" / "ape_rmse.md").read_text()
    assert "| fr2_desk_groundtruth | 0.00349 |" in (tmp_path / "t" / "rpe_rmse.md").read_text()


def test_sim3_tables_name_the_scale_the_estimate_was_given(tmp_path):
    """A monocular estimate at half scale: the APE and RPE tables of a Sim(3) evaluation say by what factor the
    estimate was scaled (the figures are in metres only after it); an SE(3) evaluation's titles say nothing of it."""
    from lidarkit.cli import main

    from lidarkit.geometry import make_se3, so3_exp

    yaw = np.linspace(0.0, np.pi, 120)  # half a circle of 20 m radius (a line leaves Umeyama's rotation undefined)
    ref = np.array([make_se3(so3_exp(np.array([0.0, 0.0, a])), [20.0 * np.sin(a), 20.0 * (1.0 - np.cos(a)), 0.0]) for a in yaw])
    Trajectory(ref, 0.1 * np.arange(120)).to_tum(tmp_path / "ref.tum")
    half = ref.copy()
    half[:, :3, 3] *= 0.5
    Trajectory(half, 0.1 * np.arange(120)).to_tum(tmp_path / "est.tum")
    for align, folder in (("sim3", "s"), ("se3", "e")):
        with pytest.raises(SystemExit) as exc:
            main(["eval", str(tmp_path / "ref.tum"), str(tmp_path / "est.tum"), "-f", "tum", "--align", align, "--tables", str(tmp_path / folder)])
        assert exc.value.code in (0, None)
    assert "**APE translation RMSE (m, Sim(3)-aligned, estimate scaled by 2)**" in (tmp_path / "s" / "ape_rmse.md").read_text()
    assert "**RPE translation RMSE (m per frame, estimate scaled by 2)**" in (tmp_path / "s" / "rpe_rmse.md").read_text()
    assert "estimate scaled by 2" in (tmp_path / "s" / "ape_rmse.tex").read_text()
    assert "scaled" not in (tmp_path / "e" / "ape_rmse.md").read_text() + (tmp_path / "e" / "rpe_rmse.md").read_text()


def test_speeds_of_the_tables_are_those_of_the_associated_poses(tmp_path):
    """An estimate at every other stamp of a denser reference, --associate: speeds were taken with the raw reference's
    frame period (0.1 s) over the associated poses (0.2 s apart), every speed doubled (24 m/s for a 12 m/s drive)."""
    ref = straight(800, 1.2)  # 1.2 m a 0.1 s frame: 12 m/s
    est = straight(800, 1.2 * 1.03)[np.arange(0, 800, 2)]
    ref.to_tum(tmp_path / "ref.txt")
    est.to_tum(tmp_path / "est.txt")
    rows = _per_speed_rows(tmp_path, "ref.txt", "est.txt", "-f", "tum", "--associate")
    assert len(rows) == 2 and rows[1].startswith("10-15 m/s,"), rows


def test_rpe_table_titles_name_how_the_pairs_were_chosen(tmp_path):
    """All pairs, consecutive and legacy pairs 5 m apart gave three different RMSEs under one title
    "RPE translation RMSE (m per 5 meters)"; the title now names the choice as the printed table does."""
    from lidarkit.cli import main
    from lidarkit.geometry import make_se3, so3_exp

    yaw = np.linspace(0.0, np.pi, 120)  # half a circle of 20 m radius
    ref = np.array([make_se3(so3_exp(np.array([0.0, 0.0, a])), [20.0 * np.sin(a), 20.0 * (1.0 - np.cos(a)), 0.0]) for a in yaw])
    est = ref.copy()
    est[:, :3, 3] += 0.05 * np.random.default_rng(0).standard_normal((120, 3))
    Trajectory(ref, 0.1 * np.arange(120)).to_tum(tmp_path / "ref.tum")
    Trajectory(est, 0.1 * np.arange(120)).to_tum(tmp_path / "est.tum")
    titles, values = {}, {}
    for folder, flags in (("c", []), ("a", ["--all-pairs"]), ("l", ["--legacy-pairs"])):
        with pytest.raises(SystemExit) as exc:
            main(["eval", str(tmp_path / "ref.tum"), str(tmp_path / "est.tum"), "-f", "tum", "--delta", "5",
                  "--delta-unit", "m", *flags, "--tables", str(tmp_path / folder)])
        assert exc.value.code in (0, None)
        lines = (tmp_path / folder / "rpe_rmse.md").read_text().splitlines()
        titles[folder], values[folder] = lines[0], lines[4]  # the title and the sequence's row
    assert len(set(values.values())) == 3  # three selections, three RMSEs
    assert titles == {"c": "**RPE translation RMSE (m per 5 meters)**",
                      "a": "**RPE translation RMSE (m per 5 meters, all pairs)**",
                      "l": "**RPE translation RMSE (m per 5 meters, legacy pairs)**"}


def test_the_per_length_table_has_a_row_for_each_length_the_segments_have(tmp_path):
    """Drift over 5 and 10 m segments (a short indoor run): the per-length table held the devkit's 100-800 m rows,
    found none of them, and kept only "all". Its rows are now the segments' own lengths."""
    from lidarkit.eval.tables import publication_tables

    ref = Trajectory.from_tum(straight(41).to_tum(tmp_path / "ref.txt"))
    est = Trajectory.from_tum(straight(41, 1.02).to_tum(tmp_path / "est.txt"))
    drift = kitti_drift(ref, est, lengths=(10, 5), step=1)
    tables = {t.name: t for t in publication_tables({("00", "orb"): SegmentErrors.from_drift(drift)}).tables}
    lengths = tables["kitti_translation_pct_per_length"]
    assert lengths.row_labels == ["5", "10", "all"]
    by_length = {r.length_m: r.translation_pct for r in drift.per_length}
    np.testing.assert_allclose(lengths.values[:, 0], [by_length[5.0], by_length[10.0], drift.translation_pct])
    # lengths asked for stay the rows (those without segments left out)
    asked = per_length_table({("00", "orb"): SegmentErrors.from_drift(drift)}, lengths_m=(5, 100))
    assert asked.row_labels == ["5", "all"]


def test_round_off_beside_real_values_does_not_size_a_tables_decimals():
    """A copy scored against itself (3e-13) beside real values made every cell print 15 decimals
    (0.612300000000000); round-off below 1e-9 of the table's largest is not sized for."""
    table = value_table({("00", "kiss"): 0.6123, ("00", "copy"): 3e-13, ("01", "kiss"): 1.234, ("01", "copy"): 2e-13},
                        "APE", name="ape")
    assert "| 00 | 0.612 | **0.000** |" in table.to_markdown()


def test_a_copy_scored_against_itself_alone_in_its_table_prints_zero(tmp_path, capsys):
    """KITTI 00's ground truth scored against itself: its round-off was the table's only value and printed as
    0.000000000000035 m; float64 noise of positions (at most 1e-9) prints as 0 whatever else the table holds."""
    from conftest import shared_path

    assert "| 00 | 0.000 |" in value_table({("00", "copy"): 3.5e-14}, "APE", name="ape").to_markdown()
    lines = shared_path("evo_testdata", "KITTI_00_gt.txt").read_text().splitlines()[:300]
    (tmp_path / "gt.txt").write_text("\n".join(lines) + "\n")
    with pytest.raises(SystemExit) as exc:
        from lidarkit.cli import main

        main(["eval", str(tmp_path / "gt.txt"), str(tmp_path / "gt.txt"), "--no-drift", "--tables", str(tmp_path / "t")])
    assert exc.value.code in (0, None)
    assert "| gt | 0.000 |" in (tmp_path / "t" / "ape_rmse.md").read_text()
    assert "| gt | 0.0000 |" in (tmp_path / "t" / "rpe_rmse.md").read_text()
    assert value_table({("00", "copy"): 4e-10}, "APE", name="ape").digits == 3
    assert value_table({("00", "tiny"): 2e-9}, "APE", name="ape").digits == 11  # (above round-off: sized for)


def test_stamp_timed_segment_speeds_count_frames_as_the_devkit_does():
    """Stamp-timed speeds (t[last] - t[first]) were one frame shorter than the devkit's (last - first + 1) periods:
    2.5 % apart on KITTI, moving segments across the 5 m/s bins. One period is added, as the devkit counts."""
    n = 301
    stamps = np.arange(n) * 0.1
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, 0, 3] = 10.0 * stamps  # 10 m/s
    estimate = poses.copy()
    estimate[:, 0, 3] *= 1.01
    drift = kitti_drift(Trajectory(poses, stamps), Trajectory(estimate, stamps))
    timed = SegmentErrors.from_drift(drift, frame_period_s=0.1, timestamps_s=stamps).speed_mps
    counted = SegmentErrors.from_drift(drift, frame_period_s=0.1).speed_mps
    np.testing.assert_allclose(timed, counted, rtol=1e-9)


def test_cli_times_a_segments_last_frame_by_the_median_stamp_interval(tmp_path):
    """KITTI 00 at every 10th pose (1.04 s apart) with its times: `eval --tables` counted the last frame of a segment as
    KITTI's 0.1 s, so 16 segments at 1.1412 % landed in the 10-15 m/s row where the 11 at 1.1344 % belong; one median
    interval of the stamps is counted, as bench and docs/evaluation.md count it."""
    from conftest import shared_path

    from lidarkit.eval.tables import frame_period_s

    every_10th = {}
    for name in ("KITTI_00_gt.txt", "KITTI_00_ORB.txt", "KITTI_00_gt_times.txt"):
        lines = shared_path("evo_testdata", name).read_text().splitlines()[::10]
        every_10th[name] = tmp_path / name
        every_10th[name].write_text("\n".join(lines) + "\n")
    rows = _per_speed_rows(tmp_path, "KITTI_00_gt.txt", "KITTI_00_ORB.txt", "--ref-times", str(every_10th["KITTI_00_gt_times.txt"]))
    by_speed = {row.split(",")[0]: float(row.split(",")[1]) for row in rows[1:]}
    assert by_speed["10-15 m/s"] == pytest.approx(1.1344, abs=1e-4)  # (was 1.1412)
    truth = Trajectory.from_kitti(every_10th["KITTI_00_gt.txt"], every_10th["KITTI_00_gt_times.txt"])
    assert frame_period_s(truth) == pytest.approx(1.0369, abs=1e-3)
    drift = kitti_drift(truth, Trajectory.from_kitti(every_10th["KITTI_00_ORB.txt"]))
    as_bench = SegmentErrors.from_drift(drift, frame_period_s(truth), timestamps_s=truth.timestamps_s)
    fast = (as_bench.speed_mps >= 10) & (as_bench.speed_mps < 15)
    assert fast.sum() == 11 and by_speed["10-15 m/s"] == pytest.approx(as_bench.translation_pct[fast].mean(), rel=1e-12)
    note = (tmp_path / "t" / "kitti_translation_pct_per_speed.md").read_text()
    assert "stamp plus one median interval" in note


def _per_speed_rows(tmp_path, ref: str, est: str, *options: str) -> list[str]:
    """The CSV rows of the per-speed drift table `lidarkit eval REF EST --align none --tables` writes (the run exits 0)."""
    from lidarkit.cli import main

    with pytest.raises(SystemExit) as exc:
        main(["eval", str(tmp_path / ref), str(tmp_path / est), *options, "--align", "none", "--tables", str(tmp_path / "t")])
    assert exc.value.code in (0, None)
    return (tmp_path / "t" / "kitti_translation_pct_per_speed.csv").read_text().splitlines()


def test_estimate_stamped_with_frame_numbers_is_timed_as_the_devkit_under_a_ground_truth_without_times(tmp_path, capsys):
    """KITTI 00 ORB written as TUM with stamps 0, 1, 2 (lidarkit vo's poses_tum.txt without times) against the ground
    truth without times: its frame numbers were read as seconds, every segment fell into 0-5 m/s (10x too slow); the
    frames take the devkit's 0.1 s, the rows of the same estimate in KITTI format, and the table says so."""
    from conftest import shared_path

    n_poses = 2000  # (KITTI 00's first 2000 frames: segments of 0-5, 5-10 and 10-15 m/s)
    for name in ("KITTI_00_gt.txt", "KITTI_00_ORB.txt"):
        lines = shared_path("evo_testdata", name).read_text().splitlines()[:n_poses]
        (tmp_path / name).write_text("\n".join(lines) + "\n")
    orb = Trajectory.from_kitti(tmp_path / "KITTI_00_ORB.txt")
    Trajectory(orb.poses_se3, np.arange(n_poses, dtype=np.float64)).to_tum(tmp_path / "orb_frames.tum")
    as_frames = _per_speed_rows(tmp_path, "KITTI_00_gt.txt", "orb_frames.tum", "--est-format", "tum")
    devkit = per_speed_table({("00", "orb"): SegmentErrors.from_drift(kitti_drift(  # (0.1 s a frame, as KITTI files read)
        Trajectory.from_kitti(tmp_path / "KITTI_00_gt.txt"), orb))})
    assert devkit.row_labels == ["0-5 m/s", "5-10 m/s", "10-15 m/s"]
    assert [row.split(",")[0] for row in as_frames[1:]] == devkit.row_labels  # (was 0-5 m/s only)
    np.testing.assert_allclose([float(row.split(",")[1]) for row in as_frames[1:]], devkit.values[:, 0], rtol=1e-5)
    note = "the estimate's stamps are frame numbers (0, 1, ...; lidarkit vo and odometry write them without time stamps)"
    assert note in capsys.readouterr().out.replace("\n", " ")
    assert note in (tmp_path / "t" / "kitti_translation_pct_per_speed.md").read_text()


def test_frame_numbers_with_a_gap_are_timed_at_the_devkit_period_and_seconds_are_left_as_they_are():
    """Frame numbers 0-19, 21-50 (one frame left out) are 0.1 s a frame, the gap 0.2 s; stamps in seconds, or frame
    numbers of a reference, are taken as given."""
    from lidarkit.eval.tables import segment_clock

    truth = straight(50)  # (stamps 0.1 s apart)
    untimed = Trajectory(truth.poses_se3)
    frames = np.r_[0:20, 21:51].astype(np.float64)
    clock = segment_clock(untimed, Trajectory(truth.poses_se3, frames))
    np.testing.assert_allclose(clock.timestamps_s, 0.1 * frames, rtol=1e-12)
    assert clock.frame_period_s == pytest.approx(0.1) and "frame numbers (0, 1, ...;" in clock.note
    counted = Trajectory(truth.poses_se3, np.arange(50.0))
    for ref, est, used in ((untimed, truth, truth), (counted, truth, counted)):
        clock = segment_clock(ref, est)
        assert clock.note == "" and clock.frame_period_s == pytest.approx(np.median(np.diff(used.timestamps_s)))
        np.testing.assert_array_equal(clock.timestamps_s, used.timestamps_s)


def _drive(n_poses: int, metres_per_pose: float) -> np.ndarray:
    """``(n_poses, 4, 4)`` poses ``metres_per_pose`` apart along x, bending a little (a drift to score)."""
    poses = np.tile(np.eye(4), (n_poses, 1, 1))
    poses[:, 0, 3] = metres_per_pose * np.arange(n_poses)
    poses[:, 1, 3] = 1e-4 * poses[:, 0, 3] ** 1.5
    return poses


def test_whole_second_stamps_since_1970_at_1_hz_are_seconds_not_frame_numbers(tmp_path, capsys):
    """An estimate stamped 1700000000, 1700000001, ... (1 Hz) against a ground truth without times: whole numbers
    stepping by 1, they were taken as frame numbers at 0.1 s, and 7 m/s segments fell into '>= 25 m/s'."""
    n_poses = 40  # (7 m a pose at 1 Hz: some 6.5 m/s with the devkit's extra frame, segments of 100-200 m)
    Trajectory(_drive(n_poses, 7.0)).to_kitti(tmp_path / "truth.txt")
    Trajectory(_drive(n_poses, 7.07), 1.7e9 + np.arange(n_poses, dtype=np.float64)).to_tum(tmp_path / "est_1hz.tum")
    rows = _per_speed_rows(tmp_path, "truth.txt", "est_1hz.tum", "--est-format", "tum")
    assert [row.split(",")[0] for row in rows[1:]] == ["5-10 m/s"]  # (was '>= 25 m/s')
    assert "frame numbers" not in (tmp_path / "t" / "kitti_translation_pct_per_speed.md").read_text()


def test_every_other_frame_numbered_as_seconds_is_timed_at_two_devkit_periods(tmp_path, capsys):
    """lidarkit odometry --frames 0:N:2 without stamps writes 0, 2, 4, ...: taken as seconds (2 s a pose) a 12 m/s
    drive was in '0-5 m/s'; the frames are 0.1 s each, 0.2 s between poses."""
    from lidarkit.eval.tables import segment_clock

    n_poses = 80  # (every other frame of a drive at 1.2 m a frame: 2.4 m a pose, 0.2 s apart)
    frames = 2.0 * np.arange(n_poses)
    Trajectory(_drive(n_poses, 2.4)).to_kitti(tmp_path / "truth.txt")
    Trajectory(_drive(n_poses, 2.42), frames).to_tum(tmp_path / "est_every_2nd.tum")
    clock = segment_clock(Trajectory.from_kitti(tmp_path / "truth.txt"),
                          Trajectory.from_tum(tmp_path / "est_every_2nd.tum"))
    np.testing.assert_allclose(clock.timestamps_s, 0.1 * frames, rtol=1e-12)
    assert clock.frame_period_s == pytest.approx(0.2) and "frame numbers (0, 2, ...;" in clock.note
    rows = _per_speed_rows(tmp_path, "truth.txt", "est_every_2nd.tum", "--est-format", "tum")
    assert [row.split(",")[0] for row in rows[1:]] == ["10-15 m/s"]  # (was '0-5 m/s')


def test_markdown_escapes_a_pipe_in_the_corner_and_column_labels_as_in_row_labels():
    """Files o|x.txt and g|y.txt name a method and a sequence: the method's '|' split the header into one column more
    than the rows have (the row label was escaped)."""
    import re

    table = value_table({("g|y", "o|x"): 2.1328, ("g|y", "kiss"): 1.5}, "APE", name="ape")
    table.corner = "sequence|run"
    lines = table.to_markdown().splitlines()
    header, rule, row = lines[2], lines[3], lines[4]
    assert header == "| sequence\\|run | o\\|x | kiss |" and row == "| g\\|y | 2.133 | **1.500** |"
    unescaped = re.compile(r"(?<!\\)\|")
    assert len(unescaped.findall(header)) == len(unescaped.findall(rule)) == len(unescaped.findall(row)) == 4
