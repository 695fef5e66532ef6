"""ScenarioUtils.spawn_entities_randomly: every reset selector, one draw per selected env."""
from __future__ import annotations

import pytest
import torch

from vmas_ros.simulator.core import Agent, Sphere, World
from vmas_ros.simulator.utils import ScenarioUtils, selected_env_count

BATCH = 16


def _world(device: str = "cpu") -> World:
    world = World(BATCH, device)
    for i in range(4):
        world.add_agent(Agent(name=f"agent_{i}", shape=Sphere(0.05)))
    for agent in world.agents:
        agent.set_pos(torch.full((BATCH, 2), 5.0), batch_index=None)  # far outside the spawn box
    return world


def test_selected_env_count():
    assert selected_env_count(8, None) == 8
    assert selected_env_count(8, 3) == 1
    assert selected_env_count(8, [1, 4]) == 2
    assert selected_env_count(8, torch.tensor([0, 2, 5])) == 3
    assert selected_env_count(8, torch.tensor([True, False] * 4)) == 4


@pytest.mark.parametrize("selector", [None, 3, [1, 4, 9], "mask"])
def test_spawn_places_exactly_the_selected_envs_apart(selector):
    torch.manual_seed(0)
    world = _world()
    chosen = torch.zeros(BATCH, dtype=torch.bool)
    if selector == "mask":
        selector = torch.arange(BATCH) % 3 == 0
        chosen = selector.clone()
    elif selector is None:
        chosen[:] = True
    else:
        chosen[torch.as_tensor(selector)] = True
    ScenarioUtils.spawn_entities_randomly(world.agents, world, selector, 0.2, (-1.0, 1.0), (-1.0, 1.0))
    pos = torch.stack([a.state.pos for a in world.agents], dim=1)  # [B, A, 2]
    assert (pos[~chosen] == 5.0).all(), "envs not selected keep their positions"
    placed = pos[chosen]
    assert (placed.abs() <= 1.0).all()
    gaps = torch.cdist(placed, placed) + torch.eye(4) * 10
    assert (gaps >= 0.2).all(), "entities at least min_dist apart in every selected env"
    if int(chosen.sum()) > 1:  # each selected env got its own draw, not one copied draw
        assert not torch.equal(placed[0], placed[1])


def test_a_swarms_positions_are_drawn_at_once_every_two_apart(device):
    from vmas_ros.simulator.thresholds import GRID_MIN_SPHERES

    world = World(batch_dim=3, device=device)
    count, min_dist = 2 * GRID_MIN_SPHERES, 0.15
    torch.manual_seed(0)
    pos = ScenarioUtils.find_random_positions(count, None, world, min_dist, (-4.0, 4.0), (-3.5, 3.5))
    assert pos.shape == (3, count, 2) and pos.device.type == torch.device(device).type
    assert (pos[..., 0].abs() <= 4).all() and (pos[..., 1].abs() <= 3.5).all()
    d = torch.linalg.vector_norm(pos.unsqueeze(2) - pos.unsqueeze(1), dim=-1)
    d = d + torch.eye(count, device=pos.device) * 10
    assert float(d.min()) >= min_dist
    # crowded enough that plain uniform draws would have put some too close: the rounds redrew them
    assert float(d.min()) < 2 * min_dist
    # one env of several, as a partial reset asks
    assert ScenarioUtils.find_random_positions(count, 1, world, min_dist, (-4.0, 4.0), (-3.5, 3.5)).shape == (1, count, 2)
