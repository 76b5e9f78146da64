"""The memory a process may still get honours ``ulimit -v`` and the cgroup limit; the CLI's line for a MemoryError."""

from __future__ import annotations

import resource
import subprocess
import sys

from conftest import shared_path

import lidarkit.resources as resources


def _vm_size_bytes() -> int:
    with open("/proc/self/status", encoding="ascii") as fh:
        return next(int(line.split()[1]) * 1024 for line in fh if line.startswith("VmSize:"))


def test_the_address_space_limit_caps_the_available_memory(monkeypatch):
    """Only /proc/meminfo was read: under `ulimit -v` the estimate passed and numpy failed with a MemoryError."""
    soft = _vm_size_bytes() + 64 * 2**20
    monkeypatch.setattr(resource, "getrlimit", lambda which: (soft, resource.RLIM_INFINITY))
    assert abs(resources.available_memory_bytes() - 64 * 2**20) < 16 * 2**20
    monkeypatch.setattr(resource, "getrlimit", lambda which: (resource.RLIM_INFINITY, resource.RLIM_INFINITY))
    assert resources.available_memory_bytes() == resources._system_available_bytes()


def test_the_cgroup_limit_caps_the_available_memory(tmp_path, monkeypatch):
    monkeypatch.setattr(resources, "CGROUP_ROOT", str(tmp_path), raising=False)
    (tmp_path / "memory.max").write_text(f"{300 * 2**20}\n")
    (tmp_path / "memory.current").write_text(f"{200 * 2**20}\n")
    assert resources.available_memory_bytes() == 100 * 2**20
    (tmp_path / "memory.max").write_text("max\n")  # no limit: the machine's figure
    assert resources._cgroup_left_bytes() is None


_RUN_UNDER_LIMIT = """
import resource, sys
import lidarkit.cli, lidarkit.pf.protocol, lidarkit.resources
if sys.argv[1] == "unchecked":  # let the allocation itself fail
    lidarkit.resources.available_memory_bytes = lambda: None
vm = next(int(l.split()[1]) * 1024 for l in open("/proc/self/status") if l.startswith("VmSize:"))
resource.setrlimit(resource.RLIMIT_AS, (vm + 200 * 2**20, resource.getrlimit(resource.RLIMIT_AS)[1]))
lidarkit.cli.main(["pf", sys.argv[2], "--particles", "9000000"])
"""


def test_a_run_past_ulimit_v_is_refused_up_front_and_a_memory_error_is_one_line():
    """9,000,000 particles under `ulimit -v` printed a 60-line traceback ending in numpy's MemoryError."""
    data = str(shared_path("pf", "burgard_particle_filter"))
    checked = subprocess.run([sys.executable, "-c", _RUN_UNDER_LIMIT, "checked", data], capture_output=True, text=True,
                             timeout=120)
    assert checked.returncode == 1
    assert checked.stderr.startswith("error: --particles: a filter of 9,000,000 particles needs about 2.68 GiB of memory")
    unchecked = subprocess.run([sys.executable, "-c", _RUN_UNDER_LIMIT, "unchecked", data], capture_output=True, text=True,
                               timeout=120)
    assert unchecked.returncode == 1
    lines = unchecked.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: lidarkit pf: out of memory: "), unchecked.stderr
