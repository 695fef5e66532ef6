"""What ``joint_passage`` and ``joint_passage_size`` share: two agents joined by a rod cross a barrier.

Both tasks live in a 2 x 2 arena closed by four wall lines. Agents ``agent_0``
and ``agent_1`` are pinned to the two ends of a rigid rod (the joint's line
landmark); a row of 14 red blocks along y = 0 (0.1476 wide along x, 0.2 tall)
forms a barrier with some blocks missing (the gaps). The team starts below the
barrier and must bring the rod onto a green goal line above it, at the goal's
position and (undirected) angle. With ``asym_package`` a heavy disc is pinned
to the rod at ``mass_position`` (in rod half-lengths from its centre, towards
``agent_1``'s end).

:class:`JointPassageBase` builds the world, resets it, scores and observes it;
a subclass says what differs: agents, world constants, where the gaps go, what
the rod is steered towards before the gaps and how its angle is rewarded.
:class:`JointPassageHeuristic` is the hand-written team policy both ship.

Per-env scenario state ([B] tensors), copied from VMAS in the parity tests:
``shaping`` (name -> last potential, see ``shaping_terms``) and ``passed``
(100 once both agents first passed the barrier, else 0).
"""
from __future__ import annotations

import abc
import math

import torch
from torch import Tensor

from vmas_ros.scenarios.common import check_flag, check_number, read_kwargs, selected_rows
from vmas_ros.scenarios.common import for_index as shaped_for
from vmas_ros.simulator.controllers.velocity_controller import VelocityController
from vmas_ros.simulator.core import Agent, Box, Landmark, Line, Sphere, World
from vmas_ros.simulator.heuristic_policy import BaseHeuristicPolicy
from vmas_ros.simulator.joints import Joint
from vmas_ros.simulator.scenario import BaseScenario
from vmas_ros.simulator.utils import Color, TorchUtils, X, Y

AGENT_RADIUS = 0.03333
SEMIDIM = 1.0
BLOCK_LENGTH = 0.1476  # along x: also the width of a one-block gap
BLOCK_WIDTH = 0.2  # along y: the barrier's thickness ("passage_width" in VMAS)
N_BLOCKS = int((2 * SEMIDIM + 2 * AGENT_RADIUS) // BLOCK_LENGTH)  # 14 slots across the arena
FIRST_SLOT_X = -SEMIDIM - AGENT_RADIUS + BLOCK_LENGTH / 2
TOUCH_DISTANCE = 0.005  # surfaces closer than this count as a collision in the reward
DONE_TOLERANCE = 0.01  # rod within this of the goal's position and (radians) angle
PID_PARAMS = (2.0, 10.0, 0.00001)  # standard form: gain, integral time, derivative time
#: wall k: centre (x, y) and angle; each is a line 2 + 2 r long just outside the arena
WALLS = (
    (SEMIDIM + AGENT_RADIUS, 0.0, math.pi / 2),
    (0.0, SEMIDIM + AGENT_RADIUS, 0.0),
    (-SEMIDIM - AGENT_RADIUS, 0.0, math.pi / 2),
    (0.0, -SEMIDIM - AGENT_RADIUS, 0.0),
)


def direction(angle: Tensor) -> Tensor:
    """Unit vectors [B, 2] of angles [B, 1]."""
    return torch.cat([torch.cos(angle), torch.sin(angle)], dim=1)


def line_angle_gap(angle: Tensor, target) -> Tensor:
    """Angle in [0, pi/2] between two undirected lines at ``angle`` [B, 1] and ``target``
    ([B, 1] or a float): [B]. A line at ``a`` and at ``a + pi`` is the same line."""
    gap = (angle % math.pi - target % math.pi).abs()
    return torch.minimum(gap, math.pi - gap).squeeze(-1)


def heading_gap(angle: Tensor, target: Tensor) -> Tensor:
    """Minus the cosine between two directed angles ([B, 1] each): [B] in [-1, 1], -1 when equal."""
    return -(direction(angle) * direction(target)).sum(dim=-1)


def slot_positions(slots: Tensor) -> Tensor:
    """Centres [..., 2] of the barrier slots ``slots`` (long, any shape)."""
    x = FIRST_SLOT_X + BLOCK_LENGTH * slots.to(torch.float32)
    return torch.stack([x, torch.zeros_like(x)], dim=-1)


def validate_common(scenario: str, config: dict) -> None:
    """The checks of the kwargs both scenarios take."""
    flags = ("random_start_angle", "random_goal_angle", "observe_joint_angle", "asym_package", "fixed_passage")
    for name in flags:
        check_flag(scenario, name, config[name])
    check_number(scenario, "joint_length", config["joint_length"], 2 * AGENT_RADIUS, strict=True)
    if config["joint_length"] > 1.0:
        raise ValueError(f"{scenario}: joint_length must be at most 1 (the rod must fit the arena), got {config['joint_length']!r}")
    check_number(scenario, "mass_ratio", config["mass_ratio"], 0.0, strict=True)
    check_number(scenario, "mass_position", config["mass_position"], None)
    if not -1 <= config["mass_position"] <= 1:
        raise ValueError(f"{scenario}: mass_position must be in [-1, 1] (rod half-lengths), got {config['mass_position']!r}")
    for name in ("pos_shaping_factor", "rot_shaping_factor", "collision_reward", "energy_reward_coeff"):
        check_number(scenario, name, config[name], None)
    for name in ("obs_noise", "joint_angle_obs_noise"):
        check_number(scenario, name, config[name], 0.0)
    if config["max_speed_1"] is not None:
        check_number(scenario, "max_speed_1", config["max_speed_1"], 0.0, strict=True)
    if config["joint_angle_obs_noise"] and not config["observe_joint_angle"]:
        raise ValueError(
            f"{scenario}: joint_angle_obs_noise={config['joint_angle_obs_noise']!r} needs observe_joint_angle=True"
        )


class JointPassageBase(BaseScenario):
    """The shared task; subclasses set the class constants and implement the hooks below."""

    supports_batched_reset = True
    fresh_observations = True
    NAME = ""
    DEFAULTS: dict = {}
    #: the rod collides (with the blocks the subclass's ``rod_filter`` admits)
    ROD_COLLIDES = False
    #: reward collisions of the rod with blocks too, not just of the agents and the package
    ROD_COLLISIONS = False
    #: the norm of an agent's action that counts as a full unit of energy, per axis
    ENERGY_SCALE = 1.0
    #: kwarg switching actions to desired velocities (a PID per agent)
    CONTROLLER_KWARG = "use_controller"

    # --------------------------------------------------------------- hooks
    @abc.abstractmethod
    def validate(self, config: dict) -> None:
        ...

    @abc.abstractmethod
    def world_params(self) -> dict:  # substeps, joint_force, collision_force and drag of the World
        ...

    @abc.abstractmethod
    def make_agents(self) -> list:  # the two agents, agent_0 first
        ...

    @abc.abstractmethod
    def is_gap_block(self, i: int) -> bool:
        """Whether block ``i`` (in world order) is a gap: not colliding, not drawn, observed."""
        ...

    @abc.abstractmethod
    def draw_angles(self, rows: int) -> tuple:
        """Start and goal angles of the rod, [rows, 1] each."""
        ...

    def agent_order(self, rows: int) -> Tensor:
        """[rows, 1]: +1 when ``agent_1`` starts at the rod's end along the start angle, -1 when ``agent_0`` does."""
        return torch.ones(rows, 1, device=self.world.device)

    @abc.abstractmethod
    def place_gaps(self, rows: int, env_index) -> Tensor:
        """Slots [rows, n_gaps] (long, distinct per row) of the gap blocks, in their order; also
        stores whatever per-env layout state the subclass keeps."""
        ...

    @abc.abstractmethod
    def shaping_terms(self) -> dict:
        """Current potentials, name -> [B]; the reward pays their decrease. Must hold ``pos_pre``
        (the rod's distance to where it should cross) and ``pos_post`` (to its goal)."""
        ...

    @abc.abstractmethod
    def rotation_reward(self, gain: dict, joint_passed: Tensor) -> Tensor:  # [B], from the potentials' gains
        ...

    @abc.abstractmethod
    def gap_observation(self, agent: Agent) -> list:  # the observed gaps relative to ``agent``, [B, 2] each
        ...

    # --------------------------------------------------------------- world
    def make_world(self, batch_dim: int, device, **kwargs) -> World:
        config = read_kwargs(kwargs, self.DEFAULTS)
        self.validate(config)
        self.config = config
        for name, value in config.items():
            setattr(self, name, value)
        self.use_velocity_control = config[self.CONTROLLER_KWARG]
        self.visualize_semidims = False
        world = World(batch_dim, device, x_semidim=SEMIDIM, y_semidim=SEMIDIM, **self.world_params())
        self._world = world  # the hooks below may read self.world
        for agent in self.make_agents():
            agent.controller = VelocityController(agent, world, PID_PARAMS, "standard")
            world.add_agent(agent)
        self.joint = Joint(
            world.agents[0], world.agents[1], dist=self.joint_length, collidable=self.ROD_COLLIDES, width=0, mass=1,
        )
        world.add_joint(self.joint)
        self.rod = self.joint.landmark
        self.package = None
        if self.asym_package:
            self.package = Landmark(
                name="mass", shape=Sphere(radius=AGENT_RADIUS * 2 / 3), collide=True, movable=True,
                color=Color.BLACK, mass=self.mass_ratio, collision_filter=lambda e: e.shape.kind != "sphere",
            )
            world.add_landmark(self.package)
            world.add_joint(Joint(self.package, self.rod, anchor_b=(self.mass_position, 0.0), dist=0.0))
        self.goal = Landmark(name="joint_goal", shape=Line(length=self.joint_length), collide=False, color=Color.GREEN)
        world.add_landmark(self.goal)
        self.walls = [
            Landmark(name=f"wall {i}", collide=True, shape=Line(length=2 * SEMIDIM + 2 * AGENT_RADIUS), color=Color.BLACK)
            for i in range(len(WALLS))
        ]
        for wall in self.walls:
            world.add_landmark(wall)
        self.blocks = [
            Landmark(
                name=f"passage {i}", collide=not self.is_gap_block(i), movable=False, color=Color.RED,
                shape=Box(length=BLOCK_LENGTH, width=BLOCK_WIDTH), collision_filter=lambda e: e.shape.kind != "box",
            )
            for i in range(N_BLOCKS)
        ]
        for block in self.blocks:
            world.add_landmark(block)
        self.gap_blocks = [b for b in self.blocks if not b.collide]
        self.solid_blocks = [b for b in self.blocks if b.collide]
        for gap in self.gap_blocks:
            gap.is_rendering[:] = False
        self._wall_pos = torch.tensor([w[:2] for w in WALLS], device=world.device)
        self._wall_rot = torch.tensor([w[2:] for w in WALLS], device=world.device)

        zeros = torch.zeros(batch_dim, device=world.device)
        self.shaping, self.passed = {}, zeros.clone()
        self.all_passed = torch.zeros(batch_dim, dtype=torch.bool, device=world.device)
        self.pos_rew, self.rot_rew, self.collision_rew, self.energy_rew, self._reward = (zeros.clone() for _ in range(5))
        return world

    # --------------------------------------------------------------- reset
    def _uniform_centres(self, half: Tensor, below: bool) -> Tensor:
        """Rod centres [rows, 2] whose ends (``half`` = centre-to-end offset, [rows, 2]) and agents stay
        inside the arena and clear of the barrier, below or above it."""
        margin = self.spawn_radius + half.abs()
        rows = half.shape[0]
        near = 2 * self.spawn_radius + BLOCK_WIDTH / 2 + half[:, Y:].abs()  # closest |y| to the barrier
        far = SEMIDIM - margin[:, Y:]
        low_x, high_x = -SEMIDIM + margin[:, X:Y], SEMIDIM - margin[:, X:Y]
        low_y, high_y = (-far, -near) if below else (near, far)
        rand = torch.rand(rows, 2, device=half.device)
        return torch.cat([low_x + (high_x - low_x) * rand[:, :1], low_y + (high_y - low_y) * rand[:, 1:]], dim=1)

    def reset_world_at(self, env_index=None) -> None:
        world = self.world
        rows = selected_rows(world.batch_dim, env_index)
        start_angle, goal_angle = self.draw_angles(rows)
        start_half = self.joint_length / 2 * direction(start_angle)
        goal_half = self.joint_length / 2 * direction(goal_angle)
        centre = self._uniform_centres(start_half, below=True)
        goal = self._uniform_centres(goal_half, below=False)
        self.goal.set_pos(shaped_for(goal, env_index), batch_index=env_index)
        self.goal.set_rot(shaped_for(goal_angle, env_index), batch_index=env_index)
        to_agent_1 = self.agent_order(rows) * start_half  # centre -> agent_1 (the package's end)
        for agent, end in zip(world.agents, (centre - to_agent_1, centre + to_agent_1)):
            agent.controller.reset(env_index)
            agent.set_pos(shaped_for(end, env_index), batch_index=env_index)  # the rod follows its ends
        if self.package is not None:
            package = centre + self.mass_position * to_agent_1
            self.package.set_pos(shaped_for(package, env_index), batch_index=env_index)

        gaps = self.place_gaps(rows, env_index)
        is_gap = torch.zeros(rows, N_BLOCKS, dtype=torch.bool, device=world.device).scatter_(1, gaps, True)
        # the solid blocks fill the other slots from left to right
        slots = torch.arange(N_BLOCKS, device=world.device).expand(rows, -1)
        solid = (slots + N_BLOCKS * is_gap).argsort(dim=1)[:, : len(self.solid_blocks)]
        for blocks, chosen in ((self.gap_blocks, gaps), (self.solid_blocks, solid)):
            pos = slot_positions(chosen)
            for k, block in enumerate(blocks):
                block.set_pos(shaped_for(pos[:, k], env_index), batch_index=env_index)
        for k, wall in enumerate(self.walls):
            wall.set_pos(shaped_for(self._wall_pos[k].expand(rows, 2), env_index), batch_index=env_index)
            wall.set_rot(shaped_for(self._wall_rot[k].expand(rows, 1), env_index), batch_index=env_index)

        now = self.shaping_terms()
        if env_index is None:
            self.shaping = now
            self.passed = torch.zeros_like(self.passed)
            self.all_passed = torch.zeros_like(self.all_passed)
        else:
            for name, value in now.items():
                self.shaping[name][env_index] = value[env_index]
            self.passed[env_index] = 0.0
            self.all_passed[env_index] = False

    # -------------------------------------------------------------- reward
    def rod_to_goal(self) -> Tensor:
        return torch.linalg.vector_norm(self.rod.state.pos - self.goal.state.pos, dim=-1)

    def reward(self, agent: Agent) -> Tensor:
        if agent is self.world.agents[0]:  # one shared reward: compute it once per step
            self._score()
        return self._reward

    def _score(self) -> None:
        joint_passed = self.rod.state.pos[:, Y] > 0
        heights = torch.stack([a.state.pos[:, Y] for a in self.world.agents], dim=1)
        self.all_passed = (heights > BLOCK_WIDTH / 2).all(dim=1)
        now = self.shaping_terms()
        gain = {name: self.shaping[name] - value for name, value in now.items()}
        self.shaping = now
        self.pos_rew = torch.where(joint_passed, gain["pos_post"], gain["pos_pre"])
        self.rot_rew = self.rotation_reward(gain, joint_passed)
        self.collision_rew = self._collisions() * self.collision_reward if self.collision_reward else torch.zeros_like(self.pos_rew)
        if self.energy_reward_coeff:
            forces = torch.stack([torch.linalg.vector_norm(a.action.u, dim=-1) for a in self.world.agents], dim=1)
            self.energy_rew = -forces.sum(dim=1) / (math.sqrt(self.world.dim_p) * self.ENERGY_SCALE) * self.energy_reward_coeff
        else:
            self.energy_rew = torch.zeros_like(self.pos_rew)
        self._reward = self.pos_rew + self.rot_rew + self.collision_rew + self.energy_rew

    def _collisions(self) -> Tensor:
        """How many (agent or package, solid block or wall) pairs, and with ``ROD_COLLISIONS``
        (rod, solid block) pairs, are within ``TOUCH_DISTANCE``: [B] float."""
        world = self.world
        bodies = list(world.agents) + ([self.package] if self.package is not None else [])
        pairs = [(a, b) for a in bodies for b in self.solid_blocks + self.walls]
        if self.ROD_COLLISIONS:
            pairs += [(b, self.rod) for b in self.solid_blocks]
        touching = torch.stack([world.get_distance(a, b) <= TOUCH_DISTANCE for a, b in pairs], dim=1)
        return touching.sum(dim=1).to(torch.float32)

    # ---------------------------------------------------------- observation
    def observation(self, agent: Agent) -> Tensor:
        pos = agent.state.pos
        parts = [pos, agent.state.vel, pos - self.goal.state.pos, *self.gap_observation(agent), direction(self.goal.state.rot)]
        if self.observe_joint_angle:
            angle = self.rod.state.rot
            if self.joint_angle_obs_noise:
                angle = angle + torch.randn_like(angle) * self.joint_angle_obs_noise
            parts.append(direction(angle))
        obs = torch.cat(parts, dim=-1)
        if self.obs_noise:
            obs = obs + torch.empty_like(obs).uniform_(-self.obs_noise, self.obs_noise)
        return obs

    def info(self, agent: Agent) -> dict:
        if agent is self.world.agents[0]:
            just_passed = self.all_passed & (self.passed == 0)
            self.passed = torch.where(just_passed, 100.0, self.passed)
            self._info = {
                "pos_rew": self.pos_rew, "rot_rew": self.rot_rew, "collision_rew": self.collision_rew,
                "energy_rew": self.energy_rew, "passed": just_passed.to(torch.int),
            }
        return self._info

    def done(self) -> Tensor:
        on_spot = self.rod_to_goal() <= DONE_TOLERANCE
        return on_spot & (line_angle_gap(self.rod.state.rot, self.goal.state.rot) <= DONE_TOLERANCE)

    def process_action(self, agent: Agent) -> None:
        if self.use_velocity_control:
            # a (near) zero command starts a fresh PID episode, without a host sync
            stopped = (torch.linalg.vector_norm(agent.action.u, dim=-1) < 1e-3).unsqueeze(-1)
            controller = agent.controller
            controller.accum_errs = torch.where(stopped, 0.0, controller.accum_errs)
            controller.prev_err = torch.where(stopped, 0.0, controller.prev_err)
            controller.process_force()

    def extra_render(self, env_index: int = 0) -> list:
        """Discs where the goal line wants the two agents."""
        from vmas_ros.simulator import rendering

        pos, rot = self.goal.state.pos[env_index], float(self.goal.state.rot[env_index])
        half = self.joint_length / 2 * torch.tensor([math.cos(rot), math.sin(rot)])
        geoms = []
        for end in (pos.cpu() - half, pos.cpu() + half):
            disc = rendering.make_circle(AGENT_RADIUS)
            xform = rendering.Transform()
            disc.add_attr(xform)
            xform.set_translation(float(end[X]), float(end[Y]))
            disc.set_color(*Color.GREEN.value)
            geoms.append(disc)
        return geoms


class JointPassageHeuristic(BaseHeuristicPolicy):
    """Both agents line the rod up vertically under a gap, climb through it, then lay it on the goal.

    Each agent sees only itself, the goal and the gaps, not its team-mate;
    the team's behaviour comes from both following the same velocity field:

    * below the barrier, each agent is pulled sideways onto the vertical axis of
      the chosen gap (``gap_offset``). The rod turns upright on its own: the two
      pulls are equal and opposite about its centre, a torque towards vertical
      from any tilt. An agent climbs only once lined up with the axis, and
      otherwise stays ``clearance`` below the barrier;
    * on the axis, above the barrier's bottom edge, it climbs straight up until
      it is a rod length above the barrier: then the upper agent has pulled the
      rod through, and the lower one follows on its own when the upper one
      turns towards the goal;
    * above the barrier, it heads for an end of the goal line: the end on its
      side of the goal's centre (along the goal's direction), plus a pull
      towards the centre that brings both agents to opposite sides of it.

    The wanted velocity is the action itself with velocity control, else it
    becomes a force through a feed-forward plus a proportional term.
    Continuous actions only.
    """

    approach_speed = 0.15
    climb_speed = 0.2
    goal_speed = 0.25
    gain = 3.0
    #: climbing starts at this distance from the gap's axis, at full speed from ``align_full``
    align_zero, align_full = 0.03, 0.012
    #: below the barrier, how far the agents' rims stay from it until lined up
    clearance = 0.04
    centre_pull, end_pull = 1.0, 3.0
    feedforward, feedback = 2.0, 4.0

    def __init__(self, continuous_action: bool, config: dict, velocity_control: bool, radius: float, u_multiplier: float):
        super().__init__(continuous_action)
        if not continuous_action:
            raise ValueError("joint passage heuristic: only continuous actions are supported")
        self.config = config
        self.velocity_control = velocity_control
        self.radius = radius  # of the largest agent: keeps every rim off the barrier
        self.u_multiplier = u_multiplier
        self.half = config["joint_length"] / 2
        self.width = 8 + 2 * self.n_gap_observations() + (2 if config["observe_joint_angle"] else 0)

    @abc.abstractmethod
    def n_gap_observations(self) -> int:
        ...

    @abc.abstractmethod
    def gap_offset(self, to_goal: Tensor, gaps: Tensor) -> Tensor:
        """The chosen gap relative to the agent, [b, 2], from the goal [b, 2] and the observed gaps [b, n, 2]."""
        ...

    def compute_action(self, observation: Tensor, u_range: float) -> Tensor:
        if observation.shape[1] != self.width:
            raise ValueError(f"joint passage heuristic: expected observation width {self.width}, got {observation.shape[1]}")
        n = self.n_gap_observations()
        pos, vel, to_goal = observation[:, 0:2], observation[:, 2:4], -observation[:, 4:6]
        gaps = -observation[:, 6 : 6 + 2 * n].view(-1, n, 2)
        heading = observation[:, 6 + 2 * n : 8 + 2 * n]
        gap = self.gap_offset(to_goal, gaps)
        off_axis, y = -gap[:, X], pos[:, Y]
        barrier = y + gap[:, Y]  # the barrier's centre line (y = 0)
        bottom = barrier - BLOCK_WIDTH / 2 - self.radius
        wait_line = bottom - self.clearance
        out_line = barrier + BLOCK_WIDTH / 2 + self.radius + 2 * self.half

        sideways = (-self.gain * off_axis).clamp(-self.approach_speed, self.approach_speed)
        lined_up = ((self.align_zero - off_axis.abs()) / (self.align_zero - self.align_full)).clamp(0.0, 1.0)
        climb = torch.where(
            y < bottom,
            torch.where(lined_up < 1, torch.minimum(self.climb_speed * lined_up, self.gain * (wait_line - y)), self.climb_speed),
            torch.full_like(y, self.climb_speed),
        )
        through = torch.stack([sideways, climb], dim=-1)

        side = torch.where((-(to_goal * heading).sum(-1, keepdim=True)) >= 0, 1.0, -1.0)
        to_end = to_goal + side * self.half * heading
        to_goal_velocity = TorchUtils.clamp_with_norm(self.centre_pull * to_goal + self.end_pull * to_end, self.goal_speed)
        in_column = (off_axis.abs() < BLOCK_LENGTH / 2) & (y < out_line)
        above = (y > barrier + BLOCK_WIDTH / 2 + self.radius) & ~in_column
        velocity = torch.where(above.unsqueeze(-1), to_goal_velocity, through)
        if self.velocity_control:
            return velocity.clamp(-u_range, u_range)
        force = self.feedforward * velocity + self.feedback * (velocity - vel)
        return (force / self.u_multiplier).clamp(-u_range, u_range)
