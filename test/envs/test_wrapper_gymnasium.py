"""``make_env(wrapper="gymnasium")``: gymnasium's own checker plus behaviour against the Environment.

Also the wrapper dispatch of ``make_env`` (names, enums, errors, lazy imports),
which every wrapper shares.
"""
from __future__ import annotations

import subprocess
import sys
import warnings

import gymnasium
import numpy as np
import pytest
import torch
from gymnasium import spaces
from gymnasium.utils.env_checker import check_env

import vmas_ros
from vmas_ros.envs import Environment
from vmas_ros.envs.gymnasium_env import GymnasiumEnv, GymnasiumWrapper
from vmas_ros.simulator.environment import Wrapper


def make(device="cpu", **kwargs):
    kwargs.setdefault("num_envs", 1)
    kwargs.setdefault("seed", 0)
    kwargs.setdefault("max_steps", 8)
    return vmas_ros.make_env("simple_spread", device=device, wrapper="gymnasium", **kwargs)


def zero_action(env):
    return [np.zeros(space.shape, dtype=space.dtype) for space in env.action_space]


# ----------------------------------------------------------------------- checker


@pytest.mark.parametrize("continuous", [True, False])
@pytest.mark.parametrize("dict_spaces", [False, True])
def test_gymnasium_check_env(device, continuous, dict_spaces):
    env = make(device, continuous_actions=continuous, dict_spaces=dict_spaces, wrapper_kwargs={"sum_rewards": True})
    assert isinstance(env, gymnasium.Env)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env)
    # only the checker's remarks on unbounded observation boxes and the missing registry spec
    # remain, plus two on VMAS's conventions: env.unwrapped is the Environment, and
    # observations for a Tuple space come as a list (Tuple.contains accepts it)
    allowed = ("infinity", "spec", "unwrapped", "expecting a tuple, actual type: <class 'list'>")
    assert [str(w.message) for w in caught if not any(a in str(w.message) for a in allowed)] == []


def test_check_env_with_per_agent_rewards_only_warns_about_reward_type():
    env = make()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env)
    messages = [str(w.message) for w in caught if "reward" in str(w.message)]
    assert messages and all("must be a float" in m for m in messages)


# ----------------------------------------------------------------------- spaces, outputs


def test_unwrapped_is_the_environment_as_vmas_code_expects():
    env = make()
    assert isinstance(env, GymnasiumWrapper) and GymnasiumEnv is GymnasiumWrapper
    assert isinstance(env.unwrapped, Environment) and env.unwrapped is env.env
    assert len(env.observation_space) == env.unwrapped.n_agents == len(env.action_space)
    env.reset(seed=0)
    # VMAS code steps with the Environment's own [1, size] random actions
    obs, reward, terminated, truncated, info = env.step(env.unwrapped.get_random_actions())
    assert env.observation_space.contains(obs) and len(reward) == 3
    discrete = make(continuous_actions=False)
    discrete.reset(seed=0)
    discrete.step([discrete.unwrapped.get_random_action(agent) for agent in discrete.unwrapped.agents])


def test_spaces_are_the_environments(device):
    env = make(device, continuous_actions=False, multidiscrete_actions=True)
    assert env.observation_space == env.env.observation_space
    assert env.action_space == env.env.action_space
    assert isinstance(env.action_space, spaces.Tuple)
    assert all(isinstance(s, spaces.MultiDiscrete) for s in env.action_space)
    dict_env = make(device, dict_spaces=True)
    assert isinstance(dict_env.observation_space, spaces.Dict)
    assert list(dict_env.observation_space.keys()) == ["agent_0", "agent_1", "agent_2"]


def test_outputs_are_numpy_and_per_agent(device):
    env = make(device)
    obs, info = env.reset(seed=1)
    assert isinstance(obs, list) and len(obs) == 3
    assert all(isinstance(o, np.ndarray) and o.dtype == np.float32 and o.shape == (14,) for o in obs)
    assert env.observation_space.contains(obs)
    assert set(info) == {"agent_0", "agent_1", "agent_2"}
    obs, reward, terminated, truncated, info = env.step(zero_action(env))
    assert isinstance(reward, list) and len(reward) == 3 and all(isinstance(r, float) for r in reward)
    assert terminated is False and truncated is False
    summed = make(device, wrapper_kwargs={"sum_rewards": True})
    summed.reset(seed=1)
    _, total, *_ = summed.step(zero_action(summed))
    assert total == pytest.approx(sum(reward), rel=1e-6)


def test_dict_spaces_give_dicts(device):
    env = make(device, dict_spaces=True)
    obs, _ = env.reset()
    assert set(obs) == {"agent_0", "agent_1", "agent_2"}
    _, reward, *_ = env.step({name: np.zeros(2, dtype=np.float32) for name in obs})
    assert set(reward) == set(obs) and all(isinstance(r, float) for r in reward.values())


def test_return_numpy_false_gives_tensors_on_the_env_device(device):
    env = make(device, wrapper_kwargs={"return_numpy": False})
    obs, _ = env.reset()
    assert all(isinstance(o, torch.Tensor) and o.device.type == device.type and o.shape == (14,) for o in obs)
    obs, reward, terminated, truncated, _ = env.step(zero_action(env))
    assert isinstance(obs, list) and all(isinstance(o, torch.Tensor) for o in obs)
    # as in VMAS: rewards and flags stay Python scalars whatever return_numpy says
    assert all(type(r) is float for r in reward) and type(terminated) is bool and type(truncated) is bool


def test_observations_equal_the_environments_for_the_same_actions(device):
    wrapped = make(device, seed=5)
    raw = vmas_ros.make_env("simple_spread", num_envs=1, device=device, seed=5, max_steps=8, terminated_truncated=True)
    obs_w, _ = wrapped.reset()
    obs_r = raw.reset()
    rng = np.random.default_rng(0)
    for _ in range(5):
        for w, r in zip(obs_w, obs_r):
            np.testing.assert_array_equal(w, r[0].cpu().numpy())
        actions = [rng.uniform(-1, 1, size=2).astype(np.float32) for _ in range(3)]
        obs_w, rew_w, term_w, trunc_w, _ = wrapped.step(actions)
        obs_r, rew_r, term_r, trunc_r, _ = raw.step([torch.as_tensor(a, device=device)[None] for a in actions])
        assert rew_w == [float(r[0]) for r in rew_r]
        assert (term_w, trunc_w) == (bool(term_r[0]), bool(trunc_r[0]))


def test_seeding_reproduces_and_different_seeds_differ():
    env = make()
    first, _ = env.reset(seed=3)
    rollout = [env.step(zero_action(env))[0] for _ in range(3)]
    again, _ = env.reset(seed=3)
    for a, b in zip(first, again):
        np.testing.assert_array_equal(a, b)
    for step_obs in rollout:
        for a, b in zip(step_obs, env.step(zero_action(env))[0]):
            np.testing.assert_array_equal(a, b)
    other, _ = env.reset(seed=4)
    assert not np.array_equal(first[0], other[0])


def test_truncation_after_max_steps():
    env = make(max_steps=3)
    env.reset()
    flags = [env.step(zero_action(env))[2:4] for _ in range(3)]
    assert flags == [(False, False), (False, False), (False, True)]


def test_render_returns_rgb_array():
    env = make()
    env.reset()
    frame = env.render()
    assert isinstance(frame, np.ndarray) and frame.ndim == 3 and frame.shape[2] == 3 and frame.dtype == np.uint8
    assert make(wrapper_kwargs={"render_mode": None}).render() is None
    # VMAS's keyword for following one agent reaches Environment.render
    assert env.render(agent_index_focus=1).shape == frame.shape
    with pytest.raises(ValueError, match="render_mode"):
        make(wrapper_kwargs={"render_mode": "human"})


# ----------------------------------------------------------------------- bad input


def test_needs_one_env_and_names_the_value():
    with pytest.raises(ValueError, match="num_envs=1, got num_envs=4.*gymnasium_vec"):
        make(num_envs=4)


def test_wrong_action_shape_names_agent_and_expected_shape(device):
    env = make(device)
    env.reset()
    actions = list(zero_action(env))
    actions[1] = np.zeros(3, dtype=np.float32)
    with pytest.raises(ValueError, match=r"agent 'agent_1' has shape \(3,\), expected \(2,\)"):
        env.step(actions)
    with pytest.raises(ValueError, match="expected actions for 3 agents"):
        env.step(zero_action(env)[:2])


def test_out_of_range_action_message_survives(device):
    env = make(device)
    env.reset()
    actions = list(zero_action(env))
    actions[2] = np.array([5.0, 0.0], dtype=np.float32)
    with pytest.raises(ValueError, match="agent 'agent_2' is out of range"):
        env.step(actions)


def test_direct_construction_needs_terminated_truncated():
    raw = vmas_ros.make_env("simple_spread", num_envs=1, seed=0)
    with pytest.raises(ValueError, match="terminated_truncated=True"):
        GymnasiumEnv(raw)


# ----------------------------------------------------------------------- dispatch


@pytest.mark.parametrize("spelling", ["gymnasium", "GYMNASIUM", Wrapper.GYMNASIUM])
def test_wrapper_spellings(spelling):
    env = vmas_ros.make_env("simple_spread", num_envs=1, wrapper=spelling)
    assert isinstance(env, GymnasiumEnv)


def test_vmas_enum_member_is_accepted():
    from vmas.simulator.environment import Wrapper as VmasWrapper

    env = vmas_ros.make_env("simple_spread", num_envs=1, wrapper=VmasWrapper.GYMNASIUM)
    assert isinstance(env, GymnasiumEnv)


def test_unknown_wrapper_lists_the_valid_ones():
    with pytest.raises(ValueError, match="'gym', 'gymnasium', 'gymnasium_vec', 'pettingzoo', 'rllib', 'torchrl'"):
        vmas_ros.make_env("simple_spread", num_envs=1, wrapper="stable_baselines")


def test_import_vmas_ros_does_not_import_the_libraries():
    code = (
        "import sys, vmas_ros, vmas_ros.envs\n"
        "vmas_ros.make_env('simple_spread', num_envs=1)\n"
        "heavy = [m for m in ('ray', 'pettingzoo', 'torchrl', 'gym') if m in sys.modules]\n"
        "assert not heavy, heavy\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)


def test_torchrl_is_dispatched_lazily_to_torchrl_env():
    from vmas_ros.envs.torchrl_env import TorchRLEnv

    env = vmas_ros.make_env("simple_spread", num_envs=2, wrapper="torchrl", seed=0)
    assert isinstance(env, TorchRLEnv)


def test_wrap_an_existing_environment():
    raw = vmas_ros.make_env("simple_spread", num_envs=1, seed=0, terminated_truncated=True)
    env = vmas_ros.envs.wrap(raw, "gymnasium", sum_rewards=True)
    assert isinstance(env, GymnasiumEnv) and env.env is raw
