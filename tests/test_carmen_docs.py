"""The CARMEN examples the docs quote are the messages lidarkit prints for them."""

from __future__ import annotations

from conftest import REPO, cli_exit_code, shared_path


def test_the_empty_scan_example_of_the_odometry_docs_is_what_the_intel_log_gives(capsys):
    """docs/odometry.md quoted "intel.clf:35 (frame 10) ... below the maximum range 50 m", which the Intel log never
    gives (its frame 10 is line 41, its maximum range 81.83 m): the quoted text is a real run's."""
    intel = shared_path("carmen_2d", "intel.clf.bz2")
    assert cli_exit_code(["odometry", f"carmen:{intel}?min_range_m=40", "-m", "vanilla", "-p", "planar=true",
                          "--no-progress"]) == 1
    error = capsys.readouterr().err.strip().splitlines()[-1]
    prefix = f"error: {intel.parent}/"
    assert error.startswith(prefix)
    docs = " ".join((REPO / "docs" / "odometry.md").read_text().split())
    assert "`carmen:.../intel.clf.bz2?min_range_m=40`" in docs
    assert f"`.../{error[len(prefix):]}`" in docs, error
