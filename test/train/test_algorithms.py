"""The four algorithms: build, one tiny iteration each, and who sees / shares what."""
import pytest
import torch

from vmas_ros.train.algorithms import ALGORITHMS
from vmas_ros.train.config import TrainConfig
from vmas_ros.train.trainer import Trainer


def _tiny(algorithm, tmp_path, **overrides):
    values = dict(scenario="balance", algorithm=algorithm, iterations=1, frames_per_batch=64, num_envs=8,
                  max_steps=5, minibatch_size=32, epochs=2, num_cells=16, eval_episodes=0, out=str(tmp_path))
    values.update(overrides)
    return TrainConfig(**values)


@pytest.mark.parametrize("algorithm", sorted(ALGORITHMS))
def test_one_iteration_updates_weights(algorithm, tmp_path):
    trainer = Trainer(_tiny(algorithm, tmp_path), progress=False)
    before = [p.detach().clone() for p in trainer.agent.actor_network.parameters()]
    row = trainer.iterate()
    assert row["iteration"] == 1 and row["frames"] == 64
    assert row["episodes"] == 8  # 8 steps per env, episodes of 5 steps
    for key in ("loss_objective", "loss_critic", "step_reward_mean", "episode_reward_mean"):
        assert torch.isfinite(torch.tensor(row[key])), key
    after = list(trainer.agent.actor_network.parameters())
    assert any(not torch.equal(a, b) for a, b in zip(before, after))


def _actions_depend_on_other_agents(network, obs_size, n_agents=3):
    obs = torch.randn(4, n_agents, obs_size)
    changed = obs.clone()
    changed[:, 1] += 1.0
    with torch.no_grad():
        return not torch.allclose(network(obs)[:, 0], network(changed)[:, 0])


@pytest.mark.parametrize("algorithm, centralised_actor, centralised_critic, agent_dim", [
    ("cppo", True, True, False), ("mappo", False, True, False),
    ("ippo", False, False, False), ("hetippo", False, False, True),
])
def test_information_and_sharing(algorithm, centralised_actor, centralised_critic, agent_dim, tmp_path):
    trainer = Trainer(_tiny(algorithm, tmp_path), progress=False)
    obs_size = trainer.env_info["observation_size"]
    agent = trainer.agent
    assert _actions_depend_on_other_agents(agent.actor_network, obs_size) == centralised_actor
    assert _actions_depend_on_other_agents(agent.critic.module, obs_size) == centralised_critic
    # HetIPPO: one weight set per agent (a leading agent dimension); the others share
    if algorithm != "cppo":
        first_weight = next(iter(agent.actor_network.params.values(True, True)))
        assert (first_weight.dim() == 3) == agent_dim
    # identical observations give identical actions exactly when weights are shared and inputs local
    same = torch.randn(1, obs_size).expand(3, obs_size).unsqueeze(0)
    with torch.no_grad():
        out = agent.actor_network(same)
    assert torch.allclose(out[:, 0], out[:, 1]) == (algorithm in ("mappo", "ippo"))
