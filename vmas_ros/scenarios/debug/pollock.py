"""pollock: a crowd of agents, rods and boxes knocking about a walled square.

Description
    A physics stress test with no task. ``n_agents`` discs (radius 0.05,
    force x0.7, rotatable), ``n_lines`` movable rods (length 0.3) and
    ``n_boxes`` movable boxes (0.2 x 0.1) share the square [-1, 1]^2 (walls
    at its edges; world drag 0.25, dt 0.1, 5 substeps, collision force 500).
    Everything collides with everything. With ``lidar`` every agent carries a
    16-ray lidar of range 0.5 (a full circle, the first ray along the
    agent's heading).
Observation (per agent, in this order)
    Without ``lidar``: a single 0 (1 value). With it: the 16 lidar distances.
    ``vectorized_lidar`` is accepted for compatibility; every cast here is
    batched, so both values measure the same way.
Reward
    0 for every agent, always.
Starting state
    Every agent, rod and box at a uniform position in [-1, 1]^2 at least 0.1
    (centre to centre) from those placed before it, at rest, unrotated.
    Shapes may still overlap at the start (a rod is longer than 0.1).
Episode termination
    Never (set ``max_steps``).
Kwargs
    ``n_agents`` (15), ``n_lines`` (15), ``n_boxes`` (15), ``lidar`` (False),
    ``vectorized_lidar`` (True).
"""
from __future__ import annotations

import math

import torch
from torch import Tensor

from vmas_ros.scenarios.common import configure, continuous_heuristic_kwargs
from vmas_ros.simulator.core import Agent, Box, Landmark, Line, Sphere, World
from vmas_ros.simulator.heuristic_policy import BaseHeuristicPolicy
from vmas_ros.simulator.scenario import BaseScenario
from vmas_ros.simulator.sensors import Lidar
from vmas_ros.simulator.utils import Color, ScenarioUtils

NAME = "pollock"
DEFAULTS = {"n_agents": 15, "n_lines": 15, "n_boxes": 15, "lidar": False, "vectorized_lidar": True}
AGENT_RADIUS = 0.05
LINE_LENGTH = 0.3
BOX_LENGTH, BOX_WIDTH = 0.2, 0.1
SEMIDIM = 1.0
MIN_SPAWN_DISTANCE = 0.1
N_RAYS, LIDAR_RANGE = 16, 0.5


def validate(config: dict) -> None:
    """Raise ValueError for a kwarg value the task cannot be built with."""
    minimum = {"n_agents": 1, "n_lines": 0, "n_boxes": 0}
    for name, low in minimum.items():
        value = config[name]
        if isinstance(value, bool) or not isinstance(value, int) or value < low:
            raise ValueError(f"{NAME}: {name} must be an int >= {low}, got {value!r}")
    for name in ("lidar", "vectorized_lidar"):
        if not isinstance(config[name], bool):
            raise ValueError(f"{NAME}: {name} must be a bool, got {config[name]!r}")


class Scenario(BaseScenario):
    supports_batched_reset = True

    def make_world(self, batch_dim: int, device, **kwargs) -> World:
        configure(self, kwargs, DEFAULTS, validate)
        world = World(
            batch_dim, device, dt=0.1, drag=0.25, substeps=5, collision_force=500,
            x_semidim=SEMIDIM, y_semidim=SEMIDIM,
        )
        for i in range(self.n_agents):
            sensors = [Lidar(world, n_rays=N_RAYS, max_range=LIDAR_RANGE)] if self.lidar else []
            world.add_agent(Agent(
                name=f"agent_{i}", shape=Sphere(radius=AGENT_RADIUS), u_multiplier=0.7, rotatable=True,
                sensors=sensors,
            ))
        for i in range(self.n_lines):
            world.add_landmark(Landmark(
                name=f"line {i}", collide=True, movable=True, rotatable=True,
                shape=Line(length=LINE_LENGTH), color=Color.BLACK,
            ))
        for i in range(self.n_boxes):
            world.add_landmark(Landmark(
                name=f"box {i}", collide=True, movable=True, rotatable=True,
                shape=Box(length=BOX_LENGTH, width=BOX_WIDTH), color=Color.RED,
            ))
        return world

    def reset_world_at(self, env_index=None) -> None:
        bounds = (-SEMIDIM, SEMIDIM)
        ScenarioUtils.spawn_entities_randomly(
            self.world.agents + self.world.landmarks, self.world, env_index, MIN_SPAWN_DISTANCE, bounds, bounds,
        )

    def reward(self, agent: Agent) -> Tensor:
        return torch.zeros(self.world.batch_dim, device=self.world.device)

    def observation(self, agent: Agent) -> Tensor:
        if not self.lidar:
            return torch.zeros(self.world.batch_dim, 1, device=self.world.device)
        return agent.sensors[0].measure()


#: What ``vmas-ros evaluate`` scores this reward-less world on, per step (see ``task_score``),
#: and the kwargs it evaluates with: without a lidar an agent senses nothing to keep clear of.
TASK_SCORE = "the agents' mean clearance, nearest lidar hit [m]"
EVALUATE_KWARGS = {"lidar": True}


def task_score(env, observations) -> Tensor:
    """[B]: the agents' mean clearance, their nearest lidar reading (``LIDAR_RANGE`` when none).

    The reward is always zero, so ``vmas-ros evaluate`` sums this per step instead.
    Needs ``lidar=True`` (``EVALUATE_KWARGS``): the observations are then the readings.
    """
    if not env.scenario.lidar:
        raise ValueError(f"{NAME}: the task score reads the lidar; build the env with lidar=True")
    return torch.stack([obs.min(dim=-1).values for obs in observations]).mean(dim=0)


class HeuristicPolicy(BaseHeuristicPolicy):
    """Keep clear of whatever the lidar sees; stand still when nothing is near.

    Every ray that hits something closer than ``LIDAR_RANGE`` pushes the agent
    the other way, the harder the closer the hit: the push is the sum of
    ``-(1 - d / range) * ray direction`` over the rays, scaled to
    ``u_range`` at most. Ray directions assume the agent's heading is 0 (the
    observation does not hold it; discs are only turned by friction-free
    contacts, which exert no torque on them). Without lidar the observation
    is a constant and the policy stands still. The task pays 0 whatever the
    agents do, so this policy is judged on clearance, not on reward.
    """

    def __init__(self, continuous_action: bool = True, **scenario_kwargs) -> None:
        super().__init__(continuous_action)
        config = continuous_heuristic_kwargs(NAME, DEFAULTS, scenario_kwargs, continuous_action)
        validate(config)
        self.lidar = config["lidar"]
        angles = torch.arange(N_RAYS, dtype=torch.float32) * (2 * math.pi / N_RAYS)
        self.rays = torch.stack([torch.cos(angles), torch.sin(angles)], dim=-1)  # [R, 2]

    def compute_action(self, observation: Tensor, u_range: float) -> Tensor:
        width = N_RAYS if self.lidar else 1
        if observation.shape[1] != width:
            raise ValueError(f"pollock heuristic: expected observation width {width}, got {observation.shape[1]}")
        if not self.lidar:
            return torch.zeros(observation.shape[0], 2, device=observation.device)
        closeness = (1.0 - observation / LIDAR_RANGE).clamp(min=0.0)  # [B, R]
        push = -closeness @ self.rays.to(observation.device)  # [B, 2]
        scale = (u_range / torch.linalg.vector_norm(push, dim=-1, keepdim=True).clamp(min=1e-9)).clamp(max=1.0)
        return push * scale
