"""Per-env mass and drag scales (vmas_ros/simulator/physics/scales.py): each env integrates with its own.

The formula is the paper's semi-implicit Euler step with the scaled values,
``v' = (1 - drag * s_drag) v + f / (m s_mass) dt``; envs with scale 1 give the
unscaled world's numbers bit for bit.
"""
from __future__ import annotations

import pytest
import torch

from vmas_ros.simulator.core import Agent, Landmark, Sphere, World

DT, DRAG, MASS = 0.1, 0.25, 2.0


def _world(device, scales=None, n_envs: int = 3) -> World:
    world = World(batch_dim=n_envs, device=device, dt=DT, drag=DRAG)
    world.add_landmark(Landmark("mark", collide=False))
    for name in ("a", "b"):
        world.add_agent(Agent(name, shape=Sphere(0.05), collide=False, mass=MASS, u_range=10.0))
    for i, agent in enumerate(world.agents):
        agent.set_pos(torch.tensor([[float(i), 0.0]] * n_envs, device=device), batch_index=None)
        agent.set_vel(torch.tensor([[0.5, -0.2]] * n_envs, device=device), batch_index=None)
    if scales is not None:
        world.scale_dynamics(*scales)
    return world


def _step(world: World, force) -> torch.Tensor:
    for agent in world.agents:
        agent.state.force = torch.tensor([force] * world.batch_dim, device=world.device)
    world.step()
    return torch.stack([agent.state.vel for agent in world.agents])  # [A, B, 2]


def test_each_env_integrates_with_its_own_mass_and_drag(device):
    mass = torch.tensor([1.0, 2.0, 1.0], device=device).expand(3, 3).contiguous()  # [N, B]: env 1 twice as heavy
    drag = torch.tensor([1.0, 1.0, 0.0], device=device).expand(3, 3).contiguous()  # env 2 without drag
    plain, scaled = _world(device), _world(device, (mass, drag))
    force = [1.0, 0.5]
    expected = _step(plain, force)
    got = _step(scaled, force)
    assert torch.equal(got[:, 0], expected[:, 0]), "scale 1: the unscaled step, bit for bit"
    v0 = torch.tensor([0.5, -0.2], device=device)
    f = torch.tensor(force, device=device)
    torch.testing.assert_close(got[:, 1], ((1 - DRAG) * v0 + f / (2 * MASS) * DT).expand(2, 2))
    torch.testing.assert_close(got[:, 2], (v0 + f / MASS * DT).expand(2, 2))


def test_new_scales_take_effect_in_the_same_tensors(device):
    world = _world(device, (torch.full((3, 3), 2.0, device=device), None))
    _step(world, [0.0, 0.0])
    constants = world.tables.step_constants
    world.scale_dynamics(None, torch.zeros(3, 3, device=device))  # back to unit mass, and no drag
    assert world.tables.step_constants is constants, "written in place: a compiled step keeps reading them"
    before = torch.stack([agent.state.vel for agent in world.agents])
    after = _step(world, [1.0, 1.0])
    torch.testing.assert_close(after, before + 1.0 / MASS * DT)


@pytest.mark.parametrize("mass, drag, message", [
    (torch.ones(2, 3), None, r"mass scale has shape \(2, 3\), expected \(3, 3\)"),
    (None, torch.full((3, 3), -1.0), "drag scale must be finite and >= 0"),
    (torch.zeros(3, 3), None, "mass scale must be finite and > 0"),
    ([[1.0] * 3] * 3, None, "mass scale must be a tensor"),
])
def test_bad_scales_are_refused_naming_them(mass, drag, message):
    with pytest.raises(ValueError, match=message):
        _world("cpu").scale_dynamics(mass, drag)


def test_adding_an_entity_after_scaling_asks_for_new_scales():
    world = _world("cpu", (torch.ones(3, 3), None))
    world.add_agent(Agent("c", shape=Sphere(0.05), collide=False))
    with pytest.raises(ValueError, match="call scale_dynamics again"):
        world.step()
