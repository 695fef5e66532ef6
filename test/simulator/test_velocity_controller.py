"""VelocityController: parity with upstream VMAS 1.5.2 and closed-loop behaviour.

Parity runs the velocity-controlled agents of the DynamicsScenario on both
engines (including a mid-run per-env reset and an agent whose integrator hits
its anti-windup clip). The other tests check what a user relies on: a held
command is tracked, resets are per env, both PID forms agree.
"""
from __future__ import annotations

import warnings

import pytest
import torch

from test.simulator import parity_dynamics_scenarios as pds
from vmas_ros.simulator.controllers.velocity_controller import VelocityController
from vmas_ros.simulator.core import Agent, Sphere, World
from vmas_ros.simulator.dynamics.holonomic_with_rot import HolonomicWithRotation

devices = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])
VEL_AGENTS = ["vel_std", "vel_par", "vel_windup", "vel_p", "diff_rk4"]
BATCH = 6
TARGET = [[0.4, -0.3], [0.8, 0.0], [-0.5, 0.5], [0.1, 0.05], [0.0, -0.7], [-0.2, -0.2]]


# ----------------------------------------------------------------- parity
@pytest.mark.parametrize("device", devices)
def test_velocity_control_matches_upstream_with_resets(device):
    up, ours = pds.make_pair(device, models=VEL_AGENTS)
    pds.copy_random_state(up, ours, seed=1)
    windup = ours.world.agents[VEL_AGENTS.index("vel_windup")].controller
    clipped = []

    def record(step: int) -> None:
        clipped.append(bool((windup.accum_errs.abs() >= windup.integrator_windup_cutoff - 1e-7).any()))

    pds.run_parity(up, ours, seed=2, steps=25, hold=10, on_step=record)
    for env in (up, ours):  # the scenario's reset_world_at calls controller.reset(env_index)
        env.reset_at(4)
    for agent in ours.world.agents:
        if hasattr(agent, "controller"):
            assert not agent.controller.accum_errs[4].any() and not agent.controller.prev_err[4].any()
    pds.assert_same(up, ours, 25)
    pds.run_parity(up, ours, seed=3, steps=25, hold=10, on_step=record)
    assert any(clipped), "the anti-windup clip must be exercised"


@pytest.mark.parametrize("device", devices)
def test_full_reset_matches_upstream(device):
    up, ours = pds.make_pair(device, models=VEL_AGENTS, collide=False)
    pds.copy_random_state(up, ours, seed=4)
    pds.run_parity(up, ours, seed=5, steps=10)
    for env in (up, ours):
        env.reset()
    pds.assert_same(up, ours, 10)
    pds.run_parity(up, ours, seed=6, steps=10)


# ------------------------------------------------------------- behaviour
def _controlled(device, params=(4.0, 0.4, 0.01), pid_form="standard", drag=0.25, f_range=5.0, attach_first=False):
    world = World(BATCH, device, dt=0.1, drag=drag)
    agent = Agent("bot", shape=Sphere(0.05), u_range=1.0, f_range=f_range, mass=1.5)
    if attach_first:
        world.add_agent(agent)
    agent.controller = VelocityController(agent, world, params, pid_form)
    if not attach_first:
        world.add_agent(agent)
    return world, agent


def _step(world: World, agent: Agent, command: torch.Tensor) -> None:
    """What the environment does: action = desired velocity, controller, dynamics, physics."""
    agent.action.u = command.clone()
    agent.controller.process_force()
    agent.dynamics.check_and_process_action()
    world.step()


@pytest.mark.parametrize("device", devices)
@pytest.mark.parametrize(
    "drag,params",
    # drag is a constant disturbance: it needs the integrator; without it P alone suffices
    [(0.25, (4.0, 0.4, 0.01)), (0.0, (5.0, 0.0, 0.0))],
    ids=["drag-PID", "nodrag-P"],
)
@pytest.mark.parametrize("attach_first", [False, True])
def test_held_command_is_tracked_within_one_second(device, drag, params, attach_first):
    world, agent = _controlled(device, params=params, drag=drag, attach_first=attach_first)
    target = torch.tensor(TARGET, device=device)
    errors = []
    for _ in range(30):  # 3 s at dt = 0.1
        _step(world, agent, target)
        errors.append(((agent.state.vel - target).norm(dim=-1) / target.norm(dim=-1)).max())
    assert agent.state.force.device.type == torch.device(device).type
    assert agent.controller.accum_errs.device.type == torch.device(device).type
    # within 5% after 1 s of simulated time, and it stays there
    assert max(errors[9:]) < 0.05, [float(e) for e in errors]


@pytest.mark.parametrize("device", devices)
def test_force_limit_bounds_the_output_and_integrator(device):
    world, agent = _controlled(device, params=(2.0, 0.05, 0.0), f_range=0.2)
    cutoff = agent.controller.integrator_windup_cutoff
    assert cutoff == pytest.approx(0.5 * 0.2 * 0.05 / (0.1 * 2.0))
    target = torch.tensor(TARGET, device=device)
    for _ in range(20):
        _step(world, agent, target)
        assert agent.state.force.abs().max() <= 0.2 + 1e-6
        assert agent.controller.accum_errs.abs().max() <= cutoff + 1e-7
    assert (agent.controller.accum_errs.abs() == cutoff).any()


@pytest.mark.parametrize("device", devices)
@pytest.mark.parametrize("index", [1, -1, "tensor", "mask"])
def test_reset_clears_only_the_given_envs(device, index):
    world, agent = _controlled(device)
    target = torch.tensor(TARGET, device=device)
    for _ in range(3):
        _step(world, agent, target)
    ctrl = agent.controller
    before = ctrl.accum_errs.clone(), ctrl.prev_err.clone()
    assert before[0].any(dim=-1).all() and before[1].any(dim=-1).all()  # every env has memory
    chosen = {1: [1], -1: [BATCH - 1], "tensor": [0, 3], "mask": [2, 5]}[index]
    if index == "tensor":
        index = torch.tensor(chosen, device=device)
    elif index == "mask":
        index = torch.zeros(BATCH, dtype=torch.bool, device=device)
        index[chosen] = True
    ctrl.reset(index)
    kept = [i for i in range(BATCH) if i not in chosen]
    for now, old in zip((ctrl.accum_errs, ctrl.prev_err), before):
        assert not now[chosen].any()
        assert torch.equal(now[kept], old[kept])
    ctrl.reset()
    assert not ctrl.accum_errs.any() and not ctrl.prev_err.any()


@pytest.mark.parametrize("device", devices)
def test_parallel_form_equals_standard_form(device):
    k_p, t_i, t_d = 3.0, 0.5, 0.02
    forces = []
    for params, form in (((k_p, t_i, t_d), "standard"), ((k_p, k_p / t_i, k_p * t_d), "parallel")):
        world, agent = _controlled(device, params=params, pid_form=form)
        torch.manual_seed(0)
        for _ in range(5):
            _step(world, agent, torch.rand(BATCH, 2, device=device) * 2 - 1)
        forces.append(agent.state.force)
    torch.testing.assert_close(forces[0], forces[1])


def test_integrator_without_force_limit_warns_and_p_only_does_not():
    world = World(2, "cpu")
    free = Agent("free", u_range=1.0)
    with pytest.warns(UserWarning, match="wind"):
        VelocityController(free, world, (1.0, 2.0, 0.0))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ctrl = VelocityController(free, world)  # VMAS default: P-only, gain 1
    assert (ctrl.ctrl_gain, ctrl.integralTs, ctrl.derivativeTs, ctrl.use_integrator) == (1, 0, 0, False)
    with pytest.raises(ValueError, match="pid_form"):
        VelocityController(free, world, (1.0, 0.0, 0.0), "series")


def test_extra_action_columns_pass_through():
    """Velocity control of translation with a directly commanded torque."""
    world = World(2, "cpu")
    agent = Agent("spin", dynamics=HolonomicWithRotation(), u_range=1.0, f_range=1.0)
    agent.controller = VelocityController(agent, world, (2.0, 0.0, 0.0))
    world.add_agent(agent)
    agent.action.u = torch.tensor([[0.5, 0.0, 0.3], [0.0, -0.5, -0.2]])
    agent.controller.process_force()
    torch.testing.assert_close(agent.action.u, torch.tensor([[1.0, 0.0, 0.3], [0.0, -1.0, -0.2]]))
