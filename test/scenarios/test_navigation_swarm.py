"""navigation at swarm size: the stacked step, the grid's collision term and LIDAR, against the small-team forms.

From GRID_MIN_SPHERES agents the collision term tests only the pairs the grid
finds and the lidars see only the agents within reach; the rewards, infos and
observations must be what every-pair comparison gives, and the stacked step
must give the episode of the list.
"""
from __future__ import annotations

import math

import torch

import vmas_ros
from vmas_ros.simulator.thresholds import GRID_MIN_LIDARS, GRID_MIN_SPHERES

N = max(GRID_MIN_SPHERES, GRID_MIN_LIDARS)


def _env(device, seed=0, num_envs=2, crowd=None):
    """A swarm spawned in the swarm layout (side 0.5 sqrt(N)); ``crowd``: then squeezed into a square of that
    side (spawning there would find no room for every agent and goal)."""
    side = 0.25 * math.sqrt(N)
    env = vmas_ros.make_env("navigation", num_envs=num_envs, device=device, seed=seed, n_agents=N,
                            agent_radius=0.05, world_spawning_x=side, world_spawning_y=side)
    if crowd is not None:
        generator = torch.Generator().manual_seed(seed)
        for agent in env.agents:
            agent.set_pos(((torch.rand(num_envs, 2, generator=generator) - 0.5) * crowd).to(device), batch_index=None)
    return env


def _every_pair_counts(pos: torch.Tensor, radius: float) -> torch.Tensor:
    """The collision term's counts by VMAS's rule, every pair at once: [B, n]."""
    centres = torch.linalg.vector_norm(pos.unsqueeze(2) - pos.unsqueeze(1), dim=-1)
    others = ~torch.eye(pos.shape[1], dtype=torch.bool, device=pos.device)
    in_play = (centres <= 2 * radius).any(dim=0, keepdim=True) & others
    return ((centres - 2 * radius <= 0.005) & in_play).sum(dim=-1)


def test_swarm_collision_counts_follow_the_batch_wide_rule(device):
    env = _env(device, num_envs=3, crowd=2.0)  # crowded: many touching pairs
    scenario = env.scenario
    pos, _ = scenario._positions()
    pos = pos.clone()
    # agents 0 and 1 overlap in env 0 and only touch in env 1: counted in both; agents 2 and 3 only
    # touch (no overlap in any env): never counted
    far = torch.tensor([50.0, 50.0], device=device)
    pos[:, 0:4] = far + torch.tensor([[0.0, 0.0], [3.0, 0.0], [6.0, 0.0], [9.0, 0.0]], device=device)
    pos[0, 1] = pos[0, 0] + torch.tensor([0.09, 0.0], device=device)
    pos[1, 1] = pos[1, 0] + torch.tensor([0.103, 0.0], device=device)
    pos[:, 3] = pos[:, 2] + torch.tensor([0.103, 0.0], device=device)
    counts = scenario._collision_counts(pos)
    assert torch.equal(counts, _every_pair_counts(pos, 0.05))
    assert counts[0, 0] == 1 and counts[1, 0] == 1 and counts[2, 0] == 0 and (counts[:, 2] == 0).all()
    assert int(counts.sum()) > 20, "the crowd must touch for the comparison to mean anything"


def test_stacked_swarm_step_is_the_list_step(device):
    envs = [_env(device, seed=4) for _ in range(2)]
    generator = torch.Generator().manual_seed(0)
    for _ in range(4):
        actions = (torch.rand(N, 2, 2, generator=generator) * 2 - 1).to(device)
        obs, rews, dones, infos = envs[0].step(actions)
        obs_l, rews_l, dones_l, infos_l = envs[1].step(list(actions))
        assert torch.equal(obs, torch.stack(obs_l)) and torch.equal(rews, torch.stack(rews_l))
        assert torch.equal(dones, dones_l)
        for key, value in infos.items():
            assert torch.equal(value, torch.stack([info[key] for info in infos_l])), key
    lidar = obs[:, :, 6:]
    assert (lidar > 0).any(), "some agent must see another for the lidar part to be tested"


def test_swarm_lidar_part_is_every_agents_own_cast(device):
    env = _env(device, crowd=2.0)
    obs = env.step(torch.zeros(N, 2, 2, device=device))[0]
    alone = torch.stack([agent.sensors[0].cast_alone() for agent in env.agents])
    assert torch.allclose(obs[:, :, 6:], env.scenario.lidar_range - alone, atol=1e-5, rtol=0)
    assert (alone < env.scenario.lidar_range).any()
    # what the lidars show when drawn is this cast
    assert torch.allclose(env.agents[7].sensors[0].last_measurement, alone[7], atol=1e-5, rtol=0)
