"""simple_reference (MPE "reference": two speakers that are also listeners).

Description
    Two agents and three landmarks coloured red, green and blue. Each agent
    knows which landmark its *partner* must reach but not its own, and both
    can talk (a ``dim_c = 10`` channel), so each must tell the other where to go
    and listen for where it should go itself.
Observation (per agent, in this order)
    own velocity (2), each landmark's position relative to the agent (2 x 3),
    colour of the landmark the partner must reach (3), the partner's last
    message (10).
Reward (shared by both agents, as in VMAS 1.5)
    Minus the sum over both agents of the distance between each one and its
    target landmark. MPE mixes a local and a global term with ``local_ratio``
    instead; the sum of MPE's two rewards equals this reward for any ratio.
Starting state
    Agents and landmarks uniform in [-1, 1]^2. Each agent's target landmark
    is uniform among the three, drawn per env (VMAS 1.5 draws one assignment
    for the whole batch and keeps it on ``reset_at``) and redrawn when an env
    is reset. ``Scenario.goal`` ([batch, 2] landmark indices) holds them:
    ``goal[:, i]`` is the landmark agent ``i`` wants its partner to reach.
    Each agent is drawn in the colour of its own target.
Episode termination
    Never (set ``max_steps``).
Kwargs
    None.
"""
from __future__ import annotations

import torch

from vmas_ros.scenarios.common import read_kwargs
from vmas_ros.simulator.core import Agent, Landmark, World
from vmas_ros.simulator.heuristic_policy import BaseHeuristicPolicy
from vmas_ros.simulator.scenario import BaseScenario

DIM_C = 10
#: landmark colours, one row per landmark (red, green, blue)
PALETTE = ((0.75, 0.25, 0.25), (0.25, 0.75, 0.25), (0.25, 0.25, 0.75))
AGENT_GRAY = (0.25, 0.25, 0.25)


def _reset_rows(world: World, env_index) -> torch.Tensor:
    """The env indices a reset touches, as a 1-D long tensor (None means every env)."""
    if env_index is None:
        return torch.arange(world.batch_dim, device=world.device)
    return torch.as_tensor(env_index, dtype=torch.long, device=world.device).reshape(-1)


class Scenario(BaseScenario):
    supports_batched_reset = True

    def make_world(self, batch_dim: int, device, **kwargs) -> World:
        read_kwargs(kwargs, {})  # no kwargs: any given one warns, naming it
        world = World(batch_dim=batch_dim, device=device, dim_c=DIM_C)
        for i in range(2):
            world.add_agent(Agent(name=f"agent_{i}", collide=False, silent=False, color=AGENT_GRAY))
        self.palette = torch.tensor(PALETTE, device=device)  # [L, 3]
        for i, color in enumerate(PALETTE):
            world.add_landmark(Landmark(name=f"landmark {i}", collide=False, color=color))
        self.goal = torch.zeros(batch_dim, 2, dtype=torch.long, device=device)  # [B, 2]
        self._reward_cache = None
        return world

    def reset_world_at(self, env_index=None) -> None:
        world = self.world
        rows = _reset_rows(world, env_index)
        self.goal[rows] = torch.randint(len(world.landmarks), (len(rows), 2), device=world.device)
        entities = world.agents + world.landmarks
        pos = torch.empty(len(rows), len(entities), 2, device=world.device).uniform_(-1.0, 1.0)
        for entity, p in zip(entities, pos.unbind(1)):
            entity.set_pos(p, batch_index=None if env_index is None else rows)
        for i, agent in enumerate(world.agents):
            agent.color = self.palette[self.goal[:, 1 - i]]  # [B, 3]: the colour of its own target

    def reward(self, agent: Agent) -> torch.Tensor:
        if agent is self.world.agents[0] or self._reward_cache is None:
            agents = torch.stack([a.state.pos for a in self.world.agents], dim=1)  # [B, 2, 2]
            landmarks = torch.stack([l.state.pos for l in self.world.landmarks], dim=1)  # [B, L, 2]
            # goal[:, i] is meant for agent 1 - i
            targets = torch.gather(landmarks, 1, self.goal.flip(-1).unsqueeze(-1).expand(-1, -1, 2))
            self._reward_cache = -torch.linalg.vector_norm(agents - targets, dim=-1).sum(dim=-1)
        return self._reward_cache

    def observation(self, agent: Agent) -> torch.Tensor:
        me = self.world.agents.index(agent)
        landmarks = torch.stack([l.state.pos for l in self.world.landmarks], dim=1)
        partner = self.world.agents[1 - me]
        return torch.cat(
            [
                agent.state.vel,
                (landmarks - agent.state.pos.unsqueeze(1)).flatten(1),
                self.palette[self.goal[:, me]],
                partner.state.c,
            ],
            dim=-1,
        )


class HeuristicPolicy(BaseHeuristicPolicy):
    """Say the partner's landmark as a one-hot word, go where the partner's word points.

    The brightest channel of the observed goal colour is the landmark's index
    (red 0, green 1, blue 2), so the agent speaks the one-hot vector of that
    index in the first three of the ten channels. It reads its partner's
    message the same way and steers to that landmark with a damped
    proportional controller; until the partner has spoken (an all-zero
    message, the first step) it brakes.
    """

    gain = 3.0
    damping = 1.0

    def compute_action(self, observation: torch.Tensor, u_range: float) -> torch.Tensor:
        batch = observation.shape[0]
        n_landmarks = len(PALETTE)
        vel = observation[:, :2]
        landmarks = observation[:, 2: 2 + 2 * n_landmarks].view(batch, n_landmarks, 2)
        goal_color = observation[:, 2 + 2 * n_landmarks: 5 + 2 * n_landmarks]
        heard = observation[:, 5 + 2 * n_landmarks:]
        word = torch.nn.functional.one_hot(goal_color.argmax(dim=-1), heard.shape[1]).to(observation.dtype)
        mine = heard[:, :n_landmarks].argmax(dim=-1)
        target = landmarks[torch.arange(batch, device=observation.device), mine]
        spoken = (heard != 0).any(dim=-1, keepdim=True)
        u = torch.where(spoken, self.gain * target, 0.0) - self.damping * vel
        return torch.cat([u.clamp(-u_range, u_range), word], dim=-1)
