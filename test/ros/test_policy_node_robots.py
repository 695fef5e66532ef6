"""policy_node as a robot base's driver: body-frame TwistStamped commands, and no command on bad data.

The test node plays the robots: it publishes their odometry (REP 105: pose
in ``odom``, twist in the body frame) and the landmarks, and listens to their
``cmd_vel`` as Jazzy's diff_drive_controller would (TwistStamped only). One
robot is healthy and faces +y, one sends a NaN pose, one never appears. Only
the healthy one may get commands, rotated into its own frame; the others are
named in warnings with what is wrong, and so is the healthy one once its
odometry stops. A LaserScan whose geometry cannot be resampled to the
training lidar stops its robot alone, with the reason.
"""
from __future__ import annotations

import math
import time

import numpy as np
import pytest
from geometry_msgs.msg import Pose, PoseArray, PoseStamped, TwistStamped
from nav_msgs.msg import Odometry
from sensor_msgs.msg import LaserScan

from test.ros.conftest import killed_at_end
from test.ros.policy_files import constant_push
from test.ros.policy_process import PolicyProcess
from vmas_ros.ros.convert import fill_odometry

# serial: its nodes must answer within fixed times, and once, on two busy workers, policy_node sent no
# command in 20 s; alone on the machine it has not failed
pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.serial]

AGENTS = ["agent_0", "agent_1", "agent_2"]
PUSH = (0.5, 0.2)  # the policy's world-frame action for every agent, whatever it sees
HEADING = math.pi / 2  # agent_0 faces +y
#: simple_spread without the other agents in the observation (4 + 2 x 3 landmarks): each robot's row
#: then needs its own odometry only, so one robot's bad data cannot hide another's
OWN_VIEW = {"obs_agents": False}
OBS_SIZE = 10


@pytest.fixture(scope="module")
def policy_node(ros, sim_log_dir):
    yield from killed_at_end(lambda index, **params: PolicyProcess(ros, params, sim_log_dir, f"robots_{index}"))


def odometry(x: float, y: float, yaw: float) -> Odometry:
    msg = Odometry()
    msg.header.frame_id, msg.child_frame_id = "odom", "agent/base_link"
    fill_odometry(msg, x, y, yaw, 0.0, 0.0, 0.0)
    return msg


def landmarks() -> PoseArray:
    array = PoseArray()
    array.header.frame_id = "odom"
    array.poses = [Pose() for _ in range(3)]
    return array


def test_stamped_body_frame_commands_and_no_command_on_bad_data(ros, policy_node, tmp_path):
    policy = constant_push(tmp_path, "push", PUSH, obs_size=OBS_SIZE)
    commands = {a: ros.collect(TwistStamped, f"/{a}/cmd_vel") for a in AGENTS}
    odom_pubs = {a: ros.node.create_publisher(Odometry, f"/{a}/odom", 10) for a in AGENTS[:2]}
    landmark_pub = ros.node.create_publisher(PoseArray, "/landmarks/poses", 10)
    good, broken = odometry(0.3, -0.2, HEADING), odometry(float("nan"), 0.0, 0.0)

    def feed(seconds: float, healthy: bool = True, until=lambda: False) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end and not until():
            if healthy:
                odom_pubs["agent_0"].publish(good)
            odom_pubs["agent_1"].publish(broken)
            ros.spin_for(0.05)

    with policy_node(policy_path=str(policy), adapter="vmas_ros.ros.adapters:SimpleSpreadAdapter",
                     adapter_kwargs=OWN_VIEW, output="cmd_vel", use_stamped_cmd_vel=True, rate_hz=20.0,
                     observation_timeout=0.5) as node:
        node.wait_publishing([f"/{a}/cmd_vel" for a in AGENTS])
        # the landmarks come at the start only, as from a planner: they stand however old they get (the
        # adapter's standing topic), while the odometry must stay fresh; a few copies, as discovery may
        # still be matching the two ends when the first goes out
        ros.spin_until(lambda: landmark_pub.get_subscription_count() > 0, 20.0, "policy_node's subscription")
        for _ in range(3):
            landmark_pub.publish(landmarks())
            ros.spin_for(0.1)
        feed(20.0, until=lambda: len(commands["agent_0"]) >= 5)
        assert len(commands["agent_0"]) >= 5, node.describe()
        feed(3.0)
        msg = commands["agent_0"].latest
        # the world-frame push (0.5, 0.2), seen from a robot facing +y: (0.2 ahead, 0.5 to the right)
        assert (msg.twist.linear.x, msg.twist.linear.y, msg.twist.angular.z) == pytest.approx((0.2, -0.5, 0.0),
                                                                                              abs=1e-6)
        assert msg.header.frame_id == "agent_0/base_link"
        assert abs(msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9 - time.time()) < 5.0
        assert len(commands["agent_1"]) == 0 and len(commands["agent_2"]) == 0
        # agent_0's odometry stops: its commands stop within the timeout (plus one tick)
        feed(1.0, healthy=False)
        stopped_at = time.monotonic() - 1.0
        late = [t for t in commands["agent_0"].arrivals if t > stopped_at + 0.5 + 0.15]
        assert late == [], f"{len(late)} commands came after agent_0's odometry went stale"
        feed(2.5, healthy=False)
    log = node.output()
    assert "no command for agent_1: odometry on agent_1/odom: NaN pose" in log, log
    assert "no command for agent_2: nothing received on agent_2/odom yet (0 publishers)" in log, log
    assert "no command for agent_0: agent_0/odom is older than observation_timeout (0.5 s)" in log, log
    assert "geometry_msgs/TwistStamped on <agent>/cmd_vel" in log and "rotated into each robot's body frame" in log
    for a in AGENTS:
        commands[a].destroy()


def test_a_diff_drive_base_gets_only_linear_x_and_angular_z(ros, policy_node, tmp_path):
    """A world-frame push on a diff-drive base: no sideways command; the turn says where the push points."""
    policy = constant_push(tmp_path, "push_dd", (0.0, 0.3), obs_size=OBS_SIZE)
    commands = ros.collect(TwistStamped, "/agent_0/cmd_vel")
    odom_pub = ros.node.create_publisher(Odometry, "/agent_0/odom", 10)
    landmark_pub = ros.node.create_publisher(PoseArray, "/landmarks/poses", 10)
    with policy_node(policy_path=str(policy), adapter="vmas_ros.ros.adapters:SimpleSpreadAdapter",
                     adapter_kwargs=OWN_VIEW, output="cmd_vel", use_stamped_cmd_vel=True,
                     base="diff_drive", lookahead=0.2, max_angular_speed=1.0, rate_hz=20.0) as node:
        node.wait_publishing(["/agent_0/cmd_vel"])
        end = time.monotonic() + 20.0
        while len(commands) < 5 and time.monotonic() < end:
            odom_pub.publish(odometry(0.0, 0.0, 0.0))
            landmark_pub.publish(landmarks())
            ros.spin_for(0.05)
    twists = np.array([[m.twist.linear.x, m.twist.linear.y, m.twist.angular.z] for m in commands.messages])
    assert len(twists) >= 5, node.describe()
    # facing +x, a push along +y: turn left on the spot, 0.3 / 0.2 = 1.5 rad/s limited to 1.0
    np.testing.assert_allclose(twists[-1], [0.0, 0.0, 1.0], atol=1e-6)
    commands.destroy()


def laser_scan(n_rays: int, angle_min: float, angle_max: float) -> LaserScan:
    scan = LaserScan()
    scan.header.frame_id = "agent/base_link"
    scan.angle_min, scan.angle_max = angle_min, angle_max
    scan.angle_increment = (angle_max - angle_min) / (n_rays - 1)
    scan.range_min, scan.range_max = 0.12, 3.5
    scan.ranges = [math.inf] * n_rays
    return scan


def test_a_scan_that_cannot_be_resampled_stops_only_its_robot(ros, policy_node, tmp_path):
    """navigation needs rays all round: a 180-degree scanner is named, and its robot gets no command."""
    policy = constant_push(tmp_path, "push_nav", (0.5, 0.0), obs_size=18, agents=("agent_0", "agent_1"),
                           scenario="navigation", scenario_kwargs={"n_agents": 2})
    commands = {a: ros.collect(TwistStamped, f"/{a}/cmd_vel") for a in ("agent_0", "agent_1")}
    publishers = {(a, kind): ros.node.create_publisher(cls, f"/{a}/{kind}", 10)
                  for a in ("agent_0", "agent_1") for kind, cls in (("odom", Odometry), ("scan", LaserScan),
                                                                     ("goal", PoseStamped))}
    scans = {"agent_0": laser_scan(360, -math.pi, math.pi - 2 * math.pi / 360),
             "agent_1": laser_scan(181, -math.pi / 2, math.pi / 2)}
    with policy_node(policy_path=str(policy), adapter="navigation", output="cmd_vel", use_stamped_cmd_vel=True,
                     rate_hz=20.0) as node:
        node.wait_publishing(["/agent_0/cmd_vel", "/agent_1/cmd_vel"])
        end = time.monotonic() + 20.0
        warning = "no command for agent_1: agent_1/scan: scan covers [-1.57, 1.57] rad"
        while time.monotonic() < end and not (len(commands["agent_0"]) >= 5 and warning in node.output()):
            for agent in ("agent_0", "agent_1"):
                publishers[agent, "odom"].publish(odometry(0.0, 0.0, 0.0))
                publishers[agent, "scan"].publish(scans[agent])
                publishers[agent, "goal"].publish(PoseStamped())
            ros.spin_for(0.05)
    log = node.output()
    assert len(commands["agent_0"]) >= 5 and len(commands["agent_1"]) == 0, log
    assert warning in log, log
    for collector in commands.values():
        collector.destroy()
