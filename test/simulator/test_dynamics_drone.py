"""``Drone`` dynamics: closed-form checks and lock-step parity with VMAS 1.5.2's ``Drone``.

Closed form: with a level start and a constant torque about one body axis
(no cross-coupling, as the other rates stay zero) the rate grows linearly
and the angle quadratically, which RK4 integrates exactly; a zero action
hovers. Parity: one agent per world, same state and actions, both
integrations, 50 steps.
"""
from __future__ import annotations

import pytest
import torch
import vmas.simulator.core as vcore
from vmas.simulator.dynamics.drone import Drone as UpstreamDrone

from vmas_ros.simulator.core import Agent, World
from vmas_ros.simulator.dynamics.drone import Drone

BATCH = 6
DT = 0.1


def single(integration: str = "rk4", batch: int = BATCH, **world_kwargs):
    world = World(batch, "cpu", dt=DT, **world_kwargs)
    agent = Agent("drone", u_range=[1.0] * 4, dynamics=Drone(world, integration=integration))
    world.add_agent(agent)
    world.reset(None)
    return world, agent


def drive(world, agent, action, steps: int) -> None:
    u = torch.as_tensor(action, dtype=torch.float32).expand(world.batch_dim, -1)
    for _ in range(steps):
        agent.action.u = u.clone()
        agent.dynamics.check_and_process_action()
        world.step()


def test_zero_action_hovers_level():
    world, agent = single(substeps=3)
    start = torch.rand(BATCH, 2) - 0.5
    agent.set_pos(start.clone(), batch_index=None)
    drive(world, agent, [0.0, 0.0, 0.0, 0.0], 30)
    assert agent.dynamics.needed_action_size == 4 and agent.action_size == 4
    torch.testing.assert_close(agent.state.pos, start, atol=1e-7, rtol=0)
    torch.testing.assert_close(agent.dynamics.drone_state[:, :9], torch.zeros(BATCH, 9), atol=1e-6, rtol=0)
    assert not agent.dynamics.needs_reset().any()


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_constant_torque_spins_up_one_axis(axis):
    """Rate = tau / I * t and angle = tau / (2 I) * t^2 about the driven axis (yaw: the agent's
    rotation takes over the model's yaw every step, so only the rate is checked there)."""
    world, agent = single(substeps=1, drag=0.0)
    tau, steps = 2e-4, 20
    action = [0.0, 0.0, 0.0, 0.0]
    action[1 + axis] = tau
    drive(world, agent, action, steps)
    dyn = agent.dynamics
    inertia = (dyn.I_xx, dyn.I_yy, dyn.I_zz)[axis]
    t = steps * DT
    state = dyn.drone_state
    torch.testing.assert_close(state[:, 3 + axis], torch.full((BATCH,), tau / inertia * t), rtol=1e-5, atol=0)
    if axis < 2:
        torch.testing.assert_close(state[:, axis], torch.full((BATCH,), tau / (2 * inertia) * t**2), rtol=1e-4, atol=0)
    others = [i for i in range(3) if i != axis]
    assert (state[:, [3 + i for i in others]] == 0).all()


def test_pitch_moves_forward_and_roll_moves_right():
    """A nose-down pitch accelerates along +x, a right roll along -y (z up, x forward)."""
    for torque_index, column, sign in ((2, 0, 1.0), (1, 1, -1.0)):
        world, agent = single()
        action = [0.0, 0.0, 0.0, 0.0]
        action[torque_index] = 1e-3
        drive(world, agent, action, 10)
        assert (sign * agent.state.vel[:, column] > 0).all() and (sign * agent.state.pos[:, column] > 0).all()
        assert (agent.state.pos[:, 1 - column].abs() < 1e-6).all()


def test_reset_needs_reset_and_validation():
    world, agent = single()
    dyn = agent.dynamics
    dyn.drone_state = torch.zeros(BATCH, 12)
    dyn.drone_state[:, 0] = torch.tensor([0.0, 0.6, -0.6, 0.5, 0.0, 0.0])
    dyn.drone_state[:, 1] = torch.tensor([0.0, 0.0, 0.0, 0.0, 0.53, -0.1])
    dyn.drone_state[:, 5] = 1.0
    assert dyn.needs_reset().tolist() == [False, True, True, False, True, False]
    dyn.reset(torch.tensor([1, 4]))
    assert (dyn.drone_state[[1, 4]] == 0).all() and (dyn.drone_state[[0, 2, 3, 5], 5] == 1).all()
    dyn.reset(2)
    assert (dyn.drone_state[2] == 0).all() and dyn.drone_state[3, 0] == 0.5
    dyn.reset()
    assert (dyn.drone_state == 0).all() and dyn.drone_state.shape == (BATCH, 12)
    with pytest.raises(ValueError, match="integration"):
        Drone(world, integration="midpoint")
    with pytest.raises(ValueError, match="I_zz"):
        Drone(world, I_zz=0.0)


# ------------------------------------------------------------------------- parity
def upstream_single(integration: str, **world_kwargs):
    world = vcore.World(BATCH, "cpu", dt=DT, **world_kwargs)
    agent = vcore.Agent("drone", u_range=[1.0] * 4, dynamics=UpstreamDrone(world, integration=integration))
    world.add_agent(agent)
    world.reset_agents = None
    return world, agent


@pytest.mark.parametrize("integration", ["rk4", "euler"])
def test_matches_upstream_drone(integration):
    """Same tilted, spinning start and the same random thrust and torques, stepped 50 times: agent
    states (pos, vel, rot, ang_vel) and the 12-value model state agree."""
    kwargs = dict(substeps=4)
    up_world, up_agent = upstream_single(integration, **kwargs)
    world, agent = single(integration, **kwargs)
    gen = torch.Generator().manual_seed(3)
    start = (torch.rand(BATCH, 12, generator=gen) - 0.5) * torch.tensor([0.2] * 3 + [0.05] * 3 + [0.0] * 6)
    pos = torch.rand(BATCH, 2, generator=gen) - 0.5
    for w_agent in (up_agent, agent):
        w_agent.dynamics.drone_state = start.clone()
        w_agent.set_pos(pos.clone(), batch_index=None)
    fastest = 0.0
    for step in range(50):
        u = (torch.rand(BATCH, 4, generator=gen) * 2 - 1) * torch.tensor([0.5, 2e-4, 2e-4, 2e-4])
        for w, a in ((up_world, up_agent), (world, agent)):
            a.action.u = u.clone()
            a.dynamics.check_and_process_action()
            w.step()
        for field in ("pos", "vel", "rot", "ang_vel"):
            torch.testing.assert_close(getattr(agent.state, field), getattr(up_agent.state, field),
                                       atol=1e-4, rtol=1e-4, msg=lambda m: f"step {step} {field}: {m}")
        torch.testing.assert_close(agent.dynamics.drone_state, up_agent.dynamics.drone_state,
                                   atol=1e-4, rtol=1e-4, msg=lambda m: f"step {step} drone_state: {m}")
        fastest = max(fastest, float(agent.state.vel.norm(dim=-1).max()))
    assert fastest > 0.5 and agent.state.rot.abs().max() > 1e-3  # moved and yawed
