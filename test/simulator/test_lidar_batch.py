"""The batched lidar casts (lidar_batch.py) against each lidar cast alone.

``BatchedLidars`` must equal ``Lidar.cast_alone()`` bit for bit for random
states of scenarios with every shape kind, or refuse (None); ``CompiledCast``
equals it to float rounding and plans again when the world's tables change.
"""
from __future__ import annotations

import pytest
import torch

import vmas_ros
from test.simulator.lidar_setup import randomise, with_lidars
from vmas_ros.simulator.lidar_batch import BatchedLidars, CompiledCast
from vmas_ros.simulator.sensors import CollidesWith, Lidar


@pytest.mark.parametrize("scenario, kwargs", [("simple_spread", {"n_agents": 4}), ("waterfall", {}), ("wheel", {}),
                                              ("passage", {})])
@pytest.mark.parametrize("num_envs", [1, 5])
def test_batched_lidars_equal_each_cast_alone(scenario, kwargs, num_envs, device):
    env = vmas_ros.make_env(scenario, num_envs=num_envs, device=device, seed=2, **kwargs)
    with_lidars(env, (12,), max_range=1.5)
    sensors = [s for a in env.world.agents for s in a.sensors if isinstance(s, Lidar)]
    batched = BatchedLidars()
    rng = torch.Generator().manual_seed(11)
    compared = 0
    for _ in range(8):
        randomise(env, rng)
        readings = batched.cast(env.world, sensors)
        if readings is None:  # differing box/line targets: the caster casts each alone
            continue
        for sensor, reading in zip(sensors, readings):
            assert torch.equal(reading, sensor.cast_alone())
        compared += 1
    assert compared > 0


def test_batching_needs_two_lidars_of_equal_ray_counts_and_ranges(device):
    env = vmas_ros.make_env("simple_spread", num_envs=1, device=device, seed=0, n_agents=2)
    with_lidars(env, (8,))
    world = env.world
    sensors = [a.sensors[-1] for a in world.agents]
    batched = BatchedLidars()
    assert batched.cast(world, sensors[:1]) is None
    world.agents[0].add_sensor(Lidar(world, n_rays=9, max_range=2.0))
    assert batched.cast(world, [sensors[1], world.agents[0].sensors[-1]]) is None
    world.agents[0].add_sensor(Lidar(world, n_rays=8, max_range=3.0))
    assert batched.cast(world, [sensors[1], world.agents[0].sensors[-1]]) is None
    assert len(batched.cast(world, sensors)) == 2


@pytest.mark.slow
def test_a_compiled_cast_plans_again_when_the_tables_change(device):
    """CompiledCast keeps its plan while the world keeps its tables object (layout-static filters): one
    identity test per cast. A collision property change (new tables) plans again: the agent that stopped
    colliding is no longer seen."""
    env = vmas_ros.make_env("simple_spread", num_envs=1, device=device, seed=0, n_agents=3)
    world = env.world
    for agent in world.agents:
        agent.add_sensor(Lidar(world, n_rays=24, max_range=2.0, entity_filter=CollidesWith(agent)))
    world.compile_physics()
    a, b, c = world.agents
    b.set_pos(a.state.pos + torch.tensor([0.4, 0.0], device=device), batch_index=None)
    c.set_pos(a.state.pos + torch.tensor([0.0, 5.0], device=device), batch_index=None)
    sensors = [agent.sensors[0] for agent in world.agents]
    cast = CompiledCast()
    first = cast.cast(world, sensors)
    plan = cast._plan
    assert cast.cast(world, sensors) is not None and cast._plan is plan, "same tables: the same plan"
    assert (first[0] < 1.0).any(), "a sees b"
    for sensor, reading in zip(sensors, first):
        torch.testing.assert_close(reading, sensor.cast_alone(), rtol=1e-5, atol=1e-5)
    b.collide = False  # new tables: b is no target any more
    readings = cast.cast(world, sensors)
    assert cast._plan is not plan
    assert (readings[0] == 2.0).all(), "a sees nothing now"
    for sensor, reading in zip(sensors, readings):
        torch.testing.assert_close(reading, sensor.cast_alone(), rtol=1e-5, atol=1e-5)


def test_a_compiled_cast_refuses_targets_other_than_spheres(device):
    """The compiled kernel knows spheres only: with a box among the targets it refuses (None), and the
    caster casts otherwise. Refusing needs no compile."""
    env = vmas_ros.make_env("passage", num_envs=2, device=device, seed=0)
    with_lidars(env, (8,))
    env.world.compile_physics()
    sensors = [a.sensors[-1] for a in env.world.agents]
    assert CompiledCast().cast(env.world, sensors) is None
