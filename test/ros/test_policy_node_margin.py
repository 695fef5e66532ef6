"""policy_node with the navigation adapter's ``scan_margin``: set in ``adapter_kwargs``, it reaches the commands.

The test node plays two robots facing +x: odometry, goals and scans whose
even training rays (0, 60, ... degrees) see a neighbour at 0.30 m and whose
odd ones see nothing. The policy's x action is the mean lidar proximity
(``0.35 - distance``, 0 for no return), so the command itself says what the
policy saw: 6 x 0.05 / 12 = 0.025 without a margin, 6 x 0.13 / 12 = 0.065
with 0.08 m.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped, TwistStamped
from nav_msgs.msg import Odometry
from sensor_msgs.msg import LaserScan

from test.ros.conftest import killed_at_end, wait_all
from test.ros.policy_files import write_policy
from test.ros.policy_process import PolicyProcess
from vmas_ros.ros.convert import fill_odometry

pytestmark = [pytest.mark.ros, pytest.mark.slow]

AGENTS = ("agent_0", "agent_1")
N_RAYS = 12  # navigation with 2 agents and an 18-value observation: 6 values, then 12 lidar rays


@pytest.fixture(scope="module")
def policy_node(ros, sim_log_dir):
    yield from killed_at_end(lambda index, **params: PolicyProcess(ros, params, sim_log_dir, f"margin_{index}"))


def mean_proximity_policy(directory):
    """x action = the mean of the 12 lidar proximities; y action 0."""
    weight = np.zeros((6 + N_RAYS, 2))
    weight[6:, 0] = 1.0 / N_RAYS
    return write_policy(directory, "proximity", weight, [0.0, 0.0], agents=AGENTS, scenario="navigation",
                        scenario_kwargs={"n_agents": 2})


def half_seen_scan() -> LaserScan:
    scan = LaserScan()
    scan.header.frame_id = "agent/base_link"
    scan.angle_min, scan.angle_increment = -math.pi, 2 * math.pi / 360
    scan.angle_max = math.pi - scan.angle_increment
    scan.range_min, scan.range_max = 0.12, 3.5
    ranges = np.full(360, math.inf)
    ranges[(180 + 60 * np.arange(6)) % 360] = 0.30  # training rays 0, 2, ..., 10
    scan.ranges = ranges.tolist()
    return scan


def feed_until(ros, until, timeout: float = 20.0) -> None:
    """Odometry, goals and scans of both robots every 0.05 s until ``until()``."""
    pubs = {(a, kind): ros.node.create_publisher(cls, f"/{a}/{kind}", 10)
            for a in AGENTS for kind, cls in (("odom", Odometry), ("scan", LaserScan), ("goal", PoseStamped))}
    odom = Odometry()
    odom.header.frame_id, odom.child_frame_id = "odom", "agent/base_link"
    fill_odometry(odom, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    scan = half_seen_scan()

    def publish_and_check():
        for a in AGENTS:
            pubs[a, "odom"].publish(odom)
            pubs[a, "scan"].publish(scan)
            pubs[a, "goal"].publish(PoseStamped())
        ros.spin_for(0.05)
        return until()

    try:
        ros.spin_until(publish_and_check, timeout, "policy_node's commands")
    finally:
        for pub in pubs.values():
            ros.node.destroy_publisher(pub)


@pytest.mark.parametrize("margin, expected", [(None, 0.025), (0.08, 0.065)])
def test_the_margin_in_adapter_kwargs_brings_what_the_policy_sees_closer(ros, policy_node, tmp_path, margin,
                                                                         expected):
    commands = {a: ros.collect(TwistStamped, f"/{a}/cmd_vel") for a in AGENTS}
    extra = {} if margin is None else {"adapter_kwargs": {"scan_margin": margin}}
    with policy_node(policy_path=str(mean_proximity_policy(tmp_path)), adapter="navigation", output="cmd_vel",
                     use_stamped_cmd_vel=True, rate_hz=20.0, **extra) as node:
        node.wait_publishing([f"/{a}/cmd_vel" for a in AGENTS])
        feed_until(ros, lambda: all(len(c) >= 5 for c in commands.values()))
        for a in AGENTS:
            xs = [m.twist.linear.x for m in commands[a].messages]
            np.testing.assert_allclose(xs, expected, atol=1e-5, err_msg=f"{a}\n{node.describe()}")
        if margin is not None:
            assert f"adapter_kwargs {{'scan_margin': {margin}}}" in node.output(), node.describe()
    assert node.returncode == 0, node.describe()
    for collector in commands.values():
        collector.destroy()


@pytest.mark.parametrize("margin, problem", [
    (-0.05, "scan_margin must be >= 0 m and below the training lidar's range 0.35 m, got -0.05"),
    (".nan", "scan_margin must be a finite number of metres, got nan"),
])
def test_a_margin_that_is_no_distance_is_refused_at_start(policy_node, tmp_path, margin, problem):
    process = policy_node(policy_path=str(mean_proximity_policy(tmp_path)), adapter="navigation",
                          adapter_kwargs=f"{{scan_margin: {margin}}}")
    code, = wait_all([process], timeout=60.0)
    stderr = process.stderr()
    assert code == 2, process.describe()
    assert f"adapter: adapter 'navigation' refused its arguments: {problem}" in stderr, stderr
    assert "Traceback" not in stderr, stderr
