"""navigation: every agent drives to its own goal without bumping into the others.

Description
    ``n_agents`` discs (radius ``agent_radius``) and as many goal marks
    (non-colliding discs of radius 0.05, one per agent, in the agent's
    colour) in an unbounded plane, or inside walls
    at ``+-world_spawning_x``/``+-world_spawning_y`` with ``enforce_bounds``.
    Each agent must reach its goal; with ``collisions`` the agents collide
    with one another and carry a lidar (``n_lidar_rays`` rays evenly round
    the circle, range ``lidar_range``) that sees the other agents. Goals may
    be shared: with ``agents_with_same_goal = k`` the first ``k`` agents go to
    one goal (then ``collisions`` must be off); with ``split_goals`` the first
    and the second half of the team each share one goal. This is the
    navigation task of the VMAS paper (and of the BenchMARL/TorchRL tutorials).
Dynamics
    ``dynamics="holonomic"`` (VMAS's task): force actions in [-1, 1] along
    the world axes; the agents never turn. ``dynamics="diff_drive"``: the
    engine's ``DiffDrive`` (unicycle) model, actions (forward speed in
    [-max_speed, max_speed] m/s, turn rate in [-max_turn_rate,
    max_turn_rate] rad/s), the ``cmd_vel`` of a wheeled ROS base; the agents
    turn, and their lidar turns with them (its ray angles are relative to the
    agent's heading). These agents have no drag, so they move at the
    commanded speed and turn rate, as a base under its wheel controller does.
Observation (per agent, in this order)
    own position (2), own velocity (2); with ``diff_drive``, the cosine and
    sine of its heading (2); its position minus its goal's (2) or,
    with ``observe_all_goals``, its position minus every agent's goal in agent
    order (2 x n_agents); with ``collisions``, the lidar's proximities
    ``lidar_range - distance`` (``n_lidar_rays``; 0 where a ray hits nothing,
    ray ``k`` at angle ``2 pi k / n_lidar_rays``: from the world's x axis for
    holonomic agents, from the agent's heading with ``diff_drive``).
Reward
    The decrease since the last step of the agent's distance to its goal
    (x ``pos_shaping_factor``); with ``shared_rew`` the decrease of the
    team's summed distances instead. Plus ``final_reward`` in every step in
    which every agent is within 0.05 (the goal's radius) of its goal, and
    ``agent_collision_penalty`` for every other agent whose surface is within
    0.005 of its own. As in VMAS 1.5, a pair of agents is penalised only in
    steps where it overlaps (centres within two radii) in at least one env of
    the batch: the world's broad-phase test for the pair is batch-wide.
    ``info`` reports ``pos_rew`` (the shaping term the agent earned),
    ``final_rew`` and ``agent_collisions``.
Starting state
    Agents, then one goal per agent, uniform in ``[-world_spawning_x,
    world_spawning_x] x [-world_spawning_y, world_spawning_y]``, every two at
    least ``2 agent_radius + 0.05`` apart; all at rest. Shared goals take the
    position drawn for the goal of the first agent sharing it (the unused
    draws still keep the others away from it). Holonomic agents face along
    +x; with ``diff_drive`` each agent's heading is uniform in [-pi, pi),
    drawn per env after the positions.
Episode termination
    When every agent is closer to its goal than its own radius
    (``agent_radius``, not the goal's: VMAS 1.5's rule).
Kwargs
    ``n_agents`` (4), ``collisions`` (True), ``world_spawning_x`` (1),
    ``world_spawning_y`` (1), ``enforce_bounds`` (False),
    ``agents_with_same_goal`` (1), ``split_goals`` (False),
    ``observe_all_goals`` (False), ``lidar_range`` (0.35), ``agent_radius``
    (0.1), ``comms_range`` (0; only drawn: lines between agents this close),
    ``n_lidar_rays`` (12), ``shared_rew`` (True), ``pos_shaping_factor`` (1),
    ``final_reward`` (0.01), ``agent_collision_penalty`` (-1),
    ``dynamics`` ("holonomic" or "diff_drive"; "holonomic"), and, read with
    ``diff_drive`` only (checked to be positive either way), ``max_speed``
    (0.5 m/s) and ``max_turn_rate`` (2.0 rad/s).
Deviations from VMAS 1.5
    Inconsistent kwargs raise ValueError instead of failing an assert. Agents
    past the seventh get fixed colours spread round the hue circle (VMAS draws
    them from ``torch.randn`` at construction, which also shifts the global
    RNG stream). Rewards, observations, dones and infos are otherwise VMAS's.
    ``dynamics``, ``max_speed`` and ``max_turn_rate`` are ours (VMAS 1.5
    has no such kwargs): with the default dynamics the task is VMAS's.
"""
from __future__ import annotations

import colorsys
import math
from typing import Optional

import torch
from torch import Tensor

from vmas_ros.scenarios.common import for_index as shaped_for
from vmas_ros.scenarios.common import check_number, configure, heuristic_kwargs, range_links, selected_rows
from vmas_ros.simulator.core import Agent, Landmark, Sphere, World
from vmas_ros.simulator.dynamics.diff_drive import DiffDrive
from vmas_ros.simulator.heuristic_policy import BaseHeuristicPolicy
from vmas_ros.simulator.neighbours import ClosePairs
from vmas_ros.simulator.observation_layout import LidarColumns, ObservationLayout
from vmas_ros.simulator.scenario import BaseScenario
from vmas_ros.simulator.sensors import Lidar
from vmas_ros.simulator.utils import ScenarioUtils, TorchUtils

#: name -> default of every kwarg (the heuristic reads the ones that shape the observation)
DEFAULTS = {
    "n_agents": 4, "collisions": True, "world_spawning_x": 1, "world_spawning_y": 1, "enforce_bounds": False,
    "agents_with_same_goal": 1, "split_goals": False, "observe_all_goals": False, "lidar_range": 0.35,
    "agent_radius": 0.1, "comms_range": 0, "n_lidar_rays": 12, "shared_rew": True, "pos_shaping_factor": 1,
    "final_reward": 0.01, "agent_collision_penalty": -1, "dynamics": "holonomic", "max_speed": 0.5,
    "max_turn_rate": 2.0,
}
#: the values of the ``dynamics`` kwarg
DYNAMICS = ("holonomic", "diff_drive")
GOAL_RADIUS = 0.05  # the goal marks' radius (the engine's default disc): "on goal" for the final reward
SPAWN_CLEARANCE = 0.05  # extra gap between any two spawned entities, beyond two agent radii
TOUCH_DISTANCE = 0.005  # surfaces closer than this count as a collision in the reward
SUBSTEPS = 2
#: the first seven agents' colours (the paper's figures)
PALETTE = (
    (0.22, 0.49, 0.72), (1.00, 0.50, 0.0), (0.30, 0.69, 0.29), (0.97, 0.51, 0.75),
    (0.60, 0.31, 0.64), (0.89, 0.10, 0.11), (0.87, 0.87, 0.0),
)


def agent_color(i: int) -> tuple:
    """Agent ``i``'s colour: the palette, then hues spaced by the golden angle (distinct, deterministic)."""
    if i < len(PALETTE):
        return PALETTE[i]
    return colorsys.hsv_to_rgb(((i - len(PALETTE)) * 0.618034) % 1.0, 0.7, 0.85)


def is_agent(entity) -> bool:
    """The lidar's filter: it sees the other agents only (goals do not collide)."""
    return isinstance(entity, Agent)


is_agent.layout_static = True  # depends on the entity's type only: the world may cache the targets


def goal_slots(n_agents: int, agents_with_same_goal: int, split_goals: bool) -> list[int]:
    """For every agent, which of the ``n_agents`` goal draws it goes to.

    ``split_goals``: the first half shares draw 0, the second half draw 1.
    Otherwise the first ``agents_with_same_goal`` agents share draw 0 and
    every later agent ``i`` has draw ``i`` to itself.
    """
    if split_goals:
        return [i // agents_with_same_goal for i in range(n_agents)]
    return [0 if i < agents_with_same_goal else i for i in range(n_agents)]


def validate(config: dict) -> None:
    """Raise ValueError for a kwarg value (or combination) the task cannot be built with."""
    def whole(name: str, low: int) -> None:
        value = config[name]
        if isinstance(value, bool) or not isinstance(value, int) or value < low:
            raise ValueError(f"navigation: {name} must be an int >= {low}, got {value!r}")

    def number(name: str, positive: bool) -> None:
        value = config[name]
        ok = isinstance(value, (int, float)) and not isinstance(value, bool) and (value > 0 if positive else value >= 0)
        if not ok:
            raise ValueError(f"navigation: {name} must be a number {'> 0' if positive else '>= 0'}, got {value!r}")

    whole("n_agents", 1)
    whole("n_lidar_rays", 1)
    if config["dynamics"] not in DYNAMICS:
        raise ValueError(f"navigation: dynamics must be one of {', '.join(DYNAMICS)}, got {config['dynamics']!r}")
    for name in ("max_speed", "max_turn_rate"):
        check_number("navigation", name, config[name], strict=True)
    for name in ("world_spawning_x", "world_spawning_y", "lidar_range", "agent_radius"):
        number(name, positive=True)
    number("comms_range", positive=False)
    for name in ("pos_shaping_factor", "final_reward", "agent_collision_penalty"):
        if isinstance(config[name], bool) or not isinstance(config[name], (int, float)):
            raise ValueError(f"navigation: {name} must be a number, got {config[name]!r}")
    n, same = config["n_agents"], config["agents_with_same_goal"]
    if isinstance(same, bool) or not isinstance(same, int) or not 1 <= same <= n:
        raise ValueError(f"navigation: agents_with_same_goal must be an int in [1, n_agents={n}], got {same!r}")
    if same > 1 and config["collisions"]:
        raise ValueError(
            f"navigation: agents_with_same_goal={same} needs collisions=False (agents sharing a goal cannot collide)"
        )
    if config["split_goals"] and (n % 2 or same != n // 2):
        raise ValueError(
            f"navigation: split_goals needs an even n_agents and agents_with_same_goal = n_agents / 2, "
            f"got n_agents={n}, agents_with_same_goal={same}"
        )


class Scenario(BaseScenario):
    supports_batched_reset = True
    fresh_observations = True

    def make_world(self, batch_dim: int, device, **kwargs) -> World:
        configure(self, kwargs, DEFAULTS, validate)
        self.plot_grid = False
        self.spawn_distance = 2 * self.agent_radius + SPAWN_CLEARANCE
        bounds = (self.world_spawning_x, self.world_spawning_y) if self.enforce_bounds else (None, None)

        world = World(batch_dim, device, substeps=SUBSTEPS, x_semidim=bounds[0], y_semidim=bounds[1])
        # the goals first: landmarks come before the agents in the world's rows, so added first each one
        # is appended (added after the agents, each would move every agent's row)
        goals = [Landmark(name=f"goal {i}", collide=False, color=agent_color(i), shape=Sphere(radius=GOAL_RADIUS))
                 for i in range(self.n_agents)]
        for goal in goals:
            world.add_landmark(goal)
        for i, goal in enumerate(goals):
            sensors = None
            if self.collisions:
                sensors = [Lidar(world, n_rays=self.n_lidar_rays, max_range=self.lidar_range, entity_filter=is_agent)]
            steering = {}
            if self.dynamics == "diff_drive":  # no drag: the agent moves at the commanded speed, as a base does
                steering = dict(u_range=[self.max_speed, self.max_turn_rate], u_multiplier=[1.0, 1.0],
                                drag=0.0, dynamics=DiffDrive(world))
            agent = Agent(
                name=f"agent_{i}", collide=self.collisions, color=agent_color(i), shape=Sphere(radius=self.agent_radius),
                render_action=True, sensors=sensors, **steering,
            )
            agent.goal = goal
            world.add_agent(agent)

        self._slots = torch.tensor(
            goal_slots(self.n_agents, self.agents_with_same_goal, self.split_goals), device=world.device
        )
        self._index = {agent.name: i for i, agent in enumerate(world.agents)}
        #: the collision term's candidates: pairs of agents close enough to touch (a little margin: the
        #: exact test is the reward's own)
        self._close = ClosePairs((2 * self.agent_radius + TOUCH_DISTANCE) * (1 + 1e-3))
        #: the agents' and their goals' rows in the world's stacked state, each [n]; the agents' lidars
        slot = {id(e): i for i, e in enumerate(world.entities)}
        self._agent_rows = torch.tensor([slot[id(a)] for a in world.agents], device=world.device)
        self._goal_rows = torch.tensor([slot[id(a.goal)] for a in world.agents], device=world.device)
        self._lidars = [agent.sensors[0] for agent in world.agents] if self.collisions else []
        #: the stacked observations and what they were computed for: (planar state, tables, hand-outs so far)
        self._obs_cache: Optional[tuple] = None
        #: per env [B, n]: each agent's distance to its goal x pos_shaping_factor, as of the last reward
        self.pos_shaping = torch.zeros(batch_dim, self.n_agents, device=world.device)
        #: the last reward's terms: per agent [B, n] (shaping, collisions), per env [B] (team shaping, final)
        self.agent_pos_rew = torch.zeros(batch_dim, self.n_agents, device=world.device)
        self.agent_collision_rew = torch.zeros(batch_dim, self.n_agents, device=world.device)
        self.pos_rew = torch.zeros(batch_dim, device=world.device)
        self.final_rew = torch.zeros(batch_dim, device=world.device)
        return world

    # ------------------------------------------------------------------- reset
    def reset_world_at(self, env_index=None) -> None:
        world = self.world
        x_bounds = (-self.world_spawning_x, self.world_spawning_x)
        y_bounds = (-self.world_spawning_y, self.world_spawning_y)
        # agents first, then one goal draw per agent, every two apart: [rows, 2n, 2]
        placed = ScenarioUtils.find_random_positions(
            2 * self.n_agents, env_index, world, self.spawn_distance, x_bounds, y_bounds)
        agents, goals = placed[:, : self.n_agents], placed[:, self.n_agents :][:, self._slots]
        if env_index is None:  # every env: two writes, not two per agent
            world.set_positions(world.agents, agents[..., 0].t(), agents[..., 1].t())
            world.set_positions([a.goal for a in world.agents], goals[..., 0].t(), goals[..., 1].t())
        else:
            for i, agent in enumerate(world.agents):
                agent.set_pos(shaped_for(agents[:, i], env_index), batch_index=env_index)
                agent.goal.set_pos(shaped_for(goals[:, i], env_index), batch_index=env_index)
        if self.dynamics == "diff_drive":  # drawn after the positions: their draws stay holonomic's
            headings = torch.empty(selected_rows(world.batch_dim, env_index), self.n_agents, device=world.device)
            headings.uniform_(-math.pi, math.pi)
            for i, agent in enumerate(world.agents):
                agent.set_rot(shaped_for(headings[:, i : i + 1], env_index), batch_index=env_index)
        shaping = torch.linalg.vector_norm(agents - goals, dim=-1) * self.pos_shaping_factor
        if env_index is None:
            self.pos_shaping = shaping
        else:
            self.pos_shaping[env_index] = shaped_for(shaping, env_index)

    # ------------------------------------------------------------------ reward
    def _positions(self) -> tuple[Tensor, Tensor]:
        """Agents' and their goals' positions, each [B, n, 2]."""
        pos = self.world.stacked_state("pos")  # [N, B, 2]
        return (pos.index_select(0, self._agent_rows).transpose(0, 1),
                pos.index_select(0, self._goal_rows).transpose(0, 1))

    def _collision_counts(self, pos: Tensor) -> Tensor:
        """How many other agents each agent touches (surfaces within TOUCH_DISTANCE): [B, n].

        A pair counts only if its centres are within two radii in some env of
        the batch (VMAS's ``World.collides``, a batch-wide test). Only pairs
        close enough to touch are tested (``ClosePairs``: every pair in a small
        team, the grid's in a swarm).
        """
        batch, n = pos.shape[:2]
        reach = 2 * self.agent_radius
        flat = pos.reshape(batch * n, 2)  # env-major
        first, second = self._close(pos)
        centres = torch.linalg.vector_norm(flat[first] - flat[second], dim=-1)
        pair = (first % n) * n + second % n  # the same two agents in every env
        in_play = torch.isin(pair, pair[centres <= reach])
        hit = (in_play & (centres - reach <= TOUCH_DISTANCE)).long()
        counts = torch.zeros(batch * n, dtype=torch.long, device=pos.device)
        return counts.index_add_(0, first, hit).index_add_(0, second, hit).view(batch, n)

    def _all_rewards(self) -> Tensor:
        """Every agent's reward [B, n]; caches the terms ``info`` reports."""
        pos, goals = self._positions()
        distance = torch.linalg.vector_norm(pos - goals, dim=-1)  # [B, n]
        shaping = distance * self.pos_shaping_factor
        self.agent_pos_rew = self.pos_shaping - shaping
        self.pos_shaping = shaping
        self.pos_rew = self.agent_pos_rew.sum(dim=1)
        all_on_goal = (distance < GOAL_RADIUS).all(dim=1)
        self.final_rew = torch.where(all_on_goal, float(self.final_reward), 0.0)
        if self.collisions:
            self.agent_collision_rew = self._collision_counts(pos) * float(self.agent_collision_penalty)
        else:
            self.agent_collision_rew = torch.zeros_like(distance)
        shaping_rew = self.pos_rew.unsqueeze(1) if self.shared_rew else self.agent_pos_rew
        return shaping_rew + self.final_rew.unsqueeze(1) + self.agent_collision_rew

    def reward(self, agent: Agent) -> Tensor:
        if agent is self.world.agents[0]:
            self._rewards = self._all_rewards()
        return self._rewards[:, self._index[agent.name]]

    def stacked_rewards(self) -> Tensor:
        """Every agent's reward [n, B] at once (the stacked step; the same values as ``reward``)."""
        self._rewards = self._all_rewards()
        return self._rewards.t()

    # ------------------------------------------------------------- observation
    def stacked_observations(self) -> Tensor:
        """Every agent's observation [n, B, width], computed once per state and hand-out; ``observation`` reads
        its row, so both forms give the same values."""
        world = self.world
        state, tables, handed_out = world.planar_state()[0], world.tables, self.env_observations_handed_out_count
        cached = self._obs_cache
        if cached is not None and cached[0] is state and cached[1] is tables and cached[2] == handed_out:
            return cached[3]
        pos_all = world.stacked_state("pos")
        pos = pos_all.index_select(0, self._agent_rows)  # [n, B, 2]
        vel = world.stacked_state("vel").index_select(0, self._agent_rows)
        goals = pos_all.index_select(0, self._goal_rows)
        if self.observe_all_goals:  # own position minus every agent's goal, in agent order: [n, B, 2n]
            to_goals = (pos.unsqueeze(2) - goals.transpose(0, 1).unsqueeze(0)).flatten(2)
        else:
            to_goals = pos - goals
        parts = [pos, vel, to_goals]
        if self.dynamics == "diff_drive":  # the heading as (cos, sin), after the velocity: [n, B, 2]
            rot = world.stacked_state("rot").index_select(0, self._agent_rows)
            parts.insert(2, torch.cat([torch.cos(rot), torch.sin(rot)], dim=-1))
        if self.collisions:
            parts.append(self.lidar_range - self._lidars[0].stacked_measure(self._lidars))
        obs = torch.cat(parts, dim=-1)
        self._obs_cache = (state, tables, handed_out, obs)
        return obs

    def observation(self, agent: Agent) -> Tensor:
        return self.stacked_observations()[self._index[agent.name]]

    def observation_layout(self, agent: Agent) -> ObservationLayout:
        """Own position and velocity first; then, from column 4 (6 after a diff-drive heading), the position
        minus one goal or every goal; then the lidar's proximities (0: nothing seen)."""
        to_goals = 6 if self.dynamics == "diff_drive" else 4
        n_goals = self.n_agents if self.observe_all_goals else 1
        position = ((0, 1),) + tuple((to_goals + 2 * k, 1) for k in range(n_goals))
        lidar = LidarColumns(to_goals + 2 * n_goals, self.n_lidar_rays, self.lidar_range) if self.collisions else None
        return ObservationLayout(position=position, velocity=((2, 1),), lidar=lidar)

    def info(self, agent: Agent) -> dict:
        i = self._index[agent.name]
        return {
            "pos_rew": self.pos_rew if self.shared_rew else self.agent_pos_rew[:, i],
            "final_rew": self.final_rew,
            "agent_collisions": self.agent_collision_rew[:, i],
        }

    def stacked_infos(self) -> dict:
        """``info`` of every agent at once, each [n, B]."""
        n = self.n_agents
        return {
            "pos_rew": self.pos_rew.repeat(n, 1) if self.shared_rew else self.agent_pos_rew.t().contiguous(),
            "final_rew": self.final_rew.repeat(n, 1),
            "agent_collisions": self.agent_collision_rew.t().contiguous(),
        }

    def done(self) -> Tensor:
        pos, goals = self._positions()
        return (torch.linalg.vector_norm(pos - goals, dim=-1) < self.agent_radius).all(dim=1)

    def extra_render(self, env_index: int = 0) -> list:
        """Black lines between agents within ``comms_range`` of each other."""
        return range_links(self.world.agents, env_index, self.comms_range)


class HeuristicPolicy(BaseHeuristicPolicy):
    """Drive to the goal with a PD law; steer off neighbours the lidar sees.

    VMAS's heuristic solves a CLF-QP per step with cvxpy/cvxpylayers; this one
    is a closed-form controller instead, batched over envs, with no solver
    dependency and no per-step optimisation: for a point mass with box-bounded
    force a saturated PD law already gives the exponential convergence the
    CLF asks for.

    From the observation only: the goal is ``pos - obs[4:6]`` (the own-goal
    block, ``goal_slot`` of them with ``observe_all_goals``). The wanted
    velocity points at the goal (``gain`` x distance, at most ``max_speed``).
    With ``collisions`` each lidar proximity ``p_k`` (0 = free, up to
    ``lidar_range`` = touching) pushes the wanted velocity away from ray
    ``k`` and a little sideways (``swerve``, always to the same hand, so two
    agents meeting head-on pass each other instead of stalling). The force
    is a velocity loop on the wanted velocity, clipped to the action range.

    With ``dynamics="diff_drive"`` the observation carries the heading
    ``(cos, sin)`` at ``obs[4:6]`` (the goal block follows it) and the lidar
    rays are relative to it, so their directions are turned by the heading
    first. The wanted world velocity then becomes (forward speed, turn rate):
    the speed is its component along the heading (negative: backing away
    from a neighbour ahead), the turn rate ``turn_gain`` x the angle from the
    heading to it, each clipped to the agent's ``u_range``.

    ``clf_epsilon`` and ``clf_slack`` are VMAS's heuristic's QP parameters
    (decay rate of the CLF, cost of relaxing it): accepted, so VMAS code that
    passes them runs, and checked to be positive; this controller has no QP
    for them to tune.
    """

    gain = 1.5
    max_speed = 0.8
    velocity_gain = 4.0
    repulsion = 3.0
    swerve = 0.6
    turn_gain = 3.0

    def __init__(self, continuous_action: bool = True, clf_epsilon: float = 0.2, clf_slack: float = 100.0,
                 goal_slot: int = 0, **scenario_kwargs) -> None:
        super().__init__(continuous_action)
        for name, value in (("clf_epsilon", clf_epsilon), ("clf_slack", clf_slack)):
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0:
                raise ValueError(f"navigation heuristic: {name} must be a number > 0, got {value!r}")
        cfg = heuristic_kwargs("navigation", DEFAULTS, scenario_kwargs)
        n_goals = cfg["n_agents"] if cfg["observe_all_goals"] else 1
        if isinstance(goal_slot, bool) or not isinstance(goal_slot, int) or not 0 <= goal_slot < n_goals:
            raise ValueError(f"navigation heuristic: goal_slot must be an int in [0, {n_goals}), got {goal_slot!r}")
        if cfg["dynamics"] not in DYNAMICS:
            raise ValueError(f"navigation heuristic: dynamics must be one of {', '.join(DYNAMICS)}, "
                             f"got {cfg['dynamics']!r}")
        self.steered = cfg["dynamics"] == "diff_drive"
        heading = 2 if self.steered else 0
        self.goal_start = 4 + heading + 2 * goal_slot
        self.n_rays = cfg["n_lidar_rays"] if cfg["collisions"] else 0
        self.lidar_range = float(cfg["lidar_range"])
        self.width = 4 + heading + 2 * n_goals + self.n_rays
        angles = 2 * torch.pi * torch.arange(self.n_rays, dtype=torch.float32) / max(self.n_rays, 1)
        self._rays = torch.stack([torch.cos(angles), torch.sin(angles)], dim=-1)  # [R, 2] unit ray directions

    def compute_action(self, observation: Tensor, u_range) -> Tensor:
        """[B, 2]: a force (holonomic, ``u_range`` a number) or (speed, turn rate) (``diff_drive``,
        ``u_range`` the pair of their limits)."""
        if observation.shape[1] != self.width:
            raise ValueError(
                f"navigation heuristic: expected observation width {self.width}, got {observation.shape[1]}"
            )
        to_goal = -observation[:, self.goal_start : self.goal_start + 2]
        wanted = TorchUtils.clamp_with_norm(self.gain * to_goal, self.max_speed)
        if self.n_rays:
            closeness = observation[:, -self.n_rays :] / self.lidar_range  # [B, R], 1 = touching
            towards = closeness @ self._rays.to(observation.device, observation.dtype)  # [B, 2], ray frame
            if self.steered:  # body-frame rays: turn the sum by the heading into the world frame
                cos, sin = observation[:, 4], observation[:, 5]
                towards = torch.stack([cos * towards[:, 0] - sin * towards[:, 1],
                                       sin * towards[:, 0] + cos * towards[:, 1]], dim=-1)
            sideways = torch.stack([towards[:, 1], -towards[:, 0]], dim=-1)
            wanted = wanted - self.repulsion * towards + self.swerve * self.repulsion * sideways
            wanted = TorchUtils.clamp_with_norm(wanted, self.max_speed)
        if self.steered:
            return self._steer(wanted, observation[:, 4:6], u_range)
        force = self.velocity_gain * (wanted - observation[:, 2:4])
        return force.clamp(-u_range, u_range)

    def _steer(self, wanted: Tensor, heading: Tensor, u_range) -> Tensor:
        """(speed, turn rate) [B, 2] following the world velocity ``wanted`` [B, 2] from ``heading`` (cos, sin)."""
        if isinstance(u_range, (int, float)) or len(u_range) != 2:
            raise ValueError(
                f"navigation heuristic: diff_drive needs u_range (max_speed, max_turn_rate), got {u_range!r}")
        max_speed, max_turn = (float(u) for u in u_range)
        forward = (wanted * heading).sum(dim=-1)
        across = heading[:, 0] * wanted[:, 1] - heading[:, 1] * wanted[:, 0]
        turn = self.turn_gain * torch.atan2(across, forward)  # 0 where nothing is wanted (atan2(0, 0))
        return torch.stack([forward.clamp(-max_speed, max_speed), turn.clamp(-max_turn, max_turn)], dim=-1)
