"""The Lidar against analytic geometry for every shape."""
from __future__ import annotations

import math

import pytest
import torch

from test.simulator.physics_helpers import (
    T,
    place,
)
from vmas_ros.simulator.core import Agent, Box, Landmark, Line, Sphere, World
from vmas_ros.simulator.sensors import Lidar

# -------------------------------------------------------------------------- lidar

N_RAYS = 8


def _lidar_world(device, n_rays=N_RAYS, entity_filter=lambda _: True, box_rot=0.0, batch_dim=1):
    """Agent at the origin; a ball on +x, a box on +y, a vertical bar on -x, nothing on -y."""
    world = World(batch_dim=batch_dim, device=device)
    lidar = Lidar(world, n_rays=n_rays, max_range=1.0, entity_filter=entity_filter)
    agent = Agent("scanner", shape=Sphere(0.05), sensors=[lidar])
    world.add_agent(agent)
    ball = Landmark("ball", shape=Sphere(0.1))
    crate = Landmark("crate", shape=Box(length=0.2, width=0.2))
    bar = Landmark("bar", shape=Line(length=0.4))
    for e in (ball, crate, bar):
        world.add_landmark(e)
    place(agent, device)
    place(ball, device, pos=(0.5, 0.0))
    place(crate, device, pos=(0.0, 0.6), rot=box_rot)
    place(bar, device, pos=(-0.7, 0.0), rot=math.pi / 2)
    return world, agent, lidar


def test_lidar_reads_analytic_distances(device):
    world, agent, lidar = _lidar_world(device)
    ranges = lidar.measure()
    assert ranges.shape == (1, N_RAYS)
    # ray k points at k * 45 degrees: ball surface at 0.4, box face at 0.5, bar at 0.7, the rest miss
    expected = T([[0.4, 1.0, 0.5, 1.0, 0.7, 1.0, 1.0, 1.0]], device)
    torch.testing.assert_close(ranges, expected, atol=1e-5, rtol=0)


def test_lidar_sees_rotated_box_corner(device):
    _, _, lidar = _lidar_world(device, box_rot=math.pi / 4)
    # the box turned 45 degrees points a corner at the agent: 0.6 - 0.1 sqrt(2)
    assert lidar.measure()[0, 2].item() == pytest.approx(0.6 - 0.1 * math.sqrt(2), abs=1e-5)


def test_lidar_16_rays_half_angles(device):
    world, agent, lidar = _lidar_world(device, n_rays=16)
    ranges = lidar.measure()[0]
    assert ranges.shape == (16,)
    assert ranges[0].item() == pytest.approx(0.4, abs=1e-5)
    assert ranges[4].item() == pytest.approx(0.5, abs=1e-5)
    assert ranges[8].item() == pytest.approx(0.7, abs=1e-5)
    # at 22.5 degrees the ray passes 0.5 sin(22.5) = 0.19 from the ball's centre: a miss
    assert ranges[1].item() == 1.0
    # a bar of half-length 0.2 at x = -0.7 is seen by rays within atan(0.2/0.7) = 15.9 degrees only
    assert ranges[7].item() == 1.0 and ranges[9].item() == 1.0


def test_lidar_rotates_with_agent(device):
    world, agent, lidar = _lidar_world(device)
    agent.set_rot(T([math.pi / 2], device), batch_index=None)
    ranges = lidar.measure()
    # ray k now points at (k + 2) * 45 degrees
    expected = T([[0.5, 1.0, 0.7, 1.0, 1.0, 1.0, 0.4, 1.0]], device)
    torch.testing.assert_close(ranges, expected, atol=1e-5, rtol=0)


def test_lidar_follows_agent_position_per_env(device):
    world, agent, lidar = _lidar_world(device, batch_dim=2)
    agent.set_pos(T([0.2, 0.0], device), batch_index=1)
    ranges = lidar.measure()
    assert ranges[0, 0].item() == pytest.approx(0.4, abs=1e-5)
    assert ranges[1, 0].item() == pytest.approx(0.2, abs=1e-5)
    assert ranges[1, 4].item() == pytest.approx(0.9, abs=1e-5)


def test_lidar_entity_filter_excludes_entities(device):
    _, _, lidar = _lidar_world(device, entity_filter=lambda e: e.name != "ball")
    ranges = lidar.measure()
    assert ranges[0, 0].item() == 1.0, "the filtered-out ball must be invisible"
    assert ranges[0, 2].item() == pytest.approx(0.5, abs=1e-5)
    lidar.entity_filter = lambda e: False
    assert torch.equal(lidar.measure(), torch.ones(1, N_RAYS, device=device))


def test_lidar_ignores_its_own_agent_and_reads_nearest(device):
    world, agent, lidar = _lidar_world(device)
    # a second ball behind the first on the same ray: the nearer one wins
    far = Landmark("far_ball", shape=Sphere(0.1))
    world.add_landmark(far)
    place(far, device, pos=(0.8, 0.0))
    assert lidar.measure()[0, 0].item() == pytest.approx(0.4, abs=1e-5)
    place(world.landmarks[0], device, pos=(5.0, 5.0))  # move the near ball away
    assert lidar.measure()[0, 0].item() == pytest.approx(0.7, abs=1e-5)
