"""asym_joint: two agents joined by a rod turn it upright, one end carrying a heavy mass.

Description
    Two discs (radius 0.03333, force x0.8; ``agent 0`` and ``agent 1``) are
    the ends of a rigid rod of ``joint_length`` (mass 1, not collidable; the
    rod is the landmark ``joint agent 0 agent 1``). They must turn the rod
    upright (angle pi/2, either way up) while spending little force. With
    ``asym_package`` (default) a non-colliding disc ``mass`` of ``mass_ratio``
    is pinned on the rod at ``mass_position`` of its half-length from the
    centre, towards ``agent 1``; otherwise ``agent 1`` itself weighs
    ``mass_ratio``. ``max_speed_1`` caps ``agent 1``'s speed. World: dt 0.1;
    with the package 10 substeps, joint force 900, drag 0.15; without it 7,
    400 and 0.25.
Observation (per agent, in this order)
    own position (2), own velocity (2) and, with ``observe_joint_angle``, the
    rod's (cos, sin) (2), its angle first perturbed by Gaussian noise of std
    ``joint_angle_obs_noise``. Every entry then gets uniform noise in
    [-obs_noise, obs_noise] (default 0.2).
Reward
    Shared: ``rot_shaping_factor`` x the decrease since the last step of the
    rod's angular distance to upright (the angle between the two lines, in
    [0, pi/2]), minus ``energy_reward_coeff`` x the summed norms of both
    agents' actions, each over its largest possible norm (sqrt(2) x 0.8).
    ``info`` reports ``rot_rew`` and ``energy_rew``.
Starting state
    The rod centred at the origin at angle 0 (uniform in [-pi/2, pi/2] with
    ``random_start_angle``), at rest; which end is ``agent 0`` is random.
    VMAS 1.5 draws that order once per reset call (shared by the whole batch
    on a full reset); here every env draws its own.
Episode termination
    When the rod is within 0.01 rad of upright.
Kwargs
    ``joint_length`` (0.5), ``random_start_angle`` (False),
    ``observe_joint_angle`` (False), ``joint_angle_obs_noise`` (0.0, only with
    ``observe_joint_angle``), ``asym_package`` (True), ``mass_ratio`` (5),
    ``mass_position`` (0.75, in [-1, 1]), ``max_speed_1`` (None),
    ``obs_noise`` (0.2), ``rot_shaping_factor`` (1), ``energy_reward_coeff``
    (0.08). VMAS 1.5 adds the angle noise to the rod's state in place (so the
    noise leaks into the physics, the reward and ``done``); here it only
    perturbs the observation.
"""
from __future__ import annotations

import math

import torch
from torch import Tensor

from vmas_ros.scenarios.common import (
    check_number, configure, continuous_heuristic_kwargs, for_index, selected_rows,
)
from vmas_ros.scenarios.line_angles import (  # noqa: F401  VMAS's names for its users
    angle_to_vector, get_line_angle_0_90, get_line_angle_0_180, get_line_angle_dist_0_180, get_line_angle_dist_0_360,
)
from vmas_ros.simulator.core import Agent, Landmark, Sphere, World
from vmas_ros.simulator.heuristic_policy import BaseHeuristicPolicy
from vmas_ros.simulator.joints import Joint
from vmas_ros.simulator.scenario import BaseScenario
from vmas_ros.simulator.utils import Color

NAME = "asym_joint"
#: name -> default of every kwarg (the heuristic takes them too)
DEFAULTS = {
    "joint_length": 0.5, "random_start_angle": False, "observe_joint_angle": False,
    "joint_angle_obs_noise": 0.0, "asym_package": True, "mass_ratio": 5, "mass_position": 0.75,
    "max_speed_1": None, "obs_noise": 0.2, "rot_shaping_factor": 1, "energy_reward_coeff": 0.08,
}
AGENT_RADIUS = 0.03333
MASS_RADIUS = AGENT_RADIUS * 2 / 3
U_MULTIPLIER = 0.8
GOAL_ANGLE = math.pi / 2
DONE_TOLERANCE = 0.01


def validate(config: dict) -> None:
    """Raise ValueError for a kwarg value the task cannot be built with."""
    check_number(NAME, "joint_length", config["joint_length"], strict=True)
    check_number(NAME, "mass_ratio", config["mass_ratio"], strict=True)
    for name in ("obs_noise", "joint_angle_obs_noise", "rot_shaping_factor", "energy_reward_coeff"):
        check_number(NAME, name, config[name])
    position = config["mass_position"]
    if isinstance(position, bool) or not isinstance(position, (int, float)) or not -1 <= position <= 1:
        raise ValueError(f"{NAME}: mass_position must be a number in [-1, 1] (of the half-length), got {position!r}")
    if config["max_speed_1"] is not None:
        check_number(NAME, "max_speed_1", config["max_speed_1"], strict=True)
    for name in ("random_start_angle", "observe_joint_angle", "asym_package"):
        if not isinstance(config[name], bool):
            raise ValueError(f"{NAME}: {name} must be a bool, got {config[name]!r}")
    if config["joint_angle_obs_noise"] and not config["observe_joint_angle"]:
        raise ValueError(
            f"{NAME}: joint_angle_obs_noise must be 0 unless observe_joint_angle is set, "
            f"got {config['joint_angle_obs_noise']!r}"
        )


def distance_to_upright(rot: Tensor) -> Tensor:
    """Angle [B] between the line at angle ``rot`` ([B, 1]) and the upright line, in [0, pi/2]."""
    turn = torch.remainder(rot[:, 0] - GOAL_ANGLE, math.pi)
    return torch.minimum(turn, math.pi - turn)


class Scenario(BaseScenario):
    supports_batched_reset = True
    fresh_observations = True

    def make_world(self, batch_dim: int, device, **kwargs) -> World:
        configure(self, kwargs, DEFAULTS, validate)
        package = self.asym_package
        world = World(
            batch_dim, device, substeps=10 if package else 7, joint_force=900 if package else 400,
            drag=0.15 if package else 0.25,
        )
        for i in range(2):
            world.add_agent(Agent(
                name=f"agent {i}", shape=Sphere(AGENT_RADIUS), u_multiplier=U_MULTIPLIER,
                mass=self.mass_ratio if i == 1 and not package else 1,
                max_speed=self.max_speed_1 if i == 1 else None, obs_noise=self.obs_noise, render_action=True,
            ))
        first, second = world.agents
        self.rod = Joint(
            first, second, dist=self.joint_length, rotate_a=True, rotate_b=True, collidable=False, width=0, mass=1,
        )
        world.add_joint(self.rod)
        self.mass = None
        if package:
            self.mass = Landmark(
                name="mass", shape=Sphere(radius=MASS_RADIUS), collide=False, movable=True, color=Color.BLACK,
                mass=self.mass_ratio, collision_filter=lambda e: not isinstance(e.shape, Sphere),
            )
            world.add_landmark(self.mass)
            world.add_joint(Joint(self.mass, self.rod.landmark, anchor_b=(self.mass_position, 0.0), dist=0.0))
        zeros = torch.zeros(batch_dim, device=device)
        #: per env, [B]: rot_shaping_factor x the rod's distance to upright as of the last reward
        self.shaping = zeros.clone()
        self.rot_rew, self.energy_rew, self._reward = zeros.clone(), zeros.clone(), zeros.clone()
        #: the largest norm an agent's action can have (after the multiplier)
        self._max_effort = math.sqrt(world.dim_p * U_MULTIPLIER**2)
        return world

    def reset_world_at(self, env_index=None) -> None:
        world = self.world
        rows = selected_rows(world.batch_dim, env_index)
        spread = math.pi / 2 if self.random_start_angle else 0.0
        angle = torch.empty(rows, 1, device=world.device).uniform_(-spread, spread)
        half = torch.cat([torch.cos(angle), torch.sin(angle)], dim=1) * (self.joint_length / 2)  # [rows, 2]
        # +1: agent 0 at the -half end, agent 1 at the +half end; -1: swapped
        side = torch.where(torch.rand(rows, 1, device=world.device) < 0.5, 1.0, -1.0)
        first, second = world.agents
        first.set_pos(for_index(-side * half, env_index), batch_index=env_index)
        second.set_pos(for_index(side * half, env_index), batch_index=env_index)
        if self.mass is not None:  # on agent 1's side of the centre
            self.mass.set_pos(for_index(side * half * self.mass_position, env_index), batch_index=env_index)
        shaping = distance_to_upright(self.rod.landmark.state.rot) * self.rot_shaping_factor
        if env_index is None:
            self.shaping = shaping
        else:
            self.shaping[env_index] = shaping[env_index]

    def _shared_reward(self) -> Tensor:
        shaping = distance_to_upright(self.rod.landmark.state.rot) * self.rot_shaping_factor
        self.rot_rew = self.shaping - shaping
        self.shaping = shaping
        effort = sum(torch.linalg.vector_norm(a.action.u, dim=-1) for a in self.world.agents) / self._max_effort
        self.energy_rew = -effort * self.energy_reward_coeff
        return self.rot_rew + self.energy_rew

    def reward(self, agent: Agent) -> Tensor:
        if agent is self.world.agents[0]:  # one shared reward: compute it once per step
            self._reward = self._shared_reward()
        return self._reward

    def observation(self, agent: Agent) -> Tensor:
        parts = [agent.state.pos, agent.state.vel]
        if self.observe_joint_angle:
            angle = self.rod.landmark.state.rot
            if self.joint_angle_obs_noise:
                angle = angle + torch.randn_like(angle) * self.joint_angle_obs_noise
            parts.append(torch.cat([torch.cos(angle), torch.sin(angle)], dim=1))
        stacked = torch.stack(parts)  # [P, B, 2]
        if self.obs_noise:
            # drawn part after part, as VMAS 1.5 does, so a seeded stream gives the same noise
            stacked = stacked + torch.empty_like(stacked).uniform_(-self.obs_noise, self.obs_noise)
        return torch.cat(list(stacked.unbind(0)), dim=-1)

    def done(self) -> Tensor:
        return distance_to_upright(self.rod.landmark.state.rot) <= DONE_TOLERANCE

    def info(self, agent: Agent) -> dict:
        return {"rot_rew": self.rot_rew, "energy_rew": self.energy_rew}

    def extra_render(self, env_index: int = 0) -> list:
        from vmas_ros.simulator import rendering

        origin = rendering.make_circle(0.01)
        origin.set_color(*Color.GREEN.value)
        return [origin]


class HeuristicPolicy(BaseHeuristicPolicy):
    """Both ends push the rod counter-clockwise until it is upright.

    Each agent estimates the rod's angle: from the observed rod direction
    with ``observe_joint_angle``, else from its own (noisy) position seen from
    the origin, where the rod starts and stays roughly centred (equal and
    opposite pushes turn it without moving its centre of mass much). It
    pushes along the counter-clockwise tangent of that estimate with a force
    proportional to the remaining turn (``gain``), capped at ``max_push``:
    counter-clockwise brings the agent with x > 0 up and the other down, so
    the two always agree without seeing each other. The proportional push and
    a dead band keep the energy cost low once the rod is close to upright,
    where the noisy estimate would otherwise make it jitter.
    """

    gain = 0.6
    max_push = 0.6
    #: no push while the estimated remaining turn is smaller (rad): wider when the
    #: estimate comes from a position blurred by +-0.2 at a radius of ~0.25
    dead_band_observed, dead_band_estimated = 0.2, 0.6

    def __init__(self, continuous_action: bool = True, **scenario_kwargs) -> None:
        super().__init__(continuous_action)
        config = continuous_heuristic_kwargs(NAME, DEFAULTS, scenario_kwargs, continuous_action)
        validate(config)
        self.observe_joint_angle = config["observe_joint_angle"]
        self.dead_band = self.dead_band_observed if self.observe_joint_angle else self.dead_band_estimated

    def compute_action(self, observation: Tensor, u_range: float) -> Tensor:
        width = 6 if self.observe_joint_angle else 4
        if observation.shape[1] != width:
            raise ValueError(f"asym_joint heuristic: expected observation width {width}, got {observation.shape[1]}")
        pos = observation[:, 0:2]
        if self.observe_joint_angle:  # the rod as a line: its angle mod pi, the end on this agent's side
            direction = observation[:, 4:6]
            along = (pos * direction).sum(-1, keepdim=True)
            radial = torch.where(along >= 0, direction, -direction)
        else:
            radial = pos
        angle = torch.atan2(radial[:, 1], radial[:, 0])  # this end's direction from the centre
        # the remaining counter-clockwise turn to the nearest upright direction, in (-pi/2, pi/2]
        remaining = torch.remainder(math.pi / 2 - angle, math.pi)
        remaining = torch.where(remaining > math.pi / 2, remaining - math.pi, remaining)
        unit = radial / torch.linalg.vector_norm(radial, dim=-1, keepdim=True).clamp(min=1e-9)
        tangent = torch.stack([-unit[:, 1], unit[:, 0]], dim=-1)
        push = (self.gain * remaining).clamp(-self.max_push, self.max_push)
        push = torch.where(remaining.abs() < self.dead_band, 0.0, push).unsqueeze(-1)
        return (push * tangent).clamp(-u_range, u_range)
