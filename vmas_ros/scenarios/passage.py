"""passage: five agents in a cross formation cross a barrier through narrow gaps.

Description
    Five agents (discs of radius 0.0333, ``u_multiplier`` 0.7) inside walls at
    +-1 start in a cross (a centre and four arms at 0.1) below a barrier along
    y = 0 and must rebuild the same cross, each in its own place, on goals
    above it (paper, "Multi-robot scenarios"). The barrier is a row of 20 red
    blocks (0.103 wide along x, 0.2 tall) spanning the arena; ``n_passages`` of
    them are missing, which leaves gaps just wide enough for one agent. Blocks
    collide only with the agents (not with each other).
Observation (per agent, in this order)
    own position (2), own velocity (2), its goal's position relative to it (2),
    and the position of every gap (missing block, in block order) relative to
    it (2 x n_passages).
Reward
    100 x the decrease of the agent's distance to its goal (with
    ``shared_reward``: the decrease of the summed distances of all agents),
    minus 10 for every other agent and every barrier block it overlaps.
    VMAS 1.5 subtracts the penalties of the shared reward from one tensor that
    every agent's reward aliases, so agent ``k`` there also pays for the
    collisions of agents 0..k-1; here each agent pays for its own only.
    ``info`` reports ``shaping_rew`` and ``collision_rew`` per agent.
Starting state
    Cross centre uniform in x in [-0.8, 0.8], y in [-0.8, -0.3]; goal cross
    centre x in [-0.8, 0.8], y in [0.3, 0.8]; each agent takes a random place
    in the cross and its goal the same place in the goal cross. Blocks are
    shuffled along the barrier, so the gaps are anywhere. VMAS 1.5 draws one
    shuffle of places and blocks per reset call (shared by the whole batch on
    a full reset); here every env draws its own.
Episode termination
    When every agent is within half its radius of its goal.
Kwargs
    ``n_passages`` (1, from 1 to 20), ``shared_reward`` (False).
"""
from __future__ import annotations

import torch
from torch import Tensor

from vmas_ros.scenarios.common import for_index as shaped_for
from vmas_ros.scenarios.common import heuristic_kwargs, read_kwargs, selected_rows
from vmas_ros.simulator import geometry as geo
from vmas_ros.simulator.core import Agent, Box, Landmark, Sphere, World
from vmas_ros.simulator.heuristic_policy import BaseHeuristicPolicy
from vmas_ros.simulator.scenario import BaseScenario
from vmas_ros.simulator.utils import Color, TorchUtils

DEFAULTS = {"n_passages": 1, "shared_reward": False}
N_AGENTS = 5
AGENT_RADIUS = 0.03333
SPACING = 0.1  # distance of the cross's arms from its centre
BLOCK_LENGTH = 0.103  # along x: also the width of a gap
BLOCK_WIDTH = 0.2  # along y: the barrier's thickness
SEMIDIM = 1.0
N_BLOCKS = int((2 * SEMIDIM + 2 * AGENT_RADIUS) // BLOCK_LENGTH)
SHAPING_FACTOR = 100.0
COLLISION_PENALTY = 10.0
#: place k of the cross relative to its centre: right, up, left, down arm, then the centre
CROSS = ((SPACING, 0.0), (0.0, SPACING), (-SPACING, 0.0), (0.0, -SPACING), (0.0, 0.0))
#: how far the cross centre stays from the walls and from the barrier
MARGIN = 3 * AGENT_RADIUS + SPACING


def random_permutations(rows: int, n: int, device) -> Tensor:
    """One uniform permutation of ``range(n)`` per row: [rows, n] long."""
    return torch.rand(rows, n, device=device).argsort(dim=1)


def uniform_points(rows: int, x_range: tuple, y_range: tuple, device) -> Tensor:
    """[rows, 2] points uniform in the rectangle ``x_range`` x ``y_range``."""
    x = torch.empty(rows, 1, device=device).uniform_(*x_range)
    y = torch.empty(rows, 1, device=device).uniform_(*y_range)
    return torch.cat([x, y], dim=1)


class Scenario(BaseScenario):
    supports_batched_reset = True

    def make_world(self, batch_dim: int, device, **kwargs) -> World:
        config = read_kwargs(kwargs, DEFAULTS)
        self.n_passages, self.shared_reward = config["n_passages"], config["shared_reward"]
        if not isinstance(self.n_passages, int) or not 1 <= self.n_passages <= N_BLOCKS:
            raise ValueError(f"passage: n_passages must be an int in [1, {N_BLOCKS}], got {self.n_passages!r}")
        self.visualize_semidims = False  # extra_render draws the walls

        world = World(batch_dim, device, x_semidim=SEMIDIM, y_semidim=SEMIDIM)
        for i in range(N_AGENTS):
            agent = Agent(name=f"agent_{i}", shape=Sphere(AGENT_RADIUS), u_multiplier=0.7)
            goal = Landmark(name=f"goal {i}", collide=False, shape=Sphere(radius=AGENT_RADIUS), color=Color.LIGHT_GREEN)
            agent.goal = goal
            world.add_agent(agent)
            world.add_landmark(goal)
        # the first n_passages blocks are the gaps: not colliding, not drawn, observed
        self.blocks = [
            Landmark(
                name=f"passage {i}", collide=i >= self.n_passages, movable=False,
                shape=Box(length=BLOCK_LENGTH, width=BLOCK_WIDTH), color=Color.RED,
                collision_filter=lambda e: e.shape.kind != "box",
            )
            for i in range(N_BLOCKS)
        ]
        for block in self.blocks:
            world.add_landmark(block)
        for gap in self.blocks[: self.n_passages]:
            gap.is_rendering[:] = False
        self._cross = torch.tensor(CROSS, device=world.device)
        first_slot_x = -SEMIDIM - AGENT_RADIUS + BLOCK_LENGTH / 2
        self._slot_x = first_slot_x + BLOCK_LENGTH * torch.arange(N_BLOCKS, device=world.device, dtype=torch.float32)
        self._index = {agent.name: i for i, agent in enumerate(world.agents)}
        #: per env [B, 5]: 100 x each agent's distance to its goal, as of the last reward
        self.global_shaping = torch.zeros(batch_dim, N_AGENTS, device=world.device)
        self.shaping_rew = torch.zeros(batch_dim, N_AGENTS, device=world.device)
        self.collision_rew = torch.zeros(batch_dim, N_AGENTS, device=world.device)
        return world

    # ------------------------------------------------------------------- reset
    def reset_world_at(self, env_index=None) -> None:
        world, device = self.world, self.world.device
        rows = selected_rows(world.batch_dim, env_index)
        across = (-SEMIDIM + MARGIN, SEMIDIM - MARGIN)
        start = uniform_points(rows, across, (-SEMIDIM + MARGIN, -MARGIN - BLOCK_WIDTH / 2), device)
        finish = uniform_points(rows, across, (MARGIN + BLOCK_WIDTH / 2, SEMIDIM - MARGIN), device)
        places = self._cross[random_permutations(rows, N_AGENTS, device)]  # [rows, 5, 2]
        agents, goals = start.unsqueeze(1) + places, finish.unsqueeze(1) + places
        for i, agent in enumerate(world.agents):
            agent.set_pos(shaped_for(agents[:, i], env_index), batch_index=env_index)
            agent.goal.set_pos(shaped_for(goals[:, i], env_index), batch_index=env_index)
        block_x = self._slot_x[random_permutations(rows, N_BLOCKS, device)]  # [rows, blocks]
        block_pos = torch.stack([block_x, torch.zeros_like(block_x)], dim=-1)
        for k, block in enumerate(self.blocks):
            block.set_pos(shaped_for(block_pos[:, k], env_index), batch_index=env_index)
        shaping = torch.linalg.vector_norm(agents - goals, dim=-1) * SHAPING_FACTOR
        if env_index is None:
            self.global_shaping = shaping
        else:
            self.global_shaping[env_index] = shaped_for(shaping, env_index)

    # ------------------------------------------------------------------ reward
    def _stack(self, entities: list) -> Tensor:
        return torch.stack([e.state.pos for e in entities], dim=1)  # [B, n, 2]

    def _collisions(self, pos: Tensor) -> Tensor:
        """How many other agents and barrier blocks each agent overlaps: [B, 5]."""
        gap = torch.linalg.vector_norm(pos.unsqueeze(2) - pos.unsqueeze(1), dim=-1)  # [B, 5, 5]
        others = ~torch.eye(N_AGENTS, dtype=torch.bool, device=pos.device)
        agents = ((gap < 2 * AGENT_RADIUS) & others).sum(dim=-1)
        solid = [b for b in self.blocks if b.collide]
        blocks = self._stack(solid).unsqueeze(1)  # [B, 1, K, 2]
        rot = torch.stack([b.state.rot[:, 0] for b in solid], dim=1).unsqueeze(1)
        # as World.is_overlapping: touching the outline, or inside the solid box
        overlapping = geo.disc_box_overlap(blocks, rot, BLOCK_LENGTH, BLOCK_WIDTH, pos.unsqueeze(2), AGENT_RADIUS)
        return agents + overlapping.sum(dim=-1)

    def _all_rewards(self) -> Tensor:
        """Every agent's reward [B, 5]; caches the terms ``info`` reports."""
        pos = self._stack(self.world.agents)
        goals = self._stack([a.goal for a in self.world.agents])
        shaping = torch.linalg.vector_norm(pos - goals, dim=-1) * SHAPING_FACTOR
        progress = self.global_shaping - shaping
        self.global_shaping = shaping
        self.shaping_rew = progress.sum(dim=1, keepdim=True).expand(-1, N_AGENTS) if self.shared_reward else progress
        self.collision_rew = -COLLISION_PENALTY * self._collisions(pos).float()
        return self.shaping_rew + self.collision_rew

    def reward(self, agent: Agent) -> Tensor:
        if agent is self.world.agents[0]:
            self._rewards = self._all_rewards()
        return self._rewards[:, self._index[agent.name]]

    # ------------------------------------------------------------- observation
    def observation(self, agent: Agent) -> Tensor:
        gaps = self._stack(self.blocks[: self.n_passages]) - agent.state.pos.unsqueeze(1)
        return torch.cat([agent.state.pos, agent.state.vel, agent.goal.state.pos - agent.state.pos, gaps.flatten(1)], dim=-1)

    def info(self, agent: Agent) -> dict:
        i = self._index[agent.name]
        return {"shaping_rew": self.shaping_rew[:, i], "collision_rew": self.collision_rew[:, i]}

    def done(self) -> Tensor:
        pos = self._stack(self.world.agents)
        goals = self._stack([a.goal for a in self.world.agents])
        return (torch.linalg.vector_norm(pos - goals, dim=-1) <= AGENT_RADIUS / 2).all(dim=1)

    def extra_render(self, env_index: int = 0) -> list:
        from vmas_ros.simulator import rendering

        edge = SEMIDIM + AGENT_RADIUS
        walls = rendering.make_polygon([(-edge, -edge), (edge, -edge), (edge, edge), (-edge, edge)], filled=False)
        walls.set_color(*Color.BLACK.value)
        return [walls]


class HeuristicPolicy(BaseHeuristicPolicy):
    """Queue up in single file under a gap, climb through it, then go to the goal.

    Decentralised and memoryless; agents do not see each other, so the
    queue comes from the shape of the velocity field alone. Below the barrier
    an agent drives sideways at its own height, slowly (``approach_speed``),
    towards the axis of the gap on its shortest way to the goal, and climbs
    only once it is lined up with the gap, at ``rise_speed`` = 4 x that speed.
    Agents of the cross on one side of the axis then reach it one after the
    other and the climbing file outruns the next arrival: in the file they are
    0.1 apart (the arms' sideways distance becomes a vertical one). Above the
    barrier each agent drives straight to its goal. Collisions remain when
    the cross straddles the gap's axis (two agents reach it at once from the
    two sides) and when an agent passes a team-mate already parked on its goal.

    The wanted velocity becomes a force through a feed-forward against the
    drag (a held speed ``v`` needs ``2.5 v``) plus a proportional term.
    """

    approach_speed = 0.06
    rise_speed = 0.24
    goal_speed = 0.25
    #: climbing speed ramps from 0 at this distance from the gap's axis ...
    align_zero = 0.025
    #: ... to full at this one (the gap leaves 0.0115 of play before a contact)
    align_full = 0.008
    #: below the barrier, how far the agent's rim stays from it until lined up
    entry_gap = 0.03
    gain = 3.0
    feedforward = 2.5  # force per unit of held speed: drag 0.25 per step of dt 0.1, mass 1
    feedback = 3.0
    u_multiplier = 0.7

    def __init__(self, continuous_action: bool = True, n_passages: int = DEFAULTS["n_passages"], **scenario_kwargs) -> None:
        super().__init__(continuous_action)
        heuristic_kwargs("passage", DEFAULTS, scenario_kwargs)  # refuses unknown kwargs
        if not isinstance(n_passages, int) or not 1 <= n_passages <= N_BLOCKS:
            raise ValueError(f"passage heuristic: n_passages must be an int in [1, {N_BLOCKS}], got {n_passages!r}")
        self.n_passages = n_passages

    def compute_action(self, observation: Tensor, u_range: float) -> Tensor:
        width = 6 + 2 * self.n_passages
        if observation.shape[1] != width:
            raise ValueError(f"passage heuristic: expected observation width {width}, got {observation.shape[1]}")
        pos, vel, to_goal = observation[:, 0:2], observation[:, 2:4], observation[:, 4:6]
        gaps = observation[:, 6:].view(-1, self.n_passages, 2)  # relative to the agent
        detour = torch.linalg.vector_norm(gaps, dim=-1) + torch.linalg.vector_norm(to_goal.unsqueeze(1) - gaps, dim=-1)
        gap = gaps[torch.arange(gaps.shape[0], device=gaps.device), detour.argmin(dim=1)]
        off_axis, y = -gap[:, 0], pos[:, 1]
        barrier = y + gap[:, 1]
        below_limit = barrier - BLOCK_WIDTH / 2 - AGENT_RADIUS - self.entry_gap
        above_limit = barrier + BLOCK_WIDTH / 2 + AGENT_RADIUS + self.entry_gap

        sideways = (-self.gain * off_axis).clamp(-self.approach_speed, self.approach_speed)
        lined_up = ((self.align_zero - off_axis.abs()) / (self.align_zero - self.align_full)).clamp(0.0, 1.0)
        climb = self.rise_speed * lined_up
        # not yet lined up: do not climb into the barrier
        climb = torch.where(lined_up < 1, torch.minimum(climb, self.gain * (below_limit - y)), climb)
        queue = torch.stack([sideways, climb], dim=-1)
        to_goal_velocity = TorchUtils.clamp_with_norm(self.gain * to_goal, self.goal_speed)
        velocity = torch.where((y >= above_limit).unsqueeze(-1), to_goal_velocity, queue)
        force = self.feedforward * velocity + self.feedback * (velocity - vel)
        return (force / self.u_multiplier).clamp(-u_range, u_range)
