"""Assertions and pytest fixtures for users' own test suites: hold a variant to a trajectory or a pinned baseline.

>>> from lidarkit.testing import assert_no_worse_than
>>> assert_no_worse_than(result, "tests/baselines/kiss_sim", metric="drift_translation_pct", method="kiss")

The pytest plugin (entry point ``lidarkit`` in ``pytest11``, loaded automatically once lidarkit is installed)
adds the ``lidarkit_baseline`` and ``load_lidarkit_baseline`` fixtures and the ``--lidarkit-baseline`` option; see
docs/regression.md. Outside a fixture, ``load_baseline(path)`` reads a baseline folder.
"""

from typing import Any

from lidarkit.testing.assertions import assert_no_worse_than, assert_trajectory_close, metrics_of


def __getattr__(name: str) -> Any:
    """``load_baseline`` (:func:`lidarkit.bench.baseline.load_baseline`) on first use: the plugin imports this package
    in every pytest run, and the bench modules behind it take most of a second to import."""
    if name == "load_baseline":
        from lidarkit.bench.baseline import load_baseline

        return load_baseline
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    """The names loaded on first use too (tab completion offered no ``load_baseline``), without loading them."""
    return sorted(set(globals()) | set(__all__))


__all__ = ["assert_no_worse_than", "assert_trajectory_close", "load_baseline", "metrics_of"]
