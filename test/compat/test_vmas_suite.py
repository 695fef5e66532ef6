"""VMAS 1.5.2's own tests (the part its source distribution carries) pass on vmas_ros.

``test/compat/vmas_suite.py`` downloads VMAS's sdist from the package index
(cached), unpacks its ``tests/test_vmas.py`` and ``tests/test_lidar.py``, and
runs them with ``vmas`` resolving to vmas_ros. Its repository-only tests
(``test_scenarios/``, ``test_wrappers/``) need a local clone: run
``python -m test.compat.vmas_suite --repo GIT_DIR`` by hand.
"""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from test.compat.vmas_suite import summary

ROOT = Path(__file__).resolve().parents[2]


def test_summary_reads_pytest_closing_line():
    assert summary("..\n3 failed, 10 passed, 2 skipped in 1.0s\n") == {
        "passed": 10, "failed": 3, "skipped": 2, "errors": 0,
    }
    assert summary("1 error in 0.5s")["errors"] == 1


def test_vmas_sdist_tests_pass_on_vmas_ros():
    run = subprocess.run(
        [sys.executable, "-m", "test.compat.vmas_suite"], cwd=ROOT, capture_output=True, text=True, timeout=900,
    )
    last = run.stdout.strip().splitlines()[-1] if run.stdout.strip() else ""
    assert run.returncode == 0, run.stdout[-6000:] + run.stderr[-3000:]
    counts = summary(run.stdout)
    assert last.startswith("vmas suite on vmas_ros:") and counts["failed"] == counts["errors"] == 0
    assert counts["passed"] >= 340, last  # all 41 scenarios through each of test_vmas.py's checks
