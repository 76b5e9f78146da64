"""Command-line interface: ``lidarkit COMMAND ...``. Commands only parse, call the library and print."""

from __future__ import annotations

import logging
import sys

from lidarkit.cli.app import app, stderr
from lidarkit.errors import LidarKitError

# Each module registers its commands on ``app`` when imported; listed here explicitly.
from lidarkit.cli import eval_cmd  # noqa: E402,F401
from lidarkit.cli import pf_cmd  # noqa: E402,F401
from lidarkit.cli import vo_cmd  # noqa: E402,F401
from lidarkit.cli import demo_cmd  # noqa: E402,F401
from lidarkit.cli import odometry_cmd  # noqa: E402,F401
from lidarkit.cli import sim_cmd  # noqa: E402,F401
from lidarkit.cli import bench_cmd  # noqa: E402,F401
from lidarkit.cli import icp_cmd  # noqa: E402,F401
from lidarkit.cli import compare_cmd  # noqa: E402,F401
from lidarkit.cli import baseline_cmd  # noqa: E402,F401

__all__ = ["app", "main"]


def main(argv: list[str] | None = None) -> None:
    """Entry point of the ``lidarkit`` console script; a LidarKitError becomes one line and exit code 1."""
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    try:
        app(args=argv, prog_name="lidarkit")
    except LidarKitError as err:
        stderr().print(f"[bold red]error:[/bold red] {err}", markup=True, soft_wrap=True)
        sys.exit(1)
