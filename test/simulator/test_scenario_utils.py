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
