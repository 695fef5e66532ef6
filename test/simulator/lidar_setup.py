"""Lidars added as sim_node adds them, and random states to cast them in (shared by the lidar tests)."""
from __future__ import annotations

import torch

from vmas_ros.simulator.sensors import Lidar


def with_lidars(env, rays=(12,), max_range=2.0) -> None:
    """Lidars as sim_node adds them (one per entry of ``rays`` per agent), with a filter that is not
    layout-static (asked on every cast)."""
    world = env.world
    for agent in world.agents:
        for n in rays:
            agent.add_sensor(Lidar(world, n_rays=n, max_range=max_range,
                                   entity_filter=lambda e, me=agent: e.collides(me) and me.collides(e)))


def randomise(env, rng: torch.Generator) -> None:
    """Random poses and velocities, some entities overlapping (negative and +inf ranges both occur)."""
    b = env.num_envs
    for e in env.world.entities:
        e.state.pos = ((torch.rand(b, 2, generator=rng) * 2 - 1) * 1.2).to(env.device)
        e.state.vel = (torch.rand(b, 2, generator=rng) * 4 - 2).to(env.device)
        e.state.rot = (torch.rand(b, 1, generator=rng) * 20 - 10).to(env.device)
        e.state.ang_vel = (torch.rand(b, 1, generator=rng) * 6 - 3).to(env.device)
