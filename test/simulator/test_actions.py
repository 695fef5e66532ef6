"""The physics step's action input (physics/actions.py): limits, held agents and assembly, each called directly.

The world-level effect (an agent with ``max_f`` accelerates by the clamped
force, and sees it) is in test_physics.py; here each function is checked
against values worked out by hand.
"""
from __future__ import annotations

import torch

from vmas_ros.simulator.core import Agent, Landmark, Sphere, World
from vmas_ros.simulator.physics.actions import assemble_actions, hold_agents, limit_actions


def _tables(device, **agents):
    """The tables of a world with one landmark first, then one agent per keyword (name -> Agent kwargs)."""
    world = World(batch_dim=2, device=device)
    world.add_landmark(Landmark("wall", shape=Sphere(0.1)))
    for name, kwargs in agents.items():
        world.add_agent(Agent(name, shape=Sphere(0.1), **kwargs))
    return world.tables


def test_forces_are_clamped_to_norm_then_range_and_torques_alike(device):
    tables = _tables(device, capped=dict(max_f=1.0, max_t=0.5), ranged=dict(f_range=0.5, t_range=0.2),
                     free=dict())
    force = torch.tensor([[[3.0, 4.0], [0.3, 0.4]], [[3.0, -0.25], [0.1, 0.2]], [[30.0, 40.0], [-5.0, 0.0]]],
                         device=device)  # [A=3, B=2, 2]
    torque = torch.tensor([[[2.0], [-0.1]], [[-1.0], [0.1]], [[9.0], [-9.0]]], device=device)
    limited_force, limited_torque = limit_actions(force, torque, tables)
    expected_force = torch.tensor([[[0.6, 0.8], [0.3, 0.4]], [[0.5, -0.25], [0.1, 0.2]], [[30.0, 40.0], [-5.0, 0.0]]],
                                  device=device)
    expected_torque = torch.tensor([[[0.5], [-0.1]], [[-0.2], [0.1]], [[9.0], [-9.0]]], device=device)
    torch.testing.assert_close(limited_force, expected_force, atol=1e-7, rtol=0)
    torch.testing.assert_close(limited_torque, expected_torque, atol=1e-7, rtol=0)


def test_a_held_agent_keeps_no_action_in_the_coordinates_it_is_held_in(device):
    tables = _tables(device, fixed=dict(movable=False), stiff=dict(rotatable=False), free=dict())
    force = torch.ones(3, 2, 2, device=device)
    torque = torch.ones(3, 2, 1, device=device)
    held_force, held_torque = hold_agents(force, torque, tables)
    assert torch.equal(held_force.sum(dim=(1, 2)), torch.tensor([0.0, 4.0, 4.0], device=device))
    assert torch.equal(held_torque.sum(dim=(1, 2)), torch.tensor([2.0, 0.0, 2.0], device=device))


def test_the_assembled_input_has_the_agents_rows_after_the_landmarks(device):
    tables = _tables(device, a=dict(), b=dict())
    q = torch.zeros(3, 3, 2, device=device)
    forces = [torch.tensor([[1.0, 2.0], [3.0, 4.0]], device=device),
              torch.tensor([[5.0, 6.0], [7.0, 8.0]], device=device)]
    torques = [torch.tensor([[0.5], [0.25]], device=device), torch.tensor([[-1.0], [-2.0]], device=device)]
    for given in ((forces, torques), (torch.stack(forces), torch.stack(torques))):
        actions = assemble_actions(q, tables, *given)
        assert actions.shape == (3, 3, 2) and not actions[:, 0].any(), "the landmark gets no action"
        assert torch.equal(actions[0, 1:], torch.tensor([[1.0, 3.0], [5.0, 7.0]], device=device))
        assert torch.equal(actions[1, 1:], torch.tensor([[2.0, 4.0], [6.0, 8.0]], device=device))
        assert torch.equal(actions[2, 1:], torch.tensor([[0.5, 0.25], [-1.0, -2.0]], device=device))
