"""discovery: agents find targets with their lidars and cover each one together.

Description
    ``n_agents`` blue discs (radius 0.05) and ``n_targets`` static green
    discs (radius 0.05) inside walls at ``+-x_semidim``, ``+-y_semidim``. A
    target is covered when at least ``agents_per_target`` agents have their
    centres within ``covering_range`` of its centre. Agents see targets only
    through a lidar (``n_lidar_rays_entities`` rays, range ``lidar_range``)
    and, with ``use_agent_lidar``, each other through a second lidar
    (``n_lidar_rays_agents`` rays starting at 0.05 rad). Paper, "Multi-robot
    scenarios": a variation of the Stick Pulling Experiment.
Observation (per agent, in this order)
    own position (2), own velocity (2), target lidar distances
    (``n_lidar_rays_entities``, ray ``k`` at ``2 pi k / n``), then with
    ``use_agent_lidar`` the agent lidar distances (``n_lidar_rays_agents``,
    ray ``k`` at ``0.05 + 2 pi k / n``). A ray that hits nothing reads
    ``lidar_range``.
Reward
    Each agent earns ``covering_rew_coeff`` per covered target it is within
    ``covering_range`` of (with ``shared_reward``, every agent earns the
    team's total halved instead), ``agent_collision_penalty`` per other
    agent whose surface is closer than 0.005, and ``time_penalty`` every step.
Starting state
    Targets then agents uniform in the arena, every two at least
    ``min_dist_between_entities`` apart. After the rewards of a step, each
    covered target moves: with ``targets_respawn`` to a fresh uniform spot
    ``min_dist_between_entities`` clear of the agents and the other targets;
    without, far outside the arena, for good.
Differences from VMAS 1.5.2 (on purpose)
    A respawned target's new spot is drawn our own way (batched over the
    envs with a covered target), so with ``targets_respawn`` the spots, and
    what follows from them, differ from VMAS's after the first cover.
Episode termination
    Without ``targets_respawn``: when every target has been covered. With
    it, never (set ``max_steps``).
Info (per agent)
    ``covering_reward`` (the covering term of its reward), ``collision_rew``
    and ``targets_covered`` (how many targets were covered this step, per env).
Kwargs
    ``n_agents`` (5), ``n_targets`` (7), ``x_semidim`` (1), ``y_semidim`` (1),
    ``min_dist_between_entities`` (0.2), ``lidar_range`` (0.35),
    ``covering_range`` (0.25), ``use_agent_lidar`` (False),
    ``n_lidar_rays_entities`` (15), ``n_lidar_rays_agents`` (12),
    ``agents_per_target`` (2), ``targets_respawn`` (True), ``shared_reward``
    (False), ``agent_collision_penalty`` (0), ``covering_rew_coeff`` (1.0),
    ``time_penalty`` (0).
"""
from __future__ import annotations

import itertools
import math
from typing import Optional, Sequence

import torch
from torch import Tensor

from vmas_ros.scenarios.common import (
    configure, for_index, pair_distances, range_links, sample_clear_positions, selected_rows,
)
from vmas_ros.simulator.masks import mask_ge, mask_lt
from vmas_ros.simulator.core import Agent, Landmark, Sphere, World
from vmas_ros.simulator.heuristic_policy import BaseHeuristicPolicy
from vmas_ros.simulator.scenario import BaseScenario
from vmas_ros.simulator.sensors import Lidar
from vmas_ros.simulator.utils import Color

#: name -> default of every kwarg (the heuristic reads the observation-layout ones too)
DEFAULTS = {
    "n_agents": 5, "n_targets": 7, "x_semidim": 1, "y_semidim": 1, "min_dist_between_entities": 0.2,
    "lidar_range": 0.35, "covering_range": 0.25, "use_agent_lidar": False, "n_lidar_rays_entities": 15,
    "n_lidar_rays_agents": 12, "agents_per_target": 2, "targets_respawn": True, "shared_reward": False,
    "agent_collision_penalty": 0, "covering_rew_coeff": 1.0, "time_penalty": 0,
}
AGENT_RADIUS = TARGET_RADIUS = 0.05
COLLISION_DISTANCE = 0.005  # surface gap below which two agents count as colliding
AGENT_LIDAR_START = 0.05  # the agent lidar's first ray, in radians
TARGET_COLOR = Color.GREEN


def is_target(entity) -> bool:
    """The target lidar's filter."""
    return entity.name.startswith("target")


def is_agent(entity) -> bool:
    """The agent lidar's filter."""
    return entity.name.startswith("agent")


#: candidate points drawn per env and step for respawns, shared by all its targets (see respawn_clear)
RESPAWN_CANDIDATES = 16


class Scenario(BaseScenario):
    supports_batched_reset = True

    def make_world(self, batch_dim: int, device, **kwargs) -> World:
        configure(self, kwargs, DEFAULTS, _validate)
        self.viewer_zoom = 1

        world = World(
            batch_dim, device, x_semidim=self.x_semidim, y_semidim=self.y_semidim,
            collision_force=500, substeps=2, drag=0.25,
        )
        for i in range(self.n_agents):
            sensors = [Lidar(
                world, n_rays=self.n_lidar_rays_entities, max_range=self.lidar_range,
                entity_filter=is_target, render_color=Color.GREEN,
            )]
            if self.use_agent_lidar:
                sensors.append(Lidar(
                    world, angle_start=AGENT_LIDAR_START, angle_end=2 * math.pi + AGENT_LIDAR_START,
                    n_rays=self.n_lidar_rays_agents, max_range=self.lidar_range,
                    entity_filter=is_agent, render_color=Color.BLUE,
                ))
            world.add_agent(Agent(name=f"agent_{i}", collide=True, shape=Sphere(radius=AGENT_RADIUS), sensors=sensors))
        self.targets: list[Landmark] = []
        for i in range(self.n_targets):
            target = Landmark(
                name=f"target_{i}", collide=True, movable=False, shape=Sphere(radius=TARGET_RADIUS),
                color=TARGET_COLOR,
            )
            world.add_landmark(target)
            self.targets.append(target)

        self._index = {agent.name: i for i, agent in enumerate(world.agents)}
        #: per env and target: covered at some step of this episode (only grows without respawns) [B, T]
        self.all_time_covered = torch.zeros(batch_dim, self.n_targets, dtype=torch.bool, device=device)
        #: per env and target: covered at the last reward [B, T]
        self.covered_targets = torch.zeros(batch_dim, self.n_targets, dtype=torch.bool, device=device)
        #: per agent and env: the last reward's terms [N, B] (agent-major); the team's covering reward [B]
        self.covering_rew = torch.zeros(self.n_agents, batch_dim, device=device)
        self.collision_rew = torch.zeros(self.n_agents, batch_dim, device=device)
        self.shared_covering_rew = torch.zeros(batch_dim, device=device)
        return world

    # ------------------------------------------------------------------- reset
    def reset_world_at(self, env_index=None) -> None:
        world = self.world
        if env_index is None:
            self.all_time_covered = torch.zeros_like(self.all_time_covered)
        else:
            self.all_time_covered[env_index] = False
        placed = self.targets + world.agents
        bounds = (-self.x_semidim, self.x_semidim), (-self.y_semidim, self.y_semidim)
        none_yet = torch.zeros(selected_rows(world.batch_dim, env_index), 0, world.dim_p, device=world.device)
        positions = sample_clear_positions(none_yet, len(placed), self.min_dist_between_entities, *bounds)
        for k, entity in enumerate(placed):
            entity.set_pos(for_index(positions[:, k], env_index), batch_index=env_index)

    # ------------------------------------------------------------------ reward
    def batched_outputs(self, q: Tensor, v: Tensor) -> tuple[Tensor, Tensor, Tensor, Tensor]:
        """The reward terms of the state ``q`` ``[3, T + N, B]`` (targets first): see :func:`reward_terms`."""
        return reward_terms(q[0], q[1], self.n_targets, self.covering_range, self.agents_per_target,
                            self.covering_rew_coeff, self.agent_collision_penalty)

    def _update_rewards(self) -> None:
        """Keep the reward terms of the state being rewarded.

        The respawn then moves the world to a new state, whose outputs differ:
        the respawn itself and ``info`` need the terms of the state the
        rewards were computed for, so they read these attributes.
        """
        covered, self.covering_rew, self.shared_covering_rew, self.collision_rew = self.outputs()
        self.covered_targets = covered.T  # [B, T]

    def _move_covered_targets(self) -> None:
        """Respawn (or retire) the targets covered this step; runs after every agent's reward.

        Plain tensor code, not an output: it writes the state (and draws random numbers).
        """
        covered = self.covered_targets.T  # [T, B]
        x, y = self.world.stacked_xy("pos")  # targets are the landmarks, the first rows
        n_targets = len(self.targets)
        if self.targets_respawn:
            # respawn_clear; every env draws its candidates every step, so seeded runs repeat exactly
            cand_x, cand_y = draw_candidates(x.shape[1], self.x_semidim, self.y_semidim, RESPAWN_CANDIDATES, x.device)
            new_x, new_y = respawn_from(cand_x, cand_y, x[n_targets:], y[n_targets:], x[:n_targets], y[:n_targets],
                                        covered, self.min_dist_between_entities ** 2)
        else:
            self.all_time_covered = self.all_time_covered | self.covered_targets
            outside = self._outside_positions(covered.shape)  # [T, B, 2]
            new_x = torch.where(covered, outside[..., 0], x[:n_targets])
            new_y = torch.where(covered, outside[..., 1], y[:n_targets])
        # all targets in one write into the world's state (they are its first rows)
        self.world.set_positions(self.targets, new_x, new_y)

    def _outside_positions(self, shape) -> Tensor:
        """Far outside the arena, where no lidar or agent reaches: both coordinates in [-1000, -10] x x_semidim."""
        return torch.empty(*shape, self.world.dim_p, device=self.world.device).uniform_(
            -1000 * self.x_semidim, -10 * self.x_semidim,
        )

    def reward(self, agent: Agent) -> Tensor:
        i = self._index[agent.name]
        if i == 0:
            self._update_rewards()
        covering = self.shared_covering_rew if self.shared_reward else self.covering_rew[i]
        rew = self.collision_rew[i] + covering + self.time_penalty
        if i == self.n_agents - 1:
            self._move_covered_targets()
        return rew

    # ------------------------------------------------------------- observation
    def observation(self, agent: Agent) -> Tensor:
        readings = [sensor.measure() for sensor in agent.sensors]
        return torch.cat([agent.state.pos, agent.state.vel] + readings, dim=-1)

    def info(self, agent: Agent) -> dict[str, Tensor]:
        i = self._index[agent.name]
        return {
            "covering_reward": self.shared_covering_rew if self.shared_reward else self.covering_rew[i],
            "collision_rew": self.collision_rew[i],
            "targets_covered": self.covered_targets.sum(dim=-1),
        }

    def done(self) -> Tensor:
        return self.all_time_covered.all(dim=-1)

    def extra_render(self, env_index: int = 0) -> list:
        from vmas_ros.simulator import rendering

        geoms = []
        for target in self.targets:
            ring = rendering.make_circle(self.covering_range, filled=False)
            xform = rendering.Transform()
            xform.set_translation(*target.state.pos[env_index].tolist())
            ring.add_attr(xform)
            ring.set_color(*TARGET_COLOR.value)
            geoms.append(ring)
        # lines between agents within lidar range of each other (VMAS calls it the comms range)
        return geoms + range_links(self.world.agents, env_index, self.lidar_range)


def reward_terms(
    x: Tensor, y: Tensor, n_targets: int, covering_range: float, agents_per_target: int, covering_coeff: float,
    collision_penalty: float,
) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    """Covered targets ``[T, B]`` (bool), covering rewards ``[N, B]``, the team's ``[B]`` and collision penalties ``[N, B]``.

    From the planar rows ``x``, ``y`` ``[T + N, B]`` (targets first). What
    ``Scenario.batched_outputs`` computes: a pure function of the positions.
    Distances are ``[agents, targets, envs]`` and every count is a reduction
    over a leading dim (a norm or a sum over a small trailing dim is a slow
    path on the CPU); terms are agent-major, so each agent's reward is a row.
    """
    tx, ty, ax, ay = x[:n_targets], y[:n_targets], x[n_targets:], y[n_targets:]
    near = pair_distances(ax, ay, tx, ty) < covering_range  # [N, T, B]
    covered = near.sum(dim=0) >= agents_per_target  # [T, B]
    covering = (near & covered).sum(dim=1).float() * covering_coeff  # [N, B]
    team = covering.sum(dim=0)
    shared = torch.where(team != 0, team / 2, team)  # halved, as in VMAS 1.5
    gap = pair_distances(ax, ay, ax, ay) - 2 * AGENT_RADIUS  # [N, N, B]
    not_self = ~torch.eye(ax.shape[0], dtype=torch.bool, device=x.device).unsqueeze(-1)  # [N, N, 1]
    touching = (gap < COLLISION_DISTANCE) & not_self
    return covered, covering, shared, touching.sum(dim=1).float() * collision_penalty


def respawn_clear(
    agents_x: Tensor, agents_y: Tensor, targets_x: Tensor, targets_y: Tensor, covered: Tensor,
    min_dist: float, x_semidim: float, y_semidim: float, candidates: int,
) -> tuple[Tensor, Tensor]:
    """New target positions ``(x, y)``, each ``[T, B]``: covered targets moved, the others kept.

    Inputs are planar rows: agents ``[N, B]``, targets ``[T, B]``, ``covered``
    ``[T, B]`` (bool). Targets move in order; target ``i`` lands on a uniform
    spot in the arena ``min_dist`` clear of every agent, of the new spots of
    targets before it and of the current spots of the targets after it (the
    order VMAS moves them in).

    Why it is fast: each env draws one stream of ``candidates`` uniform
    points per step, shared by all its targets, instead of a set per target
    (covering is rare, so most draws would go unused). Target ``i`` takes the
    first clear point *after* the last point an earlier target took: points it
    scans were never looked at before, so this is exact rejection sampling.
    Distances to the agents are computed once for all targets, the targets
    after ``i`` enter through one suffix minimum, and those before through a
    running minimum, so each target costs a dozen ops over ``[B, candidates]``.
    A covered target that finds no clear point in the rest of the stream
    (probability about ``0.35 ** 16`` at the default density) stays for a step
    and respawns on the next one, when it is still covered.
    """
    cand_x, cand_y = draw_candidates(targets_x.shape[1], x_semidim, y_semidim, candidates, targets_x.device)
    return respawn_from(cand_x, cand_y, agents_x, agents_y, targets_x, targets_y, covered, min_dist * min_dist)


def draw_candidates(batch: int, x_semidim: float, y_semidim: float, candidates: int, device) -> tuple[Tensor, Tensor]:
    """Each env's stream of ``candidates`` uniform points in the arena, ``(x, y)`` each ``[K, B]``."""
    # candidates [K, B]: every reduction of respawn_from runs over the leading dim, across contiguous
    # env rows (a reduction over a small trailing dim is a slow path on the CPU)
    cand_x = torch.empty(candidates, batch, device=device).uniform_(-x_semidim, x_semidim)
    cand_y = torch.empty(candidates, batch, device=device).uniform_(-y_semidim, y_semidim)
    return cand_x, cand_y


def respawn_from(
    cand_x: Tensor, cand_y: Tensor, agents_x: Tensor, agents_y: Tensor, targets_x: Tensor, targets_y: Tensor,
    covered: Tensor, limit: float, only_covered_envs: Optional[bool] = None,
) -> tuple[Tensor, Tensor]:
    """:func:`respawn_clear` given the candidate stream ``[K, B]`` and the squared clearance ``limit``.

    ``only_covered_envs`` (default: on the CPU) runs :func:`respawn_every_env`
    on just the envs with a covered target: covering is rare, so a few envs a
    step, often none. Finding them reads the mask, which costs nothing on the
    CPU but would make a GPU step wait. Each env's result depends on its own
    column alone, so the bits are the same either way.
    """
    if only_covered_envs is None:
        only_covered_envs = covered.device.type == "cpu"
    if not only_covered_envs:
        return respawn_every_env(cand_x, cand_y, agents_x, agents_y, targets_x, targets_y, covered, limit)
    envs = covered.any(dim=0).nonzero().squeeze(1)  # [M]
    new_x, new_y = targets_x.clone(), targets_y.clone()
    if len(envs) > 0:
        columns = [t.index_select(1, envs) for t in (cand_x, cand_y, agents_x, agents_y, targets_x, targets_y, covered)]
        moved_x, moved_y = respawn_every_env(*columns, limit, searched=columns[-1].any(dim=1).tolist())
        new_x.index_copy_(1, envs, moved_x)
        new_y.index_copy_(1, envs, moved_y)
    return new_x, new_y


def respawn_every_env(
    cand_x: Tensor, cand_y: Tensor, agents_x: Tensor, agents_y: Tensor, targets_x: Tensor, targets_y: Tensor,
    covered: Tensor, limit: float, searched: Optional[Sequence[bool]] = None,
) -> tuple[Tensor, Tensor]:
    """:func:`respawn_from` computed for every env (column) at once. Masks are float 0/1.

    ``searched``: per target, False where the caller knows it is covered in no
    env; it then stays without a search for its spot (None: search for all).
    """
    n_targets, batch = targets_x.shape
    candidates = cand_x.shape[0]
    device = targets_x.device
    searched = [True] * n_targets if searched is None else list(searched)
    last = max((i for i in range(n_targets) if searched[i]), default=-1)  # the last target that may move

    def squared_gaps(px: Tensor, py: Tensor) -> Tensor:  # points [M, B] -> [M, K, B]
        gap_x, gap_y = cand_x - px.unsqueeze(1), cand_y - py.unsqueeze(1)
        return torch.addcmul(gap_x * gap_x, gap_y, gap_y)

    # a point's weight falls along the stream, so the first clear point has the largest weighted mask
    weights = torch.arange(candidates, 0, -1, device=device, dtype=cand_x.dtype).unsqueeze(1)  # [K, 1]
    free = weights.expand(candidates, batch) if agents_x.shape[0] == 0 else \
        mask_ge(squared_gaps(agents_x, agents_y).amin(dim=0), limit).mul_(weights)
    to_targets = squared_gaps(targets_x, targets_y)  # [T, K, B] to the current spots
    after = [None] * (n_targets + 1)  # after[i]: nearest current spot among targets i+1..
    for i in range(n_targets - 2, -1, -1):
        after[i] = to_targets[i + 1] if after[i + 1] is None else torch.minimum(after[i + 1], to_targets[i + 1])
    before = None  # nearest new spot among the targets moved so far
    bound = torch.full((1, batch), candidates + 1.0, device=device)  # eligible: weight < bound
    new_x, new_y = [], []
    for i in range(n_targets):
        if searched[i]:
            near = after[i] if before is None else before if after[i] is None else torch.minimum(before, after[i])
            eligible = free * mask_lt(weights, bound)
            if near is not None:
                eligible = eligible.mul_(mask_ge(near, limit))
            score = eligible.amax(dim=0, keepdim=True)  # [1, B]: the first clear point's weight, 0 if none
            moved = (score > 0) & covered[i : i + 1]  # [1, B] bool: where on one row is cheap
            first = (candidates - score).clamp_(max=candidates - 1).long()
            x = torch.where(moved, cand_x.gather(0, first), targets_x[i : i + 1])
            y = torch.where(moved, cand_y.gather(0, first), targets_y[i : i + 1])
            if i < last:
                gaps, bound = squared_gaps(x, y)[0], torch.where(moved, score, bound)
        else:  # it stays at its current spot
            x, y, gaps = targets_x[i : i + 1], targets_y[i : i + 1], to_targets[i]
        new_x.append(x)
        new_y.append(y)
        if i < last:  # the searches still to come keep clear of its spot
            before = gaps if before is None else torch.minimum(before, gaps)
    return torch.cat(new_x), torch.cat(new_y)


def _validate(config: dict) -> None:
    """Raise ValueError naming the first kwarg whose value cannot work."""
    for name in ("n_agents", "n_targets", "n_lidar_rays_entities", "n_lidar_rays_agents", "agents_per_target"):
        if not isinstance(config[name], int) or isinstance(config[name], bool) or config[name] < 1:
            raise ValueError(f"discovery: {name} must be an int >= 1, got {config[name]!r}")
    for name in ("x_semidim", "y_semidim", "lidar_range", "covering_range"):
        if not config[name] > 0:
            raise ValueError(f"discovery: {name} must be > 0, got {config[name]!r}")
    if not config["min_dist_between_entities"] >= 0:
        raise ValueError(
            f"discovery: min_dist_between_entities must be >= 0, got {config['min_dist_between_entities']!r}"
        )


class HeuristicPolicy(BaseHeuristicPolicy):
    """Sweep the arena along one shared loop; turn towards the nearest target seen; move on if alone.

    * sweep: with no target in lidar range, follow a closed lawnmower loop
      (``sweep_loop``): rows ``row_spacing`` apart, alternately left to right
      and back, then a return lane up the left wall. The agent heads for the
      loop point ``lookahead`` samples past its nearest one. All agents share
      the loop, so a target one agent found is soon passed by another, which
      is what covering (two agents) needs, and the rows bring every spot of
      the arena within about 0.25 of some agent's path;
    * target: when a target ray reads less than the range, add a pull of
      ``target_pull`` towards the shortest ray. It is weaker than the sweep
      push, so an agent alone at a target lingers beside it, then moves on
      instead of waiting forever (all agents waiting at different targets
      would stall the team);
    * spread (only with ``use_agent_lidar``): with no target in sight, step
      away from an agent closer than ``spread_range``.

    The observation layout and the loop depend on the scenario's kwargs, so
    the policy takes them (defaults match the scenario's). ``use_agent_lidar``
    left as None is read from the observation's width, as VMAS's heuristic
    is built without kwargs.
    """

    row_spacing = 0.5
    lookahead = 8
    target_pull = 0.9
    spread_range = 0.15
    spread_gain = 1.0

    def __init__(
        self,
        continuous_action: bool = True,
        n_lidar_rays_entities: int = DEFAULTS["n_lidar_rays_entities"],
        n_lidar_rays_agents: int = DEFAULTS["n_lidar_rays_agents"],
        use_agent_lidar: Optional[bool] = None,
        lidar_range: float = DEFAULTS["lidar_range"],
        x_semidim: float = DEFAULTS["x_semidim"],
        y_semidim: float = DEFAULTS["y_semidim"],
    ) -> None:
        super().__init__(continuous_action)
        rays = {"n_lidar_rays_entities": n_lidar_rays_entities, "n_lidar_rays_agents": n_lidar_rays_agents}
        for name, value in rays.items():
            if not isinstance(value, int) or value < 1:
                raise ValueError(f"discovery heuristic: {name} must be an int >= 1, got {value!r}")
        self.n_target_rays, self.n_agent_rays = n_lidar_rays_entities, n_lidar_rays_agents
        self.use_agent_lidar, self.lidar_range = use_agent_lidar, lidar_range
        self._target_rays = _ray_directions(n_lidar_rays_entities, 0.0)
        self._agent_rays = _ray_directions(n_lidar_rays_agents, AGENT_LIDAR_START)
        self.loop = sweep_loop(x_semidim, y_semidim, self.row_spacing)

    def compute_action(self, observation: Tensor, u_range: float) -> Tensor:
        widths = {False: 4 + self.n_target_rays, True: 4 + self.n_target_rays + self.n_agent_rays}
        agent_lidar = self.use_agent_lidar
        if agent_lidar is None:  # read from the layout
            agent_lidar = observation.shape[-1] == widths[True]
        if observation.shape[-1] != widths[agent_lidar]:
            expected = widths[agent_lidar] if self.use_agent_lidar is not None else " or ".join(map(str, widths.values()))
            raise ValueError(f"discovery heuristic: expected observation width {expected}, got {observation.shape[-1]}")
        if self.loop.device != observation.device:  # move the tables once, not every step
            self.loop = self.loop.to(observation.device)
            self._target_rays = self._target_rays.to(observation.device)
            self._agent_rays = self._agent_rays.to(observation.device)
        pos, loop = observation[:, :2], self.loop
        nearest_point = torch.cdist(pos, loop).argmin(dim=-1)
        action = _unit(loop[(nearest_point + self.lookahead) % len(loop)] - pos)
        targets = observation[:, 4:4 + self.n_target_rays]
        nearest, ray = targets.min(dim=-1)
        seen = (nearest < self.lidar_range - 1e-4).unsqueeze(-1)
        action = action + self.target_pull * seen * self._target_rays[ray]
        if agent_lidar:
            agents = observation[:, 4 + self.n_target_rays:]
            closest, agent_ray = agents.min(dim=-1)
            crowded = (~seen) & (closest < self.spread_range).unsqueeze(-1)
            action = action - self.spread_gain * crowded * self._agent_rays[agent_ray]
        return (action * u_range).clamp(-u_range, u_range)


def sweep_loop(x_semidim: float, y_semidim: float, row_spacing: float, step: float = 0.02) -> Tensor:
    """Points [P, 2], ``step`` apart, along a closed lawnmower loop over the arena.

    An even number of rows at most ``row_spacing`` apart runs between
    ``x = -x_semidim + 0.3`` and ``x = x_semidim - 0.1``, starting at the top
    left and going right; after the bottom row the loop runs left along it
    to ``x = -x_semidim + 0.08`` and back up that lane (clear of the row
    turns) to the start.
    """
    n_rows = 2 * max(1, math.ceil(y_semidim / row_spacing))
    rows = [y_semidim - 2 * y_semidim * (k + 0.5) / n_rows for k in range(n_rows)]
    left, right, lane = -x_semidim + 0.3, x_semidim - 0.1, -x_semidim + 0.08
    corners = []
    for k, y in enumerate(rows):
        ends = (left, right) if k % 2 == 0 else (right, left)
        corners += [(ends[0], y), (ends[1], y)]
    corners += [(lane, rows[-1]), (lane, rows[0]), (left, rows[0])]
    points = []
    for start, end in itertools.pairwise(corners):
        start, end = torch.tensor(start), torch.tensor(end)
        pieces = max(1, round(float(torch.linalg.vector_norm(end - start)) / step))
        points.append(start + (end - start) * torch.arange(pieces).unsqueeze(-1) / pieces)
    return torch.cat(points)


def _unit(vectors: Tensor) -> Tensor:
    return vectors / torch.linalg.vector_norm(vectors, dim=-1, keepdim=True).clamp_min(1e-6)


def _ray_directions(n_rays: int, start: float) -> Tensor:
    """Unit vectors [n_rays, 2] of a full-circle lidar whose first ray is at ``start``."""
    angles = start + torch.arange(n_rays) * (2 * math.pi / n_rays)
    return torch.stack([angles.cos(), angles.sin()], dim=-1)
