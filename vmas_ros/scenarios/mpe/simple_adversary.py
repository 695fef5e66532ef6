"""simple_adversary (MPE "physical deception").

Description
    ``n_agents`` agents, the first ``n_adversaries`` of them adversaries (red),
    and ``n_agents - 1`` landmarks. In every env one landmark is the goal
    (drawn green). Good agents (blue) know which one it is; adversaries do
    not, and must guess it from where the good agents go. Good agents should
    therefore cover every landmark, so that reaching the goal gives nothing away.
Observation (per agent, in this order)
    good agent: goal position relative to the agent (2), every landmark's
    relative position (2 x n_landmarks), every other agent's relative position
    in world order, adversaries first (2 x (n_agents - 1)).
    adversary: the same without the goal (it is never told which landmark it is).
Reward (individual, as in MPE and VMAS 1.5)
    adversary: minus its distance to the goal.
    good agent (shared by the good team): minus the distance from the goal to
    the closest good agent, plus the sum of the adversaries' distances to it.
Starting state
    Agents and landmarks uniform in [-1, 1]^2, the goal uniform among the
    landmarks. Unlike VMAS 1.5 (one goal for the whole batch, kept by
    ``reset_at``), the goal is drawn per env and redrawn when an env is reset;
    ``Scenario.goal`` ([batch] landmark indices) holds it.
Episode termination
    Never (set ``max_steps``).
Kwargs
    ``n_agents`` (3), ``n_adversaries`` (1); need ``1 <= n_adversaries < n_agents``.
"""
from __future__ import annotations

import torch

from vmas_ros.scenarios.common import greedy_first_match, read_kwargs
from vmas_ros.simulator.core import Agent, Landmark, Sphere, World
from vmas_ros.simulator.heuristic_policy import BaseHeuristicPolicy
from vmas_ros.simulator.scenario import BaseScenario
from vmas_ros.simulator.utils import Color

#: name -> default of every kwarg
DEFAULTS = {"n_agents": 3, "n_adversaries": 1}

AGENT_RADIUS = 0.15
LANDMARK_RADIUS = 0.08


def _reset_rows(world: World, env_index) -> torch.Tensor:
    """The env indices a reset touches, as a 1-D long tensor (None means every env)."""
    if env_index is None:
        return torch.arange(world.batch_dim, device=world.device)
    return torch.as_tensor(env_index, dtype=torch.long, device=world.device).reshape(-1)


def _scatter_uniform(entities, rows: torch.Tensor, env_index) -> None:
    """Place ``entities`` uniformly in [-1, 1]^2 in the envs ``rows``: one draw for all of them."""
    pos = torch.empty(len(rows), len(entities), 2, device=rows.device).uniform_(-1.0, 1.0)
    for entity, p in zip(entities, pos.unbind(1)):
        entity.set_pos(p, batch_index=None if env_index is None else rows)


class Scenario(BaseScenario):
    supports_batched_reset = True

    def make_world(self, batch_dim: int, device, **kwargs) -> World:
        config = read_kwargs(kwargs, DEFAULTS)
        n_agents, n_adversaries = config["n_agents"], config["n_adversaries"]
        if not isinstance(n_agents, int) or not isinstance(n_adversaries, int) or not 1 <= n_adversaries < n_agents:
            raise ValueError(
                f"simple_adversary: need ints with 1 <= n_adversaries < n_agents, "
                f"got n_agents={n_agents!r}, n_adversaries={n_adversaries!r}"
            )
        world = World(batch_dim=batch_dim, device=device)
        for i in range(n_agents):
            adversary = i < n_adversaries
            world.add_agent(Agent(
                name=f"adversary_{i}" if adversary else f"agent_{i - n_adversaries}",
                collide=False, shape=Sphere(radius=AGENT_RADIUS),
                color=Color.RED if adversary else Color.BLUE, adversary=adversary,
            ))
        for i in range(n_agents - 1):
            world.add_landmark(Landmark(
                name=f"landmark {i}", collide=False, shape=Sphere(radius=LANDMARK_RADIUS), color=Color.BLACK,
            ))
        self.is_adversary = torch.tensor([a.adversary for a in world.agents], device=device)  # [A]
        self.goal = torch.zeros(batch_dim, dtype=torch.long, device=device)  # [B] goal landmark index
        self._goal_dist = None
        return world

    def reset_world_at(self, env_index=None) -> None:
        world = self.world
        rows = _reset_rows(world, env_index)
        self.goal[rows] = torch.randint(len(world.landmarks), (len(rows),), device=world.device)
        _scatter_uniform(world.agents + world.landmarks, rows, env_index)
        self._paint_goal()

    def _paint_goal(self) -> None:
        """Landmark colours per env: green for the goal, black for the decoys."""
        green = torch.tensor(Color.GREEN.value, device=self.world.device)
        black = torch.tensor(Color.BLACK.value, device=self.world.device)
        for i, landmark in enumerate(self.world.landmarks):
            landmark.color = torch.where((self.goal == i).unsqueeze(-1), green, black)

    def _positions(self):
        agents = torch.stack([a.state.pos for a in self.world.agents], dim=1)  # [B, A, 2]
        landmarks = torch.stack([l.state.pos for l in self.world.landmarks], dim=1)  # [B, L, 2]
        goal = landmarks[torch.arange(agents.shape[0], device=agents.device), self.goal]  # [B, 2]
        return agents, landmarks, goal

    def reward(self, agent: Agent) -> torch.Tensor:
        if agent is self.world.agents[0] or self._goal_dist is None:
            agents, _, goal = self._positions()
            self._goal_dist = torch.linalg.vector_norm(agents - goal.unsqueeze(1), dim=-1)  # [B, A]
        dist = self._goal_dist
        if agent.adversary:
            return -dist[:, self.world.agents.index(agent)]
        closest_good = dist[:, ~self.is_adversary].amin(dim=-1)
        return dist[:, self.is_adversary].sum(dim=-1) - closest_good

    def observation(self, agent: Agent) -> torch.Tensor:
        agents, landmarks, goal = self._positions()
        me = self.world.agents.index(agent)
        own = agent.state.pos.unsqueeze(1)
        others = torch.cat([agents[:, :me], agents[:, me + 1:]], dim=1)
        parts = [(landmarks - own).flatten(1), (others - own).flatten(1)]
        if not agent.adversary:
            parts.insert(0, goal - agent.state.pos)
        return torch.cat(parts, dim=-1)


class HeuristicPolicy(BaseHeuristicPolicy):
    """Good agents cover every landmark, one of them the goal; adversaries bet on an occupied landmark.

    The role is read from the observation's width (a good agent's has the 2
    extra goal columns: width 4n - 2 against 4n - 4 for n agents). Good agents
    treat the first ``n_adversaries`` other agents as adversaries (world order
    puts them first; set the attribute if the scenario was built with another
    value). A good agent matches good agents to landmarks greedily, nearest
    pair first, after moving the goal to the front of the queue, so the good
    agent nearest the goal takes it and the others sit on decoys. An adversary
    heads for the landmark with another agent nearest to it: naive good agents
    crowd the goal, while covering ones leave it a coin flip.
    """

    gain = 3.0
    n_adversaries = 1

    def compute_action(self, observation: torch.Tensor, u_range: float) -> torch.Tensor:
        batch, width = observation.shape
        good = width % 4 == 2
        body = observation[:, 2:] if good else observation  # 2 x (n - 1) landmarks, then 2 x (n - 1) agents
        n_landmarks = body.shape[1] // 4
        landmarks = body[:, : 2 * n_landmarks].view(batch, n_landmarks, 2)
        others = body[:, 2 * n_landmarks:].view(batch, -1, 2)
        rows = torch.arange(batch, device=observation.device)
        if good:
            goal = (landmarks - observation[:, None, :2]).norm(dim=-1).argmin(dim=-1)
            target = landmarks[rows, self._my_landmark(landmarks, others[:, self.n_adversaries:], goal)]
        else:
            crowd = torch.cdist(landmarks, others).amin(dim=-1)  # [B, L]
            target = landmarks[rows, crowd.argmin(dim=-1)]
        # velocity is not observed; the world's drag (0.25 per step) damps this P-controller enough
        return (self.gain * target).clamp(-u_range, u_range)

    @staticmethod
    def _my_landmark(landmarks: torch.Tensor, teammates: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
        """Index of the landmark this agent takes in a greedy good-agent/landmark matching."""
        batch, n = landmarks.shape[:2]
        team = torch.cat([torch.zeros(batch, 1, 2, device=landmarks.device), teammates], dim=1)  # self first
        dist = torch.cdist(team, landmarks)  # [B, G, L]
        dist = dist - 1e3 * torch.nn.functional.one_hot(goal, n).unsqueeze(1)  # goal pairs first
        mine = greedy_first_match(dist)
        return torch.where(mine < 0, goal, mine)
