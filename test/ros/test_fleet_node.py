"""robot_fleet as a real process, driven from this test's rclpy node over loopback DDS.

A TwistStamped moves its robot in the robot's body frame and no other; the
odometry, scans and goals follow the conventions real bases use; ``~/reset``
walks through the episodes and the process exits 0 after the last; the
summary file holds what happened, also when SIGTERM stops the node.
"""
from __future__ import annotations

import json
import math
import signal
import time

import pytest
from geometry_msgs.msg import PoseArray, PoseStamped, Twist, TwistStamped
from nav_msgs.msg import Odometry
from sensor_msgs.msg import LaserScan
from std_srvs.srv import Trigger

from test.ros.conftest import killed_at_end
from test.ros.fleet_process import NODE, FleetProcess

pytestmark = [pytest.mark.ros, pytest.mark.slow]

@pytest.fixture(scope="module")
def fleet(ros, sim_log_dir):
    """Factory: ``with fleet(n_robots=2, ...) as process: ...`` (started, not yet discovered)."""
    yield from killed_at_end(lambda index, **params: FleetProcess(ros, params, sim_log_dir, f"robot_fleet_{index}"))


def hold(ros, publisher, message, until, timeout: float, what: str):
    """Publish ``message`` every 50 ms, as a teleop holds a key, until ``until()`` is true."""
    end = time.monotonic() + timeout
    while not until():
        assert time.monotonic() < end, f"timed out after {timeout} s waiting for {what}"
        publisher.publish(message)
        ros.spin_for(0.05)


def xy(odom: Odometry):
    return odom.pose.pose.position.x, odom.pose.pose.position.y


def test_a_stamped_command_drives_one_robot_in_its_body_frame_through_two_episodes(ros, fleet, tmp_path):
    episodes = {"episodes": [
        {"robots": [[0, 0, math.pi / 2], [1, 0, 0]], "goals": [[0, 0.5], [1, 0]]},  # agent_0 faces +y
        {"robots": [[0, -1, 0], [1, -1, 0]], "goals": [[3, 3]]},                     # one landmark
    ]}
    path, summary = tmp_path / "episodes.json", tmp_path / "out" / "summary.json"
    path.write_text(json.dumps(episodes))
    odom = [ros.collect(Odometry, f"/agent_{i}/odom") for i in range(2)]
    scan = ros.collect(LaserScan, "/agent_0/scan")
    goal = ros.collect(PoseStamped, "/agent_0/goal")
    goals = ros.collect(PoseArray, "/landmarks/poses")
    with fleet(n_robots=2, episodes_file=str(path), summary_path=str(summary), seed=4) as process:
        process.wait_fleet(["agent_0", "agent_1"])

        # agent_1 stands 1 m along +x: on the right of agent_0, which faces +y (ray at -pi/2, index 90)
        first = scan.wait_for(1)[-1]
        assert first.header.frame_id == "agent_0/base_link" and len(first.ranges) == 360
        assert first.angle_increment == pytest.approx(2 * math.pi / 360)
        assert first.ranges[90] == pytest.approx(0.9, abs=1e-5)
        assert math.isinf(first.ranges[0]) and first.ranges[0] > 0
        target = goal.wait_for(1)[-1]
        assert target.header.frame_id == "odom" and (target.pose.position.x, target.pose.position.y) == (0.0, 0.5)

        command = TwistStamped()
        command.header.frame_id = "agent_0/base_link"
        command.twist.linear.x = 0.5
        publisher = ros.node.create_publisher(TwistStamped, "/agent_0/cmd_vel", 10)
        hold(ros, publisher, command, lambda: odom[0].latest is not None and xy(odom[0].latest)[1] >= 0.45,
             10.0, "agent_0 to drive 0.45 m along +y")
        ros.node.destroy_publisher(publisher)
        moving = odom[0].latest
        assert moving.header.frame_id == "odom" and moving.child_frame_id == "agent_0/base_link"
        assert abs(xy(moving)[0]) < 1e-9  # forward is +y for a robot facing +y
        assert moving.twist.twist.linear.x == pytest.approx(0.5) and moving.twist.twist.linear.y == 0.0
        assert xy(odom[1].latest) == (1.0, 0.0) and odom[1].latest.twist.twist.linear.x == 0.0

        reply = ros.call(Trigger, f"{NODE}/reset")
        assert reply.success and "episode 1 started" in reply.message
        odom[0].wait_until(lambda m: xy(m) == (0.0, -1.0), 5.0, "agent_0 at the second start")
        goals.wait_until(lambda m: [(p.position.x, p.position.y) for p in m.poses] == [(3.0, 3.0)], 5.0)
        reply = ros.call(Trigger, f"{NODE}/reset")
        assert reply.success and "last" in reply.message
        assert process.wait(10.0) == 0, process.describe()  # exit_after_last
        process.wait_gone()
    assert "expects geometry_msgs/TwistStamped on <robot>/cmd_vel" in process.output()

    doc = json.loads(summary.read_text())
    assert doc["complete"] and doc["robot_names"] == ["agent_0", "agent_1"] and doc["episodes_planned"] == 2
    assert doc["parameters"]["seed"] == 4 and doc["parameters"]["odom_noise_position"] == 0.0
    one, two = doc["episodes"]
    assert [one["ended_by"], two["ended_by"]] == ["reset", "reset"]
    assert one["time_to_goal"][0] > 0 and one["time_to_goal"][1] == 0.0
    assert one["all_reached_time"] == one["time_to_goal"][0]
    assert one["collisions"]["robot_robot"] == 0 and one["min_separation"] >= 1.0 - 1e-9
    assert two["time_to_goal"] is None and two["coverage"] == pytest.approx(math.hypot(2, 4))


def test_twist_for_a_diff_drive_fleet_bad_commands_and_a_summary_on_sigterm(ros, fleet, tmp_path):
    summary = tmp_path / "summary.json"
    odom = {name: ros.collect(Odometry, f"/{name}/odom") for name in ("scout", "hauler")}
    with fleet(n_robots=3, robot_names="scout,hauler,spare", use_stamped_cmd_vel=False, drive="diff_drive",
               scan_rate_hz=0.0, summary_path=str(summary),
               start_poses="{robots: [[0, 0, 0], [0, 1, 0], [0, -1, 0]]}") as process:
        process.wait_fleet(["scout", "hauler", "spare"], stamped=False, scans=False)
        # a TwistStamped publisher on a Twist topic never matches: the node names it
        wrong_type = ros.node.create_publisher(TwistStamped, "/spare/cmd_vel", 10)
        bad = Twist()
        bad.linear.x = math.nan
        dropped = "dropped a command for scout (linear.x=nan: expected finite numbers)"
        scout = ros.node.create_publisher(Twist, "/scout/cmd_vel", 10)
        hold(ros, scout, bad, lambda: dropped in process.output(), 10.0, "the warning about scout's NaN command")
        ros.node.destroy_publisher(scout)
        sideways = Twist()
        sideways.linear.x = sideways.linear.y = 0.4  # a diff-drive base cannot follow linear.y
        publisher = ros.node.create_publisher(Twist, "/hauler/cmd_vel", 10)
        hauler = odom["hauler"]
        hold(ros, publisher, sideways, lambda: hauler.latest is not None and xy(hauler.latest)[0] > 0.15, 10.0,
             "hauler to drive forward")
        ros.node.destroy_publisher(publisher)
        assert xy(odom["hauler"].latest)[1] == pytest.approx(1.0, abs=1e-12)
        assert odom["hauler"].latest.twist.twist.linear.y == 0.0
        assert xy(odom["scout"].latest) == (0.0, 0.0)  # its NaN command was dropped
        warning = "ignoring a publisher of geometry_msgs/msg/TwistStamped on /spare/cmd_vel"
        ros.spin_until(lambda: warning in process.output(), 10.0, "the warning about the TwistStamped publisher")
        ros.node.destroy_publisher(wrong_type)
        assert process.stop(signal.SIGTERM) == 0, process.describe()
    output = process.output()
    assert "expects geometry_msgs/Twist on <robot>/cmd_vel" in output
    doc = json.loads(summary.read_text())
    assert not doc["complete"] and doc["parameters"]["drive"] == "diff_drive"
    (episode,) = doc["episodes"]
    assert episode["ended_by"] == "shutdown" and episode["final_poses"][1][0] > 0.15


@pytest.mark.parametrize("case", ["overlap", "summary"])
def test_refused_start_exits_with_code_2_naming_the_value(sim_log_dir, tmp_path, case):
    (tmp_path / "a_file").write_text("")
    params, expected = {
        "overlap": ({"n_robots": 2, "start_poses": "{robots: [[0, 0, 0], [0.1, 0, 0]]}"},
                    "refused parameters: start_poses: robots 0 at [0.0, 0.0] and 1 at [0.1, 0.0] overlap"),
        "summary": ({"summary_path": str(tmp_path / "a_file" / "summary.json")},
                    f"refused parameters: summary_path '{tmp_path / 'a_file' / 'summary.json'}' cannot be written"),
    }[case]
    process = FleetProcess(None, params, sim_log_dir, f"robot_fleet_refused_{case}")
    try:
        assert process.wait(30.0) == 2, process.describe()
    finally:
        process.kill()
    assert expected in process.stderr()
