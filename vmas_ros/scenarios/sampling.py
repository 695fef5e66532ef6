"""sampling: a team maps an unknown density field, each grid cell paying out once.

Description
    ``n_agents`` discs (radius ``agent_radius``) move in a walled square
    ``[-xdim, xdim] x [-ydim, ydim]`` (the world's semidims keep their centres
    ``agent_radius`` inside it). Each env draws a hidden field: the sum of
    ``n_gaussians`` isotropic Gaussian densities with centres uniform in the
    square and variances ``cov``. The square is split into cells of side
    ``grid_spacing``; an agent standing in a cell samples the field there and
    collects its value, but only the first visit to a cell pays: after that it
    is spent for the rest of the episode (paper, "Multi-robot scenarios").
    With ``collisions`` the agents collide and carry a 12-ray lidar that sees
    the other agents.
Observation (per agent, in this order)
    own position (2), own velocity (2), with ``collisions`` the lidar
    distances to other agents (12 rays of range ``lidar_range``, ray ``k`` at
    angle ``0.05 + 2 pi k / 12``), then what a sample would pay one cell away
    in the 8 directions +x, -x, +y, -y, (-x,-y), (+x,-y), (-x,+y), (+x,+y):
    the field at that point (clamped into the semidims) divided by the env's
    largest value on the grid, 0 where the cell is spent or the point is
    outside the square. These 8 are always normalised, whatever ``norm``.
Reward
    Every step the agents sample in order (agent 0 first), each spending its
    cell, so two agents in one cell collect it once. An agent's sample is the
    field at its position (divided by the env's grid maximum with ``norm``),
    0 on a spent cell. With ``shared_rew`` every agent earns the sum of all
    samples, else its own. ``info``: ``agent_sample``, the agent's last sample.
Starting state
    Gaussian centres uniform in the square; agents uniform in it (clamped into
    the semidims), or all at the origin with ``spawn_same_pos``; at rest; no
    cell spent. The normaliser is the field's largest value over the grid
    points ``(-xdim + i * grid_spacing, -ydim + j * grid_spacing)`` (clamped
    into the semidims), per env.
Episode termination
    Never (set ``max_steps``).
Kwargs
    ``n_agents`` (3), ``shared_rew`` (True), ``comms_range`` (0.0, rendering
    only), ``lidar_range`` (0.2), ``agent_radius`` (0.025), ``xdim`` (1),
    ``ydim`` (1), ``grid_spacing`` (0.05; must divide ``xdim`` and ``ydim``),
    ``n_gaussians`` (3), ``cov`` (0.05: one variance for all Gaussians, or a
    list of ``n_gaussians``), ``collisions`` (True), ``spawn_same_pos``
    (False; needs ``collisions=False``), ``norm`` (True).
Deviations from VMAS 1.5
    VMAS cannot build observations without ``collisions`` (its observation
    reads a lidar the agents then lack, and its lidar may not see
    non-colliding agents): here those agents simply observe no lidar (24 - 12
    values), so ``spawn_same_pos`` works. ``reset_at`` recomputes
    ``agent_sample`` of the reset envs only (VMAS recomputes it in every env).
    ``cov`` may be any positive number (VMAS accepts only a float).
"""
from __future__ import annotations

import math
from numbers import Real

import torch
from torch import Tensor

from vmas_ros.scenarios.common import (
    continuous_heuristic_kwargs, for_index, range_links, read_kwargs, selected_rows,
)
from vmas_ros.simulator.core import Agent, Sphere, World
from vmas_ros.simulator.heuristic_policy import BaseHeuristicPolicy
from vmas_ros.simulator.scenario import BaseScenario
from vmas_ros.simulator.sensors import Lidar

#: name -> default of every kwarg (the heuristic reads the ones it needs too)
DEFAULTS = {
    "n_agents": 3, "shared_rew": True, "comms_range": 0.0, "lidar_range": 0.2, "agent_radius": 0.025,
    "xdim": 1, "ydim": 1, "grid_spacing": 0.05, "n_gaussians": 3, "cov": 0.05, "collisions": True,
    "spawn_same_pos": False, "norm": True,
}
N_LIDAR_RAYS = 12
LIDAR_START = 0.05  # angle of the first ray; the rays cover a full turn from there
#: the 8 neighbouring cells the observation looks at, in grid steps (observation order)
NEIGHBOURS = ((1, 0), (-1, 0), (0, 1), (0, -1), (-1, -1), (1, -1), (-1, 1), (1, 1))


def _is_number(value) -> bool:
    return isinstance(value, Real) and not isinstance(value, bool) and math.isfinite(value)


def validate(config: dict) -> list[float]:
    """Raise ValueError for a kwarg value the task cannot be built with; return the variances."""
    for name in ("n_agents", "n_gaussians"):
        value = config[name]
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ValueError(f"sampling: {name} must be an int >= 1, got {value!r}")
    for name in ("lidar_range", "agent_radius", "xdim", "ydim", "grid_spacing"):
        if not (_is_number(config[name]) and config[name] > 0):
            raise ValueError(f"sampling: {name} must be a number > 0, got {config[name]!r}")
    if not (_is_number(config["comms_range"]) and config["comms_range"] >= 0):
        raise ValueError(f"sampling: comms_range must be a number >= 0, got {config['comms_range']!r}")
    for name in ("xdim", "ydim"):
        cells = config[name] / config["grid_spacing"]
        if abs(cells - round(cells)) > 1e-9:
            raise ValueError(
                f"sampling: grid_spacing must divide {name} into whole cells, got {name}={config[name]!r}, "
                f"grid_spacing={config['grid_spacing']!r}"
            )
    if not config["agent_radius"] < min(config["xdim"], config["ydim"]):
        raise ValueError(f"sampling: agent_radius must be < xdim and ydim, got {config['agent_radius']!r}")
    for name in ("shared_rew", "collisions", "spawn_same_pos", "norm"):
        if not isinstance(config[name], bool):
            raise ValueError(f"sampling: {name} must be a bool, got {config[name]!r}")
    if config["spawn_same_pos"] and config["collisions"]:
        raise ValueError("sampling: spawn_same_pos=True needs collisions=False (agents would spawn overlapping)")
    cov = config["cov"]
    covs = [cov] * config["n_gaussians"] if _is_number(cov) else list(cov) if isinstance(cov, (list, tuple)) else None
    if covs is None or len(covs) != config["n_gaussians"] or not all(_is_number(c) and c > 0 for c in covs):
        raise ValueError(
            f"sampling: cov must be a number > 0 or a list of n_gaussians={config['n_gaussians']} of them, got {cov!r}"
        )
    return [float(c) for c in covs]


def is_agent(entity) -> bool:
    """The lidar's filter: it sees the other agents only."""
    return isinstance(entity, Agent)


class Scenario(BaseScenario):
    supports_batched_reset = True
    fresh_observations = True

    def make_world(self, batch_dim: int, device, **kwargs) -> World:
        config = read_kwargs(kwargs, DEFAULTS)
        self.variances = validate(config)
        for name, value in config.items():
            setattr(self, name, value)
        self.plot_grid = False
        self.visualize_semidims = False
        self.n_x_cells = round(2 * self.xdim / self.grid_spacing)
        self.n_y_cells = round(2 * self.ydim / self.grid_spacing)
        self.x_semidim = self.xdim - self.agent_radius
        self.y_semidim = self.ydim - self.agent_radius

        world = World(batch_dim, device, x_semidim=self.x_semidim, y_semidim=self.y_semidim)
        for i in range(self.n_agents):
            sensors = None
            if self.collisions:
                sensors = [Lidar(
                    world, angle_start=LIDAR_START, angle_end=2 * math.pi + LIDAR_START, n_rays=N_LIDAR_RAYS,
                    max_range=self.lidar_range, entity_filter=is_agent,
                )]
            world.add_agent(Agent(
                name=f"agent_{i}", render_action=True, collide=self.collisions,
                shape=Sphere(radius=self.agent_radius), sensors=sensors,
            ))
        self._index = {agent.name: i for i, agent in enumerate(world.agents)}

        device = world.device
        self._variance = torch.tensor(self.variances, device=device)  # [G]
        self._half_cells = torch.tensor([self.n_x_cells / 2, self.n_y_cells / 2], device=device)
        self._semidims = torch.tensor([self.x_semidim, self.y_semidim], device=device)
        self._dims = torch.tensor([float(self.xdim), float(self.ydim)], device=device)
        self._neighbours = torch.tensor(NEIGHBOURS, device=device, dtype=torch.float32) * self.grid_spacing  # [8, 2]
        # grid points of the normaliser: cell corners from (-xdim, -ydim), clamped into the semidims
        self._grid_x = torch.arange(-self.xdim, self.xdim, self.grid_spacing, device=device)
        self._grid_y = torch.arange(-self.ydim, self.ydim, self.grid_spacing, device=device)
        self._grid_x = self._grid_x.clamp(-self.x_semidim, self.x_semidim)
        self._grid_y = self._grid_y.clamp(-self.y_semidim, self.y_semidim)

        #: per env, the Gaussians' centres [B, G, 2]
        self.locs = torch.zeros(batch_dim, self.n_gaussians, world.dim_p, device=device)
        #: per env, the field's largest value over the grid points [B] (the normaliser)
        self.max_pdf = torch.ones(batch_dim, device=device)
        #: per env, the spent cells [B, n_x_cells, n_y_cells] (x index first)
        self.sampled = torch.zeros(batch_dim, self.n_x_cells, self.n_y_cells, dtype=torch.bool, device=device)
        #: per env, every agent's last sample [B, n_agents]
        self.samples = torch.zeros(batch_dim, self.n_agents, device=device)
        return world

    # ------------------------------------------------------------------- field
    def density(self, pos: Tensor, locs: Tensor) -> Tensor:
        """The field at ``pos`` [R, K, 2] for envs whose centres are ``locs`` [R, G, 2]: [R, K]."""
        offset = pos.unsqueeze(2) - locs.unsqueeze(1)  # [R, K, G, 2]
        squared = (offset * offset).sum(-1)
        return (torch.exp(-0.5 * squared / self._variance) / (2 * math.pi * self._variance)).sum(-1)

    def grid_maximum(self, locs: Tensor) -> Tensor:
        """The field's largest value over the normaliser's grid points, [R] for ``locs`` [R, G, 2].

        An isotropic Gaussian factorises over x and y, so the whole grid is one
        product of per-axis factors ([R, G, nx] x [R, G, ny]) rather than
        ``nx * ny`` separate evaluations.
        """
        variance = self._variance.view(1, -1, 1)
        along_x = torch.exp(-0.5 * (self._grid_x - locs[..., 0:1]) ** 2 / variance)  # [R, G, nx]
        along_y = torch.exp(-0.5 * (self._grid_y - locs[..., 1:2]) ** 2 / variance)
        field = torch.einsum("rgx,rgy->rxy", along_x / (2 * math.pi * variance), along_y)
        return field.flatten(1).amax(dim=1)

    def probe(self, pos: Tensor, normalise: bool, envs=slice(None)) -> tuple[Tensor, Tensor]:
        """What sampling at ``pos`` [R, K, 2] would pay, [R, K], and the flat cell index there, [R, K].

        ``envs`` selects the R envs (default: all). Points outside the square
        pay 0; others are clamped into the semidims first (the cell and the
        field are read there); a spent cell pays 0.
        """
        outside = (pos.abs() > self._dims).any(dim=-1)
        pos = torch.maximum(torch.minimum(pos, self._semidims), -self._semidims)
        index = (pos / self.grid_spacing + self._half_cells).long()  # truncation, as a cast does
        cell = index[..., 0] * self.n_y_cells + index[..., 1]
        value = self.density(pos, self.locs[envs])
        if normalise:
            value = value / self.max_pdf[envs].unsqueeze(-1)
        spent = torch.gather(self.sampled[envs].flatten(1), 1, cell)
        return torch.where(spent | outside, 0.0, value), cell

    # ------------------------------------------------------------------- reset
    def reset_world_at(self, env_index=None) -> None:
        world = self.world
        rows = selected_rows(world.batch_dim, env_index)
        dims = self._dims
        locs = (torch.rand(rows, self.n_gaussians, world.dim_p, device=world.device) * 2 - 1) * dims
        spawn = dims if not self.spawn_same_pos else torch.zeros_like(dims)
        starts = (torch.rand(rows, self.n_agents, world.dim_p, device=world.device) * 2 - 1) * spawn
        starts = torch.maximum(torch.minimum(starts, self._semidims), -self._semidims)
        for i, agent in enumerate(world.agents):
            agent.set_pos(for_index(starts[:, i], env_index), batch_index=env_index)
        if env_index is None:
            self.locs = locs
            self.max_pdf = self.grid_maximum(locs)
            self.sampled = torch.zeros_like(self.sampled)
            self.samples = self._fresh_samples(starts, locs, self.max_pdf)
        else:
            max_pdf = self.grid_maximum(locs)
            self.locs[env_index] = for_index(locs, env_index)
            self.max_pdf[env_index] = for_index(max_pdf, env_index)
            self.sampled[env_index] = False
            self.samples[env_index] = for_index(self._fresh_samples(starts, locs, max_pdf), env_index)

    def _fresh_samples(self, starts: Tensor, locs: Tensor, max_pdf: Tensor) -> Tensor:
        """Each agent's sample at its start, no cell spent yet: [R, n_agents]."""
        value = self.density(starts, locs)
        return value / max_pdf.unsqueeze(-1) if self.norm else value

    # ------------------------------------------------------------------ reward
    def _sample_all(self) -> None:
        """Agents sample in order, each spending its cell before the next samples."""
        rows = torch.arange(self.world.batch_dim, device=self.world.device)
        spent = self.sampled.view(self.world.batch_dim, -1)
        samples = []
        for agent in self.world.agents:
            value, cell = self.probe(agent.state.pos.unsqueeze(1), self.norm)
            spent[rows, cell[:, 0]] = True
            samples.append(value[:, 0])
        self.samples = torch.stack(samples, dim=1)

    def reward(self, agent: Agent) -> Tensor:
        i = self._index[agent.name]
        if i == 0:
            self._sample_all()
            self._team_reward = self.samples.sum(dim=1)
        return self._team_reward if self.shared_rew else self.samples[:, i]

    # ------------------------------------------------------------- observation
    def observation(self, agent: Agent) -> Tensor:
        parts = [agent.state.pos, agent.state.vel]
        if self.collisions:
            parts.append(agent.sensors[0].measure())
        around, _ = self.probe(agent.state.pos.unsqueeze(1) + self._neighbours, normalise=True)
        parts.append(around)
        return torch.cat(parts, dim=-1)

    def info(self, agent: Agent) -> dict:
        return {"agent_sample": self.samples[:, self._index[agent.name]]}

    def extra_render(self, env_index: int = 0) -> list:
        """The unspent field of env ``env_index``, links between agents within ``comms_range``, the walls."""
        from vmas_ros.simulator import rendering
        from vmas_ros.simulator.utils import Color

        def unspent(points) -> Tensor:
            pos = torch.as_tensor(points, dtype=torch.float32, device=self.world.device).unsqueeze(0)
            return self.probe(pos, normalise=True, envs=slice(env_index, env_index + 1))[0][0]

        geoms = [rendering.render_function_util(unspent, plot_range=(self.xdim, self.ydim), cmap_alpha=0.5)]
        geoms += range_links(self.world.agents, env_index, self.comms_range)
        x, y = self.xdim, self.ydim
        walls = rendering.make_polygon([(-x, -y), (x, -y), (x, y), (-x, y)], filled=False)
        walls.set_color(*Color.BLACK.value)
        geoms.append(walls)
        return geoms


class HeuristicPolicy(BaseHeuristicPolicy):
    """Climb towards the richest unspent neighbour cell; keep going when nothing is left nearby.

    Reads only the agent's observation: the 8 neighbour values give a local
    gradient of what is still to collect (each direction weighted by its
    value, the diagonals by 1/sqrt(2)), and the agent pushes that way. When
    all 8 are 0 (everything around is spent or outside), it keeps its current
    heading (a velocity feed-forward) and is turned back from the walls, so it
    sweeps on to fresh ground instead of stopping. With ``collisions`` a
    short lidar reading pushes it away from the agent it sees.
    Continuous actions only.
    """

    gradient_gain = 4.0  # force per unit of normalised neighbour value
    cruise_gain = 3.0  # force along the current heading, per m/s, when nothing is around
    cruise_floor = 0.6  # force along +x (then the walls turn it) when at rest with nothing around
    wall_margin = 0.1
    avoid_gain = 2.0

    def __init__(self, continuous_action: bool = True, **scenario_kwargs) -> None:
        super().__init__(continuous_action)
        config = continuous_heuristic_kwargs("sampling", DEFAULTS, scenario_kwargs, continuous_action)
        validate(config)
        self.lidar_rays = N_LIDAR_RAYS if config["collisions"] else 0
        self.lidar_range = config["lidar_range"]
        self.bounds = (config["xdim"] - config["agent_radius"], config["ydim"] - config["agent_radius"])
        directions = torch.tensor(NEIGHBOURS, dtype=torch.float32)
        self._directions = directions / directions.norm(dim=-1, keepdim=True) ** 2  # diagonals weigh 1/sqrt(2)
        angles = LIDAR_START + torch.arange(N_LIDAR_RAYS) * (2 * math.pi / N_LIDAR_RAYS)
        self._rays = torch.stack([angles.cos(), angles.sin()], dim=-1)

    def compute_action(self, observation: Tensor, u_range: float) -> Tensor:
        width = 4 + self.lidar_rays + len(NEIGHBOURS)
        if observation.shape[-1] != width:
            raise ValueError(f"sampling heuristic: expected observation width {width}, got {observation.shape[-1]}")
        device = observation.device
        pos, vel = observation[:, 0:2], observation[:, 2:4]
        around = observation[:, -len(NEIGHBOURS):]
        gradient = around @ self._directions.to(device)
        speed = vel.norm(dim=-1, keepdim=True)
        heading = torch.where(speed > 1e-3, vel / speed.clamp_min(1e-6), torch.tensor([1.0, 0.0], device=device))
        cruise = heading * torch.maximum(self.cruise_gain * speed, torch.full_like(speed, self.cruise_floor))
        nothing_near = (around.amax(dim=-1, keepdim=True) <= 0)
        action = torch.where(nothing_near, cruise, self.gradient_gain * gradient)
        # walls: push back in where the agent is within the margin of a semidim
        bounds = torch.tensor(self.bounds, device=device)
        action = action - ((pos.abs() - (bounds - self.wall_margin)).clamp_min(0.0) / self.wall_margin) * pos.sign()
        if self.lidar_rays:
            lidar = observation[:, 4:4 + self.lidar_rays]
            closeness = ((self.lidar_range - lidar) / self.lidar_range).clamp_min(0.0)
            action = action - self.avoid_gain * closeness @ self._rays.to(device)
        return action.clamp(-u_range, u_range)
