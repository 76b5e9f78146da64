"""The package's public names: what ``dir()`` (a notebook's tab completion) offers matches what can be imported."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

_PROBE = """
import json, sys
import lidarkit
top = dir(lidarkit)
trajectory_loaded = "lidarkit.trajectory" in sys.modules
import lidarkit.testing
testing = dir(lidarkit.testing)
baseline_loaded = "lidarkit.bench.baseline" in sys.modules
print(json.dumps({"top": top, "testing": testing, "trajectory_loaded": trajectory_loaded,
                  "baseline_loaded": baseline_loaded}))
"""


def test_names_loaded_on_first_use_are_listed_by_dir_without_being_loaded():
    """``'Trajectory' in dir(lidarkit)`` and ``'load_baseline' in dir(lidarkit.testing)`` were False: both load on first
    use (module ``__getattr__``), so tab completion never offered them. Listing them must not load them (a fresh
    interpreter: this test run has imported both already)."""
    out = subprocess.run([sys.executable, "-c", _PROBE], capture_output=True, text=True, timeout=60, check=True)
    seen = json.loads(out.stdout)
    assert "Trajectory" in seen["top"] and "load_baseline" in seen["testing"]
    assert seen["top"] == sorted(seen["top"]) and seen["testing"] == sorted(seen["testing"])
    assert not seen["trajectory_loaded"] and not seen["baseline_loaded"]


@pytest.mark.parametrize("module_name", ["lidarkit", "lidarkit.testing"])
def test_every_public_name_is_in_dir_and_resolves(module_name):
    import importlib

    module = importlib.import_module(module_name)
    listed = dir(module)
    assert set(module.__all__) <= set(listed)
    assert all(getattr(module, name) is not None for name in module.__all__)
    with pytest.raises(AttributeError, match="has no attribute 'Trajectoryy'"):
        getattr(module, "Trajectoryy")
