"""wind_flocking: two robots fly up against a head wind, the big one sheltering the small one.

Description
    A big disc (``agent_0``, radius 0.05) and a small one (``agent_1``, radius
    0.03) start 1 m apart, side by side, and must travel upwards at
    ``desired_vel`` while a wind pushes every agent down with force
    ``wind`` (a per-agent gravity ``(0, -wind)``). The small agent always
    feels the full wind; the big agent feels less of it the more it lies below
    the small one (it flies in the small one's lee): with ``a`` the heading
    from the small agent to the big one, its wind is scaled by
    ``(min(sin(a) + 1, tol) - 1 + tol) / tol`` for ``tol =
    cover_angle_tolerance``, i.e. 1 while it is level or above and 0 straight
    below (tol = 1). The scale is recomputed after every step, with the
    rewards, and acts from the next step on. By default actions are desired
    velocities tracked by a PID ``VelocityController`` (gain 1.5, integral
    time 0.6, derivative time 0.002); the world has no drag and linear
    friction 0.1.
Observation (per agent, in this order)
    with ``observe_pos`` own position (2), own velocity (2), with
    ``observe_rel_pos`` the other agent's position minus its own (2), with
    ``observe_rel_vel`` the other's velocity minus its own (2).
Reward
    Shared, the sum of shaping terms (each the decrease since the last step of
    a distance, times its factor): the agents' separation from 1 m
    (``dist_shaping_factor``); the angle between the line through them and the
    horizontal, in [0, pi/2] (``rot_shaping_factor``); the higher agent's
    height from 10 m (``pos_shaping_factor``); then means over the two agents
    of: the velocity error ``|v - (0, desired_vel)|`` (``vel_shaping_factor``),
    the norm of the action force (``energy_shaping_factor``, 0 during the
    first 9 steps) and the wind force on the agent (``wind_shaping_factor``,
    0 during the first 4 steps). ``info`` reports ``dist_rew``, ``rot_rew``,
    ``pos_rew``, and per agent ``agent_wind_rew``, ``agent_vel_rew``,
    ``agent_energy_rew`` and ``delta_vel_to_goal`` (its velocity error).
Starting state
    At rest, 1 m apart about the origin along a heading uniform in
    [-pi/8, pi/8]; which agent is on which end is random, drawn per env (VMAS
    1.5 draws it once for the whole batch). Both feel the full wind.
Episode termination
    Never (set ``max_steps``; VMAS's ``horizon`` only draws a marker).
Kwargs
    ``vel_shaping_factor`` (1), ``dist_shaping_factor`` (1),
    ``wind_shaping_factor`` (1), ``pos_shaping_factor`` (0),
    ``rot_shaping_factor`` (0), ``energy_shaping_factor`` (0),
    ``observe_rel_pos`` (False), ``observe_rel_vel`` (False), ``observe_pos``
    (True), ``use_controller`` (True), ``wind`` (2), ``v_range`` (0.5),
    ``desired_vel`` (``v_range``), ``f_range`` (100),
    ``cover_angle_tolerance`` (1), ``horizon`` (200).
Deviations from VMAS 1.5
    A reset env starts with the full wind on the big agent, its wind shaping
    taken from that; VMAS keeps the big agent's wind (and bases the shaping
    on it) from the last step of the previous episode. The two agree on a
    fresh env.
"""
from __future__ import annotations

import math
from numbers import Real

import torch
from torch import Tensor

from vmas_ros.scenarios.common import continuous_heuristic_kwargs, for_index, read_kwargs, selected_rows
from vmas_ros.simulator.controllers.velocity_controller import VelocityController
from vmas_ros.scenarios.line_angles import (  # noqa: F401  VMAS's names for its users
    angle_to_vector, get_line_angle_0_90, get_line_angle_0_180, get_line_angle_dist_0_180, get_line_angle_dist_0_360,
)
from vmas_ros.simulator.core import Agent, Sphere, World
from vmas_ros.simulator.heuristic_policy import BaseHeuristicPolicy
from vmas_ros.simulator.scenario import BaseScenario
from vmas_ros.simulator.utils import X, Y

#: name -> default of every kwarg; ``desired_vel`` None means ``v_range``
DEFAULTS = {
    "vel_shaping_factor": 1, "dist_shaping_factor": 1, "wind_shaping_factor": 1, "pos_shaping_factor": 0,
    "rot_shaping_factor": 0, "energy_shaping_factor": 0, "observe_rel_pos": False, "observe_rel_vel": False,
    "observe_pos": True, "use_controller": True, "wind": 2, "v_range": 0.5, "desired_vel": None, "f_range": 100,
    "cover_angle_tolerance": 1, "horizon": 200,
}
BIG_RADIUS, SMALL_RADIUS = 0.05, 0.03
DESIRED_DISTANCE = 1.0
DESIRED_HEIGHT = 10.0  # target of the (off by default) height shaping
START_SPREAD = math.pi / 8  # start heading uniform in [-START_SPREAD, START_SPREAD]
PID_PARAMS = (1.5, 0.6, 0.002)  # standard form: gain, integral time, derivative time
LINEAR_FRICTION = 0.1
ENERGY_GRACE, WIND_GRACE = 10, 5  # those terms pay nothing while the step count is below these


def _is_number(value) -> bool:
    return isinstance(value, Real) and not isinstance(value, bool) and math.isfinite(value)


def validate(config: dict) -> dict:
    """Raise ValueError for a kwarg value the task cannot be built with; return the config, ``desired_vel`` set."""
    config = dict(config)
    if config["desired_vel"] is None:
        config["desired_vel"] = config["v_range"]
    for name in ("v_range", "f_range", "cover_angle_tolerance"):
        if not (_is_number(config[name]) and config[name] > 0):
            raise ValueError(f"wind_flocking: {name} must be a number > 0, got {config[name]!r}")
    numbers = [name for name in DEFAULTS if name.endswith("_factor")] + ["wind", "desired_vel"]
    for name in numbers:
        if not _is_number(config[name]):
            raise ValueError(f"wind_flocking: {name} must be a finite number, got {config[name]!r}")
    for name in ("observe_rel_pos", "observe_rel_vel", "observe_pos", "use_controller"):
        if not isinstance(config[name], bool):
            raise ValueError(f"wind_flocking: {name} must be a bool, got {config[name]!r}")
    horizon = config["horizon"]
    if isinstance(horizon, bool) or not isinstance(horizon, int) or horizon < 1:
        raise ValueError(f"wind_flocking: horizon must be an int >= 1, got {horizon!r}")
    return config


def line_angle_to_horizontal(angle: Tensor) -> Tensor:
    """Angle in [0, pi/2] between an undirected line at ``angle`` and the x axis (same shape)."""
    folded = angle % math.pi
    return torch.minimum(folded, math.pi - folded)


class Scenario(BaseScenario):
    supports_batched_reset = True

    def make_world(self, batch_dim: int, device, **kwargs) -> World:
        config = validate(read_kwargs(kwargs, DEFAULTS))
        for name, value in config.items():
            setattr(self, name, value)
        self.plot_grid = True
        self.viewer_zoom = 2
        self.grid_spacing = DESIRED_DISTANCE
        self.u_range = self.v_range if self.use_controller else self.f_range

        world = World(batch_dim, device, drag=0, linear_friction=LINEAR_FRICTION)
        self.max_pos = self.horizon * world.dt * self.desired_vel  # height reached in a horizon at desired speed
        #: the wind force per unit mass, [B, 2]; the small agent always feels all of it
        self.wind_force = torch.tensor([0.0, -float(self.wind)], device=world.device).expand(batch_dim, 2)
        self._desired_velocity = torch.tensor([0.0, float(self.desired_vel)], device=world.device)
        for i, radius in enumerate((BIG_RADIUS, SMALL_RADIUS)):
            agent = Agent(
                name=f"agent_{i}", render_action=True, shape=Sphere(radius=radius), u_range=self.u_range,
                v_range=self.v_range, f_range=self.f_range, gravity=self.wind_force,
            )
            agent.controller = VelocityController(agent, world, PID_PARAMS, "standard")
            world.add_agent(agent)
        self.big_agent, self.small_agent = world.agents
        self._index = {agent.name: i for i, agent in enumerate(world.agents)}

        zeros = torch.zeros(batch_dim, device=world.device)
        #: per env: rewards computed since the reset [B]
        self.t = torch.zeros(batch_dim, dtype=torch.int, device=world.device)
        #: per env, the shaping values at the last reward (or reset) [B]
        self.distance_shaping, self.rot_shaping, self.pos_shaping = zeros.clone(), zeros.clone(), zeros.clone()
        #: per env and agent, the per-agent shaping values at the last reward (or reset) [B, 2]
        self.vel_shaping = torch.zeros(batch_dim, 2, device=world.device)
        self.energy_shaping, self.wind_shaping = self.vel_shaping.clone(), self.vel_shaping.clone()
        #: the last reward's terms: shared [B], per agent [B, 2]
        self.dist_rew, self.rot_rew, self.pos_rew = zeros.clone(), zeros.clone(), zeros.clone()
        self.agent_vel_rew, self.agent_energy_rew = self.vel_shaping.clone(), self.vel_shaping.clone()
        self.agent_wind_rew = self.vel_shaping.clone()
        self._reward = zeros.clone()
        return world

    def set_wind(self, wind: float) -> None:
        """Set the wind to ``wind`` (downwards) in every env; the big agent's shelter applies from the next reward."""
        if not _is_number(wind):
            raise ValueError(f"wind_flocking: wind must be a finite number, got {wind!r}")
        self.wind = wind
        self.wind_force = torch.tensor([0.0, -float(wind)], device=self.world.device).expand(self.world.batch_dim, 2)
        self.big_agent.gravity = self.wind_force
        self.small_agent.gravity = self.wind_force

    # ------------------------------------------------------------------ shaping
    def agents_heading(self) -> Tensor:
        """Heading of the vector from the small agent to the big one, [B]."""
        delta = self.big_agent.state.pos - self.small_agent.state.pos
        return torch.atan2(delta[:, Y], delta[:, X])

    def _shared_shaping(self) -> tuple[Tensor, Tensor, Tensor]:
        """Separation, line-angle and height shaping values, each [B]."""
        big, small = self.big_agent.state.pos, self.small_agent.state.pos
        separation = torch.linalg.vector_norm(small - big, dim=-1)
        distance = (separation - DESIRED_DISTANCE).abs() * self.dist_shaping_factor
        rot = line_angle_to_horizontal(self.agents_heading()) * self.rot_shaping_factor
        height = (torch.maximum(big[:, Y], small[:, Y]) - DESIRED_HEIGHT).abs() * self.pos_shaping_factor
        return distance, rot, height

    def _velocity_shaping(self) -> Tensor:
        vel = torch.stack([a.state.vel for a in self.world.agents], dim=1)  # [B, 2 agents, 2]
        return torch.linalg.vector_norm(vel - self._desired_velocity, dim=-1) * self.vel_shaping_factor

    def _wind_shaping(self) -> Tensor:
        winds = torch.stack([self.big_agent.gravity, self.small_agent.gravity], dim=1)  # [B, 2 agents, 2]
        return torch.linalg.vector_norm(winds, dim=-1) * self.wind_shaping_factor

    def shelter(self) -> Tensor:
        """The share of the wind the big agent feels in the current layout, [B, 1] in [0, 1] (tol <= 2)."""
        tol = self.cover_angle_tolerance
        lee = (torch.sin(self.agents_heading()) + 1).clamp(max=tol) + (1 - tol)
        return ((lee - 1 + tol) / tol).unsqueeze(-1)

    # -------------------------------------------------------------------- reset
    def reset_world_at(self, env_index=None) -> None:
        world = self.world
        rows = selected_rows(world.batch_dim, env_index)
        heading = torch.empty(rows, 1, device=world.device).uniform_(-START_SPREAD, START_SPREAD)
        half = torch.cat([torch.cos(heading), torch.sin(heading)], dim=1) * (DESIRED_DISTANCE / 2)  # [R, 2]
        big_first = torch.rand(rows, 1, device=world.device) < 0.5  # the big agent takes the -half end
        big_start = torch.where(big_first, -half, half)
        self.big_agent.set_pos(for_index(big_start, env_index), batch_index=env_index)
        self.small_agent.set_pos(for_index(-big_start, env_index), batch_index=env_index)
        for agent in world.agents:
            agent.controller.reset(env_index)
        # the big agent's wind back to full in the reset envs (it is rescaled after every step)
        if env_index is None:
            self.big_agent.gravity = self.wind_force
        else:
            wind = self.big_agent.gravity.clone()
            wind[env_index] = self.wind_force[env_index]
            self.big_agent.gravity = wind

        distance, rot, height = self._shared_shaping()
        if env_index is None:
            self.t = torch.zeros_like(self.t)
            self.distance_shaping, self.rot_shaping, self.pos_shaping = distance, rot, height
            self.vel_shaping = self._velocity_shaping()
            self.energy_shaping = torch.zeros_like(self.energy_shaping)
            self.wind_shaping = self._wind_shaping()
        else:
            self.t[env_index] = 0
            self.distance_shaping[env_index] = distance[env_index]
            self.rot_shaping[env_index] = rot[env_index]
            self.pos_shaping[env_index] = height[env_index]
            self.vel_shaping[env_index] = self._velocity_shaping()[env_index]
            self.energy_shaping[env_index] = 0.0
            self.wind_shaping[env_index] = self._wind_shaping()[env_index]

    # ------------------------------------------------------------------ actions
    def process_action(self, agent: Agent) -> None:
        if self.use_controller:
            agent.controller.process_force()

    # ------------------------------------------------------------------- reward
    def _update_rewards(self) -> None:
        """Every reward term of this step, once for both agents; rescales the big agent's wind first."""
        self.t = self.t + 1
        self.big_agent.gravity = self.wind_force * self.shelter()

        distance, rot, height = self._shared_shaping()
        self.dist_rew, self.distance_shaping = self.distance_shaping - distance, distance
        self.rot_rew, self.rot_shaping = self.rot_shaping - rot, rot
        self.pos_rew, self.pos_shaping = self.pos_shaping - height, height

        velocity = self._velocity_shaping()
        self.agent_vel_rew, self.vel_shaping = self.vel_shaping - velocity, velocity

        forces = torch.stack([a.action.u for a in self.world.agents], dim=1)  # [B, 2 agents, 2]
        energy = torch.linalg.vector_norm(forces, dim=-1) * self.energy_shaping_factor
        early = (self.t < ENERGY_GRACE).unsqueeze(-1)
        self.agent_energy_rew = torch.where(early, 0.0, self.energy_shaping - energy)
        self.energy_shaping = energy

        wind = self._wind_shaping()
        early = (self.t < WIND_GRACE).unsqueeze(-1)
        self.agent_wind_rew = torch.where(early, 0.0, self.wind_shaping - wind)
        self.wind_shaping = wind

        per_agent = (self.agent_vel_rew + self.agent_energy_rew + self.agent_wind_rew).mean(dim=1)
        self._reward = self.dist_rew + per_agent + self.rot_rew + self.pos_rew

    def reward(self, agent: Agent) -> Tensor:
        if self._index[agent.name] == 0:
            self._update_rewards()
        return self._reward

    # -------------------------------------------------------------- observation
    def observation(self, agent: Agent) -> Tensor:
        other = self.small_agent if agent is self.big_agent else self.big_agent
        parts = [agent.state.pos] if self.observe_pos else []
        parts.append(agent.state.vel)
        if self.observe_rel_pos:
            parts.append(other.state.pos - agent.state.pos)
        if self.observe_rel_vel:
            parts.append(other.state.vel - agent.state.vel)
        return torch.cat(parts, dim=-1)

    def info(self, agent: Agent) -> dict:
        i = self._index[agent.name]
        return {
            "dist_rew": self.dist_rew,
            "rot_rew": self.rot_rew,
            "pos_rew": self.pos_rew,
            "agent_wind_rew": self.agent_wind_rew[:, i],
            "agent_vel_rew": self.agent_vel_rew[:, i],
            "agent_energy_rew": self.agent_energy_rew[:, i],
            "delta_vel_to_goal": torch.linalg.vector_norm(agent.state.vel - self._desired_velocity, dim=-1),
        }

    def extra_render(self, env_index: int = 0) -> list:
        """A 1 m bar through the agents' midpoint along their line, and a red bar at the height of ``max_pos``."""
        from vmas_ros.simulator import rendering
        from vmas_ros.simulator.utils import Color

        half = DESIRED_DISTANCE / 2
        midpoint = (self.big_agent.state.pos[env_index] + self.small_agent.state.pos[env_index]) / 2
        bar = rendering.Line((-half, 0.0), (half, 0.0), width=1)
        bar.add_attr(rendering.Transform(translation=midpoint.tolist(), rotation=self.agents_heading()[env_index]))
        bar.set_color(*Color.BLACK.value)
        finish = rendering.Line((-half, 0.0), (half, 0.0), width=1)
        finish.add_attr(rendering.Transform(translation=(0.0, self.max_pos)))
        finish.set_color(*Color.RED.value)
        return [bar, finish]


class HeuristicPolicy(BaseHeuristicPolicy):
    """Fly straight up at the desired speed; with ``observe_rel_pos``, also hold the 1 m separation.

    The command is the desired velocity ``(0, desired_vel)``; when the other
    agent's relative position is observed, a correction along the line
    between the agents (``spacing_gain`` x the separation error) restores the
    1 m spacing, each agent doing half the work. The velocity controller
    (default) rejects the wind itself; with force actions a proportional
    velocity loop plus a wind feed-forward (the full wind, ``+wind``
    upwards) gives the force. Continuous actions only.
    """

    spacing_gain = 0.5
    force_gain = 4.0

    def __init__(self, continuous_action: bool = True, **scenario_kwargs) -> None:
        super().__init__(continuous_action)
        config = validate(continuous_heuristic_kwargs("wind_flocking", DEFAULTS, scenario_kwargs, continuous_action))
        self.desired = float(config["desired_vel"])
        self.v_range = float(config["v_range"])
        self.wind = float(config["wind"])
        self.velocity_actions = config["use_controller"]
        self.vel_at = 2 if config["observe_pos"] else 0
        self.rel_pos_at = self.vel_at + 2 if config["observe_rel_pos"] else None
        self.width = self.vel_at + 2 + 2 * (config["observe_rel_pos"] + config["observe_rel_vel"])

    def compute_action(self, observation: Tensor, u_range: float) -> Tensor:
        if observation.shape[-1] != self.width:
            raise ValueError(
                f"wind_flocking heuristic: expected observation width {self.width}, got {observation.shape[-1]}"
            )
        vel = observation[:, self.vel_at:self.vel_at + 2]
        target = torch.zeros_like(vel)
        target[:, 1] = self.desired
        if self.rel_pos_at is not None:
            offset = observation[:, self.rel_pos_at:self.rel_pos_at + 2]  # to the other agent
            separation = torch.linalg.vector_norm(offset, dim=-1, keepdim=True).clamp_min(1e-6)
            target = target + self.spacing_gain * (separation - DESIRED_DISTANCE) * offset / separation
        target = target.clamp(-self.v_range, self.v_range)
        if self.velocity_actions:
            return target.clamp(-u_range, u_range)
        force = self.force_gain * (target - vel)
        force[:, 1] += self.wind
        return force.clamp(-u_range, u_range)
