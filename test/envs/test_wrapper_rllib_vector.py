"""``make_env(..., num_envs=N, wrapper="rllib")``: the batched RLlib vector env and its env runner.

The batch must give, env by env, what the Environment gives and what RLlib's own
``SyncVectorMultiAgentEnv`` of single envs gives (autoreset included); one short
PPO run checks that RLlib samples from one batched Environment.
"""
from __future__ import annotations

import os

import numpy as np
import pytest
import torch
from gymnasium import spaces
from ray.rllib.env.multi_agent_env import MultiAgentEnv
from ray.rllib.env.vector.sync_vector_multi_agent_env import SyncVectorMultiAgentEnv
from ray.rllib.env.vector.vector_multi_agent_env import VectorMultiAgentEnv

import vmas_ros
from vmas_ros.envs import rllib_env
from vmas_ros.envs.rllib_vector import BatchedMultiAgentEnvRunner, RLlibVectorMultiAgentEnv

NAMES = ["agent_0", "agent_1", "agent_2"]


def make(num_envs=4, device="cpu", **kwargs):
    kwargs.setdefault("seed", 0)
    kwargs.setdefault("max_steps", 5)
    return vmas_ros.make_env("simple_spread", num_envs=num_envs, device=device, wrapper="rllib", **kwargs)


def fixed_actions(rng, num_envs):
    return [{n: rng.uniform(-1, 1, size=2).astype(np.float32) for n in NAMES} for _ in range(num_envs)]


def test_make_env_batches_more_than_one_env(device):
    env = make(4, device)
    assert isinstance(env, RLlibVectorMultiAgentEnv) and isinstance(env, VectorMultiAgentEnv)
    assert env.num_envs == 4 and env.env.num_envs == 4 and env.env.device == device
    assert env.metadata["autoreset_mode"] == "next_step"
    assert isinstance(make(1, device), rllib_env.RLlibMultiAgentEnv)  # one env stays the single wrapper
    assert isinstance(rllib_env.wrap(make(1, device).env, batched=True), RLlibVectorMultiAgentEnv)


def test_spaces_and_views(device):
    env = make(3, device)
    single = make(1, device)
    assert env.possible_agents == single.possible_agents == NAMES
    assert env.single_observation_spaces == single.observation_spaces
    assert env.single_action_spaces == single.action_spaces
    assert isinstance(env.single_observation_space, spaces.Dict) and isinstance(env.single_action_space, spaces.Dict)
    assert dict(env.single_action_space.spaces) == env.single_action_spaces
    assert len(env.envs) == 3
    for index, view in enumerate(env.envs):
        assert isinstance(view, MultiAgentEnv) and view.unwrapped is view and view.env is env.env
        assert view.possible_agents == view.agents == NAMES
        assert view.observation_spaces == env.single_observation_spaces
        assert all(view.get_action_space(n) is env.single_action_spaces[n] for n in NAMES)
        assert all(view.get_observation_space(n) is env.single_observation_spaces[n] for n in NAMES)
        with pytest.raises(RuntimeError, match=f"env {index} of a batched"):
            view.step({})
    obs, infos = env.reset(seed=0)
    assert len(obs) == len(infos) == 3
    assert all(env.single_observation_space.contains(o) for o in obs)


def test_steps_equal_the_environments(device):
    wrapped = make(4, device, seed=9, max_steps=50)
    raw = vmas_ros.make_env("simple_spread", num_envs=4, device=device, seed=9, max_steps=50,
                            terminated_truncated=True)
    obs_w, _ = wrapped.reset()
    obs_r = raw.reset()
    rng = np.random.default_rng(2)
    for _ in range(4):
        for i in range(4):
            for name, o in zip(NAMES, obs_r):
                np.testing.assert_array_equal(obs_w[i][name], o[i].cpu().numpy())
        actions = fixed_actions(rng, 4)
        obs_w, rew_w, term_w, trunc_w, _ = wrapped.step(actions)
        stacked = [torch.as_tensor(np.stack([a[n] for a in actions]), device=device) for n in NAMES]
        obs_r, rew_r, term_r, trunc_r, _ = raw.step(stacked)
        for i in range(4):
            assert rew_w[i] == {n: float(r[i]) for n, r in zip(NAMES, rew_r)}
            assert term_w[i]["__all__"] == bool(term_r[i]) and trunc_w[i]["__all__"] == bool(trunc_r[i])


def test_one_env_batch_equals_rllibs_sync_vector_env():
    """Through two autoresets, the batch of one env gives what RLlib's own vector env of the single env gives."""
    ours = rllib_env.wrap(make(1, seed=4, max_steps=3).env, batched=True)
    theirs = SyncVectorMultiAgentEnv([lambda: make(1, seed=4, max_steps=3)])
    results = [ours.reset(), theirs.reset()]
    rng = np.random.default_rng(0)
    ends = 0
    for step in range(8):
        _assert_same(*[r[0] for r in results])
        if step:
            for column in (1, 2, 3):
                assert list(results[0][column]) == list(results[1][column]), (step, column)
            ends += results[1][3][0]["__all__"]
        actions = fixed_actions(rng, 1)
        results = [ours.step(actions), theirs.step(actions)]
    assert ends == 2


def _assert_same(obs_a, obs_b):
    assert len(obs_a) == len(obs_b)
    for a, b in zip(obs_a, obs_b):
        assert a.keys() == b.keys()
        for name in a:
            np.testing.assert_array_equal(a[name], b[name])


def test_autoreset_resets_only_the_finished_envs(device):
    env = make(2, device, max_steps=2)
    env.reset(seed=1)
    actions = fixed_actions(np.random.default_rng(0), 2)
    env.step(actions)
    env.reset_at(0)  # env 0 starts over: from here the two envs end on different steps
    _, rewards, terminateds, truncateds, _ = env.step(actions)
    assert [t["__all__"] for t in truncateds] == [False, True]
    assert all(truncateds[1][n] for n in NAMES) and not any(terminateds[1].values())
    assert env.envs[0].agents == NAMES and env.envs[1].agents == []
    # env 1 sends no action (RLlib's runner does so for a finished env): it is reset, not stepped
    obs, rewards, terminateds, truncateds, _ = env.step([actions[0], {}])
    assert rewards[1] == dict.fromkeys(NAMES, 0.0)
    assert terminateds[1] == truncateds[1] == {**dict.fromkeys(NAMES, False), "__all__": False}
    assert truncateds[0]["__all__"] is True and rewards[0]["agent_0"] != 0.0
    assert env.env.steps.tolist() == [2, 0]
    assert env.envs[0].agents == [] and env.envs[1].agents == NAMES


def test_reset_seeds_the_batch():
    env = make(3)
    first, _ = env.reset(seed=5)
    again, _ = env.reset(seed=[5, 5, 5])
    for a, b in zip(first, again):
        _assert_same([a], [b])
    with pytest.raises(ValueError, match=r"one int seed, got \[5, 6, 7\]"):
        env.reset(seed=[5, 6, 7])


def test_discrete_actions(device):
    env = make(3, device, continuous_actions=False)
    env.reset(seed=0)
    actions = [{n: env.single_action_spaces[n].sample() for n in NAMES} for _ in range(3)]
    obs, rewards, *_ = env.step(actions)
    assert all(env.single_observation_space.contains(o) for o in obs)
    assert all(isinstance(r, float) for row in rewards for r in row.values())


@pytest.mark.parametrize("change, message", [
    (lambda a: a[:3], r"one entry per env: expected 4, got 3"),
    (lambda a: {"agent_0": a[0]}, r"list with one entry per env \(4\), got dict"),
    (lambda a: [*a[:2], {**a[2], "agent_9": a[2]["agent_0"]}, a[3]], r"actions\[2\].*unknown \['agent_9'\]"),
    (lambda a: [*a[:3], {}],
     r"actions\[3\] must have exactly the agents .*missing \['agent_0', 'agent_1', 'agent_2'\]"),
    (lambda a: [a[0], {**a[1], "agent_1": np.zeros(4, np.float32)}, *a[2:]],
     r"actions\[1\]\['agent_1'\] has shape \(4,\), expected \(2,\)"),
    (lambda a: [*a[:3], 7], r"actions\[3\] must be a dict by agent name, got int"),
])
def test_bad_actions_name_the_value_and_what_was_expected(change, message):
    env = make(4)
    env.reset()
    with pytest.raises(ValueError, match=message):
        env.step(change(fixed_actions(np.random.default_rng(0), 4)))


def test_vmas_vector_env_wrapper_methods():
    from vmas_ros.simulator.environment.rllib import VectorEnvWrapper

    assert VectorEnvWrapper is RLlibVectorMultiAgentEnv
    env = VectorEnvWrapper(vmas_ros.make_env("simple_spread", num_envs=3, seed=0, max_steps=2,
                                             terminated_truncated=True))
    assert env.get_sub_environments() == [env.env] and env.seed(3) == [3]
    obs = env.vector_reset()
    assert len(obs) == 3 and isinstance(obs[0], list) and obs[0][0].shape == (14,)
    actions = [[np.zeros(2, np.float32)] * 3 for _ in range(3)]
    obs, rewards, dones, infos = env.vector_step(actions)
    assert len(obs) == len(rewards) == len(dones) == len(infos) == 3 and dones == [False] * 3
    assert rewards[1] == pytest.approx(np.mean(list(infos[1]["rewards"].values())))
    assert set(infos[0]) == {"rewards", *NAMES}
    assert env.vector_step(actions)[2] == [True] * 3
    assert env.reset_at(1)[0].shape == (14,) and env.env.steps.tolist() == [2, 0, 2]
    assert env.try_render_at(2, mode="rgb_array").ndim == 3
    with pytest.raises(ValueError, match="one env index .* got None"):
        env.reset_at()
    with pytest.raises(ValueError, match=r"actions\[0\] must hold one action per agent .* got 2"):
        env.vector_step([[np.zeros(2, np.float32)] * 2] * 3)


def test_render_one_frame_per_env():
    frames = make(2).render()
    assert len(frames) == 2 and all(f.dtype == np.uint8 and f.ndim == 3 for f in frames)
    assert make(2, wrapper_kwargs={"render_mode": None}).render() is None


def test_from_config_batches_and_checks_num_envs():
    from ray.rllib.env.env_context import EnvContext

    config = {"scenario": "simple_spread", "max_steps": 5, "seed": 3, "scenario_kwargs": {"n_agents": 2}}
    batch = rllib_env.from_config(EnvContext(config, worker_index=1), num_envs=4, batched=True)
    single = rllib_env.from_config(EnvContext(config, worker_index=1))
    assert isinstance(batch, RLlibVectorMultiAgentEnv) and batch.num_envs == 4
    assert batch.possible_agents == single.possible_agents == ["agent_0", "agent_1"]
    assert isinstance(rllib_env.from_config({**config, "num_envs": 4}, num_envs=4, batched=True),
                      RLlibVectorMultiAgentEnv)
    with pytest.raises(ValueError, match=r"env_config\['num_envs'\] is 4, .*num_envs=1.*BatchedMultiAgentEnvRunner"):
        rllib_env.env_creator({**config, "num_envs": 4})


@pytest.mark.slow
@pytest.mark.serial  # a local Ray cluster fills the machine
def test_ppo_samples_from_one_batched_environment():
    import ray
    from ray.rllib.algorithms.ppo import PPOConfig

    os.environ.setdefault("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", "0")
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    name = rllib_env.register("vmas_ros_vector_test")
    num_envs, batch = 8, 64
    # a Ray of its own (address="local"), even when another one runs on this machine
    ray.init(address="local", num_cpus=1, include_dashboard=False, log_to_driver=False)
    try:
        config = (
            PPOConfig()
            .environment(name, env_config={"scenario": "simple_spread", "max_steps": 5, "n_agents": 2, "seed": 0})
            .env_runners(env_runner_cls=BatchedMultiAgentEnvRunner, num_env_runners=0,
                         num_envs_per_env_runner=num_envs, rollout_fragment_length=batch // num_envs)
            .learners(num_learners=0)
            .debugging(seed=0)
            .training(train_batch_size_per_learner=batch, minibatch_size=32, num_epochs=1)
            .multi_agent(policies={"shared"}, policy_mapping_fn=lambda agent_id, episode, **kwargs: "shared")
            .rl_module(model_config={"fcnet_hiddens": [16]})
        )
        algo = config.build_algo()
        try:
            result = algo.train()
            runner = algo.env_runner
            vector, views = runner.env, runner.env.envs
        finally:
            algo.stop()
    finally:
        ray.shutdown()
    assert isinstance(runner, BatchedMultiAgentEnvRunner) and isinstance(vector, RLlibVectorMultiAgentEnv)
    assert isinstance(vector.env, vmas_ros.envs.Environment) and vector.env.num_envs == num_envs
    assert len(views) == num_envs and all(view.env is vector.env for view in views)
    runners = result["env_runners"]
    assert runners["num_env_steps_sampled"] == batch
    assert runners["num_agent_steps_sampled"] == {"agent_0": batch, "agent_1": batch}
    assert runners["num_module_steps_sampled"] == {"shared": 2 * batch}
    assert runners["num_episodes"] > 0  # max_steps=5: the batch went through autoresets
    assert result["training_iteration"] == 1
    assert not ray.is_initialized()
