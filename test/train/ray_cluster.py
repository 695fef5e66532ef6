"""A real Ray cluster on this machine for the distributed-training tests: a head and worker raylets.

Every node is its own set of processes (``ray.cluster_utils.Cluster``), bound to
127.0.0.1 (``RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER=0``, set in test/conftest.py) with
usage reporting off. The head offers no CPUs, so every collector lands on a
worker node and a test can tell which one.
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from typing import List, Sequence

import pytest

ray = pytest.importorskip("ray", reason="distributed training needs ray: pip install -e '.[rllib]'")
from ray.cluster_utils import Cluster  # noqa: E402

#: the smallest object store Ray accepts; the tests move a few hundred kB per batch
OBJECT_STORE_BYTES = 80 * 1024 * 1024
REPO = Path(__file__).resolve().parents[2]


class LocalCluster:
    """A head (0 CPUs) and ``workers`` one-CPU worker nodes; ``stop()`` ends every process."""

    def __init__(self, workers: int = 2) -> None:
        assert os.environ.get("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER") == "0", "Ray must bind to 127.0.0.1"
        assert os.environ.get("RAY_USAGE_STATS_ENABLED") == "0", "Ray must not report usage"
        self.cluster = Cluster(initialize_head=True, head_node_args={
            "num_cpus": 0, "object_store_memory": OBJECT_STORE_BYTES, "include_dashboard": False,
            # notice a removed node within about a second (the default takes tens of seconds)
            "_system_config": {"health_check_period_ms": 200, "health_check_failure_threshold": 3}})
        self.workers: List = []
        try:
            for _ in range(workers):
                self.add_worker()
            self.cluster.wait_for_nodes()
        except BaseException:
            self.stop()
            raise

    @property
    def address(self) -> str:
        return self.cluster.address

    def add_worker(self):
        """Start one more one-CPU worker node and return it."""
        node = self.cluster.add_node(num_cpus=1, object_store_memory=OBJECT_STORE_BYTES)
        self.workers.append(node)
        return node

    def remove(self, node) -> None:
        self.cluster.remove_node(node, allow_graceful=False)
        self.workers.remove(node)

    def worker_ids(self) -> List[str]:
        return [node.node_id for node in self.workers]

    def stop(self) -> None:
        self.cluster.shutdown()


def run_cli(args: Sequence[str], timeout: float = 300) -> subprocess.CompletedProcess:
    """``vmas-ros ARGS`` in a fresh process (what a user runs on the head), output captured."""
    return subprocess.run([sys.executable, "-m", "vmas_ros.cli", *args], cwd=REPO, capture_output=True, text=True,
                          timeout=timeout)


#: a tiny PPO configuration: seconds per run, same code paths as a real one
TINY = ["--scenario", "balance", "--num-envs", "8", "--frames-per-batch", "80", "--minibatch-size", "40",
        "--epochs", "1", "--num-cells", "16", "--eval-episodes", "0", "--no-gif"]
