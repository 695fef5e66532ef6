"""simple_speaker_listener (MPE "cooperative communication").

Description
    Two agents and three coloured landmarks (red, green, blue). The speaker
    cannot move but knows which landmark is the goal; the listener moves but
    cannot speak. The speaker must tell the listener, over a ``dim_c = 3``
    channel, where to go.
Observation (per agent, in this order)
    speaker: the goal landmark's colour (3).
    listener: own velocity (2), each landmark's position relative to the
    listener (2 x 3), the speaker's last message (3).
Actions
    speaker: a physical action (2, ignored: it is not movable) followed by a
    message (3, each in [0, 1]; one-hot with discrete actions).
    listener: a physical action (2).
Reward (shared by both agents, as in VMAS 1.5)
    ``-2 * |x_listener - x_goal|``: the listener's distance to the goal, once
    per agent. MPE gives each agent ``-|x_listener - x_goal|^2`` instead.
Starting state
    Agents and landmarks uniform in [-1, 1]^2; the goal is drawn per env.
    (VMAS 1.5 draws one goal for the whole batch and keeps it when single envs
    are reset; here every reset env draws its own.)
Episode termination
    Never (set ``max_steps``).
Kwargs
    None.
"""
from __future__ import annotations

import torch

from vmas_ros.scenarios.common import read_kwargs
from vmas_ros.simulator.core import Agent, Landmark, Sphere, World
from vmas_ros.simulator.heuristic_policy import BaseHeuristicPolicy
from vmas_ros.simulator.scenario import BaseScenario

DIM_C = 3
AGENT_RADIUS = 0.075
LANDMARK_RADIUS = 0.04
AGENT_COLOR = (0.25, 0.25, 0.25)
#: landmark i has colour LANDMARK_COLORS[i]; its largest channel is channel i
LANDMARK_COLORS = ((0.65, 0.15, 0.15), (0.15, 0.65, 0.15), (0.15, 0.15, 0.65))
GOAL_HIGHLIGHT = 0.45  # the listener is drawn in its goal's colour, lightened


def _rows(world: World, env_index) -> int:
    """How many envs ``env_index`` (None, an int or a 1-D index tensor) selects."""
    if env_index is None:
        return world.batch_dim
    return 1 if isinstance(env_index, int) else len(env_index)


def _fit(values: torch.Tensor, env_index) -> torch.Tensor:
    """``values`` drawn for the selected rows, shaped for ``set_pos(..., env_index)``."""
    return values.squeeze(0) if isinstance(env_index, int) else values


class Scenario(BaseScenario):
    supports_batched_reset = True

    def make_world(self, batch_dim: int, device, **kwargs) -> World:
        read_kwargs(kwargs, {})  # no kwargs: any given one warns, naming it
        world = World(batch_dim=batch_dim, device=device, dim_c=DIM_C)
        self.speaker = Agent(
            name="speaker_0", collide=False, movable=False, silent=False,
            shape=Sphere(radius=AGENT_RADIUS), color=AGENT_COLOR,
        )
        self.listener = Agent(
            name="listener_0", collide=False, movable=True, silent=True,
            shape=Sphere(radius=AGENT_RADIUS), color=AGENT_COLOR,
        )
        world.add_agent(self.speaker)
        world.add_agent(self.listener)
        for i, color in enumerate(LANDMARK_COLORS):
            world.add_landmark(Landmark(name=f"landmark {i}", collide=False, shape=Sphere(radius=LANDMARK_RADIUS), color=color))
        self.palette = torch.tensor(LANDMARK_COLORS, device=device)  # [L, 3]
        #: index of each env's goal landmark, [batch] long
        self.goal = torch.zeros(batch_dim, dtype=torch.long, device=device)
        self._reward_cache = None
        return world

    def reset_world_at(self, env_index=None) -> None:
        world = self.world
        rows = _rows(world, env_index)
        goal = torch.randint(len(world.landmarks), (rows,), device=world.device)
        if env_index is None:
            self.goal = goal
        else:
            self.goal[env_index] = _fit(goal, env_index)
        for entity in world.agents + world.landmarks:
            pos = torch.empty(rows, world.dim_p, device=world.device).uniform_(-1.0, 1.0)
            entity.set_pos(_fit(pos, env_index), batch_index=env_index)
        self.listener.color = (self.goal_color() + GOAL_HIGHLIGHT).clamp(max=1.0)

    def goal_color(self) -> torch.Tensor:
        """Colour of each env's goal landmark, [batch, 3]."""
        return self.palette[self.goal]

    def _goal_distance(self) -> torch.Tensor:
        landmarks = torch.stack([l.state.pos for l in self.world.landmarks], dim=1)  # [B, L, 2]
        goal_pos = landmarks.gather(1, self.goal.view(-1, 1, 1).expand(-1, 1, 2)).squeeze(1)
        return torch.linalg.vector_norm(self.listener.state.pos - goal_pos, dim=-1)

    def reward(self, agent: Agent) -> torch.Tensor:
        if agent is self.world.agents[0]:
            self._reward_cache = -len(self.world.agents) * self._goal_distance()
        return self._reward_cache

    def observation(self, agent: Agent) -> torch.Tensor:
        if agent is self.speaker:
            return self.goal_color()
        landmarks = torch.stack([l.state.pos for l in self.world.landmarks], dim=1)
        relative = (landmarks - agent.state.pos.unsqueeze(1)).flatten(1)
        return torch.cat([agent.state.vel, relative, self.speaker.state.c], dim=-1)

    def info(self, agent: Agent) -> dict:
        return {"goal_distance": self._goal_distance()}


class HeuristicPolicy(BaseHeuristicPolicy):
    """The speaker names the goal; the listener goes where it is told.

    The speaker (3-wide observation) says the index of the goal colour's
    largest channel as a one-hot message. The listener decodes the last
    message it heard (argmax of its last 3 observation entries) and steers to
    that landmark with a damped proportional controller; before the first
    message arrives (all zeros) it only brakes. Continuous actions only.
    """

    gain = 4.0
    damping = 2.0

    def __init__(self, continuous_action: bool = True) -> None:
        super().__init__(continuous_action)
        if not continuous_action:
            raise ValueError("simple_speaker_listener's heuristic supports continuous actions only")

    def compute_action(self, observation: torch.Tensor, u_range: float) -> torch.Tensor:
        batch, width = observation.shape
        if width == DIM_C:  # speaker: no physical action, then the message
            word = torch.nn.functional.one_hot(observation.argmax(dim=-1), DIM_C).to(observation.dtype)
            return torch.cat([observation.new_zeros(batch, 2), word], dim=-1)
        vel = observation[:, :2]
        landmarks = observation[:, 2:width - DIM_C].view(batch, -1, 2)
        message = observation[:, width - DIM_C:]
        heard = message.abs().sum(dim=-1, keepdim=True) > 0
        target = landmarks[torch.arange(batch, device=observation.device), message.argmax(dim=-1)]
        action = torch.where(heard, self.gain * target, 0.0) - self.damping * vel
        return action.clamp(-u_range, u_range)
