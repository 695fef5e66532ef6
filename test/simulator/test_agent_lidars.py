"""AgentLidars (scenario observations cast every agent's lidar once per state) against Lidar.measure()."""
from __future__ import annotations

import pytest
import torch

from vmas_ros import make_env
from vmas_ros.simulator import lidar_batch


@pytest.mark.parametrize("num_envs", [3, 1000])  # batched cast, and one lidar at a time
@pytest.mark.parametrize("name", ["flocking", "discovery"])
def test_readings_equal_measure_and_follow_the_state(name, num_envs, device):
    kwargs = {"use_agent_lidar": True} if name == "discovery" else {}
    env = make_env(name, num_envs=num_envs, device=device, seed=3, **kwargs)
    env.reset()
    scenario = env.scenario
    slots = scenario._lidars if isinstance(scenario._lidars, list) else [scenario._lidars]
    agents = [a for a in env.agents if a.sensors]
    small = num_envs * agents[0].sensors[0].n_rays <= lidar_batch.BATCH_BELOW_ELEMENTS
    assert small == (num_envs == 3)
    for step in range(4):
        env.step([torch.rand(num_envs, 2, device=device) * 2 - 1 for _ in env.agents])
        # move a lidar target next to agent 0 so some rays hit, then read again: never stale
        target = next(e for e in env.world.landmarks)
        target.set_pos(agents[0].state.pos + torch.tensor([0.12, 0.0], device=device), batch_index=None)
        first_slot = None
        for slot, lidars in enumerate(slots):
            readings = [lidars.reading(agent) for agent in agents]
            first_slot = readings if first_slot is None else first_slot
            for agent, reading in zip(agents, readings):
                expected = agent.sensors[slot].measure()
                assert torch.equal(reading, expected), (step, agent.name, slot)
                assert torch.equal(agent.sensors[slot].last_measurement, expected)
        hits = first_slot[0] < agents[0].sensors[0].max_range  # slot 0 sees the landmarks
        assert hits.any(), "the moved target should be seen"


def test_one_cast_per_state(monkeypatch):
    env = make_env("flocking", num_envs=2, device="cpu", seed=0)
    env.reset()
    calls = []
    original = lidar_batch.BatchedLidars.cast
    monkeypatch.setattr(lidar_batch.BatchedLidars, "cast", lambda *a, **k: calls.append(1) or original(*a, **k))
    env.step([torch.zeros(2, 2) for _ in env.agents])
    assert len(calls) == 1, "all agents' observations of one step should share one cast"
    env.get_from_scenario(True, False, False, False)  # same state: cached
    assert len(calls) == 1
    env.agents[1].set_pos(torch.zeros(2, 2), batch_index=None)
    env.get_from_scenario(True, False, False, False)
    assert len(calls) == 2


def test_readings_follow_targets_moved_by_set_positions(device):
    """discovery moves its targets with World.set_positions between steps; readings taken before and
    after the move must each match the state they were taken in."""
    env = make_env("discovery", num_envs=3, device=device, seed=3)
    env.step([torch.zeros(3, 2, device=device) for _ in env.agents])
    lidars, agent = env.scenario._lidars[0], env.agents[0]
    before = lidars.reading(agent).clone()
    targets = env.scenario.targets
    ahead = agent.state.pos + torch.tensor([0.1, 0.0], device=device)
    x = torch.stack([ahead[:, 0]] + [torch.full((3,), 50.0, device=device)] * (len(targets) - 1))
    y = torch.stack([ahead[:, 1]] + [torch.full((3,), 50.0, device=device)] * (len(targets) - 1))
    env.world.set_positions(targets, x, y)
    after = lidars.reading(agent)
    assert torch.equal(after, agent.sensors[0].measure())
    assert not torch.equal(after, before)
    assert (after < agent.sensors[0].max_range).any(), "the target placed next to the agent is seen"


@pytest.mark.slow
def test_compiled_worlds_cast_all_lidars_in_one_graph_close_to_measure(device):
    """A compiled world's AgentLidars read all lidars from one compiled kernel: the same distances as
    each Lidar.measure() to float rounding, some of them hits."""
    env = make_env("discovery", num_envs=5, device=device, seed=2, compile_physics=True)
    env.step([torch.zeros(5, 2, device=device) for _ in env.agents])
    lidars, agents = env.scenario._lidars[0], env.agents
    target = env.scenario.targets[0]
    target.set_pos(agents[1].state.pos + torch.tensor([0.0, 0.1], device=device), batch_index=None)
    readings = [lidars.reading(agent) for agent in agents]
    assert lidars._compiled._plan is not None and lidars._compiled._plan[1] is not None, "the compiled cast ran"
    for agent, reading in zip(agents, readings):
        torch.testing.assert_close(reading, agent.sensors[0].measure(), rtol=1e-5, atol=1e-5)
    assert (readings[1] < agents[1].sensors[0].max_range).any()


def test_layout_static_filters_are_asked_once_per_tables(device):
    """A CollidesWith filter (layout_static) is evaluated once per world tables; a collision property
    change (new tables) asks it again. Other filters are asked on every call."""
    from vmas_ros.simulator.sensors import CollidesWith

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
def test_a_compiled_cast_plans_again_when_the_tables_change(device):
    """CompiledCast keeps its plan while the world keeps its tables object (layout-static filters): one
    identity test per cast. A collision property change (new tables) plans again: the agent that stopped
    colliding is no longer seen."""
    from vmas_ros.simulator.sensors import CollidesWith, Lidar

    env = make_env("simple_spread", num_envs=1, device=device, seed=0, n_agents=3)
    world = env.world
    for agent in world.agents:
        agent.add_sensor(Lidar(world, n_rays=24, max_range=2.0, entity_filter=CollidesWith(agent)))
    world.compile_physics()
    a, b, c = world.agents
    b.set_pos(a.state.pos + torch.tensor([0.4, 0.0], device=device), batch_index=None)
    c.set_pos(a.state.pos + torch.tensor([0.0, 5.0], device=device), batch_index=None)
    sensors = [agent.sensors[0] for agent in world.agents]
    cast = lidar_batch.CompiledCast()
    first = cast.cast(world, sensors)
    plan = cast._plan
    assert cast.cast(world, sensors) is not None and cast._plan is plan, "same tables: the same plan"
    assert (first[0] < 1.0).any(), "a sees b"
    b.collide = False  # new tables: b is no target any more
    readings = cast.cast(world, sensors)
    assert cast._plan is not plan
    assert (readings[0] == 2.0).all(), "a sees nothing now"
    for sensor, reading in zip(sensors, readings):
        torch.testing.assert_close(reading, sensor.measure(), rtol=1e-5, atol=1e-5)
