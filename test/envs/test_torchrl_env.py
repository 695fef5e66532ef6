"""TorchRLEnv: specs TorchRL accepts, rollout shapes, batched partial resets."""
import pytest
import torch
from tensordict import TensorDict
from torchrl.envs.utils import check_env_specs

import vmas_ros
from vmas_ros.envs.torchrl_env import TorchRLEnv


def _env(scenario="balance", num_envs=4, **kwargs):
    return TorchRLEnv(vmas_ros.make_env(scenario, num_envs=num_envs, seed=0, **kwargs))


@pytest.mark.parametrize("scenario", ["balance", "simple_spread", "simple"])
def test_check_env_specs_continuous(scenario):
    check_env_specs(_env(scenario, max_steps=5))


def test_check_env_specs_discrete():
    env = _env("simple_spread", continuous_actions=False, max_steps=5)
    assert env.action_spec[("agents", "action")].dtype == torch.int64
    check_env_specs(env)
    rollout = env.rollout(7, break_when_any_done=False)
    assert rollout[("agents", "action")].shape == (4, 7, 3)


def test_rollout_shapes_and_truncation():
    env = _env("balance", num_envs=5, max_steps=4)
    n, obs = env.n_agents, env.observation_size
    rollout = env.rollout(10, break_when_any_done=False)
    assert rollout.batch_size == (5, 10)
    assert rollout[("agents", "observation")].shape == (5, 10, n, obs)
    assert rollout[("agents", "action")].shape == (5, 10, n, 2)
    assert rollout[("next", "agents", "reward")].shape == (5, 10, n, 1)
    assert rollout[("next", "agents", "done")].shape == (5, 10, n, 1)
    assert rollout[("next", "done")].shape == (5, 10, 1)
    done = rollout[("next", "done")].squeeze(-1)
    # every env is truncated on its 4th step (unless it terminated first), then auto-reset
    assert done[:, 3].all()
    truncated = rollout[("next", "truncated")].squeeze(-1)
    terminated = rollout[("next", "terminated")].squeeze(-1)
    assert torch.equal(done, truncated | terminated)
    assert torch.equal(rollout[("next", "agents", "done")][..., 0, 0], done)


def test_partial_reset_resets_only_masked_envs():
    env = _env("balance", num_envs=6)
    env.reset()
    td = env.rand_step(env.reset())
    for _ in range(3):
        td = env.rand_step(td.get("next"))
    before = td[("next", "agents", "observation")].clone()
    assert (env.env.steps == 4).all()
    mask = torch.tensor([True, False, True, False, False, True])
    # as step_and_maybe_reset does: the current state plus "_reset" where envs should restart
    state = td.get("next").exclude("reward", ("agents", "reward")).clone()
    state.set("_reset", mask.unsqueeze(-1))
    out = env.reset(state)
    assert torch.equal(env.env.steps == 0, mask)
    after = out[("agents", "observation")]
    assert torch.equal(after[~mask], before[~mask])
    assert not torch.allclose(after[mask], before[mask])
    assert not out["done"].any()


def test_reset_through_agent_group_mask():
    env = _env("balance", num_envs=3)
    td = env.rand_step(env.reset())
    mask = torch.zeros(3, env.n_agents, 1, dtype=torch.bool)
    mask[1, 0] = True
    env.reset(TensorDict({("agents", "_reset"): mask}, batch_size=[3]))
    assert env.env.steps.tolist() == [1, 0, 1]


def test_device_follows_env():
    base = vmas_ros.make_env("balance", num_envs=2)
    env = TorchRLEnv(base)
    assert env.device == base.device
    assert env.reset()[("agents", "observation")].device == base.device


def test_refuses_heterogeneous_agents():
    with pytest.raises(ValueError, match="same observation size.*adversary_0=8"):
        _env("simple_adversary")
    with pytest.raises(ValueError, match="observation size"):
        _env("simple_speaker_listener")
