"""Shared fixtures: real data from ../shared/data, seeded random generators, temporary copies to corrupt."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = Path(os.environ.get("LIDARKIT_SHARED_DATA", REPO.parent / "shared" / "data"))


def shared_path(*parts: str) -> Path:
    """Path under ../shared/data; skips the test when the data is absent (a user's clone), fails in CI."""
    path = SHARED_DATA.joinpath(*parts)
    if not path.exists():
        if os.environ.get("CI"):
            pytest.fail(f"shared data missing in CI: {path}")
        pytest.skip(f"shared data not available: {path}")
    return path


def kiss_on_kitti_00_suite(folder: Path, frames: str) -> Path:
    """``folder/suite.yaml``: one odometry experiment, kiss on the bundled KITTI 00 scans ``frames`` (the root and
    ``sequence: "00"``, as docs/benchmarks.md writes it), dataset named K00."""
    import textwrap

    suite = folder / "suite.yaml"
    suite.write_text(textwrap.dedent(f"""
        name: kiss-kitti
        experiments:
          - task: odometry
            dataset: {{kind: kitti, path: "{shared_path('kitti_odometry')}", sequence: "00", name: K00}}
            options: {{frames: "{frames}"}}
            methods: [kiss]
    """))
    return suite


def cli_exit_code(argv: list[str]) -> int:
    """Run ``lidarkit ARGV`` in-process; its exit code (0 when it returns normally)."""
    from lidarkit.cli import main

    try:
        main(argv)
    except SystemExit as done:
        return int(done.code or 0)
    return 0


@pytest.fixture
def shared_data() -> Path:
    return shared_path()


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)


@pytest.fixture(scope="session")
def kitti_vo_frames():
    """``load("06" | "01") -> (images, K, camera ground truth)`` of ../shared KITTI image frames 0-50, each sequence
    read once per session."""
    from lidarkit.io.kitti import KittiOdometry
    from lidarkit.vo import images_in_memory

    loaded = {}

    def load(sequence: str):
        if sequence not in loaded:
            ds = KittiOdometry(shared_path("kitti_images", "sequences", sequence)).as_image_sequence()
            loaded[sequence] = (images_in_memory(ds), ds.K, ds.ground_truth)
        return loaded[sequence]

    return load


@pytest.fixture(scope="session")
def kitti_vo_run(kitti_vo_frames):
    """``run("06" | "01", preset_name, seed=None, keep_tracks=False, **changes) -> VOResult``: ``MonoVO(preset(
    preset_name, **changes), K, ground truth in scale mode gt).run(images, keep_tracks)`` on the KITTI image frames
    0-50, each distinct run done once per session (tests in several files assert on the same run: the default
    relative-scale run of 01, the gt-scale run of 06). The results are shared: read them, never change them. A run
    kept with its tracks also serves the same run asked for without them."""
    from lidarkit.vo import MonoVO, preset

    done = {}

    def run(sequence: str, preset_name: str, seed: int | None = None, keep_tracks: bool = False, **changes):
        images, K, gt = kitti_vo_frames(sequence)
        cfg = preset(preset_name, **changes, **({} if seed is None else {"seed": seed}))
        key = (sequence, cfg.model_dump_json())
        if (*key, True) in done:
            return done[(*key, True)]
        if (*key, keep_tracks) not in done:
            vo = MonoVO(cfg, K, gt if cfg.scale.mode == "gt" else None)
            done[(*key, keep_tracks)] = vo.run(images, keep_tracks=keep_tracks)
        return done[(*key, keep_tracks)]

    return run


@pytest.fixture
def seq06(kitti_vo_frames):
    """KITTI sequence 06 image frames 0-50: ``(images, K, camera ground truth)``."""
    return kitti_vo_frames("06")


@pytest.fixture
def seq01(kitti_vo_frames):
    """KITTI sequence 01 image frames 0-50: ``(images, K, camera ground truth)``."""
    return kitti_vo_frames("01")


@pytest.fixture
def copy_of(tmp_path):
    """Copy a file or folder into tmp_path so a test can corrupt it: ``copy_of(path) -> new path``."""

    def _copy(src: Path) -> Path:
        dst = tmp_path / src.name
        if src.is_dir():
            shutil.copytree(src, dst)
        else:
            shutil.copy2(src, dst)
        return dst

    return _copy
