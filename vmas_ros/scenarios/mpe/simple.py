"""simple (MPE "simple"): one agent, one landmark; a sanity-check task.

Description
    A single point agent (no collisions) must reach a single landmark. There is
    nothing multi-agent about it; it exists to debug learners and the engine.
Observation (per agent, in this order)
    own velocity (2), the landmark's position relative to the agent (2).
Reward
    Minus the squared distance between the agent and the landmark.
Starting state
    Agent and landmark uniform in [-1, 1]^2, at rest.
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
from vmas_ros.simulator.utils import Color


def uniform_positions(world: World, env_index, low: float, high: float) -> torch.Tensor:
    """Uniform positions shaped for ``set_pos(..., batch_index=env_index)``."""
    if env_index is None:
        rows = world.batch_dim
    elif isinstance(env_index, int):
        rows = 1
    else:
        rows = len(env_index)
    pos = torch.empty(rows, world.dim_p, device=world.device).uniform_(low, high)
    return pos[0] if isinstance(env_index, int) else pos


class Scenario(BaseScenario):
    supports_batched_reset = True

    def make_world(self, batch_dim: int, device, **kwargs) -> World:
        read_kwargs(kwargs, {})  # no kwargs: any given one warns, naming it
        world = World(batch_dim=batch_dim, device=device)
        world.add_agent(Agent(name="agent_0", collide=False, color=Color.GRAY))
        world.add_landmark(Landmark(name="landmark 0", collide=False, color=Color.RED))
        return world

    def reset_world_at(self, env_index=None) -> None:
        for entity in self.world.agents + self.world.landmarks:
            entity.set_pos(uniform_positions(self.world, env_index, -1.0, 1.0), batch_index=env_index)

    def reward(self, agent: Agent) -> torch.Tensor:
        offset = self.world.landmarks[0].state.pos - agent.state.pos
        return -offset.square().sum(dim=-1)

    def observation(self, agent: Agent) -> torch.Tensor:
        landmarks = torch.stack([l.state.pos for l in self.world.landmarks], dim=1)  # [B, L, 2]
        return torch.cat([agent.state.vel, (landmarks - agent.state.pos.unsqueeze(1)).flatten(1)], dim=-1)


class HeuristicPolicy(BaseHeuristicPolicy):
    """Drive to the landmark with a damped proportional controller.

    ``gain * offset - damping * velocity``; with the world's drag of 0.25 per
    step this settles on the landmark in a few seconds without overshooting much.
    """

    gain = 3.0
    damping = 1.0

    def compute_action(self, observation: torch.Tensor, u_range: float) -> torch.Tensor:
        vel, offset = observation[:, 0:2], observation[:, 2:4]
        return (self.gain * offset - self.damping * vel).clamp(-u_range, u_range)
