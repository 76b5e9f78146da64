"""``vo``: monocular visual odometry (``lidarkit.vo``) on an image sequence, scored with ``lidarkit.eval``.

Not wired yet: the VO pipeline's public entry point has not landed; ``require`` says so and the demo skips it.
"""

from __future__ import annotations

from typing import Any

from lidarkit.bench.jobs import Job
from lidarkit.bench.tasks import Metric, Task, TaskOutput
from lidarkit.errors import ConfigError


class VisualOdometryTask(Task):
    description = "monocular visual odometry (APE, RPE, final error, frames/s)"
    dataset_kinds = ("kitti", "tum")
    metrics = (
        Metric("ape_rmse_m", "APE RMSE [m]"),
        Metric("final_error_m", "final error [m]"),
        Metric("hz", "frames/s", kind="speed", better="higher"),
    )

    def require(self) -> None:
        raise ConfigError("the lidarkit.vo pipeline is not available yet", source="task")

    def validate(self, method: str, params: dict[str, Any], dataset: dict[str, Any], options: dict[str, Any]) -> None:
        self.require()

    def run(self, job: Job) -> TaskOutput:
        self.require()
        raise AssertionError("unreachable")
