"""Every Python example of README.md and docs/*.md runs as written.

Each page runs in its own process (registries, working folder and imports start clean), its blocks in order in one
namespace, as a reader pastes them one after another. What the prose leaves to the reader is supplied, and said
here: the names a page takes as given (``source_xyz``, ``guess``, ...), the placeholder files the examples open
(``poses/00.txt``, ``run.bag``, ...) and ``../shared`` where the repository's neighbour is meant.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.slow  # some pages run whole sequences (300 simulated sweeps, a KITTI image sequence)

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
PAGES = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
_FENCE = re.compile(r"^```python[ \t]*\n(.*?)^```", re.MULTILINE | re.DOTALL)

#: Blocks left out, by page and first line: they need what only a longer job makes.
NOT_RUN = {
    ("docs/regression.md", "from lidarkit.eval import compare, summarize"): "needs a bench results folder (lidarkit bench my_suite.yaml --out results/seeds)",
}

#: Text replaced before a page runs: a user's name for something -> the one the fixtures write.
REPLACE = {
    "docs/recordings.md": {'topic="/velodyne_points"': 'topic="/points"'},  # the simulator's bags carry /points
}

#: Names a page uses without defining them (the prose says what they are).
GIVEN = """
import numpy as np
from lidarkit.io.pointfile import read_kitti_bin
_velodyne = {shared!r} + "/data/kitti_odometry/sequences/00/velodyne/"
source_xyz = read_kitti_bin(_velodyne + "000001.bin").points_xyz
target_xyz = read_kitti_bin(_velodyne + "000000.bin").points_xyz
points_xyz = target_xyz
guess = np.eye(4)
"""


def python_blocks(page: Path) -> list[tuple[int, str]]:
    """``(line, code)`` of each fenced Python block of ``page`` (line: where the code starts)."""
    text = page.read_text()
    return [(text.count("\n", 0, m.start(1)) + 1, m.group(1)) for m in _FENCE.finditer(text)]


def test_the_docs_have_python_examples():
    blocks = {page.name: len(python_blocks(page)) for page in PAGES}
    assert sum(blocks.values()) >= 25, blocks
    assert blocks["README.md"] >= 1 and blocks["registration.md"] >= 5


def _fixtures(folder: Path) -> None:
    """The placeholder files the examples name, written from the shared data (a run = ground truth + seeded noise)."""
    kitti = SHARED / "data" / "kitti_odometry"
    poses = np.loadtxt(kitti / "poses" / "00.txt")[:200]
    (folder / "poses").mkdir()
    np.savetxt(folder / "poses" / "00.txt", poses, fmt="%.9e")
    (folder / "sequences" / "00").mkdir(parents=True)
    times = (kitti / "sequences" / "00" / "times.txt").read_text().splitlines()[:200]
    (folder / "sequences" / "00" / "times.txt").write_text("\n".join(times) + "\n")
    noisy = poses.reshape(-1, 3, 4).copy()
    noisy[:, :, 3] += np.cumsum(np.random.default_rng(0).normal(0.0, 0.02, (len(noisy), 3)), axis=0)
    (folder / "results").mkdir()
    np.savetxt(folder / "results" / "00.txt", noisy.reshape(-1, 12), fmt="%.9e")
    (folder / "data").mkdir()
    (folder / "data" / "kitti_odometry").symlink_to(kitti)
    from lidarkit.sim.bag_export import export_bag
    from lidarkit.sim.lidar import SimulatedLidarSequence

    export_bag(SimulatedLidarSequence(scene="street", n_frames=3, n_beams=16, n_azimuths=360, seed=0), folder / "run.bag", "rosbag1")


@pytest.fixture(scope="module")
def placeholders(tmp_path_factory) -> Path:
    """A folder of _fixtures' files, written once: each page runs in a copy of it."""
    if not SHARED.is_dir():
        pytest.skip("../shared is not beside the repository")
    folder = tmp_path_factory.mktemp("placeholders")
    _fixtures(folder)
    return folder


# (guarded: a process pool's worker, e.g. estimate_focal's, imports the main script again, and ran every block)
_RUNNER = textwrap.dedent("""
    import json, sys, traceback
    if __name__ == "__main__":
        blocks = json.load(open(sys.argv[1]))
        namespace = {"__name__": "__docs__"}
        for line, code in blocks:
            try:
                exec(compile(code, f"{sys.argv[2]}:{line}", "exec"), namespace)
            except BaseException:
                print(f"FAILED at {sys.argv[2]}:{line}", file=sys.stderr)
                traceback.print_exc()
                sys.exit(1)
""")


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.relative_to(REPO).as_posix())
def test_the_examples_run(page: Path, tmp_path: Path, placeholders: Path):
    if not SHARED.is_dir():
        pytest.skip("../shared is not beside the repository")
    rel = page.relative_to(REPO).as_posix()
    blocks = [(line, code) for line, code in python_blocks(page) if (rel, code.splitlines()[0].strip()) not in NOT_RUN]
    if not blocks:
        pytest.skip(f"{rel} has no Python example to run")
    for old, new in REPLACE.get(rel, {}).items():
        assert any(old in code for _, code in blocks), f"{rel} no longer says {old!r}: update REPLACE"
        blocks = [(line, code.replace(old, new)) for line, code in blocks]
    blocks = [(line, code.replace("../shared/", f"{SHARED}/")) for line, code in blocks]
    shutil.copytree(placeholders, tmp_path, symlinks=True, dirs_exist_ok=True)  # (data/kitti_odometry: the link)
    (tmp_path / "blocks.json").write_text(json.dumps([(0, GIVEN.format(shared=str(SHARED))), *blocks]))
    (tmp_path / "run_blocks.py").write_text(_RUNNER)
    done = subprocess.run([sys.executable, "run_blocks.py", "blocks.json", rel], cwd=tmp_path, capture_output=True, text=True,
                          timeout=900, env={**os.environ, "MPLBACKEND": "Agg", "PYTHONPATH": str(REPO)})
    assert done.returncode == 0, done.stderr[-4000:]


def test_a_broken_example_is_reported_with_its_page_and_line(tmp_path: Path):
    page = tmp_path / "page.md"
    page.write_text("Intro.\n\n```python\nx = 1\n```\n\nMore.\n\n```python\nfrom lidarkit.registration import get_icp\nget_icp('nope')\n```\n")
    blocks = python_blocks(page)
    assert [line for line, _ in blocks] == [4, 10]
    (tmp_path / "blocks.json").write_text(json.dumps(blocks))
    (tmp_path / "run_blocks.py").write_text(_RUNNER)
    done = subprocess.run([sys.executable, "run_blocks.py", "blocks.json", "page.md"], cwd=tmp_path, capture_output=True, text=True,
                          timeout=300, env={**os.environ, "PYTHONPATH": str(REPO)})
    assert done.returncode == 1
    assert "FAILED at page.md:10" in done.stderr and "nope" in done.stderr
