"""``lidarkit bench kitti --data ROOT``: the bundled KITTI suite (sequences 00-10 x strong variants) and its
KISS-ICP-paper table (drift per sequence with the devkit average row).

The bundled ``suites/kitti.yaml`` names the sequences and methods; the datasets are the sequences present under
``ROOT/sequences/NN`` with ground truth (``ROOT/poses/NN.txt`` or ``sequences/NN/poses.txt``). The resolved suite
is written beside the results (``OUT/kitti_suite.yaml``) so the run is resumable and reproducible.
"""

from __future__ import annotations

import dataclasses
import logging
import os
from collections import Counter
from collections.abc import Sequence
from pathlib import Path

import yaml

from lidarkit import atomic
from lidarkit.bench.suite import Suite, load_suite
from lidarkit.errors import DataError

log = logging.getLogger(__name__)

KITTI_SUITE = Path(__file__).resolve().parent / "suites" / "kitti.yaml"


def sequence_name(seq: str) -> str:
    """A KITTI sequence as its folder is named: a number in two digits at least (``0`` is ``00``, as a suite's
    ``sequence: 0`` and a baseline read it: ``--sequences 0`` found no folder ``sequences/0``); other names as given."""
    seq = str(seq).strip()
    return f"{int(seq):02d}" if seq.isdigit() else seq


def kitti_sequences(root: str | os.PathLike, wanted: Sequence[str]) -> list[str]:
    """The sequences of ``wanted`` (:func:`sequence_name`: ``0`` is ``00``) that ``root`` holds with scans and ground
    truth, by their folder names (DataError when none)."""
    root = Path(root)
    seq_dir = root / "sequences"
    if not seq_dir.is_dir():
        raise DataError("not a KITTI odometry root (no sequences/ folder)", source=root)
    wanted = [sequence_name(seq) for seq in wanted]
    found = []
    for seq in wanted:
        folder = seq_dir / seq
        has_gt = (root / "poses" / f"{seq}.txt").is_file() or (folder / "poses.txt").is_file()
        if (folder / "velodyne").is_dir() and has_gt:
            found.append(seq)
    if not found:  # (--sequences 0x read as a sequence without scans: the root's own sequences named)
        held = sorted(p.name for p in seq_dir.iterdir() if p.is_dir() and (p / "velodyne").is_dir())
        missing = [seq for seq in wanted if not (seq_dir / seq).is_dir()]
        raise DataError(f"none of the sequences {', '.join(wanted)} has velodyne/ scans and ground-truth poses"
                        + (f" (no folder {', '.join(missing)})" if missing else "")
                        + f"; with scans: {', '.join(held) or 'none'}", source=seq_dir)
    return found


def kitti_suite(
    root: str | os.PathLike,
    out_dir: str | os.PathLike | None,
    *,
    methods: Sequence[str] | None = None,
    sequences: Sequence[str] | None = None,
    suite_path: str | os.PathLike = KITTI_SUITE,
) -> Suite:
    """The bundled KITTI suite over ``root``'s sequences, written to ``out_dir/kitti_suite.yaml`` and loaded
    (``out_dir=None``: validated in a temporary folder, nothing written, e.g. for a dry run).

    Sequences asked for by name that ``root`` lacks are a DataError; of the suite's default list, those missing are
    left out with a warning. Unknown ``methods`` are a ConfigError naming the known ones."""
    import tempfile

    from lidarkit.errors import ConfigError
    from lidarkit.registration import available_icp

    sequences = [sequence_name(seq) for seq in sequences or ()]  # (--sequences 0 is 00, as the baseline reads it)
    _refuse_repeats(sequences, "--sequences")
    _refuse_repeats(methods or (), "--methods")
    root = Path(root).expanduser().resolve()
    spec = yaml.safe_load(Path(suite_path).read_text(encoding="utf-8"))
    wanted = sequences or [sequence_name(s) for s in spec.pop("sequences")]
    spec.pop("sequences", None)
    present = kitti_sequences(root, wanted)
    missing = [seq for seq in wanted if seq not in present]
    if missing and sequences:
        raise DataError(f"no velodyne/ scans with ground-truth poses for sequence(s) {', '.join(missing)} "
                        f"(found: {', '.join(present)})", source=root / "sequences")
    if missing:
        log.warning("%s: sequences %s have no velodyne/ scans with ground-truth poses: left out", root, ", ".join(missing))
    unknown = [m for m in methods or () if m not in available_icp()]
    if unknown:
        raise ConfigError(f"unknown method(s) {', '.join(unknown)}; known: {', '.join(available_icp())}", source="--methods")
    experiment = spec["experiments"][0]
    if methods:
        experiment["methods"] = list(methods)
    experiment["datasets"] = [{"kind": "kitti", "path": str(root / "sequences" / seq), "name": seq} for seq in present]
    text = yaml.safe_dump(spec, sort_keys=False)
    with tempfile.TemporaryDirectory() as scratch:  # validated before anything is written where the user looks
        suite = load_suite(atomic.write_text(Path(scratch) / "kitti_suite.yaml", text))
    if out_dir is not None:
        path = atomic.write_text(Path(out_dir) / "kitti_suite.yaml", text)
        suite = dataclasses.replace(suite, path=path)
    return suite


def _refuse_repeats(values: Sequence[str], option: str) -> None:
    """A name given twice is a ConfigError naming the option (it was the generated suite's "duplicate dataset" in a
    temporary file already deleted)."""
    from lidarkit.errors import ConfigError

    counts = Counter(values)
    repeated = [f"{v} given " + ("twice" if n == 2 else f"{n} times") for v, n in counts.items() if n > 1]
    if repeated:
        raise ConfigError(", ".join(repeated), source=option)


def paper_table(report) -> str:
    """The KISS-ICP-paper table (translational drift per sequence + devkit average row) in Markdown, or ''."""
    pub = getattr(report, "publication", None)
    if pub is None:
        return ""
    for table in pub.tables:
        if table.name == "kitti_translation_pct":
            return table.to_markdown()
    return ""


__all__ = ["KITTI_SUITE", "kitti_sequences", "kitti_suite", "paper_table", "sequence_name"]
