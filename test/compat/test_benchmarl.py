"""BenchMARL trains on vmas_ros, unchanged, in a venv of its own.

BenchMARL 1.5 pins torchrl < 0.12, so ``scripts/setup_benchmarl.sh`` makes
``.venv-benchmarl`` (torch 2.13.0, benchmarl, vmas_ros with the gym extra).
There a MAPPO experiment on BenchMARL's own VMAS navigation task runs with
``vmas`` resolving to vmas_ros (``test/compat/benchmarl_run.py``).
"""
from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
VENV = Path(os.environ.get("VMAS_ROS_BENCHMARL_VENV", ROOT / ".venv-benchmarl"))


def test_benchmarl_mappo_trains_on_vmas_ros(tmp_path):
    setup = subprocess.run(["bash", "scripts/setup_benchmarl.sh"], cwd=ROOT, capture_output=True, text=True,
                           timeout=1200)
    assert setup.returncode == 0, setup.stdout[-3000:] + setup.stderr[-3000:]
    python = str(VENV / "bin" / "python")
    versions = subprocess.run(
        [python, "-c", "import importlib.metadata as m; print(m.version('torchrl'), m.version('torch'))"],
        capture_output=True, text=True, check=True,
    ).stdout.split()
    assert versions[0].startswith("0.11.") and versions[1].startswith("2.13.0"), versions  # beside torchrl 0.11
    run = subprocess.run([python, "-m", "test.compat.benchmarl_run", "--algorithm", "mappo", "--task", "navigation",
                          "--out", str(tmp_path), "--frames", "1200"], cwd=ROOT, capture_output=True, text=True,
                         timeout=900)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    result = json.loads(run.stdout.strip().splitlines()[-1])
    assert result["frames"] == 1200
    assert result["env_class"] == "vmas_ros.envs.environment"  # BenchMARL stepped our Environment
    assert result["checkpoints"] and all(Path(p).is_file() for p in result["checkpoints"])
