"""What sim_node adds to a scenario and takes from it at start (ros/sim_setup.py), without a process.

The lidar geometry parameters and their refusals, the node's own lidar beside
the scenario's (whose observation must not change), the LaserScan geometry of
full and partial lidars, which agents get a ``<agent>/goal``, and the scenario
a policy's metadata names. The processes are in test_sim_node_robot.py and
test_sim_node_policy_scenario.py.
"""
from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path

import pytest
import torch
import yaml

import vmas_ros
from vmas_ros.ros import sim_setup
from vmas_ros.ros.lifecycle import ConfigError
from vmas_ros.ros.params import SIM_PARAMS, SimParams, validate

pytestmark = pytest.mark.ros

REPO = Path(__file__).resolve().parents[2]
PROFILE = REPO / "config" / "robot_profile.yaml"


def _refusals(**values) -> list:
    """Every refusal of ``values`` as sim_node gives them at start: each alone, then against all."""
    current = SimParams(**values)
    return [reason for name, value in values.items()
            for reason in (validate(name, value), validate(name, value, current)) if reason]


# ------------------------------------------------------------- parameters
@pytest.mark.parametrize("values, named", [
    ({"lidar_angle_min": 1.0, "lidar_angle_max": 0.5}, ["lidar_angle_max", "0.5", "1.0"]),
    ({"lidar_angle_min": 0.5, "lidar_angle_max": 0.5}, ["lidar_angle_max", "0.5"]),
    ({"lidar_angle_min": -3.5, "lidar_angle_max": 3.5}, ["2 pi", "-3.5", "3.5", "= 7"]),
    ({"lidar_angle_min": -180.0, "lidar_angle_max": 180.0}, ["lidar_angle_min", "-180"]),
    ({"lidar_range_min": 2.0, "lidar_range": 2.0}, ["lidar_range_min", "lidar_range (2.0)", "got 2.0"]),
    ({"lidar_range_min": -0.1}, ["lidar_range_min", "-0.1"]),
])
def test_bad_lidar_geometry_is_refused_naming_the_values(values, named):
    reasons = _refusals(**values)
    assert reasons, values
    text = "; ".join(reasons)
    for part in named:
        assert part in text, (part, text)


@pytest.mark.parametrize("values", [
    {},  # the defaults: today's full circle
    {"lidar_angle_min": -math.pi, "lidar_angle_max": math.pi},  # a full circle written as -pi .. pi
    {"lidar_angle_min": -math.pi / 2, "lidar_angle_max": math.pi / 2, "lidar_range_min": 0.05},
])
def test_good_lidar_geometry_is_accepted(values):
    assert _refusals(**values) == []


def test_the_robot_profile_is_a_valid_sim_node_parameter_file():
    values = yaml.safe_load(PROFILE.read_text())["sim_node"]["ros__parameters"]
    assert set(values) <= set(SIM_PARAMS.names())
    assert _refusals(**values) == []
    assert values["use_stamped_cmd_vel"] is True and values["robot_lidar"] is True
    assert values["frame_id"] == "odom" and values["real_time_factor"] == 1.0
    assert values["lidar_rays"] == 360 and values["lidar_range"] == 3.5 and values["lidar_range_min"] == 0.12
    assert values["lidar_angle_min"] == -math.pi
    assert values["lidar_angle_max"] == pytest.approx(math.pi - 2 * math.pi / 360, abs=1e-12)


# ------------------------------------------------------------------- lidars
def _node_lidar_env(seed: int, **values):
    env = vmas_ros.make_env("navigation", num_envs=2, seed=seed)
    own = sim_setup.add_node_lidars(env.world, SimParams(**values))
    return env, own


def test_the_robot_lidar_leaves_the_scenarios_observation_alone():
    """navigation observes through the 12-ray lidars it made; a 360-ray lidar on every agent beside them
    changes no observation, reward or state, step after step."""
    plain, _ = _node_lidar_env(3, robot_lidar=False, add_lidar=False)
    robot, own = _node_lidar_env(3, robot_lidar=True, lidar_rays=360, lidar_range=3.5,
                                 lidar_angle_min=-math.pi, lidar_angle_max=math.pi - 2 * math.pi / 360)
    assert sorted(own) == list(range(len(robot.world.agents)))
    lidars = sim_setup.published_lidars(robot.world, own)
    for i, agent in enumerate(robot.world.agents):
        assert agent.sensors[0].n_rays == 12, "the scenario's lidar keeps its place"
        assert [s.n_rays for s in lidars[i]] == [360, 12], "the node's lidar is published first"
    rng = torch.Generator().manual_seed(0)
    observations = [plain.reset(), robot.reset()]
    for step in range(8):
        assert all(torch.equal(a, b) for a, b in zip(*observations)), f"observations differ at step {step}"
        actions = [torch.rand(2, 2, generator=rng) * 2 - 1 for _ in plain.agents]
        (obs_a, rew_a, _, _), (obs_b, rew_b, _, _) = plain.step(actions), robot.step(actions)
        assert all(torch.equal(a, b) for a, b in zip(rew_a, rew_b))
        observations = [obs_a, obs_b]
        for lidar in own.values():
            assert lidar.measure().shape == (2, 360)


def test_add_lidar_only_lidarless_agents_and_robot_lidar_all():
    env, own = _node_lidar_env(0, add_lidar=True, robot_lidar=False)
    assert own == {}, "navigation's agents carry lidars already"
    env = vmas_ros.make_env("simple_spread", num_envs=1, seed=0)
    own = sim_setup.add_node_lidars(env.world, SimParams(add_lidar=False, robot_lidar=False))
    assert own == {} and not any(a.sensors for a in env.world.agents)


@pytest.mark.parametrize("rays, low, high", [
    (16, 0.0, 2 * math.pi),  # the default: a full circle, no ray twice
    (360, -math.pi, math.pi - 2 * math.pi / 360),  # a real lidar's, as the robot profile sets it
    (181, -math.pi / 2, math.pi / 2),  # a half circle, both ends measured
    (7, -math.pi, math.pi),  # a full circle written as -pi .. pi
])
def test_laser_scan_geometry_counts_the_rays(rays, low, high):
    env = vmas_ros.make_env("simple_spread", num_envs=1, seed=0)
    own = sim_setup.add_node_lidars(env.world, SimParams(lidar_rays=rays, lidar_angle_min=low, lidar_angle_max=high,
                                                         lidar_range_min=0.12))
    geometry = sim_setup.scan_geometry(sim_setup.published_lidars(env.world, own), own, 0.12)[0][0]
    assert round((geometry.angle_max - geometry.angle_min) / geometry.angle_increment) + 1 == rays
    assert geometry.angle_min == pytest.approx(low, abs=1e-6) and geometry.range_min == 0.12
    full = (high - low) % (2 * math.pi) < 1e-5
    assert geometry.angle_max == pytest.approx(low + 2 * math.pi * (rays - 1) / rays if full else high, abs=1e-5)


# -------------------------------------------------------------------- goals
@pytest.mark.parametrize("scenario, kwargs, expected", [
    ("navigation", {"n_agents": 3}, {0: 0, 1: 1, 2: 2}),  # goal i is landmark i
    ("goal", {}, {0: 0}),  # one agent, the scenario's goal
    ("transport", {}, {}),  # the goal is the package's, not an agent's
    ("simple_spread", {}, {}),
])
def test_agents_with_a_goal(scenario, kwargs, expected):
    env = vmas_ros.make_env(scenario, num_envs=1, seed=0, **kwargs)
    rows = sim_setup.goal_rows(env.world, env.scenario)
    assert rows == expected
    for i, k in rows.items():
        goal = getattr(env.world.agents[i], "goal", None) or env.scenario.goal
        assert env.world.entities[k] is goal


# ------------------------------------------------------------ the policy's
class _Log:
    def __init__(self) -> None:
        self.lines = []

    def info(self, text: str) -> None:
        self.lines.append(text)


def _metadata(directory: Path, scenario: str = "navigation", kwargs=None) -> str:
    """A policy's JSON as the exporter writes it (the ONNX beside it is not read to learn the scenario)."""
    meta = {
        "format": "vmas_ros.policy", "version": 1, "scenario": scenario, "scenario_kwargs": kwargs or {},
        "algorithm": "test", "agents": ["agent_0", "agent_1"], "observation_size": 18, "action_size": 2,
        "action_low": [-1.0, -1.0], "action_high": [1.0, 1.0], "action_type": "continuous",
        "onnx_file": "p.onnx", "onnx_sha256": hashlib.sha256(b"").hexdigest(), "created_by": "test",
    }
    path = directory / "p.json"
    path.write_text(json.dumps(meta))
    return str(path)


def test_the_scenario_comes_from_the_policy_unless_given(tmp_path):
    path = _metadata(tmp_path, kwargs={"n_agents": 2})
    log = _Log()
    policy = {"control": "policy", "policy_path": path}
    taken = sim_setup.parameters_from_policy({}, policy, log)
    assert taken == {"scenario": "navigation", "scenario_kwargs": '{"n_agents": 2}'}
    assert log.lines == [
        f'scenario navigation and scenario_kwargs {{"n_agents": 2}} from the policy\'s metadata {path}']
    # given in code or on the command line: kept, whatever the value (the default included)
    assert sim_setup.parameters_from_policy({"scenario": "simple_spread"}, policy, log) == {}
    assert sim_setup.parameters_from_policy({}, {**policy, "scenario": "simple_spread"}, log) == {}
    assert sim_setup.parameters_from_policy({}, {**policy, "scenario_kwargs": "{}"}, log) == {"scenario": "navigation"}
    assert sim_setup.parameters_from_policy({}, {**policy, "scenario": "navigation"}, log) == {
        "scenario_kwargs": '{"n_agents": 2}'}
    # no policy control, or no policy: nothing read
    assert sim_setup.parameters_from_policy({}, {"policy_path": path}, log) == {}
    assert sim_setup.parameters_from_policy({"control": "policy"}, {}, log) == {}


def test_a_policy_whose_scenario_cannot_run_is_refused_naming_it(tmp_path):
    path = _metadata(tmp_path, scenario="no_such_task")
    with pytest.raises(ConfigError, match=r"names scenario 'no_such_task'"):
        sim_setup.parameters_from_policy({}, {"control": "policy", "policy_path": path}, _Log())
    Path(path).write_text("{not json")
    with pytest.raises(ConfigError, match="not valid JSON"):
        sim_setup.parameters_from_policy({}, {"control": "policy", "policy_path": path}, _Log())
