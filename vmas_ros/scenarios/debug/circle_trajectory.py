"""circle_trajectory: one velocity-commanded robot circles the origin at radius 1.5.

Description
    A single disc robot (radius 0.16, ``agent_0``) must drive round a circle of
    radius 1.5 centred on the origin, counter-clockwise. Its action is a
    desired velocity: it passes a :class:`CommandFilter` (delay of
    ``dt_delay`` steps, clip to the disc of radius ``u_range``, zero below
    ``min_input_norm``) and a PID velocity controller (standard form, gains
    (2, 6, 0.002)) turns it into a force limited to ``a_range +
    linear_friction``. The world has no drag but ``linear_friction``; dt 0.05.
Observation (per agent, in this order)
    own position (2), own velocity (2), own position again (2): 6 values, each
    with uniform noise in [-obs_noise, obs_noise].
Reward
    ``-sqrt(d) + 0.5 * t . v``: ``d`` is the distance to the circle, ``t`` the
    unit counter-clockwise tangent (zero exactly on the circle) and ``v`` the
    agent's velocity. At the exact centre both terms are 0, as in VMAS 1.5
    (the centre has no closest point; it is taken as its own). ``info`` reports ``pos_rew`` (the
    first term) and ``dot_product`` (the second).
Starting state
    Position uniform in [-1.5, 1.5]^2, at rest, controller memory cleared.
Episode termination
    Never (set ``max_steps``).
Kwargs
    ``u_range`` (1), ``a_range`` (1), ``obs_noise`` (0), ``dt_delay`` (0),
    ``min_input_norm`` (0.08), ``linear_friction`` (0.1). Unlike VMAS 1.5,
    the delay line of a reset env is emptied (VMAS keeps one line for the
    whole run), and no noise is drawn when ``obs_noise`` is 0.
"""
from __future__ import annotations

from typing import Tuple

import torch
from torch import Tensor

from vmas_ros.scenarios.common import check_int, check_number, configure, heuristic_kwargs, uniform_rows
from vmas_ros.scenarios.debug.trajectory import (
    CommandFilter, PathFollower, noisy_concat, tracking_reward,
)
from vmas_ros.simulator.controllers.velocity_controller import VelocityController
from vmas_ros.simulator.core import Agent, Sphere, World
from vmas_ros.simulator.scenario import BaseScenario
from vmas_ros.simulator.utils import Color

NAME = "circle_trajectory"
#: name -> default of every kwarg (the heuristic takes them too)
DEFAULTS = {
    "u_range": 1.0, "a_range": 1.0, "obs_noise": 0.0, "dt_delay": 0, "min_input_norm": 0.08,
    "linear_friction": 0.1,
}
AGENT_RADIUS = 0.16
CIRCLE_RADIUS = 1.5
PID_PARAMS = (2.0, 6.0, 0.002)  # standard form: gain, integral time, derivative time


def validate(config: dict) -> None:
    """Raise ValueError for a kwarg value the task cannot be built with."""
    for name in ("u_range", "a_range"):
        check_number(NAME, name, config[name], strict=True)
    for name in ("obs_noise", "min_input_norm", "linear_friction"):
        check_number(NAME, name, config[name])
    check_int(NAME, "dt_delay", config["dt_delay"], 0, "steps")


def closest_on_circle(pos: Tensor) -> Tensor:
    """The circle's point nearest to each position [B, 2] (the origin maps to the origin)."""
    norm = torch.linalg.vector_norm(pos, dim=-1, keepdim=True)
    return torch.nan_to_num(pos / norm * CIRCLE_RADIUS)


def ccw_tangent(pos: Tensor, closest: Tensor) -> Tensor:
    """Unit counter-clockwise tangent [B, 2] at the radial through ``pos``; zero on the circle and at the centre."""
    norm = torch.linalg.vector_norm(pos, dim=-1, keepdim=True)
    perpendicular = torch.cat([-pos[:, 1:2], pos[:, 0:1]], dim=-1)
    on_path = (pos == closest).all(dim=-1, keepdim=True)
    return torch.where(on_path, 0.0, torch.nan_to_num(perpendicular / norm))


class Scenario(BaseScenario):
    supports_batched_reset = True
    fresh_observations = True

    def make_world(self, batch_dim: int, device, **kwargs) -> World:
        configure(self, kwargs, DEFAULTS, validate)
        self.viewer_zoom = 2
        world = World(batch_dim, device, dt=0.05, drag=0.0, linear_friction=self.linear_friction)
        self.agent = Agent(
            name="agent_0", shape=Sphere(AGENT_RADIUS), f_range=self.a_range + self.linear_friction,
            u_range=self.u_range, render_action=True,
        )
        self.agent.controller = VelocityController(self.agent, world, PID_PARAMS, "standard")
        world.add_agent(self.agent)
        self.commands = CommandFilter(batch_dim, world.dim_p, self.dt_delay, self.u_range, self.min_input_norm, device)
        self.pos_rew = torch.zeros(batch_dim, device=device)
        self.dot_product = torch.zeros(batch_dim, device=device)
        return world

    def reset_world_at(self, env_index=None) -> None:
        self.agent.controller.reset(env_index)
        self.commands.reset(env_index)
        self.agent.set_pos(uniform_rows(self.world, env_index, 2, -CIRCLE_RADIUS, CIRCLE_RADIUS), batch_index=env_index)

    def process_action(self, agent: Agent) -> None:
        agent.action.u = self.commands(agent.action.u)
        agent.vel_action = agent.action.u.clone()
        agent.controller.process_force()

    def reward(self, agent: Agent) -> Tensor:
        pos = agent.state.pos
        closest = closest_on_circle(pos)
        distance = torch.linalg.vector_norm(pos - closest, dim=-1)
        self.pos_rew, self.dot_product = tracking_reward(distance, ccw_tangent(pos, closest), agent.state.vel)
        return self.pos_rew + self.dot_product

    def observation(self, agent: Agent) -> Tensor:
        pos = agent.state.pos
        return noisy_concat([pos, agent.state.vel, pos], self.obs_noise)

    def info(self, agent: Agent) -> dict:
        return {"pos_rew": self.pos_rew, "dot_product": self.dot_product}

    def extra_render(self, env_index: int = 0) -> list:
        from vmas_ros.simulator import rendering

        circle = rendering.make_circle(CIRCLE_RADIUS, filled=False)
        circle.set_color(*Color.BLACK.value)
        return [circle]


class HeuristicPolicy(PathFollower):
    """Drive counter-clockwise round the circle at full speed, pulled back onto it when off.

    Reads the (possibly noisy) position; see :class:`PathFollower`. At the
    centre, where the tangent is undefined, it first drives out along +x.
    """

    def __init__(self, continuous_action: bool = True, **scenario_kwargs) -> None:
        config = heuristic_kwargs(NAME, DEFAULTS, scenario_kwargs)
        validate(config)
        super().__init__(continuous_action, speed=config["u_range"])

    def closest_and_tangent(self, pos: Tensor) -> Tuple[Tensor, Tensor]:
        at_centre = torch.linalg.vector_norm(pos, dim=-1, keepdim=True) < 1e-6
        pos = torch.where(at_centre, pos.new_tensor([1e-3, 0.0]), pos)
        closest = closest_on_circle(pos)
        norm = torch.linalg.vector_norm(pos, dim=-1, keepdim=True)
        return closest, torch.cat([-pos[:, 1:2], pos[:, 0:1]], dim=-1) / norm

