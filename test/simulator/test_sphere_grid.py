"""The sphere grid (a swarm's broad phase) against every pair: the same contacts, forces to float rounding.

Each world is built twice, ``sphere_grid = "off"`` (every pair in a pair
table) and ``"on"`` (the grid), from the same random state; one step must
agree within 1e-5 and, on sparse layouts, 100 steps within 1e-3. Dense
clusters make the grid outgrow its starting capacity: the step is computed
again with more room, never losing a contact.
"""
from __future__ import annotations

import math

import pytest
import torch

from vmas_ros.simulator.core import Agent, Box, Landmark, Line, Sphere, World
from vmas_ros.simulator.physics.collision.sphere_grid import candidate_pairs
from vmas_ros.simulator.physics.spatial_hash import MIN_BUCKETS, NEAR_OFFSETS as _NEAR, table_size
from vmas_ros.simulator.thresholds import GRID_MIN_SPHERES, GRID_START_CAPACITY


def _world(device, n: int, grid: str, side: float, batch: int = 3, seed: int = 0, extras: bool = False) -> World:
    world = World(batch_dim=batch, device=device)
    world.sphere_grid = grid
    for i in range(n):
        world.add_agent(Agent(name=f"s{i}", shape=Sphere(radius=(0.05, 0.03, 0.08)[i % 3])))
    if extras:  # outside the group: a static sphere, a box, a wall, and a sphere with a filter of its own
        world.add_landmark(Landmark(name="post", shape=Sphere(radius=0.2), collide=True))
        world.add_landmark(Landmark(name="crate", shape=Box(length=0.4, width=0.3), collide=True, movable=True))
        world.add_landmark(Landmark(name="wall", shape=Line(length=1.5), collide=True))
        world.add_agent(Agent(name="picky", shape=Sphere(radius=0.06), collision_filter=lambda e: e.name != "s0"))
    world.reset(None)
    generator = torch.Generator().manual_seed(seed)
    for entity in world.entities:
        entity.set_pos(((torch.rand(batch, 2, generator=generator) - 0.5) * side).to(device), batch_index=None)
        entity.set_vel(((torch.rand(batch, 2, generator=generator) - 0.5) * 0.4).to(device), batch_index=None)
    for agent in world.agents:
        agent.state.force = ((torch.rand(batch, 2, generator=generator) * 2 - 1) * 0.5).to(device)
    return world


def _state(world: World):
    return (torch.stack([e.state.pos for e in world.entities]), torch.stack([e.state.vel for e in world.entities]))


def _pair(device, n, side, **kwargs):
    off, on = _world(device, n, "off", side, **kwargs), _world(device, n, "on", side, **kwargs)
    assert not off.tables.sphere_groups and on.tables.sphere_groups
    return off, on


@pytest.mark.parametrize("side, extras", [(0.5 * math.sqrt(300), False), (2.0, True), (0.6, False)],
                         ids=["sparse", "mixed_shapes", "dense_cluster"])
def test_one_step_matches_every_pair(device, side, extras):
    off, on = _pair(device, 300, side, extras=extras)
    for _ in range(3):  # from identical states each time
        off.step()
        on.step()
        for a, b in zip(_state(off), _state(on)):
            assert torch.allclose(a, b, atol=1e-5, rtol=0), (a - b).abs().max()
        for entity_on, entity_off in zip(on.entities, off.entities):
            entity_on.set_pos(entity_off.state.pos.clone(), batch_index=None)
            entity_on.set_vel(entity_off.state.vel.clone(), batch_index=None)
    group = on.tables.sphere_groups[0]
    if side < 1.0:
        assert group.capacity > GRID_START_CAPACITY, "a dense cluster outgrows the starting capacity"
    assert int(group.needed) <= group.capacity
    if extras:  # every shape pair with an entity outside the group keeps its pair table
        kinds = {table.kind for table in on.tables.pairs}
        assert {("sphere", "sphere"), ("box", "sphere"), ("line", "sphere")} <= kinds, kinds


def test_trajectories_agree_on_a_sparse_swarm(device):
    off, on = _pair(device, 400, 0.5 * math.sqrt(400), batch=2)
    for _ in range(100):
        off.step()
        on.step()
    for a, b in zip(_state(off), _state(on)):
        assert torch.allclose(a, b, atol=1e-3, rtol=0), (a - b).abs().max()


def test_spheres_on_cell_borders_and_just_touching(device):
    """Centres on cell borders, contact distance apart to the last bit, and one far beyond the grid's range."""
    off, on = _pair(device, 150, 1.0, batch=1)
    cell = on.tables.sphere_groups[0].cell
    radius_sum = 0.05 + 0.03  # s0 and s1
    for world in (off, on):
        agents = world.agents
        agents[0].set_pos(torch.tensor([[cell * 7, cell * 3]], device=device), batch_index=None)
        agents[1].set_pos(torch.tensor([[cell * 7 + radius_sum, cell * 3]], device=device), batch_index=None)
        agents[2].set_pos(torch.tensor([[-cell * 2, cell * 5 - 1e-7]], device=device), batch_index=None)
        agents[3].set_pos(torch.tensor([[-cell * 2 + 0.01, cell * 5 + 0.1]], device=device), batch_index=None)
        # beyond the grid's coordinate range (clamped into its edge cells), still touching
        agents[4].set_pos(torch.tensor([[3e5, -3e5]], device=device), batch_index=None)
        agents[5].set_pos(torch.tensor([[3e5 + 0.0625, -3e5]], device=device), batch_index=None)
    off.step()
    on.step()
    for a, b in zip(_state(off), _state(on)):
        assert torch.allclose(a, b, atol=1e-5, rtol=0)


def test_candidates_are_every_close_pair_once():
    """candidate_pairs finds every pair within one cell width, once, and nothing across envs."""
    generator = torch.Generator().manual_seed(3)
    members, batch, cell = 500, 2, 0.1
    x = (torch.rand(batch * members, generator=generator) - 0.5) * 2.0
    y = (torch.rand(batch * members, generator=generator) - 0.5) * 2.0
    x[7], y[7] = 5e6, -5e6  # clamped to the edge cells: still found with its neighbour
    x[8], y[8] = 5e6 + 0.01, -5e6
    first, second, valid, needed = candidate_pairs(x, y, members, cell, capacity=64)
    assert int(needed) <= 64
    pairs = list(zip(first[valid].tolist(), second[valid].tolist()))
    found = set(pairs)
    assert len(pairs) == len(found), "a pair listed twice would get its contact force twice"
    points = torch.stack([x, y], 1).double()
    env = torch.arange(x.numel()) // members
    near = (torch.cdist(points, points) <= cell) & (env[:, None] == env[None, :])
    close = set(map(tuple, torch.triu(near, diagonal=1).nonzero().tolist()))
    assert close <= found, f"missed {sorted(close - found)[:5]}"
    assert all(i < j and i // members == j // members for i, j in found)
    assert (7, 8) in found


def test_groups_hold_only_spheres_that_collide_with_everything():
    world = _world("cpu", GRID_MIN_SPHERES + 10, "auto", 5.0, batch=1, extras=True)
    group = world.tables.sphere_groups[0]
    names = {world.entities[i].name for i in group.members.tolist()}
    assert "picky" not in names and "post" not in names and "crate" not in names
    assert len(names) == GRID_MIN_SPHERES + 10
    small = _world("cpu", GRID_MIN_SPHERES - 1, "auto", 5.0, batch=1)
    assert not small.tables.sphere_groups, "below the threshold the pair list is used"
    with pytest.raises(ValueError, match="sphere_grid must be 'auto', 'on' or 'off', got 'yes'"):
        world.sphere_grid = "yes"


def test_a_spheres_nine_buckets_are_always_distinct():
    """The hash's multipliers keep the nine neighbour cells in nine buckets for every table size used,
    which is what lets the candidate list skip a check for a bucket listed twice."""
    assert table_size(1) == MIN_BUCKETS and table_size(1000) == 2048
    for bits in range(MIN_BUCKETS.bit_length() - 1, 63):
        buckets = {offset & ((1 << bits) - 1) for offset in _NEAR}
        assert len(buckets) == 9, bits
