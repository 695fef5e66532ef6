"""``policy_node`` as a real process for the policy tests, built on conftest's SimProcess.

Same life cycle as a sim_node process (log files, ``stop`` with a signal and an
exit-code check on leaving the ``with`` block), another module to run.
"""
from __future__ import annotations

import sys
from typing import Dict, List

from test.ros.conftest import SimProcess, format_param


def policy_argv(params: Dict[str, object]) -> List[str]:
    argv = [sys.executable, "-m", "vmas_ros.ros.policy_node", "--ros-args"]
    for name, value in params.items():
        argv += ["-p", f"{name}:={format_param(value)}"]
    return argv


class PolicyProcess(SimProcess):
    """One ``policy_node`` process (stdout/stderr in ``log_dir``)."""

    @staticmethod
    def argv(params: Dict[str, object]) -> List[str]:
        return policy_argv(params)

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
