"""Gradients flow through the step (VMAS's ``grad_enabled``), on every way of keeping held bodies still.

The step writes into some of its own fresh temporaries in place to save memory
and passes; autograd must still see the textbook derivatives. Without contacts
the semi-implicit Euler step is linear in the action, so the exact gradient is
known: after ``k`` steps of one substep, a force ``u`` applied at the first
step moves the body by ``u / m * dt^2 * (1 + keep + ... + keep^(k-1))`` where
``keep = 1 - drag``. With contacts the gradient is checked against central
finite differences on a smoothed (wide-margin) contact.
"""
from __future__ import annotations

import pytest
import torch

from vmas_ros.simulator import physics
from vmas_ros.simulator.thresholds import SMALL_BATCH_ELEMENTS
from vmas_ros.simulator.core import Agent, Landmark, Sphere, World

DT, DRAG, MASS, STEPS = 0.1, 0.25, 2.0, 3


def _world(batch: int, device: str, held: str, contact_margin: float = 1e-3) -> World:
    world = World(batch_dim=batch, device=device, dt=DT, drag=DRAG, contact_margin=contact_margin)
    if held == "landmark":  # held rows form a block at the start: the block path at large batches
        world.add_landmark(Landmark(name="post", shape=Sphere(0.1), collide=True))
    world.add_agent(Agent(name="a", shape=Sphere(0.1), mass=MASS, rotatable=held != "rotation"))
    world.add_agent(Agent(name="b", shape=Sphere(0.1), mass=MASS))
    world.reset(None)
    for i, e in enumerate(world.entities):
        e.set_pos(torch.tensor([[2.0 * i - 2.0, 1.0]], device=device).expand(batch, 2).clone(), batch_index=None)
    return world


def _displacement(world: World, force: torch.Tensor) -> torch.Tensor:
    """Agent a's x after STEPS steps with ``force`` on it in the first step only."""
    a = world.agents[0]
    for step in range(STEPS):
        for agent in world.agents:
            agent.state.force = torch.zeros_like(force)
        if step == 0:
            a.state.force = force
        world.step()
    return a.state.pos[:, 0]


@pytest.mark.parametrize("batch", [4, 4096], ids=["where", "large"])  # large: block or index_copy path
@pytest.mark.parametrize("held", ["landmark", "rotation"])
def test_contact_free_gradient_is_exact(batch, held, device):
    with torch.enable_grad():
        world = _world(batch, device, held)
        force = torch.zeros(batch, 2, device=device, requires_grad=True)
        x = _displacement(world, force)
        (grad,) = torch.autograd.grad(x.sum(), force)
    keep = 1 - DRAG
    expected = DT * DT / MASS * sum(keep ** k for k in range(STEPS))
    torch.testing.assert_close(grad[:, 0], torch.full((batch,), expected, device=device), rtol=1e-5, atol=0)
    assert torch.equal(grad[:, 1], torch.zeros(batch, device=device))
    if held == "landmark" and batch > SMALL_BATCH_ELEMENTS // 9:
        assert physics.step_constants(world.tables, world._step_params()).free_span is not None


def _push(batch: int, device: str) -> torch.Tensor:
    """On b, towards a: hard enough (10 N against a 4 N contact) that the contact lasts every step."""
    return torch.tensor([[-10.0, 0.0]], device=device).repeat(batch, 1)


@pytest.mark.parametrize("batch", [4, 4096], ids=["where", "large"])
def test_contact_gradient_matches_finite_differences(batch, device):
    """Two agents pushed into each other: d(x_a)/d(force on b) through the contact force."""
    margin, h = 0.05, 1e-2  # a wide margin makes the soft contact smooth enough for float32 differences

    def run(push: torch.Tensor) -> torch.Tensor:
        world = _world(batch, device, "landmark", contact_margin=margin)
        a, b = world.agents
        b.set_pos(a.state.pos + torch.tensor([0.19, 0.0], device=device), batch_index=None)  # overlapping
        for _ in range(STEPS):
            a.state.force = torch.zeros(batch, 2, device=device)
            b.state.force = push
            world.step()
        return a.state.pos[:, 0]

    with torch.enable_grad():
        push = _push(batch, device).requires_grad_()
        (grad,) = torch.autograd.grad(run(push).sum(), push)
    step = torch.tensor([h, 0.0], device=device)
    base = _push(batch, device)
    numeric = (run(base + step) - run(base - step)) / (2 * h)
    assert torch.isfinite(grad).all()
    assert (numeric.abs() > 1e-4).all(), "the push must reach a through the contact"
    torch.testing.assert_close(grad[:, 0], numeric, rtol=0.05, atol=1e-5)


@pytest.mark.parametrize("name,batch", [("simple_spread", 4), ("simple_spread", 4096), ("flocking", 8), ("discovery", 8),
                                        ("transport", 8), ("balance", 8), ("waterfall", 8)])
def test_env_rewards_and_observations_carry_gradients(name, batch, device):
    """``grad_enabled=True``: rewards and observations after a few steps depend on the first actions."""
    import vmas_ros

    env = vmas_ros.make_env(name, num_envs=batch, device=device, seed=0, grad_enabled=True, continuous_actions=True)
    env.reset()
    first = [torch.full((batch, 2), 0.3, device=device, requires_grad=True) for _ in env.agents]
    env.step(first)
    for _ in range(2):
        obs, rews, _, _ = env.step([torch.zeros(batch, 2, device=device) for _ in env.agents])
    loss = sum(r.sum() for r in rews) + sum(o.sum() for o in obs)
    grads = torch.autograd.grad(loss, first)
    assert all(torch.isfinite(g).all() for g in grads)
    assert all(g.abs().sum() > 0 for g in grads), "every agent's first action moves what it later sees"
