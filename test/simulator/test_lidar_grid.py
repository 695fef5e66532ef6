"""The swarm LIDAR (rays tested only against the spheres near each lidar) against the all-target cast.

Worlds of GRID_MIN_LIDARS or more agents whose lidars see every other agent
are cast through the grid; every reading must equal each lidar's own cast
(``Lidar.cast_alone``, every target) to float rounding: sparse and dense
swarms, several envs, turned agents, mixed radii, agents on cell borders,
lists that outgrow their starting room.
"""
from __future__ import annotations

import math

import pytest
import torch

from vmas_ros.simulator.core import Agent, Box, Landmark, Sphere, World
from vmas_ros.simulator.lidar_grid import GRID_LIDAR_START_CAPACITY, grid_plan
from vmas_ros.simulator.physics.spatial_hash import CELL_MARGIN
from vmas_ros.simulator.sensors import Lidar, world_lidars
from vmas_ros.simulator.thresholds import GRID_MIN_LIDARS


def _sees_agents(entity) -> bool:
    return isinstance(entity, Agent)


def _sees_all(entity) -> bool:
    return True


_sees_agents.layout_static = _sees_all.layout_static = True


def _swarm(device, n: int, side: float, batch: int = 2, seed: int = 0, max_range: float = 0.35,
           entity_filter=_sees_agents, box: bool = False) -> World:
    world = World(batch_dim=batch, device=device)
    for i in range(n):
        lidar = Lidar(world, n_rays=12, max_range=max_range, entity_filter=entity_filter)
        world.add_agent(Agent(name=f"a{i}", shape=Sphere(radius=(0.05, 0.03, 0.08)[i % 3]), sensors=[lidar]))
    if box:
        world.add_agent(Agent(name="crate", shape=Box(length=0.3, width=0.2)))
    world.reset(None)
    generator = torch.Generator().manual_seed(seed)
    for agent in world.agents:
        agent.set_pos(((torch.rand(batch, 2, generator=generator) - 0.5) * side).to(device), batch_index=None)
        agent.set_rot((torch.rand(batch, 1, generator=generator) * 2 * math.pi).to(device), batch_index=None)
    return world


def _compare(world: World) -> torch.Tensor:
    lidars = world_lidars(world)
    caster = lidars[0]._world_caster()
    stacked = caster.stacked_readings(world, lidars)
    alone = torch.stack([lidar.cast_alone() for lidar in lidars])
    assert stacked.shape == alone.shape
    assert torch.allclose(stacked, alone, atol=1e-5, rtol=0), (stacked - alone).abs().max()
    # each lidar's own measure() reads the same row
    for lidar, row in zip(lidars[:5], stacked):
        assert torch.equal(lidar.measure(), row)
    return stacked


@pytest.mark.parametrize("side", [0.5 * math.sqrt(200), 3.0, 1.0], ids=["sparse", "crowded", "dense_cluster"])
def test_grid_readings_equal_every_target(device, side):
    world = _swarm(device, 200, side)
    assert grid_plan(world, world_lidars(world)) is not None
    readings = _compare(world)
    assert (readings < 0.35).any(), "the layout must give hits for the comparison to mean anything"
    grid = world_lidars(world)[0]._caster._grid
    if side <= 1.0:  # a dense cluster outgrows the starting room: cast again with more, nothing lost
        assert grid.capacity > GRID_LIDAR_START_CAPACITY


def test_grid_follows_the_state_and_the_agents_turning(device):
    world = _swarm(device, 100, 3.0, batch=3)
    first = _compare(world)
    for agent in world.agents:
        agent.state.force = torch.ones(3, 2, device=device)
    world.step()
    second = _compare(world)
    assert not torch.equal(first, second)


def test_agents_on_cell_borders(device):
    world = _swarm(device, 100, 3.0, batch=1)
    grid = world_lidars(world)[0]._world_caster()._grid  # plan made on the first cast
    _compare(world)
    width = grid._plan.reach * (1 + CELL_MARGIN)  # the side of the grid's cells
    # a row of agents exactly on cell borders, each within reach of the next
    for i, agent in enumerate(world.agents[:10]):
        agent.set_pos(torch.tensor([[i * width / 2, width]], device=device), batch_index=None)
    _compare(world)


def test_lidars_that_do_not_qualify_fall_back(device):
    # a box among the targets, or a filter that may read the state: cast as before, still equal
    world = _swarm(device, GRID_MIN_LIDARS, 3.0, box=True)
    assert grid_plan(world, world_lidars(world)) is None
    _compare(world)
    world = _swarm(device, GRID_MIN_LIDARS, 3.0, entity_filter=lambda e: isinstance(e, Agent))
    assert grid_plan(world, world_lidars(world)) is None
    _compare(world)


def test_lidars_that_see_landmarks_too(device):
    # goals to see besides the agents: lidars on agents, sphere landmarks among the targets
    world = World(batch_dim=2, device=device)
    for i in range(GRID_MIN_LIDARS):
        world.add_agent(Agent(name=f"a{i}", shape=Sphere(radius=0.05),
                              sensors=[Lidar(world, n_rays=8, max_range=0.5, entity_filter=_sees_all)]))
    for i in range(20):
        world.add_landmark(Landmark(name=f"post{i}", shape=Sphere(radius=0.1), collide=True))
    world.reset(None)
    generator = torch.Generator().manual_seed(3)
    for entity in world.entities:
        entity.set_pos(((torch.rand(2, 2, generator=generator) - 0.5) * 3).to(device), batch_index=None)
    assert grid_plan(world, world_lidars(world)) is not None
    _compare(world)
