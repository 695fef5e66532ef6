"""Policy plumbing without a ROS graph: adapters, policy checks, batched actions, policy_node parameters.

The Environment is the reference: an adapter must rebuild exactly the vector
the scenario's ``observation()`` returns for the same state, from the messages
sim_node (or a robot) would publish for that state.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from geometry_msgs.msg import Pose, PoseArray
from nav_msgs.msg import Odometry
from std_msgs.msg import Float32MultiArray

import vmas_ros
from test.ros.policy_files import constant_push, seek_landmark, write_policy
from vmas_ros.policy import OnnxPolicy
from vmas_ros.ros import convert
from vmas_ros.simulator import env_snapshot
from vmas_ros.ros.adapters import SimpleSpreadAdapter, TopicObservations, load_adapter, odometry_state
from vmas_ros.ros.params import PolicyNodeParams, validate, validate_policy_node
from vmas_ros.ros.policy_io import action_bounds, check_policy, policy_actions


def spread_messages(env, index: int, yaws=None):
    """What sim_node publishes for env ``index``: each agent's Odometry and the landmarks' PoseArray."""
    names = env_snapshot.unique_names([a.name for a in env.agents])
    latest = {}
    for k, (name, agent) in enumerate(zip(names, env.agents)):
        odom = Odometry()
        x, y = agent.state.pos[index].tolist()
        vx, vy = agent.state.vel[index].tolist()
        yaw = float(agent.state.rot[index, 0]) if yaws is None else yaws[k]
        convert.fill_odometry(odom, x, y, yaw, vx, vy, 0.0)
        latest[f"{name}/odom"] = odom
    array = PoseArray()
    for landmark in env.world.landmarks:
        pose = Pose()
        convert.set_pose(pose, *landmark.state.pos[index].tolist(), 0.0)
        array.poses.append(pose)
    latest["landmarks/poses"] = array
    return names, latest


@pytest.mark.parametrize("n_agents,obs_agents", [(3, True), (4, True), (2, False)])
def test_simple_spread_adapter_reproduces_the_environment_observation(n_agents, obs_agents):
    env = vmas_ros.make_env("simple_spread", num_envs=3, seed=4, n_agents=n_agents, obs_agents=obs_agents)
    env.reset()
    for _ in range(7):  # moving agents: velocities are part of the observation
        obs, _, _, _ = env.step(env.get_random_actions())
    size = obs[0].shape[1]
    for index in range(3):
        # a robot's odometry has a heading: the body-frame twist must be turned back into the world frame
        for yaws in (None, [0.7 * (k + 1) for k in range(n_agents)]):
            names, latest = spread_messages(env, index, yaws)
            adapter = SimpleSpreadAdapter(names, size, obs_agents=obs_agents)
            built = adapter.build(latest)
            expected = torch.stack([o[index] for o in obs]).numpy()
            assert built.shape == (n_agents, size)
            assert np.abs(expected).max() > 0.1
            np.testing.assert_allclose(built, expected, atol=1e-5)


def test_simple_spread_adapter_leaves_rows_without_inputs_empty():
    env = vmas_ros.make_env("simple_spread", num_envs=1, seed=1)
    obs = env.reset()
    names, latest = spread_messages(env, 0)
    adapter = SimpleSpreadAdapter(names, obs[0].shape[1])
    assert set(adapter.topics()) == set(latest)
    del latest["agent_1/odom"]
    # every agent observes agent_1's position: nobody's observation can be built
    assert np.isnan(adapter.build(latest)).all()
    partial = SimpleSpreadAdapter(names, 10, obs_agents=False)
    no_others = {k: v for k, v in latest.items()}
    built = partial.build(no_others)
    assert np.isnan(built[1]).all() and np.isfinite(built[[0, 2]]).all()
    assert np.isnan(adapter.build({k: v for k, v in latest.items() if k != "landmarks/poses"})).all()
    with pytest.raises(ValueError, match="does not fit simple_spread"):
        SimpleSpreadAdapter(names, 13)


def test_odometry_state_turns_the_body_twist_into_the_world_frame():
    odom = Odometry()
    convert.fill_odometry(odom, 1.0, 2.0, math.pi / 2, 0.3, -0.1, 0.0)  # world velocity (0.3, -0.1), facing +y
    assert odom.twist.twist.linear.x == pytest.approx(-0.1) and odom.twist.twist.linear.y == pytest.approx(-0.3)
    np.testing.assert_allclose(odometry_state(odom), [1.0, 2.0, 0.3, -0.1, math.pi / 2], atol=1e-12)


def test_topic_observations_pass_vectors_through_and_reject_wrong_sizes():
    adapter = TopicObservations(["a", "b", "c"], 3)
    good, wrong = Float32MultiArray(), Float32MultiArray()
    good.data, wrong.data = [1.0, 2.0, 3.0], [1.0, 2.0]
    built = adapter.build({"a/observation": good, "b/observation": wrong})
    np.testing.assert_array_equal(built[0], [1, 2, 3])
    assert np.isnan(built[1]).all() and np.isnan(built[2]).all()


def test_load_adapter_names_the_problem():
    assert isinstance(load_adapter("", ["a"], 4, {}), TopicObservations)
    spec = "vmas_ros.ros.adapters:SimpleSpreadAdapter"
    assert isinstance(load_adapter(spec, ["a", "b"], 10, {"obs_agents": True}), SimpleSpreadAdapter)
    with pytest.raises(ValueError, match="cannot import"):
        load_adapter("vmas_ros.ros.adapters:Nope", ["a"], 4, {})
    with pytest.raises(ValueError, match="refused its arguments"):
        load_adapter(spec, ["a", "b"], 10, {"bogus": 1})
    with pytest.raises(ValueError, match="takes no adapter_kwargs"):
        load_adapter("", ["a"], 4, {"x": 1})


@pytest.mark.parametrize("name,value,fragment", [
    ("policy_path", "", "existing file"),
    ("policy_path", "/nonexistent/p.json", "existing file"),
    ("output", "twist", "output must be one of"),
    ("rate_hz", 0.0, "in [0.001, 1000]"),
    ("rate_hz", math.nan, "finite"),
    ("observation_timeout", -1.0, "> 0"),
    ("adapter", "no_colon", "package.module:Class"),
    ("adapter_kwargs", "[1, 2]", "mapping"),
    ("cmd_vel_scale", "fast", "finite"),
    ("act_on", "scans", "act_on must be one of timer, scan, got 'scans'"),
    ("nope", 1, "unknown parameter"),
])
def test_policy_node_parameters_are_validated(name, value, fragment):
    assert fragment in (validate_policy_node(name, value) or "")


def test_policy_node_defaults_are_valid_except_the_required_path(tmp_path):
    defaults = PolicyNodeParams()
    for name in PolicyNodeParams.names():
        if name != "policy_path":
            assert validate_policy_node(name, getattr(defaults, name)) is None, name
    path = constant_push(tmp_path, "p", [0.1, 0.0])
    assert validate_policy_node("policy_path", str(path)) is None


def test_sim_node_policy_parameters(tmp_path):
    from vmas_ros.ros.params import SimParams

    assert "needs policy_path" in validate("control", "policy", SimParams())
    path = constant_push(tmp_path, "p", [0.1, 0.0])
    assert validate("control", "policy", SimParams(policy_path=str(path))) is None
    assert "existing file" in validate("policy_path", str(tmp_path / "missing.json"))


def test_check_policy_finds_every_mismatch(tmp_path):
    env = vmas_ros.make_env("simple_spread", num_envs=2, seed=0)
    env.reset()
    names = [a.name for a in env.agents]
    fits = OnnxPolicy.load(seek_landmark(tmp_path, "fits"))
    assert check_policy(fits, env, names) == []
    renamed = OnnxPolicy.load(constant_push(tmp_path, "renamed", [0.1, 0.0], agents=("a", "b", "c")))
    assert any("agents" in p for p in check_policy(renamed, env, names))
    small = OnnxPolicy.load(constant_push(tmp_path, "small", [0.1, 0.0], obs_size=10))
    assert any("observation_size 10" in p for p in check_policy(small, env, names))
    wide = OnnxPolicy.load(constant_push(tmp_path, "wide", [0.1, 0.0, 0.0]))
    assert any("action_size 3" in p for p in check_policy(wide, env, names))


def test_policy_actions_are_batched_over_envs_and_clamped(tmp_path):
    env = vmas_ros.make_env("simple_spread", num_envs=5, seed=3)
    obs = env.reset()
    policy = OnnxPolicy.load(seek_landmark(tmp_path, "seek", gain=2.0))
    actions = policy_actions(policy, obs, action_bounds(env))
    assert len(actions) == 3 and all(a.shape == (5, 2) for a in actions)
    for o, a in zip(obs, actions):
        expected = (2.0 * o[:, 4:6] - o[:, 2:4]).clamp(-1, 1)
        torch.testing.assert_close(a, expected, atol=1e-6, rtol=0)
    env.step(actions)  # accepted as is by the Environment (in range, right shape)
    loud = OnnxPolicy.load(write_policy(tmp_path, "loud", np.zeros((14, 2)), [5.0, -5.0], low=-9.0, high=9.0))
    clamped = policy_actions(loud, obs, action_bounds(env))
    assert all(torch.equal(a, torch.tensor([[1.0, -1.0]] * 5)) for a in clamped)


def test_documented_adapter_example_reproduces_the_simple_scenario():
    """docs/policy_node.md's adapter example is real code: run it and compare with the Environment."""
    import re
    from pathlib import Path

    from geometry_msgs.msg import PoseStamped

    page = (Path(__file__).resolve().parents[2] / "docs" / "policy_node.md").read_text()
    section = page[page.index("## Observation adapters"):]
    block = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    namespace: dict = {}
    exec(compile(block, "docs/policy_node.md", "exec"), namespace)
    env = vmas_ros.make_env("simple", num_envs=2, seed=3)
    env.reset()
    for _ in range(4):
        obs, _, _, _ = env.step(env.get_random_actions())
    agent, landmark = env.agents[0], env.world.landmarks[0]
    odom, goal = Odometry(), PoseStamped()
    convert.fill_odometry(odom, *agent.state.pos[1].tolist(), 0.4, *agent.state.vel[1].tolist(), 0.0)
    convert.set_pose(goal.pose, *landmark.state.pos[1].tolist(), 0.0)
    adapter = namespace["GoalAdapter"](["agent_0"], obs[0].shape[1])
    assert set(adapter.topics()) == {"agent_0/odom", "agent_0/goal"}
    np.testing.assert_allclose(adapter.build({"agent_0/odom": odom, "agent_0/goal": goal})[0], obs[0][1].numpy(),
                               atol=1e-5)
    assert np.isnan(adapter.build({"agent_0/odom": odom})).all()


def test_a_policy_from_the_training_export_fits_sim_node(tmp_path):
    """The contract between vmas_ros.train.export and sim_node: an exported policy passes the start-up check."""
    from vmas_ros.train.export import describe_env, export_policy

    env = vmas_ros.make_env("simple_spread", num_envs=4, seed=0)
    obs = env.reset()
    torch.manual_seed(0)
    actor = torch.nn.Linear(14, 4)  # any network giving [..., n_agents, 2 x action_size] (loc, scale)
    _, json_path = export_policy(actor, describe_env(env), "simple_spread", {}, "test", tmp_path / "trained")
    policy = OnnxPolicy.load(json_path)
    assert check_policy(policy, env, [a.name for a in env.agents]) == []
    actions = policy_actions(policy, obs, action_bounds(env))
    assert all(a.shape == (4, 2) and a.abs().max() <= 1.0 for a in actions)
    assert any(a.abs().max() > 1e-3 for a in actions)
    env.step(actions)
