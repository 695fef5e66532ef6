"""``make_env(wrapper="rllib")``: RLlib's env checker, the MultiAgentEnv contract, and one real PPO iteration."""
from __future__ import annotations

import numpy as np
import pytest
import torch
from ray.rllib.env.multi_agent_env import MultiAgentEnv
from ray.rllib.utils.pre_checks.env import check_multiagent_environments

import vmas_ros
from vmas_ros.envs import rllib_env


def make(device="cpu", **kwargs):
    kwargs.setdefault("num_envs", 1)
    kwargs.setdefault("seed", 0)
    kwargs.setdefault("max_steps", 5)
    return vmas_ros.make_env("simple_spread", device=device, wrapper="rllib", **kwargs)


@pytest.mark.parametrize("continuous", [True, False])
def test_rllib_env_checker(device, continuous):
    env = make(device, continuous_actions=continuous)
    assert isinstance(env, MultiAgentEnv)
    check_multiagent_environments(env)


def test_contract_spaces_and_all_key(device):
    env = make(device, max_steps=2)
    assert env.possible_agents == ["agent_0", "agent_1", "agent_2"]
    assert set(env.observation_spaces) == set(env.action_spaces) == set(env.possible_agents)
    for name, space in zip(env.possible_agents, env.env.observation_space):
        assert env.get_observation_space(name) is space
    obs, infos = env.reset(seed=1)
    assert set(obs) == set(infos) == set(env.agents) == set(env.possible_agents)
    assert all(env.observation_spaces[n].contains(o) for n, o in obs.items())
    actions = {n: env.action_spaces[n].sample() for n in env.agents}
    obs, rewards, terminateds, truncateds, infos = env.step(actions)
    assert terminateds["__all__"] is False and truncateds["__all__"] is False
    assert all(isinstance(r, float) for r in rewards.values())
    obs, rewards, terminateds, truncateds, infos = env.step(actions)
    assert truncateds["__all__"] is True and all(truncateds[n] for n in env.possible_agents)
    assert env.agents == []


def test_observations_equal_the_environments(device):
    wrapped = make(device, seed=9)
    raw = vmas_ros.make_env("simple_spread", num_envs=1, device=device, seed=9, max_steps=5, terminated_truncated=True)
    obs_w, _ = wrapped.reset()
    obs_r = raw.reset()
    rng = np.random.default_rng(2)
    for _ in range(3):
        for name, r in zip(wrapped.possible_agents, obs_r):
            np.testing.assert_array_equal(obs_w[name], r[0].cpu().numpy())
        actions = {n: rng.uniform(-1, 1, size=2).astype(np.float32) for n in wrapped.possible_agents}
        obs_w, *_ = wrapped.step(actions)
        obs_r, *_ = raw.step([torch.as_tensor(actions[n], device=device)[None] for n in wrapped.possible_agents])


def test_env_creator_seeds_copies_apart_and_checks_config():
    from ray.rllib.env.env_context import EnvContext

    config = {"scenario": "simple_spread", "max_steps": 5, "seed": 3, "scenario_kwargs": {"n_agents": 2}}
    first = rllib_env.env_creator(EnvContext(config, worker_index=0, vector_index=0))
    same = rllib_env.env_creator(EnvContext(config, worker_index=0, vector_index=0))
    other = rllib_env.env_creator(EnvContext(config, worker_index=1, vector_index=0))
    assert first.possible_agents == ["agent_0", "agent_1"]
    a, b, c = first.reset()[0], same.reset()[0], other.reset()[0]
    np.testing.assert_array_equal(a["agent_0"], b["agent_0"])
    assert not np.array_equal(a["agent_0"], c["agent_0"])
    unseeded = [rllib_env.env_creator({"scenario": "simple_spread"}).reset()[0]["agent_0"] for _ in range(2)]
    assert not np.array_equal(*unseeded)  # copies built from one env_config must not replay each other
    with pytest.raises(ValueError, match="'scenario'"):
        rllib_env.env_creator({"max_steps": 5})
    with pytest.raises(ValueError, match=r"env_config\['num_envs'\] is 4, but this RLlib env holds num_envs=1"):
        rllib_env.env_creator({"scenario": "simple_spread", "num_envs": 4})
    with pytest.raises(ValueError, match=r"env_config\['wrapper'\] is 'gym'"):
        rllib_env.env_creator({"scenario": "simple_spread", "wrapper": "gym"})


def test_bad_action_names_agent():
    env = make()
    env.reset()
    actions = {n: np.zeros(2, dtype=np.float32) for n in env.possible_agents}
    actions["agent_0"] = np.zeros(4, dtype=np.float32)
    with pytest.raises(ValueError, match=r"agent 'agent_0' has shape \(4,\), expected \(2,\)"):
        env.step(actions)


def test_needs_one_env():
    """The single env refuses a batch; make_env gives the batched RLlib env for one (test_wrapper_rllib_vector.py)."""
    batch = vmas_ros.make_env("simple_spread", num_envs=3, terminated_truncated=True)
    with pytest.raises(ValueError, match="num_envs=1, got num_envs=3; .*RLlibVectorMultiAgentEnv takes a batch"):
        rllib_env.RLlibMultiAgentEnv(batch)
    assert not isinstance(make(num_envs=3), MultiAgentEnv)


@pytest.mark.slow
@pytest.mark.serial  # a local Ray cluster fills the machine
def test_one_ppo_iteration_on_local_ray():
    import ray
    from ray.rllib.algorithms.ppo import PPOConfig

    name = rllib_env.register("vmas_ros_test")
    batch = 40
    # a Ray of its own (address="local"), even when another one runs on this machine
    ray.init(address="local", num_cpus=1, include_dashboard=False, log_to_driver=False)
    try:
        config = (
            PPOConfig()
            .environment(name, env_config={"scenario": "simple_spread", "max_steps": 10, "n_agents": 2, "seed": 0})
            # two env copies in the local runner: RLlib vectorizes by building copies
            .env_runners(num_env_runners=0, num_envs_per_env_runner=2, rollout_fragment_length=batch // 2)
            .learners(num_learners=0)
            .debugging(seed=0)
            .training(train_batch_size_per_learner=batch, minibatch_size=20, num_epochs=1)
            .multi_agent(policies={"shared"}, policy_mapping_fn=lambda agent_id, episode, **kwargs: "shared")
            .rl_module(model_config={"fcnet_hiddens": [16]})
        )
        algo = config.build_algo()
        try:
            result = algo.train()
            copies = [env.unwrapped for env in algo.env_runner.env.envs]
        finally:
            algo.stop()
    finally:
        ray.shutdown()
    runners = result["env_runners"]
    assert runners["num_env_steps_sampled"] == batch
    assert runners["num_agent_steps_sampled"] == {"agent_0": batch, "agent_1": batch}
    assert runners["num_module_steps_sampled"] == {"shared": 2 * batch}
    assert result["training_iteration"] == 1
    assert len(copies) == 2 and all(isinstance(c, rllib_env.RLlibMultiAgentEnv) for c in copies)
    assert not ray.is_initialized()
