"""dispersion: agents starting together must split up to eat every piece of food.

Description
    ``n_agents`` non-colliding agents (discs of radius 0.035) all start at the
    origin; ``n_food`` green food discs (radius ``food_radius``, non-colliding)
    lie scattered around them inside walls at ``+-pos_range`` (paper,
    "Multi-robot scenarios": the team is fastest when each agent goes to a
    different piece of food). An agent eats a food by overlapping it; eaten
    food stays where it is but is no longer drawn and pays nothing more.
Observation (per agent, in this order)
    own position (2), own velocity (2), then for each food in order its
    position relative to the agent (2) and whether it is eaten (1, 0. or 1.).
    Agents do not see each other.
Reward
    A food pays once, at the step it is first covered. By default it pays 1
    shared equally among the agents covering it then (so the team's total over
    an episode is the number of food eaten); with ``share_reward`` every agent
    gets 1 per food eaten anywhere that step. With ``penalise_by_time`` an
    agent whose reward is exactly 0 at a step gets -0.01 instead.
Starting state
    Agents at the origin, at rest; food uniform in [-pos_range, pos_range]^2;
    nothing eaten.
Episode termination
    When every food has been eaten.
Kwargs
    ``n_agents`` (4), ``share_reward`` (False), ``penalise_by_time`` (False),
    ``food_radius`` (0.05), ``pos_range`` (1.0), ``n_food`` (``n_agents``).
"""
from __future__ import annotations

import torch

from vmas_ros.scenarios import food as foodlib
from vmas_ros.scenarios.common import for_index, read_kwargs, selected_rows
from vmas_ros.simulator.core import Agent, Landmark, Sphere, World
from vmas_ros.simulator.heuristic_policy import BaseHeuristicPolicy
from vmas_ros.simulator.scenario import BaseScenario
from vmas_ros.simulator.utils import Color

AGENT_RADIUS = 0.035
TIME_PENALTY = -0.01
#: name -> default of every kwarg (``n_food`` None: one per agent)
DEFAULTS = {
    "n_agents": 4, "share_reward": False, "penalise_by_time": False, "food_radius": 0.05, "pos_range": 1.0,
    "n_food": None,
}


def _positive_int(name: str, value) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ValueError(f"dispersion: {name} must be an int >= 1, got {value!r}")
    return value


def _positive_float(name: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0:
        raise ValueError(f"dispersion: {name} must be a number > 0, got {value!r}")
    return float(value)


def _flag(name: str, value) -> bool:
    if not isinstance(value, bool):
        # a ValueError like every other bad kwarg value: the caller passed a wrong value, not a wrong API
        raise ValueError(f"dispersion: {name} must be True or False, got {value!r}")  # noqa: TRY004
    return value


class Scenario(BaseScenario):
    supports_batched_reset = True

    def make_world(self, batch_dim: int, device, **kwargs) -> World:
        config = read_kwargs(kwargs, DEFAULTS)
        self.n_agents = _positive_int("n_agents", config["n_agents"])
        self.share_reward = _flag("share_reward", config["share_reward"])
        self.penalise_by_time = _flag("penalise_by_time", config["penalise_by_time"])
        self.food_radius = _positive_float("food_radius", config["food_radius"])
        self.pos_range = _positive_float("pos_range", config["pos_range"])
        self.n_food = _positive_int("n_food", self.n_agents if config["n_food"] is None else config["n_food"])

        world = World(batch_dim, device, x_semidim=self.pos_range, y_semidim=self.pos_range)
        for i in range(self.n_agents):
            world.add_agent(Agent(name=f"agent_{i}", collide=False, shape=Sphere(radius=AGENT_RADIUS)))
        for i in range(self.n_food):
            world.add_landmark(Landmark(
                name=f"food_{i}", collide=False, shape=Sphere(radius=self.food_radius), color=Color.GREEN,
            ))
        self._agent_radius = foodlib.radii(world.agents, world.device)
        self._food_radius = foodlib.radii(world.landmarks, world.device)
        self._index = {agent.name: i for i, agent in enumerate(world.agents)}
        #: which food has been eaten, per env [B, F]
        self.eaten = torch.zeros(batch_dim, self.n_food, dtype=torch.bool, device=world.device)
        # food first covered at the current step [B, F], cached by the first agent's reward and
        # committed to ``eaten`` by the last agent's, so every agent is scored against the same state
        self._fresh = torch.zeros_like(self.eaten)
        self._rewards = torch.zeros(batch_dim, self.n_agents, device=world.device)
        return world

    def reset_world_at(self, env_index=None) -> None:
        world = self.world
        rows = selected_rows(world.batch_dim, env_index)
        origin = torch.zeros(rows, world.dim_p, device=world.device)
        for agent in world.agents:
            agent.set_pos(for_index(origin, env_index), batch_index=env_index)
        spots = foodlib.uniform_positions(world, env_index, self.n_food, -self.pos_range, self.pos_range)
        for k, landmark in enumerate(world.landmarks):
            landmark.set_pos(for_index(spots[:, k], env_index), batch_index=env_index)
        if env_index is None:
            self.eaten.zero_()
            self._fresh.zero_()
        else:
            self.eaten[env_index] = False
            self._fresh[env_index] = False
        foodlib.show_food(world.landmarks, env_index)

    # ------------------------------------------------------------------ reward
    def reward(self, agent: Agent) -> torch.Tensor:
        world = self.world
        if agent is world.agents[0]:
            self._rewards = self._team_rewards()
        if agent is world.agents[-1]:
            self.eaten = self.eaten | self._fresh
            foodlib.hide_eaten(world.landmarks, self.eaten)
        return self._rewards[:, self._index[agent.name]]

    def _team_rewards(self) -> torch.Tensor:
        """Every agent's reward at this step, [B, A]; records the food eaten now in ``_fresh``."""
        covered = foodlib.coverage(
            foodlib.stacked_pos(self.world.agents), self._agent_radius,
            foodlib.stacked_pos(self.world.landmarks), self._food_radius,
        )  # [B, A, F]
        eaters = covered.sum(dim=1)  # [B, F]
        self._fresh = (eaters > 0) & ~self.eaten
        if self.share_reward:
            rewards = self._fresh.sum(dim=1, keepdim=True).float().expand(-1, self.n_agents)
        else:
            share = self._fresh / eaters.clamp_min(1)  # [B, F]: 1 / number of eaters, 0 if not fresh
            rewards = (covered * share.unsqueeze(1)).sum(dim=2)
        if self.penalise_by_time:
            rewards = torch.where(rewards == 0, TIME_PENALTY, rewards)
        return rewards

    # ------------------------------------------------------------- observation
    def observation(self, agent: Agent) -> torch.Tensor:
        offsets = foodlib.stacked_pos(self.world.landmarks) - agent.state.pos.unsqueeze(1)  # [B, F, 2]
        per_food = torch.cat([offsets, self.eaten.unsqueeze(-1).to(offsets.dtype)], dim=-1)
        return torch.cat([agent.state.pos, agent.state.vel, per_food.flatten(1)], dim=-1)

    def done(self) -> torch.Tensor:
        return self.eaten.all(dim=-1)


class HeuristicPolicy(BaseHeuristicPolicy):
    """Each agent picks a food of its own, keeps to it, and moves on to the next when it is gone.

    An agent sees no other agent, and all agents start at the same spot, so
    at the first step every agent's observation is the same: no deterministic
    decentralised rule can send them to different food. The symmetry is broken
    by chance instead: an agent at rest draws a random heading. From then on an
    agent's heading is its velocity, and it targets the uneaten food that
    minimises ``distance x (1 + turn_cost x (1 - cos angle))``, the angle being
    between the heading and the food's bearing. Since the agent then flies
    towards that food, the choice sustains itself (the agents keep to
    different food when their random headings differ), a food right on the way
    is taken in passing, and after eating the agent prefers food ahead of it
    to food behind. Flight is at full thrust towards the target (the disc in
    which an agent covers a food is wider than a step, so it is never
    overshot); with every food eaten the agent stops pushing.
    """

    turn_cost = 4.0
    at_rest = 1e-3

    def compute_action(self, observation: torch.Tensor, u_range: float) -> torch.Tensor:
        batch, width = observation.shape
        if width < 7 or (width - 4) % 3:
            raise ValueError(f"dispersion heuristic: observation width {width} is not 4 + 3 x n_food")
        vel = observation[:, 2:4]
        per_food = observation[:, 4:].view(batch, -1, 3)
        offsets, eaten = per_food[..., :2], per_food[..., 2] > 0.5
        dist = torch.linalg.vector_norm(offsets, dim=-1).clamp_min(1e-6)  # [B, F]
        bearing = offsets / dist.unsqueeze(-1)
        speed = torch.linalg.vector_norm(vel, dim=-1, keepdim=True)
        random_heading = torch.nn.functional.normalize(torch.randn_like(vel), dim=-1)
        heading = torch.where(speed > self.at_rest, vel / speed.clamp_min(1e-9), random_heading)
        cos = (bearing * heading.unsqueeze(1)).sum(dim=-1)
        cost = torch.where(eaten, torch.inf, dist * (1 + self.turn_cost * (1 - cos)))
        target = cost.argmin(dim=1)
        rows = torch.arange(batch, device=observation.device)
        aim = bearing[rows, target]
        hungry = (~eaten).any(dim=1, keepdim=True)
        return torch.where(hungry, aim * u_range, 0.0).clamp(-u_range, u_range)
