"""ball_passage: two agents push a ball through a gap in a barrier to a goal beyond it.

Description
    Two agents (discs of radius 0.0333, mass 2, drag 0.25, ``u_multiplier``
    0.7) and a free ball (disc of the same radius, mass 1, linear friction
    0.02) start below a barrier along y = 0, inside walls at +-1 (the world
    has no drag or friction of its own). The barrier is a row of 20 red
    blocks (0.103 wide along x, 0.2 tall); ``n_passages`` of them are missing,
    which leaves gaps just wide enough for the ball. The agents must push the
    ball through a gap and onto a green goal above the barrier. Blocks collide
    with agents and ball but not with each other.
Observation (per agent, in this order)
    own position (2), own velocity (2), own position minus the goal's (2),
    own position minus the ball's (2), and own position minus every gap's
    (2 x ``n_passages``, gaps in block order).
Reward
    Shared by both agents. While the ball is below y = 0: the decrease of its
    distance to the nearest gap; once above: the decrease of its distance to
    the goal (both distances are tracked every step). Plus -0.06 for every
    (agent or ball, solid block) pair that overlaps. ``info`` reports
    ``pos_rew`` and ``collision_rew``.
Starting state
    The ball uniform below the barrier, agents 0.25 either side of it along a
    direction at an angle uniform in [-pi/2, pi/2] (-pi/2 without
    ``random_start_angle``: agent 0 straight above the ball), all three at
    least one radius inside the walls and below the barrier; goal uniform
    above it. Blocks are shuffled along the barrier unless ``fixed_passage``
    (then the gaps are the middle blocks, at x around 0). VMAS 1.5 draws one
    shuffle per reset call (shared by the whole batch on a full reset); here
    every env draws its own.
Episode termination
    When the ball is within 0.01 of the goal or touches a wall (its centre
    within one radius of +-1).
Kwargs
    ``n_passages`` (1, from 1 to 20), ``fixed_passage`` (False),
    ``random_start_angle`` (True).
"""
from __future__ import annotations

import math

import torch
from torch import Tensor

from vmas_ros.scenarios.common import for_index as shaped_for
from vmas_ros.scenarios.common import configure, continuous_heuristic_kwargs, selected_rows
from vmas_ros.scenarios.passage import random_permutations
from vmas_ros.simulator import geometry as geo
from vmas_ros.simulator.core import Agent, Box, Landmark, Sphere, World
from vmas_ros.simulator.heuristic_policy import BaseHeuristicPolicy
from vmas_ros.simulator.scenario import BaseScenario
from vmas_ros.simulator.utils import Color, TorchUtils

DEFAULTS = {"n_passages": 1, "fixed_passage": False, "random_start_angle": True}
N_AGENTS = 2
RADIUS = 0.03333  # agents and ball
SPACING = 0.5  # agent to agent at the start, the ball halfway
BLOCK_LENGTH = 0.103  # along x: also the width of a gap
BLOCK_WIDTH = 0.2  # along y: the barrier's thickness
SEMIDIM = 1.0
N_BLOCKS = int((2 * SEMIDIM + 2 * RADIUS) // BLOCK_LENGTH)
COLLISION_PENALTY = 0.06
GOAL_DISTANCE = 0.01


def validate(config: dict) -> None:
    """Raise ValueError for a kwarg value the task cannot be built with."""
    n = config["n_passages"]
    if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= N_BLOCKS:
        raise ValueError(f"ball_passage: n_passages must be an int in [1, {N_BLOCKS}], got {n!r}")
    for name in ("fixed_passage", "random_start_angle"):
        if not isinstance(config[name], bool):
            raise ValueError(f"ball_passage: {name} must be a bool, got {config[name]!r}")


def gap_indices(n_passages: int) -> list:
    """The blocks left out of the barrier: the ``n_passages`` in the middle of the row (VMAS 1.5's)."""
    middle = N_BLOCKS // 2
    return [i for i in range(N_BLOCKS) if middle - n_passages / 2 <= i < middle + n_passages / 2]


def disc_box_overlaps(discs: Tensor, radius: float, boxes: Tensor, box_rot: Tensor) -> Tensor:
    """Which discs overlap which barrier blocks, as ``World.is_overlapping`` judges one pair.

    ``discs`` [B, n, 2], ``boxes`` [B, K, 2], ``box_rot`` [B, K] -> [B, n, K] bool:
    the disc touches the block's outline, or its centre is inside the block.
    """
    return geo.disc_box_overlap(
        boxes.unsqueeze(1), box_rot.unsqueeze(1), BLOCK_LENGTH, BLOCK_WIDTH, discs.unsqueeze(2), radius
    )


class Scenario(BaseScenario):
    supports_batched_reset = True
    fresh_observations = True

    def make_world(self, batch_dim: int, device, **kwargs) -> World:
        configure(self, kwargs, DEFAULTS, validate)
        self.visualize_semidims = False  # extra_render draws the walls

        world = World(batch_dim, device, x_semidim=SEMIDIM, y_semidim=SEMIDIM, drag=0.0, linear_friction=0.0)
        for i in range(N_AGENTS):
            world.add_agent(Agent(name=f"agent_{i}", shape=Sphere(RADIUS), u_multiplier=0.7, mass=2.0, drag=0.25))
        self.goal = Landmark(name="goal", shape=Sphere(radius=RADIUS), collide=False, color=Color.GREEN)
        world.add_landmark(self.goal)
        self.ball = Landmark(
            name="ball", shape=Sphere(radius=RADIUS), collide=True, movable=True, mass=1.0,
            color=Color.BLACK, linear_friction=0.02,
        )
        world.add_landmark(self.ball)
        gaps = set(gap_indices(self.n_passages))
        self.blocks = [
            Landmark(
                name=f"passage {i}", collide=i not in gaps, movable=False,
                shape=Box(length=BLOCK_LENGTH, width=BLOCK_WIDTH), color=Color.RED,
                collision_filter=lambda e: e.shape.kind != "box",
            )
            for i in range(N_BLOCKS)
        ]
        for block in self.blocks:
            world.add_landmark(block)
        self.gaps = [b for b in self.blocks if not b.collide]
        self.solid = [b for b in self.blocks if b.collide]
        for gap in self.gaps:
            gap.is_rendering[:] = False
        first_slot_x = -SEMIDIM - RADIUS + BLOCK_LENGTH / 2
        self._slot_x = first_slot_x + BLOCK_LENGTH * torch.arange(N_BLOCKS, device=world.device, dtype=torch.float32)

        #: per env [B]: the ball's distance to the nearest gap / to the goal, as of the last reward
        self.pre_shaping = torch.zeros(batch_dim, device=world.device)
        self.post_shaping = torch.zeros(batch_dim, device=world.device)
        self.pos_rew = torch.zeros(batch_dim, device=world.device)
        self.collision_rew = torch.zeros(batch_dim, device=world.device)
        return world

    # ------------------------------------------------------------------- reset
    def reset_world_at(self, env_index=None) -> None:
        world, device = self.world, self.world.device
        rows = selected_rows(world.batch_dim, env_index)

        def uniform(low, high) -> Tensor:
            return low + (high - low) * torch.rand(rows, 1, device=device)

        if self.random_start_angle:
            angle = torch.empty(rows, 1, device=device).uniform_(-math.pi / 2, math.pi / 2)
        else:
            angle = torch.full((rows, 1), -math.pi / 2, device=device)
        half = (SPACING / 2) * torch.cat([torch.cos(angle), torch.sin(angle)], dim=1)  # ball -> agent 1
        # the ball's range keeps both agents inside the walls and below the barrier
        x_room = SEMIDIM - RADIUS - half[:, :1].abs()
        y_low = -SEMIDIM + RADIUS + half[:, 1:].abs()
        y_high = -2 * RADIUS - BLOCK_WIDTH / 2 - half[:, 1:].abs()
        ball = torch.cat([uniform(-x_room, x_room), uniform(y_low, y_high)], dim=1)
        goal = torch.cat([
            uniform(-SEMIDIM + RADIUS, SEMIDIM - RADIUS), uniform(2 * RADIUS + BLOCK_WIDTH / 2, SEMIDIM - RADIUS),
        ], dim=1)
        self.ball.set_pos(shaped_for(ball, env_index), batch_index=env_index)
        for i, agent in enumerate(world.agents):
            agent.set_pos(shaped_for(ball + (half if i == 1 else -half), env_index), batch_index=env_index)
        self.goal.set_pos(shaped_for(goal, env_index), batch_index=env_index)

        slots = torch.arange(N_BLOCKS, device=device).expand(rows, -1)
        order = slots if self.fixed_passage else random_permutations(rows, N_BLOCKS, device)
        block_x = self._slot_x[order]  # [rows, blocks]: block k's x
        block_pos = torch.stack([block_x, torch.zeros_like(block_x)], dim=-1)
        for k, block in enumerate(self.blocks):
            block.set_pos(shaped_for(block_pos[:, k], env_index), batch_index=env_index)

        gaps = torch.stack([block_pos[:, k] for k, b in enumerate(self.blocks) if not b.collide], dim=1)
        pre = torch.linalg.vector_norm(ball.unsqueeze(1) - gaps, dim=-1).min(dim=1).values
        post = torch.linalg.vector_norm(ball - goal, dim=-1)
        if env_index is None:
            self.pre_shaping, self.post_shaping = pre, post
        else:
            self.pre_shaping[env_index] = shaped_for(pre, env_index)
            self.post_shaping[env_index] = shaped_for(post, env_index)

    # ------------------------------------------------------------------ reward
    def _positions(self, entities: list) -> Tensor:
        return torch.stack([e.state.pos for e in entities], dim=1)  # [B, n, 2]

    def reward(self, agent: Agent) -> Tensor:
        if agent is self.world.agents[0]:  # shared: compute once per step
            ball = self.ball.state.pos
            pre = torch.linalg.vector_norm(ball.unsqueeze(1) - self._positions(self.gaps), dim=-1).min(dim=1).values
            post = torch.linalg.vector_norm(ball - self.goal.state.pos, dim=-1)
            passed = ball[:, 1] > 0
            self.pos_rew = torch.where(passed, self.post_shaping - post, self.pre_shaping - pre)
            self.pre_shaping, self.post_shaping = pre, post

            discs = self._positions([*self.world.agents, self.ball])
            rot = torch.stack([b.state.rot[:, 0] for b in self.solid], dim=1)
            overlaps = disc_box_overlaps(discs, RADIUS, self._positions(self.solid), rot)
            self.collision_rew = -COLLISION_PENALTY * overlaps.sum(dim=(1, 2)).float()
        return self.pos_rew + self.collision_rew

    # ------------------------------------------------------------- observation
    def observation(self, agent: Agent) -> Tensor:
        pos = agent.state.pos
        gaps = pos.unsqueeze(1) - self._positions(self.gaps)
        return torch.cat([
            pos, agent.state.vel, pos - self.goal.state.pos, pos - self.ball.state.pos, gaps.flatten(1),
        ], dim=-1)

    def info(self, agent: Agent) -> dict:
        return {"pos_rew": self.pos_rew, "collision_rew": self.collision_rew}

    def done(self) -> Tensor:
        ball = self.ball.state.pos
        arrived = torch.linalg.vector_norm(ball - self.goal.state.pos, dim=-1) <= GOAL_DISTANCE
        at_wall = (ball.abs() >= SEMIDIM - RADIUS).any(dim=-1)
        return arrived | at_wall

    def extra_render(self, env_index: int = 0) -> list:
        from vmas_ros.simulator import rendering

        edge = SEMIDIM + RADIUS
        walls = rendering.make_polygon([(-edge, -edge), (edge, -edge), (edge, edge), (-edge, edge)], filled=False)
        walls.set_color(*Color.BLACK.value)
        return [walls]


BAND = BLOCK_WIDTH / 2 + RADIUS  # a disc whose centre is this close to y = 0 touches a block, unless in a gap


class HeuristicPolicy(BaseHeuristicPolicy):
    """Dribble the ball gently up a funnel to the gap, through it, then to the goal; agents keep off the blocks.

    The ball has no drag and a tiny friction (it slows by 0.02 per second),
    while the agents top out at about 0.14 per axis: a ball pushed too hard
    rolls away out of reach, overshoots the gap's axis or runs into the
    barrier or a wall. So every push is paced: the agent behind the ball
    moves along the push direction at the speed from which friction alone
    would stop the ball at its mark (``pace_factor`` of
    ``sqrt(2 * ball_decel * distance)``, below ``max_pace``), and only
    closes a gap of more than ``slack`` behind its contact point faster
    (chasing a rolling ball and kicking it again is what sends it off).

    Below the barrier the ball follows a funnel: it is pushed towards the
    gap's axis aimed at a point a ``funnel``-th of the way up to a staging
    line ``stage_depth`` below the blocks, so it meets the axis moving
    straight up; its speed towards the staging line and towards the axis are
    paced separately. Once within ``align_tol`` of the axis (or inside the
    gap's column near the barrier) it is pushed straight up at
    ``climb_pace`` with a ``lateral`` correction, and rolls through the gap
    on its own if need be. A ball that ended up just under the blocks off
    the axis is steered no lower than its pusher can reach from below them
    (level along the barrier). Above the barrier it is paced to the goal.

    An agent reaches its place behind the ball by orbiting it (the short way
    round, but under the ball when the ball is near the barrier, since the
    top is blocked). The blocks are kept off by a filter on the wanted
    velocity: outside a gap's column an agent moves towards the barrier no
    faster than closes its distance to ``clearance`` outside the band blocks
    touch a disc in (so it stops there, or is sent back from closer); in a
    column (within ``enter_tol`` of its axis, ``channel_tol`` once inside)
    it may go on and is held on the axis within ``margin`` of the band.
    Balls still graze the blocks now and then
    when they reach the gap with some sideways speed. An agent left below
    once the ball is through lines up under the gap and goes through it.
    The agents do not see each other; both push, one often behind the other.
    The wanted velocity becomes a force through a feed-forward against the
    drag plus a proportional term. Continuous actions only.
    """

    max_speed = 0.3
    orbit_speed = 0.3
    orbit_radius = 3 * RADIUS
    behind_angle = 0.35  # rad off its place at which an agent stops orbiting and pushes
    gain = 3.0
    feedforward = 5.0  # force per unit of held speed: drag 0.25 per 0.1 s step, mass 2
    feedback = 4.0
    u_multiplier = 0.7
    ball_decel = 0.02  # the ball's friction deceleration
    pace_factor = 0.35  # a pushed ball runs ahead faster than its pusher: stay well under the stopping speed
    min_pace = 0.02
    max_pace = 0.13
    climb_pace = 0.08  # enough for the ball to roll through the gap by itself
    stage_depth = 0.1  # the staging line, below the band blocks touch a disc in
    funnel = 3.0
    align_tol = 0.01
    lateral = 8.0
    slack = 0.1
    low_orbit_zone = 0.15  # ball this close below the band: orbit under it
    margin = 0.035  # within this of the band an agent in a gap's column holds its axis
    clearance = 0.01  # outside a gap's column agents stay this far outside the band
    enter_tol = 0.006
    channel_tol = 0.017  # a disc this far off a gap's axis does not touch its blocks

    def __init__(self, continuous_action: bool = True, **scenario_kwargs) -> None:
        super().__init__(continuous_action)
        config = continuous_heuristic_kwargs("ball_passage", DEFAULTS, scenario_kwargs, continuous_action)
        validate(config)
        self.n_passages = config["n_passages"]

    @staticmethod
    def _nearest_gap(gaps: Tensor, point: Tensor) -> Tensor:
        """The gap whose axis is nearest ``point`` along x: gaps [b, n, 2], point [b, 2] -> [b, 2]."""
        rows = torch.arange(gaps.shape[0], device=gaps.device)
        return gaps[rows, (gaps[..., 0] - point[:, :1]).abs().argmin(dim=1)]

    def _reach(self, distance: Tensor) -> Tensor:
        """The paced speed for a ball that should stop within ``distance`` (same shape)."""
        return self.pace_factor * torch.sqrt(2 * self.ball_decel * distance.clamp_min(0))

    def _ball_plan(self, ball: Tensor, goal: Tensor, gap: Tensor) -> tuple:
        """Where and how fast to push the ball: unit direction [b, 2], pace [b, 1], and its height
        below the band [b, 1] (negative once in or above it)."""
        dx = ball[:, :1] - gap[:, :1]
        h = -BAND - ball[:, 1:]
        above = ball[:, 1:] > BAND
        entering = ~above & (h < self.stage_depth) & (dx.abs() < self.channel_tol)
        funnel = torch.cat([-dx, (h - self.stage_depth) / self.funnel], dim=1)
        climb = torch.cat([-self.lateral * dx, torch.ones_like(dx)], dim=1)
        to_goal = goal - ball
        direction = torch.where(above, to_goal, torch.where(entering, climb, funnel))
        direction = direction / torch.linalg.vector_norm(direction, dim=-1, keepdim=True).clamp_min(1e-6)
        # a ball just under the blocks can only be pushed from a place clear of them: steer no lower than that
        lowest = ((self.clearance - h) / (2 * RADIUS)).clamp(-1.0, 0.5)
        low = ~above & ~entering & (direction[:, 1:] < lowest)
        level = torch.cat([torch.sign(direction[:, :1]) * torch.sqrt(1 - lowest**2), lowest], dim=1)
        direction = torch.where(low, level, direction)
        # below: pace the climb towards the staging line and the run towards the axis separately
        climbing = entering | (dx.abs() < self.align_tol)
        to_stage = self._reach(h - self.stage_depth) + 0.005
        up_speed = torch.where(climbing, torch.full_like(dx, self.climb_pace), to_stage)
        across_speed = self._reach(dx.abs()) + self.min_pace
        pace = torch.minimum(up_speed / direction[:, 1:].abs().clamp_min(1e-6),
                             across_speed / direction[:, :1].abs().clamp_min(1e-6))
        to_goal_pace = self._reach(torch.linalg.vector_norm(to_goal, dim=-1, keepdim=True)) + self.min_pace
        pace = torch.where(above, to_goal_pace, pace).clamp(max=self.max_pace)
        return direction, pace, h

    def _keep_off_blocks(self, wanted: Tensor, pos: Tensor, own_gap: Tensor) -> Tensor:
        """Filter the wanted velocity [b, 2] so an agent at ``pos`` never reaches a block."""
        y, dx = pos[:, 1:], pos[:, :1] - own_gap[:, :1]
        side = torch.where(y >= 0, 1.0, -1.0)  # away from the barrier
        near = y.abs() < BAND + self.margin  # close enough to hold a gap's axis
        allowed = (dx.abs() < self.enter_tol) | ((y.abs() < BAND) & (dx.abs() < self.channel_tol))
        # towards the barrier no faster than closes the distance to ``clearance`` outside the band
        room = y.abs() - BAND - self.clearance
        towards = (-side * wanted[:, 1:]).clamp(max=self.gain * room)
        wy = torch.where(allowed, wanted[:, 1:], -side * towards)
        wx = torch.where(near & allowed, -self.gain * dx, wanted[:, :1])  # hold the gap's axis
        return torch.cat([wx, wy], dim=1)

    def compute_action(self, observation: Tensor, u_range: float) -> Tensor:
        width = 8 + 2 * self.n_passages
        if observation.shape[1] != width:
            raise ValueError(f"ball_passage heuristic: expected observation width {width}, got {observation.shape[1]}")
        pos, vel = observation[:, 0:2], observation[:, 2:4]
        goal, ball = pos - observation[:, 4:6], pos - observation[:, 6:8]
        gaps = pos.unsqueeze(1) - observation[:, 8:].view(-1, self.n_passages, 2)
        push_dir, pace, h = self._ball_plan(ball, goal, self._nearest_gap(gaps, ball))

        rel = observation[:, 6:8]  # agent relative to the ball
        dist = torch.linalg.vector_norm(rel, dim=-1, keepdim=True).clamp_min(1e-6)
        radial = rel / dist
        place = -push_dir  # unit, from the ball
        # signed angle from the agent's bearing to its place, about the ball
        error = torch.atan2(radial[:, 0] * place[:, 1] - radial[:, 1] * place[:, 0], (radial * place).sum(-1))
        tangent = torch.stack([-radial[:, 1], radial[:, 0]], dim=-1)  # counter-clockwise about the ball
        turn = torch.sign(error).unsqueeze(-1)
        under = torch.where(radial[:, :1] > 0, -1.0, 1.0)  # the way round that passes below the ball
        turn = torch.where((h > -BAND) & (h < self.low_orbit_zone), under, turn)
        orbit = self.orbit_speed * turn * tangent + self.gain * (self.orbit_radius - dist) * radial
        gap_to_contact = ball + place * (2 * RADIUS) - pos
        along = (gap_to_contact * push_dir).sum(-1, keepdim=True)
        speed = pace + self.gain * ((along - self.slack).clamp_min(0) + along.clamp_max(0))
        dribble = self.gain * (gap_to_contact - along * push_dir) + speed * push_dir
        wanted = torch.where((error.abs() < self.behind_angle).unsqueeze(-1), dribble, orbit)

        # the ball is through and this agent is not: line up under the gap, then go up through it
        own_gap = self._nearest_gap(gaps, pos)
        off_axis = (pos[:, :1] - own_gap[:, :1]).abs()
        lined_up = (off_axis < self.enter_tol) | ((pos[:, 1:].abs() < BAND) & (off_axis < self.channel_tol))
        way_y = torch.where(lined_up, BAND + 0.15, -BAND - self.margin - 0.02)
        way = torch.cat([own_gap[:, :1], way_y], dim=1)
        left_behind = (pos[:, 1:] < BAND) & (ball[:, 1:] > BAND)
        wanted = torch.where(left_behind, self.gain * (way - pos), wanted)

        wanted = TorchUtils.clamp_with_norm(self._keep_off_blocks(wanted, pos, own_gap), self.max_speed)
        force = self.feedforward * wanted + self.feedback * (wanted - vel)
        return (force / self.u_multiplier).clamp(-u_range, u_range)
