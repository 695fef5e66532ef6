"""``make_env(wrapper="gymnasium_vec")``: batched numpy outputs, SAME_STEP autoreset through ``reset_at``."""
from __future__ import annotations

import numpy as np
import pytest
import torch
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.wrappers.vector import DictInfoToList, RecordEpisodeStatistics

import vmas_ros
from vmas_ros.envs import Environment

N = 4


def make(device="cpu", **kwargs):
    kwargs.setdefault("num_envs", N)
    kwargs.setdefault("seed", 0)
    kwargs.setdefault("max_steps", 6)
    return vmas_ros.make_env("simple_spread", device=device, wrapper="gymnasium_vec", **kwargs)


def zero_actions(env):
    return tuple(np.zeros(space.shape, dtype=space.dtype) for space in env.action_space)


def test_is_a_vector_env_with_batched_spaces(device):
    env = make(device)
    assert isinstance(env, VectorEnv) and env.num_envs == N
    assert env.single_observation_space == env.env.observation_space
    assert env.single_action_space == env.env.action_space
    assert env.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP
    assert all(s.shape == (N, 14) for s in env.observation_space)
    assert all(s.shape == (N, 2) for s in env.action_space)
    obs, info = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    assert all(o.dtype == np.float32 for o in obs)
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    assert env.observation_space.contains(obs)
    assert all(r.shape == (N,) and r.dtype == np.float32 for r in reward)
    assert terminated.shape == truncated.shape == (N,) and terminated.dtype == np.bool_
    assert info["_agent_0"].all()


def test_discrete_batched_actions(device):
    env = make(device, continuous_actions=False)
    assert all(isinstance(s, spaces.MultiDiscrete) and s.shape == (N,) for s in env.action_space)
    env.reset()
    env.step(env.action_space.sample())


def test_observations_equal_the_environments(device):
    wrapped = make(device, seed=2)
    raw = vmas_ros.make_env("simple_spread", num_envs=N, device=device, seed=2, max_steps=6, terminated_truncated=True)
    obs_w, _ = wrapped.reset()
    obs_r = raw.reset()
    rng = np.random.default_rng(1)
    for _ in range(4):
        for w, r in zip(obs_w, obs_r):
            np.testing.assert_array_equal(w, r.cpu().numpy())
        actions = tuple(rng.uniform(-1, 1, size=(N, 2)).astype(np.float32) for _ in range(3))
        obs_w, rew_w, *_ = wrapped.step(actions)
        obs_r, rew_r, *_ = raw.step([torch.as_tensor(a, device=device) for a in actions])
        for w, r in zip(rew_w, rew_r):
            np.testing.assert_array_equal(w, r.cpu().numpy())


def test_same_step_autoreset_resets_only_finished_envs_with_one_reset_at(device, monkeypatch):
    env = make(device, max_steps=3)
    env.reset(seed=0)
    # envs 1 and 3 start one step later, so only 0 and 2 reach max_steps on the third step
    env.step(zero_actions(env))
    env.env.reset_at(torch.tensor([1, 3], device=env.env.device))
    env.step(zero_actions(env))
    before = [p.clone() for p in (a.state.pos for a in env.env.agents)]
    calls = []
    real_reset_at = Environment.reset_at

    def counting_reset_at(self, index, **kwargs):
        calls.append(torch.as_tensor(index).cpu().clone())
        return real_reset_at(self, index, **kwargs)

    monkeypatch.setattr(Environment, "reset_at", counting_reset_at)
    actions = tuple(np.full((N, 2), 0.5, dtype=np.float32) for _ in range(3))
    obs, reward, terminated, truncated, info = env.step(actions)
    np.testing.assert_array_equal(truncated, [True, False, True, False])
    assert len(calls) == 1 and calls[0].tolist() == [True, False, True, False]
    assert env.env.steps.tolist() == [0, 2, 0, 2]
    np.testing.assert_array_equal(info["_final_obs"], [True, False, True, False])
    assert info["final_obs"][1] is None and info["final_obs"][3] is None
    for i in (0, 2):
        # the last observation of the finished episode: positions moved by this step's action
        final_pos = info["final_obs"][i][0][:2]
        assert not np.allclose(final_pos, obs[0][i, :2])
        assert not np.allclose(final_pos, before[0][i].cpu().numpy())
    after = [a.state.pos for a in env.env.agents]
    for b, a, o in zip(before, after, obs):
        # envs that go on moved with the action; returned obs are the current (post-reset) state
        assert not torch.allclose(b[1], a[1])
        np.testing.assert_allclose(o[:, :2], a.cpu().numpy(), atol=1e-6)
    np.testing.assert_array_equal(info["final_info"]["_agent_0"], [True, False, True, False])


def test_autoreset_disabled_leaves_envs_and_reset_mask_resets(device):
    env = make(device, max_steps=2, wrapper_kwargs={"autoreset_mode": "Disabled"})
    assert env.metadata["autoreset_mode"] == AutoresetMode.DISABLED
    env.reset(seed=0)
    env.step(zero_actions(env))
    *_, truncated, info = env.step(zero_actions(env))
    assert truncated.all() and "final_obs" not in info
    assert env.env.steps.tolist() == [2, 2, 2, 2]
    mask = np.array([False, True, True, False])
    env.reset(options={"reset_mask": mask})
    assert env.env.steps.tolist() == [2, 0, 0, 2]
    with pytest.raises(ValueError, match="reset_mask"):
        env.reset(options={"reset_mask": np.array([1, 0, 0, 1])})


def test_seeding_reproduces():
    env = make()
    a, _ = env.reset(seed=7)
    b, _ = env.reset(seed=7)
    c, _ = env.reset(seed=8)
    np.testing.assert_array_equal(a[0], b[0])
    assert not np.array_equal(a[0], c[0])
    d, _ = env.reset(seed=[7] * N)
    np.testing.assert_array_equal(a[0], d[0])
    with pytest.raises(ValueError, match="one int seed"):
        env.reset(seed=list(range(N)))


def test_gymnasium_vector_wrappers_run_on_summed_rewards():
    env = DictInfoToList(RecordEpisodeStatistics(make(max_steps=3, wrapper_kwargs={"sum_rewards": True})))
    env.reset(seed=0)
    for _ in range(3):
        obs, reward, terminated, truncated, infos = env.step(env.action_space.sample())
    assert reward.shape == (N,) and truncated.all()
    assert isinstance(infos, list) and len(infos) == N
    assert all(info["episode"]["l"] == 3 for info in infos)


def test_wrong_batched_action_shape_names_agent(device):
    env = make(device)
    env.reset()
    actions = list(zero_actions(env))
    actions[0] = np.zeros((N - 1, 2), dtype=np.float32)
    with pytest.raises(ValueError, match=rf"agent 'agent_0' has shape \({N - 1}, 2\), expected \({N}, 2\)"):
        env.step(tuple(actions))


def test_render_gives_one_frame_per_requested_env():
    env = make(wrapper_kwargs={"render_env_indices": [0, 2]})
    env.reset()
    frames = env.render()
    assert len(frames) == 2 and all(f.ndim == 3 and f.shape[2] == 3 for f in frames)
    assert not np.array_equal(frames[0], frames[1])  # two different random starts
