"""dropout: one agent should fetch the goal while the rest of the team saves energy.

Description
    ``n_agents`` non-colliding agents (discs of radius 0.05) and one green goal
    (radius 0.03, non-colliding). The team is paid once, when any agent first
    covers the goal, and pays for every unit of thrust any agent spends (paper,
    "Multi-robot scenarios": the best team sends only the agent closest to the
    goal, and the others "drop out"). A covered goal stays where it is but is
    no longer drawn and pays nothing more.
Observation (per agent, in this order)
    own position (2), own velocity (2), the goal's position relative to the
    agent (2), whether the goal has been eaten (1, 0. or 1.).
Reward (shared: every agent gets the team's reward)
    ``pos_rew``: 1 at the step the goal is first covered, else 0; plus
    ``energy_rew``: minus ``energy_coeff`` times the sum over agents of
    ``|u| / (sqrt(2) x u_range x u_multiplier)`` (each agent's thrust as a
    fraction of the largest it can give; none before an agent's first action).
    Both terms are in ``info``.
Starting state
    Agents and goal uniform in [-1, 1]^2, at rest, centres at least 0.09 apart
    (the sum of the radii plus 0.01); with ``start_same_point`` every agent at
    the origin and the goal at least 0.09 from it. Goal not eaten.
Episode termination
    At a step where some agent covers the goal. As in VMAS 1.5 the flag
    follows the cover: without an env reset it goes back to False once no agent
    covers the (already eaten) goal any more.
Kwargs
    ``n_agents`` (4), ``energy_coeff`` (0.02), ``start_same_point`` (False).
"""
from __future__ import annotations

import math

import torch

from vmas_ros.scenarios import food as foodlib
from vmas_ros.scenarios.common import for_index, read_kwargs, selected_rows
from vmas_ros.simulator.core import Agent, Landmark, Sphere, World
from vmas_ros.simulator.heuristic_policy import BaseHeuristicPolicy
from vmas_ros.simulator.scenario import BaseScenario
from vmas_ros.simulator.utils import Color

AGENT_RADIUS = 0.05
GOAL_RADIUS = 0.03
SPAWN_GAP = AGENT_RADIUS + GOAL_RADIUS + 0.01
SPAWN_BOUND = 1.0
#: the energy penalty's default weight (VMAS's module exports it under this name)
DEFAULT_ENERGY_COEFF = 0.02
#: name -> default of every kwarg
DEFAULTS = {"n_agents": 4, "energy_coeff": DEFAULT_ENERGY_COEFF, "start_same_point": False}


class Scenario(BaseScenario):
    supports_batched_reset = True

    def make_world(self, batch_dim: int, device, **kwargs) -> World:
        config = read_kwargs(kwargs, DEFAULTS)
        self.n_agents, self.energy_coeff = config["n_agents"], config["energy_coeff"]
        self.start_same_point = config["start_same_point"]
        if isinstance(self.n_agents, bool) or not isinstance(self.n_agents, int) or self.n_agents < 1:
            raise ValueError(f"dropout: n_agents must be an int >= 1, got {self.n_agents!r}")
        if isinstance(self.energy_coeff, bool) or not isinstance(self.energy_coeff, (int, float)) \
                or not self.energy_coeff >= 0:
            raise ValueError(f"dropout: energy_coeff must be a number >= 0, got {self.energy_coeff!r}")
        if not isinstance(self.start_same_point, bool):
            # a ValueError like every other bad kwarg value: the caller passed a wrong value, not a wrong API
            raise ValueError(  # noqa: TRY004
                f"dropout: start_same_point must be True or False, got {self.start_same_point!r}"
            )

        world = World(batch_dim, device)
        for i in range(self.n_agents):
            world.add_agent(Agent(name=f"agent_{i}", collide=False, shape=Sphere(radius=AGENT_RADIUS)))
        world.add_landmark(Landmark(name="goal", collide=False, shape=Sphere(radius=GOAL_RADIUS), color=Color.GREEN))
        self._goal = world.landmarks[0]
        self._agent_radius = foodlib.radii(world.agents, world.device)
        self._goal_radius = foodlib.radii(world.landmarks, world.device)
        # each agent's largest thrust norm, which the energy penalty is measured against [A]
        self._full_thrust = torch.tensor(
            [math.sqrt(world.dim_p * (a.u_range * a.u_multiplier) ** 2) for a in world.agents], device=world.device,
        )
        self._no_thrust = torch.zeros(batch_dim, world.dim_p, device=world.device)
        #: whether the goal has been eaten, per env [B, 1]
        self.eaten = torch.zeros(batch_dim, 1, dtype=torch.bool, device=world.device)
        # set by the first agent's reward (so every agent gets the same), committed by the last one's
        self._reached = torch.zeros(batch_dim, dtype=torch.bool, device=world.device)
        self.pos_rew = torch.zeros(batch_dim, device=world.device)
        self.energy_rew = torch.zeros(batch_dim, device=world.device)
        return world

    def reset_world_at(self, env_index=None) -> None:
        world = self.world
        rows = selected_rows(world.batch_dim, env_index)
        if self.start_same_point:
            agents = torch.zeros(rows, self.n_agents, world.dim_p, device=world.device)
            goal = foodlib.spread_positions(
                world, env_index, 1, SPAWN_GAP, -SPAWN_BOUND, SPAWN_BOUND, occupied=agents[:, :1],
            )
        else:
            spots = foodlib.spread_positions(world, env_index, self.n_agents + 1, SPAWN_GAP, -SPAWN_BOUND, SPAWN_BOUND)
            agents, goal = spots[:, :-1], spots[:, -1:]
        for i, agent in enumerate(world.agents):
            agent.set_pos(for_index(agents[:, i], env_index), batch_index=env_index)
        self._goal.set_pos(for_index(goal[:, 0], env_index), batch_index=env_index)
        selected = slice(None) if env_index is None else env_index
        for flags in (self.eaten, self._reached):
            flags[selected] = False
        for term in (self.pos_rew, self.energy_rew):
            term[selected] = 0.0
        foodlib.show_food(world.landmarks, env_index)

    # ------------------------------------------------------------------ reward
    def reward(self, agent: Agent) -> torch.Tensor:
        world = self.world
        if agent is world.agents[0]:
            self._score_step()
        if agent is world.agents[-1]:
            self.eaten = self.eaten | self._reached.unsqueeze(-1)
            foodlib.hide_eaten(world.landmarks, self.eaten)
        return self.pos_rew + self.energy_rew

    def _score_step(self) -> None:
        """The team's two reward terms for this step (``pos_rew``, ``energy_rew``, [B] each)."""
        world = self.world
        covered = foodlib.coverage(
            foodlib.stacked_pos(world.agents), self._agent_radius,
            foodlib.stacked_pos(world.landmarks), self._goal_radius,
        )  # [B, A, 1]
        self._reached = covered.any(dim=1).squeeze(-1)
        self.pos_rew = (self._reached & ~self.eaten.squeeze(-1)).float()
        # before an env's first step no action has been set yet: no thrust spent
        u = [a.action.u if a.action.u is not None else self._no_thrust for a in world.agents]
        thrust = torch.linalg.vector_norm(torch.stack(u, dim=1), dim=-1)  # [B, A]
        self.energy_rew = -self.energy_coeff * (thrust / self._full_thrust).sum(dim=-1)

    # ------------------------------------------------------------- observation
    def observation(self, agent: Agent) -> torch.Tensor:
        pos = agent.state.pos
        return torch.cat(
            [pos, agent.state.vel, self._goal.state.pos - pos, self.eaten.to(pos.dtype)], dim=-1,
        )

    def info(self, agent: Agent) -> dict[str, torch.Tensor]:
        return {"pos_rew": self.pos_rew, "energy_rew": self.energy_rew}

    def done(self) -> torch.Tensor:
        return self._reached


class HeuristicPolicy(BaseHeuristicPolicy):
    """Go for the goal at a thrust that falls steeply with one's own distance to it; stop once it is eaten.

    The ideal team sends only the agent closest to the goal, but an agent
    sees only itself and the goal, so it cannot know whether it is the
    closest. It does not need to: at terminal speed the distance an agent
    covers per unit of energy does not depend on its thrust, so what the team
    pays is about proportional to the total distance its agents travel before
    the goal is eaten. Each agent therefore pushes towards the goal with
    ``u_range x min(1, (reach / distance) ** steepness)``: the closest agent
    arrives first, while the farther ones have crept only a small fraction
    ``(d_closest / d) ** steepness`` of the way, which is nearly staying
    still. Once the goal is eaten (the last observation entry) every agent
    stops pushing. With ``start_same_point`` all agents are equally far, so
    all of them go.
    """

    reach = 0.5
    steepness = 3.0

    def compute_action(self, observation: torch.Tensor, u_range: float) -> torch.Tensor:
        if observation.shape[1] != 7:
            raise ValueError(f"dropout heuristic: observation width {observation.shape[1]} is not 7")
        to_goal, eaten = observation[:, 4:6], observation[:, 6:7] > 0.5
        dist = torch.linalg.vector_norm(to_goal, dim=-1, keepdim=True).clamp_min(1e-6)
        thrust = u_range * (self.reach / dist).pow(self.steepness).clamp_max(1.0)
        return torch.where(eaten, 0.0, thrust * to_goal / dist).clamp(-u_range, u_range)
