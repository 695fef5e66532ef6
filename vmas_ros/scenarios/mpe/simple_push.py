"""simple_push (MPE "keep-away"): an adversary keeps a good agent off its goal.

Description
    One good agent and one adversary (both colliding discs of radius 0.05) and
    two non-colliding landmarks. One landmark, drawn at random per env, is the
    goal. The good agent knows which one it is; the adversary does not, and
    must guess it from the good agent's behaviour and push it away.
Observation (per agent, in this order)
    Good agent: own velocity (2), the goal's position relative to it (2), its
    own colour (3, which encodes the goal), each landmark's relative position
    (2 x 2), each landmark's colour (3 x 2), the adversary's relative position (2).
    Adversary: own velocity (2), each landmark's relative position (2 x 2), the
    good agent's relative position (2).
Reward
    Good agent: minus its distance to the goal. Adversary: the good agent's
    distance to the goal minus the adversary's own distance to the goal.
Starting state
    Agents and landmarks uniform in [-1, 1]^2, at rest; landmark ``i`` is
    coloured (0.1, 0.1, 0.1) + 0.8 on channel ``i + 1``, the good agent
    (0.25, 0.25, 0.25) + 0.5 on its goal's channel, the adversary red.
    Unlike VMAS 1.5 (one goal for the whole batch, redrawn only on a full
    reset), the goal is drawn per env on every reset of that env, as in MPE.
Episode termination
    Never (set ``max_steps``).
Kwargs
    None (unknown kwargs warn).
"""
from __future__ import annotations

import torch

from vmas_ros.scenarios.common import read_kwargs
from vmas_ros.simulator.core import Agent, Landmark, World
from vmas_ros.simulator.heuristic_policy import BaseHeuristicPolicy
from vmas_ros.simulator.scenario import BaseScenario

N_LANDMARKS = 2
ADVERSARY_COLOR = (0.75, 0.25, 0.25)


def uniform_positions(world: World, env_index, low: float, high: float) -> torch.Tensor:
    """Uniform positions shaped for ``set_pos(..., batch_index=env_index)``."""
    rows = world.batch_dim if env_index is None else 1 if isinstance(env_index, int) else len(env_index)
    pos = torch.empty(rows, world.dim_p, device=world.device).uniform_(low, high)
    return pos[0] if isinstance(env_index, int) else pos


def tint(base: float, channel: torch.Tensor, boost: float) -> torch.Tensor:
    """Grey ``base`` colours with ``boost`` added on ``channel`` (any shape of channels -> [..., 3])."""
    return base + boost * torch.nn.functional.one_hot(channel, 3).float()


class Scenario(BaseScenario):
    supports_batched_reset = True

    def make_world(self, batch_dim: int, device, **kwargs) -> World:
        read_kwargs(kwargs, {})  # no kwargs: any given one warns, naming it
        world = World(batch_dim=batch_dim, device=device)
        world.add_agent(Agent(name="adversary_0", collide=True, adversary=True))
        world.add_agent(Agent(name="agent_0", collide=True, adversary=False))
        for i in range(N_LANDMARKS):
            world.add_landmark(Landmark(name=f"landmark {i}", collide=False))
        channels = torch.arange(1, N_LANDMARKS + 1, device=world.device)
        self._landmark_colors = tint(0.1, channels, 0.8)  # [L, 3]
        for landmark, color in zip(world.landmarks, self._landmark_colors):
            landmark.color = color
        world.agents[0].color = torch.tensor(ADVERSARY_COLOR, device=world.device)
        self._adversary = torch.tensor([a.adversary for a in world.agents], device=world.device)
        self._index = {agent.name: i for i, agent in enumerate(world.agents)}
        self._good_agents = [a for a in world.agents if not a.adversary]
        #: which landmark is the goal, per env [B]
        self.goal_index = torch.zeros(batch_dim, dtype=torch.long, device=world.device)
        self.set_goal(self.goal_index)
        self._rewards = None
        return world

    def set_goal(self, goal_index: torch.Tensor, env_index=None) -> None:
        """Make landmark ``goal_index`` (an int or a tensor) the goal of the envs ``env_index``
        (all when None) and recolour the good agent."""
        goal_index = torch.as_tensor(goal_index).to(self.goal_index)
        if ((goal_index < 0) | (goal_index >= N_LANDMARKS)).any():
            raise ValueError(f"simple_push: goal_index must be in [0, {N_LANDMARKS}), got {goal_index.tolist()}")
        if env_index is None:
            self.goal_index = goal_index.expand_as(self.goal_index).clone()
        else:
            self.goal_index[env_index] = goal_index
        color = self._good_color()
        for agent in self._good_agents:
            agent.color = color

    def _good_color(self) -> torch.Tensor:
        """The good agent's colour, which tells it its goal: [B, 3]."""
        return tint(0.25, self.goal_index + 1, 0.5)

    def reset_world_at(self, env_index=None) -> None:
        world = self.world
        rows = world.batch_dim if env_index is None else 1 if isinstance(env_index, int) else len(env_index)
        goal = torch.randint(0, N_LANDMARKS, (rows,), device=world.device)
        self.set_goal(goal[0] if isinstance(env_index, int) else goal, env_index)
        for entity in world.agents + world.landmarks:
            entity.set_pos(uniform_positions(world, env_index, -1.0, 1.0), batch_index=env_index)

    # ------------------------------------------------------------------ helpers
    def _landmarks(self) -> torch.Tensor:
        return torch.stack([l.state.pos for l in self.world.landmarks], dim=1)  # [B, L, 2]

    def _goal_pos(self, landmarks: torch.Tensor) -> torch.Tensor:
        return landmarks[torch.arange(landmarks.shape[0], device=landmarks.device), self.goal_index]

    # ------------------------------------------------------------------ reward
    def reward(self, agent: Agent) -> torch.Tensor:
        if agent is self.world.agents[0]:
            agents = torch.stack([a.state.pos for a in self.world.agents], dim=1)  # [B, N, 2]
            goal = self._goal_pos(self._landmarks())
            to_goal = torch.linalg.vector_norm(agents - goal.unsqueeze(1), dim=-1)  # [B, N]
            adv = self._adversary
            self._rewards = torch.where(
                adv, to_goal[:, ~adv].amin(dim=1, keepdim=True) - to_goal, -to_goal
            )
        return self._rewards[:, self._index[agent.name]]

    # ------------------------------------------------------------- observation
    def observation(self, agent: Agent) -> torch.Tensor:
        landmarks = self._landmarks()
        own = agent.state.pos
        others = torch.stack([a.state.pos for a in self.world.agents if a is not agent], dim=1)
        landmark_offsets = (landmarks - own.unsqueeze(1)).flatten(1)
        other_offsets = (others - own.unsqueeze(1)).flatten(1)
        if agent.adversary:
            return torch.cat([agent.state.vel, landmark_offsets, other_offsets], dim=-1)
        batch = own.shape[0]
        return torch.cat([
            agent.state.vel,
            self._goal_pos(landmarks) - own,
            self._good_color(),
            landmark_offsets,
            self._landmark_colors.flatten().expand(batch, -1),
            other_offsets,
        ], dim=-1)


class HeuristicPolicy(BaseHeuristicPolicy):
    """Good agent heads for its goal; the adversary guards the landmark it believes is the goal.

    Roles are told apart by observation width (19 for the good agent, 8 for the
    adversary). The good agent uses a damped proportional controller on its
    goal offset. The adversary takes the landmark nearest the good agent as the
    goal (the good agent converges on its goal, so the guess firms up) and
    holds a point ``block`` from that landmark on the side facing the good
    agent, where it sits in the good agent's way.
    """

    gain = 3.0
    damping = 1.0
    block = 0.1
    GOOD_WIDTH = 2 + 2 + 3 + 5 * N_LANDMARKS + 2
    ADVERSARY_WIDTH = 2 + 2 * N_LANDMARKS + 2

    def compute_action(self, observation: torch.Tensor, u_range: float) -> torch.Tensor:
        width = observation.shape[1]
        vel = observation[:, 0:2]
        if width == self.GOOD_WIDTH:
            target = observation[:, 2:4]
        elif width == self.ADVERSARY_WIDTH:
            landmarks = observation[:, 2:2 + 2 * N_LANDMARKS].view(-1, N_LANDMARKS, 2)
            good = observation[:, -2:]
            guess = torch.linalg.vector_norm(landmarks - good.unsqueeze(1), dim=-1).argmin(dim=1)
            goal = landmarks[torch.arange(observation.shape[0], device=observation.device), guess]
            side = good - goal
            target = goal + self.block * side / torch.linalg.vector_norm(side, dim=-1, keepdim=True).clamp_min(1e-6)
        else:
            raise ValueError(f"simple_push heuristic: observation width {width} is neither 19 nor 8")
        return (self.gain * target - self.damping * vel).clamp(-u_range, u_range)
