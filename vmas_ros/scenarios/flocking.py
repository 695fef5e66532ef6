"""flocking: agents gather around a moving target, avoiding obstacles and each other.

Description
    ``n_agents`` blue discs (radius 0.05, each with a 12-ray lidar of range
    0.2 that sees only the red obstacles) flock around a green target disc, a
    scripted agent that pushes with unit force along a heading turning at
    1/30 rad per step (so it drives round a circle of radius ~1.2 at ~0.4
    m/s). ``n_obstacles`` static red discs (radius 0.1) stand in the way. The
    arena is unbounded (paper, "Multi-robot scenarios": "N agents have to
    flock around a target without colliding among each other and M
    obstacles").
Observation (per agent, in this order)
    own position (2), own velocity (2), own position minus the target's (2),
    lidar distances to obstacles (``n_lidar_rays``, ``0.2`` when a ray hits
    nothing; ray ``k`` points at angle ``2 pi k / n_lidar_rays``).
Reward
    Distance shaping: with ``s_i`` the mean over every other agent ``j``,
    target included, of ``(|p_i - p_j| - 0.1)^2`` times
    ``dist_shaping_factor``, the agent earns the decrease of ``s_i`` since the
    last step. Plus ``collision_reward`` for each other agent (target
    included) whose surface is within 0.005 of its own.
Starting state
    Target at (0, -1) at rest; obstacles then agents uniform in [-1, 1]^2,
    every two (and the target) at least ``min_dist_between_entities`` apart.
Episode termination
    Never (set ``max_steps``).
Info (per agent)
    ``agent_collision_rew`` and ``agent_distance_rew``, the two reward terms.
Kwargs
    ``n_agents`` (4), ``n_obstacles`` (5), ``min_dist_between_entities``
    (0.15), ``n_lidar_rays`` (12), ``collision_reward`` (-0.1),
    ``dist_shaping_factor`` (1).
"""
from __future__ import annotations

import math

import torch
from torch import Tensor

from vmas_ros.scenarios.common import for_index, pair_distances, read_kwargs, sample_clear_positions, selected_rows
from vmas_ros.simulator.core import Agent, Landmark, Sphere, World
from vmas_ros.simulator.heuristic_policy import BaseHeuristicPolicy
from vmas_ros.simulator.scenario import BaseScenario
from vmas_ros.simulator.sensors import Lidar
from vmas_ros.simulator.utils import Color

#: name -> default of every kwarg
DEFAULTS = {
    "n_agents": 4, "n_obstacles": 5, "min_dist_between_entities": 0.15, "n_lidar_rays": 12,
    "collision_reward": -0.1, "dist_shaping_factor": 1,
}
ARENA = 1.0  # spawn square half-width; the target starts at (0, -ARENA)
OBSTACLE_RADIUS = 0.1
LIDAR_RANGE = 0.2
DESIRED_DISTANCE = 0.1  # between agent centres, in the shaping term
COLLISION_DISTANCE = 0.005  # surface gap at or below which two agents count as colliding
TARGET_TURN_STEPS = 30.0  # steps per radian of the target's heading


class Scenario(BaseScenario):
    supports_batched_reset = True

    def make_world(self, batch_dim: int, device, **kwargs) -> World:
        config = read_kwargs(kwargs, DEFAULTS)
        for name in ("n_agents", "n_lidar_rays"):
            if not isinstance(config[name], int) or config[name] < 1:
                raise ValueError(f"flocking: {name} must be an int >= 1, got {config[name]!r}")
        if not isinstance(config["n_obstacles"], int) or config["n_obstacles"] < 0:
            raise ValueError(f"flocking: n_obstacles must be an int >= 0, got {config['n_obstacles']!r}")
        if not config["min_dist_between_entities"] >= 0:
            raise ValueError(
                f"flocking: min_dist_between_entities must be >= 0, got {config['min_dist_between_entities']!r}"
            )
        for name, value in config.items():
            setattr(self, name, value)
        self.plot_grid = True

        world = World(batch_dim, device, collision_force=400, substeps=5)
        self.target = Agent(
            name="target", collide=True, color=Color.GREEN, render_action=True, action_script=self._drive_target,
        )
        world.add_agent(self.target)
        for i in range(self.n_agents):
            world.add_agent(Agent(
                name=f"agent_{i}", collide=True, render_action=True,
                sensors=[Lidar(world, n_rays=self.n_lidar_rays, max_range=LIDAR_RANGE, entity_filter=is_not_agent)],
            ))
        for i in range(self.n_obstacles):
            world.add_landmark(Landmark(
                name=f"obstacle_{i}", collide=True, movable=False, shape=Sphere(radius=OBSTACLE_RADIUS),
                color=Color.RED,
            ))

        self._index = {agent.name: i for i, agent in enumerate(world.policy_agents)}
        radii = torch.tensor([a.shape.radius for a in world.agents], device=device)
        self._radii_i, self._radii_j = radii.view(-1, 1, 1), radii.view(1, -1, 1)  # [A, A, B] broadcasts
        self._not_self = ~torch.eye(len(world.agents), dtype=torch.bool, device=device).unsqueeze(-1)
        #: per env: rewards computed so far (drives the target's heading) [B]
        self.t = torch.zeros(batch_dim, device=device)
        #: per agent and env: the shaping value at the last reward [n_agents, B] (agent-major: each
        #: agent's reward is a contiguous row)
        self.distance_shaping = torch.zeros(self.n_agents, batch_dim, device=device)
        #: per agent and env: the last reward's two terms [n_agents, B]
        self.collision_rew = torch.zeros(self.n_agents, batch_dim, device=device)
        self.dist_rew = torch.zeros(self.n_agents, batch_dim, device=device)
        return world

    def _drive_target(self, target: Agent, world: World) -> None:
        """The target's script: unit force along a heading that turns 1/30 rad per step."""
        heading = self.t / TARGET_TURN_STEPS
        target.action.u = torch.stack([torch.cos(heading), torch.sin(heading)], dim=1)

    def reset_world_at(self, env_index=None) -> None:
        world = self.world
        rows = selected_rows(world.batch_dim, env_index)
        target_pos = torch.zeros(rows, world.dim_p, device=world.device)
        target_pos[:, 1] = -ARENA
        self.target.set_pos(for_index(target_pos, env_index), batch_index=env_index)
        placed = world.landmarks + world.policy_agents
        positions = sample_clear_positions(
            target_pos.unsqueeze(1), len(placed), self.min_dist_between_entities, (-ARENA, ARENA), (-ARENA, ARENA),
        )
        for k, entity in enumerate(placed):
            entity.set_pos(for_index(positions[:, k], env_index), batch_index=env_index)

        shaping = self._shaping(self._distances())
        if env_index is None:
            self.distance_shaping = shaping
            self.t = torch.zeros_like(self.t)
        else:
            self.distance_shaping[:, env_index] = shaping[:, env_index]
            self.t[env_index] = 0.0

    # ------------------------------------------------------------------ reward
    def _distances(self) -> Tensor:
        """Centre distances ``[A, A, B]`` between all agents, the target first (planar rows: vectorises)."""
        x, y = self.world.stacked_xy("pos")
        n = len(self.world.agents)  # agents are the last rows of the entity stack
        x, y = x[-n:], y[-n:]
        return pair_distances(x, y, x, y)

    def _shaping(self, dist: Tensor) -> Tensor:
        """Each policy agent's mean squared deviation from ``DESIRED_DISTANCE`` to the others, [n_agents, B]."""
        gap = (dist[1:] - DESIRED_DISTANCE).pow(2)  # rows: policy agents; columns: every agent
        return (gap * self._not_self[1:]).sum(dim=1) / (dist.shape[0] - 1) * self.dist_shaping_factor

    def _update_rewards(self) -> None:
        """All agents' reward terms for this step, in one batched pass (also advances the target's clock)."""
        self.t = self.t + 1
        dist = self._distances()
        surface_gap = dist - self._radii_j - self._radii_i
        touching = (surface_gap <= COLLISION_DISTANCE) & self._not_self
        self.collision_rew = touching[1:].sum(dim=1) * self.collision_reward
        shaping = self._shaping(dist)
        self.dist_rew = self.distance_shaping - shaping
        self.distance_shaping = shaping

    def reward(self, agent: Agent) -> Tensor:
        i = self._index[agent.name]
        if i == 0:
            self._update_rewards()
        return self.collision_rew[i] + self.dist_rew[i]

    def observation(self, agent: Agent) -> Tensor:
        return torch.cat([
            agent.state.pos, agent.state.vel, agent.state.pos - self.target.state.pos, agent.sensors[0].measure(),
        ], dim=-1)

    def info(self, agent: Agent) -> dict[str, Tensor]:
        i = self._index[agent.name]
        return {"agent_collision_rew": self.collision_rew[i], "agent_distance_rew": self.dist_rew[i]}


def is_not_agent(entity) -> bool:
    """The flocking lidar's filter: it sees obstacles only (neither agents nor the target)."""
    return not isinstance(entity, Agent)


class HeuristicPolicy(BaseHeuristicPolicy):
    """Ride along with the target on a ring around it; dodge obstacles by lidar and agents by touch.

    The lidar sees only obstacles, so an agent learns of another only when
    they touch. The policy is built so that contacts are rare and short:

    * ring: a radial spring towards ``ring_radius`` from the target; the
      bearing is left free, so agents that arrive from different sides keep
      apart instead of all heading for one point;
    * keeping pace: the target runs at about the agents' top speed, so the
      agent feeds its own velocity forward (``radial_cruise`` and
      ``lateral_cruise`` of the force that would hold it against drag), and
      the spring only corrects the offset;
    * clearance: a push away from the target inside ``target_clearance``,
      and away from every lidar ray shorter than its range (weighted by how
      short);
    * touch: at steady state ``v = (dt / drag) u``; a shortfall ``(dt / drag)
      u - v`` means something pushes back, i.e. a contact. The agent then
      sidesteps to the left of that push; two agents pressing on each other
      sidestep opposite ways and slide apart.
    """

    ring_radius = 0.45
    ring_gain = 3.0
    radial_cruise = 0.95
    lateral_cruise = 1.0
    obstacle_gain = 3.0
    target_clearance = 0.4
    target_gain = 2.0
    contact_threshold = 0.03  # shortfall (m/s) below which no contact is assumed
    contact_ramp = 0.1  # shortfall over which the sidestep reaches full strength

    #: terminal speed per unit of force of an agent (mass 1): dt / drag of the world
    speed_per_force = 0.1 / 0.25

    def __init__(self, continuous_action: bool = True, n_lidar_rays: int = DEFAULTS["n_lidar_rays"]) -> None:
        super().__init__(continuous_action)
        if not isinstance(n_lidar_rays, int) or n_lidar_rays < 1:
            raise ValueError(f"flocking heuristic: n_lidar_rays must be an int >= 1, got {n_lidar_rays!r}")
        self.n_lidar_rays = n_lidar_rays
        angles = torch.arange(n_lidar_rays) * (2 * math.pi / n_lidar_rays)
        self._rays = torch.stack([angles.cos(), angles.sin()], dim=-1)  # [R, 2]

    def compute_action(self, observation: Tensor, u_range: float) -> Tensor:
        width = 6 + self.n_lidar_rays
        if observation.shape[-1] != width:
            raise ValueError(f"flocking heuristic: expected observation width {width}, got {observation.shape[-1]}")
        vel, offset, lidar = observation[:, 2:4], observation[:, 4:6], observation[:, 6:]
        dist = torch.linalg.vector_norm(offset, dim=-1, keepdim=True).clamp_min(1e-6)
        out = offset / dist  # unit vector from the target to the agent
        side = _left(out)
        radial_speed, lateral_speed = (vel * out).sum(-1, keepdim=True), (vel * side).sum(-1, keepdim=True)
        cruise = (self.radial_cruise * radial_speed * out + self.lateral_cruise * lateral_speed * side)
        action = cruise / self.speed_per_force + self.ring_gain * (self.ring_radius - dist) * out
        action = action + self.target_gain * ((self.target_clearance - dist) / 0.1).clamp_min(0.0) * out
        if self._rays.device != observation.device:
            self._rays = self._rays.to(observation.device)
        closeness = ((LIDAR_RANGE - lidar) / LIDAR_RANGE).clamp_min(0.0)  # [B, R]
        action = action - self.obstacle_gain * closeness @ self._rays
        action = action.clamp(-u_range, u_range)

        shortfall = self.speed_per_force * action - vel
        size = torch.linalg.vector_norm(shortfall, dim=-1, keepdim=True)
        strength = ((size - self.contact_threshold) / self.contact_ramp).clamp(0.0, 1.0)
        action = action + strength * _left(shortfall / size.clamp_min(1e-6)) * u_range
        return action.clamp(-u_range, u_range)


def _left(vectors: Tensor) -> Tensor:
    """``vectors`` [B, 2] turned a quarter turn anticlockwise."""
    return torch.stack([-vectors[:, 1], vectors[:, 0]], dim=-1)
