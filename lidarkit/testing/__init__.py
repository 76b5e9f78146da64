"""Assertions and pytest fixtures for users' own test suites: hold a variant to a trajectory or a pinned baseline.

>>> from lidarkit.testing import assert_no_worse_than
>>> assert_no_worse_than(result, "tests/baselines/kiss_sim", metric="drift_translation_pct", method="kiss")

The pytest plugin (entry point ``lidarkit`` in ``pytest11``, loaded automatically once lidarkit is installed)
adds the ``lidarkit_baseline`` fixture and the ``--lidarkit-baseline`` option; see docs/regression.md.
"""

from lidarkit.testing.assertions import assert_no_worse_than, assert_trajectory_close, metrics_of

__all__ = ["assert_no_worse_than", "assert_trajectory_close", "metrics_of"]
