"""``python -m test.compat.vmas_suite --on-vmas``: VMAS's own tests on VMAS itself, the suite's yardstick.

A file of its own, so that it runs beside test_vmas_suite.py on the other worker.
"""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_the_same_tests_run_on_vmas_itself():
    """``--on-vmas``: VMAS's tests on VMAS, the yardstick for the suite's time on vmas_ros. Two of them
    here: its scenario list read from the ``vmas/`` beside the tests (VMAS's own package), and its
    seeding; the rest of the suite on VMAS is timed by hand (docs/bench/default_mode.md)."""
    run = subprocess.run(
        [sys.executable, "-m", "test.compat.vmas_suite", "--on-vmas", "--", "-k",
         "test_all_scenarios_included or test_seeding"], cwd=ROOT,
        capture_output=True, text=True, timeout=900,
    )
    assert run.returncode == 0, run.stdout[-6000:] + run.stderr[-3000:]
    lines = run.stdout.strip().splitlines()
    assert lines[0].startswith("vmas suite on VMAS 1.5.2: tests/test_vmas.py, tests/test_lidar.py; VMAS's own")
    assert re.match(r"vmas suite on VMAS 1\.5\.2: 2 passed, 0 failed, \d+ skipped in \d+ s$", lines[-1])
