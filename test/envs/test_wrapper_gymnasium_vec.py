"""``make_env(wrapper="gymnasium_vec")``: batched outputs in VMAS's containers, autoreset through ``reset_at``.

The three autoreset modes are checked step by step against gymnasium's own
``SyncVectorEnv`` of the single-env wrapper, on a deterministic scenario whose
envs finish at different steps, by termination and by truncation.
"""
from __future__ import annotations

import numpy as np
import pytest
import torch
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, SyncVectorEnv, VectorEnv
from gymnasium.wrappers.vector import DictInfoToList, RecordEpisodeStatistics

import vmas_ros
from vmas_ros.envs import Environment
from vmas_ros.simulator.core import Agent, Sphere, World
from vmas_ros.simulator.scenario import BaseScenario

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
    assert env.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    assert isinstance(env.unwrapped, Environment) and env.unwrapped is env.env
    assert len(env.observation_space) == env.unwrapped.n_agents == len(env.action_space)
    assert all(s.shape == (N, 14) for s in env.observation_space)
    assert all(s.shape == (N, 2) for s in env.action_space)
    obs, info = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    assert all(o.dtype == np.float32 for o in obs)
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    assert isinstance(obs, list) and env.observation_space.contains(obs)
    assert isinstance(reward, list) and all(r.shape == (N,) and r.dtype == np.float32 for r in reward)
    assert terminated.shape == truncated.shape == (N,) and terminated.dtype == np.bool_
    assert info["_agent_0"].all()


def test_vmas_conventions_random_actions_tensors_and_dicts(device):
    env = make(device, wrapper_kwargs={"return_numpy": False})
    obs, info = env.reset(seed=0)
    assert isinstance(obs, list) and all(isinstance(o, torch.Tensor) and o.shape == (N, 14) for o in obs)
    obs, reward, terminated, truncated, info = env.step(env.unwrapped.get_random_actions())
    assert all(isinstance(r, torch.Tensor) and r.shape == (N,) for r in reward)
    assert isinstance(terminated, torch.Tensor) and isinstance(truncated, torch.Tensor)
    dict_env = make(device, dict_spaces=True)
    obs, info = dict_env.reset(seed=0)
    assert isinstance(dict_env.observation_space, spaces.Dict) and list(obs) == ["agent_0", "agent_1", "agent_2"]
    _, reward, *_ = dict_env.step(dict_env.unwrapped.get_random_actions())
    assert list(reward) == list(obs) and all(isinstance(r, np.ndarray) for r in reward.values())


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
    env = make(device, max_steps=3, wrapper_kwargs={"autoreset_mode": AutoresetMode.SAME_STEP})
    assert env.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP
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
    with pytest.raises(ValueError, match="autoreset_mode must be one of.*got 'sometimes'"):
        make(device, wrapper_kwargs={"autoreset_mode": "sometimes"})


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
        env.step(actions)


def test_render_gives_one_frame_per_requested_env():
    env = make(wrapper_kwargs={"render_env_indices": [0, 2]})
    env.reset()
    frames = env.render()
    assert len(frames) == 2 and all(f.ndim == 3 and f.shape[2] == 3 for f in frames)
    assert not np.array_equal(frames[0], frames[1])  # two different random starts


# ------------------------------------------------------- against gymnasium's SyncVectorEnv


class _DashScenario(BaseScenario):
    """Two agents race right from ``x = -0.2``; an env terminates when one passes ``x = -0.1``.

    Nothing random, so a batch of ``N`` envs and ``N`` single-env copies see the
    same episodes for the same actions, and per-env actions make the episodes
    end at different steps.
    """

    def make_world(self, batch_dim, device, **kwargs):
        world = World(batch_dim, device)
        for i in range(2):
            world.add_agent(Agent(f"agent_{i}", shape=Sphere(0.05), collide=False))
        return world

    def reset_world_at(self, env_index=None):
        rows = () if env_index is not None else (self.world.batch_dim,)
        for i, agent in enumerate(self.world.agents):
            start = torch.tensor([-0.2, 0.3 * i], device=self.world.device).expand(*rows, 2)
            agent.set_pos(start, batch_index=env_index)
            agent.set_vel(torch.zeros_like(start), batch_index=env_index)

    def observation(self, agent):
        return torch.cat([agent.state.pos, agent.state.vel], dim=-1)

    def reward(self, agent):
        return agent.state.pos[:, 0]

    def done(self):
        return torch.stack([a.state.pos[:, 0] for a in self.world.agents], dim=-1).max(dim=-1).values > -0.1

    def info(self, agent):
        return {"x": agent.state.pos[:, 0]}


def _batched(mode):
    env = vmas_ros.make_env(_DashScenario(), num_envs=N, seed=0, max_steps=9, wrapper="gymnasium_vec",
                            wrapper_kwargs={"sum_rewards": True, "autoreset_mode": mode})
    return RecordEpisodeStatistics(env)


def _sync(mode):
    def single():
        return vmas_ros.make_env(_DashScenario, num_envs=1, seed=0, max_steps=9, wrapper="gymnasium",
                                 wrapper_kwargs={"sum_rewards": True})

    sync = SyncVectorEnv([single] * N, autoreset_mode=mode)
    # SyncVectorEnv pops options["reset_mask"], so RecordEpisodeStatistics around it takes a
    # partial reset for a full one and zeroes every env's running return: with partial resets
    # (DISABLED) ours is checked against per-env counts instead
    return sync if mode == AutoresetMode.DISABLED else RecordEpisodeStatistics(sync)


def _assert_same(ours, theirs, where, with_stats=True):
    obs_a, info_a = ours[0], ours[-1]
    obs_b, info_b = theirs[0], theirs[-1]
    assert len(obs_a) == len(obs_b)
    for a, b in zip(obs_a, obs_b):
        np.testing.assert_allclose(a, b, atol=1e-6, err_msg=where)
    for a, b in zip(ours[1:-1], theirs[1:-1]):
        np.testing.assert_allclose(np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64), atol=1e-5,
                                   err_msg=where)
    keys = ("_final_obs", "_episode") if with_stats else ("_final_obs",)
    for key in keys:
        np.testing.assert_array_equal(info_a.get(key, np.zeros(N, bool)), info_b.get(key, np.zeros(N, bool)),
                                      err_msg=f"{where}: {key}")
    if with_stats and "episode" in info_b:
        mask = info_b["_episode"]
        for stat in ("r", "l"):
            np.testing.assert_allclose(info_a["episode"][stat][mask], info_b["episode"][stat][mask], atol=1e-4,
                                       err_msg=f"{where}: episode {stat}")
    if "final_obs" in info_b:
        for i in np.flatnonzero(info_b["_final_obs"]):
            for a, b in zip(info_a["final_obs"][i], info_b["final_obs"][i]):
                np.testing.assert_allclose(a, b, atol=1e-6, err_msg=f"{where}: final_obs of env {i}")
    # infos: the same masks; values where set (gymnasium leaves zeros elsewhere)
    mask = info_b["agent_1"]["_x"]
    np.testing.assert_array_equal(info_a["agent_1"]["_x"], mask, err_msg=f"{where}: info mask")
    np.testing.assert_allclose(info_a["agent_1"]["x"][mask], info_b["agent_1"]["x"][mask], atol=1e-6,
                               err_msg=f"{where}: info")


@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP, AutoresetMode.DISABLED])
def test_each_autoreset_mode_matches_sync_vector_env_step_by_step(mode):
    ours, theirs = _batched(mode), _sync(mode)
    assert ours.metadata["autoreset_mode"] == theirs.metadata["autoreset_mode"] == mode
    stats = mode != AutoresetMode.DISABLED
    _assert_same(ours.reset(seed=0), theirs.reset(seed=0), "reset", stats)
    rng = np.random.default_rng(3)
    terminations = truncations = 0
    lengths = []
    running = np.zeros(N, dtype=int)  # steps since each env's reset, for DISABLED
    for t in range(40):
        # per-env speeds: the envs reach the line (or max_steps) at different steps
        actions = tuple(rng.uniform(-0.2, 1.0, size=(N, 2)).astype(np.float32) for _ in range(2))
        out_a, out_b = ours.step(actions), theirs.step(actions)
        _assert_same(out_a, out_b, f"{mode.name} step {t}", stats)
        terminated, truncated, info = out_b[2], out_b[3], out_a[-1]
        terminations, truncations = terminations + terminated.sum(), truncations + truncated.sum()
        if "episode" in info:
            lengths.extend(info["episode"]["l"][info["_episode"]].tolist())
        running += 1
        done = terminated | truncated
        if mode == AutoresetMode.DISABLED:
            np.testing.assert_array_equal(info.get("_episode", np.zeros(N, bool)), done)
            if done.any():
                np.testing.assert_array_equal(info["episode"]["l"][done], running[done])
                running[done] = 0
                _assert_same(ours.reset(options={"reset_mask": done.copy()}),
                             theirs.reset(options={"reset_mask": done.copy()}), f"partial reset at step {t}", stats)
    # the comparison saw many boundaries, of both kinds, and episodes of different lengths
    assert terminations >= N and truncations >= 1
    assert len(set(lengths)) >= 3 and len(lengths) >= 3 * N


def test_next_step_autoreset_is_deterministic_for_a_seed():
    def rollout():
        env = make(max_steps=3, wrapper_kwargs={"autoreset_mode": AutoresetMode.NEXT_STEP})
        obs, _ = env.reset(seed=11)
        trace = [np.concatenate(obs, axis=-1)]
        rng = np.random.default_rng(0)
        for _ in range(8):  # two autoresets, whose starts come from the seeded stream
            obs, *_ = env.step(tuple(rng.uniform(-1, 1, size=(N, 2)).astype(np.float32) for _ in range(3)))
            trace.append(np.concatenate(obs, axis=-1))
        return np.stack(trace)

    first, second = rollout(), rollout()
    np.testing.assert_array_equal(first, second)
    assert not np.allclose(first[4], first[3])  # step 4 is a reset: new random starts
