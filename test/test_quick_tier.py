"""`bash scripts/test.sh --quick`: the contributors' tier collects what docs/install.md says it runs."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_the_quick_tier_collects_the_engine_api_and_registry_tests_only():
    env = {**os.environ, "VMAS_ROS_VENV": sys.prefix}  # the venv running this test, set up already
    done = subprocess.run(["bash", "scripts/test.sh", "--quick", "--collect-only"], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    ids = [line for line in done.stdout.splitlines() if "::" in line]
    folders = {line.split("::")[0].rsplit("/", 1)[0] for line in ids}
    assert {"test/simulator", "test/envs", "test/policy", "test/scenarios"} <= folders
    assert not any(folder.startswith(("test/ros", "test/fleet", "test/train", "test/compat")) for folder in folders)
    assert not any(line.startswith("test/simulator/test_properties.py") for line in ids)
    scenario_files = {line.split("::")[0] for line in ids if line.startswith("test/scenarios")}
    assert scenario_files == {"test/scenarios/test_registry.py"}
    assert len(ids) > 500
