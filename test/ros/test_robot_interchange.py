"""One policy_node command, two kinds of robots: sim_node's robot profile, then robot_fleet.

policy_node runs a navigation policy through the navigation adapter
(odometry, a 360-ray LaserScan resampled to the training lidar, a goal
PoseStamped) and sends TwistStamped body-frame commands, as to Jazzy's
diff_drive_controller. The very same parameters drive sim_node started with
config/robot_profile.yaml and robot_fleet (robots that are not the engine,
starting with headings far from +x): in both, every robot closes in on its goal.
"""
from __future__ import annotations

import numpy as np
import pytest
import yaml
from geometry_msgs.msg import PoseArray, PoseStamped, TwistStamped
from nav_msgs.msg import Odometry
from sensor_msgs.msg import LaserScan

from test.ros.conftest import REPO, killed_at_end
from test.ros.fleet_process import FleetProcess
from test.ros.policy_files import write_policy
from test.ros.policy_process import PolicyProcess

pytestmark = [pytest.mark.ros, pytest.mark.slow]

AGENTS = ["agent_0", "agent_1"]
KWARGS = {"n_agents": 2}
OBS_SIZE = 4 + 2 + 12  # position, velocity, position - goal, 12 lidar rays


@pytest.fixture(scope="module")
def processes(ros, sim_log_dir):
    def make(index: int, kind: str, **params):
        cls = {"policy": PolicyProcess, "fleet": FleetProcess}[kind]
        return cls(ros, params, sim_log_dir, f"interchange_{kind}_{index}")

    yield from killed_at_end(make)


@pytest.fixture(scope="module")
def policy_params(tmp_path_factory):
    """The one policy_node command: a force towards the own goal, damped (world-frame actions)."""
    weight = np.zeros((OBS_SIZE, 2))
    weight[4, 0] = weight[5, 1] = -1.5  # position minus goal
    weight[2, 0] = weight[3, 1] = -1.0  # own velocity
    path = write_policy(tmp_path_factory.mktemp("interchange"), "seek_goal", weight, [0.0, 0.0], agents=AGENTS,
                        scenario="navigation", scenario_kwargs=KWARGS)
    return {"policy_path": str(path), "adapter": "navigation", "output": "cmd_vel", "use_stamped_cmd_vel": True,
            "cmd_vel_scale": 0.4, "rate_hz": 10.0}


def goal_distances(ros, start=None, timeout: float = 25.0) -> tuple:
    """(first, closest) distance of each agent to its goal while it drives, from the true poses; ``first``
    from the ``start`` positions ``[n, 2]`` when given (the robots may be moving before the goals arrive)."""
    poses = ros.collect(PoseArray, "/agents/poses")
    goals = {a: ros.collect(PoseStamped, f"/{a}/goal") for a in AGENTS}
    try:
        poses.wait_for(1, timeout=10.0)
        for collector in goals.values():
            collector.wait_for(1, timeout=10.0)
        target = np.array([[g.latest.pose.position.x, g.latest.pose.position.y] for g in goals.values()])

        def distances():
            return np.linalg.norm(np.array([[p.position.x, p.position.y] for p in poses.latest.poses]) - target, axis=1)

        first = distances() if start is None else np.linalg.norm(np.asarray(start) - target, axis=1)

        def closer():
            now = distances()
            return (now,) if ((now < 0.5 * first) | (now < 0.15)).all() else None

        (closest,) = ros.spin_until(closer, timeout, "every robot to close in on its goal")
        return first, closest
    finally:
        poses.destroy()
        for collector in goals.values():
            collector.destroy()


def test_one_policy_node_command_drives_sim_node_s_robot_profile_and_robot_fleet(ros, sim_node, processes,
                                                                                  policy_params):
    profile = yaml.safe_load((REPO / "config" / "robot_profile.yaml").read_text())["sim_node"]["ros__parameters"]
    ready = {"/agent_0/odom": "nav_msgs/msg/Odometry", "/agent_0/scan": "sensor_msgs/msg/LaserScan",
             "/agent_0/goal": "geometry_msgs/msg/PoseStamped", "/agent_0/cmd_vel": "geometry_msgs/msg/TwistStamped"}
    with sim_node(ready_topics=ready, scenario="navigation", scenario_kwargs=KWARGS, control="zero", seed=3,
                  **profile):
        odom = ros.collect(Odometry, "/agent_0/odom")
        scan = ros.collect(LaserScan, "/agent_0/scan")
        odom.wait_for(1)
        scan.wait_for(1)
        assert odom.latest.header.frame_id == "odom" and len(scan.latest.ranges) == 360
        odom.destroy()
        scan.destroy()
        with processes(kind="policy", **policy_params) as node:
            node.wait_publishing([f"/{a}/cmd_vel" for a in AGENTS])
            first, closest = goal_distances(ros)
        assert (first > 0.3).any(), f"the layout starts too close to the goals to tell: {first}"

    commands = ros.collect(TwistStamped, "/agent_0/cmd_vel")
    start = {"robots": [[-0.8, 0.3, 2.0], [0.7, -0.5, -1.2]], "goals": [[0.6, 0.4], [-0.6, -0.4]]}
    with processes(kind="fleet", n_robots=2, robot_radius=0.1, start_poses=start, command_latency=0.05,
                   velocity_lag=0.1, odom_noise_position=0.005) as fleet:
        fleet.wait_fleet(AGENTS)
        with processes(kind="policy", **policy_params) as node:
            node.wait_publishing([f"/{a}/cmd_vel" for a in AGENTS])
            first, closest = goal_distances(ros, start=[row[:2] for row in start["robots"]])
    assert (first > 1.0).all() and (closest < 0.5 * first).all()
    # robot 0 faces 2 rad and its goal lies along +x: the body-frame command points well away from body x
    heading = np.arctan2(commands.messages[0].twist.linear.y, commands.messages[0].twist.linear.x)
    assert abs(heading) > 1.0, "commands were not rotated into the robot's body frame"
    commands.destroy()
