"""goal: one velocity-commanded robot drives to a goal in a 6 x 3 lab.

Description
    A single disc robot (radius 0.16, ``agent 0``) must reach a small goal
    (a non-colliding disc of radius 0.06, ``goal``). Its action is a desired
    velocity: it passes a :class:`CommandFilter` (delay of ``dt_delay`` steps,
    clip to the disc of radius ``u_range``, zero below ``min_input_norm``) and
    a PID velocity controller (standard form, gains (2, 6, 0.002)) turns it
    into a force limited to ``a_range + linear_friction``. The agent has
    ``linear_friction``; the world has no drag; dt 0.05 with 5 substeps.
Observation (per agent, in this order)
    own position (2), own velocity (2), own position minus the goal's (2);
    with ``obs_noise > 0`` every entry gets uniform noise in [-obs_noise, obs_noise].
Reward
    While the agent is off the goal (centre distance >= 0.06):
    ``pos_shaping_factor`` x the decrease of its distance to the goal since the
    last step, plus ``time_rew_coeff``; on the goal both are 0. Always:
    ``-energy_rew_coeff`` x ``|f| / (sqrt(2) * f_range)``, ``f`` the force the
    controller asked for. ``info`` reports ``pos_rew``, ``energy_rew`` and
    ``time_rew``.
Starting state
    Agent and goal each uniform in [-3, 3] x [-1.5, 1.5], the agent at rest,
    controller memory cleared.
Episode termination
    Never (set ``max_steps``).
Kwargs
    ``u_range`` (1), ``a_range`` (1), ``obs_noise`` (0), ``dt_delay`` (0),
    ``min_input_norm`` (0.08), ``linear_friction`` (0.1), ``pos_shaping_factor``
    (1.0), ``time_rew_coeff`` (-0.01), ``energy_rew_coeff`` (0). Unlike VMAS
    1.5 the delay line of a reset env is emptied (VMAS keeps one line for the
    whole run).
"""
from __future__ import annotations

import math

import torch
from torch import Tensor

from vmas_ros.scenarios.common import (
    check_int, check_number, configure, continuous_heuristic_kwargs, for_index, selected_rows,
)
from vmas_ros.scenarios.debug.trajectory import CommandFilter, noisy_concat
from vmas_ros.simulator.controllers.velocity_controller import VelocityController
from vmas_ros.simulator.core import Agent, Landmark, Sphere, World
from vmas_ros.simulator.heuristic_policy import BaseHeuristicPolicy
from vmas_ros.simulator.scenario import BaseScenario
from vmas_ros.simulator.utils import Color, TorchUtils

NAME = "goal"
#: name -> default of every kwarg (the heuristic takes them too)
DEFAULTS = {
    "u_range": 1.0, "a_range": 1.0, "obs_noise": 0.0, "dt_delay": 0, "min_input_norm": 0.08,
    "linear_friction": 0.1, "pos_shaping_factor": 1.0, "time_rew_coeff": -0.01, "energy_rew_coeff": 0.0,
}
AGENT_RADIUS = 0.16
GOAL_RADIUS = 0.06
LAB_LENGTH, LAB_WIDTH = 6.0, 3.0  # spawn area: x in [-3, 3], y in [-1.5, 1.5]
PID_PARAMS = (2.0, 6.0, 0.002)  # standard form: gain, integral time, derivative time


def validate(config: dict) -> None:
    """Raise ValueError for a kwarg value the task cannot be built with."""
    for name in ("u_range", "a_range"):
        check_number(NAME, name, config[name], strict=True)
    for name in ("obs_noise", "min_input_norm", "linear_friction", "pos_shaping_factor", "energy_rew_coeff"):
        check_number(NAME, name, config[name])
    check_number(NAME, "time_rew_coeff", config["time_rew_coeff"], minimum=-math.inf)
    check_int(NAME, "dt_delay", config["dt_delay"], 0, "steps")


def lab_points(world, env_index) -> Tensor:
    """Uniform points in the lab for the selected envs, shaped for a setter."""
    rows = selected_rows(world.batch_dim, env_index)
    x = torch.empty(rows, 1, device=world.device).uniform_(-LAB_LENGTH / 2, LAB_LENGTH / 2)
    y = torch.empty(rows, 1, device=world.device).uniform_(-LAB_WIDTH / 2, LAB_WIDTH / 2)
    return for_index(torch.cat([x, y], dim=1), env_index)


class Scenario(BaseScenario):
    supports_batched_reset = True

    def make_world(self, batch_dim: int, device, **kwargs) -> World:
        configure(self, kwargs, DEFAULTS, validate)
        self.viewer_size = (1600, 700)
        self.viewer_zoom = 2
        self.plot_grid = True
        self.f_range = self.a_range + self.linear_friction
        world = World(batch_dim, device, drag=0.0, dt=0.05, substeps=5)
        self.goal = Landmark("goal", collide=False, movable=False, shape=Sphere(radius=GOAL_RADIUS))
        world.add_landmark(self.goal)
        self.agent = Agent(
            name="agent 0", collide=True, color=Color.GREEN, render_action=True,
            linear_friction=self.linear_friction, shape=Sphere(radius=AGENT_RADIUS),
            f_range=self.f_range, u_range=self.u_range,
        )
        self.agent.controller = VelocityController(self.agent, world, PID_PARAMS, "standard")
        world.add_agent(self.agent)
        self.commands = CommandFilter(batch_dim, world.dim_p, self.dt_delay, self.u_range, self.min_input_norm, device)
        zeros = torch.zeros(batch_dim, device=device)
        #: per env, [B]: pos_shaping_factor x the agent's distance to the goal as of the last reward
        self.shaping = zeros.clone()
        self.goal_reached = torch.zeros(batch_dim, dtype=torch.bool, device=device)
        self.pos_rew, self.time_rew, self.energy_rew = zeros.clone(), zeros.clone(), zeros.clone()
        return world

    def _distance(self) -> Tensor:
        return torch.linalg.vector_norm(self.goal.state.pos - self.agent.state.pos, dim=-1)

    def reset_world_at(self, env_index=None) -> None:
        self.agent.controller.reset(env_index)
        self.commands.reset(env_index)
        self.agent.set_pos(lab_points(self.world, env_index), batch_index=env_index)
        self.goal.set_pos(lab_points(self.world, env_index), batch_index=env_index)
        shaping = self._distance() * self.pos_shaping_factor
        if env_index is None:
            self.shaping = shaping
        else:
            self.shaping[env_index] = shaping[env_index]

    def process_action(self, agent: Agent) -> None:
        agent.action.u = self.commands(agent.action.u)
        agent.vel_action = agent.action.u.clone()
        agent.controller.process_force()

    def reward(self, agent: Agent) -> Tensor:
        distance = self._distance()
        self.goal_reached = distance < GOAL_RADIUS
        shaping = distance * self.pos_shaping_factor
        self.pos_rew = torch.where(self.goal_reached, 0.0, self.shaping - shaping)
        self.shaping = shaping
        self.time_rew = torch.where(self.goal_reached, 0.0, torch.full_like(distance, self.time_rew_coeff))
        effort = torch.linalg.vector_norm(agent.action.u, dim=-1) / math.sqrt(self.world.dim_p * self.f_range**2)
        self.energy_rew = -effort * self.energy_rew_coeff
        return self.pos_rew + self.energy_rew + self.time_rew

    def observation(self, agent: Agent) -> Tensor:
        pos = agent.state.pos
        return noisy_concat([pos, agent.state.vel, pos - self.goal.state.pos], self.obs_noise)

    def info(self, agent: Agent) -> dict:
        return {"pos_rew": self.pos_rew, "energy_rew": self.energy_rew, "time_rew": self.time_rew}


class HeuristicPolicy(BaseHeuristicPolicy):
    """Command a velocity straight at the goal, slowing down inside ``brake_distance``.

    The command is ``u_range`` towards the goal, scaled by
    ``distance / brake_distance`` when closer, so the PID controller brings
    the robot to rest on the goal, but never below ``min_input_norm`` (which
    the scenario's dead band would drop); inside ``GOAL_RADIUS / 2`` it
    commands nothing.
    """

    brake_distance = 0.5

    def __init__(self, continuous_action: bool = True, **scenario_kwargs) -> None:
        super().__init__(continuous_action)
        config = continuous_heuristic_kwargs(NAME, DEFAULTS, scenario_kwargs, continuous_action)
        validate(config)
        #: the slowest command that passes the scenario's dead band
        self.min_speed = config["min_input_norm"] * 1.05

    def compute_action(self, observation: Tensor, u_range: float) -> Tensor:
        if observation.shape[1] != 6:
            raise ValueError(f"goal heuristic: expected observation width 6, got {observation.shape[1]}")
        to_goal = -observation[:, 4:6]
        distance = torch.linalg.vector_norm(to_goal, dim=-1, keepdim=True)
        speed = (u_range * (distance / self.brake_distance).clamp(max=1.0)).clamp(min=self.min_speed)
        command = torch.nan_to_num(to_goal / distance) * speed
        command = torch.where(distance < GOAL_RADIUS / 2, 0.0, command)
        return TorchUtils.clamp_with_norm(command, u_range)
