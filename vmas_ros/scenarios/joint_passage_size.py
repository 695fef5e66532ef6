"""joint_passage_size: a small and a big agent, joined by a rod, cross a barrier with a big and a small gap.

Description
    ``agent_0`` (radius 0.0333) and ``agent_1`` (radius 0.1, mass
    ``mass_ratio``) are pinned to the ends of a rigid rod of ``joint_length``
    that does not collide; forces up to 10. The barrier of 14 blocks (0.1476 x
    0.2) along y = 0 has a big gap two blocks wide, which the big agent fits
    through, and 3 blocks to its right or left a small gap one block wide (two
    with ``n_passages`` = 4), which only the small agent fits through. Passing
    the rod horizontally, the big agent through the big gap and the small one
    through the small gap, is what the rotation reward asks for. With
    ``asym_package`` a package of mass ``mass_ratio`` is pinned to the rod as in
    ``joint_passage`` (and ``agent_1`` weighs 1). See :mod:`joint_passage_common`.
Observation (per agent, in this order)
    own position (2), own velocity (2), own position minus the goal's (2), own
    position minus the big gap's centre (2), minus the small gap's (2; its
    first block with 4 passages), the goal line's direction (cos, sin), and
    with ``observe_joint_angle`` the rod's direction (cos, sin; Gaussian noise
    of std ``joint_angle_obs_noise`` on the angle). With ``obs_noise`` every
    entry gets uniform noise in [-obs_noise, obs_noise].
Reward
    Shared: the sum of
    * position shaping: while the rod's centre is below y = 0, the decrease of
      its distance to the point midway between the two gaps, then of its
      distance to the goal (each x ``pos_shaping_factor``). VMAS 1.5 scales the
      first distance by ``pos_shaping_factor`` squared in its steps and once at
      reset; here it is scaled once throughout (the same with the default 1);
    * rotation shaping, all the time: the decrease of minus the cosine between
      the rod's direction (``agent_0`` to ``agent_1``) and the "middle angle",
      which points from the small gap to the big one (0 when the small gap is on
      the left, pi when on the right); with ``middle_angle_180`` the decrease of
      the angle between the undirected lines instead; x ``rot_shaping_factor``;
    * ``collision_reward`` per (agent or package, solid block or wall) pair
      closer than 0.005. VMAS 1.5 counts the walls for the last of those bodies
      only; here for each;
    * ``-energy_reward_coeff`` x the summed norms of the agents' forces over
      ``sqrt(2)``.
    ``info`` (the same for both agents): ``pos_rew``, ``rot_rew``,
    ``collision_rew``, ``energy_rew`` and ``passed`` (1 in the step both agents
    first got above the barrier, else 0).
Starting state
    The rod upright, ``agent_1`` above or below ``agent_0`` at random (VMAS 1.5
    ignores ``random_start_angle``, and so does this port), its centre uniform
    where both ends fit between the walls, 0.1 from them, and below the barrier
    (clear of it by 0.2). The goal likewise above the barrier, at an angle
    uniform in [-pi/2, pi/2] with ``random_goal_angle``, else pi. The big gap's
    left block is slot 5 with ``fixed_passage``, else uniform in 0..12; the small
    gap is 3 slots to the right of it (or left, at random, when unfixed), to
    whichever side has room.
Episode termination
    When the rod is within 0.01 of the goal's position and 0.01 rad of its angle.
Kwargs
    ``fixed_passage`` (False), ``joint_length`` (0.52), ``random_start_angle``
    (False, no effect), ``random_goal_angle`` (False), ``observe_joint_angle``
    (False), ``joint_angle_obs_noise`` (0; needs ``observe_joint_angle``),
    ``asym_package`` (False), ``mass_ratio`` (1), ``mass_position`` (0.75),
    ``max_speed_1`` (None), ``pos_shaping_factor`` (1), ``rot_shaping_factor``
    (1), ``collision_reward`` (0), ``energy_reward_coeff`` (0), ``obs_noise``
    (0), ``n_passages`` (3 or 4), ``middle_angle_180`` (False),
    ``use_vel_controller`` (False: actions are forces; True: desired velocities
    tracked by a PID per agent). VMAS 1.5's ``set_n_passages`` (rebuilding the
    barrier of a live env) is not provided: make a new env.
"""
from __future__ import annotations

import math

import torch
from torch import Tensor

from vmas_ros.scenarios.common import check_flag, heuristic_kwargs
from vmas_ros.scenarios.joint_passage_common import (
    AGENT_RADIUS, N_BLOCKS, JointPassageBase, JointPassageHeuristic, heading_gap, line_angle_gap,
    slot_positions, validate_common,
)
from vmas_ros.scenarios.line_angles import (  # noqa: F401  VMAS's names for its users
    angle_to_vector, get_line_angle_0_90, get_line_angle_0_180, get_line_angle_dist_0_180, get_line_angle_dist_0_360,
)
from vmas_ros.simulator.core import Agent, Sphere

NAME = "joint_passage_size"
#: name -> default of every kwarg (VMAS 1.5's)
DEFAULTS = {
    "fixed_passage": False, "joint_length": 0.52, "random_start_angle": False, "random_goal_angle": False,
    "observe_joint_angle": False, "joint_angle_obs_noise": 0.0, "asym_package": False, "mass_ratio": 1,
    "mass_position": 0.75, "max_speed_1": None, "pos_shaping_factor": 1, "rot_shaping_factor": 1,
    "collision_reward": 0, "energy_reward_coeff": 0, "obs_noise": 0.0, "n_passages": 3,
    "middle_angle_180": False, "use_vel_controller": False,
}
BIG_RADIUS = 3 * AGENT_RADIUS
F_RANGE = 10.0
FIXED_BIG_SLOT = 5  # left block of the big gap with fixed_passage
SMALL_OFFSET = 3  # slots from the big gap's left block to the small gap


def validate(config: dict) -> None:
    validate_common(NAME, config)
    for name in ("middle_angle_180", "use_vel_controller"):
        check_flag(NAME, name, config[name])
    if config["n_passages"] not in (3, 4) or isinstance(config["n_passages"], bool):
        raise ValueError(f"{NAME}: n_passages must be 3 or 4, got {config['n_passages']!r}")


class Scenario(JointPassageBase):
    NAME = NAME
    DEFAULTS = DEFAULTS
    ENERGY_SCALE = 1.0  # u_range x u_multiplier
    CONTROLLER_KWARG = "use_vel_controller"
    spawn_radius = BIG_RADIUS

    def validate(self, config: dict) -> None:
        validate(config)

    def world_params(self) -> dict:
        heavy = self.asym_package
        return dict(
            substeps=10 if heavy else 5, joint_force=700 if heavy else 400,
            collision_force=2500 if heavy else 1500, drag=0.15 if heavy else 0.25,
        )

    def make_agents(self) -> list:
        common = dict(u_range=1, obs_noise=self.obs_noise, render_action=True, f_range=F_RANGE)
        return [
            Agent(name="agent_0", shape=Sphere(AGENT_RADIUS), **common),
            Agent(
                name="agent_1", shape=Sphere(BIG_RADIUS), mass=1 if self.asym_package else self.mass_ratio,
                max_speed=self.max_speed_1, **common,
            ),
        ]

    def is_gap_block(self, i: int) -> bool:
        return i < self.n_passages

    def make_world(self, batch_dim: int, device, **kwargs):
        world = super().make_world(batch_dim, device, **kwargs)
        #: per env: where the big gap's centre is, the small gap's (first block) and the point midway, [B, 2]
        self.big_passage_pos = torch.zeros(batch_dim, 2, device=world.device)
        self.small_passage_pos = torch.zeros(batch_dim, 2, device=world.device)
        self.pass_center = torch.zeros(batch_dim, 2, device=world.device)
        #: per env [B, 1]: the rod direction the rotation reward asks for (0 or pi)
        self.middle_angle = torch.zeros(batch_dim, 1, device=world.device)
        return world

    def draw_angles(self, rows: int) -> tuple:
        device = self.world.device
        up = torch.rand(rows, 1, device=device) >= 0.5
        start = torch.where(up, math.pi / 2, -math.pi / 2)
        if self.random_goal_angle:
            goal = torch.empty(rows, 1, device=device).uniform_(-math.pi / 2, math.pi / 2)
        else:
            goal = torch.full((rows, 1), math.pi, device=device)
        return start, goal

    def place_gaps(self, rows: int, env_index) -> Tensor:
        device, n = self.world.device, self.n_passages
        if self.fixed_passage:
            big = torch.full((rows,), FIXED_BIG_SLOT, device=device)
            right = torch.ones(rows, dtype=torch.bool, device=device)
        else:
            big = torch.randint(0, N_BLOCKS - 1, (rows,), device=device)
            right = torch.randint(0, 2, (rows,), device=device) == 1
        # to whichever side has room: left near the right wall, right near the left one
        right = (right & (big <= N_BLOCKS - 2 - n)) | (big < n)
        step = torch.where(right, 1, -1)
        small = big + SMALL_OFFSET * step
        slots = [big, big + 1, small] + ([small + step] if n == 4 else [])
        big_pos = (slot_positions(big) + slot_positions(big + 1)) / 2
        small_pos = slot_positions(small)
        middle = torch.where(right, math.pi, 0.0).unsqueeze(-1)
        for name, value in (
            ("big_passage_pos", big_pos), ("small_passage_pos", small_pos),
            ("pass_center", (big_pos + small_pos) / 2), ("middle_angle", middle),
        ):
            if env_index is None:
                setattr(self, name, value)
            else:
                getattr(self, name)[env_index] = value[0] if isinstance(env_index, int) else value
        return torch.stack(slots, dim=1)

    def shaping_terms(self) -> dict:
        rod = self.rod.state
        to_middle = heading_gap if not self.middle_angle_180 else line_angle_gap
        return {
            "pos_pre": torch.linalg.vector_norm(rod.pos - self.pass_center, dim=-1) * self.pos_shaping_factor,
            "pos_post": self.rod_to_goal() * self.pos_shaping_factor,
            "rot_pre": to_middle(rod.rot, self.middle_angle) * self.rot_shaping_factor,
        }

    def rotation_reward(self, gain: dict, joint_passed: Tensor) -> Tensor:
        return gain["rot_pre"]

    def gap_observation(self, agent: Agent) -> list:
        pos = agent.state.pos
        return [pos - self.big_passage_pos, pos - self.small_passage_pos]


class HeuristicPolicy(JointPassageHeuristic):
    """:class:`JointPassageHeuristic` through the big gap, which both agents fit through, upright
    (it gives up the rotation reward for a simple, safe crossing). Keeps every rim as far from
    the barrier as the big agent's. Takes the scenario's kwargs (it needs ``joint_length``,
    ``observe_joint_angle`` and ``use_vel_controller``)."""

    def __init__(self, continuous_action: bool = True, **scenario_kwargs) -> None:
        config = heuristic_kwargs(NAME, DEFAULTS, scenario_kwargs)
        validate(config)
        super().__init__(continuous_action, config, config["use_vel_controller"], BIG_RADIUS, 1.0)

    def n_gap_observations(self) -> int:
        return 2

    def gap_offset(self, to_goal: Tensor, gaps: Tensor) -> Tensor:
        return gaps[:, 0]
