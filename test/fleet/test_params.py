"""robot_fleet's parameter table: the refusals, and the cross-checks once every value is known."""
from __future__ import annotations

import pytest

from test.fleet.helpers import params
from vmas_ros.fleet.params import CROSS_CHECKED, FLEET_PARAMS


def refusal(name, value, **others):
    """Why ``value`` is refused for ``name`` once the other values are ``others`` (None: accepted)."""
    return FLEET_PARAMS.validate(name, value, params(**{name: value, **others}))


def test_the_interface_names_and_defaults():
    p = params()
    assert p.names_list() == ["agent_0", "agent_1", "agent_2"]
    assert (p.use_stamped_cmd_vel, p.odom_frame, p.goals_topic, p.drive) == (True, "odom", "landmarks/poses",
                                                                              "holonomic")
    assert (p.scan_rays, p.scan_range_min, p.scan_range_max, p.scan_rate_hz) == (360, 0.12, 3.5, 10.0)
    assert (p.rate_hz, p.odom_rate_hz, p.cmd_vel_timeout, p.goal_radius) == (100.0, 50.0, 0.5, 0.1)
    assert params(n_robots=2, robot_names="scout, hauler").names_list() == ["scout", "hauler"]
    assert set(CROSS_CHECKED) <= set(FLEET_PARAMS.names())
    assert not FLEET_PARAMS.runtime()  # one set of values per run, stated in the summary


@pytest.mark.parametrize("name, value, others, words", [
    ("drive", "tank", {}, ["one of holonomic, diff_drive", "'tank'"]),
    ("n_robots", 0, {}, ["n_robots must be in [1, 1000], got 0"]),
    ("scan_dropout", 1.5, {}, ["scan_dropout must be in [0, 1], got 1.5"]),
    ("robot_radius", 0.0, {}, ["robot_radius must be > 0"]),
    ("rate_hz", 0.0, {}, ["rate_hz must be in [1, 10000]"]),
    ("velocity_lag", -0.1, {}, ["velocity_lag must be in [0, 100]"]),
    ("robot_names", "a,1b", {"n_robots": 2}, ["'1b' is not a ROS name token"]),
    ("robot_names", "a,b,a", {"n_robots": 3}, ["unique", "a repeats"]),
    ("robot_names", "a,b", {"n_robots": 3}, ["names 2 robots but n_robots is 3"]),
    ("scan_angle_max", -1.0, {"scan_angle_min": 0.0}, ["scan_angle_max must be above scan_angle_min (0)"]),
    ("scan_range_max", 0.1, {}, ["scan_range_max must be above scan_range_min (0.12), got 0.1"]),
    ("arena_half_x", 0.05, {}, ["arena_half_x must be 0 (no walls) or more than robot_radius (0.1)"]),
    ("start_poses", "[1, 2]", {}, ["start_poses must be a mapping", "got list"]),
    ("start_poses", "{robots: [", {}, ["start_poses must be a YAML/JSON mapping"]),
    ("episodes_file", "episodes.txt", {}, ["must be a .yaml, .yml or .json file"]),
    ("episodes_file", "/nonexistent/e.yaml", {}, ["must name an existing file"]),
    ("summary_path", "/tmp/", {}, ["must name a file"]),
    ("goals_topic", "goals//all", {}, ["goals_topic must be a topic name"]),
    ("odom_frame", " ", {}, ["odom_frame must not be empty"]),
])
def test_bad_values_are_refused_with_a_reason(name, value, others, words):
    reason = refusal(name, value, **others)
    assert reason is not None and all(word in reason for word in words), reason


def test_start_poses_and_episodes_file_exclude_each_other(tmp_path):
    path = tmp_path / "e.yaml"
    path.write_text("episodes: [{robots: [[0, 0, 0]]}]\n")
    assert refusal("episodes_file", str(path)) is None
    reason = refusal("start_poses", "{robots: [[0, 0, 0]]}", episodes_file=str(path))
    assert "start_poses and episodes_file are both set" in reason


def test_good_values_pass():
    assert refusal("robot_names", "a, b", n_robots=2) is None
    assert refusal("arena_half_x", 0.0) is None and refusal("arena_half_x", 2.0) is None
    assert refusal("scan_rate_hz", 0.0) is None  # scans off
    assert refusal("start_poses", "{robots: [[0, 0, 0]], goals: [[1, 1]]}") is None
