"""``Lidar.measure()`` through the world's LidarCaster against each lidar cast alone.

Scenarios read their agents' lidars with plain ``agent.sensors[k].measure()``;
the world's caster casts a layout's lidars together once per state. On an
eager world every reading must equal the lidar's own cast (``cast_alone``) bit
for bit, whichever strategy ran; on a compiled one to float rounding.
"""
from __future__ import annotations

import pytest
import torch

from vmas_ros import make_env
from vmas_ros.simulator import lidar_batch, thresholds
from vmas_ros.simulator.sensors import CollidesWith, Lidar, world_lidars

#: scenarios whose observations read every agent's lidar, and the kwargs that give them one
LIDAR_SCENARIOS = {
    "flocking": {}, "navigation": {}, "sampling": {"collisions": True}, "discovery": {"use_agent_lidar": True},
    "pollock": {"lidar": True, "n_agents": 5, "n_lines": 3, "n_boxes": 3},  # every shape kind, fewer of them
}


def _random_actions(env, generator):
    return [torch.rand(env.num_envs, env.get_agent_action_size(a), generator=generator).to(env.device) * 2 - 1
            for a in env.agents]


def _place_a_target_near(world, sensor, device, offset=(0.1, 0.0)) -> None:
    target = world.ray_targets(sensor.agent, sensor.entity_filter)[0]
    target.set_pos(sensor.agent.state.pos + torch.tensor(offset, device=device), batch_index=None)


def _count_calls(monkeypatch, owner, name: str) -> list:
    calls = []
    original = getattr(owner, name)
    monkeypatch.setattr(owner, name, lambda *a, **k: calls.append(1) or original(*a, **k))
    return calls


@pytest.mark.parametrize("num_envs", [3, 1000])  # batched together, and each lidar alone
@pytest.mark.parametrize("name", sorted(LIDAR_SCENARIOS))
def test_scenario_readings_equal_each_lidar_cast_alone(name, num_envs, device):
    env = make_env(name, num_envs=num_envs, device=device, seed=3, **LIDAR_SCENARIOS[name])
    env.reset()
    sensors = world_lidars(env.world)
    assert len(sensors) >= len(env.agents) > 1
    batched = num_envs * sensors[0].n_rays <= thresholds.LIDAR_BATCH_MAX_ELEMENTS
    assert batched == (num_envs == 3)
    generator = torch.Generator().manual_seed(0)
    hits = 0
    for step in range(3):
        env.step(_random_actions(env, generator))  # the observations measure every lidar
        # move a target of agent 0's lidar next to it so that some rays hit, then read again: never the
        # old state's reading
        _place_a_target_near(env.world, sensors[0], device)
        readings = [sensor.measure() for sensor in sensors]
        for sensor, reading in zip(sensors, readings):
            assert torch.equal(reading, sensor.cast_alone()), (step, sensor.agent.name)
            assert sensor.last_measurement is reading
        hits += int((readings[0] < sensors[0].max_range).sum())
    assert hits > 0, "agent 0 sees the target placed next to it"


def test_one_cast_per_state(monkeypatch):
    env = make_env("flocking", num_envs=2, device="cpu", seed=0)
    env.reset()
    casts = _count_calls(monkeypatch, lidar_batch.BatchedLidars, "cast")
    env.step([torch.zeros(2, 2) for _ in env.agents])
    assert len(casts) == 1, "all agents' observations of one step share one cast"
    with torch.no_grad():  # as in the step (grad mode on would want readings that carry gradients)
        env.get_from_scenario(True, False, False, False)  # the same state: kept
        assert len(casts) == 1
        env.agents[1].set_pos(torch.zeros(2, 2), batch_index=None)
        env.get_from_scenario(True, False, False, False)
        assert len(casts) == 2


def test_a_layout_is_cast_as_it_was_asked_for_in_the_last_state(monkeypatch):
    """Lidars asked for in the last state are cast together (the first state: all of the layout);
    a scenario that reads one lidar of fifteen casts that one alone, not all fifteen for one row."""
    env = make_env("pollock", num_envs=4, device="cpu", seed=0, lidar=True)
    batches = _count_calls(monkeypatch, lidar_batch.BatchedLidars, "cast")
    alone = _count_calls(monkeypatch, Lidar, "cast_alone")
    env.reset()  # pollock's observations read every lidar: the first state casts the layout together
    env.step([torch.zeros(4, 2) for _ in env.agents])
    assert (len(batches), len(alone)) == (2, 0)
    sensors, readings = world_lidars(env.world), []
    for step in range(3):
        env.world.agents[0].set_pos(torch.full((4, 2), 0.1 * step), batch_index=None)
        readings.append(sensors[0].measure())
    assert len(batches) == 3, "the step's state asked for every lidar: still cast together"
    assert len(alone) == 2, "then only one lidar was asked for: it is cast alone"
    assert not torch.equal(readings[0], readings[2])
    assert torch.equal(readings[2], sensors[0].cast_alone())


def test_readings_follow_set_positions(device):
    """``World.set_positions`` writes a new state right after a step: readings before and after the move
    each match the state they were taken in."""
    env = make_env("flocking", num_envs=3, device=device, seed=3)
    env.step([torch.zeros(3, 2, device=device) for _ in env.agents])
    agent, sensor = env.agents[0], env.agents[0].sensors[0]
    before = sensor.measure().clone()
    obstacles = [e for e in env.world.landmarks if e.name.startswith("obstacle")]
    ahead = agent.state.pos + torch.tensor([0.1, 0.0], device=device)
    far = torch.full((3,), 50.0, device=device)
    x = torch.stack([ahead[:, 0]] + [far] * (len(obstacles) - 1))
    y = torch.stack([ahead[:, 1]] + [far] * (len(obstacles) - 1))
    env.world.set_positions(obstacles, x, y)
    after = sensor.measure()
    assert torch.equal(after, sensor.cast_alone())
    assert not torch.equal(after, before)
    assert (after < sensor.max_range).any(), "the obstacle placed next to the agent is seen"


def test_a_new_filter_or_new_tables_cast_again(device):
    """Within one state, a lidar given another filter, or a world whose collision properties changed
    (new tables: other targets), reads afresh."""
    env = make_env("simple_spread", num_envs=2, device=device, seed=0, n_agents=3)
    world = env.world
    for agent in world.agents:
        agent.add_sensor(Lidar(world, n_rays=24, max_range=2.0, entity_filter=CollidesWith(agent)))
    a, b, c = world.agents
    b.set_pos(a.state.pos + torch.tensor([0.4, 0.0], device=device), batch_index=None)
    c.set_pos(a.state.pos + torch.tensor([0.0, 5.0], device=device), batch_index=None)
    sensor = a.sensors[0]
    assert (sensor.measure() < 1.0).any(), "a sees b"
    b.collide = False
    assert (sensor.measure() == 2.0).all(), "b collides no more: not a target"
    b.collide = True
    assert (sensor.measure() < 1.0).any()
    sensor.entity_filter = lambda other: False
    assert (sensor.measure() == 2.0).all(), "the new filter sees nothing"


def test_gradients_flow_through_a_batched_reading(device):
    """A reading cast with the others carries the same gradient as the lidar cast alone; one cast under
    ``no_grad`` in the same state is not handed to a caller who wants gradients."""
    env = make_env("navigation", num_envs=2, device=device, seed=1, grad_enabled=True)
    env.reset()
    a, b = env.agents[:2]
    push = torch.zeros(2, 2, device=device, requires_grad=True)
    b.set_pos(a.state.pos + torch.tensor([0.15, 0.0], device=device) + push, batch_index=None)
    sensors = world_lidars(env.world)
    with torch.no_grad():
        silent = sensors[0].measure()
    assert not silent.requires_grad
    reading = sensors[0].measure()
    assert reading.requires_grad and (reading < sensors[0].max_range).any()
    (grad,) = torch.autograd.grad(reading.sum(), push)
    (expected,) = torch.autograd.grad(sensors[0].cast_alone().sum(), push)
    torch.testing.assert_close(grad, expected)
    assert grad.abs().sum() > 0


def test_layout_static_filters_are_asked_once_per_tables(device):
    """A CollidesWith filter (layout_static) is evaluated once per world tables; a collision property
    change (new tables) asks it again. Other filters are asked on every call."""
    env = make_env("simple_spread", num_envs=2, device=device, seed=0, n_agents=3)
    world, (a, b, c) = env.world, env.agents
    asked = []

    class Counting(CollidesWith):
        def __call__(self, other):
            asked.append(other.name)
            return super().__call__(other)

    static = Counting(a)
    first = world.ray_targets(a, static)
    assert [e.name for e in first] == [b.name, c.name] and asked
    asked.clear()
    assert world.ray_targets(a, static) is first and not asked, "cached for these tables"
    c.collide = False  # a table property: new tables
    assert [e.name for e in world.ray_targets(a, static)] == [b.name] and asked
    plain = []
    for _ in range(2):
        world.ray_targets(a, lambda e: plain.append(e.name) or e.collides(a))
    assert len(plain) == 2 * (len(world.entities) - 1), "a plain filter may read the state: asked every time"


@pytest.mark.slow
def test_compiled_worlds_read_from_one_compiled_cast_close_to_each_alone(device, monkeypatch):
    """A compiled world's lidars are read from one compiled kernel: each alone's distances to float
    rounding, some of them hits."""
    env = make_env("navigation", num_envs=5, device=device, seed=2, compile_physics=True)
    compiled = _count_calls(monkeypatch, lidar_batch.CompiledCast, "cast")
    env.step([torch.zeros(5, 2, device=device) for _ in env.agents])
    assert len(compiled) == 1, "one compiled cast for every agent's observation"
    sensors = world_lidars(env.world)
    _place_a_target_near(env.world, sensors[0], device, offset=(0.0, 0.1))
    readings = [sensor.measure() for sensor in sensors]
    assert len(compiled) == 2
    for sensor, reading in zip(sensors, readings):
        torch.testing.assert_close(reading, sensor.cast_alone(), rtol=1e-5, atol=1e-5)
    assert (readings[0] < sensors[0].max_range).any()
