"""give_way: two robots swap ends of a one-lane corridor that has a single side nook.

Description
    A 5 m corridor, 0.4 m wide, closed at both ends (paper, "Multi-robot
    scenarios"). Halfway along its upper wall opens a nook 0.4 m wide and
    0.48 m deep. Agent 0 (blue) starts near the left end and must reach a goal
    near the right end; agent 1 (green) does the opposite. The agents (discs of
    radius 0.16, or 0.32 x 0.24 boxes) cannot pass each other in the corridor,
    so one of them has to give way by waiting in the nook. With
    ``mirror_passage`` the floor is replaced by a second ceiling with a mirrored
    nook below. By default actions are desired velocities tracked by a PID
    ``VelocityController`` (as for the RoboMaster robots the task was made for).
Observation (per agent, in this order)
    own position (2), own velocity (2), and with ``observe_rel_pos`` its own
    position minus the other agent's (2). With ``obs_noise > 0`` every entry
    gets uniform noise in [-obs_noise, obs_noise].
Reward
    Shared: the decrease of the summed distances of both agents to their goals
    (x ``pos_shaping_factor``), plus ``final_reward`` in every step both agents
    are on their goals (closer than the goal radius, 0.08). Per agent:
    ``agent_collision_penalty`` when the agents are within 0.005 of touching,
    ``passage_collision_penalty`` per nook wall and ``obstacle_collision_penalty``
    per other wall within 0.005 of the agent (walls count only within the
    engine's broad-phase reach, as in VMAS 1.5), and ``-energy_rew_coeff`` x the
    norm of its force over ``sqrt(2) * f_range``. ``info`` reports each term.
Starting state
    Agents at x = -+2.0, y = 0, plus uniform noise in [-0.02, 0.02] per
    coordinate, at rest; goals at x = +-2.29. VMAS 1.5 draws one noise vector
    for the whole batch on a full reset; here every env draws its own.
Episode termination
    When both agents are on their goals if ``done_on_completion``; else never
    (set ``max_steps``).
Kwargs
    ``v_range`` (0.5), ``a_range`` (1), ``obs_noise`` (0), ``box_agents`` (False),
    ``linear_friction`` (0.1), ``mirror_passage`` (False), ``done_on_completion``
    (False), ``observe_rel_pos`` (False), ``pos_shaping_factor`` (1.0),
    ``final_reward`` (0.01), ``energy_rew_coeff`` (0), ``agent_collision_penalty``
    (0), ``passage_collision_penalty`` (0), ``obstacle_collision_penalty`` (0),
    ``use_velocity_controller`` (True), ``min_input_norm`` (0.08), ``dt_delay`` (0).
    ``dt_delay`` delays the commanded velocities by that many steps (velocity
    controller only); unlike VMAS 1.5 the delay line of a reset env is emptied.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import torch
from torch import Tensor

from vmas_ros.scenarios.common import for_index as shaped_for
from vmas_ros.scenarios.common import check_int, check_number, configure, heuristic_kwargs, selected_rows
from vmas_ros.simulator import geometry as geo
from vmas_ros.simulator.controllers.velocity_controller import VelocityController
from vmas_ros.simulator.core import Agent, Box, Landmark, Line, Sphere, World
from vmas_ros.simulator.heuristic_policy import BaseHeuristicPolicy
from vmas_ros.simulator.scenario import BaseScenario
from vmas_ros.simulator.utils import LINE_MIN_DIST, Color, TorchUtils

#: name -> default of every kwarg (the heuristic reads the ones it needs too)
DEFAULTS = {
    "v_range": 0.5, "a_range": 1.0, "obs_noise": 0.0, "box_agents": False, "linear_friction": 0.1,
    "mirror_passage": False, "done_on_completion": False, "observe_rel_pos": False,
    "pos_shaping_factor": 1.0, "final_reward": 0.01, "energy_rew_coeff": 0.0,
    "agent_collision_penalty": 0.0, "passage_collision_penalty": 0.0, "obstacle_collision_penalty": 0.0,
    "use_velocity_controller": True, "min_input_norm": 0.08, "dt_delay": 0,
}
AGENT_RADIUS = 0.16
BOX_LENGTH, BOX_WIDTH = 0.32, 0.24  # box agents: extent along x, along y
LENGTH = 5.0  # corridor length (x in [-2.5, 2.5])
CORRIDOR = 0.4  # corridor width (y in [-0.2, 0.2]), also the nook's width
NOOK_DEPTH = 0.48
START_X = LENGTH / 2 - 0.5  # agents start this far from the centre
GOAL_X = LENGTH / 2 - (AGENT_RADIUS + 0.05)
GOAL_RADIUS = AGENT_RADIUS / 2
SPAWN_NOISE = 0.02
TOUCH_DISTANCE = 0.005  # surfaces closer than this count as a collision in the reward
PID_PARAMS = (2.0, 6.0, 0.002)  # standard form: gain, integral time, derivative time


class Wall(NamedTuple):
    """One line landmark of the map."""

    name: str
    length: float
    x: float
    y: float
    vertical: bool
    nook: bool = False  # part of a nook (``passage_collision_penalty``) rather than a plain wall


def map_layout(mirror_passage: bool) -> list[Wall]:
    """The walls of the map, in world order (VMAS 1.5's names and order).

    End walls, the two ceiling halves either side of the nook, the nook (left,
    right, top); then either the floor or, mirrored about y = 0, a second pair
    of ceiling halves and a second nook.
    """
    half_corridor, ceiling = CORRIDOR / 2, LENGTH / 2 - CORRIDOR / 2
    walls = [Wall(f"wall {i}", CORRIDOR, side * LENGTH / 2, 0.0, True, False) for i, side in enumerate((-1, 1))]
    for sign, tag in ((1.0, ""), (-1.0, "2")) if mirror_passage else ((1.0, ""),):
        walls += [
            Wall(f"ceil 1{tag} {i}", ceiling, side * (LENGTH - ceiling) / 2, sign * half_corridor, False, False)
            for i, side in enumerate((1, -1))
        ]
        walls += [
            Wall(f"ceil 2{tag} {i}", NOOK_DEPTH, side * half_corridor, sign * (half_corridor + NOOK_DEPTH / 2), True, True)
            for i, side in enumerate((-1, 1))
        ]
        walls.append(Wall(f"ceil 2{tag} 2", CORRIDOR, 0.0, sign * (half_corridor + NOOK_DEPTH), False, True))
    if not mirror_passage:
        walls.append(Wall("floor", LENGTH, 0.0, -half_corridor, False, False))
    return walls


def track_velocity(agent: Agent, command: Tensor, max_speed: float, min_input_norm: float) -> None:
    """Turn a desired velocity ``command`` [B, 2] into ``agent.action.u`` through its PID controller.

    The command is clipped to a disc of radius ``max_speed`` and zeroed below
    ``min_input_norm``; it is kept as ``agent.vel_action``. Shared with
    ``multi_give_way``, whose robots are driven the same way.
    """
    command = TorchUtils.clamp_with_norm(command, max_speed)
    small = torch.linalg.vector_norm(command, dim=-1, keepdim=True) < min_input_norm
    command = torch.where(small, 0.0, command)
    agent.action.u = command
    agent.vel_action = command.clone()
    # a zero command starts a fresh PID episode: no integral carried over from the last move
    # (the controller's reset(mask), done with torch.where so that a GPU never syncs here)
    controller = agent.controller
    stopped = (torch.linalg.vector_norm(command, dim=-1) < 1e-3).unsqueeze(-1)
    controller.accum_errs = torch.where(stopped, 0.0, controller.accum_errs)
    controller.prev_err = torch.where(stopped, 0.0, controller.prev_err)
    controller.process_force()


def validate(config: dict) -> None:
    """Raise ValueError for a kwarg value the task cannot be built with."""
    for name in ("v_range", "a_range"):
        check_number("give_way", name, config[name], strict=True)
    for name in ("obs_noise", "linear_friction", "min_input_norm"):
        check_number("give_way", name, config[name])
    check_int("give_way", "dt_delay", config["dt_delay"], 0, "steps")


class Scenario(BaseScenario):
    supports_batched_reset = True

    def make_world(self, batch_dim: int, device, **kwargs) -> World:
        configure(self, kwargs, DEFAULTS, validate)
        self.viewer_size = (1600, 700)
        self.f_range = self.a_range + self.linear_friction
        self.u_range = self.v_range if self.use_velocity_controller else self.f_range

        world = World(
            batch_dim, device, dt=0.05, drag=0.0, linear_friction=self.linear_friction,
            substeps=16 if self.box_agents else 5, collision_force=10000 if self.box_agents else 500,
        )
        for i, color in enumerate((Color.BLUE, Color.GREEN)):
            agent = Agent(
                name=f"agent_{i}", color=color, rotatable=False, linear_friction=self.linear_friction,
                shape=Box(length=BOX_LENGTH, width=BOX_WIDTH) if self.box_agents else Sphere(radius=AGENT_RADIUS),
                u_range=self.u_range, f_range=self.f_range, v_range=self.v_range, render_action=True,
            )
            if self.use_velocity_controller:
                agent.controller = VelocityController(agent, world, PID_PARAMS, "standard")
            goal = Landmark(name=f"goal_{i}", collide=False, shape=Sphere(radius=GOAL_RADIUS), color=color)
            agent.goal = goal
            world.add_agent(agent)
            world.add_landmark(goal)

        self.layout = map_layout(self.mirror_passage)
        self.walls = [
            Landmark(name=w.name, collide=True, shape=Line(length=w.length), color=Color.BLACK) for w in self.layout
        ]
        for wall in self.walls:
            world.add_landmark(wall)
        self._wall_pos = torch.tensor([[w.x, w.y] for w in self.layout], device=world.device)
        self._wall_rot = torch.tensor([[math.pi / 2 if w.vertical else 0.0] for w in self.layout], device=world.device)
        self._wall_length = torch.tensor([w.length for w in self.layout], device=world.device)
        penalties = [self.passage_collision_penalty if w.nook else self.obstacle_collision_penalty for w in self.layout]
        self._wall_penalty = torch.tensor(penalties, dtype=torch.float32, device=world.device)
        side = torch.tensor([[-1.0], [1.0]], device=world.device)
        self._start = torch.cat([side * START_X, torch.zeros(2, 1, device=world.device)], dim=1)  # [2 agents, 2]
        self._goal = torch.cat([-side * GOAL_X, torch.zeros(2, 1, device=world.device)], dim=1)

        #: per env [B, 2 agents]: distance to goal x pos_shaping_factor, as of the last reward
        self.shaping = torch.zeros(batch_dim, 2, device=world.device)
        #: per env [B]: both agents on their goals (updated with the rewards)
        self.goal_reached = torch.zeros(batch_dim, dtype=torch.bool, device=world.device)
        #: per env, per agent: the commanded velocities still in the ``dt_delay`` delay line
        self._delay_line = torch.zeros(batch_dim, 2, self.dt_delay, world.dim_p, device=world.device)
        zeros = torch.zeros(batch_dim, device=world.device)
        self.pos_rew, self.final_rew = zeros.clone(), zeros.clone()
        self.agent_collision_rew = torch.zeros(batch_dim, 2, device=world.device)
        self.obstacle_collision_rew = self.agent_collision_rew.clone()
        self.energy_rew = self.agent_collision_rew.clone()
        self._index = {agent.name: i for i, agent in enumerate(world.agents)}
        return world

    # ------------------------------------------------------------------- reset
    def reset_world_at(self, env_index=None) -> None:
        world = self.world
        rows = selected_rows(world.batch_dim, env_index)
        noise = torch.empty(rows, 2, world.dim_p, device=world.device).uniform_(-SPAWN_NOISE, SPAWN_NOISE)
        starts = self._start + noise  # [rows, 2 agents, 2]
        for i, agent in enumerate(world.agents):
            agent.set_pos(shaped_for(starts[:, i], env_index), batch_index=env_index)
            agent.goal.set_pos(self._goal[i], batch_index=env_index)
            if self.use_velocity_controller:
                agent.controller.reset(env_index)
        for k, wall in enumerate(self.walls):
            wall.set_pos(self._wall_pos[k], batch_index=env_index)
            wall.set_rot(self._wall_rot[k], batch_index=env_index)
        shaping = torch.linalg.vector_norm(starts - self._goal, dim=-1) * self.pos_shaping_factor
        if env_index is None:
            self.shaping = shaping
            self.goal_reached = torch.zeros_like(self.goal_reached)
            self._delay_line = torch.zeros_like(self._delay_line)
        else:
            self.shaping[env_index] = shaped_for(shaping, env_index)
            self.goal_reached[env_index] = False
            self._delay_line[env_index] = 0.0

    # ----------------------------------------------------------------- actions
    def process_action(self, agent: Agent) -> None:
        """Velocity mode: delay, clip the command to a disc, zero tiny ones, then run the PID."""
        if not self.use_velocity_controller:
            return
        command = agent.action.u
        if self.dt_delay:
            i = self._index[agent.name]
            line = torch.cat([self._delay_line[:, i], command.unsqueeze(1)], dim=1)
            command, self._delay_line[:, i] = line[:, 0], line[:, 1:]
        track_velocity(agent, command, self.u_range, self.min_input_norm)

    # ------------------------------------------------------------------ reward
    def _stack(self, field: str) -> Tensor:
        return torch.stack([getattr(a.state, field) for a in self.world.agents], dim=1)  # [B, 2, ...]

    def _wall_clearance(self, pos: Tensor, rot: Tensor) -> Tensor:
        """Surface distance from every agent to every wall, [B, 2 agents, W] (one batched query)."""
        walls = torch.stack([w.state.pos for w in self.walls], dim=1).unsqueeze(1)  # [B, 1, W, 2]
        wall_rot = torch.stack([w.state.rot[:, 0] for w in self.walls], dim=1).unsqueeze(1)  # [B, 1, W]
        if self.box_agents:
            on_box, on_wall = geo.closest_points_box_segment(
                pos.unsqueeze(2), rot.unsqueeze(2), BOX_LENGTH, BOX_WIDTH, walls, wall_rot, self._wall_length
            )
            return torch.linalg.vector_norm(on_box - on_wall, dim=-1) - LINE_MIN_DIST
        gap = geo.point_segment_distance(walls, wall_rot, self._wall_length, pos.unsqueeze(2))
        return gap - LINE_MIN_DIST - AGENT_RADIUS

    def _broad_phase(self, pos: Tensor) -> Tensor:
        """Which (agent, wall) pairs the engine's broad phase keeps: [B or 1, 2, W] bool.

        A wall counts only while the agent's centre is within the sum of their
        circumscribed radii, judged per env or, with the world's ``"batch"``
        broad phase (VMAS 1.5's rule, the default), for the whole batch at once.
        """
        walls = torch.stack([w.state.pos for w in self.walls], dim=1).unsqueeze(1)  # [B, 1, W, 2]
        reach = self.world.agents[0].shape.circumscribed_radius() + self._wall_length / 2
        within = torch.linalg.vector_norm(pos.unsqueeze(2) - walls, dim=-1) <= reach
        return within.any(dim=0, keepdim=True) if self.world.broad_phase == "batch" else within

    def _all_rewards(self) -> Tensor:
        """Every agent's reward [B, 2]; caches the terms ``info`` reports."""
        world = self.world
        pos = self._stack("pos")
        goals = torch.stack([a.goal.state.pos for a in world.agents], dim=1)
        distance = torch.linalg.vector_norm(pos - goals, dim=-1)  # [B, 2]
        self.goal_reached = (distance < GOAL_RADIUS).all(dim=1)
        shaping = distance * self.pos_shaping_factor
        self.pos_rew = (self.shaping - shaping).sum(dim=1)
        self.shaping = shaping
        self.final_rew = torch.where(self.goal_reached, self.final_reward, 0.0)

        touching = world.get_distance(world.agents[0], world.agents[1]) <= TOUCH_DISTANCE
        self.agent_collision_rew = (touching.float() * self.agent_collision_penalty).unsqueeze(1).expand(-1, 2)
        near = self._wall_clearance(pos, self._stack("rot")[..., 0]) <= TOUCH_DISTANCE  # [B, 2, W]
        near = near & self._broad_phase(pos)
        self.obstacle_collision_rew = (near.float() * self._wall_penalty).sum(dim=-1)

        forces = [a.action.u if a.action.u is not None else torch.zeros_like(a.state.pos) for a in world.agents]
        force_norm = torch.linalg.vector_norm(torch.stack(forces, dim=1), dim=-1)
        self.energy_rew = -force_norm / math.sqrt(world.dim_p * self.f_range**2) * self.energy_rew_coeff
        shared = (self.pos_rew + self.final_rew).unsqueeze(1)
        return shared + self.obstacle_collision_rew + self.agent_collision_rew + self.energy_rew

    def reward(self, agent: Agent) -> Tensor:
        if agent is self.world.agents[0]:
            self._rewards = self._all_rewards()
        return self._rewards[:, self._index[agent.name]]

    # ------------------------------------------------------------- observation
    def observation(self, agent: Agent) -> Tensor:
        parts = [agent.state.pos, agent.state.vel]
        if self.observe_rel_pos:
            parts += [agent.state.pos - other.state.pos for other in self.world.agents if other is not agent]
        obs = torch.cat(parts, dim=-1)
        if self.obs_noise > 0:
            obs = obs + torch.empty_like(obs).uniform_(-self.obs_noise, self.obs_noise)
        return obs

    def info(self, agent: Agent) -> dict:
        i = self._index[agent.name]
        return {
            "pos_rew": self.pos_rew,
            "final_rew": self.final_rew,
            "energy_rew": self.energy_rew[:, i],
            "agent_collision_rew": self.agent_collision_rew[:, i],
            "obstacle_collision_rew": self.obstacle_collision_rew[:, i],
        }

    def done(self) -> Tensor:
        if self.done_on_completion:
            return self.goal_reached
        return torch.zeros_like(self.goal_reached)


class HeuristicPolicy(BaseHeuristicPolicy):
    """Blue (agent 0) waits in the upper nook while green passes; each keeps its own lane.

    Decentralised and memoryless: an agent works out who it is from its own
    position and velocity, and blue's wait is timed by its own path through
    the nook, not by watching green (who is not in the default observation).

    * Identity. Blue drives in the upper lane (y = +LANE) or in the nook,
      green in the lower lane (y = -LANE): above ``LANE_TOL`` is blue, below
      ``-LANE_TOL`` green. In between (only at the start, where the spawn noise
      is smaller than ``LANE_TOL``) the direction of travel decides and, at
      rest, the side the agent stands on (blue starts at x < 0).
    * Green drives at ``green_wait_speed`` until it is ``green_slow_until``
      from the nook, which brings it there just after blue has climbed in,
      then at full speed to its goal.
    * Blue drives to the nook's left column, climbs it (fast until green's
      lane is clear, then slowly: that climb is the wait), crosses to the right
      column at the top, comes down it and drives to its goal. Which leg it is
      on follows from where it is: left column going up, right column going down.

    Actions are desired velocities (the default ``use_velocity_controller``);
    otherwise a proportional velocity loop turns them into forces. The timing
    assumes no actuation delay: with ``dt_delay`` the agents may meet.
    """

    LANE = 0.03
    LANE_TOL = 0.022
    gain = 3.0
    #: gentler gain where blue must stop on a mark: arriving under the nook, coming down to its lane
    approach_gain = 1.0
    climb_speed = 0.4
    wait_speed = 0.1  # above min_input_norm, so the velocity controller does not drop it
    green_wait_speed = 0.28
    green_slow_until = 0.45
    column = 0.03  # the nook's climbing (left) and descending (right) columns are at x = -+column
    force_gain = 4.0

    def __init__(self, continuous_action: bool = True, **scenario_kwargs) -> None:
        super().__init__(continuous_action)
        cfg = heuristic_kwargs("give_way", DEFAULTS, scenario_kwargs)
        self.v_range = cfg["v_range"]
        self.velocity_actions = cfg["use_velocity_controller"]
        self.width = 6 if cfg["observe_rel_pos"] else 4
        half_height = BOX_WIDTH / 2 if cfg["box_agents"] else AGENT_RADIUS
        self.nook_top = CORRIDOR / 2 + NOOK_DEPTH - half_height - 0.03
        self.clear = -self.LANE + 2 * half_height + 0.02  # blue above this leaves room for green below

    def compute_action(self, observation: Tensor, u_range: float) -> Tensor:
        if observation.shape[1] != self.width:
            raise ValueError(f"give_way heuristic: expected observation width {self.width}, got {observation.shape[1]}")
        pos, vel = observation[:, 0:2], observation[:, 2:4]
        x, y = pos[:, 0], pos[:, 1]
        blue = self._is_blue(pos, vel)
        velocity = torch.where(blue.unsqueeze(-1), self._blue(x, y), self._green(x, y))
        velocity = TorchUtils.clamp_with_norm(velocity, self.v_range)
        action = velocity if self.velocity_actions else self.force_gain * (velocity - vel)
        return action.clamp(-u_range, u_range)

    def _is_blue(self, pos: Tensor, vel: Tensor) -> Tensor:
        """Blue or green, [B] bool: by lane, else by direction of travel, else by side."""
        x, y, vx = pos[:, 0], pos[:, 1], vel[:, 0]
        by_motion = torch.where(vx.abs() > 0.05, vx > 0, x < 0)
        return torch.where(y.abs() > self.LANE_TOL, y > 0, by_motion)

    def _towards(self, x: Tensor, y: Tensor, target_x: float, target_y: float, speed, gain: float = 0.0) -> Tensor:
        """Proportional move to (target_x, target_y); the x speed is capped at ``speed`` (a number or [B])."""
        speed = torch.as_tensor(speed, device=x.device, dtype=x.dtype)
        vx = torch.maximum(torch.minimum((gain or self.gain) * (target_x - x), speed), -speed)
        vy = (self.gain * (target_y - y)).clamp(-self.v_range, self.v_range)
        return torch.stack([vx, vy], dim=-1)

    def _green(self, x: Tensor, y: Tensor) -> Tensor:
        speed = torch.where(x > self.green_slow_until, self.green_wait_speed, self.v_range)
        return self._towards(x, y, -GOAL_X, -self.LANE, speed)

    def _blue(self, x: Tensor, y: Tensor) -> Tensor:
        left, in_lane = x < 0, y < self.LANE + 0.02
        under_column = x >= -self.column - 0.01
        approach = self._towards(x, y, -self.column, self.LANE, self.v_range, gain=self.approach_gain)
        approach[:, 0] = approach[:, 0].clamp_min(self.wait_speed)  # never stall short of the column
        climb_speed = torch.where(y < self.clear, self.climb_speed, self.wait_speed)
        climb = torch.stack([self.gain * (-self.column - x), climb_speed], dim=-1)
        cross = torch.stack([torch.full_like(x, self.wait_speed), self.gain * (self.nook_top - y)], dim=-1)
        down = (self.approach_gain * (self.LANE - y)).clamp(-self.climb_speed, -self.wait_speed)
        descend = torch.stack([self.gain * (self.column - x), down], dim=-1)
        legs = [  # (where, what): later legs win where regions overlap
            (left & in_lane & ~under_column, approach),
            (left & under_column & (y < self.nook_top), climb),
            (left & (y >= self.nook_top), cross),
            (~left & ~in_lane, descend),
        ]
        velocity = self._towards(x, y, GOAL_X, self.LANE, self.v_range)  # out of the nook: to the goal
        for where, leg in legs:
            velocity = torch.where(where.unsqueeze(-1), leg, velocity)
        return velocity
