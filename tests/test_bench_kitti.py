"""`lidarkit bench kitti --data ROOT` on a fake KITTI root of short synthetic sequences in KITTI layout."""

from __future__ import annotations

import pytest
from fake_kitti import write_fake_kitti_root

from lidarkit.bench.kitti import kitti_sequences
from lidarkit.cli import main
from lidarkit.errors import DataError


def test_bench_kitti_writes_the_paper_table_with_the_average_row(tmp_path, capsys):
    root = write_fake_kitti_root(tmp_path / "kitti", {"00": 56, "01": 60})  # 110 m and 118 m
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as exc:
        main(["bench", "kitti", "--data", str(root), "--out", str(out), "--methods", "open3d_point_to_plane",
              "--executor", "serial"])
    text = capsys.readouterr().out
    assert exc.value.code in (0, None), text
    assert "KITTI translational drift (%) per sequence" in text and "| **Avg.** |" in text
    md = (out / "tables" / "kitti_translation_pct.md").read_text()
    rows = [line for line in md.splitlines() if line.startswith("| ")]
    assert [r.split("|")[1].strip() for r in rows] == ["sequence", "00", "01", "**Avg.**"]
    values = [float(r.split("|")[2].strip().strip("*")) for r in rows[1:]]
    assert all(0 < v < 2.0 for v in values)  # the fake scenes register well
    assert min(values[:2]) - 0.01 <= values[2] <= max(values[:2]) + 0.01  # the pooled mean lies between
    tex = (out / "tables" / "kitti_translation_pct.tex").read_text()
    assert "\\toprule" in tex and "Avg. &" in tex and "\\bottomrule" in tex
    assert (out / "tables" / "kitti_translation_pct_per_length.csv").read_text().startswith("length (m),")
    csv = (out / "report.csv").read_text().splitlines()
    assert csv[0].endswith("median,ci95_low,ci95_high,alignment,n_rerun_failed,lidarkit_version")
    assert "Publication tables" in (out / "report.html").read_text()


def test_bench_kitti_bad_root(tmp_path, capsys):
    with pytest.raises(DataError, match="no sequences/ folder"):
        kitti_sequences(tmp_path, ["00"])
    (tmp_path / "sequences" / "00" / "velodyne").mkdir(parents=True)
    with pytest.raises(DataError, match="ground-truth poses"):
        kitti_sequences(tmp_path, ["00"])
    with pytest.raises(SystemExit) as exc:
        main(["bench", "kitti", "--data", str(tmp_path), "--out", str(tmp_path / "o")])
    assert exc.value.code == 1 and "ground-truth poses" in capsys.readouterr().err
    # a sequence name that is no folder is said to be none, beside the root's sequences with scans (0x read as one
    # without scans)
    with pytest.raises(DataError) as info:
        kitti_sequences(tmp_path, ["0x"])
    assert str(info.value).endswith("has velodyne/ scans and ground-truth poses (no folder 0x); with scans: 00")


def test_bench_kitti_names_what_it_cannot_run_and_a_dry_run_writes_nothing(tmp_path, capsys):
    """A sequence asked for by name that the root lacks, and an unknown method, are errors naming them (not dropped,
    not blamed on the generated suite file); a dry run and a refused run leave no folder behind."""
    root = write_fake_kitti_root(tmp_path / "kitti", {"00": 8})

    def bench(*args):
        with pytest.raises(SystemExit) as exc:
            main(["bench", "kitti", "--data", str(root), "--executor", "serial", *args])
        return exc.value.code, capsys.readouterr()

    code, io = bench("--sequences", "00,05", "--out", str(tmp_path / "a"))
    assert code == 1 and "no velodyne/ scans with ground-truth poses for sequence(s) 05 (found: 00)" in io.err
    code, io = bench("--methods", "nosuch", "--out", str(tmp_path / "b"))
    assert code == 1 and "error: --methods: unknown method(s) nosuch; known:" in io.err
    code, io = bench("--methods", "vanilla", "--out", str(tmp_path / "c"), "--dry-run")
    assert code in (0, None) and "vanilla" in io.out
    assert not any((tmp_path / name).exists() for name in ("a", "b", "c"))


def test_bench_kitti_names_the_option_that_repeats_a_sequence_or_method(tmp_path, capsys):
    """`--sequences 00,00` (or `--methods kiss,kiss`) said "error: /tmp/tmpb7hxy8o4/kitti_suite.yaml
    (experiments[0].datasets[1], line 17): duplicate dataset", naming a temporary file already deleted."""
    root = write_fake_kitti_root(tmp_path / "kitti", {"00": 8})
    for args, line in ((["--sequences", "00,00"], "error: --sequences: 00 given twice"),
                       (["--methods", "kiss,vanilla,kiss,kiss"], "error: --methods: kiss given 3 times")):
        with pytest.raises(SystemExit) as exc:
            main(["bench", "kitti", "--data", str(root), "--out", str(tmp_path / "o"), "--dry-run", *args])
        assert exc.value.code == 1 and capsys.readouterr().err.strip() == line
    assert not (tmp_path / "o").exists()


def test_kitti_options_on_a_suite_file_name_the_options_given(tmp_path, capsys):
    """`lidarkit bench s.yaml --methods kiss` said "error: --data: --data/--methods/--sequences apply to `lidarkit
    bench kitti` only" though --data was not given."""
    suite = tmp_path / "s.yaml"
    suite.write_text("name: s\nseeds: 1\nexperiments:\n"
                     "  - {task: selftest, dataset: {kind: synthetic}, methods: [random_walk]}\n")
    for args, line in ((["--methods", "kiss"], "error: --methods: applies to `lidarkit bench kitti` only"),
                       (["--sequences", "00", "--data", str(tmp_path)],
                        "error: --data, --sequences: apply to `lidarkit bench kitti` only")):
        with pytest.raises(SystemExit) as exc:
            main(["bench", str(suite), "--out", str(tmp_path / "o"), "--dry-run", *args])
        assert exc.value.code == 1 and capsys.readouterr().err.strip() == line
