"""A bench run that cannot reach its Dask scheduler leaves the results folder as it was."""

from __future__ import annotations

import logging
import textwrap

import pytest

from lidarkit.bench import executors
from lidarkit.bench.report import build_report
from lidarkit.bench.runner import run_suite
from lidarkit.bench.suite import load_suite
from lidarkit.errors import ConfigError

SUITE = """
name: {name}
seeds: {seeds}
experiments:
  - {{name: e, task: selftest, dataset: {{kind: synthetic}}, methods: [{{name: sleep, params: {{seconds: 0}}}}]}}
"""


def test_an_unreachable_scheduler_keeps_the_folders_suite_json_and_its_report(tmp_path, monkeypatch):
    """The run wrote suite.json (the new suite's jobs) before it connected: after "cannot connect" the folder's
    manifest named jobs that never ran, and a report of its finished results no longer matched them."""
    monkeypatch.setattr(executors, "CONNECT_TIMEOUT_S", 1)  # (refused at once, retried until the timeout)
    first, second = tmp_path / "first.yaml", tmp_path / "second.yaml"
    first.write_text(textwrap.dedent(SUITE.format(name="first", seeds=2)))
    second.write_text(textwrap.dedent(SUITE.format(name="second", seeds=3)))
    out = tmp_path / "out"
    assert run_suite(load_suite(first), out, executor="serial").ok == 2
    manifest = (out / "suite.json").read_bytes()
    pytest.importorskip("distributed")  # (importing it sets its loggers' levels)
    client_level = logging.getLogger("distributed.client").level
    with pytest.raises(ConfigError, match="cannot connect to the Dask scheduler"):
        run_suite(load_suite(second), out, executor="dask", address="tcp://127.0.0.1:1")
    assert (out / "suite.json").read_bytes() == manifest
    assert logging.getLogger("distributed.client").level == client_level
    report = build_report(out, plots=False)
    assert (report.n_expected, report.n_records, report.not_run) == (2, 2, [])
    assert report.markdown_path.read_text().startswith("# lidarkit benchmark report: first\n")
