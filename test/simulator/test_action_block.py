"""Agents' action forces and torques live in one world-owned block (simulator/action_block.py).

What a user of the VMAS API does with ``agent.state.force`` must work as
before: assigning, editing in place (VMAS's own dynamics write
``state.force[:, X] = ...``), reading back the clamped force after a step,
and gradients through a differentiable force. Each is checked against a world
stepped with the same forces set the plain way.
"""
from __future__ import annotations

import torch

from vmas_ros.simulator.core import Agent, Sphere, World


def _world(device, n: int = 3, batch: int = 4, **agent_kwargs) -> World:
    world = World(batch_dim=batch, device=device)
    for i in range(n):
        world.add_agent(Agent(f"a{i}", shape=Sphere(0.05), **agent_kwargs))
    for i, agent in enumerate(world.agents):  # far apart: no contacts
        agent.state.pos = torch.tensor([[float(i), 0.0]], device=device).expand(batch, 2).clone()
    return world


def _forces(device, n: int, batch: int, seed: int = 0) -> torch.Tensor:
    generator = torch.Generator().manual_seed(seed)
    return (torch.rand(n, batch, 2, generator=generator) * 2 - 1).to(device)


def test_set_forces_are_rows_of_the_block_and_the_step_reads_them(device):
    world = _world(device)
    forces = _forces(device, 3, 4)
    for agent, f in zip(world.agents, forces):
        agent.state.force = f
    block_force, _ = world._actions.stacks()
    assert torch.equal(block_force, forces)
    assert all(agent.state.force.data_ptr() == block_force[i].data_ptr() for i, agent in enumerate(world.agents))
    forces[0].zero_()  # the caller's tensor is not aliased: the block holds a copy
    assert block_force[0].abs().sum() > 0
    world.step()
    for agent, f in zip(world.agents, block_force):  # v = F / m * dt from rest (mass 1, no drag on a fresh world)
        assert torch.all(agent.state.vel != 0) and torch.allclose(torch.sign(agent.state.vel), torch.sign(f))


def test_in_place_edits_reach_the_step(device):
    forces = _forces(device, 3, 4, seed=1)
    assigned, edited = _world(device), _world(device)
    for agent, f in zip(assigned.agents, forces):
        agent.state.force = f.clone()
    for agent, f in zip(edited.agents, forces):  # as VMAS's diff_drive and kinematic_bicycle write them
        agent.state.force[:, 0] = f[:, 0]
        agent.state.force[:, 1] = f[:, 1]
    assigned.step()
    edited.step()
    for a, b in zip(assigned.agents, edited.agents):
        assert torch.equal(a.state.pos, b.state.pos) and torch.equal(a.state.vel, b.state.vel)


def test_rows_survive_the_block_growing(device):
    world = _world(device, n=2, batch=3)
    early = world.agents[0]
    early.state.force = torch.full((3, 2), 0.5, device=device)
    early.state.torque = torch.full((3, 1), -0.25, device=device)
    for i in range(2, 40):  # several doublings of the block
        world.add_agent(Agent(f"a{i}", shape=Sphere(0.05)))
    force, torque = world._actions.stacks()
    assert force.shape == (40, 3, 2) and torque.shape == (40, 3, 1)
    assert torch.equal(early.state.force, torch.full((3, 2), 0.5, device=device))
    assert early.state.force.data_ptr() == force[0].data_ptr(), "the agent's view moved to the grown block"
    assert torch.equal(torque[0], torch.full((3, 1), -0.25, device=device))
    early.state.force[:, 1] = 2.0  # still the row the step reads
    assert torch.equal(world._actions.stacks()[0][0, :, 1], torch.full((3,), 2.0, device=device))
    assert not force[1:].any(), "a new agent starts with no action"


def test_the_clamped_force_is_what_the_agent_reads_after_the_step(device):
    world = _world(device, max_f=0.5)
    world.agents[2].movable = False  # VMAS writes the clamped force back only where an agent can move
    world._invalidate_tables()
    big = torch.tensor([[3.0, 4.0]], device=device).expand(4, 2)
    for agent in world.agents:
        agent.state.force = big.clone()
    world.step()
    for agent in world.agents[:2]:
        torch.testing.assert_close(agent.state.force, torch.tensor([[0.3, 0.4]], device=device).expand(4, 2))
    assert torch.equal(world.agents[2].state.force, big), "an agent that cannot move keeps what it was given"
    assert torch.equal(world.agents[2].state.vel, torch.zeros(4, 2, device=device))


def test_a_force_that_needs_gradients_is_kept_and_the_gradient_flows(device):
    world = _world(device, n=2, batch=2)
    pushed = torch.tensor([[0.2, -0.1], [0.0, 0.3]], device=device, requires_grad=True)
    world.agents[0].state.force = pushed
    world.agents[1].state.force = torch.tensor([[0.1, 0.1], [0.1, 0.1]], device=device)
    assert world.agents[0].state.force is pushed and world._actions.loose
    world.step()
    world.agents[0].state.pos.sum().backward()
    assert pushed.grad is not None and torch.all(pushed.grad > 0)
    assert world.agents[1].state.vel.abs().sum() > 0, "the other agent's row still drives it"
    world.agents[0].state.force = torch.zeros(2, 2, device=device)  # back to a plain value: a row again
    assert world.agents[0].state.force.data_ptr() == world._actions.stacks()[0][0].data_ptr()


def test_a_stacked_step_equals_an_agent_by_agent_one(device):
    """Many agents, forces set in one op through the rows, against forces set agent by agent."""
    n, batch = 300, 2
    forces = _forces(device, n, batch, seed=3)
    one_by_one, stacked = _world(device, n=n, batch=batch), _world(device, n=n, batch=batch)
    for agent, f in zip(one_by_one.agents, forces):
        agent.state.force = f
    stacked._actions.stacks()[0].copy_(forces)
    for _ in range(3):
        one_by_one.step()
        stacked.step()
    assert torch.equal(one_by_one.stacked_state("pos"), stacked.stacked_state("pos"))
