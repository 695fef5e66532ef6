"""joint_passage: two agents carry a rod (with a heavy package) through a gap in a barrier.

Description
    Two discs (radius 0.0333, force x0.8 up to 0.8) are pinned to the ends of
    a rigid rod of ``joint_length`` in a 2 x 2 arena with walls. A barrier of
    14 blocks (0.1476 x 0.2) along y = 0 has ``n_passages`` gaps, each just
    wide enough for an agent, so the rod must pass upright. The rod collides
    with the barrier: with ``fixed_passage`` only with the blocks next to a gap
    (the others cannot reach it when it passes), else with every block. With
    ``asym_package`` a package of mass ``mass_ratio`` (radius 0.0222, colliding
    with blocks and walls only) is pinned to the rod at ``mass_position`` half-
    lengths from its centre towards ``agent_1``; without it ``agent_1`` itself
    weighs ``mass_ratio``. The goal is a line above the barrier where the rod
    must lie (either way round). See :mod:`joint_passage_common`.
Observation (per agent, in this order)
    own position (2), own velocity (2), own position minus the goal's (2), own
    position minus each gap's (2 x ``n_passages``, in block order), the goal
    line's direction (cos, sin), and with ``observe_joint_angle`` the rod's
    direction (cos, sin; with Gaussian noise of std ``joint_angle_obs_noise``
    on the angle). With ``obs_noise`` every entry gets uniform noise in
    [-obs_noise, obs_noise].
Reward
    Shared: the sum of
    * position shaping: while the rod's centre is below y = 0, the decrease of
      its distance to the nearest gap, then of its distance to the goal (each
      x ``pos_shaping_factor``);
    * rotation shaping: until both agents are above the barrier (with
      ``all_passed_rot``; else until the rod's centre is), the decrease of the
      rod's angle to the vertical, then of its angle to the goal line's (angles
      between undirected lines, in [0, pi/2], x ``rot_shaping_factor``);
    * ``collision_reward`` per (agent or package, solid block or wall) pair and
      per (rod, block it collides with) pair closer than 0.005;
    * ``-energy_reward_coeff`` x the summed norms of the agents' forces over
      ``sqrt(2) * 0.8``.
    ``info`` (the same for both agents): ``pos_rew``, ``rot_rew``,
    ``collision_rew``, ``energy_rew`` and ``passed`` (1 in the step both agents
    first got above the barrier, else 0).
Starting state
    Rod at an angle uniform in [-pi/2, pi/2] (``random_start_angle``, else 0),
    its centre uniform where both agents fit between the walls and below the
    barrier (clear of it by 2 agent radii); which agent takes which end is
    random. The goal likewise above the barrier, at its own angle
    (``random_goal_angle``). Gaps: with ``fixed_passage`` around the middle
    block, alternately to its right and left; else each env draws distinct gap
    slots among the 13 leftmost. VMAS 1.5 draws the gap slots with
    repetition (two gaps may share a slot, pushing a block beyond the arena)
    and one agent order per reset call; here gaps are distinct and every env
    draws its own order.
Episode termination
    When the rod is within 0.01 of the goal's position and 0.01 rad of its angle.
Kwargs
    ``n_passages`` (1, 1..13; VMAS also takes 14), ``fixed_passage`` (True),
    ``joint_length`` (0.5), ``random_start_angle`` (True), ``random_goal_angle``
    (True), ``observe_joint_angle`` (False), ``joint_angle_obs_noise`` (0; needs
    ``observe_joint_angle``), ``asym_package`` (True), ``mass_ratio`` (5),
    ``mass_position`` (0.75), ``max_speed_1`` (None: ``agent_1``'s speed limit),
    ``pos_shaping_factor`` (1), ``rot_shaping_factor`` (1), ``collision_reward``
    (0), ``energy_reward_coeff`` (0), ``all_passed_rot`` (True), ``obs_noise``
    (0), ``use_controller`` (False: actions are forces; True: desired
    velocities tracked by a PID per agent).
    With ``joint_angle_obs_noise`` VMAS 1.5 adds the noise to the rod's actual
    angle in place (it accumulates in the physics); here only the observation
    is noisy.
"""
from __future__ import annotations

import math

import torch
from torch import Tensor

from vmas_ros.scenarios.common import check_flag, heuristic_kwargs
from vmas_ros.scenarios.joint_passage_common import (
    AGENT_RADIUS, N_BLOCKS, JointPassageBase, JointPassageHeuristic, line_angle_gap, validate_common,
)
from vmas_ros.scenarios.line_angles import (  # noqa: F401  VMAS's names for its users
    angle_to_vector, get_line_angle_0_90, get_line_angle_0_180, get_line_angle_dist_0_180, get_line_angle_dist_0_360,
)
from vmas_ros.simulator.core import Agent, Sphere
from vmas_ros.simulator.utils import Color

NAME = "joint_passage"
#: name -> default of every kwarg (VMAS 1.5's)
DEFAULTS = {
    "n_passages": 1, "fixed_passage": True, "joint_length": 0.5, "random_start_angle": True,
    "random_goal_angle": True, "observe_joint_angle": False, "joint_angle_obs_noise": 0.0,
    "asym_package": True, "mass_ratio": 5, "mass_position": 0.75, "max_speed_1": None,
    "pos_shaping_factor": 1, "rot_shaping_factor": 1, "collision_reward": 0, "energy_reward_coeff": 0,
    "all_passed_rot": True, "obs_noise": 0.0, "use_controller": False,
}
U_MULTIPLIER = F_RANGE = 0.8
MAX_PASSAGES = N_BLOCKS - 1
MIDDLE = N_BLOCKS // 2  # the block the gaps gather around


def validate(config: dict) -> None:
    validate_common(NAME, config)
    for name in ("all_passed_rot", "use_controller"):
        check_flag(NAME, name, config[name])
    n = config["n_passages"]
    if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= MAX_PASSAGES:
        raise ValueError(f"{NAME}: n_passages must be an int in [1, {MAX_PASSAGES}], got {n!r}")


def fixed_gap_slots(n_passages: int) -> list:
    """Slots of the gaps with ``fixed_passage``: the middle one, then alternately right and left of it."""
    slots, slot = [], MIDDLE
    for i in range(n_passages):
        slot += i if i % 2 else -i
        slots.append(slot)
    return slots


class Scenario(JointPassageBase):
    NAME = NAME
    DEFAULTS = DEFAULTS
    ROD_COLLIDES = True
    ROD_COLLISIONS = True
    ENERGY_SCALE = F_RANGE
    CONTROLLER_KWARG = "use_controller"
    spawn_radius = AGENT_RADIUS

    def validate(self, config: dict) -> None:
        validate(config)

    def world_params(self) -> dict:
        heavy = self.asym_package
        return dict(
            substeps=10 if heavy else 7, joint_force=900 if heavy else 400,
            collision_force=2500 if heavy else 1500, drag=0.15 if heavy else 0.25,
        )

    def make_agents(self) -> list:
        common = dict(obs_noise=self.obs_noise, render_action=True, u_multiplier=U_MULTIPLIER, f_range=F_RANGE)
        return [
            Agent(name="agent_0", shape=Sphere(AGENT_RADIUS), **common),
            Agent(
                name="agent_1", shape=Sphere(AGENT_RADIUS), mass=1 if self.asym_package else self.mass_ratio,
                color=Color.BLUE, max_speed=self.max_speed_1, **common,
            ),
        ]

    def is_gap_block(self, i: int) -> bool:
        return MIDDLE - self.n_passages / 2 <= i < MIDDLE + self.n_passages / 2

    def make_world(self, batch_dim: int, device, **kwargs):
        world = super().make_world(batch_dim, device, **kwargs)
        self._fixed_slots = torch.tensor(fixed_gap_slots(self.n_passages), device=world.device)
        rod_hits = self.solid_blocks
        if self.fixed_passage:
            # the fixed layout never changes: only the blocks beside a gap can touch the rod
            gaps = set(fixed_gap_slots(self.n_passages))
            solid_slots = [s for s in range(N_BLOCKS) if s not in gaps]
            rod_hits = [b for b, s in zip(self.solid_blocks, solid_slots) if s - 1 in gaps or s + 1 in gaps]
        names = frozenset(b.name for b in rod_hits)
        self.rod.collision_filter = lambda e: e.name in names
        return world

    def draw_angles(self, rows: int) -> tuple:
        device = self.world.device
        half_turn = math.pi / 2
        start = torch.empty(rows, 1, device=device).uniform_(-half_turn, half_turn) if self.random_start_angle else None
        goal = torch.empty(rows, 1, device=device).uniform_(-half_turn, half_turn) if self.random_goal_angle else None
        zeros = torch.zeros(rows, 1, device=device)
        return (zeros if start is None else start), (zeros if goal is None else goal)

    def agent_order(self, rows: int) -> Tensor:
        return torch.where(torch.rand(rows, 1, device=self.world.device) < 0.5, 1.0, -1.0)

    def place_gaps(self, rows: int, env_index) -> Tensor:
        if self.fixed_passage:
            return self._fixed_slots.expand(rows, -1)
        return torch.rand(rows, N_BLOCKS - 1, device=self.world.device).argsort(dim=1)[:, : self.n_passages]

    def shaping_terms(self) -> dict:
        rod = self.rod.state
        gaps = torch.stack([g.state.pos for g in self.gap_blocks], dim=1)
        to_gap = torch.linalg.vector_norm(rod.pos.unsqueeze(1) - gaps, dim=-1).min(dim=1).values
        return {
            "pos_pre": to_gap * self.pos_shaping_factor,
            "pos_post": self.rod_to_goal() * self.pos_shaping_factor,
            "rot_pre": line_angle_gap(rod.rot, math.pi / 2) * self.rot_shaping_factor,
            "rot_post": line_angle_gap(rod.rot, self.goal.state.rot) * self.rot_shaping_factor,
        }

    def rotation_reward(self, gain: dict, joint_passed: Tensor) -> Tensor:
        passed = self.all_passed if self.all_passed_rot else joint_passed
        return torch.where(passed, gain["rot_post"], gain["rot_pre"])

    def gap_observation(self, agent: Agent) -> list:
        return [agent.state.pos - gap.state.pos for gap in self.gap_blocks]


class HeuristicPolicy(JointPassageHeuristic):
    """:class:`JointPassageHeuristic` through the gap nearest the goal (the same for both agents,
    which see the gaps and the goal from different places but agree on their relative positions).
    Takes the scenario's kwargs (it needs ``n_passages``, ``joint_length``, ``observe_joint_angle``
    and ``use_controller``)."""

    def __init__(self, continuous_action: bool = True, **scenario_kwargs) -> None:
        config = heuristic_kwargs(NAME, DEFAULTS, scenario_kwargs)
        validate(config)
        super().__init__(continuous_action, config, config["use_controller"], AGENT_RADIUS, U_MULTIPLIER)

    def n_gap_observations(self) -> int:
        return self.config["n_passages"]

    def gap_offset(self, to_goal: Tensor, gaps: Tensor) -> Tensor:
        nearest = torch.linalg.vector_norm(gaps - to_goal.unsqueeze(1), dim=-1).argmin(dim=1)
        return gaps[torch.arange(gaps.shape[0], device=gaps.device), nearest]
