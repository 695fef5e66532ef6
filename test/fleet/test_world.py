"""The fleet stepped on a fake clock: episodes, resets, latency, collisions, odometry noise."""
from __future__ import annotations

import math

import numpy as np
import pytest

from test.fleet.helpers import episode, params, run
from vmas_ros.fleet.world import MAX_STEP_S, FleetWorld

TWO = [episode([[0, 0, math.pi / 2], [1, 0, 0]], goals=[[0, 0.5], [1, 0]]),
       episode([[0, -1, 0], [1, -1, 0]], goals=[[3, 3]])]


def world(episodes=TWO, **values) -> FleetWorld:
    values.setdefault("n_robots", len(episodes[0].robots))
    return FleetWorld(params(**values), episodes, now=0.0)


def keep_commanding(w: FleetWorld, robot: int, twist, start: float, seconds: float, dt: float = 0.01):
    ended = []
    for k in range(int(round(seconds / dt))):
        now = start + k * dt
        w.command(robot, twist, now)
        ended += w.step(now + dt)
    return ended


def test_a_command_moves_its_robot_in_its_body_frame_and_no_other():
    w = world()
    keep_commanding(w, 0, (0.5, 0.0, 0.0), 0.0, 1.0)
    assert w.state.pose[0] == pytest.approx([0.0, 0.5, math.pi / 2], abs=1e-9)
    assert w.state.pose[1] == pytest.approx([1.0, 0.0, 0.0])
    assert w.state.velocity[0] == pytest.approx([0.5, 0.0, 0.0])  # the twist stays in the body frame


def test_latency_delays_and_the_timeout_stops():
    w = world(command_latency=0.2, cmd_vel_timeout=0.3)
    w.command(0, (1.0, 0.0, 0.0), 0.0)
    run(w, 0.0, 0.2)
    assert w.state.pose[0, 1] == pytest.approx(0.0)
    run(w, 0.2, 1.0)
    # moved from 0.2 s (arrival + latency) to 0.5 s (+ timeout), then stopped
    assert w.state.pose[0, 1] == pytest.approx(0.3, abs=0.011)
    assert w.state.velocity[0] == pytest.approx([0.0, 0.0, 0.0])


def test_episodes_end_on_time_and_the_next_starts_from_rest():
    w = world(episode_seconds=1.0)
    ended = keep_commanding(w, 0, (0.5, 0.0, 0.0), 0.0, 1.0)  # the last step, to 1.0 s, ends it
    assert [r["ended_by"] for r in ended] == ["time"] and ended[0]["duration"] == pytest.approx(1.0, abs=1e-9)
    assert ended[0]["time_to_goal"][0] == pytest.approx(0.8, abs=0.011) and ended[0]["time_to_goal"][1] == 0.0
    # the second episode: teleported, at rest, and the command given before the reset is forgotten
    w.step(1.06)
    assert w.state.pose[:, :2] == pytest.approx(np.array([[0.0, -1.0], [1.0, -1.0]]))
    assert not w.state.velocity.any() and not w.state.command.any()
    assert w.tracker.index == 1 and w.episode.goals.tolist() == [[3.0, 3.0]]
    ended = run(w, 1.06, 1.0)
    assert ended[0]["index"] == 1 and ended[0]["coverage"] == pytest.approx(math.dist((1, -1), (3, 3)))
    assert w.finished and w.complete
    assert w.step(5.0) == [] and w.close() is None


def test_exit_after_last_false_starts_over():
    w = world(episode_seconds=0.5, exit_after_last=False)
    ended = run(w, 0.0, 1.6)
    assert [(r["index"], r["plan_index"]) for r in ended] == [(0, 0), (1, 1), (2, 0)]
    assert not w.finished and w.tracker.plan_index == 1


def test_reset_ends_the_episode_early_and_close_records_the_running_one():
    w = world()  # episode_seconds 0: endless
    run(w, 0.0, 0.3)
    record = w.end_episode("reset")
    assert record["ended_by"] == "reset" and record["duration"] == pytest.approx(0.3)
    run(w, 0.3, 0.2)
    closing = w.close()
    assert closing["ended_by"] == "shutdown" and closing["index"] == 1
    assert w.finished and not w.complete  # the second episode was cut short


def test_robots_driven_into_each_other_never_overlap_and_collide_once():
    w = world([episode([[0, 0, 0], [1, 0, math.pi]])])
    for k in range(150):  # both drive forward, towards each other, for 1.5 s: they meet and keep pushing
        now = k * 0.01
        w.command(0, (0.5, 0.0, 0.0), now)
        w.command(1, (0.5, 0.0, 0.0), now)
        w.step(now + 0.01)
        assert math.dist(w.state.pose[0, :2], w.state.pose[1, :2]) >= 0.2 - 1e-9
    record = w.close()
    assert record["collisions"]["robot_robot"] == 1 and record["collisions"]["per_robot_robot"] == [1, 1]
    assert record["min_separation"] == pytest.approx(0.2)


def test_a_robot_driven_into_a_wall_stays_inside_and_counts_one_wall_contact():
    w = world([episode([[0, 0, 0]])], arena_half_x=1.0, arena_half_y=1.0)
    keep_commanding(w, 0, (1.0, 0.0, 0.0), 0.0, 2.0)
    assert w.state.pose[0, 0] == pytest.approx(0.9)
    record = w.close()
    assert record["collisions"] == {"robot_robot": 0, "robot_wall": 1, "per_robot_robot": [0],
                                    "per_robot_wall": [1]}


def test_a_long_pause_is_integrated_as_one_bounded_step():
    w = world()
    w.command(0, (1.0, 0.0, 0.0), 0.0)
    w.step(0.4)  # the process was stopped for 0.4 s
    assert w.state.pose[0, 1] == pytest.approx(MAX_STEP_S)


def test_odometry_noise_never_touches_the_true_state_and_follows_the_seed():
    w = world(odom_noise_position=0.1, odom_noise_yaw=0.05, odom_noise_velocity=0.2)
    truth = w.state.pose.copy()
    reports = np.stack([w.odometry(np.random.default_rng(5)) for _ in range(2)])
    assert np.array_equal(reports[0], reports[1])
    many = np.stack([w.odometry(np.random.default_rng(k)) for k in range(2000)])  # [2000, n, 6]
    assert np.array_equal(w.state.pose, truth)
    spread = (many - np.concatenate([truth, w.state.velocity], axis=1)).std(axis=0)
    assert spread[0] == pytest.approx([0.1, 0.1, 0.05, 0.2, 0.2, 0.0], rel=0.1, abs=1e-12)


def test_a_diff_drive_odometry_reports_no_sideways_velocity():
    w = world(drive="diff_drive", odom_noise_velocity=0.2)
    report = w.odometry(np.random.default_rng(0))
    assert (report[:, 4] == 0).all() and (report[:, 3] != 0).all()


def test_the_world_scan_sees_the_other_robot_from_the_robot_frame():
    w = world()
    ranges = w.scan()  # [2, 360]
    assert ranges.shape == (2, 360) and ranges.dtype == np.float32
    # robot 0 faces +y; robot 1 lies 1 m along +x: on its right, at -pi/2, ray index 90
    assert ranges[0, 90] == pytest.approx(0.9, abs=1e-6)
    assert np.isinf(ranges[0, :80]).all()
    # robot 1 faces +x; robot 0 lies behind it, at angle -pi: ray 0
    assert ranges[1, 0] == pytest.approx(0.9, abs=1e-6)


def test_end_on_goals_ends_an_episode_when_every_robot_stands_on_its_goal():
    # robot 0 starts 0.5 m below its goal, facing it; robot 1 starts on its goal
    ended = keep_commanding(world(episode_seconds=5.0, end_on_goals=True), 0, (0.5, 0.0, 0.0), 0.0, 1.0)
    assert [r["ended_by"] for r in ended] == ["goals"]
    # within goal_radius (0.1 m) after 0.4 m at 0.5 m/s, one 10 ms step later at most
    assert ended[0]["duration"] == pytest.approx(0.8, abs=0.011) == ended[0]["all_at_goal_time"]
    # without it the same episode runs to its time, and one with landmarks (no own goals) always does
    assert keep_commanding(world(episode_seconds=5.0), 0, (0.5, 0.0, 0.0), 0.0, 1.0) == []
    w = world(episodes=TWO[1:], episode_seconds=0.5, end_on_goals=True)
    assert [r["ended_by"] for r in run(w, 0.0, 0.6)] == ["time"]
