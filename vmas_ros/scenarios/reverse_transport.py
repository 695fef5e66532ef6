"""reverse_transport: a team inside a hollow box pushes it onto a goal.

Description
    Transport turned inside out (paper, "Multi-robot scenarios"): one hollow
    box (``package_length`` along x by ``package_width`` along y, mass
    ``package_mass``, not rotatable) holds ``n_agents`` small discs (radius
    0.03, force x0.5). Only the box's outline collides, so the agents move the
    box by pressing its walls from inside; they must bring it over a goal disc
    of radius 0.09. Stiff contacts (collision force 500, margin 6e-3, 5
    substeps) keep the agents inside. There are no outer walls.
Observation (per agent, in this order)
    own position (2), own velocity (2), the box's velocity (2), the box's
    position relative to the agent (2), the box's position relative to the goal (2).
Reward
    Shared by the team: 100 x the decrease of the box's distance to the goal
    over the step, unless the box is on the goal after the step. The box is on
    the goal (and turns green) while the goal disc overlaps its outline or lies
    inside it.
Starting state
    The box and the goal uniform in [-1, 1]^2; the agents uniform inside the
    box (at least one radius from its walls). Unlike VMAS 1.5, whose agents may
    start overlapping each other, agents start at least 0.06 apart. A reset
    clears the on-goal flag even if the goal starts inside the box (it is
    measured from the first step on, as in VMAS).
Episode termination
    When the box is on the goal.
Kwargs
    ``n_agents`` (4), ``package_width`` (0.6), ``package_length`` (0.6),
    ``package_mass`` (50).

The box is named ``package {n_agents - 1}``, as in VMAS 1.5 (whose name
reuses the last agent's index), so entity names match VMAS's.
"""
from __future__ import annotations

import math

import torch

from vmas_ros.scenarios import packages as pk
from vmas_ros.scenarios.common import check_int, check_number, read_kwargs, selected_rows
from vmas_ros.simulator.core import Agent, Box, Landmark, Sphere, World
from vmas_ros.simulator.heuristic_policy import BaseHeuristicPolicy
from vmas_ros.simulator.scenario import BaseScenario
from vmas_ros.simulator.utils import Color

NAME = "reverse_transport"
AGENT_RADIUS = 0.03
AGENT_U_MULTIPLIER = 0.5
GOAL_RADIUS = 0.09
SHAPING_FACTOR = 100.0
#: the box and the goal spawn in [-SPAWN_HALF_SIDE, SPAWN_HALF_SIDE]^2
SPAWN_HALF_SIDE = 1.0
#: at most this fraction of the box's floor may be covered by agents (random packing jams near 0.55)
MAX_CROWDING = 0.3
OBS_WIDTH = 10
DEFAULTS = {"n_agents": 4, "package_width": 0.6, "package_length": 0.6, "package_mass": 50.0}


class Scenario(BaseScenario):
    supports_batched_reset = True

    def make_world(self, batch_dim: int, device, **kwargs) -> World:
        options = read_kwargs(kwargs, DEFAULTS)
        self.n_agents = check_int(NAME, "n_agents", options["n_agents"])
        self.package_width = check_number(NAME, "package_width", options["package_width"], 0.0, strict=True)
        self.package_length = check_number(NAME, "package_length", options["package_length"], 0.0, strict=True)
        self.package_mass = check_number(NAME, "package_mass", options["package_mass"], 0.0, strict=True)
        if min(self.package_length, self.package_width) <= 4 * AGENT_RADIUS:
            raise ValueError(
                f"{NAME}: the box must be wider than two agents ({4 * AGENT_RADIUS}) on both sides, "
                f"got package_length={self.package_length}, package_width={self.package_width}"
            )
        if self.n_agents * math.pi * AGENT_RADIUS**2 > MAX_CROWDING * self.package_length * self.package_width:
            raise ValueError(
                f"{NAME}: {self.n_agents} agents do not fit in a {self.package_length} x {self.package_width} "
                f"box (at most {MAX_CROWDING:.0%} of its floor may be covered)"
            )

        world = World(batch_dim, device, contact_margin=6e-3, substeps=5, collision_force=500)
        for i in range(self.n_agents):
            world.add_agent(Agent(name=f"agent_{i}", shape=Sphere(AGENT_RADIUS), u_multiplier=AGENT_U_MULTIPLIER))
        self.goal = Landmark(name="goal", collide=False, shape=Sphere(radius=GOAL_RADIUS), color=Color.LIGHT_GREEN)
        world.add_landmark(self.goal)
        self.package = Landmark(
            name=f"package {self.n_agents - 1}", collide=True, movable=True, mass=self.package_mass,
            shape=Box(length=self.package_length, width=self.package_width, hollow=True), color=Color.RED,
        )
        self.package.goal = self.goal
        world.add_landmark(self.package)

        #: 100 x the box's distance to the goal when last scored, [B]
        self.potential = torch.zeros(batch_dim, device=world.device)
        #: whether the box is on the goal, as of the last reward (False right after a reset), [B]
        self.on_goal = torch.zeros(batch_dim, dtype=torch.bool, device=world.device)
        self._reward = torch.zeros(batch_dim, device=world.device)
        return world

    # ------------------------------------------------------------------- reset
    def reset_world_at(self, env_index: pk.EnvIndex = None) -> None:
        world = self.world
        rows = selected_rows(world.batch_dim, env_index)
        box = torch.empty(rows, 2, device=world.device).uniform_(-SPAWN_HALF_SIDE, SPAWN_HALF_SIDE)
        inner = (self.package_length / 2 - AGENT_RADIUS, self.package_width / 2 - AGENT_RADIUS)
        offsets = pk.spawn_apart(
            rows, self.n_agents, 2 * AGENT_RADIUS, (-inner[0], -inner[1]), inner, world.device, what="agents in the box"
        )
        goal = torch.empty(rows, 2, device=world.device).uniform_(-SPAWN_HALF_SIDE, SPAWN_HALF_SIDE)
        pk.place(self.package, box, env_index)
        for agent, offset in zip(world.agents, offsets.unbind(1)):
            pk.place(agent, box + offset, env_index)
        pk.place(self.goal, goal, env_index)
        if env_index is None:
            self.potential = self._distance() * SHAPING_FACTOR
            self.on_goal = torch.zeros_like(self.on_goal)
        else:
            self.potential[env_index] = self._distance()[env_index] * SHAPING_FACTOR
            self.on_goal[env_index] = False
        self.package.color = pk.package_colors(self.on_goal)

    def _distance(self) -> torch.Tensor:
        return torch.linalg.vector_norm(self.package.state.pos - self.goal.state.pos, dim=-1)

    # ------------------------------------------------------------------ reward
    def reward(self, agent: Agent) -> torch.Tensor:
        """The team's reward, computed once per step (when asked for the first agent)."""
        if agent is self.world.agents[0]:
            potential = self._distance() * SHAPING_FACTOR
            self.on_goal = self.world.is_overlapping(self.package, self.goal)
            self._reward = pk.delivery_reward(self.potential, potential, self.on_goal)
            self.potential = potential
            self.package.color = pk.package_colors(self.on_goal)
        return self._reward

    # ------------------------------------------------------------- observation
    def observation(self, agent: Agent) -> torch.Tensor:
        box = self.package.state
        return torch.cat([
            agent.state.pos, agent.state.vel, box.vel, box.pos - agent.state.pos, box.pos - self.goal.state.pos,
        ], dim=-1)

    def done(self) -> torch.Tensor:
        return self.on_goal


class HeuristicPolicy(BaseHeuristicPolicy):
    """Every agent pushes the box's wall that faces the goal.

    The box never rotates and only its outline collides, so an agent inside
    that drives towards the goal meets the wall (or the corner) on the goal's
    side and presses it: the push it gives the box is the part of its force
    along that wall's normal, and the rest slides it along the wall into the
    corner the goal lies towards. Everyone pushes the same way, so no agent
    works against another. The drive eases off linearly within ``ease`` of
    the goal, so a box that has just reached it does not coast far past.
    """

    ease = 0.1

    def compute_action(self, observation: torch.Tensor, u_range: float) -> torch.Tensor:
        if observation.shape[1] != OBS_WIDTH:
            raise ValueError(f"{NAME} heuristic: observation width {observation.shape[1]} is not {OBS_WIDTH}")
        to_goal = -observation[:, 8:10]  # box -> goal
        distance = torch.linalg.vector_norm(to_goal, dim=-1, keepdim=True)
        direction = pk.unit(to_goal) * (distance / self.ease).clamp(max=1.0)
        return pk.scale_to_range(direction, u_range)
