"""``robot_fleet`` as a real process for the tests, with the life cycle of conftest's sim_node processes."""
from __future__ import annotations

import sys
from typing import Dict, List

from test.ros.conftest import SimProcess, format_param

NODE = "/robot_fleet"


def fleet_argv(params: Dict[str, object]) -> List[str]:
    argv = [sys.executable, "-m", "vmas_ros.fleet.node", "--ros-args"]
    for name, value in params.items():
        argv += ["-p", f"{name}:={format_param(value)}"]
    return argv


class FleetProcess(SimProcess):
    """One ``robot_fleet`` process, with the life cycle of conftest's sim_node processes."""

    @staticmethod
    def argv(params: Dict[str, object]) -> List[str]:
        return fleet_argv(params)

    def describe(self) -> str:
        return "robot_fleet" + super().describe().removeprefix("sim_node")

    def wait_fleet(self, names: List[str], stamped: bool = True, scans: bool = True) -> None:
        """Until every robot's topics and the reset service are on the graph."""
        command = "geometry_msgs/msg/TwistStamped" if stamped else "geometry_msgs/msg/Twist"
        topics = {"/agents/poses": "geometry_msgs/msg/PoseArray", "/landmarks/poses": "geometry_msgs/msg/PoseArray"}
        for name in names:
            topics[f"/{name}/odom"] = "nav_msgs/msg/Odometry"
            topics[f"/{name}/cmd_vel"] = command
            if scans:
                topics[f"/{name}/scan"] = "sensor_msgs/msg/LaserScan"
        self.wait_ready(topics, {f"{NODE}/reset": "std_srvs/srv/Trigger"})

    def wait_gone(self, timeout: float = 10.0) -> None:
        """Until the node's endpoints left the graph (the next process reuses every name)."""
        if self.ros is None:
            return
        try:
            self.ros.spin_until(lambda: f"{NODE}/reset" not in self.ros.services(), timeout,
                                "the stopped robot_fleet to leave the ROS graph")
        except AssertionError:
            pass  # the next node's discovery checks liveness too

    _wait_gone = wait_gone  # what SimProcess.stop waits with
