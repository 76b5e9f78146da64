"""The CLI starts without the libraries only some commands need (OpenCV, scipy.signal): every command crashed at import
under `ulimit -v 400000` (cv2's ImportError traceback), and a start took twice as long."""

from __future__ import annotations

import subprocess
import sys

_STEPS = """
import sys

def loaded(step):
    print("LOADED", step, *(m for m in ("cv2", "scipy.signal", "lidarkit.vo.pipeline") if m in sys.modules), sep="|")

import lidarkit.cli
loaded("import")
for argv in (["version"], ["odometry", "--help"], ["vo", "--help"]):
    try:
        lidarkit.cli.main(argv)
    except SystemExit:
        pass
    loaded(" ".join(argv))
"""


def test_the_cli_and_its_light_commands_import_no_opencv():
    """`import lidarkit.cli` (which reads lidarkit.vo.config for the vo options' defaults), `lidarkit version`,
    `lidarkit odometry --help` and `lidarkit vo --help` load neither cv2 nor scipy.signal nor the VO pipeline."""
    done = subprocess.run([sys.executable, "-c", _STEPS], capture_output=True, text=True, timeout=120)
    steps = [line.removeprefix("LOADED|") for line in done.stdout.splitlines() if line.startswith("LOADED|")]
    assert steps == ["import", "version", "odometry --help", "vo --help"], done.stderr


def test_the_vo_package_still_gives_every_public_name():
    """The package loads its names on first use: `from lidarkit.vo import MonoVO` is the pipeline's class, a submodule
    is an attribute, dir() and __all__ list every name, and an unknown one is an AttributeError naming it."""
    import lidarkit.vo as vo
    from lidarkit.vo import MonoVO, preset
    from lidarkit.vo.pipeline import MonoVO as defined

    assert MonoVO is defined and preset("lidarkit").features.detector
    assert vo.two_view.estimate_two_view is vo.estimate_two_view  # (a submodule as an attribute, as before)
    assert set(vo.__all__) <= set(dir(vo)) and len(vo.__all__) == 27
    assert all(getattr(vo, name) is not None for name in vo.__all__)
    try:
        vo.NoSuchThing  # noqa: B018
    except AttributeError as err:
        assert str(err) == "module 'lidarkit.vo' has no attribute 'NoSuchThing'"
    else:
        raise AssertionError("an unknown name was given")


_UNDER_LIMIT = """
import resource, sys
import lidarkit.cli
vm = next(int(l.split()[1]) * 1024 for l in open("/proc/self/status") if l.startswith("VmSize:"))
resource.setrlimit(resource.RLIMIT_AS, (vm + 30 * 2**20, resource.getrlimit(resource.RLIMIT_AS)[1]))
lidarkit.cli.main(sys.argv[1:])
"""


def test_a_library_that_cannot_be_mapped_under_ulimit_v_is_one_line(tmp_path):
    """`lidarkit vo` under a `ulimit -v` that leaves no room for OpenCV ended in a 40-line traceback ("cv2.abi3.so:
    failed to map segment from shared object"): one line naming the command, exit code 1."""
    from lidarkit.samples import sample_path

    done = subprocess.run([sys.executable, "-c", _UNDER_LIMIT, "vo", str(sample_path("kitti_vo") / "06"), "--out",
                           str(tmp_path / "run"), "--no-progress"], capture_output=True, text=True, timeout=120)
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 1, done.stderr
    assert len(lines) == 1 and lines[0].startswith("error: lidarkit vo: out of memory"), done.stderr
