"""The HTML report opened in headless Chromium: every image decodes, no console error, every table present;
a screenshot is written beside the report (report.png)."""

from __future__ import annotations

import html
import json
import os
import re
import shutil
import signal
import subprocess
import textwrap
from pathlib import Path

import pytest

from lidarkit.bench.report import build_report
from lidarkit.bench.runner import run_suite
from lidarkit.bench.suite import load_suite

SUITE = """
name: browser-check
seeds: 2
experiments:
  - name: walk
    task: selftest
    dataset: {kind: synthetic, name: synth}
    methods:
      - {name: random_walk, params: {steps: 30}}
      - {name: random_walk, params: {steps: 30, noise_m: 0.1}}
  - name: sim
    task: odometry
    seeds: [0]
    dataset: {kind: sim_lidar, scene: street, n_frames: 6, n_beams: 16, n_azimuths: 400, name: sim street}
    methods:
      - {name: vanilla, params: {voxel_size_m: 0.5}}
      - kiss
"""

# Injected at the top of <head> in a copy of the page: records errors and console.error calls, and after the load
# event writes what it found into the DOM, which --dump-dom prints.
PROBE = """<script>
window.__lk = {errors: []};
window.addEventListener("error", function (e) {
  var t = e.target && e.target !== window ? (e.target.tagName + " failed to load") : String(e.message);
  window.__lk.errors.push(t);
}, true);
(function () { var ce = console.error; console.error = function () {
  window.__lk.errors.push(Array.prototype.join.call(arguments, " ")); ce.apply(console, arguments); }; })();
window.addEventListener("load", function () {
  var imgs = Array.prototype.map.call(document.images, function (i) {
    return {alt: i.alt, complete: i.complete, w: i.naturalWidth, h: i.naturalHeight}; });
  var tables = Array.prototype.map.call(document.querySelectorAll("table"), function (t) {
    return {rows: t.rows.length, caption: t.caption ? t.caption.textContent : ""}; });
  var pre = document.createElement("pre"); pre.id = "lk-probe";
  pre.textContent = JSON.stringify({imgs: imgs, tables: tables, errors: window.__lk.errors,
                                    sections: document.querySelectorAll("section").length});
  document.body.appendChild(pre);
});
</script>"""


def chromium() -> str:
    for candidate in (os.environ.get("LIDARKIT_CHROMIUM"), "chromium", "chromium-browser", "google-chrome"):
        if candidate and shutil.which(candidate):
            return shutil.which(candidate)
    pytest.fail("headless Chromium is missing: `make test` installs it (scripts/ensure_system_deps.sh); "
                "or: sudo apt-get install chromium")


def run_chromium(args: list[str], profile: Path, timeout_s: float = 120.0) -> subprocess.CompletedProcess:
    cmd = [chromium(), "--headless", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage", "--no-first-run",
           "--disable-extensions", "--hide-scrollbars", f"--user-data-dir={profile}", *args]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        out, err = proc.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        pytest.fail(f"chromium did not finish in {timeout_s} s")
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    return subprocess.CompletedProcess(cmd, proc.returncode, out, err)


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    root = tmp_path_factory.mktemp("browser")
    (root / "suite.yaml").write_text(textwrap.dedent(SUITE))
    summary = run_suite(load_suite(root / "suite.yaml"), root / "out", executor="serial")
    assert summary.failed == 0 and summary.ok == 6
    return build_report(root / "out")


def test_report_page_in_headless_chromium(report, tmp_path):
    page = report.html_path.read_text(encoding="utf-8")
    n_tables, n_images = page.count("<table"), page.count("<img ")
    assert n_tables >= 6 and n_images >= 5
    # layout: summary first, then one section per task; method names without the experiment prefix in pivots
    assert page.index('id="summary"') < page.index('id="task-odometry"') and 'id="task-selftest"' in page
    assert "<figcaption>" in page and "walk: random_walk" not in page
    probe_page = report.html_path.with_name("report_probe.html")
    probe_page.write_text(page.replace("<head>", "<head>\n" + PROBE, 1), encoding="utf-8")
    try:
        done = run_chromium(["--virtual-time-budget=10000", "--dump-dom", probe_page.as_uri()], tmp_path / "profile")
    finally:
        probe_page.unlink()
    match = re.search(r'<pre id="lk-probe">(.*?)</pre>', done.stdout, re.S)
    assert match, f"no probe output; chromium exit {done.returncode}: {done.stderr[-2000:]}"
    found = json.loads(html.unescape(match.group(1)))
    assert found["errors"] == []
    assert len(found["imgs"]) == n_images
    bad = [i for i in found["imgs"] if not (i["complete"] and i["w"] > 0 and i["h"] > 0)]
    assert not bad, bad
    assert len(found["tables"]) == n_tables and all(t["rows"] >= 2 for t in found["tables"])
    assert found["sections"] == 3  # summary + selftest + odometry
    shot = report.html_path.with_name("report.png")
    run_chromium([f"--screenshot={shot}", "--window-size=1280,2600", report.html_path.as_uri()], tmp_path / "profile2")
    assert shot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and shot.stat().st_size > 20_000
