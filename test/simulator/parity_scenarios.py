"""Scenarios written once in VMAS style, loadable with either import prefix.

``load(prefix)`` executes the source below with ``PREFIX`` replaced by ``vmas``
or ``vmas_ros``: the very same scenario text must produce the same trajectory
on upstream VMAS and on vmas_ros. This is also the porting promise: a VMAS
scenario runs after changing its import prefix.
"""
from __future__ import annotations

import types

SOURCE = '''
import torch
from PREFIX.simulator.core import Agent, Box, Landmark, Line, Sphere, World
from PREFIX.simulator.joints import Joint
from PREFIX.simulator.scenario import BaseScenario
from PREFIX.simulator.sensors import Lidar
from PREFIX.simulator.utils import Color


def make_shape(kind):
    if kind == "sphere":
        return Sphere(radius=0.1)
    if kind == "box":
        return Box(length=0.3, width=0.15)
    if kind == "hollow_box":
        return Box(length=0.5, width=0.4, hollow=True)
    if kind == "line":
        return Line(length=0.4)
    raise ValueError(kind)


class ShapesScenario(BaseScenario):
    """Agents of each shape kind pushing movable, rotatable landmarks of each kind."""

    def make_world(self, batch_dim, device, **kwargs):
        self.agent_shapes = kwargs.pop("agent_shapes", ["sphere"])
        self.landmark_shapes = kwargs.pop("landmark_shapes", ["sphere"])
        world = World(
            batch_dim, device, dt=0.1, substeps=kwargs.pop("substeps", 2),
            drag=kwargs.pop("drag", 0.25),
            linear_friction=kwargs.pop("linear_friction", 0.0),
            angular_friction=kwargs.pop("angular_friction", 0.0),
            gravity=kwargs.pop("gravity", (0.0, 0.0)),
            x_semidim=kwargs.pop("x_semidim", None), y_semidim=kwargs.pop("y_semidim", None),
            collision_force=kwargs.pop("collision_force", 100),
        )
        max_speed = kwargs.pop("max_speed", None)
        v_range = kwargs.pop("v_range", None)
        lidar = kwargs.pop("lidar", False)
        entity_gravity = kwargs.pop("entity_gravity", None)
        agent_friction = kwargs.pop("agent_friction", None)
        assert not kwargs, kwargs
        for i, kind in enumerate(self.agent_shapes):
            agent = Agent(
                name=f"agent_{i}", shape=make_shape(kind), max_speed=max_speed, v_range=v_range,
                u_range=2.0, rotatable=True, gravity=entity_gravity, linear_friction=agent_friction,
                mass=1.0 + 0.5 * i,
            )
            if lidar:
                agent.add_sensor(Lidar(world, n_rays=12, max_range=1.5, entity_filter=lambda e: not e.name.startswith("agent_0")))
            world.add_agent(agent)
        for i, kind in enumerate(self.landmark_shapes):
            world.add_landmark(Landmark(
                name=f"landmark_{i}", shape=make_shape(kind), movable=True, rotatable=True,
                mass=2.0, collide=True,
            ))
        return world

    def reset_world_at(self, env_index=None):
        pass  # the test copies the initial state across

    def observation(self, agent):
        obs = [agent.state.pos, agent.state.vel, agent.state.rot, agent.state.ang_vel]
        for sensor in agent.sensors:
            obs.append(sensor.measure())
        return torch.cat(obs, dim=-1)

    def reward(self, agent):
        return -torch.linalg.vector_norm(agent.state.pos, dim=-1)


class ChainScenario(BaseScenario):
    """Agents joined by rods and pins, with locked and free rotations."""

    def make_world(self, batch_dim, device, **kwargs):
        world = World(batch_dim, device, substeps=5, joint_force=kwargs.pop("joint_force", 130))
        for i in range(3):
            world.add_agent(Agent(name=f"agent_{i}", shape=Sphere(0.05), u_range=1.0))
        box = Landmark(name="box", shape=Box(length=0.2, width=0.1), movable=True, rotatable=True)
        world.add_landmark(box)
        world.add_joint(Joint(world.agents[0], world.agents[1], anchor_a=(1, 0), anchor_b=(-1, 0), dist=0.2, collidable=True))
        world.add_joint(Joint(world.agents[1], world.agents[2], anchor_a=(0, 1), anchor_b=(0, -1), dist=0.0))
        world.add_joint(Joint(world.agents[2], box, anchor_a=(1, 0), anchor_b=(-1, 0), dist=0.15,
                              rotate_a=False, rotate_b=False))
        return world

    def reset_world_at(self, env_index=None):
        for i, agent in enumerate(self.world.agents):
            agent.set_pos(torch.tensor([0.3 * i - 0.3, 0.1 * i], device=self.world.device), batch_index=env_index)
        self.world.landmarks[-1].set_pos(torch.tensor([0.5, 0.2], device=self.world.device), batch_index=env_index)

    def observation(self, agent):
        return torch.cat([agent.state.pos, agent.state.vel], dim=-1)

    def reward(self, agent):
        return agent.state.pos[:, 0]
'''


def load(prefix: str) -> types.ModuleType:
    """The scenarios module compiled against ``prefix`` ("vmas" or "vmas_ros")."""
    module = types.ModuleType(f"parity_scenarios_{prefix}")
    exec(compile(SOURCE.replace("PREFIX", prefix), module.__name__, "exec"), module.__dict__)
    return module
