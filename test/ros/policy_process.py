"""``policy_node`` as a real process for the policy tests, built on conftest's SimProcess.

Same life cycle as a sim_node process (log files, ``stop`` with a signal and an
exit-code check on leaving the ``with`` block), another module to run.
"""
from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path
from typing import Dict, List, Optional

from test.ros.conftest import REPO, Ros, SimProcess, format_param, sim_env


def policy_argv(params: Dict[str, object]) -> List[str]:
    argv = [sys.executable, "-m", "vmas_ros.ros.policy_node", "--ros-args"]
    for name, value in params.items():
        argv += ["-p", f"{name}:={format_param(value)}"]
    return argv


class PolicyProcess(SimProcess):
    """One ``policy_node`` process (stdout/stderr in ``log_dir``)."""

    def __init__(self, ros: Optional[Ros], params: Dict[str, object], log_dir: Path, label: str) -> None:
        self.ros, self.params = ros, dict(params)
        log_dir.mkdir(parents=True, exist_ok=True)
        self.stdout_path = log_dir / f"{label}.stdout.log"
        self.stderr_path = log_dir / f"{label}.stderr.log"
        self._stdout = open(self.stdout_path, "wb")
        self._stderr = open(self.stderr_path, "wb")
        self.started = time.monotonic()
        self.proc = subprocess.Popen(
            policy_argv(self.params), cwd=REPO, env=sim_env(),
            stdin=subprocess.DEVNULL, stdout=self._stdout, stderr=self._stderr,
        )
        self.returncode: Optional[int] = None

    def describe(self) -> str:
        return "policy_node" + super().describe().removeprefix("sim_node")

    def wait_publishing(self, topics: List[str], timeout: float = 20.0) -> None:
        """Until every topic in ``topics`` has this node as a publisher."""
        def ready():
            if not self.alive():
                raise AssertionError(f"policy_node exited during start-up: {self.describe()}")
            return all(self.ros.node.count_publishers(t) > 0 for t in topics)

        self.ros.spin_until(ready, timeout, f"policy_node publishing {topics}")

    def _wait_gone(self, timeout: float = 10.0) -> None:
        return  # the graph check of SimProcess watches sim_node's /clock, which outlives this node
