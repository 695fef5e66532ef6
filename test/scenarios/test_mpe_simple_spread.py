"""simple_spread's two formulations (few envs: fewer calls; many envs: fewer passes) agree.

The parity tests against VMAS run at a handful of envs, where the scenario
takes the few-envs path; here the same states go through both paths.
"""
from __future__ import annotations

import pytest
import torch

import vmas_ros
from vmas_ros.simulator.thresholds import FEW_ENVS

BATCH = 2 * FEW_ENVS


@pytest.mark.parametrize("n_agents,obs_agents", [(3, True), (5, True), (1, True), (4, False)])
def test_many_envs_path_equals_few_envs_path(n_agents, obs_agents, device, monkeypatch):
    env = vmas_ros.make_env("simple_spread", num_envs=BATCH, device=device, seed=3, n_agents=n_agents,
                            obs_agents=obs_agents)
    env.reset()
    gen = torch.Generator().manual_seed(4)
    # crowd the agents so that some overlap (the reward's collision term) in some envs
    for agent in env.agents:
        agent.set_pos(((torch.rand(BATCH, 2, generator=gen) - 0.5) * 0.6).to(device), batch_index=None)
    env.step([torch.rand(BATCH, 2, generator=gen).to(device) * 2 - 1 for _ in env.agents])
    scenario = env.scenario
    assert not scenario._few_envs
    many_rew = scenario.reward(env.agents[0])
    many_obs = torch.stack([scenario.observation(agent) for agent in env.agents])
    monkeypatch.setattr(scenario, "_few_envs", True)
    scenario.env_observations_handed_out()  # the same state, computed afresh by the other formulation
    few_rew = scenario.reward(env.agents[0])
    few_obs = torch.stack([scenario.observation(agent) for agent in env.agents])
    assert torch.equal(many_obs, few_obs)
    torch.testing.assert_close(many_rew, few_rew, atol=1e-5, rtol=0)
    if n_agents == 1:
        return
    spacing = torch.cdist(torch.stack([a.state.pos for a in env.agents], 1), torch.stack([a.state.pos for a in env.agents], 1))
    assert ((spacing < 0.3).sum(dim=(1, 2)) > n_agents).any(), "some envs must have overlapping agents"


def test_many_envs_observations_carry_gradients(device):
    """With grad enabled the observations are written through autograd-visible copies (out= refuses them)."""
    env = vmas_ros.make_env("simple_spread", num_envs=BATCH, device=device, seed=5, grad_enabled=True)
    env.reset()
    start = env.agents[1].state.pos.clone().requires_grad_(True)
    env.agents[1].set_pos(start, batch_index=None)
    observations = [env.scenario.observation(agent) for agent in env.agents]
    observations[0].sum().backward()  # agent 0 sees agent 1 relative to itself: d/d(start) = 1 per coordinate
    assert torch.equal(start.grad, torch.ones_like(start))
