"""``make_env(wrapper="pettingzoo")``: PettingZoo's parallel API test plus behaviour against the Environment."""
from __future__ import annotations

import warnings

import numpy as np
import pytest
import torch
from pettingzoo import ParallelEnv
from pettingzoo.test import parallel_api_test, parallel_seed_test

import vmas_ros


def make(device="cpu", scenario="simple_spread", **kwargs):
    kwargs.setdefault("num_envs", 1)
    kwargs.setdefault("seed", 0)
    kwargs.setdefault("max_steps", 10)
    return vmas_ros.make_env(scenario, device=device, wrapper="pettingzoo", **kwargs)


@pytest.mark.parametrize("continuous", [True, False])
@pytest.mark.parametrize("scenario", ["simple_spread", "simple_speaker_listener"])
def test_parallel_api_test(device, continuous, scenario):
    env = make(device, scenario, continuous_actions=continuous)
    assert isinstance(env, ParallelEnv)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the API test reports soft violations as warnings
        parallel_api_test(env, num_cycles=30)


def test_parallel_seed_test():
    parallel_seed_test(lambda: make(max_steps=5))


def test_spaces_are_the_environments(device):
    env = make(device, scenario="simple_speaker_listener", continuous_actions=False)
    assert env.possible_agents == ["speaker_0", "listener_0"]
    for name, act, obs in zip(env.possible_agents, env.env.action_space, env.env.observation_space):
        assert env.action_space(name) is act
        assert env.observation_space(name) is obs


def test_agents_are_removed_when_the_episode_ends():
    env = make(max_steps=3)
    obs, infos = env.reset(seed=0)
    assert env.agents == env.possible_agents and set(obs) == set(infos) == set(env.possible_agents)
    for step in range(3):
        actions = {name: env.action_space(name).sample() for name in env.agents}
        _, rewards, terminations, truncations, _ = env.step(actions)
        assert set(rewards) == set(env.possible_agents)
        assert all(isinstance(r, float) for r in rewards.values())
        assert all(truncations[n] == (step == 2) for n in env.possible_agents)
        assert not any(terminations.values())
    assert env.agents == []
    with pytest.raises(ValueError, match="call reset"):
        env.step({})
    env.reset()
    assert env.agents == env.possible_agents


def test_observations_equal_the_environments(device):
    wrapped = make(device, seed=4)
    raw = vmas_ros.make_env("simple_spread", num_envs=1, device=device, seed=4, max_steps=10, terminated_truncated=True)
    obs_w, _ = wrapped.reset()
    obs_r = raw.reset()
    rng = np.random.default_rng(3)
    for _ in range(4):
        for name, r in zip(wrapped.possible_agents, obs_r):
            np.testing.assert_array_equal(obs_w[name], r[0].cpu().numpy())
        actions = {name: rng.uniform(-1, 1, size=2).astype(np.float32) for name in wrapped.agents}
        obs_w, rew_w, *_ = wrapped.step(actions)
        obs_r, rew_r, *_ = raw.step([torch.as_tensor(actions[n], device=device)[None] for n in wrapped.possible_agents])
        assert [rew_w[n] for n in wrapped.possible_agents] == [float(r[0]) for r in rew_r]


def test_seeding_reproduces():
    env = make()
    a, _ = env.reset(seed=11)
    b, _ = env.reset(seed=11)
    c, _ = env.reset(seed=12)
    np.testing.assert_array_equal(a["agent_0"], b["agent_0"])
    assert not np.array_equal(a["agent_0"], c["agent_0"])


def test_bad_actions_name_the_agent(device):
    env = make(device)
    env.reset()
    with pytest.raises(ValueError, match=r"agent 'agent_1' has shape \(1, 2\), expected \(2,\)"):
        env.step({"agent_0": np.zeros(2), "agent_1": np.zeros((1, 2)), "agent_2": np.zeros(2)})
    with pytest.raises(ValueError, match=r"missing \['agent_2'\]"):
        env.step({"agent_0": np.zeros(2), "agent_1": np.zeros(2)})


def test_needs_one_env():
    with pytest.raises(ValueError, match="num_envs=1, got num_envs=2"):
        make(num_envs=2)


def test_render():
    env = make()
    env.reset()
    frame = env.render()
    assert frame.ndim == 3 and frame.shape[2] == 3
