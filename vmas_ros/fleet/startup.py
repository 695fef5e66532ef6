"""Console-script entry of ``robot_fleet``: the signal guard first, then rclpy and the fleet node.

Like sim_node's entry (:mod:`vmas_ros.ros.startup`), it installs
:func:`vmas_ros.ros.signal_guard.guard` before the imports, so a signal during
them ends the process cleanly. The fleet imports no torch.
"""
from __future__ import annotations

from vmas_ros.ros.signal_guard import guard

__all__ = ["fleet_main"]


def fleet_main() -> int:
    """Console-script entry of ``robot_fleet``: the guard first, then rclpy (the fleet imports no torch)."""
    guard("robot_fleet")
    from vmas_ros.fleet.node import main

    return main()
