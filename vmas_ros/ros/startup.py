"""Console-script entries of ``sim_node`` and ``policy_node``: the signal guard first, then the node.

Each entry installs :func:`vmas_ros.ros.signal_guard.guard` before it imports
its node (torch, rclpy, the engine), so a signal during those imports ends the
process cleanly (see :mod:`vmas_ros.ros.signal_guard`). The nodes themselves
never import this module: it is only the programs' way in.
"""
from __future__ import annotations

from vmas_ros.ros.signal_guard import guard

__all__ = ["policy_node_main", "sim_node_main"]


def sim_node_main() -> int:
    """Console-script entry of ``sim_node``: the guard first, then the heavy imports."""
    guard("sim_node")
    from vmas_ros.ros.sim_node import main

    return main()


def policy_node_main() -> int:
    """Console-script entry of ``policy_node``: the guard first, then the heavy imports."""
    guard("policy_node")
    from vmas_ros.ros.policy_node import main

    return main()
