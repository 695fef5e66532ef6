"""sim_node started with the robot profile, as a real ROS 2 process: what a robot fleet's topics look like.

One process, started exactly as docs/node.md says (``--params-file
config/robot_profile.yaml -p scenario:=navigation``), answers every check: the
360-ray LaserScan's geometry, odometry in ``odom``, each agent's goal, a
TwistStamped in the body frame, and ``-inf`` readings where, and only where,
another robot is closer than ``range_min``. The reference for the scan is plain
geometry: rays from the agent's centre against the other agents' discs, at the
poses published for the same step.
"""
from __future__ import annotations

import math
import time

import numpy as np
import pytest
import yaml
from geometry_msgs.msg import PoseArray, PoseStamped, TwistStamped
from nav_msgs.msg import Odometry
from sensor_msgs.msg import LaserScan

from test.ros.conftest import REPO, SimProcess, sim_argv, stamp_ns
from test.ros.sim_node_helpers import angle_between, positions, xy, yaw_of

pytestmark = [pytest.mark.ros, pytest.mark.slow]

PROFILE = REPO / "config" / "robot_profile.yaml"
SETTINGS = yaml.safe_load(PROFILE.read_text())["sim_node"]["ros__parameters"]
AGENT_RADIUS = 0.1  # navigation's default
N_AGENTS = 4
SPEED = 0.3  # m/s, below navigation's top speed (force limit over drag)
READY = {
    "/clock": "rosgraph_msgs/msg/Clock",
    "/agents/poses": "geometry_msgs/msg/PoseArray",
    "/landmarks/poses": "geometry_msgs/msg/PoseArray",
    "/agent_0/odom": "nav_msgs/msg/Odometry",
    "/agent_0/scan": "sensor_msgs/msg/LaserScan",
    "/agent_0/goal": "geometry_msgs/msg/PoseStamped",
    "/agent_0/cmd_vel": "geometry_msgs/msg/TwistStamped",
}


class ProfileProcess(SimProcess):
    """sim_node with the robot profile, then the test's ``-p`` overrides (the later wins in rcl)."""

    @staticmethod
    def argv(params):
        command = sim_argv(params)
        at = command.index("--ros-args") + 1
        return command[:at] + ["--params-file", str(PROFILE)] + command[at:]


@pytest.fixture(scope="module")
def robot(ros, sim_log_dir):
    process = ProfileProcess(ros, {"scenario": "navigation"}, sim_log_dir, "robot_profile")
    with process:
        process.wait_ready(READY)
        yield process


def _matched(*collectors, timeout: float = 10.0):
    """The latest message of each collector that all of them have for one step (stamp)."""
    def common():
        stamps = set.intersection(*({stamp_ns(m.header.stamp) for m in c.messages} for c in collectors))
        return max(stamps) if stamps else None

    stamp = collectors[0].ros.spin_until(common, timeout, "messages of one step on " +
                                         ", ".join(c.topic for c in collectors))
    return [next(m for m in reversed(c.messages) if stamp_ns(m.header.stamp) == stamp) for c in collectors]


def _expected_ranges(scan: LaserScan, origin: np.ndarray, yaw: float, others: np.ndarray):
    """Per ray: the distance from ``origin`` to the nearest other disc (inf: none within range_max), and
    whether the ray passes within 2 mm of a disc's rim (a grazing ray, too sensitive to compare)."""
    angles = yaw + scan.angle_min + scan.angle_increment * np.arange(len(scan.ranges))
    directions = np.stack([np.cos(angles), np.sin(angles)], axis=1)  # [R, 2]
    expected = np.full(len(angles), np.inf)
    grazing = np.zeros(len(angles), dtype=bool)
    for centre in others:
        relative = centre - origin
        along = directions @ relative  # [R]
        miss = np.sqrt(np.maximum(relative @ relative - along ** 2, 0.0))
        grazing |= (np.abs(miss - AGENT_RADIUS) < 2e-3) & (along > 0)
        hit = along - np.sqrt(np.maximum(AGENT_RADIUS ** 2 - miss ** 2, 0.0))
        reach = (miss < AGENT_RADIUS) & (along > 0)
        expected = np.where(reach & (hit < expected), hit, expected)
    expected[expected >= scan.range_max] = np.inf
    return expected, grazing


def _check_scan_against_poses(scan: LaserScan, poses: PoseArray, agent: int) -> int:
    """Every ray of ``scan`` against the geometry of the same step: -inf closer than range_min, the distance
    up to range_max, +inf beyond (REP 117). Returns how many rays were checked to read -inf."""
    centres = positions(poses)
    yaw = yaw_of(poses.poses[agent].orientation)
    expected, grazing = _expected_ranges(scan, centres[agent], yaw, np.delete(centres, agent, axis=0))
    published = np.array(scan.ranges, dtype=np.float64)
    near_edge = np.abs(expected - scan.range_min) < 1e-3
    compare = ~grazing & ~near_edge
    too_close = expected < scan.range_min
    assert (published[compare & too_close] == -np.inf).all(), (published, expected)
    assert (published[compare & ~too_close & np.isinf(expected)] == np.inf).all(), (published, expected)
    measured = compare & np.isfinite(expected) & ~too_close
    np.testing.assert_allclose(published[measured], expected[measured], atol=1e-3)
    assert not (published[~too_close & ~near_edge & ~grazing] == -np.inf).any(), "-inf where nothing is that close"
    finite = published[np.isfinite(published)]
    assert ((finite >= scan.range_min) & (finite < scan.range_max)).all()
    return int((compare & too_close).sum())


class TestRobotProfile:
    def test_scan_is_the_configured_lidar(self, ros, robot):
        scans = [ros.collect(LaserScan, f"/agent_{i}/scan") for i in range(N_AGENTS)]
        own = ros.collect(LaserScan, "/agent_0/scan_1")
        try:
            for i, collector in enumerate(scans):
                scan = collector.wait_for(1)[-1]
                assert scan.header.frame_id == f"agent_{i}/base_link"
                assert len(scan.ranges) == SETTINGS["lidar_rays"] == 360
                assert round((scan.angle_max - scan.angle_min) / scan.angle_increment) + 1 == 360
                assert scan.angle_min == pytest.approx(SETTINGS["lidar_angle_min"], abs=1e-6)
                assert scan.angle_max == pytest.approx(SETTINGS["lidar_angle_max"], abs=1e-6)
                assert scan.angle_increment == pytest.approx(2 * math.pi / 360, rel=1e-6)
                assert scan.range_min == pytest.approx(0.12, rel=1e-7)
                assert scan.range_max == pytest.approx(3.5, rel=1e-7)
            # navigation's own 12-ray lidar, which its observation reads, follows as scan_1
            scenario_scan = own.wait_for(1)[-1]
            assert len(scenario_scan.ranges) == 12 and scenario_scan.range_max == pytest.approx(0.35, rel=1e-6)
            assert scenario_scan.range_min == 0.0
        finally:
            for collector in (*scans, own):
                collector.destroy()

    def test_odometry_in_odom_and_goals_at_the_goal_landmarks(self, ros, robot):
        odom = ros.collect(Odometry, "/agent_0/odom")
        goals = [ros.collect(PoseStamped, f"/agent_{i}/goal") for i in range(N_AGENTS)]
        landmarks = ros.collect(PoseArray, "/landmarks/poses")
        try:
            assert odom.wait_for(1)[-1].header.frame_id == "odom"
            assert odom.latest.child_frame_id == "agent_0/base_link"
            messages = _matched(landmarks, *goals)
            array, goal_poses = messages[0], messages[1:]
            assert array.header.frame_id == "odom" and len(array.poses) == N_AGENTS
            for i, goal in enumerate(goal_poses):  # navigation's goal i is landmark i
                assert goal.header.frame_id == "odom"
                assert stamp_ns(goal.header.stamp) == stamp_ns(array.header.stamp)
                assert np.array_equal(xy(goal.pose), xy(array.poses[i])), (i, goal.pose, array.poses[i])
                assert goal.pose.orientation == array.poses[i].orientation
        finally:
            for collector in (odom, *goals, landmarks):
                collector.destroy()

    def test_twist_stamped_drives_into_a_neighbour_and_the_scan_reads_minus_inf(self, ros, robot):
        """Drive agent_0 at its nearest neighbour with TwistStamped commands in its body frame: it moves
        along the commanded direction, and once the neighbour is closer than range_min its scan says -inf
        there and nowhere else."""
        poses = ros.collect(PoseArray, "/agents/poses")
        scan = ros.collect(LaserScan, "/agent_0/scan")
        odom = ros.collect(Odometry, "/agent_0/odom")
        publisher = ros.node.create_publisher(TwistStamped, "/agent_0/cmd_vel", 10)
        try:
            before_scan, before = _matched(scan, poses)
            assert _check_scan_against_poses(before_scan, before, 0) == 0
            assert not (np.array(before_scan.ranges) == -np.inf).any(), "nothing that close at the start"
            centres = positions(before)
            distances = np.linalg.norm(centres[1:] - centres[0], axis=1)
            target = int(distances.argmin()) + 1
            assert distances.min() > 0.4, f"the neighbour must start well apart, got {distances.min():.2f} m"
            heading = yaw_of(before.poses[0].orientation)
            world_direction = math.atan2(*(centres[target] - centres[0])[::-1])
            body = world_direction - heading  # the command in the body frame (REP 103)
            command = TwistStamped()
            command.header.frame_id = "agent_0/base_link"
            command.twist.linear.x, command.twist.linear.y = SPEED * math.cos(body), SPEED * math.sin(body)
            ros.spin_until(lambda: publisher.get_subscription_count() > 0, 10, "sim_node's cmd_vel subscription")
            start = stamp_ns(before.header.stamp)
            end = time.monotonic() + 15.0

            def too_close():
                for message in scan.messages:
                    if stamp_ns(message.header.stamp) > start and -math.inf in message.ranges:
                        return message
                return None

            close = None
            while close is None and time.monotonic() < end:
                command.header.stamp = ros.node.get_clock().now().to_msg()
                publisher.publish(command)
                ros.spin_for(0.05)
                close = too_close()
            assert close is not None, "agent_0 drove at its neighbour but its scan never read -inf"
            scan_then, poses_then = close, next(m for m in poses.messages
                                                if stamp_ns(m.header.stamp) == stamp_ns(close.header.stamp))
            assert _check_scan_against_poses(scan_then, poses_then, 0) > 0
            moved = positions(poses_then)[0] - centres[0]
            assert np.linalg.norm(moved) > 0.1
            assert angle_between(math.atan2(moved[1], moved[0]), heading + body) < math.radians(3)
            # at full speed before the contact: the odometry's twist is the command, in the body frame
            cruising = [m for m in odom.messages if start < stamp_ns(m.header.stamp) < stamp_ns(close.header.stamp)
                        and math.hypot(m.twist.twist.linear.x, m.twist.twist.linear.y) > 0.95 * SPEED]
            assert cruising, "agent_0 never reached the commanded speed"
            twist = cruising[-1].twist.twist
            assert twist.linear.x == pytest.approx(command.twist.linear.x, abs=0.03 * SPEED)
            assert twist.linear.y == pytest.approx(command.twist.linear.y, abs=0.03 * SPEED)
        finally:
            ros.node.destroy_publisher(publisher)
            for collector in (poses, scan, odom):
                collector.destroy()
