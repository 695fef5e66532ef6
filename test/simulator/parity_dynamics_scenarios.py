"""Dynamics and velocity-control scenarios written once in VMAS style.

``load(prefix)`` executes ``SOURCE`` with ``PREFIX`` replaced by ``vmas`` or
``vmas_ros``, so the very same scenario text (and the imports a VMAS user would
write) drives both the upstream oracle and our engine.
"""
from __future__ import annotations

import itertools
import types
from typing import Callable, Optional, Tuple

import torch

from vmas_ros.testing import parity

SOURCE = '''
import torch
from PREFIX.simulator.controllers.velocity_controller import VelocityController
from PREFIX.simulator.core import Agent, Box, Landmark, Sphere, World
from PREFIX.simulator.dynamics.diff_drive import DiffDrive
from PREFIX.simulator.dynamics.forward import Forward
from PREFIX.simulator.dynamics.holonomic import Holonomic
from PREFIX.simulator.dynamics.holonomic_with_rot import HolonomicWithRotation
from PREFIX.simulator.dynamics.kinematic_bicycle import KinematicBicycle
from PREFIX.simulator.dynamics.roatation import Rotation
from PREFIX.simulator.dynamics.static import Static
from PREFIX.simulator.scenario import BaseScenario


class DynamicsScenario(BaseScenario):
    """One agent per dynamics model, plus velocity-controlled holonomic agents.

    Agents named ``vel_*`` take a desired velocity as action; their controller
    turns it into a force in ``process_action`` (as VMAS documents).
    """

    def make_world(self, batch_dim, device, **kwargs):
        collide = kwargs.pop("collide", True)
        world = World(
            batch_dim, device, dt=0.1, substeps=kwargs.pop("substeps", 1), drag=kwargs.pop("drag", 0.25),
        )
        models = kwargs.pop("models", None)
        assert not kwargs, kwargs
        specs = {
            "holo_rot": dict(dynamics=HolonomicWithRotation(), u_range=[1.0, 1.0, 0.3]),
            "diff_rk4": dict(dynamics=DiffDrive(world), u_range=[0.5, 1.5]),
            "diff_euler": dict(dynamics=DiffDrive(world, integration="euler"), u_range=[0.5, 1.5], mass=2.0),
            "bike_rk4": dict(
                dynamics=KinematicBicycle(world, width=0.1, l_f=0.1, l_r=0.08, max_steering_angle=0.5),
                u_range=[0.5, 0.8], shape=Box(length=0.2, width=0.1),
            ),
            "bike_euler": dict(
                dynamics=KinematicBicycle(world, width=0.1, l_f=0.05, l_r=0.1, max_steering_angle=0.6,
                                          integration="euler"),
                u_range=[0.5, 0.6], shape=Box(length=0.15, width=0.1),
            ),
            "forward": dict(dynamics=Forward(), u_range=1.0),
            "rotation": dict(dynamics=Rotation(), u_range=0.5),
            "static": dict(dynamics=Static()),
            "vel_std": dict(dynamics=Holonomic(), u_range=0.5, f_range=1.0,
                            controller=((2.0, 6.0, 0.002), "standard")),
            "vel_par": dict(dynamics=Holonomic(), u_range=0.5, max_f=0.8, mass=1.5,
                            controller=((3.0, 2.0, 0.05), "parallel")),
            "vel_windup": dict(dynamics=Holonomic(), u_range=0.8, f_range=0.15, max_f=0.3,
                               controller=((2.0, 0.05, 0.0), "standard")),
            "vel_p": dict(dynamics=Holonomic(), u_range=0.5, controller=((4.0, 0.0, 0.0), "standard")),
        }
        names = models if models is not None else list(specs)
        for name in names:
            spec = dict(specs[name])
            controller = spec.pop("controller", None)
            spec.setdefault("shape", Sphere(radius=0.05))
            agent = Agent(name=name, collide=collide, **spec)
            if controller is not None:  # before add_agent, as VMAS's own scenarios do
                agent.controller = VelocityController(agent, world, *controller)
            world.add_agent(agent)
        world.add_landmark(Landmark(name="wall", shape=Box(length=0.1, width=1.0), collide=collide))
        return world

    def reset_world_at(self, env_index=None):
        for i, agent in enumerate(self.world.agents):
            pos = torch.tensor([0.3 * (i % 4) - 0.45, 0.3 * (i // 4) - 0.3], device=self.world.device)
            agent.set_pos(pos, batch_index=env_index)
            agent.set_rot(torch.tensor([0.4 * i], device=self.world.device), batch_index=env_index)
            if hasattr(agent, "controller"):
                agent.controller.reset(env_index)
        self.world.landmarks[0].set_pos(torch.tensor([0.9, 0.0], device=self.world.device), batch_index=env_index)

    def process_action(self, agent):
        if hasattr(agent, "controller"):
            agent.controller.process_force()

    def observation(self, agent):
        s = agent.state
        return torch.cat([s.pos, s.vel, s.rot, s.ang_vel], dim=-1)

    def reward(self, agent):
        return -torch.linalg.vector_norm(agent.state.pos, dim=-1)
'''


FIELDS = parity.FIELDS
ATOL = parity.ATOL


def load(prefix: str) -> types.ModuleType:
    """The scenarios module compiled against ``prefix`` ("vmas" or "vmas_ros")."""
    module = types.ModuleType(f"parity_dynamics_scenarios_{prefix}")
    exec(compile(SOURCE.replace("PREFIX", prefix), module.__name__, "exec"), module.__dict__)
    return module


UP = load("vmas")
OURS = load("vmas_ros")


def make_pair(device, batch: int = 16, **kwargs) -> Tuple[object, object]:
    """The DynamicsScenario built on upstream VMAS and on vmas_ros, same kwargs."""
    import vmas
    import vmas_ros

    up = vmas.make_env(UP.DynamicsScenario(), num_envs=batch, device=device, seed=0, **kwargs)
    ours = vmas_ros.make_env(OURS.DynamicsScenario(), num_envs=batch, device=device, seed=0, **kwargs)
    return up, ours


def copy_random_state(up, ours, seed: int, spread: float = 0.6) -> None:
    """Write one random initial state (agents only, moving) into both worlds."""
    parity.copy_random_state(up, ours, seed, spread, agents_only=True)


def assert_same(up, ours, step: int) -> None:
    """Entity states as in every parity test, plus the PID controllers' memory."""
    parity.assert_same_state(up, ours, step)
    for a_up, a_ours in zip(up.world.agents, ours.world.agents):
        if hasattr(a_up, "controller"):
            for name in ("accum_errs", "prev_err"):
                torch.testing.assert_close(
                    getattr(a_ours.controller, name), getattr(a_up.controller, name), atol=ATOL, rtol=1e-4,
                    msg=lambda m: f"step {step}, {a_ours.name}.controller.{name}: {m}",
                )


def run_parity(
    up, ours, seed: int, steps: int = 50, hold: int = 5,
    on_step: Optional[Callable[[int], None]] = None, resync: bool = False,
) -> None:
    """Step both envs with identical random actions (each held ``hold`` steps).

    Holding actions lets velocity errors build up, so integrators and their
    anti-windup clip are exercised, and lets kinematic agents trace real arcs.
    ``resync``: give ours upstream's bodies before every step (see
    ``parity.run_lockstep``), for undamped contact worlds that grow float
    rounding into visible differences; controllers keep their own state.
    """
    gen = torch.Generator().manual_seed(seed)
    assert_same(up, ours, 0)
    actions = None
    for step in range(1, steps + 1):
        if (step - 1) % hold == 0:
            actions = [
                (torch.rand(up.world.batch_dim, up.get_agent_action_size(a), generator=gen) * 2 - 1)
                * a.action.u_range_tensor.cpu()
                for a in up.agents
            ]
        if resync:
            parity.copy_state(up, ours)
        obs_up, rew_up, _, _ = up.step([a.to(up.device) for a in actions])
        obs_ours, rew_ours, _, _ = ours.step([a.to(ours.device) for a in actions])
        assert_same(up, ours, step)
        for o_up, o_ours in zip(obs_up + rew_up, obs_ours + rew_ours):
            torch.testing.assert_close(o_ours, o_up, atol=ATOL, rtol=1e-4)
        if on_step is not None:
            on_step(step)


def any_contact(world) -> bool:
    """Whether some pair of entities overlaps in some env (guards against vacuous parity)."""
    return any(bool((world.get_distance(a, b) < 0).any()) for a, b in itertools.combinations(world.entities, 2))
