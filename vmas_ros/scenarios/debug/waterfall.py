"""waterfall: a chain of jointed agents falls through a cascade of tilted boxes.

Description
    A testing scenario that exercises most of the engine (paper, "Multi-robot
    scenarios"): ``n_agents`` spheres linked by collidable rigid rods (joints),
    the last agent pinned by a rod to a green box, five movable tilted boxes
    below them and a fixed floor line at y = -1.
Observation (per agent)
    own position (2), own velocity (2), every landmark's position relative to
    the agent, in world order (joint rods, the green box, the tilted boxes, the floor).
Reward
    Minus the agent's distance to the floor's centre.
Starting state
    Agents in a row at y = 1; boxes alternating at x = +-0.2 every 0.3 down
    from y = 0.6, tilted +-45 degrees; floor at (0, -1).
Episode termination
    Never (set ``max_steps``).
Kwargs
    ``n_agents`` (5), ``joints`` (True).
"""
from __future__ import annotations

import math

import torch

from vmas_ros.scenarios.common import read_kwargs
from vmas_ros.simulator.core import Agent, Box, Landmark, Line, Sphere, World
from vmas_ros.simulator.heuristic_policy import BaseHeuristicPolicy
from vmas_ros.simulator.joints import Joint
from vmas_ros.simulator.scenario import BaseScenario
from vmas_ros.simulator.utils import Color

AGENT_RADIUS = 0.04
ROD_LENGTH = 0.1
N_BOXES = 5
#: name -> default of every kwarg
DEFAULTS = {"n_agents": 5, "joints": True}


class Scenario(BaseScenario):
    supports_batched_reset = True

    def make_world(self, batch_dim: int, device, **kwargs) -> World:
        config = read_kwargs(kwargs, DEFAULTS)
        self.n_agents, self.with_joints = config["n_agents"], config["joints"]
        if not isinstance(self.n_agents, int) or self.n_agents < 1:
            raise ValueError(f"waterfall: n_agents must be a positive int, got {self.n_agents!r}")
        world = World(batch_dim, device, dt=0.1, drag=0.25, substeps=5, collision_force=500)
        for i in range(self.n_agents):
            world.add_agent(Agent(name=f"agent_{i}", shape=Sphere(radius=AGENT_RADIUS), u_multiplier=0.7, rotatable=True))
        if self.with_joints:
            rod = dict(anchor_a=(1, 0), anchor_b=(-1, 0), dist=ROD_LENGTH, collidable=True, width=0, mass=1)
            for left, right in zip(world.agents[:-1], world.agents[1:]):
                world.add_joint(Joint(left, right, rotate_a=True, rotate_b=True, **rod))
            tail = Landmark(
                name="joined landmark", collide=True, movable=True, rotatable=True,
                shape=Box(length=AGENT_RADIUS * 2, width=0.3), color=Color.GREEN,
            )
            world.add_landmark(tail)
            world.add_joint(Joint(world.agents[-1], tail, rotate_a=False, rotate_b=False, **rod))
        for i in range(N_BOXES):
            world.add_landmark(Landmark(
                name=f"landmark {i}", collide=True, movable=True, rotatable=True,
                shape=Box(length=0.3, width=0.1), color=Color.RED,
            ))
        world.add_landmark(Landmark(name="floor", collide=True, movable=False, shape=Line(length=2), color=Color.BLACK))
        return world

    def _set(self, entity, setter: str, values, env_index) -> None:
        value = torch.tensor(values, dtype=torch.float32, device=self.world.device)
        getattr(entity, setter)(value, batch_index=env_index)

    def reset_world_at(self, env_index=None) -> None:
        world = self.world
        # the chain: agents then (with joints) the green box, evenly spaced at y = 1
        chain = world.agents + [world.landmarks[self.n_agents - 1]]
        spacing = ROD_LENGTH + 2 * AGENT_RADIUS
        for i, entity in enumerate(chain):
            self._set(entity, "set_pos", [-0.2 + spacing * i, 1.0], env_index)
        first_box = self.n_agents + 1 if self.with_joints else 0
        for i, box in enumerate(world.landmarks[first_box:-1]):
            side = 1.0 if i % 2 else -1.0
            self._set(box, "set_pos", [0.2 * side, 0.6 - 0.3 * i], env_index)
            self._set(box, "set_rot", [side * math.pi / 4], env_index)
        self._set(world.landmarks[-1], "set_pos", [0.0, -1.0], env_index)

    def reward(self, agent: Agent) -> torch.Tensor:
        return -torch.linalg.vector_norm(agent.state.pos - self.world.landmarks[-1].state.pos, dim=-1)

    def observation(self, agent: Agent) -> torch.Tensor:
        landmarks = torch.stack([l.state.pos for l in self.world.landmarks], dim=1)
        return torch.cat([agent.state.pos, agent.state.vel, (landmarks - agent.state.pos.unsqueeze(1)).flatten(1)], dim=-1)


class HeuristicPolicy(BaseHeuristicPolicy):
    """Head for the floor: full thrust towards the floor's centre (the last landmark)."""

    def compute_action(self, observation: torch.Tensor, u_range: float) -> torch.Tensor:
        to_floor = observation[:, -2:]
        direction = to_floor / torch.linalg.vector_norm(to_floor, dim=-1, keepdim=True).clamp_min(1e-6)
        return (direction * u_range).clamp(-u_range, u_range)
