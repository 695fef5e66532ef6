"""policy_node's action-to-twist conversion and limits (policy_commands.py) and its input reasons
(policy_inputs.py), without ROS graphs: pure functions on arrays and message objects."""
from __future__ import annotations

import math

import numpy as np
import pytest
from nav_msgs.msg import Odometry

from vmas_ros.ros.convert import fill_odometry
from vmas_ros.ros.policy_commands import CommandLimiter, body_commands, needs_heading, resolve_action_kind
from vmas_ros.ros.policy_inputs import AgentInputs, yaw_of

AGENTS = ["agent_0", "agent_1", "agent_2"]


def odometry(x: float, y: float, yaw: float) -> Odometry:
    msg = Odometry()
    fill_odometry(msg, x, y, yaw, 0.0, 0.0, 0.0)
    return msg


# ------------------------------------------------------------------ actions to twists
@pytest.mark.parametrize("yaw", [0.0, 0.7, math.pi / 2, -2.5, math.pi])
def test_a_world_velocity_drives_the_world_direction_whatever_the_heading(yaw):
    """Rotated into the body frame and back by the robot's heading, the command is the world velocity."""
    action = np.array([[0.3, -0.2]])
    twist = body_commands(action, np.array([yaw]), "world_velocity", "holonomic", 1.0, 0.15)
    c, s = math.cos(yaw), math.sin(yaw)
    world = np.array([c * twist[0, 0] - s * twist[0, 1], s * twist[0, 0] + c * twist[0, 1]])
    np.testing.assert_allclose(world, action[0], atol=1e-12)
    assert twist[0, 2] == 0.0


def test_a_robot_facing_minus_x_gets_the_opposite_body_command():
    twist = body_commands(np.array([[0.5, 0.0]]), np.array([math.pi]), "world_velocity", "holonomic", 1.0, 0.15)
    np.testing.assert_allclose(twist[0], [-0.5, 0.0, 0.0], atol=1e-12)


def test_an_unknown_heading_gives_no_command():
    twist = body_commands(np.array([[0.5, 0.1], [0.2, 0.2]]), np.array([0.0, np.nan]), "world_velocity",
                          "holonomic", 1.0, 0.15)
    assert np.isfinite(twist[0]).all() and np.isnan(twist[1, :2]).all()
    with pytest.raises(ValueError, match="need the robots' headings"):
        body_commands(np.zeros((1, 2)), None, "world_velocity", "holonomic", 1.0, 0.15)


def test_a_diff_drive_base_tracks_a_point_ahead_of_its_axis():
    """Wanted velocity (ux, uy) in the body frame: v = ux, w = uy / lookahead; linear.y stays 0."""
    twist = body_commands(np.array([[0.0, 0.4]]), np.array([math.pi / 2]), "world_velocity", "diff_drive", 1.0, 0.2)
    # facing +y, a wanted world velocity along +y is straight ahead: no turn
    np.testing.assert_allclose(twist[0], [0.4, 0.0, 0.0], atol=1e-12)
    twist = body_commands(np.array([[0.0, 0.4]]), np.array([0.0]), "world_velocity", "diff_drive", 1.0, 0.2)
    # facing +x, the same velocity is to the left: turn left on the spot at 0.4 / 0.2 rad/s
    np.testing.assert_allclose(twist[0], [0.0, 0.0, 2.0], atol=1e-12)


def test_point_ahead_tracking_brings_a_unicycle_onto_the_wanted_heading():
    """Integrated as a unicycle, the robot ends up driving along the wanted world direction."""
    x = y = 0.0
    theta, dt = 2.5, 0.01  # facing back-left, wanted: +x at 0.3 m/s
    for _ in range(1000):
        v, _, w = body_commands(np.array([[0.3, 0.0]]), np.array([theta]), "world_velocity", "diff_drive", 1.0, 0.15)[0]
        x, y, theta = x + v * math.cos(theta) * dt, y + v * math.sin(theta) * dt, theta + w * dt
    assert abs(math.remainder(theta, 2 * math.pi)) < 0.05 and v == pytest.approx(0.3, abs=0.01)


def test_speed_turn_and_body_velocity_need_no_heading_and_scale_the_whole_twist():
    assert not needs_heading("speed_turn") and not needs_heading("body_velocity") and needs_heading("world_velocity")
    twist = body_commands(np.array([[0.4, -1.0]]), None, "speed_turn", "diff_drive", 0.5, 0.15)
    np.testing.assert_allclose(twist[0], [0.2, 0.0, -0.5])
    twist = body_commands(np.array([[0.4, -0.2]]), None, "body_velocity", "holonomic", 2.0, 0.15)
    np.testing.assert_allclose(twist[0], [0.8, -0.4, 0.0])


@pytest.mark.parametrize("kind,base,fragment", [("spin", "holonomic", "action kind must be one of"),
                                                ("body_velocity", "tank", "base must be one of")])
def test_unknown_kinds_and_bases_are_refused_by_name(kind, base, fragment):
    with pytest.raises(ValueError, match=fragment):
        body_commands(np.zeros((1, 2)), np.zeros(1), kind, base, 1.0, 0.1)


def test_auto_reads_the_training_dynamics_from_the_policy():
    assert resolve_action_kind("auto", {"scenario": "navigation", "scenario_kwargs": {"dynamics": "diff_drive"}})[0] \
        == "speed_turn"
    kind, why = resolve_action_kind("auto", {"scenario": "simple_spread", "scenario_kwargs": {}})
    assert kind == "world_velocity" and "holonomic" in why
    assert resolve_action_kind("body_velocity", {"scenario_kwargs": {"dynamics": "diff_drive"}})[0] == "body_velocity"


# ------------------------------------------------------------------ limits
def test_speed_limits_keep_a_holonomic_command_s_direction():
    limiter = CommandLimiter(2, max_linear_speed=0.5, max_angular_speed=1.0)
    out = limiter.limit(np.array([[0.6, 0.8, 3.0], [0.1, 0.0, -0.5]]), np.array([True, True]), now=0.0)
    np.testing.assert_allclose(out[0], [0.3, 0.4, 1.0])
    np.testing.assert_allclose(out[1], [0.1, 0.0, -0.5])


def test_acceleration_limits_ramp_from_rest_and_follow_the_previous_command():
    limiter = CommandLimiter(1, max_linear_accel=1.0, max_angular_accel=2.0, period=0.1, memory=0.5)
    want, sent = np.array([[1.0, 0.0, 1.0]]), np.array([True])
    speeds = [limiter.limit(want, sent, now=0.1 * k)[0] for k in range(12)]
    np.testing.assert_allclose([s[0] for s in speeds[:10]], [0.1 * (k + 1) for k in range(10)], atol=1e-12)
    np.testing.assert_allclose([s[2] for s in speeds[:5]], [0.2 * (k + 1) for k in range(5)], atol=1e-12)
    assert speeds[-1][0] == pytest.approx(1.0) and speeds[-1][2] == pytest.approx(1.0)
    # after a pause longer than `memory` the base has stopped: the ramp starts from rest again
    again = limiter.limit(want, sent, now=5.0)
    np.testing.assert_allclose(again[0], [0.1, 0.0, 0.2])


def test_a_robot_that_was_not_sent_keeps_its_previous_command():
    limiter = CommandLimiter(2, max_linear_accel=1.0, period=0.1)
    limiter.limit(np.array([[1.0, 0, 0], [1.0, 0, 0]]), np.array([True, False]), now=0.0)
    out = limiter.limit(np.array([[1.0, 0, 0], [1.0, 0, 0]]), np.array([True, True]), now=0.1)
    np.testing.assert_allclose(out[:, 0], [0.2, 0.1])


# ------------------------------------------------------------------ input reasons
def test_yaw_of_reads_the_heading_and_refuses_nan_poses():
    assert yaw_of(odometry(1.0, 2.0, 0.9)) == pytest.approx(0.9)
    broken = odometry(float("nan"), 0.0, 0.0)
    assert math.isnan(yaw_of(broken))
    zero = odometry(0.0, 0.0, 0.0)
    zero.pose.pose.orientation.w = 0.0
    assert math.isnan(yaw_of(zero))


def test_each_agent_is_named_with_what_is_wrong_with_its_inputs():
    odom = [f"{a}/odom" for a in AGENTS]
    inputs = AgentInputs(AGENTS, [*odom, "landmarks/poses"], odom, lambda: 0.5)
    assert inputs.own["agent_1"] == ["agent_1/odom"] and inputs.shared == ["landmarks/poses"]
    fresh = {"agent_0/odom": odometry(0, 0, 0.3), "agent_1/odom": odometry(float("nan"), 0, 0),
             "landmarks/poses": object()}
    seen = {**fresh, "agent_2/odom": odometry(0, 0, 0)}
    yaw = inputs.headings(fresh)
    assert yaw[0] == pytest.approx(0.3) and np.isnan(yaw[1:]).all()
    reasons = inputs.reasons(fresh, seen, np.array([True, True, True]), yaw, {}, lambda topic: 1)
    assert sorted(reasons) == [1, 2]
    assert reasons[1] == "odometry on agent_1/odom: NaN pose"
    assert reasons[2] == "agent_2/odom is older than observation_timeout (0.5 s)"
    # a robot whose topics never appeared: how many publishers, so a wrong remap shows
    reasons = inputs.reasons({}, {}, np.zeros(3, bool), inputs.headings({}), {}, lambda topic: 0)
    assert reasons[0] == "nothing received on agent_0/odom yet (0 publishers)"


def test_missing_topics_are_named_before_the_adapter_s_reason():
    """The adapter sees fresh messages only: whether a topic is old or never came is said here; what is
    wrong with a message that did come (a scan it cannot resample), the adapter says."""
    inputs = AgentInputs(AGENTS, [f"{a}/scan" for a in AGENTS] + ["goals"], None, lambda: 0.5)
    fresh = {"agent_0/scan": 1, "agent_1/scan": 1, "goals": 1}
    usable = np.array([True, False, False])
    reasons = inputs.reasons(fresh, fresh, usable, inputs.headings(fresh),
                             {"agent_1": "agent_1/scan: scan covers [-1.57, 1.57] rad",
                              "agent_2": "agent_2/scan: no message"}, lambda topic: 1)
    assert reasons == {1: "agent_1/scan: scan covers [-1.57, 1.57] rad",
                       2: "nothing received on agent_2/scan yet (1 publisher)"}
