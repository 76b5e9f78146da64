"""The bad-input corpus: each case builds a bad input or a faulty output place in a temp folder and runs the CLI.

Every case must end as one ``error:`` line naming the culprit, exit code 1, no traceback and nothing
half-written. Grouped by family (issue #16): output paths, rich markup, backends, suites, parameter bounds,
messages that name the culprit.
"""

from __future__ import annotations

import errno
import gzip
import os
import shutil
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

import numpy as np
import pytest

from lidarkit import atomic
from lidarkit.cli import main
from lidarkit.errors import LidarKitError, OutputError
from lidarkit.samples import sample_path

PAIR = sample_path("kitti_pair")
FREIBURG = sample_path("freiburg_pf")


def run_cli(args: list[str], capsys) -> tuple[int, str, str]:
    """Run ``lidarkit ARGS`` in this process; (exit code, stdout, stderr). Any other exception fails the test."""
    capsys.readouterr()
    try:
        main([str(a) for a in args])
        code = 0
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else 1
    out, err = capsys.readouterr()
    return code, out, err


def assert_one_line_error(code: int, err: str, *names: str) -> str:
    assert code == 1, err
    assert "Traceback" not in err
    lines = [line for line in err.splitlines() if line.startswith("error:")]
    assert len(lines) == 1, err
    text = " ".join(err.split())  # rich may wrap a long line
    for name in names:
        assert name in text, (name, err)
    return text


@pytest.fixture
def gt_file(tmp_path) -> Path:
    path = tmp_path / "gt.txt"
    with gzip.open(sample_path("evo_kitti00", "KITTI_00_gt.txt.gz"), "rt") as fh:
        path.write_text("".join(fh.readlines()[:30]))
    return path


# ---------------------------------------------------------------- output paths (Found 1)

def test_out_is_an_existing_file_icp(tmp_path, capsys):
    blocker = tmp_path / "taken"
    blocker.write_text("keep me")
    code, _, err = run_cli(["icp", PAIR / "000094.npy", PAIR / "000095.npy", "--out", blocker], capsys)
    assert_one_line_error(code, err, "taken", "a file is in the way")
    assert blocker.read_text() == "keep me"


def test_out_below_an_existing_file_pf(tmp_path, capsys):
    blocker = tmp_path / "taken"
    blocker.write_text("x")
    code, _, err = run_cli(["pf", FREIBURG, "-n", "20", "--out", blocker / "run"], capsys)
    assert_one_line_error(code, err, "taken", "a file is in the way")


def test_json_names_an_existing_directory(tmp_path, gt_file, capsys):
    (tmp_path / "adir").mkdir()
    code, _, err = run_cli(["eval", gt_file, gt_file, "--json", tmp_path / "adir"], capsys)
    assert_one_line_error(code, err, "adir", "is a folder")
    assert list((tmp_path / "adir").iterdir()) == []


def test_plot_with_an_unknown_suffix(tmp_path, gt_file, capsys):
    code, _, err = run_cli(["eval", gt_file, gt_file, "--plot", tmp_path / "out.txt", "--json", tmp_path / "e.json"], capsys)
    assert_one_line_error(code, err, "out.txt", "unknown plot format", ".png")
    assert not (tmp_path / "e.json").exists()  # refused before anything was written


def test_a_name_too_long_for_the_disk_is_one_line_before_any_work(tmp_path, gt_file, capsys):
    """A 300-byte name (the disk takes 255) was an OSError traceback: for outputs from the path check, for inputs
    from a reader; a tables folder below it passed the check and failed after the evaluation, leaving its parent."""
    long = "a" * 300
    for args in (["eval", gt_file, gt_file, "--json", tmp_path / f"{long}.json"],
                 ["eval", gt_file, gt_file, "--tables", tmp_path / "x" / long / "y"]):
        code, _, err = run_cli(args, capsys)
        assert_one_line_error(code, err, long, "cannot write: file name too long (a name of 30")
    assert list(tmp_path.iterdir()) == [gt_file]
    for args in (["eval", tmp_path / f"{long}.txt", gt_file], ["icp", tmp_path / f"{long}.bin", PAIR / "000095.npy"]):
        code, _, err = run_cli(args, capsys)
        assert_one_line_error(code, err, long, "file name too long")


def test_odometry_out_is_an_existing_file(tmp_path, capsys):
    blocker = tmp_path / "run"
    blocker.write_text("x")
    code, _, err = run_cli(["odometry", "sim:open?frames=3", "--out", blocker, "--no-progress"], capsys)
    assert_one_line_error(code, err, str(blocker), "a file is in the way")


def test_bench_out_is_an_existing_file(tmp_path, capsys):
    suite = tmp_path / "s.yaml"
    suite.write_text("experiments:\n  - task: selftest\n    dataset: {kind: synthetic}\n    methods: [random_walk]\n")
    blocker = tmp_path / "res"
    blocker.write_text("x")
    code, _, err = run_cli(["bench", suite, "--out", blocker, "--executor", "serial"], capsys)
    assert_one_line_error(code, err, "res", "a file is in the way")


def test_disk_full_while_writing_is_an_output_error(tmp_path, monkeypatch):
    def full(_fd):
        raise OSError(errno.ENOSPC, "No space left on device")

    target = tmp_path / "r.json"
    target.write_text("previous")
    monkeypatch.setattr(os, "fsync", full)
    with pytest.raises(OutputError, match="r.json: cannot write: no space left"):
        atomic.write_text(target, "new")
    assert target.read_text() == "previous"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.json"]


def test_failed_run_leaves_no_run_folder(tmp_path):
    out = tmp_path / "run"
    with pytest.raises(RuntimeError):
        with atomic.run_folder(out) as tmp:
            atomic.write_text(tmp / "config.yaml", "a: 1\n")
            raise RuntimeError("plotting failed")
    assert list(tmp_path.iterdir()) == []


def test_run_folder_into_an_existing_folder_keeps_other_files(tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    with atomic.run_folder(out) as tmp:
        atomic.write_text(tmp / "metrics.json", "{}")
        atomic.write_text(tmp / "plots" / "a.png", "png")
    assert sorted(str(p.relative_to(out)) for p in out.rglob("*")) == ["metrics.json", "notes.txt", "plots", "plots/a.png"]
    assert [p.name for p in tmp_path.iterdir()] == ["run"]


def test_pf_disk_full_mid_write_leaves_nothing(tmp_path, capsys, monkeypatch):
    """The disk fills up after the pf run folder's first two files: no folder that looks like a finished run."""
    calls = []
    real_fsync = os.fsync

    def fsync(fd):
        calls.append(fd)
        if len(calls) > 2:
            raise OSError(errno.ENOSPC, "No space left on device")
        real_fsync(fd)

    monkeypatch.setattr(os, "fsync", fsync)
    out = tmp_path / "pfrun"
    code, _, err = run_cli(["pf", FREIBURG, "-n", "20", "--out", out], capsys)
    assert_one_line_error(code, err, "pfrun", "no space left")
    assert len(calls) == 3
    assert list(tmp_path.iterdir()) == []


def _unshare_available() -> bool:
    if shutil.which("unshare") is None or sys.platform != "linux":
        return False
    probe = subprocess.run(["unshare", "-m", "sh", "-c", "mount -t tmpfs -o size=8k tmpfs /mnt"], capture_output=True)
    return probe.returncode == 0


needs_mount = pytest.mark.skipif(not _unshare_available(), reason="needs unshare -m and mount (root in a private mount namespace)")


def _in_private_tmpfs(tmp_path: Path, mount_opts: str, command: str) -> subprocess.CompletedProcess:
    """Run ``command`` with ``tmp_path/fs`` mounted as a small tmpfs in a private mount namespace (nothing leaks)."""
    (tmp_path / "fs").mkdir()
    script = f"mount -t tmpfs -o {mount_opts} tmpfs fs && {command}"
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    return subprocess.run(["unshare", "-m", "sh", "-c", script], cwd=tmp_path, capture_output=True, text=True, env=env,
                          timeout=120)


@needs_mount
def test_read_only_file_system(tmp_path, gt_file):
    proc = _in_private_tmpfs(tmp_path, "size=64k,ro", f"{sys.executable} -m lidarkit.cli eval {gt_file} {gt_file} --json fs/e.json")
    assert_one_line_error(proc.returncode, proc.stderr, "fs/e.json", "read-only file system")


def _sysfs_refuses_folders() -> bool:
    try:
        os.rmdir(tempfile.mkdtemp(dir="/sys"))
    except OSError:
        return Path("/sys").is_dir() and os.access("/sys", os.W_OK)  # access() says yes, creating says no
    return False


@pytest.mark.skipif(not _sysfs_refuses_folders(), reason="needs a /sys that access() calls writable but refuses folders")
def test_an_output_folder_that_cannot_be_created_is_refused_before_the_run(capsys):
    """access() passes /sys for root: vo ran the whole sequence and then lost it ('cannot create the run folder')."""
    code, out, err = run_cli(["vo", "simcam:street?frames=30&seed=1", "--out", "/sys/lidarkit_vo_out"], capsys)
    assert_one_line_error(code, err, "/sys/lidarkit_vo_out", "cannot write")
    assert "APE" not in out  # refused before the run, not after it


@needs_mount
def test_disk_fills_up_during_bench(tmp_path):
    """The result folder on a 24 KiB file system: the run stops with one line naming the file; every result file
    that exists is complete JSON; nothing is left running."""
    suite = tmp_path / "s.yaml"
    suite.write_text(textwrap.dedent("""
        experiments:
          - task: selftest
            dataset: {kind: synthetic}
            methods: [{name: random_walk, params: {steps: 400}}]
            seeds: 40
    """))
    proc = _in_private_tmpfs(tmp_path, "size=24k", f"{sys.executable} -m lidarkit.cli bench {suite} --out fs/res "
                             f"--executor process -j 2 --no-report; rc=$?; "
                             f"{sys.executable} -c \"import json,glob; [json.load(open(p)) for p in glob.glob('fs/res/jobs/*.json')]\" "
                             f"|| echo CORRUPT; exit $rc")
    assert "CORRUPT" not in proc.stdout
    assert_one_line_error(proc.returncode, proc.stderr, "fs/res", "no space left")


# ---------------------------------------------------------------- rich markup in user strings (Found 3)

@pytest.mark.parametrize("name", ["bad[/red].txt", "scan[v2].txt", "[bold]x[/bold].txt"])
def test_markup_in_a_file_name_is_printed_verbatim(tmp_path, capsys, name):
    missing = tmp_path / name
    code, _, err = run_cli(["eval", missing, missing], capsys)
    assert_one_line_error(code, err, name)


def test_markup_in_a_bad_file_name_in_a_table(tmp_path, gt_file, capsys):
    named = tmp_path / "est[v2][bold red].txt"
    shutil.copy(gt_file, named)
    code, out, err = run_cli(["eval", gt_file, named], capsys)
    assert code == 0, err
    assert "est[v2][bold red]" in out


# ---------------------------------------------------------------- suites (Found 5: silent acceptance)

SUITE_OK = """\
name: s
seeds: [0, 1]
experiments:
  - name: a
    task: selftest
    dataset: {kind: synthetic}
    methods: [random_walk]
"""


@pytest.mark.parametrize("text, line, reason", [
    (SUITE_OK.replace("name: s\n", "name: s\nname: t\n"), 2, "duplicate key 'name' (first on line 1)"),
    (SUITE_OK.replace("    task: selftest\n", "    task: selftest\n    task: selftest\n"), 6, "duplicate key 'task'"),
    (SUITE_OK.replace("seeds: [0, 1]", "seeds: [0, 1, 1]"), 2, "duplicate seeds [1]"),
    (SUITE_OK.replace("methods: [random_walk]", "methods: [random_walk, random_walk]"), 7, "duplicate method 'random_walk'"),
    (SUITE_OK + SUITE_OK[SUITE_OK.index("  - name: a"):], 8, "duplicate experiment name 'a'"),
    (SUITE_OK.replace("methods: [random_walk]", "methods: [{name: random_walk, grid: {steps: [5, 5]}}]"), 7,
     "grid 'steps' lists a value twice"),
    (SUITE_OK.replace("methods: [random_walk]", "methods: [{name: random_walk, grid: {steps: [5, 5.0]}}]"), 7,
     "grid 'steps' lists a value twice"),  # 5 and 5.0 are one job (they ran twice, two rows with one label)
    (SUITE_OK.replace("methods: [random_walk]", "methods: [{name: random_walk, params: {steps: 50}}, {name: random_walk, params: {steps: 50.0}}]"),
     7, "duplicate method 'random_walk'"),
    (SUITE_OK.replace("seeds: [0, 1]", "seeds: [-1]"), 2, "seeds must be >= 0"),
    # one job written two ways across a method's params and another's grid (1 / 1.0, 50 / "50"): it ran twice, and the
    # report's pivot kept one of the two rows with one label
    (SUITE_OK.replace("methods: [random_walk]", "methods: [{name: random_walk, params: {noise_m: 1}}, "
                      "{name: random_walk, grid: {noise_m: [1.0, 2.0]}}]"), 7,
     "runs the same job as experiments[0].methods[0] (a value written two ways, e.g. 1 and 1.0)"),
    (SUITE_OK.replace("methods: [random_walk]", "methods: [{name: random_walk, params: {steps: 50}}, "
                      "{name: random_walk, params: {steps: '50'}}]"), 7, "runs the same job as experiments[0].methods[0]"),
])
def test_suite_duplicates_are_refused_with_file_and_line(tmp_path, capsys, text, line, reason):
    path = tmp_path / "suite.yaml"
    path.write_text(text)
    code, _, err = run_cli(["bench", path, "--dry-run"], capsys)
    assert_one_line_error(code, err, "suite.yaml", f"line {line}", reason)


def test_a_huge_grid_is_refused_instantly_with_its_count(tmp_path, capsys):
    import time

    path = tmp_path / "suite.yaml"
    grid = "{noise_m: [" + ", ".join(str(i / 1000) for i in range(1000)) + "], steps: [" + ", ".join(str(i) for i in range(2, 102)) + "]}"
    path.write_text(SUITE_OK.replace("methods: [random_walk]", f"methods: [{{name: random_walk, grid: {grid}}}]").replace(
        "seeds: [0, 1]", "seeds: 10"))
    t0 = time.perf_counter()
    code, _, err = run_cli(["bench", path, "--dry-run"], capsys)
    assert time.perf_counter() - t0 < 5.0
    assert_one_line_error(code, err, "suite.yaml", "1,000,000 jobs", "limit of 100,000", "--max-jobs")
    code, _, err = run_cli(["bench", path, "--dry-run", "--max-jobs", "999"], capsys)
    assert_one_line_error(code, err, "1,000,000 jobs", "limit of 999")


# ---------------------------------------------------------------- backend boundaries (Found 2, Found 5 overlap)

def _pcd_ascii(n_declared: int, n_body: int) -> str:
    rng = np.random.default_rng(0)
    body = "\n".join(" ".join(f"{v:.3f}" for v in row) for row in rng.uniform(-5, 5, (n_body, 3)))
    return (f"# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH {n_declared}\nHEIGHT 1\n"
            f"VIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n_declared}\nDATA ascii\n{body}\n")


def _pcd_binary(n_declared: int, n_body: int) -> bytes:
    header = (f"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH {n_declared}\nHEIGHT 1\n"
              f"VIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n_declared}\nDATA binary\n").encode()
    return header + np.random.default_rng(0).uniform(-5, 5, (n_body, 3)).astype("<f4").tobytes()


def _bad_scan(tmp_path: Path, kind: str) -> tuple[Path, str]:
    """(file, expected reason) for each bad scan of the corpus."""
    if kind == "text_as_bin":
        path = tmp_path / "notes.bin"
        path.write_bytes(b"this is a text file renamed .bin, not a KITTI scan!!" * 64)  # floats near 1e31
        return path, "not a metric point cloud"
    if kind == "scaled_1e300":
        path = tmp_path / "huge.npy"
        np.save(path, np.load(PAIR / "000094.npy")[:, :3].astype(np.float64) * 1e300)
        return path, "beyond 1e+07 m"
    if kind == "complex":
        path = tmp_path / "complex.npy"
        np.save(path, np.load(PAIR / "000094.npy")[:100, :3].astype(np.complex128))
        return path, "complex128"
    if kind == "pcd_ascii_short":
        path = tmp_path / "short.pcd"
        path.write_text(_pcd_ascii(200, 190))
        return path, "declares 200 points but the ascii body holds 190"
    if kind == "pcd_binary_short":
        path = tmp_path / "short_bin.pcd"
        path.write_bytes(_pcd_binary(200, 190))
        return path, "declares 200 points"
    raise AssertionError(kind)


@pytest.mark.parametrize("kind", ["text_as_bin", "scaled_1e300", "complex", "pcd_ascii_short", "pcd_binary_short"])
def test_bad_scan_never_reaches_a_backend(tmp_path, capsys, kind):
    bad, reason = _bad_scan(tmp_path, kind)
    out = tmp_path / "run"
    code, _, err = run_cli(["icp", bad, PAIR / "000095.npy", "--method", "open3d_gicp", "--out", out], capsys)
    assert_one_line_error(code, err, bad.name, reason)
    assert not out.exists()


def test_complex_and_huge_arrays_are_refused_by_align():
    from lidarkit.errors import DataError
    from lidarkit.registration import get_icp

    cloud = np.load(PAIR / "000094.npy")[:2000, :3].astype(np.float64)
    with pytest.raises(DataError, match="source cloud: expected real coordinates, got a complex array"):
        get_icp("vanilla").align(cloud.astype(np.complex128), cloud)
    with pytest.raises(DataError, match="target cloud: .*beyond 1e\\+07 m"):
        get_icp("open3d_gicp").align(cloud, cloud * 1e300)


@pytest.mark.parametrize("method", ["vanilla", "kiss", "open3d_gicp"])
def test_pair_without_initial_overlap_is_flagged(method):
    from lidarkit.registration import get_icp

    scan = np.load(PAIR / "000094.npy")[:, :3].astype(np.float64)
    far = scan + np.array([5000.0, 0.0, 0.0])
    result = get_icp(method).align(far, scan)
    assert not result.converged
    assert "no initial overlap" in result.reason and "pass init_T" in result.reason
    if method == "kiss":
        return  # kiss crops the source by range from its own origin: the shifted copy has no point in range
    T = np.eye(4)
    T[0, 3] = -5000.0
    good = get_icp(method).align(far, scan, init_T=T)  # the same pair with a guess: aligned
    assert good.converged and abs(good.T_target_source[0, 3] + 5000.0) < 0.5


def test_backend_exception_becomes_a_registration_error():
    from lidarkit.errors import RegistrationError
    from lidarkit.registration.vanilla import VanillaICP

    class Broken(VanillaICP):
        name = "broken"

        def _align(self, source_xyz, target_xyz, init_T):
            raise RuntimeError("[Open3D Error] (ShapeUtil.cpp:195) shape mismatch")

    cloud = np.load(PAIR / "000094.npy")[:500, :3]
    with pytest.raises(RegistrationError, match=r"broken \(500 source / 500 target points\): the broken backend failed.*ShapeUtil"):
        Broken().align(cloud, cloud)


# ---------------------------------------------------------------- parameter bounds and memory (Found 6)

@pytest.mark.parametrize("args, names", [
    (["sim", "lidar", "-o", "{tmp}/s", "-p", "speed_mps=inf"], ["speed_mps", "finite"]),
    (["sim", "lidar", "-o", "{tmp}/s", "-p", "speed_mps=1e6"], ["speed_mps", "less than or equal to 100"]),
    (["sim", "lidar", "-o", "{tmp}/s", "-p", "frame_rate_hz=1e-9"], ["frame_rate_hz", "greater than or equal to 0.1"]),
    (["sim", "lidar", "-o", "{tmp}/s", "-p", "n_beams=100000", "-p", "n_azimuths=100000"], ["n_azimuths", "GiB of memory"]),
    (["sim", "lidar", "-o", "{tmp}/s", "--seed", "-1"], ["seed", "greater than or equal to 0"]),
    # a bag's name without -f: a KITTI folder named s.bag was written
    (["sim", "lidar", "-o", "{tmp}/s.bag"], ["--out", "s.bag is named like a ROS 1 bag, but --format is kitti", "-f rosbag1"]),
    (["odometry", "sim:open?frames=3&speed_mps=1e6", "--no-progress"], ["speed_mps", "less than or equal to 100"]),
    (["pf", str(FREIBURG), "-n", "1000000000000"], ["--particles", "n_particles must be >= 1 and <="]),
    (["pf", str(FREIBURG), "--seed", "-1"], ["--seed", "must be >= 0, got -1"]),
    (["vo", str(sample_path("kitti_vo", "06")), "--seed", "-1"], ["--seed", "must be >= 0, got -1"]),
])
def test_unbounded_parameters_are_refused(tmp_path, capsys, args, names):
    code, _, err = run_cli([a.replace("{tmp}", str(tmp_path)) for a in args], capsys)
    assert_one_line_error(code, err, *names)
    assert not (tmp_path / "s").exists() and not (tmp_path / "s.bag").exists()


def test_pf_recorded_without_sensor_readings(tmp_path, capsys):
    (tmp_path / "world.dat").write_text((FREIBURG / "world.dat").read_text())
    odometry_only = [line for line in (FREIBURG / "sensor_data.dat").read_text().splitlines() if line.startswith("ODOMETRY")]
    (tmp_path / "sensor_data.dat").write_text("\n".join(odometry_only[:40]) + "\n")
    code, _, err = run_cli(["pf", tmp_path, "--recorded"], capsys)
    assert_one_line_error(code, err, "sensor_data.dat", "0 SENSOR readings")


# ---------------------------------------------------------------- messages that name the culprit (Found 7)

def _poses_with(tmp_path: Path, gt_file: Path, row: int, R: np.ndarray, name: str = "bad_poses.txt") -> Path:
    lines = gt_file.read_text().splitlines()
    values = np.array(lines[row].split(), dtype=float).reshape(3, 4)
    values[:, :3] = R
    lines[row] = " ".join(f"{v:.9e}" for v in values.ravel())
    path = tmp_path / name
    path.write_text("# a comment line\n" + "\n".join(lines) + "\n")
    return path


def test_non_orthonormal_rotation_names_file_and_line(tmp_path, gt_file, capsys):
    bad = _poses_with(tmp_path, gt_file, 2, np.diag([1.0, 1.3, 1.0]))
    code, _, err = run_cli(["eval", gt_file, bad], capsys)
    assert_one_line_error(code, err, "bad_poses.txt (line 4, frame 2)", "not orthonormal")


def test_reflection_is_called_a_reflection(tmp_path, gt_file, capsys):
    bad = _poses_with(tmp_path, gt_file, 5, np.diag([1.0, 1.0, -1.0]))
    code, _, err = run_cli(["eval", gt_file, bad], capsys)
    assert_one_line_error(code, err, "bad_poses.txt (line 7, frame 5)", "reflection", "det R = -1")


def test_non_monotonic_ref_times_names_the_times_file(tmp_path, gt_file, capsys):
    times = tmp_path / "ref_times.txt"
    stamps = np.arange(30) * 0.1
    stamps[7] = 0.05
    times.write_text("".join(f"{t:.3f}\n" for t in stamps))
    code, _, err = run_cli(["eval", gt_file, gt_file, "--ref-times", times], capsys)
    assert_one_line_error(code, err, "ref_times.txt (line 8, frame 7)", "not strictly increasing")


def test_non_rigid_tr_in_calib_names_calib_and_tr(tmp_path):
    from lidarkit.errors import DataError
    from lidarkit.io.kitti import read_kitti_calib as read_calib

    calib = tmp_path / "calib.txt"
    calib.write_text("P0: 7 0 6 0 0 7 1 0 0 0 1 0\nTr: 2 0 0 0 0 1 0 0 0 0 1 0\n")
    with pytest.raises(DataError, match=r"calib.txt \(line 2\): Tr \(LiDAR-to-camera\) is not rigid"):
        read_calib(calib)


def test_reversed_frame_selection(capsys):
    code, _, err = run_cli(["odometry", "sim:open?frames=3", "--frames", "::-1", "--no-progress"], capsys)
    assert_one_line_error(code, err, "::-1", "reversed frame selection")


def test_huge_odometry_in_sensor_data_names_file_and_line(tmp_path, capsys):
    (tmp_path / "world.dat").write_text((FREIBURG / "world.dat").read_text())
    lines = (FREIBURG / "sensor_data.dat").read_text().splitlines()
    lines[4] = "ODOMETRY 1e300 0.1 0.0"
    (tmp_path / "sensor_data.dat").write_text("\n".join(lines) + "\n")
    code, _, err = run_cli(["pf", tmp_path, "-n", "20"], capsys)
    assert_one_line_error(code, err, "sensor_data.dat (line 5)", "1e300")


def test_too_few_steps_for_the_mse(tmp_path, capsys):
    (tmp_path / "world.dat").write_text((FREIBURG / "world.dat").read_text())
    text, steps = [], 0
    for line in (FREIBURG / "sensor_data.dat").read_text().splitlines():
        steps += line.startswith("ODOMETRY")
        if steps > 3:
            break
        text.append(line)
    (tmp_path / "sensor_data.dat").write_text("\n".join(text) + "\n")
    code, _, err = run_cli(["pf", tmp_path, "-n", "20"], capsys)
    assert_one_line_error(code, err, "3 steps: the protocol scores the position MSE from step 10 on, so it needs at least 10")


def test_zero_focal_length(tmp_path, capsys):
    calib = tmp_path / "K.txt"
    calib.write_text("0 0 320 240\n")
    code, _, err = run_cli(["vo", sample_path("kitti_vo", "06"), "--calib", calib], capsys)
    assert_one_line_error(code, err, "K.txt", "focal lengths must be > 0 pixels, got fx = 0, fy = 0")


def test_bad_vo_timestamps_named_before_the_run(tmp_path, capsys):
    n = len(list(sample_path("kitti_vo", "06", "image_0").iterdir()))
    stamps = np.arange(n) * 0.1
    stamps[3] = 0.05
    times = tmp_path / "stamps.txt"
    times.write_text("".join(f"{t:.3f}\n" for t in stamps))
    code, out, err = run_cli(["vo", sample_path("kitti_vo", "06"), "--timestamps", times], capsys)
    assert_one_line_error(code, err, "stamps.txt (line 4", "not strictly increasing")
    assert out == ""  # refused before any frame was processed


def test_library_arguments_of_the_wrong_kind_are_one_clear_error():
    """Wrong argument types were TypeErrors and ValueErrors from deep inside (or, for strings that are true, taken as
    True: align_origin="no" aligned the origin); each is a LidarKitError naming the argument."""
    from conftest import shared_path
    from lidarkit.eval import ape
    from lidarkit.io import open_dataset
    from lidarkit.odometry import run
    from lidarkit.registration.vanilla import VanillaICP
    from lidarkit.trajectory import Trajectory

    still = Trajectory(np.tile(np.eye(4), (5, 1, 1)))
    spec = "sim:street?frames=3&beams=8&azimuths=90"
    for call, message in (
        (lambda: Trajectory("abc"), "poses must be numbers, an (N, 4, 4) array, got str"),
        (lambda: Trajectory(still.poses_se3, ["a"] * 5), "timestamps must be numbers (seconds)"),
        (lambda: run(spec, "vanilla", prefetch="2"), "prefetch must be a whole number of scans >= 0"),
        (lambda: run(spec, "vanilla", prefetch=-1), "prefetch must be a whole number of scans >= 0"),
        (lambda: run(spec, "vanilla", pose_covariance="yes"), "pose_covariance must be True or False, got 'yes'"),
        (lambda: run(spec, "vanilla", params=[("max_iterations", 5)]), "params must be a mapping"),
        (lambda: ape(still, still, align="se3", n_to_align="5"), "n_to_align must be a whole number of poses, got '5'"),
        (lambda: ape(still, still, align_origin="no"), "align_origin must be True or False, got 'no'"),
        (lambda: VanillaICP(max_iterations=-1), "vanilla: invalid parameters (max_iterations: Input should be greater than or equal to 1)"),
        # (Python's words: "got an unexpected keyword argument 'max_range_m'", naming one of the two)
        (lambda: open_dataset("kitti", shared_path("kitti_odometry", "sequences", "00"), max_range_m=50, foo=1),
         "kitti dataset options: unknown options 'max_range_m', 'foo'; valid options: sequence, "),
    ):
        with pytest.raises(LidarKitError) as info:
            call()
        assert message in str(info.value)


# ---------------------------------------------------------------- links that cannot be followed, pipes, far poses

LINK_LOOP = "cannot read it: a loop of symbolic links (a link that leads back to itself)"


def _broken_link(tmp_path: Path, name: str, kind: str) -> tuple[Path, str]:
    """A symbolic link ``name`` in ``tmp_path`` that cannot be followed (``kind``: "loop" or "dangling") and the reason
    an input given as it must read."""
    link = tmp_path / name
    if kind == "loop":
        back = tmp_path / f"back-{name}"
        link.symlink_to(back.name)
        back.symlink_to(link.name)
        return link, LINK_LOOP
    link.symlink_to(tmp_path / "gone" / name)
    return link, f"a symbolic link to a missing file (-> {tmp_path / 'gone' / name})"


def test_a_suite_file_that_is_a_loop_of_links_is_one_line(tmp_path, capsys):
    """`lidarkit bench l1.txt` with l1.txt -> l2.txt -> l1.txt was a "RuntimeError: Symlink loop" traceback."""
    loop, reason = _broken_link(tmp_path, "suite.yaml", "loop")
    code, _, err = run_cli(["bench", loop, "--out", tmp_path / "results"], capsys)
    assert_one_line_error(code, err, f"{loop}: {reason}")
    assert not (tmp_path / "results").exists()


@pytest.mark.parametrize("kind", ["loop", "dangling"])
@pytest.mark.parametrize("command", ["icp scan", "icp --init", "eval", "odometry kitti:", "pf", "vo", "report"])
def test_an_input_that_is_a_link_going_nowhere_says_so_not_not_found(tmp_path, capsys, gt_file, command, kind):
    """Inputs that were loops of symbolic links (or links to missing files) read "not found" (``Path.exists()`` is
    False for both), which sent the user looking for a file that is there: the message says which."""
    bad, reason = _broken_link(tmp_path, "scan.npy" if command.startswith("icp") else "input", kind)
    argv = {
        "icp scan": ["icp", bad, PAIR / "000095.npy"],
        "icp --init": ["icp", PAIR / "000094.npy", PAIR / "000095.npy", "--init", bad],
        "eval": ["eval", bad, gt_file],
        "odometry kitti:": ["odometry", f"kitti:{bad}", "--no-progress"],
        "pf": ["pf", bad],
        "vo": ["vo", bad],
        "report": ["report", bad],
    }[command]
    code, out, err = run_cli(argv, capsys)
    assert_one_line_error(code, err, f"{bad}: {reason}")
    assert "not found" not in err


@pytest.mark.parametrize("command", ["eval", "icp scan", "icp --init"])
def test_a_pipe_or_a_device_given_as_an_input_file_says_to_save_it_first(tmp_path, capsys, gt_file, command):
    """`lidarkit eval <(zcat gt.txt.gz) est.txt` read "/dev/fd/63: not a regular file", which did not say what to do."""
    pipe = tmp_path / "piped.npy"
    os.mkfifo(pipe)  # (never opened: refused by what it is)
    for given, reason in ((pipe, "a pipe (e.g. <(...)): save it to a file first"),
                          (Path("/dev/null"), "a device, not a file: save what it gives to a file first")):
        argv = {
            "eval": ["eval", given, gt_file],
            "icp scan": ["icp", given, PAIR / "000095.npy"],
            "icp --init": ["icp", PAIR / "000094.npy", PAIR / "000095.npy", "--init", given],
        }[command]
        if command == "icp scan" and given == Path("/dev/null"):
            continue  # (a scan's kind is read from its suffix: /dev/null has none)
        code, _, err = run_cli(argv, capsys)
        assert_one_line_error(code, err, f"{given}: {reason}")


def test_an_init_translation_beyond_any_map_is_refused_naming_the_init(tmp_path, capsys):
    """`icp --init` with a 1e200 m translation leaked numpy's "overflow encountered in dot" and recorded "inf m from the
    target's bounding box": a translation beyond geometry.MAX_ABS_COORDINATE_M is refused, as such a point is."""
    import warnings

    from lidarkit.errors import DataError
    from lidarkit.registration.base import check_init_T

    far = tmp_path / "far.txt"
    far.write_text("1 0 0 1e200\n0 1 0 0\n0 0 1 0\n0 0 0 1\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        code, out, err = run_cli(["icp", PAIR / "000094.npy", PAIR / "000095.npy", "--init", far], capsys)
    assert_one_line_error(code, err, f"{far}: the translation has a coordinate of 1e+200 m, beyond 1e+07 m: not a metric pose")
    T = np.eye(4)
    T[1, 3] = -2e7
    with pytest.raises(DataError, match=r"^init_T: the translation has a coordinate of 2e\+07 m"):
        check_init_T(T)
    T[1, 3] = 5.8e6  # (a UTM northing: a pose on the map)
    assert check_init_T(T)[1, 3] == 5.8e6


@pytest.mark.parametrize("kind", ["loop", "dangling"])
def test_a_landmark_dataset_read_directly_through_a_broken_link_says_so(tmp_path, kind):
    """The reader itself (not only `lidarkit pf`, which opens it through open_dataset) names a link going nowhere."""
    from lidarkit.errors import DataError
    from lidarkit.io.landmarks import LandmarkData

    bad, reason = _broken_link(tmp_path, "freiburg", kind)
    with pytest.raises(DataError) as caught:
        LandmarkData(bad)
    assert str(caught.value) == f"{bad}: {reason}"
