"""``make_env(wrapper="gym")``: VMAS's legacy ``gym`` wrapper conventions, and gym's own passive checker.

The wrapper keeps the pre-0.26 calling convention VMAS's ``GymWrapper`` has
(``reset() -> obs``, ``step() -> (obs, rewards, done, info)``), so gym 0.26's
full ``check_env``, which demands the newer API, does not apply; its passive
checker, which accepts the old step API, does.
"""
from __future__ import annotations

import subprocess
import sys
import warnings

import gym
import numpy as np
import pytest
import torch

import vmas_ros
from vmas_ros.envs import Environment
from vmas_ros.envs.gym_env import GymWrapper, to_gym_space
from vmas_ros.envs.wrapper_common import to_gymnasium_space
from vmas_ros.simulator.environment import Wrapper


def make(**kwargs):
    kwargs.setdefault("num_envs", 1)
    kwargs.setdefault("seed", 0)
    kwargs.setdefault("max_steps", 5)
    return vmas_ros.make_env("simple_spread", device="cpu", wrapper="gym", **kwargs)


@pytest.mark.parametrize("continuous", [True, False])
@pytest.mark.parametrize("dict_spaces", [False, True])
@pytest.mark.parametrize("return_numpy", [True, False])
def test_outputs_follow_vmas_conventions(continuous, dict_spaces, return_numpy):
    env = make(continuous_actions=continuous, dict_spaces=dict_spaces, wrapper_kwargs={"return_numpy": return_numpy})
    assert isinstance(env, GymWrapper) and isinstance(env, gym.Env)
    assert isinstance(env.unwrapped, Environment) and env.unwrapped is env.env
    n = env.unwrapped.n_agents
    container = gym.spaces.Dict if dict_spaces else gym.spaces.Tuple
    assert isinstance(env.observation_space, container) and isinstance(env.action_space, container)
    assert len(env.observation_space) == len(env.action_space) == n
    array = np.ndarray if return_numpy else torch.Tensor
    obs = env.reset()
    for _ in range(5):
        assert isinstance(obs, dict if dict_spaces else list) and len(obs) == n
        values = list(obs.values()) if dict_spaces else obs
        assert all(isinstance(o, array) and tuple(o.shape) == (14,) for o in values)
        obs, rewards, done, info = env.step(env.unwrapped.get_random_actions())
        assert isinstance(rewards, dict if dict_spaces else list) and len(rewards) == n
        assert all(type(r) is float for r in (rewards.values() if dict_spaces else rewards))
        assert type(done) is bool
        assert isinstance(info, dict) and list(info) == ["agent_0", "agent_1", "agent_2"]
    assert done  # max_steps=5


def test_gym_passive_checker(monkeypatch):
    # gym 0.26 still names numpy's np.bool8, which numpy 2 removed: give the checker its alias back
    monkeypatch.setattr(np, "bool8", np.bool_, raising=False)
    from gym.wrappers.env_checker import PassiveEnvChecker

    env = make()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        checked = PassiveEnvChecker(env)  # checks the spaces
        checked.reset(return_info=True)  # checks obs against the space and info's type
        for _ in range(3):
            checked.step(env.action_space.sample())  # first step: obs, done and info types
    allowed = (
        "infinity",  # unbounded observation boxes
        "old step API",  # one done flag, as VMAS's GymWrapper
        "must be a float, int",  # one reward per agent, as VMAS's GymWrapper
        "expecting a tuple, actual type: <class 'list'>",  # a list of observations, as VMAS's GymWrapper
    )
    assert [str(w.message) for w in caught if not any(a in str(w.message) for a in allowed)] == []
    assert any("old step API" in str(w.message) for w in caught)  # the step check did run


def test_reset_returns_info_when_asked_and_seeding_reproduces():
    env = make()
    first = env.reset(seed=3)
    obs, info = env.reset(seed=3, return_info=True)
    assert set(info) == {"agent_0", "agent_1", "agent_2"}
    for a, b in zip(first, obs):
        np.testing.assert_array_equal(a, b)
    other = env.reset(seed=4)
    assert not np.array_equal(first[0], other[0])


def test_observations_and_rewards_equal_the_environments():
    wrapped = make(seed=5)
    raw = vmas_ros.make_env("simple_spread", num_envs=1, seed=5, max_steps=5)
    obs_w, obs_r = wrapped.reset(), raw.reset()
    rng = np.random.default_rng(0)
    for _ in range(4):
        for w, r in zip(obs_w, obs_r):
            np.testing.assert_array_equal(w, r[0].numpy())
        actions = [rng.uniform(-1, 1, size=2).astype(np.float32) for _ in range(3)]
        obs_w, rew_w, done_w, _ = wrapped.step(actions)
        obs_r, rew_r, done_r, _ = raw.step([torch.as_tensor(a)[None] for a in actions])
        assert rew_w == [float(r[0]) for r in rew_r] and done_w == bool(done_r[0])


def test_spaces_convert_both_ways():
    env = make(continuous_actions=False, multidiscrete_actions=True, dict_spaces=True)
    assert all(isinstance(s, gym.spaces.MultiDiscrete) for s in env.action_space.values())
    assert to_gym_space(env.action_space) is env.action_space
    np.testing.assert_array_equal(env.action_space["agent_0"].nvec, env.unwrapped.action_space["agent_0"].nvec)
    # and back: the gymnasium wrappers convert the gym spaces an Environment has under install_as_vmas()
    for kwargs in ({"continuous_actions": False, "multidiscrete_actions": True, "dict_spaces": True}, {}):
        env = make(**kwargs)
        for gym_space, ours in ((env.action_space, env.unwrapped.action_space),
                                (env.observation_space, env.unwrapped.observation_space)):
            back = to_gymnasium_space(gym_space)
            assert back == ours and type(back) is type(ours)
    with pytest.raises(TypeError, match="expected a gymnasium or gym space, got builtins.list"):
        to_gymnasium_space([])
    with pytest.raises(TypeError, match="cannot convert .*Text"):
        from gymnasium.spaces import Text

        to_gym_space(Text(4))


def test_render_returns_rgb_array():
    env = make()
    env.reset()
    frame = env.render(mode="rgb_array")
    assert isinstance(frame, np.ndarray) and frame.ndim == 3 and frame.shape[2] == 3 and frame.dtype == np.uint8


def test_bad_input_is_refused_with_the_value():
    with pytest.raises(ValueError, match="terminated_truncated=False"):
        make(terminated_truncated=True)
    with pytest.raises(ValueError, match="num_envs=1, got num_envs=3"):
        make(num_envs=3)
    env = make()
    env.reset()
    with pytest.raises(ValueError, match=r"agent 'agent_0' has shape \(3,\), expected \(2,\)"):
        env.step([np.zeros(3, np.float32)] + [np.zeros(2, np.float32)] * 2)


@pytest.mark.parametrize("spelling", ["gym", "GYM", Wrapper.GYM])
def test_wrapper_spellings(spelling):
    assert isinstance(vmas_ros.make_env("simple_spread", num_envs=1, wrapper=spelling), GymWrapper)


def test_vmas_enum_member_is_accepted():
    from vmas.simulator.environment import Wrapper as VmasWrapper

    assert isinstance(vmas_ros.make_env("simple_spread", num_envs=1, wrapper=VmasWrapper.GYM), GymWrapper)


def test_missing_gym_names_the_extra():
    # None in sys.modules makes `import gym` fail as if it were not installed
    code = (
        "import sys\n"
        "sys.modules['gym'] = None\n"
        "import vmas_ros\n"
        "vmas_ros.make_env('simple_spread', num_envs=1)\n"
        "try:\n"
        "    vmas_ros.make_env('simple_spread', num_envs=1, wrapper='gym')\n"
        "except ImportError as error:\n"
        "    print(error)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], check=True, timeout=120, capture_output=True, text=True)
    assert "pip install vmas_ros[gym]" in out.stdout
