"""sim_node's cmd_vel as a real ROS 2 process: one agent driven forward and sideways, NaN, timeout, reset.

One ``python -m vmas_ros.ros.sim_node`` process with a single simple_spread
agent (class-scoped fixture); a test-side rclpy node publishes Twists and
records odometry and poses. The engine is the reference for drag and for the
layout after a reset (sim_node_helpers.py).
"""
from __future__ import annotations

import math
import time

import numpy as np
import pytest
from geometry_msgs.msg import PoseArray, PoseStamped, Twist
from nav_msgs.msg import Odometry
from rosgraph_msgs.msg import Clock
from std_srvs.srv import Trigger

from test.ros.conftest import NODE, stamp_ns
from test.ros.sim_node_helpers import (DT, DT_NS, SCENARIO, angle_between, engine, layout, pause, positions, speed,
                                       xy, yaw_of)

pytestmark = [pytest.mark.ros, pytest.mark.slow]


# ================================================= one agent, driven by cmd_vel
CMD_TIMEOUT = 0.3


@pytest.fixture(scope="class")
def single(ros, sim_node):
    with sim_node(scenario=SCENARIO, scenario_kwargs={"n_agents": 1}, seed=0, control="zero", real_time_factor=1.0,
                  cmd_vel_timeout=CMD_TIMEOUT) as sim:
        yield sim


class Drive:
    """Publish one Twist at 20 Hz for ``seconds``, then record until the agent has (nearly) stopped."""

    def __init__(self, ros, vx: float, vy: float, seconds: float = 2.0, settle: float = 3.0) -> None:
        self.command = (vx, vy)
        publisher = ros.node.create_publisher(Twist, "/agent_0/cmd_vel", 10)
        self.odom = ros.collect(Odometry, "/agent_0/odom")
        self.pose = ros.collect(PoseStamped, "/agent_0/pose")
        try:
            ros.spin_until(lambda: publisher.get_subscription_count() > 0, 10, "sim_node's cmd_vel subscription")
            self.odom.wait_for(2)
            self.pose.wait_for(2)
            msg = Twist()
            msg.linear.x, msg.linear.y = float(vx), float(vy)
            self.start = time.monotonic()
            due = self.start
            while time.monotonic() - self.start < seconds:
                if time.monotonic() >= due:
                    publisher.publish(msg)
                    due += 0.05
                ros.executor.spin_once(timeout_sec=max(0.0, min(0.01, due - time.monotonic())))
            self.stop = time.monotonic()
            slow = 0.1 * math.hypot(vx, vy)
            self.stopped = self.odom.wait_until(lambda m: speed(m) < slow and self.arrived(m) > self.stop,
                                                timeout=settle, what="the agent to slow below 10% of the command")
            self.stop_delay = self.arrived(self.stopped) - self.stop
        finally:
            ros.node.destroy_publisher(publisher)
            self.odom.destroy()
            self.pose.destroy()

    def arrived(self, msg) -> float:
        for collector in (self.odom, self.pose):
            for m, t in zip(collector.messages, collector.arrivals):
                if m is msg:
                    return t
        raise KeyError(msg)

    def during(self, collector):
        """(message, arrival) pairs received while the command was being published."""
        return [(m, t) for m, t in zip(collector.messages, collector.arrivals) if self.start < t < self.stop]

    def check(self, dt: float = DT):
        """Steady body-frame twist after 1 s of sim time, and world displacement along the command."""
        vx, vy = self.command
        commanded = math.hypot(vx, vy)
        along = np.array([vx, vy]) / commanded
        moving = [m for m, _ in self.during(self.odom)
                  if np.dot([m.twist.twist.linear.x, m.twist.twist.linear.y], along) > 0.25 * commanded]
        assert moving, "the agent never moved"
        first = stamp_ns(moving[0].header.stamp) - int(dt * 1e9)  # the step that first used the command
        steady = [m for m in moving if stamp_ns(m.header.stamp) >= first + 1_000_000_000]
        assert len(steady) >= 3, f"only {len(steady)} odometry messages after 1 s of commanded motion"
        for m in steady:
            twist = m.twist.twist
            assert twist.linear.x == pytest.approx(vx, abs=0.05 * commanded), twist
            assert twist.linear.y == pytest.approx(vy, abs=0.05 * commanded), twist
            assert twist.angular.z == pytest.approx(0.0, abs=1e-6)
        before = [m for m in self.pose.messages if stamp_ns(m.header.stamp) <= first]
        during = [m for m, _ in self.during(self.pose) if stamp_ns(m.header.stamp) > first]
        assert before and len(during) >= 10
        start, end = before[-1], during[-1]
        heading = yaw_of(start.pose.orientation)
        displacement = xy(end.pose) - xy(start.pose)
        elapsed = (stamp_ns(end.header.stamp) - stamp_ns(start.header.stamp)) / 1e9
        assert np.linalg.norm(displacement) > 0.6 * commanded * elapsed, (displacement, elapsed)
        expected_direction = heading + math.atan2(vy, vx)  # body frame -> world frame (REP 103)
        assert angle_between(math.atan2(displacement[1], displacement[0]), expected_direction) < math.radians(2)
        # positions move at the commanded speed in the world frame too
        steady_poses = [m for m in during if stamp_ns(m.header.stamp) >= first + 1_000_000_000]
        for a, b in zip(steady_poses, steady_poses[1:]):
            step = (stamp_ns(b.header.stamp) - stamp_ns(a.header.stamp)) / 1e9
            world_speed = np.linalg.norm(xy(b.pose) - xy(a.pose)) / step
            assert world_speed == pytest.approx(commanded, rel=0.05)


@pytest.fixture(scope="class")
def forward(ros, single):
    return Drive(ros, 0.3, 0.0)


class TestCmdVel:
    def test_forward_command_moves_along_heading(self, forward):
        forward.check()

    def test_command_times_out_and_drag_stops_the_agent(self, forward):
        drag = float(engine(0, n_agents=1).world.drag)
        assert forward.stop_delay < 2.0, f"took {forward.stop_delay:.2f} s to drop below 10% of the command"
        # after the timeout no force acts: speed decays by (1 - drag) per step
        after = [m for m in forward.odom.messages if forward.arrived(m) > forward.stop]
        decaying = [(a, b) for a, b in zip(after, after[1:])
                    if 0.01 < speed(b) < speed(a) < 0.95 * 0.3
                    and stamp_ns(b.header.stamp) - stamp_ns(a.header.stamp) == DT_NS]
        assert len(decaying) >= 3, [speed(m) for m in after]
        for a, b in decaying:
            assert speed(b) / speed(a) == pytest.approx(1 - drag, abs=0.01)

    def test_negative_linear_y_moves_to_the_right(self, ros, single):
        drive = Drive(ros, 0.0, -0.2)
        drive.check()
        moving = [m for m, _ in drive.during(drive.odom) if speed(m) > 0.15]
        assert moving and all(m.twist.twist.linear.y < 0 for m in moving), "REP 103: +y is left, so -y is right"

    def test_nan_command_is_dropped(self, ros, single):
        clock = ros.collect(Clock, "/clock")
        odom = ros.collect(Odometry, "/agent_0/odom")
        publisher = ros.node.create_publisher(Twist, "/agent_0/cmd_vel", 10)
        try:
            ros.spin_until(lambda: publisher.get_subscription_count() > 0, 10, "cmd_vel subscription")
            odom.wait_for(1)
            bad = [Twist(), Twist(), Twist()]
            bad[0].linear.x = math.nan
            bad[1].linear.y = math.inf
            bad[2].linear.x, bad[2].angular.z = 0.3, math.nan
            end = time.monotonic() + 0.6
            while time.monotonic() < end:
                for msg in bad:
                    publisher.publish(msg)
                ros.spin_for(0.05)
            start = time.monotonic()
            ros.spin_until(lambda: "dropped a cmd_vel with NaN or inf for agent_0" in single.stderr(), 5,
                           "the NaN warning in sim_node's log")
            ros.spin_until(lambda: len(clock.since(start)) >= 3, 5, "/clock to keep running")
            assert single.alive()
            for m in odom.messages:
                p, t = m.pose.pose.position, m.twist.twist.linear
                assert all(math.isfinite(v) for v in (p.x, p.y, t.x, t.y)), m
                assert speed(m) < 0.05, "a dropped command must not move the agent"
            # and a good command still drives it afterwards
            good = Twist()
            good.linear.x = 0.3
            end = time.monotonic() + 0.8
            while time.monotonic() < end:
                publisher.publish(good)
                ros.spin_for(0.05)
            odom.wait_until(lambda m: m.twist.twist.linear.x > 0.2, 3, "a valid command after the NaNs to act")
        finally:
            ros.node.destroy_publisher(publisher)
            clock.destroy()
            odom.destroy()

    def test_reset_jumps_to_a_fresh_layout(self, ros, single):
        agents = ros.collect(PoseArray, "/agents/poses")
        landmarks = ros.collect(PoseArray, "/landmarks/poses")
        odom = ros.collect(Odometry, "/agent_0/odom")
        collectors = (agents, landmarks, odom)
        initial, _ = layout(engine(0, n_agents=1), 0)
        try:
            for c in collectors:  # subscribed and matched while it still publishes
                c.wait_for(1)
            pause(ros, True)
            ros.spin_for(0.3)
            if np.linalg.norm(positions(agents.latest) - initial) < 0.2:  # run alone: drive it away first
                pause(ros, False)
                Drive(ros, 0.3, 0.0, seconds=1.0)
                pause(ros, True)
                ros.spin_for(0.3)
            before = positions(agents.latest)
            assert np.linalg.norm(before - initial) > 0.2
            for c in collectors:
                c.clear()
            response = ros.call(Trigger, f"{NODE}/reset")
            assert response.success, response.message
            for c in collectors:
                c.wait_for(1)
            after_agents, after_landmarks = positions(agents.latest), positions(landmarks.latest)
            assert np.linalg.norm(after_agents - before) > 1e-3, "reset did not move the agent"
            # a fresh layout: the env's next random layout (the second reset of the seeded env)
            expected_agents, expected_landmarks = layout(engine(0, resets=2, n_agents=1), 0)
            assert np.allclose(after_agents, expected_agents, atol=1e-6)
            assert np.allclose(after_landmarks, expected_landmarks, atol=1e-6)
            assert np.all(np.abs(after_agents) <= 1.0) and np.all(np.abs(after_landmarks) <= 1.0)
            assert speed(odom.latest) == 0.0
        finally:
            pause(ros, False)
            for c in collectors:
                c.destroy()
