"""line_trajectory: one velocity-commanded robot drives up the line x = 0.

Description
    A single small disc robot (radius 0.03, mass 2, ``agent_0``) must drive
    along the y axis in the +y direction and hold steady commands while doing
    so. Its action is a desired velocity, turned into a force (limited to 0.5)
    by a PID velocity controller (standard form, gains (4, 1.25, 0.001)); the
    command is used as given (no clip to a disc, no dead band). World: drag
    0.1, dt 0.1.
Observation (per agent, in this order)
    own position (2), own velocity (2), own position again (2): 6 values, each
    with uniform noise in [-obs_noise, obs_noise].
Reward
    ``-sqrt(|x|) + 0.5 * v_y + 0.2 * cos(v, c)``: the distance to the line,
    progress along it, and the cosine between the velocity ``v`` and the
    commanded velocity ``c`` of the step (a term is 0 where either is zero).
    ``info`` reports ``pos_rew``, ``dot_product`` and ``steady_rew`` (the
    three terms).
Starting state
    x uniform in [-1, 1], y uniform in [-1, 0], at rest, controller memory cleared.
Episode termination
    Once the agent is past y = 2 (the line runs from y = -1 to y = 2).
Kwargs
    ``obs_noise`` (0). No noise is drawn when it is 0 (VMAS 1.5 always draws).
"""
from __future__ import annotations

from typing import Tuple

import torch
from torch import Tensor

from vmas_ros.scenarios.common import check_number, configure, for_index, heuristic_kwargs, selected_rows
from vmas_ros.scenarios.debug.trajectory import PathFollower, noisy_concat, tracking_reward
from vmas_ros.simulator.controllers.velocity_controller import VelocityController
from vmas_ros.simulator.core import Agent, Sphere, World
from vmas_ros.simulator.scenario import BaseScenario
from vmas_ros.simulator.utils import Color

NAME = "line_trajectory"
DEFAULTS = {"obs_noise": 0.0}
AGENT_RADIUS = 0.03
LINE_START, LINE_END = -1.0, 2.0  # the line's ends on the y axis
PID_PARAMS = (4.0, 1.25, 0.001)  # standard form: gain, integral time, derivative time
STEADY_WEIGHT = 0.2


def validate(config: dict) -> None:
    check_number(NAME, "obs_noise", config["obs_noise"])


def unit_or_zero(vector: Tensor) -> Tensor:
    """``vector`` [B, 2] scaled to unit length; zero vectors stay zero."""
    return torch.nan_to_num(vector / torch.linalg.vector_norm(vector, dim=-1, keepdim=True))


class Scenario(BaseScenario):
    supports_batched_reset = True
    fresh_observations = True

    def make_world(self, batch_dim: int, device, **kwargs) -> World:
        configure(self, kwargs, DEFAULTS, validate)
        world = World(batch_dim, device, drag=0.1)
        self.agent = Agent(
            name="agent_0", shape=Sphere(AGENT_RADIUS), mass=2, f_range=0.5, u_range=1, render_action=True,
        )
        self.agent.controller = VelocityController(self.agent, world, PID_PARAMS, "standard")
        world.add_agent(self.agent)
        #: the direction of travel, the same everywhere on the line: [B, 2]
        self.tangent = torch.zeros(batch_dim, world.dim_p, device=device)
        self.tangent[:, 1] = 1.0
        #: the velocity commanded in the last step, [B, 2]
        self.vel_action = torch.zeros(batch_dim, world.dim_p, device=device)
        zeros = torch.zeros(batch_dim, device=device)
        self.pos_rew, self.dot_product, self.steady_rew = zeros, zeros.clone(), zeros.clone()
        return world

    def reset_world_at(self, env_index=None) -> None:
        self.agent.controller.reset(env_index)
        rows = selected_rows(self.world.batch_dim, env_index)
        x = torch.empty(rows, 1, device=self.world.device).uniform_(-1.0, 1.0)
        y = torch.empty(rows, 1, device=self.world.device).uniform_(LINE_START, 0.0)
        self.agent.set_pos(for_index(torch.cat([x, y], dim=1), env_index), batch_index=env_index)

    def process_action(self, agent: Agent) -> None:
        self.vel_action = agent.action.u.clone()
        agent.controller.process_force()

    def reward(self, agent: Agent) -> Tensor:
        pos, vel = agent.state.pos, agent.state.vel
        self.pos_rew, self.dot_product = tracking_reward(pos[:, 0].abs(), self.tangent, vel)
        self.steady_rew = (unit_or_zero(vel) * unit_or_zero(self.vel_action)).sum(-1) * STEADY_WEIGHT
        return self.pos_rew + self.dot_product + self.steady_rew

    def observation(self, agent: Agent) -> Tensor:
        pos = agent.state.pos
        return noisy_concat([pos, agent.state.vel, pos], self.obs_noise)

    def done(self) -> Tensor:
        return self.agent.state.pos[:, 1] > LINE_END

    def info(self, agent: Agent) -> dict:
        return {"pos_rew": self.pos_rew, "dot_product": self.dot_product, "steady_rew": self.steady_rew}

    def extra_render(self, env_index: int = 0) -> list:
        from vmas_ros.simulator import rendering

        line = rendering.Line((0.0, LINE_START), (0.0, LINE_END), width=1)
        line.set_color(*Color.BLACK.value)
        return [line]


class HeuristicPolicy(PathFollower):
    """Drive up the y axis at full speed, pulled back onto it when off (see :class:`PathFollower`)."""

    def __init__(self, continuous_action: bool = True, **scenario_kwargs) -> None:
        validate(heuristic_kwargs(NAME, DEFAULTS, scenario_kwargs))
        super().__init__(continuous_action, speed=1.0)

    def closest_and_tangent(self, pos: Tensor) -> Tuple[Tensor, Tensor]:
        closest = torch.stack([torch.zeros_like(pos[:, 0]), pos[:, 1]], dim=-1)
        tangent = torch.zeros_like(pos)
        tangent[:, 1] = 1.0
        return closest, tangent
