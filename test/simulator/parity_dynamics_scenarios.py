"""Dynamics and velocity-control scenarios written once in VMAS style.

``load(prefix)`` executes ``SOURCE`` with ``PREFIX`` replaced by ``vmas`` or
``vmas_ros``, so the very same scenario text (and the imports a VMAS user would
write) drives both the upstream oracle and our engine.
"""
from __future__ import annotations

import types

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
            world.add_agent(agent)
            if controller is not None:
                agent.controller = VelocityController(agent, world, *controller)
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


def load(prefix: str) -> types.ModuleType:
    """The scenarios module compiled against ``prefix`` ("vmas" or "vmas_ros")."""
    module = types.ModuleType(f"parity_dynamics_scenarios_{prefix}")
    exec(compile(SOURCE.replace("PREFIX", prefix), module.__name__, "exec"), module.__dict__)
    return module
