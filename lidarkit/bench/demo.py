"""``lidarkit demo``: the bundled suite on the bundled samples and the simulators, then the report.

Experiments whose module or bundled sample is not installed are skipped and listed, so the demo
always runs what exists. ``quick=True`` runs the reduced suite (fewer frames, seeds and variants)
that the tests use.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from lidarkit.bench.report import Report, build_report
from lidarkit.bench.runner import RunSummary, run_suite
from lidarkit.bench.suite import Suite, load_suite

SUITES_DIR = Path(__file__).resolve().parent / "suites"
DEMO_SUITE = SUITES_DIR / "demo.yaml"
DEMO_QUICK_SUITE = SUITES_DIR / "demo_quick.yaml"
DEFAULT_OUT = Path("results") / "demo"


@dataclass
class DemoResult:
    """The suite that ran, the run's counts, the report, and what was skipped (experiment, reason)."""

    suite: Suite
    summary: RunSummary
    report: Report | None
    skipped: list[tuple[str, str]] = field(default_factory=list)


def demo_suite_path(quick: bool = False) -> Path:
    return DEMO_QUICK_SUITE if quick else DEMO_SUITE


def run_demo(
    out_dir: str | Path = DEFAULT_OUT,
    *,
    quick: bool = False,
    suite_path: str | Path | None = None,
    executor: str = "process",
    workers: int | None = None,
    force: bool = False,
    runner: Callable[..., RunSummary] = run_suite,
    **runner_kwargs: Any,
) -> DemoResult:
    """Run the demo suite into ``out_dir`` (resumable like any suite) and build its report.

    ``runner`` is :func:`run_suite` or a wrapper with the same signature (the CLI adds a progress bar).
    """
    suite = load_suite(suite_path or demo_suite_path(quick), skip_unavailable=True)
    summary = runner(suite, out_dir, executor=executor, workers=workers, force=force, **runner_kwargs)
    keys = {job.key() for job in suite.jobs}
    report = build_report(out_dir, title="lidarkit demo", only_keys=keys) if suite.jobs else None
    return DemoResult(suite, summary, report, list(suite.skipped))
